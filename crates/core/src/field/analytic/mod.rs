//! Analytic fields: spheres, boxes and Gaussian blobs, the ground truth for accuracy.
//!
//! Each [`Primitive`] has a [`Shape`], a density scale `k` and an [`ShColor`]. Densities of
//! overlapping primitives add; the radiance at a point is the density-weighted mean of the
//! primitives' colours:
//!
//! `σ(x) = Σₖ σₖ(x)`, `c(x, d) = Σₖ σₖ(x) cₖ(d) / Σₖ σₖ(x)` (0 where `σ(x) = 0`).
//!
//! Shapes, with `k` the primitive's density:
//! - sphere: `σ = k` for `|x − c| ≤ r`;
//! - box: `σ = k` for `min ≤ x ≤ max` (axis-aligned in field space);
//! - Gaussian: `σ = k·exp(−|x − c|² / (2 s²))` for `|x − c| ≤ cutoff·s`, exactly 0 beyond, so
//!   its support is bounded and occupancy can be exactly conservative.
//!
//! Every support is a *closed* set: points on a sphere's surface, a box's faces or the cutoff
//! sphere have density. Piecewise-constant densities with direction-only colours integrate in
//! closed form along a ray, and a Gaussian has closed-form optical depth (an erf), which is
//! what the reference integrator uses.

use glam::Vec3;
use serde::{Deserialize, Serialize};

mod erf;
mod index;
mod profile;
mod sh;
mod spans;

pub(crate) use profile::{Anchor, Density, Profile};
pub use sh::ShColor;
pub(crate) use spans::Line;

use super::{Aabb, Capabilities, Field, RegionQuery, Span};
use crate::error::{number, Error, Result};
use index::PrimitiveIndex;

/// Relative padding of [`Field::may_be_occupied`]: much larger than f32 rounding (~1e-7), much
/// smaller than any cell.
const OCCUPANCY_PAD: f32 = 1e-5;

/// Points per stack-allocated chunk in [`Analytic::radiance`].
const CHUNK: usize = 64;

/// The default Gaussian cutoff, in standard deviations.
fn default_cutoff() -> f32 {
    4.0
}

/// The largest Gaussian cutoff, in standard deviations. Past about 14σ the density is 0 in
/// single precision anyway, while the support still has to be stepped through: a cutoff of
/// 2³¹ turns a small blob into one billions of steps across.
const MAX_CUTOFF: f32 = 64.0;

/// The most primitives an analytic field gives exact spans for: each ray tests every
/// primitive and sweeps the intervals it meets (quadratic in those), a cost that grows with
/// the scene where the occupancy grid's walk does not.
const MAX_SPAN_PRIMITIVES: usize = 64;

/// The support of a primitive, in field space.
///
/// JSON: `{"sphere": {"center": [x, y, z], "radius": r}}`,
/// `{"box": {"min": [x, y, z], "max": [x, y, z]}}`,
/// `{"gaussian": {"center": [x, y, z], "sigma": s, "cutoff": 4}}` (`cutoff` optional, 4).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    /// The closed ball `|x − center| ≤ radius`.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius (> 0).
        radius: f32,
    },
    /// The closed axis-aligned box `min ≤ x ≤ max`.
    Box {
        /// Smallest corner.
        min: Vec3,
        /// Largest corner (> `min` on every axis).
        max: Vec3,
    },
    /// An isotropic Gaussian `exp(−|x − center|²/(2 sigma²))`, cut to 0 beyond
    /// `|x − center| > cutoff·sigma`.
    Gaussian {
        /// Centre.
        center: Vec3,
        /// Standard deviation (> 0).
        sigma: f32,
        /// Support radius in standard deviations (> 0; default 4).
        #[serde(default = "default_cutoff")]
        cutoff: f32,
    },
}

impl Shape {
    /// The tightest box around the support.
    pub fn bounds(&self) -> Aabb {
        match *self {
            Shape::Sphere { center, radius } => Aabb::new(center, center).grow(radius),
            Shape::Box { min, max } => Aabb::new(min, max),
            Shape::Gaussian {
                center,
                sigma,
                cutoff,
            } => Aabb::new(center, center).grow(cutoff * sigma),
        }
    }

