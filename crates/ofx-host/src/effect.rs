//! Image effects (descriptors and instances), their clips and images, and the image-effect
//! suite (`OfxImageEffectSuiteV1`).
//!
//! Coordinates: OFX images are in pixel coordinates at the render scale, `y` up, origin at
//! the bottom left; the core's windows are raster (`y` down, origin top left). For an image
//! of height `H_s = ⌈h·s⌉` at render scale `s`, raster rows `[y0, y1)` are OFX rows
//! `[H_s − y1, H_s − y0)`, and raster row `y` is OFX row `H_s − 1 − y`.

use std::cell::Cell;
use std::collections::HashMap;
use std::ffi::{c_char, c_int, c_void, CStr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};

use openfx_sys as ofx;
use openfx_sys::{
    OfxImageClipHandle, OfxImageEffectHandle, OfxImageMemoryHandle, OfxParamSetHandle,
    OfxPropertySetHandle, OfxRectD, OfxStatus, OfxTime,
};

use super::handles::{self, Kind};
use super::log::{Log, Message};
use super::options::{AbsentClip, HostOptions, InterlacedField, PADDING, ROW_SLACK};
use super::params::{put, ParamSet};
use super::props::{self, PropSet, Template};
use super::source::ClipSource;
use super::spec::{cstr, SetKind};
use super::{memory, status};
use nerfx_core::image::{scaled_size, Planes, Window};

/// Guard border around the output image, in pixels.
pub(crate) const GUARD: usize = 4;
/// What the output buffer holds before the plugin writes: a quiet NaN with a payload no
/// arithmetic produces, so an unwritten pixel or a write into the guard is recognised.
pub(crate) const SENTINEL_BITS: u32 = 0x7fc5_a5a5;

/// A descriptor or an instance. Boxed and registered while alive.
pub(crate) struct Effect {
    /// The plugin's identifier.
    pub(crate) id: String,
    /// Its properties.
    pub(crate) props: Box<PropSet>,
    /// Its parameters.
    pub(crate) params: Box<ParamSet>,
    #[allow(
        clippy::vec_box,
        reason = "a clip's address is its handle: it must not move"
    )]
    clips: Mutex<Vec<Box<Clip>>>,
    /// Whether this is an instance.
    pub(crate) instance: bool,
    /// Where its messages and violations go.
    pub(crate) log: Arc<Log>,
    renders: Mutex<Vec<RenderCtx>>,
    /// The last region of definition the plugin gave (canonical), for the output clip.
    pub(crate) output_rod: Mutex<Option<[f64; 4]>>,
    /// How the host behaves (image layout, components).
    pub(crate) options: HostOptions,
    /// The persistent message set on the instance and not cleared since.
    pub(crate) persistent: Mutex<Option<Message>>,
    /// A descriptor's: the properties its instances start from in each context, made at the
    /// first instance and shared by all of them until one is written, and the name their sets
    /// go by.
    instance_props: Mutex<Vec<(String, Template)>>,
}

/// A clip. Boxed and registered while alive.
pub(crate) struct Clip {
    /// Its name (an instance's is its descriptor's).
    pub(crate) name: Arc<str>,
    /// Its properties.
    pub(crate) props: Box<PropSet>,
    effect: usize,
    /// What feeds it (inputs of an instance).
    pub(crate) source: Mutex<Option<ClipSource>>,
    /// A descriptor's: the properties its instances start from, made at the first instance
    /// and shared by all of them until one is written, and the name their sets go by.
    instance_props: OnceLock<Box<Template>>,
}

/// Where an image's pixels are: `ptr` is the bottom-left pixel of `bounds`; rows are
/// `row_bytes` apart (negative: stored top-down).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    /// Address of the bottom-left pixel of `bounds`.
    pub(crate) ptr: usize,
    /// OFX bounds of the image (for the output, the render window or more).
    pub(crate) bounds: [i32; 4],
    /// OFX region of definition at the render scale.
    pub(crate) rod: [i32; 4],
    /// Bytes from a row to the one above (negative when stored top-down).
    pub(crate) row_bytes: i32,
}

/// A render in flight.
#[derive(Clone, Debug)]
pub(crate) struct RenderCtx {
    /// Unique per process.
    pub(crate) id: u64,
    /// Frame.
    pub(crate) time: f64,
    /// Render scale.
    pub(crate) scale: f64,
    /// The regions of interest the plugin declared, canonical `[x1, y1, x2, y2]`, by clip.
    pub(crate) rois: HashMap<String, [f64; 4]>,
    /// The output buffer.
    pub(crate) output: Layout,
    /// The field rendered into the full-frame output, if one.
    pub(crate) field: Option<InterlacedField>,
}

/// An image the plugin holds.
struct LiveImage {
    props: Box<PropSet>,
    _data: Vec<f32>,
    effect: usize,
    render: Option<u64>,
    what: String,
}

