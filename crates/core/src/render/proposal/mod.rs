//! The samples of the scene's proposal-sampled nerfacto instances, delivered per pixel as
//! fragments that the marcher merges front to back with its own pieces and the splats'
//! fragments (module `march`), so such an instance occludes and is occluded by the rest.
//!
//! Each main-field sample `[t₀, t₁]` of density σ becomes a fragment of opacity
//! `1 − e^{−σ(t₁ − t₀)}` at its midpoint (world distance `(t₀ + t₁)/(2k)`). Composited in
//! order, fragments give nerfstudio's weights exactly (`get_weights`: `w_i = α_i·Π_{j<i}(1 −
//! α_j)`), and its expected depth, which also takes each sample at its midpoint. Where
//! another instance's volume overlaps a sample, the sample counts as all at its midpoint.
//! nerfstudio's `last_sample` background (the last sample's colour filling `1 − acc`) is
//! not added: nerfx delivers premultiplied colour with alpha = accumulation.

mod sampler;
mod weights;

pub use sampler::{
    sample_proposals, ProposalRay, ProposalSample, ProposalScratch, ProposalStats,
    STOP_TRANSMITTANCE,
};

use crate::camera::Ray;
use crate::render::fragment::{Fragment, LocalRays};
use crate::render::integrator::opacity;
use crate::render::RenderStats;
use crate::scene::ProposalInstance;

/// Per-thread buffers.
#[derive(Default)]
pub(super) struct ProposalFill {
    /// The tile's rays in the field's frame.
    local: LocalRays<ProposalRay>,
    pieces: Vec<ProposalSample>,
    sampler: ProposalScratch,
}

/// Appends to `out[i]` the fragments of `inst` along `rays[i]`, front to back (the marcher
/// sorts a ray's fragments when several instances gave them).
pub(super) fn fill(
    inst: &ProposalInstance,
    rays: &[Option<Ray>],
    s: &mut ProposalFill,
    out: &mut [Vec<Fragment>],
    stats: &mut RenderStats,
) {
    s.local.collect(rays, |r| proposal_ray(inst, r));
    if s.local.rays.is_empty() {
        return;
    }
    s.pieces.clear();
    let Some(done) = sample_proposals(inst.field(), &s.local.rays, &mut s.pieces, &mut s.sampler)
    else {
        return;
    };
    stats.density_samples += done.proposal_queries + done.main_queries;
    stats.color_samples += done.color_queries;
    stats.invalid_samples += done.invalid_samples;
    let per_ray = s.pieces.len() / s.local.rays.len();
    for (&(i, k), pieces) in s.local.owners.iter().zip(s.pieces.chunks_exact(per_ray)) {
        let Some(ray) = &rays[i as usize] else {
            continue;
        };
        let fragments = &mut out[i as usize];
        fragments.extend(pieces.iter().filter_map(|p| {
            let t = 0.5 * (p.t0 + p.t1) / k;
            let alpha = opacity(f64::from(p.sigma) * (p.t1 - p.t0)) as f32;
            (alpha > 0.0 && t >= ray.near && t <= ray.far).then_some(Fragment {
                t,
                alpha,
                rgb: inst.indicator().unwrap_or(p.rgb),
            })
        }));
    }
}

/// The world ray `ray` as nerfstudio's sampler sees it in `inst`'s field, and the field units
/// per world unit along it; `None` when the crop box leaves nothing of it.
///
/// nerfstudio samples a ray from the camera (distance 0 at inference) to `far_plane` in its
/// normalised frame, the field's frame here: a world ray is carried into it by `N⁻¹`, its
/// direction renormalised, and field distances `u` convert back to world ones as `u / k`
/// with `k = |N⁻¹ d|` (see [`crate::scene`]). A crop box clips that span, as nerfstudio's
/// does.
pub fn proposal_ray(inst: &ProposalInstance, ray: &Ray) -> Option<(ProposalRay, f64)> {
    let m = inst.instance().field_from_world();
    let origin = m.transform_point3(ray.origin);
    let d = m.transform_vector3(ray.dir);
    let k = d.length();
    if !(k.is_finite() && k > 0.0) {
        return None;
    }
    let dir = d / k;
    let far = f64::from(inst.field().far_plane());
    let (near, far) = match inst.instance().crop_clip() {
        Some(c) => c.clip(origin, dir, 0.0, far)?,
        None => (0.0, far),
    };
    (near < far).then_some((
        ProposalRay {
            origin,
            dir,
            near,
            far,
        },
        k,
    ))
}
