//! tiny-cuda-nn's bias-free MLPs (FullyFusedMLP / CutlassMLP), evaluated in f32 on batches.
//!
//! Layers `y = W·x` without biases, ReLU between them and none after the last. The flat
//! parameters hold the layers one after the other, each row-major `[out][in]`; the first
//! layer's input is padded to a multiple of 16 and the last layer's output to a multiple of
//! 16 (FullyFusedMLP) or 8 (CutlassMLP before September 2022). Padding inputs are zero;
//! padding outputs are dropped.
//!
//! Example: 32 → 64 → 16 with one hidden layer has `64·32 + 16·64 = 3072` parameters.
//!
//! The weights are widened to f32 once and stored transposed (`[in][out]`), so a layer is a
//! sum over inputs of `x_i · column_i`: the inner loop runs over contiguous outputs and
//! vectorises, and inputs zeroed by the ReLU are skipped.

/// The shape of an MLP.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MlpConfig {
    /// Inputs used (the layer reads `n_inputs` rounded up to 16, the rest zero).
    pub n_inputs: usize,
    /// Neurons per hidden layer.
    pub width: usize,
    /// Hidden layers (≥ 1).
    pub n_hidden_layers: usize,
    /// Outputs used.
    pub n_outputs: usize,
    /// The last layer's output is padded to a multiple of this (16, or 8 for old CutlassMLP).
    pub output_alignment: usize,
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
    pub fn n_params(&self) -> usize {
        self.layers().iter().map(|(i, o)| i * o).sum()
    }
}

/// An MLP with f32 weights.
#[derive(Clone, Debug)]
pub struct Mlp {
    config: MlpConfig,
    /// Per layer: `(in, out, weights [in][out])`; the last layer keeps only the used outputs.
    layers: Vec<(usize, usize, Vec<f32>)>,
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
                // Keep the used outputs of the last layer only.
                let kept = if k == last { config.n_outputs } else { n_out };
                let mut t = vec![0.0f32; n_in * kept];
                for o in 0..kept {
                    for i in 0..n_in {
                        t[i * kept + o] = w[o * n_in + i];
                    }
                }
                (n_in, kept, t)
            })
            .collect();
        Some(Mlp { config, layers })
    }

    /// The configuration.
    pub fn config(&self) -> &MlpConfig {
        &self.config
    }

    /// Evaluates the MLP on `n` inputs, `inputs[k·n_inputs ..][.. n_inputs]`, writing
    /// `outputs[k·n_outputs ..][.. n_outputs]`.
    pub fn forward(&self, inputs: &[f32], outputs: &mut [f32]) {
        let (ni, no) = (self.config.n_inputs, self.config.n_outputs);
        let n = inputs.len() / ni.max(1);
        debug_assert_eq!(outputs.len(), n * no);
        let w = self.config.width;
        let (mut a, mut b) = (vec![0.0f32; w], vec![0.0f32; w]);
        for (x, y) in inputs.chunks_exact(ni).zip(outputs.chunks_exact_mut(no)) {
            let (first, rest) = self.layers.split_first().expect("at least two layers");
            layer(&first.2, first.1, x, &mut a);
            relu(&mut a);
            let (last, hidden) = rest.split_last().expect("at least two layers");
            for l in hidden {
                layer(&l.2, l.1, &a, &mut b);
                relu(&mut b);
                std::mem::swap(&mut a, &mut b);
            }
            layer(&last.2, last.1, &a, y);
        }
    }
}

/// `y = Wᵀ-stored layer applied to x`: `y[o] = Σ_i x[i]·w[i·n_out + o]` (inputs past `x.len()`
/// are the zero padding and contribute nothing).
#[inline]
fn layer(w: &[f32], n_out: usize, x: &[f32], y: &mut [f32]) {
    y.fill(0.0);
    for (i, &xi) in x.iter().enumerate() {
        if xi == 0.0 {
            continue;
        }
        let col = &w[i * n_out..(i + 1) * n_out];
        for (yo, wo) in y.iter_mut().zip(col) {
            *yo += xi * wo;
        }
    }
}

#[inline]
fn relu(v: &mut [f32]) {
    for x in v {
        *x = x.max(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seeded(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                ((s >> 40) as f32 / (1u64 << 24) as f32) - 0.5
            })
            .collect()
    }

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
