//! An effect instance: parameters, connected inputs, and the actions a render needs.

use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use openfx_sys as ofx;

use super::bundle::{context_name, failure, Bundle, Plugin};
use super::effect::{self, Effect, Layout, RenderScope, GUARD, SENTINEL_BITS};
use super::log::Message;
use super::options::{ChangeReason, InterlacedField, PADDING, ROW_SLACK};
use super::props::{args, PropSet, PropValue};
use super::source::ClipSource;
use super::spec::{cstr, ParamType};
use super::status;
use nerfx_core::error::{Error, Result};
use nerfx_core::image::{Plane, Planes, Window};
use nerfx_graph::{check_render_scale, Context, Value};

#[derive(Clone, Copy, PartialEq, Eq)]
enum Safety {
    Unsafe,
    Instance,
    Fully,
}

impl Bundle {
    /// An instance of `id` in `context` (describe, describeInContext, createInstance).
    pub fn instance(&self, id: &str, context: Context) -> Result<Instance> {
        Instance::create(self, id, context)
    }
}

/// A plugin instance. `render` (and the other render-time actions) may be called from many
/// threads at once; the host serialises them as the plugin's declared thread safety asks.
pub struct Instance {
    bundle: Bundle,
    plugin: usize,
    context: Context,
    effect: Box<Effect>,
    _descriptor: Arc<Effect>,
    safety: Safety,
    render_lock: Mutex<()>,
}

impl Instance {
    pub(crate) fn create(bundle: &Bundle, id: &str, context: Context) -> Result<Instance> {
        let (descriptor, plugin) = bundle.shared_descriptor(id, context)?;
        let plugin_index = bundle
            .plugin_ids()
            .iter()
            .position(|p| p == &plugin.id)
            .unwrap_or(0);
        let effect = descriptor.instantiate(context_name(context));
        let safety = match descriptor
            .props
            .string(ofx::kOfxImageEffectPluginRenderThreadSafety)
            .as_str()
        {
            s if s == cstr(ofx::kOfxImageEffectRenderFullySafe) => Safety::Fully,
            s if s == cstr(ofx::kOfxImageEffectRenderUnsafe) => Safety::Unsafe,
            _ => Safety::Instance,
        };
        let instance = Instance {
            bundle: bundle.clone(),
            plugin: plugin_index,
            context,
            effect,
            _descriptor: descriptor,
            safety,
            render_lock: Mutex::new(()),
        };
        {
            let _main = instance.main();
            instance.run("createInstance", ofx::kOfxActionCreateInstance, None, None)?;
        }
        instance.clip_preferences()?;
        Ok(instance)
    }

    /// The handle the plugin gets for this instance.
    pub(crate) fn effect_handle(&self) -> ofx::OfxImageEffectHandle {
        self.effect.handle()
    }

    fn plugin(&self) -> &Plugin {
        // The index came from the same binary's plugin list.
        self.bundle
            .binary
            .plugin(&self.bundle.plugin_ids()[self.plugin])
            .unwrap_or_else(|_| unreachable!("the plugin list of a loaded binary does not change"))
    }

