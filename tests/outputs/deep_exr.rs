//! Deep scanline EXR output read back by OpenEXR's own library (its Python bindings,
//! `tests/openexr/read_deep.py`), not by the code that wrote it, and flattened there in NumPy
//! as OpenEXR's "Interpreting OpenEXR Deep Pixels" composites a deep pixel: the file is a
//! deep scanline part with float channels `R G B A Z ZBack`, tidy (samples sorted, not
//! overlapping, `Z ≤ ZBack`), within the sample cap, and flattens to the flat render within
//! 1e-4, for content integrated in closed form, a marched trained fog, splats and a
//! proposal-sampled nerfacto run; the CLI writes it beside the flat file with the flat
//! file's header entries, and refuses what it cannot do.
//!
//! OpenEXR's Python bindings (3.5) refuse a file with a `deepImageState` attribute, which
//! nerfx writes: the script reads the state from the header bytes and the pixels from a copy
//! without it.
//!
//! Needs `python3` with `numpy` and `OpenEXR` ≥ 3.3 (`scripts/test.sh` installs them), and a
//! build with OpenEXR (`libopenexr-dev`); without them it fails with a message saying so.

use std::path::{Path, PathBuf};
use std::process::Command;

use nerfx_core::camera::Camera;
use nerfx_core::image::{write_deep_exr, DeepImage, ExrHeader, Planes};
use nerfx_core::render::{render_deep, DeepParams, Outputs, Quality, RenderSettings};
use nerfx_core::scene::Scene;
use nerfx_testkit::bench::scenes::build;
use nerfx_testkit::bench::SceneKind;

/// What OpenEXR read from a deep file.
struct ReadBack {
    header: serde_json::Value,
    counts: Vec<u32>,
    z: Vec<f32>,
    z_back: Vec<f32>,
    alpha: Vec<f32>,
    /// The file flattened in NumPy: R, G, B, A planes.
    flat: [Vec<f32>; 4],
}

