//! Line plots for the benchmark report: time against error, one polyline per renderer,
//! drawn by `plotters` into a bitmap with the DejaVu Sans font embedded (no system fonts
//! needed on a farm node) and written as PNG.

use std::path::Path;
use std::sync::Once;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;

use nerfx_core::error::{Error, Result};
use nerfx_core::image::write_png_rgba8;

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
/// The font family name the plots ask for.
const FONT: &str = "sans-serif";
/// Series colours: the Okabe–Ito palette, distinguishable with the common colour-vision
/// deficiencies; marker shapes differ too.
const PALETTE: [RGBColor; 6] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
];

/// Plots `series` (x right, y up) into a 900×600 PNG at `path`. With `log_x`, x is drawn on a
/// base-10 log scale.
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
    let rgb = draw(title, x_label, y_label, series, log_x)?;
    let rgba: Vec<u8> = rgb
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    write_png_rgba8(path, WIDTH, HEIGHT, &rgba)
}

/// The plot as RGB8 pixels, `WIDTH × HEIGHT`.
fn draw(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    log_x: bool,
) -> Result<Vec<u8>> {
    let runs: Vec<Vec<Vec<(f64, f64)>>> = series.iter().map(|s| runs(s, log_x)).collect();
    let all = || runs.iter().flatten().flatten();
    let none = || Error::invalid(format!("plot '{title}'"), "no plottable point");
    let x = span(all().map(|p| p.0), log_x).ok_or_else(none)?;
    let y = span(all().map(|p| p.1), false).ok_or_else(none)?;
    register_font();

    let mut pixels = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    let backend = BitMapBackend::with_buffer(&mut pixels, (WIDTH, HEIGHT));
    let legend = legend_corner(&runs, &x, &y, log_x);
    let text = Text {
        title,
        x_label,
        y_label,
        legend,
    };
    let drawn = if log_x {
        chart(backend, text, &runs, series, x.log_scale(), y)
    } else {
        chart(backend, text, &runs, series, x, y)
    };
    drawn.map_err(|e| Error::invalid(format!("plot '{title}'"), e))?;
    Ok(pixels)
}

/// What a chart says besides its lines, and where its legend goes.
struct Text<'a> {
    title: &'a str,
    x_label: &'a str,
    y_label: &'a str,
    legend: SeriesLabelPosition,
}

/// Draws the framed, gridded chart with its title, axis labels, series and legend.
fn chart<X>(
    backend: BitMapBackend,
    text: Text,
    runs: &[Vec<Vec<(f64, f64)>>],
    series: &[Series],
    x: X,
    y: std::ops::Range<f64>,
) -> std::result::Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
{
    let root = backend.into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut chart = ChartBuilder::on(&root)
        .caption(text.title, (FONT, 26))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(76)
        .build_cartesian_2d(x, y)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc(text.x_label)
        .y_desc(text.y_label)
        .label_style((FONT, 16))
        .axis_desc_style((FONT, 18))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(222, 222, 222))
        .draw()
        .map_err(|e| e.to_string())?;
    for (i, (series_runs, s)) in runs.iter().zip(series).enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let line = colour.stroke_width(3);
        for (k, run) in series_runs.iter().enumerate() {
            let drawn = chart
                .draw_series(LineSeries::new(run.iter().copied(), line))
                .map_err(|e| e.to_string())?;
            if k == 0 {
                drawn
                    .label(s.label.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], line));
            }
            let points = run.iter().copied();
            match i % 3 {
                0 => chart.draw_series(points.map(|p| Circle::new(p, 5, colour.filled()))),
                1 => chart.draw_series(points.map(|p| TriangleMarker::new(p, 7, colour.filled()))),
                _ => chart.draw_series(points.map(|p| Cross::new(p, 5, colour.stroke_width(3)))),
            }
            .map_err(|e| e.to_string())?;
        }
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .position(text.legend)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// The embedded font, registered once per process for the plots' family name.
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is compiled in; it parses, or no plot could ever draw text.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// The range the values span, padded by 5 % on each side (a decade's 5 % on a log axis);
/// `None` when there are none. A single value gets a unit-wide range.
fn span(values: impl Iterator<Item = f64>, log: bool) -> Option<std::ops::Range<f64>> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if lo > hi {
        return None;
    }
    if log {
        let pad = ((hi / lo).log10() * 0.05).max(0.05);
        return Some(lo / 10f64.powf(pad)..hi * 10f64.powf(pad));
    }
    let pad = if hi > lo { 0.05 * (hi - lo) } else { 0.5 };
    Some(lo - pad..hi + pad)
}

