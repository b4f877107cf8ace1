//! An analytic field's primitives along a ray as density *profiles* in world distance: where
//! each one's support begins and ends, and its density between, constant (spheres, boxes) or a
//! 1-D Gaussian (blobs), with its optical depth over any interval in closed form.
//!
//! The ray is the field-space line `p(t) = o + (t − t₀)·v`, `t` in world units, where the
//! velocity `v` is the unit field direction times the field units per world unit `k = |v|`;
//! intersections come out directly in world `t`, also under a non-uniform scale. A density
//! `ρ` per field unit is `k·ρ` per world unit. A Gaussian blob of centre `c` and standard
//! deviation `s`, with `t*` the line's closest approach to `c` and `b` its distance there,
//! has `|p(t) − c|² = k²(t − t*)² + b²`, so along the line it is `kρ·e^{−b²/2s²}` times a
//! Gaussian in `t` of width `s/k` about `t*`.

use std::f64::consts::{FRAC_1_SQRT_2, PI, SQRT_2};

use super::erf::{erf, erfcx, rough_erfcx, small_erf, ROUGH_ERFC_ERROR};
use super::spans::{interval, Line};
use super::{Analytic, Shape};

/// One primitive's density along a ray: its support `[enter, exit]` (world distances) and
/// its profile there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Profile {
    /// The primitive's index in [`Analytic::primitives`].
    pub(crate) index: u32,
    /// Where the ray enters its support.
    pub(crate) enter: f64,
    /// Where it leaves it.
    pub(crate) exit: f64,
    /// Its density per world unit inside the support.
    pub density: Density,
}

/// A density per world unit along a ray, as a function of world distance `t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Density {
    /// The same everywhere.
    Constant(f64),
    /// `peak·exp(−(t − centre)²/(2·width²))`.
    Gaussian {
        /// The density at `centre`.
        peak: f64,
        /// Where along the ray the blob's centre is closest.
        centre: f64,
        /// Standard deviation in world units.
        width: f64,
    },
}

impl Density {
    /// What [`sample_from`](Self::sample_from) needs of the start `a` of the
    /// intervals it is asked for: one error function, so that each end `t` then costs one.
    #[inline]
    pub(crate) fn anchor(&self, a: f64) -> Anchor {
        match *self {
            Density::Constant(_) => Anchor::default(),
            Density::Gaussian { centre, width, .. } => {
                let z = (a - centre) * (FRAC_1_SQRT_2 / width);
                let bell = (-z * z).exp();
                let [erf, erfc] = erf_pair(z.abs(), bell);
                Anchor { z, erf, erfc, bell }
            }
        }
    }

    /// The density at `t`, the optical depth `τ(t) = ∫ₐᵗ σ ds` from the point `a` that
    /// `anchor` was taken at (`a ≤ t`), and its integral `∫ₐᵗ τ ds = ∫ₐᵗ (t − s)·σ(s) ds`.
    ///
    /// A Gaussian's optical depth is `peak·width·√(π/2)·(erf(z_t) − erf(z_a))`,
    /// `z = (t − centre)/(√2·width)`, taken as a difference of `erfc`s where both ends lie on
    /// one side of the centre, so that it keeps its relative precision far out in the tails
    /// (where both `erf`s round to ±1); one exponential `e^{−z_t²}` serves the density and
    /// `erfc(|z_t|) = e^{−z_t²}·erfcx(|z_t|)`. Peak 2 and width 0.5 over the whole line:
    /// `2·0.5·√(2π) = 2.5066…`. The integral of the optical depth is
    /// `(t − centre)·τ(t) − ∫ₐᵗ (s − centre)·σ(s) ds`, the latter
    /// `peak·width²·(e^{−z_a²} − e^{−z_t²})`: closed form too.
    ///
    /// `rough` takes `erfcx(|z_t|)` from a five-term rational fit ([`rough_erfcx`]) instead:
    /// the optical depth is then off by at most [`rough_depth_error`](Self::rough_depth_error).
    #[inline]
    pub(crate) fn sample_from(
        &self,
        anchor: &Anchor,
        a: f64,
        t: f64,
        rough: bool,
    ) -> (f64, f64, f64) {
        match *self {
            Density::Constant(k) => (k, k * (t - a), 0.5 * k * (t - a) * (t - a)),
            Density::Gaussian {
                peak,
                centre,
                width,
            } => {
                let zt = (t - centre) * (FRAC_1_SQRT_2 / width);
                let e = (-zt * zt).exp();
                let erfcx = if rough {
                    rough_erfcx(zt.abs())
                } else {
                    erfcx(zt.abs())
                };
                let erfc = e * erfcx;
                let difference = if anchor.z >= 0.0 {
                    anchor.erfc - erfc
                } else if zt <= 0.0 {
                    erfc - anchor.erfc
                } else {
                    (1.0 - erfc) + anchor.erf
                };
                let depth = peak * width * (0.5 * PI).sqrt() * difference.max(0.0);
                let integral = (t - centre) * depth - peak * width * width * (anchor.bell - e);
                (peak * e, depth, integral.max(0.0))
            }
        }
    }

