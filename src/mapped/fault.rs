//! The registry of the crate's live file mappings (their address ranges
//! and file names) and the `SIGBUS` handlers that consult it
//! ([`guard_truncated_files`], [`exit_on_truncated_files`]).
//!
//! The registry is lock-free for its reader, the signal handler: chunks of
//! slots that are never freed, each slot written under a sequence counter
//! (odd while being written), so that the handler never takes a lock,
//! allocates or reads a half-written slot. A slot names a [`Mark`], which
//! its [`Registration`] keeps alive as long as the slot holds the range.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{fence, AtomicBool, AtomicPtr, AtomicU8, AtomicUsize, Ordering};
use std::sync::Arc;

/// A mapped file was truncated in place while it was read: a read past
/// its new end found zeros instead of its bytes (with
/// [`guard_truncated_files`] installed), so every answer computed from the
/// mapping since is unreliable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{}: the file was truncated while memory-mapped \
     (replace files by renaming a new file over them, never in place)",
    name(path.as_deref())
)]
pub struct Truncated {
    /// The file, when known.
    pub path: Option<PathBuf>,
}

fn name(path: Option<&Path>) -> std::path::Display<'_> {
    path.unwrap_or(Path::new("a mapped file")).display()
}

/// What the mappings of one file share: its name and whether a read of
/// any of them has faulted past the file's end.
pub(crate) struct Mark {
    truncated: AtomicBool,
    path: Option<PathBuf>,
    /// The name as bytes, for the handler's message (it may not allocate).
    name: Box<[u8]>,
}

impl Mark {
    /// A mark for the file at `path` (`None`: unknown).
    pub(crate) fn new(path: Option<&Path>) -> Arc<Mark> {
        Arc::new(Mark {
            truncated: AtomicBool::new(false),
            path: path.map(Path::to_path_buf),
            name: name(path).to_string().into_bytes().into_boxed_slice(),
        })
    }

    /// `Err` once a read of one of the file's mappings has faulted.
    pub(crate) fn check(&self) -> Result<(), Truncated> {
        if self.truncated.load(Ordering::Acquire) {
            Err(Truncated { path: self.path.clone() })
        } else {
            Ok(())
        }
    }

    pub(crate) fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }
}

/// One mapping's entry in the registry.
struct Slot {
    /// Whether an owner holds the slot (written by owners only).
    taken: AtomicBool,
    /// Even when `start`, `end` and `mark` are consistent.
    seq: AtomicUsize,
    start: AtomicUsize,
    /// 0 for an empty slot: no address lies below it.
    end: AtomicUsize,
    mark: AtomicPtr<Mark>,
}

const CHUNK: usize = 64;

struct Chunk {
    slots: [Slot; CHUNK],
    next: AtomicPtr<Chunk>,
}

impl Chunk {
    const fn new() -> Chunk {
        Chunk { slots: [const { Slot::empty() }; CHUNK], next: AtomicPtr::new(std::ptr::null_mut()) }
    }
}

/// The first chunk; further ones are leaked boxes linked from it (never
/// freed, so the handler may walk them at any time).
static FIRST: Chunk = Chunk::new();

fn chunks() -> impl Iterator<Item = &'static Chunk> {
    std::iter::successors(Some(&FIRST), |c| {
        let next = c.next.load(Ordering::Acquire);
        // SAFETY: non-null `next` pointers come from `Box::into_raw` in
        // `claim` and are never freed
        (!next.is_null()).then(|| unsafe { &*next })
    })
}

/// A free slot, now taken.
fn claim() -> &'static Slot {
    let take = |s: &Slot| s.taken.compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed).is_ok();
    let mut last = &FIRST;
    for chunk in chunks() {
        if let Some(slot) = chunk.slots.iter().find(|s| take(s)) {
            return slot;
        }
        last = chunk;
    }
    let fresh: &'static Chunk = Box::leak(Box::new(Chunk::new()));
    fresh.slots[0].taken.store(true, Ordering::Relaxed);
    let fresh_ptr = fresh as *const Chunk as *mut Chunk;
    // append at the end of the list, wherever other threads have put it
    let mut tail = last;
    loop {
        match tail.next.compare_exchange(std::ptr::null_mut(), fresh_ptr, Ordering::AcqRel, Ordering::Acquire) {
            Ok(_) => return &fresh.slots[0],
            // SAFETY: as in `chunks`: a leaked chunk, never freed
            Err(next) => tail = unsafe { &*next },
        }
    }
}

impl Slot {
    const fn empty() -> Slot {
        Slot {
            taken: AtomicBool::new(false),
            seq: AtomicUsize::new(0),
            start: AtomicUsize::new(0),
            end: AtomicUsize::new(0),
            mark: AtomicPtr::new(std::ptr::null_mut()),
        }
    }

