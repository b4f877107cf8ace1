//! Compositing along a ray: optical depth → opacity → transmittance → weights.
//!
//! The marcher reduces a ray to *pieces*: intervals `[t, t + δ]` of constant density σ
//! (world units). For a piece entered with transmittance `T`:
//!
//! - opacity `α = 1 − e^{−σδ}`, computed as `−expm1(−σδ)` so it stays exact for σδ → 0
//!   and saturates to exactly 1 for σ → ∞;
//! - weight `w = T·α`, and the next transmittance is `T·e^{−σδ}`, so `Σw + T_end = 1` holds
//!   to rounding whatever σ and δ are, and `Σw ≤ 1` (no alpha > 1);
//! - the weight's first moment `∫ t σ T e^{−σ(t−t₀)} dt` over the piece, for expected depth,
//!   in closed form: `T·(t₀α + δ·g(σδ)/(σδ))` with `g(x) = 1 − e^{−x}(1 + x)`.
//!
//! Worked example, three pieces of σ = 1, 2, 0 per unit and δ = 0.5:
//! ```
//! use nerfx_core::render::RunningComposite;
//! let mut p = RunningComposite::new();
//! p.add(0.0, 0.5, 1.0);
//! p.add(0.5, 0.5, 2.0);
//! p.add(1.0, 0.5, 0.0);
//! // T after them: e^{−0.5} · e^{−1} = e^{−1.5}.
//! assert!((p.transmittance() - (-1.5f64).exp()).abs() < 1e-15);
//! assert!((p.accumulation() - (1.0 - (-1.5f64).exp())).abs() < 1e-15);
//! ```

use std::f64::consts::{LN_2, PI};

use errorfunctions::RealErrorFunctions;

/// `g(x)/x = ∫₀¹ s·x·e^{−xs} ds` with `g(x) = 1 − e^{−x}(1 + x)`: the first moment of the
/// weight inside a constant piece of optical thickness `x`, as a fraction of its length.
/// A series for small x (where the direct form cancels), the exact form otherwise.
/// `alpha = 1 − e^{−x}` is passed in so one `expm1` serves both.
#[inline]
fn first_moment_fraction(x: f64, alpha: f64) -> f64 {
    if x < 1e-3 {
        // x/2 − x²/3 + x³/8 − …
        x * (0.5 - x * (1.0 / 3.0 - x * 0.125))
    } else if x > 700.0 {
        1.0 / x
    } else {
        (alpha - x * (1.0 - alpha)) / x
    }
}

/// Opacity of a piece of optical thickness `σδ`: `1 − e^{−σδ}`, exact for tiny and huge
/// thickness.
///
/// Past an optical thickness of 37.5 it is 1 as rounded, without an exponential. From
/// `ln 2` up `e^{−σδ} ≤ ½`, so `1 − e^{−σδ}` loses nothing to cancellation and takes the
/// plain exponential, cheaper than `expm1` there (5.8 against 8.2 ns here); thinner pieces
/// take `expm1`.
///
/// ```
/// use nerfx_core::render::opacity;
/// assert_eq!(opacity(0.0), 0.0);
/// assert_eq!(opacity(f64::INFINITY), 1.0);
/// // 1 − e^{−x} ≈ x − x²/2; the naive `1.0 - (-x).exp()` is off by ~1e-4 relative here.
/// assert!((opacity(1e-12) / 1e-12 - 1.0).abs() < 1e-11);
/// ```
#[inline]
pub fn opacity(optical_thickness: f64) -> f64 {
    if optical_thickness > OPAQUE_THICKNESS {
        1.0
    } else if optical_thickness >= LN_2 {
        1.0 - (-optical_thickness).exp()
    } else {
        -(-optical_thickness).exp_m1()
    }
}

/// The optical thickness past which `1 − e^{−σδ}` rounds to 1: `e^{−σδ}` is below half an
/// ulp of 1, `2^−54` (`e^{−37.43}`).
const OPAQUE_THICKNESS: f64 = 37.5;

