//! instant-ngp's cascaded occupancy grid, in instant-ngp's own coordinates.
//!
//! Cascade `c` is a `128³` grid over the cube `0.5 ± 2^(c−1)` (cascade 0 is the unit cube,
//! each next one twice as wide). A point `q` belongs to the smallest cascade that contains it
//! strictly — the smallest `c` with `max|q − 0.5| < 2^(c−1)` — and lies in its cell
//! `⌊128·((q − 0.5)/2^c + 0.5)⌋`. The snapshot stores one fp16 density per cell, cascade
//! after cascade, each cascade in Morton order (bit `3k` of the index is bit `k` of x, then
//! y, then z); a cell is occupied where its value exceeds `min(0.01, mean)`, the mean taken
//! over cascade 0 with negative values (cells no training camera saw) counted as zero
//! (instant-ngp's `update_density_grid_mean_and_bitfield` and `grid_to_bitfield`).
//! Instant-ngp marches only occupied cells, so the field's density is zero elsewhere.
//!
//! For region queries each cascade also keeps an OR pyramid (128³, 64³, …, 1³). Cells are
//! stored as bits (64 to a word): five cascades take 1.5 MB instead of 12 MB of `bool`s,
//! so the marcher's per-sample occupancy test stays within the CPU's second-level cache.
//!
//! Instant-ngp's own marcher reads a different bitfield ([`Cascades::march_occupied`]): each
//! cascade `c ≥ 1` has the occupancy of cascade `c − 1`, max-pooled over 2×2×2 cells, OR-ed
//! into its central cells `[32, 96)³`, which cover cascade `c − 1` (`bitfield_max_pool`,
//! applied from cascade 1 outwards), so a coarse cell is empty only where every finer cell
//! inside it is. Its marcher climbs to the coarsest empty cell around a point to skip it.

use glam::{DVec3, Vec3};

/// Cells per axis of a cascade.
pub(crate) const GRID: usize = 128;
/// The finest level of the OR pyramid whose empty blocks the mask walk skips whole
/// ([`Cascades::walk`]): leaving a block takes a few face crossings, which saves nothing
/// over stepping through a block of 2³ cell by cell (measured: the trained fog's fill
/// series at its smallest ball, where the walk is most of a ray's setup).
const SKIP_LEVEL: usize = 2;
/// Instant-ngp's occupancy threshold on the density (optical thickness per cell).
const MIN_THICKNESS: f32 = 0.01;

/// The occupancy of every cascade.
#[derive(Clone, Debug)]
pub(crate) struct Cascades {
    /// Per cascade, per pyramid level `m` (`GRID >> m` cells per axis, x fastest).
    mips: Vec<Vec<Bits>>,
    /// Instant-ngp's marching bitfield: per cascade, 128³ bits in Morton order (bit `i % 8`
    /// of byte `i / 8`), finer cascades max-pooled into the centre.
    march: Vec<Vec<u8>>,
    occupied: u64,
    /// Per cascade, its lowest and highest occupied cell along each axis (`None`: none is):
    /// [`Cascades::segments`] walks only the part of a ray inside that box.
    occupied_box: Vec<Option<[[usize; 3]; 2]>>,
    /// Per cascade, a sphere `(centre, radius²)` around that box widened by a cell on each
    /// side, in coordinates `q − 0.5`: a ray whose line misses it is not walked, found with
    /// a few multiplications where clipping it to the box takes six divisions.
    occupied_sphere: Vec<Option<(DVec3, f64)>>,
}

/// A fixed-size set of cells: bit `i % 64` of word `i / 64`.
#[derive(Clone, Debug)]
struct Bits(Vec<u64>);

impl Bits {
    fn new(len: usize) -> Self {
        Bits(vec![0; len.div_ceil(64)])
    }

    #[inline]
    fn get(&self, i: usize) -> bool {
        (self.0[i >> 6] >> (i & 63)) & 1 != 0
    }

    #[inline]
    fn set(&mut self, i: usize) {
        self.0[i >> 6] |= 1 << (i & 63);
    }
}

/// `2^e` exactly for `−127 < e < 128` (built from its exponent bits: no `exp2` call per
/// sample); infinity above, zero below (only a file with over a hundred cascades gets there).
#[inline]
fn pow2(e: i32) -> f32 {
    f32::from_bits(((e.clamp(-127, 128) + 127) as u32) << 23)
}

/// Morton index (x in the lowest bit) of a cell of a 128³ grid.
#[inline]
fn morton(x: usize, y: usize, z: usize) -> usize {
    spread(x) | spread(y) << 1 | spread(z) << 2
}

/// The 7 low bits of `v` moved to bits 0, 3, 6, …, 18.
#[inline]
fn spread(v: usize) -> usize {
    let mut v = v & 0x7f;
    v = (v | v << 8) & 0x0f00f;
    v = (v | v << 4) & 0x0c30c3;
    (v | v << 2) & 0x249249
}

/// The cell coordinates of a Morton index (the inverse of [`morton`]).
fn unmorton(i: usize) -> [usize; 3] {
    let gather = |v: usize| (0..7).fold(0, |acc, k| acc | ((v >> (3 * k)) & 1) << k);
    [gather(i), gather(i >> 1), gather(i >> 2)]
}

