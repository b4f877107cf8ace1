//! instant-ngp's own marcher (`"sampler": "ngp"`) against an independent NumPy implementation
//! of instant-ngp's inference march (`tests/numpy/ingp_marcher_reference.py`) on generated
//! snapshots, with and without cone growth and outer cascades; how such an instance joins
//! other instances; the scene option; the step count on a fog.
//!
//! The NumPy checks need `python3` with `numpy` and `msgpack` and are cross-checks: they run with the
//! `cross-checks` feature (`scripts/test.sh`), and fail without the tools, saying so.

use std::path::{Path, PathBuf};

use crate::common_ingp::{
    camera, placed, scratch, write_blob_snapshot, Ball, Spec, BALLS_IN_THREE_CASCADES,
};
use glam::{DMat4, DVec3};
use nerfx_core::camera::Camera;
use nerfx_core::field::IngpField;
use nerfx_core::render::{
    march_ngp, ngp_ray, NgpRay, NgpSample, NgpScratch, NgpStats, NGP_MAX_STEPS,
};
use nerfx_core::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{Scene, SceneDesc};

/// Per ray: r, g, b, alpha, expected depth, steps taken, first and last composited sample.
fn numpy_march(snapshot: &Path, rays: &[NgpRay], max_steps: usize) -> Vec<[f64; 8]> {
    let rays: Vec<[f64; 8]> = rays
        .iter()
        .map(|r| {
            let (o, d) = (r.origin, r.dir);
            [o.x, o.y, o.z, d.x, d.y, d.z, r.near, r.far]
        })
        .collect();
    let values = crate::common_fields::numpy_rays(
        "ingp_marcher_reference.py",
        &["numpy", "msgpack"],
        snapshot,
        &rays,
        &[max_steps.to_string()],
    );
    values
        .chunks_exact(8)
        .map(|c| c.try_into().unwrap())
        .collect()
}

/// Every pixel's ray as the instance's marcher sees it (`None` where it misses the box).
fn march_rays(scene: &Scene, camera: &Camera) -> Vec<Option<NgpRay>> {
    let window = camera.full_window();
    let (w, h) = (window.width(), window.height());
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let ray = camera.ray(f64::from(x) + 0.5, f64::from(y) + 0.5)?;
            ngp_ray(scene.ngp().next().unwrap(), &ray).map(|(r, _)| r)
        })
        .collect()
}

/// The samples of `rays` marched by `field`, each ray for at most `max_steps` steps.
fn samples_of(
    field: &IngpField,
    rays: &[NgpRay],
    max_steps: usize,
) -> (Vec<Vec<NgpSample>>, NgpStats) {
    let mut out = vec![Vec::new(); rays.len()];
    let stats = march_ngp(field, rays, max_steps, &mut out, &mut NgpScratch::default());
    (out, stats)
}

