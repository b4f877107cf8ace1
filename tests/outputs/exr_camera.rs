//! The camera in the header of the EXRs `nerfx render` writes, read back by OpenEXR's own
//! library (`tests/openexr/read_header.py`), as a compositor reprojects with it: world points
//! projected with the header's `worldToNDC` land where nerfx renders them (the centre of a
//! small opaque ball placed there), and `worldToCamera` puts them at the depth the `Z` pass
//! holds, in front of the camera (+Z forward, OpenEXR's convention). The frame rate, the
//! chromaticities and the `nerfx/...` entries are there too.
//!
//! Needs `python3` with `numpy` and `OpenEXR` (`scripts/test.sh` installs them).

use std::path::Path;
use std::process::Command;

use glam::DVec3;
use nerfx_core::image::read_exr_channels;

/// The row vector `[p, 1]` times the stored (row-by-row) matrix `m`.
fn times(p: DVec3, m: &[f64]) -> [f64; 4] {
    let v = [p.x, p.y, p.z, 1.0];
    std::array::from_fn(|j| (0..4).map(|i| v[i] * m[4 * i + j]).sum())
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn header_matrices_project_world_points_onto_their_pixels() {
    let (w, h) = (96u32, 64u32);
    let dir = tempfile::tempdir().unwrap();
    // The demo's camera, with a lens shift and an NTSC frame rate.
    let mut shot = nerfx_core::demo::shot(w, h);
    shot.fps_base = 1.001;
    shot.frames.truncate(1);
    shot.frames[0].camera.shift_x = 0.08;
    shot.frames[0].camera.shift_y = -0.05;
    let camera = shot.frames[0].camera(&shot).unwrap();
    // Balls at known raster positions and depths, through the camera's own rays.
    let radius = 0.2;
    let targets = [(20.3, 15.7, 4.0), (70.6, 44.2, 6.0), (47.0, 33.5, 5.0)];
    let centers: Vec<DVec3> = targets
        .iter()
        .map(|&(x, y, depth)| {
            let ray = camera.ray(x, y).unwrap();
            ray.origin + ray.dir * (depth / ray.z_per_t)
        })
        .collect();
    let primitives: Vec<serde_json::Value> = centers
        .iter()
        .map(|c| {
            serde_json::json!({"shape": {"sphere": {"center": [c.x, c.y, c.z], "radius": radius}},
                "density": 1.0e4, "color": {"rgb": [1, 1, 1]}})
        })
        .collect();
    let scene = serde_json::json!({"instances": [{"name": "balls",
        "field": {"analytic": {"primitives": primitives}}}], "colorspace": "acescg"});
    let scene_path = dir.path().join("balls.json");
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let shot_path = dir.path().join("shot.json");
    shot.write(&shot_path).unwrap();
    let exr = dir.path().join("balls.exr");
    let run = Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .args(["render", "--quality", "draft", "-o"])
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

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/openexr/read_header.py");
    let read = Command::new("python3")
        .arg(&script)
        .arg(&exr)
        .output()
        .unwrap_or_else(|e| panic!("this check needs python3 with numpy and OpenEXR ({e})"));
    assert!(
        read.status.success(),
        "OpenEXR's reader failed (it needs python3 with numpy and OpenEXR):\n{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let header: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    let numbers = |key: &str| -> Vec<f64> {
        header[key]
            .as_array()
            .unwrap_or_else(|| panic!("no {key} in the header: {header}"))
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let to_ndc = numbers("worldToNDC");
    let to_camera = numbers("worldToCamera");
    assert_eq!((to_ndc.len(), to_camera.len()), (16, 16));
    assert_eq!(header["framesPerSecond"], serde_json::json!([24000, 1001]));
    assert_eq!(header["nerfx/colorspace"], "ACEScg");
    assert_eq!(header["nerfx/quality"], "draft");
    assert_eq!(header["nerfx/shutterSamples"], "1");
    // No depth of field in the shot: one pinhole per frame, whatever the preset.
    assert_eq!(header["nerfx/apertureSamples"], "1");
    assert!(
        (numbers("chromaticities")[0] - 0.713).abs() < 1e-6,
        "AP1 red x"
    );

    let channels = read_exr_channels(&exr).unwrap();
    let plane = |name: &str| &channels.iter().find(|(n, _)| n == name).unwrap().1;
    let (alpha, depth) = (plane("A"), plane("Z"));
    for (&(x, y, d), &center) in targets.iter().zip(&centers) {
        let ndc = times(center, &to_ndc);
        let (px, py) = (
            ndc[0] / ndc[3] * f64::from(w),
            ndc[1] / ndc[3] * f64::from(h),
        );
        // The ball's image: the alpha-weighted centre of the pixels around the projection.
        let (mut sum, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for j in (py as i64 - 8).max(0)..(py as i64 + 9).min(i64::from(h)) {
            for i in (px as i64 - 8).max(0)..(px as i64 + 9).min(i64::from(w)) {
                let a = f64::from(alpha.get(i as u32, j as u32));
                sum += a;
                sx += a * (i as f64 + 0.5);
                sy += a * (j as f64 + 0.5);
            }
        }
        assert!(
            sum > 10.0,
            "ball at ({x}, {y}): only {sum} pixels of alpha near ({px}, {py})"
        );
        let (cx, cy) = (sx / sum, sy / sum);
        eprintln!(
            "ball at ({x}, {y}): header projects ({px:.3}, {py:.3}), rendered ({cx:.3}, {cy:.3})"
        );
        assert!(
            (px - x).abs() < 1e-3 && (py - y).abs() < 1e-3,
            "projection ({px}, {py})"
        );
        assert!(
            (cx - px).abs() < 0.25 && (cy - py).abs() < 0.25,
            "rendered ({cx}, {cy})"
        );
        // The camera matrix: depth forward, as the Z pass measures it (the ball's near side
        // at its centre pixel).
        let p = times(center, &to_camera);
        assert!((p[2] - d).abs() < 1e-4 && p[3] == 1.0, "camera-space {p:?}");
        let z = f64::from(depth.get(px as u32, py as u32));
        assert!(
            z > d - radius - 1e-3 && z < d,
            "Z {z} for a ball at depth {d}"
        );
    }
}
