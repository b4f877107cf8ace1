//! The accumulation matte: an RGB render and its accumulation render → premultiplied RGBA.
//!
//! `ns-render` (and nerfx's own accumulation output) gives an RGB render premultiplied by the
//! raw accumulation `m` and the accumulation itself. The matte curve turns `m` into the alpha
//! the artist wants (tighter edges, no floaters); the colour is re-premultiplied by the same
//! change, so the unpremultiplied colour is kept: `rgb_out = rgb · α/m` where `m > 0`.

use super::{check_range, finite, rgba_pixels, rgba_planes, same_size, Rgba};
use crate::error::{number, Error, Result};
use crate::image::{Plane, Planes};

/// The matte controls: black point, white point, gamma, floater clip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatteCurve {
    /// Accumulation mapped to alpha 0.
    pub black_point: f32,
    /// Accumulation mapped to alpha 1 (must be above the black point).
    pub white_point: f32,
    /// `α = t^(1/γ)`: above 1 raises mid alphas, below 1 lowers them (must be > 0).
    pub gamma: f32,
    /// Alphas below this become 0 (floaters: faint density in empty space), in [0, 1].
    pub floater_clip: f32,
}

impl Default for MatteCurve {
    /// The identity curve: black 0, white 1, gamma 1, no clip.
    fn default() -> Self {
        MatteCurve {
            black_point: 0.0,
            white_point: 1.0,
            gamma: 1.0,
            floater_clip: 0.0,
        }
    }
}

impl MatteCurve {
    /// Refuses non-finite values, `white ≤ black`, `gamma ≤ 0`, a clip outside [0, 1].
    pub fn validate(&self) -> Result<()> {
        let what = "accumulation matte";
        check_range(what, "black point", self.black_point, f32::MIN, f32::MAX)?;
        check_range(what, "white point", self.white_point, f32::MIN, f32::MAX)?;
        check_range(what, "floater clip", self.floater_clip, 0.0, 1.0)?;
        if self.white_point <= self.black_point {
            return Err(Error::invalid(
                what,
                format!(
                    "white point {} must be above black point {}",
                    self.white_point, self.black_point
                ),
            ));
        }
        if !(self.gamma.is_finite() && self.gamma > 0.0) {
            return Err(Error::invalid(
                what,
                format!("gamma must be > 0, got {}", number(self.gamma)),
            ));
        }
        Ok(())
    }

    /// Alpha for accumulation `m`: `t = clamp((m − black)/(white − black), 0, 1)`,
    /// `α = t^(1/γ)`, then `α < clip → 0`. A non-finite `m` reads as 0.
    pub fn alpha(&self, m: f32) -> f32 {
        let t = ((finite(m) - self.black_point) / (self.white_point - self.black_point))
            .clamp(0.0, 1.0);
        let a = t.powf(1.0 / self.gamma);
        if a < self.floater_clip {
            0.0
        } else {
            a
        }
    }
}

/// Source RGB (premultiplied by the raw accumulation) and the accumulation `matte` →
/// premultiplied RGBA: `α = curve(m)`; `rgb_out = rgb·α/m` where `m > 0`, else `rgb` as is.
/// The Source's own alpha is ignored.
///
/// Worked example, black 0, white 0.5, gamma 2, clip 0.1: `m = 0.125` gives `t = 0.25`,
/// `α = 0.5` and the colour ×4; `m = 0.8` saturates (`α = 1`, colour ÷0.8); `m = 0.001`
/// gives `α ≈ 0.045`, a floater, clipped to 0.
/// ```
/// use nerfx_core::composite::{accumulation_matte, rgba_pixels, rgba_planes, MatteCurve};
/// use nerfx_core::image::Plane;
/// let source = rgba_planes(3, 1, &[
///     [0.0625, 0.125, 0.0, 1.0], [0.4, 0.2, 0.8, 1.0], [0.001, 0.001, 0.001, 1.0],
/// ]).unwrap();
/// let matte = Plane { width: 3, height: 1, data: vec![0.125, 0.8, 0.001] };
/// let curve = MatteCurve { black_point: 0.0, white_point: 0.5, gamma: 2.0, floater_clip: 0.1 };
/// let out = rgba_pixels(&accumulation_matte(&source, &matte, &curve).unwrap());
/// let expected = [[0.25, 0.5, 0.0, 0.5], [0.5, 0.25, 1.0, 1.0], [0.0; 4]];
/// for (o, e) in out.iter().zip(&expected) {
///     assert!(o.iter().zip(e).all(|(o, e)| (o - e).abs() < 1e-6), "{o:?} vs {e:?}");
/// }
/// ```
pub fn accumulation_matte(source: &Planes, matte: &Plane, curve: &MatteCurve) -> Result<Planes> {
    curve.validate()?;
    let (w, h) = same_size(
        "accumulation matte",
        &[
            ("Source", source.width, source.height),
            ("Matte", matte.width, matte.height),
        ],
    )?;
    let out: Vec<Rgba> = rgba_pixels(source)
        .into_iter()
        .zip(&matte.data)
        .map(|(s, &m)| {
            let m = finite(m);
            let a = curve.alpha(m);
            let scale = if m > 0.0 { a / m } else { 1.0 };
            [s[0] * scale, s[1] * scale, s[2] * scale, a]
        })
        .collect();
    rgba_planes(w, h, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_values() {
        let c = MatteCurve {
            black_point: 0.2,
            white_point: 0.6,
            gamma: 0.5,
            floater_clip: 0.0,
        };
        // t = 0.5, α = 0.5² = 0.25.
        assert!((c.alpha(0.4) - 0.25).abs() < 1e-6);
        assert_eq!(c.alpha(0.1), 0.0);
        assert_eq!(c.alpha(0.9), 1.0);
        assert_eq!(c.alpha(f32::NAN), 0.0);
    }

    #[test]
    fn bad_curves_are_refused() {
        let base = MatteCurve::default();
        for bad in [
            MatteCurve {
                white_point: 0.0,
                ..base
            },
            MatteCurve { gamma: 0.0, ..base },
            MatteCurve {
                floater_clip: 1.5,
                ..base
            },
            MatteCurve {
                black_point: f32::NAN,
                ..base
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }
}
