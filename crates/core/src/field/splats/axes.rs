//! The frame a splat file's values are in.
//!
//! PLY-family files (3DGS, gsplat, nerfstudio, SuperSplat) hold splats in the frame of the
//! capture's cameras, x right, y down, z forward (RDF). SPZ's specification calls its internal
//! frame RUB (x right, y up, z back) and Niantic's converter flips y and z between the two,
//! while PlayCanvas's splat-transform stores the values as they are. A file carries no word on
//! which was done, so nerfx reads the stored values as they are, and a scene that knows its
//! file was written in RUB says so: the splats are then turned by half a turn about x
//! (`(x, y, z) → (x, −y, −z)`), which brings them into the PLY frame.

use serde::{Deserialize, Serialize};

use super::{SplatColor, Splats};

/// How a splat file's stored axes relate to the PLY frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Axes {
    /// The stored values as they are (the default).
    #[default]
    Stored,
    /// Stored in RUB (right, up, back), as Niantic's tools write SPZ: y and z are flipped
    /// into the PLY frame.
    Rub,
}

/// The sign each SH basis function (gsplat's order, DC first) takes when y and z flip: the
/// functions odd in y and z together change sign.
const FLIP_YZ_SIGNS: [f32; 16] = [
    1.0, -1.0, -1.0, 1.0, // DC; y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // xy, yz, 3z²−1, xz, x²−y²
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0,
    1.0, // y(3x²−y²), xyz, y(5z²−1), z(5z²−3), x(5z²−1), z(x²−y²), x(x²−3y²)
];

impl Splats {
    /// Brings splats stored in `axes` into the PLY frame.
    pub fn into_ply_frame(mut self, axes: Axes) -> Splats {
        if axes == Axes::Rub {
            self.flip_y_z();
        }
        self
    }

    /// Turns the splats half a turn about x: means `(x, −y, −z)`, rotations conjugated by that
    /// turn, and SH coefficients signed so that each splat shows the same colour along the
    /// turned directions.
    fn flip_y_z(&mut self) {
        for m in &mut self.means {
            m.y = -m.y;
            m.z = -m.z;
        }
        for q in &mut self.rotations {
            q.y = -q.y;
            q.z = -q.z;
        }
        if let SplatColor::Sh { .. } = self.color {
            let per_splat = self.color.coefficients() * 3;
            for splat in self.coefficients.chunks_exact_mut(per_splat) {
                for (k, rgb) in splat.chunks_exact_mut(3).enumerate() {
                    let sign = FLIP_YZ_SIGNS[k];
                    rgb.iter_mut().for_each(|c| *c *= sign);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{Mat3, Quat, Vec3};

    use super::*;
    use crate::field::splats::SplatFormat;

    /// gsplat's real SH basis of degree 3 at unit direction `d` (DC first).
    fn basis(d: Vec3) -> [f32; 16] {
        let (x, y, z) = (d.x, d.y, d.z);
        let (xx, yy, zz) = (x * x, y * y, z * z);
        [
            1.0,
            -y,
            z,
            -x,
            x * y,
            y * z,
            2.0 * zz - xx - yy,
            x * z,
            xx - yy,
            y * (3.0 * xx - yy),
            x * y * z,
            y * (4.0 * zz - xx - yy),
            z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
            x * (4.0 * zz - xx - yy),
            z * (xx - yy),
            x * (xx - 3.0 * yy),
        ]
    }

    #[test]
    fn a_rub_splat_shows_the_same_colour_and_shape_along_the_turned_directions() {
        let mut s = Splats::with_capacity(1, SplatColor::Sh { degree: 3 }, SplatFormat::Spz);
        let coeffs: Vec<f32> = (0..48).map(|i| (i as f32 * 0.37).sin()).collect();
        let q = Quat::from_axis_angle(Vec3::new(0.3, -0.5, 0.8).normalize(), 0.9);
        assert!(s.push_activated(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(0.1, 0.2, 0.3),
            [q.w, q.x, q.y, q.z],
            0.5,
            &coeffs
        ));
        let turned = s.clone().into_ply_frame(Axes::Rub);
        let f = Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0));
        assert_eq!(turned.means[0], Vec3::new(1.0, -2.0, -3.0));
        // The covariance's axes turn with the frame: R' = F R F.
        let want = f * Mat3::from_quat(s.rotations[0]) * f;
        let got = Mat3::from_quat(turned.rotations[0]);
        assert!(got.abs_diff_eq(want, 1e-6), "{got} vs {want}");
        for d in [
            Vec3::X,
            Vec3::new(0.2, -0.7, 0.4),
            Vec3::new(-0.6, 0.1, -0.3),
        ] {
            let d = d.normalize();
            for c in 0..3 {
                let value = |splats: &Splats, dir: Vec3| -> f32 {
                    basis(dir)
                        .iter()
                        .enumerate()
                        .map(|(k, b)| b * splats.coefficients[k * 3 + c])
                        .sum()
                };
                let (a, b) = (value(&s, d), value(&turned, f * d));
                assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            }
        }
        assert_eq!(turned.clone().into_ply_frame(Axes::Stored), turned);
        assert_eq!(turned.into_ply_frame(Axes::Rub).means, s.means);
    }
}
