//! The samplers of a scene's instances, prepared once per render.
//!
//! Each instance's sampler was chosen when the scene was loaded (its [`SceneInstance`]
//! kind). The marched instances are planned together ([`InstancePlan`]): integrated in closed
//! form where every one is analytic and the preset asks for it
//! ([`MarchParams::closed_form`](super::MarchParams::closed_form)), else marched along each
//! ray's runs (module `runs`: a field's spans, its mask's segments or its occupied cells).
//! The instances sampled by their trainer's own estimator ([`VolumeSampler`]) and the splats
//! (module `splats`) give each ray's fragments front to back. The integrator merges a ray's
//! pieces and fragments in depth order (module `march`), whoever sampled them.

use super::march::InstancePlan;
use super::ngp::{self, NgpFill};
use super::proposal::{self, ProposalFill};
use super::splats::{splat_layer, Splatting};
use super::{RenderSettings, RenderStats};
use crate::camera::{Camera, Ray};
use crate::error::Result;
use crate::field::{ColorSpace, Fragment};
use crate::image::Window;
use crate::scene::{NgpInstance, ProposalInstance, Scene, SceneInstance};

/// Every instance of a scene with its sampler, for one render.
pub(super) struct Samplers<'a> {
    /// The marched instances, in the scene's order.
    pub plans: Vec<InstancePlan<'a>>,
    /// The marched instances are integrated in closed form (and there is nothing else).
    pub closed_form: bool,
    /// The instances sampled by their trainer's estimator: the proposal-sampled ones, then
    /// the instant-ngp ones, each kind in the scene's order.
    pub volume: Vec<VolumeSampler<'a>>,
    /// The splats' layer, when the scene holds splats.
    pub splats: Option<Splatting>,
}

impl<'a> Samplers<'a> {
    /// The samplers of `scene`'s instances for a render of `window` through `camera`.
    pub fn for_scene(
        scene: &'a Scene,
        camera: &Camera,
        window: Window,
        settings: &RenderSettings,
    ) -> Result<Self> {
        let plans = InstancePlan::for_scene(scene, &settings.march);
        let space = scene.composite_space();
        let volume: Vec<VolumeSampler<'a>> = (scene.proposal().map(VolumeSampler::Proposal))
            .chain(scene.ngp().map(|n| VolumeSampler::Ngp(n, space)))
            .collect();
        let only_marched = scene
            .instances()
            .iter()
            .all(|i| matches!(i, SceneInstance::Marched(_)));
        let closed_form = settings.march.closed_form
            && only_marched
            && scene.marched().all(|i| i.handle().as_analytic().is_some());
        Ok(Samplers {
            plans,
            closed_form,
            volume,
            splats: splat_layer(scene, camera, window, &settings.outputs)?,
        })
    }
}

/// An instance sampled by its trainer's own estimator, whose samples join the march as
/// fragments.
pub(super) enum VolumeSampler<'a> {
    /// nerfstudio's proposal sampler (module `proposal`).
    Proposal(&'a ProposalInstance),
    /// instant-ngp's marcher (module `ngp`), and the scene's composite space, which a linear
    /// snapshot's colours are encoded to.
    Ngp(&'a NgpInstance, ColorSpace),
}

/// Per-thread buffers of the volume samplers.
#[derive(Default)]
pub(super) struct VolumeScratch {
    proposal: ProposalFill,
    ngp: NgpFill,
}

impl VolumeSampler<'_> {
    /// Appends to `out[i]` the instance's fragments along `rays[i]`, front to back.
    pub fn fill(
        &self,
        rays: &[Option<Ray>],
        s: &mut VolumeScratch,
        out: &mut [Vec<Fragment>],
        stats: &mut RenderStats,
    ) {
        match *self {
            VolumeSampler::Proposal(inst) => {
                proposal::fill(inst, rays, &mut s.proposal, out, stats)
            }
            VolumeSampler::Ngp(inst, space) => ngp::fill(inst, space, rays, &mut s.ngp, out, stats),
        }
    }
}
