//! Where a search can start instead of the root.
//!
//! A map covers a few hundred metres of a key space that spans 65,536
//! voxels per axis, around its centre: below each child of the root, the
//! first levels are a chain of nodes with one child each (the simulator's
//! indoor map at 0.2 m: 9 of its 16 levels). A search for a key inside that
//! chain's region passes exactly those nodes, so it may start at the
//! chain's end: one table look-up and a compare instead of ~9 dependent
//! loads. Any node would be a correct start for the keys under it; the
//! chain's end is the deepest one that covers all of its root child's
//! content. Used by the arena tree and the mapped view alike.

use crate::key::{Key, TREE_DEPTH};
use std::sync::OnceLock;

/// Per child of the root, the end of its chain of single-child nodes, and
/// below each end a grid of the next levels.
///
/// The grid replaces the first few steps below the trunk end by one load:
/// for every path of `levels` steps from the end (the key's bits of those
/// levels, axis by axis, give the cell) it holds the deepest node on that
/// path and its depth. Where a path ends early (unknown space, a coarse
/// leaf) the cell holds the node it ends at, so the descent from the cell
/// finds what the descent from the end would. The cell is found from the
/// key alone, without its Morton code, which keeps the encoding off a point
/// query's chain of dependent loads. The grids are built by the first
/// search that needs them, so work that only changes the tree (a scan
/// after another) never pays for them.
#[derive(Clone, Debug)]
pub(crate) struct Trunks<N> {
    root: N,
    /// The Morton code bits of the path to the end (the rest zero), its
    /// depth in the top byte.
    ends: [u64; 8],
    nodes: [N; 8],
    /// How many cells the grids may have in all.
    max_cells: usize,
    grids: OnceLock<Grids<N>>,
}

#[derive(Clone, Debug)]
struct Grids<N> {
    /// Levels each grid spans (0: no grids).
    levels: u8,
    /// Per child of the root, what [`Trunks::start`] needs of it in one
    /// place, tested on the key's bits rather than its Morton code.
    entries: [Entry; 8],
    /// A grid's key bits in a [`Key::packed`] key shifted down by the
    /// entry's `shift` (`levels` bits of each axis).
    field_mask: u64,
    /// Multiplier gathering those bits into a cell index at bit 32 (z
    /// lowest, x highest; the fields land apart, nothing carries).
    gather: u64,
    cell_mask: u64,
    cells: Vec<Cell<N>>,
}

/// A trunk as [`Trunks::start`] reads it. Keys are taken as one `u64`,
/// `x | y << 16 | z << 32`.
#[derive(Clone, Copy, Debug, Default)]
struct Entry {
    /// The key bits of the path to the trunk end, and which bits those are.
    prefix: u64,
    prefix_mask: u64,
    /// Where its grid starts in `cells` ([`NO_GRID`]: none).
    first: u32,
    /// The trunk end's depth ([`NO_TRUNK`] when the root lacks the child).
    end: u8,
    /// The depth of the grid's cells (end + levels).
    grid_depth: u8,
    /// Where the grid's key bits start (16 - grid_depth).
    shift: u8,
}

const NO_TRUNK: u8 = u8::MAX;

/// A grid cell: the deepest node on its path, and that node's depth.
#[derive(Clone, Copy, Debug, Default)]
struct Cell<N> {
    node: N,
    depth: u8,
}

/// Tree nodes per grid cell at most: the grids add at most a quarter of a
/// cell (2 bytes in the arena tree) per node.
pub(crate) const GRID_NODES_PER_CELL: u64 = 4;

const DEPTH_SHIFT: u32 = 56;
const NO_GRID: u32 = u32::MAX;
/// Levels a grid spans at most (4,096 cells).
const MAX_GRID_LEVELS: u8 = 4;

impl<N: Copy + Default> Trunks<N> {
    /// Every search starts at `root`.
    pub fn at_root(root: N) -> Self {
        Trunks { root, ends: [0; 8], nodes: [root; 8], max_cells: 0, grids: OnceLock::new() }
    }

    /// Makes every search start at the root again.
    pub fn reset(&mut self) {
        *self = Self::at_root(self.root);
    }

    /// Follows the chains below `root`, given a node's child mask and its
    /// child at a position; `None` from either (a corrupted mapped file)
    /// ends a chain where it is. The grids below the ends, built later, get
    /// at most `max_cells` cells in all.
    pub fn build(
        root: N,
        max_cells: usize,
        mask: impl Fn(N) -> Option<u8>,
        child: impl Fn(N, u8, usize) -> Option<N>,
    ) -> Self {
        let mut t = Self::at_root(root);
        t.max_cells = max_cells;
        let Some(root_mask) = mask(root) else { return t };
        for pos in 0..8 {
            let Some(mut node) = (root_mask & (1 << pos) != 0).then(|| child(root, root_mask, pos)).flatten() else {
                continue;
            };
            let (mut depth, mut prefix) = (1u8, (pos as u64) << (3 * (TREE_DEPTH - 1)));
            while depth < TREE_DEPTH {
                let Some(m) = mask(node).filter(|m| m.is_power_of_two()) else { break };
                let p = m.trailing_zeros() as usize;
                let Some(c) = child(node, m, p) else { break };
                prefix |= (p as u64) << (3 * (TREE_DEPTH - 1 - depth));
                (node, depth) = (c, depth + 1);
            }
            t.ends[pos] = prefix | (u64::from(depth) << DEPTH_SHIFT);
            t.nodes[pos] = node;
        }
        t
    }

