//! The frame's splat fragments: each splat instance seen through the camera as a pinhole in
//! gsplat's frame, projected, sorted and binned once per render.

use glam::{DMat3, DMat4, DVec4};

use super::Outputs;
use crate::camera::{Camera, Projection};
use crate::error::{Error, Result};
use crate::field::{SplatLayer, SplatView, SPLAT_NEAR_PLANE};
use crate::image::Window;
use crate::scene::Scene;

/// Blender's camera (x right, y up, looking down −z) to gsplat's (x right, y down, z forward).
const GSPLAT_FROM_BLENDER: DMat4 = DMat4::from_cols(
    DVec4::new(1.0, 0.0, 0.0, 0.0),
    DVec4::new(0.0, -1.0, 0.0, 0.0),
    DVec4::new(0.0, 0.0, -1.0, 0.0),
    DVec4::new(0.0, 0.0, 0.0, 1.0),
);

/// The splat layer of `scene` seen by `camera` over `window`, or `None` when the scene holds
/// no splats.
pub(super) fn splat_layer(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    outputs: &Outputs,
) -> Result<Option<SplatLayer>> {
    if scene.splats.is_empty() {
        return Ok(None);
    }
    let Projection::Perspective(perspective) = camera.projection() else {
        return Err(Error::Unsupported(
            "splats render through perspective cameras; this shot's camera is panoramic \
             (equirectangular, ODS or VR180)"
                .into(),
        ));
    };
    let (width, height) = perspective.resolution();
    let [clip_start, clip_end] = camera.clip();
    let camera_from_world = GSPLAT_FROM_BLENDER * camera.world_from_camera().inverse();
    let eye_world = camera.world_from_camera().w_axis;
    let views: Vec<_> = scene
        .splats
        .iter()
        .map(|inst| {
            let camera_from_splats = camera_from_world * inst.world_from_splats();
            let view = SplatView {
                linear: DMat3::from_mat4(camera_from_splats),
                translation: camera_from_splats.w_axis.truncate(),
                intrinsics: perspective.intrinsics(),
                width,
                height,
                depth_range: [clip_start.max(SPLAT_NEAR_PLANE), clip_end],
                eye: (inst.splats_from_world() * eye_world).truncate(),
                antialiased: inst.antialiased(),
                rgb: outputs.rgb,
                crop: inst.crop().copied(),
            };
            (inst.splats(), view)
        })
        .collect();
    Ok(Some(SplatLayer::build(&views, window)))
}
