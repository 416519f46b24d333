//! On-disk formats. Each reader takes `impl BufRead` (or `impl Read`), or
//! a byte slice for the files of other tools read whole (PLY, PCD, binvox),
//! each writer `impl Write`; writes to a path go through [`write_atomically`]
//! so a crash never leaves a half-written file.

pub mod binvox;
pub mod bt;
pub mod graph;
mod header;
pub mod log;
pub mod ot;
pub mod pcd;
pub mod ply;
pub mod ros;
mod scalar;
pub mod xyz;

pub use header::{format_double, Header};
pub use scalar::ColoredCloud;

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// Why an `.ot` or `.bt` file (or a ROS `Octomap` message) could not be
/// read. Every variant that concerns a place in the input names its byte
/// offset (counted from the start of the file, or of the message's `data`).
#[derive(Debug, thiserror::Error)]
pub enum TreeFileError {
    #[error("I/O error: {0}")]
    Io(#[from] io::Error),
    #[error("bad header at byte {offset}: {reason}")]
    Header { offset: u64, reason: String },
    /// `offset` is that of the `res` value; `None` for a message's field.
    #[error("resolution {value}{} is not a positive finite number", at_byte(.offset))]
    BadResolution { value: f64, offset: Option<u64> },
    #[error("input ends inside {what} starting at byte {offset}")]
    Truncated { offset: u64, what: &'static str },
    #[error("node at byte {offset} lies below depth 16 (a voxel cannot have children)")]
    TooDeep { offset: u64 },
    #[error("header announces {header} nodes but the data ending at byte {offset} holds {read}")]
    SizeMismatch { offset: u64, header: u64, read: u64 },
    /// `offset` is that of the `id` value; `None` for a message's field.
    #[error("unknown tree type `{id}`{}", at_byte(.offset))]
    UnknownTreeType { id: String, offset: Option<u64> },
    #[error("tree type `{0}` is recognised but not supported yet")]
    UnsupportedTreeType(String),
    #[error("not an OctoMap {expected} at byte {offset}: {reason}")]
    WrongFormat { offset: u64, expected: &'static str, reason: String },
}

fn at_byte(offset: &Option<u64>) -> String {
    offset.map(|o| format!(" at byte {o}")).unwrap_or_default()
}

/// Writes through `write` into a fresh temporary file next to `path`,
/// syncs it, then renames it into place; on any error the temporary file is
/// removed and `path` is left as it was.
pub fn write_atomically(path: &Path, write: impl FnOnce(&mut BufWriter<&File>) -> io::Result<()>) -> io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, format!("{} names no file", path.display())))?;
    let (tmp, file) = create_temp(dir, &name.to_string_lossy())?;
    let result = (|| {
        let mut w = BufWriter::with_capacity(1 << 16, &file);
        write(&mut w)?;
        w.flush()?;
        drop(w);
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Creates a fresh `.<name>.<pid>.<n>.tmp` next to the target.
fn create_temp(dir: &Path, name: &str) -> io::Result<(PathBuf, File)> {
    let pid = std::process::id();
    for n in 0..1000u32 {
        let tmp = dir.join(format!(".{name}.{pid}.{n}.tmp"));
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(io::Error::new(io::ErrorKind::AlreadyExists, format!("no free temporary name in {}", dir.display())))
}
