//! OpenFX image buffers ⇄ the core's [`Planes`], pure and host-free.
//!
//! An OpenFX image is interleaved float pixels (`channels` per pixel: 4 for RGBA, 3 for RGB,
//! 1 for Alpha) whose rows are `row_bytes` apart, **possibly negative**; the data pointer is the
//! bottom-left pixel of `bounds` (`kOfxImagePropBounds`), so pixel `(x, y)` starts at
//! `data + (y − y1)·row_bytes + (x − x1)·channels·4`. A [`PixelView`] checks that layout
//! once; [`read_planes`] and [`write_planes`] then move pixels through a [`Frame`].

use std::ffi::c_void;

use nerfx_core::image::{Plane, Planes, Window};

use crate::coords::{Frame, PixelRect};

/// A checked view of an interleaved float image.
pub struct PixelView {
    data: *mut u8,
    bounds: PixelRect,
    row_bytes: isize,
    channels: usize,
}

impl PixelView {
    /// A view of `data`, or why its layout is unusable.
    ///
    /// # Safety
    /// For every pixel `(x, y)` of `bounds`, the `channels` floats at
    /// `data + (y − y1)·row_bytes + (x − x1)·channels·4` must be valid (and writable if the
    /// view is written to) for as long as the view is used.
    pub unsafe fn new(
        data: *mut c_void,
        bounds: PixelRect,
        row_bytes: i32,
        channels: usize,
    ) -> Result<Self, String> {
        let width = i64::from(bounds.x2) - i64::from(bounds.x1);
        let height = i64::from(bounds.y2) - i64::from(bounds.y1);
        let row = width * channels as i64 * 4;
        if width > 0 && height > 0 {
            if data.is_null() {
                return Err("the image has no data".into());
            }
            if row_bytes % 4 != 0 || i64::from(row_bytes).abs() < row {
                return Err(format!(
                    "row bytes {row_bytes} do not fit {width} float pixels of {channels} \
                     channels"
                ));
            }
        }
        Ok(PixelView {
            data: data.cast(),
            bounds,
            row_bytes: row_bytes as isize,
            channels,
        })
    }

    /// Floats per pixel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The pixel rectangle the data covers.
    pub fn bounds(&self) -> PixelRect {
        self.bounds
    }

    fn at(&self, x: i32, y: i32) -> Option<*mut f32> {
        if !self.bounds.contains(x, y) {
            return None;
        }
        let row = (y - self.bounds.y1) as isize * self.row_bytes;
        let col = (x - self.bounds.x1) as isize * (self.channels * 4) as isize;
        // SAFETY: (x, y) is inside the bounds, so the offset stays in the buffer (`new`).
        Some(unsafe { self.data.offset(row + col) }.cast())
    }

    /// The pixel at `(x, y)`, if inside the bounds.
    pub fn get(&self, x: i32, y: i32) -> Option<&[f32]> {
        // SAFETY: `at` points at `channels` valid floats (`new`); float buffers from a host
        // are 4-byte aligned, which `row_bytes % 4 == 0` keeps from row to row.
        self.at(x, y)
            .map(|p| unsafe { std::slice::from_raw_parts(p, self.channels) })
    }

    /// The pixel at `(x, y)` for writing, if inside the bounds.
    pub fn get_mut(&mut self, x: i32, y: i32) -> Option<&mut [f32]> {
        // SAFETY: as in `get`; `&mut self` keeps the slice unique within this view.
        self.at(x, y)
            .map(|p| unsafe { std::slice::from_raw_parts_mut(p, self.channels) })
    }
}

/// Which rows of the output a render writes. A host rendering fielded footage one field at a
/// time asks for the lower field (rows 0, 2, 4… counted from `y` = 0, `y` up) or the upper
/// one (rows 1, 3, 5…) of a full-frame image: the other field's rows are not ours to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rows {
    /// Every row (unfielded, both fields, or an image holding a single field).
    All,
    /// Rows with even `y` (`kOfxImageFieldLower`).
    Even,
    /// Rows with odd `y` (`kOfxImageFieldUpper`).
    Odd,
}

