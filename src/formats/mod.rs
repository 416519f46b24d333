//! On-disk formats. Each reader takes `impl BufRead` (or `impl Read`), or
//! a byte slice for the files of other tools read whole (PLY, PCD, binvox),
//! each writer `impl Write`; writes to a path go through [`write_atomically`]
//! so an interrupted write never leaves a half-written file (see [`atomic`]).

pub mod atomic;
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

pub use atomic::write_atomically;
pub use header::{format_double, Header};
pub use scalar::ColoredCloud;

use std::io;
use std::path::Path;

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

/// A file opened for reading with a 64 KiB buffer, the size the readers
/// are tuned for.
fn buffered_file(path: &Path) -> io::Result<io::BufReader<std::fs::File>> {
    Ok(io::BufReader::with_capacity(1 << 16, std::fs::File::open(path)?))
}

fn at_byte(offset: &Option<u64>) -> String {
    offset.map(|o| format!(" at byte {o}")).unwrap_or_default()
}
