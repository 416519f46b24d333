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

use crate::key::TREE_DEPTH;
use std::sync::atomic::{AtomicU32, AtomicU8, AtomicUsize, Ordering::Relaxed};

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

/// The free slot runs of one pool, by length (index 1..=8), as ids.
#[derive(Clone, Debug, Default)]
pub(crate) struct FreeRuns {
    runs: [Vec<NodeId>; 9],
    slots: usize,
}

impl FreeRuns {
    #[inline]
    fn pop(&mut self, len: usize) -> Option<NodeId> {
        let start = self.runs[len].pop()?;
        self.slots -= len;
        Some(start)
    }

    #[inline]
    fn push(&mut self, start: NodeId, len: usize) {
        if len > 0 {
            self.runs[len].push(start);
            self.slots += len;
        }
    }

    fn bytes(&self) -> usize {
        self.runs.iter().map(|r| r.capacity() * std::mem::size_of::<NodeId>()).sum()
    }

    /// Deals the runs of each length out to `parts` lists.
    fn deal(mut self, parts: usize) -> Vec<FreeRuns> {
        let mut out = vec![FreeRuns::default(); parts];
        for len in 1..9 {
            let runs = std::mem::take(&mut self.runs[len]);
            let share = runs.len().div_ceil(parts).max(1);
            for (part, runs) in out.iter_mut().zip(runs.chunks(share)) {
                part.runs[len].extend_from_slice(runs);
                part.slots += len * runs.len();
            }
        }
        out
    }

    fn append(&mut self, other: FreeRuns) {
        for (mine, theirs) in self.runs.iter_mut().zip(other.runs) {
            mine.extend(theirs);
        }
        self.slots += other.slots;
    }

    /// Frees `len` consecutive slots from `start` as runs of at most 8.
    fn push_span(&mut self, mut start: NodeId, mut len: usize) {
        while len > 0 {
            let run = len.min(8);
            self.push(start, run);
            start += run as NodeId;
            len -= run;
        }
    }
}

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
        let len = mask.count_ones();
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
        let new = self.alloc_run(new_mask.count_ones() as usize, leaf_group(depth));
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
        self.free_run(old, m.count_ones() as usize);
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
        let len = m.count_ones() as usize;
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

/// The arrays of both pools, for read-only passes over the whole tree.
/// Inner-pool ids index the first four, leaf-pool ids (less [`LEAF_POOL`])
/// the last two; the extras are empty when extras are off.
#[derive(Clone, Copy)]
pub(crate) struct Parts<'a> {
    pub values: &'a [f32],
    pub masks: &'a [u8],
    pub first_child: &'a [NodeId],
    pub extras: &'a [u32],
    pub leaf_values: &'a [f32],
    pub leaf_extras: &'a [u32],
}

