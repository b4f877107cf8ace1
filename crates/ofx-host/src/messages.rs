//! The message suite (V1 and V2; the formatting is done by `param_shim.c`) and the progress
//! suite (V1 and V2). Messages go to the log of the effect they name, or of the running
//! action when the handle is NULL; an instance remembers its persistent message until the
//! plugin clears it ([`super::Instance::persistent_message`]).

use std::ffi::{c_char, c_void};
use std::sync::PoisonError;

use openfx_sys as ofx;
use openfx_sys::OfxStatus;

use super::effect::Effect;
use super::handles::{self, Kind};
use super::log::{self, Message};
use super::spec::cstr;
use super::status;

// The C-variadic functions of the suite, defined in `param_shim.c`.
extern "C" {
    fn nerfx_message(
        handle: *mut c_void,
        kind: *const c_char,
        id: *const c_char,
        format: *const c_char,
        ...
    ) -> OfxStatus;
    fn nerfx_set_persistent_message(
        handle: *mut c_void,
        kind: *const c_char,
        id: *const c_char,
        format: *const c_char,
        ...
    ) -> OfxStatus;
}

/// Message suite V1.
pub(crate) static MESSAGE_V1: ofx::OfxMessageSuiteV1 = ofx::OfxMessageSuiteV1 {
    message: Some(nerfx_message),
};

/// Message suite V2.
pub(crate) static MESSAGE_V2: ofx::OfxMessageSuiteV2 = ofx::OfxMessageSuiteV2 {
    message: Some(nerfx_message),
    setPersistentMessage: Some(nerfx_set_persistent_message),
    clearPersistentMessage: Some(clear_persistent),
};

/// Progress suite V1.
pub(crate) static PROGRESS_V1: ofx::OfxProgressSuiteV1 = ofx::OfxProgressSuiteV1 {
    progressStart: Some(progress_start_v1),
    progressUpdate: Some(progress_update),
    progressEnd: Some(progress_end),
};

/// Progress suite V2.
pub(crate) static PROGRESS_V2: ofx::OfxProgressSuiteV2 = ofx::OfxProgressSuiteV2 {
    progressStart: Some(progress_start_v2),
    progressUpdate: Some(progress_update),
    progressEnd: Some(progress_end),
};

const KINDS: [&[u8]; 6] = [
    ofx::kOfxMessageFatal,
    ofx::kOfxMessageError,
    ofx::kOfxMessageWarning,
    ofx::kOfxMessageMessage,
    ofx::kOfxMessageLog,
    ofx::kOfxMessageQuestion,
];

/// The effect `handle` names, `Ok(None)` for NULL, or the status for a bad handle.
fn effect<'a>(handle: *mut c_void, function: &str) -> Result<Option<&'a Effect>, OfxStatus> {
    if handle.is_null() {
        return Ok(None);
    }
    // SAFETY: checked against the live handles.
    unsafe { handles::resolve(handle as *const Effect, Kind::Effect, function) }
        .map(Some)
        .ok_or(status::ERR_BAD_HANDLE)
}

/// Records a formatted message (from the shim).
pub(crate) fn post(handle: *mut c_void, message: Message) -> OfxStatus {
    let function = if message.persistent {
        "setPersistentMessage"
    } else {
        "message"
    };
    let target = match effect(handle, function) {
        Ok(t) => t,
        Err(s) => return s,
    };
    let log = target.map_or_else(log::current, |e| e.log.clone());
    if !KINDS.iter().any(|k| cstr(k) == message.kind) {
        log.violation(format!(
            "{function}: unknown message type \"{}\"",
            message.kind
        ));
        return status::ERR_UNKNOWN;
    }
    let question = message.kind == cstr(ofx::kOfxMessageQuestion);
    if let Some(e) = target.filter(|e| e.instance && message.persistent) {
        *e.persistent.lock().unwrap_or_else(PoisonError::into_inner) = Some(message.clone());
    }
    log.message(message);
    if question {
        // A headless host answers no.
        status::REPLY_NO
    } else {
        status::OK
    }
}

unsafe extern "C" fn clear_persistent(handle: *mut c_void) -> OfxStatus {
    match effect(handle, "clearPersistentMessage") {
        Err(s) => s,
        Ok(e) => {
            if let Some(e) = e {
                *e.persistent.lock().unwrap_or_else(PoisonError::into_inner) = None;
            }
            status::OK
        }
    }
}

unsafe extern "C" fn progress_start_v1(handle: *mut c_void, _label: *const c_char) -> OfxStatus {
    effect(handle, "progressStart").map_or_else(|s| s, |_| status::OK)
}

unsafe extern "C" fn progress_start_v2(
    handle: *mut c_void,
    _label: *const c_char,
    _id: *const c_char,
) -> OfxStatus {
    effect(handle, "progressStart").map_or_else(|s| s, |_| status::OK)
}

unsafe extern "C" fn progress_update(handle: *mut c_void, progress: f64) -> OfxStatus {
    match effect(handle, "progressUpdate") {
        Err(s) => s,
        Ok(e) => {
            if !(0.0..=1.0).contains(&progress) {
                let log = e.map_or_else(log::current, |e| e.log.clone());
                log.violation(format!("progressUpdate: {progress} is outside [0, 1]"));
                return status::ERR_VALUE;
            }
            status::OK
        }
    }
}

unsafe extern "C" fn progress_end(handle: *mut c_void) -> OfxStatus {
    effect(handle, "progressEnd").map_or_else(|s| s, |_| status::OK)
}
