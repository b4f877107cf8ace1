//! `kOfxActionDescribe` and `kOfxImageEffectActionDescribeInContext`, generically from a
//! registry [`Node`]'s description.
//!
//! The plugin: label, grouping, description, the node's contexts, float pixels only, tiles and
//! multi-resolution, fully thread-safe rendering (the host may call render on many threads at
//! once), no host frame threading, one clip depth, no temporal access. In a context: the RGBA
//! `Output` clip, every registry clip that exists there (RGBA; RGBA or Alpha for mattes,
//! alphas and depths; label and optional flag: OpenFX clip descriptors have no tooltip
//! property, so a clip's hint is not published), and every parameter ([`crate::param_defs`]).
//!
//! Fielded footage: every node works pixel by pixel or renders a whole frame from a camera,
//! so inputs are fetched as full interlaced frames (`kOfxImageFieldBoth`) and the host is asked
//! to render fields twice only when parameters animate (`FieldRenderTwiceAlways` 0).
//!
//! Properties that are niceties (description, field handling, clip-preference slaves, …)
//! are set with [`optional`]: a host that does not know one must not lose the plugin.

use nerfx_graph::{ClipKind, Node, ParamKind};
use openfx_sys::*;

use crate::effect::{context_from_name, context_name, effect_props, param_set};
use crate::param_defs::define_param;
use crate::props::{name, optional, Props};
use crate::status::{check, Failure, Result, ERR_UNSUPPORTED};
use crate::suites::suites;

/// `kOfxActionDescribe`.
pub fn describe(node: &Node, effect: OfxImageEffectHandle) -> Result<()> {
    let p = effect_props(effect)?;
    let d = &node.desc;
    p.set_string(name(kOfxPropLabel), d.label)?;
    p.set_string(name(kOfxImageEffectPluginPropGrouping), d.group)?;
    optional(p.set_string(name(kOfxPropPluginDescription), d.hint));
    let contexts: Vec<&str> = d
        .contexts
        .iter()
        .map(|c| name(context_name(*c)).to_str().unwrap_or_default())
        .collect();
    p.set_strings(name(kOfxImageEffectPropSupportedContexts), &contexts)?;
    let float = name(kOfxBitDepthFloat).to_str().unwrap_or_default();
    p.set_strings(name(kOfxImageEffectPropSupportedPixelDepths), &[float])?;
    p.set_int(name(kOfxImageEffectPropSupportsTiles), 1)?;
    p.set_int(name(kOfxImageEffectPropSupportsMultiResolution), 1)?;
    let safe = name(kOfxImageEffectRenderFullySafe)
        .to_str()
        .unwrap_or_default();
    p.set_string(name(kOfxImageEffectPluginRenderThreadSafety), safe)?;
    optional(p.set_int(name(kOfxImageEffectPluginPropHostFrameThreading), 0));
    optional(p.set_int(name(kOfxImageEffectPropSupportsMultipleClipDepths), 0));
    // A generator's pixel aspect is its shot's, not the project's: it sets its clips' pixel
    // aspect in getClipPreferences, which hosts allow to plugins declaring this.
    optional(p.set_int(
        name(kOfxImageEffectPropSupportsMultipleClipPARs),
        i32::from(node.has_own_format()),
    ));
    optional(p.set_int(name(kOfxImageEffectPropTemporalClipAccess), 0));
    optional(p.set_int(name(kOfxImageEffectPluginPropFieldRenderTwiceAlways), 0));
    if node.has_output_space() && crate::colour::host_offers() {
        optional(p.set_string(crate::colour::STYLE, crate::colour::STYLE_CORE));
    }
    Ok(())
}

fn define_clip(effect: OfxImageEffectHandle, clip: &str) -> Result<Props> {
    let s = suites()?;
    let define = s
        .effect
        .clipDefine
        .ok_or_else(|| Failure::missing_suite("image effect suite's clipDefine"))?;
    let c = std::ffi::CString::new(clip).map_err(|_| Failure::failed("clip name with NUL"))?;
    let mut set: OfxPropertySetHandle = std::ptr::null_mut();
    // SAFETY: the descriptor handle of this describeInContext, a C string, an out pointer.
    check(format_args!("clipDefine({clip})"), unsafe {
        define(effect, c.as_ptr(), &mut set)
    })?;
    // SAFETY: the clip descriptor lives as long as the effect descriptor.
    Ok(unsafe { Props::new(set, s.property) })
}

