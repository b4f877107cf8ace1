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

/// Forgets `ptr` if it is a live handle of `kind`, in one step under the table's lock: `true`
/// for the one caller that removed it, which alone may free its object.
///
/// A separate [`is_live`] then [`unregister`] lets two threads freeing the same handle both
/// pass the check and free twice; here the second caller finds it gone.
pub(crate) fn take<T>(ptr: *const T, kind: Kind) -> bool {
    let mut table = table().lock().unwrap_or_else(PoisonError::into_inner);
    if table.get(&(ptr as usize)) == Some(&kind) {
        table.remove(&(ptr as usize));
        true
    } else {
        false
    }
}

/// Records in the current log that `function` was given `ptr`, which is not a live handle of
/// `kind`.
pub(crate) fn report_bad<T>(ptr: *const T, kind: Kind, function: &str) {
    super::log::current().violation(format!(
        "{function}: {} is not a live {kind:?} handle the host gave out",
        if ptr.is_null() {
            "NULL".to_string()
        } else {
            format!("{ptr:p}")
        }
    ));
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
        report_bad(ptr, kind, function);
        None
    }
}

#[cfg(test)]
mod tests {
    use std::ffi::c_void;
    use std::sync::Barrier;

    use openfx_sys as ofx;

    use super::super::status;
    use super::super::testing::{image_effect_suite, violations_of};
    use super::super::threads::MULTI_THREAD;
    use super::*;

    /// Threads racing to free one handle (more than two widen the window the race needs).
    const RACERS: usize = 4;

    /// Runs `free(handle)` on [`RACERS`] threads at once; the statuses, in thread order, and
    /// the violations each thread logged.
    fn twice(
        handle: usize,
        free: impl Fn(usize) -> ofx::OfxStatus + Sync,
    ) -> Vec<(ofx::OfxStatus, Vec<String>)> {
        let start = Barrier::new(RACERS);
        std::thread::scope(|s| {
            let runs: Vec<_> = (0..RACERS)
                .map(|_| {
                    s.spawn(|| {
                        let mut st = 0;
                        let v = violations_of(|| {
                            start.wait();
                            st = free(handle);
                        });
                        (st, v)
                    })
                })
                .collect();
            runs.into_iter()
                .map(|r| r.join().unwrap_or_else(|_| panic!("free panicked")))
                .collect()
        })
    }

    /// Exactly one free succeeds; every other is ErrBadHandle with one violation naming
    /// `function`.
    fn one_winner(results: &[(ofx::OfxStatus, Vec<String>)], function: &str) {
        let (ok, bad) = (status::OK, status::ERR_BAD_HANDLE);
        let wins = results.iter().filter(|(st, v)| *st == ok && v.is_empty());
        let losses = results
            .iter()
            .filter(|(st, v)| *st == bad && v.len() == 1 && v[0].starts_with(function));
        assert_eq!(
            (wins.count(), losses.count()),
            (1, RACERS - 1),
            "{function}: {results:?}"
        );
    }

    #[test]
    fn table_take_is_won_once() {
        let x = 7u8;
        register(&x as *const u8, Kind::Mutex);
        assert!(!take(&x as *const u8, Kind::ImageMemory));
        assert!(take(&x as *const u8, Kind::Mutex));
        assert!(!take(&x as *const u8, Kind::Mutex));
        assert!(!is_live(&x as *const u8, Kind::Mutex));
    }

    #[test]
    fn two_frees_of_one_image_memory_handle_free_it_once() {
        let suite = image_effect_suite();
        let (Some(alloc), Some(free)) = (suite.imageMemoryAlloc, suite.imageMemoryFree) else {
            panic!("image memory functions missing");
        };
        // Many rounds: the two frees race for the handle in each.
        for _ in 0..1000 {
            let mut h: ofx::OfxImageMemoryHandle = std::ptr::null_mut();
            // SAFETY: a NULL effect is allowed; `h` is writable.
            let st = unsafe { alloc(std::ptr::null_mut(), 64, &mut h) };
            assert_eq!(st, status::OK);
            let results = twice(h as usize, |h| {
                // SAFETY: any pointer is checked against the registry.
                unsafe { free(h as *mut c_void as ofx::OfxImageMemoryHandle) }
            });
            one_winner(&results, "imageMemoryFree");
        }
    }

    #[test]
    fn two_destroys_of_one_mutex_destroy_it_once() {
        let (Some(create), Some(destroy)) = (MULTI_THREAD.mutexCreate, MULTI_THREAD.mutexDestroy)
        else {
            panic!("mutex functions missing");
        };
        for _ in 0..1000 {
            let mut h: ofx::OfxMutexHandle = std::ptr::null_mut();
            // SAFETY: `h` is writable.
            let st = unsafe { create(&mut h, 0) };
            assert_eq!(st, status::OK);
            let results = twice(h as usize, |h| {
                // SAFETY: any pointer is checked against the registry.
                unsafe { destroy(h as *mut c_void as ofx::OfxMutexHandle) }
            });
            one_winner(&results, "mutexDestroy");
        }
    }
}
