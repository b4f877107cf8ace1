//! Rendered splats against an independent NumPy rasteriser (`tests/numpy/splat_reference.py`,
//! written from gsplat's published conventions and Blender's camera facts), on a real trained
//! scene (`tests/data/splat_plane_sh3.ply`: 13 982 splats, SH degree 3) from Blender cameras
//! with shift, pixel aspect on either axis, a portrait vertical fit, and the splats placed by a
//! non-uniformly scaled object transform. Requires colour ≥ 50 dB PSNR and alpha within 1e-3.
//!
//! A cross-check: needs `python3` with `numpy`, and runs with the `cross-checks` feature
//! (`scripts/test.sh`); without it it fails with a message saying so.

use std::path::Path;
use std::process::Command;
use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3};
use nerfx_core::camera::{BlenderIntrinsics, Camera, Perspective, Projection, SensorFit};
use nerfx_core::field::Splats;
use nerfx_core::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{Scene, SplatInstance};
use serde_json::json;

fn ply() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/splat_plane_sh3.ply")
}

fn rows(m: DMat4) -> [[f64; 4]; 4] {
    m.transpose().to_cols_array_2d()
}

struct Case {
    name: &'static str,
    intrinsics: BlenderIntrinsics,
    eye: DVec3,
    world_from_splats: DMat4,
    antialiased: bool,
}

/// The scene's centre (the splats' median, from a NumPy look at the file).
const CENTRE: DVec3 = DVec3::new(0.42, 2.33, 3.13);

fn cases() -> Vec<Case> {
    let small = |w, h| BlenderIntrinsics {
        resolution_x: w,
        resolution_y: h,
        lens: 35.0,
        ..BlenderIntrinsics::default()
    };
    // A non-uniform scale, a turn and a move: the splats end up around the world origin.
    let placed = DMat4::from_scale_rotation_translation(
        DVec3::new(1.3, 0.8, 1.1),
        DQuat::from_euler(glam::EulerRot::ZYX, 0.4, -0.2, 0.3),
        DVec3::new(0.5, -0.3, 0.2),
    ) * DMat4::from_translation(-CENTRE);
    let towards = DVec3::new(-0.79, 0.61, -0.07);
    vec![
        Case {
            name: "plain",
            intrinsics: small(96, 64),
            eye: CENTRE + towards * 1.6,
            world_from_splats: DMat4::IDENTITY,
            antialiased: false,
        },
        Case {
            name: "shift and wide pixels",
            intrinsics: BlenderIntrinsics {
                shift_x: 0.12,
                shift_y: -0.08,
                pixel_aspect_x: 1.6,
                ..small(80, 64)
            },
            eye: CENTRE + DVec3::new(-0.6, 0.9, 0.3) * 1.4,
            world_from_splats: DMat4::IDENTITY,
            antialiased: false,
        },
        Case {
            name: "portrait, vertical fit, tall pixels, antialiased",
            intrinsics: BlenderIntrinsics {
                sensor_fit: SensorFit::Vertical,
                pixel_aspect_y: 1.4,
                shift_y: 0.1,
                ..small(56, 88)
            },
            eye: CENTRE + towards * 1.2 + DVec3::new(0.0, 0.0, 0.5),
            world_from_splats: DMat4::IDENTITY,
            antialiased: true,
        },
        Case {
            name: "scaled object",
            intrinsics: small(96, 64),
            eye: DVec3::new(-1.4, 1.2, 0.6),
            world_from_splats: placed,
            antialiased: false,
        },
    ]
}