fn images() -> MutexGuard<'static, HashMap<usize, LiveImage>> {
    static IMAGES: OnceLock<Mutex<HashMap<usize, LiveImage>>> = OnceLock::new();
    IMAGES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
}

thread_local! {
    static RENDER: Cell<Option<(usize, u64)>> = const { Cell::new(None) };
}

/// The render running on this thread (effect address, render id).
pub(crate) fn current_render() -> Option<(usize, u64)> {
    RENDER.with(Cell::get)
}

/// Marks this thread as running a render until dropped.
pub(crate) struct RenderScope(Option<(usize, u64)>);

impl RenderScope {
    /// Enters `render` (or nothing).
    pub(crate) fn enter(render: Option<(usize, u64)>) -> Self {
        RenderScope(RENDER.with(|r| r.replace(render)))
    }
}

impl Drop for RenderScope {
    fn drop(&mut self) {
        RENDER.with(|r| r.set(self.0));
    }
}

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

impl Effect {
    /// A new descriptor of plugin `id`.
    pub(crate) fn descriptor(
        id: &str,
        path: &str,
        log: Arc<Log>,
        options: HostOptions,
    ) -> Box<Effect> {
        let props = props::new_set(
            SetKind::EffectDesc,
            id,
            format!("{id} descriptor"),
            Some(log.clone()),
        );
        props.set_str(ofx::kOfxPropType, cstr(ofx::kOfxTypeImageEffect));
        props.set_str(ofx::kOfxPluginPropFilePath, path);
        let params = ParamSet::new(id, false, log.clone());
        Effect::boxed(id, props, params, false, log, options)
    }

    fn boxed(
        id: &str,
        props: Box<PropSet>,
        params: Box<ParamSet>,
        instance: bool,
        log: Arc<Log>,
        options: HostOptions,
    ) -> Box<Effect> {
        let e = Box::new(Effect {
            id: id.to_string(),
            props,
            params,
            clips: Mutex::new(Vec::new()),
            instance,
            log,
            renders: Mutex::new(Vec::new()),
            output_rod: Mutex::new(None),
            options,
            persistent: Mutex::new(None),
            instance_props: Mutex::new(Vec::new()),
        });
        handles::register(&*e as *const Effect, Kind::Effect);
        e
    }

    /// An instance of this descriptor in `context` (an OFX context name).
    pub(crate) fn instantiate(&self, context: &str) -> Box<Effect> {
        let id = &self.id;
        let log = self.log.clone();
        let props = {
            let mut templates = self
                .instance_props
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            let at = match templates.iter().position(|(c, ..)| c == context) {
                Some(at) => at,
                None => {
                    let props = props::new_set(
                        SetKind::EffectInst,
                        id,
                        format!("{id} instances' defaults in {context}"),
                        Some(log.clone()),
                    );
                    props.copy_values_from(&self.props);
                    props.set_str(ofx::kOfxPropType, cstr(ofx::kOfxTypeImageEffectInstance));
                    props.set_str(ofx::kOfxImageEffectPropContext, context);
                    props.set_doubles(ofx::kOfxImageEffectPropProjectSize, &[1920.0, 1080.0]);
                    props.set_doubles(ofx::kOfxImageEffectPropProjectExtent, &[1920.0, 1080.0]);
                    let what = format!("{id} instance").into();
                    templates.push((context.to_string(), Template { props, what }));
                    templates.len() - 1
                }
            };
            templates[at].1.instance(Some(log.clone()))
        };
        let params = self
            .params
            .instantiate(&format!("{id} instance"), log.clone());
        let e = Effect::boxed(id, props, params, true, log.clone(), self.options);
        let addr = &*e as *const Effect as usize;
        let clips = self
            .lock_clips()
            .iter()
            .map(|d| {
                let template = d.instance_props.get_or_init(|| {
                    let p = props::new_set(
                        SetKind::ClipInst,
                        &d.name,
                        format!("{id} clip {}", d.name),
                        Some(log.clone()),
                    );
                    p.copy_values_from(&d.props);
                    let supported = d.props.strings(ofx::kOfxImageEffectPropSupportedComponents);
                    let rgba = cstr(ofx::kOfxImageComponentRGBA);
                    let components = if supported.is_empty() || supported.iter().any(|c| c == rgba)
                    {
                        rgba.to_string()
                    } else {
                        supported[0].clone()
                    };
                    for name in [
                        &ofx::kOfxImageEffectPropComponents[..],
                        ofx::kOfxImageClipPropUnmappedComponents,
                    ] {
                        p.set_str(name, &components);
                    }
                    let output = &*d.name == "Output";
                    let depth = cstr(if output {
                        ofx::kOfxBitDepthFloat
                    } else {
                        ofx::kOfxBitDepthNone
                    });
                    for name in [
                        &ofx::kOfxImageEffectPropPixelDepth[..],
                        ofx::kOfxImageClipPropUnmappedPixelDepth,
                    ] {
                        p.set_str(name, depth);
                    }
                    let said_connected = output || e.options.absent_clip != AbsentClip::Unconnected;
                    p.set_ints(
                        ofx::kOfxImageClipPropConnected,
                        &[i32::from(said_connected)],
                    );
                    p.set_str(
                        ofx::kOfxImageEffectPropPreMultiplication,
                        cstr(premultiplication(&e.options, output)),
                    );
                    Box::new(Template {
                        props: p,
                        what: format!("{id} clip {}", d.name).into(),
                    })
                });
                let p = template.instance(Some(log.clone()));
                Clip::boxed(Arc::clone(&d.name), p, addr)
            })
            .collect();
        *e.lock_clips() = clips;
        e
    }

