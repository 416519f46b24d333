//! Atomic file writes. A write to `NAME` goes into a fresh temporary file
//! `.NAME.<pid>.<n>.tmp` beside it, which is synced and then renamed over
//! `NAME`: readers see the old file or the new one, never a half-written
//! one, and a failed write leaves `NAME` as it was and removes its
//! temporary file.
//!
//! * Permissions: a replaced file's permission bits carry over to the new
//!   one (so do its owner and group, where the process may set them); a
//!   new file gets the mode `File::create` gives (`0666` less the umask).
//! * Symbolic links: when `NAME` is a symbolic link, the file it finally
//!   points to is replaced (its temporary file lies beside that file) and
//!   the link stays; a dangling link's target is created. That is right
//!   for a user's output; inside a directory a writer owns (a tile set),
//!   [`write_entry_atomically`] replaces the link itself instead, so that
//!   nothing outside the directory is written. Anything but a regular file
//!   (a directory, a device, a FIFO) is never replaced.
//! * Stale temporary files (unix): a process killed outright (SIGKILL, a
//!   crash) leaves its temporary file behind; the next write to the same
//!   `NAME` removes those whose process no longer runs. A process on
//!   another machine sharing the directory, or in another PID namespace,
//!   looks as if it no longer runs: do not write one file from several
//!   machines at once.
//! * Scratch directories: [`ScratchDir`], a hidden directory beside an
//!   output (`.NAME.spill-<pid>`) for what a write keeps on disk while it
//!   runs, removed when dropped, on the signals below, and, once its
//!   process no longer runs, by the next write to the same `NAME`.
//! * Signals (unix): the temporary files of writes in progress (and the
//!   scratch directories) are listed in fixed tables that
//!   [`remove_temp_files`] empties, safely from a signal handler. A library must not take over its process's signals,
//!   so nothing here installs a handler by itself: an application calls
//!   [`remove_temp_files_on_signals`] at start (the `octolinear` tool does),
//!   or [`remove_temp_files`] from a handler of its own.

// the module's system calls, its only `unsafe`
#[cfg(unix)]
#[allow(unsafe_code)]
mod signals;
#[cfg(unix)]
use signals::process_runs;
#[cfg(unix)]
pub use signals::{remove_temp_files, remove_temp_files_on_signals};

/// Without signals there is no table of temporary files to keep.
#[cfg(not(unix))]
mod signals {
    use std::{fs::File, io, path::Path, path::PathBuf};

    pub(super) struct Listed;

    #[derive(Debug)]
    pub(super) struct ListedDir;

    /// Runs `create` only.
    pub(super) fn create_listed_dir(
        _: &Path,
        create: impl FnOnce() -> io::Result<()>,
    ) -> io::Result<Option<ListedDir>> {
        create()?;
        Ok(None)
    }

    /// Runs `create` only.
    pub(super) fn create_listed(
        create: impl FnOnce() -> io::Result<(PathBuf, File)>,
    ) -> io::Result<(PathBuf, File, Option<Listed>)> {
        let (path, file) = create()?;
        Ok((path, file, None))
    }
}

use std::ffi::{OsStr, OsString};
use std::fs::{self, File, Metadata, OpenOptions};
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};

/// Writes through `write` into a fresh temporary file beside `path` (or
/// beside the file a symbolic link `path` points to), syncs it, then
/// renames it into place; on any error, and on a panic in `write`, the
/// temporary file is removed and the file at `path` is left as it was.
/// See the [module documentation](self) for permissions, links and
/// temporary files left by killed processes.
pub fn write_atomically(path: &Path, write: impl FnOnce(&mut BufWriter<&File>) -> io::Result<()>) -> io::Result<()> {
    write_atomically_with(path, true, Links::Follow, write)
}

/// [`write_atomically`] for a file inside a directory the writer owns (a
/// tile set's manifest and parts): a symbolic link at `path` is itself
/// replaced by the new file, renamed over it, and whatever it points to
/// is left alone; the new file gets the mode `File::create` gives.
pub fn write_entry_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<&File>) -> io::Result<()>,
) -> io::Result<()> {
    write_atomically_with(path, true, Links::Replace, write)
}

/// What a write does with a symbolic link at its path.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Links {
    /// Replaces the file the link finally points to.
    Follow,
    /// Replaces the link itself.
    Replace,
}