    /// Whether the support, padded by [`OCCUPANCY_PAD`] relative to the shape's coordinates,
    /// meets the closed box `region`. Exact apart from that padding: sphere–box by the
    /// closest point of the box to the centre, box–box by interval overlap.
    fn overlaps(&self, region: &Aabb) -> bool {
        match *self {
            Shape::Sphere { center, radius } => ball_overlaps(center, radius, region),
            Shape::Box { min, max } => padded_box(min, max).intersects(region),
            Shape::Gaussian {
                center,
                sigma,
                cutoff,
            } => ball_overlaps(center, cutoff * sigma, region),
        }
    }

    /// Checks finiteness and ranges; `what` names the shape in messages.
    fn validate(&self, what: &str) -> Result<()> {
        let positive = |name: &str, v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(
                    format!("{what}.{name}"),
                    format!("must be finite and > 0, got {}", number(v)),
                ))
            }
        };
        let finite = |name: &str, v: Vec3| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(Error::invalid(
                    format!("{what}.{name}"),
                    format!(
                        "must be finite, got [{}, {}, {}]",
                        number(v.x),
                        number(v.y),
                        number(v.z)
                    ),
                ))
            }
        };
        match *self {
            Shape::Sphere { center, radius } => {
                finite("sphere.center", center)?;
                positive("sphere.radius", radius)
            }
            Shape::Box { min, max } => {
                finite("box.min", min)?;
                finite("box.max", max)?;
                if min.cmplt(max).all() {
                    Ok(())
                } else {
                    Err(Error::invalid(
                        format!("{what}.box"),
                        format!("min {min} must be < max {max} on every axis"),
                    ))
                }
            }
            Shape::Gaussian {
                center,
                sigma,
                cutoff,
            } => {
                finite("gaussian.center", center)?;
                positive("gaussian.sigma", sigma)?;
                positive("gaussian.cutoff", cutoff)?;
                if cutoff > MAX_CUTOFF {
                    return Err(Error::invalid(
                        format!("{what}.gaussian.cutoff"),
                        format!(
                            "{cutoff} standard deviations is past the most, {MAX_CUTOFF} (the \
                             density is 0 beyond about 14)"
                        ),
                    ));
                }
                Ok(())
            }
        }
    }
}

/// Whether the closed ball (centre `c`, radius `r`, padded) meets `region`: the squared
/// distance from `c` to the closest point of the box against `r²`.
fn ball_overlaps(c: Vec3, r: f32, region: &Aabb) -> bool {
    !region.is_empty() && distance2_to_box(c, region) <= padded_radius(c, r).powi(2)
}

/// A ball's radius grown by [`OCCUPANCY_PAD`] relative to its coordinates.
#[inline]
fn padded_radius(c: Vec3, r: f32) -> f32 {
    r + OCCUPANCY_PAD * (r + c.abs().max_element())
}

/// A box support grown by [`OCCUPANCY_PAD`] relative to its coordinates.
#[inline]
fn padded_box(min: Vec3, max: Vec3) -> Aabb {
    Aabb::new(min, max).grow(OCCUPANCY_PAD * min.abs().max(max.abs()).max_element())
}

/// The squared distance from `c` to the closest point of `region` (0 inside it).
#[inline]
fn distance2_to_box(c: Vec3, region: &Aabb) -> f32 {
    (region.min - c)
        .max(c - region.max)
        .max(Vec3::ZERO)
        .length_squared()
}

/// One shape with a density scale and a colour.
///
/// JSON: `{"shape": {...}, "density": 5.0, "color": {"rgb": [r, g, b]}}` (see [`Shape`] and
/// [`ShColor`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Primitive {
    /// Where the primitive has density, and its profile.
    pub shape: Shape,
    /// Density scale `k` (≥ 0, per field-space unit length): the density inside a sphere or
    /// box, the peak of a Gaussian.
    pub density: f32,
    /// The colour it emits.
    pub color: ShColor,
}

impl Primitive {
    /// A white primitive of unit density: what the tests of the field's spans and of the
    /// occupancy grid build their scenes from.
    #[cfg(test)]
    pub(crate) fn white(shape: Shape) -> Self {
        Primitive {
            shape,
            density: 1.0,
            color: ShColor::constant(Vec3::ONE),
        }
    }

