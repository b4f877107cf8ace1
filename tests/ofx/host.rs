//! The OpenFX host (`nerfx_ofx_host`): loading, describing every node of the built bundle in
//! every context, the strictness of the property suite (called directly through the same
//! function pointers the plugin gets), parameter values and messages through the C shim,
//! the multithread suite, and concurrent renders. Pixel equality of each node against the
//! core is `tests/ofx/nodes.rs`.

use std::ffi::{c_char, c_int, c_uint, c_void, CStr};
use std::path::Path;
use std::ptr;
use std::sync::atomic::{AtomicU32, Ordering};

use crate::common_ofx::images::tiles;
use nerfx_core::image::{scaled_size, Plane, Planes, Window};
use nerfx_graph::{node, nodes, Context, ParamKind, Value};
use nerfx_ofx_host::{testing, Bundle, ClipSource, HostOptions, Instance, PropValue};
use openfx_sys as ofx;

// OpenFX status codes, written out from the spec.
const OK: c_int = 0;
const ERR_UNKNOWN: c_int = 3;
const ERR_BAD_HANDLE: c_int = 9;
const ERR_BAD_INDEX: c_int = 10;
const ERR_VALUE: c_int = 11;
const REPLY_NO: c_int = 13;

fn bundle() -> Bundle {
    crate::common_ofx::load(HostOptions::default())
}

fn name(s: &[u8]) -> *const c_char {
    s.as_ptr().cast()
}

fn text(p: *const c_char) -> String {
    assert!(!p.is_null());
    unsafe { CStr::from_ptr(p) }.to_str().unwrap().to_string()
}

#[test]
fn loading_a_missing_bundle_names_the_binary_it_looked_for() {
    let e = Bundle::load(Path::new("/nonexistent/missing.ofx.bundle"))
        .err()
        .unwrap();
    let m = e.to_string();
    assert!(
        m.contains("missing.ofx.bundle/Contents/Linux-x86-64/missing.ofx"),
        "{m}"
    );
}

#[test]
fn a_library_that_is_not_openfx_is_refused() {
    let libc = [
        "/lib/x86_64-linux-gnu/libc.so.6",
        "/usr/lib/x86_64-linux-gnu/libc.so.6",
        "/lib64/libc.so.6",
    ]
    .into_iter()
    .map(Path::new)
    .find(|p| p.is_file())
    .expect("no libc.so.6 found in the usual places");
    let m = Bundle::load(libc).err().unwrap().to_string();
    assert!(
        m.contains("not an OpenFX binary") && m.contains("OfxGetNumberOfPlugins"),
        "{m}"
    );
}

#[test]
fn every_node_is_described_in_every_context_without_violations() {
    let b = bundle();
    let ids: Vec<&str> = nodes().iter().map(|n| n.desc.id).collect();
    assert_eq!(b.plugin_ids(), ids);
    for n in nodes() {
        for &context in n.desc.contexts {
            let d = b.describe(n.desc.id, context).unwrap();
            let at = format!("{} in {context:?}", n.desc.id);
            assert_eq!(d.label, n.desc.label, "{at}");
            assert_eq!(d.grouping, n.desc.group, "{at}");
            assert_eq!(d.contexts, n.desc.contexts, "{at}");
            assert!(d.supports_tiles && d.supports_multi_resolution, "{at}");
            assert_eq!(d.thread_safety, "OfxImageEffectRenderFullySafe", "{at}");
            assert_eq!(d.pixel_depths, ["OfxBitDepthFloat"], "{at}");
            let mut want: Vec<&str> = n
                .desc
                .clips
                .iter()
                .filter(|c| c.contexts.contains(&context))
                .map(|c| c.name)
                .collect();
            want.push("Output");
            let mut got: Vec<&str> = d.clips.iter().map(|c| c.name.as_str()).collect();
            want.sort_unstable();
            got.sort_unstable();
            assert_eq!(got, want, "{at}");
            for c in &d.clips {
                assert!(
                    c.components.iter().any(|x| x == "OfxImageComponentRGBA"),
                    "{at}: {}",
                    c.name
                );
                if let Some(r) = n.desc.clip(&c.name) {
                    assert_eq!(c.optional, r.optional, "{at}: {}", c.name);
                }
            }
            for p in &n.desc.params {
                let q = d.params.iter().find(|q| q.name == p.name);
                let q = q.unwrap_or_else(|| panic!("{at}: parameter {} not declared", p.name));
                assert_eq!(q.label, p.label, "{at}: {}", p.name);
                assert_eq!(q.animates, p.animates, "{at}: {}", p.name);
                let ty = match &p.kind {
                    ParamKind::Double { .. } => "OfxParamTypeDouble",
                    ParamKind::Int { .. } => "OfxParamTypeInteger",
                    ParamKind::Bool { .. } => "OfxParamTypeBoolean",
                    ParamKind::Choice { options, .. } => {
                        assert_eq!(q.choice_options.len(), options.len(), "{at}: {}", p.name);
                        "OfxParamTypeChoice"
                    }
                    ParamKind::File => {
                        assert_eq!(q.string_mode.as_deref(), Some("OfxParamStringIsFilePath"));
                        "OfxParamTypeString"
                    }
                    ParamKind::Text { .. } | ParamKind::Matrix { .. } => "OfxParamTypeString",
                    ParamKind::Rgb { .. } => "OfxParamTypeRGB",
                    ParamKind::Rgba { .. } => "OfxParamTypeRGBA",
                    ParamKind::Double3 { .. } => "OfxParamTypeDouble3D",
                };
                assert_eq!(q.param_type, ty, "{at}: {}", p.name);
                if let ParamKind::Double { default, range } = &p.kind {
                    assert_eq!(
                        q.default,
                        PropValue::Double(vec![*default]),
                        "{at}: {}",
                        p.name
                    );
                    assert_eq!(q.min, Some(vec![range.min]), "{at}: {}", p.name);
                    assert_eq!(q.max, Some(vec![range.max]), "{at}: {}", p.name);
                }
            }
        }
    }
    assert_eq!(b.violations(), Vec::<String>::new());
}

