//! The built bundle driven through the strict host, through the C ABI only: every node
//! described in every context as the registry says, every node rendering the very pixels the
//! core renders directly (odd tiles, render scales 1, ½ and ¼, many threads at once), and bad
//! input failing with a status and a message while the host keeps going.

mod common_ofx;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use nerfx::demo;
use nerfx::graph::{node, nodes, Context, ParamKind, Range, RenderRequest, Value};
use nerfx::host::{Bundle, ClipSource, Instance, PropValue};
use nerfx::image::{Plane, Planes, Window};

fn bundle() -> &'static Bundle {
    static BUNDLE: OnceLock<Bundle> = OnceLock::new();
    BUNDLE.get_or_init(|| Bundle::load(&common_ofx::bundle()).expect("the built bundle loads"))
}

/// The demo's inputs (scenes, shot, graph) at 45×27, written once per test binary.
fn demo_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("nerfx-ofx-nodes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        demo::write_graph(&dir, 45, 27).unwrap();
        dir
    })
}

fn text(s: impl AsRef<Path>) -> Value {
    Value::Text(s.as_ref().to_string_lossy().into_owned())
}

fn side(n: u32, scale: f64) -> u32 {
    ((f64::from(n) * scale).ceil() as u32).max(1)
}

/// Odd-sized tiles (7×5) covering `w × h`.
fn tiles(w: u32, h: u32) -> Vec<Window> {
    let mut out = Vec::new();
    for y in (0..h).step_by(5) {
        for x in (0..w).step_by(7) {
            out.push(Window::new(x, y, (x + 7).min(w), (y + 5).min(h)));
        }
    }
    out
}

/// `tile` pasted into `into` (both with RGBA planes).
fn paste(into: &mut Planes, tile: &Planes, at: Window) {
    let copy = |dst: &mut Plane, src: &Plane| {
        for y in 0..at.height() {
            for x in 0..at.width() {
                let d = ((at.y0 + y) * dst.width + at.x0 + x) as usize;
                dst.data[d] = src.data[(y * src.width + x) as usize];
            }
        }
    };
    for c in 0..3 {
        copy(
            &mut into.rgb.as_mut().unwrap()[c],
            &tile.rgb.as_ref().unwrap()[c],
        );
    }
    copy(into.alpha.as_mut().unwrap(), tile.alpha.as_ref().unwrap());
}

fn rgba(w: u32, h: u32, f: impl Fn(u32, u32, usize) -> f32) -> Planes {
    let plane = |c: usize| Plane {
        width: w,
        height: h,
        data: (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y, c))
            .collect(),
    };
    Planes {
        width: w,
        height: h,
        rgb: Some([plane(0), plane(1), plane(2)]),
        alpha: Some(plane(3)),
        depth_z: None,
        depth_ray: None,
        depth_median: None,
    }
}

/// The RGBA part of `p` (the host carries RGBA only).
fn rgba_of(p: &Planes) -> Planes {
    Planes {
        depth_z: None,
        depth_ray: None,
        depth_median: None,
        ..p.clone()
    }
}

/// Renders every tile through `instance` and assembles the image.
fn render_tiled(instance: &Instance, time: f64, w: u32, h: u32, scale: f64) -> Planes {
    let mut image = rgba(w, h, |_, _, _| f32::NAN);
    for tile in tiles(w, h) {
        let got = instance
            .render(time, tile, scale, false)
            .unwrap_or_else(|e| panic!("tile {tile:?} at scale {scale}: {e}"));
        assert_eq!((got.width, got.height), (tile.width(), tile.height()));
        paste(&mut image, &got, tile);
    }
    image
}

fn assert_same(got: &Planes, want: &Planes, what: &str) {
    assert_eq!((got.width, got.height), (want.width, want.height), "{what}");
    let planes = |p: &Planes| {
        let [r, g, b] = p.rgb.clone().unwrap();
        [r, g, b, p.alpha.clone().unwrap()]
    };
    for (c, (g, w)) in planes(got).iter().zip(planes(want).iter()).enumerate() {
        let differ = g
            .data
            .iter()
            .zip(&w.data)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(differ, 0, "{what}: {differ} samples of channel {c} differ");
    }
}

