//! The real nerfstudio viewer camera paths in `tests/data/` load, their values match the
//! file read by hand, and a frame of an analytic sphere renders from them where a closed-form
//! silhouette and depth say it must.

use std::path::PathBuf;
use std::sync::Arc;

use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::{CameraPath, Eye, PathCameraType};
use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};
use nerfx_core::render::{render, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};

/// `tests/data`: copies of real viewer exports (see `tests/data/README.md`).
fn data(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    assert!(
        dir.is_dir(),
        "test data directory {} is missing: the real nerfstudio camera paths must be there",
        dir.display()
    );
    dir.join(name)
}

#[test]
fn viewer_path_with_keyframes_loads_with_the_values_in_the_file() {
    let p = CameraPath::read(data("viewer_camera_path_keyframes.json")).unwrap();
    assert_eq!(p.camera_type, PathCameraType::Perspective);
    assert_eq!((p.render_width, p.render_height), (1920, 1080));
    assert_eq!(p.frames.len(), 96);
    assert_eq!(p.keyframes.len(), 7);
    assert!(p.is_cycle);
    assert!(p.crop.is_none());
    // 96 frames over 4 s.
    assert_eq!(p.frame_rate(), 24.0);
    // Frame 0: `camera_to_world` entries 3, 7, 11 (row-major) are the position.
    let cam = p.camera(0, Eye::Both).unwrap();
    let pos = cam.world_from_camera().w_axis.truncate();
    let expected = DVec3::new(0.3899983167648309, 0.02394929341971879, 0.08560227602720251);
    assert!((pos - expected).length() < 1e-15, "{pos}");
    // Entries 0, 4, 8 are the camera's X axis.
    let x = cam.world_from_camera().x_axis.truncate();
    assert!((x - DVec3::new(-0.06129325362473053, 0.9981198009558245, 0.0)).length() < 1e-7);
    // Keyframe 0 (a column-major string) is the same camera as frame 0.
    let k = p.keyframes[0].matrix;
    assert!((k.w_axis.truncate() - expected).length() < 1e-15);
    assert!(k.abs_diff_eq(p.frames[0].camera_to_world, 1e-6));
    // fov 50° at 1080 rows: f = 540/tan(25°) = 1158.0337 px. The ray 100 px right of the centre
    // makes atan(100/f) with the view axis.
    let f = 540.0 / 25f64.to_radians().tan();
    assert!((f - 1158.033737).abs() < 1e-5);
    let axis = cam.ray(960.0, 540.0).unwrap().dir;
    let off = cam.ray(1060.0, 540.0).unwrap().dir;
    assert!((axis.dot(off).acos() - (100.0 / f).atan()).abs() < 1e-12);
    assert!((axis + cam.world_from_camera().z_axis.truncate()).length() < 1e-9);
}

#[test]
fn viewer_path_with_crop_loads() {
    let p = CameraPath::read(data("viewer_camera_path_b.json")).unwrap();
    assert_eq!((p.render_width, p.render_height), (1280, 1280));
    assert_eq!(p.frames.len(), 42);
    assert_eq!(p.frame_rate(), 42.0);
    let crop = p.crop.unwrap();
    assert_eq!(crop.bounds.center, [0.0, 1.100000023841858, 0.0]);
    assert_eq!(
        crop.bounds.scale,
        [2.0, 0.800000011920929, 0.800000011920929]
    );
    assert_eq!(crop.bounds.rotation, [0.0; 3]);
    assert_eq!(crop.bg_color, [0.0; 3]);
    let pos = p.camera(0, Eye::Both).unwrap().world_from_camera().w_axis;
    assert_eq!(
        pos.truncate(),
        DVec3::new(
            -0.204382538795471,
            -0.1349176764488217,
            0.007282187696546426
        )
    );
}

