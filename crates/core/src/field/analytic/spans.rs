//! Where an analytic field's density is non-zero along a ray, in closed form.
//!
//! Each primitive's support meets a line in one interval: a sphere (and a Gaussian's cutoff
//! ball) where `|o + t·d − c|² ≤ r²`, a quadratic; a box where the ray is inside all three
//! slabs. A Gaussian's interval is cut where the ray passes closest to its centre, its peak
//! along the ray. The field's spans are the pieces of the union of those intervals between
//! consecutive interval ends: inside each piece the same primitives are present and every
//! Gaussian only rises or only falls, so the density has no jump there and no peak but the
//! slight one two overlapping Gaussians may make between their own peaks (whose curvature
//! the marcher measures between a run's inner samples and shortens its steps for, but not
//! on its first or last step), and it is constant where none of them is a Gaussian.

use glam::{DVec3, Vec3};

use super::{Primitive, Shape};
use crate::field::Span;

/// The line `o + t·d` in f64, with the reciprocals every primitive's interval needs worked
/// out once per ray: a multiplication where each primitive would divide (results move by an
/// ulp at most). An instance clips a world ray to its field's bounds with the same
/// reciprocals ([`Line::box_interval`]), and its primitives' profiles reuse them
/// ([`Line::moved`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Line {
    o: DVec3,
    d: DVec3,
    /// `1/d` per axis (infinite on an axis the line is parallel to, where it is not used).
    inv_d: DVec3,
    /// `1/|d|²`.
    inv_len2: f64,
}

impl Line {
    pub(crate) fn new(o: DVec3, d: DVec3) -> Line {
        Line {
            o,
            d,
            inv_d: d.recip(),
            inv_len2: 1.0 / d.length_squared(),
        }
    }

    /// The point at `t = 0`.
    #[inline]
    pub(crate) fn origin(&self) -> DVec3 {
        self.o
    }

    /// How far the line moves per unit of `t`.
    #[inline]
    pub(crate) fn velocity(&self) -> DVec3 {
        self.d
    }

    /// The same line with its origin moved to `o + t·d`, its reciprocals kept.
    #[inline]
    pub(super) fn moved(&self, t: f64) -> Line {
        Line {
            o: self.o + t * self.d,
            ..*self
        }
    }

    /// Where the line lies in the box `[min, max]`, `[near, far]` in its `t`: between the
    /// planes of every axis (slab by slab; an axis the line is parallel to, or so nearly
    /// that its reciprocal overflows, either holds the whole line or none of it).
    ///
    /// The slabs are ordered and narrowed by comparisons, not `f64::min`/`max`: those keep
    /// the number where the other is NaN, which costs four instructions each on baseline
    /// x86-64 where a comparison costs one (the demo's Draft: 4 % of its CPU). An end that is
    /// NaN (only an infinite bound met by an infinite origin makes one) narrows nothing.
    #[inline]
    pub(crate) fn box_interval(&self, min: DVec3, max: DVec3) -> Option<[f64; 2]> {
        let o = self.o;
        let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
        for a in 0..3 {
            if self.inv_d[a].is_finite() {
                let (ta, tb) = (
                    (min[a] - o[a]) * self.inv_d[a],
                    (max[a] - o[a]) * self.inv_d[a],
                );
                let (lo, hi) = if ta < tb { (ta, tb) } else { (tb, ta) };
                if lo > near {
                    near = lo;
                }
                if hi < far {
                    far = hi;
                }
            } else if !(o[a] >= min[a] && o[a] <= max[a]) {
                return None;
            }
        }
        (near <= far).then_some([near, far])
    }

    /// Where along the line (its `t`) it passes closest to `c`: a Gaussian's peak along it.
    #[inline]
    pub(super) fn closest(&self, c: Vec3) -> f64 {
        (c.as_dvec3() - self.o).dot(self.d) * self.inv_len2
    }
}

/// The closed interval of `t ∈ [t0, t1]` where the line lies in the primitive's support, if
/// it is longer than 0.
#[inline(always)]
pub(super) fn interval(p: &Primitive, line: &Line, t0: f64, t1: f64) -> Option<[f64; 2]> {
    let [enter, exit] = match p.shape {
        Shape::Sphere { center, radius } => ball(center, radius, line)?,
        Shape::Gaussian {
            center,
            sigma,
            cutoff,
        } => ball(center, cutoff * sigma, line)?,
        Shape::Box { min, max } => line.box_interval(min.as_dvec3(), max.as_dvec3())?,
    };
    let (enter, exit) = (enter.max(t0), exit.min(t1));
    (enter < exit).then_some([enter, exit])
}

