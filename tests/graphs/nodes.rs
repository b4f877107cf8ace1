//! The node registry: descriptions are self-consistent, every node renders through the
//! registry the same pixels as the core functions called directly, render scale ½ is the
//! half-resolution image, bad values are refused naming node and parameter, and the file
//! cache reloads changed files.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use nerfx_core::camera::read_shot;
use nerfx_core::camera::Shot;
use nerfx_core::composite::{
    accumulation_matte, depth_merge, mix, rgba_planes, shadow_catcher_merge, MatteCurve, Rgba,
};
use nerfx_core::demo;
use nerfx_core::image::{Plane, Planes, Window};
use nerfx_core::render::{Outputs, Quality, RenderSettings};
use nerfx_core::scene::SceneDesc;
use nerfx_core::shot_render::{render_frame, FrameRequest};
use nerfx_graph::{
    cached_scene, node, nodes, purge_caches, Context, ParamKind, ParamValues, RenderRequest, Value,
};

use crate::rng;

/// Seeded random pixels from the tests' one generator.
struct Rng(rng::SplitMix64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(rng::SplitMix64::new(seed))
    }

    fn unit(&mut self) -> f32 {
        self.0.unit()
    }

    fn rgba(&mut self, w: u32, h: u32) -> Planes {
        let px: Vec<Rgba> = (0..w * h)
            .map(|_| {
                let a = self.unit();
                [a * self.unit(), a * self.unit(), a * self.unit(), a]
            })
            .collect();
        rgba_planes(w, h, &px).unwrap()
    }

    fn plane(&mut self, w: u32, h: u32, lo: f32, hi: f32) -> Plane {
        Plane {
            width: w,
            height: h,
            data: (0..w * h).map(|_| lo + (hi - lo) * self.unit()).collect(),
        }
    }
}

/// A scene file and a shot file of the demo, in a fresh directory.
fn demo_files(tag: &str, width: u32, height: u32) -> (PathBuf, PathBuf, PathBuf) {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-graph-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("scene.json");
    let shot = dir.join("shot.json");
    demo::scene_desc().write(&scene).unwrap();
    demo::shot(width, height).write(&shot).unwrap();
    (dir, scene, shot)
}

fn nerf_values(scene: &Path, shot: &Path) -> ParamValues {
    let mut v = node("org.nerfx.NeRFRender").unwrap().defaults();
    v.set("file", Value::Text(scene.display().to_string()))
        .unwrap();
    v.set("shot", Value::Text(shot.display().to_string()))
        .unwrap();
    v
}

fn direct(scene: &Path, shot: &Shot, frame: i64) -> Planes {
    let loaded = SceneDesc::read(scene).unwrap().load().unwrap();
    let settings = RenderSettings::new(Quality::Preview.params(), Outputs::rgba());
    render_frame(&loaded, shot, frame, &FrameRequest::new(settings), &|_| {})
        .unwrap()
        .0
}

fn same_rgba(what: &str, got: &Planes, want: &Planes) {
    assert_eq!((got.width, got.height), (want.width, want.height), "{what}");
    let (g, w) = (got.rgb.as_ref().unwrap(), want.rgb.as_ref().unwrap());
    for c in 0..3 {
        assert_eq!(g[c].data, w[c].data, "{what}: channel {c}");
    }
    assert_eq!(got.alpha, want.alpha, "{what}: alpha");
}

