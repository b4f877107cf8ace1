//! Refinement: which steps are bisected, and the error estimates that decide it.

use super::hidden::{hides_content, hides_gap, split_point, HIDDEN_DEPTH};
use super::laying::{base_step_at, growth};
use super::sampling::evaluate_pending;
use super::{bucket_by_instance, met_by, InstancePlan, Node, Pending, Scratch, MAX_BISECTIONS};
use crate::field::Aabb;
use crate::render::MarchParams;
use crate::scene::LocalRay;

/// Bisects the steps whose two ends disagree (`|σ_b − σ_a|·δ` above the tolerance) or
/// between whose ends the fields' density bound rises well above both (a sheet thinner than
/// a step), level by level, each level one batch across the tile. After the first level only
/// the pairs next to the nodes just added can need it, and the pairs beyond those, whose
/// curvature has a new neighbour (a run's first step has no node before it: its curvature
/// is the one through the node after it, which may have moved closer), so only those are
/// looked at. Steps that cannot hold an edge of a smooth field are not bisected for their
/// jump.
pub(super) fn refine(plans: &[InstancePlan], params: &MarchParams, s: &mut Scratch) {
    s.refine.candidates.clear();
    for &r in &s.active {
        for i in 0..s.nodes[r as usize].len().saturating_sub(1) {
            s.refine.candidates.push((r, i as u32));
        }
    }
    // A step grown by 2^k needs k more bisections to reach a base step's bracket.
    let grown_levels = params.max_step_factor.max(1.0).log2().ceil() as u32;
    let levels = (params.refine_depth + grown_levels).min(MAX_BISECTIONS);
    // Where some field is smooth below a length (a trained field), steps are judged by their
    // curvature alone, which a node added two steps away changes.
    let beyond = usize::from(plans.iter().any(|p| p.smooth > 0.0));
    for level in 0..levels {
        if level > 0 {
            s.refine.candidates.clear();
            for added in &s.pending {
                let nodes = &s.nodes[added.ray as usize];
                let i = nodes.partition_point(|n| n.t < added.t);
                // The two steps beside it, and (`beyond`) the two beyond those, whose
                // curvature it is a neighbour of.
                let last = nodes.len().saturating_sub(1).min(i + 1 + beyond);
                for k in i.saturating_sub(1 + beyond)..last {
                    s.refine.candidates.push((added.ray, k as u32));
                }
            }
            if beyond > 0 {
                s.refine.candidates.sort_unstable();
                s.refine.candidates.dedup();
            }
        }
        let mut last = None;
        for &(r, _) in &s.refine.candidates {
            if last != Some(r) {
                last = Some(r);
                lay_depths_and_differences(&mut s.nodes[r as usize]);
            }
        }
        split_candidates(plans, params, s);
        if s.pending.is_empty() {
            break;
        }
        evaluate_pending(plans, s);
    }
}

/// The share of the error target a smooth step's weighted estimate ([`smooth_change`], or a
/// bump it may straddle) may reach before the step is bisected. The estimate bounds the
/// step's own error, not the pixel's, and a trained density has dips and bumps narrower
/// than its smooth length that a step's nodes do not show: two steps each within their
/// estimate may add with one sign past the target. A bare safety factor: the largest share
/// that keeps the dense blob's Final within its target.
const SMOOTH_SHARE: f64 = 0.9;

