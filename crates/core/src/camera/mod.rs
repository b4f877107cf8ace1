//! Cameras: where each pixel's ray starts and which way it goes, in the host's world.
//!
//! A [`Camera`] is a rigid `world_from_camera` placement plus a [`Projection`] (Blender's
//! perspective camera with its full intrinsics, equirectangular, VR180, ODS). Camera space is
//! Blender's and nerfstudio's: looking down −Z, +Y up, +X right. Raster space is the image's:
//! `x` right, `y` *down*, pixel centres at `i + 0.5`.
//!
//! Alignment to a field (`C_t = N⁻¹ C_o`) is not done here: the scene carries each world ray
//! into every field instance's frame (see [`crate::scene`]), so several fields with their own
//! object transforms can be marched jointly.

mod aperture;
mod environment;
mod equirect;
mod interpolate;
mod nerfstudio;
mod perspective;
mod shot;
mod shot_file;
mod shutter;
mod stereo;

pub use aperture::{aperture_points, DepthOfField, MAX_APERTURE_SAMPLES, MAX_BLADES};
pub use environment::environment_camera;
pub use equirect::Equirect;
pub use nerfstudio::{CameraPath, PathCameraType, PathCrop, PathFrame, PathKeyframe};
pub use perspective::{BlenderIntrinsics, Perspective, SensorFit};
pub use shot::{SceneWorld, Shot, ShotCamera, ShotCameraKind, ShotFrame, ShotStereo, StereoMode};
pub use shot_file::read_shot;
pub use shutter::{MotionBlur, ShutterPosition, MAX_SHUTTER, MAX_SHUTTER_SAMPLES};
pub use stereo::{Eye, Ods, Vr180, DEFAULT_IPD};

use glam::{DMat4, DVec3};

use crate::error::{Error, Result};
use crate::image::Window;

/// A ray in the host's world, one per pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Where the ray starts (world units).
    pub origin: DVec3,
    /// Unit direction (world).
    pub dir: DVec3,
    /// Camera-space depth per unit of ray distance: `dot(dir, camera −Z)` for a perspective
    /// camera (so `Z = t · z_per_t` is what Blender's Z pass holds), 1 for panoramic cameras.
    pub z_per_t: f64,
    /// Ray distance where the camera's clipping range starts (`clip_start / z_per_t`: like
    /// Blender, a perspective camera clips at planes of constant depth) …
    pub near: f64,
    /// … and where it ends.
    pub far: f64,
}

/// A ray in camera space, as a projection produces it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRay {
    /// Origin in camera space (non-zero for stereo eyes).
    pub origin: DVec3,
    /// Unit direction in camera space.
    pub(crate) dir: DVec3,
    /// See [`Ray::z_per_t`].
    pub(crate) z_per_t: f64,
}

/// How camera-space rays leave the camera.
#[derive(Clone, Debug, PartialEq)]
pub enum Projection {
    /// Blender's perspective camera.
    Perspective(Perspective),
    /// Equirectangular (latitude-longitude) panorama, nerfstudio's convention.
    Equirect(Equirect),
    /// VR180 stereo: two half-sphere fisheye-like equirect halves side by side.
    Vr180(Vr180),
    /// Omni-directional stereo: left eye stacked over right.
    Ods(Ods),
}

impl Projection {
    /// The output image size in pixels (for stereo layouts, both eyes together).
    pub(crate) fn resolution(&self) -> (u32, u32) {
        match self {
            Projection::Perspective(p) => p.resolution(),
            Projection::Equirect(p) => p.resolution(),
            Projection::Vr180(p) => p.resolution(),
            Projection::Ods(p) => p.resolution(),
        }
    }

    /// The camera-space ray through raster position (`x`, `y`) (pixel centres at `i + 0.5`),
    /// or `None` where the projection has no ray.
    pub(crate) fn camera_ray(&self, x: f64, y: f64) -> Option<CameraRay> {
        match self {
            Projection::Perspective(p) => p.camera_ray(x, y),
            Projection::Equirect(p) => p.camera_ray(x, y),
            Projection::Vr180(p) => p.camera_ray(x, y),
            Projection::Ods(p) => p.camera_ray(x, y),
        }
    }
}

/// The largest cosine between two axes of a camera matrix taken as perpendicular: far above
/// the rounding of a matrix stored in single precision (~1e-7), far below a visible shear.
const SHEAR_TOLERANCE: f64 = 1e-4;

/// A placed camera: rigid `world_from_camera` and a projection.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    world_from_camera: DMat4,
    projection: Projection,
    /// Camera-space depth range seen (Blender's `clip_start`, `clip_end`).
    clip: [f64; 2],
}

