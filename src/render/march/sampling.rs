//! Density sampling: a round's pending nodes asked of each field in one batch.

use super::{feature_stride, instances_of, FieldQuery, InstancePlan, Node, Scratch};
use crate::scene::Scene;

/// Evaluates every pending node's density (one batched call per instance) and inserts the
/// nodes, in order, into their rays' node lists.
pub(super) fn evaluate_pending(scene: &Scene, plans: &[InstancePlan], s: &mut Scratch) {
    let n_inst = plans.len();
    let stride = feature_stride(plans);
    let first_slot = s.inst_sigma.len();
    let first_node = first_slot / n_inst;
    s.inst_sigma
        .resize(first_slot + s.pending.len() * n_inst, 0.0);
    s.features
        .resize((first_node + s.pending.len()) * stride, 0.0);
    s.queries.resize_with(n_inst, FieldQuery::default);
    for query in &mut s.queries {
        query.clear();
    }
    // One pass over the pending nodes fills every instance's query, in their order: each
    // node goes to the instances its ray is inside at its probe.
    for (p, pending) in s.pending.iter().enumerate() {
        let r = pending.ray as usize;
        let range = s.ray_inst_at[r] as usize..s.ray_inst_at[r + 1] as usize;
        for (&i, steps) in s.ray_insts[range.clone()].iter().zip(&s.ray_steps[range]) {
            if pending.probe >= steps.t_near && pending.probe <= steps.t_far {
                if let Some(lr) = &s.local[r * n_inst + i as usize] {
                    let query = &mut s.queries[i as usize];
                    query.points.push(lr.at(pending.probe));
                    query.owners.push((p as u32, lr.units_per_world as f64));
                }
            }
        }
    }
    for (i, (plan, query)) in plans.iter().zip(&mut s.queries).enumerate() {
        if query.points.is_empty() {
            continue;
        }
        s.field_out.clear();
        s.field_out.resize(query.points.len(), 0.0);
        let f = plan.features;
        query.features.resize(query.points.len() * f, 0.0);
        s.tile_fields.field(scene, i).density_with_features(
            &query.points,
            &mut s.field_out,
            &mut query.features,
        );
        s.stats.density_samples += query.points.len() as u64;
        for (&(p, _), features) in query
            .owners
            .iter()
            .zip(query.features.chunks_exact(f.max(1)))
        {
            let at = (first_node + p as usize) * stride + plan.feature_offset;
            s.features[at..at + f].copy_from_slice(&features[..f]);
        }
        for (&(p, k), &sigma) in query.owners.iter().zip(&s.field_out) {
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
            s.inst_sigma[first_slot + p as usize * n_inst + i] = sigma;
        }
    }
    for (p, pending) in s.pending.iter().enumerate() {
        let r = pending.ray as usize;
        s.rays[r].samples += 1;
        let slot = first_slot + p * n_inst;
        // The other instances' densities are zero: summed in the same order as all of them.
        let sigma = instances_of(s, r)
            .iter()
            .map(|&i| s.inst_sigma[slot + i as usize])
            .sum();
        let node = Node {
            t: pending.t,
            probe: pending.probe,
            sigma,
            slot: slot as u32,
            starts_run: pending.starts_run,
            exact: pending.exact,
            extent: pending.extent,
            weight: 0.0,
            depth: 0.0,
        };
        let nodes = &mut s.nodes[r];
        if nodes.last().is_none_or(|last| last.t <= node.t) {
            nodes.push(node);
        } else {
            let at = nodes.partition_point(|n| n.t <= node.t);
            nodes.insert(at, node);
        }
    }
}