fn ofx_type(kind: &ParamKind) -> &'static str {
    match kind {
        ParamKind::Double { .. } => "OfxParamTypeDouble",
        ParamKind::Int { .. } => "OfxParamTypeInteger",
        ParamKind::Bool { .. } => "OfxParamTypeBoolean",
        ParamKind::Choice { .. } => "OfxParamTypeChoice",
        ParamKind::File | ParamKind::Text { .. } | ParamKind::Matrix { .. } => "OfxParamTypeString",
        ParamKind::Rgb { .. } => "OfxParamTypeRGB",
        ParamKind::Rgba { .. } => "OfxParamTypeRGBA",
        ParamKind::Double3 { .. } => "OfxParamTypeDouble3D",
    }
}

#[test]
fn every_node_is_described_in_every_context_as_the_registry_says() {
    let b = bundle();
    let mut ids = b.plugin_ids();
    ids.sort();
    let mut want: Vec<String> = nodes().iter().map(|n| n.desc.id.to_string()).collect();
    want.sort();
    assert_eq!(ids, want);
    for n in nodes() {
        let desc = &n.desc;
        for &context in desc.contexts {
            let d = b
                .describe(desc.id, context)
                .unwrap_or_else(|e| panic!("{} in {context:?}: {e}", desc.id));
            let what = format!("{} in {context:?}", desc.id);
            assert_eq!(d.label, desc.label, "{what}");
            assert_eq!(d.grouping, "NeRF", "{what}");
            let mut contexts = d.contexts.clone();
            contexts.sort_by_key(|c| format!("{c:?}"));
            let mut expected = desc.contexts.to_vec();
            expected.sort_by_key(|c| format!("{c:?}"));
            assert_eq!(contexts, expected, "{what}");
            assert!(d.supports_tiles && d.supports_multi_resolution, "{what}");
            assert_eq!(d.thread_safety, "OfxImageEffectRenderFullySafe", "{what}");
            assert_eq!(d.pixel_depths, ["OfxBitDepthFloat"], "{what}");

            let mut clips: Vec<(String, bool)> = d
                .clips
                .iter()
                .map(|c| (c.name.clone(), c.optional))
                .collect();
            clips.sort();
            let mut expected: Vec<(String, bool)> = desc
                .clips
                .iter()
                .filter(|c| c.contexts.contains(&context))
                .map(|c| (c.name.to_string(), c.optional))
                .chain([("Output".to_string(), false)])
                .collect();
            expected.sort();
            assert_eq!(clips, expected, "{what}: clips");
            assert!(d
                .clips
                .iter()
                .all(|c| c.components.contains(&"OfxImageComponentRGBA".to_string())));

            for p in &desc.params {
                let got = d
                    .params
                    .iter()
                    .find(|q| q.name == p.name)
                    .unwrap_or_else(|| panic!("{what}: parameter {} not declared", p.name));
                let what = format!("{what}: parameter {}", p.name);
                assert_eq!(got.param_type, ofx_type(&p.kind), "{what}");
                assert_eq!(got.label, p.label, "{what}");
                // The hint may add how the value is typed (a matrix as text).
                assert!(got.hint.starts_with(p.hint), "{what}: hint {:?}", got.hint);
                let range = |r: &Range, n: usize| {
                    (
                        Some(vec![r.min; n]),
                        Some(vec![r.max; n]),
                        Some(vec![r.display_min; n]),
                        Some(vec![r.display_max; n]),
                    )
                };
                let got_range = (
                    got.min.clone(),
                    got.max.clone(),
                    got.display_min.clone(),
                    got.display_max.clone(),
                );
                match &p.kind {
                    ParamKind::Double { default, range: r } => {
                        assert_eq!(got.default, PropValue::Double(vec![*default]), "{what}");
                        assert_eq!(got_range, range(r, 1), "{what}");
                    }
                    ParamKind::Int { default, range: r } => {
                        assert_eq!(got.default, PropValue::Int(vec![*default as i32]), "{what}");
                        assert_eq!(got_range, range(r, 1), "{what}");
                    }
                    ParamKind::Bool { default } => {
                        assert_eq!(
                            got.default,
                            PropValue::Int(vec![i32::from(*default)]),
                            "{what}"
                        )
                    }
                    ParamKind::Choice { options, default } => {
                        assert_eq!(got.default, PropValue::Int(vec![*default as i32]), "{what}");
                        let labels: Vec<&str> = options.iter().map(|o| o.1).collect();
                        assert_eq!(got.choice_options, labels, "{what}");
                    }
                    ParamKind::File => {
                        assert_eq!(
                            got.string_mode.as_deref(),
                            Some("OfxParamStringIsFilePath"),
                            "{what}"
                        );
                        assert!(!got.animates, "{what}: a file does not animate");
                    }
                    ParamKind::Rgb { default, range: r }
                    | ParamKind::Double3 { default, range: r } => {
                        assert_eq!(got.default, PropValue::Double(default.to_vec()), "{what}");
                        assert_eq!(got_range, range(r, 3), "{what}");
                    }
                    ParamKind::Rgba { default, range: r } => {
                        assert_eq!(got.default, PropValue::Double(default.to_vec()), "{what}");
                        assert_eq!(got_range, range(r, 4), "{what}");
                    }
                    ParamKind::Text { .. } | ParamKind::Matrix { .. } => {}
                }
                if !matches!(p.kind, ParamKind::File) {
                    assert_eq!(got.animates, p.animates, "{what}");
                }
            }
        }
        // A context the node does not declare is refused.
        for context in [Context::Generator, Context::Filter, Context::General] {
            if !desc.contexts.contains(&context) {
                assert!(
                    b.describe(desc.id, context).is_err(),
                    "{} in {context:?}",
                    desc.id
                );
            }
        }
    }
    assert_eq!(b.violations(), Vec::<String>::new());
}

