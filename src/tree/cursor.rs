//! Depth-16 searches that resume from the previous query's path.
//!
//! Consecutive voxels of a ray share all but their last level or two, so
//! restarting from the deepest node common to both keys turns a 16-level
//! descent into one or two steps. Keys come as Morton codes: the levels two
//! codes share are their common leading bits, a third of a `leading_zeros`.
//! Answers are exactly [`OccupancyTree::search`]'s.

use super::arena::Parts;
use super::{Found, NodeId, OccupancyTree, ROOT};
use crate::key::TREE_DEPTH;

/// A search cursor over one tree (which cannot change while it exists).
pub(crate) struct PathSearch<'a> {
    parts: Option<Parts<'a>>,
    /// The previous query's Morton code.
    code: u64,
    /// Entries `0..=len` are the nodes at depths `0..=len` on `code`'s path.
    len: u8,
    /// A query sharing at least this many levels with `code` has `answer`
    /// too: the leaf found (or the missing child) lies on its path as well.
    /// A ray crossing a pruned voxel or unknown space gets it in a compare.
    settled: u8,
    answer: Option<Found>,
    path: [NodeId; TREE_DEPTH as usize + 1],
}

impl<'a> PathSearch<'a> {
    pub fn new(tree: &'a OccupancyTree) -> Self {
        let parts = tree.arena().map(|a| a.parts());
        // an empty tree answers `None` to everything
        let settled = if parts.is_some() { TREE_DEPTH + 1 } else { 0 };
        PathSearch { parts, code: 0, len: 0, settled, answer: None, path: [ROOT; TREE_DEPTH as usize + 1] }
    }

    /// `tree.search(key, 0)` for the key whose Morton code is `code`.
    #[inline(always)]
    pub fn search(&mut self, code: u64) -> Option<Found> {
        let shared = shared_levels(code, self.code);
        self.code = code;
        if shared >= self.settled {
            return self.answer;
        }
        self.descend(shared.min(self.len), code)
    }

    /// The search from the path's node at depth `start` (kept out of
    /// line, so that the caller's loop holds only the compare above).
    #[inline(never)]
    fn descend(&mut self, start: u8, code: u64) -> Option<Found> {
        let p = self.parts?;
        let mut node = self.path[start as usize];
        let mut d = start;
        let (answer, settled) = loop {
            if d == TREE_DEPTH {
                break (Some(Found { value: p.value(node), depth: d, is_leaf: true, extra: p.extra(node) }), d);
            }
            match p.descend(node, (code >> (3 * (15 - u32::from(d)))) & 7) {
                Ok(c) => {
                    node = c;
                    d += 1;
                    self.path[d as usize] = c;
                }
                Err(0) => {
                    break (Some(Found { value: p.value(node), depth: d, is_leaf: true, extra: p.extra(node) }), d)
                }
                Err(_) => break (None, d + 1),
            }
        };
        (self.len, self.settled, self.answer) = (d, settled, answer);
        answer
    }
}

/// The number of levels (0..=16) whose child index is the same in two
/// 48-bit Morton codes.
#[inline(always)]
pub(crate) fn shared_levels(a: u64, b: u64) -> u8 {
    (((a ^ b).leading_zeros() - 16) / 3) as u8
}
