//! Structural access for the file formats: the read-only [`NodeRef`]
//! cursor, [`NodeRef::visit_preorder`], which walks a subtree in
//! depth-first pre-order for the writers, and [`PreorderBuilder`], which
//! builds a tree from nodes given in that order.

use super::arena::{in_leaf_pool, leaf_index, Parts, PreorderFill};
use super::{default_extra, NodeArena, NodeId, NodeKind, OccupancyTree, TreeError};
use crate::sensor::SensorModel;
use std::convert::Infallible;
use std::io;
use std::ops::ControlFlow;

/// A read-only cursor on a node, for structural walks (writers of other
/// formats, comparisons). Valid while the tree is borrowed.
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    pub(super) arena: &'a NodeArena,
    pub(super) id: NodeId,
}

impl<'a> NodeRef<'a> {
    /// Walks this node's subtree in depth-first pre-order (children 0..7),
    /// the order of OctoMap's files: `visitor` is told of each node with
    /// children before its subtree and again after it, and of each node
    /// without children. Depths count from this node (0; so they are the
    /// tree's depths when this is the root). The walk stops at the first
    /// [`ControlFlow::Break`] and returns it.
    ///
    /// This is how the file formats write trees: the walk reads each child
    /// group once, straight from the node arrays, and asks for the cache
    /// lines of the groups it will visit next, so it runs as fast as a
    /// hand-written recursion over the arena.
    pub fn visit_preorder<V: PreorderVisitor>(&self, visitor: &mut V) -> ControlFlow<V::Break> {
        let parts = self.arena.parts();
        let mask = parts.mask(self.id);
        let node =
            PreorderNode { depth: 0, child_mask: mask, value: parts.value(self.id), extra: parts.extra(self.id) };
        if mask == 0 {
            return visitor.leaf(&node);
        }
        visit_subtree(&parts, self.id, &node, visitor)
    }

    /// The log-odds value.
    #[inline]
    pub fn value(&self) -> f32 {
        self.arena.value(self.id)
    }

    /// Colour or stamp, by the tree's [`NodeKind`] (0 for plain trees).
    #[inline]
    pub fn extra(&self) -> u32 {
        self.arena.extra(self.id)
    }

    /// Bit `i` set when child `i` exists.
    #[inline]
    pub fn child_mask(&self) -> u8 {
        self.arena.mask(self.id)
    }

    /// True when the node has at least one child.
    #[inline]
    pub fn has_children(&self) -> bool {
        self.arena.has_children(self.id)
    }

    /// Child `pos` (0..8, x = 1, y = 2, z = 4), if it exists.
    #[inline]
    pub fn child(&self, pos: usize) -> Option<NodeRef<'a>> {
        self.arena.child(self.id, pos).map(|id| NodeRef { arena: self.arena, id })
    }

    /// Number of existing children.
    #[inline]
    pub fn child_count(&self) -> u32 {
        crate::arch::count_ones(self.arena.mask(self.id))
    }

    /// The `rank`-th existing child (0-based, in child order).
    #[inline]
    pub fn nth_child(&self, rank: u32) -> Option<NodeRef<'a>> {
        (rank < self.child_count()).then(|| NodeRef { arena: self.arena, id: self.arena.first_child(self.id) + rank })
    }

    /// Existing children with their index, in child order.
    pub fn children(&self) -> impl Iterator<Item = (usize, NodeRef<'a>)> + 'a {
        let arena = self.arena;
        arena.children(self.id).map(move |(i, id)| (i, NodeRef { arena, id }))
    }
}

/// One node as [`NodeRef::visit_preorder`] reaches it: what an `.ot`
/// record holds, and where the node lies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreorderNode {
    /// Depth below the walk's start (0 for the start itself).
    pub depth: u8,
    /// Bit `i` set when child `i` exists (0 for a leaf).
    pub child_mask: u8,
    /// The log-odds value.
    pub value: f32,
    /// Colour or stamp, by the tree's [`NodeKind`] (0 for plain trees).
    pub extra: u32,
}

