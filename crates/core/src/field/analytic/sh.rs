//! View-dependent colour as real spherical harmonics up to degree 2.
//!
//! `c(d) = max(0, Σᵢ kᵢ Yᵢ(d))` per channel, with the standard real SH basis (the sign and
//! order used by tcnn and most NeRF code), for a unit direction `d = (x, y, z)`:
//!
//! | i | Yᵢ(d)                     |
//! |---|---------------------------|
//! | 0 | 0.282095                  |
//! | 1 | −0.488603 y               |
//! | 2 | 0.488603 z                |
//! | 3 | −0.488603 x               |
//! | 4 | 1.092548 xy               |
//! | 5 | −1.092548 yz              |
//! | 6 | 0.315392 (3z² − 1)        |
//! | 7 | −1.092548 xz              |
//! | 8 | 0.546274 (x² − y²)        |
//!
//! The basis is orthonormal over the unit sphere. A colour holds 1 (constant), 4 (degree 1)
//! or 9 (degree 2) coefficients per channel.

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// `Y₀ = 1/(2√π)`.
const C0: f64 = 0.282_094_791_773_878_14;
/// `√3/(2√π)`.
const C1: f64 = 0.488_602_511_902_919_9;
/// `√15/(2√π)`.
const C2: f64 = 1.092_548_430_592_079_2;
/// `√5/(4√π)`.
const C3: f64 = 0.315_391_565_252_520_05;
/// `√15/(4√π)`.
const C4: f64 = 0.546_274_215_296_039_6;

/// A view-dependent linear-RGB colour: real SH coefficients of degree 0, 1 or 2.
///
/// JSON: `{"rgb": [r, g, b]}` for a constant colour, or `{"sh": [[r, g, b], ...]}` with 1, 4
/// or 9 coefficient triples `k₀ … k₈` in the order of the module table (so `{"sh": [k₀]}`
/// gives the colour `0.282095·k₀`).
///
/// The constant term is stored already multiplied by `Y₀`, so [`ShColor::constant`] evaluates
/// to exactly the given colour.
///
/// ```
/// use glam::Vec3;
/// use nerfx_core::field::ShColor;
/// // Brighter red when seen along +z: k₂ multiplies 0.488603·z.
/// let c = ShColor::from_coefficients(&[Vec3::splat(2.0), Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO]).unwrap();
/// let up = c.eval(Vec3::Z);
/// assert!((up.x - (2.0 * 0.282095 + 0.488603)).abs() < 1e-5);
/// assert!((up.y - 2.0 * 0.282095).abs() < 1e-5);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ShColorRepr", into = "ShColorRepr")]
pub struct ShColor {
    /// `Y₀·k₀`: the direction-independent part of the colour.
    dc: Vec3,
    /// `k₁ … k₈` (unused ones are zero).
    higher: [Vec3; 8],
    /// 0, 1 or 2.
    degree: u8,
}

/// The JSON shape of [`ShColor`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
enum ShColorRepr {
    /// A constant colour.
    Rgb(Vec3),
    /// SH coefficients `k₀ …`.
    Sh(Vec<Vec3>),
}

impl TryFrom<ShColorRepr> for ShColor {
    type Error = Error;

    fn try_from(repr: ShColorRepr) -> Result<Self> {
        match repr {
            ShColorRepr::Rgb(rgb) => {
                if !rgb.is_finite() {
                    return Err(Error::invalid("rgb", format!("not finite: {rgb}")));
                }
                Ok(ShColor::constant(rgb))
            }
            ShColorRepr::Sh(k) => ShColor::from_coefficients(&k),
        }
    }
}

impl From<ShColor> for ShColorRepr {
    fn from(c: ShColor) -> Self {
        if c.degree == 0 {
            ShColorRepr::Rgb(c.dc)
        } else {
            ShColorRepr::Sh(c.coefficients())
        }
    }
}

impl ShColor {
    /// The constant colour `rgb` (degree 0): `eval(d) == max(rgb, 0)` exactly, for every `d`.
    pub fn constant(rgb: Vec3) -> Self {
        ShColor {
            dc: rgb,
            higher: [Vec3::ZERO; 8],
            degree: 0,
        }
    }