/// [`write_entry_atomically`] for one of many files written into one
/// directory together (a tile set's tiles): without the search for stale
/// temporary files of the name, which lists the directory, and without
/// the sync, which the writer does once for all of them
/// ([`sync_filesystem`]) before anything refers to them.
pub(crate) fn write_entry_batched(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<&File>) -> io::Result<()>,
) -> io::Result<()> {
    write_atomically_with(path, false, Links::Replace, write)
}

/// Writes to disk everything written so far to the filesystem holding
/// `dir` (`syncfs`; elsewhere than on Linux, `sync`).
pub(crate) fn sync_filesystem(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        signals::sync_filesystem(dir)
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

/// [`write_atomically`], with (`alone`) or without the search for stale
/// temporary files and the sync, following links or replacing them.
fn write_atomically_with(
    path: &Path,
    alone: bool,
    links: Links,
    write: impl FnOnce(&mut BufWriter<&File>) -> io::Result<()>,
) -> io::Result<()> {
    let target = match links {
        Links::Follow => final_target(path)?,
        Links::Replace => path.to_path_buf(),
    };
    let written = replace(&target, alone, links, write);
    if target == path {
        written
    } else {
        written.map_err(|e| io::Error::new(e.kind(), format!("{} (the link's target): {e}", target.display())))
    }
}

fn replace(
    target: &Path,
    alone: bool,
    links: Links,
    write: impl FnOnce(&mut BufWriter<&File>) -> io::Result<()>,
) -> io::Result<()> {
    let name = target
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, format!("{} names no file", target.display())))?;
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let found = match links {
        Links::Follow => fs::metadata(target),
        Links::Replace => fs::symlink_metadata(target),
    };
    let existing = match found {
        Ok(m) if m.is_file() => Some(m),
        // a link replaced: the new file is a new one, of the default mode
        Ok(m) if m.file_type().is_symlink() => None,
        Ok(_) => return Err(io::Error::new(io::ErrorKind::InvalidInput, "exists and is not a regular file")),
        Err(e) if e.kind() == io::ErrorKind::NotFound => None,
        Err(e) => return Err(e),
    };
    #[cfg(unix)]
    if alone {
        remove_stale(dir, name, true);
    }
    let mut temp = create_temp(dir, name, existing.as_ref())?;
    let mut w = BufWriter::with_capacity(1 << 16, &temp.file);
    write(&mut w)?;
    w.into_inner().map_err(io::IntoInnerError::into_error)?;
    if alone {
        temp.file.sync_all()?;
    }
    fs::rename(&temp.path, target)?;
    temp.renamed = true;
    Ok(())
}

/// A hidden directory beside an output, `.NAME.spill-<pid>`, for what a
/// write keeps on disk while it runs (a capped build's tiles, records
/// waiting for their file). It is removed with everything in it when
/// dropped, by [`remove_temp_files`] (so on the signals
/// [`remove_temp_files_on_signals`] handles), and, when its process was
/// killed outright, by the next [`ScratchDir::beside`] or atomic write of
/// the same `NAME` (unix: those of processes that no longer run, as for
/// temporary files).
#[derive(Debug)]
pub struct ScratchDir {
    path: PathBuf,
    /// Dropped after the directory is removed (see [`TempFile`]).
    _listed: Option<signals::ListedDir>,
}

impl ScratchDir {
    /// Creates `.NAME.spill-<pid>` beside `output` (`NAME` its file name),
    /// after removing the scratch directories of `NAME` whose processes no
    /// longer run and anything left at this process's name.
    pub fn beside(output: &Path) -> io::Result<ScratchDir> {
        let name = output.file_name().unwrap_or(OsStr::new("map"));
        let dir = match output.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        #[cfg(unix)]
        remove_stale(dir, name, false);
        let path = dir.join(scratch_name(name, std::process::id()));
        // a name of this process's holds nothing of this process's yet
        match fs::symlink_metadata(&path) {
            Ok(m) if m.is_dir() => fs::remove_dir_all(&path)?,
            Ok(_) => fs::remove_file(&path)?,
            Err(_) => {}
        }
        let listed = signals::create_listed_dir(&path, || fs::create_dir(&path))?;
        Ok(ScratchDir { path, _listed: listed })
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.path);
    }
}

/// `.NAME.spill-<pid>`.
fn scratch_name(name: &OsStr, pid: u32) -> OsString {
    let mut s = OsString::from(".");
    s.push(name);
    s.push(format!(".spill-{pid}"));
    s
}

