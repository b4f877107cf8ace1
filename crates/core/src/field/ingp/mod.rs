//! instant-ngp NeRF snapshots (`.ingp`: gzip-framed msgpack, `.msgpack`: raw) as a [`Field`].
//!
//! **Format.** The top level is the network configuration (`encoding`, `network`,
//! `rgb_network`, `dir_encoding`) plus `snapshot` with the flat parameters (`params_binary`,
//! `__half` or `float`, inferred from the byte count when `params_type` is absent): density
//! MLP | rgb MLP | position hash grid. The rgb MLP's output is padded to 16, or to 8 in
//! CutlassMLP snapshots from before September 2022 (told apart by `n_params`).
//!
//! **Evaluation.** A point `q` (instant-ngp coordinates) is mapped into the unit cube of the
//! training box `0.5 ± 0.5·min(aabb_scale, 128)`, hash-encoded (per-level scale
//! `b = exp(ln(2048·aabb_scale/N_min)/(L − 1))` unless the config gives one) and fed to the
//! density MLP: `σ = exp(out₀)`. The rgb MLP reads the 16 density outputs then the 16 SH
//! values of the direction; colour `sigmoid(out)` (sRGB-trained, converted to linear) or
//! `exp(clamp(out, −10, 10))` for HDR snapshots. Where the cascaded occupancy grid is empty
//! the density is zero, as in instant-ngp's marcher.
//!
//! **Frames.** The field is queried in the NeRF/nerfstudio world frame of the camera poses
//! ("field space"). Instant-ngp's loader maps it by `nerf_matrix_to_ngp`: positions
//! `p ↦ (s·p + o)` with the rows cycled `(x, y, z) ← (y, z, x)`, directions cycled alike
//! (defaults `s = 0.33`, `o = 0.5`). So `q = (s·p.y + o.y, s·p.z + o.z, s·p.x + o.x)` and,
//! lengths being `s` times longer in instant-ngp, `σ_field = s·σ_ngp`.

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use half::f16;
use rmpv::Value;

mod cascades;

use super::container::{read_document, Doc, Payload, PayloadKind, Verdict};
use super::network::{
    correctly_rounded, exp_density, non_finite, sh4, HashGrid, HashGridConfig, LastInputs, Mlp,
    MlpConfig, TableStorage,
};
use super::{Aabb, Capabilities, ColorSpace, Field};
use crate::error::{Error, Result};
pub(crate) use cascades::Cascades;

/// Points per batch inside one density or radiance call (bounds the scratch memory).
const CHUNK: usize = 512;
/// Outputs of instant-ngp's density MLP (1 density + 15 geometry features).
pub(crate) const DENSITY_OUTPUTS: usize = 16;

/// An instant-ngp snapshot loaded as a field.
#[derive(Clone, Debug)]
pub struct IngpField {
    summary: Summary,
    grid: HashGrid,
    density_mlp: Mlp,
    /// The density MLP keeping its first output only (`density` needs nothing else: the last
    /// layer costs `width` multiply-adds instead of `16·width`).
    sigma_mlp: Mlp,
    /// The colour MLP reading the density network's outputs; its first layer starts from
    /// the direction's part, summed once per run of samples sharing a direction (`rgb_dir`).
    rgb_mlp: Mlp,
    rgb_dir: LastInputs,
    hdr: bool,
    /// `s` and `o` of `nerf_matrix_to_ngp`.
    scale: f32,
    offset: Vec3,
    /// The training box in instant-ngp coordinates.
    aabb_min: Vec3,
    aabb_size: Vec3,
    cascades: Cascades,
    bounds: Aabb,
}

/// What `describe` prints, gathered at load.
#[derive(Clone, Debug)]
struct Summary {
    path: PathBuf,
    gzip: bool,
    version: u64,
    half: bool,
    cutlass: bool,
    n_params: usize,
    aabb_scale: f32,
}

/// The hash grid, MLP shapes and frame, read from the configuration.
struct Layout {
    grid: HashGridConfig,
    density: MlpConfig,
    rgb: MlpConfig,
}

