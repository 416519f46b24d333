//! The node arena: no pointers, no per-node allocation; nine bytes per node
//! above depth 16 and four per voxel.
//!
//! Nodes are addressed by a `u32` node id and live in two pools. The
//! *inner pool* holds the nodes above depth 16 in three parallel arrays: the
//! value (`f32` log-odds), a child mask (bit `i` set when child `i` exists)
//! and the id of the first child. Depth-16 nodes (voxels) can never have
//! children, and they are most of a map (69–80% of the nodes of every bench
//! map), so the *leaf pool* holds only their values; their ids carry
//! [`LEAF_POOL`]. The children of a depth-15 node lie in the leaf pool, all
//! other children in the inner pool; callers that create children say the
//! parent's depth.
//!
//! The existing children of a node form one contiguous *group* of exactly
//! `popcount(mask)` slots, in child order, so child `i` sits at
//! `first_child + popcount(mask & ((1 << i) - 1))`. A group that grows or
//! shrinks moves to a slot run of the new size in its pool; the old run
//! goes on that pool's free list of its size and is reused. Nodes therefore
//! move when their siblings change: node ids are valid only until the next
//! structural change. [`NodeArena::compact_in_place`] re-lays both pools in
//! depth-first (Morton) order with no free runs left.
//!
//! Trees whose nodes carry more than log-odds (colour, time stamp, count)
//! add a `u32` *extra* per node in each pool; plain trees leave those arrays
//! empty and pay nothing for them.

#[allow(unsafe_code)]
mod atomic_view;
mod fill;
mod free;
mod parts;
mod prefetch;
mod shared;
mod store;

pub(crate) use fill::{LabelFill, PreorderFill};
pub(crate) use parts::Parts;
pub(crate) use prefetch::{prefetch, prefetch_lines, WHOLE_PREFETCH_BYTES};
pub(crate) use shared::{ArenaFree, SharedArena};
pub(crate) use store::NodeStore;

use crate::key::TREE_DEPTH;
use free::FreeRuns;

/// Id of a node in the arena.
pub type NodeId = u32;

/// Set in the ids of leaf-pool nodes (the voxels at depth 16).
pub const LEAF_POOL: NodeId = 1 << 31;

/// Sentinel for "no first child" (leaves).
const NO_CHILD: NodeId = 0;

/// Does `n` lie in the leaf pool?
#[inline(always)]
pub fn in_leaf_pool(n: NodeId) -> bool {
    n & LEAF_POOL != 0
}

/// Index of leaf-pool node `n` in the leaf arrays.
#[inline(always)]
pub(crate) fn leaf_index(n: NodeId) -> usize {
    (n & !LEAF_POOL) as usize
}

/// Do the children of a node at `depth` go to the leaf pool?
#[inline(always)]
fn leaf_group(depth: u8) -> bool {
    depth + 1 == TREE_DEPTH
}

#[derive(Clone, Debug, Default)]
pub struct NodeArena {
    // the inner pool
    values: Vec<f32>,
    masks: Vec<u8>,
    first_child: Vec<NodeId>,
    /// Per-node payload beyond the value; empty unless enabled.
    extras: Vec<u32>,
    free: FreeRuns,
    // the leaf pool
    leaf_values: Vec<f32>,
    leaf_extras: Vec<u32>,
    leaf_free: FreeRuns,
    /// The extra of a newly created node; `None` when extras are off.
    default_extra: Option<u32>,
    /// Initialised slots at the end of each pool's arrays that are not in
    /// use yet: what a parallel update made room for and did not claim
    /// ([`NodeArena::with_shared`]), taken by later runs.
    spare: usize,
    leaf_spare: usize,
    /// Slots of each pool the last parallel update allocated from its
    /// spare slots, which sizes the next one's.
    last_shared_use: Option<(usize, usize)>,
}

/// Arena statistics: slots in use and held, and the bytes really reserved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ArenaUsage {
    /// Slots holding a node.
    pub live_slots: usize,
    /// Slots left free (by pruning or moves) and awaiting reuse or compaction.
    pub free_slots: usize,
    /// Bytes reserved by the arena's arrays and free lists (capacity, not length).
    pub bytes_reserved: usize,
}

