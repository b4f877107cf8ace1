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
//! once an edge is bracketed). The pieces are composited in order; only then is colour asked
//! for, and only at nodes whose weight matters. A ray leaves the batch when its transmittance
//! falls below the threshold or its runs end.

use std::sync::Arc;

use glam::{DVec3, Vec3};

use super::composite::{crossing_depth, far_share, Pieces};
use super::ngp::{self, NgpFill};
use super::proposal::{self, ProposalScratch};
use super::runs::{instance_runs, merge, Run, RunKind, RunScratch};
use super::splats::Splatting;
use super::{MarchParams, Outputs, RenderSettings, RenderStats};
use crate::camera::{Camera, Ray};
use crate::field::{
    linear_to_srgb, Aabb, ColorSpace, Field, Fragment, Occupancy, Span, SplatPixel, Unbounded,
    SPLAT_MIN_TRANSMITTANCE,
};
use crate::image::Window;
use crate::scene::{LocalRay, Scene};

/// Nodes a live ray lays per round: small, so rays that stop at a surface waste few
/// samples past it (measured: 4 and 16 cost more samples or more rounds than 8).
const CHUNK: usize = 8;

/// Bisections of one step at most, whatever the dials say: 52 halvings take any step below
/// the resolution of an `f64` distance.
const MAX_BISECTIONS: u32 = 52;

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
const HIDDEN_DEPTH: i32 = 5;

/// Halvings at most in the search for a point of a step that [`hides_content`]
/// ([`hidden_point`]): 2^-24 of the step is below an `f32` position's resolution.
const HIDDEN_SEARCH_DEPTH: u32 = 24;

/// Midpoints asked at most in one [`hidden_point`] search: a box padded past a cell's face
/// keeps its halves next to the face "occupied" down to the depth limit, so a search may
/// follow a dead end before it finds the cell or gives up (then the step is halved). As many
/// as the depth: a search that meets no dead end reaches it.
const HIDDEN_SEARCH_QUERIES: u32 = 24;

/// What one pixel ends up with.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct PixelResult {
    pub rgb: [f32; 3],
    pub alpha: f32,
    pub depth_ray: f32,
    pub depth_z: f32,
    pub depth_median: f32,
}

/// Per instance, what the marcher needs that does not change per ray.
pub(super) struct InstancePlan {
    /// The occupancy grid that finds the field's occupied segments; `None` for a field that
    /// gives its [spans](crate::field::Field::spans) or
    /// [mask segments](crate::field::Field::mask_segments) instead.
    occupancy: Option<Arc<Occupancy>>,
    /// Base step in field units.
    base_step: f64,
    /// Floats of per-sample state the field passes from its density to its colour query,
    /// and where they start among a node's features (the instances' side by side).
    features: usize,
    feature_offset: usize,
    /// The field's [`smooth_length`](crate::field::Field::smooth_length), field units.
    smooth: f64,
    /// A linear field in a scene composited in sRGB-encoded space: its colours are encoded.
    encode: bool,
    /// How the field is marched beyond its core, when it is defined on all of space.
    unbounded: Option<Unbounded>,
    /// Whether the field bounds its density over a region ([`Field::density_bounds`]): only
    /// then can a step between two empty samples be known to hold nothing, and grow.
    bounded: bool,
    /// The side of an occupancy cell, field units, for a field that cannot bound its
    /// density (infinite for the others): [`hides_gap`] probes a step with density at both
    /// ends for gaps no finer than [`GAP_PROBES_PER_CELL`] to a cell.
    cell: f64,
    /// A world sphere `(centre, radius)` around the field's bounds, for culling the instance
    /// from a tile's rays at once; `None` where the bounds are not finite.
    world_sphere: Option<(DVec3, f64)>,
}

impl InstancePlan {
    pub(super) fn for_scene(scene: &Scene, params: &MarchParams) -> Vec<InstancePlan> {
        let mut feature_offset = 0;
        let space = scene.composite_space();
        scene
            .instances
            .iter()
            .map(|inst| {
                let features = inst.field().feature_count();
                feature_offset += features;
                let spans =
                    inst.field()
                        .spans(Vec3::ZERO, Vec3::X, 0.0, 0.0, &mut Vec::<Span>::new());
                let exact = spans
                    || inst
                        .field()
                        .mask_segments(Vec3::ZERO, Vec3::X, 0.0, 0.0, &mut Vec::new());
                let occupancy =
                    (!exact).then(|| inst.handle().occupancy(params.occupancy_resolution));
                let bounded = inst
                    .field()
                    .density_bounds(&[inst.field().bounds()], &mut [0.0]);
                // Without bounds, gaps may hide between samples: a field with spans or
                // mask segments has none unseen; one with an occupancy grid has its steps
                // probed for them.
                let cell = match &occupancy {
                    Some(o) if !bounded => {
                        o.bounds().size().min_element() as f64 / f64::from(o.resolution().max(1))
                    }
                    _ => f64::INFINITY,
                };
                InstancePlan {
                    occupancy,
                    base_step: inst.field().feature_size() as f64
                        / params.steps_per_feature.max(1e-3) as f64,
                    features,
                    feature_offset: feature_offset - features,
                    smooth: inst.field().smooth_length().max(0.0) as f64,
                    encode: space == ColorSpace::Srgb
                        && inst.field().color_space() == ColorSpace::Linear,
                    unbounded: inst.field().unbounded(),
                    bounded,
                    cell,
                    world_sphere: world_sphere(inst.field().bounds(), inst.world_from_field()),
                }
            })
            .collect()
    }
}

/// The smallest world sphere around the world box of a field's bounds `b` (its eight
/// corners placed by `world_from_field`); `None` where they are empty or not finite.
fn world_sphere(b: Aabb, world_from_field: glam::DMat4) -> Option<(DVec3, f64)> {
    if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
        return None;
    }
    let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
    let (mut wlo, mut whi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for k in 0..8 {
        let corner = DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let w = world_from_field.transform_point3(corner);
        (wlo, whi) = (wlo.min(w), whi.max(w));
    }
    let centre = 0.5 * (wlo + whi);
    let radius = 0.5 * (whi - wlo).length();
    (centre.is_finite() && radius.is_finite()).then_some((centre, radius))
}

/// Marks in `keep` the instances some ray of a tile may meet. The rays start within `ρ` of
/// their mean origin `c` and point within `θ` of their mean direction `m`: such a ray meets
/// a sphere `(b, R)` only if the ray from `c` along its direction meets `(b, R + ρ)`, which
/// needs the angle between `m` and `b − c` to be at most `θ + asin((R + ρ)/|b − c|)`. A
/// wide bundle (`θ` of 90° or more: panoramic tiles) and unbounded instances keep all.
/// This makes a tile's setup cost per instance, not per instance and pixel.
fn cull_instances(plans: &[InstancePlan], rays: &[Option<Ray>], keep: &mut Vec<bool>) {
    keep.clear();
    keep.resize(plans.len(), true);
    let (mut origin, mut dir, mut n) = (DVec3::ZERO, DVec3::ZERO, 0.0);
    for ray in rays.iter().flatten() {
        origin += ray.origin;
        dir += ray.dir;
        n += 1.0;
    }
    // No rays, or directions that cancel out: nothing to cull by.
    let Some(m) = dir.try_normalize() else {
        return;
    };
    let c = origin / n;
    let (mut rho, mut cos_theta) = (0.0f64, 1.0f64);
    for ray in rays.iter().flatten() {
        rho = rho.max((ray.origin - c).length());
        cos_theta = cos_theta.min(ray.dir.dot(m) / ray.dir.length());
    }
    // NaN directions fail this too.
    if cos_theta.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !rho.is_finite() {
        return;
    }
    // A margin for rounding in the angles.
    let theta = cos_theta.min(1.0).acos() + 1e-6;
    for (keep, plan) in keep.iter_mut().zip(plans) {
        let Some((b, radius)) = plan.world_sphere else {
            continue;
        };
        let v = b - c;
        let (l, reach) = (v.length(), radius + rho);
        if l <= reach * (1.0 + 1e-9) {
            continue;
        }
        let alpha = (v.dot(m) / l).clamp(-1.0, 1.0).acos();
        *keep = alpha - (reach / l).min(1.0).asin() <= theta;
    }
}

