//! Depth-first iteration in OctoMap's order (children 0..7).

use super::{NodeArena, NodeId, OccupancyTree, ROOT};
use crate::geometry::Point3;
use crate::key::{Key, KeySpace, KEY_CENTER, TREE_DEPTH};

/// An inclusive box of keys, as OctoMap's bounding-box iterator takes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KeyBox {
    pub min: Key,
    pub max: Key,
}

impl KeyBox {
    /// Does the node at `key`/`depth` overlap the box? (OctoMap's test,
    /// which widens by the half-size offset on both sides.)
    #[inline]
    fn overlaps(&self, key: Key, depth: u8) -> bool {
        let off = (KEY_CENTER >> depth) as i32;
        (0..3).all(|i| {
            let k = i32::from(key.0[i]);
            i32::from(self.min.0[i]) <= k + off && i32::from(self.max.0[i]) >= k - off
        })
    }
}

/// One node as iteration reports it.
#[derive(Clone, Copy, Debug)]
pub struct NodeItem<'a> {
    /// The key OctoMap's iterator computes (centre key of the node).
    pub key: Key,
    pub depth: u8,
    pub value: f32,
    /// Colour or stamp, by the tree's kind (0 for plain trees).
    pub extra: u32,
    /// No children, or at the iteration's depth limit.
    pub is_leaf: bool,
    keys: &'a KeySpace,
}

impl NodeItem<'_> {
    /// Edge length in metres.
    pub fn size(&self) -> f64 {
        self.keys.node_size(self.depth)
    }

    /// Centre in metres (double, as OctoMap's `getX/Y/Z`).
    pub fn center(&self) -> [f64; 3] {
        self.key.0.map(|k| self.keys.key_to_coord_at_depth(k, self.depth))
    }

    /// Centre as a float point (`getCoordinate`).
    pub fn center_point(&self) -> Point3 {
        self.keys.key_to_point_at_depth(self.key, self.depth)
    }
}

/// Iterator over nodes or leaves; see [`OccupancyTree::nodes`].
pub struct NodeIter<'a> {
    arena: Option<&'a NodeArena>,
    keys: &'a KeySpace,
    stack: Vec<(NodeId, Key, u8)>,
    max_depth: u8,
    leaves_only: bool,
    bbx: Option<KeyBox>,
}

impl<'a> NodeIter<'a> {
    pub(super) fn new(tree: &'a OccupancyTree, max_depth: u8, leaves_only: bool, bbx: Option<KeyBox>) -> Self {
        Self::over(tree.arena(), tree.key_space(), max_depth, leaves_only, bbx)
    }

    pub(super) fn over(
        arena: Option<&'a NodeArena>,
        keys: &'a KeySpace,
        max_depth: u8,
        leaves_only: bool,
        bbx: Option<KeyBox>,
    ) -> Self {
        let max_depth = if max_depth == 0 || max_depth > TREE_DEPTH { TREE_DEPTH } else { max_depth };
        let mut stack = Vec::with_capacity(8 * TREE_DEPTH as usize + 1);
        if arena.is_some() {
            stack.push((ROOT, Key::ROOT, 0));
        }
        NodeIter { arena, keys, stack, max_depth, leaves_only, bbx }
    }
}

impl<'a> Iterator for NodeIter<'a> {
    type Item = NodeItem<'a>;

    #[inline]
    fn next(&mut self) -> Option<NodeItem<'a>> {
        let a = self.arena?;
        while let Some((n, key, depth)) = self.stack.pop() {
            let mask = a.mask(n);
            let is_leaf = mask == 0 || depth >= self.max_depth;
            if !is_leaf {
                let first = a.first_child(n);
                let mut id = first + mask.count_ones();
                for pos in (0..8).rev() {
                    if mask & (1 << pos) != 0 {
                        id -= 1;
                        let ck = key.child_key(pos, depth);
                        if self.bbx.is_none_or(|b| b.overlaps(ck, depth + 1)) {
                            self.stack.push((id, ck, depth + 1));
                        }
                    }
                }
                if self.leaves_only {
                    continue;
                }
            }
            return Some(NodeItem { key, depth, value: a.value(n), extra: a.extra(n), is_leaf, keys: self.keys });
        }
        None
    }
}
