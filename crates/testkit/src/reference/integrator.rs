//! The exact integrator of one ray, given the density along it as world-`t` segments.
//!
//! Each primitive seen along a ray becomes a [`Segment`]: an interval `[t₀, t₁]` of world
//! distance, a density that is either constant there or a 1-D Gaussian in `t`, and a colour
//! (constant along the ray: colours depend only on the direction). The sweep sorts every
//! segment end into breakpoints; between two consecutive ones the set of active segments is
//! fixed, and the piece `[a, b]` integrates as follows, with `τ` the optical depth,
//! `T(t) = e^{−τ(t)}`, `σ(t) = Σₖ σₖ(t)`:
//!
//! - **Constant densities only** (`σ` constant, `x = σΔ`, `Δ = b − a`): everything is closed
//!   form. The absorbed fraction is `ΔA = T_a(1 − e^{−x})` (as `−expm1(−x)`), the colour
//!   `ΔA · Σσₖcₖ/σ`, and the depth moment `∫ t σ T dt = a·ΔA + T_a·Δ·m(x)` with
//!   `m(x) = (1 − e^{−x}(1+x))/x` (see [`depth_moment`]): exact for `x → 0` and, for
//!   `σ → ∞`, the entry point `a` plus the mean free path `1/σ`.
//! - **With Gaussians**: the optical depth is still closed form (`erf`), so `ΔA` and the
//!   median depth stay exact; colour `∫ T Σσₖcₖ dt` and depth `∫ (t − a) σ T dt` are
//!   integrated by adaptive Gauss–Kronrod to 1e-10 relative to `ΔA`. Pieces are split
//!   where `τ` has grown by [`TAU_STEP`], so that `T` varies by at most `e^{−2}` inside a
//!   quadrature interval (a dense box overlapping a blob makes `T` a near-step that no fixed
//!   set of nodes would otherwise see), and at the Gaussian's centre and ±1.5, ±4, ±10
//!   widths, so that no peak hides between the nodes.
//!
//! Totals: `A = 1 − e^{−τ_total}`, `rgb = Σ colour`, expected depth `Σ depth moment / A`,
//! median depth the `t` where `1 − T(t) = A/2`, i.e. `τ(t) = −ln(1 − A/2)`, solved in closed
//! form on constant pieces and by safeguarded Newton on the monotone closed-form `τ`.
//! Pieces behind a transmittance below 1e-18, and quadrature intervals that absorb less
//! than 1e-18 of `A`, change no output by more than 1e-18 relative and are skipped (their
//! optical depth still counts in `A`).

use std::f64::consts::SQRT_2;
use std::ops::Range;

use glam::{DVec3, DVec4};

use super::closed_form::{absorbed, depth_moment, erf_diff, erfc, SQRT_HALF_PI};
use super::quadrature::Quadrature;

/// Relative accuracy of the quadrature on Gaussian pieces (relative to the piece's `ΔA`).
const QUADRATURE_TOLERANCE: f64 = 1e-10;

/// Largest optical depth of one quadrature interval.
const TAU_STEP: f64 = 2.0;

/// Pieces seen through less transmittance than this are skipped.
const NEGLIGIBLE_TRANSMITTANCE: f64 = 1e-18;

/// Where the sweep splits a Gaussian's support, in widths from its centre.
const GAUSSIAN_SPLITS: [f64; 7] = [-10.0, -4.0, -1.5, 0.0, 1.5, 4.0, 10.0];

/// The reference's answer for one ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayResult {
    /// Premultiplied linear RGB, `∫ T Σₖσₖcₖ dt`.
    pub rgb: DVec3,
    /// Accumulation `A = 1 − T(∞)`.
    pub alpha: f64,
    /// Expected ray distance `∫ t σ T dt / A` (world units); `+∞` where `A = 0`.
    pub depth_ray: f64,
    /// Ray distance where `1 − T(t) = A/2` (world units); `+∞` where `A = 0`.
    pub depth_median: f64,
}

impl RayResult {
    /// A ray that meets no density.
    pub const EMPTY: RayResult = RayResult {
        rgb: DVec3::ZERO,
        alpha: 0.0,
        depth_ray: f64::INFINITY,
        depth_median: f64::INFINITY,
    };
}

/// A Gaussian density along a ray: `peak · exp(−(t − centre)²/(2·width²))` per world unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Gaussian1d {
    /// Density at `centre` (per world unit).
    pub peak: f64,
    /// World distance of the maximum.
    pub centre: f64,
    /// Standard deviation in world units.
    pub width: f64,
}

