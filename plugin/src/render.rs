//! `kOfxImageEffectActionRender`: host images in, the core's node render, host image out.
//!
//! 1. Read the render time, window (pixel coordinates, `y` up), render scale and draft flag.
//! 2. Read every parameter at that time ([`crate::params::values_at`]).
//! 3. Place the core's raster image: a node with its own region of definition renders the
//!    `ceil(w·s) × ceil(h·s)` image at scale `s`; one whose region is its inputs' works
//!    pixel by pixel on the window alone ([`Frame`]).
//! 4. Fetch each connected input over the render window only, convert it to planes, render,
//!    and write the result into the output image inside the render window (pixels of the
//!    window outside the node's image become transparent black).
//!
//! A node that is not ready (a file parameter still empty, [`crate::params::unset_file`])
//! renders its first connected RGBA input unchanged, or transparent black, and no error: the
//! render reports which file is missing, and the action marks the node with a warning. A node
//! that rendered reports the window's statistics and its frame: the action adds them to the
//! frame's ([`crate::frame_stats`]) and warns when those say the pixels may be off.
//! When the host renders one field of fielded footage into a full-frame image
//! (`kOfxImageEffectPropFieldToRender` lower or upper), only that field's rows are written;
//! the render time may then be a half frame, at which the core interpolates the shot as at any
//! sub-frame time.

use nerfx_core::image::{Plane, Planes, Window};
use nerfx_core::render::RenderStats;
use nerfx_graph::{check_render_scale, ClipKind, RenderRequest, Rendered};
use openfx_sys::*;

use crate::coords::{Frame, PixelRect};
use crate::frame_stats::FrameKey;
use crate::images::{connected, pixel_aspect, ClipImage};
use crate::instance::Instance;
use crate::params::{unset_file, values_at};
use crate::pixels::{read_planes, write_planes, Rows};
use crate::props::{name, Props};
use crate::status::{Failure, Result};

/// Transparent black RGBA of `window`'s size (an input the host has no image for).
fn clear(window: Window) -> Planes {
    let zero = Plane::filled(window.width(), window.height(), 0.0);
    Planes {
        width: zero.width,
        height: zero.height,
        rgb: Some([zero.clone(), zero.clone(), zero.clone()]),
        alpha: Some(zero),
        depth_z: None,
        depth_ray: None,
        depth_median: None,
    }
}

/// The render scale, one number: the core scales both axes alike. Each axis must be finite and
/// in (0, 1] ([`check_render_scale`], checked before anything is sized or divided by it).
pub fn uniform_scale(scale: [f64; 2]) -> Result<f64> {
    for s in scale {
        check_render_scale(s)?;
    }
    if (scale[0] - scale[1]).abs() > 1e-9 * scale[0].abs().max(1.0) {
        return Err(Failure::failed(format!(
            "render scale {}×{}: different scales in x and y are not supported",
            scale[0], scale[1]
        )));
    }
    Ok(scale[0])
}

/// The rows to write for `kOfxImageEffectPropFieldToRender` = `field` into an image that holds
/// a full frame (`single_field` false) or one field.
pub fn field_rows(field: &str, single_field: bool) -> Rows {
    let is = |f: &'static [u8]| name(f).to_bytes() == field.as_bytes();
    if single_field {
        Rows::All
    } else if is(kOfxImageFieldLower) {
        Rows::Even
    } else if is(kOfxImageFieldUpper) {
        Rows::Odd
    } else {
        Rows::All
    }
}

