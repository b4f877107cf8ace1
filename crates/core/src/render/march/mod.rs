//! The per-tile marcher: estimator (runs, step policy, refinement) and integrator (pieces →
//! planes), batched across a tile.
//!
//! A tile's rays advance together in *chunks*. Each round, every live ray lays a chunk of
//! sample positions ("nodes") along its runs (module `runs`: the exact spans of fields that
//! give them, the occupied segments of the others); the tile asks each field once for all of
//! them; steps whose two ends disagree (a surface, a steep gradient), or between whose ends a
//! field's density bound rises above both (a sheet thinner than a step, a peak), are bisected
//! — again batched across the tile — until the step is resolved or the depth limit is hit.
//! A run whose ends are a span's has no edge or peak inside, so only its quadrature is
//! judged; a run of constant density is one node and one piece. Between two nodes the
//! density is taken as their mean (the trapezoid rule, exact for piecewise-constant fields
//! once an edge is bracketed), less the bias the curvature through their neighbours
//! predicts where the density is smooth (a trained field's step whose neighbours lie
//! within its smooth length). The pieces are composited in order; only then is
//! colour asked for, and only at nodes whose weight matters. A ray leaves the batch when its
//! transmittance falls below the threshold or its runs end.

mod hidden;
mod integration;
mod laying;
mod plan;
mod refinement;
mod sampling;
mod setup;
mod shading;
#[cfg(test)]
mod tests;

use std::sync::Arc;

use glam::{DVec3, Vec3};

use self::integration::integrate;
use self::laying::lay_nodes;
use self::plan::TileFields;
pub(super) use self::plan::{cull_instances, may_meet, RayCone};
use self::refinement::refine;
use self::sampling::evaluate_pending;
use self::setup::setup_rays;
use self::shading::{clear_colour_queries, queue_colours, shade};
use super::deep::{finish_pixel, DeepParams, DeepScratch, DeepTile, RawPiece};
use super::fragment::Fragment;
use super::integrator::{crossing_depth, srgb_composite_to_linear, RunningComposite};
use super::runs::{Run, RunScratch};
use super::splats::SplatPixel;
use super::splats::Splatting;
use super::volume::{VolumeSampler, VolumeScratch};
use super::{Outputs, RenderSettings, RenderStats};
use crate::camera::{Camera, Ray};
use crate::field::{Aabb, Capabilities, Occupancy, Unbounded};
use crate::image::Window;
use crate::scene::{Instance, LocalRay};

/// Bisections of one step at most, whatever the dials say: 52 halvings take any step below
/// the resolution of an `f64` distance.
const MAX_BISECTIONS: u32 = 52;

/// What one pixel ends up with.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct PixelResult {
    pub rgb: [f32; 3],
    pub alpha: f32,
    pub(crate) depth_ray: f32,
    pub(crate) depth_z: f32,
    pub(crate) depth_median: f32,
}