/// Renders an opaque sphere of radius `r` on frame 0's view axis at distance `d`, at a tiny
/// resolution with the path's FOV, and checks the silhouette and the depth on the axis.
fn render_sphere_from(name: &str) {
    let mut p = CameraPath::read(data(name)).unwrap();
    // The real resolution was checked above; keep the aspect, render small.
    let (w, h) = (64u32, (64 * p.render_height / p.render_width).max(1));
    (p.render_width, p.render_height) = (w, h);
    let cam = p.camera(0, Eye::Both).unwrap();
    let c2w = cam.world_from_camera();
    let (d, r) = (1.0, 0.2);
    let center = c2w.w_axis.truncate() - d * c2w.z_axis.truncate();
    let field = Analytic {
        primitives: vec![Primitive {
            shape: Shape::Sphere {
                center: Vec3::ZERO,
                radius: r as f32,
            },
            density: 1e4,
            color: ShColor::constant(Vec3::ONE),
        }],
    };
    let handle = FieldHandle::new(Arc::new(field));
    let instance = Instance::new("sphere", handle, DMat4::from_translation(center), None).unwrap();
    let scene = Scene::new(vec![instance]);
    let settings = RenderSettings::new(Quality::Final.params(), Outputs::all());
    let planes = render(&scene, &cam, cam.full_window(), &settings).unwrap();
    let alpha = planes.alpha.unwrap();
    let z = planes.depth_z.unwrap();
    // Silhouette: the tangent cone's half-angle is asin(r/d); on the axis it spans
    // f·tan(asin(r/d)) pixels with f = (h/2)/tan(fov/2).
    let f = (f64::from(h) / 2.0) / (p.frames[0].fov.to_radians() / 2.0).tan();
    let radius_px = f * (r / d).asin().tan();
    let (cx, cy) = (f64::from(w) / 2.0, f64::from(h) / 2.0);
    for x in 0..w {
        let dx = (f64::from(x) + 0.5 - cx).abs();
        let a = alpha.get(x, h / 2);
        // Pixel row centre is 0.5 px off the axis for even heights; stay 1 px off the edge.
        if dx < radius_px - 1.0 {
            assert!(
                a > 0.99,
                "{name}: pixel {x} inside the silhouette has alpha {a}"
            );
        } else if dx > radius_px + 1.0 {
            assert!(
                a < 0.01,
                "{name}: pixel {x} outside the silhouette has alpha {a}"
            );
        }
    }
    // Depth at the centre: the front of the sphere, camera Z = d − r (to the ray's slant).
    let zc = f64::from(z.get(w / 2, h / 2));
    let px = DVec3::new(0.5 / f, -0.5 / f, -1.0).normalize();
    // Planar depth of the front surface point on the ray through the pixel (w/2 + 0.5).
    let b = px.dot(-d * DVec3::Z);
    let t = b - (b * b - (d * d - r * r)).sqrt();
    let expected = t * -px.z;
    assert!(
        (zc - expected).abs() < 1e-3 * expected,
        "{name}: Z {zc} vs {expected} (cy {cy})"
    );
}

#[test]
fn a_frame_of_an_analytic_sphere_renders_from_each_real_path() {
    render_sphere_from("viewer_camera_path_keyframes.json");
    render_sphere_from("viewer_camera_path_b.json");
}

