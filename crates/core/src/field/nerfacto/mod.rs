//! nerfstudio `nerfacto` runs as a [`Field`]: a run directory with `config.yml`,
//! `dataparser_transforms.json` and `nerfstudio_models/step-*.ckpt` (the highest step).
//!
//! **Frame.** The field is queried in nerfstudio's normalised frame, the frame `ns-render`
//! renders in and `ns-export` writes stand-ins in (docs/src/architecture.md); the dataparser transform is
//! read and kept ([`NerfactoField::dataparser`]) to map data-frame cameras into it.
//!
//! **Evaluation** (nerfacto's field at inference). A point `x` is contracted (L∞):
//! `c = x` when `‖x‖∞ < 1`, else `c = (2 − 1/‖x‖∞)·(x/‖x‖∞)`; then `u = (c + 2)/4` (zero
//! density unless `0 < u < 1` on every axis). The hash grid (16 levels × 2, `2^19` rows,
//! `N_min` 16, `N_max` 2048, per-level scale `exp((ln N_max − ln N_min)/(L − 1))`; all from
//! `config.yml`) encodes `u`; the density MLP (`L·F → 64 → 16`) gives `raw` and 15 geometry
//! features; `σ = average_init_density · exp(raw)`. The colour MLP reads
//! `[SH₄((d + 1)/2) (16), geometry (15), appearance (32)]` (the appearance is the mean of the
//! trained per-image embedding table, nerfacto's `use_average_appearance_embedding`; zeros
//! when the config turns that off) →
//! 64 → 64 → 3, sigmoid (evaluated with the appearance folded into the first layer's
//! biases and the direction's part of that layer summed once per ray, see `head_outputs`).
//! nerfstudio trains on sRGB-encoded pixels, so the colour is
//! converted to linear, as for instant-ngp snapshots.
//!
//! **Checkpoint layouts.** Keys under `pipeline._model.field.`: with tiny-cuda-nn,
//! `mlp_base.model.params` (tcnn's `NetworkWithInputEncoding`: density MLP then grid, in
//! tcnn's layout; older runs: `mlp_base.params`, or `mlp_base_mlp.tcnn_encoding.params` and
//! `mlp_base_grid.tcnn_encoding.params`) and `mlp_head.tcnn_encoding.params`; with the torch
//! fallback, `mlp_base.model.0.hash_table` (or `mlp_base_grid.hash_table`) and
//! `…layers.<i>.weight|bias` (see [`torch`]). Appearance:
//! `embedding_appearance.embedding.weight`.
//!
//! **Bounds and occupancy.** The contraction maps all of space into the hash grid, so the
//! field is defined everywhere: the sky and the distant scene of an outdoor capture live in
//! the shell `‖x‖∞ > 1`. As `ns-render` does, a ray is integrated from the camera to
//! `far_plane` (`config.yml`, 1000 by default), a distance along it in the field's units
//! (nerfstudio's collider starts rays at 0 at inference; `near_plane` applies in training);
//! the bounds are the cube `‖x‖∞ ≤ far_plane` (density zero beyond).
//! The field says it is [unbounded](Field::unbounded) with the unit cube as its core: there
//! the marcher steps as for any field; beyond it its steps grow as `‖x‖∞²` (a constant step
//! in contracted coordinates, where the hash grid's cells are). Empty space is skipped with
//! the marcher's occupancy grid within `[−2, 2]³`, beyond it through
//! [`Field::may_be_occupied`]. Depth of far content is thus
//! finite (at most `far_plane` field units). nerfacto has no occupancy grid, so one is
//! computed at load: `64³` cells over the *contracted* cube `[−2, 2]³`; the density is
//! sampled at every cell corner and centre; a cell is occupied when `max σ · L ≥ 10⁻³`,
//! `L` the cell's diagonal in field units (an opacity of about 10⁻³ across it; far cells
//! are long, so their threshold is low), and the occupied set is then dilated by one cell
//! (26-neighbourhood). This is conservative in practice, not by proof (a peak narrower than
//! half a cell between samples could be missed); so that the [`Field`] contract holds
//! exactly, the density is set to zero in empty cells. The grid is cached
//! (`nerfx_occupancy.bin` in the run directory, or when that cannot be written a per-user
//! cache directory; keyed by the checkpoint, `config.yml` and the grid settings; never
//! trusted beyond its key and checksum; see `nerfacto/occupancy.rs`).

use std::path::{Path, PathBuf};

use glam::Vec3;
use half::f16;

use super::container::{Checkpoint, DType};
use super::network::{
    exp_density, non_finite, sh4, HashGrid, HashGridConfig, LastInputs, Mlp, MlpConfig,
    TableStorage,
};
use super::{Aabb, ColorSpace, Field, Unbounded};
use crate::error::{Error, Result};
use config::{RunSettings, SamplerSettings};
use density_field::DensityField;
use occupancy::{
    cache_key, cache_paths, contract, GridSettings, OccupancyGrid, Source, CACHE_FILE,
};
use torch::{torch_sh4, TorchHashGrid};

mod config;
mod dataparser;
mod density_field;
#[cfg(target_arch = "x86_64")]
mod density_kernel;
mod occupancy;
mod proposal_networks;
mod torch;

pub(crate) use config::scan;
pub use dataparser::DataparserTransform;
pub(crate) use density_field::DensityScratch;
#[doc(hidden)]
pub use density_field::ProposalDensityBench;
pub(crate) use proposal_networks::ProposalNetworks;

/// Points per batch (bounds the scratch memory).
const CHUNK: usize = 512;
/// The colour MLP's inputs for the view direction: its degree-4 SH encoding.
const SH_INPUTS: usize = 16;
/// The occupancy grid's cells per axis over the contracted cube…
const OCCUPANCY_CELLS: usize = 64;
/// …and the opacity across a cell above which it is occupied.
const OCCUPANCY_OPACITY: f32 = 1e-3;
/// The marcher's finest empty-space step beyond the unit cube, in contracted units: a
/// quarter of a cell of the occupancy grid (4/64), so that the segments it marches begin
/// close to where the occupied cells do: with a whole cell, rays spend samples in cells the
/// mask empties.
const FAR_SKIP: f32 = 1.0 / 64.0;

/// The networks, in one of the two layouts. The colour MLP (`head`) reads the geometry
/// features only: its first layer's columns are reordered at load to `[geometry,
/// direction, appearance]`, the appearance folded into its biases and the direction's
/// columns split off ([`NerfactoField::head_dir`]).
#[derive(Clone, Debug)]
enum Net {
    Tcnn {
        grid: HashGrid,
        density: Mlp,
        head: Mlp,
    },
    Torch {
        grid: TorchHashGrid,
        density: Mlp,
        head: Mlp,
    },
}

