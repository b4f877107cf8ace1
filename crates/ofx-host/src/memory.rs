//! The memory suite: allocations tracked, so freeing a pointer the host never gave out is a
//! violation. The image effect suite's image memory comes from the same allocator.

use std::alloc::{alloc, dealloc, Layout};
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Mutex, OnceLock, PoisonError};

use openfx_sys as ofx;
use openfx_sys::OfxStatus;

use super::{log, status};

/// Memory suite V1.
pub(crate) static MEMORY: ofx::OfxMemorySuiteV1 = ofx::OfxMemorySuiteV1 {
    memoryAlloc: Some(memory_alloc),
    memoryFree: Some(memory_free),
};

fn allocations() -> &'static Mutex<HashMap<usize, Layout>> {
    static ALLOCATIONS: OnceLock<Mutex<HashMap<usize, Layout>>> = OnceLock::new();
    ALLOCATIONS.get_or_init(Default::default)
}

/// Allocates `n` bytes aligned to 16, tracked; NULL when `n` is 0 or too large.
pub(crate) fn allocate(n: usize) -> *mut c_void {
    let Ok(layout) = Layout::from_size_align(n.max(1), 16) else {
        return std::ptr::null_mut();
    };
    // SAFETY: a non-zero size.
    let ptr = unsafe { alloc(layout) };
    if !ptr.is_null() {
        allocations()
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(ptr as usize, layout);
    }
    ptr.cast()
}

/// Frees an allocation of [`allocate`]; false when `ptr` is not one.
pub(crate) fn free(ptr: *mut c_void) -> bool {
    let layout = allocations()
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .remove(&(ptr as usize));
    match layout {
        // SAFETY: allocated by `allocate` with this layout.
        Some(layout) => unsafe { dealloc(ptr.cast(), layout) },
        None => return false,
    }
    true
}

unsafe extern "C" fn memory_alloc(
    _handle: *mut c_void,
    n: usize,
    out: *mut *mut c_void,
) -> OfxStatus {
    if out.is_null() {
        log::current().violation("memoryAlloc: NULL destination");
        return status::FAILED;
    }
    let ptr = allocate(n);
    // SAFETY: checked non-NULL.
    unsafe { out.write(ptr) };
    if ptr.is_null() {
        status::ERR_MEMORY
    } else {
        status::OK
    }
}

unsafe extern "C" fn memory_free(ptr: *mut c_void) -> OfxStatus {
    if free(ptr) {
        status::OK
    } else {
        log::current().violation(format!(
            "memoryFree: {ptr:p} was not allocated by memoryAlloc"
        ));
        status::ERR_BAD_HANDLE
    }
}
