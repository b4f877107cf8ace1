//! The host and the suites fetched from it.
//!
//! `OfxSetHost` (or each plugin's `setHost`) hands over the host; `kOfxActionLoad` fetches the
//! suites once. Suites are `'static` references: the spec keeps them valid while the binary is
//! loaded, and they hold only function pointers, so every render thread may copy them.

use std::ffi::CStr;
use std::os::raw::c_int;
use std::sync::atomic::{AtomicPtr, Ordering};
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
    /// Error messages for the artist.
    pub message: MessageSuite,
}

static HOST: AtomicPtr<OfxHost> = AtomicPtr::new(std::ptr::null_mut());
static SUITES: RwLock<Option<Suites>> = RwLock::new(None);

/// Remembers the host (`OfxSetHost`, `OfxPlugin::setHost`).
pub fn set_host(host: *const OfxHost) {
    HOST.store(host.cast_mut(), Ordering::Release);
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

/// Fetches every suite (`kOfxActionLoad`): a missing mandatory suite is
/// `kOfxStatErrMissingHostFeature`.
pub fn load() -> Result<()> {
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
            Some(v2) => MessageSuite::V2(v2),
            None => MessageSuite::V1(
                fetch(host, kOfxMessageSuite, 1)
                    .ok_or_else(|| Failure::missing_suite("OfxMessageSuite (V1 or V2)"))?,
            ),
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
    Ok(())
}

/// The suites, once loaded.
pub fn suites() -> Result<Suites> {
    SUITES
        .read()
        .unwrap_or_else(PoisonError::into_inner)
        .ok_or_else(|| Failure::failed("action before kOfxActionLoad: no host suites"))
}
