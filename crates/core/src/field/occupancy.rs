//! An occupancy grid with a distance map: where along a ray the field may have density.
//!
//! **Idea.** A `resolution³` grid over the field's (slightly padded) bounds; a cell is
//! *occupied* where [`Field::may_be_occupied`] says the field may have density in the cell's
//! box (grown by a thousandth of a cell, so f32 rounding of sample positions never lands a
//! dense sample in a cell marked empty). Every cell also stores a *radius* `r ≥ 1`: the
//! Chebyshev (L∞) distance, in cells, to the nearest cell of the other state, capped at
//! 63. So the cube of `(2r − 1)³` cells centred on a cell is uniformly empty or
//! uniformly occupied. One byte per cell: bit 7 occupied, bits 0–6 the radius.
//!
//! The radii come from repeated 3×3×3 dilations of bit sets (shift-OR along x, OR of
//! neighbouring rows along y and slices along z): an empty cell gets `r = k` at the first
//! dilation `k` of the occupied set that covers it, an occupied cell likewise from the
//! empty set. Outside the grid counts as neither.
//!
//! [`Occupancy::segments`] walks the grid with a 3D DDA whose step, in a cell of radius `r`,
//! goes to where the ray leaves that cell's uniform cube: one step crosses empty space (up to
//! `r` cells on every axis), emits a solid interior whole, and a ray grazing a surface `h`
//! cells above it advances about `h` cells per step instead of one. Every crossing is computed
//! from the planes `bounds.min + k·cell`, and after a jump the cells on the other axes are
//! located from the exit point and then corrected against those same plane crossings, so a
//! jump lands in the cell the cell-by-cell walk would reach. Emitted intervals are padded by
//! a thousandth of a cell (plus a few ulps of the ray's magnitude), clamped to `[t0, t1]` and
//! merged when they touch.
//!
//! **Worked example.** A unit sphere at the origin, grid resolution 32 over its bounds
//! (`[−1, 1]³` padded by 0.2 %, cells ≈ 0.0626 wide, diagonal ≈ 0.108). The ray from
//! `(−3, 0, 0)` along `+x` crosses the sphere for `t ∈ [2, 4]`: it gets one segment that
//! contains `[2, 4]` and exceeds it by at most a cell diagonal at each end:
//!
//! ```
//! use glam::Vec3;
//! use nerfx_core::field::{Analytic, Occupancy, Primitive, Shape, ShColor};
//! let sphere = Primitive {
//!     shape: Shape::Sphere { center: Vec3::ZERO, radius: 1.0 },
//!     density: 1.0,
//!     color: ShColor::constant(Vec3::ONE),
//! };
//! let field = Analytic { primitives: vec![sphere] };
//! let occ = Occupancy::build(&field, 32);
//! let mut seg = Vec::new();
//! occ.segments(Vec3::new(-3.0, 0.0, 0.0), Vec3::X, 0.0, 100.0, &mut seg);
//! assert_eq!(seg.len(), 1);
//! let [a, b] = seg[0];
//! assert!(a <= 2.0 && a > 2.0 - 0.11 && b >= 4.0 && b < 4.0 + 0.11);
//! // A ray passing above the sphere gets nothing.
//! seg.clear();
//! occ.segments(Vec3::new(-3.0, 1.5, 0.0), Vec3::X, 0.0, 100.0, &mut seg);
//! assert!(seg.is_empty());
//! ```

use glam::Vec3;
use rayon::prelude::*;

use super::{Aabb, Field, RegionQuery};

/// Largest accepted resolution (512³ cells of one byte = 128 MiB).
const MAX_RESOLUTION: u32 = 512;
/// Cell boxes are grown by this fraction of a cell before asking the field.
const BUILD_PAD: f32 = 1e-3;
/// Emitted intervals are grown by this fraction of the smallest cell edge.
const SEGMENT_PAD: f32 = 1e-3;
/// A cell's byte: this bit set where the cell is occupied…
const OCCUPIED: u8 = 0x80;
/// …and these bits its radius.
const RADIUS_MASK: u8 = 0x7f;
/// Cells of at least this radius are left in one jump; smaller ones cell by cell.
const JUMP_RADIUS: u32 = 2;
/// Largest stored radius: farther cells of the other state are not looked for.
const RADIUS_CAP: u8 = 63;

/// The grid's geometry: cell `k` on axis `a` spans the planes `plane(a, k)` and
/// `plane(a, k + 1)`.
#[derive(Clone, Copy, Debug)]
struct Grid {
    lo: [f32; 3],
    cell: [f32; 3],
    /// `1/cell`, to guess a cell from a position.
    inv_cell: [f32; 3],
    n: u32,
}

