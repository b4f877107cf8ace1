//! nerfacto's far field: a run is integrated from the camera to its far plane, through
//! the contracted shell beyond the unit cube, against references that share none of the
//! marcher's code: the closed form of a constant density, and an independent NumPy march
//! (`tests/numpy/nerfacto_render.py`: the field of `nerfacto_reference.py`, its own samples
//! uniform in nerfstudio's unbounded spacing, its own compositing).
//!
//! The NumPy checks need `python3` with `numpy` and are cross-checks: they run with the
//! `cross-checks` feature (`scripts/test.sh`), and fail without the tools, saying so.

use crate::common_fields::numpy_reference;
use crate::common_nerfacto::{scene_of, scratch, write_run, Spec};
use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::{Camera, Equirect, Perspective, Projection};
use nerfx_core::field::NerfactoField;
use nerfx_core::image::Planes;
use nerfx_core::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::scene::Scene;

fn render_at(scene: &Scene, camera: &Camera, quality: Quality) -> Planes {
    let settings = RenderSettings {
        color: ColorOutput::AsTrained,
        ..RenderSettings::new(quality.params(), Outputs::all())
    };
    render(scene, camera, camera.full_window(), &settings).unwrap()
}

/// `1 − exp(−σL)` and the expected distance `∫ t σ T dt / α` over `t ∈ [n, n + L]` of a
/// constant density (f64).
fn closed_form(sigma: f64, near: f64, far: f64) -> (f64, f64) {
    let l = far - near;
    let e = (-sigma * l).exp();
    let alpha = 1.0 - e;
    let moment = near * alpha + 1.0 / sigma - e * (l + 1.0 / sigma);
    (alpha, moment / alpha)
}