impl Camera {
    /// A camera at `world_from_camera` (Blender's `matrix_world`). Scale on the camera object
    /// is removed, as Blender's renderer does; a matrix with NaN/inf, zero scale, shear or a
    /// projective row is refused.
    pub fn new(world_from_camera: DMat4, projection: Projection) -> Result<Self> {
        let m = world_from_camera;
        if !m.is_finite() {
            return Err(Error::invalid(
                "camera matrix_world",
                "contains NaN or infinity",
            ));
        }
        if m.row(3) != glam::DVec4::new(0.0, 0.0, 0.0, 1.0) {
            return Err(Error::invalid(
                "camera matrix_world",
                format!("bottom row is {:?}, expected [0, 0, 0, 1]", m.row(3)),
            ));
        }
        let x = m.x_axis.truncate();
        let y = m.y_axis.truncate();
        let z = m.z_axis.truncate();
        let (lx, ly, lz) = (x.length(), y.length(), z.length());
        let smallest = lx.min(ly).min(lz);
        if smallest <= 1e-12 * lx.max(ly).max(lz).max(1.0) || x.cross(y).dot(z) <= 0.0 {
            return Err(Error::invalid(
                "camera matrix_world",
                "degenerate or mirrored rotation",
            ));
        }
        // Scale is removed below, as Blender does; shear cannot be: the renderers that wrote
        // the matrix would see through non-perpendicular axes, and nothing here does.
        let (xu, yu, zu) = (x / lx, y / ly, z / lz);
        for (a, b, u, v) in [("X", "Y", xu, yu), ("Y", "Z", yu, zu), ("X", "Z", xu, zu)] {
            let cos = u.dot(v);
            if cos.abs() > SHEAR_TOLERANCE {
                return Err(Error::invalid(
                    "camera matrix_world",
                    format!(
                        "sheared: its {a} and {b} axes are {:.3}° apart, not 90° (a camera \
                         parented to a non-uniformly scaled object?); apply the parent's scale \
                         or unparent the camera keeping its transform",
                        cos.clamp(-1.0, 1.0).acos().to_degrees()
                    ),
                ));
            }
        }
        // Orthonormalise (Gram-Schmidt, keeping the view axis −Z exact).
        let zn = z / lz;
        let xn = (x - zn * x.dot(zn)).normalize();
        let yn = zn.cross(xn);
        let rigid = DMat4::from_cols(xn.extend(0.0), yn.extend(0.0), zn.extend(0.0), m.w_axis);
        Ok(Camera {
            world_from_camera: rigid,
            projection,
            clip: [0.0, f64::INFINITY],
        })
    }

    /// [`Camera::new`] for a matrix whose shear is carried elsewhere: a nerfstudio camera path
    /// written in a non-uniformly scaled object's frame, whose shot puts the difference
    /// between the path's matrix and this camera into that object (see
    /// `CameraPath::to_shot`). The camera is the matrix's rigid part (its −Z axis kept
    /// exact); a matrix [`Camera::new`] would refuse for any other reason is refused.
    pub(crate) fn from_affine(world_from_camera: DMat4, projection: Projection) -> Result<Self> {
        let m = world_from_camera;
        let (x, y, z) = (
            m.x_axis.truncate(),
            m.y_axis.truncate(),
            m.z_axis.truncate(),
        );
        if !(m.is_finite() && x.cross(y).dot(z) > 0.0) {
            return Self::new(m, projection);
        }
        let zn = z.normalize();
        let xn = (x - zn * x.dot(zn)).normalize();
        let rigid = DMat4::from_cols(
            xn.extend(0.0),
            zn.cross(xn).extend(0.0),
            zn.extend(0.0),
            m.w_axis,
        );
        Self::new(rigid, projection)
    }

    /// The camera seeing only depths in `[start, end]` (Blender's `clip_start`, `clip_end`;
    /// depth as its Z pass measures it); by default everything in front of it.
    pub fn with_clip(mut self, start: f64, end: f64) -> Result<Self> {
        if !(start >= 0.0 && end > start) {
            return Err(Error::invalid(
                "camera clipping",
                format!("clip_start {start} and clip_end {end}: need 0 ≤ start < end"),
            ));
        }
        self.clip = [start, end];
        Ok(self)
    }

    /// The rigid camera placement.
    pub fn world_from_camera(&self) -> DMat4 {
        self.world_from_camera
    }

    /// Camera-space depths `[clip_start, clip_end]` (Blender's clipping).
    pub fn clip(&self) -> [f64; 2] {
        self.clip
    }

    /// The projection.
    pub fn projection(&self) -> &Projection {
        &self.projection
    }

    /// The output image size in pixels.
    pub fn resolution(&self) -> (u32, u32) {
        self.projection.resolution()
    }

    /// The whole image as a render window.
    pub fn full_window(&self) -> Window {
        let (w, h) = self.resolution();
        Window::new(0, 0, w, h)
    }

