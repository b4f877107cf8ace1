//! nerfx against nerfstudio itself: a real nerfacto run (nerfstudio 1.1.5, torch layout) and
//! nerfstudio's own float32 renders of it through a camera path (`tests/data/nerfstudio/`,
//! made by `scripts/nerfstudio/`). The run is sampled by its proposal networks, as
//! nerfstudio samples it; nerfstudio's `rgb` over black is nerfx's premultiplied as-trained
//! colour, its `accumulation` nerfx's alpha, its `expected_depth` nerfx's ray depth.

use std::path::Path;

use crate::common_nerfacto::{copied_nerfstudio_run, nerfstudio_fixture, scratch};
use glam::DVec3;
use nerfx_core::camera::read_shot;
use nerfx_core::field::NerfactoField;
use nerfx_core::render::{sample_proposals, ProposalRay, ProposalScratch};
use nerfx_core::render::{ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::shot_render::{render_frame, FrameRequest};

/// A little-endian float32 `.npy` array, flattened (C order).
fn read_npy(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..6], b"\x93NUMPY", "{}", path.display());
    let header_len = if bytes[6] == 1 {
        u16::from_le_bytes([bytes[8], bytes[9]]) as usize + 10
    } else {
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize + 12
    };
    let header = String::from_utf8_lossy(&bytes[..header_len]);
    assert!(
        header.contains("'<f4'") && header.contains("'fortran_order': False"),
        "{header}"
    );
    bytes[header_len..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

#[test]
fn renders_as_nerfstudio_does() {
    let dir = scratch("nerfstudio-renders");
    let (run, scene) = copied_nerfstudio_run(&dir);
    let shot = read_shot(&nerfstudio_fixture().join("camera_path.json"), "NeRF").unwrap();
    let mut settings = RenderSettings::new(Quality::Final.params(), Outputs::all());
    settings.color = ColorOutput::AsTrained;
    for (k, frame) in shot.frames.iter().enumerate() {
        let request = FrameRequest::new(settings);
        let (planes, _, _) = render_frame(&scene, &shot, frame.frame, &request, &|_| {}).unwrap();
        let ns =
            |name: &str| read_npy(&nerfstudio_fixture().join(format!("render/cam{k}_{name}.npy")));
        let (rgb, acc, depth) = (ns("rgb"), ns("accumulation"), ns("depth_expected"));
        let n = (planes.width * planes.height) as usize;
        assert_eq!((rgb.len(), acc.len(), depth.len()), (3 * n, n, n));
        let ours = planes.rgb.as_ref().unwrap();
        let alpha = planes.alpha.as_ref().unwrap();
        let ray = planes.depth_ray.as_ref().unwrap();
        let (mut sq, mut acc_sum, mut acc_max, mut depth_max, mut covered) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0);
        for i in 0..n {
            for (c, plane) in ours.iter().enumerate() {
                sq += (f64::from(plane.data[i]) - f64::from(rgb[3 * i + c])).powi(2);
            }
            let e = (f64::from(alpha.data[i]) - f64::from(acc[i])).abs();
            acc_sum += e;
            acc_max = acc_max.max(e);
            if acc[i] > 0.5 {
                covered += 1;
                let d = f64::from(depth[i]);
                depth_max = depth_max.max((f64::from(ray.data[i]) - d).abs() / d);
            }
        }
        let psnr = 10.0 * (3.0 * n as f64 / sq.max(1e-30)).log10();
        println!(
            "camera {k}: RGB PSNR {psnr:.1} dB; accumulation within {acc_max:.2e} (mean \
             {:.2e}); expected depth within {depth_max:.2e} relative over {covered} pixels \
             of accumulation > 0.5",
            acc_sum / n as f64
        );
        // Measured: PSNR 102–107 dB (the lightest samples' colour skipped within a budget of
        // 1e-5 per ray), accumulation within 2.7e-4, depth within 3.4e-4 (float32 on both
        // sides); the bounds leave room for other CPUs' rounding.
        assert!(psnr >= 80.0, "camera {k}: PSNR {psnr:.1} dB");
        assert!(acc_max <= 1e-3, "camera {k}: accumulation off by {acc_max}");
        assert!(depth_max <= 1e-3, "camera {k}: depth off by {depth_max}");
        assert!(
            covered > n / 4,
            "camera {k}: too little covered to test depth"
        );
        check_centre_samples(&run, k);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The main field's 48 samples of camera `k`'s centre pixel against nerfstudio's own
/// (`[start, end, weight]` rows), the ray as nerfstudio generated it.
fn check_centre_samples(run: &Path, k: usize) {
    let field = NerfactoField::load(run).unwrap();
    let read =
        |name: &str| read_npy(&nerfstudio_fixture().join(format!("render/cam{k}_{name}.npy")));
    let (ray, want) = (read("centre_ray"), read("centre_samples_2"));
    let v = |i: usize| DVec3::new(ray[i].into(), ray[i + 1].into(), ray[i + 2].into());
    let rays = [ProposalRay {
        origin: v(0),
        dir: v(3).normalize(),
        near: 0.0,
        far: f64::from(field.far_plane()),
    }];
    let mut pieces = Vec::new();
    sample_proposals(&field, &rays, &mut pieces, &mut ProposalScratch::default()).unwrap();
    assert_eq!(pieces.len() * 3, want.len());
    let (mut edge, mut weight, mut t) = (0.0f64, 0.0f64, 1.0f64);
    for (p, w) in pieces.iter().zip(want.chunks_exact(3)) {
        for (a, b) in [(p.t0, w[0]), (p.t1, w[1])] {
            edge = edge.max((a - f64::from(b)).abs() / f64::from(b).max(1e-3));
        }
        let alpha = 1.0 - (-f64::from(p.sigma) * (p.t1 - p.t0)).exp();
        weight = weight.max((t * alpha - f64::from(w[2])).abs());
        t *= 1.0 - alpha;
    }
    println!("camera {k} centre pixel: main samples' edges within {edge:.2e} relative, weights within {weight:.2e}");
    assert!(edge < 1e-4, "camera {k}: sample edges off by {edge}");
    assert!(weight < 1e-4, "camera {k}: weights off by {weight}");
}
