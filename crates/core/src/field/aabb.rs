//! Axis-aligned boxes: field bounds, occupancy cells, crop boxes.
//!
//! Boxes are *closed*: a point on a face is inside. A box with `min > max` on any axis (or a
//! NaN corner) is empty; [`Aabb::EMPTY`] is the identity of [`Aabb::union`].

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A closed axis-aligned box `[min, max]`.
///
/// JSON: `{"min": [x, y, z], "max": [x, y, z]}`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aabb {
    /// The corner with the smallest coordinates.
    pub min: Vec3,
    /// The corner with the largest coordinates.
    pub max: Vec3,
}

impl Aabb {
    /// The empty box: `union(EMPTY, b) == b`, contains nothing, intersects nothing.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// The box `[min, max]` (empty if `min > max` on some axis).
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Aabb { min, max }
    }

    /// Whether the box holds no point (`min > max` on some axis, or a NaN corner).
    pub fn is_empty(&self) -> bool {
        !self.min.cmple(self.max).all()
    }

    /// Edge lengths `max − min` (meaningless for an empty box).
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }

    /// The centre `(min + max) / 2`.
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Length of the main diagonal, `|max − min|`.
    pub fn diagonal(&self) -> f32 {
        self.size().length()
    }

    /// Whether `p` lies in the closed box.
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The smallest box holding both.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// Whether the two closed boxes share at least one point (touching faces count).
    pub fn intersects(&self, other: &Aabb) -> bool {
        self.min.max(other.min).cmple(self.max.min(other.max)).all()
    }

    /// The box grown by `margin` on every side (shrunk if negative).
    pub fn grow(&self, margin: f32) -> Aabb {
        Aabb {
            min: self.min - Vec3::splat(margin),
            max: self.max + Vec3::splat(margin),
        }
    }

    /// The parameter range `[ta, tb] ⊆ [t0, t1]` where `origin + t·dir` is in the box, or
    /// `None` if the ray misses it within `[t0, t1]`.
    ///
    /// Slab test: on each axis with `dir ≠ 0` the ray is inside between
    /// `(min − origin)/dir` and `(max − origin)/dir`; an axis with `dir = 0` (or so small that
    /// `1/dir` overflows) constrains nothing if the origin is within that slab and rules the
    /// ray out otherwise. So axis-parallel rays and origins on a face never produce NaN. A ray
    /// that only touches an edge gets a zero-length range. The far end is widened by a few
    /// ulps (×(1 + 4ε)) so rounding never clips away the last point of the box.
    pub fn clip_ray(&self, origin: Vec3, dir: Vec3, t0: f32, t1: f32) -> Option<(f32, f32)> {
        if self.is_empty() {
            return None;
        }
        let mut near = t0;
        let mut far = t1;
        for a in 0..3 {
            let inv = 1.0 / dir[a];
            if inv.is_finite() {
                let ta = (self.min[a] - origin[a]) * inv;
                let tb = (self.max[a] - origin[a]) * inv;
                let (lo, hi) = if ta <= tb { (ta, tb) } else { (tb, ta) };
                let hi = hi + hi.abs() * (4.0 * f32::EPSILON);
                near = near.max(lo);
                far = far.min(hi);
            } else if !(origin[a] >= self.min[a] && origin[a] <= self.max[a]) {
                return None;
            }
        }
        (near <= far).then_some((near, far))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> Aabb {
        Aabb::new(Vec3::ZERO, Vec3::ONE)
    }

    #[test]
    fn basic_measures() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 3.0, 8.0));
        assert_eq!(b.size(), Vec3::new(2.0, 3.0, 6.0));
        assert_eq!(b.center(), Vec3::new(0.0, 1.5, 5.0));
        assert!((b.diagonal() - 7.0).abs() < 1e-6); // 2² + 3² + 6² = 49
        assert!(b.contains(Vec3::new(1.0, 3.0, 8.0)));
        assert!(b.contains(Vec3::new(-1.0, 0.0, 2.0)));
        assert!(!b.contains(Vec3::new(1.0001, 1.0, 5.0)));
        assert!(!b.is_empty());
    }

    #[test]
    fn empty_union_and_intersection() {
        assert!(Aabb::EMPTY.is_empty());
        assert!(Aabb::new(Vec3::ONE, Vec3::ZERO).is_empty());
        assert!(Aabb::new(Vec3::splat(f32::NAN), Vec3::ONE).is_empty());
        assert_eq!(Aabb::EMPTY.union(&unit()), unit());
        let far = Aabb::new(Vec3::splat(2.0), Vec3::splat(3.0));
        let u = unit().union(&far);
        assert_eq!(u, Aabb::new(Vec3::ZERO, Vec3::splat(3.0)));
        assert!(!unit().intersects(&far));
        assert!(!unit().intersects(&Aabb::EMPTY));
        let touching = Aabb::new(Vec3::new(1.0, 0.5, 0.5), Vec3::new(2.0, 2.0, 2.0));
        assert!(unit().intersects(&touching));
        assert!(touching.intersects(&unit()));
        assert!(!Aabb::EMPTY.contains(Vec3::ZERO));
    }

    #[test]
    fn clip_oblique_ray() {
        // From (-1, 0.5, 0.5) along +x: enters at t = 1, leaves at t = 2.
        let (a, b) = unit()
            .clip_ray(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 0.0, 10.0)
            .unwrap();
        assert!((a - 1.0).abs() < 1e-6 && (b - 2.0).abs() < 1e-5);
        // Diagonal through the cube from outside: enters at (0,0,0), leaves at (1,1,1).
        let d = Vec3::ONE.normalize();
        let o = Vec3::splat(-1.0);
        let (a, b) = unit().clip_ray(o, d, 0.0, 10.0).unwrap();
        let s3 = 3f32.sqrt();
        assert!((a - s3).abs() < 1e-5 && (b - 2.0 * s3).abs() < 1e-5);
        // Restricted by t1.
        let (_, b) = unit().clip_ray(o, d, 0.0, 2.0).unwrap();
        assert_eq!(b, 2.0);
        // Behind the origin.
        assert!(unit().clip_ray(Vec3::splat(2.0), d, 0.0, 10.0).is_none());
    }

    #[test]
    fn clip_axis_parallel_and_on_face() {
        // Ray lying in the face x = 0, moving along +y, from inside the y range.
        let r = unit().clip_ray(Vec3::new(0.0, 0.25, 1.0), Vec3::Y, 0.0, 5.0);
        let (a, b) = r.unwrap();
        assert!(a == 0.0 && (b - 0.75).abs() < 1e-6);
        // Origin exactly on the min face, moving outwards along -z: a single point.
        let (a, b) = unit()
            .clip_ray(Vec3::new(0.5, 0.5, 0.0), -Vec3::Z, 0.0, 5.0)
            .unwrap();
        assert!(a == 0.0 && b.abs() < 1e-6);
        // Parallel and outside the slab: miss, no NaN.
        assert!(unit()
            .clip_ray(Vec3::new(1.5, 0.5, 0.5), Vec3::Y, -5.0, 5.0)
            .is_none());
        // Denormal direction component is treated as parallel.
        let d = Vec3::new(1e-42, 1.0, 0.0);
        let (a, b) = unit()
            .clip_ray(Vec3::new(0.0, -1.0, 0.5), d, 0.0, 5.0)
            .unwrap();
        assert!(a.is_finite() && b.is_finite() && (a - 1.0).abs() < 1e-6);
        // Empty box.
        assert!(Aabb::EMPTY
            .clip_ray(Vec3::ZERO, Vec3::X, 0.0, 1.0)
            .is_none());
        assert!(Aabb::new(Vec3::ONE, Vec3::ZERO)
            .clip_ray(Vec3::splat(0.5), Vec3::X, -1.0, 1.0)
            .is_none());
    }

    #[test]
    fn clip_touching_edge() {
        // Ray along the edge y = 1, z = 1 of the cube.
        let (a, b) = unit()
            .clip_ray(Vec3::new(-2.0, 1.0, 1.0), Vec3::X, 0.0, 10.0)
            .unwrap();
        assert!((a - 2.0).abs() < 1e-6 && (b - 3.0).abs() < 1e-5);
    }

    #[test]
    fn serde_shape() {
        let b: Aabb = serde_json::from_str(r#"{"min": [0, 1, 2], "max": [3, 4, 5]}"#).unwrap();
        assert_eq!(b.min, Vec3::new(0.0, 1.0, 2.0));
        assert_eq!(b.max, Vec3::new(3.0, 4.0, 5.0));
        assert!(
            serde_json::from_str::<Aabb>(r#"{"min": [0, 1, 2], "max": [3, 4, 5], "x": 1}"#)
                .is_err()
        );
    }
}
