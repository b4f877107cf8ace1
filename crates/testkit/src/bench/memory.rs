//! Heap accounting for the benchmark: a counting global allocator and the peak it saw.
//!
//! A program that wants the figures installs [`CountingAllocator`] as its global allocator
//! (the `nerfx` binary does); [`peak_during`] then reports the most heap bytes that were
//! live at once while a closure ran, above what was live when it started. Counting is off
//! (one relaxed load per allocation) except inside [`peak_during`], and where the allocator
//! is not installed every figure is `None`.
//!
//! Heap bytes are what the program asked for, exactly and at the moment it asked; a
//! process's resident high-water mark (`VmHWM`) would also count the allocator's retained
//! free lists, stacks and code, and could not be reset per render.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicIsize, Ordering};
use std::sync::Mutex;

/// The system allocator, counting live bytes and their peak while enabled.
pub struct CountingAllocator;

static COUNTING: AtomicBool = AtomicBool::new(false);
/// Live bytes allocated since counting began, minus those freed (frees of blocks allocated
/// before can make it negative).
static LIVE: AtomicIsize = AtomicIsize::new(0);
static PEAK: AtomicIsize = AtomicIsize::new(0);
/// One measurement at a time.
static MEASURING: Mutex<()> = Mutex::new(());

impl CountingAllocator {
    #[inline]
    fn grow(bytes: usize) {
        if COUNTING.load(Ordering::Relaxed) {
            let live = LIVE.fetch_add(bytes as isize, Ordering::Relaxed) + bytes as isize;
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
    }

    #[inline]
    fn shrink(bytes: usize) {
        if COUNTING.load(Ordering::Relaxed) {
            LIVE.fetch_sub(bytes as isize, Ordering::Relaxed);
        }
    }
}

// SAFETY: every call forwards to `System` with the caller's own arguments; the counters
// are plain atomics and never affect what is allocated.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            Self::grow(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if !p.is_null() {
            Self::grow(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        Self::shrink(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if !p.is_null() {
            Self::shrink(layout.size());
            Self::grow(new_size);
        }
        p
    }
}

/// What a closure did to the heap.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HeapUse {
    /// The most bytes live at once above those live when it started.
    pub peak: usize,
    /// Bytes still live when it returned, above those live when it started (what it kept:
    /// its result, caches it filled).
    pub kept: isize,
}

/// Runs `f`, and where [`CountingAllocator`] is the global allocator, says how much heap it
/// used; `None` elsewhere. Measurements are serialised (a second caller waits; `f` itself
/// must not measure).
pub fn peak_during<T>(f: impl FnOnce() -> T) -> (T, Option<HeapUse>) {
    let _one = MEASURING.lock().unwrap_or_else(|e| e.into_inner());
    LIVE.store(0, Ordering::Relaxed);
    PEAK.store(0, Ordering::Relaxed);
    COUNTING.store(true, Ordering::SeqCst);
    // A probe: counted only when this allocator serves the program's allocations.
    let installed = {
        let probe = std::hint::black_box(vec![0u8; 64]);
        let seen = LIVE.load(Ordering::Relaxed) >= 64;
        drop(probe);
        seen
    };
    LIVE.store(0, Ordering::Relaxed);
    PEAK.store(0, Ordering::Relaxed);
    let out = f();
    COUNTING.store(false, Ordering::SeqCst);
    let used = HeapUse {
        peak: PEAK.load(Ordering::Relaxed).max(0) as usize,
        kept: LIVE.load(Ordering::Relaxed),
    };
    (out, installed.then_some(used))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_the_allocator_installed_nothing_is_claimed() {
        // The unit tests run on the system allocator.
        let (n, used) = peak_during(|| vec![1u8; 1 << 20].len());
        assert_eq!(n, 1 << 20);
        assert_eq!(used, None);
    }
}
