//! Graph rendering through the host and the built bundle — the farm's path — against the same
//! graph evaluated in process with the registry: identical pixels for every node, at full and
//! half render scale, and from the command line for a subset of frames.

use std::path::PathBuf;
use std::process::{Command, Output};

use crate::common_ofx::images::rgba_of;
use crate::common_ofx::load;
use nerfx_core::demo;
use nerfx_core::image::read_exr_channels;
use nerfx_graph::demo::write_graph;
use nerfx_graph::{evaluate, render_direct, Graph};
use nerfx_ofx_host::HostOptions;
use nerfx_ofx_host::OfxGraph;

fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-ofx-graph-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `nerfx render <args> --bundle <the built bundle>`, run to its end.
fn render_cli(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .arg("render")
        .args(args)
        .args(["--bundle", &crate::common_ofx::bundle().to_string_lossy()])
        .output()
        .unwrap()
}

/// Asserts that a run succeeded, showing its standard error if not.
fn assert_succeeded(run: &Output) {
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

#[test]
fn the_demo_graph_through_the_bundle_equals_the_core() {
    let dir = scratch_dir("equal");
    let graph = Graph::read(&write_graph(&dir, 41, 23).unwrap()).unwrap();
    let bundle = load(HostOptions::default());
    let mut ofx = OfxGraph::new(graph.clone(), &bundle).unwrap();
    for (frame, scale) in [(1001.0, 1.0), (1012.0, 0.5)] {
        let through = ofx.render(frame, scale, false, &|_| {}).unwrap();
        let direct = evaluate(&graph, frame, scale, false, &mut render_direct, &|_| {}).unwrap();
        assert_eq!(
            through.keys().collect::<Vec<_>>(),
            direct.keys().collect::<Vec<_>>()
        );
        for (name, image) in &direct {
            assert!(
                through[name] == rgba_of(image),
                "node {name} differs at frame {frame}, scale {scale}"
            );
        }
    }
    assert_eq!(bundle.violations(), Vec::<String>::new());
}

#[test]
fn the_command_line_renders_a_subset_of_frames_with_layers() {
    let dir = scratch_dir("cli");
    let comp = write_graph(&dir, 33, 19).unwrap();
    let pattern = dir.join("out/comp.####.exr");
    let run = render_cli(&[
        &comp.to_string_lossy(),
        "--frames",
        "1001,1003",
        "-o",
        &pattern.to_string_lossy(),
        "--png",
    ]);
    assert_succeeded(&run);
    let out = dir.join("out");
    assert!(out.join("comp.1001.exr").is_file() && out.join("comp.1003.exr").is_file());
    assert!(out.join("comp.1001.png").is_file());
    assert!(
        !out.join("comp.1002.exr").exists(),
        "only the frames asked for"
    );

    let graph = Graph::read(&comp).unwrap();
    let direct = evaluate(&graph, 1003.0, 1.0, false, &mut render_direct, &|_| {}).unwrap();
    let channels = read_exr_channels(&out.join("comp.1003.exr")).unwrap();
    let mut names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
    names.sort_unstable();
    assert_eq!(
        names,
        [
            "A", "B", "G", "R", "object.A", "object.B", "object.G", "object.R", "shadow.A",
            "shadow.B", "shadow.G", "shadow.R"
        ]
    );
    let find = |name: &str| &channels.iter().find(|(n, _)| n == name).unwrap().1.data;
    assert_eq!(find("R"), &direct["comp"].rgb.as_ref().unwrap()[0].data);
    assert_eq!(find("A"), &direct["comp"].alpha.as_ref().unwrap().data);
    assert_eq!(
        find("object.G"),
        &direct["obj"].rgb.as_ref().unwrap()[1].data
    );
    assert_eq!(
        find("shadow.A"),
        &direct["shadow"].alpha.as_ref().unwrap().data
    );

    // A graph naming a node that does not exist fails before any frame, naming the file.
    let bad = dir.join("bad.json");
    let text = std::fs::read_to_string(&comp)
        .unwrap()
        .replace("\"B\": \"env\"", "\"B\": \"nope\"");
    std::fs::write(&bad, text).unwrap();
    let run = render_cli(&[&bad.to_string_lossy(), "--frames", "1001"]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && err.contains("bad.json") && err.contains("nope"),
        "{err}"
    );
}

#[test]
fn an_anamorphic_shot_keeps_its_pixel_aspect_to_the_exr() {
    let dir = scratch_dir("anamorphic");
    let comp = write_graph(&dir, 30, 20).unwrap();
    let shot = dir.join("demo_shot.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&shot).unwrap()).unwrap();
    json["pixel_aspect_x"] = 2.0.into();
    std::fs::write(&shot, json.to_string()).unwrap();

    let bundle = load(HostOptions::default());
    let graph = Graph::read(&comp).unwrap();
    let mut ofx = OfxGraph::new(graph.clone(), &bundle).unwrap();
    let through = ofx.render(1004.0, 1.0, false, &|_| {}).unwrap();
    let direct = evaluate(&graph, 1004.0, 1.0, false, &mut render_direct, &|_| {}).unwrap();
    assert!(through["comp"] == rgba_of(&direct["comp"]));
    // The merges take the pixel aspect of their inputs, the renders that of the shot.
    assert_eq!(ofx.pixel_aspect("comp"), 2.0);
    assert_eq!(ofx.pixel_aspect("env"), 2.0);

    let out = dir.join("a.exr");
    let run = render_cli(&[
        &comp.to_string_lossy(),
        "--frames",
        "1004",
        "-o",
        &out.to_string_lossy(),
    ]);
    assert_succeeded(&run);
    let meta = exr::meta::MetaData::read_from_file(&out, false).unwrap();
    assert_eq!(meta.headers[0].shared_attributes.pixel_aspect, 2.0);
    // The camera of the renders the output comes from, and the graph's colour space.
    let shot = nerfx_core::camera::Shot::read(&shot).unwrap();
    let camera = shot.frame(1004).unwrap().camera(&shot).unwrap();
    let want = nerfx_core::image::CameraMatrices::of(&camera);
    let own = &meta.headers[0].own_attributes;
    let close = |got: Option<[f32; 16]>, want: [f32; 16]| {
        got.is_some_and(|g| g.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-5))
    };
    assert!(close(own.world_to_camera, want.world_to_camera));
    assert!(close(
        own.world_to_normalized_device,
        want.world_to_ndc.unwrap()
    ));
    assert_eq!(own.frames_per_second, Some((24, 1)));
    let chroma = meta.headers[0].shared_attributes.chromaticities.unwrap();
    assert_eq!((chroma.red.0, chroma.white.1), (0.64, 0.329));
    assert_eq!(bundle.violations(), Vec::<String>::new());
}

#[test]
fn without_frames_the_graph_renders_its_shot_range() {
    let dir = scratch_dir("range");
    let comp = write_graph(&dir, 12, 8).unwrap();
    let pattern = dir.join("all/c.####.exr");
    let run = render_cli(&[&comp.to_string_lossy(), "-o", &pattern.to_string_lossy()]);
    assert_succeeded(&run);
    let mut written: Vec<String> = std::fs::read_dir(dir.join("all"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    let expected: Vec<String> = (demo::FIRST_FRAME..demo::FIRST_FRAME + demo::FRAMES)
        .map(|f| format!("c.{f}.exr"))
        .collect();
    assert_eq!(written, expected);
}
