//! The handles the host has given out. Every suite function checks its handle here before
//! touching it, so a stale or invented handle is an error status and a violation rather than
//! a crash.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock, PoisonError};

/// What a handle points to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// A [`super::props::PropSet`] (also an image: images are property sets).
    PropSet,
    /// A [`super::effect::Effect`] (descriptor or instance).
    Effect,
    /// A [`super::effect::Clip`].
    Clip,
    /// A [`super::params::ParamSet`].
    ParamSet,
    /// A [`super::params::Param`].
    Param,
    /// Image memory from `imageMemoryAlloc`.
    ImageMemory,
    /// A mutex from `mutexCreate`.
    Mutex,
}

fn table() -> &'static Mutex<HashMap<usize, Kind>> {
    static TABLE: OnceLock<Mutex<HashMap<usize, Kind>>> = OnceLock::new();
    TABLE.get_or_init(Default::default)
}

/// Records `ptr` as a live handle of `kind`.
pub(crate) fn register<T>(ptr: *const T, kind: Kind) {
    table()
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .insert(ptr as usize, kind);
}

/// Forgets `ptr` (its object is being dropped).
pub(crate) fn unregister<T>(ptr: *const T) {
    table()
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .remove(&(ptr as usize));
}

/// Whether `ptr` is a live handle of `kind`.
pub(crate) fn is_live<T>(ptr: *const T, kind: Kind) -> bool {
    table()
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .get(&(ptr as usize))
        == Some(&kind)
}

/// The object behind a handle, if it is a live handle of `kind`; else records a violation
/// naming `function` in the current log.
///
/// # Safety
/// Objects register themselves only while boxed and alive, and unregister before they are
/// freed; the host frees none while an action that can reach it is running.
pub(crate) unsafe fn resolve<'a, T>(ptr: *const T, kind: Kind, function: &str) -> Option<&'a T> {
    if !ptr.is_null() && is_live(ptr, kind) {
        // SAFETY: live handles point to boxed objects that outlive the call (see above).
        Some(unsafe { &*ptr })
    } else {
        super::log::current().violation(format!(
            "{function}: {} is not a live {kind:?} handle the host gave out",
            if ptr.is_null() {
                "NULL".to_string()
            } else {
                format!("{ptr:p}")
            }
        ));
        None
    }
}
