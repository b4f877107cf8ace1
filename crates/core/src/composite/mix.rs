//! Blending a node's result with its input by the `mix` parameter.

use super::{check_range, rgba_pixels, rgba_planes, same_size, Rgba};
use crate::error::Result;
use crate::image::Planes;

/// `out = (1 − amount)·input + amount·result` per channel: `amount` 0 gives the input and 1
/// the result, exactly. `amount` must be in [0, 1].
///
/// Worked example, `amount = 0.25`:
/// ```
/// use nerfx_core::composite::{mix, rgba_pixels, rgba_planes};
/// let result = rgba_planes(3, 1, &[[1.0; 4], [0.0; 4], [0.5, 0.5, 0.5, 1.0]]).unwrap();
/// let input = rgba_planes(3, 1, &[[0.0; 4], [1.0; 4], [0.5, 0.5, 0.5, 1.0]]).unwrap();
/// assert_eq!(
///     rgba_pixels(&mix(&result, &input, 0.25).unwrap()),
///     vec![[0.25; 4], [0.75; 4], [0.5, 0.5, 0.5, 1.0]]
/// );
/// ```
pub fn mix(result: &Planes, input: &Planes, amount: f32) -> Result<Planes> {
    check_range("mix", "amount", amount, 0.0, 1.0)?;
    let (w, h) = same_size(
        "mix",
        &[
            ("result", result.width, result.height),
            ("input", input.width, input.height),
        ],
    )?;
    let out: Vec<Rgba> = rgba_pixels(result)
        .into_iter()
        .zip(rgba_pixels(input))
        .map(|(r, i)| [0, 1, 2, 3].map(|c| (1.0 - amount) * i[c] + amount * r[c]))
        .collect();
    rgba_planes(w, h, &out)
}
