//! A loaded OFX binary and its plugins: load, describe, instantiate, unload.

use std::collections::{BTreeMap, HashMap};
use std::ffi::{c_char, c_int, c_void, CStr};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock, PoisonError, Weak};

use openfx_sys as ofx;
use openfx_sys::OfxPlugin;

use super::effect::Effect;
use super::globals::{self as host, HostEntry};
use super::log::{self, ActionScope, Log, Message};
use super::options::HostOptions;
use super::props::{args, PropSet, PropValue};
use super::spec::{cstr, ParamType};
use super::status::{self, status_name, Status};
use nerfx_core::error::{Error, Result};
use nerfx_graph::Context;

type Main = unsafe extern "C" fn(
    *const c_char,
    *const c_void,
    ofx::OfxPropertySetHandle,
    ofx::OfxPropertySetHandle,
) -> Status;

type SetHost = unsafe extern "C" fn(*mut ofx::OfxHost) -> Status;
type PluginSetHost = unsafe extern "C" fn(*mut ofx::OfxHost);

/// One plugin of a binary.
pub(crate) struct Plugin {
    pub(crate) id: String,
    main: Main,
    set_host: Option<PluginSetHost>,
}

/// A dlopen'd binary, shared by every [`Bundle`] of the same file in the process.
pub(crate) struct Binary {
    plugins: Vec<Plugin>,
    path: PathBuf,
    /// Serialises the actions that are not renders (the "main thread").
    pub(crate) main_lock: Mutex<()>,
    /// Serialises renders of plugins that declare themselves unsafe.
    pub(crate) render_lock: Mutex<()>,
    /// `OfxSetHost`, if the binary exports it.
    set_host: Option<SetHost>,
    /// The host struct the binary holds now.
    host: Mutex<&'static HostEntry>,
    _library: libloading::Library,
}

impl Drop for Binary {
    fn drop(&mut self) {
        let scope = ActionScope::enter(log::orphans().clone());
        for p in &self.plugins {
            // SAFETY: the plugin's entry point, with the arguments the spec gives unload.
            unsafe {
                (p.main)(
                    ofx::kOfxActionUnload.as_ptr().cast(),
                    std::ptr::null(),
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                )
            };
        }
        drop(scope);
        self.host
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .release(false);
    }
}

fn binaries() -> &'static Mutex<HashMap<PathBuf, Weak<Binary>>> {
    static BINARIES: OnceLock<Mutex<HashMap<PathBuf, Weak<Binary>>>> = OnceLock::new();
    BINARIES.get_or_init(Default::default)
}

/// A plugin's descriptor in one context: plugin id, context, descriptor.
type Described = (String, Context, Arc<Effect>);

/// A loaded OFX bundle (or bare `.ofx` binary) and the record of what its plugins did.
#[derive(Clone)]
pub struct Bundle {
    pub(crate) binary: Arc<Binary>,
    pub(crate) log: Arc<Log>,
    pub(crate) options: HostOptions,
    host: &'static HostEntry,
    /// Each plugin's descriptor per context, described once and shared by its instances
    /// (as hosts do): a descriptor holds every parameter's properties, a hundred kilobytes
    /// that a graph of thousands of nodes would otherwise hold once per node.
    descriptors: Arc<Mutex<Vec<Described>>>,
}

/// What a plugin declared for one context.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectDescription {
    /// Identifier.
    pub id: String,
    /// Label.
    pub label: String,
    /// Menu grouping.
    pub grouping: String,
    /// Description.
    pub description: String,
    /// Supported contexts (those this host knows).
    pub contexts: Vec<Context>,
    /// Whether it renders tiles.
    pub supports_tiles: bool,
    /// Whether it renders at render scales other than 1.
    pub supports_multi_resolution: bool,
    /// `kOfxImageEffectPluginRenderThreadSafety` (`OfxImageEffectRenderFullySafe`, …).
    pub thread_safety: String,
    /// Supported pixel depths (`OfxBitDepthFloat`, …).
    pub pixel_depths: Vec<String>,
    /// Clips, in definition order (the output clip included).
    pub clips: Vec<ClipDescription>,
    /// Parameters, in definition order.
    pub params: Vec<ParamDescription>,
    /// Every property of the descriptor.
    pub properties: BTreeMap<String, PropValue>,
}

/// A clip as declared.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipDescription {
    /// Name.
    pub name: String,
    /// Label.
    pub label: String,
    /// Whether optional.
    pub optional: bool,
    /// Whether a mask.
    pub is_mask: bool,
    /// Whether it takes tiles.
    pub supports_tiles: bool,
    /// Supported components (`OfxImageComponentRGBA`, …).
    pub components: Vec<String>,
}