/// The share of a piece's weight that its far end's colour gets, when the density goes
/// linearly from `σ₀` at the near end to `σ₁` at the far end over the piece's length `δ` (the
/// trapezoid rule's piece) and the colour goes linearly between the ends' colours: the mean
/// position `u ∈ [0, 1]` of the light the piece sends, `∫ u·σ(u)·T(u) du / ∫ σ(u)·T(u) du`
/// with `T(u) = e^{−(τ₀u + (τ₁−τ₀)u²/2)}` and `τ = σδ`.
///
/// A thin piece sends light from all along it: `(σ₀ + 2σ₁) / (3(σ₀ + σ₁))`. An opaque one
/// sends it from where it starts (`1/τ` of it for a constant density of optical thickness
/// `τ`), whatever its far end's density: weighing the ends by their densities would give
/// the colour deeper inside the surface most of the weight.
///
/// Since `σ(u)·T(u)·δ = −T′(u)`, integrating by parts gives
/// `share = (∫₀¹ T du − T(1)) / (1 − T(1))`, and `∫₀¹ T du` is a Gaussian integral in closed
/// form ([`thick_far_share`]). That difference cancels for a thin piece, which takes a series
/// instead ([`thin_far_share`]). Exact to ~1e-13 relative for any thickness from 1e-12 to 1e9
/// at either end (checked against quadrature of the definition,
/// `tests/numpy/far_share_reference.py`); ½ for NaN, infinite or zero thickness.
///
/// Worked examples: a thin constant piece, ½; σ₀ = 0, thin, ⅔; σ₀δ = σ₁δ = 13,
/// `1/13 − 1/(e^{13} − 1) ≈ 0.076921`.
pub(super) fn far_share(sigma0: f64, sigma1: f64, delta: f64) -> f64 {
    let (tau0, tau1) = (sigma0 * delta, sigma1 * delta);
    let mean = 0.5 * (tau0 + tau1);
    if !(mean > 0.0 && mean.is_finite()) {
        return 0.5;
    }
    let ratio = tau1 / mean;
    // Each series is used up to where its truncation error reaches ~1e-13 of the share.
    let share = if mean < 4e-6 {
        thin_far_share::<2>(ratio, mean)
    } else if mean < 5e-3 {
        thin_far_share::<4>(ratio, mean)
    } else if mean < 0.05 {
        thin_far_share::<6>(ratio, mean)
    } else if mean < THIN_PIECE {
        thin_far_share::<THIN_TERMS>(ratio, mean)
    } else {
        thick_far_share(tau0, tau1, mean)
    };
    if share.is_finite() {
        share.clamp(0.0, 1.0)
    } else {
        0.5
    }
}

/// Below this mean optical thickness a piece's far share comes from [`THIN_SERIES`]: the
/// closed form loses ~1e-13 of the share to cancellation at 0.03 and more below (1e-10 at
/// 1e-3), where eight terms of the series are exact to ~2e-14.
const THIN_PIECE: f64 = 0.15;

