//! Blender's perspective camera with its full intrinsics (sensor fit, shift, pixel aspect,
//! resolution percentage), and nerfstudio's vertical-FOV pinhole.
//!
//! Both reduce to one pinhole in raster space: at camera depth 1 (looking down −Z, +Y up) the
//! raster point (`x`, `y`) (x right, y down, pixel centres at `i + 0.5`) lies at
//!
//! ```text
//! X = (x − cx) / fx,    Y = −(y − cy) / fy,    Z = −1
//! ```
//!
//! For Blender (docs/src/architecture.md, what `world_to_camera_view` does): with the pixel aspects clamped to
//! ≥ 1, `sizex = w·pa_x`, `sizey = h·pa_y`; the fit is horizontal when set so or when AUTO and
//! `sizex ≥ sizey`; the sensor length is `sensor_height` only for an explicit VERTICAL fit;
//! `ycor = pa_y/pa_x`; `viewfac = w` (horizontal fit) or `ycor·h`; `s = sensor/(lens·viewfac)`.
//! The image spans `X ∈ [−w/2 + shift_x·viewfac, w/2 + shift_x·viewfac]·s` and
//! `Y ∈ [−ycor·h/2 + shift_y·viewfac, ycor·h/2 + shift_y·viewfac]·s`, hence
//! `fx = 1/s`, `cx = w/2 − shift_x·viewfac`, `fy = 1/(ycor·s)`, `cy = h/2 + shift_y·viewfac/ycor`.
//!
//! Worked number: a 50 mm lens on a 36 mm sensor at 1920×1080 has `fx = fy = 1920·50/36 =
//! 2666.67` px, and the left image edge looks along `(−18/50, 0, −1)`: a horizontal FOV of
//! `2·atan(18/50) = 39.6°`.

use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};

use super::CameraRay;
use crate::error::{Error, Result};
use crate::image::Window;

/// The largest image side nerfx accepts (Blender's own limit is 65536).
const MAX_SIDE: u64 = 65536;

/// Which sensor dimension the lens is fitted to (Blender's `Camera.sensor_fit`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum SensorFit {
    /// Fit the larger image side to `sensor_width` (Blender's default).
    #[default]
    Auto,
    /// Fit the image width to `sensor_width`.
    Horizontal,
    /// Fit the image height to `sensor_height`.
    Vertical,
}

/// A Blender camera's intrinsics and the scene's output format, as plain data. Lengths are in
/// millimetres, shifts in units of the fitted image side, as in Blender's UI.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlenderIntrinsics {
    /// Focal length (mm).
    pub lens: f64,
    /// Sensor width (mm).
    pub sensor_width: f64,
    /// Sensor height (mm); only used with an explicit [`SensorFit::Vertical`].
    pub sensor_height: f64,
    /// Sensor fit.
    pub sensor_fit: SensorFit,
    /// Horizontal lens shift, in units of the fitted side.
    pub shift_x: f64,
    /// Vertical lens shift, in units of the fitted side.
    pub shift_y: f64,
    /// Output width before the percentage (`scene.render.resolution_x`).
    pub resolution_x: u32,
    /// Output height before the percentage (`scene.render.resolution_y`).
    pub resolution_y: u32,
    /// Resolution scale in percent (`scene.render.resolution_percentage`).
    pub resolution_percentage: u32,
    /// Pixel aspect X (`scene.render.pixel_aspect_x`).
    pub pixel_aspect_x: f64,
    /// Pixel aspect Y (`scene.render.pixel_aspect_y`).
    pub pixel_aspect_y: f64,
}

impl Default for BlenderIntrinsics {
    /// Blender's defaults: 50 mm lens, 36×24 mm sensor, AUTO fit, no shift, 1920×1080 at
    /// 100 %, square pixels.
    fn default() -> Self {
        BlenderIntrinsics {
            lens: 50.0,
            sensor_width: 36.0,
            sensor_height: 24.0,
            sensor_fit: SensorFit::Auto,
            shift_x: 0.0,
            shift_y: 0.0,
            resolution_x: 1920,
            resolution_y: 1080,
            resolution_percentage: 100,
            pixel_aspect_x: 1.0,
            pixel_aspect_y: 1.0,
        }
    }
}

