//! A multi-resolution occupancy grid: where along a ray the field may have density.
//!
//! **Idea.** The finest level is a `resolution³` bit grid over the field's (slightly padded)
//! bounds; a cell's bit is set where [`Field::may_be_occupied`] says the field may have
//! density in the cell's box (grown by a thousandth of a cell, so f32 rounding of sample
//! positions never lands a dense sample in a cell marked empty). Coarser levels halve the
//! resolution (rounding up) until at most 4 cells per axis remain, and keep two bits per cell:
//! *occupied* (OR of the 8 children) and *full* (AND of the children's full bits; on the
//! finest level full = occupied).
//!
//! [`Occupancy::segments`] walks a ray through this pyramid with a 3D DDA that starts at the
//! coarsest level and
//! - skips an *empty* cell whole,
//! - emits a *full* cell's whole interval without looking inside,
//! - descends into a *partially* occupied cell (to the child holding the current point),
//! - after each step, climbs while the parent is empty or full.
//!
//! So empty space and solid interiors cost one step per coarse cell, and only the thin shell
//! where occupancy changes is walked at the finest resolution. Every cell crossing is
//! computed from the same planes `bounds.min + k·cell` on every level, so levels agree on
//! where a cell ends. Emitted intervals are padded by a thousandth of a cell (plus a few ulps
//! of the ray's magnitude), clamped to `[t0, t1]` and merged when they touch.
//!
//! **Worked example.** A unit sphere at the origin, grid resolution 32 over its bounds
//! (`[−1, 1]³` padded by 0.2 %, cells ≈ 0.0626 wide, diagonal ≈ 0.108). The ray from
//! `(−3, 0, 0)` along `+x` crosses the sphere for `t ∈ [2, 4]`: it gets one segment that
//! contains `[2, 4]` and exceeds it by at most a cell diagonal at each end:
//!
//! ```
//! use glam::Vec3;
//! use nerfx::field::{Analytic, Occupancy, Primitive, Shape, ShColor};
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

use super::{Aabb, Field};

/// Largest accepted resolution (1024³ bits = 128 MiB).
const MAX_RESOLUTION: u32 = 1024;
/// The coarsest level has at most this many cells per axis.
const TOP_CELLS: u32 = 4;
/// Cell boxes are grown by this fraction of a cell before asking the field.
const BUILD_PAD: f32 = 1e-3;
/// Emitted intervals are grown by this fraction of the smallest cell edge.
const SEGMENT_PAD: f32 = 1e-3;

/// The finest grid's geometry: cell `k` on axis `a` spans the planes `plane(a, k)` and
/// `plane(a, k + 1)`; coarse cells use the same planes at multiples of `2^level`.
#[derive(Clone, Copy, Debug)]
struct Grid {
    lo: Vec3,
    cell: Vec3,
    n: u32,
}

impl Grid {
    /// The coordinate of plane `k` on axis `a`.
    #[inline]
    fn plane(&self, a: usize, k: u32) -> f32 {
        self.lo[a] + k as f32 * self.cell[a]
    }

    /// The box between planes `k0` and `k1` (finest units) on each axis.
    fn cell_box(&self, k0: [u32; 3], k1: [u32; 3]) -> Aabb {
        let corner = |k: [u32; 3]| Vec3::from_array([0, 1, 2].map(|a| self.plane(a, k[a])));
        Aabb::new(corner(k0), corner(k1))
    }

    /// The finest cell holding `p` (clamped into the grid).
    #[inline]
    fn locate(&self, p: Vec3) -> [u32; 3] {
        let g = ((p - self.lo) / self.cell).floor();
        let hi = (self.n - 1) as f32;
        [0, 1, 2].map(|a| g[a].clamp(0.0, hi) as u32)
    }

    /// The finest cell a ray at `p` moving along `step` (sign per axis) is about to cross:
    /// like [`Grid::locate`], but a point on a plane between two cells picks the cell ahead,
    /// so a ray starting on a face is not credited with a zero-length visit behind it.
    #[inline]
    fn locate_along(&self, p: Vec3, step: [i32; 3]) -> [u32; 3] {
        let mut c = self.locate(p);
        for a in 0..3 {
            if step[a] < 0 && c[a] > 0 && p[a] <= self.plane(a, c[a]) {
                c[a] -= 1;
            } else if step[a] > 0 && c[a] + 1 < self.n && p[a] >= self.plane(a, c[a] + 1) {
                c[a] += 1;
            }
        }
        c
    }
}