/// Per instance, what the marcher needs that does not change per ray.
pub(super) struct InstancePlan<'a> {
    /// The instance.
    pub(in crate::render) instance: &'a Instance,
    /// What the field declares it can answer besides densities and colours. Only a field
    /// that declares density bounds can have a step between two empty samples known to hold
    /// nothing, and grow.
    capabilities: Capabilities,
    /// The occupancy grid that finds the field's occupied segments; `None` for a field that
    /// declares [spans](crate::field::Field::spans) or
    /// [mask segments](crate::field::Field::mask_segments) instead.
    occupancy: Option<Arc<Occupancy>>,
    /// Base step in field units.
    base_step: f64,
    /// Floats of per-sample state the field passes from its density to its colour query.
    features: usize,
    /// The field's [`smooth_length`](crate::field::Field::smooth_length), field units.
    smooth: f64,
    /// A linear field in a scene composited in sRGB-encoded space: its colours are encoded.
    encode: bool,
    /// How the field is marched beyond its core, when it is defined on all of space.
    unbounded: Option<Unbounded>,
    /// The side of an occupancy cell, field units, for a field that cannot bound its
    /// density (infinite for the others): [`hides_gap`](hidden::hides_gap) probes a step
    /// with density at both ends for gaps no finer than `hidden::GAP_PROBES_PER_CELL` to a
    /// cell.
    cell: f64,
    /// A world sphere `(centre, radius)` around the field's occupied bounds, for culling the
    /// instance from a tile's rays at once and from each ray; `None` where they are empty
    /// or not finite.
    world_sphere: Option<(DVec3, f64)>,
    /// For an analytic field that gives its spans, a world sphere around each primitive
    /// (`None`: not finite), to cull the primitives from a tile's rays
    /// ([`TileFields`]); empty for other fields.
    primitive_spheres: Vec<Option<(DVec3, f64)>>,
    /// For an analytic field that gives its spans, each box primitive's placed corners and
    /// the margin its sphere is widened by (`None` for other shapes), to cull it by a
    /// pinhole tile's pyramid ([`RayCone::may_meet_box`](plan::RayCone::may_meet_box)).
    primitive_boxes: Vec<Option<([DVec3; 8], f64)>>,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    t: f64,
    /// Where the fields were sampled for this node: `t`, or just inside its run where `t`
    /// is a span's end, or the middle of a constant run.
    probe: f64,
    /// Total density per world unit.
    sigma: f64,
    /// Where this node's per-instance densities start in `Scratch::inst_sigma`: one slot
    /// per instance its ray meets, in the order of [`met_by`] (features: see
    /// [`Scratch::feature_width`]).
    slot: u32,
    /// No piece joins this node to the one before it (a run starts here).
    starts_run: bool,
    /// Its run's ends are the density's only edges
    /// ([`RunKind::Smooth`](super::runs::RunKind::Smooth),
    /// [`RunKind::Masked`](super::runs::RunKind::Masked) and
    /// [`RunKind::Constant`](super::runs::RunKind::Constant)): no edge, thin sheet or gap
    /// lies between its samples (nor a peak, but in a masked run).
    exact: bool,
    /// > 0: the node stands for the whole constant run `[t, t + extent]`, one piece.
    extent: f64,
    /// Colour weight gathered this round.
    weight: f64,
    /// Optical depth from the round's first node to this one
    /// ([`lay_depths_and_differences`](refinement::lay_depths_and_differences)).
    depth: f64,
    /// The twice second divided difference of the density through this node and its two
    /// neighbours ([`lay_depths_and_differences`](refinement::lay_depths_and_differences));
    /// NaN until it is worked out, and again once a neighbour changes.
    difference: f64,
}

/// A node to be evaluated (fields as in [`Node`]).
#[derive(Clone, Copy, Debug)]
struct Pending {
    ray: u32,
    t: f64,
    probe: f64,
    /// Where the node is probed instead if `probe` reads no density (`probe` itself
    /// where none is).
    inward: f64,
    starts_run: bool,
    exact: bool,
    extent: f64,
}

impl Pending {
    /// A node between `a` and another node of its run, sampled where it lies.
    fn between(ray: u32, t: f64, a: &Node) -> Self {
        Pending {
            ray,
            t,
            probe: t,
            inward: t,
            starts_run: false,
            exact: a.exact,
            extent: 0.0,
        }
    }
}

#[derive(Clone, Debug, Default)]
struct RayState {
    ray: Option<Ray>,
    pieces: RunningComposite,
    rgb: DVec3,
    /// The ray's runs (see module `runs`), and the current one.
    runs: Vec<Run>,
    run: usize,
    /// Next node position inside the current run; `None`: at the run's start.
    next_t: Option<f64>,
    /// How far inside a span's end its sample is taken (world units).
    inset: f64,
    live: bool,
    /// Weight whose colour was not evaluated.
    skipped_weight: f64,
    /// The pieces `[t, δ, σ₀δ, σ₁δ, T_enter]` composited so far, kept only for the median
    /// depth (see [`crossing_depth`]).
    log: Vec<[f64; 5]>,
    /// The pixel's splat fragments, front to back, and the next one to composite.
    fragments: Vec<Fragment>,
    next_fragment: usize,
    /// The pixel's volume fragments of sampled instances (modules `proposal`, `ngp`),
    /// front to back, and the next one to composite.
    volume: Vec<Fragment>,
    next_volume: usize,
    /// In searched runs: the next regular step as a multiple of the base step (see
    /// `laying::step_at`), and whether it doubles from node to node: the ray's last steps
    /// were all well within the error target.
    scale: f64,
    growing: bool,
    /// In exact runs (whose steps the error rule sets, not `scale`): the longest step the
    /// rule allows after the last round that measured a curvature
    /// (`integration::allowed_step`; unbounded before any did), and the last step
    /// laid (world units).
    allowed: f64,
    last_step: f64,
    /// Whether a step of this round was bisected, and the largest weighted error estimate
    /// of this round's steps.
    refined: bool,
    worst: f64,
    /// Nodes evaluated for this ray so far (its share of the sample budget).
    samples: u32,
    /// The shortest step bisection may leave this round: the base step where the round's
    /// nodes start, halved `refine_depth` times (a grown step may be bisected further than
    /// its own `refine_depth` halvings, never below this, but a step that can hold no edge,
    /// see `refinement::split_candidates`).
    finest: f64,
    /// The shortest smooth length (world units) of the fields the ray meets, where the
    /// round's nodes start (`laying::smooth_length_at`; 0 where one is analytic): an exact
    /// run's step whose neighbours lie within it is composited less its curvature's bias
    /// (`integration::unbiased_ends`).
    smooth: f64,
    /// The densest node of the ray's rounds so far, for the shell rule of a trained field's
    /// long steps (`refinement::split_candidates`): a round's nodes may all lie past the
    /// density that the surface it is inside reaches.
    densest: f64,
    /// A deep render: the ray's composited pieces and fragments are kept ([`DeepPiece`]).
    deep: bool,
    deep_pieces: Vec<DeepPiece>,
    /// Per node integrated (numbered across the ray's rounds), the weight its pieces gave it
    /// and the premultiplied colour its shading added, for the pieces' colours.
    deep_nodes: Vec<(f64, DVec3)>,
    /// The number of this round's first node in `deep_nodes`.
    deep_base: u32,
}

