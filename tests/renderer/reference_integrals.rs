//! The reference integrator against integrals written out by hand: closed forms for spheres,
//! boxes and Gaussians, transformed and cropped instances, extreme densities, and a brute-force
//! Riemann sum over a mixed scene.

use std::f64::consts::PI;
use std::sync::Arc;

use glam::{DMat3, DMat4, DVec3, Vec3};
use nerfx_core::camera::{Camera, Perspective, Projection, Ray};
use nerfx_core::field::{Aabb, Analytic, Field, Primitive, ShColor, Shape};
use nerfx_core::image::Window;
use nerfx_core::scene::{CropBox, FieldHandle, Instance, Scene};
use nerfx_core::Error;
use nerfx_testkit::reference::{self, RayResult, ReferenceScene};

fn rgb(r: f32, g: f32, b: f32) -> ShColor {
    ShColor::constant(Vec3::new(r, g, b))
}

fn sphere(center: [f32; 3], radius: f32, density: f32, color: ShColor) -> Primitive {
    Primitive {
        shape: Shape::Sphere {
            center: Vec3::from(center),
            radius,
        },
        density,
        color,
    }
}

fn cube(min: [f32; 3], max: [f32; 3], density: f32, color: ShColor) -> Primitive {
    Primitive {
        shape: Shape::Box {
            min: Vec3::from(min),
            max: Vec3::from(max),
        },
        density,
        color,
    }
}

fn gaussian(center: [f32; 3], sigma: f32, cutoff: f32, density: f32, color: ShColor) -> Primitive {
    Primitive {
        shape: Shape::Gaussian {
            center: Vec3::from(center),
            sigma,
            cutoff,
        },
        density,
        color,
    }
}

fn instance(
    primitives: Vec<Primitive>,
    world_from_field: DMat4,
    crop: Option<CropBox>,
) -> Instance {
    let field = FieldHandle::analytic(Analytic { primitives });
    Instance::new("test", field, world_from_field, crop).unwrap()
}

fn integrate(instances: Vec<Instance>, origin: DVec3, dir: DVec3) -> RayResult {
    let scene = Scene::new(instances);
    let ray = Ray {
        origin,
        dir: dir.normalize(),
        z_per_t: 1.0,
        near: 0.0,
        far: f64::INFINITY,
    };
    ReferenceScene::new(&scene).unwrap().integrate(&ray)
}

fn assert_close(got: f64, want: f64, tol: f64, what: &str) {
    let err = (got - want).abs();
    assert!(
        err <= tol * want.abs().max(1.0),
        "{what}: got {got}, want {want}, error {err:e}"
    );
}

/// `E[t]` over a constant piece of density σ entered at `t0`, length `l`:
/// `t0 + (1 − e^{−σl}(1 + σl)) / (σ(1 − e^{−σl}))`.
fn constant_piece_depth(t0: f64, l: f64, sigma: f64) -> f64 {
    let x = sigma * l;
    t0 + (1.0 - (-x).exp() * (1.0 + x)) / (sigma * (1.0 - (-x).exp()))
}

#[test]
fn unit_density_sphere_through_its_centre() {
    // r = 0.75 at the origin, seen from z = 5: entry at 4.25, chord 1.5.
    let red = rgb(0.9, 0.1, 0.0);
    let inst = instance(
        vec![sphere([0.0; 3], 0.75, 1.0, red)],
        DMat4::IDENTITY,
        None,
    );
    let r = integrate(vec![inst], DVec3::new(0.0, 0.0, 5.0), DVec3::NEG_Z);
    let alpha = 1.0 - (-1.5f64).exp();
    assert_close(r.alpha, alpha, 1e-15, "alpha");
    assert_close(r.rgb.x, 0.9f32 as f64 * alpha, 1e-15, "red");
    assert_close(r.rgb.y, 0.1f32 as f64 * alpha, 1e-15, "green");
    assert_eq!(r.rgb.z, 0.0);
    // E[t] = 4.25 + (1 − e^{−1.5}·2.5)/(1 − e^{−1.5}).
    let depth = 4.25 + (1.0 - (-1.5f64).exp() * 2.5) / (1.0 - (-1.5f64).exp());
    assert_close(r.depth_ray, depth, 1e-14, "expected depth");
    // Median: 1 − e^{−(t − 4.25)} = A/2.
    let median = 4.25 - (1.0 - alpha / 2.0).ln();
    assert_close(r.depth_median, median, 1e-14, "median depth");
}

