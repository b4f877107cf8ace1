//! A piece of a ray where a Gaussian blob is present: its weight from the closed-form
//! optical depth, its colour split and depth moment in closed form where it is thin or its
//! density changes little and by Gauss–Legendre panels held to the error target where not,
//! and the depth inside it where an optical depth is reached (the median).

use glam::DVec3;

use super::Budget;
use crate::field::{Anchor, Density, Profile};
use crate::render::integrator::opacity;

/// Gauss–Legendre nodes on `[−1, 1]` and their weights, 3 points (exact for polynomials of
/// degree 5) and 4 (degree 7).
const GAUSS_3: ([f64; 3], [f64; 3]) = (
    [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4],
    [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0],
);
const GAUSS_4: ([f64; 4], [f64; 4]) = (
    [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_26,
        0.339_981_043_584_856_26,
        0.861_136_311_594_052_6,
    ],
    [
        0.347_854_845_137_453_85,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_85,
    ],
);

/// What share of the error target the expected depth is held to, relative: the target
/// bounds alpha and colour, and the marcher's depths at Draft and Preview are off by about
/// a fifth of it (relative), which the closed form does not do worse than.
pub(super) const DEPTH_SHARE: f64 = 0.125;

/// What share of the error target a piece's colour is held to where it is taken in closed
/// form ([`GaussianPiece::integrate`]): its bound is a worst case that, held to the whole target,
/// leaves colours further from the exact ones than the marcher's (Final's largest colour
/// error 6.2e-4 on the demo, the marcher's 3.3e-4; a quarter gives 1.6e-4).
const COLOUR_SHARE: f64 = 0.25;

/// A Gaussian piece is integrated only up to where its light has all but gone
/// ([`GaussianPiece::integrate`]) once its optical depth is this many times what that takes.
const OPAQUE: f64 = 4.0;

/// Bisections of a Gaussian piece at most: 48 halvings take a piece of a world unit below
/// 1e-14, past any profile's scale.
const MAX_BISECTIONS: u32 = 48;

/// Newton steps at most when solving for a depth inside a piece: far more than a solve takes,
/// as each step is either at most half the one before or a bisection of the bracket.
const MAX_NEWTON_STEPS: u32 = 64;

/// `e − 2`, rounded up: [`exp_above`]'s curvature.
const E_MINUS_TWO_ABOVE: f64 = 0.718_281_9;

/// An upper bound on `e^h` for `h ≥ 0` without an exponential up to 1:
/// `(e^h − 1 − h)/h²` grows with `h`, to `e − 2` at 1, so `1 + h + (e − 2)·h²` is above
/// `e^h` there, and at most 2.002 % above it (near 0.61). `e^h` beyond.
#[inline]
fn exp_above(h: f64) -> f64 {
    if h <= 1.0 {
        1.0 + h + E_MINUS_TWO_ABOVE * h * h
    } else {
        h.exp()
    }
}

/// One piece `[a, b]` of a ray: the profiles present all over it, and their anchors at `a`.
pub(super) struct GaussianPiece<'a> {
    a: f64,
    profiles: &'a [Profile],
    colours: &'a [DVec3],
    active: &'a [u32],
    anchors: &'a [Anchor],
}

/// A Gaussian piece's integrals from `a`, relative to the transmittance it is entered with:
/// colour `∫T Σσᵢcᵢ dt`, weight `∫σT dt` and transmittance `∫T dt`.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Sums {
    rgb: DVec3,
    weight: f64,
    transmittance: f64,
}

/// A Gaussian piece integrated ([`GaussianPiece::integrate`]), relative to the transmittance it is
/// entered with: its optical depth, weight `1 − e^{−τ}`, colour `∫T Σσᵢcᵢ dt` and depth
/// moment `∫tσT dt`.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Integral {
    pub(crate) optical_depth: f64,
    pub(crate) weight: f64,
    pub(crate) colour: DVec3,
    pub(crate) moment: f64,
}

