//! A writer of small nerfstudio nerfacto runs with seeded weights, written from the format
//! facts (torch's zip layout, pickle protocol 2, nerfstudio's state-dict keys; docs/src/architecture.md),
//! for the loader's tests and the NumPy cross-check: `config.yml`,
//! `dataparser_transforms.json` and `nerfstudio_models/step-<n>.ckpt`.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use half::f16;
// The tests' one generator, through the shared harness (which every crate using this
// writer declares as `mod common_fields`).
pub use super::common_fields::SplitMix64;

/// What the density network computes (tiny-cuda-nn layout only for the two shaped ones).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Density {
    /// Seeded weights throughout.
    Seeded,
    /// The density MLP's first layer zero: `raw = 0` everywhere, so `σ` is
    /// `average_init_density` at every point of space (geometry features zero too).
    Constant,
    /// A shell far out: the coarsest (dense) hash level holds, per grid vertex, its
    /// contracted radius `‖c‖∞` and a constant 1; the density MLP computes
    /// `raw = relu(A·(ρ − ρ₀)) − B` from them (A = 30, ρ₀ = 1.8, B = 5), so the density is
    /// faint inside contracted radius ~1.97 (field radius ~30) and grows beyond it until the
    /// far field is opaque. Finer levels are zero.
    Shell,
    /// Near only: `raw = relu(A·(ρ₀ − ρ)) − B` with A = 150, ρ₀ = 0.8, B = 25: a dense cube
    /// inside contracted (and field) radius ~0.63, and a density of 10⁻¹³ elsewhere, which
    /// nothing renders.
    Core,
}

/// What to write.
#[derive(Clone, Debug)]
pub struct Spec {
    /// The torch-fallback layout (biases, `hash_table`) instead of tiny-cuda-nn's.
    pub torch: bool,
    /// Store tiny-cuda-nn's parameters as f16 (as tcnn's fp16 modules do).
    pub half: bool,
    pub log2_table_size: u32,
    pub n_images: usize,
    pub average_init_density: f32,
    /// Added to the density output's bias (torch layout only): shifts the density down so
    /// that part of the bounds is empty.
    pub density_offset: f32,
    /// Whether the occupancy computed at load should have empty cells (about half).
    pub expect_empty_space: bool,
    pub seed: u64,
    /// The two proposal networks' `log2_hashmap_size` and `max_res` (5 levels × 2
    /// features, hidden 16, as nerfacto's); `None`: no proposal networks in the checkpoint.
    pub proposal: Option<(u32, [u32; 2])>,
    /// Added to the proposal networks' output (torch layout: the bias; tcnn layout: spread
    /// over the output row's weights), shifting their density.
    pub proposal_offset: f32,
    pub density: Density,
    /// `far_plane` written into `config.yml` (`None`: nerfacto's default, 1000).
    pub far_plane: Option<f32>,
}

impl Spec {
    pub fn tcnn() -> Self {
        Spec {
            torch: false,
            half: true,
            log2_table_size: 12,
            n_images: 5,
            average_init_density: 0.01,
            density_offset: 0.0,
            expect_empty_space: false,
            seed: 11,
            proposal: Some((12, [64, 128])),
            proposal_offset: 0.0,
            density: Density::Seeded,
            far_plane: None,
        }
    }

    /// tiny-cuda-nn's layout with `σ` = `sigma` everywhere.
    pub fn constant(sigma: f32) -> Self {
        Spec {
            average_init_density: sigma,
            density: Density::Constant,
            seed: 21,
            ..Spec::tcnn()
        }
    }

    /// tiny-cuda-nn's layout with a dense core and nothing far ([`Density::Core`]).
    pub fn core() -> Self {
        Spec {
            density: Density::Core,
            seed: 23,
            expect_empty_space: true,
            ..Spec::tcnn()
        }
    }

    /// tiny-cuda-nn's layout with a distant shell ([`Density::Shell`]).
    pub fn shell() -> Self {
        Spec {
            density: Density::Shell,
            seed: 22,
            expect_empty_space: true,
            ..Spec::tcnn()
        }
    }

