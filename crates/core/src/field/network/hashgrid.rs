//! tiny-cuda-nn's multi-resolution hash encoding of a point of the unit cube, on the CPU.
//!
//! `L` levels of `F` features each. Level `l` has the (float32) scale
//! `s_l = 2^(l·log2 b)·N_min − 1` and `r_l = ⌈s_l⌉ + 1` grid points per axis; its table holds
//! `T_l = min(next_multiple_of_8(r_l³), 2^log2T)` entries of `F` contiguous features. A point
//! `x ∈ [0, 1]³` is looked up at `p = s_l·x + 0.5`, cell `c = ⌊p⌋`, fraction `w = p − c`; each
//! of the cell's 8 corners `k` has the index `k.x + k.y·r_l + k.z·r_l²` when `r_l³ ≤ T_l`
//! (a dense level) and otherwise the coherent-prime hash
//! `k.x·1 ⊕ k.y·2654435761 ⊕ k.z·805459861` (u32 arithmetic, wrapping), both taken `% T_l`.
//! The level's output is the trilinear blend of the 8 corners' features, and the encoding is
//! the levels' outputs one after the other: feature `f` of level `l` at `l·F + f`.
//!
//! Worked example: `N_min = 16`, `b = 2`: level 0 has `s = 15`, `r = 16`, `r³ = 4096`; with
//! `log2T = 12` it is dense (`T = 4096`), level 1 (`s = 31`, `r = 32`) is hashed into 4096.
//!
//! The tables are the memory-bound part of a field (a 2^19-entry table of 8×4 levels is
//! ~23 MB as f16), so they may stay in f16 ([`TableStorage::F16`]) or be widened once
//! ([`TableStorage::F32`]); the arithmetic is f32 either way.

use glam::Vec3;
use half::f16;

/// How a hash grid keeps its tables in memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TableStorage {
    /// Half precision, as trained (half the memory traffic; widened per lookup).
    F16,
    /// Single precision (widened once at load).
    F32,
}

/// The shape of a hash encoding.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HashGridConfig {
    /// Number of levels `L`.
    pub(crate) n_levels: u32,
    /// Features per level `F` (1, 2, 4 or 8).
    pub(crate) n_features: u32,
    /// `log2` of the largest table size.
    pub(crate) log2_table_size: u32,
    /// Resolution of the coarsest level `N_min`.
    pub(crate) base_resolution: u32,
    /// Growth factor between levels `b`.
    pub(crate) per_level_scale: f32,
}

/// One level's geometry.
#[derive(Clone, Copy, Debug)]
struct Level {
    scale: f32,
    resolution: u32,
    entries: u32,
    dense: bool,
    /// First entry of the level in the table.
    offset: usize,
}

/// The tables, in one of the two storages.
#[derive(Clone, Debug)]
enum Tables {
    F16(Vec<f16>),
    F32(Vec<f32>),
}

/// A multi-resolution hash encoding with its trained tables.
#[derive(Clone, Debug)]
pub(crate) struct HashGrid {
    config: HashGridConfig,
    levels: Vec<Level>,
    tables: Tables,
}

#[cfg(target_arch = "x86_64")]
use simd::Load as FeatureLoad;

/// What the vector blend needs of a table type (nothing off x86-64).
#[cfg(not(target_arch = "x86_64"))]
trait FeatureLoad {}
#[cfg(not(target_arch = "x86_64"))]
impl FeatureLoad for f16 {}
#[cfg(not(target_arch = "x86_64"))]
impl FeatureLoad for f32 {}

/// A table value that can be widened to f32.
trait Feature: Copy + Default + FeatureLoad {
    /// The `N ≤ 8` values of one entry, widened (exactly).
    fn widen<const N: usize>(e: &[Self; N]) -> [f32; N];

    /// `out[f] = Σ_k w_k·e_k[f]` over the 8 corners of lane `p` of a block (entry
    /// `ix[k·BLOCK + p]` of `table`, `N` values, weight `w[k·BLOCK + p]`), left to right from
    /// zero, each product rounded then added: the same bits whichever way it runs. `AVX`:
    /// with one vector of features per corner, loaded and (f16) widened by the F16C
    /// instructions straight from the table (only instantiated from code compiled for, and
    /// run on, CPUs with AVX2 and F16C).
    #[inline(always)]
    fn blend<const N: usize, const AVX: bool>(
        table: &[Self],
        ix: &[u32],
        w: &[f32],
        p: usize,
        out: &mut [f32],
    ) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only under `HashGrid::encode_avx2`, which runs where the
            // CPU has AVX2 and F16C.
            return unsafe { simd::blend::<Self, N>(table, ix, w, p, out) };
        }
        let mut acc = [0.0f32; N];
        for k in 0..8 {
            let i = ix[k * BLOCK + p] as usize;
            let e: &[Self; N] = table[i * N..][..N].try_into().expect("a slice of N values");
            for (a, f) in acc.iter_mut().zip(Self::widen::<N>(e)) {
                *a += w[k * BLOCK + p] * f;
            }
        }
        out[..N].copy_from_slice(&acc);
    }

    /// [`Self::blend`] for each lane of a block: lane `p`'s features go to
    /// `rows[p·width + at..][..N]`, for the `rows.len() / width` lanes given. `AVX`: through
    /// `simd::Load::blend_block_avx` (f16 pairs eight lanes at once), with the same bits.
    #[inline(always)]
    fn blend_block<const N: usize, const AVX: bool>(
        table: &[Self],
        ix: &[u32],
        w: &[f32],
        rows: &mut [f32],
        width: usize,
        at: usize,
    ) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only under `HashGrid::encode_avx2`, which runs where the
            // CPU has AVX2 and F16C.
            return unsafe { Self::blend_block_avx::<N>(table, ix, w, rows, width, at) };
        }
        for (p, row) in rows.chunks_exact_mut(width).enumerate() {
            Self::blend::<N, AVX>(table, ix, w, p, &mut row[at..at + N]);
        }
    }
}

