//! The nerfx **shot file**: what the Blender add-on writes per frame (camera placement and
//! intrinsics, the NeRF object's matrix `N`), JSON, schema version 1.
//!
//! ```json
//! {"version": 1, "fps": 24, "fps_base": 1.0,
//!  "resolution_x": 1920, "resolution_y": 1080, "resolution_percentage": 100,
//!  "pixel_aspect_x": 1, "pixel_aspect_y": 1,
//!  "nerf_object": "NeRF",
//!  "frames": [{"frame": 1001,
//!     "camera": {"matrix_world": [[1,0,0,0],[0,1,0,0],[0,0,1,5],[0,0,0,1]],
//!                "type": "PERSP", "lens": 50, "sensor_width": 36, "sensor_height": 24,
//!                "sensor_fit": "AUTO", "shift_x": 0, "shift_y": 0,
//!                "clip_start": 0.1, "clip_end": 1000, "stereo": null,
//!                "dof": {"focus_distance": 5, "fstop": 2.8, "blades": 0, "rotation": 0,
//!                        "ratio": 1}},
//!     "objects": {"NeRF": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}}]}
//! ```
//!
//! Matrices are lists of four **rows** (Blender's `matrix_world` read row by row). `type` is
//! `PERSP` or `PANO`; a `PANO` camera needs `"panorama_type": "EQUIRECTANGULAR"` (the full
//! sphere) and may carry `"stereo": {"mode": "ODS"|"VR180", "eye": "left"|"right"|"both",
//! "ipd": 0.064}`; the resolution is then per eye. For `PERSP`, `lens`, `sensor_width`,
//! `sensor_height` and `sensor_fit` are required. Optional, with Blender's defaults:
//! `fps_base` (1), `resolution_percentage` (100), `pixel_aspect_x/y` (1), `shift_x/y` (0),
//! `clip_start` (0.1), `clip_end` (1000), `stereo` (none), `dof` (none: no depth of field).
//! `dof` is a perspective camera's depth of field at that frame (see [`DepthOfField`]):
//! `focus_distance` (camera depth of the focus plane, scene units; the add-on resolves a focus
//! object per frame) and `fstop` are required, `blades` (0), `rotation` (0, radians) and
//! `ratio` (1) optional. Unknown fields are ignored.
//!
//! Reading parses the text with serde into a JSON tree, then walks it with typed accessors
//! that know where they are, so that every message names the file, the frame index and the
//! field (`shot.json: frames[3].camera.lens: expected a number > 0, got 0`); a derived
//! `Deserialize` could not say *which* field had the wrong type. Python's `json` writes
//! non-finite floats as bare `NaN`/`Infinity`, which is not JSON: those tokens are read as
//! `null` so that the refusal can name the field. Writing goes through private `Serialize`
//! structs, after checking that every number is finite.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DMat4;
use serde::Serialize;
use serde_json::Value;

use super::{
    BlenderIntrinsics, Camera, DepthOfField, Equirect, Eye, MotionBlur, Ods, Perspective,
    Projection, SensorFit, ShutterPosition, Vr180, MAX_BLADES,
};
use crate::error::{Error, Result};
use crate::json::{self, short, Describe, Obj, Style};

/// The shot-file schema version this code reads and writes.
pub(crate) const SHOT_VERSION: u64 = 1;

/// A shot: output format and, per frame, the camera and the object matrices.
#[derive(Clone, Debug, PartialEq)]
pub struct Shot {
    /// Frames per second (`scene.render.fps`); the true rate is `fps / fps_base`.
    pub fps: f64,
    /// `scene.render.fps_base`.
    pub fps_base: f64,
    /// Output width before the percentage (per eye for stereo).
    pub resolution_x: u32,
    /// Output height before the percentage (per eye for stereo).
    pub resolution_y: u32,
    /// Resolution scale in percent.
    pub resolution_percentage: u32,
    /// Pixel aspect X (perspective cameras only).
    pub pixel_aspect_x: f64,
    /// Pixel aspect Y (perspective cameras only).
    pub pixel_aspect_y: f64,
    /// Name of the NeRF stand-in object, whose matrix `N` every frame carries.
    pub nerf_object: String,
    /// The frames, in file order; frame numbers are unique.
    pub frames: Vec<ShotFrame>,
    /// Blender's motion blur, when the scene renders with it (`motion_blur` in the file:
    /// `{"shutter": frames, "position": "start" | "center" | "end"}`).
    pub motion_blur: Option<MotionBlur>,
    /// The file the shot was read from, used in messages (empty when built in memory); not
    /// written.
    pub source: PathBuf,
    /// Where a scene's fixed placements are given; not written (shot files are in Blender's
    /// world).
    pub scene_world: SceneWorld,
}

/// The frame a scene's fixed placements (`world_from_field` of an instance bound to no
/// object) are given in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SceneWorld {
    /// Blender's world: the shot file's.
    #[default]
    Blender,
    /// The NeRF object's frame: a nerfstudio camera path is written in the field's frame
    /// (`N⁻¹·C` per camera), so a fixed placement composes with the path's object.
    NerfObject,
}

/// One frame of a shot.
#[derive(Clone, Debug, PartialEq)]
pub struct ShotFrame {
    /// Blender's frame number.
    pub frame: i64,
    /// The camera at this frame.
    pub camera: ShotCamera,
    /// World matrices of named objects (`matrix_world`) at this frame.
    pub objects: BTreeMap<String, DMat4>,
}

/// A Blender camera at one frame, as the shot file stores it.
#[derive(Clone, Debug, PartialEq)]
pub struct ShotCamera {
    /// The camera object's `matrix_world` (camera to world).
    pub(crate) world_from_camera: DMat4,
    /// Perspective or equirectangular panorama.
    pub kind: ShotCameraKind,
    /// Focal length (mm).
    pub lens: f64,
    /// Sensor width (mm).
    pub sensor_width: f64,
    /// Sensor height (mm).
    pub sensor_height: f64,
    /// Sensor fit.
    pub sensor_fit: SensorFit,
    /// Horizontal shift, in units of the fitted side.
    pub shift_x: f64,
    /// Vertical shift, in units of the fitted side.
    pub shift_y: f64,
    /// Near clip distance (Blender units).
    pub clip_start: f64,
    /// Far clip distance (Blender units).
    pub clip_end: f64,
    /// Stereo settings of a panoramic camera; `None` for a mono camera.
    pub stereo: Option<ShotStereo>,
    /// Depth of field of a perspective camera; `None` for a pinhole (Blender's `use_dof`
    /// off).
    pub dof: Option<DepthOfField>,
}

/// The camera types a shot file may hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShotCameraKind {
    /// `"type": "PERSP"`.
    Perspective,
    /// `"type": "PANO"` with `"panorama_type": "EQUIRECTANGULAR"`.
    Equirect,
}

