use std::sync::Arc;

use glam::Vec3;

use crate::field::{Aabb, Analytic, Capabilities, Field, Span};
use crate::render::{render, render_with_progress, MarchParams, Outputs, Quality, RenderSettings};
use crate::scene::{FieldHandle, FieldSource, Instance, Scene};

/// Occupied only in the cube `[lo, lo + side]³`, exactly.
struct Speck {
    lo: f32,
    side: f32,
}

impl Field for Speck {
    fn bounds(&self) -> Aabb {
        Aabb::new(Vec3::ZERO, Vec3::ONE)
    }
    fn density(&self, _: &[Vec3], sigma: &mut [f32]) {
        sigma.fill(0.0);
    }
    fn radiance(&self, _: &[Vec3], _: &[Vec3], rgb: &mut [Vec3]) {
        rgb.fill(Vec3::ZERO);
    }
    fn may_be_occupied(&self, region: &Aabb) -> bool {
        let (lo, hi) = (Vec3::splat(self.lo), Vec3::splat(self.lo + self.side));
        region.min.cmple(hi).all() && region.max.cmpge(lo).all()
    }
}

/// A ray crossing a speck a hundred-thousandth of the step long (a corner clip of an
/// occupied cell) gets a split point inside it, found well within the search's budget;
/// a ray missing it gets none.
#[test]
fn hidden_point_finds_a_sliver_far_below_the_bisection_depth() {
    let speck = Speck {
        lo: 0.3,
        side: 1e-5,
    };
    let ray = |y: f32| crate::scene::LocalRay {
        origin: Vec3::new(0.0, y, 0.300_005),
        dir: Vec3::X,
        units_per_world: 1.0,
        t_near: 0.0,
        t_far: 1.0,
    };
    let lr = ray(0.300_005);
    let mut queries = super::hidden::HIDDEN_SEARCH_QUERIES;
    let depth = super::hidden::HIDDEN_SEARCH_DEPTH;
    let t = super::hidden::hidden_point(&speck, &lr, 0.0, 1.0, depth, &mut queries);
    let t = t.expect("the sliver is found");
    assert!(speck.may_be_occupied(&Aabb::new(lr.at(t), lr.at(t))), "{t}");
    let mut queries = super::hidden::HIDDEN_SEARCH_QUERIES;
    let missed = super::hidden::hidden_point(&speck, &ray(0.4), 0.0, 1.0, depth, &mut queries);
    assert_eq!(missed, None);
}

/// Hands each sample's position to the colour query as its features and colours from
/// those alone: if the marcher paired features with the wrong samples (or the wrong
/// instance), colours would change.
struct Echo(Analytic);

impl Field for Echo {
    fn bounds(&self) -> Aabb {
        self.0.bounds()
    }
    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        self.0.density(points, sigma)
    }
    fn radiance(&self, _: &[Vec3], _: &[Vec3], _: &mut [Vec3]) {
        unreachable!("the marcher asks for colour with the density pass's features")
    }
    fn feature_count(&self) -> usize {
        3
    }
    fn density_with_features(&self, points: &[Vec3], sigma: &mut [f32], features: &mut [f32]) {
        self.0.density(points, sigma);
        for (p, f) in points.iter().zip(features.chunks_exact_mut(3)) {
            f.copy_from_slice(&p.to_array());
        }
    }
    fn radiance_with_features(
        &self,
        _: &[Vec3],
        dirs: &[Vec3],
        features: &[f32],
        rgb: &mut [Vec3],
    ) {
        let points: Vec<Vec3> = features.chunks_exact(3).map(Vec3::from_slice).collect();
        self.0.radiance(&points, dirs, rgb)
    }
    fn feature_size(&self) -> f32 {
        self.0.feature_size()
    }
    fn capabilities(&self) -> Capabilities {
        self.0.capabilities()
    }
    fn density_bounds(&self, regions: &[Aabb], bounds: &mut [f32]) {
        self.0.density_bounds(regions, bounds)
    }
    fn spans(&self, o: Vec3, d: Vec3, t0: f64, t1: f64, out: &mut Vec<Span>) {
        self.0.spans(o, d, t0, t1, out)
    }
    fn may_be_occupied(&self, region: &Aabb) -> bool {
        self.0.may_be_occupied(region)
    }
}

/// A field that answers every third density sample with NaN, +inf or −inf in turn.
struct Poisoned(Analytic);

impl Field for Poisoned {
    fn bounds(&self) -> Aabb {
        self.0.bounds()
    }
    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        self.0.density(points, sigma);
        let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
        for (i, s) in sigma.iter_mut().enumerate().filter(|(i, _)| i % 3 == 0) {
            *s = bad[i / 3 % 3];
        }
    }
    fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]) {
        self.0.radiance(points, dirs, rgb)
    }
    fn may_be_occupied(&self, region: &Aabb) -> bool {
        self.0.may_be_occupied(region)
    }
}

