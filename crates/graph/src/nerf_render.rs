//! The NeRF Render node: a scene (field) file seen through a shot file's camera.
//!
//! The shot's time is the host's time plus the frame offset; between two frames the camera
//! and objects are interpolated ([`Shot::frame_at`]). Render scale `s`
//! renders the shot at `ceil(s·width) × ceil(s·height)` pixels (the same camera, fewer
//! pixels), so no parameter of this node is spatial. Outputs, as RGBA:
//! - `rgba`: the render (premultiplied, times `2^exposure`, in the Output Colour Space) over
//!   the background colour, which is over the optional Source clip;
//! - `accumulation`: the accumulation in all four channels;
//! - `depthZ` / `depthRay`: depth in Blender units in RGB (10¹⁰ where nothing was hit, as in
//!   Blender's Z pass), the accumulation in alpha; the depth plane itself rides along.
//!
//! Every output is cut from one render of every pass, shared with the node's siblings
//! (`shared_renders`): asking a field for RGBA and depth costs one march.

use std::path::Path;
use std::sync::Arc;

use glam::DMat4;

use super::cache::{cached_scene, cached_shot};
use super::desc::{ClipDesc, ClipKind, Context, NodeDesc, ParamDesc, ParamKind, Range};
use super::node::{Format, Node, OutputSpace, RenderRequest, Rendered};
use super::shared_renders::{shared_render, RenderKey};
use super::values::ParamValues;
use nerfx_core::camera::{
    Camera, Eye, Shot, ShotCameraKind, ShotFrame, ShotStereo, StereoMode, DEFAULT_IPD,
    MAX_APERTURE_SAMPLES, MAX_SHUTTER_SAMPLES,
};
use nerfx_core::composite::{over, rgba_pixels, rgba_planes};
use nerfx_core::error::{number, Error, Result};
use nerfx_core::image::{
    scaled_size, DeepImage, OutputColorSpace, Plane, Planes, BACKGROUND_DEPTH,
};
use nerfx_core::render::{conform_to, ColorOutput, Outputs, Quality};
use nerfx_core::scene::{CropBox, LoadedScene, Scene};
use nerfx_core::shot_render::{coverage_of_views, render_views, FrameRequest, FrameViews};

/// The Output Colour Space parameter's options: the scene file's, then every
/// [`OutputColorSpace`] by its name.
const OUTPUT_COLOUR_SPACES: &[(&str, &str)] = &[
    ("scene", "From Scene File"),
    ("lin_rec709", "Linear Rec.709"),
    ("acescg", "ACEScg"),
    ("aces2065-1", "ACES2065-1"),
    ("lin_rec2020", "Linear Rec.2020"),
    ("lin_p3d65", "Linear P3-D65"),
    ("srgb", "sRGB (display)"),
];

const CONTEXTS: &[Context] = &[Context::Generator, Context::Filter, Context::General];
const WITH_SOURCE: &[Context] = &[Context::Filter, Context::General];

fn choice(
    name: &'static str,
    label: &'static str,
    hint: &'static str,
    options: &'static [(&'static str, &'static str)],
) -> ParamDesc {
    ParamDesc::new(
        name,
        label,
        hint,
        ParamKind::Choice {
            options,
            default: 0,
        },
    )
}

fn vec3(
    name: &'static str,
    label: &'static str,
    hint: &'static str,
    default: [f64; 3],
    range: Range,
) -> ParamDesc {
    ParamDesc::new(name, label, hint, ParamKind::Double3 { default, range })
}