/// Stereo layout of a panoramic camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ShotStereo {
    /// ODS or VR180.
    pub mode: StereoMode,
    /// Which eye(s).
    pub eye: Eye,
    /// Interpupillary distance in scene units.
    pub ipd: f64,
}

/// Which stereo panorama.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
pub enum StereoMode {
    /// Omni-directional stereo (`"ODS"`), eyes stacked left over right.
    #[serde(rename = "ODS")]
    Ods,
    /// VR180 (`"VR180"`), eyes side by side.
    #[serde(rename = "VR180")]
    Vr180,
}

impl Shot {
    /// The pixel aspect (pixel width over height) of images `camera` renders of this shot:
    /// `pixel_aspect_x / pixel_aspect_y` for a perspective camera; panoramas have square
    /// pixels (their projection ignores Blender's pixel aspect).
    pub fn pixel_aspect_for(&self, camera: &Camera) -> f64 {
        match camera.projection() {
            Projection::Perspective(_) => self.pixel_aspect_x / self.pixel_aspect_y,
            _ => 1.0,
        }
    }

    /// Reads and validates a shot file.
    pub fn read(path: impl AsRef<Path>) -> Result<Shot> {
        let path = path.as_ref();
        let text = crate::input::read_text(path)?;
        Shot::from_json_str(&text, path)
    }

    /// Parses and validates shot JSON; `path_for_errors` names the source in messages.
    pub fn from_json_str(text: &str, path_for_errors: impl AsRef<Path>) -> Result<Shot> {
        let path = path_for_errors.as_ref();
        let root = json::parse_with_reason(text, path)?;
        let top = Obj::root(&root, path, SHOT_STYLE)?;
        let version = top.get::<u64>("version", "an integer")?;
        if version != SHOT_VERSION {
            return Err(top.error(
                "version",
                format!(
                    "version {version} is not supported; this nerfx reads version {SHOT_VERSION}"
                ),
            ));
        }
        let mut shot = Shot {
            fps: top.positive("fps")?,
            fps_base: top.positive_or("fps_base", 1.0)?,
            resolution_x: top.count("resolution_x")?,
            resolution_y: top.count("resolution_y")?,
            resolution_percentage: if top.has("resolution_percentage") {
                top.count("resolution_percentage")?
            } else {
                100
            },
            pixel_aspect_x: top.positive_or("pixel_aspect_x", 1.0)?,
            pixel_aspect_y: top.positive_or("pixel_aspect_y", 1.0)?,
            nerf_object: top.get::<String>("nerf_object", "a string")?,
            frames: Vec::new(),
            motion_blur: None,
            scene_world: SceneWorld::Blender,
            source: path.to_path_buf(),
        };
        if top.has("motion_blur") {
            let blur = top.object("motion_blur")?;
            let position = if blur.has("position") {
                blur.get::<ShutterPosition>("position", "\"start\", \"center\" or \"end\"")?
            } else {
                ShutterPosition::Center
            };
            let motion = MotionBlur {
                shutter: blur.finite("shutter", "a number of frames")?,
                position,
            };
            if let Err(Error::Invalid { message, .. }) = motion.validate("") {
                return Err(blur.error("shutter", message));
            }
            shot.motion_blur = Some(motion);
        }
        // The output format is shared by all frames: refuse an absurd size once, by field.
        let format = BlenderIntrinsics {
            resolution_x: shot.resolution_x,
            resolution_y: shot.resolution_y,
            resolution_percentage: shot.resolution_percentage,
            ..BlenderIntrinsics::default()
        };
        if let Err(Error::Invalid { what, message }) = format.effective_resolution() {
            return Err(Error::format(path, what, message));
        }
        let frames = top.array("frames")?;
        if frames.is_empty() {
            return Err(top.error("frames", "expected at least one frame"));
        }
        let mut index_of_frame = BTreeMap::new();
        for (i, value) in frames.iter().enumerate() {
            let node = Obj::new(value, path, format!("frames[{i}]"), SHOT_STYLE)?;
            let frame = read_frame(&node, &shot.nerf_object)?;
            if let Some(j) = index_of_frame.insert(frame.frame, i) {
                return Err(node.error(
                    "frame",
                    format!("frame {} is already given by frames[{j}]", frame.frame),
                ));
            }
            shot.frames.push(frame);
        }
        // Build every camera once, so that a bad matrix or resolution is reported now, with
        // its location, rather than mid-render.
        for frame in &shot.frames {
            frame.camera(&shot)?;
        }
        Ok(shot)
    }

    /// Writes the shot as JSON (schema version 1). Refuses non-finite numbers, which JSON
    /// cannot hold.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = self.to_json_string(path)?;
        crate::output::write_file(path, text.as_bytes())
    }

    /// The frame numbered `frame`; the error names the file and the frames it holds.
    pub fn frame(&self, frame: i64) -> Result<&ShotFrame> {
        if let Some(f) = self.frames.iter().find(|f| f.frame == frame) {
            return Ok(f);
        }
        let first = self.frames.iter().map(|f| f.frame).min();
        let last = self.frames.iter().map(|f| f.frame).max();
        let held = match (first, last) {
            (Some(a), Some(b)) => format!("{} frames, {a} to {b}", self.frames.len()),
            _ => "no frames".to_string(),
        };
        Err(Error::format(
            &self.source,
            "frames",
            format!("frame {frame} is not in the shot (it holds {held})"),
        ))
    }

    /// Frames per second: `fps / fps_base`.
    #[cfg(test)]
    pub(crate) fn frame_rate(&self) -> f64 {
        self.fps / self.fps_base
    }

    fn to_json_string(&self, path: &Path) -> Result<String> {
        let what = |loc: String| format!("{}: {loc}", path.display());
        let finite = |loc: String, v: f64| -> Result<f64> {
            if v.is_finite() {
                Ok(v)
            } else {
                Err(Error::invalid(
                    what(loc),
                    format!("{v} cannot be written to JSON"),
                ))
            }
        };
        let matrix = |loc: String, m: &DMat4| -> Result<[[f64; 4]; 4]> {
            if m.is_finite() {
                Ok(m.transpose().to_cols_array_2d())
            } else {
                Err(Error::invalid(what(loc), "matrix contains NaN or infinity"))
            }
        };
        let mut frames = Vec::with_capacity(self.frames.len());
        for (i, f) in self.frames.iter().enumerate() {
            let c = &f.camera;
            let at = |field: &str| format!("frames[{i}].camera.{field}");
            let mut objects = BTreeMap::new();
            for (name, m) in &f.objects {
                objects.insert(
                    name.as_str(),
                    matrix(format!("frames[{i}].objects.{name}"), m)?,
                );
            }
            let (kind, panorama_type) = match c.kind {
                ShotCameraKind::Perspective => ("PERSP", None),
                ShotCameraKind::Equirect => ("PANO", Some("EQUIRECTANGULAR")),
            };
            if let Some(s) = &c.stereo {
                finite(at("stereo.ipd"), s.ipd)?;
            }
            frames.push(RawFrame {
                frame: f.frame,
                camera: RawCamera {
                    matrix_world: matrix(at("matrix_world"), &c.world_from_camera)?,
                    kind,
                    panorama_type,
                    lens: finite(at("lens"), c.lens)?,
                    sensor_width: finite(at("sensor_width"), c.sensor_width)?,
                    sensor_height: finite(at("sensor_height"), c.sensor_height)?,
                    sensor_fit: c.sensor_fit,
                    shift_x: finite(at("shift_x"), c.shift_x)?,
                    shift_y: finite(at("shift_y"), c.shift_y)?,
                    clip_start: finite(at("clip_start"), c.clip_start)?,
                    clip_end: finite(at("clip_end"), c.clip_end)?,
                    stereo: c.stereo,
                    dof: match &c.dof {
                        None => None,
                        Some(d) => Some(RawDof {
                            focus_distance: finite(at("dof.focus_distance"), d.focus_distance)?,
                            fstop: finite(at("dof.fstop"), d.fstop)?,
                            blades: d.blades,
                            rotation: finite(at("dof.rotation"), d.rotation)?,
                            ratio: finite(at("dof.ratio"), d.ratio)?,
                        }),
                    },
                },
                objects,
            });
        }
        let raw = RawShot {
            version: SHOT_VERSION,
            fps: finite("fps".into(), self.fps)?,
            fps_base: finite("fps_base".into(), self.fps_base)?,
            resolution_x: self.resolution_x,
            resolution_y: self.resolution_y,
            resolution_percentage: self.resolution_percentage,
            pixel_aspect_x: finite("pixel_aspect_x".into(), self.pixel_aspect_x)?,
            pixel_aspect_y: finite("pixel_aspect_y".into(), self.pixel_aspect_y)?,
            nerf_object: &self.nerf_object,
            frames,
            motion_blur: self.motion_blur.map(|m| RawMotionBlur {
                shutter: m.shutter,
                position: m.position,
            }),
        };
        serde_json::to_string_pretty(&raw)
            .map_err(|e| Error::invalid(what("shot".into()), e.to_string()))
    }
}

