//! Stereo panoramas: omni-directional stereo (ODS) and VR180, nerfstudio's conventions.
//!
//! What nerfstudio does (`nerfstudio/cameras/cameras.py`, `_compute_rays_for_omnidirectional_stereo`
//! and `_compute_rays_for_vr180`; `camera_paths.py`; `scripts/render.py`), restated here:
//! - Each eye is rendered as its own image of the camera path's `render_width × render_height`,
//!   with the equirectangular intrinsics `fx = W/2`, `fy = H`, `cx = W/2`, `cy = H/2`. The
//!   eyes are then joined by ffmpeg: ODS stacks **left over right** (`W × 2H`), VR180 puts
//!   **left | right** (`2W × H`). So `width`/`height` here are *per eye*, as in
//!   `camera_path.json`, and [`Eye::Both`] gives the joined layout.
//! - ODS directions are the equirectangular ones (see [`super::Equirect`]), with azimuth
//!   `θ = −π(x − cx)/fx`; each ray starts on a circle of radius ipd/2:
//!   `origin = ±(ipd/2)(cos θ x̂ − sin θ ẑ)` (right +, left −), i.e. perpendicular to the
//!   ray's horizontal heading, on the viewer's right for the right eye.
//! - VR180 halves the azimuth range: `θ = −π(x − cx)/(2fx)` spans ±90°; rows as equirect;
//!   the eyes sit at `±(ipd/2) x̂` (right +).
//! - The ipd is 0.064 scene units ([`DEFAULT_IPD`]); the scene must be at true scale.
//!
//! Camera depth for both is ray distance (`z_per_t = 1`).

use std::f64::consts::PI;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::equirect::{check_size, equirect_direction};
use super::CameraRay;
use crate::error::{number, Error, Result};

/// nerfstudio's interpupillary distance, in scene units (metres at true scale).
pub const DEFAULT_IPD: f64 = 0.064;

/// Which eye(s) a stereo camera renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Eye {
    /// The left eye only.
    Left,
    /// The right eye only.
    Right,
    /// Both eyes in one image (ODS: left over right; VR180: left | right).
    Both,
}

/// Sign of the eye offset along the baseline: left −1, right +1.
fn eye_sign(right: bool) -> f64 {
    if right {
        1.0
    } else {
        -1.0
    }
}

fn check_ipd(what: &str, ipd: f64) -> Result<()> {
    if !(ipd.is_finite() && ipd >= 0.0) {
        return Err(Error::invalid(
            format!("{what} ipd"),
            format!("expected a finite distance ≥ 0, got {}", number(ipd)),
        ));
    }
    Ok(())
}

/// Splits a raster coordinate of a two-eye layout: `(is_right_eye, coordinate in that eye)`,
/// or `None` outside `[0, 2·side]`. Only one eye (`Left`/`Right`) covers `[0, side]`.
fn split(eye: Eye, c: f64, side: f64) -> Option<(bool, f64)> {
    match eye {
        Eye::Left | Eye::Right if (0.0..=side).contains(&c) => Some((eye == Eye::Right, c)),
        Eye::Both if (0.0..side).contains(&c) => Some((false, c)),
        Eye::Both if (side..=2.0 * side).contains(&c) => Some((true, c - side)),
        _ => None,
    }
}

/// Omni-directional stereo: a full equirectangular panorama per eye, each ray starting on
/// the eye circle tangent to its heading.
#[derive(Clone, Debug, PartialEq)]
pub struct Ods {
    width: u32,
    height: u32,
    eye: Eye,
    ipd: f64,
}

impl Ods {
    /// An ODS camera with `width × height` pixels *per eye*, rendering `eye`, with
    /// interpupillary distance `ipd` (scene units, usually [`DEFAULT_IPD`]).
    pub fn new(width: u32, height: u32, eye: Eye, ipd: f64) -> Result<Self> {
        check_size("ODS camera", width, height)?;
        if eye == Eye::Both {
            check_size("ODS camera (both eyes)", width, height.saturating_mul(2))?;
        }
        check_ipd("ODS camera", ipd)?;
        Ok(Ods {
            width,
            height,
            eye,
            ipd,
        })
    }

