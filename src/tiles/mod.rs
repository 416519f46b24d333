//! Tiled maps: a map split into the octree's subtrees at a fixed depth
//! `D` (1..=15), one tree per tile, so that a map can be built within a
//! memory budget, larger than memory, or in parts by separate processes,
//! and still be OctoMap's map to the byte. [`TiledMap`] takes scans one by
//! one (with a [`MemoryBudget`], tiles wait on disk); [`GroupedBuild`]
//! builds a tile set group of tiles by group of tiles from scans it can
//! read again, within a memory that holds the scans' updates too;
//! [`TilePlan`] splits the tiles among processes.
//!
//! A tile ([`TileId`]) is the subtree below a node of depth `D`, named by
//! the top `D` bits of each key axis; its edge is `resolution * 2^(16-D)`.
//! Its voxels' Morton codes share their top `3D` bits, so a scan's sorted
//! voxel lists fall into tiles as contiguous runs.
//!
//! # Why the tiles are the single tree
//!
//! A scan's voxel sets are computed once for the whole map (OctoMap's
//! `insertPointCloud` rules) and each tile's tree ([`TiledMap`]) receives
//! exactly the updates inside it. A tile's tree is an ordinary
//! [`OccupancyTree`](crate::OccupancyTree) holding the chain of single
//! children from the root to the tile root and the tile's subtree below:
//! nodes above `D` with one child are never pruned, so below `D` each tile
//! tree evolves as the single tree's subtree does. Above `D`, the single
//! tree keeps every inner node the maximum of its children and prunes it
//! when its eight children are leaves of one value (and one stamp): on the
//! way back up from every update that changed something below it
//! (`updateNodeRecurs`), and only then. So its upper levels are always
//! what `top.rs` derives from the tile roots. The one place where
//! the single tree's upper levels act on a tile is expansion: an update
//! reaching a pruned node above `D` expands it, and the children get the
//! parent's value and stamp — which is what each tile root held when the
//! parent was pruned (pruning needs them all equal), and still holds,
//! since nothing below a pruned node changed since. A saturated update on
//! the pruned node leaves it, and equally the tile root, alone. Deferred
//! (lazy) updates of plain trees prune nothing, so no tile root becomes a
//! leaf through them, and `updateInnerOccupancy` afterwards sets every
//! inner node to the maximum of its children: the derived levels again.
//!
//! Where this fails, tiles refuse: colour trees (colours blended in hash
//! order across the scan, and re-expanded nodes take the average colour,
//! not their own), deferred (lazy) updates of stamped trees, and a merge
//! while deferred updates left inner nodes stale. `prune()` and
//! `toMaxLikelihood()` between scans (OctoMap's `prune()` stops at the
//! first level where nothing merged, across the whole tree) are not
//! offered: do them on the merged tree.
//!
//! # Modules
//!
//! * `id`: [`TileId`], tile addressing (keys, codes, metric bounds, file names);
//! * `top`: the levels above the tiles derived from the tile roots;
//! * `map`: [`TiledMap`], updates, queries, merge and [`TiledMap::flush`];
//! * `budget`: [`MemoryBudget`], tiles spilled to disk and read back;
//! * `file`: a tile's `.olm` file, written, described and checked;
//! * `forget`: opt-in forgetting (a rolling [`Window`] of tiles, old voxels of
//!   stamped maps), departures from OctoMap;
//! * `manifest`: the tile set's manifest ([`Manifest`]), `formats/tiles.md`;
//! * `plan`: [`TileWork`] and [`TilePlan`], tasks owning balanced ranges of
//!   tiles for builds on several machines;
//! * `set`: [`TileSet`], a tile set on disk, mapped tile by tile;
//! * `stream`: the single tree walked in pre-order across the tiles, one
//!   tile read at a time, for the file writers and the merge;
//! * `query`: ray casting across tiles;
//! * `error`: [`TileError`], the one error type.

mod budget;
mod error;
mod file;
mod forget;
mod grouped;
mod id;
mod manifest;
mod map;
mod plan;
mod query;
mod set;
mod stream;
mod top;

pub use budget::MemoryBudget;
pub use error::TileError;
pub use file::TileCheck;
pub use forget::{Beyond, Window};
pub use grouped::{BuiltGroup, GroupedBuild, GroupedError, GroupedReport, UPDATE_BYTES};
pub use id::{TileId, MAX_TILE_DEPTH};
pub use manifest::{
    check_set_dir, is_tile_set_name, task_of, BuildInput, BuildRecord, Manifest, ManifestError, TaskPart, TaskTiles,
    TileEntry, MAGIC, MANIFEST_FILE, MAX_LINE_BYTES, MAX_TASKS, VERSION,
};
pub use map::{TiledMap, TiledStats};
pub use plan::{
    PlannedTask, TilePlan, TileWork, MAX_PLAN_BYTES, PLAN_MAGIC, PLAN_VERSION, SAMPLE_ABOVE, SAMPLE_STRIDE, UPDATE_COST,
};
pub use set::{
    combine_parts, oversize, read_manifest, remove_unlisted_tiles, Oversize, SetLock, TileSet, TileSetReport, LOCK_FILE,
};
pub use top::TileRoot;

#[cfg(test)]
mod tests;
