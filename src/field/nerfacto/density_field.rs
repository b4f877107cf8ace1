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
use super::torch::TorchHashGrid;
use super::{
    read_linear_layers, read_params, read_torch_grid, read_weights, tcnn_grid, tcnn_grid_config,
    Keys, NerfactoField,
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
            read_linear_layers(ckpt, &keys, "mlp_base.1.layers", grid_outputs)?
        };
        if head.config().n_outputs != 1 {
            return Err(keys.err(
                &keys.name("mlp_base.1"),
                format!("{} outputs; a density field has 1", head.config().n_outputs),
            ));
        }
        Ok(DensityField {
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
