//! A breadth-first copy of a large tree's navigation above depth 16, for
//! full-depth searches.
//!
//! A random point query on a large map is a chain of dependent cache
//! misses, one per level below the trunk grid. In the arena the nodes of
//! every level are spread over all of its `masks` and `first_child`
//! arrays (five bytes per inner node), so each level misses. Here the
//! nodes above depth 16 are laid out level by level, their masks eight to
//! a word with one `u32` per word saying where the word's first child lies
//! (the children of the nodes before it, counted): 1.5 bytes per inner
//! node, and a level's nodes side by side, so the upper levels stay in
//! cache. A voxel's value comes from a palette (one byte per voxel), the
//! arena's leaf pool at the voxel's rank, or the arena first child of its
//! depth-15 parent ([`Voxels`]).
//!
//! With a palette on a tree whose levels below depth 12 would not fit in
//! the second-level cache, those levels are kept apart: each depth-13
//! node's subtree is one run of bytes (about 45 on the largest bench map;
//! [`blocks`]), so that a search's last four steps read one or two cache
//! lines instead of missing in four arrays of megabytes each.
//!
//! Any change drops it with the trunks, so it is never stale, and the
//! first search after the trunks are derived again builds it. Answers
//! above depth 16 (pruned leaves) are left to the arena's descent.

use super::arena::{in_leaf_pool, leaf_index, NodeArena, NodeId, Parts, LEAF_POOL};
use super::blocks::{self, BlockEnd, Runs, SubtreeRuns, BLOCK_DEPTH};
use super::trunk::{Trunks, GRID_NODES_PER_CELL};
use super::ROOT;
use crate::key::{Key, TREE_DEPTH};
use crate::morton::MortonCode;
use std::sync::OnceLock;

/// Trees of fewer nodes get no index: their arena fits in the second-level
/// cache, where the index's longer steps would only cost time.
pub(crate) const LEVEL_INDEX_MIN_NODES: usize = 1 << 19;

/// Keys [`LevelIndex::search_lanes`] takes at a time.
pub(crate) const LANES: usize = 8;

/// The deepest level with inner nodes.
const LAST_INNER: u8 = TREE_DEPTH - 1;

/// Nodes at depths 13–15 from which a palette's index is laid out in
/// [`Voxels::Blocks`]: with fewer, their words (1.5 MB here) stay in the
/// second-level cache, and the blocks' counting costs more than the cached
/// levels (measured slower on the bench's indoor 0.05 m map, 0.2M nodes
/// there; faster outdoors at 0.1 m, 1.8M, and 0.05 m, 5.7M).
const BLOCKS_MIN_NODES: usize = 1 << 20;

#[derive(Clone, Debug)]
pub(crate) struct LevelIndex {
    /// Child masks of the nodes down to depth `last`, breadth-first, in
    /// each level by Morton code: node `i`'s is byte `i & 7` of word
    /// `i >> 3`.
    words: Vec<u64>,
    /// Per word: the index of the first child of its nodes (one plus the
    /// children of all nodes before it).
    first: Vec<u32>,
    /// Index of the first node at depth `last`.
    deepest: u32,
    /// The depth of the deepest nodes in `words`: 15, or [`BLOCK_DEPTH`]
    /// with `Voxels::Blocks`, whose nodes at that depth are in the blocks
    /// (their indices from `deepest` on number the blocks).
    last: u8,
    /// The nodes above depth 16: the children of the depth-15 ones are
    /// numbered on from here.
    nodes: u32,
    /// Where the voxels' values are.
    voxels: Voxels,
    /// Search starts, on index ids (voxels as [`Self::voxel`] takes them).
    trunks: Trunks<u32>,
}

/// How the index finds a voxel's value.
#[derive(Clone, Debug)]
enum Voxels {
    /// Per depth-15 node, from `deepest` on, the arena id of its first
    /// child (a leaf pool in the order the tree was built).
    FirstChild(Vec<NodeId>),
    /// The leaf pool holds the voxels in the index's numbering (after
    /// `compact()`, or in a tree read from a file): a voxel's arena id is
    /// its number.
    Ranked,
    /// Per voxel in the index's numbering, its value's place in `values`:
    /// a plain tree's voxels take few distinct values (16–246 on the bench
    /// maps), and one byte a voxel is a quarter of the leaf pool to miss
    /// in.
    Palette { codes: Vec<u8>, values: Vec<f32> },
    /// The depth-13 subtrees, their voxels' values through a palette: the
    /// layout for a palette when the levels below depth 12 would not fit
    /// in the second-level cache.
    Blocks { runs: Runs, values: Vec<f32> },
}

