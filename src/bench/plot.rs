//! Raster line plots for the benchmark report: time against error, one polyline per
//! renderer, written as PNG with no plotting or font dependency.
//!
//! [`plot_png`] draws a title, a framed plot area with grid, ticks and numeric labels
//! (linear, or base-10 log on x), each [`Series`] as a coloured polyline with a per-series
//! marker shape, and a legend in the corner with the fewest data points.

mod font;

use std::path::Path;

use crate::error::{Error, Result};
use crate::image::write_png_rgba8;

/// One named line of a plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// The legend text.
    pub label: String,
    /// `(x, y)` points, drawn joined in this order. Non-finite points (and `x ≤ 0` on a log
    /// axis) are skipped and break the line.
    pub points: Vec<(f64, f64)>,
}

/// Image size in pixels.
const WIDTH: u32 = 900;
/// Image size in pixels.
const HEIGHT: u32 = 600;
/// Plot-area margins in pixels: room for the title, tick labels and axis labels.
const LEFT: u32 = 100;
const RIGHT: u32 = 30;
const TOP: u32 = 56;
const BOTTOM: u32 = 76;
/// Font pixels per glyph pixel for labels.
const TEXT_SCALE: u32 = 2;

type Rgba = [u8; 4];
const WHITE: Rgba = [255, 255, 255, 255];
const INK: Rgba = [30, 30, 30, 255];
const GRID: Rgba = [222, 222, 222, 255];
const MINOR_GRID: Rgba = [240, 240, 240, 255];
/// Series colours: the Okabe–Ito palette, distinguishable with the common colour-vision
/// deficiencies; marker shapes differ too.
const PALETTE: [Rgba; 6] = [
    [0, 114, 178, 255],
    [213, 94, 0, 255],
    [0, 158, 115, 255],
    [204, 121, 167, 255],
    [230, 159, 0, 255],
    [86, 180, 233, 255],
];

/// Plots `series` (x right, y up) into a 900×600 PNG at `path`. With `log_x`, x is drawn on a
/// base-10 log scale (decades labelled, 2–9 as minor ticks).
///
/// Errors: [`Error::Invalid`] when no series has a plottable point; [`Error::Io`] naming
/// `path` when the file cannot be written.
pub fn plot_png(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    log_x: bool,
) -> Result<()> {
    let rgba = draw(title, x_label, y_label, series, log_x)?;
    write_png_rgba8(path, WIDTH, HEIGHT, &rgba)
}