    /// The grids below the trunk ends: as many levels as `max_cells` cells
    /// allow for all ends (up to [`MAX_GRID_LEVELS`], and not below depth
    /// 16).
    #[cold]
    fn build_grids(&self, mask: impl Fn(N) -> Option<u8>, child: impl Fn(N, u8, usize) -> Option<N>) -> Grids<N> {
        let ends: [u8; 8] = std::array::from_fn(|i| self.end_depth(i));
        let entries = std::array::from_fn(|i| match ends[i] {
            0 => Entry { first: NO_GRID, end: NO_TRUNK, ..Entry::default() },
            end => {
                // the Morton prefix's bits back on their axes
                let code = self.ends[i] & ((1 << DEPTH_SHIFT) - 1);
                let key = crate::morton::MortonCode(code).decode();
                let top = u64::from(u16::MAX << (TREE_DEPTH - end));
                let prefix_mask = top | (top << 16) | (top << 32);
                Entry { prefix: key.packed(), prefix_mask, first: NO_GRID, end, grid_depth: 0, shift: 0 }
            }
        });
        let mut g = Grids { levels: 0, entries, field_mask: 0, gather: 0, cell_mask: 0, cells: Vec::new() };
        // the root children whose trunk ends at least `k` levels above 16
        let gridded = |k: u8| -> Vec<usize> { (0..8).filter(|&i| ends[i] > 0 && ends[i] + k <= TREE_DEPTH).collect() };
        let Some(levels) = (1..=MAX_GRID_LEVELS).rev().find(|&k| {
            let n = gridded(k).len();
            n > 0 && n << (3 * k) <= self.max_cells
        }) else {
            return g;
        };
        let k = u32::from(levels);
        let m = (1u64 << k) - 1;
        g.field_mask = m | (m << 16) | (m << 32);
        g.gather = 1 | (1 << (16 + k)) | (1 << (32 + 2 * k));
        g.cell_mask = (1 << (3 * k)) - 1;
        // each grid's cells in Morton order, level by level
        let (mut level, mut next) = (Vec::new(), Vec::new());
        for i in gridded(levels) {
            let end = ends[i];
            level.clear();
            level.push(Cell { node: self.nodes[i], depth: end });
            for l in 0..levels {
                next.clear();
                for c in &level {
                    // a cell still on its path (at the level's depth) may
                    // step to a child; one whose path ended stays
                    let m = if c.depth == end + l { mask(c.node).unwrap_or(0) } else { 0 };
                    for pos in 0..8 {
                        let step = (m & (1 << pos) != 0).then(|| child(c.node, m, pos)).flatten();
                        next.push(step.map_or(*c, |node| Cell { node, depth: c.depth + 1 }));
                    }
                }
                std::mem::swap(&mut level, &mut next);
            }
            // stored by the key bits of the grid's levels, x, y, z apart
            let first = g.cells.len();
            let e = &mut g.entries[i];
            (e.first, e.grid_depth, e.shift) = (first as u32, end + levels, TREE_DEPTH - end - levels);
            g.cells.resize(first + level.len(), Cell::default());
            for (morton, c) in level.iter().enumerate() {
                let axis = |a: u32| (0..k).fold(0, |v, b| v | (((morton >> (3 * b + a)) & 1) << b));
                g.cells[first + (axis(2) | (axis(1) << k) | (axis(0) << (2 * k)))] = *c;
            }
        }
        g.levels = levels;
        g
    }

    fn end_depth(&self, i: usize) -> u8 {
        (self.ends[i] >> DEPTH_SHIFT) as u8
    }

    /// Builds the grids now if the first search has not (`mask` and
    /// `child` as for [`Self::start`]).
    pub fn prepare(&self, mask: impl Fn(N) -> Option<u8>, child: impl Fn(N, u8, usize) -> Option<N>) {
        self.grids.get_or_init(|| self.build_grids(mask, child));
    }

    /// Heap bytes of the grids (0 until a search has built them).
    pub fn bytes(&self) -> usize {
        self.grids.get().map_or(0, |g| g.cells.capacity() * std::mem::size_of::<Cell<N>>())
    }

    /// The depth of the shallowest chain end below the root (0 when the
    /// root has no children): every search for a key inside the chains'
    /// regions starts at least this deep.
    pub fn shallowest_end(&self) -> u8 {
        let present = self.ends.iter().map(|e| (e >> DEPTH_SHIFT) as u8).filter(|&d| d > 0);
        present.min().unwrap_or(0)
    }

