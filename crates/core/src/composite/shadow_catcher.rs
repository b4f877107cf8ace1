//! The shadow-catcher merge: a foreground over a background darkened by Blender's
//! shadow-catcher pass.

use super::over::over_pixel;
use super::{check_range, finite, rgba_pixels, rgba_planes, same_size, Rgba};
use crate::error::Result;
use crate::image::{Plane, Planes};

/// A over (B darkened by the shadow). A shadow-catcher render holds the shadow's opacity
/// `s` in its alpha (its RGB is black); per colour channel
/// `B'_c = B_c·(1 − opacity·s·(1 − tint_c))`, `B'_α = B_α` (a shadow darkens what is there;
/// it adds no coverage), then `out = A + (1 − A_α)·B'`. `s` is clamped to [0, 1]; `opacity`
/// and each `tint_c` must be in [0, 1] (tint 1 is no darkening in that channel).
///
/// Worked example, opacity 1, tint (0.5, 0, 0): a full shadow on white keeps half the red;
/// a half shadow on grey; an opaque A hides the shadowed B.
/// ```
/// use nerfx_core::composite::{rgba_pixels, rgba_planes, shadow_catcher_merge};
/// use nerfx_core::image::Plane;
/// let a = rgba_planes(3, 1, &[[0.0; 4], [0.0; 4], [0.3, 0.2, 0.1, 1.0]]).unwrap();
/// let shadow = Plane { width: 3, height: 1, data: vec![1.0, 0.5, 1.0] };
/// let b = rgba_planes(3, 1, &[[1.0; 4], [0.5, 0.5, 0.5, 1.0], [1.0; 4]]).unwrap();
/// let out = shadow_catcher_merge(&a, &shadow, &b, 1.0, [0.5, 0.0, 0.0]).unwrap();
/// assert_eq!(
///     rgba_pixels(&out),
///     vec![[0.5, 0.0, 0.0, 1.0], [0.375, 0.25, 0.25, 1.0], [0.3, 0.2, 0.1, 1.0]]
/// );
/// ```
pub fn shadow_catcher_merge(
    a: &Planes,
    shadow_alpha: &Plane,
    b: &Planes,
    opacity: f32,
    tint: [f32; 3],
) -> Result<Planes> {
    let what = "shadow catcher merge";
    check_range(what, "opacity", opacity, 0.0, 1.0)?;
    for t in tint {
        check_range(what, "tint", t, 0.0, 1.0)?;
    }
    let (w, h) = same_size(
        what,
        &[
            ("A", a.width, a.height),
            ("Shadow", shadow_alpha.width, shadow_alpha.height),
            ("B", b.width, b.height),
        ],
    )?;
    let out: Vec<Rgba> = rgba_pixels(a)
        .into_iter()
        .zip(&shadow_alpha.data)
        .zip(rgba_pixels(b))
        .map(|((a, &s), b)| {
            let s = finite(s).clamp(0.0, 1.0);
            let dark = |c: usize| b[c] * (1.0 - opacity * s * (1.0 - tint[c]));
            over_pixel(a, [dark(0), dark(1), dark(2), b[3]])
        })
        .collect();
    rgba_planes(w, h, &out)
}