/// One level of the pyramid: `n³` cells, each x-row padded to whole 64-bit words.
#[derive(Clone, Debug)]
struct Level {
    n: u32,
    row_words: usize,
    occupied: Vec<u64>,
    /// All finest cells below are occupied. Empty on the finest level (full = occupied).
    full: Vec<u64>,
}

impl Level {
    fn new(n: u32, with_full: bool) -> Self {
        let row_words = n.div_ceil(64) as usize;
        let words = row_words * (n as usize) * (n as usize);
        Level {
            n,
            row_words,
            occupied: vec![0; words],
            full: if with_full {
                vec![0; words]
            } else {
                Vec::new()
            },
        }
    }

    /// Words per z-slice.
    fn slice_words(&self) -> usize {
        self.row_words * self.n as usize
    }

    /// (word index, bit mask) of cell `c`.
    #[inline]
    fn bit(&self, c: [u32; 3]) -> (usize, u64) {
        let row = (c[2] as usize * self.n as usize + c[1] as usize) * self.row_words;
        (row + (c[0] >> 6) as usize, 1u64 << (c[0] & 63))
    }

    #[inline]
    fn is_occupied(&self, c: [u32; 3]) -> bool {
        let (w, m) = self.bit(c);
        self.occupied[w] & m != 0
    }

    /// Full bit; on the finest level (no `full` words) the occupied bit.
    #[inline]
    fn is_full(&self, c: [u32; 3]) -> bool {
        let (w, m) = self.bit(c);
        let words = if self.full.is_empty() {
            &self.occupied
        } else {
            &self.full
        };
        words[w] & m != 0
    }

    /// The next coarser level: occupied = OR of the (up to) 8 children, full = AND.
    fn reduce(&self) -> Level {
        let mut coarse = Level::new(self.n.div_ceil(2), true);
        let (n, row_words, slice) = (coarse.n, coarse.row_words, coarse.slice_words());
        let fine_n = self.n;
        coarse
            .occupied
            .par_chunks_mut(slice)
            .zip(coarse.full.par_chunks_mut(slice))
            .enumerate()
            .for_each(|(z, (occ, full))| {
                let z = z as u32;
                for y in 0..n {
                    for x in 0..n {
                        let (mut any, mut all) = (false, true);
                        for cz in 2 * z..(2 * z + 2).min(fine_n) {
                            for cy in 2 * y..(2 * y + 2).min(fine_n) {
                                for cx in 2 * x..(2 * x + 2).min(fine_n) {
                                    any |= self.is_occupied([cx, cy, cz]);
                                    all &= self.is_full([cx, cy, cz]);
                                }
                            }
                        }
                        let w = y as usize * row_words + (x >> 6) as usize;
                        let m = 1u64 << (x & 63);
                        if any {
                            occ[w] |= m;
                        }
                        if all {
                            full[w] |= m;
                        }
                    }
                }
            });
        coarse
    }
}

/// Marks, in one z-slice of the finest level, the cells the field may occupy: a quadtree over
/// (x, y) that only splits boxes the field says may be occupied.
struct SliceMarker<'a> {
    field: &'a dyn Field,
    grid: Grid,
    pad: f32,
    z: u32,
    row_words: usize,
}

impl SliceMarker<'_> {
    /// Visits the `s × s` square of cells at (`x0`, `y0`) (clipped to the grid).
    fn visit(&self, words: &mut [u64], x0: u32, y0: u32, s: u32) {
        let n = self.grid.n;
        if x0 >= n || y0 >= n {
            return;
        }
        let k1 = [(x0 + s).min(n), (y0 + s).min(n), self.z + 1];
        let region = self.grid.cell_box([x0, y0, self.z], k1).grow(self.pad);
        if !self.field.may_be_occupied(&region) {
            return;
        }
        if s == 1 {
            words[y0 as usize * self.row_words + (x0 >> 6) as usize] |= 1u64 << (x0 & 63);
            return;
        }
        let h = s / 2;
        for (dx, dy) in [(0, 0), (h, 0), (0, h), (h, h)] {
            self.visit(words, x0 + dx, y0 + dy, h);
        }
    }
}

/// The per-ray constants of a traversal.
struct RayCtx {
    origin: Vec3,
    dir: Vec3,
    /// `1/dir`, 0 on axes the ray is parallel to.
    inv: Vec3,
    /// −1, 0 or +1 per axis.
    step: [i32; 3],
}

