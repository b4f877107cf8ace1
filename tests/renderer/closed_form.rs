//! Scenes of analytic fields integrated in closed form (`MarchParams::closed_form`) against
//! the exact reference (which shares no code with it) and against hand-worked integrals:
//! the demo at every preset, seeded random scenes, a constant sphere, Gaussians alone, side
//! by side and in a box, a faint Gaussian in a dense box, a density of 1e9, a box 1e-9
//! thick, a grazing ray, a scaled and cropped instance; and a scene with a field that is not
//! analytic, which is still marched.

use crate::common;

use std::f64::consts::PI;
use std::sync::Arc;

use common::*;
use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::Camera;
use nerfx_core::field::{Primitive, Shape};
use nerfx_core::image::Planes;
use nerfx_core::render::{
    render_with_progress, MarchParams, Outputs, Quality, RenderSettings, RenderStats,
};
use nerfx_core::scene::{CropBox, FieldHandle, Instance, Scene};
use nerfx_testkit::reference::ErrorReport;

/// Every plane of the camera's image with `params`, and what the render did.
fn render_stats(scene: &Scene, camera: &Camera, params: MarchParams) -> (Planes, RenderStats) {
    let settings = RenderSettings::new(params, Outputs::all());
    render_with_progress(scene, camera, camera.full_window(), &settings, &|_| {}).expect("render")
}

/// The largest relative error of the expected and median depth planes where the reference's
/// alpha is at least `min_alpha`.
fn depth_errors(got: &Planes, want: &Planes, min_alpha: f32) -> [f64; 2] {
    let alpha = &want.alpha.as_ref().expect("alpha").data;
    let worst = |g: &Option<nerfx_core::image::Plane>, w: &Option<nerfx_core::image::Plane>| {
        let (g, w) = (
            &g.as_ref().expect("plane").data,
            &w.as_ref().expect("plane").data,
        );
        (0..alpha.len())
            .filter(|&i| alpha[i] >= min_alpha)
            .map(|i| f64::from((g[i] - w[i]).abs() / w[i].abs().max(1e-6)))
            .fold(0.0, f64::max)
    };
    [
        worst(&got.depth_ray, &want.depth_ray),
        worst(&got.depth_median, &want.depth_median),
    ]
}

/// The demo at 480×270, every preset: alpha and colour within the preset's error target on
/// every pixel, expected depth within an eighth of it and median depth within it (relative)
/// where alpha is at least 0.1, and no ray at its node budget.
#[test]
fn the_demo_is_within_every_presets_target() {
    let (scene, camera) = nerfx_core::demo::scene_and_camera(480, 270).expect("demo");
    let want = reference_full(&scene, &camera);
    for quality in Quality::ALL {
        let params = quality.params();
        assert!(params.closed_form, "{quality:?} integrates in closed form");
        let (got, stats) = render_stats(&scene, &camera, params);
        let e = ErrorReport::compare(&want, &got);
        let [expected, median] = depth_errors(&got, &want, 0.1);
        let (marched, _) = render_stats(&scene, &camera, marched(params));
        let m = ErrorReport::compare(&want, &marched);
        println!(
            "demo 480x270 {}: max alpha error {:.2e}, colour {:.2e}, depth {:.2e}, median \
             depth {:.2e} (the metric's depth error {:.2e}, marched {:.2e}); {:.1} density + \
             {:.1} colour samples/px",
            quality.name(),
            e.max_alpha_error,
            e.max_color_error,
            expected,
            median,
            e.max_depth_rel_error,
            m.max_depth_rel_error,
            stats.density_samples as f64 / stats.pixels as f64,
            stats.color_samples as f64 / stats.pixels as f64,
        );
        let target = f64::from(params.error_target);
        assert!(e.max_alpha_error <= target, "{quality:?}: {e:?}");
        assert!(e.max_color_error <= target, "{quality:?}: {e:?}");
        assert!(expected <= target / 8.0 && median <= target, "{quality:?}");
        assert_eq!(stats.budget_limited_rays, 0);
    }
}