/// Slots to reserve when a pool of `len` slots needs `needed` more: double
/// a small pool (up to 1024 slots), so that the many small trees of a
/// finely tiled map hold a few hundred bytes each rather than kilobytes;
/// grow a large one by an eighth, since large reallocations are remapped in
/// place by the allocator and peak memory stays low.
fn growth(len: usize, needed: usize) -> usize {
    needed.max(len / 8).max(len.min(1024)).max(16)
}

impl NodeArena {
    /// An arena holding only a root (id 0) with the given value.
    #[cfg(test)]
    pub fn with_root(value: f32) -> Self {
        Self::with_root_and_extras(value, None)
    }

    /// An arena holding only a root (id 0) with the given value, with a
    /// per-node `u32` extra when `default_extra` is given (new nodes start
    /// with it).
    pub fn with_root_and_extras(value: f32, default_extra: Option<u32>) -> Self {
        let mut a = NodeArena { default_extra, ..Default::default() };
        a.push_run(1);
        a.values[0] = value;
        a
    }

    /// Slots held in both pools (live and free).
    #[inline]
    pub fn slot_count(&self) -> usize {
        self.inner_len() + self.leaf_len()
    }

    /// Slots of the inner pool (its arrays may hold spare slots beyond).
    #[inline(always)]
    fn inner_len(&self) -> usize {
        self.values.len() - self.spare
    }

    #[inline(always)]
    fn leaf_len(&self) -> usize {
        self.leaf_values.len() - self.leaf_spare
    }

    /// Takes `len` spare slots of a pool as default slots; when fewer are
    /// left, drops them (so the pool's arrays end at its slots).
    #[cold]
    #[inline(never)]
    fn take_spare(&mut self, len: usize, leaf: bool) -> Option<NodeId> {
        let extra = self.default_extra.unwrap_or(0);
        if leaf {
            let start = self.leaf_len();
            if self.leaf_spare < len {
                self.leaf_values.truncate(start);
                self.leaf_extras.truncate(if self.default_extra.is_some() { start } else { 0 });
                self.leaf_spare = 0;
                return None;
            }
            self.leaf_values[start..start + len].fill(0.0);
            if let Some(e) = self.leaf_extras.get_mut(start..start + len) {
                e.fill(extra);
            }
            self.leaf_spare -= len;
            Some(LEAF_POOL | start as NodeId)
        } else {
            let start = self.inner_len();
            if self.spare < len {
                self.values.truncate(start);
                self.masks.truncate(start);
                self.first_child.truncate(start);
                self.extras.truncate(if self.default_extra.is_some() { start } else { 0 });
                self.spare = 0;
                return None;
            }
            self.values[start..start + len].fill(0.0);
            self.masks[start..start + len].fill(0);
            self.first_child[start..start + len].fill(NO_CHILD);
            if let Some(e) = self.extras.get_mut(start..start + len) {
                e.fill(extra);
            }
            self.spare -= len;
            Some(start as NodeId)
        }
    }

    /// Slots on the free lists (0 after compaction or when read from a file).
    #[inline]
    pub fn free_slot_count(&self) -> usize {
        self.free.slots() + self.leaf_free.slots()
    }

    /// The extra of `n` (0 when extras are off).
    #[inline(always)]
    pub fn extra(&self, n: NodeId) -> u32 {
        let e = if in_leaf_pool(n) { self.leaf_extras.get(leaf_index(n)) } else { self.extras.get(n as usize) };
        e.copied().unwrap_or(0)
    }

    #[inline(always)]
    pub fn set_extra(&mut self, n: NodeId, v: u32) {
        let e = if in_leaf_pool(n) { self.leaf_extras.get_mut(leaf_index(n)) } else { self.extras.get_mut(n as usize) };
        if let Some(e) = e {
            *e = v;
        }
    }

