//! What an EXR's header says besides its pixels: the colour space's primaries, the camera that
//! saw the image, the frame rate, and how nerfx made it.
//!
//! The camera follows OpenEXR's standard attributes (`ImfStandardAttributes.h`), which Nuke
//! reads as `exr/worldToCamera` and `exr/worldToNDC` to rebuild a camera for reprojection:
//! - `worldToCamera` takes world points to RenderMan's camera space: left-handed, +X right,
//!   +Y up, **+Z the viewing direction** (Blender's camera looks down −Z, so its Z is negated).
//! - `worldToNDC` takes world points to normalised device coordinates: after the homogeneous
//!   divide, `(0, 0)` is the display window's top-left corner and `(1, 1)` its bottom-right,
//!   y down; its z is depth mapped from the near clip (0) to the far clip (1).
//!
//! Both are Imath `M44f`: row-vector matrices (`p' = p · M`, translation in the last row),
//! stored row by row, which is the column-vector matrix stored column by column. Panoramic
//! cameras have no projective NDC: they get `worldToCamera` only.

use glam::{DMat4, DVec4};

use crate::camera::{Camera, Projection};
use crate::image::OutputColorSpace;

/// An EXR's header entries beyond the image layout.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrHeader {
    /// Width over height of a pixel (2 for an anamorphic shot).
    pub pixel_aspect: f64,
    /// What the colour channels hold; its primaries become the `chromaticities` attribute.
    pub color_space: OutputColorSpace,
    /// The camera's matrices, for a rendered image.
    pub camera: Option<CameraMatrices>,
    /// Frames per second of the sequence (`framesPerSecond`), as a fraction.
    pub frames_per_second: Option<(i32, u32)>,
    /// Further text entries (`nerfx/...`), in order.
    pub entries: Vec<(String, String)>,
}

impl Default for ExrHeader {
    /// Square pixels, linear Rec.709, no camera, no frame rate, no entries.
    fn default() -> Self {
        ExrHeader {
            pixel_aspect: 1.0,
            color_space: OutputColorSpace::LinRec709,
            camera: None,
            frames_per_second: None,
            entries: Vec::new(),
        }
    }
}

/// A camera as OpenEXR's standard attributes describe it (see the module docs): 16 numbers
/// each, in the order the attributes store them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraMatrices {
    /// `worldToCamera`.
    pub world_to_camera: [f32; 16],
    /// `worldToNDC`, for a perspective camera.
    pub world_to_ndc: Option<[f32; 16]>,
}

impl CameraMatrices {
    /// The matrices of `camera` (world = the host's world, Blender's for a shot).
    ///
    /// ```
    /// use glam::{DMat4, DVec3};
    /// use nerfx_core::camera::{BlenderIntrinsics, Camera, Perspective, Projection};
    /// use nerfx_core::image::CameraMatrices;
    /// // A camera at (0, 0, 5) looking down −Z at the origin, 1920×1080, 50 mm on 36 mm.
    /// let lens = Perspective::from_blender(&BlenderIntrinsics::default()).unwrap();
    /// let camera = Camera::new(
    ///     DMat4::from_translation(DVec3::new(0.0, 0.0, 5.0)),
    ///     Projection::Perspective(lens),
    /// )
    /// .unwrap();
    /// let m = CameraMatrices::of(&camera);
    /// // The origin is 5 units in front of the camera: RenderMan camera z = +5 (row vector
    /// // times matrix: the translation is the last row).
    /// assert_eq!(m.world_to_camera[14], 5.0);
    /// // It projects to the image centre in NDC.
    /// let ndc = m.world_to_ndc.unwrap();
    /// let (x, w) = (ndc[12], ndc[15]);
    /// assert!((x / w - 0.5).abs() < 1e-6);
    /// ```
    pub fn of(camera: &Camera) -> CameraMatrices {
        let flip_z = DMat4::from_diagonal(DVec4::new(1.0, 1.0, -1.0, 1.0));
        let camera_from_world = flip_z * camera.world_from_camera().inverse();
        let world_to_ndc = match camera.projection() {
            Projection::Perspective(p) => {
                let [fx, fy, cx, cy] = p.intrinsics();
                let (w, h) = p.resolution();
                let (w, h) = (f64::from(w), f64::from(h));
                // Depth d > 0 in front: u·d = (fx/w)·x + (cx/w)·d, v·d = −(fy/h)·y + (cy/h)·d.
                let [near, far] = camera.clip();
                let (a, b) = if far.is_finite() {
                    (far / (far - near), -far * near / (far - near))
                } else {
                    (1.0, -near)
                };
                let ndc_from_camera = DMat4::from_cols_array(&[
                    fx / w,
                    0.0,
                    0.0,
                    0.0, // column 0
                    0.0,
                    -fy / h,
                    0.0,
                    0.0, // column 1
                    cx / w,
                    cy / h,
                    a,
                    1.0, // column 2
                    0.0,
                    0.0,
                    b,
                    0.0, // column 3
                ]);
                Some(stored(ndc_from_camera * camera_from_world))
            }
            _ => None,
        };
        CameraMatrices {
            world_to_camera: stored(camera_from_world),
            world_to_ndc,
        }
    }
}

/// A column-vector matrix as an Imath `M44f` attribute stores it: its transpose, row by row,
/// which is the matrix itself column by column.
fn stored(m: DMat4) -> [f32; 16] {
    m.to_cols_array().map(|v| v as f32)
}

/// `rate` frames per second as a fraction: exact for whole rates and for NTSC's
/// `fps / fps_base` (24 / 1.001 → 24000/1001), else to a thousandth of a frame.
pub fn frames_per_second(fps: f64, fps_base: f64) -> Option<(i32, u32)> {
    if !(fps.is_finite() && fps_base.is_finite() && fps > 0.0 && fps_base > 0.0) {
        return None;
    }
    let thousandths = |v: f64| {
        let t = (v * 1000.0).round();
        ((v * 1000.0 - t).abs() < 1e-6 && t >= 1.0 && t < f64::from(i32::MAX)).then_some(t as u64)
    };
    let (n, d) = match (thousandths(fps), thousandths(fps_base)) {
        (Some(n), Some(d)) => (n, d),
        _ => {
            let rate = (fps / fps_base * 1000.0).round();
            if !(rate >= 1.0 && rate < f64::from(i32::MAX)) {
                return None;
            }
            (rate as u64, 1000)
        }
    };
    let g = gcd(n, d);
    let (n, d) = (n / g, d / g);
    Some((i32::try_from(n).ok()?, u32::try_from(d).ok()?))
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a.max(1)
    } else {
        gcd(b, a % b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_rates_are_exact_fractions() {
        assert_eq!(frames_per_second(24.0, 1.0), Some((24, 1)));
        assert_eq!(frames_per_second(24.0, 1.001), Some((24000, 1001)));
        assert_eq!(frames_per_second(30.0, 1.001), Some((30000, 1001)));
        assert_eq!(frames_per_second(25.0, 1.0), Some((25, 1)));
        assert_eq!(frames_per_second(0.0, 1.0), None);
        assert_eq!(frames_per_second(f64::NAN, 1.0), None);
        // A rate with no short fraction: to a thousandth.
        assert_eq!(frames_per_second(1.0 / 3.0, 1.0), Some((333, 1000)));
    }
}
