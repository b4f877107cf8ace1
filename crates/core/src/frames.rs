//! Farm-side plumbing: frame lists, output name patterns, and rendering one frame of a scene
//! through a shot, or an environment map of it from a point.

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::camera::{environment_camera, CameraPath, Shot, ShotFrame};
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

/// Most frames one `--frames` may name (a farm splits longer ranges over commands).
pub const MAX_FRAMES: usize = 1_000_000;

/// Parses a frame list: `1001`, `1001-1010`, `1001-1100x5` (every 5th; `1001-1100:5`, as Open
/// Job Description writes a step, is the same), or several of those separated by commas
/// (`1,5,10-12`). Frames come out in the order given, without repeats.
///
/// ```
/// assert_eq!(nerfx_core::frames::parse_frames("7,1-3,2").unwrap(), vec![7, 1, 2, 3]);
/// assert_eq!(nerfx_core::frames::parse_frames("10-20x5").unwrap(), vec![10, 15, 20]);
/// assert_eq!(nerfx_core::frames::parse_frames("10-20:5").unwrap(), vec![10, 15, 20]);
/// ```
pub fn parse_frames(spec: &str) -> Result<Vec<i64>> {
    let bad = |why: &str| Error::invalid(format!("frames '{spec}'"), why.to_string());
    let mut frames = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for part in spec.split(',').map(str::trim) {
        let (range, step) = match part.split_once(['x', ':']) {
            Some((r, s)) => (
                r,
                s.parse::<i64>()
                    .map_err(|_| bad("the step after 'x' or ':' is not a whole number"))?,
            ),
            None => (part, 1),
        };
        if step < 1 {
            return Err(bad("the step must be ≥ 1"));
        }
        // A '-' after the first character separates the range (the first may be a sign).
        let (first, last) = match range.get(1..).and_then(|r| r.find('-')) {
            Some(i) => (&range[..=i], &range[i + 2..]),
            None => (range, range),
        };
        let parse = |s: &str| {
            s.trim()
                .parse::<i64>()
                .map_err(|_| bad("expected frame numbers like 1001-1010"))
        };
        let (first, last) = (parse(first)?, parse(last)?);
        if last < first {
            return Err(bad("a range must not run backwards"));
        }
        // In i128: no range of i64 frames overflows it.
        let count = (i128::from(last) - i128::from(first)) / i128::from(step) + 1;
        if count > (MAX_FRAMES - frames.len()) as i128 {
            return Err(bad(&format!(
                "more than {MAX_FRAMES} frames in one command; split the range"
            )));
        }
        for k in 0..count {
            // first + k·step ≤ last, so it fits in i64.
            let f = (i128::from(first) + k * i128::from(step)) as i64;
            if seen.insert(f) {
                frames.push(f);
            }
        }
    }
    Ok(frames)
}

/// The output path for `frame`: the last run of `#` in `pattern` becomes the frame number,
/// zero-padded to the run's length (`out/comp.####.exr` → `out/comp.1001.exr`). A pattern
/// without `#` gets `.<frame>` before its extension when several frames are rendered.
///
/// ```
/// use std::path::Path;
/// let p = nerfx_core::frames::frame_path(Path::new("out/comp.####.exr"), 7, true);
/// assert_eq!(p, Path::new("out/comp.0007.exr"));
/// ```
pub fn frame_path(pattern: &Path, frame: i64, several: bool) -> PathBuf {
    let text = pattern.to_string_lossy();
    if let Some(end) = text.rfind('#') {
        let start = text[..=end].trim_end_matches('#').len();
        let width = end + 1 - start;
        let number = if frame < 0 {
            format!("-{:0width$}", -frame, width = width.saturating_sub(1))
        } else {
            format!("{frame:0width$}")
        };
        return PathBuf::from(format!("{}{}{}", &text[..start], number, &text[end + 1..]));
    }
    if !several {
        return pattern.to_path_buf();
    }
    let stem = pattern
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match pattern.extension() {
        Some(ext) => format!("{stem}.{frame}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{frame}"),
    };
    pattern.with_file_name(name)
}