impl ShotFrame {
    /// The camera of this frame, with the shot's output format: Blender's perspective camera,
    /// an equirectangular panorama, or ODS/VR180 for a stereo panorama.
    pub fn camera(&self, shot: &Shot) -> Result<Camera> {
        let index = shot.frames.iter().position(|f| f.frame == self.frame);
        let loc = match index {
            Some(i) => format!("frames[{i}].camera"),
            None => format!("frame {}: camera", self.frame),
        };
        let in_context = |e: Error| match e {
            Error::Invalid { what, message } => {
                Error::format(&shot.source, &loc, format!("{what}: {message}"))
            }
            other => other,
        };
        let c = &self.camera;
        if let Some(dof) = &c.dof {
            dof.validate("dof").map_err(in_context)?;
        }
        let intrinsics = c.intrinsics(shot);
        let projection = match (c.kind, c.stereo) {
            (ShotCameraKind::Perspective, None) => {
                Projection::Perspective(Perspective::from_blender(&intrinsics).map_err(in_context)?)
            }
            (ShotCameraKind::Perspective, Some(_)) => {
                return Err(Error::format(
                    &shot.source,
                    format!("{loc}.stereo"),
                    "ODS and VR180 need a panoramic camera (type PANO, EQUIRECTANGULAR)",
                ))
            }
            (ShotCameraKind::Equirect, stereo) => {
                let (w, h) = intrinsics.effective_resolution().map_err(in_context)?;
                match stereo {
                    None => Projection::Equirect(Equirect::new(w, h).map_err(in_context)?),
                    Some(s) => match s.mode {
                        StereoMode::Ods => {
                            Projection::Ods(Ods::new(w, h, s.eye, s.ipd).map_err(in_context)?)
                        }
                        StereoMode::Vr180 => {
                            Projection::Vr180(Vr180::new(w, h, s.eye, s.ipd).map_err(in_context)?)
                        }
                    },
                }
            }
        };
        Camera::new(c.world_from_camera, projection)
            .and_then(|camera| camera.with_clip(c.clip_start, c.clip_end))
            .map_err(in_context)
    }

    /// The frames a render of this frame averages over its camera's aperture: with depth of
    /// field on (a perspective camera with `dof`) and `samples` > 1, one frame per
    /// [`DepthOfField::lens_points`] point `l`, its camera moved by `l` in its own x–y plane
    /// (unit axes: Cycles clears the camera's scale too) and its shift changed by
    /// `−l·lens / (focus_distance·sensor)` (the sensor length the fit uses), so that every point
    /// of the focus plane keeps its pixel and each pixel sees the thin-lens ray through `l`
    /// (see the `aperture` module). Otherwise this frame alone, unchanged.
    pub fn through_aperture(&self, samples: u32) -> Vec<ShotFrame> {
        let c = &self.camera;
        let dof = match (c.kind, c.dof) {
            (ShotCameraKind::Perspective, Some(dof)) if samples > 1 => dof,
            _ => return vec![self.clone()],
        };
        let sensor = match c.sensor_fit {
            SensorFit::Vertical => c.sensor_height,
            _ => c.sensor_width,
        };
        let m = c.world_from_camera;
        let z = m.z_axis.truncate().normalize();
        let x = (m.x_axis.truncate() - z * m.x_axis.truncate().dot(z)).normalize();
        let y = z.cross(x);
        dof.lens_points(c.lens, samples)
            .into_iter()
            .map(|l| {
                let mut frame = self.clone();
                let cam = &mut frame.camera;
                cam.world_from_camera.w_axis += (x * l.x + y * l.y).extend(0.0);
                let slope = l / dof.focus_distance;
                cam.shift_x -= slope.x * c.lens / sensor;
                cam.shift_y -= slope.y * c.lens / sensor;
                frame
            })
            .collect()
    }

    /// The matrix taking a scene's fixed placements into the shot's world at this frame (see
    /// [`SceneWorld`]).
    pub fn world_from_scene(&self, shot: &Shot) -> Result<DMat4> {
        match shot.scene_world {
            SceneWorld::Blender => Ok(DMat4::IDENTITY),
            SceneWorld::NerfObject => self.object_matrix(&shot.nerf_object),
        }
    }

    /// The world matrix of the object `name` at this frame.
    pub fn object_matrix(&self, name: &str) -> Result<DMat4> {
        self.objects.get(name).copied().ok_or_else(|| {
            let names: Vec<&str> = self.objects.keys().map(String::as_str).collect();
            Error::invalid(
                format!("frame {}", self.frame),
                format!("no object named {name:?} (objects: {})", names.join(", ")),
            )
        })
    }
}

