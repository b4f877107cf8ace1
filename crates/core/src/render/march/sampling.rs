//! Density sampling: a round's pending nodes asked of each field in one batch.

use super::{met_by, FieldQuery, InstancePlan, Met, Node, Scratch};

/// Evaluates every pending node's density (one batched call per instance) and inserts the
/// nodes, in order, into their rays' node lists. A node gets a slot per instance its ray
/// meets, in the order of [`met_by`]; one its probe is outside keeps a density of zero.
/// A node whose probe reads no density where [`Pending::inward`](super::Pending::inward)
/// is elsewhere (a masked run's face, its position rounded out of the mask) is probed there
/// instead, in a second batch.
pub(super) fn evaluate_pending(plans: &[InstancePlan], s: &mut Scratch) {
    let n_inst = plans.len();
    let width = s.feature_width;
    let first_slot = s.inst_sigma.len();
    s.queries.resize_with(n_inst, FieldQuery::default);
    for &i in &s.tile_insts {
        s.queries[i as usize].clear();
    }
    // One pass over the pending nodes fills every instance's query, in their order: each
    // node goes to the instances its ray is inside at its probe.
    let mut slot = first_slot;
    // Whether some node may be probed again (only a masked run's faces can be).
    let mut may_retry = false;
    for pending in &s.pending {
        let r = pending.ray as usize;
        let met = &s.met[s.met_at[r] as usize..s.met_at[r + 1] as usize];
        queue(met, pending.probe, slot, &mut s.queries);
        may_retry |= pending.inward != pending.probe;
        slot += met.len();
    }
    s.inst_sigma.resize(slot, 0.0);
    s.features.resize(slot * width, 0.0);
    ask_fields(plans, s);
    if may_retry {
        retry_unread(plans, first_slot, s);
    }
    // The nodes go in a ray at a time (a round's nodes of a ray come together, a level's
    // midpoints mostly do), each after every node at the same or a smaller distance.
    let mut slot = first_slot;
    let mut k = 0;
    while k < s.pending.len() {
        let r = s.pending[k].ray as usize;
        let count = (s.pending[k..].iter())
            .take_while(|p| p.ray as usize == r)
            .count();
        let met = met_by(s, r).len();
        s.rays[r].samples += count as u32;
        let nodes = &mut s.nodes[r];
        let laid = nodes.len();
        for pending in &s.pending[k..k + count] {
            nodes.push(Node {
                t: pending.t,
                probe: pending.probe,
                sigma: s.inst_sigma[slot..slot + met].iter().sum(),
                slot: slot as u32,
                starts_run: pending.starts_run,
                exact: pending.exact,
                extent: pending.extent,
                weight: 0.0,
                depth: 0.0,
                difference: f64::NAN,
            });
            slot += met;
        }
        settle(nodes, laid, &mut s.settling);
        k += count;
    }
}

/// Probes again, at [`Pending::inward`](super::Pending::inward), each pending node from the
/// one with slot `first_slot` on whose probe no field read any density where that is
/// elsewhere (a masked run's face, its position rounded out of the mask), in a second batch.
fn retry_unread(plans: &[InstancePlan], first_slot: usize, s: &mut Scratch) {
    let mut retried = false;
    let mut slot = first_slot;
    for pending in &mut s.pending {
        let r = pending.ray as usize;
        let met = &s.met[s.met_at[r] as usize..s.met_at[r + 1] as usize];
        let read = s.inst_sigma[slot..slot + met.len()]
            .iter()
            .any(|&sigma| sigma > 0.0);
        if !read && pending.inward != pending.probe {
            if !retried {
                for &i in &s.tile_insts {
                    s.queries[i as usize].clear();
                }
                retried = true;
            }
            pending.probe = pending.inward;
            queue(met, pending.probe, slot, &mut s.queries);
        }
        slot += met.len();
    }
    if retried {
        ask_fields(plans, s);
    }
}