impl Gaussian1d {
    fn density(&self, t: f64) -> f64 {
        let z = (t - self.centre) / self.width;
        self.peak * (-0.5 * z * z).exp()
    }

    /// `∫ₐᵇ peak·e^{−(t−c)²/(2w²)} dt = peak·w·√(π/2)·(erf((b−c)/(√2w)) − erf((a−c)/(√2w)))`.
    fn optical_depth(&self, a: f64, b: f64) -> f64 {
        let scale = SQRT_2 * self.width;
        let diff = erf_diff((a - self.centre) / scale, (b - self.centre) / scale);
        self.peak * self.width * SQRT_HALF_PI * diff
    }

    /// `erfc(|t − c|/(√2w))`: the fraction of the blob's optical depth that lies beyond `t`,
    /// on `t`'s side of the centre.
    fn tail(&self, t: f64) -> f64 {
        erfc(((t - self.centre) / (SQRT_2 * self.width)).abs())
    }

    /// [`Gaussian1d::optical_depth`] over `[from, t]` given `tail(from)`, for `from` and `t`
    /// on the same side of the centre (as within any piece: the sweep splits at centres).
    /// One `erfc` per call instead of two, in the quadrature's inner loop.
    fn optical_depth_from(&self, from: f64, tail_from: f64, t: f64) -> f64 {
        let diff = if from >= self.centre {
            tail_from - self.tail(t)
        } else {
            self.tail(t) - tail_from
        };
        self.peak * self.width * SQRT_HALF_PI * diff
    }
}

/// How density varies over a segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Density {
    /// Constant density per world unit.
    Constant(f64),
    /// A Gaussian in `t`.
    Gaussian(Gaussian1d),
}

/// One primitive along one ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Segment {
    /// World distance where the primitive starts (finite).
    pub t0: f64,
    /// World distance where it ends (finite, `> t0`).
    pub t1: f64,
    /// Its density over `[t0, t1]`.
    pub density: Density,
    /// Its linear RGB for this ray's direction.
    pub color: DVec3,
}

/// A piece of the sweep: consecutive breakpoints with a fixed set of active segments.
#[derive(Clone, Debug)]
struct SweepPiece {
    a: f64,
    b: f64,
    /// Optical depth from the ray's start to `a`.
    tau_a: f64,
    /// Optical depth of the piece.
    tau: f64,
    /// Sum of the active constant densities.
    sigma: f64,
    /// `Σ σₖ cₖ` over the active constant segments.
    sigma_rgb: DVec3,
    /// Indices (into the segments) of the active Gaussians, as a range of `Sweep::active`.
    gaussians: Range<usize>,
    /// Largest colour component of any active segment (scales the quadrature tolerance).
    max_color: f64,
}

/// The active densities of a piece, borrowed for evaluation.
#[derive(Clone, Copy)]
struct PieceDensity<'a> {
    sigma: f64,
    sigma_rgb: DVec3,
    gaussians: &'a [usize],
    segments: &'a [Segment],
}

impl PieceDensity<'_> {
    fn gaussians(&self) -> impl Iterator<Item = (&Gaussian1d, DVec3)> + '_ {
        self.gaussians
            .iter()
            .filter_map(|&k| match &self.segments[k].density {
                Density::Gaussian(g) => Some((g, self.segments[k].color)),
                Density::Constant(_) => None,
            })
    }

    /// Optical depth over `[from, to]`.
    fn optical_depth(&self, from: f64, to: f64) -> f64 {
        self.sigma * (to - from)
            + self
                .gaussians()
                .map(|(g, _)| g.optical_depth(from, to))
                .sum::<f64>()
    }

    /// Total density at `t`.
    fn density(&self, t: f64) -> f64 {
        self.sigma + self.gaussians().map(|(g, _)| g.density(t)).sum::<f64>()
    }

    /// The `t ∈ [from, to]` where the optical depth from `from` reaches `target`, to within
    /// `tolerance`: Newton on the monotone `τ` (its derivative is the density), bisecting
    /// whenever a step would leave the bracket.
    fn solve(&self, from: f64, to: f64, target: f64, tolerance: f64) -> f64 {
        let (mut lo, mut hi) = (from, to);
        let mut t = from;
        for _ in 0..200 {
            let f = self.optical_depth(from, t) - target;
            if f.abs() <= tolerance {
                return t;
            }
            if f < 0.0 {
                lo = t;
            } else {
                hi = t;
            }
            let newton = t - f / self.density(t);
            let next = if newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
            if next == t || lo >= hi {
                return t;
            }
            t = next;
        }
        t
    }
}