    /// The handle the plugin gets.
    pub(crate) fn handle(&self) -> OfxImageEffectHandle {
        self as *const Effect as OfxImageEffectHandle
    }

    #[allow(
        clippy::vec_box,
        reason = "a clip's address is its handle: it must not move"
    )]
    pub(crate) fn lock_clips(&self) -> MutexGuard<'_, Vec<Box<Clip>>> {
        self.clips.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Runs `f` on the clip `name`.
    pub(crate) fn with_clip<R>(&self, name: &str, f: impl FnOnce(&Clip) -> R) -> Option<R> {
        self.lock_clips()
            .iter()
            .find(|c| &*c.name == name)
            .map(|c| f(c))
    }

    /// Registers a render in flight; returns its id.
    pub(crate) fn begin_render(
        &self,
        time: f64,
        scale: f64,
        rois: HashMap<String, [f64; 4]>,
        output: Layout,
        field: Option<InterlacedField>,
    ) -> u64 {
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        self.renders
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(RenderCtx {
                id,
                time,
                scale,
                rois,
                output,
                field,
            });
        id
    }

    /// Ends a render: forgets it and returns the images it left unreleased (released now),
    /// including those fetched on threads the host did not start once no render is left.
    pub(crate) fn end_render(&self, id: u64) -> Vec<String> {
        let mut renders = self.renders.lock().unwrap_or_else(PoisonError::into_inner);
        renders.retain(|r| r.id != id);
        let none_left = renders.is_empty();
        let me = self as *const Effect as usize;
        let mut images = images();
        let leaked: Vec<usize> = images
            .iter()
            .filter(|(_, i)| {
                i.effect == me && (i.render == Some(id) || (none_left && i.render.is_none()))
            })
            .map(|(h, _)| *h)
            .collect();
        leaked
            .into_iter()
            .filter_map(|h| images.remove(&h))
            .map(|i| i.what)
            .collect()
    }

    fn render_for(&self, time: f64) -> Result<Option<RenderCtx>, String> {
        let me = self as *const Effect as usize;
        let renders = self.renders.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((e, id)) = current_render() {
            if e == me {
                return Ok(renders.iter().find(|r| r.id == id).cloned());
            }
        }
        match renders.len() {
            0 => Ok(None),
            1 => Ok(renders.first().cloned()),
            n => {
                let same: Vec<&RenderCtx> = renders.iter().filter(|r| r.time == time).collect();
                match same.as_slice() {
                    [one] => Ok(Some((*one).clone())),
                    _ => Err(format!(
                        "called on a thread the host did not start while {n} renders are in flight"
                    )),
                }
            }
        }
    }
}

impl Drop for Effect {
    fn drop(&mut self) {
        handles::unregister(self as *const Effect);
        let me = self as *const Effect as usize;
        images().retain(|_, i| i.effect != me);
    }
}

impl Clip {
    fn boxed(name: Arc<str>, props: Box<PropSet>, effect: usize) -> Box<Clip> {
        let c = Box::new(Clip {
            name,
            props,
            effect,
            source: Mutex::new(None),
            instance_props: OnceLock::new(),
        });
        handles::register(&*c as *const Clip, Kind::Clip);
        c
    }

    fn handle(&self) -> OfxImageClipHandle {
        self as *const Clip as OfxImageClipHandle
    }
}

impl Drop for Clip {
    fn drop(&mut self) {
        handles::unregister(self as *const Clip);
    }
}

/// The suite the plugin fetches.
pub(crate) static SUITE: ofx::OfxImageEffectSuiteV1 = ofx::OfxImageEffectSuiteV1 {
    getPropertySet: Some(get_property_set),
    getParamSet: Some(get_param_set),
    clipDefine: Some(clip_define),
    clipGetHandle: Some(clip_get_handle),
    clipGetPropertySet: Some(clip_get_property_set),
    clipGetImage: Some(clip_get_image),
    clipReleaseImage: Some(clip_release_image),
    clipGetRegionOfDefinition: Some(clip_get_rod),
    abort: Some(abort),
    imageMemoryAlloc: Some(image_memory_alloc),
    imageMemoryFree: Some(image_memory_free),
    imageMemoryLock: Some(image_memory_lock),
    imageMemoryUnlock: Some(image_memory_unlock),
};

