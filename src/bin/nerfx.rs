//! `nerfx`: render the demo, render a scene through a shot for a frame range, describe a
//! field file, benchmark.
//!
//! A thin adapter: flags become the core's settings; the core does the work.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use glam::DVec3;
use nerfx::frames::{
    frame_path, parse_frames, read_shot, render_environment, render_frame, EnvironmentOrigin,
};
use nerfx::image::{write_exr, write_exr_layers, write_png_preview};
use nerfx::render::{ColorOutput, Outputs, Quality, RenderSettings};
use nerfx::scene::SceneDesc;
use nerfx::{bench, demo, Error, Result};

/// Counts heap bytes for `nerfx bench`'s peak-memory figures (off, one relaxed load per
/// allocation, outside a measurement).
#[global_allocator]
static HEAP: bench::memory::CountingAllocator = bench::memory::CountingAllocator;

#[derive(Parser)]
#[command(
    name = "nerfx",
    version,
    about = "Radiance fields for compositing pipelines"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render the embedded demo (analytic fields, no downloads): an object composited into
    /// its environment with a caught shadow and a depth merge, to EXR and PNG, with the
    /// scene, shot and node graph files it came from.
    Demo {
        /// Output folder.
        #[arg(short, long, default_value = "out")]
        out: PathBuf,
        /// Image width.
        #[arg(long, default_value_t = 1280)]
        width: u32,
        /// Image height.
        #[arg(long, default_value_t = 720)]
        height: u32,
        /// Quality preset.
        #[arg(long, value_enum, default_value_t = Quality::Final)]
        quality: Quality,
    },
    /// Render a scene file through a shot file, or a node graph (`comp.json`) through the
    /// OpenFX bundle, for a list of frames.
    Render {
        /// Scene file (JSON) or one field or splat file (`.ingp`; `.ply`, `.splat`, `.spz`,
        /// `.sog`; a nerfstudio run directory), or a node graph file when no shot is given.
        scene: PathBuf,
        /// Shot file (JSON, written by the Blender add-on), or a nerfstudio camera_path.json.
        shot: Option<PathBuf>,
        /// With a nerfstudio camera path: the scene's object the path's frame belongs to.
        #[arg(long, default_value = "NeRF")]
        nerf_object: String,
        /// Frames: `1001-1010`, `1001-1100x5`, `1,5,9`. Default: every frame of the shot (for a
        /// graph: the frames every NeRF Render it needs can make).
        #[arg(long)]
        frames: Option<String>,
        /// Output EXR pattern; `####` becomes the zero-padded frame number.
        #[arg(short, long, default_value = "out/render.####.exr")]
        output: PathBuf,
        /// Quality preset.
        #[arg(long, value_enum, default_value_t = Quality::Final)]
        quality: Quality,
        /// Scenes: scene-linear colour, or the composite as the trainer shows it (display
        /// referred; graphs set the NeRF Render node's Colour parameter instead).
        #[arg(long, value_enum, default_value_t = ColorOutput::Linear)]
        colour: ColorOutput,
        /// Scenes whose shot has motion blur: renders per frame over the shutter (default: the
        /// quality preset's, 4 / 8 / 16).
        #[arg(long)]
        shutter_samples: Option<u32>,
        /// Also write a PNG preview beside each EXR.
        #[arg(long)]
        png: bool,
        /// Scenes: the passes to render and write, comma-separated (default: all). A pass not
        /// asked for is not written, and the work only it needs is skipped (graphs choose each
        /// NeRF Render node's output instead).
        #[arg(long, value_enum, value_delimiter = ',')]
        passes: Option<Vec<Pass>>,
        /// Graphs: the OpenFX bundle (default: $NERFX_OFX_BUNDLE, then nerfx.ofx.bundle in
        /// each folder of $OFX_PLUGIN_PATH, beside this program, and in /usr/OFX/Plugins).
        #[arg(long)]
        bundle: Option<PathBuf>,
        /// Graphs: render scale in (0, 1] (0.5: half-resolution proxies).
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
    },
    /// Render an environment map (2:1 equirectangular EXR, linear HDR) of a scene from a point,
    /// laid out as Blender's World Environment Texture reads it, to relight a Blender scene as
    /// the field would.
    Envmap {
        /// Scene file (JSON) or one field or splat file (`.ingp`; `.ply`, `.splat`, `.spz`,
        /// `.sog`; a nerfstudio run).
        scene: PathBuf,
        /// Shot file, or a nerfstudio camera_path.json: places object-bound instances.
        shot: PathBuf,
        /// The shot's frame (default: its first).
        #[arg(long)]
        frame: Option<i64>,
        /// Render from this object's origin (an object of the shot, e.g. the NeRF object).
        #[arg(long, conflicts_with = "position")]
        at: Option<String>,
        /// Render from this world position: `x,y,z`.
        #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
        position: Option<Vec<f64>>,
        /// With a nerfstudio camera path: the scene's object the path's frame belongs to.
        #[arg(long, default_value = "NeRF")]
        nerf_object: String,
        /// Image height in pixels (the width is twice it).
        #[arg(long, default_value_t = 1024)]
        height: u32,
        /// Quality preset.
        #[arg(long, value_enum, default_value_t = Quality::Final)]
        quality: Quality,
        /// Output EXR.
        #[arg(short, long, default_value = "out/envmap.exr")]
        output: PathBuf,
    },
    /// Describe a field file: format, architecture, parameters, bounds, occupancy; for splats
    /// the format and version, count, SH degree, quantisation, bounds, opacity and scale
    /// ranges and memory once loaded.
    Info {
        /// The field file (instant-ngp `.ingp` or `.msgpack`, a nerfstudio run, or a splat
        /// `.ply`, `.splat`, `.spz`, `.sog` or SOG `meta.json`).
        field: PathBuf,
    },
    /// Write a stand-in point cloud (binary PLY) of a field or splat file, in the frame nerfx
    /// renders it in, to place the NeRF object by in Blender.
    ExportStandin {
        /// The field: an instant-ngp snapshot, a nerfacto run, a splat file (`.ply`, `.splat`,
        /// `.spz`, `.sog`, a SOG `meta.json`) or a splatfacto run.
        field: PathBuf,
        /// Output PLY.
        #[arg(short, long, default_value = "standin.ply")]
        output: PathBuf,
        /// Points at most.
        #[arg(long, default_value_t = 200_000)]
        points: usize,
        /// Grid cells along the field's longest side (at most 256).
        #[arg(long, default_value_t = 256)]
        resolution: u32,
        /// Opacity over a cell (or a splat's opacity) a point must exceed.
        #[arg(long, default_value_t = 0.5)]
        threshold: f32,
        /// Also write a triangle mesh (binary PLY) of the field's surface here.
        #[arg(long)]
        mesh: Option<PathBuf>,
    },
    /// Measure run time, work, error and heap of each preset and a naive marcher on a suite
    /// of scenes (analytic, trained fog, trained blob, thin sheets, splats).
    Bench {
        /// Output folder for the table (Markdown) and the plots (PNG).
        #[arg(short, long, default_value = "bench-out")]
        out: PathBuf,
        /// Image width.
        #[arg(long, default_value_t = 1920)]
        width: u32,
        /// Image height.
        #[arg(long, default_value_t = 1080)]
        height: u32,
        /// Timed repetitions per configuration: the suite reports the median (default 1),
        /// `--splats` and `--passes` the best (default 3).
        #[arg(long)]
        repeats: Option<u32>,
        /// The scenes to run (default: all, and the cost-growth series), comma-separated.
        #[arg(long, value_enum, value_delimiter = ',')]
        scene: Vec<bench::SceneKind>,
        /// Also run the cost-growth series (resolution, instances, occupancy fill) when
        /// `--scene` selects scenes.
        #[arg(long)]
        scaling: bool,
        /// Time splat rasterisation instead: a generated capture-like scene of this many
        /// splats (SH degree 3), and each `--ply` file, one RGBA frame each (best of
        /// `repeats`); each file's load is timed and its memory counted too.
        #[arg(long)]
        splats: Option<usize>,
        /// Splat files (any format nerfx reads) to time with `--splats`; the first is also
        /// the suite's splat scene (else generated splats).
        #[arg(long)]
        ply: Vec<PathBuf>,
        /// Time what extra passes of one field cost instead: NeRF Render nodes asking RGBA
        /// alone, RGBA and depth Z, and every output of the demo frame, at this preset.
        #[arg(long, value_enum)]
        passes: Option<Quality>,
    },
    /// Print a reference page of the user's guide, generated from the code: `nodes` (every
    /// node and parameter, from the node registry) or `cli` (every command and option).
    #[command(hide = true)]
    Reference {
        /// Which page.
        #[arg(value_enum)]
        page: ReferencePage,
    },
}