impl ShotCamera {
    /// The camera's intrinsics together with the shot's output format.
    pub fn intrinsics(&self, shot: &Shot) -> BlenderIntrinsics {
        BlenderIntrinsics {
            lens: self.lens,
            sensor_width: self.sensor_width,
            sensor_height: self.sensor_height,
            sensor_fit: self.sensor_fit,
            shift_x: self.shift_x,
            shift_y: self.shift_y,
            resolution_x: shot.resolution_x,
            resolution_y: shot.resolution_y,
            resolution_percentage: shot.resolution_percentage,
            pixel_aspect_x: shot.pixel_aspect_x,
            pixel_aspect_y: shot.pixel_aspect_y,
        }
    }
}

fn read_frame(node: &Obj, nerf_object: &str) -> Result<ShotFrame> {
    let frame = node.get::<i64>("frame", "an integer frame number")?;
    let cam = node.object("camera")?;
    let camera = read_camera(&cam)?;
    let objs = node.object("objects")?;
    let mut objects = BTreeMap::new();
    for key in objs.keys() {
        let m = objs.matrix(key)?;
        let det = m.determinant();
        if det.is_nan() || det.abs() <= 1e-300 {
            return Err(objs.error(
                key,
                "matrix is singular (zero scale?); it cannot be inverted",
            ));
        }
        objects.insert(key.clone(), m);
    }
    if !objects.contains_key(nerf_object) {
        return Err(node.error(
            "objects",
            format!("no matrix for the NeRF object {nerf_object:?} (see \"nerf_object\")"),
        ));
    }
    Ok(ShotFrame {
        frame,
        camera,
        objects,
    })
}

fn read_camera(cam: &Obj) -> Result<ShotCamera> {
    let kind = match cam.get::<String>("type", "a string")?.as_str() {
        "PERSP" => ShotCameraKind::Perspective,
        "PANO" => match cam.get::<String>("panorama_type", "a string")?.as_str() {
            "EQUIRECTANGULAR" => ShotCameraKind::Equirect,
            other => {
                return Err(cam.error(
                    "panorama_type",
                    format!("{other} is not supported; expected EQUIRECTANGULAR"),
                ))
            }
        },
        other => {
            return Err(cam.error(
                "type",
                format!("{other} cameras are not supported; expected PERSP or PANO"),
            ))
        }
    };
    let defaults = BlenderIntrinsics::default();
    let persp = kind == ShotCameraKind::Perspective;
    // Lens and sensor only matter for a perspective camera: required there, defaulted else.
    let lens_field = |key: &str, default: f64| {
        if persp {
            cam.positive(key)
        } else {
            cam.positive_or(key, default)
        }
    };
    let camera = ShotCamera {
        world_from_camera: cam.matrix("matrix_world")?,
        kind,
        lens: lens_field("lens", defaults.lens)?,
        sensor_width: lens_field("sensor_width", defaults.sensor_width)?,
        sensor_height: lens_field("sensor_height", defaults.sensor_height)?,
        sensor_fit: if persp || cam.opt("sensor_fit").is_some() {
            cam.get::<SensorFit>(
                "sensor_fit",
                "one of \"AUTO\", \"HORIZONTAL\", \"VERTICAL\"",
            )?
        } else {
            SensorFit::Auto
        },
        shift_x: cam.number_or("shift_x", 0.0)?,
        shift_y: cam.number_or("shift_y", 0.0)?,
        clip_start: cam.positive_or("clip_start", 0.1)?,
        clip_end: cam.positive_or("clip_end", 1000.0)?,
        stereo: match cam.opt("stereo") {
            None => None,
            Some(_) => {
                let s = cam.object("stereo")?;
                Some(ShotStereo {
                    mode: s.get::<StereoMode>("mode", "\"ODS\" or \"VR180\"")?,
                    eye: s.get::<Eye>("eye", "\"left\", \"right\" or \"both\"")?,
                    ipd: s.number_or("ipd", super::DEFAULT_IPD)?,
                })
            }
        },
        dof: None,
    };
    let mut camera = camera;
    if cam.opt("dof").is_some() {
        if !persp {
            return Err(cam.error(
                "dof",
                "depth of field is read for perspective cameras only (type PERSP)",
            ));
        }
        camera.dof = Some(read_dof(&cam.object("dof")?)?);
    }
    if camera.clip_end <= camera.clip_start {
        return Err(cam.error(
            "clip_end",
            format!(
                "{} is not beyond clip_start {}",
                camera.clip_end, camera.clip_start
            ),
        ));
    }
    Ok(camera)
}

/// A camera's `dof` object; every value is checked here, so the message names the field.
fn read_dof(dof: &Obj) -> Result<DepthOfField> {
    let blades = if dof.has("blades") {
        let n = dof.get::<i64>("blades", "a whole number of blades")?;
        match u32::try_from(n) {
            Ok(b) if b <= MAX_BLADES => b,
            _ => {
                return Err(dof.error(
                    "blades",
                    format!("{n}; expected 0 to {MAX_BLADES} (fewer than 3: a round aperture)"),
                ))
            }
        }
    } else {
        0
    };
    let positive = |key: &str, what: &str| -> Result<f64> {
        let v = dof.finite(key, what)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(dof.error(key, format!("expected {what} > 0, got {v}")))
        }
    };
    Ok(DepthOfField {
        focus_distance: positive("focus_distance", "a distance")?,
        fstop: positive("fstop", "an f-number")?,
        blades,
        rotation: dof.number_or("rotation", 0.0)?,
        ratio: if dof.has("ratio") {
            positive("ratio", "a ratio")?
        } else {
            1.0
        },
    })
}

/// How a shot file's messages are worded: `null` is refused (it is what a `NaN` token became),
/// a value of the wrong shape is named by its kind.
const SHOT_STYLE: Style = Style {
    wrong_shape: Describe::Kind,
};

/// The shot file's typed getters, on top of the shared [`Obj`] reader.
trait ShotFields {
    /// An optional finite number, `default` when absent (a `null` is refused).
    fn number_or(&self, key: &str, default: f64) -> Result<f64>;
    /// A required number > 0.
    fn positive(&self, key: &str) -> Result<f64>;
    /// An optional number > 0, `default` when absent (a `null` is refused).
    fn positive_or(&self, key: &str, default: f64) -> Result<f64>;
    /// A whole number ≥ 1 that fits in `u32`.
    fn count(&self, key: &str) -> Result<u32>;
    /// A 4×4 matrix as four rows of four finite numbers, affine (bottom row 0 0 0 1).
    fn matrix(&self, key: &str) -> Result<DMat4>;
}

