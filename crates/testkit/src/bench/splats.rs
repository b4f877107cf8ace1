//! Splat rasterisation speed: a frame of a generated capture-like scene (splats on the
//! surfaces of nested spheres, SH degree 3, sizes, opacities and overdraw spread as in real
//! captures), timed as a whole and with the projection, sort and binning alone.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Quat, Vec3};

use super::memory::{peak_during, HeapUse};
use nerfx_core::camera::{BlenderIntrinsics, Camera, Perspective, Projection};
use nerfx_core::demo::look_at;
use nerfx_core::error::{Error, Result};
use nerfx_core::field::{SplatColor, SplatFormat, Splats};
use nerfx_core::render::{
    render_with_progress, splat_stage_timings, Outputs, Quality, RenderSettings,
};
use nerfx_core::scene::{Scene, SplatInstance};
use nerfx_core::SplitMix64;

/// What one splat frame cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplatTiming {
    /// Splats in the scene.
    pub splats: usize,
    /// Best wall time of a whole RGBA frame, milliseconds.
    pub frame_ms: f64,
    /// Of which projecting the splats (milliseconds, best of the repeats)…
    pub projection_ms: f64,
    /// …and sorting and binning them; the rest is blending.
    pub binning_ms: f64,
    /// Fragments blended per pixel.
    pub fragments_per_pixel: f64,
    /// Bytes the splats hold.
    pub memory_bytes: usize,
}

