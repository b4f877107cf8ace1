//! tiny-cuda-nn's bias-free MLPs (FullyFusedMLP / CutlassMLP), and torch's `nn.Linear`
//! stacks with biases (nerfstudio's fallback layout), evaluated in f32 on batches.
//!
//! tiny-cuda-nn: layers `y = W·x` without biases, ReLU between them and none after the last. The flat
//! parameters hold the layers one after the other, each row-major `[out][in]`; the first
//! layer's input is padded to a multiple of 16 and the last layer's output to a multiple of
//! 16 (FullyFusedMLP) or 8 (CutlassMLP before September 2022). Padding inputs are zero;
//! padding outputs are dropped.
//!
//! Example: 32 → 64 → 16 with one hidden layer has `64·32 + 16·64 = 3072` parameters.
//!
//! torch ([`Mlp::with_biases`]): layers `y = W·x + b` (`W` `[out][in]`, no padding), ReLU
//! between them and none after the last; one layer alone is a linear map.
//!
//! **Kernel.** The weights are widened to f32 once and stored transposed (`[in][out]`, each
//! row padded with zeros to a multiple of [`PAD`]). The batch is cut into blocks of `B`
//! samples whose activations are kept feature-major (`act[i][b]`), so a layer is, per tile
//! of `T` outputs, `acc[o][·] += W[i][o]·act[i][·]` over the inputs `i`: one broadcast weight
//! times a vector of `B` samples, `T·B` accumulators held in registers, starting from the
//! bias (zero without one). The sum over `i` runs in input order, so the plain kernel gives
//! the same bits as `y[o] = b[o] + Σᵢ x[i]·W[o][i]` summed left to right. The fast kernel (AVX2 with FMA, chosen once per call at run time;
//! 16 samples × 4 outputs per tile) fuses each multiply-add, so it differs from the plain
//! one by f32 rounding only.

use glam::Vec3;

/// The shape of an MLP.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct MlpConfig {
    /// Inputs used (the layer reads `n_inputs` rounded up to 16, the rest zero).
    pub(crate) n_inputs: usize,
    /// Neurons per hidden layer.
    pub width: usize,
    /// Hidden layers (≥ 1).
    pub(crate) n_hidden_layers: usize,
    /// Outputs used.
    pub(crate) n_outputs: usize,
    /// The last layer's output is padded to a multiple of this (16, or 8 for old CutlassMLP).
    pub(crate) output_alignment: usize,
}

impl MlpConfig {
    /// `(in, out)` of each layer, padded as stored.
    fn layers(&self) -> Vec<(usize, usize)> {
        let mut v = vec![(self.n_inputs.next_multiple_of(16), self.width)];
        v.extend((1..self.n_hidden_layers).map(|_| (self.width, self.width)));
        v.push((
            self.width,
            self.n_outputs
                .next_multiple_of(self.output_alignment.max(1)),
        ));
        v
    }

    /// Number of parameters (padded, as stored).
    pub(crate) fn n_params(&self) -> usize {
        self.layers().iter().map(|(i, o)| i * o).sum()
    }
}

/// Weight rows are padded with zeros to a multiple of this (every kernel's tile divides it).
const PAD: usize = 16;

/// One layer: `n_in` inputs, `n_out` outputs kept, weights `[n_in][stride]`, biases
/// `[stride]` (zeros for tiny-cuda-nn's layers and the padding).
#[derive(Clone, Debug)]
struct Layer {
    n_in: usize,
    n_out: usize,
    stride: usize,
    w: Vec<f32>,
    bias: Vec<f32>,
}

impl Layer {
    /// From `w` row-major `[n_out][row]` (the first `n_in` of each row used) and the biases.
    fn new(n_in: usize, n_out: usize, row: usize, w: &[f32], b: Option<&[f32]>) -> Self {
        let stride = n_out.next_multiple_of(PAD);
        let mut t = vec![0.0f32; n_in * stride];
        for o in 0..n_out {
            for i in 0..n_in {
                t[i * stride + o] = w[o * row + i];
            }
        }
        let mut bias = vec![0.0f32; stride];
        if let Some(b) = b {
            bias[..n_out].copy_from_slice(&b[..n_out]);
        }
        Layer {
            n_in,
            n_out,
            stride,
            w: t,
            bias,
        }
    }
}

/// An MLP with f32 weights.
#[derive(Clone, Debug)]
pub(crate) struct Mlp {
    config: MlpConfig,
    /// The first layer reads the `n_inputs` used inputs only (the padding is zero); the last
    /// keeps the used outputs only.
    layers: Vec<Layer>,
}

/// Which kernel evaluates a batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kernel {
    /// Separate multiply and add, in input order: the reference.
    Plain,
    /// AVX2 + FMA, 16 samples per block (two vectors), 4 outputs per tile.
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Kernel {
    /// The fastest kernel this CPU runs.
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                return Kernel::Avx2;
            }
        }
        Kernel::Plain
    }
}

