//! The samplers of a scene's instances, prepared once per render.
//!
//! Each instance's sampler was chosen when the scene was loaded (its
//! [`SceneInstance`](crate::scene::SceneInstance) kind). The marched instances are planned
//! together ([`InstancePlan`]): integrated in closed form where every one is analytic and
//! the preset asks for it
//! ([`MarchParams::closed_form`](super::MarchParams::closed_form)), else marched along each
//! ray's runs (module `runs`: a field's spans, its mask's segments or its occupied cells).
//! The instances sampled by their trainer's own estimator ([`VolumeSampler`]) and the splats
//! (module `splats`) give each ray's fragments front to back. The integrator merges a ray's
//! pieces and fragments in depth order (module `march`), whoever sampled them.

use super::march::InstancePlan;
use super::splats::{splat_layer, Splatting};
use super::volume::VolumeSampler;
use super::RenderSettings;
use crate::camera::Camera;
use crate::error::Result;
use crate::field::ColorSpace;
use crate::image::Window;
use crate::scene::Scene;

/// Every instance of a scene with its sampler, for one render.
pub(super) struct Samplers<'a> {
    /// The space the scene's colours are composited in ([`Scene::composite_space`]).
    pub(crate) space: ColorSpace,
    /// The marched instances, in the scene's order.
    pub(crate) plans: Vec<InstancePlan<'a>>,
    /// The marched instances are integrated in closed form (and there is nothing else).
    pub(crate) closed_form: bool,
    /// The instances sampled by their trainer's estimator: the proposal-sampled ones, then
    /// the instant-ngp ones, each kind in the scene's order.
    pub(crate) volume: Vec<VolumeSampler<'a>>,
    /// The splats' layer, when the scene holds splats.
    pub splats: Option<Splatting>,
}

impl<'a> Samplers<'a> {
    /// The samplers of `scene`'s instances for a render of `window` through `camera`.
    pub(crate) fn for_scene(
        scene: &'a Scene,
        camera: &Camera,
        window: Window,
        settings: &RenderSettings,
    ) -> Result<Self> {
        let space = scene.composite_space();
        let plans = InstancePlan::for_scene(scene, space, &settings.march);
        let volume: Vec<VolumeSampler<'a>> = (scene.proposal().map(VolumeSampler::Proposal))
            .chain(scene.ngp().map(|n| VolumeSampler::Ngp(n, space)))
            .collect();
        let splats = splat_layer(scene, camera, window, &settings.outputs)?;
        // Closed form integrates marched instances alone: no fragments to merge.
        let closed_form = settings.march.closed_form
            && volume.is_empty()
            && splats.is_none()
            && plans
                .iter()
                .all(|p| p.instance.handle().as_analytic().is_some());
        Ok(Samplers {
            space,
            plans,
            closed_form,
            volume,
            splats,
        })
    }
}