#[test]
fn descriptions_are_self_consistent() {
    assert_eq!(nodes().len(), 4);
    for n in nodes() {
        let d = &n.desc;
        assert!(d.id.starts_with("org.nerfx."), "{}", d.id);
        assert_eq!(d.group, "NeRF");
        assert!(!d.contexts.is_empty() && !d.label.is_empty() && !d.hint.is_empty());
        let mut clips: Vec<&str> = d.clips.iter().map(|c| c.name).collect();
        clips.sort();
        clips.dedup();
        assert_eq!(clips.len(), d.clips.len(), "{}: clip names unique", d.id);
        let mut params: Vec<&str> = d.params.iter().map(|p| p.name).collect();
        params.sort();
        params.dedup();
        assert_eq!(
            params.len(),
            d.params.len(),
            "{}: parameter names unique",
            d.id
        );
        if d.contexts.contains(&Context::Filter) {
            let source = d.clip("Source").expect("a Filter node has a Source clip");
            assert!(source.contexts.contains(&Context::Filter));
        }
        for c in &d.clips {
            assert!(
                c.contexts.iter().all(|x| d.contexts.contains(x)),
                "{}",
                c.name
            );
            assert!(!c.contexts.contains(&Context::Generator), "{}", c.name);
        }
        // Every default is accepted by the validation, and lies within its range.
        let defaults = n.defaults();
        let mut values = n.defaults();
        for p in &d.params {
            let v = defaults.get(p.name).unwrap().clone();
            values.set(p.name, v).unwrap();
            let range = match &p.kind {
                ParamKind::Double { default, range } => Some((vec![*default], range)),
                ParamKind::Int { default, range } => Some((vec![*default as f64], range)),
                ParamKind::Rgb { default, range } | ParamKind::Double3 { default, range } => {
                    Some((default.to_vec(), range))
                }
                ParamKind::Rgba { default, range } => Some((default.to_vec(), range)),
                ParamKind::Choice { options, default } => {
                    assert!(*default < options.len());
                    None
                }
                _ => None,
            };
            if let Some((defaults, r)) = range {
                assert!(r.min <= r.display_min && r.display_min < r.display_max);
                assert!(r.display_max <= r.max, "{}", p.name);
                for v in defaults {
                    assert!(r.min <= v && v <= r.max, "{}.{}", d.id, p.name);
                }
            }
        }
    }
}

#[test]
fn compositing_nodes_render_what_the_functions_give() {
    let (w, h) = (13, 7);
    let window = Window::new(0, 0, w, h);
    let mut rng = Rng::new(0x9a7_0001);
    let (a, b) = (rng.rgba(w, h), rng.rgba(w, h));

    // Accumulation Matte, with a grey accumulation image as Matte.
    let m = rng.plane(w, h, 0.0, 1.0);
    let matte_img = rgba_planes(
        w,
        h,
        &m.data.iter().map(|&v| [v, v, v, 1.0]).collect::<Vec<_>>(),
    )
    .unwrap();
    let n = node("org.nerfx.AccumulationMatte").unwrap();
    let mut v = n.defaults();
    for (name, x) in [
        ("blackPoint", 0.1),
        ("whitePoint", 0.8),
        ("gamma", 1.7),
        ("floaterClip", 0.05),
        ("mix", 0.6),
    ] {
        v.set(name, Value::Double(x)).unwrap();
    }
    let request = RenderRequest::new(1.0, window, 1.0)
        .with_input("Source", a.clone())
        .with_input("Matte", matte_img);
    let curve = MatteCurve {
        black_point: 0.1,
        white_point: 0.8,
        gamma: 1.7,
        floater_clip: 0.05,
    };
    let want = mix(&accumulation_matte(&a, &m, &curve).unwrap(), &a, 0.6).unwrap();
    same_rgba(
        "accumulation matte",
        &n.render(&v, &request).unwrap(),
        &want,
    );

    // Shadow Catcher Merge.
    let shadow = rng.rgba(w, h);
    let n = node("org.nerfx.ShadowCatcherMerge").unwrap();
    let mut v = n.defaults();
    v.set("opacity", Value::Double(0.7)).unwrap();
    v.set("tint", Value::Doubles(vec![0.2, 0.4, 0.6])).unwrap();
    let request = RenderRequest::new(1.0, window, 1.0)
        .with_input("A", a.clone())
        .with_input("Shadow", shadow.clone())
        .with_input("B", b.clone());
    let want = shadow_catcher_merge(&a, shadow.alpha.as_ref().unwrap(), &b, 0.7, [0.2, 0.4, 0.6]);
    same_rgba(
        "shadow catcher merge",
        &n.render(&v, &request).unwrap(),
        &want.unwrap(),
    );

    // Depth Merge, depths in the red channel of RGBA images.
    let (za, zb) = (rng.plane(w, h, 1.0, 2.0), rng.plane(w, h, 1.0, 2.0));
    let as_image = |z: &Plane| {
        rgba_planes(
            w,
            h,
            &z.data
                .iter()
                .map(|&v| [v, 0.0, 0.0, 1.0])
                .collect::<Vec<_>>(),
        )
        .unwrap()
    };
    let n = node("org.nerfx.DepthMerge").unwrap();
    let mut v = n.defaults();
    v.set("softness", Value::Double(0.3)).unwrap();
    let request = RenderRequest::new(1.0, window, 1.0)
        .with_input("A", a.clone())
        .with_input("ADepth", as_image(&za))
        .with_input("B", b.clone())
        .with_input("BDepth", as_image(&zb));
    let want = depth_merge(&a, &za, &b, &zb, 0.3).unwrap();
    same_rgba("depth merge", &n.render(&v, &request).unwrap(), &want);
    v.set("mix", Value::Double(0.0)).unwrap();
    assert_eq!(n.identity(&v).unwrap(), Some("B"));
}