/// A nerfacto run loaded as a field.
#[derive(Clone, Debug)]
pub struct NerfactoField {
    run: PathBuf,
    checkpoint: PathBuf,
    step: u64,
    settings: RunSettings,
    dataparser: DataparserTransform,
    net: Net,
    /// Density MLP outputs (1 + geometry features).
    n_base: usize,
    appearance: Vec<f32>,
    /// The colour MLP's first-layer columns of the direction's SH encoding, with its biases
    /// (the appearance folded in): summed once per run of samples sharing a direction.
    head_dir: LastInputs,
    n_images: usize,
    n_params: usize,
    occupancy: OccupancyGrid,
    /// nerfacto's own sampler, when the checkpoint holds its proposal networks.
    proposal: Option<ProposalNetworks>,
}

impl NerfactoField {
    /// Loads the run directory `run` (the checkpoint with the highest step).
    pub fn load(run: &Path) -> Result<Self> {
        let config_file = run.join("config.yml");
        let config_text = crate::input::read_text(&config_file)?;
        let settings = RunSettings::from_text(&config_text, &config_file)?;
        let method = settings.method_name.as_str();
        if !(method.is_empty() || method.contains("nerfacto") || method.starts_with("splatfacto")) {
            return Err(Error::Unsupported(format!(
                "{}: a '{method}' run; nerfx reads nerfacto and splatfacto runs",
                run.display()
            )));
        }
        if settings.method_name.starts_with("splatfacto") {
            return Err(Error::Unsupported(format!(
                "{}: a splatfacto run holds splats, not a nerfacto field: name it as \
                 {{\"splats\": {{\"path\": …}}}} in the scene file",
                run.display()
            )));
        }
        if settings.disable_scene_contraction {
            return Err(Error::Unsupported(format!(
                "{}: nerfacto without scene contraction (disable_scene_contraction: true)",
                run.join("config.yml").display()
            )));
        }
        let dataparser = DataparserTransform::read(run.join("dataparser_transforms.json"))?;
        let grid = GridSettings {
            n: OCCUPANCY_CELLS,
            opacity: OCCUPANCY_OPACITY,
            far: settings.far_plane,
        };
        let (checkpoint, step) = latest_checkpoint(&run.join("nerfstudio_models"))?;
        let ckpt = Checkpoint::open(&checkpoint)?;
        let keys = Keys::find(&ckpt)?;
        let (mut appearance, n_images) = read_appearance(&ckpt, &keys)?;
        if !settings.use_average_appearance_embedding {
            appearance.fill(0.0);
        }
        let (mut net, n_base, n_params) = if keys.has("mlp_head.tcnn_encoding.params") {
            read_tcnn(&ckpt, &keys, &settings, appearance.len())?
        } else {
            read_torch(&ckpt, &keys, &settings, appearance.len())?
        };
        // The appearance is the same for every sample: folded into the colour MLP's first
        // biases. The direction is shared by a ray's samples: its columns are split off
        // (the inputs were reordered to end with it), so the MLP reads the geometry only.
        let (Net::Tcnn { head, .. } | Net::Torch { head, .. }) = &mut net;
        let (geometry_head, head_dir) = split_head(head, &appearance).ok_or_else(|| {
            Error::format(
                &checkpoint,
                "mlp_head",
                "the colour MLP has fewer inputs than the direction's encoding and the \
                 appearance embedding",
            )
        })?;
        *head = geometry_head;
        let proposal = read_proposal(&ckpt, &config_text, &config_file, &settings)?;
        let mut field = NerfactoField {
            run: run.to_path_buf(),
            checkpoint,
            step,
            settings,
            dataparser,
            net,
            n_base,
            n_params: n_params + appearance.len() * n_images,
            appearance,
            head_dir,
            n_images,
            occupancy: OccupancyGrid::full(&grid),
            proposal,
        };
        let config = run.join("config.yml");
        let key = cache_key(&grid, &field.checkpoint, &config);
        let caches = cache_paths(run);
        field.occupancy = OccupancyGrid::load_or_build(&grid, &caches, key.as_deref(), |c, s| {
            field.density_contracted(c, s)
        });
        Ok(field)
    }

    /// The run's dataparser transform (data frame → the field's frame).
    pub fn dataparser(&self) -> &DataparserTransform {
        &self.dataparser
    }

    /// A human-readable description: format, architecture, parameters, bounds, occupancy.
    pub fn describe(&self) -> String {
        let s = &self.settings;
        let (layout, grid, density, head) = match &self.net {
            Net::Tcnn {
                grid,
                density,
                head,
            } => {
                let g = grid.config();
                let (d, h) = (density.config(), head.config());
                (
                    "tiny-cuda-nn (flat params)",
                    format!(
                        "{} levels x {} features, 2^{} entries, N_min {}, per-level scale {:.6}, tables {:?}",
                        g.n_levels, g.n_features, g.log2_table_size, g.base_resolution,
                        g.per_level_scale, grid.storage()
                    ),
                    format!("{} -> {}x{} -> {}", d.n_inputs, d.n_hidden_layers, d.width, d.n_outputs),
                    format!(
                        "{} -> {}x{} -> 3",
                        SH_INPUTS + h.n_inputs + self.appearance.len(),
                        h.n_hidden_layers,
                        h.width
                    ),
                )
            }
            Net::Torch { density, head, .. } => {
                let (d, h) = (density.config(), head.config());
                (
                    "torch fallback (biases, every level hashed)",
                    format!(
                        "{} levels x {} features, 2^{} rows per level, N_min {}, N_max {}",
                        s.num_levels,
                        s.features_per_level,
                        s.log2_hashmap_size,
                        s.base_res,
                        s.max_res
                    ),
                    format!(
                        "{} -> {} layers of {} -> {}",
                        d.n_inputs,
                        d.n_hidden_layers + 1,
                        d.width,
                        d.n_outputs
                    ),
                    format!(
                        "{} -> {} layers of {} -> 3",
                        SH_INPUTS + h.n_inputs + self.appearance.len(),
                        h.n_hidden_layers + 1,
                        h.width
                    ),
                )
            }
        };
        let sampler = match &self.proposal {
            Some(p) => {
                let ps = p.settings();
                format!(
                    "{} proposal network{} ({} parameters), {} samples then {} of the field, \
                     {} initial spacing, far plane {}",
                    ps.nets.len(),
                    if ps.nets.len() == 1 { "" } else { "s" },
                    p.n_params(),
                    ps.proposal_samples
                        .iter()
                        .map(usize::to_string)
                        .collect::<Vec<_>>()
                        .join(" then "),
                    ps.nerf_samples,
                    if ps.uniform_initial {
                        "uniform"
                    } else {
                        "piecewise"
                    },
                    self.settings.far_plane
                )
            }
            None => "none (no proposal networks in the checkpoint)".into(),
        };
        let b = self.bounds();
        format!(
            "run: {}\n\
             format: nerfstudio {} run, checkpoint {} (step {}), {}, parameters {}\n\
             hash grid: {grid}\n\
             density MLP: {density} (average_init_density {} * exp)\n\
             colour MLP: {head} (sigmoid, sRGB to linear); appearance: {} of {} embeddings of {}\n\
             scene contraction: L-infinity; dataparser scale {}\n\
             nerfacto's own sampler: {sampler}\n\
             bounds (nerfstudio frame): [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]; rays \
             to far_plane {}\n\
             occupancy: {}^3 cells over the contracted cube {}, fill ratio {:.4}",
            self.run.display(),
            if s.method_name.is_empty() {
                "(unnamed method)"
            } else {
                &s.method_name
            },
            self.checkpoint.display(),
            self.step,
            layout,
            self.n_params,
            s.average_init_density,
            if s.use_average_appearance_embedding {
                "mean"
            } else {
                "zero instead"
            },
            self.n_images,
            self.appearance.len(),
            self.dataparser.scale,
            b.min.x,
            b.min.y,
            b.min.z,
            b.max.x,
            b.max.y,
            b.max.z,
            s.far_plane,
            self.occupancy.resolution(),
            match self.occupancy.source() {
                Source::Computed => "computed at load".to_string(),
                Source::Cached(path) if *path == self.run.join(CACHE_FILE) => {
                    format!("read from {CACHE_FILE}")
                }
                Source::Cached(path) => format!("read from {}", path.display()),
            },
            self.occupancy.fill_ratio(),
        )
    }

