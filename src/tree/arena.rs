//! The node arena: nine bytes per node, no pointers, no per-node allocation.
//!
//! Nodes live in three parallel arrays indexed by a `u32` node id: the
//! value (`f32` log-odds), a child mask (bit `i` set when child `i`
//! exists) and the id of the first child. The existing children of a node
//! form one contiguous *group* of exactly `popcount(mask)` slots, in child
//! order, so child `i` sits at `first_child + popcount(mask & ((1 << i) - 1))`.
//! A group that grows or shrinks moves to a slot run of the new size; the
//! old run goes on a free list of its size and is reused. Nodes therefore
//! move when their siblings change: node ids are valid only until the next
//! structural change. [`NodeArena::compacted`] re-lays every group in
//! depth-first (Morton) order with no free runs left.
//!
//! Trees whose nodes carry more than log-odds (colour, time stamp, count)
//! add a fourth array of `u32` *extras*; plain trees leave it empty and pay
//! nothing for it.

/// Id of a node in the arena.
pub type NodeId = u32;

/// Sentinel for "no first child" (leaves).
const NO_CHILD: NodeId = 0;

#[derive(Clone, Debug, Default)]
pub struct NodeArena {
    values: Vec<f32>,
    masks: Vec<u8>,
    first_child: Vec<NodeId>,
    /// Per-node payload beyond the value; empty unless enabled.
    extras: Vec<u32>,
    /// The extra of a newly created node; `None` when extras are off.
    default_extra: Option<u32>,
    /// Free slot runs by length (index 1..=8).
    free: [Vec<NodeId>; 9],
    free_slots: usize,
}

/// Arena statistics: slots in use and held, and the bytes really reserved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ArenaUsage {
    pub live_slots: usize,
    pub free_slots: usize,
    pub bytes_reserved: usize,
}

impl NodeArena {
    /// An arena holding only a root (id 0) with the given value.
    pub fn with_root(value: f32) -> Self {
        Self::with_root_and_extras(value, None)
    }

    /// Like [`Self::with_root`], with a per-node `u32` extra when
    /// `default_extra` is given (new nodes start with it).
    pub fn with_root_and_extras(value: f32, default_extra: Option<u32>) -> Self {
        let mut a = NodeArena { default_extra, ..Default::default() };
        a.push_run(1);
        a.values[0] = value;
        a
    }

    /// Slots held (live and free).
    #[inline]
    pub fn slot_count(&self) -> usize {
        self.values.len()
    }

    /// Slots on the free lists (0 after compaction or when read from a file).
    #[inline]
    pub fn free_slot_count(&self) -> usize {
        self.free_slots
    }

    #[inline(always)]
    pub fn has_extras(&self) -> bool {
        self.default_extra.is_some()
    }

    /// The extra of `n` (0 when extras are off).
    #[inline(always)]
    pub fn extra(&self, n: NodeId) -> u32 {
        self.extras.get(n as usize).copied().unwrap_or(0)
    }

    #[inline(always)]
    pub fn set_extra(&mut self, n: NodeId, v: u32) {
        if let Some(e) = self.extras.get_mut(n as usize) {
            *e = v;
        }
    }

    #[inline(always)]
    pub fn value(&self, n: NodeId) -> f32 {
        self.values[n as usize]
    }

    #[inline(always)]
    pub fn set_value(&mut self, n: NodeId, v: f32) {
        self.values[n as usize] = v;
    }

    #[inline(always)]
    pub fn mask(&self, n: NodeId) -> u8 {
        self.masks[n as usize]
    }

    #[inline(always)]
    pub fn has_children(&self, n: NodeId) -> bool {
        self.masks[n as usize] != 0
    }

    #[inline(always)]
    pub fn first_child(&self, n: NodeId) -> NodeId {
        self.first_child[n as usize]
    }

    /// Prefetches the child groups of `n`'s inner children: a depth-first
    /// walk visits them next, and on a tree fresh from updates they lie
    /// scattered, so asking for all of them at once overlaps the misses.
    #[inline(always)]
    pub fn prefetch_grandchildren(&self, n: NodeId) {
        let first = self.first_child[n as usize] as usize;
        let k = self.masks[n as usize].count_ones() as usize;
        for c in first..first + k {
            if self.masks[c] != 0 {
                let fc = self.first_child[c] as usize;
                prefetch(&self.masks, fc);
                prefetch(&self.values, fc);
                prefetch(&self.first_child, fc);
            }
        }
    }

