//! How cost grows with content: the same preset on ever more pixels (resolution), more
//! instances (a grid of small fog balls, each its own instance, covering the same part of
//! the frame) and more occupied space (the trained fog's ball growing). For each, the work
//! (density samples) and the CPU time it took: if the CPU time per sample stays flat as the
//! content grows, cost grows no faster than the work.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use glam::{DMat4, DVec3, Vec3};

use super::field::process_cpu_seconds;
use super::plot::{plot_png, Series};
use super::snapshot::{occupied_fraction, write_snapshot, Ball, SnapshotSpec};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::demo::{self, look_at};
use nerfx_core::error::{Error, Result};
use nerfx_core::field::{Analytic, IngpField, Primitive, ShColor, Shape};
use nerfx_core::render::{render_with_progress, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};

/// The preset every series renders with.
pub const PRESET: Quality = Quality::Preview;

/// One measured point of a series.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    /// What was varied, for people (`1920×1080`, `16 instances`, `fill 4.2 %`).
    pub label: String,
    /// Pixels rendered.
    pub pixels: u64,
    /// Density samples of the frame.
    pub samples: u64,
    /// Wall time of the frame, milliseconds.
    pub ms: f64,
    /// CPU time of the frame (all threads), seconds; wall time where the system does not
    /// say.
    pub cpu_s: f64,
    /// For a set-up point, the most heap bytes live at once while it was set up, where the
    /// program counts them ([`super::memory`]).
    pub peak_heap: Option<usize>,
}

impl Point {
    /// A point of a per-item series: `items` items (in `samples`) cost `cpu_s`.
    pub fn per_item(label: String, items: u64, cpu_s: f64, peak_heap: Option<usize>) -> Point {
        Point {
            label,
            pixels: 0,
            samples: items,
            ms: cpu_s * 1e3,
            cpu_s,
            peak_heap,
        }
    }

    /// Peak heap bytes per item (of a set-up point), where counted.
    pub fn heap_per_item(&self) -> Option<f64> {
        self.peak_heap
            .map(|b| b as f64 / self.samples.max(1) as f64)
    }

    /// CPU nanoseconds per density sample.
    pub fn ns_per_sample(&self) -> f64 {
        self.cpu_s * 1e9 / self.samples.max(1) as f64
    }

    /// CPU microseconds per pixel.
    pub fn us_per_pixel(&self) -> f64 {
        self.cpu_s * 1e6 / self.pixels.max(1) as f64
    }
}

/// One kind of growth.
#[derive(Clone, Debug, PartialEq)]
pub struct Growth {
    /// What grows, and in which scene.
    pub title: String,
    /// Smallest first.
    pub points: Vec<Point>,
    /// For a set-up series, the item counted (`samples` then holds items, not density
    /// samples); `None` for a frame's cost against its density samples.
    pub item: Option<&'static str>,
}

impl Growth {
    /// A series of set-up cost per `item`.
    pub fn per_item(title: &str, item: &'static str, points: Vec<Point>) -> Growth {
        Growth {
            title: title.into(),
            points,
            item: Some(item),
        }
    }
}

