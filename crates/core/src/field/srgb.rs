//! The sRGB transfer curve: encoded values to linear light (fast, tabulated: every
//! composited pixel of a field trained on photographs goes through it) and back.
//!
//! `powf` costs more than the rest of a colour sample's epilogue, so the curve is tabulated
//! once (f64, 4096 intervals over [0, 1]) and interpolated linearly: the interpolation error
//! is at most h²/8·max|f''| ≈ 2e-8 absolute (the curve's second derivative stays below 3),
//! about 1e-5 relative just above the linear toe (evaluated exactly) and 1e-6 above 0.1. The
//! standard's two pieces themselves disagree by ~1e-5 relative where they meet.

use std::sync::OnceLock;

/// Intervals of the table over [0, 1].
const N: usize = 4096;

/// The exact curve (IEC 61966-2-1).
fn exact(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn table() -> &'static [f32; N + 1] {
    static TABLE: OnceLock<[f32; N + 1]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| exact(i as f64 / N as f64) as f32))
}

/// sRGB-encoded `c` in [0, 1] (a sigmoid's output) to linear; values outside are clamped.
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        return c.max(0.0) / 12.92;
    }
    let t = c.min(1.0) * N as f32;
    let i = (t as usize).min(N - 1);
    let f = t - i as f32;
    let lut = table();
    lut[i] + f * (lut[i + 1] - lut[i])
}

/// Linear `c` to sRGB-encoded (exact; negative values give 0, values above 1 follow the
/// curve's power segment). Rarely hot: it brings linear fields into a composite with fields
/// trained on photographs.
#[inline]
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c.max(0.0) * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_curve_within_3e_5_relative() {
        let mut worst = 0.0f64;
        for k in 0..=200_000 {
            let c = k as f64 / 200_000.0;
            let want = if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            };
            let got = f64::from(srgb_to_linear(c as f32));
            if want > 0.0 {
                worst = worst.max((got - want).abs() / want);
            }
        }
        // 3e-5: an f32 input rounded across the toe's end meets the standard's own ~1e-5
        // mismatch of its two pieces; the trained-field checks allow 1e-4.
        assert!(worst < 3e-5, "worst relative error {worst:e}");
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert_eq!(srgb_to_linear(1.0), 1.0);
        assert_eq!(srgb_to_linear(-0.5), 0.0);
        assert_eq!(srgb_to_linear(2.0), 1.0);
    }

    #[test]
    fn encoding_inverts_decoding() {
        // Known points of the standard: 0.18 linear encodes to 0.46136, 0.5 to 0.73536.
        assert!((linear_to_srgb(0.18) - 0.461_356_1).abs() < 1e-6);
        assert!((linear_to_srgb(0.5) - 0.735_356_9).abs() < 1e-6);
        assert_eq!(linear_to_srgb(-1.0), 0.0);
        for k in 0..=1000 {
            let c = k as f32 / 1000.0;
            assert!((srgb_to_linear(linear_to_srgb(c)) - c).abs() < 3e-5 * c.max(1e-3));
        }
    }
}
