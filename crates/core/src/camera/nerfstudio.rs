//! nerfstudio camera paths (`camera_path.json`, what the nerfstudio viewer and its Blender
//! add-on write and `ns-render camera-path` reads): reader, writer, and per-frame [`Camera`]s.
//!
//! ```json
//! {"camera_type": "perspective", "render_width": 1920, "render_height": 1080,
//!  "camera_path": [{"camera_to_world": [16 numbers, row-major], "fov": 50, "aspect": 1}],
//!  "seconds": 4, "fps": 24, "smoothness_value": 0.5, "is_cycle": false,
//!  "keyframes": [{"matrix": "[16 numbers, column-major]", "fov": 50, "aspect": 1,
//!                 "properties": "[[\"FOV\",50],[\"NAME\",\"Camera 0\"],[\"TIME\",0]]"}],
//!  "crop": {"crop_center": [0, 0, 0], "crop_scale": [2, 2, 2], "crop_rot": [0, 0, 0],
//!           "crop_bg_color": {"r": 0, "g": 0, "b": 0}}}
//! ```
//!
//! Facts (docs/src/architecture.md): `camera_to_world` is **row-major** (nested rows load too; a 3×4 form gets
//! the row `0 0 0 1`); `fov` is the **vertical** field of view in degrees,
//! `f = (H/2)/tan(fov/2)`, `fx = fy = f`, principal point at the image centre, and `aspect` is
//! ignored. `keyframes[].matrix` is a string holding a **column-major** matrix; keyframes are
//! only the viewer's editing state and are read for completeness, never used to render.
//! `camera_type` is `perspective`, `equirectangular`, `omnidirectional` (ODS) or `vr180`;
//! `fisheye` is refused ([`Error::Unsupported`]): nerfx has no fisheye model that matches
//! nerfstudio's. For the stereo types `render_width × render_height` is *one eye's* image, as
//! `ns-render` renders each eye separately. The frame rate is `len(camera_path)/seconds`
//! (the file's `fps` is not what `ns-render` uses). The crop box (`crop_rot` = roll, pitch, yaw
//! in radians; `crop_scale` full side lengths) clips rays in the field's frame.
//!
//! Frames are numbered by their index `0..n` in `camera_path`, as `ns-render` numbers its
//! images (`00000.png` …); [`CameraPath::to_shot`] renumbers them from any first frame.
//!
//! Worked number: `fov = 50°` at 1920×1080 gives `f = 540/tan(25°) = 1158.03` px.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DMat4;
use serde::Serialize;
use serde_json::Value;

use super::{
    Camera, Equirect, Eye, Ods, Perspective, Projection, SceneWorld, SensorFit, Shot, ShotCamera,
    ShotCameraKind, ShotFrame, ShotStereo, StereoMode, Vr180, DEFAULT_IPD,
};
use crate::error::{Error, Result};
use crate::field::CropBox;
use crate::json::{self, numbers, short, Describe, Obj, Style};

/// The sensor height used when a vertical FOV becomes a Blender lens (any value works: only
/// `lens / sensor` matters).
const SHOT_SENSOR_HEIGHT: f64 = 24.0;

/// The camera models a nerfstudio camera path may name (fisheye is refused when read).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathCameraType {
    /// `"perspective"`: pinhole from the vertical FOV.
    Perspective,
    /// `"equirectangular"`: full-sphere panorama (`fx = W/2`, `fy = H`).
    Equirectangular,
    /// `"omnidirectional"`: omni-directional stereo, left eye stacked over right.
    Omnidirectional,
    /// `"vr180"`: VR180 stereo, left eye | right eye.
    Vr180,
}

impl PathCameraType {
    /// The name in the file.
    pub fn name(self) -> &'static str {
        match self {
            PathCameraType::Perspective => "perspective",
            PathCameraType::Equirectangular => "equirectangular",
            PathCameraType::Omnidirectional => "omnidirectional",
            PathCameraType::Vr180 => "vr180",
        }
    }
}

/// One entry of `camera_path`: a camera in the field's (nerfstudio's) frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathFrame {
    /// `camera_to_world` (OpenGL camera: −Z forward, +Y up).
    pub camera_to_world: DMat4,
    /// Vertical field of view in degrees (perspective cameras only; kept for the others).
    pub fov: f64,
}