#[test]
fn a_ray_that_misses_everything() {
    let inst = instance(
        vec![
            sphere([0.0; 3], 1.0, 3.0, rgb(1.0, 1.0, 1.0)),
            gaussian([0.0, 3.0, 0.0], 0.5, 4.0, 3.0, rgb(1.0, 1.0, 1.0)),
        ],
        DMat4::IDENTITY,
        None,
    );
    // Passes at x = 5; and a ray pointing away from the primitives sees nothing either.
    for (o, d) in [
        (DVec3::new(5.0, 0.0, 5.0), DVec3::NEG_Z),
        (DVec3::new(0.0, 0.0, 5.0), DVec3::Z),
    ] {
        let r = integrate(vec![inst.clone()], o, d);
        assert_eq!(r.alpha, 0.0);
        assert_eq!(r.rgb, DVec3::ZERO);
        assert_eq!(r.depth_ray, f64::INFINITY);
        assert_eq!(r.depth_median, f64::INFINITY);
    }
}

#[test]
fn two_overlapping_boxes_mix_by_density() {
    // Along +x from x = −4: box A (σ 0.7, red) on t ∈ [3, 5], box B (σ 1.3, cyan) on [4, 6].
    let (s1, s2) = (0.7f32 as f64, 1.3f32 as f64); // the f32 the field stores
    let (c1, c2) = (DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, 0.5, 1.0));
    let inst = instance(
        vec![
            cube([-1.0; 3], [1.0; 3], 0.7, rgb(1.0, 0.0, 0.0)),
            cube([0.0, -0.5, -0.5], [2.0, 0.5, 0.5], 1.3, rgb(0.0, 0.5, 1.0)),
        ],
        DMat4::IDENTITY,
        None,
    );
    let r = integrate(vec![inst], DVec3::new(-4.0, 0.1, 0.2), DVec3::X);
    // The sweep by hand: pieces [3,4] σ1, [4,5] σ1+σ2, [5,6] σ2.
    let pieces = [
        (3.0, s1, c1),
        (4.0, s1 + s2, (s1 * c1 + s2 * c2) / (s1 + s2)),
        (5.0, s2, c2),
    ];
    let (mut t_in, mut color, mut alpha, mut moment) = (1.0f64, DVec3::ZERO, 0.0, 0.0);
    for (t0, sigma, mix) in pieces {
        let absorbed = t_in * (1.0 - (-sigma).exp());
        color += absorbed * mix;
        alpha += absorbed;
        moment += absorbed * constant_piece_depth(t0, 1.0, sigma);
        t_in *= (-sigma).exp();
    }
    assert_close(r.alpha, alpha, 1e-14, "alpha");
    for k in 0..3 {
        assert_close(r.rgb[k], color[k], 1e-14, "colour");
    }
    assert_close(r.depth_ray, moment / alpha, 1e-14, "depth");
}