/// The node's description and functions.
pub(crate) fn nerf_render_node() -> Node {
    let identity: [f64; 16] = DMat4::IDENTITY.transpose().to_cols_array();
    Node {
        desc: NodeDesc {
            id: NODE_ID,
            label: "NeRF Render",
            group: "NeRF",
            hint: "Renders radiance fields from a Blender shot's camera: premultiplied RGBA, \
                   accumulation or depth in Blender units.",
            contexts: CONTEXTS,
            clips: vec![ClipDesc {
                name: "Source",
                label: "Source",
                hint: "Optional background: the render goes over it.",
                kind: ClipKind::Rgba,
                optional: true,
                contexts: WITH_SOURCE,
            }],
            params: vec![
                ParamDesc::new(
                    "file",
                    "Field File",
                    "Scene file (JSON): the fields and splats and where they sit; or one \
                     instant-ngp snapshot, splat file (.ply, .splat, .spz, .sog) or nerfstudio \
                     run, in its own frame.",
                    ParamKind::File,
                )
                .fixed(),
                ParamDesc::new(
                    "shot",
                    "Shot File",
                    "nerfx shot file from the Blender add-on, or a nerfstudio camera_path.json.",
                    ParamKind::File,
                )
                .fixed(),
                ParamDesc::new(
                    "frameOffset",
                    "Frame Offset",
                    "Added to the host's frame to find the shot's frame.",
                    ParamKind::Int {
                        default: 0,
                        range: Range::display(-1.0e6, 1.0e6, -100.0, 100.0),
                    },
                )
                .fixed(),
                ParamDesc::new(
                    "overrideTransform",
                    "Override Object Transform",
                    "Place the NeRF object by the matrix below instead of the shot's.",
                    ParamKind::Bool { default: false },
                ),
                ParamDesc::new(
                    "objectTransform",
                    "Object Transform",
                    "The NeRF object's matrix_world, row-major.",
                    ParamKind::Matrix { default: identity },
                ),
                choice(
                    "cameraModel",
                    "Camera Model",
                    "The shot's camera, or a panorama from its position.",
                    &[
                        ("shot", "From Shot"),
                        ("equirect", "Equirectangular"),
                        ("ods", "ODS (stereo)"),
                        ("vr180", "VR180 (stereo)"),
                    ],
                ),
                choice(
                    "eye",
                    "Eye",
                    "Which eye(s) of a stereo camera.",
                    &[
                        ("shot", "From Shot"),
                        ("left", "Left"),
                        ("right", "Right"),
                        ("both", "Both"),
                    ],
                ),
                choice(
                    "output",
                    "Output",
                    "What the image holds.",
                    &[
                        ("rgba", "RGBA (premultiplied)"),
                        ("accumulation", "Accumulation"),
                        ("depthZ", "Depth Z"),
                        ("depthRay", "Ray Depth"),
                    ],
                ),
                choice(
                    "colour",
                    "Colour",
                    "Linear: a capture trained on photographs is composited as its trainer \
                     did, in sRGB-encoded space, then converted to scene-linear. As Trained: \
                     that composite unconverted, as the trainer's viewer shows it.",
                    &[("linear", "Linear"), ("asTrained", "As Trained (display)")],
                ),
                choice(
                    "outputColourSpace",
                    "Output Colour Space",
                    "The colour space of the RGBA output: the scene file's (linear Rec.709 when \
                     it names none), a linear space of an ACES pipeline or a wide gamut, or \
                     display-encoded sRGB for previews. Background and Source are taken to be \
                     in it already.",
                    OUTPUT_COLOUR_SPACES,
                ),
                ParamDesc::new(
                    "crop",
                    "Crop",
                    "Clip rays to the box below (field space) in every field.",
                    ParamKind::Bool { default: false },
                ),
                vec3(
                    "cropCenter",
                    "Crop Center",
                    "Box centre, field units.",
                    [0.0; 3],
                    Range::display(-1.0e6, 1.0e6, -2.0, 2.0),
                ),
                vec3(
                    "cropSize",
                    "Crop Size",
                    "Full side lengths, field units.",
                    [2.0; 3],
                    Range::display(0.0, 1.0e6, 0.0, 4.0),
                ),
                vec3(
                    "cropRotation",
                    "Crop Rotation",
                    "Roll, pitch, yaw in degrees (Rz·Ry·Rx).",
                    [0.0; 3],
                    Range::display(-360.0, 360.0, -180.0, 180.0),
                ),
                ParamDesc::new(
                    "quality",
                    "Quality",
                    "March preset; the host's draft mode uses Draft.",
                    ParamKind::Choice {
                        options: &[
                            ("draft", "Draft"),
                            ("preview", "Preview"),
                            ("final", "Final"),
                        ],
                        default: 1,
                    },
                ),
                ParamDesc::new(
                    "shutterSamples",
                    "Shutter Samples",
                    "Times per frame the render is averaged over the shot's motion-blur \
                     shutter (0: the quality preset's; 1: no blur).",
                    ParamKind::Int {
                        default: 0,
                        range: Range::display(0.0, 1024.0, 0.0, 32.0),
                    },
                ),
                ParamDesc::new(
                    "apertureSamples",
                    "Aperture Samples",
                    "Points of the lens aperture the render is averaged over per shutter time \
                     when the shot's camera has depth of field (0: the quality preset's; 1: a \
                     pinhole).",
                    ParamKind::Int {
                        default: 0,
                        range: Range::display(0.0, 4096.0, 0.0, 64.0),
                    },
                ),
                ParamDesc::new(
                    "background",
                    "Background",
                    "Colour (premultiplied) behind the render.",
                    ParamKind::Rgba {
                        default: [0.0; 4],
                        range: Range::display(0.0, 1.0e6, 0.0, 1.0),
                    },
                ),
                ParamDesc::new(
                    "exposure",
                    "Exposure",
                    "Stops: the colour is scaled by 2^exposure.",
                    ParamKind::Double {
                        default: 0.0,
                        range: Range::display(-20.0, 20.0, -5.0, 5.0),
                    },
                ),
            ],
            frame_varying: true,
        },
        render: render_node,
        rod: Some(Format {
            size: |values, time| {
                let shot = node_shot(values)?;
                let time = within_shot(values, &shot, time)?;
                Ok(camera(values, &shot, time, 1.0)?.1.resolution())
            },
            time_domain: Some(|values| time_domain(values, &*node_shot(values)?)),
            pixel_aspect: Some(pixel_aspect),
        }),
        identity: None,
        output_space: Some(|values| {
            Ok(match values.choice("output")? {
                "rgba" => OutputSpace::Colour(output_color_space(values)?),
                _ => OutputSpace::Data,
            })
        }),
    }
}

