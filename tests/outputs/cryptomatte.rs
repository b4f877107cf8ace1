//! `nerfx render --cryptomatte`, read back by a decoder written from the Cryptomatte
//! specification (`tests/cryptomatte/decode.py`: OpenEXR's own reader, Python's mmh3): the
//! header and manifest are the specification's, every ID is an instance's, ranks come in
//! order of coverage, a pixel's coverages add up to its alpha, and where one instance alone
//! is seen its coverage is the alpha. Four instances: two overlapping fogs, so coverage is
//! shared, and more than one render of indicator colours (three instances each).
//!
//! Needs `python3` with `numpy`, `OpenEXR` and `mmh3` (`scripts/test.sh` installs them).

use crate::{common_ingp, common_ofx};

use std::path::Path;
use std::process::Command;

use nerfx_core::image::read_exr_channels;

/// The decoder's reading of the layer `CryptoObject` of `exr`, checked error-free: the names
/// of its manifest and each name's coverage per pixel.
fn decode(exr: &Path) -> (Vec<String>, std::collections::BTreeMap<String, Vec<f64>>) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cryptomatte/decode.py");
    let read = Command::new("python3")
        .arg(&script)
        .arg(exr)
        .arg("CryptoObject")
        .output()
        .unwrap_or_else(|e| panic!("this check needs python3 with OpenEXR and mmh3 ({e})"));
    assert!(
        read.status.success(),
        "the decoder failed (it needs python3 with numpy, OpenEXR and mmh3):\n{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let decoded: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    assert_eq!(
        decoded["errors"],
        serde_json::json!([]),
        "{}",
        decoded["errors"]
    );
    let names = decoded["names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap().to_string())
        .collect();
    let coverage = decoded["coverage"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(n, c)| {
            let c = c.as_array().unwrap().iter().map(|v| v.as_f64().unwrap());
            (n.clone(), c.collect())
        })
        .collect();
    (names, coverage)
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn mattes_decode_per_the_specification_and_add_up_to_alpha() {
    let (w, h) = (96u32, 64u32);
    let dir = tempfile::tempdir().unwrap();
    let mut shot = nerfx_core::demo::shot(w, h);
    shot.frames.truncate(1);
    let camera = shot.frames[0].camera(&shot).unwrap();
    let at = |x: f64, y: f64, depth: f64| {
        let ray = camera.ray(x, y).unwrap();
        let p = ray.origin + ray.dir * (depth / ray.z_per_t);
        [p.x, p.y, p.z]
    };
    let instance = |name: &str, shape: serde_json::Value, density: f64| {
        serde_json::json!({"name": name, "field": {"analytic": {"primitives": [
            {"shape": shape, "density": density, "color": {"rgb": [0.8, 0.5, 0.2]}}]}}})
    };
    let scene = serde_json::json!({"instances": [
        instance("solo", serde_json::json!({"sphere": {"center": at(10.0, 9.0, 5.0), "radius": 0.3}}), 40.0),
        instance("fog.a", serde_json::json!({"gaussian": {"center": at(48.0, 34.0, 6.0), "sigma": 0.45, "cutoff": 2.5}}), 3.0),
        instance("fog.b", serde_json::json!({"gaussian": {"center": at(56.0, 36.0, 5.5), "sigma": 0.4, "cutoff": 2.5}}), 3.0),
        instance("cube", serde_json::json!({"sphere": {"center": at(84.0, 52.0, 7.0), "radius": 0.4}}), 200.0),
    ]});
    let scene_path = dir.path().join("scene.json");
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let shot_path = dir.path().join("shot.json");
    shot.write(&shot_path).unwrap();
    let exr = dir.path().join("mattes.exr");
    let run = Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .args(["render", "--quality", "preview", "--cryptomatte", "-o"])
        .arg(&exr)
        .arg(&scene_path)
        .arg(&shot_path)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );

    let (manifest, decoded) = decode(&exr);
    assert_eq!(manifest, ["cube", "fog.a", "fog.b", "solo"]);
    let coverage = |name: &str| -> Vec<f64> { decoded[name].clone() };
    let names = ["solo", "fog.a", "fog.b", "cube"];
    let all: Vec<Vec<f64>> = names.iter().map(|n| coverage(n)).collect();
    let channels = read_exr_channels(&exr).unwrap();
    let alpha = &channels.iter().find(|(n, _)| n == "A").unwrap().1.data;
    let (mut worst, mut shared, mut solo) = (0.0f64, 0, 0);
    for (p, &a) in alpha.iter().enumerate() {
        let sum: f64 = all.iter().map(|c| c[p]).sum();
        worst = worst.max((sum - f64::from(a)).abs());
        if all[1][p] > 0.05 && all[2][p] > 0.05 {
            shared += 1;
        }
        // The sphere on its own: its coverage is the alpha.
        if all[0][p] > 0.0 && all[1..].iter().all(|c| c[p] == 0.0) {
            solo += 1;
            assert!(
                (all[0][p] - f64::from(a)).abs() < 1e-5,
                "pixel {p}: coverage {} alpha {a}",
                all[0][p]
            );
        }
    }
    eprintln!("coverage sums to alpha within {worst:.2e}; {shared} pixels share the fogs");
    assert!(worst < 1e-4, "coverage sums differ from alpha by {worst}");
    assert!(shared > 20, "the fogs overlap: {shared} pixels hold both");
    assert!(solo > 20, "the sphere is seen alone: {solo} pixels");
    for (name, c) in names.iter().zip(&all) {
        assert!(
            c.iter().cloned().fold(0.0, f64::max) > 0.2,
            "{name} is seen"
        );
    }
}

