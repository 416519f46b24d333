//! A tile's file: its tree as an `.olm` map (full variant, rank index)
//! holding the chain of single children from the root down to the tile
//! root and the tile's subtree below it. Writing, describing (the manifest
//! entry) and checking one.

use super::error::TileError;
use super::id::{code_shift, TileId};
use super::manifest::{Manifest, TileEntry};
use super::top::{root_of, tile_root_node, TileRoot};
use crate::mapped::{self, MapView, MappedMap, Variant, WriteOptions};
use crate::morton::MortonCode;
use crate::tree::OccupancyTree;
use std::io::Write;
use std::path::Path;

/// How much of a tile file is checked when a query maps it. Whatever
/// this says, a tile whose nodes are read into a merge or an output (a
/// [`TileSet::merge`](super::TileSet::merge), a walk for the file
/// writers, a tiled map's tile read back) is checked by its length,
/// `.olm` header and CRC-32 against the manifest first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TileCheck {
    /// O(1): the length, and the `.olm` header against the manifest; the
    /// bytes are trusted (a file swapped for another of the same length
    /// and header answers from its own nodes).
    Header,
    /// O(file): also the CRC-32, every `.olm` checksum and the structure,
    /// and the tile root against the manifest.
    #[default]
    Full,
}

/// Writes `tree` (tile `id` alone) as `.olm` to `path`, atomically but
/// without a sync (see [`crate::formats::atomic::sync_filesystem`], which a
/// tile set's writer calls once before its manifest), and describes it.
pub(crate) fn write_tile(tree: &OccupancyTree, id: TileId, path: &Path) -> Result<TileEntry, TileError> {
    let bytes = mapped::to_bytes(tree, WriteOptions::default()).map_err(|e| TileError::io(path, e))?;
    let entry = describe(id, &bytes).map_err(|reason| TileError::damaged(id, path, reason))?;
    write_bytes(path, &bytes)?;
    Ok(entry)
}

/// Writes a tile file's bytes to `path` inside a tile set or a budget's
/// directory, atomically, without a sync: a symbolic link at `path` is
/// replaced, never written through.
pub(crate) fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), TileError> {
    crate::formats::atomic::write_entry_batched(path, |w| w.write_all(bytes)).map_err(|e| TileError::io(path, e))
}

/// The manifest entry of tile `id` whose file holds `bytes` (header and
/// structure checks only; the caller trusts or verified the nodes).
fn describe(id: TileId, bytes: &[u8]) -> Result<TileEntry, String> {
    let map = MappedMap::new(bytes).map_err(|e| e.to_string())?;
    let root = root_in_view(map.view(), id)?;
    Ok(TileEntry { id, nodes: map.header().node_count, bytes: bytes.len() as u64, crc32: crc32fast::hash(bytes), root })
}

/// The tile root of a mapped tile file, after checking that the nodes
/// down to it form the chain of single children a tile file has.
fn root_in_view(view: MapView<'_>, id: TileId) -> Result<TileRoot, String> {
    let depth = id.depth();
    let mut chain = 0u8;
    for item in view.nodes(depth).take(usize::from(depth) + 2) {
        if item.depth != chain
            || (chain > 0 && TileId::of_key(item.key, chain).prefix() != id.prefix() >> (3 * u32::from(depth - chain)))
        {
            return Err(format!("the node at depth {} lies outside the tile's path from the root", item.depth));
        }
        chain += 1;
    }
    if chain != depth + 1 {
        return Err(format!("the path from the root to the tile root ends at depth {}", i32::from(chain) - 1));
    }
    let found = view.search(id.key_range().0, depth).filter(|f| f.depth == depth);
    let f = found.ok_or("the tile root cannot be found")?;
    Ok(TileRoot { value: f.value, extra: f.extra, is_leaf: f.is_leaf })
}

/// The child mask of the tile root in a mapped tile file (the tile's
/// children at depth `D + 1`, from the file's pre-order nodes).
pub(crate) fn root_mask_in_view(view: MapView<'_>, id: TileId) -> u8 {
    let below = id.depth() + 1;
    let shift = code_shift(below);
    view.nodes(below)
        .filter(|n| n.depth == below)
        .fold(0, |mask, n| mask | 1 << ((MortonCode::encode(n.key).0 >> shift) & 7))
}

