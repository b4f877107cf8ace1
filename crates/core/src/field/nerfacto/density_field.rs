//! nerfacto's proposal density fields (nerfstudio's `HashMLPDensityField`): a small hash
//! grid and MLP giving density only, one per proposal iteration (or one shared), under
//! `_model.proposal_networks.<i>.` in the checkpoint.
//!
//! A point is contracted and mapped to the unit cube exactly as for the main field; the grid
//! (`proposal_net_args_list`: 5 levels × 2 features, `2^17` rows, `N_min` 16, `N_max` 128
//! then 256 by default) encodes it; the MLP (`num_layers` 2: one hidden layer of 16, ReLU)
//! gives `raw`; `σ = average_init_density · exp(raw)`, zero outside the selector
//! `0 < u < 1`. With `use_linear` one linear layer (with a bias) replaces the MLP.
//!
//! **Layouts.** The module is `encoding` plus `mlp_base = Sequential(encoding, mlp)`, so the
//! state dict names the grid twice. tiny-cuda-nn: `mlp_base.0.tcnn_encoding.params` (or
//! `encoding.tcnn_encoding.params`) and `mlp_base.1.tcnn_encoding.params` (a FullyFusedMLP
//! without biases, output padded to 16); torch fallback: `mlp_base.0.hash_table` (or
//! `encoding.hash_table`) and `mlp_base.1.layers.<k>.weight|bias`; `use_linear`:
//! `linear.weight|bias`.

use glam::Vec3;

use super::config::ProposalNetSettings;
#[cfg(target_arch = "x86_64")]
use super::density_kernel::FusedDensity;
use super::torch::TorchHashGrid;
use super::{
    linear_mlp, read_linear_layers, read_linear_params, read_params, read_torch_grid, read_weights,
    tcnn_grid, tcnn_grid_config, Keys, NerfactoField,
};
use crate::error::Result;
use crate::field::container::Checkpoint;
use crate::field::network::{exp_density, HashGrid, Mlp, MlpConfig};

/// The grid, in one of the two layouts.
#[derive(Clone, Debug)]
enum Grid {
    Tcnn(HashGrid),
    Torch(TorchHashGrid),
}

/// One proposal density field.
#[derive(Clone, Debug)]
pub(crate) struct DensityField {
    grid: Grid,
    /// What turns the encoding into `raw`: tiny-cuda-nn's MLP (no biases), or torch
    /// `nn.Linear` layers with biases (the torch MLP, or `use_linear`'s one layer).
    head: Mlp,
    average_init_density: f32,
    n_params: usize,
    /// The torch layout's grid and MLP in one pass, where the CPU and the shapes allow.
    #[cfg(target_arch = "x86_64")]
    fused: Option<FusedDensity>,
}

/// Reusable buffers for [`DensityField::density`].
#[derive(Clone, Debug, Default)]
pub(crate) struct DensityScratch {
    units: Vec<Vec3>,
    index: Vec<u32>,
    encoded: Vec<f32>,
    raw: Vec<f32>,
}

