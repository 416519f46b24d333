//! Structural access for the file formats: the read-only [`NodeRef`]
//! cursor, and [`PreorderBuilder`], which builds a tree from nodes
//! given in depth-first pre-order.

use super::arena::PreorderFill;
use super::{default_extra, NodeArena, NodeId, NodeKind, OccupancyTree, TreeError};
use crate::sensor::SensorModel;

/// A read-only cursor on a node, for structural walks (writers of other
/// formats, comparisons). Valid while the tree is borrowed.
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    pub(super) arena: &'a NodeArena,
    pub(super) id: NodeId,
}

impl<'a> NodeRef<'a> {
    /// The arena and id of this node, for whole-tree passes.
    pub(crate) fn arena_id(&self) -> (&'a NodeArena, NodeId) {
        (self.arena, self.id)
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
