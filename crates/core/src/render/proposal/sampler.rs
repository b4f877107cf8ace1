//! nerfacto's own estimator at inference (nerfstudio's `ProposalNetworkSampler`): where the
//! main field is sampled along a ray, decided by the proposal density fields it was trained
//! with. Deterministic at inference (no jitter, no annealing).
//!
//! Distances `t` are in the field's frame from the ray's origin, between `near` and `far`
//! (nerfstudio: 0 — its collider resets the near plane at inference — and `far_plane`,
//! 1000). Sampling works in a *spacing* coordinate `s ∈ [0, 1]`:
//! `t(s) = g⁻¹(s·g(far) + (1 − s)·g(near))` with, for the default piecewise initial sampler,
//! `g(x) = x/2` for `x < 1` and `1 − 1/(2x)` beyond (uniform to distance 1, uniform in
//! disparity after), or `g(x) = x` for the uniform one.
//!
//! 1. Iteration 0 lays `N₀` (256) intervals between the edges `s_j = j/N₀`.
//! 2. Each interval `[t_j, t_{j+1}]` is sampled at its midpoint; with `δ_j = t_{j+1} − t_j`
//!    the weights are `w_j = (1 − e^{−σ_j δ_j})·e^{−Σ_{k<j} σ_k δ_k}` (`get_weights`: every
//!    δ is an interval's length, the last one too).
//! 3. The next iteration (`N₁` = 96, then the main field's 48) resamples by inverse CDF
//!    (`PDFSampler`, `include_original` false): `p_j = w_j + 0.01` (histogram padding),
//!    normalised (`+1e-5` spread over the bins if their sum falls below it),
//!    `c = [0, min(1, cumsum p)]`, `B = N + 1` edges at `u_k = (k + ½)/B`; for each, the
//!    first `i` with `c_i > u_k`, `lo = clamp(i − 1)`, `hi = clamp(i)` in `0..=N_prev`, and
//!    `s = s_lo + clip((u − c_lo)/(c_hi − c_lo), 0, 1)·(s_hi − s_lo)` (0/0 → 0, x/0 → 1).
//! 4. The last iteration's intervals are where the main field is sampled; its weights give
//!    the pixel.
//!
//! Two savings, both bounded: once a ray's transmittance falls below [`STOP_TRANSMITTANCE`]
//! its later samples are not evaluated (their weights are below it, beside a padding of
//! 0.01 per bin), and a ray's lightest main samples are not shaded as long as their weights
//! sum to at most [`COLOR_SKIP_BUDGET`] (colours lie in `[0, 1]`, so the pixel's
//! premultiplied colour in the trained space moves by at most that much per channel, the
//! scene-linear output by at most the sRGB decode's slope times that; accumulation and
//! depth not at all). The budget is nerfstudio's look, the same at every preset.

use std::ops::Range;
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};

use super::weights::{sanitised, weigh_run};
use crate::field::{DensityScratch, NerfactoField, ProposalNetworks};

/// Transmittance below which a ray's later samples are not evaluated.
pub const STOP_TRANSMITTANCE: f64 = 1e-6;
/// The most weight per ray that may go unshaded (its lightest main-field samples, black).
pub(crate) const COLOR_SKIP_BUDGET: f64 = 1e-5;
/// Samples per ray evaluated per round (front to back, so rays can stop early).
const ROUND: usize = 16;
/// `PDFSampler`'s histogram padding and `eps`.
const HISTOGRAM_PADDING: f64 = 0.01;
const PDF_EPS: f64 = 1e-5;

/// A ray to sample, in the field's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProposalRay {
    /// Origin (the camera).
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
    /// Where sampling starts and ends, field units from the origin.
    pub near: f64,
    /// See `near`.
    pub far: f64,
}

/// One main-field sample of a ray: the interval `[t0, t1]` (field units from the ray's
/// origin), its density and colour (trained space; black where not shaded).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProposalSample {
    /// Interval start.
    pub t0: f64,
    /// Interval end.
    pub t1: f64,
    /// Density per field unit.
    pub sigma: f32,
    /// Colour, as trained.
    pub rgb: [f32; 3],
}