    /// Sets the range and mark (the slot's owner only).
    fn publish(&self, start: usize, end: usize, mark: *const Mark) {
        let seq = self.seq.load(Ordering::Relaxed);
        self.seq.store(seq.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        self.start.store(start, Ordering::Relaxed);
        self.end.store(end, Ordering::Relaxed);
        self.mark.store(mark.cast_mut(), Ordering::Relaxed);
        self.seq.store(seq.wrapping_add(2), Ordering::Release);
    }

    /// The range and mark, when read whole.
    fn read(&self) -> Option<(usize, usize, *const Mark)> {
        let seq = self.seq.load(Ordering::Acquire);
        if seq & 1 == 1 {
            return None;
        }
        let got = (
            self.start.load(Ordering::Relaxed),
            self.end.load(Ordering::Relaxed),
            self.mark.load(Ordering::Relaxed).cast_const(),
        );
        fence(Ordering::Acquire);
        (self.seq.load(Ordering::Relaxed) == seq).then_some(got)
    }
}

/// The page size, read before any handler may need it.
static PAGE: AtomicUsize = AtomicUsize::new(0);

fn page_size() -> usize {
    match PAGE.load(Ordering::Relaxed) {
        0 => {
            #[cfg(unix)]
            // SAFETY: sysconf has no preconditions
            let page = usize::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).unwrap_or(4096);
            #[cfg(not(unix))]
            let page = 4096;
            let page = if page.is_power_of_two() { page } else { 4096 };
            PAGE.store(page, Ordering::Relaxed);
            page
        }
        page => page,
    }
}

/// A mapping's place in the registry, from [`register`] until dropped
/// (drop it before the mapping is unmapped).
pub(crate) struct Registration {
    slot: &'static Slot,
    /// Kept alive while the slot names it.
    _mark: Arc<Mark>,
}

/// Enters the pages holding `bytes` (a live mapping of the file `mark`
/// stands for) into the registry; `None` for an empty mapping. Installs
/// the chosen handler again if another one replaced it since.
pub(crate) fn register(bytes: &[u8], mark: &Arc<Mark>) -> Option<Registration> {
    if bytes.is_empty() {
        return None;
    }
    let page = page_size();
    let start = bytes.as_ptr() as usize & !(page - 1);
    let end = (bytes.as_ptr() as usize + bytes.len()).next_multiple_of(page);
    let slot = claim();
    slot.publish(start, end, Arc::as_ptr(mark));
    handler::reinstall();
    Some(Registration { slot, _mark: Arc::clone(mark) })
}

impl Drop for Registration {
    fn drop(&mut self) {
        self.slot.publish(0, 0, std::ptr::null());
        self.slot.taken.store(false, Ordering::Release);
    }
}

/// The registered mapping holding `addr`: its mark and the end of its
/// pages. Async-signal-safe (atomic loads only).
fn find(addr: usize) -> Option<(&'static Mark, usize)> {
    for chunk in chunks() {
        for slot in &chunk.slots {
            match slot.read() {
                Some((start, end, mark)) if start <= addr && addr < end && !mark.is_null() => {
                    // SAFETY: a slot names its mark only while its
                    // `Registration` (which holds the `Arc`) lives, and the
                    // mapping holding `addr` is being read, so it is not
                    // being unregistered; the reference does not outlive
                    // the handler
                    return Some((unsafe { &*mark }, end));
                }
                _ => {}
            }
        }
    }
    None
}

/// No handler chosen yet.
const NONE: u8 = 0;
/// [`guard_truncated_files`]: zeros in, mark set, read completes.
const GUARD: u8 = 1;
/// [`exit_on_truncated_files`]: a line on standard error, exit status 1.
const EXIT: u8 = 2;

static MODE: AtomicU8 = AtomicU8::new(NONE);

/// Makes a read of a registered mapping past the end of its truncated file
/// complete, with zeros, instead of killing the process by `SIGBUS`: the
/// pages from the faulting one to the mapping's end are replaced by
/// anonymous zero pages, and the mapping's file is marked truncated, which
/// [`MappedMap::check_mapping`](super::MappedMap::check_mapping),
/// [`MappedMap::verify`](super::MappedMap::verify) and
/// [`MappedMap::to_tree`](super::MappedMap::to_tree) then report as
/// [`Truncated`] (and a `.graph` reader as an I/O error). A `SIGBUS` from
/// anywhere else goes to the handler that was installed before (or the
/// default action: the process dies). Idempotent; when another handler
/// replaced this one, opening a mapping installs it again, in front of the
/// other.
///
/// On Linux and Android; elsewhere this does nothing and a truncated
/// mapping still raises `SIGBUS`.
pub fn guard_truncated_files() -> io::Result<()> {
    handler::install(GUARD)
}

