//! Scenes of analytic fields integrated in closed form, ray by ray, instead of marched.
//!
//! Along a ray every primitive of every instance is a support interval of world distance
//! with a density profile there, constant or a 1-D Gaussian
//! ([`Analytic::profiles`](crate::field::Analytic)); its colour depends on the view
//! direction only, so it is evaluated once per ray. Between consecutive interval ends the
//! same primitives are present: the ray is swept piece by piece, front to back.
//!
//! - A piece of constant densities (total `K`, colour `Σkᵢcᵢ/K`) is exact:
//!   weight `T(1 − e^{−Kℓ})` and its depth moment ([`Pieces::add`]).
//! - A piece holding a Gaussian has a closed-form optical depth (erf), so its weight
//!   `w = T_a − T_b` is exact too, and so is its colour when it holds one primitive alone.
//!   Where they can change the pixel by more than the error target allows
//!   ([`Piece::integrate`]), the colour split `∫T Σσᵢcᵢ dt` between several primitives and
//!   the depth moment (by parts, `∫ₐᵇ tσT dt = a·w + ∫ₐᵇ T dt − (b − a)·T_b`) come from
//!   Gauss–Legendre panels ([`Piece::quadrature`]); the split is scaled so that its weight
//!   is the exact one.
//! - Median depth: where `1 − T(t) = A/2`, `A` the ray's final alpha, found in the piece that
//!   crosses it, exactly in a constant piece, by safeguarded Newton steps on the closed-form
//!   optical depth in a Gaussian one.
//!
//! A ray stops once what is left of it cannot change its pixel by more than a thousandth of
//! the preset's error target ([`stop_transmittance`]). Pixels are written with the marcher's
//! conventions: premultiplied linear colour, infinite depths where nothing was accumulated.

use glam::DVec3;

use super::composite::{opacity, Pieces};
use super::march::{cull_instances, may_meet, Bundle, InstancePlan, PixelResult};
use super::{MarchParams, Outputs, RenderSettings, RenderStats};
use crate::camera::{Camera, Ray};
use crate::field::{Anchor, Density, Profile};
use crate::image::Window;
use crate::scene::Scene;

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

/// How close to it a median depth is found, relative: below the resolution of the `f32` it
/// is written as.
const MEDIAN_RESOLUTION: f64 = 1e-9;

/// What share of the error target the expected depth is held to, relative: the target
/// bounds alpha and colour, and the marcher's depths at Draft and Preview are off by about
/// a fifth of it (relative), which the closed form does not do worse than.
const DEPTH_SHARE: f64 = 0.125;

/// A Gaussian piece is integrated only up to where its light has all but gone
/// ([`Piece::integrate`]) once its optical depth is this many times what that takes.
const OPAQUE: f64 = 4.0;

/// Bisections of a Gaussian piece at most: 48 halvings take a piece of a world unit below
/// 1e-14, past any profile's scale.
const MAX_BISECTIONS: u32 = 48;

/// Newton steps at most when solving for a depth inside a piece: far more than a solve takes,
/// as each step is either at most half the one before or a bisection of the bracket.
const MAX_NEWTON_STEPS: u32 = 64;

/// Whether `scene` is integrated in closed form with `params`: the dial is on, every
/// instance's field is analytic, and nothing else (splats, trainer-sampled instances) is in
/// it.
pub(super) fn applies(scene: &Scene, params: &MarchParams) -> bool {
    params.closed_form
        && scene.splats.is_empty()
        && !scene.has_sampled()
        && scene
            .instances
            .iter()
            .all(|inst| inst.handle().as_analytic().is_some())
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
    /// The pieces composited, `(a, b, T_a, T_b)`, for the median depth.
    log: Vec<[f64; 4]>,
    /// Panels waiting to be integrated: `(p, q, the sums taken for them if the ray's node
    /// budget runs out)`.
    panels: Vec<(f64, f64, Sums)>,
}