#[test]
fn gaussian_through_its_centre_has_the_erf_integral() {
    // ∫ ρ e^{−s²/(2σ²)} ds over the whole line = ρ·σ·√(2π); a cutoff of 20σ leaves out
    // erfc(20/√2) ≈ 6e-89 of it.
    let (rho, sd) = (0.8f32 as f64, 0.5); // the f32 the field stores
    let color = DVec3::new(0.25, 0.5, 1.0);
    let inst = instance(
        vec![gaussian([0.0; 3], 0.5, 20.0, 0.8, rgb(0.25, 0.5, 1.0))],
        DMat4::IDENTITY,
        None,
    );
    let r = integrate(vec![inst.clone()], DVec3::new(0.0, 0.0, 5.0), DVec3::NEG_Z);
    let alpha = 1.0 - (-rho * sd * (2.0 * PI).sqrt()).exp();
    assert_close(r.alpha, alpha, 1e-14, "alpha");
    for k in 0..3 {
        assert_close(r.rgb[k], color[k] * alpha, 1e-10, "colour = colour × alpha");
    }
    // The front absorbs first, so the expected depth is in front of the centre (its exact
    // value is checked against a Riemann sum below).
    assert!(r.depth_ray < 5.0 && r.depth_ray > 4.0, "{}", r.depth_ray);
    // Off centre by b = 0.3: the optical depth scales by e^{−b²/(2σ²)}.
    let r = integrate(vec![inst], DVec3::new(0.3, 0.0, 5.0), DVec3::NEG_Z);
    let tau = rho * sd * (2.0 * PI).sqrt() * (-0.09f64 / (2.0 * 0.25)).exp();
    assert_close(r.alpha, 1.0 - (-tau).exp(), 1e-14, "off-centre alpha");
}

#[test]
fn non_uniform_scale_stretches_the_chord_and_thins_the_density() {
    // N = translate(3, 0, 0)·scale(2, 1, 1): the sphere of radius 0.5 becomes an ellipsoid
    // with semi-axes (1, 0.5, 0.5). Along world x the chord is 4r = 2 (world t ∈ [2, 4]) and
    // one world unit is k = |N⁻¹x̂| = 1/2 field unit, so the density per world unit is ρ/2.
    let rho = 1.2f32 as f64; // the f32 the field stores
    let n = DMat4::from_translation(DVec3::new(3.0, 0.0, 0.0))
        * DMat4::from_scale(DVec3::new(2.0, 1.0, 1.0));
    let inst = instance(
        vec![sphere([0.0; 3], 0.5, 1.2, rgb(1.0, 1.0, 1.0))],
        n,
        None,
    );
    let r = integrate(vec![inst.clone()], DVec3::ZERO, DVec3::X);
    let sigma_world = rho / 2.0;
    assert_close(
        r.alpha,
        1.0 - (-sigma_world * 2.0).exp(),
        1e-15,
        "alpha along x",
    );
    assert_close(
        r.depth_ray,
        constant_piece_depth(2.0, 2.0, sigma_world),
        1e-14,
        "depth along x",
    );
    // Along world y the axis is not scaled: chord 2r = 1 at density ρ.
    let r = integrate(vec![inst.clone()], DVec3::new(3.0, -5.0, 0.0), DVec3::Y);
    assert_close(r.alpha, 1.0 - (-rho).exp(), 1e-15, "alpha along y");
    assert_close(
        r.depth_ray,
        constant_piece_depth(4.5, 1.0, rho),
        1e-14,
        "depth along y",
    );
    // Diagonally (1, 1, 0)/√2 through the centre: the ellipsoid x²/1 + y²/0.25 = 1 meets the
    // line at s²/2·(1 + 4) = 1, chord 2√0.4; k = |(1/2, 1, 0)/√2| = √(5/8).
    let chord = 2.0 * 0.4f64.sqrt();
    let k = (5.0f64 / 8.0).sqrt();
    let dir = DVec3::new(1.0, 1.0, 0.0).normalize();
    let r = integrate(vec![inst], DVec3::new(3.0, 0.0, 0.0) - 5.0 * dir, dir);
    assert_close(
        r.alpha,
        1.0 - (-k * rho * chord).exp(),
        1e-14,
        "alpha diagonally",
    );
    assert_close(
        r.depth_ray,
        constant_piece_depth(5.0 - chord / 2.0, chord, k * rho),
        1e-13,
        "depth diagonally",
    );
}