impl Feature for f16 {
    #[inline(always)]
    fn widen<const N: usize>(e: &[Self; N]) -> [f32; N] {
        e.map(f16::to_f32)
    }
}

impl Feature for f32 {
    #[inline(always)]
    fn widen<const N: usize>(e: &[Self; N]) -> [f32; N] {
        *e
    }
}

/// `f(x)` rounded once to f32: what a correctly rounded f32 `log2f`/`exp2f` gives. The GPU's
/// functions are within an ulp or two of it; computing through f64 makes the result
/// independent of this machine's f32 libm (an ulp matters: the fine levels' scales are near
/// integers for many configurations, and `⌈s⌉` or the cell fraction would follow the ulp).
pub(crate) fn correctly_rounded(f: fn(f64) -> f64, x: f32) -> f32 {
    f(f64::from(x)) as f32
}

/// The primes of tcnn's coherent hash, per axis.
const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

impl HashGridConfig {
    /// The levels' geometry (float32 arithmetic, as tcnn does it).
    fn levels(&self) -> Vec<Level> {
        let log2_b = correctly_rounded(f64::log2, self.per_level_scale);
        let max_entries = 1u64 << self.log2_table_size.min(31);
        let mut offset = 0usize;
        (0..self.n_levels)
            .map(|l| {
                let e = correctly_rounded(f64::exp2, l as f32 * log2_b);
                let scale = e * self.base_resolution as f32 - 1.0;
                let resolution = scale.ceil() as u32 + 1;
                let dense_entries = u64::from(resolution).pow(3).next_multiple_of(8);
                let entries = dense_entries.min(max_entries) as u32;
                let level = Level {
                    scale,
                    resolution,
                    entries,
                    dense: u64::from(resolution).pow(3) <= u64::from(entries),
                    offset,
                };
                offset += entries as usize;
                level
            })
            .collect()
    }

    /// The finest level's scale `s_{L−1}` (cells per unit of the unit cube: a point maps
    /// to `s·x + 0.5`), so its cells are `1/s` wide.
    pub(crate) fn finest_scale(&self) -> f32 {
        self.levels().last().map_or(1.0, |l| l.scale)
    }

    /// Table entries over all levels (`Σ T_l`); the parameter count is this times `F`.
    pub(crate) fn n_entries(&self) -> usize {
        self.levels().iter().map(|l| l.entries as usize).sum()
    }

    /// Number of parameters (`Σ T_l · F`).
    pub(crate) fn n_params(&self) -> usize {
        self.n_entries() * self.n_features as usize
    }

    /// Whether the encoder handles this shape (the feature counts tiny-cuda-nn allows).
    fn supported(&self) -> bool {
        [1, 2, 4, 8].contains(&self.n_features)
    }

    /// Output width `L·F`.
    pub(crate) fn n_outputs(&self) -> usize {
        (self.n_levels * self.n_features) as usize
    }
}

impl HashGrid {
    /// A grid of `config` with the parameters `params` (`config.n_params()` values, level
    /// after level, entry after entry, feature after feature), stored as `storage`. `None`
    /// when the count does not match or the feature count is not 1, 2, 4 or 8.
    pub fn new(config: HashGridConfig, params: &[f16], storage: TableStorage) -> Option<Self> {
        let levels = config.levels();
        if params.len() != config.n_params() || !config.supported() {
            return None;
        }
        let tables = match storage {
            TableStorage::F16 => Tables::F16(table_of(params.iter().copied())),
            TableStorage::F32 => Tables::F32(table_of(params.iter().map(|v| v.to_f32()))),
        };
        Some(HashGrid {
            config,
            levels,
            tables,
        })
    }