fn numpy(job: &serde_json::Value, dir: &Path) -> Vec<f32> {
    let (input, output) = (dir.join("job.json"), dir.join("out.bin"));
    std::fs::write(&input, job.to_string()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/numpy/splat_reference.py");
    let run = Command::new("python3")
        .arg(&script)
        .arg(&input)
        .arg(&output)
        .output()
        .unwrap_or_else(|e| panic!("the NumPy cross-check needs python3 with numpy ({e})"));
    assert!(
        run.status.success(),
        "the NumPy reference failed (it needs numpy):\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let bytes = std::fs::read(&output).unwrap();
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn splats_match_an_independent_numpy_rasteriser() {
    let splats = Arc::new(Splats::load(&ply()).unwrap());
    assert_eq!((splats.len(), splats.dropped), (13_982, 0));
    let dir = tempfile::tempdir().unwrap();
    for case in cases() {
        let world_from_camera =
            nerfx_core::demo::look_at(case.eye, case.world_from_splats.transform_point3(CENTRE));
        let camera = Camera::new(
            world_from_camera,
            Projection::Perspective(Perspective::from_blender(&case.intrinsics).unwrap()),
        )
        .unwrap();
        let scene = Scene::default().with(vec![SplatInstance::new(
            "plane",
            splats.clone(),
            case.world_from_splats,
            None,
            case.antialiased,
        )
        .unwrap()]);
        let b = &case.intrinsics;
        let fit = match b.sensor_fit {
            SensorFit::Auto => "AUTO",
            SensorFit::Horizontal => "HORIZONTAL",
            SensorFit::Vertical => "VERTICAL",
        };
        let job = json!({
            "ply": ply(),
            "world_from_splats": rows(case.world_from_splats),
            "antialiased": case.antialiased,
            "camera": {
                "matrix_world": rows(world_from_camera),
                "lens": b.lens, "sensor_width": b.sensor_width, "sensor_height": b.sensor_height,
                "sensor_fit": fit, "shift_x": b.shift_x, "shift_y": b.shift_y,
                "resolution_x": b.resolution_x, "resolution_y": b.resolution_y,
                "pixel_aspect_x": b.pixel_aspect_x, "pixel_aspect_y": b.pixel_aspect_y,
            },
        });
        let want = numpy(&job, dir.path());
        // With the median depth each pixel composites its list of fragments; without it
        // a tile of splats alone is composited sixteen pixels at once: both are checked.
        let median = [true, false];
        for (outputs, way) in median.map(|m| {
            let outputs = Outputs {
                depth_median: m,
                ..Outputs::all()
            };
            (outputs, if m { "fragment lists" } else { "lanes" })
        }) {
            let mut settings = RenderSettings::new(Quality::Final.params(), outputs);
            settings.color = ColorOutput::AsTrained;
            let planes = render(&scene, &camera, camera.full_window(), &settings).unwrap();
            compare(case.name, way, &planes, &want);
        }
    }
}

/// Checks nerfx's planes against the NumPy rasteriser's pixels (`R G B A Z` each).
fn compare(case: &str, way: &str, planes: &nerfx_core::image::Planes, want: &[f32]) {
    let (w, h) = (planes.width, planes.height);
    assert_eq!(want.len(), (w * h * 5) as usize);
    let (rgb, alpha, depth) = (
        planes.rgb.as_ref().unwrap(),
        planes.alpha.as_ref().unwrap(),
        planes.depth_z.as_ref().unwrap(),
    );
    let (mut sq, mut max_alpha, mut covered, mut max_depth) = (0.0f64, 0.0f32, 0, 0.0f32);
    for y in 0..h {
        for x in 0..w {
            let at = ((y * w + x) * 5) as usize;
            for (c, plane) in rgb.iter().enumerate() {
                sq += f64::from(plane.get(x, y) - want[at + c]).powi(2);
            }
            max_alpha = max_alpha.max((alpha.get(x, y) - want[at + 3]).abs());
            if want[at + 3] > 0.5 {
                covered += 1;
                let rel = (depth.get(x, y) - want[at + 4]).abs() / want[at + 4];
                max_depth = max_depth.max(rel);
            }
        }
    }
    let mse = sq / f64::from(w * h * 3);
    let psnr = -10.0 * mse.max(1e-30).log10();
    println!(
        "{case} ({way}): {w}x{h}, {covered} pixels over half covered: colour PSNR {psnr:.1} dB, alpha max error {max_alpha:.2e}, depth max relative error {max_depth:.2e}"
    );
    assert!(
        covered > (w * h / 10) as usize,
        "{case}: the splats are barely in view ({covered} pixels)"
    );
    assert!(psnr >= 50.0, "{case} ({way}): colour PSNR {psnr:.1} dB");
    assert!(
        max_alpha <= 1e-3,
        "{case} ({way}): alpha max error {max_alpha:.2e}"
    );
    assert!(
        max_depth <= 1e-4,
        "{case} ({way}): depth max relative error {max_depth:.2e}"
    );
}
