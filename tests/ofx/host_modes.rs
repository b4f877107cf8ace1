//! The built bundle through the host behaving as hosts in production differ
//! ([`HostOptions`]): message suite V1 only or none, RGB input images, top-down images with
//! padded bounds and rows, fields rendered one at a time, change reasons, and a second host
//! struct. In each, the plugin must render the very pixels the core renders, report errors
//! as the message suite allows, and break no rule of the strict host.
//!
//! The tests take turns ([`turn`]): the message suite is a property of the host struct the
//! binary holds, one at a time, so bundles with different hosts must not act at once.

use std::path::Path;
use std::sync::{Mutex, MutexGuard, PoisonError};

use crate::common_ofx::fixtures::{instance_with, text};
use crate::common_ofx::images::{assert_same, at, pattern, rgba, rgba_of, tiled};
use crate::common_ofx::load;
use nerfx_core::image::{scaled_size, Planes, Window};
use nerfx_graph::{node, Context, ParamValues, RenderRequest, Value};
use nerfx_ofx_host::{
    Bundle, ChangeReason, ClipSource, HostOptions, Instance, InterlacedField, MessageSuiteOffer,
};

/// The demo image size.
const W: u32 = 32;
const H: u32 = 20;
/// A frame of the demo shot.
const FRAME: f64 = 1003.0;

fn turn() -> MutexGuard<'static, ()> {
    static TURN: Mutex<()> = Mutex::new(());
    TURN.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The demo's inputs at `W × H`, written once per test binary.
fn demo_dir() -> &'static Path {
    crate::common_ofx::fixtures::demo_dir(W, H)
}

/// A NeRF Render of the demo environment at draft quality, and its values for the core.
fn nerf(bundle: &Bundle, field_file: &Path) -> (Instance, ParamValues) {
    let set = [
        ("file", text(field_file)),
        ("shot", text(demo_dir().join("demo_shot.json"))),
        ("quality", Value::Choice(0)),
        ("exposure", Value::Double(0.5)),
    ];
    instance_with(bundle, "org.nerfx.NeRFRender", Context::Generator, &set)
}

/// The core's NeRF Render of the whole image at `scale`.
fn core_nerf(values: &ParamValues, scale: f64) -> Planes {
    let (w, h) = (scaled_size(W, scale), scaled_size(H, scale));
    let p = node("org.nerfx.NeRFRender")
        .unwrap()
        .render(
            values,
            &RenderRequest::new(FRAME, Window::new(0, 0, w, h), scale),
        )
        .unwrap();
    rgba_of(&p)
}

/// A compositing node to test: identifier, context, connected clips, parameter values.
type Case = (
    &'static str,
    Context,
    &'static [&'static str],
    Vec<(&'static str, Value)>,
);

fn cases() -> Vec<Case> {
    vec![
        (
            "org.nerfx.AccumulationMatte",
            Context::General,
            &["Source", "Matte"],
            vec![
                ("blackPoint", Value::Double(0.2)),
                ("mix", Value::Double(0.6)),
            ],
        ),
        (
            "org.nerfx.ShadowCatcherMerge",
            Context::General,
            &["A", "Shadow", "B"],
            vec![
                ("opacity", Value::Double(0.7)),
                ("tint", Value::Doubles(vec![0.1, 0.2, 0.3])),
            ],
        ),
        (
            "org.nerfx.DepthMerge",
            Context::General,
            &["A", "ADepth", "B", "BDepth"],
            vec![("softness", Value::Double(0.3))],
        ),
    ]
}

/// Size of the compositing nodes' inputs.
const CW: u32 = 23;
const CH: u32 = 17;

/// An instance of `case` with its inputs connected to [`pattern`]s, and its values.
fn compositing(bundle: &Bundle, case: &Case) -> (Instance, ParamValues) {
    compositing_of(bundle, case, |p| p)
}

/// An instance of `case` with each input connected to `input` of its [`pattern`], and its
/// values.
fn compositing_of(
    bundle: &Bundle,
    case: &Case,
    input: fn(Planes) -> Planes,
) -> (Instance, ParamValues) {
    let (id, context, clips, params) = case;
    let (mut instance, values) = instance_with(bundle, id, *context, params);
    for (seed, clip) in clips.iter().enumerate() {
        let source = ClipSource::new((CW, CH), move |_, w, s| {
            Ok(input(pattern(seed as u32, w, s)))
        });
        instance.connect(clip, source).unwrap();
    }
    (instance, values)
}