    /// A grid with f32 parameters (kept in f32); `None` as for [`Self::new`].
    pub(crate) fn from_f32(config: HashGridConfig, params: Vec<f32>) -> Option<Self> {
        let levels = config.levels();
        (params.len() == config.n_params() && config.supported()).then(|| HashGrid {
            config,
            levels,
            tables: Tables::F32(table_of(params.into_iter())),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &HashGridConfig {
        &self.config
    }

    /// The storage of the tables.
    pub(crate) fn storage(&self) -> TableStorage {
        match self.tables {
            Tables::F16(_) => TableStorage::F16,
            Tables::F32(_) => TableStorage::F32,
        }
    }

    /// Encodes each point `xs[i]` (unit cube) into `out[i·L·F .. (i+1)·L·F]`.
    /// Level by level, so one level's table stays in cache across the batch.
    pub(crate) fn encode(&self, xs: &[Vec3], out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if simd::available() {
            // SAFETY: the CPU has AVX2 and F16C (checked just above).
            return unsafe { self.encode_avx2(xs, out) };
        }
        self.encode_by_shape::<false>(xs, out);
    }

    /// [`Self::encode`] compiled for AVX2 and F16C: the same arithmetic in the same order
    /// (Rust never fuses a multiply and an add by itself), with inline `floor`, vector
    /// index arithmetic and F16C widening.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,f16c")]
    fn encode_avx2(&self, xs: &[Vec3], out: &mut [f32]) {
        self.encode_by_shape::<true>(xs, out);
    }

    /// Picks the table type and the feature count once for the batch.
    #[inline(always)]
    fn encode_by_shape<const AVX: bool>(&self, xs: &[Vec3], out: &mut [f32]) {
        match (&self.tables, self.config.n_features) {
            (Tables::F16(t), 1) => self.encode_with::<f16, 1, AVX>(t, xs, out),
            (Tables::F16(t), 2) => self.encode_with::<f16, 2, AVX>(t, xs, out),
            (Tables::F16(t), 4) => self.encode_with::<f16, 4, AVX>(t, xs, out),
            (Tables::F16(t), _) => self.encode_with::<f16, 8, AVX>(t, xs, out),
            (Tables::F32(t), 1) => self.encode_with::<f32, 1, AVX>(t, xs, out),
            (Tables::F32(t), 2) => self.encode_with::<f32, 2, AVX>(t, xs, out),
            (Tables::F32(t), 4) => self.encode_with::<f32, 4, AVX>(t, xs, out),
            (Tables::F32(t), _) => self.encode_with::<f32, 8, AVX>(t, xs, out),
        }
    }

    /// Level by level over the whole batch, in blocks of [`BLOCK`] points: a block's 8
    /// corners' indices and weights (eight points at once, in vectors, where the CPU has
    /// AVX2), each entry prefetched as soon as its index is known (x86-64) so the cache
    /// misses overlap, [`AHEAD`] blocks before that block's blend of the 8 entries, corner
    /// after corner (the same sums as one point at a time: `f = Σ_k w_k·e_k` left to right,
    /// each product rounded). Prefetching a whole level of the batch first (4096 lines for
    /// 512 points) overflowed the 32 KiB first-level cache before the blend came to them.
    #[inline(always)]
    fn encode_with<T: Feature, const NF: usize, const AVX: bool>(
        &self,
        table: &[T],
        xs: &[Vec3],
        out: &mut [f32],
    ) {
        let width = self.config.n_outputs();
        debug_assert_eq!(out.len(), xs.len() * width);
        let n = xs.len();
        let blocks = n.div_ceil(BLOCK);
        // The coordinates axis by axis, padded to whole blocks with points that are located
        // but never blended.
        let mut axes = vec![0.0f32; 3 * blocks * BLOCK];
        let (ax, ayz) = axes.split_at_mut(blocks * BLOCK);
        let (ay, az) = ayz.split_at_mut(blocks * BLOCK);
        for (i, x) in xs.iter().enumerate() {
            (ax[i], ay[i], az[i]) = (x.x, x.y, x.z);
        }
        // Per block, corner-major: corner `k` of lane `p` at `k·BLOCK + p`.
        let mut index = vec![0u32; blocks * CORNERS];
        let mut weight = vec![0.0f32; blocks * CORNERS];
        for (l, level) in self.levels.iter().enumerate() {
            let t = &table[level.offset * NF..(level.offset + level.entries as usize) * NF];
            // Block `b`'s corners (and prefetches) are laid `AHEAD` blocks before its blend.
            for b in 0..blocks + AHEAD {
                if b < blocks {
                    let lanes = b * BLOCK..(b + 1) * BLOCK;
                    let coords = [&ax[lanes.clone()], &ay[lanes.clone()], &az[lanes]];
                    let ix = &mut index[b * CORNERS..(b + 1) * CORNERS];
                    let wx = &mut weight[b * CORNERS..(b + 1) * CORNERS];
                    level.block_corners::<AVX>(coords, ix, wx);
                    let m = n.min((b + 1) * BLOCK) - b * BLOCK;
                    for corner in ix.chunks_exact(BLOCK) {
                        prefetch(t, NF, &corner[..m]);
                    }
                }
                if b >= AHEAD {
                    let a = b - AHEAD;
                    let r = a * BLOCK..(n.min((a + 1) * BLOCK));
                    let ix = &index[a * CORNERS..(a + 1) * CORNERS];
                    let wx = &weight[a * CORNERS..(a + 1) * CORNERS];
                    let rows = &mut out[r.start * width..r.end * width];
                    T::blend_block::<NF, AVX>(t, ix, wx, rows, width, l * NF);
                }
            }
        }
    }
}

/// Points whose corners are located (and their entries prefetched) together: one vector.
const BLOCK: usize = 8;
/// Corners of a block.
const CORNERS: usize = 8 * BLOCK;
/// How many blocks ahead of the blend the corners are located: far enough for the entries
/// to arrive, near enough for them to still be in the first-level cache.
const AHEAD: usize = 4;

/// The values of `values` in a vector whose memory the kernel is asked, before it is first
/// touched, to back with 2 MiB pages where it can (Linux transparent huge pages in `madvise`
/// mode): the lookups are random over tens of megabytes, and with 4 KiB pages nearly every
/// one would also miss the TLB (a page walk, two-dimensional under a hypervisor).
fn table_of<T: Copy>(values: impl ExactSizeIterator<Item = T>) -> Vec<T> {
    let mut v = Vec::with_capacity(values.len());
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let bytes = v.capacity() * std::mem::size_of::<T>();
        if bytes >= HUGE {
            extern "C" {
                fn madvise(addr: *mut std::ffi::c_void, len: usize, advice: i32) -> i32;
            }
            /// `MADV_HUGEPAGE` of Linux's `<sys/mman.h>`.
            const MADV_HUGEPAGE: i32 = 14;
            let start = v.as_mut_ptr() as usize;
            let (lo, hi) = (start.next_multiple_of(4096), (start + bytes) / 4096 * 4096);
            if hi > lo {
                // SAFETY: advice on pages of this vector's own (unused) allocation; it
                // changes no contents and an error (an old kernel) only means no advice.
                unsafe { madvise(lo as *mut std::ffi::c_void, hi - lo, MADV_HUGEPAGE) };
            }
        }
    }
    v.extend(values);
    v
}

/// Asks the CPU to start loading the table entries `index` (each `nf` values) into cache.
#[inline]
fn prefetch<T>(table: &[T], nf: usize, index: &[u32]) {
    #[cfg(target_arch = "x86_64")]
    for &i in index {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // No bounds check (two instructions of a prefetch's six): the address is only a
        // hint, and the indices are the table's anyway.
        let p = table.as_ptr().wrapping_add(i as usize * nf);
        // SAFETY: a prefetch is a hint that never faults, whatever the address.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (table, nf, index);
}

impl Level {
    /// The cell and fractions of `x` on this level: `p = s·x + 0.5`, `c = ⌊p⌋` (as tcnn: the
    /// integer is reinterpreted as u32, so a slightly negative input wraps and is hashed).
    #[inline]
    fn locate(&self, x: Vec3) -> ([u32; 3], [f32; 3]) {
        let p = x.to_array().map(|v| self.scale * v + 0.5);
        let c = p.map(f32::floor);
        (
            [0, 1, 2].map(|a| c[a] as i32 as u32),
            [0, 1, 2].map(|a| p[a] - c[a]),
        )
    }

    /// The table entry of index `i` (before the modulo): `i % T`, as a mask when `T` is a
    /// power of two (every hashed level), and without a division when `i < T` already (a
    /// dense level inside the unit cube).
    #[inline(always)]
    fn entry(&self, i: u32) -> u32 {
        if self.entries.is_power_of_two() {
            i & (self.entries - 1)
        } else if i < self.entries {
            i
        } else {
            i % self.entries
        }
    }

    /// The axis multipliers of the index terms: the grid's strides (dense) or the hash's
    /// primes.
    #[inline(always)]
    fn multipliers<const DENSE: bool>(&self) -> [u32; 3] {
        let r = self.resolution;
        if DENSE {
            [1, r, r.wrapping_mul(r)]
        } else {
            PRIMES
        }
    }

    /// The table entries (`index`) and trilinear weights (`weight`) of the 8 corners of each
    /// of a block's points (`coords`: x, y and z of its [`BLOCK`] lanes), corner-major (corner
    /// `k` of lane `p` at `k·BLOCK + p`). `AVX`: all lanes at once in vectors, with the same
    /// arithmetic in the same order (only from code compiled for, and run on, CPUs with
    /// AVX2).
    #[inline(always)]
    fn block_corners<const AVX: bool>(
        &self,
        coords: [&[f32]; 3],
        index: &mut [u32],
        weight: &mut [f32],
    ) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only under `HashGrid::encode_avx2`, which runs where the
            // CPU has AVX2 and F16C.
            unsafe {
                if self.dense {
                    simd::corners::<true>(self, coords, index, weight)
                } else {
                    simd::corners::<false>(self, coords, index, weight)
                }
            }
            return;
        }
        let lanes = coords[0].iter().zip(coords[1]).zip(coords[2]);
        for (p, ((&x, &y), &z)) in lanes.take(BLOCK).enumerate() {
            let x = Vec3::new(x, y, z);
            if self.dense {
                self.corners::<true>(x, p, index, weight);
            } else {
                self.corners::<false>(x, p, index, weight);
            }
        }
    }

    /// [`Self::block_corners`] for lane `p` alone (`DENSE`: this level is dense); corner `k`
    /// adds bit `a` of `k` along axis `a`, its weight is the product over the axes of `w` or
    /// `1 − w` (in axis order). The index is a sum (dense: `k.x + k.y·r + k.z·r²`) or an
    /// exclusive or (hashed) of one term per axis, each term computed once for both of the
    /// axis's grid coordinates.
    #[inline(always)]
    fn corners<const DENSE: bool>(&self, x: Vec3, p: usize, index: &mut [u32], weight: &mut [f32]) {
        let (c, w) = self.locate(x);
        let mul = self.multipliers::<DENSE>();
        let term: [[u32; 2]; 3] = [0, 1, 2].map(|a| {
            let t = c[a].wrapping_mul(mul[a]);
            [t, t.wrapping_add(mul[a])]
        });
        let wa: [[f32; 2]; 3] = [0, 1, 2].map(|a| [1.0 - w[a], w[a]]);
        for corner in 0..8 {
            let b = [corner & 1, corner >> 1 & 1, corner >> 2 & 1];
            let i = if DENSE {
                term[0][b[0]]
                    .wrapping_add(term[1][b[1]])
                    .wrapping_add(term[2][b[2]])
            } else {
                term[0][b[0]] ^ term[1][b[1]] ^ term[2][b[2]]
            };
            index[corner * BLOCK + p] = self.entry(i);
            weight[corner * BLOCK + p] = wa[0][b[0]] * wa[1][b[1]] * wa[2][b[2]];
        }
    }
}

/// The x86-64 kernels' pieces.
#[cfg(target_arch = "x86_64")]
mod simd {
    use super::{Level, BLOCK};
    use half::f16;
    use std::arch::x86_64::*;

