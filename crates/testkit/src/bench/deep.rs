//! What deep output costs: each scene of the suite rendered flat (and written as an EXR) and
//! rendered deep (and both written), at one preset: the deep file's samples per pixel (mean,
//! max), its size against the flat file's, and the time of each, best of `repeats`.

use std::path::Path;
use std::time::Instant;

use crate::bench::scenes::build;
use crate::bench::SceneKind;
use nerfx_core::error::Result;
use nerfx_core::image::{write_deep_exr, write_exr, ExrHeader};
use nerfx_core::render::{
    render_deep, render_with_progress, DeepParams, Outputs, Quality, RenderSettings,
};

/// One scene's flat and deep renders.
#[derive(Clone, Debug, PartialEq)]
pub struct DeepTiming {
    /// The scene.
    pub scene: SceneKind,
    /// Mean samples per pixel of the deep image.
    pub mean_samples: f64,
    /// Most samples a pixel of it holds.
    pub max_samples: usize,
    /// Size of the flat EXR (RGBA and depth Z), bytes.
    pub flat_bytes: u64,
    /// Size of the deep EXR, bytes.
    pub deep_bytes: u64,
    /// Best wall time of rendering and writing the flat EXR, milliseconds.
    pub flat_ms: f64,
    /// Best wall time of rendering both and writing both files, milliseconds.
    pub deep_ms: f64,
}

/// Renders each of `scenes` at `width × height` and `quality` flat and deep (the preset's
/// sample cap), writing the files into `dir`, best of `repeats`.
pub fn time_deep(
    dir: &Path,
    scenes: &[SceneKind],
    (width, height): (u32, u32),
    quality: Quality,
    repeats: u32,
    splats: Option<&Path>,
) -> Result<Vec<DeepTiming>> {
    let params = quality.params();
    let outputs = Outputs {
        depth_ray: false,
        depth_median: false,
        ..Outputs::all()
    };
    let settings = RenderSettings::new(params, outputs);
    let deep = DeepParams {
        max_samples: quality.deep_samples(),
        error_target: params.error_target,
    };
    let mut timings = Vec::new();
    for &kind in scenes {
        let b = build(kind, width, height, dir, splats)?;
        let window = b.camera.full_window();
        let (flat_file, deep_file) = (
            dir.join(format!("deep_bench_{}.flat.exr", kind.name())),
            dir.join(format!("deep_bench_{}.deep.exr", kind.name())),
        );
        let (mut flat_ms, mut deep_ms) = (f64::INFINITY, f64::INFINITY);
        let mut counts = (0, 0.0);
        for _ in 0..repeats.max(1) {
            let started = Instant::now();
            let (planes, _) =
                render_with_progress(&b.scene, &b.camera, window, &settings, &|_| {})?;
            write_exr(&flat_file, &planes)?;
            flat_ms = flat_ms.min(started.elapsed().as_secs_f64() * 1e3);
            let started = Instant::now();
            let (planes, image, _) =
                render_deep(&b.scene, &b.camera, window, &settings, &deep, &|_| {})?;
            write_exr(&flat_file, &planes)?;
            write_deep_exr(&deep_file, &image, &ExrHeader::default())?;
            deep_ms = deep_ms.min(started.elapsed().as_secs_f64() * 1e3);
            counts = image.sample_counts();
        }
        let size = |p: &Path| std::fs::metadata(p).map_or(0, |m| m.len());
        timings.push(DeepTiming {
            scene: kind,
            mean_samples: counts.1,
            max_samples: counts.0,
            flat_bytes: size(&flat_file),
            deep_bytes: size(&deep_file),
            flat_ms,
            deep_ms,
        });
    }
    Ok(timings)
}

/// The timings as a Markdown table.
pub fn table(timings: &[DeepTiming], quality: Quality, (width, height): (u32, u32)) -> String {
    let mut out = format!(
        "| scene ({}, {width}×{height}, cap {}) | samples/px mean | max | flat KB | deep KB | flat ms | deep ms (both files) | × flat |\n",
        quality.name(),
        quality.deep_samples()
    );
    out.push_str("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for t in timings {
        out.push_str(&format!(
            "| {} | {:.2} | {} | {:.0} | {:.0} | {:.0} | {:.0} | {:.2} |\n",
            t.scene.name(),
            t.mean_samples,
            t.max_samples,
            t.flat_bytes as f64 / 1e3,
            t.deep_bytes as f64 / 1e3,
            t.flat_ms,
            t.deep_ms,
            t.deep_ms / t.flat_ms
        ));
    }
    out
}
