//! The files `nerfx` writes, read back by the tools a compositor reads them with (OpenEXR's
//! own library, OpenColorIO, a Cryptomatte decoder written from the specification), not by
//! the code that wrote them: one test binary, so the workspace is linked once for all of them.
//!
//! - [`exr_openexr`]: every channel of a flat EXR, the compression and the pixel aspect;
//! - [`exr_camera`]: the camera in the header, reprojected as a compositor does;
//! - [`deep_exr`]: deep scanline EXRs, flattened as OpenEXR composites a deep pixel;
//! - [`cryptomatte`]: the Cryptomatte layers, manifest and coverages;
//! - [`color_spaces`]: the output colour spaces against OpenColorIO's own configuration.

#[path = "../common_fields/mod.rs"]
mod common_fields;
#[path = "../common_ingp/mod.rs"]
#[allow(dead_code)] // the writers of bytes and folders these tests do not use
mod common_ingp;
#[path = "../common_ofx/mod.rs"]
mod common_ofx;

mod color_spaces;
mod cryptomatte;
mod deep_exr;
mod exr_camera;
mod exr_openexr;
