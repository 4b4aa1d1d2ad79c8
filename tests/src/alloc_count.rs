//! A counting global allocator for the zero-allocation tests. A test binary installs
//! it with `#[global_allocator] static A: Counting = Counting;` and wraps the code
//! under test in [`count`].
//!
//! Counted, while a window is open: every allocation and free on the thread that
//! opened it (the real-time path), and the same on every thread (printed by the
//! tests: it includes helper threads such as the forwarder). A reallocation both
//! allocates and frees.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

pub struct Counting;

static THIS_ALLOCS: AtomicU64 = AtomicU64::new(0);
static THIS_FREES: AtomicU64 = AtomicU64::new(0);
static ALL_ALLOCS: AtomicU64 = AtomicU64::new(0);
static ALL_FREES: AtomicU64 = AtomicU64::new(0);
static WINDOW: AtomicBool = AtomicBool::new(false);

thread_local! {
    // const-initialised and without a destructor: reading it never allocates.
    static COUNTED_THREAD: Cell<bool> = const { Cell::new(false) };
}

fn tally(this: &AtomicU64, all: &AtomicU64) {
    if WINDOW.load(Ordering::Relaxed) {
        all.fetch_add(1, Ordering::Relaxed);
        // try_with: a thread being torn down has no thread-locals left.
        if COUNTED_THREAD.try_with(Cell::get).unwrap_or(false) {
            this.fetch_add(1, Ordering::Relaxed);
        }
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        tally(&THIS_ALLOCS, &ALL_ALLOCS);
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        tally(&THIS_ALLOCS, &ALL_ALLOCS);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        tally(&THIS_FREES, &ALL_FREES);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        tally(&THIS_ALLOCS, &ALL_ALLOCS);
        tally(&THIS_FREES, &ALL_FREES);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// What one window counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// On the thread that ran [`count`].
    pub this_thread_allocs: u64,
    pub this_thread_frees: u64,
    /// On every thread, over the same window.
    pub all_allocs: u64,
    pub all_frees: u64,
}

/// Runs `f` with the window open and returns what it counted. Windows do not nest;
/// each zero-allocation test binary runs one test.
pub fn count<R>(f: impl FnOnce() -> R) -> (R, Counts) {
    for c in [&THIS_ALLOCS, &THIS_FREES, &ALL_ALLOCS, &ALL_FREES] {
        c.store(0, Ordering::SeqCst);
    }
    COUNTED_THREAD.with(|c| c.set(true));
    WINDOW.store(true, Ordering::SeqCst);
    let r = f();
    WINDOW.store(false, Ordering::SeqCst);
    COUNTED_THREAD.with(|c| c.set(false));
    let counts = Counts {
        this_thread_allocs: THIS_ALLOCS.load(Ordering::SeqCst),
        this_thread_frees: THIS_FREES.load(Ordering::SeqCst),
        all_allocs: ALL_ALLOCS.load(Ordering::SeqCst),
        all_frees: ALL_FREES.load(Ordering::SeqCst),
    };
    (r, counts)
}