/// What a batch of sampling did: queries and time in the proposal fields and the main field.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProposalStats {
    /// Proposal-field density queries.
    pub proposal_queries: u64,
    /// Main-field density queries.
    pub main_queries: u64,
    /// Main-field colour queries.
    pub color_queries: u64,
    /// Main-field samples whose density was NaN or infinite, taken as empty.
    pub(crate) invalid_samples: u64,
    /// Time in the proposal iterations (evaluation and resampling).
    pub proposal_time: Duration,
    /// Time in the main field (density, features, colour).
    pub main_time: Duration,
}

impl std::ops::AddAssign for ProposalStats {
    fn add_assign(&mut self, o: ProposalStats) {
        self.proposal_queries += o.proposal_queries;
        self.main_queries += o.main_queries;
        self.color_queries += o.color_queries;
        self.invalid_samples += o.invalid_samples;
        self.proposal_time += o.proposal_time;
        self.main_time += o.main_time;
    }
}

/// Reusable buffers for [`sample_proposals`].
#[derive(Clone, Debug, Default)]
pub struct ProposalScratch {
    /// Spacing edges (rows of `n + 1`) of this iteration and the last, and where each
    /// ray's row starts (iteration 0 has one row for every ray).
    edges: Vec<f64>,
    prev_edges: Vec<f64>,
    edge_rows: Vec<usize>,
    prev_edge_rows: Vec<usize>,
    /// Weights per ray (`n` each) of the last evaluated iteration, one ray's CDF of them,
    /// and where in it the next iteration's edges go.
    weights: Vec<f64>,
    cdf: Vec<f64>,
    quantiles: Vec<f64>,
    /// `(g(near), g(far))` per ray, the distances of this iteration's edges (rows of
    /// `n + 1`) and where each ray's row starts (rays with the same edges and span share
    /// one).
    span: Vec<[f64; 2]>,
    distances: Vec<f64>,
    distance_rows: Vec<usize>,
    /// Transmittance so far, per ray; rays still being evaluated.
    transmittance: Vec<f64>,
    live: Vec<u32>,
    points: Vec<Vec3>,
    sigma: Vec<f32>,
    features: Vec<f32>,
    density: DensityScratch,
    /// Main samples to shade: `(ray, sample)`, their features and directions, colours;
    /// per ray the weight below which its samples go unshaded.
    shade: Vec<(u32, u32)>,
    shade_cut: Vec<f64>,
    shade_features: Vec<f32>,
    dirs: Vec<Vec3>,
    rgb: Vec<Vec3>,
}

/// The `B` positions `u_k = (k + ½)/B` in the CDF at which [`resample`] places its edges.
fn quantiles(b: usize, out: &mut Vec<f64>) {
    out.clear();
    out.extend((0..b).map(|k| (k as f64 + 0.5) / b as f64));
}

/// `B` edges resampled by inverse CDF from `edges` (`n + 1`) and their `weights` (`n`) at
/// the [`quantiles`] `u` (`B` of them), appended to `out`; see the module's step 3. `cdf`
/// is scratch.
pub(crate) fn resample(
    edges: &[f64],
    weights: &[f64],
    u: &[f64],
    cdf: &mut Vec<f64>,
    out: &mut Vec<f64>,
) {
    let n = weights.len();
    let mut sum: f64 = weights.iter().map(|w| w + HISTOGRAM_PADDING).sum();
    let pad = (PDF_EPS - sum).max(0.0);
    sum += pad;
    let pad = pad / n as f64;
    // The CDF, with its leading 0: c[0] = 0, c[i] = min(1, Σ_{j<i} p_j).
    // The probabilities first (a loop without a carried sum, so its divisions run in
    // vectors), then their running sum in place.
    cdf.clear();
    cdf.push(0.0);
    cdf.extend(weights.iter().map(|w| (w + HISTOGRAM_PADDING + pad) / sum));
    let mut acc = 0.0;
    for c in &mut cdf[1..] {
        acc += *c;
        *c = acc.min(1.0);
    }
    let mut i = 0;
    for &u in u {
        // First index with c_i > u (u grows with k, so the search resumes).
        while i < cdf.len() && cdf[i] <= u {
            i += 1;
        }
        let lo = i.saturating_sub(1).min(n);
        let hi = i.min(n);
        let (c0, c1) = (cdf[lo], cdf[hi]);
        let t = if c1 - c0 > 0.0 {
            ((u - c0) / (c1 - c0)).clamp(0.0, 1.0)
        } else if u - c0 > 0.0 {
            1.0
        } else {
            0.0
        };
        out.push(edges[lo] + t * (edges[hi] - edges[lo]));
    }
}

