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

    /// Mutable access to every slot's value (free slots included).
    pub fn values_mut(&mut self) -> &mut [f32] {
        &mut self.values
    }
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