impl BlenderIntrinsics {
    /// The rendered size: `resolution · percentage / 100`, rounded down as Blender does.
    /// Refused when a side is 0 or above 65536.
    pub fn effective_resolution(&self) -> Result<(u32, u32)> {
        let scale = |side: u32, name: &str| -> Result<u32> {
            let s = u64::from(side) * u64::from(self.resolution_percentage) / 100;
            if s == 0 || s > MAX_SIDE {
                return Err(Error::invalid(
                    name,
                    format!(
                        "{side} at {}% gives {s} pixels; expected 1 to {MAX_SIDE}",
                        self.resolution_percentage
                    ),
                ));
            }
            Ok(s as u32)
        };
        Ok((
            scale(self.resolution_x, "resolution_x")?,
            scale(self.resolution_y, "resolution_y")?,
        ))
    }

    /// Refuses values outside the ranges where the camera's maths stays finite and
    /// meaningful: wider than Blender's own (lens and sensor from 1 mm, pixel aspect 1 to 200,
    /// shift ±10), so that nerfstudio paths of up to ~180° (lens well under 1 mm on the
    /// 24 mm sensor they are given) still pass, but never a number that makes rays or depth
    /// non-finite.
    fn validate(&self) -> Result<()> {
        let ranges = [
            ("lens", self.lens, 1e-4, 1e7),
            ("sensor_width", self.sensor_width, 1e-3, 1e5),
            ("sensor_height", self.sensor_height, 1e-3, 1e5),
            ("pixel_aspect_x", self.pixel_aspect_x, 1e-3, 1e3),
            ("pixel_aspect_y", self.pixel_aspect_y, 1e-3, 1e3),
            ("shift_x", self.shift_x, -1e3, 1e3),
            ("shift_y", self.shift_y, -1e3, 1e3),
        ];
        for (name, v, lo, hi) in ranges {
            if !(v >= lo && v <= hi) {
                return Err(Error::invalid(
                    name,
                    format!("{v} is outside {lo:e} to {hi:e}"),
                ));
            }
        }
        Ok(())
    }
}

/// A pinhole camera in raster space: `X = (x − cx)/fx`, `Y = −(y − cy)/fy` at depth 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Perspective {
    width: u32,
    height: u32,
    /// Pixels per unit of camera-space X at depth 1.
    fx: f64,
    /// Pixels per unit of camera-space Y at depth 1.
    fy: f64,
    /// Raster x of the optical axis.
    cx: f64,
    /// Raster y of the optical axis.
    cy: f64,
}

impl Perspective {
    /// Blender's perspective camera, exactly as Blender frames it (see the module docs).
    /// Pixel aspects below 1 are raised to 1, as Blender's UI does.
    pub fn from_blender(b: &BlenderIntrinsics) -> Result<Perspective> {
        b.validate()?;
        let (width, height) = b.effective_resolution()?;
        let (w, h) = (f64::from(width), f64::from(height));
        let pa_x = b.pixel_aspect_x.max(1.0);
        let pa_y = b.pixel_aspect_y.max(1.0);
        let horizontal = match b.sensor_fit {
            SensorFit::Horizontal => true,
            SensorFit::Vertical => false,
            SensorFit::Auto => w * pa_x >= h * pa_y,
        };
        let sensor = if b.sensor_fit == SensorFit::Vertical {
            b.sensor_height
        } else {
            b.sensor_width
        };
        let ycor = pa_y / pa_x;
        let viewfac = if horizontal { w } else { ycor * h };
        let s = sensor / (b.lens * viewfac);
        Ok(Perspective {
            width,
            height,
            fx: 1.0 / s,
            fy: 1.0 / (ycor * s),
            cx: w / 2.0 - b.shift_x * viewfac,
            cy: h / 2.0 + b.shift_y * viewfac / ycor,
        })
    }

    /// nerfstudio's perspective camera: vertical field of view `fov_deg` (degrees),
    /// `f = (H/2)/tan(fov/2)`, `fx = fy = f`, principal point at the image centre.
    pub fn from_vertical_fov(width: u32, height: u32, fov_deg: f64) -> Result<Perspective> {
        for (name, side) in [("width", width), ("height", height)] {
            if side == 0 || u64::from(side) > MAX_SIDE {
                return Err(Error::invalid(
                    format!("camera {name}"),
                    format!("{side} pixels; expected 1 to {MAX_SIDE}"),
                ));
            }
        }
        if !(fov_deg.is_finite() && fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(Error::invalid(
                "camera fov",
                format!("{fov_deg} degrees; expected a vertical FOV strictly between 0 and 180"),
            ));
        }
        let (w, h) = (f64::from(width), f64::from(height));
        let f = (h / 2.0) / (fov_deg.to_radians() / 2.0).tan();
        Ok(Perspective {
            width,
            height,
            fx: f,
            fy: f,
            cx: w / 2.0,
            cy: h / 2.0,
        })
    }

