//! Closed forms the reference integrator is built from: `erf`/`erfc` in f64 and the
//! integrals of a constant-density piece of ray.
//!
//! Everything here is written to stay exact at the extremes the renderer is tested against:
//! a density so small that `σΔ` is 1e-12, one so large that `σΔ` is 1e8, and Gaussian tails
//! where `erfc` is 1e-17.

use std::f64::consts::FRAC_2_SQRT_PI;

/// Below this `|x|`, `erf` comes from its Maclaurin series (no cancellation: the terms
/// shrink from the first one on), and `erfc = 1 − erf`.
const SERIES_LIMIT: f64 = 0.5;

/// Up to this `x`, `erfc` is a Taylor expansion about the nearest node of [`ERFC_NODES`];
/// above it, the continued fraction, which converges in [`CF_DEPTH`] terms there.
const TABLE_LIMIT: f64 = 6.0;

/// Node spacing of [`ERFC_NODES`]: `erfc(x)` is expanded about `x₀ = round(8x)/8`, so the
/// step `|h| ≤ 1/16` and the expansion converges in at most ~15 terms.
const NODES_PER_UNIT: f64 = 8.0;

/// Depth of the continued fraction for `x > 6` (20 terms already give 1e-16 relative).
const CF_DEPTH: u32 = 24;

/// `erfc(x)` is below the smallest subnormal f64 beyond this.
const ERFC_UNDERFLOW: f64 = 27.3;

/// `erfc(j/8)` for `j = 0..=48`, each the f64 nearest to the value computed with 40-digit
/// arithmetic (mpmath). These are the anchors of the Taylor expansion; everything else is
/// computed.
const ERFC_NODES: [f64; 49] = [
    1.0,
    0.8596837951986662,
    0.7236736098317631,
    0.5958830905651777,
    0.4795001221869535,
    0.376759117811582,
    0.28884436634648486,
    0.21592493894014034,
    0.15729920705028513,
    0.11161176829829224,
    0.07709987174354177,
    0.051829927217909674,
    0.033894853524689274,
    0.021556266760016336,
    0.013328328780817557,
    0.00800994232988003,
    0.004677734981047266,
    0.0026540293594823415,
    0.0014627165866811518,
    0.0007829382178911192,
    0.0004069520174449589,
    0.00020537573614121745,
    0.00010062192211963683,
    4.785483974377341e-05,
    2.209049699858544e-05,
    9.89673462524562e-06,
    4.302779463675122e-06,
    1.8152814274403558e-06,
    7.430983723414128e-07,
    2.951401925115699e-07,
    1.1372725656979665e-07,
    4.2513944082491124e-08,
    1.541725790028002e-08,
    5.423400799565066e-09,
    1.8505741373867425e-09,
    6.12483295356936e-10,
    1.9661604415428876e-10,
    6.121610513034226e-11,
    1.8485047721485312e-11,
    5.413406466297941e-12,
    1.537459794428035e-12,
    4.234563376336224e-13,
    1.1310313266887154e-13,
    2.9294885544871546e-14,
    7.357847917974398e-15,
    1.7920200056510066e-15,
    4.232136617425738e-16,
    9.691555645277176e-17,
    2.1519736712498913e-17,
];

/// The error function `erf(x) = (2/√π)∫₀ˣ e^{−s²} ds`, to ~1e-15 relative.
pub(crate) fn erf(x: f64) -> f64 {
    if x.abs() < SERIES_LIMIT {
        erf_series(x)
    } else if x > 0.0 {
        1.0 - erfc(x)
    } else {
        erfc(-x) - 1.0
    }
}

/// The complementary error function `erfc(x) = 1 − erf(x)`, to ~1e-15 relative also deep
/// in the tail (`erfc(6) ≈ 2e-17`), 0 beyond `x ≈ 27.3` where it underflows.
pub(crate) fn erfc(x: f64) -> f64 {
    if x.is_nan() {
        x
    } else if x < 0.0 {
        2.0 - erfc(-x)
    } else if x < SERIES_LIMIT {
        1.0 - erf_series(x)
    } else if x <= TABLE_LIMIT {
        erfc_taylor(x)
    } else if x < ERFC_UNDERFLOW {
        erfc_continued_fraction(x)
    } else {
        0.0
    }
}

/// `erf(b) − erf(a)`, written as a difference of `erfc`s when both arguments are on the
/// same side of 0, so that tails keep their relative precision (`erf(7) − erf(6)` is 2e-17,
/// which `erf` alone would round to 0).
pub(crate) fn erf_diff(a: f64, b: f64) -> f64 {
    if a >= 0.0 {
        erfc(a) - erfc(b)
    } else if b <= 0.0 {
        erfc(-b) - erfc(-a)
    } else {
        erf(b) - erf(a)
    }
}

