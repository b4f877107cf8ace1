//! The `nerfx` command and its user's guide, as a user meets them: one test binary, so the
//! workspace is linked once for all of them.
//!
//! - [`cli`]: the demo, a frame range through scene and shot files, bad input refused;
//! - [`export_standin`]: the stand-ins `nerfx export-standin` writes (points on a field's
//!   surface, splat means, meshes), built through the library;
//! - [`docs`]: the guide's links, its table of contents, and the generated reference pages.

mod cli;
mod docs;
mod export_standin;
