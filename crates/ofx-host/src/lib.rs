//! A small, strict OpenFX host: it loads a bundle, describes and instantiates its plugins
//! and renders them, so tests drive the real binary through the C ABI and the suites, and a
//! farm render takes the same code path as a compositor.
//!
//! [`Bundle::load`] dlopens a binary; [`Bundle::describe`] returns what a plugin declared
//! ([`EffectDescription`]); [`Bundle::instance`] creates an [`Instance`], whose parameters
//! are set with the core's [`nerfx_graph::Value`]s and whose input clips are fed by
//! [`ClipSource`]s; [`Instance::render`] returns the core's [`nerfx_core::image::Planes`].
//! [`Bundle::load_with`] makes the host behave as hosts in production differ
//! ([`HostOptions`]: message suite V1 or none, RGB images, top-down padded images, a second
//! host struct); [`Instance::render_field`] renders one field of interlaced footage and
//! [`Instance::instance_changed_with_reason`] says why a parameter changed.
//!
//! **Strict**: every property access is checked against a table of the spec's properties
//! (name, type, dimension, which sets hold it, whether the plugin may write it); every handle
//! against those the host gave out; every image fetch against the regions of interest the
//! plugin declared; the output buffer has a guard border filled with a sentinel, checked
//! after each render, as is every pixel of the window; images must be released by the end
//! of the render. Each breach gets the spec's error status and is recorded:
//! [`Bundle::violations`] is empty when the plugin behaved.
//!
//! The suites: property, image effect, parameter (values constant over time), memory,
//! multithread (real threads, recursive mutexes), message V1/V2 (as [`HostOptions`] offers)
//! and progress V1/V2. The C-variadic functions are in `param_shim.c`, forwarding to typed
//! Rust callbacks.
//!
//! ```no_run
//! use nerfx_graph::{Context, Value};
//! use nerfx_ofx_host::Bundle;
//! use nerfx_core::image::Window;
//! let bundle = Bundle::load("target/release/nerfx.ofx.bundle".as_ref()).unwrap();
//! let mut node = bundle.instance("org.nerfx.NeRFRender", Context::Generator).unwrap();
//! node.set_param("file", &Value::Text("scene.json".into())).unwrap();
//! node.set_param("shot", &Value::Text("shot.json".into())).unwrap();
//! let planes = node.render(1001.0, Window::new(0, 0, 64, 64), 1.0, false).unwrap();
//! assert!(bundle.violations().is_empty());
//! # let _ = planes;
//! ```

mod bundle;
mod effect;
mod globals;
mod graph;
mod handles;
mod instance;
mod log;
mod memory;
mod messages;
mod options;
mod params;
mod prop_suite;
mod props;
mod shim;
mod source;
mod spec;
mod status;
mod threads;

pub use bundle::{Bundle, ClipDescription, EffectDescription, ParamDescription};
pub use graph::OfxGraph;
pub use instance::Instance;
pub use log::Message;
pub use options::{
    AbsentClip, ChangeReason, HostOptions, InterlacedField, MessageSuiteOffer, PADDING,
};
pub use props::PropValue;
pub use source::{ClipSource, SourceFn};
pub use spec::PropType;
pub use status::{status_name, Status};

/// Direct access to the host's suites, as a plugin sees them, for tests of the host itself.
pub mod testing {
    use std::sync::Arc;

    use openfx_sys as ofx;

    /// The property suite the plugin gets from `fetchSuite`.
    pub fn property_suite() -> &'static ofx::OfxPropertySuiteV1 {
        &super::prop_suite::SUITE
    }

    /// The image effect suite.
    pub fn image_effect_suite() -> &'static ofx::OfxImageEffectSuiteV1 {
        &super::effect::SUITE
    }

    /// The parameter suite (its variadic functions are the C shim's).
    pub fn parameter_suite() -> ofx::OfxParameterSuiteV1 {
        super::params::suite()
    }

    /// The message suite, version 2.
    pub fn message_suite() -> &'static ofx::OfxMessageSuiteV2 {
        &super::messages::MESSAGE_V2
    }

    /// The host descriptor's property set.
    pub fn host_properties() -> ofx::OfxPropertySetHandle {
        super::globals::host_props()
    }

    /// The `OfxHost` handed to plugins.
    pub fn host() -> *mut ofx::OfxHost {
        super::globals::host()
    }

    /// The effect handle the plugin gets for `instance`.
    pub fn effect_handle(instance: &super::Instance) -> ofx::OfxImageEffectHandle {
        instance.effect_handle()
    }

    /// Runs `f` as if inside an action, and returns the violations it caused (on objects
    /// that log to the running action: the host's properties, bad handles).
    pub fn violations_of(f: impl FnOnce()) -> Vec<String> {
        let log: Arc<super::log::Log> = Arc::default();
        let scope = super::log::ActionScope::enter(log.clone());
        f();
        drop(scope);
        log.violations()
    }
}