    /// The part of `window` inside the image, refused when it is larger than one render may
    /// produce (16k × 16k pixels), so an absurd resolution fails before anything allocates.
    pub fn clamp_window(&self, window: Window) -> Result<Window> {
        const MAX_WINDOW_PIXELS: usize = 1 << 28;
        let window = window.intersect(&self.full_window());
        if window.area() > MAX_WINDOW_PIXELS {
            return Err(Error::invalid(
                "render window",
                format!(
                    "{}×{} pixels is more than one render may produce ({MAX_WINDOW_PIXELS})",
                    window.width(),
                    window.height()
                ),
            ));
        }
        Ok(window)
    }

    /// The world ray through raster position (`x`, `y`) (top-left origin, pixel centres at
    /// `i + 0.5`), or `None` where the projection has none.
    pub fn ray(&self, x: f64, y: f64) -> Option<Ray> {
        let r = self.projection.camera_ray(x, y)?;
        Some(self.world_ray(r, self.world_from_camera.transform_point3(r.origin)))
    }

    /// Whether a window's rays ([`window_rays`](Self::window_rays)) share one origin and each
    /// points inside the pyramid of the window's corner pixels' rays: a pinhole's do, their
    /// directions being affine in the pixel position before they are normalised.
    pub(crate) fn rectilinear(&self) -> bool {
        matches!(self.projection, Projection::Perspective(_))
    }

    /// Replaces `out` with the world rays through the pixel centres of `window`, row by row:
    /// the same rays as [`Self::ray`] gives, with what they share (a perspective camera's
    /// origin, its columns' and rows' slopes) worked out once.
    pub(crate) fn window_rays(&self, window: Window, out: &mut Vec<Option<Ray>>) {
        out.clear();
        match &self.projection {
            Projection::Perspective(p) => {
                let origin = self.world_from_camera.transform_point3(DVec3::ZERO);
                p.window_rays(window, |r| {
                    out.push(r.map(|r| self.world_ray(r, origin)));
                });
            }
            _ => out.extend((window.y0..window.y1).flat_map(|y| {
                (window.x0..window.x1)
                    .map(move |x| self.ray(f64::from(x) + 0.5, f64::from(y) + 0.5))
            })),
        }
    }

    /// The camera ray `r` in the world, its origin placed there already (`origin`).
    #[inline]
    fn world_ray(&self, r: CameraRay, origin: DVec3) -> Ray {
        let [start, end] = self.clip;
        Ray {
            origin,
            dir: self.world_from_camera.transform_vector3(r.dir),
            z_per_t: r.z_per_t,
            near: start / r.z_per_t,
            far: end / r.z_per_t,
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::DQuat;

    use super::*;

    #[test]
    fn a_sheared_camera_is_refused_a_scaled_one_is_not() {
        let projection =
            Projection::Perspective(Perspective::from_vertical_fov(8, 8, 40.0).unwrap());
        // Scaled non-uniformly but perpendicular: the scale is removed.
        let scaled = DMat4::from_scale(DVec3::new(2.0, 0.5, 3.0));
        assert!(Camera::new(scaled, projection.clone()).is_ok());
        // Y leans 5.7° towards X.
        let mut sheared = DMat4::IDENTITY;
        sheared.y_axis.x = 0.1;
        let e = Camera::new(sheared, projection.clone())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sheared") && e.contains("X and Y axes are 84.289°"),
            "{e}"
        );
        // Rounding of a single-precision matrix is not shear.
        let mut rounded = DMat4::from_rotation_y(0.3);
        rounded.x_axis.y += 1e-7;
        assert!(Camera::new(rounded, projection).is_ok());
    }

    /// A window's rays, worked out together, are the rays [`Camera::ray`] gives pixel by
    /// pixel, bit for bit, for a perspective camera (the shared path) and a panoramic one.
    #[test]
    fn window_rays_are_the_pixels_rays() {
        let placement = DMat4::from_rotation_translation(
            DQuat::from_euler(glam::EulerRot::XYZ, 1.1, -0.3, 0.7),
            DVec3::new(3.0, -4.5, 2.25),
        );
        let intrinsics = BlenderIntrinsics {
            lens: 35.0,
            shift_x: 0.1,
            resolution_x: 97,
            resolution_y: 61,
            ..BlenderIntrinsics::default()
        };
        let projections = [
            Projection::Perspective(Perspective::from_blender(&intrinsics).unwrap()),
            Projection::Equirect(Equirect::new(64, 32).unwrap()),
        ];
        let window = Window::new(13, 7, 29, 24);
        let mut rays = Vec::new();
        for projection in projections {
            let camera = Camera::new(placement, projection)
                .unwrap()
                .with_clip(0.1, 100.0)
                .unwrap();
            camera.window_rays(window, &mut rays);
            let expected: Vec<_> = (window.y0..window.y1)
                .flat_map(|y| (window.x0..window.x1).map(move |x| (x, y)))
                .map(|(x, y)| camera.ray(f64::from(x) + 0.5, f64::from(y) + 0.5))
                .collect();
            assert_eq!(rays.len(), window.area());
            assert_eq!(rays, expected);
        }
    }
}
