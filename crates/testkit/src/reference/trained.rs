//! A reference for trained fields cut by an occupancy mask (instant-ngp), which have no
//! closed form: an adaptive quadrature in f64 along each ray, sharing nothing with the
//! marcher but the field's own queries.
//!
//! Such a field's density is zero outside its mask and a smooth interpolant inside
//! ([`Field::mask_segments`](nerfx_core::field::Field::mask_segments),
//! [`Field::smooth_length`](nerfx_core::field::Field::smooth_length)), so along a ray the only
//! edges are the mask's crossings. Between them, the ray is laid with nodes a quarter of
//! the field's smooth length apart (no detail lies between them but curvature), a chunk at
//! a time from the camera. Each interval is then halved while halving changes what it adds
//! to the pixel (its absorbed fraction and premultiplied colour, entered with the
//! transmittance before it) by more than the tolerance; every interval is composited with
//! the density and the density-weighted colour linear between its ends, its optical depth
//! exactly `δ·(σ_a + σ_b)/2`. A ray stops once its transmittance is below
//! [`STOP_TRANSMITTANCE`]. A scene composited in sRGB has its pixels decoded to linear
//! light, as renders have by default. The error per interval is then about a third of the
//! tolerance; [`render_trained`](super::render_trained) with a lower tolerance tells how
//! far the result is from converged.

use glam::{DVec3, Vec3};

use super::integrator::RayResult;
use nerfx_core::camera::Ray;
use nerfx_core::error::{Error, Result};
use nerfx_core::field::{linear_to_srgb, srgb_to_linear, ColorSpace};
use nerfx_core::scene::{Instance, LocalRay, Scene, SceneInstance};

/// A ray stops once its transmittance falls below this (alpha is then off by at most this).
const STOP_TRANSMITTANCE: f64 = 1e-8;

/// Nodes are first laid this many per smooth length of the field.
const NODES_PER_SMOOTH_LENGTH: f64 = 4.0;

/// Intervals laid per chunk: a ray is integrated a chunk at a time so that nodes behind
/// an opaque surface are never laid.
const CHUNK_INTERVALS: usize = 64;

/// Halvings of a first interval at most (2^-40 of it: below f64's resolution of most `t`).
const MAX_HALVINGS: u32 = 40;

/// A scene prepared for the quadrature: its instances, each with density that a mask cuts.
pub struct TrainedReference<'a> {
    /// The scene's instances, all marched.
    instances: Vec<&'a Instance>,
    /// Per instance: whether its colours are encoded to sRGB before compositing (a linear
    /// field in a scene composited in sRGB).
    encode: Vec<bool>,
    /// Whether the scene composites in sRGB: a pixel's colour is then decoded to linear
    /// (unpremultiplied, decoded, premultiplied again), as renders are by default.
    decode: bool,
    tolerance: f64,
}

/// One node: world distance, density (per world unit) and density times colour.
#[derive(Clone, Copy, Debug, Default)]
struct Node {
    t: f64,
    sigma: f64,
    emitted: DVec3,
}

/// What an interval adds to a pixel: absorbed fraction, premultiplied colour, depth moment
/// `∫ t σ T dt`; and the transmittance it leaves.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Contribution {
    absorbed: f64,
    rgb: DVec3,
    moment: f64,
    leaves: f64,
}

/// Per-thread scratch: nodes, which intervals are settled, and field queries.
#[derive(Default)]
pub struct Scratch {
    nodes: Vec<Node>,
    settled: Vec<bool>,
    next: Vec<Node>,
    next_settled: Vec<bool>,
    pending: Vec<f64>,
    evaluated: Vec<Node>,
    points: Vec<Vec3>,
    dirs: Vec<Vec3>,
    sigma: Vec<f32>,
    rgb: Vec<Vec3>,
    local: Vec<(usize, LocalRay)>,
    segments: Vec<[f64; 2]>,
    /// World intervals of mask segments, with the index in `local` of their instance.
    cuts: Vec<(f64, f64, usize)>,
    ends: Vec<f64>,
    /// The instances whose masks are on over the piece integrated, each with the mask
    /// segment that holds it: `(index in local, start, end)`.
    active: Vec<(usize, f64, f64)>,
    /// Nodes whose position rounded out of the mask, by index in `pending`, with how far
    /// they are to be moved in.
    outside: Vec<(usize, f64)>,
    moved: Vec<Vec3>,
    moved_sigma: Vec<f32>,
    /// `(t, 1 − T)` after each composited interval, for the median depth.
    absorbed: Vec<(f64, f64)>,
}