/// The far share of a piece of mean optical thickness `τ̄ = mean ≥ 0.15` with `τ₀`, `τ₁` at its
/// ends, by parts `(∫₀¹ T du − T(1))/(1 − T(1))` with `T(1) = e^{−τ̄}` and
/// `∫₀¹ T du = ∫₀¹ e^{−(τ₀u + au²)} du`, `a = (τ₁ − τ₀)/2`. Completing the square with
/// `xᵢ = τᵢ/(2√|a|)` (so that `x₀² − x₁² = −τ̄`; `erfcx` and `F` as in DLMF §7.2):
///
/// - density rising (`a > 0`): `(√π/2)(erfcx(x₀) − T(1)·erfcx(x₁))/√a`;
/// - density falling (`a < 0`): `(F(x₀) − T(1)·F(x₁))/√|a|`, `F` Dawson's integral;
/// - constant (`|a|` below rounding of `τ̄`): `(1 − e^{−τ̄})/τ̄`.
///
/// `erfcx` and `F` are scaled so nothing overflows; they come from the `errorfunctions` crate
/// (S. G. Johnson's Faddeeva-package algorithms: Chebyshev fits and continued fractions,
/// near machine precision).
fn thick_far_share(tau0: f64, tau1: f64, mean: f64) -> f64 {
    let t_end = (-mean).exp();
    let half_slope = 0.5 * (tau1 - tau0);
    let integral = if half_slope.abs() <= 1e-15 * mean {
        opacity(mean) / mean
    } else {
        let root = half_slope.abs().sqrt();
        let scale = 0.5 / root;
        // Each at most 1, so the far end's term is below rounding when T(1) is.
        let g = |x: f64| {
            if half_slope > 0.0 {
                0.5 * PI.sqrt() * x.erfcx()
            } else {
                x.dawson()
            }
        };
        let near = g(tau0 * scale);
        let difference = if t_end < 1e-17 * near {
            near
        } else {
            near - t_end * g(tau1 * scale)
        };
        difference / root
    };
    (integral - t_end) / (1.0 - t_end)
}

/// The far share of a thin piece from its mean optical thickness `τ̄` and `r = τ₁/τ̄ ∈ [0, 2]`:
/// the first `TERMS` of `share = Σₖ τ̄^{k−1} dₖ(r)` ([`THIN_SERIES`]).
///
/// With `v = 1 − u`, `τ̄ − τ(u) = v·(τ₁(1 − v) + τ̄v)`, so
/// `share = ∫₀¹ (e^{τ̄−τ(u)} − 1) du / (e^{τ̄} − 1)`. Expanding both exponentials and
/// integrating `v^{k+j}(1 − v)^{k−j}` (a Beta integral) gives the numerator
/// `Σₖ τ̄^k cₖ(r)`, `cₖ(r) = Σᵢ (2k−i)!/((k−i)!(2k+1)!) rⁱ` (`i ≤ k`, every term positive,
/// so nothing cancels), and the denominator `Σₖ τ̄^k/k!`; their quotient, a series in τ̄ whose
/// terms shrink about a hundredfold for every two at τ̄ = 0.1, starts with the trapezoid's
/// `(2 + r)/6 = (τ₀ + 2τ₁)/(3(τ₀ + τ₁))`.
#[inline]
fn thin_far_share<const TERMS: usize>(ratio: f64, mean: f64) -> f64 {
    THIN_SERIES[..TERMS]
        .iter()
        .enumerate()
        .rev()
        .fold(0.0, |share, (k, d)| {
            let term = d[..=k + 1]
                .iter()
                .rev()
                .fold(0.0, |acc, &c| acc * ratio + c);
            share * mean + term
        })
}

/// Terms in [`THIN_SERIES`].
const THIN_TERMS: usize = 8;

/// `THIN_SERIES[k − 1][i]`: the coefficient of `rⁱ` in `dₖ(r)`, the k-th term of the thin
/// series ([`thin_far_share`]): `d₁ = (2 + r)/6`, `d₂ = −1/15 − r/30 + r²/60`, …
const THIN_SERIES: [[f64; THIN_TERMS + 1]; THIN_TERMS] = thin_series();

/// The quotient series `Σ dₖτ̄^{k−1} = Σ cₖτ̄^{k−1} / Σ τ̄^{k−1}/k!`, term by term:
/// `dₖ = cₖ − Σ_{j<k} d_{k−j}/(j+1)!`.
const fn thin_series() -> [[f64; THIN_TERMS + 1]; THIN_TERMS] {
    const fn factorial(n: usize) -> f64 {
        let (mut f, mut i) = (1.0, 2);
        while i <= n {
            f *= i as f64;
            i += 1;
        }
        f
    }
    let mut d = [[0.0; THIN_TERMS + 1]; THIN_TERMS];
    let mut k = 1;
    while k <= THIN_TERMS {
        let mut i = 0;
        while i <= k {
            d[k - 1][i] = factorial(2 * k - i) / (factorial(k - i) * factorial(2 * k + 1));
            i += 1;
        }
        let mut j = 1;
        while j < k {
            let mut i = 0;
            while i <= k - j {
                d[k - 1][i] -= d[k - j - 1][i] / factorial(j + 1);
                i += 1;
            }
            j += 1;
        }
        k += 1;
    }
    d
}

