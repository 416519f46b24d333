//! The `octolinear` command-line tool.

mod cli;

fn main() {
    limit_heap_retention();
    std::process::exit(cli::main());
}

/// glibc raises its mmap threshold whenever a large block is freed, after
/// which big arrays come from the heap and freed space stays resident; a
/// fixed threshold keeps large buffers (key sets, arenas) in their own
/// mappings, returned to the system when freed and grown in place.
fn limit_heap_retention() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        const M_MMAP_THRESHOLD: libc::c_int = -3;
        // SAFETY: mallopt only adjusts allocator tuning; called before any
        // other thread exists.
        unsafe {
            libc::mallopt(M_MMAP_THRESHOLD, 128 * 1024);
        }
    }
}
