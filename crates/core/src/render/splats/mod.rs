//! The frame's splat fragments: each splat instance seen through the camera as a pinhole in
//! gsplat's frame, projected, sorted and binned once per render; through a panoramic camera,
//! binned by direction for each pixel's own ray.

mod project;
mod raster;
mod rays;

pub(crate) use project::NEAR_PLANE;
pub(crate) use raster::{SplatPixel, MIN_TRANSMITTANCE};

use glam::{DMat3, DMat4, DVec4};

use project::View as SplatView;
use raster::SplatLayer;
use rays::{RayLayer, RayView as SplatRayView};

use super::fragment::Fragment;
use super::Outputs;
use crate::camera::{Camera, Projection, Ray};
use crate::error::{Error, Result};
use crate::image::Window;
use crate::scene::{CropBox, Scene};

/// Blender's camera (x right, y up, looking down −z) to gsplat's (x right, y down, z forward).
const GSPLAT_FROM_BLENDER: DMat4 = DMat4::from_cols(
    DVec4::new(1.0, 0.0, 0.0, 0.0),
    DVec4::new(0.0, -1.0, 0.0, 0.0),
    DVec4::new(0.0, 0.0, -1.0, 0.0),
    DVec4::new(0.0, 0.0, 0.0, 1.0),
);

/// A frame's splats, ready to give each pixel its fragments.
pub(crate) enum Splatting {
    /// A perspective camera: gsplat's rasteriser.
    Tiles(SplatLayer),
    /// A panoramic camera: each pixel's ray meets the splats (see `field::splats::rays`).
    Rays(RayLayer),
}

impl Splatting {
    /// Seconds spent projecting, and sorting and binning (0 for the per-ray layer's).
    pub(crate) fn timings(&self) -> [f64; 2] {
        match self {
            Splatting::Tiles(layer) => layer.timings,
            Splatting::Rays(_) => [0.0; 2],
        }
    }

    /// Hands each pixel of `window` (row-major) whose world ray is `rays[i]` its fragments,
    /// front to back, through `sink(i, fragment)` (see [`SplatLayer::fill`]); `z_per_t` and
    /// `along` are scratch.
    pub(super) fn fill(
        &self,
        window: Window,
        rays: &[Option<Ray>],
        z_per_t: &mut Vec<f64>,
        along: &mut Vec<Fragment>,
        mut sink: impl FnMut(usize, Fragment) -> bool,
    ) {
        match self {
            Splatting::Tiles(layer) => {
                layer.fill(window, z_per_t_of(rays, z_per_t), sink);
            }
            Splatting::Rays(layer) => {
                for (i, ray) in rays.iter().enumerate() {
                    let Some(r) = ray else { continue };
                    along.clear();
                    layer.fragments(r.origin, r.dir, along);
                    // Within the camera's clipping, as the marcher's rays are.
                    for f in along.iter().filter(|f| f.t >= r.near && f.t <= r.far) {
                        if !sink(i, *f) {
                            break;
                        }
                    }
                }
            }
        }
    }

    /// Composites each pixel of `window` (row-major) whose world ray is `rays[i]` from its
    /// fragments alone into `out[i]` (see [`SplatLayer::composite`]), when this layer can
    /// (a perspective camera's), with the depth moment where `depth` asks for it: the number
    /// of fragments met, or `None` where [`Self::fill`] must be used.
    pub(super) fn composite(
        &self,
        window: Window,
        rays: &[Option<Ray>],
        z_per_t: &mut Vec<f64>,
        depth: bool,
        out: &mut Vec<SplatPixel>,
    ) -> Option<u64> {
        let Splatting::Tiles(layer) = self else {
            return None;
        };
        out.resize(rays.len(), SplatPixel::default());
        Some(layer.composite(window, z_per_t_of(rays, z_per_t), depth, out))
    }
}

/// Each ray's camera z per unit distance (NaN for a pixel without a ray), into `out`.
fn z_per_t_of<'a>(rays: &[Option<Ray>], out: &'a mut Vec<f64>) -> &'a [f64] {
    out.clear();
    out.extend(rays.iter().map(|r| r.map_or(f64::NAN, |r| r.z_per_t)));
    out
}

