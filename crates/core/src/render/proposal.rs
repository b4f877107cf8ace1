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

use super::integrator::opacity;
use super::RenderStats;
use crate::camera::Ray;
use crate::field::{Fragment, Piece, SamplerRay, SamplerScratch};
use crate::scene::ProposalInstance;

/// Per-thread buffers.
#[derive(Default)]
pub(super) struct ProposalScratch {
    rays: Vec<SamplerRay>,
    /// Per sampled ray: the pixel and field units per world unit.
    owners: Vec<(u32, f64)>,
    pieces: Vec<Piece>,
    sampler: SamplerScratch,
}

/// Appends to `out[i]` the fragments of `inst` along `rays[i]`, front to back (the marcher
/// sorts a ray's fragments when several instances gave them).
pub(super) fn fill(
    inst: &ProposalInstance,
    rays: &[Option<Ray>],
    s: &mut ProposalScratch,
    out: &mut [Vec<Fragment>],
    stats: &mut RenderStats,
) {
    s.rays.clear();
    s.owners.clear();
    for (i, ray) in rays.iter().enumerate() {
        if let Some((r, k)) = ray.as_ref().and_then(|r| inst.sampler_ray(r)) {
            s.rays.push(r);
            s.owners.push((i as u32, k));
        }
    }
    if s.rays.is_empty() {
        return;
    }
    s.pieces.clear();
    let Some(done) = inst
        .field()
        .sample_rays(&s.rays, &mut s.pieces, &mut s.sampler)
    else {
        return;
    };
    stats.density_samples += done.proposal_queries + done.main_queries;
    stats.color_samples += done.color_queries;
    stats.invalid_samples += done.invalid_samples;
    let per_ray = s.pieces.len() / s.rays.len();
    for (&(i, k), pieces) in s.owners.iter().zip(s.pieces.chunks_exact(per_ray)) {
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
