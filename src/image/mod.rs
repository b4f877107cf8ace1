//! Images: planar f32 planes, render windows, EXR and PNG output.

mod exr_io;
mod plane;
mod replace;
pub(crate) use replace::replace_file;
// Crate-visible so that other modules' tests can use its test PNG decoder.
pub(crate) mod png;

pub use exr_io::{read_exr_channels, write_exr, write_exr_layers, BACKGROUND_DEPTH};
pub use plane::{scaled_size, Plane, Planes, Window};
pub use png::{encode_png_rgba8, write_png_preview};
