//! The three compositing nodes: Accumulation Matte, Shadow Catcher Merge, Depth Merge. Each
//! reads its clips, calls one [`nerfx_core::composite`] function, then mixes with its input.

use super::desc::{ClipDesc, ClipKind, Context, NodeDesc, ParamDesc, ParamKind, Range};
use super::node::{single_channel, Node, RenderRequest, Rendered};
use super::values::ParamValues;
use nerfx_core::composite::{
    accumulation_matte, depth_merge, mix, shadow_catcher_merge, MatteCurve,
};
use nerfx_core::error::Result;
use nerfx_core::image::Planes;

const FILTER_GENERAL: &[Context] = &[Context::Filter, Context::General];
const GENERAL: &[Context] = &[Context::General];

fn clip(
    name: &'static str,
    hint: &'static str,
    kind: ClipKind,
    optional: bool,
    contexts: &'static [Context],
) -> ClipDesc {
    ClipDesc {
        name,
        label: name,
        hint,
        kind,
        optional,
        contexts,
    }
}

fn double(
    name: &'static str,
    label: &'static str,
    hint: &'static str,
    default: f64,
    range: Range,
) -> ParamDesc {
    ParamDesc::new(name, label, hint, ParamKind::Double { default, range })
}

fn mix_param() -> ParamDesc {
    double(
        "mix",
        "Mix",
        "Blends the result (1) with the input (0).",
        1.0,
        Range::new(0.0, 1.0),
    )
}

/// `mix` applied against the input clip `input`; identity when mix is 1 (saves a pass).
fn mixed(
    result: Planes,
    values: &ParamValues,
    request: &RenderRequest,
    input: &str,
) -> Result<Planes> {
    let m = values.double("mix")?;
    if m == 1.0 {
        return Ok(result);
    }
    mix(&result, &request.rgba_or_clear(input), m as f32)
}

/// Accumulation Matte: Source (RGB premultiplied by the accumulation) + Matte → RGBA.
pub(crate) fn accumulation_matte_node() -> Node {
    Node {
        desc: NodeDesc {
            id: "org.nerfx.AccumulationMatte",
            label: "Accumulation Matte",
            group: "NeRF",
            hint: "Turns an RGB render and its accumulation render into premultiplied RGBA, \
                   with black/white point, gamma and a floater clip on the matte.",
            contexts: FILTER_GENERAL,
            clips: vec![
                clip(
                    "Source",
                    "The RGB render (premultiplied by the accumulation).",
                    ClipKind::Rgba,
                    false,
                    FILTER_GENERAL,
                ),
                clip(
                    "Matte",
                    "The accumulation render; when absent, the Source's alpha.",
                    ClipKind::Matte,
                    true,
                    FILTER_GENERAL,
                ),
            ],
            params: vec![
                double(
                    "blackPoint",
                    "Black Point",
                    "Accumulation that becomes alpha 0.",
                    0.0,
                    Range::display(-1.0, 1.0, 0.0, 1.0),
                ),
                double(
                    "whitePoint",
                    "White Point",
                    "Accumulation that becomes alpha 1 (above the black point).",
                    1.0,
                    Range::display(0.0, 2.0, 0.0, 1.0),
                ),
                double(
                    "gamma",
                    "Gamma",
                    "alpha = t^(1/gamma): above 1 thickens the matte.",
                    1.0,
                    Range::display(0.01, 10.0, 0.2, 5.0),
                ),
                double(
                    "floaterClip",
                    "Clip Floaters",
                    "Alphas below this become 0.",
                    0.0,
                    Range::display(0.0, 1.0, 0.0, 0.2),
                ),
                mix_param(),
            ],
            frame_varying: false,
        },
        render: |values, request| {
            let source = request.rgba_or_clear("Source");
            let matte = match request.inputs.get("Matte") {
                Some(m) => single_channel(ClipKind::Matte, m),
                None => single_channel(ClipKind::Rgba, &source),
            };
            let curve = MatteCurve {
                black_point: values.double("blackPoint")? as f32,
                white_point: values.double("whitePoint")? as f32,
                gamma: values.double("gamma")? as f32,
                floater_clip: values.double("floaterClip")? as f32,
            };
            let out = accumulation_matte(&source, &matte, &curve)?;
            mixed(out, values, request, "Source").map(Rendered::from)
        },
        rod: None,
        identity: Some(|v| Ok((v.double("mix")? == 0.0).then_some("Source"))),
        output_space: None,
    }
}

