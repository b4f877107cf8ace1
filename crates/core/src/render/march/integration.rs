//! Integration: a round's nodes composited into pieces, merged with fragments, in order.

use glam::Vec3;

use super::refinement::{change, larger_side, step_curvature, trapezoid_bias, LastDifference};
use super::{DeepPiece, Node, RayState, NO_NODE, PENDING_NODE};
use crate::render::deep::RawPiece;
use crate::render::fragment::Fragment;
use crate::render::integrator::far_share;
use crate::render::splats::MIN_TRANSMITTANCE as SPLAT_MIN_TRANSMITTANCE;
use crate::render::{MarchParams, Outputs};

/// What the error rule aims a step's weighted error estimate at, as a fraction of the target
/// ([`allowed_step`]): the curvature ahead is estimated from the round behind, and a step
/// whose own estimate exceeds the target is bisected, so the curvature may double from the
/// one to the other before a step costs a bisection (a tighter aim lays more samples for no
/// gain the presets need; the guide's benchmark history has the measurements).
const STEP_SAFETY: f64 = 2.0;

/// Composites a ray's nodes, in order, until it is opaque enough; distributes each piece's
/// weight to its two nodes as the light it sends comes from along it ([`far_share`]: a thin
/// piece's from all along it, an opaque one's from its near end).
pub(super) fn integrate(
    state: &mut RayState,
    nodes: &mut [Node],
    params: &MarchParams,
    outputs: &Outputs,
    empty_is_known: bool,
    budget_limited: &mut u64,
) {
    let min_t = params.min_transmittance as f64;
    // The largest weighted error estimate per cubed step length of the round's exact steps,
    // and whether any of them had a neighbour to measure its curvature through.
    let mut rate = 0.0f64;
    let mut measured = false;
    // The pieces come in order: each shares a second difference with the one before.
    let mut last_difference = LastDifference::default();
    if state.deep {
        // This round's nodes are numbered from here on (a carried node anew: its shading
        // this round is for this round's pieces).
        state.deep_base = state.deep_nodes.len() as u32;
        let n = state.deep_nodes.len() + nodes.len();
        state.deep_nodes.resize(n, (0.0, glam::DVec3::ZERO));
    }
    for i in 0..nodes.len() {
        let b = nodes[i];
        state.densest = state.densest.max(b.sigma);
        let stopped = if b.extent > 0.0 {
            // A constant run: one piece, its weight all this node's.
            let first = state.deep_pieces.len();
            let (w, stopped) = composite_piece(state, [b.t, b.t + b.extent], [b.sigma; 2], outputs);
            nodes[i].weight += w;
            name_deep_nodes(state, first, [i, i], 0.0);
            stopped
        } else if i > 0 && !b.starts_run {
            let a = nodes[i - 1];
            let sum = a.sigma + b.sigma;
            let weight = (b.t - a.t) * state.pieces.transmittance();
            let jump = (b.sigma - a.sigma).abs();
            // The curvature is worked out where the error rule needs it (an exact run) or
            // where it may decide the change: the jump bounds the change, and a jump that
            // would leave the worst estimate as it is needs no more.
            let curvature = (a.exact || weight * jump > state.worst)
                .then(|| step_curvature(nodes, i - 1, 0, &mut last_difference));
            let error = if sum == 0.0 && !empty_is_known {
                // Nothing seen at either end of a field that cannot say what lies between.
                f64::INFINITY
            } else if weight * jump > state.worst {
                weight * curvature.map_or(jump, |c| change(jump, c))
            } else {
                0.0
            };
            state.worst = state.worst.max(error);
            if let (true, Some(sides @ [before, after])) = (a.exact, curvature) {
                if before.is_some() || after.is_some() {
                    let delta = b.t - a.t;
                    measured = true;
                    rate = rate.max(weight * larger_side(sides) / (delta * delta * delta));
                }
            }
            let ends = if a.exact {
                let bias = trapezoid_bias(nodes, i - 1, 0, &mut last_difference, state.smooth);
                unbiased_ends(&a, &b, bias)
            } else {
                [a.sigma, b.sigma]
            };
            let first = state.deep_pieces.len();
            let (w, stopped) = composite_piece(state, [a.t, b.t], ends, outputs);
            if w > 0.0 {
                // An empty end's colour is not asked for: the other end gets all the weight.
                let far = if a.sigma == 0.0 {
                    1.0
                } else if b.sigma == 0.0 {
                    0.0
                } else {
                    far_share(a.sigma, b.sigma, b.t - a.t)
                };
                nodes[i - 1].weight += w * (1.0 - far);
                nodes[i].weight += w * far;
                name_deep_nodes(state, first, [i - 1, i], far);
            }
            stopped
        } else {
            continue;
        };
        if stopped || state.pieces.transmittance() < min_t {
            state.live = false;
            // Nothing after this node counts.
            for n in &mut nodes[i + 1..] {
                n.weight = 0.0;
            }
            return;
        }
    }
    if state.run >= state.runs.len() {
        composite_fragments(state, f64::INFINITY, outputs);
        state.live = false;
    } else if state.samples >= params.max_samples {
        // Out of budget: what lies further is not marched (the caller counts the ray).
        composite_fragments(state, f64::INFINITY, outputs);
        state.live = false;
        *budget_limited += 1;
    }
    if measured {
        state.allowed = allowed_step(rate, params);
    }
    adapt_step(state, params);
}

