//! Camera conventions through the public API: world points seen through placed cameras land
//! where independent pinhole / panorama formulas, written out here, say they must.

use glam::{DMat3, DMat4, DQuat, DVec2, DVec3, EulerRot};
use nerfx_core::camera::{
    BlenderIntrinsics, Camera, Equirect, Eye, Ods, Perspective, Projection, SensorFit, Shot,
};

/// A camera placement with a non-trivial rotation and translation.
fn placement() -> DMat4 {
    let rot = DQuat::from_euler(EulerRot::ZYX, 0.4, -0.7, 0.25);
    DMat4::from_rotation_translation(rot, DVec3::new(3.0, -1.5, 2.25))
}

/// Camera-space coordinates of a world point, from the rotation's transpose (not an inverse).
fn to_camera(world_from_camera: DMat4, p: DVec3) -> DVec3 {
    let r = DMat3::from_mat4(world_from_camera);
    r.transpose() * (p - world_from_camera.w_axis.truncate())
}

#[test]
fn world_point_lands_where_the_blender_pinhole_says() {
    // 28 mm on a 36 mm sensor, 1280×720, horizontal fit, shift (0.05, −0.1).
    let b = BlenderIntrinsics {
        lens: 28.0,
        sensor_fit: SensorFit::Horizontal,
        shift_x: 0.05,
        shift_y: -0.1,
        resolution_x: 1280,
        resolution_y: 720,
        ..BlenderIntrinsics::default()
    };
    let m = placement();
    let cam = Camera::new(
        m,
        Projection::Perspective(Perspective::from_blender(&b).unwrap()),
    )
    .unwrap();
    // Focal length in pixels: lens / sensor · width; the shift moves the principal point by
    // shift · width pixels (left for +x: the image slides right over the scene).
    let f_px = 28.0 / 36.0 * 1280.0;
    let (cx, cy) = (640.0 - 0.05 * 1280.0, 360.0 + -0.1 * 1280.0);
    // Points chosen in front of the camera (placed through `m`, checked back through the
    // transpose of its rotation).
    for local in [
        DVec3::new(0.0, 0.0, -2.0),
        DVec3::new(1.0, 0.4, -3.0),
        DVec3::new(-4.0, -1.5, -6.0),
    ] {
        let p_world = m.transform_point3(local);
        let pc = to_camera(m, p_world);
        assert!(pc.z < 0.0, "test point must be in front: {pc:?}");
        let expected = DVec2::new(cx + f_px * pc.x / -pc.z, cy - f_px * pc.y / -pc.z);
        // project() agrees with the formula …
        let Projection::Perspective(persp) = cam.projection() else {
            panic!("not perspective")
        };
        let got = persp
            .project(m.inverse().transform_point3(p_world))
            .unwrap();
        assert!((got - expected).length() < 1e-9, "{got:?} vs {expected:?}");
        // … and the world ray through that pixel passes through the point, with the planar
        // depth `t · z_per_t` equal to the camera-space depth.
        let ray = cam.ray(expected.x, expected.y).unwrap();
        let to_p = p_world - ray.origin;
        assert!((to_p.normalize() - ray.dir).length() < 1e-12);
        let t = to_p.length();
        assert!((t * ray.z_per_t - -pc.z).abs() < 1e-9);
    }
}

#[test]
fn nerfstudio_perspective_matches_its_ray_formula() {
    // nerfstudio: dir = c2w_R · [(x − cx)/fx, −(y − cy)/fy, −1], normalised.
    let (w, h, fov) = (800u32, 600u32, 50.0f64);
    let m = placement();
    let cam = Camera::new(
        m,
        Projection::Perspective(Perspective::from_vertical_fov(w, h, fov).unwrap()),
    )
    .unwrap();
    let f = 300.0 / (25.0f64).to_radians().tan();
    let r = DMat3::from_mat4(m);
    for (x, y) in [(0.5, 0.5), (400.0, 300.0), (799.5, 17.5), (123.25, 598.0)] {
        let d = (r * DVec3::new((x - 400.0) / f, -(y - 300.0) / f, -1.0)).normalize();
        let ray = cam.ray(x, y).unwrap();
        assert!((ray.dir - d).length() < 1e-12, "({x}, {y})");
        assert!((ray.origin - m.w_axis.truncate()).length() < 1e-15);
    }
}

