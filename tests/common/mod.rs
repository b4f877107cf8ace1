//! Shared helpers of the marcher's accuracy and stability tests: a seeded generator of random
//! analytic scenes and cameras, the one tolerance helper every comparison goes through
//! ([`assert_close`]), and the invariants every render must satisfy ([`assert_sane`]).

use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::demo::look_at;
use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};
use nerfx_core::image::{Plane, Planes};
use nerfx_core::render::{render, MarchParams, Outputs, RenderSettings};
use nerfx_core::scene::{CropBox, FieldHandle, Instance, Scene};
use nerfx_testkit::reference::metrics;

pub mod rng;
pub use rng::SplitMix64;

/// A primitive with a constant colour.
pub fn prim(shape: Shape, density: f32, rgb: [f32; 3]) -> Primitive {
    Primitive {
        shape,
        density,
        color: ShColor::constant(Vec3::from(rgb)),
    }
}

pub fn sphere(center: [f32; 3], radius: f32) -> Shape {
    Shape::Sphere {
        center: Vec3::from(center),
        radius,
    }
}

pub fn cube(min: [f32; 3], max: [f32; 3]) -> Shape {
    Shape::Box {
        min: Vec3::from(min),
        max: Vec3::from(max),
    }
}

/// One instance of `primitives` at `world_from_field`.
pub fn instance(
    name: &str,
    primitives: Vec<Primitive>,
    world_from_field: DMat4,
    crop: Option<CropBox>,
) -> Instance {
    let field = FieldHandle::analytic(Analytic { primitives });
    Instance::new(name, field, world_from_field, crop).expect("a valid test instance")
}

/// The largest field-space density of a random primitive (per field unit).
pub const MAX_DENSITY: f64 = 200.0;

/// 1–4 random primitives in `[−1, 1]³`: spheres, boxes and cut Gaussians with densities
/// log-uniform in `[0.1, 200]` and constant or view-dependent (degree-1 SH) colours.
fn random_field(rng: &mut SplitMix64) -> Analytic {
    let n = 1 + rng.below(4);
    let primitives = (0..n)
        .map(|_| {
            let shape = match rng.below(3) {
                0 => Shape::Sphere {
                    center: rng.vec3(-0.6, 0.6),
                    radius: rng.uniform(0.15, 0.5) as f32,
                },
                1 => {
                    let c = rng.vec3(-0.5, 0.5);
                    let half = rng.vec3(0.1, 0.5);
                    Shape::Box {
                        min: c - half,
                        max: c + half,
                    }
                }
                _ => Shape::Gaussian {
                    center: rng.vec3(-0.5, 0.5),
                    sigma: rng.uniform(0.08, 0.2) as f32,
                    cutoff: rng.uniform(2.5, 4.0) as f32,
                },
            };
            let base = rng.vec3(0.05, 1.0);
            let color = if rng.below(2) == 0 {
                ShColor::constant(base)
            } else {
                ShColor::from_coefficients(&[
                    base * 2.0,
                    rng.vec3(-0.3, 0.3),
                    rng.vec3(-0.3, 0.3),
                    rng.vec3(-0.3, 0.3),
                ])
                .expect("4 finite triples")
            };
            Primitive {
                shape,
                density: rng.log_uniform(0.1, MAX_DENSITY) as f32,
                color,
            }
        })
        .collect();
    Analytic { primitives }
}

/// A seeded random scene of 1–3 instances, each rotated, non-uniformly scaled (0.6–1.4 per
/// axis), moved by up to 1 unit, a third of them cropped; all within about 3 units of the
/// origin.
pub fn random_scene(rng: &mut SplitMix64) -> Scene {
    let n = 1 + rng.below(3);
    let instances: Vec<Instance> = (0..n)
        .map(|i| {
            let m = DMat4::from_scale_rotation_translation(
                rng.dvec3(0.6, 1.4),
                rng.rotation(),
                rng.dvec3(-1.0, 1.0),
            );
            let crop = (rng.below(3) == 0).then(|| CropBox {
                center: rng.dvec3(-0.3, 0.3).to_array(),
                scale: rng.dvec3(0.8, 1.8).to_array(),
                rotation: rng.dvec3(-1.0, 1.0).to_array(),
            });
            let field = FieldHandle::analytic(random_field(rng));
            Instance::new(format!("random {i}"), field, m, crop).expect("a valid random instance")
        })
        .collect();
    Scene::new(instances)
}

/// A perspective camera at `eye` looking at `target` (Z up), `width × height`, vertical FOV
/// `fov` degrees.
pub fn camera_at(eye: DVec3, target: DVec3, width: u32, height: u32, fov: f64) -> Camera {
    let p = Perspective::from_vertical_fov(width, height, fov).expect("a valid test camera");
    Camera::new(look_at(eye, target), Projection::Perspective(p)).expect("a valid test camera")
}

/// A random perspective camera 5–7 units from the origin, looking at a point near it.
pub fn random_camera(rng: &mut SplitMix64, width: u32, height: u32) -> Camera {
    let azimuth = rng.uniform(0.0, std::f64::consts::TAU);
    let elevation = rng.uniform(-0.6, 1.0);
    let dist = rng.uniform(5.0, 7.0);
    let eye = dist
        * DVec3::new(
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        );
    let target = rng.dvec3(-0.5, 0.5);
    camera_at(eye, target, width, height, rng.uniform(40.0, 60.0))
}

