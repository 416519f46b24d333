//! Whole-tree walks and what they measure: iteration entry points,
//! node counts, metric bounds and memory usage.

use super::TreeError;
use super::{default_extra, ArenaUsage, Bounds, BoundsRule, KeyBox, NodeArena, NodeId, NodeIter, NodeKind, NodeRef};
use super::{
    ChildGroup, OccupancyTree, PreorderNode, PreorderSource, PreorderVisitor, OCTOMAP_TREE_OBJECT_BYTES, ROOT,
};
use crate::key::{Key, KeySpace};
use crate::sensor::SensorModel;
use std::convert::Infallible;
use std::ops::ControlFlow;

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

    /// How many nodes at `depth` (1..=16; 0 means 16) lie below the leaves
    /// whose value satisfies `want`, coarser leaves counted as every node
    /// of `depth` inside them (`8^(depth - d)` for a leaf at depth `d`):
    /// the points of a point extraction at that depth. Saturates at
    /// `u64::MAX`; counted from the leaves, without expanding.
    pub fn voxel_count(&self, depth: u8, want: impl Fn(f32) -> bool) -> u64 {
        let depth = if depth == 0 { 16 } else { depth.min(16) };
        self.leaves(depth)
            .filter(|leaf| want(leaf.value))
            .map(|leaf| 1u64.checked_shl(3 * u32::from(depth - leaf.depth)).unwrap_or(u64::MAX))
            .fold(0u64, u64::saturating_add)
    }

    /// [`Self::voxel_count`] if it is at most `limit` ([`OUTPUT_LIMIT`](super::OUTPUT_LIMIT) is
    /// the usual limit), else [`TreeError::TooLarge`] naming `what` (the
    /// operation), the count and the limit: the check an operation that
    /// makes one point or record per voxel of coarse leaves runs first.
    pub fn voxels_within(
        &self,
        depth: u8,
        want: impl Fn(f32) -> bool,
        limit: u64,
        what: &'static str,
    ) -> Result<u64, TreeError> {
        let count = self.voxel_count(depth, want);
        if count > limit {
            return Err(TreeError::TooLarge { what, items: "points", count, limit });
        }
        Ok(count)
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

    /// Metric bounds of all leaves (zero for an empty tree): the extremes
    /// of their corners, each computed as OctoMap computes a leaf's. One
    /// descent per face of the box, trying the children on its side first
    /// and skipping a subtree whose own box lies more than a voxel inside
    /// the best bound found so far (the corners of the leaves below it,
    /// computed in doubles, differ from its box by far less than a voxel):
    /// a large map costs the nodes along the faces instead of every leaf.
    pub fn bounds(&self, rule: BoundsRule) -> Bounds {
        let Some(arena) = self.arena.as_ref() else {
            return Bounds { min: [0.0; 3], max: [0.0; 3] };
        };
        let mut b = Bounds { min: [f64::MAX; 3], max: [-f64::MAX; 3] };
        for axis in 0..3 {
            for upper in [false, true] {
                let face = Face { tree: self, arena, rule, axis, upper };
                let best = if upper { &mut b.max[axis] } else { &mut b.min[axis] };
                face.descend(ROOT, 0, 0, best);
            }
        }
        b
    }

    /// What [`Summarize`] gathers from a walk of this tree, from the arena:
    /// the counts by a recursion over the child masks, the bounds by
    /// [`Self::bounds`].
    pub fn summary(&self) -> TreeSummary {
        let mut s = TreeSummary::empty(self.kind, self.resolution());
        if let Some(a) = self.arena.as_ref() {
            count_summary(a, ROOT, 0, &self.sensor, &mut s);
            s.bounds = self.bounds(BoundsRule::CenterHalfSize);
        }
        s.finish()
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

/// One face of [`OccupancyTree::bounds`]: the lowest (or, `upper`, the
/// highest) leaf corner along `axis`.
struct Face<'a> {
    tree: &'a OccupancyTree,
    arena: &'a NodeArena,
    rule: BoundsRule,
    axis: usize,
    upper: bool,
}

impl Face<'_> {
    /// The node's extent along the axis, as OctoMap computes a leaf's:
    /// `key` is the key along the axis of any voxel below the node.
    fn extent(&self, key: u16, depth: u8) -> (f64, f64) {
        let keys = &self.tree.keys;
        let size = keys.node_size(depth);
        let c = keys.key_to_coord_at_depth(key, depth);
        let lo = c - size / 2.0;
        let hi = match self.rule {
            BoundsRule::CenterHalfSize => c + size / 2.0,
            BoundsRule::MinPlusSize => lo + size,
        };
        (lo, hi)
    }

    /// Moves `best` out to the leaves below `n` (at `depth`, with `key`
    /// along the axis, lower bits zero).
    fn descend(&self, n: NodeId, depth: u8, key: u16, best: &mut f64) {
        let (lo, hi) = self.extent(key, depth);
        let a = self.arena;
        if !a.has_children(n) {
            if self.upper && hi > *best {
                *best = hi;
            } else if !self.upper && lo < *best {
                *best = lo;
            }
            return;
        }
        let margin = self.tree.resolution();
        if (self.upper && hi + margin < *best) || (!self.upper && lo - margin > *best) {
            return;
        }
        let (mask, first) = (a.mask(n), a.first_child(n));
        // the children on the face's side first
        for side in [u8::from(!self.upper), u8::from(self.upper)] {
            let bit = 1u8 << self.axis;
            for pos in (0..8u8).filter(|&pos| mask & (1 << pos) != 0 && ((pos & bit) != 0) == (side == 1)) {
                let child = first + crate::arch::count_ones(u32::from(mask) & ((1 << pos) - 1));
                let key = key | (u16::from(side) << (15 - depth));
                self.descend(child, depth + 1, key, best);
            }
        }
    }
}

