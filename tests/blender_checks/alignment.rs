//! Alignment against Blender itself. Headless Blender builds scenes (an animated, rotated,
//! non-uniformly scaled NeRF object; animated focal length; every sensor fit on landscape,
//! portrait and square images; lens shift; pixel aspect ≠ 1; resolution percentage; an
//! equirectangular panorama), exports them with the add-on in `blender/`, and writes what
//! Blender says: `world_to_camera_view` of world points and Cycles renders of a sphere mesh
//! (alpha, Z). nerfx reads the exported shots and must agree:
//!
//! - projections within 1e-3 px;
//! - alpha silhouettes of the analytic sphere: IoU ≥ 0.99, every differing pixel within 1 px
//!   of Blender's silhouette edge;
//! - depth (nerfx Z vs Blender's Z pass) within 1e-3 relative away from the edge.
//!
//! It runs in every Blender tested (Debian's 3.4, bpy 4.5 and 5.0; see `common_blender`,
//! `NERFX_SKIP_BPY=1` skips the `bpy` runs knowingly), each of which must write the
//! same shot files.

use crate::common_blender;

use std::path::PathBuf;
use std::sync::Arc;

use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::{CameraPath, Projection, Shot};
use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};
use nerfx_core::render::{render, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};
use serde_json::Value;

/// Runs the scene script; returns the reference JSON and the output folder.
fn run_blender(blender: &common_blender::Blender, index: usize) -> (Value, PathBuf) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-blender-{}-{index}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    blender.run_ok(
        &root.join("tests/blender/alignment_scene.py"),
        &[&root.join("blender"), &out],
        "nerfx alignment: wrote",
    );
    let text = std::fs::read_to_string(out.join("reference.json")).unwrap();
    (serde_json::from_str(&text).unwrap(), out)
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn grid(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().unwrap().iter().map(f64s).collect()
}

/// Largest projection error (px) over a case's points, and their number. The case's shot is
/// its shot file, or the add-on's nerfstudio camera path made into one (frames from 1).
fn check_points(case: &Value) -> (f64, usize) {
    let shot = match case.get("camera_path") {
        Some(p) => CameraPath::read(p.as_str().unwrap())
            .unwrap()
            .to_shot(1, "NeRF")
            .unwrap(),
        None => Shot::read(case["shot"].as_str().unwrap()).unwrap(),
    };
    let mut worst: f64 = 0.0;
    let points = case["points"].as_array().unwrap();
    for p in points {
        let frame = shot.frame(p["frame"].as_i64().unwrap()).unwrap();
        let camera = frame.camera(&shot).unwrap();
        // Aligned: the point is in the NeRF object's frame, placed by the shot's `N`.
        let n = frame.object_matrix(&shot.nerf_object).unwrap();
        let local = f64s(&p["local"]);
        let local = DVec3::new(local[0], local[1], local[2]);
        let world = n.transform_point3(local);
        // An instance bound to no object, placed by `W`, sees the same point at `W⁻¹·p`: in a
        // shot file `W` is in Blender's world; a camera path is in the NeRF object's frame.
        let w = DMat4::from_scale_rotation_translation(
            DVec3::new(1.7, 0.6, 1.1),
            glam::DQuat::from_rotation_z(0.4),
            DVec3::new(0.3, -0.2, 0.5),
        );
        let fixed = frame.world_from_scene(&shot).unwrap() * w;
        let local_to_world = match case.get("camera_path") {
            Some(_) => fixed.transform_point3(w.inverse().transform_point3(local)),
            None => fixed.transform_point3(w.inverse().transform_point3(world)),
        };
        assert!(
            (local_to_world - world).length() < 1e-9 * (1.0 + world.length()),
            "{}: a fixed placement lands at {local_to_world}, the bound one at {world}",
            case["name"]
        );
        let in_camera = camera.world_from_camera().inverse().transform_point3(world);
        let Projection::Perspective(persp) = camera.projection() else {
            panic!("{}: not perspective", case["name"])
        };
        let px = persp.project(in_camera).unwrap();
        let (bx, by) = (p["x"].as_f64().unwrap(), p["y"].as_f64().unwrap());
        let err = (px.x - bx).hypot(px.y - by);
        worst = worst.max(err);
        let depth = p["depth"].as_f64().unwrap();
        assert!(
            (-in_camera.z - depth).abs() < 1e-5 * depth,
            "{}: depth {} vs Blender {depth}",
            case["name"],
            -in_camera.z
        );
    }
    (worst, points.len())
}