/// Seconds the splat rasteriser spends projecting `scene`'s splats for `camera`, and sorting
/// and binning them (zeros for a panoramic camera's per-ray layer), or `None` when the
/// scene holds none: the stages of a render's splat layer, for the benchmark.
pub fn splat_stage_timings(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    outputs: &Outputs,
) -> Result<Option<[f64; 2]>> {
    Ok(splat_layer(scene, camera, window, outputs)?.map(|layer| layer.timings()))
}

/// The splats of `scene` seen by `camera` over `window`, or `None` when the scene holds
/// none.
pub(crate) fn splat_layer(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    outputs: &Outputs,
) -> Result<Option<Splatting>> {
    if scene.splats().next().is_none() {
        return Ok(None);
    }
    let [clip_start, clip_end] = camera.clip();
    let world_from_camera = camera.world_from_camera();
    let eye_world = world_from_camera.w_axis;
    let Projection::Perspective(perspective) = camera.projection() else {
        return Ok(Some(Splatting::Rays(ray_layer(scene, camera, outputs)?)));
    };
    let (width, height) = perspective.resolution();
    let camera_from_world = GSPLAT_FROM_BLENDER * world_from_camera.inverse();
    let views: Vec<_> = scene
        .splats()
        .map(|inst| {
            let camera_from_splats = camera_from_world * inst.world_from_splats();
            let view = SplatView {
                linear: DMat3::from_mat4(camera_from_splats),
                translation: camera_from_splats.w_axis.truncate(),
                intrinsics: perspective.intrinsics(),
                width,
                height,
                depth_range: [clip_start.max(NEAR_PLANE), clip_end],
                eye: (inst.splats_from_world() * eye_world).truncate(),
                antialiased: inst.antialiased(),
                rgb: outputs.rgb,
                crop: inst.crop().map(CropBox::clipper),
            };
            (inst.splats(), view)
        })
        .collect();
    Ok(Some(Splatting::Tiles(SplatLayer::build(&views, window))))
}

/// The per-ray layer for a panoramic camera.
fn ray_layer(scene: &Scene, camera: &Camera, outputs: &Outputs) -> Result<RayLayer> {
    let world_from_camera = camera.world_from_camera();
    let centre = world_from_camera.w_axis.truncate();
    let (w, h) = camera.resolution();
    // The pixel angle (vertical neighbours in the first eye's image) and the eyes' largest
    // offset from the centre, from the camera's own rays.
    let (x, y) = (f64::from(w) / 4.0, f64::from(h) / 4.0);
    let (a, b) = (camera.ray(x, y), camera.ray(x, y + 1.0));
    let (Some(a), Some(b)) = (a, b) else {
        return Err(Error::invalid(
            "splats",
            "the camera has no rays to render them with",
        ));
    };
    let pixel_angle = a.dir.dot(b.dir).clamp(-1.0, 1.0).acos();
    let eye_offset = [0.0, 0.5, 1.0]
        .iter()
        .flat_map(|&u| [0.25, 0.75].map(|v| (u * f64::from(w), v * f64::from(h))))
        .filter_map(|(x, y)| camera.ray(x.min(f64::from(w) - 0.5), y))
        .map(|r| (r.origin - centre).length())
        .fold(0.0, f64::max)
        * 1.01;
    let [clip_start, clip_end] = camera.clip();
    let views: Vec<_> = scene
        .splats()
        .map(|inst| {
            let world_from_splats = inst.world_from_splats();
            let view = SplatRayView {
                linear: DMat3::from_mat4(world_from_splats),
                translation: world_from_splats.w_axis.truncate(),
                centre,
                camera_from_world: DMat3::from_mat4(world_from_camera).transpose(),
                eye_offset,
                pixel_angle,
                eye: inst.splats_from_world().transform_point3(centre),
                depth_range: [clip_start.max(NEAR_PLANE), clip_end],
                rgb: outputs.rgb,
                crop: inst.crop().map(CropBox::clipper),
            };
            (inst.splats(), view)
        })
        .collect();
    Ok(RayLayer::build(&views))
}
