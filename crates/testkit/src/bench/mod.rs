//! Benchmarks: render time against error on a suite of scenes, heap use, and the report.
//!
//! [`suite::run`] renders each [`SceneKind`] (the analytic demo, thin analytic sheets, a
//! smooth trained fog, a dense trained blob, Gaussian splats) with each quality preset and
//! with the naive uniform-step marcher, compares every image with the scene's reference
//! (exact for analytic scenes; for trained fields a much finer march, or for the dense blob
//! an adaptive quadrature of the field that shares no code with the marcher) and reports
//! ms/frame, CPU time, samples per pixel, PSNR, the largest alpha, colour and depth errors
//! (and whether the preset keeps its error target) and peak heap ([`memory`]), as Markdown
//! and as plots of time against PSNR ([`report`]); [`scaling`] measures how cost grows
//! with resolution, instances and occupied space. [`snapshot`] generates the trained
//! fields (and the tests' snapshot fixtures); [`splats`], [`passes`] and [`field`] time
//! splat rasterisation, extra passes and field throughput; [`deep`] what deep output costs;
//! [`targets`] is the `main` of the measurements under `benches/` (`cargo bench --bench NAME`).

pub mod deep;
pub mod field;
pub mod memory;
pub mod passes;
pub mod plot;
pub mod report;
pub mod scaling;
pub mod scenes;
pub mod setup;
pub mod snapshot;
pub mod splats;
pub mod suite;
pub mod targets;

pub use scenes::SceneKind;
pub use suite::{run, Report, SuiteOptions};
