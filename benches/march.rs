//! The marcher's speed and error per preset, printed: `cargo bench --bench march -- [NAME…]`.
//!
//! - `demo`, `fog`: speed and error per preset on two kinds of content, never asserted: the
//!   analytic demo (hard edges) against its exact reference, and a trained instant-ngp fog
//!   (smooth density, no ray stops early) against a converged march of the same field.
//!   `NERFX_BENCH_SIZE=WxH` (default 1920x1080 for the demo, 240x135 for the fog) and
//!   `NERFX_BENCH_QUALITY=draft,final` choose the size and the presets,
//!   `NERFX_BENCH_NO_REFERENCE=1` skips the reference. Both wall and CPU time are printed: on
//!   a shared machine the CPU time is the steadier figure.
//! - `fog_error_by_dial`: where the benchmark fog's per-pixel error comes from (`nerfx bench
//!   --scene fog`: Preview and Final miss their alpha targets). The fog at 480×270 on the
//!   benchmark's reference rows, each preset against the fine reference with one dial changed
//!   at a time, printed as a table. A diagnostic, not a threshold on the presets: it asserts
//!   only that the reference is converged enough to judge Final by (against a march twice as
//!   fine, it is off by well under Final's target), which is what makes a preset's miss on
//!   these rows the marcher's own.
//! - `blob_worst_pixels`: the worst pixels of each preset on the bench's dense blob at
//!   1920×1080, against the quadrature: a diagnostic for tracing misses.

#[path = "../tests/common_fields/mod.rs"]
mod common_fields;
#[path = "../tests/common_ingp/mod.rs"]
#[allow(dead_code)] // the snapshot writers these measurements do not use
mod common_ingp;

use std::sync::Arc;
use std::time::Instant;

use common_ingp::{scratch, write_blob_snapshot, Ball, Spec, SplitMix64};
use glam::{DMat4, DVec3};
use half::f16;
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::field::IngpField;
use nerfx_core::image::{Planes, Window};
use nerfx_core::render::{render_with_progress, MarchParams, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};
use nerfx_testkit::bench::field::process_cpu_seconds;
use nerfx_testkit::bench::scenes::{build, BenchScene, SceneKind};
use nerfx_testkit::bench::suite::{
    fine_params, finer_params, load_average, sampled_rows, QUADRATURE_ROW_STRIDE,
    QUADRATURE_TOLERANCE, ROW_STRIDE,
};
use nerfx_testkit::bench::targets::{bench_size, Measurement};
use nerfx_testkit::reference::ErrorReport;
use rayon::prelude::*;

