//! instant-ngp snapshots placed in the world and marched by instant-ngp's own marcher
//! (what its viewer shows), instead of nerfx's occupancy marcher.
//!
//! How a world ray becomes the ray instant-ngp's marcher walks is the renderer's
//! ([`crate::render::ngp_ray`]).

use std::sync::Arc;

use glam::DMat4;

use super::instance::{FieldHandle, Instance};
use super::CropBox;
use crate::error::Result;
use crate::field::IngpField;

/// An instant-ngp snapshot placed in the world, marched by instant-ngp's marcher.
#[derive(Clone)]
pub struct NgpInstance {
    instance: Instance,
    field: Arc<IngpField>,
    /// A colour replacing the field's everywhere (indicator colours for coverage).
    indicator: Option<[f32; 3]>,
}

impl NgpInstance {
    /// Places `field` by `world_from_field`.
    pub fn new(
        name: impl Into<String>,
        field: Arc<IngpField>,
        world_from_field: DMat4,
        crop: Option<CropBox>,
    ) -> Result<Self> {
        let handle = FieldHandle::new(field.clone());
        let instance = Instance::new(name, handle, world_from_field, crop)?;
        Ok(NgpInstance {
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

    /// The snapshot.
    pub fn field(&self) -> &IngpField {
        &self.field
    }

    /// The placement and crop (the snapshot as a plain instance).
    pub(crate) fn instance(&self) -> &Instance {
        &self.instance
    }
}