    /// The image size: one eye's, or `W × 2H` for [`Eye::Both`] (left on top).
    pub(crate) fn resolution(&self) -> (u32, u32) {
        match self.eye {
            Eye::Both => (self.width, 2 * self.height),
            _ => (self.width, self.height),
        }
    }

    /// The camera-space ray through raster (`x`, `y`), `None` outside the image.
    pub(crate) fn camera_ray(&self, x: f64, y: f64) -> Option<CameraRay> {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        if !(0.0..=w).contains(&x) {
            return None;
        }
        let (right, y) = split(self.eye, y, h)?;
        let theta = -PI * (x - w / 2.0) / (w / 2.0);
        let (sin_t, cos_t) = theta.sin_cos();
        let r = eye_sign(right) * self.ipd / 2.0;
        Some(CameraRay {
            origin: DVec3::new(r * cos_t, 0.0, -r * sin_t),
            dir: equirect_direction(theta, y, h),
            z_per_t: 1.0,
        })
    }
}

/// VR180: a front half-sphere per eye (azimuth ±90°), eyes side by side on the camera X axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Vr180 {
    width: u32,
    height: u32,
    eye: Eye,
    ipd: f64,
}

impl Vr180 {
    /// A VR180 camera with `width × height` pixels *per eye*, rendering `eye`, with
    /// interpupillary distance `ipd` (scene units, usually [`DEFAULT_IPD`]).
    pub fn new(width: u32, height: u32, eye: Eye, ipd: f64) -> Result<Self> {
        check_size("VR180 camera", width, height)?;
        if eye == Eye::Both {
            check_size("VR180 camera (both eyes)", width.saturating_mul(2), height)?;
        }
        check_ipd("VR180 camera", ipd)?;
        Ok(Vr180 {
            width,
            height,
            eye,
            ipd,
        })
    }

    /// The image size: one eye's, or `2W × H` for [`Eye::Both`] (left eye on the left).
    pub(crate) fn resolution(&self) -> (u32, u32) {
        match self.eye {
            Eye::Both => (2 * self.width, self.height),
            _ => (self.width, self.height),
        }
    }