impl Cascades {
    /// From the snapshot's densities (`values.len()` a positive multiple of 128³).
    pub(crate) fn from_densities(values: &[f32]) -> Option<Self> {
        let n3 = GRID * GRID * GRID;
        if values.is_empty() || !values.len().is_multiple_of(n3) {
            return None;
        }
        let mean = values[..n3]
            .iter()
            .map(|&v| f64::from(v.max(0.0)))
            .sum::<f64>()
            / n3 as f64;
        let threshold = MIN_THICKNESS.min(mean as f32);
        let march = march_bitfield(values, threshold);
        let mut occupied = 0;
        let mut occupied_box = Vec::new();
        let mips = values
            .chunks_exact(n3)
            .map(|cascade| {
                let mut base = Bits::new(n3);
                let mut bounds: Option<[[usize; 3]; 2]> = None;
                for z in 0..GRID {
                    for y in 0..GRID {
                        for x in 0..GRID {
                            if cascade[morton(x, y, z)] > threshold {
                                base.set((z * GRID + y) * GRID + x);
                                occupied += 1;
                                let [lo, hi] = bounds.get_or_insert([[x, y, z]; 2]);
                                for (k, i) in [x, y, z].into_iter().enumerate() {
                                    lo[k] = lo[k].min(i);
                                    hi[k] = hi[k].max(i);
                                }
                            }
                        }
                    }
                }
                occupied_box.push(bounds);
                pyramid(base)
            })
            .collect();
        let occupied_sphere = occupied_box
            .iter()
            .enumerate()
            .map(|(c, b)| {
                let (lo, hi) = Self::widened_box(c, (*b)?);
                Some((0.5 * (lo + hi), (0.5 * (hi - lo)).length_squared()))
            })
            .collect();
        Some(Cascades {
            mips,
            march,
            occupied,
            occupied_box,
            occupied_sphere,
        })
    }

    /// Cascade `c`'s box of occupied cells `[lo, hi]` (grid units) widened by a cell on each
    /// side, in coordinates `q − 0.5`.
    fn widened_box(c: usize, [lo, hi]: [[usize; 3]; 2]) -> (DVec3, DVec3) {
        // Grid units to `q − 0.5`: u = (g/128 − 1/2)·2h.
        let to_u = |g: f64| (g / GRID as f64 - 0.5) * 2.0 * f64::from(Self::half_width(c));
        (
            DVec3::from_array(lo.map(|i| to_u(i as f64 - 1.0))),
            DVec3::from_array(hi.map(|i| to_u(i as f64 + 2.0))),
        )
    }

    /// The box, in instant-ngp coordinates `q`, of every cascade's occupied cells widened
    /// by a cell on each side: outside it the mask holds no cell. `None` where none is
    /// occupied.
    pub(crate) fn occupied_extent(&self) -> Option<(Vec3, Vec3)> {
        let boxes = self.occupied_box.iter().enumerate();
        let boxes = boxes.filter_map(|(c, b)| Some(Self::widened_box(c, (*b)?)));
        let (lo, hi) = boxes.reduce(|(a, b), (lo, hi)| (a.min(lo), b.max(hi)))?;
        Some(((lo + 0.5).as_vec3(), (hi + 0.5).as_vec3()))
    }

    /// Number of cascades.
    pub(crate) fn count(&self) -> usize {
        self.mips.len()
    }

    /// The fraction of occupied cells over all cascades.
    pub(crate) fn fill_ratio(&self) -> f64 {
        self.occupied as f64 / (self.count() * GRID * GRID * GRID) as f64
    }

    /// Half the width of cascade `c`: `2^(c−1)`.
    fn half_width(c: usize) -> f32 {
        pow2(c as i32 - 1)
    }

    /// The cascade and cell of `q`, or `None` beyond the largest cascade.
    #[inline]
    pub(crate) fn cell(&self, q: Vec3) -> Option<(usize, [usize; 3])> {
        let m = (q - Vec3::splat(0.5)).abs().max_element();
        let c = (0..self.count()).find(|&c| m < Self::half_width(c))?;
        let inv = pow2(-(c as i32));
        let u = ((q - Vec3::splat(0.5)) * inv + Vec3::splat(0.5)) * GRID as f32;
        // `⌊v⌋` clamped to the grid: a float-to-integer cast truncates toward zero and
        // saturates (NaN and negatives to 0), which for the clamped result is the same.
        let idx = u.to_array().map(|v| (v as usize).min(GRID - 1));
        Some((c, idx))
    }

    /// Whether `q` lies in an occupied cell.
    #[inline]
    pub(crate) fn occupied_at(&self, q: Vec3) -> bool {
        self.cell(q).is_some_and(|(c, i)| self.occupied_cell(c, i))
    }

    /// Whether cell `[x, y, z]` of cascade `c` is occupied.
    #[inline]
    fn occupied_cell(&self, c: usize, [x, y, z]: [usize; 3]) -> bool {
        self.mips[c][0].get((z * GRID + y) * GRID + x)
    }

    /// The intervals of the ray `q0 + t·v` (instant-ngp coordinates), `t ∈ [t0, t1]`, where
    /// [`Cascades::occupied_at`] holds, appended to `out` sorted and apart (touching
    /// intervals joined). The ray is cut where it crosses the cascades' cubes, and each
    /// piece walks the cells of the cascade that owns its points, from face crossing to
    /// face crossing (worked out in `f64`), skipping blocks of empty cells whole
    /// ([`Cascades::walk`]). An axis along which the ray does not move takes its cell from
    /// `q0` as [`Cascades::cell`] does, so a ray lying in a cell's face gets the cells its
    /// points are looked up in. Elsewhere a crossing may differ from the face an `f32`
    /// point rounds to by the rounding of that point: a sample taken just inside an
    /// interval's end lands inside it. Nothing is allocated but what `out` grows by.
    pub(crate) fn segments(&self, q0: Vec3, v: Vec3, t0: f64, t1: f64, out: &mut Vec<[f64; 2]>) {
        let first = out.len();
        let u0 = (q0 - Vec3::splat(0.5)).as_dvec3();
        let v = v.as_dvec3();
        if !(0..self.count()).any(|c| self.may_meet_occupied(c, u0, v)) {
            return;
        }
        let inside = |c: usize| Self::inside(c, u0, v, (t0, t1));
        // From the outermost cascade in, each owns what lies between its cube and the next
        // smaller one's, before and after it, down to the innermost the ray meets.
        let Some(mut part) = self.count().checked_sub(1).and_then(inside) else {
            return;
        };
        let mut m = self.count() - 1;
        while let Some(inner) = m.checked_sub(1).and_then(inside) {
            self.walk(m, u0, v, (part.0, inner.0), out, first);
            (m, part) = (m - 1, inner);
        }
        self.walk(m, u0, v, part, out, first);
        for c in m + 1..self.count() {
            let outer = inside(c).unwrap_or((t0, t0));
            self.walk(c, u0, v, (part.1, outer.1), out, first);
            part = outer;
        }
    }