fn demo_with(object: impl Fn(Analytic) -> Arc<dyn Field>) -> (Scene, crate::camera::Camera) {
    let (plain, camera) = crate::demo::scene_and_camera(48, 27).unwrap();
    let desc = crate::demo::scene_desc();
    let instances: Vec<Instance> = plain
        .marched()
        .zip(&desc.instances)
        .map(|(inst, d)| {
            let FieldSource::Analytic(a) = &d.field else {
                unreachable!("the demo is analytic")
            };
            let handle = if inst.name == "object" {
                FieldHandle::new(object(a.clone()))
            } else {
                inst.handle().clone()
            };
            Instance::new(inst.name.clone(), handle, inst.world_from_field(), None).unwrap()
        })
        .collect();
    (Scene::new(instances), camera)
}

fn assert_finite(planes: &crate::image::Planes) {
    let alpha = planes.alpha.as_ref().unwrap();
    assert!(alpha.data.iter().all(|a| (0.0..=1.0).contains(a)));
    for plane in planes.rgb.as_ref().unwrap() {
        assert!(plane.data.iter().all(|c| c.is_finite() && *c >= 0.0));
    }
}

fn node(t: f64, sigma: f64) -> super::Node {
    super::Node {
        t,
        probe: t,
        sigma,
        slot: 0,
        starts_run: false,
        exact: false,
        extent: 0.0,
        weight: 0.0,
        depth: 0.0,
        difference: f64::NAN,
    }
}

#[test]
fn a_bump_between_ends_of_equal_density_is_judged_by_its_curvature() {
    // σ = 0, 5, 5, 0 at t = 0, 1, 2, 3: the middle step has no jump, but the density
    // turns over inside it.
    let nodes = [
        node(0.0, 0.0),
        node(1.0, 5.0),
        node(2.0, 5.0),
        node(3.0, 0.0),
    ];
    assert_eq!(super::refinement::step_change(&nodes, 1), 0.0);
    assert_eq!(super::refinement::smooth_change(&nodes, 1), 5.0);
    // A steady slope has none.
    let slope = [
        node(0.0, 1.0),
        node(1.0, 2.0),
        node(2.0, 3.0),
        node(3.0, 4.0),
    ];
    assert_eq!(super::refinement::smooth_change(&slope, 1), 0.0);
    // Without neighbours, the denser end.
    assert_eq!(super::refinement::smooth_change(&slope[1..3], 0), 3.0);
}

/// On a cubic density the trapezoid rule's bias is exact, steps of any lengths: the
/// trapezoid's optical depth less it is the integral, to rounding. Without a node on either
/// side in the run, or over nodes further apart than the smooth length, there is none.
#[test]
fn a_steps_trapezoid_bias_is_exact_for_a_cubic() {
    use super::refinement::{trapezoid_bias, LastDifference};
    let bias = |nodes: &[super::Node], i, smooth| {
        trapezoid_bias(nodes, i, 0, &mut LastDifference::default(), smooth)
    };
    let cubic = |t: f64| 2.0 + t - 0.5 * t * t + 0.3 * t * t * t;
    let integral = |t: f64| 2.0 * t + 0.5 * t * t - t * t * t / 6.0 + 0.075 * t.powi(4);
    let nodes: Vec<_> = [0.0, 0.5, 1.5, 2.25]
        .iter()
        .map(|&t| node(t, cubic(t)))
        .collect();
    let (a, b) = (&nodes[1], &nodes[2]);
    let trapezoid = 0.5 * (b.t - a.t) * (a.sigma + b.sigma);
    let exact = integral(b.t) - integral(a.t);
    assert!(
        (trapezoid - exact).abs() > 1e-3,
        "the cubic bends over the step"
    );
    let unbiased = trapezoid - bias(&nodes, 1, 2.25).unwrap();
    assert!((unbiased - exact).abs() < 1e-12, "{unbiased} ≠ {exact}");
    // Four nodes further apart than the field is smooth, or a run cut short: none.
    assert_eq!(bias(&nodes, 1, 2.2), None);
    assert_eq!((bias(&nodes, 0, 9.0), bias(&nodes, 2, 9.0)), (None, None));
    for k in [1, 3] {
        let mut cut = nodes.clone();
        cut[k].starts_run = true;
        assert_eq!(bias(&cut, 1, 9.0), None, "a run starts at node {k}");
    }
}

