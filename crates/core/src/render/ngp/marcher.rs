//! instant-ngp's own marcher at inference, as an estimator: where a snapshot is sampled
//! along a ray, and how its samples composite, as instant-ngp's viewer renders it
//! (`render_nerf` in `fused_kernels/render_nerf.cuh`, the unfused `NerfTracer` of
//! `testbed_nerf.cu`, the stepping rules of `nerf_device.cuh`).
//!
//! Everything here is in instant-ngp's coordinates (its unit cube; field lengths times the
//! dataset scale `s`), `t` measured from the camera along the unit direction.
//!
//! - **Step.** `dt = clamp(t·c, √3/1024, √3)` in effect, through instant-ngp's *stepping
//!   space* (`to_stepping_space`, `from_stepping_space`): with `c` the cone angle (0 when
//!   `aabb_scale ≤ 1`, else 1/256), `ℓ = ln(1 + c)`, `t_a = (√3/1024)/ℓ` and `t_b = √3/ℓ`,
//!   the step index is `n(t) = (t − t_a)/(√3/1024) + a` below `t_a`, `ln t/ℓ` between, and
//!   `(t − t_b)/√3 + b` beyond `t_b` (`a = ln t_a/ℓ`, `b = ln t_b/ℓ`); a step is
//!   `dt = t(n(t) + 1) − t` (`calc_dt`): `√3/1024` near the camera, then `t·c` (the next
//!   sample at `t·(1 + c)`), at most `√3` (`MAX_CONE_STEPSIZE`, the width of a cell of the
//!   coarsest of 8 cascades). With `c = 0`, `n(t) = t/(√3/1024)`.
//! - **Start.** At `max(t_entry, 0) + 10⁻⁶`, the entry into the render box. The viewer
//!   jitters this start by a random fraction of a step per frame (`ld_random_val`) and
//!   averages frames; nerfx renders the unjittered march.
//! - **Occupancy.** A point's cascade is `mip = clamp(e + 1, 0, max_cascade)` with `e` the
//!   binary exponent of `max|q − 0.5|` (`frexp`: `m·2^e`, `m ∈ [0.5, 1)`; `mip_from_pos`),
//!   read in the marching bitfield (see `cascades`). In an occupied cell the marcher takes a
//!   sample at `t` with the step `dt` and moves to `t + dt`. In an empty one it climbs to
//!   the coarsest cascade whose cell there is still empty, finds the distance `δ` to that
//!   cell's exit (`distance_to_next_voxel`: per axis to the next cell plane in the ray's
//!   direction, the smallest), and jumps a whole number of steps in stepping space:
//!   `t ← t(n + ⌈max(n(t + δ) − n, ½)⌉)` (`advance_to_next_voxel`), so samples stay on the
//!   ray's grid of steps. The march ends when `t` reaches 16384 (`MAX_DEPTH`) or the point
//!   leaves the render box. Those jumps reach the first step whose point is occupied (every
//!   step they pass lies in an empty cell), so where the cascades' OR pyramid proves a long
//!   stretch empty nerfx jumps straight to the first step past it: the same samples, in
//!   fewer moves.
//! - **Alpha.** `α = 1 − exp(−σ·dt)` with σ the density network's `exp` output per
//!   instant-ngp unit and `dt` in instant-ngp units (the same optical depth as the field's
//!   `σ_field·dt/s`), composited front to back: `w = α·T`, `T = 1 − Σw`. Colours composite
//!   as the network gives them: sRGB-encoded for a snapshot trained on photographs
//!   (the viewer converts the composite to linear after), linear for an HDR one.
//! - **Early stop.** Once the accumulated alpha exceeds `1 − 0.01` (`min_transmittance`,
//!   0.01 by default) the colour and alpha are divided by it (alpha becomes 1) and the ray
//!   ends. Delivered as samples to composite with other instances, this is: every colour
//!   of the ray divided by that alpha `A`, and the last sample opaque with colour
//!   `α_last·c_last/A`; composited alone they give instant-ngp's pixel exactly.
//! - **Cap.** The unfused tracer stops after 10000 steps (`MARCH_ITER`, counted in rounds of
//!   1 to 8); the fused kernel has no cap. A ray inside a box of `aabb_scale ≤ 128` takes
//!   fewer than 2000 steps (1024 along the unit cube's diagonal at `aabb_scale` 1:
//!   `NERF_STEPS` per `√3`), so the cap bounds work on malformed input only; rays that
//!   reach it are counted ([`NgpStats::capped`]).
//!
//! Arithmetic is f64 here (positions go to the networks as f32); instant-ngp's f32 stepping
//! is not reproduced bit for bit.