/// A NeRF Render instance over the demo environment with `output` (choice index) at draft
/// quality (the pixels compared are the same at any preset; draft keeps the test short).
fn nerf_instance(
    context: Context,
    scene: &str,
    output: usize,
) -> (Instance, nerfx::graph::ParamValues) {
    let dir = demo_dir();
    let n = node("org.nerfx.NeRFRender").unwrap();
    let mut values = n.defaults();
    let set = [
        ("file", text(dir.join(scene))),
        ("shot", text(dir.join("demo_shot.json"))),
        ("output", Value::Choice(output)),
        ("quality", Value::Choice(0)),
        ("exposure", Value::Double(0.5)),
    ];
    let mut instance = bundle().instance(n.desc.id, context).unwrap();
    for (name, value) in set {
        values.set(name, value.clone()).unwrap();
        instance.set_param(name, &value).unwrap();
    }
    (instance, values)
}

#[test]
fn nerf_render_tiles_at_every_scale_equal_the_core() {
    let n = node("org.nerfx.NeRFRender").unwrap();
    for (scene, output) in [
        ("demo_environment.json", 0),
        ("demo_object.json", 1),
        ("demo_object.json", 2),
    ] {
        let (instance, values) = nerf_instance(Context::Generator, scene, output);
        assert_eq!(instance.region_of_definition(1005.0).unwrap(), (45, 27));
        for scale in [1.0, 0.5, 0.25] {
            let (w, h) = (side(45, scale), side(27, scale));
            let want = n
                .render(
                    &values,
                    &RenderRequest::new(1005.0, Window::new(0, 0, w, h), scale),
                )
                .unwrap();
            let got = render_tiled(&instance, 1005.0, w, h, scale);
            assert_same(
                &got,
                &rgba_of(&want),
                &format!("{scene} output {output} scale {scale}"),
            );
        }
    }
    assert_eq!(bundle().violations(), Vec::<String>::new());
}

/// A deterministic premultiplied image, different per clip and per render scale (a stand-in
/// for an upstream node that honours the render scale).
fn pattern(seed: u32, window: Window, scale: f64) -> Planes {
    let s = (scale * 8.0) as u32;
    rgba(window.width(), window.height(), |x, y, c| {
        let (x, y) = (x + window.x0, y + window.y0);
        let h = (x.wrapping_mul(73_856_093)
            ^ y.wrapping_mul(19_349_663)
            ^ (seed + s + c as u32).wrapping_mul(83_492_791))
            % 1000;
        let v = h as f32 / 1000.0;
        if c == 3 {
            v
        } else {
            v * (0.2 + 0.8 * v) + seed as f32 * 0.5
        }
    })
}