/// Maclaurin series `erf(x) = (2/√π) Σₙ (−1)ⁿ x^{2n+1} / (n!(2n+1))`; for `|x| < 0.5` each
/// term is below a tenth of the one before, so there is no cancellation.
fn erf_series(x: f64) -> f64 {
    let x2 = x * x;
    let mut power = x; // (−1)ⁿ x^{2n+1} / n!
    let mut sum = x;
    for n in 1..40 {
        power *= -x2 / n as f64;
        let term = power / (2 * n + 1) as f64;
        sum += term;
        if term.abs() <= 1e-17 * sum.abs() {
            break;
        }
    }
    FRAC_2_SQRT_PI * sum
}

/// Taylor expansion of `erfc` about the node `x₀ = j/8` nearest to `x`, `h = x − x₀`:
///
/// `dⁿ/dxⁿ erfc(x) = −(2/√π)(−1)^{n−1} H_{n−1}(x) e^{−x²}` (physicists' Hermite `H`), so
/// `erfc(x₀+h) = erfc(x₀) − (2/√π) e^{−x₀²} Σ_{m≥0} (−1)ᵐ H_m(x₀) h^{m+1}/(m+1)!`,
/// with `H₀ = 1`, `H₁ = 2x`, `H_{m+1} = 2x H_m − 2m H_{m−1}`. `x₀²` is exact in f64.
fn erfc_taylor(x: f64) -> f64 {
    let j = (x * NODES_PER_UNIT).round();
    let x0 = j / NODES_PER_UNIT;
    let h = x - x0;
    let (mut hermite_prev, mut hermite) = (0.0, 1.0); // H_{m−1}, H_m
    let mut power = h; // (−1)ᵐ h^{m+1}/(m+1)!
    let mut sum = 0.0;
    for m in 0..60 {
        let term = power * hermite;
        sum += term;
        if m >= 2 && term.abs() <= 1e-17 * sum.abs() {
            break;
        }
        let next = 2.0 * x0 * hermite - 2.0 * m as f64 * hermite_prev;
        hermite_prev = hermite;
        hermite = next;
        power *= -h / (m + 2) as f64;
    }
    ERFC_NODES[j as usize] - FRAC_2_SQRT_PI * (-x0 * x0).exp() * sum
}

/// Laplace's continued fraction
/// `erfc(x) = (e^{−x²}/√π) · 1/(x + (1/2)/(x + 1/(x + (3/2)/(x + 2/(x + …)))))`,
/// evaluated bottom-up at a fixed depth (ample for `x > 6`).
fn erfc_continued_fraction(x: f64) -> f64 {
    let mut f = x;
    for k in (1..=CF_DEPTH).rev() {
        f = x + 0.5 * k as f64 / f;
    }
    exp_neg_square(x) * 0.5 * FRAC_2_SQRT_PI / f
}

/// `e^{−x²}` without the rounding error of `x²` (which, times `x² ≈ 700`, would cost
/// ~1e-13 relative): with `x = xₕ + xₗ` and `xₕ` on a 1/4096 grid, `xₕ²` is exact and
/// `e^{−x²} = e^{−xₕ²}·e^{−xₗ(x + xₕ)}`.
fn exp_neg_square(x: f64) -> f64 {
    let xh = (x * 4096.0).trunc() / 4096.0;
    (-xh * xh).exp() * (-(x - xh) * (x + xh)).exp()
}

/// `1 − e^{−x}`: the fraction of light a piece of optical depth `x` absorbs. Exact for
/// `x → 0` (through `expm1`) and exactly 1 for large `x`.
pub(crate) fn absorbed(x: f64) -> f64 {
    -(-x).exp_m1()
}

/// `m(x) = (1 − e^{−x}(1 + x))/x`, the depth moment of a constant piece.
///
/// For density σ on `[a, a+Δ]` with transmittance `T_a` at `a` and `x = σΔ`:
/// `∫ₐ^{a+Δ} (t − a) σ T_a e^{−σ(t−a)} dt = T_a (1 − e^{−x}(1+x))/σ = T_a·Δ·m(x)`.
/// For `x < 1` the numerator cancels (it is `x²/2 − x³/3 + …`), so the series
/// `m(x) = Σ_{n≥2} (−1)ⁿ (n−1) x^{n−1}/n!` is summed instead; for large `x`, `m(x) → 1/x`
/// and the moment tends to `T_a/σ`, the mean free path (no NaN, no overflow).
pub(crate) fn depth_moment(x: f64) -> f64 {
    if x >= 1.0 {
        return (absorbed(x) - x * (-x).exp()) / x;
    }
    let mut power = x / 2.0; // (−1)ⁿ x^{n−1}/n!, n = 2
    let mut sum = 0.0;
    for n in 2..40 {
        let term = (n - 1) as f64 * power;
        sum += term;
        if term.abs() <= 1e-17 * sum.abs() {
            break;
        }
        power *= -x / (n + 1) as f64;
    }
    sum
}

