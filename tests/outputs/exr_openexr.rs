//! nerfx's EXR output read back by OpenEXR's own library (its Python bindings,
//! `tests/openexr/read_channels.py`), not by the crate that wrote it: a render with every
//! plane plus a layer under a name, every channel bit for bit (a depth where nothing was hit
//! as Blender's background value, 10¹⁰), the compression and the pixel aspect from the
//! header.
//!
//! Needs `python3` with `numpy` and `OpenEXR` (`scripts/test.sh` installs them); without them
//! it fails with a message saying so.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use nerfx_core::image::{write_exr_layers, ExrHeader, Plane, Planes, BACKGROUND_DEPTH};
use nerfx_core::render::{render, Outputs, Quality, RenderSettings};

/// The channels a file of `main` with `layers` holds, each with the plane it was written from
/// and whether it is a depth.
fn expected<'a>(main: &'a Planes, layers: &[(&str, &'a Planes)]) -> Vec<(String, &'a Plane, bool)> {
    let of = |prefix: &str, p: &'a Planes| {
        let [r, g, b] = p.rgb.as_ref().expect("a render with colour");
        let depth = |d: &'a Option<Plane>| d.as_ref().expect("a render with every depth");
        [
            ("R", r, false),
            ("G", g, false),
            ("B", b, false),
            ("A", p.alpha.as_ref().expect("a render with alpha"), false),
            ("Z", depth(&p.depth_z), true),
            ("depth.ray", depth(&p.depth_ray), true),
            ("depth.median", depth(&p.depth_median), true),
        ]
        .map(|(name, plane, is_depth)| (format!("{prefix}{name}"), plane, is_depth))
    };
    let mut all = of("", main).to_vec();
    for (name, planes) in layers {
        all.extend(of(&format!("{name}."), planes));
    }
    all
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn openexr_reads_every_channel_bit_for_bit() {
    let (scene, camera) = nerfx_core::demo::scene_and_camera(64, 36).unwrap();
    let settings = RenderSettings::new(Quality::Draft.params(), Outputs::all());
    let main = render(&scene, &camera, camera.full_window(), &settings).unwrap();
    // Another image under a name: every value moved, so that a channel read from the wrong
    // layer differs.
    let moved = |p: &Option<Plane>| {
        p.as_ref().map(|p| Plane {
            data: p.data.iter().map(|v| 0.5 * v + 0.25).collect(),
            ..p.clone()
        })
    };
    let layer = Planes {
        rgb: main
            .rgb
            .as_ref()
            .map(|rgb| rgb.each_ref().map(|c| moved(&Some(c.clone())).unwrap())),
        alpha: moved(&main.alpha),
        depth_z: moved(&main.depth_z),
        depth_ray: moved(&main.depth_ray),
        depth_median: moved(&main.depth_median),
        ..main.clone()
    };
    assert!(
        main.depth_z
            .as_ref()
            .is_some_and(|z| z.data.iter().any(|d| d.is_infinite())),
        "the frame has background, where depth is written as 1e10"
    );

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("frame.exr");
    let layers = [("object", &layer)];
    let header = ExrHeader {
        pixel_aspect: 2.0,
        ..ExrHeader::default()
    };
    write_exr_layers(&file, &main, &layers, &header).unwrap();
    let read = dir.path().join("read");
    std::fs::create_dir(&read).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/openexr/read_channels.py");
    let run = Command::new("python3")
        .arg(&script)
        .arg(&file)
        .arg(&read)
        .output()
        .unwrap_or_else(|e| panic!("this check needs python3 with numpy and OpenEXR ({e})"));
    assert!(
        run.status.success(),
        "OpenEXR's reader failed (it needs python3 with numpy and OpenEXR):\n{}",
        String::from_utf8_lossy(&run.stderr)
    );

    let header: serde_json::Value =
        serde_json::from_slice(&std::fs::read(read.join("header.json")).unwrap()).unwrap();
    assert_eq!(header["compression"], "ZIP_COMPRESSION");
    assert_eq!(
        (header["width"].as_u64(), header["height"].as_u64()),
        (Some(64), Some(36))
    );
    assert_eq!(header["pixel_aspect"].as_f64(), Some(2.0));
    let types: BTreeMap<String, String> = header["channels"]
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
    let want = expected(&main, &layers);
    assert_eq!(
        types.keys().collect::<BTreeSet<_>>(),
        want.iter().map(|(n, ..)| n).collect::<BTreeSet<_>>(),
        "channel names"
    );
    for (name, plane, is_depth) in want {
        assert_eq!(types[&name], "float32", "{name}: sample type");
        let bytes = std::fs::read(read.join(format!("{name}.f32"))).unwrap();
        let got: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(got.len(), plane.data.len(), "{name}: samples");
        for (i, (got, &value)) in got.iter().zip(&plane.data).enumerate() {
            let value = if is_depth && value.is_infinite() {
                BACKGROUND_DEPTH
            } else {
                value
            };
            assert_eq!(got.to_bits(), value.to_bits(), "{name}: sample {i}");
        }
    }
}
