//! Changes of the tree's shape rather than its values: pruning,
//! expansion, deletion, and compaction of the arena.

use super::rules::{prune_node, update_from_children};
use super::{blocks, level_index, Compaction, NodeArena, NodeId, NodeKind, OccupancyTree, Rules, ROOT};
use crate::geometry::Point3;
use crate::key::{Key, KeyError, TREE_DEPTH};

impl OccupancyTree {
    /// Merges complete groups of eight equal leaf children into their
    /// parent, level by level from depth 15 up, stopping at the first level
    /// where nothing merged (OctoMap's `prune`, including that early stop).
    pub fn prune(&mut self) {
        /// What a node would be after level-by-level pruning of every level
        /// below it: `Some((value, extra))` when it is or would become a
        /// leaf. Counts the merges per depth.
        fn would_merge(
            a: &NodeArena,
            n: NodeId,
            depth: u8,
            rules: Rules,
            counts: &mut [usize; 16],
        ) -> Option<(f32, u32)> {
            let mask = a.mask(n);
            if mask == 0 {
                return Some((a.value(n), a.extra(n)));
            }
            let first = a.first_child(n);
            let mut all = mask == 0xff;
            let mut first_leaf = None;
            for i in 0..crate::arch::count_ones(mask) {
                match would_merge(a, first + i, depth + 1, rules, counts) {
                    None => all = false,
                    Some((v, e)) => match first_leaf {
                        None => first_leaf = Some((v, e)),
                        Some((v0, e0)) => {
                            if v != v0 || (rules.kind == NodeKind::Stamped && e != e0) {
                                all = false;
                            }
                        }
                    },
                }
            }
            if all && depth >= 1 {
                counts[depth as usize] += 1;
                first_leaf
            } else {
                None
            }
        }
        fn merge_below(a: &mut NodeArena, n: NodeId, depth: u8, lowest: u8, rules: Rules, pruned: &mut usize) {
            let first = a.first_child(n);
            for i in 0..crate::arch::count_ones(a.mask(n)) {
                merge_below(a, first + i, depth + 1, lowest, rules, pruned);
            }
            if depth >= lowest && prune_node(a, n, rules).is_some() {
                *pruned += 1;
            }
        }
        let rules = self.rules();
        let Some(a) = self.arena_mut() else { return };
        // OctoMap prunes level by level from depth 15 up and stops after the
        // first level that merged nothing; find that level first, then merge
        // everything below it in one bottom-up pass
        let mut counts = [0usize; 16];
        would_merge(a, ROOT, 0, rules, &mut counts);
        let stop = (1..TREE_DEPTH).rev().find(|&d| counts[d as usize] == 0).unwrap_or(0);
        let mut pruned = 0;
        merge_below(a, ROOT, 0, stop.max(1), rules, &mut pruned);
        self.size -= 8 * pruned;
        self.refresh_trunks();
    }

    /// Gives every leaf above depth 16 eight children holding its value
    /// (`expand`).
    pub fn expand(&mut self) {
        fn recurse(a: &mut NodeArena, n: NodeId, depth: u8, added: &mut usize) {
            if depth >= TREE_DEPTH {
                return;
            }
            if !a.has_children(n) {
                a.expand_node(n, depth);
                *added += 8;
            }
            let first = a.first_child(n);
            for i in 0..crate::arch::count_ones(a.mask(n)) {
                recurse(a, first + i, depth + 1, added);
            }
        }
        let mut added = 0;
        if let Some(a) = self.arena_mut() {
            recurse(a, ROOT, 0, &mut added);
        }
        self.size += added;
        self.refresh_trunks();
    }

    /// Deletes the node at `depth` (0 or 16 = a voxel) containing `key`,
    /// with OctoMap's `deleteNode` semantics: pruned nodes on the way are
    /// expanded, a parent losing its last child is deleted too, and the
    /// return value is `true` only when the root is left without children
    /// (or the tree was empty).
    pub fn delete(&mut self, key: Key, depth: u8) -> bool {
        fn recurse(t: &mut OccupancyTree, n: NodeId, depth: u8, max_depth: u8, key: Key, rules: Rules) -> bool {
            if depth >= max_depth {
                return true;
            }
            let a = t.arena.as_mut().expect("root exists");
            let pos = key.child_index(depth);
            if a.child(n, pos).is_none() {
                if !a.has_children(n) && n != ROOT {
                    a.expand_node(n, depth);
                    t.size += 8;
                } else {
                    return false;
                }
            }
            let child = a.child(n, pos).expect("exists or expanded");
            if recurse(t, child, depth + 1, max_depth, key, rules) {
                let a = t.arena.as_mut().expect("root exists");
                a.remove_child(n, pos);
                t.size -= 1;
                if !a.has_children(n) {
                    return true;
                }
                update_from_children(a, n, rules);
            }
            false
        }
        if self.arena.is_none() {
            return true;
        }
        let max_depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
        let rules = self.rules();
        self.forget_trunks();
        recurse(self, ROOT, 0, max_depth, key, rules)
    }

    /// [`Self::delete`] at the voxel containing `p`.
    pub fn delete_point(&mut self, p: Point3, depth: u8) -> Result<bool, KeyError> {
        let key = self.keys.key(p)?;
        Ok(self.delete(key, depth))
    }

    /// When the arena is compacted without being asked.
    pub fn set_compaction(&mut self, compaction: Compaction) {
        self.compaction = compaction;
    }

    /// The depth-13 subtrees as search-block runs for a mapped file (see
    /// `level_index::subtree_runs`), for a tree with `min_nodes` or more
    /// nodes at depths 13–15.
    pub(crate) fn subtree_runs(&self, min_nodes: usize) -> Option<blocks::SubtreeRuns> {
        level_index::subtree_runs(&self.arena.as_ref()?.parts(), min_nodes)
    }

    /// Re-lays the arena in depth-first (Morton) order with no free slots,
    /// so traversals walk memory forwards and no capacity is wasted.
    pub fn compact(&mut self) {
        if let Some(a) = self.arena_mut() {
            a.compact_in_place(ROOT);
        }
        self.refresh_trunks();
    }
}