    /// The point of the hash grid's unit cube for a field-space point (L∞ contraction,
    /// then `(c + 2)/4`), or `None` outside nerfacto's selector `0 < u < 1`.
    #[inline]
    fn unit_from_field(p: Vec3) -> Option<Vec3> {
        let u = (contract(p) + Vec3::splat(2.0)) / 4.0;
        (u.cmpgt(Vec3::ZERO).all() && u.cmplt(Vec3::ONE).all()).then_some(u)
    }

    /// The density MLP's outputs at unit-cube points: `out[k·n_base ..][.. n_base]`.
    fn base(&self, xs: &[Vec3], enc: &mut Vec<f32>, out: &mut Vec<f32>) {
        out.resize(xs.len() * self.n_base, 0.0);
        match &self.net {
            Net::Tcnn { grid, density, .. } => {
                enc.resize(xs.len() * grid.config().n_outputs(), 0.0);
                grid.encode(xs, enc);
                density.forward(enc, out);
            }
            Net::Torch { grid, density, .. } => {
                enc.resize(xs.len() * grid.n_outputs(), 0.0);
                grid.encode(xs, enc);
                density.forward(enc, out);
            }
        }
    }

    /// Densities without the occupancy mask at contracted points `c` (`‖c‖∞ < 2`; zero
    /// outside nerfacto's selector).
    fn density_contracted(&self, cs: &[Vec3], sigma: &mut [f32]) {
        let (mut xs, mut idx) = (Vec::with_capacity(CHUNK), Vec::with_capacity(CHUNK));
        let (mut enc, mut out) = (Vec::new(), Vec::new());
        for (pts, sig) in cs.chunks(CHUNK).zip(sigma.chunks_mut(CHUNK)) {
            xs.clear();
            idx.clear();
            for (i, c) in pts.iter().enumerate() {
                sig[i] = 0.0;
                let u = (*c + Vec3::splat(2.0)) / 4.0;
                if u.cmpgt(Vec3::ZERO).all() && u.cmplt(Vec3::ONE).all() {
                    xs.push(u);
                    idx.push(i);
                }
            }
            self.base(&xs, &mut enc, &mut out);
            for (k, &i) in idx.iter().enumerate() {
                sig[i] = self.sigma_from_raw(out[k * self.n_base]);
            }
        }
    }

    /// Densities without the occupancy mask.
    fn density_unmasked(&self, points: &[Vec3], sigma: &mut [f32]) {
        let (mut xs, mut idx) = (Vec::with_capacity(CHUNK), Vec::with_capacity(CHUNK));
        let (mut enc, mut out) = (Vec::new(), Vec::new());
        let bounds = self.bounds();
        for (pts, sig) in points.chunks(CHUNK).zip(sigma.chunks_mut(CHUNK)) {
            xs.clear();
            idx.clear();
            for (i, p) in pts.iter().enumerate() {
                sig[i] = 0.0;
                if !bounds.contains(*p) {
                    continue;
                }
                if let Some(u) = Self::unit_from_field(*p) {
                    xs.push(u);
                    idx.push(i);
                }
            }
            self.base(&xs, &mut enc, &mut out);
            for (k, &i) in idx.iter().enumerate() {
                sig[i] = self.sigma_from_raw(out[k * self.n_base]);
            }
        }
    }

    /// `average_init_density · exp(raw)` (see [`exp_density`]).
    #[inline]
    fn sigma_from_raw(&self, raw: f32) -> f32 {
        self.settings.average_init_density * exp_density(raw)
    }

    /// Whether `p` may have density: inside the bounds and in an occupied cell.
    #[inline]
    fn kept(&self, p: Vec3) -> bool {
        self.bounds().contains(p) && self.occupancy.point(p)
    }

    /// Colours from the geometry features (`n_base − 1` per point) and directions (see
    /// [`head_outputs`]).
    pub(crate) fn colour(&self, geo: &[f32], dirs: &[Vec3], rgb: &mut [Vec3]) {
        let n_geo = self.n_base - 1;
        let (Net::Tcnn { head, .. } | Net::Torch { head, .. }) = &self.net;
        let encoding = |d| self.direction_encoding(d);
        let (mut scratch, mut colour) = (HeadScratch::default(), Vec::new());
        let parts = geo.chunks(CHUNK * n_geo).zip(dirs.chunks(CHUNK));
        for ((g, ds), dst) in parts.zip(rgb.chunks_mut(CHUNK)) {
            colour.resize(ds.len() * 3, 0.0);
            head_outputs(
                head,
                &self.head_dir,
                encoding,
                g,
                ds,
                &mut scratch,
                &mut colour,
            );
            for (c, v) in dst.iter_mut().zip(colour.chunks_exact(3)) {
                *c = Vec3::from_array([v[0], v[1], v[2]].map(|x| 1.0 / (1.0 + (-x).exp())));
            }
        }
    }

    /// The colour MLP's encoding of the view direction `d`.
    fn direction_encoding(&self, d: Vec3) -> [f32; SH_INPUTS] {
        match self.net {
            Net::Tcnn { .. } => sh4(d),
            Net::Torch { .. } => torch_sh4((d + Vec3::ONE) * 0.5),
        }
    }

