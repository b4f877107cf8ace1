//! The scene suite: every [`SceneKind`] rendered with each preset and with the naive
//! uniform-step marcher, measured for time, work, error against the scene's reference and
//! heap.
//!
//! Analytic scenes, which the presets integrate in closed form, are also marched with each
//! preset's dials, so that the marcher's cost and error on their edges and sheets stay
//! measured.
//!
//! References: analytic scenes have the exact closed form for every pixel. Trained fields
//! have none; their reference is taken on every [`ROW_STRIDE`]-th row of the frame, or
//! every [`QUADRATURE_ROW_STRIDE`]-th for the quadrature (a full reference frame would take
//! longer than the rest of the suite), and renders are compared
//! on those rows: a much finer nerfx march ([`fine_params`]), or, for a dense field whose
//! opaque shells a march cannot be trusted to judge (it shares the marcher's refinement),
//! an adaptive f64 quadrature of the field between its mask's crossings
//! ([`reference::render_trained`], to [`QUADRATURE_TOLERANCE`]). The naive marcher, which
//! neither skips empty space nor stops early, is timed on the same rows of trained scenes
//! and its time scaled to a frame (`baseline_row`; a second reference for trained fields,
//! such as instant-ngp's own marcher, is one more such row, compared on the same rows).
//! Splats are rasterised, not marched: they have neither reference nor naive row.
//!
//! Each preset promises a per-pixel error ([`MarchParams::error_target`], alpha and
//! premultiplied colour): a row says whether it keeps it over the pixels compared. Neither
//! row reference is exact, so its own error is estimated too, against one twice as fine
//! ([`finer_params`], or a quarter of the tolerance) on every [`CHECK_ROW_STRIDE`]-th row of
//! the frame: a preset missing its target by less than that may be the reference's miss.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use super::field::process_cpu_seconds;
use super::memory::{peak_during, HeapUse};
use super::scaling::{self, Growth};
use super::scenes::{build, BenchScene, SceneKind, Truth};
use crate::reference::metrics::nan_max;
use crate::reference::{self, ErrorReport};
use nerfx_core::camera::Camera;
use nerfx_core::error::{Error, Result};
use nerfx_core::image::{Planes, Window};
use nerfx_core::render::{
    render_naive, render_with_progress, MarchParams, Outputs, Quality, RenderSettings, RenderStats,
};
use nerfx_core::scene::Scene;

/// Trained scenes are compared on every this many rows (starting at the middle of the
/// first band), but where the quadrature is their reference ([`QUADRATURE_ROW_STRIDE`]).
pub const ROW_STRIDE: u32 = 16;

/// The quadrature's rows are this many apart: it is cheap enough (the dense blob's 270 rows
/// at 1920×1080 took 72 s of a 2-core machine under load, its presets' three frames 75 s
/// of CPU), and a dense field's misses lie in single pixels (a sharp peak that one ray's
/// steps straddle), which a sparser sample passes over.
pub const QUADRATURE_ROW_STRIDE: u32 = 4;

/// A row reference's own error is estimated on every this many rows of the frame (a
/// multiple of both row strides).
pub const CHECK_ROW_STRIDE: u32 = 64;

/// What the quadrature reference lets one interval of a ray get wrong (in alpha and each
/// premultiplied colour channel): far below Final's target, so that the reference judges it.
pub const QUADRATURE_TOLERANCE: f64 = 1e-6;

/// Naive step sizes, as fractions of the scene's largest bounding-box diagonal: analytic
/// scenes, then trained ones (whose naive run only covers the reference rows).
const NAIVE_STEPS_PER_DIAGONAL: [[f64; 2]; 2] = [[384.0, 1536.0], [256.0, 1024.0]];

/// What to run.
#[derive(Clone, Debug, PartialEq)]
pub struct SuiteOptions {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Timed frames per preset (the median is reported).
    pub repeats: u32,
    /// The scenes, in order.
    pub scenes: Vec<SceneKind>,
    /// The splat scene's PLY (else generated splats).
    pub splats: Option<PathBuf>,
    /// Also measure how cost grows with content ([`super::scaling`]).
    pub scaling: bool,
}

