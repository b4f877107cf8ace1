//! Shading: colour asked where a node's weight matters.

use glam::{DVec3, Vec3};

use super::{FieldQuery, InstancePlan, Scratch};
use crate::field::linear_to_srgb;
use crate::render::MarchParams;

/// Empties each of the tile's instances' colour queries, for [`queue_colours`] to fill.
pub(super) fn clear_colour_queries(n_inst: usize, s: &mut Scratch) {
    s.queries.resize_with(n_inst, FieldQuery::default);
    for &i in &s.tile_insts {
        s.queries[i as usize].clear();
    }
}

/// Queues colour queries of ray `r`'s nodes whose weight matters, each instance with density
/// at a node asked for its share of the node's weight. The lightest nodes of a ray go
/// unshaded while their weights add up to at most [`MarchParams::color_skip_budget`], so the
/// colour error a ray can get from skipping is bounded by that budget times its brightest
/// radiance. Called for the rays in order, right after each is integrated (its nodes are
/// still at hand), then [`shade`] asks the fields.
pub(super) fn queue_colours(
    r: usize,
    plans: &[InstancePlan],
    params: &MarchParams,
    s: &mut Scratch,
) {
    let width = s.feature_width;
    let budget = params.color_skip_budget as f64;
    let state = &mut s.rays[r];
    let met = &s.met[s.met_at[r] as usize..s.met_at[r + 1] as usize];
    for (k, node) in s.nodes[r].iter_mut().enumerate() {
        let deep_id = state.deep_base + k as u32;
        if state.deep {
            if let Some(entry) = state.deep_nodes.get_mut(deep_id as usize) {
                entry.0 = node.weight;
            }
        }
        if node.weight > 0.0 && state.skipped_weight + node.weight <= budget {
            state.skipped_weight += node.weight;
            node.weight = 0.0;
        }
        if node.weight <= 0.0 {
            continue;
        }
        for (j, met) in met.iter().enumerate() {
            let (i, lr, slot) = (met.inst as usize, &met.local, node.slot as usize + j);
            // Only an instance with density here gets a share (tested before dividing).
            let sigma = s.inst_sigma[slot];
            if sigma <= 0.0 {
                continue;
            }
            let share = node.weight * sigma / node.sigma;
            if share > 0.0 {
                let (plan, query) = (&plans[i], &mut s.queries[i]);
                query.points.push(lr.at(node.probe));
                query.dirs.push(lr.dir);
                query.owners.push((r as u32, share));
                if state.deep {
                    query.deep_nodes.push(deep_id);
                }
                let at = slot * width;
                query
                    .features
                    .extend_from_slice(&s.features[at..at + plan.features]);
            }
        }
    }
}

/// Evaluates the colours [`queue_colours`] queued, one batched call per instance, and adds
/// them to the rays' colours.
pub(super) fn shade(plans: &[InstancePlan], s: &mut Scratch) {
    for &i in &s.tile_insts {
        let (plan, query) = (&plans[i as usize], &s.queries[i as usize]);
        if query.points.is_empty() {
            continue;
        }
        s.rgb_out.clear();
        s.rgb_out.resize(query.points.len(), Vec3::ZERO);
        s.tile_fields
            .field(plans, i as usize)
            .radiance_with_features(&query.points, &query.dirs, &query.features, &mut s.rgb_out);
        s.stats.color_samples += query.points.len() as u64;
        for (k, (&(r, share), c)) in query.owners.iter().zip(&s.rgb_out).enumerate() {
            let c = if plan.encode {
                c.map(linear_to_srgb)
            } else {
                *c
            };
            let c = c.as_dvec3().max(DVec3::ZERO);
            if c.is_finite() {
                let state = &mut s.rays[r as usize];
                state.rgb += c * share;
                if let Some(&id) = query.deep_nodes.get(k) {
                    if let Some(entry) = state.deep_nodes.get_mut(id as usize) {
                        entry.1 += c * share;
                    }
                }
            }
        }
    }
}