    pub fn torch() -> Self {
        Spec {
            torch: true,
            half: false,
            log2_table_size: 11,
            n_images: 3,
            average_init_density: 0.05,
            density_offset: -2.0,
            expect_empty_space: true,
            seed: 12,
            proposal: Some((11, [64, 128])),
            proposal_offset: 1.0,
            density: Density::Seeded,
            far_plane: None,
        }
    }
}

pub const LEVELS: u32 = 16;
pub const FEATURES: usize = 2;
pub const APPEARANCE: usize = 32;
pub const STEP: u64 = 3000;

/// A storage and the tensors viewing it.
struct Storage {
    half: bool,
    bytes: Vec<u8>,
}

struct Tensor {
    name: String,
    storage: usize,
    shape: Vec<usize>,
    stride: Vec<usize>,
    offset: usize,
}

#[derive(Default)]
struct StateDict {
    storages: Vec<Storage>,
    tensors: Vec<Tensor>,
}

impl StateDict {
    /// A contiguous tensor in a storage of its own.
    fn add(&mut self, name: &str, shape: &[usize], values: &[f32], half: bool) {
        let bytes = if half {
            values
                .iter()
                .flat_map(|v| f16::from_f32(*v).to_le_bytes())
                .collect()
        } else {
            values.iter().flat_map(|v| v.to_le_bytes()).collect()
        };
        self.storages.push(Storage { half, bytes });
        let mut stride = vec![1; shape.len()];
        for d in (0..shape.len().saturating_sub(1)).rev() {
            stride[d] = stride[d + 1] * shape[d + 1];
        }
        self.tensors.push(Tensor {
            name: name.into(),
            storage: self.storages.len() - 1,
            shape: shape.to_vec(),
            stride,
            offset: 0,
        });
    }

    /// A linear layer stored the way a view can be: the weight `[out][in]` kept transposed
    /// in the storage (stride `(1, out)`) after 3 padding values, the bias in the same
    /// storage after it.
    fn add_linear(&mut self, prefix: &str, w: &[f32], b: &[f32], n_in: usize) {
        let n_out = b.len();
        let mut values = vec![9.0f32; 3];
        for i in 0..n_in {
            for o in 0..n_out {
                values.push(w[o * n_in + i]);
            }
        }
        values.extend(b);
        self.storages.push(Storage {
            half: false,
            bytes: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        });
        let s = self.storages.len() - 1;
        self.tensors.push(Tensor {
            name: format!("{prefix}.weight"),
            storage: s,
            shape: vec![n_out, n_in],
            stride: vec![1, n_out],
            offset: 3,
        });
        self.tensors.push(Tensor {
            name: format!("{prefix}.bias"),
            storage: s,
            shape: vec![n_out],
            stride: vec![1],
            offset: 3 + n_in * n_out,
        });
    }
}

/// tiny-cuda-nn's hash-grid parameter count for the spec (levels of
/// `min(next_multiple_of_8(res³), 2^log2T)` entries, `res = ⌈2^(l·log2 b)·16 − 1⌉ + 1`).
pub fn tcnn_grid_params(s: &Spec) -> usize {
    tcnn_grid_params_of(LEVELS, s.log2_table_size, 2048)
}

/// The same for `levels` levels from 16 to `max_res`, 2 features each.
pub fn tcnn_grid_params_of(levels: u32, log2_table_size: u32, max_res: u32) -> usize {
    let b = ((f64::from(max_res).ln() - 16f64.ln()) / f64::from(levels - 1)).exp() as f32;
    let log2_b = (b as f64).log2() as f32;
    (0..levels)
        .map(|l| {
            let scale = ((l as f32 * log2_b) as f64).exp2() as f32 * 16.0 - 1.0;
            let r = scale.ceil() as usize + 1;
            (r * r * r)
                .div_ceil(8)
                .saturating_mul(8)
                .min(1 << log2_table_size)
        })
        .sum::<usize>()
        * FEATURES
}

