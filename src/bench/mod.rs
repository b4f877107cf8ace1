//! Benchmarks: render time against error, and the report plots.
//!
//! [`run`] renders the demo scene (see [`crate::demo`]) with each quality preset and with the
//! naive uniform-step marcher at a few step sizes, compares every image with the exact
//! reference ([`crate::reference`]), and reports ms/frame, density samples per pixel, PSNR
//! and the largest alpha and depth errors, as Markdown and as a plot of time against PSNR.

pub mod field;
pub mod passes;
pub mod plot;
pub mod splats;

use std::path::Path;
use std::time::Instant;

use crate::demo;
use crate::error::{Error, Result};
use crate::image::Planes;
use crate::reference::{self, ErrorReport};
use crate::render::{
    render_naive, render_with_progress, Outputs, Quality, RenderSettings, RenderStats,
};
use plot::{plot_png, Series};

/// Naive step sizes, as fractions of the scene's largest bounding-box diagonal.
const NAIVE_STEPS_PER_DIAGONAL: [f64; 2] = [384.0, 1536.0];

/// One measured configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// `draft`, `preview`, `final` or `naive (step …)`.
    pub name: String,
    /// Median wall time of a frame, in milliseconds.
    pub ms_per_frame: f64,
    /// Density queries per pixel.
    pub samples_per_pixel: f64,
    /// Radiance queries per pixel.
    pub color_samples_per_pixel: f64,
    /// Errors against the reference.
    pub error: ErrorReport,
}

/// A benchmark run.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Worker threads used.
    pub threads: usize,
    /// Time of the reference render, in milliseconds.
    pub reference_ms: f64,
    /// The configurations, presets first.
    pub rows: Vec<Row>,
}

/// Runs the benchmark at `width × height`, timing each preset `repeats` times (after one
/// untimed warm-up that also builds the occupancy grids) and the naive marcher once per step
/// size. `log` receives progress lines.
pub fn run(width: u32, height: u32, repeats: u32, log: &dyn Fn(&str)) -> Result<Report> {
    let (scene, camera) = demo::scene_and_camera(width, height)?;
    let window = camera.full_window();
    let outputs = Outputs::all();

    log(&format!("reference {width}×{height} …"));
    let started = Instant::now();
    let truth = reference::render(&scene, &camera, window)?;
    let reference_ms = started.elapsed().as_secs_f64() * 1e3;
    log(&format!("reference: {:.0} ms", reference_ms));

    let mut rows = Vec::new();
    for quality in Quality::ALL {
        let settings = RenderSettings::new(quality.params(), outputs);
        let render = || render_with_progress(&scene, &camera, window, &settings, &|_| {});
        render()?;
        let mut times = Vec::new();
        let mut last = None;
        for _ in 0..repeats.max(1) {
            let started = Instant::now();
            let out = render()?;
            times.push(started.elapsed().as_secs_f64() * 1e3);
            last = Some(out);
        }
        let (planes, stats) = last.ok_or_else(|| Error::invalid("bench", "no repeats"))?;
        let row = row(
            format!("{quality:?}").to_lowercase(),
            median(&mut times),
            &planes,
            &stats,
            &truth,
        );
        log(&row_line(&row));
        rows.push(row);
    }

    let diagonal = scene
        .instances
        .iter()
        .map(|i| i.field().bounds().diagonal() as f64)
        .fold(0.0, f64::max);
    for steps in NAIVE_STEPS_PER_DIAGONAL {
        let step = diagonal / steps;
        let started = Instant::now();
        let (planes, stats) = render_naive(&scene, &camera, window, step, &outputs)?;
        let ms = started.elapsed().as_secs_f64() * 1e3;
        let row = row(
            format!("naive (step diag/{steps})"),
            ms,
            &planes,
            &stats,
            &truth,
        );
        log(&row_line(&row));
        rows.push(row);
    }

    Ok(Report {
        width,
        height,
        threads: rayon::current_num_threads(),
        reference_ms,
        rows,
    })
}

fn row(name: String, ms: f64, planes: &Planes, stats: &RenderStats, truth: &Planes) -> Row {
    let pixels = stats.pixels.max(1) as f64;
    Row {
        name,
        ms_per_frame: ms,
        samples_per_pixel: stats.density_samples as f64 / pixels,
        color_samples_per_pixel: stats.color_samples as f64 / pixels,
        error: ErrorReport::compare(truth, planes),
    }
}

fn row_line(r: &Row) -> String {
    format!(
        "{}: {:.0} ms, {:.1} spp, PSNR {:.2} dB, max alpha err {:.2e}",
        r.name, r.ms_per_frame, r.samples_per_pixel, r.error.psnr, r.error.max_alpha_error
    )
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

impl Report {
    /// The table, as Markdown.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Demo scene at {}×{}, {} threads; exact reference took {:.0} ms.\n\n\
             | configuration | ms/frame | density samples/px | colour samples/px | PSNR (dB) | max alpha error | max depth error (rel.) |\n\
             |---|---:|---:|---:|---:|---:|---:|\n",
            self.width, self.height, self.threads, self.reference_ms
        );
        for r in &self.rows {
            s += &format!(
                "| {} | {:.0} | {:.1} | {:.1} | {:.2} | {:.2e} | {:.2e} |\n",
                r.name,
                r.ms_per_frame,
                r.samples_per_pixel,
                r.color_samples_per_pixel,
                r.error.psnr,
                r.error.max_alpha_error,
                r.error.max_depth_rel_error
            );
        }
        s
    }

    /// Writes `report.md` and `time_vs_psnr.png` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let md = dir.join("report.md");
        std::fs::write(&md, self.markdown()).map_err(|e| Error::io(&md, e))?;
        let presets = Series {
            label: "nerfx presets".into(),
            points: self
                .rows
                .iter()
                .filter(|r| !r.name.starts_with("naive"))
                .map(|r| (r.ms_per_frame, r.error.psnr))
                .collect(),
        };
        let naive = Series {
            label: "naive uniform steps".into(),
            points: self
                .rows
                .iter()
                .filter(|r| r.name.starts_with("naive"))
                .map(|r| (r.ms_per_frame, r.error.psnr))
                .collect(),
        };
        plot_png(
            &dir.join("time_vs_psnr.png"),
            &format!("Run time against error, {}x{}", self.width, self.height),
            "ms per frame",
            "PSNR (dB)",
            &[presets, naive],
            true,
        )
    }
}