fn file<'a>(values: &'a ParamValues, name: &str) -> Result<&'a Path> {
    let path = values.text(name)?;
    if path.is_empty() {
        return Err(Error::invalid(format!("parameter {name}"), "no file given"));
    }
    Ok(Path::new(path))
}

/// The node's shot, from the file cache.
fn node_shot(values: &ParamValues) -> Result<Arc<Shot>> {
    cached_shot(file(values, "shot")?)
}

/// The host frames the shot covers: its first and last frame less the frame offset (the
/// node renders shot frame `time + frameOffset`).
fn time_domain(values: &ParamValues, shot: &Shot) -> Result<Option<(f64, f64)>> {
    let offset = values.int("frameOffset")? as f64;
    let first = shot.frames.iter().map(|f| f.frame).min();
    let last = shot.frames.iter().map(|f| f.frame).max();
    Ok(first
        .zip(last)
        .map(|(a, b)| (a as f64 - offset, b as f64 - offset)))
}

/// `time` moved into the host frames the shot covers. A node's format is the shot's whatever
/// the frame: a host asking for it at a frame outside the shot gets it, and the render of that
/// frame is the one to fail, saying which frames the shot holds.
fn within_shot(values: &ParamValues, shot: &Shot, time: f64) -> Result<f64> {
    Ok(match time_domain(values, shot)? {
        Some((first, last)) if time.is_finite() => time.clamp(first, last),
        _ => time,
    })
}

/// The shot's pixel aspect (`pixel_aspect_x / pixel_aspect_y`) when the camera at `time` is
/// perspective; panoramas (from the shot or the camera model) have square pixels.
fn pixel_aspect(values: &ParamValues, time: f64) -> Result<f64> {
    let shot = node_shot(values)?;
    let (_, camera) = camera(values, &shot, within_shot(values, &shot, time)?, 1.0)?;
    Ok(shot.pixel_aspect_for(&camera))
}