/// A parameter as declared.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamDescription {
    /// Name.
    pub name: String,
    /// OFX type (`OfxParamTypeDouble`, …).
    pub param_type: String,
    /// Label.
    pub label: String,
    /// Tooltip.
    pub hint: String,
    /// Default (empty ints for types without a value).
    pub default: PropValue,
    /// Minimum, per component (numeric types).
    pub min: Option<Vec<f64>>,
    /// Maximum, per component.
    pub max: Option<Vec<f64>>,
    /// Slider minimum, per component.
    pub display_min: Option<Vec<f64>>,
    /// Slider maximum, per component.
    pub display_max: Option<Vec<f64>>,
    /// Whether it animates (false for types without a value).
    pub animates: bool,
    /// Options of a choice.
    pub choice_options: Vec<String>,
    /// String mode of a string parameter (`OfxParamStringIsFilePath`, …).
    pub string_mode: Option<String>,
    /// Every property.
    pub properties: BTreeMap<String, PropValue>,
}

/// The OFX name of a context.
pub(crate) fn context_name(c: Context) -> &'static str {
    cstr(match c {
        Context::Generator => ofx::kOfxImageEffectContextGenerator,
        Context::Filter => ofx::kOfxImageEffectContextFilter,
        Context::General => ofx::kOfxImageEffectContextGeneral,
    })
}

fn context_of(name: &str) -> Option<Context> {
    [Context::Generator, Context::Filter, Context::General]
        .into_iter()
        .find(|c| context_name(*c) == name)
}

/// The binary inside a bundle directory (`Contents/Linux-x86-64/<name>.ofx`), or `path`.
fn binary_path(path: &Path) -> Result<PathBuf> {
    let named_bundle = path.extension().is_some_and(|e| e == "bundle");
    if !path.is_dir() && !named_bundle {
        return Ok(path.to_path_buf());
    }
    let stem = path
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_suffix(".bundle"))
        .ok_or_else(|| {
            Error::invalid(
                path.display().to_string(),
                "a bundle directory is named <name>.ofx.bundle",
            )
        })?;
    Ok(path.join("Contents").join("Linux-x86-64").join(stem))
}

/// A failed action as an error carrying the status and what the plugin said.
pub(crate) fn failure(id: &str, what: &str, s: Status, messages: &[String]) -> Error {
    let said = if messages.is_empty() {
        "the plugin posted no message".to_string()
    } else {
        messages.join("; ")
    };
    Error::invalid(id, format!("{what} failed ({}): {said}", status_name(s)))
}

impl Binary {
    fn load(file: &Path, host: &'static HostEntry) -> Result<Arc<Binary>> {
        let key = file.canonicalize().map_err(|e| Error::io(file, e))?;
        let mut map = binaries().lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(b) = map.get(&key).and_then(Weak::upgrade) {
            return Ok(b);
        }
        let b = Arc::new(Binary::open(&key, host)?);
        map.insert(key, Arc::downgrade(&b));
        Ok(b)
    }

    fn open(file: &Path, host: &'static HostEntry) -> Result<Binary> {
        // Held from before OfxSetHost: the load actions fetch suites through it.
        host.hold();
        let opened = Binary::open_held(file, host);
        if opened.is_err() {
            host.release(false);
        }
        opened
    }

