//! Where a search can start instead of the root.
//!
//! A map covers a few hundred metres of a key space that spans 65,536
//! voxels per axis, around its centre: below each child of the root, the
//! first levels are a chain of nodes with one child each (the simulator's
//! indoor map at 0.2 m: 9 of its 16 levels). A search for a key inside that
//! chain's region passes exactly those nodes, so it may start at the
//! chain's end: one table look-up and a compare instead of ~9 dependent
//! loads. Any node would be a correct start for the keys under it; the
//! chain's end is the deepest one that covers all of its root child's
//! content. Used by the arena tree and the mapped view alike.

use crate::key::TREE_DEPTH;

/// Per child of the root, the end of its chain of single-child nodes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Trunks<N> {
    root: N,
    /// The Morton code bits of the path to the end (the rest zero), its
    /// depth in the top byte.
    ends: [u64; 8],
    nodes: [N; 8],
}

const DEPTH_SHIFT: u32 = 56;

impl<N: Copy> Trunks<N> {
    /// Every search starts at `root`.
    pub fn at_root(root: N) -> Self {
        Trunks { root, ends: [0; 8], nodes: [root; 8] }
    }

    /// Follows the chains below `root`, given a node's child mask and its
    /// child at a position; `None` from either (a corrupted mapped file)
    /// ends a chain where it is.
    pub fn build(root: N, mask: impl Fn(N) -> Option<u8>, child: impl Fn(N, u8, usize) -> Option<N>) -> Self {
        let mut t = Self::at_root(root);
        let Some(root_mask) = mask(root) else { return t };
        for pos in 0..8 {
            let Some(mut node) = (root_mask & (1 << pos) != 0).then(|| child(root, root_mask, pos)).flatten() else {
                continue;
            };
            let (mut depth, mut prefix) = (1u8, (pos as u64) << (3 * (TREE_DEPTH - 1)));
            while depth < TREE_DEPTH {
                let Some(m) = mask(node).filter(|m| m.count_ones() == 1) else { break };
                let p = m.trailing_zeros() as usize;
                let Some(c) = child(node, m, p) else { break };
                prefix |= (p as u64) << (3 * (TREE_DEPTH - 1 - depth));
                (node, depth) = (c, depth + 1);
            }
            t.ends[pos] = prefix | (u64::from(depth) << DEPTH_SHIFT);
            t.nodes[pos] = node;
        }
        t
    }

    /// The depth of the shallowest chain end below the root (0 when the
    /// root has no children): every search for a key inside the chains'
    /// regions starts at least this deep.
    pub fn shallowest_end(&self) -> u8 {
        let present = self.ends.iter().map(|e| (e >> DEPTH_SHIFT) as u8).filter(|&d| d > 0);
        present.min().unwrap_or(0)
    }

    /// The node a search for `code` (a Morton code, at `depth`) can start
    /// from, and its depth.
    #[inline(always)]
    pub fn start(&self, code: u64, depth: u8) -> (N, u8) {
        let i = (code >> (3 * (TREE_DEPTH - 1))) as usize & 7;
        let end = self.ends[i];
        let end_depth = (end >> DEPTH_SHIFT) as u8;
        let shift = 3 * u32::from(TREE_DEPTH - end_depth);
        // the prefix bits without the depth byte
        if end_depth <= depth && ((code ^ end) & ((1 << DEPTH_SHIFT) - 1)) >> shift == 0 {
            (self.nodes[i], end_depth)
        } else {
            (self.root, 0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;
    use crate::morton::MortonCode;
    use crate::OccupancyTree;

    /// Starting at the trunk gives what starting at the root gives, for keys
    /// inside, beside and far from the mapped region, at every depth.
    #[test]
    fn searches_from_the_trunk_match_searches_from_the_root() {
        let mut tree = OccupancyTree::new(0.1).unwrap();
        let mut keys = Vec::new();
        for (x, y, z) in
            [(32768u16, 32768u16, 32768u16), (32770, 32760, 32769), (32700, 32800, 32790), (40000, 1, 65535)]
        {
            keys.push(Key([x, y, z]));
        }
        for k in &keys[..3] {
            tree.update_occupancy(*k, true, crate::InnerNodes::Update);
        }
        let a = tree.arena().unwrap();
        let p = a.parts();
        let t = Trunks::build(crate::tree::ROOT, |n| Some(p.mask(n)), |n, _, pos| p.descend(n, pos as u64).ok());
        assert!(t.ends.iter().any(|e| e >> DEPTH_SHIFT > 8), "{t:?}");
        for k in keys.iter().chain([Key([32769, 32768, 32768]), Key([0, 0, 0]), Key([32767, 32767, 32767])].iter()) {
            let code = MortonCode::encode(*k).0;
            for depth in 0..=TREE_DEPTH {
                let (node, d) = t.start(code, depth);
                // the start is on the key's path: descending from the root
                // `d` levels reaches it
                let mut n = crate::tree::ROOT;
                for level in 0..d {
                    n = p.descend(n, MortonCode(code).child_index(level) as u64).expect("on the path");
                }
                assert_eq!(n, node, "{k} depth {depth}");
                assert!(d <= depth);
            }
        }
    }
}