/// Runs the three series: resolution (the demo, up to `width × height`), instances (1 to
/// 64, at a quarter of each side) and occupancy fill (the trained fog, ball radius 0.1 to
/// 0.4, at a quarter of each side). `dir` takes the generated snapshots while they load.
pub fn run(width: u32, height: u32, dir: &Path, log: &dyn Fn(&str)) -> Result<Vec<Growth>> {
    let quarter = ((width / 4).max(16), (height / 4).max(16));
    let mut out = Vec::new();

    let mut points = Vec::new();
    for div in [4, 2, 1] {
        let (w, h) = ((width / div).max(16), (height / div).max(16));
        let (scene, camera) = demo::scene_and_camera(w, h)?;
        points.push(measure(&scene, &camera, format!("{w}×{h}"))?);
    }
    out.push(Growth {
        title: "resolution (the demo)".into(),
        points,
        item: None,
    });
    log(&line(&out[0]));

    let mut points = Vec::new();
    for side in [1u32, 2, 4, 8] {
        let scene = ball_grid(side)?;
        let camera = front_camera(quarter.0, quarter.1)?;
        let label = match side * side {
            1 => "1 instance".to_string(),
            n => format!("{n} instances"),
        };
        points.push(measure(&scene, &camera, label)?);
    }
    out.push(Growth {
        title: format!(
            "instances (a grid of fog balls, {}×{})",
            quarter.0, quarter.1
        ),
        points,
        item: None,
    });
    log(&line(&out[1]));

    let mut points = Vec::new();
    for radius in [0.1f32, 0.2, 0.3, 0.4] {
        let spec = SnapshotSpec {
            occupancy: vec![Ball {
                centre: [0.5; 3],
                radius,
            }],
            ..SnapshotSpec::fog_sphere()
        };
        let path = write_snapshot(dir, "nerfx-bench-fill", &spec)?;
        let field = IngpField::load(&path);
        std::fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
        let handle = FieldHandle::new(Arc::new(field?));
        let scene = Scene::new(vec![Instance::new("fog", handle, DMat4::IDENTITY, None)?]);
        let camera = {
            let p = Perspective::from_vertical_fov(quarter.0, quarter.1, 40.0)?;
            let eye = DVec3::new(2.4, -3.0, 0.9).normalize() * 4.0;
            Camera::new(look_at(eye, DVec3::ZERO), Projection::Perspective(p))?
        };
        let label = format!("fill {:.1} %", 100.0 * occupied_fraction(&spec));
        points.push(measure(&scene, &camera, label)?);
    }
    out.push(Growth {
        title: format!(
            "occupancy fill (the trained fog's ball, radius 0.1 to 0.4, {}×{})",
            quarter.0, quarter.1
        ),
        points,
        item: None,
    });
    log(&line(&out[2]));

    out.push(super::setup::primitives(&[2_000, 20_000, 200_000])?);
    log(&line(&out[3]));
    out.push(super::setup::graph_nodes(&[100, 1_000, 4_000], dir)?);
    log(&line(&out[4]));
    Ok(out)
}

/// The CPU (or wall) time a point is measured over at least: the kernel counts CPU time in
/// 10 ms ticks, so small frames are rendered repeatedly.
const MIN_SECONDS: f64 = 0.5;

/// A frame of `scene` at [`PRESET`] (after a small render that builds the occupancy):
/// frames are rendered until [`MIN_SECONDS`] have passed, and their mean reported.
fn measure(scene: &Scene, camera: &Camera, label: String) -> Result<Point> {
    let settings = RenderSettings::new(PRESET.params(), Outputs::rgba());
    let full = camera.full_window();
    let corner = nerfx_core::image::Window::new(0, 0, full.width().min(16), full.height().min(16));
    render_with_progress(scene, camera, corner, &settings, &|_| {})?;
    let (t, cpu) = (Instant::now(), process_cpu_seconds());
    let spent = || {
        let wall = t.elapsed().as_secs_f64();
        (
            wall,
            cpu.zip(process_cpu_seconds()).map_or(wall, |(a, b)| b - a),
        )
    };
    let mut frames = 0u32;
    let stats = loop {
        let (_, stats) = render_with_progress(scene, camera, full, &settings, &|_| {})?;
        frames += 1;
        let (wall, cpu) = spent();
        if wall.max(cpu) >= MIN_SECONDS {
            break stats;
        }
    };
    let (wall, cpu_s) = spent();
    let n = f64::from(frames);
    Ok(Point {
        label,
        pixels: stats.pixels,
        samples: stats.density_samples,
        ms: wall * 1e3 / n,
        cpu_s: cpu_s / n,
        peak_heap: None,
    })
}