/// A compositing node to test: identifier, context, connected clips, parameter values.
type Case<'a> = (&'a str, Context, &'a [&'a str], &'a [(&'a str, Value)]);

#[test]
fn compositing_nodes_through_the_host_equal_the_core() {
    let (w, h) = (23, 17);
    let cases: [Case; 4] = [
        (
            "org.nerfx.AccumulationMatte",
            Context::Filter,
            &["Source"],
            &[
                ("gamma", Value::Double(1.7)),
                ("floaterClip", Value::Double(0.1)),
            ],
        ),
        (
            "org.nerfx.AccumulationMatte",
            Context::General,
            &["Source", "Matte"],
            &[
                ("blackPoint", Value::Double(0.2)),
                ("mix", Value::Double(0.6)),
            ],
        ),
        (
            "org.nerfx.ShadowCatcherMerge",
            Context::General,
            &["A", "Shadow", "B"],
            &[
                ("opacity", Value::Double(0.7)),
                ("tint", Value::Doubles(vec![0.1, 0.2, 0.3])),
            ],
        ),
        (
            "org.nerfx.DepthMerge",
            Context::General,
            &["A", "ADepth", "B", "BDepth"],
            &[("softness", Value::Double(0.3))],
        ),
    ];
    for (id, context, clips, params) in cases {
        let n = node(id).unwrap();
        let mut values = n.defaults();
        let mut instance = bundle().instance(id, context).unwrap();
        for (name, value) in params {
            values.set(name, value.clone()).unwrap();
            instance.set_param(name, value).unwrap();
        }
        for (seed, clip) in clips.iter().enumerate() {
            let source = ClipSource::new((w, h), move |_, window, scale| {
                Ok(pattern(seed as u32, window, scale))
            });
            instance.connect(clip, source).unwrap();
        }
        for scale in [1.0, 0.5, 0.25] {
            let (sw, sh) = (side(w, scale), side(h, scale));
            let full = Window::new(0, 0, sw, sh);
            let mut request = RenderRequest::new(3.0, full, scale);
            for (seed, clip) in clips.iter().enumerate() {
                request = request.with_input(clip, pattern(seed as u32, full, scale));
            }
            let want = n.render(&values, &request).unwrap();
            let got = render_tiled(&instance, 3.0, sw, sh, scale);
            assert_same(
                &got,
                &rgba_of(&want),
                &format!("{id} in {context:?} at scale {scale}"),
            );
        }
        // mix = 0 passes the input through.
        instance.set_param("mix", &Value::Double(0.0)).unwrap();
        let through = instance
            .is_identity(3.0, Window::new(0, 0, w, h), 1.0)
            .unwrap();
        let expected = n.identity(&{
            let mut v = values.clone();
            v.set("mix", Value::Double(0.0)).unwrap();
            v
        });
        assert_eq!(through.as_deref(), expected.unwrap(), "{id}");
        assert!(through.is_some(), "{id}: mix 0 is an identity");
    }
    assert_eq!(bundle().violations(), Vec::<String>::new());
}

