//! nerfx against Blender itself, headless, in every Blender tested (Debian's 3.4, bpy 4.5 and
//! 5.0, see [`common_blender`]): the scripts in `tests/blender/` build the scenes and export
//! them with the add-on, and Blender's own projection and Cycles renders are the references.
//! One test binary, so the workspace is linked once for all of them.
//!
//! - [`alignment`]: `world_to_camera_view`, Cycles silhouettes and Z passes;
//! - [`depth_of_field`], [`motion_blur`]: Cycles renders with depth of field and motion blur;
//! - [`environment`]: Cycles looking through the World at an environment map;
//! - [`splat_import`]: the add-on's splat import against nerfx's reading of the file.

#[path = "../common_blender/mod.rs"]
mod common_blender;

mod alignment;
mod depth_of_field;
mod environment;
mod motion_blur;
mod splat_import;