/// One viewer keyframe (editing state; not used to render).
#[derive(Clone, Debug, PartialEq)]
pub struct PathKeyframe {
    /// The keyframe's camera-to-world matrix (read from its column-major string).
    pub matrix: DMat4,
    /// Vertical field of view in degrees.
    pub fov: f64,
    /// The viewer's `properties` string, kept verbatim (empty when absent).
    pub properties: String,
}

/// nerfstudio's crop: a box that clips rays, and the colour `ns-render` puts outside it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathCrop {
    /// The box, in the field's frame.
    pub bounds: CropBox,
    /// Background colour, 0–255 per channel.
    pub bg_color: [f64; 3],
}

/// A nerfstudio camera path.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPath {
    /// The camera model of every frame.
    pub camera_type: PathCameraType,
    /// Image width (per eye for the stereo types).
    pub render_width: u32,
    /// Image height (per eye for the stereo types).
    pub render_height: u32,
    /// The cameras, frame `i` at index `i`.
    pub frames: Vec<PathFrame>,
    /// Duration in seconds; the frame rate is `frames.len() / seconds`.
    pub seconds: f64,
    /// The viewer's keyframes (may be empty).
    pub keyframes: Vec<PathKeyframe>,
    /// The viewer's spline smoothness (0 when absent).
    pub smoothness_value: f64,
    /// Whether the viewer's spline loops (false when absent).
    pub is_cycle: bool,
    /// The crop box, if any.
    pub crop: Option<PathCrop>,
    /// The file read, for messages (empty when built in memory); not written.
    pub source: PathBuf,
}

impl CameraPath {
    /// Reads and validates a camera path.
    pub fn read(path: impl AsRef<Path>) -> Result<CameraPath> {
        let path = path.as_ref();
        let text = crate::input::read_text(path)?;
        CameraPath::from_json_str(&text, path)
    }

    /// Parses and validates camera-path JSON; `path_for_errors` names the source in messages.
    pub(crate) fn from_json_str(
        text: &str,
        path_for_errors: impl AsRef<Path>,
    ) -> Result<CameraPath> {
        let path = path_for_errors.as_ref();
        let root = json::parse(text, path)?;
        let top = Obj::root(&root, path, PATH_STYLE)?;
        let camera_type = match top.opt("camera_type") {
            None => PathCameraType::Perspective,
            Some(_) => match top.string("camera_type")?.to_lowercase().as_str() {
                "perspective" => PathCameraType::Perspective,
                "equirectangular" => PathCameraType::Equirectangular,
                "omnidirectional" => PathCameraType::Omnidirectional,
                "vr180" => PathCameraType::Vr180,
                "fisheye" => {
                    return Err(Error::Unsupported(format!(
                        "{}: camera_type \"fisheye\" (nerfx renders perspective, \
                         equirectangular, omnidirectional and vr180 camera paths)",
                        path.display()
                    )))
                }
                other => {
                    return Err(top.error(
                        "camera_type",
                        format!(
                            "{other:?} is not a nerfstudio camera type; expected perspective, \
                             equirectangular, omnidirectional or vr180"
                        ),
                    ))
                }
            },
        };
        let perspective = camera_type == PathCameraType::Perspective;
        let entries = top.array("camera_path")?;
        if entries.is_empty() {
            return Err(top.error("camera_path", "expected at least one camera"));
        }
        let mut frames = Vec::with_capacity(entries.len());
        for (i, v) in entries.iter().enumerate() {
            let cam = Obj::new(v, path, format!("camera_path[{i}]"), PATH_STYLE)?;
            let fov = if perspective || cam.opt("fov").is_some() {
                cam.fov("fov", perspective)?
            } else {
                90.0
            };
            frames.push(PathFrame {
                camera_to_world: cam.row_major_matrix("camera_to_world")?,
                fov,
            });
        }
        let mut keyframes = Vec::new();
        if top.opt("keyframes").is_some() {
            for (i, v) in top.array("keyframes")?.iter().enumerate() {
                let k = Obj::new(v, path, format!("keyframes[{i}]"), PATH_STYLE)?;
                keyframes.push(PathKeyframe {
                    matrix: k.column_major_string("matrix")?,
                    fov: if k.opt("fov").is_some() {
                        k.fov("fov", false)?
                    } else {
                        90.0
                    },
                    properties: match k.opt("properties") {
                        Some(_) => k.string("properties")?,
                        None => String::new(),
                    },
                });
            }
        }
        let crop = match top.opt("crop") {
            None => None,
            Some(_) => Some(read_crop(&top.object("crop")?)?),
        };
        let camera_path = CameraPath {
            camera_type,
            render_width: top.side("render_width")?,
            render_height: top.side("render_height")?,
            seconds: top.positive("seconds")?,
            smoothness_value: match top.opt("smoothness_value") {
                Some(_) => top.number("smoothness_value")?,
                None => 0.0,
            },
            is_cycle: match top.opt("is_cycle") {
                Some(v) => v.as_bool().ok_or_else(|| {
                    top.error("is_cycle", format!("expected true or false, got {v}"))
                })?,
                None => false,
            },
            frames,
            keyframes,
            crop,
            source: path.to_path_buf(),
        };
        // Build every camera once, so a bad matrix is reported now, with its location.
        for i in 0..camera_path.frames.len() {
            camera_path.camera(i, Eye::Both)?;
        }
        Ok(camera_path)
    }

