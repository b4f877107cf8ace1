//! The built bundle driven through the strict host, through the C ABI only: every node
//! described in every context as the registry says, every node rendering the very pixels the
//! core renders directly (odd tiles, render scales 1, ½ and ¼, many threads at once), and bad
//! input failing with a status and a message while the host keeps going.

use std::path::Path;

use crate::common_ofx::fixtures::{instance_with, shared as bundle, text};
use crate::common_ofx::images::{assert_same, paste, pattern, render_tiled, rgba, rgba_of, tiles};
use nerfx_core::image::{scaled_size, Planes, Window};
use nerfx_graph::{node, nodes, Context, ParamKind, Range, RenderRequest, Value};
use nerfx_ofx_host::{ClipSource, Instance, PropValue};

/// The demo's inputs (scenes, shot, graph) at 45×27, written once per test binary.
fn demo_dir() -> &'static Path {
    crate::common_ofx::fixtures::demo_dir(45, 27)
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
) -> (Instance, nerfx_graph::ParamValues) {
    let dir = demo_dir();
    let set = [
        ("file", text(dir.join(scene))),
        ("shot", text(dir.join("demo_shot.json"))),
        ("output", Value::Choice(output)),
        ("quality", Value::Choice(0)),
        ("exposure", Value::Double(0.5)),
    ];
    instance_with(bundle(), "org.nerfx.NeRFRender", context, &set)
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
            let (w, h) = (scaled_size(45, scale), scaled_size(27, scale));
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
        let (mut instance, values) = instance_with(bundle(), id, context, params);
        for (seed, clip) in clips.iter().enumerate() {
            let source = ClipSource::new((w, h), move |_, window, scale| {
                Ok(pattern(seed as u32, window, scale))
            });
            instance.connect(clip, source).unwrap();
        }
        for scale in [1.0, 0.5, 0.25] {
            let (sw, sh) = (scaled_size(w, scale), scaled_size(h, scale));
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