/// The plot as RGBA8 pixels, `WIDTH × HEIGHT`.
fn draw(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    log_x: bool,
) -> Result<Vec<u8>> {
    let runs: Vec<Vec<Vec<(f64, f64)>>> = series.iter().map(|s| runs(s, log_x)).collect();
    let all = || runs.iter().flatten().flatten();
    let x_axis = Axis::fit(all().map(|p| p.0), log_x)
        .ok_or_else(|| Error::invalid(format!("plot '{title}'"), "no plottable point"))?;
    let y_axis = Axis::fit(all().map(|p| p.1), false)
        .ok_or_else(|| Error::invalid(format!("plot '{title}'"), "no plottable point"))?;

    let (x0, y0, x1, y1) = (LEFT, TOP, WIDTH - RIGHT, HEIGHT - BOTTOM);
    let px = |x: f64| x0 as f64 + x_axis.unit(x) * (x1 - x0) as f64;
    let py = |y: f64| y1 as f64 - y_axis.unit(y) * (y1 - y0) as f64;
    let mut canvas = Canvas::new(WIDTH, HEIGHT);
    let s = TEXT_SCALE;
    let glyph_h = font::HEIGHT * s;

    // Grid first, so the data draws over it.
    for &x in &x_axis.minor_ticks() {
        canvas.fill_rect(px(x) as i32, y0 as i32, 1, (y1 - y0) as i32, MINOR_GRID);
    }
    for &x in &x_axis.ticks() {
        canvas.fill_rect(px(x) as i32, y0 as i32, 1, (y1 - y0) as i32, GRID);
    }
    for &y in &y_axis.ticks() {
        canvas.fill_rect(x0 as i32, py(y) as i32, (x1 - x0) as i32, 1, GRID);
    }

    for (i, series_runs) in runs.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        for run in series_runs {
            for pair in run.windows(2) {
                let (a, b) = (
                    (px(pair[0].0), py(pair[0].1)),
                    (px(pair[1].0), py(pair[1].1)),
                );
                canvas.line(a, b, 3, color);
            }
            for &(x, y) in run {
                canvas.marker(px(x), py(y), i, color);
            }
        }
    }

    // Frame, ticks and tick labels.
    canvas.frame(
        x0 as i32,
        y0 as i32,
        (x1 - x0) as i32,
        (y1 - y0) as i32,
        INK,
    );
    for &x in &x_axis.minor_ticks() {
        canvas.fill_rect(px(x) as i32, y1 as i32 - 4, 1, 4, INK);
    }
    for &x in &x_axis.ticks() {
        canvas.fill_rect(px(x) as i32, y1 as i32 - 8, 1, 8, INK);
        let label = x_axis.label(x);
        let w = text_width(&label, s) as i32;
        canvas.text(px(x) as i32 - w / 2, y1 as i32 + 8, &label, s, INK);
    }
    for &y in &y_axis.ticks() {
        canvas.fill_rect(x0 as i32, py(y) as i32, 8, 1, INK);
        let label = y_axis.label(y);
        let w = text_width(&label, s) as i32;
        let top = py(y) as i32 - glyph_h as i32 / 2;
        canvas.text(x0 as i32 - 8 - w, top, &label, s, INK);
    }

    // Title, axis labels.
    let title_scale = if text_width(title, 3) + 20 <= WIDTH {
        3
    } else {
        s
    };
    let w = text_width(title, title_scale) as i32;
    canvas.text((WIDTH as i32 - w) / 2, 16, title, title_scale, INK);
    let w = text_width(x_label, s) as i32;
    let x_mid = (x0 + x1) as i32 / 2;
    let label_top = (y1 + 16 + glyph_h + 12) as i32;
    canvas.text(x_mid - w / 2, label_top, x_label, s, INK);
    let h = text_width(y_label, s) as i32;
    let y_mid = (y0 + y1) as i32 / 2;
    canvas.text_up(18, y_mid + h / 2, y_label, s, INK);

    draw_legend(
        &mut canvas,
        series,
        &all().map(|&(x, y)| (px(x), py(y))).collect::<Vec<_>>(),
    );
    Ok(canvas.pixels)
}

/// Draws the legend into the plot-area corner that covers the fewest of `points` (pixels).
fn draw_legend(canvas: &mut Canvas, series: &[Series], points: &[(f64, f64)]) {
    if series.is_empty() {
        return;
    }
    let s = TEXT_SCALE;
    let row = (font::HEIGHT * s + 10) as i32;
    let sample = 36;
    let label_w = series
        .iter()
        .map(|x| text_width(&x.label, s))
        .max()
        .unwrap_or(0) as i32;
    let (w, h) = (sample + 24 + label_w + 12, row * series.len() as i32 + 12);
    let inset = 12;
    let (left, right) = (LEFT as i32 + inset, (WIDTH - RIGHT) as i32 - inset - w);
    let (top, bottom) = (TOP as i32 + inset, (HEIGHT - BOTTOM) as i32 - inset - h);
    let corners = [(left, top), (right, bottom), (right, top), (left, bottom)];
    let covered = |&(cx, cy): &(i32, i32)| {
        points
            .iter()
            .filter(|&&(x, y)| {
                let (x, y) = (x as i32, y as i32);
                x >= cx - 8 && x < cx + w + 8 && y >= cy - 8 && y < cy + h + 8
            })
            .count()
    };
    let (lx, ly) = corners
        .iter()
        .copied()
        .min_by_key(covered)
        .unwrap_or((left, top));

    canvas.fill_rect(lx, ly, w, h, WHITE);
    canvas.frame(lx, ly, w, h, GRID);
    for (i, entry) in series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let cy = ly + 6 + row * i as i32 + row / 2;
        let (sx0, sx1) = (lx + 12, lx + 12 + sample);
        canvas.line((sx0 as f64, cy as f64), (sx1 as f64, cy as f64), 3, color);
        canvas.marker((sx0 + sx1) as f64 / 2.0, cy as f64, i, color);
        let top = cy - (font::HEIGHT * s) as i32 / 2;
        canvas.text(sx1 + 12, top, &entry.label, s, INK);
    }
}