    /// The node a search for `key` at `depth` can start from, and its
    /// depth: the cell of its trunk's grid, else the trunk end, else the
    /// root. `mask` and `child` (as for [`Self::build`]) build the grids
    /// when this is the first search. Kept to few instructions: on maps
    /// that fit the caches, fewer instructions a query let the processor
    /// overlap more consecutive queries.
    #[inline(always)]
    pub fn start(
        &self,
        key: Key,
        depth: u8,
        mask: impl Fn(N) -> Option<u8>,
        child: impl Fn(N, u8, usize) -> Option<N>,
    ) -> (N, u8) {
        self.start_in(key.packed(), key.child_index(0), depth, mask, child)
    }

    /// [`Self::start`] for a [`Key::packed`] key `k` and its root child
    /// `i` (its child index at depth 1), which a caller may have sooner
    /// than the key.
    #[inline(always)]
    pub fn start_in(
        &self,
        k: u64,
        i: usize,
        depth: u8,
        mask: impl Fn(N) -> Option<u8>,
        child: impl Fn(N, u8, usize) -> Option<N>,
    ) -> (N, u8) {
        let g = self.grids.get_or_init(|| self.build_grids(mask, child));
        let e = g.entries[i & 7];
        if (k ^ e.prefix) & e.prefix_mask != 0 || e.end > depth {
            return (self.root, 0);
        }
        if e.first == NO_GRID || e.grid_depth > depth {
            return (self.nodes[i & 7], e.end);
        }
        let cell = (((k >> e.shift) & g.field_mask).wrapping_mul(g.gather) >> 32) & g.cell_mask;
        let c = g.cells[e.first as usize + cell as usize];
        (c.node, c.depth)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;
    use crate::morton::MortonCode;
    use crate::OccupancyTree;

    /// A start is on the key's path, at most `depth` deep; with grids it is
    /// the deepest node on the path down to the grid's last level (or the
    /// trunk end when the search stops above that level). Keys inside,
    /// beside and far from the mapped region, at every depth, for trees
    /// without and with grids of 1 to 4 levels.
    #[test]
    fn starts_lie_on_the_path_and_grids_reach_its_deepest_node() {
        let mut tree = OccupancyTree::new(0.1).unwrap();
        let mut keys = Vec::new();
        let mut s = 11u32;
        let mut rand = |n: u32| {
            s = s.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            (s >> 8) % n
        };
        for _ in 0..400 {
            let c = |r: u32| (32700 + r) as u16;
            keys.push(Key([c(rand(140)), c(rand(140)), c(rand(140))]));
        }
        for k in &keys[..200] {
            tree.update_occupancy(*k, true, crate::InnerNodes::Update);
        }
        // a whole 8x8x8 block, which prunes to one depth-13 leaf
        for i in 0..512u16 {
            let k = Key([32800 + (i & 7), 32808 + ((i >> 3) & 7), 32816 + (i >> 6)]);
            tree.update_occupancy(k, true, crate::InnerNodes::Update);
            tree.update_occupancy(k, true, crate::InnerNodes::Update);
        }
        tree.prune();
        keys.extend([Key([32803, 32810, 32820]), Key([0, 0, 0]), Key([40000, 1, 65535]), Key([32767, 32767, 32767])]);
        let a = tree.arena().unwrap();
        let p = a.parts();
        let walk = |code: u64, levels: u8| {
            // the root's descent along `code`: the node at `levels`, or where it stops
            let (mut n, mut d) = (crate::tree::ROOT, 0);
            while d < levels {
                let Ok(c) = p.descend(n, MortonCode(code).child_index(d) as u64) else { break };
                (n, d) = (c, d + 1);
            }
            (n, d)
        };
        let mut grid_levels = Vec::new();
        for cells in [0, 64, 512, 4096, 1 << 20] {
            let t =
                Trunks::build(crate::tree::ROOT, cells, |n| Some(p.mask(n)), |n, _, pos| p.descend(n, pos as u64).ok());
            assert!(t.ends.iter().any(|e| e >> DEPTH_SHIFT > 8), "{t:?}");
            let (mask, child) = (|n| Some(p.mask(n)), |n, _, pos: usize| p.descend(n, pos as u64).ok());
            let g = t.grids.get_or_init(|| t.build_grids(mask, child));
            grid_levels.push(g.levels);
            let k = g.levels;
            for key in &keys {
                let code = MortonCode::encode(*key).0;
                let i = code as usize >> 45 & 7;
                for depth in 0..=TREE_DEPTH {
                    let (node, d) = t.start(*key, depth, mask, child);
                    assert!(d <= depth, "{key} depth {depth}");
                    assert_eq!(walk(code, d), (node, d), "{key} depth {depth}: not on the path");
                    let end = t.end_depth(i);
                    let on_trunk = end > 0 && walk(code, end).1 == end && t.nodes[i] == walk(code, end).0;
                    let want = if !on_trunk || end > depth {
                        0
                    } else if g.entries[i].first != NO_GRID && end + k <= depth {
                        walk(code, end + k).1
                    } else {
                        end
                    };
                    assert_eq!(d, want, "{key} depth {depth}, {k} grid levels");
                }
            }
        }
        assert_eq!(grid_levels, [0, 1, 2, 3, 4]);
    }
}