/// Renders `snapshot` (written from `spec`) with the ngp sampler and checks it against the
/// NumPy march; returns the fraction of composited samples outside cascade 0.
fn check_against_numpy(name: &str, spec: &Spec, snapshot: &Path, camera: &Camera) -> f64 {
    let dir = snapshot.parent().unwrap();
    let scene = placed(dir, snapshot, Some("ngp")).unwrap();
    assert_eq!((scene.marched().count(), scene.ngp().count()), (0, 1));
    let mut settings = RenderSettings::new(Quality::Final.params(), Outputs::all());
    settings.color = ColorOutput::AsTrained;
    let planes = render(&scene, camera, camera.full_window(), &settings).unwrap();
    let rays = march_rays(&scene, camera);
    let hit: Vec<NgpRay> = rays.iter().flatten().copied().collect();
    let field = scene.ngp().next().unwrap().field();
    let (samples, stats) = samples_of(field, &hit, NGP_MAX_STEPS);
    // Where the samples lie, in instant-ngp coordinates.
    let (mut outer, mut all) = (0usize, 0usize);
    let (scale, offset) = (f64::from(spec.scale), spec.offset.map(f64::from));
    for (r, s) in hit.iter().zip(&samples) {
        for f in s {
            let p = r.origin + r.dir * f.t;
            let q = DVec3::new(p.y, p.z, p.x) * scale + DVec3::new(offset[1], offset[2], offset[0]);
            outer += usize::from((q - 0.5).abs().max_element() >= 0.5);
            all += 1;
        }
    }
    let want = numpy_march(snapshot, &hit, NGP_MAX_STEPS);
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
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
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
    let outer = check_against_numpy("aabb_scale 1", &spec, &path, &camera);
    assert_eq!(outer, 0.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn aabb_scale_4_with_cone_growth_and_three_cascades_renders_as_a_numpy_march() {
    let dir = scratch("ngp-numpy-4");
    let spec = Spec {
        aabb_scale: 4,
        n_cascades: 3,
        ..Spec::small_8x4()
    };
    let balls = BALLS_IN_THREE_CASCADES;
    let path = snapshot(&dir, &spec, &balls, 1.4);
    let camera = camera(
        48,
        36,
        40.0,
        DVec3::new(7.0, -5.0, 1.0),
        DVec3::new(-0.1, 0.9, -1.3),
    );
    let outer = check_against_numpy("aabb_scale 4", &spec, &path, &camera);
    assert!(outer > 0.1, "{outer} of the samples outside cascade 0");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The older layout: 16×2 levels, float parameters, CutlassMLP padding, an HDR (linear)
/// snapshot, a dataset scale 0.5 and offset (0.4, 0.6, 0.45), `aabb_scale` 4.
#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn an_hdr_snapshot_with_its_own_dataset_transform_renders_as_a_numpy_march() {
    let dir = scratch("ngp-numpy-hdr");
    let spec = Spec::old_16x2();
    let balls = [
        Ball {
            centre: [0.5, 0.5, 0.5],
            radius: 0.3,
        },
        Ball {
            centre: [0.5, 0.5, 1.3],
            radius: 0.3,
        },
    ];
    let path = snapshot(&dir, &spec, &balls, 1.4);
    let camera = camera(48, 36, 40.0, DVec3::new(2.5, -3.0, 1.5), DVec3::ZERO);
    let outer = check_against_numpy("HDR", &spec, &path, &camera);
    assert!(outer > 0.1, "{outer} of the samples outside cascade 0");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_sampler_is_chosen_per_instance_and_refused_where_it_does_not_apply() {
    let dir = scratch("ngp-option");
    let balls = [Ball {
        centre: [0.5, 0.5, 0.5],
        radius: 0.3,
    }];
    let path = snapshot(&dir, &Spec::small_8x4(), &balls, 1.0);
    let count = |s: &Scene| (s.marched().count(), s.ngp().count(), s.proposal().count());
    assert_eq!(count(&placed(&dir, &path, Some("ngp")).unwrap()), (0, 1, 0));
    assert_eq!(
        count(&placed(&dir, &path, Some("occupancy")).unwrap()),
        (1, 0, 0)
    );
    // The default: nerfx's marcher, from a scene file or the snapshot on its own.
    assert_eq!(count(&placed(&dir, &path, None).unwrap()), (1, 0, 0));
    let alone = SceneDesc::for_path(&path).unwrap().load().unwrap();
    let alone = alone.place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY));
    assert_eq!(count(&alone.unwrap()), (1, 0, 0));
    // nerfacto's sampler on a snapshot, instant-ngp's on a nerfacto run, any on splats.
    let e = placed(&dir, &path, Some("proposal"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("instances[0] ('blob').field.ingp.sampler") && e.contains("\"ngp\""),
        "{e}"
    );
    let refused = |json: &str| {
        SceneDesc::from_json_str(json, &dir.join("scene.json"))
            .err()
            .unwrap()
            .to_string()
    };
    let e = refused(
        r#"{"instances": [{"name": "run", "field": {"nerfacto": {"path": "run",
            "sampler": "ngp"}}}]}"#,
    );
    assert!(
        e.contains("field.nerfacto.sampler") && e.contains("instant-ngp snapshots"),
        "{e}"
    );
    let e = refused(
        r#"{"instances": [{"name": "scan", "field": {"splats": {"path": "scan.ply",
            "sampler": "ngp"}}}]}"#,
    );
    assert!(e.contains("sampler"), "{e}");
    let e = refused(
        r#"{"instances": [{"name": "blob", "field": {"ingp": {"path": "blob.ingp",
            "sampler": "nearest"}}}]}"#,
    );
    assert!(e.contains("nearest") && e.contains("ngp"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// An opaque white slab `y ∈ [y0, y1]`, `|x|, |z| ≤ half`, as an analytic instance. (The
/// marcher finds its face to a fraction of its base step, itself a fraction of the slab's
/// size: samples of another instance closer to the face than that may composite on either
/// side of it, so the slab is no larger than the view needs.)
fn slab(y0: f32, y1: f32, half: f32) -> nerfx_core::scene::Instance {
    use glam::Vec3;
    use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};
    let field = Analytic {
        primitives: vec![Primitive {
            shape: Shape::Box {
                min: Vec3::new(-half, y0, -half),
                max: Vec3::new(half, y1, half),
            },
            density: 1e4,
            color: ShColor::constant(Vec3::ONE),
        }],
    };
    let handle = nerfx_core::scene::FieldHandle::analytic(field);
    nerfx_core::scene::Instance::new("slab", handle, DMat4::IDENTITY, None).unwrap()
}

#[test]
fn an_ngp_marched_snapshot_occludes_and_is_occluded_by_other_instances() {
    let dir = scratch("ngp-joint");
    let balls = [Ball {
        centre: [0.5, 0.5, 0.5],
        radius: 0.35,
    }];
    let path = snapshot(&dir, &Spec::small_8x4(), &balls, 1.2);
    let (w, h) = (24u32, 16u32);
    let camera = camera(w, h, 40.0, DVec3::new(0.5, -3.0, 1.0), DVec3::ZERO);
    let mut settings = RenderSettings::new(Quality::Final.params(), Outputs::rgba());
    settings.color = ColorOutput::AsTrained;
    // The marcher's own bounded errors: the transmittance it stops at, and the weight whose
    // colour it may leave unshaded.
    let tolerance =
        f64::from(settings.march.min_transmittance + settings.march.color_skip_budget) + 1e-5;
    let alone = placed(&dir, &path, Some("ngp")).unwrap();
    let nerf = render(&alone, &camera, camera.full_window(), &settings).unwrap();
    let rays = march_rays(&alone, &camera);
    let hit: Vec<NgpRay> = rays.iter().flatten().copied().collect();
    let (samples, _) = samples_of(alone.ngp().next().unwrap().field(), &hit, NGP_MAX_STEPS);
    // An opaque white slab through the middle of the blob (y = 0 in the field's frame, the
    // world's here): the blob shows only in front of it.
    let mut front = alone.clone();
    front.push(slab(0.0, 0.1, 4.0));
    let got = render(&front, &camera, camera.full_window(), &settings).unwrap();
    // A slab far behind the blob: the blob over it.
    let mut behind = alone.clone();
    behind.push(slab(30.0, 40.0, 40.0));
    let over = render(&behind, &camera, camera.full_window(), &settings).unwrap();
    let (mut seen, mut hidden, mut worst, mut at) = (0.0f64, 0.0f64, 0.0f64, 0);
    let pixel = |planes: &nerfx_core::image::Planes, x: u32, y: u32| {
        let rgb = planes.rgb.as_ref().unwrap();
        [0, 1, 2].map(|c| f64::from(rgb[c].get(x, y)))
    };
    for (i, ray) in rays.iter().enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let fragments: &[NgpSample] = match ray {
            Some(_) => {
                at += 1;
                &samples[at - 1]
            }
            None => &[],
        };
        let world = camera.ray(f64::from(x) + 0.5, f64::from(y) + 0.5).unwrap();
        let entry = (0.0 - world.origin.y) / world.dir.y;
        // By hand: the blob's samples (with the early stop folded in) before the slab, then
        // the slab's white; and all of them alone.
        let composite = |until: f64| {
            let (mut rgb, mut t) = ([0.0f64; 3], 1.0f64);
            for f in fragments.iter().filter(|f| f.t < until) {
                let a = f64::from(f.alpha);
                for (acc, v) in rgb.iter_mut().zip(f.rgb) {
                    *acc += t * a * f64::from(v);
                }
                t *= 1.0 - a;
            }
            (rgb, t)
        };
        // The marcher places the slab's face to within a small fraction of its step; a
        // sample closer to the face than `FACE` may composite on either side of it (or
        // partly), so the front render must lie between the two cuts.
        const FACE: f64 = 1e-3;
        let (before, t) = composite(entry - FACE);
        let (before_late, t_late) = composite(entry + FACE);
        let (all, t_all) = composite(f64::INFINITY);
        let a = f64::from(nerf.alpha.as_ref().unwrap().get(x, y));
        seen += a;
        hidden += t;
        worst = worst.max((a - (1.0 - t_all)).abs());
        assert!((f64::from(got.alpha.as_ref().unwrap().get(x, y)) - 1.0).abs() < tolerance);
        assert!((f64::from(over.alpha.as_ref().unwrap().get(x, y)) - 1.0).abs() < tolerance);
        for c in 0..3 {
            let (lo, hi) = (before[c] + t, before_late[c] + t_late);
            let front = pixel(&got, x, y)[c];
            let e = [
                (pixel(&nerf, x, y)[c] - all[c]).abs(),
                (front - front.clamp(lo.min(hi), lo.max(hi))).abs(),
                (pixel(&over, x, y)[c] - (all[c] + (1.0 - a))).abs(),
            ];
            worst = worst.max(e[0].max(e[1]).max(e[2]));
        }
    }
    println!("joint renders within {worst:.1e} of the samples composited by hand");
    assert!(worst < tolerance, "joint renders off by {worst}");
    let pixels = f64::from(w * h);
    assert!(
        seen > 0.25 * pixels,
        "the blob shows too little to test ({seen})"
    );
    assert!(
        hidden > 0.25 * pixels,
        "the slab hides too little to test ({hidden})"
    );
    assert!(
        hidden < pixels - 0.1 * seen,
        "the blob in front of the slab shows too little ({hidden})"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A fog filling the unit cube (every cell occupied, σ = 1 per instant-ngp unit): a ray
/// along the cube's diagonal takes instant-ngp's 1024 finest steps (`NERF_STEPS` per √3) and
/// never reaches 99 %; a cap below that ends it early, counted, as in NumPy.
#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn a_fog_takes_1024_steps_along_the_diagonal_and_a_lower_cap_is_counted() {
    let dir = scratch("ngp-fog");
    let spec = Spec {
        aabb_scale: 1,
        n_cascades: 1,
        ..Spec::small_8x4()
    };
    let fog = [Ball {
        centre: [0.5, 0.5, 0.5],
        radius: 10.0,
    }];
    // Gain 0: the density network's σ output is exp(0) = 1.
    let path = snapshot(&dir, &spec, &fog, 0.0);
    let scene = placed(&dir, &path, Some("ngp")).unwrap();
    // In the field's frame the cube is 0.5 ± 0.5 of instant-ngp's unit over s = 0.33, its
    // diagonal still along (1, 1, 1).
    let corner = DVec3::splat(-0.5 / 0.33);
    let world = nerfx_core::camera::Ray {
        origin: corner - DVec3::splat(1.0),
        dir: DVec3::ONE.normalize(),
        z_per_t: 1.0,
        near: 0.0,
        far: f64::INFINITY,
    };
    let (ray, k) = ngp_ray(scene.ngp().next().unwrap(), &world).unwrap();
    assert!((k - 1.0).abs() < 1e-12);
    let field = scene.ngp().next().unwrap().field();
    let (full, stats) = samples_of(field, &[ray], NGP_MAX_STEPS);
    assert_eq!((stats.samples, stats.capped, stats.opaque), (1024, 0, 0));
    assert_eq!(full[0].len(), 1024);
    let alpha = |s: &[NgpSample]| 1.0 - s.iter().map(|f| 1.0 - f64::from(f.alpha)).product::<f64>();
    // σ·√3 of optical depth.
    assert!((alpha(&full[0]) - (1.0 - (-(3f64.sqrt())).exp())).abs() < 1e-3);
    let (capped, stats) = samples_of(field, &[ray], 1000);
    assert_eq!((stats.samples, stats.capped), (1000, 1));
    assert_eq!(capped[0][..], full[0][..1000]);
    let want = numpy_march(&path, &[ray], 1000);
    assert_eq!(want[0][5], 1000.0);
    assert!((alpha(&capped[0]) - want[0][3]).abs() < 1e-6, "{want:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
