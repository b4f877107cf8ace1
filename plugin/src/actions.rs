//! The actions of one registry node, by name: what each one does with the core.
//!
//! - load: fetch the host's suites; unload: the last one forgets them ([`crate::suites`]).
//! - describe / describeInContext: [`crate::describe`].
//! - createInstance / destroyInstance: [`crate::instance`].
//! - getRegionOfDefinition: the node's own size `(w, h)` → canonical `(0, 0, w·par, h)`
//!   with `par` the output's pixel aspect ratio (whatever render scale the host passes: the
//!   region is canonical); nodes sized by their inputs reply default.
//! - A node with a file parameter still empty (a node just created, before the artist picked
//!   its files) is *not ready*: where its region of definition needs the file it replies
//!   default, it renders transparent black or passes its first connected RGBA input through,
//!   and it never posts an error — hosts ask for the region at once, and a dialog before the
//!   artist could pick a file is noise. Wherever it learns the file is missing (region of
//!   definition, isIdentity — a host that honours it never renders the node —, an edit, a
//!   render) it marks the node with a persistent warning naming the missing file
//!   ([`message::warn`], posted once, not per tile or query), so a node left empty does not
//!   render black without a word. A file that is set but unreadable is an error.
//! - A connected input clip the host gives no image for is said in the frame's warning,
//!   naming the clip: an optional one is taken as not connected, a mandatory one as
//!   transparent black.
//! - getRegionsOfInterest: each connected input needs exactly the region asked for (every
//!   node works pixel by pixel).
//! - getClipPreferences: float everywhere, RGBA output premultiplied, Alpha or RGBA inputs
//!   as each clip accepts, frame varying as the node says; the node's pixel aspect
//!   ([`Node::pixel_aspect`], a shot's `pixel_aspect_x / pixel_aspect_y`) for the output and
//!   the connected inputs (`OfxImageClipPropPAR_`: inputs are asked for on the output's pixel
//!   grid, as every node works pixel by pixel), taken at the first frame of its time domain
//!   (the action has no time). A node not ready, or whose files fail, keeps the host's
//!   default: the error is the region of definition's and the render's to report.
//! - isIdentity: the clip the node passes through with these values, at the same time
//!   (the host's time, whole frame or not: `kOfxPropTime` is set as an out-argument).
//! - getTimeDomain: the node's frame range ([`Node::time_domain`]: a NeRF Render's is its
//!   shot's) as `kOfxImageEffectPropFrameRange`; default when it has none or is not ready.
//!   The 1.4 header has hosts ask only in the General context; hosts also ask generators
//!   (Natron), and the answer does not depend on the context.
//! - begin/endSequenceRender: nothing to prepare (files are cached on first use).
//! - render: [`crate::render`]. A frame whose renders counted rays stopped at their sample
//!   budget or NaN densities marks the node with a persistent warning saying how many and
//!   what to do ([`nerfx_core::render::RenderStats::warning`]); the render succeeds, and the next
//!   clean frame clears it.
//! - instanceChanged: an edit by the artist or the plugin (`kOfxPropChangeReason`) clears the
//!   instance's persistent error (the next action re-checks); a change because the time
//!   moved changes nothing.
//! - purgeCaches: drops the core's cached files.
//! - GetOutputColourspace (OpenFX 1.5): the node's output space by its native identifier
//!   ([`crate::colour`]).
//!
//! Anything else is replied the host's default.

use std::ffi::{c_void, CStr};

use nerfx_graph::{ClipKind, Node, OutputSpace};
use openfx_sys::*;

use crate::images::{connected, pixel_aspect};
use crate::instance::{self, Instance};
use crate::message::{self, Target};
use crate::params::{unset_file, values_at};
use crate::props::{name, Props};
use crate::status::{Failure, Result, OK, REPLY_DEFAULT};
use crate::suites::{self, suites};
use crate::{describe, render};

/// Wraps an action argument (`null` for actions without one).
fn props(set: OfxPropertySetHandle, what: &str) -> Result<Props> {
    if set.is_null() {
        return Err(Failure::failed(format!("the host passed no {what}")));
    }
    // SAFETY: a property set the host passed for the duration of this action.
    Ok(unsafe { Props::new(set, suites()?.property) })
}

/// Where an error in `action` on `handle` is reported.
pub fn message_target(action: &CStr, handle: *const c_void) -> Target {
    let is = |a: &'static [u8]| action == name(a);
    let h = handle.cast_mut();
    if handle.is_null() || is(kOfxActionLoad) || is(kOfxActionUnload) {
        Target::Plugin
    } else if is(kOfxActionDescribe) || is(kOfxImageEffectActionDescribeInContext) {
        Target::Descriptor(h)
    } else {
        Target::Instance(h)
    }
}

