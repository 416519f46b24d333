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
///
/// Keeps one frame per level (the parent's key, the id of its next child
/// and the children still to visit) instead of a stack of pushed children,
/// so a node costs one mask test and one key step.
pub struct NodeIter<'a> {
    arena: Option<&'a NodeArena>,
    keys: &'a KeySpace,
    /// `frames[..len]`: frame `d` walks the children of a node at depth `d`.
    frames: [Frame; TREE_DEPTH as usize],
    len: usize,
    root_pending: bool,
    max_depth: u8,
    leaves_only: bool,
    bbx: Option<KeyBox>,
}

#[derive(Clone, Copy, Default)]
struct Frame {
    key: Key,
    next: NodeId,
    remaining: u8,
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
        NodeIter {
            arena,
            keys,
            frames: [Frame::default(); TREE_DEPTH as usize],
            len: 0,
            root_pending: arena.is_some(),
            max_depth,
            leaves_only,
            bbx,
        }
    }

    #[inline(always)]
    fn item(&self, a: &NodeArena, n: NodeId, key: Key, depth: u8, is_leaf: bool) -> NodeItem<'a> {
        NodeItem { key, depth, value: a.value(n), extra: a.extra(n), is_leaf, keys: self.keys }
    }
}

impl<'a> Iterator for NodeIter<'a> {
    type Item = NodeItem<'a>;

    #[inline]
    fn next(&mut self) -> Option<NodeItem<'a>> {
        let a = self.arena?;
        if self.root_pending {
            self.root_pending = false;
            let mask = a.mask(ROOT);
            if mask != 0 {
                self.frames[0] = Frame { key: Key::ROOT, next: a.first_child(ROOT), remaining: mask };
                self.len = 1;
                if self.leaves_only {
                    return self.next();
                }
            }
            return Some(self.item(a, ROOT, Key::ROOT, 0, mask == 0));
        }
        while self.len > 0 {
            let parent_depth = (self.len - 1) as u8;
            let f = &mut self.frames[self.len - 1];
            if f.remaining == 0 {
                self.len -= 1;
                continue;
            }
            let pos = f.remaining.trailing_zeros() as usize;
            f.remaining &= f.remaining - 1;
            let id = f.next;
            f.next += 1;
            let key = f.key.child_key(pos, parent_depth);
            let depth = parent_depth + 1;
            if self.bbx.is_some_and(|b| !b.overlaps(key, depth)) {
                continue;
            }
            let mask = a.mask(id);
            let is_leaf = mask == 0 || depth >= self.max_depth;
            if !is_leaf {
                a.prefetch_grandchildren(id);
                self.frames[self.len] = Frame { key, next: a.first_child(id), remaining: mask };
                self.len += 1;
                if self.leaves_only {
                    continue;
                }
            }
            return Some(self.item(a, id, key, depth, is_leaf));
        }
        None
    }
}