/// The children of a node with children, in child order, as
/// [`PreorderVisitor::enter`] gets them: their masks, values and extras
/// side by side, so a writer that labels a node by its children (the
/// `.bt` formats) reads them in one pass.
#[derive(Clone, Copy, Debug)]
pub struct ChildGroup<'a> {
    mask: u8,
    masks: &'a [u8],
    values: &'a [f32],
    extras: &'a [u32],
}

/// Child masks of a group of voxels, which never have children.
const NO_MASKS: [u8; 8] = [0; 8];
/// Extras of a group in a tree without extras.
const NO_EXTRAS: [u32; 8] = [0; 8];

impl<'a> ChildGroup<'a> {
    /// A group of `masks.len()` children (one per bit of `mask`, side by
    /// side in child order), for walks that do not come from an arena.
    pub(crate) fn new(mask: u8, masks: &'a [u8], values: &'a [f32], extras: &'a [u32]) -> Self {
        debug_assert!(masks.len() == mask.count_ones() as usize && values.len() == masks.len());
        debug_assert_eq!(extras.len(), masks.len());
        ChildGroup { mask, masks, values, extras }
    }

    /// The parent's child mask: bit `i` set when child `i` exists.
    #[inline(always)]
    pub fn mask(&self) -> u8 {
        self.mask
    }

    /// Number of children (1..=8).
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Always false: a group has at least one child.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The children's child masks, in child order (0 for a leaf).
    #[inline(always)]
    pub fn child_masks(&self) -> &'a [u8] {
        self.masks
    }

    /// The children's log-odds values, in child order.
    #[inline(always)]
    pub fn values(&self) -> &'a [f32] {
        self.values
    }

    /// The children's colours or stamps, in child order (0 for plain trees).
    #[inline(always)]
    pub fn extras(&self) -> &'a [u32] {
        self.extras
    }

    /// Each child's position (0..8, x = 1, y = 2, z = 4) with its rank in
    /// the group, in child order.
    #[inline(always)]
    pub fn positions(&self) -> impl Iterator<Item = (usize, u32)> {
        let mut rest = self.mask;
        (0..self.len()).map(move |rank| {
            let pos = rest.trailing_zeros();
            rest &= rest.wrapping_sub(1);
            (rank, pos)
        })
    }
}

/// What [`NodeRef::visit_preorder`] calls, node by node in depth-first
/// pre-order. A node with children gets [`Self::enter`], then its
/// children's calls in child order, then [`Self::leave`]; a node without
/// children gets [`Self::leaf`] alone. Each call may stop the walk with
/// [`ControlFlow::Break`] (a writer's I/O error, say).
pub trait PreorderVisitor {
    /// What a visitor stops the walk with.
    type Break;

    /// A node with children, before its subtree, with its children.
    fn enter(&mut self, node: &PreorderNode, children: &ChildGroup<'_>) -> ControlFlow<Self::Break>;

    /// A node without children (by default: nothing).
    #[inline(always)]
    fn leaf(&mut self, _node: &PreorderNode) -> ControlFlow<Self::Break> {
        ControlFlow::Continue(())
    }

    /// A node with children, after its subtree (by default: nothing).
    #[inline(always)]
    fn leave(&mut self, _node: &PreorderNode) -> ControlFlow<Self::Break> {
        ControlFlow::Continue(())
    }
}

/// Nothing to see: the visitor of a walk that only one side needs
/// (see [`Tee`]).
impl PreorderVisitor for () {
    type Break = Infallible;

    #[inline(always)]
    fn enter(&mut self, _: &PreorderNode, _: &ChildGroup<'_>) -> ControlFlow<Infallible> {
        ControlFlow::Continue(())
    }
}

/// Two visitors driven by one walk, so that a writer and whatever watches
/// the same nodes (statistics, a second format) read the tree once:
/// `.1` sees each node first and never stops the walk; `.0` may.
pub struct Tee<'a, A, B>(pub &'a mut A, pub &'a mut B);

impl<A: PreorderVisitor, B: PreorderVisitor<Break = Infallible>> PreorderVisitor for Tee<'_, A, B> {
    type Break = A::Break;