    /// Frames per second: `len(camera_path) / seconds`, as `ns-render` computes it.
    pub fn frame_rate(&self) -> f64 {
        self.frames.len() as f64 / self.seconds
    }

    /// The camera of frame `index` (0-based) in the field's frame; `eye` picks the eye(s) of
    /// the stereo types and is ignored by the mono ones.
    pub fn camera(&self, index: usize, eye: Eye) -> Result<Camera> {
        let at = format!("camera_path[{index}]");
        let frame = self.frames.get(index).ok_or_else(|| {
            Error::format(
                &self.source,
                "camera_path",
                format!(
                    "frame {index} is not in the path (it holds frames 0 to {})",
                    self.frames.len().saturating_sub(1)
                ),
            )
        })?;
        let in_context = |e: Error| match e {
            Error::Invalid { what, message } => {
                Error::format(&self.source, &at, format!("{what}: {message}"))
            }
            other => other,
        };
        let (w, h) = (self.render_width, self.render_height);
        let projection = match self.camera_type {
            PathCameraType::Perspective => Projection::Perspective(
                Perspective::from_vertical_fov(w, h, frame.fov).map_err(in_context)?,
            ),
            PathCameraType::Equirectangular => {
                Projection::Equirect(Equirect::new(w, h).map_err(in_context)?)
            }
            PathCameraType::Omnidirectional => {
                Projection::Ods(Ods::new(w, h, eye, DEFAULT_IPD).map_err(in_context)?)
            }
            PathCameraType::Vr180 => {
                Projection::Vr180(Vr180::new(w, h, eye, DEFAULT_IPD).map_err(in_context)?)
            }
        };
        Camera::from_affine(frame.camera_to_world, projection).map_err(in_context)
    }

    /// The path as a nerfx shot: frame `i` becomes `first_frame + i`. A vertical FOV becomes
    /// a Blender lens with a VERTICAL sensor fit, `lens = (sensor_height/2)/tan(fov/2)`, which
    /// frames exactly as `f = (H/2)/tan(fov/2)`. Stereo types render both eyes; the frame rate
    /// is [`Self::frame_rate`].
    ///
    /// Exact for any affine `camera_to_world` `M`, also one with non-uniform scale (a path
    /// written from a scaled NeRF object, `N⁻¹·C_o`), which [`Self::camera`] would make rigid:
    /// the shot's camera is the rigid part `C` of `M` and the object `nerf_object` gets
    /// `C·M⁻¹`, so the field sees `(C·M⁻¹)⁻¹·C = M`, as `ns-render` does.
    pub fn to_shot(&self, first_frame: i64, nerf_object: &str) -> Result<Shot> {
        let stereo = |mode| {
            Some(ShotStereo {
                mode,
                eye: Eye::Both,
                ipd: DEFAULT_IPD,
            })
        };
        let (kind, stereo) = match self.camera_type {
            PathCameraType::Perspective => (ShotCameraKind::Perspective, None),
            PathCameraType::Equirectangular => (ShotCameraKind::Equirect, None),
            PathCameraType::Omnidirectional => (ShotCameraKind::Equirect, stereo(StereoMode::Ods)),
            PathCameraType::Vr180 => (ShotCameraKind::Equirect, stereo(StereoMode::Vr180)),
        };
        let mut frames = Vec::with_capacity(self.frames.len());
        for (i, f) in self.frames.iter().enumerate() {
            // The field sees the path's camera as written (scale included): the NeRF object
            // is placed so that `object⁻¹ · rigid` is that camera. Affine by construction, so
            // the bottom row is set exactly rather than left to the inverse's rounding.
            let rigid = self.camera(i, Eye::Both)?.world_from_camera();
            let mut object = rigid * f.camera_to_world.inverse();
            object.x_axis.w = 0.0;
            object.y_axis.w = 0.0;
            object.z_axis.w = 0.0;
            object.w_axis.w = 1.0;
            frames.push(ShotFrame {
                frame: first_frame + i as i64,
                camera: ShotCamera {
                    world_from_camera: rigid,
                    kind,
                    lens: (SHOT_SENSOR_HEIGHT / 2.0) / (f.fov.to_radians() / 2.0).tan(),
                    sensor_width: 36.0,
                    sensor_height: SHOT_SENSOR_HEIGHT,
                    sensor_fit: SensorFit::Vertical,
                    shift_x: 0.0,
                    shift_y: 0.0,
                    // nerfacto's near and far planes.
                    clip_start: 0.05,
                    clip_end: 1000.0,
                    stereo,
                    dof: None,
                },
                objects: BTreeMap::from([(nerf_object.to_string(), object)]),
            });
        }
        Ok(Shot {
            fps: self.frame_rate(),
            fps_base: 1.0,
            resolution_x: self.render_width,
            resolution_y: self.render_height,
            resolution_percentage: 100,
            pixel_aspect_x: 1.0,
            pixel_aspect_y: 1.0,
            nerf_object: nerf_object.to_string(),
            frames,
            motion_blur: None,
            scene_world: SceneWorld::NerfObject,
            source: self.source.clone(),
        })
    }