    fn open_held(file: &Path, host: &'static HostEntry) -> Result<Binary> {
        let where_ = file.display().to_string();
        // SAFETY: loading a plugin runs its initialisers; that is what a host does.
        let library = unsafe { libloading::Library::new(file) }
            .map_err(|e| Error::invalid(where_.clone(), format!("cannot load: {e}")))?;
        // SAFETY: the symbols have the signatures the OFX spec gives them.
        let (count, get) = unsafe {
            let count = library
                .get::<unsafe extern "C" fn() -> c_int>(b"OfxGetNumberOfPlugins\0")
                .map_err(|e| {
                    Error::invalid(where_.clone(), format!("not an OpenFX binary: {e}"))
                })?;
            let get = library
                .get::<unsafe extern "C" fn(c_int) -> *mut OfxPlugin>(b"OfxGetPlugin\0")
                .map_err(|e| {
                    Error::invalid(where_.clone(), format!("not an OpenFX binary: {e}"))
                })?;
            (*count, *get)
        };
        let scope = ActionScope::enter(log::orphans().clone());
        // SAFETY: the optional entry point of OFX 1.4, called before anything else.
        let set_host = unsafe { library.get::<SetHost>(b"OfxSetHost\0") }
            .ok()
            .map(|f| *f);
        if let Some(set_host) = set_host {
            // SAFETY: the host struct is leaked: it outlives the binary.
            let s = unsafe { set_host(host.host()) };
            if s != status::OK && s != status::REPLY_DEFAULT {
                return Err(failure(&where_, "OfxSetHost", s, &scope.messages()));
            }
        }
        let mut plugins = Vec::new();
        // SAFETY: plugin structs stay valid while the binary is loaded.
        for i in 0..unsafe { count() } {
            let p = unsafe { get(i) };
            if p.is_null() {
                return Err(Error::invalid(
                    where_,
                    format!("OfxGetPlugin({i}) returned NULL"),
                ));
            }
            let p = unsafe { &*p };
            let text = |s: *const c_char| {
                if s.is_null() {
                    String::new()
                } else {
                    unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned()
                }
            };
            if text(p.pluginApi) != cstr(ofx::kOfxImageEffectPluginApi) || p.apiVersion != 1 {
                continue;
            }
            let id = text(p.pluginIdentifier);
            let main = p
                .mainEntry
                .ok_or_else(|| Error::invalid(format!("{where_}: {id}"), "no main entry point"))?;
            if let Some(set_host) = p.setHost {
                unsafe { set_host(host.host()) };
            }
            let s = unsafe {
                main(
                    ofx::kOfxActionLoad.as_ptr().cast(),
                    std::ptr::null(),
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                )
            };
            if s != status::OK && s != status::REPLY_DEFAULT {
                return Err(failure(&id, "load", s, &scope.messages()));
            }
            plugins.push(Plugin {
                id,
                main,
                set_host: p.setHost,
            });
        }
        drop(scope);
        Ok(Binary {
            plugins,
            path: file.to_path_buf(),
            main_lock: Mutex::new(()),
            render_lock: Mutex::new(()),
            set_host,
            host: Mutex::new(host),
            _library: library,
        })
    }

    /// Gives the binary `host` if it holds another: `OfxSetHost`, then every plugin's
    /// `setHost`, as a host does that hands a plugin a second host struct. A failure of
    /// `OfxSetHost` is a violation in `log` (the plugin keeps whatever it had).
    fn give_host(&self, host: &'static HostEntry, log: &Arc<Log>) {
        let mut held = self.host.lock().unwrap_or_else(PoisonError::into_inner);
        if std::ptr::eq(*held, host) {
            return;
        }
        let scope = ActionScope::enter(log.clone());
        host.hold();
        held.release(true);
        *held = host;
        if let Some(set_host) = self.set_host {
            // SAFETY: the entry point with a host struct that outlives the binary.
            let s = unsafe { set_host(host.host()) };
            if s != status::OK && s != status::REPLY_DEFAULT {
                log.violation(
                    failure(
                        &self.path.display().to_string(),
                        "OfxSetHost (a second host)",
                        s,
                        &scope.messages(),
                    )
                    .to_string(),
                );
            }
        }
        for p in &self.plugins {
            if let Some(set_host) = p.set_host {
                // SAFETY: as above.
                unsafe { set_host(host.host()) };
            }
        }
    }

    pub(crate) fn plugin(&self, id: &str) -> Result<&Plugin> {
        self.plugins.iter().find(|p| p.id == id).ok_or_else(|| {
            let ids: Vec<&str> = self.plugins.iter().map(|p| p.id.as_str()).collect();
            Error::invalid(
                format!("plugin {id}"),
                format!(
                    "not in {} (plugins: {})",
                    self.path.display(),
                    ids.join(", ")
                ),
            )
        })
    }
}

impl Plugin {
    /// Runs `action` on `handle` with the calling thread's log set to the bundle's, after
    /// giving the binary the bundle's host if another bundle gave it another; returns the
    /// status and the messages the plugin posted meanwhile.
    pub(crate) fn call(
        &self,
        bundle: &Bundle,
        action: &[u8],
        handle: *const c_void,
        in_args: Option<&PropSet>,
        out_args: Option<&PropSet>,
    ) -> (Status, Vec<String>) {
        bundle.binary.give_host(bundle.host, &bundle.log);
        let scope = ActionScope::enter(bundle.log.clone());
        let h = |p: Option<&PropSet>| p.map_or(std::ptr::null_mut(), PropSet::handle);
        // SAFETY: the plugin's entry point with handles the host owns for the whole call.
        let s = unsafe { (self.main)(action.as_ptr().cast(), handle, h(in_args), h(out_args)) };
        (s, scope.messages())
    }

