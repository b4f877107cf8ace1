//! nerfx's output colour spaces against OpenColorIO's own built-in CG configuration
//! (`ocio://cg-config-latest`, through its Python package, `tests/ocio/convert.py`): a render
//! written in each space, read back by OpenEXR's own library, must match OpenColorIO's
//! conversion of the linear Rec.709 render to ≥ 60 dB, and carry its primaries in the
//! standard `chromaticities` attribute.
//!
//! Needs `python3` with `numpy`, `OpenEXR` and `opencolorio` (`scripts/test.sh` installs
//! them); without them it fails with a message saying so.

use std::path::Path;
use std::process::Command;

use nerfx_core::image::{write_exr_layers, ExrHeader, OutputColorSpace, Planes};
use nerfx_core::render::{render, Outputs, Quality, RenderSettings};

/// A render with partial coverage and values above 1 (the demo, brightened), as linear
/// Rec.709 RGBA.
fn render_rgba() -> Planes {
    let (scene, camera) = nerfx_core::demo::scene_and_camera(48, 27).unwrap();
    let settings = RenderSettings::new(Quality::Draft.params(), Outputs::rgba());
    let mut planes = render(&scene, &camera, camera.full_window(), &settings).unwrap();
    for c in planes.rgb.as_mut().unwrap() {
        for v in &mut c.data {
            *v *= 3.0;
        }
    }
    let alpha = &planes.alpha.as_ref().unwrap().data;
    assert!(
        alpha.iter().any(|&a| a > 0.01 && a < 0.99),
        "the frame has partly covered pixels"
    );
    planes
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn every_space_matches_opencolorio_and_names_its_primaries() {
    let linear = render_rgba();
    let dir = tempfile::tempdir().unwrap();
    let linear_path = dir.path().join("linear.exr");
    write_exr_layers(&linear_path, &linear, &[], &ExrHeader::default()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ocio/convert.py");
    for space in OutputColorSpace::ALL {
        let mut planes = linear.clone();
        space.convert_planes(&mut planes);
        let path = dir.path().join(format!("{}.exr", space.name()));
        let header = ExrHeader {
            color_space: space,
            ..ExrHeader::default()
        };
        write_exr_layers(&path, &planes, &[], &header).unwrap();
        let run = Command::new("python3")
            .arg(&script)
            .arg(&linear_path)
            .arg(&path)
            .arg(space.ocio_name())
            .output()
            .unwrap_or_else(|e| panic!("this check needs python3 with OpenColorIO ({e})"));
        assert!(
            run.status.success(),
            "OpenColorIO's check failed (it needs python3 with numpy, OpenEXR and \
             opencolorio):\n{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let facts: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
        let psnr = facts["psnr"].as_f64().unwrap();
        eprintln!("{}: {psnr:.1} dB against OpenColorIO", space.name());
        assert!(psnr >= 60.0, "{}: {psnr:.1} dB", space.name());
        let c = space.chromaticities();
        let want = [c.red, c.green, c.blue, c.white].concat();
        let got: Vec<f64> = facts["chromaticities"]
            .as_array()
            .unwrap_or_else(|| panic!("{}: no chromaticities attribute", space.name()))
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(got.len(), 8, "{}", space.name());
        for (g, w) in got.iter().zip(want) {
            assert!(
                (g - w).abs() < 1e-6,
                "{}: chromaticities {got:?}",
                space.name()
            );
        }
    }
}
