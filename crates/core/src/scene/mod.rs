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

use crate::error::Result;
use crate::field::ColorSpace;

/// One instance of a scene with the sampler it is rendered by, chosen when the scene is
/// loaded (a scene file's `sampler`, or its field's default).
#[derive(Clone)]
pub enum SceneInstance {
    /// Marched by nerfx's occupancy marcher jointly with the other marched instances (their
    /// densities add), or integrated in closed form where every marched instance is analytic
    /// and the quality preset asks for it.
    Marched(Instance),
    /// A nerfacto run sampled by its own proposal networks; its samples join the march as
    /// fragments.
    Proposal(ProposalInstance),
    /// An instant-ngp snapshot marched by instant-ngp's own marcher; its samples join the
    /// march as fragments.
    Ngp(NgpInstance),
    /// 3D Gaussian splats, rasterised into fragments that join the march.
    Splats(SplatInstance),
}

impl SceneInstance {
    /// The instance's name (the scene file's).
    pub fn name(&self) -> &str {
        match self {
            SceneInstance::Marched(i) => &i.name,
            SceneInstance::Proposal(p) => p.name(),
            SceneInstance::Ngp(n) => n.name(),
            SceneInstance::Splats(s) => &s.name,
        }
    }

    /// The same instance with the crop box `crop` (field space) instead of its own.
    pub(crate) fn with_crop(&self, crop: Option<CropBox>) -> Result<Self> {
        Ok(match self {
            SceneInstance::Marched(i) => SceneInstance::Marched(Instance::new(
                i.name.clone(),
                i.handle().clone(),
                i.world_from_field(),
                crop,
            )?),
            SceneInstance::Proposal(p) => SceneInstance::Proposal(p.with_crop(crop)?),
            SceneInstance::Ngp(n) => SceneInstance::Ngp(n.with_crop(crop)?),
            SceneInstance::Splats(s) => SceneInstance::Splats(s.with_crop(crop)?),
        })
    }
}

impl From<Instance> for SceneInstance {
    fn from(instance: Instance) -> Self {
        SceneInstance::Marched(instance)
    }
}

impl From<ProposalInstance> for SceneInstance {
    fn from(instance: ProposalInstance) -> Self {
        SceneInstance::Proposal(instance)
    }
}

impl From<NgpInstance> for SceneInstance {
    fn from(instance: NgpInstance) -> Self {
        SceneInstance::Ngp(instance)
    }
}

impl From<SplatInstance> for SceneInstance {
    fn from(instance: SplatInstance) -> Self {
        SceneInstance::Splats(instance)
    }
}

/// The instances to render together, in the scene's order.
#[derive(Clone, Default)]
pub struct Scene {
    instances: Vec<SceneInstance>,
}

impl Scene {
    /// A scene of the given instances.
    pub fn new<I: Into<SceneInstance>>(instances: impl IntoIterator<Item = I>) -> Self {
        Scene {
            instances: instances.into_iter().map(Into::into).collect(),
        }
    }

    /// The scene with these instances too, after its own.
    pub fn with<I: Into<SceneInstance>>(mut self, instances: impl IntoIterator<Item = I>) -> Self {
        self.instances.extend(instances.into_iter().map(Into::into));
        self
    }

    /// Adds an instance after the others.
    pub fn push(&mut self, instance: impl Into<SceneInstance>) {
        self.instances.push(instance.into());
    }

    /// The scene with every instance cropped by `crop` (field space) instead of its own box.
    pub fn with_crop(&self, crop: Option<CropBox>) -> Result<Self> {
        let instances = self.instances.iter().map(|i| i.with_crop(crop));
        Ok(Scene {
            instances: instances.collect::<Result<_>>()?,
        })
    }

    /// Every instance, in the scene's order.
    pub fn instances(&self) -> &[SceneInstance] {
        &self.instances
    }

    /// The instances marched jointly by nerfx's occupancy marcher (or in closed form).
    pub fn marched(&self) -> impl Iterator<Item = &Instance> + Clone {
        self.instances.iter().filter_map(|i| match i {
            SceneInstance::Marched(m) => Some(m),
            _ => None,
        })
    }

    /// The nerfacto instances sampled by their proposal networks.
    pub fn proposal(&self) -> impl Iterator<Item = &ProposalInstance> + Clone {
        self.instances.iter().filter_map(|i| match i {
            SceneInstance::Proposal(p) => Some(p),
            _ => None,
        })
    }

    /// The instant-ngp instances marched by instant-ngp's marcher.
    pub fn ngp(&self) -> impl Iterator<Item = &NgpInstance> + Clone {
        self.instances.iter().filter_map(|i| match i {
            SceneInstance::Ngp(n) => Some(n),
            _ => None,
        })
    }

    /// The splat instances.
    pub fn splats(&self) -> impl Iterator<Item = &SplatInstance> + Clone {
        self.instances.iter().filter_map(|i| match i {
            SceneInstance::Splats(s) => Some(s),
            _ => None,
        })
    }

    /// Whether any instance is sampled by its trainer's own estimator (its samples merged
    /// with the march as fragments): nerfacto's proposal sampler, instant-ngp's marcher.
    pub(crate) fn has_sampled(&self) -> bool {
        self.instances
            .iter()
            .any(|i| matches!(i, SceneInstance::Proposal(_) | SceneInstance::Ngp(_)))
    }

    /// Every field instance, however it is sampled: the marched ones, then the
    /// proposal-sampled ones, then the instant-ngp ones.
    pub fn field_instances(&self) -> impl Iterator<Item = &Instance> {
        self.marched()
            .chain(self.proposal().map(|p| p.instance()))
            .chain(self.ngp().map(|p| p.instance()))
    }

    /// The space colours are composited in: sRGB-encoded when any instance was trained on
    /// photographs (its trainer composited encoded colours; linear instances are encoded to
    /// join it), as splats and nerfacto runs always are, else linear.
    pub fn composite_space(&self) -> ColorSpace {
        let srgb = |i: &SceneInstance| match i {
            SceneInstance::Splats(_) | SceneInstance::Proposal(_) => true,
            SceneInstance::Marched(m) => m.field().color_space() == ColorSpace::Srgb,
            SceneInstance::Ngp(n) => n.instance().field().color_space() == ColorSpace::Srgb,
        };
        if self.instances.iter().any(srgb) {
            ColorSpace::Srgb
        } else {
            ColorSpace::Linear
        }
    }
}
