//! Synthetic instant-ngp snapshots with seeded weights, written from the format's facts
//! (docs/src/architecture.md): the benchmark's trained-field scenes and the loader's test fixtures come from
//! this one generator.
//!
//! A [`SnapshotSpec`] names the architecture (levels × features, table size, fp16 or f32,
//! CutlassMLP padding, HDR), the dataset transform, how the weights are drawn
//! ([`Weights`]) and the occupancy: seeded noise below instant-ngp's threshold, or solid
//! [`Ball`]s (1 inside, 0 outside, in every cascade). [`snapshot_bytes`] gives the msgpack
//! document, [`file_bytes`] frames it as the spec says, [`write_snapshot`] writes it.
//!
//! ```
//! use nerfx_testkit::bench::snapshot::{snapshot_bytes, SnapshotSpec};
//! let spec = SnapshotSpec { log2_table_size: 10, n_cascades: 1, ..SnapshotSpec::small_8x4() };
//! assert_eq!(snapshot_bytes(&spec).unwrap(), snapshot_bytes(&spec).unwrap());
//! ```

use std::io::Write;
use std::path::{Path, PathBuf};

use half::f16;
use rmpv::Value;

use nerfx_core::error::{Error, Result};
use nerfx_core::SplitMix64;

/// Cells per side of each occupancy cascade.
const GRID: usize = 128;

/// How the flat parameters are drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Weights {
    /// MLP weights uniform in `±√(6/fan_in)` (a trained network's scale), hash-grid entries
    /// uniform in `±1`: the density MLP's first output varies strongly in space.
    FanIn,
    /// Every parameter uniform with this standard deviation (in `±√3·std`): with a small
    /// one the density MLP's output stays near 0, so `σ ≈ e⁰ = 1` per instant-ngp unit
    /// wherever the occupancy allows — a smooth fog.
    Uniform {
        /// The standard deviation.
        std: f32,
    },
}

/// A solid ball of occupancy, in instant-ngp coordinates (the unit cube is cascade 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    /// Centre.
    pub centre: [f32; 3],
    /// Radius.
    pub radius: f32,
}

/// What to write.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotSpec {
    /// Hash-grid levels.
    pub n_levels: u32,
    /// Features per level.
    pub n_features: u32,
    /// log2 of the largest table's entries.
    pub log2_table_size: u32,
    /// `N_min`.
    pub base_resolution: u32,
    /// `nerf.aabb_scale`.
    pub aabb_scale: u32,
    /// Occupancy cascades.
    pub n_cascades: usize,
    /// Parameters as `__half` (else `float`).
    pub half: bool,
    /// Old CutlassMLP: rgb output padded to 8 (with `otype` "CutlassMLP").
    pub cutlass: bool,
    /// `nerf.dataset.is_hdr`.
    pub hdr: bool,
    /// `nerf.dataset.scale`.
    pub scale: f32,
    /// `nerf.dataset.offset`.
    pub offset: [f32; 3],
    /// Gzip-framed (`.ingp`), else raw msgpack.
    pub gzip: bool,
    /// Write `params_type` and `n_params` (older files have neither).
    pub typed: bool,
    /// The generator's seed.
    pub seed: u64,
    /// How the parameters are drawn.
    pub weights: Weights,
    /// Empty: every cascade's cells hold seeded values in `[0, 0.02)`. Else the cells whose
    /// centre lies in a ball hold 1 and all others 0 (only the balls are occupied: the
    /// threshold is `min(0.01, mean)`).
    pub occupancy: Vec<Ball>,
    /// When set, the density MLP's σ row (the first 64 weights of its last layer,
    /// row-major `[out][in]`) becomes `|w|·gain`: the hidden activations being ReLUs (≥ 0),
    /// the log-density is then ≥ 0 and grows with the gain (a dense, surface-like blob),
    /// while the other 15 outputs (the colour network's geometry input) stay as drawn.
    pub sigma_gain: Option<f32>,
}

impl SnapshotSpec {
    /// Current default architecture, small table: 8 levels × 4 features, fp16, gzip.
    pub fn small_8x4() -> Self {
        SnapshotSpec {
            n_levels: 8,
            n_features: 4,
            log2_table_size: 12,
            base_resolution: 16,
            aabb_scale: 2,
            n_cascades: 2,
            half: true,
            cutlass: false,
            hdr: false,
            scale: 0.33,
            offset: [0.5, 0.5, 0.5],
            gzip: true,
            typed: true,
            seed: 1,
            weights: Weights::FanIn,
            occupancy: Vec::new(),
            sigma_gain: None,
        }
    }