/// The runs of plottable points of `series`: maximal stretches of finite points (with
/// `x > 0` when `log_x`).
fn runs(series: &Series, log_x: bool) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut run = Vec::new();
    for &(x, y) in &series.points {
        if x.is_finite() && y.is_finite() && (!log_x || x > 0.0) {
            run.push((x, y));
        } else if !run.is_empty() {
            runs.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    runs
}

/// The width in pixels of `text` at `scale` (1 pixel gap between glyphs).
fn text_width(text: &str, scale: u32) -> u32 {
    let n = text.chars().count() as u32;
    (n * (font::WIDTH + 1)).saturating_sub(1) * scale
}

/// One axis: a value range, linear or base-10 logarithmic.
#[derive(Clone, Copy, Debug)]
struct Axis {
    /// Lower end, in axis space (`log10(v)` for a log axis).
    lo: f64,
    /// Upper end, in axis space.
    hi: f64,
    log: bool,
}

impl Axis {
    /// The range of `values` with 5 % padding each side (a lone value gets a range around
    /// it); `None` when there are no values.
    fn fit(values: impl Iterator<Item = f64>, log: bool) -> Option<Axis> {
        let to_axis = |v: f64| if log { v.log10() } else { v };
        let (lo, hi) = values.map(to_axis).fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((v.min(lo), v.max(hi))),
        })?;
        let span = hi - lo;
        let pad = if span > 0.0 {
            0.05 * span
        } else if log {
            0.5
        } else {
            (0.1 * lo.abs()).max(1.0)
        };
        Some(Axis {
            lo: lo - pad,
            hi: hi + pad,
            log,
        })
    }

    /// Where `v` lies on the axis: 0 at the low end, 1 at the high end.
    fn unit(&self, v: f64) -> f64 {
        let a = if self.log { v.log10() } else { v };
        (a - self.lo) / (self.hi - self.lo)
    }

    /// Labelled tick values: multiples of a 1-2-5 step giving about six ticks on a linear
    /// axis; powers of ten on a log axis (with 2× and 5× when it spans under two decades).
    fn ticks(&self) -> Vec<f64> {
        if self.log {
            let decades = (self.lo.floor() as i32)..=(self.hi.ceil() as i32);
            let steps: &[f64] = if self.hi - self.lo < 2.0 {
                &[1.0, 2.0, 5.0]
            } else {
                &[1.0]
            };
            let mut ticks = Vec::new();
            for k in decades {
                for &m in steps {
                    ticks.push(m * 10f64.powi(k));
                }
            }
            ticks.retain(|&v| self.contains(v));
            ticks
        } else {
            let step = self.linear_step();
            let first = (self.lo / step).ceil() as i64;
            let last = (self.hi / step).floor() as i64;
            (first..=last).map(|k| k as f64 * step).collect()
        }
    }

    /// Unlabelled minor ticks: 2·10ᵏ … 9·10ᵏ on a log axis; none on a linear one.
    fn minor_ticks(&self) -> Vec<f64> {
        if !self.log {
            return Vec::new();
        }
        let decades = (self.lo.floor() as i32)..=(self.hi.ceil() as i32);
        decades
            .flat_map(|k| (2..=9).map(move |m| f64::from(m) * 10f64.powi(k)))
            .filter(|&v| self.contains(v))
            .collect()
    }

    fn contains(&self, v: f64) -> bool {
        (0.0..=1.0).contains(&self.unit(v))
    }

    /// The 1-2-5 step closest to a sixth of the range (a linear axis).
    fn linear_step(&self) -> f64 {
        let raw = (self.hi - self.lo) / 6.0;
        let magnitude = 10f64.powf(raw.log10().floor());
        let norm = raw / magnitude;
        let nice = [1.0, 2.0, 5.0, 10.0]
            .into_iter()
            .find(|&n| n >= norm * 0.75)
            .unwrap_or(10.0);
        nice * magnitude
    }

    /// The tick label for `v`: as many decimals as the step needs on a linear axis; plain
    /// numbers from 0.001 to 100000 and `1e-5`-style beyond on a log axis.
    fn label(&self, v: f64) -> String {
        if self.log {
            // Nudged so that a power of ten whose log10 rounds just below stays in its decade.
            let exponent = (v.log10() + 1e-9).floor() as i32;
            if (-3..=5).contains(&exponent) {
                format!("{:.*}", (-exponent).max(0) as usize, v)
            } else {
                format!("{v:e}")
            }
        } else {
            let step = self.linear_step();
            let decimals = (-step.log10().floor()).max(0.0) as usize;
            // `+ 0.0` turns −0 into 0.
            format!("{:.*}", decimals, v + 0.0)
        }
    }
}

