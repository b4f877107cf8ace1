//! Every parser against seeded mutations of valid inputs (the fixture writers' files and the
//! real ones in `tests/data`): shot JSON, nerfstudio camera paths, scene and graph JSON,
//! instant-ngp msgpack (raw and gzip), torch checkpoints (the zip and the pickle inside),
//! nerfstudio `config.yml` and `dataparser_transforms.json`, splat PLY, and the compact splat
//! formats: `.splat`, SuperSplat's compressed PLY, SPZ (its gzip stream's contents, and
//! version 4's zstd streams), SOG (the zip, its `meta.json` and a WebP image).
//!
//! Each case must end in an error, or in something loaded that renders an 8×8 frame to
//! finite planes; never a panic, never longer than [`CASE_TIME`], never more memory at once
//! than [`memory_bound`] of its input (counted by this binary's global allocator). A failing
//! case is reported by target and case number, which replay it exactly (`replay`); each one
//! found is fixed in the library and kept below as a named regression test.
//!
//! `cargo test --test fuzz` runs a few thousand cases; `NERFX_FUZZ_CASES=100000 cargo test
//! --release --test fuzz -- --ignored --nocapture` runs that many per target, from other
//! seeds (case numbers from 1 000 000, or from `NERFX_FUZZ_FIRST`).

mod common_fields;
mod common_fuzz;
// The snapshot writer's blob and scratch helpers serve other tests.
#[allow(dead_code)]
mod common_ingp;
mod common_nerfacto;

use std::alloc::{GlobalAlloc, Layout, System};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{mpsc, Mutex, OnceLock, PoisonError};
use std::time::{Duration, Instant};

use common_fields::SplitMix64;
use common_fuzz::{mutate, Kind};
use glam::{DMat4, DVec3};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::demo::look_at;
use nerfx_core::image::{Planes, Window};
use nerfx_core::render::{render, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{LoadedScene, Scene, SceneDesc};
use nerfx_graph::{evaluate, purge_caches, render_direct, Graph};

/// The longest a case may take.
const CASE_TIME: Duration = Duration::from_secs(10);

/// The most a case may hold at once beyond what was allocated before it: 64 times its input
/// and 64 MiB (a run's occupancy grid and the renderer's scratch are fixed-size), and never
/// more than 1 GiB. The seeds peak below 20 MiB.
fn memory_bound(input: usize) -> usize {
    (64 * input + (64 << 20)).min(1 << 30)
}

// ---------------------------------------------------------------------------------------
// The counting allocator.

/// The system allocator, counting the bytes alive and the most alive at once. A single
/// request past [`REFUSED`] is refused (as an out-of-memory system would), naming the case.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static REFUSED_ONE: AtomicBool = AtomicBool::new(false);
/// The case running, for the refusal's message: target index and case number.
static CASE_TARGET: AtomicUsize = AtomicUsize::new(usize::MAX);
static CASE_NUMBER: AtomicU64 = AtomicU64::new(0);
const REFUSED: usize = 4 << 30;

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > REFUSED {
            REFUSED_ONE.store(true, Ordering::SeqCst);
            say_refused(layout.size());
            return std::ptr::null_mut();
        }
        let p = System.alloc(layout);
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        System.dealloc(p, layout);
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Writes which case asked for `size` bytes to stderr without allocating (the process may
/// abort right after, when the caller cannot take a refusal).
fn say_refused(size: usize) {
    fn decimal(mut n: u64, buf: &mut [u8; 20]) -> &[u8] {
        let mut i = buf.len();
        loop {
            i -= 1;
            buf[i] = b'0' + (n % 10) as u8;
            n /= 10;
            if n == 0 {
                return &buf[i..];
            }
        }
    }
    let (mut a, mut b, mut c) = ([0u8; 20], [0u8; 20], [0u8; 20]);
    let target = CASE_TARGET.load(Ordering::SeqCst);
    let name = TARGET_NAMES.get(target).copied().unwrap_or("(no case)");
    let mut err = std::io::stderr().lock();
    for part in [
        b"fuzz: target ".as_slice(),
        name.as_bytes(),
        b" case ",
        decimal(CASE_NUMBER.load(Ordering::SeqCst), &mut a),
        b" asked for ",
        decimal(size as u64, &mut b),
        b" bytes at once (refused; the bound is ",
        decimal(REFUSED as u64, &mut c),
        b")\n",
    ] {
        let _ = err.write_all(part);
    }
}

// ---------------------------------------------------------------------------------------
// Targets.

/// The targets, in [`targets`] order.
const TARGET_NAMES: [&str; 21] = [
    "shot JSON",
    "camera path",
    "scene JSON",
    "graph JSON",
    "instant-ngp msgpack",
    "instant-ngp gzip",
    "checkpoint zip (tcnn)",
    "checkpoint zip (torch)",
    "checkpoint pickle (tcnn)",
    "checkpoint pickle (torch)",
    "config.yml",
    "dataparser_transforms.json",
    "splat PLY",
    "antimatter15 .splat",
    "compressed PLY",
    "SPZ gzip contents",
    "SPZ version 4",
    "SOG zip",
    "SOG meta.json",
    "SOG WebP image",
    "frame list and stripe",
];

/// How a case ended well.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Verdict {
    /// The input was refused with this error.
    Refused(String),
    /// It loaded, and rendered to finite planes.
    Rendered,
}

/// What a case does with its bytes, in its own scratch folder: a [`Verdict`], or what went
/// wrong.
type Check = fn(&Fixtures, &Path, &[u8]) -> Result<Verdict, String>;

use Verdict::{Refused, Rendered};

/// The value of a `Result`, or the case ends as refused with its error.
macro_rules! attempt {
    ($e:expr) => {
        match $e {
            Ok(v) => v,
            Err(e) => return Ok(Refused(e.to_string())),
        }
    };
}

struct Target {
    name: &'static str,
    kind: Kind,
    seeds: Vec<Vec<u8>>,
    /// Cases in the default run.
    cases: u64,
    check: Check,
}

/// Inputs written once per binary and shared by the cases.
struct Fixtures {
    /// The demo's scenes, shot and graph (8×8).
    demo: PathBuf,
    /// The demo scene with its instances unbound (placed as they are by any shot).
    scene: LoadedScene,
    /// The files of two valid nerfacto runs (tiny-cuda-nn's layout, the torch fallback's):
    /// config.yml, dataparser_transforms.json, the checkpoint.
    runs: [[Vec<u8>; 3]; 2],
}

/// The fixtures, made once per binary. The demo's files stay (statics are not dropped) in
/// the build's scratch folder, as the OpenFX tests' do; the runs are kept as bytes only.
fn fixtures() -> &'static Fixtures {
    static F: OnceLock<Fixtures> = OnceLock::new();
    F.get_or_init(|| {
        let demo = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("nerfx-fuzz-demo-{}", std::process::id()));
        std::fs::create_dir_all(&demo).unwrap();
        nerfx_graph::demo::write_graph(&demo, 8, 8).unwrap();
        let mut desc = nerfx_core::demo::scene_desc();
        for inst in &mut desc.instances {
            inst.object = None;
        }
        let run = |spec: common_nerfacto::Spec| {
            let dir = tempfile::tempdir().unwrap();
            let run = common_nerfacto::write_run(dir.path(), &spec);
            let read = |p: &str| std::fs::read(run.join(p)).unwrap();
            [
                read("config.yml"),
                read("dataparser_transforms.json"),
                common_nerfacto::checkpoint_bytes(&spec),
            ]
        };
        Fixtures {
            demo,
            scene: desc.load().unwrap(),
            runs: [
                run(common_nerfacto::Spec::tcnn()),
                run(common_nerfacto::Spec::torch()),
            ],
        }
    })
}

