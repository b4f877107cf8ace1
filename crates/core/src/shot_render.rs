//! The shot renderer: one frame of a scene through a shot, the mean over its views (shutter
//! times and lens points), its Cryptomatte coverage and deep image; or an environment map of
//! it from a point.

use glam::DVec3;

use crate::camera::{environment_camera, Shot, ShotFrame};
use crate::composite::shutter_average;
use crate::error::{Error, Result};
use crate::image::{DeepImage, Planes, Window};
use crate::render::{
    average_images, render_deep, render_with_progress, DeepParams, Outputs, RenderSettings,
    RenderStats,
};
use crate::scene::LoadedScene;

/// Each instance's coverage of the pixels `window` of frame `frame` (one plane per instance
/// of `scene`, in its order): the share of every pixel's opacity its samples and fragments
/// hold, summing to the pixel's alpha, integrated over the shutter and the aperture as the
/// frame's colour is. Rendered with the instances in indicator colours, three at a time
/// ([`LoadedScene::with_indicator_colours`]), at `settings`' quality, as
/// [`render_frame_window`] renders: a window's coverage is the whole frame's, bit for bit.
pub fn render_coverage(
    scene: &LoadedScene,
    shot: &Shot,
    frame: i64,
    window: Window,
    settings: &RenderSettings,
) -> Result<Vec<crate::image::Plane>> {
    let settings = RenderSettings {
        outputs: Outputs {
            rgb: true,
            alpha: true,
            depth_z: false,
            depth_ray: false,
            depth_median: false,
        },
        color: crate::render::ColorOutput::AsTrained,
        ..*settings
    };
    coverage_by_indicators(scene, &mut |lit| {
        Ok(render_frame_window(lit, shot, frame, window, &settings, &|_| {})?.0)
    })
}

/// Each instance's coverage from renders of `scene` recoloured to indicator colours, three
/// instances a render (red, green, blue; the rest black), by `render`, which must render
/// colour as trained (no conversion) and alpha: an instance's colour channel is then the
/// share of the pixel's opacity its samples and fragments hold. One plane per instance, in
/// the scene's order.
pub fn coverage_by_indicators(
    scene: &LoadedScene,
    render: &mut dyn FnMut(&LoadedScene) -> Result<Planes>,
) -> Result<Vec<crate::image::Plane>> {
    let count = scene.desc().instances.len();
    let mut coverage = Vec::with_capacity(count);
    for first in (0..count).step_by(3) {
        let colours: Vec<glam::Vec3> = (0..count)
            .map(|i| match i.checked_sub(first) {
                Some(k @ 0..=2) => glam::Vec3::AXES[k],
                _ => glam::Vec3::ZERO,
            })
            .collect();
        let Some(rgb) = render(&scene.with_indicator_colours(&colours)?)?.rgb else {
            return Err(Error::invalid("coverage", "the render has no colour"));
        };
        coverage.extend(rgb.into_iter().take(count - first));
    }
    Ok(coverage)
}

/// Renders `frame` of `shot`: the shot's camera at that frame, object-bound instances placed
/// by the shot's object matrices at that frame. With the shot's motion blur on, the frame is
/// the [`shutter_average`] of renders at `settings.shutter_samples` stratified times over the
/// shutter, camera and objects interpolated between the shot's frames ([`Shot::frame_at`]:
/// the shot must hold the frames around the shutter interval); a closed shutter or one
/// sample renders the frame itself. With the camera's depth of field on, each time is the
/// mean of renders through `settings.aperture_samples` stratified points of the aperture
/// ([`ShotFrame::through_aperture`]: shutter × aperture, the product of both patterns); depth
/// of field off, or one aperture sample, is the pinhole render, bit for bit. The average
/// weighs each sample's depths by its alpha, so depths asked for without alpha are averaged
/// with it all the same (and it is dropped after): a depth pass is the same number whichever
/// passes come with it.
pub fn render_frame(
    scene: &LoadedScene,
    shot: &Shot,
    frame: i64,
    settings: &RenderSettings,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, RenderStats)> {
    let window = shot.frame(frame)?.camera(shot)?.full_window();
    render_frame_window(scene, shot, frame, window, settings, on_tile)
}

/// The views a frame at shot time `time` is the mean of, grouped by shutter time: with the
/// shot's motion blur, its `shutter_samples` stratified times over the shutter
/// ([`MotionBlur::times`](crate::camera::MotionBlur::times); `time` itself with a closed
/// shutter, one sample or no motion blur); at each time, the camera through
/// `aperture_samples` stratified points of its aperture where it has depth of field
/// ([`ShotFrame::through_aperture`]; that frame alone otherwise). `frame_at` gives the shot's
/// frame at a time. Every group holds as many views. The command line, the NeRF Render node
/// and graphs all render a frame as the mean over these views ([`mean_over_views`]).
pub fn frame_views(
    shot: &Shot,
    time: f64,
    shutter_samples: u32,
    aperture_samples: u32,
    frame_at: &dyn Fn(f64) -> Result<ShotFrame>,
) -> Result<Vec<Vec<ShotFrame>>> {
    let times = shot
        .motion_blur
        .map_or_else(|| vec![time], |blur| blur.times(time, shutter_samples));
    times
        .into_iter()
        .map(|t| Ok(frame_at(t)?.through_aperture(aperture_samples)))
        .collect()
}

