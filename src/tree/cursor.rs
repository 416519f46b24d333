//! Depth-16 searches that resume from the previous query's path, over any
//! node source: the arena ([`ArenaPath`]) or a mapped file's layout.
//!
//! Consecutive voxels of a ray share all but their last level or two, so
//! restarting from the deepest node common to both keys turns a 16-level
//! descent into one or two steps. Keys come as Morton codes: the levels two
//! codes share are their common leading bits, a third of a `leading_zeros`.
//! Answers are exactly [`OccupancyTree::search`]'s (and the mapped view's
//! `search`): the shared nodes are the same nodes.

use super::arena::Parts;
use super::{Found, NodeId, OccupancyTree, ROOT};
use crate::key::TREE_DEPTH;

/// A path cursor's previous query and how far its answer holds: a query
/// sharing at least `settled` levels with `code` has `answer` too (the leaf
/// found, or the missing child, lies on its path as well), so a ray
/// crossing a pruned voxel or unknown space gets it in a compare.
#[derive(Clone, Copy)]
struct LastAnswer {
    code: u64,
    settled: u8,
    answer: Option<Found>,
}

impl LastAnswer {
    /// Nothing holds yet.
    fn new() -> Self {
        LastAnswer { code: 0, settled: TREE_DEPTH + 1, answer: None }
    }

    /// Takes `code` as the current query: the previous answer when it
    /// holds, else `Err` with the levels `code` shares with the previous
    /// query (whose path the cursor still has).
    #[inline(always)]
    fn next(&mut self, code: u64) -> Result<Option<Found>, u8> {
        let shared = shared_levels(code, self.code);
        self.code = code;
        if shared >= self.settled {
            Ok(self.answer)
        } else {
            Err(shared)
        }
    }

    /// The current query's answer, holding for queries that share
    /// `settled` levels with it (0: every query; 17: none).
    #[inline(always)]
    fn set(&mut self, settled: u8, answer: Option<Found>) -> Option<Found> {
        (self.settled, self.answer) = (settled, answer);
        answer
    }
}

/// The nodes a [`PathSearch`] descends through: what it keeps of a node
/// on its path, and one step of a descent.
pub(crate) trait PathNodes: Copy {
    /// A node on the path, with what a step from it needs.
    type Entry: Copy + Default;
    /// The root; `None` for an empty map (every answer is then `None`).
    fn root(&self) -> Option<Self::Entry>;
    /// Child `pos` (0..8) of `e`, a node above depth 16: `Some(Ok(child))`,
    /// `Some(Err(mask of e))` when it does not exist, `None` when the node
    /// source gives no answer (a corrupted file).
    fn child(&self, e: Self::Entry, pos: usize) -> Option<Result<Self::Entry, u8>>;
    /// The answer for a descent that ends at `e`, a leaf at `depth`.
    fn found(&self, e: Self::Entry, depth: u8) -> Found;
}

/// A search cursor over one map (which cannot change while it exists).
pub(crate) struct PathSearch<S: PathNodes> {
    nodes: S,
    last: LastAnswer,
    /// Entries `0..=len` are the nodes at depths `0..=len` on the previous
    /// query's path.
    len: u8,
    path: [S::Entry; TREE_DEPTH as usize + 1],
}

impl<S: PathNodes> PathSearch<S> {
    pub fn new(nodes: S) -> Self {
        let mut last = LastAnswer::new();
        let root = nodes.root();
        if root.is_none() {
            // an empty map answers `None` to everything
            last.set(0, None);
        }
        // an empty map's path is never read
        let path = [root.unwrap_or_default(); TREE_DEPTH as usize + 1];
        PathSearch { nodes, last, len: 0, path }
    }

    /// `search(key, 0)` for the key whose Morton code is `code`.
    #[inline(always)]
    pub fn search(&mut self, code: u64) -> Option<Found> {
        match self.last.next(code) {
            Ok(answer) => answer,
            Err(shared) => self.descend(shared.min(self.len), code),
        }
    }