fn targets() -> &'static [Target] {
    static T: OnceLock<Vec<Target>> = OnceLock::new();
    T.get_or_init(build_targets)
}

fn build_targets() -> Vec<Target> {
    let f = fixtures();
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let file = |p: &Path| std::fs::read(p).unwrap();
    let ingp = common_ingp::Spec {
        n_cascades: 1,
        log2_table_size: 10,
        gzip: false,
        ..common_ingp::Spec::small_8x4()
    };
    let ingp_old = common_ingp::Spec {
        n_cascades: 1,
        log2_table_size: 9,
        ..common_ingp::Spec::old_16x2()
    };
    let gzip = |s: &common_ingp::Spec| {
        common_ingp::file_bytes(&common_ingp::Spec {
            gzip: true,
            ..s.clone()
        })
    };
    let ply = file(&data.join("splat_plane_sh3.ply"));
    let splats = |name: &str| file(&data.join("splats").join(name));
    let sog = splats("subset_sh3.sog");
    let targets = vec![
        Target {
            name: TARGET_NAMES[0],
            kind: Kind::Text,
            seeds: vec![
                file(&f.demo.join("demo_shot.json")),
                shot_with_extras(&f.demo.join("demo_shot.json")),
            ],
            cases: 600,
            check: check_shot,
        },
        Target {
            name: TARGET_NAMES[1],
            kind: Kind::Text,
            seeds: vec![
                file(&data.join("viewer_camera_path_b.json")),
                file(&data.join("viewer_camera_path_keyframes.json")),
            ],
            cases: 600,
            check: check_shot,
        },
        Target {
            name: TARGET_NAMES[2],
            kind: Kind::Text,
            seeds: vec![
                serde_json::to_vec_pretty(&nerfx_core::demo::scene_desc()).unwrap(),
                file(&f.demo.join("demo_shadow.json")),
            ],
            cases: 800,
            check: check_scene,
        },
        Target {
            name: TARGET_NAMES[3],
            kind: Kind::Text,
            seeds: vec![file(&f.demo.join("demo_comp.json"))],
            cases: 150,
            check: check_graph,
        },
        Target {
            name: TARGET_NAMES[4],
            kind: Kind::Msgpack,
            seeds: vec![
                common_ingp::snapshot_bytes(&ingp),
                common_ingp::snapshot_bytes(&ingp_old),
            ],
            cases: 100,
            check: check_ingp_raw,
        },
        Target {
            name: TARGET_NAMES[5],
            kind: Kind::GzipMsgpack,
            seeds: vec![gzip(&ingp), gzip(&ingp_old)],
            cases: 40,
            check: check_ingp_gzip,
        },
        Target {
            name: TARGET_NAMES[6],
            kind: Kind::Zip,
            seeds: vec![f.runs[0][2].clone()],
            cases: 20,
            check: |f, dir, b| run_with(f, 0, dir, 2, b),
        },
        Target {
            name: TARGET_NAMES[7],
            kind: Kind::Zip,
            seeds: vec![f.runs[1][2].clone()],
            cases: 8,
            check: |f, dir, b| run_with(f, 1, dir, 2, b),
        },
        Target {
            name: TARGET_NAMES[8],
            kind: Kind::Pickle,
            seeds: vec![zip_member(&f.runs[0][2], "data.pkl")],
            cases: 100,
            check: |f, dir, b| {
                run_with(f, 0, dir, 2, &with_zip_member(&f.runs[0][2], "data.pkl", b))
            },
        },
        Target {
            name: TARGET_NAMES[9],
            kind: Kind::Pickle,
            seeds: vec![zip_member(&f.runs[1][2], "data.pkl")],
            cases: 60,
            check: |f, dir, b| {
                run_with(f, 1, dir, 2, &with_zip_member(&f.runs[1][2], "data.pkl", b))
            },
        },
        Target {
            name: TARGET_NAMES[10],
            kind: Kind::Text,
            seeds: vec![f.runs[0][0].clone()],
            cases: 15,
            check: |f, dir, b| run_with(f, 0, dir, 0, b),
        },
        Target {
            name: TARGET_NAMES[11],
            kind: Kind::Text,
            seeds: vec![f.runs[0][1].clone()],
            cases: 8,
            check: |f, dir, b| run_with(f, 0, dir, 1, b),
        },
        Target {
            name: TARGET_NAMES[12],
            kind: Kind::Ply,
            seeds: vec![first_vertices(&ply, 64), first_vertices(&ply, 9)],
            cases: 1000,
            check: check_ply,
        },
        Target {
            name: TARGET_NAMES[13],
            kind: Kind::Bytes,
            seeds: vec![splats("sjeongab_512.splat")[..64 * 32].to_vec()],
            cases: 300,
            check: |_, dir, b| load_and_render(dir, "splats.splat", b),
        },
        Target {
            name: TARGET_NAMES[14],
            kind: Kind::Ply,
            seeds: vec![
                splats("guitar_512.compressed.ply"),
                splats("subset_sh3.compressed.ply"),
            ],
            cases: 300,
            check: |_, dir, b| load_and_render(dir, "splats.compressed.ply", b),
        },
        Target {
            name: TARGET_NAMES[15],
            kind: Kind::Bytes,
            seeds: vec![gunzip(&splats("subset_sh3.v3.spz"))],
            cases: 300,
            check: |_, dir, b| load_and_render(dir, "splats.spz", &gzip_bytes(b)),
        },
        Target {
            name: TARGET_NAMES[16],
            kind: Kind::Bytes,
            seeds: vec![splats("subset_sh3.spz")],
            cases: 300,
            check: |_, dir, b| load_and_render(dir, "splats.spz", b),
        },
        Target {
            name: TARGET_NAMES[17],
            kind: Kind::Zip,
            seeds: vec![sog.clone()],
            cases: 200,
            check: |_, dir, b| load_and_render(dir, "splats.sog", b),
        },
        Target {
            name: TARGET_NAMES[18],
            kind: Kind::Text,
            seeds: vec![zip_member(&sog, "meta.json")],
            cases: 200,
            check: |_, dir, b| {
                let sog = fixture_sog();
                load_and_render(dir, "splats.sog", &with_zip_member(sog, "meta.json", b))
            },
        },
        Target {
            name: TARGET_NAMES[19],
            kind: Kind::Bytes,
            seeds: vec![zip_member(&sog, "quats.webp")],
            cases: 300,
            check: |_, dir, b| {
                let sog = fixture_sog();
                load_and_render(dir, "splats.sog", &with_zip_member(sog, "quats.webp", b))
            },
        },
        Target {
            name: TARGET_NAMES[20],
            kind: Kind::Text,
            seeds: vec![
                b"1001-1100x5,7,10-12:2\n2/4".to_vec(),
                b"-3--1,1001\n16/16".to_vec(),
            ],
            cases: 400,
            check: check_frames_and_stripe,
        },
    ];
    assert!(targets.iter().zip(TARGET_NAMES).all(|(t, n)| t.name == n));
    targets
}