/// Integrates one tile in closed form. `out` receives the tile's pixels row by row.
pub(super) fn integrate_tile(
    scene: &Scene,
    plans: &[InstancePlan],
    camera: &Camera,
    tile: Window,
    settings: &RenderSettings,
    s: &mut ClosedScratch,
    out: &mut Vec<PixelResult>,
) -> RenderStats {
    camera.window_rays(tile, &mut s.rays);
    let bundle = Bundle::of(&s.rays);
    cull_instances(plans, bundle.as_ref(), &mut s.insts);
    s.prims.clear();
    s.prim_at.clear();
    s.prim_at.push(0);
    for &i in &s.insts {
        let spheres = plans[i as usize].primitive_spheres();
        let count = scene.instances[i as usize]
            .handle()
            .as_analytic()
            .map_or(0, |a| a.primitives.len());
        s.prims.extend((0..count as u32).filter(|&k| {
            // No sphere (a field of many primitives, or one not finite): kept.
            let sphere = spheres.get(k as usize).copied().flatten();
            match (&bundle, sphere) {
                (Some(bundle), Some(sphere)) => bundle.may_meet(sphere),
                _ => true,
            }
        }));
        s.prim_at.push(s.prims.len() as u32);
    }
    let mut stats = RenderStats {
        pixels: tile.area() as u64,
        ..RenderStats::default()
    };
    let ctx = Context {
        scene,
        plans,
        insts: &s.insts,
        prims: &s.prims,
        prim_at: &s.prim_at,
        params: &settings.march,
        outputs: &settings.outputs,
    };
    out.clear();
    for ray in &s.rays {
        out.push(match ray {
            Some(ray) => ctx.integrate(ray, &mut s.ray, &mut stats),
            None => finish(&Pieces::new(), DVec3::ZERO, 1.0, f64::INFINITY),
        });
    }
    stats
}