use glam::{DVec3, Vec3};

use crate::field::{exp_density, Cascades, ColourScratch, IngpField, DENSITY_OUTPUTS};

/// `STEPSIZE()`: `√3/1024`, the finest step (`NERF_STEPS` of them span the unit cube's
/// diagonal).
const MIN_STEP: f64 = 1.732_050_807_568_877_2 / 1024.0;
/// `MAX_CONE_STEPSIZE()`: the width of a cell of the coarsest of 8 cascades, `√3`.
const MAX_STEP: f64 = MIN_STEP * 1024.0;
/// The cone angle of snapshots with `aabb_scale > 1`.
const CONE_ANGLE: f64 = 1.0 / 256.0;
/// `MAX_DEPTH()`.
const MAX_DEPTH: f64 = 16384.0;
/// The offset past the render box's entry where the march starts.
const ENTRY_OFFSET: f64 = 1e-6;
/// `render_min_transmittance`, the viewer's default.
const MIN_TRANSMITTANCE: f64 = 0.01;
/// Steps after which a ray ends (`MARCH_ITER`).
pub const NGP_MAX_STEPS: usize = 10_000;
/// Samples lighter than this (alone, before the early stop's renormalisation) are not
/// shaded; their colour is black.
const COLOR_MIN_WEIGHT: f64 = 1e-6;
/// Samples a live ray lays per round (rays stop early: few are wasted).
const ROUND: usize = 16;
/// Cells per axis of a cascade.
const GRID: f64 = 128.0;
/// The first stretch the empty-space skip tries, in cells of the coarsest empty cascade.
const SKIP_CELLS: f64 = 8.0;

/// A ray to march, in the field's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NgpRay {
    /// Origin (the camera).
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
    /// Where the ray enters the field's box (and crop), field units from the origin.
    pub near: f64,
    /// Where it leaves it.
    pub far: f64,
}

/// One sample to composite: at `t` (field units from the ray's origin), of opacity `alpha`
/// and colour `rgb` (trained space), the early stop's renormalisation folded in.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NgpSample {
    /// Where instant-ngp takes the sample: the start of its step.
    pub t: f64,
    /// `1 − exp(−σ·dt)`; 1 for the last sample of a ray stopped at 99 %.
    pub alpha: f32,
    /// Colour, as trained.
    pub rgb: [f32; 3],
}

/// What a batch of marching did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NgpStats {
    /// Rays marched.
    pub(crate) rays: u64,
    /// Samples taken (density queries).
    pub samples: u64,
    /// Colour queries.
    pub(crate) color_queries: u64,
    /// Rays that stopped at 99 % accumulation.
    pub opaque: u64,
    /// Rays that reached the step cap.
    pub capped: u64,
    /// Samples whose density was NaN, taken as empty.
    pub(crate) invalid: u64,
}

impl std::ops::AddAssign for NgpStats {
    fn add_assign(&mut self, o: NgpStats) {
        self.rays += o.rays;
        self.samples += o.samples;
        self.color_queries += o.color_queries;
        self.opaque += o.opaque;
        self.capped += o.capped;
        self.invalid += o.invalid;
    }
}

/// Reusable buffers for [`march_ngp`].
#[derive(Default)]
pub struct NgpScratch {
    rays: Vec<RayMarch>,
    live: Vec<u32>,
    /// This round's samples: owner ray, `t` (instant-ngp units), `dt`.
    laid: Vec<(u32, f64, f64)>,
    xs: Vec<Vec3>,
    enc: Vec<f32>,
    outputs: Vec<f32>,
    /// Samples to shade: (ray, index in its output), their network outputs, directions.
    shade: Vec<(u32, u32)>,
    shade_outputs: Vec<f32>,
    dirs: Vec<Vec3>,
    rgb: Vec<Vec3>,
    colour: ColourScratch,
}

