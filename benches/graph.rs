//! Node graphs, printed: `cargo bench --bench graph -- [NAME…]`.
//!
//! - `through_the_bundle`: the host's cost, the demo graph through the release bundle against
//!   the same graph evaluated in process.
//! - `set_up_series`: how set-up grows with content (analytic spheres, graph nodes), the
//!   figures of the guide's benchmark chapter; `nerfx bench --scaling` measures the same
//!   series beside the others.

#[path = "../tests/common_ofx/mod.rs"]
#[allow(dead_code)] // the test profile's bundle, which these measurements do not use
mod common_ofx;

use nerfx_graph::demo::write_graph;
use nerfx_graph::{evaluate, render_direct, Graph};
use nerfx_ofx_host::{Bundle, OfxGraph};
use nerfx_testkit::bench::targets::Measurement;

fn main() {
    nerfx_testkit::bench::targets::main(
        "graph",
        &[
            Measurement::new(
                "through_the_bundle",
                "the demo graph at 1280x720 through the release bundle and in process",
                through_the_bundle,
            ),
            Measurement::new(
                "set_up_series",
                "set-up per sphere and per graph node as the content grows",
                set_up_series,
            ),
        ],
    );
}

/// The host's cost: the demo graph at 1280×720 through the release bundle against the same
/// graph in process (`cargo bench --bench graph -- through_the_bundle`).
fn through_the_bundle() {
    let dir = tempfile::tempdir().unwrap();
    let graph = Graph::read(&write_graph(dir.path(), 1280, 720).unwrap()).unwrap();
    let bundle = Bundle::load(&common_ofx::release_bundle()).unwrap();
    let mut ofx = OfxGraph::new(graph.clone(), &bundle).unwrap();
    let time = |f: &mut dyn FnMut()| {
        (0..3)
            .map(|_| {
                let start = std::time::Instant::now();
                f();
                start.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    // Warm both caches (files are read once per process image: the plugin's and the test's).
    ofx.render(1001.0, 1.0, false, &|_| {}).unwrap();
    evaluate(&graph, 1001.0, 1.0, false, &mut render_direct, &|_| {}).unwrap();
    let through = time(&mut || {
        ofx.render(1001.0, 1.0, false, &|_| {}).unwrap();
    });
    let direct = time(&mut || {
        evaluate(&graph, 1001.0, 1.0, false, &mut render_direct, &|_| {}).unwrap();
    });
    println!(
        "demo graph 1280×720, 7 nodes, best of 3: through the bundle {:.3} s, in process {:.3} s ({:+.1} %)",
        through,
        direct,
        100.0 * (through / direct - 1.0)
    );
}

/// The set-up series of `nerfx bench --scaling`, alone, as a Markdown table.
fn set_up_series() {
    use nerfx_testkit::bench::{scaling, setup};
    let dir = tempfile::tempdir().unwrap();
    let growths = vec![
        setup::primitives(&[2_000, 20_000, 200_000]).unwrap(),
        setup::graph_nodes(&[100, 1_000, 4_000], dir.path()).unwrap(),
    ];
    println!("{}", scaling::markdown(&growths));
}