/// Tests each candidate pair `(ray, i)` (nodes `i` and `i + 1`) and lays the midpoints of
/// those that need splitting into `s.pending`. What a step may get wrong matters
/// only as much as light from there reaches the camera, so each test is weighed by the
/// ray's transmittance at the step ([`transmittance_at`]: the steps of a round laid behind a
/// surface are not refined as if it were not there), not by what lies behind (the piece's
/// own weight and colour depend on what the step holds). A step that can hold no edge of a
/// smooth field is judged by its curvature ([`smooth_change`]). Pairs that pass the cheap
/// jump test ask the fields for a density bound over the step's box, one batch per
/// instance.
fn split_candidates(plans: &[InstancePlan], params: &MarchParams, s: &mut Scratch) {
    let empty_is_known = plans.iter().all(|p| p.capabilities.density_bounds);
    let n_inst = plans.len();
    let tolerance = params.error_target as f64;
    let any_smooth = plans.iter().any(|p| p.smooth > 0.0);
    s.pending.clear();
    s.refine.unsure.clear();
    // Candidates come in order along their rays: most share a difference with the last.
    let mut last_difference = LastDifference::default();
    // The densest node of the ray the last candidates were on (see the shell rule below).
    let mut densest: Option<(u32, f64)> = None;
    for &(r, i) in &s.refine.candidates {
        let nodes = &s.nodes[r as usize];
        let (a, b) = (&nodes[i as usize], &nodes[i as usize + 1]);
        if b.starts_run {
            continue;
        }
        let t_round = s.rays[r as usize].pieces.transmittance();
        // Only steps that are not exact use it (edges and what a step hides).
        let base = if a.exact {
            0.0
        } else {
            base_step_at(r as usize, a.t, plans, s)
        };
        // An exact run's spans are where its density is: it hides nothing a probe could find.
        let hides = |transmittance: f64| {
            !a.exact
                && b.t - a.t > 1.5 * base * 0.5f64.powi(HIDDEN_DEPTH)
                && hides_content(plans, r as usize, i as usize, transmittance, tolerance, s)
        };
        // Every test below grows with the transmittance: see [`confirmed`].
        // A step that can hold no edge is bisected below the floor: its weighted estimate
        // shrinks at least as the square of its length (its jump and curvature with it), so
        // bisection soon clears the target, within the levels that bound every step. Held
        // at the floor, a Draft step on the dense blob at 1080p from a mask's face, its
        // density falling from 3000 to 600, held 0.15 too much optical depth.
        let smooth = any_smooth && smooth_step(r as usize, a, b, plans, s);
        // A smooth step longer than half its field's smooth length may straddle a peak its
        // ends and their curvature do not show: inside one finest cell a trained density is
        // the exponential of a cubic along the ray (on the dense blob at 1080p a Preview
        // step 0.9 smooth lengths long straddled a rise from 58 to 218, and the pixel's
        // colour was off by 1.3e-2). It is judged as if a bump one smooth length wide, as
        // dense as its denser end, lay inside: one bisection clears the rule.
        let straddled = if smooth {
            unresolved_detail(r as usize, a, b, plans, s, 0.5)
                .map_or(0.0, |width| a.sigma.max(b.sigma) * width / (b.t - a.t))
        } else {
            0.0
        };
        if !smooth && b.t - a.t <= 1.5 * s.rays[r as usize].finest {
            // Shorter than bisection may leave: only what the step may wholly hide is
            // searched for.
            if confirmed(hides, t_round, nodes, i as usize) {
                let t = split_point(plans, r as usize, i as usize, s);
                s.pending.push(Pending::between(r, t, a));
            }
            continue;
        }
        let jump = (b.sigma - a.sigma).abs();
        // Worked out once for both transmittances.
        let exact_estimate = (a.exact && !smooth).then(|| {
            let sides = step_curvature(nodes, i as usize, r, &mut last_difference);
            let trained = any_smooth
                && (met_by(s, r as usize).iter()).any(|m| plans[m.inst as usize].smooth > 0.0);
            let change = exact_change(a, b, sides, trained);
            // A trained field's step longer than its smooth length may straddle a thin shell
            // its ends and their curvature do not show (on the dense blob, ends of density
            // ~9 one Draft step apart held a shell of ~400 between them). Its finest detail
            // is a smooth length wide: the step is judged as if a shell that wide, as dense
            // as the densest node its ray has shown, lay inside.
            match trained
                .then(|| unresolved_detail(r as usize, a, b, plans, s, 1.0))
                .flatten()
            {
                Some(width) => {
                    let peak = match densest {
                        Some((ray, peak)) if ray == r => peak,
                        _ => {
                            let before = s.rays[r as usize].densest;
                            let peak = nodes.iter().fold(before, |m, n| m.max(n.sigma));
                            densest = Some((r, peak));
                            peak
                        }
                    };
                    change.max(peak * width / (b.t - a.t))
                }
                None => change,
            }
        });
        let change = |weight: f64| {
            if smooth {
                smooth_change(nodes, i as usize).max(straddled) * weight > SMOOTH_SHARE * tolerance
            } else if let Some(change) = exact_estimate {
                change * weight > tolerance
            } else {
                // The jump bounds `step_change`: the curvature is asked only where it may
                // decide.
                jump * weight > tolerance && step_change(nodes, i as usize) * weight > tolerance
            }
        };
        // A grown step where density starts or ends is bisected back to an ungrown one
        // whatever its weight, so faint content keeps the base step's edges; so is one
        // between two empty samples of a field that cannot say what lies between. A step of
        // an exact run holds no edge, sheet or peak: only its quadrature is judged.
        let unknown = !a.exact
            && ((a.sigma > 0.0) != (b.sigma > 0.0)
                || (a.sigma + b.sigma == 0.0 && !empty_is_known));
        // The cone's steps are no exception: a grazing ray's whole crossing may fit in one.
        let edge = unknown && b.t - a.t > 1.5 * base;
        // A sample with density between two empty ones says nothing of how dense the thin
        // shell it hit is (a grazing ray's silhouette): its steps are bisected until the
        // shell has two samples, whatever their weight.
        let lone = !a.exact
            && (a.sigma > 0.0) != (b.sigma > 0.0)
            && if a.sigma > 0.0 {
                i > 0 && !a.starts_run && nodes[i as usize - 1].sigma == 0.0
            } else {
                nodes
                    .get(i as usize + 2)
                    .is_some_and(|q| !q.starts_run && q.sigma == 0.0)
            };
        let split = |transmittance: f64| {
            (lone && transmittance > tolerance)
                || change((b.t - a.t) * transmittance)
                || hides(transmittance)
                || (!a.exact && hides_gap(plans, r as usize, (a, b), transmittance, tolerance, s))
        };
        if edge || confirmed(split, t_round, nodes, i as usize) {
            s.rays[r as usize].refined = true;
            let t = split_point(plans, r as usize, i as usize, s);
            s.pending.push(Pending::between(r, t, a));
        } else if !a.exact {
            s.refine.unsure.push((r, i, 0.0));
        }
    }
    // Density bounds over the unsure steps, summed over instances (per world unit).
    bucket_by_instance(
        &mut s.by_inst,
        n_inst,
        &s.tile_insts,
        &s.met,
        &s.met_at,
        s.refine
            .unsure
            .iter()
            .enumerate()
            .map(|(u, n)| (u as u32, n.0)),
    );
    for &k in &s.tile_insts {
        let (inst, k) = (&plans[k as usize].instance, k as usize);
        if s.by_inst[k].is_empty() {
            continue;
        }
        s.refine.regions.clear();
        s.refine.owners.clear();
        for &(u, e) in &s.by_inst[k] {
            let (r, i, _) = s.refine.unsure[u as usize];
            let lr = &s.met[e as usize].local;
            let nodes = &s.nodes[r as usize];
            let (a, b) = (
                nodes[i as usize].t.max(lr.t_near),
                nodes[i as usize + 1].t.min(lr.t_far),
            );
            if a <= b {
                let (pa, pb) = (lr.at(a), lr.at(b));
                s.refine.regions.push(Aabb::new(pa.min(pb), pa.max(pb)));
                s.refine.owners.push((u, lr.units_per_world as f64));
            }
        }
        if s.refine.regions.is_empty() {
            continue;
        }
        s.field_out.clear();
        s.field_out.resize(s.refine.regions.len(), 0.0);
        if !plans[k].capabilities.density_bounds {
            // No bound from this field: its steps cannot be searched.
            for &(u, _) in &s.refine.owners {
                s.refine.unsure[u as usize].2 = f64::NEG_INFINITY;
            }
            continue;
        }
        inst.field()
            .density_bounds(&s.refine.regions, &mut s.field_out);
        for (&(u, k), &bound) in s.refine.owners.iter().zip(&s.field_out) {
            s.refine.unsure[u as usize].2 += bound as f64 * k;
        }
    }
    for &(r, i, bound) in &s.refine.unsure {
        let nodes = &s.nodes[r as usize];
        let (a, b) = (&nodes[i as usize], &nodes[i as usize + 1]);
        // As above: the round's transmittance first, the step's only where that says split.
        let t_round = s.rays[r as usize].pieces.transmittance();
        let excess = (bound - a.sigma.max(b.sigma)) * (b.t - a.t);
        if excess * t_round > tolerance
            && excess * transmittance_at(t_round, nodes, i as usize) > tolerance
        {
            s.rays[r as usize].refined = true;
            s.pending.push(Pending::between(r, 0.5 * (a.t + b.t), a));
        }
    }
}