/// One measured configuration of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// `draft`, `preview`, `final` or `naive (step …)`.
    pub name: String,
    /// Median wall time of a frame, milliseconds.
    pub ms_per_frame: f64,
    /// CPU time of that frame (user + system, all threads), seconds, where the system says.
    pub cpu_s_per_frame: Option<f64>,
    /// Density queries per pixel.
    pub samples_per_pixel: f64,
    /// Radiance queries per pixel.
    pub color_samples_per_pixel: f64,
    /// Splat fragments per pixel.
    pub fragments_per_pixel: f64,
    /// Errors against the reference (`None` where there is none).
    pub error: Option<ErrorReport>,
    /// Rays that ran out of their sample budget.
    pub budget_hits: u64,
    /// The per-pixel error the configuration promises (a preset's
    /// [`MarchParams::error_target`]; `None` for baselines, which promise nothing).
    pub error_target: Option<f64>,
    /// Peak heap of the frame above what was live before it, where measured.
    pub peak_heap: Option<usize>,
    /// The run covered only the reference rows; its time is scaled to the frame.
    pub on_rows: bool,
}

/// One scene's measurements.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneReport {
    /// Which scene.
    pub kind: SceneKind,
    /// What it holds.
    pub description: String,
    /// What the errors are measured against.
    pub truth: String,
    /// Time of the reference, milliseconds (0 when there is none).
    pub reference_ms: f64,
    /// A row reference's own error: against one twice as fine on every
    /// [`CHECK_ROW_STRIDE`]-th row (`None` for exact references and scenes without one).
    pub reference_error: Option<ErrorReport>,
    /// What that finer one is (empty without one).
    pub reference_check: String,
    /// Compared on every this many rows (1: every pixel; 0 without a reference).
    pub row_stride: u32,
    /// Heap the loaded scene and its occupancy grids hold, where measured.
    pub scene_heap: Option<usize>,
    /// Peak heap of a one-tile (16×16) Final render once the occupancy is built: the tile's
    /// scratch and the render's fixed setup, where measured.
    pub tile_heap: Option<usize>,
    /// The presets, then the naive runs.
    pub rows: Vec<Row>,
}

/// A suite run.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Worker threads.
    pub threads: usize,
    /// Load average (1, 5, 15 minutes) when the run ended, where the system says.
    pub load: Option<[f64; 3]>,
    /// The scenes.
    pub scenes: Vec<SceneReport>,
    /// How cost grows with content (empty when not asked for).
    pub growth: Vec<Growth>,
}

/// The reference march for trained fields, fixed whatever the presets' steps become: 32
/// base steps per feature (4× Final's today) that never grow, a stop at transmittance 1e-6,
/// 14 bisections, every sample shaded, the finest occupancy grid; its refinement threshold
/// is Final's.
pub fn fine_params() -> MarchParams {
    MarchParams {
        steps_per_feature: 32.0,
        cone: 0.0,
        max_step_factor: 1.0,
        min_transmittance: 1e-6,
        occupancy_resolution: 256,
        refine_depth: 14,
        color_skip_budget: 0.0,
        max_samples: u32::MAX,
        ..Quality::Final.params()
    }
}

/// The march a fine reference is checked against: twice as fine in every dial (half the
/// base step and the refinement threshold, one more bisection, a ten times lower stopping
/// transmittance).
pub fn finer_params() -> MarchParams {
    let p = fine_params();
    MarchParams {
        steps_per_feature: 2.0 * p.steps_per_feature,
        min_transmittance: 0.1 * p.min_transmittance,
        refine_depth: p.refine_depth + 1,
        error_target: 0.5 * p.error_target,
        ..p
    }
}

impl Row {
    /// Whether the row keeps its promised per-pixel error in alpha and colour over the
    /// pixels compared; `None` when it promises none or has no reference.
    pub fn within_target(&self) -> Option<bool> {
        let (e, target) = (self.error?, self.error_target?);
        // NaN errors compare false: they keep nothing.
        Some(e.max_alpha_error <= target && e.max_color_error <= target)
    }
}

