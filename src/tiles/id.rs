//! Tile addressing: which subtree of the octree a tile is, the keys and
//! the metric box it covers, and its file name in a tile set.

use crate::key::{Key, KeySpace, TREE_DEPTH};
use crate::morton::MortonCode;
use crate::tree::Bounds;
use std::fmt;

/// Finest tile depth: a tile of depth 15 is 2 voxels a side.
pub const MAX_TILE_DEPTH: u8 = TREE_DEPTH - 1;

/// A tile: the octree's subtree rooted at a node of depth `depth` (1..=15),
/// named by the top `depth` bits of each key axis. Its voxels' Morton codes
/// share their top `3 * depth` bits (the [`Self::prefix`]), so a sorted
/// list of codes falls into tiles as contiguous runs, in tile order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileId {
    // field order gives the derived order: by depth, then Morton order
    depth: u8,
    prefix: u64,
}

impl TileId {
    /// The tile of depth `depth` at tile coordinates `xyz` (each below
    /// `2^depth`); `None` when the depth is outside 1..=15 or a coordinate
    /// is too large.
    pub fn new(depth: u8, xyz: [u32; 3]) -> Option<TileId> {
        if !(1..=MAX_TILE_DEPTH).contains(&depth) || xyz.iter().any(|&c| c >= 1 << depth) {
            return None;
        }
        let shift = TREE_DEPTH - depth;
        let key = Key(xyz.map(|c| (c << shift) as u16));
        Some(TileId::of_key(key, depth))
    }

    /// The tile of depth `depth` holding `key`. `depth` must be in 1..=15.
    #[inline]
    pub fn of_key(key: Key, depth: u8) -> TileId {
        TileId::of_code(MortonCode::encode(key).0, depth)
    }

    /// The tile of depth `depth` holding the voxel with Morton code `code`.
    #[inline]
    pub fn of_code(code: u64, depth: u8) -> TileId {
        debug_assert!((1..=MAX_TILE_DEPTH).contains(&depth));
        TileId { depth, prefix: code >> code_shift(depth) }
    }

    /// The tile with Morton prefix `prefix` at `depth` (`prefix` below `8^depth`).
    pub(crate) fn from_prefix(depth: u8, prefix: u64) -> TileId {
        debug_assert!(prefix >> (3 * u32::from(depth)) == 0);
        TileId { depth, prefix }
    }

    /// Depth of the tile's root node.
    pub fn depth(self) -> u8 {
        self.depth
    }

    /// The top `3 * depth` bits of the Morton code of every voxel inside.
    pub fn prefix(self) -> u64 {
        self.prefix
    }

    /// Tile coordinates: the top `depth` bits of each key axis.
    pub fn coords(self) -> [u32; 3] {
        MortonCode(self.prefix).decode().0.map(u32::from)
    }

    /// The first and last voxel keys inside (inclusive, per axis).
    pub fn key_range(self) -> (Key, Key) {
        let shift = TREE_DEPTH - self.depth;
        let low = self.coords().map(|c| (c << shift) as u16);
        let high = low.map(|c| c | ((1u32 << shift) - 1) as u16);
        (Key(low), Key(high))
    }

    /// The Morton codes inside: `first..=last`.
    pub fn code_range(self) -> (u64, u64) {
        let shift = code_shift(self.depth);
        (self.prefix << shift, ((self.prefix + 1) << shift) - 1)
    }

    /// True when `key` lies inside.
    pub fn contains(self, key: Key) -> bool {
        TileId::of_key(key, self.depth) == self
    }

    /// The tile's cube in metres: edge `resolution * 2^(16 - depth)`.
    pub fn bounds(self, keys: &KeySpace) -> Bounds {
        let (low, _) = self.key_range();
        let edge = keys.node_size(self.depth);
        let min = low.0.map(|k| (f64::from(k) - f64::from(crate::key::KEY_CENTER)) * keys.resolution());
        Bounds { min, max: min.map(|m| m + edge) }
    }

    /// The child position (0..8) of the tile's path below a node at
    /// `depth` (< the tile's depth).
    #[inline]
    pub(crate) fn child_index(self, depth: u8) -> usize {
        debug_assert!(depth < self.depth);
        ((self.prefix >> (3 * u32::from(self.depth - 1 - depth))) & 7) as usize
    }