    /// Adds this primitive's density at each point to `sigma` (the concrete shape is chosen
    /// once, outside the loop). A sphere or box adds `k` inside and 0 outside without a
    /// branch (a batch's points straddle its surface, and the branch was mispredicted): the
    /// same sums, since `sigma` starts at +0 and only grows.
    fn add_density(&self, points: &[Vec3], sigma: &mut [f32]) {
        let k = self.density;
        match self.shape {
            Shape::Sphere { center, radius } => {
                let r2 = radius * radius;
                for (p, s) in points.iter().zip(sigma.iter_mut()) {
                    let inside = (*p - center).length_squared() <= r2;
                    *s += if inside { k } else { 0.0 };
                }
            }
            Shape::Box { min, max } => {
                for (p, s) in points.iter().zip(sigma.iter_mut()) {
                    let inside = (p.cmpge(min) & p.cmple(max)).all();
                    *s += if inside { k } else { 0.0 };
                }
            }
            Shape::Gaussian {
                center,
                sigma: sd,
                cutoff,
            } => {
                let r = cutoff * sd;
                let r2 = r * r;
                let a = -0.5 / (sd * sd);
                for (p, s) in points.iter().zip(sigma.iter_mut()) {
                    let d2 = (*p - center).length_squared();
                    if d2 <= r2 {
                        *s += k * (a * d2).exp();
                    }
                }
            }
        }
    }
}

/// A field made of analytic primitives. See the module docs for the formulas.
///
/// ```
/// use glam::Vec3;
/// use nerfx_core::field::{Analytic, Field};
/// let json = r#"{"primitives": [
///   {"shape": {"sphere": {"center": [0, 0, 0], "radius": 1}},
///    "density": 5, "color": {"rgb": [0.8, 0.2, 0.1]}},
///   {"shape": {"box": {"min": [-2, -2, -2], "max": [2, -1.5, 2]}},
///    "density": 20, "color": {"sh": [[1, 1, 1], [0, 0.2, 0], [0, 0, 0], [0, 0, 0]]}},
///   {"shape": {"gaussian": {"center": [1, 1, 0], "sigma": 0.3}},
///    "density": 8, "color": {"rgb": [0.2, 0.4, 1]}}
/// ]}"#;
/// let field: Analytic = serde_json::from_str(json).unwrap();
/// field.validate().unwrap();
/// let mut sigma = [0.0; 2];
/// field.density(&[Vec3::ZERO, Vec3::new(0.0, 3.0, 0.0)], &mut sigma);
/// assert_eq!(sigma, [5.0, 0.0]);
/// assert_eq!(field.bounds().min, Vec3::new(-2.0, -2.0, -2.0));
/// ```
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Analytic {
    /// The primitives; their densities add.
    pub primitives: Vec<Primitive>,
}

impl Analytic {
    /// Checks every primitive: finite values, radius/sigma/cutoff > 0, box `min < max`,
    /// density ≥ 0. Errors name the primitive, e.g. `primitives[2].shape.sphere.radius`.
    pub fn validate(&self) -> Result<()> {
        for (i, p) in self.primitives.iter().enumerate() {
            p.shape.validate(&format!("primitives[{i}].shape"))?;
            if !(p.density.is_finite() && p.density >= 0.0) {
                return Err(Error::invalid(
                    format!("primitives[{i}].density"),
                    format!("must be finite and ≥ 0, got {}", number(p.density)),
                ));
            }
        }
        Ok(())
    }

    /// The primitives that contribute anything (density > 0).
    fn active(&self) -> impl Iterator<Item = &Primitive> {
        self.primitives.iter().filter(|p| p.density > 0.0)
    }
}

impl Field for Analytic {
    /// The union of the supports of the primitives with density > 0 ([`Aabb::EMPTY`] if none).
    fn bounds(&self) -> Aabb {
        self.active()
            .fold(Aabb::EMPTY, |b, p| b.union(&p.shape.bounds()))
    }