/// Where a search through the index ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Reach {
    /// The voxel, by arena id.
    Voxel(NodeId),
    /// The voxel's value (a plain tree's voxel: no extra).
    Value(f32),
    /// Unknown space: the path ends at an inner node lacking the child.
    Unknown,
    /// A leaf above depth 16, which the arena's descent finds.
    Coarse,
}

impl LevelIndex {
    /// The index of the arena's nodes (`size` of them, OctoMap's count).
    pub fn build(p: &Parts<'_>, size: usize) -> Self {
        Self::build_with(p, size, BLOCKS_MIN_NODES)
    }

    /// [`Self::build`], with blocks from `blocks_min` nodes at depths 13–15.
    fn build_with(p: &Parts<'_>, size: usize, blocks_min: usize) -> Self {
        let BreadthFirst { masks, starts, leaf_first } = BreadthFirst::of(p);
        let nodes = masks.len() as u32;
        let start = |depth: u8| starts[usize::from(depth)].min(masks.len());
        let (voxels, last) = Voxels::new(p, &masks, start, leaf_first, blocks_min);
        let deepest = start(last) as u32;
        // with blocks, the words end above them
        let in_words = if last == BLOCK_DEPTH { deepest as usize } else { masks.len() };
        let masks = &masks[..in_words];
        let mut words = Vec::with_capacity(masks.len().div_ceil(8));
        let mut first = Vec::with_capacity(words.capacity());
        let mut children = 1u32;
        for chunk in masks.chunks(8) {
            let mut bytes = [0u8; 8];
            bytes[..chunk.len()].copy_from_slice(chunk);
            let w = u64::from_le_bytes(bytes);
            words.push(w);
            first.push(children);
            children += crate::arch::count_ones(w);
        }
        let mut index = LevelIndex { words, first, deepest, last, nodes, voxels, trunks: Trunks::at_root(0) };
        let trunks = {
            // the grids stop at the blocks
            let (mask, child) = (|n| Some(index.mask(n)), |n, m, pos| index.word_child(n, m, pos));
            let trunks = Trunks::build(0, size / GRID_NODES_PER_CELL as usize, mask, child);
            trunks.prepare(mask, child);
            trunks
        };
        index.trunks = trunks;
        index
    }

    /// Heap bytes held.
    pub fn bytes(&self) -> usize {
        let voxels = match &self.voxels {
            Voxels::FirstChild(f) => 4 * f.capacity(),
            Voxels::Ranked => 0,
            Voxels::Palette { codes, values } => codes.capacity() + 4 * values.capacity(),
            Voxels::Blocks { runs, values } => {
                4 * runs.offsets.capacity() + runs.bytes.capacity() + 4 * values.capacity()
            }
        };
        8 * self.words.capacity() + 4 * self.first.capacity() + voxels + self.trunks.bytes()
    }

    #[inline(always)]
    fn mask(&self, n: u32) -> u8 {
        if in_leaf_pool(n) {
            return 0;
        }
        match &self.voxels {
            Voxels::Blocks { runs, .. } if n >= self.deepest => {
                runs.bytes[runs.offsets[(n - self.deepest) as usize] as usize]
            }
            _ => (self.words[(n >> 3) as usize] >> (8 * (n & 7))) as u8,
        }
    }

    /// [`Self::child`] of a node in `words` (`None` for one in a block,
    /// whose children have no index).
    #[inline(always)]
    fn word_child(&self, n: u32, m: u8, pos: usize) -> Option<u32> {
        (self.last != BLOCK_DEPTH || n < self.deepest).then(|| self.child(n, m, pos))
    }