/// Runs the suite; `dir` takes generated files while they load, `log` progress lines.
pub fn run(options: &SuiteOptions, dir: &Path, log: &dyn Fn(&str)) -> Result<Report> {
    let mut scenes = Vec::new();
    for &kind in &options.scenes {
        log(&format!(
            "{}: building at {}×{} …",
            kind.name(),
            options.width,
            options.height
        ));
        let (built, heap) = peak_during(|| {
            build(
                kind,
                options.width,
                options.height,
                dir,
                options.splats.as_deref(),
            )
        });
        let report = measure_scene(&built?, heap, options.repeats, log)?;
        scenes.push(report);
    }
    let growth = if options.scaling {
        scaling::run(options.width, options.height, dir, log)?
    } else {
        Vec::new()
    };
    Ok(Report {
        width: options.width,
        height: options.height,
        threads: rayon::current_num_threads(),
        load: load_average(),
        scenes,
        growth,
    })
}

/// The reference of a scene: every pixel, or the sampled rows.
enum Reference {
    Frame(Box<Planes>),
    Rows(Vec<(u32, Planes)>),
    None,
}

fn measure_scene(
    b: &BenchScene,
    built: Option<HeapUse>,
    repeats: u32,
    log: &dyn Fn(&str),
) -> Result<SceneReport> {
    let (scene, camera) = (&b.scene, &b.camera);
    let outputs = Outputs::all();
    let full = camera.full_window();
    let row_stride = match b.truth {
        Truth::Exact => 1,
        Truth::FineMarch => ROW_STRIDE,
        Truth::Quadrature => QUADRATURE_ROW_STRIDE,
        Truth::Rasterised => 0,
    };
    let rows = sampled_rows(full.height(), row_stride.max(1));

    // Occupancy grids are built on first use: a small render per preset builds them, so
    // the timed frames measure rendering alone.
    let (warm, occupancy) = peak_during(|| -> Result<()> {
        for q in Quality::ALL {
            render_frame(
                scene,
                camera,
                centre_window(camera, 32),
                q.params(),
                outputs,
            )?;
        }
        Ok(())
    });
    warm?;
    let scene_heap = built
        .zip(occupancy)
        .map(|(a, b)| (a.kept + b.kept).max(0) as usize);
    let (tile, tile_heap) = peak_during(|| {
        let params = Quality::Final.params();
        render_frame(scene, camera, centre_window(camera, 16), params, outputs)
    });
    tile?;

    let started = Instant::now();
    let (truth, reference_note) = match b.truth {
        Truth::Exact => (
            Reference::Frame(Box::new(reference::render(scene, camera, full)?)),
            "the exact closed-form integral of every pixel".to_string(),
        ),
        Truth::FineMarch => {
            let fine = render_rows(camera, &rows, |w| {
                render_frame(scene, camera, w, fine_params(), outputs).map(|(p, _)| p)
            })?;
            let p = fine_params();
            (
                Reference::Rows(fine),
                format!(
                    "a finer nerfx march ({} steps per feature, stop at transmittance {:.0e}, \
                     every sample shaded) of every {row_stride}th row ({} of {}); all errors \
                     are over those rows",
                    p.steps_per_feature,
                    p.min_transmittance,
                    rows.len(),
                    full.height()
                ),
            )
        }
        Truth::Quadrature => {
            let fine = render_rows(camera, &rows, |w| {
                reference::render_trained(scene, camera, w, QUADRATURE_TOLERANCE)
            })?;
            (
                Reference::Rows(fine),
                format!(
                    "an adaptive f64 quadrature of the trained field between its mask's \
                     crossings (no code shared with the marcher; every interval converged to \
                     {QUADRATURE_TOLERANCE:.0e} in alpha and colour) of every {row_stride}th \
                     row ({} of {}); all errors are over those rows",
                    rows.len(),
                    full.height()
                ),
            )
        }
        Truth::Rasterised => (
            Reference::None,
            "none: splats are rasterised exactly as gsplat's classic mode (checked against \
             NumPy in tests/splats/numpy.rs); presets change only marched content"
                .to_string(),
        ),
    };
    let reference_ms = started.elapsed().as_secs_f64() * 1e3;
    log(&format!(
        "{}: reference {reference_ms:.0} ms",
        b.kind.name()
    ));
    let (reference_error, reference_check) = match &truth {
        Reference::Rows(fine) => {
            let started = Instant::now();
            let every = (CHECK_ROW_STRIDE / row_stride) as usize;
            let checked: Vec<&(u32, Planes)> = fine.iter().step_by(every).collect();
            let ys: Vec<u32> = checked.iter().map(|(y, _)| *y).collect();
            let (finer, check) = if b.truth == Truth::Quadrature {
                let tolerance = 0.25 * QUADRATURE_TOLERANCE;
                let finer = render_rows(camera, &ys, |w| {
                    reference::render_trained(scene, camera, w, tolerance)
                })?;
                (finer, format!("the quadrature to {tolerance:.1e}"))
            } else {
                let finer = render_rows(camera, &ys, |w| {
                    render_frame(scene, camera, w, finer_params(), outputs).map(|(p, _)| p)
                })?;
                (finer, "a march twice as fine again".to_string())
            };
            let e = combine(
                finer
                    .iter()
                    .zip(&checked)
                    .map(|((_, finer), (_, fine))| ErrorReport::compare(finer, fine)),
            );
            log(&format!(
                "{}: reference's own error {e} ({:.0} ms)",
                b.kind.name(),
                started.elapsed().as_secs_f64() * 1e3
            ));
            (Some(e), check)
        }
        _ => (None, String::new()),
    };

    let mut report_rows = Vec::new();
    for (name, params) in configurations(b.truth) {
        let mut timed = Vec::new();
        for _ in 0..repeats.max(1) {
            let (out, heap) = peak_during(|| timed_frame(scene, camera, params));
            let (planes, stats, ms, cpu) = out?;
            timed.push((ms, cpu, planes, stats, heap));
        }
        timed.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (ms, cpu, planes, stats, heap) = timed.swap_remove(timed.len() / 2);
        let row = Row {
            name,
            ms_per_frame: ms,
            cpu_s_per_frame: cpu,
            error: compare(&truth, &planes)?,
            error_target: Some(f64::from(params.error_target)),
            peak_heap: heap.map(|h| h.peak),
            on_rows: false,
            ..counts(&stats)
        };
        log(&format!("{}: {}", b.kind.name(), row_line(&row)));
        report_rows.push(row);
    }

    let naive_steps: &[f64] = match b.truth {
        Truth::Exact => &NAIVE_STEPS_PER_DIAGONAL[0],
        Truth::FineMarch | Truth::Quadrature => &NAIVE_STEPS_PER_DIAGONAL[1],
        Truth::Rasterised => &[],
    };
    let diagonal = scene
        .marched()
        .map(|i| i.field().bounds().diagonal() as f64)
        .fold(0.0, f64::max);
    // Baselines and further references (such as instant-ngp's own marcher on trained
    // fields) are taken like the reference: on its rows where it has rows, but no more
    // often than every [`ROW_STRIDE`]th (a naive march of the quadrature's rows would cost
    // three times the presets' frames).
    let on_rows = matches!(truth, Reference::Rows(_));
    let baseline_rows: Vec<u32> = (rows.iter().copied())
        .step_by((ROW_STRIDE / row_stride.max(1)).max(1) as usize)
        .collect();
    for &steps in naive_steps {
        let step = diagonal / steps;
        let row = baseline_row(
            format!("naive (step diag/{steps})"),
            &truth,
            camera,
            on_rows.then_some(&baseline_rows[..]),
            |w| render_naive(scene, camera, w, step, &outputs),
        )?;
        log(&format!("{}: {}", b.kind.name(), row_line(&row)));
        report_rows.push(row);
    }

    if let Some(native) = &b.native {
        let row = baseline_row(
            "instant-ngp's own marcher".to_string(),
            &truth,
            camera,
            on_rows.then_some(&baseline_rows[..]),
            |w| render_frame(native, camera, w, Quality::Final.params(), outputs),
        )?;
        log(&format!("{}: {}", b.kind.name(), row_line(&row)));
        report_rows.push(row);
    }

    Ok(SceneReport {
        kind: b.kind,
        description: b.description.clone(),
        truth: reference_note,
        reference_ms,
        reference_error,
        reference_check,
        row_stride,
        scene_heap,
        tile_heap: tile_heap.map(|h| h.peak),
        rows: report_rows,
    })
}

