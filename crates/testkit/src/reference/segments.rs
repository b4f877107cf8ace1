//! A scene's analytic primitives as world-`t` segments along one world ray.
//!
//! Per instance, with `N⁻¹ = field_from_world`, the world ray `o + t·d` (`|d| = 1`, `t` in
//! world units) is the field-space line `p(t) = O + t·D` with `O = N⁻¹o`, `D = N⁻¹d` left
//! **un-normalised**, so every intersection below comes out directly in world `t`, also when
//! `N` scales non-uniformly. With `k = |D|`, field-space arc length is `u = k·t`, so a
//! density ρ per field unit is `k·ρ` per world unit (`dτ = ρ du = kρ dt`). Colours are
//! evaluated once per ray along the field-space unit direction `D/k`.
//!
//! - **Sphere and Gaussian support** (centre `c`, radius `R`): with `w = O − c`,
//!   `|p(t) − c|² = k²(t − t*)² + b²`, where `t* = −(w·D)/k²` is the closest approach and
//!   `b² = |w + t*·D|²` the squared miss distance (computed as a length, so it never goes
//!   negative). The line is inside for `|t − t*| ≤ √(R² − b²)/k`.
//! - **Gaussian density**: `ρ·exp(−|p − c|²/(2s²))` becomes, per world unit,
//!   `kρ·e^{−b²/(2s²)} · exp(−(t − t*)²/(2(s/k)²))`: a 1-D Gaussian in `t` of peak
//!   `kρ·e^{−b²/(2s²)}` and width `s/k`, whose optical depth over `[t₀, t₁]` is
//!   `ρ·s·e^{−b²/(2s²)}·√(π/2)·(erf((t₁−t*)k/(√2 s)) − erf((t₀−t*)k/(√2 s)))` — `k` cancels in
//!   front, as it must: optical depth does not depend on the units `t` is measured in.
//!   Supports wider than 40 widths are cut there: the density beyond is below
//!   `e^{−800}`, which is 0 in f64, so this changes nothing.
//! - **Box**: the slab test on `p(t)` per axis.
//! - **Crop box** (centre, full sides, rotation `R = Rz(yaw)·Ry(pitch)·Rx(roll)`, in field
//!   space): the slab test on `Rᵀ(p(t) − centre)` against the half sides. It clips the
//!   instance's interval of `t` (and `t ≥ 0`, the ray starts at the camera); it does not mask
//!   density. This is computed here again rather than through
//!   [`nerfx_core::scene::CropClip::clip`], so that the reference stays independent of the renderer.

use glam::{DMat3, DMat4, DVec3};

use super::integrator::{Density, Gaussian1d, RayResult, Segment, Sweep};
use nerfx_core::camera::Ray;
use nerfx_core::error::{Error, Result};
use nerfx_core::field::{Primitive, Shape};
use nerfx_core::scene::Scene;

/// A Gaussian's support is cut at this many widths (its density there is `e^{−800}`, 0 in
/// f64).
const GAUSSIAN_REACH: f64 = 40.0;

/// A scene prepared for exact per-ray integration: every instance must be analytic.
///
/// ```
/// use glam::{DMat4, DVec3, Vec3};
/// use nerfx_core::camera::Ray;
/// use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};
/// use nerfx_testkit::reference::ReferenceScene;
/// use nerfx_core::scene::{FieldHandle, Instance, Scene};
/// // A unit sphere of density 2 at the origin, seen through its centre from z = 5.
/// let field = Analytic {
///     primitives: vec![Primitive {
///         shape: Shape::Sphere { center: Vec3::ZERO, radius: 1.0 },
///         density: 2.0,
///         color: ShColor::constant(Vec3::ONE),
///     }],
/// };
/// let instance = Instance::new("ball", FieldHandle::analytic(field), DMat4::IDENTITY, None)?;
/// let scene = Scene::new(vec![instance]);
/// let reference = ReferenceScene::new(&scene)?;
/// let ray = Ray {
///     origin: DVec3::new(0.0, 0.0, 5.0),
///     dir: DVec3::NEG_Z,
///     z_per_t: 1.0,
///     near: 0.0,
///     far: f64::INFINITY,
/// };
/// let r = reference.integrate(&ray);
/// assert!((r.alpha - (1.0 - (-4.0f64).exp())).abs() < 1e-15);
/// # Ok::<(), nerfx_core::Error>(())
/// ```
pub struct ReferenceScene<'a> {
    instances: Vec<PlacedPrimitives<'a>>,
}