    /// A colour from 1, 4 or 9 coefficient triples `k₀ … ` (see the module table).
    /// Refuses any other count and non-finite values.
    pub fn from_coefficients(k: &[Vec3]) -> Result<Self> {
        let degree = match k.len() {
            1 => 0,
            4 => 1,
            9 => 2,
            n => {
                return Err(Error::invalid(
                    "sh",
                    format!("expected 1, 4 or 9 coefficient triples, got {n}"),
                ))
            }
        };
        if let Some(i) = k.iter().position(|c| !c.is_finite()) {
            return Err(Error::invalid(
                format!("sh[{i}]"),
                format!("not finite: {}", k[i]),
            ));
        }
        let mut higher = [Vec3::ZERO; 8];
        higher[..k.len() - 1].copy_from_slice(&k[1..]);
        Ok(ShColor {
            dc: k[0] * C0 as f32,
            higher,
            degree,
        })
    }

    /// The SH degree: 0, 1 or 2.
    #[cfg(test)]
    pub(crate) fn degree(&self) -> u32 {
        u32::from(self.degree)
    }

    /// The coefficient triples `k₀ …` (1, 4 or 9 of them).
    pub(crate) fn coefficients(&self) -> Vec<Vec3> {
        let n = (usize::from(self.degree) + 1).pow(2);
        let mut k = Vec::with_capacity(n);
        k.push(self.dc / C0 as f32);
        k.extend_from_slice(&self.higher[..n - 1]);
        k
    }

    /// The colour seen along the unit direction `dir` (linear RGB, clamped at ≥ 0).
    #[inline]
    pub fn eval(&self, dir: Vec3) -> Vec3 {
        let mut c = self.dc;
        if self.degree >= 1 {
            let (x, y, z) = (dir.x, dir.y, dir.z);
            let h = &self.higher;
            let c1 = C1 as f32;
            c += h[0] * (-c1 * y) + h[1] * (c1 * z) + h[2] * (-c1 * x);
            if self.degree >= 2 {
                let (c2, c3, c4) = (C2 as f32, C3 as f32, C4 as f32);
                c += h[3] * (c2 * x * y)
                    + h[4] * (-c2 * y * z)
                    + h[5] * (c3 * (3.0 * z * z - 1.0))
                    + h[6] * (-c2 * x * z)
                    + h[7] * (c4 * (x * x - y * y));
            }
        }
        c.max(Vec3::ZERO)
    }

