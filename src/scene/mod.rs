//! Scenes: field instances placed in the host's world, rendered jointly.
