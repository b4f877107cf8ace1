//! The marcher's speed and error per preset on two kinds of content, printed, never asserted:
//! the analytic demo (hard edges) against its exact reference, and a trained instant-ngp fog
//! (smooth density, no ray stops early) against a converged march of the same field.
//!
//! `cargo test --release --test march_speed -- --ignored --nocapture`, with
//! `NERFX_BENCH_SIZE=WxH` (default 1920x1080 for the demo, 240x135 for the fog) and
//! `NERFX_BENCH_QUALITY=draft,final` to choose presets. Both wall and CPU time are printed:
//! on a shared machine the CPU time is the steadier figure.

mod common_fields;
#[allow(dead_code)]
mod common_ingp;

use std::sync::Arc;
use std::time::Instant;

use common_ingp::{scratch, write_blob_snapshot, Ball, Spec, SplitMix64};
use glam::{DMat4, DVec3};
use half::f16;
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::field::IngpField;
use nerfx_core::image::Planes;
use nerfx_core::render::{render_with_progress, MarchParams, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};
use nerfx_testkit::reference::ErrorReport;

/// The presets `NERFX_BENCH_QUALITY` names (all by default).
fn presets() -> Vec<Quality> {
    let Ok(names) = std::env::var("NERFX_BENCH_QUALITY") else {
        return Quality::ALL.to_vec();
    };
    Quality::ALL
        .into_iter()
        .filter(|q| names.split(',').any(|n| n.trim() == q.name()))
        .collect()
}

/// One timed render (after an untimed one that builds the occupancy grids): planes,
/// samples per pixel (density, colour), budget-limited rays, wall ms, CPU s.
fn timed(
    scene: &Scene,
    camera: &Camera,
    params: MarchParams,
    outputs: Outputs,
) -> (Planes, [f64; 3], f64, Option<f64>) {
    let settings = RenderSettings::new(params, outputs);
    let run =
        || render_with_progress(scene, camera, camera.full_window(), &settings, &|_| {}).unwrap();
    run();
    let (t, cpu) = (Instant::now(), process_cpu_seconds());
    let (planes, stats) = run();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let cpu = cpu.zip(process_cpu_seconds()).map(|(a, b)| b - a);
    let n = stats.pixels.max(1) as f64;
    let per_px = [
        stats.density_samples as f64 / n,
        stats.color_samples as f64 / n,
        stats.budget_limited_rays as f64,
    ];
    (planes, per_px, ms, cpu)
}

/// The error report of `got` against `want`, and where alpha is off most: `(x, y, got, want)`.
fn errors(want: &Planes, got: &Planes) -> (ErrorReport, (u32, u32, f32, f32)) {
    let (a, b) = (got.alpha.as_ref().unwrap(), want.alpha.as_ref().unwrap());
    let worst = (0..a.data.len())
        .max_by(|&i, &j| {
            let e = |k: usize| (a.data[k] - b.data[k]).abs();
            e(i).total_cmp(&e(j))
        })
        .unwrap_or(0);
    let w = got.width as usize;
    let at = (
        (worst % w) as u32,
        (worst / w) as u32,
        a.data[worst],
        b.data[worst],
    );
    (ErrorReport::compare(want, got), at)
}

type Errors = (ErrorReport, (u32, u32, f32, f32));

fn line(name: &str, per_px: [f64; 3], ms: f64, cpu: Option<f64>, error: Option<&Errors>) {
    let cpu = cpu.map_or("?".into(), |c| format!("{c:.2}"));
    let error = error.map_or(String::new(), |(e, (x, y, got, want))| {
        format!(
            ", PSNR {:.2} dB, max alpha error {:.2e} at ({x}, {y}): {got} for {want}, \
             max depth error {:.2e} (rel.)",
            e.psnr, e.max_alpha_error, e.max_depth_rel_error
        )
    });
    println!(
        "{name}: {ms:.0} ms wall, {cpu} s CPU, {:.1} density + {:.1} colour samples/px, \
         {} rays at their budget{error}",
        per_px[0], per_px[1], per_px[2]
    );
}

/// The demo scene with every plane, each preset against the exact reference.
#[test]
#[ignore]
fn bench_demo() {
    let (w, h) = common_fields::bench_size((1920, 1080));
    let (scene, camera) = nerfx_core::demo::scene_and_camera(w, h).unwrap();
    let reference = std::env::var("NERFX_BENCH_NO_REFERENCE").is_err().then(|| {
        let t = Instant::now();
        let truth =
            nerfx_testkit::reference::render(&scene, &camera, camera.full_window()).unwrap();
        println!(
            "exact reference {w}x{h}: {:.0} ms",
            t.elapsed().as_secs_f64() * 1e3
        );
        truth
    });
    println!(
        "{} rayon threads, load {}",
        rayon::current_num_threads(),
        load()
    );
    for q in presets() {
        let (planes, per_px, ms, cpu) = timed(&scene, &camera, q.params(), Outputs::all());
        let error = reference.as_ref().map(|truth| errors(truth, &planes));
        line(
            &format!("demo {w}x{h} {}", q.name()),
            per_px,
            ms,
            cpu,
            error.as_ref(),
        );
    }
}