/// `side × side` fog balls, each its own instance, in a square of side 2 facing −y: the
/// balls shrink as they multiply, so they cover about the same part of the frame.
fn ball_grid(side: u32) -> Result<Scene> {
    let spacing = 2.0 / side as f64;
    let radius = 0.45 * spacing as f32;
    let ball = FieldHandle::analytic(Analytic {
        primitives: vec![Primitive {
            shape: Shape::Sphere {
                center: Vec3::ZERO,
                radius,
            },
            density: 1.5 / radius,
            color: ShColor::constant(Vec3::new(0.8, 0.5, 0.3)),
        }],
    });
    let mut instances = Vec::new();
    for i in 0..side {
        for k in 0..side {
            let at = DVec3::new(
                -1.0 + (i as f64 + 0.5) * spacing,
                0.0,
                -1.0 + (k as f64 + 0.5) * spacing,
            );
            instances.push(Instance::new(
                format!("ball {i},{k}"),
                ball.clone(),
                DMat4::from_translation(at),
                None,
            )?);
        }
    }
    Ok(Scene::new(instances))
}

/// A camera 4 units in front of the grid (on −y), looking at its centre.
fn front_camera(width: u32, height: u32) -> Result<Camera> {
    let p = Perspective::from_vertical_fov(width, height, 40.0)?;
    Camera::new(
        look_at(DVec3::new(0.0, -4.0, 0.0), DVec3::ZERO),
        Projection::Perspective(p),
    )
}

fn line(g: &Growth) -> String {
    let points: Vec<String> = g
        .points
        .iter()
        .map(|p| match g.item {
            Some(item) => format!(
                "{}: {:.2} µs/{item}{}",
                p.label,
                p.ns_per_sample() / 1e3,
                p.heap_per_item()
                    .map_or_else(String::new, |b| format!(", {b:.0} B heap/{item}"))
            ),
            None => format!("{}: {:.0} ns/sample", p.label, p.ns_per_sample()),
        })
        .collect();
    format!("{}: {}", g.title, points.join(", "))
}

/// The series as Markdown: one table per kind of growth.
pub fn markdown(growths: &[Growth]) -> String {
    let mut s = format!(
        "\n### Cost as content grows\n\n{} preset, RGBA, the mean of frames rendered for at \
         least {MIN_SECONDS} s after the occupancy is built. Work is density samples; cost is CPU time (all threads). Flat CPU time \
         per sample means cost grows no faster than the work.\n",
        PRESET.name()
    );
    for g in growths {
        if let Some(item) = g.item {
            s += &format!(
                "\n{} (set-up: CPU time per {item} flat means set-up grows no faster than the \
                 content; peak heap per {item}, where counted, flat means its memory does too):\n\n\
                 | content | {item}s | CPU s | CPU µs per {item} | peak heap B per {item} |\n\
                 |---|---:|---:|---:|---:|\n",
                g.title
            );
            for p in &g.points {
                s += &format!(
                    "| {} | {} | {:.3} | {:.2} | {} |\n",
                    p.label,
                    p.samples,
                    p.cpu_s,
                    p.ns_per_sample() / 1e3,
                    p.heap_per_item()
                        .map_or_else(|| "–".to_string(), |b| format!("{b:.0}"))
                );
            }
            continue;
        }
        s += &format!(
            "\n{}:\n\n| content | pixels | density samples/px | ms/frame | CPU s/frame | CPU µs/px \
             | CPU ns/sample |\n|---|---:|---:|---:|---:|---:|---:|\n",
            g.title
        );
        for p in &g.points {
            s += &format!(
                "| {} | {} | {:.1} | {:.0} | {:.2} | {:.2} | {:.0} |\n",
                p.label,
                p.pixels,
                p.samples as f64 / p.pixels.max(1) as f64,
                p.ms,
                p.cpu_s,
                p.us_per_pixel(),
                p.ns_per_sample()
            );
        }
    }
    s
}

/// Plots CPU time per sample against the work, one line per kind of growth, into
/// `cost_vs_content.png` in `dir`.
pub fn write_plot(growths: &[Growth], dir: &Path) -> Result<()> {
    let series: Vec<Series> = growths
        .iter()
        .filter(|g| g.item.is_none())
        .map(|g| Series {
            label: g.title.split(" (").next().unwrap_or(&g.title).to_string(),
            points: g
                .points
                .iter()
                .map(|p| (p.samples as f64 / 1e6, p.ns_per_sample()))
                .collect(),
        })
        .collect();
    plot_png(
        &dir.join("cost_vs_content.png"),
        "CPU time per sample as content grows",
        "density samples per frame (millions)",
        "CPU ns per density sample",
        &series,
        true,
    )
}
