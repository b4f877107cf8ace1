//! Environment maps against Blender itself: `nerfx envmap` renders an analytic scene of
//! coloured spheres around a point; headless Blender presses the add-on's *Render Environment
//! Map* button (which runs `nerfx envmap` from an empty's position and sets the image as the
//! World's colour), then Cycles renders one pixel along each sphere's direction from that
//! point. Each must see its sphere's colour: the map is oriented as Blender reads it.
//!
//! It runs in every Blender tested (Debian's 3.4, bpy 4.5 and 5.0; see `common_blender`).

use crate::common_blender;

use std::ffi::OsStr;
use std::path::PathBuf;

use glam::DVec3;
use serde_json::{json, Value};

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn blender_sees_each_sphere_where_the_field_has_it_in_every_blender() {
    for blender in common_blender::blenders("blender_environment") {
        check(&blender);
    }
}

/// The check in one Blender.
fn check(blender: &common_blender::Blender) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let out = tempfile::tempdir().unwrap();
    let centre = DVec3::new(1.0, 2.0, 0.5);
    // Primaries and their mixes: every channel 0 or 1, which no transfer curve changes.
    let spheres = [
        (DVec3::new(1.0, 0.0, 0.0), [1.0, 0.0, 0.0]),
        (DVec3::new(0.0, 1.0, 0.0), [0.0, 1.0, 0.0]),
        (DVec3::new(0.0, -1.0, 0.0), [0.0, 0.0, 1.0]),
        (DVec3::new(-1.0, 0.2, 0.3), [1.0, 1.0, 0.0]),
        (DVec3::new(0.5, -0.4, 0.75), [0.0, 1.0, 1.0]),
        (DVec3::new(0.3, 0.6, -0.74), [1.0, 0.0, 1.0]),
    ];
    let primitives: Vec<Value> = spheres
        .iter()
        .map(|(d, rgb)| {
            let c = centre + d.normalize() * 10.0;
            json!({"shape": {"sphere": {"center": [c.x, c.y, c.z], "radius": 1.2}},
                   "density": 200, "color": {"rgb": rgb}})
        })
        .collect();
    let scene = json!({"instances": [{"name": "spheres",
        "field": {"analytic": {"primitives": primitives}}}]});
    let scene_path = out.path().join("scene.json");
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let mut directions: Vec<[f64; 3]> = spheres.iter().map(|(d, _)| d.to_array()).collect();
    // And one direction with nothing in it.
    directions.push([-0.3, -0.9, -0.3]);
    let probes = json!({"position": centre.to_array(), "height": 64, "directions": directions});

    let addon = root.join("blender");
    let probes = probes.to_string();
    blender.run_ok_with(
        &root.join("tests/blender/environment_check.py"),
        &[
            addon.as_os_str(),
            OsStr::new(env!("CARGO_BIN_EXE_nerfx")),
            scene_path.as_os_str(),
            out.path().as_os_str(),
            OsStr::new(&probes),
        ],
        "nerfx environment: wrote",
    );
    let text = std::fs::read_to_string(out.path().join("environment.json")).unwrap();
    let seen: Value = serde_json::from_str(&text).unwrap();
    let colours = seen["colours"].as_array().unwrap();
    let mut want: Vec<[f64; 3]> = spheres.iter().map(|(_, c)| *c).collect();
    want.push([0.0; 3]);
    for (i, (got, want)) in colours.iter().zip(&want).enumerate() {
        let got: Vec<f64> = got
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for c in 0..3 {
            assert!(
                (got[c] - want[c]).abs() < 0.02,
                "{}: direction {:?}: Blender sees {got:?}, the field has {want:?}",
                blender.name,
                directions[i]
            );
        }
    }
    assert_eq!(colours.len(), want.len());
}
