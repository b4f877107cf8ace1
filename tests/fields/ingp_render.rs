//! Rendered pixels of an instant-ngp snapshot against an independent NumPy march
//! (`tests/numpy/ingp_render.py`: the field of `ingp_reference.py`, the compositing
//! `α = 1 − exp(−σδ)`, `T = Π(1 − α)` written out again) over the same rays and samples.
//!
//! The NumPy checks need `python3` with `numpy` and `msgpack` and are cross-checks: they run with the
//! `cross-checks` feature (`scripts/test.sh`), and fail without the tools, saying so.

use std::sync::Arc;

use crate::common_fields::numpy_reference;
use crate::common_ingp::{scratch, write_blob_snapshot, Ball, Spec};
use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::field::IngpField;
use nerfx_core::render::{render_naive, Outputs};
use nerfx_core::scene::{FieldHandle, Instance, Scene};

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn naive_render_agrees_with_a_numpy_march() {
    let dir = scratch("render-numpy");
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
    // A low gain: rays stay partly transparent, so every sample along them counts.
    let (path, _) = write_blob_snapshot(&dir, "blob", &Spec::small_8x4(), &balls, 0.5);
    let field = Arc::new(IngpField::load(&path).unwrap());
    let scene = Scene::new(vec![Instance::new(
        "blob",
        FieldHandle::new(field.clone()),
        DMat4::IDENTITY,
        None,
    )
    .unwrap()]);
    let (w, h) = (12u32, 8u32);
    let p = Perspective::from_vertical_fov(w, h, 30.0).unwrap();
    let camera = Camera::new(
        nerfx_core::demo::look_at(DVec3::new(2.0, -2.5, 0.9), DVec3::ZERO),
        Projection::Perspective(p),
    )
    .unwrap();
    // A step exactly representable in f32, so both sides place the samples alike.
    let step = 1.0 / 512.0;
    let (planes, _) = render_naive(
        &scene,
        &camera,
        camera.full_window(),
        step,
        &Outputs::rgba(),
    )
    .unwrap();
    let (alpha, rgb) = (planes.alpha.unwrap(), planes.rgb.unwrap());

    // The same rays, as render_naive lays them: samples at (j + 1/2)·step past the entry
    // into the field's bounds while they stay inside.
    let inst = &scene.marched().next().unwrap();
    let (mut rows_a, mut rows_b) = (Vec::new(), Vec::new());
    let mut pixels = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5).unwrap();
            let (origin, dir, k, n) = match inst.local_ray(&ray, ray.near, ray.far) {
                Some(lr) => {
                    let n = (0..)
                        .take_while(|&j| lr.t_near + (j as f64 + 0.5) * step <= lr.t_far)
                        .count();
                    (lr.origin, lr.dir, lr.units_per_world, n)
                }
                None => (Vec3::ZERO, Vec3::X, 1.0, 0),
            };
            rows_a.extend([origin, Vec3::new(step as f32, k, n as f32)]);
            rows_b.extend([dir, Vec3::ZERO]);
            pixels.push((x, y));
        }
    }
    let want = numpy_reference(
        "ingp_render.py",
        &["numpy", "msgpack"],
        &path,
        &rows_a,
        &rows_b,
    );
    assert_eq!(want.len(), pixels.len());
    let (mut max_err, mut partial) = (0.0f32, 0);
    for (&(x, y), w) in pixels.iter().zip(&want) {
        let got = [
            rgb[0].get(x, y),
            rgb[1].get(x, y),
            rgb[2].get(x, y),
            alpha.get(x, y),
        ];
        for (g, r) in got.iter().zip(w) {
            let err = (g - r).abs();
            assert!(err <= 1e-3, "pixel ({x}, {y}): nerfx {got:?}, NumPy {w:?}");
            max_err = max_err.max(err);
        }
        partial += usize::from(w[3] > 0.05 && w[3] < 0.95);
    }
    // The check means something: some pixels are partly covered.
    assert!(partial >= 5, "{partial} partly covered pixels");
    println!(
        "{} pixels, {partial} partly covered: max |nerfx − NumPy| {max_err:.2e}",
        pixels.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The marcher's two colour outputs: linear is the as-trained composite unpremultiplied,
/// decoded by the sRGB standard's curve (written out here in f64) and premultiplied again;
/// alpha is the same in both.
#[test]
fn linear_output_is_the_as_trained_composite_decoded() {
    use nerfx_core::render::{render, ColorOutput, Quality, RenderSettings};
    let dir = scratch("render-colour");
    let balls = [Ball {
        centre: [0.5, 0.5, 0.5],
        radius: 0.3,
    }];
    let (path, _) = write_blob_snapshot(&dir, "blob", &Spec::small_8x4(), &balls, 0.5);
    let field = Arc::new(IngpField::load(&path).unwrap());
    let scene = Scene::new(vec![Instance::new(
        "blob",
        FieldHandle::new(field),
        DMat4::IDENTITY,
        None,
    )
    .unwrap()]);
    let p = Perspective::from_vertical_fov(16, 12, 30.0).unwrap();
    let camera = Camera::new(
        nerfx_core::demo::look_at(DVec3::new(2.0, -2.5, 0.9), DVec3::ZERO),
        Projection::Perspective(p),
    )
    .unwrap();
    let settings = |color| RenderSettings {
        color,
        ..RenderSettings::new(Quality::Preview.params(), Outputs::rgba())
    };
    let linear = render(
        &scene,
        &camera,
        camera.full_window(),
        &settings(ColorOutput::Linear),
    );
    let trained = render(
        &scene,
        &camera,
        camera.full_window(),
        &settings(ColorOutput::AsTrained),
    );
    let (linear, trained) = (linear.unwrap(), trained.unwrap());
    let (la, ta) = (linear.alpha.unwrap(), trained.alpha.unwrap());
    assert_eq!(la.data, ta.data);
    let (lc, tc) = (linear.rgb.unwrap(), trained.rgb.unwrap());
    let mut partly = 0;
    for i in 0..la.data.len() {
        let a = f64::from(ta.data[i]);
        if a > 0.0 && a < 0.99 {
            partly += 1;
        }
        for c in 0..3 {
            let want = if a > 0.0 {
                let s = (f64::from(tc[c].data[i]) / a).clamp(0.0, 1.0);
                let l = if s <= 0.04045 {
                    s / 12.92
                } else {
                    ((s + 0.055) / 1.055).powf(2.4)
                };
                l * a
            } else {
                0.0
            };
            let got = f64::from(lc[c].data[i]);
            assert!(
                (got - want).abs() < 1e-4,
                "pixel {i} channel {c}: {got} vs {want}"
            );
        }
    }
    assert!(partly > 10, "only {partly} partly covered pixels");
    let _ = std::fs::remove_dir_all(&dir);
}
