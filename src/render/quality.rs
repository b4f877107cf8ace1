//! Quality presets: how finely to march, when to stop, how fine the occupancy grid is.

use serde::{Deserialize, Serialize};

/// A named quality level. Each maps to [`MarchParams`]; the benchmark (`nerfx bench`)
/// measures each for time and error against the exact reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// Interactive: coarse steps, early stop at 1 % transmittance.
    Draft,
    /// Look development.
    Preview,
    /// Final frames: converged to the reference within the benchmark's targets.
    Final,
}

/// The marcher's dials.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MarchParams {
    /// Base step: each field's [`feature_size`](crate::field::Field::feature_size) divided by
    /// this (in field units).
    pub steps_per_feature: f32,
    /// Step growth with world distance from the camera: `δ = max(base, cone·t)`.
    pub cone: f32,
    /// The step never exceeds `base · max_step_factor`.
    pub max_step_factor: f32,
    /// A ray stops once its transmittance falls below this.
    pub min_transmittance: f32,
    /// Occupancy grid cells per side at the finest level.
    pub occupancy_resolution: u32,
    /// A step whose density jump `|σ_b − σ_a|·δ` (optical depth) exceeds this is bisected…
    pub refine_tolerance: f32,
    /// …at most this many times.
    pub refine_depth: u32,
    /// Per ray, the lightest samples go without a colour query while their weights add up
    /// to at most this (which bounds the colour error it causes).
    pub color_skip_budget: f32,
}

impl Quality {
    /// The preset's parameters.
    pub fn params(self) -> MarchParams {
        match self {
            Quality::Draft => MarchParams {
                steps_per_feature: 1.0,
                cone: 1.0 / 256.0,
                max_step_factor: 4.0,
                min_transmittance: 1e-2,
                occupancy_resolution: 64,
                refine_tolerance: 5e-2,
                refine_depth: 2,
                color_skip_budget: 1e-3,
            },
            Quality::Preview => MarchParams {
                steps_per_feature: 2.0,
                cone: 1.0 / 512.0,
                max_step_factor: 2.0,
                min_transmittance: 1e-3,
                occupancy_resolution: 128,
                refine_tolerance: 5e-3,
                refine_depth: 6,
                color_skip_budget: 1e-4,
            },
            Quality::Final => MarchParams {
                steps_per_feature: 8.0,
                cone: 0.0,
                max_step_factor: 1.0,
                min_transmittance: 1e-4,
                occupancy_resolution: 256,
                refine_tolerance: 1e-3,
                refine_depth: 11,
                color_skip_budget: 1e-5,
            },
        }
    }

    /// The preset's number of times a motion-blurred frame is rendered at over its shutter:
    /// the blur of a motion linear over the shutter is exact with any number; curved motion
    /// and shading changes converge as 1/n², and a fast move shows `n` distinct copies until
    /// `n` reaches its length in pixels.
    pub fn shutter_samples(self) -> u32 {
        match self {
            Quality::Draft => 4,
            Quality::Preview => 8,
            Quality::Final => 16,
        }
    }

    /// The preset's identifier, as the command line and the NeRF Render node name it.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Draft => "draft",
            Quality::Preview => "preview",
            Quality::Final => "final",
        }
    }

    /// All presets, coarse to fine.
    pub const ALL: [Quality; 3] = [Quality::Draft, Quality::Preview, Quality::Final];
}