impl Parts<'_> {
    /// The value of any node.
    #[inline(always)]
    pub fn value(&self, n: NodeId) -> f32 {
        if in_leaf_pool(n) {
            self.leaf_values[leaf_index(n)]
        } else {
            self.values[n as usize]
        }
    }

    /// The extra of any node (0 when extras are off).
    #[inline(always)]
    pub fn extra(&self, n: NodeId) -> u32 {
        let e = if in_leaf_pool(n) { self.leaf_extras.get(leaf_index(n)) } else { self.extras.get(n as usize) };
        e.copied().unwrap_or(0)
    }

    /// The child mask of any node (0 in the leaf pool).
    #[inline(always)]
    pub fn mask(&self, n: NodeId) -> u8 {
        if in_leaf_pool(n) {
            0
        } else {
            self.masks[n as usize]
        }
    }

    /// One step of a descent: child `pos` of `n`, which lies above depth
    /// 16 (so in the inner pool, indexed without the pool check), or
    /// `Err(mask of n)` when that child does not exist.
    #[inline(always)]
    pub fn descend(&self, n: NodeId, pos: u64) -> Result<NodeId, u8> {
        let m = self.masks[n as usize];
        if m & (1 << pos) == 0 {
            Err(m)
        } else {
            Ok(self.first_child[n as usize] + (u32::from(m) & ((1 << pos) - 1)).count_ones())
        }
    }

    /// Asks for the cache lines of the group starting at `first`.
    #[inline(always)]
    pub fn prefetch_group(&self, first: NodeId) {
        if in_leaf_pool(first) {
            prefetch(self.leaf_values, leaf_index(first));
            prefetch(self.leaf_extras, leaf_index(first));
        } else {
            let i = first as usize;
            prefetch(self.masks, i);
            prefetch(self.values, i);
            prefetch(self.first_child, i);
            prefetch(self.extras, i);
        }
    }
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
        self.free.slots + self.leaf_free.slots
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
        let k = self.masks[n as usize].count_ones() as usize;
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
            Some(self.first_child[n as usize] + (m & ((1u8 << pos) - 1)).count_ones())
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
        // grow by an eighth rather than doubling: large reallocations are
        // remapped in place by the allocator, and peak memory stays low; keep
        // room for eight more slots, which the fast path appends
        let more = (len + 8).max(start / 8).max(1024);
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

    /// Makes room for `len` more leaf slots, growing by an eighth.
    #[cold]
    #[inline(never)]
    fn grow_leaves(&mut self, len: usize) {
        let start = self.leaf_values.len();
        assert!(start + len < LEAF_POOL as usize, "node arena exceeds 2^31 leaf slots");
        let more = len.max(start / 8).max(1024);
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
        let old_len = m.count_ones() as usize;
        let old = self.first_child[n as usize];
        let new = self.alloc_run(old_len + 1, leaf_group(depth));
        debug_assert!(old_len == 0 || in_leaf_pool(old) == in_leaf_pool(new), "depth {depth} is not n's");
        let rank = (m & ((1u8 << pos) - 1)).count_ones();
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
        let old_len = m.count_ones() as usize;
        let old = self.first_child[n as usize];
        let rank = (m & ((1u8 << pos) - 1)).count_ones();
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
            let len = m.count_ones();
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
            let k = self.masks[n as usize].count_ones();
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

/// Spare slots a worker of a parallel update claims at a time.
const CHUNK: usize = 256;

/// Spare slots to make in a pool so that the workers of a parallel update,
/// which allocate at most `allocations` slots between them (runs of at
/// most 8), never run out: a worker claims a new chunk only when fewer than
/// 8 slots are left in its last, so all its chunks but the last are filled
/// to `CHUNK - 7` slots at least.
fn room_for(allocations: usize, workers: usize) -> usize {
    (allocations * CHUNK).div_ceil(CHUNK - 7) + workers * CHUNK
}

impl NodeArena {
    /// Runs `f` with the arena shared by `workers` threads ([`SharedArena`])
    /// and the free lists dealt out to them (`f` hands them back). The
    /// workers allocate from spare slots, made here for a budget: a worker
    /// takes a task only once it has reserved the task's worst case from
    /// the budget ([`ArenaWorker::reserve`]). The worst cases of all tasks
    /// (`bound`, inner and leaf pool) are four times what an outdoor scan
    /// allocates and a hundred times what a scan of mapped space does, so
    /// the budget is twice what the last parallel update allocated (a
    /// quarter of `bound` at first) plus the largest task's worst case
    /// (`largest`), and never more than `bound`; tasks the budget cannot
    /// cover are left to the caller. The slots claimed join the pools, the rest stay spare.
    /// Spare slots are initialised when made (no slot is ever
    /// uninitialised), so they are made once and kept for later runs.
    pub(crate) fn with_shared<R>(
        &mut self,
        bound: (usize, usize),
        largest: (usize, usize),
        workers: usize,
        f: impl FnOnce(&SharedArena<'_>, Vec<ArenaFree>) -> (R, Vec<ArenaFree>),
    ) -> R {
        // with no history, a quarter of the worst case (a scan of new
        // space allocates that much)
        let (i, l) = self.last_shared_use.unwrap_or((bound.0 / 4, bound.1 / 4));
        let budget = ((2 * i + largest.0).min(bound.0), (2 * l + largest.1).min(bound.1));
        let (inner, leaf) = (room_for(budget.0, workers), room_for(budget.1, workers));
        let free = std::mem::take(&mut self.free).deal(workers);
        let leaf_free = std::mem::take(&mut self.leaf_free).deal(workers);
        let lists = free.into_iter().zip(leaf_free).map(|(free, leaf_free)| ArenaFree { free, leaf_free }).collect();
        let (n, nl) = (self.inner_len(), self.leaf_len());
        assert!(n + inner < LEAF_POOL as usize, "node arena exceeds 2^31 inner slots");
        assert!(nl + leaf < LEAF_POOL as usize, "node arena exceeds 2^31 leaf slots");
        self.make_spare(inner, false);
        self.make_spare(leaf, true);
        let (result, lists, ends) = {
            let shared = SharedArena {
                inner: SharedPool {
                    arrays: Arrays::of(&mut self.values, &mut self.masks, &mut self.first_child, &mut self.extras),
                    next: AtomicUsize::new(n),
                    budget: AtomicUsize::new(budget.0),
                },
                leaf: SharedPool {
                    arrays: Arrays::of(&mut self.leaf_values, &mut [], &mut [], &mut self.leaf_extras),
                    next: AtomicUsize::new(nl),
                    budget: AtomicUsize::new(budget.1),
                },
                default_extra: self.default_extra,
            };
            let (result, lists) = f(&shared, lists);
            let used = |p: &SharedPool, budget: usize| budget - p.budget.load(Relaxed);
            self.last_shared_use = Some((used(&shared.inner, budget.0), used(&shared.leaf, budget.1)));
            (result, lists, (shared.inner.claimed(), shared.leaf.claimed()))
        };
        // what was not claimed stays as spare slots for later runs
        self.spare = self.values.len() - ends.0;
        self.leaf_spare = self.leaf_values.len() - ends.1;
        for list in lists {
            self.free.append(list.free);
            self.leaf_free.append(list.leaf_free);
        }
        result
    }

    /// Makes at least `k` spare slots in a pool, growing its arrays by an
    /// eighth at least, as the serial path does. Spare slots are written
    /// once, when made, and reused until taken.
    fn make_spare(&mut self, k: usize, leaf: bool) {
        let spare = if leaf { self.leaf_spare } else { self.spare };
        if spare >= k {
            return;
        }
        let extra = self.default_extra;
        let (values, extras) =
            if leaf { (&mut self.leaf_values, &mut self.leaf_extras) } else { (&mut self.values, &mut self.extras) };
        let (len, add) = (values.len(), k - spare);
        let more = if len + add > values.capacity() { add.max(len / 8) } else { 0 };
        values.reserve_exact(more);
        values.resize(len + add, 0.0);
        if let Some(e) = extra {
            extras.reserve_exact(more);
            extras.resize(len + add, e);
        }
        if leaf {
            self.leaf_spare = k;
        } else {
            self.masks.reserve_exact(more);
            self.masks.resize(len + add, 0);
            self.first_child.reserve_exact(more);
            self.first_child.resize(len + add, NO_CHILD);
            self.spare = k;
        }
    }
}

/// A worker's free lists, for both pools.
#[derive(Default)]
pub(crate) struct ArenaFree {
    free: FreeRuns,
    leaf_free: FreeRuns,
}

/// A pool's arrays as atomics (masks and first children empty in the leaf
/// pool, extras empty when off).
struct Arrays<'a> {
    values: &'a [AtomicU32],
    masks: &'a [AtomicU8],
    first_child: &'a [AtomicU32],
    extras: &'a [AtomicU32],
}

impl<'a> Arrays<'a> {
    fn of(values: &'a mut [f32], masks: &'a mut [u8], first_child: &'a mut [u32], extras: &'a mut [u32]) -> Self {
        Arrays {
            values: atomic_f32s(values),
            masks: atomic_u8s(masks),
            first_child: atomic_u32s(first_child),
            extras: atomic_u32s(extras),
        }
    }
}

// the atomics stand in for the arrays' elements: same size and alignment
const _: () = assert!(std::mem::size_of::<AtomicU32>() == 4 && std::mem::align_of::<AtomicU32>() == 4);
const _: () = assert!(std::mem::align_of::<f32>() == 4 && std::mem::align_of::<u32>() == 4);
const _: () = assert!(std::mem::size_of::<AtomicU8>() == 1 && std::mem::align_of::<AtomicU8>() == 1);

fn atomic_u32s(s: &mut [u32]) -> &[AtomicU32] {
    // SAFETY: AtomicU32 has the size, alignment (checked above) and bit
    // validity of u32; the exclusive borrow means nothing else reads or
    // writes the slice while the atomics are in use.
    unsafe { &*(s as *mut [u32] as *const [AtomicU32]) }
}

fn atomic_f32s(s: &mut [f32]) -> &[AtomicU32] {
    // SAFETY: as in `atomic_u32s`, f32 having the size and alignment of
    // u32, and every bit pattern being valid for both.
    unsafe { &*(s as *mut [f32] as *const [AtomicU32]) }
}

fn atomic_u8s(s: &mut [u8]) -> &[AtomicU8] {
    // SAFETY: as in `atomic_u32s`, for u8 and AtomicU8.
    unsafe { &*(s as *mut [u8] as *const [AtomicU8]) }
}

/// The arena, shared by the workers of a parallel batch update
/// ([`NodeArena::with_shared`]). Each worker changes only the nodes of its
/// own subtrees, so no slot is used by two; the arrays are relaxed atomics
/// all the same (plain loads and stores on x86-64), so that a slot used
/// twice would be a wrong answer, never a data race.
pub(crate) struct SharedArena<'a> {
    inner: SharedPool<'a>,
    leaf: SharedPool<'a>,
    default_extra: Option<u32>,
}