/// As [`guard_truncated_files`], but a read past the end of a truncated
/// mapped file writes `{prefix}{file}: the file was truncated while
/// memory-mapped (...)` and a newline to standard error and ends the
/// process with exit status 1, for a command-line program that has
/// nothing to recover.
pub fn exit_on_truncated_files(prefix: &'static str) -> io::Result<()> {
    handler::set_prefix(prefix);
    handler::install(EXIT)
}

#[cfg(any(target_os = "linux", target_os = "android"))]
mod handler {
    use super::{find, page_size, EXIT, GUARD, MODE, NONE};
    use std::io;
    use std::sync::atomic::{AtomicPtr, AtomicUsize, Ordering};
    use std::sync::Mutex;

    /// The handler before ours (leaked boxes, never freed); null: the default.
    static PREVIOUS: AtomicPtr<libc::sigaction> = AtomicPtr::new(std::ptr::null_mut());
    /// [`super::exit_on_truncated_files`]'s prefix.
    static PREFIX: AtomicPtr<u8> = AtomicPtr::new(std::ptr::null_mut());
    static PREFIX_LEN: AtomicUsize = AtomicUsize::new(0);
    /// Serialises installations (never taken by the handler).
    static INSTALLING: Mutex<()> = Mutex::new(());

    const SUFFIX: &[u8] = b": the file was truncated while memory-mapped \
        (replace files by renaming a new file over them, never in place)\n";

    pub(super) fn set_prefix(prefix: &'static str) {
        PREFIX_LEN.store(0, Ordering::Release);
        PREFIX.store(prefix.as_ptr().cast_mut(), Ordering::Release);
        PREFIX_LEN.store(prefix.len(), Ordering::Release);
    }

    fn ours() -> libc::sighandler_t {
        on_sigbus as extern "C" fn(libc::c_int, *mut libc::siginfo_t, *mut libc::c_void) as libc::sighandler_t
    }

    pub(super) fn install(mode: u8) -> io::Result<()> {
        page_size();
        let _one = INSTALLING.lock().unwrap_or_else(|e| e.into_inner());
        MODE.store(mode, Ordering::Release);
        install_locked()
    }

    /// Installs the handler again when a mode was chosen and another
    /// handler replaced ours.
    pub(super) fn reinstall() {
        if MODE.load(Ordering::Acquire) != NONE {
            let _one = INSTALLING.lock().unwrap_or_else(|e| e.into_inner());
            // best effort: the mapping works without it
            let _ = install_locked();
        }
    }

    fn install_locked() -> io::Result<()> {
        // SAFETY: a zeroed sigaction is a valid value to be overwritten;
        // a null new action only queries the current one
        let mut current: libc::sigaction = unsafe { std::mem::zeroed() };
        // SAFETY: valid pointers to a sigaction
        if unsafe { libc::sigaction(libc::SIGBUS, std::ptr::null(), &mut current) } != 0 {
            return Err(io::Error::last_os_error());
        }
        if current.sa_sigaction == ours() {
            return Ok(());
        }
        // SAFETY: as above
        let mut action: libc::sigaction = unsafe { std::mem::zeroed() };
        action.sa_sigaction = ours();
        // SIGBUS stays blocked while the handler runs: a re-raised signal
        // waits until it returns
        action.sa_flags = libc::SA_SIGINFO | libc::SA_ONSTACK;
        // SAFETY: valid pointer to the action's mask
        unsafe { libc::sigemptyset(&mut action.sa_mask) };
        // SAFETY: as above
        let mut previous: libc::sigaction = unsafe { std::mem::zeroed() };
        // SAFETY: valid pointers; the handler only calls async-signal-safe
        // functions (mmap, write, _exit, sigaction, raise) and reads atomics
        // and data that outlive it
        if unsafe { libc::sigaction(libc::SIGBUS, &action, &mut previous) } != 0 {
            return Err(io::Error::last_os_error());
        }
        // leaked: the handler may read it at any time (one per installation)
        PREVIOUS.store(Box::into_raw(Box::new(previous)), Ordering::Release);
        Ok(())
    }

    /// Puts the previous handler (or the default action) back.
    fn restore_previous() {
        let previous = PREVIOUS.load(Ordering::Acquire);
        // SAFETY: a zeroed sigaction is SIG_DFL with no flags
        let default: libc::sigaction = unsafe { std::mem::zeroed() };
        let action: *const libc::sigaction = if previous.is_null() { &default } else { previous };
        // SAFETY: `action` points to a valid sigaction (a leaked box, never freed, or a local)
        unsafe { libc::sigaction(libc::SIGBUS, action, std::ptr::null_mut()) };
    }

