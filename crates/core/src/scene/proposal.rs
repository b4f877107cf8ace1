//! nerfacto runs placed in the world and sampled by their own proposal networks (what
//! nerfstudio's viewer and `ns-render` show), instead of nerfx's occupancy marcher.
//!
//! How a world ray becomes the ray nerfstudio's sampler sees is the renderer's
//! ([`crate::render::proposal_ray`]).

use std::sync::Arc;

use glam::DMat4;

use super::instance::{FieldHandle, Instance};
use super::CropBox;
use crate::error::{Error, Result};
use crate::field::NerfactoField;

/// A nerfacto run placed in the world, sampled by its proposal networks.
#[derive(Clone)]
pub struct ProposalInstance {
    instance: Instance,
    field: Arc<NerfactoField>,
    /// A colour replacing the field's everywhere (indicator colours for coverage).
    indicator: Option<[f32; 3]>,
}

impl ProposalInstance {
    /// Places `field` by `world_from_field`; refuses a run without proposal networks.
    pub fn new(
        name: impl Into<String>,
        field: Arc<NerfactoField>,
        world_from_field: DMat4,
        crop: Option<CropBox>,
    ) -> Result<Self> {
        let name = name.into();
        if !field.has_proposal_sampler() {
            return Err(Error::invalid(
                format!("instance '{name}'"),
                "the nerfacto run's checkpoint holds no proposal networks, so it cannot be \
                 sampled as nerfstudio does: give the instance \"sampler\": \"occupancy\"",
            ));
        }
        let handle = FieldHandle::new(field.clone());
        let instance = Instance::new(name, handle, world_from_field, crop)?;
        Ok(ProposalInstance {
            instance,
            field,
            indicator: None,
        })
    }

    /// The same placement with another crop box.
    pub(crate) fn with_crop(&self, crop: Option<CropBox>) -> Result<Self> {
        let m = self.instance.world_from_field();
        Ok(Self {
            indicator: self.indicator,
            ..Self::new(self.name(), self.field.clone(), m, crop)?
        })
    }

    /// The instance coloured `rgb` everywhere, its sampling untouched (indicator colours
    /// for coverage, `scene::indicator`).
    pub(crate) fn with_indicator(self, rgb: Option<[f32; 3]>) -> Self {
        Self {
            indicator: rgb,
            ..self
        }
    }

    /// The colour replacing the field's, if any.
    pub(crate) fn indicator(&self) -> Option<[f32; 3]> {
        self.indicator
    }

    /// The instance's name.
    pub fn name(&self) -> &str {
        &self.instance.name
    }

    /// The run.
    pub fn field(&self) -> &NerfactoField {
        &self.field
    }

    /// The placement and crop (the run as a plain instance).
    pub(crate) fn instance(&self) -> &Instance {
        &self.instance
    }
}