/// The components a clip of `kind` accepts.
fn components(kind: ClipKind) -> Vec<&'static str> {
    let rgba = name(kOfxImageComponentRGBA).to_str().unwrap_or_default();
    let alpha = name(kOfxImageComponentAlpha).to_str().unwrap_or_default();
    match kind {
        ClipKind::Rgba => vec![rgba],
        ClipKind::Matte | ClipKind::Alpha | ClipKind::Depth => vec![rgba, alpha],
    }
}

/// `kOfxImageEffectActionDescribeInContext` for the context named in `in_args`.
pub fn describe_in_context(
    node: &Node,
    effect: OfxImageEffectHandle,
    in_args: Props,
) -> Result<()> {
    let context = context_from_name(&in_args.string(name(kOfxImageEffectPropContext))?)?;
    if !node.desc.contexts.contains(&context) {
        return Err(Failure {
            status: ERR_UNSUPPORTED,
            message: format!("{}: context {context:?} is not supported", node.desc.id),
        });
    }
    let output = define_clip(
        effect,
        &name(kOfxImageEffectOutputClipName).to_string_lossy(),
    )?;
    output.set_strings(
        name(kOfxImageEffectPropSupportedComponents),
        &components(ClipKind::Rgba),
    )?;
    optional(output.set_int(name(kOfxImageEffectPropSupportsTiles), 1));
    for c in node
        .desc
        .clips
        .iter()
        .filter(|c| c.contexts.contains(&context))
    {
        let clip = define_clip(effect, c.name)?;
        clip.set_string(name(kOfxPropLabel), c.label)?;
        clip.set_strings(
            name(kOfxImageEffectPropSupportedComponents),
            &components(c.kind),
        )?;
        clip.set_int(name(kOfxImageClipPropOptional), i32::from(c.optional))?;
        optional(clip.set_int(name(kOfxImageEffectPropSupportsTiles), 1));
        optional(clip.set_string(
            name(kOfxImageClipPropFieldExtraction),
            &name(kOfxImageFieldBoth).to_string_lossy(),
        ));
    }
    let set = param_set(effect)?;
    for p in &node.desc.params {
        define_param(set, p)?;
    }
    let slaves = clip_preference_slaves(node);
    if !slaves.is_empty() {
        optional(
            effect_props(effect)?
                .set_strings(name(kOfxImageEffectPropClipPreferencesSlaveParam), &slaves),
        );
    }
    Ok(())
}

/// The parameters whose change re-asks the clip preferences
/// (`kOfxImageEffectPropClipPreferencesSlaveParam`): files (they decide the region of
/// definition and frame variance) and, of a node with its own format
/// ([`Node::has_own_format`]), every parameter that does not animate: such a node's format,
/// frame range or time mapping (a frame offset, say) may depend on any of them, and the plugin
/// stays generic rather than naming them.
fn clip_preference_slaves(node: &Node) -> Vec<&'static str> {
    node.desc
        .params
        .iter()
        .filter(|p| matches!(p.kind, ParamKind::File) || (node.has_own_format() && !p.animates))
        .map(|p| p.name)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_parameters_of_a_node_with_its_own_format_are_clip_preference_slaves() {
        let nerf = nerfx_graph::node("org.nerfx.NeRFRender").unwrap();
        let slaves = clip_preference_slaves(nerf);
        // The two files, and the non-animating frame offset that moves the time domain.
        for p in ["file", "shot", "frameOffset"] {
            assert!(slaves.contains(&p), "{p} missing from {slaves:?}");
        }
        // Animating parameters do not change the format.
        assert!(!slaves.contains(&"overrideTransform"), "{slaves:?}");
        // A node sized by its inputs has no file and no format of its own.
        let merge = nerfx_graph::node("org.nerfx.DepthMerge").unwrap();
        assert!(clip_preference_slaves(merge).is_empty());
    }
}
