//! Point queries: OctoMap's `search`, one key or many at once, through
//! the trunks and the level index.

use super::level_index::{self, Reach};
use super::{Found, NodeArena, NodeId, OccupancyTree, Parts, ROOT};
use crate::geometry::Point3;
use crate::key::{adjust_key_to_depth, Key, KeyError, TREE_DEPTH};
use crate::morton::MortonCode;

impl OccupancyTree {
    /// OctoMap's `search(key, depth)`: the node at `depth` (0 means 16)
    /// containing `key`, or the deepest existing leaf above it. `None`
    /// when the path ends at an inner node lacking the needed child.
    #[inline(always)]
    pub fn search(&self, key: Key, depth: u8) -> Option<Found> {
        self.search_in(key, key.child_index(0), depth)
    }

    /// [`Self::search`] given the key's root child (its child index at
    /// depth 1).
    #[inline(always)]
    fn search_in(&self, key: Key, octant: usize, depth: u8) -> Option<Found> {
        let a = self.arena.as_ref()?;
        if depth == 0 || depth >= TREE_DEPTH {
            if let Some(index) = self.levels.get(a, self.size) {
                return self.answer(a, key, index.search_in(key, octant, MortonCode::encode_table(key).0));
            }
            return self.search_full(a, key, octant);
        }
        self.search_arena(key, depth)
    }

    /// [`Self::search`] at depth 16 in the arena, with as few instructions
    /// as it takes: on a map that fits the caches, the processor overlaps
    /// consecutive queries as far as its window of instructions reaches.
    #[inline(always)]
    fn search_full(&self, a: &NodeArena, key: Key, octant: usize) -> Option<Found> {
        let (masks, first_child) = (a.masks(), a.first_child_ids());
        let child = |n: NodeId, pos: u64| -> Result<NodeId, u8> {
            let m = masks[n as usize];
            if m & (1 << pos) == 0 {
                Err(m)
            } else {
                Ok(first_child[n as usize] + crate::arch::count_ones(u32::from(m) & ((1 << pos) - 1)))
            }
        };
        let k = key.packed();
        let (mut node, from) = self.trunks.start_in(
            k,
            octant,
            TREE_DEPTH,
            |n| Some(masks[n as usize]),
            |n, _, pos| child(n, pos as u64).ok(),
        );
        // the child positions from depth `from` on, the next one on top
        let mut positions = if from >= 8 {
            (MortonCode::low_levels(k) << 40) << (3 * u32::from(from - 8))
        } else {
            (MortonCode::encode_table(key).0 << 16) << (3 * u32::from(from))
        };
        for d in from..TREE_DEPTH {
            match child(node, positions >> 61) {
                Ok(c) => node = c,
                Err(0) => return Some(Found { value: a.value(node), depth: d, is_leaf: true, extra: a.extra(node) }),
                Err(_) => return None,
            }
            positions <<= 3;
        }
        Some(Found { value: a.leaf_value(node), depth: TREE_DEPTH, is_leaf: true, extra: a.leaf_extra(node) })
    }

    /// The full-depth answer for `key` from where the level index got.
    #[inline(always)]
    fn answer(&self, a: &NodeArena, key: Key, reach: Reach) -> Option<Found> {
        let voxel = |value, extra| Some(Found { value, depth: TREE_DEPTH, is_leaf: true, extra });
        match reach {
            Reach::Voxel(id) => voxel(a.value(id), a.extra(id)),
            Reach::Value(value) => voxel(value, 0),
            Reach::Unknown => None,
            Reach::Coarse => self.search_arena(key, 0),
        }
    }

    /// Builds now what searches otherwise build at the first one after a
    /// bulk change: the grids below the trunks and, on trees of 2^19 nodes
    /// or more, the level index (about two leaf walks). For callers
    /// whose first query must not wait; answers do not change. Does nothing
    /// while the tree is changing (after a change other than a bulk one).
    pub fn prepare_search(&self) {
        if let Some(a) = &self.arena {
            let p = a.parts();
            self.trunks.prepare(|n| Some(p.mask(n)), |n, _, pos| p.descend(n, pos as u64).ok());
            self.levels.get(a, self.size);
        }
    }

    /// Whether full-depth searches go through the level index.
    pub(crate) fn levels_armed(&self) -> bool {
        self.levels.is_armed()
    }

    /// [`Self::search`] in the arena alone: for changes, which would drop
    /// the index they built.
    #[inline(always)]
    pub(super) fn search_arena(&self, key: Key, depth: u8) -> Option<Found> {
        let a = self.arena.as_ref()?;
        let (id, depth, is_leaf) = self.search_id(key, depth)?;
        Some(Found { value: a.value(id), depth, is_leaf, extra: a.extra(id) })
    }