    #[inline(always)]
    pub fn value(&self, n: NodeId) -> f32 {
        if in_leaf_pool(n) {
            self.leaf_values[leaf_index(n)]
        } else {
            self.values[n as usize]
        }
    }

    #[inline(always)]
    pub fn set_value(&mut self, n: NodeId, v: f32) {
        if in_leaf_pool(n) {
            self.leaf_values[leaf_index(n)] = v;
        } else {
            self.values[n as usize] = v;
        }
    }

    #[inline(always)]
    pub fn mask(&self, n: NodeId) -> u8 {
        if in_leaf_pool(n) {
            0
        } else {
            self.masks[n as usize]
        }
    }

    #[inline(always)]
    pub fn has_children(&self, n: NodeId) -> bool {
        self.mask(n) != 0
    }

    /// The first child's id; meaningless for nodes without children.
    #[inline(always)]
    pub fn first_child(&self, n: NodeId) -> NodeId {
        if in_leaf_pool(n) {
            NO_CHILD
        } else {
            self.first_child[n as usize]
        }
    }

    /// Prefetches the child groups of `n`'s inner children: a depth-first
    /// walk visits them next, and on a tree fresh from updates they lie
    /// scattered, so asking for all of them at once overlaps the misses.
    #[inline(always)]
    pub fn prefetch_grandchildren(&self, n: NodeId) {
        let first = self.first_child(n);
        if in_leaf_pool(first) {
            return;
        }
        let first = first as usize;
        let k = crate::arch::count_ones(self.masks[n as usize]) as usize;
        let parts = self.parts();
        for c in first..first + k {
            if self.masks[c] != 0 {
                parts.prefetch_group(self.first_child[c]);
            }
        }
    }

    /// Id of child `pos` of `n`, if it exists.
    #[inline(always)]
    pub fn child(&self, n: NodeId, pos: usize) -> Option<NodeId> {
        let m = self.mask(n);
        if m & (1 << pos) == 0 {
            None
        } else {
            Some(self.first_child[n as usize] + crate::arch::count_ones(m & ((1u8 << pos) - 1)))
        }
    }

    /// Children of `n` as `(child index, id)` in child order.
    #[inline]
    pub fn children(&self, n: NodeId) -> impl Iterator<Item = (usize, NodeId)> {
        let m = self.mask(n);
        let first = self.first_child(n);
        (0..8usize).filter(move |&i| m & (1 << i) != 0).scan(first, |next, i| {
            let id = *next;
            *next += 1;
            Some((i, id))
        })
    }

    /// Appends `len` default slots to the inner pool; returns the first id.
    #[inline]
    fn push_run(&mut self, len: usize) -> NodeId {
        if self.spare != 0 {
            if let Some(id) = self.take_spare(len, false) {
                return id;
            }
        }
        let start = self.values.len();
        if len > 8 || start + 8 > self.values.capacity() {
            return self.push_run_growing(len);
        }
        // a group: append eight slots and drop the surplus, which compiles to
        // a few stores where `resize` would call `memset`
        self.values.extend_from_slice(&[0.0; 8]);
        self.values.truncate(start + len);
        self.masks.extend_from_slice(&[0; 8]);
        self.masks.truncate(start + len);
        self.first_child.extend_from_slice(&[NO_CHILD; 8]);
        self.first_child.truncate(start + len);
        if let Some(e) = self.default_extra {
            self.extras.extend_from_slice(&[e; 8]);
            self.extras.truncate(start + len);
        }
        start as NodeId
    }

    /// [`Self::push_run`] when the arena has to grow first.
    #[cold]
    #[inline(never)]
    fn push_run_growing(&mut self, len: usize) -> NodeId {
        let start = self.values.len();
        assert!(start + len < LEAF_POOL as usize, "node arena exceeds 2^31 inner slots");
        // keep room for eight more slots, which the fast path appends
        let more = growth(start, len + 8);
        if start + len + 8 > self.values.capacity() {
            self.values.reserve_exact(more);
            self.masks.reserve_exact(more);
            self.first_child.reserve_exact(more);
            if self.default_extra.is_some() {
                self.extras.reserve_exact(more);
            }
        }
        self.values.resize(start + len, 0.0);
        self.masks.resize(start + len, 0);
        self.first_child.resize(start + len, NO_CHILD);
        if let Some(e) = self.default_extra {
            self.extras.resize(start + len, e);
        }
        start as NodeId
    }