/// The core's render of `case` over the whole image at `scale`, each input made by
/// `input` from its pattern.
fn core_compositing(
    case: &Case,
    values: &ParamValues,
    scale: f64,
    input: impl Fn(Planes) -> Planes,
) -> Planes {
    let full = Window::new(0, 0, scaled_size(CW, scale), scaled_size(CH, scale));
    let mut request = RenderRequest::new(3.0, full, scale);
    for (seed, clip) in case.2.iter().enumerate() {
        request = request.with_input(clip, input(pattern(seed as u32, full, scale)));
    }
    rgba_of(&node(case.0).unwrap().render(values, &request).unwrap())
}

fn no_violations(bundle: &Bundle) {
    assert_eq!(bundle.violations(), Vec::<String>::new());
}

/// The messages `bundle` recorded whose text names `needle`: (persistent, kind).
fn said(bundle: &Bundle, needle: &str) -> Vec<(bool, String)> {
    bundle
        .messages()
        .into_iter()
        .filter(|m| m.text.contains(needle))
        .map(|m| (m.persistent, m.kind))
        .collect()
}

/// A render of an 8×8 window that must fail; its error text.
fn failing_render(instance: &Instance) -> String {
    failing_render_at(instance, FRAME)
}

#[test]
fn v2_a_persistent_error_cleared_by_edits_and_renders_but_not_by_time() {
    let _turn = turn();
    let b = load(HostOptions::default());
    let missing = demo_dir().join("missing_v2.json");
    let (mut i, _) = nerf(&b, &missing);
    let e = failing_render(&i);
    assert!(e.contains("missing_v2.json"), "{e}");
    let m = i.persistent_message().expect("a persistent message is set");
    assert_eq!(m.kind, "OfxMessageError");
    assert!(m.text.contains("missing_v2.json"), "{}", m.text);
    // The time moving is no edit: the error stays.
    i.instance_changed_with_reason("exposure", ChangeReason::Time)
        .unwrap();
    assert!(i.persistent_message().is_some());
    // Edits by the plugin and by the artist clear it; the next failure sets it again.
    for reason in [ChangeReason::PluginEdited, ChangeReason::UserEdited] {
        i.instance_changed_with_reason("file", reason).unwrap();
        assert_eq!(i.persistent_message(), None, "{reason:?}");
        failing_render(&i);
        assert!(i.persistent_message().is_some(), "{reason:?}");
    }
    // Never a transient message: every one posted is persistent.
    let posted = said(&b, "missing_v2.json");
    assert!(
        posted.len() >= 3 && posted.iter().all(|(p, _)| *p),
        "{posted:?}"
    );
    // A successful render clears it.
    i.set_param("file", &text(demo_dir().join("demo_environment.json")))
        .unwrap();
    i.render(FRAME, Window::new(0, 0, 8, 8), 1.0, false)
        .unwrap();
    assert_eq!(i.persistent_message(), None);
    no_violations(&b);
}

#[test]
fn v1_one_transient_message_per_instance_until_an_edit() {
    let _turn = turn();
    let b = load(HostOptions {
        message_suite: MessageSuiteOffer::V1Only,
        ..HostOptions::default()
    });
    let missing = demo_dir().join("missing_v1.json");
    let (i, _) = nerf(&b, &missing);
    let count = || said(&b, "missing_v1.json");
    let first = failing_render(&i);
    assert!(first.contains("missing_v1.json"), "{first}");
    assert_eq!(count(), [(false, "OfxMessageError".to_string())]);
    // Later failures of the same instance go to standard error, not to another dialog.
    for _ in 0..3 {
        let e = failing_render(&i);
        assert!(e.contains("posted no message"), "{e}");
    }
    assert_eq!(count().len(), 1);
    assert_eq!(i.persistent_message(), None);
    // The time moving is no edit.
    i.instance_changed_with_reason("exposure", ChangeReason::Time)
        .unwrap();
    failing_render(&i);
    assert_eq!(count().len(), 1);
    // An edit (by the artist or by the plugin) lets one more through.
    i.instance_changed_with_reason("file", ChangeReason::UserEdited)
        .unwrap();
    failing_render(&i);
    failing_render(&i);
    assert_eq!(count().len(), 2);
    i.instance_changed_with_reason("file", ChangeReason::PluginEdited)
        .unwrap();
    failing_render(&i);
    assert_eq!(count().len(), 3);
    // Another instance has its own.
    let (other, _) = nerf(&b, &missing);
    failing_render(&other);
    failing_render(&other);
    let all = count();
    assert_eq!(all.len(), 4);
    assert!(
        all.iter().all(|(p, k)| !p && k == "OfxMessageError"),
        "{all:?}"
    );
    no_violations(&b);
}