/// `params` with [`MarchParams::closed_form`] off: the tests of the marcher's accuracy and
/// stability march analytic scenes as they would march any field.
pub fn marched(params: MarchParams) -> MarchParams {
    MarchParams {
        closed_form: false,
        ..params
    }
}

/// Renders the camera's full image with `march`, every plane, 16-pixel tiles.
pub fn render_full(scene: &Scene, camera: &Camera, march: MarchParams) -> Planes {
    let settings = RenderSettings::new(march, Outputs::all());
    render(scene, camera, camera.full_window(), &settings).expect("render")
}

/// The reference of the camera's full image.
pub fn reference_full(scene: &Scene, camera: &Camera) -> Planes {
    nerfx_testkit::reference::render(scene, camera, camera.full_window()).expect("reference")
}

/// How close two renders must be. Every bound is on the worst pixel except `min_psnr`.
#[derive(Clone, Copy, Debug)]
pub struct Tol {
    /// PSNR of premultiplied RGB over the image (peak 1), dB.
    pub min_psnr: f64,
    /// PSNR of alpha over the image (peak 1), dB.
    pub min_alpha_psnr: f64,
    /// Largest absolute error of any RGB sample.
    pub rgb: f64,
    /// Largest absolute alpha error.
    pub alpha: f64,
    /// Largest relative error of depth (camera Z, ray distance and median) where the wanted
    /// alpha is at least [`DEPTH_ALPHA`].
    pub depth_rel: f64,
}

impl Tol {
    /// Bit-for-bit equality of every plane.
    pub const EXACT: Tol = Tol {
        min_psnr: f64::INFINITY,
        min_alpha_psnr: f64::INFINITY,
        rgb: 0.0,
        alpha: 0.0,
        depth_rel: 0.0,
    };
}

/// Final: step = feature size / 8, edges bisected while `|Δσ|·δ·T > 1e-3` (at most 10
/// times), stop at T < 1e-4.
///
/// - Alpha. Bisection stops once an edge's bracket holds at most 1e-3 of optical depth
///   (weighted by the light reaching it), and the trapezoid rule gets about half of that
///   bracket wrong; with the entry and exit edges of a primitive and early termination
///   (≤ 1e-4) a pixel's alpha is off by ≤ ~1.1e-3 (measured worst over the seeds about
///   9e-4). Bound 2e-3; losing refinement (a bracket 4× wider) breaks it. Alpha PSNR ≥ 60 dB
///   (an RMS error of 1e-3: a small image where every pixel crosses a dense edge reaches it).
/// - RGB: colour errors are alpha errors times colours ≤ ~2.5: bound 2e-3 per pixel and
///   PSNR ≥ 70 dB (an RMS error of 3e-4).
/// - Depth (where the reference alpha ≥ 0.5): an alpha error Δα moves the expected depth by
///   about `Δα·(depth spread)/α` ≈ 1e-3·2/0.5 over depths ≥ 4, i.e. 1e-3 relative; the median
///   moves by `Δα/(σT)` likewise. Bound 2e-3.
pub const FINAL: Tol = Tol {
    min_psnr: 70.0,
    min_alpha_psnr: 60.0,
    rgb: 2e-3,
    alpha: 2e-3,
    depth_rel: 2e-3,
};

/// Depth is compared where the wanted alpha is at least this (as the benchmark's metric does:
/// a faint pixel's depth is an average over a little density anywhere along the ray).
pub const DEPTH_ALPHA: f32 = 0.5;

/// The worst sample of one plane: `(error, x, y, got, want)`.
type Worst = (f64, u32, u32, f32, f32);

/// The worst sample of `got` against `want`, with `error(got, want)` (`None`: not compared).
/// Samples equal as numbers (both `+∞` included) have error 0; a NaN anywhere is an infinite
/// error.
fn worst(got: &Plane, want: &Plane, error: impl Fn(usize, f32, f32) -> Option<f64>) -> Worst {
    assert_eq!(
        (got.width, got.height),
        (want.width, want.height),
        "plane sizes differ"
    );
    let mut w: Worst = (0.0, 0, 0, 0.0, 0.0);
    for (i, (&g, &r)) in got.data.iter().zip(&want.data).enumerate() {
        let e = if g.is_nan() || r.is_nan() {
            Some(f64::INFINITY)
        } else if g == r {
            Some(0.0)
        } else {
            error(i, g, r)
        };
        if let Some(e) = e {
            if e > w.0 {
                let x = i as u32 % got.width;
                w = (e, x, i as u32 / got.width, g, r);
            }
        }
    }
    w
}