    /// Older architecture: 16 levels × 2, float params, raw msgpack, CutlassMLP padding,
    /// HDR, a non-default dataset transform and no type keys.
    pub fn old_16x2() -> Self {
        SnapshotSpec {
            n_levels: 16,
            n_features: 2,
            log2_table_size: 11,
            base_resolution: 16,
            aabb_scale: 4,
            n_cascades: 3,
            half: false,
            cutlass: true,
            hdr: true,
            scale: 0.5,
            offset: [0.4, 0.6, 0.45],
            gzip: false,
            typed: false,
            seed: 2,
            ..Self::small_8x4()
        }
    }

    /// The benchmark's smooth trained fog: 16 × 2 levels, 2^19 rows, fp16, every weight of
    /// standard deviation 0.05, occupied in a ball of radius 0.35 at the unit cube's centre
    /// (aabb_scale 1, one cascade). With the default dataset transform the ball is centred
    /// on the NeRF frame's origin, radius 0.35/0.33 ≈ 1.06, σ ≈ 0.33 per NeRF unit.
    pub fn fog_sphere() -> Self {
        SnapshotSpec {
            n_levels: 16,
            n_features: 2,
            log2_table_size: 19,
            aabb_scale: 1,
            n_cascades: 1,
            seed: 3,
            weights: Weights::Uniform { std: 0.05 },
            occupancy: vec![Ball {
                centre: [0.5; 3],
                radius: 0.35,
            }],
            ..Self::small_8x4()
        }
    }

    /// The benchmark's dense trained blob: 8 × 4 levels, 2^19 rows, fp16, three overlapping
    /// balls occupied, σ's row scaled by 4 so rays terminate inside them.
    pub fn dense_blob() -> Self {
        SnapshotSpec {
            log2_table_size: 19,
            occupancy: vec![
                Ball {
                    centre: [0.5, 0.5, 0.5],
                    radius: 0.25,
                },
                Ball {
                    centre: [0.7, 0.55, 0.42],
                    radius: 0.16,
                },
                Ball {
                    centre: [0.33, 0.45, 0.62],
                    radius: 0.13,
                },
            ],
            sigma_gain: Some(4.0),
            ..Self::small_8x4()
        }
    }

    /// The file extension instant-ngp gives such a file.
    pub fn extension(&self) -> &'static str {
        if self.gzip {
            "ingp"
        } else {
            "msgpack"
        }
    }

    /// Inputs of the density MLP: the grid's outputs padded to 16.
    fn mlp_inputs(&self) -> usize {
        ((self.n_levels * self.n_features) as usize).div_ceil(16) * 16
    }
}

/// Hash-grid entries per level, from the facts: scale `2^(l·log2 b)·N_min − 1`,
/// resolution `⌈scale⌉ + 1`, `min(next multiple of 8 of res³, 2^log2T)`.
fn grid_entries(s: &SnapshotSpec) -> usize {
    // Each f32 function correctly rounded (through f64), as the loader does.
    let ln = ((2048.0 * s.aabb_scale as f32 / s.base_resolution as f32) as f64).ln() as f32;
    let b = ((ln / (s.n_levels - 1) as f32) as f64).exp() as f32;
    let log2_b = (b as f64).log2() as f32;
    (0..s.n_levels)
        .map(|l| {
            let e = ((l as f32 * log2_b) as f64).exp2() as f32;
            let scale = e * s.base_resolution as f32 - 1.0;
            let r = scale.ceil() as usize + 1;
            (r * r * r)
                .div_ceil(8)
                .saturating_mul(8)
                .min(1 << s.log2_table_size)
        })
        .sum()
}

/// Parameter counts: (density MLP, rgb MLP, grid).
pub fn param_counts(s: &SnapshotSpec) -> (usize, usize, usize) {
    let density = 64 * s.mlp_inputs() + 16 * 64;
    let rgb = 64 * 32 + 64 * 64 + if s.cutlass { 8 } else { 16 } * 64;
    (density, rgb, grid_entries(s) * s.n_features as usize)
}

