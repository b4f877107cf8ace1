//! Scenes of analytic fields integrated in closed form, ray by ray, instead of marched.
//!
//! Along a ray every primitive of every instance is a support interval of world distance
//! with a density profile there, constant or a 1-D Gaussian
//! ([`Analytic::profiles`](crate::field::Analytic)); its colour depends on the view
//! direction only, so it is evaluated once per ray. Between consecutive interval ends the
//! same primitives are present: the ray is swept piece by piece, front to back.
//!
//! - A piece of constant densities (total `K`, colour `Σkᵢcᵢ/K`) is exact:
//!   weight `T(1 − e^{−Kℓ})` and its depth moment ([`RunningComposite::add`]).
//! - A piece holding a Gaussian has a closed-form optical depth (erf), so its weight
//!   `w = T_a − T_b` is exact too, and so is its colour when it holds one primitive alone.
//!   Where they can change the pixel by more than the error target allows
//!   ([`GaussianPiece::integrate`]), the colour split `∫T Σσᵢcᵢ dt` between several primitives and
//!   the depth moment (by parts, `∫ₐᵇ tσT dt = a·w + ∫ₐᵇ T dt − (b − a)·T_b`) come from
//!   Gauss–Legendre panels ([`GaussianPiece::quadrature`]); the split is scaled so that its weight
//!   is the exact one. A piece thin enough (small optical depth `τ`), or whose total density
//!   changes little over it, has both in closed form: the split as the profiles' optical
//!   depths' ratio, `∫T dt` from the integral of the optical depth or the weight over the
//!   densities, each off by a bound (in `τ`, in the densities' range) that is checked
//!   against the target. The panels' nodes take a rough `erfc` (a rational fit) where its
//!   error, bounded, is within a hundredth of what they are held to.
//! - Median depth: where `1 − T(t) = A/2`, `A` the ray's final alpha, found in the piece that
//!   crosses it, exactly in a constant piece, by safeguarded Newton steps on the closed-form
//!   optical depth in a Gaussian one, held (relative) to the share of the error target the
//!   expected depth is held to ([`median_resolution`]).
//!
//! A ray stops once what is left of it cannot change its pixel by more than a thousandth of
//! the preset's error target ([`stop_transmittance`]). Pixels are written with the marcher's
//! conventions: premultiplied linear colour, infinite depths where nothing was accumulated.

mod gaussian_piece;

use glam::DVec3;

use self::gaussian_piece::{GaussianPiece, Integral, Sums};
use super::deep::{finish_pixel, DeepScratch, DeepTile, RawPiece};
use super::integrator::srgb_composite_to_linear;
use super::integrator::RunningComposite;
use super::march::{cull_instances, may_meet, DeepPass, InstancePlan, PixelResult, RayCone};
use super::{MarchParams, Outputs, RenderSettings, RenderStats};
use crate::camera::{Camera, Ray};
use crate::field::{Anchor, Density, Profile};
use crate::image::Window;

/// How close to it a median depth is found at the finest, relative: below the resolution of
/// the `f32` it is written as.
const MEDIAN_RESOLUTION: f64 = 1e-9;

/// How close to it a ray's median depth is found, relative, with `error_target`: within the
/// share of it that the expected depth is held to ([`gaussian_piece::DEPTH_SHARE`]), as a depth is
/// judged by one measure whichever of the two it is; never finer than
/// [`MEDIAN_RESOLUTION`]. Each Newton step of a Gaussian piece's median costs an error
/// function per profile, so a coarser preset's median takes fewer.
fn median_resolution(error_target: f32) -> f64 {
    (gaussian_piece::DEPTH_SHARE * f64::from(error_target)).max(MEDIAN_RESOLUTION)
}

/// Per-thread scratch reused from tile to tile: no allocation per ray.
#[derive(Default)]
pub(super) struct ClosedScratch {
    rays: Vec<Option<Ray>>,
    /// The instances some ray of the tile may meet, and per instance
    /// (`prims[prim_at[j]..prim_at[j + 1]]`) the primitives it may meet.
    insts: Vec<u32>,
    prims: Vec<u32>,
    prim_at: Vec<u32>,
    ray: RayScratch,
    deep: DeepScratch,
}

