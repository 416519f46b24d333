//! The walk that applies one sorted batch of updates to a subtree.

use super::arena::NodeStore;
use super::rules::{prune_node, prune_or_update_plain, update_from_children};
use super::{parallel, NodeId, NodeKind, Rules};
use crate::key::{Key, TREE_DEPTH};
use crate::sensor::SensorModel;
use hashbrown::HashMap;

/// State of one [`OccupancyTree::update_batch`](super::OccupancyTree::update_batch)
/// walk, over the arena or, in a parallel update, over one worker's share
/// of it.
pub(super) struct Batch<'a, S: NodeStore> {
    pub(super) arena: &'a mut S,
    pub(super) rules: Rules,
    pub(super) sensor: SensorModel,
    pub(super) delta: f32,
    pub(super) lazy: bool,
    pub(super) size: isize,
    pub(super) changes: Option<&'a mut HashMap<Key, bool>>,
    /// Where the walk stops short for a parallel update
    /// ([`parallel::Split`]); `None` for a whole walk.
    pub(super) split: Option<&'a mut parallel::Split>,
    /// Where the batch's codes part among children.
    pub(super) ranges: ChildRanges<'a>,
}

/// Codes below a node from which its child ranges come from [`Splits`]
/// instead of a pass over the codes. Such a node spans more voxels: it
/// lies at depth [`SPLIT_DEPTH`] or above.
const LARGE: usize = 1024;

/// The deepest nodes that may have more than [`LARGE`] codes (a depth-13
/// node spans 512 voxels).
const SPLIT_DEPTH: usize = 12;

/// Where a sorted batch of codes parts, by depth: for nodes at depth `d`
/// (0 to [`SPLIT_DEPTH`]), the positions `i` at which `codes[i + 1]` lies
/// below another child than `codes[i]`, ascending. One pass over the codes
/// finds them all, and a large node's child ranges are then its few entries
/// of its depth's list: searching its codes by gallops and binary searches
/// (chains of dependent loads) took a tenth of a large map's insertion.
pub(super) struct Splits {
    at: [Vec<u32>; SPLIT_DEPTH + 1],
}

impl Splits {
    /// The splits of `codes` (Morton codes, strictly increasing; fewer
    /// than 2^32).
    pub(super) fn new(codes: &[u64]) -> Splits {
        let mut at: [Vec<u32>; SPLIT_DEPTH + 1] = Default::default();
        for (i, pair) in codes.windows(2).enumerate() {
            let differ = pair[0] ^ pair[1];
            // codes in one depth-13 node (its 512 voxels: the low 9 bits)
            // part below the split depth
            if differ >> 9 != 0 {
                // the depth of the deepest node above both: the highest
                // bit that differs picks the child below it
                let top_bit = 63 - differ.leading_zeros();
                let depth = TREE_DEPTH as usize - 1 - top_bit as usize / 3;
                at[depth].push(u32::try_from(i).expect("fewer than 2^32 codes in a batch"));
            }
        }
        Splits { at }
    }
}

/// A walk's view of a batch's [`Splits`]: the address of the batch's first
/// code (to turn a node's codes into positions) and, per depth, where the
/// last node's entries ended. A walk visits each depth's nodes in code
/// order, so each list is read forward once.
#[derive(Clone, Copy)]
pub(super) struct ChildRanges<'a> {
    splits: &'a Splits,
    base: usize,
    next: [usize; SPLIT_DEPTH + 1],
}

impl<'a> ChildRanges<'a> {
    /// For a walk over `codes`, whose splits are `splits`.
    pub(super) fn new(splits: &'a Splits, codes: &[u64]) -> Self {
        ChildRanges { splits, base: codes.as_ptr() as usize, next: [0; SPLIT_DEPTH + 1] }
    }

    /// The same batch for another walk (from the start of each list).
    pub(super) fn restart(&self) -> Self {
        ChildRanges { next: [0; SPLIT_DEPTH + 1], ..*self }
    }

    /// Where each child's codes start in `codes` (all of them below one
    /// node at `depth`, more than [`LARGE`] of them, and a run of the
    /// batch's codes), in `bounds[child]`, `codes.len()` for a child
    /// without codes, and the children with codes.
    fn find(&mut self, depth: u8, codes: &[u64], bounds: &mut [usize; 9]) -> u8 {
        let shift = 3 * (15 - u32::from(depth));
        let child_of = |c: u64| ((c >> shift) & 7) as usize;
        let list = &self.splits.at[usize::from(depth)];
        let first = (codes.as_ptr() as usize - self.base) / std::mem::size_of::<u64>();
        let last = first + codes.len() - 1;
        // the list's first entry at or after `first`: usually the next one,
        // unless the walk skipped nodes (or started in the middle)
        let mut k = self.next[usize::from(depth)];
        if list.get(k).is_some_and(|&p| (p as usize) < first) {
            k += list[k..].partition_point(|&p| (p as usize) < first);
        }
        let mut needed = 0u8;
        let mut start = 0;
        loop {
            let pos = child_of(codes[start]);
            bounds[pos] = start;
            needed |= 1 << pos;
            match list.get(k) {
                Some(&p) if (p as usize) < last => {
                    start = p as usize + 1 - first;
                    k += 1;
                }
                _ => break,
            }
        }
        self.next[usize::from(depth)] = k;
        for pos in (0..8).rev() {
            bounds[pos] = bounds[pos].min(bounds[pos + 1]);
        }
        needed
    }
}

