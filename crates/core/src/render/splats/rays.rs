//! Splats seen through panoramic cameras (equirectangular, ODS, VR180), where no single
//! pinhole exists to project onto: each pixel's own ray meets each Gaussian.
//!
//! Along a ray `o + t·d`, a Gaussian's exponent `½ (x − μ)ᵀ Σ⁻¹ (x − μ)` is smallest at
//! `t* = dᵀΣ⁻¹m / dᵀΣ⁻¹d` (`m = μ − o`), where it is `½ (mᵀΣ⁻¹m − (dᵀΣ⁻¹m)² / dᵀΣ⁻¹d)`; that
//! minimum plays the part of gsplat's 2D `σ` (for a pixel near the view axis it is EWA's
//! projection without the affine approximation). gsplat's 0.3 px² low-pass becomes an
//! isotropic 3D term `0.3·(ω·r)²` added to `Σ`, with `ω` the camera's pixel angle and `r` the
//! splat's distance. Fragments are ordered by the distance of the means from the camera centre
//! and sit at `t*`. The approximation, measured against the pinhole rasteriser on a perspective
//! view in the tests, is stated in the guide (`docs/src/splats.md`).
//!
//! Splats are binned by direction from the camera centre into a longitude × latitude grid of
//! cells, each splat into the cells its cone of influence (where its opacity can reach 1/255,
//! widened by the largest eye offset of a stereo camera) touches.

use glam::{DMat3, DVec3, Vec3};
use rayon::prelude::*;