/// What one ray's integration works in.
#[derive(Default)]
struct RayScratch {
    /// The profiles the ray meets, and each one's colour along it.
    profiles: Vec<Profile>,
    colours: Vec<DVec3>,
    /// Their ends, sorted.
    ends: Vec<f64>,
    /// The profiles present in the current piece, and their anchors at its start.
    active: Vec<u32>,
    anchors: Vec<Anchor>,
    /// The pieces composited, for the median depth.
    log: Vec<Logged>,
    /// A deep render: the pieces composited, with their weights and colours.
    deep: Option<Vec<RawPiece>>,
    /// The logged Gaussian piece that `active` and `anchors` still describe, if any: the
    /// median's solve takes them as they are when its piece is that one (a ray's last).
    anchored: Option<usize>,
    /// Panels waiting to be integrated: `(p, q, the sums taken for them if the ray's node
    /// budget runs out)`.
    panels: Vec<(f64, f64, Sums)>,
}

/// Integrates one tile in closed form. `out` receives the tile's pixels row by row, and
/// `deep`'s tile their deep samples where it is given.
#[allow(clippy::too_many_arguments)]
pub(super) fn integrate_tile(
    plans: &[InstancePlan],
    camera: &Camera,
    tile: Window,
    settings: &RenderSettings,
    s: &mut ClosedScratch,
    out: &mut Vec<PixelResult>,
    mut deep: Option<(&DeepPass, &mut DeepTile)>,
) -> RenderStats {
    camera.window_rays(tile, &mut s.rays);
    let cone = RayCone::of(&s.rays, tile.width() as usize, camera.rectilinear());
    cull_instances(plans, cone.as_ref(), &mut s.insts);
    s.prims.clear();
    s.prim_at.clear();
    s.prim_at.push(0);
    for &i in &s.insts {
        let count = plans[i as usize]
            .instance
            .handle()
            .as_analytic()
            .map_or(0, |a| a.primitives.len());
        s.prims
            .extend(plans[i as usize].primitives_met(count, cone.as_ref()));
        s.prim_at.push(s.prims.len() as u32);
    }
    let mut stats = RenderStats {
        pixels: tile.area() as u64,
        ..RenderStats::default()
    };
    let ctx = Context {
        plans,
        insts: &s.insts,
        prims: &s.prims,
        prim_at: &s.prim_at,
        params: &settings.march,
        outputs: &settings.outputs,
    };
    out.clear();
    if let Some((_, tile_out)) = &mut deep {
        tile_out.clear();
    }
    for ray in &s.rays {
        match &mut s.ray.deep {
            Some(pieces) => pieces.clear(),
            None if deep.is_some() => s.ray.deep = Some(Vec::new()),
            None => {}
        }
        let px = match ray {
            Some(ray) => ctx.integrate(ray, &mut s.ray, &mut stats),
            None => finish(&RunningComposite::new(), DVec3::ZERO, 1.0, f64::INFINITY),
        };
        if let (Some((pass, tile_out)), Some(pieces)) = (&mut deep, &s.ray.deep) {
            let rgb = if pass.decode {
                srgb_composite_to_linear(px.rgb, px.alpha)
            } else {
                px.rgb
            };
            let z_per_t = ray.as_ref().map_or(1.0, |r| r.z_per_t);
            finish_pixel(
                pieces,
                z_per_t,
                rgb,
                pass.decode,
                &pass.params,
                &mut s.deep,
                tile_out,
            );
        }
        out.push(px);
    }
    if deep.is_none() {
        s.ray.deep = None;
    }
    stats
}

/// What every ray of a tile shares.
struct Context<'a> {
    plans: &'a [InstancePlan<'a>],
    insts: &'a [u32],
    prims: &'a [u32],
    prim_at: &'a [u32],
    params: &'a MarchParams,
    outputs: &'a Outputs,
}