/// Shadow Catcher Merge: A over B darkened by a shadow-catcher render.
pub(crate) fn shadow_catcher_merge_node() -> Node {
    Node {
        desc: NodeDesc {
            id: "org.nerfx.ShadowCatcherMerge",
            label: "Shadow Catcher Merge",
            group: "NeRF",
            hint: "A (foreground) over B (background) darkened by the shadow of a Blender \
                   shadow-catcher render, with opacity and tint.",
            contexts: GENERAL,
            clips: vec![
                clip(
                    "A",
                    "The foreground (premultiplied RGBA).",
                    ClipKind::Rgba,
                    true,
                    GENERAL,
                ),
                clip(
                    "Shadow",
                    "The shadow-catcher render: its alpha is the shadow.",
                    ClipKind::Alpha,
                    true,
                    GENERAL,
                ),
                clip(
                    "B",
                    "The background (plate).",
                    ClipKind::Rgba,
                    false,
                    GENERAL,
                ),
            ],
            params: vec![
                double(
                    "opacity",
                    "Shadow Opacity",
                    "Scales the shadow.",
                    1.0,
                    Range::new(0.0, 1.0),
                ),
                ParamDesc::new(
                    "tint",
                    "Shadow Tint",
                    "Colour the shadow lets through (black: full darkening).",
                    ParamKind::Rgb {
                        default: [0.0; 3],
                        range: Range::new(0.0, 1.0),
                    },
                ),
                mix_param(),
            ],
            frame_varying: false,
        },
        render: |values, request| {
            let shadow = match request.inputs.get("Shadow") {
                Some(s) => single_channel(ClipKind::Alpha, s),
                None => nerfx_core::image::Plane::filled(
                    request.window.width(),
                    request.window.height(),
                    0.0,
                ),
            };
            let t = values.doubles("tint")?;
            let out = shadow_catcher_merge(
                &request.rgba_or_clear("A"),
                &shadow,
                &request.rgba_or_clear("B"),
                values.double("opacity")? as f32,
                [t[0] as f32, t[1] as f32, t[2] as f32],
            )?;
            mixed(out, values, request, "B").map(Rendered::from)
        },
        rod: None,
        identity: Some(|v| Ok((v.double("mix")? == 0.0).then_some("B"))),
        output_space: None,
    }
}

/// Depth Merge: nearest first with a soft edge.
pub(crate) fn depth_merge_node() -> Node {
    Node {
        desc: NodeDesc {
            id: "org.nerfx.DepthMerge",
            label: "Depth Merge",
            group: "NeRF",
            hint: "Combines A and B nearest first by their camera-Z depths (Blender units), \
                   blending over a depth band where they are close.",
            contexts: GENERAL,
            clips: vec![
                clip(
                    "A",
                    "First image (premultiplied RGBA).",
                    ClipKind::Rgba,
                    false,
                    GENERAL,
                ),
                clip(
                    "ADepth",
                    "A's depth (camera Z; 1e10 or inf: nothing).",
                    ClipKind::Depth,
                    false,
                    GENERAL,
                ),
                clip(
                    "B",
                    "Second image (premultiplied RGBA).",
                    ClipKind::Rgba,
                    false,
                    GENERAL,
                ),
                clip(
                    "BDepth",
                    "B's depth (camera Z; 1e10 or inf: nothing).",
                    ClipKind::Depth,
                    false,
                    GENERAL,
                ),
            ],
            params: vec![
                double(
                    "softness",
                    "Softness",
                    "Width of the depth band (Blender units) over which A and B blend.",
                    0.01,
                    Range::display(0.0, 1.0e6, 0.0, 1.0),
                ),
                mix_param(),
            ],
            frame_varying: false,
        },
        render: |values, request| {
            let depth = |name: &str| single_channel(ClipKind::Depth, &request.rgba_or_clear(name));
            let out = depth_merge(
                &request.rgba_or_clear("A"),
                &depth("ADepth"),
                &request.rgba_or_clear("B"),
                &depth("BDepth"),
                values.double("softness")? as f32,
            )?;
            mixed(out, values, request, "B").map(Rendered::from)
        },
        rod: None,
        identity: Some(|v| Ok((v.double("mix")? == 0.0).then_some("B"))),
        output_space: None,
    }
}