#[test]
fn without_a_message_suite_errors_are_statuses_and_renders_still_work() {
    let _turn = turn();
    let b = load(HostOptions {
        message_suite: MessageSuiteOffer::Absent,
        ..HostOptions::default()
    });
    let missing = demo_dir().join("missing_none.json");
    let (i, _) = nerf(&b, &missing);
    for _ in 0..2 {
        let e = failing_render(&i);
        assert!(e.contains("kOfxStatFailed"), "{e}");
        assert!(e.contains("posted no message"), "{e}");
    }
    assert!(said(&b, "missing_none.json").is_empty());
    assert_eq!(i.persistent_message(), None);
    // Edits and good renders go on as usual.
    i.instance_changed_with_reason("file", ChangeReason::UserEdited)
        .unwrap();
    let (good, values) = nerf(&b, &demo_dir().join("demo_environment.json"));
    let got = tiled(W, H, |t| good.render(FRAME, t, 1.0, false).unwrap());
    assert_same(&got, &core_nerf(&values, 1.0), "no message suite");
    no_violations(&b);
}

/// `p` as the plugin sees an RGB input image: its colour with alpha 1.
fn opaque(p: Planes) -> Planes {
    rgba(p.width, p.height, |x, y, c| {
        if c == 3 {
            1.0
        } else {
            at(&p, x, y, c)
        }
    })
}

#[test]
fn rgb_input_images_read_as_opaque_rgba() {
    let _turn = turn();
    let b = load(HostOptions {
        rgb_inputs: true,
        ..HostOptions::default()
    });
    for case in cases() {
        let (instance, values) = compositing(&b, &case);
        for scale in [1.0, 0.5] {
            let (w, h) = (scaled_size(CW, scale), scaled_size(CH, scale));
            let got = tiled(w, h, |t| instance.render(3.0, t, scale, false).unwrap());
            let want = core_compositing(&case, &values, scale, opaque);
            assert_same(&got, &want, &format!("{} RGB inputs at {scale}", case.0));
        }
    }
    no_violations(&b);
}

/// `p` as a premultiplied image must be: no colour where alpha is 0 (there, straight colour
/// cannot hold it).
fn no_colour_without_alpha(p: Planes) -> Planes {
    rgba(p.width, p.height, |x, y, c| {
        if c < 3 && at(&p, x, y, 3) == 0.0 {
            0.0
        } else {
            at(&p, x, y, c)
        }
    })
}

#[test]
fn unpremultiplied_input_images_are_premultiplied_before_compositing() {
    let _turn = turn();
    let b = load(HostOptions {
        unpremultiplied_inputs: true,
        ..HostOptions::default()
    });
    for case in cases() {
        let (instance, values) = compositing_of(&b, &case, no_colour_without_alpha);
        for scale in [1.0, 0.5] {
            let (w, h) = (scaled_size(CW, scale), scaled_size(CH, scale));
            let got = tiled(w, h, |t| instance.render(3.0, t, scale, false).unwrap());
            // The core on the premultiplied source: the host divided colour by alpha, the
            // plugin multiplied it back, so only the rounding of (c / a) · a may differ.
            let want = core_compositing(&case, &values, scale, no_colour_without_alpha);
            assert_eq!((got.width, got.height), (want.width, want.height));
            let mut worst = 0.0f32;
            for c in 0..4 {
                for y in 0..h {
                    for x in 0..w {
                        let (g, v) = (at(&got, x, y, c), at(&want, x, y, c));
                        worst = worst.max((g - v).abs() / v.abs().max(1.0));
                    }
                }
            }
            assert!(
                worst <= 1e-6,
                "{} at {scale}: relative difference {worst}",
                case.0
            );
        }
    }
    no_violations(&b);
}

