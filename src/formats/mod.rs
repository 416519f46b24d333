//! On-disk formats. Each reader takes `impl BufRead` (or `impl Read`), or
//! a byte slice for the files of other tools read whole (PLY, PCD, binvox),
//! each writer `impl Write`; writes to a path go through [`write_atomically`]
//! so an interrupted write never leaves a half-written file (see [`atomic`]).

pub mod atomic;
pub mod binvox;
pub mod bounded;
pub mod bt;
pub mod graph;
mod header;
pub mod log;
mod map_file;
mod ml_records;
pub mod ot;
pub mod pcd;
mod pieces;
pub mod ply;
pub mod ros;
mod scalar;
pub mod xyz;

pub use atomic::write_atomically;
pub use header::{format_double, Header};
pub use map_file::{read_map_file, MapFileError, MapFormat};
pub use scalar::ColoredCloud;

use std::io;
use std::path::Path;

/// Why an `.ot` or `.bt` file (or a ROS `Octomap` message) could not be
/// read. Every variant that concerns a place in the input names its byte
/// offset (counted from the start of the file, or of the message's `data`).
#[derive(Debug, thiserror::Error)]
pub enum TreeFileError {
    /// The underlying reader failed (other than by ending early).
    #[error("I/O error")]
    Io(#[from] io::Error),
    /// The text header is malformed: no `data` line, no `id`, a line or
    /// token too long, or a `res` or `size` value that does not parse.
    #[error("bad header at byte {offset}: {reason}")]
    Header {
        /// Byte offset of the offending token or line.
        offset: u64,
        /// What is wrong with it.
        reason: String,
    },
    /// The resolution (voxel edge length, metres) is outside the usable
    /// range ([`crate::key::check_resolution`]).
    /// `offset` is that of the `res` value; `None` for a message's field.
    #[error("{}{}", crate::key::KeyError::BadResolution { value: *.value }, at_byte(.offset))]
    BadResolution {
        /// The resolution read.
        value: f64,
        /// Byte offset of the value, where it has one.
        offset: Option<u64>,
    },
    /// The input ends before a field or record is complete.
    #[error("input ends inside {what} starting at byte {offset}")]
    Truncated {
        /// Byte offset where the incomplete item starts.
        offset: u64,
        /// What was being read, e.g. "a node's child labels".
        what: &'static str,
    },
    /// A node record gives children to a node at depth 16, the voxel level.
    #[error("node at byte {offset} lies below depth 16 (a voxel cannot have children)")]
    TooDeep {
        /// Byte offset of that node's record.
        offset: u64,
    },
    /// The header's `size` differs from the number of nodes the data holds.
    #[error("header announces {header} nodes but the data ending at byte {offset} holds {read}")]
    SizeMismatch {
        /// Byte offset just past the node data.
        offset: u64,
        /// Node count the header announces.
        header: u64,
        /// Node count actually read.
        read: u64,
    },
    /// The tree type `id` (OctoMap's class name, e.g. `OcTree`) is not
    /// one this crate knows.
    /// `offset` is that of the `id` value; `None` for a message's field.
    #[error("unknown tree type `{id}`{}", at_byte(.offset))]
    UnknownTreeType {
        /// The `id` read.
        id: String,
        /// Byte offset of the value, where it has one.
        offset: Option<u64>,
    },
    /// The tree type (the `id` given) is known but cannot be read yet.
    #[error("tree type `{0}` is recognised but not supported yet")]
    UnsupportedTreeType(String),
    /// The input is not the kind of file expected: e.g. a full `.ot` file
    /// given to the `.bt` reader, or an unknown first line.
    #[error("not an OctoMap {expected} at byte {offset}: {reason}")]
    WrongFormat {
        /// Byte offset where the mismatch was found (0 when it is the first line).
        offset: u64,
        /// What was expected, e.g. ".bt file".
        expected: &'static str,
        /// What was found instead.
        reason: String,
    },
}

/// A file opened for reading with a 64 KiB buffer, the size the readers
/// are tuned for.
fn buffered_file(path: &Path) -> io::Result<io::BufReader<std::fs::File>> {
    Ok(io::BufReader::with_capacity(1 << 16, std::fs::File::open(path)?))
}

fn at_byte(offset: &Option<u64>) -> String {
    offset.map(|o| format!(" at byte {o}")).unwrap_or_default()
}