#[test]
fn scaled_gaussian_keeps_its_optical_depth_and_widens() {
    // Uniform scale 3: the blob is 3× wider in the world but holds the same optical depth
    // through its centre (optical depth does not depend on units of length).
    let (rho, sd) = (0.6f32 as f64, 0.4f32 as f64); // the f32s the field stores
    let n = DMat4::from_scale(DVec3::splat(3.0));
    let inst = instance(
        vec![gaussian([0.0; 3], 0.4, 30.0, 0.6, rgb(1.0, 1.0, 1.0))],
        n,
        None,
    );
    let r = integrate(vec![inst], DVec3::new(0.0, 0.0, 20.0), DVec3::NEG_Z);
    let tau = rho * sd * (2.0 * PI).sqrt();
    assert_close(r.alpha, 1.0 - (-tau).exp(), 1e-14, "alpha");
    // In the world the blob is 3σ = 1.2 wide: the median lies within a few widths in front
    // of its centre.
    assert!(
        r.depth_median > 20.0 - 3.0 * 1.2 && r.depth_median < 20.0,
        "{}",
        r.depth_median
    );
}

#[test]
fn crop_box_halving_a_sphere_halves_the_chord() {
    // Sphere r = 1, ρ = 0.5, at field origin; the field is placed at world x = 10. The crop
    // keeps field x ∈ [0, 1]: the chord through the centre along x shrinks from 2 to 1,
    // world t ∈ [15, 16] from x = −5.
    let n = DMat4::from_translation(DVec3::new(10.0, 0.0, 0.0));
    let prims = || vec![sphere([0.0; 3], 1.0, 0.5, rgb(1.0, 1.0, 1.0))];
    let axis_aligned = CropBox {
        center: [0.5, 0.0, 0.0],
        scale: [1.0, 4.0, 4.0],
        rotation: [0.0; 3],
    };
    // The same box as a 4 × 1 × 4 box turned 90° about z (yaw).
    let turned = CropBox {
        center: [0.5, 0.0, 0.0],
        scale: [4.0, 1.0, 4.0],
        rotation: [0.0, 0.0, PI / 2.0],
    };
    for crop in [axis_aligned, turned] {
        let inst = instance(prims(), n, Some(crop));
        let r = integrate(vec![inst], DVec3::new(-5.0, 0.0, 0.0), DVec3::X);
        assert_close(r.alpha, 1.0 - (-0.5f64).exp(), 1e-14, "alpha");
        assert_close(
            r.depth_ray,
            constant_piece_depth(15.0, 1.0, 0.5),
            1e-14,
            "depth",
        );
    }
    // Uncropped, for comparison: the full chord.
    let r = integrate(
        vec![instance(prims(), n, None)],
        DVec3::new(-5.0, 0.0, 0.0),
        DVec3::X,
    );
    assert_close(r.alpha, 1.0 - (-1.0f64).exp(), 1e-14, "uncropped alpha");
}

#[test]
fn huge_density_is_opaque_at_the_entry_point() {
    let inst = instance(
        vec![
            sphere([0.0; 3], 1.0, 1e8, rgb(0.2, 0.4, 0.6)),
            gaussian([0.0, 0.0, 0.5], 0.3, 4.0, 1e8, rgb(1.0, 0.0, 0.0)),
        ],
        DMat4::IDENTITY,
        None,
    );
    let r = integrate(vec![inst], DVec3::new(0.0, 0.0, 5.0), DVec3::NEG_Z);
    assert_eq!(r.alpha, 1.0);
    // The blob's cutoff sphere (radius 4σ = 1.2 about z = 0.5) is met first, at t = 3.3,
    // where its density jumps from 0 to 1e8·e^{−8} ≈ 3e4: opaque within ~1e-4, in red.
    assert_close(r.depth_ray, 3.3, 1e-4, "depth at the blob's edge");
    assert_close(r.depth_median, 3.3, 1e-4, "median at the blob's edge");
    assert_close(r.rgb.x, 1.0, 1e-10, "blob colour");
    assert!(r.rgb.y.abs() < 1e-10, "{}", r.rgb.y);
    // The blob alone: entry at its cutoff, t = 3.8.
    let blob = instance(
        vec![gaussian([0.0; 3], 0.3, 4.0, 1e8, rgb(1.0, 0.0, 0.0))],
        DMat4::IDENTITY,
        None,
    );
    let r = integrate(vec![blob], DVec3::new(0.0, 0.0, 5.0), DVec3::NEG_Z);
    assert_eq!(r.alpha, 1.0);
    assert_close(r.rgb.x, 1.0, 1e-10, "blob colour");
    assert_close(r.depth_ray, 3.8, 1e-4, "blob depth");
    // A dense sphere alone: the entry point, to the mean free path 1e-8.
    let solid = instance(
        vec![sphere([0.0; 3], 1.0, 1e8, rgb(0.2, 0.4, 0.6))],
        DMat4::IDENTITY,
        None,
    );
    let r = integrate(vec![solid], DVec3::new(0.0, 0.0, 5.0), DVec3::NEG_Z);
    assert_eq!(r.alpha, 1.0);
    assert_close(r.depth_ray, 4.0, 1e-7, "depth at entry");
    assert_close(r.depth_median, 4.0, 1e-7, "median at entry");
    assert_close(r.rgb.z, 0.6f32 as f64, 1e-15, "colour");
}