/// Floats of field features per node: every instance's, side by side.
fn feature_stride(plans: &[InstancePlan]) -> usize {
    plans.iter().map(|p| p.features).sum()
}

#[derive(Clone, Copy, Debug)]
struct Node {
    t: f64,
    /// Where the fields were sampled for this node: `t`, or just inside its run where `t`
    /// is a span's end, or the middle of a constant run.
    probe: f64,
    /// Total density per world unit.
    sigma: f64,
    /// Where this node's per-instance densities start in `Scratch::inst_sigma`.
    slot: u32,
    /// No piece joins this node to the one before it (a run starts here).
    starts_run: bool,
    /// Its run's ends are the density's only edges and peaks ([`RunKind::Smooth`] and
    /// [`RunKind::Constant`]): no edge, thin sheet or peak lies between its samples.
    exact: bool,
    /// > 0: the node stands for the whole constant run `[t, t + extent]`, one piece.
    extent: f64,
    /// Colour weight gathered this round.
    weight: f64,
    /// Optical depth from the round's first node to this one ([`lay_depths`]).
    depth: f64,
}

/// A node to be evaluated (fields as in [`Node`]).
#[derive(Clone, Copy, Debug)]
struct Pending {
    ray: u32,
    t: f64,
    probe: f64,
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
            starts_run: false,
            exact: a.exact,
            extent: 0.0,
        }
    }
}

#[derive(Clone, Debug, Default)]
struct RayState {
    ray: Option<Ray>,
    pieces: Pieces,
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
    /// The next regular step as a multiple of the base step (see [`step_at`]), and whether
    /// it doubles from node to node: the ray's last steps were all well within the error
    /// target.
    scale: f64,
    growing: bool,
    /// Whether a step of this round was bisected, and the largest weighted error estimate
    /// of this round's steps.
    refined: bool,
    worst: f64,
    /// Nodes evaluated for this ray so far (its share of the sample budget).
    samples: u32,
    /// The shortest step bisection may leave this round: the base step where the round's
    /// nodes start, halved `refine_depth` times (a grown step may be bisected further than
    /// its own `refine_depth` halvings, never below this).
    finest: f64,
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

/// One instance's steps along one ray ([`base_step_at`]), worked out once per ray.
#[derive(Clone, Copy, Debug)]
struct RaySteps {
    /// Where the ray is inside the instance (world distance).
    t_near: f64,
    t_far: f64,
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
}

impl FieldQuery {
    fn clear(&mut self) {
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
    /// `local[ray · n_instances + i]`.
    local: Vec<Option<LocalRay>>,
    /// Per ray, the instances it has a local ray in (`ray_insts[ray_inst_at[r]..
    /// ray_inst_at[r + 1]]`, ascending): the only ones its samples visit, so a sample's cost
    /// does not grow with the scene's instance count.
    ray_insts: Vec<u32>,
    ray_inst_at: Vec<u32>,
    /// Per entry of `ray_insts`, that instance's steps along the ray.
    ray_steps: Vec<RaySteps>,
    /// Per instance, the items (pending nodes, steps, rays) of one batched query.
    by_inst: Vec<Vec<u32>>,
    /// Per instance, whether some ray of the tile may meet it ([`cull_instances`]).
    tile_insts: Vec<bool>,
    run_scratch: RunScratch,
    nodes: Vec<Vec<Node>>,
    inst_sigma: Vec<f64>,
    inst_sigma_prev: Vec<f64>,
    /// Field features per node (`slot / n_instances · stride + offset`), and last round's.
    features: Vec<f32>,
    features_prev: Vec<f32>,
    pending: Vec<Pending>,
    /// Pairs `(ray, first node)` to test for refinement.
    candidates: Vec<(u32, u32)>,
    /// Candidates that passed the jump test, with their density bound.
    unsure: Vec<(u32, u32, f64)>,
    /// Step boxes for one batched density-bound query.
    regions: Vec<Aabb>,
    owners: Vec<(u32, f64)>,
    field_out: Vec<f32>,
    rgb_out: Vec<Vec3>,
    /// Per instance, one batched query (of [`evaluate_pending`] or [`shade`]).
    queries: Vec<FieldQuery>,
    /// Per pixel of the tile: its world ray and camera z per unit ray distance; one ray's
    /// splat fragments (panoramic cameras).
    world_rays: Vec<Option<Ray>>,
    z_per_t: Vec<f64>,
    along: Vec<Fragment>,
    splat_pixels: Vec<SplatPixel>,
    /// Per pixel of the tile: its sampled instances' fragments.
    volume: Vec<Vec<Fragment>>,
    proposal: ProposalScratch,
    ngp: NgpFill,
    stats: RenderStats,
}

/// Marches one tile. `out` receives the tile's pixels row by row.
#[allow(clippy::too_many_arguments)]
pub(super) fn march_tile(
    scene: &Scene,
    plans: &[InstancePlan],
    splats: Option<&Splatting>,
    camera: &Camera,
    tile: Window,
    settings: &RenderSettings,
    s: &mut Scratch,
    out: &mut Vec<PixelResult>,
) -> RenderStats {
    let (params, outputs) = (&settings.march, &settings.outputs);
    let n_inst = scene.instances.len();
    let stride = feature_stride(plans);
    let n_rays = tile.area();
    setup_rays(scene, plans, splats, camera, tile, outputs, s);
    let empty_is_known = plans.iter().all(|p| p.bounded);

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
                let slot = node.slot as usize;
                node.slot = s.inst_sigma.len() as u32;
                s.inst_sigma
                    .extend_from_slice(&s.inst_sigma_prev[slot..slot + n_inst]);
                let f = slot / n_inst * stride;
                s.features
                    .extend_from_slice(&s.features_prev[f..f + stride]);
                node.weight = 0.0;
                s.nodes[r].push(node);
            }
            lay_nodes(r, plans, params, s);
        }
        evaluate_pending(scene, plans, s);

        refine(scene, plans, params, s);

        // Integrate the pieces, in order.
        for &r in &s.active {
            let r = r as usize;
            integrate(
                &mut s.rays[r],
                &mut s.nodes[r],
                params,
                outputs,
                empty_is_known,
                &mut s.stats.budget_limited_rays,
            );
        }

        if outputs.rgb {
            shade(scene, plans, params, s);
        }
        let rays = &s.rays;
        s.active.retain(|&r| rays[r as usize].live);
    }

    out.clear();
    out.extend(s.rays[..n_rays].iter().map(|st| finish(st, outputs)));
    RenderStats {
        pixels: n_rays as u64,
        ..std::mem::take(&mut s.stats)
    }
}

