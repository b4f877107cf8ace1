//! Depth of field against Cycles, in every Blender tested (Debian's 3.4, bpy 4.5 and 5.0):
//! Blender renders an emissive sphere in front of an emissive wall with depth of field focused
//! on the wall (a focus object), with a round aperture and with a turned, anamorphic
//! five-bladed one, and exports both shots with the add-on. Every Blender must write the same
//! shot files. nerfx renders an analytic sphere and wall of the same colours through each
//! shot, averaging stratified points of the aperture. Cycles' pixels are Monte Carlo
//! estimates: nerfx must agree with them within a small multiple of how two Cycles renders
//! with different seeds differ, sharp renders must agree, and the blur must be real.

use crate::common_blender;

use std::path::PathBuf;

use nerfx_core::camera::read_shot;
use nerfx_core::render::{ColorOutput, Outputs, Quality, RenderSettings};
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

fn mean_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
}

fn mean(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| 0.5 * (x + y)).collect()
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn a_defocused_sphere_blurs_as_cycles_blurs_it_in_every_blender() {
    let blenders = common_blender::blenders("blender_depth_of_field");
    if blenders.is_empty() {
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let script = root.join("tests/blender/depth_of_field_scene.py");
    let addon = root.join("blender");
    let mut failed = Vec::new();
    let mut shots: Option<(String, String)> = None;
    for blender in &blenders {
        let out = tempfile::tempdir().unwrap();
        blender.run_ok(
            &script,
            &[&addon, out.path()],
            "nerfx depth of field: wrote",
        );
        let text = |name: &str| std::fs::read_to_string(out.path().join(name)).unwrap();
        let written = (text("shot.json"), text("shot_polygon.json"));
        match &shots {
            None => shots = Some(written),
            Some(first) if *first != written => failed.push(format!(
                "{}: the add-on wrote other shot files than in {}",
                blender.name, blenders[0].name
            )),
            Some(_) => {}
        }
        let reference: Value = serde_json::from_str(&text("reference.json")).unwrap();
        if let Err(e) = compare(&reference, out.path()) {
            failed.push(format!(
                "{} (Blender {}): {e}",
                blender.name, reference["blender"]
            ));
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

/// nerfx's renders through the shots in `dir` against Cycles' in `reference`.
fn compare(reference: &Value, dir: &std::path::Path) -> Result<(), String> {
    let (ball, wall) = (&reference["ball"], &reference["wall"]);
    let y = wall["y"].as_f64().unwrap();
    let half = wall["half_size"].as_f64().unwrap();
    let scene = SceneDesc::from_json_str(
        &format!(
            r#"{{"instances": [{{"name": "ball", "object": "Ball", "field": {{"analytic":
            {{"primitives": [
              {{"shape": {{"sphere": {{"center": [0, 0, 0], "radius": {r}}}}},
                "density": 5000, "color": {{"rgb": {ball_rgb}}}}},
              {{"shape": {{"box": {{"min": [-{half}, {y}, -{half}], "max": [{half}, {back}, {half}]}}}},
                "density": 5000, "color": {{"rgb": {wall_rgb}}}}}]}}}}}}]}}"#,
            r = ball["radius"],
            ball_rgb = ball["color"],
            wall_rgb = wall["color"],
            back = y + 0.01,
        ),
        &dir.join("scene.json"),
    )
    .unwrap()
    .load()
    .unwrap();
    let frame = reference["frame"].as_i64().unwrap();
    let render = |shot: &str, samples: u32| {
        let shot = read_shot(&dir.join(shot), "Ball").unwrap();
        let settings = RenderSettings {
            color: ColorOutput::AsTrained,
            ..RenderSettings::new(Quality::Final.params(), Outputs::rgba())
        };
        let settings = FrameRequest::new(settings)
            .with_aperture_samples(samples)
            .unwrap();
        let (planes, _, _) = render_frame(&scene, &shot, frame, &settings, &|_| {}).unwrap();
        let rgb = planes.rgb.unwrap();
        let n = rgb[0].data.len();
        (0..n)
            .flat_map(|i| rgb.iter().map(move |p| f64::from(p.data[i])))
            .collect::<Vec<f64>>()
    };
    let (disk, again, polygon, sharp) = (
        rows(&reference["disk"]),
        rows(&reference["disk_again"]),
        rows(&reference["polygon"]),
        rows(&reference["sharp"]),
    );
    let noise = mean_abs_diff(&disk, &again);
    let cycles = mean(&disk, &again);
    let nerfx = render("shot.json", 1024);
    let nerfx_polygon = render("shot_polygon.json", 1024);
    let off = mean_abs_diff(&nerfx, &cycles);
    let off_polygon = mean_abs_diff(&nerfx_polygon, &polygon);
    let unblurred = mean_abs_diff(&render("shot.json", 1), &sharp);
    let blur = mean_abs_diff(&sharp, &cycles);
    let shape = mean_abs_diff(&polygon, &cycles);
    let wrong_shape = mean_abs_diff(&nerfx, &polygon);
    // Where the blur is: the values the defocus changes (the wall elsewhere is exact in both).
    let ring: Vec<usize> = (0..sharp.len())
        .filter(|&i| (sharp[i] - cycles[i]).abs() > 1e-3 || (sharp[i] - polygon[i]).abs() > 1e-3)
        .collect();
    let pick = |v: &[f64]| ring.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let ring_noise = mean_abs_diff(&pick(&disk), &pick(&again));
    let ring_off = mean_abs_diff(&pick(&nerfx), &pick(&cycles));
    let ring_off_polygon = mean_abs_diff(&pick(&nerfx_polygon), &pick(&polygon));
    eprintln!(
        "Blender {}: |RGB| difference, mean: nerfx vs Cycles {off:.5} (round), {off_polygon:.5} \
         (polygon; round nerfx vs polygon Cycles {wrong_shape:.5}); Cycles vs Cycles {noise:.5}; \
         sharp nerfx vs Cycles {unblurred:.5}; blur {blur:.5}; polygon vs round {shape:.5}; \
         in the {} blurred values: nerfx vs Cycles {ring_off:.5} (round), {ring_off_polygon:.5} \
         (polygon), Cycles vs Cycles {ring_noise:.5}",
        reference["blender"],
        ring.len()
    );
    // Measured (bpy 5.0; 3.4 and 4.5 alike): in the blurred values nerfx is 0.0021 (round)
    // and 0.0024 (polygon) from Cycles, whose two seeds differ by 0.0035: a perfect render
    // would be half of that from the mean of the two seeds and 0.71 of it from one, and 256
    // aperture samples instead of 1024 leave 0.0033. The polygon's shape is real: Cycles'
    // round and polygonal renders differ by 11 times the noise, and nerfx's polygon is ten
    // times closer to Cycles' than its disk.
    let mut wrong = Vec::new();
    if ring_off > 0.8 * ring_noise {
        wrong.push(format!(
            "round aperture: nerfx is {ring_off} from Cycles where it blurs, Cycles \
             {ring_noise} from itself"
        ));
    }
    if ring_off_polygon > ring_noise {
        wrong.push(format!(
            "polygonal aperture: nerfx is {ring_off_polygon} from Cycles where it blurs \
             (noise {ring_noise})"
        ));
    }
    if 4.0 * off_polygon >= wrong_shape {
        wrong.push(format!(
            "polygonal aperture: nerfx's polygon ({off_polygon}) is not much closer to Cycles' \
             than its disk ({wrong_shape})"
        ));
    }
    if off > noise {
        wrong.push(format!(
            "nerfx is {off} from Cycles, Cycles {noise} from itself"
        ));
    }
    if blur <= 10.0 * noise {
        wrong.push(format!("the blur is not visible: {blur}"));
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