    /// Densities and geometry features as nerfacto's own sampler sees them: on all of space
    /// (no bounds, no occupancy), zero outside the contraction's selector.
    pub(crate) fn density_features_unbounded(
        &self,
        points: &[Vec3],
        sigma: &mut [f32],
        features: &mut [f32],
    ) {
        let n_geo = self.n_base - 1;
        self.for_each_base(points, |i, selected, o| {
            sigma[i] = if selected {
                self.sigma_from_raw(o[0])
            } else {
                0.0
            };
            features[i * n_geo..(i + 1) * n_geo].copy_from_slice(&o[1..]);
        });
    }

    /// Where nerfacto's sampling stops, field units from the camera (`far_plane`).
    pub fn far_plane(&self) -> f32 {
        self.settings.far_plane
    }

    /// Whether the run holds nerfacto's proposal networks (so its proposal sampler,
    /// [`crate::render::sample_proposals`], can sample it).
    pub(crate) fn has_proposal_sampler(&self) -> bool {
        self.proposal.is_some()
    }

    /// The proposal networks, when the checkpoint holds them.
    pub(crate) fn proposal_networks(&self) -> Option<&ProposalNetworks> {
        self.proposal.as_ref()
    }

    /// Floats of geometry features per point that the density pass leaves for the colour
    /// ([`Self::density_features_unbounded`], [`Self::colour`]).
    pub(crate) fn geometry_features(&self) -> usize {
        self.n_base - 1
    }

    /// The density outputs at every point (nerfacto zeroes the position outside its
    /// selector), calling `each(i, selected, outputs)` per point, `selected` whether the
    /// point is inside the selector.
    fn for_each_base(&self, points: &[Vec3], mut each: impl FnMut(usize, bool, &[f32])) {
        let (mut xs, mut enc, mut out) = (Vec::with_capacity(CHUNK), Vec::new(), Vec::new());
        let mut selected = Vec::with_capacity(CHUNK);
        for (c, pts) in points.chunks(CHUNK).enumerate() {
            xs.clear();
            selected.clear();
            for p in pts {
                let u = Self::unit_from_field(*p);
                selected.push(u.is_some());
                xs.push(u.unwrap_or(Vec3::ZERO));
            }
            self.base(&xs, &mut enc, &mut out);
            let outputs = out.chunks_exact(self.n_base).zip(&selected);
            for (k, (o, &selected)) in outputs.enumerate() {
                each(c * CHUNK + k, selected, o);
            }
        }
    }
}

/// nerfacto's proposal sampler, when the checkpoint has proposal networks.
fn read_proposal(
    ckpt: &Checkpoint,
    config_text: &str,
    config_file: &Path,
    settings: &RunSettings,
) -> Result<Option<ProposalNetworks>> {
    if Keys::under(ckpt, "_model.proposal_networks.").is_none() {
        return Ok(None);
    }
    let sampler = SamplerSettings::from_text(config_text, config_file)?;
    let nets = sampler
        .nets
        .iter()
        .enumerate()
        .map(|(i, net)| DensityField::read(ckpt, i, net, settings.average_init_density))
        .collect::<Result<Vec<_>>>()?;
    Ok(Some(ProposalNetworks::new(sampler, nets)))
}

/// `nerfstudio_models/step-<n>.ckpt` with the highest `n`.
pub(crate) fn latest_checkpoint(dir: &Path) -> Result<(PathBuf, u64)> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut best: Option<(u64, PathBuf)> = None;
    for entry in entries {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let digits = name
            .strip_prefix("step-")
            .and_then(|n| n.strip_suffix(".ckpt"))
            .filter(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        if let Some(digits) = digits {
            // Skipping a checkpoint whose step is too large would load an older one.
            let step = digits.parse::<u64>().map_err(|_| {
                Error::format(
                    &path,
                    "",
                    format!(
                        "the step {digits} does not fit 64 bits, so which checkpoint is the \
                         latest cannot be told: rename it or move it out of nerfstudio_models"
                    ),
                )
            })?;
            if best.as_ref().is_none_or(|(b, _)| step > *b) {
                best = Some((step, path));
            }
        }
    }
    best.map(|(s, p)| (p, s)).ok_or_else(|| {
        Error::format(
            dir,
            "",
            "no step-<n>.ckpt checkpoint in the run's nerfstudio_models",
        )
    })
}

/// The field's state-dict prefix and key lookup.
struct Keys<'a> {
    ckpt: &'a Checkpoint,
    prefix: String,
    path: PathBuf,
}

impl<'a> Keys<'a> {
    fn find(ckpt: &'a Checkpoint) -> Result<Self> {
        Self::under(ckpt, "_model.field.").ok_or_else(|| {
            Error::format(
                ckpt.path().to_path_buf(),
                "pipeline",
                "no '_model.field.' tensors: not a nerfacto checkpoint",
            )
        })
    }

    /// The keys under the module path `mark` (`_model.<module>.`), wherever the state
    /// dict puts it; `None` when no tensor is under it.
    fn under(ckpt: &'a Checkpoint, mark: &str) -> Option<Self> {
        let prefix = ckpt
            .tensors()
            .keys()
            .find_map(|k| k.find(mark).map(|i| k[..i + mark.len()].to_owned()))?;
        Some(Keys {
            ckpt,
            prefix,
            path: ckpt.path().to_path_buf(),
        })
    }

    fn name(&self, key: &str) -> String {
        format!("{}{key}", self.prefix)
    }

    fn has(&self, key: &str) -> bool {
        self.ckpt.get(&self.name(key)).is_some()
    }

    /// The first of `keys` present.
    fn first(&self, keys: &[&str]) -> Option<String> {
        keys.iter().find(|k| self.has(k)).map(|k| self.name(k))
    }

    fn err(&self, key: &str, msg: impl Into<String>) -> Error {
        Error::format(&self.path, key, msg.into())
    }

    fn shape(&self, name: &str) -> Vec<usize> {
        self.ckpt
            .get(name)
            .map(|t| t.shape.clone())
            .unwrap_or_default()
    }
}

/// The mean appearance embedding and the number of images (empty without embeddings).
fn read_appearance(ckpt: &Checkpoint, keys: &Keys) -> Result<(Vec<f32>, usize)> {
    let name = keys.name("embedding_appearance.embedding.weight");
    if ckpt.get(&name).is_none() {
        return Ok((Vec::new(), 0));
    }
    let shape = keys.shape(&name);
    let [n, d] = shape[..] else {
        return Err(keys.err(&name, format!("expected [images, dim], found {shape:?}")));
    };
    if n == 0 {
        return Err(keys.err(&name, "no embeddings"));
    }
    let w = read_weights(ckpt, &name)?;
    let mean = (0..d)
        .map(|j| ((0..n).map(|i| f64::from(w[i * d + j])).sum::<f64>() / n as f64) as f32)
        .collect();
    Ok((mean, n))
}

