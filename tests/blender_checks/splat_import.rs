//! The Blender add-on's splat import: headless Blender imports `tests/data/splat_plane_sh3.ply`
//! through the operator; every vertex must sit on its splat's mean as nerfx reads the file
//! (the frame nerfx renders the splats in) and carry the splat's DC colour, and the object
//! becomes the NeRF object. Every other splat format goes through `nerfx export-standin` (the
//! add-on runs the program): the same holds, colours to 8 bits.
//!
//! It runs in every Blender tested (Debian's 3.4, bpy 4.5 and 5.0; see `common_blender`).

use crate::common_blender;

use std::path::{Path, PathBuf};

use nerfx_core::field::Splats;

/// What each Blender made of importing `file`: its name, the vertex count, the NeRF object
/// and the points (x y z r g b).
fn blender_imports(
    file: &Path,
    executable: Option<&Path>,
) -> Vec<(String, u64, String, Vec<Vec<f64>>)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut all = Vec::new();
    for blender in common_blender::blenders("blender_splat_import") {
        let out = tempfile::tempdir().unwrap();
        let json_path = out.path().join("import.json");
        let addon = root.join("blender");
        let mut args = vec![addon.as_path(), file, json_path.as_path()];
        args.extend(executable);
        let run = blender.run(
            &root.join("tests/blender/splat_import_check.py"),
            &args.iter().map(|a| a.as_os_str()).collect::<Vec<_>>(),
        );
        let text = std::fs::read_to_string(&json_path).unwrap_or_else(|_| {
            panic!(
                "{}: Blender wrote nothing:\n{}\n{}",
                blender.name,
                String::from_utf8_lossy(&run.stdout),
                String::from_utf8_lossy(&run.stderr)
            )
        });
        let got: serde_json::Value = serde_json::from_str(&text).unwrap();
        let points = got["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                p.as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect()
            })
            .collect();
        all.push((
            blender.name.clone(),
            got["vertices"].as_u64().unwrap(),
            got["nerf_object"].as_str().unwrap().to_string(),
            points,
        ));
    }
    all
}

/// The largest position and colour errors of Blender's points against the splats.
fn errors(splats: &Splats, points: &[Vec<f64>]) -> (f64, f64) {
    let stride = splats.color.coefficients() * 3;
    let (mut max_pos, mut max_col) = (0.0f64, 0.0f64);
    for (i, p) in points.iter().enumerate() {
        let mean = splats.means[i].as_dvec3();
        max_pos = max_pos.max((glam::DVec3::new(p[0], p[1], p[2]) - mean).length());
        for c in 0..3 {
            let dc = f64::from(splats.coefficients[i * stride + c]);
            let want = (0.5 + 0.282_094_791_773_878_14 * dc).clamp(0.0, 1.0);
            max_col = max_col.max((p[3 + c] - want).abs());
        }
    }
    (max_pos, max_col)
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn blender_imports_splats_as_points_at_their_means() {
    let ply = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/splat_plane_sh3.ply");
    let splats = Splats::load(&ply).unwrap();
    for (blender, vertices, nerf_object, points) in blender_imports(&ply, None) {
        assert_eq!(vertices, splats.len() as u64, "{blender}");
        assert_eq!(nerf_object, "splat_plane_sh3", "{blender}");
        let (max_pos, max_col) = errors(&splats, &points);
        println!(
            "{blender}: {} points: max position error {max_pos:.2e}, max colour error \
             {max_col:.2e}",
            points.len()
        );
        assert!(max_pos <= 1e-5, "{blender}: position error {max_pos}");
        assert!(max_col <= 1e-6, "{blender}: colour error {max_col}");
    }
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn blender_imports_every_other_format_through_nerfx() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/splats");
    let exe = Path::new(env!("CARGO_BIN_EXE_nerfx"));
    for name in [
        "subset_sh3.compressed.ply",
        "subset_sh3.sog",
        "subset_sh3.spz",
        "sjeongab_512.splat",
    ] {
        let file = data.join(name);
        let splats = Splats::load(&file).unwrap();
        for (blender, vertices, nerf_object, points) in blender_imports(&file, Some(exe)) {
            assert_eq!(vertices, splats.len() as u64, "{blender}: {name}");
            assert_eq!(
                nerf_object,
                name.split('.').next().unwrap(),
                "{blender}: {name}"
            );
            let (max_pos, max_col) = errors(&splats, &points);
            println!(
                "{blender}: {name}: max position error {max_pos:.2e}, max colour error \
                 {max_col:.2e}"
            );
            assert!(
                max_pos <= 1e-5,
                "{blender}: {name}: position error {max_pos}"
            );
            // The stand-in's colours are bytes.
            assert!(
                max_col <= 0.5 / 255.0 + 1e-6,
                "{blender}: {name}: colour error {max_col}"
            );
        }
    }
}