/// Whether `reason` (`kOfxPropChangeReason`) is an edit, not the time moving.
fn is_edit(reason: &str) -> bool {
    reason.as_bytes() != name(kOfxChangeTime).to_bytes()
}

/// Runs `action` of `node`.
pub fn run(
    node: &'static Node,
    action: &CStr,
    handle: *const c_void,
    in_args: OfxPropertySetHandle,
    out_args: OfxPropertySetHandle,
) -> Result<OfxStatus> {
    let is = |a: &'static [u8]| action == name(a);
    let effect: OfxImageEffectHandle = handle.cast_mut().cast();
    if is(kOfxActionLoad) {
        suites::load()?;
        return Ok(OK);
    }
    if is(kOfxActionUnload) {
        suites::unload();
        return Ok(OK);
    }
    if is(kOfxActionDescribe) {
        describe::describe(node, effect)?;
        return Ok(OK);
    }
    if is(kOfxImageEffectActionDescribeInContext) {
        describe::describe_in_context(node, effect, props(in_args, "inArgs")?)?;
        return Ok(OK);
    }
    if is(kOfxActionCreateInstance) {
        instance::create(node, effect)?;
        return Ok(OK);
    }
    if is(kOfxActionDestroyInstance) {
        instance::destroy(effect)?;
        return Ok(OK);
    }
    if is(kOfxActionPurgeCaches) {
        nerfx_graph::purge_caches();
        return Ok(OK);
    }
    if is(kOfxActionInstanceChanged) {
        // A host that passes no reason is taken to mean an edit.
        let edit = props(in_args, "inArgs")
            .and_then(|p| p.string(name(kOfxPropChangeReason)))
            .map_or(true, |r| is_edit(&r));
        if edit {
            // SAFETY: an instance action, between create and destroy.
            let inst = unsafe { instance::get(effect) }?;
            message::reset(effect.cast(), &inst.shown);
            inst.frame_stats.reset();
            // An edit that leaves a file empty (or empties one) says so at once.
            let time = props(in_args, "inArgs")
                .and_then(|p| p.double(name(kOfxPropTime)))
                .unwrap_or(0.0);
            warn_if_not_ready(inst, effect, time);
        }
        return Ok(OK);
    }
    if is(kOfxImageEffectActionBeginSequenceRender) || is(kOfxImageEffectActionEndSequenceRender) {
        return Ok(OK);
    }
    if action == crate::colour::GET_OUTPUT_COLOURSPACE {
        // SAFETY: an instance action, between create and destroy.
        let inst = unsafe { instance::get(effect) }?;
        return output_colourspace(inst, props(out_args, "outArgs")?);
    }
    let known = [
        kOfxImageEffectActionGetRegionOfDefinition.as_slice(),
        kOfxImageEffectActionGetRegionsOfInterest,
        kOfxImageEffectActionGetClipPreferences,
        kOfxImageEffectActionIsIdentity,
        kOfxImageEffectActionGetTimeDomain,
        kOfxImageEffectActionRender,
    ];
    if !known.iter().any(|a| action.to_bytes_with_nul() == *a) {
        return Ok(REPLY_DEFAULT);
    }
    // SAFETY: these actions are instance actions, called between create and destroy.
    let inst = unsafe { instance::get(effect) }?;
    if is(kOfxImageEffectActionGetRegionOfDefinition) {
        region_of_definition(
            inst,
            effect,
            props(in_args, "inArgs")?,
            props(out_args, "outArgs")?,
        )
    } else if is(kOfxImageEffectActionGetRegionsOfInterest) {
        regions_of_interest(inst, props(in_args, "inArgs")?, props(out_args, "outArgs")?)
    } else if is(kOfxImageEffectActionGetClipPreferences) {
        clip_preferences(inst, props(out_args, "outArgs")?)
    } else if is(kOfxImageEffectActionIsIdentity) {
        is_identity(
            inst,
            effect,
            props(in_args, "inArgs")?,
            props(out_args, "outArgs")?,
        )
    } else if is(kOfxImageEffectActionGetTimeDomain) {
        time_domain(inst, props(out_args, "outArgs")?)
    } else {
        let node = inst.node.desc.label;
        match render::render(inst, props(in_args, "inArgs")?)? {
            render::Outcome::Rendered {
                time,
                frame,
                window,
                stats,
                missing,
            } => {
                // Under the record's lock: tiles rendered at once post in the order they count.
                inst.frame_stats
                    .record(frame, window, stats, &missing, |frame_stats, missing| {
                        let parts: Vec<String> = missing
                            .iter()
                            .map(|clip| missing_input(inst.node, clip))
                            .chain(frame_stats.warning())
                            .collect();
                        if parts.is_empty() {
                            message::succeeded(effect.cast(), &inst.shown);
                        } else {
                            let text = format!("{node}, frame {time}: {}", parts.join("; "));
                            message::warn(effect.cast(), &inst.shown, &text);
                        }
                    });
            }
            render::Outcome::NotReady(param) => {
                message::warn(effect.cast(), &inst.shown, &not_ready(inst.node, param));
            }
        }
        Ok(OK)
    }
}