/// The marcher's path (a trained field, splats and an analytic ball marched jointly, in one
/// render of indicator colours), and instant-ngp's own marcher's fragments: each instance's
/// coverage channel adds up to the alpha of the scene's own render, within the preset's
/// error target, and each instance is seen.
#[test]
fn coverage_of_a_trained_field_splats_and_a_ball_adds_up_to_alpha() {
    use nerfx_core::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
    use nerfx_core::scene::SceneDesc;
    use nerfx_testkit::bench::snapshot::Weights;
    let dir = tempfile::tempdir().unwrap();
    let fog = common_ingp::write_snapshot(
        dir.path(),
        "fog.ingp",
        &common_ingp::Spec {
            weights: Weights::Uniform { std: 0.01 },
            ..common_ingp::Spec::small_8x4()
        },
    );
    let splats = nerfx_testkit::bench::splats::generated_splats(3000);
    let camera = nerfx_testkit::bench::splats::framing_camera(&splats, 64, 40).unwrap();
    let ply = dir.path().join("splats.ply");
    splats.write_ply(&ply).unwrap();
    // The snapshot marched by nerfx's marcher, then by instant-ngp's own (fragments).
    for sampler in ["occupancy", "ngp"] {
        let scene = serde_json::json!({"instances": [
        {"name": "fog", "field": {"ingp": {"path": fog, "sampler": sampler}}},
        {"name": "splats", "field": {"splats": {"path": ply}}},
        {"name": "ball", "field": {"analytic": {"primitives": [{"shape": {"sphere":
            {"center": [0.3, 0.0, 0.2], "radius": 0.25}}, "density": 30.0,
            "color": {"rgb": [1, 1, 1]}}]}}}]});
        let path = dir.path().join("scene.json");
        std::fs::write(&path, scene.to_string()).unwrap();
        let loaded = SceneDesc::read(&path).unwrap().load().unwrap();
        let settings = RenderSettings {
            color: ColorOutput::AsTrained,
            ..RenderSettings::new(Quality::Preview.params(), Outputs::rgba())
        };
        let identity = glam::DMat4::IDENTITY;
        let place =
            |s: &nerfx_core::scene::LoadedScene| s.place(identity, &|_| Ok(identity)).unwrap();
        let window = camera.full_window();
        let plain = render(&place(&loaded), &camera, window, &settings).unwrap();
        let lit = loaded.with_indicator_colours(&glam::Vec3::AXES).unwrap();
        let coverage = render(&place(&lit), &camera, window, &settings).unwrap();
        let alpha = &plain.alpha.unwrap().data;
        let [a, b, c] = coverage.rgb.as_ref().unwrap();
        let mut worst = 0.0f32;
        for (p, &want) in alpha.iter().enumerate() {
            worst = worst.max((a.data[p] + b.data[p] + c.data[p] - want).abs());
        }
        let seen = |p: &nerfx_core::image::Plane| p.data.iter().cloned().fold(0.0, f32::max);
        eprintln!(
            "{sampler}: coverage sums to alpha within {worst:.2e}; most of fog {:.3}, splats \
         {:.3}, ball {:.3}",
            seen(a),
            seen(b),
            seen(c)
        );
        assert!(
            worst <= Quality::Preview.params().error_target,
            "{sampler}: {worst}"
        );
        assert!(
            seen(a) > 0.05 && seen(b) > 0.05 && seen(c) > 0.05,
            "{sampler}"
        );
    }
}