impl<'a> TrainedReference<'a> {
    /// Prepares `scene` for integration to `tolerance` per interval (see the module's
    /// doc); [`Error::Unsupported`] when an instance's field gives no mask segments or has
    /// no smooth length.
    pub fn new(scene: &'a Scene, tolerance: f64) -> Result<Self> {
        let srgb = scene.composite_space() == ColorSpace::Srgb;
        let mut encode = Vec::new();
        let mut instances = Vec::new();
        for entry in scene.instances() {
            let unsupported = |why: &str| {
                Error::Unsupported(format!(
                    "the trained reference of instance '{}': {why}",
                    entry.name()
                ))
            };
            let SceneInstance::Marched(instance) = entry else {
                return Err(unsupported("it is not marched by the occupancy marcher"));
            };
            let field = instance.field();
            if !field.capabilities().mask_segments || field.smooth_length() <= 0.0 {
                return Err(unsupported(
                    "its field is not a smooth interpolant cut by a mask",
                ));
            }
            encode.push(srgb && field.color_space() == ColorSpace::Linear);
            instances.push(instance);
        }
        Ok(TrainedReference {
            instances,
            encode,
            decode: srgb,
            tolerance,
        })
    }

    /// Colour, accumulation and depths along `ray`.
    pub fn integrate_with(&self, ray: &Ray, s: &mut Scratch) -> RayResult {
        s.local.clear();
        s.cuts.clear();
        for (i, instance) in self.instances.iter().enumerate() {
            let Some(lr) = instance.local_ray(ray, ray.near, ray.far) else {
                continue;
            };
            let k = lr.units_per_world as f64;
            s.segments.clear();
            let length = (lr.t_far - lr.t_near) * k;
            instance
                .field()
                .mask_segments(lr.origin, lr.dir, 0.0, length, &mut s.segments);
            let j = s.local.len();
            s.local.push((i, lr));
            let world = |u: f64| (lr.t_near + u / k).clamp(lr.t_near, lr.t_far);
            s.cuts.extend(
                (s.segments.iter())
                    .map(|&[a, b]| (world(a), world(b), j))
                    .filter(|c| c.0 < c.1),
            );
        }
        s.ends.clear();
        s.ends.extend(s.cuts.iter().flat_map(|c| [c.0, c.1]));
        s.ends.sort_unstable_by(f64::total_cmp);
        s.ends.dedup();
        s.absorbed.clear();
        let mut total = Contribution {
            leaves: 1.0,
            ..Contribution::default()
        };
        for k in 1..s.ends.len() {
            let (a, b) = (s.ends[k - 1], s.ends[k]);
            let mid = 0.5 * (a + b);
            s.active.clear();
            s.active.extend(
                (s.cuts.iter())
                    .filter(|c| c.0 <= mid && mid <= c.1)
                    .map(|c| (c.2, c.0, c.1)),
            );
            if !s.active.is_empty() {
                self.piece(a, b, &mut total, s);
            }
            if total.leaves < STOP_TRANSMITTANCE {
                break;
            }
        }
        let alpha = 1.0 - total.leaves;
        if alpha <= 0.0 {
            return RayResult::EMPTY;
        }
        // The median: where the absorbed fraction crosses half the total, between the ends
        // of the interval that crosses it.
        let half = 0.5 * alpha;
        let at = s.absorbed.partition_point(|&(_, a)| a < half);
        let depth_median = match (at.checked_sub(1).map(|p| s.absorbed[p]), s.absorbed.get(at)) {
            (Some((t0, a0)), Some(&(t1, a1))) if a1 > a0 => {
                t0 + (t1 - t0) * (half - a0) / (a1 - a0)
            }
            (_, Some(&(t1, _))) => t1,
            _ => f64::INFINITY,
        };
        let rgb = if self.decode {
            (total.rgb / alpha).map(|c| srgb_to_linear(c as f32) as f64) * alpha
        } else {
            total.rgb
        };
        RayResult {
            rgb,
            alpha,
            depth_ray: total.moment / alpha,
            depth_median,
        }
    }