/// One pool: its slots, then spare slots that workers claim by chunks.
struct SharedPool<'a> {
    arrays: Arrays<'a>,
    /// The first unclaimed slot.
    next: AtomicUsize,
    /// Slots not reserved by a task ([`ArenaWorker::reserve`]).
    budget: AtomicUsize,
}

impl SharedPool<'_> {
    /// Where the claimed slots end.
    fn claimed(&self) -> usize {
        self.next.load(Relaxed).min(self.arrays.values.len())
    }

    /// Takes `k` slots from the budget, if it has them.
    fn reserve(&self, k: usize) -> bool {
        self.budget.fetch_update(Relaxed, Relaxed, |b| b.checked_sub(k)).is_ok()
    }

    /// Claims a chunk of spare slots; returns its first slot. The budget
    /// keeps the claims within the spare slots: a worker claims a chunk
    /// only for the slots of a task's reservation, and only when fewer
    /// than 8 are left in its last (see [`room_for`]).
    fn claim(&self) -> usize {
        let start = self.next.fetch_add(CHUNK, Relaxed);
        assert!(start + CHUNK <= self.arrays.values.len(), "a parallel update outgrew the spare slots made for it");
        start
    }
}

impl SharedArena<'_> {
    /// A worker that allocates from `free` first, then from chunks of
    /// spare slots.
    pub(crate) fn worker(&self, free: ArenaFree) -> ArenaWorker<'_, '_> {
        ArenaWorker { shared: self, lists: free, chunk: (0, 0), leaf_chunk: (0, 0), reserved: (0, 0), taken: (0, 0) }
    }

    /// The arrays holding node `n`, and its index there.
    #[inline(always)]
    fn pool(&self, n: NodeId) -> (&Arrays<'_>, usize) {
        if in_leaf_pool(n) {
            (&self.leaf.arrays, leaf_index(n))
        } else {
            (&self.inner.arrays, n as usize)
        }
    }
}

