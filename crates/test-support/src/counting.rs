//! A global allocator that counts allocations three ways: every thread's
//! ([`process_allocations`]), this thread's ([`thread_allocations`]), and
//! those of the threads inside [`counted`] ([`allocations`]; the test's
//! thread standing for the loop's). What the allocation-free claims of the
//! loop's path are proved with. A test binary installs it with
//! `#[global_allocator] static GLOBAL: Counting = Counting;` (a global
//! allocator is declared once per binary, so in the test file). It also
//! keeps the bytes allocated and their peak ([`peak_bytes_in`]): what the
//! memory bounds of the readers are shown with.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

/// The counting allocator (forwards to the system allocator).
pub struct Counting;

/// Allocations on every thread.
static PROCESS: AtomicU64 = AtomicU64::new(0);
/// Allocations on the threads inside [`counted`].
static COUNTED_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
/// Bytes allocated and not freed, every thread.
static LIVE_BYTES: AtomicU64 = AtomicU64::new(0);
/// The largest `LIVE_BYTES` since the last [`peak_bytes_in`] began.
static PEAK_BYTES: AtomicU64 = AtomicU64::new(0);

/// `n` bytes more in use.
fn grow(n: usize) {
    let live = LIVE_BYTES.fetch_add(n as u64, Ordering::SeqCst) + n as u64;
    PEAK_BYTES.fetch_max(live, Ordering::SeqCst);
}

/// `n` bytes fewer in use.
fn shrink(n: usize) {
    LIVE_BYTES.fetch_sub(n as u64, Ordering::SeqCst);
}

thread_local! {
    /// Whether this thread is inside [`counted`] (const thread-locals
    /// without destructor: reading them never allocates).
    static COUNTED: Cell<bool> = const { Cell::new(false) };
    /// This thread's allocations.
    static THREAD: Cell<u64> = const { Cell::new(0) };
}

/// Counts one allocation (or reallocation).
fn count() {
    PROCESS.fetch_add(1, Ordering::SeqCst);
    let _ = THREAD.try_with(|c| c.set(c.get() + 1));
    if COUNTED.try_with(Cell::get).unwrap_or(false) {
        COUNTED_ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
    }
}

// SAFETY: forwards to the system allocator, only counting.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grow(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        shrink(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            grow(new_size);
            shrink(layout.size());
        }
        p
    }
}

/// Runs `f` with this thread's allocations counted in [`allocations`].
pub fn counted<T>(f: impl FnOnce() -> T) -> T {
    COUNTED.with(|c| c.set(true));
    let out = f();
    COUNTED.with(|c| c.set(false));
    out
}

/// Allocations counted so far inside [`counted`] (on any thread).
pub fn allocations() -> u64 {
    COUNTED_ALLOCATIONS.load(Ordering::SeqCst)
}

/// Allocations so far on every thread of the process.
pub fn process_allocations() -> u64 {
    PROCESS.load(Ordering::SeqCst)
}

/// Allocations so far on this thread.
pub fn thread_allocations() -> u64 {
    THREAD.with(Cell::get)
}

/// Runs `f`: its result and the allocations it made on this thread.
pub fn allocations_in<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let before = thread_allocations();
    let out = f();
    (out, thread_allocations() - before)
}

/// Runs `f`: its result and the peak of the bytes in use while it ran,
/// above those in use when it began (every thread's: run such a test
/// alone in its binary, or serialised, for a figure of `f`'s own).
pub fn peak_bytes_in<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let base = LIVE_BYTES.load(Ordering::SeqCst);
    PEAK_BYTES.store(base, Ordering::SeqCst);
    let out = f();
    (out, PEAK_BYTES.load(Ordering::SeqCst).saturating_sub(base))
}
