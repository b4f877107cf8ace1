//! instant-ngp's own marcher (`"sampler": "ngp"`) against an independent NumPy implementation
//! of instant-ngp's inference march (`tests/numpy/ingp_marcher_reference.py`) on generated
//! snapshots, with and without cone growth and outer cascades; how such an instance joins
//! other instances; the scene option; the step count on a fog.
//!
//! The NumPy check needs `python3` with `numpy` and `msgpack`; without them it fails with a
//! message saying so, unless `NERFX_SKIP_NUMPY=1` (then it prints a skip line).

mod common_fields;
#[allow(dead_code)] // the snapshot writers this test does not use
mod common_ingp;

use std::path::{Path, PathBuf};
use std::process::Command;

use common_ingp::{scratch, write_blob_snapshot, Ball, Spec};
use glam::{DMat4, DVec3};
use nerfx::camera::{Camera, Perspective, Projection};
use nerfx::field::{IngpField, NgpRay, NgpSample, NgpScratch, NGP_MAX_STEPS};
use nerfx::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx::scene::{Scene, SceneDesc};

/// The snapshot at `snapshot` (in `dir`) as the one instance of a scene, at the identity,
/// with `"sampler": sampler` when given.
fn placed(dir: &Path, snapshot: &Path, sampler: Option<&str>) -> nerfx::Result<Scene> {
    let scene_file = dir.join("scene.json");
    let sampler = sampler.map_or(String::new(), |s| format!(r#", "sampler": "{s}""#));
    std::fs::write(
        &scene_file,
        format!(
            r#"{{"instances": [{{"name": "blob", "field": {{"ingp": {{"path": "{}"{sampler}}}}}}}]}}"#,
            snapshot.file_name().unwrap().to_string_lossy()
        ),
    )
    .unwrap();
    SceneDesc::read(&scene_file)?
        .load()?
        .place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY))
}

/// Per ray: r, g, b, alpha, expected depth, steps taken, first and last composited sample.
fn numpy_march(snapshot: &Path, rays: &[NgpRay], max_steps: usize) -> Option<Vec<[f64; 8]>> {
    if std::env::var("NERFX_SKIP_NUMPY").as_deref() == Ok("1") {
        println!("skipped: NumPy cross-check (NERFX_SKIP_NUMPY=1)");
        return None;
    }
    let dir = snapshot.parent().unwrap();
    let (input, output) = (dir.join("rays.bin"), dir.join("numpy_out.bin"));
    let bytes: Vec<u8> = rays
        .iter()
        .flat_map(|r| {
            [
                r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z, r.near, r.far,
            ]
        })
        .flat_map(f64::to_le_bytes)
        .collect();
    std::fs::write(&input, bytes).unwrap();
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/numpy/ingp_marcher_reference.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(snapshot)
        .arg(&input)
        .arg(&output)
        .arg(max_steps.to_string())
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "the NumPy cross-check needs python3 with numpy and msgpack ({e}); \
                 NERFX_SKIP_NUMPY=1 skips it"
            )
        });
    assert!(
        out.status.success(),
        "the NumPy reference failed (it needs numpy and msgpack; NERFX_SKIP_NUMPY=1 skips \
         it):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let values: Vec<f64> = std::fs::read(&output)
        .unwrap()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect();
    Some(
        values
            .chunks_exact(8)
            .map(|c| c.try_into().unwrap())
            .collect(),
    )
}

fn camera(w: u32, h: u32, fov: f64, eye: DVec3, target: DVec3) -> Camera {
    let p = Perspective::from_vertical_fov(w, h, fov).unwrap();
    Camera::new(
        nerfx::demo::look_at(eye, target),
        Projection::Perspective(p),
    )
    .unwrap()
}