/// The name a preset's row has where the scene, which the renderer would integrate in
/// closed form, is marched instead.
pub(super) fn marched_name(quality: Quality) -> String {
    format!("{} (marched)", quality.name())
}

/// The configurations a scene's rows are timed with: each preset, and where the scene is
/// analytic (so the presets integrate it in closed form, [`MarchParams::closed_form`]) each
/// preset again with the marcher, which holds the same targets on it (the marcher's cost
/// on hard edges and thin sheets stays measured).
fn configurations(truth: Truth) -> Vec<(String, MarchParams)> {
    let mut all: Vec<_> = (Quality::ALL.iter())
        .map(|q| (q.name().to_string(), q.params()))
        .collect();
    if truth == Truth::Exact {
        all.extend(Quality::ALL.map(|q| {
            let params = MarchParams {
                closed_form: false,
                ..q.params()
            };
            (marched_name(q), params)
        }));
    }
    all
}

/// A row of `render` measured against `truth`: on `rows` (each a one-row window, its time
/// scaled to the frame) or, without, on the full frame.
fn baseline_row(
    name: String,
    truth: &Reference,
    camera: &Camera,
    rows: Option<&[u32]>,
    render: impl Fn(Window) -> Result<(Planes, RenderStats)> + Sync,
) -> Result<Row> {
    let full = camera.full_window();
    let (t, cpu) = (Instant::now(), process_cpu_seconds());
    let (planes, stats, scale) = match rows {
        Some(rows) => {
            let parts = render_rows(camera, rows, render)?;
            let stats = parts.iter().fold(RenderStats::default(), |s, p| s + p.1 .1);
            let planes = Reference::Rows(parts.into_iter().map(|(y, (p, _))| (y, p)).collect());
            let scale = f64::from(full.height()) / rows.len().max(1) as f64;
            (planes, stats, scale)
        }
        None => {
            let (p, s) = render(full)?;
            (Reference::Frame(Box::new(p)), s, 1.0)
        }
    };
    let ms = t.elapsed().as_secs_f64() * 1e3 * scale;
    let cpu = cpu.zip(process_cpu_seconds()).map(|(a, b)| (b - a) * scale);
    Ok(Row {
        name,
        ms_per_frame: ms,
        cpu_s_per_frame: cpu,
        error: compare_references(truth, &planes)?,
        peak_heap: None,
        on_rows: rows.is_some(),
        ..counts(&stats)
    })
}