/// The shot frame for `time` and its camera at render scale `scale`.
fn camera(values: &ParamValues, shot: &Shot, time: f64, scale: f64) -> Result<(ShotFrame, Camera)> {
    let at = node_frame(values, shot, time)?;
    let camera = scaled_camera(shot, &at, scale)?;
    Ok((at, camera))
}

/// The shot's frame at host time `time` as the node sees it: the frame offset applied, the
/// camera model and eye overridden (a panoramic model has no depth of field).
fn node_frame(values: &ParamValues, shot: &Shot, time: f64) -> Result<ShotFrame> {
    shot_frame(values, shot, shot_time(values, time)?)
}

/// The shot's time at host time `time`: the frame offset applied.
fn shot_time(values: &ParamValues, time: f64) -> Result<f64> {
    if !time.is_finite() {
        return Err(Error::invalid(
            "time",
            format!("expected a frame, got {}", number(time)),
        ));
    }
    Ok(time + values.int("frameOffset")? as f64)
}

/// The shot's frame at shot time `time` as the node sees it (see [`node_frame`]).
fn shot_frame(values: &ParamValues, shot: &Shot, time: f64) -> Result<ShotFrame> {
    // A sub-frame time (motion blur, a field at t + 0.5) falls between two shot frames.
    let mut at = shot.frame_at(time)?;
    let c = &mut at.camera;
    let mode = match values.choice("cameraModel")? {
        "ods" => Some(StereoMode::Ods),
        "vr180" => Some(StereoMode::Vr180),
        _ => None,
    };
    if values.choice("cameraModel")? != "shot" {
        c.kind = ShotCameraKind::Equirect;
        c.dof = None;
        c.stereo = mode.map(|mode| ShotStereo {
            mode,
            eye: c.stereo.map_or(Eye::Both, |s| s.eye),
            ipd: c.stereo.map_or(DEFAULT_IPD, |s| s.ipd),
        });
    }
    if let Some(s) = &mut c.stereo {
        match values.choice("eye")? {
            "left" => s.eye = Eye::Left,
            "right" => s.eye = Eye::Right,
            "both" => s.eye = Eye::Both,
            _ => {}
        }
    }
    Ok(at)
}

/// The camera of `at` with the shot's format at render scale `scale`.
fn scaled_camera(shot: &Shot, at: &ShotFrame, scale: f64) -> Result<Camera> {
    let (w, h) = at.camera.intrinsics(shot).effective_resolution()?;
    // Below one pixel a side there is no image to scale the camera to.
    if f64::from(w.min(h)) * scale < 1.0 {
        return Err(Error::invalid(
            "render scale",
            format!(
                "{} makes the {w}×{h} image less than one pixel: the smallest scale for it is \
                 1/{} ({})",
                number(scale),
                w.min(h),
                number(1.0 / f64::from(w.min(h)))
            ),
        ));
    }
    // The shot's format at render scale, holding only this frame (cheap to build per call).
    let one = Shot {
        fps: shot.fps,
        fps_base: shot.fps_base,
        resolution_x: scaled_size(w, scale),
        resolution_y: scaled_size(h, scale),
        resolution_percentage: 100,
        pixel_aspect_x: shot.pixel_aspect_x,
        pixel_aspect_y: shot.pixel_aspect_y,
        nerf_object: shot.nerf_object.clone(),
        frames: vec![at.clone()],
        motion_blur: None,
        scene_world: shot.scene_world,
        source: shot.source.clone(),
    };
    at.camera(&one)
}