/// # Safety
/// `h` is any pointer; it is checked against the live handles.
unsafe fn effect<'a>(h: OfxImageEffectHandle, function: &str) -> Result<&'a Effect, OfxStatus> {
    // SAFETY: checked against the registry.
    unsafe { handles::resolve(h as *const Effect, Kind::Effect, function) }
        .ok_or(status::ERR_BAD_HANDLE)
}

/// # Safety
/// `h` is any pointer; it is checked against the live handles.
unsafe fn clip<'a>(
    h: OfxImageClipHandle,
    function: &str,
) -> Result<(&'a Clip, &'a Effect), OfxStatus> {
    // SAFETY: checked against the registry; a live clip's effect outlives it.
    unsafe {
        let c = handles::resolve(h as *const Clip, Kind::Clip, function)
            .ok_or(status::ERR_BAD_HANDLE)?;
        Ok((c, &*(c.effect as *const Effect)))
    }
}

/// # Safety
/// `s` must be NULL or a C string.
unsafe fn name<'a>(s: *const c_char, log: &Log, function: &str) -> Result<&'a str, OfxStatus> {
    if s.is_null() {
        log.violation(format!("{function}: NULL name"));
        return Err(status::ERR_UNKNOWN);
    }
    // SAFETY: checked non-NULL; a C string by contract.
    unsafe { CStr::from_ptr(s) }.to_str().map_err(|_| {
        log.violation(format!("{function}: name is not UTF-8"));
        status::ERR_UNKNOWN
    })
}

fn result(r: Result<(), OfxStatus>) -> OfxStatus {
    r.err().unwrap_or(status::OK)
}

unsafe extern "C" fn get_property_set(
    h: OfxImageEffectHandle,
    out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    // SAFETY: the handle is checked; `out` is writable by contract.
    result((|| unsafe {
        put(out, effect(h, "getPropertySet")?.props.handle());
        Ok(())
    })())
}

unsafe extern "C" fn get_param_set(
    h: OfxImageEffectHandle,
    out: *mut OfxParamSetHandle,
) -> OfxStatus {
    // SAFETY: the handle is checked; `out` is writable by contract.
    result((|| unsafe {
        put(out, effect(h, "getParamSet")?.params.handle());
        Ok(())
    })())
}

unsafe extern "C" fn clip_define(
    h: OfxImageEffectHandle,
    n: *const c_char,
    out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    let f = "clipDefine";
    // SAFETY: handles and strings are checked as the suite's contract allows.
    result((|| unsafe {
        let e = effect(h, f)?;
        let n = name(n, &e.log, f)?;
        if e.instance {
            e.log
                .violation(format!("{f}(\"{n}\"): called on an instance"));
            return Err(status::ERR_BAD_HANDLE);
        }
        let mut clips = e.lock_clips();
        if clips.iter().any(|c| &*c.name == n) {
            e.log.violation(format!("{f}(\"{n}\"): defined twice"));
            return Err(status::ERR_EXISTS);
        }
        let p = props::new_set(
            SetKind::ClipDesc,
            n,
            format!("{} clip {n}", e.id),
            Some(e.log.clone()),
        );
        p.set_str(ofx::kOfxPropType, cstr(ofx::kOfxTypeClip));
        p.set_str(ofx::kOfxPropName, n);
        put(out, p.handle());
        clips.push(Clip::boxed(n.into(), p, e as *const Effect as usize));
        Ok(())
    })())
}

unsafe extern "C" fn clip_get_handle(
    h: OfxImageEffectHandle,
    n: *const c_char,
    out: *mut OfxImageClipHandle,
    props_out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    let f = "clipGetHandle";
    // SAFETY: handles and strings are checked as the suite's contract allows.
    result((|| unsafe {
        let e = effect(h, f)?;
        let n = name(n, &e.log, f)?;
        let found = e.with_clip(n, |c| (c.handle(), c.props.handle()));
        let Some((c, p)) = found else {
            e.log
                .violation(format!("{f}(\"{n}\"): no such clip on {}", e.id));
            return Err(status::ERR_UNKNOWN);
        };
        put(out, c);
        put(props_out, p);
        Ok(())
    })())
}

unsafe extern "C" fn clip_get_property_set(
    h: OfxImageClipHandle,
    out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    // SAFETY: the handle is checked; `out` is writable by contract.
    result((|| unsafe {
        put(out, clip(h, "clipGetPropertySet")?.0.props.handle());
        Ok(())
    })())
}

/// `v` rounded down, forgiving float noise from canonical ↔ pixel round trips.
fn floor(v: f64) -> i64 {
    (v + 1e-6).floor() as i64
}

