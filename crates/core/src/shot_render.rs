//! The shot renderer: one frame of a scene through a shot, the mean over its views (shutter
//! times and lens points), its Cryptomatte coverage and deep image; or an environment map of
//! it from a point.
//!
//! A [`FrameRequest`] says what a frame is made of (per-view settings, shutter and aperture
//! samples, the deep pass, the window), validated once where it is built; [`render_views`]
//! renders it from a [`FrameViews`] (the shot's frame at a time, and each view's scene and
//! camera). The command line, the NeRF Render node and graphs all render frames through it.

use glam::DVec3;

use crate::camera::{
    environment_camera, Camera, Shot, ShotFrame, MAX_APERTURE_SAMPLES, MAX_SHUTTER_SAMPLES,
};
use crate::composite::shutter_average;
use crate::error::{Error, Result};
use crate::image::{DeepImage, Plane, Planes, Window};
use crate::render::{
    average_images, render_deep, render_with_progress, ColorOutput, DeepParams, Outputs, Quality,
    RenderSettings, RenderStats,
};
use crate::scene::{LoadedScene, Scene};

/// What one frame is rendered as: each view's settings (march, passes, tile size, colour),
/// the shutter times and aperture points it is the mean of, its deep pass and its window.
/// Built by [`FrameRequest::new`] or [`FrameRequest::for_quality`] and the `with_` methods,
/// each of which refuses what a frame cannot be, so a request is valid once built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRequest {
    /// The preset the defaults came from, if any.
    quality: Option<Quality>,
    settings: RenderSettings,
    shutter_samples: u32,
    aperture_samples: u32,
    deep: Option<DeepParams>,
    window: Option<Window>,
}

impl FrameRequest {
    /// A frame of one view per frame (no shutter sampling, a pinhole) with `settings`, no
    /// deep pass, the whole image.
    pub fn new(settings: RenderSettings) -> Self {
        FrameRequest {
            quality: None,
            settings,
            shutter_samples: 1,
            aperture_samples: 1,
            deep: None,
            window: None,
        }
    }

    /// A frame at `quality`'s preset: its march ([`Quality::params`]), its shutter and
    /// aperture samples ([`Quality::shutter_samples`], [`Quality::aperture_samples`]) and,
    /// for a deep pass, its cap ([`Quality::deep_samples`]); the passes `outputs`, linear
    /// colour.
    pub fn for_quality(quality: Quality, outputs: Outputs) -> Self {
        FrameRequest {
            quality: Some(quality),
            shutter_samples: quality.shutter_samples(),
            aperture_samples: quality.aperture_samples(),
            ..FrameRequest::new(RenderSettings::new(quality.params(), outputs))
        }
    }

    /// The request with colour `color`.
    pub fn with_colour(mut self, color: ColorOutput) -> Self {
        self.settings.color = color;
        self
    }

    /// The request rendered at `samples` times over a shot's motion-blur shutter (1: none);
    /// refuses 0 and more than [`MAX_SHUTTER_SAMPLES`].
    pub fn with_shutter_samples(mut self, samples: u32) -> Result<Self> {
        self.shutter_samples = count("shutter samples", samples, MAX_SHUTTER_SAMPLES)?;
        Ok(self)
    }

    /// The request rendered through `samples` points of the aperture per shutter time where
    /// the camera has depth of field (1: a pinhole); refuses 0 and more than
    /// [`MAX_APERTURE_SAMPLES`].
    pub fn with_aperture_samples(mut self, samples: u32) -> Result<Self> {
        self.aperture_samples = count("aperture samples", samples, MAX_APERTURE_SAMPLES)?;
        Ok(self)
    }

    /// The request with a deep pass keeping at most `max_samples` samples a pixel (the
    /// quality preset's cap without it), merged within the march's error target. Refuses a
    /// cap out of range ([`DeepParams::validate`]), no cap without a preset, and passes
    /// without colour and alpha (the deep samples flatten to them).
    pub fn with_deep(mut self, max_samples: Option<u32>) -> Result<Self> {
        let Some(max_samples) = max_samples.or(self.quality.map(Quality::deep_samples)) else {
            return Err(Error::invalid(
                "deep samples",
                "none given, and no quality preset to take its cap from",
            ));
        };
        let deep = DeepParams {
            max_samples,
            error_target: self.settings.march.error_target,
        };
        deep.validate()?;
        if !(self.settings.outputs.rgb && self.settings.outputs.alpha) {
            return Err(Error::invalid(
                "deep output",
                "needs the colour and alpha passes (the samples flatten to them)",
            ));
        }
        self.deep = Some(deep);
        Ok(self)
    }

