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

    /// Encodes `x` (unit cube) into `out` (`L·F` values).
    pub(crate) fn encode(&self, x: Vec3, out: &mut [f32]) {
        let nf = self.n_features;
        // Rows per level are a power of two: the hash's modulo is a mask.
        let mask = self.table_size - 1;
        for (l, (&s, dst)) in self.scales.iter().zip(out.chunks_exact_mut(nf)).enumerate() {
            let p = x.to_array().map(|v| v * s);
            // `p ≥ 0` in the unit cube: truncation is the floor, and the upper corner is the
            // ceiling (the same corner as the lower one where `p` is a whole number), without
            // libm's floor and ceil calls on CPUs the build does not assume SSE4.1 of.
            let lo = p.map(|v| v as u32);
            let w = [0, 1, 2].map(|a| p[a] - lo[a] as f32);
            let hi = [0, 1, 2].map(|a| lo[a] + u32::from(w[a] > 0.0));
            dst.fill(0.0);
            for corner in 0..8u32 {
                let mut weight = 1.0f32;
                let mut k = [0u32; 3];
                for a in 0..3 {
                    if corner >> a & 1 == 1 {
                        weight *= w[a];
                        k[a] = hi[a];
                    } else {
                        weight *= 1.0 - w[a];
                        k[a] = lo[a];
                    }
                }
                let h = k[0] ^ k[1].wrapping_mul(2_654_435_761) ^ k[2].wrapping_mul(805_459_861);
                let row = (h & mask) as usize + l * self.table_size as usize;
                for (d, v) in dst.iter_mut().zip(&self.table[row * nf..(row + 1) * nf]) {
                    *d += weight * v;
                }
            }
        }
    }
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
        g.encode(Vec3::new(0.25, 0.75, 0.5), &mut out);
        let h = (1u64 ^ (3 * 2_654_435_761u64) ^ (2 * 805_459_861u64)) % 64;
        assert_eq!(k[0], 1);
        assert_eq!(out, [2.0 * h as f32, 2.0 * h as f32 + 1.0]);
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