    /// Appends `len` (at most 8) default slots to the leaf pool; returns the
    /// first id.
    #[inline]
    fn push_leaf_run(&mut self, len: usize) -> NodeId {
        if self.leaf_spare != 0 {
            if let Some(id) = self.take_spare(len, true) {
                return id;
            }
        }
        let start = self.leaf_values.len();
        if start + len > self.leaf_values.capacity() {
            self.grow_leaves(len);
        }
        self.leaf_values.extend_from_slice(&[0.0; 8][..len]);
        if let Some(e) = self.default_extra {
            self.leaf_extras.extend_from_slice(&[e; 8][..len]);
        }
        LEAF_POOL | start as NodeId
    }

    /// Makes room for `len` more leaf slots (see [`growth`]).
    #[cold]
    #[inline(never)]
    fn grow_leaves(&mut self, len: usize) {
        let start = self.leaf_values.len();
        assert!(start + len < LEAF_POOL as usize, "node arena exceeds 2^31 leaf slots");
        let more = growth(start, len);
        self.leaf_values.reserve_exact(more);
        if self.default_extra.is_some() {
            self.leaf_extras.reserve_exact(more);
        }
    }

    /// A run of `len` slots in the leaf pool (`leaf`) or the inner pool.
    #[inline]
    fn alloc_run(&mut self, len: usize, leaf: bool) -> NodeId {
        if leaf {
            match self.leaf_free.pop(len) {
                Some(start) => start,
                None => self.push_leaf_run(len),
            }
        } else {
            match self.free.pop(len) {
                Some(start) => start,
                None => self.push_run(len),
            }
        }
    }

    #[inline]
    fn free_run(&mut self, start: NodeId, len: usize) {
        if in_leaf_pool(start) {
            self.leaf_free.push(start, len);
        } else {
            self.free.push(start, len);
        }
    }

    /// Copies a slot to another of the same pool.
    #[inline(always)]
    fn copy_slot(&mut self, from: NodeId, to: NodeId) {
        let extras = self.default_extra.is_some();
        if in_leaf_pool(from) {
            let (f, t) = (leaf_index(from), leaf_index(to));
            self.leaf_values[t] = self.leaf_values[f];
            if extras {
                self.leaf_extras[t] = self.leaf_extras[f];
            }
        } else {
            let (f, t) = (from as usize, to as usize);
            self.values[t] = self.values[f];
            self.masks[t] = self.masks[f];
            self.first_child[t] = self.first_child[f];
            if extras {
                self.extras[t] = self.extras[f];
            }
        }
    }

    /// Makes slot `id` a fresh leaf holding `value` and `extra`.
    #[inline(always)]
    fn init_slot(&mut self, id: NodeId, value: f32, extra: Option<u32>) {
        if in_leaf_pool(id) {
            let i = leaf_index(id);
            self.leaf_values[i] = value;
            if let Some(e) = extra {
                self.leaf_extras[i] = e;
            }
        } else {
            let i = id as usize;
            self.values[i] = value;
            self.masks[i] = 0;
            self.first_child[i] = NO_CHILD;
            if let Some(e) = extra {
                self.extras[i] = e;
            }
        }
    }