    /// The camera-space ray through raster (`x`, `y`), `None` outside the image.
    pub(crate) fn camera_ray(&self, x: f64, y: f64) -> Option<CameraRay> {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        if !(0.0..=h).contains(&y) {
            return None;
        }
        let (right, x) = split(self.eye, x, w)?;
        // θ = −π(x − cx)/(2 fx) with fx = cx = W/2.
        let theta = -PI * (x - w / 2.0) / w;
        Some(CameraRay {
            origin: DVec3::new(eye_sign(right) * self.ipd / 2.0, 0.0, 0.0),
            dir: equirect_direction(theta, y, h),
            z_per_t: 1.0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-12
    }

    #[test]
    fn ods_layout_stacks_left_over_right() {
        let both = Ods::new(400, 200, Eye::Both, DEFAULT_IPD).unwrap();
        assert_eq!(both.resolution(), (400, 400));
        assert_eq!(
            Ods::new(400, 200, Eye::Left, DEFAULT_IPD)
                .unwrap()
                .resolution(),
            (400, 200)
        );
        // Centre of the top half: left eye, looking −Z, origin at −ipd/2 along X.
        let top = both.camera_ray(200.0, 100.0).unwrap();
        assert!(close(top.dir, DVec3::NEG_Z));
        assert!(close(top.origin, DVec3::new(-0.032, 0.0, 0.0)));
        // Same pixel in the bottom half: right eye.
        let bottom = both.camera_ray(200.0, 300.0).unwrap();
        assert!(close(bottom.dir, DVec3::NEG_Z));
        assert!(close(bottom.origin, DVec3::new(0.032, 0.0, 0.0)));
        assert_eq!(bottom.z_per_t, 1.0);
        assert!(both.camera_ray(200.0, 400.5).is_none());
        assert!(both.camera_ray(-1.0, 10.0).is_none());
    }

    #[test]
    fn ods_origins_are_on_the_viewers_side_perpendicular_to_the_heading() {
        let ipd = 0.1;
        for eye in [Eye::Left, Eye::Right] {
            let cam = Ods::new(360, 180, eye, ipd).unwrap();
            for x in [0.5, 45.0, 90.0, 133.0, 270.0, 359.5] {
                let r = cam.camera_ray(x, 90.0).unwrap();
                assert!((r.origin.length() - ipd / 2.0).abs() < 1e-12);
                assert!(r.origin.dot(r.dir).abs() < 1e-12);
                // The viewer's right for heading d (y up) is d × ŷ.
                let right = r.dir.cross(DVec3::Y);
                let side = r.origin.dot(right).signum();
                assert_eq!(side, if eye == Eye::Right { 1.0 } else { -1.0 }, "{x}");
            }
        }
        // Looking −X (a quarter from the left), the right eye sits at −Z (ipd/2).
        let cam = Ods::new(360, 180, Eye::Right, ipd).unwrap();
        let r = cam.camera_ray(90.0, 90.0).unwrap();
        assert!(close(r.dir, DVec3::NEG_X));
        assert!(close(r.origin, DVec3::new(0.0, 0.0, -0.05)));
    }

    #[test]
    fn vr180_layout_is_left_then_right_and_spans_a_half_sphere() {
        let both = Vr180::new(300, 300, Eye::Both, DEFAULT_IPD).unwrap();
        assert_eq!(both.resolution(), (600, 300));
        let l = both.camera_ray(150.0, 150.0).unwrap();
        assert!(close(l.dir, DVec3::NEG_Z));
        assert!(close(l.origin, DVec3::new(-0.032, 0.0, 0.0)));
        let r = both.camera_ray(450.0, 150.0).unwrap();
        assert!(close(r.dir, DVec3::NEG_Z));
        assert!(close(r.origin, DVec3::new(0.032, 0.0, 0.0)));
        // Each eye's left edge looks along −X, right edge along +X; top row up.
        let right_only = Vr180::new(300, 300, Eye::Right, DEFAULT_IPD).unwrap();
        assert_eq!(right_only.resolution(), (300, 300));
        assert!(close(
            right_only.camera_ray(0.0, 150.0).unwrap().dir,
            DVec3::NEG_X
        ));
        assert!(close(
            right_only.camera_ray(300.0, 150.0).unwrap().dir,
            DVec3::X
        ));
        assert!(close(
            both.camera_ray(300.0, 150.0).unwrap().dir,
            DVec3::NEG_X
        ));
        assert!(close(both.camera_ray(80.0, 0.0).unwrap().dir, DVec3::Y));
        // Origins do not depend on the pixel.
        assert_eq!(
            right_only.camera_ray(17.0, 3.0).unwrap().origin,
            DVec3::new(0.032, 0.0, 0.0)
        );
        assert!(both.camera_ray(601.0, 10.0).is_none());
    }

    #[test]
    fn eye_serde_and_invalid_input() {
        let s = serde_json::to_string(&[Eye::Left, Eye::Right, Eye::Both]).unwrap();
        assert_eq!(s, r#"["left","right","both"]"#);
        assert!(Ods::new(10, 10, Eye::Left, -0.1).is_err());
        assert!(Vr180::new(10, 10, Eye::Left, f64::NAN).is_err());
        assert!(Vr180::new(40000, 10, Eye::Both, 0.064).is_err());
        assert!(Ods::new(10, 0, Eye::Both, 0.064).is_err());
    }
}
