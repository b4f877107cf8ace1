//! A node: its description and the one function that renders it.

use std::collections::BTreeMap;

use super::desc::{ClipKind, NodeDesc};
use super::values::ParamValues;
use nerfx_core::error::{number, Error, Result};
use nerfx_core::image::{OutputColorSpace, Plane, Planes, Window};
use nerfx_core::render::RenderStats;

/// What one render call asks for.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderRequest {
    /// The host's time (frame number; between two frames a shot is interpolated).
    pub time: f64,
    /// The pixels to produce, in raster space at `render_scale` (top-left origin, `y` down).
    pub window: Window,
    /// Render scale in (0, 1]: 0.5 renders the image at half its size.
    pub render_scale: f64,
    /// The host asks for draft quality (scrubbing): the NeRF Render uses its draft preset.
    pub draft: bool,
    /// Input images by clip name, each exactly the window's size; absent clips are left out.
    pub inputs: BTreeMap<String, Planes>,
    /// The size of the node's whole image at `render_scale`, which the window lies in (a
    /// frame rendered in stripes asks for one stripe of it).
    pub image_size: (u32, u32),
}

impl RenderRequest {
    /// A full-quality request for `window` at `time` and `render_scale`, without inputs, of
    /// an image that ends where the window does.
    pub fn new(time: f64, window: Window, render_scale: f64) -> Self {
        RenderRequest {
            time,
            window,
            render_scale,
            draft: false,
            inputs: BTreeMap::new(),
            image_size: (window.x1, window.y1),
        }
    }

    /// The request with the input clip `name` connected to `planes`.
    pub fn with_input(mut self, name: &str, planes: Planes) -> Self {
        self.inputs.insert(name.to_string(), planes);
        self
    }

    /// The input `name` if connected, else a transparent image of the window's size.
    pub(crate) fn rgba_or_clear(&self, name: &str) -> Planes {
        self.inputs.get(name).cloned().unwrap_or_else(|| {
            let clear = Plane::filled(self.window.width(), self.window.height(), 0.0);
            Planes {
                width: clear.width,
                height: clear.height,
                rgb: Some([clear.clone(), clear.clone(), clear.clone()]),
                alpha: Some(clear),
                depth_z: None,
                depth_ray: None,
                depth_median: None,
            }
        })
    }
}

/// Refuses a render scale outside (0, 1] (0, negatives, infinities and NaN included).
///
/// A render scale is the fraction of full resolution a host asks for (proxy renders); above 1
/// or not a finite positive number, every size and coordinate derived from it is meaningless,
/// so the OpenFX plugin, the OpenFX host and [`Node::render`] all check it here, first.
pub fn check_render_scale(s: f64) -> Result<()> {
    // Written so that NaN fails: every comparison with NaN is false.
    if s.is_finite() && s > 0.0 && s <= 1.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            "render scale",
            format!("expected (0, 1], got {}", number(s)),
        ))
    }
}

/// The single channel a clip of `kind` contributes (see [`ClipKind`]); for
/// [`ClipKind::Rgba`], its alpha (opaque when only RGB is present).
pub fn single_channel(kind: ClipKind, planes: &Planes) -> Plane {
    let red = planes.rgb.as_ref().map(|rgb| &rgb[0]);
    let pick = match kind {
        ClipKind::Depth => planes.depth_z.as_ref().or(red).or(planes.alpha.as_ref()),
        ClipKind::Matte => red.or(planes.alpha.as_ref()),
        ClipKind::Alpha | ClipKind::Rgba => planes.alpha.as_ref(),
    };
    let fill = if kind == ClipKind::Rgba && red.is_some() {
        1.0
    } else {
        0.0
    };
    pick.cloned()
        .unwrap_or_else(|| Plane::filled(planes.width, planes.height, fill))
}

/// A node's output and what rendering it did.
#[derive(Clone, Debug, PartialEq)]
pub struct Rendered {
    /// RGBA premultiplied planes of the request's window.
    pub planes: Planes,
    /// The marcher's counts, summed over the renders the output was made from (none for a
    /// node that only composites its inputs); [`RenderStats::warning`] says what a user
    /// should hear about them.
    pub stats: RenderStats,
}