/// A step's curvature is the same, bit for bit, whether its second differences are worked
/// out afresh or kept from the step before ([`super::refinement::LastDifference`]): seeded
/// rays of nodes (runs starting anywhere, repeated positions), their steps visited in order,
/// backwards and at random, two rays interleaved on one memo.
#[test]
fn a_kept_second_difference_gives_the_curvature_worked_out_afresh() {
    use super::refinement::{step_curvature, LastDifference};
    use crate::rng::SplitMix64;

    let mut rng = SplitMix64::new(3);
    let mut ray = || {
        let mut t = 0.0;
        (0..2 + rng.next_u64() % 14)
            .map(|_| {
                if rng.unit() > 0.1 {
                    t += f64::from(rng.unit()) * 0.5;
                }
                let mut n = node(t, f64::from(rng.unit()) * 40.0);
                n.starts_run = rng.unit() < 0.15;
                n
            })
            .collect::<Vec<_>>()
    };
    let fresh = |nodes: &[super::Node], i| {
        step_curvature(nodes, i, 0, &mut LastDifference::default()).map(|c| c.map(f64::to_bits))
    };
    for _ in 0..2000 {
        let rays = [ray(), ray()];
        let mut visits: Vec<(u32, usize)> = (0..2u32)
            .flat_map(|r| (0..rays[r as usize].len() - 1).map(move |i| (r, i)))
            .collect();
        for order in 0..3 {
            match order {
                1 => visits.reverse(),
                2 => visits.sort_by_key(|&(r, i)| (i * 7 + r as usize * 3) % 5),
                _ => {}
            }
            let mut last = LastDifference::default();
            for &(r, i) in &visits {
                let nodes = &rays[r as usize];
                let kept = step_curvature(nodes, i, r, &mut last).map(|c| c.map(f64::to_bits));
                assert_eq!(kept, fresh(nodes, i), "ray {r} step {i}");
            }
        }
    }
}

#[test]
fn a_trained_run_one_step_long_is_judged_by_its_denser_end() {
    use super::refinement::exact_change;
    // Equal ends, a run of their own: no jump and no curvature, yet a trained field's bump
    // may lie between (an analytic field's spans end at its peaks: the jump bounds them).
    let (mut a, b) = (node(0.0, 4.0), node(1.0, 4.0));
    a.starts_run = true;
    assert_eq!(exact_change(&a, &b, [None, None], true), 4.0);
    assert_eq!(exact_change(&a, &b, [None, None], false), 0.0);
    // So is a step alone in a later round of its run.
    a.starts_run = false;
    assert_eq!(exact_change(&a, &b, [None, None], true), 4.0);
    // With a neighbour on one side, the larger of the jump and that side's curvature.
    let c = node(2.0, 5.0);
    assert_eq!(exact_change(&b, &c, [Some(0.5), None], true), 1.0);
    assert_eq!(exact_change(&b, &c, [Some(3.0), None], true), 3.0);
    // With both, the curvature alone.
    assert_eq!(exact_change(&b, &c, [Some(0.0), Some(0.25)], true), 0.25);
}

#[test]
fn transmittance_inside_a_round_goes_through_the_lower_end_of_each_step() {
    let mut nodes = [
        node(0.0, 0.0),
        node(1.0, 2.0),
        node(1.5, 4.0),
        node(2.0, 1.0),
    ];
    let mut cut = nodes;
    super::refinement::lay_depths_and_differences(&mut nodes);
    assert_eq!(super::refinement::transmittance_at(0.5, &nodes, 0), 0.5);
    // The first step may hold its edge anywhere: no depth from it.
    assert_eq!(super::refinement::transmittance_at(0.5, &nodes, 1), 0.5);
    let want = 0.5 * (-(0.5 * 2.0 + 0.5 * 1.0f64)).exp();
    assert!((super::refinement::transmittance_at(0.5, &nodes, 3) - want).abs() < 1e-15);
    // A run's start joins nothing to the node before it.
    cut[2].starts_run = true;
    super::refinement::lay_depths_and_differences(&mut cut);
    let want = 0.5 * (-(0.5 * 1.0f64)).exp();
    assert!((super::refinement::transmittance_at(0.5, &cut, 3) - want).abs() < 1e-15);
}

#[test]
fn non_finite_densities_are_empty_and_counted() {
    let (scene, camera) = demo_with(|a| Arc::new(Poisoned(a)));
    let settings = RenderSettings::new(Quality::Preview.params(), Outputs::all());
    let (planes, stats) =
        render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {}).unwrap();
    assert_finite(&planes);
    assert!(stats.invalid_samples > 0);
    assert!(stats.warning().unwrap().contains("NaN or infinite"));
}