    /// Integrates the piece `[a, b]` of the ray where the instances `s.active` (indices
    /// into `s.local`) have their masks on, a chunk at a time, into `total`.
    fn piece(&self, a: f64, b: f64, total: &mut Contribution, s: &mut Scratch) {
        let step = (s.active.iter())
            .map(|&(j, ..)| {
                let (i, lr) = &s.local[j];
                let field = self.instances[*i].field();
                field.smooth_length() as f64 / (NODES_PER_SMOOTH_LENGTH * lr.units_per_world as f64)
            })
            .fold(f64::INFINITY, f64::min);
        let mut start = a;
        while start < b && total.leaves >= STOP_TRANSMITTANCE {
            let end = (start + CHUNK_INTERVALS as f64 * step).min(b);
            let n = ((end - start) / step).ceil().max(1.0) as usize;
            s.pending.clear();
            s.pending
                .extend((0..=n).map(|i| start + (end - start) * i as f64 / n as f64));
            s.pending[n] = end;
            self.evaluate(s);
            std::mem::swap(&mut s.nodes, &mut s.evaluated);
            s.settled.clear();
            s.settled.resize(n, false);
            let finest = (end - start) / n as f64 * 0.5f64.powi(MAX_HALVINGS as i32);
            self.refine(total.leaves, finest, s);
            for w in s.nodes.windows(2) {
                let c = contribution(total.leaves, &w[0], &w[1]);
                total.absorbed += c.absorbed;
                total.rgb += c.rgb;
                total.moment += c.moment;
                total.leaves = c.leaves;
                s.absorbed.push((w[1].t, 1.0 - c.leaves));
                if total.leaves < STOP_TRANSMITTANCE {
                    break;
                }
            }
            start = end;
        }
    }

    /// Halves the chunk's unsettled intervals, level by level (one field query per level),
    /// until halving changes none by more than the tolerance or they are `finest` long.
    fn refine(&self, entering: f64, finest: f64, s: &mut Scratch) {
        loop {
            // Each interval's transmittance at its start, and its midpoint if unsettled.
            s.pending.clear();
            let mut leaves = entering;
            for (w, &settled) in s.nodes.windows(2).zip(&s.settled) {
                if !settled && w[1].t - w[0].t > finest && leaves >= STOP_TRANSMITTANCE {
                    s.pending.push(0.5 * (w[0].t + w[1].t));
                }
                leaves = contribution(leaves, &w[0], &w[1]).leaves;
            }
            if s.pending.is_empty() {
                return;
            }
            self.evaluate(s);
            s.next.clear();
            s.next_settled.clear();
            let mut mids = s.evaluated.iter().peekable();
            let mut leaves = entering;
            for w in s.nodes.windows(2) {
                let (a, b) = (&w[0], &w[1]);
                s.next.push(*a);
                let whole = contribution(leaves, a, b);
                match mids.next_if(|m| a.t < m.t && m.t < b.t) {
                    Some(m) => {
                        let first = contribution(leaves, a, m);
                        let second = contribution(first.leaves, m, b);
                        // Alpha and colour, what a preset's target is about (depth follows).
                        let change = (first.rgb + second.rgb - whole.rgb)
                            .abs()
                            .max_element()
                            .max((first.absorbed + second.absorbed - whole.absorbed).abs());
                        let done = change <= self.tolerance;
                        s.next.push(*m);
                        s.next_settled.extend([done, done]);
                        leaves = second.leaves;
                    }
                    None => {
                        // Settled, too short or hidden: it stays as it is.
                        s.next_settled.push(true);
                        leaves = whole.leaves;
                    }
                }
            }
            s.next.extend(s.nodes.last().copied());
            std::mem::swap(&mut s.nodes, &mut s.next);
            std::mem::swap(&mut s.settled, &mut s.next_settled);
        }
    }

