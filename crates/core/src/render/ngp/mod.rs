//! The samples of the scene's instant-ngp instances marched by instant-ngp's own marcher,
//! delivered per pixel as fragments that the marcher merges front to back with its own
//! pieces and the other fragments (module `march`), as the proposal-sampled instances'
//! are (module `proposal`).
//!
//! Each sample becomes a fragment at its position (world distance `t/k`) with the opacity
//! and colour instant-ngp composites it with, the early stop's renormalisation folded in
//! (see [`NgpSample`]): composited alone they give instant-ngp's pixel. Where
//! another instance's volume overlaps a sample's step, the sample counts as all at its
//! position. Colours are in the field's trained space, encoded to sRGB when the scene
//! composites in sRGB and the snapshot is HDR (linear).

mod marcher;

pub use marcher::{march_ngp, NgpRay, NgpSample, NgpScratch, NgpStats, NGP_MAX_STEPS};

use crate::camera::Ray;
use crate::field::{linear_to_srgb, ColorSpace, Field};
use crate::render::fragment::{Fragment, LocalRays};
use crate::render::RenderStats;
use crate::scene::NgpInstance;

/// Per-thread buffers.
#[derive(Default)]
pub(super) struct NgpFill {
    /// The tile's rays in the field's frame.
    local: LocalRays<NgpRay>,
    samples: Vec<Vec<NgpSample>>,
    marcher: NgpScratch,
}

/// Appends to `out[i]` the fragments of `inst` along `rays[i]`, front to back (the caller
/// sorts when fragments of several sources meet); `space`: the scene's composite space.
pub(super) fn fill(
    inst: &NgpInstance,
    space: ColorSpace,
    rays: &[Option<Ray>],
    s: &mut NgpFill,
    out: &mut [Vec<Fragment>],
    stats: &mut RenderStats,
) {
    s.local.collect(rays, |r| ngp_ray(inst, r));
    if s.local.rays.is_empty() {
        return;
    }
    if s.samples.len() < s.local.rays.len() {
        s.samples.resize_with(s.local.rays.len(), Vec::new);
    }
    let field = inst.field();
    let samples = &mut s.samples[..s.local.rays.len()];
    let done = march_ngp(field, &s.local.rays, NGP_MAX_STEPS, samples, &mut s.marcher);
    stats.density_samples += done.samples;
    stats.color_samples += done.color_queries;
    stats.budget_limited_rays += done.capped;
    stats.invalid_samples += done.invalid;
    let encode = space == ColorSpace::Srgb && field.color_space() == ColorSpace::Linear;
    for (&(i, k), samples) in s.local.owners.iter().zip(samples.iter()) {
        out[i as usize].extend(samples.iter().filter(|f| f.alpha > 0.0).map(|f| Fragment {
            t: f.t / k,
            alpha: f.alpha,
            rgb: match inst.indicator() {
                Some(rgb) => rgb,
                None if encode => f.rgb.map(linear_to_srgb),
                None => f.rgb,
            },
        }));
    }
}

/// The world ray `ray` as instant-ngp's marcher sees it in `inst`'s snapshot, from the
/// camera, and the field units per world unit along it; `None` when it misses the field's
/// box or crop.
///
/// instant-ngp's step grows with the distance from the camera, so the march starts from the
/// camera: a world ray is carried into the field's frame by `N⁻¹`, its direction
/// renormalised, and field distances `u` convert back to world ones as `u / k` with
/// `k = |N⁻¹ d|` (see [`crate::scene`]). The field's box, the crop box and the camera's
/// clipping range bound the march.
pub fn ngp_ray(inst: &NgpInstance, ray: &Ray) -> Option<(NgpRay, f64)> {
    let lr = inst.instance().local_ray(ray, ray.near, ray.far)?;
    let m = inst.instance().field_from_world();
    let d = m.transform_vector3(ray.dir);
    let k = d.length();
    if !(k.is_finite() && k > 0.0) {
        return None;
    }
    Some((
        NgpRay {
            origin: m.transform_point3(ray.origin),
            dir: d / k,
            near: lr.t_near * k,
            far: lr.t_far * k,
        },
        k,
    ))
}