#[test]
fn rays_out_of_budget_stop_and_are_counted() {
    let (scene, camera) = demo_with(|a| Arc::new(a));
    let final_params = Quality::Final.params();
    let render = |max_samples| {
        let params = MarchParams {
            max_samples,
            ..final_params
        };
        let settings = RenderSettings::new(params, Outputs::all());
        render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {}).unwrap()
    };
    let (planes, stats) = render(final_params.max_samples);
    assert_finite(&planes);
    assert_eq!(stats.budget_limited_rays, 0);
    assert_eq!(stats.warning(), None);
    let (short, stats) = render(6);
    assert_finite(&short);
    assert!(stats.budget_limited_rays > 0 && stats.budget_limited_rays <= stats.pixels);
    assert!(stats.warning().unwrap().contains("sample budget"));
    // A ray stopped early has composited less, never more.
    let (a, b) = (short.alpha.unwrap(), planes.alpha.unwrap());
    assert!(a.data.iter().zip(&b.data).all(|(s, f)| *s <= f + 1e-6));
    assert!(a.data.iter().zip(&b.data).any(|(s, f)| *s < f - 1e-3));
}

/// An 8×8 grid of small balls facing a 64×48 camera, one ball behind it and one far to its
/// side: tiles see a few balls each, and no tile sees the last two.
fn ball_grid() -> (Scene, crate::camera::Camera) {
    use crate::camera::{Camera, Perspective, Projection};
    use crate::field::{Primitive, ShColor, Shape};
    use glam::{DMat4, DVec3};

    let ball = FieldHandle::analytic(Analytic {
        primitives: vec![Primitive {
            shape: Shape::Sphere {
                center: Vec3::ZERO,
                radius: 0.1,
            },
            density: 1.0,
            color: ShColor::constant(Vec3::ONE),
        }],
    });
    let mut at: Vec<DVec3> = (0..64)
        .map(|k| {
            DVec3::new(
                -1.0 + 0.25 * (k % 8) as f64 + 0.125,
                0.0,
                -1.0 + 0.25 * (k / 8) as f64 + 0.125,
            )
        })
        .collect();
    at.extend([DVec3::new(0.0, -8.0, 0.0), DVec3::new(30.0, 0.0, 0.0)]);
    let instances: Vec<Instance> = at
        .iter()
        .enumerate()
        .map(|(k, p)| {
            Instance::new(
                format!("ball {k}"),
                ball.clone(),
                DMat4::from_translation(*p),
                None,
            )
            .unwrap()
        })
        .collect();
    let p = Perspective::from_vertical_fov(64, 48, 40.0).unwrap();
    let eye = crate::demo::look_at(DVec3::new(0.0, -4.0, 0.0), DVec3::ZERO);
    let camera = Camera::new(eye, Projection::Perspective(p)).unwrap();
    (Scene::new(instances), camera)
}

#[test]
fn tile_culling_keeps_every_instance_a_ray_of_the_tile_meets() {
    let (scene, camera) = ball_grid();
    let plans =
        super::InstancePlan::for_scene(&scene, scene.composite_space(), &Quality::Draft.params());
    let (mut keep, mut kept, mut met) = (Vec::new(), 0, 0);
    for (x0, y0) in (0..4).flat_map(|i| (0..3).map(move |j| (16 * i, 16 * j))) {
        let rays: Vec<_> = (0..256)
            .map(|k| camera.ray((x0 + k % 16) as f64 + 0.5, (y0 + k / 16) as f64 + 0.5))
            .collect();
        let cone = super::plan::RayCone::of(&rays, 16, camera.rectilinear());
        super::plan::cull_instances(&plans, cone.as_ref(), &mut keep);
        for (i, inst) in scene.marched().enumerate() {
            let meets = rays
                .iter()
                .flatten()
                .any(|r| inst.local_ray(r, r.near, r.far).is_some());
            let kept_i = keep.contains(&(i as u32));
            assert!(
                kept_i || !meets,
                "tile ({x0}, {y0}) culled instance {i}, which a ray meets"
            );
            kept += usize::from(kept_i);
            met += usize::from(meets);
        }
        assert!(!keep.contains(&64) && !keep.contains(&65));
    }
    // Conservative, yet close: a tile keeps a few balls per ball it meets (the sphere
    // around a ball's box, and the cone around the tile's rays, are wider than both).
    assert!(met > 0 && kept <= 3 * met, "kept {kept}, met {met}");
}