    /// Evaluates density and colour at the world distances `s.pending` (sorted) over the
    /// instances `s.active`, into `s.evaluated`. Inside its mask a field's density is
    /// positive; a node there that reads none has had its position rounded out of the mask
    /// (in f32, within a few units of rounding of a face, many more along a grazing ray), so
    /// it takes the density and colour the field has just inside instead: moved towards its
    /// segment's middle by one unit of rounding, then two, four, and on.
    fn evaluate(&self, s: &mut Scratch) {
        s.evaluated.clear();
        s.evaluated.extend(s.pending.iter().map(|&t| Node {
            t,
            ..Node::default()
        }));
        for a in 0..s.active.len() {
            let (j, start, end) = s.active[a];
            let (i, lr) = s.local[j];
            let field = self.instances[i].field();
            let k = lr.units_per_world as f64;
            // One unit of f32 rounding of a field-space position here, in world distance.
            let rounding = (lr.origin.abs().max_element() as f64 + (lr.t_far - lr.t_near) * k)
                * f64::from(f32::EPSILON)
                / k;
            let middle = 0.5 * (start + end);
            s.points.clear();
            s.points.extend(s.pending.iter().map(|&t| lr.at(t)));
            s.sigma.clear();
            s.sigma.resize(s.points.len(), 0.0);
            field.density(&s.points, &mut s.sigma);
            s.outside.clear();
            s.outside.extend(
                (s.sigma.iter().enumerate())
                    .filter(|(_, &sigma)| sigma <= 0.0)
                    .map(|(n, _)| (n, rounding)),
            );
            let inward = |t: f64, by: f64| {
                if t < middle {
                    (t + by).min(middle)
                } else {
                    (t - by).max(middle)
                }
            };
            while !s.outside.is_empty() {
                s.moved.clear();
                s.moved
                    .extend((s.outside.iter()).map(|&(n, by)| lr.at(inward(s.pending[n], by))));
                s.moved_sigma.clear();
                s.moved_sigma.resize(s.moved.len(), 0.0);
                field.density(&s.moved, &mut s.moved_sigma);
                for (&(n, _), (&p, &sigma)) in
                    (s.outside.iter()).zip(s.moved.iter().zip(&s.moved_sigma))
                {
                    s.points[n] = p;
                    s.sigma[n] = sigma;
                }
                // Those still outside move twice as far, the middle the last place tried.
                let (sigma, pending) = (&s.sigma, &s.pending);
                s.outside.retain_mut(|(n, by)| {
                    let keep = sigma[*n] <= 0.0 && inward(pending[*n], *by) != middle;
                    *by *= 2.0;
                    keep
                });
            }
            s.dirs.clear();
            s.dirs.resize(s.points.len(), lr.dir);
            s.rgb.clear();
            s.rgb.resize(s.points.len(), Vec3::ZERO);
            field.radiance(&s.points, &s.dirs, &mut s.rgb);
            for ((node, &sigma), &rgb) in s.evaluated.iter_mut().zip(&s.sigma).zip(&s.rgb) {
                let rgb = if self.encode[i] {
                    rgb.map(linear_to_srgb)
                } else {
                    rgb
                };
                let sigma = sigma as f64 * k;
                node.sigma += sigma;
                node.emitted += sigma * rgb.as_dvec3().max(DVec3::ZERO);
            }
        }
    }
}

