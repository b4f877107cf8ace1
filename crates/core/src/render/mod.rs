//! The tiled ray marcher.
//!
//! [`render`] splits the window into tiles and marches them in parallel (rayon), each with
//! per-thread scratch (module `march`), or, for scenes of analytic fields, integrates their
//! rays in closed form (module `closed_form`, [`MarchParams::closed_form`]); module
//! `integrator` holds the pure compositing formulas along a ray;
//! [`Quality`] presets set the dials; [`render_naive`] is the uniform-step baseline the
//! benchmark compares against.

mod closed_form;
mod deep;
mod fragment;
mod integrator;
mod march;
mod naive;
mod ngp;
mod proposal;
mod quality;
mod runs;
mod samplers;
mod splats;
mod volume;

pub use splats::splat_stage_timings;

pub use deep::{average_images, conform_to, DeepParams, MAX_DEEP_SAMPLES};
pub use integrator::{opacity, srgb_composite_to_linear, RunningComposite};
pub use naive::render_naive;
pub use ngp::{march_ngp, ngp_ray, NgpRay, NgpSample, NgpScratch, NgpStats, NGP_MAX_STEPS};
pub use proposal::{
    proposal_ray, sample_proposals, ProposalRay, ProposalSample, ProposalScratch, ProposalStats,
    STOP_TRANSMITTANCE,
};
pub use quality::{MarchParams, Quality};

use std::sync::{Mutex, PoisonError};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::error::Result;
use crate::field::ColorSpace;
use crate::image::{DeepImage, Plane, Planes, Window};
use crate::scene::Scene;
use closed_form::ClosedScratch;
use deep::DeepTile;
use march::{march_tile, DeepPass, PixelResult, Scratch};
use samplers::Samplers;

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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ColorOutput {
    /// Scene-linear: the composite converted from the trained space (unpremultiply, decode,
    /// premultiply), for compositing with linear renders and plates.
    #[default]
    Linear,
    /// The composite as trained (display-referred, what the trainer's viewer shows),
    /// unconverted.
    AsTrained,
}

/// Everything one view's render needs besides the scene and camera (a frame of a shot, the
/// mean over several views, is a [`FrameRequest`](crate::shot_render::FrameRequest)).
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
}

/// The side of the tiles a render is cut into unless its settings say otherwise.
pub const TILE_SIZE: u32 = 16;

impl RenderSettings {
    /// Settings with [`TILE_SIZE`] tiles.
    pub fn new(march: MarchParams, outputs: Outputs) -> Self {
        RenderSettings {
            march,
            outputs,
            tile_size: TILE_SIZE,
            color: ColorOutput::Linear,
        }
    }
}

/// What a render did, for benchmarks and logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// Pixels rendered.
    pub pixels: u64,
    /// Density queries (regular and refinement samples, summed over instances). Where a
    /// scene is integrated in closed form ([`MarchParams::closed_form`]): one per piece
    /// between the primitives' support ends, plus every quadrature node and Newton step in
    /// pieces that hold Gaussian blobs.
    pub density_samples: u64,
    /// Radiance queries; in closed form, one colour per primitive a ray meets.
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
///
/// The frame's planes are allocated once, cut into bands of one tile row, and every tile
/// is written straight into its band as soon as it is marched: a frame's pixels are held
/// once, not once as tiles and again as planes, and the tiles still run in parallel one by
/// one (a host's render window may be a single band high).
pub fn render_with_progress(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    settings: &RenderSettings,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, RenderStats)> {
    render_planes(scene, camera, window, settings, None, on_tile).map(|(p, _, s)| (p, s))
}

/// [`render_with_progress`], and the window's deep image as well: every pixel's pieces and
/// fragments as deep samples (module `deep`), kept as `deep` says, flattening to the planes'
/// colour and alpha. The planes must include colour and alpha.
pub fn render_deep(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    settings: &RenderSettings,
    deep: &DeepParams,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, DeepImage, RenderStats)> {
    deep.validate()?;
    if !(settings.outputs.rgb && settings.outputs.alpha) {
        return Err(crate::error::Error::invalid(
            "deep output",
            "needs the colour and alpha planes (the samples flatten to them)",
        ));
    }
    let (planes, image, stats) =
        render_planes(scene, camera, window, settings, Some(deep), on_tile)?;
    Ok((planes, image.unwrap_or_default(), stats))
}