/// The process id in `file` if it names a scratch directory of `name`
/// (`.NAME.spill-<pid>`, the pid decimal and positive).
#[cfg(unix)]
fn scratch_pid(name: &OsStr, file: &OsStr) -> Option<libc::pid_t> {
    let pid =
        file.as_encoded_bytes().strip_prefix(b".")?.strip_prefix(name.as_encoded_bytes())?.strip_prefix(b".spill-")?;
    if pid.is_empty() || !pid.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let pid: libc::pid_t = std::str::from_utf8(pid).ok()?.parse().ok()?;
    (pid > 0).then_some(pid)
}

/// Removes what processes that no longer run left of `name` in `dir`, in
/// one pass over it: scratch directories (`.NAME.spill-<pid>`), with what
/// they hold, and, with `temps`, temporary files (`.NAME.<pid>.<n>.tmp`).
/// Never those of running processes (or of this one), never anything of
/// another type (a link of such a name is left, and nothing a link inside
/// points to is touched). Best effort: a directory that cannot be read is
/// left to the write to report.
#[cfg(unix)]
fn remove_stale(dir: &Path, name: &OsStr, temps: bool) {
    let Ok(entries) = fs::read_dir(dir) else { return };
    let own = std::process::id();
    for entry in entries.flatten() {
        let file = entry.file_name();
        let (pid, scratch) = match temps.then(|| temp_pid(name, &file)).flatten() {
            Some(pid) => (pid, false),
            None => match scratch_pid(name, &file) {
                Some(pid) => (pid, true),
                None => continue,
            },
        };
        if pid as u32 == own || process_runs(pid) {
            continue;
        }
        let removed = match entry.file_type() {
            Ok(t) if scratch && t.is_dir() => fs::remove_dir_all(entry.path()),
            Ok(t) if !scratch && t.is_file() => fs::remove_file(entry.path()),
            _ => Ok(()),
        };
        // best effort: what cannot be removed is left
        let _ = removed;
    }
}

/// Linux's limit on the links followed in resolving one path.
const MAX_LINKS: usize = 40;

/// The file a write to `path` replaces: `path` itself, or the final target
/// of the symbolic links starting there (which need not exist).
fn final_target(path: &Path) -> io::Result<PathBuf> {
    let mut target = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match fs::symlink_metadata(&target) {
            Ok(m) if m.file_type().is_symlink() => {
                // a relative link is relative to the directory holding it
                let link = fs::read_link(&target)?;
                target = match target.parent() {
                    Some(dir) => dir.join(link),
                    None => link,
                };
            }
            _ => return Ok(target),
        }
    }
    Err(io::Error::other("too many levels of symbolic links"))
}

/// A temporary file being written, removed when dropped unless renamed
/// into place; listed in the signal cleanup's table while it exists.
struct TempFile {
    path: PathBuf,
    file: File,
    renamed: bool,
    /// Dropped after the file is removed (fields drop after `drop`), so a
    /// signal in between finds it listed and removes nothing else.
    _listed: Option<signals::Listed>,
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !self.renamed {
            let _ = fs::remove_file(&self.path);
        }
    }
}

/// `.NAME.<pid>.<n>.tmp`.
fn temp_name(name: &OsStr, pid: u32, n: u32) -> OsString {
    let mut s = OsString::from(".");
    s.push(name);
    s.push(format!(".{pid}.{n}.tmp"));
    s
}

/// Creates a fresh temporary file for `name` in `dir`, with the mode and
/// owner of the file it is to replace, if any.
fn create_temp(dir: &Path, name: &OsStr, existing: Option<&Metadata>) -> io::Result<TempFile> {
    let mut options = OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    if let Some(m) = existing {
        // never wider than the final mode while being written (the umask
        // may narrow it; `copy_owner_and_mode` sets it exactly)
        std::os::unix::fs::OpenOptionsExt::mode(&mut options, std::os::unix::fs::MetadataExt::mode(m) & 0o777);
    }
    let pid = std::process::id();
    let (path, file, listed) = signals::create_listed(|| {
        for n in 0..1000u32 {
            let path = dir.join(temp_name(name, pid, n));
            match options.open(&path) {
                Ok(file) => return Ok((path, file)),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(e),
            }
        }
        Err(io::Error::new(io::ErrorKind::AlreadyExists, format!("no free temporary name in {}", dir.display())))
    })?;
    let temp = TempFile { path, file, renamed: false, _listed: listed };
    #[cfg(unix)]
    if let Some(m) = existing {
        copy_owner_and_mode(&temp.file, m)?;
    }
    #[cfg(not(unix))]
    let _ = existing;
    Ok(temp)
}