/// nerfacto's proposal networks: `HashMLPDensityField`s of 5 levels × 2 features, one
/// hidden layer of 16, under `_model.proposal_networks.<i>.` (the grid under both of its
/// names, `encoding` and `mlp_base.0`, as torch's state dict holds it).
fn add_proposal_networks(sd: &mut StateDict, s: &Spec, rng: &mut SplitMix64) {
    let Some((log2, max_res)) = s.proposal else {
        return;
    };
    for (i, max) in max_res.into_iter().enumerate() {
        let p = format!("_model.proposal_networks.{i}.");
        if s.torch {
            let rows = 5 * (1usize << log2);
            let table = seeded(rng, rows * FEATURES, 1.0);
            for name in ["encoding.hash_table", "mlp_base.0.hash_table"] {
                sd.add(&format!("{p}{name}"), &[rows, FEATURES], &table, false);
            }
            let w0 = seeded(rng, 10 * 16, 0.5);
            let b0 = seeded(rng, 16, 0.2);
            sd.add_linear(&format!("{p}mlp_base.1.layers.0"), &w0, &b0, 10);
            let w1 = seeded(rng, 16, 0.5);
            let b1 = vec![s.proposal_offset];
            sd.add_linear(&format!("{p}mlp_base.1.layers.1"), &w1, &b1, 16);
        } else {
            let grid = seeded(rng, tcnn_grid_params_of(5, log2, max), 1.0);
            for name in [
                "encoding.tcnn_encoding.params",
                "mlp_base.0.tcnn_encoding.params",
            ] {
                sd.add(&format!("{p}{name}"), &[grid.len()], &grid, s.half);
            }
            // 10 inputs padded to 16 → 16 → 1 padded to 16.
            let mut mlp = seeded(rng, 16 * 16 + 16 * 16, 0.5);
            for w in &mut mlp[16 * 16..16 * 16 + 16] {
                *w += s.proposal_offset / 8.0;
            }
            sd.add(
                &format!("{p}mlp_base.1.tcnn_encoding.params"),
                &[mlp.len()],
                &mlp,
                false,
            );
        }
    }
}

fn seeded(rng: &mut SplitMix64, n: usize, amplitude: f32) -> Vec<f32> {
    (0..n).map(|_| rng.range(-amplitude, amplitude)).collect()
}

fn state_dict(s: &Spec) -> StateDict {
    let mut rng = SplitMix64::new(s.seed);
    let mut sd = StateDict::default();
    let f = "_model.field.";
    let n_grid_out = LEVELS as usize * FEATURES;
    let head_in = 16 + 15 + APPEARANCE;
    // The proposal networks first, as in real runs (from a generator of their own, so the
    // main field's weights do not depend on them).
    add_proposal_networks(&mut sd, s, &mut SplitMix64::new(s.seed ^ 0x9e37_79b9));
    if s.torch {
        let rows = LEVELS as usize * (1 << s.log2_table_size);
        let table = seeded(&mut rng, rows * FEATURES, 1.0);
        sd.add(
            &format!("{f}mlp_base.model.0.hash_table"),
            &[rows, FEATURES],
            &table,
            false,
        );
        for (k, (n_in, n_out, amp)) in [(n_grid_out, 64, 0.35), (64, 16, 0.3)]
            .into_iter()
            .enumerate()
        {
            let w = seeded(&mut rng, n_in * n_out, amp);
            let mut b = seeded(&mut rng, n_out, 0.2);
            if k == 1 {
                b[0] += s.density_offset;
            }
            sd.add_linear(&format!("{f}mlp_base.model.1.layers.{k}"), &w, &b, n_in);
        }
        for (k, (n_in, n_out)) in [(head_in, 64), (64, 64), (64, 3)].into_iter().enumerate() {
            let w = seeded(&mut rng, n_in * n_out, 0.3);
            let b = seeded(&mut rng, n_out, 0.2);
            sd.add_linear(&format!("{f}mlp_head.layers.{k}"), &w, &b, n_in);
        }
    } else {
        let n_in = n_grid_out.next_multiple_of(16);
        let density = 64 * n_in + 16 * 64;
        let mut params = seeded(&mut rng, density, 0.35);
        let mut grid = seeded(&mut rng, tcnn_grid_params(s), 1.0);
        match s.density {
            Density::Seeded => {}
            Density::Constant => params[..64 * n_in].fill(0.0),
            Density::Shell => shell_network(&mut params, &mut grid, n_in, 1.8, 30.0, 5.0),
            Density::Core => shell_network(&mut params, &mut grid, n_in, 0.8, -150.0, 25.0),
        }
        params.extend(grid);
        sd.add(
            &format!("{f}mlp_base.model.params"),
            &[params.len()],
            &params,
            s.half,
        );
        let head = 64 * head_in.next_multiple_of(16) + 64 * 64 + 16 * 64;
        let p = seeded(&mut rng, head, 0.3);
        sd.add(
            &format!("{f}mlp_head.tcnn_encoding.params"),
            &[head],
            &p,
            s.half,
        );
    }
    let emb = seeded(&mut rng, s.n_images * APPEARANCE, 1.0);
    sd.add(
        &format!("{f}embedding_appearance.embedding.weight"),
        &[s.n_images, APPEARANCE],
        &emb,
        false,
    );
    sd
}

