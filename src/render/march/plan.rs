//! What the marcher works out once per instance and frame, and which instances a tile's rays
//! may meet.

use glam::{DVec3, Vec3};

use super::InstancePlan;
use crate::camera::Ray;
use crate::field::{Aabb, ColorSpace, Span};
use crate::render::MarchParams;
use crate::scene::Scene;

impl InstancePlan {
    pub(in crate::render) fn for_scene(scene: &Scene, params: &MarchParams) -> Vec<InstancePlan> {
        let space = scene.composite_space();
        scene
            .instances
            .iter()
            .map(|inst| {
                let spans =
                    inst.field()
                        .spans(Vec3::ZERO, Vec3::X, 0.0, 0.0, &mut Vec::<Span>::new());
                let exact = spans
                    || inst
                        .field()
                        .mask_segments(Vec3::ZERO, Vec3::X, 0.0, 0.0, &mut Vec::new());
                let occupancy =
                    (!exact).then(|| inst.handle().occupancy(params.occupancy_resolution));
                let bounded = inst
                    .field()
                    .density_bounds(&[inst.field().bounds()], &mut [0.0]);
                // Without bounds, gaps may hide between samples: a field with spans or
                // mask segments has none unseen; one with an occupancy grid has its steps
                // probed for them.
                let cell = match &occupancy {
                    Some(o) if !bounded => {
                        o.bounds().size().min_element() as f64 / f64::from(o.resolution().max(1))
                    }
                    _ => f64::INFINITY,
                };
                InstancePlan {
                    occupancy,
                    base_step: inst.field().feature_size() as f64
                        / params.steps_per_feature.max(1e-3) as f64,
                    features: inst.field().feature_count(),
                    smooth: inst.field().smooth_length().max(0.0) as f64,
                    encode: space == ColorSpace::Srgb
                        && inst.field().color_space() == ColorSpace::Linear,
                    unbounded: inst.field().unbounded(),
                    bounded,
                    cell,
                    world_sphere: world_sphere(inst.field().bounds(), inst.world_from_field()),
                }
            })
            .collect()
    }
}

/// The smallest world sphere around the world box of a field's bounds `b` (its eight
/// corners placed by `world_from_field`); `None` where they are empty or not finite.
fn world_sphere(b: Aabb, world_from_field: glam::DMat4) -> Option<(DVec3, f64)> {
    if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
        return None;
    }
    let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
    let (mut wlo, mut whi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for k in 0..8 {
        let corner = DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let w = world_from_field.transform_point3(corner);
        (wlo, whi) = (wlo.min(w), whi.max(w));
    }
    let centre = 0.5 * (wlo + whi);
    let radius = 0.5 * (whi - wlo).length();
    (centre.is_finite() && radius.is_finite()).then_some((centre, radius))
}

/// Lists in `keep`, ascending, the instances some ray of a tile may meet. The rays start
/// within `ρ` of their mean origin `c` and point within `θ` of their mean direction `m`:
/// such a ray meets a sphere `(b, R)` only if the ray from `c` along its direction meets
/// `(b, R + ρ)`, which needs the angle `α` between `m` and `b − c` to be at most `θ + β`,
/// `β = asin((R + ρ)/|b − c|)`; as both sides lie in `[0, π)`, that is
/// `cos α ≥ cos θ cos β − sin θ sin β`, no trigonometry per instance. A wide bundle (`θ` of
/// 90° or more: panoramic tiles) and unbounded instances keep all. This makes a tile's
/// setup cost per instance, not per instance and pixel.
pub(super) fn cull_instances(plans: &[InstancePlan], rays: &[Option<Ray>], keep: &mut Vec<u32>) {
    keep.clear();
    keep.extend(0..plans.len() as u32);
    let (mut origin, mut dir, mut n) = (DVec3::ZERO, DVec3::ZERO, 0.0);
    for ray in rays.iter().flatten() {
        origin += ray.origin;
        dir += ray.dir;
        n += 1.0;
    }
    // No rays, or directions that cancel out: nothing to cull by.
    let Some(m) = dir.try_normalize() else {
        return;
    };
    let c = origin / n;
    let (mut rho, mut cos_theta) = (0.0f64, 1.0f64);
    for ray in rays.iter().flatten() {
        rho = rho.max((ray.origin - c).length());
        cos_theta = cos_theta.min(ray.dir.dot(m) / ray.dir.length());
    }
    // NaN directions fail this too.
    if cos_theta.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !rho.is_finite() {
        return;
    }
    // A margin for rounding in the angles.
    let theta = cos_theta.min(1.0).acos() + 1e-6;
    let (sin_theta, cos_theta) = theta.sin_cos();
    keep.retain(|&i| {
        let Some((b, radius)) = plans[i as usize].world_sphere else {
            return true;
        };
        let v = b - c;
        let (l, reach) = (v.length(), radius + rho);
        if l <= reach * (1.0 + 1e-9) {
            return true;
        }
        let sin_beta = reach / l;
        let cos_beta = (1.0 - sin_beta * sin_beta).sqrt();
        v.dot(m) / l >= cos_theta * cos_beta - sin_theta * sin_beta - 1e-9
    });
}

/// Whether `ray` passes within the instance's world sphere (one without a sphere always
/// may): conservative, like [`cull_instances`], and a few multiplications where
/// [`Instance::local_ray`](crate::scene::Instance::local_ray) carries the ray into the
/// field and clips it. Asked first, it makes a ray's setup cost per instance it meets (and
/// the few whose spheres it grazes), not per instance its tile keeps.
pub(super) fn may_meet(plan: &InstancePlan, ray: &Ray) -> bool {
    let Some((b, radius)) = plan.world_sphere else {
        return true;
    };
    // Squared distances times `|d|²`: of `b` behind the origin and from the line, against
    // the radius with margins for rounding (here and in the field's frame).
    let (v, d2) = (b - ray.origin, ray.dir.length_squared());
    let along = v.dot(ray.dir);
    let reach = (radius * radius * (1.0 + 1e-6) + 1e-12 * v.length_squared()) * d2;
    (along >= 0.0 || along * along <= reach) && v.length_squared() * d2 - along * along <= reach
}
