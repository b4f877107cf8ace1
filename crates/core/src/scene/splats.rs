//! Splats placed in the world.
//!
//! An affine object transform takes a Gaussian to a Gaussian (`μ' = Nμ`, `Σ' = A Σ Aᵀ` with
//! `A` the linear part of `N`), so a splat instance is rendered exactly, non-uniform scale
//! included, by projecting straight from the splats' own frame with `camera_from_world · N`.

use std::sync::Arc;

use glam::DMat4;

use super::instance::check_placement;
use super::CropBox;
use crate::error::Result;
use crate::field::Splats;

/// A set of splats placed in the world.
#[derive(Clone)]
pub struct SplatInstance {
    /// A name for messages (the scene file's instance name).
    pub name: String,
    splats: Arc<Splats>,
    world_from_splats: DMat4,
    splats_from_world: DMat4,
    crop: Option<CropBox>,
    antialiased: bool,
}

impl SplatInstance {
    /// Places `splats` by `world_from_splats` (the NeRF object's `matrix_world`); `crop` (in
    /// the splats' frame) drops the splats whose mean is outside it; `antialiased` selects
    /// mip-splatting's opacity compensation (for splats trained with it).
    pub fn new(
        name: impl Into<String>,
        splats: Arc<Splats>,
        world_from_splats: DMat4,
        crop: Option<CropBox>,
        antialiased: bool,
    ) -> Result<Self> {
        let name = name.into();
        let splats_from_world = check_placement(&name, world_from_splats, crop.as_ref())?;
        Ok(SplatInstance {
            name,
            splats,
            world_from_splats,
            splats_from_world,
            crop,
            antialiased,
        })
    }

    /// The same placement with another crop box.
    pub(crate) fn with_crop(&self, crop: Option<CropBox>) -> Result<Self> {
        let (name, splats) = (self.name.clone(), self.splats.clone());
        Self::new(name, splats, self.world_from_splats, crop, self.antialiased)
    }

    /// The splats.
    pub fn splats(&self) -> &Splats {
        &self.splats
    }

    /// `N`, the object transform.
    pub(crate) fn world_from_splats(&self) -> DMat4 {
        self.world_from_splats
    }

    /// `N⁻¹`.
    pub(crate) fn splats_from_world(&self) -> DMat4 {
        self.splats_from_world
    }

    /// The crop box, in the splats' frame.
    pub fn crop(&self) -> Option<&CropBox> {
        self.crop.as_ref()
    }

    /// Whether mip-splatting's compensation is applied.
    pub fn antialiased(&self) -> bool {
        self.antialiased
    }
}