    fn main(&self) -> MutexGuard<'_, ()> {
        self.bundle
            .binary
            .main_lock
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }

    fn render_guard(&self) -> Option<MutexGuard<'_, ()>> {
        let lock = match self.safety {
            Safety::Fully => return None,
            Safety::Instance => &self.render_lock,
            Safety::Unsafe => &self.bundle.binary.render_lock,
        };
        Some(lock.lock().unwrap_or_else(PoisonError::into_inner))
    }

    fn run(
        &self,
        what: &str,
        action: &[u8],
        in_args: Option<&PropSet>,
        out_args: Option<&PropSet>,
    ) -> Result<status::Status> {
        let handle = self.effect.handle() as *const c_void;
        self.plugin()
            .run(&self.bundle, what, action, handle, in_args, out_args)
    }

    fn args(&self, out: bool, what: &str, values: &[(&[u8], PropValue)]) -> Box<PropSet> {
        let named: Vec<(&str, PropValue)> = values
            .iter()
            .map(|(n, v)| (super::spec::cstr_dyn(n), v.clone()))
            .collect();
        let side = if out { "outArgs" } else { "inArgs" };
        args(
            out,
            format!("{} {what} {side}", self.effect.id),
            &named,
            self.bundle.log.clone(),
        )
    }

    fn input_clips(&self) -> Vec<String> {
        self.effect
            .lock_clips()
            .iter()
            .filter(|c| &*c.name != "Output")
            .map(|c| c.name.to_string())
            .collect()
    }

    /// Sets a parameter, checked against its declared type and range: `Double` for double
    /// parameters, `Int` for integers, `Bool` for booleans, `Choice` (an index) for choices,
    /// `Text` for string and custom parameters (file paths, the matrix string), `Doubles`
    /// for RGB, RGBA and 2D/3D doubles. Then asks the plugin for its clip preferences again.
    pub fn set_param(&mut self, name: &str, value: &Value) -> Result<()> {
        let id = self.effect.id.clone();
        let what = format!("{id}: parameter {name}");
        let set = self.effect.params.with(name, |p| {
            let v = match (p.ty, value) {
                (ParamType::Double, Value::Double(x)) => PropValue::Double(vec![*x]),
                (ParamType::Integer, Value::Int(i)) => {
                    PropValue::Int(vec![i32::try_from(*i)
                        .map_err(|_| format!("{i} does not fit an OFX integer"))?])
                }
                (ParamType::Boolean, Value::Bool(b)) => PropValue::Int(vec![i32::from(*b)]),
                (ParamType::Choice, Value::Choice(i)) => PropValue::Int(vec![
                    i32::try_from(*i).map_err(|_| format!("option {i} is out of range"))?
                ]),
                (ParamType::String | ParamType::Custom, Value::Text(s)) => {
                    PropValue::String(vec![s.clone()])
                }
                (
                    ParamType::Double2D | ParamType::Double3D | ParamType::Rgb | ParamType::Rgba,
                    Value::Doubles(v),
                ) => PropValue::Double(v.clone()),
                (t, v) => return Err(format!("a {} parameter cannot take {v:?}", t.name())),
            };
            p.set_value(&v)
        });
        match set {
            None => return Err(Error::invalid(what, "no such parameter")),
            Some(Err(why)) => return Err(Error::invalid(what, why)),
            Some(Ok(())) => {}
        }
        self.clip_preferences()
    }

    /// The current value of a parameter (as the plugin would read it).
    pub fn param(&self, name: &str) -> Result<PropValue> {
        self.effect.params.with(name, |p| p.value()).ok_or_else(|| {
            Error::invalid(
                format!("{}: parameter {name}", self.effect.id),
                "no such parameter",
            )
        })
    }

    /// Connects the input clip `clip` to `source`, then asks for the clip preferences again.
    pub fn connect(&mut self, clip: &str, source: ClipSource) -> Result<()> {
        let id = self.effect.id.clone();
        let found = self.effect.with_clip(clip, |c| {
            if &*c.name == "Output" {
                return false;
            }
            let float = cstr(ofx::kOfxBitDepthFloat);
            c.props.set_str(ofx::kOfxImageEffectPropPixelDepth, float);
            c.props
                .set_str(ofx::kOfxImageClipPropUnmappedPixelDepth, float);
            c.props.set_ints(ofx::kOfxImageClipPropConnected, &[1]);
            *c.source.lock().unwrap_or_else(PoisonError::into_inner) = Some(source);
            true
        });
        if found != Some(true) {
            return Err(Error::invalid(
                format!("{id}: clip {clip}"),
                format!(
                    "no such input clip (inputs: {})",
                    self.input_clips().join(", ")
                ),
            ));
        }
        self.clip_preferences()
    }

    /// getClipPreferences: the plugin's choices are checked (components it declared for the
    /// clip) and applied to the clip properties.
    fn clip_preferences(&self) -> Result<()> {
        let clips: Vec<(String, String, f64)> = self
            .effect
            .lock_clips()
            .iter()
            .map(|c| {
                (
                    c.name.to_string(),
                    c.props.string(ofx::kOfxImageEffectPropComponents),
                    effect::clip_par(c),
                )
            })
            .collect();
        let mut names = Vec::new();
        for (c, components, par) in &clips {
            names.push((
                format!("OfxImageClipPropComponents_{c}"),
                PropValue::String(vec![components.clone()]),
            ));
            names.push((
                format!("OfxImageClipPropDepth_{c}"),
                PropValue::String(vec![cstr(ofx::kOfxBitDepthFloat).to_string()]),
            ));
            names.push((
                format!("OfxImageClipPropPAR_{c}"),
                PropValue::Double(vec![*par]),
            ));
        }
        let fixed: [(&[u8], PropValue); 6] = [
            (
                ofx::kOfxImageEffectPropFrameRate,
                PropValue::Double(vec![24.0]),
            ),
            (
                ofx::kOfxImagePropPixelAspectRatio,
                PropValue::Double(vec![1.0]),
            ),
            (
                ofx::kOfxImageEffectPropPreMultiplication,
                PropValue::String(vec![cstr(ofx::kOfxImagePreMultiplied).to_string()]),
            ),
            (
                ofx::kOfxImageClipPropContinuousSamples,
                PropValue::Int(vec![0]),
            ),
            (ofx::kOfxImageEffectFrameVarying, PropValue::Int(vec![0])),
            (
                ofx::kOfxImageClipPropFieldOrder,
                PropValue::String(vec![cstr(ofx::kOfxImageFieldNone).to_string()]),
            ),
        ];
        let mut values: Vec<(&[u8], PropValue)> = names
            .iter()
            .map(|(n, v)| (n.as_bytes(), v.clone()))
            .collect();
        values.extend(fixed);
        let out = self.args(true, "getClipPreferences", &values);
        {
            let _main = self.main();
            self.run(
                "getClipPreferences",
                ofx::kOfxImageEffectActionGetClipPreferences,
                None,
                Some(&out),
            )?;
        }
        let log = &self.bundle.log;
        let may_set_par = self
            .effect
            .props
            .int(ofx::kOfxImageEffectPropSupportsMultipleClipPARs)
            != 0;
        for c in self.effect.lock_clips().iter() {
            let chosen = out.string(format!("OfxImageClipPropComponents_{}", c.name).as_bytes());
            let supported = c.props.strings(ofx::kOfxImageEffectPropSupportedComponents);
            if !supported.contains(&chosen) {
                log.violation(format!("{}: getClipPreferences chose {chosen} for clip {}, which it does not support ({})", self.effect.id, c.name, supported.join(", ")));
                continue;
            }
            c.props.set_str(ofx::kOfxImageEffectPropComponents, &chosen);
            let par = out.doubles(format!("OfxImageClipPropPAR_{}", c.name).as_bytes());
            match par.as_slice() {
                [p] if p.is_finite() && *p > 0.0 => {
                    if *p != 1.0 && !may_set_par {
                        log.violation(format!("{}: getClipPreferences set the pixel aspect ratio {p} on clip {} without declaring kOfxImageEffectPropSupportsMultipleClipPARs", self.effect.id, c.name));
                    } else {
                        c.props.set_doubles(ofx::kOfxImagePropPixelAspectRatio, &[*p]);
                    }
                }
                other => log.violation(format!(
                    "{}: getClipPreferences set the pixel aspect ratio {other:?} on clip {}, not a number > 0",
                    self.effect.id, c.name
                )),
            }
            if &*c.name == "Output" {
                let premult = out.string(ofx::kOfxImageEffectPropPreMultiplication);
                c.props
                    .set_str(ofx::kOfxImageEffectPropPreMultiplication, &premult);
            }
        }
        Ok(())
    }

    /// The region of definition at `time`: `(width, height)` in full-resolution pixels (the
    /// plugin's canonical region, whose `x` is stretched by the output's pixel aspect ratio,
    /// brought back to pixels). A region not starting at the origin is refused (the core's
    /// images start there).
    pub fn region_of_definition(&self, time: f64) -> Result<(u32, u32)> {
        let default = match self.context {
            Context::Generator => [0.0, 0.0, 1920.0, 1080.0],
            _ => {
                let mut r = [0.0f64; 4];
                for c in self.effect.lock_clips().iter() {
                    if let Some(s) = c
                        .source
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .as_ref()
                    {
                        r[2] = r[2].max(f64::from(s.rod.0) * effect::clip_par(c));
                        r[3] = r[3].max(f64::from(s.rod.1));
                    }
                }
                r
            }
        };
        let in_args = self.args(
            false,
            "getRegionOfDefinition",
            &[
                (ofx::kOfxPropTime, PropValue::Double(vec![time])),
                (
                    ofx::kOfxImageEffectPropRenderScale,
                    PropValue::Double(vec![1.0, 1.0]),
                ),
            ],
        );
        let out = self.args(
            true,
            "getRegionOfDefinition",
            &[(
                ofx::kOfxImageEffectPropRegionOfDefinition,
                PropValue::Double(default.to_vec()),
            )],
        );
        {
            let _g = self.render_guard();
            self.run(
                "getRegionOfDefinition",
                ofx::kOfxImageEffectActionGetRegionOfDefinition,
                Some(&in_args),
                Some(&out),
            )?;
        }
        let r = out.doubles(ofx::kOfxImageEffectPropRegionOfDefinition);
        let what = format!("{}: region of definition at {time}", self.effect.id);
        let ok = r.len() == 4
            && r.iter().all(|v| v.is_finite())
            && r[0] == 0.0
            && r[1] == 0.0
            && r[2] >= 0.0
            && r[3] >= 0.0
            && r[2] <= f64::from(u32::MAX)
            && r[3] <= f64::from(u32::MAX);
        if !ok {
            return Err(Error::invalid(what, format!("{r:?} is not [0, 0, w, h]")));
        }
        *self
            .effect
            .output_rod
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some([r[0], r[1], r[2], r[3]]);
        // Canonical x is pixels times the output's pixel aspect ratio.
        let par = self.output_par();
        Ok((effect::ceil(r[2] / par) as u32, effect::ceil(r[3]) as u32))
    }

    /// The pixel aspect ratio (pixel width over height) of the output, as the plugin's clip
    /// preferences last set it (1 unless it said otherwise): what a writer records with the
    /// image.
    pub fn pixel_aspect(&self) -> f64 {
        self.output_par()
    }

    fn output_par(&self) -> f64 {
        self.effect
            .with_clip("Output", effect::clip_par)
            .unwrap_or(1.0)
    }

    /// The frames the effect can produce, `(first, last)`, by getTimeDomain; `None` when it
    /// replies default (the host's default: its non-optional inputs' range, else infinite).
    /// The 1.4 header allows the action only in the General context; like Natron, this host
    /// also asks generators, whose range is otherwise unknown. In the Filter context the
    /// host decides the range and asks nothing: `None`. A range that is not two finite
    /// numbers in order is a violation and an error.
    pub fn time_domain(&self) -> Result<Option<(f64, f64)>> {
        if !matches!(self.context, Context::General | Context::Generator) {
            return Ok(None);
        }
        let infinite = [f64::from(i32::MIN), f64::from(i32::MAX)];
        let out = self.args(
            true,
            "getTimeDomain",
            &[(
                ofx::kOfxImageEffectPropFrameRange,
                PropValue::Double(infinite.to_vec()),
            )],
        );
        let s = {
            let _main = self.main();
            self.run(
                "getTimeDomain",
                ofx::kOfxImageEffectActionGetTimeDomain,
                None,
                Some(&out),
            )?
        };
        if s == status::REPLY_DEFAULT {
            return Ok(None);
        }
        let r = out.doubles(ofx::kOfxImageEffectPropFrameRange);
        if r.len() != 2 || !r.iter().all(|v| v.is_finite()) || r[0] > r[1] {
            let m = format!("getTimeDomain gave the frame range {r:?}, not [first, last]");
            self.bundle
                .log
                .violation(format!("{}: {m}", self.effect.id));
            return Err(Error::invalid(&self.effect.id, m));
        }
        Ok(Some((r[0], r[1])))
    }

    /// The OFX render window of a raster `window` at scale `s` for an output of height
    /// `hs` pixels at that scale.
    fn ofx_window(window: Window, hs: i64) -> [i32; 4] {
        [
            window.x0 as i32,
            (hs - i64::from(window.y1)) as i32,
            window.x1 as i32,
            (hs - i64::from(window.y0)) as i32,
        ]
    }

    /// [`check_render_scale`], the error naming this instance's effect.
    fn check_scale(&self, s: f64) -> Result<()> {
        check_render_scale(s).map_err(|e| match e {
            Error::Invalid { what, message } => {
                Error::invalid(format!("{}: {what}", self.effect.id), message)
            }
            other => other,
        })
    }

    /// The input clip the plugin passes through unchanged for this render, if any.
    pub fn is_identity(
        &self,
        time: f64,
        window: Window,
        render_scale: f64,
    ) -> Result<Option<String>> {
        self.check_scale(render_scale)?;
        let rod = self.region_of_definition(time)?;
        let (_, hs) = effect::scaled(rod, render_scale);
        let in_args = self.args(
            false,
            "isIdentity",
            &[
                (ofx::kOfxPropTime, PropValue::Double(vec![time])),
                (
                    ofx::kOfxImageEffectPropFieldToRender,
                    PropValue::String(vec![cstr(ofx::kOfxImageFieldNone).to_string()]),
                ),
                (
                    ofx::kOfxImageEffectPropRenderWindow,
                    PropValue::Int(Self::ofx_window(window, hs).to_vec()),
                ),
                (
                    ofx::kOfxImageEffectPropRenderScale,
                    PropValue::Double(vec![render_scale, render_scale]),
                ),
            ],
        );
        let out = self.args(
            true,
            "isIdentity",
            &[
                (ofx::kOfxPropName, PropValue::String(vec![String::new()])),
                (ofx::kOfxPropTime, PropValue::Double(vec![time])),
            ],
        );
        let s = {
            let _g = self.render_guard();
            self.run(
                "isIdentity",
                ofx::kOfxImageEffectActionIsIdentity,
                Some(&in_args),
                Some(&out),
            )?
        };
        if s == status::REPLY_DEFAULT {
            return Ok(None);
        }
        let name = out.string(ofx::kOfxPropName);
        if !self.input_clips().contains(&name) {
            self.bundle.log.violation(format!(
                "{}: isIdentity named \"{name}\", not an input clip",
                self.effect.id
            ));
            return Err(Error::invalid(
                &self.effect.id,
                format!("isIdentity named \"{name}\", not an input clip"),
            ));
        }
        Ok(Some(name))
    }

    /// OpenFX 1.5's GetOutputColourspace, given the host's `preferred` colourspaces: the
    /// colourspace the plugin says its output is in, or `None` when it replies default (the
    /// output is in its first input's space).
    pub fn output_colourspace(&self, preferred: &[&str]) -> Result<Option<String>> {
        use super::spec::{CLIP_COLOURSPACE, GET_OUTPUT_COLOURSPACE, PREFERRED_COLOURSPACES};
        let preferred = preferred.iter().map(|s| s.to_string()).collect();
        let in_args = self.args(
            false,
            "GetOutputColourspace",
            &[(PREFERRED_COLOURSPACES, PropValue::String(preferred))],
        );
        let out = self.args(
            true,
            "GetOutputColourspace",
            &[(CLIP_COLOURSPACE, PropValue::String(vec![String::new()]))],
        );
        let s = self.run(
            "GetOutputColourspace",
            GET_OUTPUT_COLOURSPACE,
            Some(&in_args),
            Some(&out),
        )?;
        if s == status::REPLY_DEFAULT {
            return Ok(None);
        }
        Ok(Some(out.string(CLIP_COLOURSPACE)))
    }

    /// The regions of interest for a render (canonical), by input clip.
    fn regions_of_interest(
        &self,
        time: f64,
        canonical: [f64; 4],
        s: f64,
    ) -> Result<HashMap<String, [f64; 4]>> {
        let inputs = self.input_clips();
        let in_args = self.args(
            false,
            "getRegionsOfInterest",
            &[
                (ofx::kOfxPropTime, PropValue::Double(vec![time])),
                (
                    ofx::kOfxImageEffectPropRenderScale,
                    PropValue::Double(vec![s, s]),
                ),
                (
                    ofx::kOfxImageEffectPropRegionOfInterest,
                    PropValue::Double(canonical.to_vec()),
                ),
            ],
        );
        let names: Vec<String> = inputs
            .iter()
            .map(|c| format!("OfxImageClipPropRoI_{c}"))
            .collect();
        let values: Vec<(&[u8], PropValue)> = names
            .iter()
            .map(|n| (n.as_bytes(), PropValue::Double(canonical.to_vec())))
            .collect();
        let out = self.args(true, "getRegionsOfInterest", &values);
        self.run(
            "getRegionsOfInterest",
            ofx::kOfxImageEffectActionGetRegionsOfInterest,
            Some(&in_args),
            Some(&out),
        )?;
        Ok(inputs
            .into_iter()
            .zip(&names)
            .map(|(c, n)| {
                let r = out.doubles(n.as_bytes());
                (c, [r[0], r[1], r[2], r[3]])
            })
            .collect())
    }

    /// Renders `window` (raster, `y` down, at `render_scale`) at `time`: getRegionsOfInterest,
    /// then render into a guarded buffer; returns premultiplied RGBA planes of the window's
    /// size. A write outside the window, a pixel left unwritten or an image left unreleased
    /// is a violation and an error.
    pub fn render(
        &self,
        time: f64,
        window: Window,
        render_scale: f64,
        draft: bool,
    ) -> Result<Planes> {
        self.render_impl(time, window, render_scale, draft, None)
    }

    /// Renders one field of interlaced footage as a host does that renders fields separately:
    /// `kOfxImageEffectPropFieldToRender` is `field`, the output image is a full frame holding
    /// both fields (`kOfxImagePropField` both, as are the input images), and the plugin must
    /// write exactly the rows of `field` in the window (OFX rows counted from the bottom of
    /// the image, [`InterlacedField::has_row`]): a row of the other field written, or one of
    /// this field left unwritten, is a violation and an error. The other field's rows come
    /// back transparent black.
    pub fn render_field(
        &self,
        time: f64,
        window: Window,
        render_scale: f64,
        field: InterlacedField,
    ) -> Result<Planes> {
        self.render_impl(time, window, render_scale, false, Some(field))
    }

    fn render_impl(
        &self,
        time: f64,
        window: Window,
        render_scale: f64,
        draft: bool,
        field: Option<InterlacedField>,
    ) -> Result<Planes> {
        let s = render_scale;
        self.check_scale(s)?;
        let id = self.effect.id.clone();
        let rod = self.region_of_definition(time)?;
        let (ws, hs) = effect::scaled(rod, s);
        let bounds = Self::ofx_window(window, hs);
        let par = self.output_par();
        let canonical = [
            f64::from(bounds[0]) * par / s,
            f64::from(bounds[1]) / s,
            f64::from(bounds[2]) * par / s,
            f64::from(bounds[3]) / s,
        ];
        let (w, h) = (window.width() as usize, window.height() as usize);
        let padded = self.bundle.options.padded_images;
        let mut buffer = OutputBuffer::new(w, h, padded);
        let output = buffer.layout(bounds, [0, 0, ws as i32, hs as i32]);
        let field_name = cstr(match field {
            None => ofx::kOfxImageFieldNone,
            Some(InterlacedField::Lower) => ofx::kOfxImageFieldLower,
            Some(InterlacedField::Upper) => ofx::kOfxImageFieldUpper,
        });
        let in_args = self.args(
            false,
            "render",
            &[
                (ofx::kOfxPropTime, PropValue::Double(vec![time])),
                (
                    ofx::kOfxImageEffectPropFieldToRender,
                    PropValue::String(vec![field_name.to_string()]),
                ),
                (
                    ofx::kOfxImageEffectPropRenderWindow,
                    PropValue::Int(bounds.to_vec()),
                ),
                (
                    ofx::kOfxImageEffectPropRenderScale,
                    PropValue::Double(vec![s, s]),
                ),
                (
                    ofx::kOfxImageEffectPropSequentialRenderStatus,
                    PropValue::Int(vec![0]),
                ),
                (
                    ofx::kOfxImageEffectPropInteractiveRenderStatus,
                    PropValue::Int(vec![0]),
                ),
                (
                    ofx::kOfxImageEffectPropRenderQualityDraft,
                    PropValue::Int(vec![i32::from(draft)]),
                ),
            ],
        );
        let (result, leaked) = {
            let _g = self.render_guard();
            let rois = self.regions_of_interest(time, canonical, s)?;
            let render_id = self.effect.begin_render(time, s, rois, output, field);
            let scope =
                RenderScope::enter(Some((&*self.effect as *const Effect as usize, render_id)));
            let handle = self.effect.handle() as *const c_void;
            let (st, said) = self.plugin().call(
                &self.bundle,
                ofx::kOfxImageEffectActionRender,
                handle,
                Some(&in_args),
                None,
            );
            drop(scope);
            let leaked = self.effect.end_render(render_id);
            (
                if st == status::OK {
                    Ok(())
                } else {
                    Err(failure(&id, "render", st, &said))
                },
                leaked,
            )
        };
        result?;
        let log = &self.bundle.log;
        if !leaked.is_empty() {
            let m = format!(
                "render at {time}: images not released: {}",
                leaked.join(", ")
            );
            log.violation(format!("{id}: {m}"));
            return Err(Error::invalid(&id, m));
        }
        // Rows of the window that are the plugin's to write.
        let mine = |oy: i64| field.is_none_or(|f| f.has_row(i64::from(bounds[1]) + oy));
        buffer.check(&mine).map_err(|m| {
            log.violation(format!("{id}: render at {time} of {window:?}: {m}"));
            Error::invalid(&id, format!("render at {time}: {m}"))
        })?;
        Ok(buffer.to_planes(&mine))
    }

    fn sequence(&self, what: &str, action: &[u8], first: f64, last: f64, s: f64) -> Result<()> {
        self.check_scale(s)?;
        let in_args = self.args(
            false,
            what,
            &[
                (
                    ofx::kOfxImageEffectPropFrameRange,
                    PropValue::Double(vec![first, last]),
                ),
                (
                    ofx::kOfxImageEffectPropFrameStep,
                    PropValue::Double(vec![1.0]),
                ),
                (ofx::kOfxPropIsInteractive, PropValue::Int(vec![0])),
                (
                    ofx::kOfxImageEffectPropRenderScale,
                    PropValue::Double(vec![s, s]),
                ),
                (
                    ofx::kOfxImageEffectPropSequentialRenderStatus,
                    PropValue::Int(vec![0]),
                ),
                (
                    ofx::kOfxImageEffectPropInteractiveRenderStatus,
                    PropValue::Int(vec![0]),
                ),
                (
                    ofx::kOfxImageEffectPropRenderQualityDraft,
                    PropValue::Int(vec![0]),
                ),
            ],
        );
        let _g = self.render_guard();
        self.run(what, action, Some(&in_args), None).map(|_| ())
    }

    /// beginSequenceRender for frames `first..=last`.
    pub fn begin_sequence(&self, first: f64, last: f64, render_scale: f64) -> Result<()> {
        self.sequence(
            "beginSequenceRender",
            ofx::kOfxImageEffectActionBeginSequenceRender,
            first,
            last,
            render_scale,
        )
    }

    /// endSequenceRender for frames `first..=last`.
    pub fn end_sequence(&self, first: f64, last: f64, render_scale: f64) -> Result<()> {
        self.sequence(
            "endSequenceRender",
            ofx::kOfxImageEffectActionEndSequenceRender,
            first,
            last,
            render_scale,
        )
    }

    /// Tells the plugin the user edited `param` (beginInstanceChanged, instanceChanged,
    /// endInstanceChanged, at time 0 and render scale 1).
    pub fn instance_changed(&self, param: &str) -> Result<()> {
        self.instance_changed_with_reason(param, ChangeReason::UserEdited)
    }

    /// Tells the plugin `param` changed for `reason` (`kOfxPropChangeReason` in the in-args
    /// of beginInstanceChanged, instanceChanged and endInstanceChanged), at time 0 and
    /// render scale 1.
    pub fn instance_changed_with_reason(&self, param: &str, reason: ChangeReason) -> Result<()> {
        if self.effect.params.with(param, |_| ()).is_none() {
            return Err(Error::invalid(
                format!("{}: parameter {param}", self.effect.id),
                "no such parameter",
            ));
        }
        let reason = cstr(match reason {
            ChangeReason::UserEdited => ofx::kOfxChangeUserEdited,
            ChangeReason::PluginEdited => ofx::kOfxChangePluginEdited,
            ChangeReason::Time => ofx::kOfxChangeTime,
        });
        let reason = PropValue::String(vec![reason.to_string()]);
        let begin = self.args(
            false,
            "beginInstanceChanged",
            &[(ofx::kOfxPropChangeReason, reason.clone())],
        );
        let changed = self.args(
            false,
            "instanceChanged",
            &[
                (
                    ofx::kOfxPropType,
                    PropValue::String(vec![cstr(ofx::kOfxTypeParameter).to_string()]),
                ),
                (
                    ofx::kOfxPropName,
                    PropValue::String(vec![param.to_string()]),
                ),
                (ofx::kOfxPropChangeReason, reason),
                (ofx::kOfxPropTime, PropValue::Double(vec![0.0])),
                (
                    ofx::kOfxImageEffectPropRenderScale,
                    PropValue::Double(vec![1.0, 1.0]),
                ),
            ],
        );
        let _main = self.main();
        self.run(
            "beginInstanceChanged",
            ofx::kOfxActionBeginInstanceChanged,
            Some(&begin),
            None,
        )?;
        self.run(
            "instanceChanged",
            ofx::kOfxActionInstanceChanged,
            Some(&changed),
            None,
        )?;
        self.run(
            "endInstanceChanged",
            ofx::kOfxActionEndInstanceChanged,
            Some(&begin),
            None,
        )?;
        Ok(())
    }

    /// The persistent message the plugin set on this instance (message suite V2) and has
    /// not cleared since.
    pub fn persistent_message(&self) -> Option<Message> {
        self.effect
            .persistent
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// purgeCaches.
    pub fn purge_caches(&self) -> Result<()> {
        let _main = self.main();
        self.run("purgeCaches", ofx::kOfxActionPurgeCaches, None, None)
            .map(|_| ())
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        let _main = self.main();
        let handle = self.effect.handle() as *const c_void;
        let (s, said) = self.plugin().call(
            &self.bundle,
            ofx::kOfxActionDestroyInstance,
            handle,
            None,
            None,
        );
        if s != status::OK && s != status::REPLY_DEFAULT {
            self.bundle
                .log
                .violation(failure(&self.effect.id, "destroyInstance", s, &said).to_string());
        }
    }
}