/// A tile's culled analytic field ([`super::plan::TileFields`]) gives the whole field's
/// spans, densities and colours, bit for bit, along every ray of the tile as the marcher
/// sees it (its `f32` local ray), and leaves out most primitives no ray meets: a scattered
/// field of small balls, boxes and Gaussians, rotated, scaled and moved into the world,
/// seen by tiles of a perspective camera.
/// A scene of `field` placed by `world_from_field` and a `width`×`height` pinhole camera with a vertical field of view of `fov` degrees at `eye`,
/// looking at the origin.
fn placed_and_seen(
    field: &Analytic,
    world_from_field: glam::DMat4,
    (width, height, fov): (u32, u32, f64),
    eye: glam::DVec3,
) -> (Scene, crate::camera::Camera) {
    use crate::camera::{Camera, Perspective, Projection};
    let scene = Scene::new(vec![Instance::new(
        "placed",
        FieldHandle::analytic(field.clone()),
        world_from_field,
        None,
    )
    .unwrap()]);
    let p = Perspective::from_vertical_fov(width, height, fov).unwrap();
    let eye = crate::demo::look_at(eye, glam::DVec3::ZERO);
    let camera = Camera::new(eye, Projection::Perspective(p)).unwrap();
    (scene, camera)
}

/// A pinhole tile's pyramid culls a long thin box (a pillar, leaning, in a rotated and
/// stretched instance) from the tiles beside it whose cone takes in its loose sphere, and
/// keeps it for every tile one of whose rays meets it.
#[test]
fn a_tiles_pyramid_culls_a_thin_box_and_keeps_it_where_a_ray_meets_it() {
    use crate::field::{Primitive, ShColor, Shape};
    use glam::{DMat4, DQuat, DVec3};

    let pillar = Primitive {
        shape: Shape::Box {
            min: Vec3::new(-0.1, -0.1, -2.0),
            max: Vec3::new(0.1, 0.1, 2.0),
        },
        density: 5.0,
        color: ShColor::constant(Vec3::ONE),
    };
    let field = Analytic {
        primitives: vec![pillar],
    };
    let world_from_field = DMat4::from_scale_rotation_translation(
        DVec3::new(1.3, 0.8, 1.0),
        DQuat::from_euler(glam::EulerRot::XYZ, 0.2, 0.4, -0.3),
        DVec3::new(0.3, 0.1, 0.0),
    );
    let (scene, camera) = placed_and_seen(
        &field,
        world_from_field,
        (160, 96, 60.0),
        DVec3::new(0.5, -4.0, 0.5),
    );
    let plans =
        super::InstancePlan::for_scene(&scene, scene.composite_space(), &Quality::Draft.params());
    assert!(camera.rectilinear());
    let (mut pyramid_culled, mut met) = (0, 0);
    for (x0, y0) in (0..10).flat_map(|i| (0..6).map(move |j| (16 * i, 16 * j))) {
        let rays: Vec<_> = (0..256)
            .map(|k| camera.ray((x0 + k % 16) as f64 + 0.5, (y0 + k / 16) as f64 + 0.5))
            .collect();
        let pyramid = super::plan::RayCone::of(&rays, 16, true).expect("a narrow tile");
        let kept = plans[0].primitives_met(1, Some(&pyramid)).count() == 1;
        let cone = super::plan::RayCone::of(&rays, 16, false).expect("a narrow tile");
        let cone_kept = plans[0].primitives_met(1, Some(&cone)).count() == 1;
        let meets = rays.iter().flatten().any(|r| {
            plans[0]
                .instance
                .local_ray(r, r.near, r.far)
                .is_some_and(|lr| {
                    let length = (lr.t_far - lr.t_near) * f64::from(lr.units_per_world);
                    let mut spans = Vec::new();
                    field.spans(lr.origin, lr.dir, 0.0, length, &mut spans);
                    !spans.is_empty()
                })
        });
        assert!(kept || !meets, "tile ({x0}, {y0}) meets the pillar");
        assert!(cone_kept || !kept, "tile ({x0}, {y0})");
        met += usize::from(meets);
        pyramid_culled += usize::from(cone_kept && !kept);
    }
    // 9 and 23 here.
    assert!(met >= 6, "{met} tiles meet the pillar");
    assert!(
        pyramid_culled >= 12,
        "{pyramid_culled} tiles culled by the pyramid alone"
    );
}