/// Builds each pixel's world ray, its local rays, its occupied segments and its splat
/// fragments; a pixel with fragments and no segments is composited here and done.
fn setup_rays(
    scene: &Scene,
    plans: &[InstancePlan],
    splats: Option<&Splatting>,
    camera: &Camera,
    tile: Window,
    outputs: &Outputs,
    s: &mut Scratch,
) {
    let n_rays = tile.area();
    s.rays.resize_with(n_rays, RayState::default);
    s.nodes.resize_with(n_rays, Vec::new);
    s.local.clear();
    s.ray_insts.clear();
    s.ray_steps.clear();
    s.ray_inst_at.clear();
    s.ray_inst_at.push(0);
    s.active.clear();
    s.world_rays.clear();
    s.world_rays.extend((0..n_rays).map(|r| {
        let x = tile.x0 + (r % tile.width() as usize) as u32;
        let y = tile.y0 + (r / tile.width() as usize) as u32;
        camera.ray(x as f64 + 0.5, y as f64 + 0.5)
    }));
    cull_instances(plans, &s.world_rays, &mut s.tile_insts);
    for (r, state) in s.rays.iter_mut().enumerate().take(n_rays) {
        let ray = s.world_rays[r];
        state.ray = ray;
        state.pieces = Pieces::new();
        state.rgb = DVec3::ZERO;
        state.next_t = None;
        state.skipped_weight = 0.0;
        state.scale = 1.0;
        state.growing = false;
        state.refined = false;
        state.worst = 0.0;
        state.samples = 0;
        state.finest = 0.0;
        state.log.clear();
        state.runs.clear();
        state.run = 0;
        state.inset = 0.0;
        s.nodes[r].clear();
        for (i, (inst, plan)) in scene.instances.iter().zip(plans).enumerate() {
            let local = ray
                .filter(|_| s.tile_insts[i])
                .and_then(|ray| inst.local_ray(&ray, ray.near, ray.far));
            if let Some(lr) = &local {
                let inset = instance_runs(
                    lr,
                    inst.field(),
                    plan.occupancy.as_deref(),
                    plan.unbounded.as_ref(),
                    &mut s.run_scratch,
                    &mut state.runs,
                );
                state.inset = state.inset.max(inset);
                s.ray_insts.push(i as u32);
                s.ray_steps.push(RaySteps {
                    t_near: lr.t_near,
                    t_far: lr.t_far,
                    step: plan.base_step / lr.units_per_world as f64,
                    grows: plan.unbounded.is_some(),
                });
            }
            s.local.push(local);
        }
        s.ray_inst_at.push(s.ray_insts.len() as u32);
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
    if scene.has_sampled() {
        s.volume.resize_with(n_rays, Vec::new);
        for f in &mut s.volume[..n_rays] {
            f.clear();
        }
        let volume = &mut s.volume[..n_rays];
        proposal::fill(scene, &s.world_rays, &mut s.proposal, volume, &mut s.stats);
        ngp::fill(scene, &s.world_rays, &mut s.ngp, volume, &mut s.stats);
        if scene.proposal.len() + scene.ngp.len() > 1 {
            for f in volume.iter_mut() {
                f.sort_by(|a, b| a.t.total_cmp(&b.t));
            }
        }
        for (state, volume) in s.rays[..n_rays].iter_mut().zip(&mut s.volume) {
            std::mem::swap(&mut state.volume, volume);
        }
    }
    if let Some(layer) = splats {
        // A tile of splats alone is composited sixteen pixels at once.
        if s.active.is_empty() && !scene.has_sampled() && !outputs.depth_median {
            let composited =
                layer.composite(tile, &s.world_rays, &mut s.z_per_t, &mut s.splat_pixels);
            if let Some(fragments) = composited {
                s.stats.splat_fragments += fragments;
                for (state, px) in s.rays[..n_rays].iter_mut().zip(&s.splat_pixels) {
                    state.pieces = Pieces::from_sums(px.transmittance, px.depth_moment);
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
        layer.fill(tile, &s.world_rays, &mut s.z_per_t, &mut s.along, sink);
    }
    for state in &mut s.rays[..n_rays] {
        if !state.live {
            composite_fragments(state, f64::INFINITY, outputs);
        }
    }
}

/// The instances ray `r` has a local ray in, ascending.
#[inline]
fn instances_of(s: &Scratch, r: usize) -> &[u32] {
    &s.ray_insts[s.ray_inst_at[r] as usize..s.ray_inst_at[r + 1] as usize]
}

/// Sorts `items` (an item and its ray) into one list per instance the ray has a local ray
/// in, keeping their order: a batched query per instance then visits only its own items.
fn bucket_by_instance(
    by_inst: &mut Vec<Vec<u32>>,
    n_inst: usize,
    ray_insts: &[u32],
    ray_inst_at: &[u32],
    items: impl Iterator<Item = (u32, u32)>,
) {
    by_inst.resize_with(n_inst, Vec::new);
    for list in by_inst.iter_mut() {
        list.clear();
    }
    for (item, r) in items {
        let r = r as usize;
        for &i in &ray_insts[ray_inst_at[r] as usize..ray_inst_at[r + 1] as usize] {
            by_inst[i as usize].push(item);
        }
    }
}

/// The step at world distance `t` on a ray whose base step there is `base` (see
/// [`base_step_at`]): the base step times the ray's current growth `scale` (or grown with
/// distance by the cone, whichever is longer), at most `max_step_factor` base steps.
fn step_at(base: f64, t: f64, scale: f64, params: &MarchParams) -> f64 {
    let longest = base * params.max_step_factor.max(1.0) as f64;
    let grown = (params.cone as f64 * t).max(base * scale);
    grown.min(longest).max(base).max(f64::MIN_POSITIVE)
}

/// The base step at world distance `t` on ray `r`, before growth and the cone: the finest
/// among the instances the ray is inside at `t` (each grown beyond an unbounded field's
/// core).
fn base_step_at(r: usize, t: f64, plans: &[InstancePlan], s: &Scratch) -> f64 {
    let n_inst = plans.len();
    let (mut here, mut anywhere) = (f64::INFINITY, f64::INFINITY);
    let range = s.ray_inst_at[r] as usize..s.ray_inst_at[r + 1] as usize;
    for (&i, steps) in s.ray_insts[range.clone()].iter().zip(&s.ray_steps[range]) {
        anywhere = anywhere.min(steps.step);
        if t >= steps.t_near && t <= steps.t_far {
            if !steps.grows {
                here = here.min(steps.step);
            } else if let Some(lr) = &s.local[r * n_inst + i as usize] {
                here = here.min(steps.step * growth(&plans[i as usize], lr, t));
            }
        }
    }
    // Segments lie inside instances, so `here` is finite but for rounding at their ends.
    let base = if here.is_finite() { here } else { anywhere };
    base.max(f64::MIN_POSITIVE)
}

/// How much an instance's step grows at world distance `t` (beyond an unbounded field's
/// core; 1 elsewhere).
#[inline]
fn growth(plan: &InstancePlan, lr: &LocalRay, t: f64) -> f64 {
    plan.unbounded
        .map_or(1.0, |u| f64::from(u.step_growth(lr.at(t))))
}

/// Lays the next chunk of regular nodes for ray `r` into `s.pending`: from each run's start
/// to its end at the step policy's steps, or one node for a constant run. A run whose ends
/// are a span's is sampled just inside them (see [`RayState::inset`]).
fn lay_nodes(r: usize, plans: &[InstancePlan], params: &MarchParams, s: &mut Scratch) {
    if !s.rays[r].live {
        return;
    }
    let mut laid = 0;
    // The round's bisection floor is set at its first stepped node: constant runs take no
    // steps, so a round of them alone keeps the last round's (0 on the ray's first).
    let mut floor_set = false;
    while laid < CHUNK && s.rays[r].run < s.rays[r].runs.len() {
        let state = &s.rays[r];
        let run = state.runs[state.run];
        let (t, starts_run) = match state.next_t {
            Some(t) => (t, false),
            None => (run.start, true),
        };
        let exact = run.kind != RunKind::Searched;
        if run.kind == RunKind::Constant {
            let state = &mut s.rays[r];
            state.run += 1;
            s.pending.push(Pending {
                ray: r as u32,
                t: run.start,
                probe: 0.5 * (run.start + run.end),
                starts_run: true,
                exact,
                extent: run.end - run.start,
            });
            laid += 1;
            continue;
        }
        if starts_run {
            // Density may begin where a run does: its first step is a base one.
            s.rays[r].scale = 1.0;
        }
        let base = base_step_at(r, t, plans, s);
        if !floor_set {
            floor_set = true;
            s.rays[r].finest = base * 0.5f64.powi(params.refine_depth.min(MAX_BISECTIONS) as i32);
        }
        let next = if t >= run.end {
            None
        } else {
            Some((t + step_at(base, t, s.rays[r].scale, params)).min(run.end))
        };
        let state = &mut s.rays[r];
        let at_end = match next {
            Some(n) if n > t => {
                state.next_t = Some(n);
                false
            }
            _ => {
                state.run += 1;
                state.next_t = None;
                true
            }
        };
        if state.growing {
            state.scale = (2.0 * state.scale).min(params.max_step_factor.max(1.0) as f64);
        }
        let inset = if exact {
            state.inset.min(0.25 * (run.end - run.start))
        } else {
            0.0
        };
        let probe = if starts_run {
            t + inset
        } else if at_end {
            t - inset
        } else {
            t
        };
        s.pending.push(Pending {
            ray: r as u32,
            t,
            probe,
            starts_run,
            exact,
            extent: 0.0,
        });
        laid += 1;
    }
}

/// Evaluates every pending node's density (one batched call per instance) and inserts the
/// nodes, in order, into their rays' node lists.
fn evaluate_pending(scene: &Scene, plans: &[InstancePlan], s: &mut Scratch) {
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
    for (i, ((inst, plan), query)) in scene
        .instances
        .iter()
        .zip(plans)
        .zip(&mut s.queries)
        .enumerate()
    {
        if query.points.is_empty() {
            continue;
        }
        s.field_out.clear();
        s.field_out.resize(query.points.len(), 0.0);
        let f = plan.features;
        query.features.resize(query.points.len() * f, 0.0);
        inst.field()
            .density_with_features(&query.points, &mut s.field_out, &mut query.features);
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

/// Bisects the steps whose two ends disagree (`|σ_b − σ_a|·δ` above the tolerance) or
/// between whose ends the fields' density bound rises well above both (a sheet thinner than
/// a step), level by level, each level one batch across the tile. After the first level only
/// the pairs next to the nodes just added can need it, and the pairs beyond those, whose
/// curvature has a new neighbour (a run's first step has no node before it: its curvature
/// is the one through the node after it, which may have moved closer), so only those are
/// looked at. Steps that cannot hold an edge of a smooth field are not bisected for their
/// jump.
fn refine(scene: &Scene, plans: &[InstancePlan], params: &MarchParams, s: &mut Scratch) {
    s.candidates.clear();
    for &r in &s.active {
        for i in 0..s.nodes[r as usize].len().saturating_sub(1) {
            s.candidates.push((r, i as u32));
        }
    }
    // A step grown by 2^k needs k more bisections to reach a base step's bracket.
    let grown_levels = params.max_step_factor.max(1.0).log2().ceil() as u32;
    let levels = (params.refine_depth + grown_levels).min(MAX_BISECTIONS);
    for level in 0..levels {
        if level > 0 {
            s.candidates.clear();
            for added in &s.pending {
                let nodes = &s.nodes[added.ray as usize];
                let i = nodes.partition_point(|n| n.t < added.t);
                // The two steps beside it, and the two beyond those, whose curvature it is a
                // neighbour of.
                for k in i.saturating_sub(2)..(i + 2).min(nodes.len().saturating_sub(1)) {
                    s.candidates.push((added.ray, k as u32));
                }
            }
            s.candidates.sort_unstable();
            s.candidates.dedup();
        }
        let mut last = None;
        for &(r, _) in &s.candidates {
            if last != Some(r) {
                last = Some(r);
                lay_depths(&mut s.nodes[r as usize]);
            }
        }
        split_candidates(scene, plans, params, s);
        if s.pending.is_empty() {
            break;
        }
        evaluate_pending(scene, plans, s);
    }
}

/// Tests each candidate pair `(ray, i)` (nodes `i` and `i + 1`) and lays the midpoints of
/// those that need splitting into `s.pending`. What a step may get wrong matters
/// only as much as light from there reaches the camera, so each test is weighed by the
/// ray's transmittance at the step ([`transmittance_at`]: the steps of a round laid behind a
/// surface are not refined as if it were not there), not by what lies behind (the piece's
/// own weight and colour depend on what the step holds). A step that can hold no edge of a
/// smooth field is judged by its curvature ([`smooth_change`]). Pairs that pass the cheap
/// jump test ask the fields for a density bound over the step's box, one batch per
/// instance.
fn split_candidates(scene: &Scene, plans: &[InstancePlan], params: &MarchParams, s: &mut Scratch) {
    let empty_is_known = plans.iter().all(|p| p.bounded);
    let n_inst = plans.len();
    let tolerance = params.error_target as f64;
    let any_smooth = plans.iter().any(|p| p.smooth > 0.0);
    s.pending.clear();
    s.unsure.clear();
    for &(r, i) in &s.candidates {
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
                && hides_content(
                    scene,
                    plans,
                    r as usize,
                    i as usize,
                    transmittance,
                    tolerance,
                    s,
                )
        };
        // Every test below grows with the transmittance, and the round's bounds the step's:
        // the step's own (an exponential, [`transmittance_at`]) is worked out only where the
        // round's says split.
        let exact_t = || transmittance_at(t_round, nodes, i as usize);
        let confirmed = |test: &dyn Fn(f64) -> bool| {
            test(t_round) && (nodes[i as usize].depth == 0.0 || test(exact_t()))
        };
        if b.t - a.t <= 1.5 * s.rays[r as usize].finest {
            // Shorter than bisection may leave: only what the step may wholly hide is
            // searched for.
            if confirmed(&hides) {
                let t = split_point(scene, plans, r as usize, i as usize, s);
                s.pending.push(Pending::between(r, t, a));
            }
            continue;
        }
        let smooth = any_smooth && smooth_step(r as usize, a, b, plans, s);
        // The jump bounds `step_change`: the curvature is asked only where it may decide.
        let jump = (b.sigma - a.sigma).abs();
        let change = |weight: f64| {
            if smooth {
                smooth_change(nodes, i as usize) * weight > tolerance
            } else {
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
                || (!a.exact
                    && hides_gap(
                        scene,
                        plans,
                        r as usize,
                        (a, b),
                        transmittance,
                        tolerance,
                        s,
                    ))
        };
        if edge || confirmed(&split) {
            s.rays[r as usize].refined = true;
            let t = split_point(scene, plans, r as usize, i as usize, s);
            s.pending.push(Pending::between(r, t, a));
        } else if !a.exact {
            s.unsure.push((r, i, 0.0));
        }
    }
    // Density bounds over the unsure steps, summed over instances (per world unit).
    bucket_by_instance(
        &mut s.by_inst,
        n_inst,
        &s.ray_insts,
        &s.ray_inst_at,
        s.unsure.iter().enumerate().map(|(u, n)| (u as u32, n.0)),
    );
    for (k, inst) in scene.instances.iter().enumerate() {
        if s.by_inst[k].is_empty() {
            continue;
        }
        s.regions.clear();
        s.owners.clear();
        for &u in &s.by_inst[k] {
            let (r, i, _) = s.unsure[u as usize];
            let Some(lr) = &s.local[r as usize * n_inst + k] else {
                continue;
            };
            let nodes = &s.nodes[r as usize];
            let (a, b) = (
                nodes[i as usize].t.max(lr.t_near),
                nodes[i as usize + 1].t.min(lr.t_far),
            );
            if a <= b {
                let (pa, pb) = (lr.at(a), lr.at(b));
                s.regions.push(Aabb::new(pa.min(pb), pa.max(pb)));
                s.owners.push((u, lr.units_per_world as f64));
            }
        }
        if s.regions.is_empty() {
            continue;
        }
        s.field_out.clear();
        s.field_out.resize(s.regions.len(), 0.0);
        if !inst.field().density_bounds(&s.regions, &mut s.field_out) {
            // No bound from this field: its steps cannot be searched.
            for &(u, _) in &s.owners {
                s.unsure[u as usize].2 = f64::NEG_INFINITY;
            }
            continue;
        }
        for (&(u, k), &bound) in s.owners.iter().zip(&s.field_out) {
            s.unsure[u as usize].2 += bound as f64 * k;
        }
    }
    for &(r, i, bound) in &s.unsure {
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

/// The instances that cannot bound their density (the others are searched by their bounds)
/// and that ray `r` is inside over some of `[t0, t1]`, with their local ray, the part of
/// `[t0, t1]` inside them, and their index.
fn unbounded_over<'a>(
    plans: &'a [InstancePlan],
    r: usize,
    t0: f64,
    t1: f64,
    s: &'a Scratch,
) -> impl Iterator<Item = (usize, &'a LocalRay, f64, f64)> + 'a {
    let n_inst = plans.len();
    instances_of(s, r).iter().filter_map(move |&i| {
        let i = i as usize;
        let lr = s.local[r * n_inst + i]
            .as_ref()
            .filter(|_| !plans[i].bounded)?;
        let (a, b) = (t0.max(lr.t_near), t1.min(lr.t_far));
        (a < b).then_some((i, lr, a, b))
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
fn hides_content(
    scene: &Scene,
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
    unbounded_over(plans, r, a.t, b.t, s).any(|(i, lr, t0, t1)| {
        let sigma = |n: &Node| s.inst_sigma[n.slot as usize + i];
        if sigma(a) != 0.0 || sigma(b) != 0.0 || before.is_some_and(|n| sigma(n) > 0.0) {
            return false;
        }
        if after.is_some_and(|n| sigma(n) > 0.0) {
            return false;
        }
        let (p, q) = (lr.at(t0), lr.at(t1));
        scene.instances[i]
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
fn split_point(scene: &Scene, plans: &[InstancePlan], r: usize, k: usize, s: &Scratch) -> f64 {
    let (a, b) = (&s.nodes[r][k], &s.nodes[r][k + 1]);
    let mid = 0.5 * (a.t + b.t);
    if a.exact || a.sigma != 0.0 || b.sigma != 0.0 {
        return mid;
    }
    unbounded_over(plans, r, a.t, b.t, s)
        .find_map(|(i, lr, t0, t1)| {
            let field = scene.instances[i].field();
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
fn hidden_point(
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
fn hides_gap(
    scene: &Scene,
    plans: &[InstancePlan],
    r: usize,
    (a, b): (&Node, &Node),
    transmittance: f64,
    tolerance: f64,
    s: &Scratch,
) -> bool {
    let length = b.t - a.t;
    unbounded_over(plans, r, a.t, b.t, s).any(|(i, lr, t0, t1)| {
        let (sa, sb) = (
            s.inst_sigma[a.slot as usize + i],
            s.inst_sigma[b.slot as usize + i],
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
        let field = scene.instances[i].field();
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

/// Lays each node's [`Node::depth`]: the optical depth of a round's steps before it, each at
/// the lower of its two densities (an edge inside a step may lie anywhere in it), constant
/// runs whole.
fn lay_depths(nodes: &mut [Node]) {
    let mut depth = 0.0;
    for k in 0..nodes.len() {
        nodes[k].depth = depth;
        let a = &nodes[k];
        if a.extent > 0.0 {
            depth += a.extent * a.sigma;
        } else if let Some(b) = nodes.get(k + 1).filter(|b| !b.starts_run) {
            depth += (b.t - a.t) * a.sigma.min(b.sigma);
        }
    }
}

/// The transmittance a ray entered the round with, `t_round`, carried to node `i` of its
/// round's nodes through the steps before it ([`lay_depths`]).
fn transmittance_at(t_round: f64, nodes: &[Node], i: usize) -> f64 {
    match nodes[i].depth {
        0.0 => t_round,
        depth => t_round * (-depth).exp(),
    }
}

/// Whether the step from `a` to `b` on ray `r` can hold no edge: every instance with density
/// at either end has it at both and is smooth over the step's length (see
/// [`Field::smooth_length`](crate::field::Field::smooth_length)).
fn smooth_step(r: usize, a: &Node, b: &Node, plans: &[InstancePlan], s: &Scratch) -> bool {
    let n_inst = plans.len();
    instances_of(s, r).iter().all(|&i| {
        let (i, plan) = (i as usize, &plans[i as usize]);
        let (sa, sb) = (
            s.inst_sigma[a.slot as usize + i],
            s.inst_sigma[b.slot as usize + i],
        );
        if sa == 0.0 && sb == 0.0 {
            return true;
        }
        let Some(lr) = &s.local[r * n_inst + i] else {
            return true;
        };
        let smooth = plan.smooth * growth(plan, lr, a.t).min(growth(plan, lr, b.t));
        sa > 0.0 && sb > 0.0 && (b.t - a.t) * lr.units_per_world as f64 <= smooth
    })
}

/// How much the density changes across the step from node `i` to `i + 1` in a way the
/// trapezoid rule may get wrong: the jump `|σ_b − σ_a|`, unless the curvature through the
/// step's ends and their outer neighbours says the density is (nearly) linear there, which
/// the rule integrates exactly: the smaller of the jump and `δ²·|σ''|` ([`step_curvature`],
/// the larger of its two sides). An edge keeps its full jump; a steady slope of a smooth
/// field is not bisected.
#[inline]
fn step_change(nodes: &[Node], i: usize) -> f64 {
    let (a, b) = (&nodes[i], &nodes[i + 1]);
    let jump = (b.sigma - a.sigma).abs();
    match step_curvature(nodes, i) {
        [Some(before), Some(after)] => jump.min(before.max(after)),
        _ => jump,
    }
}

/// How much the trapezoid rule may get a step wrong that can hold no edge ([`smooth_step`]):
/// its curvature `δ²·|σ''|` alone, the larger side where both are known. Not the jump: a
/// bump between two ends of equal density has none, yet holds most of a surface's weight
/// where a trained density is the exponential of a smooth function. A step with neither
/// neighbour keeps its jump.
#[inline]
fn smooth_change(nodes: &[Node], i: usize) -> f64 {
    match step_curvature(nodes, i) {
        [None, None] => (nodes[i + 1].sigma - nodes[i].sigma).abs(),
        [before, after] => before.unwrap_or(0.0).max(after.unwrap_or(0.0)),
    }
}

/// `δ²·|σ''|` over the step from node `i` to `i + 1`, `σ''` estimated by the second divided
/// difference through the step's ends and the node before it, and through them and the one
/// after it (steps may differ in length); `None` where the run has no such node.
#[inline]
fn step_curvature(nodes: &[Node], i: usize) -> [Option<f64>; 2] {
    let (a, b) = (&nodes[i], &nodes[i + 1]);
    let h = b.t - a.t;
    let before = (i > 0 && !a.starts_run).then(|| &nodes[i - 1]);
    let after = nodes.get(i + 2).filter(|n| !n.starts_run);
    // 2·f[x0, x1, x2]·h², which is `σ0 − 2σ1 + σ2` for equal steps of length `h`.
    let curvature = |x: &Node, y: &Node, z: &Node| {
        let (h0, h1) = (y.t - x.t, z.t - y.t);
        if h0 > 0.0 && h1 > 0.0 {
            let d = (z.sigma - y.sigma) / h1 - (y.sigma - x.sigma) / h0;
            (2.0 * d / (h0 + h1) * h * h).abs()
        } else {
            f64::INFINITY
        }
    };
    [
        before.map(|p| curvature(p, a, b)),
        after.map(|q| curvature(a, b, q)),
    ]
}

/// Composites a ray's nodes, in order, until it is opaque enough; distributes each piece's
/// weight to its two nodes as the light it sends comes from along it ([`far_share`]: a thin
/// piece's from all along it, an opaque one's from its near end).
fn integrate(
    state: &mut RayState,
    nodes: &mut [Node],
    params: &MarchParams,
    outputs: &Outputs,
    empty_is_known: bool,
    budget_limited: &mut u64,
) {
    let min_t = params.min_transmittance as f64;
    for i in 0..nodes.len() {
        let b = nodes[i];
        let stopped = if b.extent > 0.0 {
            // A constant run: one piece, its weight all this node's.
            let (w, stopped) = composite_piece(state, [b.t, b.t + b.extent], [b.sigma; 2], outputs);
            nodes[i].weight += w;
            stopped
        } else if i > 0 && !b.starts_run {
            let a = nodes[i - 1];
            let sum = a.sigma + b.sigma;
            let error = if sum == 0.0 && !empty_is_known {
                // Nothing seen at either end of a field that cannot say what lies between.
                f64::INFINITY
            } else {
                // The change is at most the jump: not worked out where even that would
                // leave the worst estimate as it is.
                let weight = (b.t - a.t) * state.pieces.transmittance();
                if weight * (b.sigma - a.sigma).abs() > state.worst {
                    weight * step_change(nodes, i - 1)
                } else {
                    0.0
                }
            };
            state.worst = state.worst.max(error);
            let (w, stopped) = composite_piece(state, [a.t, b.t], [a.sigma, b.sigma], outputs);
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
    adapt_step(state, params);
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

/// After a round: back to the base step where a step was bisected (an edge is near); steps
/// double from node to node while every step's weighted error estimate is under 1/64 of the
/// target (the trapezoid rule's error grows as `δ³`, so a doubled step stays under an eighth
/// of it), and are halved where one was over it.
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
fn composite_fragments(state: &mut RayState, t_end: f64, outputs: &Outputs) -> bool {
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
    state.rgb += Vec3::from_array(f.rgb).as_dvec3() * w;
    if outputs.depth_median && alpha > 0.0 {
        let x = -(-alpha).ln_1p();
        state.log_piece([f.t, 0.0, x, x, t_enter]);
    }
}

/// Composites the ray's next splat fragment; `false` (and nothing composited) when it would
/// bring the ray's transmittance to the splats' floor: the ray is done.
#[inline]
fn composite_fragment(state: &mut RayState, f: Fragment, outputs: &Outputs) -> bool {
    if state.pieces.transmittance() * (1.0 - f64::from(f.alpha)) <= SPLAT_MIN_TRANSMITTANCE {
        return false;
    }
    composite_volume_fragment(state, f, outputs);
    true
}

/// Evaluates colour where the weight matters and adds it to the rays' colours. The lightest
/// nodes of a ray go unshaded while their weights add up to at most
/// [`MarchParams::color_skip_budget`], so the colour error a ray can get from skipping is
/// bounded by that budget times its brightest radiance.
fn shade(scene: &Scene, plans: &[InstancePlan], params: &MarchParams, s: &mut Scratch) {
    let n_inst = plans.len();
    let stride = feature_stride(plans);
    let budget = params.color_skip_budget as f64;
    s.queries.resize_with(n_inst, FieldQuery::default);
    for query in &mut s.queries {
        query.clear();
    }
    // One pass over the rays' nodes fills every instance's query, in ray order.
    for &r in &s.active {
        let r = r as usize;
        let state = &mut s.rays[r];
        let instances = &s.ray_insts[s.ray_inst_at[r] as usize..s.ray_inst_at[r + 1] as usize];
        for node in s.nodes[r].iter_mut() {
            if node.weight > 0.0 && state.skipped_weight + node.weight <= budget {
                state.skipped_weight += node.weight;
                node.weight = 0.0;
            }
            if node.weight <= 0.0 {
                continue;
            }
            for &i in instances {
                let i = i as usize;
                let Some(lr) = &s.local[r * n_inst + i] else {
                    continue;
                };
                // Only an instance with density here gets a share (tested before dividing).
                let sigma = s.inst_sigma[node.slot as usize + i];
                if sigma <= 0.0 {
                    continue;
                }
                let share = node.weight * sigma / node.sigma;
                if share > 0.0 {
                    let (plan, query) = (&plans[i], &mut s.queries[i]);
                    query.points.push(lr.at(node.probe));
                    query.dirs.push(lr.dir);
                    query.owners.push((r as u32, share));
                    let at = node.slot as usize / n_inst * stride + plan.feature_offset;
                    query
                        .features
                        .extend_from_slice(&s.features[at..at + plan.features]);
                }
            }
        }
    }
    for ((inst, plan), query) in scene.instances.iter().zip(plans).zip(&s.queries) {
        if query.points.is_empty() {
            continue;
        }
        s.rgb_out.clear();
        s.rgb_out.resize(query.points.len(), Vec3::ZERO);
        inst.field().radiance_with_features(
            &query.points,
            &query.dirs,
            &query.features,
            &mut s.rgb_out,
        );
        s.stats.color_samples += query.points.len() as u64;
        for (&(r, share), c) in query.owners.iter().zip(&s.rgb_out) {
            let c = if plan.encode {
                c.map(linear_to_srgb)
            } else {
                *c
            };
            let c = c.as_dvec3().max(DVec3::ZERO);
            if c.is_finite() {
                s.rays[r as usize].rgb += c * share;
            }
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

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::Vec3;

    use super::super::{
        render, render_with_progress, MarchParams, Outputs, Quality, RenderSettings,
    };
    use crate::field::{Aabb, Analytic, Field, Span};
    use crate::scene::{FieldHandle, FieldSource, Instance, Scene};

    /// Occupied only in the cube `[lo, lo + side]³`, exactly.
    struct Speck {
        lo: f32,
        side: f32,
    }

    impl Field for Speck {
        fn bounds(&self) -> Aabb {
            Aabb::new(Vec3::ZERO, Vec3::ONE)
        }
        fn density(&self, _: &[Vec3], sigma: &mut [f32]) {
            sigma.fill(0.0);
        }
        fn radiance(&self, _: &[Vec3], _: &[Vec3], rgb: &mut [Vec3]) {
            rgb.fill(Vec3::ZERO);
        }
        fn may_be_occupied(&self, region: &Aabb) -> bool {
            let (lo, hi) = (Vec3::splat(self.lo), Vec3::splat(self.lo + self.side));
            region.min.cmple(hi).all() && region.max.cmpge(lo).all()
        }
    }

    /// A ray crossing a speck a hundred-thousandth of the step long (a corner clip of an
    /// occupied cell) gets a split point inside it, found well within the search's budget;
    /// a ray missing it gets none.
    #[test]
    fn hidden_point_finds_a_sliver_far_below_the_bisection_depth() {
        let speck = Speck {
            lo: 0.3,
            side: 1e-5,
        };
        let ray = |y: f32| crate::scene::LocalRay {
            origin: Vec3::new(0.0, y, 0.300_005),
            dir: Vec3::X,
            units_per_world: 1.0,
            t_near: 0.0,
            t_far: 1.0,
        };
        let lr = ray(0.300_005);
        let mut queries = super::HIDDEN_SEARCH_QUERIES;
        let depth = super::HIDDEN_SEARCH_DEPTH;
        let t = super::hidden_point(&speck, &lr, 0.0, 1.0, depth, &mut queries);
        let t = t.expect("the sliver is found");
        assert!(speck.may_be_occupied(&Aabb::new(lr.at(t), lr.at(t))), "{t}");
        let mut queries = super::HIDDEN_SEARCH_QUERIES;
        let missed = super::hidden_point(&speck, &ray(0.4), 0.0, 1.0, depth, &mut queries);
        assert_eq!(missed, None);
    }

    /// Hands each sample's position to the colour query as its features and colours from
    /// those alone: if the marcher paired features with the wrong samples (or the wrong
    /// instance), colours would change.
    struct Echo(Analytic);

    impl Field for Echo {
        fn bounds(&self) -> Aabb {
            self.0.bounds()
        }
        fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
            self.0.density(points, sigma)
        }
        fn radiance(&self, _: &[Vec3], _: &[Vec3], _: &mut [Vec3]) {
            unreachable!("the marcher asks for colour with the density pass's features")
        }
        fn feature_count(&self) -> usize {
            3
        }
        fn density_with_features(&self, points: &[Vec3], sigma: &mut [f32], features: &mut [f32]) {
            self.0.density(points, sigma);
            for (p, f) in points.iter().zip(features.chunks_exact_mut(3)) {
                f.copy_from_slice(&p.to_array());
            }
        }
        fn radiance_with_features(
            &self,
            _: &[Vec3],
            dirs: &[Vec3],
            features: &[f32],
            rgb: &mut [Vec3],
        ) {
            let points: Vec<Vec3> = features.chunks_exact(3).map(Vec3::from_slice).collect();
            self.0.radiance(&points, dirs, rgb)
        }
        fn feature_size(&self) -> f32 {
            self.0.feature_size()
        }
        fn density_bounds(&self, regions: &[Aabb], bounds: &mut [f32]) -> bool {
            self.0.density_bounds(regions, bounds)
        }
        fn spans(&self, o: Vec3, d: Vec3, t0: f64, t1: f64, out: &mut Vec<Span>) -> bool {
            self.0.spans(o, d, t0, t1, out)
        }
        fn may_be_occupied(&self, region: &Aabb) -> bool {
            self.0.may_be_occupied(region)
        }
    }

    /// A field that answers every third density sample with NaN, +inf or −inf in turn.
    struct Poisoned(Analytic);

    impl Field for Poisoned {
        fn bounds(&self) -> Aabb {
            self.0.bounds()
        }
        fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
            self.0.density(points, sigma);
            let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
            for (i, s) in sigma.iter_mut().enumerate().filter(|(i, _)| i % 3 == 0) {
                *s = bad[i / 3 % 3];
            }
        }
        fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]) {
            self.0.radiance(points, dirs, rgb)
        }
        fn may_be_occupied(&self, region: &Aabb) -> bool {
            self.0.may_be_occupied(region)
        }
    }

    fn demo_with(object: impl Fn(Analytic) -> Arc<dyn Field>) -> (Scene, crate::camera::Camera) {
        let (plain, camera) = crate::demo::scene_and_camera(48, 27).unwrap();
        let desc = crate::demo::scene_desc();
        let instances = plain
            .instances
            .iter()
            .zip(&desc.instances)
            .map(|(inst, d)| {
                let FieldSource::Analytic(a) = &d.field else {
                    unreachable!("the demo is analytic")
                };
                let handle = if inst.name == "object" {
                    FieldHandle::new(object(a.clone()))
                } else {
                    inst.handle().clone()
                };
                Instance::new(inst.name.clone(), handle, inst.world_from_field(), None).unwrap()
            })
            .collect();
        (Scene::new(instances), camera)
    }

    fn assert_finite(planes: &crate::image::Planes) {
        let alpha = planes.alpha.as_ref().unwrap();
        assert!(alpha.data.iter().all(|a| (0.0..=1.0).contains(a)));
        for plane in planes.rgb.as_ref().unwrap() {
            assert!(plane.data.iter().all(|c| c.is_finite() && *c >= 0.0));
        }
    }

    fn node(t: f64, sigma: f64) -> super::Node {
        super::Node {
            t,
            probe: t,
            sigma,
            slot: 0,
            starts_run: false,
            exact: false,
            extent: 0.0,
            weight: 0.0,
            depth: 0.0,
        }
    }

    #[test]
    fn a_bump_between_ends_of_equal_density_is_judged_by_its_curvature() {
        // σ = 0, 5, 5, 0 at t = 0, 1, 2, 3: the middle step has no jump, but the density
        // turns over inside it.
        let nodes = [
            node(0.0, 0.0),
            node(1.0, 5.0),
            node(2.0, 5.0),
            node(3.0, 0.0),
        ];
        assert_eq!(super::step_change(&nodes, 1), 0.0);
        assert_eq!(super::smooth_change(&nodes, 1), 5.0);
        // A steady slope has none.
        let slope = [
            node(0.0, 1.0),
            node(1.0, 2.0),
            node(2.0, 3.0),
            node(3.0, 4.0),
        ];
        assert_eq!(super::smooth_change(&slope, 1), 0.0);
        // Without neighbours, the jump.
        assert_eq!(super::smooth_change(&slope[1..3], 0), 1.0);
    }

    #[test]
    fn transmittance_inside_a_round_goes_through_the_lower_end_of_each_step() {
        let mut nodes = [
            node(0.0, 0.0),
            node(1.0, 2.0),
            node(1.5, 4.0),
            node(2.0, 1.0),
        ];
        let mut cut = nodes;
        super::lay_depths(&mut nodes);
        assert_eq!(super::transmittance_at(0.5, &nodes, 0), 0.5);
        // The first step may hold its edge anywhere: no depth from it.
        assert_eq!(super::transmittance_at(0.5, &nodes, 1), 0.5);
        let want = 0.5 * (-(0.5 * 2.0 + 0.5 * 1.0f64)).exp();
        assert!((super::transmittance_at(0.5, &nodes, 3) - want).abs() < 1e-15);
        // A run's start joins nothing to the node before it.
        cut[2].starts_run = true;
        super::lay_depths(&mut cut);
        let want = 0.5 * (-(0.5 * 1.0f64)).exp();
        assert!((super::transmittance_at(0.5, &cut, 3) - want).abs() < 1e-15);
    }

    #[test]
    fn non_finite_densities_are_empty_and_counted() {
        let (scene, camera) = demo_with(|a| Arc::new(Poisoned(a)));
        let settings = RenderSettings::new(Quality::Preview.params(), Outputs::all());
        let (planes, stats) =
            render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {})
                .unwrap();
        assert_finite(&planes);
        assert!(stats.invalid_samples > 0);
        assert!(stats.warning().unwrap().contains("NaN or infinite"));
    }

    #[test]
    fn rays_out_of_budget_stop_and_are_counted() {
        let (scene, camera) = demo_with(|a| Arc::new(a));
        let final_params = Quality::Final.params();
        let render = |max_samples| {
            let params = MarchParams {
                max_samples,
                ..final_params
            };
            let settings = RenderSettings::new(params, Outputs::all());
            render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {}).unwrap()
        };
        let (planes, stats) = render(final_params.max_samples);
        assert_finite(&planes);
        assert_eq!(stats.budget_limited_rays, 0);
        assert_eq!(stats.warning(), None);
        let (short, stats) = render(6);
        assert_finite(&short);
        assert!(stats.budget_limited_rays > 0 && stats.budget_limited_rays <= stats.pixels);
        assert!(stats.warning().unwrap().contains("sample budget"));
        // A ray stopped early has composited less, never more.
        let (a, b) = (short.alpha.unwrap(), planes.alpha.unwrap());
        assert!(a.data.iter().zip(&b.data).all(|(s, f)| *s <= f + 1e-6));
        assert!(a.data.iter().zip(&b.data).any(|(s, f)| *s < f - 1e-3));
    }

    #[test]
    fn tile_culling_keeps_every_instance_a_ray_of_the_tile_meets() {
        use crate::camera::{Camera, Perspective, Projection};
        use crate::field::{Primitive, ShColor, Shape};
        use glam::{DMat4, DVec3};

        // An 8×8 grid of small balls facing the camera, one ball behind it and one far to
        // its side: tiles see a few balls each, and no tile sees the last two.
        let ball = FieldHandle::analytic(Analytic {
            primitives: vec![Primitive {
                shape: Shape::Sphere {
                    center: Vec3::ZERO,
                    radius: 0.1,
                },
                density: 1.0,
                color: ShColor::constant(Vec3::ONE),
            }],
        });
        let mut at: Vec<DVec3> = (0..64)
            .map(|k| {
                DVec3::new(
                    -1.0 + 0.25 * (k % 8) as f64 + 0.125,
                    0.0,
                    -1.0 + 0.25 * (k / 8) as f64 + 0.125,
                )
            })
            .collect();
        at.extend([DVec3::new(0.0, -8.0, 0.0), DVec3::new(30.0, 0.0, 0.0)]);
        let instances = at
            .iter()
            .enumerate()
            .map(|(k, p)| {
                Instance::new(
                    format!("ball {k}"),
                    ball.clone(),
                    DMat4::from_translation(*p),
                    None,
                )
                .unwrap()
            })
            .collect();
        let scene = Scene::new(instances);
        let plans = super::InstancePlan::for_scene(&scene, &Quality::Draft.params());
        let p = Perspective::from_vertical_fov(64, 48, 40.0).unwrap();
        let eye = crate::demo::look_at(DVec3::new(0.0, -4.0, 0.0), DVec3::ZERO);
        let camera = Camera::new(eye, Projection::Perspective(p)).unwrap();
        let (mut keep, mut kept, mut met) = (Vec::new(), 0, 0);
        for (x0, y0) in (0..4).flat_map(|i| (0..3).map(move |j| (16 * i, 16 * j))) {
            let rays: Vec<_> = (0..256)
                .map(|k| camera.ray((x0 + k % 16) as f64 + 0.5, (y0 + k / 16) as f64 + 0.5))
                .collect();
            super::cull_instances(&plans, &rays, &mut keep);
            for (i, inst) in scene.instances.iter().enumerate() {
                let meets = rays
                    .iter()
                    .flatten()
                    .any(|r| inst.local_ray(r, r.near, r.far).is_some());
                assert!(
                    keep[i] || !meets,
                    "tile ({x0}, {y0}) culled instance {i}, which a ray meets"
                );
                kept += usize::from(keep[i]);
                met += usize::from(meets);
            }
            assert!(!keep[64] && !keep[65]);
        }
        // Conservative, yet close: a tile keeps a few balls per ball it meets (the sphere
        // around a ball's box, and the cone around the tile's rays, are wider than both).
        assert!(met > 0 && kept <= 3 * met, "kept {kept}, met {met}");
    }

    /// The median depth from a log cut where [`super::RayState::log_piece`] cuts it is the
    /// full log's, bit for bit: seeded rays of pieces (some of them fragments, `δ = 0`, some
    /// after a fragment's drop in transmittance), every share of the pixel's alpha.
    #[test]
    fn a_cut_median_log_gives_the_full_logs_depth() {
        use crate::bench::rng::SplitMix64;
        use crate::render::crossing_depth;

        let mut rng = SplitMix64::new(11);
        let mut cut_short = 0;
        for _ in 0..4000 {
            let (mut state, mut full) = (super::RayState::default(), Vec::new());
            let (mut t, mut transmittance) = (1.0, 1.0f64);
            for _ in 0..1 + rng.next_u64() % 24 {
                let delta = if rng.unit() < 0.2 {
                    0.0
                } else {
                    f64::from(rng.range(0.0, 0.3))
                };
                let scale = f64::from(rng.range(0.0, 6.0)).powi(2);
                let (x0, x1) = (
                    scale * delta * f64::from(rng.unit()),
                    scale * delta * f64::from(rng.unit()),
                );
                let piece = [t, delta, x0, x1, transmittance];
                full.push(piece);
                state.log_piece(piece);
                t += delta + f64::from(rng.range(0.0, 0.1));
                transmittance *= (-0.5 * (x0 + x1)).exp();
                if rng.unit() < 0.1 {
                    transmittance *= f64::from(rng.unit());
                }
            }
            cut_short += usize::from(state.log.len() < full.len());
            for alpha in [1.0 - transmittance, 0.3 * (1.0 - transmittance), 1.0] {
                let (want, got) = (
                    crossing_depth(&full, 0.5 * alpha),
                    crossing_depth(&state.log, 0.5 * alpha),
                );
                assert_eq!(want.to_bits(), got.to_bits(), "{full:?}, alpha {alpha}");
            }
        }
        assert!(
            cut_short > 100,
            "the seeded rays exercise the cut: {cut_short}"
        );
    }

    #[test]
    fn features_reach_the_colour_query_of_their_own_samples() {
        let (plain, camera) = crate::demo::scene_and_camera(48, 27).unwrap();
        // The object instance echoes its features, the environment does not: offsets into
        // a node's features must keep them apart.
        let (echo, _) = demo_with(|a| Arc::new(Echo(a)));
        let settings = RenderSettings::new(Quality::Preview.params(), Outputs::rgba());
        let want = render(&plain, &camera, camera.full_window(), &settings).unwrap();
        let got = render(&echo, &camera, camera.full_window(), &settings).unwrap();
        assert_eq!(got, want);
    }
}
