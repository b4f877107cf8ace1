//! Images: planar f32 planes, render windows, EXR and PNG output.

mod exr_io;
mod plane;
mod png;

pub use exr_io::write_exr;
pub use plane::{Plane, Planes, Window};
pub use png::write_png_preview;