#[test]
fn a_tiles_culled_field_is_the_whole_field_along_its_rays() {
    use crate::field::{Primitive, ShColor, Shape};
    use crate::rng::SplitMix64;
    use glam::{DMat4, DQuat, DVec3};

    let mut rng = SplitMix64::new(5);
    let primitives: Vec<_> = (0..48)
        .map(|k| {
            let c = rng.in_cube(-2.0, 2.0);
            let r = 0.05 + 0.1 * (k % 3) as f32;
            let shape = match k % 3 {
                0 => Shape::Sphere {
                    center: c,
                    radius: r,
                },
                1 => Shape::Box {
                    min: c - r,
                    max: c + r,
                },
                _ => Shape::Gaussian {
                    center: c,
                    sigma: 0.5 * r,
                    cutoff: 3.0,
                },
            };
            Primitive {
                shape,
                density: 1.0 + k as f32,
                color: ShColor::constant(Vec3::new(1.0, 0.1 * (k % 7) as f32, 0.5)),
            }
        })
        .collect();
    let field = Analytic { primitives };
    let world_from_field = DMat4::from_scale_rotation_translation(
        DVec3::new(1.5, 0.7, 1.1),
        DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 1.1),
        DVec3::new(0.4, 0.2, -0.3),
    );
    let (scene, camera) = placed_and_seen(
        &field,
        world_from_field,
        (96, 64, 50.0),
        DVec3::new(1.0, -7.0, 2.0),
    );
    let plans =
        super::InstancePlan::for_scene(&scene, scene.composite_space(), &Quality::Draft.params());
    let (mut keep, mut tile_fields) = (Vec::new(), super::plan::TileFields::default());
    let (mut kept, mut seen, mut samples) = (0, 0, 0);
    for (x0, y0) in (0..6).flat_map(|i| (0..4).map(move |j| (16 * i, 16 * j))) {
        let rays: Vec<_> = (0..256)
            .map(|k| camera.ray((x0 + k % 16) as f64 + 0.5, (y0 + k / 16) as f64 + 0.5))
            .collect();
        let cone = super::plan::RayCone::of(&rays, 16, camera.rectilinear());
        super::plan::cull_instances(&plans, cone.as_ref(), &mut keep);
        tile_fields.cull(&plans, cone.as_ref(), &keep);
        let tile_field = tile_fields.field(&plans, 0);
        for lr in rays
            .iter()
            .flatten()
            .filter_map(|r| plans[0].instance.local_ray(r, r.near, r.far))
        {
            let length = (lr.t_far - lr.t_near) * lr.units_per_world as f64;
            let (mut whole, mut culled) = (Vec::new(), Vec::new());
            assert!(field.capabilities().spans && tile_field.capabilities().spans);
            field.spans(lr.origin, lr.dir, 0.0, length, &mut whole);
            tile_field.spans(lr.origin, lr.dir, 0.0, length, &mut culled);
            assert_eq!(whole, culled);
            let points: Vec<_> = (0..=256)
                .map(|k| lr.at(lr.t_near + (lr.t_far - lr.t_near) * k as f64 / 256.0))
                .collect();
            let dirs = vec![lr.dir; points.len()];
            let (mut a, mut b) = (vec![0.0; points.len()], vec![0.0; points.len()]);
            field.density(&points, &mut a);
            tile_field.density(&points, &mut b);
            assert_eq!(a, b, "tile ({x0}, {y0})");
            samples += a.iter().filter(|&&s| s > 0.0).count();
            let (mut a, mut b) = (
                vec![Vec3::ZERO; points.len()],
                vec![Vec3::ZERO; points.len()],
            );
            field.radiance(&points, &dirs, &mut a);
            tile_field.radiance(&points, &dirs, &mut b);
            assert_eq!(a, b, "tile ({x0}, {y0})");
        }
        // A primitive is held where the tile's field has the whole one's density at its
        // centre (few overlap).
        for p in &field.primitives {
            let centre = match p.shape {
                Shape::Sphere { center, .. } | Shape::Gaussian { center, .. } => center,
                Shape::Box { min, max } => 0.5 * (min + max),
            };
            let (mut a, mut b) = ([0.0], [0.0]);
            field.density(&[centre], &mut a);
            tile_field.density(&[centre], &mut b);
            kept += usize::from(a == b);
            seen += 1;
        }
    }
    assert!(samples > 1000, "{samples} samples with density");
    assert!(kept < seen / 3, "kept {kept} of {seen}");
}