/// Where the line meets the closed ball: the roots of `a·t² + 2b·t + c = 0`, in the form
/// that does not cancel (`q = −(b + sign(b)·√(b² − ac))`, roots `q/a` and `c/q`).
fn ball(center: Vec3, radius: f32, line: &Line) -> Option<[f64; 2]> {
    let oc = line.o - center.as_dvec3();
    let r = f64::from(radius);
    let a = line.d.length_squared();
    let b = oc.dot(line.d);
    let c = oc.length_squared() - r * r;
    let disc = b * b - a * c;
    if !(disc > 0.0 && a > 0.0) {
        return None;
    }
    let q = -(b + disc.sqrt().copysign(b));
    let x = q * line.inv_len2;
    let y = if q != 0.0 { c / q } else { x };
    Some([x.min(y), x.max(y)])
}

/// Appends to `out` the spans of the primitives along `o + t·d`, `t ∈ [t0, t1]`: sorted,
/// not overlapping, split wherever a primitive's support begins or ends and at each
/// Gaussian's peak along the ray, each marked `varies` when a Gaussian is present in it.
///
/// The primitives' own intervals are gathered at the end of `out` first and replaced by the
/// spans, so nothing is allocated once `out` has grown. The pieces are found by sweeping
/// from interval end to interval end (quadratic in the primitives the ray meets, a handful).
pub(super) fn spans<'a>(
    primitives: impl Iterator<Item = &'a Primitive>,
    origin: Vec3,
    dir: Vec3,
    t0: f64,
    t1: f64,
    out: &mut Vec<Span>,
) {
    let line = Line::new(origin.as_dvec3(), dir.as_dvec3());
    let first = out.len();
    for p in primitives {
        let Some([enter, exit]) = interval(p, &line, t0, t1) else {
            continue;
        };
        if let Shape::Gaussian { center, .. } = p.shape {
            let peak = line.closest(center);
            if enter < peak && peak < exit {
                out.push(Span {
                    enter,
                    exit: peak,
                    varies: true,
                });
                out.push(Span {
                    enter: peak,
                    exit,
                    varies: true,
                });
                continue;
            }
        }
        out.push(Span {
            enter,
            exit,
            varies: matches!(p.shape, Shape::Gaussian { .. }),
        });
    }
    let crossed = out.len() - first;
    if crossed <= 1 {
        return;
    }
    let mut x = out[first..]
        .iter()
        .map(|s| s.enter)
        .fold(f64::INFINITY, f64::min);
    loop {
        // The next interval end after x, and what covers [x, y].
        let y = out[first..first + crossed]
            .iter()
            .flat_map(|s| [s.enter, s.exit])
            .filter(|&e| e > x)
            .fold(f64::INFINITY, f64::min);
        if y == f64::INFINITY {
            break;
        }
        let mut covered = false;
        let mut varies = false;
        for s in &out[first..first + crossed] {
            if s.enter <= x && s.exit >= y {
                covered = true;
                varies |= s.varies;
            }
        }
        if covered {
            out.push(Span {
                enter: x,
                exit: y,
                varies,
            });
        }
        x = y;
    }
    out.drain(first..first + crossed);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::{Analytic, Field};

    fn spans_of(f: &Analytic, o: Vec3, d: Vec3, t0: f64, t1: f64) -> Vec<Span> {
        let mut out = vec![Span {
            enter: -1.0,
            exit: -1.0,
            varies: true,
        }];
        assert!(f.capabilities().spans);
        f.spans(o, d, t0, t1, &mut out);
        assert_eq!(out[0].enter, -1.0, "what was in `out` stays");
        out.split_off(1)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn a_field_of_many_primitives_declares_no_spans() {
        let puffs = |n: usize| Analytic {
            primitives: (0..n)
                .map(|i| {
                    Primitive::white(Shape::Gaussian {
                        center: Vec3::new(i as f32 * 0.1, 0.0, 0.0),
                        sigma: 0.05,
                        cutoff: 3.0,
                    })
                })
                .collect(),
        };
        let limit = super::super::MAX_SPAN_PRIMITIVES;
        let (o, d) = (Vec3::new(-1.0, 0.0, 0.0), Vec3::X);
        assert!(!spans_of(&puffs(limit), o, d, 0.0, 100.0).is_empty());
        let many = puffs(limit + 1).capabilities();
        assert!(!many.spans, "{many:?}");
        assert!(many.density_bounds, "{many:?}");
    }

    #[test]
    fn sphere_box_and_gaussian_in_closed_form() {
        // Along +x through the origin: a unit sphere at 5 (4 to 6), a box from 7 to 8, a
        // Gaussian of cutoff radius 2·0.5 = 1 at 10 (9 to 11, peaking at 10), and a sphere
        // the ray misses.
        let f = Analytic {
            primitives: vec![
                Primitive::white(Shape::Sphere {
                    center: Vec3::new(5.0, 0.0, 0.0),
                    radius: 1.0,
                }),
                Primitive::white(Shape::Gaussian {
                    center: Vec3::new(10.0, 0.0, 0.0),
                    sigma: 0.5,
                    cutoff: 2.0,
                }),
                Primitive::white(Shape::Box {
                    min: Vec3::new(7.0, -1.0, -1.0),
                    max: Vec3::new(8.0, 1.0, 1.0),
                }),
                Primitive::white(Shape::Sphere {
                    center: Vec3::new(5.0, 3.0, 0.0),
                    radius: 1.0,
                }),
            ],
        };
        let s = spans_of(&f, Vec3::ZERO, Vec3::X, 0.0, 100.0);
        let want = [
            (4.0, 6.0, false),
            (7.0, 8.0, false),
            (9.0, 10.0, true),
            (10.0, 11.0, true),
        ];
        assert_eq!(s.len(), want.len(), "{s:?}");
        for (s, (a, b, v)) in s.iter().zip(want) {
            assert!(
                close(s.enter, a) && close(s.exit, b) && s.varies == v,
                "{s:?}"
            );
        }
        // Clipped to the range.
        let s = spans_of(&f, Vec3::ZERO, Vec3::X, 5.0, 7.5);
        assert_eq!(s.len(), 2, "{s:?}");
        assert!(close(s[0].enter, 5.0) && close(s[0].exit, 6.0));
        assert!(close(s[1].enter, 7.0) && close(s[1].exit, 7.5));
    }

    #[test]
    fn overlaps_split_where_a_support_begins_or_ends() {
        // A Gaussian (radius 3) around a box (−1 to 1 on x), seen along +x from −10:
        // haze, haze and box up to the peak and from it, haze.
        let f = Analytic {
            primitives: vec![
                Primitive::white(Shape::Box {
                    min: Vec3::splat(-1.0),
                    max: Vec3::splat(1.0),
                }),
                Primitive::white(Shape::Gaussian {
                    center: Vec3::ZERO,
                    sigma: 1.0,
                    cutoff: 3.0,
                }),
            ],
        };
        let s = spans_of(&f, Vec3::new(-10.0, 0.0, 0.0), Vec3::X, 0.0, 100.0);
        let want = [(7.0, 9.0), (9.0, 10.0), (10.0, 11.0), (11.0, 13.0)];
        assert_eq!(s.len(), 4, "{s:?}");
        for (s, (a, b)) in s.iter().zip(want) {
            assert!(close(s.enter, a) && close(s.exit, b) && s.varies, "{s:?}");
        }
        // Two boxes, one inside the other: three constant spans.
        let g = Analytic {
            primitives: vec![
                Primitive::white(Shape::Box {
                    min: Vec3::splat(-2.0),
                    max: Vec3::splat(2.0),
                }),
                Primitive::white(Shape::Box {
                    min: Vec3::splat(-1.0),
                    max: Vec3::splat(1.0),
                }),
            ],
        };
        let s = spans_of(&g, Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 0.0, 100.0);
        let want = [(3.0, 4.0), (4.0, 6.0), (6.0, 7.0)];
        assert_eq!(s.len(), 3, "{s:?}");
        for (s, (a, b)) in s.iter().zip(want) {
            assert!(close(s.enter, a) && close(s.exit, b) && !s.varies, "{s:?}");
        }
    }

    #[test]
    fn parallel_rays_tangents_and_empty_fields() {
        let b = Analytic {
            primitives: vec![Primitive::white(Shape::Box {
                min: Vec3::ZERO,
                max: Vec3::ONE,
            })],
        };
        // Parallel to x inside the y and z slabs, and outside the y slab.
        assert_eq!(
            spans_of(&b, Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 0.0, 9.0).len(),
            1
        );
        assert!(spans_of(&b, Vec3::new(-1.0, 1.5, 0.5), Vec3::X, 0.0, 9.0).is_empty());
        // Grazing the unit sphere: no interval of positive length.
        let s = Analytic {
            primitives: vec![Primitive::white(Shape::Sphere {
                center: Vec3::ZERO,
                radius: 1.0,
            })],
        };
        assert!(spans_of(&s, Vec3::new(-5.0, 1.0, 0.0), Vec3::X, 0.0, 9.0).is_empty());
        // Zero density contributes nothing; no primitives, no spans.
        let zero = Analytic {
            primitives: vec![Primitive {
                density: 0.0,
                ..s.primitives[0]
            }],
        };
        assert!(spans_of(&zero, Vec3::new(-5.0, 0.0, 0.0), Vec3::X, 0.0, 9.0).is_empty());
        assert!(spans_of(&Analytic::default(), Vec3::ZERO, Vec3::X, 0.0, 9.0).is_empty());
    }

    /// The spans against dense samples of the density along seeded rays: every sample with
    /// density lies in a span, every sample well inside a span has density, and a span not
    /// marked `varies` has one density throughout.
    #[test]
    fn spans_agree_with_sampled_density() {
        let f = Analytic {
            primitives: vec![
                Primitive::white(Shape::Sphere {
                    center: Vec3::new(0.1, 0.2, -0.3),
                    radius: 0.7,
                }),
                Primitive {
                    density: 2.0,
                    ..Primitive::white(Shape::Box {
                        min: Vec3::new(-1.0, 0.5, -1.0),
                        max: Vec3::new(-0.2, 0.9, 0.1),
                    })
                },
                Primitive::white(Shape::Gaussian {
                    center: Vec3::new(0.6, -0.6, 0.6),
                    sigma: 0.2,
                    cutoff: 4.0,
                }),
                Primitive::white(Shape::Box {
                    min: Vec3::new(-0.5, -0.5, -0.5),
                    max: Vec3::new(0.3, 0.1, 0.4),
                }),
            ],
        };
        let mut rng = crate::rng::SplitMix64::new(7);
        let mut pts = Vec::new();
        let mut sigma = Vec::new();
        for _ in 0..200 {
            let o = rng.in_cube(-3.0, 3.0);
            let target = rng.in_cube(-1.0, 1.0);
            let d = (target - o).normalize();
            let s = spans_of(&f, o, d, 0.0, 8.0);
            for w in s.windows(2) {
                assert!(w[0].exit <= w[1].enter && w[0].enter < w[0].exit, "{s:?}");
            }
            let n = 4000;
            pts.clear();
            pts.extend((0..n).map(|i| o + d * (8.0 * (i as f32 + 0.5) / n as f32)));
            sigma.resize(n, 0.0);
            f.density(&pts, &mut sigma);
            for (i, &sg) in sigma.iter().enumerate() {
                let t = 8.0 * (f64::from(i as u32) + 0.5) / f64::from(n as u32);
                let inside = s.iter().find(|s| s.enter - 1e-5 <= t && t <= s.exit + 1e-5);
                let deep = s.iter().find(|s| s.enter + 1e-5 <= t && t <= s.exit - 1e-5);
                if sg > 0.0 {
                    assert!(inside.is_some(), "density {sg} at t = {t} outside {s:?}");
                }
                if let Some(span) = deep {
                    assert!(sg > 0.0, "no density at t = {t} inside {span:?}");
                }
            }
            // Inside a varying span the only Gaussian here rises or falls, never both.
            for span in s.iter().filter(|s| s.varies) {
                let inner: Vec<f32> = sigma
                    .iter()
                    .enumerate()
                    .filter(|&(i, _)| {
                        let t = 8.0 * (f64::from(i as u32) + 0.5) / f64::from(n as u32);
                        span.enter + 1e-5 <= t && t <= span.exit - 1e-5
                    })
                    .map(|(_, &v)| v)
                    .collect();
                let rises = inner.windows(2).all(|w| w[1] >= w[0] - 1e-6);
                let falls = inner.windows(2).all(|w| w[1] <= w[0] + 1e-6);
                assert!(rises || falls, "{span:?} peaks inside");
            }
            for span in s.iter().filter(|s| !s.varies && s.exit - s.enter > 1e-3) {
                let at = |u: f64| o + d * (span.enter + u * (span.exit - span.enter)) as f32;
                let mut v = [0.0; 3];
                f.density(&[at(0.1), at(0.5), at(0.9)], &mut v);
                assert!(
                    v[0] == v[1] && v[1] == v[2] && v[0] > 0.0,
                    "{span:?}: {v:?}"
                );
            }
        }
    }
}
