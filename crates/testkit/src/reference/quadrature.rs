//! Globally adaptive Gauss–Kronrod (7/15-point) quadrature of a vector-valued integrand.
//!
//! The reference integrator needs it only on pieces of ray where a Gaussian blob is active
//! (colour and depth have no closed form there). Each interval is integrated with the
//! 15-point Kronrod rule (exact for polynomials of degree 22); `|K15 − G7|`, a pessimistic
//! bound on the Kronrod rule's error, drives the refinement: the interval with the largest
//! error is halved until the errors sum below the tolerance.

use glam::DVec4;

/// Kronrod abscissae on [−1, 1] (the non-negative half; odd indices are the Gauss nodes).
const KRONROD_NODES: [f64; 8] = [
    0.9914553711208126,
    0.9491079123427585,
    0.8648644233597691,
    0.7415311855993945,
    0.5860872354676911,
    0.4058451513773972,
    0.20778495500789848,
    0.0,
];

/// Kronrod weights, matching [`KRONROD_NODES`].
const KRONROD_WEIGHTS: [f64; 8] = [
    0.022935322010529224,
    0.06309209262997856,
    0.10479001032225019,
    0.14065325971552592,
    0.1690047266392679,
    0.19035057806478542,
    0.20443294007529889,
    0.20948214108472782,
];

/// 7-point Gauss weights for the nodes `KRONROD_NODES[1, 3, 5, 7]`.
const GAUSS_WEIGHTS: [f64; 4] = [
    0.1294849661688697,
    0.27970539148927664,
    0.3818300505051189,
    0.4179591836734694,
];

/// At most this many intervals; past it the best estimate so far is returned (it is only
/// reached by integrands far rougher than a sum of Gaussians and exponentials).
const MAX_INTERVALS: usize = 400;

/// One interval of the adaptive partition.
#[derive(Clone, Copy, Debug)]
struct Interval {
    a: f64,
    b: f64,
    value: DVec4,
    /// `max_i |K15 − G7|_i / tolerance_i`.
    error: f64,
}

/// Reusable scratch for [`Quadrature::integrate`] (no allocation per call once warm).
#[derive(Debug, Default)]
pub(crate) struct Quadrature {
    intervals: Vec<Interval>,
}

impl Quadrature {
    /// `∫ₐᵇ f(t) dt`, each component to within about `tolerance` (absolute, per component;
    /// a zero tolerance is treated as the smallest positive one).
    pub(crate) fn integrate(
        &mut self,
        mut f: impl FnMut(f64) -> DVec4,
        a: f64,
        b: f64,
        tolerance: DVec4,
    ) -> DVec4 {
        let tolerance = tolerance.max(DVec4::splat(f64::MIN_POSITIVE));
        self.intervals.clear();
        self.intervals.push(kronrod(&mut f, a, b, tolerance));
        while self.intervals.len() < MAX_INTERVALS {
            let total: f64 = self.intervals.iter().map(|i| i.error).sum();
            if total <= 1.0 {
                break;
            }
            let (worst, _) =
                self.intervals
                    .iter()
                    .enumerate()
                    .fold((0, f64::NEG_INFINITY), |best, (k, i)| {
                        if i.error > best.1 {
                            (k, i.error)
                        } else {
                            best
                        }
                    });
            let Interval { a, b, .. } = self.intervals[worst];
            let mid = 0.5 * (a + b);
            if !(a < mid && mid < b) {
                // Cannot split further in f64: accept what there is.
                self.intervals[worst].error = 0.0;
                continue;
            }
            self.intervals[worst] = kronrod(&mut f, a, mid, tolerance);
            self.intervals.push(kronrod(&mut f, mid, b, tolerance));
        }
        self.intervals.iter().map(|i| i.value).sum()
    }
}

/// The 15-point Kronrod estimate on `[a, b]` and its normalised error against the 7-point
/// Gauss estimate from the same evaluations.
fn kronrod(f: &mut impl FnMut(f64) -> DVec4, a: f64, b: f64, tolerance: DVec4) -> Interval {
    let centre = 0.5 * (a + b);
    let half = 0.5 * (b - a);
    let mut kronrod = DVec4::ZERO;
    let mut gauss = DVec4::ZERO;
    for (k, (&x, &w)) in KRONROD_NODES.iter().zip(&KRONROD_WEIGHTS).enumerate() {
        let pair = if x == 0.0 {
            f(centre)
        } else {
            f(centre - half * x) + f(centre + half * x)
        };
        kronrod += w * pair;
        if k % 2 == 1 {
            gauss += GAUSS_WEIGHTS[k / 2] * pair;
        }
    }
    let value = kronrod * half;
    let difference = (value - gauss * half).abs() / tolerance;
    Interval {
        a,
        b,
        value,
        error: difference.max_element(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kronrod_is_exact_to_degree_22_and_gauss_to_degree_13() {
        // ∫₋₁¹ x^p dx = 2/(p+1) for even p, 0 for odd p.
        let tol = DVec4::splat(1.0);
        for p in 0..=22 {
            let exact = if p % 2 == 0 {
                2.0 / (p + 1) as f64
            } else {
                0.0
            };
            let mut f = |t: f64| DVec4::splat(t.powi(p));
            let i = kronrod(&mut f, -1.0, 1.0, tol);
            assert!(
                (i.value.x - exact).abs() < 1e-15,
                "K15 degree {p}: {}",
                i.value.x
            );
            // K15 − G7 vanishes exactly where G7 is exact too.
            if p <= 13 {
                assert!(i.error < 1e-15, "G7 degree {p}: {}", i.error);
            }
        }
        // Degree 14 is where G7 stops being exact: the estimate must notice.
        let mut f = |t: f64| DVec4::splat(t.powi(14));
        assert!(kronrod(&mut f, -1.0, 1.0, tol).error > 1e-5);
    }

    #[test]
    fn adaptive_rule_resolves_a_narrow_peak_near_a_node() {
        // ∫₀¹⁰ e^{−(t−5.003)²/(2·0.01²)} dt = 0.01·√(2π) (the tails beyond ±300 widths
        // vanish). The peak sits by the centre node; a peak between all 15 nodes would be
        // missed by any quadrature, which is why the integrator splits at Gaussian centres.
        let width = 0.01;
        let mut q = Quadrature::default();
        let v = q.integrate(
            |t| DVec4::splat((-0.5 * ((t - 5.003) / width).powi(2)).exp()),
            0.0,
            10.0,
            DVec4::splat(1e-12),
        );
        let exact = width * (2.0 * std::f64::consts::PI).sqrt();
        assert!((v.x - exact).abs() < 1e-11, "{} vs {exact}", v.x);
    }

    #[test]
    fn components_are_integrated_independently() {
        let mut q = Quadrature::default();
        let v = q.integrate(
            |t| DVec4::new(1.0, t, t.exp(), 0.0),
            0.0,
            2.0,
            DVec4::splat(1e-13),
        );
        assert!((v.x - 2.0).abs() < 1e-13);
        assert!((v.y - 2.0).abs() < 1e-13);
        assert!((v.z - (2.0f64.exp() - 1.0)).abs() < 1e-12);
        assert_eq!(v.w, 0.0);
    }
}
