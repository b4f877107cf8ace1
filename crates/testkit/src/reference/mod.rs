//! The reference: exact per-pixel integrals of analytic scenes, and the error metrics the
//! renderer's quality presets are measured with.
//!
//! It shares nothing with the marcher in [`nerfx_core::render`] but the scene description: no
//! samples, no occupancy, no f32. Along each world ray the primitives of every instance
//! become intervals of world distance ([`ReferenceScene`]); a sweep over their sorted ends
//! integrates each piece exactly — constant densities in closed form, Gaussian blobs with a
//! closed-form (erf) optical depth and adaptive Gauss–Kronrod quadrature for colour and
//! depth. The physics is the rendering rules of docs/src/architecture.md taken to the limit of zero step size:
//! `C = ∫ T(t) Σₖ σₖ(t) cₖ dt`, `T(t) = exp(−∫₀ᵗ σ)`, `A = 1 − T(∞)`, expected depth
//! `∫ t σ T dt / A`, median depth where `1 − T(t) = A/2`.
//!
//! [`render`] does this for every pixel of a window; [`metrics`] compares two renders.
//! Trained fields have no closed form: [`render_trained`] integrates those cut by an
//! occupancy mask by an adaptive quadrature, to a stated tolerance.

mod closed_form;
mod integrator;
pub mod metrics;
mod quadrature;
mod segments;
mod trained;

pub use integrator::RayResult;
pub use metrics::ErrorReport;
pub use segments::ReferenceScene;
pub use trained::TrainedReference;

use rayon::prelude::*;

use integrator::Sweep;
use nerfx_core::camera::{Camera, Ray};
use nerfx_core::error::Result;
use nerfx_core::image::{Plane, Planes, Window};
use nerfx_core::scene::Scene;

/// Renders every pixel of `window` (raster centres `x + 0.5`, `y + 0.5`) exactly, in
/// parallel over rows, with all planes present: premultiplied RGB, alpha, depth as camera
/// Z (`depth_ray · z_per_t`), depth along the ray and median depth, as f32. Pixels without
/// a ray or without density are transparent black with infinite depths.
///
/// [`nerfx_core::Error::Unsupported`] when an instance's field is not analytic.
pub fn render(scene: &Scene, camera: &Camera, window: Window) -> Result<Planes> {
    let reference = ReferenceScene::new(scene)?;
    render_rays(camera, window, Sweep::default, |ray, sweep| {
        reference.integrate_with(ray, sweep)
    })
}

/// [`render`] for scenes of trained fields cut by an occupancy mask (instant-ngp), which
/// have no closed form: an adaptive f64 quadrature of each ray between its mask's
/// crossings ([`TrainedReference`]), each interval converged to `tolerance`.
///
/// [`nerfx_core::Error::Unsupported`] when an instance's field gives no mask segments.
pub fn render_trained(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    tolerance: f64,
) -> Result<Planes> {
    let reference = TrainedReference::new(scene, tolerance)?;
    render_rays(camera, window, trained::Scratch::default, |ray, scratch| {
        reference.integrate_with(ray, scratch)
    })
}

/// Every pixel of `window` by `integrate` (with per-thread scratch from `scratch`), rows
/// in parallel, as planes.
fn render_rays<S>(
    camera: &Camera,
    window: Window,
    scratch: impl Fn() -> S + Sync + Send,
    integrate: impl Fn(&Ray, &mut S) -> RayResult + Sync + Send,
) -> Result<Planes> {
    let window = camera.clamp_window(window)?;
    let (width, height) = (window.width(), window.height());
    let mut pixels = vec![(RayResult::EMPTY, 1.0); window.area()];
    if width > 0 {
        pixels
            .par_chunks_mut(width as usize)
            .enumerate()
            .for_each_init(&scratch, |s, (row, out)| {
                let y = (window.y0 as usize + row) as f64 + 0.5;
                for (col, pixel) in out.iter_mut().enumerate() {
                    let x = (window.x0 as usize + col) as f64 + 0.5;
                    if let Some(ray) = camera.ray(x, y) {
                        *pixel = (integrate(&ray, s), ray.z_per_t);
                    }
                }
            });
    }
    let plane = |value: &dyn Fn(&(RayResult, f64)) -> f64| Plane {
        width,
        height,
        data: pixels.iter().map(|p| value(p) as f32).collect(),
    };
    Ok(Planes {
        width,
        height,
        rgb: Some([
            plane(&|(r, _)| r.rgb.x),
            plane(&|(r, _)| r.rgb.y),
            plane(&|(r, _)| r.rgb.z),
        ]),
        alpha: Some(plane(&|(r, _)| r.alpha)),
        depth_z: Some(plane(&|(r, z_per_t)| {
            if r.depth_ray.is_finite() {
                r.depth_ray * z_per_t
            } else {
                f64::INFINITY
            }
        })),
        depth_ray: Some(plane(&|(r, _)| r.depth_ray)),
        depth_median: Some(plane(&|(r, _)| r.depth_median)),
    })
}
