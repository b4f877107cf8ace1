//! The C entry points: `OfxGetNumberOfPlugins`, `OfxGetPlugin`, `OfxSetHost`, and one
//! `mainEntry` trampoline per registry node.
//!
//! `mainEntry` is not told which plugin it belongs to, so each node gets its own
//! monomorphised [`main_entry`]`::<I>` from a fixed table of [`MAX_NODES`]. Every entry point
//! runs behind `catch_unwind`: a panic becomes `kOfxStatFailed` and an error message, never an
//! unwind across the C boundary or an abort.

use std::ffi::{c_void, CStr, CString};
use std::os::raw::{c_char, c_int};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::OnceLock;

use nerfx_graph::{nodes, Node};
use openfx_sys::{
    kOfxImageEffectPluginApi, kOfxImageEffectPluginApiVersion, OfxHost, OfxPlugin,
    OfxPluginEntryPoint, OfxPropertySetHandle, OfxStatus,
};

use crate::actions::{message_target, run};
use crate::instance;
use crate::message::{post_error, Target};
use crate::status::{Failure, FAILED, OK};
use crate::suites::set_host;

/// How many registry nodes the trampoline table serves.
pub const MAX_NODES: usize = 16;

/// The text of a panic payload.
fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_string())
}

/// Posts `text` to `target` as an error, with what an instance target has already shown.
fn report(target: Target, text: &str) {
    let inst = match target {
        // SAFETY: messages go to an instance only during its actions, between its create and
        // destroy actions; the reference does not outlive this call.
        Target::Instance(h) => unsafe { instance::get(h.cast()) }.ok(),
        _ => None,
    };
    post_error(target, inst.map(|i| &i.shown), text);
}

/// Runs `f`, turning a failure or a panic into a status and a message to `target`.
fn guarded(
    target: Target,
    what: &str,
    f: impl FnOnce() -> Result<OfxStatus, Failure>,
) -> OfxStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(status)) => status,
        Ok(Err(failure)) => {
            report(target, &failure.message);
            failure.status
        }
        Err(payload) => {
            let text = format!("{what}: internal error: {}", panic_text(payload.as_ref()));
            // Posting itself must not unwind out of here either.
            let _ = catch_unwind(AssertUnwindSafe(|| report(target, &text)));
            FAILED
        }
    }
}

/// The node behind trampoline `I`.
fn node(index: usize) -> Result<&'static Node, Failure> {
    nodes()
        .get(index)
        .ok_or_else(|| Failure::failed(format!("no registry node {index}")))
}

/// `mainEntry` of the `I`th registry node.
unsafe extern "C" fn main_entry<const I: usize>(
    action: *const c_char,
    handle: *const c_void,
    in_args: OfxPropertySetHandle,
    out_args: OfxPropertySetHandle,
) -> OfxStatus {
    if action.is_null() {
        return FAILED;
    }
    // SAFETY: the host passes a NUL-terminated action name.
    let action = unsafe { CStr::from_ptr(action) };
    let target = message_target(action, handle);
    guarded(target, &action.to_string_lossy(), || {
        let node = node(I)?;
        run(node, action, handle, in_args, out_args).map_err(|f| Failure {
            status: f.status,
            message: if f.message.starts_with(node.desc.id) {
                f.message
            } else {
                format!("{}: {}", node.desc.id, f.message)
            },
        })
    })
}

macro_rules! table {
    ($($i:literal)*) => { [$(Some(main_entry::<$i> as unsafe extern "C" fn(_, _, _, _) -> _)),*] };
}

static ENTRIES: [OfxPluginEntryPoint; MAX_NODES] = table!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15);

/// `OfxPlugin::setHost`.
unsafe extern "C" fn plugin_set_host(host: *mut OfxHost) {
    let _ = catch_unwind(|| set_host(host));
}

/// The plugin structs, built once; they hold pointers into leaked, immutable strings.
struct Plugins(Vec<OfxPlugin>);
// SAFETY: the structs are never mutated after construction and point only to 'static data.
unsafe impl Sync for Plugins {}
unsafe impl Send for Plugins {}