/// A frame's planes, counts, wall milliseconds and CPU seconds.
fn timed_frame(
    scene: &Scene,
    camera: &Camera,
    params: MarchParams,
) -> Result<(Planes, RenderStats, f64, Option<f64>)> {
    let (t, cpu) = (Instant::now(), process_cpu_seconds());
    let (planes, stats) =
        render_frame(scene, camera, camera.full_window(), params, Outputs::all())?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let cpu = cpu.zip(process_cpu_seconds()).map(|(a, b)| b - a);
    Ok((planes, stats, ms, cpu))
}

fn render_frame(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    params: MarchParams,
    outputs: Outputs,
) -> Result<(Planes, RenderStats)> {
    let settings = RenderSettings::new(params, outputs);
    render_with_progress(scene, camera, window, &settings, &|_| {})
}

/// The rows references are taken on: the middle row of each band `stride` rows high.
pub fn sampled_rows(height: u32, stride: u32) -> Vec<u32> {
    (0..height.div_ceil(stride))
        .map(|k| (k * stride + stride / 2).min(height - 1))
        .collect()
}

/// A centred square window of side `side` (clamped to the image).
fn centre_window(camera: &Camera, side: u32) -> Window {
    let full = camera.full_window();
    let (w, h) = (side.min(full.width()), side.min(full.height()));
    let (x0, y0) = ((full.width() - w) / 2, (full.height() - h) / 2);
    Window::new(x0, y0, x0 + w, y0 + h)
}