#[test]
fn a_context_the_node_lacks_is_refused() {
    let b = bundle();
    let m = b
        .describe("org.nerfx.DepthMerge", Context::Generator)
        .err()
        .unwrap()
        .to_string();
    assert!(
        m.contains("OfxImageEffectContextGenerator") && m.contains("not supported"),
        "{m}"
    );
    let m = b
        .describe("org.nerfx.NoSuchNode", Context::General)
        .err()
        .unwrap()
        .to_string();
    assert!(m.contains("org.nerfx.NoSuchNode"), "{m}");
}

#[test]
fn instances_are_created_and_destroyed_without_violations() {
    let b = bundle();
    for n in nodes() {
        for &context in n.desc.contexts {
            let i = b.instance(n.desc.id, context).unwrap();
            i.purge_caches().unwrap();
            let p = n
                .desc
                .params
                .iter()
                .find(|p| p.kind != ParamKind::File)
                .unwrap();
            i.instance_changed(p.name).unwrap();
            drop(i);
        }
    }
    assert_eq!(b.violations(), Vec::<String>::new());
}

#[test]
fn the_property_suite_refuses_bad_accesses_with_the_specs_statuses() {
    let s = testing::property_suite();
    let host = testing::host_properties();
    let mut statuses = Vec::new();
    let violations = testing::violations_of(|| unsafe {
        let mut i: c_int = -1;
        let mut d: f64 = -1.0;
        let mut p: *mut c_char = ptr::null_mut();
        // Well-formed reads: the host's API version is 1.4, its contexts the three we serve.
        assert_eq!(
            s.propGetInt.unwrap()(host, name(ofx::kOfxPropAPIVersion), 1, &mut i),
            OK
        );
        assert_eq!(i, 4);
        let mut n: c_int = 0;
        let contexts = name(ofx::kOfxImageEffectPropSupportedContexts);
        assert_eq!(s.propGetDimension.unwrap()(host, contexts, &mut n), OK);
        assert_eq!(n, 3);
        assert_eq!(s.propGetString.unwrap()(host, contexts, 2, &mut p), OK);
        assert_eq!(text(p), "OfxImageEffectContextGeneral");
        // A property of the spec that this set does not hold: probing the host is legitimate.
        assert_eq!(
            s.propGetString.unwrap()(host, name(ofx::kOfxImageEffectPropContext), 0, &mut p),
            ERR_UNKNOWN
        );
        // Each of these is a violation.
        statuses.push(s.propGetInt.unwrap()(
            host,
            name(b"OfxNoSuchProperty\0"),
            0,
            &mut i,
        ));
        statuses.push(s.propGetDouble.unwrap()(
            host,
            name(ofx::kOfxImageEffectPropSupportsTiles),
            0,
            &mut d,
        ));
        statuses.push(s.propSetInt.unwrap()(
            host,
            name(ofx::kOfxImageEffectPropSupportsTiles),
            0,
            0,
        ));
        statuses.push(s.propGetInt.unwrap()(
            host,
            name(ofx::kOfxPropAPIVersion),
            2,
            &mut i,
        ));
        statuses.push(s.propGetInt.unwrap()(
            host,
            name(ofx::kOfxPropAPIVersion),
            -1,
            &mut i,
        ));
        statuses.push(s.propGetInt.unwrap()(
            0x1234usize as ofx::OfxPropertySetHandle,
            name(ofx::kOfxPropAPIVersion),
            0,
            &mut i,
        ));
        let mut two = [0 as c_int; 3];
        statuses.push(s.propGetIntN.unwrap()(
            host,
            name(ofx::kOfxPropAPIVersion),
            3,
            two.as_mut_ptr(),
        ));
    });
    assert_eq!(
        statuses,
        [
            ERR_UNKNOWN,
            ERR_VALUE,
            ERR_VALUE,
            ERR_BAD_INDEX,
            ERR_BAD_INDEX,
            ERR_BAD_HANDLE,
            ERR_BAD_INDEX
        ]
    );
    assert_eq!(violations.len(), statuses.len(), "{violations:#?}");
    assert!(
        violations[0].contains("OfxNoSuchProperty"),
        "{violations:#?}"
    );
    assert!(violations[2].contains("read-only"), "{violations:#?}");
    // The host's properties are unchanged.
    let mut i: c_int = -1;
    unsafe { s.propGetInt.unwrap()(host, name(ofx::kOfxImageEffectPropSupportsTiles), 0, &mut i) };
    assert_eq!(i, 1);
}

