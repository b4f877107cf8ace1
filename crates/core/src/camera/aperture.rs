//! Depth of field: Cycles' thin lens, and the points of its aperture a frame is sampled at.
//!
//! Blender's camera (`Camera.dof`) focuses at `focus_distance` along its view axis, the
//! focus *plane* at camera depth `d` (a focus object gives the depth of its origin, which the
//! add-on works out per frame). Cycles gives the aperture a radius of
//! `R = lens·10⁻³ / (2·fstop)` scene units (the lens in millimetres read as metres, whatever
//! the scene's unit scale), the shape of a disk, or, with `aperture_blades ≥ 3`, of a regular
//! polygon with its corners on the circle of radius `R`, turned by `aperture_rotation`; an
//! anamorphic `aperture_ratio` divides the aperture's horizontal extent. A ray leaves the
//! lens at `(R·u/ratio, R·v, 0)` in camera space (`(u, v)` a point of the unit aperture)
//! towards the point its pinhole ray meets the focus plane.
//!
//! nerfx renders one pinhole image per aperture point: the pinhole moved to the lens point
//! `l = (lx, ly)` and its image plane sheared by `−l/d` (a lens shift of
//! `−l·lens/(d·sensor)`), so that every point of the focus plane lands on the pixel it has
//! without depth of field.
//! Each pixel of that image is then exactly the thin-lens ray through that lens point, for
//! every pixel at once, and the frame is the mean of the images over stratified aperture
//! points ([`aperture_points`]): the same construction for fields and splats.

use glam::DVec2;

use crate::error::{Error, Result};

/// Most aperture samples one frame may be rendered with.
pub const MAX_APERTURE_SAMPLES: u32 = 4096;

/// Most aperture blades Blender allows.
pub const MAX_BLADES: u32 = 100;

/// A camera's depth of field at one frame, as Blender's `Camera.dof` gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthOfField {
    /// Camera depth of the focus plane, scene units (> 0).
    pub focus_distance: f64,
    /// The f-number (> 0): the aperture radius is `lens·10⁻³ / (2·fstop)`.
    pub fstop: f64,
    /// Polygonal aperture: 0 (or 1, 2: Cycles reads fewer than 3 as a disk) for a disk, else
    /// the number of corners (at most [`MAX_BLADES`]).
    pub blades: u32,
    /// Turn of the polygon, radians, counter-clockwise as seen from behind the camera.
    pub rotation: f64,
    /// Anamorphic ratio (> 0): the aperture's width is divided by it.
    pub ratio: f64,
}

impl DepthOfField {
    /// Checks every setting, naming `what` and the field in the error.
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |field: &str, why: String| Err(Error::invalid(format!("{what}.{field}"), why));
        if !(self.focus_distance.is_finite() && self.focus_distance > 0.0) {
            return bad(
                "focus_distance",
                format!("{}; expected a distance > 0", self.focus_distance),
            );
        }
        if !(self.fstop.is_finite() && self.fstop > 0.0) {
            return bad("fstop", format!("{}; expected an f-number > 0", self.fstop));
        }
        if self.blades > MAX_BLADES {
            return bad(
                "blades",
                format!(
                    "{}; expected 0 to {MAX_BLADES} (fewer than 3: a round aperture)",
                    self.blades
                ),
            );
        }
        if !self.rotation.is_finite() {
            return bad("rotation", format!("{}; expected an angle", self.rotation));
        }
        if !(self.ratio.is_finite() && self.ratio > 0.0) {
            return bad("ratio", format!("{}; expected a ratio > 0", self.ratio));
        }
        Ok(())
    }

    /// The aperture radius in scene units for a lens of `lens` mm (Cycles':
    /// `lens·10⁻³ / (2·fstop)`).
    ///
    /// ```
    /// use nerfx_core::camera::DepthOfField;
    /// let dof = DepthOfField {
    ///     focus_distance: 4.0, fstop: 2.0, blades: 0, rotation: 0.0, ratio: 1.0,
    /// };
    /// assert_eq!(dof.aperture_radius(50.0), 0.0125);
    /// ```
    pub fn aperture_radius(&self, lens: f64) -> f64 {
        lens * 1e-3 / (2.0 * self.fstop)
    }

    /// The camera-space lens points (x right, y up, scene units) a frame is rendered through
    /// with `samples` samples: [`aperture_points`] of this aperture's shape, scaled by its
    /// radius for a lens of `lens` mm, the x coordinate divided by the anamorphic ratio.
    pub fn lens_points(&self, lens: f64, samples: u32) -> Vec<DVec2> {
        let r = self.aperture_radius(lens);
        aperture_points(samples, self.blades, self.rotation)
            .into_iter()
            .map(|p| DVec2::new(p.x * r / self.ratio, p.y * r))
            .collect()
    }
}

