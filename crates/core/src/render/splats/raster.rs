//! A frame's splats, binned to image tiles and sorted by depth, and the fragments each pixel
//! gets from them.
//!
//! As in gsplat, a splat reaches every pixel of each 16×16 image tile its bounding square
//! touches (tiles anchored at the image's corner, whatever window is rendered, so a crop of a
//! render equals the render cropped), and a pixel meets its splats in order of the camera z of
//! their means. Only tiles of the render window are binned, and a splat only in the tiles
//! where its opacity can reach 1/255 (the others would skip it pixel by pixel).

use rayon::prelude::*;

use super::project::{project, Projected, View};
use crate::field::Splats;
use crate::image::Window;
use crate::render::fragment::Fragment;

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
/// 6e-9 relative). `n` is rounded by adding `1.5·2²³`, where floats are spaced by 1, so it
/// lands in the low bits of the sum (no float-to-int conversion, whose saturation checks
/// would not vectorise as well). Fused multiply-adds: the pixel loop runs where the CPU has
/// FMA (x86-64 with AVX2, and every AArch64).
#[inline(always)]
fn exp_neg(s: f32) -> f32 {
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    const ROUND: f32 = 12_582_912.0;
    let x = -s;
    let shifted = x * std::f32::consts::LOG2_E + ROUND;
    let n = shifted - ROUND;
    let r = (-n).mul_add(LN2_LO, (-n).mul_add(LN2_HI, x));
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
        p = p.mul_add(r, c);
    }
    // `n` (in [−116, 0]) as the low bits of `shifted`, moved into a float's exponent.
    let n_bits = shifted.to_bits().wrapping_sub(ROUND.to_bits());
    p * f32::from_bits(n_bits.wrapping_add(127) << 23)
}