/// The instance's property set, through the image effect suite.
fn instance_properties(i: &Instance) -> ofx::OfxPropertySetHandle {
    let mut props: ofx::OfxPropertySetHandle = ptr::null_mut();
    let get = testing::image_effect_suite().getPropertySet.unwrap();
    assert_eq!(unsafe { get(testing::effect_handle(i), &mut props) }, OK);
    props
}

#[test]
fn instance_properties_are_typed_and_guarded() {
    let b = bundle();
    let i = b
        .instance("org.nerfx.DepthMerge", Context::General)
        .unwrap();
    let s = testing::property_suite();
    let props = instance_properties(&i);
    unsafe {
        let mut p: *mut c_char = ptr::null_mut();
        let context = name(ofx::kOfxImageEffectPropContext);
        assert_eq!(s.propGetString.unwrap()(props, context, 0, &mut p), OK);
        assert_eq!(text(p), "OfxImageEffectContextGeneral");
        // Writable by the plugin on an instance.
        let sequential = name(ofx::kOfxImageEffectInstancePropSequentialRender);
        assert_eq!(s.propSetInt.unwrap()(props, sequential, 0, 1), OK);
        assert_eq!(s.propReset.unwrap()(props, sequential), OK);
        let mut v: c_int = -1;
        assert_eq!(s.propGetInt.unwrap()(props, sequential, 0, &mut v), OK);
        assert_eq!(v, 0);
        // Read-only, and not a property of an instance.
        assert_eq!(
            s.propSetString.unwrap()(props, context, 0, name(b"OfxImageEffectContextFilter\0")),
            ERR_VALUE
        );
        assert_eq!(
            s.propGetInt.unwrap()(props, name(ofx::kOfxImageClipPropOptional), 0, &mut v),
            ERR_UNKNOWN
        );
    }
    let v = b.violations();
    assert_eq!(v.len(), 2, "{v:#?}");
    assert!(
        v[0].contains("OfxImageEffectPropContext") && v[0].contains("read-only"),
        "{v:#?}"
    );
    assert!(v[1].contains("OfxImageClipPropOptional"), "{v:#?}");
}