/// The warning of a node whose file parameter `param` is empty.
fn not_ready(node: &Node, param: &str) -> String {
    let label = node.desc.param(param).map_or(param, |p| p.label);
    format!(
        "{}: no {label} chosen; it renders nothing of its own until one is",
        node.desc.label
    )
}

/// What a render says of a connected input clip `clip` the host gave no image for.
fn missing_input(node: &Node, clip: &str) -> String {
    let optional = node.desc.clip(clip).is_some_and(|c| c.optional);
    let taken = if optional {
        "taken as not connected"
    } else {
        "taken as transparent black"
    };
    format!("the {clip} clip is connected but the host gave no image for it; it was {taken}")
}

/// Marks the node with its not-ready warning when a file parameter is empty at `time`: a
/// host may learn it from any action (a host that honours isIdentity never renders a node
/// that passes its Source through), so each says it, once.
fn warn_if_not_ready(inst: &Instance, effect: OfxImageEffectHandle, time: f64) {
    if let Ok(values) = values_at(inst, time) {
        if let Some(param) = unset_file(inst.node, &values) {
            message::warn(effect.cast(), &inst.shown, &not_ready(inst.node, param));
        }
    }
}

fn region_of_definition(
    inst: &Instance,
    effect: OfxImageEffectHandle,
    in_args: Props,
    out: Props,
) -> Result<OfxStatus> {
    let time = in_args.double(name(kOfxPropTime))?;
    let values = values_at(inst, time)?;
    let unset = unset_file(inst.node, &values);
    if unset.is_some() {
        warn_if_not_ready(inst, effect, time);
    }
    let rod = match inst.node.region_of_definition(&values, time) {
        Err(_) if unset.is_some() => return Ok(REPLY_DEFAULT),
        rod => rod?,
    };
    match rod {
        Some((w, h)) => {
            let par = pixel_aspect(&inst.output);
            let rod = [0.0, 0.0, f64::from(w) * par, f64::from(h)];
            out.set_doubles(name(kOfxImageEffectPropRegionOfDefinition), &rod)?;
            Ok(OK)
        }
        None => Ok(REPLY_DEFAULT),
    }
}

/// GetOutputColourspace: a node that says its output's space answers it (at the start of
/// its time domain: the action has no time, and what decides the space does not animate in
/// practice); others, and a node not ready, leave the host its default.
fn output_colourspace(inst: &Instance, out: Props) -> Result<OfxStatus> {
    let values = values_at(inst, 0.0)?;
    if unset_file(inst.node, &values).is_some() {
        return Ok(REPLY_DEFAULT);
    }
    let space = match inst.node.output_space(&values)? {
        Some(OutputSpace::Colour(space)) => space.ofx_name(),
        Some(OutputSpace::Data) => crate::colour::RAW,
        None => return Ok(REPLY_DEFAULT),
    };
    out.set_string(crate::colour::CLIP_COLOURSPACE, space)?;
    Ok(OK)
}

fn time_domain(inst: &Instance, out: Props) -> Result<OfxStatus> {
    // The action has no time; what decides the range (files, frame offset) does not animate.
    let values = values_at(inst, 0.0)?;
    if unset_file(inst.node, &values).is_some() {
        return Ok(REPLY_DEFAULT);
    }
    match inst.node.time_domain(&values)? {
        Some((first, last)) => {
            out.set_doubles(name(kOfxImageEffectPropFrameRange), &[first, last])?;
            Ok(OK)
        }
        None => Ok(REPLY_DEFAULT),
    }
}

fn regions_of_interest(inst: &Instance, in_args: Props, out: Props) -> Result<OfxStatus> {
    let roi = in_args.doubles::<4>(name(kOfxImageEffectPropRegionOfInterest))?;
    let mut set = false;
    for (clip, handle) in &inst.inputs {
        if connected(handle)? {
            let prop = std::ffi::CString::new(format!("OfxImageClipPropRoI_{}", clip.name))
                .map_err(|_| Failure::failed("clip name with NUL"))?;
            out.set_doubles(&prop, &roi)?;
            set = true;
        }
    }
    Ok(if set { OK } else { REPLY_DEFAULT })
}