    /// The search from the path's node at depth `start` (kept out of
    /// line, so that the caller's loop holds only the compare above).
    #[inline(never)]
    fn descend(&mut self, start: u8, code: u64) -> Option<Found> {
        let mut e = self.path[start as usize];
        let mut d = start;
        let (answer, settled) = loop {
            if d == TREE_DEPTH {
                break (Some(self.nodes.found(e, d)), d);
            }
            match self.nodes.child(e, ((code >> (3 * (15 - u32::from(d)))) & 7) as usize) {
                Some(Ok(c)) => {
                    e = c;
                    d += 1;
                    self.path[d as usize] = c;
                }
                Some(Err(0)) => break (Some(self.nodes.found(e, d)), d),
                Some(Err(_)) => break (None, d + 1),
                // a corrupted file may end the walk: no answer, as `search`
                None => break (None, TREE_DEPTH + 1),
            }
        };
        self.len = d;
        self.last.set(settled, answer)
    }
}

/// The arena's nodes for a [`PathSearch`] (`OccupancyTree::cast_ray`).
#[derive(Clone, Copy)]
pub(crate) struct ArenaPath<'a> {
    /// Empty arrays for an empty tree, whose path is never walked.
    parts: Parts<'a>,
    empty: bool,
}

impl<'a> ArenaPath<'a> {
    pub fn new(tree: &'a OccupancyTree) -> Self {
        match tree.arena() {
            Some(a) => ArenaPath { parts: a.parts(), empty: false },
            None => ArenaPath { parts: Parts::EMPTY, empty: true },
        }
    }
}

impl PathNodes for ArenaPath<'_> {
    type Entry = NodeId;

    fn root(&self) -> Option<NodeId> {
        (!self.empty).then_some(ROOT)
    }

    #[inline(always)]
    fn child(&self, n: NodeId, pos: usize) -> Option<Result<NodeId, u8>> {
        Some(self.parts.descend(n, pos as u64))
    }

    #[inline(always)]
    fn found(&self, n: NodeId, depth: u8) -> Found {
        Found { value: self.parts.value(n), depth, is_leaf: true, extra: self.parts.extra(n) }
    }
}

/// The number of levels (0..=16) whose child index is the same in two
/// 48-bit Morton codes.
#[inline(always)]
fn shared_levels(a: u64, b: u64) -> u8 {
    (((a ^ b).leading_zeros() - 16) / 3) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;
    use crate::mapped::{self, MappedMap};
    use crate::morton::MortonCode;
    use crate::InnerNodes;

    /// Any sequence of codes, steps to neighbours and jumps alike, gets
    /// `search`'s answers from both cursors (the resumed paths and the
    /// settled answers included).
    #[test]
    fn cursors_answer_as_search_for_any_sequence() {
        let mut tree = OccupancyTree::new(0.1).unwrap();
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut rand = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let near = |r: u64| (32700 + (r % 140)) as u16;
        for i in 0..3000 {
            let k = Key([near(rand()), near(rand() >> 16), near(rand() >> 32)]);
            tree.update_occupancy(k, i % 3 != 0, InnerNodes::Update);
        }
        // pruned regions: a full block of equal free voxels
        for x in 32704..32720u16 {
            for y in 32704..32720u16 {
                for z in 32704..32720u16 {
                    tree.set_value(Key([x, y, z]), -2.0, InnerNodes::Update);
                }
            }
        }
        tree.prune();
        let bytes = mapped::to_bytes(&tree, mapped::WriteOptions::default()).unwrap();
        let map = MappedMap::new(bytes).unwrap();
        let mut key = Key([32710, 32710, 32710]);
        let codes: Vec<u64> = (0..20_000)
            .map(|i| {
                let r = rand();
                key = if i % 7 == 0 {
                    Key([near(r), near(r >> 16), near(r >> 32)])
                } else {
                    let axis = (r % 3) as usize;
                    key.0[axis] = if r & 8 == 0 { key.0[axis].wrapping_add(1) } else { key.0[axis].wrapping_sub(1) };
                    key
                };
                MortonCode::encode(key).0
            })
            .collect();
        let mut ours = PathSearch::new(ArenaPath::new(&tree));
        let theirs = map.view().path_search_all(&codes);
        for (&code, t) in codes.iter().zip(theirs) {
            let key = MortonCode(code).decode();
            let want = tree.search(key, 0);
            assert_eq!(ours.search(code), want, "{key}");
            let bits = |f: Option<Found>| f.map(|f| (f.value.to_bits(), f.depth, f.is_leaf));
            assert_eq!(bits(t), bits(want), "mapped, {key}");
        }
    }
}
