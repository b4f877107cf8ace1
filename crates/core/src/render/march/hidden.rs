//! What a step may hide between its samples from a field that cannot bound its density
//! and is marched by an occupancy grid (one that gives its mask's segments has its runs end
//! at the mask's edges, and hides neither): content inside an occupied cell it clips, gaps
//! inside masked fog.

use glam::Vec3;

use super::laying::growth;
use super::{met_by, InstancePlan, Node, Scratch};
use crate::field::{Aabb, Field};
use crate::scene::LocalRay;

/// A gap a step may jump over unseen changes the pixel by at most the error target over
/// this: a ray grazing a masked fog's staircase rim crosses a few such gaps (measured: two
/// on the benchmark fog's worst Final pixel, together 1.2× the target at a share of 1).
const GAP_SHARE: f64 = 4.0;

/// Gap probes per occupancy cell at most ([`hides_gap`]): each is a point query, and a
/// dense field would ask for thousands per step (the target over `δ·T·σ`). Below this
/// spacing a step's gaps are found down to an eighth of a cell, not to the target's length.
/// A step shorter than a cell gets as many as one a cell long: a gap a probe found is found
/// again in the bisected halves, whatever their length.
const GAP_PROBES_PER_CELL: f64 = 8.0;

/// Gap probes per step at most, whatever the cell (a grid squeezed thin along one axis by a
/// crop has tiny cells) and the step's growth: they bound a step's cost.
const GAP_PROBES_MAX: f64 = 1024.0;

/// Gap probes asked of a field in one batch.
const GAP_BATCH: usize = 32;

/// Bisections below the base step at most in the search for what a step empty at both ends
/// may hide ([`hides_content`]), whatever the preset's depth: a ray running along an
/// occupied cell's face keeps touching it, and each level may double its samples there.
pub(super) const HIDDEN_DEPTH: i32 = 5;

/// Halvings at most in the search for a point of a step that [`hides_content`]
/// ([`hidden_point`]): 2^-24 of the step is below an `f32` position's resolution.
pub(super) const HIDDEN_SEARCH_DEPTH: u32 = 24;

/// Midpoints asked at most in one [`hidden_point`] search: a box padded past a cell's face
/// keeps its halves next to the face "occupied" down to the depth limit, so a search may
/// follow a dead end before it finds the cell or gives up (then the step is halved). As many
/// as the depth: a search that meets no dead end reaches it.
pub(super) const HIDDEN_SEARCH_QUERIES: u32 = 24;

