//! The host descriptors and `fetchSuite`. One host struct per message-suite offer is shared
//! by every bundle that asks for it (a binary loaded twice is the same binary); a bundle
//! asking for a second host ([`super::HostOptions::second_host`]) gets a struct of its own.
//! A binary holds one host at a time, as in any host process: [`super::Bundle`] gives it
//! its own again (`OfxSetHost`) before an action if another bundle gave it another.

use std::ffi::{c_char, c_int, c_void, CStr};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock, PoisonError};

use openfx_sys as ofx;
use openfx_sys::{OfxHost, OfxPropertySetHandle};

use super::options::MessageSuiteOffer;
use super::props::{self, PropSet, PropValue};
use super::spec::SetKind;
use super::{effect, memory, messages, params, prop_suite, shim, threads};

/// One host struct handed to plugins: its property set, the `OfxHost`, the message suite it
/// offers, and how many binaries hold it now (a host struct a binary was told to replace
/// and that no binary holds is retired: `fetchSuite` through it is a violation).
pub(crate) struct HostEntry {
    props: Box<PropSet>,
    host: OfxHost,
    offer: MessageSuiteOffer,
    /// One of the shared hosts (not a second host).
    standard: bool,
    holders: AtomicUsize,
    retired: AtomicBool,
}

// SAFETY: the raw pointers inside are to the boxed host set and to functions, never mutated;
// the counters are atomics.
unsafe impl Sync for HostEntry {}
// SAFETY: as above.
unsafe impl Send for HostEntry {}

impl HostEntry {
    /// The `OfxHost` handed to `OfxSetHost` and `setHost`.
    pub(crate) fn host(&'static self) -> *mut OfxHost {
        &self.host as *const OfxHost as *mut OfxHost
    }

    /// A binary now holds this host.
    pub(crate) fn hold(&self) {
        self.holders.fetch_add(1, Ordering::AcqRel);
        self.retired.store(false, Ordering::Release);
    }

    /// A binary was given another host (or unloaded, `replaced` false).
    pub(crate) fn release(&self, replaced: bool) {
        let before = self.holders.fetch_sub(1, Ordering::AcqRel);
        if replaced && before == 1 {
            self.retired.store(true, Ordering::Release);
        }
    }
}

struct Globals {
    /// Host structs, by address of their property set; leaked, as a plugin may keep the
    /// pointer it was given for as long as it is loaded.
    hosts: Mutex<Vec<&'static HostEntry>>,
    params: ofx::OfxParameterSuiteV1,
}

fn new_entry(offer: MessageSuiteOffer, serial: usize, standard: bool) -> &'static HostEntry {
    let p = props::new_set(
        SetKind::Host,
        "org.nerfx.host",
        format!("host {serial}"),
        None,
    );
    let strings = |name: &[u8], values: &[&[u8]]| {
        let v = values.iter().map(|s| cstr_owned(s)).collect();
        p.put(super::spec::cstr_dyn(name), PropValue::String(v));
    };
    strings(ofx::kOfxPropType, &[ofx::kOfxTypeImageEffectHost]);
    p.set_str(ofx::kOfxPropLabel, "nerfx strict host");
    p.set_ints(ofx::kOfxPropAPIVersion, &[1, 4]);
    p.set_ints(ofx::kOfxPropVersion, &[0, 1, 0]);
    p.set_str(ofx::kOfxPropVersionLabel, "0.1.0");
    strings(
        ofx::kOfxImageEffectPropSupportedComponents,
        &[ofx::kOfxImageComponentRGBA, ofx::kOfxImageComponentAlpha],
    );
    strings(
        ofx::kOfxImageEffectPropSupportedContexts,
        &[
            ofx::kOfxImageEffectContextGenerator,
            ofx::kOfxImageEffectContextFilter,
            ofx::kOfxImageEffectContextGeneral,
        ],
    );
    strings(
        ofx::kOfxImageEffectPropSupportedPixelDepths,
        &[ofx::kOfxBitDepthFloat],
    );
    strings(
        ofx::kOfxImageEffectHostPropNativeOrigin,
        &[b"kOfxImageEffectHostPropNativeOriginBottomLeft\0"],
    );
    p.set_ints(ofx::kOfxParamHostPropPageRowColumnCount, &[0, 0]);
    // Clip preferences may set clips' pixel aspect ratios (a generator's shot).
    p.set_ints(ofx::kOfxImageEffectPropSupportsMultipleClipPARs, &[1]);
    // OpenFX 1.5's core native colour management (the colourspaces of ofxColourspaceList.h).
    strings(
        super::spec::COLOUR_MANAGEMENT_STYLE,
        &[super::spec::COLOUR_MANAGEMENT_CORE],
    );
    let host = OfxHost {
        host: p.handle(),
        fetchSuite: Some(fetch_suite),
    };
    Box::leak(Box::new(HostEntry {
        props: p,
        host,
        offer,
        standard,
        holders: AtomicUsize::new(0),
        retired: AtomicBool::new(false),
    }))
}

fn globals() -> &'static Globals {
    static GLOBALS: OnceLock<Globals> = OnceLock::new();
    GLOBALS.get_or_init(|| {
        shim::init();
        Globals {
            hosts: Mutex::new(vec![new_entry(MessageSuiteOffer::V2, 0, true)]),
            params: params::suite(),
        }
    })
}

fn lock_hosts() -> std::sync::MutexGuard<'static, Vec<&'static HostEntry>> {
    globals()
        .hosts
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
}

/// The process's host struct offering `offer` (one each, made on first use; the first one
/// made is the default host's).
pub(crate) fn standard(offer: MessageSuiteOffer) -> &'static HostEntry {
    let mut hosts = lock_hosts();
    if let Some(h) = hosts.iter().find(|h| h.offer == offer && h.standard) {
        return h;
    }
    let h = new_entry(offer, hosts.len(), true);
    hosts.push(h);
    h
}