/// What every ray of a tile shares.
struct Context<'a> {
    scene: &'a Scene,
    plans: &'a [InstancePlan],
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
        let mut pieces = Pieces::new();
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
        for e in 1..s.ends.len() {
            let (a, b) = (s.ends[e - 1], s.ends[e]);
            if b <= a {
                continue;
            }
            s.active.clear();
            s.active.extend(
                (0..s.profiles.len() as u32).filter(|&h| covers(&s.profiles[h as usize], a, b)),
            );
            if s.active.is_empty() {
                continue;
            }
            stats.density_samples += 1;
            let t_enter = pieces.transmittance();
            match constant(&s.profiles, &s.colours, &s.active) {
                Some((k, colour)) => {
                    let w = pieces.add(a, b - a, k);
                    rgb += w * colour;
                }
                None => {
                    let piece = Piece::new(a, &s.profiles, &s.colours, &s.active, &mut s.anchors);
                    let (w, colour, moment) = piece.integrate(
                        b,
                        self.params.error_target,
                        depth,
                        &mut budget,
                        &mut s.panels,
                    );
                    rgb += t_enter * colour;
                    pieces.add_integrated(t_enter * w, t_enter * moment);
                }
            }
            if self.outputs.depth_median {
                s.log.push([a, b, t_enter, pieces.transmittance()]);
            }
            if pieces.transmittance() <= stop {
                break;
            }
        }
        let median = if self.outputs.depth_median {
            median_depth(s, pieces.accumulation(), &mut budget)
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
            let (inst, plan) = (&self.scene.instances[i as usize], &self.plans[i as usize]);
            let Some(analytic) = inst.handle().as_analytic() else {
                continue;
            };
            if !may_meet(plan, ray) {
                continue;
            }
            let Some(local) = inst.local_ray(ray, ray.near, ray.far) else {
                continue;
            };
            // The line in f64 (the local ray keeps its origin and direction in f32, for
            // samples): `velocity` is field units per world unit, unnormalised.
            let field_from_world = inst.field_from_world();
            let velocity = field_from_world.transform_vector3(ray.dir);
            let origin = field_from_world.transform_point3(ray.origin) + local.t_near * velocity;
            let first = s.profiles.len();
            let prims = &self.prims[self.prim_at[j] as usize..self.prim_at[j + 1] as usize];
            analytic.profiles(
                origin,
                velocity,
                [local.t_near, local.t_far],
                prims.iter().copied(),
                &mut s.profiles,
            );
            for p in &s.profiles[first..] {
                let colour = analytic.primitives[p.index as usize].color.eval(local.dir);
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

/// Whether profile `p` is present all over `[a, b]`.
#[inline]
fn covers(p: &Profile, a: f64, b: f64) -> bool {
    p.enter <= a && p.exit >= b
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
fn finish(pieces: &Pieces, rgb: DVec3, z_per_t: f64, median: f64) -> PixelResult {
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

/// Where the accumulation reaches half the final alpha `alpha`: in the first logged piece
/// that leaves the ray at `T ≤ 1 − A/2`, where its optical depth reaches `ln(T_a/(1 − A/2))`.
/// `inf` when nothing was accumulated.
fn median_depth(s: &mut RayScratch, alpha: f64, budget: &mut Budget) -> f64 {
    let t_star = 1.0 - 0.5 * alpha;
    if alpha.is_nan() || alpha <= 0.0 {
        return f64::INFINITY;
    }
    let Some(&[a, b, t_a, _]) = s.log.iter().find(|piece| piece[3] <= t_star) else {
        return f64::INFINITY;
    };
    if t_a <= t_star {
        return a;
    }
    let profiles = &s.profiles;
    s.active.clear();
    s.active
        .extend((0..profiles.len() as u32).filter(|&h| covers(&profiles[h as usize], a, b)));
    let depth = (t_a / t_star).ln();
    match constant(profiles, &s.colours, &s.active) {
        Some((k, _)) => (a + depth / k).min(b),
        None => Piece::new(a, profiles, &s.colours, &s.active, &mut s.anchors).depth_reaching(
            depth,
            b,
            MEDIAN_RESOLUTION * b,
            budget,
        ),
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

/// One piece `[a, b]` of a ray: the profiles present all over it, and their anchors at `a`.
struct Piece<'a> {
    a: f64,
    profiles: &'a [Profile],
    colours: &'a [DVec3],
    active: &'a [u32],
    anchors: &'a [Anchor],
}

/// A Gaussian piece's integrals from `a`, relative to the transmittance it is entered with:
/// colour `∫T Σσᵢcᵢ dt`, weight `∫σT dt` and transmittance `∫T dt`.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    rgb: DVec3,
    weight: f64,
    transmittance: f64,
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

impl<'a> Piece<'a> {
    /// The piece from `a` of the profiles `active`, their anchors worked out into `anchors`.
    fn new(
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
        Piece {
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
    #[inline]
    fn sample(&self, t: f64) -> (f64, DVec3, f64) {
        let (mut sigma, mut rgb, mut depth) = (0.0, DVec3::ZERO, 0.0);
        for ((p, c), anchor) in self.each().zip(self.anchors) {
            let (s, d) = p.density.sample_from(anchor, self.a, t);
            sigma += s;
            rgb += s * c;
            depth += d;
        }
        (sigma, rgb, depth)
    }

    /// The piece's weight `1 − e^{−τ}`, colour and depth moment (`∫tσT dt`), relative to
    /// the transmittance it is entered with. The weight is exact, and so is the colour of a
    /// profile alone. The rest comes from [`quadrature`](Self::quadrature) held to the error
    /// target where it can matter: a colour split only where the profiles' colours differ by
    /// more than the target (any split is off by at most that spread), the moment (asked for
    /// with `depth`) only where half the piece's length is more than [`DEPTH_SHARE`] of the
    /// target times `a` (the mean depth inside it lies between `a` and `b`, so its middle is
    /// off by at most that half). Else the colour is the density-weighted one at the middle, the moment the
    /// middle's.
    fn integrate(
        &self,
        b: f64,
        error_target: f32,
        depth: bool,
        budget: &mut Budget,
        panels: &mut Vec<(f64, f64, Sums)>,
    ) -> (f64, DVec3, f64) {
        let tau = self.sample(b).2;
        let w = opacity(tau);
        if w.is_nan() || w <= 0.0 {
            return (0.0, DVec3::ZERO, 0.0);
        }
        let target = f64::from(error_target);
        let middle = 0.5 * (self.a + b);
        let split = self.spread() > target;
        let moment = depth && b - middle > DEPTH_SHARE * target * self.a;
        // Any mean of the colours is within their spread; a density that underflows at
        // the middle (a blob's far tail) leaves the plain mean.
        let mix = || {
            let (sigma, rgb, _) = self.sample(middle);
            if sigma > 0.0 {
                rgb / sigma
            } else {
                self.each().map(|(_, c)| c).sum::<DVec3>() / self.active.len() as f64
            }
        };
        if !split && !moment {
            return (w, w * mix(), w * middle);
        }
        // Where the optical depth passes `cut`, 1e-3 of the target is left. A piece far
        // more opaque than that (σ of 1e9) is integrated up to there only: its light comes
        // from a sliver at its start, which panels over the whole piece could all miss.
        let cut = (1e3 / target).ln();
        let end = if tau > OPAQUE * cut {
            self.depth_reaching(cut, b, 1e-2 * (b - self.a), budget)
        } else {
            b
        };
        let sums = self.quadrature(end, target * w, split, moment, budget, panels);
        // Scaled to the exact weight; every node underflowing (the budget ran out at once)
        // leaves the middle's colour.
        let colour = if split && sums.weight > 0.0 {
            (w / sums.weight) * sums.rgb
        } else {
            w * mix()
        };
        // By parts, from `T` alone (which falls smoothly from 1, where `σT` may be a sharp
        // bell); past `end` the light left is taken at `end`.
        let moment = if moment {
            let by_parts = sums.transmittance - (end - self.a) * (1.0 - w);
            self.a * w + by_parts.clamp(0.0, (b - self.a) * w)
        } else {
            w * middle
        };
        (w, colour, moment)
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
    fn node(&self, t: f64) -> Sums {
        let (sigma, rgb, depth) = self.sample(t);
        let transmittance = (-depth).exp();
        let weight = transmittance * sigma;
        Sums {
            rgb: transmittance * rgb,
            weight,
            transmittance,
        }
    }

    /// The 3- and 4-point Gauss–Legendre sums over `[p, q]`.
    fn panel(&self, p: f64, q: f64) -> (Sums, Sums) {
        let (mid, half) = (0.5 * (p + q), 0.5 * (q - p));
        let rule = |nodes: &[f64], weights: &[f64]| {
            let mut sum = Sums::default();
            for (x, w) in nodes.iter().zip(weights) {
                let n = self.node(mid + half * x);
                sum.rgb += w * n.rgb;
                sum.weight += w * n.weight;
                sum.transmittance += w * n.transmittance;
            }
            Sums {
                rgb: half * sum.rgb,
                weight: half * sum.weight,
                transmittance: half * sum.transmittance,
            }
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
    /// latter marks the ray budget-limited).
    fn quadrature(
        &self,
        end: f64,
        tolerance: f64,
        colour: bool,
        depth: bool,
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
            let (three, four) = self.panel(p, q);
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
                let half = Sums {
                    rgb: 0.5 * four.rgb,
                    weight: 0.5 * four.weight,
                    transmittance: 0.5 * four.transmittance,
                };
                panels.push((p, m, half));
                panels.push((m, q, half));
            }
        }
        total
    }

    /// Where in `[a, b]` the optical depth from `a` reaches `depth` (`b` if it does not), to
    /// within `resolution`: Newton steps on the closed-form optical depth, kept inside a
    /// bracket that each step narrows, bisecting where a step would leave it or would not
    /// halve the one before (a Newton step can bounce between the two sides of a density's
    /// sharp rise).
    fn depth_reaching(&self, depth: f64, b: f64, resolution: f64, budget: &mut Budget) -> f64 {
        let total = self.sample(b).2;
        if total.is_nan() || total <= depth {
            return b;
        }
        let (mut lo, mut hi) = (self.a, b);
        let mut t = self.a + (b - self.a) * (depth / total);
        let mut step = hi - lo;
        for _ in 0..MAX_NEWTON_STEPS {
            if !budget.take(1) {
                budget.exhausted = true;
                break;
            }
            let (sigma, _, reached) = self.sample(t);
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
