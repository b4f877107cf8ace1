//! The error functions the closed-form integrator takes a Gaussian's optical depth from,
//! each a table lookup and a short polynomial. A general-purpose `erfcx` chooses among a
//! hundred polynomials by branches and evaluates one term after another; here the piece is
//! an index and the polynomial's terms are taken in parallel (the demo's Draft at 1080p: 0.52
//! → 0.46 s of CPU, where error functions were a fifth of it).
//!
//! - [`erfcx`]`(x) = e^{x²}·erfc(x)` for `x ≥ 0`, to 1e-15 relative: `y·g(y)` with
//!   `y = 4/(4 + x)` in `(0, 1]`, where `g` is smooth up to `y = 0` (the tail), one of 64
//!   polynomials of degree 6 by the piece of `y` the argument falls in.
//! - [`erf`] from it, and below ½ (where `1 − erfc` would lose its relative precision) as
//!   `x·h(x²)`, `h` of degree 9 ([`small_erf`]).
//! - [`rough_erfcx`], a five-term rational fit for the quadrature's nodes.
//!
//! The tables are fitted by `scripts/erf_tables.py` with mpmath.

mod tables;

use self::tables::{ERFCX, ERF_SMALL, INTERVALS};

/// `erfcx(x) = e^{x²}·erfc(x)` for `x ≥ 0` (the module docs say how), within 1e-15 of it
/// relatively; 0 at `+∞`, NaN for NaN.
#[inline]
pub(crate) fn erfcx(x: f64) -> f64 {
    let y = 4.0 / (4.0 + x);
    let scaled = y * INTERVALS as f64;
    // `as` saturates: a NaN takes piece 0, and the NaN through.
    let piece = (scaled as usize).min(INTERVALS - 1);
    // Typed, so that a table of another degree does not build against these terms.
    let c: &[f64; 7] = &ERFCX[piece];
    let u = 2.0 * (scaled - piece as f64) - 1.0;
    // Estrin's order: pairs, then pairs of pairs, so that the multiplications do not wait
    // on one another as Horner's do.
    let u2 = u * u;
    let low = (c[0] + c[1] * u) + (c[2] + c[3] * u) * u2;
    let high = (c[4] + c[5] * u) + c[6] * u2;
    y * (low + high * (u2 * u2))
}

/// `erf(x)`, within 1e-15 of it relatively below ½ in magnitude and absolutely above.
#[inline]
pub(crate) fn erf(x: f64) -> f64 {
    let a = x.abs();
    let magnitude = if a < 0.5 {
        small_erf(a)
    } else {
        1.0 - (-a * a).exp() * erfcx(a)
    };
    magnitude.copysign(x)
}

/// `erf(x)` for `0 ≤ x < ½`, within 1e-15 of it relatively.
#[inline]
pub(crate) fn small_erf(x: f64) -> f64 {
    let u = 8.0 * x * x - 1.0;
    x * ERF_SMALL.iter().rev().fold(0.0, |acc, &c| acc * u + c)
}

/// How far `e^{−x²}·`[`rough_erfcx`]`(x)` can be from `erfc(x)`, for any `x ≥ 0`.
pub(crate) const ROUGH_ERFC_ERROR: f64 = 1.5e-7;

/// `erfcx(x)` for `x ≥ 0` as `s·P(s)`, `s = 1/(1 + p·x)`, `P` of degree 4 (Abramowitz and
/// Stegun 7.1.26): times `e^{−x²}`, within [`ROUGH_ERFC_ERROR`] of `erfc(x)`. A division
/// and a polynomial.
#[inline]
pub(crate) fn rough_erfcx(x: f64) -> f64 {
    const P: f64 = 0.327_591_1;
    const A: [f64; 5] = [
        0.254_829_592,
        -0.284_496_736,
        1.421_413_741,
        -1.453_152_027,
        1.061_405_429,
    ];
    let s = 1.0 / (1.0 + P * x);
    s * (A[0] + s * (A[1] + s * (A[2] + s * (A[3] + s * A[4]))))
}

#[cfg(test)]
mod tests {
    use errorfunctions::RealErrorFunctions;

    use super::*;

    /// Against the `errorfunctions` crate (Faddeeva's Chebyshev pieces, written apart from
    /// these tables) from 0 far into the tail, against the Maclaurin series below ½, and at
    /// the ends of the range.
    #[test]
    fn erfcx_and_erf_match_independent_implementations() {
        let mut worst = [0.0f64; 3];
        for i in 0..=200_000 {
            let x = f64::from(i) * 1e-4;
            let far = 10f64.powf(f64::from(i) * 6e-5);
            for (k, (got, want)) in [
                (erfcx(x), RealErrorFunctions::erfcx(x)),
                (erfcx(far), RealErrorFunctions::erfcx(far)),
                (erf(x - 10.0), RealErrorFunctions::erf(x - 10.0)),
            ]
            .into_iter()
            .enumerate()
            {
                let scale = if k == 2 { want.abs().min(1.0) } else { want };
                worst[k] = worst[k].max((got - want).abs() / scale);
            }
        }
        // The crate's own `erf` is off by up to 8e-15 relatively near 0.08 (against
        // mpmath), where the Maclaurin sum below holds this one to 1e-15.
        assert!(
            worst[0] < 2e-15 && worst[1] < 2e-15 && worst[2] < 1e-14,
            "{worst:?}"
        );
        for i in 1..=5_000 {
            let x = f64::from(i) * 1e-4;
            let (mut term, mut sum, mut n) = (x, x, 0.0);
            while term.abs() > 1e-18 * sum {
                n += 1.0;
                term *= -x * x / n;
                sum += term / (2.0 * n + 1.0);
            }
            let want = 2.0 / std::f64::consts::PI.sqrt() * sum;
            assert!((erf(x) - want).abs() < 1e-15 * want, "{x}");
        }
        assert!((erfcx(0.0) - 1.0).abs() < 1e-15);
        assert_eq!(erfcx(f64::INFINITY), 0.0);
        assert!(erfcx(f64::NAN).is_nan() && erf(f64::NAN).is_nan());
        assert_eq!(erf(f64::INFINITY), 1.0);
        assert_eq!(erf(-f64::INFINITY), -1.0);
    }

    /// The rough `erfc` against the exact one, within its stated error, from 0 far into the
    /// tail.
    #[test]
    fn rough_erfc_is_within_its_error() {
        let mut worst: f64 = 0.0;
        for i in 0..=40_000 {
            let x = f64::from(i) * 2e-4;
            let exact = RealErrorFunctions::erfc(x);
            let rough = (-x * x).exp() * rough_erfcx(x);
            worst = worst.max((rough - exact).abs());
        }
        assert!(worst <= ROUGH_ERFC_ERROR, "{worst}");
        assert!(worst > 0.1 * ROUGH_ERFC_ERROR, "{worst}");
    }
}
