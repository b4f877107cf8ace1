//! Error messages for the artist, through the host's message suite.
//!
//! Hosts show the two kinds very differently: a *persistent* message (message suite V2) marks
//! the node until the plugin clears it, while a transient message is, in most hosts, a modal
//! dialog. Hosts call the instance queries (region of definition, clip preferences, identity,
//! regions of interest) at will, many times per second while the artist scrubs or edits, so:
//!
//! - with V2 every instance failure becomes the node's persistent message, cleared by the next
//!   successful render and by an edit of the artist ([`reset`]);
//! - without V2 the first failure after an edit of the artist becomes one transient message
//!   (a dialog) and later ones go to standard error until the next edit: a query must be able
//!   to speak (a host does not render a node whose region of definition failed), but texts
//!   often name the frame, so one per distinct text would still be a dialog per frame;
//! - descriptors and the plugin itself get transient messages (or standard error).
//!
//! The text always goes through a `"%s"` format, so no `%` in a file name is ever interpreted.

use std::ffi::c_void;
use std::sync::{Mutex, PoisonError};

use openfx_sys::{kOfxMessageError, kOfxMessageWarning};

use crate::props::{c_string, name};
use crate::suites::{suites, MessageSuite};

/// Where a message goes.
#[derive(Clone, Copy, Debug)]
pub enum Target {
    /// No handle (entry points outside any action).
    Plugin,
    /// A descriptor (describe actions): transient messages only.
    Descriptor(*mut c_void),
    /// An effect instance: persistent messages where the host offers them.
    Instance(*mut c_void),
}

/// What an instance has shown the artist.
#[derive(Debug, Default)]
pub struct Shown {
    /// A persistent message is set on the node.
    persistent: bool,
    /// The text of the persistent warning set on the node, if that is what is set: the same
    /// warning is not posted again (every tile of a frame, every query would).
    warning: Option<String>,
    /// A transient message was shown since the last edit.
    transient: bool,
}

/// How to deliver a message, given the host's suite and what the instance already showed.
#[derive(Debug, PartialEq, Eq)]
enum Delivery {
    Persistent,
    Transient,
    StandardError,
}

/// The pure decision of [`post_error`] (updates `shown`).
fn delivery(v2: Option<bool>, target: Target, shown: Option<&mut Shown>) -> Delivery {
    let Some(v2) = v2 else {
        return Delivery::StandardError;
    };
    match target {
        Target::Plugin | Target::Descriptor(_) => Delivery::Transient,
        Target::Instance(_) => match shown {
            Some(s) if v2 => {
                s.persistent = true;
                s.warning = None;
                Delivery::Persistent
            }
            _ if v2 => Delivery::Persistent,
            Some(s) if s.transient => Delivery::StandardError,
            Some(s) => {
                s.transient = true;
                Delivery::Transient
            }
            None => Delivery::Transient,
        },
    }
}

/// Posts `text` as an error as the module explains; standard error when the host has no
/// message suite or its suites are not loaded yet. `shown` is the record of an instance
/// target (none for other targets, or when the instance cannot be found).
pub fn post_error(target: Target, shown: Option<&Mutex<Shown>>, text: &str) {
    let Ok(s) = suites() else {
        eprintln!("nerfx.ofx: {text}");
        return;
    };
    let v2 = s.message.map(|m| matches!(m, MessageSuite::V2(_)));
    let how = match shown {
        Some(shown) => {
            let mut shown = shown.lock().unwrap_or_else(PoisonError::into_inner);
            delivery(v2, target, Some(&mut shown))
        }
        None => delivery(v2, target, None),
    };
    let c_text = c_string(text);
    let kind = name(kOfxMessageError).as_ptr();
    let id = c"".as_ptr();
    let format = c"%s".as_ptr();
    let handle = match target {
        Target::Plugin => std::ptr::null_mut(),
        Target::Descriptor(h) | Target::Instance(h) => h,
    };
    // SAFETY: the suite functions are the host's; "%s" takes exactly one C string argument.
    unsafe {
        match (s.message, how) {
            (Some(MessageSuite::V2(m)), Delivery::Persistent) => {
                if let Some(f) = m.setPersistentMessage {
                    f(handle, kind, id, format, c_text.as_ptr());
                }
            }
            (Some(MessageSuite::V2(m)), Delivery::Transient) => {
                if let Some(f) = m.message {
                    f(handle, kind, id, format, c_text.as_ptr());
                }
            }
            (Some(MessageSuite::V1(m)), Delivery::Transient) => {
                if let Some(f) = m.message {
                    f(handle, kind, id, format, c_text.as_ptr());
                }
            }
            _ => eprintln!("nerfx.ofx: {text}"),
        }
    }
}

