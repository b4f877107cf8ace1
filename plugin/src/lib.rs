//! The OpenFX plugin over the nerfx core: one image effect per registry node.
//!
//! A thin, generic adapter: everything a node is (contexts, clips, parameters, rendering)
//! comes from [`nerfx_graph::nodes`], so adding a node to the registry never touches this
//! crate. The binary is the bundle's `nerfx.ofx` (`bash bundle/build.sh`).
//!
//! - `entry`: `OfxGetNumberOfPlugins`, `OfxGetPlugin`, `OfxSetHost`, per-node trampolines,
//!   `catch_unwind` around everything.
//! - `actions`: each action's meaning in terms of the core; `describe` and
//!   `param_defs` publish nodes; `instance` keeps per-instance handles; `render` renders;
//!   `effect`: an action's effect handle (its property and parameter sets, its context).
//! - `params`: parameter values at a time; `images` and `pixels`: clip images ⇄
//!   [`nerfx_core::image::Planes`]; `coords`: OpenFX pixel rectangles ⇄ raster windows.
//! - `props`, `suites`, `message`, `status`: the host's suites made safe, and errors;
//!   `frame_stats`: a frame's render statistics over its tiles, for the node's warning;
//!   `colour`: OpenFX 1.5's colour management names, for hosts that offer it.
#![deny(missing_docs)]

mod actions;
mod colour;
mod coords;
mod describe;
mod effect;
mod entry;
mod frame_stats;
mod images;
mod instance;
mod message;
mod param_defs;
mod params;
mod pixels;
mod props;
mod render;
mod status;
mod suites;