/// The mean of `render` over `views` ([`frame_views`]): each shutter time's views averaged,
/// then the times ([`shutter_average`]: alpha-weighted depths, so with equal groups this is
/// the mean over every view, holding one time's renders at once rather than all of them); a
/// lone render is returned as it is. The statistics are the renders' sum.
pub fn mean_over_views(
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

/// The views of `frame` of `shot` at `settings`' shutter and aperture samples, the shutter's
/// times interpolated between the shot's frames ([`Shot::frame_at`]: the shot must hold the
/// frames around the shutter interval).
fn views_of(shot: &Shot, frame: i64, settings: &RenderSettings) -> Result<Vec<Vec<ShotFrame>>> {
    // Without a shutter to sample, the frame is the shot's own, not one interpolated to it.
    let still = shot
        .motion_blur
        .is_none_or(|blur| blur.times(frame as f64, settings.shutter_samples).len() == 1);
    let at = |t: f64| {
        if still {
            return shot.frame(frame).cloned();
        }
        shot.frame_at(t).map_err(|e| {
            Error::invalid(
                format!("frame {frame}: motion blur"),
                format!("the shutter needs the shot at frame {t}: {e}"),
            )
        })
    };
    frame_views(
        shot,
        frame as f64,
        settings.shutter_samples,
        settings.aperture_samples,
        &at,
    )
}

/// Renders the pixels of `window` of `frame` as [`render_frame`] renders the whole frame: each
/// pixel is the whole frame's, bit for bit, so windows rendered apart (on several machines)
/// join into the whole frame.
pub fn render_frame_window(
    scene: &LoadedScene,
    shot: &Shot,
    frame: i64,
    window: Window,
    settings: &RenderSettings,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, RenderStats)> {
    let views = views_of(shot, frame, settings)?;
    let outputs = settings.outputs;
    // A mean weighs depths by alpha: it is rendered for the mean whether asked for or not.
    let depths = outputs.depth_z || outputs.depth_ray || outputs.depth_median;
    let weighed = match &views[..] {
        [one] if one.len() == 1 => *settings,
        _ => RenderSettings {
            outputs: Outputs {
                alpha: outputs.alpha || depths,
                ..outputs
            },
            ..*settings
        },
    };
    let (mut mean, stats) = mean_over_views(&views, &mut |at| {
        let camera = at.camera(shot)?;
        let placed = scene.place(at.world_from_scene(shot)?, &|name| at.object_matrix(name))?;
        render_with_progress(&placed, &camera, window, &weighed, on_tile)
    })?;
    if !outputs.alpha {
        mean.alpha = None;
    }
    Ok((mean, stats))
}

/// Renders the pixels of `window` of `frame` as [`render_frame_window`] does, and their deep
/// image ([`render_deep`]): over several views (motion blur, depth of field), the deep pixels
/// of every view averaged ([`average_images`]: cut at every depth where one of them has a
/// sample boundary, the opacity and colour each adds in a slot averaged), which flattens to
/// the averaged flat frame exactly. The settings must ask for colour and alpha.
pub fn render_frame_window_deep(
    scene: &LoadedScene,
    shot: &Shot,
    frame: i64,
    window: Window,
    settings: &RenderSettings,
    deep: &DeepParams,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Result<(Planes, DeepImage, RenderStats)> {
    let views = views_of(shot, frame, settings)?;
    let mut deeps = Vec::new();
    let (planes, stats) = mean_over_views(&views, &mut |at| {
        let camera = at.camera(shot)?;
        let placed = scene.place(at.world_from_scene(shot)?, &|name| at.object_matrix(name))?;
        let (planes, deep_image, stats) =
            render_deep(&placed, &camera, window, settings, deep, on_tile)?;
        deeps.push(deep_image);
        Ok((planes, stats))
    })?;
    let deep_image = match deeps.len() {
        1 => deeps.remove(0),
        _ => average_images(&deeps, deep)?,
    };
    Ok((planes, deep_image, stats))
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
        let settings = RenderSettings {
            shutter_samples: 16,
            ..RenderSettings::new(Quality::Draft.params(), Outputs::all())
        };
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
        let one = RenderSettings {
            shutter_samples: 1,
            ..settings
        };
        assert_eq!(
            sharp,
            render_frame(&scene, &shot, frame, &one, &|_| {}).unwrap().0
        );
        // A depth is the same with or without alpha asked for beside it.
        let depth_only = RenderSettings {
            outputs: Outputs {
                rgb: false,
                alpha: false,
                ..Outputs::all()
            },
            ..settings
        };
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
        let settings = RenderSettings {
            aperture_samples: 8,
            ..RenderSettings::new(Quality::Draft.params(), Outputs::all())
        };
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
        let one = RenderSettings {
            aperture_samples: 1,
            ..settings
        };
        let lens_centre = render_frame(&scene, &shot, frame, &one, &|_| {}).unwrap().0;
        assert_eq!(pinhole, lens_centre);
        let defocused = render_frame(&scene, &shot, frame, &settings, &|_| {})
            .unwrap()
            .0;
        assert_ne!(pinhole, defocused);
        let window = Window::new(0, 0, pinhole.width, pinhole.height);
        let coverage = render_coverage(&scene, &shot, frame, window, &settings).unwrap();
        let alpha = defocused.alpha.as_ref().unwrap();
        for (i, a) in alpha.data.iter().enumerate() {
            let sum: f32 = coverage.iter().map(|p| p.data[i]).sum();
            assert!((sum - a).abs() < 1e-4, "pixel {i}: {sum} vs {a}");
        }
    }
}