/// Adds the node counts of the subtree of `n` (at `depth`) to `s`.
fn count_summary(a: &NodeArena, n: NodeId, depth: u8, sensor: &SensorModel, s: &mut TreeSummary) {
    s.nodes += 1;
    s.at_threshold += u64::from(sensor.is_at_threshold(a.value(n)));
    if !a.has_children(n) {
        s.add_leaf(depth);
        return;
    }
    let first = a.first_child(n);
    for i in 0..crate::arch::count_ones(a.mask(n)) {
        count_summary(a, first + i, depth + 1, sensor, s);
    }
}

fn count_leaves(a: &NodeArena, n: NodeId) -> usize {
    if !a.has_children(n) {
        return 1;
    }
    let first = a.first_child(n);
    (0..crate::arch::count_ones(a.mask(n))).map(|i| count_leaves(a, first + i)).sum()
}

/// What `graph2tree` reports of a tree (node and leaf counts, nodes at a
/// clamping bound, metric bounds, memory), gathered from a pre-order walk
/// ([`Summarize`]) or from `.bt` records, so that a map written without
/// ever being one tree (a tiled map) reports what that tree would.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeSummary {
    /// Nodes (`size()`).
    pub nodes: u64,
    /// Leaves (`getNumLeafNodes`).
    pub leaves: u64,
    /// Nodes whose value is at a clamping bound (`isNodeAtThreshold`).
    pub at_threshold: u64,
    /// Leaves at depth 16 (voxels).
    pub voxels: u64,
    /// [`OccupancyTree::bounds`] by [`BoundsRule::CenterHalfSize`].
    pub bounds: Bounds,
    kind: NodeKind,
    resolution: f64,
}

impl TreeSummary {
    /// An empty tree's, to be filled leaf by leaf.
    pub(crate) fn empty(kind: NodeKind, resolution: f64) -> Self {
        let bounds = Bounds { min: [f64::MAX; 3], max: [-f64::MAX; 3] };
        TreeSummary { nodes: 0, leaves: 0, at_threshold: 0, voxels: 0, bounds, kind, resolution }
    }

    /// Counts a leaf at `depth` (the node itself is counted by the caller;
    /// its bounds by [`LeafExtremes`]).
    #[inline(always)]
    pub(crate) fn add_leaf(&mut self, depth: u8) {
        self.leaves += 1;
        self.voxels += u64::from(depth == 16);
    }

    /// Done: an empty tree's bounds are zero, as [`OccupancyTree::bounds`] says.
    pub(crate) fn finish(mut self) -> Self {
        if self.nodes == 0 {
            self.bounds = Bounds { min: [0.0; 3], max: [0.0; 3] };
        }
        self
    }

    /// [`OccupancyTree::octomap_memory_usage`] of the tree.
    pub fn octomap_memory_usage(&self) -> usize {
        let inner = (self.nodes - self.leaves) as usize;
        OCTOMAP_TREE_OBJECT_BYTES + 16 * self.nodes as usize + 64 * inner
    }

    /// [`OccupancyTree::memory_usage`] of the tree once compacted
    /// ([`OccupancyTree::compact`]): voxels in the leaf pool, every other
    /// node in the inner pool, no spare slots.
    pub fn compacted_memory_usage(&self) -> usize {
        let object = std::mem::size_of::<OccupancyTree>();
        if self.nodes == 0 {
            return object;
        }
        let extra = if default_extra(self.kind).is_some() { 4 } else { 0 };
        let inner = (self.nodes - self.voxels) as usize;
        object + inner * (4 + 1 + 4 + extra) + self.voxels as usize * (4 + extra)
    }