/// The demo shot with motion blur, depth of field, stereo and a pixel aspect, so that their
/// fields are mutated too.
fn shot_with_extras(path: &Path) -> Vec<u8> {
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    json["pixel_aspect_x"] = 2.0.into();
    json["motion_blur"] = serde_json::json!({"shutter": 0.5, "position": "center"});
    for frame in json["frames"].as_array_mut().unwrap() {
        frame["camera"]["dof"] = serde_json::json!(
            {"focus_distance": 6.0, "fstop": 1.4, "blades": 6, "rotation": 0.2, "ratio": 1.3}
        );
    }
    serde_json::to_vec_pretty(&json).unwrap()
}

/// The PLY `bytes` keeping its first `n` vertices.
fn first_vertices(bytes: &[u8], n: usize) -> Vec<u8> {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let stride = (bytes.len() - end) / count;
    let header = header.replace(
        &format!("element vertex {count}"),
        &format!("element vertex {n}"),
    );
    let mut out = header.into_bytes();
    out.extend_from_slice(&bytes[end..end + n * stride]);
    out
}

/// The committed SOG fixture, read once.
fn fixture_sog() -> &'static [u8] {
    static SOG: OnceLock<Vec<u8>> = OnceLock::new();
    SOG.get_or_init(|| {
        std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/splats/subset_sh3.sog"),
        )
        .unwrap()
    })
}

/// The contents of a gzip stream.
fn gunzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(bytes)
        .read_to_end(&mut out)
        .unwrap();
    out
}

/// `bytes` as a gzip stream.
fn gzip_bytes(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(bytes).unwrap();
    gz.finish().unwrap()
}

/// The member of a zip whose name ends with `suffix`.
fn zip_member(zip: &[u8], suffix: &str) -> Vec<u8> {
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(zip)).unwrap();
    let name = archive
        .file_names()
        .find(|n| n.ends_with(suffix))
        .unwrap()
        .to_owned();
    let mut out = Vec::new();
    archive
        .by_name(&name)
        .unwrap()
        .read_to_end(&mut out)
        .unwrap();
    out
}