/// The guide's generated reference pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum ReferencePage {
    /// `docs/src/reference/nodes.md`.
    Nodes,
    /// `docs/src/reference/cli.md`.
    Cli,
}

/// A pass `nerfx render --passes` names (as the NeRF Render node's Output names them), and
/// the EXR channels it writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Pass {
    /// Premultiplied colour and its alpha: `R`, `G`, `B`, `A`.
    Rgba,
    /// The accumulation alone, a matte: `A`.
    Accumulation,
    /// Expected depth as camera Z: `Z`.
    #[value(name = "depthZ")]
    DepthZ,
    /// Expected depth as ray distance: `depth.ray`.
    #[value(name = "depthRay")]
    DepthRay,
    /// Median depth (ray distance): `depth.median`.
    #[value(name = "depthMedian")]
    DepthMedian,
}

impl Pass {
    /// The planes `passes` ask for.
    fn outputs(passes: &[Pass]) -> Outputs {
        let has = |p: Pass| passes.contains(&p);
        Outputs {
            rgb: has(Pass::Rgba),
            alpha: has(Pass::Rgba) || has(Pass::Accumulation),
            depth_z: has(Pass::DepthZ),
            depth_ray: has(Pass::DepthRay),
            depth_median: has(Pass::DepthMedian),
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("nerfx: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Demo {
            out,
            width,
            height,
            quality,
        } => {
            create_dir(&out)?;
            let started = Instant::now();
            let comp = demo::render_comp(&out, width, height, quality)?;
            for (node, warning) in &comp.warnings {
                eprintln!("nerfx: warning: demo node {node}: {warning}");
            }
            let layers: Vec<(&str, &_)> =
                comp.layers.iter().map(|(n, p)| (n.as_str(), p)).collect();
            write_exr_layers(&out.join("demo.exr"), &comp.image, &layers, 1.0)?;
            write_png_preview(&out.join("demo.png"), &comp.image)?;
            println!(
                "demo: {width}×{height} {} in {:.2} s → {} (and demo.png; its graph: {})",
                quality.name(),
                started.elapsed().as_secs_f64(),
                out.join("demo.exr").display(),
                comp.graph.display()
            );
            Ok(())
        }
        Command::Render {
            scene,
            shot,
            nerf_object,
            frames,
            output,
            quality,
            colour,
            shutter_samples,
            png,
            passes,
            bundle,
            scale,
        } => {
            let frames = frames.as_deref().map(parse_frames).transpose()?;
            let Some(shot) = shot else {
                if passes.is_some() {
                    return Err(Error::invalid(
                        "--passes",
                        "a graph's NeRF Render nodes choose their own outputs",
                    ));
                }
                return graph::render(&scene, frames, &output, png, bundle, scale);
            };
            let outputs = passes.as_deref().map_or_else(Outputs::all, Pass::outputs);
            if png && !outputs.rgb {
                return Err(Error::invalid(
                    "--png",
                    "the preview is of the colour: add rgba to --passes",
                ));
            }
            let scene = SceneDesc::for_path(&scene)?.load()?;
            for warning in scene.warnings() {
                eprintln!("nerfx: warning: {warning}");
            }
            let shot = read_shot(&shot, &nerf_object)?;
            let frames = frames.unwrap_or_else(|| shot.frames.iter().map(|f| f.frame).collect());
            let shutter_samples = match shutter_samples {
                None => quality.shutter_samples(),
                Some(n @ 1..=1024) => n,
                Some(n) => {
                    return Err(Error::invalid(
                        "--shutter-samples",
                        format!("{n}; expected 1 to 1024"),
                    ))
                }
            };
            let settings = RenderSettings {
                color: colour,
                shutter_samples,
                ..RenderSettings::new(quality.params(), outputs)
            };
            let bar = progress_bar(frames.len() as u64, "frames");
            for &frame in &frames {
                let path = frame_path(&output, frame, frames.len() > 1);
                if let Some(dir) = path.parent() {
                    create_dir(dir)?;
                }
                let (planes, stats) = render_frame(&scene, &shot, frame, &settings, &|_| {})?;
                if let Some(warning) = stats.warning() {
                    bar.suspend(|| eprintln!("nerfx: warning: frame {frame}: {warning}"));
                }
                let pixel_aspect = shot.pixel_aspect_for(&shot.frame(frame)?.camera(&shot)?);
                write_exr_layers(&path, &planes, &[], pixel_aspect)?;
                if png {
                    write_png_preview(&path.with_extension("png"), &planes)?;
                }
                bar.inc(1);
                bar.suspend(|| println!("frame {frame} → {}", path.display()));
            }
            bar.finish_and_clear();
            Ok(())
        }
        Command::Envmap {
            scene,
            shot,
            frame,
            at,
            position,
            nerf_object,
            height,
            quality,
            output,
        } => {
            let origin = match (at, position) {
                (Some(name), _) => EnvironmentOrigin::Object(name),
                (None, Some(p)) => match p[..] {
                    [x, y, z] => EnvironmentOrigin::Position(DVec3::new(x, y, z)),
                    _ => {
                        return Err(Error::invalid(
                            "envmap --position",
                            format!("{} numbers given; expected x,y,z", p.len()),
                        ))
                    }
                },
                (None, None) => {
                    return Err(Error::invalid(
                        "envmap",
                        "say where to render from: --at OBJECT or --position x,y,z",
                    ))
                }
            };
            let scene = SceneDesc::for_path(&scene)?.load()?;
            for warning in scene.warnings() {
                eprintln!("nerfx: warning: {warning}");
            }
            let shot = read_shot(&shot, &nerf_object)?;
            let frame = match frame {
                Some(f) => f,
                None => shot
                    .frames
                    .first()
                    .map(|f| f.frame)
                    .ok_or_else(|| Error::invalid("shot", "has no frames"))?,
            };
            if let Some(dir) = output.parent() {
                create_dir(dir)?;
            }
            let settings = RenderSettings::new(quality.params(), Outputs::all());
            let bar = progress_bar(2 * u64::from(height) * u64::from(height), "envmap");
            let (planes, stats) =
                render_environment(&scene, &shot, frame, &origin, height, &settings, &|n| {
                    bar.inc(n)
                })?;
            bar.finish_and_clear();
            if let Some(warning) = stats.warning() {
                eprintln!("nerfx: warning: envmap: {warning}");
            }
            write_exr(&output, &planes)?;
            println!("envmap: frame {frame} → {}", output.display());
            Ok(())
        }
        Command::Reference { page } => {
            match page {
                ReferencePage::Nodes => {
                    let descs: Vec<_> = nerfx::graph::nodes().iter().map(|n| &n.desc).collect();
                    print!("{}", nerfx::graph::nodes_markdown(&descs));
                }
                ReferencePage::Cli => print!("{}", cli_markdown()),
            }
            Ok(())
        }
        Command::Info { field } => {
            println!("{}", nerfx::field::describe(&field)?);
            Ok(())
        }
        Command::ExportStandin {
            field,
            output,
            points,
            resolution,
            threshold,
            mesh,
        } => {
            let started = Instant::now();
            let scene = SceneDesc::for_path(&field)?
                .load()?
                .place(glam::DMat4::IDENTITY, &|_| Ok(glam::DMat4::IDENTITY))?;
            let cloud = nerfx::standin::points(&scene, resolution, threshold, points);
            nerfx::standin::write_ply(&output, &cloud)?;
            println!(
                "export-standin: {} points in {:.2} s → {}",
                cloud.len(),
                started.elapsed().as_secs_f64(),
                output.display()
            );
            if let Some(mesh_path) = mesh {
                if scene.field_instances().next().is_none() {
                    return Err(Error::invalid(
                        field.display().to_string(),
                        "splats have no density grid to mesh; use the point stand-in",
                    ));
                }
                let surface = nerfx::standin::mesh(&scene, resolution, threshold);
                nerfx::standin::write_mesh_ply(&mesh_path, &surface)?;
                println!(
                    "export-standin: a mesh of {} vertices, {} triangles in {:.2} s → {}",
                    surface.vertices.len(),
                    surface.triangles.len(),
                    started.elapsed().as_secs_f64(),
                    mesh_path.display()
                );
            }
            Ok(())
        }
        Command::Bench {
            passes: Some(quality),
            out,
            width,
            height,
            repeats,
            ..
        } => {
            create_dir(&out)?;
            let preset = quality.name();
            let timings =
                bench::passes::time_passes(&out, width, height, quality, repeats.unwrap_or(3))?;
            println!("| outputs ({preset}, {width}×{height}) | ms | marches | × RGBA |");
            println!("|---|---:|---:|---:|");
            let alone = timings.first().map_or(f64::NAN, |t| t.ms);
            for t in &timings {
                println!(
                    "| {} | {:.0} | {} | {:.2} |",
                    t.outputs.join(" + "),
                    t.ms,
                    t.marched,
                    t.ms / alone
                );
            }
            Ok(())
        }
        Command::Bench {
            splats: Some(n),
            ply,
            out,
            width,
            height,
            repeats,
            ..
        } => {
            use nerfx::bench::memory::peak_during;
            use nerfx::bench::splats::{generated_splats, time_load, time_splats};
            let mib = |b: f64| b / (1 << 20) as f64;
            let generated = generated_splats(n);
            create_dir(&out)?;
            let (load_s, file_bytes) = time_load(&generated, &out)?;
            println!(
                "load: {n} capture-like splats, a {:.1} MiB PLY, read in {:.2} s ({:.2} s per \
                 million)",
                mib(file_bytes as f64),
                load_s,
                load_s * 1e6 / n.max(1) as f64
            );
            let mut sets = vec![(format!("generated, {n} capture-like splats"), generated)];
            if !ply.is_empty() {
                println!(
                    "\n| file | format | splats | load (s) | s per million | peak while \
                     loading (MiB) | held once loaded (MiB) | splats' arrays (MiB) |"
                );
                println!("|---|---|---:|---:|---:|---:|---:|---:|");
            }
            for path in ply {
                let (loaded, heap) = peak_during(|| {
                    let start = Instant::now();
                    nerfx::field::Splats::load(&path).map(|s| (s, start.elapsed().as_secs_f64()))
                });
                let (splats, seconds) = loaded?;
                let (peak, kept) = heap.map_or((f64::NAN, f64::NAN), |h| {
                    (mib(h.peak as f64), mib(h.kept as f64))
                });
                let version = splats
                    .source
                    .version
                    .map_or_else(String::new, |v| format!(" {v}"));
                println!(
                    "| {} | {}{version} | {} | {seconds:.2} | {:.2} | {peak:.1} | {kept:.1} | \
                     {:.1} |",
                    path.display(),
                    splats.source.format,
                    splats.len(),
                    seconds * 1e6 / splats.len().max(1) as f64,
                    mib(splats.memory_bytes() as f64),
                );
                sets.push((path.display().to_string(), splats));
            }
            println!(
                "\n| splats | frame (ms) | projection (ms) | sort + bin (ms) | blending (ms) | \
                 fragments / pixel | splats (MiB) | peak while rendering (MiB) |"
            );
            println!("|---|---:|---:|---:|---:|---:|---:|---:|");
            for (name, splats) in sets {
                let (timing, heap) = peak_during(|| {
                    time_splats(
                        std::sync::Arc::new(splats),
                        width,
                        height,
                        repeats.unwrap_or(3),
                    )
                });
                let t = timing?;
                let blending = t.frame_ms - t.projection_ms - t.binning_ms;
                println!(
                    "| {name} ({}) at {width}×{height} | {:.0} | {:.0} | {:.0} | {blending:.0} | \
                     {:.1} | {:.1} | {:.1} |",
                    t.splats,
                    t.frame_ms,
                    t.projection_ms,
                    t.binning_ms,
                    t.fragments_per_pixel,
                    mib(t.memory_bytes as f64),
                    heap.map_or(f64::NAN, |h| mib(h.peak as f64)),
                );
            }
            Ok(())
        }
        Command::Bench {
            out,
            width,
            height,
            repeats,
            scene,
            ply,
            scaling,
            ..
        } => {
            create_dir(&out)?;
            let options = bench::SuiteOptions {
                width,
                height,
                repeats: repeats.unwrap_or(1),
                scaling: scaling || scene.is_empty(),
                scenes: if scene.is_empty() {
                    bench::SceneKind::ALL.to_vec()
                } else {
                    scene
                },
                splats: ply.into_iter().next(),
            };
            let report = bench::run(&options, &out, &|line| eprintln!("{line}"))?;
            report.write(&out)?;
            println!("{}", report.markdown());
            println!("wrote {}", out.display());
            Ok(())
        }
    }
}

/// Graph rendering through the OpenFX host and bundle (`host` feature).
#[cfg(feature = "host")]
mod graph {
    use super::*;
    use nerfx::graph::Graph;
    use nerfx::host::Bundle;
    use nerfx::host::OfxGraph;