/// One ray's march in instant-ngp coordinates.
#[derive(Clone, Copy, Debug, Default)]
struct RayMarch {
    origin: DVec3,
    dir: DVec3,
    /// The next position to step from, and where the ray leaves the box.
    t: f64,
    far: f64,
    steps: usize,
    /// Accumulated alpha.
    acc: f64,
    done: bool,
}

/// instant-ngp's stepping space for one cone angle.
#[derive(Clone, Copy, Debug)]
struct Stepping {
    cone: f64,
    ln1p: f64,
    a: f64,
    b: f64,
    ta: f64,
    tb: f64,
}

impl Stepping {
    fn new(cone: f64) -> Self {
        let ln1p = cone.ln_1p();
        let a = (MIN_STEP.ln() - ln1p.ln()) / ln1p;
        let b = (MAX_STEP.ln() - ln1p.ln()) / ln1p;
        Stepping {
            cone,
            ln1p,
            a,
            b,
            ta: (a * ln1p).exp(),
            tb: (b * ln1p).exp(),
        }
    }

    /// `to_stepping_space`.
    fn steps(&self, t: f64) -> f64 {
        if self.cone <= 1e-5 {
            t / MIN_STEP
        } else if t <= self.ta {
            (t - self.ta) / MIN_STEP + self.a
        } else if t <= self.tb {
            t.ln() / self.ln1p
        } else {
            (t - self.tb) / MAX_STEP + self.b
        }
    }

    /// `from_stepping_space`.
    fn distance(&self, n: f64) -> f64 {
        if self.cone <= 1e-5 {
            n * MIN_STEP
        } else if n <= self.a {
            (n - self.a) * MIN_STEP + self.ta
        } else if n <= self.b {
            (n * self.ln1p).exp()
        } else {
            (n - self.b) * MAX_STEP + self.tb
        }
    }

    /// `calc_dt`: one step from `t`.
    fn dt(&self, t: f64) -> f64 {
        self.distance(self.steps(t) + 1.0) - t
    }

    /// `advance_to_next_voxel`: from `t` at `pos` past the exit of its cell of cascade `mip`,
    /// by a whole number (≥ 1) of steps.
    fn past_cell(&self, t: f64, pos: DVec3, dir: DVec3, mip: usize) -> f64 {
        let res = GRID / f64::from(1u32 << mip.min(31));
        let p = (pos - 0.5) * res;
        let mut exit = f64::INFINITY;
        for k in 0..3 {
            if dir[k] != 0.0 {
                let plane = (p[k] + 0.5 + 0.5 * dir[k].signum()).floor();
                exit = exit.min((plane - p[k]) / dir[k]);
            }
        }
        let target = t + (exit / res).max(0.0);
        let (n, m) = (self.steps(t), self.steps(target));
        self.distance(n + (m - n).max(0.5).ceil())
    }
}

/// `mip_from_pos`: the cascade of `q`, `clamp(e + 1, 0, max_mip)` with `max|q − 0.5| = m·2^e`,
/// `m ∈ [0.5, 1)` (`e = 0` for 0, as `frexp` gives).
fn mip_from_pos(q: DVec3, max_mip: usize) -> usize {
    let m = (q - 0.5).abs().max_element();
    let e = if m == 0.0 || !m.is_finite() {
        0
    } else {
        ((m.to_bits() >> 52) & 0x7ff) as i64 - 1022
    };
    (e + 1).clamp(0, max_mip as i64) as usize
}

/// The cone angle instant-ngp marches this snapshot with: 0 for `aabb_scale ≤ 1`, else
/// 1/256.
fn cone_angle(field: &IngpField) -> f64 {
    if field.aabb_scale() <= 1.0 {
        0.0
    } else {
        CONE_ANGLE
    }
}