    /// Writes the path as the nerfstudio Blender add-on does: `camera_to_world` row-major
    /// flat, keyframes with column-major matrix strings, `fps = len/seconds`, plus `crop` when
    /// set. Refuses non-finite numbers, which JSON cannot hold.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = self.to_json_string(path)?;
        crate::output::write_file(path, text.as_bytes())
    }

    fn to_json_string(&self, path: &Path) -> Result<String> {
        let finite = |loc: String, v: &[f64]| -> Result<()> {
            if v.iter().all(|x| x.is_finite()) {
                Ok(())
            } else {
                Err(Error::invalid(
                    format!("{}: {loc}", path.display()),
                    "NaN or infinity cannot be written to JSON",
                ))
            }
        };
        let mut camera_path = Vec::with_capacity(self.frames.len());
        for (i, f) in self.frames.iter().enumerate() {
            let m = f.camera_to_world.transpose().to_cols_array();
            finite(format!("camera_path[{i}]"), &m)?;
            finite(format!("camera_path[{i}].fov"), &[f.fov])?;
            camera_path.push(RawFrame {
                camera_to_world: m,
                fov: f.fov,
                aspect: 1.0,
            });
        }
        let mut keyframes = Vec::with_capacity(self.keyframes.len());
        for (i, k) in self.keyframes.iter().enumerate() {
            let m = k.matrix.to_cols_array();
            finite(format!("keyframes[{i}]"), &m)?;
            finite(format!("keyframes[{i}].fov"), &[k.fov])?;
            keyframes.push(RawKeyframe {
                matrix: serde_json::to_string(&m.to_vec()).unwrap_or_default(),
                fov: k.fov,
                aspect: 1.0,
                properties: k.properties.clone(),
            });
        }
        let crop = match &self.crop {
            None => None,
            Some(c) => {
                let b = &c.bounds;
                finite(
                    "crop".into(),
                    &[b.center, b.scale, b.rotation, c.bg_color].concat(),
                )?;
                Some(RawCrop {
                    crop_center: b.center,
                    crop_scale: b.scale,
                    crop_rot: b.rotation,
                    crop_bg_color: RawColor {
                        r: c.bg_color[0],
                        g: c.bg_color[1],
                        b: c.bg_color[2],
                    },
                })
            }
        };
        finite(
            "seconds".into(),
            &[self.seconds, self.frame_rate(), self.smoothness_value],
        )?;
        let raw = RawPath {
            keyframes,
            camera_type: self.camera_type.name(),
            render_height: self.render_height,
            render_width: self.render_width,
            camera_path,
            fps: self.frame_rate(),
            seconds: self.seconds,
            smoothness_value: self.smoothness_value,
            is_cycle: self.is_cycle,
            crop,
        };
        serde_json::to_string_pretty(&raw)
            .map_err(|e| Error::invalid(path.display().to_string(), e.to_string()))
    }
}

