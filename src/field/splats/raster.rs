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
pub(super) const MIN_ALPHA: f32 = 1.0 / 255.0;
/// Largest fragment opacity.
pub(super) const MAX_ALPHA: f32 = 0.999;
/// A pixel stops before its transmittance would fall to this.
pub(crate) const MIN_TRANSMITTANCE: f64 = 1e-4;

/// `exp(−s)` for `s` in [0, 80], within a few ulp of the exact value, without branches or
/// calls so that a loop of them vectorises: `e^(−s) = 2^n · e^r` with `n = round(−s / ln 2)`,
/// `r = −s − n·ln 2` (ln 2 split in two, the first part with trailing zero bits so `n` times
/// it is exact) and `e^r` by its Taylor series to `r⁷` (`|r| ≤ ln 2 / 2`: truncation below
/// 6e-9 relative).
#[inline(always)]
fn exp_neg(s: f32) -> f32 {
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    let x = -s;
    let n = (x * std::f32::consts::LOG2_E).round();
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let mut p: f32 = 1.0 / 5040.0;
    for c in [
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    p * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

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
    /// Camera z of the mean.
    z: f32,
    /// Colour.
    rgb: [f32; 3],
    /// Half extents in x and y of the ellipse `σ ≤ sigma_cut`: no pixel centre farther from
    /// the mean gets a fragment (infinite for a degenerate conic).
    extent: [f32; 2],
}

impl Entry {
    fn new(p: &Projected) -> Entry {
        let sigma_cut = (255.0 * p.opacity).ln() + 1e-3;
        // σ = ½ dᵀQd ≤ s reaches |d_x| ≤ √(2s·Σ_xx), |d_y| ≤ √(2s·Σ_yy) with Σ = Q⁻¹.
        // In f64: the determinant of a thin splat's conic cancels.
        let [a, b, c] = p.conic.map(f64::from);
        let det = a * c - b * b;
        let reach = |q: f64| {
            let e = (2.0 * f64::from(sigma_cut.max(0.0)) * q / det).sqrt();
            if det > 0.0 && e.is_finite() {
                (e * (1.0 + 1e-3) + 1e-3) as f32
            } else {
                f32::INFINITY
            }
        };
        Entry {
            xy: p.xy,
            conic: p.conic,
            opacity: p.opacity,
            sigma_cut,
            z: p.z,
            rgb: p.rgb,
            extent: [reach(c), reach(a)],
        }
    }
}

/// The splats of a frame, projected, sorted and binned.
pub(crate) struct SplatLayer {
    /// Per row of tiles: where each tile's entries start (one more at the end), and the
    /// entries.
    rows: Vec<(Vec<u32>, Vec<Entry>)>,
    /// Tile coordinates covered: `[x0, y0, x1, y1)`.
    tiles: [u32; 4],
    /// The CPU has AVX2 and FMA: the pixel loop runs eight lanes wide.
    avx2: bool,
    /// Seconds spent projecting, and sorting and binning (for benchmarks).
    pub timings: [f64; 2],
}

impl SplatLayer {
    /// Projects every set of splats with its view and bins them to the tiles `window` touches.
    pub fn build(sets: &[(&Splats, View)], window: Window) -> SplatLayer {
        let start = std::time::Instant::now();
        let mut projected: Vec<Projected> = Vec::new();
        for (splats, view) in sets {
            projected.par_extend(
                (0..splats.len())
                    .into_par_iter()
                    .filter_map(|i| project(splats, i, view)),
            );
        }
        let projecting = start.elapsed().as_secs_f64();
        projected.par_sort_by(|a, b| a.z.total_cmp(&b.z));

        let tiles = [
            window.x0 / TILE,
            window.y0 / TILE,
            window.x1.div_ceil(TILE),
            window.y1.div_ceil(TILE),
        ];
        let tiles_x = (tiles[2] - tiles[0]) as usize;
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
        // Each splat is listed in the rows of tiles it touches (in depth order), then each
        // row is binned on its own (in parallel), so every tile's list comes out sorted.
        let ranges: Vec<[u32; 4]> = projected.par_iter().map(range).collect();
        let rows_n = (tiles[3] - tiles[1]) as usize;
        let mut row_starts = vec![0usize; rows_n + 1];
        for r in &ranges {
            for ty in r[1]..r[3] {
                row_starts[(ty - tiles[1]) as usize + 1] += 1;
            }
        }
        for i in 1..row_starts.len() {
            row_starts[i] += row_starts[i - 1];
        }
        let mut in_rows = vec![0u32; row_starts[rows_n]];
        let mut next = row_starts.clone();
        for (i, r) in ranges.iter().enumerate() {
            for ty in r[1]..r[3] {
                let slot = &mut next[(ty - tiles[1]) as usize];
                in_rows[*slot] = i as u32;
                *slot += 1;
            }
        }
        let rows: Vec<(Vec<u32>, Vec<Entry>)> = (0..rows_n)
            .into_par_iter()
            .map(|row| {
                let splats = &in_rows[row_starts[row]..row_starts[row + 1]];
                let mut counts = vec![0u32; tiles_x + 1];
                for &i in splats {
                    let r = &ranges[i as usize];
                    for tx in r[0]..r[2] {
                        counts[(tx - tiles[0]) as usize + 1] += 1;
                    }
                }
                for i in 1..counts.len() {
                    counts[i] += counts[i - 1];
                }
                let starts = counts.clone();
                let mut entries = vec![Entry::default(); counts[tiles_x] as usize];
                for &i in splats {
                    let r = &ranges[i as usize];
                    let entry = Entry::new(&projected[i as usize]);
                    for tx in r[0]..r[2] {
                        let slot = &mut counts[(tx - tiles[0]) as usize];
                        entries[*slot as usize] = entry;
                        *slot += 1;
                    }
                }
                (starts, entries)
            })
            .collect();
        #[cfg(target_arch = "x86_64")]
        let avx2 = is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma");
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        SplatLayer {
            rows,
            tiles,
            avx2,
            timings: [projecting, start.elapsed().as_secs_f64() - projecting],
        }
    }

    /// Fills each pixel's fragments for the pixels of `window` (row-major, `out[i]` and
    /// `z_per_t[i]` for its `i`-th pixel; a non-finite `z_per_t` marks a pixel without a
    /// ray), front to back, up to the one that brings the pixel's transmittance (from splats
    /// alone) to [`MIN_TRANSMITTANCE`] or below.
    ///
    /// Per image tile, the splats are walked once for all its pixels of the window, sixteen
    /// pixels at a time: the quadratic form is evaluated for the sixteen together (a loop the
    /// compiler vectorises), and only the pixels it reaches go on to the exponential.
    pub fn fill(&self, window: Window, z_per_t: &[f64], out: &mut [Vec<Fragment>]) {
        for ty in window.y0 / TILE..window.y1.div_ceil(TILE) {
            for tx in window.x0 / TILE..window.x1.div_ceil(TILE) {
                if tx < self.tiles[0]
                    || tx >= self.tiles[2]
                    || ty < self.tiles[1]
                    || ty >= self.tiles[3]
                {
                    continue;
                }
                let part = window.intersect(&Window::new(
                    tx * TILE,
                    ty * TILE,
                    (tx + 1) * TILE,
                    (ty + 1) * TILE,
                ));
                let (starts, entries) = &self.rows[(ty - self.tiles[1]) as usize];
                let col = (tx - self.tiles[0]) as usize;
                let tile = &entries[starts[col] as usize..starts[col + 1] as usize];
                self.fill_part(tile, window, part, z_per_t, out);
            }
        }
    }

    fn fill_part(
        &self,
        tile: &[Entry],
        window: Window,
        part: Window,
        z_per_t: &[f64],
        out: &mut [Vec<Fragment>],
    ) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `build` found AVX2 and FMA on this CPU.
            return unsafe { self.fill_part_avx2(tile, window, part, z_per_t, out) };
        }
        self.fill_part_lanes(tile, window, part, z_per_t, out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn fill_part_avx2(
        &self,
        tile: &[Entry],
        window: Window,
        part: Window,
        z_per_t: &[f64],
        out: &mut [Vec<Fragment>],
    ) {
        self.fill_part_lanes(tile, window, part, z_per_t, out);
    }

    /// The pixels of `part` (inside `window`) against the entries of image tile `tile`.
    #[inline(always)]
    fn fill_part_lanes(
        &self,
        tile: &[Entry],
        window: Window,
        part: Window,
        z_per_t: &[f64],
        out: &mut [Vec<Fragment>],
    ) {
        // One chunk of lanes per pixel row of `part` (at most a tile's side), so a splat
        // walks only the rows its ellipse reaches.
        const LANES: usize = TILE as usize;
        let mut px = [0f32; LANES];
        for (l, x) in px.iter_mut().zip(part.x0..part.x1) {
            *l = x as f32 + 0.5;
        }
        let mut index = [[0usize; LANES]; LANES];
        let mut live = [0u16; LANES];
        let mut remaining = 0;
        for (r, y) in (part.y0..part.y1).enumerate() {
            for (l, x) in (part.x0..part.x1).enumerate() {
                let i = ((y - window.y0) * window.width() + (x - window.x0)) as usize;
                index[r][l] = i;
                if z_per_t[i].is_finite() {
                    live[r] |= 1 << l;
                    remaining += 1;
                }
            }
        }
        let (x_lo, x_hi) = (part.x0 as f32 + 0.5, (part.x1 - 1) as f32 + 0.5);
        let mut transmittance = [[1f64; LANES]; LANES];
        for e in tile {
            let [ex, ey] = e.extent;
            if e.xy[0] + ex < x_lo || e.xy[0] - ex > x_hi {
                continue;
            }
            // Rows whose pixel centres `y + ½` lie within the ellipse's reach.
            let first = (e.xy[1] - ey - 0.5).ceil().max(part.y0 as f32);
            let last = (e.xy[1] + ey - 0.5).floor().min((part.y1 - 1) as f32);
            if first > last {
                continue;
            }
            let [a, b, c] = e.conic;
            for r in (first as u32 - part.y0) as usize..=(last as u32 - part.y0) as usize {
                if live[r] == 0 {
                    continue;
                }
                let dy = e.xy[1] - ((part.y0 + r as u32) as f32 + 0.5);
                let mut sigma = [0f32; LANES];
                for l in 0..LANES {
                    let dx = e.xy[0] - px[l];
                    sigma[l] = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
                }
                let mut reached = 0u16;
                for (l, &v) in sigma.iter().enumerate() {
                    reached |= u16::from(v >= 0.0 && v <= e.sigma_cut) << l;
                }
                let mut hits = reached & live[r];
                if hits == 0 {
                    continue;
                }
                // The row's sixteen exponentials at once (a loop the compiler vectorises).
                let mut alphas = [0f32; LANES];
                for l in 0..LANES {
                    alphas[l] = e.opacity * exp_neg(sigma[l].clamp(0.0, 80.0));
                }
                while hits != 0 {
                    let l = hits.trailing_zeros() as usize;
                    hits &= hits - 1;
                    let alpha = alphas[l].min(MAX_ALPHA);
                    if alpha.is_nan() || alpha < MIN_ALPHA {
                        continue;
                    }
                    let i = index[r][l];
                    out[i].push(Fragment {
                        t: f64::from(e.z) / z_per_t[i],
                        alpha,
                        rgb: e.rgb,
                    });
                    let tr = &mut transmittance[r][l];
                    *tr *= 1.0 - f64::from(alpha);
                    if *tr <= MIN_TRANSMITTANCE {
                        live[r] &= !(1 << l);
                        remaining -= 1;
                    }
                }
            }
            if remaining == 0 {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::exp_neg;

    #[test]
    fn exp_neg_is_within_a_few_ulp_of_the_exact_exponential() {
        let mut worst: f64 = 0.0;
        for i in 0..=800_000 {
            let s = i as f32 * 1e-4;
            let exact = (-f64::from(s)).exp();
            worst = worst.max((f64::from(exp_neg(s)) - exact).abs() / exact);
        }
        // f32's ulp is 2^-23 ≈ 1.2e-7 relative at worst.
        assert!(worst < 3.0e-7, "largest relative error {worst:e}");
        assert_eq!(exp_neg(0.0), 1.0);
    }
}