impl ShotFields for Obj<'_> {
    fn number_or(&self, key: &str, default: f64) -> Result<f64> {
        if self.has(key) {
            self.get::<f64>(key, "a finite number")
        } else {
            Ok(default)
        }
    }

    fn positive(&self, key: &str) -> Result<f64> {
        let v = self.get::<f64>(key, "a number > 0")?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.error(key, format!("expected a number > 0, got {v}")))
        }
    }

    fn positive_or(&self, key: &str, default: f64) -> Result<f64> {
        if self.has(key) {
            self.positive(key)
        } else {
            Ok(default)
        }
    }

    fn count(&self, key: &str) -> Result<u32> {
        let v = self.get::<u64>(key, "a whole number ≥ 1")?;
        match u32::try_from(v) {
            Ok(n) if n >= 1 => Ok(n),
            _ => Err(self.error(key, format!("expected a whole number ≥ 1, got {v}"))),
        }
    }

    fn matrix(&self, key: &str) -> Result<DMat4> {
        let loc = self.field_loc(key);
        let rows = match self.required(key, "a 4×4 matrix (four rows)")? {
            Value::Array(rows) if rows.len() == 4 => rows,
            other => {
                return Err(self.error(
                    key,
                    format!("expected a 4×4 matrix (four rows), got {}", short(other)),
                ))
            }
        };
        let mut m = [[0.0f64; 4]; 4];
        for (r, row) in rows.iter().enumerate() {
            let cells = match row {
                Value::Array(cells) if cells.len() == 4 => cells,
                other => {
                    return Err(self.error_at(
                        format!("{loc}[{r}]"),
                        format!("expected a row of four numbers, got {}", short(other)),
                    ))
                }
            };
            for (c, cell) in cells.iter().enumerate() {
                m[r][c] = match cell.as_f64() {
                    Some(x) if x.is_finite() => x,
                    _ => {
                        return Err(self.error_at(
                            format!("{loc}[{r}][{c}]"),
                            format!(
                                "expected a finite number, got {} (NaN or infinity in the matrix?)",
                                short(cell)
                            ),
                        ))
                    }
                };
            }
        }
        if m[3] != [0.0, 0.0, 0.0, 1.0] {
            return Err(self.error(
                key,
                format!("bottom row is {:?}, expected [0, 0, 0, 1]", m[3]),
            ));
        }
        // Rows in the file; glam is column-major.
        Ok(DMat4::from_cols_array_2d(&m).transpose())
    }
}

#[derive(Serialize)]
struct RawShot<'a> {
    version: u64,
    fps: f64,
    fps_base: f64,
    resolution_x: u32,
    resolution_y: u32,
    resolution_percentage: u32,
    pixel_aspect_x: f64,
    pixel_aspect_y: f64,
    nerf_object: &'a str,
    frames: Vec<RawFrame<'a>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    motion_blur: Option<RawMotionBlur>,
}

#[derive(Serialize)]
struct RawMotionBlur {
    shutter: f64,
    position: ShutterPosition,
}

#[derive(Serialize)]
struct RawFrame<'a> {
    frame: i64,
    camera: RawCamera,
    objects: BTreeMap<&'a str, [[f64; 4]; 4]>,
}

#[derive(Serialize)]
struct RawCamera {
    matrix_world: [[f64; 4]; 4],
    #[serde(rename = "type")]
    kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    panorama_type: Option<&'static str>,
    lens: f64,
    sensor_width: f64,
    sensor_height: f64,
    sensor_fit: SensorFit,
    shift_x: f64,
    shift_y: f64,
    clip_start: f64,
    clip_end: f64,
    stereo: Option<ShotStereo>,
    #[serde(skip_serializing_if = "Option::is_none")]
    dof: Option<RawDof>,
}