/// Conservative empty-space skipping for any [`Field`]: see the module docs.
#[derive(Clone, Debug)]
pub struct Occupancy {
    bounds: Aabb,
    grid: Grid,
    /// Finest first; the last has at most 4 cells per axis.
    levels: Vec<Level>,
    occupied_cells: u64,
}

impl Occupancy {
    /// Builds the pyramid for `field` at `resolution³` finest cells (clamped to 1..=1024)
    /// over `field.bounds()` padded by 0.1 %. The finest level is built top-down per
    /// z-slice, in parallel; the coarser ones by OR/AND reduction. A field with empty bounds
    /// gives a grid with no occupied cell.
    pub fn build(field: &dyn Field, resolution: u32) -> Occupancy {
        let n = resolution.clamp(1, MAX_RESOLUTION);
        let field_bounds = field.bounds();
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
        let grid = Grid {
            lo: bounds.min,
            cell: bounds.size() / n as f32,
            n,
        };
        let mut finest = Level::new(n, false);
        if !field_bounds.is_empty() {
            let marker = SliceMarker {
                field,
                grid,
                pad: BUILD_PAD * grid.cell.min_element(),
                z: 0,
                row_words: finest.row_words,
            };
            let slice = finest.slice_words();
            finest
                .occupied
                .par_chunks_mut(slice)
                .enumerate()
                .for_each(|(z, words)| {
                    let m = SliceMarker {
                        z: z as u32,
                        ..marker
                    };
                    m.visit(words, 0, 0, n.next_power_of_two());
                });
        }
        let occupied_cells = finest
            .occupied
            .iter()
            .map(|w| u64::from(w.count_ones()))
            .sum();
        let mut levels = vec![finest];
        while let Some(last) = levels.last().filter(|l| l.n > TOP_CELLS) {
            let coarse = last.reduce();
            levels.push(coarse);
        }
        Occupancy {
            bounds,
            grid,
            levels,
            occupied_cells,
        }
    }

    /// Finest cells per axis.
    pub fn resolution(&self) -> u32 {
        self.grid.n
    }

    /// The box the grid covers (the field's bounds, slightly padded).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The fraction of finest cells marked occupied, in `[0, 1]`.
    pub fn fill_ratio(&self) -> f64 {
        self.occupied_cells as f64 / f64::from(self.grid.n).powi(3)
    }

    /// Whether the finest cell holding `p` is marked occupied (false outside the bounds).
    pub fn is_occupied_point(&self, p: Vec3) -> bool {
        self.bounds.contains(p) && self.levels[0].is_occupied(self.grid.locate(p))
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
        let Some((t_in, t_out)) = self.bounds.clip_ray(origin, dir, t0, t1) else {
            return;
        };
        let mut inv = Vec3::ZERO;
        let mut step = [0i32; 3];
        for a in 0..3 {
            let i = 1.0 / dir[a];
            if i.is_finite() {
                inv[a] = i;
                step[a] = if i > 0.0 { 1 } else { -1 };
            }
        }
        let ray = RayCtx {
            origin,
            dir,
            inv,
            step,
        };
        let magnitude = origin.abs().max_element() + t_in.abs().max(t_out.abs()).min(f32::MAX);
        let pad = SEGMENT_PAD * self.grid.cell.min_element() + 8.0 * f32::EPSILON * magnitude;
        let start = out.len();
        let mut emit = |a: f32, b: f32| {
            let (a, b) = ((a - pad).max(t0), (b + pad).min(t1));
            match out[start..].last_mut() {
                Some(last) if last[1] >= a => last[1] = last[1].max(b),
                _ => out.push([a, b]),
            }
        };

        let top = self.levels.len() - 1;
        let mut l = top;
        let mut c = self
            .grid
            .locate_along(origin + t_in * dir, step)
            .map(|k| k >> top);
        let mut t = t_in;
        loop {
            let level = &self.levels[l];
            let (exit, axis) = self.exit(&ray, l, c);
            let exit = exit.min(t_out).max(t);
            if level.is_occupied(c) {
                if l > 0 && !level.is_full(c) {
                    l -= 1;
                    c = self.child(&ray, l, c, t);
                    continue;
                }
                emit(t, exit);
            }
            if exit >= t_out {
                break;
            }
            let next = c[axis] as i64 + i64::from(ray.step[axis]);
            if next < 0 || next >= i64::from(level.n) {
                break;
            }
            c[axis] = next as u32;
            t = exit;
            while l < top {
                let parent = c.map(|k| k >> 1);
                let up = &self.levels[l + 1];
                if up.is_occupied(parent) && !up.is_full(parent) {
                    break;
                }
                l += 1;
                c = parent;
            }
        }
    }