    /// [`OccupancyTree::memory_full_grid`] by [`BoundsRule::CenterHalfSize`].
    pub fn memory_full_grid(&self) -> u64 {
        if self.nodes == 0 {
            return 0;
        }
        let (s, r) = (self.bounds.size(), self.resolution);
        ((s[0] / r) * (s[1] / r) * (s[2] / r) * 4.0) as u64
    }
}

/// The leaves' bounds from the lowest and highest key along each axis
/// among the leaves of each depth: at one depth a leaf's corner
/// coordinate grows with its key (every operation computing it is
/// monotone), so those keys' corners are the extremes, computed once per
/// depth at the end instead of in doubles for every leaf.
#[derive(Clone, Copy)]
pub(crate) struct LeafExtremes {
    /// Per depth, lowest and highest key (`u16::MAX` and zero where there
    /// are no leaves), in four lanes: updated as whole words, a leaf's
    /// loads never straddle an earlier leaf's stores (with three, a store
    /// forward failed at every leaf).
    keys: [([u16; 4], [u16; 4]); 17],
}

impl LeafExtremes {
    /// No leaves yet.
    pub(crate) fn new() -> Self {
        LeafExtremes { keys: [([u16::MAX; 4], [0; 4]); 17] }
    }

    /// Adds the leaf at `depth` whose key is `key` (the bits below the
    /// node zero, the fourth lane anything).
    #[inline(always)]
    pub(crate) fn add(&mut self, key: [u16; 4], depth: u8) {
        let (lo, hi) = &mut self.keys[usize::from(depth)];
        *lo = std::array::from_fn(|i| lo[i].min(key[i]));
        *hi = std::array::from_fn(|i| hi[i].max(key[i]));
    }

    /// Widens `bounds` to the leaves' corners ([`BoundsRule::CenterHalfSize`]).
    pub(crate) fn widen(&self, keys: &KeySpace, bounds: &mut Bounds) {
        for (depth, (lo, hi)) in (0u8..).zip(self.keys) {
            if lo[0] > hi[0] {
                continue;
            }
            let half = keys.node_size(depth) / 2.0;
            for axis in 0..3 {
                bounds.min[axis] = bounds.min[axis].min(keys.key_to_coord_at_depth(lo[axis], depth) - half);
                bounds.max[axis] = bounds.max[axis].max(keys.key_to_coord_at_depth(hi[axis], depth) + half);
            }
        }
    }
}

/// The key of child `pos` (0..8) at `depth` of the node whose key is
/// `parent`.
#[inline(always)]
pub(crate) fn child_key(parent: [u16; 4], pos: u32, depth: u8) -> [u16; 4] {
    debug_assert!(pos < 8 && (1..=16).contains(&depth));
    std::array::from_fn(|axis| parent[axis] | (((pos >> axis) & 1) as u16) << (16 - depth))
}

/// Gathers a [`TreeSummary`] as a visitor of a pre-order walk (alone, or
/// beside a writer through [`super::Tee`]).
pub struct Summarize {
    keys: KeySpace,
    sensor: SensorModel,
    summary: TreeSummary,
    /// Key of the open node at each depth of the walk's path (the bits
    /// below the node zero).
    path: [[u16; 4]; 17],
    /// Children of the open node at each depth not reached yet.
    rest: [u8; 17],
    extremes: LeafExtremes,
}

impl Summarize {
    /// Ready for a walk of `map` from its root.
    pub fn new(map: &impl PreorderSource) -> Self {
        Summarize {
            keys: KeySpace::new(map.resolution()),
            sensor: *map.sensor(),
            summary: TreeSummary::empty(map.node_kind(), map.resolution()),
            path: [[0; 4]; 17],
            rest: [0; 17],
            extremes: LeafExtremes::new(),
        }
    }

    /// The summary of the nodes walked.
    pub fn finish(mut self) -> TreeSummary {
        self.extremes.widen(&self.keys, &mut self.summary.bounds);
        self.summary.finish()
    }

    /// Counts `node` and returns its key.
    #[inline(always)]
    fn reach(&mut self, node: &PreorderNode) -> [u16; 4] {
        self.summary.nodes += 1;
        self.summary.at_threshold += u64::from(self.sensor.is_at_threshold(node.value));
        let d = usize::from(node.depth);
        if d == 0 {
            return [0; 4];
        }
        let pos = self.rest[d - 1].trailing_zeros();
        self.rest[d - 1] &= self.rest[d - 1].wrapping_sub(1);
        child_key(self.path[d - 1], pos, node.depth)
    }
}

impl PreorderVisitor for Summarize {
    type Break = Infallible;

