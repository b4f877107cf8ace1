//! nerfacto's proposal networks: the density fields its proposal sampler was trained with,
//! and the sampler's settings and spacing function, as the checkpoint and its config hold
//! them.

use super::config::SamplerSettings;
use super::density_field::DensityField;

/// The proposal networks and the settings nerfacto's proposal sampler was trained with
/// (the sampler itself is the renderer's: `render::proposal`).
#[derive(Clone, Debug)]
pub(crate) struct ProposalNetworks {
    settings: SamplerSettings,
    nets: Vec<DensityField>,
}

impl ProposalNetworks {
    pub(crate) fn new(settings: SamplerSettings, nets: Vec<DensityField>) -> Self {
        ProposalNetworks { settings, nets }
    }

    /// The network of proposal iteration `i`.
    pub(crate) fn net(&self, i: usize) -> &DensityField {
        &self.nets[if self.settings.same_network { 0 } else { i }]
    }

    pub(crate) fn settings(&self) -> &SamplerSettings {
        &self.settings
    }

    /// Parameters of the proposal networks.
    pub(crate) fn n_params(&self) -> usize {
        self.nets.iter().map(DensityField::n_params).sum()
    }

    /// The spacing function `g`.
    pub(crate) fn spacing(&self, x: f64) -> f64 {
        if self.settings.uniform_initial {
            x
        } else if x < 1.0 {
            x / 2.0
        } else {
            1.0 - 1.0 / (2.0 * x)
        }
    }

    /// `g⁻¹`.
    fn spacing_inv(&self, s: f64) -> f64 {
        if self.settings.uniform_initial {
            s
        } else if s < 0.5 {
            2.0 * s
        } else {
            1.0 / (2.0 - 2.0 * s)
        }
    }

    /// Distance of spacing `s` on a ray with `span = (g(near), g(far))`.
    #[inline]
    pub(crate) fn distance(&self, s: f64, span: [f64; 2]) -> f64 {
        self.spacing_inv(s * span[1] + (1.0 - s) * span[0])
    }
}