    /// Whether this CPU runs [`super::HashGrid::encode_avx2`].
    pub(super) fn available() -> bool {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("f16c")
    }

    /// A table type whose entries the vector blend loads.
    pub(super) trait Load: Copy {
        /// The `N ≤ 8` values at `p` as f32 lanes `0..N` of a vector (lanes past `N`
        /// unspecified, never read back); f16 widened exactly by F16C.
        ///
        /// # Safety
        /// `p` must point at `N` readable values; the CPU must have AVX2 and F16C.
        unsafe fn load<const N: usize>(p: *const Self) -> __m256;

        /// [`super::Feature::blend_block`]'s vector kernel: [`blend`] lane after lane.
        ///
        /// # Safety
        /// The CPU must have AVX2 and F16C.
        #[inline(always)]
        unsafe fn blend_block_avx<const N: usize>(
            table: &[Self],
            ix: &[u32],
            w: &[f32],
            rows: &mut [f32],
            width: usize,
            at: usize,
        ) {
            // SAFETY: the caller's.
            unsafe { blend_lanes::<Self, N>(table, ix, w, rows, width, at) }
        }
    }

    /// [`blend`] for each lane of a block (lane `p` to `rows[p·width + at..][..N]`).
    ///
    /// # Safety
    /// The CPU must have AVX2 and F16C.
    #[inline]
    #[target_feature(enable = "avx2,f16c")]
    unsafe fn blend_lanes<T: Load, const N: usize>(
        table: &[T],
        ix: &[u32],
        w: &[f32],
        rows: &mut [f32],
        width: usize,
        at: usize,
    ) {
        for (p, row) in rows.chunks_exact_mut(width).enumerate() {
            // SAFETY: the caller's.
            unsafe { blend::<T, N>(table, ix, w, p, &mut row[at..at + N]) };
        }
    }

