//! The table of temporary files that a signal handler removes, and the
//! other system calls of atomic writes (the process probe of the stale-file
//! removal): all of their `unsafe`.
//!
//! A handler may not allocate or take a lock a thread might hold, so the
//! table is fixed: [`SLOTS`] slots, each a flag and a buffer holding a
//! temporary file's path as a NUL-terminated C string, ready for `unlink`.
//! Scratch directories have a table of their own ([`DIR_SLOTS`] slots),
//! listed by the same protocol (the directory created inside a creation
//! window) and removed after the temporary files, with their files.
//!
//! The protocol, and why the handler neither misses a temporary file nor
//! removes anything else:
//!
//! * A temporary file is created and listed inside a *creation window*
//!   ([`create_listed`]): the thread blocks every signal, increments
//!   [`CREATING`], reads [`ENDING`] and creates nothing if it is set;
//!   otherwise it creates the file, claims a free slot (its flag from
//!   false to true) and copies the path in; then it decrements
//!   `CREATING` and unblocks its signals.
//! * [`remove_temp_files`] sets `ENDING`, waits until `CREATING` is zero,
//!   then unlinks the path of every claimed slot.
//! * No file escapes: the window's increment and read and the cleanup's
//!   store and read are all sequentially consistent, so either the window
//!   sees `ENDING` and creates nothing, or the cleanup sees the window
//!   open and waits for its end, after which the slot is claimed and its
//!   path written (the decrement releases the writes, the cleanup's read
//!   acquires them). A file created while a handler runs is thus either
//!   refused or waited for and removed.
//! * The wait cannot deadlock: a thread blocks every signal while in a
//!   window, so a handler never runs on a thread it would wait for.
//! * A path is never read while being written: paths are written only in
//!   windows; the cleanup reads none until the windows open before it are
//!   closed, and none opens after it has set `ENDING`.
//! * The final file is never removed: a slot is freed after the rename
//!   (or after the temporary file is removed on failure), so a cleanup
//!   between the two unlinks the temporary path, which then names no file.
//!   The final name differs from every temporary name, and a new file at
//!   the same temporary path can only be another temporary file of this
//!   process (the name holds its pid), itself listed and due for removal.
//!   Freeing the slot before the rename would instead let a signal in
//!   between leave the complete temporary file behind.

use std::cell::UnsafeCell;
use std::ffi::c_int;
use std::fs::File;
use std::io;
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};
use std::ptr;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Writes in progress at once that a signal cleans up after; further ones
/// still write atomically but are left to the stale-file removal.
const SLOTS: usize = 64;
/// Scratch directories at once that a signal removes; further ones are
/// left to the stale-directory removal.
const DIR_SLOTS: usize = 8;
/// Linux's `PATH_MAX` (with the NUL): longer paths cannot be opened.
const PATH_CAPACITY: usize = 4096;

/// The signals after which [`remove_temp_files_on_signals`] cleans up:
/// the polite ways to end a process (Ctrl-C, `kill`, a closed terminal,
/// Ctrl-\).
const CLEANUP_SIGNALS: [c_int; 4] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP, libc::SIGQUIT];

struct Slot {
    claimed: AtomicBool,
    path: UnsafeCell<[u8; PATH_CAPACITY]>,
}

// SAFETY: `path` is written only by the thread that claimed the slot,
// inside a creation window, and read only by `remove_temp_files` when no
// window is open or can open (see the protocol in the module doc).
unsafe impl Sync for Slot {}

static TABLE: [Slot; SLOTS] =
    [const { Slot { claimed: AtomicBool::new(false), path: UnsafeCell::new([0; PATH_CAPACITY]) } }; SLOTS];
/// The scratch directories ([`super::ScratchDir`]), listed by the same
/// protocol as the temporary files.
static DIR_TABLE: [Slot; DIR_SLOTS] =
    [const { Slot { claimed: AtomicBool::new(false), path: UnsafeCell::new([0; PATH_CAPACITY]) } }; DIR_SLOTS];
/// Creation windows open now.
static CREATING: AtomicUsize = AtomicUsize::new(0);
/// Set by the cleanup: no temporary file is created from then on.
static ENDING: AtomicBool = AtomicBool::new(false);

/// A temporary file's slot in the table, freed when dropped.
pub(super) struct Listed(usize);

impl Drop for Listed {
    fn drop(&mut self) {
        TABLE[self.0].claimed.store(false, Ordering::Release);
    }
}

/// A scratch directory's slot in its table, freed when dropped.
#[derive(Debug)]
pub(super) struct ListedDir(usize);