/// Lays each node's [`Node::depth`] and, where it is not known, [`Node::difference`], in one
/// pass over a ray's nodes.
///
/// The depth is the optical depth of a round's steps before the node, each at the lower of
/// its two densities (an edge inside a step may lie anywhere in it), constant runs whole.
///
/// The difference is worked out for the nodes inside an exact run, with a neighbour in it on
/// either side: every step of such a run is judged by its curvature ([`step_curvature`]), in
/// each level of refinement that looks at it and again when it is integrated, and those read
/// them.
pub(super) fn lay_depths_and_differences(nodes: &mut [Node]) {
    let mut depth = 0.0;
    for k in 0..nodes.len() {
        nodes[k].depth = depth;
        let a = &nodes[k];
        let next = nodes.get(k + 1).filter(|b| !b.starts_run);
        if a.extent > 0.0 {
            depth += a.extent * a.sigma;
        } else if let Some(b) = next {
            depth += (b.t - a.t) * a.sigma.min(b.sigma);
        }
        if k > 0 && next.is_some() && a.exact && !a.starts_run && a.difference.is_nan() {
            if let Some(d) = difference(&nodes[k - 1..=k + 1]) {
                nodes[k].difference = d;
            }
        }
    }
}

/// Whether `test`, which grows with the transmittance, holds at the step from node `i`:
/// at the round's transmittance `t_round` first, which bounds the step's, and only where
/// that says so at the step's own (an exponential, [`transmittance_at`]).
#[inline]
fn confirmed(test: impl Fn(f64) -> bool, t_round: f64, nodes: &[Node], i: usize) -> bool {
    test(t_round) && (nodes[i].depth == 0.0 || test(transmittance_at(t_round, nodes, i)))
}

