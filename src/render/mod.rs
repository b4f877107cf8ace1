//! The tiled ray marcher.
//!
//! [`render`] splits the window into tiles and marches them in parallel (rayon), each with
//! per-thread scratch (module `march`); module `composite` holds the pure compositing formulas;
//! [`Quality`] presets set the dials; [`render_naive`] is the uniform-step baseline the
//! benchmark compares against.

mod composite;
mod march;
mod naive;
mod ngp;
mod proposal;
mod quality;
mod splats;

pub(crate) use splats::splat_layer;

pub use composite::{crossing_depth, opacity, srgb_composite_to_linear, Pieces};
pub use naive::render_naive;
pub use quality::{MarchParams, Quality};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::error::Result;
use crate::field::ColorSpace;
use crate::image::{Plane, Planes, Window};
use crate::scene::Scene;
use march::{march_tile, InstancePlan, PixelResult, Scratch};

/// Which planes to produce. Work for planes nobody asked for is not done (no colour
/// queries without `rgb`, no median log without `depth_median`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Outputs {
    /// Premultiplied RGB.
    pub rgb: bool,
    /// Accumulation.
    pub alpha: bool,
    /// Expected depth as camera Z.
    pub depth_z: bool,
    /// Expected depth as ray distance.
    pub depth_ray: bool,
    /// Median depth (ray distance).
    pub depth_median: bool,
}

impl Outputs {
    /// Every plane.
    pub fn all() -> Self {
        Outputs {
            rgb: true,
            alpha: true,
            depth_z: true,
            depth_ray: true,
            depth_median: true,
        }
    }

    /// Premultiplied RGBA only.
    pub fn rgba() -> Self {
        Outputs {
            rgb: true,
            alpha: true,
            depth_z: false,
            depth_ray: false,
            depth_median: false,
        }
    }
}

/// What the colour planes hold when a scene holds fields trained on photographs (composited in
/// their sRGB-encoded space; see [`srgb_composite_to_linear`]).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
pub enum ColorOutput {
    /// Scene-linear: the composite converted from the trained space (unpremultiply, decode,
    /// premultiply), for compositing with linear renders and plates.
    #[default]
    Linear,
    /// The composite as trained (display-referred, what the trainer's viewer shows),
    /// unconverted.
    AsTrained,
}

/// Everything a render needs besides the scene and camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    /// The marcher's dials (usually a [`Quality`] preset's).
    pub march: MarchParams,
    /// Which planes to produce.
    pub outputs: Outputs,
    /// Tile side in pixels.
    pub tile_size: u32,
    /// Linear or as-trained colour.
    pub color: ColorOutput,
    /// Times per frame a shot with motion blur is rendered at over its shutter (1: none);
    /// see [`Quality::shutter_samples`].
    pub shutter_samples: u32,
}

impl RenderSettings {
    /// Settings with 16-pixel tiles.
    pub fn new(march: MarchParams, outputs: Outputs) -> Self {
        RenderSettings {
            march,
            outputs,
            tile_size: 16,
            color: ColorOutput::Linear,
            shutter_samples: 1,
        }
    }
}

/// What a render did, for benchmarks and logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// Pixels rendered.
    pub pixels: u64,
    /// Density queries (regular and refinement samples, summed over instances).
    pub density_samples: u64,
    /// Radiance queries.
    pub color_samples: u64,
    /// Splat fragments met by the pixels.
    pub splat_fragments: u64,
    /// Rays that spent their whole sample budget ([`MarchParams::max_samples`]) before
    /// reaching the preset's error target: their pixels may be off by more than it.
    pub budget_limited_rays: u64,
    /// Density samples a field answered with NaN or an infinity: each was taken as empty.
    pub invalid_samples: u64,
}

impl RenderStats {
    /// What a user should hear about this render, if anything, and what to do about it: rays
    /// that stopped at their sample budget (a finer preset has a larger one) and density
    /// samples a field answered with NaN or an infinity (the field file holds weights that
    /// overflow, or a broken training).
    pub fn warning(&self) -> Option<String> {
        let mut parts = Vec::new();
        if self.budget_limited_rays > 0 {
            parts.push(format!(
                "{} of {} pixels stopped at the preset's sample budget and may miss its \
                 error target (a higher quality preset gives rays a larger budget)",
                self.budget_limited_rays, self.pixels
            ));
        }
        if self.invalid_samples > 0 {
            parts.push(format!(
                "{} density samples were NaN or infinite and were taken as empty (check the \
                 field file: its network overflows there)",
                self.invalid_samples
            ));
        }
        (!parts.is_empty()).then(|| parts.join("; "))
    }
}

/// Two renders' counts together.
impl std::ops::Add for RenderStats {
    type Output = RenderStats;

    fn add(mut self, other: RenderStats) -> RenderStats {
        self.pixels += other.pixels;
        self.density_samples += other.density_samples;
        self.color_samples += other.color_samples;
        self.splat_fragments += other.splat_fragments;
        self.budget_limited_rays += other.budget_limited_rays;
        self.invalid_samples += other.invalid_samples;
        self
    }
}

