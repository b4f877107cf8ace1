//! nerfacto's own sampler (`"sampler": "proposal"`) against an independent NumPy
//! implementation of nerfstudio's inference sampling and render
//! (`tests/numpy/nerfacto_proposal_reference.py`), on synthetic runs in both checkpoint
//! layouts: the main field's sample positions, and the rendered pixels; and how such an
//! instance joins other instances.
//!
//! The NumPy checks need `python3` with `numpy` and are cross-checks: they run with the
//! `cross-checks` feature (`scripts/test.sh`), and fail without the tools, saying so.

use std::path::Path;

use crate::common_nerfacto::{placed, scratch, write_run, Spec};
use glam::{DMat4, DVec3};
use nerfx_core::camera::{Camera, Perspective, Projection, Ray};
use nerfx_core::field::NerfactoField;
use nerfx_core::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::render::{sample_proposals, ProposalRay, ProposalSample, ProposalScratch};
use nerfx_core::scene::SceneDesc;

const W: u32 = 24;
const H: u32 = 16;

/// Per ray: the main samples' edges, then r, g, b, accumulation, expected depth.
fn numpy_render(run: &Path, rays: &[ProposalRay], n_edges: usize) -> Vec<Vec<f64>> {
    let rays: Vec<[f64; 8]> = rays
        .iter()
        .map(|r| {
            let (o, d) = (r.origin, r.dir);
            [o.x, o.y, o.z, d.x, d.y, d.z, r.near, r.far]
        })
        .collect();
    let values = crate::common_fields::numpy_rays(
        "nerfacto_proposal_reference.py",
        &["numpy"],
        run,
        &rays,
        &[],
    );
    values
        .chunks_exact(n_edges + 5)
        .map(<[f64]>::to_vec)
        .collect()
}

fn camera() -> Camera {
    let p = Perspective::from_vertical_fov(W, H, 50.0).unwrap();
    let eye = DVec3::new(0.5, -3.0, 1.0);
    Camera::new(
        nerfx_core::demo::look_at(eye, DVec3::ZERO),
        Projection::Perspective(p),
    )
    .unwrap()
}

/// The camera's pixel rays as nerfstudio's sampler sees them (the field placed at the
/// identity): from the camera, 0 to the far plane.
fn sampler_rays(camera: &Camera, far: f64) -> Vec<ProposalRay> {
    (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .map(|(x, y)| {
            let r: Ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5).unwrap();
            ProposalRay {
                origin: r.origin,
                dir: r.dir,
                near: 0.0,
                far,
            }
        })
        .collect()
}

