//! 3D Gaussian splats: a set of anisotropic Gaussians with view-dependent colour.
//!
//! Splats are not marched: they are rasterised into depth-sorted fragments per pixel, and a
//! pixel's fragments are merged front to back with the marcher's pieces. This module holds
//! the splats in their *activated* form (linear scales, unit quaternions, opacities in
//! (0, 1)), as every reader delivers them, so the rasteriser never sees a logit or a log.

use glam::{Quat, Vec3};

/// How a splat's colour is computed from its coefficients.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SplatColor {
    /// Real spherical harmonics of the given degree (0–3) in gsplat's basis and sign
    /// convention, evaluated along the unit direction from the camera centre to the mean
    /// (in the splats' own frame), plus 0.5, clamped at 0. The INRIA PLY and splatfacto with
    /// `sh_degree` ≥ 1 use this.
    Sh {
        /// SH degree (0–3): `(degree + 1)²` coefficients per channel.
        degree: u8,
    },
    /// `sigmoid(c)` of the one coefficient per channel: splatfacto's colour with
    /// `sh_degree` 0.
    Sigmoid,
}

impl SplatColor {
    /// Coefficients per channel.
    pub fn coefficients(self) -> usize {
        match self {
            SplatColor::Sh { degree } => (degree as usize + 1).pow(2),
            SplatColor::Sigmoid => 1,
        }
    }
}

/// Gaussians in their own frame ("splat space", the frame their file is in).
#[derive(Clone, Debug, PartialEq)]
pub struct Splats {
    /// Centres.
    pub means: Vec<Vec3>,
    /// Standard deviations along the Gaussian's own axes (`exp` of the stored log scales).
    pub scales: Vec<Vec3>,
    /// Unit rotations of the Gaussians' axes (normalised from the stored `w x y z`).
    pub rotations: Vec<Quat>,
    /// Opacities in (0, 1) (`sigmoid` of the stored logits).
    pub opacities: Vec<f32>,
    /// How colour is computed.
    pub color: SplatColor,
    /// Colour coefficients, `color.coefficients() · 3` per splat, coefficient-major:
    /// `[k0: r g b][k1: r g b]…` (the DC term first).
    pub coefficients: Vec<f32>,
}
