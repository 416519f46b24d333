//! Measuring memory for real: a counting global allocator, glibc's own heap
//! statistics and the resident set size.
//!
//! A binary that wants the counts installs the allocator:
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOC: octolinear_ablation::alloc::CountingAlloc = octolinear_ablation::alloc::CountingAlloc;
//! ```
//!
//! [`CountingAlloc`] wraps [`System`] and counts the bytes Rust code
//! requests (live and peak, process-wide, plus a per-thread live count).
//! Allocations made by C or C++ code (OctoMap through the oracle) bypass
//! it; [`heap_in_use`] (glibc's `mallinfo2`) sees both, including malloc's
//! per-chunk headers and rounding, and [`rss_bytes`] sees what the kernel
//! has mapped.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static CALLS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static THREAD_LIVE: Cell<isize> = const { Cell::new(0) };
}

/// [`System`] with byte counting; see the module docs.
pub struct CountingAlloc;

#[inline(always)]
fn added(size: usize) {
    let live = LIVE.fetch_add(size, Relaxed) + size;
    PEAK.fetch_max(live, Relaxed);
    CALLS.fetch_add(1, Relaxed);
    let _ = THREAD_LIVE.try_with(|t| t.set(t.get() + size as isize));
}

#[inline(always)]
fn removed(size: usize) {
    LIVE.fetch_sub(size, Relaxed);
    let _ = THREAD_LIVE.try_with(|t| t.set(t.get() - size as isize));
}

// SAFETY: every call is forwarded unchanged to `System`; only counters change.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            added(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: as for `alloc`.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            added(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` with `layout`.
        unsafe { System.dealloc(ptr, layout) };
        removed(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller upholds `GlobalAlloc::realloc`'s contract.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            removed(layout.size());
            added(new_size);
        }
        p
    }
}

/// Bytes requested through [`CountingAlloc`] and not yet freed, all threads.
pub fn live_bytes() -> usize {
    LIVE.load(Relaxed)
}

/// Highest [`live_bytes`] since the start or the last [`reset_peak`].
pub fn peak_bytes() -> usize {
    PEAK.load(Relaxed)
}

/// Starts a new peak from the current live bytes.
pub fn reset_peak() {
    PEAK.store(LIVE.load(Relaxed), Relaxed);
}

/// Allocation calls (`alloc`, `alloc_zeroed`, `realloc`) so far.
pub fn alloc_calls() -> usize {
    CALLS.load(Relaxed)
}

/// Live bytes allocated minus freed by the calling thread (signed: a thread
/// may free what another allocated).
pub fn thread_live_bytes() -> isize {
    THREAD_LIVE.with(Cell::get)
}

/// `true` when [`CountingAlloc`] is the global allocator of this binary
/// (checked by allocating).
pub fn is_counting() -> bool {
    let before = alloc_calls();
    let v = std::hint::black_box(vec![0u8; 1]);
    drop(v);
    alloc_calls() != before
}

/// Resident set size (`VmRSS` in `/proc/self/status`), in bytes.
pub fn rss_bytes() -> Option<usize> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod glibc {
    /// glibc's `struct mallinfo2` (glibc >= 2.33).
    #[repr(C)]
    #[derive(Default)]
    pub struct MallInfo2 {
        pub arena: usize,
        pub ordblks: usize,
        pub smblks: usize,
        pub hblks: usize,
        pub hblkhd: usize,
        pub usmblks: usize,
        pub fsmblks: usize,
        pub uordblks: usize,
        pub fordblks: usize,
        pub keepcost: usize,
    }

    extern "C" {
        pub fn mallinfo2() -> MallInfo2;
        pub fn malloc_trim(pad: usize) -> i32;
    }
}

/// Bytes glibc's malloc has handed out and not got back, all arenas
/// (`mallinfo2().uordblks + hblkhd`): every chunk including its header and
/// rounding, whether Rust or C++ asked for it. `None` off glibc.
pub fn heap_in_use() -> Option<usize> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: `mallinfo2` takes no arguments and returns a plain struct.
        let m = unsafe { glibc::mallinfo2() };
        Some(m.uordblks + m.hblkhd)
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        None
    }
}

/// Returns free heap memory to the kernel (`malloc_trim(0)`), so that the
/// resident set size reflects memory in use; a no-op off glibc.
pub fn trim() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` is safe to call at any time.
    unsafe {
        glibc::malloc_trim(0);
    }
}

/// One reading of every memory figure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemSnapshot {
    /// [`live_bytes`] (0 unless [`CountingAlloc`] is installed).
    pub live: usize,
    /// [`heap_in_use`] (0 when unavailable).
    pub heap: usize,
    /// [`rss_bytes`] after [`trim`] (0 when unavailable).
    pub rss: usize,
}

impl MemSnapshot {
    /// Trims the heap, then reads all three figures.
    pub fn take() -> MemSnapshot {
        trim();
        MemSnapshot { live: live_bytes(), heap: heap_in_use().unwrap_or(0), rss: rss_bytes().unwrap_or(0) }
    }

    /// Growth since `earlier` (saturating at 0 per figure).
    pub fn since(&self, earlier: &MemSnapshot) -> MemSnapshot {
        MemSnapshot {
            live: self.live.saturating_sub(earlier.live),
            heap: self.heap.saturating_sub(earlier.heap),
            rss: self.rss.saturating_sub(earlier.rss),
        }
    }
}
