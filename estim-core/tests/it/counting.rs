//! A counting global allocator for the allocation tests: forwards to `System` and counts this
//! thread's allocations. Shared by the estim-core and estim-filters test binaries (estim-filters
//! includes this file with `#[path]`); each binary's `main.rs` declares `mod counting;` once,
//! which installs it for the whole binary.
//!
//! The count is per thread, so the other tests of the binary, running in parallel on their
//! own threads, never show up in a test's count, and a test that does not measure is not
//! affected (it only pays a thread-local increment per allocation).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::hint::black_box;

struct Counting;

thread_local! {
    // Const-initialised and without a destructor: accessing it never allocates, and it is
    // usable at any point of the thread's life.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn bump() {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

// The only unsafe code of the tests: a `#[global_allocator]` has to implement the unsafe trait
// `GlobalAlloc`; this impl only forwards to `System` and bumps the counter.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        bump();
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc::alloc`'s contract.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        bump();
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        bump();
        // SAFETY: as above; `ptr` came from this allocator, i.e. from `System`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Runs `f` and returns its result with the number of heap allocations (including
/// reallocations) it made on this thread (other test threads do not count).
pub fn allocations<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let before = ALLOCATIONS.with(Cell::get);
    let result = black_box(f());
    let after = ALLOCATIONS.with(Cell::get);
    (result, after - before)
}

/// Allocations made by this thread while running `f` (other test threads do not count).
#[allow(dead_code)] // estim-filters' binary uses this form, estim-core's uses `allocations`
pub fn allocations_during(f: impl FnOnce()) -> usize {
    allocations(f).1
}