#[derive(Serialize)]
struct RawDof {
    focus_distance: f64,
    fstop: f64,
    blades: u32,
    rotation: f64,
    ratio: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};
    use serde_json::json;

    fn rows(m: DMat4) -> Value {
        json!(m.transpose().to_cols_array_2d())
    }

    /// A two-frame shot: a shifted perspective camera, then an ODS panorama.
    fn base() -> Value {
        let cam0 = DMat4::from_rotation_translation(
            DQuat::from_rotation_y(0.3),
            DVec3::new(1.0, 2.0, 5.0),
        );
        let nerf = DMat4::from_scale_rotation_translation(
            DVec3::new(2.0, 2.0, 3.0),
            DQuat::from_rotation_z(0.2),
            DVec3::new(0.0, 0.5, 0.0),
        );
        json!({
            "version": 1, "fps": 24, "fps_base": 1.001,
            "resolution_x": 1920, "resolution_y": 1080, "resolution_percentage": 50,
            "pixel_aspect_x": 1, "pixel_aspect_y": 1,
            "nerf_object": "NeRF",
            "comment": "unknown fields are ignored",
            "frames": [
                {"frame": 1001,
                 "camera": {"matrix_world": rows(cam0), "type": "PERSP", "lens": 35,
                            "sensor_width": 36, "sensor_height": 24, "sensor_fit": "HORIZONTAL",
                            "shift_x": 0.1, "shift_y": -0.05, "clip_start": 0.1, "clip_end": 100,
                            "stereo": null},
                 "objects": {"NeRF": rows(nerf), "Plate": rows(DMat4::IDENTITY)}},
                {"frame": 1002,
                 "camera": {"matrix_world": rows(DMat4::IDENTITY), "type": "PANO",
                            "panorama_type": "EQUIRECTANGULAR", "lens": 50,
                            "sensor_width": 36, "sensor_height": 24, "sensor_fit": "AUTO",
                            "stereo": {"mode": "ODS", "eye": "both", "ipd": 0.07}},
                 "objects": {"NeRF": rows(nerf)}}
            ]
        })
    }

    fn parse(v: &Value) -> Result<Shot> {
        Shot::from_json_str(&v.to_string(), "shot.json")
    }

    fn parse_err(v: &Value) -> String {
        parse(v).unwrap_err().to_string()
    }

    fn assert_mentions(message: &str, parts: &[&str]) {
        for p in parts {
            assert!(message.contains(p), "{message:?} does not mention {p:?}");
        }
    }

    #[test]
    fn reads_the_documented_schema() {
        let shot = parse(&base()).unwrap();
        assert_eq!(shot.frames.len(), 2);
        assert!((shot.frame_rate() - 24.0 / 1.001).abs() < 1e-12);
        assert_eq!(shot.resolution_percentage, 50);
        let f = shot.frame(1001).unwrap();
        assert_eq!(f.camera.kind, ShotCameraKind::Perspective);
        assert_eq!(f.camera.sensor_fit, SensorFit::Horizontal);
        assert_eq!((f.camera.shift_x, f.camera.shift_y), (0.1, -0.05));
        assert_eq!((f.camera.clip_start, f.camera.clip_end), (0.1, 100.0));
        // Matrices are rows in the file: the translation is the last column.
        assert_eq!(
            f.camera.world_from_camera.w_axis.truncate(),
            DVec3::new(1.0, 2.0, 5.0)
        );
        assert_eq!(f.object_matrix("Plate").unwrap(), DMat4::IDENTITY);
        let g = shot.frame(1002).unwrap();
        assert_eq!(g.camera.kind, ShotCameraKind::Equirect);
        assert_eq!(
            g.camera.stereo,
            Some(ShotStereo {
                mode: StereoMode::Ods,
                eye: Eye::Both,
                ipd: 0.07
            })
        );
        // Defaults for fields a panorama may leave out.
        assert_eq!((g.camera.clip_start, g.camera.clip_end), (0.1, 1000.0));
        assert_eq!((g.camera.shift_x, g.camera.shift_y), (0.0, 0.0));
    }

    #[test]
    fn builds_cameras_with_the_right_projection() {
        let shot = parse(&base()).unwrap();
        let cam = shot.frame(1001).unwrap().camera(&shot).unwrap();
        assert!(matches!(cam.projection(), Projection::Perspective(_)));
        assert_eq!(cam.resolution(), (960, 540));
        // 35 mm on 36 mm, horizontal fit, shift 0.1: the centre pixel's ray leaves at
        // (0.1·36/35, −0.05·36/35, −1) in camera space.
        let r = cam.ray(480.0, 270.0).unwrap();
        let local = DVec3::new(0.1 * 36.0 / 35.0, -0.05 * 36.0 / 35.0, -1.0).normalize();
        let expected = DQuat::from_rotation_y(0.3) * local;
        assert!((r.dir - expected).length() < 1e-12);
        assert!((r.origin - DVec3::new(1.0, 2.0, 5.0)).length() < 1e-12);

        let pano = shot.frame(1002).unwrap().camera(&shot).unwrap();
        assert!(matches!(pano.projection(), Projection::Ods(_)));
        assert_eq!(pano.resolution(), (960, 1080));
        let right_eye = pano.ray(480.0, 540.0 + 270.0).unwrap();
        assert!((right_eye.origin - DVec3::new(0.035, 0.0, 0.0)).length() < 1e-12);

        let mut v = base();
        v["frames"][1]["camera"]["stereo"] = json!({"mode": "VR180", "eye": "both"});
        let shot = parse(&v).unwrap();
        let vr = shot.frame(1002).unwrap().camera(&shot).unwrap();
        assert!(matches!(vr.projection(), Projection::Vr180(_)));
        assert_eq!(vr.resolution(), (1920, 540));
        let r = vr.ray(10.0, 10.0).unwrap();
        assert!((r.origin - DVec3::new(-0.032, 0.0, 0.0)).length() < 1e-12);

        v["frames"][1]["camera"]["stereo"] = Value::Null;
        let shot = parse(&v).unwrap();
        let eq = shot.frame(1002).unwrap().camera(&shot).unwrap();
        assert!(matches!(eq.projection(), Projection::Equirect(_)));
    }

    /// The base shot with depth of field on frame 1001's camera.
    fn with_dof(dof: Value) -> Value {
        let mut v = base();
        v["frames"][0]["camera"]["dof"] = dof;
        v
    }

    fn project(cam: &Camera, world: DVec3) -> glam::DVec2 {
        let Projection::Perspective(p) = cam.projection() else {
            panic!("a perspective camera");
        };
        let local = cam.world_from_camera().inverse().transform_point3(world);
        p.project(local).unwrap()
    }

    /// Each aperture sample's camera is Cycles' thin lens for every pixel: its ray through a
    /// pixel starts at the lens point and meets the pinhole ray of that pixel on the focus
    /// plane; a point off the plane moves by `fx·l·(1/d − 1/z)` pixels (its circle of
    /// confusion).
    #[test]
    fn aperture_cameras_are_the_thin_lens() {
        let shot = parse(&with_dof(json!({
            "focus_distance": 4.0, "fstop": 0.7, "blades": 5, "rotation": 0.3, "ratio": 1.5
        })))
        .unwrap();
        let frame = shot.frame(1001).unwrap();
        let pinhole = frame.camera(&shot).unwrap();
        let lenses = frame.through_aperture(8);
        assert_eq!(lenses.len(), 8);
        let world_from_camera = pinhole.world_from_camera();
        let fx = match pinhole.projection() {
            Projection::Perspective(p) => p.intrinsics()[0],
            _ => unreachable!(),
        };
        let mut moved = 0.0f64;
        for at in &lenses {
            let cam = at.camera(&shot).unwrap();
            // The lens point, in the pinhole camera's frame: in its x–y plane, inside the
            // aperture (35 mm at f/0.7: radius 0.025; x squeezed by the ratio).
            let l = world_from_camera
                .inverse()
                .transform_point3(cam.world_from_camera().w_axis.truncate());
            assert!(l.z.abs() < 1e-12, "{l}");
            assert!((l.x * 1.5).hypot(l.y) <= 0.025 + 1e-12, "{l}");
            moved = moved.max(l.length());
            for (x, y) in [(0.5, 0.5), (480.0, 270.0), (900.25, 77.5), (13.0, 530.0)] {
                let a = pinhole.ray(x, y).unwrap();
                let b = cam.ray(x, y).unwrap();
                assert!(b
                    .origin
                    .abs_diff_eq(cam.world_from_camera().w_axis.truncate(), 1e-12));
                // Both rays reach camera depth 4 at the same point.
                let depth = |r: &crate::camera::Ray, t: f64| r.z_per_t * t;
                let focus_a = a.origin + a.dir * (4.0 / depth(&a, 1.0));
                let focus_b = b.origin + b.dir * (4.0 / depth(&b, 1.0));
                assert!(focus_a.abs_diff_eq(focus_b, 1e-9), "{focus_a} {focus_b}");
            }
            // A point at depth 10 on the pixel (480, 270)'s pinhole ray.
            let a = pinhole.ray(480.0, 270.0).unwrap();
            let p = a.origin + a.dir * (10.0 / a.z_per_t);
            let shift = project(&cam, p) - glam::DVec2::new(480.0, 270.0);
            let expected = glam::DVec2::new(l.x, -l.y) * fx * (1.0 / 4.0 - 1.0 / 10.0);
            assert!((shift - expected).length() < 1e-6, "{shift} vs {expected}");
        }
        assert!(moved > 0.015, "{moved}");
    }

    /// Without depth of field, or with one aperture sample, a frame is its own pinhole; the
    /// camera's scale does not scale the aperture.
    #[test]
    fn no_depth_of_field_is_the_frame_itself() {
        let shot = parse(&base()).unwrap();
        let frame = shot.frame(1001).unwrap();
        assert_eq!(frame.through_aperture(64), vec![frame.clone()]);
        let dof = json!({"focus_distance": 2.0, "fstop": 2.0});
        let shot = parse(&with_dof(dof.clone())).unwrap();
        let frame = shot.frame(1001).unwrap();
        assert_eq!(frame.through_aperture(1), vec![frame.clone()]);
        assert_eq!(frame.through_aperture(0), vec![frame.clone()]);
        let mut v = with_dof(dof);
        let scaled = DMat4::from_scale_rotation_translation(
            DVec3::splat(3.0),
            DQuat::from_rotation_y(0.3),
            DVec3::new(1.0, 2.0, 5.0),
        );
        v["frames"][0]["camera"]["matrix_world"] = rows(scaled);
        let shot = parse(&v).unwrap();
        for at in shot.frame(1001).unwrap().through_aperture(16) {
            let offset = at.camera.world_from_camera.w_axis.truncate() - DVec3::new(1.0, 2.0, 5.0);
            assert!(offset.length() <= 35e-3 / 4.0 + 1e-12, "{offset}");
        }
    }

    #[test]
    fn depth_of_field_round_trips_and_bad_values_name_the_field() {
        let shot = parse(&with_dof(json!({
            "focus_distance": 4.5, "fstop": 2.8, "blades": 6, "rotation": 0.25, "ratio": 1.2
        })))
        .unwrap();
        let dof = shot.frame(1001).unwrap().camera.dof.unwrap();
        assert_eq!(
            dof,
            DepthOfField {
                focus_distance: 4.5,
                fstop: 2.8,
                blades: 6,
                rotation: 0.25,
                ratio: 1.2
            }
        );
        assert_eq!(shot.frame(1002).unwrap().camera.dof, None);
        let text = shot.to_json_string(Path::new("shot.json")).unwrap();
        let back = Shot::from_json_str(&text, "shot.json").unwrap();
        assert_eq!(back.frames, shot.frames);
        // Defaults: a round aperture, unturned, not anamorphic; null is no depth of field.
        let d = parse(&with_dof(json!({"focus_distance": 3, "fstop": 4})))
            .unwrap()
            .frames[0]
            .camera
            .dof
            .unwrap();
        assert_eq!((d.blades, d.rotation, d.ratio), (0, 0.0, 1.0));
        let none = parse(&with_dof(Value::Null)).unwrap();
        assert_eq!(none.frames[0].camera.dof, None);

        let ok = json!({"focus_distance": 3, "fstop": 4});
        let cases: Vec<(&str, Value, &[&str])> = vec![
            ("fstop", json!(0), &["frames[0].camera.dof.fstop", "> 0"]),
            ("fstop", json!(-1.4), &["frames[0].camera.dof.fstop"]),
            ("fstop", Value::Null, &["frames[0].camera.dof.fstop", "NaN"]),
            (
                "focus_distance",
                Value::Null,
                &["frames[0].camera.dof.focus_distance"],
            ),
            (
                "focus_distance",
                json!(-2),
                &["frames[0].camera.dof.focus_distance"],
            ),
            ("blades", json!(-3), &["frames[0].camera.dof.blades", "-3"]),
            ("blades", json!(2.5), &["frames[0].camera.dof.blades"]),
            ("blades", json!(101), &["frames[0].camera.dof.blades"]),
            ("ratio", json!(0), &["frames[0].camera.dof.ratio"]),
            (
                "rotation",
                json!("a lot"),
                &["frames[0].camera.dof.rotation"],
            ),
        ];
        for (field, value, parts) in cases {
            let mut dof = ok.clone();
            dof[field] = value;
            let e = parse_err(&with_dof(dof));
            assert_mentions(&e, &["shot.json"]);
            assert_mentions(&e, parts);
        }
        let mut dof = ok.clone();
        dof.as_object_mut().unwrap().remove("fstop");
        assert_mentions(
            &parse_err(&with_dof(dof)),
            &["frames[0].camera.dof.fstop", "missing"],
        );
        // A shot built in memory is checked when its cameras are built.
        let mut shot = parse(&with_dof(json!({"focus_distance": 3, "fstop": 4}))).unwrap();
        if let Some(d) = &mut shot.frames[0].camera.dof {
            d.fstop = 0.0;
        }
        let e = shot.frames[0].camera(&shot).unwrap_err().to_string();
        assert_mentions(&e, &["shot.json", "frames[0].camera", "dof.fstop"]);
        // Only a perspective camera has a thin lens.
        let mut v = base();
        v["frames"][1]["camera"]["dof"] = ok;
        assert_mentions(&parse_err(&v), &["frames[1].camera.dof", "PERSP"]);
        // A NaN token (what Python writes) is refused by name.
        let text = with_dof(json!({"focus_distance": 12345.5, "fstop": 2}))
            .to_string()
            .replace("12345.5", "NaN");
        let e = Shot::from_json_str(&text, "shot.json")
            .unwrap_err()
            .to_string();
        assert_mentions(&e, &["shot.json", "frames[0].camera.dof.focus_distance"]);
    }

    #[test]
    fn write_then_read_round_trips() {
        let shot = parse(&base()).unwrap();
        let dir = std::env::temp_dir().join(format!("nerfx-shot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("round_trip.json");
        shot.write(&path).unwrap();
        let back = Shot::read(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back.source, path);
        assert_eq!(back.frames.len(), shot.frames.len());
        let near = |a: f64, b: f64| (a - b).abs() <= 1e-15 * a.abs().max(1.0);
        assert!(near(back.fps_base, shot.fps_base));
        assert_eq!(
            (
                back.resolution_x,
                back.resolution_y,
                back.resolution_percentage
            ),
            (1920, 1080, 50)
        );
        assert_eq!(back.nerf_object, "NeRF");
        for (a, b) in shot.frames.iter().zip(&back.frames) {
            assert_eq!(a.frame, b.frame);
            assert_eq!(a.camera.kind, b.camera.kind);
            assert_eq!(a.camera.stereo, b.camera.stereo);
            assert_eq!(a.camera.sensor_fit, b.camera.sensor_fit);
            for (x, y) in [
                (a.camera.lens, b.camera.lens),
                (a.camera.shift_x, b.camera.shift_x),
                (a.camera.shift_y, b.camera.shift_y),
                (a.camera.clip_end, b.camera.clip_end),
            ] {
                assert!(near(x, y));
            }
            assert!(a
                .camera
                .world_from_camera
                .abs_diff_eq(b.camera.world_from_camera, 1e-15));
            assert_eq!(
                a.objects.keys().collect::<Vec<_>>(),
                b.objects.keys().collect::<Vec<_>>()
            );
            for (name, m) in &a.objects {
                assert!(m.abs_diff_eq(b.objects[name], 1e-15));
            }
        }
    }

    #[test]
    fn writing_refuses_non_finite_values() {
        let mut shot = parse(&base()).unwrap();
        shot.frames[1].objects.get_mut("NeRF").unwrap().x_axis.y = f64::NAN;
        let path = std::env::temp_dir().join("nerfx-never-written.json");
        let e = shot.write(&path).unwrap_err().to_string();
        assert_mentions(&e, &["frames[1].objects.NeRF", "NaN"]);
        assert!(!path.exists());
    }

    #[test]
    fn missing_field_names_file_frame_and_field() {
        let mut v = base();
        v["frames"][0]["camera"]
            .as_object_mut()
            .unwrap()
            .remove("lens");
        assert_mentions(
            &parse_err(&v),
            &["shot.json", "frames[0].camera.lens", "missing"],
        );
        let mut v = base();
        v["frames"][1].as_object_mut().unwrap().remove("objects");
        assert_mentions(
            &parse_err(&v),
            &["shot.json", "frames[1].objects", "missing"],
        );
        let mut v = base();
        v.as_object_mut().unwrap().remove("fps");
        assert_mentions(&parse_err(&v), &["shot.json: fps: missing"]);
    }

    #[test]
    fn bad_values_name_file_frame_and_field() {
        let cases: Vec<(&str, Value, &[&str])> = vec![
            (
                "/frames/1/camera/lens",
                json!(0),
                &["frames[1].camera.lens: expected a number > 0"],
            ),
            (
                "/frames/0/camera/lens",
                json!("fifty"),
                &["frames[0].camera.lens", "\"fifty\""],
            ),
            (
                "/frames/0/camera/sensor_fit",
                json!("auto"),
                &["frames[0].camera.sensor_fit"],
            ),
            (
                "/frames/0/camera/type",
                json!("ORTHO"),
                &["frames[0].camera.type", "ORTHO"],
            ),
            (
                "/frames/1/camera/panorama_type",
                json!("MIRRORBALL"),
                &["frames[1].camera.panorama_type"],
            ),
            (
                "/frames/1/camera/stereo/eye",
                json!("middle"),
                &["frames[1].camera.stereo.eye"],
            ),
            (
                "/frames/1/camera/stereo/ipd",
                json!(-1),
                &["frames[1].camera", "ipd"],
            ),
            (
                "/frames/0/camera/clip_end",
                json!(0.05),
                &["frames[0].camera.clip_end"],
            ),
            (
                "/frames/1/frame",
                json!(1001),
                &["frames[1].frame", "frames[0]"],
            ),
            ("/frames/0/frame", json!(1001.5), &["frames[0].frame"]),
            ("/resolution_x", json!(0), &["shot.json: resolution_x"]),
            (
                "/resolution_percentage",
                json!(10000),
                &["shot.json: resolution_x: 1920 at 10000%"],
            ),
            ("/version", json!(2), &["version 2"]),
            (
                "/nerf_object",
                json!("Missing"),
                &["frames[0].objects", "\"Missing\""],
            ),
            (
                "/frames/0/camera/matrix_world/3",
                json!([0, 0, 1, 1]),
                &["frames[0].camera.matrix_world", "bottom row"],
            ),
            (
                "/frames/0/camera/matrix_world/1",
                json!([0, 0, 0]),
                &["frames[0].camera.matrix_world[1]"],
            ),
            (
                "/frames/0/objects/NeRF",
                json!([[0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
                &["frames[0].objects.NeRF", "singular"],
            ),
            (
                "/frames/1/camera/matrix_world",
                json!([[0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
                &["frames[1].camera", "degenerate"],
            ),
            (
                "/frames",
                json!([]),
                &["frames: expected at least one frame"],
            ),
        ];
        for (pointer, value, parts) in cases {
            let mut v = base();
            *v.pointer_mut(pointer).unwrap() = value;
            let e = parse_err(&v);
            assert_mentions(&e, &["shot.json"]);
            assert_mentions(&e, parts);
        }
        // A stereo perspective camera is refused rather than silently rendered as a panorama.
        let mut v = base();
        v["frames"][0]["camera"]["stereo"] = json!({"mode": "ODS", "eye": "left"});
        assert_mentions(&parse_err(&v), &["frames[0].camera.stereo", "PANO"]);
    }

    #[test]
    fn nan_and_infinity_tokens_are_refused_naming_the_element() {
        let mut v = base();
        v["frames"][1]["camera"]["matrix_world"][0][1] = json!(12345.5);
        let text = v.to_string().replace("12345.5", "NaN");
        let e = Shot::from_json_str(&text, "shot.json")
            .unwrap_err()
            .to_string();
        assert_mentions(
            &e,
            &["shot.json", "frames[1].camera.matrix_world[0][1]", "finite"],
        );
        let text = v.to_string().replace("12345.5", "-Infinity");
        let e = Shot::from_json_str(&text, "shot.json")
            .unwrap_err()
            .to_string();
        assert_mentions(&e, &["frames[1].camera.matrix_world[0][1]"]);
        // The same token inside a string is left alone.
        v["nerf_object"] = json!("NaN");
        v["frames"][1]["camera"]["matrix_world"][0][1] = json!(0);
        v["frames"][0]["objects"]["NaN"] = v["frames"][0]["objects"]["NeRF"].clone();
        v["frames"][1]["objects"]["NaN"] = v["frames"][1]["objects"]["NeRF"].clone();
        assert_eq!(parse(&v).unwrap().nerf_object, "NaN");
        // A lone NaN scalar reads as null and is refused by name.
        let mut v = base();
        v["fps"] = json!(12345.5);
        let text = v.to_string().replace("12345.5", "NaN");
        let e = Shot::from_json_str(&text, "shot.json")
            .unwrap_err()
            .to_string();
        assert_mentions(&e, &["shot.json: fps", "NaN"]);
    }

    #[test]
    fn wrong_json_names_the_file_and_position() {
        let e = Shot::from_json_str("{\"version\": 1,\n  oops}", "shot.json").unwrap_err();
        assert_mentions(&e.to_string(), &["shot.json", "line 2", "not valid JSON"]);
        let e = Shot::from_json_str("[1, 2]", "shot.json")
            .unwrap_err()
            .to_string();
        assert_mentions(&e, &["shot.json", "expected a JSON object"]);
        let e = Shot::read("/nonexistent/dir/shot.json")
            .unwrap_err()
            .to_string();
        assert_mentions(&e, &["/nonexistent/dir/shot.json"]);
    }

    #[test]
    fn missing_frame_names_the_range_held() {
        let shot = parse(&base()).unwrap();
        let e = shot.frame(1200).unwrap_err().to_string();
        assert_mentions(&e, &["shot.json", "frame 1200", "2 frames, 1001 to 1002"]);
        let e = shot
            .frame(1001)
            .unwrap()
            .object_matrix("Cube")
            .unwrap_err()
            .to_string();
        assert_mentions(&e, &["frame 1001", "\"Cube\"", "NeRF, Plate"]);
    }
}
