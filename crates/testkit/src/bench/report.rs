//! The suite's report: a Markdown table per scene, and per scene a plot of time against
//! PSNR, written into the output folder.

use std::fmt::Write as _;
use std::path::Path;

use super::plot::{plot_png, Series};
use super::scaling;
use super::suite::{marched_name, Report, Row, SceneReport, CHECK_ROW_STRIDE, ROW_STRIDE};
use nerfx_core::error::Result;
use nerfx_core::render::Quality;

/// Bytes as MiB with one decimal, or `n/a`.
fn mib(bytes: Option<usize>) -> String {
    bytes.map_or("n/a".into(), |b| {
        format!("{:.1}", b as f64 / (1 << 20) as f64)
    })
}

impl Report {
    /// The report, as Markdown: a heading and a table per scene.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "{}×{}, {} threads{}. Times are the median of the timed frames; CPU is user + \
             system time of all threads for that frame. Heap: peak bytes allocated during \
             the frame above those live before it (a counting allocator in the `nerfx` \
             binary); n/a where it is not installed.\n",
            self.width,
            self.height,
            self.threads,
            self.load.map_or(String::new(), |l| format!(
                ", load average {:.1} {:.1} {:.1} at the end",
                l[0], l[1], l[2]
            )),
        );
        for scene in &self.scenes {
            s += &scene_markdown(scene);
        }
        if !self.growth.is_empty() {
            s += &scaling::markdown(&self.growth);
        }
        s
    }

    /// Writes `report.md`, per scene with a reference `time_vs_psnr_<scene>.png`, and with
    /// the growth series `cost_vs_content.png` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let md = dir.join("report.md");
        nerfx_core::write_file(&md, self.markdown().as_bytes())?;
        for scene in &self.scenes {
            let series = |label: &str, keep: &dyn Fn(&str) -> bool| Series {
                label: label.into(),
                points: scene
                    .rows
                    .iter()
                    .filter(|r| keep(&r.name))
                    .filter_map(|r| r.error.map(|e| (r.ms_per_frame, e.psnr)))
                    .collect(),
            };
            let preset = |name: &str| Quality::ALL.iter().any(|q| q.name() == name);
            let marched = |name: &str| Quality::ALL.iter().any(|&q| marched_name(q) == name);
            let naive = |name: &str| name.starts_with("naive");
            let series = [
                series("nerfx presets", &preset),
                series("nerfx presets, marched", &marched),
                series("naive uniform steps", &naive),
                series("trainer's own marcher", &|n| {
                    !preset(n) && !marched(n) && !naive(n)
                }),
            ];
            if series.iter().all(|s| s.points.is_empty()) {
                continue;
            }
            plot_png(
                &dir.join(format!("time_vs_psnr_{}.png", scene.kind.name())),
                &format!(
                    "{}: run time against error, {}x{}",
                    scene.kind.name(),
                    self.width,
                    self.height
                ),
                "ms per frame",
                "PSNR (dB)",
                &series,
                true,
            )?;
        }
        if !self.growth.is_empty() {
            scaling::write_plot(&self.growth, dir)?;
        }
        Ok(())
    }
}

fn scene_markdown(scene: &SceneReport) -> String {
    let mut s = format!(
        "\n### {}\n\n{}. Reference: {} ({:.0} ms). Scene and occupancy heap: {} MiB; one \
         16×16 Final tile: {} MiB.\n\n",
        scene.kind.name(),
        scene.description,
        scene.truth,
        scene.reference_ms,
        mib(scene.scene_heap),
        mib(scene.tile_heap),
    );
    s += "| configuration | ms/frame | CPU s/frame | density samples/px | colour samples/px | \
          splat fragments/px | PSNR (dB) | max alpha error | max colour error | within \
          target ² | max depth error (rel.) | rays at budget | peak heap (MiB) |\n\
          |---|---:|---:|---:|---:|---:|---:|---:|---:|:---:|---:|---:|---:|\n";
    for r in &scene.rows {
        s += &row_markdown(r);
    }
    s += "\n";
    if scene.rows.iter().any(|r| r.on_rows) {
        s += &format!(
            "¹ timed and compared on every {}th row only (reference rows), scaled to a frame.\n",
            ROW_STRIDE.max(scene.row_stride)
        );
    }
    s += &target_note(scene);
    s
}

/// What "within target" compared, and how far a fine reference is itself from converged.
fn target_note(scene: &SceneReport) -> String {
    let targets = Quality::ALL
        .iter()
        .map(|q| format!("{} {:.0e}", q.name(), q.params().error_target))
        .collect::<Vec<_>>()
        .join(", ");
    let mut s = format!(
        "² whether the largest error of any pixel compared, in alpha and in each \
         premultiplied colour channel, is within the preset's error target ({targets}); \
         baselines promise none. "
    );
    if !scene.rows.iter().any(|r| r.error.is_some()) {
        s += "This scene has no reference: nothing was compared.\n";
        return s;
    }
    match scene.reference_error {
        None => s += "Compared: every pixel, against the exact integral.\n",
        Some(e) => {
            s += &format!(
                "Compared: every {}th row, against the reference above, which is not \
                 exact: against {} (on every {CHECK_ROW_STRIDE}th row) it is off by up \
                 to {:.2e} in alpha and {:.2e} in colour, so a preset missing its target by \
                 less than that may be the reference's miss.\n",
                scene.row_stride, scene.reference_check, e.max_alpha_error, e.max_color_error
            );
        }
    }
    s
}

fn row_markdown(r: &Row) -> String {
    let mut s = format!(
        "| {}{} | {:.0} | {} | {:.1} | {:.1} | {:.1} |",
        r.name,
        if r.on_rows { " ¹" } else { "" },
        r.ms_per_frame,
        r.cpu_s_per_frame
            .map_or("n/a".into(), |c| format!("{c:.2}")),
        r.samples_per_pixel,
        r.color_samples_per_pixel,
        r.fragments_per_pixel,
    );
    match r.error {
        Some(e) => {
            let within = match r.within_target() {
                Some(true) => "yes",
                Some(false) => "no",
                None => "—",
            };
            let _ = write!(
                s,
                " {:.2} | {:.2e} | {:.2e} | {within} | {:.2e} |",
                e.psnr, e.max_alpha_error, e.max_color_error, e.max_depth_rel_error
            );
        }
        None => s += " — | — | — | — | — |",
    }
    let _ = writeln!(s, " {} | {} |", r.budget_hits, mib(r.peak_heap));
    s
}