#[test]
fn concurrent_renders_on_many_threads_give_the_same_pixels() {
    let (instance, values) = nerf_instance(Context::Generator, "demo_environment.json", 0);
    let (w, h) = (45, 27);
    let want = node("org.nerfx.NeRFRender")
        .unwrap()
        .render(
            &values,
            &RenderRequest::new(1010.0, Window::new(0, 0, w, h), 1.0),
        )
        .unwrap();
    let tiles = tiles(w, h);
    for _round in 0..3 {
        let results: Vec<(Window, Planes)> = std::thread::scope(|s| {
            let handles: Vec<_> = tiles
                .chunks(tiles.len().div_ceil(8))
                .map(|chunk| {
                    let instance = &instance;
                    s.spawn(move || {
                        chunk
                            .iter()
                            .map(|&t| (t, instance.render(1010.0, t, 1.0, false).unwrap()))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap())
                .collect()
        });
        let mut image = rgba(w, h, |_, _, _| f32::NAN);
        for (t, p) in &results {
            paste(&mut image, p, *t);
        }
        assert_same(&image, &rgba_of(&want), "8 threads");
    }
    assert_eq!(bundle().violations(), Vec::<String>::new());
}

/// A NeRF Render whose render must fail with a message containing `needle`.
fn must_fail(instance: &Instance, needle: &str) {
    let window = Window::new(0, 0, 8, 8);
    let e = instance
        .render(1001.0, window, 1.0, false)
        .expect_err("the render fails")
        .to_string();
    assert!(e.contains(needle), "{needle:?} not in {e}");
    let posted = bundle()
        .messages()
        .iter()
        .any(|m| m.kind == "OfxMessageError" && m.text.contains(needle));
    assert!(posted, "no error message containing {needle:?} was posted");
}

#[test]
fn bad_input_fails_with_a_status_and_a_message_and_the_host_goes_on() {
    let dir = demo_dir();
    // A missing field file.
    let (mut i, _) = nerf_instance(Context::Generator, "demo_environment.json", 0);
    i.set_param("file", &text(dir.join("no_such_field.json")))
        .unwrap();
    must_fail(&i, "no_such_field.json");

    // A corrupt shot file.
    let corrupt = dir.join("corrupt_shot.json");
    std::fs::write(&corrupt, "{\"fps\": 24, \"frames\": [").unwrap();
    let (mut i, _) = nerf_instance(Context::Generator, "demo_environment.json", 0);
    i.set_param("shot", &text(&corrupt)).unwrap();
    must_fail(&i, "corrupt_shot.json");
    assert!(i.region_of_definition(1001.0).is_err());

    // A NaN transform override.
    let (mut i, _) = nerf_instance(Context::Generator, "demo_object.json", 0);
    i.set_param("overrideTransform", &Value::Bool(true))
        .unwrap();
    let nan = "nan 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1";
    i.set_param("objectTransform", &Value::Text(nan.into()))
        .unwrap();
    must_fail(&i, "objectTransform");

    // An absurd resolution.
    let shot = std::fs::read_to_string(dir.join("demo_shot.json")).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&shot).unwrap();
    json["resolution_x"] = 100_000.into();
    json["resolution_y"] = 100_000.into();
    let huge = dir.join("huge_shot.json");
    std::fs::write(&huge, json.to_string()).unwrap();
    let (mut i, _) = nerf_instance(Context::Generator, "demo_environment.json", 0);
    i.set_param("shot", &text(&huge)).unwrap();
    must_fail(&i, "100000");

    // The host and the plugin carry on: a good render still works.
    let (i, _) = nerf_instance(Context::Generator, "demo_environment.json", 0);
    let ok = i
        .render(1001.0, Window::new(0, 0, 8, 8), 1.0, false)
        .unwrap();
    assert_eq!((ok.width, ok.height), (8, 8));
    assert_eq!(bundle().violations(), Vec::<String>::new());
}

#[test]
fn a_changed_field_file_is_read_again_and_caches_purge() {
    let dir = demo_dir();
    let file = dir.join("changing_scene.json");
    std::fs::copy(dir.join("demo_environment.json"), &file).unwrap();
    let (mut instance, _) = nerf_instance(Context::Generator, "demo_environment.json", 0);
    instance.set_param("file", &text(&file)).unwrap();
    let window = Window::new(0, 0, 45, 27);
    let before = instance.render(1001.0, window, 1.0, false).unwrap();
    // Another scene under the same path (a different size, so the cache key changes even
    // within the file system's mtime resolution).
    std::fs::copy(dir.join("demo_object.json"), &file).unwrap();
    let after = instance.render(1001.0, window, 1.0, false).unwrap();
    assert_ne!(before, after, "the changed file was not read again");
    let (object, _) = nerf_instance(Context::Generator, "demo_object.json", 0);
    assert_same(
        &after,
        &object.render(1001.0, window, 1.0, false).unwrap(),
        "reloaded",
    );
    instance.purge_caches().unwrap();
    let purged = instance.render(1001.0, window, 1.0, false).unwrap();
    assert_same(&purged, &after, "after purgeCaches");
    assert_eq!(bundle().violations(), Vec::<String>::new());
}
