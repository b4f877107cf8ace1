//! The MLP in bf16 with AVX-512 (`VDPBF16PS`): weights and activations rounded to bf16 (8
//! significant bits), products summed in f32.
//!
//! `VDPBF16PS` multiplies 32 bf16 pairs and adds each adjacent two products into one of 16
//! f32 lanes: twice the multiply-adds of an f32 FMA of the same width. So a layer takes its
//! inputs two at a time: lane `b` of input pair `k` holds `x[2k][b]` in its low 16 bits and
//! `x[2k+1][b]` in its high 16 bits (a block of 16 samples, one per lane), and weight pair
//! `w[k][o]` is `W[2k][o]`, `W[2k+1][o]` in one 32-bit word, broadcast to every lane. Per
//! tile of `T` outputs, `acc[o] += x[2k]·W[2k][o] + x[2k+1]·W[2k+1][o]` over the pairs `k`,
//! then ReLU; a hidden layer rounds its outputs to bf16 pairs for the next one, the last
//! writes f32.
//!
//! bf16 keeps 8 of f32's 24 significant bits (an f16 weight of a snapshot loses 3): each
//! product is off by up to about 2⁻⁸ of itself, so a layer's sums by about 2⁻⁸ of the sum of
//! their terms' magnitudes.

use super::Layer;

/// A layer's weights as bf16 pairs: `w[k·stride + o]` holds `W[2k][o]` (low half) and
/// `W[2k+1][o]` (high half), zero past the layer's inputs and outputs.
#[derive(Clone, Debug)]
pub(super) struct PairedLayer {
    n_pairs: usize,
    n_out: usize,
    stride: usize,
    w: Vec<u32>,
    bias: Vec<f32>,
}

impl PairedLayer {
    /// The weights of `l` rounded to bf16 (to nearest, ties to even) and paired.
    pub(super) fn new(l: &Layer) -> Self {
        let n_pairs = l.n_in.div_ceil(2);
        let weight = |i: usize, o: usize| {
            if i < l.n_in {
                u32::from(bf16_bits(l.w[i * l.stride + o]))
            } else {
                0
            }
        };
        let mut w = vec![0u32; n_pairs * l.stride];
        for k in 0..n_pairs {
            for o in 0..l.n_out {
                w[k * l.stride + o] = weight(2 * k, o) | weight(2 * k + 1, o) << 16;
            }
        }
        PairedLayer {
            n_pairs,
            n_out: l.n_out,
            stride: l.stride,
            w,
            bias: l.bias.clone(),
        }
    }
}

/// The bits of `v` rounded to bf16 (to nearest, ties to even; NaN stays NaN).
pub(super) fn bf16_bits(v: f32) -> u16 {
    if v.is_nan() {
        return 0x7fc0;
    }
    let bits = v.to_bits();
    let rounded = bits.wrapping_add(0x7fff + ((bits >> 16) & 1));
    (rounded >> 16) as u16
}

#[cfg(target_arch = "x86_64")]
pub(super) use avx512::forward;