    fn write_all(bytes: &[u8]) {
        let mut rest = bytes;
        while !rest.is_empty() {
            // SAFETY: write(2) is async-signal-safe; the buffer is valid
            let n = unsafe { libc::write(libc::STDERR_FILENO, rest.as_ptr().cast(), rest.len()) };
            if n <= 0 {
                return;
            }
            rest = &rest[n as usize..];
        }
    }

    extern "C" fn on_sigbus(_signal: libc::c_int, info: *mut libc::siginfo_t, _context: *mut libc::c_void) {
        // SAFETY: with SA_SIGINFO the kernel passes a valid siginfo_t; the
        // address field is meaningful for the faults (code > 0) it is read for
        let (code, addr) = unsafe { ((*info).si_code, (*info).si_addr() as usize) };
        if code <= 0 {
            // sent by a process or raise(), not a fault: there is no address
            // to judge, so the default action (chaining to the previous
            // handler could loop with one that re-raises to us)
            // SAFETY: a zeroed sigaction is SIG_DFL; raise is async-signal-safe
            // and the signal waits, blocked, until this handler returns
            unsafe {
                let default: libc::sigaction = std::mem::zeroed();
                libc::sigaction(libc::SIGBUS, &default, std::ptr::null_mut());
                libc::raise(libc::SIGBUS);
            }
            return;
        }
        if let Some((mark, end)) = find(addr) {
            match MODE.load(Ordering::Acquire) {
                GUARD => {
                    mark.truncated.store(true, Ordering::Release);
                    let page = addr & !(page_size() - 1);
                    // SAFETY: [page, end) lies in a live mapping of this crate
                    // (registered until its owner unmaps it, which cannot
                    // happen while it is read); replacing its pages by
                    // read-only zero pages keeps every address readable, and
                    // the owner's munmap later removes them with the rest
                    let zeros = unsafe {
                        libc::mmap(
                            page as *mut libc::c_void,
                            end - page,
                            libc::PROT_READ,
                            libc::MAP_PRIVATE | libc::MAP_ANONYMOUS | libc::MAP_FIXED,
                            -1,
                            0,
                        )
                    };
                    if zeros as usize == page {
                        // the read is retried and finds zeros
                        return;
                    }
                }
                EXIT => {
                    let (prefix, len) = (PREFIX.load(Ordering::Acquire), PREFIX_LEN.load(Ordering::Acquire));
                    if !prefix.is_null() {
                        // SAFETY: PREFIX and its length come from a &'static str
                        write_all(unsafe { std::slice::from_raw_parts(prefix, len) });
                    }
                    write_all(&mark.name);
                    write_all(SUFFIX);
                    // SAFETY: _exit is async-signal-safe
                    unsafe { libc::_exit(1) };
                }
                _ => {}
            }
        }
        // a fault elsewhere: the retried read faults again, into the
        // previous handler or the default action
        restore_previous();
    }
}

#[cfg(not(any(target_os = "linux", target_os = "android")))]
mod handler {
    pub(super) fn set_prefix(_prefix: &'static str) {}

    pub(super) fn install(mode: u8) -> std::io::Result<()> {
        super::MODE.store(mode, std::sync::atomic::Ordering::Release);
        Ok(())
    }

    pub(super) fn reinstall() {}
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Registered ranges are found by any address in their pages, and no
    /// longer once unregistered; more mappings than a chunk holds get
    /// slots of their own.
    #[test]
    fn the_registry_finds_live_ranges_only() {
        let mark = Mark::new(Some(Path::new("x.olm")));
        let bufs: Vec<Vec<u8>> = (0..CHUNK * 2 + 3).map(|_| vec![1u8; 10_000]).collect();
        let regs: Vec<Registration> = bufs.iter().map(|b| register(b, &mark).unwrap()).collect();
        for b in &bufs {
            let (found, end) = find(b.as_ptr() as usize + 9_999).expect("registered");
            assert_eq!(found.path(), Some(Path::new("x.olm")));
            assert!(end >= b.as_ptr() as usize + b.len());
        }
        let addr = bufs[5].as_ptr() as usize + 3;
        drop(regs);
        // another test's mapping may share the page, never this mark
        assert!(find(addr).is_none_or(|(m, _)| !std::ptr::eq(m, &*mark)));
        assert!(register(&[], &mark).is_none());
        assert_eq!(mark.check(), Ok(()));
        mark.truncated.store(true, Ordering::Release);
        let err = mark.check().unwrap_err();
        assert_eq!(
            err.to_string(),
            "x.olm: the file was truncated while memory-mapped \
             (replace files by renaming a new file over them, never in place)"
        );
    }
}