    /// [`Plugin::call`], with a status other than OK or "default" as an error.
    pub(crate) fn run(
        &self,
        bundle: &Bundle,
        what: &str,
        action: &[u8],
        handle: *const c_void,
        in_args: Option<&PropSet>,
        out_args: Option<&PropSet>,
    ) -> Result<Status> {
        let (s, said) = self.call(bundle, action, handle, in_args, out_args);
        if s == status::OK || s == status::REPLY_DEFAULT {
            Ok(s)
        } else {
            Err(failure(&self.id, what, s, &said))
        }
    }
}

impl Bundle {
    /// Loads a `.ofx.bundle` directory (its `Contents/Linux-x86-64/<name>.ofx`) or an `.ofx`
    /// file: dlopen, `OfxSetHost`, `OfxGetNumberOfPlugins`/`OfxGetPlugin`, and the load
    /// action of every image-effect plugin. A binary already loaded in this process is
    /// shared (it was loaded once; see [`Bundle::load_with`] for bundles of one binary
    /// with different hosts). The strict host's default behaviour.
    pub fn load(path: &Path) -> Result<Bundle> {
        Bundle::load_with(path, HostOptions::default())
    }

    /// [`Bundle::load`], the host behaving as `options` says (see [`HostOptions`]).
    ///
    /// The message suite offered is a property of the host struct the binary was given, and
    /// a binary holds one host at a time: a bundle whose host differs from the one its
    /// binary holds gives it its own again (`OfxSetHost`) before each action. Bundles of one
    /// binary with different message suites or a second host therefore take turns; they
    /// must not run actions at the same time.
    pub fn load_with(path: &Path, options: HostOptions) -> Result<Bundle> {
        let file = binary_path(path)?;
        if !file.is_file() {
            return Err(Error::io(
                &file,
                std::io::Error::from(std::io::ErrorKind::NotFound),
            ));
        }
        let first = host::standard(options.message_suite);
        let log: Arc<Log> = Arc::default();
        let binary = Binary::load(&file, first)?;
        binary.give_host(first, &log);
        let host = match options.second_host {
            Some(offer) => {
                let second = host::fresh(offer);
                binary.give_host(second, &log);
                second
            }
            None => first,
        };
        Ok(Bundle {
            binary,
            log,
            options,
            host,
            descriptors: Arc::default(),
        })
    }

    /// The identifiers of the image-effect plugins.
    pub fn plugin_ids(&self) -> Vec<String> {
        self.binary.plugins.iter().map(|p| p.id.clone()).collect()
    }

    /// The descriptor of `id` in `context`, described on first request (see
    /// [`Bundle::descriptor`]) and shared from then on.
    pub(crate) fn shared_descriptor(
        &self,
        id: &str,
        context: Context,
    ) -> Result<(Arc<Effect>, &Plugin)> {
        let cached = self
            .descriptors
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .find(|(i, c, _)| i == id && *c == context)
            .map(|(_, _, d)| d.clone());
        if let Some(d) = cached {
            return Ok((d, self.binary.plugin(id)?));
        }
        let (d, plugin) = self.descriptor(id, context)?;
        let d: Arc<Effect> = Arc::from(d);
        self.descriptors
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((id.to_owned(), context, d.clone()));
        Ok((d, plugin))
    }

    /// A fresh descriptor of `id` in `context`, described (describe, then
    /// describeInContext), with the spec's requirements on a description checked.
    pub(crate) fn descriptor(&self, id: &str, context: Context) -> Result<(Box<Effect>, &Plugin)> {
        let plugin = self.binary.plugin(id)?;
        let d = Effect::descriptor(
            id,
            &self.binary.path.display().to_string(),
            self.log.clone(),
            self.options,
        );
        let _main = self
            .binary
            .main_lock
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let handle = d.handle() as *const c_void;
        plugin.run(
            self,
            "describe",
            ofx::kOfxActionDescribe,
            handle,
            None,
            None,
        )?;
        let contexts = d.props.strings(ofx::kOfxImageEffectPropSupportedContexts);
        let name = context_name(context);
        if !contexts.iter().any(|c| c == name) {
            return Err(Error::invalid(
                id,
                format!(
                    "context {name} not supported (contexts: {})",
                    contexts.join(", ")
                ),
            ));
        }
        let in_args = args(
            false,
            format!("{id} describeInContext inArgs"),
            &[(
                cstr(ofx::kOfxImageEffectPropContext),
                PropValue::String(vec![name.to_string()]),
            )],
            self.log.clone(),
        );
        plugin.run(
            self,
            "describeInContext",
            ofx::kOfxImageEffectActionDescribeInContext,
            handle,
            Some(&in_args),
            None,
        )?;
        self.check_description(&d, context);
        Ok((d, plugin))
    }