/// The instances that cannot bound their density (the others are searched by their bounds)
/// and that ray `r` is inside over some of `[t0, t1]`, with their index, their place among
/// the ray's instances ([`met_by`]), their local ray and the part of `[t0, t1]` inside them.
fn unbounded_over<'a>(
    plans: &'a [InstancePlan],
    r: usize,
    t0: f64,
    t1: f64,
    s: &'a Scratch,
) -> impl Iterator<Item = (usize, usize, &'a LocalRay, f64, f64)> + 'a {
    met_by(s, r).iter().enumerate().filter_map(move |(j, met)| {
        let (i, lr) = (met.inst as usize, &met.local);
        if plans[i].capabilities.density_bounds {
            return None;
        }
        let (a, b) = (t0.max(lr.t_near), t1.min(lr.t_far));
        (a < b).then_some((i, j, lr, a, b))
    })
}

/// Whether the step from node `k` to `k + 1` on ray `r`, empty at both ends in an instance
/// that cannot bound its density, may cross density there: the step's box may be occupied
/// ([`Field::may_be_occupied`], exact where a trained field's mask sets its density to
/// zero). A ray clipping the corner of an occupied cell of a dense field crosses it between
/// two samples (a tenth of a base step can hold an optical depth of 30), so such a step is
/// bisected until the boxes miss the cell, to [`HIDDEN_DEPTH`] below the base step even where
/// the preset's own depth stops sooner. What it hides changes the
/// pixel by at most the transmittance `T`: not searched where that is within the target.
/// Nor next to a node with density in the instance: the mask's edge is near, the box of a
/// step ending there touches it at every bisection, and the step beyond brackets the edge.
pub(super) fn hides_content(
    plans: &[InstancePlan],
    r: usize,
    k: usize,
    transmittance: f64,
    tolerance: f64,
    s: &Scratch,
) -> bool {
    let nodes = &s.nodes[r];
    let (a, b) = (&nodes[k], &nodes[k + 1]);
    if transmittance <= tolerance {
        return false;
    }
    let before = (!a.starts_run && k > 0).then(|| &nodes[k - 1]);
    let after = nodes.get(k + 2).filter(|n| !n.starts_run);
    unbounded_over(plans, r, a.t, b.t, s).any(|(i, j, lr, t0, t1)| {
        let sigma = |n: &Node| s.inst_sigma[n.slot as usize + j];
        if sigma(a) != 0.0 || sigma(b) != 0.0 || before.is_some_and(|n| sigma(n) > 0.0) {
            return false;
        }
        if after.is_some_and(|n| sigma(n) > 0.0) {
            return false;
        }
        let (p, q) = (lr.at(t0), lr.at(t1));
        plans[i]
            .instance
            .field()
            .may_be_occupied(&Aabb::new(p.min(q), p.max(q)))
    })
}

/// Where to split the step from node `k` to `k + 1` on ray `r`: its midpoint, unless the
/// step is empty at both ends and a field that cannot bound its density, whose box over the
/// step may be occupied, has a point inside it that it does not call empty
/// ([`hidden_point`]). A ray clipping the corner of an occupied cell crosses a sliver far
/// shorter than bisection below the base step reaches ([`HIDDEN_DEPTH`]); a node placed
/// inside it sees that content whatever its length.
pub(super) fn split_point(plans: &[InstancePlan], r: usize, k: usize, s: &Scratch) -> f64 {
    let (a, b) = (&s.nodes[r][k], &s.nodes[r][k + 1]);
    let mid = 0.5 * (a.t + b.t);
    if a.exact || a.sigma != 0.0 || b.sigma != 0.0 {
        return mid;
    }
    unbounded_over(plans, r, a.t, b.t, s)
        .find_map(|(i, _, lr, t0, t1)| {
            let field = plans[i].instance.field();
            let (p, q) = (lr.at(t0), lr.at(t1));
            if !field.may_be_occupied(&Aabb::new(p.min(q), p.max(q))) {
                return None;
            }
            let mut queries = HIDDEN_SEARCH_QUERIES;
            hidden_point(field, lr, t0, t1, HIDDEN_SEARCH_DEPTH, &mut queries)
        })
        .filter(|&t| t > a.t && t < b.t)
        .unwrap_or(mid)
}

/// A point strictly inside `(t0, t1)` on `lr` that `field` does not call certainly empty
/// ([`Field::certainly_empty`], the mask itself for a masked field), found depth first,
/// nearest first: the midpoint is asked, then each half whose box may be occupied
/// ([`Field::may_be_occupied`]). `None` where no such point turned up within `depth`
/// halvings and `queries` midpoints (each asks at most two boxes).
pub(super) fn hidden_point(
    field: &dyn Field,
    lr: &LocalRay,
    t0: f64,
    t1: f64,
    depth: u32,
    queries: &mut u32,
) -> Option<f64> {
    if *queries == 0 {
        return None;
    }
    *queries -= 1;
    let mid = 0.5 * (t0 + t1);
    let mut empty = [true];
    field.certainly_empty(&[lr.at(mid)], &mut empty);
    if !empty[0] {
        return Some(mid);
    }
    if depth == 0 {
        return None;
    }
    let mut half = |a: f64, b: f64| {
        let (p, q) = (lr.at(a), lr.at(b));
        if *queries == 0 || !field.may_be_occupied(&Aabb::new(p.min(q), p.max(q))) {
            return None;
        }
        hidden_point(field, lr, a, b, depth - 1, queries)
    };
    half(t0, mid).or_else(|| half(mid, t1))
}

/// Whether the step from `a` to `b` on ray `r`, with density at both ends in an instance
/// that cannot bound its density, may jump over a gap that matters: the field says some
/// point between them is empty ([`Field::certainly_empty`], one batch per step), where its
/// density is zero (an occupancy mask's edge), which the ends cannot show: a grown step
/// across the staircase rim of a masked fog would integrate the gap as fog. Points are
/// probed at most `g = target / (GAP_SHARE·T·σ)` apart (`σ` the larger end's density), so a
/// gap the probes miss is shorter than `g` and changes the pixel by less than a
/// `GAP_SHARE`th of the target; a step no longer than `g` is not probed, and a step gets at
/// most [`GAP_PROBES_PER_CELL`] probes per occupancy cell it spans (that many if it spans
/// less), and never more than [`GAP_PROBES_MAX`]. So a step of any length is probed as
/// finely as one a cell long, and steps in smooth fog may grow past a cell.
pub(super) fn hides_gap(
    plans: &[InstancePlan],
    r: usize,
    (a, b): (&Node, &Node),
    transmittance: f64,
    tolerance: f64,
    s: &Scratch,
) -> bool {
    let length = b.t - a.t;
    unbounded_over(plans, r, a.t, b.t, s).any(|(i, j, lr, t0, t1)| {
        let (sa, sb) = (
            s.inst_sigma[a.slot as usize + j],
            s.inst_sigma[b.slot as usize + j],
        );
        // `δ·T·σ`: what a gap as long as the step could hide, times the share.
        let hidden = GAP_SHARE * length * transmittance * sa.max(sb);
        if sa <= 0.0 || sb <= 0.0 || hidden <= tolerance {
            return false;
        }
        // An occupancy cell, world units.
        let plan = &plans[i];
        let cell = plan.cell * growth(plan, lr, a.t) / lr.units_per_world as f64;
        let per_cell = GAP_PROBES_PER_CELL * (length / cell).max(1.0);
        let probes = (hidden / tolerance)
            .min(per_cell)
            .min(GAP_PROBES_MAX)
            .ceil()
            .max(1.0) as usize;
        let (mut points, mut empty) = ([Vec3::ZERO; GAP_BATCH], [false; GAP_BATCH]);
        let field = plans[i].instance.field();
        (1..probes).step_by(GAP_BATCH).any(|first| {
            let n = GAP_BATCH.min(probes - first);
            for (j, p) in points[..n].iter_mut().enumerate() {
                let t = a.t + length * (first + j) as f64 / probes as f64;
                *p = lr.at(t.clamp(t0, t1));
            }
            field.certainly_empty(&points[..n], &mut empty[..n]);
            empty[..n].contains(&true)
        })
    })
}
