//! Per-instance data: the node, its context and the host handles fetched once at
//! `kOfxActionCreateInstance`, boxed in the effect's `kOfxPropInstanceData`.
//!
//! The handles never change after creation, so render threads share them without locks (the
//! plugin declares itself fully thread safe): every value a render needs is read from the host
//! per call, and the core's caches are internally synchronised. The mutable parts are the
//! record of messages shown to the artist and the frame's render statistics, each behind its
//! own mutex.

use std::ffi::CString;
use std::sync::Mutex;

use nerfx_graph::{ClipDesc, Node};
use openfx_sys::{
    kOfxImageEffectOutputClipName, kOfxImageEffectPropContext, kOfxPropInstanceData,
    OfxImageClipHandle, OfxImageEffectHandle, OfxParamHandle, OfxPropertySetHandle,
};

use crate::effect::{context_from_name, effect_props, param_set};
use crate::frame_stats::FrameStats;
use crate::message::Shown;
use crate::props::name;
use crate::status::{check, Failure, Result};
use crate::suites::suites;

/// A parameter handle (valid for the instance's life time).
pub struct ParamRef(pub OfxParamHandle);

/// A clip handle and its property set (valid for the instance's life time).
pub struct ClipRef {
    /// The clip.
    pub handle: OfxImageClipHandle,
    /// Its properties (connected, pixel aspect ratio, components).
    pub props: OfxPropertySetHandle,
}

/// What the plugin keeps per effect instance.
pub struct Instance {
    /// The registry node.
    pub node: &'static Node,
    /// Parameter handles, in the order of the node's parameters.
    pub params: Vec<ParamRef>,
    /// The `Output` clip.
    pub output: ClipRef,
    /// The node's input clips that exist in this context.
    pub inputs: Vec<(&'static ClipDesc, ClipRef)>,
    /// What the instance has shown the artist ([`crate::message`]).
    pub shown: Mutex<Shown>,
    /// What the renders of the frame on show counted ([`crate::frame_stats`]).
    pub frame_stats: FrameStats,
}

fn clip(effect: OfxImageEffectHandle, clip_name: &str) -> Result<ClipRef> {
    let get = suites()?
        .effect
        .clipGetHandle
        .ok_or_else(|| Failure::missing_suite("image effect suite's clipGetHandle"))?;
    let c = CString::new(clip_name).map_err(|_| Failure::failed("clip name with NUL"))?;
    let mut r = ClipRef {
        handle: std::ptr::null_mut(),
        props: std::ptr::null_mut(),
    };
    // SAFETY: a live instance handle, a C string and two out pointers.
    let status = unsafe { get(effect, c.as_ptr(), &mut r.handle, &mut r.props) };
    check(format_args!("clipGetHandle({clip_name})"), status)?;
    Ok(r)
}

/// `kOfxActionCreateInstance`: fetches the handles and stores the boxed data.
pub fn create(node: &'static Node, effect: OfxImageEffectHandle) -> Result<()> {
    let s = suites()?;
    let props = effect_props(effect)?;
    let context = context_from_name(&props.string(name(kOfxImageEffectPropContext))?)?;
    let set = param_set(effect)?;
    let get_param = s
        .param
        .paramGetHandle
        .ok_or_else(|| Failure::missing_suite("parameter suite's paramGetHandle"))?;
    let params = node
        .desc
        .params
        .iter()
        .map(|p| {
            let c = CString::new(p.name).map_err(|_| Failure::failed("parameter name with NUL"))?;
            let mut h: OfxParamHandle = std::ptr::null_mut();
            // SAFETY: the instance's parameter set, a C string, an out pointer, no props.
            let status = unsafe { get_param(set, c.as_ptr(), &mut h, std::ptr::null_mut()) };
            check(format_args!("paramGetHandle({})", p.name), status)?;
            Ok(ParamRef(h))
        })
        .collect::<Result<Vec<_>>>()?;
    let output = clip(
        effect,
        &name(kOfxImageEffectOutputClipName).to_string_lossy(),
    )?;
    let inputs = node
        .desc
        .clips
        .iter()
        .filter(|c| c.contexts.contains(&context))
        .map(|c| Ok((c, clip(effect, c.name)?)))
        .collect::<Result<Vec<_>>>()?;
    let data = Box::new(Instance {
        node,
        params,
        output,
        inputs,
        shown: Mutex::new(Shown::default()),
        frame_stats: FrameStats::default(),
    });
    let ptr = Box::into_raw(data);
    if let Err(e) = props.set_pointer(name(kOfxPropInstanceData), ptr.cast()) {
        // SAFETY: `ptr` came from `Box::into_raw` above and was not handed out.
        drop(unsafe { Box::from_raw(ptr) });
        return Err(e);
    }
    Ok(())
}

/// The instance's data.
///
/// # Safety
/// `effect` must be an instance handle of this plugin, between its create and destroy
/// actions (the host guarantees this for instance actions).
pub unsafe fn get<'a>(effect: OfxImageEffectHandle) -> Result<&'a Instance> {
    let ptr = effect_props(effect)?.pointer(name(kOfxPropInstanceData))?;
    // SAFETY: only `create` stores this pointer, and only `destroy` frees it.
    unsafe { ptr.cast::<Instance>().as_ref() }
        .ok_or_else(|| Failure::failed("no instance data: createInstance did not succeed"))
}

/// `kOfxActionDestroyInstance`: frees the data.
pub fn destroy(effect: OfxImageEffectHandle) -> Result<()> {
    let props = effect_props(effect)?;
    let ptr = props.pointer(name(kOfxPropInstanceData))?;
    if !ptr.is_null() {
        props.set_pointer(name(kOfxPropInstanceData), std::ptr::null_mut())?;
        // SAFETY: stored by `create` from `Box::into_raw`; cleared above, so freed once.
        drop(unsafe { Box::from_raw(ptr.cast::<Instance>()) });
    }
    Ok(())
}