/// `render` of each row (a one-row window), the rows in parallel.
fn render_rows<T: Send>(
    camera: &Camera,
    rows: &[u32],
    render: impl Fn(Window) -> Result<T> + Sync,
) -> Result<Vec<(u32, T)>> {
    let width = camera.full_window().width();
    rows.par_iter()
        .map(|&y| render(Window::new(0, y, width, y + 1)).map(|out| (y, out)))
        .collect()
}

/// A full frame's errors against the reference.
fn compare(truth: &Reference, test: &Planes) -> Result<Option<ErrorReport>> {
    Ok(match truth {
        Reference::Frame(t) => Some(ErrorReport::compare(t, test)),
        Reference::Rows(rows) => {
            let pairs = rows
                .iter()
                .map(|(y, t)| Ok((t, test.crop(Window::new(0, *y, test.width, y + 1))?)))
                .collect::<Result<Vec<_>>>()?;
            Some(combine(
                pairs.iter().map(|(t, p)| ErrorReport::compare(t, p)),
            ))
        }
        Reference::None => None,
    })
}

/// Errors of a render taken like the reference (on some of its rows, or a full frame).
fn compare_references(truth: &Reference, test: &Reference) -> Result<Option<ErrorReport>> {
    let unmatched = || {
        Error::invalid(
            "benchmark",
            "a render on rows compared with a reference that lacks them",
        )
    };
    match (truth, test) {
        (_, Reference::Frame(p)) => compare(truth, p),
        (Reference::Rows(t), Reference::Rows(p)) => {
            let parts = p
                .iter()
                .map(|(y, p)| {
                    let (_, t) = t.iter().find(|(ty, _)| ty == y).ok_or_else(unmatched)?;
                    Ok(ErrorReport::compare(t, p))
                })
                .collect::<Result<Vec<_>>>()?;
            Ok(Some(combine(parts.into_iter())))
        }
        _ => Err(unmatched()),
    }
}

/// Errors over equally wide parts, as over their union: PSNR from the mean of the parts'
/// squared errors, the largest of the other errors (NaN if any is NaN).
fn combine(parts: impl Iterator<Item = ErrorReport>) -> ErrorReport {
    let (mut mse, mut n) = (0.0, 0usize);
    let mut worst = [0.0f64; 3];
    for e in parts {
        mse += 10f64.powf(-e.psnr / 10.0);
        n += 1;
        worst = [
            nan_max(worst[0], e.max_alpha_error),
            nan_max(worst[1], e.max_color_error),
            nan_max(worst[2], e.max_depth_rel_error),
        ];
    }
    ErrorReport {
        psnr: -10.0 * (mse / n.max(1) as f64).log10(),
        max_alpha_error: worst[0],
        max_color_error: worst[1],
        max_depth_rel_error: worst[2],
    }
}

/// A row's per-pixel counts (the rest left to fill).
fn counts(stats: &RenderStats) -> Row {
    let pixels = stats.pixels.max(1) as f64;
    Row {
        name: String::new(),
        ms_per_frame: f64::NAN,
        cpu_s_per_frame: None,
        samples_per_pixel: stats.density_samples as f64 / pixels,
        color_samples_per_pixel: stats.color_samples as f64 / pixels,
        fragments_per_pixel: stats.splat_fragments as f64 / pixels,
        error: None,
        budget_hits: stats.budget_limited_rays,
        error_target: None,
        peak_heap: None,
        on_rows: false,
    }
}

fn row_line(r: &Row) -> String {
    let error = r
        .error
        .map_or("no reference".to_string(), |e| e.to_string());
    format!(
        "{}: {:.0} ms, {:.1} spp, {error}",
        r.name, r.ms_per_frame, r.samples_per_pixel
    )
}

/// The 1, 5 and 15 minute load averages (Linux `/proc/loadavg`).
pub fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut v = text.split_whitespace().map(|s| s.parse::<f64>().ok());
    Some([v.next()??, v.next()??, v.next()??])
}

#[cfg(test)]
mod tests {
    use super::*;
    use nerfx_core::image::Plane;