/// Marks an instance whose render succeeded but has something to say with a persistent
/// *warning* (the host goes on; the node is flagged, without a dialog): a node without all
/// its files says why it renders nothing, a render whose pixels may be off says why and what
/// to do. Hosts without persistent messages get it once per edit on standard error. Cleared
/// like an error: by the artist's next edit or a clean render. A warning already on the node
/// is not posted again: every tile of a frame, and every query of a node not ready, would.
pub fn warn(instance: *mut c_void, shown: &Mutex<Shown>, text: &str) {
    let mut shown = shown.lock().unwrap_or_else(PoisonError::into_inner);
    match suites().ok().and_then(|s| s.message) {
        Some(MessageSuite::V2(m)) => {
            if shown.persistent && shown.warning.as_deref() == Some(text) {
                return;
            }
            if let Some(f) = m.setPersistentMessage {
                shown.persistent = true;
                shown.warning = Some(text.to_string());
                let c_text = c_string(text);
                // SAFETY: the host's function on the current action's instance; "%s" takes
                // exactly one C string argument.
                unsafe {
                    f(
                        instance,
                        name(kOfxMessageWarning).as_ptr(),
                        c"".as_ptr(),
                        c"%s".as_ptr(),
                        c_text.as_ptr(),
                    )
                };
            }
        }
        _ if !shown.transient => {
            shown.transient = true;
            eprintln!("nerfx.ofx: {text}");
        }
        _ => {}
    }
}

/// After a clean render: clears the node's persistent message, if one is set.
pub fn succeeded(instance: *mut c_void, shown: &Mutex<Shown>) {
    let was = {
        let mut shown = shown.lock().unwrap_or_else(PoisonError::into_inner);
        shown.warning = None;
        std::mem::take(&mut shown.persistent)
    };
    if was {
        clear_persistent(instance);
    }
}

/// After an edit of the artist: clears the persistent message and lets a transient one be
/// shown again (the next action re-checks and reports what is still wrong).
pub fn reset(instance: *mut c_void, shown: &Mutex<Shown>) {
    *shown.lock().unwrap_or_else(PoisonError::into_inner) = Shown::default();
    clear_persistent(instance);
}

fn clear_persistent(instance: *mut c_void) {
    if let Ok(s) = suites() {
        if let Some(MessageSuite::V2(m)) = s.message {
            if let Some(f) = m.clearPersistentMessage {
                // SAFETY: `instance` is the effect instance handle of the current action.
                unsafe { f(instance) };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: *mut c_void = 8usize as *mut c_void;

    #[test]
    fn with_v2_instance_failures_are_persistent_and_remembered() {
        let mut shown = Shown::default();
        for _ in 0..2 {
            let t = Target::Instance(H);
            assert_eq!(
                delivery(Some(true), t, Some(&mut shown)),
                Delivery::Persistent
            );
            assert!(shown.persistent);
        }
        assert_eq!(
            delivery(Some(true), Target::Descriptor(H), None),
            Delivery::Transient
        );
    }

    #[test]
    fn without_v2_one_dialog_per_edit() {
        let mut shown = Shown::default();
        // The same instance, asked for its region, then rendered.
        let query = Target::Instance(H);
        let render = Target::Instance(H);
        // A failed region of definition must speak: the host will not render.
        assert_eq!(
            delivery(Some(false), query, Some(&mut shown)),
            Delivery::Transient
        );
        // Everything after it (other frames, the render) waits for an edit.
        for t in [render, query, render] {
            assert_eq!(
                delivery(Some(false), t, Some(&mut shown)),
                Delivery::StandardError
            );
        }
        assert!(!shown.persistent);
        // After an edit a failure is shown again.
        shown = Shown::default();
        assert_eq!(
            delivery(Some(false), render, Some(&mut shown)),
            Delivery::Transient
        );
    }

    #[test]
    fn no_message_suite_means_standard_error() {
        for t in [Target::Plugin, Target::Descriptor(H), Target::Instance(H)] {
            assert_eq!(delivery(None, t, None), Delivery::StandardError);
        }
    }
}
