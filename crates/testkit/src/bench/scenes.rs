//! The benchmark's scenes, one per kind of content the presets must handle: the analytic
//! demo, thin analytic sheets (surfaces thinner than any step), a smooth trained fog, a dense
//! trained blob and Gaussian splats; each with its camera and the reference it is measured
//! against.

use std::path::Path;
use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3, Vec3};

use super::snapshot::{write_snapshot, SnapshotSpec};
use super::splats::{framing_camera, generated_splats};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::demo::{self, look_at};
use nerfx_core::error::{Error, Result};
use nerfx_core::field::{Analytic, IngpField, Primitive, ShColor, Shape, Splats};
use nerfx_core::scene::{FieldHandle, Instance, NgpInstance, Scene, SplatInstance};

/// A benchmark scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum SceneKind {
    /// The embedded analytic demo (see [`nerfx_core::demo`]).
    Demo,
    /// Thin, dense analytic sheets at angles, inside a faint haze.
    Sheets,
    /// A smooth trained fog: an instant-ngp snapshot (16 × 2 levels) occupied in a ball.
    Fog,
    /// A dense trained blob: an instant-ngp snapshot (8 × 4 levels) that rays stop in.
    Blob,
    /// Gaussian splats (a PLY, or a generated capture-like set).
    Splats,
}

impl SceneKind {
    /// Every scene, in the report's order.
    pub const ALL: [SceneKind; 5] = [
        SceneKind::Demo,
        SceneKind::Sheets,
        SceneKind::Fog,
        SceneKind::Blob,
        SceneKind::Splats,
    ];

    /// The scene's identifier (as `--scene` takes it).
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Demo => "demo",
            SceneKind::Sheets => "sheets",
            SceneKind::Fog => "fog",
            SceneKind::Blob => "blob",
            SceneKind::Splats => "splats",
        }
    }
}

/// What a scene's renders are measured against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Truth {
    /// The exact closed-form integral of every pixel ([`crate::reference`]).
    Exact,
    /// A much finer nerfx march (trained fields have no closed form).
    FineMarch,
    /// An adaptive f64 quadrature of the trained field between its mask's crossings
    /// ([`crate::reference::render_trained`]), which shares no code with the marcher.
    Quadrature,
    /// None: splats are rasterised, not marched, exactly as gsplat's classic mode (checked
    /// against a NumPy rasteriser in the tests); the presets do not change them.
    Rasterised,
}

/// A scene ready to render.
pub struct BenchScene {
    /// Which one.
    pub kind: SceneKind,
    /// What it holds, for the report.
    pub description: String,
    /// The scene.
    pub scene: Scene,
    /// Its camera, at the benchmark's size.
    pub camera: Camera,
    /// Its reference.
    pub truth: Truth,
    /// A trained scene marched by its trainer's own marcher instead (instant-ngp's), as a
    /// further reference row.
    pub native: Option<Scene>,
}

/// Builds `kind` at `width × height`. Generated snapshot files are written into `dir` and
/// removed once loaded. `splats` is the PLY the splat scene renders (else 200 000 generated
/// splats).
pub fn build(
    kind: SceneKind,
    width: u32,
    height: u32,
    dir: &Path,
    splats: Option<&Path>,
) -> Result<BenchScene> {
    let framed = |eye: DVec3| -> Result<Camera> {
        let p = Perspective::from_vertical_fov(width, height, 40.0)?;
        Camera::new(look_at(eye, DVec3::ZERO), Projection::Perspective(p))
    };
    let mut native = None;
    let (description, scene, camera, truth) = match kind {
        SceneKind::Demo => {
            let (scene, camera) = demo::scene_and_camera(width, height)?;
            let d = "analytic object in an analytic environment (boxes, spheres, Gaussian haze)";
            (d.to_string(), scene, camera, Truth::Exact)
        }
        SceneKind::Sheets => (
            "four analytic sheets 1e-3 to 1e-5 units thick (optical depth 0.5 to 3 across), \
             rotated, inside a faint Gaussian haze"
                .to_string(),
            sheets()?,
            framed(DVec3::new(2.6, -3.0, 1.4))?,
            Truth::Exact,
        ),
        SceneKind::Fog => {
            let spec = SnapshotSpec::fog_sphere();
            let (scene, ngp) = trained(dir, "fog", &spec)?;
            native = Some(ngp);
            let d = "instant-ngp snapshot, 16×2 levels, 2^19 rows, fp16, weights of std 0.05, \
                     occupied in a ball of radius 0.35 (a smooth fog, σ ≈ 0.33/unit)";
            (
                d.to_string(),
                scene,
                framed(DVec3::new(2.4, -3.0, 0.9).normalize() * 4.0)?,
                Truth::FineMarch,
            )
        }
        SceneKind::Blob => {
            let spec = SnapshotSpec::dense_blob();
            let (scene, ngp) = trained(dir, "blob", &spec)?;
            native = Some(ngp);
            let d = "instant-ngp snapshot, 8×4 levels, 2^19 rows, fp16, three balls occupied, \
                     σ's row scaled by 4 (rays stop inside)";
            (
                d.to_string(),
                scene,
                framed(DVec3::new(2.2, -1.6, 0.8))?,
                Truth::Quadrature,
            )
        }
        SceneKind::Splats => {
            let (d, splats) = match splats {
                Some(path) => (format!("splats of {}", path.display()), Splats::load(path)?),
                None => (
                    "200 000 generated splats, SH degree 3".to_string(),
                    generated_splats(200_000),
                ),
            };
            let d = format!("{d} ({} splats)", splats.len());
            let splats = Arc::new(splats);
            let camera = framing_camera(&splats, width, height)?;
            let instance = SplatInstance::new("splats", splats, DMat4::IDENTITY, None, false)?;
            let scene = Scene::default().with(vec![instance]);
            (d, scene, camera, Truth::Rasterised)
        }
    };
    Ok(BenchScene {
        kind,
        description,
        scene,
        camera,
        truth,
        native,
    })
}