/// `n` splats laid out as a trained capture's: on the surfaces of three nested spheres around
/// the origin (radii 0.6, 0.8, 1.0, each jittered by a few percent as a trained surface is
/// thick), SH degree 3, seeded.
///
/// What drives a frame's cost is each splat's size on screen, its opacity and how many
/// overlap (fragments per pixel), so those follow real captures: the shared 14 k-splat PLY
/// and a 112 k-splat `.splat` object capture, both seen from [`framing_camera`]. Their
/// longest axis is log-normal with a spread of about a factor 2.5 (one standard deviation),
/// the middle axis a fifth of it and the shortest a fiftieth (flat discs), and a splat's
/// longest axis shrinks as `1/√n` (the captures cover their surfaces about as densely: a
/// median of 6.8 % of the interquartile extent at 14 k, 1.4 % at 112 k), so overdraw stays
/// like a capture's at any count (42 fragments a pixel at 112 k, 47 at 1 M, 53 at 3 M). Opacities are a logistic of a normal (median 0.23, a quarter below 0.06,
/// a quarter above 0.67), as trained opacities pile up near 0 and 1.
pub fn generated_splats(n: usize) -> Splats {
    let mut rng = SplitMix64::new(0x2545_f491_4f6c_dd1d);
    let mut normal = move || {
        // Box–Muller, one of the pair.
        let (u, v) = (rng.unit().max(1e-7), rng.unit());
        (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
    };
    let mut rng = SplitMix64::new(0x9e37_79b9_7f4a_7c15);
    let mut s = Splats::with_capacity(n, SplatColor::Sh { degree: 3 }, SplatFormat::Generated);
    // The median longest axis at 112 k splats, in units of the interquartile extent (about
    // 1.0 for these spheres): below the object capture's 1.4 %, as the nested spheres show
    // the camera several surfaces where it shows one or two, so that a frame meets about as
    // many fragments per pixel as the captures' frames (42 at 112 k; the captures 39 and 42).
    let median_size = 0.0085 * (111_650.0 / n.max(1) as f32).sqrt();
    for i in 0..n {
        let radius = [0.6, 0.8, 1.0][i % 3] * (1.0 + 0.02 * normal());
        let z = 2.0 * rng.unit() - 1.0;
        let phi = std::f32::consts::TAU * rng.unit();
        let r = (1.0 - z * z).max(0.0).sqrt();
        s.means
            .push(Vec3::new(r * phi.cos(), r * phi.sin(), z) * radius);
        let long = median_size * (0.9 * normal()).exp();
        let middle = long * 0.2 * (0.8 * normal()).exp().min(5.0);
        s.scales.push(Vec3::new(long, middle, long * 0.02));
        let axis = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
        s.rotations.push(Quat::from_axis_angle(
            axis.normalize_or(Vec3::Z),
            6.0 * rng.unit(),
        ));
        s.opacities.push(1.0 / (1.0 + (1.2 - 2.4 * normal()).exp()));
        for k in 0..16 {
            let spread = if k == 0 { 1.5 } else { 0.2 };
            s.coefficients
                .extend([0; 3].map(|_| spread * (rng.unit() - 0.5)));
        }
    }
    s
}

/// Writes `splats` as an INRIA PLY at `path` and reads it back: `(seconds to load, file
/// bytes)`. The file is kept (other tools convert it to the compact formats).
pub fn time_load(splats: &Splats, path: &Path) -> Result<(f64, u64)> {
    splats.write_ply(path)?;
    let bytes = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    let start = Instant::now();
    Splats::load(path)?;
    Ok((start.elapsed().as_secs_f64(), bytes))
}

/// What loading one splat file cost.
#[derive(Clone, Debug)]
pub struct LoadTiming {
    /// The splats read.
    pub splats: Splats,
    /// Wall seconds to read and decode the file.
    pub seconds: f64,
    /// The file's size in bytes.
    pub file_bytes: u64,
    /// The most heap live at once while it loaded, and the heap still held once loaded
    /// (where the counting allocator is installed, as in the `nerfx` binary).
    pub heap: Option<HeapUse>,
}

/// Loads the splat file at `path` (any format [`Splats::load`] reads), timed, with the heap
/// it took.
pub fn time_file(path: &Path) -> Result<LoadTiming> {
    let file_bytes = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    let start = Instant::now();
    let (splats, heap) = peak_during(|| Splats::load(path));
    let seconds = start.elapsed().as_secs_f64();
    Ok(LoadTiming {
        splats: splats?,
        seconds,
        file_bytes,
        heap,
    })
}

/// The splat benchmark's report (Markdown): `n` generated capture-like splats written as a
/// PLY in `out` and read back, then each of `files` loaded; a table of what each load cost
/// (seconds, seconds per million, the decoded arrays' bytes, the heap held once loaded and
/// its peak while loading) and one of what a `width × height` RGBA frame of each cost (best of
/// `repeats`: projection, sort and binning, blending, fragments per pixel, the frame's heap).
pub fn report(
    n: usize,
    files: &[PathBuf],
    out: &Path,
    (width, height): (u32, u32),
    repeats: u32,
) -> Result<String> {
    let mib = |b: f64| b / f64::from(1 << 20);
    let generated = generated_splats(n);
    let ply = out.join(format!("generated_{n}.ply"));
    let (seconds, file_bytes) = time_load(&generated, &ply)?;
    let mut sets = vec![(
        format!("generated, {n} splats ({})", ply.display()),
        LoadTiming {
            splats: generated,
            seconds,
            file_bytes,
            heap: None,
        },
    )];
    for path in files {
        sets.push((path.display().to_string(), time_file(path)?));
    }
    let mut text = String::from(
        "| splats | format | count | file (MiB) | load (s) | s per million | arrays (MiB) | \
         held once loaded (MiB) | peak while loading (MiB) |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for (name, load) in &sets {
        let source = &load.splats.source;
        let version = source.version.map_or_else(String::new, |v| format!(" {v}"));
        let [kept, peak] = load.heap.map_or_else(
            || ["–".to_string(), "–".to_string()],
            |h| [h.kept as f64, h.peak as f64].map(|b| format!("{:.1}", mib(b))),
        );
        text.push_str(&format!(
            "| {name} | {}{version} | {} | {:.1} | {:.2} | {:.2} | {:.1} | {kept} | {peak} |\n",
            source.format,
            load.splats.len(),
            mib(load.file_bytes as f64),
            load.seconds,
            load.seconds * 1e6 / load.splats.len().max(1) as f64,
            mib(load.splats.memory_bytes() as f64),
        ));
    }
    text.push_str(&format!(
        "\n| splats at {width}×{height} | frame (ms) | projection (ms) | sort + bin (ms) | \
         blending (ms) | fragments / pixel | frame heap (MiB) |\n|---|---:|---:|---:|---:|---:|---:|\n"
    ));
    for (name, load) in sets {
        let (timing, heap) =
            peak_during(|| time_splats(Arc::new(load.splats), width, height, repeats));
        let t = timing?;
        let blending = t.frame_ms - t.projection_ms - t.binning_ms;
        let heap = heap.map_or_else(|| "–".to_string(), |h| format!("{:.0}", mib(h.peak as f64)));
        text.push_str(&format!(
            "| {name} | {:.0} | {:.0} | {:.0} | {blending:.0} | {:.1} | {heap} |\n",
            t.frame_ms, t.projection_ms, t.binning_ms, t.fragments_per_pixel,
        ));
    }
    Ok(text)
}

/// Renders `splats` at `width × height` from a camera at distance 3, `repeats` times, and
/// reports the best.
pub fn time_splats(
    splats: Arc<Splats>,
    width: u32,
    height: u32,
    repeats: u32,
) -> Result<SplatTiming> {
    let camera = framing_camera(&splats, width, height)?;
    let memory_bytes = splats.memory_bytes();
    let count = splats.len();
    let scene = Scene::default().with(vec![SplatInstance::new(
        "splats",
        splats,
        glam::DMat4::IDENTITY,
        None,
        false,
    )?]);
    let settings = RenderSettings::new(Quality::Final.params(), Outputs::rgba());
    let (mut best, mut stages) = (f64::INFINITY, [f64::INFINITY; 2]);
    let mut fragments = 0;
    for _ in 0..repeats.max(1) {
        let start = Instant::now();
        let (_, stats) =
            render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {})?;
        best = best.min(start.elapsed().as_secs_f64() * 1e3);
        fragments = stats.splat_fragments;
        // The stages alone, as the render runs them.
        if let Some([p, b]) =
            splat_stage_timings(&scene, &camera, camera.full_window(), &settings.outputs)?
        {
            stages = [stages[0].min(p * 1e3), stages[1].min(b * 1e3)];
        }
    }
    Ok(SplatTiming {
        splats: count,
        frame_ms: best,
        projection_ms: stages[0],
        binning_ms: stages[1],
        fragments_per_pixel: fragments as f64 / f64::from(width * height),
        memory_bytes,
    })
}