/// A run whose density is faint but everywhere, seen from its centre in every direction (an
/// equirectangular camera): every pixel's alpha is the closed form from the camera to the
/// run's far plane (nerfstudio's near plane is 0 at inference), and its depth the closed
/// form's, in Blender units (a placement scaling the field by 2 doubles it). Before the far
/// field was rendered, the field ended at `‖x‖∞ = 2` and these pixels had alpha 0.02.
#[test]
fn faint_density_everywhere_matches_the_closed_form() {
    let sigma = 0.01f32;
    for (far_plane, scale) in [(Some(200.0), 1.0), (None, 1.0), (Some(150.0), 2.0)] {
        let dir = scratch(&format!("constant-{scale}-{far_plane:?}"));
        let spec = Spec {
            far_plane,
            ..Spec::constant(sigma)
        };
        let run = write_run(&dir, &spec);
        let field = NerfactoField::load(&run).unwrap();
        let (near, far) = (0.0, far_plane.unwrap_or(1000.0));
        let scene = scene_of(field, DMat4::from_scale(DVec3::splat(scale)));
        let camera = Camera::new(
            DMat4::IDENTITY,
            Projection::Equirect(Equirect::new(12, 6).unwrap()),
        )
        .unwrap();
        let (want_alpha, want_depth) = closed_form(f64::from(sigma), near, far.into());
        for quality in [Quality::Draft, Quality::Final] {
            let out = render_at(&scene, &camera, quality);
            let (alpha, depth) = (out.alpha.unwrap(), out.depth_ray.unwrap());
            // A ray stops once its transmittance is below the preset's threshold: what
            // lies behind is not composited.
            let stop = f64::from(quality.params().min_transmittance);
            let (mut max_alpha, mut max_depth) = (0.0f64, 0.0f64);
            for (&a, &d) in alpha.data.iter().zip(&depth.data) {
                let (a, d) = (f64::from(a), f64::from(d));
                let err = (a - want_alpha).abs();
                if 1.0 - want_alpha >= stop {
                    assert!(
                        err < 1e-4,
                        "{quality:?} far {far}: alpha {a}, want {want_alpha}"
                    );
                    let rel = (d / scale - want_depth).abs() / want_depth;
                    assert!(
                        rel < 1e-3,
                        "{quality:?} far {far}: depth {d}, want {}",
                        want_depth * scale
                    );
                    max_depth = max_depth.max(rel);
                } else {
                    assert!(a >= 1.0 - stop - 1e-6 && a <= want_alpha + 1e-6, "{a}");
                    assert!(d.is_finite() && d > 0.0 && d < far as f64 * scale);
                }
                max_alpha = max_alpha.max(err);
            }
            println!(
                "σ {sigma}, planes {near}..{far}, scale {scale}, {quality:?}: alpha \
                 {want_alpha:.6} (closed form), max |error| {max_alpha:.2e}; depth \
                 {:.4}, max relative error {max_depth:.2e}",
                want_depth * scale
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// A distant shell (faint inside field radius ~30, opaque by ~100) from a camera off the
/// centre, at Final, against the NumPy march: alpha, colour (as trained) and depth.
#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn a_distant_shell_agrees_with_a_numpy_march() {
    let dir = scratch("shell");
    let run = write_run(&dir, &Spec::shell());
    let field = NerfactoField::load(&run).unwrap();
    let scene = scene_of(field, DMat4::IDENTITY);
    let (w, h) = (12u32, 8u32);
    let eye = DVec3::new(0.2, -0.1, 0.3);
    let camera = Camera::new(
        nerfx_core::demo::look_at(eye, eye + DVec3::new(1.0, 0.3, -0.5)),
        Projection::Perspective(Perspective::from_vertical_fov(w, h, 100.0).unwrap()),
    )
    .unwrap();
    let out = render_at(&scene, &camera, Quality::Final);
    let (alpha, depth, rgb) = (out.alpha.unwrap(), out.depth_ray.unwrap(), out.rgb.unwrap());
    let (mut origins, mut dirs) = (Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5).unwrap();
            origins.extend([ray.origin.as_vec3(), Vec3::new(4000.0, 0.0, 0.0)]);
            dirs.extend([ray.dir.normalize().as_vec3(), Vec3::ZERO]);
        }
    }
    let want = numpy_reference("nerfacto_render.py", &["numpy"], &run, &origins, &dirs);
    assert_eq!(want.len(), 2 * (w * h) as usize);
    let (mut sq, mut n, mut max_alpha, mut max_depth) = (0.0f64, 0, 0.0f32, 0.0f32);
    let mut depths = Vec::new();
    for (i, pair) in want.chunks_exact(2).enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let [r, g, b, a] = pair[0];
        let want_depth = pair[1][0];
        for (c, v) in [r, g, b].into_iter().enumerate() {
            sq += f64::from(rgb[c].get(x, y) - v).powi(2);
            n += 1;
        }
        max_alpha = max_alpha.max((alpha.get(x, y) - a).abs());
        let rel = (depth.get(x, y) - want_depth).abs() / want_depth;
        max_depth = max_depth.max(rel);
        depths.push(want_depth);
        assert!(
            a > 0.9,
            "pixel ({x}, {y}): the shell should be nearly opaque: {a}"
        );
    }
    let psnr = 10.0 * (n as f64 / sq).log10();
    let (lo, hi) = depths
        .iter()
        .fold((f32::INFINITY, 0.0f32), |(l, h), &d| (l.min(d), h.max(d)));
    println!(
        "shell, {w}x{h} at Final vs NumPy: colour PSNR {psnr:.1} dB, max |alpha error| \
         {max_alpha:.2e}, max relative depth error {max_depth:.2e} (depths {lo:.1}..{hi:.1})"
    );
    assert!(lo > 10.0 && hi < 1000.0, "depths {lo}..{hi}");
    assert!(psnr > 40.0, "PSNR {psnr:.1} dB");
    assert!(max_alpha < 2e-3, "alpha error {max_alpha}");
    assert!(max_depth < 1e-2, "depth error {max_depth}");
    let _ = std::fs::remove_dir_all(&dir);
}