/// What a pixel loop reads of a splat: one per projected splat, in depth order, which the
/// tiles' lists index.
#[derive(Clone, Copy, Debug)]
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
    /// Every projected splat's entry, in depth order.
    entries: Vec<Entry>,
    /// Per row of tiles: where each tile's list starts (one more at the end), and the lists:
    /// indices into `entries`, in depth order (four bytes for each tile a splat covers, as
    /// gsplat keeps them, rather than a copy of its entry).
    rows: Vec<(Vec<u32>, Vec<u32>)>,
    /// Tile coordinates covered: `[x0, y0, x1, y1)`.
    tiles: [u32; 4],
    /// How wide the pixel loop runs on this CPU.
    lanes: Lanes,
    /// Seconds spent projecting, and sorting and binning (for benchmarks).
    pub(crate) timings: [f64; 2],
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
        // Depth order, ties in projection order (a stable sort by z): each splat's key is
        // its z's bits (z > 0, so they order as the numbers do) above its index, and eight-byte
        // keys sort far faster than the splats themselves.
        let mut order: Vec<u64> = projected
            .par_iter()
            .enumerate()
            .map(|(i, p)| u64::from(p.z.to_bits()) << 32 | i as u64)
            .collect();
        order.par_sort_unstable();
        let in_order = |key: &u64| &projected[(*key & u64::from(u32::MAX)) as usize];

        let tiles = [
            window.x0 / TILE,
            window.y0 / TILE,
            window.x1.div_ceil(TILE),
            window.y1.div_ceil(TILE),
        ];
        let tiles_x = (tiles[2] - tiles[0]) as usize;
        // gsplat's bounding square, narrowed on each axis to where the splat can give a
        // fragment at all (opacity ≥ 1/255: the ellipse's reach): the tiles left out are
        // ones whose pixels would all skip it, so the render is unchanged and each tile
        // walks fewer splats.
        let range = |(p, e): (&Projected, &Entry)| {
            let (x, y) = (p.xy[0] / TILE as f32, p.xy[1] / TILE as f32);
            let rx = p.radius.min(e.extent[0]) / TILE as f32;
            let ry = p.radius.min(e.extent[1]) / TILE as f32;
            let clamp = |v: f32, lo: u32, hi: u32| (v.max(0.0) as u32).clamp(lo, hi);
            [
                clamp((x - rx).floor(), tiles[0], tiles[2]),
                clamp((y - ry).floor(), tiles[1], tiles[3]),
                clamp((x + rx).ceil(), tiles[0], tiles[2]),
                clamp((y + ry).ceil(), tiles[1], tiles[3]),
            ]
        };
        // Each splat is listed in the rows of tiles it touches (in depth order), then each
        // row is binned on its own (in parallel), so every tile's list comes out sorted.
        let splat_entries: Vec<Entry> = order.par_iter().map(|k| Entry::new(in_order(k))).collect();
        let ranges: Vec<[u32; 4]> = order
            .par_iter()
            .zip(&splat_entries)
            .map(|(k, e)| range((in_order(k), e)))
            .collect();
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
        let rows: Vec<(Vec<u32>, Vec<u32>)> = (0..rows_n)
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
                let mut list = vec![0u32; counts[tiles_x] as usize];
                for &i in splats {
                    let r = &ranges[i as usize];
                    for tx in r[0]..r[2] {
                        let slot = &mut counts[(tx - tiles[0]) as usize];
                        list[*slot as usize] = i;
                        *slot += 1;
                    }
                }
                (starts, list)
            })
            .collect();
        SplatLayer {
            entries: splat_entries,
            rows,
            tiles,
            lanes: Lanes::detect(),
            timings: [projecting, start.elapsed().as_secs_f64() - projecting],
        }
    }

    /// Hands each pixel of `window` its fragments, front to back: `sink(i, fragment)` for
    /// its `i`-th pixel (row-major; `z_per_t[i]` is that pixel's, a non-finite one marks a
    /// pixel without a ray), up to the one that brings the pixel's transmittance (from
    /// splats alone) to [`MIN_TRANSMITTANCE`] or below, or until the sink returns `false`
    /// (it wants no more for that pixel).
    pub fn fill<S: FnMut(usize, Fragment) -> bool>(
        &self,
        window: Window,
        z_per_t: &[f64],
        mut sink: S,
    ) {
        self.walk(
            window,
            &mut Handing {
                index: [[0; LANES]; LANES],
                z_per_t,
                transmittance: [[1.0; LANES]; LANES],
                sink: &mut sink,
            },
        );
    }

    /// Composites each pixel of `window` from its fragments alone, as [`SplatLayer::fill`]
    /// would hand them to a sink that composites them in order (alpha over, stopping before
    /// the transmittance would fall to [`MIN_TRANSMITTANCE`]): `out[i]` for the `i`-th pixel
    /// (row-major), whose ray has camera z `z_per_t[i]` per unit distance (non-finite: no
    /// ray, left transparent). Sixteen pixels of a row are composited at once, in `f32` as
    /// gsplat composites; the depth moment only where `depth` asks for it (else 0). Returns
    /// the number of fragments met.
    pub fn composite(
        &self,
        window: Window,
        z_per_t: &[f64],
        depth: bool,
        out: &mut [SplatPixel],
    ) -> u64 {
        for px in out.iter_mut() {
            *px = SplatPixel::default();
        }
        let mut compositing = Compositing {
            index: [[0; LANES]; LANES],
            part: window,
            acc: LaneSums::default(),
            out,
            z_per_t,
            fragments: 0,
            depth,
        };
        self.walk(window, &mut compositing);
        compositing.fragments
    }

    /// Walks every tile part of `window` with `action`.
    ///
    /// Per image tile, the splats are walked once for all its pixels of the window, sixteen
    /// pixels at a time: the quadratic form is evaluated for the sixteen together (a loop the
    /// compiler vectorises), and only the pixels it reaches go on to the exponential.
    fn walk<A: RowAction>(&self, window: Window, action: &mut A) {
        for ty in window.y0 / TILE..window.y1.div_ceil(TILE) {
            for tx in window.x0 / TILE..window.x1.div_ceil(TILE) {
                let part = window.intersect(&Window::new(
                    tx * TILE,
                    ty * TILE,
                    (tx + 1) * TILE,
                    (ty + 1) * TILE,
                ));
                let mut index = [[usize::MAX; LANES]; LANES];
                for (r, y) in (part.y0..part.y1).enumerate() {
                    for (l, x) in (part.x0..part.x1).enumerate() {
                        index[r][l] = ((y - window.y0) * window.width() + (x - window.x0)) as usize;
                    }
                }
                action.start(part, index);
                if tx < self.tiles[0]
                    || tx >= self.tiles[2]
                    || ty < self.tiles[1]
                    || ty >= self.tiles[3]
                {
                    action.finish();
                    continue;
                }
                let (starts, list) = &self.rows[(ty - self.tiles[1]) as usize];
                let col = (tx - self.tiles[0]) as usize;
                let tile = &list[starts[col] as usize..starts[col + 1] as usize];
                self.walk_part(tile, part, action);
                action.finish();
            }
        }
    }

    fn walk_part<A: RowAction>(&self, tile: &[u32], part: Window, action: &mut A) {
        let entries = &self.entries;
        match self.lanes {
            // SAFETY: `Lanes::detect` found these features on this CPU.
            #[cfg(target_arch = "x86_64")]
            Lanes::Avx512 => unsafe { walk_part_avx512(entries, tile, part, action) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Lanes::Avx2 => unsafe { walk_part_avx2(entries, tile, part, action) },
            Lanes::Plain => walk_part_lanes(entries, tile, part, action),
        }
    }
}

