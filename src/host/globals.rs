//! The host descriptor and `fetchSuite`: one per process, shared by every bundle (a binary
//! loaded twice is the same binary, and it keeps the host pointer it was given).

use std::ffi::{c_char, c_int, c_void, CStr};
use std::sync::OnceLock;

use openfx_sys as ofx;
use openfx_sys::{OfxHost, OfxPropertySetHandle};

use super::props::{self, PropSet, PropValue};
use super::spec::SetKind;
use super::{effect, messages, params, prop_suite, shim, threads};

struct Globals {
    props: Box<PropSet>,
    host: OfxHost,
    params: ofx::OfxParameterSuiteV1,
}

// SAFETY: the raw pointers inside are to the boxed host set and to functions, never mutated.
unsafe impl Sync for Globals {}
// SAFETY: as above.
unsafe impl Send for Globals {}

fn globals() -> &'static Globals {
    static GLOBALS: OnceLock<Globals> = OnceLock::new();
    GLOBALS.get_or_init(|| {
        shim::init();
        let p = props::new_set(SetKind::Host, "org.nerfx.host", "host".to_string(), None);
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
        let host = OfxHost {
            host: p.handle(),
            fetchSuite: Some(fetch_suite),
        };
        Globals {
            props: p,
            host,
            params: params::suite(),
        }
    })
}

fn cstr_owned(s: &[u8]) -> String {
    super::spec::cstr_dyn(s).to_string()
}

/// The `OfxHost` handed to `OfxSetHost` and `setHost`.
pub(crate) fn host() -> *mut OfxHost {
    &globals().host as *const OfxHost as *mut OfxHost
}

/// The host's property set (for tests of the property suite).
pub(crate) fn host_props() -> OfxPropertySetHandle {
    globals().props.handle()
}

unsafe extern "C" fn fetch_suite(
    host: OfxPropertySetHandle,
    name: *const c_char,
    version: c_int,
) -> *const c_void {
    let g = globals();
    if host != g.props.handle() {
        super::log::current().violation(format!("fetchSuite: {host:p} is not the host handle"));
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
        1 if is(ofx::kOfxMemorySuite) => (&threads::MEMORY as *const ofx::OfxMemorySuiteV1).cast(),
        1 if is(ofx::kOfxMultiThreadSuite) => {
            (&threads::MULTI_THREAD as *const ofx::OfxMultiThreadSuiteV1).cast()
        }
        1 if is(ofx::kOfxMessageSuite) => {
            (&messages::MESSAGE_V1 as *const ofx::OfxMessageSuiteV1).cast()
        }
        2 if is(ofx::kOfxMessageSuite) => {
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
    use crate::host::spec::cstr;

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
    fn the_host_names_its_type() {
        assert_eq!(
            globals().props.string(ofx::kOfxPropType),
            cstr(ofx::kOfxTypeImageEffectHost)
        );
    }
}