/// The one tolerance helper: asserts that `got` matches `want` within `tol`, plane by plane
/// (planes missing from `want` are not compared; a plane `want` has and `got` lacks fails),
/// and names the worst pixel — its coordinates and both values — of any plane that does not.
/// With [`Tol::EXACT`] every sample must be identical to the bit.
pub fn assert_close(what: &str, got: &Planes, want: &Planes, tol: Tol) {
    assert_eq!(
        (got.width, got.height),
        (want.width, want.height),
        "{what}: sizes differ"
    );
    let exact = |g: f32, r: f32| g.to_bits() == r.to_bits();
    let mut failures = Vec::new();
    let mut check = |name: &str, g: &Plane, r: &Plane, bound: f64, rel: bool| {
        let alpha = want.alpha.as_ref();
        let (e, x, y, gv, rv) = worst(g, r, |i, gv, rv| {
            if rel && alpha.is_some_and(|a| a.data[i] < DEPTH_ALPHA) {
                return None;
            }
            let abs = (gv as f64 - rv as f64).abs();
            Some(if rel { abs / (rv as f64).abs() } else { abs })
        });
        let bits_differ = bound == 0.0 && g.data.iter().zip(&r.data).any(|(&a, &b)| !exact(a, b));
        if e > bound || e.is_nan() || bits_differ {
            failures.push(format!(
                "{name}: worst {} error {e:.3e} > {bound:.1e} at ({x}, {y}): got {gv}, want {rv}",
                if rel { "relative" } else { "absolute" }
            ));
        }
    };
    if let Some(want_rgb) = &want.rgb {
        let got_rgb = got.rgb.as_ref().expect("rgb plane missing");
        for (c, name) in ["r", "g", "b"].iter().enumerate() {
            check(name, &got_rgb[c], &want_rgb[c], tol.rgb, false);
        }
    }
    let pairs = [
        ("alpha", &got.alpha, &want.alpha, tol.alpha, false),
        ("depth_z", &got.depth_z, &want.depth_z, tol.depth_rel, true),
        (
            "depth_ray",
            &got.depth_ray,
            &want.depth_ray,
            tol.depth_rel,
            true,
        ),
        (
            "depth_median",
            &got.depth_median,
            &want.depth_median,
            tol.depth_rel,
            true,
        ),
    ];
    for (name, g, r, bound, rel) in pairs {
        if let Some(r) = r {
            let g = g
                .as_ref()
                .unwrap_or_else(|| panic!("{what}: {name} missing"));
            check(name, g, r, bound, rel);
        }
    }
    if want.rgb.is_some() {
        let psnr = metrics::psnr(want, got);
        if psnr.is_nan() || psnr < tol.min_psnr {
            failures.push(format!("PSNR {psnr:.2} dB < {:.2} dB", tol.min_psnr));
        }
    }
    if let (Some(g), Some(r)) = (&got.alpha, &want.alpha) {
        // The same PSNR, of alpha alone: alpha put in all three channels.
        let as_rgb = |p: &Planes, a: &Plane| Planes {
            rgb: Some([a.clone(), a.clone(), a.clone()]),
            ..p.clone()
        };
        let psnr = metrics::psnr(&as_rgb(want, r), &as_rgb(got, g));
        if psnr.is_nan() || psnr < tol.min_alpha_psnr {
            failures.push(format!(
                "alpha PSNR {psnr:.2} dB < {:.2} dB",
                tol.min_alpha_psnr
            ));
        }
    }
    assert!(failures.is_empty(), "{what}:\n  {}", failures.join("\n  "));
}

/// The invariants of every render: alpha in [0, 1]; RGB finite and ≥ 0; every depth finite
/// and ≥ 0 wherever alpha > 0 (`+∞` allowed only where alpha is 0); nothing NaN.
pub fn assert_sane(what: &str, planes: &Planes) {
    let n = planes.width as usize * planes.height as usize;
    let at = |i: usize| {
        (
            i % planes.width.max(1) as usize,
            i / planes.width.max(1) as usize,
        )
    };
    let alpha = planes.alpha.as_ref().map(|a| &a.data);
    if let Some(a) = alpha {
        assert_eq!(a.len(), n, "{what}: alpha size");
        for (i, &v) in a.iter().enumerate() {
            assert!((0.0..=1.0).contains(&v), "{what}: alpha {v} at {:?}", at(i));
        }
    }
    if let Some(rgb) = &planes.rgb {
        for (c, plane) in rgb.iter().enumerate() {
            assert_eq!(plane.data.len(), n, "{what}: rgb size");
            for (i, &v) in plane.data.iter().enumerate() {
                assert!(
                    v.is_finite() && v >= 0.0,
                    "{what}: rgb[{c}] {v} at {:?}",
                    at(i)
                );
            }
        }
    }
    for (name, plane) in [
        ("depth_z", &planes.depth_z),
        ("depth_ray", &planes.depth_ray),
        ("depth_median", &planes.depth_median),
    ] {
        let Some(plane) = plane else { continue };
        assert_eq!(plane.data.len(), n, "{what}: {name} size");
        for (i, &d) in plane.data.iter().enumerate() {
            let transparent = alpha.is_some_and(|a| a[i] == 0.0);
            let ok = d >= 0.0 && (d.is_finite() || (d == f32::INFINITY && transparent));
            assert!(ok, "{what}: {name} {d} at {:?}", at(i));
        }
    }
}