/// An RGBA8 raster with the few drawing operations a plot needs; everything is clipped.
struct Canvas {
    width: u32,
    height: u32,
    pixels: Vec<u8>,
}

impl Canvas {
    /// A white canvas.
    fn new(width: u32, height: u32) -> Self {
        Canvas {
            width,
            height,
            pixels: vec![255; width as usize * height as usize * 4],
        }
    }

    fn set(&mut self, x: i32, y: i32, color: Rgba) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = 4 * (y as usize * self.width as usize + x as usize);
            self.pixels[i..i + 4].copy_from_slice(&color);
        }
    }

    fn fill_rect(&mut self, x: i32, y: i32, w: i32, h: i32, color: Rgba) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.set(xx, yy, color);
            }
        }
    }

    /// A 1-pixel outline of the rectangle.
    fn frame(&mut self, x: i32, y: i32, w: i32, h: i32, color: Rgba) {
        self.fill_rect(x, y, w, 1, color);
        self.fill_rect(x, y + h - 1, w, 1, color);
        self.fill_rect(x, y, 1, h, color);
        self.fill_rect(x + w - 1, y, 1, h, color);
    }

    /// A line `thickness` pixels wide (a square brush stepped one pixel at a time along the
    /// longer axis).
    fn line(&mut self, a: (f64, f64), b: (f64, f64), thickness: i32, color: Rgba) {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let steps = dx.abs().max(dy.abs()).ceil().max(1.0) as i32;
        let half = thickness / 2;
        for i in 0..=steps {
            let t = f64::from(i) / f64::from(steps);
            let (x, y) = ((a.0 + t * dx).round() as i32, (a.1 + t * dy).round() as i32);
            self.fill_rect(x - half, y - half, thickness, thickness, color);
        }
    }

    /// A filled marker centred at (`x`, `y`), its shape chosen by the series index: circle,
    /// square, diamond, triangle; with a white rim so it stands out from lines.
    fn marker(&mut self, x: f64, y: f64, series: usize, color: Rgba) {
        let (cx, cy) = (x.round() as i32, y.round() as i32);
        let inside = |dx: i32, dy: i32, r: i32| match series % 4 {
            0 => dx * dx + dy * dy <= r * r + r,
            1 => dx.abs() < r && dy.abs() < r,
            2 => dx.abs() + dy.abs() <= r + 1,
            _ => dy <= r * 3 / 4 && dy >= -r && 2 * dx.abs() <= dy + r,
        };
        for (r, c) in [(7, WHITE), (5, color)] {
            for dy in -r - 1..=r + 1 {
                for dx in -r - 1..=r + 1 {
                    if inside(dx, dy, r) {
                        self.set(cx + dx, cy + dy, c);
                    }
                }
            }
        }
    }

    /// `text` with its top-left corner at (`x`, `y`), each font pixel `scale` pixels square.
    fn text(&mut self, x: i32, y: i32, text: &str, scale: u32, color: Rgba) {
        self.glyphs(text, scale, color, |gx, gy| (x + gx, y + gy));
    }

    /// `text` reading bottom to top (rotated 90° anticlockwise), starting at (`x`, `y`),
    /// which becomes the bottom-left corner of the first glyph.
    fn text_up(&mut self, x: i32, y: i32, text: &str, scale: u32, color: Rgba) {
        self.glyphs(text, scale, color, |gx, gy| (x + gy, y - gx));
    }

    /// Draws the glyphs of `text` laid out left to right in text space (`gx` along the
    /// line, `gy` down), mapped to the canvas by `place`.
    fn glyphs(
        &mut self,
        text: &str,
        scale: u32,
        color: Rgba,
        place: impl Fn(i32, i32) -> (i32, i32),
    ) {
        let scale = scale as i32;
        let advance = (font::WIDTH + 1) as i32 * scale;
        for (i, c) in text.chars().enumerate() {
            for (row, bits) in font::glyph(c).iter().enumerate() {
                for col in 0..font::WIDTH as i32 {
                    if (bits >> (font::WIDTH as i32 - 1 - col)) & 1 == 1 {
                        let gx = i as i32 * advance + col * scale;
                        let gy = row as i32 * scale;
                        for (sx, sy) in (0..scale).flat_map(|a| (0..scale).map(move |b| (a, b))) {
                            let (px, py) = place(gx + sx, gy + sy);
                            self.set(px, py, color);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::decode_rgba8;

    fn bench_like_series() -> Vec<Series> {
        let preset = |label: &str, pts: &[(f64, f64)]| Series {
            label: label.to_string(),
            points: pts.to_vec(),
        };
        vec![
            preset("draft", &[(4.0, 24.5), (6.5, 27.0), (9.0, 28.1)]),
            preset("preview", &[(15.0, 31.0), (22.0, 33.2), (31.0, 34.0)]),
            preset("final", &[(80.0, 38.5), (120.0, 40.2), (170.0, 41.0)]),
            preset(
                "naive marcher",
                &[(300.0, 30.0), (900.0, 36.0), (2500.0, 40.5)],
            ),
        ]
    }

    #[test]
    fn plot_decodes_as_png_with_series_colours() {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let path =
            std::env::temp_dir().join(format!("nerfx-plot-{}-{nanos}.png", std::process::id()));
        let series = bench_like_series();
        plot_png(
            &path,
            "Render time against error",
            "time per frame (ms, log)",
            "PSNR (dB)",
            &series,
            true,
        )
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let (w, h, rgba) = decode_rgba8(&bytes);
        assert_eq!((w, h), (900, 600));
        let count = |c: [u8; 4]| rgba.chunks_exact(4).filter(|p| *p == c).count();
        // Each series colour covers at least its markers (~70 px each) and legend sample.
        for (i, color) in [
            [0, 114, 178, 255],
            [213, 94, 0, 255],
            [0, 158, 115, 255],
            [204, 121, 167, 255],
        ]
        .into_iter()
        .enumerate()
        {
            assert!(count(color) > 200, "series {i}: {} pixels", count(color));
        }
        // Mostly white background.
        assert!(count([255, 255, 255, 255]) > 900 * 600 / 2);
    }

    #[test]
    fn no_plottable_point_is_refused() {
        let series = [Series {
            label: "bad".into(),
            points: vec![(0.0, 1.0), (f64::NAN, 2.0)],
        }];
        assert!(matches!(
            draw("t", "x", "y", &series, true),
            Err(Error::Invalid { .. })
        ));
        assert!(matches!(
            draw("t", "x", "y", &[], false),
            Err(Error::Invalid { .. })
        ));
    }

    #[test]
    fn runs_break_at_unplottable_points() {
        let s = Series {
            label: String::new(),
            points: vec![
                (1.0, 1.0),
                (2.0, 2.0),
                (-1.0, 0.0),
                (3.0, f64::INFINITY),
                (4.0, 4.0),
            ],
        };
        assert_eq!(
            runs(&s, true),
            vec![vec![(1.0, 1.0), (2.0, 2.0)], vec![(4.0, 4.0)]]
        );
        assert_eq!(
            runs(&s, false),
            vec![vec![(1.0, 1.0), (2.0, 2.0), (-1.0, 0.0)], vec![(4.0, 4.0)]]
        );
    }

    #[test]
    fn ticks_are_round_numbers_inside_the_range() {
        // 0..100 padded to −5..105: step 20 (a sixth is 18.3).
        let lin = Axis::fit([0.0, 100.0].into_iter(), false).unwrap();
        assert_eq!(lin.ticks(), vec![0.0, 20.0, 40.0, 60.0, 80.0, 100.0]);
        assert_eq!(lin.label(40.0), "40");
        let small = Axis::fit([0.1, 0.35].into_iter(), false).unwrap();
        assert_eq!(small.label(0.25), "0.25");
        // 3 ms .. 3000 ms: decades 10, 100, 1000 and minor 4..9, 20..90, ...
        let log = Axis::fit([3.0, 3000.0].into_iter(), true).unwrap();
        assert_eq!(log.ticks(), vec![10.0, 100.0, 1000.0]);
        assert_eq!(log.minor_ticks().first(), Some(&3.0));
        assert_eq!(log.label(1000.0), "1000");
        assert_eq!(log.label(0.01), "0.01");
        assert_eq!(log.label(1.0e7), "1e7");
        // A lone point still gets a non-empty range around it.
        let lone = Axis::fit([5.0].into_iter(), false).unwrap();
        assert!(lone.lo < 5.0 && lone.hi > 5.0);
    }

    #[test]
    fn text_width_counts_glyph_cells() {
        // Two glyphs: 5 + 1 gap + 5 font pixels, doubled.
        assert_eq!(text_width("ab", 2), 22);
        assert_eq!(text_width("", 2), 0);
    }
}