    /// The part of `[t0, t1]` where the ray `0.5 + u0 + t·v` is inside cascade `c`'s cube;
    /// `None` where it misses it. Nested like the cubes, exactly: each bound is a chain of
    /// correctly rounded (so monotonic) operations on the half width, which doubles from
    /// cascade to cascade, so a cube's part lies within the next larger one's.
    fn inside(c: usize, u0: DVec3, v: DVec3, (t0, t1): (f64, f64)) -> Option<(f64, f64)> {
        let h = f64::from(Self::half_width(c));
        let (mut a, mut b) = (t0, t1);
        for k in 0..3 {
            if v[k] == 0.0 {
                if u0[k].abs() >= h {
                    return None;
                }
                continue;
            }
            let (p, q) = ((-h - u0[k]) / v[k], (h - u0[k]) / v[k]);
            a = a.max(p.min(q));
            b = b.min(p.max(q));
        }
        (a < b).then_some((a, b))
    }

    /// Whether the line `0.5 + u0 + t·v` passes within cascade `c`'s
    /// [`occupied_sphere`](Cascades::occupied_sphere), with margins for rounding.
    #[inline]
    fn may_meet_occupied(&self, c: usize, u0: DVec3, v: DVec3) -> bool {
        let Some((centre, radius2)) = self.occupied_sphere[c] else {
            return false;
        };
        // Squared distance from the line, times `|v|²`.
        let (w, v2) = (centre - u0, v.length_squared());
        let along = w.dot(v);
        w.length_squared() * v2 - along * along
            <= (radius2 * (1.0 + 1e-6) + 1e-12 * w.length_squared()) * v2
    }

    /// Appends the occupied cells of cascade `c` that the ray `0.5 + u0 + t·v` crosses over
    /// `[ta, tb]` to `out` (joined to `out[first..]`'s last interval where they touch). The
    /// cells of the next smaller cascade's cube are skipped: the walk meets them only where
    /// rounding puts the start on the wrong side of that cube's face.
    ///
    /// The walk visits the cells one by one, but where a cell is empty it looks up the
    /// largest block of the OR pyramid around it that is empty too, and goes to the face the
    /// ray leaves that block by: from there, every axis is on the cell the one-by-one walk
    /// would have reached (the cells are found from the same face crossings), so the
    /// intervals are the same, and a ray through empty space costs per block, not per cell.
    fn walk(
        &self,
        c: usize,
        u0: DVec3,
        v: DVec3,
        (ta, tb): (f64, f64),
        out: &mut Vec<[f64; 2]>,
        first: usize,
    ) {
        let Some([lo, hi]) = self.occupied_box[c] else {
            return;
        };
        if !self.may_meet_occupied(c, u0, v) {
            return;
        }
        let h = f64::from(Self::half_width(c));
        // Grid units: g = 128·(u/2h + 1/2). Both factors are powers of two: multiplying by
        // one is dividing by the other, exactly.
        let per_unit = GRID as f64 / (2.0 * h);
        let cell_size = 2.0 * h / GRID as f64;
        // Only the part of the ray inside the box of occupied cells, widened by a cell on
        // each side (so rounding at its faces loses nothing), can meet one.
        let (mut ta, mut tb) = (ta, tb);
        for k in (0..3).filter(|&k| v[k] != 0.0) {
            let at = |g: f64| ((g - 0.5 * GRID as f64) * cell_size - u0[k]) / v[k];
            let (a, b) = (at(lo[k] as f64 - 1.0), at(hi[k] as f64 + 2.0));
            ta = ta.max(a.min(b));
            tb = tb.min(a.max(b));
        }
        if ta >= tb {
            return;
        }
        let grid_at = |k: usize, t: f64| (u0[k] + v[k] * t) * per_unit + 0.5 * GRID as f64;
        let mut cell = [0i64; 3];
        let mut next = [f64::INFINITY; 3];
        for k in 0..3 {
            cell[k] = if v[k] == 0.0 {
                // As `cell` computes it, in f32.
                let u = ((u0[k] as f32) * pow2(-(c as i32)) + 0.5) * GRID as f32;
                (u as i64).clamp(0, GRID as i64 - 1)
            } else {
                (grid_at(k, ta).floor() as i64).clamp(0, GRID as i64 - 1)
            };
        }
        if (0..3).any(|k| v[k] == 0.0 && !(lo[k]..=hi[k]).contains(&(cell[k] as usize))) {
            return;
        }
        let step = v.to_array().map(|v| if v > 0.0 { 1 } else { -1 });
        // Where the ray leaves cell `cell` along axis `k`.
        let crossing = |k: usize, cell: i64| {
            let face = if v[k] > 0.0 { cell + 1 } else { cell };
            ((face as f64 - 0.5 * GRID as f64) * cell_size - u0[k]) / v[k]
        };
        for k in 0..3 {
            if v[k] != 0.0 {
                next[k] = crossing(k, cell[k]);
            }
        }
        // A point is the smaller cascade's where it lies strictly inside its cube: along an
        // axis the ray moves on, where its cell is a central one; along one it does not,
        // where `cell` finds it so.
        let inner =
            c > 0 && (0..3).all(|k| v[k] != 0.0 || (u0[k] as f32).abs() < Self::half_width(c - 1));
        let central =
            |k: usize, i: i64| v[k] == 0.0 || (GRID as i64 / 4..3 * GRID as i64 / 4).contains(&i);
        let in_grid = |i: i64| (0..GRID as i64).contains(&i);
        let mut t = ta;
        loop {
            let index = cell.map(|i| i as usize);
            let occupied = self.occupied_cell(c, index);
            if !occupied {
                if let Some(m) = self.empty_block(c, index) {
                    // The block's last cell along each axis, and where the ray leaves it.
                    let last = |k: usize| {
                        let block = (cell[k] >> m) << m;
                        if v[k] > 0.0 {
                            block + (1 << m) - 1
                        } else {
                            block
                        }
                    };
                    let exit = (0..3)
                        .filter(|&k| v[k] != 0.0)
                        .map(|k| crossing(k, last(k)))
                        .fold(tb, f64::min);
                    if exit >= tb {
                        return;
                    }
                    for k in 0..3 {
                        if next[k] > exit {
                            continue;
                        }
                        // The cell whose exit face is the first crossed after `exit`:
                        // guessed from the position there, never behind the next cell,
                        // then set by the crossings themselves.
                        let guess = (grid_at(k, exit).floor() as i64).clamp(-1, GRID as i64);
                        let ahead = cell[k] + step[k];
                        let mut i = if step[k] > 0 {
                            guess.max(ahead)
                        } else {
                            guess.min(ahead)
                        };
                        while i != ahead && crossing(k, i - step[k]) > exit {
                            i -= step[k];
                        }
                        let leaves = loop {
                            let leaves = crossing(k, i);
                            if leaves > exit {
                                break leaves;
                            }
                            i += step[k];
                        };
                        if !in_grid(i) {
                            return;
                        }
                        (cell[k], next[k]) = (i, leaves);
                    }
                    t = t.max(exit);
                    continue;
                }
            }
            let tn = next[0].min(next[1]).min(next[2]).min(tb);
            let owned = !(inner && (0..3).all(|k| central(k, cell[k])));
            if tn > t && owned && occupied {
                match out[first..].last_mut() {
                    Some(last) if last[1] >= t => last[1] = last[1].max(tn),
                    _ => out.push([t, tn]),
                }
            }
            if tn >= tb {
                return;
            }
            for k in 0..3 {
                if next[k] == tn {
                    cell[k] += step[k];
                    if !in_grid(cell[k]) {
                        return;
                    }
                    next[k] = crossing(k, cell[k]);
                }
            }
            t = t.max(tn);
        }
    }

