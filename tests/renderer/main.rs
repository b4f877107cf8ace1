//! The renderer's accuracy against references that share no code with it — closed-form and
//! hand-worked integrals, the exact f64 reference, formulas written out again — and its
//! properties: one test binary, so the workspace is linked once for all of them and the
//! shared harness ([`common`]) is compiled once.
//!
//! - cameras: [`camera_conventions`] (pinhole and panorama formulas), [`nerfstudio_paths`]
//!   (the real nerfstudio viewer camera paths);
//! - integration: [`closed_form`], [`reference_integrals`], [`marcher_accuracy`];
//! - [`composite_formulas`]: the compositing functions against their formulas;
//! - properties: [`occupancy_conservative`] (empty-space skipping), [`stability`] (the marcher
//!   at the edges of its range).

#[path = "../common/mod.rs"]
mod common;

mod camera_conventions;
mod closed_form;
mod composite_formulas;
mod marcher_accuracy;
mod nerfstudio_paths;
mod occupancy_conservative;
mod reference_integrals;
mod stability;