/// The flat parameters: density MLP | rgb MLP | grid, drawn as `s.weights` says.
fn params(s: &SnapshotSpec, rng: &mut SplitMix64) -> Vec<f32> {
    let (nd, nr, ng) = param_counts(s);
    let n_in = s.mlp_inputs();
    let mut draw = |n: usize, amplitude: &dyn Fn(usize) -> f32| -> Vec<f32> {
        (0..n)
            .map(|i| rng.range(-1.0, 1.0) * amplitude(i))
            .collect()
    };
    let mut params = Vec::with_capacity(nd + nr + ng);
    match s.weights {
        Weights::FanIn => {
            params.extend(draw(64 * n_in, &|_| (6.0 / n_in as f32).sqrt()));
            params.extend(draw(16 * 64, &|_| (6.0f32 / 64.0).sqrt()));
            params.extend(draw(nr, &|i| {
                let fan_in = if i < 64 * 32 { 32.0 } else { 64.0f32 };
                (6.0 / fan_in).sqrt()
            }));
            params.extend(draw(ng, &|_| 1.0));
        }
        Weights::Uniform { std } => {
            params.extend(draw(nd + nr + ng, &|_| 3f32.sqrt() * std));
        }
    }
    if let Some(gain) = s.sigma_gain {
        for w in &mut params[64 * n_in..64 * n_in + 64] {
            // The stored weight, as the file will hold it.
            let stored = if s.half {
                f16::from_f32(*w).to_f32()
            } else {
                *w
            };
            *w = stored.abs() * gain;
        }
    }
    params
}

/// The density grid (fp16, Morton order per cascade) and the occupied fraction of cascade 0.
fn density_grid(s: &SnapshotSpec, rng: &mut SplitMix64) -> (Vec<u8>, f64) {
    let n3 = GRID * GRID * GRID;
    if s.occupancy.is_empty() {
        let grid = (0..n3 * s.n_cascades)
            .flat_map(|_| f16::from_f32(rng.range(0.0, 0.02)).to_le_bytes())
            .collect();
        return (grid, f64::NAN);
    }
    let mut grid = Vec::with_capacity(2 * n3 * s.n_cascades);
    let mut cascade0 = 0usize;
    for c in 0..s.n_cascades {
        let width = (c as f32).exp2();
        for m in 0..n3 {
            // Morton index: bit 3k + a is bit k of axis a (x, y, z).
            let axis = |a: usize| (0..7).fold(0, |acc, k| acc | ((m >> (3 * k + a)) & 1) << k);
            let q = [0, 1, 2].map(|a| 0.5 + width * ((axis(a) as f32 + 0.5) / GRID as f32 - 0.5));
            let inside = s.occupancy.iter().any(|b| {
                (0..3).map(|a| (q[a] - b.centre[a]).powi(2)).sum::<f32>() < b.radius * b.radius
            });
            cascade0 += usize::from(inside && c == 0);
            grid.extend(f16::from_f32(if inside { 1.0 } else { 0.0 }).to_le_bytes());
        }
    }
    (grid, cascade0 as f64 / n3 as f64)
}

/// The fraction of cascade 0's cells that `s.occupancy` occupies (NaN without balls: the
/// seeded noise's occupancy is instant-ngp's threshold's business).
pub fn occupied_fraction(s: &SnapshotSpec) -> f64 {
    if s.occupancy.is_empty() {
        return f64::NAN;
    }
    density_grid(
        &SnapshotSpec {
            n_cascades: 1,
            ..s.clone()
        },
        &mut SplitMix64::new(0),
    )
    .1
}

fn kv(k: &str, v: Value) -> (Value, Value) {
    (Value::from(k), v)
}