impl Grid {
    /// The coordinate of plane `k` on axis `a`.
    #[inline]
    fn plane(&self, a: usize, k: u32) -> f32 {
        self.lo[a] + k as f32 * self.cell[a]
    }

    /// The box between planes `k0` and `k1` on each axis.
    fn cell_box(&self, k0: [u32; 3], k1: [u32; 3]) -> Aabb {
        let corner = |k: [u32; 3]| Vec3::from_array([0, 1, 2].map(|a| self.plane(a, k[a])));
        Aabb::new(corner(k0), corner(k1))
    }

    /// The cell holding `p` on axis `a`, `⌊(p − lo)/cell⌋` clamped into the grid (clamping
    /// first, the cast truncates a non-negative value: no `floor` call).
    #[inline]
    fn locate_axis(&self, a: usize, p: f32) -> u32 {
        let g = (p - self.lo[a]) / self.cell[a];
        g.clamp(0.0, (self.n - 1) as f32) as u32
    }

    /// The cell holding `p` (clamped into the grid).
    #[inline]
    fn locate(&self, p: Vec3) -> [u32; 3] {
        [
            self.locate_axis(0, p.x),
            self.locate_axis(1, p.y),
            self.locate_axis(2, p.z),
        ]
    }

    /// The smallest cell edge.
    fn min_cell(&self) -> f32 {
        self.cell.into_iter().fold(f32::INFINITY, f32::min)
    }

    /// Index of cell `c` in a per-cell array, x fastest.
    #[inline]
    fn index(&self, c: [u32; 3]) -> usize {
        let n = self.n as usize;
        (c[2] as usize * n + c[1] as usize) * n + c[0] as usize
    }
}

/// A bit per cell, each x-row padded to whole 64-bit words (bits past the row's end are 0).
#[derive(Clone, Debug)]
struct Bits {
    n: u32,
    row_words: usize,
    words: Vec<u64>,
}

impl Bits {
    fn new(n: u32) -> Self {
        let row_words = n.div_ceil(64) as usize;
        Bits {
            n,
            row_words,
            words: vec![0; row_words * (n as usize) * (n as usize)],
        }
    }

    /// Words per z-slice.
    fn slice_words(&self) -> usize {
        self.row_words * self.n as usize
    }

    /// The bits of a row's last word that lie inside the grid.
    fn tail_mask(&self) -> u64 {
        match self.n % 64 {
            0 => u64::MAX,
            r => (1u64 << r) - 1,
        }
    }

    fn count(&self) -> u64 {
        self.words.iter().map(|w| u64::from(w.count_ones())).sum()
    }

    /// The other cells of the grid.
    fn complement(&self) -> Bits {
        let (rw, tail) = (self.row_words, self.tail_mask());
        let mut out = self.clone();
        for row in out.words.chunks_mut(rw) {
            for w in row.iter_mut() {
                *w = !*w;
            }
            row[rw - 1] &= tail;
        }
        out
    }

    /// `out` = this set grown by one cell along x and y, slice by slice: each row of `out`
    /// is the OR of the x-dilated rows `y − 1`, `y`, `y + 1`, where the x-dilation of a row
    /// is `in[x−1] | in[x] | in[x+1]` (shifts with carries between words).
    fn dilate_xy(&self, out: &mut Bits) {
        let (rw, n, tail) = (self.row_words, self.n as usize, self.tail_mask());
        let dilate_x = |s: &[u64], i: usize| {
            let prev = if i > 0 { s[i - 1] >> 63 } else { 0 };
            let next = if i + 1 < rw { s[i + 1] << 63 } else { 0 };
            s[i] | s[i] << 1 | prev | s[i] >> 1 | next
        };
        out.words
            .par_chunks_mut(self.slice_words())
            .zip(self.words.par_chunks(self.slice_words()))
            .for_each(|(dst, src)| {
                for y in 0..n {
                    let rows = [y.saturating_sub(1), y, (y + 1).min(n - 1)]
                        .map(|r| &src[r * rw..(r + 1) * rw]);
                    let d = &mut dst[y * rw..(y + 1) * rw];
                    for (i, w) in d.iter_mut().enumerate() {
                        *w = rows.iter().fold(0, |acc, r| acc | dilate_x(r, i));
                    }
                    d[rw - 1] &= tail;
                }
            });
    }
}

/// Marks, in one z-slice, the cells the field may occupy: a quadtree over (x, y) that only
/// splits boxes the field says may be occupied.
struct SliceMarker<'a> {
    /// [`Field::region_query`] of the field.
    query: &'a dyn RegionQuery,
    grid: Grid,
    pad: f32,
    z: u32,
    row_words: usize,
}

