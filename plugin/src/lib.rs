//! The OpenFX adapter over the nerfx core.
//!
//! An empty shell for now: the entry points (`OfxGetNumberOfPlugins`, `OfxGetPlugin`,
//! `OfxSetHost`), each behind `catch_unwind`, arrive with the node registry (issue 4).
