//! The torch layout's proposal density network fused with its hash encoding: eight points
//! at a time from field-space points to σ in vector registers, with nothing written between
//! the stages (apart, the encoding stores `2L` values per point, the MLP transposes them
//! back to feature-major blocks and pads its one output to a tile of four).
//!
//! Per point: nerfacto's contraction and map to the unit cube (`u = (c + 2)/4`, the
//! selector `0 < u < 1`), the grid's `L` levels × 2 features, the hidden layer
//! `h_o = max(0, b_o + Σᵢ W_oi·xᵢ)` and the output `raw = b + Σ_o v_o·h_o`, each sum a chain
//! of fused multiply-adds in input order from the bias (the shared MLP kernel's order, so
//! the same bits as the encoding and that kernel run apart), then
//! `σ = average_init_density · exp(raw)`.
//!
//! Two kernels, the same bits. With AVX2 and FMA, block by block: all levels of a block
//! ([`TorchHashGrid::encode8_avx2`]), then its network one neuron at a time. With AVX-512,
//! a batch of [`BATCH_BLOCKS`] blocks level by level, so that one level's table (32 KiB at
//! nerfstudio's default `2^12` rows) serves the whole batch before the next is touched, each
//! corner's rows fetched by one gather ([`TorchHashGrid::encode8_level_avx512`]); then each
//! block's network [`NEURON_GROUP`] hidden neurons at a time, their sums side by side in
//! registers (AVX-512 has 32 vector registers, AVX2 16), so that the multiply-adds of one
//! input are independent instead of one neuron's chain waiting on each other.
//!
//! Example: one level of one cell whose corners all hold `(1, 0)`, `W = [[1, 0]]`, `b = [0]`,
//! `v = [2]`, output bias `−1`: every point encodes to `(1, 0)`, `h = 1`, `raw = 1` and
//! `σ = average_init_density · e`.

use std::arch::x86_64::*;

use glam::Vec3;

use super::torch::TorchHashGrid;
use crate::field::network::exp_density;

/// The most inputs the kernel keeps in registers (16 levels × 2 features).
const MAX_INPUTS: usize = 32;
/// Blocks of eight points the AVX-512 kernel encodes level by level.
const BATCH_BLOCKS: usize = 8;
/// Hidden neurons whose sums the AVX-512 kernel keeps in registers at once.
const NEURON_GROUP: usize = 16;

/// Which loop evaluates a batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kernel {
    Avx2,
    Avx512,
}

/// A proposal network `L·2 → H → 1` (torch `nn.Linear` layers with biases, ReLU between).
#[derive(Clone, Debug)]
pub(super) struct FusedDensity {
    kernel: Kernel,
    n_inputs: usize,
    /// The hidden layer's weights `[H][n_inputs]` (torch's row-major layout) and biases.
    hidden: Vec<f32>,
    hidden_bias: Vec<f32>,
    /// The hidden weights per group of [`NEURON_GROUP`] neurons, input-major:
    /// `[⌈H/G⌉][n_inputs][G]` (zero past the last neuron).
    hidden_groups: Vec<[f32; NEURON_GROUP]>,
    /// The output layer's weights `[H]` and bias.
    output: Vec<f32>,
    output_bias: f32,
}

impl FusedDensity {
    /// The kernel for torch `layers` `(W, b)` over `grid`: `None` unless they are two layers
    /// `grid.n_outputs() → H → 1` over a grid of two features per level, on a CPU with AVX2
    /// and FMA.
    pub(super) fn new(grid: &TorchHashGrid, layers: &[(Vec<f32>, Vec<f32>)]) -> Option<Self> {
        let [(w0, b0), (w1, b1)] = layers else {
            return None;
        };
        let (n_inputs, width) = (grid.n_outputs(), b0.len());
        let fits = n_inputs <= MAX_INPUTS
            && width > 0
            && w0.len() == n_inputs * width
            && w1.len() == width
            && b1.len() == 1
            && grid.has_encode8_avx2()
            && is_x86_feature_detected!("fma");
        let kernel = if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl")
        {
            Kernel::Avx512
        } else {
            Kernel::Avx2
        };
        let mut hidden_groups = Vec::with_capacity(width.div_ceil(NEURON_GROUP) * n_inputs);
        for first in (0..width).step_by(NEURON_GROUP) {
            for i in 0..n_inputs {
                let mut column = [0.0; NEURON_GROUP];
                for (w, o) in column.iter_mut().zip(first..width) {
                    *w = w0[o * n_inputs + i];
                }
                hidden_groups.push(column);
            }
        }
        fits.then(|| FusedDensity {
            kernel,
            n_inputs,
            hidden: w0.clone(),
            hidden_bias: b0.clone(),
            hidden_groups,
            output: w1.clone(),
            output_bias: b1[0],
        })
    }