/// An image made without marching anything.
impl From<Planes> for Rendered {
    fn from(planes: Planes) -> Self {
        Rendered {
            planes,
            stats: RenderStats::default(),
        }
    }
}

/// Renders a node: validated values and a checked request in, output planes out.
pub type RenderFn = fn(&ParamValues, &RenderRequest) -> Result<Rendered>;
/// A node's region of definition at a time (full-resolution pixels).
pub type RodFn = fn(&ParamValues, f64) -> Result<(u32, u32)>;
/// The frames a node can produce, `(first, last)` in the host's time, or `None` when that
/// is not known with these values.
pub type TimeDomainFn = fn(&ParamValues) -> Result<Option<(f64, f64)>>;
/// The width of a node's pixels over their height at a time (2 for an anamorphic plate
/// squeezed 2:1).
pub type PixelAspectFn = fn(&ParamValues, f64) -> Result<f64>;

/// The image format of a node that makes its own images (a generator) rather than taking its
/// inputs' (the compositing nodes).
#[derive(Clone, Copy, Debug)]
pub struct Format {
    /// Its region of definition at a time.
    pub size: RodFn,
    /// The frames it can produce (a shot's range); `None`: any frame.
    pub time_domain: Option<TimeDomainFn>,
    /// Its pixel aspect ratio; `None`: square pixels.
    pub pixel_aspect: Option<PixelAspectFn>,
}
/// The input clip a node passes through unchanged with these values (e.g. `mix` = 0).
pub type IdentityFn = fn(&ParamValues) -> Result<Option<&'static str>>;

/// What a node's output image holds, for a host's colour management.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputSpace {
    /// Colour in this space.
    Colour(OutputColorSpace),
    /// Not colour (depth, a matte): not to be colour managed.
    Data,
}

/// The space of a node's output with these values.
pub type OutputSpaceFn = fn(&ParamValues) -> Result<OutputSpace>;

/// A node of the registry: described once, rendered once.
#[derive(Debug)]
pub struct Node {
    /// The description adapters publish.
    pub desc: NodeDesc,
    pub(crate) render: RenderFn,
    /// The node's own format; `None`: its inputs' (region of definition, pixel aspect and
    /// frame range).
    pub(crate) rod: Option<Format>,
    pub(crate) identity: Option<IdentityFn>,
    /// The space of its output; `None`: its inputs' (it composites them as they come).
    pub(crate) output_space: Option<OutputSpaceFn>,
}

impl Node {
    /// Default values for every parameter.
    pub fn defaults(&'static self) -> ParamValues {
        ParamValues::defaults(&self.desc)
    }

    /// Whether the node says the space of its output itself ([`Node::output_space`]).
    pub fn has_output_space(&self) -> bool {
        self.output_space.is_some()
    }

    /// What the node's output holds with `values`; `None` for a node whose output is in its
    /// inputs' space.
    pub fn output_space(&self, values: &ParamValues) -> Result<Option<OutputSpace>> {
        self.own(values)?;
        self.output_space
            .map(|f| f(values))
            .transpose()
            .map_err(|e| self.in_context(e))
    }

    fn own(&self, values: &ParamValues) -> Result<()> {
        if values.desc().id != self.desc.id {
            return Err(Error::invalid(
                self.desc.id,
                format!("given the parameter values of {}", values.desc().id),
            ));
        }
        Ok(())
    }

    /// Prefixes errors with the node's identifier unless they already name it.
    fn in_context(&self, e: Error) -> Error {
        match e {
            Error::Invalid { what, message } if !what.starts_with(self.desc.id) => {
                Error::invalid(format!("{}: {what}", self.desc.id), message)
            }
            other => other,
        }
    }

    /// The output for `request`: RGBA premultiplied planes of the window's size. Refuses
    /// values of another node, unknown or missing clips, inputs not of the window's size and
    /// a render scale outside (0, 1]; every error names the node.
    pub fn render(&self, values: &ParamValues, request: &RenderRequest) -> Result<Planes> {
        self.render_with_stats(values, request).map(|r| r.planes)
    }