/// `if_unoccupied_advance_to_next_occupied_voxel`: the first occupied position at or
/// after `r.t`, or `None` when the ray leaves the box first.
fn next_occupied(cascades: &Cascades, r: &RayMarch, stepping: &Stepping) -> Option<f64> {
    let max_mip = cascades.count().saturating_sub(1);
    let mut t = r.t;
    loop {
        if t >= MAX_DEPTH || t > r.far {
            return None;
        }
        let pos = r.origin + r.dir * t;
        let q = pos.to_array();
        let mut mip = mip_from_pos(pos, max_mip);
        if cascades.march_occupied(q, mip) {
            return Some(t);
        }
        while mip < max_mip && !cascades.march_occupied(q, mip + 1) {
            mip += 1;
        }
        let cell = f64::from(1u32 << mip.min(31)) / GRID;
        t = match empty_until(cascades, r, t, SKIP_CELLS * cell) {
            // Every step point before `end` is empty: the first at or past it, as
            // instant-ngp's jumps from empty cell to empty cell would reach.
            Some(end) => {
                let (n, m) = (stepping.steps(t), stepping.steps(end));
                stepping.distance(n + (m - n).max(0.5).ceil())
            }
            None => stepping.past_cell(t, pos, r.dir, mip),
        };
    }
}

/// Where a stretch of the ray from `t` that the occupancy pyramid proves empty ends,
/// trying `len` first and doubling while the next stretch is empty too; `None` when the
/// first is not. (A speed-up only: instant-ngp walks the same stretch one coarsest empty
/// cell at a time, and lands on the same step.)
fn empty_until(cascades: &Cascades, r: &RayMarch, t: f64, mut len: f64) -> Option<f64> {
    let mut end = t;
    while end <= r.far {
        let (a, b) = (r.origin + r.dir * end, r.origin + r.dir * (end + len));
        if cascades.may_be_occupied(a.min(b).as_vec3(), a.max(b).as_vec3()) {
            break;
        }
        end += len;
        len *= 2.0;
    }
    (end > t).then_some(end)
}

/// Marches `rays` as instant-ngp's viewer does (see the module doc), each for at most
/// `max_steps` steps (the renderer passes [`NGP_MAX_STEPS`]): `out[i]` (cleared)
/// receives ray `i`'s samples front to back. Field queries are batched across the rays,
/// a round of steps at a time.
pub fn march_ngp(
    field: &IngpField,
    rays: &[NgpRay],
    max_steps: usize,
    out: &mut [Vec<NgpSample>],
    s: &mut NgpScratch,
) -> NgpStats {
    let stepping = Stepping::new(cone_angle(field));
    let scale = f64::from(field.ngp_scale());
    let mut stats = NgpStats {
        rays: rays.len() as u64,
        ..NgpStats::default()
    };
    s.rays.clear();
    s.live.clear();
    for (i, (ray, o)) in rays.iter().zip(out.iter_mut()).enumerate() {
        o.clear();
        let origin = field.ngp_from_field_f64(ray.origin);
        let dir = DVec3::new(ray.dir.y, ray.dir.z, ray.dir.x);
        let near = scale * ray.near.max(0.0) + ENTRY_OFFSET;
        let far = scale * ray.far;
        s.rays.push(RayMarch {
            origin,
            dir,
            t: near,
            far,
            ..RayMarch::default()
        });
        if near <= far && dir.is_finite() && origin.is_finite() {
            s.live.push(i as u32);
        }
    }
    while !s.live.is_empty() {
        // Lay each live ray's next steps.
        s.laid.clear();
        for &i in &s.live {
            let r = &mut s.rays[i as usize];
            for _ in 0..ROUND {
                let Some(t) = next_occupied(field.cascades(), r, &stepping) else {
                    r.done = true;
                    break;
                };
                // Capped only with a step left to take.
                if r.steps >= max_steps {
                    r.done = true;
                    stats.capped += 1;
                    break;
                }
                let dt = stepping.dt(t);
                s.laid.push((i, t, dt));
                r.t = t + dt;
                r.steps += 1;
            }
        }
        stats.samples += s.laid.len() as u64;
        evaluate_laid(field, rays, s);
        // Composite them in order, each ray to 99 %.
        s.shade.clear();
        s.shade_outputs.clear();
        s.dirs.clear();
        let mut at = 0;
        while at < s.laid.len() {
            let i = s.laid[at].0;
            let end = at + s.laid[at..].iter().take_while(|l| l.0 == i).count();
            let r = &mut s.rays[i as usize];
            let o = &mut out[i as usize];
            for k in at..end {
                if r.acc > 1.0 - MIN_TRANSMITTANCE {
                    break;
                }
                let (_, t, dt) = s.laid[k];
                // A NaN density (an overflowed network) is empty, and counted.
                let sigma = exp_density(s.outputs[k * DENSITY_OUTPUTS]);
                let sigma = if sigma.is_nan() {
                    stats.invalid += 1;
                    0.0
                } else {
                    sigma
                };
                let alpha = -(-f64::from(sigma) * dt).exp_m1();
                let weight = alpha * (1.0 - r.acc);
                r.acc += weight;
                if weight >= COLOR_MIN_WEIGHT {
                    s.shade.push((i, o.len() as u32));
                    s.shade_outputs.extend_from_slice(
                        &s.outputs[k * DENSITY_OUTPUTS..(k + 1) * DENSITY_OUTPUTS],
                    );
                    s.dirs.push(rays[i as usize].dir.as_vec3());
                }
                o.push(NgpSample {
                    t: t / scale,
                    alpha: alpha as f32,
                    rgb: [0.0; 3],
                });
            }
            if r.acc > 1.0 - MIN_TRANSMITTANCE {
                r.done = true;
                stats.opaque += 1;
            }
            at = end;
        }
        shade_laid(field, out, s);
        stats.color_queries += s.shade.len() as u64;
        let done = &s.rays;
        s.live.retain(|&i| !done[i as usize].done);
    }
    for (r, o) in s.rays.iter().zip(out.iter_mut()) {
        if r.acc > 1.0 - MIN_TRANSMITTANCE {
            renormalise(o, r.acc);
        }
    }
    stats
}

