//! Depth-16 searches that resume from the previous query's path.
//!
//! Consecutive voxels of a ray share all but their last level or two, so
//! restarting from the deepest node common to both keys turns a 16-level
//! descent into one or two steps. Answers are exactly [`OccupancyTree::search`]'s.

use super::{Found, NodeArena, NodeId, OccupancyTree, ROOT};
use crate::key::{Key, TREE_DEPTH};

/// A search cursor over one tree (which cannot change while it exists).
pub(crate) struct PathSearch<'a> {
    arena: Option<&'a NodeArena>,
    key: Key,
    /// Entries `0..=len` are the nodes at depths `0..=len` on `key`'s path.
    len: u8,
    path: [NodeId; TREE_DEPTH as usize + 1],
}

impl<'a> PathSearch<'a> {
    pub fn new(tree: &'a OccupancyTree) -> Self {
        PathSearch { arena: tree.arena(), key: Key::ROOT, len: 0, path: [ROOT; TREE_DEPTH as usize + 1] }
    }

    /// `tree.search(key, 0)`.
    #[inline]
    pub fn search(&mut self, key: Key) -> Option<Found> {
        let a = self.arena?;
        // levels whose child index is the same for both keys
        let common = (0..3).map(|i| (key.0[i] ^ self.key.0[i]).leading_zeros()).min().unwrap_or(0);
        let start = (common as u8).min(self.len);
        self.key = key;
        self.len = start;
        let p = a.parts();
        let mut node = self.path[start as usize];
        for d in start..TREE_DEPTH {
            match p.descend(node, key.child_index(d) as u64) {
                Ok(c) => node = c,
                Err(0) => return Some(Found { value: p.value(node), depth: d, is_leaf: true, extra: p.extra(node) }),
                Err(_) => return None,
            }
            self.path[d as usize + 1] = node;
            self.len = d + 1;
        }
        Some(Found { value: p.value(node), depth: TREE_DEPTH, is_leaf: true, extra: p.extra(node) })
    }
}