/// (IoU, largest distance in px of a differing pixel from Blender's edge, largest relative Z
/// error inside, pixels whose Z was compared).
fn check_render(case: &Value, sphere: &Value) -> (f64, u32, f64, u32) {
    let name = case["name"].as_str().unwrap();
    let shot = Shot::read(case["shot"].as_str().unwrap()).unwrap();
    let r = &case["render"];
    let frame = shot.frame(r["frame"].as_i64().unwrap()).unwrap();
    let camera = frame.camera(&shot).unwrap();
    let n = frame.object_matrix(&shot.nerf_object).unwrap();
    let c = f64s(&sphere["center"]);
    let field = Analytic {
        primitives: vec![Primitive {
            shape: Shape::Sphere {
                center: Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32),
                radius: sphere["radius"].as_f64().unwrap() as f32,
            },
            density: 1e5,
            color: ShColor::constant(Vec3::ONE),
        }],
    };
    let instance = Instance::new("NeRF", FieldHandle::new(Arc::new(field)), n, None).unwrap();
    let outputs = Outputs {
        rgb: false,
        alpha: true,
        depth_z: true,
        depth_ray: false,
        depth_median: false,
    };
    let settings = RenderSettings::new(Quality::Final.params(), outputs);
    let planes = render(
        &Scene::new(vec![instance]),
        &camera,
        camera.full_window(),
        &settings,
    )
    .unwrap();
    let (w, h) = (planes.width, planes.height);
    assert_eq!(
        (u64::from(w), u64::from(h)),
        (r["width"].as_u64().unwrap(), r["height"].as_u64().unwrap()),
        "{name}: resolution"
    );
    let (ba, bz) = (grid(&r["alpha"]), grid(&r["z"]));
    let (na, nz) = (planes.alpha.unwrap(), planes.depth_z.unwrap());
    let blender_in = |x: i64, y: i64| -> Option<bool> {
        (x >= 0 && y >= 0 && x < i64::from(w) && y < i64::from(h))
            .then(|| ba[y as usize][x as usize] > 0.5)
    };
    // Blender's edge pixels: inside pixels with an outside 4-neighbour, and vice versa.
    let on_edge = |x: i64, y: i64| -> bool {
        let me = blender_in(x, y);
        [(1, 0), (-1, 0), (0, 1), (0, -1)]
            .iter()
            .any(|(dx, dy)| matches!(blender_in(x + dx, y + dy), Some(o) if Some(o) != me))
    };
    let near_edge = |x: i64, y: i64, r: i64| -> bool {
        (-r..=r).any(|dy| (-r..=r).any(|dx| on_edge(x + dx, y + dy)))
    };
    let (mut inter, mut union, mut worst_edge, mut worst_z) = (0u64, 0u64, 0u32, 0f64);
    let mut z_pixels = 0u32;
    for y in 0..h {
        for x in 0..w {
            let b = ba[y as usize][x as usize] > 0.5;
            let ours = na.get(x, y) > 0.5;
            inter += u64::from(b && ours);
            union += u64::from(b || ours);
            let (xi, yi) = (i64::from(x), i64::from(y));
            if b != ours {
                let d = (0..=4).find(|&r| near_edge(xi, yi, r)).unwrap_or(99);
                worst_edge = worst_edge.max(d as u32);
            }
            if b && ours && !near_edge(xi, yi, 1) {
                z_pixels += 1;
                let zb = bz[y as usize][x as usize];
                let zn = f64::from(nz.get(x, y));
                worst_z = worst_z.max((zn - zb).abs() / zb);
            }
        }
    }
    assert!(union > 20, "{name}: the sphere is not in view");
    (inter as f64 / union as f64, worst_edge, worst_z, z_pixels)
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn nerfx_agrees_with_blender_projections_silhouettes_and_depth_in_every_blender() {
    let blenders = common_blender::blenders("blender_alignment");
    let mut first: Option<(String, Vec<(String, String)>)> = None;
    for (index, blender) in blenders.iter().enumerate() {
        let (reference, out) = run_blender(blender, index);
        check_reference(&reference);
        let shots = shot_texts(&reference);
        match &first {
            None => first = Some((blender.name.clone(), shots)),
            Some((name, texts)) => assert!(
                *texts == shots,
                "{}: the add-on wrote other shot files than in {name}",
                blender.name
            ),
        }
        std::fs::remove_dir_all(out).unwrap();
    }
}

/// The text of every shot file and camera path a reference names, by case.
fn shot_texts(reference: &Value) -> Vec<(String, String)> {
    reference["cases"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|case| {
            let path = case.get("shot").or_else(|| case.get("camera_path"))?;
            let name = case["name"].as_str().unwrap().to_string();
            Some((
                name,
                std::fs::read_to_string(path.as_str().unwrap()).unwrap(),
            ))
        })
        .collect()
}

/// Every case of one Blender's reference.
fn check_reference(reference: &Value) {
    eprintln!("Blender {}", reference["blender"]);
    let (mut worst_px, mut n_points, mut renders) = (0f64, 0usize, 0);
    for case in reference["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        if case.get("points").is_some() {
            let (err, n) = check_points(case);
            eprintln!("{name}: {n} points, max error {err:.2e} px");
            assert!(err < 1e-3, "{name}: projection error {err} px");
            worst_px = worst_px.max(err);
            n_points += n;
        } else {
            let (iou, edge, z, z_pixels) = check_render(case, &reference["sphere"]);
            eprintln!("{name}: IoU {iou:.4}, differing pixels within {edge} px of the edge, Z rel error {z:.2e} over {z_pixels} pixels");
            assert!(iou >= 0.99, "{name}: IoU {iou}");
            assert!(
                edge <= 1,
                "{name}: a differing pixel is {edge} px from the edge"
            );
            assert!(z <= 1e-3, "{name}: depth relative error {z}");
            assert!(
                z_pixels >= 10,
                "{name}: only {z_pixels} pixels to compare depth on"
            );
            renders += 1;
        }
    }
    eprintln!("{n_points} points, max {worst_px:.2e} px; {renders} renders");
    assert!(n_points >= 300 && renders >= 4);
}
