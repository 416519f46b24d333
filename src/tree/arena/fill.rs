//! Arenas built from file streams: [`PreorderFill`] from nodes in
//! depth-first pre-order, [`LabelFill`] from a `.bt` stream of child labels.

use super::{in_leaf_pool, leaf_group, leaf_index, NodeArena, NodeId, LEAF_POOL, NO_CHILD};

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
            let k = crate::arch::count_ones(mask);
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
            g.first + crate::arch::count_ones(u32::from(g.mask) & ((1u32 << pos) - 1))
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
        let k = crate::arch::count_ones(mask);
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
                let max = max_of(self.slots.group_values(g.first, crate::arch::count_ones(g.mask) as usize));
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
