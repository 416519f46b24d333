//! A tiled map's memory budget: tiles in memory are counted by the bytes
//! their trees hold; past the budget, the least recently updated ones are
//! written to the budget's directory as tile files and dropped, and read
//! back (verified) when an update or a merge reaches them again. A tile
//! read back and not changed since is dropped again without a write.

use super::error::TileError;
use super::file::{load_tree, open_to_read, write_tile};
use super::id::TileId;
use super::manifest::TileEntry;
use super::map::{Tile, TileState, TiledMap};
use crate::mapped::MappedMap;
use crate::tree::OccupancyTree;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// How much memory a [`TiledMap`]'s tiles may hold, and where the others go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MemoryBudget {
    /// Bytes the trees of the tiles in memory may hold together (their
    /// [`OccupancyTree::memory_usage`]). The tiles one group of updates
    /// touches stay in memory until the group is done, so a single tile
    /// larger than this is still held while it is updated.
    pub bytes: usize,
    /// Where tiles out of memory are kept, one `.olm` file each under its
    /// tile set name (a tile set's own directory may be given: its files
    /// are then written once). The map does not remove them.
    pub dir: PathBuf,
}

/// A [`MemoryBudget`] in force.
#[derive(Debug)]
pub(super) struct Budget {
    cap: usize,
    dir: PathBuf,
    live_bytes: usize,
    /// Tiles in memory by (last use, prefix): the first is evicted first.
    lru: BTreeSet<(u64, u64)>,
}

impl Budget {
    pub(super) fn new(b: MemoryBudget) -> Self {
        Budget { cap: b.bytes, dir: b.dir, live_bytes: 0, lru: BTreeSet::new() }
    }

    /// Counts a tile now in memory.
    pub(super) fn count_live(&mut self, last_use: u64, prefix: u64, bytes: usize) {
        self.live_bytes += bytes;
        self.lru.insert((last_use, prefix));
    }

    /// Stops counting a tile leaving memory.
    pub(super) fn uncount(&mut self, last_use: u64, prefix: u64, bytes: usize) {
        self.live_bytes -= bytes;
        self.lru.remove(&(last_use, prefix));
    }

    /// The spilled file of tile `id`.
    pub(super) fn path(&self, id: TileId) -> PathBuf {
        self.dir.join(id.file_name())
    }

    /// True when `dir` is the budget's directory.
    pub(super) fn is_dir(&self, dir: &Path) -> bool {
        match (std::fs::canonicalize(&self.dir), std::fs::canonicalize(dir)) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        }
    }

    /// Maps a spilled tile's file, checked against what was written (its
    /// length, node count and CRC-32): a file changed or replaced on disk
    /// meanwhile is an error naming it, never read into the map.
    pub(super) fn open(&self, entry: &TileEntry) -> Result<MappedMap<memmap2::Mmap>, TileError> {
        open_to_read(&self.dir, entry, None)
    }

    /// Reads a spilled tile's tree back, verified.
    pub(super) fn load(&self, entry: &TileEntry) -> Result<OccupancyTree, TileError> {
        let map = self.open(entry)?;
        load_tree(&map, entry).map_err(|reason| TileError::damaged(entry.id, self.path(entry.id), reason))
    }
}

impl TiledMap {
    /// The budget, where a tile was spilled (always, then).
    pub(super) fn budget_ref(&self) -> Result<&Budget, TileError> {
        self.budget.as_ref().ok_or(TileError::Internal("a spilled tile without a memory budget"))
    }

    /// Takes tile `prefix`'s tree out of the map for an update (a new one
    /// if the tile has none), reading it back if it was spilled; with it,
    /// the description of its spilled file when that file holds it.
    pub(super) fn take_tree(&mut self, prefix: u64) -> Result<(OccupancyTree, Option<TileEntry>), TileError> {
        let Some(tile) = self.tiles.remove(&prefix) else {
            return Ok((self.new_tile_tree(), None));
        };
        match tile.state {
            TileState::Live { tree, bytes, saved } => {
                if let Some(b) = &mut self.budget {
                    b.uncount(tile.last_use, prefix, bytes);
                }
                Ok((*tree, saved))
            }
            TileState::Spilled(entry) => match self.budget_ref().and_then(|b| b.load(&entry)) {
                Ok(mut tree) => {
                    tree.set_sensor(self.sensor);
                    Ok((tree, Some(entry)))
                }
                Err(e) => {
                    self.tiles.insert(prefix, Tile { state: TileState::Spilled(entry), last_use: tile.last_use });
                    Err(e)
                }
            },
        }
    }

    /// Puts tile `prefix`'s tree back, used now.
    pub(super) fn put_tree(&mut self, prefix: u64, tree: OccupancyTree, saved: Option<TileEntry>) {
        let bytes = tree.memory_usage();
        if let Some(b) = &mut self.budget {
            b.count_live(self.uses, prefix, bytes);
        }
        let tree = Box::new(tree);
        self.tiles.insert(prefix, Tile { state: TileState::Live { tree, bytes, saved }, last_use: self.uses });
    }

    /// Spills the least recently used tiles until those in memory fit the
    /// budget.
    pub(super) fn enforce_budget(&mut self) -> Result<(), TileError> {
        loop {
            let Some(b) = &self.budget else { return Ok(()) };
            if b.live_bytes <= b.cap {
                return Ok(());
            }
            let Some(&(_, prefix)) = b.lru.first() else { return Ok(()) };
            self.spill(prefix)?;
        }
    }

    /// Writes tile `prefix`'s tree to the budget's directory (unless its
    /// file already holds it) and drops it from memory.
    pub(super) fn spill(&mut self, prefix: u64) -> Result<(), TileError> {
        let id = TileId::from_prefix(self.depth, prefix);
        let b = self.budget.as_mut().ok_or(TileError::Internal("spilling without a budget"))?;
        let tile = self.tiles.get_mut(&prefix).ok_or(TileError::Internal("spilling a tile the map lacks"))?;
        let TileState::Live { tree, bytes, saved } = &tile.state else {
            return Err(TileError::Internal("spilling a tile not in memory"));
        };
        let entry = match saved {
            Some(entry) => *entry,
            None => write_tile(tree, id, &b.path(id))?,
        };
        b.uncount(tile.last_use, prefix, *bytes);
        tile.state = TileState::Spilled(entry);
        Ok(())
    }
}
