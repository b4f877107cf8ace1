//! Equirectangular (latitude-longitude) panorama, nerfstudio's convention.
//!
//! With `fx = W/2`, `fy = H`, `cx = W/2`, `cy = H/2`, the raster point (`x`, `y`) gives
//! `u = (x − cx)/fx ∈ [−1, 1]`, `v = −(y − cy)/fy ∈ [−½, ½]`, azimuth `θ = −π·u` and polar
//! angle `φ = π(½ − v)`, and the camera-space direction is
//! `(−sin θ sin φ, cos φ, −cos θ sin φ)`: the image centre looks down −Z, the left and right
//! edges look along +Z (behind), the top row at +Y, and the left half of the image sees −X.
//! The stereo projections ([`super::Ods`], [`super::Vr180`]) reuse [`equirect_direction`].

use std::f64::consts::PI;

use glam::DVec3;

use super::CameraRay;
use crate::error::{Error, Result};

/// The largest image side nerfx accepts.
const MAX_SIDE: u32 = 65536;

/// A full-sphere equirectangular camera of `width × height` pixels (usually 2:1).
#[derive(Clone, Debug, PartialEq)]
pub struct Equirect {
    width: u32,
    height: u32,
}

impl Equirect {
    /// An equirectangular camera; each side must be 1 to 65536 pixels.
    pub fn new(width: u32, height: u32) -> Result<Self> {
        check_size("equirectangular camera", width, height)?;
        Ok(Equirect { width, height })
    }

    /// The image size in pixels.
    pub(crate) fn resolution(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The camera-space ray through raster (`x`, `y`): origin 0, `z_per_t = 1` (depth of a
    /// panorama is distance). `None` outside `[0, W] × [0, H]`, where latitude has no meaning.
    pub(crate) fn camera_ray(&self, x: f64, y: f64) -> Option<CameraRay> {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        if !((0.0..=w).contains(&x) && (0.0..=h).contains(&y)) {
            return None;
        }
        let u = (x - w / 2.0) / (w / 2.0);
        Some(CameraRay {
            origin: DVec3::ZERO,
            dir: equirect_direction(-PI * u, y, h),
            z_per_t: 1.0,
        })
    }
}

/// The unit direction for azimuth `theta` and raster row `y` of an image `h` pixels tall:
/// `v = −(y − h/2)/h`, `φ = π(½ − v)`, direction `(−sin θ sin φ, cos φ, −cos θ sin φ)`.
pub(super) fn equirect_direction(theta: f64, y: f64, h: f64) -> DVec3 {
    let v = -(y - h / 2.0) / h;
    let phi = PI * (0.5 - v);
    let (sin_t, cos_t) = theta.sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    DVec3::new(-sin_t * sin_p, cos_p, -cos_t * sin_p)
}

/// Refuses a zero or oversized image side, naming `what`.
pub(super) fn check_size(what: &str, width: u32, height: u32) -> Result<()> {
    for (name, side) in [("width", width), ("height", height)] {
        if side == 0 || side > MAX_SIDE {
            return Err(Error::invalid(
                format!("{what} {name}"),
                format!("{side} pixels; expected 1 to {MAX_SIDE}"),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(cam: &Equirect, x: f64, y: f64) -> DVec3 {
        cam.camera_ray(x, y).unwrap().dir
    }

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-12
    }

    #[test]
    fn landmarks() {
        let cam = Equirect::new(2048, 1024).unwrap();
        assert_eq!(cam.resolution(), (2048, 1024));
        // Centre: straight ahead, −Z.
        assert!(close(dir(&cam, 1024.0, 512.0), DVec3::NEG_Z));
        // Left and right edges: behind, +Z.
        assert!(close(dir(&cam, 0.0, 512.0), DVec3::Z));
        assert!(close(dir(&cam, 2048.0, 512.0), DVec3::Z));
        // A quarter in from the left: −X (the viewer's left); from the right: +X.
        assert!(close(dir(&cam, 512.0, 512.0), DVec3::NEG_X));
        assert!(close(dir(&cam, 1536.0, 512.0), DVec3::X));
        // Top row: up; bottom row: down.
        assert!(close(dir(&cam, 700.0, 0.0), DVec3::Y));
        assert!(close(dir(&cam, 700.0, 1024.0), DVec3::NEG_Y));
    }

    #[test]
    fn latitude_is_linear_in_rows_and_rays_are_unit() {
        let cam = Equirect::new(360, 180).unwrap();
        // Row y is at elevation 90° − y degrees.
        for y in [0.5, 30.0, 89.5, 150.25] {
            let r = cam.camera_ray(180.0, y).unwrap();
            let elevation = r.dir.y.asin().to_degrees();
            assert!((elevation - (90.0 - y)).abs() < 1e-9, "{y}: {elevation}");
            assert!((r.dir.length() - 1.0).abs() < 1e-14);
            assert_eq!(r.z_per_t, 1.0);
            assert_eq!(r.origin, DVec3::ZERO);
        }
    }

    #[test]
    fn outside_the_image_has_no_ray_and_bad_sizes_are_refused() {
        let cam = Equirect::new(64, 32).unwrap();
        assert!(cam.camera_ray(-0.1, 5.0).is_none());
        assert!(cam.camera_ray(5.0, 32.5).is_none());
        assert!(cam.camera_ray(f64::NAN, 5.0).is_none());
        assert!(Equirect::new(0, 32).is_err());
        assert!(Equirect::new(64, 70000)
            .unwrap_err()
            .to_string()
            .contains("height"));
    }
}