/// A piece's optical depth and what bounds its integrals in closed form: over `[a, b]`, the
/// optical depth `τ`, the colour sum `Στᵢcᵢ` of the profiles' own optical depths, the
/// integral of the optical depth from `a`, `∫ₐᵇ τ(t) dt`, the least and greatest total
/// density (sums of each profile's least and greatest), and the density at `b`.
#[derive(Clone, Copy, Debug, Default)]
struct Whole {
    at_b: f64,
    tau: f64,
    rgb_tau: DVec3,
    integral: f64,
    least: f64,
    greatest: f64,
}

/// What a [`GaussianPiece::quadrature`] is held to: the colour split, `∫T dt`, and whether its
/// nodes take rough error functions.
#[derive(Clone, Copy, Debug)]
struct Asks {
    colour: bool,
    depth: bool,
    rough: bool,
}

impl Sums {
    /// Every integral times `k`.
    #[inline]
    fn scaled(self, k: f64) -> Sums {
        Sums {
            rgb: k * self.rgb,
            weight: k * self.weight,
            transmittance: k * self.transmittance,
        }
    }
}

impl std::ops::Add for Sums {
    type Output = Sums;

    fn add(self, o: Sums) -> Sums {
        Sums {
            rgb: self.rgb + o.rgb,
            weight: self.weight + o.weight,
            transmittance: self.transmittance + o.transmittance,
        }
    }
}

impl<'a> GaussianPiece<'a> {
    /// The piece from `a` of the profiles `active`, their anchors worked out into `anchors`.
    pub(super) fn new(
        a: f64,
        profiles: &'a [Profile],
        colours: &'a [DVec3],
        active: &'a [u32],
        anchors: &'a mut Vec<Anchor>,
    ) -> Self {
        anchors.clear();
        anchors.extend(
            active
                .iter()
                .map(|&h| profiles[h as usize].density.anchor(a)),
        );
        Self::anchored(a, profiles, colours, active, anchors)
    }

    /// The piece from `a` of the profiles `active`, whose anchors at `a` are `anchors`.
    pub(super) fn anchored(
        a: f64,
        profiles: &'a [Profile],
        colours: &'a [DVec3],
        active: &'a [u32],
        anchors: &'a [Anchor],
    ) -> Self {
        GaussianPiece {
            a,
            profiles,
            colours,
            active,
            anchors,
        }
    }

