//! Splat rasterisation speed: a frame of a generated capture-like scene (splats on the
//! surfaces of nested spheres, SH degree 3, with the opacities, shapes and overdraw of a real
//! trained capture), timed as a whole and with the projection, sort and binning alone.

use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Quat, Vec3};

use crate::camera::{BlenderIntrinsics, Camera, Perspective, Projection};
use crate::demo::look_at;
use crate::error::{Error, Result};
use crate::field::{SplatColor, SplatFormat, Splats};
use crate::render::{render_with_progress, splat_layer, Outputs, Quality, RenderSettings};
use crate::scene::{Scene, SplatInstance};

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

/// Deciles (0 %, 10 %, … 100 %) of a real trained capture's splats (`tests/data/`
/// `splat_plane_sh3.ply`, 13 982 splats): opacity; largest standard deviation over the
/// scene's extent (the largest interquartile range of the means); middle and smallest over
/// largest.
const CAPTURE_OPACITY: [f32; 11] = [
    0.002, 0.008, 0.04, 0.09, 0.172, 0.337, 0.67, 0.967, 0.998, 1.0, 1.0,
];
const CAPTURE_LARGEST: [f32; 11] = [
    0.0049, 0.0302, 0.0399, 0.0487, 0.0574, 0.0677, 0.0788, 0.0933, 0.1133, 0.1468, 1.676,
];
const CAPTURE_MIDDLE: [f32; 11] = [
    0.003, 0.083, 0.133, 0.18, 0.233, 0.295, 0.368, 0.459, 0.574, 0.731, 0.999,
];
const CAPTURE_SMALLEST: [f32; 11] = [
    1e-5, 1e-4, 5e-4, 0.0013, 0.0033, 0.0078, 0.0167, 0.0351, 0.072, 0.1465, 0.9413,
];
/// Splats in that capture: its splats' summed area over the extent squared (its overdraw)
/// is held at any count by scaling the sizes by `√(CAPTURE_SPLATS / n)`.
const CAPTURE_SPLATS: f32 = 13_982.0;

/// The value at quantile `u` (0–1) of a decile table, interpolated geometrically (sizes and
/// opacities spread over decades).
fn decile(table: &[f32; 11], u: f32) -> f32 {
    let x = (u.clamp(0.0, 1.0) * 10.0).min(9.999_999);
    let (i, f) = (x as usize, x.fract());
    let (a, b) = (table[i].max(1e-6), table[i + 1].max(1e-6));
    a * (b / a).powf(f)
}

/// `n` capture-like splats on three nested spheres around the origin (radii 0.6, 0.8, 1.0),
/// seeded: opacities and shapes drawn from a real capture's deciles, sizes relative to the
/// spheres' extent as that capture's are to its own, scaled with the count so that their
/// overdraw seen from [`framing_camera`] is the capture's, SH degree 3.
pub fn generated_splats(n: usize) -> Splats {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut s = Splats::with_capacity(n, SplatColor::Sh { degree: 3 }, SplatFormat::Generated);
    for i in 0..n {
        let radius = [0.6, 0.8, 1.0][i % 3];
        let z = 2.0 * uniform() - 1.0;
        let phi = std::f32::consts::TAU * uniform();
        let r = (1.0 - z * z).max(0.0).sqrt();
        s.means
            .push(Vec3::new(r * phi.cos(), r * phi.sin(), z) * radius);
    }
    // The extent framing_camera frames: the largest interquartile range of the means.
    let extent = (0..3)
        .map(|axis| {
            let mut v: Vec<f32> = s.means.iter().map(|m| m[axis]).collect();
            let mut at = |q: f64| {
                let k = ((v.len().max(1) - 1) as f64 * q) as usize;
                *v.select_nth_unstable_by(k, f32::total_cmp).1
            };
            let hi = at(0.75);
            hi - at(0.25)
        })
        .fold(1e-3, f32::max);
    let size = extent * (CAPTURE_SPLATS / n.max(1) as f32).sqrt();
    for _ in 0..n {
        let largest = size * decile(&CAPTURE_LARGEST, uniform());
        let middle = largest * decile(&CAPTURE_MIDDLE, uniform());
        let smallest = largest * decile(&CAPTURE_SMALLEST, uniform());
        s.scales.push(Vec3::new(largest, middle, smallest));
        let axis = Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
        s.rotations.push(Quat::from_axis_angle(
            axis.normalize_or(Vec3::Z),
            6.0 * uniform(),
        ));
        s.opacities.push(decile(&CAPTURE_OPACITY, uniform()));
        for k in 0..16 {
            let spread = if k == 0 { 1.5 } else { 0.2 };
            s.coefficients
                .extend([0; 3].map(|_| spread * (uniform() - 0.5)));
        }
    }
    s.source.quantisation = "none: generated".into();
    s
}

/// Writes `splats` as a PLY into `dir` and reads it back: `(seconds to load, file bytes)`.
pub fn time_load(splats: &Splats, dir: &std::path::Path) -> Result<(f64, u64)> {
    let path = dir.join("nerfx-bench-splats.ply");
    splats.write_ply(&path)?;
    let bytes = std::fs::metadata(&path)
        .map_err(|e| crate::error::Error::io(&path, e))?
        .len();
    let start = Instant::now();
    let read = Splats::load(&path);
    let seconds = start.elapsed().as_secs_f64();
    let _ = std::fs::remove_file(&path);
    read?;
    Ok((seconds, bytes))
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
    let scene = Scene::default().with_splats(vec![SplatInstance::new(
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
        if let Some(layer) = splat_layer(&scene, &camera, camera.full_window(), &settings.outputs)?
        {
            let [p, b] = layer.timings();
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
