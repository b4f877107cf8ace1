//! tiny-cuda-nn's spherical-harmonics direction encoding of degree 4 (16 terms, bands 0–3).
//!
//! The network is fed `(d + 1)/2` and the encoding maps it back (`x = 2u − 1`, in f32, so
//! the same rounding as on the GPU) before evaluating the real SH basis with tcnn's signs and
//! order: `0.2821; −0.4886y, 0.4886z, −0.4886x; 1.0925xy, −1.0925yz, 0.9462z² − 0.3154,
//! −1.0925xz, 0.5463(x² − y²); 0.5900y(y² − 3x²), 2.8906xyz, 0.4570y(1 − 5z²),
//! 0.3732z(5z² − 3), 0.4570x(1 − 5z²), 1.4453z(x² − y²), 0.5900x(3y² − x²)`.
//! (Constants: `Y₀ = 1/(2√π)`, `√3/(2√π)`, `√15/(2√π)`, … as below.)

use glam::Vec3;

/// `1/(2√π)`.
const K0: f32 = 0.282_094_8;
/// `√3/(2√π)`.
const K1: f32 = 0.488_602_52;
/// `√15/(2√π)`.
const K2A: f32 = 1.092_548_4;
/// `3√5/(4√π)` and `√5/(4√π)`.
const K2B: (f32, f32) = (0.946_174_7, 0.315_391_57);
/// `√15/(4√π)`.
const K2C: f32 = 0.546_274_2;
/// `√70/(8√π)`.
const K3A: f32 = 0.590_043_6;
/// `√105/(2√π)`.
const K3B: f32 = 2.890_611_4;
/// `√42/(8√π)`.
const K3C: f32 = 0.457_045_8;
/// `√7/(4√π)`.
const K3D: f32 = 0.373_176_33;
/// `√105/(4√π)`.
const K3E: f32 = 1.445_305_7;

/// The 16 SH values of the unit direction `d` as tcnn computes them from `(d + 1)/2`.
pub(crate) fn sh4(d: Vec3) -> [f32; 16] {
    let u = (d + Vec3::ONE) * 0.5;
    sh_basis(u * 2.0 - Vec3::ONE)
}

/// The real SH basis of bands 0–3 at the unit direction `v`, in the order and signs above
/// (shared with 3D Gaussian splats, whose SH use the same basis).
pub(crate) fn sh_basis(v: Vec3) -> [f32; 16] {
    let (x, y, z) = (v.x, v.y, v.z);
    let (x2, y2, z2) = (x * x, y * y, z * z);
    [
        K0,
        -K1 * y,
        K1 * z,
        -K1 * x,
        K2A * x * y,
        -K2A * y * z,
        K2B.0 * z2 - K2B.1,
        -K2A * x * z,
        K2C * x2 - K2C * y2,
        K3A * y * (-3.0 * x2 + y2),
        K3B * x * y * z,
        K3C * y * (1.0 - 5.0 * z2),
        K3D * z * (5.0 * z2 - 3.0),
        K3C * x * (1.0 - 5.0 * z2),
        K3E * z * (x2 - y2),
        K3A * x * (-x2 + 3.0 * y2),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The basis from its closed form in f64 (spherical coordinates), with tcnn's sign
    /// convention: odd-`m` terms carry a minus sign (Condon–Shortley).
    fn reference(d: [f64; 3]) -> [f64; 16] {
        let [x, y, z] = d;
        let s = PI.sqrt();
        [
            0.5 / s,
            -(3f64).sqrt() / (2.0 * s) * y,
            (3f64).sqrt() / (2.0 * s) * z,
            -(3f64).sqrt() / (2.0 * s) * x,
            (15f64).sqrt() / (2.0 * s) * x * y,
            -(15f64).sqrt() / (2.0 * s) * y * z,
            (5f64).sqrt() / (4.0 * s) * (3.0 * z * z - 1.0),
            -(15f64).sqrt() / (2.0 * s) * x * z,
            (15f64).sqrt() / (4.0 * s) * (x * x - y * y),
            -(70f64).sqrt() / (8.0 * s) * y * (3.0 * x * x - y * y),
            (105f64).sqrt() / (2.0 * s) * x * y * z,
            -(42f64).sqrt() / (8.0 * s) * y * (5.0 * z * z - 1.0),
            (7f64).sqrt() / (4.0 * s) * z * (5.0 * z * z - 3.0),
            -(42f64).sqrt() / (8.0 * s) * x * (5.0 * z * z - 1.0),
            (105f64).sqrt() / (4.0 * s) * z * (x * x - y * y),
            -(70f64).sqrt() / (8.0 * s) * x * (x * x - 3.0 * y * y),
        ]
    }

    #[test]
    fn matches_closed_form() {
        for k in 0..40 {
            let (th, ph) = (0.3 + k as f64 * 0.07, k as f64 * 0.61);
            let d = [th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()];
            let got = sh4(Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32));
            for (g, r) in got.iter().zip(reference(d)) {
                assert!((*g as f64 - r).abs() < 2e-6, "{g} vs {r}");
            }
        }
    }

    #[test]
    fn basis_is_orthonormal() {
        // Midpoint rule over (θ, φ): ∫ Yᵢ Yⱼ dΩ = δᵢⱼ.
        let (nt, np) = (200, 400);
        let mut gram = [[0.0f64; 16]; 16];
        for i in 0..nt {
            let th = (i as f64 + 0.5) * PI / nt as f64;
            for j in 0..np {
                let ph = (j as f64 + 0.5) * 2.0 * PI / np as f64;
                let d = Vec3::new(
                    (th.sin() * ph.cos()) as f32,
                    (th.sin() * ph.sin()) as f32,
                    th.cos() as f32,
                );
                let y = sh4(d);
                let w = th.sin() * (PI / nt as f64) * (2.0 * PI / np as f64);
                for a in 0..16 {
                    for b in 0..16 {
                        gram[a][b] += w * y[a] as f64 * y[b] as f64;
                    }
                }
            }
        }
        for (a, row) in gram.iter().enumerate() {
            for (b, g) in row.iter().enumerate() {
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((g - want).abs() < 2e-3, "({a}, {b}): {g}");
            }
        }
    }
}