/// `v` rounded up, forgiving float noise.
pub(crate) fn ceil(v: f64) -> i64 {
    (v - 1e-6).ceil() as i64
}

/// The pixel rectangle covering canonical `r` at scale `s` for pixels of aspect ratio `par`
/// (canonical `x` is pixel `x` times `par / s`, canonical `y` pixel `y` over `s`).
fn to_pixels(r: [f64; 4], s: f64, par: f64) -> [i64; 4] {
    [
        floor(r[0] * s / par),
        floor(r[1] * s),
        ceil(r[2] * s / par),
        ceil(r[3] * s),
    ]
}

/// A clip's pixel aspect ratio (`kOfxImagePropPixelAspectRatio`, set from the clip
/// preferences; 1 by default).
pub(crate) fn clip_par(c: &Clip) -> f64 {
    match c
        .props
        .doubles(ofx::kOfxImagePropPixelAspectRatio)
        .as_slice()
    {
        [p] if p.is_finite() && *p > 0.0 => *p,
        _ => 1.0,
    }
}

/// The pixel size of a `(w, h)` image at render scale `s`: [`scaled_size`] of each side, as
/// the core sizes it.
pub(crate) fn scaled(size: (u32, u32), s: f64) -> (i64, i64) {
    (
        i64::from(scaled_size(size.0, s)),
        i64::from(scaled_size(size.1, s)),
    )
}

unsafe extern "C" fn clip_get_image(
    h: OfxImageClipHandle,
    time: OfxTime,
    region: *const OfxRectD,
    out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    let f = "clipGetImage";
    // SAFETY: the handle is checked; `region` is NULL or readable and `out` writable.
    let (c, e) = match unsafe { clip(h, f) } {
        Ok(x) => x,
        Err(s) => return s,
    };
    if out.is_null() {
        e.log
            .violation(format!("{f}({}): NULL destination", c.name));
        return status::FAILED;
    }
    if !e.instance {
        e.log
            .violation(format!("{f}({}): called on a descriptor's clip", c.name));
        return status::ERR_BAD_HANDLE;
    }
    let region = if region.is_null() {
        None
    } else {
        // SAFETY: checked non-NULL; readable by contract.
        let r = unsafe { *region };
        Some([r.x1, r.y1, r.x2, r.y2])
    };
    let ctx = match e.render_for(time) {
        Ok(ctx) => ctx,
        Err(why) => {
            e.log.violation(format!("{f}({}): {why}", c.name));
            return status::FAILED;
        }
    };
    let made = if &*c.name == "Output" {
        output_image(e, c, ctx.as_ref(), time)
    } else {
        input_image(e, c, ctx.as_ref(), time, region)
    };
    match made {
        Ok(image) => {
            let handle = image.props.handle();
            images().insert(handle as usize, image);
            // SAFETY: checked non-NULL.
            unsafe { out.write(handle) };
            status::OK
        }
        Err((s, Some(why))) => {
            e.log
                .violation(format!("{f}({}, time {time}): {why}", c.name));
            s
        }
        Err((s, None)) => s,
    }
}

type Made = Result<LiveImage, (OfxStatus, Option<String>)>;

/// `kOfxImageEffectPropPreMultiplication` of a clip's images: straight colour for inputs
/// under [`HostOptions::unpremultiplied_inputs`], else premultiplied.
fn premultiplication(options: &HostOptions, output: bool) -> &'static [u8] {
    if options.unpremultiplied_inputs && !output {
        ofx::kOfxImageUnPreMultiplied
    } else {
        ofx::kOfxImagePreMultiplied
    }
}