/// What the nerfstudio Blender add-on writes for a scaled, turned and moved NeRF object `N`:
/// every camera as `N⁻¹·C` (its columns 0.735 long). A sphere bound to the NeRF object, placed
/// in the field's frame where the Blender camera sees a point 1.2 units ahead, must render
/// centred with its Blender-unit size and depth.
#[test]
fn a_path_written_for_a_scaled_object_renders_the_bound_field_in_blender_units() {
    let mut p = CameraPath::read(data("viewer_camera_path_b.json")).unwrap();
    let scale = 0.735;
    let field_from_world = DMat4::from_scale_rotation_translation(
        DVec3::splat(scale),
        glam::DQuat::from_euler(glam::EulerRot::ZYX, 0.7, -0.3, 0.2),
        DVec3::new(0.4, -1.1, 0.25),
    );
    let blender_c0 = p.frames[0].camera_to_world;
    for f in &mut p.frames {
        f.camera_to_world = field_from_world * f.camera_to_world;
    }
    let (w, h) = (48u32, 48u32);
    (p.render_width, p.render_height) = (w, h);
    let dir = tempfile::tempdir().unwrap();
    let path_file = dir.path().join("camera_path.json");
    p.write(&path_file).unwrap();

    // In Blender's world: a sphere of radius 0.2 at distance 1.2 on frame 0's view axis.
    let (d, r) = (1.2, 0.2);
    let centre_world = blender_c0.w_axis.truncate() - d * blender_c0.z_axis.truncate().normalize();
    let centre_field = field_from_world.transform_point3(centre_world);
    let scene_file = dir.path().join("scene.json");
    std::fs::write(
        &scene_file,
        serde_json::json!({"instances": [{"name": "sphere", "object": "NeRF",
            "field": {"analytic": {"primitives": [{
                "shape": {"sphere": {"center": centre_field.to_array(), "radius": r * scale}},
                "density": 1e4, "color": {"rgb": [1, 1, 1]}}]}}}]})
        .to_string(),
    )
    .unwrap();
    let shot = nerfx_core::camera::read_shot(&path_file, "NeRF").unwrap();
    let scene = nerfx_core::scene::SceneDesc::read(&scene_file)
        .unwrap()
        .load()
        .unwrap();
    let settings = RenderSettings::new(Quality::Final.params(), Outputs::all());
    let first = shot.frames[0].frame;
    let request = nerfx_core::shot_render::FrameRequest::new(settings);
    let (planes, _, _) =
        nerfx_core::shot_render::render_frame(&scene, &shot, first, &request, &|_| {}).unwrap();
    let (alpha, z) = (planes.alpha.unwrap(), planes.depth_z.unwrap());
    let f = (f64::from(h) / 2.0) / (p.frames[0].fov.to_radians() / 2.0).tan();
    let radius_px = f * (r / d).asin().tan();
    for x in 0..w {
        let dx = (f64::from(x) + 0.5 - f64::from(w) / 2.0).abs();
        let a = alpha.get(x, h / 2);
        if dx < radius_px - 1.0 {
            assert!(a > 0.99, "pixel {x} inside the silhouette: alpha {a}");
        } else if dx > radius_px + 1.0 {
            assert!(a < 0.01, "pixel {x} outside the silhouette: alpha {a}");
        }
    }
    let zc = f64::from(z.get(w / 2, h / 2));
    assert!(
        (zc - (d - r)).abs() < 0.01,
        "depth Z {zc}, expected about {} Blender units",
        d - r
    );
}