/// Samples `rays` as nerfstudio does at inference and evaluates the main field there:
/// `pieces` receives `nerf_samples` pieces per ray, in order (those after a ray's
/// transmittance fell below [`STOP_TRANSMITTANCE`] with σ = 0). `None` when the run has
/// no proposal networks.
pub fn sample_proposals(
    field: &NerfactoField,
    rays: &[ProposalRay],
    pieces: &mut Vec<ProposalSample>,
    s: &mut ProposalScratch,
) -> Option<ProposalStats> {
    let sampler = field.proposal_networks()?;
    let mut stats = ProposalStats::default();
    let settings = sampler.settings();
    let iterations = settings.proposal_samples.len();
    let start = Instant::now();
    s.span.clear();
    s.span.extend(
        rays.iter()
            .map(|r| [sampler.spacing(r.near), sampler.spacing(r.far)]),
    );
    // Iteration 0: uniform in spacing, the same edges for every ray.
    let mut n = settings.proposal_samples[0];
    s.edges.clear();
    s.edges.extend((0..=n).map(|j| j as f64 / n as f64));
    s.edge_rows.clear();
    s.edge_rows.resize(rays.len(), 0);
    for level in 0..=iterations {
        if level > 0 {
            let b = if level < iterations {
                settings.proposal_samples[level]
            } else {
                settings.nerf_samples
            } + 1;
            std::mem::swap(&mut s.edges, &mut s.prev_edges);
            std::mem::swap(&mut s.edge_rows, &mut s.prev_edge_rows);
            s.edges.clear();
            s.edge_rows.clear();
            s.edge_rows.extend((0..rays.len()).map(|r| r * b));
            quantiles(b, &mut s.quantiles);
            for r in 0..rays.len() {
                let row = s.prev_edge_rows[r];
                resample(
                    &s.prev_edges[row..row + n + 1],
                    &s.weights[r * n..(r + 1) * n],
                    &s.quantiles,
                    &mut s.cdf,
                    &mut s.edges,
                );
            }
            n = b - 1;
        }
        s.distances.clear();
        s.distance_rows.clear();
        for (r, ray) in rays.iter().enumerate() {
            // Iteration 0's edges are the same for every ray: so are its distances on
            // rays of the same span (most often all of them), kept once.
            let row = s.edge_rows[r];
            if r > 0
                && row == s.edge_rows[r - 1]
                && (ray.near, ray.far) == (rays[r - 1].near, rays[r - 1].far)
            {
                s.distance_rows.push(s.distance_rows[r - 1]);
                continue;
            }
            s.distance_rows.push(s.distances.len());
            let span = s.span[r];
            let mut prev = ray.near;
            for &e in &s.edges[row..row + n + 1] {
                // Kept within the ray's span and in order (rounding in `g⁻¹`).
                let t = sampler.distance(e, span).clamp(prev, ray.far);
                s.distances.push(t);
                prev = t;
            }
        }
        if level < iterations {
            stats.proposal_queries += weigh(sampler, level, rays, n, s);
        }
    }
    stats.proposal_time = start.elapsed();
    let start = Instant::now();
    shade_main(field, rays, n, pieces, s, &mut stats);
    stats.main_time = start.elapsed();
    Some(stats)
}