    /// The request for the pixels of `window` only; refuses an empty window.
    pub fn with_window(mut self, window: Window) -> Result<Self> {
        if window.area() == 0 {
            return Err(Error::invalid(
                "render window",
                format!("{window:?} holds no pixels"),
            ));
        }
        self.window = Some(window);
        Ok(self)
    }

    /// Each view's render settings, with the passes asked for.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Times a frame is rendered at over a shot's shutter.
    pub fn shutter_samples(&self) -> u32 {
        self.shutter_samples
    }

    /// Points of the aperture each shutter time is rendered through.
    pub fn aperture_samples(&self) -> u32 {
        self.aperture_samples
    }

    /// The request for coverage ([`render_coverage`]): colour as trained and alpha, no deep
    /// pass, the same views and window.
    fn for_coverage(&self) -> Self {
        FrameRequest {
            settings: RenderSettings {
                outputs: Outputs::rgba(),
                color: ColorOutput::AsTrained,
                ..self.settings
            },
            deep: None,
            ..*self
        }
    }
}

/// `samples` where it is 1 to `max`.
fn count(what: &str, samples: u32, max: u32) -> Result<u32> {
    if !(1..=max).contains(&samples) {
        return Err(Error::invalid(
            what,
            format!("{samples}; expected 1 to {max}"),
        ));
    }
    Ok(samples)
}

/// How a frame's views are made: the shot, the frame's time in it, the shot's frame at a
/// time of its shutter, and the scene and camera of each view. The shot's own
/// ([`render_frame`]) place the scene by the shot's object matrices; the NeRF Render node's
/// apply its camera overrides, transform, crop and render scale.
pub trait FrameViews {
    /// The shot the frame belongs to (its motion blur sets the shutter's times).
    fn shot(&self) -> &Shot;
    /// The frame's time in the shot.
    fn time(&self) -> f64;
    /// The shot's frame at shot time `time`, a shutter time of the frame.
    fn frame_at(&self, time: f64) -> Result<ShotFrame>;
    /// `scene` placed for the view `at`, and the camera it is seen through.
    fn place(&self, scene: &LoadedScene, at: &ShotFrame) -> Result<(Scene, Camera)>;
}

/// The views a frame is the mean of, grouped by shutter time: with the shot's motion blur,
/// `shutter_samples` stratified times over the shutter
/// ([`MotionBlur::times`](crate::camera::MotionBlur::times); the frame's time itself with a
/// closed shutter, one sample or no motion blur); at each time, the camera through
/// `aperture_samples` stratified points of its aperture where it has depth of field
/// ([`ShotFrame::through_aperture`]; that frame alone otherwise). Every group holds as many
/// views.
fn frame_views(views: &dyn FrameViews, request: &FrameRequest) -> Result<Vec<Vec<ShotFrame>>> {
    let time = views.time();
    let times = views.shot().motion_blur.map_or_else(
        || vec![time],
        |blur| blur.times(time, request.shutter_samples),
    );
    times
        .into_iter()
        .map(|t| {
            Ok(views
                .frame_at(t)?
                .through_aperture(request.aperture_samples))
        })
        .collect()
}

/// The mean of `render` over `views` ([`frame_views`]): each shutter time's views averaged,
/// then the times ([`shutter_average`]: alpha-weighted depths, so with equal groups this is
/// the mean over every view, holding one time's renders at once rather than all of them); a
/// lone render is returned as it is. The statistics are the renders' sum.
fn mean_over_views(
    views: &[Vec<ShotFrame>],
    render: &mut dyn FnMut(&ShotFrame) -> Result<(Planes, RenderStats)>,
) -> Result<(Planes, RenderStats)> {
    let mean = |mut planes: Vec<Planes>| match planes.len() {
        1 => Ok(planes.remove(0)),
        _ => shutter_average(planes),
    };
    let mut stats = RenderStats::default();
    let mut means = Vec::with_capacity(views.len());
    for group in views {
        let mut renders = Vec::with_capacity(group.len());
        for view in group {
            let (planes, s) = render(view)?;
            stats = stats + s;
            renders.push(planes);
        }
        means.push(mean(renders)?);
    }
    Ok((mean(means)?, stats))
}