impl Drop for ListedDir {
    fn drop(&mut self) {
        DIR_TABLE[self.0].claimed.store(false, Ordering::Release);
    }
}

/// A creation window: every signal blocked and `CREATING` counted.
struct Window {
    old_mask: libc::sigset_t,
}

impl Window {
    fn open() -> io::Result<Window> {
        // SAFETY: sigfillset fills a set owned here; pthread_sigmask only
        // changes this thread's mask, saving the old one to restore.
        let old_mask = unsafe {
            let mut all: libc::sigset_t = std::mem::zeroed();
            let mut old: libc::sigset_t = std::mem::zeroed();
            libc::sigfillset(&mut all);
            libc::pthread_sigmask(libc::SIG_BLOCK, &all, &mut old);
            old
        };
        let window = Window { old_mask };
        CREATING.fetch_add(1, Ordering::SeqCst);
        if ENDING.load(Ordering::SeqCst) {
            return Err(io::Error::other("the process is ending: its temporary files are being removed"));
        }
        Ok(window)
    }
}

impl Drop for Window {
    fn drop(&mut self) {
        CREATING.fetch_sub(1, Ordering::SeqCst);
        // SAFETY: restores the mask saved by `open`.
        unsafe {
            libc::pthread_sigmask(libc::SIG_SETMASK, &self.old_mask, ptr::null_mut());
        }
    }
}

/// Runs `create` (which creates a temporary file and returns its path)
/// in a creation window and lists the file; `None` when the table is full
/// or the path too long for a slot.
pub(super) fn create_listed(
    create: impl FnOnce() -> io::Result<(PathBuf, File)>,
) -> io::Result<(PathBuf, File, Option<Listed>)> {
    let _window = Window::open()?;
    let (path, file) = create()?;
    let listed = list(&TABLE, &path).map(Listed);
    Ok((path, file, listed))
}

/// Runs `create` (which creates the directory `path`) in a creation
/// window and lists the directory; `None` when the table is full or the
/// path too long for a slot.
pub(super) fn create_listed_dir(path: &Path, create: impl FnOnce() -> io::Result<()>) -> io::Result<Option<ListedDir>> {
    let _window = Window::open()?;
    create()?;
    Ok(list(&DIR_TABLE, path).map(ListedDir))
}

/// Claims a free slot of `table` for `path`; its index.
fn list(table: &[Slot], path: &Path) -> Option<usize> {
    let bytes = path.as_os_str().as_bytes();
    if bytes.len() >= PATH_CAPACITY || bytes.contains(&0) {
        return None;
    }
    let index = table
        .iter()
        .position(|s| s.claimed.compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed).is_ok())?;
    // SAFETY: the slot was claimed just now, inside a creation window:
    // no other thread writes it, and the cleanup does not read it before
    // the window closes.
    let buffer = unsafe { &mut *table[index].path.get() };
    buffer[..bytes.len()].copy_from_slice(bytes);
    buffer[bytes.len()] = 0;
    Some(index)
}

/// Removes the temporary files of the atomic writes in progress, and the
/// scratch directories ([`super::ScratchDir`]) with the files in them;
/// their writes then fail, and writes started later fail at once. Meant
/// for a signal handler just before the process ends: it is
/// async-signal-safe (no allocation, no lock; it waits only for other
/// threads to finish creating a temporary file) and may run in several
/// handlers at once.
pub fn remove_temp_files() {
    ENDING.store(true, Ordering::SeqCst);
    while CREATING.load(Ordering::SeqCst) != 0 {
        std::hint::spin_loop();
    }
    for slot in &TABLE {
        if slot.claimed.load(Ordering::Acquire) {
            // SAFETY: a claimed slot holds a NUL-terminated path written
            // in a window that has closed, and no window writes any more
            // (`ENDING` is set); unlink is async-signal-safe. A path whose
            // file was already renamed or removed names no file.
            unsafe {
                libc::unlink(slot.path.get().cast());
            }
        }
    }
    for slot in &DIR_TABLE {
        if slot.claimed.load(Ordering::Acquire) {
            // SAFETY: as above, a claimed slot holds a NUL-terminated path
            // no window writes any more.
            unsafe { remove_flat_dir(slot.path.get().cast()) };
        }
    }
}