/// The transmittance a ray entered the round with, `t_round`, carried to node `i` of its
/// round's nodes through the steps before it ([`lay_depths_and_differences`]).
pub(super) fn transmittance_at(t_round: f64, nodes: &[Node], i: usize) -> f64 {
    match nodes[i].depth {
        0.0 => t_round,
        depth => t_round * (-depth).exp(),
    }
}

/// Whether the step from `a` to `b` on ray `r` can hold no edge: every instance with density
/// at either end has it at both and is smooth over the step's length (see
/// [`Field::smooth_length`](crate::field::Field::smooth_length)).
fn smooth_step(r: usize, a: &Node, b: &Node, plans: &[InstancePlan], s: &Scratch) -> bool {
    met_by(s, r).iter().enumerate().all(|(j, met)| {
        let (plan, lr) = (&plans[met.inst as usize], &met.local);
        let (sa, sb) = (
            s.inst_sigma[a.slot as usize + j],
            s.inst_sigma[b.slot as usize + j],
        );
        if sa == 0.0 && sb == 0.0 {
            return true;
        }
        sa > 0.0
            && sb > 0.0
            && (b.t - a.t) * lr.units_per_world as f64 <= smooth_over(plan, lr, a, b)
    })
}

/// The instance's smooth length over the step from `a` to `b` (field units): its
/// [`Field::smooth_length`](crate::field::Field::smooth_length), grown as its steps grow
/// where it is unbounded, the less of the two ends.
fn smooth_over(plan: &InstancePlan, lr: &LocalRay, a: &Node, b: &Node) -> f64 {
    plan.smooth * growth(plan, lr, a.t).min(growth(plan, lr, b.t))
}

/// The shortest smooth length (see
/// [`Field::smooth_length`](crate::field::Field::smooth_length), world units) whose
/// `fraction` the step from `a` to `b` on ray `r` is longer than, of the trained instances
/// with density at either end: between two such samples the density may hold detail that
/// narrow.
fn unresolved_detail(
    r: usize,
    a: &Node,
    b: &Node,
    plans: &[InstancePlan],
    s: &Scratch,
    fraction: f64,
) -> Option<f64> {
    let mut shortest = None;
    for (j, met) in met_by(s, r).iter().enumerate() {
        let (plan, lr) = (&plans[met.inst as usize], &met.local);
        let dense =
            s.inst_sigma[a.slot as usize + j] > 0.0 || s.inst_sigma[b.slot as usize + j] > 0.0;
        let smooth = smooth_over(plan, lr, a, b) / lr.units_per_world as f64;
        if dense && smooth > 0.0 && b.t - a.t > fraction * smooth {
            shortest = Some(shortest.map_or(smooth, |s: f64| s.min(smooth)));
        }
    }
    shortest
}