/// What a render has to tell the artist.
#[derive(Debug)]
pub enum Outcome {
    /// The node rendered `window` of the frame at `time`.
    Rendered {
        /// The host's time.
        time: f64,
        /// The frame: time, render scale and quality.
        frame: FrameKey,
        /// The raster window rendered.
        window: Window,
        /// What rendering it counted (nothing for a node that only composites).
        stats: RenderStats,
        /// Connected input clips the host gave no image for: an optional one was taken as
        /// absent, a mandatory one as transparent black.
        missing: Vec<&'static str>,
    },
    /// That file parameter is empty: the node rendered its first RGBA input or nothing.
    NotReady(&'static str),
}

/// Renders one window of `instance`.
pub fn render(instance: &Instance, in_args: Props) -> Result<Outcome> {
    let node = instance.node;
    let time = in_args.double(name(kOfxPropTime))?;
    let render = PixelRect::from_ints(in_args.ints::<4>(name(kOfxImageEffectPropRenderWindow))?);
    let scale = in_args.doubles::<2>(name(kOfxImageEffectPropRenderScale))?;
    let s = uniform_scale(scale)?;
    let draft = in_args
        .int(name(kOfxImageEffectPropRenderQualityDraft))
        .is_ok_and(|v| v != 0);
    let field = in_args
        .string(name(kOfxImageEffectPropFieldToRender))
        .unwrap_or_default();
    let values = values_at(instance, time)?;
    let unset = unset_file(node, &values);
    let ready = unset.is_none();
    let rod = if ready {
        node.region_of_definition(&values, time)?
    } else {
        None
    };
    let frame = match rod {
        Some((w, h)) => Frame::of_rod(w, h, s),
        None => Frame::of_window(render),
    };
    let window = frame.raster(render);
    let mut output =
        ClipImage::fetch(&instance.output, "Output", time, None)?.ok_or_else(|| {
            Failure::failed(format!("{}: the host gave no output image", node.desc.id))
        })?;
    let rows = field_rows(&field, output.single_field);
    let mut missing = Vec::new();
    let rendered = if window.area() == 0 {
        Rendered::from(clear(window))
    } else if !ready {
        let region = render.canonical(scale, pixel_aspect(&instance.output));
        let mut planes = clear(window);
        for (clip, handle) in &instance.inputs {
            if clip.kind == ClipKind::Rgba && connected(handle)? {
                if let Some(image) = ClipImage::fetch(handle, clip.name, time, Some(region))? {
                    planes = read_planes(&image.view, frame, window, image.straight);
                }
                break;
            }
        }
        Rendered::from(planes)
    } else {
        let region = render.canonical(scale, pixel_aspect(&instance.output));
        let mut request = RenderRequest::new(time, window, s);
        request.draft = draft;
        for (clip, handle) in &instance.inputs {
            if !connected(handle)? {
                continue;
            }
            let planes = match ClipImage::fetch(handle, clip.name, time, Some(region))? {
                Some(image) => read_planes(&image.view, frame, window, image.straight),
                // A connected input the host has no image for is said (the action warns);
                // an optional one is absent (the node then does what it does without it:
                // Accumulation Matte takes the Source's alpha), a mandatory one is
                // transparent black.
                None => {
                    missing.push(clip.name);
                    if clip.optional {
                        continue;
                    }
                    clear(window)
                }
            };
            request = request.with_input(clip.name, planes);
        }
        node.render_with_stats(&values, &request)?
    };
    write_planes(
        &mut output.view,
        frame,
        window,
        render,
        rows,
        &rendered.planes,
    )
    .map_err(|e| Failure::failed(format!("{}: Output: {e}", node.desc.id)))?;
    Ok(match unset {
        Some(param) => Outcome::NotReady(param),
        None => Outcome::Rendered {
            time,
            frame: FrameKey::new(time, s, draft),
            window,
            stats: rendered.stats,
            missing,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_must_agree() {
        assert_eq!(uniform_scale([0.5, 0.5]).unwrap(), 0.5);
        let e = uniform_scale([0.5, 0.25]).unwrap_err();
        assert!(e.message.contains("0.5×0.25"), "{}", e.message);
        // Outside (0, 1] on either axis, refused before anything uses it (NaN included, which
        // a mere x == y comparison lets through).
        for bad in [0.0, -0.5, 1.5, f64::INFINITY, f64::NAN] {
            for scale in [[bad, bad], [bad, 0.5], [0.5, bad]] {
                let e = uniform_scale(scale).unwrap_err();
                assert!(
                    e.message.contains("render scale"),
                    "{scale:?}: {}",
                    e.message
                );
            }
        }
        assert_eq!(uniform_scale([1.0, 1.0]).unwrap(), 1.0);
        assert_eq!(uniform_scale([0.25, 0.25]).unwrap(), 0.25);
        assert_eq!(
            clear(Window::new(1, 1, 4, 3)).alpha.unwrap().data,
            vec![0.0; 6]
        );
    }

    #[test]
    fn one_field_into_a_full_frame_writes_its_rows_only() {
        // ofxImageEffect.h: lower = rows 0, 2, 4…; upper = rows 1, 3, 5….
        assert_eq!(field_rows("OfxFieldLower", false), Rows::Even);
        assert_eq!(field_rows("OfxFieldUpper", false), Rows::Odd);
        assert_eq!(field_rows("OfxFieldUpper", true), Rows::All);
        assert_eq!(field_rows("OfxFieldBoth", false), Rows::All);
        assert_eq!(field_rows("OfxFieldNone", false), Rows::All);
        assert_eq!(field_rows("", false), Rows::All);
    }
}