/// Removes the directory `path` and the files in it (a scratch directory
/// holds files only), with async-signal-safe calls alone: `open`,
/// `getdents64` into a buffer on the stack, `unlinkat`, `rmdir`. The
/// directory is read again from its start until a pass removes nothing
/// (entries removed while reading may hide others from that pass), a few
/// passes at most. Elsewhere than on Linux only an empty directory is
/// removed (the stale-directory removal takes the rest).
///
/// # Safety
///
/// `path` points to a NUL-terminated path that stays unchanged meanwhile.
unsafe fn remove_flat_dir(path: *const libc::c_char) {
    #[cfg(target_os = "linux")]
    // SAFETY: every call takes this function's descriptor or buffers, and
    // `path` is a C string (the caller's promise); the records read are
    // within the bytes getdents64 returned, each `d_reclen` long.
    unsafe {
        let fd = libc::open(path, libc::O_RDONLY | libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC);
        if fd < 0 {
            return;
        }
        // u64s: the records are 8-byte aligned
        let mut buffer = [0u64; 512];
        for _ in 0..8 {
            let mut removed = false;
            libc::lseek(fd, 0, libc::SEEK_SET);
            loop {
                let n = libc::syscall(libc::SYS_getdents64, fd, buffer.as_mut_ptr(), std::mem::size_of_val(&buffer));
                if n <= 0 {
                    break;
                }
                let mut at = 0usize;
                while at < n as usize {
                    let record = buffer.as_ptr().cast::<u8>().add(at).cast::<libc::dirent64>();
                    let name = (*record).d_name.as_ptr();
                    let dots = *name == b'.' as libc::c_char
                        && (*name.add(1) == 0 || (*name.add(1) == b'.' as libc::c_char && *name.add(2) == 0));
                    if !dots && libc::unlinkat(fd, name, 0) == 0 {
                        removed = true;
                    }
                    at += usize::from((*record).d_reclen);
                }
            }
            if !removed {
                break;
            }
        }
        libc::close(fd);
    }
    // SAFETY: rmdir on the caller's C string; it fails harmlessly on a
    // directory that is not empty.
    unsafe {
        libc::rmdir(path);
    }
}

/// Installs a handler for SIGINT, SIGTERM, SIGHUP and SIGQUIT that calls
/// [`remove_temp_files`] and then ends the process by the signal, as its
/// default action would (a shell sees 128 plus the signal's number).
/// Signals the process ignores (as under `nohup`, or in a background job)
/// stay ignored; handlers installed before are replaced. Call it once, at
/// the start of `main`.
pub fn remove_temp_files_on_signals() -> io::Result<()> {
    for signal in CLEANUP_SIGNALS {
        // SAFETY: sigaction reads and writes structs owned here; the
        // handler is async-signal-safe (see `remove_temp_files_and_end`).
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(signal, ptr::null(), &mut old) != 0 {
                return Err(io::Error::last_os_error());
            }
            if old.sa_sigaction == libc::SIG_IGN {
                continue;
            }
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = remove_temp_files_and_end as extern "C" fn(c_int) as libc::sighandler_t;
            libc::sigemptyset(&mut action.sa_mask);
            for other in CLEANUP_SIGNALS {
                libc::sigaddset(&mut action.sa_mask, other);
            }
            if libc::sigaction(signal, &action, ptr::null_mut()) != 0 {
                return Err(io::Error::last_os_error());
            }
        }
    }
    Ok(())
}

extern "C" fn remove_temp_files_and_end(signal: c_int) {
    remove_temp_files();
    // SAFETY: sigaction and raise are async-signal-safe. With the default
    // action restored, the raised signal, blocked while this handler runs,
    // is delivered as it returns and ends the process.
    unsafe {
        let mut default: libc::sigaction = std::mem::zeroed();
        default.sa_sigaction = libc::SIG_DFL;
        libc::sigaction(signal, &default, ptr::null_mut());
        libc::raise(signal);
    }
}

/// Whether process `pid` exists (also one of another user, which the
/// probe may not signal), by sending it signal 0.
pub(super) fn process_runs(pid: libc::pid_t) -> bool {
    debug_assert!(pid > 0);
    // SAFETY: signal 0 only checks that the process exists; `pid` is
    // positive, so it names one process, never a process group.
    let probed = unsafe { libc::kill(pid, 0) };
    probed == 0 || io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
}

/// Writes to disk everything written so far to the filesystem holding
/// `dir` (`syncfs`; elsewhere than on Linux, `sync`).
pub(super) fn sync_filesystem(dir: &std::path::Path) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let d = std::fs::File::open(dir)?;
        // SAFETY: syncfs on a descriptor this function owns and keeps open
        // for the call.
        if unsafe { libc::syncfs(d.as_raw_fd()) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = dir;
        // SAFETY: sync takes no arguments and cannot fail.
        unsafe { libc::sync() };
        Ok(())
    }
}