#[test]
fn top_down_padded_images_give_the_same_pixels() {
    let _turn = turn();
    let b = load(HostOptions {
        padded_images: true,
        ..HostOptions::default()
    });
    let (nerf_instance, values) = nerf(&b, &demo_dir().join("demo_environment.json"));
    for scale in [1.0, 0.5] {
        let (w, h) = (scaled_size(W, scale), scaled_size(H, scale));
        let got = tiled(w, h, |t| {
            nerf_instance.render(FRAME, t, scale, false).unwrap()
        });
        assert_same(
            &got,
            &core_nerf(&values, scale),
            &format!("NeRF Render at {scale}"),
        );
    }
    for case in cases() {
        let (instance, values) = compositing(&b, &case);
        for scale in [1.0, 0.5] {
            let (w, h) = (scaled_size(CW, scale), scaled_size(CH, scale));
            let got = tiled(w, h, |t| instance.render(3.0, t, scale, false).unwrap());
            let want = core_compositing(&case, &values, scale, |p| p);
            assert_same(&got, &want, &format!("{} padded at {scale}", case.0));
        }
    }
    no_violations(&b);
}

#[test]
fn padded_rgb_images_together() {
    let _turn = turn();
    let b = load(HostOptions {
        padded_images: true,
        rgb_inputs: true,
        ..HostOptions::default()
    });
    let case = &cases()[2];
    let (instance, values) = compositing(&b, case);
    let got = tiled(CW, CH, |t| instance.render(3.0, t, 1.0, false).unwrap());
    assert_same(
        &got,
        &core_compositing(case, &values, 1.0, opaque),
        "padded RGB",
    );
    no_violations(&b);
}

/// `full` with the rows of the other field than `field` transparent black; raster row `y`
/// of an image `h` rows high is OFX row `h − 1 − y` (the lower field: even OFX rows).
fn only_field(full: &Planes, field: InterlacedField) -> Planes {
    let h = full.height;
    rgba(full.width, h, |x, y, c| {
        let ofx_row = h - 1 - y;
        let lower = ofx_row.is_multiple_of(2);
        if lower == (field == InterlacedField::Lower) {
            at(full, x, y, c)
        } else {
            0.0
        }
    })
}

#[test]
fn a_field_render_writes_that_field_rows_only() {
    let _turn = turn();
    let b = load(HostOptions::default());
    let (nerf_instance, values) = nerf(&b, &demo_dir().join("demo_environment.json"));
    let (comp, comp_values) = compositing(&b, &cases()[1]);
    for field in [InterlacedField::Lower, InterlacedField::Upper] {
        for scale in [1.0, 0.5] {
            let (w, h) = (scaled_size(W, scale), scaled_size(H, scale));
            let got = tiled(w, h, |t| {
                nerf_instance.render_field(FRAME, t, scale, field).unwrap()
            });
            let want = only_field(&core_nerf(&values, scale), field);
            assert_same(&got, &want, &format!("NeRF Render {field:?} at {scale}"));
        }
        let got = tiled(CW, CH, |t| comp.render_field(3.0, t, 1.0, field).unwrap());
        let want = only_field(
            &core_compositing(&cases()[1], &comp_values, 1.0, |p| p),
            field,
        );
        assert_same(&got, &want, &format!("ShadowCatcherMerge {field:?}"));
    }
    // The same, padded and top-down (the field is counted from the image's bottom, not the
    // buffer's).
    let padded = load(HostOptions {
        padded_images: true,
        ..HostOptions::default()
    });
    let (i, values) = nerf(&padded, &demo_dir().join("demo_environment.json"));
    let got = tiled(W, H, |t| {
        i.render_field(FRAME, t, 1.0, InterlacedField::Upper)
            .unwrap()
    });
    assert_same(
        &got,
        &only_field(&core_nerf(&values, 1.0), InterlacedField::Upper),
        "padded upper field",
    );
    no_violations(&b);
    no_violations(&padded);
}

#[test]
fn a_second_host_makes_the_plugin_fetch_its_suites_again() {
    let _turn = turn();
    // First a host without a message suite, then one with V2: the error is persistent only
    // if the plugin fetched the second host's suites.
    let b = load(HostOptions {
        message_suite: MessageSuiteOffer::Absent,
        second_host: Some(MessageSuiteOffer::V2),
        ..HostOptions::default()
    });
    let (i, _) = nerf(&b, &demo_dir().join("missing_second.json"));
    failing_render(&i);
    let m = i
        .persistent_message()
        .expect("the second host's message suite is used");
    assert!(m.text.contains("missing_second.json"), "{}", m.text);
    // The other way round: suites of a host with V2 forgotten for one without.
    let quiet = load(HostOptions {
        second_host: Some(MessageSuiteOffer::Absent),
        ..HostOptions::default()
    });
    let (q, _) = nerf(&quiet, &demo_dir().join("missing_quiet.json"));
    let e = failing_render(&q);
    assert!(e.contains("posted no message"), "{e}");
    assert_eq!(q.persistent_message(), None);
    assert!(said(&quiet, "missing_quiet.json").is_empty());
    // Bundles with different hosts take turns: the first one's instance is given its host
    // back and speaks persistently again.
    i.instance_changed_with_reason("file", ChangeReason::UserEdited)
        .unwrap();
    assert_eq!(i.persistent_message(), None);
    failing_render(&i);
    assert!(i.persistent_message().is_some());
    no_violations(&b);
    no_violations(&quiet);
}

