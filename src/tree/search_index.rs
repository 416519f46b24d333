//! A level-skip index for read-heavy work: random point queries that start
//! below the root.
//!
//! A search walks 16 dependent levels, and on a large map each one can miss
//! the cache. [`SearchIndex`] hashes the nodes of a few depths `D`, `D - 3`,
//! `D - 6`, ... by their key prefix, so a query makes one probe (two or
//! three when its path ends above `D`, as in unknown space) and then walks
//! only the levels below the table that answered. The index borrows the
//! tree, so the borrow checker rules out the tree changing under it (node
//! ids move on structural changes). Answers are exactly
//! [`OccupancyTree::search`]'s. On trees large enough to have a level
//! index (`level_index.rs`) its one-at-a-time searches go through that
//! instead, which is faster than the tables.

use super::{descend_to, search_target, Found, NodeArena, NodeId, OccupancyTree, Parts, ROOT};
use crate::key::{adjust_key_to_depth, Key, TREE_DEPTH};
use crate::morton::MortonCode;

/// One hash slot: the key prefix plus one (0 = empty) and its node.
#[derive(Clone, Copy, Default)]
struct Slot<T> {
    tag: u64,
    node: T,
}

/// Multiplier of the Fibonacci hash over prefixes.
const HASH: u64 = 0x9E37_79B9_7F4A_7C15;

/// When the depth is chosen automatically, the deepest table holds at most
/// one entry per this many tree nodes (the tables then cost at most about
/// one byte per tree node) ...
const NODES_PER_ENTRY: usize = 32;

/// ... and at most this many entries, so that the tables stay in a core's
/// cache (256 KiB of slots): a table that misses the cache costs as much as
/// the levels it skips, which on a large map are cached anyway.
const MAX_ENTRIES: usize = 8192;

/// Depths between consecutive tables.
const TABLE_STEP: u8 = 3;

/// The nodes of one depth, hashed by key prefix (open addressing, linear
/// probing, at most half full).
struct Table<T> {
    depth: u8,
    /// `slots.len() - 1`; the length is a power of two.
    slot_mask: usize,
    /// `64 - log2(slots.len())`.
    hash_shift: u32,
    slots: Vec<Slot<T>>,
}

impl<T: Copy + Default> Table<T> {
    fn new(depth: u8, nodes: &[(Key, T)]) -> Table<T> {
        let cap = (nodes.len() * 2).next_power_of_two().max(8);
        let mut t = Table { depth, slot_mask: cap - 1, hash_shift: 64 - cap.trailing_zeros(), slots: Vec::new() };
        t.slots = vec![Slot::default(); cap];
        for &(key, node) in nodes {
            let prefix = prefix_at(key, depth);
            let mut h = t.home(prefix);
            while t.slots[h].tag != 0 {
                h = (h + 1) & t.slot_mask;
            }
            t.slots[h] = Slot { tag: prefix + 1, node };
        }
        t
    }

    #[inline(always)]
    fn home(&self, prefix: u64) -> usize {
        (prefix.wrapping_mul(HASH) >> self.hash_shift) as usize & self.slot_mask
    }

    /// The node at this table's depth on the path of `key`.
    #[inline(always)]
    fn lookup(&self, key: Key) -> Option<T> {
        let prefix = prefix_at(key, self.depth);
        let mut h = self.home(prefix);
        loop {
            let s = self.slots[h];
            if s.tag == prefix + 1 {
                return Some(s.node);
            }
            if s.tag == 0 {
                return None;
            }
            h = (h + 1) & self.slot_mask;
        }
    }
}

/// Hash tables of the nodes at depths `D`, `D - 3`, ... of any tree layout
/// (`T` is the layout's node handle); shared by [`SearchIndex`] and the
/// mapped view's index.
pub(crate) struct LevelTables<T> {
    /// Deepest first; empty when no depth qualifies.
    tables: Vec<Table<T>>,
}