use super::project::color;
use super::raster::{MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::field::CropClip;
use crate::field::Splats;
use crate::render::fragment::Fragment;

/// Direction cells: longitude × latitude.
const CELLS_X: usize = 128;
const CELLS_Y: usize = 64;

/// How one set of splats is seen by a panoramic camera.
pub(crate) struct RayView {
    /// `world_from_splats`: linear part and translation.
    pub linear: DMat3,
    pub translation: DVec3,
    /// The camera centre (world) and `camera_from_world`'s rotation.
    pub centre: DVec3,
    pub(crate) camera_from_world: DMat3,
    /// Largest distance of a ray origin from the centre (stereo eyes).
    pub(crate) eye_offset: f64,
    /// Angle between neighbouring pixels, radians.
    pub(crate) pixel_angle: f64,
    /// The camera centre in the splats' frame (SH directions).
    pub(crate) eye: DVec3,
    /// Distance range kept.
    pub(crate) depth_range: [f64; 2],
    pub rgb: bool,
    pub crop: Option<CropClip>,
}

/// A splat as the pixel loop reads it.
#[derive(Clone, Copy, Debug)]
struct Entry {
    /// Mean relative to the camera centre.
    mean: Vec3,
    /// The dilated covariance's inverse: xx, xy, xz, yy, yz, zz.
    inverse: [f32; 6],
    opacity: f32,
    rgb: [f32; 3],
}

/// The splats of a frame binned by direction for per-pixel rays.
pub(crate) struct RayLayer {
    centre: DVec3,
    camera_from_world: DMat3,
    /// Per cell: where its entries start (one more at the end).
    starts: Vec<u32>,
    entries: Vec<Entry>,
}

/// A splat ready to bin: its entry, distance and cell ranges.
struct Binned {
    entry: Entry,
    distance: f64,
    /// `[lat0, lat1]` inclusive and `[lon0, lon1]` inclusive (`lon1 < lon0`: wraps), or all.
    cells: Option<[usize; 4]>,
}

impl RayLayer {
    /// Bins every set of splats with its view.
    pub fn build(sets: &[(&Splats, RayView)]) -> RayLayer {
        let mut binned: Vec<Binned> = Vec::new();
        let (mut centre, mut camera_from_world) = (DVec3::ZERO, DMat3::IDENTITY);
        for (splats, view) in sets {
            (centre, camera_from_world) = (view.centre, view.camera_from_world);
            binned.par_extend(
                (0..splats.len())
                    .into_par_iter()
                    .filter_map(|i| prepare(splats, i, view)),
            );
        }
        binned.par_sort_by(|a, b| a.distance.total_cmp(&b.distance));
        let mut counts = vec![0u32; CELLS_X * CELLS_Y + 1];
        let each_cell = |b: &Binned, f: &mut dyn FnMut(usize)| match b.cells {
            None => (0..CELLS_X * CELLS_Y).for_each(f),
            Some([y0, y1, x0, x1]) => {
                for y in y0..=y1 {
                    let mut x = x0;
                    loop {
                        f(y * CELLS_X + x);
                        if x == x1 {
                            break;
                        }
                        x = (x + 1) % CELLS_X;
                    }
                }
            }
        };
        for b in &binned {
            each_cell(b, &mut |c| counts[c + 1] += 1);
        }
        for i in 1..counts.len() {
            counts[i] += counts[i - 1];
        }
        let starts = counts.clone();
        let mut entries =
            vec![binned.first().map_or(EMPTY, |b| b.entry); counts[CELLS_X * CELLS_Y] as usize];
        for b in &binned {
            each_cell(b, &mut |c| {
                entries[counts[c] as usize] = b.entry;
                counts[c] += 1;
            });
        }
        RayLayer {
            centre,
            camera_from_world,
            starts,
            entries,
        }
    }

    /// Appends the fragments of the world ray `origin + t·dir` (`dir` unit) front to back,
    /// up to the one that brings its transmittance (from splats alone) to the floor.
    pub(crate) fn fragments(&self, origin: DVec3, dir: DVec3, out: &mut Vec<Fragment>) {
        let cell = cell_of(self.camera_from_world * dir);
        let o = (origin - self.centre).as_vec3();
        let d = dir.as_vec3();
        let mut transmittance = 1.0f64;
        for e in &self.entries[self.starts[cell] as usize..self.starts[cell + 1] as usize] {
            let m = e.mean - o;
            let [xx, xy, xz, yy, yz, zz] = e.inverse;
            let apply = |v: Vec3| {
                Vec3::new(
                    xx * v.x + xy * v.y + xz * v.z,
                    xy * v.x + yy * v.y + yz * v.z,
                    xz * v.x + yz * v.y + zz * v.z,
                )
            };
            let (im, id) = (apply(m), apply(d));
            let (dd, dm) = (d.dot(id), d.dot(im));
            if dd <= 0.0 || dm <= 0.0 {
                continue; // behind the ray's origin
            }
            let sigma = 0.5 * (m.dot(im) - dm * dm / dd).max(0.0);
            let alpha = (e.opacity * (-sigma).exp()).min(MAX_ALPHA);
            if alpha.is_nan() || alpha < MIN_ALPHA {
                continue;
            }
            out.push(Fragment {
                t: f64::from(dm / dd),
                alpha,
                rgb: e.rgb,
            });
            transmittance *= 1.0 - f64::from(alpha);
            if transmittance <= MIN_TRANSMITTANCE {
                return;
            }
        }
    }
}

const EMPTY: Entry = Entry {
    mean: Vec3::ZERO,
    inverse: [0.0; 6],
    opacity: 0.0,
    rgb: [0.0; 3],
};

/// The cell of a camera-space unit direction.
fn cell_of(d: DVec3) -> usize {
    let (lon, lat) = (d.x.atan2(d.z), d.y.clamp(-1.0, 1.0).asin());
    let x = ((lon / std::f64::consts::TAU + 0.5) * CELLS_X as f64) as usize;
    let y = ((lat / std::f64::consts::PI + 0.5) * CELLS_Y as f64) as usize;
    y.min(CELLS_Y - 1) * CELLS_X + x.min(CELLS_X - 1)
}

/// Splat `i` in the world, dilated, with its cells; `None` when culled.
fn prepare(splats: &Splats, i: usize, view: &RayView) -> Option<Binned> {
    let local = splats.means[i].as_dvec3();
    if view.crop.as_ref().is_some_and(|c| !c.contains(local)) {
        return None;
    }
    let mean = view.linear * local + view.translation;
    let rel = mean - view.centre;
    let distance = rel.length();
    if !(distance > view.depth_range[0] && distance < view.depth_range[1]) {
        return None;
    }
    let opacity = splats.opacities[i];
    // Where the opacity can reach 1/255: a Mahalanobis radius of sqrt(2 ln(255 o)).
    let reach = (2.0 * (255.0 * f64::from(opacity)).ln()).max(0.0).sqrt();
    if reach == 0.0 {
        return None;
    }
    let m = view.linear
        * DMat3::from_quat(splats.rotations[i].as_dquat())
        * DMat3::from_diagonal(splats.scales[i].as_dvec3());
    let blur = 0.3 * (view.pixel_angle * distance).powi(2);
    let cov = m * m.transpose() + DMat3::from_diagonal(DVec3::splat(blur));
    let inv = cov.inverse();
    if !inv.is_finite() {
        return None;
    }
    // λ_max ≤ trace: a conservative radius.
    let radius = reach * (cov.x_axis.x + cov.y_axis.y + cov.z_axis.z).sqrt() + view.eye_offset;
    let cells = if radius >= distance {
        None
    } else {
        let angle = (radius / distance).asin();
        let d = view.camera_from_world * (rel / distance);
        let lat = d.y.clamp(-1.0, 1.0).asin();
        let half_pi = std::f64::consts::FRAC_PI_2;
        let (lat0, lat1) = (lat - angle, lat + angle);
        let row = |l: f64| {
            (((l / std::f64::consts::PI + 0.5) * CELLS_Y as f64).floor() as i64)
                .clamp(0, CELLS_Y as i64 - 1) as usize
        };
        let widest = lat0.abs().max(lat1.abs());
        if lat1 >= half_pi || lat0 <= -half_pi || angle.sin() >= widest.cos() {
            Some([row(lat0), row(lat1), 0, CELLS_X - 1])
        } else {
            let spread = (angle.sin() / widest.cos()).asin();
            let lon = d.x.atan2(d.z);
            let column = |l: f64| {
                (((l / std::f64::consts::TAU + 0.5) * CELLS_X as f64).floor() as i64)
                    .rem_euclid(CELLS_X as i64) as usize
            };
            if 2.0 * spread >= std::f64::consts::TAU * (1.0 - 1.0 / CELLS_X as f64) {
                Some([row(lat0), row(lat1), 0, CELLS_X - 1])
            } else {
                Some([
                    row(lat0),
                    row(lat1),
                    column(lon - spread),
                    column(lon + spread),
                ])
            }
        }
    };
    let rgb = if view.rgb {
        color(splats, i, (local - view.eye).as_vec3())
    } else {
        [0.0; 3]
    };
    Some(Binned {
        entry: Entry {
            mean: rel.as_vec3(),
            inverse: [
                inv.x_axis.x as f32,
                inv.y_axis.x as f32,
                inv.z_axis.x as f32,
                inv.y_axis.y as f32,
                inv.z_axis.y as f32,
                inv.z_axis.z as f32,
            ],
            opacity,
            rgb,
        },
        distance,
        cells,
    })
}