    /// The tile's file name in a tile set: `d{depth}-{x}-{y}-{z}.olm`.
    pub fn file_name(self) -> String {
        let [x, y, z] = self.coords();
        format!("d{}-{x}-{y}-{z}.olm", self.depth)
    }

    /// The tile a file name names, when it is exactly what
    /// [`Self::file_name`] gives for some tile.
    pub fn from_file_name(name: &str) -> Option<TileId> {
        let stem = name.strip_prefix('d')?.strip_suffix(".olm")?;
        let mut parts = stem.split('-');
        let mut number = || -> Option<u32> {
            let s = parts.next()?;
            // canonical decimal only: no sign, no leading zeros
            if s.is_empty() || s.len() > 5 || (s.len() > 1 && s.starts_with('0')) {
                return None;
            }
            s.bytes().all(|b| b.is_ascii_digit()).then(|| s.parse().ok())?
        };
        let depth = u8::try_from(number()?).ok()?;
        let xyz = [number()?, number()?, number()?];
        if parts.next().is_some() {
            return None;
        }
        TileId::new(depth, xyz)
    }
}

/// The shift that leaves a code's tile prefix at `depth`.
#[inline]
pub(crate) fn code_shift(depth: u8) -> u32 {
    3 * u32::from(TREE_DEPTH - depth)
}

impl fmt::Display for TileId {
    /// The file name's stem, `d{depth}-{x}-{y}-{z}`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.coords();
        write!(f, "d{}-{x}-{y}-{z}", self.depth)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_codes_and_coordinates_agree() {
        let key = Key::new(40000, 12345, 32768);
        for depth in 1..=MAX_TILE_DEPTH {
            let t = TileId::of_key(key, depth);
            let shift = TREE_DEPTH - depth;
            assert_eq!(t.coords(), key.0.map(|k| u32::from(k >> shift)));
            assert_eq!(TileId::new(depth, t.coords()), Some(t));
            let (low, high) = t.key_range();
            assert!((0..3).all(|i| low.0[i] <= key.0[i] && key.0[i] <= high.0[i]));
            assert_eq!(TileId::of_key(low, depth), t);
            assert_eq!(TileId::of_key(high, depth), t);
            let (first, last) = t.code_range();
            assert_eq!(first, MortonCode::encode(low).0);
            assert_eq!(last, MortonCode::encode(high).0);
            assert!(t.contains(key));
            assert_eq!(TileId::from_file_name(&t.file_name()), Some(t));
            assert_eq!(t.to_string() + ".olm", t.file_name());
            // the path from the root: the key's own child indices
            for d in 0..depth {
                assert_eq!(t.child_index(d), key.child_index(d));
            }
        }
    }

    #[test]
    fn bounds_are_the_tile_cube() {
        let keys = KeySpace::new(0.5);
        let t = TileId::new(2, [2, 0, 3]).unwrap();
        let b = t.bounds(&keys);
        // a depth-2 tile spans 2^14 voxels of 0.5 m
        assert_eq!(b.min, [0.0, -16384.0, 8192.0]);
        assert_eq!(b.size(), [8192.0; 3]);
    }

    #[test]
    fn only_canonical_names_and_valid_ids_are_accepted() {
        assert_eq!(TileId::new(0, [0, 0, 0]), None);
        assert_eq!(TileId::new(16, [0, 0, 0]), None);
        assert_eq!(TileId::new(3, [8, 0, 0]), None);
        for bad in ["d3-1-2-3", "d3-1-2-3.olm.olm", "d03-1-2-3.olm", "d3-+1-2-3.olm", "d3-1-2.olm", "d3-1-2-3-4.olm"] {
            assert_eq!(TileId::from_file_name(bad), None, "{bad}");
        }
        assert_eq!(TileId::from_file_name("d3-8-0-0.olm"), None);
        assert_eq!(TileId::from_file_name("../d3-1-2-3.olm"), None);
        assert!(TileId::from_file_name("d3-1-2-3.olm").is_some());
    }
}
