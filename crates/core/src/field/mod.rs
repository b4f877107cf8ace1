//! Radiance fields: what the marcher samples.
//!
//! A [`Field`] answers *batched* density and radiance queries in its own frame and says,
//! conservatively, where it may have density. The [`Occupancy`] structure is built from that
//! answer and lets the marcher skip empty space.
//!
//! One folder per representation: `analytic/` ([`Analytic`]: spheres, boxes and Gaussian
//! blobs with closed-form ray integrals, the ground truth for accuracy), `ingp/`
//! ([`IngpField`]: instant-ngp snapshots), `nerfacto/` ([`NerfactoField`]: nerfstudio nerfacto
//! runs) and `splats/` ([`Splats`]: 3D Gaussian splats, rendered as fragments rather than
//! marched). The two trained networks share `network/` (hash grid, MLP, SH encoding); the
//! files the fields come in (torch checkpoints and their zip archives, PLY) are read in
//! `container/`.

mod aabb;
mod analytic;
mod container;
mod crop;
mod ingp;
mod nerfacto;
mod network;
mod occupancy;
mod splats;
mod srgb;

pub use aabb::Aabb;
pub use analytic::{Analytic, Primitive, ShColor, Shape};
pub(crate) use analytic::{Anchor, Density, Line, Profile};
pub use crop::{CropBox, CropClip};
pub use ingp::IngpField;
pub(crate) use ingp::{Cascades, ColourScratch, DENSITY_OUTPUTS};
pub use nerfacto::{DataparserTransform, NerfactoField};
pub(crate) use nerfacto::{DensityScratch, ProposalNetworks};
pub use network::TableStorage;
pub(crate) use network::{exp_density, sh_basis};
pub use occupancy::Occupancy;
pub(crate) use splats::is_splatfacto_run;
pub use splats::{Axes, SplatColor, SplatFormat, SplatSource, Splats};
pub use srgb::{linear_to_srgb, srgb_to_linear};
// The kernels the bench targets time on seeded data (`benches/ingp.rs`, `benches/nerfacto.rs`).
#[doc(hidden)]
pub use nerfacto::{ColorHeadBench, ProposalDensityBench};
#[doc(hidden)]
pub use network::NetworksBench;

use std::path::Path;

use glam::Vec3;

use crate::error::{Error, Result};

/// The colour space radiance is trained and composited in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ColorSpace {
    /// Scene-linear light.
    Linear,
    /// sRGB-encoded (IEC 61966-2-1) values in [0, 1], as in the photographs a capture is
    /// trained on.
    Srgb,
}

/// How a field defined on all of space is marched (nerfstudio's nerfacto, whose scene
/// contraction maps every point to its hash grid): its detail lies in the *core* cube
/// `‖x‖∞ ≤ core`, where steps do not grow; beyond it the field's own coordinates are
/// contracted like `2 − core/‖x‖∞`, so a step at `‖x‖∞ = r` is `(r/core)²` times the core's
/// step (a constant step in the contracted coordinates). The marcher's occupancy grid covers
/// the cube `‖x‖∞ ≤ grid` (`grid ≥ core`), skipping empty space there as for a bounded
/// field; beyond it empty space is skipped with [`Field::may_be_occupied`] in steps of
/// `skip` contracted units. A ray is integrated from `near` to `far`: distances
/// along it from its origin, in field units (nerfstudio's near and far planes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unbounded {
    /// Half the side of the core cube, centred on the field's origin (field units).
    pub(crate) core: f32,
    /// Half the side of the cube the marcher's occupancy grid covers.
    pub(crate) grid: f32,
    /// The empty-space test's step in contracted units (fractions of the core's half side).
    pub(crate) skip: f32,
    /// Where a ray's integration starts: distance from its origin, field units.
    pub(crate) near: f32,
    /// Where it ends.
    pub(crate) far: f32,
}

impl Unbounded {
    /// The core cube.
    pub(crate) fn core_box(&self) -> Aabb {
        Aabb::new(Vec3::splat(-self.core), Vec3::splat(self.core))
    }