/// Seeded random scenes (spheres, boxes, Gaussians, scaled and rotated instances, crop
/// boxes, view-dependent colours) at Final against the reference.
#[test]
fn random_scenes_match_the_reference_at_final() {
    let mut rng = SplitMix64::new(0xC105ED);
    let params = Quality::Final.params();
    for seed in 0..12 {
        let scene = random_scene(&mut rng);
        let camera = random_camera(&mut rng, 48, 36);
        let want = reference_full(&scene, &camera);
        let (got, _) = render_stats(&scene, &camera, params);
        let e = ErrorReport::compare(&want, &got);
        assert!(
            e.max_alpha_error <= 1e-4 && e.max_color_error <= f64::from(params.error_target),
            "scene {seed}: {e:?}"
        );
        let [expected, median] = depth_errors(&got, &want, 0.1);
        assert!(
            expected <= 1.25e-4 && median <= 1e-4,
            "scene {seed}: {expected} {median}"
        );
    }
}

/// One pixel looking from `eye` at `target` (its ray is the camera's axis).
fn one_pixel(eye: DVec3, target: DVec3) -> Camera {
    camera_at(eye, target, 1, 1, 30.0)
}

/// The pixel of a 1×1 render at `quality`: `[r, g, b, alpha, depth_ray, depth_median]`.
fn pixel(scene: &Scene, camera: &Camera, quality: Quality) -> [f64; 6] {
    let (p, _) = render_stats(scene, camera, quality.params());
    let at = |plane: &Option<nerfx_core::image::Plane>| {
        f64::from(plane.as_ref().expect("plane").data[0])
    };
    let rgb = p.rgb.as_ref().expect("rgb");
    [
        f64::from(rgb[0].data[0]),
        f64::from(rgb[1].data[0]),
        f64::from(rgb[2].data[0]),
        at(&p.alpha),
        at(&p.depth_ray),
        at(&p.depth_median),
    ]
}

fn scene_of(primitives: Vec<Primitive>) -> Scene {
    Scene::new(vec![instance("hand", primitives, DMat4::IDENTITY, None)])
}

fn gaussian(center: [f32; 3], sigma: f32) -> Shape {
    Shape::Gaussian {
        center: Vec3::from(center),
        sigma,
        cutoff: 8.0,
    }
}

/// How far a median depth `want` may be off at `quality`: an eighth of the preset's error
/// target, relatively, as the expected depth (and no closer than `f32` holds it).
fn median_tolerance(quality: Quality, want: f64) -> f64 {
    (f64::from(quality.params().error_target) / 8.0 * want).max(1e-5)
}

fn close(got: f64, want: f64, tol: f64, what: &str) {
    assert!((got - want).abs() <= tol, "{what}: {got} vs {want}");
}

/// A unit sphere of density 2 through its centre from 5 away: alpha `1 − e^{−4}`, colour
/// alpha times its colour, expected depth `4 + ∫₀² s·2e^{−2s} ds / α`, median where
/// `1 − e^{−2s} = α/2`.
#[test]
fn a_constant_sphere_through_its_centre() {
    let scene = scene_of(vec![prim(sphere([0.0; 3], 1.0), 2.0, [0.5, 0.25, 1.0])]);
    let camera = one_pixel(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO);
    let alpha = 1.0 - (-4.0f64).exp();
    let moment = (1.0 - (-4.0f64).exp() * 5.0) / 2.0; // ∫₀² s·2e^{−2s} ds
    let median = -(1.0 - alpha / 2.0f64).ln() / 2.0;
    for q in Quality::ALL {
        let [r, g, b, a, depth, med] = pixel(&scene, &camera, q);
        close(a, alpha, 1e-6, "alpha");
        close(r, 0.5 * alpha, 1e-6, "r");
        close(g, 0.25 * alpha, 1e-6, "g");
        close(b, alpha, 1e-6, "b");
        close(depth, 4.0 + moment / alpha, 1e-5, "depth");
        close(med, 4.0 + median, 1e-5, "median");
    }
}

/// A Gaussian blob alone (peak ρ = 3 and 0.5, s = 0.4, cut at 8 s) through its centre: alpha
/// `1 − exp(−ρ s √(2π))` exactly, colour alpha times its colour, and by symmetry nothing
/// but the transmittance decides the depths: the median where the optical depth reaches
/// `ln(1/(1 − α/2))`, `ρ s √(π/2)(1 + erf(u/(√2 s)))` at `u` from the centre, and the
/// expected depth within an eighth of the target of a sum of `u·σ(u)·T(u)`.
#[test]
fn a_gaussian_alone() {
    for peak in [3.0, 0.5] {
        a_gaussian_alone_of(peak);
    }
}