/// The corner of the plotting area whose legend box would cover the fewest of the lines
/// (their points and points sampled along each segment, as drawn: `x` on a log scale with
/// `log_x`), lower right first among equals, then upper right, upper left, lower left: so
/// that the legend does not hide a line where a corner is free.
fn legend_corner(
    runs: &[Vec<Vec<(f64, f64)>>],
    x: &std::ops::Range<f64>,
    y: &std::ops::Range<f64>,
    log_x: bool,
) -> SeriesLabelPosition {
    let along_x = |v: f64| {
        if log_x {
            (v / x.start).log10() / (x.end / x.start).log10()
        } else {
            (v - x.start) / (x.end - x.start)
        }
    };
    let unit = |(px, py): (f64, f64)| (along_x(px), (py - y.start) / (y.end - y.start));
    // The legend's share of the plotting area (a 900×600 image's): its width, and a line a
    // series with a margin.
    let (w, h) = (0.32, 0.04 + 0.05 * runs.len() as f64);
    let mut samples = Vec::new();
    for run in runs.iter().flatten() {
        let points: Vec<(f64, f64)> = run.iter().map(|&p| unit(p)).collect();
        samples.extend(&points);
        for pair in points.windows(2) {
            let ((x0, y0), (x1, y1)) = (pair[0], pair[1]);
            samples.extend((1..SEGMENT_SAMPLES).map(|k| {
                let s = f64::from(k) / f64::from(SEGMENT_SAMPLES);
                (x0 + s * (x1 - x0), y0 + s * (y1 - y0))
            }));
        }
    }
    let corners = [
        (SeriesLabelPosition::LowerRight, (1.0 - w, 0.0)),
        (SeriesLabelPosition::UpperRight, (1.0 - w, 1.0 - h)),
        (SeriesLabelPosition::UpperLeft, (0.0, 1.0 - h)),
        (SeriesLabelPosition::LowerLeft, (0.0, 0.0)),
    ];
    let covered = |(cx, cy): (f64, f64)| {
        (samples.iter())
            .filter(|&&(u, v)| u >= cx && u <= cx + w && v >= cy && v <= cy + h)
            .count()
    };
    let mut best = (usize::MAX, SeriesLabelPosition::LowerRight);
    for (corner, at) in corners {
        let n = covered(at);
        if n < best.0 {
            best = (n, corner);
        }
    }
    best.1
}

/// Points sampled along each segment of a line when placing the legend.
const SEGMENT_SAMPLES: u32 = 32;

/// The series split into runs of plottable points.
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

#[cfg(test)]
mod tests {
    use super::*;

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
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plot.png");
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
        let file = std::fs::File::open(&path).unwrap();
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .unwrap();
        let mut rgba = vec![0; reader.output_buffer_size().unwrap()];
        let frame = reader.next_frame(&mut rgba).unwrap();
        assert_eq!(frame.color_type, png::ColorType::Rgba);
        let (w, h) = (frame.width, frame.height);
        assert_eq!((w, h), (900, 600));
        let count = |c: [u8; 4]| rgba.chunks_exact(4).filter(|p| *p == c).count();
        // Each series colour covers at least its markers and legend sample.
        for (i, c) in PALETTE.iter().take(series.len()).enumerate() {
            let n = count([c.0, c.1, c.2, 255]);
            assert!(n > 200, "series {i}: {n} pixels");
        }
        // Mostly white background.
        assert!(count([255, 255, 255, 255]) > 900 * 600 / 2);
    }

    #[test]
    fn the_legend_goes_to_a_corner_no_line_crosses() {
        let place = |pts: &[(f64, f64)], log_x: bool| {
            let runs = vec![vec![pts.to_vec()]];
            let all = || pts.iter();
            let x = span(all().map(|p| p.0), log_x).unwrap();
            let y = span(all().map(|p| p.1), false).unwrap();
            legend_corner(&runs, &x, &y, log_x)
        };
        let is = |p: SeriesLabelPosition, want: SeriesLabelPosition| {
            format!("{p:?}") == format!("{want:?}")
        };
        // A line rising from the lower left to the upper right leaves the lower right free.
        let rising = [(1.0, 1.0), (10.0, 10.0), (100.0, 100.0)];
        assert!(is(place(&rising, false), SeriesLabelPosition::LowerRight));
        // Falling into it on a log axis, bent, it leaves the upper right and the lower left
        // free, and takes the first of them.
        let falling = [(1.0, 100.0), (10.0, 90.0), (100.0, 50.0), (1000.0, 1.0)];
        assert!(is(place(&falling, true), SeriesLabelPosition::UpperRight));
        // With the upper right taken too, the lower left.
        let both = [
            (1.0, 100.0),
            (10.0, 90.0),
            (100.0, 50.0),
            (1000.0, 1.0),
            (1000.0, 100.0),
        ];
        assert!(is(place(&both, true), SeriesLabelPosition::LowerLeft));
        // Points in the lower right only (the demo's naive marcher): any other corner.
        let low_right = [(900.0, 1.0), (1000.0, 2.0), (10.0, 50.0)];
        assert!(!is(
            place(&low_right, true),
            SeriesLabelPosition::LowerRight
        ));
    }

    #[test]
    fn the_title_is_drawn_in_the_embedded_font() {
        // Non-white pixels in the band above the plot area, where only the title goes.
        let inked = |title: &str| {
            let rgb = draw(title, "x", "y", &bench_like_series(), true).unwrap();
            rgb[..(WIDTH * 40 * 3) as usize]
                .chunks_exact(3)
                .filter(|p| p.iter().any(|&c| c < 200))
                .count()
        };
        assert_eq!(inked(""), 0);
        let n = inked("Render time against error");
        assert!(n > 500, "{n} inked pixels for the title");
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
    fn a_single_point_gets_a_range() {
        let series = [Series {
            label: "one".into(),
            points: vec![(10.0, 40.0)],
        }];
        assert!(draw("t", "x", "y", &series, true).is_ok());
        assert!(draw("t", "x", "y", &series, false).is_ok());
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
}
