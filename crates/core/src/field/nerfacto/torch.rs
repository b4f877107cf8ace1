//! nerfstudio's pure-torch fallbacks of nerfacto's components (used when tiny-cuda-nn is not
//! installed at training time): they differ from tiny-cuda-nn's in ways that change every
//! output, so a checkpoint trained with them is evaluated with them.
//!
//! - **Hash grid** (`HashEncoding.pytorch_fwd`): level `l` has the scale
//!   `s_l = ⌊N_min · g^l⌋` (float32, `g = exp((ln N_max − ln N_min)/(L − 1))` rounded to
//!   float32 first), *every* level hashed into its own `2^log2T` rows of one table
//!   (`[L·2^log2T][F]`), no `+0.5` offset: `p = s_l·x`, trilinear between `⌊p⌋` and `⌈p⌉`
//!   with weight `p − ⌊p⌋` on the ceiling corner, index
//!   `(k.x·1 ⊕ k.y·2654435761 ⊕ k.z·805459861) mod 2^log2T + l·2^log2T` (torch multiplies in
//!   int64; modulo a power of two that equals tcnn's u32 wrap).
//! - **MLP** (`MLP.pytorch_fwd`): `nn.Linear` layers *with biases*, `y = W·x + b`, `W`
//!   `[out][in]`, ReLU between layers, none after the last (evaluated in batches by the
//!   shared MLP kernel, [`Mlp::with_biases`](crate::field::network::Mlp::with_biases)).
//! - **SH** (`components_from_spherical_harmonics`): fed `(d + 1)/2` *as is* (no mapping
//!   back to `[−1, 1]`), with all-positive signs: `0.2821; 0.4886y, 0.4886z, 0.4886x;
//!   1.0925xy, 1.0925yz, 0.9462z² − 0.3154, 1.0925xz, 0.5463(x² − y²); 0.5900y(3x² − y²),
//!   2.8906xyz, 0.4570y(5z² − 1), 0.3732z(5z² − 3), 0.4570x(5z² − 1), 1.4453z(x² − y²),
//!   0.5900x(x² − 3y²)`.

use glam::Vec3;

/// Which loop encodes a batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kernel {
    /// Point by point: the reference.
    Plain,
    /// Eight points at a time (two features per level).
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

/// The torch fallback's hash encoding.
#[derive(Clone, Debug)]
pub(crate) struct TorchHashGrid {
    scales: Vec<f32>,
    n_features: usize,
    table_size: u32,
    /// `[L·T][F]`, row-major.
    table: Vec<f32>,
}

impl TorchHashGrid {
    /// The finest level's scale (cells per unit of the unit cube).
    pub(crate) fn finest_scale(&self) -> f32 {
        self.scales.last().copied().unwrap_or(1.0)
    }

    /// A grid of `n_levels` levels of `n_features` features, `2^log2_table_size` rows each,
    /// resolutions from `min_res` to `max_res`; `None` when `table` has the wrong length.
    pub(crate) fn new(
        n_levels: u32,
        n_features: usize,
        log2_table_size: u32,
        min_res: u32,
        max_res: u32,
        table: Vec<f32>,
    ) -> Option<Self> {
        let table_size = 1u32.checked_shl(log2_table_size)?;
        if table.len() != n_levels as usize * table_size as usize * n_features {
            return None;
        }
        let growth = if n_levels > 1 {
            ((f64::from(max_res).ln() - f64::from(min_res).ln()) / f64::from(n_levels - 1)).exp()
        } else {
            1.0
        };
        let g = growth as f32;
        let scales = (0..n_levels)
            .map(|l| (min_res as f32 * f64::from(g).powi(l as i32) as f32).floor())
            .collect();
        Some(TorchHashGrid {
            scales,
            n_features,
            table_size,
            table,
        })
    }

    /// Output width `L·F`.
    pub(crate) fn n_outputs(&self) -> usize {
        self.scales.len() * self.n_features
    }

    /// Encodes the points `xs` (unit cube) into `out` (`L·F` values each, point after
    /// point). Level by level, so that one level's rows stay in cache across the batch.
    pub(crate) fn encode(&self, xs: &[Vec3], out: &mut [f32]) {
        self.encode_with(self.kernel(), xs, out);
    }

