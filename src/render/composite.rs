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
//! use nerfx::render::Pieces;
//! let mut p = Pieces::new();
//! p.add(0.0, 0.5, 1.0);
//! p.add(0.5, 0.5, 2.0);
//! p.add(1.0, 0.5, 0.0);
//! // T after them: e^{−0.5} · e^{−1} = e^{−1.5}.
//! assert!((p.transmittance() - (-1.5f64).exp()).abs() < 1e-15);
//! assert!((p.accumulation() - (1.0 - (-1.5f64).exp())).abs() < 1e-15);
//! ```

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
/// ```
/// use nerfx::render::opacity;
/// assert_eq!(opacity(0.0), 0.0);
/// assert_eq!(opacity(f64::INFINITY), 1.0);
/// // 1 − e^{−x} ≈ x − x²/2; the naive `1.0 - (-x).exp()` is off by ~1e-4 relative here.
/// assert!((opacity(1e-12) / 1e-12 - 1.0).abs() < 1e-11);
/// ```
#[inline]
pub fn opacity(optical_thickness: f64) -> f64 {
    -(-optical_thickness).exp_m1()
}

/// The share of a piece's weight that its far end's colour gets, when the density goes
/// linearly from `σ₀` at the near end to `σ₁` at the far end over the piece's length `δ` (the
/// trapezoid rule's piece) and the colour goes linearly between the ends' colours: the mean
/// position `u ∈ [0, 1]` of the light the piece sends, `∫ u·σ(u)·T(u) du / ∫ σ(u)·T(u) du`
/// with `T(u) = e^{−δ(σ₀u + (σ₁−σ₀)u²/2)}`.
///
/// A thin piece sends light from all along it: `(σ₀ + 2σ₁) / (3(σ₀ + σ₁))`. An opaque one
/// sends it from where it starts (`1/τ` of it for a constant density of optical thickness
/// `τ`), whatever its far end's density: weighing the ends by their densities would give
/// the colour deeper inside the surface most of the weight. Computed as the mean of `u` over
/// the cumulative weight `v` (Gauss–Legendre, six points), where `u(v)` is smooth: the
/// optical depth reached is `s = −ln(1 − v·α)`, and `u` solves `τ₀u + (τ₁−τ₀)u²/2 = s`.
///
/// Worked examples: a thin constant piece, ½; σ₀ = 0, thin, ⅔; σ₀δ = σ₁δ = 13, `1/13`.
pub(super) fn far_share(sigma0: f64, sigma1: f64, delta: f64) -> f64 {
    let (tau0, tau1) = (sigma0 * delta, sigma1 * delta);
    let tau = 0.5 * (tau0 + tau1);
    let thick = tau > 1e-2 && tau.is_finite();
    if !thick {
        // Thin (or empty, or not finite): the trapezoid's own share, off by about τ/12 (a
        // colour error under a thousandth of the piece's weight).
        let sum = tau0 + tau1;
        return if sum > 0.0 && sum.is_finite() {
            (tau0 + 2.0 * tau1) / (3.0 * sum)
        } else {
            0.5
        };
    }
    // Nodes and weights of six-point Gauss–Legendre on [0, 1].
    const NODES: [f64; 3] = [
        0.033_765_242_898_423_98,
        0.169_395_306_766_867_74,
        0.380_690_406_958_401_5,
    ];
    const WEIGHTS: [f64; 3] = [
        0.085_662_246_189_585_17,
        0.180_380_786_524_069_3,
        0.233_956_967_286_345_5,
    ];
    let alpha = opacity(tau);
    let u = |v: f64| {
        let s = -(-v * alpha).ln_1p();
        let root = (tau0 * tau0 + 2.0 * (tau1 - tau0) * s).max(0.0).sqrt();
        2.0 * s / (tau0 + root)
    };
    let share: f64 = NODES
        .iter()
        .zip(WEIGHTS)
        .map(|(&x, w)| w * (u(x) + u(1.0 - x)))
        .sum();
    if share.is_finite() {
        share.clamp(0.0, 1.0)
    } else {
        0.5
    }
}

/// A pixel composited in sRGB-encoded space (premultiplied RGB, accumulation `alpha`) as
/// scene-linear premultiplied RGB: unpremultiply, decode each channel, premultiply. A trainer
/// composites the encoded colours of the photographs it learned from, so a soft edge or a
/// haze looks as approved only when composited encoded and converted afterwards.
///
/// ```
/// use nerfx::render::srgb_composite_to_linear;
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
pub struct Pieces {
    transmittance: f64,
    depth_moment: f64,
}

impl Default for Pieces {
    fn default() -> Self {
        Self::new()
    }
}

impl Pieces {
    /// Nothing composited yet: `T = 1`.
    pub fn new() -> Self {
        Pieces {
            transmittance: 1.0,
            depth_moment: 0.0,
        }
    }

    /// The pieces of a pixel composited elsewhere, from its transmittance `T` and `Σ w·t`.
    pub fn from_sums(transmittance: f64, depth_moment: f64) -> Self {
        Pieces {
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
    pub fn add_fragment(&mut self, t: f64, alpha: f64) -> f64 {
        let w = self.transmittance * alpha;
        self.depth_moment += w * t;
        self.transmittance = (self.transmittance - w).max(0.0);
        w
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
    pub fn expected_depth(&self) -> f64 {
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
pub fn crossing_depth(pieces: &[[f64; 5]], target: f64) -> f64 {
    let t_star = 1.0 - target;
    for &[t, delta, x0, x1, t_enter] in pieces {
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

    #[test]
    fn far_share_is_the_mean_position_of_the_light_a_linear_piece_sends() {
        // Against a midpoint sum of the defining integrals, 200 000 slices.
        let brute = |s0: f64, s1: f64, d: f64| {
            let n = 200_000;
            let (t0, t1) = (s0 * d, s1 * d);
            let (mut num, mut den) = (0.0, 0.0);
            for k in 0..n {
                let u = (k as f64 + 0.5) / n as f64;
                let w = (t0 + (t1 - t0) * u) * (-(t0 * u + 0.5 * (t1 - t0) * u * u)).exp();
                num += u * w;
                den += w;
            }
            num / den
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
        ] {
            let (got, want) = (super::far_share(s0, s1, d), brute(s0, s1, d));
            assert!(
                (got - want).abs() < 1.5e-3,
                "{s0} {s1} {d}: {got} vs {want}"
            );
        }
        // The worked examples, and the thin limit where the ends' densities differ.
        assert_eq!(super::far_share(3.0, 3.0, 1e-9), 0.5);
        assert!((super::far_share(0.0, 1.0, 1e-6) - 2.0 / 3.0).abs() < 1e-6);
        assert!((super::far_share(13.0, 13.0, 1.0) - 1.0 / 13.0).abs() < 1.5e-3);
        assert_eq!(super::far_share(0.0, 0.0, 1.0), 0.5);
    }

    #[test]
    fn one_thick_piece_is_exact() {
        let mut p = Pieces::new();
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
        let mut thin = Pieces::new();
        for i in 0..1000 {
            thin.add(2.0 + i as f64 * 0.003, 0.003, 0.5);
        }
        let mut thick = Pieces::new();
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
            let mut p = Pieces::new();
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
        let mut opaque = Pieces::new();
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
        let mut p = Pieces::new();
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