fn floats(path: &Path) -> Vec<f32> {
    std::fs::read(path)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

fn read_back(file: &Path) -> ReadBack {
    let dir = tempfile::tempdir().unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/openexr/read_deep.py");
    let run = Command::new("python3")
        .arg(&script)
        .arg(file)
        .arg(dir.path())
        .output()
        .unwrap_or_else(|e| panic!("this check needs python3 with numpy and OpenEXR ({e})"));
    assert!(
        run.status.success(),
        "OpenEXR's reader failed (it needs python3 with numpy and OpenEXR ≥ 3.3):\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let header: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("header.json")).unwrap()).unwrap();
    let counts = std::fs::read(dir.path().join("counts.u32"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let flat = floats(&dir.path().join("flat.f32"));
    let n = flat.len() / 4;
    ReadBack {
        header,
        counts,
        z: floats(&dir.path().join("Z.f32")),
        z_back: floats(&dir.path().join("ZBack.f32")),
        alpha: floats(&dir.path().join("A.f32")),
        flat: [0, 1, 2, 3].map(|k| flat[k * n..(k + 1) * n].to_vec()),
    }
}

/// Checks the file OpenEXR read against the flat render `planes`: its layout, tidiness, the
/// cap, and flattening within 1e-4. Returns what was read.
fn check(what: &str, file: &Path, planes: &Planes, cap: u32) -> ReadBack {
    let back = read_back(file);
    let h = &back.header;
    assert!(
        h["type"].as_str().unwrap().contains("deepscanline"),
        "{what}: {h}"
    );
    assert_eq!(h["compression"], "ZIPS_COMPRESSION", "{what}");
    // deepImageState DIS_TIDY (3), read from the header bytes by the script.
    assert_eq!(h["deepImageState"], 3, "{what}: {h}");
    assert_eq!(
        (h["width"].as_u64(), h["height"].as_u64()),
        (Some(planes.width.into()), Some(planes.height.into())),
        "{what}"
    );
    let mut names: Vec<(String, String)> = h["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            (
                c["name"].as_str().unwrap().into(),
                c["type"].as_str().unwrap().into(),
            )
        })
        .collect();
    names.sort();
    let want: Vec<(String, String)> = ["A", "B", "G", "R", "Z", "ZBack"]
        .iter()
        .map(|n| (n.to_string(), "float32".to_string()))
        .collect();
    assert_eq!(names, want, "{what}");
    let max = back.counts.iter().copied().max().unwrap_or(0);
    assert!(max <= cap, "{what}: {max} samples in a pixel, cap {cap}");
    let mut at = 0usize;
    for (p, &n) in back.counts.iter().enumerate() {
        let range = at..at + n as usize;
        at += n as usize;
        for i in range.clone() {
            assert!(back.z[i] <= back.z_back[i], "{what}: pixel {p} Z > ZBack");
            assert!(
                (0.0..=1.0).contains(&back.alpha[i]),
                "{what}: pixel {p} alpha"
            );
            if i + 1 < range.end {
                assert!(
                    back.z_back[i] <= back.z[i + 1],
                    "{what}: pixel {p}: samples overlap or are unsorted"
                );
            }
        }
    }
    let [r, g, b] = planes.rgb.as_ref().unwrap();
    let a = planes.alpha.as_ref().unwrap();
    let mut worst = 0.0f32;
    for (k, plane) in [r, g, b, a].into_iter().enumerate() {
        for (p, (&flat, &deep)) in plane.data.iter().zip(&back.flat[k]).enumerate() {
            let e = (flat - deep).abs();
            assert!(
                e <= 1e-4,
                "{what}: channel {k} pixel {p}: flat {flat}, deep {deep}"
            );
            worst = worst.max(e);
        }
    }
    eprintln!(
        "{what}: {} samples, {max} at most a pixel; flattening off by {worst:e} at most",
        back.z.len()
    );
    back
}

fn render_and_write(
    scene: &Scene,
    camera: &Camera,
    quality: Quality,
    cap: u32,
    file: &Path,
) -> (Planes, DeepImage) {
    let params = quality.params();
    let settings = RenderSettings::new(params, Outputs::all());
    let deep = DeepParams {
        max_samples: cap,
        error_target: params.error_target,
    };
    let (planes, image, _) = render_deep(
        scene,
        camera,
        camera.full_window(),
        &settings,
        &deep,
        &|_| {},
    )
    .unwrap();
    write_deep_exr(file, &image, &ExrHeader::default()).unwrap();
    (planes, image)
}

/// Where a pixel is one opaque surface (its first sample takes all but 1e-4 of it), its
/// flat depth lies inside that sample.
fn check_surface_depth(what: &str, back: &ReadBack, planes: &Planes) {
    let z = planes.depth_z.as_ref().unwrap();
    let mut at = 0usize;
    let mut checked = 0;
    for (p, &n) in back.counts.iter().enumerate() {
        if n > 0 && back.alpha[at] > 0.9999 {
            let (front, rear) = (back.z[at], back.z_back[at]);
            let d = z.data[p];
            let slack = 1e-4 * d.abs().max(1.0);
            assert!(
                front - slack <= d && d <= rear + slack,
                "{what}: pixel {p}: flat Z {d} outside its opaque sample [{front}, {rear}]"
            );
            checked += 1;
        }
        at += n as usize;
    }
    assert!(checked > 0, "{what}: no opaque pixel to check");
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn closed_form_scene_flattens_to_the_flat_render() {
    let (scene, camera) = nerfx_core::demo::scene_and_camera(64, 36).unwrap();
    assert!(Quality::Preview.params().closed_form);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("demo.deep.exr");
    let (planes, image) = render_and_write(&scene, &camera, Quality::Preview, 16, &file);
    assert!(image.is_tidy());
    let back = check("demo (closed form)", &file, &planes, 16);
    check_surface_depth("demo (closed form)", &back, &planes);
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn marched_fog_flattens_and_keeps_to_the_cap() {
    let dir = tempfile::tempdir().unwrap();
    let fog = build(SceneKind::Fog, 40, 24, dir.path(), None).unwrap();
    let file = dir.path().join("fog.deep.exr");
    let (planes, image) = render_and_write(&fog.scene, &fog.camera, Quality::Preview, 2, &file);
    let (max, mean) = image.sample_counts();
    assert!(max == 2 && mean > 0.1, "{max} {mean}");
    check("fog (marched, capped)", &file, &planes, 2);
    // Without a tight cap the merging alone keeps a fog pixel to a few samples.
    let file = dir.path().join("fog_merged.deep.exr");
    let (planes, image) = render_and_write(&fog.scene, &fog.camera, Quality::Preview, 4096, &file);
    let (max, mean) = image.sample_counts();
    eprintln!("fog, merged only: {mean:.2} samples a pixel, {max} at most");
    assert!(max < 100, "{max}");
    check("fog (merged, no cap)", &file, &planes, 4096);
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn splats_flatten_and_sit_at_their_depths() {
    let dir = tempfile::tempdir().unwrap();
    let splats = build(SceneKind::Splats, 48, 32, dir.path(), None).unwrap();
    let file = dir.path().join("splats.deep.exr");
    let (planes, _) = render_and_write(&splats.scene, &splats.camera, Quality::Draft, 64, &file);
    check("splats", &file, &planes, 64);
    // Unmerged (no error allowed), every sample is a splat fragment: a point at its depth.
    let settings = RenderSettings::new(Quality::Draft.params(), Outputs::all());
    let exact = DeepParams {
        max_samples: 4096,
        error_target: f32::MIN_POSITIVE,
    };
    let camera = &splats.camera;
    let (planes, image, _) = render_deep(
        &splats.scene,
        camera,
        camera.full_window(),
        &settings,
        &exact,
        &|_| {},
    )
    .unwrap();
    write_deep_exr(&file, &image, &ExrHeader::default()).unwrap();
    let back = check("splats (unmerged)", &file, &planes, 4096);
    assert!(back.z.iter().zip(&back.z_back).all(|(a, b)| a == b));
}

/// The real nerfstudio run of `tests/data/nerfstudio`, copied (nerfx caches an occupancy
/// grid beside a run it loads), rendered through its camera path with nerfacto's own
/// proposal sampler.
#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn proposal_sampled_nerfacto_flattens() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/nerfstudio");
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    copy_dir(&data.join("run"), &run);
    let scene_file = dir.path().join("scene.json");
    std::fs::write(
        &scene_file,
        r#"{"instances": [{"name": "run", "object": "NeRF",
            "field": {"nerfacto": {"path": "run"}}}]}"#,
    )
    .unwrap();
    let loaded = nerfx_core::scene::SceneDesc::read(&scene_file)
        .and_then(|d| d.load())
        .unwrap();
    assert!(!loaded.desc().instances.is_empty());
    let shot = nerfx_core::camera::read_shot(&data.join("camera_path.json"), "NeRF").unwrap();
    let settings = RenderSettings::new(Quality::Draft.params(), Outputs::all());
    let request = nerfx_core::shot_render::FrameRequest::new(settings)
        .with_deep(Some(16))
        .unwrap();
    let (planes, image, _) =
        nerfx_core::shot_render::render_frame(&loaded, &shot, 0, &request, &|_| {}).unwrap();
    let image = image.unwrap();
    let file = dir.path().join("nerfacto.deep.exr");
    write_deep_exr(&file, &image, &ExrHeader::default()).unwrap();
    check("nerfacto (proposal sampler)", &file, &planes, 16);
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

fn nerfx_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_nerfx"))
}

fn nerfx(args: &[&str]) -> std::process::Output {
    Command::new(nerfx_bin())
        .args(args)
        .output()
        .expect("the nerfx binary runs")
}

/// The demo's scene and a shot of it, `blur`red or not, written to `dir`.
fn demo_files(dir: &Path, blur: bool) -> (String, String) {
    let scene = dir.join("scene.json");
    nerfx_core::demo::scene_desc().write(&scene).unwrap();
    let mut shot = nerfx_core::demo::shot(32, 18);
    if blur {
        shot.motion_blur = Some(nerfx_core::camera::MotionBlur {
            shutter: 1.0,
            position: nerfx_core::camera::ShutterPosition::Center,
        });
    }
    let shot_file = dir.join("shot.json");
    shot.write(&shot_file).unwrap();
    (
        scene.to_string_lossy().into_owned(),
        shot_file.to_string_lossy().into_owned(),
    )
}

/// The flat file's planes as nerfx's own reader gives them.
fn flat_planes(path: &Path) -> Planes {
    exr_planes(path, "", true)
}

/// The RGBA planes of the layer `prefix` (`""`: the main layer) of an EXR as nerfx's own
/// reader gives them, and its `Z` plane with `depth`.
fn exr_planes(path: &Path, prefix: &str, depth: bool) -> Planes {
    let channels = nerfx_core::image::read_exr_channels(path).unwrap();
    let find = |name: &str| {
        let name = format!("{prefix}{name}");
        channels
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, p)| p.clone())
            .unwrap_or_else(|| panic!("{name} in {}", path.display()))
    };
    let r = find("R");
    Planes {
        width: r.width,
        height: r.height,
        rgb: Some([r, find("G"), find("B")]),
        alpha: Some(find("A")),
        depth_z: depth.then(|| find("Z")),
        depth_ray: None,
        depth_median: None,
    }
}