    /// Child `pos` (present in `m`, `n`'s mask) of index node `n` (one in
    /// `words`).
    #[inline(always)]
    fn child(&self, n: u32, m: u8, pos: usize) -> u32 {
        if n >= self.deepest {
            if let Voxels::FirstChild(f) = &self.voxels {
                return f[(n - self.deepest) as usize] + crate::arch::count_ones(u32::from(m) & ((1 << pos) - 1));
            }
        }
        let w = (n >> 3) as usize;
        let bit = 8 * (n & 7) + pos as u32;
        let c = self.first[w] + crate::arch::count_ones(self.words[w] & ((1 << bit) - 1));
        if n >= self.deepest {
            LEAF_POOL | (c - self.nodes)
        } else {
            c
        }
    }

    /// Where a full-depth search for `key` (in root child `octant`)
    /// starts (the grids are built with the index, so the closures only
    /// look up).
    #[inline(always)]
    fn start(&self, key: Key, octant: usize) -> (u32, u8) {
        let (mask, child) = (|n| Some(self.mask(n)), |n, m, pos| Some(self.child(n, m, pos)));
        self.trunks.start_in(key.packed(), octant, TREE_DEPTH, mask, child)
    }

    /// Child `pos` of index node `i`, or where the path ends there.
    #[inline(always)]
    fn step(&self, i: u32, pos: usize) -> Result<u32, Reach> {
        let m = self.mask(i);
        if m & (1 << pos) == 0 {
            Err(ended(m))
        } else {
            Ok(self.child(i, m, pos))
        }
    }

    /// A full-depth search for `key` (Morton `code`).
    #[inline(always)]
    #[cfg(test)]
    pub fn search(&self, key: Key, code: u64) -> Reach {
        self.search_in(key, key.child_index(0), code)
    }

    /// A full-depth search given the key's root child.
    #[inline(always)]
    pub fn search_in(&self, key: Key, octant: usize, code: u64) -> Reach {
        let (mut i, from) = self.start(key, octant);
        if from == TREE_DEPTH {
            return self.voxel(i);
        }
        // one word and its first-child entry per level: the chain of
        // dependent steps is a load, a shift, a popcount and an add
        let mut positions = (code << (64 - 3 * u32::from(TREE_DEPTH))) << (3 * u32::from(from));
        for _ in from..self.last {
            let w = (i >> 3) as usize;
            let word = self.words[w];
            let bit = 8 * (i & 7) + (positions >> 61) as u32;
            positions <<= 3;
            if word & (1 << bit) == 0 {
                return ended((word >> (8 * (i & 7))) as u8);
            }
            i = self.first[w] + crate::arch::count_ones(word & ((1 << bit) - 1));
        }
        self.last_step(i, code)
    }

    /// The end of a search for `code` that has reached node `i` at depth
    /// `last`.
    #[inline(always)]
    fn last_step(&self, i: u32, code: u64) -> Reach {
        match &self.voxels {
            Voxels::Blocks { runs, values } => {
                find_in_run(runs, values, runs.offsets[(i - self.deepest) as usize] as usize, code)
            }
            _ => match self.step(i, (code & 7) as usize) {
                Ok(v) => self.voxel(v),
                Err(end) => end,
            },
        }
    }

    /// [`Self::search_in`] for up to [`LANES`] keys in lockstep, answers in
    /// `out`: each round steps every lane still walking one level, so the
    /// lanes' cache misses overlap (on the largest maps the processor does
    /// not overlap one search after another as well).
    pub fn search_lanes(&self, keys: &[Key], out: &mut [Reach; LANES]) {
        debug_assert!(keys.len() <= LANES);
        let mut node = [0u32; LANES];
        let mut depth = [0u8; LANES];
        let mut code = [0u64; LANES];
        let mut walking = 0u32;
        for (l, &key) in keys.iter().enumerate() {
            code[l] = MortonCode::encode_table(key).0;
            let (n, from) = self.start(key, key.child_index(0));
            if from == TREE_DEPTH {
                out[l] = self.voxel(n);
            } else {
                (node[l], depth[l]) = (n, from);
                walking |= 1 << l;
            }
        }
        while walking != 0 {
            let mut lanes = walking;
            while lanes != 0 {
                let l = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                if depth[l] >= self.last {
                    match &self.voxels {
                        // a round for the block's offset, one for the block,
                        // so that the lanes' misses on both overlap
                        Voxels::Blocks { runs, .. } if depth[l] == self.last => {
                            (node[l], depth[l]) = (runs.offsets[(node[l] - self.deepest) as usize], TREE_DEPTH);
                            continue;
                        }
                        Voxels::Blocks { runs, values } => {
                            out[l] = find_in_run(runs, values, node[l] as usize, code[l])
                        }
                        _ => out[l] = self.last_step(node[l], code[l]),
                    }
                    walking &= !(1 << l);
                    continue;
                }
                let pos = ((code[l] >> (3 * (LAST_INNER - depth[l]))) & 7) as usize;
                match self.step(node[l], pos) {
                    Ok(c) => (node[l], depth[l]) = (c, depth[l] + 1),
                    Err(end) => {
                        out[l] = end;
                        walking &= !(1 << l);
                    }
                }
            }
        }
    }