/// Renders the frame `request` asks for of `scene` seen through `views`: the mean over the
/// frame's views (shutter times × aperture points) of each view's render of the request's
/// window (each view's camera's whole image without one), and, where the request has a deep
/// pass, the deep image: each view's deep pixels ([`render_deep`]) averaged as
/// [`average_images`] does (cut at every depth where one of them has a sample boundary, the
/// opacity and colour each adds in a slot averaged), which flattens to the averaged planes
/// exactly. The mean weighs each view's depths by its alpha, so depths asked for without
/// alpha are averaged with it all the same (and it is dropped after): a depth pass is the
/// same number whichever passes come with it. A frame of one view is that view's render,
/// bit for bit. The statistics are the views' sum.
pub fn render_views(
    scene: &LoadedScene,
    views: &dyn FrameViews,
    request: &FrameRequest,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, Option<DeepImage>, RenderStats)> {
    let frame_views = frame_views(views, request)?;
    let outputs = request.settings.outputs;
    // A mean weighs depths by alpha: it is rendered for the mean whether asked for or not.
    let depths = outputs.depth_z || outputs.depth_ray || outputs.depth_median;
    let settings = match &frame_views[..] {
        [one] if one.len() == 1 => request.settings,
        _ => RenderSettings {
            outputs: Outputs {
                alpha: outputs.alpha || depths,
                ..outputs
            },
            ..request.settings
        },
    };
    let mut deeps = Vec::new();
    let (mut mean, stats) = mean_over_views(&frame_views, &mut |at| {
        let (placed, camera) = views.place(scene, at)?;
        let window = request.window.unwrap_or_else(|| camera.full_window());
        match &request.deep {
            Some(deep) => {
                let (planes, image, stats) =
                    render_deep(&placed, &camera, window, &settings, deep, on_tile)?;
                deeps.push(image);
                Ok((planes, stats))
            }
            None => render_with_progress(&placed, &camera, window, &settings, on_tile),
        }
    })?;
    if !outputs.alpha {
        mean.alpha = None;
    }
    let deep = match (&request.deep, deeps.len()) {
        (None, _) => None,
        (Some(_), 1) => Some(deeps.remove(0)),
        (Some(params), _) => Some(average_images(&deeps, params)?),
    };
    Ok((mean, deep, stats))
}

/// Each instance's coverage of the frame `request` asks for of `scene` seen through `views`
/// (one plane per instance of `scene`, in its order): the share of every pixel's opacity its
/// samples and fragments hold, summing to the pixel's alpha, integrated over the shutter and
/// the aperture as the frame's colour is ([`render_views`], at the request's quality,
/// views and window; a window's coverage is the whole frame's, bit for bit). Rendered with
/// the instances in indicator colours, three at a time (red, green, blue; the rest black;
/// [`LoadedScene::with_indicator_colours`]), colour as trained: an instance's colour channel
/// is then its share of the pixel's opacity.
pub fn coverage_of_views(
    scene: &LoadedScene,
    views: &dyn FrameViews,
    request: &FrameRequest,
) -> Result<Vec<Plane>> {
    let request = request.for_coverage();
    let count = scene.desc().instances.len();
    let mut coverage = Vec::with_capacity(count);
    for first in (0..count).step_by(3) {
        let colours: Vec<glam::Vec3> = (0..count)
            .map(|i| match i.checked_sub(first) {
                Some(k @ 0..=2) => glam::Vec3::AXES[k],
                _ => glam::Vec3::ZERO,
            })
            .collect();
        let lit = scene.with_indicator_colours(&colours)?;
        let Some(rgb) = render_views(&lit, views, &request, &|_| {})?.0.rgb else {
            return Err(Error::invalid("coverage", "the render has no colour"));
        };
        coverage.extend(rgb.into_iter().take(count - first));
    }
    Ok(coverage)
}

/// A frame of a shot as the shot itself gives it: its camera at each time, object-bound
/// instances placed by its object matrices.
struct ShotViews<'a> {
    shot: &'a Shot,
    frame: i64,
    /// Whether the frame has no shutter to sample: its views are then the shot's own frame,
    /// not one interpolated to it.
    still: bool,
}

