//! What the marcher works out once per instance and frame, and which instances (and which
//! primitives of an analytic field) a tile's rays may meet.

use glam::{DMat3, DMat4, DVec3, Vec3};

use super::InstancePlan;
use crate::camera::Ray;
use crate::field::{Aabb, Analytic, ColorSpace, Field, Shape};
use crate::render::MarchParams;
use crate::scene::Scene;

/// How far a primitive's world sphere is widened, relative to the world radius of its
/// field's bounds and origin: the marcher samples along a local ray kept in `f32`, which
/// strays from the world ray by ~1e-7 of the field's coordinates.
const SAMPLE_ROUNDING: f64 = 1e-4;

impl<'a> InstancePlan<'a> {
    /// The plans of `scene`'s marched instances, in its order, for a scene composited in
    /// `space` ([`Scene::composite_space`]).
    pub(in crate::render) fn for_scene(
        scene: &'a Scene,
        space: ColorSpace,
        params: &MarchParams,
    ) -> Vec<Self> {
        scene
            .marched()
            .map(|inst| {
                let capabilities = inst.field().capabilities();
                let spans = capabilities.spans;
                let exact = spans || capabilities.mask_segments;
                let occupancy =
                    (!exact).then(|| inst.handle().occupancy(params.occupancy_resolution));
                // Without bounds, gaps may hide between samples: a field with spans or
                // mask segments has none unseen; one with an occupancy grid has its steps
                // probed for them.
                let (primitive_spheres, primitive_boxes) = match inst.handle().as_analytic() {
                    Some(analytic) if spans => (
                        primitive_spheres(analytic, inst.world_from_field()),
                        primitive_boxes(analytic, inst.world_from_field()),
                    ),
                    _ => (Vec::new(), Vec::new()),
                };
                let cell = match &occupancy {
                    Some(o) if !capabilities.density_bounds => {
                        o.bounds().size().min_element() as f64 / f64::from(o.resolution().max(1))
                    }
                    _ => f64::INFINITY,
                };
                InstancePlan {
                    instance: inst,
                    capabilities,
                    occupancy,
                    base_step: inst.field().feature_size() as f64
                        / params.steps_per_feature.max(1e-3) as f64,
                    features: inst.field().feature_count(),
                    smooth: inst.field().smooth_length().max(0.0) as f64,
                    encode: space == ColorSpace::Srgb
                        && inst.field().color_space() == ColorSpace::Linear,
                    unbounded: inst.field().unbounded(),
                    cell,
                    world_sphere: world_sphere(
                        inst.field().occupied_bounds(),
                        inst.world_from_field(),
                    ),
                    primitive_spheres,
                    primitive_boxes,
                }
            })
            .collect()
    }

    /// The indices, ascending, of the first `count` primitives of the instance's analytic
    /// field that some ray of `cone` may meet: those whose world sphere it may meet (and,
    /// for a box, whose placed corners are not all outside one side of its pyramid), and
    /// those without one (not finite, or a field that is not culled by primitive); without a
    /// cone, all of them.
    pub(in crate::render) fn primitives_met<'b>(
        &'b self,
        count: usize,
        cone: Option<&'b RayCone>,
    ) -> impl Iterator<Item = u32> + 'b {
        (0..count as u32).filter(move |&k| {
            let sphere = self.primitive_spheres.get(k as usize).copied().flatten();
            match (cone, sphere) {
                (Some(cone), Some(sphere)) => {
                    cone.may_meet(sphere)
                        && self
                            .primitive_boxes
                            .get(k as usize)
                            .and_then(Option::as_ref)
                            .is_none_or(|(corners, margin)| cone.may_meet_box(corners, *margin))
                }
                _ => true,
            }
        })
    }
}

/// The smallest world sphere around the world box of a field's bounds `b` (its eight
/// corners placed by `world_from_field`); `None` where they are empty or not finite.
fn world_sphere(b: Aabb, world_from_field: DMat4) -> Option<(DVec3, f64)> {
    if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
        return None;
    }
    let (mut wlo, mut whi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for corner in corners(b) {
        let w = world_from_field.transform_point3(corner);
        (wlo, whi) = (wlo.min(w), whi.max(w));
    }
    let centre = 0.5 * (wlo + whi);
    let radius = 0.5 * (whi - wlo).length();
    (centre.is_finite() && radius.is_finite()).then_some((centre, radius))
}