/// The tiny-cuda-nn layout: `(net, density outputs, parameter count)`.
fn read_tcnn(
    ckpt: &Checkpoint,
    keys: &Keys,
    s: &RunSettings,
    n_appearance: usize,
) -> Result<(Net, usize, usize)> {
    const N_BASE: usize = 16;
    let grid_config = tcnn_grid_config(
        s.num_levels,
        s.features_per_level,
        s.log2_hashmap_size,
        s.base_res,
        s.max_res,
    );
    let density_config = MlpConfig {
        n_inputs: grid_config.n_outputs(),
        width: s.hidden_dim,
        n_hidden_layers: 1,
        n_outputs: N_BASE,
        output_alignment: 16,
    };
    let (nd, ng) = (density_config.n_params(), grid_config.n_params());
    // Density MLP and grid: one flat tensor (MLP first), or one each.
    let (mlp_params, grid_params, grid_name) =
        if let Some(name) = keys.first(&["mlp_base.model.params", "mlp_base.params"]) {
            let p = read_params(ckpt, keys, &name, nd + ng)?;
            let (m, g) = p.split_at(nd);
            (m.to_vec(), g.to_vec(), name)
        } else {
            let m = keys
                .first(&["mlp_base_mlp.tcnn_encoding.params"])
                .ok_or_else(|| {
                    keys.err(
                        "pipeline",
                        "no density network (mlp_base) in the checkpoint",
                    )
                })?;
            let g = keys
                .first(&["mlp_base_grid.tcnn_encoding.params"])
                .ok_or_else(|| {
                    keys.err("pipeline", "no hash grid (mlp_base_grid) in the checkpoint")
                })?;
            (
                read_params(ckpt, keys, &m, nd)?,
                read_params(ckpt, keys, &g, ng)?,
                g,
            )
        };
    let grid = tcnn_grid(ckpt, keys, &grid_name, grid_config, grid_params)?;
    let density = Mlp::new(density_config, &mlp_params)
        .ok_or_else(|| keys.err(&grid_name, "density MLP parameters do not match the config"))?;
    let head_name = keys.name("mlp_head.tcnn_encoding.params");
    let mut head_params = read_weights(ckpt, &head_name)?;
    let head_config = [16, 8]
        .map(|align| MlpConfig {
            n_inputs: SH_INPUTS + (N_BASE - 1) + n_appearance,
            width: s.hidden_dim_color,
            n_hidden_layers: 2,
            n_outputs: 3,
            output_alignment: align,
        })
        .into_iter()
        .find(|c| c.n_params() == head_params.len())
        .ok_or_else(|| {
            keys.err(
                &head_name,
                format!(
                    "{} parameters do not fit a colour MLP of width {} over {} inputs",
                    head_params.len(),
                    s.hidden_dim_color,
                    SH_INPUTS + (N_BASE - 1) + n_appearance
                ),
            )
        })?;
    let first_layer = head_config.width * head_config.n_inputs.next_multiple_of(16);
    direction_after_geometry(
        &mut head_params[..first_layer],
        head_config.n_inputs.next_multiple_of(16),
        N_BASE - 1,
    );
    let head = Mlp::new(head_config, &head_params)
        .ok_or_else(|| keys.err(&head_name, "colour MLP parameters do not match"))?;
    let n_params = nd + ng + head_params.len();
    Ok((
        Net::Tcnn {
            grid,
            density,
            head,
        },
        N_BASE,
        n_params,
    ))
}

/// The tensor `name` as float32 values, refused naming the checkpoint and the tensor when
/// any is NaN or infinite (see [`non_finite`]).
fn read_weights(ckpt: &Checkpoint, name: &str) -> Result<Vec<f32>> {
    let values = ckpt.read_f32(name)?;
    match non_finite(&values) {
        Some(why) => Err(Error::format(ckpt.path().to_path_buf(), name, why)),
        None => Ok(values),
    }
}

/// tiny-cuda-nn's hash grid as nerfstudio configures it: per-level scale
/// `exp((ln N_max − ln N_min)/(L − 1))` (computed in f64, stored as f32).
fn tcnn_grid_config(
    n_levels: u32,
    n_features: u32,
    log2_table_size: u32,
    base_res: u32,
    max_res: u32,
) -> HashGridConfig {
    let growth = if n_levels > 1 {
        ((f64::from(max_res).ln() - f64::from(base_res).ln()) / f64::from(n_levels - 1)).exp()
    } else {
        1.0
    };
    HashGridConfig {
        n_levels,
        n_features,
        log2_table_size,
        base_resolution: base_res,
        per_level_scale: growth as f32,
    }
}

/// A tiny-cuda-nn grid from its parameters, kept in f16 when the checkpoint stores them so.
fn tcnn_grid(
    ckpt: &Checkpoint,
    keys: &Keys,
    name: &str,
    config: HashGridConfig,
    params: Vec<f32>,
) -> Result<HashGrid> {
    let half = ckpt.get(name).is_some_and(|t| t.dtype == DType::F16);
    if half {
        let h: Vec<f16> = params.iter().map(|&v| f16::from_f32(v)).collect();
        HashGrid::new(config, &h, TableStorage::F16)
    } else {
        HashGrid::from_f32(config, params)
    }
    .ok_or_else(|| keys.err(name, "hash grid parameters do not match the config"))
}

/// nerfstudio's torch hash grid from the table tensor `name`: `levels` levels of `2^log2`
/// rows of `nf` features, resolutions `base_res` to `max_res`; refused naming the tensor and
/// its shape when the table is the wrong size. Also gives the number of values read.
fn read_torch_grid(
    ckpt: &Checkpoint,
    keys: &Keys,
    name: &str,
    [levels, log2, base_res, max_res]: [u32; 4],
    nf: usize,
) -> Result<(TorchHashGrid, usize)> {
    let table = read_weights(ckpt, name)?;
    let n = table.len();
    let grid = TorchHashGrid::new(levels, nf, log2, base_res, max_res, table).ok_or_else(|| {
        keys.err(
            name,
            format!(
                "shape {:?} ({n} values) is not {levels} levels x 2^{log2} rows x {nf} features",
                keys.shape(name)
            ),
        )
    })?;
    Ok((grid, n))
}

/// A flat parameter tensor of exactly `count` values.
fn read_params(ckpt: &Checkpoint, keys: &Keys, name: &str, count: usize) -> Result<Vec<f32>> {
    let p = read_weights(ckpt, name)?;
    if p.len() != count {
        return Err(keys.err(
            name,
            format!(
                "{} parameters, the config's architecture needs {count}: truncated or a \
                 different config",
                p.len()
            ),
        ));
    }
    Ok(p)
}