impl<'a> ShotViews<'a> {
    fn new(shot: &'a Shot, frame: i64, request: &FrameRequest) -> Self {
        let still = shot
            .motion_blur
            .is_none_or(|blur| blur.times(frame as f64, request.shutter_samples).len() == 1);
        ShotViews { shot, frame, still }
    }
}

impl FrameViews for ShotViews<'_> {
    fn shot(&self) -> &Shot {
        self.shot
    }

    fn time(&self) -> f64 {
        self.frame as f64
    }

    fn frame_at(&self, t: f64) -> Result<ShotFrame> {
        if self.still {
            return self.shot.frame(self.frame).cloned();
        }
        self.shot.frame_at(t).map_err(|e| {
            Error::invalid(
                format!("frame {}: motion blur", self.frame),
                format!("the shutter needs the shot at frame {t}: {e}"),
            )
        })
    }

    fn place(&self, scene: &LoadedScene, at: &ShotFrame) -> Result<(Scene, Camera)> {
        let camera = at.camera(self.shot)?;
        let placed = scene.place(at.world_from_scene(self.shot)?, &|name| {
            at.object_matrix(name)
        })?;
        Ok((placed, camera))
    }
}

/// Renders `frame` of `shot` as `request` asks ([`render_views`]): the shot's camera at that
/// frame, object-bound instances placed by the shot's object matrices at that frame. With the
/// shot's motion blur on, the frame is the mean of renders at the request's shutter samples,
/// stratified times over the shutter, camera and objects interpolated between the shot's
/// frames ([`Shot::frame_at`]: the shot must hold the frames around the shutter interval); a
/// closed shutter or one sample renders the frame itself. With the camera's depth of field
/// on, each time is the mean of renders through the request's aperture samples
/// ([`ShotFrame::through_aperture`]); depth of field off, or one aperture sample, is the
/// pinhole render, bit for bit. A window's pixels are the whole frame's, bit for bit, so
/// windows rendered apart (on several machines) join into the whole frame.
pub fn render_frame(
    scene: &LoadedScene,
    shot: &Shot,
    frame: i64,
    request: &FrameRequest,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, Option<DeepImage>, RenderStats)> {
    let request = match request.window {
        Some(_) => *request,
        None => request.with_window(shot.frame(frame)?.camera(shot)?.full_window())?,
    };
    render_views(
        scene,
        &ShotViews::new(shot, frame, &request),
        &request,
        on_tile,
    )
}

/// Each instance's coverage of `frame` of `shot` as [`render_frame`] renders it
/// ([`coverage_of_views`]).
pub fn render_coverage(
    scene: &LoadedScene,
    shot: &Shot,
    frame: i64,
    request: &FrameRequest,
) -> Result<Vec<Plane>> {
    let request = match request.window {
        Some(_) => *request,
        None => request.with_window(shot.frame(frame)?.camera(shot)?.full_window())?,
    };
    coverage_of_views(scene, &ShotViews::new(shot, frame, &request), &request)
}

/// Where an environment map is rendered from.
#[derive(Clone, Debug, PartialEq)]
pub enum EnvironmentOrigin {
    /// The origin of the shot's object of this name at the frame.
    Object(String),
    /// A world position.
    Position(DVec3),
}