impl Context<'_> {
    /// One ray's pixel.
    fn integrate(&self, ray: &Ray, s: &mut RayScratch, stats: &mut RenderStats) -> PixelResult {
        self.gather(ray, s);
        stats.color_samples += s.profiles.len() as u64;
        let mut pieces = RunningComposite::new();
        let mut rgb = DVec3::ZERO;
        if s.profiles.is_empty() {
            return finish(&pieces, rgb, ray.z_per_t, f64::INFINITY);
        }
        s.ends.clear();
        for p in &s.profiles {
            s.ends.extend([p.enter, p.exit]);
        }
        insertion_sort(&mut s.ends);
        let brightest = s.colours.iter().fold(1.0f64, |m, c| m.max(c.max_element()));
        let stop = stop_transmittance(self.params.error_target, brightest);
        let depth = self.outputs.depth_ray || self.outputs.depth_z;
        let mut budget = Budget {
            left: self.params.max_samples,
            exhausted: false,
        };
        s.log.clear();
        s.anchored = None;
        for e in 1..s.ends.len() {
            let (a, b) = (s.ends[e - 1], s.ends[e]);
            if b <= a {
                continue;
            }
            present(&s.profiles, a, b, &mut s.active);
            s.anchored = None;
            if s.active.is_empty() {
                continue;
            }
            stats.density_samples += 1;
            let t_enter = pieces.transmittance();
            let (optical_depth, density) = match constant(&s.profiles, &s.colours, &s.active) {
                Some((k, colour)) => {
                    let w = pieces.add(a, b - a, k);
                    rgb += w * colour;
                    if let Some(deep) = &mut s.deep {
                        deep.push(RawPiece {
                            t0: a,
                            t1: b,
                            weight: w,
                            rgb: w * colour,
                        });
                    }
                    (k * (b - a), Some(k))
                }
                None => {
                    let piece =
                        GaussianPiece::new(a, &s.profiles, &s.colours, &s.active, &mut s.anchors);
                    let Integral {
                        optical_depth,
                        weight,
                        colour,
                        moment,
                    } = piece.integrate(
                        b,
                        self.params.error_target,
                        depth,
                        &mut budget,
                        &mut s.panels,
                    );
                    rgb += t_enter * colour;
                    pieces.add_integrated(t_enter * weight, t_enter * moment);
                    if let Some(deep) = &mut s.deep {
                        deep.push(RawPiece {
                            t0: a,
                            t1: b,
                            weight: t_enter * weight,
                            rgb: t_enter * colour,
                        });
                    }
                    s.anchored = Some(s.log.len());
                    (optical_depth, None)
                }
            };
            if self.outputs.depth_median {
                s.log.push(Logged {
                    a,
                    b,
                    t_a: t_enter,
                    t_b: pieces.transmittance(),
                    optical_depth,
                    density,
                });
            }
            if pieces.transmittance() <= stop {
                break;
            }
        }
        let median = if self.outputs.depth_median {
            let resolution = median_resolution(self.params.error_target);
            median_depth(s, pieces.accumulation(), resolution, &mut budget)
        } else {
            f64::INFINITY
        };
        stats.density_samples += u64::from(self.params.max_samples - budget.left);
        stats.budget_limited_rays += u64::from(budget.exhausted);
        finish(&pieces, rgb, ray.z_per_t, median)
    }

    /// The profiles (and their colours) of every primitive the ray meets, in the tile's
    /// instances, clipped to each instance's bounds, crop and the camera's near and far.
    fn gather(&self, ray: &Ray, s: &mut RayScratch) {
        s.profiles.clear();
        s.colours.clear();
        for (j, &i) in self.insts.iter().enumerate() {
            let (inst, plan) = (self.plans[i as usize].instance, &self.plans[i as usize]);
            let prims = &self.prims[self.prim_at[j] as usize..self.prim_at[j + 1] as usize];
            let Some(analytic) = inst.handle().as_analytic() else {
                continue;
            };
            if prims.is_empty() || !may_meet(plan, ray) {
                continue;
            }
            let Some(line) = inst.local_line(ray, ray.near, ray.far) else {
                continue;
            };
            let first = s.profiles.len();
            analytic.profiles(
                &line.line,
                line.units_per_world,
                [line.t_near, line.t_far],
                prims.iter().copied(),
                &mut s.profiles,
            );
            let dir = line.dir.as_vec3();
            for p in &s.profiles[first..] {
                let colour = analytic.primitives[p.index as usize].color.eval(dir);
                s.colours.push(colour.as_dvec3());
            }
        }
    }
}

/// The transmittance below which a ray stops: what is left of it can change its alpha by at
/// most that and its colour by at most that times its brightest primitive's colour
/// (`brightest ≥ 1`), which this keeps within a thousandth of the error target.
fn stop_transmittance(error_target: f32, brightest: f64) -> f64 {
    1e-3 * f64::from(error_target) / brightest
}

/// Lists in `active` the profiles present all over `[a, b]`.
#[inline]
fn present(profiles: &[Profile], a: f64, b: f64, active: &mut Vec<u32>) {
    active.clear();
    active.extend((0..profiles.len() as u32).filter(|&h| {
        let p = &profiles[h as usize];
        p.enter <= a && p.exit >= b
    }));
}

/// Sorts a handful of numbers in place (a ray meets a few primitives).
fn insertion_sort(v: &mut [f64]) {
    for i in 1..v.len() {
        let x = v[i];
        let mut j = i;
        while j > 0 && v[j - 1] > x {
            v[j] = v[j - 1];
            j -= 1;
        }
        v[j] = x;
    }
}