    /// The voxel numbered `v` (with [`LEAF_POOL`] set; never reached with
    /// blocks, which hold all voxels).
    #[inline(always)]
    fn voxel(&self, v: u32) -> Reach {
        match &self.voxels {
            Voxels::Palette { codes, values } => Reach::Value(values[usize::from(codes[leaf_index(v)])]),
            _ => {
                debug_assert!(!matches!(self.voxels, Voxels::Blocks { .. }));
                Reach::Voxel(v)
            }
        }
    }
}

impl Voxels {
    /// For the index's `masks` (breadth-first, depth `d`'s from `start(d)`
    /// on) and the depth-15 nodes' arena first children: a palette when the
    /// tree has no extras and at most 256 voxel values (in blocks from
    /// `blocks_min` nodes at depths 13–15 on), else the rank when
    /// the leaf pool is in the index's numbering, else the first children;
    /// and the depth where the words end.
    fn new(
        p: &Parts<'_>,
        masks: &[u8],
        start: impl Fn(u8) -> usize,
        mut leaf_first: Vec<NodeId>,
        blocks_min: usize,
    ) -> (Self, u8) {
        let deepest = &masks[start(LAST_INNER)..];
        // the depth-15 nodes' child groups in the leaf pool, in order
        let groups =
            || deepest.iter().zip(&leaf_first).map(|(&m, &f)| (leaf_index(f), crate::arch::count_ones(m) as usize));
        if p.extras.is_empty() && p.leaf_extras.is_empty() {
            let voxels = groups().map(|(_, k)| k).sum();
            if let Some((codes, values)) =
                Palette::of(groups().flat_map(|(first, k)| &p.leaf_values[first..first + k]), voxels)
            {
                if masks.len() - start(BLOCK_DEPTH) < blocks_min {
                    return (Voxels::Palette { codes, values }, LAST_INNER);
                }
                let level = |d: u8| &masks[start(d)..start(d + 1).max(start(d))];
                let runs =
                    Runs::build([level(BLOCK_DEPTH), level(BLOCK_DEPTH + 1), &masks[start(LAST_INNER)..]], &codes);
                return (Voxels::Blocks { runs, values }, BLOCK_DEPTH);
            }
        }
        let mut next = 0;
        if groups().all(|(first, k)| {
            let in_order = k == 0 || first == next;
            next += k;
            in_order
        }) {
            return (Voxels::Ranked, LAST_INNER);
        }
        leaf_first.shrink_to_fit();
        (Voxels::FirstChild(leaf_first), LAST_INNER)
    }
}

/// The rest of a search for `code` below the depth-13 node whose run
/// starts at `at` in `runs`, voxel values by palette code in `values`.
#[inline(always)]
fn find_in_run(runs: &Runs, values: &[f32], at: usize, code: u64) -> Reach {
    match blocks::walk(&runs.bytes, at, code) {
        Some(BlockEnd::Voxel(c)) => Reach::Value(values[usize::from(c)]),
        Some(BlockEnd::Unknown) => Reach::Unknown,
        // (the bytes never end early here: the arena's descent answers)
        Some(BlockEnd::Coarse) | None => Reach::Coarse,
    }
}

/// Where a path ends at a node with mask `m` that lacks the next child.
#[inline(always)]
fn ended(m: u8) -> Reach {
    if m == 0 {
        Reach::Coarse
    } else {
        Reach::Unknown
    }
}