    /// Seeded planes: `width × height`, every plane present.
    fn planes(width: u32, height: u32, seed: u32) -> Planes {
        let plane = |k: u32| Plane {
            width,
            height,
            data: (0..width * height)
                .map(|i| ((i * 7919 + seed * 104_729 + k * 31) % 1000) as f32 / 1000.0 + 0.5)
                .collect(),
        };
        Planes {
            width,
            height,
            rgb: Some([plane(0), plane(1), plane(2)]),
            alpha: Some(plane(3)),
            depth_z: Some(plane(4)),
            depth_ray: Some(plane(5)),
            depth_median: Some(plane(6)),
        }
    }

    #[test]
    fn errors_over_rows_combine_as_over_their_union() {
        let (a, b) = (planes(7, 5, 1), planes(7, 5, 2));
        let whole = ErrorReport::compare(&a, &b);
        let rows = (0..5).map(|y| {
            let row = Window::new(0, y, 7, y + 1);
            ErrorReport::compare(&a.crop(row).unwrap(), &b.crop(row).unwrap())
        });
        let combined = combine(rows);
        assert!(
            (combined.psnr - whole.psnr).abs() < 1e-9,
            "{combined} vs {whole}"
        );
        assert_eq!(combined.max_alpha_error, whole.max_alpha_error);
        assert_eq!(combined.max_color_error, whole.max_color_error);
        assert_eq!(combined.max_depth_rel_error, whole.max_depth_rel_error);
        // Compared on sampled rows, a frame is measured on exactly those rows.
        let truth = Reference::Rows(vec![(1, a.crop(Window::new(0, 1, 7, 2)).unwrap())]);
        let on_row = compare(&truth, &b).unwrap().unwrap();
        let want = ErrorReport::compare(
            &a.crop(Window::new(0, 1, 7, 2)).unwrap(),
            &b.crop(Window::new(0, 1, 7, 2)).unwrap(),
        );
        assert_eq!(on_row, want);
    }

    #[test]
    fn a_row_keeps_its_target_only_in_alpha_and_colour_both() {
        let row = |alpha: f64, color: f64, target: Option<f64>| Row {
            error: Some(ErrorReport {
                psnr: 40.0,
                max_alpha_error: alpha,
                max_color_error: color,
                max_depth_rel_error: 0.0,
            }),
            error_target: target,
            ..counts(&RenderStats::default())
        };
        let t = Some(5e-3);
        assert_eq!(row(5e-3, 1e-3, t).within_target(), Some(true));
        assert_eq!(row(5.1e-3, 1e-3, t).within_target(), Some(false));
        assert_eq!(row(1e-3, 6e-3, t).within_target(), Some(false));
        assert_eq!(row(f64::NAN, 0.0, t).within_target(), Some(false));
        assert_eq!(row(0.0, 0.0, None).within_target(), None);
        let no_reference = Row {
            error: None,
            ..row(0.0, 0.0, t)
        };
        assert_eq!(no_reference.within_target(), None);
    }

    #[test]
    fn the_finer_march_is_finer_in_every_dial() {
        let (fine, finer) = (fine_params(), finer_params());
        assert!(finer.steps_per_feature > fine.steps_per_feature);
        assert!(finer.error_target < fine.error_target);
        assert!(finer.min_transmittance < fine.min_transmittance);
        assert!(finer.refine_depth > fine.refine_depth);
        assert_eq!(finer.max_step_factor, 1.0);
    }

    #[test]
    fn sampled_rows_are_the_middles_of_bands_within_the_image() {
        assert_eq!(sampled_rows(40, 16), vec![8, 24, 39]);
        assert_eq!(sampled_rows(1, 16), vec![0]);
        assert_eq!(sampled_rows(1080, 16).len(), 68);
        assert_eq!(sampled_rows(10, 4), vec![2, 6, 9]);
        assert_eq!(sampled_rows(1080, QUADRATURE_ROW_STRIDE).len(), 270);
        // The reference's own check takes whole rows of either sample.
        for stride in [ROW_STRIDE, QUADRATURE_ROW_STRIDE] {
            assert_eq!(CHECK_ROW_STRIDE % stride, 0);
        }
    }
}