/// One worker's view of a [`SharedArena`]: its own free lists, and the
/// chunk of spare slots it allocates new runs from.
pub(crate) struct ArenaWorker<'s, 'a> {
    shared: &'s SharedArena<'a>,
    lists: ArenaFree,
    /// The unallocated rest of the worker's chunk of each pool, as
    /// (first, end) slot indices.
    chunk: (usize, usize),
    leaf_chunk: (usize, usize),
    /// The current task's reservation, and the slots it took from chunks.
    reserved: (usize, usize),
    taken: (usize, usize),
}

impl ArenaWorker<'_, '_> {
    /// Reserves a task's worst case (inner-pool and leaf-pool slots) from
    /// the budget of spare slots; `false` when the budget cannot cover it,
    /// and the task must not be applied through this worker.
    pub(crate) fn reserve(&mut self, k: (usize, usize)) -> bool {
        let (inner, leaf) = (&self.shared.inner, &self.shared.leaf);
        if !inner.reserve(k.0) {
            return false;
        }
        if !leaf.reserve(k.1) {
            inner.budget.fetch_add(k.0, Relaxed);
            return false;
        }
        self.reserved = k;
        self.taken = (0, 0);
        true
    }

    /// Ends the task reserved for: gives back what it did not take.
    pub(crate) fn release(&mut self) {
        let (r, t) = (self.reserved, self.taken);
        assert!(t.0 <= r.0 && t.1 <= r.1, "a task took more slots than its reservation");
        self.shared.inner.budget.fetch_add(r.0 - t.0, Relaxed);
        self.shared.leaf.budget.fetch_add(r.1 - t.1, Relaxed);
        self.reserved = (0, 0);
    }

    /// Ends the worker; the rest of its chunks joins its free lists.
    pub(crate) fn finish(mut self) -> ArenaFree {
        let (a, b) = self.chunk;
        self.lists.free.push_span(a as NodeId, b - a);
        let (a, b) = self.leaf_chunk;
        self.lists.leaf_free.push_span(LEAF_POOL | a as NodeId, b - a);
        self.lists
    }