/// Gives `file` the permission bits of `original`, and its owner and group
/// as far as the process may: root sets both, others a group they belong
/// to; otherwise the file keeps the writer's.
#[cfg(unix)]
fn copy_owner_and_mode(file: &File, original: &Metadata) -> io::Result<()> {
    use std::os::unix::fs::{fchown, MetadataExt, PermissionsExt};
    let own = file.metadata()?;
    if (own.uid(), own.gid()) != (original.uid(), original.gid()) {
        let _ = fchown(file, Some(original.uid()), Some(original.gid()))
            .or_else(|_| fchown(file, None, Some(original.gid())));
    }
    file.set_permissions(fs::Permissions::from_mode(original.mode() & 0o777))
}

/// The process id in `file` if it names a temporary file of `name`
/// (`.NAME.<pid>.<n>.tmp`, both numbers decimal, the pid positive).
#[cfg(unix)]
fn temp_pid(name: &OsStr, file: &OsStr) -> Option<libc::pid_t> {
    let numbers = file
        .as_encoded_bytes()
        .strip_prefix(b".")?
        .strip_prefix(name.as_encoded_bytes())?
        .strip_prefix(b".")?
        .strip_suffix(b".tmp")?;
    let dot = numbers.iter().position(|&b| b == b'.')?;
    let (pid, n) = (&numbers[..dot], &numbers[dot + 1..]);
    let decimal = |s: &[u8]| !s.is_empty() && s.iter().all(u8::is_ascii_digit);
    if !decimal(pid) || !decimal(n) {
        return None;
    }
    let pid: libc::pid_t = std::str::from_utf8(pid).ok()?.parse().ok()?;
    (pid > 0).then_some(pid)
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;
    use std::io::Write;
    use std::os::unix::fs::{symlink, PermissionsExt};

    fn write_text(path: &Path, text: &str) -> io::Result<()> {
        write_atomically(path, |w| w.write_all(text.as_bytes()))
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    fn mode(path: &Path) -> u32 {
        fs::metadata(path).unwrap().permissions().mode() & 0o7777
    }

    #[test]
    fn writes_replace_the_file_and_leave_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.txt");
        write_text(&out, "one").unwrap();
        write_text(&out, "two").unwrap();
        assert_eq!(fs::read_to_string(&out).unwrap(), "two");
        assert_eq!(names(dir.path()), ["a.txt"]);
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_removes_its_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.txt");
        write_text(&out, "old").unwrap();
        let err = write_atomically(&out, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("writer failed"))
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "writer failed");
        assert_eq!(fs::read_to_string(&out).unwrap(), "old");
        assert_eq!(names(dir.path()), ["a.txt"]);
        let panicked = std::panic::catch_unwind(|| write_atomically(&out, |_| panic!("writer panicked")));
        assert!(panicked.is_err());
        assert_eq!(names(dir.path()), ["a.txt"]);
    }

    #[test]
    fn stale_removal_takes_only_dead_processes_temporary_files_of_that_name() {
        let dir = tempfile::tempdir().unwrap();
        // a pid that no longer runs: a child that has been waited for
        let mut child = std::process::Command::new("true").spawn().unwrap();
        child.wait().unwrap();
        let dead = child.id();
        let live = std::os::unix::process::parent_id();
        let own = std::process::id();
        let kept = [
            format!(".a.txt.{live}.0.tmp"),
            format!(".a.txt.{own}.7.tmp"),
            format!(".b.txt.{dead}.0.tmp"),
            format!(".a.txt.{dead}.0.tmp.bak"),
            format!("a.txt.{dead}.0.tmp"),
            format!(".a.txt.{dead}.x.tmp"),
            format!(".a.txt.+{dead}.0.tmp"),
            ".a.txt.0.0.tmp".to_string(),
            ".a.txt.99999999999.0.tmp".to_string(),
        ];
        let removed = [format!(".a.txt.{dead}.0.tmp"), format!(".a.txt.{dead}.12.tmp")];
        for name in kept.iter().chain(&removed) {
            fs::write(dir.path().join(name), "junk").unwrap();
        }
        // a directory of a dead process's temporary name is not a temporary file
        fs::create_dir(dir.path().join(format!(".a.txt.{dead}.3.tmp"))).unwrap();
        write_text(&dir.path().join("a.txt"), "new").unwrap();
        let mut want: Vec<String> = kept.to_vec();
        want.extend(["a.txt".to_string(), format!(".a.txt.{dead}.3.tmp")]);
        want.sort();
        assert_eq!(names(dir.path()), want);
    }

    #[test]
    fn a_replaced_file_keeps_its_mode_and_owner_and_a_new_one_gets_file_creates() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.txt");
        for m in [0o600, 0o640, 0o755, 0o444, 0o666] {
            write_text(&out, "old").unwrap();
            fs::set_permissions(&out, fs::Permissions::from_mode(m)).unwrap();
            write_text(&out, "new").unwrap();
            assert_eq!(mode(&out), m, "mode {m:o} became {:o}", mode(&out));
            assert_eq!(fs::read_to_string(&out).unwrap(), "new");
            fs::remove_file(&out).unwrap();
        }
        // a process that may give files away (root) gives the new file the
        // old one's owner and group
        write_text(&out, "old").unwrap();
        if std::os::unix::fs::chown(&out, Some(12345), Some(23456)).is_ok() {
            use std::os::unix::fs::MetadataExt;
            write_text(&out, "new").unwrap();
            let m = fs::metadata(&out).unwrap();
            assert_eq!((m.uid(), m.gid()), (12345, 23456));
        }
        fs::remove_file(&out).unwrap();
        let created = dir.path().join("created.txt");
        File::create(&created).unwrap();
        write_text(&out, "new").unwrap();
        assert_eq!(mode(&out), mode(&created));
    }

    #[test]
    fn writes_through_a_symbolic_link_replace_its_target_and_keep_the_link() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real");
        fs::create_dir(&real).unwrap();
        let target = real.join("map.txt");
        write_text(&target, "old").unwrap();
        fs::set_permissions(&target, fs::Permissions::from_mode(0o640)).unwrap();
        // a chain of two links, the first relative
        symlink(&target, dir.path().join("abs")).unwrap();
        symlink("abs", dir.path().join("link")).unwrap();
        write_text(&dir.path().join("link"), "new").unwrap();
        assert_eq!(fs::read_link(dir.path().join("link")).unwrap(), Path::new("abs"));
        assert_eq!(fs::read_to_string(&target).unwrap(), "new");
        assert_eq!(mode(&target), 0o640);
        assert_eq!(names(&real), ["map.txt"]);
        // a dangling link: its target is created
        symlink("real/fresh.txt", dir.path().join("dangling")).unwrap();
        write_text(&dir.path().join("dangling"), "fresh").unwrap();
        assert!(fs::symlink_metadata(dir.path().join("dangling")).unwrap().file_type().is_symlink());
        assert_eq!(fs::read_to_string(real.join("fresh.txt")).unwrap(), "fresh");
        assert_eq!(names(&real), ["fresh.txt", "map.txt"]);
        // a loop is an error
        symlink("loop", dir.path().join("loop")).unwrap();
        let err = write_text(&dir.path().join("loop"), "x").unwrap_err();
        assert!(err.to_string().contains("too many levels of symbolic links"), "{err}");
        // an error through a link names the target
        symlink("missing/x.txt", dir.path().join("nowhere")).unwrap();
        let err = write_text(&dir.path().join("nowhere"), "x").unwrap_err();
        assert!(err.to_string().contains("missing/x.txt (the link's target)"), "{err}");
    }

    #[test]
    fn entry_writes_replace_a_link_itself_and_leave_its_target_alone() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("outside.txt");
        write_text(&target, "precious").unwrap();
        fs::set_permissions(&target, fs::Permissions::from_mode(0o600)).unwrap();
        let link = dir.path().join("entry");
        symlink(&target, &link).unwrap();
        write_entry_atomically(&link, |w| w.write_all(b"new")).unwrap();
        assert_eq!(fs::read_to_string(&target).unwrap(), "precious");
        assert!(fs::symlink_metadata(&link).unwrap().is_file());
        assert_eq!(fs::read_to_string(&link).unwrap(), "new");
        // dangling: nothing created where it pointed
        symlink(dir.path().join("nowhere.txt"), dir.path().join("dangling")).unwrap();
        write_entry_atomically(&dir.path().join("dangling"), |w| w.write_all(b"x")).unwrap();
        assert!(!dir.path().join("nowhere.txt").exists());
        // a link to a directory is replaced too; a directory is not
        fs::create_dir(dir.path().join("d")).unwrap();
        symlink(dir.path().join("d"), dir.path().join("to-dir")).unwrap();
        write_entry_atomically(&dir.path().join("to-dir"), |w| w.write_all(b"x")).unwrap();
        assert!(dir.path().join("d").is_dir());
        let err = write_entry_atomically(&dir.path().join("d"), |w| w.write_all(b"x")).unwrap_err();
        assert!(err.to_string().contains("is not a regular file"), "{err}");
        assert_eq!(names(dir.path()), ["d", "dangling", "entry", "outside.txt", "to-dir"]);
    }

    #[test]
    fn scratch_dirs_go_when_dropped_and_dead_processes_ones_at_the_next_write() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("map.ot");
        let scratch = ScratchDir::beside(&out).unwrap();
        let own = format!(".map.ot.spill-{}", std::process::id());
        assert_eq!(scratch.path(), dir.path().join(&own));
        fs::write(scratch.path().join("d8-1-2-3.olm"), "tile").unwrap();
        drop(scratch);
        assert!(names(dir.path()).is_empty());
        let mut child = std::process::Command::new("true").spawn().unwrap();
        child.wait().unwrap();
        let (dead, live) = (child.id(), std::os::unix::process::parent_id());
        let outside = dir.path().join("outside");
        fs::create_dir(&outside).unwrap();
        fs::write(outside.join("keep"), "precious").unwrap();
        let stale = |name: &str| {
            let d = dir.path().join(name);
            fs::create_dir(&d).unwrap();
            fs::write(d.join("d8-1-2-3.olm"), "tile").unwrap();
            symlink(&outside, d.join("link")).unwrap();
        };
        stale(&format!(".map.ot.spill-{dead}"));
        stale(&format!(".map.ot.spill-{live}"));
        stale(&format!(".other.ot.spill-{dead}"));
        symlink(&outside, dir.path().join(format!(".map.ot.spill-{}", dead + 1))).unwrap();
        let kept = names(dir.path()).into_iter().filter(|n| !n.ends_with(&format!("spill-{dead}"))).collect::<Vec<_>>();
        write_text(&out, "map").unwrap();
        let mut want = kept.clone();
        want.push(format!(".other.ot.spill-{dead}"));
        want.push("map.ot".into());
        want.sort();
        assert_eq!(names(dir.path()), want);
        assert_eq!(fs::read_to_string(outside.join("keep")).unwrap(), "precious");
        // a scratch directory beside the output removes them too
        stale(&format!(".map.ot.spill-{dead}"));
        let scratch = ScratchDir::beside(&out).unwrap();
        assert!(!dir.path().join(format!(".map.ot.spill-{dead}")).exists());
        drop(scratch);
        assert_eq!(names(dir.path()), want);
    }

    #[test]
    fn more_writes_at_once_than_the_signal_table_lists_all_succeed() {
        let dir = tempfile::tempdir().unwrap();
        let writers = 80;
        let all_open = std::sync::Barrier::new(writers);
        std::thread::scope(|scope| {
            for i in 0..writers {
                let (dir, all_open) = (dir.path(), &all_open);
                scope.spawn(move || {
                    write_atomically(&dir.join(format!("{i}.txt")), |w| {
                        all_open.wait();
                        write!(w, "{i}")
                    })
                    .unwrap();
                });
            }
        });
        for i in 0..writers {
            assert_eq!(fs::read_to_string(dir.path().join(format!("{i}.txt"))).unwrap(), i.to_string());
        }
        assert_eq!(names(dir.path()).len(), writers);
    }

    #[test]
    fn only_regular_files_are_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let err = write_text(dir.path(), "x").unwrap_err();
        assert!(err.to_string().contains("is not a regular file"), "{err}");
        symlink("/dev/null", dir.path().join("null")).unwrap();
        let err = write_text(&dir.path().join("null"), "x").unwrap_err();
        assert_eq!(err.to_string(), "/dev/null (the link's target): exists and is not a regular file");
    }
}