/// The torch-fallback layout: `(net, density outputs, parameter count)`.
fn read_torch(
    ckpt: &Checkpoint,
    keys: &Keys,
    s: &RunSettings,
    n_appearance: usize,
) -> Result<(Net, usize, usize)> {
    let (table_name, mlp_prefix) = if keys.has("mlp_base.model.0.hash_table") {
        ("mlp_base.model.0.hash_table", "mlp_base.model.1.layers")
    } else if keys.has("mlp_base_grid.hash_table") {
        ("mlp_base_grid.hash_table", "mlp_base_mlp.layers")
    } else {
        return Err(keys.err(
            "pipeline",
            "neither tiny-cuda-nn parameters nor a torch hash table for the field: not a \
             nerfacto checkpoint",
        ));
    };
    let table_name = keys.name(table_name);
    let nf = s.features_per_level as usize;
    let shape = [s.num_levels, s.log2_hashmap_size, s.base_res, s.max_res];
    let (grid, _) = read_torch_grid(ckpt, keys, &table_name, shape, nf)?;
    let (density, nd) = read_linear_layers(ckpt, keys, mlp_prefix, grid.n_outputs())?;
    let n_base = density.config().n_outputs;
    if n_base < 2 {
        return Err(keys.err(mlp_prefix, "the density MLP has no geometry features"));
    }
    let head_inputs = SH_INPUTS + (n_base - 1) + n_appearance;
    let mut head_layers = read_linear_params(ckpt, keys, "mlp_head.layers")?;
    let nh: usize = head_layers.iter().map(|(w, b)| w.len() + b.len()).sum();
    if let Some((w, _)) = head_layers.first_mut() {
        direction_after_geometry(w, head_inputs, n_base - 1);
    }
    let head = linear_mlp(keys, "mlp_head.layers", head_inputs, &head_layers)?;
    if head.config().n_outputs != 3 {
        return Err(keys.err("mlp_head.layers", "the colour MLP does not give 3 outputs"));
    }
    let n_params = s.num_levels as usize * (1 << s.log2_hashmap_size) * nf + nd + nh;
    Ok((
        Net::Torch {
            grid,
            density,
            head,
        },
        n_base,
        n_params,
    ))
}

/// The colour MLP as loaded (first-layer inputs `[geometry, direction, appearance]`, see
/// [`direction_after_geometry`]) with the appearance folded into its biases and the
/// direction's columns split off: the MLP on the geometry features and those columns.
fn split_head(head: &Mlp, appearance: &[f32]) -> Option<(Mlp, LastInputs)> {
    head.with_last_inputs(appearance)?
        .split_last_inputs(SH_INPUTS)
}

/// Scratch of [`head_outputs`]: the first-layer starts, one row per run of equal
/// directions, and each sample's run.
#[derive(Default)]
struct HeadScratch {
    starts: Vec<f32>,
    row_of: Vec<u32>,
}

/// The colour MLP's raw outputs (3 per sample, before the sigmoid) for the geometry
/// features `geo` (`head`'s inputs per sample) and the directions, `head` and `dir` from
/// [`split_head`]: the direction's part of the first layer (its encoding times those
/// columns, plus the biases) is summed once per run of consecutive equal directions (a
/// ray's samples share one), each sample's layer starting from its run's sums.
fn head_outputs(
    head: &Mlp,
    dir: &LastInputs,
    encoding: impl Fn(Vec3) -> [f32; SH_INPUTS],
    geo: &[f32],
    dirs: &[Vec3],
    s: &mut HeadScratch,
    out: &mut [f32],
) {
    dir.starts_per_run(dirs, encoding, &mut s.starts, &mut s.row_of);
    let n_geo = head.config().n_inputs;
    head.forward_from(&geo[..dirs.len() * n_geo], &s.starts, &s.row_of, out);
}

/// Moves the direction's columns after the geometry's in a colour MLP's first layer,
/// row-major `[out][row]` with inputs `[direction (16), geometry (n_geo), …]`, so that
/// after the appearance is folded in they are the last ones ([`Mlp::split_last_inputs`]).
/// Rows too short to hold both are left as they are (the MLP refuses them).
fn direction_after_geometry(w: &mut [f32], row: usize, n_geo: usize) {
    for r in w.chunks_exact_mut(row.max(1)) {
        if let Some(inputs) = r.get_mut(..SH_INPUTS + n_geo) {
            inputs.rotate_left(SH_INPUTS);
        }
    }
}

/// `<prefix>.<i>.weight|bias` for `i = 0, 1, …` as a torch [`Mlp`] (with biases), and its
/// parameter count.
fn read_linear_layers(
    ckpt: &Checkpoint,
    keys: &Keys,
    prefix: &str,
    n_inputs: usize,
) -> Result<(Mlp, usize)> {
    let layers = read_linear_params(ckpt, keys, prefix)?;
    let count = layers.iter().map(|(w, b)| w.len() + b.len()).sum();
    Ok((linear_mlp(keys, prefix, n_inputs, &layers)?, count))
}

/// `<prefix>.<i>.weight|bias` for `i = 0, 1, …`: each layer's `(W, b)`, `W` row-major
/// `[out][in]`.
fn read_linear_params(
    ckpt: &Checkpoint,
    keys: &Keys,
    prefix: &str,
) -> Result<Vec<(Vec<f32>, Vec<f32>)>> {
    let mut layers = Vec::new();
    while keys.has(&format!("{prefix}.{}.weight", layers.len())) {
        let w = read_weights(
            ckpt,
            &keys.name(&format!("{prefix}.{}.weight", layers.len())),
        )?;
        let b = read_weights(ckpt, &keys.name(&format!("{prefix}.{}.bias", layers.len())))?;
        layers.push((w, b));
    }
    Ok(layers)
}

/// The torch [`Mlp`] of the layers read from `<prefix>`, checked to chain from `n_inputs`.
fn linear_mlp(
    keys: &Keys,
    prefix: &str,
    n_inputs: usize,
    layers: &[(Vec<f32>, Vec<f32>)],
) -> Result<Mlp> {
    Mlp::with_biases(n_inputs, layers).ok_or_else(|| {
        keys.err(
            &keys.name(prefix),
            format!("layers missing or not chaining from {n_inputs} inputs"),
        )
    })
}

impl Field for NerfactoField {
    /// The cube `‖x‖∞ ≤ far_plane`: a ray from a camera at the centre ends at the far plane
    /// inside it.
    fn bounds(&self) -> Aabb {
        let far = self.settings.far_plane;
        Aabb::new(Vec3::splat(-far), Vec3::splat(far))
    }

    /// The unit cube as the core (the contraction is the identity there); the marcher's
    /// occupancy grid over `[−2, 2]³`, as when the field ended there (so a run whose content
    /// is near is skipped through as before, and the coarse far-field test starts where its
    /// boxes no longer reach the core's cells); the finest empty-space step beyond it a
    /// quarter of an occupancy cell; rays from the camera (nerfstudio's near plane at
    /// inference) to the run's far plane.
    fn unbounded(&self) -> Option<Unbounded> {
        Some(Unbounded {
            core: 1.0,
            grid: 2.0,
            skip: FAR_SKIP,
            near: 0.0,
            far: self.settings.far_plane,
        })
    }

