//! nerfx's reading of a compact splat file against splat-transform's decoding of it to an
//! INRIA PLY (`NAME.decoded.ply` beside it): the largest differences splat for splat, and
//! the PSNR of the two rendered alike. Shared by `tests/splats/formats.rs` and the whole real
//! captures of `benches/splats.rs`.

use std::path::Path;
use std::sync::Arc;

use glam::{DMat4, Quat, Vec3};
use nerfx_core::field::{Axes, SplatFormat, Splats};
use nerfx_core::image::Planes;
use nerfx_core::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{Scene, SplatInstance};
use nerfx_testkit::bench::splats::framing_camera;

/// The largest differences between two splat sets of one order: means, relative scales,
/// rotations (sign-free), opacities, colour coefficients.
pub fn differences(a: &Splats, b: &Splats) -> [f32; 5] {
    assert_eq!(a.len(), b.len());
    assert_eq!(a.color, b.color);
    let mut d = [0.0f32; 5];
    for i in 0..a.len() {
        d[0] = d[0].max((a.means[i] - b.means[i]).abs().max_element());
        let rel = (a.scales[i] - b.scales[i]).abs() / b.scales[i].abs().max(Vec3::splat(1e-12));
        d[1] = d[1].max(rel.max_element());
        let dot = a.rotations[i].dot(b.rotations[i]).abs();
        d[2] = d[2].max(1.0 - dot.min(1.0));
        d[3] = d[3].max((a.opacities[i] - b.opacities[i]).abs());
    }
    for (x, y) in a.coefficients.iter().zip(&b.coefficients) {
        d[4] = d[4].max((x - y).abs());
    }
    d
}

fn settings() -> RenderSettings {
    let mut s = RenderSettings::new(Quality::Final.params(), Outputs::all());
    s.color = ColorOutput::AsTrained;
    s
}

fn render_splats(splats: &Splats, camera_of: &Splats) -> Planes {
    let camera = framing_camera(camera_of, 192, 128).unwrap();
    let scene = Scene::default().with(vec![SplatInstance::new(
        "splats",
        Arc::new(splats.clone()),
        DMat4::IDENTITY,
        None,
        false,
    )
    .unwrap()]);
    render(&scene, &camera, camera.full_window(), &settings()).unwrap()
}

/// PSNR of premultiplied RGB and alpha together (peak 1), dB.
fn psnr(a: &Planes, b: &Planes) -> f64 {
    let planes = |p: &Planes| {
        let rgb = p.rgb.as_ref().unwrap();
        let alpha = p.alpha.as_ref().unwrap();
        [&rgb[0], &rgb[1], &rgb[2], alpha]
            .map(|plane| plane.data.clone())
            .concat()
    };
    let (x, y) = (planes(a), planes(b));
    let mse = x
        .iter()
        .zip(&y)
        .map(|(p, q)| f64::from(p - q).powi(2))
        .sum::<f64>()
        / x.len() as f64;
    let coverage = y
        .iter()
        .skip(3 * y.len() / 4)
        .filter(|v| **v > 0.05)
        .count();
    assert!(coverage > y.len() / 40, "the render shows almost nothing");
    if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// `name` read by nerfx against splat-transform's decoding `name.decoded.ply` in `dir`:
/// the largest differences and the render's PSNR.
pub fn check_against_decoding(dir: &Path, name: &str, axes: Axes) -> ([f32; 5], f64) {
    let file = dir.join(name);
    let ours = Splats::load(&file).unwrap().into_ply_frame(axes);
    let mut theirs = Splats::load(&dir.join(format!("{name}.decoded.ply"))).unwrap();
    assert_eq!(ours.dropped, 0, "{name}");
    if ours.source.format == SplatFormat::Splat {
        // splat-transform centres rotation bytes at 127.5; antimatter15's viewer, and the
        // viewers after it, at 128: `(q − 128)/128`. Take the rotations from the bytes so.
        let bytes = std::fs::read(&file).unwrap();
        for (i, r) in bytes.chunks_exact(32).enumerate() {
            let q = [28, 29, 30, 31].map(|k| (f32::from(r[k]) - 128.0) / 128.0);
            theirs.rotations[i] = Quat::from_xyzw(q[1], q[2], q[3], q[0]).normalize();
        }
    }
    let d = differences(&ours, &theirs);
    let db = psnr(
        &render_splats(&ours, &theirs),
        &render_splats(&theirs, &theirs),
    );
    println!(
        "{name}: {} splats; means {:.1e}, scales {:.1e} (relative), rotations {:.1e}, \
         opacities {:.1e}, coefficients {:.1e}; render {db:.1} dB",
        ours.len(),
        d[0],
        d[1],
        d[2],
        d[3],
        d[4]
    );
    (d, db)
}

pub fn assert_matches(name: &str, (d, db): ([f32; 5], f64)) {
    // splat-transform computes in f64 and stores f32; the opacity crosses a logit.
    assert!(d[0] <= 1e-5, "{name}: means differ by {}", d[0]);
    assert!(d[1] <= 1e-4, "{name}: scales differ by {}", d[1]);
    assert!(d[2] <= 1e-5, "{name}: rotations differ by {}", d[2]);
    assert!(d[3] <= 1e-5, "{name}: opacities differ by {}", d[3]);
    assert!(d[4] <= 1e-4, "{name}: coefficients differ by {}", d[4]);
    assert!(db >= 60.0, "{name}: {db:.1} dB");
}