/// A pixel composited in sRGB-encoded space (premultiplied RGB, accumulation `alpha`) as
/// scene-linear premultiplied RGB: unpremultiply, decode each channel, premultiply. A trainer
/// composites the encoded colours of the photographs it learned from, so a soft edge or a
/// haze looks as approved only when composited encoded and converted afterwards.
///
/// ```
/// use nerfx_core::render::srgb_composite_to_linear;
/// // Half coverage of encoded grey 0.5 (premultiplied 0.25): linear 0.2140 at alpha 0.5.
/// let [r, _, _] = srgb_composite_to_linear([0.25; 3], 0.5);
/// assert!((r - 0.5 * 0.214_041_1).abs() < 1e-5);
/// // Nothing covered stays nothing.
/// assert_eq!(srgb_composite_to_linear([0.0; 3], 0.0), [0.0; 3]);
/// ```
pub fn srgb_composite_to_linear(rgb: [f32; 3], alpha: f32) -> [f32; 3] {
    if alpha.is_nan() || alpha <= 0.0 {
        return [0.0; 3];
    }
    rgb.map(|c| crate::field::srgb_to_linear(c / alpha) * alpha)
}

/// The running composite of one ray: transmittance, accumulation and the depth moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunningComposite {
    transmittance: f64,
    depth_moment: f64,
}

impl Default for RunningComposite {
    fn default() -> Self {
        Self::new()
    }
}

impl RunningComposite {
    /// Nothing composited yet: `T = 1`.
    pub fn new() -> Self {
        RunningComposite {
            transmittance: 1.0,
            depth_moment: 0.0,
        }
    }

    /// The pieces of a pixel composited elsewhere, from its transmittance `T` and `Σ w·t`.
    pub(crate) fn from_sums(transmittance: f64, depth_moment: f64) -> Self {
        RunningComposite {
            transmittance,
            depth_moment,
        }
    }

    /// Composites the piece `[t, t + δ]` of density `σ` (both ≥ 0; σ may be `inf`) and
    /// returns its weight `w = T·α`.
    #[inline]
    pub fn add(&mut self, t: f64, delta: f64, sigma: f64) -> f64 {
        let x = sigma * delta;
        if x.is_nan() || x <= 0.0 {
            // Empty, zero-length (σ = inf with δ = 0 gives NaN here too) or invalid.
            return 0.0;
        }
        let alpha = opacity(x);
        let w = self.transmittance * alpha;
        self.depth_moment +=
            self.transmittance * (t * alpha + delta * first_moment_fraction(x, alpha));
        self.transmittance -= w;
        // `T·e^{−x}` and `T − T·α` are the same number; the subtraction keeps Σw + T = 1
        // exact, and the clamp keeps rounding from making T negative.
        self.transmittance = self.transmittance.max(0.0);
        w
    }

    /// Composites a fragment of opacity `alpha` (in [0, 1]) at distance `t` (a splat's, with
    /// no extent along the ray) and returns its weight `w = T·α`.
    #[inline]
    pub(crate) fn add_fragment(&mut self, t: f64, alpha: f64) -> f64 {
        let w = self.transmittance * alpha;
        self.depth_moment += w * t;
        self.transmittance = (self.transmittance - w).max(0.0);
        w
    }

    /// Composites a piece integrated elsewhere (a closed-form integrator's): its weight
    /// `w = T_enter − T_exit` and its first moment `∫ t σ T dt`.
    #[inline]
    pub(super) fn add_integrated(&mut self, weight: f64, moment: f64) {
        self.depth_moment += moment;
        self.transmittance = (self.transmittance - weight).max(0.0);
    }