impl Rows {
    /// Whether row `y` is written.
    pub fn has(self, y: i32) -> bool {
        match self {
            Rows::All => true,
            Rows::Even => y.rem_euclid(2) == 0,
            Rows::Odd => y.rem_euclid(2) == 1,
        }
    }
}

/// The pixels of `view` under raster `window` of `frame` as planes of the window's size: RGB
/// and alpha from a 4-channel image, RGB and opaque alpha from a 3-channel one (a host that
/// ignores the declared components), alpha alone from a 1-channel one; pixels outside the
/// image's bounds are transparent black.
///
/// The core composites premultiplied colour: a 4-channel image whose colour is `straight`
/// (`kOfxImageUnPreMultiplied`) is premultiplied here, `(r·a, g·a, b·a, a)`; premultiplied and
/// opaque images are read as they are.
pub fn read_planes(view: &PixelView, frame: Frame, window: Window, straight: bool) -> Planes {
    let (w, h) = (window.width(), window.height());
    let mut planes = [(); 4].map(|_| Plane::filled(w, h, 0.0));
    let n = view.channels();
    let rgba = n >= 3;
    for ry in window.y0..window.y1 {
        for rx in window.x0..window.x1 {
            let (x, y) = frame.pixel(rx, ry);
            let Some(px) = view.get(x, y) else { continue };
            let i = (ry - window.y0) as usize * w as usize + (rx - window.x0) as usize;
            if rgba {
                for (plane, v) in planes.iter_mut().zip(px) {
                    plane.data[i] = *v;
                }
                if n == 3 {
                    planes[3].data[i] = 1.0;
                } else if straight {
                    let a = px[3];
                    for plane in &mut planes[..3] {
                        plane.data[i] *= a;
                    }
                }
            } else {
                planes[3].data[i] = px[0];
            }
        }
    }
    let [r, g, b, a] = planes;
    Planes {
        width: w,
        height: h,
        rgb: rgba.then_some([r, g, b]),
        alpha: Some(a),
        depth_z: None,
        depth_ray: None,
        depth_median: None,
    }
}