    /// `len` slots from the worker's chunk of a pool, claiming a new chunk
    /// when fewer are left (the rest becomes a free run).
    #[inline]
    fn take(&mut self, len: usize, leaf: bool) -> NodeId {
        let (chunk, pool, free, tag) = if leaf {
            (&mut self.leaf_chunk, &self.shared.leaf, &mut self.lists.leaf_free, LEAF_POOL)
        } else {
            (&mut self.chunk, &self.shared.inner, &mut self.lists.free, 0)
        };
        if chunk.1 - chunk.0 < len {
            free.push(tag | chunk.0 as NodeId, chunk.1 - chunk.0);
            let start = pool.claim();
            *chunk = (start, start + CHUNK);
        }
        let id = chunk.0;
        chunk.0 += len;
        if leaf {
            self.taken.1 += len;
        } else {
            self.taken.0 += len;
        }
        tag | id as NodeId
    }
}

impl NodeStore for ArenaWorker<'_, '_> {
    #[inline(always)]
    fn value(&self, n: NodeId) -> f32 {
        let (a, i) = self.shared.pool(n);
        f32::from_bits(a.values[i].load(Relaxed))
    }
    #[inline(always)]
    fn set_value(&mut self, n: NodeId, v: f32) {
        let (a, i) = self.shared.pool(n);
        a.values[i].store(v.to_bits(), Relaxed);
    }
    #[inline(always)]
    fn extra(&self, n: NodeId) -> u32 {
        let (a, i) = self.shared.pool(n);
        a.extras.get(i).map_or(0, |e| e.load(Relaxed))
    }
    #[inline(always)]
    fn set_extra(&mut self, n: NodeId, v: u32) {
        let (a, i) = self.shared.pool(n);
        if let Some(e) = a.extras.get(i) {
            e.store(v, Relaxed);
        }
    }
    #[inline(always)]
    fn mask(&self, n: NodeId) -> u8 {
        if in_leaf_pool(n) {
            return 0;
        }
        self.shared.inner.arrays.masks[n as usize].load(Relaxed)
    }
    #[inline(always)]
    fn first_child(&self, n: NodeId) -> NodeId {
        if in_leaf_pool(n) {
            return NO_CHILD;
        }
        self.shared.inner.arrays.first_child[n as usize].load(Relaxed)
    }
    #[inline(always)]
    fn set_children(&mut self, n: NodeId, mask: u8, first: NodeId) {
        let a = &self.shared.inner.arrays;
        a.masks[n as usize].store(mask, Relaxed);
        a.first_child[n as usize].store(first, Relaxed);
    }
    #[inline(always)]
    fn default_extra(&self) -> Option<u32> {
        self.shared.default_extra
    }
    #[inline]
    fn alloc_run(&mut self, len: usize, leaf: bool) -> NodeId {
        let list = if leaf { &mut self.lists.leaf_free } else { &mut self.lists.free };
        match list.pop(len) {
            Some(start) => start,
            None => self.take(len, leaf),
        }
    }
    #[inline]
    fn free_run(&mut self, start: NodeId, len: usize) {
        if in_leaf_pool(start) {
            self.lists.leaf_free.push(start, len);
        } else {
            self.lists.free.push(start, len);
        }
    }
    #[inline(always)]
    fn copy_slot(&mut self, from: NodeId, to: NodeId) {
        let v = self.value(from);
        self.set_value(to, v);
        if self.shared.default_extra.is_some() {
            let e = self.extra(from);
            self.set_extra(to, e);
        }
        if !in_leaf_pool(from) {
            let (m, f) = (self.mask(from), self.first_child(from));
            self.set_children(to, m, f);
        }
    }
    #[inline(always)]
    fn init_slot(&mut self, id: NodeId, value: f32, extra: Option<u32>) {
        self.set_value(id, value);
        if let Some(e) = extra {
            self.set_extra(id, e);
        }
        if !in_leaf_pool(id) {
            self.set_children(id, 0, NO_CHILD);
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

/// Why [`PreorderFill::push`] refused a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FillError {
    /// The node has children but lies at depth 16.
    TooDeep,
    /// Every announced node has been given already.
    Complete,
}

/// An arena being filled in pre-order. Its arrays are initialised (zero,
/// extras the default) up to their length, which is the capacity in slots;
/// the first `len` inner and `leaf_len` leaf slots are in use.
struct Slots {
    arena: NodeArena,
    len: usize,
    leaf_len: usize,
    /// Expected node count; capacity grows toward it, never past what the
    /// nodes given so far justify (see [`Self::grow`]).
    hint: usize,
}

/// Grows `v` to `cap` elements of `fill`. Fresh zeroed memory comes from
/// the allocator already zeroed, so large zero reservations cost no writes
/// (nor resident memory) until used.
fn fill_to<T: Clone>(v: &mut Vec<T>, cap: usize, fill: T) {
    if v.is_empty() {
        *v = vec![fill; cap];
    } else {
        v.resize(cap, fill);
    }
}

impl Slots {
    fn new(default_extra: Option<u32>, hint: usize) -> Self {
        Slots { arena: NodeArena { default_extra, ..Default::default() }, len: 0, leaf_len: 0, hint }
    }

    /// Makes room for `n` more slots at once in each pool (either may need
    /// them all).
    fn reserve(&mut self, n: usize) {
        self.reserve_pool(n, false);
        self.reserve_pool(n, true);
    }

    fn reserve_pool(&mut self, n: usize, leaf: bool) {
        let a = &mut self.arena;
        let len = if leaf { self.leaf_len } else { self.len };
        let cap = len + n.min(LEAF_POOL as usize - 1 - len);
        if leaf {
            if cap > a.leaf_values.len() {
                fill_to(&mut a.leaf_values, cap, 0.0);
                if let Some(e) = a.default_extra {
                    fill_to(&mut a.leaf_extras, cap, e);
                }
            }
        } else if cap > a.values.len() {
            fill_to(&mut a.values, cap, 0.0);
            fill_to(&mut a.masks, cap, 0);
            fill_to(&mut a.first_child, cap, NO_CHILD);
            if let Some(e) = a.default_extra {
                fill_to(&mut a.extras, cap, e);
            }
        }
    }

    /// Makes room for `k` more slots in a pool: doubles its capacity,
    /// capped at the hint while the hint is still ahead, so memory stays
    /// within twice what the input has really announced.
    #[cold]
    #[inline(never)]
    fn grow(&mut self, k: usize, leaf: bool) {
        let len = if leaf { self.leaf_len } else { self.len };
        assert!(len + k < LEAF_POOL as usize, "node arena exceeds 2^31 slots in a pool");
        let mut want = (2 * len).max(1024);
        if self.hint >= len + k {
            want = want.min(self.hint);
        }
        self.reserve_pool(want.max(len + k) - len, leaf);
    }

    /// Takes `k` more inner slots; returns the first.
    #[inline(always)]
    fn take(&mut self, k: usize) -> NodeId {
        let first = self.len;
        if first + k > self.arena.values.len() {
            self.grow(k, false);
        }
        self.len = first + k;
        first as NodeId
    }

    /// Takes `k` more leaf slots; returns the first.
    #[inline(always)]
    fn take_leaves(&mut self, k: usize) -> NodeId {
        let first = self.leaf_len;
        if first + k > self.arena.leaf_values.len() {
            self.grow(k, true);
        }
        self.leaf_len = first + k;
        LEAF_POOL | first as NodeId
    }

    /// A new child group of `k` slots for a node at `depth`.
    #[inline(always)]
    fn take_group(&mut self, k: usize, depth: usize) -> NodeId {
        if leaf_group(depth as u8) {
            self.take_leaves(k)
        } else {
            self.take(k)
        }
    }

    /// The values of the group of `k` slots from `first`.
    #[inline(always)]
    fn group_values(&mut self, first: NodeId, k: usize) -> &mut [f32] {
        let a = &mut self.arena;
        if in_leaf_pool(first) {
            &mut a.leaf_values[leaf_index(first)..][..k]
        } else {
            &mut a.values[first as usize..][..k]
        }
    }

    /// The arena of the slots in use.
    fn into_arena(self) -> NodeArena {
        let (len, leaf_len) = (self.len, self.leaf_len);
        let mut a = self.arena;
        let extras = a.default_extra.is_some();
        a.values.truncate(len);
        a.masks.truncate(len);
        a.first_child.truncate(len);
        a.extras.truncate(if extras { len } else { 0 });
        a.leaf_values.truncate(leaf_len);
        a.leaf_extras.truncate(if extras { leaf_len } else { 0 });
        a.shrink_to_fit();
        a
    }
}

/// Fills an arena from nodes given in depth-first pre-order (children
/// 0..7): each node's child group is allocated when the node is given, so
/// the result has the layout of `NodeArena::compacted` and no free slots.
///
/// Open child groups are kept on a fixed stack, one per depth: the group
/// at index `d` holds the nodes of depth `d + 1`; groups whose nodes have
/// all been given are closed after each leaf, so the depth of the next node
/// is the number of open groups.
pub(crate) struct PreorderFill {
    slots: Slots,
    /// Per open group: its next slot and its end.
    open: [(NodeId, NodeId); 16],
    depth: usize,
}

impl PreorderFill {
    /// An empty fill; `hint` (unchecked, e.g. a header's size field) is the
    /// node count to grow toward.
    pub(crate) fn new(default_extra: Option<u32>, hint: usize) -> Self {
        PreorderFill { slots: Slots::new(default_extra, hint), open: [(0, 0); 16], depth: 0 }
    }

    /// Makes room for `n` more nodes at once (callers cap `n` by what their
    /// input can still hold).
    pub(crate) fn reserve(&mut self, n: usize) {
        self.slots.reserve(n);
    }

    /// True once the root and every announced node have been given.
    #[inline(always)]
    pub(crate) fn is_complete(&self) -> bool {
        self.slots.len != 0 && self.depth == 0
    }

    /// Depth of the next node (0 for the root); `None` when complete.
    pub(crate) fn next_depth(&self) -> Option<u8> {
        if self.is_complete() {
            None
        } else {
            Some(self.depth as u8)
        }
    }

    /// Nodes given or announced so far.
    pub(crate) fn len(&self) -> usize {
        self.slots.len + self.slots.leaf_len
    }

    /// Gives the next node: its value, its extra (`None` keeps the
    /// default) and its child mask.
    #[inline(always)]
    pub(crate) fn push(&mut self, value: f32, extra: Option<u32>, mask: u8) -> Result<(), FillError> {
        let depth = self.depth;
        let id = if depth > 0 {
            let g = &mut self.open[depth - 1];
            let id = g.0;
            g.0 += 1;
            id
        } else if self.slots.len == 0 {
            self.slots.take(1)
        } else {
            return Err(FillError::Complete);
        };
        let s = &mut self.slots;
        s.arena.set_value(id, value);
        if let Some(e) = extra {
            s.arena.set_extra(id, e);
        }
        if mask != 0 {
            if depth >= 16 {
                return Err(FillError::TooDeep);
            }
            let k = mask.count_ones();
            let first = s.take_group(k as usize, depth);
            s.arena.masks[id as usize] = mask;
            s.arena.first_child[id as usize] = first;
            self.open[depth] = (first, first + k);
            self.depth = depth + 1;
        } else {
            // close the groups this leaf completed
            while self.depth > 0 && self.open[self.depth - 1].0 == self.open[self.depth - 1].1 {
                self.depth -= 1;
            }
        }
        Ok(())
    }

    /// The arena (root at 0) once complete, `None` before the root or while
    /// nodes are missing.
    pub(crate) fn finish(self) -> Option<NodeArena> {
        self.is_complete().then(|| self.slots.into_arena())
    }
}

/// Fills an arena from a `.bt` node stream: one record per node with
/// children, in depth-first pre-order, giving a 2-bit label per child
/// (`0` absent, `1` free leaf, `2` occupied leaf, `3` inner node whose
/// record comes later). Leaves get the free or occupied value, inner nodes
/// the maximum of their children once those are known, nodes announced as
/// inner but given no children `-f32::MAX` (OctoMap's `getMaxChildLogOdds`
/// of no children); the root keeps its initial value. The layout is that
/// of [`PreorderFill`].
pub(crate) struct LabelFill {
    slots: Slots,
    /// Value per label: unused, free, occupied, inner placeholder.
    label_values: [f32; 4],
    /// Per depth `d`, the child group of the node at depth `d` whose
    /// subtree is being read.
    open: [OpenGroup; 16],
    depth: usize,
    started: bool,
}

#[derive(Clone, Copy, Default)]
struct OpenGroup {
    parent: NodeId,
    first: NodeId,
    mask: u8,
    /// Children labelled inner whose record has not come yet.
    due: u8,
}

/// Bits `0, 2, 4, .., 14` of `x` as one byte.
#[inline(always)]
fn even_bits(x: u16) -> u8 {
    let x = x & 0x5555;
    let x = (x | (x >> 1)) & 0x3333;
    let x = (x | (x >> 2)) & 0x0f0f;
    ((x | (x >> 4)) & 0x00ff) as u8
}

impl LabelFill {
    /// A fill whose root holds `root_value`; leaves get `free` or
    /// `occupied`. `hint` as for [`PreorderFill::new`].
    pub(crate) fn new(default_extra: Option<u32>, hint: usize, root_value: f32, free: f32, occupied: f32) -> Self {
        let mut slots = Slots::new(default_extra, hint);
        let root = slots.take(1);
        slots.arena.values[root as usize] = root_value;
        LabelFill {
            slots,
            label_values: [0.0, free, occupied, -f32::MAX],
            open: [OpenGroup::default(); 16],
            depth: 0,
            started: false,
        }
    }

    /// Makes room for `n` more nodes at once.
    pub(crate) fn reserve(&mut self, n: usize) {
        self.slots.reserve(n);
    }

    /// True once the root and every announced inner node have their record.
    #[inline(always)]
    pub(crate) fn is_complete(&self) -> bool {
        self.started && self.depth == 0
    }

    /// Gives the next record: child `i`'s label in bits `2i, 2i + 1`.
    #[inline(always)]
    pub(crate) fn push(&mut self, labels: u16) -> Result<(), FillError> {
        let depth = self.depth;
        let id = if depth > 0 {
            let g = &mut self.open[depth - 1];
            let pos = g.due.trailing_zeros();
            g.due &= g.due - 1;
            g.first + (u32::from(g.mask) & ((1u32 << pos) - 1)).count_ones()
        } else if !self.started {
            self.started = true;
            0
        } else {
            return Err(FillError::Complete);
        };
        let mask = even_bits(labels | (labels >> 1));
        if mask == 0 {
            self.close_groups();
            return Ok(());
        }
        if depth >= 16 {
            return Err(FillError::TooDeep);
        }
        let due = even_bits(labels & (labels >> 1));
        let k = mask.count_ones();
        let s = &mut self.slots;
        let first = s.take_group(k as usize, depth);
        let mut rest = mask;
        for v in s.group_values(first, k as usize) {
            let pos = rest.trailing_zeros();
            rest &= rest - 1;
            *v = self.label_values[usize::from((labels >> (2 * pos)) as u8 & 3)];
        }
        s.arena.masks[id as usize] = mask;
        s.arena.first_child[id as usize] = first;
        if due != 0 {
            self.open[depth] = OpenGroup { parent: id, first, mask, due };
            self.depth = depth + 1;
        } else {
            if id != 0 {
                s.arena.values[id as usize] = max_of(s.group_values(first, k as usize));
            }
            self.close_groups();
        }
        Ok(())
    }

    /// Closes the groups whose subtrees are now complete, giving each
    /// parent (but the root) the maximum of its children.
    #[inline(always)]
    fn close_groups(&mut self) {
        while self.depth > 0 {
            let g = self.open[self.depth - 1];
            if g.due != 0 {
                break;
            }
            if g.parent != 0 {
                let max = max_of(self.slots.group_values(g.first, g.mask.count_ones() as usize));
                self.slots.arena.values[g.parent as usize] = max;
            }
            self.depth -= 1;
        }
    }

    /// The arena once complete.
    pub(crate) fn finish(self) -> Option<NodeArena> {
        self.is_complete().then(|| self.slots.into_arena())
    }
}

/// `getMaxChildLogOdds` over a child group.
#[inline(always)]
fn max_of(values: &[f32]) -> f32 {
    values.iter().fold(-f32::MAX, |m, &v| if v > m { v } else { m })
}

/// Arenas (and mapped files) up to this size are prefetched whole before
/// an iteration: a quarter of the smallest L2 of current x86 and Arm cores
/// (1 MB here), so the lines stay there for the walk.
pub(crate) const WHOLE_PREFETCH_BYTES: usize = 256 << 10;

/// [`prefetch`] for every 64-byte line of `s`.
pub(crate) fn prefetch_lines<T>(s: &[T]) {
    let step = (64 / std::mem::size_of::<T>().max(1)).max(1);
    for i in (0..s.len()).step_by(step) {
        prefetch(s, i);
    }
    if let Some(last) = s.len().checked_sub(1) {
        prefetch(s, last);
    }
}

/// Asks for the cache line holding `s[i]` (nothing when `i` is out of
/// range): tree walks over an arena whose groups lie scattered after many
/// updates ask for the groups they will visit next all at once.
#[inline(always)]
pub(crate) fn prefetch<T>(s: &[T], i: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(x) = s.get(i) {
        // SAFETY: a prefetch is a hint that never faults nor changes memory;
        // SSE is part of the x86_64 baseline
        unsafe { std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>((x as *const T).cast()) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (s, i);
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
        assert_eq!(a.leaf_free.slots, 3);
        let kids: Vec<_> = a.children(p).map(|(i, c)| (i, a.value(c), a.extra(c))).collect();
        assert_eq!(kids, vec![(2, 2.0, 102), (4, 4.0, 104), (6, 6.0, 106)]);
        // a freed run is reused, in its own pool
        assert_eq!(a.remove_child(p, 4), 1);
        assert_eq!(a.leaf_values.len(), 6);
        assert_eq!(a.leaf_free.slots, 4);
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

    /// Extends a chain of child 0s from `n` at `depth` down to `to`.
    fn chain_below(a: &mut NodeArena, mut n: NodeId, depth: u8, to: u8) -> NodeId {
        for d in depth..to {
            n = a.insert_child(n, 0, 0.0, d);
        }
        n
    }
}
