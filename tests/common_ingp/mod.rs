//! A writer of small instant-ngp snapshots with seeded random weights, written from the
//! format facts (DESIGN §4), for the loader's tests and the NumPy cross-check.

use std::io::Write;
use std::path::{Path, PathBuf};

use half::f16;
use rmpv::Value;
// The tests' one generator, through the shared harness (which every crate using this
// writer declares as `mod common_fields`).
pub use super::common_fields::SplitMix64;

/// What to write.
#[derive(Clone, Debug)]
pub struct Spec {
    pub n_levels: u32,
    pub n_features: u32,
    pub log2_table_size: u32,
    pub base_resolution: u32,
    pub aabb_scale: u32,
    pub n_cascades: usize,
    pub half: bool,
    /// Old CutlassMLP: rgb output padded to 8 (with `otype` "CutlassMLP").
    pub cutlass: bool,
    pub hdr: bool,
    pub scale: f32,
    pub offset: [f32; 3],
    pub gzip: bool,
    /// Write `params_type` and `n_params` (older files have neither).
    pub typed: bool,
    pub seed: u64,
}

impl Spec {
    /// Current default architecture, small table: 8 levels × 4 features, fp16, gzip.
    pub fn small_8x4() -> Self {
        Spec {
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
        }
    }

    /// Older architecture: 16 levels × 2, float params, raw msgpack, CutlassMLP padding,
    /// HDR, a non-default dataset transform and no type keys.
    pub fn old_16x2() -> Self {
        Spec {
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
        }
    }
}