/// The weights of [`Density::Shell`]: the density MLP's (`[64][n_in]` then `[16][64]`,
/// row-major) and the grid's (level 0 first: 16³ entries of 2 features, dense, entry
/// `x + 16y + 256z` for the vertex whose hash-grid coordinate is `(x, y, z)`, at
/// `u = (g − 1/2)/15` per axis, contracted `c = 4u − 2`).
/// `raw = relu(a·(ρ − ρ₀)) − b` (a negative `a`: a core instead of a shell).
fn shell_network(mlp: &mut [f32], grid: &mut [f32], n_in: usize, rho0: f32, a: f32, b: f32) {
    const RES: usize = 16;
    let (first, second) = mlp.split_at_mut(64 * n_in);
    first.fill(0.0);
    first[0] = a; // hidden 0 = relu(a·(ρ − ρ₀))
    first[1] = -a * rho0;
    first[n_in + 1] = 1.0; // hidden 1 = relu(1) = 1
    for o in 0..16 {
        // Output 0: raw = hidden 0 − B·hidden 1; the geometry features keep seeded weights on
        // those two hidden units only.
        let row = &mut second[o * 64..(o + 1) * 64];
        let (h0, h1) = (row[0], row[1]);
        row.fill(0.0);
        (row[0], row[1]) = if o == 0 { (1.0, -b) } else { (h0, h1) };
    }
    grid.fill(0.0);
    for z in 0..RES {
        for y in 0..RES {
            for x in 0..RES {
                let c = |g: usize| 4.0 * (g as f32 - 0.5) / 15.0 - 2.0;
                let rho = c(x).abs().max(c(y).abs()).max(c(z).abs());
                let e = x + RES * y + RES * RES * z;
                grid[2 * e] = rho;
                grid[2 * e + 1] = 1.0;
            }
        }
    }
}

/// Pickle opcodes (protocol 2), written from the format.
struct Pickle {
    out: Vec<u8>,
    memo: u32,
    globals: Vec<(String, u32)>,
}

impl Pickle {
    fn str(&mut self, s: &str) {
        self.out.push(b'X');
        self.out.extend((s.len() as u32).to_le_bytes());
        self.out.extend(s.as_bytes());
        self.put();
    }

    fn int(&mut self, v: usize) {
        if v < 256 {
            self.out.extend([b'K', v as u8]);
        } else if v < 65536 {
            self.out.push(b'M');
            self.out.extend((v as u16).to_le_bytes());
        } else {
            self.out.push(b'J');
            self.out.extend((v as i32).to_le_bytes());
        }
    }

    fn float(&mut self, v: f64) {
        self.out.push(b'G');
        self.out.extend(v.to_be_bytes());
    }

    /// BINPUT or LONG_BINPUT of the top of the stack.
    fn put(&mut self) {
        if self.memo < 256 {
            self.out.extend([b'q', self.memo as u8]);
        } else {
            self.out.push(b'r');
            self.out.extend(self.memo.to_le_bytes());
        }
        self.memo += 1;
    }