    /// Constant pieces integrate exactly at any step once their edges are bracketed, so only
    /// the Gaussians set a scale: their standard deviation. Without one, 1/32 of the bounds.
    fn feature_size(&self) -> f32 {
        self.active()
            .filter_map(|p| match p.shape {
                Shape::Gaussian { sigma, .. } => Some(sigma),
                _ => None,
            })
            .fold(self.bounds().diagonal() / 32.0, f32::min)
    }

    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        debug_assert_eq!(points.len(), sigma.len());
        sigma.fill(0.0);
        for p in self.active() {
            p.add_density(points, sigma);
        }
    }

    /// `Σσₖcₖ(d) / Σσₖ`, in chunks of 64 points with the weights on the stack.
    fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]) {
        debug_assert_eq!(points.len(), dirs.len());
        debug_assert_eq!(points.len(), rgb.len());
        for ((pts, ds), out) in points
            .chunks(CHUNK)
            .zip(dirs.chunks(CHUNK))
            .zip(rgb.chunks_mut(CHUNK))
        {
            let n = pts.len();
            let mut total = [0.0f32; CHUNK];
            let mut own = [0.0f32; CHUNK];
            out.fill(Vec3::ZERO);
            for prim in self.active() {
                own[..n].fill(0.0);
                prim.add_density(pts, &mut own[..n]);
                for j in 0..n {
                    let s = own[j];
                    if s > 0.0 {
                        out[j] += s * prim.color.eval(ds[j]);
                        total[j] += s;
                    }
                }
            }
            for (c, &s) in out.iter_mut().zip(&total[..n]) {
                if s > 0.0 {
                    *c /= s;
                }
            }
        }
    }

    /// Spans and density bounds, always; spans only up to `MAX_SPAN_PRIMITIVES` primitives
    /// (beyond, the marcher walks the field's occupancy grid instead).
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            spans: self.active().nth(MAX_SPAN_PRIMITIVES).is_none(),
            mask_segments: false,
            density_bounds: true,
        }
    }

    /// Each primitive's interval in closed form, cut where any begins or ends; a span is
    /// constant unless a Gaussian is in it (see `spans.rs`).
    fn spans(&self, origin: Vec3, dir: Vec3, t0: f64, t1: f64, out: &mut Vec<Span>) {
        spans::spans(self.active(), origin, dir, t0, t1, out);
    }

    fn may_be_occupied(&self, region: &Aabb) -> bool {
        !region.is_empty() && self.active().any(|p| p.shape.overlaps(region))
    }

    fn region_query(&self) -> Box<dyn RegionQuery + '_> {
        Box::new(PrimitiveIndex::new(&self.primitives))
    }

    /// For each region, the sum over the primitives whose support meets it (padded as in
    /// [`Field::may_be_occupied`]) of each one's largest density there: its density for
    /// spheres and boxes, for a Gaussian its value at the point of the region nearest its
    /// centre. The shape is chosen once per primitive, outside the loop over regions.
    fn density_bounds(&self, regions: &[Aabb], bounds: &mut [f32]) {
        bounds.fill(0.0);
        for p in self.active() {
            let k = p.density;
            let pairs = regions.iter().zip(bounds.iter_mut());
            match p.shape {
                Shape::Sphere { center, radius } => {
                    let r2 = padded_radius(center, radius).powi(2);
                    for (region, bound) in pairs {
                        if distance2_to_box(center, region) <= r2 {
                            *bound += k;
                        }
                    }
                }
                Shape::Box { min, max } => {
                    let support = padded_box(min, max);
                    for (region, bound) in pairs {
                        if support.intersects(region) {
                            *bound += k;
                        }
                    }
                }
                Shape::Gaussian {
                    center,
                    sigma,
                    cutoff,
                } => {
                    let r2 = padded_radius(center, cutoff * sigma).powi(2);
                    let a = -0.5 / (sigma * sigma);
                    for (region, bound) in pairs {
                        let g = distance2_to_box(center, region);
                        if g <= r2 {
                            *bound += k * (a * g).exp();
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(c: Vec3, r: f32, k: f32, rgb: Vec3) -> Primitive {
        Primitive {
            shape: Shape::Sphere {
                center: c,
                radius: r,
            },
            density: k,
            color: ShColor::constant(rgb),
        }
    }

    fn boxed(min: Vec3, max: Vec3, k: f32, rgb: Vec3) -> Primitive {
        Primitive {
            shape: Shape::Box { min, max },
            density: k,
            color: ShColor::constant(rgb),
        }
    }

    fn gauss(c: Vec3, s: f32, cutoff: f32, k: f32) -> Primitive {
        Primitive {
            shape: Shape::Gaussian {
                center: c,
                sigma: s,
                cutoff,
            },
            density: k,
            color: ShColor::constant(Vec3::ONE),
        }
    }

    fn density_at(f: &Analytic, p: Vec3) -> f32 {
        let mut s = [0.0];
        f.density(&[p], &mut s);
        s[0]
    }

    #[test]
    fn sphere_and_box_are_closed_constant() {
        let f = Analytic {
            primitives: vec![
                sphere(Vec3::ZERO, 1.0, 3.0, Vec3::ONE),
                boxed(Vec3::splat(2.0), Vec3::splat(3.0), 7.0, Vec3::ONE),
            ],
        };
        assert_eq!(density_at(&f, Vec3::ZERO), 3.0);
        assert_eq!(density_at(&f, Vec3::X), 3.0); // on the surface
        assert_eq!(density_at(&f, Vec3::new(0.0, 1.0001, 0.0)), 0.0);
        assert_eq!(density_at(&f, Vec3::new(2.0, 2.5, 3.0)), 7.0); // on faces
        assert_eq!(density_at(&f, Vec3::new(2.0, 2.5, 3.001)), 0.0);
        assert_eq!(density_at(&f, Vec3::splat(1.5)), 0.0);
    }

    #[test]
    fn gaussian_profile_and_cutoff() {
        let c = Vec3::new(1.0, -1.0, 0.5);
        let f = Analytic {
            primitives: vec![gauss(c, 0.5, 3.0, 4.0)],
        };
        for r in [0.0f32, 0.25, 0.5, 1.0, 1.49] {
            let p = c + Vec3::new(0.0, r, 0.0);
            let expect = 4.0 * (-(r * r) / (2.0 * 0.25)).exp();
            assert!((density_at(&f, p) - expect).abs() < 1e-5, "r = {r}");
        }
        assert_eq!(density_at(&f, c + Vec3::new(1.51, 0.0, 0.0)), 0.0);
        let b = f.bounds();
        assert!((b.min - (c - 1.5)).abs().max_element() < 1e-6);
        assert!((b.max - (c + 1.5)).abs().max_element() < 1e-6);
    }

    #[test]
    fn overlapping_densities_add_and_colours_mix() {
        let red = Vec3::new(1.0, 0.0, 0.0);
        let blue = Vec3::new(0.0, 0.0, 1.0);
        let f = Analytic {
            primitives: vec![
                sphere(Vec3::ZERO, 1.0, 1.0, red),
                sphere(Vec3::new(0.5, 0.0, 0.0), 1.0, 3.0, blue),
            ],
        };
        let pts = [
            Vec3::new(0.25, 0.0, 0.0),
            Vec3::new(-0.9, 0.0, 0.0),
            Vec3::new(1.4, 0.0, 0.0),
            Vec3::new(9.0, 0.0, 0.0),
        ];
        let mut s = [0.0; 4];
        f.density(&pts, &mut s);
        assert_eq!(s, [4.0, 1.0, 3.0, 0.0]);
        let mut c = [Vec3::splat(-1.0); 4];
        f.radiance(&pts, &[Vec3::X; 4], &mut c);
        // (1·red + 3·blue) / 4
        assert!((c[0] - Vec3::new(0.25, 0.0, 0.75)).abs().max_element() < 1e-6);
        assert!((c[1] - red).abs().max_element() < 1e-6);
        assert!((c[2] - blue).abs().max_element() < 1e-6);
        assert_eq!(c[3], Vec3::ZERO);
    }

    #[test]
    fn radiance_is_view_dependent_and_chunked() {
        // 150 points (more than one chunk), SH colour brighter towards +z (and > 0 everywhere).
        let color = ShColor::from_coefficients(&[
            Vec3::splat(2.0),
            Vec3::ZERO,
            Vec3::splat(1.0),
            Vec3::ZERO,
        ])
        .unwrap();
        let f = Analytic {
            primitives: vec![Primitive {
                shape: Shape::Sphere {
                    center: Vec3::ZERO,
                    radius: 10.0,
                },
                density: 2.0,
                color,
            }],
        };
        let n = 150;
        let pts: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(i as f32 * 0.01, 0.0, 0.0))
            .collect();
        let dirs: Vec<Vec3> = (0..n)
            .map(|i| if i % 2 == 0 { Vec3::Z } else { -Vec3::Z })
            .collect();
        let mut c = vec![Vec3::ZERO; n];
        f.radiance(&pts, &dirs, &mut c);
        for (i, v) in c.iter().enumerate() {
            let z = if i % 2 == 0 { 1.0 } else { -1.0 };
            let expect = 2.0 * 0.282_095 + 0.488_603 * z;
            assert!((v.x - expect).abs() < 1e-5, "{i}: {v}");
        }
    }

    #[test]
    fn bounds_union_skips_zero_density() {
        let f = Analytic {
            primitives: vec![
                sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE),
                boxed(
                    Vec3::new(2.0, 0.0, 0.0),
                    Vec3::new(3.0, 4.0, 0.5),
                    1.0,
                    Vec3::ONE,
                ),
                sphere(Vec3::splat(50.0), 1.0, 0.0, Vec3::ONE),
            ],
        };
        let b = f.bounds();
        assert_eq!(b.min, Vec3::new(-1.0, -1.0, -1.0));
        assert_eq!(b.max, Vec3::new(3.0, 4.0, 1.0));
        assert!(!f.may_be_occupied(&Aabb::new(Vec3::splat(49.0), Vec3::splat(51.0))));
        assert!(Analytic::default().bounds().is_empty());
        assert!(!Analytic::default().may_be_occupied(&b));
    }

    #[test]
    fn density_bound_bounds_every_sample() {
        let f = Analytic {
            primitives: vec![
                sphere(Vec3::ZERO, 1.0, 3.0, Vec3::ONE),
                gauss(Vec3::new(1.0, 0.0, 0.0), 0.5, 4.0, 2.0),
            ],
        };
        // Far from both: nothing. Inside the sphere, away from the blob's centre: the
        // sphere's 3 plus the Gaussian at the box's nearest point (distance 0.5 → 2e^{-1/2}).
        let far = Aabb::new(Vec3::splat(5.0), Vec3::splat(6.0));
        let b = Aabb::new(Vec3::new(-0.5, -0.1, -0.1), Vec3::new(0.5, 0.1, 0.1));
        let mut bounds = [f32::NAN; 2];
        assert!(f.capabilities().density_bounds);
        f.density_bounds(&[far, b], &mut bounds);
        assert_eq!(bounds[0], 0.0);
        let expected = 3.0 + 2.0 * (-0.5f32).exp();
        assert!((bounds[1] - expected).abs() < 1e-6);
        // Every sample in the box is below the bound.
        let mut pts = Vec::new();
        for i in 0..=10 {
            pts.push(Vec3::new(-0.5 + 0.1 * i as f32, 0.05, -0.02));
        }
        let mut s = vec![0.0; pts.len()];
        f.density(&pts, &mut s);
        assert!(s.iter().all(|&v| v <= expected + 1e-6), "{s:?}");
    }

    #[test]
    fn may_be_occupied_exact_cases() {
        let f = Analytic {
            primitives: vec![sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE)],
        };
        // The box [0.8, 2]³: closest point (0.8, 0.8, 0.8) at distance 1.386 > 1.
        assert!(!f.may_be_occupied(&Aabb::new(Vec3::splat(0.8), Vec3::splat(2.0))));
        // The box [0.5, 2]³: closest point at distance 0.866 < 1.
        assert!(f.may_be_occupied(&Aabb::new(Vec3::splat(0.5), Vec3::splat(2.0))));
        // Touching the sphere at (1, 0, 0).
        assert!(f.may_be_occupied(&Aabb::new(Vec3::new(1.0, -1.0, -1.0), Vec3::splat(2.0))));
        assert!(!f.may_be_occupied(&Aabb::new(Vec3::new(1.01, -1.0, -1.0), Vec3::splat(2.0))));
        // A box inside the sphere.
        assert!(f.may_be_occupied(&Aabb::new(Vec3::splat(-0.1), Vec3::splat(0.1))));
        let g = Analytic {
            primitives: vec![gauss(Vec3::ZERO, 0.5, 4.0, 1.0)],
        };
        assert!(g.may_be_occupied(&Aabb::new(Vec3::new(1.99, 0.0, 0.0), Vec3::splat(3.0))));
        assert!(!g.may_be_occupied(&Aabb::new(Vec3::new(2.01, 0.0, 0.0), Vec3::splat(3.0))));
        let b = Analytic {
            primitives: vec![boxed(Vec3::ZERO, Vec3::ONE, 1.0, Vec3::ONE)],
        };
        assert!(b.may_be_occupied(&Aabb::new(Vec3::splat(1.0), Vec3::splat(2.0))));
        assert!(!b.may_be_occupied(&Aabb::new(Vec3::new(1.01, 0.0, 0.0), Vec3::splat(2.0))));
    }

    /// Random boxes against dense samples: wherever a sample inside a box sees density,
    /// `may_be_occupied` must say so.
    #[test]
    fn may_be_occupied_is_conservative_on_samples() {
        let f = Analytic {
            primitives: vec![
                sphere(Vec3::new(0.1, 0.2, -0.3), 0.7, 1.0, Vec3::ONE),
                boxed(
                    Vec3::new(-1.0, 0.5, -1.0),
                    Vec3::new(-0.2, 0.9, 0.1),
                    2.0,
                    Vec3::ONE,
                ),
                gauss(Vec3::new(0.6, -0.6, 0.6), 0.2, 4.0, 3.0),
            ],
        };
        let mut state = 0x1234_5678_9abc_def0u64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut pts = Vec::new();
        for _ in 0..300 {
            let a = Vec3::new(rnd(), rnd(), rnd()) * 3.0 - 1.5;
            let s = Vec3::new(rnd(), rnd(), rnd()) * 0.6;
            let region = Aabb::new(a, a + s);
            pts.clear();
            for i in 0..6 {
                for j in 0..6 {
                    for k in 0..6 {
                        let u = Vec3::new(i as f32, j as f32, k as f32) / 5.0;
                        pts.push(region.min + u * s);
                    }
                }
            }
            let mut sig = vec![0.0; pts.len()];
            f.density(&pts, &mut sig);
            if sig.iter().any(|&x| x > 0.0) {
                assert!(f.may_be_occupied(&region), "{region:?}");
            }
        }
    }

    #[test]
    fn validation_names_primitive_and_field() {
        let bad = |p: Primitive| {
            let f = Analytic {
                primitives: vec![sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE), p],
            };
            f.validate().unwrap_err().to_string()
        };
        let e = bad(sphere(Vec3::ZERO, -1.0, 1.0, Vec3::ONE));
        assert!(e.contains("primitives[1].shape.sphere.radius"), "{e}");
        let e = bad(sphere(Vec3::new(f32::NAN, 0.0, 0.0), 1.0, 1.0, Vec3::ONE));
        assert!(e.contains("primitives[1].shape.sphere.center"), "{e}");
        let e = bad(boxed(Vec3::ONE, Vec3::ZERO, 1.0, Vec3::ONE));
        assert!(e.contains("primitives[1].shape.box"), "{e}");
        let e = bad(gauss(Vec3::ZERO, 0.0, 4.0, 1.0));
        assert!(e.contains("primitives[1].shape.gaussian.sigma"), "{e}");
        let e = bad(gauss(Vec3::ZERO, 1.0, f32::INFINITY, 1.0));
        assert!(e.contains("primitives[1].shape.gaussian.cutoff"), "{e}");
        let e = bad(gauss(Vec3::ZERO, 0.6, 2147483647.0, 1.0));
        assert!(
            e.contains("gaussian.cutoff") && e.contains("past the most"),
            "{e}"
        );
        let e = bad(sphere(Vec3::ZERO, 1.0, -2.0, Vec3::ONE));
        assert!(e.contains("primitives[1].density"), "{e}");
        let e = bad(sphere(Vec3::ZERO, 1.0, f32::NAN, Vec3::ONE));
        assert!(e.contains("primitives[1].density"), "{e}");
    }

    #[test]
    fn serde_default_cutoff_and_unknown_fields() {
        let p: Primitive = serde_json::from_str(
            r#"{"shape": {"gaussian": {"center": [0, 0, 0], "sigma": 2}},
                "density": 1, "color": {"rgb": [1, 1, 1]}}"#,
        )
        .unwrap();
        assert_eq!(
            p.shape,
            Shape::Gaussian {
                center: Vec3::ZERO,
                sigma: 2.0,
                cutoff: 4.0
            }
        );
        assert!(serde_json::from_str::<Primitive>(
            r#"{"shape": {"sphere": {"center": [0, 0, 0], "radius": 1, "r": 2}},
                "density": 1, "color": {"rgb": [1, 1, 1]}}"#,
        )
        .is_err());
        assert!(serde_json::from_str::<Analytic>(r#"{"primitives": [], "extra": 1}"#).is_err());
        assert!(serde_json::from_str::<Shape>(r#"{"cone": {"radius": 1}}"#).is_err());
        let f = Analytic {
            primitives: vec![boxed(Vec3::ZERO, Vec3::ONE, 2.0, Vec3::X)],
        };
        let back: Analytic = serde_json::from_str(&serde_json::to_string(&f).unwrap()).unwrap();
        assert_eq!(back, f);
    }
}