/// The eight corners of box `b`.
fn corners(b: Aabb) -> [DVec3; 8] {
    let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
    std::array::from_fn(|k| {
        DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

/// How far a primitive's culling volume is widened in the world ([`SAMPLE_ROUNDING`] of the
/// world radius of the field's bounds and origin); `None` where that is not finite.
fn sample_margin(analytic: &Analytic, world_from_field: DMat4) -> Option<f64> {
    let b = analytic.bounds();
    let reach = Aabb::new(b.min.min(Vec3::ZERO), b.max.max(Vec3::ZERO));
    world_sphere(reach, world_from_field).map(|(_, r)| SAMPLE_ROUNDING * r)
}

/// Per primitive of an analytic field, a world sphere around its support ([`support_sphere`]),
/// widened for the rounding of the marcher's samples ([`SAMPLE_ROUNDING`]); `None` where it
/// is not finite.
fn primitive_spheres(analytic: &Analytic, world_from_field: DMat4) -> Vec<Option<(DVec3, f64)>> {
    let margin = sample_margin(analytic, world_from_field);
    let stretch = largest_stretch(DMat3::from_mat4(world_from_field));
    analytic
        .primitives
        .iter()
        .map(|p| {
            let (centre, radius) = support_sphere(&p.shape, world_from_field, stretch)?;
            Some((centre, radius + margin?))
        })
        .collect()
}

/// Per primitive of an analytic field, a box's eight corners placed in the world, and the
/// margin its sphere is widened by ([`sample_margin`]); `None` for the other shapes, and
/// where either is not finite.
fn primitive_boxes(analytic: &Analytic, world_from_field: DMat4) -> Vec<Option<([DVec3; 8], f64)>> {
    let margin = sample_margin(analytic, world_from_field);
    analytic
        .primitives
        .iter()
        .map(|p| {
            let Shape::Box { min, max } = p.shape else {
                return None;
            };
            let placed = corners(Aabb::new(min, max)).map(|c| world_from_field.transform_point3(c));
            let margin = margin?;
            placed
                .iter()
                .all(|c| c.is_finite())
                .then_some((placed, margin))
        })
        .collect()
}

/// A world sphere around `shape`'s support, `stretch` being `world_from_field`'s largest
/// ([`largest_stretch`]): a ball's (a Gaussian's to its cutoff) about its placed centre, its
/// radius stretched that much; a box's through its farthest placed corner about its placed
/// centre. `None` where it is not finite.
fn support_sphere(shape: &Shape, world_from_field: DMat4, stretch: f64) -> Option<(DVec3, f64)> {
    let ball = |center: Vec3, radius: f32| {
        (
            world_from_field.transform_point3(center.as_dvec3()),
            f64::from(radius) * stretch,
        )
    };
    let (centre, radius) = match *shape {
        Shape::Sphere { center, radius } => ball(center, radius),
        // The field cuts the blob off at this `f32` product.
        Shape::Gaussian {
            center,
            sigma,
            cutoff,
        } => ball(center, cutoff * sigma),
        Shape::Box { min, max } => {
            let b = Aabb::new(min, max);
            let centre = world_from_field.transform_point3(0.5 * (b.min + b.max).as_dvec3());
            let radius = corners(b)
                .iter()
                .map(|&c| world_from_field.transform_point3(c).distance(centre))
                .fold(0.0, f64::max);
            (centre, radius)
        }
    };
    (centre.is_finite() && radius.is_finite()).then_some((centre, radius))
}

/// The most `m` lengthens a vector by, its spectral norm: the root of the largest
/// eigenvalue of the symmetric `mᵀm`, the largest root of its characteristic cubic in
/// trigonometric form. Widened by a millionth: next to a double eigenvalue the arc cosine
/// amplifies rounding to ~1e-8 of the result.
fn largest_stretch(m: DMat3) -> f64 {
    let s = m.transpose() * m;
    let q = (s.x_axis.x + s.y_axis.y + s.z_axis.z) / 3.0;
    let off = s.y_axis.x.powi(2) + s.z_axis.x.powi(2) + s.z_axis.y.powi(2);
    let spread = (s.x_axis.x - q).powi(2) + (s.y_axis.y - q).powi(2) + (s.z_axis.z - q).powi(2);
    let p = ((spread + 2.0 * off) / 6.0).sqrt();
    let largest = if p > 0.0 {
        let b = (s - DMat3::from_diagonal(DVec3::splat(q))) * (1.0 / p);
        let r = (0.5 * b.determinant()).clamp(-1.0, 1.0);
        q + 2.0 * p * (r.acos() / 3.0).cos()
    } else {
        q
    };
    largest.max(0.0).sqrt() * (1.0 + 1e-6)
}

/// A tile's rays as a cone: they start within `rho` of their mean origin and point within
/// `θ` of their mean direction `axis` (kept as `θ`'s sine and cosine). A pinhole's tile is
/// also a pyramid: its rays share their origin and point inside the four planes through it
/// and each pair of neighbouring corner pixels' rays (`sides`, their unit normals, inward).
pub(in crate::render) struct RayCone {
    origin: DVec3,
    axis: DVec3,
    rho: f64,
    sin_theta: f64,
    cos_theta: f64,
    sides: Option<[DVec3; 4]>,
}

impl RayCone {
    /// The cone around `rays`; `None` where it culls nothing: no rays, directions that
    /// cancel out, or a wide cone (`θ` of 90° or more: panoramic tiles). `rays` are a
    /// tile's, row by row, `width` to a row; `rectilinear`: they share their origin and
    /// each points inside the pyramid of the tile's corner rays (as a pinhole camera's do,
    /// [`Camera::rectilinear`](crate::camera::Camera::rectilinear)), which then bounds them
    /// too.
    pub(in crate::render) fn of(
        rays: &[Option<Ray>],
        width: usize,
        rectilinear: bool,
    ) -> Option<RayCone> {
        if rectilinear {
            if let Some(cone) = RayCone::of_pyramid(rays, width) {
                return Some(cone);
            }
        }
        let (mut origin, mut dir, mut n) = (DVec3::ZERO, DVec3::ZERO, 0.0);
        for ray in rays.iter().flatten() {
            origin += ray.origin;
            dir += ray.dir;
            n += 1.0;
        }
        let axis = dir.try_normalize()?;
        let origin = origin / n;
        // The farthest origin's distance is the root of the largest squared one (one root);
        // a ray's direction is a unit one, off by rounding that the angle's margin covers.
        let (mut rho2, mut cos_theta) = (0.0f64, 1.0f64);
        for ray in rays.iter().flatten() {
            rho2 = rho2.max((ray.origin - origin).length_squared());
            cos_theta = cos_theta.min(ray.dir.dot(axis));
        }
        let rho = rho2.sqrt();
        RayCone::around(origin, axis, rho, cos_theta, None)
    }

    /// The cone of a rectilinear tile's rays (see [`of`](Self::of)) from its four corner
    /// rays alone: they share the origin, and the angle from an axis inside the pyramid is
    /// greatest at one of its edges' ends, the corners. `None` where the tile has no pyramid
    /// ([`pyramid`]) or its corners spread 90° or more.
    fn of_pyramid(rays: &[Option<Ray>], width: usize) -> Option<RayCone> {
        let (origin, corners) = pyramid_corners(rays, width)?;
        let axis = corners.iter().sum::<DVec3>().try_normalize()?;
        let cos_theta = corners.iter().fold(1.0f64, |m, d| m.min(d.dot(axis)));
        let sides = pyramid(corners, axis)?;
        RayCone::around(origin, axis, 0.0, cos_theta, Some(sides))
    }

    /// The cone about `axis` from within `rho` of `origin` whose rays' directions have
    /// `cos_theta` at least with it; `None` where that is not above 0 (90° or more, or NaN).
    fn around(
        origin: DVec3,
        axis: DVec3,
        rho: f64,
        cos_theta: f64,
        sides: Option<[DVec3; 4]>,
    ) -> Option<RayCone> {
        if cos_theta.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !rho.is_finite() {
            return None;
        }
        // A margin for rounding in the angles.
        let (sin_theta, cos_theta) = (cos_theta.min(1.0).acos() + 1e-6).sin_cos();
        Some(RayCone {
            origin,
            axis,
            rho,
            sin_theta,
            cos_theta,
            sides,
        })
    }

    /// Whether some ray of the cone may meet the convex hull of `corners`: not where they
    /// all lie more than `margin` outside one side of its pyramid (always, without one).
    pub(in crate::render) fn may_meet_box(&self, corners: &[DVec3; 8], margin: f64) -> bool {
        let Some(sides) = &self.sides else {
            return true;
        };
        sides
            .iter()
            .all(|n| corners.iter().any(|&c| n.dot(c - self.origin) >= -margin))
    }

    /// Whether some ray of the cone may meet the sphere `(b, R)`: a ray starting within
    /// `ρ` of the cone's origin `c` meets it only if the ray from `c` along its direction
    /// meets `(b, R + ρ)`, which needs the angle `α` between the cone's axis and `b − c` to
    /// be at most `θ + β`, `β = asin((R + ρ)/|b − c|)`; as both sides lie in `[0, π]` (`θ + β`
    /// may pass π by `θ`'s rounding margin, which the slack below covers), that is
    /// `cos α ≥ cos θ cos β − sin θ sin β`, no trigonometry per sphere.
    pub(in crate::render) fn may_meet(&self, (b, radius): (DVec3, f64)) -> bool {
        let v = b - self.origin;
        let (l, reach) = (v.length(), radius + self.rho);
        if l <= reach * (1.0 + 1e-9) {
            return true;
        }
        let sin_beta = reach / l;
        let cos_beta = (1.0 - sin_beta * sin_beta).sqrt();
        v.dot(self.axis) / l >= self.cos_theta * cos_beta - self.sin_theta * sin_beta - 1e-9
    }
}

/// A rectilinear tile's shared origin and its corner rays' directions, going round (`rays`
/// row by row, `width` to a row); `None` for a tile less than two rays wide or high, or a
/// missing or off-origin corner.
fn pyramid_corners(rays: &[Option<Ray>], width: usize) -> Option<(DVec3, [DVec3; 4])> {
    let height = rays.len().checked_div(width)?;
    if width < 2 || height < 2 || width * height != rays.len() {
        return None;
    }
    let corner = |i: usize| rays[i].as_ref();
    let around = [
        corner(0)?,
        corner(width - 1)?,
        corner(rays.len() - 1)?,
        corner(rays.len() - width)?,
    ];
    let origin = around[0].origin;
    around
        .iter()
        .all(|r| r.origin == origin)
        .then(|| (origin, around.map(|r| r.dir)))
}

/// The inward unit normals of the planes through a pyramid's apex and each pair of its
/// neighbouring edges `corners` (directions, going round, `axis` inside them); `None` where
/// two are too close to parallel for a plane.
fn pyramid(corners: [DVec3; 4], axis: DVec3) -> Option<[DVec3; 4]> {
    let mut sides = [DVec3::ZERO; 4];
    for (k, side) in sides.iter_mut().enumerate() {
        let n = corners[k].cross(corners[(k + 1) % 4]).try_normalize()?;
        *side = if n.dot(axis) >= 0.0 { n } else { -n };
    }
    Some(sides)
}

/// Lists in `keep`, ascending, the instances some ray of a tile (its [`RayCone`]) may meet;
/// without a cone, and for instances without finite bounds, all. This makes a tile's setup cost per
/// instance, not per instance and pixel.
pub(in crate::render) fn cull_instances(
    plans: &[InstancePlan],
    cone: Option<&RayCone>,
    keep: &mut Vec<u32>,
) {
    keep.clear();
    keep.extend(0..plans.len() as u32);
    let Some(cone) = cone else {
        return;
    };
    keep.retain(|&i| {
        plans[i as usize]
            .world_sphere
            .is_none_or(|sphere| cone.may_meet(sphere))
    });
}

/// Whether `ray` passes within the instance's world sphere (one without a sphere always
/// may): conservative, like [`cull_instances`], and a few multiplications where
/// [`Instance::local_ray`](crate::scene::Instance::local_ray) carries the ray into the
/// field and clips it. Asked first, it makes a ray's setup cost per instance it meets (and
/// the few whose spheres it grazes), not per instance its tile keeps.
pub(in crate::render) fn may_meet(plan: &InstancePlan, ray: &Ray) -> bool {
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

/// Per instance, the field a tile's rays sample: an analytic field's primitives that some
/// ray of the tile may meet, where that is fewer than all, else the instance's own field.
/// The primitives left out have no density on the tile's rays, and the others add theirs in
/// the same order, so the spans, densities and colours are the whole field's, bit for bit,
/// for less work: a tile of the demo sees two or three of its environment's primitives.
#[derive(Default)]
pub(super) struct TileFields {
    culled: Vec<Analytic>,
    /// Whether `culled[i]` is instance `i`'s field for this tile.
    in_use: Vec<bool>,
}

impl TileFields {
    /// Picks the fields for a tile of `cone`'s rays, whose instances `keep` lists.
    pub(super) fn cull(&mut self, plans: &[InstancePlan], cone: Option<&RayCone>, keep: &[u32]) {
        let n_inst = plans.len();
        self.culled.resize_with(n_inst, Analytic::default);
        self.in_use.clear();
        self.in_use.resize(n_inst, false);
        let Some(cone) = cone else {
            return;
        };
        for &i in keep {
            let (i, plan) = (i as usize, &plans[i as usize]);
            let Some(analytic) = plans[i].instance.handle().as_analytic() else {
                continue;
            };
            // A lone primitive's sphere holds the instance's, which the tile kept.
            if plan.primitive_spheres.len() <= 1 {
                continue;
            }
            let culled = &mut self.culled[i].primitives;
            culled.clear();
            culled.extend(
                plan.primitives_met(analytic.primitives.len(), Some(cone))
                    .map(|k| analytic.primitives[k as usize])
                    // Primitives without density add nothing anywhere.
                    .filter(|p| p.density > 0.0),
            );
            self.in_use[i] = culled.len() < analytic.primitives.len();
        }
    }

    /// The field instance `i`'s spans, densities and colours on this tile's rays are asked
    /// of. Its bounds and density bounds are not the instance's: ask the instance's own
    /// field for those.
    pub(super) fn field<'a>(&'a self, plans: &[InstancePlan<'a>], i: usize) -> &'a dyn Field {
        if self.in_use[i] {
            &self.culled[i]
        } else {
            plans[i].instance.field()
        }
    }
}
