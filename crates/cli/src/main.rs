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
use nerfx::farm::{is_done, ExitStatus, FarmJob, Progress, Stripe};
use nerfx::frames::{frame_path, parse_frames};
use nerfx_core::camera::read_shot;
use nerfx_core::image::{
    frames_per_second, write_deep_exr, write_exr, write_exr_layers, write_png_preview,
    CameraMatrices, ExrHeader, OutputColorSpace,
};
use nerfx_core::render::{ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::scene::SceneDesc;
use nerfx_core::shot_render::{
    render_coverage, render_environment, render_frame, EnvironmentOrigin, FrameRequest,
};
use nerfx_core::{demo, Error, Result};
use nerfx_testkit::bench;

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
        /// Scenes: the colour space the EXR is written in (default: the scene file's
        /// `colorspace`, else lin_rec709); its primaries go into the EXR's `chromaticities`
        /// (graphs: the graph's `colorspace` and each NeRF Render node's Output Colour Space).
        #[arg(long, value_enum)]
        colorspace: Option<OutputColorSpace>,
        /// Also write Cryptomatte object mattes (layers CryptoObject00, … with an ID per scene
        /// instance name, and the manifest in the header); graphs: of every NeRF Render node
        /// the output needs, unless the graph file's `cryptomatte` names the nodes itself.
        #[arg(long)]
        cryptomatte: bool,
        /// With Cryptomatte: ID–coverage pairs kept per pixel (two per layer).
        #[arg(long, default_value_t = nerfx_core::image::cryptomatte::DEFAULT_RANKS)]
        cryptomatte_ranks: usize,
        /// Scenes whose shot has motion blur: renders per frame over the shutter (default: the
        /// quality preset's, 4 / 8 / 16).
        #[arg(long)]
        shutter_samples: Option<u32>,
        /// Scenes whose shot's camera has depth of field: points of the aperture each shutter
        /// time is rendered through (default: the quality preset's, 4 / 16 / 64).
        #[arg(long)]
        aperture_samples: Option<u32>,
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
        /// Skip a frame whose output reads back whole and was written after its inputs last
        /// changed (a farm task run again renders only what it has not finished).
        #[arg(long)]
        resume: bool,
        /// How progress is reported: a line per frame, or Open Job Description's
        /// `openjd_progress:` and `openjd_status:` lines as well.
        #[arg(long, value_enum, default_value_t = Progress::Plain)]
        progress: Progress,
        /// Render stripe K of N of each frame (`2/4`), to the frame's name with `.stripe2of4`
        /// before the extension; `nerfx assemble` joins the stripes.
        #[arg(long)]
        stripe: Option<String>,
        /// Scenes: also write a deep scanline EXR per frame to this pattern (`####`: the
        /// frame number), beside the flat one: samples R G B A Z ZBack that flatten to the
        /// flat render (Nuke: DeepRead). Needs a build with OpenEXR (libopenexr-dev).
        #[arg(long)]
        deep: Option<PathBuf>,
        /// With --deep: most samples a deep pixel keeps, 1 to 4096 (default: the quality
        /// preset's, 8 / 16 / 32).
        #[arg(long)]
        deep_samples: Option<u32>,
    },
    /// Join the stripes of frames rendered with `nerfx render --stripe K/N` into the frames,
    /// bit for bit the whole-frame render, every pass and layer, and remove the stripes.
    Assemble {
        /// Frames: `1001-1010`, `1001-1100x5`, `1,5,9`.
        #[arg(long)]
        frames: String,
        /// How many stripes each frame was rendered in.
        #[arg(long)]
        split_frame: u32,
        /// Output EXR pattern, as given to `nerfx render`.
        #[arg(short, long)]
        output: PathBuf,
        /// How progress is reported.
        #[arg(long, value_enum, default_value_t = Progress::Plain)]
        progress: Progress,
    },
    /// Write a render job for a farm engine: a Slurm job array, an Open Job Description
    /// template (and Deadline Cloud job bundle), or an OpenCue PyOutline script.
    Farm {
        #[command(subcommand)]
        engine: FarmEngine,
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
        /// Time splat loading and rasterisation instead: a generated capture-like scene of
        /// this many splats (SH degree 3, written as `generated_N.ply` in the output folder and
        /// read back), and each `--ply` file; a table of loads (time, decoded size, heap) and
        /// one of RGBA frames (best of `repeats`).
        #[arg(long)]
        splats: Option<usize>,
        /// Splat files (any format nerfx reads) to time with `--splats`; the first is also the
        /// suite's splat scene (else generated splats).
        #[arg(long)]
        ply: Vec<PathBuf>,
        /// Time what extra passes of one field cost instead: NeRF Render nodes asking RGBA
        /// alone, RGBA and depth Z, and every output of the demo frame, at this preset.
        #[arg(long, value_enum)]
        passes: Option<Quality>,
        /// Time deep output instead: each scene (`--scene`, default all) rendered flat and
        /// deep at this preset, written as EXRs: the deep file's samples per pixel (mean,
        /// max), both files' sizes and both times (best of `repeats`).
        #[arg(long, value_enum)]
        deep: Option<Quality>,
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

/// The engines `nerfx farm` writes jobs for.
#[derive(Subcommand)]
enum FarmEngine {
    /// An `sbatch` job-array script: one array task per chunk (per chunk and stripe with
    /// `--split-frame`, and a second array, dependent on the first, joining the stripes).
    Slurm {
        #[command(flatten)]
        job: FarmArgs,
        /// Write the script here (default: standard output; with `--split-frame` or
        /// `--submit`, beside the logs). The joining array's script goes beside it
        /// (`job.assemble.sh`).
        #[arg(long)]
        script: Option<PathBuf>,
        /// Slurm partition.
        #[arg(long)]
        partition: Option<String>,
        /// At most this many array tasks run at once.
        #[arg(long)]
        max_running: Option<u32>,
        /// The tasks' logs (one per task; default: `logs` in the output folder).
        #[arg(long)]
        log_dir: Option<PathBuf>,
        /// Submit with `sbatch`; the last line printed is `submitted job <id>`.
        #[arg(long)]
        submit: bool,
    },
    /// An Open Job Description job template (`jobtemplate-2023-09`) for `openjd run` and AWS
    /// Deadline Cloud.
    Openjd {
        #[command(flatten)]
        job: FarmArgs,
        /// Write the template here (default: standard output), and beside it the values of
        /// its path parameters for `openjd run -p file://…` (`job.yaml` →
        /// `job.parameters.yaml`).
        #[arg(long)]
        template: Option<PathBuf>,
        /// Also write a Deadline Cloud job bundle in this folder: `template.yaml`,
        /// `parameter_values.yaml`, `asset_references.yaml` (submit it with
        /// `deadline bundle submit DIR`).
        #[arg(long)]
        bundle: Option<PathBuf>,
    },
    /// An OpenCue PyOutline script (submit it with `pycuerun`).
    Opencue {
        #[command(flatten)]
        job: FarmArgs,
        /// Write the script here (default: standard output).
        #[arg(long)]
        script: Option<PathBuf>,
    },
}

/// What every engine's job takes.
#[derive(clap::Args)]
struct FarmArgs {
    /// What `nerfx render` takes: a scene file and a shot file, or a node graph file.
    #[arg(required = true, num_args = 1..=2)]
    inputs: Vec<PathBuf>,
    /// Frames: `1001-1100`, `1001-1100x5`, `1,5,9`.
    #[arg(long)]
    frames: String,
    /// Frames per task.
    #[arg(long, default_value_t = 10)]
    chunk: usize,
    /// Output EXR pattern; `####` becomes the zero-padded frame number.
    #[arg(short, long)]
    output: PathBuf,
    /// Render each frame as this many stripes, each a task of its own, and join them in a last
    /// step.
    #[arg(long, default_value_t = 1)]
    split_frame: u32,
    /// CPUs a task asks for.
    #[arg(long)]
    cpus: Option<u32>,
    /// Memory a task asks for, in MiB.
    #[arg(long)]
    mem: Option<u64>,
    /// How often a task that failed transiently (exit 75) may run again.
    #[arg(long, default_value_t = 2)]
    retries: u32,
    /// The nerfx program the workers run (default: this one).
    #[arg(long)]
    program: Option<PathBuf>,
    /// Further `nerfx render` options, after `--` (`-- --quality draft --passes rgba`).
    #[arg(last = true)]
    render_args: Vec<String>,
}

impl FarmArgs {
    fn job(&self) -> Result<FarmJob> {
        let mut job = FarmJob::new(
            &self.inputs,
            &self.frames,
            self.chunk,
            &self.output,
            self.split_frame,
        )?;
        if let Some(program) = &self.program {
            job.program = std::path::absolute(program).map_err(|e| Error::io(program, e))?;
        }
        job.render_args = self.render_args.clone();
        job.cpus = self.cpus;
        job.memory_mib = self.mem;
        job.retries = self.retries;
        if let [scene, _shot] = &job.inputs[..] {
            job.sources = SceneDesc::for_path(scene)?.sources();
        }
        job.check()?;
        Ok(job)
    }
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
            ExitCode::from(ExitStatus::of(&e).code())
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
            let comp = nerfx_graph::demo::render_comp(&out, width, height, quality)?;
            for (node, warning) in &comp.warnings {
                eprintln!("nerfx: warning: demo node {node}: {warning}");
            }
            let layers: Vec<(&str, &_)> =
                comp.layers.iter().map(|(n, p)| (n.as_str(), p)).collect();
            // The demo renders its shot's first frame.
            let shot = demo::shot(width, height);
            let camera = shot.frame(demo::FIRST_FRAME)?.camera(&shot)?;
            let header = ExrHeader {
                camera: Some(CameraMatrices::of(&camera)),
                frames_per_second: frames_per_second(shot.fps, shot.fps_base),
                entries: vec![
                    ("nerfx/version".into(), env!("CARGO_PKG_VERSION").into()),
                    ("nerfx/quality".into(), quality.name().into()),
                    (
                        "nerfx/colorspace".into(),
                        OutputColorSpace::LinRec709.ocio_name().into(),
                    ),
                ],
                ..ExrHeader::default()
            };
            write_exr_layers(&out.join("demo.exr"), &comp.image, &layers, &header)?;
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
            colorspace,
            cryptomatte,
            cryptomatte_ranks,
            shutter_samples,
            aperture_samples,
            png,
            passes,
            bundle,
            scale,
            resume,
            progress,
            stripe,
            deep,
            deep_samples,
        } => {
            let frames = frames.as_deref().map(parse_frames).transpose()?;
            let stripe = stripe.as_deref().map(Stripe::parse).transpose()?;
            let inputs: Vec<PathBuf> = std::iter::once(scene.clone()).chain(shot.clone()).collect();
            let mut task = Task {
                resume,
                progress,
                inputs,
                stripe,
            };
            if png && stripe.is_some() {
                return Err(Error::invalid(
                    "--png",
                    "a preview is of a whole frame: render it after `nerfx assemble`",
                ));
            }
            check_ranks(cryptomatte, cryptomatte_ranks)?;
            let Some(shot) = shot else {
                if passes.is_some() {
                    return Err(Error::invalid(
                        "--passes",
                        "a graph's NeRF Render nodes choose their own outputs",
                    ));
                }
                if deep.is_some() {
                    return Err(Error::invalid(
                        "--deep",
                        "a graph names the NeRF Render nodes it writes deep files of, and \
                         where: its `deep` key",
                    ));
                }
                if colorspace.is_some() {
                    return Err(Error::invalid(
                        "--colorspace",
                        "a graph says its colour space itself: its `colorspace` key, or its \
                         NeRF Render nodes' Output Colour Space",
                    ));
                }
                let mattes = Mattes {
                    all_renders: cryptomatte,
                    ranks: cryptomatte_ranks,
                    deep_samples,
                };
                return graph::render(&scene, frames, &output, png, bundle, scale, mattes, &task);
            };
            check_deep(deep.as_deref(), deep_samples, stripe.is_some())?;
            let outputs = passes.as_deref().map_or_else(Outputs::all, Pass::outputs);
            let request = frame_request(
                quality,
                outputs,
                colour,
                shutter_samples,
                aperture_samples,
                deep.is_some().then_some(deep_samples),
            )?;
            if png && !outputs.rgb {
                return Err(Error::invalid(
                    "--png",
                    "the preview is of the colour: add rgba to --passes",
                ));
            }
            let scene = SceneDesc::for_path(&scene)?;
            // A frame older than a field file is rendered again on resume (a run folder's
            // time says nothing about its checkpoints: only files count).
            task.inputs
                .extend(scene.sources().into_iter().filter(|p| p.is_file()));
            let scene = scene.load()?;
            for warning in scene.warnings() {
                eprintln!("nerfx: warning: {warning}");
            }
            let space = colorspace.unwrap_or(scene.desc().colorspace.unwrap_or_default());
            let shot = read_shot(&shot, &nerf_object)?;
            let frames = frames.unwrap_or_else(|| shot.frames.iter().map(|f| f.frame).collect());
            let bar = progress_bar(frames.len() as u64, "frames");
            for (done, &frame) in frames.iter().enumerate() {
                let whole = frame_path(&output, frame, frames.len() > 1);
                let path = stripe.map_or_else(|| whole.clone(), |s| s.path(&whole));
                if let Some(dir) = path.parent() {
                    create_dir(dir)?;
                }
                let deep_path = deep
                    .as_deref()
                    .map(|pattern| frame_path(pattern, frame, frames.len() > 1));
                if let Some(dir) = deep_path.as_deref().and_then(Path::parent) {
                    create_dir(dir)?;
                }
                // A stripe is done too when the frame it belongs to has been assembled; a
                // frame with a deep file when that was written after the inputs too (it is
                // written before the flat file).
                let deep_done = deep_path
                    .as_deref()
                    .is_none_or(|d| written_after(d, &task.inputs));
                if task.resume
                    && deep_done
                    && (task.is_done(&path) || (stripe.is_some() && task.is_done(&whole)))
                {
                    bar.inc(1);
                    let what = format!("frame {frame}: {} is already whole", path.display());
                    bar.suspend(|| task.report(done + 1, frames.len(), &what));
                    continue;
                }
                task.clear(&path)?;
                let camera = shot.frame(frame)?.camera(&shot)?;
                let window = match stripe {
                    Some(s) => {
                        let full = camera.full_window();
                        s.window(full.width(), full.height(), request.settings().tile_size)?
                    }
                    None => camera.full_window(),
                };
                let request = request.with_window(window)?;
                let (mut planes, mut deep_image, stats) =
                    render_frame(&scene, &shot, frame, &request, &|_| {})?;
                if let Some(warning) = stats.warning() {
                    bar.suspend(|| eprintln!("nerfx: warning: frame {frame}: {warning}"));
                }
                space.convert_planes(&mut planes);
                let mut header = ExrHeader {
                    pixel_aspect: shot.pixel_aspect_for(&camera),
                    color_space: space,
                    camera: Some(CameraMatrices::of(&camera)),
                    frames_per_second: frames_per_second(shot.fps, shot.fps_base),
                    entries: render_entries(&scene, &shot, quality, &request, space),
                };
                // The deep file first: a flat file that reads back whole then says the frame's
                // deep file was written too (see `deep_done`).
                if let (Some(image), Some(deep_path)) = (&mut deep_image, &deep_path) {
                    space.convert_deep(image);
                    nerfx_core::render::conform_to(image, &planes);
                    task.clear(deep_path)?;
                    write_deep_exr(deep_path, image, &header)?;
                }
                let mattes = if cryptomatte {
                    let coverage = render_coverage(&scene, &shot, frame, &request)?;
                    let names: Vec<&str> = scene
                        .desc()
                        .instances
                        .iter()
                        .map(|i| i.name.as_str())
                        .collect();
                    let layer = nerfx_core::image::cryptomatte::OBJECT_LAYER;
                    header
                        .entries
                        .extend(nerfx_core::image::cryptomatte::header_entries(
                            layer, &names,
                        ));
                    nerfx_core::image::cryptomatte::layers(
                        layer,
                        &names,
                        &coverage,
                        cryptomatte_ranks,
                    )?
                } else {
                    Vec::new()
                };
                let layers: Vec<(&str, &_)> = mattes.iter().map(|(n, p)| (n.as_str(), p)).collect();
                write_exr_layers(&path, &planes, &layers, &header)?;
                if png {
                    write_png_preview(&path.with_extension("png"), &planes)?;
                }
                bar.inc(1);
                let what = format!("frame {frame} → {}", path.display());
                bar.suspend(|| task.report(done + 1, frames.len(), &what));
            }
            bar.finish_and_clear();
            Ok(())
        }
        Command::Assemble {
            frames,
            split_frame,
            output,
            progress,
        } => {
            let frames = parse_frames(&frames)?;
            let task = Task {
                resume: true,
                progress,
                inputs: Vec::new(),
                stripe: None,
            };
            for (done, &frame) in frames.iter().enumerate() {
                let path = frame_path(&output, frame, frames.len() > 1);
                let first = Stripe::new(1, split_frame)?.path(&path);
                // Assembled already (the stripes are removed once the frame is written).
                let what = if !first.exists() && task.is_done(&path) {
                    format!("frame {frame}: {} is already assembled", path.display())
                } else {
                    nerfx::farm::assemble(&path, split_frame)?;
                    format!("frame {frame} → {}", path.display())
                };
                task.report(done + 1, frames.len(), &what);
            }
            Ok(())
        }
        Command::Farm { engine } => farm(engine),
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
                    let descs: Vec<_> = nerfx_graph::nodes().iter().map(|n| &n.desc).collect();
                    print!("{}", nerfx_graph::nodes_markdown(&descs));
                }
                ReferencePage::Cli => print!("{}", cli_markdown()),
            }
            Ok(())
        }
        Command::Info { field } => {
            println!("{}", nerfx_core::field::describe(&field)?);
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
            let cloud = nerfx_core::standin::points(&scene, resolution, threshold, points);
            nerfx_core::standin::write_ply(&output, &cloud)?;
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
                let surface = nerfx_core::standin::mesh(&scene, resolution, threshold);
                nerfx_core::standin::write_mesh_ply(&mesh_path, &surface)?;
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
            deep: Some(quality),
            out,
            width,
            height,
            repeats,
            scene,
            ply,
            ..
        } => {
            create_dir(&out)?;
            let scenes = if scene.is_empty() {
                bench::SceneKind::ALL.to_vec()
            } else {
                scene
            };
            let timings = bench::deep::time_deep(
                &out,
                &scenes,
                (width, height),
                quality,
                repeats.unwrap_or(3),
                ply.first().map(PathBuf::as_path),
            )?;
            print!("{}", bench::deep::table(&timings, quality, (width, height)));
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
            create_dir(&out)?;
            let report =
                bench::splats::report(n, &ply, &out, (width, height), repeats.unwrap_or(3))?;
            print!("{report}");
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

/// What `nerfx render` does as a farm task besides rendering: skip what an earlier attempt
/// finished, report progress in the engine's convention, and clear what a killed attempt left.
struct Task {
    /// Skip frames already whole (`--resume`).
    resume: bool,
    /// How progress is reported.
    progress: Progress,
    /// The files the frames are rendered from: a frame older than one is rendered again.
    inputs: Vec<PathBuf>,
    /// The stripe of each frame to render (`--stripe`), or the whole frames.
    stripe: Option<Stripe>,
}

impl Task {
    fn is_done(&self, path: &Path) -> bool {
        is_done(path, &self.inputs)
    }

    fn report(&self, done: usize, total: usize, what: &str) {
        for line in self.progress.frame_lines(done, total, what) {
            println!("{line}");
        }
    }

    /// With `--resume` the task alone writes `path`: what an attempt killed while writing it
    /// left beside it goes.
    fn clear(&self, path: &Path) -> Result<()> {
        if self.resume {
            nerfx::farm::remove_stale_temporaries(path)?;
        }
        Ok(())
    }
}

/// `nerfx farm`: writes (and for Slurm, may submit) a job.
fn farm(engine: FarmEngine) -> Result<()> {
    use nerfx::farm::slurm::{self, Array, SlurmOptions};
    use nerfx::farm::{opencue, openjd, write_job_file};
    let written = |path: &Path| println!("wrote {}", path.display());
    match engine {
        FarmEngine::Slurm {
            job,
            script,
            partition,
            max_running,
            log_dir,
            submit,
        } => {
            let job = job.job()?;
            let log_dir = match log_dir {
                Some(dir) => std::path::absolute(&dir).map_err(|e| Error::io(&dir, e))?,
                None => job.output_dir().join("logs"),
            };
            // Slurm opens each task's log there before the task starts.
            create_dir(&log_dir)?;
            let options = SlurmOptions {
                partition,
                max_running,
                log_dir: log_dir.clone(),
            };
            let render = slurm::script(&job, &options, Array::Render);
            let split = job.split > 1;
            let script = match script {
                Some(path) => Some(path),
                None if split || submit => Some(log_dir.join(format!("{}.sh", job.name))),
                None => None,
            };
            let Some(path) = script else {
                print!("{render}");
                return Ok(());
            };
            write_job_file(&path, &render)?;
            written(&path);
            let assemble = split.then(|| slurm::assemble_script_path(&path));
            if let Some(assemble) = &assemble {
                write_job_file(assemble, &slurm::script(&job, &options, Array::Assemble))?;
                written(assemble);
            }
            if !submit {
                if let Some(assemble) = &assemble {
                    println!(
                        "submit with: jid=$(sbatch --parsable {}) && sbatch \
                         --dependency=afterok:$jid --kill-on-invalid-dep=yes {}",
                        nerfx::farm::shell_quote(&path.display().to_string()),
                        nerfx::farm::shell_quote(&assemble.display().to_string())
                    );
                }
                return Ok(());
            }
            let id = sbatch(&[path.display().to_string()])?;
            match assemble {
                None => println!("submitted job {id}"),
                Some(assemble) => {
                    println!("submitted job {id} (render)");
                    let joined = sbatch(&[
                        format!("--dependency=afterok:{id}"),
                        "--kill-on-invalid-dep=yes".into(),
                        assemble.display().to_string(),
                    ])?;
                    println!("submitted job {joined}");
                }
            }
            Ok(())
        }
        FarmEngine::Openjd {
            job,
            template,
            bundle,
        } => {
            let job = job.job()?;
            let text = openjd::template(&job)?;
            if let Some(dir) = &bundle {
                openjd::write_bundle(&job, dir)?;
                written(dir);
            }
            match template {
                Some(path) => {
                    write_job_file(&path, &text)?;
                    written(&path);
                    let values = openjd::run_parameters_path(&path);
                    write_job_file(&values, &openjd::run_parameters(&job))?;
                    written(&values);
                    println!(
                        "run with: openjd run {} -p file://{}",
                        nerfx::farm::shell_quote(&path.display().to_string()),
                        nerfx::farm::shell_quote(&values.display().to_string())
                    );
                }
                None if bundle.is_none() => print!("{text}"),
                None => {}
            }
            Ok(())
        }
        FarmEngine::Opencue { job, script } => {
            let text = opencue::script(&job.job()?)?;
            match script {
                Some(path) => {
                    write_job_file(&path, &text)?;
                    written(&path);
                }
                None => print!("{text}"),
            }
            Ok(())
        }
    }
}

/// Runs `sbatch --parsable ARGS` and returns the job id it prints.
fn sbatch(args: &[String]) -> Result<String> {
    let out = std::process::Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .output()
        .map_err(|e| Error::io("sbatch", e))?;
    let text = String::from_utf8_lossy(&out.stdout);
    // `--parsable` prints `<id>` or `<id>;<cluster>`.
    let id = text
        .trim()
        .split(';')
        .next()
        .unwrap_or_default()
        .to_string();
    if !out.status.success() || id.is_empty() {
        return Err(Error::invalid(
            "sbatch",
            format!(
                "failed ({}): {}",
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            ),
        ));
    }
    Ok(id)
}

/// The Cryptomatte a graph's frames carry: layers for the NeRF Render nodes its file names
/// (`cryptomatte`), or with `--cryptomatte` for every one the output needs when it names
/// none; `ranks` ID–coverage pairs per pixel.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(not(feature = "host"), allow(dead_code))]
struct Mattes {
    all_renders: bool,
    ranks: usize,
    /// `--deep-samples`: the cap of the graph's deep files (their nodes' presets' without).
    deep_samples: Option<u32>,
}

/// Refuses `--cryptomatte-ranks` outside 1 to the most ranks where mattes are written.
fn check_ranks(cryptomatte: bool, ranks: usize) -> Result<()> {
    let max = nerfx_core::image::cryptomatte::MAX_RANKS;
    if cryptomatte && !(1..=max).contains(&ranks) {
        return Err(Error::invalid(
            "--cryptomatte-ranks",
            format!("{ranks}; expected 1 to {max}"),
        ));
    }
    Ok(())
}

/// Graph rendering through the OpenFX host and bundle (`host` feature).
#[cfg(feature = "host")]
mod graph {
    use super::*;
    use nerfx_graph::Graph;
    use nerfx_ofx_host::Bundle;
    use nerfx_ofx_host::OfxGraph;

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
    #[allow(clippy::too_many_arguments)]
    pub fn render(
        path: &Path,
        frames: Option<Vec<i64>>,
        output: &Path,
        png: bool,
        bundle: Option<PathBuf>,
        scale: f64,
        mattes: Mattes,
        task: &Task,
    ) -> Result<()> {
        let graph = Graph::read(path)?;
        check_ranks(!graph.cryptomatte.is_empty(), mattes.ranks)?;
        check_graph_deep(&graph, mattes.deep_samples, task.stripe.is_some())?;
        let matted = graph.cryptomatte_nodes(mattes.all_renders);
        let stripe = task.stripe;
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
        let rendered = frames.iter().enumerate().try_for_each(|(done, &frame)| {
            let whole = target(frame);
            let path = stripe.map_or_else(|| whole.clone(), |s| s.path(&whole));
            // A stripe is done too when the frame it belongs to has been assembled.
            let done_already = task.is_done(&path) || (stripe.is_some() && task.is_done(&whole));
            let what = if task.resume && done_already {
                bar.inc(nodes as u64);
                format!("frame {frame}: {} is already whole", path.display())
            } else {
                task.clear(&path)?;
                let to = Target {
                    path: &path,
                    png,
                    scale,
                    stripe,
                    matted: &matted,
                    ranks: mattes.ranks,
                    deep_samples: mattes.deep_samples,
                    several: frames.len() > 1,
                };
                render_frame(&mut graph, frame, &to, &bar)?;
                format!("frame {frame} → {}", path.display())
            };
            bar.suspend(|| task.report(done + 1, frames.len(), &what));
            Ok(())
        });
        bar.finish_and_clear();
        let ended = graph.end_sequence(first, last, scale);
        rendered.and(ended)
    }

    /// Where and how a graph's frame is written.
    struct Target<'a> {
        path: &'a Path,
        png: bool,
        scale: f64,
        stripe: Option<Stripe>,
        /// The NeRF Render nodes whose instances get Cryptomatte layers.
        matted: &'a [String],
        ranks: usize,
        /// The cap of the graph's deep files.
        deep_samples: Option<u32>,
        /// Whether the frames are several (their file names carry the frame).
        several: bool,
    }

    /// Refuses a graph's deep files where they cannot be written: in stripes, by a build
    /// without OpenEXR; and `--deep-samples` for a graph that writes none.
    fn check_graph_deep(graph: &Graph, samples: Option<u32>, striped: bool) -> Result<()> {
        if graph.deep.is_empty() {
            return match samples {
                Some(_) => Err(Error::invalid(
                    "--deep-samples",
                    "is for a graph whose file names deep outputs (its `deep` key)",
                )),
                None => Ok(()),
            };
        }
        if striped {
            return Err(Error::invalid(
                "deep",
                "deep files are written with whole frames: render the graph without --stripe",
            ));
        }
        if !nerfx_core::image::deep_exr_available() {
            return Err(Error::invalid(
                "deep",
                "this build of nerfx has no OpenEXR library, which writes deep files: install \
                 OpenEXR's development files (Debian: apt-get install libopenexr-dev) and build \
                 nerfx again",
            ));
        }
        Ok(())
    }

    /// The deep files of the graph's `deep` nodes at `frame`, each its node's render of the
    /// frame's window, with the graph's header and the node's own camera.
    fn write_graph_deep(
        graph: &OfxGraph,
        frame: i64,
        to: &Target,
        window_of: &dyn Fn(u32, u32) -> Result<nerfx_core::image::Window>,
        header: &ExrHeader,
    ) -> Result<()> {
        let g = graph.graph();
        for (node, pattern) in &g.deep {
            let path = frame_path(pattern, frame, to.several);
            if let Some(dir) = path.parent() {
                create_dir(dir)?;
            }
            let time = frame as f64;
            let (_, image) = g.deep(node, time, to.scale, window_of, to.deep_samples)?;
            let (camera, _) = g.node_camera(node, time)?;
            let header = ExrHeader {
                pixel_aspect: graph.pixel_aspect(node),
                camera: Some(CameraMatrices::of(&camera)),
                ..header.clone()
            };
            write_deep_exr(&path, &image, &header)?;
        }
        Ok(())
    }

    /// One frame of the graph written to `to`.
    fn render_frame(
        graph: &mut OfxGraph,
        frame: i64,
        to: &Target,
        bar: &ProgressBar,
    ) -> Result<()> {
        let (target, png, scale, stripe) = (to.path, to.png, to.scale, to.stripe);
        if let Some(dir) = target.parent() {
            create_dir(dir)?;
        }
        let window_of = |w, h| match stripe {
            Some(s) => s.window(w, h, nerfx_core::render::TILE_SIZE),
            None => Ok(nerfx_core::image::Window::new(0, 0, w, h)),
        };
        let images = graph.render_window(frame as f64, scale, false, &window_of, &|node| {
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
        let mut layers = graph
            .graph()
            .layers
            .iter()
            .map(|(layer, node)| Ok((layer.as_str(), image(node)?)))
            .collect::<Result<Vec<_>>>()?;
        let mut header = graph_header(graph, frame as f64)?;
        // The deep files first (their header without the mattes' manifest): a flat file that
        // reads back whole says they were written too.
        if !graph.graph().deep.is_empty() {
            bar.set_message(format!("frame {frame} deep"));
            write_graph_deep(graph, frame, to, &window_of, &header)?;
        }
        let mattes = if to.matted.is_empty() {
            Vec::new()
        } else {
            bar.set_message(format!("frame {frame} cryptomatte"));
            let (names, coverage) = graph_coverage(graph.graph(), frame, to, &window_of, main)?;
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            let layer = nerfx_core::image::cryptomatte::OBJECT_LAYER;
            header
                .entries
                .extend(nerfx_core::image::cryptomatte::header_entries(
                    layer, &names,
                ));
            nerfx_core::image::cryptomatte::layers(layer, &names, &coverage, to.ranks)?
        };
        layers.extend(mattes.iter().map(|(n, p)| (n.as_str(), p)));
        write_exr_layers(target, main, &layers, &header)?;
        if png {
            write_png_preview(&target.with_extension("png"), main)?;
        }
        Ok(())
    }

    /// Every instance of the NeRF Render nodes `to.matted` and its coverage of the frame's
    /// window, each from its own node's render; every plane the size of the `main` image.
    fn graph_coverage(
        graph: &Graph,
        frame: i64,
        to: &Target,
        window_of: &dyn Fn(u32, u32) -> Result<nerfx_core::image::Window>,
        main: &nerfx_core::image::Planes,
    ) -> Result<(Vec<String>, Vec<nerfx_core::image::Plane>)> {
        let (mut names, mut planes) = (Vec::new(), Vec::new());
        for node in to.matted {
            for (name, plane) in graph.coverage(node, frame as f64, to.scale, window_of)? {
                if (plane.width, plane.height) != (main.width, main.height) {
                    return Err(Error::invalid(
                        format!("graph node {node}: cryptomatte"),
                        format!(
                            "its image is {}×{}, the output's {}×{}: Cryptomatte comes from \
                             NeRF Render nodes of the output's size",
                            plane.width, plane.height, main.width, main.height
                        ),
                    ));
                }
                names.push(name);
                planes.push(plane);
            }
        }
        Ok((names, planes))
    }

    /// The EXR header of a graph's frame: its colour space, the camera of the NeRF Render
    /// node the output comes from, and the field files the output needs.
    fn graph_header(graph: &OfxGraph, time: f64) -> Result<ExrHeader> {
        let g = graph.graph();
        let camera = g.output_camera(time)?;
        let needed = g.needed();
        let fields: Vec<&str> = g
            .nodes
            .iter()
            .zip(needed)
            .filter(|(n, needed)| *needed && n.node.desc.param("file").is_some())
            .filter_map(|(n, _)| n.values.text("file").ok())
            .collect();
        let mut entries = vec![
            (
                "nerfx/version".to_string(),
                env!("CARGO_PKG_VERSION").to_string(),
            ),
            ("nerfx/fieldFiles".to_string(), fields.join(";")),
            (
                "nerfx/colorspace".to_string(),
                g.colorspace.ocio_name().to_string(),
            ),
        ];
        if let Some(node) = g.output_render() {
            for (key, param) in [
                ("nerfx/quality", "quality"),
                ("nerfx/shutterSamples", "shutterSamples"),
                ("nerfx/apertureSamples", "apertureSamples"),
            ] {
                if let Some(value) = param_text(&node.values, param) {
                    entries.push((key.to_string(), value));
                }
            }
        }
        Ok(ExrHeader {
            pixel_aspect: graph.pixel_aspect(&g.output),
            color_space: g.colorspace,
            camera: camera.as_ref().map(|(c, _)| CameraMatrices::of(c)),
            frames_per_second: camera
                .as_ref()
                .and_then(|(_, shot)| frames_per_second(shot.fps, shot.fps_base)),
            entries,
        })
    }

    /// A choice or whole-number parameter's value as text.
    fn param_text(values: &nerfx_graph::ParamValues, name: &str) -> Option<String> {
        values
            .choice(name)
            .map(str::to_string)
            .or_else(|_| values.int(name).map(|v| v.to_string()))
            .ok()
    }
}

/// Without the `host` feature there is no OpenFX host to render graphs with.
#[cfg(not(feature = "host"))]
mod graph {
    use super::*;

    #[allow(clippy::too_many_arguments)]
    pub fn render(
        path: &Path,
        _: Option<Vec<i64>>,
        _: &Path,
        _: bool,
        _: Option<PathBuf>,
        _: f64,
        _: Mattes,
        _: &Task,
    ) -> Result<()> {
        Err(Error::Unsupported(format!(
            "{}: rendering a node graph needs the OpenFX host; this nerfx was built without it \
             (build with `cargo build --release --features host`)",
            path.display()
        )))
    }
}

/// The `nerfx/...` header entries of a scene's render: what made it.
fn render_entries(
    scene: &nerfx_core::scene::LoadedScene,
    shot: &nerfx_core::camera::Shot,
    quality: Quality,
    request: &FrameRequest,
    space: OutputColorSpace,
) -> Vec<(String, String)> {
    let fields: Vec<String> = scene
        .desc()
        .instances
        .iter()
        .map(|i| match &i.field {
            nerfx_core::scene::FieldSource::Analytic(_) => format!("{} (analytic)", i.name),
            nerfx_core::scene::FieldSource::Ingp { path, .. }
            | nerfx_core::scene::FieldSource::Nerfacto { path, .. }
            | nerfx_core::scene::FieldSource::Splats { path, .. } => path.display().to_string(),
        })
        .collect();
    [
        ("nerfx/version", env!("CARGO_PKG_VERSION").to_string()),
        ("nerfx/fieldFiles", fields.join(";")),
        ("nerfx/quality", quality.name().to_string()),
        // Renders averaged per frame: the shutter's only where the shot has motion blur.
        (
            "nerfx/shutterSamples",
            match shot.motion_blur {
                Some(_) => request.shutter_samples(),
                None => 1,
            }
            .to_string(),
        ),
        // Points of the aperture per time: only where a frame's camera has depth of field.
        (
            "nerfx/apertureSamples",
            match shot.frames.iter().any(|f| f.camera.dof.is_some()) {
                true => request.aperture_samples(),
                false => 1,
            }
            .to_string(),
        ),
        ("nerfx/colorspace", space.ocio_name().to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// Refuses `--deep-samples` without `--deep`, and `--deep` with a stripe (deep files are
/// written with whole frames) or in a build without OpenEXR, before anything renders.
fn check_deep(deep: Option<&Path>, samples: Option<u32>, striped: bool) -> Result<()> {
    let Some(_) = deep else {
        if samples.is_some() {
            return Err(Error::invalid(
                "--deep-samples",
                "is for --deep: add --deep PATTERN",
            ));
        }
        return Ok(());
    };
    if striped {
        return Err(Error::invalid(
            "--deep",
            "deep files are written with whole frames: render without --stripe",
        ));
    }
    if !nerfx_core::image::deep_exr_available() {
        return Err(Error::invalid(
            "--deep",
            "this build of nerfx has no OpenEXR library, which writes deep files: install \
             OpenEXR's development files (Debian: apt-get install libopenexr-dev) and build \
             nerfx again",
        ));
    }
    Ok(())
}

/// The frame request `nerfx render`'s flags ask for of a scene: `quality`'s preset with the
/// passes `outputs` and colour `colour`, the shutter and aperture samples given (the
/// preset's without them), and a deep pass where `deep` is given (at most its samples a
/// pixel; the preset's cap without them). Its refusals name the flag at fault.
fn frame_request(
    quality: Quality,
    outputs: Outputs,
    colour: ColorOutput,
    shutter_samples: Option<u32>,
    aperture_samples: Option<u32>,
    deep: Option<Option<u32>>,
) -> Result<FrameRequest> {
    let flag = |name: &'static str| {
        move |e: Error| match e {
            Error::Invalid { message, .. } => Error::invalid(name, message),
            other => other,
        }
    };
    let mut request = FrameRequest::for_quality(quality, outputs).with_colour(colour);
    if let Some(samples) = deep {
        request = request.with_deep(samples).map_err(|e| match e {
            Error::Invalid { what, .. } if what == "deep output" => Error::invalid(
                "--deep",
                "deep samples carry colour and alpha: add rgba to --passes",
            ),
            other => flag("--deep-samples")(other),
        })?;
    }
    if let Some(n) = shutter_samples {
        request = request
            .with_shutter_samples(n)
            .map_err(flag("--shutter-samples"))?;
    }
    if let Some(n) = aperture_samples {
        request = request
            .with_aperture_samples(n)
            .map_err(flag("--aperture-samples"))?;
    }
    Ok(request)
}

/// Whether `path` exists and was written after every one of `inputs` last changed.
fn written_after(path: &Path, inputs: &[PathBuf]) -> bool {
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    modified(path).is_some_and(|written| {
        inputs
            .iter()
            .all(|input| modified(input).is_some_and(|changed| changed <= written))
    })
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
