//! The host and the suites fetched from it.
//!
//! `OfxSetHost` (or each plugin's `setHost`) hands over the host; `kOfxActionLoad` fetches the
//! suites. Suites are `'static` references: the spec keeps them valid while the binary is
//! loaded, and they hold only function pointers, so every render thread may copy them.
//!
//! Real hosts differ in order and repetition: `OfxSetHost` before or after `OfxGetPlugin`,
//! `setHost` once per plugin, load/unload per plugin (some hosts load, describe and unload at
//! start-up, then load again). So: a host pointer different from the one the suites came from
//! forgets them; the last `unload` forgets them; and an action finding none fetches them from
//! the current host (a host that skipped `load` for this plugin after a new `setHost`). The
//! message suite is optional (errors then go to standard error).

use std::ffi::CStr;
use std::os::raw::c_int;
use std::sync::atomic::{AtomicPtr, AtomicUsize, Ordering};
use std::sync::{PoisonError, RwLock};

use openfx_sys::{
    OfxHost, OfxImageEffectSuiteV1, OfxMessageSuiteV1, OfxMessageSuiteV2, OfxParameterSuiteV1,
    OfxPropertySuiteV1,
};

use crate::status::{Failure, Result};

/// The message suite in the newest version the host offers.
#[derive(Clone, Copy)]
pub enum MessageSuite {
    /// Transient messages only.
    V1(&'static OfxMessageSuiteV1),
    /// Transient and persistent messages.
    V2(&'static OfxMessageSuiteV2),
}

/// Every suite the plugin uses.
#[derive(Clone, Copy)]
pub struct Suites {
    /// Properties of every object.
    pub property: &'static OfxPropertySuiteV1,
    /// Clips, images, effect property and parameter sets.
    pub effect: &'static OfxImageEffectSuiteV1,
    /// Parameter definition and values.
    pub param: &'static OfxParameterSuiteV1,
    /// Error messages for the artist, if the host has a message suite.
    pub message: Option<MessageSuite>,
}

static HOST: AtomicPtr<OfxHost> = AtomicPtr::new(std::ptr::null_mut());
static SUITES: RwLock<Option<Suites>> = RwLock::new(None);
/// Plugins of the binary loaded and not unloaded yet.
static LOADED: AtomicUsize = AtomicUsize::new(0);

fn forget() {
    *SUITES.write().unwrap_or_else(PoisonError::into_inner) = None;
}

/// Remembers the host (`OfxSetHost`, `OfxPlugin::setHost`); a different host than before
/// makes the plugin fetch its suites again.
pub fn set_host(host: *const OfxHost) {
    let before = HOST.swap(host.cast_mut(), Ordering::AcqRel);
    if before != host.cast_mut() {
        forget();
    }
}

/// One suite, or `None` when the host does not offer it.
///
/// # Safety
/// `host` must be the host the plugin was given, and `T` the struct of `name` at `version`.
unsafe fn fetch<T>(host: &OfxHost, name: &[u8], version: c_int) -> Option<&'static T> {
    let name = CStr::from_bytes_with_nul(name).ok()?;
    let fetch = host.fetchSuite?;
    // SAFETY: per the caller; the host returns null or a suite valid while we are loaded.
    unsafe {
        fetch(host.host, name.as_ptr(), version)
            .cast::<T>()
            .as_ref()
    }
}

/// `kOfxActionLoad` of one plugin: fetches every suite; a missing mandatory suite is
/// `kOfxStatErrMissingHostFeature`.
pub fn load() -> Result<()> {
    fetch_all()?;
    LOADED.fetch_add(1, Ordering::AcqRel);
    Ok(())
}

/// `kOfxActionUnload` of one plugin: the last one forgets the suites (the host may go away).
pub fn unload() {
    let last = LOADED
        .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| n.checked_sub(1))
        .is_ok_and(|n| n == 1);
    if last {
        forget();
    }
}

fn fetch_all() -> Result<Suites> {
    let host = HOST.load(Ordering::Acquire);
    // SAFETY: the host pointer stays valid while the binary is loaded (ofxCore.h).
    let Some(host) = (unsafe { host.as_ref() }) else {
        return Err(Failure::missing_suite("host (OfxSetHost was not called)"));
    };
    use openfx_sys::{
        kOfxImageEffectSuite, kOfxMessageSuite, kOfxParameterSuite, kOfxPropertySuite,
    };
    // SAFETY: each name is fetched with the struct its header defines for that version.
    let suites = unsafe {
        let message = match fetch::<OfxMessageSuiteV2>(host, kOfxMessageSuite, 2) {
            Some(v2) => Some(MessageSuite::V2(v2)),
            None => fetch(host, kOfxMessageSuite, 1).map(MessageSuite::V1),
        };
        Suites {
            property: fetch(host, kOfxPropertySuite, 1)
                .ok_or_else(|| Failure::missing_suite("OfxPropertySuite V1"))?,
            effect: fetch(host, kOfxImageEffectSuite, 1)
                .ok_or_else(|| Failure::missing_suite("OfxImageEffectSuite V1"))?,
            param: fetch(host, kOfxParameterSuite, 1)
                .ok_or_else(|| Failure::missing_suite("OfxParameterSuite V1"))?,
            message,
        }
    };
    *SUITES.write().unwrap_or_else(PoisonError::into_inner) = Some(suites);
    Ok(suites)
}

/// A string property of the host's descriptor (`OfxHost::host`), if the host sets it.
pub fn host_string(prop: &std::ffi::CStr) -> Option<String> {
    let host = HOST.load(Ordering::Acquire);
    // SAFETY: the host pointer stays valid while the binary is loaded (ofxCore.h).
    let host = unsafe { host.as_ref() }?;
    let property = suites().ok()?.property;
    // SAFETY: the host's descriptor property set, valid as long as the host.
    unsafe { crate::props::Props::new(host.host, property) }
        .string(prop)
        .ok()
}

/// The suites: those loaded, or fetched now from the current host.
pub fn suites() -> Result<Suites> {
    let loaded = *SUITES.read().unwrap_or_else(PoisonError::into_inner);
    match loaded {
        Some(s) => Ok(s),
        None => fetch_all(),
    }
}
