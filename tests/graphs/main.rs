//! Node graphs evaluated in process: one test binary, so the workspace is linked once for
//! both.
//!
//! - [`file`]: the demo's graph file, its wiring, pruning and render scale;
//! - [`nodes`]: the node registry against the core's functions called directly.
//!
//! The shared renders of NeRF Render nodes (`tests/shared_renders.rs`) and the memory of a
//! graph (`tests/graph_memory.rs`) read process-wide counts: each stays a binary of its own.

#[path = "../common/rng.rs"]
mod rng;

mod file;
mod nodes;