fn read_layout(doc: &Doc, top: &Value, aabb_scale: f32) -> Result<Layout> {
    let enc = doc.get(top, "", "encoding")?;
    let n_levels = doc.u32_or(enc, "encoding", "n_levels", 16)?;
    let n_features = doc.u32_or(enc, "encoding", "n_features_per_level", 2)?;
    let log2_table_size = doc.u32_or(enc, "encoding", "log2_hashmap_size", 19)?;
    let base_resolution = doc.u32_or(enc, "encoding", "base_resolution", 16)?;
    if !(1..=32).contains(&n_levels)
        || ![1, 2, 4, 8].contains(&n_features)
        || !(1..=30).contains(&log2_table_size)
        || !(1..=4096).contains(&base_resolution)
    {
        return Err(doc.err("encoding", "unsupported hash grid shape"));
    }
    let given = match doc.find(enc, "per_level_scale") {
        Some(v) => doc.f64(v, "encoding.per_level_scale")? as f32,
        None => 0.0,
    };
    let per_level_scale = if given > 0.0 {
        given
    } else if n_levels > 1 {
        let ln = correctly_rounded(f64::ln, 2048.0 * aabb_scale / base_resolution as f32);
        correctly_rounded(f64::exp, ln / (n_levels - 1) as f32)
    } else {
        1.0
    };
    let grid = HashGridConfig {
        n_levels,
        n_features,
        log2_table_size,
        base_resolution,
        per_level_scale,
    };
    let net = |key: &str, hidden: u32, n_inputs: usize, n_outputs: usize| -> Result<MlpConfig> {
        let v = doc.get(top, "", key)?;
        let width = doc.u32_or(v, key, "n_neurons", 64)? as usize;
        let layers = doc.u32_or(v, key, "n_hidden_layers", hidden)? as usize;
        if !(1..=1024).contains(&width) || !(1..=16).contains(&layers) {
            return Err(doc.err(key, "unsupported MLP shape"));
        }
        Ok(MlpConfig {
            n_inputs,
            width,
            n_hidden_layers: layers,
            n_outputs,
            output_alignment: 16,
        })
    };
    let density = net("network", 1, grid.n_outputs(), DENSITY_OUTPUTS)?;
    let rgb = net("rgb_network", 2, DENSITY_OUTPUTS + 16, 3)?;
    Ok(Layout { grid, density, rgb })
}

impl IngpField {
    /// Loads a snapshot; the hash tables stay in the precision they were saved in.
    pub fn load(path: &Path) -> Result<Self> {
        Self::load_with(path, None)
    }

