//! A over B, premultiplied.

use super::{rgba_pixels, rgba_planes, same_size, Rgba};
use crate::error::Result;
use crate::image::Planes;

/// The Porter–Duff *over* of one premultiplied pixel: `out = A + (1 − A_α)·B`, every channel
/// (alpha included).
pub(crate) fn over_pixel(a: Rgba, b: Rgba) -> Rgba {
    let t = 1.0 - a[3];
    [0, 1, 2, 3].map(|c| a[c] + t * b[c])
}

/// A over B per pixel: `out = A + (1 − A_α)·B`. Both premultiplied, of one size.
///
/// Worked example: a half-transparent red over blue, a transparent A, an opaque grey A.
/// ```
/// use nerfx_core::composite::{over, rgba_pixels, rgba_planes};
/// let a = rgba_planes(3, 1, &[[0.5, 0.0, 0.0, 0.5], [0.0; 4], [0.2, 0.2, 0.2, 1.0]]).unwrap();
/// let b = rgba_planes(3, 1, &[[0.0, 0.0, 1.0, 1.0], [0.1, 0.2, 0.3, 0.4], [1.0; 4]]).unwrap();
/// assert_eq!(
///     rgba_pixels(&over(&a, &b).unwrap()),
///     vec![[0.5, 0.0, 0.5, 1.0], [0.1, 0.2, 0.3, 0.4], [0.2, 0.2, 0.2, 1.0]]
/// );
/// ```
pub fn over(a: &Planes, b: &Planes) -> Result<Planes> {
    let (w, h) = same_size(
        "over",
        &[("A", a.width, a.height), ("B", b.width, b.height)],
    )?;
    let out: Vec<Rgba> = rgba_pixels(a)
        .into_iter()
        .zip(rgba_pixels(b))
        .map(|(a, b)| over_pixel(a, b))
        .collect();
    rgba_planes(w, h, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opaque_a_hides_b_and_alpha_adds_up() {
        assert_eq!(
            over_pixel([0.3, 0.2, 0.1, 1.0], [9.0, 9.0, 9.0, 1.0]),
            [0.3, 0.2, 0.1, 1.0]
        );
        assert_eq!(
            over_pixel([0.0, 0.0, 0.0, 0.25], [0.0, 0.0, 0.0, 0.5])[3],
            0.625
        );
    }
}