    /// The fastest encoder for this grid on this CPU: eight points at a time with AVX2
    /// for nerfstudio's two features per level.
    fn kernel(&self) -> Kernel {
        #[cfg(target_arch = "x86_64")]
        if self.n_features == 2 && is_x86_feature_detected!("avx2") {
            return Kernel::Avx2;
        }
        Kernel::Plain
    }

    fn encode_with(&self, kernel: Kernel, xs: &[Vec3], out: &mut [f32]) {
        match kernel {
            // Two features get a loop of their own width.
            Kernel::Plain if self.n_features == 2 => self.encode_features(2, xs, out),
            Kernel::Plain => self.encode_features(self.n_features, xs, out),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `kernel` chose AVX2 only where the CPU has it, for two features.
            Kernel::Avx2 => unsafe { self.encode_pairs_avx2(xs, out) },
        }
    }

    /// Whether [`Self::encode8_avx2`] applies: two features per level and a CPU with AVX2.
    #[cfg(target_arch = "x86_64")]
    pub(super) fn has_encode8_avx2(&self) -> bool {
        self.kernel() == Kernel::Avx2
    }

    /// The encoding of eight unit-cube points (`u`: their x, y and z lanes) feature-major:
    /// `out[2l + f]` is feature `f` of level `l`, lane `k` point `k`; the same operations in
    /// the same order as [`Self::encode_features`] (so the same bits). Only where
    /// [`Self::has_encode8_avx2`]; `out` holds `2L` vectors.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) fn encode8_avx2(
        &self,
        u: [std::arch::x86_64::__m256; 3],
        out: &mut [std::arch::x86_64::__m256],
    ) {
        use std::arch::x86_64::*;
        let rows = self.table_size as usize;
        let levels = self.scales.iter().zip(self.table.chunks_exact(rows * 2));
        for ((&s, table), features) in levels.zip(out.chunks_exact_mut(2)) {
            let cells = Cells8::new(u, s);
            let mut acc = [_mm256_setzero_ps(); 2];
            for corner in 0..8 {
                let (r, weight) = cells.corner(corner, self.table_size);
                // Points (0, 1, 4, 5) and (2, 3, 6, 7): the two shuffles that separate the
                // features then leave the points in order.
                // SAFETY: every row is below `rows`, and the level's table has `2·rows` values.
                let (first, second) = unsafe {
                    (
                        pairs4(table, [r[0], r[1], r[4], r[5]]),
                        pairs4(table, [r[2], r[3], r[6], r[7]]),
                    )
                };
                let pairs = [
                    _mm256_shuffle_ps::<0b10_00_10_00>(first, second),
                    _mm256_shuffle_ps::<0b11_01_11_01>(first, second),
                ];
                for (sum, v) in acc.iter_mut().zip(pairs) {
                    *sum = _mm256_add_ps(*sum, _mm256_mul_ps(weight, v));
                }
            }
            features.copy_from_slice(&acc);
        }
    }

    /// The number of levels `L`.
    #[cfg(target_arch = "x86_64")]
    pub(super) fn n_levels(&self) -> usize {
        self.scales.len()
    }

    /// Level `level` of eight unit-cube points (`u`: their x, y and z lanes), feature by
    /// feature (lane `k` point `k`), as [`Self::encode8_avx2`] gives that level (the same
    /// operations in the same order, so the same bits): each corner's eight rows of two
    /// features in one 64-bit AVX-512 gather, each point's weight twice beside them, the
    /// features separated once at the end. Only where [`Self::has_encode8_avx2`] and the
    /// CPU has AVX-512 F and VL; `level < L`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx2")]
    #[inline]
    pub(super) fn encode8_level_avx512(
        &self,
        u: [std::arch::x86_64::__m256; 3],
        level: usize,
    ) -> [std::arch::x86_64::__m256; 2] {
        use std::arch::x86_64::*;
        let rows = self.table_size as usize;
        let twice = _mm512_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7);
        let apart = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 1, 3, 5, 7, 9, 11, 13, 15);
        let table = &self.table[level * rows * 2..(level + 1) * rows * 2];
        let cells = Cells8::new(u, self.scales[level]);
        let mut acc = _mm512_setzero_ps();
        for corner in 0..8 {
            let (r, weight) = cells.corner_lanes(corner, self.table_size);
            // SAFETY: every row is below `rows`, and the level's table has `2·rows` values
            // (a row is one f64's bytes, `f32` rows need no more than 4-byte alignment for
            // a gather).
            let v = unsafe { _mm512_i32gather_pd::<8>(r, table.as_ptr().cast()) };
            let w = _mm512_permutexvar_ps(twice, _mm512_castps256_ps512(weight));
            acc = _mm512_add_ps(acc, _mm512_mul_ps(w, _mm512_castpd_ps(v)));
        }
        let f = _mm512_castps_pd(_mm512_permutexvar_ps(apart, acc));
        [
            _mm256_castpd_ps(_mm512_castpd512_pd256(f)),
            _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(f)),
        ]
    }

    /// [`Self::encode_features`] for two features, eight points per step with the same
    /// operations in the same order (so the same bits): the corners' hashes and weights as
    /// vectors, the rows fetched four at a time ([`pairs4`]). The last `len mod 8` points go through the plain loop.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn encode_pairs_avx2(&self, xs: &[Vec3], out: &mut [f32]) {
        use std::arch::x86_64::*;
        let width = self.scales.len() * 2;
        let rows = self.table_size as usize;
        let n8 = xs.len() / 8 * 8;
        // The coordinates axis-major, for vector loads.
        let mut axes = vec![0.0f32; 3 * n8];
        for (i, x) in xs[..n8].iter().enumerate() {
            for (a, v) in x.to_array().into_iter().enumerate() {
                axes[a * n8 + i] = v;
            }
        }
        let pairs = [
            _mm256_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3),
            _mm256_setr_epi32(4, 4, 5, 5, 6, 6, 7, 7),
        ];
        let levels = self.scales.iter().zip(self.table.chunks_exact(rows * 2));
        for (l, (&s, table)) in levels.enumerate() {
            for g in (0..n8).step_by(8) {
                // A loop, not `map`: the closure would be called, not inlined (`map` does
                // not have the target features), and it returned its vector through memory.
                let mut u = [_mm256_setzero_ps(); 3];
                for (a, v) in u.iter_mut().enumerate() {
                    // SAFETY: `axes` holds `n8` values per axis and `g + 8 ≤ n8`.
                    *v = unsafe { _mm256_loadu_ps(axes[a * n8 + g..].as_ptr()) };
                }
                let cells = Cells8::new(u, s);
                // Per half of the points, their two features interleaved as in `out`.
                let mut acc = [_mm256_setzero_ps(); 2];
                for corner in 0..8 {
                    let (r, weight) = cells.corner(corner, self.table_size);
                    for (half, (sum, r)) in acc.iter_mut().zip(r.chunks_exact(4)).enumerate() {
                        // Each point's weight twice, for its two features.
                        let twice = _mm256_permutevar8x32_ps(weight, pairs[half]);
                        // SAFETY: every row is below `rows`, and the level's table has
                        // `2·rows` values.
                        let v = unsafe { pairs4(table, [r[0], r[1], r[2], r[3]]) };
                        *sum = _mm256_add_ps(*sum, _mm256_mul_ps(twice, v));
                    }
                }
                for (half, v) in acc.into_iter().enumerate() {
                    let mut lanes = [0.0f32; 8];
                    // SAFETY: `lanes` has 8 values.
                    unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), v) };
                    let first = g + 4 * half;
                    for (o, pair) in out[first * width..(first + 4) * width]
                        .chunks_exact_mut(width)
                        .zip(lanes.chunks_exact(2))
                    {
                        o[2 * l..2 * l + 2].copy_from_slice(pair);
                    }
                }
            }
        }
        self.encode_features(2, &xs[n8..], &mut out[n8 * width..]);
    }

    /// [`Self::encode`] for `nf` features per level (a constant once inlined). Per point
    /// and level: `p = s_l·x`; per axis the lower corner `⌊p⌋` with weight `1 − w`, the
    /// upper `⌈p⌉` with `w = p − ⌊p⌋`; the 8 corners in the order of their bits (x, then y,
    /// then z), each weight `w_x·w_y·w_z` and each feature summed from zero in that order.
    #[inline(always)]
    fn encode_features(&self, nf: usize, xs: &[Vec3], out: &mut [f32]) {
        let width = self.scales.len() * nf;
        // Rows per level are a power of two: the hash's modulo is a mask.
        let rows = self.table_size as usize;
        let mask = self.table_size - 1;
        let levels = self.scales.iter().zip(self.table.chunks_exact(rows * nf));
        for (l, (&s, table)) in levels.enumerate() {
            for (x, dst) in xs.iter().zip(out.chunks_exact_mut(width)) {
                let dst = &mut dst[l * nf..(l + 1) * nf];
                let p = x.to_array().map(|v| v * s);
                // `p ≥ 0` in the unit cube: truncation is the floor, and the upper corner is
                // the ceiling (the same corner as the lower one where `p` is a whole
                // number), without libm's floor and ceil calls on CPUs the build does not
                // assume SSE4.1 of.
                let lo = p.map(|v| v as u32);
                let w = [0, 1, 2].map(|a| p[a] - lo[a] as f32);
                let hi = [0, 1, 2].map(|a| lo[a] + u32::from(w[a] > 0.0));
                let hx = [lo[0], hi[0]];
                let hy = [lo[1], hi[1]].map(|k| k.wrapping_mul(2_654_435_761));
                let hz = [lo[2], hi[2]].map(|k| k.wrapping_mul(805_459_861));
                let wx = [1.0 - w[0], w[0]];
                let wy = [1.0 - w[1], w[1]];
                let wz = [1.0 - w[2], w[2]];
                dst.fill(0.0);
                for corner in 0..8 {
                    let (a, b, c) = (corner & 1, corner >> 1 & 1, corner >> 2);
                    let weight = wx[a] * wy[b] * wz[c];
                    let row = ((hx[a] ^ hy[b] ^ hz[c]) & mask) as usize;
                    for (d, v) in dst.iter_mut().zip(&table[row * nf..row * nf + nf]) {
                        *d += weight * v;
                    }
                }
            }
        }
    }
}

