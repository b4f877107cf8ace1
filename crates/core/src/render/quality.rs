//! Quality presets: how finely to march, when to stop, how fine the occupancy grid is.

use serde::{Deserialize, Serialize};

/// A named quality level. Each maps to [`MarchParams`]; the benchmark (`nerfx bench`)
/// measures each for time and error against the exact reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
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
///
/// A preset is an **error target** first: [`error_target`](Self::error_target) is what a
/// pixel may be off by (alpha, premultiplied colour), and the marcher spends samples where
/// they change the pixel by more than that. The other dials bound the work: the base step
/// (and how far it may grow where the content is smooth or hidden), the bisection depth, the
/// transmittance at which a ray stops, and every ray's sample budget.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MarchParams {
    /// Base step: each field's [`feature_size`](crate::field::Field::feature_size) divided by
    /// this (in field units).
    pub steps_per_feature: f32,
    /// Step growth with world distance from the camera: `δ = max(base, cone·t)`, in runs
    /// searched for their edges (the error rule sets the steps of exact runs).
    pub cone: f32,
    /// The step never exceeds `base · max_step_factor`. Steps grow towards it (doubling
    /// from node to node) where the last steps' error estimates are far below the target:
    /// empty or evenly dense space, smooth fog, and wherever the transmittance left makes a
    /// step's error irrelevant. In a run whose ends are a field's exact spans (no edge
    /// inside) a step is as long as the trapezoid rule's error estimate allows at the last
    /// round's curvature and transmittance, at most twice the step before it.
    pub max_step_factor: f32,
    /// A ray stops once its transmittance falls below this.
    pub min_transmittance: f32,
    /// Occupancy grid cells per side at the finest level.
    pub occupancy_resolution: u32,
    /// What one step may change the pixel by: a step is bisected when its weight
    /// (`δ·T`, length times the transmittance it is entered with) times its local error
    /// estimate exceeds this. The estimate is the density jump `|σ_b − σ_a|` between its
    /// ends, or the curvature through its neighbours (`δ²·|σ''|`) where that is smaller (a
    /// smooth slope the trapezoid rule integrates well), or how far the field's density
    /// bound over the step rises above both ends (a sheet thinner than the step). A step
    /// that can hold no edge (density at both ends, shorter than the field's
    /// [`smooth_length`](crate::field::Field::smooth_length)) is judged by its curvature
    /// alone: a bump between ends of equal density has no jump. `T` is the ray's at the
    /// step, carried through the steps before it.
    pub error_target: f32,
    /// Bisections of a base step at most (a step grown by `2^k` gets `k` more).
    pub refine_depth: u32,
    /// Per ray, the lightest samples go without a colour query while their weights add up
    /// to at most this (which bounds the colour error it causes).
    pub color_skip_budget: f32,
    /// A ray's sample budget: density samples (regular and refinement, over all instances'
    /// shared nodes) after which it stops, at the end of the round that reaches it (a round
    /// lays at most a chunk of nodes and their bisections, so a ray may pass the budget by
    /// that much). A ray that reaches it is counted in
    /// [`RenderStats::budget_limited_rays`](super::RenderStats::budget_limited_rays): its
    /// pixel may miss the target.
    pub max_samples: u32,
    /// Integrate scenes of analytic fields in closed form; false: march them like any
    /// field. A scene qualifies when every instance's field is analytic and it holds no
    /// splats and no instance sampled by its trainer's estimator; its rays are then
    /// integrated exactly, piece by piece between the primitives' support ends (module
    /// `closed_form`), and only the quadrature of the colour and depth inside pieces that
    /// hold Gaussian blobs follows [`error_target`](Self::error_target) (with
    /// [`max_samples`](Self::max_samples) as its node budget). Absent from older
    /// serialised settings: on.
    #[serde(default = "closed_form_by_default")]
    pub closed_form: bool,
}

/// Settings serialised before [`MarchParams::closed_form`] existed integrate in closed form,
/// as every preset does.
fn closed_form_by_default() -> bool {
    true
}

impl Quality {
    /// The preset's parameters.
    pub fn params(self) -> MarchParams {
        match self {
            Quality::Draft => MarchParams {
                steps_per_feature: 1.0,
                cone: 1.0 / 256.0,
                max_step_factor: 64.0,
                min_transmittance: 1e-2,
                occupancy_resolution: 64,
                error_target: 5e-2,
                refine_depth: 4,
                color_skip_budget: 1e-3,
                max_samples: 1024,
                closed_form: true,
            },
            Quality::Preview => MarchParams {
                steps_per_feature: 2.0,
                cone: 1.0 / 512.0,
                max_step_factor: 64.0,
                min_transmittance: 1e-3,
                occupancy_resolution: 128,
                error_target: 5e-3,
                refine_depth: 6,
                color_skip_budget: 1e-4,
                max_samples: 4096,
                closed_form: true,
            },
            Quality::Final => MarchParams {
                steps_per_feature: 8.0,
                cone: 0.0,
                // Final's base step is an eighth of Draft's: 128 of them are 16 of Draft's.
                // Where steps may grow is the growth rule's to say (smooth fog), not this bound.
                max_step_factor: 128.0,
                min_transmittance: 1e-4,
                occupancy_resolution: 256,
                error_target: 1e-3,
                refine_depth: 11,
                color_skip_budget: 1e-5,
                max_samples: 16384,
                closed_form: true,
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

    /// The preset's number of points of the aperture a frame with depth of field is rendered
    /// through (per shutter time): an out-of-focus point spreads over its circle of confusion
    /// as that many copies until their spacing falls below a pixel, and smooth defocus
    /// converges as the stratified mean does.
    pub fn aperture_samples(self) -> u32 {
        match self {
            Quality::Draft => 4,
            Quality::Preview => 16,
            Quality::Final => 64,
        }
    }

    /// The preset's cap on the samples a deep pixel keeps
    /// ([`DeepParams::max_samples`](crate::render::DeepParams::max_samples)): its merging
    /// rule keeps far fewer in fog and on surfaces; the cap bounds the file where content
    /// has many distinct layers (splats seen edge on, sheets).
    pub fn deep_samples(self) -> u32 {
        match self {
            Quality::Draft => 8,
            Quality::Preview => 16,
            Quality::Final => 32,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Settings serialised before the closed-form dial existed still read, with it on.
    #[test]
    fn settings_without_the_closed_form_dial_read_with_it_on() {
        let mut json = serde_json::to_value(Quality::Draft.params()).unwrap();
        json.as_object_mut().unwrap().remove("closed_form");
        let old: MarchParams = serde_json::from_value(json).unwrap();
        assert_eq!(old, Quality::Draft.params());
        assert!(Quality::ALL.iter().all(|q| q.params().closed_form));
        let off = MarchParams {
            closed_form: false,
            ..Quality::Final.params()
        };
        let back: MarchParams =
            serde_json::from_str(&serde_json::to_string(&off).unwrap()).unwrap();
        assert_eq!(back, off);
    }
}
