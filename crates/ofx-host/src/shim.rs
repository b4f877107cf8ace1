//! The Rust side of `param_shim.c`: the typed callbacks its variadic functions forward to
//! (installed once by [`init`]). The parameter and message suites declare the variadic
//! functions themselves.

use std::ffi::{c_char, c_double, c_int, c_void, CStr};
use std::sync::Once;

use super::log::Message;
use super::{messages, params, status};

/// Mirrors `struct nerfx_shim_callbacks` in `ofx_headers/nerfx_shim.h`.
#[repr(C)]
struct Callbacks {
    param_shape: unsafe extern "C" fn(*mut c_void, *mut c_int, *mut c_int) -> c_int,
    param_get: unsafe extern "C" fn(
        *mut c_void,
        c_int,
        c_double,
        c_double,
        *mut c_double,
        *mut c_int,
        *mut *const c_char,
    ) -> c_int,
    param_set: unsafe extern "C" fn(
        *mut c_void,
        c_int,
        c_double,
        *const c_double,
        *const c_int,
        *const c_char,
    ) -> c_int,
    message: unsafe extern "C" fn(
        *mut c_void,
        *const c_char,
        *const c_char,
        *const c_char,
        c_int,
    ) -> c_int,
}

/// The most components a value has (`NERFX_SHIM_MAX_DIM`).
const MAX_DIM: usize = 4;

extern "C" {
    fn nerfx_shim_init(callbacks: *const Callbacks);
}

static CALLBACKS: Callbacks = Callbacks {
    param_shape,
    param_get,
    param_set,
    message,
};

/// Hands the callbacks to the shim (once per process).
pub(crate) fn init() {
    static ONCE: Once = Once::new();
    // SAFETY: CALLBACKS is a static with the C layout the shim expects.
    ONCE.call_once(|| unsafe { nerfx_shim_init(&CALLBACKS) });
}

unsafe extern "C" fn param_shape(h: *mut c_void, kind: *mut c_int, dim: *mut c_int) -> c_int {
    // SAFETY: the handle is checked; the shim passes valid out-pointers.
    match unsafe { params::param(h, "paramGetValue/paramSetValue") } {
        Ok(p) => {
            let (k, d) = params::shape(p);
            // SAFETY: the shim passes valid out-pointers.
            unsafe {
                params::put(kind, k);
                params::put(dim, d);
            }
            status::OK
        }
        Err(s) => s,
    }
}

unsafe extern "C" fn param_get(
    h: *mut c_void,
    query: c_int,
    t1: c_double,
    t2: c_double,
    doubles: *mut c_double,
    ints: *mut c_int,
    string: *mut *const c_char,
) -> c_int {
    // SAFETY: the handle is checked; the shim passes arrays of MAX_DIM and a string slot.
    unsafe {
        let p = match params::param(h, "paramGetValue") {
            Ok(p) => p,
            Err(s) => return s,
        };
        let doubles = std::slice::from_raw_parts_mut(doubles, MAX_DIM);
        let ints = std::slice::from_raw_parts_mut(ints, MAX_DIM);
        params::get(p, query, t1, t2, doubles, ints, &mut *string)
    }
}

unsafe extern "C" fn param_set(
    h: *mut c_void,
    _has_time: c_int,
    _time: c_double,
    doubles: *const c_double,
    ints: *const c_int,
    string: *const c_char,
) -> c_int {
    // SAFETY: the handle is checked; the shim passes arrays of MAX_DIM.
    unsafe {
        let p = match params::param(h, "paramSetValue") {
            Ok(p) => p,
            Err(s) => return s,
        };
        let doubles = std::slice::from_raw_parts(doubles, MAX_DIM);
        let ints = std::slice::from_raw_parts(ints, MAX_DIM);
        params::set(p, doubles, ints, string)
    }
}

unsafe extern "C" fn message(
    handle: *mut c_void,
    kind: *const c_char,
    _id: *const c_char,
    text: *const c_char,
    persistent: c_int,
) -> c_int {
    let read = |s: *const c_char| {
        if s.is_null() {
            None
        } else {
            // SAFETY: checked non-NULL; C strings by contract (text formatted by the shim).
            Some(unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned())
        }
    };
    let message = Message {
        kind: read(kind).unwrap_or_default(),
        text: read(text).unwrap_or_default(),
        persistent: persistent != 0,
    };
    messages::post(handle, message)
}