    fn color_space(&self) -> ColorSpace {
        ColorSpace::Srgb
    }

    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        self.density_unmasked(points, sigma);
        for (p, s) in points.iter().zip(sigma.iter_mut()) {
            if *s != 0.0 && !self.occupancy.point(*p) {
                *s = 0.0;
            }
        }
    }

    fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]) {
        let n_geo = self.n_base - 1;
        let mut geo = vec![0.0; points.len() * n_geo];
        self.for_each_base(points, |i, _, o| {
            geo[i * n_geo..(i + 1) * n_geo].copy_from_slice(&o[1..]);
        });
        self.colour(&geo, dirs, rgb);
    }

    /// The geometry features (15 for nerfacto) of the density network.
    fn feature_count(&self) -> usize {
        self.n_base - 1
    }

    fn density_with_features(&self, points: &[Vec3], sigma: &mut [f32], features: &mut [f32]) {
        let n_geo = self.n_base - 1;
        self.for_each_base(points, |i, selected, o| {
            let inside = selected && self.kept(points[i]);
            sigma[i] = if inside {
                self.sigma_from_raw(o[0])
            } else {
                0.0
            };
            features[i * n_geo..(i + 1) * n_geo].copy_from_slice(&o[1..]);
        });
    }

    fn radiance_with_features(
        &self,
        _points: &[Vec3],
        dirs: &[Vec3],
        features: &[f32],
        rgb: &mut [Vec3],
    ) {
        self.colour(features, dirs, rgb);
    }

    /// Twice the finest level's cell inside the unit ball: `4/1024` scene units (the
    /// contracted cube `[−2, 2]` spans the grid's unit side at `N_max = 2048`).
    fn feature_size(&self) -> f32 {
        4.0 / 1024.0
    }

    /// The finest hash-grid cell inside the unit ball, where the contraction is the identity
    /// and the grid's unit side spans 4 field units: `4/s_{L−1}`. Outside it the contraction
    /// stretches cells, so this is their shortest extent anywhere.
    fn smooth_length(&self) -> f32 {
        let finest = match &self.net {
            Net::Tcnn { grid, .. } => grid.config().finest_scale(),
            Net::Torch { grid, .. } => grid.finest_scale(),
        };
        4.0 / finest.max(1.0)
    }

    fn may_be_occupied(&self, region: &Aabb) -> bool {
        if region.is_empty() {
            return false;
        }
        let b = self.bounds();
        let clipped = Aabb::new(region.min.max(b.min), region.max.min(b.max));
        !clipped.is_empty() && self.occupancy.region(&clipped)
    }

    /// The density's own mask, cell for cell: a point outside the bounds or the occupied
    /// cells is given zero density. NaN points lie in no cell.
    fn certainly_empty(&self, points: &[Vec3], empty: &mut [bool]) {
        for (p, e) in points.iter().zip(empty) {
            *e = !self.kept(*p);
        }
    }
}

/// `n` values in `[−scale, scale)` from a seeded generator: the unit tests' weights and
/// inputs, and [`ColorHeadBench`]'s.
fn seeded(n: usize, seed: u64, scale: f32) -> Vec<f32> {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            scale * ((x >> 40) as f32 / (1u64 << 23) as f32 - 1.0)
        })
        .collect()
}

/// A seeded torch colour head (15 geometry features, 32 of appearance, width 64) on
/// [`SAMPLES`](Self::SAMPLES) samples in runs of 40 sharing a direction, by runs
/// ([`head_outputs`]) and as the whole network on the full inputs: what
/// `cargo bench --bench nerfacto -- colour_by_runs` times.
#[doc(hidden)]
pub struct ColorHeadBench {
    whole: Mlp,
    head: Mlp,
    dir: LastInputs,
    dirs: Vec<Vec3>,
    geo: Vec<f32>,
    input: Vec<f32>,
    out: Vec<f32>,
    scratch: HeadScratch,
}

impl ColorHeadBench {
    /// Samples per run.
    pub const SAMPLES: usize = 512;
    const N_GEO: usize = 15;

    /// The seeded head, directions and geometry features.
    pub fn new() -> Self {
        let (n, n_geo, n_app, width) = (Self::SAMPLES, Self::N_GEO, 32, 64);
        let n_in = SH_INPUTS + n_geo + n_app;
        let appearance = seeded(n_app, 1, 1.0);
        let layers = vec![
            (seeded(width * n_in, 3, 0.3), seeded(width, 4, 0.5)),
            (seeded(width * width, 5, 0.2), seeded(width, 6, 0.5)),
            (seeded(3 * width, 7, 0.2), seeded(3, 8, 0.5)),
        ];
        let dirs: Vec<Vec3> = (0..n)
            .map(|k| Vec3::new(1.0, (k / 40) as f32 * 0.01, 0.5).normalize())
            .collect();
        let geo = seeded(n * n_geo, 2, 3.0);
        let whole = Mlp::with_biases(SH_INPUTS + n_geo, &{
            let mut l = layers.clone();
            l[0].0 = l[0]
                .0
                .chunks_exact(n_in)
                .flat_map(|r| r[..SH_INPUTS + n_geo].to_vec())
                .collect();
            l
        })
        .unwrap();
        let mut reordered = layers;
        direction_after_geometry(&mut reordered[0].0, n_in, n_geo);
        let (head, dir) =
            split_head(&Mlp::with_biases(n_in, &reordered).unwrap(), &appearance).unwrap();
        Self {
            whole,
            head,
            dir,
            dirs,
            geo,
            input: Vec::new(),
            out: vec![0.0; n * 3],
            scratch: HeadScratch::default(),
        }
    }

    fn encoding(d: Vec3) -> [f32; SH_INPUTS] {
        torch_sh4((d + Vec3::ONE) * 0.5)
    }

    /// The whole network on the full inputs, each sample's direction encoded with its
    /// geometry features.
    pub fn run_whole(&mut self) {
        self.input.clear();
        for (d, g) in self.dirs.iter().zip(self.geo.chunks_exact(Self::N_GEO)) {
            self.input.extend_from_slice(&Self::encoding(*d));
            self.input.extend_from_slice(g);
        }
        self.whole.forward(&self.input, &mut self.out);
    }

    /// The head by runs: the direction's part summed once per run of equal directions.
    pub fn run_by_runs(&mut self) {
        head_outputs(
            &self.head,
            &self.dir,
            Self::encoding,
            &self.geo,
            &self.dirs,
            &mut self.scratch,
            &mut self.out,
        );
    }
}