fn a_gaussian_alone_of(peak: f64) {
    let scene = scene_of(vec![prim(
        gaussian([0.0; 3], 0.4),
        peak as f32,
        [1.0, 0.5, 0.25],
    )]);
    let camera = one_pixel(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO);
    let tau = peak * 0.4 * (2.0 * PI).sqrt();
    let alpha = 1.0 - (-tau).exp();
    // Median: bisection on the closed form, independent of the renderer's Newton steps.
    let depth_at = |u: f64| 0.5 * tau * (1.0 + erf(u / (2f64.sqrt() * 0.4)));
    let goal = -(1.0 - alpha / 2.0).ln();
    let (mut lo, mut hi) = (-3.2, 3.2);
    for _ in 0..100 {
        let m = 0.5 * (lo + hi);
        if depth_at(m) < goal {
            lo = m;
        } else {
            hi = m;
        }
    }
    // Expected depth: a midpoint sum of `u·σ(u)·T(u)` over the blob's support.
    let n = 20_000;
    let du = 6.4 / f64::from(n);
    let moment: f64 = (0..n)
        .map(|i| {
            let u = -3.2 + (f64::from(i) + 0.5) * du;
            u * peak * (-0.5 * (u / 0.4).powi(2)).exp() * (-depth_at(u)).exp()
        })
        .sum::<f64>()
        * du;
    let expected = 5.0 + moment / alpha;
    for q in Quality::ALL {
        let [r, g, b, a, depth, med] = pixel(&scene, &camera, q);
        close(a, alpha, 1e-6, "alpha");
        close(r, alpha, 1e-6, "r");
        close(g, 0.5 * alpha, 1e-6, "g");
        close(b, 0.25 * alpha, 1e-6, "b");
        let target = f64::from(q.params().error_target);
        close(depth, expected, target / 8.0 * expected, "depth");
        close(med, 5.0 + lo, median_tolerance(q, 5.0 + lo), "median");
    }
}

/// `erf` by its Maclaurin series (|x| ≤ 3 here), for the hand cases.
fn erf(x: f64) -> f64 {
    let (mut term, mut sum, mut n) = (x, x, 0.0);
    while term.abs() > 1e-17 * sum.abs().max(1e-300) {
        n += 1.0;
        term *= -x * x / n;
        sum += term / (2.0 * n + 1.0);
    }
    2.0 / PI.sqrt() * sum
}

/// Two overlapping Gaussians of different colours along the ray, and a Gaussian inside a
/// box: alpha in closed form, colour and depths against the reference.
#[test]
fn overlapping_gaussians_and_a_gaussian_in_a_box() {
    let camera = one_pixel(DVec3::new(0.0, 0.0, 6.0), DVec3::ZERO);
    let two = scene_of(vec![
        prim(gaussian([0.0, 0.0, 0.3], 0.3), 4.0, [1.0, 0.1, 0.1]),
        prim(gaussian([0.0, 0.0, -0.2], 0.5), 2.0, [0.1, 0.2, 1.0]),
    ]);
    let in_box = scene_of(vec![
        prim(gaussian([0.0; 3], 0.3), 5.0, [1.0, 0.8, 0.2]),
        prim(cube([-3.0; 3], [3.0; 3]), 0.2, [0.2, 0.3, 0.4]),
    ]);
    let root = (2.0 * PI).sqrt();
    for (scene, tau) in [
        (&two, 4.0 * 0.3 * root + 2.0 * 0.5 * root),
        (&in_box, 5.0 * 0.3 * root + 0.2 * 6.0),
    ] {
        let want = reference_full(scene, &camera);
        let at =
            |p: &Option<nerfx_core::image::Plane>| f64::from(p.as_ref().expect("plane").data[0]);
        for q in Quality::ALL {
            let target = f64::from(q.params().error_target);
            let [r, g, b, a, depth, med] = pixel(scene, &camera, q);
            close(a, 1.0 - (-tau).exp(), 1e-6, "alpha");
            let rgb = want.rgb.as_ref().expect("rgb");
            for (c, plane) in [r, g, b].into_iter().zip(rgb) {
                close(c, f64::from(plane.data[0]), target, "colour");
            }
            close(
                depth,
                at(&want.depth_ray),
                target / 8.0 * at(&want.depth_ray),
                "depth",
            );
            close(
                med,
                at(&want.depth_median),
                median_tolerance(q, at(&want.depth_median)),
                &format!("median {q:?} {tau}"),
            );
        }
    }
}

