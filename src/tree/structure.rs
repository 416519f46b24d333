//! Changes of the tree's shape rather than its values: pruning,
//! expansion, deletion, and compaction of the arena.

use super::rules::{prune_node, update_from_children};
use super::ROOT;
use super::{blocks, level_index, Compaction, NodeArena, NodeId, NodeKind, OccupancyTree, Rules, TreeError};
use crate::geometry::Point3;
use crate::key::{Key, KeyError, TREE_DEPTH};

/// Nodes the expansion of a leaf at `depth` adds: `8 + 64 + ... +
/// 8^(16 - depth)`, at most 8^17 / 7 (a root without children).
fn added_below(depth: u8) -> u64 {
    let levels = u32::from(TREE_DEPTH.saturating_sub(depth));
    (8u64.pow(levels + 1) - 8) / 7
}

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

    /// How many nodes [`Self::expand`] would add (saturating at
    /// `u64::MAX`), counted from the leaves' depths without expanding: a
    /// leaf at depth `d` gains `8 + 64 + ... + 8^(16 - d)` nodes.
    pub fn expansion_nodes(&self) -> u64 {
        fn recurse(a: &NodeArena, n: NodeId, depth: u8) -> u64 {
            if !a.has_children(n) {
                return added_below(depth);
            }
            let first = a.first_child(n);
            (0..crate::arch::count_ones(a.mask(n)))
                .map(|i| recurse(a, first + i, depth + 1))
                .fold(0, u64::saturating_add)
        }
        self.arena.as_ref().map_or(0, |a| recurse(a, ROOT, 0))
    }

    /// Gives every leaf above depth 16 eight children holding its value
    /// (OctoMap's `expand`) if that adds at most
    /// [`OUTPUT_LIMIT`](super::OUTPUT_LIMIT) nodes: a leaf at depth `d`
    /// becomes `8^(16 - d)` voxels, so a map of a few coarse leaves could
    /// need more memory than there is. Returns the nodes added; past the
    /// limit the tree is left unchanged and [`TreeError::TooLarge`] names
    /// the count. [`Self::expand_within`] takes another limit.
    pub fn expand(&mut self) -> Result<u64, TreeError> {
        self.expand_within(super::OUTPUT_LIMIT)
    }

    /// [`Self::expand`] if it adds at most `limit` nodes (counted first by
    /// [`Self::expansion_nodes`]); returns the nodes added. Past the limit
    /// the tree is left unchanged and [`TreeError::TooLarge`] names the
    /// count and the limit.
    pub fn expand_within(&mut self, limit: u64) -> Result<u64, TreeError> {
        let count = self.expansion_nodes();
        if count > limit {
            return Err(TreeError::TooLarge { what: "expand", items: "nodes to add", count, limit });
        }
        self.expand_all();
        Ok(count)
    }

    /// Expands every leaf above depth 16, whatever that costs.
    fn expand_all(&mut self) {
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

#[cfg(test)]
mod tests {
    use super::super::{PreorderBuilder, OUTPUT_LIMIT};
    use super::*;
    use crate::formats::bt;
    use crate::sensor::SensorModel;

    /// A tree whose root has one occupied child at `depth` 1 or below, a
    /// leaf standing for `8^(16 - depth)` voxels (a chain of single
    /// children above it), read back from the `.bt` file the library
    /// writes of it.
    fn one_coarse_leaf(depth: u8) -> (OccupancyTree, Vec<u8>) {
        let mut b = PreorderBuilder::new();
        for d in 0..=depth {
            b.push(2.0, if d == depth { 0 } else { 1 }, u64::from(d)).unwrap();
        }
        let tree = b.finish(0.1, SensorModel::default()).unwrap().unwrap();
        let mut file = Vec::new();
        bt::write(&tree, &mut file).unwrap();
        (bt::read(&file[..]).unwrap(), file)
    }

    /// A 138-byte `.bt` whose root has one occupied child at depth 1:
    /// its expansion would add 8 + 64 + ... + 8^15 nodes. Counted from the
    /// leaves, it is refused with the count and the limit in the message,
    /// the tree left as it was.
    #[test]
    fn expansion_past_the_limit_is_refused_before_any_node_is_made() {
        let (mut tree, file) = one_coarse_leaf(1);
        assert_eq!(file.len(), 138);
        let want = (8u64.pow(16) - 8) / 7;
        assert_eq!(tree.expansion_nodes(), want);
        let err = tree.expand_within(OUTPUT_LIMIT).unwrap_err();
        assert_eq!(
            err,
            TreeError::TooLarge { what: "expand", items: "nodes to add", count: want, limit: OUTPUT_LIMIT }
        );
        let text = err.to_string();
        assert!(text.contains(&want.to_string()) && text.contains("268435456 (2^28)"), "{text}");
        assert!(text.contains("higher limit"), "{text}");
        assert_eq!((tree.size(), tree.calc_num_nodes()), (2, 2));
        // a root without children stands for the whole map
        let mut root = PreorderBuilder::new();
        root.push(-2.0, 0, 0).unwrap();
        let root = root.finish(0.1, SensorModel::default()).unwrap().unwrap();
        assert_eq!(root.expansion_nodes(), (8u64.pow(17) - 8) / 7);
    }

    /// Within the limit, `expand_within` is `expand`: same nodes, same
    /// count, and the count it returns is the nodes added; one node short
    /// of the limit it refuses.
    #[test]
    fn expansion_within_the_limit_is_expand() {
        for depth in [13, 14, 15, 16] {
            let (tree, _) = one_coarse_leaf(depth);
            let added = (8u64.pow(u32::from(16 - depth) + 1) - 8) / 7;
            assert_eq!(tree.expansion_nodes(), added);
            let mut plain = tree.clone();
            plain.expand_all();
            let mut within = tree.clone();
            assert_eq!(within.expand_within(added), Ok(added));
            assert_eq!(within.size(), tree.size() + added as usize);
            let nodes = |t: &OccupancyTree| t.nodes(0).map(|n| (n.key, n.depth, n.value.to_bits())).collect::<Vec<_>>();
            assert_eq!(nodes(&within), nodes(&plain));
            if added > 0 {
                let mut short = tree.clone();
                assert!(matches!(short.expand_within(added - 1), Err(TreeError::TooLarge { .. })));
                assert_eq!(short.size(), tree.size());
            }
        }
        let mut empty = OccupancyTree::new(0.1).unwrap();
        assert_eq!(empty.expand_within(0), Ok(0));
    }

    /// The points of a point extraction are counted from the leaves:
    /// `8^(depth - d)` per leaf at depth `d`, only the leaves asked for,
    /// refused past the limit with the operation's name.
    #[test]
    fn voxels_of_coarse_leaves_are_counted_and_bounded() {
        let (tree, _) = one_coarse_leaf(1);
        assert_eq!(tree.voxel_count(16, |_| true), 8u64.pow(15));
        assert_eq!(tree.voxel_count(0, |_| true), 8u64.pow(15));
        assert_eq!(tree.voxel_count(3, |_| true), 64);
        assert_eq!(tree.voxel_count(16, |v| v < 0.0), 0);
        let err = tree.voxels_within(16, |_| true, OUTPUT_LIMIT, "extraction").unwrap_err();
        assert_eq!(
            err,
            TreeError::TooLarge { what: "extraction", items: "points", count: 8u64.pow(15), limit: OUTPUT_LIMIT }
        );
        assert_eq!(tree.voxels_within(10, |_| true, OUTPUT_LIMIT, "extraction"), Ok(8u64.pow(9)));
        let (fine, _) = one_coarse_leaf(16);
        assert_eq!(fine.voxel_count(16, |_| true), 1);
    }
}