impl Mlp {
    /// An MLP of `config` from its flat parameters (`config.n_params()` values, each layer
    /// row-major `[out][in]`); `None` when the count does not match.
    pub fn new(config: MlpConfig, params: &[f32]) -> Option<Self> {
        if params.len() != config.n_params() || config.n_hidden_layers == 0 {
            return None;
        }
        let shapes = config.layers();
        let last = shapes.len() - 1;
        let mut at = 0;
        let layers = shapes
            .iter()
            .enumerate()
            .map(|(k, &(n_in, n_out))| {
                let w = &params[at..at + n_in * n_out];
                at += n_in * n_out;
                // Read the used inputs of the first layer and keep the used outputs of the
                // last only.
                let used_in = if k == 0 { config.n_inputs } else { n_in };
                let kept = if k == last { config.n_outputs } else { n_out };
                Layer::new(used_in, kept, n_in, w, None)
            })
            .collect();
        Some(Mlp { config, layers })
    }

    /// A torch MLP from `(W, b)` per layer, `W` row-major `[out][in]`, the first reading
    /// `n_inputs`; `None` when there is no layer or the shapes do not chain. Its
    /// configuration gives the inputs, the first layer's width, the layers after the first
    /// as hidden ones (0 for one linear layer) and the outputs, unpadded.
    pub(crate) fn with_biases(n_inputs: usize, layers: &[(Vec<f32>, Vec<f32>)]) -> Option<Self> {
        let mut n_in = n_inputs;
        let mut out = Vec::with_capacity(layers.len());
        for (w, b) in layers {
            let n_out = b.len();
            if n_out == 0 || w.len() != n_in * n_out {
                return None;
            }
            out.push(Layer::new(n_in, n_out, n_in, w, Some(b)));
            n_in = n_out;
        }
        let config = MlpConfig {
            n_inputs,
            width: out.first()?.n_out,
            n_hidden_layers: out.len() - 1,
            n_outputs: n_in,
            output_alignment: 1,
        };
        Some(Mlp {
            config,
            layers: out,
        })
    }

    /// The MLP with its last `values.len()` inputs fixed at `values`: their products with
    /// the first layer's weights are summed (in f64) into its biases once, so that a batch
    /// carries only the inputs that vary. `None` when there are fewer inputs than values.
    pub(crate) fn with_last_inputs(&self, values: &[f32]) -> Option<Mlp> {
        let mut m = self.clone();
        let first = m.layers.first_mut()?;
        let keep = first.n_in.checked_sub(values.len())?;
        for o in 0..first.n_out {
            let fixed: f64 = values
                .iter()
                .enumerate()
                .map(|(k, &v)| f64::from(first.w[(keep + k) * first.stride + o]) * f64::from(v))
                .sum();
            first.bias[o] = (f64::from(first.bias[o]) + fixed) as f32;
        }
        first.w.truncate(keep * first.stride);
        first.n_in = keep;
        m.config.n_inputs = keep;
        Some(m)
    }

    /// The MLP without its last `n` inputs, and those inputs' columns of the first layer
    /// ([`LastInputs`]): where the last inputs are shared by runs of samples (a ray's view
    /// direction), [`LastInputs::starts`] sums their part once per run and
    /// [`Self::forward_from`] starts each sample's first layer from it. `None` when there
    /// are fewer inputs than `n`. The first layer's biases go with the split-off columns
    /// (each row starts from them), so the MLP returned is for `forward_from` only.
    pub(crate) fn split_last_inputs(&self, n: usize) -> Option<(Mlp, LastInputs)> {
        let mut m = self.clone();
        let first = m.layers.first_mut()?;
        let keep = first.n_in.checked_sub(n)?;
        let last = LastInputs {
            n_out: first.n_out,
            stride: first.stride,
            w: first.w.split_off(keep * first.stride),
            bias: std::mem::replace(&mut first.bias, vec![0.0; first.stride]),
        };
        first.n_in = keep;
        m.config.n_inputs = keep;
        Some((m, last))
    }

    /// The configuration.
    pub fn config(&self) -> &MlpConfig {
        &self.config
    }

    /// Evaluates the MLP on `n` inputs, `inputs[k·n_inputs ..][.. n_inputs]`, writing
    /// `outputs[k·n_outputs ..][.. n_outputs]`.
    pub(crate) fn forward(&self, inputs: &[f32], outputs: &mut [f32]) {
        self.forward_with(Kernel::detect(), inputs, None, outputs);
    }

    /// [`Self::forward`] of an MLP from [`Self::split_last_inputs`]: sample `k`'s first
    /// layer starts from row `row_of[k]` of `starts` (rows of [`LastInputs::stride`] values,
    /// from [`LastInputs::starts`]) instead of its biases.
    pub(crate) fn forward_from(
        &self,
        inputs: &[f32],
        starts: &[f32],
        row_of: &[u32],
        out: &mut [f32],
    ) {
        let starts = Starts {
            rows: starts,
            row_of,
        };
        self.forward_with(Kernel::detect(), inputs, Some(starts), out);
    }