/// The zip with the member ending with `suffix` replaced by `bytes`.
fn with_zip_member(zip: &[u8], suffix: &str, bytes: &[u8]) -> Vec<u8> {
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(zip)).unwrap();
    let mut files = Vec::new();
    for i in 0..archive.len() {
        let mut member = archive.by_index(i).unwrap();
        let mut data = Vec::new();
        member.read_to_end(&mut data).unwrap();
        if member.name().ends_with(suffix) {
            data = bytes.to_vec();
        }
        files.push((member.name().to_owned(), data));
    }
    common_nerfacto::zip(&files)
}

// ---------------------------------------------------------------------------------------
// Checks.

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap();
}

fn check_shot(f: &Fixtures, dir: &Path, bytes: &[u8]) -> Result<Verdict, String> {
    let path = dir.join("shot.json");
    write(&path, bytes);
    let shot = attempt!(nerfx_core::camera::read_shot(&path, "NeRF"));
    let first = attempt!(shot.frames.first().ok_or("no frames"));
    // Through a point of the aperture: the pinhole itself when the camera has no depth of
    // field.
    let lenses = first.through_aperture(3);
    let at = attempt!(lenses.last().ok_or("no aperture samples"));
    let camera = attempt!(at.camera(&shot));
    let world = attempt!(at.world_from_scene(&shot));
    let scene = attempt!(f.scene.place(world, &|name| at.object_matrix(name)));
    finite_render(&scene, &camera)
}

fn check_scene(_: &Fixtures, dir: &Path, bytes: &[u8]) -> Result<Verdict, String> {
    let path = dir.join("scene.json");
    write(&path, bytes);
    render_loaded(&attempt!(SceneDesc::read(&path).and_then(SceneDesc::load)))
}

fn check_graph(f: &Fixtures, _: &Path, bytes: &[u8]) -> Result<Verdict, String> {
    let text = attempt!(std::str::from_utf8(bytes));
    let graph = attempt!(Graph::from_json_str(text, &f.demo.join("comp.json")));
    // The caches would carry one case's renders into the next one's memory.
    purge_caches();
    let images = evaluate(&graph, 1001.0, 1.0, false, &mut render_direct, &|_| {});
    purge_caches();
    for (name, p) in &attempt!(images) {
        finite(p).map_err(|e| format!("node {name}: {e}"))?;
    }
    Ok(Rendered)
}

/// A farm task's `--frames` (first line) and `--stripe` (second line): a frame list must
/// read back from its compact form, and a stripe must fall inside the frame on tile rows.
fn check_frames_and_stripe(_: &Fixtures, _: &Path, bytes: &[u8]) -> Result<Verdict, String> {
    let text = attempt!(std::str::from_utf8(bytes));
    let (frames, stripe) = text.split_once('\n').unwrap_or((text, "1/1"));
    let frames = attempt!(nerfx::frames::parse_frames(frames));
    let spec = nerfx::farm::frame_spec(&frames);
    if nerfx::frames::parse_frames(&spec).ok().as_ref() != Some(&frames) {
        return Err(format!(
            "frame spec {spec} does not read back as its frames"
        ));
    }
    let stripe = attempt!(nerfx::farm::Stripe::parse(stripe));
    let window = attempt!(stripe.window(37, 1000, 16));
    let inside = window.x1 == 37 && window.y1 <= 1000 && window.y0.is_multiple_of(16);
    if !inside || window.y1 <= window.y0 {
        return Err(format!("stripe {stripe:?} gave the window {window:?}"));
    }
    Ok(Rendered)
}

fn check_ingp_raw(_: &Fixtures, dir: &Path, bytes: &[u8]) -> Result<Verdict, String> {
    load_and_render(dir, "snapshot.msgpack", bytes)
}

fn check_ingp_gzip(_: &Fixtures, dir: &Path, bytes: &[u8]) -> Result<Verdict, String> {
    load_and_render(dir, "snapshot.ingp", bytes)
}

fn check_ply(_: &Fixtures, dir: &Path, bytes: &[u8]) -> Result<Verdict, String> {
    load_and_render(dir, "splats.ply", bytes)
}

/// Nerfacto run `r` of the fixtures in `dir`, file `i` of it (config, dataparser,
/// checkpoint) replaced by `bytes`, loaded and rendered.
fn run_with(f: &Fixtures, r: usize, dir: &Path, i: usize, bytes: &[u8]) -> Result<Verdict, String> {
    let run = dir.join("run");
    std::fs::create_dir_all(run.join("nerfstudio_models")).unwrap();
    let names = [
        "config.yml".to_string(),
        "dataparser_transforms.json".to_string(),
        format!("nerfstudio_models/step-{:09}.ckpt", common_nerfacto::STEP),
    ];
    for (k, name) in names.iter().enumerate() {
        write(&run.join(name), if k == i { bytes } else { &f.runs[r][k] });
    }
    render_loaded(&attempt!(
        SceneDesc::for_path(&run).and_then(SceneDesc::load)
    ))
}

fn load_and_render(dir: &Path, name: &str, bytes: &[u8]) -> Result<Verdict, String> {
    let path = dir.join(name);
    write(&path, bytes);
    render_loaded(&attempt!(
        SceneDesc::for_path(&path).and_then(SceneDesc::load)
    ))
}