    /// `σ` at each field-space point of `points` into `sigma` (0 outside the selector).
    pub(super) fn density(
        &self,
        grid: &TorchHashGrid,
        average_init_density: f32,
        points: &[Vec3],
        sigma: &mut [f32],
    ) {
        self.density_with(self.kernel, grid, average_init_density, points, sigma);
    }

    fn density_with(
        &self,
        kernel: Kernel,
        grid: &TorchHashGrid,
        average_init_density: f32,
        points: &[Vec3],
        sigma: &mut [f32],
    ) {
        // SAFETY: `new` made the kernel only where the CPU has AVX2 and FMA and the grid
        // takes `encode8_avx2`, and chose AVX-512 only where the CPU has it.
        unsafe {
            match kernel {
                Kernel::Avx2 => self.density_avx2(grid, average_init_density, points, sigma),
                Kernel::Avx512 => self.density_avx512(grid, average_init_density, points, sigma),
            }
        }
    }

    #[target_feature(enable = "avx2,fma")]
    fn density_avx2(
        &self,
        grid: &TorchHashGrid,
        average_init_density: f32,
        points: &[Vec3],
        sigma: &mut [f32],
    ) {
        let zero = _mm256_setzero_ps();
        let mut x = [zero; MAX_INPUTS];
        let x = &mut x[..self.n_inputs];
        for (block, out) in points.chunks(8).zip(sigma.chunks_mut(8)) {
            let (u, selected) = unit_cube8(block);
            grid.encode8_avx2(u, x);
            let mut raw = _mm256_set1_ps(self.output_bias);
            let neurons = self.hidden.chunks_exact(self.n_inputs);
            for ((w, &b), &v) in neurons.zip(&self.hidden_bias).zip(&self.output) {
                let mut h = _mm256_set1_ps(b);
                for (&wi, &xi) in w.iter().zip(x.iter()) {
                    h = _mm256_fmadd_ps(_mm256_set1_ps(wi), xi, h);
                }
                raw = _mm256_fmadd_ps(_mm256_set1_ps(v), _mm256_max_ps(h, zero), raw);
            }
            store_sigma(raw, selected, average_init_density, out);
        }
    }

    #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
    fn density_avx512(
        &self,
        grid: &TorchHashGrid,
        average_init_density: f32,
        points: &[Vec3],
        sigma: &mut [f32],
    ) {
        let zero = _mm256_setzero_ps();
        let mut units = [([zero; 3], 0); BATCH_BLOCKS];
        let mut inputs = [[zero; MAX_INPUTS]; BATCH_BLOCKS];
        let batch = 8 * BATCH_BLOCKS;
        for (points, sigma) in points.chunks(batch).zip(sigma.chunks_mut(batch)) {
            let blocks = points.len().div_ceil(8);
            for (block, unit) in points.chunks(8).zip(units.iter_mut()) {
                *unit = unit_cube8(block);
            }
            for level in 0..grid.n_levels() {
                for ((u, _), x) in units[..blocks].iter().zip(inputs.iter_mut()) {
                    [x[2 * level], x[2 * level + 1]] = grid.encode8_level_avx512(*u, level);
                }
            }
            let blocks = units.iter().zip(&inputs).zip(sigma.chunks_mut(8));
            for ((&(_, selected), x), out) in blocks {
                let x = &x[..self.n_inputs];
                let mut raw = _mm256_set1_ps(self.output_bias);
                let groups = self.hidden_groups.chunks_exact(self.n_inputs).zip(
                    self.hidden_bias
                        .chunks(NEURON_GROUP)
                        .zip(self.output.chunks(NEURON_GROUP)),
                );
                for (w, (bias, v)) in groups {
                    let mut h = [zero; NEURON_GROUP];
                    for (h, &b) in h.iter_mut().zip(bias) {
                        *h = _mm256_set1_ps(b);
                    }
                    for (w, &xi) in w.iter().zip(x) {
                        for (h, &w) in h.iter_mut().zip(w) {
                            *h = _mm256_fmadd_ps(_mm256_set1_ps(w), xi, *h);
                        }
                    }
                    for (h, &v) in h.iter().zip(v) {
                        raw = _mm256_fmadd_ps(_mm256_set1_ps(v), _mm256_max_ps(*h, zero), raw);
                    }
                }
                store_sigma(raw, selected, average_init_density, out);
            }
        }
    }
}