/// `√(π/2)`: `∫ e^{−s²/(2w²)} ds` over the whole line is `w·√(2π) = 2w·√(π/2)`.
pub(crate) const SQRT_HALF_PI: f64 = 1.253_314_137_315_500_3;

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_rel(got: f64, want: f64, tol: f64, what: &str) {
        let rel = ((got - want) / want).abs();
        assert!(
            rel <= tol,
            "{what}: got {got:e}, want {want:e}, rel {rel:e}"
        );
    }

    #[test]
    fn erf_matches_published_values() {
        assert_rel(erf(0.5), 0.520_499_877_813_046_5, 1e-15, "erf(0.5)");
        assert_rel(erf(1.0), 0.842_700_792_949_714_9, 1e-15, "erf(1)");
        assert_rel(erfc(3.0), 2.209_049_699_858_544e-5, 1e-15, "erfc(3)");
        assert_rel(erfc(5.0), 1.537_459_794_428_035e-12, 1e-15, "erfc(5)");
    }

    #[test]
    fn erf_and_erfc_match_high_precision_values_between_nodes() {
        // (x, erf(x), erfc(x)), from 40-digit arithmetic on the f64 nearest to x.
        let cases = [
            (1e-10, 1.1283791670955126e-10, 0.999999999887162),
            (0.001, 0.0011283787909692365, 0.9988716212090307),
            (0.3, 0.3286267594591274, 0.6713732405408726),
            (1.7, 0.9837904585907745, 0.01620954140922544),
            (2.3, 0.9988568234026434, 0.0011431765973566525),
            (4.1, 0.9999999932999724, 6.700027654084918e-9),
            (5.9, 0.9999999999999999, 7.190409783550478e-17),
            (6.2, 1.0, 1.816675617238127e-18),
            (7.5, 1.0, 2.776649386030569e-26),
            (12.0, 1.0, 1.3562611692059042e-64),
            (20.0, 1.0, 5.395865611607901e-176),
            (26.0, 1.0, 5.663192408856143e-296),
        ];
        for (x, e, ec) in cases {
            assert_rel(erf(x), e, 2e-15, &format!("erf({x})"));
            assert_rel(erf(-x), -e, 2e-15, &format!("erf(-{x})"));
            assert_rel(erfc(x), ec, 2e-15, &format!("erfc({x})"));
            assert_rel(erfc(-x), 2.0 - ec, 2e-15, &format!("erfc(-{x})"));
        }
        assert_eq!(erfc(30.0), 0.0);
        assert_eq!(erf(0.0), 0.0);
        assert!(erf(f64::NAN).is_nan() && erfc(f64::NAN).is_nan());
    }

    #[test]
    fn erf_is_continuous_across_its_branches() {
        for x in [SERIES_LIMIT, TABLE_LIMIT, 0.5625, 3.0625] {
            let (below, above) = (erfc(x * (1.0 - 1e-15)), erfc(x * (1.0 + 1e-15)));
            // erfc' = −(2/√π)e^{−x²}: the two sides differ by at most that slope × 2e-15·x.
            let slope = FRAC_2_SQRT_PI * (-x * x).exp();
            assert!(
                (below - above).abs() <= slope * 3e-15 * x + 4e-16 * below,
                "x = {x}: {below:e} vs {above:e}"
            );
        }
    }

    #[test]
    fn erf_diff_keeps_tails_relative() {
        // erf(7) − erf(6) = erfc(6) − erfc(7); erfc(7) = 4.183825607779414e-23.
        let want = 2.151_973_671_249_891_3e-17 - 4.183_825_607_779_414e-23;
        assert_rel(erf_diff(6.0, 7.0), want, 1e-15, "tail");
        assert_rel(erf_diff(-7.0, -6.0), want, 1e-15, "mirrored tail");
        assert_rel(
            erf_diff(-1.0, 0.5),
            0.842_700_792_949_714_9 + 0.520_499_877_813_046_5,
            1e-15,
            "across 0",
        );
    }

    #[test]
    fn sqrt_half_pi_matches_its_definition() {
        assert_rel(
            SQRT_HALF_PI,
            (std::f64::consts::PI / 2.0).sqrt(),
            3e-16,
            "sqrt(pi/2)",
        );
    }

    #[test]
    fn absorbed_is_exact_at_both_ends() {
        assert_rel(absorbed(1e-12), 1e-12 - 5e-25, 1e-15, "tiny");
        assert_eq!(absorbed(1e8), 1.0);
        assert_rel(absorbed(1.0), 1.0 - (-1.0f64).exp(), 1e-15, "one");
    }

    #[test]
    fn depth_moment_matches_the_closed_form_and_its_limits() {
        // Direct formula where it has no cancellation.
        for x in [0.7f64, 1.0, 2.0, 30.0] {
            let direct = (1.0 - (-x).exp() * (1.0 + x)) / x;
            assert_rel(depth_moment(x), direct, 1e-14, &format!("m({x})"));
        }
        // m(x) = x/2 − x²/3 + x³/8 − … for small x.
        let x = 1e-6;
        assert_rel(
            depth_moment(x),
            x / 2.0 - x * x / 3.0 + x * x * x / 8.0,
            1e-15,
            "small",
        );
        assert_eq!(depth_moment(0.0), 0.0);
        // Large x: the mean free path, 1/x.
        assert_rel(depth_moment(1e8), 1e-8, 1e-15, "large");
    }
}
