//! The depth merge: two premultiplied images with camera-Z depths, nearest first.

use super::over::over_pixel;
use super::{check_range, depth, rgba_pixels, rgba_planes, same_size, Rgba};
use crate::error::Result;
use crate::image::{Plane, Planes};

/// How much of "A in front" to take where A is nearer than B by `d = z_B − z_A`:
/// a smoothstep `w = t²(3 − 2t)` with `t = clamp(d/softness + ½, 0, 1)`, so the blend spans
/// the depth band `|d| < softness/2`; with `softness = 0`, `w = 1` for `d ≥ 0`, else 0.
fn front_weight(d: f32, softness: f32) -> f32 {
    if softness > 0.0 {
        let t = (d / softness + 0.5).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    } else if d >= 0.0 {
        1.0
    } else {
        0.0
    }
}

/// Nearest first, per pixel: `out = w·(A over B) + (1 − w)·(B over A)` with `w` a smoothstep
/// of `d = z_B − z_A` over the band `|d| < softness/2` (`w = 1` when A is nearer by more
/// than `softness/2`; `softness = 0` is a hard cut, ties to A). Depths are camera Z in
/// Blender units; NaN, +inf and ≥ 10¹⁰ (Blender's background) mean nothing, infinitely far;
/// where both are nothing, `d = 0`. `softness` must be finite and ≥ 0.
///
/// Worked example, softness 0.2: A nearer; B nearer; equal depths (half of each order).
/// ```
/// use nerfx_core::composite::{depth_merge, rgba_pixels, rgba_planes};
/// use nerfx_core::image::Plane;
/// let px = [[0.5, 0.0, 0.0, 0.5], [0.5, 0.0, 0.0, 0.5], [0.5, 0.0, 0.0, 0.5]];
/// let a = rgba_planes(3, 1, &px).unwrap();
/// let b = rgba_planes(3, 1, &[[0.0, 0.0, 1.0, 1.0]; 3]).unwrap();
/// let za = Plane { width: 3, height: 1, data: vec![1.0, 3.0, 2.0] };
/// let zb = Plane { width: 3, height: 1, data: vec![2.0, 1.0, 2.0] };
/// let out = rgba_pixels(&depth_merge(&a, &za, &b, &zb, 0.2).unwrap());
/// // A over B = (0.5, 0, 0.5, 1); B over A = (0, 0, 1, 1): B is opaque.
/// assert_eq!(out, vec![[0.5, 0.0, 0.5, 1.0], [0.0, 0.0, 1.0, 1.0], [0.25, 0.0, 0.75, 1.0]]);
/// ```
pub fn depth_merge(
    a: &Planes,
    a_depth: &Plane,
    b: &Planes,
    b_depth: &Plane,
    softness: f32,
) -> Result<Planes> {
    let what = "depth merge";
    check_range(what, "softness", softness, 0.0, f32::MAX)?;
    let (w, h) = same_size(
        what,
        &[
            ("A", a.width, a.height),
            ("A depth", a_depth.width, a_depth.height),
            ("B", b.width, b.height),
            ("B depth", b_depth.width, b_depth.height),
        ],
    )?;
    let depths = a_depth.data.iter().zip(&b_depth.data);
    let out: Vec<Rgba> = rgba_pixels(a)
        .into_iter()
        .zip(rgba_pixels(b))
        .zip(depths)
        .map(|((a, b), (&za, &zb))| {
            let (za, zb) = (depth(za), depth(zb));
            let d = if za == zb { 0.0 } else { zb - za };
            let wa = front_weight(d, softness);
            let (ab, ba) = (over_pixel(a, b), over_pixel(b, a));
            [0, 1, 2, 3].map(|c| wa * ab[c] + (1.0 - wa) * ba[c])
        })
        .collect();
    rgba_planes(w, h, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights() {
        assert_eq!(front_weight(0.0, 0.0), 1.0);
        assert_eq!(front_weight(-1e-6, 0.0), 0.0);
        assert_eq!(front_weight(0.0, 1.0), 0.5);
        assert_eq!(front_weight(0.5, 1.0), 1.0);
        assert_eq!(front_weight(-0.5, 1.0), 0.0);
        // t = 0.75: 0.5625·1.5.
        assert!((front_weight(0.25, 1.0) - 0.84375).abs() < 1e-7);
        assert_eq!(front_weight(f32::INFINITY, 1.0), 1.0);
        assert_eq!(front_weight(f32::NEG_INFINITY, 1.0), 0.0);
    }
}