/// A trained-looking fog: a 16×2-level fp16 instant-ngp snapshot with 2^19-entry tables whose
/// weights (network and grid) are all seeded uniform with standard deviation 0.05, occupied in
/// a ball of radius 0.35 in the middle of the unit cube; seen from distance 4 (40° vertical
/// field of view). Each preset against a march at Final's base step of one eighth of the
/// field's own step everywhere (no growth), no early stop and every colour evaluated
/// (`NERFX_BENCH_NO_REFERENCE` skips it).
#[test]
#[ignore]
fn bench_fog() {
    let (w, h) = common_fields::bench_size((240, 135));
    let dir = scratch("fog");
    let scene = fog_scene(&dir);
    let p = Perspective::from_vertical_fov(w, h, 40.0).unwrap();
    let eye = DVec3::new(3.2, -2.2, 1.1).normalize() * 4.0;
    let camera = Camera::new(
        nerfx_core::demo::look_at(eye, DVec3::ZERO),
        Projection::Perspective(p),
    )
    .unwrap();
    println!(
        "{} rayon threads, load {}",
        rayon::current_num_threads(),
        load()
    );
    let reference = std::env::var("NERFX_BENCH_NO_REFERENCE").is_err().then(|| {
        let fine = MarchParams {
            steps_per_feature: 8.0,
            max_step_factor: 1.0,
            cone: 0.0,
            min_transmittance: 1e-6,
            color_skip_budget: 0.0,
            ..Quality::Final.params()
        };
        let (planes, per_px, ms, cpu) = timed(&scene, &camera, fine, Outputs::rgba());
        line(&format!("fog {w}x{h} reference"), per_px, ms, cpu, None);
        planes
    });
    for q in presets() {
        let (planes, per_px, ms, cpu) = timed(&scene, &camera, q.params(), Outputs::rgba());
        let error = reference.as_ref().map(|truth| errors(truth, &planes));
        line(
            &format!("fog {w}x{h} {}", q.name()),
            per_px,
            ms,
            cpu,
            error.as_ref(),
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Writes the fog snapshot into `dir` and loads it as a one-instance scene (the field's frame
/// is the world's).
fn fog_scene(dir: &std::path::Path) -> Scene {
    let spec = Spec {
        n_levels: 16,
        n_features: 2,
        log2_table_size: 19,
        gzip: false,
        seed: 5,
        ..Spec::small_8x4()
    };
    let ball = Ball {
        centre: [0.5, 0.5, 0.5],
        radius: 0.35,
    };
    let (path, _) = write_blob_snapshot(dir, "fog", &spec, &[ball], 1.0);
    // Every parameter re-drawn uniform in ±0.05·√3 (standard deviation 0.05).
    let bytes = std::fs::read(&path).unwrap();
    let mut top = rmpv::decode::read_value(&mut &bytes[..]).unwrap();
    let mut rng = SplitMix64::new(17);
    let rmpv::Value::Map(entries) = &mut top else {
        panic!("top level is not a map")
    };
    for (k, v) in entries.iter_mut() {
        if k.as_str() != Some("snapshot") {
            continue;
        }
        let rmpv::Value::Map(snap) = v else {
            panic!("snapshot is not a map")
        };
        for (k, v) in snap.iter_mut() {
            if let (Some("params_binary"), rmpv::Value::Binary(b)) = (k.as_str(), v) {
                for c in b.chunks_exact_mut(2) {
                    let x = rng.range(-1.0, 1.0) * 0.05 * 3f32.sqrt();
                    c.copy_from_slice(&f16::from_f32(x).to_le_bytes());
                }
            }
        }
    }
    let mut out = Vec::new();
    rmpv::encode::write_value(&mut out, &top).unwrap();
    std::fs::write(&path, out).unwrap();
    let field = IngpField::load(&path).unwrap();
    let handle = FieldHandle::new(Arc::new(field));
    Scene::new(vec![
        Instance::new("fog", handle, DMat4::IDENTITY, None).unwrap()
    ])
}

/// The 1-minute load average.
fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

/// User + system CPU time of this process so far (Linux `/proc/self/stat`, in the kernel's
/// fixed 100 Hz `USER_HZ` ticks); `None` elsewhere.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which ends at the last ')'): utime and stime are
    // fields 14 and 15 of the line, 12 and 13 of this rest.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 / 100.0)
}