    /// [`Self::search`] giving the node id (valid until the next change).
    #[inline(always)]
    pub(super) fn search_id(&self, key: Key, depth: u8) -> Option<(NodeId, u8, bool)> {
        let a = self.arena.as_ref()?;
        let (key, depth) = search_target(key, depth);
        // the table encoding: the code is on the query's chain of dependent
        // steps, and the table is faster than shifts and masks
        // (`docs/benchmarks.md`, "Criterion micro-benchmarks")
        let code = MortonCode::encode_table(key).0;
        let p = a.parts();
        let (node, from) = self.start(&p, key, depth);
        descend_to(&p, node, from, depth, code)
    }

    /// [`Self::search`] for many keys at once, answers in `out` (cleared
    /// first) in the order of `keys`. Eight descents advance in lockstep, so
    /// the cache misses of one overlap those of the others: for random
    /// queries this is several times the throughput of one `search` after
    /// another.
    pub fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>) {
        const LANES: usize = 8;
        out.clear();
        let Some(a) = self.arena.as_ref() else {
            out.resize(keys.len(), None);
            return;
        };
        let depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
        let p = a.parts();
        if let Some(index) = self.levels.get(a, self.size).filter(|_| depth == TREE_DEPTH) {
            let mut reach = [Reach::Unknown; level_index::LANES];
            for chunk in keys.chunks(level_index::LANES) {
                index.search_lanes(chunk, &mut reach);
                out.extend(chunk.iter().zip(&reach).map(|(&key, &r)| self.answer(a, key, r)));
            }
            return;
        }
        for chunk in keys.chunks(LANES) {
            let mut code = [0u64; LANES];
            let mut key = [Key::ROOT; LANES];
            for ((c, k), q) in code.iter_mut().zip(&mut key).zip(chunk) {
                *k = if depth == TREE_DEPTH { *q } else { adjust_key_to_depth(*q, depth) };
                *c = MortonCode::encode_table(*k).0;
            }
            // each lane starts at its trunk end: lanes join the walk at
            // that depth; those starting at `depth` itself have arrived
            let mut node = [ROOT; LANES];
            let mut joins = [0u32; TREE_DEPTH as usize + 1];
            for l in 0..chunk.len() {
                let (n, from) = self.start(&p, key[l], depth);
                node[l] = n;
                joins[from as usize] |= 1 << l;
            }
            let mut found: [Option<(NodeId, u8, bool)>; LANES] = [None; LANES];
            let mut walking = 0u32;
            let mut waiting = ((1u32 << chunk.len()) - 1) & !joins[depth as usize];
            for d in 0..depth {
                walking |= joins[d as usize];
                waiting &= !joins[d as usize];
                let shift = 3 * (TREE_DEPTH - 1 - d);
                let mut lanes = walking;
                while lanes != 0 {
                    let l = lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    match p.descend(node[l], (code[l] >> shift) & 7) {
                        Ok(c) => node[l] = c,
                        Err(m) => {
                            walking &= !(1 << l);
                            if m == 0 {
                                found[l] = Some((node[l], d, true));
                            }
                        }
                    }
                }
                if walking | waiting == 0 {
                    break;
                }
            }
            walking |= joins[depth as usize];
            while walking != 0 {
                let l = walking.trailing_zeros() as usize;
                walking &= walking - 1;
                found[l] = Some((node[l], depth, !a.has_children(node[l])));
            }
            out.extend(found[..chunk.len()].iter().map(|f| {
                f.map(|(id, depth, is_leaf)| Found { value: a.value(id), depth, is_leaf, extra: a.extra(id) })
            }));
        }
    }

    /// [`Self::search`] at the voxel containing `p`.
    #[inline]
    pub fn search_point(&self, p: Point3, depth: u8) -> Result<Option<Found>, KeyError> {
        let (key, octant) = self.keys.key_and_octant(p)?;
        Ok(self.search_in(key, octant, depth))
    }
}

/// A search's key and depth as OctoMap's `search` takes them: depth 0 (or
/// above 16) means 16, and a coarser depth's key is its node's centre key.
#[inline(always)]
pub(crate) fn search_target(key: Key, depth: u8) -> (Key, u8) {
    let depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
    (if depth == TREE_DEPTH { key } else { adjust_key_to_depth(key, depth) }, depth)
}

/// The rest of a search for the Morton `code` from `node`, which lies at
/// depth `from` on its path, down to `depth`: the node found, its depth
/// and whether it is a leaf; `None` when the path ends at an inner node
/// lacking the needed child (unknown space).
#[inline(always)]
pub(super) fn descend_to(
    p: &Parts<'_>,
    mut node: NodeId,
    from: u8,
    depth: u8,
    code: u64,
) -> Option<(NodeId, u8, bool)> {
    for d in from..depth {
        match p.descend(node, (code >> (3 * (TREE_DEPTH - 1 - d))) & 7) {
            Ok(c) => node = c,
            Err(m) => return (m == 0).then_some((node, d, true)),
        }
    }
    Some((node, depth, depth == TREE_DEPTH || p.masks[node as usize] == 0))
}