    /// The level of the largest block of the OR pyramid around the empty cell `[x, y, z]`
    /// of cascade `c` that is empty, `2^m` cells across; `None` where the cell's own block
    /// of `(2^SKIP_LEVEL)³` is not (the walk then steps to the next cell).
    #[inline]
    fn empty_block(&self, c: usize, [x, y, z]: [usize; 3]) -> Option<usize> {
        let levels = &self.mips[c];
        let empty = |m: usize| {
            let n = GRID >> m;
            !levels[m].get((((z >> m) * n + (y >> m)) * n) + (x >> m))
        };
        (SKIP_LEVEL..levels.len()).take_while(|&m| empty(m)).last()
    }

    /// Whether instant-ngp's marching bitfield has the cell of cascade `mip` holding `q`
    /// occupied: `q` is carried into the cascade's unit cube, `(q − 0.5)·2^−mip + 0.5`, and
    /// its cell is that times 128 truncated toward zero (so a point less than one cell below
    /// the cube still reads cell 0, as in instant-ngp); a cell outside the grid, or a
    /// cascade the snapshot lacks, is empty.
    #[inline]
    pub(crate) fn march_occupied(&self, q: [f64; 3], mip: usize) -> bool {
        let Some(bits) = self.march.get(mip) else {
            return false;
        };
        let scale = f64::from(pow2(-(mip as i32)));
        let mut cell = [0usize; 3];
        for (c, v) in cell.iter_mut().zip(q) {
            let u = ((v - 0.5) * scale + 0.5) * GRID as f64;
            // Truncation toward zero; NaN fails the test.
            if !(u > -1.0 && u < GRID as f64) {
                return false;
            }
            *c = u as usize;
        }
        let i = morton(cell[0], cell[1], cell[2]);
        bits[i >> 3] >> (i & 7) & 1 != 0
    }

    /// Whether any point of the box `[lo, hi]` may lie in an occupied cell (conservative).
    pub(crate) fn may_be_occupied(&self, lo: Vec3, hi: Vec3) -> bool {
        let d = (lo - Vec3::splat(0.5))
            .abs()
            .max((hi - Vec3::splat(0.5)).abs())
            .max_element();
        (0..self.count()).any(|c| {
            let h = Self::half_width(c);
            // Points of cascade c have max|q − 0.5| ≥ h/2: a box strictly inside the next
            // smaller cascade has none.
            if c > 0 && d < 0.5 * h * (1.0 - 1e-6) {
                return false;
            }
            let to_cell = |v: f32| ((v - 0.5) / (2.0 * h) + 0.5) * GRID as f32;
            let pad = 1e-3;
            let a = lo.to_array().map(|v| to_cell(v) - pad);
            let b = hi.to_array().map(|v| to_cell(v) + pad);
            if (0..3).any(|k| b[k] < 0.0 || a[k] >= GRID as f32) {
                return false;
            }
            let i0 = a.map(|v| v.max(0.0) as usize);
            let i1 = b.map(|v| (v.max(0.0) as usize).min(GRID - 1));
            self.any_in(c, i0, i1)
        })
    }

