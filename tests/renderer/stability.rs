//! The marcher at the edges of its input range: far from the origin, at tiny and huge
//! scales, with extreme densities (σ up to 1e9, transmittance underflowing) and steps (down
//! to 1e-9), rays grazing surfaces and lying on occupancy cell planes, fields answering NaN
//! or infinity, cameras inside fields, invalid matrices and degenerate or absurd windows.
//! Every render must satisfy `assert_sane` (alpha in [0, 1], RGB finite and ≥ 0, depth
//! finite wherever alpha > 0) and agree with the exact reference where that is meaningful;
//! invalid input must be an error that says what is wrong, never a panic.

use crate::common;

use common::*;
use glam::{DMat4, DVec3};
use nerfx_core::camera::{Camera, Equirect, Perspective, Projection};
use nerfx_core::image::{Planes, Window};
use nerfx_core::render::{render, render_naive, MarchParams, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{CropBox, Instance, Scene};

const W: u32 = 48;
const H: u32 = 36;

/// `world_from_scene · N` for every instance (same fields, names and crops).
fn moved_scene(scene: &Scene, world_from_scene: DMat4) -> Scene {
    let instances: Vec<Instance> = scene
        .marched()
        .map(|inst| {
            Instance::new(
                inst.name.clone(),
                inst.handle().clone(),
                world_from_scene * inst.world_from_field(),
                inst.crop().copied(),
            )
            .expect("a moved instance")
        })
        .collect();
    Scene::new(instances)
}

/// The same camera moved by `world_from_scene` (its scale, if any, is dropped by
/// `Camera::new`, so a scaled world keeps the image).
fn moved_camera(camera: &Camera, world_from_scene: DMat4) -> Camera {
    Camera::new(
        world_from_scene * camera.world_from_camera(),
        camera.projection().clone(),
    )
    .expect("a moved camera")
}

/// `planes` with every depth multiplied by `s`.
fn scaled_depths(planes: &Planes, s: f32) -> Planes {
    let scale = |p: &Option<nerfx_core::image::Plane>| {
        p.clone().map(|mut p| {
            p.data.iter_mut().for_each(|d| *d *= s);
            p
        })
    };
    Planes {
        depth_z: scale(&planes.depth_z),
        depth_ray: scale(&planes.depth_ray),
        depth_median: scale(&planes.depth_median),
        ..planes.clone()
    }
}

fn seeded(seed: u64) -> (Scene, Camera) {
    let mut rng = SplitMix64::new(seed);
    let scene = random_scene(&mut rng);
    let camera = random_camera(&mut rng, W, H);
    (scene, camera)
}

/// Moving scene and camera together by 1e5 units changes nothing the marcher computes in
/// f32: each world ray is carried into the field's frame in f64 and its f32 positions are
/// taken relative to the entry point, so only the f64 rounding of the transforms (~1e5 ·
/// 2⁻⁵² ≈ 2e-11 units) differs — a sample shifted by that much can only change which side of
/// a density edge it falls on when it is within 2e-11 of it. The bound is the f32 rounding
/// of the outputs (1e-6 absolute, 1e-6 relative depth); the moved render also matches the
/// moved reference at Final's tolerance.
#[test]
fn far_from_the_origin_renders_as_at_the_origin() {
    let far = DMat4::from_translation(DVec3::new(1e5, -1e5, 1e5));
    for seed in 0..4 {
        let (scene, camera) = seeded(seed);
        let here = render_full(&scene, &camera, marched(Quality::Final.params()));
        let (scene_far, camera_far) = (moved_scene(&scene, far), moved_camera(&camera, far));
        let there = render_full(&scene_far, &camera_far, marched(Quality::Final.params()));
        let what = format!("random scene {seed} moved by 1e5");
        assert_sane(&what, &there);
        let f32_rounding = Tol {
            min_psnr: 120.0,
            min_alpha_psnr: 120.0,
            rgb: 1e-6,
            alpha: 1e-6,
            depth_rel: 1e-6,
        };
        assert_close(&what, &there, &here, f32_rounding);
        let want = reference_full(&scene_far, &camera_far);
        assert_close(
            &format!("{what}, against the reference"),
            &there,
            &want,
            FINAL,
        );
    }
}

/// Scaling the world (instances and camera position) by 1e-3 or 1e3 gives the same image
/// with every depth scaled: the marcher steps in field units and works with optical depths
/// `σ_world·δ_world = σ_field·δ_field`, which do not change. What does change is the f32
/// rounding of sample positions (`(t − t_near)·units_per_world` with an f32 factor, ~1e-7
/// field units): at the last bisection level (brackets of `δ/2^refine_depth` ≈ 1e-5 units) a
/// node that close to an edge changes sides in about one edge pixel in a hundred, which
/// moves that pixel by up to the edge's discretisation error (FINAL's derivation: ≤ 2e-3;
/// measured 2e-4). So: per pixel 1e-3 in alpha and RGB, Final's depth bound (measured
/// 1.1e-4), PSNR 90 dB.
#[test]
fn world_scale_only_scales_depth() {
    for seed in [1, 5] {
        let (scene, camera) = seeded(seed);
        let unit = render_full(&scene, &camera, marched(Quality::Final.params()));
        for s in [1e-3, 1e3] {
            let m = DMat4::from_scale(DVec3::splat(s));
            let (scene_s, camera_s) = (moved_scene(&scene, m), moved_camera(&camera, m));
            let got = render_full(&scene_s, &camera_s, marched(Quality::Final.params()));
            let what = format!("random scene {seed} scaled by {s}");
            assert_sane(&what, &got);
            let rounding_flips = Tol {
                min_psnr: 90.0,
                min_alpha_psnr: 90.0,
                rgb: 1e-3,
                alpha: 1e-3,
                depth_rel: FINAL.depth_rel,
            };
            assert_close(&what, &got, &scaled_depths(&unit, s as f32), rounding_flips);
            let want = reference_full(&scene_s, &camera_s);
            assert_close(
                &format!("{what}, against the reference"),
                &got,
                &want,
                FINAL,
            );
        }
    }
}

/// A camera at `eye` looking down −Z with +Y up (an unrotated Blender camera), so that the
/// rays of an odd-sized image's middle row and column lie exactly in the planes `y = eye.y`
/// and `x = eye.x`.
fn axis_camera(eye: DVec3, width: u32, height: u32, fov: f64) -> Camera {
    let p = Perspective::from_vertical_fov(width, height, fov).expect("a valid camera");
    Camera::new(DMat4::from_translation(eye), Projection::Perspective(p)).expect("a camera")
}

fn single(primitive: nerfx_core::field::Primitive) -> Scene {
    Scene::new(vec![instance(
        "one",
        vec![primitive],
        DMat4::IDENTITY,
        None,
    )])
}

/// σ = 1e8 per unit: every ray through the box is opaque to the bit (alpha exactly 1), and
/// its depth is the face's: the camera 4 units in front of the face `z = 1` sees camera Z =
/// 4 on every pixel that hits it. Bisection brackets the face to `δ/2^refine_depth`, far
/// below the bound of 1e-4 relative (4e-4 units). The edge pixels (partly covered) are only
/// required to be sane.
#[test]
fn a_huge_density_is_opaque_with_the_surface_depth() {
    let camera = axis_camera(DVec3::new(0.0, 0.0, 5.0), 33, 25, 40.0);
    let scene = single(prim(cube([-1.0; 3], [1.0; 3]), 1e8, [0.3, 0.6, 0.9]));
    for quality in Quality::ALL {
        let got = render_full(&scene, &camera, marched(quality.params()));
        let what = format!("σ = 1e8, {quality:?}");
        assert_sane(&what, &got);
        let want = reference_full(&scene, &camera);
        let (alpha, z) = (
            got.alpha.as_ref().expect("alpha"),
            got.depth_z.as_ref().expect("z"),
        );
        let want_alpha = want.alpha.as_ref().expect("alpha");
        let mut hits = 0;
        for i in 0..alpha.data.len() {
            if want_alpha.data[i] == 1.0 {
                hits += 1;
                assert_eq!(alpha.data[i], 1.0, "{what}: alpha at pixel {i}");
                let e = (z.data[i] - 4.0).abs() / 4.0;
                assert!(e <= 1e-4, "{what}: depth {} at pixel {i}", z.data[i]);
                let rgb = got.rgb.as_ref().expect("rgb");
                let c = [rgb[0].data[i], rgb[1].data[i], rgb[2].data[i]];
                for (k, want_c) in [0.3f32, 0.6, 0.9].iter().enumerate() {
                    assert!(
                        (c[k] - want_c).abs() < 1e-5,
                        "{what}: rgb {c:?} at pixel {i}"
                    );
                }
            }
        }
        assert!(
            hits > 100,
            "{what}: the box must fill the middle of the image"
        );
    }
    // A sphere: the same on its centre pixel, where the surface is at camera Z 4.
    let ball = single(prim(sphere([0.0; 3], 1.0), 1e8, [1.0, 1.0, 1.0]));
    let got = render_full(&ball, &camera, marched(Quality::Final.params()));
    assert_sane("σ = 1e8 sphere", &got);
    assert_eq!(got.alpha.as_ref().expect("alpha").get(16, 12), 1.0);
    let z = got.depth_z.as_ref().expect("z").get(16, 12);
    assert!((z - 4.0).abs() <= 4e-4, "σ = 1e8 sphere: centre depth {z}");
}

/// σ = 1e-8 per unit: alpha ≈ σ·chord ≤ 2e-8 must neither vanish nor turn into noise. The
/// marcher's composite is exact for tiny optical depths (`−expm1`); without refinement (the
/// density jump never exceeds the tolerance) each of the two edges costs at most `σ·δ/2` of
/// optical depth, δ the step: alpha error ≤ σ·δ, relative to the peak `2σ` (diameter 2) that
/// is `δ/2` — Final's step (feature/8 ≈ 0.0135) gives 0.7 %, bound 2 %; Preview 4×, bound
/// 5 %; Draft up to 32×, bound 25 %. Depth is compared where the chord is at least half the
/// diameter, within the same fractions. Colour is left out of such faint samples by design
/// (`color_skip_budget`), so RGB is only required to be below alpha's order (1e-7).
#[test]
fn a_tiny_density_keeps_its_tiny_alpha() {
    let camera = axis_camera(DVec3::new(0.0, 0.0, 5.0), 33, 25, 40.0);
    let scene = single(prim(sphere([0.0; 3], 1.0), 1e-8, [1.0, 1.0, 1.0]));
    let want = reference_full(&scene, &camera);
    let peak = want
        .alpha
        .as_ref()
        .expect("alpha")
        .data
        .iter()
        .fold(0.0f32, |m, &a| m.max(a));
    assert!((1.9e-8..=2e-8).contains(&peak), "peak alpha {peak}");
    for (quality, bound) in [
        (Quality::Final, 0.02),
        (Quality::Preview, 0.05),
        (Quality::Draft, 0.25),
    ] {
        let got = render_full(&scene, &camera, marched(quality.params()));
        let what = format!("σ = 1e-8, {quality:?}");
        assert_sane(&what, &got);
        let (a, ra) = (
            &got.alpha.as_ref().expect("alpha").data,
            &want.alpha.as_ref().expect("alpha").data,
        );
        let (d, rd) = (
            &got.depth_ray.as_ref().expect("depth").data,
            &want.depth_ray.as_ref().expect("depth").data,
        );
        let mut seen = 0;
        for i in 0..a.len() {
            let ea = (a[i] - ra[i]).abs() / peak;
            let ed = if ra[i] >= 0.5 * peak {
                seen += 1;
                (d[i] - rd[i]).abs() / rd[i]
            } else {
                0.0
            };
            {
                assert!(
                    ea <= bound && ed <= bound,
                    "{what}: pixel {i}: alpha {} vs {}, depth {} vs {}",
                    a[i],
                    ra[i],
                    d[i],
                    rd[i]
                );
            }
        }
        assert!(seen > 100, "{what}: the sphere must fill the middle");
        for plane in got.rgb.as_ref().expect("rgb") {
            assert!(plane.data.iter().all(|&c| c <= 1e-7), "{what}: rgb");
        }
    }
}

/// A step 12 500× finer than Final's (1e5 steps per feature) on a tiny window: millions of
/// samples per ray, whose f32 positions differ by a few ulps; the result must still be the
/// reference's.
///
/// Regression: RGB used to come out 0 here while alpha was right, because every node's
/// weight was below a per-sample colour threshold; the skipped weight is now a per-ray
/// budget (`color_skip_budget`).
#[test]
fn tiny_steps_still_converge() {
    let (scene, camera) = seeded(2);
    let tiny = MarchParams {
        steps_per_feature: 1e5,
        ..marched(Quality::Final.params())
    };
    let settings = RenderSettings::new(tiny, Outputs::all());
    // A 4 × 3 window around the most opaque pixel.
    let full = reference_full(&scene, &camera);
    let alpha = full.alpha.as_ref().expect("alpha");
    let best = (0..alpha.data.len())
        .max_by(|&i, &j| alpha.data[i].total_cmp(&alpha.data[j]))
        .expect("pixels");
    let (x, y) = ((best % W as usize) as u32, (best / W as usize) as u32);
    let window = Window::new(x.saturating_sub(2), y.saturating_sub(1), x + 2, y + 2);
    let got = render(&scene, &camera, window, &settings).expect("render");
    assert_sane("1e5 steps per feature", &got);
    let want = nerfx_testkit::reference::render(&scene, &camera, window).expect("reference");
    assert!(
        want.alpha
            .as_ref()
            .is_some_and(|a| a.data.iter().any(|&v| v > 0.1)),
        "the window must see the scene"
    );
    assert_close("1e5 steps per feature", &got, &want, FINAL);
}

/// Rays in the plane of a box face (the middle row of an odd-sized image of an unrotated
/// camera at y = 1 has `dir.y = 0` exactly, so its samples have y = 1 exactly, on the closed
/// face) and rays tangent to a sphere (the middle pixel touches the unit sphere at (0, 1,
/// 0)). The occupancy traversal and the slab tests see rays lying exactly on cell and box
/// planes; the result must be the reference's.
#[test]
fn grazing_rays_match_the_reference() {
    let camera = axis_camera(DVec3::new(0.0, 1.0, 5.0), 33, 25, 40.0);
    let cases = [
        (
            "along a box face",
            single(prim(cube([-1.0; 3], [1.0; 3]), 5.0, [0.9, 0.5, 0.2])),
        ),
        (
            "tangent to a sphere",
            single(prim(sphere([0.0; 3], 1.0), 5.0, [0.2, 0.5, 0.9])),
        ),
    ];
    // f32 limits what any f32 field can answer here: the support test `|p − c|² ≤ r²` of
    // the tangent ray's samples `(0, 1, z)` passes for |z| < 2.4e-4, where `1 + z²` rounds
    // to 1, so the f32 field itself holds a chord of ~4.9e-4 the exact one lacks: σ = 5 makes
    // that 2.4e-3 of optical depth on top of Final's discretisation error.
    let grazing = Tol {
        alpha: FINAL.alpha + 5.0 * 4.9e-4,
        rgb: FINAL.rgb + 5.0 * 4.9e-4,
        ..FINAL
    };
    for (what, scene) in cases {
        let ray = camera.ray(16.5, 12.5).expect("a ray");
        assert_eq!((ray.origin.y, ray.dir.y), (1.0, 0.0), "{what}: set-up");
        let want = reference_full(&scene, &camera);
        for quality in Quality::ALL {
            let got = render_full(&scene, &camera, marched(quality.params()));
            assert_sane(&format!("{what}, {quality:?}"), &got);
            if quality == Quality::Final {
                assert_close(what, &got, &want, grazing);
            }
        }
    }
}

/// Cameras inside a field start integrating at the camera (t = 0): inside a sphere, inside a
/// box, inside two overlapping instances, and a panorama inside a sphere, whose every ray
/// sees the same closed form `α = 1 − e^{−σr}`.
#[test]
fn cameras_inside_fields_match_the_reference() {
    let ball = instance(
        "ball",
        vec![prim(sphere([0.0; 3], 2.0), 1.0, [0.8, 0.3, 0.2])],
        DMat4::IDENTITY,
        None,
    );
    let block = instance(
        "block",
        vec![prim(cube([-2.0; 3], [2.0; 3]), 0.7, [0.2, 0.3, 0.8])],
        DMat4::from_rotation_z(0.4) * DMat4::from_scale(DVec3::new(1.0, 0.7, 1.2)),
        None,
    );
    let look = |eye: DVec3| camera_at(eye, eye + DVec3::new(1.0, 0.3, 0.2), 24, 18, 60.0);
    let cases = [
        (
            "inside a sphere",
            Scene::new(vec![ball.clone()]),
            look(DVec3::ZERO),
        ),
        (
            "inside a box",
            Scene::new(vec![block.clone()]),
            look(DVec3::new(0.5, 0.2, 0.1)),
        ),
        (
            "inside two overlapping instances",
            Scene::new(vec![ball, block]),
            look(DVec3::new(-0.3, 0.1, 0.2)),
        ),
    ];
    for (what, scene, camera) in &cases {
        let want = reference_full(scene, camera);
        let got = render_full(scene, camera, marched(Quality::Final.params()));
        assert_sane(what, &got);
        assert_close(what, &got, &want, FINAL);
    }
    // A panorama at the centre of a sphere of radius 2, σ = 1: α = 1 − e^{−2} on every pixel;
    // expected distance ∫₀² t e^{−t} dt / α = (1 − 3e^{−2}) / α.
    let (_, scene, _) = &cases[0];
    let pano = Camera::new(
        DMat4::IDENTITY,
        Projection::Equirect(Equirect::new(32, 16).expect("equirect")),
    )
    .expect("camera");
    let got = render_full(scene, &pano, marched(Quality::Final.params()));
    assert_sane("panorama inside a sphere", &got);
    let alpha = 1.0 - (-2.0f64).exp();
    let depth = (1.0 - 3.0 * (-2.0f64).exp()) / alpha;
    let n = 32 * 16;
    let want = Planes {
        width: 32,
        height: 16,
        rgb: Some(
            [0.8, 0.3, 0.2].map(|c| nerfx_core::image::Plane::filled(32, 16, (c * alpha) as f32)),
        ),
        alpha: Some(nerfx_core::image::Plane::filled(32, 16, alpha as f32)),
        depth_z: Some(nerfx_core::image::Plane::filled(32, 16, depth as f32)),
        depth_ray: Some(nerfx_core::image::Plane::filled(32, 16, depth as f32)),
        depth_median: None,
    };
    assert_eq!(want.alpha.as_ref().map(|a| a.data.len()), Some(n));
    assert_close("panorama inside a sphere", &got, &want, FINAL);
}

fn unit_ball() -> nerfx_core::scene::FieldHandle {
    nerfx_core::scene::FieldHandle::analytic(nerfx_core::field::Analytic {
        primitives: vec![prim(sphere([0.0; 3], 1.0), 1.0, [1.0; 3])],
    })
}

/// The message of an error, or a failure naming `what` when there was none.
fn message<T>(what: &str, r: nerfx_core::Result<T>) -> String {
    match r {
        Ok(_) => panic!("{what}: accepted"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn non_finite_matrices_and_crop_boxes_are_refused_with_a_reason() {
    let p = Perspective::from_vertical_fov(8, 8, 40.0).expect("perspective");
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut m = DMat4::IDENTITY;
        m.w_axis.y = bad;
        let e = message("camera", Camera::new(m, Projection::Perspective(p.clone())));
        assert!(
            e.contains("camera") && e.contains("NaN or infinity"),
            "camera with {bad}: {e}"
        );
        let mut m = DMat4::IDENTITY;
        m.x_axis.z = bad;
        let e = message("instance", Instance::new("thing", unit_ball(), m, None));
        assert!(
            e.contains("'thing'")
                && e.contains("world_from_field")
                && e.contains("NaN or infinity"),
            "instance with {bad}: {e}"
        );
        for field in 0..3 {
            let mut crop = CropBox {
                center: [0.0; 3],
                scale: [1.0; 3],
                rotation: [0.0; 3],
            };
            match field {
                0 => crop.center[1] = bad,
                1 => crop.scale[2] = bad,
                _ => crop.rotation[0] = bad,
            }
            let e = message(
                "crop",
                Instance::new("cropped", unit_ball(), DMat4::IDENTITY, Some(crop)),
            );
            assert!(
                e.contains("'cropped'") && e.contains("crop") && e.contains("NaN or infinity"),
                "crop with {bad} in part {field}: {e}"
            );
        }
    }
    // Not finite problems, but refused too, each with its own reason.
    let e = message(
        "projective camera",
        Camera::new(
            DMat4::from_cols_array(&[
                1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
            ]),
            Projection::Perspective(p.clone()),
        ),
    );
    assert!(e.contains("bottom row"), "{e}");
    let e = message(
        "mirrored camera",
        Camera::new(
            DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)),
            Projection::Perspective(p),
        ),
    );
    assert!(e.contains("mirrored"), "{e}");
    let e = message(
        "flat instance",
        Instance::new(
            "flat",
            unit_ball(),
            DMat4::from_scale(DVec3::new(1.0, 1.0, 0.0)),
            None,
        ),
    );
    assert!(e.contains("'flat'") && e.contains("singular"), "{e}");
    let e = message("fov", Perspective::from_vertical_fov(8, 8, f64::NAN));
    assert!(e.contains("fov"), "{e}");
}

/// Empty windows, windows outside the image and zero-sized tiles render nothing, without
/// panicking, in the marcher, the naive baseline and the reference alike.
#[test]
fn degenerate_windows_render_nothing() {
    let (scene, camera) = seeded(4);
    let settings = RenderSettings::new(marched(Quality::Final.params()), Outputs::all());
    for window in [
        Window::new(10, 10, 10, 20),
        Window::new(10, 10, 20, 10),
        Window::new(20, 10, 5, 30),
        Window::new(1000, 1000, 1010, 1010),
        Window::new(W, 0, W + 10, H),
        Window::new(u32::MAX - 1, u32::MAX - 1, u32::MAX, u32::MAX),
    ] {
        let what = format!("window {window:?}");
        let got = render(&scene, &camera, window, &settings).expect("an empty render");
        assert_eq!(got.width as usize * got.height as usize, 0, "{what}");
        assert_sane(&what, &got);
        let (naive, _) =
            render_naive(&scene, &camera, window, 0.01, &Outputs::all()).expect("naive");
        assert_eq!(naive.width as usize * naive.height as usize, 0, "{what}");
        let clamped = window.intersect(&camera.full_window());
        let reference =
            nerfx_testkit::reference::render(&scene, &camera, clamped).expect("reference");
        assert_eq!(reference.alpha.map(|a| a.data.len()), Some(0), "{what}");
    }
    // A tile size of 0 is taken as 1.
    let window = Window::new(20, 15, 27, 19);
    let zero = RenderSettings {
        tile_size: 0,
        ..settings
    };
    let one = RenderSettings {
        tile_size: 1,
        ..settings
    };
    let a = render(&scene, &camera, window, &zero).expect("tile 0");
    let b = render(&scene, &camera, window, &one).expect("tile 1");
    assert_close("tile size 0 vs 1", &a, &b, Tol::EXACT);
}

/// A 65536 × 65536 image (Blender's largest) as one window would need 4·2³² samples per
/// plane: refused with an error naming the size, before anything is allocated.
#[test]
fn an_absurd_window_is_refused() {
    let (scene, _) = seeded(0);
    let huge = camera_at(DVec3::new(6.0, 0.0, 1.0), DVec3::ZERO, 65536, 65536, 40.0);
    let settings = RenderSettings::new(marched(Quality::Draft.params()), Outputs::all());
    let e = message(
        "render",
        render(&scene, &huge, huge.full_window(), &settings),
    );
    assert!(e.contains("65536×65536"), "{e}");
    let e = message(
        "naive",
        render_naive(&scene, &huge, huge.full_window(), 0.01, &Outputs::all()),
    );
    assert!(e.contains("65536×65536"), "{e}");
    // A reasonable window of the same camera renders.
    let small = render(
        &scene,
        &huge,
        Window::new(32760, 32760, 32776, 32776),
        &settings,
    )
    .expect("a 16 × 16 window of a huge image");
    assert_sane("16 × 16 window of a 65536² image", &small);
}

/// σ = 1e9 per unit, with the early stop switched off (`min_transmittance` 0), so every ray
/// through the boxes marches on after its transmittance has underflowed to exactly 0 (one
/// step inside is `e^{−1e9·δ}`, far below f32's and f64's smallest numbers): the weights
/// behind must come out 0, not `0·∞` or `0/0`. A second box behind the first and a sphere
/// of the same density add more underflowed steps. Every preset must give alpha exactly 1,
/// the first face's depth (camera Z 4, within 1e-4 relative) and its colour, and agree with
/// the reference.
#[test]
fn a_density_of_1e9_underflows_transmittance_cleanly() {
    let camera = axis_camera(DVec3::new(0.0, 0.0, 5.0), 33, 25, 40.0);
    let scene = Scene::new(vec![instance(
        "stack",
        vec![
            prim(
                cube([-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]),
                1e9,
                [0.3, 0.6, 0.9],
            ),
            prim(
                cube([-1.0, -1.0, -1.0], [1.0, 1.0, -0.5]),
                1e9,
                [0.9, 0.1, 0.1],
            ),
            prim(sphere([0.0, 0.0, -2.0], 0.8), 1e9, [0.1, 0.9, 0.1]),
        ],
        DMat4::IDENTITY,
        None,
    )]);
    let want = reference_full(&scene, &camera);
    let want_alpha = want.alpha.as_ref().expect("alpha");
    for quality in Quality::ALL {
        let params = MarchParams {
            min_transmittance: 0.0,
            ..marched(quality.params())
        };
        let got = render_full(&scene, &camera, params);
        let what = format!("σ = 1e9, no early stop, {quality:?}");
        assert_sane(&what, &got);
        let (alpha, z, rgb) = (
            got.alpha.as_ref().expect("alpha"),
            got.depth_z.as_ref().expect("z"),
            got.rgb.as_ref().expect("rgb"),
        );
        let mut hits = 0;
        for i in (0..alpha.data.len()).filter(|&i| want_alpha.data[i] == 1.0) {
            hits += 1;
            assert_eq!(alpha.data[i], 1.0, "{what}: alpha at pixel {i}");
            let e = (z.data[i] - 4.0).abs() / 4.0;
            assert!(e <= 1e-4, "{what}: depth {} at pixel {i}", z.data[i]);
            for (k, c) in [0.3f32, 0.6, 0.9].iter().enumerate() {
                let v = rgb[k].data[i];
                assert!((v - c).abs() < 1e-5, "{what}: rgb[{k}] {v} at pixel {i}");
            }
        }
        assert!(hits > 100, "{what}: the box must fill the middle");
    }
}

/// A field a tenth of a micrometre across: a ball of radius 1e-7 field units, so Final's
/// step is ~1.4e-9 (Draft's ~1.1e-8); σ = 5e6 per unit gives it an optical depth of 1
/// across. Seen from 5e-7 away, every preset must be sane and Final
/// must agree with the reference at its usual tolerance: nothing in the marcher may assume a
/// step, a distance or a cell is larger than f32's resolution at 1.
#[test]
fn a_tenth_of_a_micrometre_field_marches_with_nanometre_steps() {
    let camera = axis_camera(DVec3::new(0.0, 0.0, 5e-7), 33, 25, 40.0);
    let scene = single(prim(sphere([0.0; 3], 1e-7), 5e6, [0.8, 0.4, 0.2]));
    let field = scene.marched().next().unwrap().field();
    let step = field.feature_size() / Quality::Final.params().steps_per_feature;
    assert!(step < 2e-9, "set-up: Final's step {step:e}");
    let want = reference_full(&scene, &camera);
    assert!(
        want.alpha
            .as_ref()
            .is_some_and(|a| a.data.iter().any(|&v| v > 0.5)),
        "set-up: the ball must be seen"
    );
    for quality in Quality::ALL {
        let got = render_full(&scene, &camera, marched(quality.params()));
        assert_sane(&format!("a 1e-7 ball, {quality:?}"), &got);
        if quality == Quality::Final {
            assert_close("a 1e-7 ball, Final", &got, &want, FINAL);
        }
    }
}

/// Rays lying exactly on the occupancy grid's cell planes: the field's bounds are the cube
/// ±1, so at every grid resolution the planes `x = 0` and `y = 0` are cell faces, and an
/// unrotated camera on the z axis puts the middle row and column of an odd-sized image in
/// them. A box with a corner at the origin is occupied on one side of those planes only,
/// so a traversal that rounds a ray into the wrong cell skips it (or the ball around it).
/// Every preset must be sane, Final must match the reference (with the f32 allowance of
/// [`grazing_rays_match_the_reference`] for rays in a face's plane).
#[test]
fn rays_along_occupancy_cell_planes_match_the_reference() {
    let camera = axis_camera(DVec3::new(0.0, 0.0, 5.0), 33, 25, 40.0);
    let scene = Scene::new(vec![instance(
        "corner",
        vec![
            prim(sphere([0.0; 3], 1.0), 0.5, [0.2, 0.4, 0.8]),
            prim(cube([0.0; 3], [0.5; 3]), 40.0, [0.9, 0.6, 0.1]),
        ],
        DMat4::IDENTITY,
        None,
    )]);
    let ray = camera.ray(16.5, 12.5).expect("a ray");
    assert_eq!((ray.dir.x, ray.dir.y), (0.0, 0.0), "set-up");
    let grazing = Tol {
        alpha: FINAL.alpha + 40.0 * 4.9e-4,
        rgb: FINAL.rgb + 40.0 * 4.9e-4,
        ..FINAL
    };
    let want = reference_full(&scene, &camera);
    for quality in Quality::ALL {
        let got = render_full(&scene, &camera, marched(quality.params()));
        assert_sane(&format!("on cell planes, {quality:?}"), &got);
        if quality == Quality::Final {
            assert_close("on cell planes, Final", &got, &want, grazing);
        }
    }
}

/// What a [`Broken`] field gets wrong.
#[derive(Clone, Copy, Debug)]
enum Fault {
    NanDensity,
    InfiniteDensity,
    NegativeDensity,
    NanRadiance,
    InfiniteRadiance,
}

/// A ball of radius 1 (σ = 2, grey) whose half `x < 0` answers with `fault`: a trained
/// field with corrupt weights or an overflowing network, as the marcher could meet it.
struct Broken(Fault);

impl nerfx_core::field::Field for Broken {
    fn bounds(&self) -> nerfx_core::field::Aabb {
        nerfx_core::field::Aabb::new(glam::Vec3::splat(-1.0), glam::Vec3::splat(1.0))
    }

    fn density(&self, points: &[glam::Vec3], sigma: &mut [f32]) {
        for (p, s) in points.iter().zip(sigma) {
            *s = match (p.length() <= 1.0, p.x < 0.0, self.0) {
                (false, ..) => 0.0,
                (true, true, Fault::NanDensity) => f32::NAN,
                (true, true, Fault::InfiniteDensity) => f32::INFINITY,
                (true, true, Fault::NegativeDensity) => -3.0,
                _ => 2.0,
            };
        }
    }

    fn radiance(&self, points: &[glam::Vec3], _dirs: &[glam::Vec3], rgb: &mut [glam::Vec3]) {
        for (p, c) in points.iter().zip(rgb) {
            *c = match (p.x < 0.0, self.0) {
                (true, Fault::NanRadiance) => glam::Vec3::NAN,
                (true, Fault::InfiniteRadiance) => glam::Vec3::INFINITY,
                _ => glam::Vec3::splat(0.5),
            };
        }
    }

    fn may_be_occupied(&self, region: &nerfx_core::field::Aabb) -> bool {
        !region.is_empty()
    }
}

/// A field answering NaN, ±∞ or negative densities, or NaN or infinite colours, in half of
/// its support: every preset and the naive baseline must either refuse the render with an
/// error that says what was wrong, or treat the bad samples as empty — never a NaN, an
/// infinite colour or an alpha outside [0, 1] in the image. The healthy half (x > 0, the
/// right of the image) must still render: some pixel there has alpha above 0.5.
#[test]
fn non_finite_fields_give_an_error_or_empty_samples_never_nan() {
    let camera = axis_camera(DVec3::new(0.0, 0.0, 5.0), 33, 25, 40.0);
    for fault in [
        Fault::NanDensity,
        Fault::InfiniteDensity,
        Fault::NegativeDensity,
        Fault::NanRadiance,
        Fault::InfiniteRadiance,
    ] {
        let handle = nerfx_core::scene::FieldHandle::new(std::sync::Arc::new(Broken(fault)));
        let scene = Scene::new(vec![
            Instance::new("broken", handle, DMat4::IDENTITY, None).expect("an instance")
        ]);
        let check = |what: String, result: nerfx_core::Result<Planes>| match result {
            Err(e) => {
                let m = e.to_string();
                assert!(
                    m.contains("broken") || m.to_lowercase().contains("finite"),
                    "{what}: the error must name the instance or the fault: {m}"
                );
            }
            Ok(planes) => {
                assert_sane(&what, &planes);
                let alpha = planes.alpha.as_ref().expect("alpha");
                let seen = (17..33).any(|x| (0..25).any(|y| alpha.get(x, y) > 0.5));
                assert!(seen, "{what}: the healthy half must still render");
            }
        };
        for quality in Quality::ALL {
            let settings = RenderSettings::new(marched(quality.params()), Outputs::all());
            let got = render(&scene, &camera, camera.full_window(), &settings);
            check(format!("{fault:?}, {quality:?}"), got);
        }
        let naive = render_naive(&scene, &camera, camera.full_window(), 0.01, &Outputs::all());
        check(format!("{fault:?}, naive"), naive.map(|(p, _)| p));
    }
}
