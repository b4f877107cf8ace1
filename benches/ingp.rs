//! instant-ngp fields, printed: `cargo bench --bench ingp -- [NAME…]`.
//!
//! - `field_throughput`: samples per second of the hash grid and its networks.
//! - `render_1080p_final`, `render_final_accuracy`: a 1080p Final render of a surface-like
//!   snapshot (the benchmark suite's blob), and its accuracy at 160×90 against a naive march.
//! - `ngp_sampler_against_final`: instant-ngp's own marcher against nerfx's Final march.
//! - `networks_against_the_fma_peak`: what bounds a shaded sample: the networks' multiply-adds
//!   against the core's peak.
//!
//! Timing is printed, never asserted; the assertions that remain check the renders are sane.

#[path = "../tests/common_fields/mod.rs"]
mod common_fields;
#[path = "../tests/common_ingp/mod.rs"]
#[allow(dead_code)] // the writers these measurements do not use
mod common_ingp;

use std::sync::Arc;
use std::time::Instant;

use common_ingp::{
    camera, placed, scratch, write_blob_snapshot, write_snapshot, Spec, SplitMix64,
    BALLS_IN_THREE_CASCADES,
};
use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::field::{Field, IngpField, NetworksBench, TableStorage};
use nerfx_core::render::{render_naive, render_with_progress, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};
use nerfx_testkit::bench::field::process_cpu_seconds;
use nerfx_testkit::bench::snapshot::occupied_fraction;
use nerfx_testkit::bench::targets::{bench_size, Measurement};
use nerfx_testkit::reference::metrics::psnr;

fn main() {
    nerfx_testkit::bench::targets::main(
        "ingp",
        &[
            Measurement::new(
                "field_throughput",
                "hash-grid field samples per second: 8x4 and 16x2 levels, f16 and f32 tables",
                field_throughput,
            ),
            Measurement::new(
                "render_1080p_final",
                "a 1920x1080 Final RGBA render of a surface-like snapshot",
                render_1080p_final,
            ),
            Measurement::new(
                "render_final_accuracy",
                "that render's accuracy at 160x90 against a naive march at a quarter step",
                render_final_accuracy,
            ),
            Measurement::new(
                "ngp_sampler_against_final",
                "instant-ngp's own marcher against nerfx's Final march",
                ngp_sampler_against_final,
            ),
            Measurement::new(
                "networks_against_the_fma_peak",
                "the 8x4 field's networks on an in-cache batch against the core's FMA peak",
                networks_against_the_fma_peak,
            ),
        ],
    );
}

/// Seeded points inside the field's bounds and unit directions.
fn samples(field: &IngpField, n: usize, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let b = field.bounds();
    common_fields::samples_in_box(b.min, b.max, n, seed)
}

/// Samples along `n_rays` random chords of the bounds, 1024 per ray (as the marcher batches
/// them), each with its ray's direction.
fn along_rays(field: &IngpField, n_rays: usize, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let (ends, _) = samples(field, 2 * n_rays, seed);
    ends.chunks_exact(2)
        .flat_map(|e| {
            let d = (e[1] - e[0]).normalize_or(Vec3::X);
            (0..1024).map(move |k| (e[0].lerp(e[1], k as f32 / 1023.0), d))
        })
        .unzip()
}

