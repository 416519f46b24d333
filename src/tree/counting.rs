//! OctoMap's `CountingOcTree`: a hit count per node, incremented along the
//! whole path of every update. No occupancy, no pruning.

use super::arena::NodeArena;
use super::iter::NodeIter;
use super::{NodeId, ROOT};
use crate::geometry::Point3;
use crate::key::{Key, KeyError, KeySpace, TREE_DEPTH};

/// OctoMap's `CountingOcTree`: each node counts the updates whose path
/// went through it.
#[derive(Clone, Debug)]
pub struct CountingTree {
    keys: KeySpace,
    arena: Option<NodeArena>,
    size: usize,
}

impl CountingTree {
    /// An empty tree; `resolution` is the voxel edge length in metres.
    pub fn new(resolution: f64) -> Result<Self, super::TreeError> {
        crate::key::check_resolution(resolution).map_err(|_| super::TreeError::BadResolution(resolution))?;
        Ok(CountingTree { keys: KeySpace::new(resolution), arena: None, size: 0 })
    }

    pub(crate) fn from_arena(resolution: f64, arena: Option<NodeArena>) -> Result<Self, super::TreeError> {
        let mut t = Self::new(resolution)?;
        t.arena = arena;
        t.size = t.nodes(0).count();
        Ok(t)
    }

    /// Voxel edge length at the finest depth, metres.
    pub fn resolution(&self) -> f64 {
        self.keys.resolution()
    }

    /// The tree's coordinate/key arithmetic.
    pub fn key_space(&self) -> &KeySpace {
        &self.keys
    }

    /// OctoMap's `size()` node counter.
    pub fn size(&self) -> usize {
        self.size
    }

    /// A cursor on the root (counts in [`super::NodeRef::extra`]).
    pub fn root(&self) -> Option<super::NodeRef<'_>> {
        self.arena.as_ref().map(|arena| super::NodeRef { arena, id: ROOT })
    }

    /// `updateNode(key)`: counts one hit in the root and every node down to
    /// the voxel, creating nodes as needed; returns the voxel's count.
    pub fn update(&mut self, key: Key) -> u32 {
        let a = self.arena.get_or_insert_with(|| {
            self.size += 1;
            NodeArena::with_root_and_extras(0.0, Some(0))
        });
        let mut node: NodeId = ROOT;
        a.set_extra(node, a.extra(node).wrapping_add(1));
        for depth in 0..TREE_DEPTH {
            let pos = key.child_index(depth);
            node = match a.child(node, pos) {
                Some(c) => c,
                None => {
                    self.size += 1;
                    a.insert_child(node, pos, 0.0, depth)
                }
            };
            a.set_extra(node, a.extra(node).wrapping_add(1));
        }
        a.extra(node)
    }

    /// The count of the node `search(key, depth)` finds (depth 0 means 16):
    /// the node at `depth` containing `key`, or the deepest existing leaf
    /// above it; `None` when the path ends at an inner node lacking the
    /// child, or the tree is empty.
    pub fn count(&self, key: Key, depth: u8) -> Option<u32> {
        let a = self.arena.as_ref()?;
        let depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
        let key = if depth == TREE_DEPTH { key } else { crate::key::adjust_key_to_depth(key, depth) };
        let mut node = ROOT;
        for d in 0..depth {
            match a.child(node, key.child_index(d)) {
                Some(c) => node = c,
                None if a.has_children(node) => return None,
                None => break,
            }
        }
        Some(a.extra(node))
    }

    /// [`Self::update`] at the voxel containing `p`.
    pub fn update_point(&mut self, p: Point3) -> Result<u32, KeyError> {
        let key = self.keys.key(p)?;
        Ok(self.update(key))
    }

    /// Every node with its count (in `NodeItem::extra`), OctoMap's order.
    pub fn nodes(&self, max_depth: u8) -> NodeIter<'_> {
        NodeIter::over(self.arena.as_ref(), &self.keys, max_depth, false, None)
    }

    /// `getCentersMinHits`: centres of the leaves counted at least
    /// `min_hits` times, depth first.
    pub fn centers_min_hits(&self, min_hits: u32) -> Vec<Point3> {
        self.nodes(0)
            .filter(|n| n.is_leaf && n.extra >= min_hits)
            .map(|n| self.keys.key_to_point_at_depth(n.key, n.depth))
            .collect()
    }
}