fn read_crop(c: &Obj) -> Result<PathCrop> {
    let bg_color = match c.opt("crop_bg_color") {
        None => [0.0; 3],
        Some(Value::Object(_)) => {
            let o = c.object("crop_bg_color")?;
            [o.number("r")?, o.number("g")?, o.number("b")?]
        }
        Some(_) => c.triple("crop_bg_color")?,
    };
    let bounds = CropBox {
        center: c.triple("crop_center")?,
        scale: c.triple("crop_scale")?,
        rotation: match c.opt("crop_rot") {
            Some(_) => c.triple("crop_rot")?,
            None => [0.0; 3],
        },
    };
    // A side of 0 crops everything away: the render would be the background alone.
    if let Some(i) = bounds.scale.iter().position(|&s| s.is_nan() || s <= 0.0) {
        return Err(c.error(
            "crop_scale",
            format!(
                "side {i} is {}; expected > 0 (a crop box of no size leaves nothing to render)",
                crate::error::number(bounds.scale[i])
            ),
        ));
    }
    Ok(PathCrop { bounds, bg_color })
}

#[derive(Serialize)]
struct RawPath<'a> {
    keyframes: Vec<RawKeyframe>,
    camera_type: &'a str,
    render_height: u32,
    render_width: u32,
    camera_path: Vec<RawFrame>,
    fps: f64,
    seconds: f64,
    smoothness_value: f64,
    is_cycle: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    crop: Option<RawCrop>,
}

#[derive(Serialize)]
struct RawFrame {
    camera_to_world: [f64; 16],
    fov: f64,
    aspect: f64,
}

#[derive(Serialize)]
struct RawKeyframe {
    matrix: String,
    fov: f64,
    aspect: f64,
    properties: String,
}

#[derive(Serialize)]
struct RawCrop {
    crop_center: [f64; 3],
    crop_scale: [f64; 3],
    crop_rot: [f64; 3],
    crop_bg_color: RawColor,
}

#[derive(Serialize)]
struct RawColor {
    r: f64,
    g: f64,
    b: f64,
}

/// How a camera path's messages are worded: `null` counts as absent, a value of the wrong
/// shape is quoted.
const PATH_STYLE: Style = Style {
    wrong_shape: Describe::Value,
};

/// The camera path's typed getters, on top of the shared [`Obj`] reader.
trait PathFields {
    /// A required string.
    fn string(&self, key: &str) -> Result<String>;
    /// A required finite number.
    fn number(&self, key: &str) -> Result<f64>;
    /// A required number > 0.
    fn positive(&self, key: &str) -> Result<f64>;
    /// A vertical FOV in degrees, strictly between 0 and 180 when `strict`.
    fn fov(&self, key: &str, strict: bool) -> Result<f64>;
    /// An image side: a whole number from 1 to 65536.
    fn side(&self, key: &str) -> Result<u32>;
    /// Three finite numbers.
    fn triple(&self, key: &str) -> Result<[f64; 3]>;
    /// A row-major matrix: 16 (or 12, a 3×4) numbers flat, or 4 (or 3) rows of 4.
    fn row_major_matrix(&self, key: &str) -> Result<DMat4>;
    /// A string holding 16 numbers of a column-major matrix (the viewer's keyframes).
    fn column_major_string(&self, key: &str) -> Result<DMat4>;
}