/// Eight points' grid cells at one level, as the plain loop finds them
/// ([`TorchHashGrid::encode_features`]): per axis the lower and upper corner's index times
/// the hash's prime, and their trilinear weights `1 − frac` and `frac`; the x and y parts
/// of the four corners of a z-face combined once for both faces (the same operations in
/// the same order as per corner, so the same bits).
#[cfg(target_arch = "x86_64")]
struct Cells8 {
    /// Per corner of a face (bits: x, y upper) the xor of the x and y hashes and the product
    /// of the x and y weights.
    face_h: [std::arch::x86_64::__m256i; 4],
    face_w: [std::arch::x86_64::__m256; 4],
    /// The lower and upper z corner's hash and weight.
    h_z: [std::arch::x86_64::__m256i; 2],
    w_z: [std::arch::x86_64::__m256; 2],
}

#[cfg(target_arch = "x86_64")]
impl Cells8 {
    /// The cells of the unit-cube points `u` (their x, y and z lanes) at level scale `s`.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn new(u: [std::arch::x86_64::__m256; 3], s: f32) -> Self {
        use std::arch::x86_64::*;
        let (zero, one, scale) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0), _mm256_set1_ps(s));
        // The hash's primes as i32 bit patterns (the products wrap as the u32 ones do).
        let primes = [1u32, 2_654_435_761, 805_459_861].map(|p| _mm256_set1_epi32(p as i32));
        let mut h = [[_mm256_setzero_si256(); 2]; 3];
        let mut w = [[zero; 2]; 3];
        for a in 0..3 {
            let p = _mm256_mul_ps(u[a], scale);
            let lo = _mm256_cvttps_epi32(p);
            let frac = _mm256_sub_ps(p, _mm256_cvtepi32_ps(lo));
            // `hi = lo + (frac > 0)`: the comparison's mask is −1 where true.
            let up = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GT_OQ>(frac, zero));
            let hi = _mm256_sub_epi32(lo, up);
            h[a] = [lo, hi].map(|k| _mm256_mullo_epi32(k, primes[a]));
            w[a] = [_mm256_sub_ps(one, frac), frac];
        }
        let mut cells = Cells8 {
            face_h: [_mm256_setzero_si256(); 4],
            face_w: [zero; 4],
            h_z: h[2],
            w_z: w[2],
        };
        for corner in 0..4 {
            let (a, b) = (corner & 1, corner >> 1);
            cells.face_h[corner] = _mm256_xor_si256(h[0][a], h[1][b]);
            cells.face_w[corner] = _mm256_mul_ps(w[0][a], w[1][b]);
        }
        cells
    }

    /// Corner `corner` (bits: x, y, z upper) of the eight cells: each point's row in a
    /// table of `table_size` rows (a power of two) and its weight.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn corner(&self, corner: usize, table_size: u32) -> ([u32; 8], std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let (rows, weight) = self.corner_lanes(corner, table_size);
        let mut r = [0u32; 8];
        // SAFETY: `r` has 8 values.
        unsafe { _mm256_storeu_si256(r.as_mut_ptr().cast(), rows) };
        (r, weight)
    }

    /// [`Self::corner`] with the rows left in a vector (for a gather).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn corner_lanes(
        &self,
        corner: usize,
        table_size: u32,
    ) -> (std::arch::x86_64::__m256i, std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let (face, c) = (corner & 3, corner >> 2);
        let weight = _mm256_mul_ps(self.face_w[face], self.w_z[c]);
        let hash = _mm256_xor_si256(self.face_h[face], self.h_z[c]);
        let mask = _mm256_set1_epi32((table_size - 1) as i32);
        (_mm256_and_si256(hash, mask), weight)
    }
}