/// The tree's depth-13 subtrees as [`blocks`] runs, for a tree with
/// `min_nodes` or more nodes at depths 13–15; `None` when its voxels carry
/// extras or take more than 256 values, or it has fewer nodes there.
pub(crate) fn subtree_runs(p: &Parts<'_>, min_nodes: usize) -> Option<SubtreeRuns> {
    let BreadthFirst { masks, starts, leaf_first } = BreadthFirst::of(p);
    let start = |depth: u8| starts[usize::from(depth)].min(masks.len());
    match Voxels::new(p, &masks, start, leaf_first, min_nodes).0 {
        Voxels::Blocks { runs, values } => Some(SubtreeRuns { first: start(BLOCK_DEPTH) as u32, values, runs }),
        _ => None,
    }
}

/// The arena's nodes above depth 16 in breadth-first order.
struct BreadthFirst {
    /// Their child masks, each level in Morton order.
    masks: Vec<u8>,
    /// Where each depth's nodes start in `masks` (`usize::MAX`: none).
    starts: [usize; TREE_DEPTH as usize],
    /// The depth-15 nodes' arena first children.
    leaf_first: Vec<NodeId>,
}

impl BreadthFirst {
    fn of(p: &Parts<'_>) -> Self {
        let mut b =
            BreadthFirst { masks: Vec::new(), starts: [usize::MAX; TREE_DEPTH as usize], leaf_first: Vec::new() };
        let (mut level, mut next) = (vec![ROOT], Vec::new());
        for depth in 0..=LAST_INNER {
            if level.is_empty() {
                break;
            }
            b.starts[usize::from(depth)] = b.masks.len();
            next.clear();
            for &n in &level {
                let m = p.masks[n as usize];
                b.masks.push(m);
                let first = p.first_child[n as usize];
                if depth == LAST_INNER {
                    b.leaf_first.push(first);
                } else {
                    next.extend((0..crate::arch::count_ones(m)).map(|k| first + k));
                }
            }
            std::mem::swap(&mut level, &mut next);
        }
        b
    }
}

/// Builds the palette of [`Voxels::Palette`] and [`Voxels::Blocks`]: an
/// open-addressed table of the values seen so far (a hash map per voxel
/// made the first search of a 16M-node tree take three times as long).
struct Palette {
    bits: [u32; Self::SLOTS],
    code: [u16; Self::SLOTS],
}

impl Palette {
    const SLOTS: usize = 1024;
    const EMPTY: u16 = u16::MAX;

    /// The codes of `voxels` values and the palette, `None` past 256
    /// distinct values.
    fn of<'a>(values: impl Iterator<Item = &'a f32>, voxels: usize) -> Option<(Vec<u8>, Vec<f32>)> {
        let mut t = Palette { bits: [0; Self::SLOTS], code: [Self::EMPTY; Self::SLOTS] };
        let mut distinct: Vec<f32> = Vec::new();
        let mut codes = Vec::with_capacity(voxels);
        let mut last: Option<(u32, u8)> = None;
        for v in values {
            let bits = v.to_bits();
            let code = match last {
                Some((b, c)) if b == bits => c,
                _ => {
                    let mut h = (bits.wrapping_mul(0x9E37_79B9) >> 22) as usize;
                    while t.code[h] != Self::EMPTY && t.bits[h] != bits {
                        h = (h + 1) % Self::SLOTS;
                    }
                    if t.code[h] == Self::EMPTY {
                        t.code[h] = u16::try_from(distinct.len()).ok().filter(|&c| c < 256)?;
                        t.bits[h] = bits;
                        distinct.push(*v);
                    }
                    let c = t.code[h] as u8;
                    last = Some((bits, c));
                    c
                }
            };
            codes.push(code);
        }
        Some((codes, distinct))
    }
}

/// The tree's index, if it has one: none while the tree is changing (after
/// any change until the trunks are derived again) or when it is small;
/// otherwise built by the first search that can use it.
#[derive(Clone, Debug, Default)]
pub(crate) struct LevelSlot(Option<OnceLock<LevelIndex>>);

impl LevelSlot {
    /// No index until [`Self::armed`].
    pub fn off() -> Self {
        LevelSlot(None)
    }

    /// An index built on demand, for a tree of `size` nodes.
    pub fn armed(size: usize) -> Self {
        LevelSlot((size >= LEVEL_INDEX_MIN_NODES).then(OnceLock::new))
    }

    #[inline(always)]
    pub fn get(&self, a: &NodeArena, size: usize) -> Option<&LevelIndex> {
        Some(self.0.as_ref()?.get_or_init(|| LevelIndex::build(&a.parts(), size)))
    }