/// Interval `j` of ray `r` of the current iteration.
#[inline]
fn interval(s: &ProposalScratch, r: usize, j: usize) -> (f64, f64) {
    let at = s.distance_rows[r] + j;
    (s.distances[at], s.distances[at + 1])
}

/// Evaluates proposal iteration `level` (`n` intervals per ray) front to back, filling
/// `s.weights`; returns the queries made.
fn weigh(
    sampler: &ProposalNetworks,
    level: usize,
    rays: &[ProposalRay],
    n: usize,
    s: &mut ProposalScratch,
) -> u64 {
    let net = sampler.net(level);
    let mut queries = 0;
    s.weights.clear();
    s.weights.resize(rays.len() * n, 0.0);
    s.transmittance.clear();
    s.transmittance.resize(rays.len(), 1.0);
    s.live.clear();
    s.live.extend(0..rays.len() as u32);
    let mut first = 0;
    while !s.live.is_empty() && first < n {
        let last = (first + ROUND).min(n);
        s.lay_midpoints(rays, first..last);
        s.sigma.resize(s.points.len(), 0.0);
        net.density(&s.points, &mut s.sigma, &mut s.density);
        queries += s.points.len() as u64;
        for (&r, sigma) in s.live.iter().zip(s.sigma.chunks_exact(last - first)) {
            let r = r as usize;
            weigh_run(
                sigma,
                &s.distances[s.distance_rows[r]..][first..=last],
                &mut s.transmittance[r],
                &mut s.weights[r * n + first..r * n + last],
            );
        }
        let transmittance = &s.transmittance;
        s.live
            .retain(|&r| transmittance[r as usize] >= STOP_TRANSMITTANCE);
        first = last;
    }
    queries
}

/// Evaluates the main field on the final intervals (`n` per ray) front to back and shades
/// the samples whose weight matters.
fn shade_main(
    field: &NerfactoField,
    rays: &[ProposalRay],
    n: usize,
    pieces: &mut Vec<ProposalSample>,
    s: &mut ProposalScratch,
    stats: &mut ProposalStats,
) {
    let n_geo = field.geometry_features();
    let base = pieces.len();
    pieces.resize(base + rays.len() * n, ProposalSample::default());
    for r in 0..rays.len() {
        for j in 0..n {
            let (t0, t1) = interval(s, r, j);
            pieces[base + r * n + j] = ProposalSample {
                t0,
                t1,
                ..ProposalSample::default()
            };
        }
    }
    s.weights.clear();
    s.weights.resize(rays.len() * n, 0.0);
    s.transmittance.clear();
    s.transmittance.resize(rays.len(), 1.0);
    s.live.clear();
    s.live.extend(0..rays.len() as u32);
    s.shade.clear();
    s.shade_features.clear();
    s.dirs.clear();
    let mut first = 0;
    while !s.live.is_empty() && first < n {
        let last = (first + ROUND).min(n);
        s.lay_midpoints(rays, first..last);
        s.sigma.resize(s.points.len(), 0.0);
        s.features.resize(s.points.len() * n_geo, 0.0);
        field.density_features_unbounded(&s.points, &mut s.sigma, &mut s.features);
        stats.main_queries += s.points.len() as u64;
        let runs = s.live.iter().zip(s.sigma.chunks_exact(last - first));
        for (i, (&r, sigma)) in runs.enumerate() {
            let r = r as usize;
            let weights = &mut s.weights[r * n + first..r * n + last];
            weigh_run(
                sigma,
                &s.distances[s.distance_rows[r]..][first..=last],
                &mut s.transmittance[r],
                weights,
            );
            for (j, (&sigma, &w)) in (first..).zip(sigma.iter().zip(weights.iter())) {
                stats.invalid_samples += u64::from(!sigma.is_finite());
                pieces[base + r * n + j].sigma = sanitised(sigma) as f32;
                if w > 0.0 {
                    let k = i * (last - first) + j - first;
                    s.shade.push((r as u32, j as u32));
                    s.shade_features
                        .extend_from_slice(&s.features[k * n_geo..(k + 1) * n_geo]);
                    s.dirs.push(rays[r].dir.as_vec3());
                }
            }
        }
        let transmittance = &s.transmittance;
        s.live
            .retain(|&r| transmittance[r as usize] >= STOP_TRANSMITTANCE);
        first = last;
    }
    s.skip_lightest(n, n_geo);
    s.rgb.clear();
    s.rgb.resize(s.shade.len(), Vec3::ZERO);
    field.colour(&s.shade_features, &s.dirs, &mut s.rgb);
    stats.color_queries += s.shade.len() as u64;
    for (&(r, j), c) in s.shade.iter().zip(&s.rgb) {
        pieces[base + r as usize * n + j as usize].rgb = c.to_array();
    }
}
impl ProposalScratch {
    /// The midpoints of samples `samples` of the live rays (of this iteration), ray after
    /// ray, into `points`.
    fn lay_midpoints(&mut self, rays: &[ProposalRay], samples: Range<usize>) {
        self.points.clear();
        for &r in &self.live {
            let ray = &rays[r as usize];
            let t = &self.distances[self.distance_rows[r as usize]..][samples.start..=samples.end];
            self.points.extend(
                t.windows(2)
                    .map(|t| (ray.origin + ray.dir * (0.5 * (t[0] + t[1]))).as_vec3()),
            );
        }
    }