/// A piece or fragment of a deep render's ray, before its colour is known: its own colour
/// contribution (a fragment's), plus shares of up to two nodes' colours (a marched piece's
/// weight goes to its end nodes as the flat render's does); `NO_NODE` where there is none.
#[derive(Clone, Copy, Debug)]
struct DeepPiece {
    piece: RawPiece,
    nodes: [(u32, f64); 2],
}

/// No node: see [`DeepPiece`].
const NO_NODE: u32 = u32::MAX;
/// A piece whose nodes the integrator names once it has split its weight.
const PENDING_NODE: u32 = u32::MAX - 1;

impl DeepPiece {
    /// The piece with its colour: its own plus its nodes' shares.
    fn resolved(&self, nodes: &[(f64, DVec3)]) -> RawPiece {
        let mut piece = self.piece;
        for &(n, share) in &self.nodes {
            if let Some(&(weight, rgb)) = nodes.get(n as usize) {
                if weight > 0.0 {
                    piece.rgb += rgb * (share / weight);
                }
            }
        }
        piece
    }
}

impl RayState {
    /// Logs a piece `[t, δ, σ₀δ, σ₁δ, T_enter]` for the median depth, unless the log already
    /// holds its answer: [`crossing_depth`] stops at the first piece whose exit transmittance
    /// is at most `1 − alpha/2` (never below ½) and whose entry one is above 0, and a piece
    /// entered at `0 < T ≤ ½` is such a piece whatever follows it.
    #[inline]
    fn log_piece(&mut self, piece: [f64; 5]) {
        let complete = self
            .log
            .last()
            .is_some_and(|last| last[4] > 0.0 && last[4] <= 0.5);
        if !complete {
            self.log.push(piece);
        }
    }

