//! Scenes: field instances placed in the host's world, marched jointly.
//!
//! An [`Instance`] is a field with its object transform (`world_from_field`, the NeRF object's
//! `matrix_world` in Blender, `N`) and an optional crop box in field space. A world ray is
//! carried into each instance's frame once per pixel ([`Instance::local_ray`]); distances stay
//! in *world* units along it, so several instances share one march: their densities add and
//! their colours mix by density, which gives correct mutual occlusion and transparency.
//!
//! Why world units: with `field_from_world = N⁻¹`, a world ray `o + t·d` (|d| = 1) maps to
//! `N⁻¹o + t·N⁻¹d`. With `k = |N⁻¹d|` the local unit direction is `N⁻¹d / k` and the local
//! distance is `u = k·t`; a local density σ per field unit is `k·σ` per world unit. This is
//! the alignment `C_t = N⁻¹ C_o` with renormalised directions, and depth comes out in world units
//! for free — also when `N` carries non-uniform scale.

mod file;
mod indicator;
mod instance;
mod ngp;
mod proposal;
mod splats;

pub use crate::field::{CropBox, CropClip};
pub use file::{FieldSource, InstanceDesc, LoadedScene, Sampler, SceneDesc};
pub use instance::{FieldHandle, Instance, LocalRay};
pub use ngp::NgpInstance;
pub use proposal::ProposalInstance;
pub use splats::SplatInstance;

use crate::field::ColorSpace;

/// The fields and splats to render together.
#[derive(Clone, Default)]
pub struct Scene {
    /// The field instances, marched jointly.
    pub instances: Vec<Instance>,
    /// The splat instances, rasterised into fragments merged with the march.
    pub splats: Vec<SplatInstance>,
    /// The nerfacto instances sampled by their own proposal networks, their samples merged
    /// with the march as the splats' fragments are.
    pub proposal: Vec<ProposalInstance>,
    /// The instant-ngp instances marched by instant-ngp's own marcher, merged likewise.
    pub ngp: Vec<NgpInstance>,
}

impl Scene {
    /// A scene of the given field instances.
    pub fn new(instances: Vec<Instance>) -> Self {
        Scene {
            instances,
            splats: Vec::new(),
            proposal: Vec::new(),
            ngp: Vec::new(),
        }
    }

    /// The scene with these splat instances too.
    pub fn with_splats(mut self, splats: Vec<SplatInstance>) -> Self {
        self.splats = splats;
        self
    }

    /// Whether any instance is sampled by its trainer's own estimator (its samples merged
    /// with the march as fragments): nerfacto's proposal sampler, instant-ngp's marcher.
    pub fn has_sampled(&self) -> bool {
        !self.proposal.is_empty() || !self.ngp.is_empty()
    }

    /// Every field instance, however it is sampled.
    pub fn field_instances(&self) -> impl Iterator<Item = &Instance> {
        self.instances
            .iter()
            .chain(self.proposal.iter().map(|p| p.instance()))
            .chain(self.ngp.iter().map(|p| p.instance()))
    }

    /// The space colours are composited in: sRGB-encoded when any instance was trained on
    /// photographs (its trainer composited encoded colours; linear instances are encoded to
    /// join it), as splats and nerfacto runs always are, else linear.
    pub fn composite_space(&self) -> ColorSpace {
        if !self.splats.is_empty()
            || !self.proposal.is_empty()
            || self
                .instances
                .iter()
                .chain(self.ngp.iter().map(|n| n.instance()))
                .any(|i| i.field().color_space() == ColorSpace::Srgb)
        {
            ColorSpace::Srgb
        } else {
            ColorSpace::Linear
        }
    }
}
