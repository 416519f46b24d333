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
        } else {
            if codes.len() <= 1024 {
                // a linear pass: stores only, no mispredicted search branches
                // and no chain of dependent loads (below 1024 codes it costs
                // less than the eight gallops' chains)
                for (i, &c) in codes.iter().enumerate().rev() {
                    bounds[child_of(c)] = i;
                }
                for pos in (0..8).rev() {
                    bounds[pos] = bounds[pos].min(bounds[pos + 1]);
                }
            } else {
                // each child's range ends where the next begins: gallop
                // forwards from its start (the memory just read) instead of
                // binary searches over the whole list
                let n = codes.len();
                let mut start = 0;
                for (pos, b) in bounds.iter_mut().enumerate().take(8) {
                    *b = start;
                    if start == n || child_of(codes[start]) != pos {
                        continue;
                    }
                    let (mut last, mut step) = (start, 1);
                    while last + step < n && child_of(codes[last + step]) == pos {
                        last += step;
                        step *= 2;
                    }
                    let limit = (last + step).min(n);
                    start = last + 1 + codes[last + 1..limit].partition_point(|&c| child_of(c) == pos);
                }
            }
            for pos in 0..8 {
                needed |= u8::from(bounds[pos] < bounds[pos + 1]) << pos;
            }
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
                self.size += new_children.count_ones() as isize;
            }
        }
        let (first, mask) = (a.first_child(n), a.mask(n));
        let mut changed = false;
        if depth == TREE_DEPTH - 1 {
            for &c in codes {
                let pos = (c & 7) as u32;
                let child = first + (u32::from(mask) & ((1 << pos) - 1)).count_ones();
                changed |= self.apply_leaf(child, c, new_children & (1 << pos) != 0);
            }
        } else {
            let mut rest = needed;
            while rest != 0 {
                let pos = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                let child = first + (mask & ((1u8 << pos) - 1)).count_ones();
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
            if created {
                changes.insert(key, true);
            } else if self.sensor.is_occupied(before) != self.sensor.is_occupied(after) {
                match changes.get(&key) {
                    None => {
                        changes.insert(key, false);
                    }
                    Some(false) => {
                        changes.remove(&key);
                    }
                    Some(true) => {}
                }
            }
        }
        true
    }
}
