//! Motion blur against Cycles, in every Blender tested (Debian's 3.4, bpy 4.5 and 5.0, see
//! `common_blender`): Blender renders an emissive sphere moving across the frame
//! with motion blur (shutter 0.6 frames, closing at the frame), and exports the shot with the add-on
//! (Blender's shutter, and the frames the shutter reaches). nerfx renders an analytic sphere
//! bound to the same object through that shot, averaging stratified times over the shutter.
//! Cycles' alpha is a Monte Carlo estimate: nerfx must agree with it within a small multiple
//! of how two Cycles renders with different seeds differ, sharp frames must agree exactly, and
//! the blur must be real (far from the sharp render).
//!
//! Every Blender must export the same shot file.

use crate::common_blender;

use std::path::{Path, PathBuf};

use nerfx_core::camera::read_shot;
use nerfx_core::camera::ShutterPosition;
use nerfx_core::render::{Outputs, Quality, RenderSettings};
use nerfx_core::scene::SceneDesc;
use nerfx_core::shot_render::{render_frame, FrameRequest};
use serde_json::Value;

fn rows(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .flat_map(|row| row.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        .collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn mean_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn a_moving_sphere_blurs_as_cycles_blurs_it_in_every_blender() {
    let blenders = common_blender::blenders("blender_motion_blur");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let script = root.join("tests/blender/motion_blur_scene.py");
    let mut failed = Vec::new();
    let mut first_shot: Option<String> = None;
    for blender in &blenders {
        let out = tempfile::tempdir().unwrap();
        blender.run_ok(
            &script,
            &[&root.join("blender"), out.path()],
            "nerfx motion blur: wrote",
        );
        let shot = std::fs::read_to_string(out.path().join("shot.json")).unwrap();
        match &first_shot {
            None => first_shot = Some(shot),
            Some(first) if *first != shot => failed.push(format!(
                "{}: the add-on wrote another shot file than in {}",
                blender.name, blenders[0].name
            )),
            Some(_) => {}
        }
        if let Err(e) = compare(out.path()) {
            failed.push(format!("{}: {e}", blender.name));
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

/// nerfx's render through the shot in `dir` against Cycles' renders there.
fn compare(dir: &Path) -> Result<(), String> {
    let reference: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap())
            .unwrap();
    let shot = read_shot(&dir.join("shot.json"), "Ball").unwrap();
    let blur = shot
        .motion_blur
        .expect("the add-on writes the shot's motion blur");
    assert!((blur.shutter - 0.6).abs() < 1e-6);
    if blur.position != ShutterPosition::End {
        return Err(format!(
            "the shot's shutter position is {:?}, not End",
            blur.position
        ));
    }
    let radius = reference["radius"].as_f64().unwrap();
    let scene = SceneDesc::from_json_str(
        &format!(
            r#"{{"instances": [{{"name": "ball", "object": "Ball", "field": {{"analytic":
            {{"primitives": [{{"shape": {{"sphere": {{"center": [0, 0, 0], "radius": {radius}}}}},
            "density": 5000, "color": {{"rgb": [1, 1, 1]}}}}]}}}}}}]}}"#
        ),
        &dir.join("scene.json"),
    )
    .unwrap()
    .load()
    .unwrap();
    let frame = reference["frame"].as_i64().unwrap();
    let render = |samples: u32| {
        let settings = FrameRequest::new(RenderSettings::new(
            Quality::Final.params(),
            Outputs::rgba(),
        ))
        .with_shutter_samples(samples)
        .unwrap();
        let (planes, _, _) = render_frame(&scene, &shot, frame, &settings, &|_| {}).unwrap();
        planes
            .alpha
            .unwrap()
            .data
            .iter()
            .map(|&a| f64::from(a))
            .collect::<Vec<f64>>()
    };
    let nerfx = render(256);
    let (cycles, again, sharp) = (
        rows(&reference["blurred"]),
        rows(&reference["blurred_again"]),
        rows(&reference["sharp"]),
    );
    assert_eq!(nerfx.len(), cycles.len());
    let noise = mean_abs_diff(&cycles, &again);
    let mean_cycles: Vec<f64> = cycles
        .iter()
        .zip(&again)
        .map(|(a, b)| 0.5 * (a + b))
        .collect();
    let off = mean_abs_diff(&nerfx, &mean_cycles);
    let unblurred = mean_abs_diff(&render(1), &sharp);
    let blur_size = mean_abs_diff(&sharp, &mean_cycles);
    let (off_max, noise_max) = (
        max_abs_diff(&nerfx, &mean_cycles),
        max_abs_diff(&cycles, &again),
    );
    eprintln!(
        "|alpha| difference, mean and max: nerfx vs Cycles {off:.5} {off_max:.4}, Cycles vs \
         Cycles {noise:.5} {noise_max:.4}; sharp nerfx vs sharp Cycles {unblurred:.5}; blurred \
         vs sharp {blur_size:.5}"
    );
    // Measured, mean and max: 7.2e-4 and 0.011 (Blender 3.4), 5.0e-4 and 0.015 (4.5), 5.2e-4
    // and 0.010 (5.0), against 3.1e-4 and 0.012, 3.4e-4 and 0.015, 3.5e-4 and 0.021 between
    // Cycles' seeds. The rest is a shift of the blur by about 0.1 px (0.003 frames: moving
    // nerfx's sphere 0.005 units back gives 5.3e-4), within what one Cycles pixel varies.
    let mut wrong = Vec::new();
    if !(off_max <= 2.0 * noise_max && off <= 3.0 * noise) {
        wrong.push(format!(
            "nerfx is {off} ({off_max} at most) from Cycles, Cycles {noise} ({noise_max}) from \
             itself"
        ));
    }
    if blur_size <= 10.0 * noise {
        wrong.push(format!("the blur is not visible: {blur_size}"));
    }
    if unblurred > noise {
        wrong.push(format!("sharp renders differ by {unblurred}"));
    }
    if wrong.is_empty() {
        Ok(())
    } else {
        Err(wrong.join("; "))
    }
}