    /// Where the bundle is looked for, in order.
    fn bundle_candidates(given: Option<PathBuf>) -> Vec<PathBuf> {
        if let Some(path) = given {
            return vec![path];
        }
        let name = "nerfx.ofx.bundle";
        let mut places: Vec<PathBuf> = std::env::var_os("NERFX_OFX_BUNDLE")
            .map(PathBuf::from)
            .into_iter()
            .collect();
        if let Some(paths) = std::env::var_os("OFX_PLUGIN_PATH") {
            places.extend(std::env::split_paths(&paths).map(|dir| dir.join(name)));
        }
        if let Some(dir) = std::env::current_exe()
            .ok()
            .and_then(|e| e.parent().map(Path::to_path_buf))
        {
            places.push(dir.join(name));
        }
        places.push(Path::new("/usr/OFX/Plugins").join(name));
        places
    }

    fn load_bundle(given: Option<PathBuf>) -> Result<Bundle> {
        let places = bundle_candidates(given);
        match places.iter().find(|p| p.exists()) {
            Some(path) => Bundle::load(path),
            None => Err(Error::invalid(
                "OpenFX bundle",
                format!(
                    "nerfx.ofx.bundle not found (looked at {}); build it with `bash bundle/build.sh` \
                     or pass --bundle",
                    places
                        .iter()
                        .map(|p| p.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
        }
    }

    /// Renders `frames` of the graph at `path`: the output node as `R G B A`, each layer as
    /// `layer.R …`, through the bundle's plugins.
    pub fn render(
        path: &Path,
        frames: Option<Vec<i64>>,
        output: &Path,
        png: bool,
        bundle: Option<PathBuf>,
        scale: f64,
    ) -> Result<()> {
        let graph = Graph::read(path)?;
        let nodes = graph.needed().iter().filter(|&&n| n).count();
        let mut graph = OfxGraph::new(graph, &load_bundle(bundle)?)?;
        let frames = match frames {
            Some(frames) => frames,
            None => match graph.time_domain()? {
                Some((first, last)) => (first.ceil() as i64..=last.floor() as i64).collect(),
                None => {
                    return Err(Error::invalid(
                        format!("{}", path.display()),
                        "no node of the graph has a frame range of its own: give --frames",
                    ))
                }
            },
        };
        let frames = frames.as_slice();
        let (first, last) = match (frames.iter().min(), frames.iter().max()) {
            (Some(&a), Some(&b)) => (a as f64, b as f64),
            _ => return Ok(()),
        };
        graph.begin_sequence(first, last, scale)?;
        let bar = progress_bar((frames.len() * nodes) as u64, "nodes");
        // The sequence is ended on every path, a failed frame included.
        let target = |frame| frame_path(output, frame, frames.len() > 1);
        let rendered = frames.iter().try_for_each(|&frame| {
            render_frame(&mut graph, frame, &target(frame), png, scale, &bar)
        });
        bar.finish_and_clear();
        let ended = graph.end_sequence(first, last, scale);
        rendered.and(ended)
    }

    /// One frame of the graph written to `target`.
    fn render_frame(
        graph: &mut OfxGraph,
        frame: i64,
        target: &Path,
        png: bool,
        scale: f64,
        bar: &ProgressBar,
    ) -> Result<()> {
        if let Some(dir) = target.parent() {
            create_dir(dir)?;
        }
        let images = graph.render(frame as f64, scale, false, &|node| {
            bar.set_message(format!("frame {frame} {node}"));
            bar.inc(1);
        })?;
        // The plugin's text names the frame.
        for (node, warning) in graph.warnings() {
            bar.suspend(|| eprintln!("nerfx: warning: graph node {node}: {warning}"));
        }
        let image = |name: &str| {
            images
                .get(name)
                .ok_or_else(|| Error::invalid(format!("graph node {name}"), "was not rendered"))
        };
        let main = image(&graph.graph().output)?;
        let layers = graph
            .graph()
            .layers
            .iter()
            .map(|(layer, node)| Ok((layer.as_str(), image(node)?)))
            .collect::<Result<Vec<_>>>()?;
        let pixel_aspect = graph.pixel_aspect(&graph.graph().output);
        write_exr_layers(target, main, &layers, pixel_aspect)?;
        if png {
            write_png_preview(&target.with_extension("png"), main)?;
        }
        bar.suspend(|| println!("frame {frame} → {}", target.display()));
        Ok(())
    }
}

/// Without the `host` feature there is no OpenFX host to render graphs with.
#[cfg(not(feature = "host"))]
mod graph {
    use super::*;

    pub fn render(
        path: &Path,
        _: Option<Vec<i64>>,
        _: &Path,
        _: bool,
        _: Option<PathBuf>,
        _: f64,
    ) -> Result<()> {
        Err(Error::Unsupported(format!(
            "{}: rendering a node graph needs the OpenFX host; this nerfx was built without it \
             (build with `cargo build --release --features host`)",
            path.display()
        )))
    }
}

fn create_dir(dir: &Path) -> Result<()> {
    if dir.as_os_str().is_empty() {
        return Ok(());
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))
}

fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {percent}% {elapsed}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}

/// The command-line reference page, from the argument definitions.
fn cli_markdown() -> String {
    use clap::CommandFactory;
    use std::fmt::Write;
    let mut cli = Cli::command();
    cli.build();
    let mut md = String::from(
        "# Command-line reference\n\n\
         Generated from the argument definitions by `nerfx reference cli`; do not edit by \
         hand. `nerfx help COMMAND` prints the same.\n",
    );
    for sub in cli.get_subcommands_mut().filter(|c| !c.is_hide_set()) {
        let name = sub.get_name().to_string();
        let about = sub
            .get_long_about()
            .or(sub.get_about())
            .map(|a| a.to_string())
            .unwrap_or_default();
        let usage = sub.render_usage().to_string();
        let usage = usage.trim_start_matches("Usage: ");
        let _ = write!(
            md,
            "\n## `nerfx {name}`\n\n{about}\n\n```text\n{usage}\n```\n"
        );
        let args: Vec<_> = sub
            .get_arguments()
            .filter(|a| !a.is_hide_set() && a.get_id() != "help")
            .collect();
        if args.is_empty() {
            continue;
        }
        md.push_str("\n| argument | default | what it is |\n|---|---|---|\n");
        for arg in args {
            let value = arg
                .get_value_names()
                .map(|v| {
                    v.iter()
                        .map(|s| s.to_string())
                        .collect::<Vec<_>>()
                        .join(" ")
                })
                .unwrap_or_else(|| arg.get_id().to_string().to_uppercase());
            let takes_value = arg.get_num_args().is_some_and(|n| n.takes_values());
            let shown = match (arg.get_short(), arg.get_long()) {
                (Some(s), Some(l)) if takes_value => format!("`-{s}`, `--{l} {value}`"),
                (Some(s), Some(l)) => format!("`-{s}`, `--{l}`"),
                (None, Some(l)) if takes_value => format!("`--{l} {value}`"),
                (None, Some(l)) => format!("`--{l}`"),
                (Some(s), None) => format!("`-{s}`"),
                (None, None) => format!("`{value}`"),
            };
            let defaults: Vec<String> = arg
                .get_default_values()
                .iter()
                .map(|d| d.to_string_lossy().into_owned())
                .collect();
            let mut help = arg
                .get_long_help()
                .or(arg.get_help())
                .map(|h| h.to_string())
                .unwrap_or_default();
            let values: Vec<String> = arg
                .get_possible_values()
                .iter()
                .filter(|v| !v.is_hide_set())
                .map(|v| format!("`{}`", v.get_name()))
                .collect();
            if !values.is_empty() && takes_value {
                let _ = write!(help, " One of {}.", values.join(", "));
            }
            let help = help
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" ")
                .replace('|', "\\|");
            let default = if defaults.is_empty() {
                String::new()
            } else {
                format!("`{}`", defaults.join(","))
            };
            let _ = writeln!(md, "| {shown} | {default} | {help} |");
        }
    }
    md
}
