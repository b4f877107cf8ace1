//! PLACEHOLDER: a small, strict OpenFX host (owner: host helper).