fn clip_preferences(inst: &Instance, out: Props) -> Result<OfxStatus> {
    let text = |c: &'static [u8]| name(c).to_string_lossy().into_owned();
    let (float, rgba, alpha) = (
        text(kOfxBitDepthFloat),
        text(kOfxImageComponentRGBA),
        text(kOfxImageComponentAlpha),
    );
    let prop = |prefix: &str, clip: &str| {
        std::ffi::CString::new(format!("{prefix}{clip}"))
            .map_err(|_| Failure::failed("clip name with NUL"))
    };
    let output = text(kOfxImageEffectOutputClipName);
    out.set_string(&prop("OfxImageClipPropComponents_", &output)?, &rgba)?;
    out.set_string(&prop("OfxImageClipPropDepth_", &output)?, &float)?;
    for (clip, handle) in &inst.inputs {
        if !connected(handle)? {
            continue;
        }
        let components = prop("OfxImageClipPropComponents_", clip.name)?;
        // Mattes, alphas and depths may stay Alpha; everything else is asked for as RGBA.
        let keep_alpha = clip.kind != ClipKind::Rgba && out.string(&components)? == alpha;
        if !keep_alpha {
            out.set_string(&components, &rgba)?;
        }
        out.set_string(&prop("OfxImageClipPropDepth_", clip.name)?, &float)?;
    }
    out.set_string(
        name(kOfxImageEffectPropPreMultiplication),
        &text(kOfxImagePreMultiplied),
    )?;
    out.set_int(
        name(kOfxImageEffectFrameVarying),
        i32::from(inst.node.desc.frame_varying),
    )?;
    if let Some(par) = node_pixel_aspect(inst) {
        out.set_double(&prop("OfxImageClipPropPAR_", &output)?, par)?;
        for (clip, handle) in &inst.inputs {
            if connected(handle)? {
                out.set_double(&prop("OfxImageClipPropPAR_", clip.name)?, par)?;
            }
        }
    }
    Ok(OK)
}

/// The node's own pixel aspect at the start of its time domain (time 0 without one), if it
/// has one and can say.
fn node_pixel_aspect(inst: &Instance) -> Option<f64> {
    let values = values_at(inst, 0.0).ok()?;
    if unset_file(inst.node, &values).is_some() {
        return None;
    }
    let time = inst
        .node
        .time_domain(&values)
        .ok()?
        .map_or(0.0, |(first, _)| first);
    let values = values_at(inst, time).ok()?;
    inst.node.pixel_aspect(&values, time).ok()?
}

fn is_identity(
    inst: &Instance,
    effect: OfxImageEffectHandle,
    in_args: Props,
    out: Props,
) -> Result<OfxStatus> {
    let time = in_args.double(name(kOfxPropTime))?;
    let values = values_at(inst, time)?;
    let clip = if unset_file(inst.node, &values).is_some() {
        warn_if_not_ready(inst, effect, time);
        inst.inputs
            .iter()
            .find(|(c, _)| c.kind == ClipKind::Rgba)
            .map(|(c, _)| c.name)
    } else {
        inst.node.identity(&values)?
    };
    let Some(clip) = clip else {
        return Ok(REPLY_DEFAULT);
    };
    let Some((_, handle)) = inst.inputs.iter().find(|(c, _)| c.name == clip) else {
        return Ok(REPLY_DEFAULT);
    };
    if !connected(handle)? {
        return Ok(REPLY_DEFAULT);
    }
    out.set_string(name(kOfxPropName), clip)?;
    out.set_double(name(kOfxPropTime), time)?;
    Ok(OK)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_go_to_instances_only_in_instance_actions() {
        let h = 8usize as *const c_void;
        let target = |a: &'static [u8]| message_target(name(a), h);
        assert!(matches!(target(kOfxActionLoad), Target::Plugin));
        assert!(matches!(target(kOfxActionDescribe), Target::Descriptor(_)));
        assert!(matches!(
            target(kOfxImageEffectActionDescribeInContext),
            Target::Descriptor(_)
        ));
        assert!(matches!(
            target(kOfxImageEffectActionRender),
            Target::Instance(_)
        ));
        assert!(matches!(
            target(kOfxImageEffectActionGetRegionOfDefinition),
            Target::Instance(_)
        ));
        assert!(matches!(
            message_target(name(kOfxImageEffectActionRender), std::ptr::null()),
            Target::Plugin
        ));
    }

    #[test]
    fn only_the_time_moving_is_not_an_edit() {
        assert!(!is_edit("OfxChangeTime"));
        assert!(is_edit("OfxChangeUserEdited"));
        assert!(is_edit("OfxChangePluginEdited"));
    }
}