#[test]
fn tiny_density_gives_alpha_sigma_times_chord() {
    // σ = 1e-9 over the chord 2: A = 1 − e^{−2e-9} ≈ 2e-9 (relative error 1e-9), and the
    // depth weights are uniform along the chord, so E[t] is its midpoint.
    let inst = instance(
        vec![sphere([0.0; 3], 1.0, 1e-9, rgb(1.0, 1.0, 1.0))],
        DMat4::IDENTITY,
        None,
    );
    let r = integrate(vec![inst], DVec3::new(0.0, 0.0, 5.0), DVec3::NEG_Z);
    let sigma = 1e-9f32 as f64;
    assert!(
        ((r.alpha - 2.0 * sigma) / (2.0 * sigma)).abs() < 2e-9,
        "{}",
        r.alpha
    );
    assert_close(r.depth_ray, 5.0, 1e-8, "depth");
    assert_close(r.depth_median, 5.0, 1e-8, "median");
}

/// Density (per field unit) and density-weighted colour of one primitive at a field-space
/// point, written again from the primitive definitions.
fn density_at(p: &Primitive, x: DVec3, dir: DVec3) -> (f64, DVec3) {
    let rho = p.density as f64;
    let sigma = match p.shape {
        Shape::Sphere { center, radius } => {
            if (x - center.as_dvec3()).length() <= radius as f64 {
                rho
            } else {
                0.0
            }
        }
        Shape::Box { min, max } => {
            if x.cmpge(min.as_dvec3()).all() && x.cmple(max.as_dvec3()).all() {
                rho
            } else {
                0.0
            }
        }
        Shape::Gaussian {
            center,
            sigma,
            cutoff,
        } => {
            let (r, s) = ((x - center.as_dvec3()).length(), sigma as f64);
            if r <= cutoff as f64 * s {
                rho * (-r * r / (2.0 * s * s)).exp()
            } else {
                0.0
            }
        }
    };
    (sigma, sigma * p.color.eval_f64(dir))
}