/// A faint Gaussian inside a dense box of another colour (as where the demo's haze meets its
/// ground): the box sets the light and the blob tints it, and the piece's total density
/// changes little, which bounds its colour split and depth in closed form. From a faint
/// blob to one as dense as the box, at every preset, against the reference: alpha in
/// closed form, the colour within a quarter of the target (what the closed form's bound is
/// held to) and the depth within an eighth of it.
#[test]
fn a_faint_gaussian_inside_a_dense_box() {
    let camera = one_pixel(DVec3::new(0.1, 0.05, 6.0), DVec3::new(0.1, 0.05, 0.0));
    for peak in [0.01, 0.1, 1.0, 8.0] {
        let scene = scene_of(vec![
            prim(
                Shape::Gaussian {
                    center: Vec3::ZERO,
                    sigma: 0.1,
                    cutoff: 2.0,
                },
                peak,
                [0.2, 0.4, 1.0],
            ),
            prim(
                cube([-1.0, -1.0, -0.25], [1.0, 1.0, 0.25]),
                8.0,
                [0.9, 0.6, 0.3],
            ),
        ]);
        let want = reference_full(&scene, &camera);
        let at =
            |p: &Option<nerfx_core::image::Plane>| f64::from(p.as_ref().expect("plane").data[0]);
        let rgb = want.rgb.as_ref().expect("rgb");
        for q in Quality::ALL {
            let target = f64::from(q.params().error_target);
            let [r, g, b, a, depth, _] = pixel(&scene, &camera, q);
            close(a, at(&want.alpha), 1e-6, "alpha");
            for (c, plane) in [r, g, b].into_iter().zip(rgb) {
                let what = format!("colour, peak {peak}, {q:?}");
                close(c, f64::from(plane.data[0]), 0.25 * target, &what);
            }
            let z = at(&want.depth_ray);
            close(
                depth,
                z,
                target / 8.0 * z,
                &format!("depth, peak {peak}, {q:?}"),
            );
        }
    }
}

/// A density of 1e9 (transmittance gone within 1e-8 of the surface), a box 1e-9 thick
/// (alpha `1 − e^{−k·1e-9}`), and a ray grazing a sphere (a chord of `2√(R² − b²)`).
#[test]
fn extreme_densities_thin_boxes_and_grazing_rays() {
    let camera = one_pixel(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO);
    let dense = scene_of(vec![
        prim(sphere([0.0; 3], 1.0), 1e9, [0.3, 0.6, 0.9]),
        prim(gaussian([0.0, 0.0, 0.8], 0.3), 1e9, [0.9, 0.1, 0.1]),
    ]);
    // The blob's far tail is already opaque, well before the sphere (at 4).
    let want = reference_full(&dense, &camera);
    let at = |p: &Option<nerfx_core::image::Plane>| f64::from(p.as_ref().expect("plane").data[0]);
    assert!(at(&want.depth_median) < 3.0);
    for q in Quality::ALL {
        let [r, g, b, a, depth, med] = pixel(&dense, &camera, q);
        close(a, 1.0, 1e-9, "alpha");
        let rgb = want.rgb.as_ref().expect("rgb");
        for (c, plane) in [r, g, b].into_iter().zip(rgb) {
            close(c, f64::from(plane.data[0]), 1e-6, "colour");
        }
        let target = f64::from(q.params().error_target);
        close(
            depth,
            at(&want.depth_ray),
            target / 8.0 * at(&want.depth_ray),
            "depth",
        );
        let want_median = at(&want.depth_median);
        close(med, want_median, median_tolerance(q, want_median), "median");
    }
    let thin = scene_of(vec![prim(
        cube([-1.0, -1.0, 0.0], [1.0, 1.0, 1e-9]),
        1e6,
        [1.0; 3],
    )]);
    let thickness = f64::from(1e-9f32);
    for q in Quality::ALL {
        let [r, _, _, a, depth, _] = pixel(&thin, &camera, q);
        let alpha = 1.0 - (-1e6 * thickness).exp();
        close(a, alpha, 1e-6 * alpha, "thin alpha");
        close(r, alpha, 1e-6 * alpha, "thin colour");
        close(depth, 5.0, 1e-6, "thin depth");
    }
    // Off the axis by 0.999 of the radius: a chord of 2√(1 − 0.999²) ≈ 0.0894.
    let grazed = scene_of(vec![prim(sphere([0.999, 0.0, 0.0], 1.0), 5.0, [1.0; 3])]);
    let chord = 2.0 * (1.0 - 0.999f64 * 0.999).sqrt();
    for q in Quality::ALL {
        let [_, _, _, a, _, _] = pixel(&grazed, &camera, q);
        close(a, 1.0 - (-5.0 * chord).exp(), 1e-4, "grazing alpha");
    }
}