fn header_of(path: &Path) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/openexr/read_header.py");
    let run = Command::new("python3")
        .arg(script)
        .arg(path)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&run.stdout).unwrap()
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn the_cli_writes_a_deep_file_beside_the_flat_one_with_its_header() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, shot) = demo_files(dir.path(), false);
    let frame = (nerfx_core::demo::FIRST_FRAME + 2).to_string();
    let flat = dir.path().join("flat.####.exr");
    let deep = dir.path().join("deep/deep.####.exr");
    let run = nerfx(&[
        "render",
        &scene,
        &shot,
        "--frames",
        &frame,
        "--quality",
        "draft",
        "--colorspace",
        "acescg",
        "-o",
        &flat.to_string_lossy(),
        "--deep",
        &deep.to_string_lossy(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let flat_file = dir.path().join(format!("flat.{frame:0>4}.exr"));
    let deep_file = dir.path().join(format!("deep/deep.{frame:0>4}.exr"));
    let planes = flat_planes(&flat_file);
    let back = check(
        "CLI, ACEScg",
        &deep_file,
        &planes,
        Quality::Draft.deep_samples(),
    );
    check_surface_depth("CLI, ACEScg", &back, &planes);
    // The flat file's header entries, as OpenEXR reads them from both.
    let flat_header = header_of(&flat_file);
    let entries = back.header["entries"].as_object().unwrap();
    for key in [
        "chromaticities",
        "worldToCamera",
        "worldToNDC",
        "framesPerSecond",
        "pixelAspectRatio",
        "nerfx/version",
        "nerfx/quality",
        "nerfx/colorspace",
        "nerfx/fieldFiles",
    ] {
        assert_eq!(entries.get(key), flat_header.get(key), "{key}");
        assert!(entries.contains_key(key), "{key}");
    }
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn a_motion_blurred_deep_frame_flattens_to_the_averaged_flat_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, shot) = demo_files(dir.path(), true);
    let frame = (nerfx_core::demo::FIRST_FRAME + 3).to_string();
    let flat = dir.path().join("flat.exr");
    let deep = dir.path().join("deep.exr");
    let run = nerfx(&[
        "render",
        &scene,
        &shot,
        "--frames",
        &frame,
        "--quality",
        "draft",
        "--shutter-samples",
        "3",
        "--deep-samples",
        "64",
        "-o",
        &flat.to_string_lossy(),
        "--deep",
        &deep.to_string_lossy(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    check("CLI, motion blur", &deep, &flat_planes(&flat), 64);
}

#[test]
fn the_cli_refuses_what_deep_output_cannot_do_and_keeps_what_stands() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, shot) = demo_files(dir.path(), false);
    let deep = dir.path().join("deep.exr");
    std::fs::write(&deep, b"an earlier frame").unwrap();
    let deep_arg = deep.to_string_lossy().into_owned();
    let frame = nerfx_core::demo::FIRST_FRAME.to_string();
    let base = ["render", &scene, &shot, "--quality", "draft", "--frames"];
    for (extra, says) in [
        (
            vec![&frame, "--deep", &deep_arg, "--stripe", "1/2"],
            "whole frames",
        ),
        (
            vec![&frame, "--deep", &deep_arg, "--deep-samples", "0"],
            "expected 1 to 4096",
        ),
        (
            vec![&frame, "--deep", &deep_arg, "--deep-samples", "5000"],
            "expected 1 to 4096",
        ),
        (vec![&frame, "--deep-samples", "8"], "add --deep"),
        (
            vec![&frame, "--deep", &deep_arg, "--passes", "depthZ"],
            "add rgba",
        ),
        (vec!["99999", "--deep", &deep_arg], "99999"),
    ] {
        let args: Vec<&str> = base.iter().copied().chain(extra.iter().copied()).collect();
        let run = nerfx(&args);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{extra:?}");
        assert!(stderr.contains(says), "{extra:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert_eq!(std::fs::read(&deep).unwrap(), b"an earlier frame");
    }
    // A graph names its outputs itself.
    let run = nerfx(&["render", &scene, "--deep", &deep_arg]);
    assert!(String::from_utf8_lossy(&run.stderr).contains("its `deep` key"));
}

/// The demo's node graph with its object's NeRF Render node writing deep files.
fn demo_graph_with_deep(dir: &Path) -> PathBuf {
    let graph = nerfx_graph::demo::write_graph(dir, 32, 18).unwrap();
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&graph).unwrap()).unwrap();
    json["deep"] = serde_json::json!({"obj": "deep/obj.####.exr"});
    std::fs::write(&graph, serde_json::to_vec_pretty(&json).unwrap()).unwrap();
    graph
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn a_graph_writes_its_nerf_renders_deep_files_flattening_to_their_layers() {
    let dir = tempfile::tempdir().unwrap();
    let graph = demo_graph_with_deep(dir.path());
    let frame = nerfx_core::demo::FIRST_FRAME + 1;
    let out = dir.path().join("comp.####.exr");
    let frames = format!("{frame}-{}", frame + 1);
    let run = nerfx(&[
        "render",
        &graph.to_string_lossy(),
        "--frames",
        &frames,
        "-o",
        &out.to_string_lossy(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for f in [frame, frame + 1] {
        // The object's node is also the graph's `object` layer: its RGBA as the bundle
        // rendered it.
        let flat = dir.path().join(format!("comp.{f:04}.exr"));
        let layer = exr_planes(&flat, "object.", false);
        let deep = dir.path().join(format!("deep/obj.{f:04}.exr"));
        let back = check(
            &format!("graph node obj, frame {f}"),
            &deep,
            &layer,
            Quality::Preview.deep_samples(),
        );
        let entries = back.header["entries"].as_object().unwrap();
        let flat_header = header_of(&flat);
        for key in [
            "chromaticities",
            "worldToCamera",
            "worldToNDC",
            "nerfx/colorspace",
        ] {
            assert!(entries.contains_key(key), "{key}");
            assert_eq!(entries.get(key), flat_header.get(key), "{key}");
        }
        assert!(!entries.keys().any(|k| k.starts_with("cryptomatte/")));
    }
}

#[test]
fn a_graph_refuses_deep_output_it_cannot_write() {
    let dir = tempfile::tempdir().unwrap();
    let graph = demo_graph_with_deep(dir.path());
    let graph = graph.to_string_lossy();
    let out = dir.path().join("comp.exr");
    let out = out.to_string_lossy();
    let frame = nerfx_core::demo::FIRST_FRAME.to_string();
    let refused = |args: &[&str], says: &str| {
        let run = nerfx(args);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{args:?} succeeded");
        assert!(err.contains(says), "{args:?}: {err}");
    };
    refused(
        &[
            "render", &graph, "--frames", &frame, "-o", &out, "--stripe", "1/2",
        ],
        "deep files are written with whole frames",
    );
    refused(
        &[
            "render", &graph, "--frames", &frame, "-o", &out, "--deep", "x.exr",
        ],
        "its `deep` key",
    );
    std::fs::create_dir_all(dir.path().join("plain")).unwrap();
    let plain = nerfx_graph::demo::write_graph(&dir.path().join("plain"), 8, 8).unwrap();
    refused(
        &[
            "render",
            &plain.to_string_lossy(),
            "--frames",
            &frame,
            "-o",
            &out,
            "--deep-samples",
            "4",
        ],
        "is for a graph whose file names deep outputs",
    );
    // A deep output must come from a NeRF Render node.
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(graph.as_ref()).unwrap()).unwrap();
    json["deep"] = serde_json::json!({"comp": "d.exr"});
    std::fs::write(graph.as_ref(), serde_json::to_vec(&json).unwrap()).unwrap();
    refused(
        &["render", &graph, "--frames", &frame, "-o", &out],
        "deep images come from NeRF Render nodes",
    );
    assert!(!dir.path().join("comp.exr").exists());
}