/// The scene `loaded` (the node's file, perhaps recoloured) placed at `at`, with the
/// transform override and crop box applied.
fn placed_scene(
    values: &ParamValues,
    shot: &Shot,
    at: &ShotFrame,
    loaded: &LoadedScene,
) -> Result<Scene> {
    let over_ride = if values.bool("overrideTransform")? {
        let m = values.doubles("objectTransform")?;
        let mut rows = [0.0; 16];
        rows.copy_from_slice(m);
        Some(DMat4::from_cols_array(&rows).transpose())
    } else {
        None
    };
    let scene = loaded.place(at.world_from_scene(shot)?, &|name| match over_ride {
        Some(m) => Ok(m),
        None => at.object_matrix(name),
    })?;
    if !values.bool("crop")? {
        return Ok(scene);
    }
    let v3 = |name: &str| -> Result<[f64; 3]> {
        let v = values.doubles(name)?;
        Ok([v[0], v[1], v[2]])
    };
    let crop = CropBox {
        center: v3("cropCenter")?,
        scale: v3("cropSize")?,
        rotation: v3("cropRotation")?.map(f64::to_radians),
    };
    scene.with_crop(Some(crop))
}

/// Parameters that only pick or grade the output: nodes differing only in these share one
/// render.
const LOOK: &[&str] = &["output", "background", "exposure", "outputColourSpace"];

/// The values that decide what a node with `values` renders: two nodes with the same ones
/// march the same scene the same way (they may show different outputs of it).
pub(crate) fn render_values(values: &ParamValues) -> ParamValues {
    values.with_defaults(LOOK)
}

/// The registry identifier of the NeRF Render node.
pub(crate) const NODE_ID: &str = "org.nerfx.NeRFRender";

/// The colour space a node with `values` outputs, read from its scene file's text without
/// loading its fields (a graph settles its colour space when it is read).
pub(crate) fn declared_color_space(values: &ParamValues) -> Result<OutputColorSpace> {
    match values.choice("outputColourSpace")? {
        "scene" => Ok(
            nerfx_core::scene::SceneDesc::for_path(file(values, "file")?)?
                .colorspace
                .unwrap_or_default(),
        ),
        name => OutputColorSpace::parse(name, "parameter outputColourSpace"),
    }
}

/// The camera a node with `values` renders through at host time `time` (full resolution),
/// and its shot.
pub(crate) fn node_camera(values: &ParamValues, time: f64) -> Result<(Camera, Arc<Shot>)> {
    let shot = node_shot(values)?;
    let time = within_shot(values, &shot, time)?;
    let (_, camera) = camera(values, &shot, time, 1.0)?;
    Ok((camera, shot))
}

/// The colour space the node's RGBA output is in: its Output Colour Space, or the scene
/// file's (linear Rec.709 when it names none).
pub(crate) fn output_color_space(values: &ParamValues) -> Result<OutputColorSpace> {
    match values.choice("outputColourSpace")? {
        "scene" => Ok(cached_scene(file(values, "file")?)?
            .desc()
            .colorspace
            .unwrap_or_default()),
        name => OutputColorSpace::parse(name, "parameter outputColourSpace"),
    }
}

fn render_node(values: &ParamValues, request: &RenderRequest) -> Result<Rendered> {
    let shot = node_shot(values)?;
    let key = RenderKey {
        scene: Arc::downgrade(&cached_scene(file(values, "file")?)?),
        shot: Arc::downgrade(&shot),
        values: values.with_defaults(LOOK),
        time: request.time,
        render_scale: request.render_scale,
        window: request.window,
        draft: request.draft,
    };
    let shared = shared_render(key, || march(values, &shot, request))?;
    Ok(Rendered {
        planes: look(values, request, &shared.planes)?,
        stats: shared.stats,
    })
}

/// Every pass of the node's scene for `request`, from one march per view, and the marches'
/// statistics summed.
fn march(values: &ParamValues, shot: &Shot, request: &RenderRequest) -> Result<Rendered> {
    let loaded = cached_scene(file(values, "file")?)?;
    let frame = node_request(values, request, Outputs::all())?;
    let views = NodeViews::new(values, shot, request)?;
    let (planes, _, stats) = render_views(&loaded, &views, &frame, &|_| {})?;
    Ok(Rendered { planes, stats })
}