    /// [`Node::render`], with what the render did: the counts behind a warning the node's
    /// user should see (rays at their sample budget, NaN densities).
    pub fn render_with_stats(
        &self,
        values: &ParamValues,
        request: &RenderRequest,
    ) -> Result<Rendered> {
        self.own(values)?;
        let id = self.desc.id;
        check_render_scale(request.render_scale).map_err(|e| self.in_context(e))?;
        let (w, h) = (request.window.width(), request.window.height());
        for (name, planes) in &request.inputs {
            if self.desc.clip(name).is_none() {
                return Err(Error::invalid(format!("{id}: clip {name}"), "no such clip"));
            }
            if (planes.width, planes.height) != (w, h) {
                return Err(Error::invalid(
                    format!("{id}: clip {name}"),
                    format!(
                        "image is {}×{}, the render window {w}×{h}",
                        planes.width, planes.height
                    ),
                ));
            }
        }
        if let Some(c) = self
            .desc
            .clips
            .iter()
            .find(|c| !c.optional && !request.inputs.contains_key(c.name))
        {
            return Err(Error::invalid(
                format!("{id}: clip {}", c.name),
                "not connected",
            ));
        }
        (self.render)(values, request).map_err(|e| self.in_context(e))
    }

    /// The region of definition `(width, height)` in full-resolution pixels, or `None` when
    /// it is that of the inputs (the compositing nodes).
    pub fn region_of_definition(
        &self,
        values: &ParamValues,
        time: f64,
    ) -> Result<Option<(u32, u32)>> {
        self.own(values)?;
        self.rod
            .map(|format| (format.size)(values, time))
            .transpose()
            .map_err(|e| self.in_context(e))
    }

    /// Whether the node makes its own images (its own region of definition, pixel aspect and
    /// frame range) rather than taking its inputs'.
    pub fn has_own_format(&self) -> bool {
        self.rod.is_some()
    }

    /// The pixel aspect ratio (pixel width over height) of the node's images with `values` at
    /// `time`: 1 for a node making its own images without saying otherwise, `None` for a node
    /// sized by its inputs (theirs). The region of definition stays in pixels; an OpenFX
    /// host's canonical coordinates stretch `x` by this ratio.
    pub fn pixel_aspect(&self, values: &ParamValues, time: f64) -> Result<Option<f64>> {
        self.own(values)?;
        let Some(format) = self.rod else {
            return Ok(None);
        };
        let par = match format.pixel_aspect {
            Some(f) => f(values, time).map_err(|e| self.in_context(e))?,
            None => 1.0,
        };
        if !(par.is_finite() && par > 0.0) {
            return Err(Error::invalid(
                format!("{}: pixel aspect", self.desc.id),
                format!("expected a number > 0, got {}", number(par)),
            ));
        }
        Ok(Some(par))
    }

    /// The frames `(first, last)` the node can produce with `values` (host time, inclusive),
    /// or `None` when it can produce any (a node sized by its inputs, or one without a
    /// range). A host asks this of a generator to size its timeline to the shot.
    pub fn time_domain(&self, values: &ParamValues) -> Result<Option<(f64, f64)>> {
        self.own(values)?;
        match self.rod.and_then(|format| format.time_domain) {
            Some(f) => f(values).map_err(|e| self.in_context(e)),
            None => Ok(None),
        }
    }

    /// The input clip the node would pass through unchanged with `values`, if any.
    pub fn identity(&self, values: &ParamValues) -> Result<Option<&'static str>> {
        self.own(values)?;
        match self.identity {
            Some(f) => f(values).map_err(|e| self.in_context(e)),
            None => Ok(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_scale_must_be_finite_and_in_zero_one() {
        for s in [1.0, 0.25, 0.5, 1e-6] {
            assert!(check_render_scale(s).is_ok(), "{s}");
        }
        for s in [
            0.0,
            -0.0,
            -0.5,
            1.0 + 1e-12,
            2.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            let e = check_render_scale(s).unwrap_err().to_string();
            assert!(e.contains("render scale"), "{s}: {e}");
        }
    }
}