/// Names the nodes (this round's `i` and `j`) whose colours the deep pieces from `first` on
/// get, `1 − far` of each piece's weight from `i` and `far` from `j`, as the flat render
/// splits the weight of the piece they were cut from.
fn name_deep_nodes(state: &mut RayState, first: usize, [i, j]: [usize; 2], far: f64) {
    if !state.deep {
        return;
    }
    let base = state.deep_base;
    for p in &mut state.deep_pieces[first..] {
        if p.nodes[0].0 == PENDING_NODE {
            let w = p.piece.weight;
            p.nodes = [
                (base + i as u32, w * (1.0 - far)),
                (base + j as u32, w * far),
            ];
        }
    }
}

/// The densities a step of an exact run is composited with: its ends', scaled so that their
/// mean's optical depth is the trapezoid rule's less its `bias` ([`trapezoid_bias`], where
/// both sides give a curvature; never below zero). The trapezoid rule's error, `δ³·σ''/12`,
/// has the sign of the curvature: over a convex stretch of a trained surface it adds up,
/// step after step, each within its own estimate, past the target. Less the bias, what is left is the change of the curvature across the
/// step, which changes sign along a bump. The bias is at most a twelfth of the step's
/// weighted error estimate (`T·δ³·|σ''|`), so it moves a piece's weight by at most a
/// twelfth of the target where the step meets it, and by nothing where it has no neighbour
/// on a side.
///
/// Only where the step and its neighbours lie within the smooth length of every field the
/// ray meets (`RayState::smooth`): over nodes further apart a trained field's cells have
/// kinks the cubic does not model, and correcting there makes the error worse. An analytic
/// field declares no such length: its exact runs are smooth, but over steps as long as its
/// features (a Gaussian's width at Draft) the cubic fits them no better than the trapezoid.
fn unbiased_ends(a: &Node, b: &Node, bias: Option<f64>) -> [f64; 2] {
    let ends = [a.sigma, b.sigma];
    let mean = 0.5 * (a.sigma + b.sigma);
    match bias {
        Some(bias) if mean > 0.0 => {
            let scale = (1.0 - bias / ((b.t - a.t) * mean)).max(0.0);
            ends.map(|sigma| sigma * scale)
        }
        _ => ends,
    }
}

/// The error rule's step in an exact run: the trapezoid rule's error over a step of length
/// `δ` is `δ³·|σ''|/12` in optical depth, and a step's weighted error estimate is
/// `e = w·δ²·|σ''|` ([`step_curvature`], the larger side; `w = δ·T`), so `e` grows as
/// `rate·δ³`. The rule's step is estimated at `target / STEP_SAFETY` at the round's highest
/// `rate`: `(target / (STEP_SAFETY·rate))^⅓`. Infinite where the measured curvature was
/// zero (a linear density); zero, so the finest step, where it was infinite or not a number.
pub(super) fn allowed_step(rate: f64, params: &MarchParams) -> f64 {
    if rate == 0.0 {
        f64::INFINITY
    } else if rate > 0.0 && rate.is_finite() {
        (params.error_target as f64 / (STEP_SAFETY * rate)).cbrt()
    } else {
        0.0
    }
}