/// Hash-grid entries per level, from the facts: scale `2^(l·log2 b)·N_min − 1`,
/// resolution `⌈scale⌉ + 1`, `min(next multiple of 8 of res³, 2^log2T)`.
fn grid_entries(s: &Spec) -> usize {
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
pub fn param_counts(s: &Spec) -> (usize, usize, usize) {
    let n_in = ((s.n_levels * s.n_features) as usize).div_ceil(16) * 16;
    let density = 64 * n_in + 16 * 64;
    let rgb = 64 * 32 + 64 * 64 + if s.cutlass { 8 } else { 16 } * 64;
    (density, rgb, grid_entries(s) * s.n_features as usize)
}

fn kv(k: &str, v: Value) -> (Value, Value) {
    (Value::from(k), v)
}

/// The snapshot's msgpack bytes (before any gzip framing).
pub fn snapshot_bytes(s: &Spec) -> Vec<u8> {
    let mut rng = SplitMix64::new(s.seed);
    let (nd, nr, ng) = param_counts(s);
    let n_in = ((s.n_levels * s.n_features) as usize).div_ceil(16) * 16;
    let mut params = Vec::with_capacity(nd + nr + ng);
    // Weights scaled like a trained network's (±√(6/fan_in)), grid entries ±1.
    params.extend((0..64 * n_in).map(|_| rng.range(-1.0, 1.0) * (6.0 / n_in as f32).sqrt()));
    params.extend((0..16 * 64).map(|_| rng.range(-1.0, 1.0) * (6.0f32 / 64.0).sqrt()));
    params.extend((0..nr).map(|i| {
        let fan_in = if i < 64 * 32 { 32.0 } else { 64.0f32 };
        rng.range(-1.0, 1.0) * (6.0 / fan_in).sqrt()
    }));
    params.extend((0..ng).map(|_| rng.range(-1.0, 1.0)));
    let params_binary: Vec<u8> = if s.half {
        params
            .iter()
            .flat_map(|&v| f16::from_f32(v).to_le_bytes())
            .collect()
    } else {
        params.iter().flat_map(|&v| v.to_le_bytes()).collect()
    };
    let n3 = 128 * 128 * 128;
    let grid: Vec<u8> = (0..n3 * s.n_cascades)
        .flat_map(|_| f16::from_f32(rng.range(0.0, 0.02)).to_le_bytes())
        .collect();
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
        kv("density_grid_size", Value::from(128)),
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
    rmpv::encode::write_value(&mut out, &top).unwrap();
    out
}

/// The file's bytes: msgpack, gzip-framed when `s.gzip`.
pub fn file_bytes(s: &Spec) -> Vec<u8> {
    framed(s, snapshot_bytes(s))
}

/// `raw` msgpack, gzip-framed when `s.gzip`.
fn framed(s: &Spec, raw: Vec<u8>) -> Vec<u8> {
    if !s.gzip {
        return raw;
    }
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(&raw).unwrap();
    enc.finish().unwrap()
}

/// A fresh scratch folder for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-ingp-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes the snapshot of `s` into `dir`; returns its path.
pub fn write_snapshot(dir: &Path, name: &str, s: &Spec) -> PathBuf {
    let ext = if s.gzip { "ingp" } else { "msgpack" };
    let path = dir.join(format!("{name}.{ext}"));
    std::fs::write(&path, file_bytes(s)).unwrap();
    path
}

/// A solid ball in instant-ngp coordinates.
pub struct Ball {
    pub centre: [f32; 3],
    pub radius: f32,
}

/// Writes the snapshot of `s` made surface-like: the density grid of every cascade is 1 in
/// the cells whose centre lies in one of `balls` and 0 elsewhere (so only the blob is
/// occupied: the threshold is `min(0.01, mean)`), and the density MLP's σ row (the first
/// 64 weights of its last layer, row-major `[out][in]`) is replaced by `|w|·gain`. The hidden
/// activations being ReLUs (≥ 0), the log-density `out₀ = Σ gain·|w_j|·h_j` is then ≥ 0 and
/// grows with `gain`, while the other 15 outputs (the colour network's geometry input) stay
/// as written. Returns the path and the occupied fraction of cascade 0.
pub fn write_blob_snapshot(
    dir: &Path,
    name: &str,
    s: &Spec,
    balls: &[Ball],
    gain: f32,
) -> (PathBuf, f64) {
    let raw = snapshot_bytes(s);
    let mut top = rmpv::decode::read_value(&mut &raw[..]).unwrap();
    let n_in = ((s.n_levels * s.n_features) as usize).div_ceil(16) * 16;
    let sigma_row = 64 * n_in..64 * n_in + 64;
    let n3 = 128 * 128 * 128;
    let mut cascade0 = 0usize;
    let Value::Map(entries) = &mut top else {
        panic!("top level is not a map")
    };
    let (_, Value::Map(snap)) = entries
        .iter_mut()
        .find(|(k, _)| k.as_str() == Some("snapshot"))
        .unwrap()
    else {
        panic!("snapshot is not a map")
    };
    for (k, v) in snap.iter_mut() {
        match (k.as_str(), v) {
            (Some("params_binary"), Value::Binary(bytes)) => {
                for i in sigma_row.clone() {
                    if s.half {
                        let b = &mut bytes[2 * i..2 * i + 2];
                        let w = f16::from_le_bytes([b[0], b[1]]).to_f32().abs() * gain;
                        b.copy_from_slice(&f16::from_f32(w).to_le_bytes());
                    } else {
                        let b = &mut bytes[4 * i..4 * i + 4];
                        let w = f32::from_le_bytes(b.try_into().unwrap()).abs() * gain;
                        b.copy_from_slice(&w.to_le_bytes());
                    }
                }
            }
            (Some("density_grid_binary"), Value::Binary(bytes)) => {
                for c in 0..s.n_cascades {
                    let width = (c as f32).exp2();
                    for m in 0..n3 {
                        // Morton index: bit 3k + a is bit k of axis a (x, y, z).
                        let axis =
                            |a: usize| (0..7).fold(0, |acc, k| acc | ((m >> (3 * k + a)) & 1) << k);
                        let q =
                            [0, 1, 2].map(|a| 0.5 + width * ((axis(a) as f32 + 0.5) / 128.0 - 0.5));
                        let inside = balls.iter().any(|b| {
                            (0..3).map(|a| (q[a] - b.centre[a]).powi(2)).sum::<f32>()
                                < b.radius * b.radius
                        });
                        cascade0 += usize::from(inside && c == 0);
                        let v = f16::from_f32(if inside { 1.0 } else { 0.0 });
                        let at = 2 * (c * n3 + m);
                        bytes[at..at + 2].copy_from_slice(&v.to_le_bytes());
                    }
                }
            }
            _ => {}
        }
    }
    let mut out = Vec::new();
    rmpv::encode::write_value(&mut out, &top).unwrap();
    let ext = if s.gzip { "ingp" } else { "msgpack" };
    let path = dir.join(format!("{name}.{ext}"));
    std::fs::write(&path, framed(s, out)).unwrap();
    (path, cascade0 as f64 / n3 as f64)
}