    /// Whether full-depth searches go through an index.
    pub fn is_armed(&self) -> bool {
        self.0.is_some()
    }

    pub fn bytes(&self) -> usize {
        self.0.as_ref().and_then(OnceLock::get).map_or(0, LevelIndex::bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{InnerNodes, OccupancyTree};

    /// A tree with voxels in random order, pruned leaves at depths 13, 14
    /// and 15, and a full depth-13 subtree; keys on its voxels, beside them and far away.
    fn tree_and_keys(distinct_values: bool) -> (OccupancyTree, Vec<Key>) {
        let mut tree = OccupancyTree::new(0.1).unwrap();
        let mut s = 7u32;
        let mut rand = |n: u32| {
            s = s.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            (s >> 8) % n
        };
        let mut keys = Vec::new();
        for _ in 0..3000 {
            let c = |r: u32| (32600 + r) as u16;
            keys.push(Key([c(rand(300)), c(rand(300)), c(rand(60))]));
        }
        for (i, k) in keys.iter().enumerate() {
            if distinct_values {
                // more values than a palette holds
                tree.set_value(*k, i as f32 / 1024.0, InnerNodes::Update);
            } else {
                tree.update_occupancy(*k, i % 3 != 0, InnerNodes::Update);
            }
        }
        for i in 0..512u16 {
            let k = Key([32640 + (i & 7), 32648 + ((i >> 3) & 7), 32616 + (i >> 6)]);
            tree.set_value(k, 2.0, InnerNodes::Update);
        }
        for i in 0..8u16 {
            tree.set_value(Key([32900 + (i & 1), 32902 + ((i >> 1) & 1), 32604 + (i >> 2)]), -1.5, InnerNodes::Update);
        }
        // and a 4x4x4 one, a depth-14 leaf
        for i in 0..64u16 {
            tree.set_value(Key([32644 + (i & 3), 32652 + ((i >> 2) & 3), 32624 + (i >> 4)]), 1.25, InnerNodes::Update);
        }
        // a depth-13 node with all its 64 depth-15 nodes, half their voxels
        for i in 0..512u16 {
            let k = Key([32664 + (i & 7), 32672 + ((i >> 3) & 7), 32664 + (i >> 6)]);
            if k.0.iter().map(|&c| u32::from(c)).sum::<u32>() % 2 == 0 {
                tree.update_occupancy(k, i % 3 == 0, InnerNodes::Update);
            }
            keys.push(k);
        }
        tree.prune();
        let probes: Vec<Key> = keys.iter().map(|k| Key(k.0.map(|c| c + 1))).collect();
        keys.extend(probes);
        keys.extend([
            Key([32643, 32650, 32620]),
            Key([32645, 32653, 32625]),
            Key([32901, 32903, 32605]),
            Key([0, 0, 0]),
            Key([40000, 1, 65535]),
        ]);
        (tree, keys)
    }

    /// The index's answer is the arena descent's: the same voxel, unknown
    /// space where the arena finds nothing, a coarse leaf where it finds
    /// one above depth 16.
    fn agrees(tree: &OccupancyTree, keys: &[Key], blocks_min: usize) -> LevelIndex {
        let a = tree.arena().unwrap();
        let index = LevelIndex::build_with(&a.parts(), tree.size(), blocks_min);
        let mut reached = [0; 3];
        for &key in keys {
            let got = index.search(key, MortonCode::encode(key).0);
            let want = tree.search_id(key, 0);
            match (got, want) {
                (Reach::Voxel(id), Some((n, TREE_DEPTH, true))) => assert_eq!(id, n, "{key}"),
                (Reach::Value(v), Some((n, TREE_DEPTH, true))) => {
                    assert_eq!(v.to_bits(), a.value(n).to_bits(), "{key}")
                }
                (Reach::Unknown, None) => {}
                (Reach::Coarse, Some((_, d, true))) if d < TREE_DEPTH => {}
                _ => panic!("{key}: index {got:?}, arena {want:?}"),
            }
            reached[match got {
                Reach::Voxel(_) | Reach::Value(_) => 0,
                Reach::Unknown => 1,
                Reach::Coarse => 2,
            }] += 1;
        }
        assert!(reached.iter().all(|&n| n > 0), "{reached:?}");
        let mut lanes = [Reach::Unknown; LANES];
        for chunk in keys.chunks(LANES - 1) {
            index.search_lanes(chunk, &mut lanes);
            for (l, &key) in chunk.iter().enumerate() {
                assert_eq!(lanes[l], index.search(key, MortonCode::encode(key).0), "{key} in lanes");
            }
        }
        index
    }

    /// All four ways to a voxel's value: the palette and the blocks (a
    /// plain tree with few values, as built and compacted), the arena's
    /// first children (as built, many values) and the rank (compacted,
    /// many values).
    #[test]
    fn the_index_finds_what_the_arena_finds_as_built_and_compacted() {
        let kind = |index: &LevelIndex| match index.voxels {
            Voxels::FirstChild(_) => "first child",
            Voxels::Ranked => "rank",
            Voxels::Palette { .. } => "palette",
            Voxels::Blocks { .. } => "blocks",
        };
        for (distinct, blocks_min, as_built, compacted) in [
            (false, usize::MAX, "palette", "palette"),
            (false, 0, "blocks", "blocks"),
            (true, 0, "first child", "rank"),
        ] {
            let (mut tree, keys) = tree_and_keys(distinct);
            assert_eq!(kind(&agrees(&tree, &keys, blocks_min)), as_built);
            tree.compact();
            assert_eq!(kind(&agrees(&tree, &keys, blocks_min)), compacted);
        }
    }

    /// A tree large enough to get its index by itself: `search`,
    /// `search_many` and `SearchIndex` all answer as the arena does.
    #[test]
    fn a_large_tree_searches_through_its_index() {
        let mut tree = OccupancyTree::new(0.1).unwrap();
        let mut s = 3u64;
        let mut codes: Vec<u64> = (0..400_000)
            .map(|_| {
                s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                let c = |shift: u32| 32_000 + ((s >> shift) % 1_500) as u16;
                MortonCode::encode(Key([c(10), c(25), 32_700 + ((s >> 40) % 40) as u16])).0
            })
            .collect();
        codes.sort_unstable();
        codes.dedup();
        let (hits, misses) = codes.split_at(codes.len() / 3);
        tree.update_batch(hits, 0.85, InnerNodes::Update);
        tree.update_batch(misses, -0.4, InnerNodes::Update);
        assert!(tree.size() >= LEVEL_INDEX_MIN_NODES && tree.levels_armed(), "{} nodes", tree.size());
        assert_eq!((tree.levels.bytes(), tree.trunks.bytes()), (0, 0), "nothing built before a search");
        tree.prepare_search();
        assert!(tree.levels.bytes() > 0 && tree.trunks.bytes() > 0, "prepare_search builds both");
        let keys: Vec<Key> =
            codes.iter().step_by(7).map(|&c| MortonCode(c).decode()).chain(tree_and_keys(false).1).collect();
        let want: Vec<_> = keys.iter().map(|&k| tree.search_arena(k, 0)).collect();
        let got: Vec<_> = keys.iter().map(|&k| tree.search(k, 0)).collect();
        assert_eq!(got, want);
        let mut many = Vec::new();
        tree.search_many(&keys, 0, &mut many);
        assert_eq!(many, want);
        let index = crate::SearchIndex::new(&tree);
        assert!(keys.iter().zip(&want).all(|(&k, w)| index.search(k, 0) == *w));
        assert!(want.iter().any(Option::is_none) && want.iter().any(Option::is_some));
    }

    /// `OccupancyTree::search` through the index gives the arena's
    /// answers, values and all, and a change drops the index.
    #[test]
    fn search_through_the_index_matches_the_arena() {
        for distinct in [false, true] {
            let (mut tree, keys) = tree_and_keys(distinct);
            tree.prepare_search();
            assert_eq!(tree.levels.bytes(), 0, "a small tree gets no index");
            tree.levels = LevelSlot(Some(OnceLock::new()));
            for &k in &keys {
                assert_eq!(tree.search(k, 0), tree.search_arena(k, 0), "{k}");
            }
            assert!(tree.levels.bytes() > 0);
            tree.update_occupancy(keys[0], true, InnerNodes::Update);
            assert_eq!(tree.levels.bytes(), 0);
        }
    }
}