/// Renders an environment map of the scene at `frame` of `shot` from `origin`: a 2:1
/// equirectangular image `height` pixels tall, laid out as Blender's World Environment
/// Texture reads it (see [`environment_camera`]), so that it relights a Blender scene as the
/// field would. Object-bound instances are placed by the shot at that frame.
pub fn render_environment(
    scene: &LoadedScene,
    shot: &Shot,
    frame: i64,
    origin: &EnvironmentOrigin,
    height: u32,
    settings: &RenderSettings,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, RenderStats)> {
    let at = shot.frame(frame)?;
    let position = match origin {
        EnvironmentOrigin::Object(name) => at.object_matrix(name)?.w_axis.truncate(),
        EnvironmentOrigin::Position(p) => *p,
    };
    let camera = environment_camera(position, height)?;
    let placed = scene.place(at.world_from_scene(shot)?, &|name| at.object_matrix(name))?;
    render_with_progress(&placed, &camera, camera.full_window(), settings, on_tile)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{MotionBlur, ShutterPosition};
    use crate::render::{Outputs, Quality};

    #[test]
    fn a_closed_shutter_renders_the_frame_itself_bit_for_bit() {
        let scene = crate::demo::scene_desc().load().unwrap();
        let mut shot = crate::demo::shot(32, 18);
        let draft =
            |outputs| FrameRequest::new(RenderSettings::new(Quality::Draft.params(), outputs));
        let settings = draft(Outputs::all()).with_shutter_samples(16).unwrap();
        let frame = crate::demo::FIRST_FRAME + 3;
        let sharp = render_frame(&scene, &shot, frame, &settings, &|_| {})
            .unwrap()
            .0;
        shot.motion_blur = Some(MotionBlur {
            shutter: 0.0,
            position: ShutterPosition::Center,
        });
        let closed = render_frame(&scene, &shot, frame, &settings, &|_| {})
            .unwrap()
            .0;
        assert_eq!(sharp, closed);
        // An open shutter blurs; one sample is the frame again.
        shot.motion_blur = Some(MotionBlur {
            shutter: 1.0,
            position: ShutterPosition::Center,
        });
        let blurred = render_frame(&scene, &shot, frame, &settings, &|_| {})
            .unwrap()
            .0;
        assert_ne!(sharp, blurred);
        let one = settings.with_shutter_samples(1).unwrap();
        assert_eq!(
            sharp,
            render_frame(&scene, &shot, frame, &one, &|_| {}).unwrap().0
        );
        // A depth is the same with or without alpha asked for beside it.
        let depth_only = draft(Outputs {
            rgb: false,
            alpha: false,
            ..Outputs::all()
        })
        .with_shutter_samples(16)
        .unwrap();
        let depths = render_frame(&scene, &shot, frame, &depth_only, &|_| {})
            .unwrap()
            .0;
        assert!(depths.alpha.is_none() && depths.rgb.is_none());
        assert_eq!(depths.depth_z, blurred.depth_z);
        assert_eq!(depths.depth_ray, blurred.depth_ray);
        assert_eq!(depths.depth_median, blurred.depth_median);
        // The shutter must stay inside the shot.
        let first = crate::demo::FIRST_FRAME;
        let e = render_frame(&scene, &shot, first, &settings, &|_| {}).unwrap_err();
        assert!(e.to_string().contains("motion blur"), "{e}");
    }

    /// Depth of field off, or one aperture sample, is the pinhole render bit for bit; on, it
    /// blurs, and each instance's coverage still sums to the averaged alpha.
    #[test]
    fn depth_of_field_off_is_the_pinhole_bit_for_bit() {
        let scene = crate::demo::scene_desc().load().unwrap();
        let mut shot = crate::demo::shot(32, 18);
        let settings =
            FrameRequest::new(RenderSettings::new(Quality::Draft.params(), Outputs::all()))
                .with_aperture_samples(8)
                .unwrap();
        let frame = crate::demo::FIRST_FRAME + 3;
        let pinhole = render_frame(&scene, &shot, frame, &settings, &|_| {})
            .unwrap()
            .0;
        let index = shot.frames.iter().position(|f| f.frame == frame).unwrap();
        shot.frames[index].camera.dof = Some(crate::camera::DepthOfField {
            focus_distance: 0.5,
            fstop: 0.05,
            blades: 0,
            rotation: 0.0,
            ratio: 1.0,
        });
        let one = settings.with_aperture_samples(1).unwrap();
        let lens_centre = render_frame(&scene, &shot, frame, &one, &|_| {}).unwrap().0;
        assert_eq!(pinhole, lens_centre);
        let defocused = render_frame(&scene, &shot, frame, &settings, &|_| {})
            .unwrap()
            .0;
        assert_ne!(pinhole, defocused);
        let window = Window::new(0, 0, pinhole.width, pinhole.height);
        let coverage =
            render_coverage(&scene, &shot, frame, &settings.with_window(window).unwrap()).unwrap();
        let alpha = defocused.alpha.as_ref().unwrap();
        for (i, a) in alpha.data.iter().enumerate() {
            let sum: f32 = coverage.iter().map(|p| p.data[i]).sum();
            assert!((sum - a).abs() < 1e-4, "pixel {i}: {sum} vs {a}");
        }
    }
}