#[test]
fn a_nerf_render_without_a_field_file_says_so_without_a_dialog() {
    let _turn = turn();
    for offer in [MessageSuiteOffer::V2, MessageSuiteOffer::V1Only] {
        let b = load(HostOptions {
            message_suite: offer,
            ..HostOptions::default()
        });
        let shot = text(demo_dir().join("demo_shot.json"));
        let (mut i, _) = instance_with(
            &b,
            "org.nerfx.NeRFRender",
            Context::Generator,
            &[("shot", shot)],
        );
        // The render succeeds (transparent), and the node says why, once for all its tiles.
        for x in [0, 8, 16] {
            i.render(FRAME, Window::new(x, 0, x + 8, 8), 1.0, false)
                .unwrap();
        }
        let posted = said(&b, "no Field File chosen");
        match offer {
            MessageSuiteOffer::V2 => {
                assert_eq!(posted.len(), 1, "posted once, not per tile: {posted:?}");
                let m = i.persistent_message().expect("a persistent warning");
                assert_eq!(m.kind, "OfxMessageWarning");
                assert!(
                    m.text.contains("NeRF Render: no Field File chosen"),
                    "{}",
                    m.text
                );
                assert!(posted.iter().all(|(p, _)| *p), "{posted:?}");
                // Choosing the file and rendering clears it.
                i.set_param("file", &text(demo_dir().join("demo_environment.json")))
                    .unwrap();
                i.render(FRAME, Window::new(0, 0, 8, 8), 1.0, false)
                    .unwrap();
                assert_eq!(i.persistent_message(), None);
            }
            _ => assert!(posted.is_empty(), "no dialog for an empty file: {posted:?}"),
        }
        no_violations(&b);
    }
}

/// In the Filter and General contexts a NeRF Render without a Field File passes its Source
/// through (isIdentity): a host that honours that never renders it, so the node says what is
/// missing when it is asked, once however often it is asked.
#[test]
fn a_nerf_render_passing_its_source_through_says_it_has_no_field_file() {
    let _turn = turn();
    for context in [Context::Filter, Context::General] {
        let b = load(HostOptions::default());
        let shot = text(demo_dir().join("demo_shot.json"));
        let (mut i, _) = instance_with(&b, "org.nerfx.NeRFRender", context, &[("shot", shot)]);
        i.connect(
            "Source",
            ClipSource::image(pattern(3, Window::new(0, 0, W, H), 1.0)),
        )
        .unwrap();
        for _ in 0..3 {
            let through = i.is_identity(FRAME, Window::new(0, 0, 8, 8), 1.0).unwrap();
            assert_eq!(through.as_deref(), Some("Source"), "{context:?}");
        }
        let m = i.persistent_message().expect("a persistent warning");
        assert!(
            m.kind == "OfxMessageWarning" && m.text.contains("NeRF Render: no Field File chosen"),
            "{context:?}: {m:?}"
        );
        assert_eq!(said(&b, "no Field File chosen").len(), 1, "{context:?}");
        no_violations(&b);
    }
}