    /// Loads a snapshot with its hash tables in `storage` (`None`: as saved).
    pub fn load_with(path: &Path, storage: Option<TableStorage>) -> Result<Self> {
        let doc = Doc { path };
        let (top, gzip) = read_bounded(&doc)?;
        let snap = doc.get(&top, "", "snapshot")?;
        let version = match doc.find(snap, "version") {
            Some(v) => v.as_u64().unwrap_or(0),
            None => 0,
        };
        if let Some(mode) = doc.find(snap, "mode").and_then(Value::as_str) {
            if mode != "nerf" {
                return Err(Error::Unsupported(format!(
                    "{}: instant-ngp mode '{mode}' (only NeRF snapshots)",
                    path.display()
                )));
            }
        }
        let nerf = doc.get(snap, "snapshot", "nerf")?;
        let aabb_scale = doc.f64(
            doc.get(nerf, "snapshot.nerf", "aabb_scale")?,
            "snapshot.nerf.aabb_scale",
        )? as f32;
        if !aabb_scale.is_finite() || aabb_scale <= 0.0 {
            return Err(doc.err("snapshot.nerf.aabb_scale", "must be positive"));
        }
        let (scale, offset, hdr) = match doc.find(nerf, "dataset") {
            Some(ds) => (
                match doc.find(ds, "scale") {
                    Some(v) => doc.f64(v, "snapshot.nerf.dataset.scale")? as f32,
                    None => 0.33,
                },
                match doc.find(ds, "offset") {
                    Some(v) => doc.vec3(v, "snapshot.nerf.dataset.offset")?,
                    None => Vec3::splat(0.5),
                },
                doc.find(ds, "is_hdr")
                    .and_then(Value::as_bool)
                    .unwrap_or(false),
            ),
            None => (0.33, Vec3::splat(0.5), false),
        };
        if !scale.is_finite() || scale <= 0.0 {
            return Err(doc.err("snapshot.nerf.dataset.scale", "must be positive"));
        }
        let mut layout = read_layout(&doc, &top, aabb_scale)?;
        let bytes = doc.bytes(
            doc.get(snap, "snapshot", "params_binary")?,
            "snapshot.params_binary",
        )?;
        let (half, cutlass) = params_encoding(&doc, snap, &layout, bytes.len())?;
        if cutlass {
            layout.rgb.output_alignment = 8;
        }
        let params: Vec<f32> = if half {
            bytes
                .chunks_exact(2)
                .map(|b| f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect()
        } else {
            bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        };
        let (nd, nr) = (layout.density.n_params(), layout.rgb.n_params());
        let blocks = [
            ("density MLP", 0..nd),
            ("rgb MLP", nd..nd + nr),
            ("hash grid", nd + nr..nd + nr + layout.grid.n_params()),
        ];
        for (block, range) in blocks {
            if let Some(why) = params.get(range).and_then(non_finite) {
                return Err(doc.err("snapshot.params_binary", format!("the {block}: {why}")));
            }
        }
        let bad = |what: &str| doc.err("snapshot.params_binary", format!("bad {what} parameters"));
        let density_mlp =
            Mlp::new(layout.density, &params[..nd]).ok_or_else(|| bad("density MLP"))?;
        let sigma_config = MlpConfig {
            n_outputs: 1,
            ..layout.density
        };
        let sigma_mlp = Mlp::new(sigma_config, &params[..nd]).ok_or_else(|| bad("density MLP"))?;
        let (rgb_mlp, rgb_dir) = Mlp::new(layout.rgb, &params[nd..nd + nr])
            .and_then(|m| m.split_last_inputs(16))
            .ok_or_else(|| bad("rgb MLP"))?;
        let grid_params = &params[nd + nr..nd + nr + layout.grid.n_params()];
        let storage = storage.unwrap_or(if half {
            TableStorage::F16
        } else {
            TableStorage::F32
        });
        let grid = match storage {
            TableStorage::F32 => HashGrid::from_f32(layout.grid, grid_params.to_vec()),
            TableStorage::F16 => {
                let h: Vec<f16> = grid_params.iter().map(|&v| f16::from_f32(v)).collect();
                HashGrid::new(layout.grid, &h, TableStorage::F16)
            }
        }
        .ok_or_else(|| bad("hash grid"))?;
        let cascades = read_cascades(&doc, snap)?;
        let half_size = 0.5 * aabb_scale.min(128.0);
        let (aabb_min, aabb_max) = (Vec3::splat(0.5 - half_size), Vec3::splat(0.5 + half_size));
        let outer = 0.5 * ((cascades.count() as f32) - 1.0).exp2();
        let mut lo = aabb_min.max(Vec3::splat(0.5 - outer));
        let mut hi = aabb_max.min(Vec3::splat(0.5 + outer));
        if let Some((rlo, rhi)) = render_aabb(&doc, snap)? {
            lo = lo.max(rlo);
            hi = hi.min(rhi);
        }
        let field = IngpField {
            summary: Summary {
                path: path.to_path_buf(),
                gzip,
                version,
                half,
                cutlass,
                n_params: params.len(),
                aabb_scale,
            },
            grid,
            density_mlp,
            sigma_mlp,
            rgb_mlp,
            rgb_dir,
            hdr,
            scale,
            offset,
            aabb_min,
            aabb_size: aabb_max - aabb_min,
            cascades,
            bounds: Aabb::new(Vec3::ZERO, Vec3::ZERO),
        };
        let bounds = if lo.cmplt(hi).all() {
            let (a, b) = (field.field_from_ngp(lo), field.field_from_ngp(hi));
            Aabb::new(a.min(b), a.max(b))
        } else {
            Aabb::new(Vec3::ZERO, Vec3::ZERO)
        };
        Ok(IngpField { bounds, ..field })
    }

    /// Instant-ngp coordinates of a field-space point.
    #[inline]
    fn ngp_from_field(&self, p: Vec3) -> Vec3 {
        let (s, o) = (self.scale, self.offset);
        Vec3::new(p.y * s + o.y, p.z * s + o.z, p.x * s + o.x)
    }

    /// Instant-ngp coordinates of a field-space point, in f64.
    pub(crate) fn ngp_from_field_f64(&self, p: DVec3) -> DVec3 {
        let (s, o) = (f64::from(self.scale), self.offset.as_dvec3());
        DVec3::new(p.y * s + o.y, p.z * s + o.z, p.x * s + o.x)
    }

    /// The dataset scale: instant-ngp units per field unit.
    pub(crate) fn ngp_scale(&self) -> f32 {
        self.scale
    }

    /// The snapshot's `aabb_scale`, which sets instant-ngp's cone angle.
    pub(crate) fn aabb_scale(&self) -> f32 {
        self.summary.aabb_scale
    }

    /// The occupancy cascades instant-ngp's marcher walks.
    pub(crate) fn cascades(&self) -> &Cascades {
        &self.cascades
    }

    /// The hash grid's unit-cube point of a field-space point.
    pub(crate) fn grid_point(&self, p: Vec3) -> Vec3 {
        self.unit_from_ngp(self.ngp_from_field(p))
    }

    /// The density network's outputs (`DENSITY_OUTPUTS` per point, the first the raw
    /// density) at the hash grid's unit-cube points `xs`, into `out`; `enc` is scratch.
    pub(crate) fn density_network(&self, xs: &[Vec3], enc: &mut Vec<f32>, out: &mut Vec<f32>) {
        self.density_outputs(&self.density_mlp, xs, enc, out)
    }

    /// The inverse of [`Self::ngp_from_field`].
    fn field_from_ngp(&self, q: Vec3) -> Vec3 {
        let (s, o) = (self.scale, self.offset);
        Vec3::new((q.z - o.x) / s, (q.x - o.y) / s, (q.y - o.z) / s)
    }

    /// The point of the hash grid's unit cube for an instant-ngp point.
    #[inline]
    fn unit_from_ngp(&self, q: Vec3) -> Vec3 {
        (q - self.aabb_min) / self.aabb_size
    }

    /// The unit-cube points `xs` of those of `points` in occupied cells, and their indices
    /// `idx`. Branch-free: the occupancy bits of a batch are scattered over megabytes, and
    /// a branch on each (taken about half the time) would stop the CPU from having several
    /// of those cache misses in flight at once.
    fn occupied_points(&self, points: &[Vec3], xs: &mut Vec<Vec3>, idx: &mut Vec<usize>) {
        xs.resize(points.len(), Vec3::ZERO);
        idx.resize(points.len(), 0);
        let mut kept = 0;
        for (i, p) in points.iter().enumerate() {
            let q = self.ngp_from_field(*p);
            xs[kept] = self.unit_from_ngp(q);
            idx[kept] = i;
            kept += usize::from(self.cascades.occupied_at(q));
        }
        xs.truncate(kept);
        idx.truncate(kept);
    }

    /// The outputs of `mlp` (the density MLP, whole or σ only) at `n` points (unit cube):
    /// `enc` and `out` are scratch.
    fn density_outputs(&self, mlp: &Mlp, xs: &[Vec3], enc: &mut Vec<f32>, out: &mut Vec<f32>) {
        enc.resize(xs.len() * self.grid.config().n_outputs(), 0.0);
        out.resize(xs.len() * mlp.config().n_outputs, 0.0);
        self.grid.encode(xs, enc);
        mlp.forward(enc, out);
    }

    /// A human-readable description: format, architecture, parameters, bounds, occupancy.
    pub fn describe(&self) -> String {
        let s = &self.summary;
        let g = self.grid.config();
        let (d, r) = (self.density_mlp.config(), self.rgb_mlp.config());
        let b = self.bounds;
        format!(
            "file: {}\n\
             format: instant-ngp NeRF snapshot ({}, version {}), parameters {} ({})\n\
             hash grid: {} levels x {} features, 2^{} entries, N_min {}, per-level scale {:.6}, tables {:?}\n\
             density MLP: {} -> {}x{} -> {} (exp)\n\
             rgb MLP: {}+16 SH -> {}x{} -> 3 ({}, output padding {})\n\
             aabb_scale {}, scale {}, offset [{}, {}, {}]\n\
             bounds (NeRF world): [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]\n\
             occupancy: {} cascades of 128^3, fill ratio {:.4}",
            s.path.display(),
            if s.gzip { "gzip msgpack" } else { "msgpack" },
            s.version,
            s.n_params,
            if s.half { "__half" } else { "float" },
            g.n_levels,
            g.n_features,
            g.log2_table_size,
            g.base_resolution,
            g.per_level_scale,
            self.grid.storage(),
            d.n_inputs,
            d.n_hidden_layers,
            d.width,
            d.n_outputs,
            DENSITY_OUTPUTS,
            r.n_hidden_layers,
            r.width,
            if self.hdr { "HDR exp, linear" } else { "sigmoid, sRGB-encoded" },
            if s.cutlass { 8 } else { 16 },
            s.aabb_scale,
            self.scale,
            self.offset.x,
            self.offset.y,
            self.offset.z,
            b.min.x,
            b.min.y,
            b.min.z,
            b.max.x,
            b.max.y,
            b.max.z,
            self.cascades.count(),
            self.cascades.fill_ratio(),
        )
    }
}

/// The most bytes instant-ngp's density grid holds: 128³ fp16 values for each of at most 8
/// cascades (`NERF_CASCADES`, reached at aabb_scale 128).
const MAX_DENSITY_GRID_BYTES: u64 = (cascades::GRID as u64).pow(3) * 8 * 2;
/// A binary this long is kept before the configuration that bounds it has been read.
const SMALL_BINARY: u64 = 1 << 20;
/// The longest text a snapshot holds (names, paths).
const MAX_STRING: u64 = 64 << 10;

/// The snapshot at `doc.path`, decoded with every binary bounded by what its field can hold
/// before a byte of it is read: the density grid by 128³ × 8 cascades in fp16, any other
/// binary (the parameters, an optimiser's moments) by the parameters of the network the
/// configuration describes in single precision. instant-ngp writes the configuration before
/// the snapshot; a file with its binaries first is decoded twice, the first time reading
/// past them, so that nothing longer than its bound is ever held.
fn read_bounded(doc: &Doc) -> Result<(Value, bool)> {
    let first = read_document(doc.path, &mut |p| judge(doc, p, p.top))?;
    if first.skipped.is_empty() {
        return Ok((first.top, first.gzip));
    }
    let Some(top) = first.top.as_map() else {
        return Err(doc.err("top level", "not a map of keys"));
    };
    for (at, len) in &first.skipped {
        if let Verdict::Refuse(why) = judge_with_config(doc, *len, top)? {
            return Err(doc.err(at, why));
        }
    }
    let second = read_document(doc.path, &mut |p| judge(doc, p, top))?;
    Ok((second.top, second.gzip))
}

/// What to do with a payload, given the top-level entries known (`top`).
fn judge(doc: &Doc, p: &Payload, top: &[(Value, Value)]) -> Verdict {
    match p.kind {
        PayloadKind::String if p.len > MAX_STRING => Verdict::Refuse(format!(
            "a string of {} bytes: no snapshot key holds text longer than {} KiB",
            p.len,
            MAX_STRING >> 10
        )),
        PayloadKind::String => Verdict::Keep,
        _ if p.at == "snapshot.density_grid_binary" => {
            if p.len > MAX_DENSITY_GRID_BYTES {
                Verdict::Refuse(format!(
                    "{} bytes, more than the density grid holds (128^3 cells x 8 cascades x 2                      bytes = {MAX_DENSITY_GRID_BYTES})",
                    p.len
                ))
            } else {
                Verdict::Keep
            }
        }
        _ if p.len <= SMALL_BINARY => Verdict::Keep,
        _ => {
            let config = ["encoding", "network", "rgb_network"];
            let known = config
                .iter()
                .all(|k| top.iter().any(|(key, _)| key.as_str() == Some(*k)));
            if !known {
                return Verdict::Skip;
            }
            // A configuration that does not load is reported as such after decoding.
            judge_with_config(doc, p.len, top).unwrap_or(Verdict::Skip)
        }
    }
}

/// Whether a binary of `len` bytes fits the parameters of the network `top` configures.
fn judge_with_config(doc: &Doc, len: u64, top: &[(Value, Value)]) -> Result<Verdict> {
    let config: Vec<(Value, Value)> = top
        .iter()
        .filter(|(k, _)| {
            matches!(
                k.as_str(),
                Some("encoding" | "network" | "rgb_network" | "dir_encoding")
            )
        })
        .cloned()
        .collect();
    let layout = read_layout(doc, &Value::Map(config), 1.0)?;
    let most = layout.density.n_params()
        + MlpConfig {
            output_alignment: 16,
            ..layout.rgb
        }
        .n_params()
        + layout.grid.n_params();
    let bound = most as u64 * 4;
    Ok(if len > bound {
        Verdict::Refuse(format!(
            "{len} bytes, more than the network the snapshot configures can hold ({most} \
             parameters x 4 bytes = {bound})"
        ))
    } else {
        Verdict::Keep
    })
}

/// Whether the parameters are `__half` and whether the rgb MLP's output is padded to 8
/// (old CutlassMLP), from `params_type`, `n_params` and the byte count.
fn params_encoding(
    doc: &Doc,
    snap: &Value,
    layout: &Layout,
    n_bytes: usize,
) -> Result<(bool, bool)> {
    let total = |align: usize| {
        layout.density.n_params()
            + MlpConfig {
                output_alignment: align,
                ..layout.rgb
            }
            .n_params()
            + layout.grid.n_params()
    };
    let (t16, t8) = (total(16), total(8));
    let n_params = match doc.find(snap, "n_params") {
        Some(v) => Some(
            v.as_u64()
                .ok_or_else(|| doc.err("snapshot.n_params", "expected a count"))?
                as usize,
        ),
        None => None,
    };
    let half = match doc.find(snap, "params_type").and_then(Value::as_str) {
        Some("__half") => Some(true),
        Some("float") => Some(false),
        Some(other) => {
            return Err(doc.err("snapshot.params_type", format!("unknown type '{other}'")))
        }
        None => None,
    };
    for (count, cutlass) in [(t16, false), (t8, true)] {
        if n_params.is_some_and(|n| n != count) {
            continue;
        }
        for h in [true, false] {
            if half.is_some_and(|x| x != h) {
                continue;
            }
            if n_bytes == count * if h { 2 } else { 4 } {
                return Ok((h, cutlass));
            }
        }
    }
    let declared = match n_params {
        Some(n) => format!("; n_params says {n}"),
        None => String::new(),
    };
    Err(doc.err(
        "snapshot.params_binary",
        format!(
            "{n_bytes} bytes do not hold the network's parameters ({t16}, or {t8} with \
             CutlassMLP padding{declared}): truncated or a different architecture"
        ),
    ))
}

/// The cascaded occupancy grid from `density_grid_binary` (fp16, 128³ per cascade).
fn read_cascades(doc: &Doc, snap: &Value) -> Result<Cascades> {
    let at = "snapshot.density_grid_binary";
    if let Some(v) = doc.find(snap, "density_grid_size") {
        if v.as_u64() != Some(cascades::GRID as u64) {
            return Err(doc.err(
                "snapshot.density_grid_size",
                format!("expected 128, found {v}"),
            ));
        }
    }
    let bytes = doc.bytes(doc.get(snap, "snapshot", "density_grid_binary")?, at)?;
    if bytes.len() % 2 != 0 {
        return Err(doc.err(at, "odd byte count for fp16 values"));
    }
    let values: Vec<f32> = bytes
        .chunks_exact(2)
        .map(|b| f16::from_le_bytes([b[0], b[1]]).to_f32())
        .collect();
    // Negative values mark cells no camera saw and +∞ a density past fp16's range; NaN is
    // neither, and would read as empty.
    if let Some(first) = values.iter().position(|v| v.is_nan()) {
        let count = values.iter().filter(|v| v.is_nan()).count();
        return Err(doc.err(
            at,
            format!(
                "{count} of {} density grid values are NaN (the first at index {first}): the \
                 training diverged before this was saved",
                values.len()
            ),
        ));
    }
    Cascades::from_densities(&values).ok_or_else(|| {
        doc.err(
            at,
            format!(
                "{} values are not a whole number of 128^3 cascades",
                values.len()
            ),
        )
    })
}

/// The render box (instant-ngp coordinates) when it is axis-aligned; `None` when absent or
/// rotated (then the training box bounds the field).
fn render_aabb(doc: &Doc, snap: &Value) -> Result<Option<(Vec3, Vec3)>> {
    let Some(b) = doc.find(snap, "render_aabb") else {
        return Ok(None);
    };
    if let Some(m) = doc.find(snap, "render_aabb_to_local") {
        let number = |x: &Value| {
            x.as_f64()
                .or_else(|| x.as_i64().map(|i| i as f64))
                .unwrap_or(f64::NAN)
        };
        let flat: Vec<f64> = m
            .as_array()
            .into_iter()
            .flatten()
            .flat_map(|r| match r.as_array() {
                Some(a) => a.iter().map(number).collect(),
                None => vec![number(r)],
            })
            .collect();
        // A matrix that is not a rotation cannot place the box: refused, not ignored.
        let at = "snapshot.render_aabb_to_local";
        if flat.len() != 9 || flat.iter().any(|v| !v.is_finite()) {
            return Err(doc.err(at, "expected a 3x3 matrix of finite numbers"));
        }
        let mut cols = [0.0; 9];
        cols.copy_from_slice(&flat);
        let det = glam::DMat3::from_cols_array(&cols).determinant();
        if det.is_nan() || det.abs() <= 1e-6 {
            return Err(doc.err(
                at,
                format!(
                    "singular (determinant {}): the render box's rotation must be invertible",
                    crate::error::number(det)
                ),
            ));
        }
        let identity = flat
            .iter()
            .enumerate()
            .all(|(i, v)| (v - if i % 4 == 0 { 1.0 } else { 0.0 }).abs() < 1e-6);
        if !identity {
            return Ok(None);
        }
    }
    let lo = doc.vec3(
        doc.get(b, "snapshot.render_aabb", "min")?,
        "snapshot.render_aabb.min",
    )?;
    let hi = doc.vec3(
        doc.get(b, "snapshot.render_aabb", "max")?,
        "snapshot.render_aabb.max",
    )?;
    if let Some(axis) = (0..3).find(|&a| lo[a] > hi[a]) {
        return Err(doc.err(
            "snapshot.render_aabb",
            format!(
                "inverted: min {} is above max {} on {}; a box with min <= max on every axis \
                 was expected",
                lo[axis],
                hi[axis],
                ["x", "y", "z"][axis]
            ),
        ));
    }
    Ok(Some((lo, hi)))
}

/// Scratch of [`IngpField::colour`].
#[derive(Default)]
pub(crate) struct ColourScratch {
    /// The colour network's first-layer starts, one row per run of equal directions, and
    /// each sample's run.
    starts: Vec<f32>,
    row_of: Vec<u32>,
    colour: Vec<f32>,
}

impl IngpField {
    /// Linear RGB from the density network's outputs (16 per point) and the view
    /// directions: the colour network on [outputs, SH₄(d)], then sigmoid and sRGB → linear
    /// (or instant-ngp's HDR exp). The SH part of the network's first layer is summed once
    /// per run of consecutive equal directions (a ray's samples; 1 024 of a sample's 6 400
    /// multiply-adds), each sample's layer starting from its run's sums.
    pub(crate) fn colour(
        &self,
        outputs: &[f32],
        dirs: &[Vec3],
        dst: &mut [Vec3],
        s: &mut ColourScratch,
    ) {
        self.rgb_dir.starts_per_run(
            dirs,
            |d| sh4(Vec3::new(d.y, d.z, d.x)),
            &mut s.starts,
            &mut s.row_of,
        );
        s.colour.resize(dirs.len() * 3, 0.0);
        let features = &outputs[..dirs.len() * DENSITY_OUTPUTS];
        self.rgb_mlp
            .forward_from(features, &s.starts, &s.row_of, &mut s.colour);
        for (c, v) in dst.iter_mut().zip(s.colour.chunks_exact(3)) {
            *c = Vec3::from_array([v[0], v[1], v[2]].map(|x| {
                if self.hdr {
                    x.clamp(-10.0, 10.0).exp()
                } else {
                    1.0 / (1.0 + (-x).exp())
                }
            }));
        }
    }
}

impl Field for IngpField {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The box of the occupancy mask's cells (widened by a cell), within the bounds.
    fn occupied_bounds(&self) -> Aabb {
        let Some((lo, hi)) = self.cascades.occupied_extent() else {
            return self.bounds;
        };
        let (a, b) = (self.field_from_ngp(lo), self.field_from_ngp(hi));
        let within = &self.bounds;
        Aabb::new(a.min(b).max(within.min), a.max(b).min(within.max))
    }