/// The density network's outputs at this round's samples, into `s.outputs`. The marcher
/// has already found each in an occupied cell: the network's density is used as it is.
fn evaluate_laid(field: &IngpField, rays: &[NgpRay], s: &mut NgpScratch) {
    let scale = f64::from(field.ngp_scale());
    s.xs.clear();
    s.xs.extend(s.laid.iter().map(|&(i, t, _)| {
        let ray = &rays[i as usize];
        let p = (ray.origin + ray.dir * (t / scale)).as_vec3();
        field.grid_point(p)
    }));
    let (xs, enc, outputs) = (&s.xs, &mut s.enc, &mut s.outputs);
    field.density_network(xs, enc, outputs);
}

/// Colours of the samples in `s.shade`, written into their place in `out`.
fn shade_laid(field: &IngpField, out: &mut [Vec<NgpSample>], s: &mut NgpScratch) {
    if s.shade.is_empty() {
        return;
    }
    s.rgb.clear();
    s.rgb.resize(s.shade.len(), Vec3::ZERO);
    field.colour(&s.shade_outputs, &s.dirs, &mut s.rgb, &mut s.colour);
    for (&(i, k), c) in s.shade.iter().zip(&s.rgb) {
        out[i as usize][k as usize].rgb = c.to_array();
    }
}