/// The snapshot's msgpack bytes (before any gzip framing).
pub fn snapshot_bytes(s: &SnapshotSpec) -> Result<Vec<u8>> {
    let mut rng = SplitMix64::new(s.seed);
    let params = params(s, &mut rng);
    let params_binary: Vec<u8> = if s.half {
        params
            .iter()
            .flat_map(|&v| f16::from_f32(v).to_le_bytes())
            .collect()
    } else {
        params.iter().flat_map(|&v| v.to_le_bytes()).collect()
    };
    let (grid, _) = density_grid(s, &mut rng);
    let half = 0.5 * s.aabb_scale.min(128) as f32;
    let f = |x: f32| Value::from(x as f64);
    let otype = if s.cutlass {
        "CutlassMLP"
    } else {
        "FullyFusedMLP"
    };
    let mut snapshot = vec![
        kv("version", Value::from(1)),
        kv("mode", Value::from("nerf")),
        kv("params_binary", Value::Binary(params_binary)),
        kv("density_grid_size", Value::from(GRID as u64)),
        kv("density_grid_binary", Value::Binary(grid)),
        kv(
            "render_aabb",
            Value::Map(vec![
                kv("min", Value::Array(vec![f(0.5 - half); 3])),
                kv("max", Value::Array(vec![f(0.5 + half); 3])),
            ]),
        ),
        kv(
            "nerf",
            Value::Map(vec![
                kv("aabb_scale", Value::from(s.aabb_scale)),
                kv(
                    "dataset",
                    Value::Map(vec![
                        kv("scale", f(s.scale)),
                        kv(
                            "offset",
                            Value::Array(s.offset.iter().map(|&o| f(o)).collect()),
                        ),
                        kv("is_hdr", Value::from(s.hdr)),
                    ]),
                ),
            ]),
        ),
    ];
    if s.typed {
        snapshot.push(kv("n_params", Value::from(params.len() as u64)));
        snapshot.push(kv(
            "params_type",
            Value::from(if s.half { "__half" } else { "float" }),
        ));
    }
    let net = |layers: u32| {
        Value::Map(vec![
            kv("otype", Value::from(otype)),
            kv("activation", Value::from("ReLU")),
            kv("output_activation", Value::from("None")),
            kv("n_neurons", Value::from(64)),
            kv("n_hidden_layers", Value::from(layers)),
        ])
    };
    let top = Value::Map(vec![
        kv(
            "encoding",
            Value::Map(vec![
                kv("otype", Value::from("HashGrid")),
                kv("n_levels", Value::from(s.n_levels)),
                kv("n_features_per_level", Value::from(s.n_features)),
                kv("log2_hashmap_size", Value::from(s.log2_table_size)),
                kv("base_resolution", Value::from(s.base_resolution)),
            ]),
        ),
        kv("network", net(1)),
        kv("rgb_network", net(2)),
        kv(
            "dir_encoding",
            Value::Map(vec![
                kv("otype", Value::from("SphericalHarmonics")),
                kv("degree", Value::from(4)),
            ]),
        ),
        kv("snapshot", Value::Map(snapshot)),
    ]);
    let mut out = Vec::new();
    rmpv::encode::write_value(&mut out, &top)
        .map_err(|e| Error::invalid("synthetic snapshot", e.to_string()))?;
    Ok(out)
}

/// The file's bytes: msgpack, gzip-framed when `s.gzip`.
pub fn file_bytes(s: &SnapshotSpec) -> Result<Vec<u8>> {
    let raw = snapshot_bytes(s)?;
    if !s.gzip {
        return Ok(raw);
    }
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    let framed = enc.write_all(&raw).and_then(|()| enc.finish());
    framed.map_err(|e| Error::invalid("synthetic snapshot", e.to_string()))
}

/// Writes the snapshot of `s` into `dir` as `name.ingp` (or `.msgpack`); returns its path.
pub fn write_snapshot(dir: &Path, name: &str, s: &SnapshotSpec) -> Result<PathBuf> {
    let path = dir.join(format!("{name}.{}", s.extension()));
    nerfx_core::write_file(&path, &file_bytes(s)?)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn balls_set_the_occupied_fraction_and_uniform_weights_their_spread() {
        let spec = SnapshotSpec {
            log2_table_size: 10,
            ..SnapshotSpec::fog_sphere()
        };
        // A ball of radius 0.35 fills 4/3·π·0.35³ ≈ 0.1796 of the unit cube.
        let fill = occupied_fraction(&spec);
        assert!((fill - 0.1796).abs() < 2e-3, "{fill}");
        let p = params(&spec, &mut SplitMix64::new(spec.seed));
        let std = (p.iter().map(|&w| f64::from(w).powi(2)).sum::<f64>() / p.len() as f64).sqrt();
        assert!((std - 0.05).abs() < 2e-3, "{std}");
        let gained = params(&SnapshotSpec::dense_blob(), &mut SplitMix64::new(1));
        let n_in = SnapshotSpec::dense_blob().mlp_inputs();
        assert!(gained[64 * n_in..64 * n_in + 64].iter().all(|&w| w >= 0.0));
    }
}
