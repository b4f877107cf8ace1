//! Planar f32 images and the windows they cover.

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