impl SliceMarker<'_> {
    /// Visits the `s × s` square of cells at (`x0`, `y0`) (clipped to the grid). `scopes[0]`
    /// holds what the visit of the square holding this one left to look at (`None`: this is
    /// the slice's whole square); the rest is scratch for the squares inside.
    fn visit(
        &self,
        words: &mut [u64],
        x0: u32,
        y0: u32,
        s: u32,
        scopes: &mut [Vec<u32>],
        top: bool,
    ) {
        let n = self.grid.n;
        if x0 >= n || y0 >= n {
            return;
        }
        let k1 = [(x0 + s).min(n), (y0 + s).min(n), self.z + 1];
        let region = self.grid.cell_box([x0, y0, self.z], k1).grow(self.pad);
        let (within, inside) = scopes.split_at_mut(1);
        let within = (!top).then_some(within[0].as_slice());
        if !self.query.may_be_occupied(&region, within, &mut inside[0]) {
            return;
        }
        if s == 1 {
            words[y0 as usize * self.row_words + (x0 >> 6) as usize] |= 1u64 << (x0 & 63);
            return;
        }
        let h = s / 2;
        for (dx, dy) in [(0, 0), (h, 0), (0, h), (h, h)] {
            self.visit(words, x0 + dx, y0 + dy, h, &mut scopes[1..], false);
        }
    }
}

/// Sets `flag | k` in `cells` for every cell outside `seed` whose Chebyshev distance to the
/// nearest seed cell is `k < RADIUS_CAP` (the others keep what they hold): the cells that
/// the `k`-th 3×3×3 dilation of `seed` adds. Stops early once a dilation adds nothing.
fn write_radii(seed: &Bits, flag: u8, cells: &mut [u8]) {
    if seed.words.iter().all(|&w| w == 0) {
        return;
    }
    let (n, rw, slice) = (seed.n as usize, seed.row_words, seed.slice_words());
    let mut cur = seed.clone();
    let mut xys = Bits::new(seed.n);
    let mut next = Bits::new(seed.n);
    for k in 1..RADIUS_CAP {
        cur.dilate_xy(&mut xys);
        let added: u64 = next
            .words
            .par_chunks_mut(slice)
            .zip(cells.par_chunks_mut(n * n))
            .enumerate()
            .map(|(z, (dst, cells))| {
                let (a, b) = (z.saturating_sub(1), (z + 1).min(n - 1));
                let (below, here, above) = (
                    &xys.words[a * slice..(a + 1) * slice],
                    &xys.words[z * slice..(z + 1) * slice],
                    &xys.words[b * slice..(b + 1) * slice],
                );
                let old = &cur.words[z * slice..(z + 1) * slice];
                let mut added = 0;
                for (i, d) in dst.iter_mut().enumerate() {
                    *d = below[i] | here[i] | above[i];
                    let mut new = *d & !old[i];
                    if new == 0 {
                        continue;
                    }
                    added += u64::from(new.count_ones());
                    let first = (i / rw) * n + (i % rw) * 64;
                    while new != 0 {
                        cells[first + new.trailing_zeros() as usize] = flag | k;
                        new &= new - 1;
                    }
                }
                added
            })
            .sum();
        if added == 0 {
            break;
        }
        std::mem::swap(&mut cur, &mut next);
    }
}

/// The per-ray constants of a traversal, as arrays for cheap per-axis indexing.
struct RayCtx {
    origin: [f32; 3],
    dir: [f32; 3],
    /// `1/dir`, 0 on axes the ray is parallel to (where `1/dir` is not finite).
    inv: [f32; 3],
    /// −1, 0 or +1 per axis.
    step: [i32; 3],
    /// 1 where the ray moves up the axis, else 0: a cell's exit plane is `k + ahead`.
    ahead: [u32; 3],
    /// ∞ on parallel axes, else 0: added to a crossing, keeps those axes out of a minimum.
    parallel: [f32; 3],
    /// Change of the cell index for a step along each axis (wrapping).
    stride: [usize; 3],
}

impl RayCtx {
    fn new(origin: Vec3, dir: Vec3, n: u32) -> Self {
        let mut ray = RayCtx {
            origin: origin.to_array(),
            dir: dir.to_array(),
            inv: [0.0; 3],
            step: [0; 3],
            ahead: [0; 3],
            parallel: [f32::INFINITY; 3],
            stride: [0; 3],
        };
        let n = n as usize;
        for (a, stride) in [1, n, n * n].into_iter().enumerate() {
            let i = 1.0 / dir[a];
            if i.is_finite() {
                ray.inv[a] = i;
                ray.parallel[a] = 0.0;
                if i > 0.0 {
                    (ray.step[a], ray.ahead[a], ray.stride[a]) = (1, 1, stride);
                } else {
                    (ray.step[a], ray.stride[a]) = (-1, stride.wrapping_neg());
                }
            }
        }
        ray
    }
}