/// Every pixel's ray as the instance's marcher sees it (`None` where it misses the box).
fn march_rays(scene: &Scene, camera: &Camera) -> Vec<Option<NgpRay>> {
    let window = camera.full_window();
    let (w, h) = (window.width(), window.height());
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let ray = camera.ray(f64::from(x) + 0.5, f64::from(y) + 0.5)?;
            scene.ngp[0].march_ray(&ray).map(|(r, _)| r)
        })
        .collect()
}

/// The samples of `rays` marched by `field`, each ray for at most `max_steps` steps.
fn samples_of(
    field: &IngpField,
    rays: &[NgpRay],
    max_steps: usize,
) -> (Vec<Vec<NgpSample>>, nerfx::field::NgpStats) {
    let mut out = vec![Vec::new(); rays.len()];
    let stats = field.march_rays(rays, max_steps, &mut out, &mut NgpScratch::default());
    (out, stats)
}

/// Renders `snapshot` with the ngp sampler and checks it against the NumPy march; returns
/// the fraction of composited samples outside cascade 0.
fn check_against_numpy(name: &str, snapshot: &Path, camera: &Camera) -> f64 {
    let dir = snapshot.parent().unwrap();
    let scene = placed(dir, snapshot, Some("ngp")).unwrap();
    assert_eq!((scene.instances.len(), scene.ngp.len()), (0, 1));
    let mut settings = RenderSettings::new(Quality::Final.params(), Outputs::all());
    settings.color = ColorOutput::AsTrained;
    let planes = render(&scene, camera, camera.full_window(), &settings).unwrap();
    let rays = march_rays(&scene, camera);
    let hit: Vec<NgpRay> = rays.iter().flatten().copied().collect();
    let field = scene.ngp[0].field();
    let (samples, stats) = samples_of(field, &hit, NGP_MAX_STEPS);
    // Where the samples lie: instant-ngp coordinates from the snapshot's default transform.
    let (mut outer, mut all) = (0usize, 0usize);
    for (r, s) in hit.iter().zip(&samples) {
        for f in s {
            let p = r.origin + r.dir * f.t;
            let q = DVec3::new(p.y, p.z, p.x) * 0.33 + 0.5;
            outer += usize::from((q - 0.5).abs().max_element() >= 0.5);
            all += 1;
        }
    }
    let Some(want) = numpy_march(snapshot, &hit, NGP_MAX_STEPS) else {
        return outer as f64 / all.max(1) as f64;
    };
    let (rgb, alpha, depth) = (
        planes.rgb.as_ref().unwrap(),
        planes.alpha.as_ref().unwrap(),
        planes.depth_ray.as_ref().unwrap(),
    );
    let (mut sq, mut worst_alpha, mut worst_depth, mut worst_t) = (0.0, 0.0f64, 0.0f64, 0.0f64);
    let (mut opaque, mut partial, mut n) = (0, 0, 0);
    let mut at = 0;
    for (i, ray) in rays.iter().enumerate() {
        let w = camera.full_window().width();
        let (x, y) = (i as u32 % w, i as u32 / w);
        let px = match ray {
            Some(_) => {
                at += 1;
                want[at - 1]
            }
            None => [0.0; 8],
        };
        n += 1;
        for c in 0..3 {
            sq += (f64::from(rgb[c].get(x, y)) - px[c]).powi(2);
        }
        worst_alpha = worst_alpha.max((f64::from(alpha.get(x, y)) - px[3]).abs());
        opaque += usize::from(px[3] == 1.0);
        partial += usize::from(px[3] > 0.05 && px[3] < 0.99);
        if px[3] > 0.05 {
            // The renormalised weights put the last (1 − A) ≤ 1 % at the last sample in
            // nerfx, spread over all samples in NumPy: at most 1 % of the span apart.
            let bound = 0.01 * (px[7] - px[6]) + 1e-5 * px[4];
            let e = (f64::from(depth.get(x, y)) - px[4]).abs();
            assert!(
                e <= bound,
                "{name}: pixel ({x}, {y}) depth {} vs NumPy {} (bound {bound})",
                depth.get(x, y),
                px[4]
            );
            worst_depth = worst_depth.max(e / px[4]);
        }
        // The march's positions: the first and last composited samples.
        if let Some(s) = ray
            .and_then(|_| samples.get(at - 1))
            .filter(|s| !s.is_empty())
        {
            let last = s.iter().rposition(|f| f.alpha > 0.0).unwrap_or(s.len() - 1);
            for (got, want) in [(s[0].t, px[6]), (s[last].t, px[7])] {
                let e = (got - want).abs() / want.abs().max(1e-3);
                assert!(
                    e < 1e-9,
                    "{name}: pixel ({x}, {y}) sample at {got}, NumPy {want}"
                );
                worst_t = worst_t.max(e);
            }
        }
    }
    let psnr = 10.0 * (3.0 * n as f64 / sq.max(1e-30)).log10();
    println!(
        "{name}: {n} pixels ({opaque} stopped at 99 %, {partial} partly covered), {} samples \
         ({:.0} % outside cascade 0); RGB PSNR {psnr:.1} dB, alpha within {worst_alpha:.1e}, \
         depth within {worst_depth:.1e} relative, sample positions within {worst_t:.1e}",
        stats.samples,
        100.0 * outer as f64 / all.max(1) as f64,
    );
    assert!(psnr >= 60.0, "{name}: PSNR {psnr:.1} dB");
    assert!(worst_alpha < 1e-4, "{name}: alpha off by {worst_alpha}");
    // The fixture exercises the early stop and partial coverage.
    assert!(
        opaque >= 50 && partial >= 50,
        "{name}: {opaque} opaque and {partial} partial pixels of {n}"
    );
    assert_eq!(
        stats.opaque as usize, opaque,
        "{name}: rays stopped at 99 %"
    );
    outer as f64 / all.max(1) as f64
}