    fn color_space(&self) -> ColorSpace {
        if self.hdr {
            ColorSpace::Linear
        } else {
            ColorSpace::Srgb
        }
    }

    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        let (mut xs, mut idx) = (Vec::with_capacity(CHUNK), Vec::with_capacity(CHUNK));
        let (mut enc, mut out) = (Vec::new(), Vec::new());
        for (pts, sig) in points.chunks(CHUNK).zip(sigma.chunks_mut(CHUNK)) {
            sig.fill(0.0);
            self.occupied_points(pts, &mut xs, &mut idx);
            self.density_outputs(&self.sigma_mlp, &xs, &mut enc, &mut out);
            for (&i, &raw) in idx.iter().zip(out.iter()) {
                sig[i] = self.scale * exp_density(raw);
            }
        }
    }

    fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]) {
        let mut xs = Vec::with_capacity(CHUNK);
        let (mut enc, mut out) = (Vec::new(), Vec::new());
        let mut scratch = ColourScratch::default();
        let parts = points.chunks(CHUNK).zip(dirs.chunks(CHUNK));
        for ((pts, ds), dst) in parts.zip(rgb.chunks_mut(CHUNK)) {
            xs.clear();
            xs.extend(
                pts.iter()
                    .map(|p| self.unit_from_ngp(self.ngp_from_field(*p))),
            );
            self.density_outputs(&self.density_mlp, &xs, &mut enc, &mut out);
            self.colour(&out, ds, dst, &mut scratch);
        }
    }

    /// The density network's 16 outputs: σ is the first, and the colour network takes all.
    fn feature_count(&self) -> usize {
        DENSITY_OUTPUTS
    }

    fn density_with_features(&self, points: &[Vec3], sigma: &mut [f32], features: &mut [f32]) {
        let (mut xs, mut idx) = (Vec::with_capacity(CHUNK), Vec::with_capacity(CHUNK));
        let (mut enc, mut out) = (Vec::new(), Vec::new());
        let chunks = points
            .chunks(CHUNK)
            .zip(sigma.chunks_mut(CHUNK))
            .zip(features.chunks_mut(CHUNK * DENSITY_OUTPUTS));
        for ((pts, sig), feat) in chunks {
            sig.fill(0.0);
            feat.fill(0.0);
            self.occupied_points(pts, &mut xs, &mut idx);
            self.density_outputs(&self.density_mlp, &xs, &mut enc, &mut out);
            for (&i, o) in idx.iter().zip(out.chunks_exact(DENSITY_OUTPUTS)) {
                sig[i] = self.scale * exp_density(o[0]);
                feat[i * DENSITY_OUTPUTS..(i + 1) * DENSITY_OUTPUTS].copy_from_slice(o);
            }
        }
    }

    fn radiance_with_features(
        &self,
        _points: &[Vec3],
        dirs: &[Vec3],
        features: &[f32],
        rgb: &mut [Vec3],
    ) {
        let mut scratch = ColourScratch::default();
        let parts = features
            .chunks(CHUNK * DENSITY_OUTPUTS)
            .zip(dirs.chunks(CHUNK));
        for ((feat, ds), dst) in parts.zip(rgb.chunks_mut(CHUNK)) {
            self.colour(feat, ds, dst, &mut scratch);
        }
    }

    /// Instant-ngp's smallest step, `√3/1024` of its unit, in field units.
    fn feature_size(&self) -> f32 {
        3f32.sqrt() / 1024.0 / self.scale
    }

    /// The finest hash-grid cell, `1/s_{L−1}` of the training box's side (instant-ngp
    /// units), in field units (`/ scale`). The training box is a cube, so the cell is too.
    fn smooth_length(&self) -> f32 {
        self.aabb_size.min_element() / self.grid.config().finest_scale().max(1.0) / self.scale
    }

    fn may_be_occupied(&self, region: &Aabb) -> bool {
        if region.is_empty() {
            return false;
        }
        let (a, b) = (
            self.ngp_from_field(region.min),
            self.ngp_from_field(region.max),
        );
        self.cascades.may_be_occupied(a.min(b), a.max(b))
    }

    /// Mask segments: the occupancy cascades are the density's own mask.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            mask_segments: true,
            ..Capabilities::default()
        }
    }

    /// The cells of the cascades the ray crosses, walked in instant-ngp coordinates
    /// (`q = ngp_from_field(origin) + t·s·dir`, the axes cycled): the density is zero exactly
    /// outside the occupied ones, and the networks' smooth interpolant inside them.
    fn mask_segments(&self, origin: Vec3, dir: Vec3, t0: f64, t1: f64, out: &mut Vec<[f64; 2]>) {
        let v = Vec3::new(dir.y, dir.z, dir.x) * self.scale;
        self.cascades
            .segments(self.ngp_from_field(origin), v, t0, t1, out);
    }

    /// The density's own mask: a point outside every occupied cell (of the smallest
    /// cascade holding it) is never given to the networks, so its density is zero. NaN
    /// points and points beyond the largest cascade lie in no cell.
    fn certainly_empty(&self, points: &[Vec3], empty: &mut [bool]) {
        for (p, e) in points.iter().zip(empty) {
            *e = !self.cascades.occupied_at(self.ngp_from_field(*p));
        }
    }
}