    /// [`blend`] of two-feature f16 entries for the 8 lanes of a block at once: per corner
    /// one 32-bit gather of the 8 lanes' entries, widened by F16C four lanes (8 values) at a
    /// time, each value weighted by its lane's weight and added in corner order (a multiply
    /// then an add, never fused): lane by lane the arithmetic of [`blend`].
    ///
    /// # Safety
    /// The CPU must have AVX2 and F16C.
    #[inline]
    #[target_feature(enable = "avx2,f16c")]
    unsafe fn blend_f16_pairs(
        table: &[f16],
        ix: &[u32],
        w: &[f32],
        rows: &mut [f32],
        width: usize,
        at: usize,
    ) {
        let entries = table.len() / 2;
        if entries == 0 {
            return;
        }
        // Indices are reduced to the table already; the clamp makes every gather's read
        // provably inside it, and changes nothing.
        let last = _mm256_set1_epi32((entries - 1).min(i32::MAX as usize) as i32);
        let base = table.as_ptr().cast::<i32>();
        // Lane `p`'s weight beside each of its two features: lanes 0–3, then 4–7.
        let (spread_lo, spread_hi) = (
            _mm256_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3),
            _mm256_setr_epi32(4, 4, 5, 5, 6, 6, 7, 7),
        );
        let (mut lo, mut hi) = (_mm256_setzero_ps(), _mm256_setzero_ps());
        for k in 0..8 {
            let (i, wk) = (&ix[k * BLOCK..][..BLOCK], &w[k * BLOCK..][..BLOCK]);
            // SAFETY: `i` and `wk` hold a vector's 8 values; every gathered index is at most
            // `entries − 1`, so each 4-byte read lies inside `table`.
            let (e, wv) = unsafe {
                let i = _mm256_min_epu32(_mm256_loadu_si256(i.as_ptr().cast()), last);
                (
                    _mm256_i32gather_epi32::<4>(base, i),
                    _mm256_loadu_ps(wk.as_ptr()),
                )
            };
            let (f_lo, f_hi) = (
                _mm256_cvtph_ps(_mm256_castsi256_si128(e)),
                _mm256_cvtph_ps(_mm256_extracti128_si256::<1>(e)),
            );
            let (w_lo, w_hi) = (
                _mm256_permutevar8x32_ps(wv, spread_lo),
                _mm256_permutevar8x32_ps(wv, spread_hi),
            );
            lo = _mm256_add_ps(lo, _mm256_mul_ps(w_lo, f_lo));
            hi = _mm256_add_ps(hi, _mm256_mul_ps(w_hi, f_hi));
        }
        let mut pairs = [0.0f32; 2 * BLOCK];
        // SAFETY: `pairs` holds 16 values.
        unsafe {
            _mm256_storeu_ps(pairs.as_mut_ptr(), lo);
            _mm256_storeu_ps(pairs[BLOCK..].as_mut_ptr(), hi);
        }
        for (row, pair) in rows.chunks_exact_mut(width).zip(pairs.chunks_exact(2)) {
            row[at..at + 2].copy_from_slice(pair);
        }
    }