    fn enter(&mut self, node: &PreorderNode, children: &ChildGroup<'_>) -> ControlFlow<Infallible> {
        let key = self.reach(node);
        let d = usize::from(node.depth);
        (self.path[d], self.rest[d]) = (key, children.mask());
        ControlFlow::Continue(())
    }

    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<Infallible> {
        let key = self.reach(node);
        self.summary.add_leaf(node.depth);
        self.extremes.add(key, node.depth);
        ControlFlow::Continue(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point3;
    use crate::{InnerNodes, ScanOptions};

    /// [`OccupancyTree::bounds`] as every leaf's corners give it.
    fn bounds_of_every_leaf(tree: &OccupancyTree, rule: BoundsRule) -> Bounds {
        let mut b = Bounds { min: [f64::MAX; 3], max: [-f64::MAX; 3] };
        for leaf in tree.leaves(0) {
            let size = tree.keys.node_size(leaf.depth);
            for axis in 0..3 {
                let c = tree.keys.key_to_coord_at_depth(leaf.key.0[axis], leaf.depth);
                let lo = c - size / 2.0;
                let hi = if rule == BoundsRule::CenterHalfSize { c + size / 2.0 } else { lo + size };
                b.min[axis] = b.min[axis].min(lo);
                b.max[axis] = b.max[axis].max(hi);
            }
        }
        b
    }

    /// [`OccupancyTree::summary`] is what a [`Summarize`] walk gathers, to
    /// the bit: trees at several resolutions, as built and in maximum
    /// likelihood pruned (leaves above depth 16), a colour tree, a single
    /// voxel and an empty tree.
    #[test]
    fn summary_is_the_walks() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph");
        let graph = crate::formats::graph::read_file(path).unwrap();
        let mut trees = Vec::new();
        for (res, kind) in [(0.05, NodeKind::Plain), (0.2, NodeKind::Color), (1.0, NodeKind::Plain)] {
            let mut t = OccupancyTree::with_kind(res, SensorModel::default(), kind).unwrap();
            for node in &graph.nodes[..3] {
                let (cloud, origin) = node.graph2tree();
                t.insert_point_cloud(&cloud.points, origin, &ScanOptions::default()).unwrap();
            }
            let mut ml = t.clone();
            ml.to_max_likelihood();
            ml.prune();
            trees.extend([t, ml]);
        }
        let mut one = OccupancyTree::new(0.1).unwrap();
        one.update_point(Point3::new(-3.0, 2.0, 0.5), true, InnerNodes::Update).unwrap();
        trees.extend([one, OccupancyTree::new(0.1).unwrap()]);
        let fields = |s: TreeSummary| {
            let bounds = [s.bounds.min, s.bounds.max].map(|v| v.map(f64::to_bits));
            (s.nodes, s.leaves, s.at_threshold, s.voxels, bounds, s.kind, s.resolution.to_bits())
        };
        for t in &trees {
            let mut walk = Summarize::new(t);
            assert!(PreorderSource::visit_preorder(t, &mut walk).is_ok());
            let want = walk.finish();
            assert_eq!(fields(t.summary()), fields(want), "res {}, {} nodes", t.resolution(), t.size());
        }
        assert!(trees.iter().any(|t| t.summary().at_threshold > 0 && t.summary().voxels < t.summary().leaves));
    }

    /// The descents along the faces give every leaf's bounds to the bit:
    /// scans at several resolutions (leaves at depth 16 and pruned ones
    /// above), a single voxel, and eight leaves just below the root.
    #[test]
    fn bounds_are_those_of_every_leaf() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph");
        let graph = crate::formats::graph::read_file(path).unwrap();
        let mut trees = Vec::new();
        for res in [0.05, 0.2, 1.0, 3.7] {
            let mut t = OccupancyTree::new(res).unwrap();
            for node in &graph.nodes[..3] {
                let (cloud, origin) = node.graph2tree();
                t.insert_point_cloud(&cloud.points, origin, &ScanOptions::default()).unwrap();
            }
            trees.push(t);
        }
        let mut one = OccupancyTree::new(0.1).unwrap();
        one.update_point(Point3::new(-3.0, 2.0, 0.5), true, InnerNodes::Update).unwrap();
        trees.push(one);
        let mut bt = b"# Octomap OcTree binary file\n#\n#\nid OcTree\nsize 9\nres 0.1\ndata\n".to_vec();
        bt.extend([0x55, 0x55]); // the root's eight children: free leaves
        trees.push(crate::formats::bt::read(&bt[..]).unwrap());
        for t in &trees {
            assert!(t.num_leaves() > 0);
            for rule in [BoundsRule::CenterHalfSize, BoundsRule::MinPlusSize] {
                let (got, want) = (t.bounds(rule), bounds_of_every_leaf(t, rule));
                let bits = |b: Bounds| [b.min, b.max].map(|v| v.map(f64::to_bits));
                assert_eq!(bits(got), bits(want), "{rule:?}, res {}", t.resolution());
            }
        }
    }
}
