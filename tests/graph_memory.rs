//! A graph's memory: the images alive while a frame evaluates are bounded by the graph's
//! width, not its length, and a graph's size is bounded. Measured with a counting allocator,
//! so this binary holds a single test (another test's allocations would count too).

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use nerfx_graph::{evaluate, render_direct, Graph};

/// The system allocator, counting the bytes allocated now and the most ever at once.
struct Counting;

static NOW: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            let now = NOW.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        System.dealloc(p, layout);
        NOW.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// A NeRF Render of the demo environment (64×36, draft) followed by `length` Accumulation
/// Mattes, each reading the one before; the output is the last, a layer the middle one.
fn chain(dir: &Path, length: usize) -> Graph {
    let mut nodes = vec![
        serde_json::json!({"name": "m0", "node": "org.nerfx.NeRFRender",
        "params": {"file": "demo_environment.json", "shot": "demo_shot.json",
                   "quality": "draft"}}),
    ];
    for i in 1..=length {
        nodes.push(serde_json::json!({"name": format!("m{i}"),
            "node": "org.nerfx.AccumulationMatte", "inputs": {"Source": format!("m{}", i - 1)}}));
    }
    let text = serde_json::json!({"nodes": nodes, "output": format!("m{length}"),
        "layers": {"middle": format!("m{}", length / 2)}})
    .to_string();
    Graph::from_json_str(&text, &dir.join("chain.json")).unwrap()
}

/// The most bytes allocated at once, beyond those allocated before, while `graph` evaluates;
/// and the names of the images it returns.
fn peak_while_evaluating(graph: &Graph) -> (usize, Vec<String>) {
    let before = NOW.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let images = evaluate(graph, 1001.0, 1.0, false, &mut render_direct, &|_| {}).unwrap();
    let peak = PEAK.load(Ordering::Relaxed) - before;
    (peak, images.into_keys().collect())
}

#[test]
fn a_long_chain_holds_as_few_images_as_a_short_one_and_size_is_bounded() {
    let dir = tempfile::tempdir().unwrap();
    nerfx_graph::demo::write_graph(dir.path(), 64, 36).unwrap();
    let (short, long) = (chain(dir.path(), 8), chain(dir.path(), 4000));
    // The first evaluation loads and caches the scene and shot; the measured ones do not.
    peak_while_evaluating(&short);
    let (short_peak, _) = peak_while_evaluating(&short);
    let (long_peak, names) = peak_while_evaluating(&long);
    // One 64×36 RGBA image in f32.
    let image = 64 * 36 * 4 * 4;
    println!(
        "peak beyond the baseline: chain of 8 {short_peak} B, chain of 4000 {long_peak} B \
         ({image} B an image)"
    );
    // Evaluation keeps a few words of bookkeeping per node (an image is 36 KiB): holding
    // every intermediate image, the long chain would peak near 150 MB.
    let bookkeeping = 128 * 4000;
    assert!(
        long_peak <= short_peak + 4 * image + bookkeeping,
        "a chain of 4000 peaks at {long_peak} B, one of 8 at {short_peak} B"
    );
    assert!(
        names == ["m2000", "m4000"],
        "{} images returned, not the output's and the layer's",
        names.len()
    );

    // Past the limit a graph is refused before its nodes are read (these lack their inputs),
    // naming the file.
    let mut nodes = Vec::new();
    for i in 0..=Graph::MAX_NODES {
        nodes.push(serde_json::json!({"name": format!("n{i}"), "node": "org.nerfx.DepthMerge"}));
    }
    let text = serde_json::json!({"nodes": nodes, "output": "n0"}).to_string();
    let e = Graph::from_json_str(&text, &dir.path().join("huge.json"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("huge.json")
            && e.contains(&format!("{} nodes", Graph::MAX_NODES + 1))
            && e.contains(&format!("at most {}", Graph::MAX_NODES)),
        "{e}"
    );
}