/// The handle of parameter `param` of `i`, through the suites.
fn param_handle(i: &Instance, param: &str) -> ofx::OfxParamHandle {
    let mut set: ofx::OfxParamSetHandle = ptr::null_mut();
    let get_set = testing::image_effect_suite().getParamSet.unwrap();
    assert_eq!(unsafe { get_set(testing::effect_handle(i), &mut set) }, OK);
    let mut h: ofx::OfxParamHandle = ptr::null_mut();
    let c = std::ffi::CString::new(param).unwrap();
    let get = testing::parameter_suite().paramGetHandle.unwrap();
    assert_eq!(unsafe { get(set, c.as_ptr(), &mut h, ptr::null_mut()) }, OK);
    h
}

#[test]
fn parameter_values_pass_through_the_c_shim() {
    let b = bundle();
    let ps = testing::parameter_suite();
    let mut matte = b
        .instance("org.nerfx.AccumulationMatte", Context::General)
        .unwrap();
    matte.set_param("gamma", &Value::Double(2.5)).unwrap();
    let gamma = param_handle(&matte, "gamma");
    unsafe {
        let mut v = 0.0f64;
        assert_eq!(ps.paramGetValue.unwrap()(gamma, &mut v as *mut f64), OK);
        assert_eq!(v, 2.5);
        v = 0.0;
        assert_eq!(
            ps.paramGetValueAtTime.unwrap()(gamma, 7.0, &mut v as *mut f64),
            OK
        );
        assert_eq!(v, 2.5);
        assert_eq!(
            ps.paramGetDerivative.unwrap()(gamma, 7.0, &mut v as *mut f64),
            OK
        );
        assert_eq!(v, 0.0);
        // Constant over [1, 3]: the integral is 2.5 × 2.
        assert_eq!(
            ps.paramGetIntegral.unwrap()(gamma, 1.0, 3.0, &mut v as *mut f64),
            OK
        );
        assert_eq!(v, 5.0);
        assert_eq!(ps.paramSetValue.unwrap()(gamma, 3.0f64), OK);
        // Outside the declared range [0.01, 10]: refused, recorded.
        assert_eq!(ps.paramSetValue.unwrap()(gamma, 100.0f64), ERR_VALUE);
        let mut keys: c_uint = 9;
        assert_eq!(ps.paramGetNumKeys.unwrap()(gamma, &mut keys), OK);
        assert_eq!(keys, 0);
    }
    // A handle the host never gave out (in an action scope of its own: outside any action
    // it would be reported by every bundle of this process).
    let bad = testing::violations_of(|| unsafe {
        let mut v = 0.0f64;
        let h = 0x10usize as ofx::OfxParamHandle;
        assert_eq!(
            ps.paramGetValue.unwrap()(h, &mut v as *mut f64),
            ERR_BAD_HANDLE
        );
    });
    assert!(bad.len() == 1 && bad[0].contains("0x10"), "{bad:#?}");
    assert_eq!(matte.param("gamma").unwrap(), PropValue::Double(vec![3.0]));
    assert!(matte.set_param("gamma", &Value::Double(11.0)).is_err());
    assert!(matte.set_param("gamma", &Value::Bool(true)).is_err());
    assert!(matte.set_param("noSuchParam", &Value::Double(1.0)).is_err());
    let v = b.violations();
    assert_eq!(v.len(), 1, "{v:#?}");
    assert!(v[0].contains("gamma") && v[0].contains("100"), "{v:#?}");

    // Strings (file paths) and choices.
    let nerf = node("org.nerfx.NeRFRender").unwrap();
    let file = nerf
        .desc
        .params
        .iter()
        .find(|p| p.kind == ParamKind::File)
        .unwrap()
        .name;
    let choice = nerf
        .desc
        .params
        .iter()
        .find(|p| matches!(p.kind, ParamKind::Choice { .. }))
        .unwrap()
        .name;
    let mut render = b.instance(nerf.desc.id, Context::Generator).unwrap();
    render
        .set_param(file, &Value::Text("/data/shot é.json".into()))
        .unwrap();
    render.set_param(choice, &Value::Choice(1)).unwrap();
    assert!(render.set_param(choice, &Value::Choice(99)).is_err());
    unsafe {
        let mut s: *const c_char = ptr::null();
        assert_eq!(
            ps.paramGetValue.unwrap()(param_handle(&render, file), &mut s as *mut *const c_char),
            OK
        );
        assert_eq!(text(s), "/data/shot é.json");
        let mut i: c_int = -1;
        assert_eq!(
            ps.paramGetValue.unwrap()(param_handle(&render, choice), &mut i as *mut c_int),
            OK
        );
        assert_eq!(i, 1);
    }
}