    /// Drops from the samples to shade each ray's lightest ones, as many as keep their
    /// summed weight within [`COLOR_SKIP_BUDGET`] (`weights`: `n` per ray; `n_geo` features
    /// per sample). Kept samples stay in order, so their colours do not change.
    fn skip_lightest(&mut self, n: usize, n_geo: usize) {
        self.shade_cut.clear();
        for w in self.weights.chunks_exact(n) {
            // Only samples lighter than the budget can go unshaded (when all of them fit,
            // the cut is the budget).
            self.cdf.clear();
            self.cdf
                .extend(w.iter().copied().filter(|&w| w < COLOR_SKIP_BUDGET));
            let cut = lightest_within(&mut self.cdf, COLOR_SKIP_BUDGET);
            self.shade_cut.push(cut.min(COLOR_SKIP_BUDGET));
        }
        let mut kept = 0;
        for k in 0..self.shade.len() {
            let (r, j) = self.shade[k];
            if self.weights[r as usize * n + j as usize] < self.shade_cut[r as usize] {
                continue;
            }
            self.shade[kept] = self.shade[k];
            self.dirs[kept] = self.dirs[k];
            self.shade_features
                .copy_within(k * n_geo..(k + 1) * n_geo, kept * n_geo);
            kept += 1;
        }
        self.shade.truncate(kept);
        self.dirs.truncate(kept);
        self.shade_features.truncate(kept * n_geo);
    }
}