/// Lanes of the pixel loop: a tile's row.
const LANES: usize = TILE as usize;

/// What the walk does with the fragments one splat gives one row of a tile part.
trait RowAction {
    /// A tile part begins: `index[r][l]` is the pixel index of its row `r`, lane `l`.
    fn start(&mut self, part: Window, index: [[usize; LANES]; LANES]);
    /// Whether lane `l` of row `r` is a pixel with a ray.
    fn has_ray(&self, r: usize, l: usize) -> bool;
    /// Row `r`'s lanes get a fragment of entry `e` with opacity `alphas[l]` (in
    /// `[MIN_ALPHA, MAX_ALPHA]`), or none where it is 0. Returns the lanes that want no
    /// more (as bits).
    fn row(&mut self, r: usize, alphas: &[f32; LANES], e: &Entry) -> u16;
    /// The part is done.
    fn finish(&mut self) {}
}

/// The widest vector instructions the pixel loop can use here: its sixteen lanes of `f32` are
/// one AVX-512 register, two AVX2 ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Lanes {
    #[cfg(target_arch = "x86_64")]
    Avx512,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    Plain,
}

impl Lanes {
    fn detect() -> Lanes {
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma");
            if avx2 && is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl") {
                return Lanes::Avx512;
            }
            if avx2 {
                return Lanes::Avx2;
            }
        }
        Lanes::Plain
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
fn walk_part_avx512<A: RowAction>(entries: &[Entry], tile: &[u32], part: Window, action: &mut A) {
    walk_part_lanes(entries, tile, part, action);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn walk_part_avx2<A: RowAction>(entries: &[Entry], tile: &[u32], part: Window, action: &mut A) {
    walk_part_lanes(entries, tile, part, action);
}

/// The pixels of `part` against the entries of its image tile, `tile` (indices into
/// `entries`, in depth order).
#[inline(always)]
fn walk_part_lanes<A: RowAction>(entries: &[Entry], tile: &[u32], part: Window, action: &mut A) {
    // One chunk of lanes per pixel row of `part` (at most a tile's side), so a splat walks
    // only the rows its ellipse reaches. Lanes are kept as numbers (a live lane's factor is
    // 1, a pixel without a ray or done is 0) so that the row loops vectorise.
    let mut px = [0f32; LANES];
    for (l, x) in px.iter_mut().zip(part.x0..part.x1) {
        *l = x as f32 + 0.5;
    }
    let mut live = [[0f32; LANES]; LANES];
    let mut live_rows = [false; LANES];
    let mut remaining = 0;
    for (r, (row, any)) in live.iter_mut().zip(&mut live_rows).enumerate() {
        for (l, lane) in row.iter_mut().enumerate().take(part.width() as usize) {
            if r < part.height() as usize && action.has_ray(r, l) {
                *lane = 1.0;
                *any = true;
                remaining += 1;
            }
        }
    }
    if remaining == 0 {
        return;
    }
    let (x_lo, x_hi) = (part.x0 as f32 + 0.5, (part.x1 - 1) as f32 + 0.5);
    for &i in tile {
        let Some(e) = entries.get(i as usize) else {
            continue;
        };
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
            if !live_rows[r] {
                continue;
            }
            // The row's sixteen fragments at once: opacity, or 0 where the pixel gets none.
            let dy = e.xy[1] - ((part.y0 + r as u32) as f32 + 0.5);
            // The quadratic form first: a row whose live lanes all lie past the cut-off (most
            // rows of a large, thin or faint splat's box) skips the exponential.
            let mut sigmas = [0f32; LANES];
            let mut inside = 0u32;
            for l in 0..LANES {
                let dx = e.xy[0] - px[l];
                let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
                sigmas[l] = sigma;
                let reach = (sigma >= 0.0) & (sigma <= e.sigma_cut) & (live[r][l] != 0.0);
                inside |= u32::from(reach);
            }
            if inside == 0 {
                continue;
            }
            let mut alphas = [0f32; LANES];
            for l in 0..LANES {
                let sigma = sigmas[l];
                let alpha = (e.opacity * exp_neg(sigma.clamp(0.0, 80.0))).min(MAX_ALPHA);
                let met = (sigma >= 0.0) & (sigma <= e.sigma_cut) & (alpha >= MIN_ALPHA);
                alphas[l] = if met { alpha * live[r][l] } else { 0.0 };
            }
            // No fragment in the row: every opacity is +0 (its bits OR to zero, a reduction
            // that vectorises where a float comparison chain would not).
            if alphas.iter().fold(0u32, |m, &a| m | a.to_bits()) == 0 {
                continue;
            }
            let done = action.row(r, &alphas, e);
            if done != 0 {
                for (l, lane) in live[r].iter_mut().enumerate() {
                    if done >> l & 1 == 1 && *lane != 0.0 {
                        *lane = 0.0;
                        remaining -= 1;
                    }
                }
                live_rows[r] = live[r].iter().any(|&v| v != 0.0);
            }
        }
        if remaining == 0 {
            return;
        }
    }
}