    /// Adds child `pos` (which must not exist) of `n`, which lies at
    /// `depth`, as a leaf with `value`; returns its id. Moves the other
    /// children of `n`.
    pub fn insert_child(&mut self, n: NodeId, pos: usize, value: f32, depth: u8) -> NodeId {
        let m = self.masks[n as usize];
        debug_assert_eq!(m & (1 << pos), 0);
        let old_len = crate::arch::count_ones(m) as usize;
        let old = self.first_child[n as usize];
        let new = self.alloc_run(old_len + 1, leaf_group(depth));
        debug_assert!(old_len == 0 || in_leaf_pool(old) == in_leaf_pool(new), "depth {depth} is not n's");
        let rank = crate::arch::count_ones(m & ((1u8 << pos) - 1));
        for i in 0..rank {
            self.copy_slot(old + i, new + i);
        }
        for i in rank..old_len as u32 {
            self.copy_slot(old + i, new + i + 1);
        }
        let id = new + rank;
        self.init_slot(id, value, self.default_extra);
        self.free_run(old, old_len);
        self.masks[n as usize] = m | (1 << pos);
        self.first_child[n as usize] = new;
        id
    }

    /// Expands a leaf `n` at `depth`: eight children holding its value and
    /// extra (OctoMap's `expandNode` copies the node's data).
    pub fn expand_node(&mut self, n: NodeId, depth: u8) {
        NodeStore::expand_node(self, n, depth)
    }

    /// Removes child `pos` of `n` and its whole subtree; returns the number
    /// of nodes freed.
    pub fn remove_child(&mut self, n: NodeId, pos: usize) -> usize {
        let m = self.masks[n as usize];
        debug_assert_ne!(m & (1 << pos), 0);
        let old_len = crate::arch::count_ones(m) as usize;
        let old = self.first_child[n as usize];
        let rank = crate::arch::count_ones(m & ((1u8 << pos) - 1));
        let freed = NodeStore::free_subtree_children(self, old + rank) + 1;
        if old_len == 1 {
            self.masks[n as usize] = 0;
            self.first_child[n as usize] = NO_CHILD;
        } else {
            let new = self.alloc_run(old_len - 1, in_leaf_pool(old));
            for i in 0..rank {
                self.copy_slot(old + i, new + i);
            }
            for i in rank + 1..old_len as u32 {
                self.copy_slot(old + i, new + i - 1);
            }
            self.masks[n as usize] = m & !(1 << pos);
            self.first_child[n as usize] = new;
        }
        self.free_run(old, old_len);
        freed
    }

    #[cfg(test)]
    /// A copy laid out in depth-first order, built by copying: each node's
    /// child group allocated as the node is visited, exactly sized.
    pub fn compacted(&self, root: NodeId) -> NodeArena {
        let mut out = NodeArena { default_extra: self.default_extra, ..Default::default() };
        out.push_run(1);
        out.values[0] = self.values[root as usize];
        out.set_extra(0, self.extra(root));
        // (old id, new id) pairs whose child groups still need copying
        let mut stack = vec![(root, 0 as NodeId)];
        while let Some((old, new)) = stack.pop() {
            let m = self.mask(old);
            if m == 0 {
                continue;
            }
            let len = crate::arch::count_ones(m);
            let first_old = self.first_child[old as usize];
            let first_new =
                if in_leaf_pool(first_old) { out.push_leaf_run(len as usize) } else { out.push_run(len as usize) };
            out.masks[new as usize] = m;
            out.first_child[new as usize] = first_new;
            for i in 0..len {
                out.set_value(first_new + i, self.value(first_old + i));
                out.set_extra(first_new + i, self.extra(first_old + i));
            }
            stack.extend((0..len).rev().map(|i| (first_old + i, first_new + i)));
        }
        out.shrink_to_fit();
        out
    }

    /// Releases spare capacity (after building).
    pub fn shrink_to_fit(&mut self) {
        self.take_spare(usize::MAX, false);
        self.take_spare(usize::MAX, true);
        self.values.shrink_to_fit();
        self.masks.shrink_to_fit();
        self.first_child.shrink_to_fit();
        self.extras.shrink_to_fit();
        self.leaf_values.shrink_to_fit();
        self.leaf_extras.shrink_to_fit();
    }