impl<S: NodeStore> Batch<'_, S> {
    /// Applies `codes` (all below `n`, which sits at `depth`) to the
    /// subtree; returns whether any voxel was updated. Like `updateNode`,
    /// whose early exit on a saturated voxel leaves the path above it alone,
    /// a node is updated and pruned only when something below it changed
    /// (which matters when earlier lazy updates left inner nodes stale).
    pub(super) fn apply(&mut self, n: NodeId, depth: u8, codes: &[u64], created: bool) -> bool {
        if depth == TREE_DEPTH {
            return self.apply_leaf(n, codes[0], created);
        }
        if let Some(split) = self.split.as_deref_mut() {
            if split.is_task(depth, codes.len()) {
                return split.visit(n, depth, codes, created);
            }
        }
        // where each child's codes start: codes are sorted and share the
        // prefix above this node, so the child index is monotone in them
        let shift = 3 * (15 - u32::from(depth));
        let child_of = |c: u64| ((c >> shift) & 7) as usize;
        let mut bounds = [codes.len(); 9];
        let mut needed = 0u8;
        if depth == TREE_DEPTH - 1 {
            // children are voxels, one code each: no ranges needed
            for &c in codes {
                needed |= 1 << (c & 7);
            }
        } else if codes.len() <= LARGE {
            // a pass over the codes: stores only, no mispredicted branches
            for (i, &c) in codes.iter().enumerate().rev() {
                bounds[child_of(c)] = i;
            }
            for pos in (0..8).rev() {
                bounds[pos] = bounds[pos].min(bounds[pos + 1]);
                needed |= u8::from(bounds[pos] < bounds[pos + 1]) << pos;
            }
        } else {
            needed = self.ranges.find(depth, codes, &mut bounds);
        }
        let a = &mut *self.arena;
        let mask = a.mask(n);
        let mut new_children = 0u8;
        if mask == 0 && !created {
            // a pruned leaf: unchanged when the update saturates, else expanded
            if self.sensor.is_saturated(a.value(n), self.delta) {
                return false;
            }
            a.expand_node(n, depth);
            self.size += 8;
        } else {
            new_children = needed & !mask;
            if new_children != 0 {
                a.add_missing_children(n, new_children, 0.0, depth);
                self.size += crate::arch::count_ones(new_children) as isize;
            }
        }
        let (first, mask) = (a.first_child(n), a.mask(n));
        let mut changed = false;
        if depth == TREE_DEPTH - 1 {
            for &c in codes {
                let pos = (c & 7) as u32;
                let child = first + crate::arch::count_ones(u32::from(mask) & ((1 << pos) - 1));
                changed |= self.apply_leaf(child, c, new_children & (1 << pos) != 0);
            }
        } else {
            let mut rest = needed;
            while rest != 0 {
                let pos = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                let child = first + crate::arch::count_ones(mask & ((1u8 << pos) - 1));
                let range = &codes[bounds[pos]..bounds[pos + 1]];
                changed |= self.apply(child, depth + 1, range, new_children & (1 << pos) != 0);
            }
        }
        if changed && !self.lazy {
            if self.rules.kind == NodeKind::Plain {
                if prune_or_update_plain(&mut *self.arena, n) {
                    self.size -= 8;
                }
            } else if prune_node(&mut *self.arena, n, self.rules).is_some() {
                self.size -= 8;
            } else {
                update_from_children(&mut *self.arena, n, self.rules);
            }
        }
        changed
    }

    #[inline]
    fn apply_leaf(&mut self, n: NodeId, code: u64, created: bool) -> bool {
        let before = self.arena.value(n);
        if !created && self.sensor.is_saturated(before, self.delta) {
            return false;
        }
        let after = self.sensor.apply(before, self.delta);
        self.arena.set_value(n, after);
        if self.rules.kind == NodeKind::Stamped {
            self.arena.set_extra(n, self.rules.now);
        }
        if let Some(changes) = self.changes.as_deref_mut() {
            let key = crate::morton::MortonCode(code).decode();
            let (was, is) = (self.sensor.is_occupied(before), self.sensor.is_occupied(after));
            super::changes::record_change(changes, key, created, was, is);
        }
        true
    }
}