/// A scene of one instant-ngp snapshot written from `spec` into `dir`, loaded, and removed;
/// and the same snapshot marched by instant-ngp's own marcher.
fn trained(dir: &Path, name: &str, spec: &SnapshotSpec) -> Result<(Scene, Scene)> {
    let path = write_snapshot(dir, &format!("nerfx-bench-{name}"), spec)?;
    let field = IngpField::load(&path);
    std::fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
    let field = Arc::new(field?);
    let handle = FieldHandle::new(field.clone());
    let scene = Scene::new(vec![Instance::new(name, handle, DMat4::IDENTITY, None)?]);
    let native = Scene::new([NgpInstance::new(name, field, DMat4::IDENTITY, None)?]);
    Ok((scene, native))
}

/// Four thin sheets (boxes flat along z, rotated by their instance) and a haze: surfaces far
/// thinner than any preset's step, which only the marcher's refinement finds.
fn sheets() -> Result<Scene> {
    let sheet = |half_thickness: f32, density: f32, rgb: Vec3| Analytic {
        primitives: vec![Primitive {
            shape: Shape::Box {
                min: Vec3::new(-1.0, -0.7, -half_thickness),
                max: Vec3::new(1.0, 0.7, half_thickness),
            },
            density,
            color: ShColor::constant(rgb),
        }],
    };
    let placed = |name: &str, field: Analytic, axis: DVec3, angle: f64, at: DVec3| {
        Instance::new(
            name,
            FieldHandle::analytic(field),
            DMat4::from_rotation_translation(DQuat::from_axis_angle(axis.normalize(), angle), at),
            None,
        )
    };
    let haze = Analytic {
        primitives: vec![Primitive {
            shape: Shape::Gaussian {
                center: Vec3::ZERO,
                sigma: 0.8,
                cutoff: 3.0,
            },
            density: 0.15,
            color: ShColor::constant(Vec3::new(0.6, 0.65, 0.7)),
        }],
    };
    Ok(Scene::new(vec![
        // Optical depth across = 2·half_thickness·density.
        placed(
            "sheet a",
            sheet(5e-4, 500.0, Vec3::new(0.9, 0.3, 0.2)),
            DVec3::X,
            0.3,
            DVec3::new(0.0, 0.0, -0.4),
        )?,
        placed(
            "sheet b",
            sheet(5e-5, 1e4, Vec3::new(0.2, 0.8, 0.3)),
            DVec3::new(1.0, 1.0, 0.0),
            1.1,
            DVec3::new(0.2, 0.1, 0.0),
        )?,
        placed(
            "sheet c",
            sheet(5e-6, 3e5, Vec3::new(0.25, 0.35, 0.95)),
            DVec3::new(0.0, 1.0, 0.3),
            -0.9,
            DVec3::new(-0.3, 0.2, 0.3),
        )?,
        placed(
            "sheet d",
            sheet(2.5e-4, 1e3, Vec3::new(0.9, 0.85, 0.2)),
            DVec3::Z,
            0.0,
            DVec3::new(0.1, -0.2, 0.55),
        )?,
        placed("haze", haze, DVec3::Z, 0.0, DVec3::ZERO)?,
    ]))
}