/// Renders a loaded scene (instances in their own frame, objects at the origin) from a
/// camera looking at what it holds.
fn render_loaded(loaded: &LoadedScene) -> Result<Verdict, String> {
    let scene = attempt!(loaded.place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY)));
    let boxes = scene
        .marched()
        .map(|i| i.field().bounds())
        .chain(scene.splats().map(|s| s.splats().bounds()));
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for b in boxes {
        lo = lo.min(b.min.as_dvec3());
        hi = hi.max(b.max.as_dvec3());
    }
    let size = (hi - lo).length();
    let (eye, target) = if size.is_finite() && size > 1e-6 && size < 1e6 {
        let centre = 0.5 * (lo + hi);
        (
            centre + DVec3::new(0.3, -1.0, 0.5).normalize() * size,
            centre,
        )
    } else {
        (DVec3::new(0.3, -5.0, 2.0), DVec3::ZERO)
    };
    let projection = Projection::Perspective(Perspective::from_vertical_fov(8, 8, 50.0).unwrap());
    let camera = Camera::new(look_at(eye, target), projection).unwrap();
    finite_render(&scene, &camera)
}

/// Renders (at most) the top-left 8×8 of `camera`'s image; a render error is an outcome,
/// planes that are not finite are not.
fn finite_render(scene: &Scene, camera: &Camera) -> Result<Verdict, String> {
    let (w, h) = camera.resolution();
    let window = Window::new(0, 0, w.min(8), h.min(8));
    let settings = RenderSettings::new(Quality::Draft.params(), Outputs::all());
    finite(&attempt!(render(scene, camera, window, &settings))).map(|()| Rendered)
}