#[test]
fn messages_are_formatted_by_the_shim_and_recorded() {
    let b = bundle();
    let i = b
        .instance("org.nerfx.DepthMerge", Context::General)
        .unwrap();
    let ms = testing::message_suite();
    let h = testing::effect_handle(&i) as *mut c_void;
    unsafe {
        let warning = name(ofx::kOfxMessageWarning);
        let s = ms.message.unwrap()(
            h,
            warning,
            ptr::null(),
            name(b"%s has %d items\0"),
            name(b"list\0"),
            3 as c_int,
        );
        assert_eq!(s, OK);
        let error = name(ofx::kOfxMessageError);
        let s = ms.setPersistentMessage.unwrap()(h, error, ptr::null(), name(b"%.2f\0"), 1.5f64);
        assert_eq!(s, OK);
        let question = name(ofx::kOfxMessageQuestion);
        assert_eq!(
            ms.message.unwrap()(h, question, ptr::null(), name(b"go?\0")),
            REPLY_NO
        );
        assert_eq!(
            ms.message.unwrap()(h, name(b"Bogus\0"), ptr::null(), name(b"x\0")),
            ERR_UNKNOWN
        );
        assert_eq!(ms.clearPersistentMessage.unwrap()(h), OK);
    }
    let m = b.messages();
    let texts: Vec<(&str, &str, bool)> = m
        .iter()
        .map(|m| (m.kind.as_str(), m.text.as_str(), m.persistent))
        .collect();
    assert_eq!(
        texts,
        [
            ("OfxMessageWarning", "list has 3 items", false),
            ("OfxMessageError", "1.50", true),
            ("OfxMessageQuestion", "go?", false)
        ]
    );
    let v = b.violations();
    assert!(v.len() == 1 && v[0].contains("Bogus"), "{v:#?}");
}

static CALLS: AtomicU32 = AtomicU32::new(0);
static INDICES: AtomicU32 = AtomicU32::new(0);

unsafe extern "C" fn count_call(index: c_uint, max: c_uint, arg: *mut c_void) {
    assert_eq!(max, 5);
    assert_eq!(arg as usize, 42);
    CALLS.fetch_add(1, Ordering::SeqCst);
    INDICES.fetch_or(1 << index, Ordering::SeqCst);
}

#[test]
fn the_multithread_suite_runs_every_index_and_locks_recursively() {
    let host = testing::host();
    let mt = unsafe {
        let fetch = (*host).fetchSuite.unwrap();
        &*(fetch((*host).host, name(ofx::kOfxMultiThreadSuite), 1)
            as *const ofx::OfxMultiThreadSuiteV1)
    };
    let violations = testing::violations_of(|| unsafe {
        assert_eq!(
            mt.multiThread.unwrap()(Some(count_call), 5, 42usize as *mut c_void),
            OK
        );
        let mut m: ofx::OfxMutexHandle = ptr::null_mut();
        assert_eq!(mt.mutexCreate.unwrap()(&mut m, 0), OK);
        assert_eq!(mt.mutexLock.unwrap()(m), OK);
        assert_eq!(mt.mutexTryLock.unwrap()(m), OK);
        assert_eq!(mt.mutexUnLock.unwrap()(m), OK);
        assert_eq!(mt.mutexUnLock.unwrap()(m), OK);
        // Unlocking a free mutex is a plugin bug.
        assert_ne!(mt.mutexUnLock.unwrap()(m), OK);
        assert_eq!(mt.mutexDestroy.unwrap()(m), OK);
        assert_eq!(mt.mutexLock.unwrap()(m), ERR_BAD_HANDLE);
    });
    assert_eq!(CALLS.load(Ordering::SeqCst), 5);
    assert_eq!(INDICES.load(Ordering::SeqCst), 0b11111);
    assert_eq!(violations.len(), 2, "{violations:#?}");
}