/// One instance: its transform, crop and primitives.
struct PlacedPrimitives<'a> {
    field_from_world: DMat4,
    crop: Option<Crop>,
    primitives: &'a [Primitive],
}

/// The crop box in the form the slab test wants.
struct Crop {
    crop_from_field: DMat3,
    center: DVec3,
    half: DVec3,
}

impl<'a> ReferenceScene<'a> {
    /// Prepares `scene`; [`Error::Unsupported`] when an instance is not an analytic field
    /// (only analytic primitives have exact ray integrals).
    pub fn new(scene: &'a Scene) -> Result<Self> {
        let instances = scene
            .marched()
            .map(|instance| {
                let analytic = instance.handle().as_analytic().ok_or_else(|| {
                    Error::Unsupported(format!(
                        "reference integration of instance '{}': its field is not analytic",
                        instance.name
                    ))
                })?;
                let crop = instance.crop().map(|c| {
                    let [roll, pitch, yaw] = c.rotation;
                    let field_from_crop = DMat3::from_rotation_z(yaw)
                        * DMat3::from_rotation_y(pitch)
                        * DMat3::from_rotation_x(roll);
                    Crop {
                        crop_from_field: field_from_crop.transpose(),
                        center: DVec3::from(c.center),
                        half: 0.5 * DVec3::from(c.scale),
                    }
                });
                Ok(PlacedPrimitives {
                    field_from_world: instance.field_from_world(),
                    crop,
                    primitives: &analytic.primitives,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(ReferenceScene { instances })
    }

    /// The exact colour, accumulation and depths along `ray` (`ray.dir` unit length).
    pub fn integrate(&self, ray: &Ray) -> RayResult {
        self.integrate_with(ray, &mut Sweep::default())
    }

    /// [`ReferenceScene::integrate`] with caller-owned scratch (one per thread).
    pub(crate) fn integrate_with(&self, ray: &Ray, sweep: &mut Sweep) -> RayResult {
        sweep.segments.clear();
        for instance in &self.instances {
            instance.push_segments(ray, &mut sweep.segments);
        }
        sweep.integrate()
    }
}

impl PlacedPrimitives<'_> {
    /// Appends the segments of every primitive of this instance along `ray`.
    fn push_segments(&self, ray: &Ray, out: &mut Vec<Segment>) {
        let o = self.field_from_world.transform_point3(ray.origin);
        let d = self.field_from_world.transform_vector3(ray.dir);
        let k = d.length();
        if !o.is_finite() || !d.is_finite() || k == 0.0 {
            return;
        }
        let (mut lo, mut hi) = (ray.near, ray.far);
        if let Some(crop) = &self.crop {
            let oc = crop.crop_from_field * (o - crop.center);
            let dc = crop.crop_from_field * d;
            match slab(oc, dc, -crop.half, crop.half) {
                Some((a, b)) => (lo, hi) = (a.max(lo), b),
                None => return,
            }
        }
        if lo >= hi {
            return;
        }
        let dir = d / k;
        for p in self.primitives {
            if p.density.is_nan() || p.density <= 0.0 {
                continue;
            }
            let rho = p.density as f64;
            let (range, density) = match p.shape {
                Shape::Sphere { center, radius } => {
                    let Some(chord) = Chord::new(o, d, k, center.as_dvec3()) else {
                        continue;
                    };
                    (chord.within(radius as f64), Density::Constant(k * rho))
                }
                Shape::Box { min, max } => (
                    slab(o, d, min.as_dvec3(), max.as_dvec3()),
                    Density::Constant(k * rho),
                ),
                Shape::Gaussian {
                    center,
                    sigma,
                    cutoff,
                } => {
                    let Some(chord) = Chord::new(o, d, k, center.as_dvec3()) else {
                        continue;
                    };
                    let s = sigma as f64;
                    let width = s / k;
                    let range = chord.within(cutoff as f64 * s).map(|(a, b)| {
                        let reach = GAUSSIAN_REACH * width;
                        (
                            a.max(chord.t_closest - reach),
                            b.min(chord.t_closest + reach),
                        )
                    });
                    let gaussian = Gaussian1d {
                        peak: k * rho * (-0.5 * chord.miss_squared / (s * s)).exp(),
                        centre: chord.t_closest,
                        width,
                    };
                    (range, Density::Gaussian(gaussian))
                }
            };
            let Some((t0, t1)) = range else { continue };
            let (t0, t1) = (t0.max(lo), t1.min(hi));
            if t0 < t1 {
                out.push(Segment {
                    t0,
                    t1,
                    density,
                    color: p.color.eval_f64(dir),
                });
            }
        }
    }
}

/// The line `o + t·d` relative to a centre `c`: `|o + t·d − c|² = k²(t − t*)² + b²`.
struct Chord {
    k: f64,
    /// `t*`, the closest approach.
    t_closest: f64,
    /// `b²`, the squared distance at the closest approach.
    miss_squared: f64,
}

impl Chord {
    fn new(o: DVec3, d: DVec3, k: f64, c: DVec3) -> Option<Chord> {
        let w = o - c;
        let t_closest = -w.dot(d) / (k * k);
        let miss_squared = (w + t_closest * d).length_squared();
        t_closest.is_finite().then_some(Chord {
            k,
            t_closest,
            miss_squared,
        })
    }

    /// The `t` interval within `radius` of the centre.
    fn within(&self, radius: f64) -> Option<(f64, f64)> {
        let gap = radius * radius - self.miss_squared;
        if gap.is_nan() || gap <= 0.0 {
            return None;
        }
        let half = gap.sqrt() / self.k;
        Some((self.t_closest - half, self.t_closest + half))
    }
}

/// The `t` interval where `o + t·d` lies in the box `[min, max]` (unbounded `t`).
fn slab(o: DVec3, d: DVec3, min: DVec3, max: DVec3) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for axis in 0..3 {
        if d[axis] == 0.0 {
            if o[axis] < min[axis] || o[axis] > max[axis] {
                return None;
            }
            continue;
        }
        let (a, b) = (
            (min[axis] - o[axis]) / d[axis],
            (max[axis] - o[axis]) / d[axis],
        );
        lo = lo.max(a.min(b));
        hi = hi.min(a.max(b));
    }
    (lo < hi).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chord_of_a_line_through_a_sphere() {
        // Field-space line (−5, 0.6, 0) + t·(2, 0, 0): k = 2, closest at x = 0 → t* = 2.5,
        // miss 0.6, so within radius 1 for |t − 2.5| ≤ √(1 − 0.36)/2 = 0.4.
        let c = Chord::new(
            DVec3::new(-5.0, 0.6, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            2.0,
            DVec3::ZERO,
        )
        .unwrap();
        assert!((c.t_closest - 2.5).abs() < 1e-15);
        assert!((c.miss_squared - 0.36).abs() < 1e-15);
        let (a, b) = c.within(1.0).unwrap();
        assert!(
            (a - 2.1).abs() < 1e-15 && (b - 2.9).abs() < 1e-15,
            "{a} {b}"
        );
        assert!(c.within(0.6).is_none());
    }

    #[test]
    fn slab_handles_axis_parallel_lines() {
        let min = DVec3::splat(-1.0);
        let max = DVec3::splat(1.0);
        let (a, b) = slab(DVec3::new(0.5, 0.5, -3.0), DVec3::Z, min, max).unwrap();
        assert!((a - 2.0).abs() < 1e-15 && (b - 4.0).abs() < 1e-15);
        assert!(slab(DVec3::new(1.5, 0.5, -3.0), DVec3::Z, min, max).is_none());
        // Negative direction: the interval is still ordered.
        let (a, b) = slab(DVec3::new(0.0, 0.0, 3.0), -0.5 * DVec3::Z, min, max).unwrap();
        assert!((a - 4.0).abs() < 1e-15 && (b - 8.0).abs() < 1e-15);
    }
}