    /// The integral of the squared optical depth from the point `a` that `anchor` was taken
    /// at, `∫ₐᵗ τ(s)² ds`. A constant's is `k²(t − a)³/3`. A Gaussian's optical depth is
    /// `A·(erf z − erf z_a)`, `A = peak·width·√(π/2)`, so this is `A²·√2·width` times
    /// `∫(erf z − erf z_a)² dz`, which `∫erf = z·erf + e^{−z²}/√π` and
    /// `∫erf² = z·erf² + (2/√π)·e^{−z²}·erf − √(2/π)·erf(√2·z)` give as
    /// `z_t·Δ² + (2/√π)·e^{−z_t²}·Δ − √(2/π)·(erf(√2·z_t) − erf(√2·z_a))`, `Δ = erf z_t − erf z_a`.
    /// Its terms cancel where both ends lie far in one tail: it is good to about 1e-15 of
    /// `A²·width·(|z_t| + 1)`, absolutely, not relatively. `(sigma, depth)` are the density
    /// and optical depth at `t` that [`sample_from`](Self::sample_from) gave, and `start`
    /// what [`squared_depth_start`](Self::squared_depth_start) gave for `anchor`, which it
    /// takes rather than works out again.
    pub(crate) fn squared_depth_integral(
        &self,
        (anchor, start): (&Anchor, f64),
        a: f64,
        t: f64,
        (sigma, depth): (f64, f64),
    ) -> f64 {
        match *self {
            Density::Constant(k) => k * k * (t - a).powi(3) / 3.0,
            Density::Gaussian { peak, width, .. } => {
                let scale = peak * width * (0.5 * PI).sqrt();
                let zt = anchor.z + (t - a) * (FRAC_1_SQRT_2 / width);
                let difference = depth / scale;
                let bell = sigma / peak;
                let h = erf(SQRT_2 * zt) - start;
                let z_integral = zt * difference * difference + 2.0 / PI.sqrt() * bell * difference
                    - (2.0 / PI).sqrt() * h;
                scale * scale * SQRT_2 * width * z_integral.max(0.0)
            }
        }
    }

    /// The error function [`squared_depth_integral`](Self::squared_depth_integral) takes
    /// at the point `anchor` was taken at, `erf(√2·z_a)` (0 for a constant), for any number
    /// of ends.
    pub(crate) fn squared_depth_start(&self, anchor: &Anchor) -> f64 {
        match *self {
            Density::Constant(_) => 0.0,
            Density::Gaussian { .. } => erf(SQRT_2 * anchor.z),
        }
    }

    /// The least and greatest density over `[a, b]`, given the anchor at `a` and the density
    /// at `b` ([`sample_from`](Self::sample_from) gives it): a Gaussian's least is at one
    /// end, its greatest at its centre where that lies inside, else at the other end.
    pub fn range(&self, anchor: &Anchor, a: f64, b: f64, at_b: f64) -> [f64; 2] {
        match *self {
            Density::Constant(k) => [k, k],
            Density::Gaussian { peak, centre, .. } => {
                let at_a = peak * anchor.bell;
                let highest = if centre > a && centre < b {
                    peak
                } else {
                    at_a.max(at_b)
                };
                [at_a.min(at_b), highest]
            }
        }
    }

    /// How far the optical depth a `rough` [`sample_from`](Self::sample_from) gives can be
    /// from the exact one: its `erfc` at `t` is off by at most [`ROUGH_ERFC_ERROR`], times
    /// `peak·width·√(π/2)`; 0 for a constant.
    pub(crate) fn rough_depth_error(&self) -> f64 {
        match *self {
            Density::Constant(_) => 0.0,
            Density::Gaussian { peak, width, .. } => {
                peak * width * (0.5 * PI).sqrt() * ROUGH_ERFC_ERROR
            }
        }
    }
}

/// A Gaussian's error functions at the start of an interval of the ray: `erf` and `erfc` of
/// `|z|`, and its bell `e^{−z²}` ([`Density::anchor`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Anchor {
    z: f64,
    erf: f64,
    erfc: f64,
    bell: f64,
}

