//! RGBA images for the tests that compare the plugin's pixels with the core's: built from a
//! function, assembled from odd-sized tiles, compared bit for bit.
//!
//! The host carries RGBA only, so images here have colour and alpha planes and no depth.

use nerfx_core::image::{Plane, Planes, Window};
use nerfx_ofx_host::Instance;

/// A `w × h` RGBA image whose channel `c` (0–2 colour, 3 alpha) at raster pixel `(x, y)` is
/// `f(x, y, c)`.
pub fn rgba(w: u32, h: u32, f: impl Fn(u32, u32, usize) -> f32) -> Planes {
    let plane = |c: usize| Plane {
        width: w,
        height: h,
        data: (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y, c))
            .collect(),
    };
    Planes {
        width: w,
        height: h,
        rgb: Some([plane(0), plane(1), plane(2)]),
        alpha: Some(plane(3)),
        depth_z: None,
        depth_ray: None,
        depth_median: None,
    }
}

/// The RGBA part of `p`: what crosses the OpenFX boundary.
pub fn rgba_of(p: &Planes) -> Planes {
    Planes {
        depth_z: None,
        depth_ray: None,
        depth_median: None,
        ..p.clone()
    }
}

/// Channel `c` (0–2 colour, 3 alpha) of raster pixel `(x, y)`.
pub fn at(p: &Planes, x: u32, y: u32, c: usize) -> f32 {
    if c == 3 {
        p.alpha.as_ref().unwrap().get(x, y)
    } else {
        p.rgb.as_ref().unwrap()[c].get(x, y)
    }
}

/// Odd-sized tiles (7×5, smaller at the right and top edges) covering `w × h`: sizes no
/// renderer rounds to, so that an offset or stride error shows.
pub fn tiles(w: u32, h: u32) -> Vec<Window> {
    let mut out = Vec::new();
    for y in (0..h).step_by(5) {
        for x in (0..w).step_by(7) {
            out.push(Window::new(x, y, (x + 7).min(w), (y + 5).min(h)));
        }
    }
    out
}

/// `tile` (an RGBA image the size of `at`) pasted into `into` at `at`.
pub fn paste(into: &mut Planes, tile: &Planes, at: Window) {
    let copy = |dst: &mut Plane, src: &Plane| {
        for y in 0..at.height() {
            for x in 0..at.width() {
                let d = ((at.y0 + y) * dst.width + at.x0 + x) as usize;
                dst.data[d] = src.data[(y * src.width + x) as usize];
            }
        }
    };
    for c in 0..3 {
        copy(
            &mut into.rgb.as_mut().unwrap()[c],
            &tile.rgb.as_ref().unwrap()[c],
        );
    }
    copy(into.alpha.as_mut().unwrap(), tile.alpha.as_ref().unwrap());
}

/// Every one of [`tiles`]`(w, h)` rendered by `render` (which must return an image the
/// tile's size) and pasted into one `w × h` image; pixels no tile covers stay NaN.
pub fn tiled(w: u32, h: u32, render: impl Fn(Window) -> Planes) -> Planes {
    let mut image = rgba(w, h, |_, _, _| f32::NAN);
    for tile in tiles(w, h) {
        let got = render(tile);
        assert_eq!(
            (got.width, got.height),
            (tile.width(), tile.height()),
            "tile {tile:?}"
        );
        paste(&mut image, &got, tile);
    }
    image
}

/// The `w × h` image at `time` and render `scale`, rendered through `instance` tile by tile.
pub fn render_tiled(instance: &Instance, time: f64, w: u32, h: u32, scale: f64) -> Planes {
    tiled(w, h, |tile| {
        instance
            .render(time, tile, scale, false)
            .unwrap_or_else(|e| panic!("tile {tile:?} at scale {scale}: {e}"))
    })
}

/// For each channel (R, G, B, A), how many samples of `got` and `want` differ bit for bit.
fn differing_channels(got: &Planes, want: &Planes) -> [usize; 4] {
    let planes = |p: &Planes| {
        let [r, g, b] = p.rgb.clone().unwrap();
        [r, g, b, p.alpha.clone().unwrap()]
    };
    let (got, want) = (planes(got), planes(want));
    std::array::from_fn(|c| {
        assert_eq!(got[c].data.len(), want[c].data.len(), "channel {c}");
        got[c]
            .data
            .iter()
            .zip(&want[c].data)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count()
    })
}

/// How many samples of the RGBA planes of `got` and `want` differ bit for bit.
pub fn differing(got: &Planes, want: &Planes) -> usize {
    differing_channels(got, want).iter().sum()
}

/// Asserts that `got` and `want` have the same size and the same RGBA samples bit for bit;
/// `what` names the case in the failure.
pub fn assert_same(got: &Planes, want: &Planes, what: &str) {
    assert_eq!((got.width, got.height), (want.width, want.height), "{what}");
    for (c, differ) in differing_channels(got, want).into_iter().enumerate() {
        assert_eq!(differ, 0, "{what}: {differ} samples of channel {c} differ");
    }
}

/// A deterministic premultiplied image over `window`, different per clip (`seed`) and per
/// render `scale` (a stand-in for an upstream node that honours the render scale).
pub fn pattern(seed: u32, window: Window, scale: f64) -> Planes {
    let s = (scale * 8.0) as u32;
    rgba(window.width(), window.height(), |x, y, c| {
        let (x, y) = (x + window.x0, y + window.y0);
        let h = (x.wrapping_mul(73_856_093)
            ^ y.wrapping_mul(19_349_663)
            ^ (seed + s + c as u32).wrapping_mul(83_492_791))
            % 1000;
        let v = h as f32 / 1000.0;
        if c == 3 {
            v
        } else {
            v * (0.2 + 0.8 * v) + seed as f32 * 0.5
        }
    })
}
