//! 3D Gaussian splats: a set of anisotropic Gaussians with view-dependent colour.
//!
//! Splats are not marched: the renderer rasterises them into depth-sorted fragments per pixel
//! (`render::splats`), and a pixel's fragments are merged front to back with the marcher's
//! pieces. This module holds
//! the splats in their *activated* form (linear scales, unit quaternions, opacities in
//! (0, 1)), as every reader delivers them, so the rasteriser never sees a logit or a log.

mod axes;
mod formats;
mod ply;
mod splatfacto;

pub use axes::Axes;
pub use formats::{SplatFormat, SplatSource};
pub(crate) use splatfacto::is_splatfacto_run;

use std::path::Path;

use glam::{Quat, Vec3};

use super::Aabb;
use crate::error::Result;

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
    /// Splats the reader dropped because a value was not finite or the rotation was zero.
    pub dropped: usize,
    /// What the file was.
    pub source: SplatSource,
}

impl Splats {
    /// No splats yet, room for `n`, coloured by `color`, from a file of `format`.
    pub fn with_capacity(n: usize, color: SplatColor, format: SplatFormat) -> Splats {
        Splats {
            means: Vec::with_capacity(n),
            scales: Vec::with_capacity(n),
            rotations: Vec::with_capacity(n),
            opacities: Vec::with_capacity(n),
            color,
            coefficients: Vec::with_capacity(n * color.coefficients() * 3),
            dropped: 0,
            source: SplatSource {
                format,
                ..SplatSource::default()
            },
        }
    }

    /// Reads splats from any file they come in: an INRIA or SuperSplat compressed `.ply`, an
    /// antimatter15 `.splat`, a Niantic `.spz`, a PlayCanvas `.sog` (or a SOG folder or its
    /// `meta.json`), or a nerfstudio splatfacto run (its directory or its `config.yml`). The
    /// stored values are kept as they are (no change of axes).
    pub fn load(path: &Path) -> Result<Splats> {
        formats::load(path)
    }

    /// Number of splats.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Bytes held by the splats' arrays.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.means.len() * (2 * size_of::<Vec3>() + size_of::<Quat>() + size_of::<f32>())
            + self.coefficients.len() * size_of::<f32>()
    }

    /// The box of the means (empty when there are none).
    pub fn bounds(&self) -> Aabb {
        self.means.iter().fold(
            Aabb::new(Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |b, &m| Aabb::new(b.min.min(m), b.max.max(m)),
        )
    }

    /// What `nerfx info` prints: count, colour model, bounds, opacity and scale ranges,
    /// memory.
    pub fn describe(&self, path: &Path) -> String {
        let range = |values: &mut dyn Iterator<Item = f32>| {
            values.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
        };
        let (o_lo, o_hi) = range(&mut self.opacities.iter().copied());
        let (s_lo, s_hi) = range(&mut self.scales.iter().flat_map(|s| s.to_array()));
        let b = self.bounds();
        let color = match self.color {
            SplatColor::Sh { degree } => format!("spherical harmonics, degree {degree}"),
            SplatColor::Sigmoid => "sigmoid of one coefficient per channel".to_string(),
        };
        let source = &self.source;
        let version = source
            .version
            .map_or_else(String::new, |v| format!(", version {v}"));
        let mut text = format!(
            "file: {}\n\
             format: {}{version}: 3D Gaussian splats, {} splats\n\
             colour: {color}\n",
            path.display(),
            source.format,
            self.len(),
        );
        if !source.quantisation.is_empty() {
            text.push_str(&format!("quantisation: {}\n", source.quantisation));
        }
        text.push_str(&format!(
            "antialiased (mip-splatting) mode: {}\n\
             bounds of the means: [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]\n\
             opacity: {o_lo:.4} .. {o_hi:.4}\n\
             scale (standard deviation): {s_lo:.3e} .. {s_hi:.3e}\n\
             memory: {:.1} MiB",
            if source.antialiased {
                "yes, the file says so"
            } else {
                "no"
            },
            b.min.x,
            b.min.y,
            b.min.z,
            b.max.x,
            b.max.y,
            b.max.z,
            self.memory_bytes() as f64 / (1024.0 * 1024.0),
        ));
        for note in &source.notes {
            text.push_str(&format!("\nnote: {note}"));
        }
        if self.dropped > 0 {
            text.push_str(&format!(
                "\nwarning: {} splats dropped (a value not finite or a zero rotation)",
                self.dropped
            ));
        }
        text
    }
}
