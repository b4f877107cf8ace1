//! nerfstudio's crop box: an oriented box in field space that clips each ray's near/far.

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use super::Line;
use crate::error::{Error, Result};

/// An oriented box in field space (nerfstudio's `crop`): it clips rays, it does not mask
/// density.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CropBox {
    /// Centre (`crop_center`).
    pub center: [f64; 3],
    /// Full side lengths (`crop_scale`).
    pub scale: [f64; 3],
    /// Roll, pitch, yaw in radians (`crop_rot`); the rotation is `Rz(yaw)·Ry(pitch)·Rx(roll)`.
    #[serde(default)]
    pub rotation: [f64; 3],
}

impl CropBox {
    /// Refuses non-finite values and sides that are not positive (a side of 0 crops
    /// everything away).
    pub fn validate(&self, what: &str) -> Result<()> {
        let all = self.center.iter().chain(&self.scale).chain(&self.rotation);
        if all.clone().any(|v| !v.is_finite()) {
            return Err(Error::invalid(what, "crop box holds NaN or infinity"));
        }
        if let Some(i) = self.scale.iter().position(|&s| s <= 0.0) {
            return Err(Error::invalid(
                what,
                format!(
                    "crop box side {i} is {}: expected > 0 (a box of no size leaves nothing to \
                     render)",
                    self.scale[i]
                ),
            ));
        }
        Ok(())
    }

    /// `field_from_crop` rotation.
    fn rotation_matrix(&self) -> DMat3 {
        let [roll, pitch, yaw] = self.rotation;
        DMat3::from_rotation_z(yaw) * DMat3::from_rotation_y(pitch) * DMat3::from_rotation_x(roll)
    }

    /// The box ready to clip rays ([`CropClip::clip`]): its rotation worked out once.
    pub(crate) fn clipper(&self) -> CropClip {
        CropClip {
            crop_from_field: self.rotation_matrix().transpose(),
            center: DVec3::from(self.center),
            half: DVec3::from(self.scale) * 0.5,
        }
    }
}

/// A [`CropBox`] prepared for clipping rays, one after another: a ray costs two rotations and
/// four divisions (its line's reciprocals), where building the box's rotation from its angles
/// (six sines and cosines, two matrix products) would cost more than that again per ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CropClip {
    crop_from_field: DMat3,
    center: DVec3,
    half: DVec3,
}

impl CropClip {
    /// Whether the field-space point `p` is inside the box (splats are cropped by their mean,
    /// as nerfstudio's viewer crops them).
    pub(crate) fn contains(&self, p: DVec3) -> bool {
        let local = self.crop_from_field * (p - self.center);
        local.abs().cmple(self.half).all()
    }

    /// The parameter interval `[u0, u1]` of the field-space ray `o + u·d` inside the box, if any:
    /// the ray carried into the box's frame, where the box is the axis-aligned `[−half, half]`
    /// that a field-space line clips to slab by slab.
    pub fn clip(&self, o: DVec3, d: DVec3, u0: f64, u1: f64) -> Option<(f64, f64)> {
        let line = Line::new(
            self.crop_from_field * (o - self.center),
            self.crop_from_field * d,
        );
        let [lo, hi] = line.box_interval(-self.half, self.half)?;
        let (lo, hi) = (lo.max(u0), hi.min(u1));
        (lo <= hi).then_some((lo, hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn axis_aligned_box_clips_to_its_faces() {
        let c = CropBox {
            center: [1.0, 0.0, 0.0],
            scale: [2.0, 4.0, 6.0],
            rotation: [0.0; 3],
        };
        let (a, b) = c
            .clipper()
            .clip(DVec3::new(-5.0, 0.0, 0.0), DVec3::X, 0.0, 100.0)
            .unwrap();
        assert!((a - 5.0).abs() < 1e-12 && (b - 7.0).abs() < 1e-12);
        assert!(c
            .clipper()
            .clip(DVec3::new(-5.0, 3.0, 0.0), DVec3::X, 0.0, 100.0)
            .is_none());
    }

    #[test]
    fn yaw_rotates_the_box_about_z() {
        // A 2×4×6 box turned 90° about z is 4 wide along x.
        let c = CropBox {
            center: [0.0; 3],
            scale: [2.0, 4.0, 6.0],
            rotation: [0.0, 0.0, std::f64::consts::FRAC_PI_2],
        };
        let (a, b) = c
            .clipper()
            .clip(DVec3::new(-5.0, 0.0, 0.0), DVec3::X, 0.0, 100.0)
            .unwrap();
        assert!((a - 3.0).abs() < 1e-9 && (b - 7.0).abs() < 1e-9, "{a} {b}");
    }

    #[test]
    fn roll_pitch_yaw_compose_as_rz_ry_rx() {
        let c = CropBox {
            center: [0.0; 3],
            scale: [1.0; 3],
            rotation: [0.3, -0.2, 0.7],
        };
        let (r, p, y) = (0.3f64, -0.2f64, 0.7f64);
        // Rz·Ry·Rx written out element by element.
        let expected = [
            [
                y.cos() * p.cos(),
                y.cos() * p.sin() * r.sin() - y.sin() * r.cos(),
                y.cos() * p.sin() * r.cos() + y.sin() * r.sin(),
            ],
            [
                y.sin() * p.cos(),
                y.sin() * p.sin() * r.sin() + y.cos() * r.cos(),
                y.sin() * p.sin() * r.cos() - y.cos() * r.sin(),
            ],
            [-p.sin(), p.cos() * r.sin(), p.cos() * r.cos()],
        ];
        let m = c.rotation_matrix();
        for (i, row) in expected.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                assert!((m.row(i)[j] - v).abs() < 1e-12);
            }
        }
    }

    /// Rotated boxes and rays in every direction: the clip against the box's own
    /// membership test, which shares its rotation but not its slabs. Points a little inside
    /// the clipped interval are in the box, points a little outside it are not, and a ray the
    /// clip says misses the box has no point in it at 2 000 steps along.
    #[test]
    fn the_clip_holds_the_points_the_box_contains() {
        let mut rng = SplitMix64::new(5);
        let mut met = 0;
        for _ in 0..300 {
            let v = |rng: &mut SplitMix64, lo, hi| rng.in_cube(lo, hi).as_dvec3();
            let c = CropBox {
                center: v(&mut rng, -0.5, 0.5).into(),
                scale: v(&mut rng, 0.2, 2.0).into(),
                rotation: v(&mut rng, -3.0, 3.0).into(),
            }
            .clipper();
            let o = v(&mut rng, -3.0, 3.0);
            let d = v(&mut rng, -1.0, 1.0) - o;
            match c.clip(o, d, 0.0, 2.0) {
                Some((a, b)) => {
                    met += 1;
                    let slack = 1e-9 * (b - a).max(1e-3);
                    assert!(c.contains(o + (a + slack) * d) && c.contains(o + (b - slack) * d));
                    assert!(a <= 0.0 || !c.contains(o + (a - 1e-6) * d), "{a} {b}");
                    assert!(b >= 2.0 || !c.contains(o + (b + 1e-6) * d), "{a} {b}");
                }
                None => {
                    let inside = (0..=2000).any(|i| c.contains(o + (f64::from(i) / 1e3) * d));
                    assert!(!inside);
                }
            }
        }
        // Both branches are exercised.
        assert!(met > 30 && met < 270, "{met}");
    }
}
