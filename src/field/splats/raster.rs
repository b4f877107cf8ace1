//! A frame's splats, binned to image tiles and sorted by depth, and the fragments each pixel
//! gets from them.
//!
//! As in gsplat, a splat reaches every pixel of each 16×16 image tile its bounding square
//! touches (tiles anchored at the image's corner, whatever window is rendered, so a crop of a
//! render equals the render cropped), and a pixel meets its splats in order of the camera z of
//! their means. Only tiles of the render window are binned.

use rayon::prelude::*;

use super::project::{project, Projected, View};
use super::Splats;
use crate::image::Window;

/// Side of gsplat's image tiles, in pixels.
const TILE: u32 = 16;
/// Fragments fainter than this are skipped (gsplat's `1/255`).
const MIN_ALPHA: f32 = 1.0 / 255.0;
/// Largest fragment opacity.
const MAX_ALPHA: f32 = 0.999;
/// A pixel stops before its transmittance would fall to this.
pub(crate) const MIN_TRANSMITTANCE: f64 = 1e-4;

/// One splat's contribution to one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Fragment {
    /// Distance along the pixel's world ray (`z / z_per_t` of the splat's mean).
    pub t: f64,
    pub alpha: f32,
    /// Colour in the trained space.
    pub rgb: [f32; 3],
}

/// What a pixel loop reads of a splat, stored per tile entry so the loop walks memory in
/// order.
#[derive(Clone, Copy, Debug, Default)]
struct Entry {
    xy: [f32; 2],
    conic: [f32; 3],
    opacity: f32,
    /// `ln(255·opacity)` plus a margin: beyond this σ the fragment is below 1/255, so the
    /// exponential need not be taken.
    sigma_cut: f32,
    /// Index into the projected splats (depth and colour).
    splat: u32,
}

/// The splats of a frame, projected, sorted and binned.
pub(crate) struct SplatLayer {
    projected: Vec<Projected>,
    /// Per tile of `tiles`: where its entries start in `entries` (one more at the end).
    starts: Vec<u32>,
    entries: Vec<Entry>,
    /// Tile coordinates covered: `[x0, y0, x1, y1)`.
    tiles: [u32; 4],
}

impl SplatLayer {
    /// Projects every set of splats with its view and bins them to the tiles `window` touches.
    pub fn build(sets: &[(&Splats, View)], window: Window) -> SplatLayer {
        let mut projected: Vec<Projected> = Vec::new();
        for (splats, view) in sets {
            projected.par_extend(
                (0..splats.len())
                    .into_par_iter()
                    .filter_map(|i| project(splats, i, view)),
            );
        }
        projected.par_sort_by(|a, b| a.z.total_cmp(&b.z));

        let tiles = [
            window.x0 / TILE,
            window.y0 / TILE,
            window.x1.div_ceil(TILE),
            window.y1.div_ceil(TILE),
        ];
        let tiles_x = (tiles[2] - tiles[0]) as usize;
        let n_tiles = tiles_x * (tiles[3] - tiles[1]) as usize;
        let range = |p: &Projected| {
            let (x, y, r) = (
                p.xy[0] / TILE as f32,
                p.xy[1] / TILE as f32,
                p.radius / TILE as f32,
            );
            let clamp = |v: f32, lo: u32, hi: u32| (v.max(0.0) as u32).clamp(lo, hi);
            [
                clamp((x - r).floor(), tiles[0], tiles[2]),
                clamp((y - r).floor(), tiles[1], tiles[3]),
                clamp((x + r).ceil(), tiles[0], tiles[2]),
                clamp((y + r).ceil(), tiles[1], tiles[3]),
            ]
        };
        let mut counts = vec![0u32; n_tiles + 1];
        for p in &projected {
            let [x0, y0, x1, y1] = range(p);
            for ty in y0..y1 {
                let row = (ty - tiles[1]) as usize * tiles_x;
                for tx in x0..x1 {
                    counts[row + (tx - tiles[0]) as usize + 1] += 1;
                }
            }
        }
        for i in 1..counts.len() {
            counts[i] += counts[i - 1];
        }
        let starts = counts.clone();
        let mut entries = vec![Entry::default(); counts[n_tiles] as usize];
        for (i, p) in projected.iter().enumerate() {
            let entry = Entry {
                xy: p.xy,
                conic: p.conic,
                opacity: p.opacity,
                sigma_cut: (255.0 * p.opacity).ln() + 1e-3,
                splat: i as u32,
            };
            let [x0, y0, x1, y1] = range(p);
            for ty in y0..y1 {
                let row = (ty - tiles[1]) as usize * tiles_x;
                for tx in x0..x1 {
                    let slot = &mut counts[row + (tx - tiles[0]) as usize];
                    entries[*slot as usize] = entry;
                    *slot += 1;
                }
            }
        }
        SplatLayer {
            projected,
            starts,
            entries,
            tiles,
        }
    }

    /// Appends the fragments of pixel (`x`, `y`) front to back, `z_per_t` converting camera z
    /// to ray distance, up to the one that brings the pixel's transmittance (from splats
    /// alone) to [`MIN_TRANSMITTANCE`] or below.
    pub fn fragments(&self, x: u32, y: u32, z_per_t: f64, out: &mut Vec<Fragment>) {
        let (tx, ty) = (x / TILE, y / TILE);
        if tx < self.tiles[0] || tx >= self.tiles[2] || ty < self.tiles[1] || ty >= self.tiles[3] {
            return;
        }
        let tile = (ty - self.tiles[1]) as usize * (self.tiles[2] - self.tiles[0]) as usize
            + (tx - self.tiles[0]) as usize;
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        let mut transmittance = 1.0f64;
        for e in &self.entries[self.starts[tile] as usize..self.starts[tile + 1] as usize] {
            let (dx, dy) = (e.xy[0] - px, e.xy[1] - py);
            let [a, b, c] = e.conic;
            let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
            if sigma < 0.0 || sigma > e.sigma_cut {
                continue;
            }
            let alpha = (e.opacity * (-sigma).exp()).min(MAX_ALPHA);
            if alpha.is_nan() || alpha < MIN_ALPHA {
                continue;
            }
            let p = &self.projected[e.splat as usize];
            out.push(Fragment {
                t: f64::from(p.z) / z_per_t,
                alpha,
                rgb: p.rgb,
            });
            transmittance *= 1.0 - f64::from(alpha);
            if transmittance <= MIN_TRANSMITTANCE {
                return;
            }
        }
    }
}