    #[inline(always)]
    fn enter(&mut self, node: &PreorderNode, children: &ChildGroup<'_>) -> ControlFlow<A::Break> {
        let ControlFlow::Continue(()) = self.1.enter(node, children);
        self.0.enter(node, children)
    }

    #[inline(always)]
    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<A::Break> {
        let ControlFlow::Continue(()) = self.1.leaf(node);
        self.0.leaf(node)
    }

    #[inline(always)]
    fn leave(&mut self, node: &PreorderNode) -> ControlFlow<A::Break> {
        let ControlFlow::Continue(()) = self.1.leave(node);
        self.0.leave(node)
    }
}

/// A map the file writers can walk as one tree, in pre-order from the
/// root: an [`OccupancyTree`], or a tiled map whose tiles are read one at a
/// time (`crate::tiles`), so that a map larger than memory is written
/// without ever being one tree.
pub trait PreorderSource {
    /// What the nodes carry besides occupancy.
    fn node_kind(&self) -> NodeKind;

    /// Voxel edge length, metres.
    fn resolution(&self) -> f64;

    /// The sensor model (the `.bt` writers label leaves by it).
    fn sensor(&self) -> &SensorModel;

    /// Nodes of the tree (`size()`), known before the walk.
    fn node_count(&self) -> u64;

    /// Walks the whole tree from the root as [`NodeRef::visit_preorder`]
    /// does (nothing for an empty tree). `Err` when the walk cannot read a
    /// part of the map (a tile file); the visitor's own stop is the
    /// `ControlFlow`.
    fn visit_preorder<V: PreorderVisitor>(&self, visitor: &mut V) -> io::Result<ControlFlow<V::Break>>;
}

impl PreorderSource for OccupancyTree {
    fn node_kind(&self) -> NodeKind {
        self.kind()
    }

    fn resolution(&self) -> f64 {
        OccupancyTree::resolution(self)
    }

    fn sensor(&self) -> &SensorModel {
        OccupancyTree::sensor(self)
    }

    fn node_count(&self) -> u64 {
        self.size() as u64
    }

    fn visit_preorder<V: PreorderVisitor>(&self, visitor: &mut V) -> io::Result<ControlFlow<V::Break>> {
        Ok(self.root().map_or(ControlFlow::Continue(()), |root| root.visit_preorder(visitor)))
    }
}

/// The walk below inner-pool node `n` (`node`, which has children).
fn visit_subtree<V: PreorderVisitor>(
    p: &Parts<'_>,
    n: NodeId,
    node: &PreorderNode,
    visitor: &mut V,
) -> ControlFlow<V::Break> {
    let first = p.first_child[n as usize];
    let k = crate::arch::count_ones(node.child_mask) as usize;
    let depth = node.depth + 1;
    if in_leaf_pool(first) {
        // the voxels of a depth-15 node: leaves, values side by side
        let i = leaf_index(first);
        let values = &p.leaf_values[i..i + k];
        let extras = p.leaf_extras.get(i..i + k).unwrap_or(&NO_EXTRAS[..k]);
        let group = ChildGroup { mask: node.child_mask, masks: &NO_MASKS[..k], values, extras };
        visitor.enter(node, &group)?;
        for (&value, &extra) in values.iter().zip(extras) {
            visitor.leaf(&PreorderNode { depth, child_mask: 0, value, extra })?;
        }
        return visitor.leave(node);
    }
    let f = first as usize;
    let masks = &p.masks[f..f + k];
    let extras = p.extras.get(f..f + k).unwrap_or(&NO_EXTRAS[..k]);
    let group = ChildGroup { mask: node.child_mask, masks, values: &p.values[f..f + k], extras };
    // ask for the inner children's groups before the walk needs them
    for (c, &m) in masks.iter().enumerate() {
        if m != 0 {
            p.prefetch_group(p.first_child[f + c]);
        }
    }
    visitor.enter(node, &group)?;
    for (c, &child_mask) in masks.iter().enumerate() {
        let child = PreorderNode { depth, child_mask, value: group.values[c], extra: extras[c] };
        if child_mask == 0 {
            visitor.leaf(&child)?;
        } else {
            visit_subtree(p, (f + c) as NodeId, &child, visitor)?;
        }
    }
    visitor.leave(node)
}