    /// The cube the marcher's occupancy grid covers.
    pub(crate) fn grid_box(&self) -> Aabb {
        Aabb::new(Vec3::splat(-self.grid), Vec3::splat(self.grid))
    }

    /// The factor a step at field point `p` grows by: `(‖p‖∞/core)²` beyond the core, else 1.
    #[inline]
    pub(crate) fn step_growth(&self, p: Vec3) -> f32 {
        let r = p.abs().max_element() / self.core;
        if r > 1.0 {
            r * r
        } else {
            1.0
        }
    }
}

/// An interval of a field-space ray where a field's density is non-zero (see
/// [`Field::spans`]): distances along the ray's unit direction, in field units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    /// Where the ray enters the interval.
    pub(crate) enter: f64,
    /// Where it leaves it (> `enter`).
    pub(crate) exit: f64,
    /// Whether the density may change inside the interval; `false`: it is one constant
    /// throughout, so one sample gives its integral exactly.
    pub(crate) varies: bool,
}

/// What a field can tell the marcher beyond its densities and colours, declared once per
/// field ([`Field::capabilities`]): the marcher picks how to march an instance from it when
/// the render starts, and asks only what was declared.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Capabilities {
    /// It gives the exact intervals of a ray where its density may be non-zero
    /// ([`Field::spans`]): the marcher runs its samples between their ends instead of
    /// searching for edges (analytic fields).
    pub spans: bool,
    /// It gives the intervals of a ray its occupancy mask is on
    /// ([`Field::mask_segments`]): a smooth density cut by a mask of cells (instant-ngp).
    pub mask_segments: bool,
    /// It bounds its density over a region ([`Field::density_bounds`]): only then can a
    /// step between two empty samples be known to hold nothing.
    pub density_bounds: bool,
}

/// [`Field::may_be_occupied`] asked of regions inside regions (see [`Field::region_query`]).
pub trait RegionQuery: Sync {
    /// Whether the field may have density in `region`: [`Field::may_be_occupied`]'s answer.
    /// `within` is what the call for a region holding this one left in its `left` (`None`:
    /// there was none); `left` receives what a call for a region inside this one needs to
    /// look at (what it holds is the query's own business).
    fn may_be_occupied(&self, region: &Aabb, within: Option<&[u32]>, left: &mut Vec<u32>) -> bool;
}

/// A field asked directly.
struct Plain<'a, F: ?Sized>(&'a F);

impl<F: Field + ?Sized> RegionQuery for Plain<'_, F> {
    fn may_be_occupied(&self, region: &Aabb, _: Option<&[u32]>, _: &mut Vec<u32>) -> bool {
        self.0.may_be_occupied(region)
    }
}

/// A radiance field in its own frame ("field space").
///
/// Queries are batched: the marcher gathers a tile's samples and asks once, so an
/// implementation can vectorise and the per-call cost (a virtual call, a lock) is amortised.
pub trait Field: Send + Sync {
    /// A box outside of which the density is exactly zero.
    fn bounds(&self) -> Aabb;

    /// A box, within [`Field::bounds`], outside of which the density is zero at every
    /// point the marcher samples (a trained field's occupied cells, where its mask zeroes
    /// the rest); the renderer skips the rays that miss it, but still lays a ray that meets
    /// it within [`Field::bounds`], so its samples stay where they were. By default the
    /// bounds.
    fn occupied_bounds(&self) -> Aabb {
        self.bounds()
    }

    /// For a field defined on all of space through a contraction, how to march it (see
    /// [`Unbounded`]); `None` (the default): a bounded field, marched within
    /// [`Field::bounds`] at the base step.
    fn unbounded(&self) -> Option<Unbounded> {
        None
    }

    /// Volume density σ (per field-space unit of length, ≥ 0, finite) at each point.
    /// `sigma.len() == points.len()`.
    fn density(&self, points: &[Vec3], sigma: &mut [f32]);