/// Each instance of the node's scene and its coverage of `request`'s window: the share of
/// every pixel's opacity in the node's own render (before its background and Source) that
/// the instance's samples and fragments hold, so that a pixel's coverages add up to that
/// render's alpha. The render is the node's own (camera, transform, crop, quality, shutter),
/// made with the instances in indicator colours three at a time ([`coverage_of_views`]).
pub(crate) fn node_coverage(
    values: &ParamValues,
    request: &RenderRequest,
) -> Result<Vec<(String, Plane)>> {
    let shot = node_shot(values)?;
    let loaded = cached_scene(file(values, "file")?)?;
    let names: Vec<String> = loaded
        .desc()
        .instances
        .iter()
        .map(|i| i.name.clone())
        .collect();
    let frame = node_request(values, request, Outputs::rgba())?;
    let views = NodeViews::new(values, &shot, request)?;
    let coverage = coverage_of_views(&loaded, &views, &frame)?;
    Ok(names.into_iter().zip(coverage).collect())
}

/// The node's render of `request`'s window (its RGBA, exposed and in its Output Colour Space,
/// without its background and Source) and the deep image of it: at most `deep_samples` a
/// pixel (the quality preset's cap without it); over several views (motion blur, depth of
/// field) the views' deep pixels averaged ([`render_views`]), which flattens to the averaged
/// render.
pub(crate) fn node_deep(
    values: &ParamValues,
    request: &RenderRequest,
    deep_samples: Option<u32>,
) -> Result<(Planes, DeepImage)> {
    let frame = node_request(values, request, Outputs::rgba())?.with_deep(deep_samples)?;
    let shot = node_shot(values)?;
    let loaded = cached_scene(file(values, "file")?)?;
    let views = NodeViews::new(values, &shot, request)?;
    let (mut planes, image, _) = render_views(&loaded, &views, &frame, &|_| {})?;
    let mut image = image.ok_or_else(|| Error::invalid("deep output", "no deep image made"))?;
    // Exposed in linear light, then converted, as the node's RGBA output is.
    let gain = values.double("exposure")?.exp2() as f32;
    if gain != 1.0 {
        for plane in planes.rgb.iter_mut().flatten() {
            plane.data.iter_mut().for_each(|v| *v *= gain);
        }
        for sample in &mut image.samples {
            sample.rgb = sample.rgb.map(|v| v * gain);
        }
    }
    let space = output_color_space(values)?;
    space.convert_planes(&mut planes);
    space.convert_deep(&mut image);
    conform_to(&mut image, &planes);
    Ok((planes, image))
}

/// The quality preset the node renders `request` at (Draft for a host's draft render).
fn node_quality(values: &ParamValues, request: &RenderRequest) -> Result<Quality> {
    Ok(match values.choice("quality")? {
        _ if request.draft => Quality::Draft,
        "draft" => Quality::Draft,
        "final" => Quality::Final,
        _ => Quality::Preview,
    })
}

/// The frame the node renders for `request` with the passes `outputs`: its quality preset,
/// its colour, its shutter and aperture samples (the preset's where they are 0), the
/// request's window.
fn node_request(
    values: &ParamValues,
    request: &RenderRequest,
    outputs: Outputs,
) -> Result<FrameRequest> {
    let quality = node_quality(values, request)?;
    let color = match values.choice("colour")? {
        "asTrained" => ColorOutput::AsTrained,
        _ => ColorOutput::Linear,
    };
    // A count past its parameter's range is taken as the range's nearest end.
    let samples = |name: &str, max: u32| -> Result<Option<u32>> {
        Ok(match values.int(name)? {
            0 => None,
            n => Some(n.clamp(1, i64::from(max)) as u32),
        })
    };
    let mut frame = FrameRequest::for_quality(quality, outputs)
        .with_colour(color)
        .with_window(request.window)?;
    if let Some(n) = samples("shutterSamples", MAX_SHUTTER_SAMPLES)? {
        frame = frame.with_shutter_samples(n)?;
    }
    if let Some(n) = samples("apertureSamples", MAX_APERTURE_SAMPLES)? {
        frame = frame.with_aperture_samples(n)?;
    }
    Ok(frame)
}

