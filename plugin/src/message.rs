//! Error messages for the artist, through the host's message suite.
//!
//! On an effect instance with the V2 suite the message is *persistent* (the host marks the
//! node until the plugin clears it, see [`clear`]); otherwise it is a transient message. The
//! text always goes through a `"%s"` format, so no `%` in a file name is ever interpreted.

use std::ffi::c_void;

use openfx_sys::kOfxMessageError;

use crate::props::{c_string, name};
use crate::suites::{suites, MessageSuite};

/// Where a message goes.
#[derive(Clone, Copy)]
pub enum Target {
    /// No handle (entry points outside any action).
    Plugin,
    /// A descriptor (describe actions): transient messages only.
    Descriptor(*mut c_void),
    /// An effect instance: persistent messages where the host offers them.
    Instance(*mut c_void),
}

/// Posts `text` as an error; falls back to standard error when the host's suites are not
/// loaded yet (a failure in `OfxSetHost` or `kOfxActionLoad` itself).
pub fn post_error(target: Target, text: &str) {
    let Ok(s) = suites() else {
        eprintln!("nerfx.ofx: {text}");
        return;
    };
    let text = c_string(text);
    let kind = name(kOfxMessageError).as_ptr();
    let id = c"".as_ptr();
    let format = c"%s".as_ptr();
    let handle = match target {
        Target::Plugin => std::ptr::null_mut(),
        Target::Descriptor(h) | Target::Instance(h) => h,
    };
    // SAFETY: the suite functions are the host's; "%s" takes exactly one C string argument.
    unsafe {
        match (s.message, target) {
            (MessageSuite::V2(m), Target::Instance(_)) => {
                if let Some(f) = m.setPersistentMessage {
                    f(handle, kind, id, format, text.as_ptr());
                }
            }
            (MessageSuite::V2(m), _) => {
                if let Some(f) = m.message {
                    f(handle, kind, id, format, text.as_ptr());
                }
            }
            (MessageSuite::V1(m), _) => {
                if let Some(f) = m.message {
                    f(handle, kind, id, format, text.as_ptr());
                }
            }
        }
    }
}

/// Clears the instance's persistent message (after the artist changed something).
pub fn clear(instance: *mut c_void) {
    if let Ok(s) = suites() {
        if let MessageSuite::V2(m) = s.message {
            if let Some(f) = m.clearPersistentMessage {
                // SAFETY: `instance` is the effect instance handle of the current action.
                unsafe { f(instance) };
            }
        }
    }
}