fn check_against_numpy(name: &str, spec: &Spec) {
    let dir = scratch(&format!("proposal-{name}"));
    let run = write_run(&dir, spec);
    let field = NerfactoField::load(&run).unwrap();
    let camera = camera();
    let rays = sampler_rays(&camera, f64::from(field.far_plane()));
    let mut pieces: Vec<ProposalSample> = Vec::new();
    let stats = sample_proposals(&field, &rays, &mut pieces, &mut ProposalScratch::default())
        .expect("the run has proposal networks");
    let n = pieces.len() / rays.len();
    assert_eq!(n, 48);
    assert!(stats.proposal_queries > 0 && stats.main_queries > 0);

    // The scene renders the same rays with the proposal sampler (the default).
    let scene_file = dir.join("scene.json");
    std::fs::write(
        &scene_file,
        r#"{"instances": [{"name": "run", "field": {"nerfacto": {"path": "run"}}}]}"#,
    )
    .unwrap();
    let scene = SceneDesc::read(&scene_file)
        .unwrap()
        .load()
        .unwrap()
        .place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY))
        .unwrap();
    assert_eq!((scene.marched().count(), scene.proposal().count()), (0, 1));
    let mut settings = RenderSettings::new(Quality::Final.params(), Outputs::all());
    settings.color = ColorOutput::AsTrained;
    let planes = render(&scene, &camera, camera.full_window(), &settings).unwrap();

    let want = numpy_render(&run, &rays, n + 1);
    // Sample positions: every edge of every ray.
    let mut worst_edge = 0.0f64;
    for (r, (got, want)) in pieces.chunks_exact(n).zip(&want).enumerate() {
        let edges = got.iter().map(|p| p.t0).chain([got[n - 1].t1]);
        for (j, (a, &b)) in edges.zip(&want[..=n]).enumerate() {
            let e = (a - b).abs() / b.abs().max(1e-3);
            assert!(
                e < 1e-5,
                "{name}: ray {r} edge {j}: {a} against NumPy's {b}"
            );
            worst_edge = worst_edge.max(e);
        }
    }
    // Pixels: premultiplied as-trained colour, accumulation, expected depth.
    let rgb = planes.rgb.as_ref().unwrap();
    let (alpha, depth) = (
        planes.alpha.as_ref().unwrap(),
        planes.depth_ray.as_ref().unwrap(),
    );
    let (mut sq, mut worst_alpha, mut worst_depth, mut mean_alpha) = (0.0, 0.0f64, 0.0f64, 0.0);
    let mut opaque = 0;
    for (i, row) in want.iter().enumerate() {
        let (x, y) = (i as u32 % W, i as u32 / W);
        let px = &row[n + 1..];
        for c in 0..3 {
            sq += (f64::from(rgb[c].get(x, y)) - px[c]).powi(2);
        }
        worst_alpha = worst_alpha.max((f64::from(alpha.get(x, y)) - px[3]).abs());
        mean_alpha += px[3] / want.len() as f64;
        if px[3] > 0.05 {
            opaque += 1;
            let e = (f64::from(depth.get(x, y)) - px[4]).abs() / px[4];
            worst_depth = worst_depth.max(e);
        }
    }
    let psnr = 10.0 * (3.0 * want.len() as f64 / sq.max(1e-30)).log10();
    println!(
        "{name}: edges within {worst_edge:.2e} relative; RGB PSNR {psnr:.1} dB; alpha within \
         {worst_alpha:.2e} (mean alpha {mean_alpha:.3}); depth within {worst_depth:.2e} relative \
         ({opaque} pixels of alpha > 0.05)"
    );
    assert!(psnr >= 60.0, "{name}: PSNR {psnr:.1} dB");
    assert!(worst_alpha < 1e-4, "{name}: alpha off by {worst_alpha}");
    assert!(worst_depth < 1e-4, "{name}: depth off by {worst_depth}");
    assert!(
        mean_alpha > 0.05 && opaque > want.len() / 4,
        "{name}: the fixture shows too little (mean alpha {mean_alpha}, {opaque} pixels)"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn tcnn_layout_samples_and_renders_as_numpy() {
    check_against_numpy("tcnn", &Spec::tcnn());
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn torch_layout_samples_and_renders_as_numpy() {
    check_against_numpy("torch", &Spec::torch());
}

/// An opaque slab `y ∈ [y0, y1]` (|x|, |z| ≤ 3000) as an analytic instance.
fn slab(y0: f32, y1: f32) -> nerfx_core::scene::Instance {
    use glam::Vec3;
    use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};
    let field = Analytic {
        primitives: vec![Primitive {
            shape: Shape::Box {
                min: Vec3::new(-3000.0, y0, -3000.0),
                max: Vec3::new(3000.0, y1, 3000.0),
            },
            density: 1e4,
            color: ShColor::constant(Vec3::ONE),
        }],
    };
    let handle = nerfx_core::scene::FieldHandle::analytic(field);
    nerfx_core::scene::Instance::new("slab", handle, DMat4::IDENTITY, None).unwrap()
}

#[test]
fn a_proposal_sampled_run_occludes_and_is_occluded_by_other_instances() {
    let dir = scratch("proposal-joint");
    let run = write_run(&dir, &Spec::tcnn());
    let camera = camera();
    let mut settings = RenderSettings::new(Quality::Final.params(), Outputs::rgba());
    settings.color = ColorOutput::AsTrained;
    // The marcher's own bounded errors: the transmittance it stops at, and the weight whose
    // colour it may leave unshaded.
    let tolerance =
        f64::from(settings.march.min_transmittance + settings.march.color_skip_budget) + 1e-5;
    let alone = placed(&dir, "proposal").unwrap();
    let nerf = render(&alone, &camera, camera.full_window(), &settings).unwrap();
    // The run's samples along each pixel's ray, to composite by hand.
    let field = NerfactoField::load(&run).unwrap();
    let rays = sampler_rays(&camera, f64::from(field.far_plane()));
    let mut pieces = Vec::new();
    sample_proposals(&field, &rays, &mut pieces, &mut ProposalScratch::default()).unwrap();
    let n = pieces.len() / rays.len();
    // An opaque white slab between the camera (y = −3) and the origin: the run shows only
    // in front of it (the run has density everywhere, near the camera too).
    let mut front = alone.clone();
    front.push(slab(-2.1, -2.0));
    let got = render(&front, &camera, camera.full_window(), &settings).unwrap();
    // A slab beyond the far plane (1000 from the camera): the run over it.
    let mut behind = alone.clone();
    behind.push(slab(1300.0, 1400.0));
    let over = render(&behind, &camera, camera.full_window(), &settings).unwrap();
    let (mut seen, mut hidden, mut worst) = (0.0f64, 0.0f64, 0.0f64);
    for (i, (ray, pieces)) in rays.iter().zip(pieces.chunks_exact(n)).enumerate() {
        let (x, y) = (i as u32 % W, i as u32 / W);
        let a = f64::from(nerf.alpha.as_ref().unwrap().get(x, y));
        seen += a;
        // In front: the run's samples before the slab, then the slab's white.
        let entry = (-2.1 - ray.origin.y) / ray.dir.y;
        let (mut rgb, mut t) = ([0.0f64; 3], 1.0f64);
        for p in pieces.iter().filter(|p| 0.5 * (p.t0 + p.t1) < entry) {
            let alpha = 1.0 - (-f64::from(p.sigma) * (p.t1 - p.t0)).exp();
            for (acc, v) in rgb.iter_mut().zip(p.rgb) {
                *acc += t * alpha * f64::from(v);
            }
            t *= 1.0 - alpha;
        }
        hidden += t;
        assert!((got.alpha.as_ref().unwrap().get(x, y) - 1.0).abs() < 1e-5);
        assert!((f64::from(over.alpha.as_ref().unwrap().get(x, y)) - 1.0).abs() < tolerance);
        for (c, before) in rgb.iter().enumerate() {
            let front_c = f64::from(got.rgb.as_ref().unwrap()[c].get(x, y));
            worst = worst.max((front_c - (before + t)).abs());
            let want = f64::from(nerf.rgb.as_ref().unwrap()[c].get(x, y)) + (1.0 - a);
            worst = worst.max((f64::from(over.rgb.as_ref().unwrap()[c].get(x, y)) - want).abs());
        }
    }
    assert!(worst < tolerance, "joint renders off by {worst}");
    let pixels = f64::from(W * H);
    assert!(seen > 0.5 * pixels, "the run shows too little to test");
    assert!(hidden > 0.5 * pixels, "the slab hides too little to test");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_occupancy_sampler_is_chosen_per_instance_and_runs_without_proposals_are_marched() {
    let dir = scratch("proposal-choice");
    write_run(&dir, &Spec::tcnn());
    let scene = placed(&dir, "occupancy").unwrap();
    assert_eq!((scene.marched().count(), scene.proposal().count()), (1, 0));
    let e = placed(&dir, "nearest").err().unwrap().to_string();
    assert!(e.contains("sampler") && e.contains("proposal"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
    let dir = scratch("proposal-none");
    let spec = Spec {
        proposal: None,
        ..Spec::tcnn()
    };
    write_run(&dir, &spec);
    let e = placed(&dir, "proposal").err().unwrap().to_string();
    assert!(
        e.contains("no proposal networks") && e.contains("occupancy"),
        "{e}"
    );
    assert_eq!(placed(&dir, "occupancy").unwrap().marched().count(), 1);
    // Without a sampler named, such a run is marched, from a scene file or on its own.
    let scene_file = dir.join("bare.json");
    std::fs::write(
        &scene_file,
        r#"{"instances": [{"name": "run", "field": {"nerfacto": {"path": "run"}}}]}"#,
    )
    .unwrap();
    for desc in [
        SceneDesc::read(&scene_file).unwrap(),
        SceneDesc::for_path(&dir.join("run")).unwrap(),
    ] {
        let scene = desc
            .load()
            .unwrap()
            .place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY))
            .unwrap();
        assert_eq!((scene.marched().count(), scene.proposal().count()), (1, 0));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