/// A seeded RGBA test image at any render scale: raster pixel (x, y) of the image at scale
/// `s` has colour from a hash of (x, y, s) and alpha in [0, 1].
fn pattern(size: (u32, u32)) -> ClipSource {
    ClipSource::new(size, |time, w, s| {
        let value = |x: u32, y: u32, k: u32| {
            let mut h = (u64::from(x) << 32 | u64::from(y))
                ^ (u64::from(k) << 60)
                ^ (s * 1e6) as u64
                ^ time as u64;
            h = h.wrapping_mul(0x9e37_79b9_7f4a_7c15);
            h ^= h >> 29;
            (h % 1000) as f32 / 1000.0
        };
        let plane = |k: u32| Plane {
            width: w.width(),
            height: w.height(),
            data: (w.y0..w.y1)
                .flat_map(|y| (w.x0..w.x1).map(move |x| value(x, y, k)))
                .collect(),
        };
        let alpha = plane(3);
        let rgb = [0, 1, 2].map(|k| {
            let mut p = plane(k);
            for (c, a) in p.data.iter_mut().zip(&alpha.data) {
                *c *= a;
            }
            p
        });
        Ok(Planes {
            width: w.width(),
            height: w.height(),
            rgb: Some(rgb),
            alpha: Some(alpha),
            depth_z: None,
            depth_ray: None,
            depth_median: None,
        })
    })
}

fn crop(p: &Planes, w: Window) -> Vec<Vec<f32>> {
    let rgb = p.rgb.as_ref().unwrap();
    [&rgb[0], &rgb[1], &rgb[2], p.alpha.as_ref().unwrap()]
        .iter()
        .map(|q| {
            (w.y0..w.y1)
                .flat_map(|y| (w.x0..w.x1).map(move |x| q.get(x, y)))
                .collect()
        })
        .collect()
}

fn whole(p: &Planes) -> Vec<Vec<f32>> {
    crop(p, Window::new(0, 0, p.width, p.height))
}

#[test]
fn concurrent_tile_renders_agree_with_one_full_render() {
    let b = bundle();
    let mut matte = b
        .instance("org.nerfx.AccumulationMatte", Context::Filter)
        .unwrap();
    matte.connect("Source", pattern((37, 23))).unwrap();
    matte.set_param("gamma", &Value::Double(1.7)).unwrap();
    assert_eq!(matte.region_of_definition(1.0).unwrap(), (37, 23));
    for s in [1.0f64, 0.5] {
        let (w, h) = (scaled_size(37, s), scaled_size(23, s));
        let full = matte
            .render(1.0, Window::new(0, 0, w, h), s, false)
            .unwrap();
        assert_eq!((full.width, full.height), (w, h));
        let tiles = tiles(w, h);
        matte.begin_sequence(1.0, 1.0, s).unwrap();
        std::thread::scope(|scope| {
            for chunk in tiles.chunks(tiles.len().div_ceil(6)) {
                let (matte, full) = (&matte, &full);
                scope.spawn(move || {
                    for &t in chunk {
                        let tile = matte.render(1.0, t, s, false).unwrap();
                        assert_eq!(whole(&tile), crop(full, t), "tile {t:?} at scale {s}");
                    }
                });
            }
        });
        matte.end_sequence(1.0, 1.0, s).unwrap();
    }
    assert_eq!(b.violations(), Vec::<String>::new());
}

#[test]
fn identity_follows_the_mix() {
    let b = bundle();
    let mut matte = b
        .instance("org.nerfx.AccumulationMatte", Context::Filter)
        .unwrap();
    matte.connect("Source", pattern((8, 8))).unwrap();
    let w = Window::new(0, 0, 8, 8);
    assert_eq!(matte.is_identity(1.0, w, 1.0).unwrap(), None);
    matte.set_param("mix", &Value::Double(0.0)).unwrap();
    assert_eq!(
        matte.is_identity(1.0, w, 1.0).unwrap().as_deref(),
        Some("Source")
    );
    assert_eq!(b.violations(), Vec::<String>::new());
}

#[test]
fn a_failed_action_carries_the_status_and_the_plugins_message() {
    let b = bundle();
    let nerf = node("org.nerfx.NeRFRender").unwrap();
    let mut i = b.instance(nerf.desc.id, Context::Generator).unwrap();
    for p in nerf
        .desc
        .params
        .iter()
        .filter(|p| p.kind == ParamKind::File)
    {
        i.set_param(p.name, &Value::Text("/nonexistent/missing.json".into()))
            .unwrap();
    }
    let e = i
        .render(1.0, Window::new(0, 0, 4, 4), 1.0, false)
        .err()
        .unwrap()
        .to_string();
    assert!(e.starts_with("org.nerfx.NeRFRender: "), "{e}");
    assert!(
        e.contains("failed (kOfxStat") && e.contains("missing.json"),
        "{e}"
    );
    assert!(!b.messages().is_empty());
}