fn snapshot(dir: &Path, spec: &Spec, balls: &[Ball], gain: f32) -> PathBuf {
    write_blob_snapshot(dir, "blob", spec, balls, gain).0
}

#[test]
fn aabb_scale_1_renders_as_a_numpy_march() {
    let dir = scratch("ngp-numpy-1");
    let spec = Spec {
        aabb_scale: 1,
        n_cascades: 1,
        ..Spec::small_8x4()
    };
    let balls = [
        Ball {
            centre: [0.5, 0.5, 0.5],
            radius: 0.3,
        },
        Ball {
            centre: [0.68, 0.55, 0.42],
            radius: 0.15,
        },
    ];
    let path = snapshot(&dir, &spec, &balls, 1.6);
    let camera = camera(48, 36, 30.0, DVec3::new(2.0, -2.5, 0.9), DVec3::ZERO);
    let outer = check_against_numpy("aabb_scale 1", &path, &camera);
    assert_eq!(outer, 0.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn aabb_scale_4_with_cone_growth_and_three_cascades_renders_as_a_numpy_march() {
    let dir = scratch("ngp-numpy-4");
    let spec = Spec {
        aabb_scale: 4,
        n_cascades: 3,
        ..Spec::small_8x4()
    };
    // One ball in each cascade.
    let balls = [
        Ball {
            centre: [0.5, 0.5, 0.5],
            radius: 0.3,
        },
        Ball {
            centre: [1.4, 0.6, 0.5],
            radius: 0.35,
        },
        Ball {
            centre: [0.5, -0.9, 0.4],
            radius: 0.45,
        },
    ];
    let path = snapshot(&dir, &spec, &balls, 1.4);
    let camera = camera(
        48,
        36,
        40.0,
        DVec3::new(7.0, -5.0, 1.0),
        DVec3::new(-0.1, 0.9, -1.3),
    );
    let outer = check_against_numpy("aabb_scale 4", &path, &camera);
    assert!(outer > 0.1, "{outer} of the samples outside cascade 0");
    let _ = std::fs::remove_dir_all(&dir);
}