    /// The image size in pixels (after the resolution percentage).
    pub(crate) fn resolution(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// `[fx, fy, cx, cy]` in pixels: the pinhole a rasteriser projects with.
    pub(crate) fn intrinsics(&self) -> [f64; 4] {
        [self.fx, self.fy, self.cx, self.cy]
    }

    /// The camera-space ray through raster (`x`, `y`): origin 0, unit direction through
    /// `((x − cx)/fx, −(y − cy)/fy, −1)`, `z_per_t = −dir.z`. Raster positions outside the
    /// image still have rays (overscan); `None` only for non-finite input.
    pub fn camera_ray(&self, x: f64, y: f64) -> Option<CameraRay> {
        Self::through(self.column(x), self.row(y))
    }

    /// The camera rays through the pixel centres of `window`, row by row: each column's and
    /// row's slope worked out once (the same numbers [`Self::camera_ray`] gives).
    pub(super) fn window_rays(&self, window: Window, mut emit: impl FnMut(Option<CameraRay>)) {
        let columns: Vec<f64> = (window.x0..window.x1)
            .map(|x| self.column(f64::from(x) + 0.5))
            .collect();
        for y in window.y0..window.y1 {
            let row = self.row(f64::from(y) + 0.5);
            for &column in &columns {
                emit(Self::through(column, row));
            }
        }
    }

    /// Camera-space X per unit of depth at raster `x`.
    #[inline]
    fn column(&self, x: f64) -> f64 {
        (x - self.cx) / self.fx
    }

    /// Camera-space Y per unit of depth at raster `y` (down the image, so up is negative).
    #[inline]
    fn row(&self, y: f64) -> f64 {
        -(y - self.cy) / self.fy
    }

    /// The ray through the camera-space point `(column, row, −1)`.
    #[inline]
    fn through(column: f64, row: f64) -> Option<CameraRay> {
        let d = DVec3::new(column, row, -1.0);
        if !d.is_finite() {
            return None;
        }
        let dir = d.normalize();
        Some(CameraRay {
            origin: DVec3::ZERO,
            dir,
            z_per_t: -dir.z,
        })
    }

    /// The raster position of a camera-space point (the inverse of [`Self::camera_ray`]), or
    /// `None` when the point is not in front of the camera (`z ≥ 0`).
    pub fn project(&self, p_camera: DVec3) -> Option<DVec2> {
        let depth = -p_camera.z;
        if depth <= 0.0 || !p_camera.is_finite() {
            return None;
        }
        Some(DVec2::new(
            self.cx + self.fx * p_camera.x / depth,
            self.cy - self.fy * p_camera.y / depth,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The image's extent at camera depth 1, written out from docs/src/architecture.md in its own terms
    /// (`[xmin, xmax] × [ymin, ymax]`), independently of the fx/cx form used by the code.
    fn blender_bounds(b: &BlenderIntrinsics) -> (f64, f64, f64, f64, f64, f64) {
        let w = (b.resolution_x * b.resolution_percentage / 100) as f64;
        let h = (b.resolution_y * b.resolution_percentage / 100) as f64;
        let ax = if b.pixel_aspect_x < 1.0 {
            1.0
        } else {
            b.pixel_aspect_x
        };
        let ay = if b.pixel_aspect_y < 1.0 {
            1.0
        } else {
            b.pixel_aspect_y
        };
        let fit_horizontal = match b.sensor_fit {
            SensorFit::Horizontal => true,
            SensorFit::Vertical => false,
            SensorFit::Auto => w * ax >= h * ay,
        };
        let sensor = match b.sensor_fit {
            SensorFit::Vertical => b.sensor_height,
            _ => b.sensor_width,
        };
        let ycor = ay / ax;
        let viewfac = if fit_horizontal { w } else { ycor * h };
        let pix = sensor / b.lens / viewfac;
        let xmin = (-0.5 * w + b.shift_x * viewfac) * pix;
        let xmax = (0.5 * w + b.shift_x * viewfac) * pix;
        let ymin = (-0.5 * ycor * h + b.shift_y * viewfac) * pix;
        let ymax = (0.5 * ycor * h + b.shift_y * viewfac) * pix;
        (xmin, xmax, ymin, ymax, w, h)
    }

    /// The expected unit direction through raster (x, y): linear interpolation of the bounds.
    fn expected_dir(b: &BlenderIntrinsics, x: f64, y: f64) -> DVec3 {
        let (xmin, xmax, ymin, ymax, w, h) = blender_bounds(b);
        let px = xmin + (xmax - xmin) * x / w;
        let py = ymax - (ymax - ymin) * y / h;
        let n = (px * px + py * py + 1.0).sqrt();
        DVec3::new(px / n, py / n, -1.0 / n)
    }

    fn cases() -> Vec<BlenderIntrinsics> {
        let mut out = Vec::new();
        let resolutions = [(1920, 1080), (1080, 1920), (1000, 1000), (37, 53)];
        let fits = [SensorFit::Auto, SensorFit::Horizontal, SensorFit::Vertical];
        let shifts = [(0.0, 0.0), (0.1, 0.0), (0.0, -0.25), (0.3, 0.2)];
        let aspects = [(1.0, 1.0), (2.0, 1.0), (1.0, 1.5)];
        for &(rx, ry) in &resolutions {
            for &fit in &fits {
                for &(sx, sy) in &shifts {
                    for &(ax, ay) in &aspects {
                        for pct in [100, 50] {
                            out.push(BlenderIntrinsics {
                                lens: 35.0,
                                sensor_width: 36.0,
                                sensor_height: 20.25,
                                sensor_fit: fit,
                                shift_x: sx,
                                shift_y: sy,
                                resolution_x: rx,
                                resolution_y: ry,
                                resolution_percentage: pct,
                                pixel_aspect_x: ax,
                                pixel_aspect_y: ay,
                            });
                        }
                    }
                }
            }
        }
        out
    }

    #[test]
    fn matches_blender_frustum_for_every_fit_shift_aspect_and_percentage() {
        for b in cases() {
            let cam = Perspective::from_blender(&b).unwrap();
            let (_, _, _, _, w, h) = blender_bounds(&b);
            assert_eq!(cam.resolution(), (w as u32, h as u32), "{b:?}");
            for &(fx, fy) in &[(0.0, 0.0), (1.0, 1.0), (0.5, 0.5), (0.25, 0.8), (0.9, 0.1)] {
                let (x, y) = (fx * w, fy * h);
                let r = cam.camera_ray(x, y).unwrap();
                let e = expected_dir(&b, x, y);
                assert!(
                    (r.dir - e).length() < 1e-12,
                    "{b:?} at ({x}, {y}): {:?} vs {e:?}",
                    r.dir
                );
                assert_eq!(r.origin, DVec3::ZERO);
                assert!((r.z_per_t - (-e.z)).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn known_fov_50mm_on_36mm_at_1920x1080() {
        let cam = Perspective::from_blender(&BlenderIntrinsics::default()).unwrap();
        assert_eq!(cam.resolution(), (1920, 1080));
        let left = cam.camera_ray(0.0, 540.0).unwrap().dir;
        let right = cam.camera_ray(1920.0, 540.0).unwrap().dir;
        let hfov = left.angle_between(right);
        assert!((hfov - 2.0 * (18.0f64 / 50.0).atan()).abs() < 1e-12);
        // Vertical extent follows from square pixels: 18/50 · 1080/1920.
        let top = cam.camera_ray(960.0, 0.0).unwrap().dir;
        assert!((top.y / -top.z - 18.0 / 50.0 * 1080.0 / 1920.0).abs() < 1e-12);
        // The centre looks straight down −Z.
        let c = cam.camera_ray(960.0, 540.0).unwrap();
        assert!((c.dir - DVec3::NEG_Z).length() < 1e-15);
        assert_eq!(c.z_per_t, 1.0);
    }

    #[test]
    fn portrait_auto_fits_the_width_sensor_to_the_height() {
        let b = BlenderIntrinsics {
            resolution_x: 1080,
            resolution_y: 1920,
            ..Default::default()
        };
        let cam = Perspective::from_blender(&b).unwrap();
        let top = cam.camera_ray(540.0, 0.0).unwrap().dir;
        assert!((top.y / -top.z - 18.0 / 50.0).abs() < 1e-12);
        let left = cam.camera_ray(0.0, 960.0).unwrap().dir;
        assert!((left.x / -left.z + 18.0 / 50.0 * 1080.0 / 1920.0).abs() < 1e-12);
    }

    #[test]
    fn explicit_vertical_fit_uses_the_sensor_height() {
        let b = BlenderIntrinsics {
            sensor_fit: SensorFit::Vertical,
            ..Default::default()
        };
        let cam = Perspective::from_blender(&b).unwrap();
        let top = cam.camera_ray(960.0, 0.0).unwrap().dir;
        assert!((top.y / -top.z - 12.0 / 50.0).abs() < 1e-12);
    }

    #[test]
    fn numbers_that_would_break_the_maths_are_refused_by_name() {
        for (b, name) in [
            (
                BlenderIntrinsics {
                    lens: 1e-300,
                    ..Default::default()
                },
                "lens",
            ),
            (
                BlenderIntrinsics {
                    lens: f64::NAN,
                    ..Default::default()
                },
                "lens",
            ),
            (
                BlenderIntrinsics {
                    sensor_width: 1e300,
                    ..Default::default()
                },
                "sensor_width",
            ),
            (
                BlenderIntrinsics {
                    pixel_aspect_x: 1e-300,
                    ..Default::default()
                },
                "pixel_aspect_x",
            ),
            (
                BlenderIntrinsics {
                    shift_y: -1e9,
                    ..Default::default()
                },
                "shift_y",
            ),
        ] {
            let e = Perspective::from_blender(&b).unwrap_err().to_string();
            assert!(e.contains(name), "{name}: {e}");
        }
        // A nerfstudio path's 179° field of view is a lens well under 1 mm: still fine.
        let wide = BlenderIntrinsics {
            lens: 12.0 / (89.5f64).to_radians().tan(),
            sensor_fit: SensorFit::Vertical,
            ..Default::default()
        };
        let cam = Perspective::from_blender(&wide).unwrap();
        assert!(cam.camera_ray(0.0, 0.0).unwrap().dir.is_finite());
    }

    #[test]
    fn shift_is_in_units_of_the_fitted_side() {
        // Horizontal fit: shift_x 0.1 moves the centre ray by 0.1·36/50 at depth 1.
        let b = BlenderIntrinsics {
            shift_x: 0.1,
            shift_y: 0.1,
            ..Default::default()
        };
        let cam = Perspective::from_blender(&b).unwrap();
        let c = cam.camera_ray(960.0, 540.0).unwrap().dir;
        assert!((c.x / -c.z - 0.1 * 36.0 / 50.0).abs() < 1e-12);
        assert!((c.y / -c.z - 0.1 * 36.0 / 50.0).abs() < 1e-12);
    }

    #[test]
    fn pixel_aspect_known_values() {
        // 2×1 at 1920×1080: horizontal fit, pixels half as tall as wide in the frustum.
        let b = BlenderIntrinsics {
            pixel_aspect_x: 2.0,
            ..Default::default()
        };
        let cam = Perspective::from_blender(&b).unwrap();
        let left = cam.camera_ray(0.0, 540.0).unwrap().dir;
        assert!((left.x / -left.z + 18.0 / 50.0).abs() < 1e-12);
        let top = cam.camera_ray(960.0, 0.0).unwrap().dir;
        assert!((top.y / -top.z - 0.5 * 540.0 * 36.0 / (50.0 * 1920.0)).abs() < 1e-12);
        // 1×1.5 at 1000×1000: AUTO becomes vertical (1500 > 1000), width sensor on the height.
        let b = BlenderIntrinsics {
            resolution_x: 1000,
            resolution_y: 1000,
            pixel_aspect_y: 1.5,
            ..Default::default()
        };
        let cam = Perspective::from_blender(&b).unwrap();
        let top = cam.camera_ray(500.0, 0.0).unwrap().dir;
        assert!((top.y / -top.z - 18.0 / 50.0).abs() < 1e-12);
        let left = cam.camera_ray(0.0, 500.0).unwrap().dir;
        assert!((left.x / -left.z + 0.24).abs() < 1e-12);
    }

    #[test]
    fn pixel_aspect_below_one_is_raised_to_one() {
        let square = Perspective::from_blender(&BlenderIntrinsics::default()).unwrap();
        let b = BlenderIntrinsics {
            pixel_aspect_x: 0.5,
            pixel_aspect_y: 0.25,
            ..Default::default()
        };
        assert_eq!(Perspective::from_blender(&b).unwrap(), square);
    }

    #[test]
    fn percentage_scales_pixels_not_the_field_of_view() {
        let b = BlenderIntrinsics {
            resolution_percentage: 50,
            resolution_x: 1921,
            ..Default::default()
        };
        let cam = Perspective::from_blender(&b).unwrap();
        assert_eq!(cam.resolution(), (960, 540));
        let left = cam.camera_ray(0.0, 270.0).unwrap().dir;
        assert!((left.x / -left.z + 18.0 / 50.0).abs() < 1e-12);
    }

    #[test]
    fn project_inverts_camera_ray() {
        for b in cases() {
            let cam = Perspective::from_blender(&b).unwrap();
            for &(x, y) in &[(0.5, 0.5), (10.25, 3.75), (30.0, 50.0), (-5.0, 70.0)] {
                for d in [0.01, 1.0, 123.0] {
                    let p = cam.camera_ray(x, y).unwrap().dir * d;
                    let q = cam.project(p).unwrap();
                    assert!((q - DVec2::new(x, y)).length() < 1e-9, "{b:?}: {q:?}");
                }
            }
        }
        let cam = Perspective::from_blender(&BlenderIntrinsics::default()).unwrap();
        assert_eq!(cam.project(DVec3::new(0.0, 0.0, 1.0)), None);
        assert_eq!(cam.project(DVec3::new(1.0, 0.0, 0.0)), None);
    }

    #[test]
    fn vertical_fov_camera() {
        let cam = Perspective::from_vertical_fov(640, 480, 60.0).unwrap();
        assert_eq!(cam.resolution(), (640, 480));
        let top = cam.camera_ray(320.0, 0.0).unwrap().dir;
        assert!((top.angle_between(DVec3::NEG_Z) - 30f64.to_radians()).abs() < 1e-12);
        // fx = fy: a pixel step is the same angle horizontally and vertically at the centre.
        let f = 240.0 / 30f64.to_radians().tan();
        let r = cam.camera_ray(320.0 + f, 240.0).unwrap().dir;
        assert!((r.angle_between(DVec3::NEG_Z) - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    }

    #[test]
    fn invalid_intrinsics_are_refused_with_the_field_name() {
        let bad = [
            (
                BlenderIntrinsics {
                    lens: 0.0,
                    ..Default::default()
                },
                "lens",
            ),
            (
                BlenderIntrinsics {
                    sensor_width: f64::NAN,
                    ..Default::default()
                },
                "sensor_width",
            ),
            (
                BlenderIntrinsics {
                    pixel_aspect_y: -1.0,
                    ..Default::default()
                },
                "pixel_aspect_y",
            ),
            (
                BlenderIntrinsics {
                    shift_x: f64::INFINITY,
                    ..Default::default()
                },
                "shift_x",
            ),
            (
                BlenderIntrinsics {
                    resolution_x: 0,
                    ..Default::default()
                },
                "resolution_x",
            ),
            (
                BlenderIntrinsics {
                    resolution_percentage: 0,
                    ..Default::default()
                },
                "resolution_x",
            ),
            (
                BlenderIntrinsics {
                    resolution_y: 70000,
                    ..Default::default()
                },
                "resolution_y",
            ),
        ];
        for (b, field) in bad {
            let e = Perspective::from_blender(&b).unwrap_err().to_string();
            assert!(e.contains(field), "{e}");
        }
        assert!(Perspective::from_vertical_fov(0, 10, 50.0).is_err());
        assert!(Perspective::from_vertical_fov(10, 10, 180.0).is_err());
        assert!(Perspective::from_vertical_fov(10, 10, f64::NAN).is_err());
    }

    #[test]
    fn sensor_fit_serde_uses_blender_names() {
        let s =
            serde_json::to_string(&[SensorFit::Auto, SensorFit::Horizontal, SensorFit::Vertical])
                .unwrap();
        assert_eq!(s, r#"["AUTO","HORIZONTAL","VERTICAL"]"#);
        let b: BlenderIntrinsics =
            serde_json::from_str(&serde_json::to_string(&BlenderIntrinsics::default()).unwrap())
                .unwrap();
        assert_eq!(b, BlenderIntrinsics::default());
    }
}