    impl Load for f16 {
        #[inline(always)]
        unsafe fn load<const N: usize>(p: *const Self) -> __m256 {
            // SAFETY: the caller's; each load reads exactly `N` values (2·N bytes).
            unsafe {
                let bits = match N {
                    1 => _mm_cvtsi32_si128(i32::from(p.cast::<u16>().read_unaligned())),
                    2 => _mm_cvtsi32_si128(p.cast::<i32>().read_unaligned()),
                    4 => _mm_loadl_epi64(p.cast()),
                    _ => _mm_loadu_si128(p.cast()),
                };
                _mm256_cvtph_ps(bits)
            }
        }

        #[inline(always)]
        unsafe fn blend_block_avx<const N: usize>(
            table: &[Self],
            ix: &[u32],
            w: &[f32],
            rows: &mut [f32],
            width: usize,
            at: usize,
        ) {
            // SAFETY: the caller's.
            unsafe {
                if N == 2 {
                    blend_f16_pairs(table, ix, w, rows, width, at)
                } else {
                    blend_lanes::<Self, N>(table, ix, w, rows, width, at)
                }
            }
        }
    }

    impl Load for f32 {
        #[inline(always)]
        unsafe fn load<const N: usize>(p: *const Self) -> __m256 {
            // SAFETY: the caller's; each load reads exactly `N` values (4·N bytes).
            unsafe {
                match N {
                    1 => _mm256_castps128_ps256(_mm_load_ss(p)),
                    2 => _mm256_castps128_ps256(_mm_castsi128_ps(_mm_loadl_epi64(p.cast()))),
                    4 => _mm256_castps128_ps256(_mm_loadu_ps(p)),
                    _ => _mm256_loadu_ps(p),
                }
            }
        }
    }

    /// [`super::Feature::blend`] with one vector per corner: lane `f` gets
    /// `acc + w_k·e_k[f]` (a multiply then an add, never fused), corner after corner, so
    /// every lane rounds exactly as the scalar sum does.
    ///
    /// # Safety
    /// The CPU must have AVX2 and F16C.
    #[inline]
    #[target_feature(enable = "avx2,f16c")]
    pub(super) unsafe fn blend<T: Load, const N: usize>(
        table: &[T],
        ix: &[u32],
        w: &[f32],
        p: usize,
        out: &mut [f32],
    ) {
        let mut acc = _mm256_setzero_ps();
        for k in 0..8 {
            let e = &table[ix[k * BLOCK + p] as usize * N..][..N];
            // SAFETY: `e` holds `N` values.
            let v = unsafe { T::load::<N>(e.as_ptr()) };
            acc = _mm256_add_ps(acc, _mm256_mul_ps(_mm256_set1_ps(w[k * BLOCK + p]), v));
        }
        let out = &mut out[..N];
        // SAFETY: each store writes exactly `N` floats of `out`.
        unsafe {
            match N {
                1 => _mm_store_ss(out.as_mut_ptr(), _mm256_castps256_ps128(acc)),
                2 => _mm_storel_epi64(
                    out.as_mut_ptr().cast(),
                    _mm_castps_si128(_mm256_castps256_ps128(acc)),
                ),
                4 => _mm_storeu_ps(out.as_mut_ptr(), _mm256_castps256_ps128(acc)),
                _ => _mm256_storeu_ps(out.as_mut_ptr(), acc),
            }
        }
    }