/// Reusable per-thread state of the sweep: fill [`Sweep::segments`], then
/// [`Sweep::integrate`].
#[derive(Debug, Default)]
pub(crate) struct Sweep {
    /// The segments of the ray being integrated.
    pub segments: Vec<Segment>,
    breaks: Vec<f64>,
    pieces: Vec<SweepPiece>,
    active: Vec<usize>,
    /// Per active Gaussian, `tail` at the start of the current quadrature interval.
    tails: Vec<f64>,
    quadrature: Quadrature,
}

impl Sweep {
    /// Integrates the current [`Sweep::segments`].
    pub(crate) fn integrate(&mut self) -> RayResult {
        self.build_pieces();
        let tau_total = self.pieces.last().map_or(0.0, |p| p.tau_a + p.tau);
        let alpha = absorbed(tau_total);
        if alpha <= 0.0 {
            return RayResult::EMPTY;
        }
        let (mut rgb, mut moment) = (DVec3::ZERO, 0.0);
        for piece in &self.pieces {
            let density = PieceDensity {
                sigma: piece.sigma,
                sigma_rgb: piece.sigma_rgb,
                gaussians: &self.active[piece.gaussians.clone()],
                segments: &self.segments,
            };
            let (c, m) = if density.gaussians.is_empty() {
                constant_piece(piece)
            } else {
                gaussian_piece(piece, density, alpha, &mut self.quadrature, &mut self.tails)
            };
            rgb += c;
            moment += m;
        }
        RayResult {
            rgb,
            alpha,
            depth_ray: moment / alpha,
            depth_median: self.median(alpha),
        }
    }

    /// Sorts the breakpoints and records each piece's active set and optical depth.
    fn build_pieces(&mut self) {
        self.breaks.clear();
        self.pieces.clear();
        self.active.clear();
        for s in &self.segments {
            self.breaks.push(s.t0);
            self.breaks.push(s.t1);
            if let Density::Gaussian(g) = &s.density {
                let inside = GAUSSIAN_SPLITS
                    .iter()
                    .map(|k| g.centre + k * g.width)
                    .filter(|&t| t > s.t0 && t < s.t1);
                self.breaks.extend(inside);
            }
        }
        self.breaks.sort_by(f64::total_cmp);
        self.breaks.dedup();
        let mut tau_a = 0.0;
        for w in self.breaks.windows(2) {
            let (a, b) = (w[0], w[1]);
            let start = self.active.len();
            let (mut sigma, mut sigma_rgb, mut max_color) = (0.0, DVec3::ZERO, 0.0f64);
            let mut any = false;
            for (k, s) in self.segments.iter().enumerate() {
                // Every segment end is a breakpoint, so a segment covers a piece or misses it.
                if s.t0 > a || s.t1 < b {
                    continue;
                }
                any = true;
                max_color = max_color.max(s.color.max_element());
                match s.density {
                    Density::Constant(d) => {
                        sigma += d;
                        sigma_rgb += d * s.color;
                    }
                    Density::Gaussian(_) => self.active.push(k),
                }
            }
            if !any {
                continue;
            }
            let gaussians = start..self.active.len();
            let density = PieceDensity {
                sigma,
                sigma_rgb,
                gaussians: &self.active[gaussians.clone()],
                segments: &self.segments,
            };
            let tau = density.optical_depth(a, b);
            self.pieces.push(SweepPiece {
                a,
                b,
                tau_a,
                tau,
                sigma,
                sigma_rgb,
                gaussians,
                max_color,
            });
            tau_a += tau;
        }
    }

    /// The `t` where `1 − T(t) = A/2`: `τ(t) = −ln(1 − A/2)`.
    fn median(&self, alpha: f64) -> f64 {
        let target = -(-0.5 * alpha).ln_1p();
        let Some(piece) = self
            .pieces
            .iter()
            .find(|p| p.tau > 0.0 && p.tau_a + p.tau >= target)
            .or(self.pieces.last())
        else {
            return f64::INFINITY;
        };
        let need = (target - piece.tau_a).clamp(0.0, piece.tau);
        if piece.gaussians.is_empty() {
            return (piece.a + need / piece.sigma).min(piece.b);
        }
        let density = PieceDensity {
            sigma: piece.sigma,
            sigma_rgb: piece.sigma_rgb,
            gaussians: &self.active[piece.gaussians.clone()],
            segments: &self.segments,
        };
        density.solve(piece.a, piece.b, need, 1e-15 * target)
    }
}