/// The two features of the rows `r` of a level's `table` (`[rows][2]`), row after row:
/// what a 64-bit AVX2 gather fetches, but from four plain loads, which run about a fifth
/// faster than the gather on the CPUs measured (AMD EPYC, the tables in the second-level
/// cache).
///
/// # Safety
/// The CPU has AVX2, and every row is below `table.len() / 2`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn pairs4(table: &[f32], r: [u32; 4]) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    debug_assert!(r.iter().all(|&r| 2 * r as usize + 1 < table.len()));
    let rows = table.as_ptr().cast::<i64>();
    // SAFETY: the caller keeps every row inside the table; `f32` rows need not be 8-aligned.
    let at = |i: usize| unsafe { rows.add(r[i] as usize).read_unaligned() };
    _mm256_castsi256_ps(_mm256_setr_epi64x(at(0), at(1), at(2), at(3)))
}

/// nerfstudio's torch SH components of degree 4 for the vector `v` as given (nerfacto
/// passes `(d + 1)/2`).
pub(crate) fn torch_sh4(v: Vec3) -> [f32; 16] {
    let (x, y, z) = (v.x, v.y, v.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    [
        0.282_094_8,
        0.488_602_52 * y,
        0.488_602_52 * z,
        0.488_602_52 * x,
        1.092_548_4 * x * y,
        1.092_548_4 * y * z,
        0.946_174_7 * zz - 0.315_391_57,
        1.092_548_4 * x * z,
        0.546_274_2 * (xx - yy),
        0.590_043_6 * y * (3.0 * xx - yy),
        2.890_611_4 * x * y * z,
        0.457_045_8 * y * (5.0 * zz - 1.0),
        0.373_176_33 * z * (5.0 * zz - 3.0),
        0.457_045_8 * x * (5.0 * zz - 1.0),
        1.445_305_7 * z * (xx - yy),
        0.590_043_6 * x * (xx - 3.0 * yy),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_scales_follow_the_floor_rule() {
        // 16 → 2048 over 16 levels: g = 128^(1/15) ≈ 1.3819; ⌊16·g^l⌋.
        let g = TorchHashGrid::new(16, 2, 4, 16, 2048, vec![0.0; 16 * 16 * 2]).unwrap();
        let want: Vec<f32> = (0..16)
            .map(|l| (16.0 * 128f64.powf(l as f64 / 15.0)).floor() as f32)
            .collect();
        for (l, (a, b)) in g.scales.iter().zip(&want).enumerate() {
            // The last level is 2048 up to float rounding of g^15 (either side of 2048).
            if l < 15 {
                assert_eq!(a, b, "level {l}");
            } else {
                assert!((2047.0..=2048.0).contains(a), "{a}");
            }
        }
        assert_eq!(g.scales[0], 16.0);
    }

    #[test]
    fn grid_points_return_their_hashed_row() {
        // One level, scale 4 (min = max = 4): x = k/4 lands on grid point k exactly.
        let rows = 1usize << 6;
        let table: Vec<f32> = (0..rows * 2).map(|i| i as f32).collect();
        let g = TorchHashGrid::new(1, 2, 6, 4, 4, table).unwrap();
        let k = [1u32, 3, 2];
        let mut out = [0.0; 2];
        g.encode(&[Vec3::new(0.25, 0.75, 0.5)], &mut out);
        let h = (1u64 ^ (3 * 2_654_435_761u64) ^ (2 * 805_459_861u64)) % 64;
        assert_eq!(k[0], 1);
        assert_eq!(out, [2.0 * h as f32, 2.0 * h as f32 + 1.0]);
    }

    #[test]
    fn batches_match_the_trilinear_formula() {
        // A slow f64 reference of the module's formula (torch's int64 hash, modulo the rows)
        // on seeded points, for the default 2 features and an odd 3, several levels.
        for nf in [2usize, 3] {
            let (levels, log2) = (4u32, 6u32);
            let rows = 1usize << log2;
            let table: Vec<f32> = (0..levels as usize * rows * nf)
                .map(|i| ((i * 7919 % 1000) as f32 / 500.0) - 1.0)
                .collect();
            let g = TorchHashGrid::new(levels, nf, log2, 3, 40, table.clone()).unwrap();
            let mut rng = crate::rng::Mmix::new(5);
            let mut next = || rng.unit();
            // Random points, and one on grid lines of every level (x = 0.5·k).
            let mut xs: Vec<Vec3> = (0..50).map(|_| Vec3::new(next(), next(), next())).collect();
            xs.push(Vec3::new(0.5, 0.0, 0.25));
            let mut out = vec![f32::NAN; xs.len() * g.n_outputs()];
            g.encode(&xs, &mut out);
            for (x, got) in xs.iter().zip(out.chunks_exact(g.n_outputs())) {
                for (l, &s) in g.scales.iter().enumerate() {
                    let p = x.to_array().map(|v| f64::from(v * s));
                    for f in 0..nf {
                        let mut want = 0.0f64;
                        for corner in 0..8 {
                            let (mut weight, mut k) = (1.0f64, [0u64; 3]);
                            for a in 0..3 {
                                let up = corner >> a & 1 == 1;
                                k[a] = if up { p[a].ceil() } else { p[a].floor() } as u64;
                                let w = p[a] - p[a].floor();
                                weight *= if up { w } else { 1.0 - w };
                            }
                            let h = (k[0] ^ (k[1] * 2_654_435_761) ^ (k[2] * 805_459_861))
                                % rows as u64;
                            let row = h as usize + l * rows;
                            want += weight * f64::from(table[row * nf + f]);
                        }
                        let ours = f64::from(got[l * nf + f]);
                        assert!(
                            (ours - want).abs() < 1e-5,
                            "{nf} {x} level {l}: {ours} {want}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn every_kernel_gives_the_plain_loop_bits() {
        // nerfstudio's proposal-network shape (5 levels × 2, 2^12 rows), batches that are
        // not multiples of 8, points on cell faces.
        let rows = 1usize << 12;
        let table: Vec<f32> = (0..5 * rows * 2)
            .map(|i| ((i * 7919 % 1999) as f32 / 999.0) - 1.0)
            .collect();
        let g = TorchHashGrid::new(5, 2, 12, 16, 256, table).unwrap();
        let mut rng = crate::rng::Mmix::new(9);
        let mut next = || rng.unit();
        for n in [0, 1, 8, 37] {
            let mut xs: Vec<Vec3> = (0..n).map(|_| Vec3::new(next(), next(), next())).collect();
            if n > 1 {
                xs[1] = Vec3::new(0.5, 0.25, 0.0);
            }
            let mut plain = vec![f32::NAN; n * g.n_outputs()];
            g.encode_with(Kernel::Plain, &xs, &mut plain);
            let mut fast = vec![f32::NAN; n * g.n_outputs()];
            g.encode_with(g.kernel(), &xs, &mut fast);
            assert_eq!(
                fast.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                plain.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                "{n} points"
            );
        }
    }

    #[test]
    fn sh_constant_and_linear_terms() {
        let v = Vec3::new(0.2, 0.5, 0.9);
        let s = torch_sh4(v);
        let c1 = 3f32.sqrt() / (2.0 * std::f32::consts::PI.sqrt());
        assert!((s[0] - 0.5 / std::f32::consts::PI.sqrt()).abs() < 1e-6);
        assert!((s[1] - c1 * 0.5).abs() < 1e-6 && (s[3] - c1 * 0.2).abs() < 1e-6);
        assert!((s[15] - 0.590_043_6 * 0.2 * (0.04 - 0.75)).abs() < 1e-6);
    }
}