/// Renders `window` (clamped to the camera's image) of `scene` seen by `camera`.
pub fn render(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    settings: &RenderSettings,
) -> Result<Planes> {
    render_with_progress(scene, camera, window, settings, &|_| {}).map(|(planes, _)| planes)
}

/// [`render`], calling `on_tile(pixels)` as each tile finishes (from any thread) and
/// returning what the render did.
pub fn render_with_progress(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    settings: &RenderSettings,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, RenderStats)> {
    let window = camera.clamp_window(window)?;
    let plans = InstancePlan::for_scene(scene, &settings.march);
    let splats = splats::splat_layer(scene, camera, window, &settings.outputs)?;
    let tiles = tiles(window, settings.tile_size.max(1));
    let results: Vec<(Window, Vec<PixelResult>, RenderStats)> = tiles
        .into_par_iter()
        .map_init(Scratch::default, |scratch, tile| {
            let mut out = Vec::with_capacity(tile.area());
            let stats = march_tile(
                scene,
                &plans,
                splats.as_ref(),
                camera,
                tile,
                settings,
                scratch,
                &mut out,
            );
            on_tile(tile.area() as u64);
            (tile, out, stats)
        })
        .collect();
    let stats = results
        .iter()
        .fold(RenderStats::default(), |acc, r| acc + r.2);
    let tiles: Vec<_> = results.into_iter().map(|(w, px, _)| (w, px)).collect();
    let decode =
        scene.composite_space() == ColorSpace::Srgb && settings.color == ColorOutput::Linear;
    Ok((assemble(window, &tiles, &settings.outputs, decode), stats))
}

fn tiles(window: Window, size: u32) -> Vec<Window> {
    let mut tiles = Vec::new();
    for y in (window.y0..window.y1).step_by(size as usize) {
        for x in (window.x0..window.x1).step_by(size as usize) {
            tiles.push(Window::new(
                x,
                y,
                (x + size).min(window.x1),
                (y + size).min(window.y1),
            ));
        }
    }
    tiles
}

/// Gathers tiles' pixels into the requested planes; `decode`: the colours were composited in
/// sRGB-encoded space and are wanted linear.
fn assemble(
    window: Window,
    tiles: &[(Window, Vec<PixelResult>)],
    outputs: &Outputs,
    decode: bool,
) -> Planes {
    let (w, h) = (window.width(), window.height());
    let plane = |on: bool| on.then(|| Plane::filled(w, h, 0.0));
    let mut planes = Planes {
        width: w,
        height: h,
        rgb: outputs.rgb.then(|| {
            [
                Plane::filled(w, h, 0.0),
                Plane::filled(w, h, 0.0),
                Plane::filled(w, h, 0.0),
            ]
        }),
        alpha: plane(outputs.alpha),
        depth_z: plane(outputs.depth_z),
        depth_ray: plane(outputs.depth_ray),
        depth_median: plane(outputs.depth_median),
    };
    for (tile, pixels) in tiles {
        for (i, px) in pixels.iter().enumerate() {
            let x = tile.x0 - window.x0 + i as u32 % tile.width();
            let y = tile.y0 - window.y0 + i as u32 / tile.width();
            let at = y as usize * w as usize + x as usize;
            if let Some(rgb) = &mut planes.rgb {
                let colour = if decode {
                    srgb_composite_to_linear(px.rgb, px.alpha)
                } else {
                    px.rgb
                };
                for (c, plane) in rgb.iter_mut().enumerate() {
                    plane.data[at] = colour[c];
                }
            }
            let set = |p: &mut Option<Plane>, v: f32| {
                if let Some(p) = p {
                    p.data[at] = v;
                }
            };
            set(&mut planes.alpha, px.alpha);
            set(&mut planes.depth_z, px.depth_z);
            set(&mut planes.depth_ray, px.depth_ray);
            set(&mut planes.depth_median, px.depth_median);
        }
    }
    planes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_warning_says_how_many_and_what_to_do_and_a_clean_render_has_none() {
        let clean = RenderStats {
            pixels: 100,
            density_samples: 4000,
            ..RenderStats::default()
        };
        assert_eq!(clean.warning(), None);
        let budget = RenderStats {
            budget_limited_rays: 7,
            ..clean
        };
        let w = budget.warning().expect("a warning");
        assert!(
            w.contains("7 of 100 pixels") && w.contains("higher quality preset"),
            "{w}"
        );
        assert!(!w.contains("NaN"), "{w}");
        let both = RenderStats {
            invalid_samples: 12,
            ..budget
        };
        let w = both.warning().expect("a warning");
        assert!(
            w.contains("7 of 100 pixels")
                && w.contains("12 density samples were NaN or infinite")
                && w.contains("check the field file"),
            "{w}"
        );
    }
}