/// Reads a nerfx shot file, or a nerfstudio `camera_path.json` (recognised by its
/// `camera_path` key) as a shot whose frames count from 0, as `ns-render` numbers them, and
/// whose NeRF object (the scene instances bound to `nerf_object`) is placed so that the
/// field sees each frame's `camera_to_world` exactly (see [`CameraPath::to_shot`]).
pub fn read_shot(path: &Path, nerf_object: &str) -> Result<Shot> {
    let text = crate::input::read_text(path)?;
    // Python's json writes NaN and Infinity: read as null, they still leave the file's kind
    // clear, and the reader of that kind names the element that holds one.
    let is_camera_path = crate::json::parse_json::<serde_json::Value>(&text, path, "a shot")
        .is_ok_and(|v| v.get("camera_path").is_some());
    if is_camera_path {
        CameraPath::from_json_str(&text, path)?.to_shot(0, nerf_object)
    } else {
        Shot::from_json_str(&text, path)
    }
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
    fn frame_lists_at_the_ends_of_i64_end_or_are_refused() {
        let max = i64::MAX;
        assert_eq!(parse_frames(&max.to_string()).unwrap(), vec![max]);
        assert_eq!(
            parse_frames(&format!("{}-{max}", max - 2)).unwrap(),
            vec![max - 2, max - 1, max]
        );
        assert_eq!(
            parse_frames(&format!("{}", i64::MIN)).unwrap(),
            vec![i64::MIN]
        );
        // A step past the end of the range adds nothing.
        assert_eq!(
            parse_frames(&format!("1001-1003x{max}")).unwrap(),
            vec![1001]
        );
        let e = parse_frames(&format!("{}-{max}", i64::MIN))
            .unwrap_err()
            .to_string();
        assert!(e.contains("more than 1000000 frames"), "{e}");
        // The limit counts every part together, and repeats are dropped in linear time.
        assert_eq!(parse_frames("1-600000,1-300000").unwrap().len(), 600_000);
        assert!(parse_frames("1-600000,700000-1300000").is_err());
    }

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

    #[test]
    fn frame_lists() {
        assert_eq!(parse_frames("1001").unwrap(), vec![1001]);
        assert_eq!(
            parse_frames("1001-1004").unwrap(),
            vec![1001, 1002, 1003, 1004]
        );
        assert_eq!(parse_frames("-2-1").unwrap(), vec![-2, -1, 0, 1]);
        assert_eq!(parse_frames("1-10x4, 3").unwrap(), vec![1, 5, 9, 3]);
        assert_eq!(parse_frames("1-10:4").unwrap(), vec![1, 5, 9]);
        for bad in [
            "",
            "a-b",
            "5-1",
            "1-10x0",
            "1-10:x2",
            "1-2-3",
            "1-1000000000",
        ] {
            let e = parse_frames(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("'{bad}'")), "{e}");
        }
    }

    #[test]
    fn camera_paths_read_as_shots() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data");
        let path = data.join("viewer_camera_path_b.json");
        let shot = read_shot(&path, "NeRF").unwrap();
        assert_eq!(shot.frames.len(), 42);
        assert_eq!(shot.frames[0].frame, 0);
        assert!(shot.frame(0).unwrap().object_matrix("NeRF").is_ok());
        let demo = std::env::temp_dir().join(format!("nerfx-frames-{}.json", std::process::id()));
        crate::demo::shot(8, 6).write(&demo).unwrap();
        let back = read_shot(&demo, "NeRF").unwrap();
        std::fs::remove_file(&demo).ok();
        assert_eq!(back.frames.len(), crate::demo::FRAMES as usize);
    }

    #[test]
    fn frame_paths() {
        let p = |s: &str, f, several| frame_path(Path::new(s), f, several);
        assert_eq!(p("a/b.####.exr", 1001, true), Path::new("a/b.1001.exr"));
        assert_eq!(p("a/b.##.exr", 1001, true), Path::new("a/b.1001.exr"));
        assert_eq!(p("b_#.exr", -3, true), Path::new("b_-3.exr"));
        assert_eq!(p("b.exr", 12, true), Path::new("b.12.exr"));
        assert_eq!(p("b.exr", 12, false), Path::new("b.exr"));
    }
}