    /// Where the ray leaves cell `c` of level `l`, and through which axis's plane.
    #[inline]
    fn exit(&self, ray: &RayCtx, l: usize, c: [u32; 3]) -> (f32, usize) {
        let mut best = (f32::INFINITY, 0);
        for (a, &ca) in c.iter().enumerate() {
            let k = match ray.step[a] {
                0 => continue,
                s if s > 0 => (ca + 1) << l,
                _ => ca << l,
            };
            let t = (self.grid.plane(a, k) - ray.origin[a]) * ray.inv[a];
            if t < best.0 {
                best = (t, a);
            }
        }
        best
    }

    /// The child (on level `l`) of cell `parent` (on level `l + 1`) that holds the ray's
    /// point at `t`, clamped into the parent so rounding never leaves it.
    #[inline]
    fn child(&self, ray: &RayCtx, l: usize, parent: [u32; 3], t: f32) -> [u32; 3] {
        let fine = self.grid.locate_along(ray.origin + t * ray.dir, ray.step);
        let n = self.levels[l].n;
        [0, 1, 2].map(|a| (fine[a] >> l).clamp(2 * parent[a], (2 * parent[a] + 1).min(n - 1)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::{Analytic, Primitive, ShColor, Shape};

    fn one(shape: Shape) -> Analytic {
        Analytic {
            primitives: vec![Primitive {
                shape,
                density: 1.0,
                color: ShColor::constant(Vec3::ONE),
            }],
        }
    }

    #[test]
    fn pyramid_shape_and_fill_of_a_box() {
        // A box filling [0, 1]³: padded bounds make every cell overlap it.
        let f = one(Shape::Box {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        });
        let occ = Occupancy::build(&f, 16);
        assert_eq!(occ.resolution(), 16);
        // 16 → 8 → 4.
        assert_eq!(occ.levels.len(), 3);
        assert_eq!(occ.fill_ratio(), 1.0);
        let occ = Occupancy::build(&f, 37);
        let ns: Vec<u32> = occ.levels.iter().map(|l| l.n).collect();
        assert_eq!(ns, [37, 19, 10, 5, 3]);
        // Every coarse cell of a fully occupied grid is full.
        for l in &occ.levels {
            for z in 0..l.n {
                for y in 0..l.n {
                    for x in 0..l.n {
                        assert!(l.is_full([x, y, z]));
                    }
                }
            }
        }
    }

    #[test]
    fn sphere_fill_ratio_is_near_its_volume() {
        let f = one(Shape::Sphere {
            center: Vec3::new(1.0, 2.0, 3.0),
            radius: 2.0,
        });
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

    /// Coarse levels against a direct OR / AND over their finest cells.
    #[test]
    fn coarse_levels_are_or_and_of_finest() {
        let f = Analytic {
            primitives: vec![
                Primitive {
                    shape: Shape::Sphere {
                        center: Vec3::ZERO,
                        radius: 1.0,
                    },
                    density: 1.0,
                    color: ShColor::constant(Vec3::ONE),
                },
                Primitive {
                    shape: Shape::Gaussian {
                        center: Vec3::new(1.5, 1.5, 0.0),
                        sigma: 0.1,
                        cutoff: 4.0,
                    },
                    density: 1.0,
                    color: ShColor::constant(Vec3::ONE),
                },
            ],
        };
        let occ = Occupancy::build(&f, 23);
        let fine = &occ.levels[0];
        for (l, level) in occ.levels.iter().enumerate().skip(1) {
            let s = 1u32 << l;
            for z in 0..level.n {
                for y in 0..level.n {
                    for x in 0..level.n {
                        let (mut any, mut all) = (false, true);
                        for fz in z * s..((z + 1) * s).min(23) {
                            for fy in y * s..((y + 1) * s).min(23) {
                                for fx in x * s..((x + 1) * s).min(23) {
                                    let o = fine.is_occupied([fx, fy, fz]);
                                    any |= o;
                                    all &= o;
                                }
                            }
                        }
                        assert_eq!(level.is_occupied([x, y, z]), any, "level {l} {x} {y} {z}");
                        assert_eq!(level.is_full([x, y, z]), all, "level {l} {x} {y} {z}");
                    }
                }
            }
        }
    }

    #[test]
    fn tiny_resolutions_cover_the_chord() {
        let f = one(Shape::Sphere {
            center: Vec3::new(0.5, 0.0, 0.0),
            radius: 1.0,
        });
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