    /// [`ShColor::eval`] in f64 (for the reference integrator): the same stored coefficients,
    /// evaluated with f64 basis functions.
    pub fn eval_f64(&self, dir: DVec3) -> DVec3 {
        let mut c = self.dc.as_dvec3();
        if self.degree >= 1 {
            let (x, y, z) = (dir.x, dir.y, dir.z);
            let h = self.higher.map(|v| v.as_dvec3());
            c += h[0] * (-C1 * y) + h[1] * (C1 * z) + h[2] * (-C1 * x);
            if self.degree >= 2 {
                c += h[3] * (C2 * x * y)
                    + h[4] * (-C2 * y * z)
                    + h[5] * (C3 * (3.0 * z * z - 1.0))
                    + h[6] * (-C2 * x * z)
                    + h[7] * (C4 * (x * x - y * y));
            }
        }
        c.max(DVec3::ZERO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(theta: f64, phi: f64) -> DVec3 {
        DVec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    #[test]
    fn constant_is_exact_and_direction_independent() {
        let rgb = Vec3::new(0.3, 0.7, 0.123_456_7);
        let c = ShColor::constant(rgb);
        for d in [Vec3::X, -Vec3::Y, Vec3::new(0.6, 0.0, 0.8), Vec3::Z] {
            assert_eq!(c.eval(d), rgb);
            assert_eq!(c.eval_f64(d.as_dvec3()), rgb.as_dvec3());
        }
        // Negative constants clamp to 0.
        assert_eq!(
            ShColor::constant(Vec3::new(-1.0, 0.5, 0.0)).eval(Vec3::X),
            Vec3::new(0.0, 0.5, 0.0)
        );
    }

    #[test]
    fn basis_values_at_axes() {
        // k₀ = 1/0.282095 (a DC colour of 1, keeping the sum ≥ 0) plus a unit coefficient i on
        // the red channel only; green shows the DC part alone.
        let dc = 1.0 / 0.282_094_8;
        let cases: [(usize, DVec3, f64); 6] = [
            (1, DVec3::Y, -0.488_603),
            (2, DVec3::Z, 0.488_603),
            (3, -DVec3::X, 0.488_603),
            (6, DVec3::Z, 0.315_392 * 2.0),
            (8, DVec3::X, 0.546_274),
            (4, DVec3::new(1.0, 1.0, 0.0).normalize(), 1.092_548 * 0.5),
        ];
        for (i, d, expect) in cases {
            let mut k = vec![Vec3::splat(dc); 9];
            for c in k.iter_mut().skip(1) {
                *c = Vec3::ZERO;
            }
            k[i] = Vec3::new(1.0, 0.0, 0.0);
            let c = ShColor::from_coefficients(&k).unwrap();
            let v = c.eval_f64(d);
            assert!((v.x - (1.0 + expect)).abs() < 1e-5, "Y{i}: {v}");
            assert!((v.y - 1.0).abs() < 1e-6);
            let v32 = c.eval(d.as_vec3());
            assert!((f64::from(v32.x) - v.x).abs() < 1e-5);
        }
    }

    /// ∫ Yᵢ Yⱼ dω = δᵢⱼ, by midpoint quadrature in cos θ and uniform φ. Each Yᵢ is read back
    /// through the public API as `eval(d) − Y₀·k₀` with a DC large enough to stay ≥ 0.
    #[test]
    fn basis_is_orthonormal() {
        let offset = 1.0; // |Yᵢ| ≤ 0.631 for degree ≤ 2.
        let colors: Vec<ShColor> = (0..9)
            .map(|i| {
                let mut k = vec![Vec3::ZERO; 9];
                k[0] = Vec3::splat((offset / C0) as f32);
                k[i] += Vec3::X;
                ShColor::from_coefficients(&k).unwrap()
            })
            .collect();
        let base = ShColor::from_coefficients(&[Vec3::splat((offset / C0) as f32)]).unwrap();
        let (nz, nphi) = (400, 256);
        let mut gram = [[0.0f64; 9]; 9];
        let w = (2.0 / nz as f64) * (2.0 * std::f64::consts::PI / nphi as f64);
        for iz in 0..nz {
            let z = -1.0 + (iz as f64 + 0.5) * 2.0 / nz as f64;
            let theta = z.acos();
            for ip in 0..nphi {
                let d = dir(
                    theta,
                    (ip as f64 + 0.5) * 2.0 * std::f64::consts::PI / nphi as f64,
                );
                let b0 = base.eval_f64(d).x;
                let y: Vec<f64> = colors.iter().map(|c| c.eval_f64(d).x - b0).collect();
                for i in 0..9 {
                    for j in 0..9 {
                        gram[i][j] += w * y[i] * y[j];
                    }
                }
            }
        }
        for (i, row) in gram.iter().enumerate() {
            for (j, &g) in row.iter().enumerate() {
                let expect = if i == j { 1.0 } else { 0.0 };
                assert!((g - expect).abs() < 2e-4, "<Y{i},Y{j}> = {g}");
            }
        }
    }

    #[test]
    fn counts_and_serde() {
        assert!(ShColor::from_coefficients(&[Vec3::ONE; 2]).is_err());
        assert!(ShColor::from_coefficients(&[]).is_err());
        assert!(ShColor::from_coefficients(&[Vec3::splat(f32::INFINITY)]).is_err());
        let c: ShColor = serde_json::from_str(r#"{"rgb": [0.5, 0.25, 1]}"#).unwrap();
        assert_eq!(c.eval(Vec3::X), Vec3::new(0.5, 0.25, 1.0));
        assert_eq!(c.degree(), 0);
        let c: ShColor =
            serde_json::from_str(r#"{"sh": [[1,1,1],[0,0,0],[0,0,1],[0,0,0]]}"#).unwrap();
        assert_eq!(c.degree(), 1);
        let blue_up = c.eval(Vec3::Z).z;
        assert!((blue_up - (0.282_095 + 0.488_603)).abs() < 1e-5);
        assert!(serde_json::from_str::<ShColor>(r#"{"sh": [[1,1,1],[0,0,0]]}"#).is_err());
        assert!(serde_json::from_str::<ShColor>(r#"{"hsv": [1,1,1]}"#).is_err());
        // Round trip.
        let s = serde_json::to_string(&c).unwrap();
        let back: ShColor = serde_json::from_str(&s).unwrap();
        assert!((back.eval(Vec3::Z) - c.eval(Vec3::Z)).abs().max_element() < 1e-6);
        let k = back.coefficients();
        assert_eq!(k.len(), 4);
        assert!((k[0] - Vec3::ONE).abs().max_element() < 1e-6);
    }
}
