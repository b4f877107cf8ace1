//! The built OpenFX bundle driven through the strict host, through the C ABI only: one test
//! binary, so the bundle is built once for all of them and the fixtures are compiled once.
//!
//! - [`host`], [`host_modes`]: the host's suites and the modes a host may run the plugin in;
//! - [`nodes`]: every node described as the registry says and rendering the core's pixels;
//! - [`formats`]: what a compositor learns about the images (frame range, pixel aspect…);
//! - [`graph`]: graphs through the bundle (the farm's path) against the registry in process;
//! - [`render_warnings`]: what a render reports to the host and the command line.
//!
//! The memory of a graph through the bundle (`tests/ofx_graph_memory.rs`) is measured by a
//! counting global allocator: it stays a binary of its own.

#[path = "../common_fields/mod.rs"]
mod common_fields;
#[path = "../common_ingp/mod.rs"]
#[allow(dead_code)] // the writers of bytes and blobs these tests do not use
mod common_ingp;
#[path = "../common_ofx/mod.rs"]
mod common_ofx;

mod formats;
mod graph;
mod host;
mod host_modes;
mod nodes;
mod render_warnings;