/// The kernel.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use std::arch::x86_64::*;

    use super::super::{transpose, Starts, PAD};
    use super::PairedLayer;

    /// Samples per block: one per lane of a 512-bit vector of f32.
    const B: usize = 16;

    /// The network `layers` on `n` samples (`inputs` sample-major, `n_inputs` each), writing
    /// `n_outputs` per sample; with `starts`, the first layer's sums start from each sample's
    /// row instead of its biases.
    #[target_feature(enable = "avx2,fma,avx512f,avx512bw,avx512bf16")]
    pub(in super::super) fn forward(
        layers: &[PairedLayer],
        n_inputs: usize,
        n_outputs: usize,
        inputs: &[f32],
        starts: Option<Starts>,
        outputs: &mut [f32],
    ) {
        let n = inputs.len() / n_inputs.max(1);
        let widest = layers.iter().map(|l| l.stride).max().unwrap_or(0);
        let first_stride = layers.first().map_or(0, |l| l.stride);
        let mut x = vec![0.0f32; n_inputs.next_multiple_of(2) * B];
        // Pairs of activations, in and out of a layer; the last layer's f32 outputs.
        let pairs = widest.max(n_inputs).div_ceil(2) * B;
        let (mut a, mut b) = (vec![0u32; pairs], vec![0u32; pairs]);
        let mut y = vec![0.0f32; widest * B];
        let (mut rows, mut init) = match starts {
            Some(_) => (
                vec![0.0f32; first_stride * B],
                vec![0.0f32; first_stride * B],
            ),
            None => (Vec::new(), Vec::new()),
        };
        for (start, ys) in (0..n).step_by(B).zip(outputs.chunks_mut(B * n_outputs)) {
            let m = (n - start).min(B);
            let block = &inputs[start * n_inputs..(start + m) * n_inputs];
            transpose::<true, B>(block, n_inputs, &mut x, B, m, n_inputs);
            for i in 0..n_inputs {
                x[i * B + m..(i + 1) * B].fill(0.0);
            }
            pack_pairs(&x, n_inputs.div_ceil(2), &mut a);
            if let Some(s) = starts {
                s.block::<true, B>(
                    &s.row_of[start..start + m],
                    first_stride,
                    &mut rows,
                    &mut init,
                );
            }
            let last = layers.len() - 1;
            for (k, l) in layers.iter().enumerate() {
                let init = (k == 0 && starts.is_some()).then_some(&init[..]);
                let mut out = if k == last {
                    Out::F32(&mut y)
                } else {
                    Out::Pairs(&mut b)
                };
                for o0 in (0..l.n_out).step_by(PAD) {
                    if l.n_out - o0 > 4 {
                        tile::<PAD>(l, &a, init, o0, k < last, out.reborrow());
                    } else {
                        tile::<4>(l, &a, init, o0, k < last, out.reborrow());
                    }
                }
                std::mem::swap(&mut a, &mut b);
            }
            transpose::<true, B>(&y, B, ys, n_outputs, n_outputs, m);
        }
    }

    /// Where a tile's outputs go: bf16 pairs for the next layer (`[stride / 2][B]`), or f32
    /// (`[stride][B]`) from the last.
    enum Out<'a> {
        Pairs(&'a mut [u32]),
        F32(&'a mut [f32]),
    }

    impl Out<'_> {
        fn reborrow(&mut self) -> Out<'_> {
            match self {
                Out::Pairs(p) => Out::Pairs(p),
                Out::F32(y) => Out::F32(y),
            }
        }
    }

    /// `n_pairs` pairs of feature-major rows of `x` (`[2·n_pairs][B]` f32) rounded to bf16
    /// pairs in `dst` (`[n_pairs][B]`).
    #[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
    fn pack_pairs(x: &[f32], n_pairs: usize, dst: &mut [u32]) {
        for (k, d) in dst.chunks_exact_mut(B).take(n_pairs).enumerate() {
            let rows = &x[2 * k * B..(2 * k + 2) * B];
            // SAFETY: `rows` holds 2·B values, `d` B.
            unsafe {
                let lo = _mm512_loadu_ps(rows.as_ptr());
                let hi = _mm512_loadu_ps(rows[B..].as_ptr());
                _mm512_storeu_si512(d.as_mut_ptr().cast(), paired(lo, hi));
            }
        }
    }

    /// Lane `b` of the result: `lo[b]` rounded to bf16 in its low half, `hi[b]` in its high.
    #[inline]
    #[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
    fn paired(lo: __m512, hi: __m512) -> __m512i {
        // `cvtne2ps` puts its second operand's 16 values in the low 256 bits; the permutation
        // interleaves the two halves' 16-bit words.
        let halves: __m512i = unsafe { std::mem::transmute(_mm512_cvtne2ps_pbh(hi, lo)) };
        let interleave = _mm512_set_epi16(
            31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8, 23, 7, 22, 6, 21, 5, 20,
            4, 19, 3, 18, 2, 17, 1, 16, 0,
        );
        _mm512_permutexvar_epi16(interleave, halves)
    }

    /// `T` outputs from `o0` for a block: `x` is `[n_pairs][B]` pairs, the sums start from
    /// `init` (`[stride][B]`) or the biases; ReLU when `relu`.
    #[inline]
    #[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
    fn tile<const T: usize>(
        l: &PairedLayer,
        x: &[u32],
        init: Option<&[f32]>,
        o0: usize,
        relu: bool,
        out: Out,
    ) {
        let mut acc = [_mm512_setzero_ps(); T];
        for (o, a) in acc.iter_mut().enumerate() {
            *a = match init {
                // SAFETY: `init` holds `stride` rows of B values, and `o0 + o < stride`.
                Some(v) => unsafe { _mm512_loadu_ps(v[(o0 + o) * B..][..B].as_ptr()) },
                None => _mm512_set1_ps(l.bias[o0 + o]),
            };
        }
        for (k, xk) in x.chunks_exact(B).take(l.n_pairs).enumerate() {
            let w = &l.w[k * l.stride + o0..][..T];
            // SAFETY: `xk` holds B values.
            let xv: __m512bh =
                unsafe { std::mem::transmute(_mm512_loadu_si512(xk.as_ptr().cast())) };
            for (a, &wo) in acc.iter_mut().zip(w) {
                let wv: __m512bh = unsafe { std::mem::transmute(_mm512_set1_epi32(wo as i32)) };
                *a = _mm512_dpbf16_ps(*a, xv, wv);
            }
        }
        if relu {
            for a in &mut acc {
                *a = _mm512_max_ps(*a, _mm512_setzero_ps());
            }
        }
        match out {
            Out::Pairs(dst) => {
                for (j, pair) in acc.chunks_exact(2).enumerate() {
                    let d = &mut dst[(o0 / 2 + j) * B..][..B];
                    // SAFETY: `d` holds B values.
                    unsafe { _mm512_storeu_si512(d.as_mut_ptr().cast(), paired(pair[0], pair[1])) };
                }
            }
            Out::F32(dst) => {
                for (o, a) in acc.iter().enumerate() {
                    let d = &mut dst[(o0 + o) * B..][..B];
                    // SAFETY: `d` holds B values.
                    unsafe { _mm512_storeu_ps(d.as_mut_ptr(), *a) };
                }
            }
        }
    }
}