    /// Re-lays both pools in depth-first order: the root first, each
    /// node's child group placed as the node is visited, no free runs left.
    /// Groups move whole, so each array is rebuilt by copying runs (one
    /// cache miss per group rather than per slot); the scratch space is the
    /// run list (5 bytes per group) and one array's new copy at a time.
    pub fn compact_in_place(&mut self, root: NodeId) {
        let mut inner = Runs::default();
        let mut leaf = Runs::default();
        inner.push(root, 1);
        let (mut next, mut next_leaf) = (1u32, 0u32);
        let mut stack = vec![root];
        while let Some(n) = stack.pop() {
            let k = crate::arch::count_ones(self.masks[n as usize]);
            if k == 0 {
                continue;
            }
            // each first child is read once, here, so it can be rewritten
            // before the slots move
            let first = self.first_child[n as usize];
            if in_leaf_pool(first) {
                leaf.push(leaf_index(first) as u32, k);
                self.first_child[n as usize] = LEAF_POOL | next_leaf;
                next_leaf += k;
            } else {
                inner.push(first, k);
                self.first_child[n as usize] = next;
                next += k;
                stack.extend((0..k).rev().map(|i| first + i));
            }
        }
        inner.gather(&mut self.values, next);
        inner.gather(&mut self.masks, next);
        inner.gather(&mut self.first_child, next);
        leaf.gather(&mut self.leaf_values, next_leaf);
        if self.default_extra.is_some() {
            inner.gather(&mut self.extras, next);
            leaf.gather(&mut self.leaf_extras, next_leaf);
        }
        self.free = FreeRuns::default();
        self.leaf_free = FreeRuns::default();
        (self.spare, self.leaf_spare) = (0, 0);
    }

    pub fn usage(&self) -> ArenaUsage {
        let free_slots = self.free_slot_count();
        ArenaUsage {
            live_slots: self.slot_count() - free_slots,
            free_slots,
            bytes_reserved: self.values.capacity() * 4
                + self.masks.capacity()
                + self.first_child.capacity() * 4
                + self.extras.capacity() * 4
                + self.leaf_values.capacity() * 4
                + self.leaf_extras.capacity() * 4
                + self.free.bytes()
                + self.leaf_free.bytes(),
        }
    }

    /// Asks for every cache line of the arena when it is small enough to
    /// stay in a core's L2 (at most [`WHOLE_PREFETCH_BYTES`]); returns
    /// whether it did. A walk over a small tree that other work has pushed
    /// out of L2 otherwise waits for its nodes one dependent miss at a time;
    /// asked for at once, the lines arrive together in about a microsecond.
    /// `voxels`: the walk reaches depth 16, so the leaf pool is wanted too.
    pub(crate) fn prefetch_all_if_small(&self, voxels: bool) -> bool {
        let p = self.parts();
        let leaf_pool = if voxels { 4 * (p.leaf_values.len() + p.leaf_extras.len()) } else { 0 };
        let bytes = 4 * (p.values.len() + p.first_child.len() + p.extras.len()) + p.masks.len() + leaf_pool;
        if bytes > WHOLE_PREFETCH_BYTES {
            return false;
        }
        prefetch_lines(p.masks);
        prefetch_lines(p.first_child);
        prefetch_lines(p.values);
        prefetch_lines(p.extras);
        if voxels {
            prefetch_lines(p.leaf_values);
            prefetch_lines(p.leaf_extras);
        }
        true
    }

    /// The inner pool's child masks, by id.
    #[inline(always)]
    pub(crate) fn masks(&self) -> &[u8] {
        &self.masks[..self.inner_len()]
    }

    /// The inner pool's first-child ids, by id.
    #[inline(always)]
    pub(crate) fn first_child_ids(&self) -> &[NodeId] {
        &self.first_child[..self.inner_len()]
    }

    /// The value of leaf-pool node `n`.
    #[inline(always)]
    pub(crate) fn leaf_value(&self, n: NodeId) -> f32 {
        self.leaf_values[leaf_index(n)]
    }

    /// The extra of leaf-pool node `n` (0 when extras are off).
    #[inline(always)]
    pub(crate) fn leaf_extra(&self, n: NodeId) -> u32 {
        self.leaf_extras.get(leaf_index(n)).copied().unwrap_or(0)
    }

