//! Depth-16 searches that resume from the previous query's path.
//!
//! Consecutive voxels of a ray share all but their last level or two, so
//! restarting from the deepest node common to both keys turns a 16-level
//! descent into one or two steps. Keys come as Morton codes: the levels two
//! codes share are their common leading bits, a third of a `leading_zeros`.
//! Answers are exactly [`OccupancyTree::search`]'s.

use super::{Found, NodeArena, NodeId, OccupancyTree, ROOT};
use crate::key::TREE_DEPTH;

/// A search cursor over one tree (which cannot change while it exists).
pub(crate) struct PathSearch<'a> {
    arena: Option<&'a NodeArena>,
    /// The previous query's Morton code.
    code: u64,
    /// Entries `0..=len` are the nodes at depths `0..=len` on `code`'s path.
    len: u8,
    path: [NodeId; TREE_DEPTH as usize + 1],
}

impl<'a> PathSearch<'a> {
    pub fn new(tree: &'a OccupancyTree) -> Self {
        PathSearch { arena: tree.arena(), code: 0, len: 0, path: [ROOT; TREE_DEPTH as usize + 1] }
    }

    /// `tree.search(key, 0)` for the key whose Morton code is `code`.
    #[inline]
    pub fn search(&mut self, code: u64) -> Option<Found> {
        let a = self.arena?;
        let start = (shared_levels(code, self.code)).min(self.len);
        self.code = code;
        self.len = start;
        let p = a.parts();
        let mut node = self.path[start as usize];
        for d in start..TREE_DEPTH {
            match p.descend(node, (code >> (3 * (15 - u32::from(d)))) & 7) {
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

/// The number of levels (0..=16) whose child index is the same in two
/// 48-bit Morton codes.
#[inline(always)]
pub(crate) fn shared_levels(a: u64, b: u64) -> u8 {
    (((a ^ b).leading_zeros() - 16) / 3) as u8
}