/// `samples` fixed, stratified points of the unit aperture: a disk (`blades` < 3) or the
/// regular polygon with `blades` corners on the unit circle turned by `rotation`. The points
/// are the centred Hammersley set `((k + ½)/n, frac(φ₂(k) + 1/(2n)))` (`φ₂` the base-2 radical
/// inverse: for `n` a power of two, one point in each of the `n` elementary intervals of the
/// unit square), mapped as Cycles maps its lens samples: the disk by Shirley and Chiu's
/// concentric mapping, the polygon by choosing its triangle from the first coordinate and a
/// uniform point in it. Both maps preserve area, so the points are uniform in the aperture
/// and stratified; one sample is the aperture's centre.
///
/// ```
/// use nerfx_core::camera::aperture_points;
/// assert_eq!(aperture_points(1, 0, 0.0), vec![glam::DVec2::ZERO]);
/// assert!(aperture_points(64, 6, 0.3).iter().all(|p| p.length() <= 1.0 + 1e-12));
/// ```
pub fn aperture_points(samples: u32, blades: u32, rotation: f64) -> Vec<DVec2> {
    let n = samples.max(1);
    let half = 0.5 / f64::from(n);
    (0..n)
        .map(|k| {
            let u = (f64::from(k) + 0.5) / f64::from(n);
            let v = (radical_inverse(k) + half).fract();
            if blades < 3 {
                concentric_disk(u, v)
            } else {
                polygon(u, v, blades, rotation)
            }
        })
        .collect()
}

/// The base-2 radical inverse of `k`: its bits mirrored about the binary point.
fn radical_inverse(k: u32) -> f64 {
    f64::from(k.reverse_bits()) / 4_294_967_296.0
}

/// Shirley and Chiu's concentric map of the unit square onto the unit disk.
fn concentric_disk(u: f64, v: f64) -> DVec2 {
    let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    if a == 0.0 && b == 0.0 {
        return DVec2::ZERO;
    }
    let quarter = std::f64::consts::FRAC_PI_4;
    let (r, phi) = if a.abs() > b.abs() {
        (a, quarter * (b / a))
    } else {
        (b, 2.0 * quarter - quarter * (a / b))
    };
    DVec2::new(r * phi.cos(), r * phi.sin())
}