/// `[erf(x), erfc(x)]` for `x ≥ 0` and its bell `e^{−x²}`, from one error function: the
/// smaller of the two is computed (`erf` below ½, `erfc = e^{−x²}·erfcx(x)` above), the other
/// is 1 minus it, above ½ either way so exact to rounding.
#[inline]
fn erf_pair(x: f64, bell: f64) -> [f64; 2] {
    if x < 0.5 {
        let erf = small_erf(x);
        [erf, 1.0 - erf]
    } else {
        let erfc = bell * erfcx(x);
        [1.0 - erfc, erfc]
    }
}

impl Analytic {
    /// Appends to `out` the profiles of the primitives `indices` names (those of density > 0
    /// whose support the ray meets for a length > 0) along the field-space line `line`,
    /// `t ∈ [t_near, t_far]` in world units, `units_per_world` its speed `|velocity|` (see
    /// the module docs). The intervals are worked out from the line's point at `t_near`, so
    /// that they keep their precision however far the line's origin is.
    pub(crate) fn profiles(
        &self,
        line: &Line,
        units_per_world: f64,
        [t_near, t_far]: [f64; 2],
        indices: impl Iterator<Item = u32>,
        out: &mut Vec<Profile>,
    ) {
        let line = line.moved(t_near);
        let origin = line.origin();
        for index in indices {
            let Some(p) = (self.primitives.get(index as usize)).filter(|p| p.density > 0.0) else {
                continue;
            };
            let Some([enter, exit]) = interval(p, &line, 0.0, t_far - t_near) else {
                continue;
            };
            let k = f64::from(p.density) * units_per_world;
            let density = match p.shape {
                Shape::Sphere { .. } | Shape::Box { .. } => Density::Constant(k),
                Shape::Gaussian { center, sigma, .. } => {
                    let closest = line.closest(center);
                    let miss2 =
                        (center.as_dvec3() - origin - closest * line.velocity()).length_squared();
                    let s = f64::from(sigma);
                    Density::Gaussian {
                        peak: k * (-0.5 * miss2 / (s * s)).exp(),
                        centre: t_near + closest,
                        width: s / units_per_world,
                    }
                }
            };
            out.push(Profile {
                index,
                enter: t_near + enter,
                exit: t_near + exit,
                density,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use super::*;
    use crate::field::{Field, Primitive};

    impl Density {
        fn optical_depth(&self, a: f64, b: f64) -> f64 {
            self.sample_from(&self.anchor(a), a, b, false).1
        }

        fn depth_integral(&self, a: f64, b: f64) -> f64 {
            self.sample_from(&self.anchor(a), a, b, false).2
        }

        fn at(&self, t: f64) -> f64 {
            self.sample_from(&self.anchor(t), t, t, false).0
        }
    }

    /// The Gaussian the tests integrate: peak 2, centre 1, width ½.
    const BLOB: Density = Density::Gaussian {
        peak: 2.0,
        centre: 1.0,
        width: 0.5,
    };

    /// `∫ₐᵇ f` by the midpoint rule over `n` slices.
    fn midpoint_sum(a: f64, b: f64, n: u32, f: impl Fn(f64) -> f64) -> f64 {
        let h = (b - a) / f64::from(n);
        let sum: f64 = (0..n).map(|i| f(a + (f64::from(i) + 0.5) * h)).sum();
        sum * h
    }

    /// Optical depths against a midpoint sum of the density (200 000 slices).
    #[test]
    fn optical_depth_matches_a_sum_of_the_density_and_keeps_the_tails() {
        let g = BLOB;
        for (a, b) in [(-3.0, 5.0), (0.2, 0.9), (1.0, 1.7), (0.5, 2.5), (2.0, 2.1)] {
            let want = midpoint_sum(a, b, 200_000, |t| g.at(t));
            let got = g.optical_depth(a, b);
            assert!((got - want).abs() < 1e-9 * want, "{a} {b}: {got} vs {want}");
        }
        let whole = 2.0 * 0.5 * (2.0 * PI).sqrt();
        assert!((g.optical_depth(-1e3, 1e3) - whole).abs() < 1e-14);
        // 12 widths out on either side: ~e^{-72}, still to full relative precision.
        let far = g.optical_depth(7.0, 8.0);
        let mirrored = g.optical_depth(-6.0, -5.0);
        assert!(
            far > 0.0 && (far - mirrored).abs() < 1e-12 * far,
            "{far} {mirrored}"
        );
        assert_eq!(Density::Constant(3.0).optical_depth(1.0, 1.5), 1.5);
    }

    /// A Gaussian's least and greatest density over intervals on either side of its centre
    /// and across it, against a fine scan of it.
    #[test]
    fn range_holds_the_density_over_the_interval() {
        let g = BLOB;
        for (a, b) in [(-1.0, 0.5), (0.2, 1.7), (1.5, 3.0), (0.9, 1.1)] {
            let at_b = g.at(b);
            let [least, greatest] = g.range(&g.anchor(a), a, b, at_b);
            let scan: Vec<f64> = (0..=10_000)
                .map(|i| g.at(a + (b - a) * f64::from(i) / 1e4))
                .collect();
            let lo = scan.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = scan.iter().copied().fold(0.0, f64::max);
            assert!(
                (least - lo).abs() < 1e-12 && (greatest - hi).abs() < 1e-6,
                "{a} {b}"
            );
        }
        assert_eq!(
            Density::Constant(3.0).range(&Anchor::default(), 0.0, 1.0, 3.0),
            [3.0, 3.0]
        );
    }

    /// The integral of the squared optical depth against a midpoint sum of it (20 000
    /// slices), across the centre, on either side and far in a tail.
    #[test]
    fn squared_depth_integral_matches_a_sum_of_it() {
        for density in [BLOB, Density::Constant(3.0)] {
            for (a, b) in [(-3.0, 5.0), (0.2, 0.9), (1.0, 1.7), (-1.0, 1.0), (3.0, 4.0)] {
                let want = midpoint_sum(a, b, 20_000, |t| density.optical_depth(a, t).powi(2));
                let anchor = density.anchor(a);
                let (sigma, depth, _) = density.sample_from(&anchor, a, b, false);
                let start = density.squared_depth_start(&anchor);
                let got = density.squared_depth_integral((&anchor, start), a, b, (sigma, depth));
                assert!(
                    (got - want).abs() < 1e-7 * want + 1e-14,
                    "{density:?} {a} {b}: {got} vs {want}"
                );
            }
        }
    }

    /// The integral of the optical depth against a midpoint sum of it (20 000 slices).
    #[test]
    fn integral_of_the_optical_depth_matches_a_sum_of_it() {
        for density in [BLOB, Density::Constant(3.0)] {
            for (a, b) in [
                (-3.0, 5.0),
                (0.2, 0.9),
                (1.0, 1.7),
                (2.0, 2.1),
                (0.999, 1.001),
            ] {
                let want = midpoint_sum(a, b, 20_000, |t| density.optical_depth(a, t));
                let got = density.depth_integral(a, b);
                assert!(
                    (got - want).abs() < 1e-7 * want,
                    "{density:?} {a} {b}: {got} vs {want}"
                );
            }
        }
    }

    /// Profiles along a line through a scaled frame: the density they give at world `t`
    /// is the field's density at the line's point there, times the units per world unit.
    #[test]
    fn profiles_give_the_fields_density_per_world_unit() {
        let f = Analytic {
            primitives: vec![
                Primitive::white(Shape::Sphere {
                    center: Vec3::new(0.5, 0.0, 0.0),
                    radius: 0.7,
                }),
                Primitive {
                    density: 3.0,
                    ..Primitive::white(Shape::Gaussian {
                        center: Vec3::new(0.2, 0.3, -0.1),
                        sigma: 0.4,
                        cutoff: 4.0,
                    })
                },
                Primitive::white(Shape::Box {
                    min: Vec3::new(-1.0, -0.2, -0.2),
                    max: Vec3::new(-0.5, 0.2, 0.2),
                }),
            ],
        };
        let origin = DVec3::new(-2.0, 0.05, 0.02);
        let velocity = DVec3::new(1.0, 0.01, -0.02).normalize() * 2.5;
        let (t_near, t_far) = (10.0, 12.0);
        let line = Line::new(origin - t_near * velocity, velocity);
        let mut out = Vec::new();
        f.profiles(&line, velocity.length(), [t_near, t_far], 0..3, &mut out);
        assert_eq!(out.len(), 3, "{out:?}");
        for i in 0..=400 {
            let t = t_near + (t_far - t_near) * f64::from(i) / 400.0;
            let p = (origin + (t - t_near) * velocity).as_vec3();
            let mut want = [0.0];
            f.density(&[p], &mut want);
            let got: f64 = out
                .iter()
                .filter(|pr| pr.enter < t && t < pr.exit)
                .map(|pr| pr.density.at(t))
                .sum();
            let want = 2.5 * f64::from(want[0]);
            assert!(
                (got - want).abs() < 1e-5 * want.max(1.0),
                "t {t}: {got} vs {want}"
            );
        }
    }
}