fn plugins() -> &'static [OfxPlugin] {
    static PLUGINS: OnceLock<Plugins> = OnceLock::new();
    &PLUGINS
        .get_or_init(|| {
            let api = CStr::from_bytes_with_nul(kOfxImageEffectPluginApi)
                .unwrap_or(c"OfxImageEffectPluginAPI");
            let list = nodes()
                .iter()
                .zip(ENTRIES)
                .map(|(n, entry)| {
                    let id = CString::new(n.desc.id).unwrap_or_default();
                    OfxPlugin {
                        pluginApi: api.as_ptr(),
                        apiVersion: kOfxImageEffectPluginApiVersion as c_int,
                        pluginIdentifier: Box::leak(id.into_boxed_c_str()).as_ptr(),
                        pluginVersionMajor: 1,
                        pluginVersionMinor: 0,
                        setHost: Some(plugin_set_host),
                        mainEntry: entry,
                    }
                })
                .collect();
            Plugins(list)
        })
        .0
}

/// How many plugins the binary holds: one per registry node, or none (and a message on
/// standard error) when the registry outgrew the trampoline table.
#[no_mangle]
pub extern "C" fn OfxGetNumberOfPlugins() -> c_int {
    catch_unwind(|| {
        let n = nodes().len();
        if n > MAX_NODES {
            eprintln!("nerfx.ofx: {n} nodes, but only {MAX_NODES} entry points: raise MAX_NODES");
            return 0;
        }
        n as c_int
    })
    .unwrap_or(0)
}

/// The `nth` plugin, or null when out of range.
#[no_mangle]
pub extern "C" fn OfxGetPlugin(nth: c_int) -> *mut OfxPlugin {
    catch_unwind(|| {
        let count = OfxGetNumberOfPlugins();
        usize::try_from(nth)
            .ok()
            .filter(|&i| (i as c_int) < count)
            .and_then(|i| plugins().get(i))
            .map_or(std::ptr::null_mut(), |p| (p as *const OfxPlugin).cast_mut())
    })
    .unwrap_or(std::ptr::null_mut())
}

/// Remembers the host before any plugin is asked for (OpenFX 1.5).
#[no_mangle]
pub extern "C" fn OfxSetHost(host: *const OfxHost) -> OfxStatus {
    guarded(Target::Plugin, "OfxSetHost", || {
        set_host(host);
        Ok(OK)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_registry_fits_and_every_node_is_a_plugin() {
        assert!(nodes().len() <= MAX_NODES);
        assert_eq!(OfxGetNumberOfPlugins() as usize, nodes().len());
        for (i, n) in nodes().iter().enumerate() {
            let p = unsafe { &*OfxGetPlugin(i as c_int) };
            let id = unsafe { CStr::from_ptr(p.pluginIdentifier) };
            assert_eq!(id.to_str().unwrap(), n.desc.id);
            assert!(id.to_str().unwrap().starts_with("org.nerfx."));
            let api = unsafe { CStr::from_ptr(p.pluginApi) };
            assert_eq!(api.to_bytes(), b"OfxImageEffectPluginAPI");
            assert_eq!(
                (p.apiVersion, p.pluginVersionMajor, p.pluginVersionMinor),
                (1, 1, 0)
            );
        }
        assert!(OfxGetPlugin(-1).is_null());
        assert!(OfxGetPlugin(nodes().len() as c_int).is_null());
    }

    #[test]
    fn panics_and_failures_become_statuses() {
        assert_eq!(guarded(Target::Plugin, "t", || panic!("boom")), FAILED);
        assert_eq!(
            guarded(Target::Plugin, "t", || Err(Failure::missing_suite("x"))),
            crate::status::ERR_MISSING_HOST_FEATURE
        );
        assert_eq!(guarded(Target::Plugin, "t", || Ok(OK)), OK);
        assert_eq!(panic_text(&"s"), "s");
    }

    #[test]
    fn trampolines_refuse_unknown_nodes_without_unwinding() {
        // Entry 15 exists in the table, but the registry is smaller.
        let status = unsafe {
            main_entry::<15>(
                c"OfxActionLoad".as_ptr(),
                std::ptr::null(),
                std::ptr::null_mut(),
                std::ptr::null_mut(),
            )
        };
        assert_eq!(status, FAILED);
    }
}