/// Builds a tree from nodes given in depth-first pre-order (children
/// 0..7), each as its value and child mask: how `.ot`-like streams and the
/// mapped format are turned back into a tree. The arena comes out in
/// depth-first order with no free slots.
pub struct PreorderBuilder {
    kind: NodeKind,
    fill: PreorderFill,
}

/// A node below depth 16 was announced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("node {index} in pre-order lies below depth 16")]
pub struct TooDeep {
    /// The `index` given with the offending node.
    pub index: u64,
}

impl PreorderBuilder {
    /// A builder for a plain tree.
    pub fn new() -> Self {
        Self::with_kind(NodeKind::Plain)
    }

    /// A builder for a tree of `kind`; give extras with [`Self::push_with_extra`].
    pub fn with_kind(kind: NodeKind) -> Self {
        PreorderBuilder { kind, fill: PreorderFill::new(default_extra(kind), 0) }
    }

    /// A builder that expects about `nodes` nodes. The hint need not be
    /// right nor trusted: memory grows toward it only as nodes arrive.
    pub(crate) fn with_hint(kind: NodeKind, nodes: usize) -> Self {
        PreorderBuilder { kind, fill: PreorderFill::new(default_extra(kind), nodes) }
    }

    /// Reserves room for `n` more nodes at once.
    pub(crate) fn reserve(&mut self, n: usize) {
        self.fill.reserve(n);
    }

    /// True once the root and every announced node have been given.
    #[inline(always)]
    pub fn is_complete(&self) -> bool {
        self.fill.is_complete()
    }

    /// Depth of the next node to give (0 for the root); `None` when complete.
    pub fn next_depth(&self) -> Option<u8> {
        self.fill.next_depth()
    }

    /// Gives the next node. `index` only labels errors.
    pub fn push(&mut self, value: f32, mask: u8, index: u64) -> Result<(), TooDeep> {
        self.push_with_extra(value, None, mask, index)
    }

    /// Gives the next node with its colour or stamp (`None` keeps the
    /// kind's default).
    #[inline(always)]
    pub fn push_with_extra(&mut self, value: f32, extra: Option<u32>, mask: u8, index: u64) -> Result<(), TooDeep> {
        self.fill.push(value, extra, mask).map_err(|_| TooDeep { index })
    }

    /// The finished arena (root at 0); `None` when nodes are still missing.
    pub(crate) fn finish_arena(self) -> Option<Option<NodeArena>> {
        if self.fill.len() == 0 {
            return Some(None);
        }
        self.fill.finish().map(Some)
    }

    /// The finished tree; `None` when nodes are still missing.
    pub fn finish(self, resolution: f64, sensor: SensorModel) -> Result<Option<OccupancyTree>, TreeError> {
        let mut tree = OccupancyTree::with_kind(resolution, sensor, self.kind)?;
        let Some(arena) = self.finish_arena() else {
            return Ok(None);
        };
        if let Some(a) = arena {
            tree.set_arena_with_size(a);
        }
        Ok(Some(tree))
    }
}

impl Default for PreorderBuilder {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;
    use crate::tree::{Clock, InnerNodes};

    /// What a walk reported, as events.
    #[derive(Debug, PartialEq)]
    enum Event {
        Enter(PreorderNode, Vec<(u8, f32, u32)>),
        Leaf(PreorderNode),
        Leave(u8),
    }