    /// Transmittance `T` after the pieces so far.
    #[inline]
    pub fn transmittance(&self) -> f64 {
        self.transmittance
    }

    /// Accumulation (alpha) `Σw = 1 − T`.
    #[inline]
    pub fn accumulation(&self) -> f64 {
        1.0 - self.transmittance
    }

    /// Expected ray distance `Σ w t / Σ w`, or `inf` when nothing was accumulated.
    pub(crate) fn expected_depth(&self) -> f64 {
        let a = self.accumulation();
        if a > 0.0 {
            self.depth_moment / a
        } else {
            f64::INFINITY
        }
    }
}

/// Where, inside a logged sequence of pieces `(t, δ, x₀, x₁, T_enter)` whose density goes
/// linearly from `σ₀ = x₀/δ` to `σ₁ = x₁/δ` (optical thickness `(x₀ + x₁)/2`; a constant
/// piece has `x₀ = x₁`, a splat fragment `δ = 0` and `x₀ = x₁ = −ln(1 − α)`), the
/// accumulation first reaches `target`: the exact position inside the crossing piece, where
/// its optical depth `σ₀s + (σ₁ − σ₀)s²/2δ` reaches `ln(T_enter/(1 − target))`. `inf` when it
/// never does.
///
/// The pieces are as composited: each entered with the transmittance the one before it left
/// (or less, where something unlogged lay between), up to rounding. So a piece followed by
/// one entered clearly above `1 − target` does not cross; as transmittance only falls, those
/// pieces are the log's first ones, passed over by bisection, their exit transmittances (an
/// exponential each) not worked out.
pub(crate) fn crossing_depth(pieces: &[[f64; 5]], target: f64) -> f64 {
    let t_star = 1.0 - target;
    // Far above the rounding of `T − T·α` against `T·e^{−x}` (~1e-16 relative) at `T ≥ ½`.
    let clearly_above = t_star * (1.0 + 1e-9);
    let passed = (pieces.get(1..)).map_or(0, |next| {
        next.partition_point(|&[.., t_enter]| t_enter > clearly_above)
    });
    for &[t, delta, x0, x1, t_enter] in &pieces[passed..] {
        let t_exit = t_enter * (-0.5 * (x0 + x1)).exp();
        if t_exit <= t_star && t_enter > 0.0 {
            if t_enter <= t_star || delta == 0.0 {
                return t;
            }
            // In units of the piece's length: x₀u + (x₁ − x₀)u²/2 = depth, solved in the form
            // that does not cancel (x₀ ≥ 0, and the discriminant is ≥ x₁² ≥ 0 up to rounding).
            let depth = (t_enter / t_star).ln();
            let root = (x0 * x0 + 2.0 * (x1 - x0) * depth).max(0.0).sqrt();
            let u = 2.0 * depth / (x0 + root);
            let u = if u.is_finite() { u } else { 1.0 };
            return t + (u * delta).clamp(0.0, delta);
        }
    }
    f64::INFINITY
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each of the opacity's three regimes against `expm1` over all of them: within two
    /// ulps, and exactly 1 where `expm1` rounds to it too.
    #[test]
    fn opacity_keeps_expm1s_precision_in_every_regime() {
        for i in 0..=200_000 {
            let x = 1e-12 * 1.000_2f64.powi(i);
            if x > 60.0 {
                break;
            }
            let want = -(-x).exp_m1();
            let got = opacity(x);
            assert!(
                (got - want).abs() <= 2.0 * f64::EPSILON * want,
                "{x}: {got} {want}"
            );
        }
        assert_eq!(-(-OPAQUE_THICKNESS).exp_m1(), 1.0);
        assert!(opacity(f64::NAN).is_nan());
    }

    #[test]
    fn far_share_is_the_mean_position_of_the_light_a_linear_piece_sends() {
        // Against midpoint sums of the defining integrals (200 000 and 400 000 slices),
        // Richardson-extrapolated: the h² error terms cancel, leaving ~1e-13.
        let brute = |s0: f64, s1: f64, d: f64| {
            let (t0, t1) = (s0 * d, s1 * d);
            let sums = |n: u32| {
                let (mut num, mut den) = (0.0, 0.0);
                for k in 0..n {
                    let u = (k as f64 + 0.5) / n as f64;
                    let w = (t0 + (t1 - t0) * u) * (-(t0 * u + 0.5 * (t1 - t0) * u * u)).exp();
                    num += u * w;
                    den += w;
                }
                (num / n as f64, den / n as f64)
            };
            let ((num1, den1), (num2, den2)) = (sums(200_000), sums(400_000));
            (4.0 * num2 - num1) / (4.0 * den2 - den1)
        };
        for (s0, s1, d) in [
            (1.0, 2.0, 1e-5),
            (0.1, 5.0, 1.0),
            (6.0, 20.0, 1.0),
            (13.0, 13.0, 1.0),
            (0.0, 20.0, 1.0),
            (20.0, 0.0, 1.0),
            (100.0, 300.0, 1.0),
            (2.0, 2.0, 1.0),
            (5.0, 0.01, 1.0),
            (12.0, 0.3, 1.0),
            (0.04, 0.07, 1.0),
        ] {
            let (got, want) = (super::far_share(s0, s1, d), brute(s0, s1, d));
            assert!(
                (got - want).abs() < 1e-11 * want,
                "{s0} {s1} {d}: {got} vs {want}"
            );
        }
        // The worked examples: a constant piece's share is 1/τ − 1/(e^τ − 1), ½ − τ/12 thin.
        let thin = 3e-9;
        assert!((super::far_share(3.0, 3.0, 1e-9) - (0.5 - thin / 12.0)).abs() < 1e-15);
        assert!((super::far_share(0.0, 1.0, 1e-6) - 2.0 / 3.0).abs() < 1e-6);
        let opaque = 1.0 / 13.0 - 1.0 / 13f64.exp_m1();
        assert!((super::far_share(13.0, 13.0, 1.0) - opaque).abs() < 1e-15);
        for (s0, s1, d) in [
            (0.0, 0.0, 1.0),
            (f64::NAN, 1.0, 1.0),
            (1.0, f64::INFINITY, 1.0),
            (1.0, 1.0, f64::INFINITY),
            (f64::INFINITY, 1.0, 0.0),
        ] {
            assert_eq!(super::far_share(s0, s1, d), 0.5, "{s0} {s1} {d}");
        }
    }

    /// Quadrature of the definition in mpmath (`tests/numpy/far_share_reference.py`): a grid
    /// of thicknesses from 0 to 1e9 at either end, seeded random pairs, and density falling
    /// steeply across an opaque piece. A cross-check: needs `python3` with `mpmath`, and runs
    /// with the `cross-checks` feature (`scripts/test.sh`).
    #[test]
    #[cfg_attr(
        not(feature = "cross-checks"),
        ignore = "a cross-check: scripts/test.sh runs it"
    )]
    fn far_share_matches_quadrature_of_its_definition() {
        let script = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../tests/numpy/far_share_reference.py"
        );
        let run = std::process::Command::new("python3")
            .arg(script)
            .output()
            .unwrap_or_else(|e| panic!("the mpmath cross-check needs python3 ({e})"));
        assert!(
            run.status.success(),
            "the mpmath reference failed (it needs mpmath):\n{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let mut worst = (0.0, String::new());
        let mut cases = 0;
        for line in String::from_utf8_lossy(&run.stdout).lines() {
            let v: Vec<f64> = line.split(' ').map(|x| x.parse().unwrap()).collect();
            let (got, want) = (super::far_share(v[0], v[1], v[2]), v[3]);
            let error = (got - want).abs() / want;
            if error > worst.0 {
                worst = (error, format!("{line}: got {got}"));
            }
            cases += 1;
        }
        assert!(cases > 500, "{cases} cases");
        println!("worst relative error {:e} over {cases} cases", worst.0);
        assert!(
            worst.0 < 1e-12,
            "relative error {:e} at {}",
            worst.0,
            worst.1
        );
    }

    #[test]
    fn one_thick_piece_is_exact() {
        let mut p = RunningComposite::new();
        let w = p.add(2.0, 3.0, 0.5);
        let alpha = 1.0 - (-1.5f64).exp();
        assert!((w - alpha).abs() < 1e-15);
        // Expected depth of an exponential truncated to [2, 5] with rate 0.5, written out:
        // ∫ t·0.5e^{−0.5(t−2)} dt / α = 2 + (1/0.5) − 3e^{−1.5}/α.
        let expected = 2.0 + 2.0 - 3.0 * (-1.5f64).exp() / alpha;
        assert!((p.expected_depth() - expected).abs() < 1e-12);
    }

    #[test]
    fn many_thin_pieces_equal_one_thick_piece() {
        let mut thin = RunningComposite::new();
        for i in 0..1000 {
            thin.add(2.0 + i as f64 * 0.003, 0.003, 0.5);
        }
        let mut thick = RunningComposite::new();
        thick.add(2.0, 3.0, 0.5);
        assert!((thin.accumulation() - thick.accumulation()).abs() < 1e-13);
        assert!((thin.expected_depth() - thick.expected_depth()).abs() < 1e-10);
    }

    #[test]
    fn extreme_density_and_step_stay_finite_and_bounded() {
        for &(sigma, delta) in &[
            (1e8, 1e-9),
            (1e8, 1.0),
            (f64::INFINITY, 1e-3),
            (1e-12, 1e-12),
            (f64::INFINITY, 0.0),
            (f64::NAN, 1.0),
            (5.0, 0.0),
        ] {
            let mut p = RunningComposite::new();
            for i in 0..10 {
                p.add(1.0 + i as f64 * delta, delta, sigma);
            }
            let a = p.accumulation();
            assert!((0.0..=1.0).contains(&a), "{sigma} {delta}: {a}");
            let d = p.expected_depth();
            assert!(
                d.is_infinite() || (d >= 1.0 && d <= 1.0 + 10.0 * delta + 1e-12),
                "{d}"
            );
        }
        let mut opaque = RunningComposite::new();
        opaque.add(4.0, 1.0, f64::INFINITY);
        assert_eq!(opaque.accumulation(), 1.0);
        assert_eq!(opaque.expected_depth(), 4.0);
    }

    #[test]
    fn first_moment_fraction_is_continuous_across_branches() {
        for &x in &[1e-3f64, 700.0] {
            let (lo, hi) = (x * (1.0 - 1e-9), x * (1.0 + 1e-9));
            let below = first_moment_fraction(lo, opacity(lo));
            let above = first_moment_fraction(hi, opacity(hi));
            // The function itself changes by ~1e-9 relative over the bracket.
            assert!((below - above).abs() < 1e-8 * below.abs());
        }
        // Direct integral ∫₀¹ s·x·e^{−xs} ds by a fine midpoint sum at x = 0.37.
        let x = 0.37f64;
        let n = 200_000;
        let sum: f64 = (0..n)
            .map(|i| {
                let s = (i as f64 + 0.5) / n as f64;
                s * x * (-x * s).exp() / n as f64
            })
            .sum();
        assert!((first_moment_fraction(x, opacity(x)) - sum).abs() < 1e-10);
    }

    #[test]
    fn median_crossing_inside_a_piece() {
        // σ = 1 from t = 1: accumulation reaches 0.5 at 1 + ln 2.
        let log = [[1.0, 10.0, 10.0, 10.0, 1.0]];
        assert!((crossing_depth(&log, 0.5) - (1.0 + 2f64.ln())).abs() < 1e-12);
        assert!(crossing_depth(&log, 0.9999).is_finite());
        assert!(crossing_depth(&log, 0.99999).is_infinite());
        assert!(crossing_depth(&[[1.0, 0.1, 0.1, 0.1, 1.0]], 0.5).is_infinite());
    }

    /// A log as the marcher keeps it (seeded pieces, thin to opaque, constant and linear)
    /// crosses where the plain search, an exponential for every piece, finds it: the pieces
    /// skipped on their successors' entries are the ones that do not cross.
    #[test]
    fn median_crossing_skips_only_pieces_that_do_not_cross() {
        let plain = |pieces: &[[f64; 5]], target: f64| {
            let t_star = 1.0 - target;
            pieces
                .iter()
                .position(|&[_, _, x0, x1, t_enter]| {
                    t_enter * (-0.5 * (x0 + x1)).exp() <= t_star && t_enter > 0.0
                })
                .map_or(f64::INFINITY, |i| crossing_depth(&pieces[i..=i], target))
        };
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..200 {
            let (mut pieces, mut log, mut t) = (RunningComposite::new(), Vec::new(), 0.0);
            for _ in 0..40 {
                let delta = 0.01 + uniform();
                let (s0, s1) = (uniform().powi(4) * 3.0, uniform().powi(4) * 3.0);
                let t_enter = pieces.transmittance();
                if pieces.add(t, delta, 0.5 * (s0 + s1)) > 0.0 {
                    log.push([t, delta, s0 * delta, s1 * delta, t_enter]);
                }
                t += delta;
            }
            let alpha = pieces.accumulation();
            for target in [0.5 * alpha, 0.1 * alpha, 0.9 * alpha, 0.999 * alpha] {
                assert_eq!(crossing_depth(&log, target), plain(&log, target));
            }
        }
    }

    #[test]
    fn median_crossing_inside_a_linear_piece() {
        // σ(t) = 2(t − 1) on [1, 2]: optical depth (t − 1)², accumulation 0.5 at 1 + √ln 2.
        let log = [[1.0, 1.0, 0.0, 2.0, 1.0]];
        assert!((crossing_depth(&log, 0.5) - (1.0 + 2f64.ln().sqrt())).abs() < 1e-12);
        // Falling from σ = 2 to 0 on [1, 2]: optical depth 2s − s², so 0.5 at 1 + 1 − √(1 − ln 2).
        let log = [[1.0, 1.0, 2.0, 0.0, 1.0]];
        let want = 2.0 - (1.0 - 2f64.ln()).sqrt();
        assert!((crossing_depth(&log, 0.5) - want).abs() < 1e-12);
    }

    #[test]
    fn fragments_composite_as_alpha_over_and_cross_where_they_are() {
        // A half-opaque fragment at t = 2, then a piece σ = 1 over [3, 13]: T = 0.5·e^{−10}.
        let mut p = RunningComposite::new();
        assert_eq!(p.add_fragment(2.0, 0.5), 0.5);
        let w = p.add(3.0, 10.0, 1.0);
        assert!((w - 0.5 * opacity(10.0)).abs() < 1e-15);
        assert!((p.transmittance() - 0.5 * (-10f64).exp()).abs() < 1e-15);
        // Expected depth: half the weight at 2, the other half near 4 (the piece's mean).
        let piece_mean = 3.0 + 10.0 * first_moment_fraction(10.0, opacity(10.0)) / opacity(10.0);
        let want = (0.5 * 2.0 + w * piece_mean) / (0.5 + w);
        assert!((p.expected_depth() - want).abs() < 1e-12);
        // The median: accumulation reaches 0.3 at the fragment, 0.75 at 3 + ln 2.
        let log = [
            [2.0, 0.0, 2f64.ln(), 2f64.ln(), 1.0],
            [3.0, 10.0, 10.0, 10.0, 0.5],
        ];
        assert_eq!(crossing_depth(&log, 0.3), 2.0);
        assert!((crossing_depth(&log, 0.75) - (3.0 + 2f64.ln())).abs() < 1e-12);
    }
}