/// A ray's list of instances, which its nodes keep densities for, holds exactly those it
/// meets: found through the tile's culling and [`may_meet`](super::plan::may_meet), the same
/// as asking every instance. And `may_meet` stays close: few rays ask an instance's local
/// ray without meeting it.
#[test]
fn a_ray_lists_exactly_the_instances_it_meets() {
    let (scene, camera) = ball_grid();
    let settings = RenderSettings::new(Quality::Draft.params(), Outputs::rgba());
    let window = camera.full_window();
    let samplers =
        crate::render::samplers::Samplers::for_scene(&scene, &camera, window, &settings).unwrap();
    let plans = &samplers.plans;
    let mut s = super::Scratch::default();
    let (mut met, mut asked) = (0, 0);
    for (x0, y0) in (0..4).flat_map(|i| (0..3).map(move |j| (16 * i, 16 * j))) {
        let tile = crate::image::Window::new(x0, y0, x0 + 16, y0 + 16);
        super::setup::setup_rays(
            plans,
            &samplers.volume,
            None,
            &camera,
            tile,
            &Outputs::rgba(),
            false,
            &mut s,
        );
        for (r, ray) in s.world_rays.clone().iter().enumerate() {
            let ray = ray.unwrap();
            let listed: Vec<u32> = super::met_by(&s, r).iter().map(|m| m.inst).collect();
            let meets: Vec<u32> = (0..plans.len() as u32)
                .filter(|&i| {
                    let inst = plans[i as usize].instance;
                    inst.local_ray(&ray, ray.near, ray.far).is_some()
                })
                .collect();
            assert_eq!(listed, meets, "ray {r} of tile ({x0}, {y0})");
            met += meets.len();
            asked += plans
                .iter()
                .filter(|p| super::plan::may_meet(p, &ray))
                .count();
        }
    }
    assert!(met > 0 && asked <= 5 * met, "asked {asked}, met {met}");
}

/// The median depth from a log cut where [`super::RayState::log_piece`] cuts it is the
/// full log's, bit for bit: seeded rays of pieces (some of them fragments, `δ = 0`, some
/// after a fragment's drop in transmittance), every share of the pixel's alpha.
#[test]
fn a_cut_median_log_gives_the_full_logs_depth() {
    use crate::render::integrator::crossing_depth;
    use crate::rng::SplitMix64;

    let mut rng = SplitMix64::new(11);
    let mut cut_short = 0;
    for _ in 0..4000 {
        let (mut state, mut full) = (super::RayState::default(), Vec::new());
        let (mut t, mut transmittance) = (1.0, 1.0f64);
        for _ in 0..1 + rng.next_u64() % 24 {
            let delta = if rng.unit() < 0.2 {
                0.0
            } else {
                f64::from(rng.range(0.0, 0.3))
            };
            let scale = f64::from(rng.range(0.0, 6.0)).powi(2);
            let (x0, x1) = (
                scale * delta * f64::from(rng.unit()),
                scale * delta * f64::from(rng.unit()),
            );
            let piece = [t, delta, x0, x1, transmittance];
            full.push(piece);
            state.log_piece(piece);
            t += delta + f64::from(rng.range(0.0, 0.1));
            transmittance *= (-0.5 * (x0 + x1)).exp();
            if rng.unit() < 0.1 {
                transmittance *= f64::from(rng.unit());
            }
        }
        cut_short += usize::from(state.log.len() < full.len());
        for alpha in [1.0 - transmittance, 0.3 * (1.0 - transmittance), 1.0] {
            let (want, got) = (
                crossing_depth(&full, 0.5 * alpha),
                crossing_depth(&state.log, 0.5 * alpha),
            );
            assert_eq!(want.to_bits(), got.to_bits(), "{full:?}, alpha {alpha}");
        }
    }
    assert!(
        cut_short > 100,
        "the seeded rays exercise the cut: {cut_short}"
    );
}

#[test]
fn features_reach_the_colour_query_of_their_own_samples() {
    let (plain, camera) = crate::demo::scene_and_camera(48, 27).unwrap();
    // The object instance echoes its features, the environment does not: offsets into
    // a node's features must keep them apart.
    let (echo, _) = demo_with(|a| Arc::new(Echo(a)));
    // Both marched: the plain demo's fields are analytic.
    let params = MarchParams {
        closed_form: false,
        ..Quality::Preview.params()
    };
    let settings = RenderSettings::new(params, Outputs::rgba());
    let want = render(&plain, &camera, camera.full_window(), &settings).unwrap();
    let got = render(&echo, &camera, camera.full_window(), &settings).unwrap();
    assert_eq!(got, want);
}

#[test]
fn the_step_rule_grows_only_where_a_curvature_allows_it() {
    use super::integration::allowed_step;
    let params = crate::render::Quality::Final.params();
    // A linear density (curvature measured zero): no bound from the rule.
    assert_eq!(allowed_step(0.0, &params), f64::INFINITY);
    // An infinite or undefined curvature: the finest step, never the longest.
    assert_eq!(allowed_step(f64::INFINITY, &params), 0.0);
    assert_eq!(allowed_step(f64::NAN, &params), 0.0);
    // Otherwise the step whose estimate `rate·δ³` is half the target.
    let rate = 1e3;
    let step = allowed_step(rate, &params);
    let estimate = rate * step.powi(3);
    assert!((estimate / f64::from(params.error_target) - 0.5).abs() < 1e-12);
}

