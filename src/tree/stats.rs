//! Whole-tree walks and what they measure: iteration entry points,
//! node counts, metric bounds and memory usage.

use super::{ArenaUsage, Bounds, BoundsRule, KeyBox, NodeArena, NodeId, NodeIter, NodeRef, OccupancyTree};
use super::{OCTOMAP_TREE_OBJECT_BYTES, ROOT};
use crate::key::Key;

impl OccupancyTree {
    /// A cursor on the root, `None` for an empty tree.
    pub fn root(&self) -> Option<NodeRef<'_>> {
        self.arena.as_ref().map(|arena| NodeRef { arena, id: ROOT })
    }

    /// The value of the root (OctoMap keeps it as the max of everything).
    pub fn root_value(&self) -> Option<f32> {
        self.arena.as_ref().map(|a| a.value(ROOT))
    }

    /// Whether a log-odds value counts as occupied under this tree's
    /// sensor model (`isNodeOccupied`).
    pub fn is_occupied(&self, value: f32) -> bool {
        self.sensor.is_occupied(value)
    }

    /// Every node, depth first with children 0..7 (`begin_tree(max_depth)`);
    /// `max_depth` 0 means 16.
    pub fn nodes(&self, max_depth: u8) -> NodeIter<'_> {
        NodeIter::new(self, max_depth, false, None)
    }

    /// Every leaf (and every node at `max_depth`), in OctoMap's order.
    pub fn leaves(&self, max_depth: u8) -> NodeIter<'_> {
        NodeIter::new(self, max_depth, true, None)
    }

    /// Leaves overlapping the key box, as OctoMap's `leaf_bbx_iterator`.
    pub fn leaves_in_box(&self, bbx: KeyBox, max_depth: u8) -> NodeIter<'_> {
        NodeIter::new(self, max_depth, true, Some(bbx))
    }

    /// Number of leaves (`getNumLeafNodes`).
    pub fn num_leaves(&self) -> usize {
        self.arena.as_ref().map_or(0, |a| count_leaves(a, ROOT))
    }

    /// Number of nodes reachable from the root (`calcNumNodes`).
    pub fn calc_num_nodes(&self) -> usize {
        fn count(a: &NodeArena, n: NodeId) -> usize {
            let first = a.first_child(n);
            1 + (0..crate::arch::count_ones(a.mask(n))).map(|i| count(a, first + i)).sum::<usize>()
        }
        self.arena.as_ref().map_or(0, |a| count(a, ROOT))
    }

    /// Metric bounds of all leaves (zero for an empty tree).
    pub fn bounds(&self, rule: BoundsRule) -> Bounds {
        if self.arena.is_none() {
            return Bounds { min: [0.0; 3], max: [0.0; 3] };
        }
        let mut b = Bounds { min: [f64::MAX; 3], max: [-f64::MAX; 3] };
        for leaf in self.leaves(0) {
            let size = self.keys.node_size(leaf.depth);
            let half = size / 2.0;
            for axis in 0..3 {
                let c = self.keys.key_to_coord_at_depth(leaf.key.0[axis], leaf.depth);
                let lo = c - half;
                let hi = match rule {
                    BoundsRule::CenterHalfSize => c + half,
                    BoundsRule::MinPlusSize => lo + size,
                };
                if lo < b.min[axis] {
                    b.min[axis] = lo;
                }
                if hi > b.max[axis] {
                    b.max[axis] = hi;
                }
            }
        }
        b
    }

    /// OctoMap's `volume()`: product of the (non-const) metric sizes.
    pub fn volume(&self) -> f64 {
        let s = self.bounds(BoundsRule::MinPlusSize).size();
        s[0] * s[1] * s[2]
    }

    /// OctoMap's `memoryFullGrid()`: bytes of a dense float grid over the
    /// bounds (OctoMap uses its const bounds, [`BoundsRule::CenterHalfSize`],
    /// unless its extent cache is filled).
    pub fn memory_full_grid(&self, rule: BoundsRule) -> u64 {
        if self.arena.is_none() {
            return 0;
        }
        let s = self.bounds(rule).size();
        let r = self.resolution();
        ((s[0] / r) * (s[1] / r) * (s[2] / r) * 4.0) as u64
    }

    /// What OctoMap's `memoryUsage()` reports for this tree on x86-64.
    pub fn octomap_memory_usage(&self) -> usize {
        let leaves = self.num_leaves();
        let inner = self.size.saturating_sub(leaves);
        OCTOMAP_TREE_OBJECT_BYTES + 16 * self.size + 64 * inner
    }

    /// Bytes this tree really holds: the arena's reserved capacity plus
    /// the tree object and change-detection map.
    pub fn memory_usage(&self) -> usize {
        let arena = self.arena.as_ref().map_or(0, |a| a.usage().bytes_reserved);
        let changes = self.changes.as_ref().map_or(0, |c| c.capacity() * (std::mem::size_of::<(Key, bool)>() + 1));
        std::mem::size_of::<Self>() + arena + changes + self.trunks.bytes() + self.levels.bytes()
    }

    /// Slot statistics of the arena.
    pub fn arena_usage(&self) -> Option<ArenaUsage> {
        self.arena.as_ref().map(|a| a.usage())
    }
}

fn count_leaves(a: &NodeArena, n: NodeId) -> usize {
    if !a.has_children(n) {
        return 1;
    }
    let first = a.first_child(n);
    (0..crate::arch::count_ones(a.mask(n))).map(|i| count_leaves(a, first + i)).sum()
}