/// Writes `planes` (the core's output for raster `window` of `frame`) into a 4-channel
/// `view`, touching only pixels inside `render` (the host's render window), the view's bounds
/// and the `rows` of the field being rendered; render-window pixels the window does not cover
/// become transparent black. Missing RGB is black; missing alpha is opaque when RGB is present.
pub fn write_planes(
    view: &mut PixelView,
    frame: Frame,
    window: Window,
    render: PixelRect,
    rows: Rows,
    planes: &Planes,
) -> Result<(), String> {
    if view.channels() != 4 {
        return Err(format!(
            "the output image has {} channels, expected RGBA",
            view.channels()
        ));
    }
    if (planes.width, planes.height) != (window.width(), window.height()) {
        return Err(format!(
            "the render produced {}×{} pixels for a {}×{} window",
            planes.width,
            planes.height,
            window.width(),
            window.height()
        ));
    }
    let b = view.bounds();
    let opaque = if planes.rgb.is_some() { 1.0 } else { 0.0 };
    let top = i64::from(frame.y0) + i64::from(frame.height);
    for y in (render.y1.max(b.y1)..render.y2.min(b.y2)).filter(|&y| rows.has(y)) {
        for x in render.x1.max(b.x1)..render.x2.min(b.x2) {
            let rx = i64::from(x) - i64::from(frame.x0);
            let ry = top - 1 - i64::from(y);
            let inside = rx >= i64::from(window.x0)
                && rx < i64::from(window.x1)
                && ry >= i64::from(window.y0)
                && ry < i64::from(window.y1);
            let value = if inside {
                let i = (ry - i64::from(window.y0)) as usize * planes.width as usize
                    + (rx - i64::from(window.x0)) as usize;
                let rgb = planes
                    .rgb
                    .as_ref()
                    .map_or([0.0; 3], |p| [p[0].data[i], p[1].data[i], p[2].data[i]]);
                let a = planes.alpha.as_ref().map_or(opaque, |p| p.data[i]);
                [rgb[0], rgb[1], rgb[2], a]
            } else {
                [0.0; 4]
            };
            if let Some(px) = view.get_mut(x, y) {
                px.copy_from_slice(&value);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A distinct value for channel `c` of pixel `(x, y)`.
    fn f(x: i32, y: i32, c: usize) -> f32 {
        (x * 100 + y * 10) as f32 + c as f32 * 0.25
    }

    /// A host-like buffer: `bounds`, `pad` spare floats per row, rows stored top-down when
    /// `flipped` (negative row bytes, the data pointer at the last stored row).
    struct Buffer {
        store: Vec<f32>,
        bounds: PixelRect,
        stride: usize,
        channels: usize,
        flipped: bool,
    }

    impl Buffer {
        fn new(bounds: PixelRect, channels: usize, pad: usize, flipped: bool) -> Self {
            let w = (bounds.x2 - bounds.x1) as usize;
            let h = (bounds.y2 - bounds.y1) as usize;
            let stride = w * channels + pad;
            let mut b = Buffer {
                store: vec![-7.0; stride * h],
                bounds,
                stride,
                channels,
                flipped,
            };
            for y in bounds.y1..bounds.y2 {
                for x in bounds.x1..bounds.x2 {
                    for c in 0..channels {
                        let i = b.index(x, y, c);
                        b.store[i] = f(x, y, c);
                    }
                }
            }
            b
        }

        /// Where channel `c` of pixel `(x, y)` is stored, computed without `PixelView`.
        fn index(&self, x: i32, y: i32, c: usize) -> usize {
            let h = (self.bounds.y2 - self.bounds.y1) as usize;
            let row = (y - self.bounds.y1) as usize;
            let row = if self.flipped { h - 1 - row } else { row };
            row * self.stride + (x - self.bounds.x1) as usize * self.channels + c
        }

        fn view(&mut self) -> PixelView {
            let h = (self.bounds.y2 - self.bounds.y1) as usize;
            let bytes = (self.stride * 4) as i32;
            let (data, row_bytes) = if self.flipped {
                (self.store[(h - 1) * self.stride..].as_mut_ptr(), -bytes)
            } else {
                (self.store.as_mut_ptr(), bytes)
            };
            unsafe { PixelView::new(data.cast(), self.bounds, row_bytes, self.channels) }.unwrap()
        }
    }

    #[test]
    fn reads_odd_sized_images_with_either_row_order() {
        for flipped in [false, true] {
            // A 5×3 image at (−2, 4) with one spare float per row, the frame a 9×11 image.
            let mut buf = Buffer::new(PixelRect::from_ints([-2, 4, 3, 7]), 4, 1, flipped);
            let view = buf.view();
            let frame = Frame {
                x0: -4,
                y0: 0,
                width: 9,
                height: 11,
            };
            // Raster window columns 1..8 → x −3..4; rows 3..6 → y 7..5 (y = 10 − ry).
            let window = Window::new(1, 3, 8, 6);
            let p = read_planes(&view, frame, window, false);
            assert_eq!((p.width, p.height), (7, 3));
            let rgb = p.rgb.as_ref().unwrap();
            let alpha = p.alpha.as_ref().unwrap();
            for ry in 0..3u32 {
                for rx in 0..7u32 {
                    let x = -4 + 1 + rx as i32;
                    let y = 10 - (3 + ry as i32);
                    let inside = (-2..3).contains(&x) && (4..7).contains(&y);
                    let want = |c| if inside { f(x, y, c) } else { 0.0 };
                    assert_eq!(rgb[0].get(rx, ry), want(0), "flipped {flipped} ({x},{y})");
                    assert_eq!(rgb[2].get(rx, ry), want(2));
                    assert_eq!(alpha.get(rx, ry), want(3));
                }
            }
        }
    }

    #[test]
    fn an_alpha_image_gives_only_alpha() {
        let mut buf = Buffer::new(PixelRect::from_ints([0, 0, 3, 2]), 1, 0, true);
        let frame = Frame::of_rod(3, 2, 1.0);
        let p = read_planes(&buf.view(), frame, Window::new(0, 0, 3, 2), false);
        assert!(p.rgb.is_none());
        // Raster row 0 is the top row, y = 1.
        assert_eq!(p.alpha.as_ref().unwrap().get(2, 0), f(2, 1, 0));
        assert_eq!(p.alpha.as_ref().unwrap().get(0, 1), f(0, 0, 0));
    }

    #[test]
    fn writes_only_inside_the_render_window() {
        for flipped in [false, true] {
            // Output buffer 7×5 at the origin; the frame a 7×5 image; render window
            // x∈[1,6), y∈[1,4); the core covered raster columns 2..6, rows 1..3.
            let bounds = PixelRect::from_ints([0, 0, 7, 5]);
            let mut buf = Buffer::new(bounds, 4, 3, flipped);
            let frame = Frame::of_rod(7, 5, 1.0);
            let render = PixelRect::from_ints([1, 1, 6, 4]);
            let window = Window::new(2, 1, 6, 3);
            let planes = Planes {
                width: 4,
                height: 2,
                rgb: Some([0.0, 1.0, 2.0].map(|c| Plane {
                    width: 4,
                    height: 2,
                    data: (0..8).map(|i| i as f32 + c * 10.0).collect(),
                })),
                alpha: None,
                depth_z: None,
                depth_ray: None,
                depth_median: None,
            };
            let mut view = buf.view();
            write_planes(&mut view, frame, window, render, Rows::All, &planes).unwrap();
            for y in 0..5 {
                for x in 0..7 {
                    let got: Vec<f32> = (0..4).map(|c| buf.store[buf.index(x, y, c)]).collect();
                    let (rx, ry) = (x - 2, 4 - y - 1);
                    let want: Vec<f32> = if !render.contains(x, y) {
                        (0..4).map(|c| f(x, y, c)).collect()
                    } else if (0..4).contains(&rx) && (0..2).contains(&ry) {
                        let i = (ry * 4 + rx) as f32;
                        vec![i, i + 10.0, i + 20.0, 1.0]
                    } else {
                        vec![0.0; 4]
                    };
                    assert_eq!(got, want, "flipped {flipped} pixel ({x},{y})");
                }
            }
            // Padding floats are never touched.
            assert_eq!(buf.store[28..31], [-7.0; 3]);
        }
    }

    #[test]
    fn refuses_bad_layouts_and_sizes() {
        let bounds = PixelRect::from_ints([0, 0, 4, 1]);
        let mut store = vec![0.0f32; 16];
        let data = store.as_mut_ptr().cast();
        assert!(unsafe { PixelView::new(data, bounds, 60, 4) }.is_err());
        assert!(unsafe { PixelView::new(data, bounds, 62, 4) }.is_err());
        assert!(unsafe { PixelView::new(std::ptr::null_mut(), bounds, 64, 4) }.is_err());
        let mut one = unsafe { PixelView::new(data, bounds, 16, 1) }.unwrap();
        let planes = read_planes(
            &one,
            Frame::of_rod(4, 1, 1.0),
            Window::new(0, 0, 4, 1),
            false,
        );
        let e = write_planes(
            &mut one,
            Frame::of_rod(4, 1, 1.0),
            Window::new(0, 0, 4, 1),
            bounds,
            Rows::All,
            &planes,
        );
        assert!(e.unwrap_err().contains("RGBA"));
        let mut four = unsafe { PixelView::new(data, bounds, 64, 4) }.unwrap();
        let e = write_planes(
            &mut four,
            Frame::of_rod(4, 1, 1.0),
            Window::new(0, 0, 2, 1),
            bounds,
            Rows::All,
            &planes,
        );
        assert!(e.unwrap_err().contains("4×1 pixels for a 2×1 window"));
    }

    #[test]
    fn straight_colour_is_premultiplied_and_only_rgba_images_change() {
        let window = Window::new(0, 0, 3, 2);
        let frame = Frame::of_rod(3, 2, 1.0);
        let mut rgba = Buffer::new(PixelRect::from_ints([0, 0, 3, 2]), 4, 1, false);
        let premultiplied = read_planes(&rgba.view(), frame, window, false);
        let straight = read_planes(&rgba.view(), frame, window, true);
        for (rx, ry) in [(0, 0), (2, 0), (1, 1)] {
            // Raster row 0 is y = 1.
            let (x, y) = (rx as i32, 1 - ry as i32);
            let a = f(x, y, 3);
            for c in 0..3 {
                assert_eq!(
                    premultiplied.rgb.as_ref().unwrap()[c].get(rx, ry),
                    f(x, y, c)
                );
                assert_eq!(
                    straight.rgb.as_ref().unwrap()[c].get(rx, ry),
                    f(x, y, c) * a
                );
            }
            assert_eq!(straight.alpha.as_ref().unwrap().get(rx, ry), a);
        }
        // RGB images are opaque and alpha images have no colour: nothing to premultiply.
        let mut rgb = Buffer::new(PixelRect::from_ints([0, 0, 3, 2]), 3, 0, false);
        assert_eq!(
            read_planes(&rgb.view(), frame, window, true),
            read_planes(&rgb.view(), frame, window, false)
        );
        let mut alpha = Buffer::new(PixelRect::from_ints([0, 0, 3, 2]), 1, 0, false);
        assert_eq!(
            read_planes(&alpha.view(), frame, window, true),
            read_planes(&alpha.view(), frame, window, false)
        );
    }

    #[test]
    fn an_rgb_image_reads_as_opaque_rgba() {
        let mut buf = Buffer::new(PixelRect::from_ints([0, 0, 2, 2]), 3, 2, false);
        // The frame reaches one column past the image: that column stays transparent.
        let frame = Frame::of_rod(3, 2, 1.0);
        let p = read_planes(&buf.view(), frame, Window::new(0, 0, 3, 2), false);
        let rgb = p.rgb.as_ref().unwrap();
        let alpha = p.alpha.as_ref().unwrap();
        // Raster (1, 0) is pixel (1, 1).
        assert_eq!(rgb[1].get(1, 0), f(1, 1, 1));
        assert_eq!(rgb[2].get(0, 1), f(0, 0, 2));
        assert_eq!((alpha.get(1, 0), alpha.get(0, 1)), (1.0, 1.0));
        assert_eq!((alpha.get(2, 0), rgb[0].get(2, 0)), (0.0, 0.0));
    }

    #[test]
    fn a_field_render_writes_only_its_rows() {
        // Output 3×6 at y = −1..5; lower field = even y, upper = odd y (negative y too).
        for (rows, parity) in [(Rows::Even, 0), (Rows::Odd, 1)] {
            let bounds = PixelRect::from_ints([0, -1, 3, 5]);
            let mut buf = Buffer::new(bounds, 4, 0, false);
            let frame = Frame::of_window(bounds);
            let window = Window::new(0, 0, 3, 6);
            let one = Plane::filled(3, 6, 0.5);
            let planes = Planes {
                width: 3,
                height: 6,
                rgb: Some([one.clone(), one.clone(), one.clone()]),
                alpha: Some(one),
                depth_z: None,
                depth_ray: None,
                depth_median: None,
            };
            let mut view = buf.view();
            write_planes(&mut view, frame, window, bounds, rows, &planes).unwrap();
            for y in -1..5 {
                for x in 0..3 {
                    let got = buf.store[buf.index(x, y, 3)];
                    let mine = (y % 2 + 2) % 2 == parity;
                    let want = if mine { 0.5 } else { f(x, y, 3) };
                    assert_eq!(got, want, "{rows:?} ({x},{y})");
                }
            }
        }
        assert!(Rows::All.has(-3) && Rows::All.has(4));
    }
}