/// A camera at `width × height` looking at the middle half of `splats` (trained scenes carry
/// far outliers) from three times its extent.
pub fn framing_camera(splats: &Splats, width: u32, height: u32) -> Result<Camera> {
    if splats.means.is_empty() {
        return Err(Error::invalid("splat benchmark", "the splat set is empty"));
    }
    let quantile = |axis: usize, q: f64| {
        let mut v: Vec<f32> = splats.means.iter().map(|m| m[axis]).collect();
        let k = ((v.len().max(1) - 1) as f64 * q) as usize;
        v.select_nth_unstable_by(k, f32::total_cmp);
        f64::from(v.get(k).copied().unwrap_or(0.0))
    };
    let centre = DVec3::new(quantile(0, 0.5), quantile(1, 0.5), quantile(2, 0.5));
    let extent = (0..3)
        .map(|a| quantile(a, 0.75) - quantile(a, 0.25))
        .fold(1e-3, f64::max);
    let eye = centre + DVec3::new(0.0, -3.0, 0.4) * extent;
    Camera::new(
        look_at(eye, centre),
        Projection::Perspective(Perspective::from_blender(&BlenderIntrinsics {
            resolution_x: width,
            resolution_y: height,
            ..BlenderIntrinsics::default()
        })?),
    )
}
