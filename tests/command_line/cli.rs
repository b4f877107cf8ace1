//! The `nerfx` command line, run as a user would: the demo, a frame range through the demo's
//! own scene and shot files, and bad input that must fail with a message naming the file.

use std::path::{Path, PathBuf};
use std::process::Command;

use nerfx_core::image::read_exr_channels;

fn nerfx(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .args(args)
        .output()
        .expect("the nerfx binary runs")
}

fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn channels(path: &Path) -> Vec<String> {
    let mut names: Vec<String> = read_exr_channels(path)
        .expect("readable EXR")
        .into_iter()
        .map(|(name, _)| name)
        .collect();
    names.sort();
    names
}

#[test]
fn demo_then_render_a_frame_range_from_its_files() {
    let dir = scratch_dir("demo");
    let out = dir.to_string_lossy().into_owned();
    let demo = nerfx(&[
        "demo",
        "-o",
        &out,
        "--width",
        "48",
        "--height",
        "27",
        "--quality",
        "draft",
    ]);
    assert!(
        demo.status.success(),
        "{}",
        String::from_utf8_lossy(&demo.stderr)
    );
    assert_eq!(
        channels(&dir.join("demo.exr")),
        [
            "A", "B", "G", "R", "object.A", "object.B", "object.G", "object.R", "shadow.A",
            "shadow.B", "shadow.G", "shadow.R"
        ]
    );
    // The composite's empty sky is transparent in the PNG, the ground opaque.
    let png = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(dir.join("demo.png")).unwrap(),
    ));
    let mut reader = png.read_info().unwrap();
    let mut rgba = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut rgba).unwrap();
    assert_eq!(
        (info.width, info.height, info.color_type),
        (48, 27, png::ColorType::Rgba)
    );
    let alpha = |x: usize, y: usize| rgba[4 * (y * 48 + x) + 3];
    assert_eq!(alpha(47, 0), 0, "the sky top right");
    // Draft stops a ray once its transmittance is under 1 %: opaque is alpha ≥ 0.99.
    assert!(alpha(24, 26) >= 253, "the ground: {}", alpha(24, 26));

    let pattern = dir.join("frames/f.####.exr");
    let render = nerfx(&[
        "render",
        &dir.join("demo_scene.json").to_string_lossy(),
        &dir.join("demo_shot.json").to_string_lossy(),
        "--frames",
        "1001-1005x2",
        "-o",
        &pattern.to_string_lossy(),
        "--quality",
        "draft",
    ]);
    assert!(
        render.status.success(),
        "{}",
        String::from_utf8_lossy(&render.stderr)
    );
    for frame in [1001, 1003, 1005] {
        assert!(
            dir.join(format!("frames/f.{frame}.exr")).is_file(),
            "frame {frame}"
        );
    }
    assert!(!dir.join("frames/f.1002.exr").exists());
    assert_eq!(
        channels(&dir.join("frames/f.1001.exr")),
        ["A", "B", "G", "R", "Z", "depth.median", "depth.ray"],
        "every pass by default"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn render_passes_choose_the_channels_written() {
    let dir = scratch_dir("passes");
    let out = dir.to_string_lossy().into_owned();
    let demo = nerfx(&["demo", "-o", &out, "--width", "32", "--height", "18"]);
    assert!(
        demo.status.success(),
        "{}",
        String::from_utf8_lossy(&demo.stderr)
    );
    let (scene, shot) = (dir.join("demo_scene.json"), dir.join("demo_shot.json"));
    let render = |name: &str, extra: &[&str]| {
        let file = dir.join(name);
        let (scene, shot, path) = (
            scene.to_string_lossy(),
            shot.to_string_lossy(),
            file.to_string_lossy(),
        );
        let mut args = vec![
            "render",
            &scene,
            &shot,
            "--frames",
            "1001",
            "--quality",
            "draft",
            "-o",
            &path,
        ];
        args.extend(extra);
        (nerfx(&args), file)
    };
    for (passes, want) in [
        ("rgba,depthZ", &["A", "B", "G", "R", "Z"][..]),
        ("accumulation,depthMedian", &["A", "depth.median"][..]),
        ("depthRay", &["depth.ray"][..]),
        ("rgba,accumulation,rgba", &["A", "B", "G", "R"][..]),
    ] {
        let (run, file) = render(
            &format!("{}.exr", passes.replace(',', "_")),
            &["--passes", passes],
        );
        assert!(
            run.status.success(),
            "{passes}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
        assert_eq!(channels(&file), want, "--passes {passes}");
    }
    // An aperture sample count outside 1 to 4096 is refused by its flag, nothing written.
    let (run, file) = render("no_aperture.exr", &["--aperture-samples", "0"]);
    assert!(!run.status.success());
    let said = String::from_utf8_lossy(&run.stderr);
    assert!(
        said.contains("--aperture-samples") && said.contains("1 to 4096"),
        "{said}"
    );
    assert!(!file.exists());
    // A preview needs the colour; nothing is written when it is not asked for.
    let (run, file) = render("depth_only.exr", &["--passes", "depthZ", "--png"]);
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("--png"));
    assert!(!file.exists() && !file.with_extension("png").exists());
    // A graph's nodes choose their own outputs.
    let comp = dir.join("demo_comp.json");
    let run = nerfx(&["render", &comp.to_string_lossy(), "--passes", "rgba"]);
    assert!(!run.status.success());
    let said = String::from_utf8_lossy(&run.stderr);
    assert!(
        said.contains("--passes") && said.contains("choose their own outputs"),
        "{said}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_input_fails_with_a_message_naming_the_file() {
    let dir = scratch_dir("bad");
    let scene = dir.join("scene.json");
    nerfx_core::demo::scene_desc()
        .write(&scene)
        .expect("scene file");
    let corrupt = dir.join("shot.json");
    std::fs::write(&corrupt, "{\"version\": 1, \"frames\": [").expect("write");
    let missing = dir.join("missing.json");
    for (shot, frames) in [(&corrupt, "1"), (&missing, "1")] {
        let run = nerfx(&[
            "render",
            &scene.to_string_lossy(),
            &shot.to_string_lossy(),
            "--frames",
            frames,
        ]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success());
        assert!(stderr.contains(&*shot.to_string_lossy()), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    let frames = nerfx(&[
        "render",
        &scene.to_string_lossy(),
        "x.json",
        "--frames",
        "9-1",
    ]);
    assert!(String::from_utf8_lossy(&frames.stderr).contains("frames '9-1'"));
    std::fs::remove_dir_all(&dir).ok();
}

/// `nerfx bench` on a tiny frame of an analytic and a trained scene: the report has a table
/// per scene with measured errors (the exact reference for the demo, the finer march on
/// sampled rows for the blob), whether Final keeps its error target, the demo's presets
/// marched as well as in closed form, what was compared,
/// heap figures from the binary's counting allocator (not `n/a`), and a plot per scene; the
/// generated snapshot is gone from the output folder.
#[test]
fn bench_reports_errors_heap_and_plots_per_scene() {
    let dir = scratch_dir("bench");
    let run = nerfx(&[
        "bench",
        "-o",
        &dir.to_string_lossy(),
        "--width",
        "48",
        "--height",
        "32",
        "--scene",
        "demo,blob",
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let report = std::fs::read_to_string(dir.join("report.md")).expect("report.md");
    for scene in ["### demo", "### blob"] {
        assert!(report.contains(scene), "{report}");
    }
    assert!(report.contains("every 4th row (8 of 32)"), "{report}");
    assert!(
        report.contains("timed and compared on every 16th row only"),
        "{report}"
    );
    // What "within target" compared: every pixel against the exact integral for the demo; the
    // blob's rows against its quadrature, whose own error is estimated by a tighter one.
    assert!(
        report.contains("Compared: every pixel, against the exact integral."),
        "{report}"
    );
    assert!(
        report.contains("against the quadrature to 2.5e-7"),
        "{report}"
    );
    let header: Vec<&str> = report
        .lines()
        .find(|l| l.starts_with("| configuration |"))
        .expect("a table")
        .split('|')
        .map(str::trim)
        .collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h.starts_with(name))
            .unwrap_or_else(|| panic!("no column {name}: {header:?}"))
    };
    let final_rows: Vec<&str> = report
        .lines()
        .filter(|l| l.starts_with("| final |"))
        .collect();
    assert_eq!(final_rows.len(), 2, "{report}");
    for row in final_rows {
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let psnr: f64 = cells[column("PSNR")].parse().expect("a PSNR");
        assert!(psnr > 40.0, "{row}");
        // Final's target is 1e-3 in alpha and colour (the cells are rounded: a margin).
        let alpha: f64 = cells[column("max alpha")].parse().expect("an error");
        let colour: f64 = cells[column("max colour")].parse().expect("an error");
        let within = cells[column("within target")];
        if alpha.max(colour) > 1.01e-3 {
            assert_eq!(within, "no", "{row}");
        } else if alpha.max(colour) < 0.99e-3 {
            assert_eq!(within, "yes", "{row}");
        }
        let budget: u64 = cells[column("rays at")].parse().expect("a count");
        assert_eq!(budget, 0, "{row}");
        let heap: f64 = cells[column("peak heap")]
            .parse()
            .expect("a measured peak heap");
        assert!(heap > 0.0, "{row}");
    }
    // The demo, integrated in closed form by the presets, is marched with them too, and the
    // marcher keeps the same targets on it.
    let marched: Vec<&str> = report
        .lines()
        .filter(|l| l.contains(" (marched) |"))
        .collect();
    assert_eq!(marched.len(), 3, "{report}");
    for row in marched {
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        assert_eq!(cells[column("within target")], "yes", "{row}");
    }
    for png in ["time_vs_psnr_demo.png", "time_vs_psnr_blob.png"] {
        assert!(dir.join(png).is_file(), "{png}");
    }
    let left: Vec<_> = std::fs::read_dir(&dir)
        .expect("out dir")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("nerfx-bench"))
        .collect();
    assert!(left.is_empty(), "generated files left behind: {left:?}");
    std::fs::remove_dir_all(&dir).ok();
}
