//! The multithread suite: real threads and real, recursive mutexes.

use std::cell::Cell;
use std::ffi::{c_int, c_uint, c_void};
use std::sync::{Condvar, Mutex, PoisonError};
use std::thread::ThreadId;

use openfx_sys as ofx;
use openfx_sys::{OfxMutexHandle, OfxStatus};

use super::handles::{self, Kind};
use super::{effect, log, params::put, status};

/// Multithread suite V1.
pub(crate) static MULTI_THREAD: ofx::OfxMultiThreadSuiteV1 = ofx::OfxMultiThreadSuiteV1 {
    multiThread: Some(multi_thread),
    multiThreadNumCPUs: Some(num_cpus),
    multiThreadIndex: Some(thread_index),
    multiThreadIsSpawnedThread: Some(is_spawned),
    mutexCreate: Some(mutex_create),
    mutexDestroy: Some(mutex_destroy),
    mutexLock: Some(mutex_lock),
    mutexUnLock: Some(mutex_unlock),
    mutexTryLock: Some(mutex_try_lock),
};

thread_local! {
    static INDEX: Cell<Option<u32>> = const { Cell::new(None) };
}

unsafe extern "C" fn multi_thread(
    func: ofx::OfxThreadFunctionV1,
    n: c_uint,
    arg: *mut c_void,
) -> OfxStatus {
    let Some(func) = func else {
        log::current().violation("multiThread: NULL function");
        return status::FAILED;
    };
    let n = n.max(1);
    let current_log = log::current();
    let render = effect::current_render();
    let arg = arg as usize;
    std::thread::scope(|s| {
        for i in 0..n {
            let current_log = current_log.clone();
            s.spawn(move || {
                let _scope = log::ActionScope::enter(current_log);
                let _render = effect::RenderScope::enter(render);
                INDEX.with(|x| x.set(Some(i)));
                // SAFETY: the plugin's function, called as the suite promises.
                unsafe { func(i, n, arg as *mut c_void) };
            });
        }
    });
    status::OK
}

unsafe extern "C" fn num_cpus(out: *mut c_uint) -> OfxStatus {
    let n = std::thread::available_parallelism().map_or(1, |n| n.get() as c_uint);
    // SAFETY: writable by contract.
    unsafe { put(out, n) };
    status::OK
}

unsafe extern "C" fn thread_index(out: *mut c_uint) -> OfxStatus {
    // SAFETY: writable by contract.
    unsafe { put(out, INDEX.with(|x| x.get()).unwrap_or(0)) };
    status::OK
}

unsafe extern "C" fn is_spawned() -> c_int {
    c_int::from(INDEX.with(|x| x.get()).is_some())
}

/// A recursive mutex: the owning thread may lock it again; it is free when its count is 0.
#[derive(Default)]
struct RecursiveMutex {
    state: Mutex<(Option<ThreadId>, u32)>,
    freed: Condvar,
}

impl RecursiveMutex {
    fn try_lock(&self, wait: bool) -> bool {
        let me = std::thread::current().id();
        let mut s = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            match s.0 {
                None => {
                    *s = (Some(me), 1);
                    return true;
                }
                Some(owner) if owner == me => {
                    s.1 += 1;
                    return true;
                }
                Some(_) if !wait => return false,
                Some(_) => s = self.freed.wait(s).unwrap_or_else(PoisonError::into_inner),
            }
        }
    }

    fn unlock(&self) -> bool {
        let me = std::thread::current().id();
        let mut s = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        if s.0 != Some(me) {
            return false;
        }
        s.1 -= 1;
        if s.1 == 0 {
            s.0 = None;
            self.freed.notify_one();
        }
        true
    }
}

/// # Safety
/// `h` is any pointer; it is checked against the live handles.
unsafe fn mutex<'a>(h: OfxMutexHandle, function: &str) -> Option<&'a RecursiveMutex> {
    // SAFETY: checked against the registry.
    unsafe { handles::resolve(h as *const RecursiveMutex, Kind::Mutex, function) }
}

unsafe extern "C" fn mutex_create(out: *mut OfxMutexHandle, count: c_int) -> OfxStatus {
    if out.is_null() {
        log::current().violation("mutexCreate: NULL destination");
        return status::FAILED;
    }
    let m = Box::new(RecursiveMutex::default());
    for _ in 0..count.max(0) {
        m.try_lock(true);
    }
    let ptr = Box::into_raw(m);
    handles::register(ptr as *const RecursiveMutex, Kind::Mutex);
    // SAFETY: checked non-NULL.
    unsafe { out.write(ptr as OfxMutexHandle) };
    status::OK
}

unsafe extern "C" fn mutex_destroy(h: OfxMutexHandle) -> OfxStatus {
    let p = h as *const RecursiveMutex;
    // Taken from the registry in one step: of two threads destroying the same mutex, only one
    // gets it; the other's is a bad handle.
    if !handles::take(p, Kind::Mutex) {
        handles::report_bad(p, Kind::Mutex, "mutexDestroy");
        return status::ERR_BAD_HANDLE;
    }
    // SAFETY: a live handle came from Box::into_raw, and this caller alone removed it.
    drop(unsafe { Box::from_raw(p as *mut RecursiveMutex) });
    status::OK
}

unsafe extern "C" fn mutex_lock(h: OfxMutexHandle) -> OfxStatus {
    // SAFETY: checked against the registry.
    match unsafe { mutex(h, "mutexLock") } {
        Some(m) => {
            m.try_lock(true);
            status::OK
        }
        None => status::ERR_BAD_HANDLE,
    }
}

unsafe extern "C" fn mutex_unlock(h: OfxMutexHandle) -> OfxStatus {
    // SAFETY: checked against the registry.
    match unsafe { mutex(h, "mutexUnLock") } {
        Some(m) if m.unlock() => status::OK,
        Some(_) => {
            log::current().violation("mutexUnLock: the calling thread does not hold the mutex");
            status::FAILED
        }
        None => status::ERR_BAD_HANDLE,
    }
}

unsafe extern "C" fn mutex_try_lock(h: OfxMutexHandle) -> OfxStatus {
    // SAFETY: checked against the registry.
    match unsafe { mutex(h, "mutexTryLock") } {
        Some(m) if m.try_lock(false) => status::OK,
        Some(_) => status::FAILED,
        None => status::ERR_BAD_HANDLE,
    }
}