/// Hands fragments to a sink, tracking each pixel's transmittance from splats alone.
struct Handing<'a, S> {
    index: [[usize; LANES]; LANES],
    z_per_t: &'a [f64],
    transmittance: [[f64; LANES]; LANES],
    sink: &'a mut S,
}

impl<S: FnMut(usize, Fragment) -> bool> RowAction for Handing<'_, S> {
    fn start(&mut self, _part: Window, index: [[usize; LANES]; LANES]) {
        self.index = index;
        self.transmittance = [[1.0; LANES]; LANES];
    }

    fn has_ray(&self, r: usize, l: usize) -> bool {
        self.z_per_t[self.index[r][l]].is_finite()
    }

    #[inline(always)]
    fn row(&mut self, r: usize, alphas: &[f32; LANES], e: &Entry) -> u16 {
        let mut done = 0;
        for (l, &alpha) in alphas.iter().enumerate() {
            if alpha == 0.0 {
                continue;
            }
            let i = self.index[r][l];
            let wants_more = (self.sink)(
                i,
                Fragment {
                    t: f64::from(e.z) / self.z_per_t[i],
                    alpha,
                    rgb: e.rgb,
                },
            );
            let tr = &mut self.transmittance[r][l];
            *tr *= 1.0 - f64::from(alpha);
            if *tr <= MIN_TRANSMITTANCE || !wants_more {
                done |= 1 << l;
            }
        }
        done
    }
}