/// A primitive's world sphere holds its support, placed by a rotated, non-uniformly scaled
/// (also with two equal scales) and moved transform, and is tighter than the sphere around
/// the world box of the primitive's bounds: points of each support (a ball's or blob's
/// surface, a box's corners and faces) all lie within it, and some reach nearly its radius.
#[test]
fn a_primitives_world_sphere_holds_its_support_and_no_more_than_needed() {
    use crate::field::{Primitive, ShColor, Shape};
    use crate::rng::SplitMix64;
    use glam::{DMat4, DQuat, DVec3};

    let shapes = [
        Shape::Sphere {
            center: Vec3::new(0.5, -1.0, 0.25),
            radius: 0.3,
        },
        Shape::Box {
            min: Vec3::new(-1.0, 0.2, -0.4),
            max: Vec3::new(-0.2, 0.5, 0.9),
        },
        Shape::Gaussian {
            center: Vec3::new(1.2, 0.8, -0.6),
            sigma: 0.1,
            cutoff: 3.0,
        },
    ];
    let primitives: Vec<_> = shapes
        .iter()
        .map(|&shape| Primitive {
            shape,
            density: 1.0,
            color: ShColor::constant(Vec3::ONE),
        })
        .collect();
    // Points of a support: a ball's surface (a spiral of directions), a box's corners and
    // points of its faces.
    let mut rng = SplitMix64::new(11);
    let support = |shape: &Shape, rng: &mut SplitMix64| -> Vec<DVec3> {
        let ball = |c: Vec3, r: f32| -> Vec<DVec3> {
            let n = 4000;
            (0..n)
                .map(|k| {
                    let z = 1.0 - (2 * k + 1) as f64 / n as f64;
                    let phi = k as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                    let rho = (1.0 - z * z).sqrt();
                    c.as_dvec3() + f64::from(r) * DVec3::new(rho * phi.cos(), rho * phi.sin(), z)
                })
                .collect()
        };
        match *shape {
            Shape::Sphere { center, radius } => ball(center, radius),
            Shape::Gaussian {
                center,
                sigma,
                cutoff,
            } => ball(center, cutoff * sigma),
            Shape::Box { min, max } => {
                let (lo, hi) = (min.as_dvec3(), max.as_dvec3());
                let mut points: Vec<_> = (0..8)
                    .map(|k| {
                        DVec3::select(glam::BVec3::new(k & 1 == 0, k & 2 == 0, k & 4 == 0), lo, hi)
                    })
                    .collect();
                for k in 0..600 {
                    let u = rng.in_cube(0.0, 1.0).as_dvec3();
                    let mut p = lo + u * (hi - lo);
                    p[k % 3] = if k % 2 == 0 { lo[k % 3] } else { hi[k % 3] };
                    points.push(p);
                }
                points
            }
        }
    };
    for scale in [DVec3::new(2.0, 0.5, 1.2), DVec3::new(1.5, 0.6, 1.5)] {
        let world_from_field = DMat4::from_scale_rotation_translation(
            scale,
            DQuat::from_euler(glam::EulerRot::XYZ, 0.4, -0.9, 0.7),
            DVec3::new(3.0, -1.0, 0.5),
        );
        let field = Analytic {
            primitives: primitives.clone(),
        };
        let scene = Scene::new(vec![Instance::new(
            "primitives",
            FieldHandle::analytic(field),
            world_from_field,
            None,
        )
        .unwrap()]);
        let plans = super::InstancePlan::for_scene(
            &scene,
            scene.composite_space(),
            &Quality::Draft.params(),
        );
        for (shape, sphere) in shapes.iter().zip(&plans[0].primitive_spheres) {
            let (centre, radius) = sphere.expect("a finite primitive has a sphere");
            let farthest = support(shape, &mut rng)
                .iter()
                .map(|&p| world_from_field.transform_point3(p).distance(centre))
                .fold(0.0, f64::max);
            assert!(
                farthest <= radius,
                "{shape:?} at {scale}: {farthest} > {radius}"
            );
            assert!(
                farthest >= 0.97 * radius,
                "{shape:?} at {scale}: {farthest} of {radius}"
            );
            // The sphere around the world box of the bounds, as the culling had it.
            let b = shape.bounds();
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for k in 0..8 {
                let corner = Vec3::select(
                    glam::BVec3::new(k & 1 == 0, k & 2 == 0, k & 4 == 0),
                    b.min,
                    b.max,
                );
                let w = world_from_field.transform_point3(corner.as_dvec3());
                (lo, hi) = (lo.min(w), hi.max(w));
            }
            let loose = 0.5 * (hi - lo).length();
            assert!(
                radius < 0.95 * loose,
                "{shape:?} at {scale}: {radius} of {loose}"
            );
        }
    }
}
