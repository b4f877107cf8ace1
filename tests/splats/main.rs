//! Gaussian splats read, rendered and placed in scenes: one test binary, so the workspace is
//! linked once for all of them.
//!
//! - [`formats`]: the compact splat formats against decodings nobody here wrote, and against
//!   writers written from the formats' descriptions;
//! - [`numpy`]: rendered splats against an independent NumPy rasteriser;
//! - [`scene`]: splats merged per pixel with fields, and through the command line.
//!
//! The trained splatfacto checkpoints are `tests/fields/` (`splatfacto_run`).

#[path = "../common_splats/mod.rs"]
mod common_splats;

mod formats;
mod numpy;
mod scene;
