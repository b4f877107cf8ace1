//! The camera of an environment map for Blender's World: an equirectangular panorama laid out
//! as Blender's *Environment Texture* node maps directions, so that the image, set as the
//! World's colour with no Mapping node, lights a Blender scene from where the field is.
//!
//! Blender (checked against Cycles renders of a coded texture) looks a world direction
//! `(x, y, z)` up at `u = ½ − atan2(y, x)/2π`, `v = ½ + asin(z)/π`, with `v` from the
//! image's bottom row: the image centre faces +X, `u` grows towards −Y, the top row is +Z.
//! nerfx's [`Equirect`] (nerfstudio's convention) has the centre at camera −Z, `u` growing
//! towards camera +X and the top at camera +Y; the same image results when the camera's axes
//! sit in the world as X → −Y, Y → +Z, Z → −X.

use glam::{DMat4, DVec3, DVec4};

use super::{Camera, Equirect, Projection};
use crate::error::{Error, Result};

/// An environment-map camera at world `position`: a 2:1 equirectangular image `height`
/// pixels tall (1 to 32768), oriented as Blender's World Environment Texture reads it.
pub fn environment_camera(position: DVec3, height: u32) -> Result<Camera> {
    if !position.is_finite() {
        return Err(Error::invalid(
            "environment map position",
            format!("{position:?} is not finite"),
        ));
    }
    let width = height.checked_mul(2).ok_or_else(|| {
        Error::invalid(
            "environment map height",
            format!("{height} pixels is too large"),
        )
    })?;
    let world_from_camera = DMat4::from_cols(
        DVec4::new(0.0, -1.0, 0.0, 0.0),
        DVec4::new(0.0, 0.0, 1.0, 0.0),
        DVec4::new(-1.0, 0.0, 0.0, 0.0),
        position.extend(1.0),
    );
    Camera::new(
        world_from_camera,
        Projection::Equirect(Equirect::new(width, height)?),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Blender's lookup, written out: the raster position (top-down rows) of direction `d`.
    fn blender_raster(d: DVec3, w: f64, h: f64) -> (f64, f64) {
        let d = d.normalize();
        let u = 0.5 - d.y.atan2(d.x) / (2.0 * PI);
        let v = 0.5 + d.z.asin() / PI;
        (u * w, (1.0 - v) * h)
    }

    #[test]
    fn rays_point_where_blender_looks_the_texture_up() {
        let cam = environment_camera(DVec3::new(1.0, 2.0, 3.0), 64).unwrap();
        assert_eq!(cam.resolution(), (128, 64));
        for d in [
            DVec3::X,
            DVec3::Y,
            DVec3::NEG_Y,
            DVec3::new(0.6, 0.3, 0.5),
            DVec3::new(-0.2, 0.7, -0.4),
            DVec3::new(0.3, -0.8, 0.2),
            DVec3::new(-1.0, -0.1, 0.05),
        ] {
            let (x, y) = blender_raster(d, 128.0, 64.0);
            let ray = cam.ray(x, y).unwrap();
            assert!((ray.origin - DVec3::new(1.0, 2.0, 3.0)).length() < 1e-12);
            assert!(
                (ray.dir - d.normalize()).length() < 1e-9,
                "{d}: {}",
                ray.dir
            );
        }
    }

    #[test]
    fn bad_positions_and_sizes_are_refused() {
        assert!(environment_camera(DVec3::new(f64::NAN, 0.0, 0.0), 64).is_err());
        assert!(environment_camera(DVec3::ZERO, 0).is_err());
        assert!(environment_camera(DVec3::ZERO, 40000).is_err());
    }
}