/// The one render loop: planes, and a deep image where `deep` is given.
fn render_planes(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    settings: &RenderSettings,
    deep: Option<&DeepParams>,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, Option<DeepImage>, RenderStats)> {
    let window = camera.clamp_window(window)?;
    let samplers = Samplers::for_scene(scene, camera, window, settings)?;
    let size = settings.tile_size.max(1);
    let decode = samplers.space == ColorSpace::Srgb && settings.color == ColorOutput::Linear;
    let mut planes = empty_planes(window, &settings.outputs);
    let bands: Vec<Mutex<Band>> = bands(&mut planes, size)
        .into_iter()
        .map(Mutex::new)
        .collect();
    let pass = deep.map(|params| DeepPass {
        params: *params,
        decode,
    });
    let deep_tiles: Mutex<Vec<(Window, DeepTile)>> = Mutex::new(Vec::new());
    let stats = tiles(window, size)
        .into_par_iter()
        .map_init(
            || (Scratch::default(), ClosedScratch::default(), Vec::new()),
            |(scratch, closed_scratch, out), tile| {
                out.clear();
                let mut deep_tile = DeepTile::default();
                let deep = pass.as_ref().map(|p| (p, &mut deep_tile));
                let stats = if samplers.closed_form {
                    closed_form::integrate_tile(
                        &samplers.plans,
                        camera,
                        tile,
                        settings,
                        closed_scratch,
                        out,
                        deep,
                    )
                } else {
                    march_tile(
                        &samplers.plans,
                        &samplers.volume,
                        samplers.splats.as_ref(),
                        camera,
                        tile,
                        settings,
                        scratch,
                        out,
                        deep,
                    )
                };
                if pass.is_some() {
                    deep_tiles
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .push((tile, deep_tile));
                }
                let band = &bands[((tile.y0 - window.y0) / size) as usize];
                // Writing a tile cannot panic, so the lock is never poisoned; if it were,
                // the rows are still whole.
                band.lock().unwrap_or_else(PoisonError::into_inner).write(
                    tile.x0 - window.x0,
                    tile.width(),
                    out,
                    decode,
                );
                on_tile(tile.area() as u64);
                stats
            },
        )
        .reduce(RenderStats::default, |a, b| a + b);
    drop(bands);
    let deep = pass.map(|_| {
        let tiles = deep_tiles
            .into_inner()
            .unwrap_or_else(PoisonError::into_inner);
        deep::assemble(window, tiles)
    });
    Ok((planes, deep, stats))
}

/// `window` cut into tiles of `size` pixels, row by row.
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

/// The requested planes of `window`, zeroed.
fn empty_planes(window: Window, outputs: &Outputs) -> Planes {
    let (w, h) = (window.width(), window.height());
    let plane = |on: bool| on.then(|| Plane::filled(w, h, 0.0));
    Planes {
        width: w,
        height: h,
        rgb: outputs
            .rgb
            .then(|| [(); 3].map(|_| Plane::filled(w, h, 0.0))),
        alpha: plane(outputs.alpha),
        depth_z: plane(outputs.depth_z),
        depth_ray: plane(outputs.depth_ray),
        depth_median: plane(outputs.depth_median),
    }
}

/// One band's rows of every present plane, starting at row `row` of the window: R, G, B,
/// alpha, depth Z, ray depth and median depth, in that order.
struct Band<'a> {
    row: u32,
    width: usize,
    planes: [Option<&'a mut [f32]>; 7],
}

impl Band<'_> {
    /// Writes a tile's pixels (row by row, `tile_width` wide) at column `x` of the band;
    /// `decode`: the colours were composited in sRGB-encoded space and are wanted linear.
    /// Each plane is written a tile row at a time: one stretch of a band's row per plane.
    fn write(&mut self, x: u32, tile_width: u32, pixels: &[PixelResult], decode: bool) {
        let tile_width = tile_width.max(1) as usize;
        for (dy, row) in pixels.chunks(tile_width).enumerate() {
            let start = dy * self.width + x as usize;
            let span = start..start + row.len();
            if let [Some(r), Some(g), Some(b), ..] = &mut self.planes {
                let (r, g, b) = (
                    &mut r[span.clone()],
                    &mut g[span.clone()],
                    &mut b[span.clone()],
                );
                for (i, px) in row.iter().enumerate() {
                    [r[i], g[i], b[i]] = if decode {
                        srgb_composite_to_linear(px.rgb, px.alpha)
                    } else {
                        px.rgb
                    };
                }
            }
            let [.., alpha, depth_z, depth_ray, depth_median] = &mut self.planes;
            put(alpha, &span, row, |px| px.alpha);
            put(depth_z, &span, row, |px| px.depth_z);
            put(depth_ray, &span, row, |px| px.depth_ray);
            put(depth_median, &span, row, |px| px.depth_median);
        }
    }
}

/// Writes `value` of each pixel of `row` over `span` of `plane`, where it is present: one
/// loop per plane and value, each a run of loads and stores.
#[inline]
fn put(
    plane: &mut Option<&mut [f32]>,
    span: &std::ops::Range<usize>,
    row: &[PixelResult],
    value: impl Fn(&PixelResult) -> f32,
) {
    if let Some(plane) = plane {
        for (v, px) in plane[span.clone()].iter_mut().zip(row) {
            *v = value(px);
        }
    }
}

/// `planes` cut into bands of `rows` rows.
fn bands(planes: &mut Planes, rows: u32) -> Vec<Band<'_>> {
    let width = planes.width as usize;
    let rows = rows.max(1);
    let count = (planes.height as usize).div_ceil(rows as usize);
    let mut bands: Vec<Band> = (0..count)
        .map(|i| Band {
            row: i as u32 * rows,
            width,
            planes: Default::default(),
        })
        .collect();
    let [r, g, b] = match &mut planes.rgb {
        Some([r, g, b]) => [Some(r), Some(g), Some(b)],
        None => [None, None, None],
    };
    let all = [
        r,
        g,
        b,
        planes.alpha.as_mut(),
        planes.depth_z.as_mut(),
        planes.depth_ray.as_mut(),
        planes.depth_median.as_mut(),
    ];
    let chunk = (width * rows as usize).max(1);
    for (k, plane) in all.into_iter().enumerate() {
        if let Some(plane) = plane {
            for (band, rows) in bands.iter_mut().zip(plane.data.chunks_mut(chunk)) {
                band.planes[k] = Some(rows);
            }
        }
    }
    bands
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