/// With a host offering OpenFX 1.5's colour management, a NeRF Render says its output's
/// colourspace by its native identifier (Raw for depth), and a compositing node leaves the
/// host its default (its input's).
#[test]
fn the_output_colourspace_is_declared_to_a_colour_managed_host() {
    let _turn = turn();
    let b = load(HostOptions::default());
    let env = demo_dir().join("demo_environment.json");
    let (mut i, _) = nerf(&b, &env);
    let preferred = ["ACEScg", "lin_rec709_srgb"];
    assert_eq!(
        i.output_colourspace(&preferred).unwrap().as_deref(),
        Some("lin_rec709_srgb"),
        "the scene file names no space: linear Rec.709"
    );
    for (space, native) in [
        ("acescg", "ACEScg"),
        ("aces2065-1", "ACES2065-1"),
        ("srgb", "srgb_tx"),
    ] {
        let index = [
            "scene",
            "lin_rec709",
            "acescg",
            "aces2065-1",
            "lin_rec2020",
            "lin_p3d65",
            "srgb",
        ]
        .iter()
        .position(|s| *s == space)
        .unwrap();
        i.set_param("outputColourSpace", &Value::Choice(index))
            .unwrap();
        assert_eq!(
            i.output_colourspace(&preferred).unwrap().as_deref(),
            Some(native)
        );
    }
    i.set_param("output", &Value::Choice(2)).unwrap();
    assert_eq!(
        i.output_colourspace(&preferred).unwrap().as_deref(),
        Some("Raw")
    );
    let matte = b
        .instance("org.nerfx.AccumulationMatte", Context::General)
        .unwrap();
    assert_eq!(matte.output_colourspace(&preferred).unwrap(), None);
    no_violations(&b);
}

/// A mandatory input that is connected but for which the host hands out no image is not
/// taken as black without a word: the frame's warning names the clip, once per frame.
#[test]
fn a_connected_input_without_an_image_is_named() {
    let _turn = turn();
    let b = load(HostOptions::default());
    let mut i = b
        .instance("org.nerfx.AccumulationMatte", Context::General)
        .unwrap();
    let failing = ClipSource::new((12, 9), |_, _, _| {
        Err(nerfx_core::Error::invalid(
            "test source",
            "no image at this time",
        ))
    });
    i.connect("Source", failing).unwrap();
    for x in [0, 6] {
        i.render(FRAME, Window::new(x, 0, x + 6, 9), 1.0, false)
            .unwrap();
    }
    let m = i.persistent_message().expect("a persistent warning");
    assert!(
        m.kind == "OfxMessageWarning"
            && m.text
                .contains("the Source clip is connected but the host gave no image")
            && m.text.contains("transparent black"),
        "{m:?}"
    );
    assert_eq!(said(&b, "the Source clip is connected").len(), 1);
}

#[test]
fn a_frame_outside_the_shot_has_the_shots_format_and_fails_to_render_saying_why() {
    let _turn = turn();
    let b = load(HostOptions::default());
    let (i, _) = nerf(&b, &demo_dir().join("demo_environment.json"));
    // The demo shot holds frames 1001 onwards.
    assert_eq!(i.region_of_definition(990.0).unwrap(), (W, H));
    let e = failing_render_at(&i, 990.0);
    assert!(
        e.contains("frame 990 is not in the shot") && e.contains("1001"),
        "{e}"
    );
    no_violations(&b);
}

/// A render of an 8×8 window at `time` that must fail; its error text.
fn failing_render_at(instance: &Instance, time: f64) -> String {
    instance
        .render(time, Window::new(0, 0, 8, 8), 1.0, false)
        .expect_err("the render fails")
        .to_string()
}

/// An Accumulation Matte whose optional Matte is left unconnected takes the Source's alpha,
/// however the host presents the absent clip: unconnected, "connected" with no image, or an
/// image without pixels. Each must give the core's render without a Matte input.
#[test]
fn an_absent_matte_falls_back_to_the_sources_alpha_however_the_host_says_it() {
    use nerfx_ofx_host::AbsentClip;
    let _turn = turn();
    let values = {
        let mut v = node("org.nerfx.AccumulationMatte").unwrap().defaults();
        v.set("gamma", Value::Double(1.6)).unwrap();
        v
    };
    let source = |window: Window| pattern(7, window, 1.0);
    let full = Window::new(0, 0, 12, 9);
    let want = rgba_of(
        &node("org.nerfx.AccumulationMatte")
            .unwrap()
            .render(
                &values,
                &RenderRequest::new(FRAME, full, 1.0).with_input("Source", source(full)),
            )
            .unwrap(),
    );
    for absent in [
        AbsentClip::Unconnected,
        AbsentClip::NoImage,
        AbsentClip::EmptyImage,
    ] {
        let b = load(HostOptions {
            absent_clip: absent,
            ..HostOptions::default()
        });
        let mut i = b
            .instance("org.nerfx.AccumulationMatte", Context::General)
            .unwrap();
        i.connect("Source", ClipSource::image(source(full)))
            .unwrap();
        i.set_param("gamma", &Value::Double(1.6)).unwrap();
        let got = rgba_of(&i.render(FRAME, full, 1.0, false).unwrap());
        assert_same(&got, &want, &format!("{absent:?}"));
        no_violations(&b);
    }
}