impl Default for ColorHeadBench {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_checkpoint_step_past_64_bits_is_refused_not_skipped() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["step-000000100.ckpt", "step-99999999999999999999999.ckpt"] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        let e = latest_checkpoint(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("step-99999999999999999999999.ckpt") && e.contains("does not fit 64 bits"),
            "{e}"
        );
        std::fs::remove_file(dir.path().join("step-99999999999999999999999.ckpt")).unwrap();
        let (path, step) = latest_checkpoint(dir.path()).unwrap();
        assert_eq!(
            (path.file_name().unwrap(), step),
            ("step-000000100.ckpt".as_ref(), 100)
        );
    }

    #[test]
    fn contraction_follows_the_formula() {
        // Inside the unit cube: unchanged, then (p + 2)/4.
        let u = NerfactoField::unit_from_field(Vec3::new(0.5, -0.25, 0.0)).unwrap();
        assert!((u - Vec3::new(0.625, 0.4375, 0.5)).length() < 1e-7);
        // ‖x‖∞ = 4: (2 − 1/4)·x/4 = 1.75·(1, 0.5, −0.25) → (+2)/4.
        let u = NerfactoField::unit_from_field(Vec3::new(4.0, 2.0, -1.0)).unwrap();
        let c = Vec3::new(1.75, 0.875, -0.4375);
        assert!((u - (c + Vec3::splat(2.0)) / 4.0).length() < 1e-6);
        // Infinitely far: u reaches 1 and leaves the selector.
        assert!(NerfactoField::unit_from_field(Vec3::new(f32::INFINITY, 0.0, 0.0)).is_none());
    }

    /// The MLP `(W [out][in], b)` per layer on `x` in f64, ReLU between layers.
    fn reference(layers: &[(Vec<f32>, Vec<f32>)], x: &[f32]) -> Vec<f64> {
        let mut a: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        for (k, (w, b)) in layers.iter().enumerate() {
            let n_in = w.len() / b.len();
            a.resize(n_in, 0.0);
            a = w
                .chunks_exact(n_in)
                .zip(b)
                .map(|(row, &bias)| {
                    let y = row
                        .iter()
                        .zip(&a)
                        .fold(f64::from(bias), |s, (&wi, &ai)| s + f64::from(wi) * ai);
                    if k + 1 < layers.len() {
                        y.max(0.0)
                    } else {
                        y
                    }
                })
                .collect();
        }
        a
    }

    /// The colour head as the field evaluates it (inputs reordered, appearance folded in,
    /// the direction's part summed once per run) against the whole network on
    /// `[encoding, geometry, appearance]`, in both layouts, on runs of equal directions of
    /// lengths across the kernels' blocks.
    #[test]
    fn colour_by_runs_matches_the_whole_network() {
        let (n_geo, n_app, width) = (15, 32, 64);
        let n_in = SH_INPUTS + n_geo + n_app;
        let appearance = seeded(n_app, 1, 1.0);
        let runs = [1, 3, 16, 17, 48, 2, 5, 33, 48, 7];
        let dirs: Vec<Vec3> = runs
            .iter()
            .enumerate()
            .flat_map(|(r, &len)| {
                let v = seeded(3, 100 + r as u64, 1.0);
                let d = Vec3::new(v[0], v[1], v[2] + 0.1).normalize();
                std::iter::repeat_n(d, len)
            })
            .collect();
        let n = dirs.len();
        let geo = seeded(n * n_geo, 2, 3.0);
        let torch_layers = vec![
            (seeded(width * n_in, 3, 0.3), seeded(width, 4, 0.5)),
            (seeded(width * width, 5, 0.2), seeded(width, 6, 0.5)),
            (seeded(3 * width, 7, 0.2), seeded(3, 8, 0.5)),
        ];
        let tcnn_config = MlpConfig {
            n_inputs: n_in,
            width,
            n_hidden_layers: 2,
            n_outputs: 3,
            output_alignment: 16,
        };
        let tcnn_params = seeded(tcnn_config.n_params(), 9, 0.2);
        // tiny-cuda-nn's layers as `(W, 0)`: inputs padded to 64, outputs to 16.
        let row = n_in.next_multiple_of(16);
        let (l0, rest) = tcnn_params.split_at(width * row);
        let (l1, l2) = rest.split_at(width * width);
        let tcnn_layers = vec![
            (l0.to_vec(), vec![0.0; width]),
            (l1.to_vec(), vec![0.0; width]),
            (l2.to_vec(), vec![0.0; 16]),
        ];
        let tcnn_sh = |d: Vec3| sh4(d);
        let torch_sh = |d: Vec3| torch_sh4((d + Vec3::ONE) * 0.5);
        let cases: [(&dyn Fn(Vec3) -> [f32; SH_INPUTS], _, _, _); 2] = [
            (
                &tcnn_sh,
                &tcnn_layers,
                Mlp::new(tcnn_config, &tcnn_params).unwrap(),
                {
                    let mut p = tcnn_params.clone();
                    direction_after_geometry(&mut p[..width * row], row, n_geo);
                    Mlp::new(tcnn_config, &p).unwrap()
                },
            ),
            (
                &torch_sh,
                &torch_layers,
                Mlp::with_biases(n_in, &torch_layers).unwrap(),
                {
                    let mut layers = torch_layers.clone();
                    direction_after_geometry(&mut layers[0].0, n_in, n_geo);
                    Mlp::with_biases(n_in, &layers).unwrap()
                },
            ),
        ];
        for (encoding, layers, whole, reordered) in cases {
            let full: Vec<f32> = dirs
                .iter()
                .zip(geo.chunks_exact(n_geo))
                .flat_map(|(d, g)| {
                    let mut x = encoding(*d).to_vec();
                    x.extend_from_slice(g);
                    x.extend_from_slice(&appearance);
                    x
                })
                .collect();
            let (head, dir) = split_head(&reordered, &appearance).unwrap();
            assert_eq!(head.config().n_inputs, n_geo);
            let mut got = vec![f32::NAN; n * 3];
            let mut scratch = HeadScratch::default();
            head_outputs(&head, &dir, encoding, &geo, &dirs, &mut scratch, &mut got);
            assert_eq!(scratch.starts.len(), runs.len() * dir.stride());
            // The whole network in f64 from the weights as stored, and the shared kernel
            // on the full inputs.
            let mut kernel = vec![f32::NAN; n * 3];
            whole.forward(&full, &mut kernel);
            let want: Vec<f64> = full
                .chunks_exact(n_in)
                .flat_map(|x| reference(layers, x)[..3].to_vec())
                .collect();
            let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for (k, ((&g, &w), &f)) in got.iter().zip(&want).zip(&kernel).enumerate() {
                assert!(
                    (f64::from(g) - w).abs() <= 1e-5 * scale,
                    "sample {} output {}: {g} by runs, {w} by the reference",
                    k / 3,
                    k % 3
                );
                assert!(
                    (g - f).abs() <= 1e-5 * scale as f32,
                    "sample {} output {}: {g} by runs, {f} by the whole network",
                    k / 3,
                    k % 3
                );
            }
        }
    }
}
