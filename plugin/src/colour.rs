//! OpenFX colour management (OpenFX 1.5, `ofxColour.h`), for hosts that offer it.
//!
//! The headers `openfx-sys` binds are OpenFX 1.4's, which have no colour management: the
//! property and action names are defined here. A node that says the space of its output
//! ([`nerfx_graph::Node::output_space`]: a NeRF Render) declares the core native style on
//! its descriptor when the host's descriptor offers any style but none, and answers
//! `GetOutputColourspace` with its Output Colour Space by its native identifier
//! ([`nerfx_core::image::OutputColorSpace::ofx_name`]), or `Raw` for a depth or matte output.
//! Other nodes composite their inputs as they come and leave the host its default (the
//! output is in the space of the first input).

use std::ffi::CStr;

/// `kOfxImageEffectPropColourManagementStyle`: on the host descriptor (what it offers) and the
/// plugin descriptor (what the plugin uses).
pub const STYLE: &CStr = c"OfxImageEffectPropColourManagementStyle";
/// `kOfxImageEffectPropColourManagementNone`.
pub const STYLE_NONE: &str = "OfxImageEffectPropColourManagementNone";
/// `kOfxImageEffectPropColourManagementCore`: the core native colourspaces.
pub const STYLE_CORE: &str = "OfxImageEffectPropColourManagementCore";
/// `kOfxImageEffectActionGetOutputColourspace`.
pub const GET_OUTPUT_COLOURSPACE: &CStr = c"OfxImageEffectActionGetOutputColourspace";
/// `kOfxImageClipPropColourspace`: the out-argument of that action.
pub const CLIP_COLOURSPACE: &CStr = c"OfxImageClipPropColourspace";
/// `kOfxColourspaceRaw`: values that are not colour.
pub const RAW: &str = "Raw";

/// Whether the host offers colour management (a style other than none).
pub fn host_offers() -> bool {
    crate::suites::host_string(STYLE).is_some_and(|s| !s.is_empty() && s != STYLE_NONE)
}