/// How much the density changes across the step from node `i` to `i + 1` in a way the
/// trapezoid rule may get wrong: the jump `|σ_b − σ_a|`, unless the curvature through the
/// step's ends and their outer neighbours says the density is (nearly) linear there, which
/// the rule integrates exactly: the smaller of the jump and `δ²·|σ''|` ([`step_curvature`],
/// the larger of its two sides). An edge keeps its full jump; a steady slope of a smooth
/// field is not bisected.
#[inline]
pub(super) fn step_change(nodes: &[Node], i: usize) -> f64 {
    let (a, b) = (&nodes[i], &nodes[i + 1]);
    let curvature = step_curvature(nodes, i, 0, &mut LastDifference::default());
    change((b.sigma - a.sigma).abs(), curvature)
}

/// [`step_change`] from a step's jump and its curvature on either side.
#[inline]
pub(super) fn change(jump: f64, curvature: [Option<f64>; 2]) -> f64 {
    match curvature {
        [Some(before), Some(after)] => jump.min(before.max(after)),
        _ => jump,
    }
}

/// How much the trapezoid rule may get a step wrong that can hold no edge ([`smooth_step`]):
/// as much as a trained field's step of an exact run ([`exact_change`]). Its curvature
/// `δ²·|σ''|` alone where both sides are known, not the jump: a bump between two ends of
/// equal density has none, yet holds most of a surface's weight where a trained density is
/// the exponential of a smooth function. With one side unknown (a round's first step: the
/// nodes before it went with the round before) the larger of the jump and that side: on the
/// dense blob at 1080p a Final round's first step held a bump that the rise into it, in the
/// round before, showed and the fall after it did not (alpha off by 1.3e-3). With neither
/// (a mask segment one step long, a segment's last step alone in its round), its denser
/// end: a Preview segment one step long between ends of ~60 held a dip their jump did not
/// bound (alpha off by 1.5e-2).
#[inline]
pub(super) fn smooth_change(nodes: &[Node], i: usize) -> f64 {
    let sides = step_curvature(nodes, i, 0, &mut LastDifference::default());
    exact_change(&nodes[i], &nodes[i + 1], sides, true)
}

/// How much the trapezoid rule may get a step of an exact run wrong that is longer than
/// its field is smooth: such a step may straddle a bump its ends do not show (the slight
/// peak two overlapping Gaussians make inside a span; a trained density's inside its
/// mask), so it is judged by its curvature (`sides`, [`step_curvature`]) where both sides
/// give one (which bounds its [`step_change`]), else by the larger of its jump and the side
/// it has. With neither side, by its jump, but on a ray that meets a trained field
/// (`trained`): [`unmeasured_change`]. An analytic field's spans are split at their peaks;
/// a trained field's mask segments are not, and a step with no neighbour in its round shows
/// nothing of what lies inside it: a mask segment one step long, or a segment's last step
/// alone in a later round, may hold a dip its nearly equal ends do not show.
#[inline]
pub(super) fn exact_change(a: &Node, b: &Node, sides: [Option<f64>; 2], trained: bool) -> f64 {
    match sides {
        [Some(before), Some(after)] => before.max(after),
        [None, None] if trained => unmeasured_change(a, b),
        sides => (b.sigma - a.sigma).abs().max(larger_side(sides)),
    }
}

/// What a step whose curvature cannot be measured (a mask segment one step long) may get
/// wrong: a bump as high as its denser end may lie between its ends, which their jump does
/// not bound (on the dense blob a segment one Draft step long held a bump of nearly twice
/// its ends' density, and the pixel's colour was off by 5.6e-2). One bisection gives both
/// halves a neighbour.
#[inline]
fn unmeasured_change(a: &Node, b: &Node) -> f64 {
    a.sigma.max(b.sigma)
}

/// The larger of a step's curvatures on its two sides ([`step_curvature`]), 0 for a side
/// without a neighbour.
#[inline]
pub(super) fn larger_side([before, after]: [Option<f64>; 2]) -> f64 {
    before.unwrap_or(0.0).max(after.unwrap_or(0.0))
}