/// The output buffer of a render: the window with a [`GUARD`] border of sentinels, rows
/// stored bottom-up, or top-down with [`ROW_SLACK`] spare floats each for a host with
/// [`HostOptions::padded_images`](super::HostOptions), whose image bounds then reach
/// [`PADDING`] pixels past the window.
struct OutputBuffer {
    data: Vec<f32>,
    w: usize,
    h: usize,
    /// Floats per stored row.
    stride: usize,
    padded: bool,
}

impl OutputBuffer {
    fn new(w: usize, h: usize, padded: bool) -> Self {
        let stride = (w + 2 * GUARD) * 4 + if padded { ROW_SLACK } else { 0 };
        OutputBuffer {
            data: vec![f32::from_bits(SENTINEL_BITS); stride * (h + 2 * GUARD)],
            w,
            h,
            stride,
            padded,
        }
    }

    /// The stored row of window row `oy` (`y` up, from −[`GUARD`]).
    fn row(&self, oy: i64) -> usize {
        let r = (oy + GUARD as i64) as usize;
        if self.padded {
            self.h + 2 * GUARD - 1 - r
        } else {
            r
        }
    }

    /// The index of window pixel `(ox, oy)` (`y` up, both from −[`GUARD`]).
    fn index(&self, ox: i64, oy: i64) -> usize {
        self.row(oy) * self.stride + (ox + GUARD as i64) as usize * 4
    }