/// Colour and alpha finite, depth never NaN (+∞ is where nothing was hit).
fn finite(p: &Planes) -> Result<(), String> {
    let colour = p.rgb.iter().flatten().chain(&p.alpha);
    for plane in colour {
        if let Some(v) = plane.data.iter().find(|v| !v.is_finite()) {
            return Err(format!("a colour or alpha value is {v}"));
        }
    }
    let depth = [&p.depth_z, &p.depth_ray, &p.depth_median];
    for plane in depth.into_iter().flatten() {
        if plane.data.iter().any(|v| v.is_nan()) {
            return Err("a depth value is NaN".into());
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// The runner.

/// What one case did.
enum Outcome {
    Passed {
        verdict: Verdict,
        peak: usize,
        time: Duration,
    },
    Failed(String),
}

/// Cases run one at a time (the allocator's counts are the whole process's).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The input of case `case` of target `t`: a mutation of the target's seeds drawn by a
/// generator seeded with the target and the case number.
fn case_input(t: usize, case: u64) -> Vec<u8> {
    let target = &targets()[t];
    let mut rng = SplitMix64::new(case.wrapping_mul(0x9E37_79B9).wrapping_add(t as u64 * 7919));
    let which = rng.below(target.seeds.len() as u64) as usize;
    mutate(&mut rng, &target.seeds, which, target.kind)
}

/// Runs case `case` of target `t` ([`case_input`]).
fn run_case(t: usize, case: u64) -> Outcome {
    let target = &targets()[t];
    let bytes = case_input(t, case);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().to_path_buf();
    let check = target.check;
    let bound = memory_bound(bytes.len());

    CASE_TARGET.store(t, Ordering::SeqCst);
    CASE_NUMBER.store(case, Ordering::SeqCst);
    REFUSED_ONE.store(false, Ordering::SeqCst);
    let before = LIVE.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    let start = Instant::now();
    let (tx, rx) = mpsc::channel();
    let worker = std::thread::Builder::new()
        .name(format!("{} case {case}", target.name))
        .spawn(move || {
            let result = check(fixtures(), &path, &bytes);
            let _ = tx.send(result);
        })
        .unwrap();
    let what = format!("{} case {case}", target.name);
    let result = match rx.recv_timeout(CASE_TIME) {
        Ok(result) => result,
        Err(mpsc::RecvTimeoutError::Timeout) => {
            // The worker is left running: the test fails now and the process ends with it.
            return Outcome::Failed(format!("{what}: still running after {CASE_TIME:?}"));
        }
        Err(mpsc::RecvTimeoutError::Disconnected) => {
            let message = match worker.join() {
                Err(panic) => panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default(),
                Ok(()) => String::new(),
            };
            return Outcome::Failed(format!("{what}: panicked: {message}"));
        }
    };
    let _ = worker.join();
    let time = start.elapsed();
    let peak = PEAK.load(Ordering::SeqCst).saturating_sub(before);
    CASE_TARGET.store(usize::MAX, Ordering::SeqCst);
    drop(dir);
    if REFUSED_ONE.load(Ordering::SeqCst) {
        return Outcome::Failed(format!(
            "{what}: asked for more than {REFUSED} bytes at once"
        ));
    }
    if peak > bound {
        return Outcome::Failed(format!(
            "{what}: held {peak} bytes at once, past its bound of {bound}"
        ));
    }
    match result {
        Ok(verdict) => Outcome::Passed {
            verdict,
            peak,
            time,
        },
        Err(e) => Outcome::Failed(format!("{what}: {e}")),
    }
}

/// Runs `cases(target)` cases of every target from case number `first`; fails listing every
/// failing case.
fn run_all(first: u64, cases: impl Fn(&Target) -> u64) {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let mut failures = Vec::new();
    for (t, target) in targets().iter().enumerate() {
        let n = cases(target);
        if n == 0 {
            continue;
        }
        let (mut peak, mut slowest, mut rendered) = (0, Duration::ZERO, 0);
        let start = Instant::now();
        for case in first..first + n {
            match run_case(t, case) {
                Outcome::Passed {
                    verdict,
                    peak: p,
                    time,
                } => {
                    rendered += u64::from(verdict == Rendered);
                    peak = peak.max(p);
                    slowest = slowest.max(time);
                }
                Outcome::Failed(why) => {
                    let hung = why.contains("still running");
                    failures.push(why);
                    if hung {
                        break;
                    }
                }
            }
        }
        println!(
            "{:28} {n:6} cases ({rendered:6} rendered) in {:6.2} s, slowest {:5.3} s, \
             peak {:6.1} MiB",
            target.name,
            start.elapsed().as_secs_f64(),
            slowest.as_secs_f64(),
            peak as f64 / f64::from(1 << 20)
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Replays one case (a regression kept by name).
fn replay(target: &str, case: u64) {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let t = TARGET_NAMES.iter().position(|n| *n == target).unwrap();
    if let Outcome::Failed(why) = run_case(t, case) {
        panic!("{why}");
    }
}

#[test]
fn every_seed_loads_and_renders_finite_planes() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    for target in targets() {
        for (i, seed) in target.seeds.iter().enumerate() {
            let dir = tempfile::tempdir().unwrap();
            let verdict = (target.check)(fixtures(), dir.path(), seed)
                .unwrap_or_else(|e| panic!("{} seed {i}: {e}", target.name));
            assert_eq!(verdict, Rendered, "{} seed {i}", target.name);
        }
    }
}

#[test]
fn mutated_inputs_give_errors_or_finite_renders() {
    run_all(0, |t| t.cases);
}

/// The long run: `NERFX_FUZZ_CASES` cases per target (default 10000), from case 1000000 or
/// `NERFX_FUZZ_FIRST`; `NERFX_FUZZ_TARGETS` (words separated by commas) keeps the targets
/// whose names hold one.
#[test]
#[ignore = "long fuzz run"]
fn long_fuzz_run() {
    let n = std::env::var("NERFX_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000);
    let only = std::env::var("NERFX_FUZZ_TARGETS").unwrap_or_default();
    let first: u64 = std::env::var("NERFX_FUZZ_FIRST").map_or(1_000_000, |v| {
        v.parse()
            .unwrap_or_else(|_| panic!("NERFX_FUZZ_FIRST: a case number, not '{v}'"))
    });
    assert!(
        first.checked_add(n).is_some(),
        "NERFX_FUZZ_FIRST + NERFX_FUZZ_CASES overflows"
    );
    let chosen = |t: &Target| only.is_empty() || only.split(',').any(|w| t.name.contains(w));
    run_all(first, |t| if chosen(t) { n } else { 0 });
}

/// Writes the input of one case to a file, to look at it: `NERFX_FUZZ_CASE="scene JSON:113"
/// NERFX_FUZZ_OUT=case.json cargo test --test fuzz -- --ignored write_case_input`.
#[test]
#[ignore = "a tool: writes one case's input"]
fn write_case_input() {
    let spec = std::env::var("NERFX_FUZZ_CASE").expect("NERFX_FUZZ_CASE=\"target:case\"");
    let (name, case) = spec.rsplit_once(':').expect("target:case");
    let t = TARGET_NAMES
        .iter()
        .position(|n| *n == name)
        .expect("a target's name");
    let out = std::env::var("NERFX_FUZZ_OUT").expect("NERFX_FUZZ_OUT=<file>");
    std::fs::write(out, case_input(t, case.parse().expect("a case number"))).unwrap();
}

/// A Gaussian with a cutoff of 2³¹ standard deviations was stepped through for minutes; the
/// cutoff is now bounded at load.
#[test]
fn regression_scene_gaussian_cutoff_of_two_billion() {
    replay("scene JSON", 113);
}

// ---------------------------------------------------------------------------------------
// Inflate bombs: small files claiming gigabytes.

/// Runs `f` with no case running beside it; returns its result and the most it held at once
/// beyond what was alive before.
fn peak_of<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let before = LIVE.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    let r = f();
    (r, PEAK.load(Ordering::SeqCst).saturating_sub(before))
}

/// A snapshot of `spec` with its top-level entries in `order` (the snapshot first or last)
/// and its `params_binary` replaced by a header declaring `claimed` bytes followed by
/// `written` zero bytes, gzip-framed as it is written (nothing of that size is held here).
fn params_bomb(
    spec: &common_ingp::Spec,
    snapshot_first: bool,
    claimed: u32,
    written: usize,
) -> Vec<u8> {
    let bytes = common_ingp::snapshot_bytes(spec);
    let rmpv::Value::Map(mut top) = rmpv::decode::read_value(&mut &bytes[..]).unwrap() else {
        panic!("a snapshot is a map");
    };
    let marker = vec![0xA5u8; 13];
    for (k, v) in &mut top {
        if k.as_str() == Some("snapshot") {
            let rmpv::Value::Map(snap) = v else {
                panic!("snapshot is a map")
            };
            for (k, v) in snap {
                if k.as_str() == Some("params_binary") {
                    *v = rmpv::Value::Binary(marker.clone());
                }
            }
        }
    }
    top.sort_by_key(|(k, _)| (k.as_str() == Some("snapshot")) != snapshot_first);
    let mut encoded = Vec::new();
    rmpv::encode::write_value(&mut encoded, &rmpv::Value::Map(top)).unwrap();
    let mut needle = vec![0xc4, 13];
    needle.extend(&marker);
    let at = encoded
        .windows(needle.len())
        .position(|w| w == needle)
        .unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(&encoded[..at]).unwrap();
    gz.write_all(&[0xc6]).unwrap();
    gz.write_all(&claimed.to_be_bytes()).unwrap();
    let zeros = vec![0u8; 1 << 20];
    let mut left = written;
    while left > 0 {
        let n = left.min(zeros.len());
        gz.write_all(&zeros[..n]).unwrap();
        left -= n;
    }
    gz.write_all(&encoded[at + needle.len()..]).unwrap();
    gz.finish().unwrap()
}

fn small_snapshot() -> common_ingp::Spec {
    common_ingp::Spec {
        n_cascades: 1,
        log2_table_size: 10,
        gzip: false,
        ..common_ingp::Spec::small_8x4()
    }
}

/// A gzip snapshot whose parameters claim 3 GiB after the configuration that says they hold
/// a few hundred kilobytes: refused at the header, holding next to nothing.
#[test]
fn ingp_params_claiming_gigabytes_are_refused_at_their_header() {
    let bomb = params_bomb(&small_snapshot(), false, 3 << 30, 1 << 20);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.ingp");
    write(&path, &bomb);
    let (r, peak) = peak_of(|| nerfx_core::field::IngpField::load(&path).map(|_| ()));
    let e = r.unwrap_err().to_string();
    assert!(
        e.contains("bomb.ingp") && e.contains("snapshot.params_binary") && e.contains("3221225472"),
        "{e}"
    );
    assert!(peak < 4 << 20, "held {peak} bytes to refuse it");
}

/// The same with the snapshot written before its configuration: its binaries are read past
/// (never held), then refused against the configuration read after them.
#[test]
fn ingp_params_before_their_configuration_are_bounded_too() {
    let bomb = params_bomb(&small_snapshot(), true, 48 << 20, 48 << 20);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.ingp");
    write(&path, &bomb);
    let (r, peak) = peak_of(|| nerfx_core::field::IngpField::load(&path).map(|_| ()));
    let e = r.unwrap_err().to_string();
    assert!(
        e.contains("snapshot.params_binary") && e.contains("more than the network"),
        "{e}"
    );
    assert!(peak < 16 << 20, "held {peak} bytes to refuse it");
}

/// A valid snapshot with its binaries before its configuration loads as the same field.
#[test]
fn ingp_snapshot_before_its_configuration_loads_the_same() {
    // Its allocations would count in the bombs' peaks.
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let spec = common_ingp::Spec {
        log2_table_size: 17,
        ..small_snapshot()
    };
    let bytes = common_ingp::snapshot_bytes(&spec);
    let rmpv::Value::Map(mut top) = rmpv::decode::read_value(&mut &bytes[..]).unwrap() else {
        panic!("a snapshot is a map");
    };
    top.sort_by_key(|(k, _)| k.as_str() != Some("snapshot"));
    let mut reordered = Vec::new();
    rmpv::encode::write_value(&mut reordered, &rmpv::Value::Map(top)).unwrap();
    assert_ne!(reordered, bytes);
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.msgpack"), dir.path().join("b.msgpack"));
    write(&a, &bytes);
    write(&b, &reordered);
    let (fa, fb) = (
        nerfx_core::field::IngpField::load(&a).unwrap(),
        nerfx_core::field::IngpField::load(&b).unwrap(),
    );
    let points: Vec<glam::Vec3> = (0..64)
        .map(|i| glam::Vec3::new(i as f32 / 64.0 - 0.5, 0.1, -0.2))
        .collect();
    use nerfx_core::field::Field;
    let (mut sa, mut sb) = (vec![0.0; 64], vec![0.0; 64]);
    fa.density(&points, &mut sa);
    fb.density(&points, &mut sb);
    assert_eq!(sa, sb);
    assert_eq!(fa.bounds(), fb.bounds());
}

/// A checkpoint's deflated storage declaring more than deflate can expand its bytes to, and
/// one declaring more than its tensor's storage holds: both refused before inflating.
#[test]
fn checkpoint_entries_declaring_more_than_they_can_hold_are_refused() {
    let f = fixtures();
    let ckpt = &f.runs[0][2];
    // The largest storage entry: its declared size (central directory and local header)
    // raised by a factor of 4096.
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = ckpt.clone();
    let mut patched = 0;
    let mut at = 0;
    while let Some(p) = bytes[at..]
        .windows(4)
        .position(|w| w == [0x50, 0x4b, 0x01, 0x02])
    {
        let cd = at + p;
        let name_len = u16::from_le_bytes([bytes[cd + 28], bytes[cd + 29]]) as usize;
        let name = String::from_utf8_lossy(&bytes[cd + 46..cd + 46 + name_len]).to_string();
        if name.contains("/data/") {
            let size = u32::from_le_bytes(bytes[cd + 24..cd + 28].try_into().unwrap());
            let big = (size.max(1) as u64 * 4096).min(u32::MAX as u64 - 1) as u32;
            bytes[cd + 24..cd + 28].copy_from_slice(&big.to_le_bytes());
            let local = u32::from_le_bytes(bytes[cd + 42..cd + 46].try_into().unwrap()) as usize;
            bytes[local + 22..local + 26].copy_from_slice(&big.to_le_bytes());
            patched += 1;
        }
        at = cd + 4;
    }
    assert!(patched > 0);
    let (r, peak) = peak_of(|| run_with(f, 0, dir.path(), 2, &bytes));
    let Ok(Refused(e)) = r else {
        panic!("accepted: {r:?}")
    };
    assert!(e.contains("declares") && e.contains("more than"), "{e}");
    assert!(peak < 64 << 20, "held {peak} bytes");
}

// ---------------------------------------------------------------------------------------
// Output paths: what stands where an output is written.

/// A 2×2 image to write.
fn tiny_image() -> Planes {
    let p = nerfx_core::image::Plane::filled(2, 2, 0.5);
    Planes {
        width: 2,
        height: 2,
        rgb: Some([p.clone(), p.clone(), p.clone()]),
        alpha: Some(p),
        depth_z: None,
        depth_ray: None,
        depth_median: None,
    }
}

/// Every kind of thing that can stand at an output path, made inside a temporary folder
/// (devices by `mknod` as root; never the machine's `/dev`): a regular file keeps its
/// permissions, a link stays a link to a replaced target, a dangling link's target is
/// created, a character device and a FIFO are written directly and stay what they were, a
/// block device, a socket and a folder are refused naming what is there; and, as a user who
/// cannot write the folder, a writable file in it is refused naming the folder.
#[test]
fn output_paths_of_every_kind() {
    use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
    // Its allocations would count in the bombs' peaks.
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let dir = tempfile::tempdir().unwrap();
    let at = |n: &str| dir.path().join(n);
    let image = tiny_image();
    let write = |p: &Path| nerfx_core::image::write_png_preview(p, &image);
    let png = |p: &Path| std::fs::read(p).unwrap().starts_with(b"\x89PNG");

    // A regular file of mode 0600 stays 0600.
    let file = at("file.png");
    std::fs::write(&file, b"old").unwrap();
    std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).unwrap();
    write(&file).unwrap();
    assert!(png(&file));
    assert_eq!(std::fs::metadata(&file).unwrap().mode() & 0o777, 0o600);

    // A link stays a link; its target is replaced. A dangling link's target is created.
    let target = at("target.png");
    std::fs::write(&target, b"old").unwrap();
    std::os::unix::fs::symlink(&target, at("link.png")).unwrap();
    write(&at("link.png")).unwrap();
    assert!(std::fs::symlink_metadata(at("link.png"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(png(&target));
    std::os::unix::fs::symlink(at("later.png"), at("dangling.png")).unwrap();
    write(&at("dangling.png")).unwrap();
    assert!(std::fs::symlink_metadata(at("dangling.png"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(png(&at("later.png")));

    // A FIFO is written directly: a reader gets the image, the FIFO stays a FIFO.
    let fifo = at("fifo");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(&fifo).unwrap())
    };
    write(&fifo).unwrap();
    assert!(reader.join().unwrap().starts_with(b"\x89PNG"));
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());

    // Devices, as root: a character device (a null device made here) is written to and
    // stays a device; a block device is refused.
    let root = unsafe { libc_geteuid() } == 0;
    if root {
        let null = at("null");
        let ok = std::process::Command::new("mknod")
            .arg(&null)
            .args(["c", "1", "3"])
            .status();
        if ok.is_ok_and(|s| s.success()) {
            write(&null).unwrap();
            assert!(std::fs::symlink_metadata(&null)
                .unwrap()
                .file_type()
                .is_char_device());
            let block = at("block");
            let ok = std::process::Command::new("mknod")
                .arg(&block)
                .args(["b", "7", "200"])
                .status();
            if ok.is_ok_and(|s| s.success()) {
                let e = write(&block).unwrap_err().to_string();
                assert!(e.contains("block"), "{e}");
                assert!(std::fs::symlink_metadata(&block)
                    .unwrap()
                    .file_type()
                    .is_block_device());
            }
        }
    }

    // A socket and a folder are refused, and left as they are.
    let socket = at("socket");
    let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
    let e = write(&socket).unwrap_err().to_string();
    assert!(e.contains("socket"), "{e}");
    assert!(std::fs::symlink_metadata(&socket)
        .unwrap()
        .file_type()
        .is_socket());
    std::fs::create_dir(at("folder")).unwrap();
    let e = write(&at("folder")).unwrap_err().to_string();
    assert!(e.contains("folder"), "{e}");

    // As nobody: a writable file in a folder nobody may not write is refused naming the
    // folder (the check runs this test's binary as that user, through `setpriv`).
    if root && std::env::var_os("NERFX_OUTPUT_AS_NOBODY").is_none() {
        let locked = at("locked");
        std::fs::create_dir(&locked).unwrap();
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
        let inside = locked.join("out.png");
        std::fs::write(&inside, b"old").unwrap();
        std::fs::set_permissions(&inside, std::fs::Permissions::from_mode(0o666)).unwrap();
        std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o755)).unwrap();
        let exe = std::env::current_exe().unwrap();
        let out = std::process::Command::new("setpriv")
            .args(["--reuid=nobody", "--regid=nogroup", "--clear-groups"])
            .arg(&exe)
            .args([
                "--exact",
                "output_as_nobody",
                "--nocapture",
                "--include-ignored",
            ])
            .env("NERFX_OUTPUT_AS_NOBODY", &inside)
            .output();
        if let Ok(out) = out {
            let text = String::from_utf8_lossy(&out.stdout).to_string();
            assert!(
                out.status.success(),
                "{text}{}",
                String::from_utf8_lossy(&out.stderr)
            );
            assert!(
                text.contains("refused:") && text.contains("locked"),
                "{text}"
            );
        }
    }
}

/// Run as another user by [`output_paths_of_every_kind`]: writes the file it is given and
/// prints the refusal.
#[test]
#[ignore = "run by output_paths_of_every_kind as an unprivileged user"]
fn output_as_nobody() {
    let Some(path) = std::env::var_os("NERFX_OUTPUT_AS_NOBODY") else {
        return;
    };
    let e = nerfx_core::image::write_png_preview(Path::new(&path), &tiny_image()).unwrap_err();
    println!("refused: {e}");
}

extern "C" {
    #[link_name = "geteuid"]
    fn libc_geteuid() -> u32;
}