/// A uniform point of the regular polygon with `corners` corners on the unit circle, turned
/// by `rotation`: `u` picks one of the triangles (centre, two neighbouring corners) and its
/// remainder with `v` a uniform point in it.
fn polygon(u: f64, v: f64, corners: u32, rotation: f64) -> DVec2 {
    let n = f64::from(corners);
    let corner = (u * n).floor().min(n - 1.0);
    // The triangle's axis is +x, its outer corners (cos h, ±sin h): `s` (√ of the remainder,
    // so that area grows linearly) is how far out along the axis, `v` where across.
    let s = (u * n - corner).sqrt();
    let half = std::f64::consts::PI / n;
    let local = DVec2::new(s * half.cos(), (1.0 - 2.0 * v) * s * half.sin());
    DVec2::from_angle(rotation + corner * 2.0 * half).rotate(local)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dof() -> DepthOfField {
        DepthOfField {
            focus_distance: 3.0,
            fstop: 1.4,
            blades: 0,
            rotation: 0.0,
            ratio: 1.0,
        }
    }

    /// Points are uniform over the aperture: their mean is its centre and their second
    /// moments are the disk's `R²/4` per axis (a polygon's from its closed form).
    #[test]
    fn points_are_uniform_over_the_aperture() {
        let disk = aperture_points(1024, 0, 0.0);
        let mean = disk.iter().copied().sum::<DVec2>() / 1024.0;
        assert!(mean.length() < 1e-3, "{mean}");
        let xx = disk.iter().map(|p| p.x * p.x).sum::<f64>() / 1024.0;
        let yy = disk.iter().map(|p| p.y * p.y).sum::<f64>() / 1024.0;
        assert!(
            (xx - 0.25).abs() < 2e-3 && (yy - 0.25).abs() < 2e-3,
            "{xx} {yy}"
        );
        assert!(disk.iter().all(|p| p.length() <= 1.0 + 1e-12));
        // A regular n-gon of circumradius 1: the second moment of each of its triangles
        // (0, c1, c2) about the origin.
        for blades in [3u32, 5, 6, 8] {
            let pts = aperture_points(960, blades, 0.4);
            let n = f64::from(blades);
            let h = std::f64::consts::PI / n;
            // Corners (cos h, ±sin h): E[r²] = (|c1|² + |c2|² + c1·c2)/6 = (2 + cos 2h)/6.
            let expected = (2.0 + (2.0 * h).cos()) / 6.0;
            let rr = pts.iter().map(|p| p.length_squared()).sum::<f64>() / 960.0;
            assert!((rr - expected).abs() < 2e-3, "{blades}: {rr} vs {expected}");
            let mean = pts.iter().copied().sum::<DVec2>() / 960.0;
            assert!(mean.length() < 2e-3, "{blades}: {mean}");
            // Inside the polygon: every point's distance along each edge normal ≤ cos h.
            for p in &pts {
                for k in 0..blades {
                    let normal = DVec2::from_angle(0.4 + 2.0 * h * f64::from(k));
                    assert!(p.dot(normal) <= h.cos() + 1e-12, "{blades}: {p} outside");
                }
            }
        }
    }

    /// The polygon's corners are where Blender puts them: turned by the rotation, half a
    /// sector from the first triangle's axis.
    #[test]
    fn polygon_corners_follow_the_rotation() {
        let pts = aperture_points(4096, 4, 0.0);
        let farthest = pts
            .iter()
            .copied()
            .max_by(|a, b| a.length().total_cmp(&b.length()))
            .unwrap();
        // A square turned by 0 has its corners at ±45°, ±135°.
        let angle = farthest.y.atan2(farthest.x).to_degrees().rem_euclid(90.0);
        assert!((angle - 45.0).abs() < 3.0, "{angle}");
        let turned = aperture_points(4096, 4, 45f64.to_radians());
        let far = turned
            .iter()
            .copied()
            .max_by(|a, b| a.length().total_cmp(&b.length()))
            .unwrap();
        let angle = far.y.atan2(far.x).to_degrees().rem_euclid(90.0);
        assert!(!(3.0..87.0).contains(&angle), "{angle}");
    }

    #[test]
    fn lens_points_scale_by_radius_and_ratio() {
        let d = DepthOfField {
            ratio: 2.0,
            ..dof()
        };
        let r = d.aperture_radius(35.0);
        assert!((r - 0.035 / 2.8).abs() < 1e-15);
        let pts = d.lens_points(35.0, 256);
        let max_x = pts.iter().map(|p| p.x.abs()).fold(0.0, f64::max);
        let max_y = pts.iter().map(|p| p.y.abs()).fold(0.0, f64::max);
        assert!(max_x <= r / 2.0 + 1e-12 && max_x > 0.9 * r / 2.0, "{max_x}");
        assert!(max_y <= r + 1e-12 && max_y > 0.9 * r, "{max_y}");
    }

    #[test]
    fn absurd_settings_are_refused_by_field() {
        let cases = [
            (
                DepthOfField {
                    fstop: 0.0,
                    ..dof()
                },
                "fstop",
            ),
            (
                DepthOfField {
                    fstop: -2.0,
                    ..dof()
                },
                "fstop",
            ),
            (
                DepthOfField {
                    focus_distance: f64::NAN,
                    ..dof()
                },
                "focus_distance",
            ),
            (
                DepthOfField {
                    focus_distance: 0.0,
                    ..dof()
                },
                "focus_distance",
            ),
            (
                DepthOfField {
                    blades: 101,
                    ..dof()
                },
                "blades",
            ),
            (
                DepthOfField {
                    rotation: f64::INFINITY,
                    ..dof()
                },
                "rotation",
            ),
            (
                DepthOfField {
                    ratio: 0.0,
                    ..dof()
                },
                "ratio",
            ),
        ];
        for (d, field) in cases {
            let e = d.validate("dof").unwrap_err().to_string();
            assert!(e.contains(&format!("dof.{field}")), "{e}");
        }
        assert!(dof().validate("dof").is_ok());
    }
}
