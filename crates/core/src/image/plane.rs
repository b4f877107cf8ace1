//! Planar f32 images and the windows they cover.

use crate::error::{Error, Result};

/// A pixel rectangle `[x0, x1) × [y0, y1)` in raster space (top-left origin, `y` down).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// Left edge (inclusive).
    pub x0: u32,
    /// Top edge (inclusive).
    pub y0: u32,
    /// Right edge (exclusive).
    pub x1: u32,
    /// Bottom edge (exclusive).
    pub y1: u32,
}

impl Window {
    /// The window `[x0, x1) × [y0, y1)`; empty when `x1 <= x0` or `y1 <= y0`.
    pub fn new(x0: u32, y0: u32, x1: u32, y1: u32) -> Self {
        Window {
            x0,
            y0,
            x1: x1.max(x0),
            y1: y1.max(y0),
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }

    /// Number of pixels.
    pub fn area(&self) -> usize {
        self.width() as usize * self.height() as usize
    }

    /// The part of `self` inside `other`.
    pub fn intersect(&self, other: &Window) -> Window {
        Window::new(
            self.x0.max(other.x0),
            self.y0.max(other.y0),
            self.x1.min(other.x1),
            self.y1.min(other.y1),
        )
    }
}

/// One channel, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` samples, row-major, top row first.
    pub data: Vec<f32>,
}

impl Plane {
    /// A plane filled with `value`.
    pub fn filled(width: u32, height: u32, value: f32) -> Self {
        Plane {
            width,
            height,
            data: vec![value; width as usize * height as usize],
        }
    }

    /// The sample at (`x`, `y`).
    pub fn get(&self, x: u32, y: u32) -> f32 {
        self.data[y as usize * self.width as usize + x as usize]
    }
}

/// The planes a render produces; only the requested ones are present.
#[derive(Clone, Debug, PartialEq)]
pub struct Planes {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Premultiplied linear RGB.
    pub rgb: Option<[Plane; 3]>,
    /// Accumulation (opacity): `Σ wᵢ`.
    pub alpha: Option<Plane>,
    /// Expected depth as camera-space Z in world units (`inf` where nothing was hit).
    pub depth_z: Option<Plane>,
    /// Expected depth as distance along the ray in world units (`inf` where nothing was hit).
    pub depth_ray: Option<Plane>,
    /// Median depth (ray distance where the cumulative weight reaches half the
    /// accumulation), world units (`inf` where nothing was hit).
    pub depth_median: Option<Plane>,
}

impl Planes {
    /// The part of every present plane inside `window` (which must lie within the image).
    pub fn crop(&self, window: Window) -> Result<Planes> {
        if window.x1 > self.width || window.y1 > self.height {
            return Err(Error::invalid(
                "crop",
                format!(
                    "window {window:?} is outside the {}×{} image",
                    self.width, self.height
                ),
            ));
        }
        let cut = |p: &Plane| Plane {
            width: window.width(),
            height: window.height(),
            data: (window.y0..window.y1)
                .flat_map(|y| {
                    let row = (y * p.width) as usize;
                    p.data[row + window.x0 as usize..row + window.x1 as usize].iter()
                })
                .copied()
                .collect(),
        };
        Ok(Planes {
            width: window.width(),
            height: window.height(),
            rgb: self.rgb.as_ref().map(|[r, g, b]| [cut(r), cut(g), cut(b)]),
            alpha: self.alpha.as_ref().map(cut),
            depth_z: self.depth_z.as_ref().map(cut),
            depth_ray: self.depth_ray.as_ref().map(cut),
            depth_median: self.depth_median.as_ref().map(cut),
        })
    }
}

/// The side of an image of `n` full-resolution pixels at render scale `s`: `max(1, ⌈n·s⌉)`.
///
/// One definition for every place that sizes an image at render scale (the camera, the graph
/// evaluator, the OpenFX host and plugin), so that they agree pixel for pixel. Never zero: a
/// node's image keeps at least one pixel at any scale (a scale the caller has not checked, 0 or
/// NaN, also gives 1 rather than an empty image).
pub fn scaled_size(n: u32, s: f64) -> u32 {
    ((f64::from(n) * s).ceil() as u32).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_size_is_the_ceiling_and_at_least_one() {
        assert_eq!(scaled_size(1920, 1.0), 1920);
        assert_eq!(scaled_size(1920, 0.25), 480);
        // Odd sizes round up: 1081/4 = 270.25, 7/2 = 3.5.
        assert_eq!(scaled_size(1081, 0.25), 271);
        assert_eq!(scaled_size(7, 0.5), 4);
        assert_eq!(scaled_size(3, 0.25), 1);
        assert_eq!(scaled_size(1, 0.001), 1);
        assert_eq!(scaled_size(0, 1.0), 1);
        assert_eq!(scaled_size(100, 0.0), 1);
        assert_eq!(scaled_size(100, f64::NAN), 1);
    }

    #[test]
    fn crop_takes_the_window_of_every_plane() {
        let numbered = |w: u32, h: u32, k: f32| Plane {
            width: w,
            height: h,
            data: (0..w * h).map(|i| i as f32 + k).collect(),
        };
        let planes = Planes {
            width: 5,
            height: 4,
            rgb: None,
            alpha: Some(numbered(5, 4, 0.0)),
            depth_z: Some(numbered(5, 4, 0.5)),
            depth_ray: None,
            depth_median: None,
        };
        let c = planes.crop(Window::new(1, 2, 4, 4)).unwrap();
        assert_eq!((c.width, c.height), (3, 2));
        // Pixel (x, y) of the 5-wide image is number 5y + x.
        assert_eq!(c.alpha.unwrap().data, [11.0, 12.0, 13.0, 16.0, 17.0, 18.0]);
        assert_eq!(c.depth_z.unwrap().data[0], 11.5);
        assert!(c.rgb.is_none());
        assert!(planes.crop(Window::new(0, 0, 6, 4)).is_err());
    }
}