/// `δ²·|σ''|` over the step from node `i` to `i + 1` of ray `ray`, `σ''` estimated by the
/// second divided difference through the step's ends and the node before it, and through
/// them and the one after it (steps may differ in length); `None` where the run has no such
/// node. `last` keeps the last difference worked out ([`LastDifference`]).
#[inline]
pub(super) fn step_curvature(
    nodes: &[Node],
    i: usize,
    ray: u32,
    last: &mut LastDifference,
) -> [Option<f64>; 2] {
    let (a, b) = (&nodes[i], &nodes[i + 1]);
    let h = b.t - a.t;
    // `2·f[x0, x1, x2]·h²`, which is `σ0 − 2σ1 + σ2` for equal steps of length `h`.
    let side = |difference: Option<f64>| difference.map_or(f64::INFINITY, |k| (k * h * h).abs());
    let before = (i > 0 && !a.starts_run).then(|| side(last.around(nodes, i, ray)));
    let after = nodes
        .get(i + 2)
        .filter(|n| !n.starts_run)
        .map(|_| side(last.around(nodes, i + 1, ray)));
    [before, after]
}

/// The trapezoid rule's bias over the step from node `i` to `i + 1` of ray `ray`, in
/// optical depth: `δ·(σ_a + σ_b)/2` exceeds the integral by `δ³·σ''(ξ)/12` for some `ξ` in
/// the step, estimated at its middle from the cubic through its ends and their outer
/// neighbours (their two second differences, [`step_curvature`]'s, interpolated there; exact
/// for a cubic density). Its size is at most a twelfth of the step's [`step_curvature`] (the
/// larger side) times `δ`. `None` where the run has no node on either side, or where those
/// four nodes span more than `smooth` (world units): a trained field is a smooth curve only
/// within its [smooth length](crate::field::Field::smooth_length), and a cubic through
/// nodes further apart spans kinks between its cells that it does not model.
#[inline]
pub(super) fn trapezoid_bias(
    nodes: &[Node],
    i: usize,
    ray: u32,
    last: &mut LastDifference,
    smooth: f64,
) -> Option<f64> {
    let (a, b) = (&nodes[i], &nodes[i + 1]);
    let after = nodes.get(i + 2).filter(|n| !n.starts_run)?;
    if i == 0 || a.starts_run || after.t - nodes[i - 1].t > smooth {
        return None;
    }
    let before = &nodes[i - 1];
    let near = last.around(nodes, i, ray)?;
    let far = last.around(nodes, i + 1, ray)?;
    // Each second difference is the cubic's `σ''` at the mean of its three nodes; the
    // step's middle lies between those two means.
    let (m0, m1) = ((before.t + a.t + b.t) / 3.0, (a.t + b.t + after.t) / 3.0);
    let middle = near + (far - near) * (0.5 * (a.t + b.t) - m0) / (m1 - m0);
    let delta = b.t - a.t;
    Some(delta * delta * delta * middle / 12.0)
}

/// The twice second divided difference `2·f[x0, x1, x2]` of the density through three
/// consecutive nodes; `None` where a step between them is not longer than 0.
#[inline]
fn difference(nodes: &[Node]) -> Option<f64> {
    let (x, y, z) = (&nodes[0], &nodes[1], &nodes[2]);
    let (h0, h1) = (y.t - x.t, z.t - y.t);
    (h0 > 0.0 && h1 > 0.0).then(|| {
        let d = (z.sigma - y.sigma) / h1 - (y.sigma - x.sigma) / h0;
        2.0 * d / (h0 + h1)
    })
}

/// The twice second divided difference `2·f[x0, x1, x2]` around a node that [`step_curvature`]
/// worked out last, by ray and node: a step's `after` side is around the same node as the
/// next step's `before`, so a pass over a ray's steps in order works each out once. Valid
/// while the ray's nodes stay as they are.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct LastDifference(Option<(u32, usize, Option<f64>)>);

impl LastDifference {
    /// The difference through nodes `i − 1`, `i` and `i + 1` of ray `ray` (node `i`'s own
    /// where it is known, [`lay_depths_and_differences`]); `None` where a step between them
    /// is not longer than 0.
    #[inline]
    fn around(&mut self, nodes: &[Node], i: usize, ray: u32) -> Option<f64> {
        if let Some((r, at, difference)) = self.0 {
            if (r, at) == (ray, i) {
                return difference;
            }
        }
        let cached = nodes[i].difference;
        let difference = if cached.is_nan() {
            difference(&nodes[i - 1..=i + 1])
        } else {
            Some(cached)
        };
        self.0 = Some((ray, i, difference));
        difference
    }
}
