//! Images: planar f32 planes, render windows, EXR and PNG output, output colour spaces,
//! what an EXR's header says, Cryptomatte layers ([`cryptomatte`]) and deep images
//! ([`DeepImage`], written as deep scanline EXR by [`write_deep_exr`]).

mod color_spaces;
pub mod cryptomatte;
mod deep_exr;
mod exr_header;
mod exr_io;
mod plane;
mod png;

pub use self::png::write_png_preview;
pub use self::png::write_png_rgba8;
pub use color_spaces::{Chromaticities, OutputColorSpace};
pub use deep_exr::{deep_exr_available, write_deep_exr, DeepImage, DeepSample};
pub use exr_header::{frames_per_second, CameraMatrices, ExrHeader};
pub use exr_io::{
    read_exr_channels, read_exr_image, write_exr, write_exr_channels, write_exr_layers,
    BACKGROUND_DEPTH,
};
pub use plane::{scaled_size, Plane, Planes, Window};