impl<T: Copy + Default> LevelTables<T> {
    /// Tables over the tree below `root`, whose children `children` lists
    /// (child index, child). `depth` `None` chooses the deepest depth
    /// holding at most one node per 32 of `total_nodes` and at most 8192;
    /// `Some(d)` builds at `d` (0: no tables; above 15 counts as 15). The
    /// walk visits only the levels down to that depth. Tables at or above
    /// `trunk_depth` are left out: a search starts at least that deep from
    /// its trunk end, and in unknown space it would probe them in vain.
    pub fn build(
        root: Option<T>,
        total_nodes: u64,
        depth: Option<u8>,
        trunk_depth: u8,
        mut children: impl FnMut(T, &mut Vec<(usize, T)>),
    ) -> Self {
        let Some(root) = root else { return LevelTables { tables: Vec::new() } };
        let budget = usize::try_from(total_nodes / NODES_PER_ENTRY as u64).unwrap_or(usize::MAX).clamp(64, MAX_ENTRIES);
        let target = depth.map_or(TREE_DEPTH - 1, |d| d.min(TREE_DEPTH - 1));
        // levels 0..=deepest, breadth first, with their centre keys
        let mut levels: Vec<Vec<(Key, T)>> = vec![vec![(Key::ROOT, root)]];
        let mut kids = Vec::with_capacity(8);
        for d in 0..target {
            let mut next = Vec::new();
            for &(key, n) in &levels[d as usize] {
                kids.clear();
                children(n, &mut kids);
                next.extend(kids.iter().map(|&(pos, c)| (key.child_key(pos, d), c)));
            }
            if next.is_empty() || (depth.is_none() && next.len() > budget) {
                break;
            }
            levels.push(next);
        }
        let mut tables = Vec::new();
        let mut d = (levels.len() - 1) as u8;
        while d > trunk_depth {
            tables.push(Table::new(d, &levels[d as usize]));
            d = d.saturating_sub(TABLE_STEP);
        }
        LevelTables { tables }
    }

    /// The depth of the deepest table (0: none).
    pub fn depth(&self) -> u8 {
        self.tables.first().map_or(0, |t| t.depth)
    }

    /// Heap bytes of the tables.
    pub fn bytes(&self) -> usize {
        self.tables.iter().map(|t| t.slots.capacity() * std::mem::size_of::<Slot<T>>()).sum()
    }

    /// The deepest indexed node on the path of `key` at or above `depth`,
    /// with its depth; `None` when no table answers (start at the root).
    #[inline(always)]
    pub fn start(&self, key: Key, depth: u8) -> Option<(T, u8)> {
        for t in &self.tables {
            if t.depth <= depth {
                if let Some(n) = t.lookup(key) {
                    return Some((n, t.depth));
                }
            }
        }
        None
    }
}

/// A search accelerator over one tree; see the module documentation.
pub struct SearchIndex<'t> {
    tree: &'t OccupancyTree,
    tables: LevelTables<NodeId>,
}

impl<'t> SearchIndex<'t> {
    /// An index whose deepest table is at the deepest depth holding at most
    /// one node per 32 of the tree and at most 8192 nodes.
    pub fn new(tree: &'t OccupancyTree) -> Self {
        Self::build(tree, None)
    }

    /// An index with tables at `depth`, `depth - 3`, ... down to depth 1
    /// (none for depth 0; depths above 15 count as 15; a depth below which
    /// the tree has no nodes, the deepest level it has).
    pub fn at_depth(tree: &'t OccupancyTree, depth: u8) -> Self {
        Self::build(tree, Some(depth))
    }

    fn build(tree: &'t OccupancyTree, depth: Option<u8>) -> Self {
        let a = tree.arena();
        let trunk_depth = tree.trunks.shallowest_end();
        let tables = LevelTables::build(a.map(|_| ROOT), tree.size() as u64, depth, trunk_depth, |n, out| {
            if let Some(a) = a {
                out.extend(a.children(n));
            }
        });
        SearchIndex { tree, tables }
    }

    /// The depth of the deepest table (0: none).
    pub fn depth(&self) -> u8 {
        self.tables.depth()
    }

    /// Heap bytes of the tables.
    pub fn bytes(&self) -> usize {
        self.tables.bytes()
    }

    #[inline(always)]
    /// Where a search for `key` (Morton `code`, at `depth`) starts: the
    /// deepest table that answers, or else the trunk end.
    fn start(&self, p: &Parts<'_>, key: Key, depth: u8) -> (NodeId, u8) {
        self.tables.start(key, depth).unwrap_or_else(|| self.tree.start(p, key, depth))
    }

    /// `tree.search(key, depth)`: the descent of [`OccupancyTree::search`]
    /// from the deepest table that answers, or from the trunk end when none
    /// does (as in unknown space above the tables).
    #[inline]
    pub fn search(&self, key: Key, depth: u8) -> Option<Found> {
        let (key, depth) = search_target(key, depth);
        if depth == TREE_DEPTH && self.tree.levels_armed() {
            // a large tree's level index beats the tables
            return self.tree.search(key, depth);
        }
        let a = self.tree.arena()?;
        let code = MortonCode::encode_table(key).0;
        let p = a.parts();
        let (node, from) = self.start(&p, key, depth);
        let (node, depth, is_leaf) = descend_to(&p, node, from, depth, code)?;
        Some(found(a, node, depth, is_leaf))
    }

