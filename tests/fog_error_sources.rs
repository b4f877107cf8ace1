//! Where the benchmark fog's per-pixel error comes from (`nerfx bench --scene fog`: Preview
//! and Final miss their alpha targets). The fog at 480×270 on the benchmark's reference rows,
//! each preset against the fine reference with one dial changed at a time, printed as a
//! table: `cargo test --release --test fog_error_sources -- --ignored --nocapture`.
//!
//! A diagnostic, not a threshold on the presets: it asserts only that the reference is
//! converged enough to judge Final by (against a march twice as fine, it is off by well under
//! Final's target), which is what makes a preset's miss on these rows the marcher's own.

use nerfx_core::image::{Planes, Window};
use nerfx_core::render::{render_with_progress, MarchParams, Outputs, Quality, RenderSettings};
use nerfx_testkit::bench::scenes::{build, BenchScene};
use nerfx_testkit::bench::suite::{fine_params, finer_params, ROW_STRIDE};
use nerfx_testkit::bench::SceneKind;

const W: u32 = 480;
const H: u32 = 270;

/// The benchmark's reference rows rendered with `params`, and the density samples per pixel.
fn rows(b: &BenchScene, params: MarchParams, ys: &[u32]) -> (Vec<Planes>, f64) {
    let settings = RenderSettings::new(params, Outputs::all());
    let (mut samples, mut pixels) = (0, 0);
    let planes = ys
        .iter()
        .map(|&y| {
            let row = Window::new(0, y, W, y + 1);
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
fn worst(reference: &[Planes], test: &[Planes], ys: &[u32]) -> ((f64, u32, u32, f32), f64) {
    let (mut alpha, mut colour) = ((0.0, 0, 0, 0.0), 0.0f64);
    for ((r, t), &y) in reference.iter().zip(test).zip(ys) {
        let (ra, ta) = (r.alpha.as_ref().unwrap(), t.alpha.as_ref().unwrap());
        for x in 0..W as usize {
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

#[test]
#[ignore = "diagnostic"]
fn fog_error_by_dial() {
    let dir = std::env::temp_dir().join(format!("nerfx-fog-sources-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let built = build(SceneKind::Fog, W, H, &dir, None);
    std::fs::remove_dir_all(&dir).ok();
    let b = built.unwrap();
    let ys: Vec<u32> = (0..H.div_ceil(ROW_STRIDE))
        .map(|k| (k * ROW_STRIDE + ROW_STRIDE / 2).min(H - 1))
        .collect();
    let (fine, _) = rows(&b, fine_params(), &ys);
    let (finer, _) = rows(&b, finer_params(), &ys);
    let ((own_alpha, ..), own_colour) = worst(&finer, &fine, &ys);
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
            let (test, spp) = rows(&b, params, &ys);
            let ((e, x, y, a), colour) = worst(&fine, &test, &ys);
            println!(
                "| {} | {changed} | {e:.2e} | ({x}, {y}) | {a:.4} | {colour:.2e} | {spp:.1} |",
                q.name()
            );
        }
    }
}