/// A pixel composited from its splat fragments alone (see [`SplatLayer::composite`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SplatPixel {
    /// Transmittance left (1 − accumulation).
    pub transmittance: f64,
    /// Premultiplied colour in the trained space.
    pub rgb: [f64; 3],
    /// `Σ w·t`: the weights times the fragments' ray distances.
    pub(crate) depth_moment: f64,
}

impl Default for SplatPixel {
    fn default() -> Self {
        SplatPixel {
            transmittance: 1.0,
            rgb: [0.0; 3],
            depth_moment: 0.0,
        }
    }
}

/// One tile part's running sums, lane by lane, in `f32` as gsplat composites them (sixteen
/// lanes are one AVX-512 register).
#[derive(Clone, Copy)]
struct LaneSums {
    transmittance: [[f32; LANES]; LANES],
    rgb: [[[f32; LANES]; 3]; LANES],
    /// `Σ w·z` with the camera z of the fragments' splats (kept only when depth is wanted).
    depth_moment: [[f32; LANES]; LANES],
}

impl Default for LaneSums {
    fn default() -> Self {
        LaneSums {
            transmittance: [[1.0; LANES]; LANES],
            rgb: [[[0.0; LANES]; 3]; LANES],
            depth_moment: [[0.0; LANES]; LANES],
        }
    }
}

/// Composites fragments where they fall, sixteen lanes at a time.
struct Compositing<'a> {
    index: [[usize; LANES]; LANES],
    part: Window,
    acc: LaneSums,
    out: &'a mut [SplatPixel],
    z_per_t: &'a [f64],
    fragments: u64,
    /// Whether the depth moment is wanted.
    depth: bool,
}

impl RowAction for Compositing<'_> {
    fn start(&mut self, part: Window, index: [[usize; LANES]; LANES]) {
        self.index = index;
        self.part = part;
        self.acc = LaneSums::default();
    }

    fn has_ray(&self, r: usize, l: usize) -> bool {
        self.z_per_t[self.index[r][l]].is_finite()
    }

    /// Alpha over, lane by lane without branches: a lane whose fragment would bring its
    /// transmittance to the floor takes nothing and is done, as a compositing sink would
    /// refuse it.
    #[inline(always)]
    fn row(&mut self, r: usize, alphas: &[f32; LANES], e: &Entry) -> u16 {
        let transmittance = &mut self.acc.transmittance[r];
        let rgb = &mut self.acc.rgb[r];
        let colour = e.rgb;
        let floor = MIN_TRANSMITTANCE as f32;
        let mut refused = [false; LANES];
        let mut weights = [0f32; LANES];
        let mut met = 0;
        for l in 0..LANES {
            let alpha = alphas[l];
            met += u32::from(alpha > 0.0);
            let t_enter = transmittance[l];
            refused[l] = alpha > 0.0 && t_enter * (1.0 - alpha) <= floor;
            let w = if refused[l] { 0.0 } else { t_enter * alpha };
            weights[l] = w;
            transmittance[l] = (t_enter - w).max(0.0);
            for c in 0..3 {
                rgb[c][l] += w * colour[c];
            }
        }
        if self.depth {
            let depth = &mut self.acc.depth_moment[r];
            for l in 0..LANES {
                depth[l] += weights[l] * e.z;
            }
        }
        self.fragments += u64::from(met);
        if !refused.contains(&true) {
            return 0;
        }
        refused
            .iter()
            .enumerate()
            .fold(0, |done, (l, &no)| done | u16::from(no) << l)
    }

    fn finish(&mut self) {
        for r in 0..self.part.height() as usize {
            for l in 0..self.part.width() as usize {
                let i = self.index[r][l];
                if !self.z_per_t[i].is_finite() {
                    continue;
                }
                self.out[i] = SplatPixel {
                    transmittance: f64::from(self.acc.transmittance[r][l]),
                    rgb: [0, 1, 2].map(|c| f64::from(self.acc.rgb[r][c][l])),
                    depth_moment: f64::from(self.acc.depth_moment[r][l]) / self.z_per_t[i],
                };
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