    fn global(&mut self, module: &str, name: &str) {
        let key = format!("{module}\n{name}\n");
        if let Some((_, m)) = self.globals.iter().find(|(k, _)| *k == key) {
            let m = *m;
            if m < 256 {
                self.out.extend([b'h', m as u8]);
            } else {
                self.out.push(b'j');
                self.out.extend(m.to_le_bytes());
            }
            return;
        }
        self.out.push(b'c');
        self.out.extend(key.as_bytes());
        self.globals.push((key, self.memo));
        self.put();
    }

    fn ints(&mut self, v: &[usize]) {
        match v.len() {
            0 => self.out.push(b')'),
            1..=3 => {
                for x in v {
                    self.int(*x);
                }
                self.out.push(0x84 + v.len() as u8);
            }
            _ => {
                self.out.push(b'(');
                for x in v {
                    self.int(*x);
                }
                self.out.push(b't');
            }
        }
        self.put();
    }

    fn tensor(&mut self, t: &Tensor, storages: &[Storage]) {
        let st = &storages[t.storage];
        let es = if st.half { 2 } else { 4 };
        self.global("torch._utils", "_rebuild_tensor_v2");
        self.out.extend([b'(', b'(']);
        self.str("storage");
        self.global(
            "torch",
            if st.half {
                "HalfStorage"
            } else {
                "FloatStorage"
            },
        );
        self.str(&t.storage.to_string());
        self.str("cpu");
        self.int(st.bytes.len() / es);
        self.out.push(b't');
        self.put();
        self.out.push(b'Q');
        self.int(t.offset);
        self.ints(&t.shape);
        self.ints(&t.stride);
        self.out.push(0x89);
        self.global("collections", "OrderedDict");
        self.out.extend([b')', b'R']);
        self.put();
        self.out.push(b't');
        self.put();
        self.out.push(b'R');
        self.put();
    }
}

/// `{'step': STEP, 'pipeline': OrderedDict(tensors), 'optimizers': {...}, 'scalers': {...}}`.
fn pickle(sd: &StateDict) -> Vec<u8> {
    let mut p = Pickle {
        out: vec![0x80, 2, b'}'],
        memo: 0,
        globals: Vec::new(),
    };
    p.put();
    p.out.push(b'(');
    p.str("step");
    p.int(STEP as usize);
    p.str("pipeline");
    p.global("collections", "OrderedDict");
    p.out.extend([b')', b'R']);
    p.put();
    p.out.push(b'(');
    for t in &sd.tensors {
        p.str(&t.name);
        p.tensor(t, &sd.storages);
    }
    p.out.push(b'u');
    // `_metadata`, set by BUILD as torch's state dicts carry it.
    p.out.push(b'}');
    p.put();
    p.str("_metadata");
    p.global("collections", "OrderedDict");
    p.out.extend([b')', b'R', b's', b'b']);
    p.str("optimizers");
    p.out.push(b'}');
    p.put();
    p.str("fields");
    p.out.extend([b'}', b'(']);
    p.str("state");
    p.out.push(b'}');
    p.str("param_groups");
    p.out.extend([b']', b'(', b'}', b'(']);
    p.str("lr");
    p.float(0.01);
    p.str("betas");
    p.float(0.9);
    p.float(0.99);
    p.out.push(0x86);
    p.str("amsgrad");
    p.out.push(0x89);
    p.str("foreach");
    p.out.push(b'N');
    p.str("params");
    p.out.extend([b']', b'(', b'K', 0, b'K', 1, b'e']);
    p.out.extend([b'u', b'e', b'u', b's']);
    p.str("scalers");
    p.out.extend([b'}', b'(']);
    p.str("scale");
    p.float(65536.0);
    p.out.extend([b'u', b'u', b'.']);
    p.out
}