/// Field throughput (2^19-entry tables, 8×4 and 16×2 levels, tables in f16 and in f32, one
/// and two threads, samples scattered or along rays; per CPU second where it can be read):
/// `cargo bench --bench ingp -- field_throughput`.
fn field_throughput() {
    let dir = scratch("bench");
    for (name, base) in [("8x4", Spec::small_8x4()), ("16x2", Spec::old_16x2())] {
        let spec = Spec {
            log2_table_size: 19,
            aabb_scale: 16,
            n_cascades: 5,
            ..base
        };
        let path = write_snapshot(&dir, name, &spec);
        for storage in [TableStorage::F16, TableStorage::F32] {
            let f = IngpField::load_with(&path, Some(storage)).unwrap();
            let scattered = samples(&f, 1 << 16, 3);
            let rays = along_rays(&f, 64, 8);
            for (what, (pts, dirs)) in [("scattered", &scattered), ("along rays", &rays)] {
                let mut sigma = vec![0.0; pts.len()];
                f.density(pts, &mut sigma);
                let occupied = sigma.iter().filter(|&&s| s > 0.0).count() as f64;
                for threads in [1, 2] {
                    let t = nerfx_testkit::bench::field::throughput(&f, pts, dirs, threads, 1.0)
                        .unwrap();
                    println!(
                        "{name} {storage:?} {what:10} ({:2.0}% occupied), {threads} thread(s): \
                         density {:5.2}, density + radiance as renders (features) {:5.2}, \
                         standalone density then radiance {:5.2} M samples per {} second; \
                         as renders {:5.2} M samples per wall second",
                        100.0 * occupied / pts.len() as f64,
                        t.density / 1e6,
                        t.shaded / 1e6,
                        t.density_radiance / 1e6,
                        if t.per_cpu_second { "CPU" } else { "wall" },
                        t.shaded_wall / 1e6
                    );
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The synthetic benchmark scene: a 8×4 fp16 2^19 snapshot whose occupied cells are three
/// overlapping balls and whose σ row is scaled so rays terminate inside them (instant-ngp
/// coordinates: the unit cube is cascade 0; s = 0.33, o = 0.5). Prints what it is.
fn blob_bench_scene(dir: &std::path::Path) -> Scene {
    // The benchmark suite's blob scene (`nerfx bench --scene blob`).
    let spec = Spec::dense_blob();
    let gain = spec.sigma_gain.unwrap_or(1.0);
    let path = write_snapshot(dir, "blob", &spec);
    let cascade0 = occupied_fraction(&spec);
    let field = IngpField::load(&path).unwrap();
    let fill = field
        .describe()
        .lines()
        .find(|l| l.contains("fill ratio"))
        .unwrap_or_default()
        .to_string();
    // σ (field units) at seeded points of the main ball; field p = ((q.z − o)/s, (q.x − o)/s,
    // (q.y − o)/s).
    let mut rng = SplitMix64::new(21);
    let inside: Vec<Vec3> = (0..4000)
        .filter_map(|_| {
            let u = rng.vec(-1.0, 1.0);
            (u.length() < 0.9).then(|| u * 0.25 / 0.33)
        })
        .collect();
    let mut sigma = vec![0.0; inside.len()];
    field.density(&inside, &mut sigma);
    sigma.sort_by(f32::total_cmp);
    let pct = |p: f64| sigma[((sigma.len() - 1) as f64 * p) as usize];
    let step = field.feature_size() / Quality::Final.params().steps_per_feature;
    println!(
        "snapshot: 8x4 fp16 2^19, density gain {gain}, cascade 0 occupied {:.2} %, {fill}",
        100.0 * cascade0
    );
    println!(
        "sigma inside (field units): p5 {:.3e}, p50 {:.3e}, p95 {:.3e}; Final base step {step:.3e} \
         (optical depth per step at p50 {:.3})",
        pct(0.05),
        pct(0.5),
        pct(0.95),
        pct(0.5) * step
    );
    assert!(pct(0.05) > 0.0, "the blob's interior must be occupied");

    let handle = FieldHandle::new(Arc::new(field));
    Scene::new(vec![
        Instance::new("blob", handle, DMat4::IDENTITY, None).unwrap()
    ])
}

/// The benchmark's camera at `w × h` (40° vertical field of view, looking at the blob).
fn blob_bench_camera(w: u32, h: u32) -> Camera {
    let p = Perspective::from_vertical_fov(w, h, 40.0).unwrap();
    let eye = DVec3::new(2.2, -1.6, 0.8);
    Camera::new(
        nerfx_core::demo::look_at(eye, DVec3::ZERO),
        Projection::Perspective(p),
    )
    .unwrap()
}

/// A 1920×1080 `Quality::Final` RGBA render of a surface-like snapshot (8×4 levels, fp16,
/// 2^19-entry tables; three overlapping balls occupied, σ's output row scaled so rays
/// terminate inside them): `cargo bench --bench ingp -- render_1080p_final`. Timing is printed,
/// never asserted.
fn render_1080p_final() {
    let dir = scratch("bench-render");
    let scene = blob_bench_scene(&dir);
    let (w, h) = (1920, 1080);
    let camera = blob_bench_camera(w, h);
    let settings = RenderSettings::new(Quality::Final.params(), Outputs::rgba());
    let run = || {
        let (t, cpu) = (Instant::now(), process_cpu_seconds());
        let out = render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {})
            .unwrap();
        let cpu = cpu.zip(process_cpu_seconds()).map(|(a, b)| b - a);
        (out, t.elapsed().as_secs_f64() * 1e3, cpu)
    };
    let (_, warm_ms, _) = run();
    let ((planes, stats), ms, cpu) = run();
    let alpha = planes.alpha.as_ref().unwrap();
    let rgb = planes.rgb.as_ref().unwrap();
    let n = (w * h) as usize;
    assert_eq!(stats.pixels, n as u64);
    let mut opaque = 0;
    for i in 0..n {
        let a = alpha.data[i];
        assert!((0.0..=1.0 + 1e-5).contains(&a), "alpha {a} at pixel {i}");
        for c in rgb {
            let v = c.data[i];
            // Sigmoid colours are in [0, 1]: premultiplied, at most alpha.
            assert!(
                v.is_finite() && v >= 0.0 && v <= a + 1e-4,
                "rgb {v}, alpha {a} at pixel {i}"
            );
        }
        opaque += usize::from(a > 0.5);
    }
    assert!(opaque > n / 20, "only {opaque} pixels opaque");
    println!(
        "1920x1080 Final rgba, {} rayon threads: {ms:.0} ms/frame (warm-up {warm_ms:.0} ms); \
         per pixel: {:.2} density, {:.2} colour samples; alpha > 0.5: {:.2} % of pixels",
        rayon::current_num_threads(),
        stats.density_samples as f64 / n as f64,
        stats.color_samples as f64 / n as f64,
        100.0 * opaque as f64 / n as f64
    );
    if let Some(cpu) = cpu {
        // On a shared machine the CPU time is the steadier figure.
        println!("CPU time (user + system, all threads): {cpu:.1} s/frame");
    }
    println!(
        "per opaque pixel: {:.1} density, {:.1} colour samples",
        stats.density_samples as f64 / opaque as f64,
        stats.color_samples as f64 / opaque as f64
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The accuracy of that render: the same scene and view at 160×90, `Quality::Final` against
/// `render_naive` at a quarter of Final's base step (no skipping, no early stop, no
/// refinement): PSNR of the premultiplied RGB (peak 1) and the largest alpha error, with
/// Final's samples per pixel. `cargo bench --bench ingp -- render_final_accuracy`. Printed,
/// never asserted.
fn render_final_accuracy() {
    let dir = scratch("bench-accuracy");
    let scene = blob_bench_scene(&dir);
    let (w, h) = (160, 90);
    let camera = blob_bench_camera(w, h);
    let final_params = Quality::Final.params();
    let field_step =
        scene.marched().next().unwrap().field().feature_size() / final_params.steps_per_feature;
    let settings = RenderSettings::new(final_params, Outputs::rgba());
    let (got, stats) =
        render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {}).unwrap();
    // The instance's frame is the world's (identity): field units are world units.
    let (want, _) = render_naive(
        &scene,
        &camera,
        camera.full_window(),
        field_step as f64 / 4.0,
        &Outputs::rgba(),
    )
    .unwrap();
    let n = (w * h) as usize;
    let (ga, wa) = (got.alpha.unwrap(), want.alpha.unwrap());
    let (gc, wc) = (got.rgb.unwrap(), want.rgb.unwrap());
    let mut sq = 0.0f64;
    for c in 0..3 {
        for i in 0..n {
            sq += f64::from(gc[c].data[i] - wc[c].data[i]).powi(2);
        }
    }
    let psnr = -10.0 * (sq / (3 * n) as f64).log10();
    let mut alpha_errs: Vec<f32> = (0..n).map(|i| (ga.data[i] - wa.data[i]).abs()).collect();
    alpha_errs.sort_by(f32::total_cmp);
    let alpha_err = alpha_errs[n - 1];
    let over = |e: f32| alpha_errs.iter().filter(|&&x| x > e).count();
    let mean_alpha = (0..n).map(|i| f64::from(wa.data[i])).sum::<f64>() / n as f64;
    println!(
        "{w}x{h} Final vs naive at step/4 (mean alpha {mean_alpha:.3}): PSNR {psnr:.1} dB, \
         max |alpha error| {alpha_err:.2e} (pixels over 1e-2: {}, over 1e-3: {}); Final per \
         pixel: {:.2} density, {:.2} colour samples",
        over(1e-2),
        over(1e-3),
        stats.density_samples as f64 / n as f64,
        stats.color_samples as f64 / n as f64
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// instant-ngp's marcher against nerfx's `Final` occupancy march on trained-like snapshots
/// (the current default architecture, 8 levels × 4 features, `2^19` rows, fp16;
/// `aabb_scale` 4 with three cascades, one blob in each): dense surfaces (gain 3, rays stop
/// at 99 %) and soft ones (gain 1.4), 320×180 unless `NERFX_BENCH_SIZE=WxH`:
/// `cargo bench --bench ingp -- ngp_sampler_against_final`. Each
/// sampler renders twice, in alternation; the faster of each is printed with the process
/// CPU time, the PSNR between the two (linear RGBA) and the queries per pixel. Timing is
/// never asserted.
fn ngp_sampler_against_final() {
    let (w, h) = bench_size((320, 180));
    let dir = scratch("ngp-bench");
    let spec = Spec {
        log2_table_size: 19,
        aabb_scale: 4,
        n_cascades: 3,
        ..Spec::small_8x4()
    };
    let balls = BALLS_IN_THREE_CASCADES;
    let camera = camera(
        w,
        h,
        40.0,
        DVec3::new(7.0, -5.0, 1.0),
        DVec3::new(-0.1, 0.9, -1.3),
    );
    let settings = RenderSettings::new(Quality::Final.params(), Outputs::rgba());
    for (name, gain) in [("dense", 3.0), ("soft", 1.4)] {
        let (path, _) = write_blob_snapshot(&dir, "blob", &spec, &balls, gain);
        let scenes = [
            ("ngp", placed(&dir, &path, Some("ngp")).unwrap()),
            ("final", placed(&dir, &path, Some("occupancy")).unwrap()),
        ];
        let mut best = [(f64::INFINITY, 0.0); 2];
        let mut planes = Vec::new();
        let mut queries = [(0.0, 0.0); 2];
        for round in 0..2 {
            for (k, (_, scene)) in scenes.iter().enumerate() {
                let (t, c) = (Instant::now(), process_cpu_seconds().unwrap_or(0.0));
                let (p, stats) =
                    render_with_progress(scene, &camera, camera.full_window(), &settings, &|_| {})
                        .unwrap();
                let wall = t.elapsed().as_secs_f64();
                let cpu = process_cpu_seconds().unwrap_or(0.0) - c;
                if wall < best[k].0 {
                    best[k] = (wall, cpu);
                }
                let n = f64::from(w * h);
                queries[k] = (
                    stats.density_samples as f64 / n,
                    stats.color_samples as f64 / n,
                );
                if round == 0 {
                    planes.push(p);
                }
            }
        }
        let alpha = |p: &nerfx_core::image::Planes| {
            p.alpha
                .as_ref()
                .unwrap()
                .data
                .iter()
                .map(|&a| f64::from(a))
                .sum::<f64>()
                / f64::from(w * h)
        };
        let max_alpha = planes[0]
            .alpha
            .as_ref()
            .unwrap()
            .data
            .iter()
            .zip(&planes[1].alpha.as_ref().unwrap().data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        println!(
            "{name} ({w}x{h}, {} rayon threads): ngp {:.2} s wall / {:.2} s CPU, {:.1} density \
             + {:.1} colour queries/pixel; Final {:.2} s wall / {:.2} s CPU, {:.1} + {:.1}; \
             PSNR between them {:.1} dB, max alpha difference {max_alpha:.3}, mean alpha \
             {:.3} / {:.3}",
            rayon::current_num_threads(),
            best[0].0,
            best[0].1,
            queries[0].0,
            queries[0].1,
            best[1].0,
            best[1].1,
            queries[1].0,
            queries[1].1,
            psnr(&planes[1], &planes[0]),
            alpha(&planes[0]),
            alpha(&planes[1]),
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Independent chains of 256-bit fused multiply-adds, `n` rounds of ten (more than the
/// two pipes' latency needs): the core's peak rate of `f32` multiply-adds.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma_chains(n: usize) -> f32 {
    use std::arch::x86_64::{_mm256_fmadd_ps, _mm256_set1_ps, _mm256_storeu_ps};
    let (a, b) = (_mm256_set1_ps(0.999_999), _mm256_set1_ps(1e-7));
    let mut acc = [_mm256_set1_ps(1.0); 10];
    for _ in 0..n {
        for x in &mut acc {
            *x = _mm256_fmadd_ps(*x, a, b);
        }
    }
    let mut lanes = [0.0f32; 8];
    let mut sum = 0.0;
    for x in acc {
        // SAFETY: `lanes` holds the eight values stored.
        unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), x) };
        sum += lanes.iter().sum::<f32>();
    }
    sum
}

/// Multiply-adds per nanosecond of a core's time of `work` (which does `macs` of them per
/// call), on `threads` threads at once calling it for about a second each: a core's rate
/// while the machine runs nothing else (each thread is timed by its own clock).
fn macs_per_cpu_ns(threads: usize, macs: f64, work: &(dyn Fn() -> f32 + Sync)) -> f64 {
    let (calls, seconds) = std::thread::scope(|scope| {
        let runs: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let t = std::time::Instant::now();
                    let (mut calls, mut sink) = (0u64, 0.0f32);
                    while t.elapsed().as_secs_f64() < 1.0 {
                        sink += work();
                        calls += 1;
                    }
                    std::hint::black_box(sink);
                    (calls, t.elapsed().as_secs_f64())
                })
            })
            .collect();
        runs.into_iter()
            .map(|r| r.join().unwrap_or((0, 0.0)))
            .fold((0u64, 0.0), |(c, s), (dc, ds)| (c + dc, s + ds))
    });
    calls as f64 * macs / seconds / 1e9
}

/// What bounds a shaded instant-ngp sample (8×4 grid): the networks' multiply-adds as the
/// kernel does them (the density network 32 → 64 → 16, the colour network's head 16 →
/// 64 → 64 → 3 once its direction part is split off, four outputs to a tile), timed on an
/// in-cache batch against the core's peak; the samples per second they alone allow,
/// whatever the encoding costs.
#[cfg(target_arch = "x86_64")]
fn networks_against_the_fma_peak() {
    if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
        println!("no AVX2 and FMA: nothing to measure");
        return;
    }
    let networks = NetworksBench::new();
    let per_sample = NetworksBench::MACS_PER_SAMPLE;
    let n = NetworksBench::BATCH;
    let rounds = 1 << 20;
    for threads in [1, 2] {
        // SAFETY: the CPU has AVX2 and FMA (checked above).
        let peak = macs_per_cpu_ns(threads, rounds as f64 * 80.0, &|| unsafe {
            fma_chains(rounds)
        });
        let shaded = macs_per_cpu_ns(threads, n as f64 * (per_sample[0] + per_sample[1]), &|| {
            networks.run()
        });
        let total = per_sample[0] + per_sample[1];
        println!(
            "{threads} thread(s): a core's peak {peak:.1} multiply-adds per CPU ns; the \
             networks {shaded:.1} ({:.0} % of it), {total} per shaded sample: at most \
             {:.2} M shaded samples per CPU second from the networks alone ({:.2} M at \
             the peak)",
            100.0 * shaded / peak,
            shaded * 1e3 / total,
            peak * 1e3 / total,
        );
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn networks_against_the_fma_peak() {
    println!("the peak is measured with AVX2 and FMA: nothing to measure on this CPU");
}