    /// Distance of the next fragment to composite, splat or volume.
    fn next_fragment_t(&self) -> Option<f64> {
        let splat = self.fragments.get(self.next_fragment).map(|f| f.t);
        let volume = self.volume.get(self.next_volume).map(|f| f.t);
        match (splat, volume) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// An instance a ray meets: its local ray, and its steps along it
/// ([`base_step_at`](laying::base_step_at)), worked out once per ray.
#[derive(Clone, Copy, Debug)]
struct Met {
    /// The instance's index in the scene.
    inst: u32,
    /// The ray in the instance's field; where it is inside the instance
    /// (`t_near..=t_far`).
    local: LocalRay,
    /// The instance's base step in world units, before an unbounded field's growth.
    step: f64,
    /// The instance's steps grow with distance (an unbounded field).
    grows: bool,
}

/// One instance's batched field query: sample points (and directions and features, for
/// colour), and what each answer goes to: a pending node and its field units per world unit
/// (density), or a ray and its share of the weight (colour).
#[derive(Default)]
struct FieldQuery {
    points: Vec<Vec3>,
    dirs: Vec<Vec3>,
    features: Vec<f32>,
    owners: Vec<(u32, f64)>,
    /// A deep render's colour query: per owner, the node (numbered as in
    /// `RayState::deep_nodes`) the colour is for.
    deep_nodes: Vec<u32>,
}

impl FieldQuery {
    fn clear(&mut self) {
        self.deep_nodes.clear();
        self.points.clear();
        self.dirs.clear();
        self.features.clear();
        self.owners.clear();
    }
}

/// Per-thread scratch reused from tile to tile: no allocation per sample.
#[derive(Default)]
pub(super) struct Scratch {
    rays: Vec<RayState>,
    /// The rays still marching, in pixel order.
    active: Vec<u32>,
    /// Per ray, the instances it has a local ray in (`met[met_at[r]..met_at[r + 1]]`,
    /// ascending, see [`met_by`]): the only ones its samples visit and keep densities of, so
    /// a sample's cost does not grow with the scene's instance count.
    met: Vec<Met>,
    met_at: Vec<u32>,
    /// Per instance, the items (pending nodes, steps, rays) of one batched query, each with
    /// its ray's entry in `met`.
    by_inst: Vec<Vec<(u32, u32)>>,
    /// The instances some ray of the tile may meet, ascending
    /// ([`cull_instances`]): the only ones a tile's rays look at, or
    /// its rounds batch queries for.
    tile_insts: Vec<u32>,
    /// Floats of field features kept per slot (a node and an instance its ray meets): the
    /// most any of the tile's instances has, so a slot's features start at
    /// `slot · feature_width`, and a tile that meets only featureless fields keeps none.
    feature_width: usize,
    /// Per instance, the field its spans, densities and colours on the tile's rays are asked
    /// of ([`TileFields`]); its bounds and density bounds are the instance's own field's.
    tile_fields: TileFields,
    run_scratch: RunScratch,
    nodes: Vec<Vec<Node>>,
    inst_sigma: Vec<f64>,
    inst_sigma_prev: Vec<f64>,
    /// Field features per slot (`feature_width` each), and last round's.
    features: Vec<f32>,
    features_prev: Vec<f32>,
    pending: Vec<Pending>,
    /// The new nodes of one ray while they are merged in among its others.
    settling: Vec<Node>,
    /// What refinement's tests of a round's steps keep.
    refine: RefineScratch,
    field_out: Vec<f32>,
    rgb_out: Vec<Vec3>,
    /// Per instance, one batched query (of [`evaluate_pending`] or [`shade`]).
    queries: Vec<FieldQuery>,
    /// Per pixel of the tile: its world ray.
    world_rays: Vec<Option<Ray>>,
    /// The tile's splat and volume fragments before they join its rays.
    fragments: FragmentScratch,
    stats: RenderStats,
    /// A deep render's per-pixel buffers.
    deep: DeepBuffers,
}

/// What refinement keeps of a round's steps.
#[derive(Default)]
struct RefineScratch {
    /// Pairs `(ray, first node)` to test for refinement.
    candidates: Vec<(u32, u32)>,
    /// Candidates that passed the jump test, with their density bound.
    unsure: Vec<(u32, u32, f64)>,
    /// Step boxes for one batched density-bound query, and each one's owner.
    regions: Vec<Aabb>,
    owners: Vec<(u32, f64)>,
}

/// A tile's fragments before they join its rays.
#[derive(Default)]
struct FragmentScratch {
    /// Per pixel, camera z per unit ray distance; one ray's splat fragments (panoramic
    /// cameras); the splat layer's composited pixels.
    z_per_t: Vec<f64>,
    along: Vec<Fragment>,
    splat_pixels: Vec<SplatPixel>,
    /// Per pixel of the tile: its sampled instances' fragments, and the samplers' buffers.
    volume: Vec<Vec<Fragment>>,
    samplers: VolumeScratch,
}

/// A deep render's per-pixel buffers: the finishing scratch, and a ray's pieces resolved.
#[derive(Default)]
struct DeepBuffers {
    finish: DeepScratch,
    resolved: Vec<RawPiece>,
}

/// What a deep render asks of a tile: the samples to keep, and whether the flat colours are
/// decoded from the sRGB-encoded composite.
#[derive(Clone, Copy, Debug)]
pub(super) struct DeepPass {
    pub params: DeepParams,
    pub(crate) decode: bool,
}

/// Marches one tile. `out` receives the tile's pixels row by row, and `deep`'s tile their
/// deep samples where it is given.
#[allow(clippy::too_many_arguments)]
pub(super) fn march_tile(
    plans: &[InstancePlan],
    volume: &[VolumeSampler],
    splats: Option<&Splatting>,
    camera: &Camera,
    tile: Window,
    settings: &RenderSettings,
    s: &mut Scratch,
    out: &mut Vec<PixelResult>,
    deep: Option<(&DeepPass, &mut DeepTile)>,
) -> RenderStats {
    let (params, outputs) = (&settings.march, &settings.outputs);
    let n_rays = tile.area();
    setup_rays(
        plans,
        volume,
        splats,
        camera,
        tile,
        outputs,
        deep.is_some(),
        s,
    );
    let width = s.feature_width;
    let empty_is_known = plans.iter().all(|p| p.capabilities.density_bounds);

    while !s.active.is_empty() {
        // Each live ray keeps its last node (the start of its next piece), then lays more.
        std::mem::swap(&mut s.inst_sigma, &mut s.inst_sigma_prev);
        std::mem::swap(&mut s.features, &mut s.features_prev);
        s.inst_sigma.clear();
        s.features.clear();
        s.pending.clear();
        for a in 0..s.active.len() {
            let r = s.active[a] as usize;
            // A constant run's node is a piece of its own, never the start of the next one.
            let carried = s.nodes[r].last().copied().filter(|n| n.extent == 0.0);
            s.nodes[r].clear();
            if let Some(mut node) = carried {
                let (slot, n) = (node.slot as usize, met_by(s, r).len());
                node.slot = s.inst_sigma.len() as u32;
                s.inst_sigma
                    .extend_from_slice(&s.inst_sigma_prev[slot..slot + n]);
                s.features
                    .extend_from_slice(&s.features_prev[slot * width..(slot + n) * width]);
                node.weight = 0.0;
                node.difference = f64::NAN;
                s.nodes[r].push(node);
            }
            lay_nodes(r, plans, params, s);
        }
        evaluate_pending(plans, s);

        refine(plans, params, s);

        // Integrate the pieces, in order, and queue colour where their weight matters.
        if outputs.rgb {
            clear_colour_queries(plans.len(), s);
        }
        for a in 0..s.active.len() {
            let r = s.active[a] as usize;
            integrate(
                &mut s.rays[r],
                &mut s.nodes[r],
                params,
                outputs,
                empty_is_known,
                &mut s.stats.budget_limited_rays,
            );
            if outputs.rgb {
                queue_colours(r, plans, params, s);
            }
        }
        if outputs.rgb {
            shade(plans, s);
        }
        let rays = &s.rays;
        s.active.retain(|&r| rays[r as usize].live);
    }

    out.clear();
    out.extend(s.rays[..n_rays].iter().map(|st| finish(st, outputs)));
    if let Some((pass, tile_out)) = deep {
        tile_out.clear();
        for (st, px) in s.rays[..n_rays].iter().zip(out.iter()) {
            s.deep.resolved.clear();
            s.deep
                .resolved
                .extend(st.deep_pieces.iter().map(|p| p.resolved(&st.deep_nodes)));
            let rgb = if pass.decode {
                srgb_composite_to_linear(px.rgb, px.alpha)
            } else {
                px.rgb
            };
            let z_per_t = st.ray.map_or(1.0, |r| r.z_per_t);
            finish_pixel(
                &s.deep.resolved,
                z_per_t,
                rgb,
                pass.decode,
                &pass.params,
                &mut s.deep.finish,
                tile_out,
            );
        }
    }
    RenderStats {
        pixels: n_rays as u64,
        ..std::mem::take(&mut s.stats)
    }
}

/// The instances ray `r` has a local ray in, ascending: the `j`th keeps its densities in
/// slot `node.slot + j` of each of the ray's nodes.
#[inline]
fn met_by(s: &Scratch, r: usize) -> &[Met] {
    &s.met[s.met_at[r] as usize..s.met_at[r + 1] as usize]
}

/// Sorts `items` (an item and its ray) into one list per instance the ray has a local ray
/// in, each with the ray's entry of `s.met` for it, keeping their order: a batched query per
/// instance then visits only its own items. Only the tile's instances' lists are cleared
/// and filled: no other is to be read.
fn bucket_by_instance(
    by_inst: &mut Vec<Vec<(u32, u32)>>,
    n_inst: usize,
    tile_insts: &[u32],
    met: &[Met],
    met_at: &[u32],
    items: impl Iterator<Item = (u32, u32)>,
) {
    by_inst.resize_with(n_inst, Vec::new);
    for &i in tile_insts {
        by_inst[i as usize].clear();
    }
    for (item, r) in items {
        let r = r as usize;
        for e in met_at[r]..met_at[r + 1] {
            by_inst[met[e as usize].inst as usize].push((item, e));
        }
    }
}

fn finish(state: &RayState, outputs: &Outputs) -> PixelResult {
    let alpha = state.pieces.accumulation();
    let depth = state.pieces.expected_depth();
    let z_per_t = state.ray.map_or(1.0, |r| r.z_per_t);
    PixelResult {
        rgb: state.rgb.as_vec3().to_array(),
        alpha: alpha as f32,
        depth_ray: depth as f32,
        depth_z: (depth * z_per_t) as f32,
        depth_median: if outputs.depth_median {
            crossing_depth(&state.log, 0.5 * alpha) as f32
        } else {
            f32::INFINITY
        },
    }
}