    /// Whether cascade `c` has an occupied cell in the index box `[i0, i1]`: looked up in the
    /// pyramid level where the box spans at most three cells per axis.
    fn any_in(&self, c: usize, i0: [usize; 3], i1: [usize; 3]) -> bool {
        let m = (0..self.mips[c].len())
            .find(|&m| (0..3).all(|k| (i1[k] >> m) - (i0[k] >> m) <= 2))
            .unwrap_or(self.mips[c].len() - 1);
        let n = GRID >> m;
        let level = &self.mips[c][m];
        for z in i0[2] >> m..=i1[2] >> m {
            for y in i0[1] >> m..=i1[1] >> m {
                for x in i0[0] >> m..=i1[0] >> m {
                    if level.get((z * n + y) * n + x) {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Instant-ngp's marching bitfield (see the module doc): per cascade, bit `i` set where the
/// Morton-ordered value `i` exceeds `threshold`; then from cascade 1 outwards each
/// cascade's central cells OR-ed with the 2×2×2 max-pool of the cascade inside it.
fn march_bitfield(values: &[f32], threshold: f32) -> Vec<Vec<u8>> {
    let n3 = GRID * GRID * GRID;
    let mut levels: Vec<Vec<u8>> = values
        .chunks_exact(n3)
        .map(|cascade| {
            cascade
                .chunks_exact(8)
                .map(|v| (0..8).fold(0u8, |b, j| b | u8::from(v[j] > threshold) << j))
                .collect()
        })
        .collect();
    for c in 1..levels.len() {
        let (inner, outer) = levels.split_at_mut(c);
        let (fine, coarse) = (&inner[c - 1], &mut outer[0]);
        // A byte of the finer cascade holds a 2×2×2 block (Morton order): its OR is one
        // coarse cell. Coarse cell (x, y, z) of the block at Morton index i lies at
        // GRID/4 + (x, y, z) in the coarser cascade.
        for (i, &byte) in fine.iter().enumerate() {
            if byte != 0 {
                let [x, y, z] = unmorton(i);
                let at = morton(x + GRID / 4, y + GRID / 4, z + GRID / 4);
                coarse[at >> 3] |= 1 << (at & 7);
            }
        }
    }
    levels
}

/// The OR pyramid of a cubic grid of side `GRID`: level `m + 1` cell is occupied where any
/// of its 8 children is.
fn pyramid(base: Bits) -> Vec<Bits> {
    let mut levels = vec![base];
    let mut n = GRID;
    while n > 1 {
        let (prev, h) = (&levels[levels.len() - 1], n / 2);
        let mut next = Bits::new(h * h * h);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    if prev.get((z * n + y) * n + x) {
                        next.set(((z / 2) * h + y / 2) * h + x / 2);
                    }
                }
            }
        }
        levels.push(next);
        n = h;
    }
    levels
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two cascades, each with one occupied cell, written in Morton order by hand.
    fn two_cascades() -> Cascades {
        let n3 = GRID * GRID * GRID;
        let mut v = vec![0.0f32; 2 * n3];
        // Cascade 0, cell (5, 6, 7).
        v[morton_by_hand(5, 6, 7)] = 1.0;
        // Cascade 1, cell (127, 0, 64).
        v[n3 + morton_by_hand(127, 0, 64)] = 1.0;
        Cascades::from_densities(&v).unwrap()
    }

    fn morton_by_hand(x: usize, y: usize, z: usize) -> usize {
        let mut r = 0;
        for k in 0..7 {
            r |= ((x >> k) & 1) << (3 * k)
                | ((y >> k) & 1) << (3 * k + 1)
                | ((z >> k) & 1) << (3 * k + 2);
        }
        r
    }

    #[test]
    fn morton_order_and_threshold() {
        assert_eq!(morton(1, 0, 0), 1);
        assert_eq!(morton(0, 1, 0), 2);
        assert_eq!(morton(0, 0, 1), 4);
        assert_eq!(morton(3, 0, 0), 0b1001);
        let c = two_cascades();
        assert_eq!(c.count(), 2);
        // The centre of cascade-0 cell (5, 6, 7) is at ((k + 0.5)/128).
        let centre = |k: [usize; 3], c: i32| {
            Vec3::from_array(k.map(|v| ((v as f32 + 0.5) / 128.0 - 0.5) * 2f32.powi(c) + 0.5))
        };
        assert!(c.occupied_at(centre([5, 6, 7], 0)));
        assert!(!c.occupied_at(centre([5, 6, 8], 0)));
        // Cascade 1 cell (127, 0, 64) lies outside cascade 0 (x ≈ 1.49).
        assert!(c.occupied_at(centre([127, 0, 64], 1)));
        // Cascade 1's cell containing the unit cube is never consulted for inner points.
        assert!(!c.occupied_at(Vec3::splat(0.5)));
        // Beyond the largest cascade.
        assert!(!c.occupied_at(Vec3::new(2.0, 0.5, 0.5)));
        // Mean of cascade 0 is 1/128³ < 0.01: that is the threshold, and 1.0 exceeds it.
        assert!((c.fill_ratio() - 2.0 / (2 * GRID * GRID * GRID) as f64).abs() < 1e-12);
    }

    #[test]
    fn region_queries_are_conservative_and_tight() {
        let c = two_cascades();
        let cell = 1.0 / 128.0;
        let lo = Vec3::new(5.0, 6.0, 7.0) * cell;
        assert!(c.may_be_occupied(lo, lo + Vec3::splat(cell)));
        assert!(c.may_be_occupied(Vec3::ZERO, Vec3::ONE));
        // A box two cells away from it is empty.
        let far = lo + Vec3::new(3.0 * cell, 0.0, 0.0);
        assert!(!c.may_be_occupied(far, far + Vec3::splat(cell)));
        // A large box inside cascade 0 but away from its cell.
        assert!(!c.may_be_occupied(Vec3::splat(0.5), Vec3::splat(0.9)));
        // The cascade-1 cell is found from a box that reaches it.
        assert!(c.may_be_occupied(Vec3::new(1.4, -0.5, 0.4), Vec3::new(1.5, -0.4, 0.6)));
    }

    #[test]
    fn the_occupied_extent_holds_every_occupied_cell_and_a_cell_more() {
        // Cascade 0's cell (5, 6, 7) spans q = g/128, cascade 1's (127, 0, 64) q = g/64 − 1/2,
        // each widened by a cell: the union of [4, 7]/128, [5, 8]/128, [6, 9]/128 and
        // [126, 129]/64, [−1, 2]/64, [63, 66]/64 less 1/2.
        let (lo, hi) = two_cascades().occupied_extent().unwrap();
        assert_eq!(lo, Vec3::new(4.0 / 128.0, -1.0 / 64.0 - 0.5, 6.0 / 128.0));
        assert_eq!(
            hi,
            Vec3::new(129.0 / 64.0 - 0.5, 8.0 / 128.0, 66.0 / 64.0 - 0.5)
        );
        // Two clumps in cascade 0 and a cell of cascade 1: the box is theirs, and every
        // occupied point drawn around it lies inside.
        let n3 = GRID * GRID * GRID;
        let mut v = vec![0.0f32; 2 * n3];
        for (c, [x, y, z]) in [(0, [40, 50, 60]), (0, [44, 52, 61]), (1, [70, 66, 64])] {
            v[c * n3 + morton_by_hand(x, y, z)] = 1.0;
        }
        let c = Cascades::from_densities(&v).unwrap();
        let (lo, hi) = c.occupied_extent().unwrap();
        assert_eq!(lo, Vec3::new(39.0, 49.0, 59.0) / 128.0);
        assert_eq!(hi, Vec3::new(72.0, 68.0, 66.0) / 64.0 - 0.5);
        let mut rng = crate::rng::SplitMix64::new(3);
        let mut found = 0;
        for _ in 0..200_000 {
            let q = rng.in_cube(lo.min_element() - 0.1, hi.max_element() + 0.1);
            if c.occupied_at(q) {
                found += 1;
                assert!(
                    q.cmpge(lo).all() && q.cmple(hi).all(),
                    "{q} outside {lo} {hi}"
                );
            }
        }
        assert!(found > 0);
        let empty = Cascades::from_densities(&vec![0.0; n3]).unwrap();
        assert_eq!(empty.occupied_extent(), None);
    }

    #[test]
    fn unseen_cells_count_as_empty_in_the_mean() {
        // Cascade 0 mostly unseen (−1), with one cell in 32 at 0.008 and one in 32 at
        // 0.0002: the raw mean is negative (every seen cell would pass), the clamped one is
        // 0.0082/32 = 0.000256, which 0.008 exceeds and 0.0002 does not.
        let n3 = GRID * GRID * GRID;
        let mut v = vec![-1.0f32; n3];
        for x in v.iter_mut().skip(n3 / 2).step_by(16) {
            *x = 0.008;
        }
        for x in v.iter_mut().skip(n3 / 2 + 1).step_by(16) {
            *x = 0.0002;
        }
        let c = Cascades::from_densities(&v).unwrap();
        assert!(
            (c.fill_ratio() - 1.0 / 32.0).abs() < 1e-12,
            "{}",
            c.fill_ratio()
        );
    }

    #[test]
    fn the_marching_bitfield_pools_finer_cascades_into_the_centre() {
        let c = two_cascades();
        let centre = |k: [usize; 3], c: i32| {
            k.map(|v| ((v as f64 + 0.5) / 128.0 - 0.5) * 2f64.powi(c) + 0.5)
        };
        // Cascade 0's cell (5, 6, 7) as itself, and inside cascade 1's cell
        // (32 + 2, 32 + 3, 32 + 3) that holds it.
        assert!(c.march_occupied(centre([5, 6, 7], 0), 0));
        assert!(c.march_occupied(centre([34, 35, 35], 1), 1));
        assert!(!c.march_occupied(centre([34, 35, 36], 1), 1));
        // The plain lookup keeps the smallest cascade's own cells.
        assert!(c.march_occupied(centre([127, 0, 64], 1), 1));
        // Outside the grid, or a cascade the snapshot lacks.
        assert!(!c.march_occupied([1.6, 0.5, 0.5], 1));
        assert!(!c.march_occupied([0.5, 0.5, 0.5], 2));
        // Less than a cell below the cube truncates to cell 0 (instant-ngp's int cast).
        let mut v = vec![0.0f32; GRID * GRID * GRID];
        v[0] = 1.0;
        let c = Cascades::from_densities(&v).unwrap();
        assert!(c.march_occupied([-0.004, 0.001, 0.001], 0));
        assert!(!c.march_occupied([-0.008, 0.001, 0.001], 0));
        assert_eq!(unmorton(morton(5, 6, 7)), [5, 6, 7]);
        assert_eq!(spread(0x7f), 0x49249);
    }

    /// Checks `segments` along the ray `q0 + t·v`, `t ∈ [t0, t1]`, against `occupied_at`
    /// sampled densely at the `f32` points a marcher would ask: sorted, apart, and agreeing
    /// with every sample farther than `slack` (in `t`) from a segment's end.
    fn check_segments(c: &Cascades, q0: Vec3, v: Vec3, (t0, t1): (f64, f64), slack: f64) {
        let mut segs = Vec::new();
        c.segments(q0, v, t0, t1, &mut segs);
        for s in &segs {
            assert!(
                t0 <= s[0] && s[0] < s[1] && s[1] <= t1,
                "{s:?} outside [{t0}, {t1}]"
            );
        }
        for w in segs.windows(2) {
            assert!(w[0][1] < w[1][0], "not sorted and apart: {w:?}");
        }
        let n = 20_000;
        for j in 0..=n {
            let t = t0 + (t1 - t0) * j as f64 / n as f64;
            let near_end = segs
                .iter()
                .any(|s| (t - s[0]).abs() < slack || (t - s[1]).abs() < slack);
            if near_end {
                continue;
            }
            let inside = segs.iter().any(|s| s[0] <= t && t <= s[1]);
            let q = q0 + v * t as f32;
            assert_eq!(
                inside,
                c.occupied_at(q),
                "t = {t} (q = {q}) on the ray {q0} + t·{v}: segments {segs:?}"
            );
        }
    }

    /// Three cascades, a seeded fifth of their cells occupied.
    fn seeded_cascades() -> Cascades {
        let n3 = GRID * GRID * GRID;
        let mut rng = crate::rng::SplitMix64::new(11);
        let v: Vec<f32> = (0..3 * n3)
            .map(|_| if rng.unit() < 0.2 { 1.0 } else { 0.0 })
            .collect();
        Cascades::from_densities(&v).unwrap()
    }

    #[test]
    fn mask_segments_agree_with_sampled_cells() {
        let c = seeded_cascades();
        let mut rng = crate::rng::SplitMix64::new(5);
        for _ in 0..40 {
            // From outside every cascade (half width 2) or from inside one, in any direction.
            let outside = rng.unit() < 0.5;
            let reach = if outside { 3.0 } else { 1.5 };
            let q0 = rng.in_cube(0.5 - reach, 0.5 + reach);
            let d = rng.in_cube(-1.0, 1.0).normalize();
            check_segments(&c, q0, d, (0.0, 8.0), 1e-5);
        }
    }

    #[test]
    fn mask_segments_of_small_clumps_agree_with_sampled_cells() {
        // Per cascade, a ball of cells 6 across at a seeded place (the walk is clipped to
        // the box of occupied cells): rays aimed at a clump's cells, from anywhere, and
        // rays along the axes through them.
        let n3 = GRID * GRID * GRID;
        let mut rng = crate::rng::SplitMix64::new(23);
        let mut v = vec![0.0f32; 3 * n3];
        let mut centres = Vec::new();
        for cascade in 0..3 {
            let centre = [0; 3].map(|_| rng.range(10.0, 118.0) as usize);
            // The cells within 3 of the centre, found in the cube of 7 around it.
            let near = |i: usize| i - 3..=i + 3;
            for x in near(centre[0]) {
                for y in near(centre[1]) {
                    for z in near(centre[2]) {
                        let d2 = [x, y, z]
                            .iter()
                            .zip(centre)
                            .map(|(&i, c)| (i as f64 - c as f64).powi(2))
                            .sum::<f64>();
                        if d2 <= 9.0 {
                            v[cascade * n3 + morton(x, y, z)] = 1.0;
                        }
                    }
                }
            }
            centres.push((cascade as i32, centre));
        }
        let c = Cascades::from_densities(&v).unwrap();
        let at = |i: f64, cascade: i32| ((i / GRID as f64 - 0.5) * 2f64.powi(cascade) + 0.5) as f32;
        for &(cascade, centre) in &centres {
            let target = Vec3::from(centre.map(|i| at(i as f64 + 0.5, cascade)));
            for _ in 0..20 {
                let q0 = rng.in_cube(-2.5, 3.5);
                let jitter = rng.in_cube(-0.02, 0.02);
                let d = (target + jitter - q0).normalize();
                check_segments(&c, q0, d, (0.0, 8.0), 1e-5);
            }
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                check_segments(&c, target - 3.0 * axis, axis, (0.0, 6.0), 1e-5);
            }
        }
    }

    #[test]
    fn a_lone_cell_next_to_large_empty_blocks_is_found_whole() {
        // Cascade 0: a lone cell at the corner of the empty half x ≥ 64 (a block of 64³
        // and smaller ones around it), with cells at two far corners so the walk's box is
        // the whole grid; cascade 1: a lone cell just outside cascade 0's cube. Rays aimed
        // at a lone cell's centre, corners and edges from anywhere (they cross empty blocks
        // of every size, and graze the cell), and along the axes through it and in its faces.
        let n3 = GRID * GRID * GRID;
        let mut v = vec![0.0f32; 2 * n3];
        for (cascade, [x, y, z]) in [
            (0, [63, 64, 64]),
            (0, [0, 0, 0]),
            (0, [127, 127, 127]),
            (1, [97, 64, 40]),
        ] {
            v[cascade * n3 + morton(x, y, z)] = 1.0;
        }
        let c = Cascades::from_densities(&v).unwrap();
        let mut rng = crate::rng::SplitMix64::new(31);
        for (cascade, lone) in [(0, [63, 64, 64]), (1, [97, 64, 40])] {
            let at = |i: [f64; 3]| {
                Vec3::from(i.map(|i| ((i / GRID as f64 - 0.5) * 2f64.powi(cascade) + 0.5) as f32))
            };
            let centre = at(lone.map(|i| i as f64 + 0.5));
            for j in 0..60 {
                // A corner (j % 3 == 0), the middle of an edge (1) or the centre (2).
                let offset = [0; 3].map(|_| match j % 3 {
                    0 => f64::from(rng.unit() < 0.5),
                    1 => [0.0, 0.5, 1.0][(rng.unit() * 3.0) as usize % 3],
                    _ => 0.5,
                });
                let target = at([0, 1, 2].map(|k| lone[k] as f64 + offset[k]));
                let q0 = rng.in_cube(-2.5, 3.5);
                check_segments(&c, q0, (target - q0).normalize(), (0.0, 8.0), 1e-5);
            }
            let face = at(lone.map(|i| i as f64));
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                check_segments(&c, centre - 3.0 * axis, axis, (0.0, 6.0), 1e-5);
                check_segments(&c, face - 3.0 * axis, axis, (0.0, 6.0), 1e-5);
            }
        }
    }

    #[test]
    fn rays_along_faces_and_edges_get_the_cells_their_points_read() {
        let c = seeded_cascades();
        let face = |k: f32, cascade: i32| (k / GRID as f32 - 0.5) * 2f32.powi(cascade) + 0.5;
        // In a cell face of cascade 0 (y), along x; along an edge (y and z) of cascade 1
        // crossing cascade 0 too; along the faces of the cascades' own cubes.
        let rays = [
            (Vec3::new(-2.5, face(40.0, 0), 0.3), Vec3::X),
            (Vec3::new(-2.5, face(40.0, 1), face(70.0, 1)), Vec3::X),
            (Vec3::new(0.3, -2.5, face(0.0, 0)), Vec3::Y),
            (Vec3::new(face(128.0, 1), face(20.0, 1), -2.5), Vec3::Z),
            (Vec3::new(face(64.0, 0), -2.5, face(64.0, 0)), Vec3::Y),
        ];
        for (q0, d) in rays {
            check_segments(&c, q0, d, (0.0, 6.0), 1e-5);
        }
    }

    #[test]
    fn a_ray_clipping_a_cell_corner_gets_its_sliver() {
        // One occupied cell of cascade 0, (5, 6, 7); a ray in the plane z = its middle,
        // cutting its (x, y) = (6, 7) corner 1e-4 of a cell deep: a sliver 2e-4 of a cell
        // long along a 45° ray.
        let n3 = GRID * GRID * GRID;
        let mut v = vec![0.0f32; n3];
        v[morton(5, 6, 7)] = 1.0;
        let c = Cascades::from_densities(&v).unwrap();
        let cell = 1.0 / GRID as f64;
        let depth = 1e-4 * cell;
        // The line x + y = 13·cell − depth, z = 7.5·cell.
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        let q0 = Vec3::new(0.0, (13.0 * cell - depth) as f32, (7.5 * cell) as f32);
        let mut segs = Vec::new();
        c.segments(q0, d, 0.0, 2.0, &mut segs);
        assert_eq!(segs.len(), 1, "{segs:?}");
        let [a, b] = segs[0];
        let expected = depth * std::f64::consts::SQRT_2;
        assert!(
            ((b - a) - expected).abs() < 0.05 * expected,
            "{} vs {expected}",
            b - a
        );
        assert!(c.occupied_at(q0 + d * (0.5 * (a + b)) as f32));
        check_segments(&c, q0, d, (0.0, 2.0), 1e-6);
        // A ray 1e-4 of a cell beyond the corner gets nothing.
        let q1 = Vec3::new(0.0, (13.0 * cell + depth) as f32, (7.5 * cell) as f32);
        segs.clear();
        c.segments(q1, d, 0.0, 2.0, &mut segs);
        assert!(segs.is_empty(), "{segs:?}");
    }

    #[test]
    fn occupied_cells_across_a_cascade_face_join() {
        // Every cell of both cascades occupied: a ray through them is one segment, from
        // the outer cube's face to the other, its ends exact.
        let c = Cascades::from_densities(&vec![1.0f32; 2 * GRID * GRID * GRID]).unwrap();
        let mut segs = Vec::new();
        c.segments(Vec3::new(-2.0, 0.45, 0.55), Vec3::X, 0.0, 10.0, &mut segs);
        assert_eq!(segs, [[1.5, 3.5]]);
        // A ray starting inside cascade 0 leaves through cascade 1.
        segs.clear();
        c.segments(Vec3::new(0.6, 0.5, 0.5), -Vec3::X, 0.0, 10.0, &mut segs);
        assert_eq!(segs.len(), 1);
        assert_eq!(segs[0][0], 0.0);
        assert!((segs[0][1] - 1.1).abs() < 1e-6, "{segs:?}");
    }

    #[test]
    fn bits_set_and_read_across_word_boundaries() {
        let mut b = Bits::new(200);
        assert_eq!(b.0.len(), 4);
        for i in [0, 63, 64, 130, 199] {
            b.set(i);
        }
        let on: Vec<usize> = (0..200).filter(|&i| b.get(i)).collect();
        assert_eq!(on, [0, 63, 64, 130, 199]);
    }

    #[test]
    fn powers_of_two_are_exact() {
        for (e, v) in [
            (-5, 0.03125f32),
            (-1, 0.5),
            (0, 1.0),
            (1, 2.0),
            (4, 16.0),
            (200, f32::INFINITY),
        ] {
            assert_eq!(pow2(e), v);
        }
    }

    #[test]
    fn bad_lengths_are_refused() {
        assert!(Cascades::from_densities(&[]).is_none());
        assert!(Cascades::from_densities(&vec![0.0; GRID * GRID * GRID + 1]).is_none());
    }
}