/// Adds the point at world distance `probe` of a node whose first slot is `slot` to the
/// query of each instance in `met` whose local ray holds it.
fn queue(met: &[Met], probe: f64, slot: usize, queries: &mut [FieldQuery]) {
    for (j, met) in met.iter().enumerate() {
        let lr = &met.local;
        if probe >= lr.t_near && probe <= lr.t_far {
            let query = &mut queries[met.inst as usize];
            query.points.push(lr.at(probe));
            query
                .owners
                .push(((slot + j) as u32, lr.units_per_world as f64));
        }
    }
}

/// Asks each instance's field for the densities and features of its query's points, into
/// their slots.
fn ask_fields(plans: &[InstancePlan], s: &mut Scratch) {
    let width = s.feature_width;
    for &i in &s.tile_insts {
        let plan = &plans[i as usize];
        let query = &mut s.queries[i as usize];
        if query.points.is_empty() {
            continue;
        }
        s.field_out.clear();
        s.field_out.resize(query.points.len(), 0.0);
        let f = plan.features;
        query.features.resize(query.points.len() * f, 0.0);
        s.tile_fields
            .field(plans, i as usize)
            .density_with_features(&query.points, &mut s.field_out, &mut query.features);
        s.stats.density_samples += query.points.len() as u64;
        for (&(slot, _), features) in query
            .owners
            .iter()
            .zip(query.features.chunks_exact(f.max(1)))
        {
            let at = slot as usize * width;
            s.features[at..at + f].copy_from_slice(&features[..f]);
        }
        for (&(slot, k), &sigma) in query.owners.iter().zip(&s.field_out) {
            // Sanitise: negative densities count as empty, and so do NaN and infinite ones,
            // which are counted.
            let sigma = if !sigma.is_finite() {
                s.stats.invalid_samples += 1;
                0.0
            } else if sigma > 0.0 {
                sigma as f64 * k
            } else {
                0.0
            };
            s.inst_sigma[slot as usize] = sigma;
        }
    }
}

/// Moves `nodes[laid..]`, in the order they were laid, into place among `nodes[..laid]`
/// (sorted by distance) as inserting them one by one would: each after every node at the
/// same or a smaller distance. In one pass, not one shift of the nodes behind per node:
/// a level's midpoints of a ray are merged in at once. A node with a new neighbour forgets
/// its [`Node::difference`].
fn settle(nodes: &mut [Node], laid: usize, scratch: &mut Vec<Node>) {
    let in_order = nodes[laid.saturating_sub(1)..]
        .windows(2)
        .all(|w| w[0].t <= w[1].t);
    if in_order {
        if let Some(last) = laid.checked_sub(1).and_then(|k| nodes.get_mut(k)) {
            last.difference = f64::NAN;
        }
        return;
    }
    scratch.clear();
    scratch.extend_from_slice(&nodes[laid..]);
    // A stable insertion sort of the new nodes (a handful)...
    for k in 1..scratch.len() {
        let node = scratch[k];
        let mut at = k;
        while at > 0 && scratch[at - 1].t > node.t {
            scratch[at] = scratch[at - 1];
            at -= 1;
        }
        scratch[at] = node;
    }
    // ...merged with the others from the back, a new node behind an old one at the same
    // distance.
    let (mut old, mut new, mut to) = (laid, scratch.len(), nodes.len());
    // Whether the node placed last was new: the one placed next is its neighbour.
    let mut beside_new = false;
    while new > 0 {
        to -= 1;
        let is_new = !(old > 0 && nodes[old - 1].t > scratch[new - 1].t);
        if is_new {
            new -= 1;
            nodes[to] = scratch[new];
            if let Some(next) = nodes.get_mut(to + 1) {
                next.difference = f64::NAN;
            }
        } else {
            old -= 1;
            nodes[to] = nodes[old];
            if beside_new {
                nodes[to].difference = f64::NAN;
            }
        }
        beside_new = is_new;
    }
    if let Some(before) = to.checked_sub(1).filter(|_| beside_new) {
        nodes[before].difference = f64::NAN;
    }
}
