//! A tile's rays before marching: world and local rays, runs, splat and volume fragments.

use glam::DVec3;

use super::integration::{composite_fragment, composite_fragments};
use super::plan::{cull_instances, may_meet, RayCone};
use super::RayState;
use super::{InstancePlan, Met, Scratch};
use crate::camera::Camera;
use crate::image::Window;
use crate::render::fragment::Fragment;
use crate::render::integrator::RunningComposite;
use crate::render::runs::{instance_runs, merge};
use crate::render::splats::Splatting;
use crate::render::volume::VolumeSampler;
use crate::render::Outputs;

/// Builds each pixel's world ray, its local rays, its occupied segments and its splat
/// fragments; a pixel with fragments and no segments is composited here and done.
#[allow(clippy::too_many_arguments)]
pub(super) fn setup_rays(
    plans: &[InstancePlan],
    volume_samplers: &[VolumeSampler],
    splats: Option<&Splatting>,
    camera: &Camera,
    tile: Window,
    outputs: &Outputs,
    deep: bool,
    s: &mut Scratch,
) {
    let n_rays = tile.area();
    s.rays.resize_with(n_rays, RayState::default);
    s.nodes.resize_with(n_rays, Vec::new);
    s.met.clear();
    s.met_at.clear();
    s.met_at.push(0);
    s.active.clear();
    camera.window_rays(tile, &mut s.world_rays);
    let cone = RayCone::of(&s.world_rays, tile.width() as usize, camera.rectilinear());
    cull_instances(plans, cone.as_ref(), &mut s.tile_insts);
    s.feature_width = (s.tile_insts.iter())
        .map(|&i| plans[i as usize].features)
        .max()
        .unwrap_or(0);
    s.tile_fields.cull(plans, cone.as_ref(), &s.tile_insts);
    for (r, state) in s.rays.iter_mut().enumerate().take(n_rays) {
        let ray = s.world_rays[r];
        state.ray = ray;
        state.pieces = RunningComposite::new();
        state.rgb = DVec3::ZERO;
        state.next_t = None;
        state.skipped_weight = 0.0;
        state.scale = 1.0;
        state.growing = false;
        state.allowed = f64::INFINITY;
        state.last_step = 0.0;
        state.refined = false;
        state.worst = 0.0;
        state.samples = 0;
        state.finest = 0.0;
        state.smooth = f64::INFINITY;
        state.densest = 0.0;
        state.log.clear();
        state.deep = deep;
        state.deep_pieces.clear();
        state.deep_nodes.clear();
        state.deep_base = 0;
        state.runs.clear();
        state.run = 0;
        state.inset = 0.0;
        s.nodes[r].clear();
        for &i in &s.tile_insts {
            let plan = &plans[i as usize];
            let inst = plan.instance;
            let Some(lr) = ray
                .filter(|ray| may_meet(plan, ray))
                .and_then(|ray| inst.local_ray(&ray, ray.near, ray.far))
            else {
                continue;
            };
            let inset = instance_runs(
                &lr,
                s.tile_fields.field(plans, i as usize),
                plan.capabilities,
                plan.occupancy.as_deref(),
                plan.unbounded.as_ref(),
                &mut s.run_scratch,
                &mut state.runs,
            );
            state.inset = state.inset.max(inset);
            s.met.push(Met {
                inst: i,
                local: lr,
                step: plan.base_step / lr.units_per_world as f64,
                grows: plan.unbounded.is_some(),
            });
        }
        s.met_at.push(s.met.len() as u32);
        merge(&mut state.runs, &mut s.run_scratch);
        state.fragments.clear();
        state.next_fragment = 0;
        state.volume.clear();
        state.next_volume = 0;
        state.live = !state.runs.is_empty();
        if state.live {
            s.active.push(r as u32);
        }
    }
    let sampled = !volume_samplers.is_empty();
    if sampled {
        s.fragments.volume.resize_with(n_rays, Vec::new);
        for f in &mut s.fragments.volume[..n_rays] {
            f.clear();
        }
        let volume = &mut s.fragments.volume[..n_rays];
        for sampler in volume_samplers {
            sampler.fill(
                &s.world_rays,
                &mut s.fragments.samplers,
                volume,
                &mut s.stats,
            );
        }
        if volume_samplers.len() > 1 {
            for f in volume.iter_mut() {
                f.sort_by(|a, b| a.t.total_cmp(&b.t));
            }
        }
        for (state, volume) in s.rays[..n_rays].iter_mut().zip(&mut s.fragments.volume) {
            std::mem::swap(&mut state.volume, volume);
        }
    }
    if let Some(layer) = splats {
        // A tile of splats alone is composited sixteen pixels at once.
        if s.active.is_empty() && !sampled && !outputs.depth_median && !deep {
            let depth = outputs.depth_z || outputs.depth_ray;
            let composited = layer.composite(
                tile,
                &s.world_rays,
                &mut s.fragments.z_per_t,
                depth,
                &mut s.fragments.splat_pixels,
            );
            if let Some(fragments) = composited {
                s.stats.splat_fragments += fragments;
                for (state, px) in s.rays[..n_rays].iter_mut().zip(&s.fragments.splat_pixels) {
                    state.pieces = RunningComposite::from_sums(px.transmittance, px.depth_moment);
                    state.rgb = DVec3::from_array(px.rgb);
                }
                return;
            }
        }
        let (rays, stats) = (&mut s.rays, &mut s.stats);
        // A ray that marches nothing and has no volume fragments composites its fragments as
        // they come; the others keep them to merge with their pieces or volume fragments.
        let sink = |i: usize, f: Fragment| {
            stats.splat_fragments += 1;
            let state = &mut rays[i];
            if state.live || !state.volume.is_empty() {
                state.fragments.push(f);
                true
            } else {
                composite_fragment(state, f, outputs)
            }
        };
        layer.fill(
            tile,
            &s.world_rays,
            &mut s.fragments.z_per_t,
            &mut s.fragments.along,
            sink,
        );
    }
    for state in &mut s.rays[..n_rays] {
        if !state.live {
            composite_fragments(state, f64::INFINITY, outputs);
        }
    }
}
