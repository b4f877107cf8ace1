//! A render whose pixels may be off says so where its user looks: the NeRF Render node's
//! statistics in process, its persistent warning in an OpenFX host (cleared by a clean
//! frame; the render still succeeds), and `nerfx render` of a graph through the bundle, per
//! node and frame. The field answering NaN is an instant-ngp snapshot whose finite f32
//! weights are so large that its density network overflows (the loader refuses NaN and
//! infinite weights, but not huge ones).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard, PoisonError};

use crate::common_ingp::{write_snapshot, Spec};
use crate::common_ofx::fixtures::{demo_dir, instance_with, text};
use crate::common_ofx::load;
use nerfx_core::image::{Planes, Window};
use nerfx_graph::{node, Context, Graph, ParamValues, RenderRequest};
use nerfx_ofx_host::OfxGraph;
use nerfx_ofx_host::{HostOptions, MessageSuiteOffer};
use nerfx_testkit::bench::snapshot::Weights;

const W: u32 = 32;
const H: u32 = 18;
const FRAME: f64 = 1001.0;

/// A folder of its own for one test, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        Scratch(crate::common_ingp::scratch(&format!("warnings-{name}")))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A snapshot whose density network answers NaN: f32 parameters drawn with a standard
/// deviation of 1e30, whose products overflow to ±∞ and whose sums of those are NaN.
/// The bundle's binary keeps the host it was last given (one host per process, as a real
/// host runs a plugin): tests that load it with their own host and count its messages take
/// turns, or one test's warnings reach another's host.
fn one_host_at_a_time() -> MutexGuard<'static, ()> {
    static HOST: Mutex<()> = Mutex::new(());
    HOST.lock().unwrap_or_else(PoisonError::into_inner)
}

fn overflowing_snapshot(dir: &Path) -> PathBuf {
    let spec = Spec {
        half: false,
        weights: Weights::Uniform { std: 1e30 },
        ..Spec::small_8x4()
    };
    write_snapshot(dir, "overflowing.ingp", &spec)
}

/// A snapshot of ordinary weights: a smooth fog of density ≈ 1 (the loader tests' kind).
fn clean_snapshot(dir: &Path) -> PathBuf {
    let spec = Spec {
        weights: Weights::Uniform { std: 0.01 },
        ..Spec::small_8x4()
    };
    write_snapshot(dir, "clean.ingp", &spec)
}

fn nerf_values(field: &Path) -> ParamValues {
    let mut v = node("org.nerfx.NeRFRender").unwrap().defaults();
    v.set("file", text(field)).unwrap();
    v.set("shot", text(demo_dir(W, H).join("demo_shot.json")))
        .unwrap();
    v
}

#[test]
fn the_node_counts_what_its_march_took_as_empty() {
    let dir = Scratch::new("node");
    let n = node("org.nerfx.NeRFRender").unwrap();
    let request = RenderRequest::new(FRAME, Window::new(0, 0, W, H), 1.0);
    let bad = n
        .render_with_stats(&nerf_values(&overflowing_snapshot(&dir.0)), &request)
        .unwrap();
    let clean = n
        .render_with_stats(&nerf_values(&clean_snapshot(&dir.0)), &request)
        .unwrap();
    assert!(bad.stats.invalid_samples > 0, "{:?}", bad.stats);
    let warning = bad.stats.warning().expect("a warning");
    assert!(warning.contains("check the field file"), "{warning}");
    assert_eq!(clean.stats.warning(), None, "{:?}", clean.stats);
}

/// Every pixel of a render is a number: the NaN densities were taken as empty.
fn finite(p: &Planes) -> bool {
    let rgb = p.rgb.iter().flatten();
    rgb.chain(&p.alpha)
        .all(|plane| plane.data.iter().all(|v| v.is_finite()))
}