impl PathFields for Obj<'_> {
    fn string(&self, key: &str) -> Result<String> {
        self.get::<String>(key, "a string")
    }

    fn number(&self, key: &str) -> Result<f64> {
        self.finite(key, "a number")
    }

    fn positive(&self, key: &str) -> Result<f64> {
        let v = self.number(key)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.error(key, format!("expected a number > 0, got {v}")))
        }
    }

    fn fov(&self, key: &str, strict: bool) -> Result<f64> {
        let v = self.number(key)?;
        if strict && !(v > 0.0 && v < 180.0) {
            return Err(self.error(
                key,
                format!("{v} degrees; expected a vertical FOV strictly between 0 and 180"),
            ));
        }
        Ok(v)
    }

    fn side(&self, key: &str) -> Result<u32> {
        let v = self.required(key, "a whole number of pixels")?;
        match v.as_u64() {
            Some(n) if (1..=65536).contains(&n) => Ok(n as u32),
            _ => Err(self.error(
                key,
                format!(
                    "expected a whole number of pixels from 1 to 65536, got {}",
                    short(v)
                ),
            )),
        }
    }

    fn triple(&self, key: &str) -> Result<[f64; 3]> {
        let v = self.required(key, "three numbers")?;
        let nums = numbers(v).filter(|n| n.len() == 3);
        match nums {
            Some(n) => Ok([n[0], n[1], n[2]]),
            None => Err(self.error(
                key,
                format!("expected three finite numbers, got {}", short(v)),
            )),
        }
    }

    fn row_major_matrix(&self, key: &str) -> Result<DMat4> {
        let v = self.required(key, "a 4×4 matrix")?;
        let flat = match v {
            Value::Array(items) if items.iter().all(Value::is_array) => {
                let mut flat = Vec::new();
                for row in items {
                    match numbers(row) {
                        Some(r) if r.len() == 4 => flat.extend(r),
                        _ => {
                            return Err(self.error(
                                key,
                                format!("expected rows of four finite numbers, got {}", short(row)),
                            ))
                        }
                    }
                }
                Some(flat)
            }
            other => numbers(other),
        };
        let rows = match flat {
            Some(f) if f.len() == 16 || f.len() == 12 => f,
            _ => {
                return Err(self.error(
                    key,
                    format!(
                        "expected 16 finite numbers (a row-major 4×4 matrix), got {}",
                        short(v)
                    ),
                ))
            }
        };
        let mut m = [0.0f64; 16];
        m[..rows.len()].copy_from_slice(&rows);
        if rows.len() == 12 {
            m[15] = 1.0;
        }
        if m[12..] != [0.0, 0.0, 0.0, 1.0] {
            return Err(self.error(
                key,
                format!("bottom row is {:?}, expected [0, 0, 0, 1]", &m[12..]),
            ));
        }
        Ok(DMat4::from_cols_array(&m).transpose())
    }

    fn column_major_string(&self, key: &str) -> Result<DMat4> {
        let text = self.string(key)?;
        let parsed: Option<Vec<f64>> = serde_json::from_str::<Value>(&text)
            .ok()
            .as_ref()
            .and_then(numbers);
        match parsed {
            Some(m) if m.len() == 16 => Ok(DMat4::from_cols_slice(&m)),
            _ => Err(self.error(
                key,
                "expected a string holding 16 finite numbers (a column-major 4×4 matrix)",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A path with one perspective camera at `c2w_json` (any accepted form).
    fn one_camera(c2w_json: &str, extra: &str) -> String {
        format!(
            r#"{{"camera_type": "perspective", "render_width": 200, "render_height": 100,
                "seconds": 0.5, "fps": 99{extra},
                "camera_path": [{{"camera_to_world": {c2w_json}, "fov": 90, "aspect": 3}}]}}"#
        )
    }

    const ROWS: [[f64; 4]; 4] = [
        [0.0, -1.0, 0.0, 1.0],
        [1.0, 0.0, 0.0, 2.0],
        [0.0, 0.0, 1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ];

    #[test]
    fn row_major_flat_nested_and_3x4_agree() {
        let flat: Vec<f64> = ROWS.iter().flatten().copied().collect();
        let forms = [
            serde_json::to_string(&flat).unwrap(),
            serde_json::to_string(&ROWS).unwrap(),
            serde_json::to_string(&flat[..12]).unwrap(),
        ];
        for form in forms {
            let p = CameraPath::from_json_str(&one_camera(&form, ""), "p.json").unwrap();
            let m = p.frames[0].camera_to_world;
            // Row-major: the translation is the last entry of each row.
            assert_eq!(m.w_axis.truncate(), DVec3::new(1.0, 2.0, 3.0), "{form}");
            // Camera X axis is the first column: (0, 1, 0).
            assert_eq!(m.x_axis.truncate(), DVec3::Y, "{form}");
        }
    }

    #[test]
    fn vertical_fov_gives_the_focal_length_and_frame_rate_from_seconds() {
        let flat: Vec<f64> = ROWS.iter().flatten().copied().collect();
        let text = one_camera(&serde_json::to_string(&flat).unwrap(), "");
        let p = CameraPath::from_json_str(&text, "p.json").unwrap();
        // fps = 1 frame / 0.5 s, not the file's 99.
        assert_eq!(p.frame_rate(), 2.0);
        let cam = p.camera(0, Eye::Both).unwrap();
        assert_eq!(cam.resolution(), (200, 100));
        // fov 90° at H = 100: f = 50/tan(45°) = 50 px; the top edge looks 45° up, whatever
        // the `aspect`; a pixel 25 px right of centre looks along (0.5, 0, −1) in camera space.
        let Projection::Perspective(persp) = cam.projection() else {
            panic!("not perspective")
        };
        let top = persp.camera_ray(100.0, 0.0).unwrap().dir;
        assert!((top - DVec3::new(0.0, 1.0, -1.0).normalize()).length() < 1e-12);
        let right = persp.camera_ray(125.0, 50.0).unwrap().dir;
        assert!((right - DVec3::new(0.5, 0.0, -1.0).normalize()).length() < 1e-12);
    }

    #[test]
    fn keyframe_matrices_are_column_major_strings() {
        let flat: Vec<f64> = ROWS.iter().flatten().copied().collect();
        // Column-major: the translation is the 13th..15th entries.
        let cols = "[0,1,0,0, -1,0,0,0, 0,0,1,0, 1,2,3,1]";
        let extra = format!(r#", "keyframes": [{{"matrix": "{cols}", "fov": 40}}]"#);
        let text = one_camera(&serde_json::to_string(&flat).unwrap(), &extra);
        let p = CameraPath::from_json_str(&text, "p.json").unwrap();
        assert_eq!(p.keyframes[0].matrix, p.frames[0].camera_to_world);
        assert_eq!(p.keyframes[0].fov, 40.0);
    }

    #[test]
    fn schema_errors_name_file_frame_and_field() {
        let good = r#"{"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 50}"#;
        let cases = [
            (
                format!(r#"[{good}, {{"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}}]"#),
                "camera_path[1].fov",
            ),
            (
                format!(r#"[{good}, {{"camera_to_world": [1,0,0], "fov": 50}}]"#),
                "camera_path[1].camera_to_world",
            ),
            (
                format!(
                    r#"[{good}, {{"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 180}}]"#
                ),
                "camera_path[1].fov",
            ),
            (
                format!(
                    r#"[{good}, {{"camera_to_world": [0,0,0,0, 0,0,0,0, 0,0,0,0, 0,0,0,1], "fov": 50}}]"#
                ),
                "camera_path[1]",
            ),
        ];
        for (frames, location) in cases {
            let text = format!(
                r#"{{"render_width": 8, "render_height": 8, "seconds": 1, "camera_path": {frames}}}"#
            );
            let e = CameraPath::from_json_str(&text, "shots/p.json").unwrap_err();
            let msg = e.to_string();
            assert!(
                matches!(e, Error::Format { .. })
                    && msg.contains("shots/p.json")
                    && msg.contains(location),
                "{msg} (expected {location})"
            );
        }
        let text = r#"{"render_width": 8, "render_height": 0, "seconds": 1, "camera_path": []}"#;
        let msg = CameraPath::from_json_str(text, "p.json")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("camera_path"), "{msg}");
    }

    #[test]
    fn fisheye_is_refused_as_unsupported() {
        let text = r#"{"camera_type": "fisheye", "render_width": 8, "render_height": 8,
            "seconds": 1, "camera_path": [{"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 50}]}"#;
        let e = CameraPath::from_json_str(text, "p.json").unwrap_err();
        assert!(matches!(e, Error::Unsupported(_)), "{e}");
    }

    #[test]
    fn panoramic_and_stereo_types_use_per_eye_resolution() {
        for (name, both, left) in [
            ("equirectangular", (64, 32), (64, 32)),
            ("omnidirectional", (64, 64), (64, 32)),
            ("vr180", (128, 32), (64, 32)),
        ] {
            let text = format!(
                r#"{{"camera_type": "{name}", "render_width": 64, "render_height": 32, "seconds": 1,
                    "camera_path": [{{"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}}]}}"#
            );
            let p = CameraPath::from_json_str(&text, "p.json").unwrap();
            assert_eq!(p.camera(0, Eye::Both).unwrap().resolution(), both, "{name}");
            assert_eq!(p.camera(0, Eye::Left).unwrap().resolution(), left, "{name}");
            // The image centre (of the left eye) looks down −Z.
            let r = p.camera(0, Eye::Left).unwrap().ray(32.0, 16.0).unwrap();
            assert!((r.dir - DVec3::NEG_Z).length() < 1e-12, "{name}");
        }
    }

    #[test]
    fn a_crop_of_no_size_is_refused() {
        let text = r#"{"camera_type": "perspective", "render_width": 32, "render_height": 16,
            "seconds": 1, "camera_path": [{"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,4, 0,0,0,1], "fov": 30}],
            "keyframes": [], "crop": {"crop_center": [0, 0, 0], "crop_scale": [2, 0, 2]}}"#;
        let e = CameraPath::from_json_str(text, "p.json")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("crop_scale") && e.contains("side 1 is 0; expected > 0"),
            "{e}"
        );
        let ok = text.replace("[2, 0, 2]", "[2, 1e-3, 2]");
        assert!(CameraPath::from_json_str(&ok, "p.json").is_ok());
    }

    #[test]
    fn crop_reads_both_colour_forms_and_round_trips() {
        let text = r#"{"camera_type": "perspective", "render_width": 32, "render_height": 16,
            "seconds": 2, "is_cycle": true, "smoothness_value": 0.25,
            "camera_path": [{"camera_to_world": [1,0,0,0.5, 0,1,0,0, 0,0,1,4, 0,0,0,1], "fov": 30},
                            {"camera_to_world": [[1,0,0,0], [0,1,0,0], [0,0,1,5], [0,0,0,1]], "fov": 35}],
            "keyframes": [{"matrix": "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0.5,0,4,1]", "fov": 30,
                           "properties": "[[\"NAME\",\"Camera 0\"]]"}],
            "crop": {"crop_center": [0, 1.1, 0], "crop_scale": [2, 0.8, 0.8],
                     "crop_rot": [0.1, 0.2, 0.3], "crop_bg_color": {"r": 10, "g": 20, "b": 30}}}"#;
        let p = CameraPath::from_json_str(text, "p.json").unwrap();
        let crop = p.crop.unwrap();
        assert_eq!(crop.bg_color, [10.0, 20.0, 30.0]);
        assert_eq!(crop.bounds.center, [0.0, 1.1, 0.0]);
        assert_eq!(crop.bounds.rotation, [0.1, 0.2, 0.3]);
        let list = text.replace(r#"{"r": 10, "g": 20, "b": 30}"#, "[10, 20, 30]");
        let q = CameraPath::from_json_str(&list, "p.json").unwrap();
        assert_eq!(q.crop.unwrap().bg_color, [10.0, 20.0, 30.0]);

        let dir = std::env::temp_dir().join(format!("nerfx-ns-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("camera_path.json");
        p.write(&out).unwrap();
        let back = CameraPath::read(&out).unwrap();
        assert_eq!(
            CameraPath {
                source: PathBuf::new(),
                ..back.clone()
            },
            CameraPath {
                source: PathBuf::new(),
                ..p.clone()
            }
        );
        // Written as the add-on writes: flat row-major matrices, fps = len/seconds = 1.
        let raw: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        assert_eq!(raw["camera_path"][1]["camera_to_world"][11], 5.0);
        assert_eq!(raw["camera_path"][0]["camera_to_world"][3], 0.5);
        assert_eq!(raw["fps"], 1.0);
        let kf: Vec<f64> =
            serde_json::from_str(raw["keyframes"][0]["matrix"].as_str().unwrap()).unwrap();
        assert_eq!(kf[12..15], [0.5, 0.0, 4.0]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn shot_from_a_path_frames_exactly_like_the_path() {
        let text = r#"{"render_width": 48, "render_height": 30, "seconds": 1,
            "camera_path": [{"camera_to_world": [0,-1,0,1, 1,0,0,2, 0,0,1,3, 0,0,0,1], "fov": 37}]}"#;
        let p = CameraPath::from_json_str(text, "p.json").unwrap();
        let shot = p.to_shot(1001, "NeRF").unwrap();
        let frame = shot.frame(1001).unwrap();
        assert!(frame
            .object_matrix("NeRF")
            .unwrap()
            .abs_diff_eq(DMat4::IDENTITY, 1e-15));
        let a = p.camera(0, Eye::Both).unwrap();
        let b = frame.camera(&shot).unwrap();
        for (x, y) in [(0.5, 0.5), (24.0, 15.0), (47.5, 3.25)] {
            let (ra, rb) = (a.ray(x, y).unwrap(), b.ray(x, y).unwrap());
            assert!((ra.dir - rb.dir).length() < 1e-12 && (ra.origin - rb.origin).length() < 1e-12);
        }
    }
}