/// The pixel of a composited ray, as the marcher writes it.
fn finish(pieces: &RunningComposite, rgb: DVec3, z_per_t: f64, median: f64) -> PixelResult {
    let depth = pieces.expected_depth();
    PixelResult {
        rgb: rgb.as_vec3().to_array(),
        alpha: pieces.accumulation() as f32,
        depth_ray: depth as f32,
        depth_z: (depth * z_per_t) as f32,
        depth_median: median as f32,
    }
}

/// A ray's quadrature and Newton nodes left ([`MarchParams::max_samples`]), and whether a
/// quadrature stopped for want of them.
struct Budget {
    left: u32,
    exhausted: bool,
}

impl Budget {
    /// Takes `n` nodes; false when they are not there (nothing is taken then).
    fn take(&mut self, n: u32) -> bool {
        if self.left >= n {
            self.left -= n;
            true
        } else {
            false
        }
    }
}

/// A piece composited, as the median depth takes it: where it lies, the transmittance on
/// either side, its optical depth, and its density where that is constant.
#[derive(Clone, Copy, Debug)]
struct Logged {
    a: f64,
    b: f64,
    t_a: f64,
    t_b: f64,
    optical_depth: f64,
    density: Option<f64>,
}

/// Where the accumulation reaches half the final alpha `alpha`: in the first logged piece
/// that leaves the ray at `T ≤ 1 − A/2`, where its optical depth reaches `ln(T_a/(1 − A/2))`,
/// to within `resolution` of the piece's far end (relative). `inf` when nothing was
/// accumulated.
fn median_depth(s: &mut RayScratch, alpha: f64, resolution: f64, budget: &mut Budget) -> f64 {
    let t_star = 1.0 - 0.5 * alpha;
    if alpha.is_nan() || alpha <= 0.0 {
        return f64::INFINITY;
    }
    let Some(at) = s.log.iter().position(|piece| piece.t_b <= t_star) else {
        return f64::INFINITY;
    };
    let Logged {
        a,
        b,
        t_a,
        optical_depth,
        density,
        ..
    } = s.log[at];
    if t_a <= t_star {
        return a;
    }
    let depth = half_logarithm(t_a / t_star);
    if let Some(k) = density {
        return (a + depth / k).min(b);
    }
    let piece = if s.anchored == Some(at) {
        GaussianPiece::anchored(a, &s.profiles, &s.colours, &s.active, &s.anchors)
    } else {
        present(&s.profiles, a, b, &mut s.active);
        GaussianPiece::new(a, &s.profiles, &s.colours, &s.active, &mut s.anchors)
    };
    piece.depth_reaching(depth, b, optical_depth, resolution * b, budget)
}

/// `ln x`, without the logarithm where `x` is within 1e-8 of 2 (a ray that goes opaque in
/// the piece it enters with `T = 1`, whose median is where `T` halves): there
/// `ln 2 + (x/2 − 1)` is within `(x/2 − 1)²/2 ≤ 5e-17` of it, below rounding.
#[inline]
fn half_logarithm(x: f64) -> f64 {
    let off = 0.5 * x - 1.0;
    if off.abs() <= 1e-8 {
        std::f64::consts::LN_2 + off
    } else {
        x.ln()
    }
}

/// The total density and density-weighted colour of the profiles `active` when every one
/// of them is constant.
fn constant(profiles: &[Profile], colours: &[DVec3], active: &[u32]) -> Option<(f64, DVec3)> {
    let (mut k, mut colour) = (0.0, DVec3::ZERO);
    for &h in active {
        let Density::Constant(density) = profiles[h as usize].density else {
            return None;
        };
        k += density;
        colour += density * colours[h as usize];
    }
    Some((k, colour / k))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within an ulp of `ln` near 2, on either side of where it stops taking the logarithm,
    /// and `ln` itself elsewhere.
    #[test]
    fn half_logarithm_is_the_logarithm() {
        for k in -200..=200 {
            let x = 2.0 + f64::from(k) * 1e-10;
            let (got, want) = (half_logarithm(x), x.ln());
            assert!(
                (got - want).abs() <= f64::EPSILON * want,
                "{x}: {got} vs {want}"
            );
        }
        // Where `ln 2 + (x/2 − 1)` would be off by more than an ulp.
        for x in [
            1.0,
            1.5,
            2.0 - 1e-4,
            2.0 - 1e-6,
            2.0 + 1e-6,
            2.0 + 1e-4,
            3.0,
            1e-300,
            7.5e9,
        ] {
            assert_eq!(half_logarithm(x), x.ln());
        }
        assert_eq!(half_logarithm(2.0), std::f64::consts::LN_2);
        assert!(half_logarithm(f64::NAN).is_nan());
    }
}