    fn check_description(&self, d: &Effect, context: Context) {
        let id = &d.id;
        let v = |m: String| self.log.violation(format!("{id}: {m}"));
        if d.props
            .strings(ofx::kOfxImageEffectPropSupportedPixelDepths)
            .is_empty()
        {
            v("no supported pixel depths declared".into());
        }
        let clips = d.lock_clips();
        if !clips.iter().any(|c| &*c.name == "Output") {
            v("no Output clip defined".into());
        }
        if context == Context::Filter && !clips.iter().any(|c| &*c.name == "Source") {
            v("the Filter context needs a Source clip".into());
        }
        for c in clips.iter() {
            if c.props
                .strings(ofx::kOfxImageEffectPropSupportedComponents)
                .is_empty()
            {
                v(format!("clip {} declares no supported components", c.name));
            }
        }
    }

    /// What plugin `id` declares in `context`.
    pub fn describe(&self, id: &str, context: Context) -> Result<EffectDescription> {
        let (d, _) = self.descriptor(id, context)?;
        let p = &d.props;
        let clips = d
            .lock_clips()
            .iter()
            .map(|c| ClipDescription {
                name: c.name.to_string(),
                label: c.props.string(ofx::kOfxPropLabel),
                optional: c.props.int(ofx::kOfxImageClipPropOptional) != 0,
                is_mask: c.props.int(ofx::kOfxImageClipPropIsMask) != 0,
                supports_tiles: c.props.int(ofx::kOfxImageEffectPropSupportsTiles) != 0,
                components: c.props.strings(ofx::kOfxImageEffectPropSupportedComponents),
            })
            .collect();
        let params = d.params.each(|q| {
            let range = |name: &[u8]| match q.props.get(cstr_of(name)) {
                Some(PropValue::Double(v)) => Some(v),
                Some(PropValue::Int(v)) => Some(v.into_iter().map(f64::from).collect()),
                _ => None,
            };
            let valued = q.ty.value_shape().is_some();
            ParamDescription {
                name: q.name.to_string(),
                param_type: q.ty.name().to_string(),
                label: q.props.string(ofx::kOfxPropLabel),
                hint: q.props.string(ofx::kOfxParamPropHint),
                default: q
                    .props
                    .get(cstr(ofx::kOfxParamPropDefault))
                    .unwrap_or(PropValue::Int(Vec::new())),
                min: range(ofx::kOfxParamPropMin),
                max: range(ofx::kOfxParamPropMax),
                display_min: range(ofx::kOfxParamPropDisplayMin),
                display_max: range(ofx::kOfxParamPropDisplayMax),
                animates: valued && q.props.int(ofx::kOfxParamPropAnimates) != 0,
                choice_options: q.props.strings(ofx::kOfxParamPropChoiceOption),
                string_mode: (q.ty == ParamType::String)
                    .then(|| q.props.string(ofx::kOfxParamPropStringMode)),
                properties: q.props.all(),
            }
        });
        Ok(EffectDescription {
            id: id.to_string(),
            label: p.string(ofx::kOfxPropLabel),
            grouping: p.string(ofx::kOfxImageEffectPluginPropGrouping),
            description: p.string(ofx::kOfxPropPluginDescription),
            contexts: p
                .strings(ofx::kOfxImageEffectPropSupportedContexts)
                .iter()
                .filter_map(|c| context_of(c))
                .collect(),
            supports_tiles: p.int(ofx::kOfxImageEffectPropSupportsTiles) != 0,
            supports_multi_resolution: p.int(ofx::kOfxImageEffectPropSupportsMultiResolution) != 0,
            thread_safety: p.string(ofx::kOfxImageEffectPluginRenderThreadSafety),
            pixel_depths: p.strings(ofx::kOfxImageEffectPropSupportedPixelDepths),
            clips,
            params,
            properties: p.all(),
        })
    }

    /// Every message the plugins posted, persistent ones included, with those posted
    /// outside any action in this process.
    pub fn messages(&self) -> Vec<Message> {
        let mut m = self.log.messages();
        m.extend(log::orphans().messages());
        m
    }

    /// Every strictness violation seen (empty: the plugins behaved), with those seen outside
    /// any action in this process.
    pub fn violations(&self) -> Vec<String> {
        let mut v = self.log.violations();
        v.extend(log::orphans().violations());
        v
    }
}

fn cstr_of(name: &[u8]) -> &str {
    super::spec::cstr_dyn(name)
}
