//! The torch layout's proposal density network fused with its hash encoding: eight points
//! at a time from field-space points to σ in AVX2/FMA registers, with nothing written
//! between the stages (apart, the encoding stores `2L` values per point, the MLP transposes
//! them back to feature-major blocks and pads its one output to a tile of four).
//!
//! Per point: nerfacto's contraction and map to the unit cube (`u = (c + 2)/4`, the
//! selector `0 < u < 1`), the grid's `L` levels × 2 features
//! ([`TorchHashGrid::encode8_avx2`]), the hidden layer `h_o = max(0, b_o + Σᵢ W_oi·xᵢ)` and
//! the output `raw = b + Σ_o v_o·h_o`, each sum a chain of fused multiply-adds in input
//! order from the bias (the shared MLP kernel's order, so the same bits as the encoding and
//! that kernel run apart), then `σ = average_init_density · exp(raw)`.
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

/// A proposal network `L·2 → H → 1` (torch `nn.Linear` layers with biases, ReLU between).
#[derive(Clone, Debug)]
pub(super) struct FusedDensity {
    n_inputs: usize,
    /// The hidden layer's weights `[H][n_inputs]` (torch's row-major layout) and biases.
    hidden: Vec<f32>,
    hidden_bias: Vec<f32>,
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
        fits.then(|| FusedDensity {
            n_inputs,
            hidden: w0.clone(),
            hidden_bias: b0.clone(),
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
        // SAFETY: `new` made the kernel only where the CPU has AVX2 and FMA and the grid
        // takes `encode8_avx2`.
        unsafe { self.density_avx2(grid, average_init_density, points, sigma) }
    }

    #[target_feature(enable = "avx2,fma")]
    fn density_avx2(
        &self,
        grid: &TorchHashGrid,
        average_init_density: f32,
        points: &[Vec3],
        sigma: &mut [f32],
    ) {
        let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
        let (two, four) = (_mm256_set1_ps(2.0), _mm256_set1_ps(4.0));
        let sign = _mm256_set1_ps(-0.0);
        let mut x = [zero; MAX_INPUTS];
        let x = &mut x[..self.n_inputs];
        for (block, out) in points.chunks(8).zip(sigma.chunks_mut(8)) {
            // The block's coordinates axis-major (a short last block padded with the origin).
            let mut axes = [[0.0f32; 8]; 3];
            for (k, p) in block.iter().enumerate() {
                for (axis, v) in axes.iter_mut().zip(p.to_array()) {
                    axis[k] = v;
                }
            }
            // SAFETY: each axis has 8 values.
            let p = axes.map(|a| unsafe { _mm256_loadu_ps(a.as_ptr()) });
            // `contract`: `p` where `m = ‖p‖∞ < 1`, else `(p/m)·(2 − 1/m)`; then `(c + 2)/4`.
            let abs = p.map(|v| _mm256_andnot_ps(sign, v));
            let m = _mm256_max_ps(abs[0], _mm256_max_ps(abs[1], abs[2]));
            let inside = _mm256_cmp_ps::<_CMP_LT_OQ>(m, one);
            let shrink = _mm256_sub_ps(two, _mm256_div_ps(one, m));
            let u = p.map(|v| {
                let far = _mm256_mul_ps(_mm256_div_ps(v, m), shrink);
                _mm256_div_ps(_mm256_add_ps(_mm256_blendv_ps(far, v, inside), two), four)
            });
            let selected = u
                .iter()
                .fold(_mm256_castsi256_ps(_mm256_set1_epi32(-1)), |s, &v| {
                    let within = _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_GT_OQ>(v, zero),
                        _mm256_cmp_ps::<_CMP_LT_OQ>(v, one),
                    );
                    _mm256_and_ps(s, within)
                });
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
            let mut lanes = [0.0f32; 8];
            // SAFETY: `lanes` has 8 values.
            unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), raw) };
            let selected = _mm256_movemask_ps(selected);
            for (k, (s, &raw)) in out.iter_mut().zip(&lanes).enumerate() {
                *s = if selected >> k & 1 == 1 {
                    average_init_density * exp_density(raw)
                } else {
                    0.0
                };
            }
        }
    }
}
