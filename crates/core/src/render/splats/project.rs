//! Projection of each splat onto the image: gsplat's classic EWA splatting.
//!
//! In a camera frame with x right, y down and z forward (OpenCV's, gsplat's), a splat of
//! covariance `Σ = R S Sᵀ Rᵀ` (splat frame) has camera covariance `Σc = W Σ Wᵀ`, where `W`
//! is the linear part of `camera_from_splat` — which includes the instance's object transform,
//! so a non-uniformly scaled splat object stays exact. The image covariance is `J Σc Jᵀ` with
//! the perspective Jacobian at the mean, its `x/z`, `y/z` clamped to the frustum widened by
//! 30 % of its half-tangent (gsplat's guard against splats far outside the view), plus `0.3`
//! pixel² on the diagonal (the low-pass filter the splats were trained with).

use glam::{DMat3, DVec3, Vec3};

use crate::field::sh_basis;
use crate::field::CropClip;
use crate::field::{SplatColor, Splats};

/// Near cull of gsplat's rasteriser (camera z).
pub(crate) const NEAR_PLANE: f64 = 0.01;

/// How one set of splats is seen: a pinhole camera in gsplat's frame.
pub(crate) struct View {
    /// `camera_from_splat`'s linear part (x right, y down, z forward) and translation.
    pub linear: DMat3,
    pub translation: DVec3,
    /// `[fx, fy, cx, cy]` in pixels (raster y down, pixel centres at +0.5).
    pub(crate) intrinsics: [f64; 4],
    /// The whole image, in pixels.
    pub width: u32,
    pub height: u32,
    /// Camera z range kept.
    pub(crate) depth_range: [f64; 2],
    /// The camera centre in the splats' frame (SH directions are taken there).
    pub(crate) eye: DVec3,
    /// Mip-splatting's opacity compensation.
    pub antialiased: bool,
    /// Colours wanted.
    pub rgb: bool,
    /// Splats whose mean is outside are dropped.
    pub crop: Option<CropClip>,
}

/// A splat on the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Projected {
    /// Raster position of the mean.
    pub(crate) xy: [f32; 2],
    /// Inverse image covariance `(a, b, c)`: `σ = ½(a dx² + c dy²) + b dx dy`.
    pub(crate) conic: [f32; 3],
    /// Opacity (with the antialiasing compensation applied).
    pub opacity: f32,
    /// Camera z of the mean.
    pub z: f32,
    /// Colour in the space it was trained in (`SH + 0.5` clamped at 0, or a sigmoid).
    pub rgb: [f32; 3],
    /// Half side in pixels of the square that bounds it (`ceil(3·sqrt(λ_max))`).
    pub radius: f32,
}

/// Projects splat `i`, or `None` when it is culled (behind the near plane or beyond the far
/// one, cropped, degenerate, or wholly outside the image).
pub(crate) fn project(splats: &Splats, i: usize, view: &View) -> Option<Projected> {
    let mean = splats.means[i].as_dvec3();
    if let Some(crop) = &view.crop {
        if !crop.contains(mean) {
            return None;
        }
    }
    let p = view.linear * mean + view.translation;
    if !(p.z > view.depth_range[0] && p.z < view.depth_range[1]) {
        return None;
    }
    let rs = DMat3::from_quat(splats.rotations[i].as_dquat())
        * DMat3::from_diagonal(splats.scales[i].as_dvec3());
    let m = view.linear * rs;
    let cov = m * m.transpose();

    let [fx, fy, cx, cy] = view.intrinsics;
    let (w, h) = (f64::from(view.width), f64::from(view.height));
    let (tan_x, tan_y) = (0.5 * w / fx, 0.5 * h / fy);
    let lim_x = [cx / fx + 0.3 * tan_x, (w - cx) / fx + 0.3 * tan_x];
    let lim_y = [cy / fy + 0.3 * tan_y, (h - cy) / fy + 0.3 * tan_y];
    let z = p.z;
    let tx = z * (p.x / z).clamp(-lim_x[0], lim_x[1]);
    let ty = z * (p.y / z).clamp(-lim_y[0], lim_y[1]);
    // Rows of J (the third column of each is the z derivative).
    let j0 = DVec3::new(fx / z, 0.0, -fx * tx / (z * z));
    let j1 = DVec3::new(0.0, fy / z, -fy * ty / (z * z));
    let (cj0, cj1) = (cov * j0, cov * j1);
    let (a0, b, c0) = (j0.dot(cj0), j0.dot(cj1), j1.dot(cj1));
    let det_raw = a0 * c0 - b * b;
    let (a, c) = (a0 + 0.3, c0 + 0.3);
    let det = a * c - b * b;
    if det.is_nan() || det <= 0.0 {
        return None;
    }
    let mid = 0.5 * (a + c);
    let lambda = mid + (mid * mid - det).max(0.01).sqrt();
    let radius = (3.0 * lambda.sqrt()).ceil();
    let xy = [fx * p.x / z + cx, fy * p.y / z + cy];
    let inside =
        xy[0] + radius > 0.0 && xy[0] - radius < w && xy[1] + radius > 0.0 && xy[1] - radius < h;
    if !inside || !radius.is_finite() {
        return None;
    }
    let mut opacity = splats.opacities[i];
    if view.antialiased {
        opacity *= (det_raw / det).max(0.0).sqrt() as f32;
    }
    let rgb = if view.rgb {
        color(splats, i, (mean - view.eye).as_vec3())
    } else {
        [0.0; 3]
    };
    Some(Projected {
        xy: [xy[0] as f32, xy[1] as f32],
        conic: [(c / det) as f32, (-b / det) as f32, (a / det) as f32],
        opacity,
        z: z as f32,
        rgb,
        radius: radius as f32,
    })
}

/// Splat `i`'s colour seen along `view_dir` (camera centre to mean, splat frame).
pub(super) fn color(splats: &Splats, i: usize, view_dir: Vec3) -> [f32; 3] {
    let n = splats.color.coefficients();
    let k = &splats.coefficients[i * n * 3..(i + 1) * n * 3];
    match splats.color {
        SplatColor::Sigmoid => [0, 1, 2].map(|c| 1.0 / (1.0 + (-k[c]).exp())),
        SplatColor::Sh { .. } => {
            let basis = sh_basis(view_dir.normalize_or_zero());
            let mut rgb = [0.5f32; 3];
            for (y, coeffs) in basis.iter().zip(k.chunks_exact(3)) {
                for c in 0..3 {
                    rgb[c] += y * coeffs[c];
                }
            }
            rgb.map(|v| v.max(0.0))
        }
    }
}