/// A host struct offering `offer`, distinct from every other (a second host).
pub(crate) fn fresh(offer: MessageSuiteOffer) -> &'static HostEntry {
    let mut hosts = lock_hosts();
    let h = new_entry(offer, hosts.len(), false);
    hosts.push(h);
    h
}

fn cstr_owned(s: &[u8]) -> String {
    super::spec::cstr_dyn(s).to_string()
}

/// The default `OfxHost` (message suite V2), for tests of the suites.
pub(crate) fn host() -> *mut OfxHost {
    standard(MessageSuiteOffer::V2).host()
}

/// The default host's property set (for tests of the property suite).
pub(crate) fn host_props() -> OfxPropertySetHandle {
    standard(MessageSuiteOffer::V2).props.handle()
}

unsafe extern "C" fn fetch_suite(
    host: OfxPropertySetHandle,
    name: *const c_char,
    version: c_int,
) -> *const c_void {
    let g = globals();
    let Some(entry) = lock_hosts()
        .iter()
        .find(|h| h.props.handle() == host)
        .copied()
    else {
        super::log::current().violation(format!("fetchSuite: {host:p} is not a host handle"));
        return std::ptr::null();
    };
    if entry.retired.load(Ordering::Acquire) {
        super::log::current().violation(format!(
            "fetchSuite: {host:p} is a host struct OfxSetHost has since replaced"
        ));
        return std::ptr::null();
    }
    if name.is_null() {
        super::log::current().violation("fetchSuite: NULL suite name");
        return std::ptr::null();
    }
    // SAFETY: checked non-NULL; a C string by contract.
    let name = unsafe { CStr::from_ptr(name) }.to_bytes_with_nul();
    let is = |suite: &[u8]| name == suite;
    let suite: *const c_void = match version {
        1 if is(ofx::kOfxPropertySuite) => {
            (&prop_suite::SUITE as *const ofx::OfxPropertySuiteV1).cast()
        }
        1 if is(ofx::kOfxImageEffectSuite) => {
            (&effect::SUITE as *const ofx::OfxImageEffectSuiteV1).cast()
        }
        1 if is(ofx::kOfxParameterSuite) => (&g.params as *const ofx::OfxParameterSuiteV1).cast(),
        1 if is(ofx::kOfxMemorySuite) => (&memory::MEMORY as *const ofx::OfxMemorySuiteV1).cast(),
        1 if is(ofx::kOfxMultiThreadSuite) => {
            (&threads::MULTI_THREAD as *const ofx::OfxMultiThreadSuiteV1).cast()
        }
        1 if is(ofx::kOfxMessageSuite) && entry.offer != MessageSuiteOffer::Absent => {
            (&messages::MESSAGE_V1 as *const ofx::OfxMessageSuiteV1).cast()
        }
        2 if is(ofx::kOfxMessageSuite) && entry.offer == MessageSuiteOffer::V2 => {
            (&messages::MESSAGE_V2 as *const ofx::OfxMessageSuiteV2).cast()
        }
        1 if is(ofx::kOfxProgressSuite) => {
            (&messages::PROGRESS_V1 as *const ofx::OfxProgressSuiteV1).cast()
        }
        2 if is(ofx::kOfxProgressSuite) => {
            (&messages::PROGRESS_V2 as *const ofx::OfxProgressSuiteV2).cast()
        }
        _ => std::ptr::null(),
    };
    suite
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::cstr;

    #[test]
    fn fetch_suite_knows_the_suites_and_refuses_others() {
        let h = host();
        // SAFETY: the host struct is static.
        let fetch = unsafe { (*h).fetchSuite }.unwrap();
        let hp = unsafe { (*h).host };
        let get = |name: &[u8], v| unsafe { fetch(hp, name.as_ptr().cast(), v) };
        assert!(!get(ofx::kOfxPropertySuite, 1).is_null());
        assert!(!get(ofx::kOfxMessageSuite, 2).is_null());
        assert!(get(ofx::kOfxPropertySuite, 2).is_null());
        assert!(get(b"OfxNoSuchSuite\0", 1).is_null());
    }

    #[test]
    fn each_host_offers_its_message_suites_and_a_replaced_one_is_refused() {
        let get = |h: &'static HostEntry, v| {
            let fetch = h.host.fetchSuite.unwrap();
            // SAFETY: a host of this process and a suite name.
            unsafe { fetch(h.host.host, ofx::kOfxMessageSuite.as_ptr().cast(), v) }
        };
        let v1 = standard(MessageSuiteOffer::V1Only);
        assert!(!get(v1, 1).is_null() && get(v1, 2).is_null());
        let none = standard(MessageSuiteOffer::Absent);
        assert!(get(none, 1).is_null() && get(none, 2).is_null());
        assert!(std::ptr::eq(v1, standard(MessageSuiteOffer::V1Only)));
        let second = fresh(MessageSuiteOffer::V1Only);
        assert!(!std::ptr::eq(v1, second));
        assert_ne!(second.host.host, v1.host.host);
        second.hold();
        second.release(true);
        let log: std::sync::Arc<super::super::log::Log> = Default::default();
        let scope = super::super::log::ActionScope::enter(log.clone());
        assert!(get(second, 1).is_null());
        drop(scope);
        assert_eq!(log.violations().len(), 1);
    }

    #[test]
    fn the_host_names_its_type() {
        assert_eq!(
            standard(MessageSuiteOffer::V2)
                .props
                .string(ofx::kOfxPropType),
            cstr(ofx::kOfxTypeImageEffectHost)
        );
    }
}
