//! A scene's instances recoloured to indicator colours, so that a render's colour planes are
//! each instance's share of every pixel's opacity (what a Cryptomatte's coverage is).
//!
//! The render composites `Σ wⱼ cⱼ` over its samples and fragments, where a sample's colour is
//! the density-weighted mix of the instances present there. Give instance `i` a colour that
//! is 1 in one channel and 0 in the others, and that channel composites
//! `Σ wⱼ σᵢ/σ` — instance `i`'s coverage, from the very weights the colour render uses
//! (densities, steps and early stop untouched). Three instances fit in one render.
//! The colours 0 and 1 are their own sRGB encoding and decoding, so the render's
//! colour space does not touch them.

use std::sync::Arc;

use glam::Vec3;

use crate::field::{Aabb, Capabilities, ColorSpace, Field, Span, Splats, Unbounded};

/// A field with its colour replaced by a constant; everything else the field's own.
pub(crate) struct Indicator {
    pub(crate) field: Arc<dyn Field>,
    pub(crate) rgb: Vec3,
}

impl Field for Indicator {
    fn bounds(&self) -> Aabb {
        self.field.bounds()
    }
    fn occupied_bounds(&self) -> Aabb {
        self.field.occupied_bounds()
    }
    fn unbounded(&self) -> Option<Unbounded> {
        self.field.unbounded()
    }
    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        self.field.density(points, sigma)
    }
    fn radiance(&self, _points: &[Vec3], _dirs: &[Vec3], rgb: &mut [Vec3]) {
        rgb.fill(self.rgb)
    }
    fn color_space(&self) -> ColorSpace {
        self.field.color_space()
    }
    fn feature_count(&self) -> usize {
        self.field.feature_count()
    }
    fn density_with_features(&self, points: &[Vec3], sigma: &mut [f32], features: &mut [f32]) {
        self.field.density_with_features(points, sigma, features)
    }
    fn radiance_with_features(&self, _: &[Vec3], _: &[Vec3], _: &[f32], rgb: &mut [Vec3]) {
        rgb.fill(self.rgb)
    }
    fn feature_size(&self) -> f32 {
        self.field.feature_size()
    }
    fn smooth_length(&self) -> f32 {
        self.field.smooth_length()
    }
    fn capabilities(&self) -> Capabilities {
        self.field.capabilities()
    }
    fn density_bounds(&self, regions: &[Aabb], bounds: &mut [f32]) {
        self.field.density_bounds(regions, bounds)
    }
    fn spans(&self, origin: Vec3, dir: Vec3, t0: f64, t1: f64, out: &mut Vec<Span>) {
        self.field.spans(origin, dir, t0, t1, out)
    }
    fn mask_segments(&self, origin: Vec3, dir: Vec3, t0: f64, t1: f64, out: &mut Vec<[f64; 2]>) {
        self.field.mask_segments(origin, dir, t0, t1, out)
    }
    fn may_be_occupied(&self, region: &Aabb) -> bool {
        self.field.may_be_occupied(region)
    }
    fn certainly_empty(&self, points: &[Vec3], empty: &mut [bool]) {
        self.field.certainly_empty(points, empty)
    }
}

/// `splats` coloured `rgb` (0 or 1 per channel) from every direction.
pub(crate) fn indicator_splats(splats: &Splats, rgb: Vec3) -> Splats {
    use crate::field::SplatColor;
    let per = splats.color.coefficients() * 3;
    let dc = match splats.color {
        // SH: colour = SH₀·c₀ + 0.5 (clamped at 0), the other terms zero.
        SplatColor::Sh { .. } => (rgb - Vec3::splat(0.5)) / 0.282_094_8,
        // sigmoid(±30) is 0 and 1 in f32.
        SplatColor::Sigmoid => rgb.map(|v| if v > 0.5 { 30.0 } else { -30.0 }),
    };
    let mut out = splats.clone();
    for c in out.coefficients.chunks_mut(per.max(1)) {
        c.fill(0.0);
        c[..3].copy_from_slice(&dc.to_array());
    }
    out
}