    fn each(&self) -> impl Iterator<Item = (&Profile, DVec3)> + '_ {
        self.active
            .iter()
            .map(|&h| (&self.profiles[h as usize], self.colours[h as usize]))
    }

    /// The density, its colour sum `Σσᵢcᵢ` and the optical depth from `a`, at `t`.
    /// `rough` as in [`Density::sample_from`].
    #[inline]
    fn sample(&self, t: f64, rough: bool) -> (f64, DVec3, f64) {
        let (mut sigma, mut rgb, mut depth) = (0.0, DVec3::ZERO, 0.0);
        for ((p, c), anchor) in self.each().zip(self.anchors) {
            let (s, d, _) = p.density.sample_from(anchor, self.a, t, rough);
            sigma += s;
            rgb += s * c;
            depth += d;
        }
        (sigma, rgb, depth)
    }

    /// What the closed forms of the piece `[a, b]` take ([`Whole`]).
    fn whole(&self, b: f64) -> Whole {
        let mut whole = Whole::default();
        for ((p, c), anchor) in self.each().zip(self.anchors) {
            let (at_b, d, i) = p.density.sample_from(anchor, self.a, b, false);
            let [least, greatest] = p.density.range(anchor, self.a, b, at_b);
            whole.at_b += at_b;
            whole.tau += d;
            whole.rgb_tau += d * c;
            whole.integral += i;
            whole.least += least;
            whole.greatest += greatest;
        }
        whole
    }

    /// The piece's [`Integral`]. The optical depth and weight are exact, and so is the
    /// colour of a profile alone. The rest is taken in closed form where bounds on it
    /// (below) are within what it is held to: the colour split within [`COLOUR_SHARE`] of the
    /// error target (any split is off by at most the spread of the profiles' colours), the
    /// moment (asked for with `depth`) within [`DEPTH_SHARE`] of the target times `a` (the
    /// mean depth inside the piece lies between `a` and `b`, so its middle is off by at most
    /// half its length). Elsewhere it comes from [`quadrature`](Self::quadrature), held to
    /// the target.
    pub(super) fn integrate(
        &self,
        b: f64,
        error_target: f32,
        depth: bool,
        budget: &mut Budget,
        panels: &mut Vec<(f64, f64, Sums)>,
    ) -> Integral {
        let Whole {
            at_b,
            tau,
            rgb_tau,
            integral,
            least,
            greatest,
        } = self.whole(b);
        let w = opacity(tau);
        if w.is_nan() || w <= 0.0 {
            return Integral {
                optical_depth: tau,
                ..Integral::default()
            };
        }
        let target = f64::from(error_target);
        let middle = 0.5 * (self.a + b);
        let spread = self.spread();
        let moment = depth && b - middle > DEPTH_SHARE * target * self.a;
        // The closed forms. The colour split is the profiles' optical depths' ratio, a share
        // of the weight within the range of each one's share of the density over the piece,
        // `[σᵢ⁻/σ⁺, σᵢ⁺/σ⁻]` (`σ⁻`, `σ⁺` the least and greatest total): with every colour
        // within `spread/2` of the middle one, the colour is within
        // `spread/2·Σᵢ(σᵢ⁺/σ⁻ − σᵢ⁻/σ⁺) = spread/2·(σ⁺/σ⁻ − σ⁻/σ⁺)`. In a thin piece `T` lies
        // in `[e^{−τ}, 1]`, which puts each share within a factor `e^{±τ}` of that ratio and
        // the colour within `spread·(e^τ − 1)/2`. The piece's `∫ₐᵇ T dt` lies in
        // `[w/σ⁺, w/σ⁻]` (as `w = ∫σT dt`), in `[ℓ·e^{−τ}, ℓ]`, and in
        // `[ℓ − I, ℓ − I + τ·I/2]` (`I = ∫τ dt`, as `1 − x ≤ e^{−x} ≤ 1 − x + x·τ/2` for
        // `x ≤ τ`): the middle of where they meet is off by half its width. The first bounds
        // serve a piece whose density changes little (a faint blob inside a dense box), the
        // last a thin one; a Gaussian alone has a closer one ([`lone_transmittance`]). Each
        // is taken where it is within what it is held to.
        //
        // [`lone_transmittance`]: Self::lone_transmittance
        let split = spread > COLOUR_SHARE * target && {
            let shares = (greatest / least - least / greatest).min(tau.exp_m1());
            spread * (0.5 * shares).min(1.0) > COLOUR_SHARE * target
        };
        let length = b - self.a;
        let mut lowest = (w / greatest)
            .max(length * (1.0 - w))
            .max(length - integral);
        let mut highest = (w / least)
            .min(length)
            .min(length - integral + 0.5 * tau * integral);
        let tolerance = 2.0 * DEPTH_SHARE * target * w * self.a;
        if moment && highest - lowest > tolerance {
            if let Some((estimate, off)) = self.lone_transmittance(b, (at_b, tau, integral)) {
                lowest = lowest.max(estimate - off);
                highest = highest.min(estimate + off);
            }
        }
        let quadrature_moment = moment && highest - lowest > tolerance;
        // The colours weighed by the profiles' optical depths: any mean of them is within
        // their spread, and this one is the one the bounds above are about.
        let mix = rgb_tau / tau;
        let by_parts = |transmittance: f64, end: f64| {
            let by_parts = transmittance - (end - self.a) * (1.0 - w);
            self.a * w + by_parts.clamp(0.0, length * w)
        };
        let closed = |colour: DVec3| {
            let moment = if moment {
                by_parts(0.5 * (lowest + highest), b)
            } else {
                w * middle
            };
            Integral {
                optical_depth: tau,
                weight: w,
                colour: w * colour,
                moment,
            }
        };
        if !split && !quadrature_moment {
            return closed(mix);
        }
        // Where the optical depth passes `cut`, 1e-3 of the target is left. A piece far
        // more opaque than that (σ of 1e9) is integrated up to there only: its light comes
        // from a sliver at its start, which panels over the whole piece could all miss.
        let cut = (1e3 / target).ln();
        let end = if tau > OPAQUE * cut {
            self.depth_reaching(cut, b, tau, 1e-2 * (b - self.a), budget)
        } else {
            b
        };
        // Rough error functions at the nodes where what they can be off by (a relative error
        // `δ` in every `T`: `δ` in the weight and colour, twice that in the colour scaled to
        // the exact weight, `δ·ℓ` in `∫T dt`) is within a hundredth of the tolerances below,
        // which the panels are then held to the rest of.
        let delta = self
            .each()
            .map(|(p, _)| p.density.rough_depth_error())
            .sum::<f64>()
            .exp_m1();
        let brightest = self.each().fold(1.0f64, |m, (_, c)| m.max(c.max_element()));
        let rough = 2.0 * delta * brightest <= 0.01 * target
            && delta * length <= 0.01 * DEPTH_SHARE * target * w * self.a;
        let tolerance = if rough { 0.99 } else { 1.0 } * target * w;
        let asks = Asks {
            colour: split,
            depth: quadrature_moment,
            rough,
        };
        let sums = self.quadrature(end, tolerance, asks, budget, panels);
        // Scaled to the exact weight; every node underflowing (the budget ran out at once)
        // leaves the middle's colour.
        let colour = if split && sums.weight > 0.0 {
            (w / sums.weight) * sums.rgb
        } else {
            w * mix
        };
        // By parts, from `T` alone (which falls smoothly from 1, where `σT` may be a sharp
        // bell); past `end` the light left is taken at `end`.
        let moment = if quadrature_moment {
            by_parts(sums.transmittance, end)
        } else {
            closed(DVec3::ZERO).moment
        };
        Integral {
            optical_depth: tau,
            weight: w,
            colour,
            moment,
        }
    }

    /// `∫ₐᵇ T dt` of a piece that holds one Gaussian alone, and how far off it can be; `None`
    /// for any other piece. On each side of the blob's centre the optical depth `τ` is
    /// monotone, within `h` of the middle `m` of its values at the side's ends: there
    /// `e^{−τ} = e^{−m}·(1 − δ + δ²/2)` (`δ = τ − m`) up to `e^{−m}·h³·e^h/6`, and the
    /// integrals of `τ` and `τ²` are closed forms ([`Density::squared_depth_integral`]): a
    /// few error functions per side, where panels over the same piece take fourteen nodes.
    /// `end` is the density, optical depth and its integral at `b`, which
    /// [`whole`](Self::whole) worked out.
    fn lone_transmittance(&self, b: f64, end: (f64, f64, f64)) -> Option<(f64, f64)> {
        let ([h], [anchor]) = (self.active, self.anchors) else {
            return None;
        };
        let density = self.profiles[*h as usize].density;
        let Density::Gaussian { centre, .. } = density else {
            return None;
        };
        let sides = if centre > self.a && centre < b {
            [centre, b]
        } else {
            [b, b]
        };
        // At the start of the side: where, the optical depth and its and its square's
        // integrals from `a`.
        let mut from = (self.a, 0.0, 0.0, 0.0);
        let (mut sum, mut off) = (0.0, 0.0);
        let start = density.squared_depth_start(anchor);
        for t in sides {
            if t <= from.0 {
                continue;
            }
            let (sigma, tau, integral) = if t == b {
                end
            } else {
                density.sample_from(anchor, self.a, t, false)
            };
            let to = (
                t,
                tau,
                integral,
                density.squared_depth_integral((anchor, start), self.a, t, (sigma, tau)),
            );
            let (length, first, second) = (t - from.0, to.2 - from.2, to.3 - from.3);
            let (m, h) = (0.5 * (to.1 + from.1), 0.5 * (to.1 - from.1));
            let bell = (-m).exp();
            // ∫δ = ∫τ − m·ℓ and ∫δ² = ∫τ² − 2m∫τ + m²ℓ.
            let delta = first - m * length;
            let delta_squared = second - 2.0 * m * first + m * m * length;
            sum += bell * (length - delta + 0.5 * delta_squared);
            off += bell * length * h.powi(3) * exp_above(h) / 6.0;
            from = to;
        }
        Some((sum, off))
    }

    /// The largest difference between the piece's profiles' colours in any channel (0 for
    /// one profile alone).
    fn spread(&self) -> f64 {
        let (lo, hi) = self.each().fold(
            (DVec3::INFINITY, DVec3::NEG_INFINITY),
            |(lo, hi), (_, c)| (lo.min(c), hi.max(c)),
        );
        (hi - lo).max_element()
    }

    /// The integrands at `t`, with `T` from the closed-form optical depth.
    #[inline]
    fn node(&self, t: f64, rough: bool) -> Sums {
        let (sigma, rgb, depth) = self.sample(t, rough);
        let transmittance = (-depth).exp();
        let weight = transmittance * sigma;
        Sums {
            rgb: transmittance * rgb,
            weight,
            transmittance,
        }
    }

    /// The 3- and 4-point Gauss–Legendre sums over `[p, q]`.
    fn panel(&self, p: f64, q: f64, rough: bool) -> (Sums, Sums) {
        let (mid, half) = (0.5 * (p + q), 0.5 * (q - p));
        let rule = |nodes: &[f64], weights: &[f64]| {
            let mut sum = Sums::default();
            for (x, &w) in nodes.iter().zip(weights) {
                sum = sum + self.node(mid + half * x, rough).scaled(w);
            }
            sum.scaled(half)
        };
        (rule(&GAUSS_3.0, &GAUSS_3.1), rule(&GAUSS_4.0, &GAUSS_4.1))
    }

    /// The piece's [`Sums`] over `[a, end]` by adaptive Gauss–Legendre panels: a panel's
    /// 4-point sum is taken once it differs from its 3-point sum by at most the panel's
    /// share (by length) of `tolerance` in the weight and every colour channel (when
    /// `colour` is asked for), and of `DEPTH_SHARE·tolerance·a` in `∫T dt` (when `depth`
    /// is); else the panel is bisected. That difference bounds the error of the 3-point sum
    /// (exact to degree 5), far above the 4-point one's (degree 7), so the colour the piece
    /// adds is off by at most `tolerance` (its weight times the error target: over the ray,
    /// at most the target) and its moment by its weight times [`DEPTH_SHARE`] of the target
    /// times `a` (over the ray, as `Σ wᵢaᵢ` is at most the alpha times the expected depth,
    /// that depth by at most that share of the target, relative). A panel bisected
    /// [`MAX_BISECTIONS`] times, or the ray's node budget spent, is taken as it is (the
    /// latter marks the ray budget-limited). With `rough` nodes (the caller leaves room for
    /// what they are off by) the optical depths come from rough error functions.
    fn quadrature(
        &self,
        end: f64,
        tolerance: f64,
        Asks {
            colour,
            depth,
            rough,
        }: Asks,
        budget: &mut Budget,
        panels: &mut Vec<(f64, f64, Sums)>,
    ) -> Sums {
        let length = end - self.a;
        let finest = length * 0.5f64.powi(MAX_BISECTIONS as i32);
        panels.clear();
        // A blob's peak inside the piece starts a panel: each side of it is a half bell.
        let mut from = self.a;
        for (p, _) in self.each() {
            if let Density::Gaussian { centre, .. } = p.density {
                if centre > from && centre < end {
                    panels.push((from, centre, Sums::default()));
                    from = centre;
                }
            }
        }
        panels.push((from, end, Sums::default()));
        let mut total = Sums::default();
        while let Some((p, q, coarse)) = panels.pop() {
            if !budget.take(7) {
                budget.exhausted = true;
                total = total + coarse;
                continue;
            }
            let (three, four) = self.panel(p, q, rough);
            let share = (q - p) / length;
            let colour_ok =
                !colour || (four.rgb - three.rgb).abs().max_element() <= tolerance * share;
            // The weight sets the scale of the colour (`integrate`).
            let weight_ok = !colour || (four.weight - three.weight).abs() <= tolerance * share;
            let moment_ok = !depth
                || (four.transmittance - three.transmittance).abs()
                    <= DEPTH_SHARE * tolerance * self.a * share;
            if (colour_ok && weight_ok && moment_ok) || q - p <= finest {
                total = total + four;
            } else {
                let m = 0.5 * (p + q);
                // A half that finds no budget left falls back on half the panel's sum.
                let half = four.scaled(0.5);
                panels.push((p, m, half));
                panels.push((m, q, half));
            }
        }
        total
    }

    /// Where in `[a, b]` the optical depth from `a` reaches `depth` (`b` if it does not;
    /// `total` is the piece's), to within `resolution`: Newton steps on the closed-form
    /// optical depth, kept inside a bracket that each step narrows, bisecting where a step
    /// would leave it or would not halve the one before (a Newton step can bounce between the
    /// two sides of a density's sharp rise).
    ///
    /// A step is the last one where its own size bounds what its end is off by within the
    /// resolution: `f = τ − depth` has `f′ = σ ≥ m` (the constants' density) and
    /// `|f″| = |σ′| ≤ M` (`peak/(width·√e)` per Gaussian), so a Newton step of size `s` ends
    /// where `|f| ≤ M·s²/2`, within `M·s²/2m` of the root: in a piece a constant density
    /// dominates, after one step from the linear guess.
    pub(super) fn depth_reaching(
        &self,
        depth: f64,
        b: f64,
        total: f64,
        resolution: f64,
        budget: &mut Budget,
    ) -> f64 {
        if total.is_nan() || total <= depth {
            return b;
        }
        let (least, bend) = self
            .each()
            .fold((0.0, 0.0), |(m, big_m), (p, _)| match p.density {
                Density::Constant(k) => (m + k, big_m),
                Density::Gaussian { peak, width, .. } => {
                    (m, big_m + peak / (width * std::f64::consts::E.sqrt()))
                }
            });
        let settled = |step: f64| bend * step * step <= 2.0 * least * resolution;
        let (mut lo, mut hi) = (self.a, b);
        let mut t = self.a + (b - self.a) * (depth / total);
        let mut step = hi - lo;
        for _ in 0..MAX_NEWTON_STEPS {
            if !budget.take(1) {
                budget.exhausted = true;
                break;
            }
            let (sigma, _, reached) = self.sample(t, false);
            let f = reached - depth;
            if f == 0.0 {
                return t;
            }
            if f < 0.0 {
                lo = t;
            } else {
                hi = t;
            }
            let newton = t - f / sigma;
            let step_before = std::mem::replace(&mut step, (newton - t).abs());
            // A step within the resolution is the answer, also where it rounds onto the end
            // of the bracket (which bisecting the bracket down to it would not be faster).
            if step <= resolution || settled(step) {
                return newton.clamp(lo, hi);
            }
            let next = if newton > lo && newton < hi && 2.0 * step <= step_before {
                newton
            } else {
                step = 0.5 * (hi - lo);
                lo + step
            };
            if step <= resolution {
                return next;
            }
            t = next;
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Above `e^h` up to 1 (where it takes no exponential), within 2.002 % of it, and `e^h`
    /// beyond; its curvature is `e − 2` rounded up (below it, the bound falls under `e^h`
    /// at 1).
    #[test]
    fn exp_above_bounds_the_exponential() {
        for i in 0..=1000 {
            let h = f64::from(i) * 1e-3;
            let (bound, e) = (exp_above(h), h.exp());
            assert!(bound >= e && bound <= 1.020_02 * e, "{h}: {bound} vs {e}");
            // Still above it where rounding makes the optical depth fall a little.
            assert!(exp_above(-h) >= (-h).exp(), "{}", -h);
        }
        assert_eq!(exp_above(1.5), 1.5f64.exp());
        let e_minus_two = std::f64::consts::E - 2.0;
        assert!(E_MINUS_TWO_ABOVE >= e_minus_two && E_MINUS_TWO_ABOVE - e_minus_two < 1e-7);
    }
}