/// An instance scaled by (2, 1, 0.5) and rotated, seen along its stretched axis: the optical
/// depth is the field's (the world chord is twice as long, the density per world unit half);
/// cropped, the image matches the reference's.
#[test]
fn a_scaled_rotated_and_cropped_instance() {
    let place = DMat4::from_translation(DVec3::new(0.0, 0.0, 1.0))
        * DMat4::from_rotation_y(0.5 * PI)
        * DMat4::from_scale(DVec3::new(2.0, 1.0, 0.5));
    let field = vec![prim(sphere([0.0; 3], 1.0), 1.5, [0.2, 0.9, 0.4])];
    let scene = Scene::new(vec![instance("s", field.clone(), place, None)]);
    // Field x maps to world −z: the camera on the world z axis looks along field x.
    let camera = one_pixel(DVec3::new(0.0, 0.0, 8.0), DVec3::new(0.0, 0.0, 1.0));
    for q in Quality::ALL {
        let [_, _, _, a, depth, _] = pixel(&scene, &camera, q);
        let alpha = 1.0 - (-3.0f64).exp();
        close(a, alpha, 1e-6, "alpha");
        // Entered at world z = 3, 5 from the eye; 4 world units of density 0.75.
        let moment = (1.0 - (-3.0f64).exp() * 4.0) / 0.75; // ∫₀⁴ s·0.75e^{−0.75s} ds
        close(depth, 5.0 + moment / alpha, 1e-5, "depth");
    }
    let crop = CropBox {
        center: [0.3, 0.0, 0.0],
        scale: [1.2; 3],
        rotation: [0.2, 0.1, 0.0],
    };
    let cropped = Scene::new(vec![instance("c", field, place, Some(crop))]);
    let view = camera_at(
        DVec3::new(3.0, 2.0, 6.0),
        DVec3::new(0.0, 0.0, 1.0),
        40,
        30,
        40.0,
    );
    let want = reference_full(&cropped, &view);
    let (got, _) = render_stats(&cropped, &view, Quality::Final.params());
    let e = ErrorReport::compare(&want, &got);
    assert!(
        e.max_alpha_error <= 1e-5 && e.max_color_error <= 1e-5,
        "{e:?}"
    );
}

/// A scene with a field that is not analytic (here an analytic one behind a plain handle,
/// as a trained field would be) is marched whatever the dial says: the same pixels and
/// statistics as with the dial off; with the handle analytic, the dial changes both.
#[test]
fn a_scene_with_a_field_that_is_not_analytic_is_marched() {
    let primitives = vec![
        prim(sphere([0.0; 3], 0.8), 4.0, [0.8, 0.4, 0.2]),
        prim(gaussian([0.5, 0.2, 0.0], 0.3), 6.0, [0.2, 0.4, 0.8]),
    ];
    let plain = FieldHandle::new(Arc::new(nerfx_core::field::Analytic {
        primitives: primitives.clone(),
    }));
    let analytic = instance("a", primitives, DMat4::IDENTITY, None);
    let opaque =
        Instance::new("b", plain, DMat4::from_translation(DVec3::X * 2.0), None).expect("instance");
    let camera = camera_at(
        DVec3::new(1.0, 0.5, 6.0),
        DVec3::new(1.0, 0.0, 0.0),
        32,
        24,
        50.0,
    );
    let on = Quality::Draft.params();
    let off = marched(on);
    let mixed = Scene::new(vec![analytic.clone(), opaque]);
    let (a, sa) = render_stats(&mixed, &camera, on);
    let (b, sb) = render_stats(&mixed, &camera, off);
    assert_close("mixed scene, dial on and off", &a, &b, Tol::EXACT);
    assert_eq!(sa, sb);
    let alone = Scene::new(vec![analytic]);
    let (c, sc) = render_stats(&alone, &camera, on);
    let (d, sd) = render_stats(&alone, &camera, off);
    assert_ne!(sc, sd, "the closed form counts its own samples");
    assert_ne!(c.alpha.map(|p| p.data), d.alpha.map(|p| p.data));
}