    /// The output image's layout for a render window of OFX bounds `window`.
    fn layout(&mut self, window: [i32; 4], rod: [i32; 4]) -> Layout {
        let pad = if self.padded { PADDING } else { 0 };
        let at = self.index(-pad, -pad);
        let bytes = (self.stride * 4) as i32;
        let p = pad as i32;
        Layout {
            ptr: self.data[at..].as_mut_ptr() as usize,
            bounds: [window[0] - p, window[1] - p, window[2] + p, window[3] + p],
            rod,
            row_bytes: if self.padded { -bytes } else { bytes },
        }
    }

    /// Checks that every pixel of the window in a row that is `mine` was written and that
    /// nothing else was (the guard border, the spare floats, the other field's rows).
    fn check(&self, mine: &dyn Fn(i64) -> bool) -> std::result::Result<(), String> {
        let (w, h, g) = (self.w as i64, self.h as i64, GUARD as i64);
        for oy in -g..h + g {
            for ox in -g..w + g {
                let i = self.index(ox, oy);
                let px = &self.data[i..i + 4];
                let untouched = px.iter().all(|v| v.to_bits() == SENTINEL_BITS);
                let written = px.iter().all(|v| v.to_bits() != SENTINEL_BITS);
                let inside = (0..w).contains(&ox) && (0..h).contains(&oy);
                if inside && mine(oy) {
                    if !written {
                        return Err(format!("left window pixel ({ox}, {oy}) (y up) unwritten"));
                    }
                } else if !untouched {
                    let what = if inside {
                        "a row of the other field"
                    } else {
                        "outside the render window"
                    };
                    return Err(format!("wrote {what} at window pixel ({ox}, {oy}) (y up)"));
                }
            }
            let r = self.row(oy) * self.stride;
            let spare = &self.data[r + (self.w + 2 * GUARD) * 4..r + self.stride];
            if spare.iter().any(|v| v.to_bits() != SENTINEL_BITS) {
                return Err(format!(
                    "wrote the spare floats after window row {oy} (y up)"
                ));
            }
        }
        Ok(())
    }

    /// Raster RGBA planes of the window; rows not `mine` are transparent black.
    fn to_planes(&self, mine: &dyn Fn(i64) -> bool) -> Planes {
        let (w, h) = (self.w, self.h);
        let mut ch: [Vec<f32>; 4] = Default::default();
        for c in &mut ch {
            c.reserve(w * h);
        }
        for r in 0..h {
            let oy = (h - 1 - r) as i64;
            for x in 0..w {
                let i = self.index(x as i64, oy);
                for (k, c) in ch.iter_mut().enumerate() {
                    c.push(if mine(oy) { self.data[i + k] } else { 0.0 });
                }
            }
        }
        let [r, g, b, a] = ch;
        let p = |data| Plane {
            width: w as u32,
            height: h as u32,
            data,
        };
        Planes {
            width: w as u32,
            height: h as u32,
            rgb: Some([p(r), p(g), p(b)]),
            alpha: Some(p(a)),
            depth_z: None,
            depth_ray: None,
            depth_median: None,
        }
    }
}