#[test]
fn riemann_sum_agrees_on_a_mixed_scene() {
    // Instance 1: identity, a sphere with a direction-dependent colour, a box and a blob.
    let sh = ShColor::from_coefficients(&[
        Vec3::new(1.2, 0.8, 0.4),
        Vec3::new(0.1, 0.0, 0.0),
        Vec3::new(0.0, 0.2, 0.0),
        Vec3::new(0.0, 0.0, 0.3),
    ])
    .unwrap();
    let first = instance(
        vec![
            sphere([0.0, 0.0, 0.0], 1.0, 0.3, sh),
            cube([0.3, -0.5, -0.5], [1.8, 0.6, 0.4], 0.5, rgb(0.1, 0.9, 0.2)),
            gaussian([0.9, 0.1, 0.0], 0.35, 4.0, 1.5, rgb(1.0, 0.3, 0.0)),
        ],
        DMat4::IDENTITY,
        None,
    );
    // Instance 2: rotated, non-uniformly scaled, moved and cropped; a blob and a sphere.
    let n = DMat4::from_translation(DVec3::new(2.5, 0.2, -0.1))
        * DMat4::from_mat3(DMat3::from_rotation_z(0.4) * DMat3::from_rotation_x(-0.3))
        * DMat4::from_scale(DVec3::new(1.5, 0.7, 1.0));
    let crop = CropBox {
        center: [0.2, 0.0, 0.0],
        scale: [1.6, 3.0, 3.0],
        rotation: [0.1, 0.2, 0.3],
    };
    let second = instance(
        vec![
            gaussian([0.0, 0.0, 0.0], 0.5, 3.0, 2.0, rgb(0.2, 0.2, 1.0)),
            sphere([-0.4, 0.1, 0.0], 0.6, 0.9, rgb(0.9, 0.9, 0.9)),
        ],
        n,
        Some(crop),
    );
    let origin = DVec3::new(-3.0, 0.25, 0.15);
    let dir = DVec3::new(1.0, 0.03, -0.04).normalize();
    let exact = integrate(vec![first.clone(), second.clone()], origin, dir);
    assert!(
        exact.alpha > 0.5,
        "the ray should cross real density: {}",
        exact.alpha
    );
    let first_alone = integrate(vec![first.clone()], origin, dir);
    assert!(
        exact.alpha > first_alone.alpha + 0.05,
        "the second instance should matter: {} vs {}",
        exact.alpha,
        first_alone.alpha
    );

    // The brute force: midpoint rule, 2e6 steps over t ∈ [0, 8], exact per-step opacity.
    let analytic = |inst: &Instance| inst.handle().as_analytic().unwrap().primitives.clone();
    let placed = [
        (first.field_from_world(), analytic(&first), None),
        (second.field_from_world(), analytic(&second), Some(crop)),
    ];
    let inside_crop = |c: &CropBox, x: DVec3| {
        let [roll, pitch, yaw] = c.rotation;
        let rot = DMat3::from_rotation_z(yaw)
            * DMat3::from_rotation_y(pitch)
            * DMat3::from_rotation_x(roll);
        let local = rot.transpose() * (x - DVec3::from(c.center));
        (local.abs() - 0.5 * DVec3::from(c.scale)).max_element() <= 0.0
    };
    let steps = 2_000_000;
    let dt = 8.0 / steps as f64;
    let (mut transmittance, mut color, mut moment) = (1.0f64, DVec3::ZERO, 0.0);
    let mut weights = Vec::with_capacity(steps);
    for i in 0..steps {
        let t = (i as f64 + 0.5) * dt;
        let world = origin + t * dir;
        let (mut sigma, mut sigma_rgb) = (0.0, DVec3::ZERO);
        for (field_from_world, prims, crop) in &placed {
            let x = field_from_world.transform_point3(world);
            let d = field_from_world.transform_vector3(dir);
            let k = d.length();
            if crop.as_ref().is_some_and(|c| !inside_crop(c, x)) {
                continue;
            }
            for p in prims {
                let (s, c) = density_at(p, x, d / k);
                sigma += k * s;
                sigma_rgb += k * c;
            }
        }
        let alpha = 1.0 - (-sigma * dt).exp();
        let w = transmittance * alpha;
        if sigma > 0.0 {
            color += w * sigma_rgb / sigma;
        }
        moment += w * t;
        weights.push((t, w));
        transmittance *= 1.0 - alpha;
    }
    let alpha = 1.0 - transmittance;
    assert_close(exact.alpha, alpha, 1e-5, "alpha");
    for k in 0..3 {
        assert_close(exact.rgb[k], color[k], 1e-5, "colour");
    }
    assert_close(exact.depth_ray, moment / alpha, 1e-5, "depth");
    let mut cumulative = 0.0;
    let median = weights
        .iter()
        .find(|(_, w)| {
            cumulative += w;
            cumulative >= alpha / 2.0
        })
        .map(|(t, _)| *t)
        .unwrap();
    assert_close(exact.depth_median, median, 1e-5, "median");
}