    /// RGB radiance (≥ 0) in the field's [`Field::color_space`] at each point seen along each
    /// unit direction `dirs[i]`. `rgb.len() == points.len() == dirs.len()`.
    fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]);

    /// The space [`Field::radiance`] is in: the one the field was trained in. Linear (the
    /// default) for analytic fields and HDR captures; sRGB-encoded for fields trained on
    /// photographs, whose trainer composited the encoded values.
    fn color_space(&self) -> ColorSpace {
        ColorSpace::Linear
    }

    /// Floats of per-sample state that [`Field::density_with_features`] can leave for
    /// [`Field::radiance_with_features`], so that a colour query need not redo the density
    /// pass's work (a trained field's encoding and density network); 0 (the default): none.
    fn feature_count(&self) -> usize {
        0
    }

    /// [`Field::density`], also writing [`Field::feature_count`] floats per point into
    /// `features` (`features.len() == points.len() · feature_count()`).
    fn density_with_features(&self, points: &[Vec3], sigma: &mut [f32], _features: &mut [f32]) {
        self.density(points, sigma)
    }

    /// [`Field::radiance`] at points whose density pass left `features` (laid out as in
    /// [`Field::density_with_features`]).
    fn radiance_with_features(
        &self,
        points: &[Vec3],
        dirs: &[Vec3],
        _features: &[f32],
        rgb: &mut [Vec3],
    ) {
        self.radiance(points, dirs, rgb)
    }

    /// The length (field units) over which the density varies smoothly: the marcher's step
    /// is a quality preset's fraction of it. Sharper changes (surfaces) are found by the
    /// marcher's refinement, so this is about smooth variation, not about edges.
    fn feature_size(&self) -> f32 {
        self.bounds().diagonal() / 256.0
    }

    /// The length (field units) below which the density, where it is non-zero, has no detail
    /// of its own: between two points closer than this that both have density it is a
    /// smooth interpolant. A trained field's is its finest hash-grid cell: the encoding is
    /// trilinear inside a cell, and the networks after it are continuous, so nothing but
    /// curvature lies between two samples of the same or neighbouring cells. Its only edges
    /// are where an occupancy mask sets the density to zero.
    ///
    /// The marcher bisects a step whose ends disagree to find an edge inside it; a step
    /// shorter than this whose ends both have density holds no edge, and bisecting it
    /// would only refine the quadrature of a smooth curve, which the base step (a preset's
    /// fraction of [`Field::feature_size`]) already sets. So such steps are not bisected for
    /// their jump (steps with an empty end still are). 0 (the default): the density may
    /// jump anywhere (analytic surfaces), every step is judged by its jump.
    fn smooth_length(&self) -> f32 {
        0.0
    }

    /// What the field can tell the marcher beyond densities and colours: which of
    /// [`Field::spans`], [`Field::mask_segments`] and [`Field::density_bounds`] it answers.
    /// The same for every ray and region. None by default (a trained field's densities
    /// alone, marched through its occupancy grid).
    fn capabilities(&self) -> Capabilities {
        Capabilities::default()
    }

    /// Upper bounds of the density over each region (`bounds.len() == regions.len()`), for a
    /// field that declares [`Capabilities::density_bounds`] (asked of no other). The
    /// marcher uses them to find features thinner than a step between two samples (a dense
    /// sheet inside fog); a field without bounds gets no such search.
    fn density_bounds(&self, _regions: &[Aabb], bounds: &mut [f32]) {
        bounds.fill(f32::INFINITY);
    }

    /// The exact intervals of the ray `origin + t·dir`, `t ∈ [t0, t1]` (`dir` a unit
    /// vector), where the density may be non-zero, appended to `out` sorted and not
    /// overlapping, and cut wherever the density may jump and at the peaks of its smooth
    /// parts: inside a span the density is continuous and has no bump two samples could
    /// straddle, so the marcher starts and ends its runs of samples at span ends instead of
    /// searching for edges, and searches for no thin sheet or peak between samples. Outside
    /// every span the density must be exactly zero. Asked only of a field that declares
    /// [`Capabilities::spans`]; the others' edges the marcher finds by sampling (trained
    /// fields). By default `out` is left untouched.
    fn spans(&self, _origin: Vec3, _dir: Vec3, _t0: f64, _t1: f64, _out: &mut Vec<Span>) {}

    /// The exact intervals `[enter, exit]` of the ray `origin + t·dir`, `t ∈ [t0, t1]` (`dir`
    /// a unit vector), where the field's occupancy mask is on, appended to `out` sorted and
    /// apart (touching cells joined), for a field whose density is a smooth interpolant (see
    /// [`Field::smooth_length`]) cut to zero by a mask of cells: the density is zero outside
    /// them and has no jump inside them, so the marcher starts and ends its runs at their
    /// ends instead of searching for the mask's edges between samples. Asked only of a
    /// field that declares [`Capabilities::mask_segments`]; by default `out` is left
    /// untouched.
    fn mask_segments(
        &self,
        _origin: Vec3,
        _dir: Vec3,
        _t0: f64,
        _t1: f64,
        _out: &mut Vec<[f64; 2]>,
    ) {
    }

    /// Whether the density may be non-zero anywhere in `region`. Must be *conservative*:
    /// `false` only where the density is exactly zero throughout.
    fn may_be_occupied(&self, region: &Aabb) -> bool;

    /// [`Field::may_be_occupied`] prepared for many nested regions (an occupancy grid's
    /// build asks for every cell it may split): the same answers, from an index the field
    /// builds once where it has one, so that the build grows with the cells, not with cells
    /// times content. By default the field itself.
    fn region_query(&self) -> Box<dyn RegionQuery + '_> {
        Box::new(Plain(self))
    }

    /// For each point, whether the density there is certainly zero (`empty.len() ==
    /// points.len()`): `true` only where [`Field::density`] gives exactly zero. The marcher
    /// probes the inside of a step with density at both ends for a masked-out gap its ends
    /// cannot show, so a field whose density is cut by a mask answers from the mask itself,
    /// cell for cell, where a box query pads and walks. The default asks
    /// [`Field::may_be_occupied`] for each point's degenerate box (NaN points: what the box
    /// query says). A "not empty" where the density is zero lets a gap through unseen, so
    /// a masked field should answer exactly, and a field that wraps another forwards this.
    fn certainly_empty(&self, points: &[Vec3], empty: &mut [bool]) {
        for (p, e) in points.iter().zip(empty) {
            *e = !self.may_be_occupied(&Aabb::new(*p, *p));
        }
    }
}