/// Interleaved RGBA `pixels` unpremultiplied in place: colour over alpha where alpha > 0.
fn unpremultiply(pixels: &mut [f32]) {
    for px in pixels.chunks_exact_mut(4) {
        let a = px[3];
        if a > 0.0 {
            for c in &mut px[..3] {
                *c /= a;
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn image_props(
    e: &Effect,
    c: &Clip,
    time: f64,
    scale: f64,
    components: &str,
    layout: Layout,
    fielded: bool,
    premultiplication: &'static [u8],
) -> Box<PropSet> {
    static SERIAL: AtomicU64 = AtomicU64::new(1);
    let what = format!("{} clip {} image at {time}", e.id, c.name);
    let p = props::new_set(SetKind::Image, &c.name, what, Some(e.log.clone()));
    p.set_str(ofx::kOfxPropType, cstr(ofx::kOfxTypeImage));
    p.set_str(
        ofx::kOfxImageEffectPropPixelDepth,
        cstr(ofx::kOfxBitDepthFloat),
    );
    p.set_str(ofx::kOfxImageEffectPropComponents, components);
    p.set_str(
        ofx::kOfxImageEffectPropPreMultiplication,
        cstr(premultiplication),
    );
    p.set_doubles(ofx::kOfxImageEffectPropRenderScale, &[scale, scale]);
    p.set_doubles(ofx::kOfxImagePropPixelAspectRatio, &[clip_par(c)]);
    p.put(
        cstr(ofx::kOfxImagePropData),
        props::PropValue::Pointer(vec![layout.ptr]),
    );
    p.set_ints(ofx::kOfxImagePropBounds, &layout.bounds);
    p.set_ints(ofx::kOfxImagePropRegionOfDefinition, &layout.rod);
    p.set_ints(ofx::kOfxImagePropRowBytes, &[layout.row_bytes]);
    // A field render hands over full interlaced frames (both fields), as the plugin's
    // field extraction asks.
    p.set_str(
        ofx::kOfxImagePropField,
        cstr(if fielded {
            ofx::kOfxImageFieldBoth
        } else {
            ofx::kOfxImageFieldNone
        }),
    );
    let serial = SERIAL.fetch_add(1, Ordering::Relaxed);
    p.set_str(
        ofx::kOfxImagePropUniqueIdentifier,
        &format!("{}:{time}:{serial}", c.name),
    );
    p
}

fn output_image(e: &Effect, c: &Clip, ctx: Option<&RenderCtx>, time: f64) -> Made {
    let Some(ctx) = ctx else {
        return Err((
            status::FAILED,
            Some("the output image exists only during a render".into()),
        ));
    };
    let props = image_props(
        e,
        c,
        time,
        ctx.scale,
        cstr(ofx::kOfxImageComponentRGBA),
        ctx.output,
        ctx.field.is_some(),
        ofx::kOfxImagePreMultiplied,
    );
    Ok(LiveImage {
        what: format!("{} clip {} image at {time}", e.id, c.name),
        props,
        _data: Vec::new(),
        effect: e as *const Effect as usize,
        render: Some(ctx.id),
    })
}

fn input_image(
    e: &Effect,
    c: &Clip,
    ctx: Option<&RenderCtx>,
    time: f64,
    region: Option<[f64; 4]>,
) -> Made {
    let Some(source) = c
        .source
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone()
    else {
        // Fetching an unconnected clip fails, as the spec says (not a plugin bug), or, as
        // some hosts do, gives an image without pixels.
        if e.options.absent_clip == AbsentClip::EmptyImage {
            return Ok(empty_image(e, c, time));
        }
        return Err((status::FAILED, None));
    };
    let scale = ctx.map_or(1.0, |r| r.scale);
    let (ws, hs) = scaled(source.rod, scale);
    let par = clip_par(c);
    let full = [
        0.0,
        0.0,
        f64::from(source.rod.0) * par,
        f64::from(source.rod.1),
    ];
    let roi = ctx.map(|r| r.rois.get(&*c.name).copied().unwrap_or(full));
    let wanted = region.or(roi).unwrap_or(full);
    if wanted.iter().any(|v| !v.is_finite()) {
        return Err((
            status::ERR_VALUE,
            Some(format!("region {wanted:?} is not finite")),
        ));
    }
    let px = to_pixels(wanted, scale, par);
    if let Some(roi) = roi {
        let allowed = to_pixels(roi, scale, par);
        let inside = px[0] >= allowed[0]
            && px[1] >= allowed[1]
            && px[2] <= allowed[2]
            && px[3] <= allowed[3];
        if !inside && px[0] < px[2] && px[1] < px[3] {
            return Err((status::FAILED, Some(format!(
                "region {wanted:?} (pixels {px:?}) is outside the region of interest {roi:?} (pixels {allowed:?}) declared in getRegionsOfInterest"
            ))));
        }
    }
    let asked = [px[0].max(0), px[1].max(0), px[2].min(ws), px[3].min(hs)];
    if asked[0] >= asked[2] || asked[1] >= asked[3] {
        return Err((status::FAILED, None));
    }
    // A padding host hands over more than asked, within the input's region of definition.
    let pad = if e.options.padded_images { PADDING } else { 0 };
    let b = [
        (asked[0] - pad).max(0),
        (asked[1] - pad).max(0),
        (asked[2] + pad).min(ws),
        (asked[3] + pad).min(hs),
    ];
    let window = Window::new(
        b[0] as u32,
        (hs - b[3]) as u32,
        b[2] as u32,
        (hs - b[1]) as u32,
    );
    let planes = match (source.render)(time, window, scale) {
        Ok(p) => p,
        Err(err) => {
            return Err((
                status::FAILED,
                Some(format!("the clip source failed: {err}")),
            ))
        }
    };
    if (planes.width, planes.height) != (window.width(), window.height()) {
        return Err((
            status::FAILED,
            Some(format!(
                "the clip source returned {}×{} for a {}×{} window",
                planes.width,
                planes.height,
                window.width(),
                window.height()
            )),
        ));
    }
    let declared = c.props.string(ofx::kOfxImageEffectPropComponents);
    // A host ignoring components hands an RGBA clip RGB images.
    let rgb = e.options.rgb_inputs && declared == cstr(ofx::kOfxImageComponentRGBA);
    let (components, n) = if declared == cstr(ofx::kOfxImageComponentAlpha) {
        (declared.as_str(), 1)
    } else if rgb {
        (cstr(ofx::kOfxImageComponentRGB), 3)
    } else {
        (declared.as_str(), 4)
    };
    let (w, h) = (window.width() as usize, window.height() as usize);
    let mut pixels = to_ofx(&planes, n);
    // Only RGBA images have colour to unpremultiply (RGB ones are opaque, Alpha ones matte).
    if e.options.unpremultiplied_inputs && n == 4 {
        unpremultiply(&mut pixels);
    }
    let (data, offset, row_bytes) = store(&pixels, w * n, h, e.options.padded_images);
    let bounds = [b[0] as i32, b[1] as i32, b[2] as i32, b[3] as i32];
    let props = image_props(
        e,
        c,
        time,
        scale,
        components,
        Layout {
            ptr: data[offset..].as_ptr() as usize,
            bounds,
            rod: [0, 0, ws as i32, hs as i32],
            row_bytes,
        },
        ctx.is_some_and(|r| r.field.is_some()),
        premultiplication(&e.options, false),
    );
    Ok(LiveImage {
        what: format!("{} clip {} image at {time}", e.id, c.name),
        props,
        _data: data,
        effect: e as *const Effect as usize,
        render: current_render()
            .filter(|(m, _)| *m == e as *const Effect as usize)
            .map(|(_, id)| id),
    })
}

/// An image with NULL data and empty bounds, as some hosts present an absent input.
fn empty_image(e: &Effect, c: &Clip, time: f64) -> LiveImage {
    let props = image_props(
        e,
        c,
        time,
        1.0,
        cstr(ofx::kOfxImageComponentRGBA),
        Layout {
            ptr: 0,
            bounds: [0; 4],
            rod: [0; 4],
            row_bytes: 0,
        },
        false,
        premultiplication(&e.options, false),
    );
    LiveImage {
        what: format!("{} clip {} empty image at {time}", e.id, c.name),
        props,
        _data: Vec::new(),
        effect: e as *const Effect as usize,
        render: current_render()
            .filter(|(m, _)| *m == e as *const Effect as usize)
            .map(|(_, id)| id),
    }
}

/// Stores `rows` (`h` rows bottom up, `row` floats each) as the host lays images out:
/// as they are, or (`padded`) top-down with [`ROW_SLACK`] quiet NaNs after each row.
/// Returns the store, the index of the bottom row's first float and the row bytes.
fn store(rows: &[f32], row: usize, h: usize, padded: bool) -> (Vec<f32>, usize, i32) {
    if !padded {
        return (rows.to_vec(), 0, (row * 4) as i32);
    }
    let stride = row + ROW_SLACK;
    let mut out = vec![f32::from_bits(SENTINEL_BITS); stride * h];
    for (y, src) in rows.chunks_exact(row.max(1)).enumerate().take(h) {
        let at = (h - 1 - y) * stride;
        out[at..at + row].copy_from_slice(src);
    }
    (out, h.saturating_sub(1) * stride, -((stride * 4) as i32))
}

/// Interleaved OFX pixels (rows bottom up) from raster planes, `n` floats a pixel: RGBA
/// (4) or RGB (3) (missing colour black, depth standing in for colour when only depth is
/// present, missing alpha opaque where there is colour), or alpha alone (1: alpha, else
/// red).
fn to_ofx(p: &Planes, n: usize) -> Vec<f32> {
    let alpha_only = n == 1;
    let (w, h) = (p.width as usize, p.height as usize);
    let rgb = p.rgb.as_ref().map(|c| [&c[0].data, &c[1].data, &c[2].data]);
    let depth = p.depth_z.as_ref().map(|d| [&d.data, &d.data, &d.data]);
    let colour = rgb.or(depth);
    let opaque = if colour.is_some() { 1.0 } else { 0.0 };
    let mut out = vec![0.0f32; w * h * n];
    for j in 0..h {
        let src = (h - 1 - j) * w;
        for x in 0..w {
            let i = src + x;
            let a = p.alpha.as_ref().map_or(opaque, |a| a.data[i]);
            let o = (j * w + x) * n;
            if alpha_only {
                out[o] = p
                    .alpha
                    .as_ref()
                    .map(|a| a.data[i])
                    .or(rgb.map(|c| c[0][i]))
                    .unwrap_or(0.0);
            } else {
                if let Some(c) = colour {
                    out[o] = c[0][i];
                    out[o + 1] = c[1][i];
                    out[o + 2] = c[2][i];
                }
                if n == 4 {
                    out[o + 3] = a;
                }
            }
        }
    }
    out
}

unsafe extern "C" fn clip_release_image(h: OfxPropertySetHandle) -> OfxStatus {
    match images().remove(&(h as usize)) {
        Some(_) => status::OK,
        None => {
            super::log::current().violation(format!(
                "clipReleaseImage: {h:p} is not an image the host gave out (or released twice)"
            ));
            status::ERR_BAD_HANDLE
        }
    }
}

unsafe extern "C" fn clip_get_rod(
    h: OfxImageClipHandle,
    _time: OfxTime,
    out: *mut OfxRectD,
) -> OfxStatus {
    // SAFETY: the handle is checked; `out` is writable by contract.
    let (c, e) = match unsafe { clip(h, "clipGetRegionOfDefinition") } {
        Ok(x) => x,
        Err(s) => return s,
    };
    let rod = if &*c.name == "Output" {
        *e.output_rod.lock().unwrap_or_else(PoisonError::into_inner)
    } else {
        c.source
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .map(|s| {
                [
                    0.0,
                    0.0,
                    f64::from(s.rod.0) * clip_par(c),
                    f64::from(s.rod.1),
                ]
            })
    };
    match rod {
        Some(r) => {
            // SAFETY: writable by contract.
            unsafe {
                put(
                    out,
                    OfxRectD {
                        x1: r[0],
                        y1: r[1],
                        x2: r[2],
                        y2: r[3],
                    },
                )
            };
            status::OK
        }
        None => status::FAILED,
    }
}

unsafe extern "C" fn abort(h: OfxImageEffectHandle) -> c_int {
    // SAFETY: the handle is checked.
    let _ = unsafe { effect(h, "abort") };
    0
}

/// Memory from `imageMemoryAlloc`. Boxed and registered while alive.
struct ImageMemory {
    ptr: *mut c_void,
    locks: Mutex<u32>,
}

unsafe extern "C" fn image_memory_alloc(
    h: OfxImageEffectHandle,
    n: usize,
    out: *mut OfxImageMemoryHandle,
) -> OfxStatus {
    if !h.is_null() {
        // SAFETY: the handle is checked.
        if let Err(s) = unsafe { effect(h, "imageMemoryAlloc") } {
            return s;
        }
    }
    let ptr = memory::allocate(n);
    if ptr.is_null() {
        return status::ERR_MEMORY;
    }
    let m = Box::into_raw(Box::new(ImageMemory {
        ptr,
        locks: Mutex::new(0),
    }));
    handles::register(m as *const ImageMemory, Kind::ImageMemory);
    // SAFETY: writable by contract.
    unsafe { put(out, m as OfxImageMemoryHandle) };
    status::OK
}

/// # Safety
/// `h` is any pointer; it is checked against the live handles.
unsafe fn memory<'a>(
    h: OfxImageMemoryHandle,
    function: &str,
) -> Result<&'a ImageMemory, OfxStatus> {
    // SAFETY: checked against the registry.
    unsafe { handles::resolve(h as *const ImageMemory, Kind::ImageMemory, function) }
        .ok_or(status::ERR_BAD_HANDLE)
}

unsafe extern "C" fn image_memory_free(h: OfxImageMemoryHandle) -> OfxStatus {
    let p = h as *const ImageMemory;
    // Taken from the registry in one step: of two threads freeing the same handle, only one
    // gets it; the other's is a bad handle.
    if !handles::take(p, Kind::ImageMemory) {
        handles::report_bad(p, Kind::ImageMemory, "imageMemoryFree");
        return status::ERR_BAD_HANDLE;
    }
    // SAFETY: a live handle came from Box::into_raw, and this caller alone removed it.
    let m = unsafe { Box::from_raw(p as *mut ImageMemory) };
    memory::free(m.ptr);
    status::OK
}

unsafe extern "C" fn image_memory_lock(
    h: OfxImageMemoryHandle,
    out: *mut *mut c_void,
) -> OfxStatus {
    // SAFETY: the handle is checked; `out` is writable by contract.
    result((|| unsafe {
        let m = memory(h, "imageMemoryLock")?;
        *m.locks.lock().unwrap_or_else(PoisonError::into_inner) += 1;
        put(out, m.ptr);
        Ok(())
    })())
}

unsafe extern "C" fn image_memory_unlock(h: OfxImageMemoryHandle) -> OfxStatus {
    // SAFETY: the handle is checked.
    result((|| unsafe {
        let m = memory(h, "imageMemoryUnlock")?;
        let mut locks = m.locks.lock().unwrap_or_else(PoisonError::into_inner);
        if *locks == 0 {
            super::log::current().violation("imageMemoryUnlock: not locked");
            return Err(status::FAILED);
        }
        *locks -= 1;
        Ok(())
    })())
}