    /// Id of child `pos` of `n`, if it exists.
    #[inline(always)]
    pub fn child(&self, n: NodeId, pos: usize) -> Option<NodeId> {
        let m = self.masks[n as usize];
        if m & (1 << pos) == 0 {
            None
        } else {
            Some(self.first_child[n as usize] + (m & ((1u8 << pos) - 1)).count_ones())
        }
    }

    /// Children of `n` as `(child index, id)` in child order.
    #[inline]
    pub fn children(&self, n: NodeId) -> impl Iterator<Item = (usize, NodeId)> {
        let m = self.masks[n as usize];
        let first = self.first_child[n as usize];
        (0..8usize).filter(move |&i| m & (1 << i) != 0).scan(first, |next, i| {
            let id = *next;
            *next += 1;
            Some((i, id))
        })
    }

    /// Appends `len` default slots; returns the first id.
    #[inline]
    fn push_run(&mut self, len: usize) -> NodeId {
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
        assert!(start + len <= u32::MAX as usize - 2, "node arena exceeds 2^32 slots");
        // grow by a quarter rather than doubling: large reallocations are
        // remapped in place by the allocator, and peak memory stays low; keep
        // room for eight more slots, which the fast path appends
        let more = (len + 8).max(start / 4).max(1024);
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

    fn alloc_run(&mut self, len: usize) -> NodeId {
        match self.free[len].pop() {
            Some(start) => {
                self.free_slots -= len;
                start
            }
            None => self.push_run(len),
        }
    }

    fn free_run(&mut self, start: NodeId, len: usize) {
        if len > 0 {
            self.free[len].push(start);
            self.free_slots += len;
        }
    }

    #[inline(always)]
    fn copy_slot(&mut self, from: NodeId, to: NodeId) {
        let (f, t) = (from as usize, to as usize);
        self.values[t] = self.values[f];
        self.masks[t] = self.masks[f];
        self.first_child[t] = self.first_child[f];
        if self.default_extra.is_some() {
            self.extras[t] = self.extras[f];
        }
    }

    /// Makes slot `id` a fresh leaf holding `value` and `extra`.
    #[inline(always)]
    fn init_slot(&mut self, id: NodeId, value: f32, extra: Option<u32>) {
        let i = id as usize;
        self.values[i] = value;
        self.masks[i] = 0;
        self.first_child[i] = NO_CHILD;
        if let Some(e) = extra {
            self.extras[i] = e;
        }
    }

    /// Adds child `pos` (which must not exist) as a leaf with `value`;
    /// returns its id. Moves the other children of `n`.
    pub fn insert_child(&mut self, n: NodeId, pos: usize, value: f32) -> NodeId {
        let m = self.masks[n as usize];
        debug_assert_eq!(m & (1 << pos), 0);
        let old_len = m.count_ones() as usize;
        let old = self.first_child[n as usize];
        let new = self.alloc_run(old_len + 1);
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

    /// Gives a leaf `n` the children in `mask`, each a new leaf holding
    /// `value`; returns the id of the first.
    pub fn add_children(&mut self, n: NodeId, mask: u8, value: f32) -> NodeId {
        self.add_children_with(n, mask, value, self.default_extra)
    }

    fn add_children_with(&mut self, n: NodeId, mask: u8, value: f32, extra: Option<u32>) -> NodeId {
        debug_assert_eq!(self.masks[n as usize], 0);
        let len = mask.count_ones();
        let new = if len == 0 {
            NO_CHILD
        } else if let Some(start) = self.free[len as usize].pop() {
            self.free_slots -= len as usize;
            for i in 0..len {
                self.init_slot(start + i, value, extra);
            }
            start
        } else {
            let start = self.push_run(len as usize);
            // fresh slots hold the defaults; only the value and extra differ
            for i in 0..len {
                self.values[(start + i) as usize] = value;
            }
            if let Some(e) = extra {
                for i in 0..len {
                    self.extras[(start + i) as usize] = e;
                }
            }
            start
        };
        self.masks[n as usize] = mask;
        self.first_child[n as usize] = new;
        new
    }

    /// Adds the children in `add` (none of which exists yet) to `n` as
    /// leaves holding `value`, moving its group once; returns the first id.
    pub fn add_missing_children(&mut self, n: NodeId, add: u8, value: f32) -> NodeId {
        let m = self.masks[n as usize];
        debug_assert_eq!(m & add, 0);
        if m == 0 {
            return self.add_children(n, add, value);
        }
        if add == 0 {
            return self.first_child[n as usize];
        }
        let old = self.first_child[n as usize];
        let new_mask = m | add;
        let new = self.alloc_run(new_mask.count_ones() as usize);
        let (mut from, mut to) = (old, new);
        for i in 0..8 {
            if m & (1 << i) != 0 {
                self.copy_slot(from, to);
                from += 1;
                to += 1;
            } else if add & (1 << i) != 0 {
                self.init_slot(to, value, self.default_extra);
                to += 1;
            }
        }
        self.free_run(old, m.count_ones() as usize);
        self.masks[n as usize] = new_mask;
        self.first_child[n as usize] = new;
        new
    }

    /// Expands a leaf `n`: eight children holding its value and extra
    /// (OctoMap's `expandNode` copies the node's data).
    pub fn expand_node(&mut self, n: NodeId) {
        let extra = self.default_extra.map(|_| self.extra(n));
        self.add_children_with(n, 0xff, self.value(n), extra);
    }

    /// Removes child `pos` of `n` and its whole subtree; returns the number
    /// of nodes freed.
    pub fn remove_child(&mut self, n: NodeId, pos: usize) -> usize {
        let m = self.masks[n as usize];
        debug_assert_ne!(m & (1 << pos), 0);
        let old_len = m.count_ones() as usize;
        let old = self.first_child[n as usize];
        let rank = (m & ((1u8 << pos) - 1)).count_ones();
        let freed = self.free_subtree_children(old + rank) + 1;
        if old_len == 1 {
            self.masks[n as usize] = 0;
            self.first_child[n as usize] = NO_CHILD;
        } else {
            let new = self.alloc_run(old_len - 1);
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

    /// Removes all children of `n` (and their subtrees); returns the number
    /// of nodes freed.
    pub fn remove_all_children(&mut self, n: NodeId) -> usize {
        let freed = self.free_subtree_children(n);
        self.masks[n as usize] = 0;
        self.first_child[n as usize] = NO_CHILD;
        freed
    }

    /// Frees every descendant run below `n` (not `n` itself).
    fn free_subtree_children(&mut self, n: NodeId) -> usize {
        let m = self.masks[n as usize];
        if m == 0 {
            return 0;
        }
        let len = m.count_ones() as usize;
        let first = self.first_child[n as usize];
        let mut freed = len;
        for i in 0..len as u32 {
            freed += self.free_subtree_children(first + i);
        }
        self.free_run(first, len);
        freed
    }

    #[cfg(test)]
    /// A copy laid out in depth-first order: the root first, each node's
    /// child group allocated as the node is visited, exactly sized.
    pub fn compacted(&self, root: NodeId) -> NodeArena {
        let mut out = NodeArena { default_extra: self.default_extra, ..Default::default() };
        let total = self.values.len() - self.free_slots;
        out.values.reserve_exact(total);
        if self.default_extra.is_some() {
            out.extras.reserve_exact(total);
        }
        out.masks.reserve_exact(total);
        out.first_child.reserve_exact(total);
        out.push_run(1);
        out.values[0] = self.values[root as usize];
        out.set_extra(0, self.extra(root));
        // (old id, new id) pairs whose child groups still need copying
        let mut stack = vec![(root, 0 as NodeId)];
        while let Some((old, new)) = stack.pop() {
            let m = self.masks[old as usize];
            out.masks[new as usize] = m;
            if m == 0 {
                continue;
            }
            let len = m.count_ones() as usize;
            let first_old = self.first_child[old as usize];
            let first_new = out.push_run(len);
            out.first_child[new as usize] = first_new;
            for i in 0..len as u32 {
                out.values[(first_new + i) as usize] = self.values[(first_old + i) as usize];
                out.set_extra(first_new + i, self.extra(first_old + i));
            }
            for i in (0..len as u32).rev() {
                stack.push((first_old + i, first_new + i));
            }
        }
        out
    }

    /// Releases spare capacity (after building).
    pub fn shrink_to_fit(&mut self) {
        self.values.shrink_to_fit();
        self.masks.shrink_to_fit();
        self.first_child.shrink_to_fit();
        self.extras.shrink_to_fit();
    }

    /// Re-lays the arena in place in the order [`Self::compacted`] gives,
    /// needing 4 bytes per slot of scratch space instead of a full copy.
    pub fn compact_in_place(&mut self, root: NodeId) {
        const FREE: u32 = u32::MAX;
        const MOVED: u32 = u32::MAX - 1;
        let len = self.values.len();
        // new id of every live slot, in depth-first group order
        let mut new_of = vec![FREE; len];
        new_of[root as usize] = 0;
        let mut next = 1u32;
        let mut stack = vec![root];
        while let Some(n) = stack.pop() {
            let k = self.masks[n as usize].count_ones();
            if k == 0 {
                continue;
            }
            let first = self.first_child[n as usize];
            for i in 0..k {
                new_of[(first + i) as usize] = next + i;
            }
            next += k;
            stack.extend((0..k).rev().map(|i| first + i));
        }
        for (i, &m) in self.masks.iter().enumerate() {
            if new_of[i] != FREE && m != 0 {
                self.first_child[i] = new_of[self.first_child[i] as usize];
            }
        }
        // follow each chain: the element at `dst` is picked up before its slot
        // is overwritten; a chain ends at a free or already emptied slot
        let has_extras = self.default_extra.is_some();
        for start in 0..len {
            let mut dst = new_of[start];
            if dst == FREE || dst == MOVED {
                continue;
            }
            new_of[start] = MOVED;
            let mut carry = self.slot(start, has_extras);
            loop {
                let d = dst as usize;
                let following = new_of[d];
                let displaced = self.slot(d, has_extras);
                self.put_slot(d, carry, has_extras);
                if following == FREE || following == MOVED {
                    break;
                }
                new_of[d] = MOVED;
                carry = displaced;
                dst = following;
            }
        }
        let live = next as usize;
        self.values.truncate(live);
        self.masks.truncate(live);
        self.first_child.truncate(live);
        self.extras.truncate(if has_extras { live } else { 0 });
        self.shrink_to_fit();
        self.free = Default::default();
        self.free_slots = 0;
    }

    #[inline]
    fn slot(&self, i: usize, extras: bool) -> (f32, u8, NodeId, u32) {
        (self.values[i], self.masks[i], self.first_child[i], if extras { self.extras[i] } else { 0 })
    }

    #[inline]
    fn put_slot(&mut self, i: usize, s: (f32, u8, NodeId, u32), extras: bool) {
        self.values[i] = s.0;
        self.masks[i] = s.1;
        self.first_child[i] = s.2;
        if extras {
            self.extras[i] = s.3;
        }
    }

    pub fn usage(&self) -> ArenaUsage {
        let free_list_bytes: usize = self.free.iter().map(|f| f.capacity() * std::mem::size_of::<NodeId>()).sum();
        ArenaUsage {
            live_slots: self.values.len() - self.free_slots,
            free_slots: self.free_slots,
            bytes_reserved: self.values.capacity() * 4
                + self.masks.capacity()
                + self.first_child.capacity() * 4
                + self.extras.capacity() * 4
                + free_list_bytes,
        }
    }

    /// The slot arrays, for read-only passes over the whole tree: values,
    /// child masks, first children and extras (empty when extras are off).
    #[inline]
    pub(crate) fn parts(&self) -> (&[f32], &[u8], &[NodeId], &[u32]) {
        (&self.values, &self.masks, &self.first_child, &self.extras)
    }

    /// Mutable access to every slot's value (free slots included).
    pub fn values_mut(&mut self) -> &mut [f32] {
        &mut self.values
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

/// The arrays of an arena being filled in pre-order: zero-initialised
/// (extras: the default) up to their length, which is the capacity in
/// slots; the first `len` slots are in use.
struct Slots {
    values: Vec<f32>,
    masks: Vec<u8>,
    first_child: Vec<NodeId>,
    extras: Vec<u32>,
    default_extra: Option<u32>,
    len: usize,
    /// Expected node count; capacity grows toward it, never past what the
    /// nodes given so far justify (see [`Self::grow`]).
    hint: usize,
}

impl Slots {
    fn new(default_extra: Option<u32>, hint: usize) -> Self {
        Slots {
            values: Vec::new(),
            masks: Vec::new(),
            first_child: Vec::new(),
            extras: Vec::new(),
            default_extra,
            len: 0,
            hint,
        }
    }

    /// Makes room for `n` more slots at once. Fresh zeroed memory comes
    /// from the allocator already zeroed, so large reservations cost no
    /// writes up front.
    fn reserve(&mut self, n: usize) {
        let cap = self.len + n.min(u32::MAX as usize - 2 - self.len);
        if cap <= self.values.len() {
            return;
        }
        if self.values.is_empty() {
            self.values = vec![0.0; cap];
            self.masks = vec![0; cap];
            self.first_child = vec![NO_CHILD; cap];
            if let Some(e) = self.default_extra {
                self.extras = vec![e; cap];
            }
        } else {
            self.values.resize(cap, 0.0);
            self.masks.resize(cap, 0);
            self.first_child.resize(cap, NO_CHILD);
            if let Some(e) = self.default_extra {
                self.extras.resize(cap, e);
            }
        }
    }

    /// Makes room for `k` more slots: doubles the capacity, capped at the
    /// hint while the hint is still ahead, so memory stays within twice
    /// what the input has really announced.
    #[cold]
    #[inline(never)]
    fn grow(&mut self, k: usize) {
        let len = self.len;
        assert!(len + k <= u32::MAX as usize - 2, "node arena exceeds 2^32 slots");
        let mut want = (2 * len).max(1024);
        if self.hint >= len + k {
            want = want.min(self.hint);
        }
        self.reserve(want.max(len + k) - len);
    }

    /// Takes `k` more slots; returns the first.
    #[inline(always)]
    fn take(&mut self, k: usize) -> NodeId {
        let first = self.len;
        if first + k > self.values.len() {
            self.grow(k);
        }
        self.len = first + k;
        first as NodeId
    }

    /// The arena of the slots in use.
    fn into_arena(self) -> NodeArena {
        let len = self.len;
        let mut a = NodeArena {
            values: self.values,
            masks: self.masks,
            first_child: self.first_child,
            extras: self.extras,
            default_extra: self.default_extra,
            free: Default::default(),
            free_slots: 0,
        };
        if a.values.len() > len || a.values.capacity() > len {
            a.values.truncate(len);
            a.masks.truncate(len);
            a.first_child.truncate(len);
            a.extras.truncate(if a.default_extra.is_some() { len } else { 0 });
            a.shrink_to_fit();
        }
        a
    }
}

/// Fills an arena from nodes given in depth-first pre-order (children
/// 0..7): each node's child group is allocated when the node is given, so
/// the result has the layout of [`NodeArena::compacted`] and no free slots.
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
        self.slots.len
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
        let i = id as usize;
        s.values[i] = value;
        if let (Some(e), Some(slot)) = (extra, s.extras.get_mut(i)) {
            *slot = e;
        }
        if mask != 0 {
            if depth >= 16 {
                return Err(FillError::TooDeep);
            }
            let k = mask.count_ones();
            let first = s.take(k as usize);
            s.masks[i] = mask;
            s.first_child[i] = first;
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
        slots.values[root as usize] = root_value;
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
        let first = s.take(k as usize);
        let mut rest = mask;
        for v in &mut s.values[first as usize..(first + k) as usize] {
            let pos = rest.trailing_zeros();
            rest &= rest - 1;
            *v = self.label_values[usize::from((labels >> (2 * pos)) as u8 & 3)];
        }
        s.masks[id as usize] = mask;
        s.first_child[id as usize] = first;
        if due != 0 {
            self.open[depth] = OpenGroup { parent: id, first, mask, due };
            self.depth = depth + 1;
        } else {
            if id != 0 {
                s.values[id as usize] = max_of(&s.values[first as usize..(first + k) as usize]);
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
                let (a, b) = (g.first as usize, (g.first + g.mask.count_ones()) as usize);
                self.slots.values[g.parent as usize] = max_of(&self.slots.values[a..b]);
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
            a.insert_child(0, pos, pos as f32);
        }
        let kids: Vec<_> = a.children(0).map(|(i, id)| (i, a.value(id))).collect();
        assert_eq!(kids, vec![(0, 0.0), (1, 1.0), (5, 5.0), (7, 7.0)]);
        assert_eq!(a.child(0, 5).map(|id| a.value(id)), Some(5.0));
        assert_eq!(a.child(0, 4), None);
        // runs of length 1, 2 and 3 were freed along the way
        assert_eq!(a.usage().free_slots, 6);
        let c = a.child(0, 1).unwrap();
        a.set_value(c, 9.0);
        a.expand_node(c);
        assert_eq!(a.remove_child(0, 1), 9);
        let kids: Vec<_> = a.children(0).map(|(i, id)| (i, a.value(id))).collect();
        assert_eq!(kids, vec![(0, 0.0), (5, 5.0), (7, 7.0)]);
        let c = a.compacted(0);
        let mut d = a.clone();
        d.compact_in_place(0);
        assert_eq!(
            (d.values.clone(), d.masks.clone(), d.first_child.clone()),
            (c.values.clone(), c.masks.clone(), c.first_child.clone())
        );
        assert_eq!(c.usage().free_slots, 0);
        assert_eq!(c.usage().live_slots, 4);
        let kids: Vec<_> = c.children(0).map(|(i, id)| (i, c.value(id))).collect();
        assert_eq!(kids, vec![(0, 0.0), (5, 5.0), (7, 7.0)]);
    }
}
