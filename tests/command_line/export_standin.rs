//! Stand-ins: points on the closed-form surface of an analytic field, within the point
//! budget, placed by `world_from_field`; splat stand-ins are the splat means.

use std::path::Path;

use glam::{DMat4, DVec3, Vec3};
use nerfx_core::field::{Analytic, Primitive, ShColor, Shape, Splats};
use nerfx_core::scene::{FieldHandle, Instance, Scene, SceneDesc};
use nerfx_core::standin::{field_points, points, write_ply};

fn sphere(center: Vec3, radius: f32) -> Analytic {
    Analytic {
        primitives: vec![Primitive {
            shape: Shape::Sphere { center, radius },
            density: 50.0,
            color: ShColor::constant(Vec3::new(0.2, 0.5, 0.8)),
        }],
    }
}

#[test]
fn sphere_points_lie_within_two_cells_of_its_surface() {
    let (center, radius) = (Vec3::new(0.1, -0.2, 0.3), 0.7);
    let field = sphere(center, radius);
    let resolution = 64;
    let cell = 2.0 * radius / resolution as f32;
    let pts = field_points(&field, resolution, 0.5);
    assert!(pts.len() > 1000, "{} points", pts.len());
    let worst = pts
        .iter()
        .map(|p| ((p.position - center).length() - radius).abs())
        .fold(0.0f32, f32::max);
    println!(
        "{} points, worst distance to the sphere {worst:.4} (cell {cell:.4})",
        pts.len()
    );
    assert!(worst <= 2.0 * cell, "worst {worst} > {}", 2.0 * cell);
    // Display colour of a linear-light constant: the sRGB encoding of (0.2, 0.5, 0.8).
    let want = [124u8, 188, 231];
    assert!(pts
        .iter()
        .all(|p| p.rgb.iter().zip(want).all(|(a, b)| a.abs_diff(b) <= 1)));
}

#[test]
fn points_are_placed_by_world_from_field_and_respect_the_budget() {
    let (center, radius) = (Vec3::ZERO, 0.5);
    let m = DMat4::from_scale_rotation_translation(
        DVec3::splat(2.0),
        glam::DQuat::from_rotation_z(0.7),
        DVec3::new(1.0, 2.0, 3.0),
    );
    let inst = Instance::new(
        "ball",
        FieldHandle::analytic(sphere(center, radius)),
        m,
        None,
    )
    .expect("a valid placement");
    let scene = Scene::new(vec![inst]);
    let pts = points(&scene, 48, 0.5, 500);
    assert_eq!(pts.len(), 500);
    let cell = 2.0 * radius / 48.0;
    for p in pts {
        let r = (p.position.as_dvec3() - DVec3::new(1.0, 2.0, 3.0)).length() / 2.0;
        assert!((r - radius as f64).abs() <= 2.0 * cell as f64, "radius {r}");
    }
}

#[test]
fn splat_standin_is_the_splat_means() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/splat_plane_sh3.ply");
    let splats = Splats::load(&path).expect("the test splats");
    let scene = SceneDesc::for_path(&path)
        .and_then(|d| d.load())
        .and_then(|l| l.place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY)))
        .expect("the splat scene");
    let pts = points(&scene, 64, 0.0, usize::MAX);
    assert_eq!(pts.len(), splats.len());
    for (p, m) in pts.iter().zip(&splats.means) {
        assert_eq!(p.position, *m);
    }
    // The PLY holds what was computed: header, then 15 bytes per point.
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("splat_standin.ply");
    write_ply(&out, &pts).expect("writable temp folder");
    let bytes = std::fs::read(&out).expect("written");
    std::fs::remove_file(&out).expect("removable");
    let header_end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("a header")
        + 11;
    assert_eq!(bytes.len() - header_end, pts.len() * 15);
    let first = &bytes[header_end..header_end + 12];
    let x = f32::from_le_bytes([first[0], first[1], first[2], first[3]]);
    assert_eq!(x, pts[0].position.x);
}

#[test]
fn sphere_mesh_vertices_lie_within_root_three_cells_of_its_surface() {
    let (center, radius) = (Vec3::new(0.1, -0.2, 0.3), 0.7);
    let resolution = 48;
    let cell = 2.0 * radius / resolution as f32;
    let mesh =
        nerfx_core::standin::field_mesh(&sphere(center, radius), DMat4::IDENTITY, resolution, 0.5);
    assert!(
        mesh.triangles.len() > 1000,
        "{} triangles",
        mesh.triangles.len()
    );
    let worst = mesh
        .vertices
        .iter()
        .map(|p| ((p.position - center).length() - radius).abs())
        .fold(0.0f32, f32::max);
    println!(
        "{} vertices, {} triangles, worst distance {worst:.4} (cell {cell:.4})",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    assert!(worst <= 3f32.sqrt() * cell, "worst {worst}");
    let n = mesh.vertices.len() as u32;
    assert!(mesh.triangles.iter().flatten().all(|&i| i < n));
}