/// A zip archive of stored entries, data aligned to 64 bytes by an extra field (as torch).
pub fn zip(files: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in files {
        let mut crc = flate2::Crc::new();
        crc.update(data);
        let offset = out.len() as u32;
        let header = 30 + name.len() + 4;
        let pad = (64 - (out.len() + header) % 64) % 64;
        out.extend(0x0403_4b50u32.to_le_bytes());
        out.extend([20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
        out.extend(crc.sum().to_le_bytes());
        out.extend((data.len() as u32).to_le_bytes());
        out.extend((data.len() as u32).to_le_bytes());
        out.extend((name.len() as u16).to_le_bytes());
        out.extend(((4 + pad) as u16).to_le_bytes());
        out.extend(name.as_bytes());
        out.extend(0x4246u16.to_le_bytes());
        out.extend((pad as u16).to_le_bytes());
        out.extend(std::iter::repeat_n(b'Z', pad));
        out.extend(data);
        central.extend(0x0201_4b50u32.to_le_bytes());
        central.extend([20, 0, 20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
        central.extend(crc.sum().to_le_bytes());
        central.extend((data.len() as u32).to_le_bytes());
        central.extend((data.len() as u32).to_le_bytes());
        central.extend((name.len() as u16).to_le_bytes());
        central.extend([0u8; 12]);
        central.extend(offset.to_le_bytes());
        central.extend(name.as_bytes());
    }
    let cd = out.len() as u32;
    out.extend(&central);
    out.extend(0x0605_4b50u32.to_le_bytes());
    out.extend([0, 0, 0, 0]);
    out.extend((files.len() as u16).to_le_bytes());
    out.extend((files.len() as u16).to_le_bytes());
    out.extend((central.len() as u32).to_le_bytes());
    out.extend(cd.to_le_bytes());
    out.extend([0, 0]);
    out
}

/// The checkpoint file's bytes.
pub fn checkpoint_bytes(s: &Spec) -> Vec<u8> {
    checkpoint_of_state(&state_dict(s))
}

/// A checkpoint holding these float32 tensors `(name, shape, values)` under `pipeline`.
pub fn checkpoint_of(tensors: &[(&str, Vec<usize>, Vec<f32>)]) -> Vec<u8> {
    let mut sd = StateDict::default();
    for (name, shape, values) in tensors {
        sd.add(name, shape, values, false);
    }
    checkpoint_of_state(&sd)
}

fn checkpoint_of_state(sd: &StateDict) -> Vec<u8> {
    let stem = format!("step-{STEP:09}");
    let mut files = vec![(format!("{stem}/data.pkl"), pickle(sd))];
    files.push((format!("{stem}/byteorder"), b"little".to_vec()));
    for (i, st) in sd.storages.iter().enumerate() {
        files.push((format!("{stem}/data/{i}"), st.bytes.clone()));
    }
    files.push((format!("{stem}/version"), b"3\n".to_vec()));
    zip(&files)
}

pub fn config_yml(s: &Spec) -> String {
    format!(
        "!!python/object:nerfstudio.engine.trainer.TrainerConfig
_target: !!python/name:nerfstudio.engine.trainer.Trainer ''
method_name: nerfacto
pipeline: !!python/object:nerfstudio.pipelines.base_pipeline.VanillaPipelineConfig
  datamanager: !!python/object:nerfstudio.data.datamanagers.base_datamanager.VanillaDataManagerConfig
    camera_res_scale_factor: 1.0
  model: !!python/object:nerfstudio.models.nerfacto.NerfactoModelConfig
    _target: !!python/name:nerfstudio.models.nerfacto.NerfactoModel ''
    appearance_embed_dim: {APPEARANCE}
    average_init_density: {}
    base_res: 16
    collider_params:
      far_plane: 1000.0
      near_plane: 2.0
    disable_scene_contraction: false
    features_per_level: {FEATURES}
    hidden_dim: 64
    hidden_dim_color: 64
    implementation: {}
    log2_hashmap_size: {}
    max_res: 2048
    num_levels: {LEVELS}
    far_plane: {far:?}
    near_plane: 0.05
    num_nerf_samples_per_ray: 48
    num_proposal_iterations: 2
    num_proposal_samples_per_ray: !!python/tuple
    - 256
    - 96
    proposal_initial_sampler: piecewise
    proposal_net_args_list:
    - hidden_dim: 16
      log2_hashmap_size: {p_log2}
      max_res: {p0}
      num_levels: 5
      use_linear: false
    - hidden_dim: 16
      log2_hashmap_size: {p_log2}
      max_res: {p1}
      num_levels: 5
      use_linear: false
    use_average_appearance_embedding: true
    use_same_proposal_network: false
",
        s.average_init_density,
        if s.torch { "torch" } else { "tcnn" },
        s.log2_table_size,
        far = s.far_plane.unwrap_or(1000.0),
        p_log2 = s.proposal.map_or(17, |p| p.0),
        p0 = s.proposal.map_or(128, |p| p.1[0]),
        p1 = s.proposal.map_or(256, |p| p.1[1]),
    )
}

/// A fresh scratch folder for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-nerfacto-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes the run of `s` into `dir/run` (with a corrupt lower-step checkpoint next to the
/// real one, which the loader must not pick); returns the run directory.
pub fn write_run(dir: &Path, s: &Spec) -> PathBuf {
    let run = dir.join("run");
    let models = run.join("nerfstudio_models");
    std::fs::create_dir_all(&models).unwrap();
    std::fs::write(run.join("config.yml"), config_yml(s)).unwrap();
    std::fs::write(
        run.join("dataparser_transforms.json"),
        r#"{"transform": [[0, 1, 0, 0.5], [-1, 0, 0, 0.25], [0, 0, 1, -1]], "scale": 0.2}"#,
    )
    .unwrap();
    std::fs::write(
        models.join(format!("step-{STEP:09}.ckpt")),
        checkpoint_bytes(s),
    )
    .unwrap();
    std::fs::write(models.join("step-000000999.ckpt"), b"not a checkpoint").unwrap();
    run
}

/// The run in `dir/run` placed at the identity, sampled as `sampler` says.
pub fn placed(dir: &Path, sampler: &str) -> nerfx_core::Result<nerfx_core::scene::Scene> {
    let scene_file = dir.join("scene.json");
    std::fs::write(
        &scene_file,
        format!(
            r#"{{"instances": [{{"name": "run", "field": {{"nerfacto": {{"path": "run",
                "sampler": "{sampler}"}}}}}}]}}"#
        ),
    )
    .unwrap();
    nerfx_core::scene::SceneDesc::read(&scene_file)?
        .load()?
        .place(glam::DMat4::IDENTITY, &|_| Ok(glam::DMat4::IDENTITY))
}