/// Composites the piece `[t₀, t₁]` whose density goes linearly from `σ₀` to `σ₁` (the
/// trapezoid rule's mean), split at the fragments inside it (composited in between). Returns
/// the piece's weight, and whether a fragment stopped the ray.
fn composite_piece(
    state: &mut RayState,
    [a, b]: [f64; 2],
    [sigma_a, sigma_b]: [f64; 2],
    outputs: &Outputs,
) -> (f64, bool) {
    let mean = 0.5 * (sigma_a + sigma_b);
    let mut t0 = a;
    let mut weight = 0.0;
    loop {
        let fragment = state.next_fragment_t().filter(|&t| t < b);
        let t1 = fragment.map_or(b, |t| t.max(t0));
        let t_enter = state.pieces.transmittance();
        let w = state.pieces.add(t0, t1 - t0, mean);
        if w > 0.0 && state.deep {
            state.deep_pieces.push(DeepPiece {
                piece: RawPiece {
                    t0,
                    t1,
                    weight: w,
                    rgb: glam::DVec3::ZERO,
                },
                nodes: [(PENDING_NODE, 0.0), (NO_NODE, 0.0)],
            });
        }
        if w > 0.0 && outputs.depth_median {
            // A piece cut by a fragment keeps the mean.
            let delta = t1 - t0;
            let (x0, x1) = if t0 == a && t1 == b {
                (sigma_a * delta, sigma_b * delta)
            } else {
                (mean * delta, mean * delta)
            };
            state.log_piece([t0, delta, x0, x1, t_enter]);
        }
        weight += w;
        t0 = t1;
        if fragment.is_none() {
            return (weight, false);
        }
        if !composite_fragments(state, t0, outputs) {
            return (weight, true);
        }
    }
}

/// After a round, for the steps of runs searched for their edges (exact runs' steps are the
/// error rule's, [`allowed_step`]): back to the base step where a step was bisected (an edge
/// is near); steps double from node to node while every step's weighted error estimate is
/// under 1/64 of the target (the trapezoid rule's error grows as `δ³`, so a doubled step
/// stays under an eighth of it), and are halved where one was over it.
fn adapt_step(state: &mut RayState, params: &MarchParams) {
    let target = params.error_target as f64;
    if state.refined {
        state.scale = 1.0;
        state.growing = false;
    } else {
        state.growing = 64.0 * state.worst <= target;
        if state.worst > target {
            state.scale = (0.5 * state.scale).max(1.0);
        }
    }
    state.refined = false;
    state.worst = 0.0;
}

/// Composites the ray's fragments up to `t_end`, splat and volume ones merged in order.
/// `false` when the ray is done: a splat fragment would bring its transmittance to the
/// splats' floor (gsplat's rule, which makes a pixel of splats alone exactly gsplat's).
/// Volume fragments (proposal samples) have no such floor: nerfstudio composites every
/// sample.
pub(super) fn composite_fragments(state: &mut RayState, t_end: f64, outputs: &Outputs) -> bool {
    loop {
        let splat = state.fragments.get(state.next_fragment);
        let volume = state.volume.get(state.next_volume);
        let (f, is_splat) = match (splat, volume) {
            (Some(a), Some(b)) if b.t < a.t => (*b, false),
            (Some(a), _) => (*a, true),
            (None, Some(b)) => (*b, false),
            (None, None) => break,
        };
        if f.t > t_end {
            break;
        }
        if !is_splat {
            composite_volume_fragment(state, f, outputs);
            state.next_volume += 1;
        } else if composite_fragment(state, f, outputs) {
            state.next_fragment += 1;
        } else {
            state.next_fragment = state.fragments.len();
            state.next_volume = state.volume.len();
            state.live = false;
            return false;
        }
    }
    true
}

/// Composites a fragment with no floor (a proposal sample: nerfstudio composites every
/// sample; a splat fragment once it has passed the floor).
#[inline]
fn composite_volume_fragment(state: &mut RayState, f: Fragment, outputs: &Outputs) {
    let alpha = f64::from(f.alpha);
    let t_enter = state.pieces.transmittance();
    let w = state.pieces.add_fragment(f.t, alpha);
    let rgb = Vec3::from_array(f.rgb).as_dvec3() * w;
    state.rgb += rgb;
    if state.deep && w > 0.0 {
        state.deep_pieces.push(DeepPiece {
            piece: RawPiece {
                t0: f.t,
                t1: f.t,
                weight: w,
                rgb,
            },
            nodes: [(NO_NODE, 0.0); 2],
        });
    }
    if outputs.depth_median && alpha > 0.0 {
        let x = -(-alpha).ln_1p();
        state.log_piece([f.t, 0.0, x, x, t_enter]);
    }
}

/// Composites the ray's next splat fragment; `false` (and nothing composited) when it would
/// bring the ray's transmittance to the splats' floor: the ray is done.
#[inline]
pub(super) fn composite_fragment(state: &mut RayState, f: Fragment, outputs: &Outputs) -> bool {
    if state.pieces.transmittance() * (1.0 - f64::from(f.alpha)) <= SPLAT_MIN_TRANSMITTANCE {
        return false;
    }
    composite_volume_fragment(state, f, outputs);
    true
}
