//! OpenFX pixel coordinates ⇄ the core's raster windows.
//!
//! OpenFX pixel coordinates have `y` up, origin at the bottom-left, and rectangles
//! `(x1, y1, x2, y2)` with `x2`, `y2` exclusive; canonical coordinates are pixels divided by
//! the render scale, with `x` also times the pixel aspect ratio `par`:
//! `canonical = (px·par/sx, py/sy)`. The core's [`Window`] is raster (top-left origin, `y`
//! down) inside an image of a known size. A [`Frame`] says where that raster image lies in
//! pixel coordinates; raster `(rx, ry)` is pixel `(x0 + rx, y0 + height − 1 − ry)`, so a pixel
//! rectangle maps to the raster window `[x1 − x0, x2 − x0) × [top − y2, top − y1)` with
//! `top = y0 + height`.

use nerfx_core::image::{scaled_size, Window};

/// A rectangle in OpenFX pixel coordinates (`kOfxImagePropBounds`, render windows).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelRect {
    /// Left (inclusive).
    pub x1: i32,
    /// Bottom (inclusive).
    pub y1: i32,
    /// Right (exclusive).
    pub x2: i32,
    /// Top (exclusive).
    pub y2: i32,
}

impl PixelRect {
    /// From the four ints of an OpenFX rectangle property.
    pub fn from_ints(v: [i32; 4]) -> Self {
        PixelRect {
            x1: v[0],
            y1: v[1],
            x2: v[2],
            y2: v[3],
        }
    }

    /// Whether pixel `(x, y)` lies inside.
    pub fn contains(&self, x: i32, y: i32) -> bool {
        self.x1 <= x && x < self.x2 && self.y1 <= y && y < self.y2
    }

    /// The rectangle in canonical coordinates for render scale `(sx, sy)` and pixel aspect
    /// ratio `par` (what `clipGetImage` takes).
    pub fn canonical(&self, scale: [f64; 2], par: f64) -> [f64; 4] {
        [
            f64::from(self.x1) * par / scale[0],
            f64::from(self.y1) / scale[1],
            f64::from(self.x2) * par / scale[0],
            f64::from(self.y2) / scale[1],
        ]
    }
}

/// Where the core's raster image lies in pixel coordinates: its bottom-left pixel and size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Pixel `x` of raster column 0.
    pub x0: i32,
    /// Pixel `y` of the raster image's bottom row.
    pub y0: i32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl Frame {
    /// The image of a node with its own region of definition: `ceil(w·s) × ceil(h·s)` pixels
    /// (at least one) from the origin, as the core sizes an image at render scale `s`.
    pub fn of_rod(width: u32, height: u32, scale: f64) -> Self {
        Frame {
            x0: 0,
            y0: 0,
            width: scaled_size(width, scale),
            height: scaled_size(height, scale),
        }
    }

    /// The render window itself as the image (nodes whose region of definition is their
    /// inputs': they work pixel by pixel, so only the window's size matters to them).
    pub fn of_window(rect: PixelRect) -> Self {
        Frame {
            x0: rect.x1,
            y0: rect.y1,
            width: (i64::from(rect.x2) - i64::from(rect.x1)).clamp(0, u32::MAX.into()) as u32,
            height: (i64::from(rect.y2) - i64::from(rect.y1)).clamp(0, u32::MAX.into()) as u32,
        }
    }

    /// The part of `rect` inside the frame, as a raster window (empty when they miss).
    pub fn raster(&self, rect: PixelRect) -> Window {
        let clamp = |v: i32, lo: i32, n: u32| (i64::from(v) - i64::from(lo)).clamp(0, n.into());
        let x0 = clamp(rect.x1, self.x0, self.width);
        let x1 = clamp(rect.x2, self.x0, self.width);
        let bottom = clamp(rect.y1, self.y0, self.height);
        let top = clamp(rect.y2, self.y0, self.height);
        let h = i64::from(self.height);
        Window::new(x0 as u32, (h - top) as u32, x1 as u32, (h - bottom) as u32)
    }

    /// The pixel coordinates of raster pixel `(rx, ry)`.
    pub fn pixel(&self, rx: u32, ry: u32) -> (i32, i32) {
        let x = i64::from(self.x0) + i64::from(rx);
        let y = i64::from(self.y0) + i64::from(self.height) - 1 - i64::from(ry);
        (x as i32, y as i32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raster_flips_y_about_the_image_height() {
        // A 10×6 image; the pixel rectangle x∈[2,5), y∈[1,3) (y up) covers raster rows
        // 6−3 = 3 to 6−1 = 5 (exclusive).
        let f = Frame::of_rod(10, 6, 1.0);
        let w = f.raster(PixelRect::from_ints([2, 1, 5, 3]));
        assert_eq!(w, Window::new(2, 3, 5, 5));
        // The bottom-left pixel is the last raster row, the top-right the first.
        assert_eq!(f.pixel(0, 5), (0, 0));
        assert_eq!(f.pixel(9, 0), (9, 5));
        // Every raster pixel of the window maps back inside the rectangle.
        let r = PixelRect::from_ints([2, 1, 5, 3]);
        for ry in w.y0..w.y1 {
            for rx in w.x0..w.x1 {
                let (x, y) = f.pixel(rx, ry);
                assert!(r.contains(x, y), "({rx},{ry}) -> ({x},{y})");
            }
        }
    }

    #[test]
    fn windows_are_clipped_to_the_image() {
        let f = Frame::of_rod(4, 4, 1.0);
        assert_eq!(
            f.raster(PixelRect::from_ints([-3, -2, 9, 7])),
            Window::new(0, 0, 4, 4)
        );
        assert_eq!(f.raster(PixelRect::from_ints([5, 0, 9, 4])).area(), 0);
        assert_eq!(f.raster(PixelRect::from_ints([0, -5, 4, -1])).area(), 0);
    }

    #[test]
    fn render_scale_rounds_sides_up() {
        // 1001 × 0.5 = 500.5 → 501; 7 × 0.25 = 1.75 → 2; a tiny scale keeps one pixel.
        let f = Frame::of_rod(1001, 7, 0.5);
        assert_eq!((f.width, f.height), (501, 4));
        assert_eq!(Frame::of_rod(7, 7, 0.25).width, 2);
        assert_eq!(Frame::of_rod(3, 3, 1e-9).width, 1);
        // At half scale the top half of the 501×4 image is raster rows 0 and 1.
        assert_eq!(
            f.raster(PixelRect::from_ints([0, 2, 501, 4])),
            Window::new(0, 0, 501, 2)
        );
    }

    #[test]
    fn a_window_frame_is_the_window_at_the_origin() {
        let r = PixelRect::from_ints([-7, 10, 3, 14]);
        let f = Frame::of_window(r);
        assert_eq!(f.raster(r), Window::new(0, 0, 10, 4));
        assert_eq!(f.pixel(0, 0), (-7, 13));
        assert_eq!(f.pixel(9, 3), (2, 10));
    }

    #[test]
    fn canonical_divides_by_scale_and_stretches_by_par() {
        let r = PixelRect::from_ints([10, 20, 30, 40]);
        assert_eq!(r.canonical([0.5, 0.5], 2.0), [40.0, 40.0, 120.0, 80.0]);
        assert_eq!(r.canonical([1.0, 1.0], 1.0), [10.0, 20.0, 30.0, 40.0]);
    }
}