/// Colour and depth moment of a piece of constant density, in closed form.
fn constant_piece(piece: &SweepPiece) -> (DVec3, f64) {
    let transmittance = (-piece.tau_a).exp();
    if transmittance < NEGLIGIBLE_TRANSMITTANCE || piece.sigma <= 0.0 {
        return (DVec3::ZERO, 0.0);
    }
    let length = piece.b - piece.a;
    let absorbed_here = transmittance * absorbed(piece.tau);
    let rgb = piece.sigma_rgb / piece.sigma * absorbed_here;
    let moment = piece.a * absorbed_here + transmittance * length * depth_moment(piece.tau);
    (rgb, moment)
}

/// Colour and depth moment of a piece with Gaussians: quadrature over sub-intervals of
/// optical depth at most [`TAU_STEP`]; `alpha` is the ray's total accumulation (sub-intervals
/// absorbing less than 1e-18 of it are skipped).
fn gaussian_piece(
    piece: &SweepPiece,
    density: PieceDensity,
    alpha: f64,
    quadrature: &mut Quadrature,
    tails: &mut Vec<f64>,
) -> (DVec3, f64) {
    let (mut rgb, mut moment) = (DVec3::ZERO, 0.0);
    let (mut lo, mut tau_lo) = (piece.a, piece.tau_a);
    let tau_end = piece.tau_a + piece.tau;
    while lo < piece.b {
        let transmittance = (-tau_lo).exp();
        if transmittance < NEGLIGIBLE_TRANSMITTANCE {
            break;
        }
        let hi = if tau_end - tau_lo <= TAU_STEP {
            piece.b
        } else {
            density.solve(lo, piece.b, TAU_STEP, 0.25)
        };
        if hi <= lo {
            break;
        }
        let tau = density.optical_depth(lo, hi);
        let absorbed_here = transmittance * absorbed(tau);
        if absorbed_here <= NEGLIGIBLE_TRANSMITTANCE * alpha {
            // Far in a tail: below 1e-18 of the ray's total, and a tolerance relative to it
            // could underflow.
            (lo, tau_lo) = (hi, tau_lo + tau);
            continue;
        }
        tails.clear();
        tails.extend(density.gaussians().map(|(g, _)| g.tail(lo)));
        let tails = &*tails;
        let integrand = |t: f64| {
            let mut tau = density.sigma * (t - lo);
            let mut sigma_rgb = density.sigma_rgb;
            let mut sigma = density.sigma;
            for ((g, color), &tail_lo) in density.gaussians().zip(tails) {
                tau += g.optical_depth_from(lo, tail_lo, t);
                let d = g.density(t);
                sigma += d;
                sigma_rgb += d * color;
            }
            let weight = transmittance * (-tau).exp();
            (weight * sigma_rgb).extend(weight * sigma * (t - lo))
        };
        let tolerance = QUADRATURE_TOLERANCE
            * absorbed_here
            * DVec4::new(piece.max_color, piece.max_color, piece.max_color, hi - lo);
        let v = quadrature.integrate(integrand, lo, hi, tolerance);
        rgb += v.truncate();
        moment += lo * absorbed_here + v.w;
        (lo, tau_lo) = (hi, tau_lo + tau);
    }
    (rgb, moment)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(t0: f64, t1: f64, sigma: f64, color: DVec3) -> Segment {
        Segment {
            t0,
            t1,
            density: Density::Constant(sigma),
            color,
        }
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * b.abs().max(1e-300)
    }

    #[test]
    fn no_segments_is_empty() {
        let mut s = Sweep::default();
        assert_eq!(s.integrate(), RayResult::EMPTY);
    }

    #[test]
    fn single_constant_segment_matches_the_textbook_formulas() {
        // σ = 0.7 on [2, 5]: A = 1 − e^{−2.1}; E[t] = ∫ t σ e^{−σ(t−2)} dt / A;
        // ∫₀^Δ (2 + s) σ e^{−σs} ds = 2A + (1 − e^{−σΔ}(1 + σΔ))/σ.
        let mut s = Sweep::default();
        s.segments
            .push(constant(2.0, 5.0, 0.7, DVec3::new(1.0, 0.5, 0.0)));
        let r = s.integrate();
        let a = 1.0 - (-2.1f64).exp();
        let depth = (2.0 * a + (1.0 - (-2.1f64).exp() * 3.1) / 0.7) / a;
        // Median: 1 − e^{−σ(t−2)} = A/2.
        let median = 2.0 - (1.0 - a / 2.0).ln() / 0.7;
        assert!(close(r.alpha, a, 1e-15));
        assert!(close(r.rgb.x, a, 1e-15) && close(r.rgb.y, 0.5 * a, 1e-15) && r.rgb.z == 0.0);
        assert!(close(r.depth_ray, depth, 1e-14), "{} {depth}", r.depth_ray);
        assert!(
            close(r.depth_median, median, 1e-14),
            "{} {median}",
            r.depth_median
        );
    }

    #[test]
    fn gaussian_optical_depth_matches_a_fine_sum() {
        let g = Gaussian1d {
            peak: 3.0,
            centre: 1.0,
            width: 0.4,
        };
        // Midpoint rule with 200k steps on [0.2, 1.9].
        let n = 200_000;
        let h = 1.7 / n as f64;
        let sum: f64 = (0..n)
            .map(|i| {
                let t = 0.2 + (i as f64 + 0.5) * h;
                3.0 * (-(t - 1.0) * (t - 1.0) / (2.0 * 0.16)).exp() * h
            })
            .sum();
        assert!(close(g.optical_depth(0.2, 1.9), sum, 1e-9));
    }

    #[test]
    fn optical_depth_from_a_cached_tail_matches_a_fine_sum_on_both_sides() {
        let g = Gaussian1d {
            peak: 2.0,
            centre: 1.0,
            width: 0.3,
        };
        let midpoint_sum = |a: f64, b: f64| {
            let n = 100_000;
            let h = (b - a) / n as f64;
            (0..n)
                .map(|i| {
                    let t = a + (i as f64 + 0.5) * h;
                    2.0 * (-(t - 1.0) * (t - 1.0) / (2.0 * 0.09)).exp() * h
                })
                .sum::<f64>()
        };
        for (a, b) in [(0.1, 0.8), (1.0, 1.7), (1.2, 2.0)] {
            let got = g.optical_depth_from(a, g.tail(a), b);
            assert!(close(got, midpoint_sum(a, b), 1e-9), "[{a}, {b}]: {got}");
        }
    }

    #[test]
    fn median_inside_a_gaussian_piece_is_where_half_the_alpha_is_reached() {
        let mut s = Sweep::default();
        let g = Gaussian1d {
            peak: 5.0,
            centre: 3.0,
            width: 0.5,
        };
        s.segments.push(Segment {
            t0: 1.0,
            t1: 5.0,
            density: Density::Gaussian(g),
            color: DVec3::ONE,
        });
        let r = s.integrate();
        // 1 − T(median) = A/2 with T from the closed-form optical depth.
        let t_median = (-g.optical_depth(1.0, r.depth_median)).exp();
        assert!(close(1.0 - t_median, r.alpha / 2.0, 1e-13));
    }

    #[test]
    fn dense_box_over_a_gaussian_is_seen_by_the_quadrature() {
        // A box of σ = 1e6 on [2, 3] overlaps a blob centred at 2.5: the light is absorbed
        // within ~1e-6 of t = 2, where the blob's density is tiny next to the box's. So the
        // colour is the box's and the depth 2 + ~1e-6.
        let mut s = Sweep::default();
        s.segments
            .push(constant(2.0, 3.0, 1e6, DVec3::new(0.0, 1.0, 0.0)));
        s.segments.push(Segment {
            t0: 1.5,
            t1: 3.5,
            density: Density::Gaussian(Gaussian1d {
                peak: 1.0,
                centre: 2.5,
                width: 0.2,
            }),
            color: DVec3::new(1.0, 0.0, 0.0),
        });
        let r = s.integrate();
        assert_eq!(r.alpha, 1.0);
        // Red: what the blob absorbs before t = 2, plus its share inside the box.
        // The blob's optical depth on [1.5, 2] by a midpoint sum.
        let n = 100_000;
        let h = 0.5 / n as f64;
        let tau: f64 = (0..n)
            .map(|i| {
                let t = 1.5 + (i as f64 + 0.5) * h;
                (-(t - 2.5) * (t - 2.5) / (2.0 * 0.04)).exp() * h
            })
            .sum();
        let before = 1.0 - (-tau).exp();
        assert!((r.rgb.x - before).abs() < 1e-6, "{} {before}", r.rgb.x);
        assert!((r.rgb.y - (1.0 - before)).abs() < 1e-6, "{}", r.rgb.y);
        assert!((r.depth_median - 2.0).abs() < 1e-5, "{}", r.depth_median);
    }
}