#[test]
fn equirect_follows_the_placed_camera_axes() {
    let m = placement();
    let cam = Camera::new(m, Projection::Equirect(Equirect::new(1000, 500).unwrap())).unwrap();
    let (x_axis, y_axis, z_axis) = (
        m.x_axis.truncate(),
        m.y_axis.truncate(),
        m.z_axis.truncate(),
    );
    let dir = |x: f64, y: f64| cam.ray(x, y).unwrap().dir;
    assert!((dir(500.0, 250.0) - -z_axis).length() < 1e-12); // centre: forward
    assert!((dir(0.0, 250.0) - z_axis).length() < 1e-12); // edges: behind
    assert!((dir(250.0, 250.0) - -x_axis).length() < 1e-12); // left quarter: left
    assert!((dir(750.0, 250.0) - x_axis).length() < 1e-12); // right quarter: right
    assert!((dir(321.0, 0.0) - y_axis).length() < 1e-12); // top row: up
                                                          // A world point at azimuth 30° to the right and elevation 20° lands at
                                                          // x = W/2 + (30/360)·W, y = H/2 − (20/180)·H.
    let (az, el) = (30f64.to_radians(), 20f64.to_radians());
    let local = DVec3::new(az.sin() * el.cos(), el.sin(), -az.cos() * el.cos());
    let ray = cam.ray(500.0 + 1000.0 / 12.0, 250.0 - 500.0 / 9.0).unwrap();
    assert!((ray.dir - DMat3::from_mat4(m) * local).length() < 1e-12);
    assert_eq!(ray.z_per_t, 1.0);
}

#[test]
fn ods_eyes_follow_the_placed_camera() {
    let m = placement();
    let cam = Camera::new(
        m,
        Projection::Ods(Ods::new(400, 200, Eye::Both, 0.064).unwrap()),
    )
    .unwrap();
    assert_eq!(cam.resolution(), (400, 400));
    let centre = m.w_axis.truncate();
    let x_axis = m.x_axis.truncate();
    let left = cam.ray(200.0, 100.0).unwrap();
    let right = cam.ray(200.0, 300.0).unwrap();
    assert!((left.origin - (centre - 0.032 * x_axis)).length() < 1e-12);
    assert!((right.origin - (centre + 0.032 * x_axis)).length() < 1e-12);
    assert!((left.dir - right.dir).length() < 1e-12);
}

#[test]
fn shot_file_on_disk_gives_the_same_camera() {
    // Portrait 1080×1920 at 50 %, AUTO fit, pixel aspect 1×1: the 36 mm width sensor spans
    // the height, so f_px = lens/36 · 960 at the effective 540×960.
    let m = placement();
    let rows = |m: DMat4| format!("{:?}", m.transpose().to_cols_array_2d());
    let text = format!(
        r#"{{"version": 1, "fps": 25, "resolution_x": 1080, "resolution_y": 1920,
            "resolution_percentage": 50, "nerf_object": "NeRF",
            "frames": [{{"frame": 7, "camera": {{"matrix_world": {}, "type": "PERSP",
              "lens": 40, "sensor_width": 36, "sensor_height": 24, "sensor_fit": "AUTO"}},
              "objects": {{"NeRF": {}}}}}]}}"#,
        rows(m),
        rows(DMat4::from_scale(DVec3::splat(2.0)))
    );
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-conventions-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("shot.json");
    std::fs::write(&path, text).unwrap();
    let shot = Shot::read(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let frame = shot.frame(7).unwrap();
    assert_eq!(
        frame.object_matrix("NeRF").unwrap(),
        DMat4::from_scale(DVec3::splat(2.0))
    );
    let cam = frame.camera(&shot).unwrap();
    assert_eq!(cam.resolution(), (540, 960));
    let f_px = 40.0 / 36.0 * 960.0;
    let p_world = m.transform_point3(DVec3::new(-0.5, 0.8, -3.0));
    let pc = to_camera(m, p_world);
    let (x, y) = (270.0 + f_px * pc.x / -pc.z, 480.0 - f_px * pc.y / -pc.z);
    let ray = cam.ray(x, y).unwrap();
    assert!(((p_world - ray.origin).normalize() - ray.dir).length() < 1e-12);
    // Written and read again, the camera is the same to rounding.
    let again_dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-conventions-w-{}", std::process::id()));
    std::fs::create_dir_all(&again_dir).unwrap();
    let again_path = again_dir.join("again.json");
    shot.write(&again_path).unwrap();
    let again = Shot::read(&again_path).unwrap();
    std::fs::remove_dir_all(&again_dir).unwrap();
    let ray2 = again
        .frame(7)
        .unwrap()
        .camera(&again)
        .unwrap()
        .ray(x, y)
        .unwrap();
    assert!((ray2.dir - ray.dir).length() < 1e-14);
}
