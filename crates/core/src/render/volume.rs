//! The instances sampled by their trainer's own estimator, whose samples join the march as
//! fragments: nerfstudio's proposal sampler (module `proposal`) and instant-ngp's marcher
//! (module `ngp`).

use super::fragment::Fragment;
use super::ngp::{self, NgpFill};
use super::proposal::{self, ProposalFill};
use super::RenderStats;
use crate::camera::Ray;
use crate::field::ColorSpace;
use crate::scene::{NgpInstance, ProposalInstance};

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