    /// [`Self::search`] for many keys, answers in `out` (cleared first) in
    /// the order of `keys`: eight queries advance in lockstep so that their
    /// cache misses overlap.
    pub fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>) {
        const LANES: usize = 8;
        out.clear();
        let Some(a) = self.tree.arena() else {
            out.resize(keys.len(), None);
            return;
        };
        let depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
        let p = a.parts();
        for chunk in keys.chunks(LANES) {
            let mut key = [Key::ROOT; LANES];
            let mut node = [ROOT; LANES];
            // lanes whose walk begins at each depth
            let mut begin = [0u32; TREE_DEPTH as usize + 1];
            for (l, q) in chunk.iter().enumerate() {
                key[l] = if depth == TREE_DEPTH { *q } else { adjust_key_to_depth(*q, depth) };
                let (n, from) = self.start(&p, key[l], depth);
                node[l] = n;
                begin[from as usize] |= 1 << l;
            }
            let mut answer: [Option<Found>; LANES] = [None; LANES];
            let mut walking = 0u32;
            for d in 0..depth {
                walking |= begin[d as usize];
                let mut lanes = walking;
                while lanes != 0 {
                    let l = lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    match a.child(node[l], key[l].child_index(d)) {
                        Some(c) => node[l] = c,
                        None => {
                            walking &= !(1 << l);
                            if !a.has_children(node[l]) {
                                answer[l] = Some(found(a, node[l], d, true));
                            }
                        }
                    }
                }
            }
            walking |= begin[depth as usize];
            while walking != 0 {
                let l = walking.trailing_zeros() as usize;
                walking &= walking - 1;
                answer[l] = Some(found(a, node[l], depth, !a.has_children(node[l])));
            }
            out.extend_from_slice(&answer[..chunk.len()]);
        }
    }
}

#[inline(always)]
fn found(a: &NodeArena, node: NodeId, depth: u8, is_leaf: bool) -> Found {
    Found { value: a.value(node), depth, is_leaf, extra: a.extra(node) }
}

/// The top `depth` bits of each coordinate of `key`, packed in 16-bit
/// fields: the identity of the key's node at `depth`.
#[inline(always)]
fn prefix_at(key: Key, depth: u8) -> u64 {
    let shift = TREE_DEPTH - depth;
    let [x, y, z] = key.0.map(|k| u64::from(k >> shift));
    x | (y << 16) | (z << 32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point3;

    fn sample_tree() -> OccupancyTree {
        let mut t = OccupancyTree::new(0.1).unwrap();
        let mut s = 12345u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s % 2000) as f32 / 100.0 - 10.0
        };
        for i in 0..4000 {
            let p = Point3::new(next(), next(), next() / 4.0);
            t.update_point(p, i % 3 != 0, crate::tree::InnerNodes::Update).unwrap();
        }
        t.prune();
        t
    }

    #[test]
    fn answers_equal_ordinary_search_at_every_index_depth() {
        let t = sample_tree();
        let keys: Vec<Key> = {
            let mut s = 99u64;
            (0..3000)
                .map(|i| {
                    s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    let r = (s >> 16) as u16;
                    if i % 2 == 0 {
                        // near the data: keys around the centre
                        Key([32768 - 100 + r % 200, 32768 - 100 + (r >> 4) % 200, 32768 - 30 + (r >> 8) % 60])
                    } else {
                        Key([r, r.rotate_left(5), r.rotate_left(11)])
                    }
                })
                .collect()
        };
        let mut out = Vec::new();
        for d in 0..=TREE_DEPTH {
            let index = SearchIndex::at_depth(&t, d);
            for depth in [0, 1, 5, 12, 15, 16] {
                let want: Vec<_> = keys.iter().map(|&k| t.search(k, depth)).collect();
                let got: Vec<_> = keys.iter().map(|&k| index.search(k, depth)).collect();
                assert_eq!(got, want, "index depth {d}, query depth {depth}");
                index.search_many(&keys, depth, &mut out);
                assert_eq!(out, want, "search_many, index depth {d}, query depth {depth}");
            }
        }
        let auto = SearchIndex::new(&t);
        assert!(auto.depth() > 0 && auto.bytes() > 0);
    }

    #[test]
    fn empty_tree_has_no_table() {
        let t = OccupancyTree::new(0.1).unwrap();
        let index = SearchIndex::new(&t);
        assert_eq!(index.depth(), 0);
        assert_eq!(index.search(Key([1, 2, 3]), 0), None);
    }
}