fn main() {
    nerfx_testkit::bench::targets::main(
        "march",
        &[
            Measurement::new(
                "demo",
                "the analytic demo, every plane, each preset against the exact reference",
                demo,
            ),
            Measurement::new(
                "fog",
                "a trained instant-ngp fog, each preset against a converged march",
                fog,
            ),
            Measurement::new(
                "fog_error_by_dial",
                "the benchmark fog's error per preset with one dial changed at a time",
                fog_error_by_dial,
            ),
            Measurement::new(
                "blob_worst_pixels",
                "the dense blob's worst pixels per preset at 1920x1080 against the quadrature",
                blob_worst_pixels,
            ),
        ],
    );
}

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
fn demo() {
    let (w, h) = bench_size((1920, 1080));
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
fn fog() {
    let (w, h) = bench_size((240, 135));
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

const FOG_W: u32 = 480;
const FOG_H: u32 = 270;

/// The benchmark's reference rows rendered with `params`, and the density samples per pixel.
fn fog_rows(b: &BenchScene, params: MarchParams, ys: &[u32]) -> (Vec<Planes>, f64) {
    let settings = RenderSettings::new(params, Outputs::all());
    let (mut samples, mut pixels) = (0, 0);
    let planes = ys
        .iter()
        .map(|&y| {
            let row = Window::new(0, y, FOG_W, y + 1);
            let (p, s) = render_with_progress(&b.scene, &b.camera, row, &settings, &|_| {})
                .expect("a row renders");
            samples += s.density_samples;
            pixels += s.pixels;
            p
        })
        .collect();
    (planes, samples as f64 / pixels.max(1) as f64)
}

/// The largest alpha error `(error, x, y, reference alpha)` and the largest colour error.
fn fog_worst(reference: &[Planes], test: &[Planes], ys: &[u32]) -> ((f64, u32, u32, f32), f64) {
    let (mut alpha, mut colour) = ((0.0, 0, 0, 0.0), 0.0f64);
    for ((r, t), &y) in reference.iter().zip(test).zip(ys) {
        let (ra, ta) = (r.alpha.as_ref().unwrap(), t.alpha.as_ref().unwrap());
        for x in 0..FOG_W as usize {
            let e = (f64::from(ra.data[x]) - f64::from(ta.data[x])).abs();
            if e > alpha.0 {
                alpha = (e, x as u32, y, ra.data[x]);
            }
            for (rc, tc) in r.rgb.as_ref().unwrap().iter().zip(t.rgb.as_ref().unwrap()) {
                colour = colour.max((f64::from(rc.data[x]) - f64::from(tc.data[x])).abs());
            }
        }
    }
    (alpha, colour)
}

fn fog_error_by_dial() {
    let dir = std::env::temp_dir().join(format!("nerfx-fog-sources-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let built = build(SceneKind::Fog, FOG_W, FOG_H, &dir, None);
    std::fs::remove_dir_all(&dir).ok();
    let b = built.unwrap();
    let ys: Vec<u32> = (0..FOG_H.div_ceil(ROW_STRIDE))
        .map(|k| (k * ROW_STRIDE + ROW_STRIDE / 2).min(FOG_H - 1))
        .collect();
    let (fine, _) = fog_rows(&b, fine_params(), &ys);
    let (finer, _) = fog_rows(&b, finer_params(), &ys);
    let ((own_alpha, ..), own_colour) = fog_worst(&finer, &fine, &ys);
    println!(
        "reference against a march twice as fine: alpha {own_alpha:.2e}, colour {own_colour:.2e}"
    );
    let target = f64::from(Quality::Final.params().error_target);
    assert!(
        own_alpha < 0.25 * target && own_colour < 0.25 * target,
        "the reference is not converged enough to judge Final ({own_alpha:.2e}, {own_colour:.2e})"
    );
    println!("| preset | changed | max alpha error | at (x, y) | reference alpha | max colour error | density samples/px |");
    println!("|---|---|---:|---|---:|---:|---:|");
    for q in [Quality::Preview, Quality::Final] {
        let p = q.params();
        let variants = [
            ("nothing", p),
            (
                "max_step_factor 1",
                MarchParams {
                    max_step_factor: 1.0,
                    ..p
                },
            ),
            (
                "max_step_factor 4",
                MarchParams {
                    max_step_factor: 4.0,
                    ..p
                },
            ),
            ("cone 0", MarchParams { cone: 0.0, ..p }),
            (
                "cone 0, max_step_factor 8",
                MarchParams {
                    cone: 0.0,
                    max_step_factor: 8.0,
                    ..p
                },
            ),
            (
                "error_target / 100",
                MarchParams {
                    error_target: p.error_target / 100.0,
                    ..p
                },
            ),
            (
                "steps_per_feature × 4",
                MarchParams {
                    steps_per_feature: 4.0 * p.steps_per_feature,
                    ..p
                },
            ),
            (
                "refine_depth + 4",
                MarchParams {
                    refine_depth: p.refine_depth + 4,
                    ..p
                },
            ),
            (
                "occupancy_resolution 256",
                MarchParams {
                    occupancy_resolution: 256,
                    ..p
                },
            ),
            (
                "min_transmittance 1e-6",
                MarchParams {
                    min_transmittance: 1e-6,
                    ..p
                },
            ),
            (
                "color_skip_budget 0",
                MarchParams {
                    color_skip_budget: 0.0,
                    ..p
                },
            ),
        ];
        for (changed, params) in variants {
            let (test, spp) = fog_rows(&b, params, &ys);
            let ((e, x, y, a), colour) = fog_worst(&fine, &test, &ys);
            println!(
                "| {} | {changed} | {e:.2e} | ({x}, {y}) | {a:.4} | {colour:.2e} | {spp:.1} |",
                q.name()
            );
        }
    }
}

/// The worst pixels of each preset on the bench's dense blob at 1920×1080, over the
/// benchmark's reference rows against the quadrature: a diagnostic for tracing misses
/// (`cargo bench --bench march -- blob_worst_pixels`).
fn blob_worst_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let bench = build(SceneKind::Blob, 1920, 1080, dir.path(), None).expect("the blob");
    let ys = sampled_rows(1080, QUADRATURE_ROW_STRIDE);
    let row = |y: u32| Window::new(0, y, 1920, y + 1);
    let want: Vec<Vec<f32>> = ys
        .par_iter()
        .map(|&y| {
            let p = nerfx_testkit::reference::render_trained(
                &bench.scene,
                &bench.camera,
                row(y),
                QUADRATURE_TOLERANCE,
            )
            .expect("the quadrature");
            let mut v = p.alpha.expect("alpha").data;
            for c in p.rgb.expect("colour") {
                v.extend(c.data);
            }
            v
        })
        .collect();
    for quality in Quality::ALL {
        let params = MarchParams {
            closed_form: false,
            ..quality.params()
        };
        let target = f64::from(params.error_target);
        let settings = RenderSettings::new(params, Outputs::all());
        let mut worst = Vec::new();
        let (mut samples, mut pixels) = (0, 0);
        let (mut wa, mut wc) = (0.0f64, 0.0f64);
        for (&y, want) in ys.iter().zip(&want) {
            let (p, s) =
                render_with_progress(&bench.scene, &bench.camera, row(y), &settings, &|_| {})
                    .expect("a row");
            samples += s.density_samples;
            pixels += s.pixels;
            let got_a = &p.alpha.as_ref().unwrap().data;
            let got_c = p.rgb.as_ref().unwrap();
            for x in 0..1920usize {
                let ea = (f64::from(got_a[x]) - f64::from(want[x])).abs();
                let ec = (0..3)
                    .map(|c| {
                        (f64::from(got_c[c].data[x]) - f64::from(want[(1 + c) * 1920 + x])).abs()
                    })
                    .fold(0.0, f64::max);
                wa = wa.max(ea);
                wc = wc.max(ec);
                worst.push((ea.max(ec) / target, x, y, got_a[x], want[x], ea, ec));
            }
        }
        worst.sort_by(|a, b| b.0.total_cmp(&a.0));
        println!(
            "{quality:?}: alpha {wa:.2e} colour {wc:.2e}, {:.2} spp",
            samples as f64 / pixels as f64
        );
        for w in worst.iter().take(12) {
            println!(
                "  ({}, {}) {:.2}× target: alpha {:.4} want {:.4} (err {:.2e}), colour err {:.2e}",
                w.1, w.2, w.0, w.3, w.4, w.5, w.6
            );
        }
    }
}

/// The 1-minute load average.
fn load() -> String {
    load_average().map_or_else(|| "?".into(), |l| l[0].to_string())
}