#[test]
fn nerf_render_renders_what_the_core_renders() {
    let (dir, scene, shot_path) = demo_files("direct", 64, 36);
    let n = node("org.nerfx.NeRFRender").unwrap();
    let v = nerf_values(&scene, &shot_path);
    let frame = demo::FIRST_FRAME + 3;
    assert_eq!(
        n.region_of_definition(&v, frame as f64).unwrap(),
        Some((64, 36))
    );
    let got = n.render(
        &v,
        &RenderRequest::new(frame as f64, Window::new(0, 0, 64, 36), 1.0),
    );
    let shot = read_shot(&shot_path, "NeRF").unwrap();
    same_rgba("NeRF Render", &got.unwrap(), &direct(&scene, &shot, frame));

    // A tile is that part of the full image.
    let tile = n
        .render(
            &v,
            &RenderRequest::new(frame as f64, Window::new(10, 5, 31, 20), 1.0),
        )
        .unwrap();
    let full = direct(&scene, &shot, frame);
    let alpha = full.alpha.as_ref().unwrap();
    for y in 0..15 {
        for x in 0..21 {
            assert_eq!(
                tile.alpha.as_ref().unwrap().get(x, y),
                alpha.get(x + 10, y + 5)
            );
        }
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn render_scale_half_is_the_half_resolution_render() {
    let (dir, scene, shot_path) = demo_files("half", 64, 36);
    let n = node("org.nerfx.NeRFRender").unwrap();
    let v = nerf_values(&scene, &shot_path);
    let frame = demo::FIRST_FRAME;
    let got = n.render(
        &v,
        &RenderRequest::new(frame as f64, Window::new(0, 0, 32, 18), 0.5),
    );
    same_rgba(
        "scale ½",
        &got.unwrap(),
        &direct(&scene, &demo::shot(32, 18), frame),
    );
    // The full-size window does not fit at scale ½.
    let e = n.render(
        &v,
        &RenderRequest::new(frame as f64, Window::new(0, 0, 64, 36), 0.5),
    );
    assert!(e
        .unwrap_err()
        .to_string()
        .contains("org.nerfx.NeRFRender: render window"));
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn invalid_values_are_refused_naming_node_and_parameter() {
    let n = node("org.nerfx.AccumulationMatte").unwrap();
    let mut v = n.defaults();
    let cases = [
        ("gama", Value::Double(1.0), "no such parameter"),
        ("gamma", Value::Bool(true), "expected a double, got a bool"),
        ("gamma", Value::Double(0.0), "outside"),
        ("gamma", Value::Double(f64::NAN), "outside"),
    ];
    for (name, value, why) in cases {
        let e = v.set(name, value).unwrap_err().to_string();
        assert!(
            e.contains(&format!("org.nerfx.AccumulationMatte: parameter {name}")),
            "{e}"
        );
        assert!(e.contains(why), "{e}");
    }
    let r = node("org.nerfx.NeRFRender").unwrap();
    let mut rv = r.defaults();
    let e = rv
        .set("objectTransform", Value::Doubles(vec![1.0; 15]))
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("parameter objectTransform: expected 16 values"),
        "{e}"
    );
    let e = rv.set("output", Value::Choice(9)).unwrap_err();
    assert!(
        e.to_string()
            .contains("org.nerfx.NeRFRender: parameter output"),
        "{e}"
    );
    // Cross-parameter checks happen at render time and also name the node.
    v.set("whitePoint", Value::Double(0.0)).unwrap();
    let req = RenderRequest::new(1.0, Window::new(0, 0, 2, 2), 1.0)
        .with_input("Source", Rng::new(3).rgba(2, 2));
    let e = n.render(&v, &req).unwrap_err().to_string();
    assert!(
        e.contains("org.nerfx.AccumulationMatte") && e.contains("white point"),
        "{e}"
    );
    // No field file, values of another node, a wrongly sized input, an unknown node.
    let e = r
        .render(&rv, &RenderRequest::new(1.0, Window::new(0, 0, 2, 2), 1.0))
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("org.nerfx.NeRFRender: parameter shot"),
        "{e}"
    );
    assert!(r.render(&v, &req).is_err());
    let bad = RenderRequest::new(1.0, Window::new(0, 0, 3, 2), 1.0)
        .with_input("Source", Rng::new(3).rgba(2, 2));
    let e = n.render(&n.defaults(), &bad).unwrap_err().to_string();
    assert!(
        e.contains("org.nerfx.AccumulationMatte: clip Source"),
        "{e}"
    );
    assert!(node("org.nerfx.Blur").is_err());
}

#[test]
fn scene_cache_reloads_changed_files_and_after_purge() {
    let (dir, scene, _) = demo_files("cache", 8, 8);
    let first = cached_scene(&scene).unwrap();
    assert!(Arc::ptr_eq(&first, &cached_scene(&scene).unwrap()));
    // Same contents, new modification time: reloaded.
    let later = SystemTime::now() + Duration::from_secs(60);
    std::fs::File::options()
        .write(true)
        .open(&scene)
        .unwrap()
        .set_modified(later)
        .unwrap();
    let second = cached_scene(&scene).unwrap();
    assert!(!Arc::ptr_eq(&first, &second));
    assert!(Arc::ptr_eq(&second, &cached_scene(&scene).unwrap()));
    purge_caches();
    assert!(!Arc::ptr_eq(&second, &cached_scene(&scene).unwrap()));
    std::fs::remove_dir_all(dir).unwrap();
}

/// With the shot's motion blur, the node averages renders over the shutter exactly as
/// `nerfx render` does (its own sample count, or the quality preset's with 0), and a shot
/// without blur renders the same whatever the sample count.
#[test]
fn nerf_render_blurs_over_the_shots_shutter_as_the_command_line_does() {
    use nerfx_core::camera::{MotionBlur, ShutterPosition};
    let (dir, scene, shot_path) = demo_files("blur", 48, 27);
    let frame = demo::FIRST_FRAME + 3;
    let n = node("org.nerfx.NeRFRender").unwrap();
    let mut v = nerf_values(&scene, &shot_path);
    v.set("shutterSamples", Value::Int(5)).unwrap();
    let request = RenderRequest::new(frame as f64, Window::new(0, 0, 48, 27), 1.0);
    let sharp = n.render(&v, &request).unwrap();
    let shot = read_shot(&shot_path, "NeRF").unwrap();
    same_rgba("no blur", &sharp, &direct(&scene, &shot, frame));

    let mut blurred_shot = demo::shot(48, 27);
    blurred_shot.motion_blur = Some(MotionBlur {
        shutter: 0.8,
        position: ShutterPosition::Center,
    });
    blurred_shot.write(&shot_path).unwrap();
    let loaded = SceneDesc::read(&scene).unwrap().load().unwrap();
    let cli = |samples: u32| {
        let settings = FrameRequest::new(RenderSettings::new(
            Quality::Preview.params(),
            Outputs::rgba(),
        ))
        .with_shutter_samples(samples)
        .unwrap();
        render_frame(&loaded, &blurred_shot, frame, &settings, &|_| {})
            .unwrap()
            .0
    };
    let got = n.render(&v, &request).unwrap();
    same_rgba("5 samples", &got, &cli(5));
    assert_ne!(got.alpha, sharp.alpha, "the blur changes the image");
    v.set("shutterSamples", Value::Int(0)).unwrap();
    let preset = Quality::Preview.shutter_samples();
    same_rgba(
        "the preset's samples",
        &n.render(&v, &request).unwrap(),
        &cli(preset),
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// A render scale that leaves less than one pixel of the shot's image is refused, naming the
/// smallest scale that works; that one renders.
#[test]
fn a_render_scale_below_one_pixel_is_refused() {
    let (dir, scene, shot_path) = demo_files("tiny", 64, 36);
    let n = node("org.nerfx.NeRFRender").unwrap();
    let v = nerf_values(&scene, &shot_path);
    let frame = demo::FIRST_FRAME as f64;
    let e = n
        .render(
            &v,
            &RenderRequest::new(frame, Window::new(0, 0, 1, 1), 1e-9),
        )
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("render scale")
            && e.contains("1e-9")
            && e.contains("less than one pixel")
            && e.contains("1/36"),
        "{e}"
    );
    let smallest = 1.0 / 36.0;
    assert!(n
        .render(
            &v,
            &RenderRequest::new(frame, Window::new(0, 0, 2, 1), smallest)
        )
        .is_ok());
    std::fs::remove_dir_all(dir).unwrap();
}

/// With the shot camera's depth of field, the node averages renders over the aperture exactly
/// as `nerfx render` does (its own sample count, or the quality preset's with 0).
#[test]
fn nerf_render_defocuses_through_the_aperture_as_the_command_line_does() {
    let (dir, scene, shot_path) = demo_files("dof", 48, 27);
    let frame = demo::FIRST_FRAME + 3;
    let n = node("org.nerfx.NeRFRender").unwrap();
    let mut v = nerf_values(&scene, &shot_path);
    v.set("apertureSamples", Value::Int(6)).unwrap();
    let request = RenderRequest::new(frame as f64, Window::new(0, 0, 48, 27), 1.0);
    let sharp = n.render(&v, &request).unwrap();

    let mut shot = demo::shot(48, 27);
    for f in &mut shot.frames {
        f.camera.dof = Some(nerfx_core::camera::DepthOfField {
            focus_distance: 4.0,
            fstop: 0.1,
            blades: 6,
            rotation: 0.3,
            ratio: 1.2,
        });
    }
    shot.write(&shot_path).unwrap();
    let loaded = SceneDesc::read(&scene).unwrap().load().unwrap();
    let cli = |samples: u32| {
        let settings = FrameRequest::new(RenderSettings::new(
            Quality::Preview.params(),
            Outputs::rgba(),
        ))
        .with_aperture_samples(samples)
        .unwrap();
        render_frame(&loaded, &shot, frame, &settings, &|_| {})
            .unwrap()
            .0
    };
    let got = n.render(&v, &request).unwrap();
    same_rgba("6 samples", &got, &cli(6));
    assert_ne!(got.alpha, sharp.alpha, "the defocus changes the image");
    v.set("apertureSamples", Value::Int(0)).unwrap();
    same_rgba(
        "the preset's samples",
        &n.render(&v, &request).unwrap(),
        &cli(Quality::Preview.aperture_samples()),
    );
    std::fs::remove_dir_all(dir).unwrap();
}