#[test]
fn render_fills_every_plane_per_pixel() {
    // A sphere r = 1, σ = 2 at the origin; a 16 × 12 camera at z = 6 looking down −Z; a
    // window offset into the frame. Through pixel centres, alpha is 1 − e^{−σ·chord} with
    // chord = 2√(r² − b²), b the ray's miss distance; Z = ray depth · z_per_t.
    let inst = instance(
        vec![sphere([0.0; 3], 1.0, 2.0, rgb(0.5, 0.5, 0.5))],
        DMat4::IDENTITY,
        None,
    );
    let scene = Scene::new(vec![inst]);
    let projection = Projection::Perspective(Perspective::from_vertical_fov(16, 12, 30.0).unwrap());
    let camera = Camera::new(
        DMat4::from_translation(DVec3::new(0.0, 0.0, 6.0)),
        projection,
    )
    .unwrap();
    let window = Window::new(3, 2, 15, 11);
    let planes = reference::render(&scene, &camera, window).unwrap();
    assert_eq!((planes.width, planes.height), (12, 9));
    let (alpha, z, ray_depth) = (
        planes.alpha.as_ref().unwrap(),
        planes.depth_z.as_ref().unwrap(),
        planes.depth_ray.as_ref().unwrap(),
    );
    let mut hits = 0;
    for y in 0..9 {
        for x in 0..12 {
            let ray = camera
                .ray((x + 3) as f64 + 0.5, (y + 2) as f64 + 0.5)
                .unwrap();
            let miss = ray.origin.cross(ray.dir).length();
            let chord = 2.0 * (1.0 - miss * miss).max(0.0).sqrt();
            let want = 1.0 - (-2.0 * chord).exp();
            let got = alpha.get(x, y) as f64;
            assert!(
                (got - want).abs() < 1e-6,
                "pixel ({x}, {y}): {got} vs {want}"
            );
            assert!((planes.rgb.as_ref().unwrap()[1].get(x, y) as f64 - 0.5 * want).abs() < 1e-6);
            if chord > 0.0 {
                hits += 1;
                let ratio = z.get(x, y) as f64 / ray_depth.get(x, y) as f64;
                assert!((ratio - ray.z_per_t).abs() < 1e-6);
            } else {
                assert_eq!(z.get(x, y), f32::INFINITY);
                assert_eq!(
                    planes.depth_median.as_ref().unwrap().get(x, y),
                    f32::INFINITY
                );
            }
        }
    }
    assert!(
        hits > 10 && hits < 12 * 9,
        "{hits} hits: the window should show an edge"
    );
}

/// A field that is not analytic.
struct Fog;

impl Field for Fog {
    fn bounds(&self) -> Aabb {
        Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0))
    }
    fn density(&self, _points: &[Vec3], sigma: &mut [f32]) {
        sigma.fill(1.0);
    }
    fn radiance(&self, _points: &[Vec3], _dirs: &[Vec3], rgb: &mut [Vec3]) {
        rgb.fill(Vec3::ONE);
    }
    fn may_be_occupied(&self, _region: &Aabb) -> bool {
        true
    }
}

#[test]
fn non_analytic_fields_are_refused() {
    let fog = Instance::new(
        "fog",
        FieldHandle::new(Arc::new(Fog)),
        DMat4::IDENTITY,
        None,
    )
    .unwrap();
    let scene = Scene::new(vec![fog]);
    let camera = Camera::new(
        DMat4::IDENTITY,
        Projection::Perspective(Perspective::from_vertical_fov(4, 4, 40.0).unwrap()),
    )
    .unwrap();
    match reference::render(&scene, &camera, camera.full_window()) {
        Err(e @ Error::Unsupported(_)) => assert!(e.to_string().contains("fog"), "{e}"),
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("a non-analytic field was rendered"),
    }
}