/// A description of a field file for people (`nerfx info`): format, architecture, parameter
/// count, bounds and occupancy fill ratio. Formats: instant-ngp snapshots (`.ingp`,
/// `.msgpack`), nerfstudio nerfacto and splatfacto run directories (holding `config.yml`) and
/// every splat file [`Splats::load`] reads. Unreadable or corrupt files give an error naming
/// the file.
pub fn describe(path: &Path) -> Result<String> {
    let sog_folder = path.is_dir() && path.join("meta.json").is_file();
    if is_splatfacto_run(path) || sog_folder {
        return Ok(Splats::load(path)?.describe(path));
    }
    if path.is_dir() {
        return Ok(NerfactoField::load(path)?.describe());
    }
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let is_meta = path
        .file_name()
        .is_some_and(|n| n.eq_ignore_ascii_case("meta.json"));
    match extension.as_deref() {
        Some("ingp" | "msgpack") => Ok(IngpField::load(path)?.describe()),
        Some("ply" | "splat" | "spz" | "sog") => Ok(Splats::load(path)?.describe(path)),
        _ if is_meta => Ok(Splats::load(path)?.describe(path)),
        _ => Err(Error::Unsupported(format!(
            "{}: unknown field format (expected an instant-ngp .ingp or .msgpack snapshot, a \
             splat .ply, .splat, .spz, .sog or SOG meta.json, or a nerfstudio run directory)",
            path.display()
        ))),
    }
}