/// The unit-cube points (x, y and z lanes) of up to eight field-space points (a short
/// block padded with the origin), and the mask of those inside nerfacto's selector (bit
/// `k`: point `k`). `contract`: `p` where `m = ‖p‖∞ < 1`, else `(p/m)·(2 − 1/m)`; then
/// `(c + 2)/4`.
#[target_feature(enable = "avx2")]
#[inline]
fn unit_cube8(block: &[Vec3]) -> ([__m256; 3], i32) {
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    let (two, four) = (_mm256_set1_ps(2.0), _mm256_set1_ps(4.0));
    let sign = _mm256_set1_ps(-0.0);
    // The block's coordinates axis-major.
    let mut axes = [[0.0f32; 8]; 3];
    for (k, p) in block.iter().enumerate() {
        for (axis, v) in axes.iter_mut().zip(p.to_array()) {
            axis[k] = v;
        }
    }
    let mut p = [zero; 3];
    for (v, axis) in p.iter_mut().zip(&axes) {
        // SAFETY: each axis has 8 values.
        *v = unsafe { _mm256_loadu_ps(axis.as_ptr()) };
    }
    let abs = p.map(|v| _mm256_andnot_ps(sign, v));
    let m = _mm256_max_ps(abs[0], _mm256_max_ps(abs[1], abs[2]));
    let inside = _mm256_cmp_ps::<_CMP_LT_OQ>(m, one);
    let shrink = _mm256_sub_ps(two, _mm256_div_ps(one, m));
    let mut u = [zero; 3];
    let mut selected = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
    for (u, &v) in u.iter_mut().zip(&p) {
        let far = _mm256_mul_ps(_mm256_div_ps(v, m), shrink);
        *u = _mm256_div_ps(_mm256_add_ps(_mm256_blendv_ps(far, v, inside), two), four);
        let within = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(*u, zero),
            _mm256_cmp_ps::<_CMP_LT_OQ>(*u, one),
        );
        selected = _mm256_and_ps(selected, within);
    }
    (u, _mm256_movemask_ps(selected))
}

/// `σ = average_init_density · exp(raw)` of the block's points into `out` (up to eight),
/// 0 where bit `k` of `selected` is clear.
#[target_feature(enable = "avx2")]
#[inline]
fn store_sigma(raw: __m256, selected: i32, average_init_density: f32, out: &mut [f32]) {
    let mut lanes = [0.0f32; 8];
    // SAFETY: `lanes` has 8 values.
    unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), raw) };
    for (k, (s, &raw)) in out.iter_mut().zip(&lanes).enumerate() {
        *s = if selected >> k & 1 == 1 {
            average_init_density * exp_density(raw)
        } else {
            0.0
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_kernels_give_the_same_bits() {
        // A grid of 5 levels × 2, 2^10 rows, a hidden layer of 20 (a full group of 16 and
        // a partial one); batches that are not whole blocks or whole batches of blocks.
        let mut rng = crate::rng::Mmix::new(13);
        let mut next = move || rng.unit() - 0.5;
        let table: Vec<f32> = (0..5 << 11).map(|_| next()).collect();
        let Some(grid) = TorchHashGrid::new(5, 2, 10, 16, 256, table) else {
            panic!("the table fits the grid");
        };
        let layers: Vec<(Vec<f32>, Vec<f32>)> = [(10, 20), (20, 1)]
            .into_iter()
            .map(|(n_in, n_out)| {
                let w = (0..n_in * n_out).map(|_| next()).collect();
                (w, (0..n_out).map(|_| next()).collect())
            })
            .collect();
        let Some(fused) = FusedDensity::new(&grid, &layers) else {
            eprintln!("no AVX2 and FMA: the fused kernel does not run here");
            return;
        };
        if fused.kernel != Kernel::Avx512 {
            eprintln!("no AVX-512: only the AVX2 kernel runs here");
            return;
        }
        for n in [1, 8, 61, 64, 200] {
            let points: Vec<Vec3> = (0..n)
                .map(|_| Vec3::new(next(), next(), next()) * 6.0)
                .collect();
            let mut sigma = [vec![f32::NAN; n], vec![f32::NAN; n]];
            for (kernel, sigma) in [Kernel::Avx2, Kernel::Avx512].into_iter().zip(&mut sigma) {
                fused.density_with(kernel, &grid, 0.7, &points, sigma);
            }
            let bits = sigma
                .each_ref()
                .map(|s| s.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
            assert_eq!(bits[0], bits[1], "{n} points");
            assert!(sigma[0].iter().any(|&s| s > 0.0), "{n} points: all empty");
        }
    }
}