    struct Recorder {
        events: Vec<Event>,
        /// Stop at this many events.
        stop_at: usize,
    }

    impl Recorder {
        fn push(&mut self, e: Event) -> ControlFlow<usize> {
            self.events.push(e);
            if self.events.len() == self.stop_at {
                ControlFlow::Break(self.events.len())
            } else {
                ControlFlow::Continue(())
            }
        }
    }

    impl PreorderVisitor for Recorder {
        type Break = usize;

        fn enter(&mut self, node: &PreorderNode, g: &ChildGroup<'_>) -> ControlFlow<usize> {
            assert_eq!(g.mask(), node.child_mask);
            assert_eq!(g.positions().count(), g.len());
            let children = g.positions().map(|(r, _)| (g.child_masks()[r], g.values()[r], g.extras()[r])).collect();
            self.push(Event::Enter(*node, children))
        }

        fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<usize> {
            self.push(Event::Leaf(*node))
        }

        fn leave(&mut self, node: &PreorderNode) -> ControlFlow<usize> {
            self.push(Event::Leave(node.depth))
        }
    }

    /// The events a walk must report, from the `NodeRef` cursor.
    fn expected(n: NodeRef<'_>, depth: u8, out: &mut Vec<Event>) {
        let node = PreorderNode { depth, child_mask: n.child_mask(), value: n.value(), extra: n.extra() };
        if !n.has_children() {
            out.push(Event::Leaf(node));
            return;
        }
        let children = n.children().map(|(_, c)| (c.child_mask(), c.value(), c.extra())).collect();
        out.push(Event::Enter(node, children));
        n.children().for_each(|(_, c)| expected(c, depth + 1, out));
        out.push(Event::Leave(depth));
    }

    #[test]
    fn a_walk_visits_every_node_in_preorder_with_its_children_and_stops_on_break() {
        // a stamped tree (extras in both pools) with voxels, coarse leaves
        // from pruning and nodes of every depth
        let mut tree = OccupancyTree::with_kind(0.1, SensorModel::default(), NodeKind::Stamped).unwrap();
        for i in 0..400u16 {
            tree.set_clock(Clock::Fixed(u32::from(i % 5)));
            let k = Key([32768 + i % 13, 32760 + i % 7, 32770 + i / 40]);
            tree.update_occupancy(k, i % 4 != 0, InnerNodes::Update);
        }
        tree.set_clock(Clock::Fixed(9));
        for x in 32800..32816 {
            for y in 32800..32808 {
                for z in 32800..32808 {
                    tree.update_occupancy(Key([x, y, z]), true, InnerNodes::Update);
                }
            }
        }
        tree.prune();
        let root = tree.root().unwrap();
        let mut want = Vec::new();
        expected(root, 0, &mut want);
        assert!(want.iter().any(|e| matches!(e, Event::Leaf(n) if n.depth < 16)), "a coarse leaf");
        let mut all = Recorder { events: Vec::new(), stop_at: usize::MAX };
        assert_eq!(root.visit_preorder(&mut all), ControlFlow::Continue(()));
        assert_eq!(all.events, want);
        let mut some = Recorder { events: Vec::new(), stop_at: want.len() / 2 };
        assert_eq!(root.visit_preorder(&mut some), ControlFlow::Break(want.len() / 2));
        assert_eq!(some.events[..], want[..want.len() / 2]);
    }

    #[test]
    fn a_walk_from_a_lone_root_reports_one_leaf() {
        let mut b = PreorderBuilder::new();
        b.push(1.5, 0, 0).unwrap();
        let tree = b.finish(0.1, SensorModel::default()).unwrap().unwrap();
        let mut all = Recorder { events: Vec::new(), stop_at: usize::MAX };
        assert_eq!(tree.root().unwrap().visit_preorder(&mut all), ControlFlow::Continue(()));
        let root = PreorderNode { depth: 0, child_mask: 0, value: 1.5, extra: 0 };
        assert_eq!(all.events, [Event::Leaf(root)]);
    }
}