    /// The arrays of both pools, for read-only passes over the whole tree.
    #[inline]
    pub(crate) fn parts(&self) -> Parts<'_> {
        let (n, nl) = (self.inner_len(), self.leaf_len());
        let extras = if self.default_extra.is_some() { (n, nl) } else { (0, 0) };
        Parts {
            values: &self.values[..n],
            masks: &self.masks[..n],
            first_child: &self.first_child[..n],
            extras: &self.extras[..extras.0],
            leaf_values: &self.leaf_values[..nl],
            leaf_extras: &self.leaf_extras[..extras.1],
        }
    }

    /// Replaces every slot's value `v` by `f(v)` (free slots included).
    pub fn map_values(&mut self, f: impl Fn(f32) -> f32) {
        let (n, nl) = (self.inner_len(), self.leaf_len());
        for v in self.values[..n].iter_mut().chain(&mut self.leaf_values[..nl]) {
            *v = f(*v);
        }
    }
}

/// Child groups in their new order, as (first old slot, length) runs.
#[derive(Default)]
struct Runs {
    firsts: Vec<u32>,
    lens: Vec<u8>,
}

impl Runs {
    fn push(&mut self, first: u32, len: u32) {
        self.firsts.push(first);
        self.lens.push(len as u8);
    }

    /// Replaces `slots` by the concatenation of the runs (`live` slots).
    fn gather<T: Copy>(&self, slots: &mut Vec<T>, live: u32) {
        let mut out = Vec::with_capacity(live as usize);
        for (&first, &len) in self.firsts.iter().zip(&self.lens) {
            let first = first as usize;
            out.extend_from_slice(&slots[first..first + len as usize]);
        }
        debug_assert_eq!(out.len(), live as usize);
        *slots = out;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn children_stay_in_order_while_groups_move() {
        let mut a = NodeArena::with_root(0.0);
        for &pos in &[5usize, 1, 7, 0] {
            a.insert_child(0, pos, pos as f32, 0);
        }
        let kids: Vec<_> = a.children(0).map(|(i, id)| (i, a.value(id))).collect();
        assert_eq!(kids, vec![(0, 0.0), (1, 1.0), (5, 5.0), (7, 7.0)]);
        assert_eq!(a.child(0, 5).map(|id| a.value(id)), Some(5.0));
        assert_eq!(a.child(0, 4), None);
        // runs of length 1, 2 and 3 were freed along the way
        assert_eq!(a.usage().free_slots, 6);
        let c = a.child(0, 1).unwrap();
        a.set_value(c, 9.0);
        a.expand_node(c, 1);
        assert_eq!(a.remove_child(0, 1), 9);
        let kids: Vec<_> = a.children(0).map(|(i, id)| (i, a.value(id))).collect();
        assert_eq!(kids, vec![(0, 0.0), (5, 5.0), (7, 7.0)]);
        let c = a.compacted(0);
        let mut d = a.clone();
        d.compact_in_place(0);
        assert_same_slots(&c, &d);
        assert_eq!(c.usage().free_slots, 0);
        assert_eq!(c.usage().live_slots, 4);
        let kids: Vec<_> = c.children(0).map(|(i, id)| (i, c.value(id))).collect();
        assert_eq!(kids, vec![(0, 0.0), (5, 5.0), (7, 7.0)]);
    }

    /// Both arenas hold the same slots, and no spare capacity.
    fn assert_same_slots(a: &NodeArena, b: &NodeArena) {
        assert_eq!(a.values, b.values);
        assert_eq!(a.masks, b.masks);
        assert_eq!(a.first_child, b.first_child);
        assert_eq!(a.extras, b.extras);
        assert_eq!(a.leaf_values, b.leaf_values);
        assert_eq!(a.leaf_extras, b.leaf_extras);
        for x in [a, b] {
            assert_eq!(x.free_slot_count(), 0);
            assert_eq!(x.values.capacity(), x.values.len());
            assert_eq!(x.leaf_values.capacity(), x.leaf_values.len());
        }
    }

    /// A chain of single children from the root down to depth `depth`;
    /// returns the node there.
    fn chain(a: &mut NodeArena, depth: u8, pos: usize) -> NodeId {
        let mut n = 0;
        for d in 0..depth {
            n = a.child(n, pos).unwrap_or_else(|| a.insert_child(n, pos, 0.0, d));
        }
        n
    }

    #[test]
    fn voxels_live_in_the_leaf_pool() {
        let mut a = NodeArena::with_root_and_extras(0.0, Some(7));
        let p = chain(&mut a, 15, 3);
        assert!(!in_leaf_pool(p));
        let inner_slots = a.values.len();
        for &pos in &[6usize, 2, 4] {
            let c = a.insert_child(p, pos, pos as f32, 15);
            assert!(in_leaf_pool(c));
            assert_eq!((a.value(c), a.extra(c), a.mask(c), a.first_child(c)), (pos as f32, 7, 0, NO_CHILD));
            assert!(!a.has_children(c));
            assert_eq!(a.children(c).count(), 0);
            a.set_extra(c, 100 + pos as u32);
        }
        // the inner pool did not grow; the leaf pool holds the runs of 1, 2
        // and 3 slots, the first two free
        assert_eq!(a.values.len(), inner_slots);
        assert_eq!(a.leaf_values.len(), 6);
        assert_eq!(a.leaf_free.slots(), 3);
        let kids: Vec<_> = a.children(p).map(|(i, c)| (i, a.value(c), a.extra(c))).collect();
        assert_eq!(kids, vec![(2, 2.0, 102), (4, 4.0, 104), (6, 6.0, 106)]);
        // a freed run is reused, in its own pool
        assert_eq!(a.remove_child(p, 4), 1);
        assert_eq!(a.leaf_values.len(), 6);
        assert_eq!(a.leaf_free.slots(), 4);
        let u = a.usage();
        assert_eq!((u.live_slots, u.free_slots), (16 + 2, 4));
        // a second depth-15 node, expanded: eight voxels copying its data
        let q = a.insert_child(0, 5, 0.0, 0);
        let q = chain_below(&mut a, q, 1, 15);
        a.set_value(q, 1.5);
        a.set_extra(q, 9);
        a.expand_node(q, 15);
        assert!(a.children(q).all(|(_, c)| in_leaf_pool(c) && a.value(c) == 1.5 && a.extra(c) == 9));
        let c = a.compacted(0);
        let mut d = a.clone();
        d.compact_in_place(0);
        assert_same_slots(&c, &d);
        assert_eq!(d.leaf_values.len(), 10);
        assert_eq!(d.usage().live_slots, a.usage().live_slots);
        // depth first: p's group before q's
        let p2 = chain(&mut d, 15, 3);
        assert_eq!(d.first_child(p2), LEAF_POOL);
        let kids: Vec<_> = d.children(p2).map(|(i, c)| (i, d.value(c), d.extra(c))).collect();
        assert_eq!(kids, vec![(2, 2.0, 102), (6, 6.0, 106)]);
        // real bytes: 9 per inner slot, 8 per voxel with extras
        assert_eq!(d.usage().bytes_reserved, d.values.len() * 13 + 10 * 8);
        // removing the chain frees both pools
        d.remove_all_children(0);
        assert_eq!(d.usage().live_slots, 1);
    }

    #[test]
    fn a_small_arena_reserves_little_and_a_large_one_grows_by_an_eighth() {
        // a path to one voxel: 16 inner slots, 1 leaf
        let mut a = NodeArena::with_root(0.0);
        chain(&mut a, 16, 0);
        assert!(a.usage().bytes_reserved < 512, "{:?}", a.usage());
        assert_eq!(growth(16, 9), 16);
        assert_eq!(growth(1 << 20, 9), 1 << 17);
    }

    /// Extends a chain of child 0s from `n` at `depth` down to `to`.
    fn chain_below(a: &mut NodeArena, mut n: NodeId, depth: u8, to: u8) -> NodeId {
        for d in depth..to {
            n = a.insert_child(n, 0, 0.0, d);
        }
        n
    }
}