impl DensityField {
    /// Reads proposal network `index` of shape `s` from `ckpt`.
    pub(crate) fn read(
        ckpt: &Checkpoint,
        index: usize,
        s: &ProposalNetSettings,
        average_init_density: f32,
    ) -> Result<Self> {
        let mark = format!("_model.proposal_networks.{index}.");
        let keys = Keys::under(ckpt, &mark).ok_or_else(|| {
            crate::error::Error::format(
                ckpt.path(),
                format!("pipeline{mark}"),
                "no such proposal network in the checkpoint (config.yml's \
                 num_proposal_iterations and use_same_proposal_network say it exists)",
            )
        })?;
        let n_levels = s.num_levels as usize;
        let nf = s.features_per_level as usize;
        let (grid, grid_outputs, n_grid) = if let Some(name) = keys.first(&[
            "mlp_base.0.tcnn_encoding.params",
            "encoding.tcnn_encoding.params",
        ]) {
            let config = tcnn_grid_config(
                s.num_levels,
                s.features_per_level,
                s.log2_hashmap_size,
                s.base_res,
                s.max_res,
            );
            let params = read_params(ckpt, &keys, &name, config.n_params())?;
            let n = params.len();
            let grid = tcnn_grid(ckpt, &keys, &name, config, params)?;
            (Grid::Tcnn(grid), config.n_outputs(), n)
        } else if let Some(name) = keys.first(&["mlp_base.0.hash_table", "encoding.hash_table"]) {
            let shape = [s.num_levels, s.log2_hashmap_size, s.base_res, s.max_res];
            let (grid, n) = read_torch_grid(ckpt, &keys, &name, shape, nf)?;
            (Grid::Torch(grid), n_levels * nf, n)
        } else {
            return Err(keys.err(
                &keys.name("encoding"),
                "no hash grid (tcnn_encoding.params or hash_table) for this proposal network",
            ));
        };
        // The torch MLP's layers, for the fused kernel.
        let mut layers = None;
        let (head, n_head) = if s.use_linear {
            read_linear_layers(ckpt, &keys, "linear", grid_outputs)?
        } else if let Some(name) = keys.first(&["mlp_base.1.tcnn_encoding.params"]) {
            let p = read_weights(ckpt, &name)?;
            let config = [16, 8]
                .map(|align| MlpConfig {
                    n_inputs: grid_outputs,
                    width: s.hidden_dim,
                    n_hidden_layers: s.num_layers.saturating_sub(1).max(1),
                    n_outputs: 1,
                    output_alignment: align,
                })
                .into_iter()
                .find(|c| c.n_params() == p.len() && s.num_layers >= 2)
                .ok_or_else(|| {
                    keys.err(
                        &name,
                        format!(
                            "{} parameters do not fit an MLP of {} layers of width {} over {} \
                             inputs (config.yml's proposal_net_args_list)",
                            p.len(),
                            s.num_layers,
                            s.hidden_dim,
                            grid_outputs
                        ),
                    )
                })?;
            let mlp = Mlp::new(config, &p)
                .ok_or_else(|| keys.err(&name, "MLP parameters do not match"))?;
            (mlp, p.len())
        } else {
            let prefix = "mlp_base.1.layers";
            let params = read_linear_params(ckpt, &keys, prefix)?;
            let mlp = linear_mlp(&keys, prefix, grid_outputs, &params)?;
            let n = params.iter().map(|(w, b)| w.len() + b.len()).sum();
            layers = Some(params);
            (mlp, n)
        };
        if head.config().n_outputs != 1 {
            return Err(keys.err(
                &keys.name("mlp_base.1"),
                format!("{} outputs; a density field has 1", head.config().n_outputs),
            ));
        }
        // The fused kernel is x86-64's only.
        #[cfg(not(target_arch = "x86_64"))]
        let _ = layers;
        #[cfg(target_arch = "x86_64")]
        let fused = match (&grid, &layers) {
            (Grid::Torch(g), Some(layers)) => FusedDensity::new(g, layers),
            _ => None,
        };
        Ok(DensityField {
            #[cfg(target_arch = "x86_64")]
            fused,
            grid,
            head,
            average_init_density,
            n_params: n_grid + n_head,
        })
    }

    /// Trained parameters (for descriptions).
    pub(crate) fn n_params(&self) -> usize {
        self.n_params
    }

    /// `σ` at each field-space point (0 outside the selector).
    pub(crate) fn density(&self, points: &[Vec3], sigma: &mut [f32], s: &mut DensityScratch) {
        #[cfg(target_arch = "x86_64")]
        if let (Some(fused), Grid::Torch(g)) = (&self.fused, &self.grid) {
            fused.density(g, self.average_init_density, points, sigma);
            return;
        }
        s.units.clear();
        s.index.clear();
        for (i, (p, out)) in points.iter().zip(sigma.iter_mut()).enumerate() {
            *out = 0.0;
            if let Some(u) = NerfactoField::unit_from_field(*p) {
                s.units.push(u);
                s.index.push(i as u32);
            }
        }
        let n = s.units.len();
        let width = match &self.grid {
            Grid::Tcnn(g) => g.config().n_outputs(),
            Grid::Torch(g) => g.n_outputs(),
        };
        s.encoded.resize(n * width, 0.0);
        match &self.grid {
            Grid::Tcnn(g) => g.encode(&s.units, &mut s.encoded),
            Grid::Torch(g) => g.encode(&s.units, &mut s.encoded),
        }
        s.raw.resize(n, 0.0);
        self.head.forward(&s.encoded, &mut s.raw);
        for (&i, &raw) in s.index.iter().zip(&s.raw) {
            sigma[i as usize] = self.average_init_density * exp_density(raw);
        }
    }
}