/// The weight `c` such that the weights below it sum to at most `budget`: the first of
/// them, smallest first, that would take the sum past it (infinite when all fit). `weights`
/// is reordered.
///
/// Example: weights `(0.3, 1e-6, 2e-6, 0.5)` and budget `1e-5` give `0.3` (the two light
/// ones sum to `3·10⁻⁶`).
fn lightest_within(weights: &mut [f64], budget: f64) -> f64 {
    weights.sort_unstable_by(f64::total_cmp);
    let mut sum = 0.0;
    for &w in weights.iter() {
        sum += w;
        if sum > budget {
            return w;
        }
    }
    f64::INFINITY
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resampling_uniform_weights_keeps_the_edges_spread() {
        // Equal weights: the CDF is linear, so B edges land at (k + ½)/B of the span.
        let edges: Vec<f64> = (0..=4).map(|j| j as f64 / 4.0).collect();
        let mut out = Vec::new();
        let mut u = Vec::new();
        quantiles(5, &mut u);
        resample(&edges, &[0.25; 4], &u, &mut Vec::new(), &mut out);
        for (k, e) in out.iter().enumerate() {
            assert!((e - (k as f64 + 0.5) / 5.0).abs() < 1e-12, "{k}: {e}");
        }
    }

    #[test]
    fn resampling_concentrates_edges_where_the_weight_is() {
        // All weight in bin 2 of 4 (plus the padding 0.01 each): p = (0.01, 0.01, 1.01,
        // 0.01)/1.04; the 9 edges at u = (k + ½)/9 from k = 1 to 7 fall inside [0.5, 0.75].
        let edges: Vec<f64> = (0..=4).map(|j| j as f64 / 4.0).collect();
        let mut out = Vec::new();
        let mut u = Vec::new();
        quantiles(9, &mut u);
        resample(&edges, &[0.0, 0.0, 1.0, 0.0], &u, &mut Vec::new(), &mut out);
        let c1 = 0.02 / 1.04;
        // u = 1/18 lies in bin 2: 0.5 + 0.25·(u − c1)/(1.01/1.04).
        let want = 0.5 + 0.25 * (1.0 / 18.0 - c1) / (1.01 / 1.04);
        assert!((out[0] - want).abs() < 1e-12, "{} {want}", out[0]);
        assert!(out[1..8].iter().all(|&e| (0.5..=0.75).contains(&e)));
        assert!(out.windows(2).all(|w| w[0] <= w[1]));
    }

    #[test]
    fn the_lightest_samples_within_the_budget_go_unshaded() {
        // The doc's example: 1e-6 + 2e-6 fit in 1e-5, 0.3 does not.
        let mut w = [0.3, 1e-6, 2e-6, 0.5];
        assert_eq!(lightest_within(&mut w, 1e-5), 0.3);
        // Equal weights: those below the cut sum to at most the budget (4·3e-6 ≤ 1.3e-5
        // < 5·3e-6), and ties at the cut are all kept.
        let mut w = [3e-6; 8];
        assert_eq!(lightest_within(&mut w, 1.3e-5), 3e-6);
        // Everything fits: nothing is shaded; no samples: nothing to cut.
        assert_eq!(lightest_within(&mut [1e-6, 0.0], 1e-5), f64::INFINITY);
        assert_eq!(lightest_within(&mut [], 1e-5), f64::INFINITY);
    }

    #[test]
    fn skipped_samples_sum_within_the_budget() {
        // Seeded weights of 5 rays × 48 samples spanning 1e-9 to 1: the samples dropped
        // from the shading list are each ray's lightest and weigh at most the budget.
        let n = 48;
        let mut seed = 7u64;
        let mut s = ProposalScratch::default();
        for _ in 0..5 * n {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            s.weights
                .push(10f64.powf(-9.0 * (seed >> 11) as f64 / (1u64 << 53) as f64));
        }
        for (r, j) in (0..5u32).flat_map(|r| (0..n as u32).map(move |j| (r, j))) {
            s.shade.push((r, j));
            s.shade_features.extend([r as f32, j as f32]);
            s.dirs.push(Vec3::splat(r as f32));
        }
        s.skip_lightest(n, 2);
        assert_eq!(s.shade_features.len(), 2 * s.shade.len());
        for r in 0..5 {
            let w = &s.weights[r * n..(r + 1) * n];
            let kept: Vec<u32> = s
                .shade
                .iter()
                .filter(|k| k.0 == r as u32)
                .map(|k| k.1)
                .collect();
            let skipped: f64 = (0..n as u32)
                .filter(|j| !kept.contains(j))
                .map(|j| w[j as usize])
                .sum();
            assert!(skipped <= COLOR_SKIP_BUDGET, "ray {r}: {skipped}");
            assert!(skipped > 0.0 && kept.len() < n, "ray {r}: nothing skipped");
            let lightest_kept = kept.iter().map(|&j| w[j as usize]).fold(1.0, f64::min);
            assert!((0..n).all(|j| kept.contains(&(j as u32)) || w[j] <= lightest_kept));
        }
        // The kept samples keep their order and their features.
        assert!(s.shade.windows(2).all(|p| p[0] < p[1]));
        for (k, &(r, j)) in s.shade.iter().enumerate() {
            assert_eq!(s.shade_features[2 * k..2 * k + 2], [r as f32, j as f32]);
            assert_eq!(s.dirs[k], Vec3::splat(r as f32));
        }
    }
}