/// `field` as the one instance of a scene, named "run", at `world_from_field`.
pub fn scene_of(
    field: nerfx_core::field::NerfactoField,
    world_from_field: glam::DMat4,
) -> nerfx_core::scene::Scene {
    use nerfx_core::scene::{FieldHandle, Instance, Scene};
    Scene::new(vec![Instance::new(
        "run",
        FieldHandle::new(std::sync::Arc::new(field)),
        world_from_field,
        None,
    )
    .unwrap()])
}

/// The real nerfacto run and nerfstudio's own renders of it (`tests/data/nerfstudio/`).
pub fn nerfstudio_fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/nerfstudio")
}

/// A copy of the real run in `dir/run` (nerfx caches an occupancy grid beside a run) and a
/// scene naming it as the path's object, loaded.
pub fn copied_nerfstudio_run(dir: &Path) -> (PathBuf, nerfx_core::scene::LoadedScene) {
    let run = dir.join("run");
    for sub in ["", "nerfstudio_models"] {
        std::fs::create_dir_all(run.join(sub)).unwrap();
        for entry in std::fs::read_dir(nerfstudio_fixture().join("run").join(sub)).unwrap() {
            let path = entry.unwrap().path();
            if path.is_file() {
                std::fs::copy(&path, run.join(sub).join(path.file_name().unwrap())).unwrap();
            }
        }
    }
    let scene_file = dir.join("scene.json");
    std::fs::write(
        &scene_file,
        r#"{"instances": [{"name": "run", "object": "NeRF",
            "field": {"nerfacto": {"path": "run"}}}]}"#,
    )
    .unwrap();
    (
        run,
        nerfx_core::scene::SceneDesc::read(&scene_file)
            .unwrap()
            .load()
            .unwrap(),
    )
}