/// What the interval from `a` to `b` adds to a pixel, entered with transmittance
/// `entering`, its density and density-weighted colour linear between its ends: optical
/// depth `τ = δ·(σ_a + σ_b)/2`, absorbed fraction `T·(1 − e^{−τ})`, colour that times the
/// mean colour `(σc_a + σc_b)/(σ_a + σ_b)`, depth moment that times the midpoint.
fn contribution(entering: f64, a: &Node, b: &Node) -> Contribution {
    let density = a.sigma + b.sigma;
    if density <= 0.0 {
        return Contribution {
            leaves: entering,
            ..Contribution::default()
        };
    }
    let depth = 0.5 * (b.t - a.t) * density;
    let absorbed = -entering * (-depth).exp_m1();
    Contribution {
        absorbed,
        rgb: (a.emitted + b.emitted) * (absorbed / density),
        moment: absorbed * 0.5 * (a.t + b.t),
        leaves: entering * (-depth).exp(),
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::{DMat4, DVec3};

    use super::*;
    use nerfx_core::field::{Aabb, Capabilities, Field};
    use nerfx_core::scene::{FieldHandle, Instance};

    /// A unit cube of constant density and colour, cut by its own mask: the density reads
    /// zero wherever an f32 position lands on or outside its faces, so that a layer about
    /// one unit of rounding thick inside the exact chord reads none, as a trained field's
    /// mask does.
    struct MaskedCube {
        sigma: f32,
        rgb: Vec3,
    }

    const HALF: f32 = 0.5;
    /// Dense enough that a layer one unit of f32 rounding thick holds 1e-3 of optical depth.
    const SIGMA: f32 = 3e4;

    impl Field for MaskedCube {
        fn bounds(&self) -> Aabb {
            Aabb::new(Vec3::splat(-HALF), Vec3::splat(HALF))
        }
        fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
            for (p, s) in points.iter().zip(sigma) {
                *s = if p.abs().max_element() < HALF {
                    self.sigma
                } else {
                    0.0
                };
            }
        }
        fn radiance(&self, _points: &[Vec3], _dirs: &[Vec3], rgb: &mut [Vec3]) {
            rgb.fill(self.rgb);
        }
        fn smooth_length(&self) -> f32 {
            1e-2
        }
        fn capabilities(&self) -> Capabilities {
            Capabilities {
                mask_segments: true,
                ..Capabilities::default()
            }
        }
        fn mask_segments(
            &self,
            origin: Vec3,
            dir: Vec3,
            t0: f64,
            t1: f64,
            out: &mut Vec<[f64; 2]>,
        ) {
            let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
            let (mut a, mut b) = (t0, t1);
            for k in 0..3 {
                let (lo, hi) = ((-0.5 - o[k]) / d[k], (0.5 - o[k]) / d[k]);
                a = a.max(lo.min(hi));
                b = b.min(lo.max(hi));
            }
            if a < b {
                out.push([a, b]);
            }
        }
        fn may_be_occupied(&self, region: &Aabb) -> bool {
            region.intersects(&self.bounds())
        }
    }

    /// Through a constant cube the answer is closed form: alpha `1 − e^{−σL}` over the
    /// chord `L`, colour alpha times the colour. Rays that graze a face (the thin chords a
    /// silhouette has) come out right too: where a node's position rounds out of the mask it
    /// takes the density just inside.
    #[test]
    fn a_masked_constant_cube_integrates_in_closed_form() {
        let rgb = Vec3::new(0.2, 0.5, 0.9);
        let field = MaskedCube { sigma: SIGMA, rgb };
        let instance = Instance::new(
            "cube",
            FieldHandle::new(Arc::new(field)),
            DMat4::IDENTITY,
            None,
        )
        .unwrap();
        let scene = Scene::new(vec![instance]);
        let reference = TrainedReference::new(&scene, 1e-7).unwrap();
        let mut scratch = Scratch::default();
        // Chords past an edge of the cube, from a long one down to a few units of f32
        // rounding of its faces.
        let dir = DVec3::new(1.0, -1.0, 0.2).normalize();
        for inside in [0.3, 1e-4, 1e-6, 1e-7, 3e-8] {
            let at = DVec3::new(0.5 - inside, 0.5 - inside, 0.1);
            let ray = Ray {
                origin: at - 4.0 * dir,
                dir,
                z_per_t: 1.0,
                near: 0.0,
                far: f64::INFINITY,
            };
            // The chord as the field's mask gives it along the ray the reference sees.
            let lr = reference.instances[0]
                .local_ray(&ray, 0.0, f64::INFINITY)
                .unwrap();
            let mut chord = Vec::new();
            let far = lr.t_far - lr.t_near;
            (reference.instances[0].field()).mask_segments(lr.origin, lr.dir, 0.0, far, &mut chord);
            let length = chord.first().map_or(0.0, |c| c[1] - c[0]);
            let alpha = -(-f64::from(SIGMA) * length).exp_m1();
            let got = reference.integrate_with(&ray, &mut scratch);
            assert!(
                (got.alpha - alpha).abs() < 1e-6,
                "{inside} inside: alpha {} vs {alpha}",
                got.alpha
            );
            let want = rgb.as_dvec3() * alpha;
            assert!(
                (got.rgb - want).abs().max_element() < 1e-6,
                "{inside} inside: rgb {} vs {want}",
                got.rgb
            );
        }
    }
}