    /// [`Level::block_corners`] in vectors of the block's 8 lanes: `p = s·x + 0.5`, its
    /// floor and fraction, the index terms and the weights, each operation the scalar code's
    /// (products rounded, never fused; the cell converted by truncation, which is the
    /// scalar conversion wherever `|p| < 2³¹`, i.e. for every point of the unit cube).
    /// Entries of a level that is not a power of two in size are reduced lane by lane where
    /// the index reaches past the table (outside the unit cube only).
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn corners<const DENSE: bool>(
        level: &Level,
        coords: [&[f32]; 3],
        index: &mut [u32],
        weight: &mut [f32],
    ) {
        let mul = level.multipliers::<DENSE>();
        let (scale, half, one) = (
            _mm256_set1_ps(level.scale),
            _mm256_set1_ps(0.5),
            _mm256_set1_ps(1.0),
        );
        let mut term = [[_mm256_setzero_si256(); 2]; 3];
        let mut wa = [[_mm256_setzero_ps(); 2]; 3];
        for a in 0..3 {
            let x = &coords[a][..BLOCK];
            // SAFETY: `x` holds a vector's 8 values.
            let x = unsafe { _mm256_loadu_ps(x.as_ptr()) };
            let p = _mm256_add_ps(_mm256_mul_ps(scale, x), half);
            let c = _mm256_floor_ps(p);
            let m = _mm256_set1_epi32(mul[a] as i32);
            let t = _mm256_mullo_epi32(_mm256_cvttps_epi32(c), m);
            term[a] = [t, _mm256_add_epi32(t, m)];
            let w = _mm256_sub_ps(p, c);
            wa[a] = [_mm256_sub_ps(one, w), w];
        }
        let pow2 = level.entries.is_power_of_two();
        let mask = _mm256_set1_epi32(level.entries.wrapping_sub(1) as i32);
        for k in 0..8 {
            let b = [k & 1, k >> 1 & 1, k >> 2 & 1];
            let i = if DENSE {
                _mm256_add_epi32(
                    _mm256_add_epi32(term[0][b[0]], term[1][b[1]]),
                    term[2][b[2]],
                )
            } else {
                _mm256_xor_si256(
                    _mm256_xor_si256(term[0][b[0]], term[1][b[1]]),
                    term[2][b[2]],
                )
            };
            let w = _mm256_mul_ps(_mm256_mul_ps(wa[0][b[0]], wa[1][b[1]]), wa[2][b[2]]);
            let (ix, wx) = (
                &mut index[k * BLOCK..][..BLOCK],
                &mut weight[k * BLOCK..][..BLOCK],
            );
            // SAFETY: `ix` and `wx` hold a vector's 8 values each.
            unsafe {
                if pow2 {
                    _mm256_storeu_si256(ix.as_mut_ptr().cast(), _mm256_and_si256(i, mask));
                } else {
                    _mm256_storeu_si256(ix.as_mut_ptr().cast(), i);
                    // Lanes past the table (unsigned `i > T − 1`) wrap; none inside the cube.
                    let inside = _mm256_cmpeq_epi32(_mm256_max_epu32(i, mask), mask);
                    if _mm256_movemask_epi8(inside) != -1 {
                        for v in ix.iter_mut() {
                            *v = level.entry(*v);
                        }
                    }
                }
                _mm256_storeu_ps(wx.as_mut_ptr(), w);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(n_levels: u32, nf: u32, log2t: u32, b: f32) -> HashGridConfig {
        HashGridConfig {
            n_levels,
            n_features: nf,
            log2_table_size: log2t,
            base_resolution: 16,
            per_level_scale: b,
        }
    }

    /// A seeded table of values exactly representable in f16.
    fn params(n: usize, seed: u64) -> Vec<f16> {
        let mut rng = crate::rng::Mmix::new(seed);
        (0..n)
            .map(|_| f16::from_f32(rng.unit() * 2.0 - 1.0))
            .collect()
    }

    #[test]
    fn level_sizes_follow_tcnn() {
        // b = 2: scales 15, 31, 63 → resolutions 16, 32, 64; 2^12 entries at most.
        let c = config(3, 2, 12, 2.0);
        let l = c.levels();
        assert_eq!(
            l.iter().map(|l| l.resolution).collect::<Vec<_>>(),
            [16, 32, 64]
        );
        assert_eq!(l.iter().map(|l| l.entries).collect::<Vec<_>>(), [4096; 3]);
        assert_eq!(
            l.iter().map(|l| l.dense).collect::<Vec<_>>(),
            [true, false, false]
        );
        assert_eq!(c.n_params(), 3 * 4096 * 2);
        // Resolution 5 (scale 3.x): 125 rounded up to 128 entries, dense.
        let c = HashGridConfig {
            base_resolution: 4,
            ..config(1, 1, 19, 2.0)
        };
        let l = c.levels();
        assert_eq!((l[0].resolution, l[0].entries, l[0].dense), (4, 64, true));
        let c = HashGridConfig {
            base_resolution: 5,
            ..config(1, 1, 19, 2.0)
        };
        assert_eq!(c.levels()[0].entries, 128);
    }

    /// The encoding written out again for one point and one level, straight from the
    /// formulas in the module docs.
    fn reference(c: &HashGridConfig, p: &[f16], x: Vec3) -> Vec<f32> {
        let nf = c.n_features as usize;
        let mut out = Vec::new();
        let mut offset = 0usize;
        for l in 0..c.n_levels {
            let log2_b = (c.per_level_scale as f64).log2() as f32;
            let s = ((l as f32 * log2_b) as f64).exp2() as f32 * c.base_resolution as f32 - 1.0;
            let r = s.ceil() as u64 + 1;
            let t = ((r * r * r).div_ceil(8) * 8).min(1 << c.log2_table_size);
            let pos = [x.x, x.y, x.z].map(|v| s * v + 0.5);
            let mut feat = vec![0.0f32; nf];
            for dz in 0..2u64 {
                for dy in 0..2u64 {
                    for dx in 0..2u64 {
                        let k = [dx, dy, dz].map(|d| d);
                        let g: Vec<u64> = (0..3).map(|a| pos[a].floor() as u64 + k[a]).collect();
                        let w: f32 = (0..3)
                            .map(|a| {
                                let f = pos[a] - pos[a].floor();
                                if k[a] == 1 {
                                    f
                                } else {
                                    1.0 - f
                                }
                            })
                            .product();
                        let idx = if r * r * r <= t {
                            g[0] + g[1] * r + g[2] * r * r
                        } else {
                            ((g[0] as u32)
                                ^ (g[1] as u32).wrapping_mul(2_654_435_761)
                                ^ (g[2] as u32).wrapping_mul(805_459_861))
                                as u64
                        } % t;
                        for (f, v) in feat.iter_mut().enumerate() {
                            *v += w * p[offset * nf + idx as usize * nf + f].to_f32();
                        }
                    }
                }
            }
            out.extend(feat);
            offset += t as usize;
        }
        out
    }

    #[test]
    fn encoding_matches_the_formulas_in_both_storages() {
        for (nf, levels, b) in [(2, 5, 1.7), (4, 4, 2.3), (1, 3, 1.5), (8, 2, 3.0)] {
            let c = config(levels, nf, 11, b);
            let p = params(c.n_params(), 7 + nf as u64);
            let pts: Vec<Vec3> = (0..50)
                .map(|i| {
                    let t = i as f32 * 0.618_034;
                    Vec3::new(t.fract(), (t * 1.3).fract(), (t * 2.7 + 0.1).fract())
                })
                .collect();
            for storage in [TableStorage::F16, TableStorage::F32] {
                let g = HashGrid::new(c, &p, storage).unwrap();
                let w = c.n_outputs();
                let mut out = vec![0.0; pts.len() * w];
                g.encode(&pts, &mut out);
                for (i, x) in pts.iter().enumerate() {
                    let r = reference(&c, &p, *x);
                    for (a, b) in out[i * w..(i + 1) * w].iter().zip(&r) {
                        assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{a} vs {b}");
                    }
                }
            }
        }
    }

    /// The vector kernels give the scalar code's bits, inside the unit cube and out of it
    /// (where indices wrap), on dense levels whose size is not a power of two and on hashed
    /// ones, for batches that do not fill their last block.
    #[test]
    fn vector_and_scalar_encodings_agree_bit_for_bit() {
        for (nf, levels, log2t, base) in [(4, 6, 12, 5), (2, 8, 14, 16), (1, 3, 19, 7)] {
            let c = HashGridConfig {
                base_resolution: base,
                ..config(levels, nf, log2t, 1.6)
            };
            let p = params(c.n_params(), 11);
            let pts: Vec<Vec3> = (0..61)
                .map(|i| {
                    let t = i as f32 * 0.618_034;
                    Vec3::new(
                        t.fract() * 1.4 - 0.2,
                        (t * 1.3).fract(),
                        (t * 2.7).fract() - 0.5,
                    )
                })
                .collect();
            for storage in [TableStorage::F16, TableStorage::F32] {
                let g = HashGrid::new(c, &p, storage).unwrap();
                let w = c.n_outputs();
                let (mut fast, mut plain) = (vec![0.0; pts.len() * w], vec![0.0; pts.len() * w]);
                g.encode(&pts, &mut fast);
                g.encode_by_shape::<false>(&pts, &mut plain);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&fast),
                    bits(&plain),
                    "{nf}x{levels}, 2^{log2t}, {storage:?}"
                );
            }
        }
    }

    #[test]
    fn grid_points_return_their_entry() {
        // At x = (k − 0.5)/s the lookup lands exactly on grid point k: a dense level returns
        // entry k.x + k.y·r + k.z·r².
        let c = config(1, 2, 19, 2.0);
        let p = params(c.n_params(), 3);
        let g = HashGrid::new(c, &p, TableStorage::F32).unwrap();
        let (s, r) = (15.0f32, 16usize);
        let k = [3usize, 7, 11];
        let x = Vec3::new(
            (k[0] as f32 - 0.5) / s,
            (k[1] as f32 - 0.5) / s,
            (k[2] as f32 - 0.5) / s,
        );
        let mut out = [0.0; 2];
        g.encode(&[x], &mut out);
        let e = k[0] + k[1] * r + k[2] * r * r;
        assert!((out[0] - p[2 * e].to_f32()).abs() < 1e-5);
        assert!((out[1] - p[2 * e + 1].to_f32()).abs() < 1e-5);
    }

    #[test]
    fn wrong_parameter_count_is_refused() {
        let c = config(2, 2, 10, 2.0);
        assert!(HashGrid::new(c, &params(c.n_params() - 1, 1), TableStorage::F16).is_none());
        assert!(HashGrid::from_f32(c, vec![0.0; c.n_params() + 2]).is_none());
        let c3 = config(2, 3, 10, 2.0);
        assert!(HashGrid::from_f32(c3, vec![0.0; c3.n_params()]).is_none());
    }
}
