//! nerfacto runs, printed: `cargo bench --bench nerfacto -- [NAME…]`.
//!
//! - `far_field_cost`: what the far field (the contracted shell) costs per frame.
//! - `proposal_render_1080p_final`: a 1080p Final render of a synthetic run of nerfacto's real
//!   architecture sampled by its proposal networks, and where the sampler's time goes.
//! - `nerfstudio_first_camera_final`: the real nerfstudio run's first camera at Final.
//! - `proposal_density`: a proposal network's fused kernel against its separate stages.
//! - `colour_by_runs`: the colour head by runs of samples sharing a direction against the
//!   whole network.
//!
//! Timing is printed, never asserted.

#[path = "../tests/common_fields/mod.rs"]
mod common_fields;
#[path = "../tests/common_nerfacto/mod.rs"]
mod common_nerfacto;

use std::time::Instant;

use common_nerfacto::{
    copied_nerfstudio_run, nerfstudio_fixture, placed, scene_of, scratch, write_run, Spec,
};
use glam::{DMat4, DVec3};
use nerfx_core::camera::read_shot;
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::field::{ColorHeadBench, NerfactoField, ProposalDensityBench};
use nerfx_core::render::{
    proposal_ray, sample_proposals, ProposalRay, ProposalScratch, ProposalStats,
};
use nerfx_core::render::{render_with_progress, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::shot_render::{render_frame, FrameRequest};
use nerfx_testkit::bench::targets::{bench_size, Measurement};
use rayon::prelude::*;

fn main() {
    nerfx_testkit::bench::targets::main(
        "nerfacto",
        &[
            Measurement::new(
                "far_field_cost",
                "480x270 frames of the far shell, a faint fog and a near-only run",
                far_field_cost,
            ),
            Measurement::new(
                "proposal_render_1080p_final",
                "a synthetic run of nerfacto's architecture through its proposal sampler",
                proposal_render_1080p_final,
            ),
            Measurement::new(
                "nerfstudio_first_camera_final",
                "the real nerfstudio run's first camera at Final, as trained",
                nerfstudio_first_camera_final,
            ),
            Measurement::new(
                "proposal_density",
                "a proposal network on 4096 seeded points, fused kernel against separate stages",
                proposal_density,
            ),
            Measurement::new(
                "colour_by_runs",
                "the colour head on 512 samples by runs of one direction against the whole network",
                colour_by_runs,
            ),
        ],
    );
}

/// What the far field costs: a 480×270 frame of the distant shell (seen from inside), of
/// faint density everywhere (Draft only: Final marches it to the far plane) and of a
/// near-only run (a dense core seen from outside; its misses now walk the empty shell), at
/// Draft and Final: milliseconds and density samples per pixel. A benchmark, not a test:
/// `cargo bench --bench nerfacto -- far_field_cost`. With
/// `NERFX_FAR_FIXTURES=<dir>` the runs and a `camera_path.json` per run are left there, for
/// timing `nerfx render <dir>/<name>/run <dir>/<name>/camera_path.json` against another
/// build; `NERFX_FAR_CASES=shell,core` picks cases.
fn far_field_cost() {
    let keep = std::env::var_os("NERFX_FAR_FIXTURES").map(std::path::PathBuf::from);
    let cases = [
        (
            "shell",
            Spec::shell(),
            DVec3::new(0.2, -0.1, 0.3),
            DVec3::new(1.0, 0.3, -0.5),
        ),
        (
            "constant",
            Spec::constant(0.01),
            DVec3::ZERO,
            DVec3::new(1.0, 0.3, -0.5),
        ),
        (
            "core",
            Spec::core(),
            DVec3::new(0.4, -3.0, 0.8),
            DVec3::new(-0.4, 3.0, -0.8),
        ),
    ];
    let only = std::env::var("NERFX_FAR_CASES").ok();
    for (name, spec, eye, look) in cases {
        if only
            .as_ref()
            .is_some_and(|o| !o.split(',').any(|c| c == name))
        {
            continue;
        }
        let dir = match &keep {
            Some(k) => k.join(name),
            None => scratch(&format!("cost-{name}")),
        };
        let run = write_run(&dir, &spec);
        let field = NerfactoField::load(&run).unwrap();
        let scene = scene_of(field, DMat4::IDENTITY);
        let (w, h) = (480u32, 270u32);
        let world_from_camera = nerfx_core::demo::look_at(eye, eye + look);
        let camera = Camera::new(
            world_from_camera,
            Projection::Perspective(Perspective::from_vertical_fov(w, h, 60.0).unwrap()),
        )
        .unwrap();
        let rows: Vec<String> = (0..4)
            .map(|r| {
                let row = world_from_camera.row(r);
                format!("{}, {}, {}, {}", row.x, row.y, row.z, row.w)
            })
            .collect();
        std::fs::write(
            dir.join("camera_path.json"),
            format!(
                "{{\"camera_type\": \"perspective\", \"render_height\": {h}, \"render_width\": \
                 {w}, \"seconds\": 1, \"camera_path\": [{{\"camera_to_world\": [{}], \"fov\": \
                 60, \"aspect\": 1}}]}}",
                rows.join(", ")
            ),
        )
        .unwrap();
        for quality in [Quality::Draft, Quality::Final] {
            if name == "constant" && quality == Quality::Final {
                continue;
            }
            let settings = RenderSettings::new(quality.params(), Outputs::rgba());
            let started = std::time::Instant::now();
            let (planes, stats) = nerfx_core::render::render_with_progress(
                &scene,
                &camera,
                camera.full_window(),
                &settings,
                &|_| {},
            )
            .unwrap();
            let ms = started.elapsed().as_secs_f64() * 1e3;
            let alpha = planes.alpha.unwrap();
            let mean =
                alpha.data.iter().map(|&a| f64::from(a)).sum::<f64>() / alpha.data.len() as f64;
            println!(
                "{name} {w}x{h} {quality:?}: {ms:.0} ms, {:.1} density samples per pixel, \
                 {:.1} colour samples per pixel, mean alpha {mean:.4}",
                stats.density_samples as f64 / stats.pixels as f64,
                stats.color_samples as f64 / stats.pixels as f64,
            );
        }
        if keep.is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}

/// A `Quality::Final` RGBA render of a synthetic run of nerfacto's real architecture (16
/// levels × 2, `2^19` rows, fp16; proposal networks of `2^17` rows, max res 128 and 256;
/// 256 + 96 proposal and 48 main samples) sampled by its proposal networks, 1920×1080 unless
/// `NERFX_BENCH_SIZE=WxH`: `cargo bench --bench nerfacto -- proposal_render_1080p_final`. Prints the frame time and the split between the proposal networks and
/// the main field (thread-seconds, from sampling every pixel's ray again in 256-ray
/// batches); timing is never asserted. Its seeded weights make a fog, not a surface: rays
/// rarely stop early, the worst case for the sampler.
fn proposal_render_1080p_final() {
    let (w, h) = bench_size((1920, 1080));
    let dir = scratch("proposal-bench");
    let spec = Spec {
        log2_table_size: 19,
        proposal: Some((17, [128, 256])),
        ..Spec::tcnn()
    };
    let t = Instant::now();
    write_run(&dir, &spec);
    let scene = placed(&dir, "proposal").unwrap();
    println!(
        "run written and loaded in {:.1} s",
        t.elapsed().as_secs_f64()
    );
    let p = Perspective::from_vertical_fov(w, h, 50.0).unwrap();
    let camera = Camera::new(
        nerfx_core::demo::look_at(DVec3::new(0.5, -3.0, 1.0), DVec3::ZERO),
        Projection::Perspective(p),
    )
    .unwrap();
    let settings = RenderSettings::new(Quality::Final.params(), Outputs::rgba());
    let t = Instant::now();
    let (planes, stats) =
        render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {}).unwrap();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let n = f64::from(w * h);
    let alpha = planes.alpha.as_ref().unwrap();
    let mean_alpha = alpha.data.iter().map(|&a| f64::from(a)).sum::<f64>() / n;
    println!(
        "{w}x{h} Final rgba, proposal sampler, {} rayon threads: {ms:.0} ms/frame; per pixel \
         {:.1} density and {:.1} colour queries; mean alpha {mean_alpha:.3}",
        rayon::current_num_threads(),
        stats.density_samples as f64 / n,
        stats.color_samples as f64 / n,
    );
    // The split, sampling every ray again outside the renderer.
    let instance = scene.proposal().next().unwrap();
    let field = instance.field();
    let rays: Vec<ProposalRay> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter_map(|(x, y)| camera.ray(f64::from(x) + 0.5, f64::from(y) + 0.5))
        .filter_map(|r| proposal_ray(instance, &r).map(|(s, _)| s))
        .collect();
    println!("{}", sampler_split(field, &rays, n));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The run's first camera rendered at Final (as trained), 1920×1080 unless
/// `NERFX_BENCH_SIZE=WxH` (the camera path at that size, as `nerfx render` of the path does):
/// `cargo bench --bench nerfacto -- nerfstudio_first_camera_final`. Prints the
/// frame time, the queries per pixel and the split between the proposal networks and the main
/// field (sampling every pixel's ray again); timing is never asserted.
fn nerfstudio_first_camera_final() {
    let (w, h) = bench_size((1920, 1080));
    let dir = scratch("nerfstudio-bench");
    let (_, scene) = copied_nerfstudio_run(&dir);
    let text = std::fs::read_to_string(nerfstudio_fixture().join("camera_path.json")).unwrap();
    let mut path: serde_json::Value = serde_json::from_str(&text).unwrap();
    path["render_width"] = w.into();
    path["render_height"] = h.into();
    let path_file = dir.join("camera_path.json");
    std::fs::write(&path_file, path.to_string()).unwrap();
    let shot = read_shot(&path_file, "NeRF").unwrap();
    let mut settings = RenderSettings::new(Quality::Final.params(), Outputs::rgba());
    settings.color = ColorOutput::AsTrained;
    let t = Instant::now();
    let request = FrameRequest::new(settings);
    let (_, _, stats) = render_frame(&scene, &shot, 0, &request, &|_| {}).unwrap();
    let n = f64::from(w * h);
    println!(
        "{w}x{h} Final rgba, first camera, {} rayon threads: {:.0} ms/frame; per pixel {:.1} \
         density and {:.1} colour queries",
        rayon::current_num_threads(),
        t.elapsed().as_secs_f64() * 1e3,
        stats.density_samples as f64 / n,
        stats.color_samples as f64 / n,
    );
    let at = shot.frame(0).unwrap();
    let camera = at.camera(&shot).unwrap();
    let placed = scene
        .place(at.world_from_scene(&shot).unwrap(), &|name| {
            at.object_matrix(name)
        })
        .unwrap();
    let instance = &placed.proposal().next().unwrap();
    let rays: Vec<ProposalRay> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter_map(|(x, y)| camera.ray(f64::from(x) + 0.5, f64::from(y) + 0.5))
        .filter_map(|r| proposal_ray(instance, &r).map(|(s, _)| s))
        .collect();
    println!("{}", sampler_split(instance.field(), &rays, n));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Samples `rays` (an image's, `pixels` of them) again outside the renderer, in 256-ray
/// batches on rayon's threads, and says where the sampler's time goes: thread-seconds in the
/// proposal networks and in the main field, and each one's queries per pixel.
fn sampler_split(field: &NerfactoField, rays: &[ProposalRay], pixels: f64) -> String {
    let t = std::time::Instant::now();
    let split = rays
        .par_chunks(256)
        .map_init(
            || (ProposalScratch::default(), Vec::new()),
            |(s, pieces), batch| {
                pieces.clear();
                sample_proposals(field, batch, pieces, s).unwrap()
            },
        )
        .reduce(ProposalStats::default, |mut a, b| {
            a += b;
            a
        });
    let (prop, main) = (
        split.proposal_time.as_secs_f64(),
        split.main_time.as_secs_f64(),
    );
    format!(
        "sampling alone: {:.0} ms wall; thread-seconds: proposal networks {prop:.2} s ({:.0} %, \
         {:.1} queries/pixel), main field {main:.2} s ({:.0} %, {:.1} density and {:.1} colour \
         queries/pixel)",
        t.elapsed().as_secs_f64() * 1e3,
        100.0 * prop / (prop + main),
        split.proposal_queries as f64 / pixels,
        100.0 * main / (prop + main),
        split.main_queries as f64 / pixels,
        split.color_queries as f64 / pixels,
    )
}

/// A proposal network of nerfstudio's default shape (torch layout, seeded) on 4096 seeded
/// points (a tile's round): the fused kernel against the separate stages, nanoseconds per
/// point, each twice.
fn proposal_density() {
    let mut bench = ProposalDensityBench::new();
    if !bench.has_fused_kernel() {
        println!("no AVX2 and FMA: both take the separate stages");
    }
    let points = ProposalDensityBench::POINTS;
    for (name, fused) in [("separate", false), ("fused", true)].repeat(2) {
        let t = Instant::now();
        for _ in 0..300 {
            bench.run(fused);
        }
        let ns = t.elapsed().as_secs_f64() * 1e9 / (300.0 * points as f64);
        println!("{name}: {ns:.1} ns per point");
    }
}

/// The torch colour head (seeded) on 512 samples in runs of 40 sharing a direction, by runs
/// against the whole network on the full inputs, nanoseconds per sample, six rounds.
fn colour_by_runs() {
    let mut bench = ColorHeadBench::new();
    let rounds = 2000;
    for round in 0..6 {
        let t = Instant::now();
        for _ in 0..rounds {
            bench.run_whole();
        }
        let a = t.elapsed().as_secs_f64();
        let t = Instant::now();
        for _ in 0..rounds {
            bench.run_by_runs();
        }
        let b = t.elapsed().as_secs_f64();
        let per = |s: f64| s * 1e9 / (rounds * ColorHeadBench::SAMPLES) as f64;
        println!(
            "round {round}: whole network {:.1} ns/sample, by runs {:.1} ns/sample ({:.2}x)",
            per(a),
            per(b),
            a / b
        );
    }
}