/// A fixed placement in a scene rendered from a camera path is in the path's frame (the
/// field's): it composes with the path's object, so an unbound instance placed by `W` renders
/// exactly what a bound one holding the same shapes carried through `W` renders — a rotated,
/// uniformly scaled sphere and a non-uniformly scaled box — with depth in Blender units.
#[test]
fn an_unbound_instance_composes_with_a_scaled_camera_path() {
    let mut p = CameraPath::read(data("viewer_camera_path_b.json")).unwrap();
    let field_from_world = DMat4::from_scale_rotation_translation(
        DVec3::splat(0.735),
        glam::DQuat::from_euler(glam::EulerRot::ZYX, -0.4, 0.25, 0.6),
        DVec3::new(-0.3, 0.8, 0.1),
    );
    let c0 = p.frames[0].camera_to_world;
    for f in &mut p.frames {
        f.camera_to_world = field_from_world * f.camera_to_world;
    }
    let (w, h) = (40u32, 30u32);
    (p.render_width, p.render_height) = (w, h);
    let dir = tempfile::tempdir().unwrap();
    let path_file = dir.path().join("camera_path.json");
    p.write(&path_file).unwrap();

    // Points ahead of frame 0's camera, in the path's (field) frame.
    let ahead = |d: f64, right: f64| {
        field_from_world.transform_point3(
            c0.w_axis.truncate() - d * c0.z_axis.truncate().normalize()
                + right * c0.x_axis.truncate().normalize(),
        )
    };
    let (sphere_at, box_at) = (ahead(1.5, -0.15), ahead(1.8, 0.25));
    let sphere_w = DMat4::from_scale_rotation_translation(
        DVec3::splat(2.0),
        glam::DQuat::from_rotation_y(0.9),
        DVec3::new(0.2, -0.1, 0.3),
    );
    let box_w = DMat4::from_scale_rotation_translation(
        DVec3::new(2.0, 1.0, 0.5),
        glam::DQuat::IDENTITY,
        DVec3::new(-0.2, 0.1, 0.05),
    );
    let half = DVec3::new(0.06, 0.09, 0.12);
    let shapes = |sphere: DMat4, cube: DMat4, radius: f64| {
        let c = sphere.inverse().transform_point3(sphere_at);
        let (lo, hi) = (
            cube.inverse().transform_point3(box_at - half),
            cube.inverse().transform_point3(box_at + half),
        );
        serde_json::json!([
            {"shape": {"sphere": {"center": c.to_array(), "radius": radius}},
             "density": 1e4, "color": {"rgb": [1, 0.5, 0.2]}},
            {"shape": {"box": {"min": lo.to_array(), "max": hi.to_array()}},
             "density": 1e4, "color": {"rgb": [0.2, 0.5, 1]}}])
    };
    let render_scene = |name: &str, instances: serde_json::Value| {
        let file = dir.path().join(name);
        std::fs::write(
            &file,
            serde_json::json!({ "instances": instances }).to_string(),
        )
        .unwrap();
        let scene = nerfx_core::scene::SceneDesc::read(&file)
            .unwrap()
            .load()
            .unwrap();
        let shot = nerfx_core::camera::read_shot(&path_file, "NeRF").unwrap();
        let settings = RenderSettings::new(Quality::Final.params(), Outputs::all());
        let first = shot.frames[0].frame;
        let request = nerfx_core::shot_render::FrameRequest::new(settings);
        nerfx_core::shot_render::render_frame(&scene, &shot, first, &request, &|_| {})
            .unwrap()
            .0
    };
    let rows = |m: DMat4| m.transpose().to_cols_array_2d();
    let bound = render_scene(
        "bound.json",
        serde_json::json!([{"name": "both", "object": "NeRF",
            "field": {"analytic": {"primitives": shapes(DMat4::IDENTITY, DMat4::IDENTITY, 0.07)}}}]),
    );
    let primitives = shapes(sphere_w, box_w, 0.035);
    let unbound = render_scene(
        "unbound.json",
        serde_json::json!([
            {"name": "sphere", "world_from_field": rows(sphere_w),
             "field": {"analytic": {"primitives": [primitives[0]]}}},
            {"name": "box", "world_from_field": rows(box_w),
             "field": {"analytic": {"primitives": [primitives[1]]}}}]),
    );
    let (a, b) = (bound.alpha.unwrap(), unbound.alpha.unwrap());
    let covered = a.data.iter().filter(|&&v| v > 0.5).count();
    assert!(covered > 30, "both shapes are in view ({covered} pixels)");
    let mean = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .sum::<f32>()
        / a.data.len() as f32;
    assert!(mean < 2e-3, "alpha differs by {mean} on average");
    let (za, zb) = (bound.depth_z.unwrap(), unbound.depth_z.unwrap());
    for i in (0..a.data.len()).filter(|&i| a.data[i] > 0.999 && b.data[i] > 0.999) {
        let (x, y) = (za.data[i], zb.data[i]);
        assert!(
            (x - y).abs() < 1e-3 * x,
            "pixel {i}: depth Z {x} bound, {y} unbound"
        );
        assert!(
            x > 1.2 && x < 2.2,
            "depth {x} is in Blender units (1.5 to 1.8 ahead)"
        );
    }
}