/// The early stop's renormalisation of a ray's samples composited to alpha `acc`: every
/// colour divided by `acc`, the last sample opaque carrying its own weight's share.
fn renormalise(samples: &mut [NgpSample], acc: f64) {
    let inv = (1.0 / acc) as f32;
    for s in samples.iter_mut() {
        s.rgb = s.rgb.map(|c| c * inv);
    }
    if let Some(last) = samples.last_mut() {
        last.rgb = last.rgb.map(|c| c * last.alpha);
        last.alpha = 1.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_grow_with_the_cone_and_are_clamped() {
        let flat = Stepping::new(0.0);
        for t in [0.0, 0.3, 5.0, 900.0] {
            assert!((flat.dt(t) - MIN_STEP).abs() < 1e-12);
        }
        let cone = Stepping::new(CONE_ANGLE);
        // Near the camera: the finest step; then t·c (the next sample at t·(1 + c)); far
        // away: √3.
        assert!((cone.dt(0.1) - MIN_STEP).abs() < 1e-12);
        let t = 10.0;
        assert!((cone.dt(t) - t * CONE_ANGLE).abs() < 1e-9 * t);
        assert!((cone.dt(2000.0) - MAX_STEP).abs() < 1e-9);
        // The regimes join: steps are continuous where they meet.
        for edge in [cone.ta, cone.tb] {
            let (below, above) = (cone.dt(edge * (1.0 - 1e-9)), cone.dt(edge * (1.0 + 1e-9)));
            assert!((below - above).abs() < 1e-6 * above, "{below} {above}");
        }
        for n in [-3.0, 0.5, 700.0, 2000.0, 3000.0] {
            assert!((cone.steps(cone.distance(n)) - n).abs() < 1e-9 * n.abs().max(1.0));
        }
    }

    #[test]
    fn jumps_past_a_cell_land_on_the_step_grid() {
        let flat = Stepping::new(0.0);
        // From t = 3 steps at x = 0.5 (a cell edge of cascade 0) along +x: the cell's exit
        // is one cell (1/128) ahead, 4.5 steps: the jump is ⌈4.5⌉ = 5 steps.
        let t = 3.0 * MIN_STEP;
        let next = flat.past_cell(t, DVec3::new(0.5, 0.3, 0.3), DVec3::X, 0);
        assert!((next - 8.0 * MIN_STEP).abs() < 1e-12, "{}", next / MIN_STEP);
        // Cascade 2's cells are 4/128 wide.
        let next = flat.past_cell(0.0, DVec3::new(0.5, 0.3, 0.3), DVec3::X, 2);
        assert!((next - (4.0 / 128.0 / MIN_STEP).ceil() * MIN_STEP).abs() < 1e-12);
        // Already at the exit: at least one step (n + ⌈½⌉).
        let next = flat.past_cell(0.0, DVec3::new(0.5, 0.3, 0.3), -DVec3::X, 0);
        assert!((next - MIN_STEP).abs() < 1e-12);
    }

    #[test]
    fn cascades_follow_the_binary_exponent() {
        let at = |m: f64| mip_from_pos(DVec3::new(0.5 + m, 0.5, 0.5), 7);
        assert_eq!(at(0.0), 1); // frexp(0) has exponent 0
        assert_eq!(at(0.2), 0);
        assert_eq!(at(0.499), 0);
        assert_eq!(at(0.5), 1);
        assert_eq!(at(-0.75), 1);
        assert_eq!(at(1.0), 2);
        assert_eq!(at(100.0), 7);
        assert_eq!(mip_from_pos(DVec3::splat(9.0), 2), 2);
    }

    #[test]
    fn renormalising_composites_to_the_divided_pixel() {
        let mut s = vec![
            NgpSample {
                t: 1.0,
                alpha: 0.9,
                rgb: [0.2, 0.4, 0.6],
            },
            NgpSample {
                t: 2.0,
                alpha: 0.95,
                rgb: [1.0, 0.5, 0.0],
            },
        ];
        // Alone: colour 0.9·c₀ + 0.1·0.95·c₁, alpha 0.995.
        let acc = 0.9 + 0.1 * 0.95;
        let want: Vec<f64> = (0..3)
            .map(|k| (0.9 * f64::from(s[0].rgb[k]) + 0.095 * f64::from(s[1].rgb[k])) / acc)
            .collect();
        renormalise(&mut s, acc);
        let mut transmittance = 1.0f64;
        let mut colour = [0.0f64; 3];
        for f in &s {
            for (c, v) in colour.iter_mut().zip(f.rgb) {
                *c += transmittance * f64::from(f.alpha) * f64::from(v);
            }
            transmittance *= 1.0 - f64::from(f.alpha);
        }
        assert_eq!(transmittance, 0.0);
        for (c, w) in colour.iter().zip(&want) {
            assert!((c - w).abs() < 1e-6, "{colour:?} {want:?}");
        }
    }
}