/// A seeded proposal network of nerfstudio's default shape (5 levels × 2 features,
/// `2^12` rows, resolutions 16 to 256, hidden layer of 16), torch layout: as read (with
/// the fused kernel where it applies) and without the fused kernel.
fn seeded_pair(seed: u64) -> (DensityField, DensityField) {
    let mut rng = crate::rng::Mmix::new(seed);
    let mut next = move || rng.unit() - 0.5;
    let rows = 1usize << 12;
    let table: Vec<f32> = (0..5 * rows * 2).map(|_| next()).collect();
    let grid = TorchHashGrid::new(5, 2, 12, 16, 256, table).unwrap();
    let layers: Vec<(Vec<f32>, Vec<f32>)> = [(10, 16), (16, 1)]
        .into_iter()
        .map(|(n_in, n_out)| {
            let w = (0..n_in * n_out).map(|_| next()).collect();
            let b = (0..n_out).map(|_| next()).collect();
            (w, b)
        })
        .collect();
    let head = Mlp::with_biases(10, &layers).unwrap();
    let plain = DensityField {
        grid: Grid::Torch(grid.clone()),
        head: head.clone(),
        average_init_density: 0.7,
        n_params: 0,
        #[cfg(target_arch = "x86_64")]
        fused: None,
    };
    let read = DensityField {
        #[cfg(target_arch = "x86_64")]
        fused: FusedDensity::new(&grid, &layers),
        ..plain.clone()
    };
    (read, plain)
}

/// Seeded field-space points: inside the unit cube, beyond it (contracted), on the
/// cells' faces of every level, at the selector's edge and beyond, infinite and NaN.
fn seeded_points(n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = crate::rng::Mmix::new(seed);
    let mut next = move || rng.unit() * 6.0 - 3.0;
    let special = [
        Vec3::new(0.25, -0.5, 0.0),
        Vec3::new(1.0, 0.5, -1.0),
        Vec3::new(-2.0, 0.0, 0.0),
        Vec3::new(1e30, 3.0, 0.0),
        Vec3::new(f32::INFINITY, 0.0, 0.0),
        Vec3::new(0.5, f32::NAN, 0.0),
    ];
    (0..n)
        .map(|i| {
            special
                .get(i)
                .copied()
                .unwrap_or_else(|| Vec3::new(next(), next(), next()))
        })
        .collect()
}

/// A seeded proposal network of nerfstudio's default shape, torch layout, with and without the
/// fused kernel, and [`POINTS`](Self::POINTS) seeded points (a tile's round): what
/// `cargo bench --bench nerfacto -- proposal_density` times.
#[doc(hidden)]
pub struct ProposalDensityBench {
    fused: DensityField,
    plain: DensityField,
    points: Vec<Vec3>,
    sigma: Vec<f32>,
    scratch: DensityScratch,
}

impl ProposalDensityBench {
    /// Points per [`run`](Self::run).
    pub const POINTS: usize = 4096;

    /// The seeded network and points.
    pub fn new() -> Self {
        let (fused, plain) = seeded_pair(3);
        let points = seeded_points(Self::POINTS, 11);
        Self {
            fused,
            plain,
            sigma: vec![0.0; points.len()],
            points,
            scratch: DensityScratch::default(),
        }
    }

    /// Whether the fused kernel runs on this CPU (AVX2 and FMA); without it both runs take
    /// the separate stages.
    pub fn has_fused_kernel(&self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return self.fused.fused.is_some();
        #[cfg(not(target_arch = "x86_64"))]
        return false;
    }

    /// The density at every point, by the fused kernel or by the separate stages (the grid,
    /// then the MLP).
    pub fn run(&mut self, fused: bool) {
        let field = if fused { &self.fused } else { &self.plain };
        field.density(&self.points, &mut self.sigma, &mut self.scratch);
    }
}

impl Default for ProposalDensityBench {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fused_kernel_gives_the_separate_stages_bits() {
        let (read, plain) = seeded_pair(3);
        #[cfg(target_arch = "x86_64")]
        if read.fused.is_none() {
            eprintln!("no AVX2 and FMA: the fused kernel does not run here");
            return;
        }
        let mut scratch = DensityScratch::default();
        for n in [0, 1, 8, 37, 300] {
            let points = seeded_points(n, n as u64);
            let mut want = vec![f32::NAN; n];
            plain.density(&points, &mut want, &mut scratch);
            let mut got = vec![f32::NAN; n];
            read.density(&points, &mut got, &mut scratch);
            // The separate stages run the MLP with the same fused multiply-adds on this CPU.
            for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "{n} points, {i} at {}: {a} {b}",
                    points[i]
                );
            }
            assert!(want.iter().any(|&v| v > 0.0) || n < 8);
            assert!(n < 6 || want[4] == 0.0 && want[5] == 0.0);
        }
    }
}
