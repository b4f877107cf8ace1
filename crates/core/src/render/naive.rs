//! The baseline: a uniform-step marcher with no empty-space skipping, no early termination,
//! no refinement, colour at every sample with density. The benchmark measures the real marcher against it.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::integrator::{crossing_depth, RunningComposite};
use super::march::PixelResult;
use super::{bands, empty_planes, Outputs, RenderStats};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::field::{linear_to_srgb, ColorSpace};
use crate::image::{Planes, Window};
use crate::scene::Scene;

/// Renders with a fixed world-space `step`, sampling each step at its midpoint over the span
/// of all the instances' bounds a ray crosses.
pub fn render_naive(
    scene: &Scene,
    camera: &Camera,
    window: Window,
    step: f64,
    outputs: &Outputs,
) -> Result<(Planes, RenderStats)> {
    if !(step > 0.0 && step.is_finite()) {
        return Err(Error::invalid("naive step", format!("{step} is not > 0")));
    }
    if scene.splats().next().is_some() || scene.has_sampled() {
        return Err(Error::Unsupported(
            "the uniform-step baseline marches fields only; this scene holds splats or an \
             instance sampled by its trainer's own sampler"
                .into(),
        ));
    }
    let window = camera.clamp_window(window)?;
    let decode = scene.composite_space() == ColorSpace::Srgb;
    let mut planes = empty_planes(window, outputs);
    let counts = bands(&mut planes, 1)
        .into_par_iter()
        .map(|mut band| {
            let y = window.y0 + band.row;
            let mut counts = [0; 3];
            let pixels: Vec<PixelResult> = (window.x0..window.x1)
                .map(|x| naive_pixel(scene, camera, x, y, step, outputs, &mut counts))
                .collect();
            band.write(0, window.width(), &pixels, decode);
            counts
        })
        .reduce(|| [0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    let stats = RenderStats {
        pixels: window.area() as u64,
        density_samples: counts[0],
        color_samples: counts[1],
        invalid_samples: counts[2],
        ..RenderStats::default()
    };
    Ok((planes, stats))
}

fn naive_pixel(
    scene: &Scene,
    camera: &Camera,
    x: u32,
    y: u32,
    step: f64,
    outputs: &Outputs,
    counts: &mut [u64; 3],
) -> PixelResult {
    let [samples, colours, invalid] = counts;
    let mut result = PixelResult {
        depth_ray: f32::INFINITY,
        depth_z: f32::INFINITY,
        depth_median: f32::INFINITY,
        ..Default::default()
    };
    let Some(ray) = camera.ray(x as f64 + 0.5, y as f64 + 0.5) else {
        return result;
    };
    let locals: Vec<_> = scene
        .marched()
        .map(|inst| inst.local_ray(&ray, ray.near, ray.far))
        .collect();
    let near = locals
        .iter()
        .flatten()
        .map(|l| l.t_near)
        .fold(f64::INFINITY, f64::min);
    let far = locals.iter().flatten().map(|l| l.t_far).fold(0.0, f64::max);
    if near.is_nan() || far.is_nan() || near >= far {
        return result;
    }
    let n = ((far - near) / step).ceil() as usize;
    let ts: Vec<f64> = (0..n).map(|j| near + (j as f64 + 0.5) * step).collect();
    let mut sigma = vec![0.0f64; n];
    let mut rgb = vec![DVec3::ZERO; n];
    let (mut points, mut dirs, mut idx) = (Vec::new(), Vec::new(), Vec::new());
    let (mut dens, mut cols) = (Vec::new(), Vec::new());
    let (mut lit, mut lit_points) = (Vec::new(), Vec::new());
    let encode = scene.composite_space() == ColorSpace::Srgb;
    for (inst, local) in scene.marched().zip(&locals) {
        let Some(lr) = local else { continue };
        points.clear();
        idx.clear();
        for (j, &t) in ts.iter().enumerate() {
            if t >= lr.t_near && t <= lr.t_far {
                points.push(lr.at(t));
                idx.push(j);
            }
        }
        dens.clear();
        dens.resize(points.len(), 0.0f32);
        inst.field().density(&points, &mut dens);
        *samples += points.len() as u64;
        // Colour only where there is density: elsewhere it is weighed by zero.
        lit.clear();
        lit_points.clear();
        // As the marcher takes them: a NaN or infinite density is empty, and counted.
        for d in dens.iter_mut() {
            if !d.is_finite() {
                *invalid += 1;
            }
            *d = if d.is_finite() && *d > 0.0 { *d } else { 0.0 };
        }
        for (k, (&j, &d)) in idx.iter().zip(&dens).enumerate() {
            if d > 0.0 {
                sigma[j] += d as f64 * lr.units_per_world as f64;
                lit.push(k);
                lit_points.push(points[k]);
            }
        }
        if !outputs.rgb || lit.is_empty() {
            continue;
        }
        dirs.clear();
        dirs.resize(lit.len(), lr.dir);
        cols.clear();
        cols.resize(lit.len(), Vec3::ZERO);
        inst.field().radiance(&lit_points, &dirs, &mut cols);
        *colours += lit.len() as u64;
        if encode && inst.field().color_space() == ColorSpace::Linear {
            cols.iter_mut().for_each(|c| *c = c.map(linear_to_srgb));
        }
        for (&k, c) in lit.iter().zip(&cols) {
            let s = dens[k] as f64 * lr.units_per_world as f64;
            // A non-finite colour adds nothing, as in the marcher.
            let c = c.as_dvec3().max(DVec3::ZERO);
            if c.is_finite() {
                rgb[idx[k]] += c * s;
            }
        }
    }
    let mut pieces = RunningComposite::new();
    let mut color = DVec3::ZERO;
    let mut log = Vec::new();
    for j in 0..n {
        let t_enter = pieces.transmittance();
        let w = pieces.add(ts[j] - 0.5 * step, step, sigma[j]);
        if w > 0.0 {
            color += rgb[j] / sigma[j] * w;
            let x = sigma[j] * step;
            log.push([ts[j] - 0.5 * step, step, x, x, t_enter]);
        }
    }
    let alpha = pieces.accumulation();
    let depth = pieces.expected_depth();
    result.rgb = color.as_vec3().to_array();
    result.alpha = alpha as f32;
    result.depth_ray = depth as f32;
    result.depth_z = (depth * ray.z_per_t) as f32;
    result.depth_median = crossing_depth(&log, 0.5 * alpha) as f32;
    result
}