/// A graph comp of two NeRF Render nodes, each of its own scene, with mattes for both: one
/// manifest of every instance, an instance named in both scenes one object, and each
/// pixel's coverages adding up to the two renders' own alphas (written as layers, so read
/// back from the same file), whatever the comp did with them. A graph naming a node that
/// is not a NeRF Render for its mattes is refused, naming the key.
#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn a_graph_mattes_the_instances_of_the_renders_it_names() {
    let (w, h) = (48u32, 32u32);
    let dir = tempfile::tempdir().unwrap();
    let mut shot = nerfx_core::demo::shot(w, h);
    shot.frames.truncate(1);
    let frame = shot.frames[0].frame;
    let camera = shot.frames[0].camera(&shot).unwrap();
    let at = |x: f64, y: f64, depth: f64| {
        let ray = camera.ray(x, y).unwrap();
        let p = ray.origin + ray.dir * (depth / ray.z_per_t);
        [p.x, p.y, p.z]
    };
    let ball = |name: &str, x: f64, y: f64, depth: f64, radius: f64, density: f64| {
        serde_json::json!({"name": name, "field": {"analytic": {"primitives": [
            {"shape": {"sphere": {"center": at(x, y, depth), "radius": radius}},
             "density": density, "color": {"rgb": [0.8, 0.5, 0.2]}}]}}})
    };
    let front = serde_json::json!({"instances": [
        ball("solo", 8.0, 8.0, 5.0, 0.4, 40.0),
        ball("haze", 26.0, 18.0, 6.0, 0.5, 2.0),
    ]});
    let back = serde_json::json!({"instances": [
        ball("wall", 30.0, 18.0, 9.0, 0.9, 3.0),
        ball("haze", 38.0, 24.0, 8.0, 0.5, 2.0),
    ]});
    std::fs::write(dir.path().join("front.json"), front.to_string()).unwrap();
    std::fs::write(dir.path().join("back.json"), back.to_string()).unwrap();
    shot.write(dir.path().join("shot.json")).unwrap();
    let render = |name: &str, file: &str| {
        serde_json::json!({"name": name, "node": "org.nerfx.NeRFRender",
            "params": {"file": file, "shot": "shot.json", "quality": "preview"}})
    };
    let graph = |mattes: serde_json::Value| {
        serde_json::json!({"nodes": [
            render("front", "front.json"),
            render("back", "back.json"),
            {"name": "comp", "node": "org.nerfx.ShadowCatcherMerge",
             "inputs": {"A": "front", "B": "back"}}],
         "output": "comp",
         "layers": {"front": "front", "back": "back"},
         "cryptomatte": mattes})
    };
    let path = dir.path().join("comp.json");
    std::fs::write(
        &path,
        graph(serde_json::json!(["front", "back"])).to_string(),
    )
    .unwrap();
    let exr = dir.path().join("comp.exr");
    let run = |graph: &Path| {
        Command::new(env!("CARGO_BIN_EXE_nerfx"))
            .arg("render")
            .arg(graph)
            .args(["--frames", &frame.to_string(), "--bundle"])
            .arg(common_ofx::bundle())
            .arg("-o")
            .arg(&exr)
            .output()
            .unwrap()
    };
    let out = run(&path);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let (names, coverage) = decode(&exr);
    assert_eq!(names, ["haze", "solo", "wall"]);
    let channels = read_exr_channels(&exr).unwrap();
    let plane = |name: &str| {
        let found = channels.iter().find(|(n, _)| n == name);
        found
            .unwrap_or_else(|| panic!("no channel {name}"))
            .1
            .data
            .clone()
    };
    let (front_alpha, back_alpha, comp_alpha) = (plane("front.A"), plane("back.A"), plane("A"));
    let (mut worst, mut both, mut solo) = (0.0f64, 0, 0);
    for p in 0..front_alpha.len() {
        let sum: f64 = names.iter().map(|n| coverage[n][p]).sum();
        let want = f64::from(front_alpha[p]) + f64::from(back_alpha[p]);
        worst = worst.max((sum - want).abs());
        if front_alpha[p] > 0.05 && back_alpha[p] > 0.05 {
            both += 1;
        }
        // Where the front sphere alone is seen, its coverage is the front render's alpha.
        if coverage["solo"][p] > 0.0 && back_alpha[p] == 0.0 && coverage["haze"][p] == 0.0 {
            solo += 1;
            assert!((coverage["solo"][p] - f64::from(front_alpha[p])).abs() < 1e-5);
        }
    }
    eprintln!("coverage sums to the renders' alphas within {worst:.2e}; {both} pixels hold both");
    assert!(
        worst < 1e-4,
        "coverage sums differ from the renders' alphas by {worst}"
    );
    assert!(both > 20, "the renders overlap: {both} pixels");
    assert!(solo > 5, "the sphere is seen alone: {solo} pixels");
    // The comp's alpha (A over B) is not the sum where both are seen: the layers hold the
    // renders' own shares, not the comp's.
    let differs = (0..comp_alpha.len())
        .filter(|&p| {
            (f64::from(comp_alpha[p]) - f64::from(front_alpha[p] + back_alpha[p])).abs() > 1e-3
        })
        .count();
    assert!(differs > 0);

    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, graph(serde_json::json!(["comp"])).to_string()).unwrap();
    let out = run(&bad);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        said.contains("cryptomatte[0]") && said.contains("NeRF Render"),
        "{said}"
    );
}