    fn forward_with(
        &self,
        kernel: Kernel,
        inputs: &[f32],
        starts: Option<Starts>,
        outputs: &mut [f32],
    ) {
        match kernel {
            Kernel::Plain => self.forward_blocks::<false, 8, 8>(inputs, starts, outputs),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Kernel::detect` chose these only where the CPU has the features.
            Kernel::Avx2 => unsafe { self.forward_avx2(inputs, starts, outputs) },
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn forward_avx2(&self, inputs: &[f32], starts: Option<Starts>, outputs: &mut [f32]) {
        self.forward_blocks::<true, 16, 4>(inputs, starts, outputs);
    }

    /// The batch in blocks of `B` samples (the last one zero-filled), each block's
    /// activations feature-major; `FMA` fuses the multiply-adds, `T` outputs per tile.
    /// With `starts`, the first layer's accumulators start from each sample's row.
    #[inline(always)]
    fn forward_blocks<const FMA: bool, const B: usize, const T: usize>(
        &self,
        inputs: &[f32],
        starts: Option<Starts>,
        outputs: &mut [f32],
    ) {
        let (ni, no) = (self.config.n_inputs, self.config.n_outputs);
        let n = inputs.len() / ni.max(1);
        debug_assert_eq!(outputs.len(), n * no);
        let widest = self.layers.iter().map(|l| l.stride).max().unwrap_or(0);
        let first_stride = self.layers.first().map_or(0, |l| l.stride);
        let mut x = vec![0.0f32; ni * B];
        let (mut a, mut b) = (vec![0.0f32; widest * B], vec![0.0f32; widest * B]);
        // The block's starting rows, sample-major then feature-major.
        let (mut rows, mut init) = match starts {
            Some(_) => (
                vec![0.0f32; first_stride * B],
                vec![0.0f32; first_stride * B],
            ),
            None => (Vec::new(), Vec::new()),
        };
        for (start, ys) in (0..n).step_by(B).zip(outputs.chunks_mut(B * no)) {
            let m = (n - start).min(B);
            // Transpose the block's inputs to feature-major.
            transpose::<FMA, B>(&inputs[start * ni..(start + m) * ni], ni, &mut x, B, m, ni);
            for i in 0..ni {
                x[i * B + m..(i + 1) * B].fill(0.0);
            }
            if let Some(s) = starts {
                s.block::<FMA, B>(
                    &s.row_of[start..start + m],
                    first_stride,
                    &mut rows,
                    &mut init,
                );
            }
            let first_init = starts.map(|_| &init[..]);
            // ReLU after every layer but the last.
            let n_layers = self.layers.len();
            for (k, l) in self.layers.iter().enumerate() {
                let relu = k + 1 < n_layers;
                if k == 0 {
                    layer::<FMA, B, T>(l, &x, first_init, &mut a, relu);
                } else {
                    layer::<FMA, B, T>(l, &a, None, &mut b, relu);
                    std::mem::swap(&mut a, &mut b);
                }
            }
            transpose::<FMA, B>(&a, B, ys, no, no, m);
        }
    }
}

/// The first layer's columns of an MLP's last inputs, split off by
/// [`Mlp::split_last_inputs`], with its biases.
#[derive(Clone, Debug)]
pub(crate) struct LastInputs {
    n_out: usize,
    stride: usize,
    /// `[input][stride]`, as in [`Layer`].
    w: Vec<f32>,
    bias: Vec<f32>,
}

impl LastInputs {
    /// Values per row of [`Self::starts`] (the first layer's outputs, padded): what the
    /// tests check the rows' length by.
    #[cfg(test)]
    pub(crate) fn stride(&self) -> usize {
        self.stride
    }

    /// Appends to `rows` one row of [`Self::stride`] values: `bias[o] + Σᵢ W[i][o]·v[i]`
    /// over these inputs `v = values`, summed in input order (each product rounded, then
    /// added); the padding is zero. `values` beyond the inputs split off are ignored.
    pub(crate) fn starts(&self, values: &[f32], rows: &mut Vec<f32>) {
        let at = rows.len();
        rows.extend_from_slice(&self.bias);
        let row = &mut rows[at..];
        for (w, &v) in self.w.chunks_exact(self.stride).zip(values) {
            for (r, &wo) in row[..self.n_out].iter_mut().zip(w) {
                *r += wo * v;
            }
        }
    }

    /// The rows of [`Mlp::forward_from`] for samples seen along `dirs`: one row of
    /// [`Self::starts`] (of `encode(direction)`) per run of consecutive equal directions (a
    /// ray's samples share one) into `rows`, and each sample's row into `row_of`, both
    /// cleared first.
    pub(crate) fn starts_per_run<const N: usize>(
        &self,
        dirs: &[Vec3],
        encode: impl Fn(Vec3) -> [f32; N],
        rows: &mut Vec<f32>,
        row_of: &mut Vec<u32>,
    ) {
        rows.clear();
        row_of.clear();
        let mut run = None;
        for &d in dirs {
            let bits = d.to_array().map(f32::to_bits);
            if run != Some(bits) {
                run = Some(bits);
                self.starts(&encode(d), rows);
            }
            row_of.push((rows.len() / self.stride).saturating_sub(1) as u32);
        }
    }
}

/// Each sample's starting row of the first layer ([`Mlp::forward_from`]).
#[derive(Clone, Copy)]
struct Starts<'a> {
    rows: &'a [f32],
    row_of: &'a [u32],
}

impl Starts<'_> {
    /// A block's starting values feature-major in `init` (`[stride][B]`), for the samples
    /// whose rows are `row_of` (the rest zero), through `scratch` (`[B][stride]`). A block
    /// whose samples share one row (most: a run is a ray's samples) fills each output's
    /// values with its one value.
    #[inline(always)]
    fn block<const FMA: bool, const B: usize>(
        &self,
        row_of: &[u32],
        stride: usize,
        scratch: &mut [f32],
        init: &mut [f32],
    ) {
        let row = |r: u32| &self.rows[r as usize * stride..][..stride];
        let first = row_of.first().copied().unwrap_or(0);
        if row_of.len() == B && row_of.iter().all(|&r| r == first) {
            for (dst, &v) in init.chunks_exact_mut(B).zip(row(first)) {
                dst.fill(v);
            }
            return;
        }
        for (k, &r) in row_of.iter().enumerate() {
            scratch[k * stride..(k + 1) * stride].copy_from_slice(row(r));
        }
        scratch[row_of.len() * stride..].fill(0.0);
        transpose::<FMA, B>(scratch, stride, init, B, B, stride);
    }
}

/// `dst[c·dst_stride + r] = src[r·src_stride + c]` for `r < rows`, `c < cols`: a block's rows
/// of samples to feature-major rows and back. With `FMA` and `B = 16` (the AVX2 kernel's
/// blocks) whole 8×8 tiles move through vector shuffles, the rest value by value; either
/// way the values are copied, never changed.
#[inline(always)]
fn transpose<const FMA: bool, const B: usize>(
    src: &[f32],
    src_stride: usize,
    dst: &mut [f32],
    dst_stride: usize,
    rows: usize,
    cols: usize,
) {
    let (mut r0, mut c0) = (0, 0);
    #[cfg(target_arch = "x86_64")]
    if FMA && B == 16 {
        (r0, c0) = (rows / 8 * 8, cols / 8 * 8);
        for r in (0..r0).step_by(8) {
            for c in (0..c0).step_by(8) {
                // SAFETY: this runs only from `Mlp::forward_avx2`, which `Kernel::detect`
                // picks where the CPU has AVX2.
                unsafe {
                    simd::transpose8x8(
                        &src[r * src_stride + c..],
                        src_stride,
                        &mut dst[c * dst_stride + r..],
                        dst_stride,
                    )
                };
            }
        }
    }
    // What the tiles left: the columns past `c0` of the tiled rows, then the rows past `r0`.
    for r in 0..rows {
        let from = if r < r0 { c0 } else { 0 };
        for c in from..cols {
            dst[c * dst_stride + r] = src[r * src_stride + c];
        }
    }
}

/// One layer on a block of `B` samples: `y[o][b] = bias[o] + Σ_i W[i][o]·x[i][b]` summed in
/// input order (fused, with explicit vectors, when `FMA`), then ReLU when `relu`; with
/// `init` (`[stride][B]`), `init[o][b]` in place of `bias[o]`. `x` holds `l.n_in` rows of
/// `B`, `y` at least `n_out` rounded up to `T` rows.
#[inline(always)]
fn layer<const FMA: bool, const B: usize, const T: usize>(
    l: &Layer,
    x: &[f32],
    init: Option<&[f32]>,
    y: &mut [f32],
    relu: bool,
) {
    let x = &x[..l.n_in * B];
    for o0 in (0..l.n_out).step_by(T) {
        let init = init.map(|v| &v[o0 * B..(o0 + T) * B]);
        // SAFETY: the fused kernel runs only from `Mlp::forward_avx2` (B = 16), which
        // `Kernel::detect` picks where the CPU has AVX2 and FMA.
        #[cfg(target_arch = "x86_64")]
        if FMA && B == 16 {
            unsafe { simd::tile_avx2::<T>(l, x, init, &mut y[o0 * B..(o0 + T) * B], o0, relu) };
            continue;
        }
        let mut acc = [[0.0f32; B]; T];
        for (o, acc_o) in acc.iter_mut().enumerate() {
            match init {
                Some(v) => acc_o.copy_from_slice(&v[o * B..(o + 1) * B]),
                None => acc_o.fill(l.bias[o0 + o]),
            }
        }
        for (i, xi) in x.chunks_exact(B).enumerate() {
            let w = &l.w[i * l.stride + o0..][..T];
            for (acc_o, &wo) in acc.iter_mut().zip(w) {
                for (a, &xb) in acc_o.iter_mut().zip(xi) {
                    *a = if FMA {
                        wo.mul_add(xb, *a)
                    } else {
                        *a + xb * wo
                    };
                }
            }
        }
        for (acc_o, dst) in acc.iter().zip(y[o0 * B..].chunks_exact_mut(B)) {
            for (d, &a) in dst.iter_mut().zip(acc_o) {
                *d = if relu { a.max(0.0) } else { a };
            }
        }
    }
}

/// The fused tiles with explicit vectors (the compiler does not keep `T` accumulator
/// vectors in registers by itself): one vector of samples per output row.
#[cfg(target_arch = "x86_64")]
mod simd {
    use super::Layer;
    use std::arch::x86_64::*;

    /// Row `r < 8` of `src` (8 values from `r·src_stride`) to column `r` of `dst` (value `c`
    /// at `c·dst_stride + r`).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn transpose8x8(src: &[f32], src_stride: usize, dst: &mut [f32], dst_stride: usize) {
        // A loop, not a closure: a closure would not inherit the target features, and its
        // loads would become calls.
        let mut r = [_mm256_setzero_ps(); 8];
        for (k, v) in r.iter_mut().enumerate() {
            let s = &src[k * src_stride..][..8];
            // SAFETY: `s` holds 8 values.
            *v = unsafe { _mm256_loadu_ps(s.as_ptr()) };
        }
        // Pairs of rows interleaved, then pairs of pairs, then the 128-bit halves swapped.
        let t = [
            _mm256_unpacklo_ps(r[0], r[1]),
            _mm256_unpackhi_ps(r[0], r[1]),
            _mm256_unpacklo_ps(r[2], r[3]),
            _mm256_unpackhi_ps(r[2], r[3]),
            _mm256_unpacklo_ps(r[4], r[5]),
            _mm256_unpackhi_ps(r[4], r[5]),
            _mm256_unpacklo_ps(r[6], r[7]),
            _mm256_unpackhi_ps(r[6], r[7]),
        ];
        let u = [
            _mm256_shuffle_ps::<0x44>(t[0], t[2]),
            _mm256_shuffle_ps::<0xee>(t[0], t[2]),
            _mm256_shuffle_ps::<0x44>(t[1], t[3]),
            _mm256_shuffle_ps::<0xee>(t[1], t[3]),
            _mm256_shuffle_ps::<0x44>(t[4], t[6]),
            _mm256_shuffle_ps::<0xee>(t[4], t[6]),
            _mm256_shuffle_ps::<0x44>(t[5], t[7]),
            _mm256_shuffle_ps::<0xee>(t[5], t[7]),
        ];
        for c in 0..8 {
            let v = if c < 4 {
                _mm256_permute2f128_ps::<0x20>(u[c], u[c + 4])
            } else {
                _mm256_permute2f128_ps::<0x31>(u[c - 4], u[c])
            };
            let d = &mut dst[c * dst_stride..][..8];
            // SAFETY: `d` holds 8 values.
            unsafe { _mm256_storeu_ps(d.as_mut_ptr(), v) };
        }
    }

    /// `T` outputs from `o0` for 16 samples (two vectors of 8); `x` is `[n_in][16]`, `y` is
    /// `[T][16]`.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn tile_avx2<const T: usize>(
        l: &Layer,
        x: &[f32],
        init: Option<&[f32]>,
        y: &mut [f32],
        o0: usize,
        relu: bool,
    ) {
        let mut acc = [[_mm256_setzero_ps(); 2]; T];
        for (o, a) in acc.iter_mut().enumerate() {
            *a = match init {
                Some(v) => {
                    let v = &v[o * 16..][..16];
                    // SAFETY: `v` holds 16 values.
                    unsafe {
                        [
                            _mm256_loadu_ps(v.as_ptr()),
                            _mm256_loadu_ps(v[8..].as_ptr()),
                        ]
                    }
                }
                None => [_mm256_set1_ps(l.bias[o0 + o]); 2],
            };
        }
        for (i, xi) in x.chunks_exact(16).enumerate() {
            let w = &l.w[i * l.stride + o0..][..T];
            // SAFETY: `xi` has 16 values.
            let (lo, hi) = unsafe {
                (
                    _mm256_loadu_ps(xi.as_ptr()),
                    _mm256_loadu_ps(xi[8..].as_ptr()),
                )
            };
            for (a, &wo) in acc.iter_mut().zip(w) {
                let wv = _mm256_set1_ps(wo);
                a[0] = _mm256_fmadd_ps(wv, lo, a[0]);
                a[1] = _mm256_fmadd_ps(wv, hi, a[1]);
            }
        }
        let zero = _mm256_setzero_ps();
        for (a, dst) in acc.iter().zip(y.chunks_exact_mut(16)) {
            for (h, v) in a.iter().enumerate() {
                let v = if relu { _mm256_max_ps(*v, zero) } else { *v };
                // SAFETY: `dst` has 16 values.
                unsafe { _mm256_storeu_ps(dst[8 * h..].as_mut_ptr(), v) };
            }
        }
    }
}

/// `n` seeded values in `[−0.5, 0.5)`: weights and inputs of the unit tests and of
/// [`NetworksBench`].
fn seeded(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = crate::rng::Mmix::new(seed);
    (0..n).map(|_| rng.unit() - 0.5).collect()
}

/// The networks of a shaded instant-ngp sample (8×4 grid) as the kernel runs them, on an
/// in-cache batch of [`BATCH`](Self::BATCH) seeded inputs: the density network 32 → 64 → 16
/// and the colour network's head 16 → 64 → 64 → 3 once its direction part is split off.
/// What `cargo bench --bench ingp -- networks_against_the_fma_peak` times.
#[doc(hidden)]
pub struct NetworksBench {
    density: Mlp,
    colour: Mlp,
    x_density: Vec<f32>,
    x_colour: Vec<f32>,
}

impl NetworksBench {
    /// Samples per [`run`](Self::run).
    pub const BATCH: usize = 256;
    /// The multiply-adds per sample, density network then colour head (four outputs to a
    /// tile).
    pub const MACS_PER_SAMPLE: [f64; 2] = [
        32.0 * 64.0 + 64.0 * 16.0,
        16.0 * 64.0 + 64.0 * 64.0 + 64.0 * 4.0,
    ];

    /// Seeded weights and inputs.
    pub fn new() -> Self {
        let config = |n_inputs, n_hidden_layers, n_outputs| MlpConfig {
            n_inputs,
            width: 64,
            n_hidden_layers,
            n_outputs,
            output_alignment: 16,
        };
        let [density, colour] = [config(32, 1, 16), config(16, 2, 3)]
            .map(|c| Mlp::new(c, &seeded(c.n_params(), 5)).unwrap());
        let n = Self::BATCH;
        Self {
            density,
            colour,
            x_density: seeded(n * 32, 6),
            x_colour: seeded(n * 16, 7),
        }
    }

    /// Both networks over the batch, into fresh outputs; a value of them, to keep.
    pub fn run(&self) -> f32 {
        let n = Self::BATCH;
        let (mut sigma, mut rgb) = (vec![0.0; n * 16], vec![0.0; n * 3]);
        self.density.forward(&self.x_density, &mut sigma);
        self.colour.forward(&self.x_colour, &mut rgb);
        sigma[0] + rgb[0]
    }
}

impl Default for NetworksBench {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_counts() {
        let density = MlpConfig {
            n_inputs: 32,
            width: 64,
            n_hidden_layers: 1,
            n_outputs: 16,
            output_alignment: 16,
        };
        assert_eq!(density.n_params(), 64 * 32 + 16 * 64);
        let rgb = MlpConfig {
            n_inputs: 32,
            width: 64,
            n_hidden_layers: 2,
            n_outputs: 3,
            output_alignment: 16,
        };
        assert_eq!(rgb.n_params(), 64 * 32 + 64 * 64 + 16 * 64);
        let cutlass = MlpConfig {
            output_alignment: 8,
            ..rgb
        };
        assert_eq!(cutlass.n_params(), 64 * 32 + 64 * 64 + 8 * 64);
        // 3 inputs are padded to 16.
        let small = MlpConfig {
            n_inputs: 3,
            ..density
        };
        assert_eq!(small.n_params(), 64 * 16 + 16 * 64);
    }

    #[test]
    fn forward_matches_row_major_matrices() {
        let c = MlpConfig {
            n_inputs: 5,
            width: 8,
            n_hidden_layers: 2,
            n_outputs: 3,
            output_alignment: 8,
        };
        let p = seeded(c.n_params(), 11);
        let mlp = Mlp::new(c, &p).unwrap();
        let x = seeded(4 * 5, 5);
        let mut y = vec![0.0; 4 * 3];
        mlp.forward(&x, &mut y);
        // Reference: W0 is 8×16 row-major, W1 8×8, W2 8×8 (3 outputs used).
        let mat = |off: usize, rows: usize, cols: usize, v: &[f32], relu: bool| -> Vec<f32> {
            (0..rows)
                .map(|r| {
                    let s: f32 = (0..cols)
                        .map(|k| p[off + r * cols + k] * v.get(k).copied().unwrap_or(0.0))
                        .sum();
                    if relu {
                        s.max(0.0)
                    } else {
                        s
                    }
                })
                .collect()
        };
        for k in 0..4 {
            let h0 = mat(0, 8, 16, &x[k * 5..k * 5 + 5], true);
            let h1 = mat(128, 8, 8, &h0, true);
            let out = mat(192, 8, 8, &h1, false);
            for o in 0..3 {
                assert!((y[k * 3 + o] - out[o]).abs() < 1e-6, "{k} {o}");
            }
        }
    }

    /// The one tolerance between a fast kernel and the plain reference: fused multiply-adds
    /// round once instead of twice per term, so over `k` terms of magnitude up to `m` the
    /// results differ by at most about `k·m·2⁻²⁴` per layer.
    fn assert_close(fast: &[f32], plain: &[f32], scale: f32) {
        assert_eq!(fast.len(), plain.len());
        for (i, (a, b)) in fast.iter().zip(plain).enumerate() {
            assert!((a - b).abs() <= 1e-5 * scale, "output {i}: {a} vs {b}");
        }
    }

    #[test]
    fn every_kernel_agrees_with_the_plain_reference() {
        // Several shapes, batch sizes that are not multiples of any block, and inputs with
        // zeros (ReLU-like sparsity).
        for (ni, width, hidden, no, n) in
            [(32, 64, 1, 16, 37), (32, 64, 2, 3, 100), (7, 24, 3, 5, 1)]
        {
            let c = MlpConfig {
                n_inputs: ni,
                width,
                n_hidden_layers: hidden,
                n_outputs: no,
                output_alignment: 16,
            };
            let mlp = Mlp::new(c, &seeded(c.n_params(), 3 + ni as u64)).unwrap();
            let x: Vec<f32> = seeded(n * ni, 9)
                .into_iter()
                .map(|v| if v < -0.3 { 0.0 } else { 4.0 * v })
                .collect();
            let mut plain = vec![0.0; n * no];
            mlp.forward_with(Kernel::Plain, &x, None, &mut plain);
            let scale = plain.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            let mut fast = vec![f32::NAN; n * no];
            mlp.forward_with(Kernel::detect(), &x, None, &mut fast);
            assert_close(&fast, &plain, scale);
            #[cfg(target_arch = "x86_64")]
            if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                let mut avx2 = vec![f32::NAN; n * no];
                mlp.forward_with(Kernel::Avx2, &x, None, &mut avx2);
                assert_close(&avx2, &plain, scale);
            }
        }
    }

    #[test]
    fn tiled_transposes_move_every_value_where_the_plain_loop_does() {
        // Blocks of 16 samples and of fewer, feature counts with and without a partial tile.
        for (rows, cols) in [(16, 32), (13, 32), (16, 3), (7, 16), (16, 63), (8, 8)] {
            let src = seeded(rows * cols, rows as u64);
            let mut want = vec![f32::NAN; cols * 16];
            for r in 0..rows {
                for c in 0..cols {
                    want[c * 16 + r] = src[r * cols + c];
                }
            }
            let mut plain = vec![f32::NAN; cols * 16];
            transpose::<false, 16>(&src, cols, &mut plain, 16, rows, cols);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&plain), bits(&want), "plain {rows}x{cols}");
            #[cfg(target_arch = "x86_64")]
            if Kernel::detect() == Kernel::Avx2 {
                let mut tiled = vec![f32::NAN; cols * 16];
                transpose::<true, 16>(&src, cols, &mut tiled, 16, rows, cols);
                assert_eq!(bits(&tiled), bits(&want), "tiled {rows}x{cols}");
                // And back: feature-major rows to sample rows.
                let mut back = vec![f32::NAN; rows * cols];
                transpose::<true, 16>(&tiled, 16, &mut back, cols, cols, rows);
                assert_eq!(bits(&back), bits(&src), "back {rows}x{cols}");
            }
        }
    }

    #[test]
    fn biased_layers_are_affine_with_relu_between() {
        // 2 → 2 → 1: W0 = [[1, −1], [2, 0]], b0 = [0, −1]; W1 = [[1, 1]], b1 = [0.5].
        // x = (1, 3): h = relu(−2, 1) = (0, 1); y = 1.5. x = (2, 0): h = (2, 3); y = 5.5.
        let layers = [
            (vec![1.0, -1.0, 2.0, 0.0], vec![0.0, -1.0]),
            (vec![1.0, 1.0], vec![0.5]),
        ];
        let m = Mlp::with_biases(2, &layers).unwrap();
        for kernel in [Kernel::Plain, Kernel::detect()] {
            let mut y = [0.0; 2];
            m.forward_with(kernel, &[1.0, 3.0, 2.0, 0.0], None, &mut y);
            assert_eq!(y, [1.5, 5.5], "{kernel:?}");
        }
        // One layer is linear: no ReLU on its output.
        let linear = Mlp::with_biases(2, &layers[..1]).unwrap();
        let mut y = [0.0; 2];
        linear.forward(&[1.0, 3.0], &mut y);
        assert_eq!(y, [-2.0, 1.0]);
        assert_eq!(linear.config().n_hidden_layers, 0);
        // Shapes that do not chain.
        assert!(Mlp::with_biases(3, &layers).is_none());
        assert!(Mlp::with_biases(2, &[]).is_none());
    }

    #[test]
    fn biased_kernels_agree_with_the_plain_reference() {
        // nerfstudio's torch shapes: proposal 10 → 16 → 1, density 32 → 64 → 16, colour
        // 63 → 64 → 64 → 3; batches that are not multiples of a block.
        for (ni, widths, n) in [
            (10, vec![16, 1], 37),
            (32, vec![64, 16], 100),
            (63, vec![64, 64, 3], 21),
        ] {
            let mut fan_in = ni;
            let layers: Vec<(Vec<f32>, Vec<f32>)> = widths
                .iter()
                .enumerate()
                .map(|(k, &w)| {
                    let l = (seeded(w * fan_in, 7 + k as u64), seeded(w, 70 + k as u64));
                    fan_in = w;
                    l
                })
                .collect();
            let mlp = Mlp::with_biases(ni, &layers).unwrap();
            let no = *widths.last().unwrap();
            let x: Vec<f32> = seeded(n * ni, 5).into_iter().map(|v| 4.0 * v).collect();
            // Reference: y = W·x + b per layer, f64.
            let mut want = Vec::new();
            for row in x.chunks_exact(ni) {
                let mut v: Vec<f64> = row.iter().map(|&a| f64::from(a)).collect();
                for (k, (w, b)) in layers.iter().enumerate() {
                    v = b
                        .iter()
                        .enumerate()
                        .map(|(o, &bo)| {
                            let s = f64::from(bo)
                                + (0..v.len())
                                    .map(|i| f64::from(w[o * v.len() + i]) * v[i])
                                    .sum::<f64>();
                            if k + 1 < layers.len() {
                                s.max(0.0)
                            } else {
                                s
                            }
                        })
                        .collect();
                }
                want.extend(v.iter().map(|&a| a as f32));
            }
            let scale = want.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            let mut plain = vec![f32::NAN; n * no];
            mlp.forward_with(Kernel::Plain, &x, None, &mut plain);
            assert_close(&plain, &want, scale);
            let mut fast = vec![f32::NAN; n * no];
            mlp.forward_with(Kernel::detect(), &x, None, &mut fast);
            assert_close(&fast, &plain, scale);
        }
    }

    /// A colour network of `n_inputs` → 64 → 64 → 3 in both layouts, seeded: tiny-cuda-nn's
    /// (no biases, outputs padded to 16) and a torch one with biases.
    fn colour_networks(n_inputs: usize) -> [Mlp; 2] {
        let tcnn = MlpConfig {
            n_inputs,
            width: 64,
            n_hidden_layers: 2,
            n_outputs: 3,
            output_alignment: 16,
        };
        let torch_layers = [
            (seeded(64 * n_inputs, 1), seeded(64, 2)),
            (seeded(64 * 64, 3), seeded(64, 4)),
            (seeded(3 * 64, 5), seeded(3, 6)),
        ];
        [
            Mlp::new(tcnn, &seeded(tcnn.n_params(), 7)).unwrap(),
            Mlp::with_biases(n_inputs, &torch_layers).unwrap(),
        ]
    }

    #[test]
    fn fixed_inputs_fold_into_the_first_biases() {
        // tiny-cuda-nn's 63 → 64 → 64 → 3 colour MLP and a torch one, the last 32 inputs
        // fixed: the same outputs as passing them every time, up to f32 rounding.
        let fixed = seeded(32, 8);
        for mlp in colour_networks(63) {
            let folded = mlp.with_last_inputs(&fixed).unwrap();
            assert_eq!(folded.config().n_inputs, 31);
            let n = 19;
            let varying = seeded(n * 31, 9);
            let full: Vec<f32> = varying
                .chunks_exact(31)
                .flat_map(|v| v.iter().chain(&fixed).copied())
                .collect();
            let (mut want, mut got) = (vec![0.0; n * 3], vec![0.0; n * 3]);
            mlp.forward_with(Kernel::Plain, &full, None, &mut want);
            folded.forward_with(Kernel::Plain, &varying, None, &mut got);
            let scale = want.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            assert_close(&got, &want, scale);
            assert!(mlp.with_last_inputs(&[0.0; 64]).is_none());
        }
    }

    #[test]
    fn split_inputs_summed_once_per_run_give_the_full_network() {
        // instant-ngp's colour MLP (16 features + 16 direction values → 64 → 64 → 3) and a
        // torch one with biases, the last 16 inputs shared by runs of samples of every
        // length around a block's (1, 3, 16, 17, 40, …).
        let runs = [1, 3, 16, 17, 40, 2, 16, 5, 32];
        let n: usize = runs.iter().sum();
        let row_of: Vec<u32> = runs
            .iter()
            .enumerate()
            .flat_map(|(r, &len)| std::iter::repeat_n(r as u32, len))
            .collect();
        let shared = seeded(runs.len() * 16, 8);
        let varying: Vec<f32> = seeded(n * 16, 9).into_iter().map(|v| 4.0 * v).collect();
        let full: Vec<f32> = varying
            .chunks_exact(16)
            .zip(&row_of)
            .flat_map(|(v, &r)| v.iter().chain(&shared[r as usize * 16..][..16]).copied())
            .collect();
        for mlp in colour_networks(32) {
            let (head, last) = mlp.split_last_inputs(16).unwrap();
            assert_eq!(head.config().n_inputs, 16);
            let mut rows = Vec::new();
            for values in shared.chunks_exact(16) {
                last.starts(values, &mut rows);
            }
            assert_eq!(rows.len(), runs.len() * last.stride());
            let mut want = vec![0.0; n * 3];
            mlp.forward_with(Kernel::Plain, &full, None, &mut want);
            let scale = want.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            let starts = Starts {
                rows: &rows,
                row_of: &row_of,
            };
            for kernel in [Kernel::Plain, Kernel::detect()] {
                let mut got = vec![f32::NAN; n * 3];
                head.forward_with(kernel, &varying, Some(starts), &mut got);
                assert_close(&got, &want, scale);
            }
            let mut got = vec![f32::NAN; n * 3];
            head.forward_from(&varying, &rows, &row_of, &mut got);
            assert_close(&got, &want, scale);
            assert!(mlp.split_last_inputs(33).is_none());
        }
    }

    #[test]
    fn wrong_counts_are_refused() {
        let c = MlpConfig {
            n_inputs: 16,
            width: 16,
            n_hidden_layers: 1,
            n_outputs: 1,
            output_alignment: 16,
        };
        assert!(Mlp::new(c, &vec![0.0; c.n_params() - 1]).is_none());
    }
}