/// A frame of the node's shot as the node sees it for a render request: at the host's time
/// plus the frame offset, its camera model and eye applied to every view, the scene placed
/// with its transform override and crop box, seen at the request's render scale.
struct NodeViews<'a> {
    values: &'a ParamValues,
    shot: &'a Shot,
    request: &'a RenderRequest,
    /// The shot's time of the request.
    time: f64,
}

impl<'a> NodeViews<'a> {
    fn new(values: &'a ParamValues, shot: &'a Shot, request: &'a RenderRequest) -> Result<Self> {
        Ok(NodeViews {
            values,
            shot,
            request,
            time: shot_time(values, request.time)?,
        })
    }
}

impl FrameViews for NodeViews<'_> {
    fn shot(&self) -> &Shot {
        self.shot
    }

    fn time(&self) -> f64 {
        self.time
    }

    fn frame_at(&self, time: f64) -> Result<ShotFrame> {
        shot_frame(self.values, self.shot, time)
    }

    /// The scene placed for the view `at` and its camera at the request's render scale,
    /// which must hold the request's window.
    fn place(&self, loaded: &LoadedScene, at: &ShotFrame) -> Result<(Scene, Camera)> {
        let (window, scale) = (self.request.window, self.request.render_scale);
        let camera = scaled_camera(self.shot, at, scale)?;
        if camera.clamp_window(window)? != window {
            let (w, h) = camera.resolution();
            return Err(Error::invalid(
                "render window",
                format!("{window:?} is not inside the {w}×{h} image at render scale {scale}"),
            ));
        }
        Ok((placed_scene(self.values, self.shot, at, loaded)?, camera))
    }
}

/// The output the node shows of `planes`: one pass, exposed and over the background.
fn look(values: &ParamValues, request: &RenderRequest, planes: &Planes) -> Result<Planes> {
    let output = values.choice("output")?;
    let (w, h) = (planes.width, planes.height);
    let alpha = planes
        .alpha
        .clone()
        .unwrap_or_else(|| Plane::filled(w, h, 0.0));
    let grey = |p: &Plane, a: &Plane| {
        let px: Vec<[f32; 4]> = p
            .data
            .iter()
            .zip(&a.data)
            .map(|(&v, &a)| [v, v, v, a])
            .collect();
        rgba_planes(w, h, &px)
    };
    let far = |p: &Option<Plane>| {
        let mut p = p
            .clone()
            .unwrap_or_else(|| Plane::filled(w, h, f32::INFINITY));
        for z in &mut p.data {
            *z = z.min(BACKGROUND_DEPTH);
        }
        p
    };
    match output {
        "accumulation" => grey(&alpha, &alpha),
        "depthZ" => Ok(Planes {
            depth_z: Some(far(&planes.depth_z)),
            ..grey(&far(&planes.depth_z), &alpha)?
        }),
        "depthRay" => Ok(Planes {
            depth_ray: Some(far(&planes.depth_ray)),
            ..grey(&far(&planes.depth_ray), &alpha)?
        }),
        _ => {
            // Exposed in linear light, then converted (an encoding applies to the exposed
            // colour), then over a background and Source already in the output space.
            let gain = values.double("exposure")?.exp2() as f32;
            let space = output_color_space(values)?;
            let lit: Vec<[f32; 4]> = rgba_pixels(planes)
                .into_iter()
                .map(|p| {
                    let [r, g, b] =
                        space.convert_pixel([p[0] * gain, p[1] * gain, p[2] * gain], p[3]);
                    [r, g, b, p[3]]
                })
                .collect();
            let bg = values.doubles("background")?;
            let bg = [bg[0] as f32, bg[1] as f32, bg[2] as f32, bg[3] as f32];
            let background = rgba_planes(w, h, &vec![bg; w as usize * h as usize])?;
            let under = match request.inputs.get("Source") {
                Some(source) => over(&background, source)?,
                None => background,
            };
            over(&rgba_planes(w, h, &lit)?, &under)
        }
    }
}