#[test]
fn the_host_shows_a_persistent_warning_until_a_clean_frame() {
    let _host = one_host_at_a_time();
    let dir = Scratch::new("host");
    let (bad, clean) = (overflowing_snapshot(&dir.0), clean_snapshot(&dir.0));
    let b = load(HostOptions::default());
    let shot = text(demo_dir(W, H).join("demo_shot.json"));
    let (mut i, _) = instance_with(
        &b,
        "org.nerfx.NeRFRender",
        Context::Generator,
        &[("file", text(&bad)), ("shot", shot)],
    );
    let full = Window::new(0, 0, W, H);
    // The render succeeds; the node is flagged with a warning saying what and what to do.
    let image = i.render(FRAME, full, 1.0, false).unwrap();
    assert!(finite(&image));
    let m = i.persistent_message().expect("a persistent warning");
    assert_eq!(m.kind, "OfxMessageWarning");
    for needle in [
        "NeRF Render, frame 1001:",
        "were NaN or infinite",
        "check the field file",
    ] {
        assert!(m.text.contains(needle), "{needle}: {}", m.text);
    }
    // Another tile of the frame keeps the frame's warning.
    i.render(FRAME, Window::new(0, 0, 1, 1), 1.0, false)
        .unwrap();
    assert!(i.persistent_message().is_some());
    // The next frame, clean (another file, set without an edit notification, as an animated
    // parameter would change), clears it.
    i.set_param("file", &text(&clean)).unwrap();
    i.render(FRAME + 1.0, full, 1.0, false).unwrap();
    assert_eq!(i.persistent_message(), None);
    // No dialog ever: every message posted was persistent.
    assert!(
        b.messages().iter().all(|m| m.persistent),
        "{:?}",
        b.messages()
    );
    assert_eq!(b.violations(), Vec::<String>::new());
}

#[test]
fn without_persistent_messages_the_render_still_succeeds_without_a_dialog() {
    let _host = one_host_at_a_time();
    let dir = Scratch::new("v1");
    let b = load(HostOptions {
        message_suite: MessageSuiteOffer::V1Only,
        ..HostOptions::default()
    });
    let shot = text(demo_dir(W, H).join("demo_shot.json"));
    let (i, _) = instance_with(
        &b,
        "org.nerfx.NeRFRender",
        Context::Generator,
        &[("file", text(overflowing_snapshot(&dir.0))), ("shot", shot)],
    );
    let image = i
        .render(FRAME, Window::new(0, 0, W, H), 1.0, false)
        .unwrap();
    assert!(finite(&image));
    assert_eq!(i.persistent_message(), None);
    assert!(b.messages().is_empty(), "{:?}", b.messages());
    assert_eq!(b.violations(), Vec::<String>::new());
}

/// A graph of one NeRF Render node named `fog` of `field`, seen through the demo's shot.
fn fog_graph(dir: &Path, field: &Path) -> PathBuf {
    let shot = demo_dir(W, H).join("demo_shot.json");
    let graph = serde_json::json!({
        "nodes": [{"name": "fog", "node": "org.nerfx.NeRFRender",
                   "params": {"file": field, "shot": shot}}],
        "output": "fog"
    });
    let path = dir.join(format!(
        "{}.graph.json",
        field.file_stem().unwrap().to_string_lossy()
    ));
    std::fs::write(&path, graph.to_string()).unwrap();
    path
}

#[test]
fn a_graph_names_the_node_and_frame_whose_pixels_may_be_off() {
    let _host = one_host_at_a_time();
    let dir = Scratch::new("graph");
    let bad = fog_graph(&dir.0, &overflowing_snapshot(&dir.0));
    let clean = fog_graph(&dir.0, &clean_snapshot(&dir.0));
    let bundle = load(HostOptions::default());
    // In process: the graph's warnings after each frame, by node.
    let mut ofx = OfxGraph::new(Graph::read(&bad).unwrap(), &bundle).unwrap();
    ofx.render(FRAME, 1.0, false, &|_| {}).unwrap();
    let warnings = ofx.warnings().to_vec();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!(warnings[0].0, "fog");
    assert!(warnings[0].1.contains("frame 1001"), "{}", warnings[0].1);
    let mut ofx = OfxGraph::new(Graph::read(&clean).unwrap(), &bundle).unwrap();
    ofx.render(FRAME, 1.0, false, &|_| {}).unwrap();
    assert_eq!(ofx.warnings(), &[]);
    // From the command line: one line per node and frame, on standard error, and the
    // frames are written.
    let run = |graph: &Path, frames: &str| {
        let out = dir.0.join("out.####.exr");
        let run = Command::new(env!("CARGO_BIN_EXE_nerfx"))
            .arg("render")
            .arg(graph)
            .args(["--frames", frames, "-o"])
            .arg(&out)
            .args(["--bundle", &crate::common_ofx::bundle().to_string_lossy()])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
        assert!(run.status.success(), "{stderr}");
        stderr
    };
    let said = run(&bad, "1001,1002");
    let lines: Vec<&str> = said.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(lines.len(), 2, "{said}");
    for (line, frame) in lines.iter().zip(["1001", "1002"]) {
        assert!(
            line.starts_with("nerfx: warning: graph node fog: NeRF Render, frame ")
                && line.contains(frame)
                && line.contains("density samples were NaN or infinite"),
            "{line}"
        );
    }
    assert!(dir.0.join("out.1002.exr").exists());
    let said = run(&clean, "1001");
    assert!(!said.contains("warning"), "{said}");
}
