//! The one error type of tiled maps and tile sets.

use super::id::TileId;
use crate::key::KeyError;
use crate::ray::CastError;
use crate::scan::ScanError;
use crate::tree::TreeError;
use std::io;
use std::path::PathBuf;

/// Why a tiled map or a tile set could not do what was asked. Errors
/// about a tile name it (`d{depth}-{x}-{y}-{z}`) and its file.
#[derive(Debug, thiserror::Error)]
pub enum TileError {
    /// The tile depth is outside 1..=15.
    #[error("tile depth {0} is outside 1..=15")]
    BadDepth(u8),
    /// A window's radius is not a finite number of metres ≥ 0.
    #[error("window radius {0} m: expected a finite number >= 0")]
    BadWindow(f64),
    /// The resolution is not a positive finite number.
    #[error(transparent)]
    Tree(#[from] TreeError),
    /// The operation cannot be done exactly on tiles (the message says why).
    #[error("{0}")]
    Unsupported(&'static str),
    /// A scan was refused; nothing of it was applied.
    #[error(transparent)]
    Scan(#[from] ScanError),
    /// A point has no key in the map.
    #[error(transparent)]
    Key(#[from] KeyError),
    /// A ray could not be cast.
    #[error(transparent)]
    Cast(#[from] CastError),
    /// Reading or writing a file failed (the I/O error is the source).
    #[error("{}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What failed.
        source: io::Error,
    },
    /// A manifest (or a task's part of one) is malformed.
    #[error("{}: line {line}: {reason}", path.display())]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// Line number (1-based) of the fault; 0 for the file as a whole.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A tile's file is damaged or does not match the manifest.
    #[error("tile {tile} ({}): {reason}", path.display())]
    DamagedTile {
        /// The tile.
        tile: TileId,
        /// Its file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A tile the manifest lists has no file.
    #[error("tile {tile}: its file {} is missing", path.display())]
    MissingTile {
        /// The tile.
        tile: TileId,
        /// The file that should hold it.
        path: PathBuf,
    },
    /// The task parts of a tile set do not add up to one set.
    #[error("{}: {reason}", dir.display())]
    Parts {
        /// The tile set's directory.
        dir: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A directory cannot receive a tile set: writing one there could
    /// replace or remove files that are not the set's.
    #[error("{}: {reason}", dir.display())]
    SetDir {
        /// The directory.
        dir: PathBuf,
        /// Why not.
        reason: String,
    },
    /// A plan file is malformed.
    #[error("{}: line {line}: {reason}", path.display())]
    PlanFile {
        /// The plan file.
        path: PathBuf,
        /// Line number (1-based) of the fault.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The tile set's path exists and is not a directory.
    #[error(
        "{} exists and is not a directory (a tile set is a directory): remove it or write to another NAME.tiles",
        dir.display()
    )]
    NotADirectory {
        /// The path.
        dir: PathBuf,
    },
    /// Another writer holds the tile set's lock ([`super::SetLock`]): a
    /// build of the whole set, or of the same task.
    #[error("{}: {holder} is writing this tile set (it holds {}); wait for it to end or write to another NAME.tiles", dir.display(), lock.display())]
    Locked {
        /// The tile set's directory.
        dir: PathBuf,
        /// The lock file held.
        lock: PathBuf,
        /// Who holds it, as the message says it.
        holder: String,
    },
    /// A tile plan is malformed or cannot be made (line 0: not about a
    /// line of a plan file).
    #[error("tile plan{}: {reason}", at_line(*.line))]
    Plan {
        /// Line number (1-based) of the fault in the plan file; 0 for none.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// Inner nodes are stale after deferred updates: the single tree's
    /// upper levels cannot be derived until they are updated.
    #[error("inner nodes are stale after deferred (lazy) updates: call update_inner_occupancy first")]
    StaleInnerNodes,
    /// A broken invariant of this crate (a bug), named.
    #[error("internal error: {0}")]
    Internal(&'static str),
}

/// `, line N` for a line of a file, nothing for line 0.
fn at_line(line: usize) -> String {
    if line == 0 {
        String::new()
    } else {
        format!(", line {line}")
    }
}

impl TileError {
    /// An I/O error on `path`.
    pub(crate) fn io(path: impl Into<PathBuf>, source: io::Error) -> Self {
        TileError::Io { path: path.into(), source }
    }

    /// A damaged tile.
    pub(crate) fn damaged(tile: TileId, path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        TileError::DamagedTile { tile, path: path.into(), reason: reason.into() }
    }
}
