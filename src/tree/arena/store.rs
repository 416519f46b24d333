//! [`NodeStore`]: the structural operations of a batch update, written once
//! over the slot primitives of the arena and of a worker's share of it.

use super::{in_leaf_pool, leaf_group, NodeArena, NodeId, NO_CHILD};

/// Node storage as a batch update sees it: the [`NodeArena`] itself, or one
/// worker's share of it while several threads update disjoint subtrees
/// ([`ArenaWorker`]). The structural operations are written once, here,
/// over the slot primitives.
pub(crate) trait NodeStore {
    fn value(&self, n: NodeId) -> f32;
    fn set_value(&mut self, n: NodeId, v: f32);
    /// 0 when extras are off.
    fn extra(&self, n: NodeId) -> u32;
    /// Does nothing when extras are off.
    fn set_extra(&mut self, n: NodeId, v: u32);
    /// 0 in the leaf pool.
    fn mask(&self, n: NodeId) -> u8;
    /// Meaningless for nodes without children.
    fn first_child(&self, n: NodeId) -> NodeId;
    /// Sets the child mask and first child of inner-pool node `n`.
    fn set_children(&mut self, n: NodeId, mask: u8, first: NodeId);
    /// The extra of a new node; `None` when extras are off.
    fn default_extra(&self) -> Option<u32>;
    /// A run of `len` (1..=8) slots in the leaf pool (`leaf`) or the inner
    /// pool, each to be written by [`Self::init_slot`] or
    /// [`Self::copy_slot`] before it is read.
    fn alloc_run(&mut self, len: usize, leaf: bool) -> NodeId;
    fn free_run(&mut self, start: NodeId, len: usize);
    /// Copies a slot to another of the same pool.
    fn copy_slot(&mut self, from: NodeId, to: NodeId);
    /// Makes slot `id` a fresh leaf holding `value` and `extra`.
    fn init_slot(&mut self, id: NodeId, value: f32, extra: Option<u32>);

    #[inline(always)]
    fn has_children(&self, n: NodeId) -> bool {
        self.mask(n) != 0
    }

    /// Gives a leaf `n` at `depth` the children in `mask`, each a new leaf
    /// holding `value` and `extra`; returns the id of the first.
    #[inline]
    fn add_children(&mut self, n: NodeId, mask: u8, value: f32, extra: Option<u32>, depth: u8) -> NodeId {
        debug_assert_eq!(self.mask(n), 0);
        let len = crate::arch::count_ones(mask);
        let new = if len == 0 { NO_CHILD } else { self.alloc_run(len as usize, leaf_group(depth)) };
        for i in 0..len {
            self.init_slot(new + i, value, extra);
        }
        self.set_children(n, mask, new);
        new
    }

    /// Adds the children in `add` (none of which exists yet) to `n`, which
    /// lies at `depth`, as leaves holding `value`, moving its group once;
    /// returns the first id.
    #[inline]
    fn add_missing_children(&mut self, n: NodeId, add: u8, value: f32, depth: u8) -> NodeId {
        let m = self.mask(n);
        debug_assert_eq!(m & add, 0);
        if m == 0 {
            return self.add_children(n, add, value, self.default_extra(), depth);
        }
        if add == 0 {
            return self.first_child(n);
        }
        let old = self.first_child(n);
        let new_mask = m | add;
        let new = self.alloc_run(crate::arch::count_ones(new_mask) as usize, leaf_group(depth));
        let (mut from, mut to) = (old, new);
        for i in 0..8 {
            if m & (1 << i) != 0 {
                self.copy_slot(from, to);
                from += 1;
                to += 1;
            } else if add & (1 << i) != 0 {
                self.init_slot(to, value, self.default_extra());
                to += 1;
            }
        }
        self.free_run(old, crate::arch::count_ones(m) as usize);
        self.set_children(n, new_mask, new);
        new
    }

    /// Expands a leaf `n` at `depth`: eight children holding its value and
    /// extra (OctoMap's `expandNode` copies the node's data).
    #[inline]
    fn expand_node(&mut self, n: NodeId, depth: u8) {
        let extra = self.default_extra().map(|_| self.extra(n));
        self.add_children(n, 0xff, self.value(n), extra, depth);
    }

    /// Removes all children of `n` (and their subtrees); returns the number
    /// of nodes freed.
    #[inline]
    fn remove_all_children(&mut self, n: NodeId) -> usize {
        let freed = self.free_subtree_children(n);
        self.set_children(n, 0, NO_CHILD);
        freed
    }

    /// Frees every descendant run below `n` (not `n` itself).
    fn free_subtree_children(&mut self, n: NodeId) -> usize {
        let m = self.mask(n);
        if m == 0 {
            return 0;
        }
        let len = crate::arch::count_ones(m) as usize;
        let first = self.first_child(n);
        let mut freed = len;
        if !in_leaf_pool(first) {
            for i in 0..len as u32 {
                freed += self.free_subtree_children(first + i);
            }
        }
        self.free_run(first, len);
        freed
    }
}

impl NodeStore for NodeArena {
    #[inline(always)]
    fn value(&self, n: NodeId) -> f32 {
        NodeArena::value(self, n)
    }
    #[inline(always)]
    fn set_value(&mut self, n: NodeId, v: f32) {
        NodeArena::set_value(self, n, v)
    }
    #[inline(always)]
    fn extra(&self, n: NodeId) -> u32 {
        NodeArena::extra(self, n)
    }
    #[inline(always)]
    fn set_extra(&mut self, n: NodeId, v: u32) {
        NodeArena::set_extra(self, n, v)
    }
    #[inline(always)]
    fn mask(&self, n: NodeId) -> u8 {
        NodeArena::mask(self, n)
    }
    #[inline(always)]
    fn first_child(&self, n: NodeId) -> NodeId {
        NodeArena::first_child(self, n)
    }
    #[inline(always)]
    fn set_children(&mut self, n: NodeId, mask: u8, first: NodeId) {
        self.masks[n as usize] = mask;
        self.first_child[n as usize] = first;
    }
    #[inline(always)]
    fn default_extra(&self) -> Option<u32> {
        self.default_extra
    }
    #[inline(always)]
    fn alloc_run(&mut self, len: usize, leaf: bool) -> NodeId {
        NodeArena::alloc_run(self, len, leaf)
    }
    #[inline(always)]
    fn free_run(&mut self, start: NodeId, len: usize) {
        NodeArena::free_run(self, start, len)
    }
    #[inline(always)]
    fn copy_slot(&mut self, from: NodeId, to: NodeId) {
        NodeArena::copy_slot(self, from, to)
    }
    #[inline(always)]
    fn init_slot(&mut self, id: NodeId, value: f32, extra: Option<u32>) {
        NodeArena::init_slot(self, id, value, extra)
    }
}