/// Checks a mapped tile file against its manifest entry and the set's
/// parameters, as far as `check` asks.
pub(crate) fn check_tile<D: AsRef<[u8]>>(
    map: &MappedMap<D>,
    entry: &TileEntry,
    manifest: &Manifest,
    check: TileCheck,
) -> Result<(), String> {
    let h = map.header();
    let bytes = map.bytes();
    if bytes.len() as u64 != entry.bytes {
        return Err(format!("file is {} bytes, the manifest says {}", bytes.len(), entry.bytes));
    }
    if h.variant != Variant::Full {
        return Err("not the full variant of .olm".into());
    }
    if h.kind != manifest.kind {
        return Err(format!("holds a {} map, the manifest says {}", h.kind.name(), manifest.kind.name()));
    }
    if h.resolution.to_bits() != manifest.resolution.to_bits() {
        return Err(format!("resolution {} differs from the manifest's {}", h.resolution, manifest.resolution));
    }
    if sensor_bits(&h.sensor) != sensor_bits(&manifest.sensor) {
        return Err("sensor model differs from the manifest's".into());
    }
    if h.node_count != entry.nodes {
        return Err(format!("holds {} nodes, the manifest says {}", h.node_count, entry.nodes));
    }
    if check == TileCheck::Header {
        return Ok(());
    }
    check_crc(bytes, entry)?;
    map.verify().map_err(|e| e.to_string())?;
    let root = root_in_view(map.view(), entry.id)?;
    if root_bits(root) != root_bits(entry.root) {
        return Err(format!("tile root {root:?} differs from the manifest's {:?}", entry.root));
    }
    Ok(())
}

/// The CRC-32 of a tile file's bytes against its manifest entry.
fn check_crc(bytes: &[u8], entry: &TileEntry) -> Result<(), String> {
    let crc = crc32fast::hash(bytes);
    if crc != entry.crc32 {
        return Err(format!(
            "CRC-32 {crc:08x} differs from the manifest's {:08x}: the file is not the tile the manifest lists",
            entry.crc32
        ));
    }
    Ok(())
}

/// Maps the file of `entry` in `dir` for its nodes to be read into a
/// merge or an output, checked first against the entry: its length, its
/// `.olm` header (against `manifest`'s parameters when given, else its
/// node count) and its CRC-32, so that no other file's bytes go in.
pub(crate) fn open_to_read(
    dir: &Path,
    entry: &TileEntry,
    manifest: Option<&Manifest>,
) -> Result<MappedMap<memmap2::Mmap>, TileError> {
    let map = open_tile(dir, entry)?;
    let header = match manifest {
        Some(m) => check_tile(&map, entry, m, TileCheck::Header),
        None if map.header().node_count != entry.nodes => {
            Err(format!("holds {} nodes, the tile written held {}", map.header().node_count, entry.nodes))
        }
        None => Ok(()),
    };
    header
        .and_then(|()| check_crc(map.bytes(), entry))
        .map_err(|reason| TileError::damaged(entry.id, dir.join(entry.id.file_name()), reason))?;
    Ok(map)
}

/// The in-memory tree of a checked tile file, with its tile root node
/// checked against the manifest entry.
pub(crate) fn load_tree<D: AsRef<[u8]>>(map: &MappedMap<D>, entry: &TileEntry) -> Result<OccupancyTree, String> {
    let tree = map.to_tree().map_err(|e| e.to_string())?;
    let root = tree.root().ok_or("the tile file holds no node")?;
    let node = tile_root_node(root, entry.id)?;
    if root_bits(root_of(node)) != root_bits(entry.root) {
        return Err(format!("tile root {:?} differs from the manifest's {:?}", root_of(node), entry.root));
    }
    Ok(tree)
}

fn sensor_bits(s: &crate::sensor::SensorModel) -> [u32; 5] {
    [s.hit, s.miss, s.clamping_min, s.clamping_max, s.occupancy_threshold].map(f32::to_bits)
}

fn root_bits(r: TileRoot) -> (u32, u32, bool) {
    (r.value.to_bits(), r.extra, r.is_leaf)
}

/// Maps the file of `entry` in `dir`: a missing file is
/// [`TileError::MissingTile`], anything else wrong names the tile.
pub(crate) fn open_tile(dir: &Path, entry: &TileEntry) -> Result<MappedMap<memmap2::Mmap>, TileError> {
    let path = dir.join(entry.id.file_name());
    match std::fs::metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(TileError::MissingTile { tile: entry.id, path });
        }
        Err(e) => return Err(TileError::io(&path, e)),
        Ok(m) if !m.is_file() => return Err(TileError::damaged(entry.id, &path, "not a regular file")),
        Ok(m) if m.len() != entry.bytes => {
            let reason = format!("file is {} bytes, the manifest says {}", m.len(), entry.bytes);
            return Err(TileError::damaged(entry.id, &path, reason));
        }
        Ok(_) => {}
    }
    mapped::open(&path).map_err(|e| TileError::damaged(entry.id, &path, e.to_string()))
}