/// Conservative empty-space skipping for any [`Field`]: see the module docs.
#[derive(Clone, Debug)]
pub struct Occupancy {
    bounds: Aabb,
    grid: Grid,
    /// `grid.plane(a, k)` for `k ∈ 0..=n`, per axis: a crossing is then one load, one
    /// subtraction and one product.
    planes: [Vec<f32>; 3],
    /// Per cell ([`Grid::index`]): [`OCCUPIED`] bit and radius.
    cells: Vec<u8>,
    occupied_cells: u64,
}

impl Occupancy {
    /// Builds the grid for `field` at `resolution³` cells (clamped to 1..=512) over
    /// `field.bounds()` (an [unbounded](Field::unbounded) field's grid cube) padded by
    /// 0.1 %. Occupancy is marked top-down per z-slice, in parallel; the radii by dilation
    /// (see the module docs). A field with empty bounds gives a grid with no occupied cell.
    pub fn build(field: &dyn Field, resolution: u32) -> Occupancy {
        let n = resolution.clamp(1, MAX_RESOLUTION);
        let field_bounds = field
            .unbounded()
            .map_or_else(|| field.bounds(), |u| u.grid_box());
        let bounds = if field_bounds.is_empty() {
            Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5))
        } else {
            let size = field_bounds.size().max_element();
            let scale = field_bounds
                .min
                .abs()
                .max(field_bounds.max.abs())
                .max_element();
            field_bounds.grow(1e-3 * size + 1e-6 * scale + f32::MIN_POSITIVE)
        };
        let cell = (bounds.size() / n as f32).to_array();
        let grid = Grid {
            lo: bounds.min.to_array(),
            cell,
            inv_cell: cell.map(|c| 1.0 / c),
            n,
        };
        let mut occupied = Bits::new(n);
        if !field_bounds.is_empty() {
            let query = field.region_query();
            let marker = SliceMarker {
                query: &*query,
                grid,
                pad: BUILD_PAD * grid.min_cell(),
                z: 0,
                row_words: occupied.row_words,
            };
            let slice = occupied.slice_words();
            occupied
                .words
                .par_chunks_mut(slice)
                .enumerate()
                .for_each(|(z, words)| {
                    let m = SliceMarker {
                        z: z as u32,
                        ..marker
                    };
                    let side = n.next_power_of_two();
                    // One scope per level of the quadtree, and the first one unused.
                    let mut scopes = vec![Vec::new(); side.trailing_zeros() as usize + 2];
                    m.visit(words, 0, 0, side, &mut scopes, true);
                });
        }
        let occupied_cells = occupied.count();
        let nn = (n as usize).pow(2);
        let mut cells = vec![0u8; nn * n as usize];
        cells
            .par_chunks_mut(n as usize)
            .zip(occupied.words.par_chunks(occupied.row_words))
            .for_each(|(row, bits)| {
                for (x, c) in row.iter_mut().enumerate() {
                    let occ = bits[x >> 6] >> (x & 63) & 1 != 0;
                    *c = if occ { OCCUPIED } else { 0 } | RADIUS_CAP;
                }
            });
        write_radii(&occupied, 0, &mut cells);
        write_radii(&occupied.complement(), OCCUPIED, &mut cells);
        Occupancy {
            bounds,
            grid,
            planes: [0, 1, 2].map(|a| (0..=n).map(|k| grid.plane(a, k)).collect()),
            cells,
            occupied_cells,
        }
    }

    /// Cells per axis.
    pub fn resolution(&self) -> u32 {
        self.grid.n
    }

    /// The box the grid covers (the field's bounds, slightly padded).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The fraction of cells marked occupied, in `[0, 1]`.
    #[cfg(test)]
    pub(crate) fn fill_ratio(&self) -> f64 {
        self.occupied_cells as f64 / f64::from(self.grid.n).powi(3)
    }

    /// Whether the cell holding `p` is marked occupied (false outside the bounds).
    pub fn is_occupied_point(&self, p: Vec3) -> bool {
        self.bounds.contains(p) && self.cells[self.grid.index(self.grid.locate(p))] & OCCUPIED != 0
    }

    /// Appends to `out` the intervals `[a, b]` of `t ∈ [t0, t1]` where the ray
    /// `origin + t·dir` (unit `dir`, field space) crosses occupied cells: sorted, disjoint,
    /// touching ones merged, each padded by a thousandth of a cell, so that every point of
    /// the ray where the field has density lies in one of them. Nothing is appended for a ray
    /// that misses every occupied cell. No allocation beyond `out`'s growth.
    pub fn segments(&self, origin: Vec3, dir: Vec3, t0: f32, t1: f32, out: &mut Vec<[f32; 2]>) {
        if self.occupied_cells == 0 || !origin.is_finite() || !dir.is_finite() {
            return;
        }
        let ray = RayCtx::new(origin, dir, self.grid.n);
        let Some((t_in, t_out)) = self.clip(&ray, t0, t1) else {
            return;
        };
        let magnitude = origin.abs().max_element() + t_in.abs().max(t_out.abs()).min(f32::MAX);
        let pad = SEGMENT_PAD * self.grid.min_cell() + 8.0 * f32::EPSILON * magnitude;
        let start = out.len();
        let mut emit = |a: f32, b: f32| {
            let (a, b) = ((a - pad).max(t0), (b + pad).min(t1));
            match out[start..].last_mut() {
                Some(last) if last[1] >= a => last[1] = last[1].max(b),
                _ => out.push([a, b]),
            }
        };

        let n = self.grid.n;
        let mut t = t_in;
        // The current cell and where the ray leaves it through each axis's plane (∞ on axes
        // it is parallel to).
        let mut c = [0; 3];
        let mut t_next = [f32::INFINITY; 3];
        for a in 0..3 {
            if ray.step[a] == 0 {
                c[a] = self.grid.locate_axis(a, ray.origin[a] + t * ray.dir[a]);
            } else {
                (c[a], t_next[a]) = self.cell_at(&ray, a, 0, n - 1, t);
            }
        }
        let mut index = self.grid.index(c);
        // Start of the occupied run the ray is in.
        let mut run = None;
        loop {
            let cell = self.cells[index];
            match (cell & OCCUPIED != 0, run) {
                (true, None) => run = Some(t),
                (false, Some(a)) => {
                    emit(a, t);
                    run = None;
                }
                _ => {}
            }
            let r = u32::from(cell & RADIUS_MASK);
            if r < JUMP_RADIUS {
                // One cell: leave through the nearest exit plane.
                let (mut axis, mut exit) = (0, t_next[0]);
                if t_next[1] < exit {
                    (axis, exit) = (1, t_next[1]);
                }
                if t_next[2] < exit {
                    (axis, exit) = (2, t_next[2]);
                }
                if exit >= t_out {
                    break;
                }
                t = t.max(exit);
                let next = c[axis].wrapping_add_signed(ray.step[axis]);
                if next >= n {
                    break;
                }
                c[axis] = next;
                index = index.wrapping_add(ray.stride[axis]);
                t_next[axis] = self.crossing(&ray, axis, next + ray.ahead[axis]);
                continue;
            }
            // Leave the uniform cube of cells within r − 1 of c (clipped to the grid): on each
            // axis its far plane `k`, crossed at `ta` (∞ on parallel axes).
            let (mut exit, mut axis, mut plane) = (f32::INFINITY, 0, 0);
            for (a, &ca) in c.iter().enumerate() {
                let k = if ray.ahead[a] == 1 {
                    (ca + r).min(n)
                } else {
                    (ca + 1).saturating_sub(r)
                };
                let ta = self.crossing(&ray, a, k) + ray.parallel[a];
                if ta < exit {
                    (exit, axis, plane) = (ta, a, k);
                }
            }
            if exit >= t_out {
                break;
            }
            t = t.max(exit);
            // The cell on the far side of that plane.
            let next = plane.wrapping_sub(1 - ray.ahead[axis]);
            if next >= n {
                break;
            }
            for b in 0..3 {
                if b != axis && ray.step[b] != 0 {
                    let (lo, hi) = if ray.ahead[b] == 1 {
                        (c[b], (c[b] + r - 1).min(n - 1))
                    } else {
                        ((c[b] + 1).saturating_sub(r), c[b])
                    };
                    (c[b], t_next[b]) = self.cell_at(&ray, b, lo, hi, t);
                }
            }
            c[axis] = next;
            t_next[axis] = self.crossing(&ray, axis, next + ray.ahead[axis]);
            index = self.grid.index(c);
        }
        if let Some(a) = run {
            emit(a, t_out.max(t));
        }
    }

    /// `[t0, t1]` clipped to the grid's bounds: the slab test of [`Aabb::clip_ray`], with
    /// the same arithmetic (so the same result), reusing the ray's `1/dir`.
    #[inline]
    fn clip(&self, ray: &RayCtx, t0: f32, t1: f32) -> Option<(f32, f32)> {
        let (min, max) = (self.bounds.min.to_array(), self.bounds.max.to_array());
        let (mut near, mut far) = (t0, t1);
        for a in 0..3 {
            let o = ray.origin[a];
            if ray.step[a] != 0 {
                let ta = (min[a] - o) * ray.inv[a];
                let tb = (max[a] - o) * ray.inv[a];
                let (lo, hi) = if ta <= tb { (ta, tb) } else { (tb, ta) };
                let hi = hi + hi.abs() * (4.0 * f32::EPSILON);
                near = near.max(lo);
                far = far.min(hi);
            } else if !(o >= min[a] && o <= max[a]) {
                return None;
            }
        }
        (near <= far).then_some((near, far))
    }

    /// Where the ray crosses plane `k` of axis `a` (not parallel to it).
    #[inline]
    fn crossing(&self, ray: &RayCtx, a: usize, k: u32) -> f32 {
        (self.planes[a][k as usize] - ray.origin[a]) * ray.inv[a]
    }

    /// The cell in `lo..=hi` on axis `a` (not parallel to the ray) holding the ray at `t`,
    /// and where the ray leaves it: guessed from the point, then moved until the cell's
    /// plane crossings bracket `t` (entry ≤ t < exit), so that it agrees with the crossings
    /// a cell-by-cell walk compares.
    #[inline]
    fn cell_at(&self, ray: &RayCtx, a: usize, lo: u32, hi: u32, t: f32) -> (u32, f32) {
        let g = (ray.origin[a] + t * ray.dir[a] - self.grid.lo[a]) * self.grid.inv_cell[a];
        let mut k = g.clamp(lo as f32, hi as f32) as u32;
        if ray.ahead[a] == 1 {
            let mut exit = self.crossing(ray, a, k + 1);
            while k < hi && exit <= t {
                k += 1;
                exit = self.crossing(ray, a, k + 1);
            }
            while k > lo {
                let entry = self.crossing(ray, a, k);
                if entry <= t {
                    break;
                }
                (k, exit) = (k - 1, entry);
            }
            (k, exit)
        } else {
            let mut exit = self.crossing(ray, a, k);
            while k > lo && exit <= t {
                k -= 1;
                exit = self.crossing(ray, a, k);
            }
            while k < hi {
                let entry = self.crossing(ray, a, k + 1);
                if entry <= t {
                    break;
                }
                (k, exit) = (k + 1, entry);
            }
            (k, exit)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::{Analytic, Primitive, Shape};

    fn one(shape: Shape) -> Analytic {
        Analytic {
            primitives: vec![Primitive::white(shape)],
        }
    }

    fn sphere(center: Vec3, radius: f32) -> Shape {
        Shape::Sphere { center, radius }
    }

    /// An analytic field asked primitive by primitive (no index).
    struct Scan(Analytic);

    impl Field for Scan {
        fn bounds(&self) -> Aabb {
            self.0.bounds()
        }
        fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
            self.0.density(points, sigma);
        }
        fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]) {
            self.0.radiance(points, dirs, rgb);
        }
        fn may_be_occupied(&self, region: &Aabb) -> bool {
            self.0.may_be_occupied(region)
        }
    }

    /// A thousand scattered spheres, boxes and blobs of every size: the grid built through the
    /// field's index is the grid built by asking every primitive of every cell.
    #[test]
    fn the_indexed_build_is_the_scanning_build() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let primitives = (0..1000)
            .map(|i| {
                let c = Vec3::new(rnd(), rnd(), rnd()) * 4.0 - 2.0;
                let r = 0.002 + 0.2 * rnd().powi(3);
                Primitive::white(match i % 3 {
                    0 => sphere(c, r),
                    1 => Shape::Box {
                        min: c,
                        max: c + Vec3::new(rnd(), rnd(), rnd()) * r + Vec3::splat(1e-4),
                    },
                    _ => Shape::Gaussian {
                        center: c,
                        sigma: r / 3.0,
                        cutoff: 3.0,
                    },
                })
            })
            .collect();
        let field = Analytic { primitives };
        let indexed = Occupancy::build(&field, 96);
        let scanned = Occupancy::build(&Scan(field), 96);
        assert!(indexed.occupied_cells > 1000);
        assert_eq!(indexed.occupied_cells, scanned.occupied_cells);
        assert!(indexed.cells == scanned.cells);
    }

    /// Every cell's (occupied, radius), from the per-cell bytes.
    fn cell(occ: &Occupancy, c: [u32; 3]) -> (bool, u32) {
        let v = occ.cells[occ.grid.index(c)];
        (v & OCCUPIED != 0, u32::from(v & RADIUS_MASK))
    }

    fn all_cells(n: u32) -> impl Iterator<Item = [u32; 3]> {
        (0..n).flat_map(move |z| (0..n).flat_map(move |y| (0..n).map(move |x| [x, y, z])))
    }

    /// The same grid walked one cell at a time: every radius set to 1.
    fn unit_walk(occ: &Occupancy) -> Occupancy {
        let mut unit = occ.clone();
        for v in &mut unit.cells {
            *v = (*v & OCCUPIED) | 1;
        }
        unit
    }

    #[test]
    fn a_full_box_is_one_segment() {
        // A box filling [0, 1]³: padded bounds make every cell overlap it.
        let f = one(Shape::Box {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        });
        let occ = Occupancy::build(&f, 37);
        assert_eq!(occ.resolution(), 37);
        assert_eq!(occ.fill_ratio(), 1.0);
        // No empty cell anywhere: every radius is the cap.
        assert!(all_cells(37).all(|c| cell(&occ, c) == (true, u32::from(RADIUS_CAP))));
        // A diagonal ray through it, entering at t = 1 (x = 0) and leaving at t = 2 (x = 1),
        // is one segment, within the padded bounds (0.1 % of the size each side).
        let d = Vec3::new(1.0, 0.6, 0.3).normalize();
        let o = Vec3::splat(0.0) - d / d.x + Vec3::new(0.0, 0.2, 0.4);
        let mut seg = Vec::new();
        occ.segments(o, d, 0.0, 10.0, &mut seg);
        assert_eq!(seg.len(), 1, "{seg:?}");
        let (ta, tb) = (1.0 / d.x, 2.0 / d.x);
        let slack = 2e-3 / d.x;
        assert!((seg[0][0] - ta).abs() <= slack && (seg[0][1] - tb).abs() <= slack);
    }

    #[test]
    fn sphere_fill_ratio_is_near_its_volume() {
        let f = one(sphere(Vec3::new(1.0, 2.0, 3.0), 2.0));
        let n = 64;
        let occ = Occupancy::build(&f, n);
        let b = occ.bounds();
        let cell = b.size().x / n as f32;
        // Cells meeting the ball lie within radius + a cell diagonal, and every cell inside
        // radius − a cell diagonal is marked.
        let vol = |r: f32| 4.0 / 3.0 * std::f64::consts::PI * f64::from(r).powi(3);
        let total = f64::from(b.size().x).powi(3);
        let d = cell * 3f32.sqrt() * 1.01;
        let fill = occ.fill_ratio();
        assert!(
            fill >= vol(2.0 - d) / total && fill <= vol(2.0 + d) / total,
            "{fill}"
        );
        assert!(occ.is_occupied_point(Vec3::new(1.0, 2.0, 3.0)));
        assert!(occ.is_occupied_point(Vec3::new(2.99, 2.0, 3.0)));
        assert!(!occ.is_occupied_point(b.min + Vec3::splat(0.01)));
        assert!(!occ.is_occupied_point(Vec3::splat(100.0)));
    }

    /// Radii against the definition: the Chebyshev distance to the nearest cell of the
    /// other state, by brute force over all cell pairs.
    #[test]
    fn radii_are_chebyshev_distances_to_the_other_state() {
        let f = Analytic {
            primitives: vec![
                Primitive::white(sphere(Vec3::ZERO, 1.0)),
                Primitive::white(Shape::Gaussian {
                    center: Vec3::new(1.5, 1.5, 0.0),
                    sigma: 0.1,
                    cutoff: 4.0,
                }),
            ],
        };
        let n = 19;
        let occ = Occupancy::build(&f, n);
        let cells: Vec<([u32; 3], bool)> = all_cells(n).map(|c| (c, cell(&occ, c).0)).collect();
        assert!(cells.iter().any(|c| c.1) && cells.iter().any(|c| !c.1));
        for &(c, occupied) in &cells {
            let reference = cells
                .iter()
                .filter(|o| o.1 != occupied)
                .map(|(o, _)| (0..3).map(|a| c[a].abs_diff(o[a])).max().unwrap_or(0))
                .min()
                .unwrap_or(u32::MAX)
                .min(63);
            assert_eq!(cell(&occ, c).1, reference, "cell {c:?}");
        }
    }

    /// Far from everything an empty cell's radius stops at the cap (63).
    #[test]
    fn radii_are_capped() {
        // Two small balls at opposite corners of a 150³ grid.
        let f = Analytic {
            primitives: vec![
                Primitive::white(sphere(Vec3::splat(-1.0), 0.01)),
                Primitive::white(sphere(Vec3::splat(1.0), 0.01)),
            ],
        };
        let n = 150;
        let occ = Occupancy::build(&f, n);
        let occupied: Vec<[u32; 3]> = all_cells(n).filter(|&c| cell(&occ, c).0).collect();
        assert!(!occupied.is_empty() && occupied.len() < 100);
        let mut capped = 0;
        for c in all_cells(n).step_by(997).filter(|&c| !cell(&occ, c).0) {
            let d = occupied
                .iter()
                .map(|o| (0..3).map(|a| c[a].abs_diff(o[a])).max().unwrap_or(0))
                .min()
                .unwrap_or(u32::MAX);
            assert_eq!(cell(&occ, c).1, d.min(63), "cell {c:?}");
            capped += usize::from(d > 63);
        }
        assert!(capped > 100, "{capped}");
    }

    /// Jumps land where the cell-by-cell walk goes: the same segments for random rays of
    /// every kind (grazing, starting in a cell next to an occupied one, windowed).
    #[test]
    fn jumps_agree_with_the_cell_by_cell_walk() {
        let f = Analytic {
            primitives: vec![
                Primitive::white(Shape::Box {
                    min: Vec3::new(-2.0, -2.0, -0.3),
                    max: Vec3::new(2.0, 2.0, 0.0),
                }),
                Primitive::white(sphere(Vec3::new(0.5, 0.3, 0.8), 0.4)),
                Primitive::white(Shape::Box {
                    min: Vec3::new(-1.5, 1.0, 0.0),
                    max: Vec3::new(-1.2, 1.3, 1.5),
                }),
            ],
        };
        let mut state = 0x1234_5678_u64;
        let mut unit = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for n in [16, 50, 64] {
            let occ = Occupancy::build(&f, n);
            let reference = unit_walk(&occ);
            let b = occ.bounds();
            let mut jumped = 0;
            for i in 0..3000 {
                let p = b.min + Vec3::new(unit(), unit(), unit()) * b.size();
                let mut d = Vec3::new(unit(), unit(), unit()) * 2.0 - 1.0;
                if i % 3 == 0 {
                    // Grazing the slab's top.
                    d.z = (unit() - 0.5) * 0.02;
                }
                let d = d.normalize();
                let (t0, t1) = if i % 2 == 0 {
                    (0.0, 10.0)
                } else {
                    (unit() * 2.0, 2.0 + unit() * 3.0)
                };
                let (mut a, mut r) = (Vec::new(), Vec::new());
                occ.segments(p, d, t0, t1, &mut a);
                reference.segments(p, d, t0, t1, &mut r);
                assert_eq!(a, r, "n {n} ray {p} {d} [{t0}, {t1}]");
                jumped += usize::from(cell(&occ, occ.grid.locate(p)).1 > 1);
            }
            assert!(jumped > 300, "{jumped}");
        }
    }

    #[test]
    fn tiny_resolutions_cover_the_chord() {
        let f = one(sphere(Vec3::new(0.5, 0.0, 0.0), 1.0));
        for res in [1, 2, 3, 5, 9] {
            let occ = Occupancy::build(&f, res);
            let mut seg = Vec::new();
            // Chord along the x axis through the centre: t ∈ [2.5, 4.5].
            occ.segments(Vec3::new(-3.0, 0.0, 0.0), Vec3::X, 0.0, 10.0, &mut seg);
            assert!(
                seg.iter().any(|s| s[0] <= 2.5 && s[1] >= 4.5),
                "{res}: {seg:?}"
            );
        }
    }

    #[test]
    fn empty_field_gives_no_segments() {
        let occ = Occupancy::build(&Analytic::default(), 32);
        assert_eq!(occ.fill_ratio(), 0.0);
        let mut seg = Vec::new();
        occ.segments(Vec3::new(-1.0, 0.0, 0.0), Vec3::X, 0.0, 10.0, &mut seg);
        assert!(seg.is_empty());
    }

    #[test]
    fn segments_append_and_clamp_to_range() {
        let f = one(Shape::Box {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        });
        let occ = Occupancy::build(&f, 8);
        let mut seg = vec![[-5.0, -4.0]];
        // Starts inside the box: the segment starts at t0 and ends at t1.
        occ.segments(Vec3::splat(0.5), Vec3::X, 0.1, 0.3, &mut seg);
        assert_eq!(seg, [[-5.0, -4.0], [0.1, 0.3]]);
        // Range behind the box.
        seg.clear();
        occ.segments(Vec3::splat(0.5), Vec3::X, 2.0, 3.0, &mut seg);
        assert!(seg.is_empty());
    }
}
