//! Child lookup on the mapped sections, one implementation per layout.
//!
//! Every read is bounds-checked; an index that falls outside its section,
//! or a child that would not lie strictly after its parent, ends the walk
//! (`None`) instead of panicking. Verified files never take those exits.

use super::format::{f32_at, u16_at, u32_at, u64_at, Index, Meta, TreeKind, Variant};
use crate::key::TREE_DEPTH;
use crate::tree::{pack_rgb, WHITE};

/// A node of the mapped tree. For the full layouts `idx` is the node's
/// position in the node arrays; for maximum likelihood, `label` is the
/// node's two-bit label (1 free leaf, 2 occupied leaf, 3 inner) and `idx`
/// the inner record of an inner node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Node {
    pub idx: u32,
    pub label: u8,
}

/// Navigation over one layout.
pub(crate) trait Nav: Copy {
    fn root(&self) -> Option<Node>;
    /// The node's log-odds and child mask.
    fn get(&self, n: Node) -> Option<(f32, u8)>;
    /// The child mask alone (a descent needs the value only where it ends).
    #[inline(always)]
    fn mask(&self, n: Node) -> Option<u8> {
        self.get(n).map(|(_, m)| m)
    }
    /// Child `pos` (present in `mask`, the node's mask).
    fn child(&self, n: Node, mask: u8, pos: usize) -> Option<Node>;
    /// Where the children of `n` (whose mask is `mask`) begin, for the
    /// layouts whose child `pos` is that index plus the number of children
    /// before `pos`; `None` for the others.
    #[inline(always)]
    fn first_child_index(&self, _n: Node, _mask: u8) -> Option<u32> {
        None
    }
    /// A search's descent for the Morton `code` from `node`, at depth
    /// `from` on its path, down to `depth`: where it stops, at what depth,
    /// and that node's mask (0 when it stopped early at a leaf); `None`
    /// when the path ends at an inner node lacking the child (unknown) or
    /// the layout's bytes give no answer.
    #[inline(always)]
    fn descend(&self, node: Node, from: u8, depth: u8, code: u64) -> Option<(Node, u8, u8)> {
        descend_by_child(self, node, from, depth, code)
    }
    /// The children present in `mask`, in child order; returns how many.
    fn children(&self, n: Node, mask: u8, out: &mut [Node; 8]) -> Option<usize>;
    /// An upper bound on the nodes a traversal may visit.
    fn node_budget(&self) -> u64;
    /// [`Nav::children`] for a traversal that visits each level's nodes in
    /// increasing order: `slot` (one per level, initially `(0, 0)`)
    /// remembers where the next node's children start, so that a run of
    /// consecutive nodes needs no rank computation.
    #[inline]
    fn children_seq(&self, n: Node, mask: u8, _slot: &mut (u32, u32), out: &mut [Node; 8]) -> Option<usize> {
        self.children(n, mask, out)
    }
    /// Tells the sequence that a childless node `n` was passed.
    #[inline]
    fn skip_seq(&self, _n: Node, _slot: &mut (u32, u32)) {}

    /// How an iteration holds a node's children: the first index where
    /// they are consecutive records, the listed nodes otherwise.
    type Group: Copy + Default;
    /// [`Nav::children_seq`] as a group of exactly `popcount(mask)`
    /// children; `None` when the layout cannot give them all.
    fn group_seq(&self, n: Node, mask: u8, slot: &mut (u32, u32)) -> Option<Self::Group>;
    /// Child `j` (in child order) of a group.
    fn member(&self, g: &Self::Group, j: usize) -> Node;
}

/// [`Nav::descend`]'s generic body, for overrides that fall back to it.
#[inline(always)]
fn descend_by_child<N: Nav>(nav: &N, mut node: Node, from: u8, depth: u8, code: u64) -> Option<(Node, u8, u8)> {
    let mut mask = nav.mask(node)?;
    for d in from..depth {
        let pos = ((code >> (3 * (TREE_DEPTH - 1 - d))) & 7) as usize;
        if mask & (1 << pos) == 0 {
            return (mask == 0).then_some((node, d, 0));
        }
        node = nav.child(node, mask, pos)?;
        mask = nav.mask(node)?;
    }
    Some((node, depth, mask))
}

#[inline(always)]
pub(crate) fn below(pos: usize) -> u8 {
    ((1u16 << pos) - 1) as u8
}

/// Counts of `11` pairs (inner children) in a word of two-bit labels.
#[inline(always)]
pub(crate) fn count_inner(x: u64) -> u32 {
    crate::arch::count_ones(x & (x >> 1) & 0x5555_5555_5555_5555)
}

/// Child mask of a label word: bit `i` set when label `i` is not `00`.
#[inline(always)]
pub(crate) fn label_mask(w: u16) -> u8 {
    let x = u32::from((w | (w >> 1)) & 0x5555);
    let x = (x | (x >> 1)) & 0x3333;
    let x = (x | (x >> 2)) & 0x0f0f;
    let x = (x | (x >> 4)) & 0x00ff;
    x as u8
}

/// Full variant, breadth-first order, rank directory.
#[derive(Clone, Copy)]
pub(crate) struct RankNav<'a> {
    pub masks: &'a [u8],
    pub values: &'a [u8],
    /// The values section holds counts (a counting tree): values read 0,
    /// as in the in-memory [`crate::CountingTree`], and counts are extras.
    pub counts: bool,
    pub dir: &'a [u8],
    pub log2: u32,
    pub n: u32,
}

impl RankNav<'_> {
    /// Children of the nodes `0..i` (the first child of `i` is at `1 + rank(i)`).
    #[inline(always)]
    pub fn rank(&self, i: u32) -> Option<u32> {
        let i = i as usize;
        if self.log2 == 3 {
            // one word of masks per block (the writer's default): one
            // directory entry plus one masked popcount
            // no branch on `i & 7`: it is 0 for one node in eight at
            // random, and the mispredicted branch cost more than the load
            // it saved (the block's word lies in the mask section, which
            // holds whole words)
            let base = u32_at(self.dir, 4 * (i >> 3))?;
            let word = u64_at(self.masks, 8 * (i >> 3))?;
            return Some(base.wrapping_add(crate::arch::count_ones(word & ((1u64 << (8 * (i & 7))) - 1))));
        }
        let b = i >> self.log2;
        let mut s = u32_at(self.dir, 4 * b)?;
        let end = i >> 3;
        let mut w = (b << self.log2) >> 3;
        while w < end {
            s = s.wrapping_add(crate::arch::count_ones(u64_at(self.masks, 8 * w)?));
            w += 1;
        }
        let rem = i & 7;
        if rem != 0 {
            let word = u64_at(self.masks, 8 * end)?;
            s = s.wrapping_add(crate::arch::count_ones(word & ((1u64 << (8 * rem)) - 1)));
        }
        Some(s)
    }

    #[inline(always)]
    fn first_child(&self, n: Node) -> Option<u32> {
        let c = self.rank(n.idx)?.checked_add(1)?;
        (c > n.idx).then_some(c)
    }
}

impl Nav for RankNav<'_> {
    #[inline(always)]
    fn first_child_index(&self, n: Node, mask: u8) -> Option<u32> {
        (mask != 0).then(|| self.first_child(n)).flatten()
    }

    #[inline(always)]
    fn root(&self) -> Option<Node> {
        (self.n > 0).then_some(Node { idx: 0, label: 0 })
    }

    #[inline(always)]
    fn get(&self, n: Node) -> Option<(f32, u8)> {
        let i = n.idx as usize;
        let value = if self.counts { 0.0 } else { f32_at(self.values, 4 * i)? };
        Some((value, *self.masks.get(i)?))
    }

    #[inline(always)]
    fn mask(&self, n: Node) -> Option<u8> {
        self.masks.get(n.idx as usize).copied()
    }

    /// Child `pos` lies after its parent and within the nodes (in a
    /// corrupted file a rank may point anywhere; [`Nav::descend`] makes the
    /// same test, so single and batched searches agree on any bytes).
    #[inline(always)]
    fn child(&self, n: Node, mask: u8, pos: usize) -> Option<Node> {
        let c = u64::from(self.rank(n.idx)?) + 1 + u64::from(crate::arch::count_ones(mask & below(pos)));
        (c > u64::from(n.idx) && c < u64::from(self.n)).then_some(Node { idx: c as u32, label: 0 })
    }

    /// With the writer's default 8-node blocks, one word of masks holds a
    /// node's own mask and those counted by its rank, so a level reads
    /// that word and one directory entry, and one popcount of the word
    /// gives the child: the chain of dependent steps per level is a load,
    /// a mask, a popcount and an add.
    #[inline(always)]
    fn descend(&self, node: Node, from: u8, depth: u8, code: u64) -> Option<(Node, u8, u8)> {
        if self.log2 != 3 {
            return descend_by_child(self, node, from, depth, code);
        }
        // the sections cut to the blocks that nodes `0..n` use, once per
        // descent, so that a level tests only its block
        let blocks = (self.n as usize).div_ceil(8);
        let (Some(masks), Some(dir)) = (self.masks.get(..8 * blocks), self.dir.get(..4 * blocks)) else {
            return descend_by_child(self, node, from, depth, code);
        };
        let n = u64::from(self.n);
        let mut i = node.idx;
        // the child positions still to take, left-aligned: level `d`'s three
        // bits are the top ones when it is reached
        let mut positions = (code << (64 - 3 * u32::from(TREE_DEPTH))) << (3 * u32::from(from));
        for d in from..depth {
            let block = (i >> 3) as usize;
            if block >= blocks {
                return None;
            }
            let word = u64::from_le_bytes(masks[8 * block..8 * block + 8].try_into().ok()?);
            let pos = (positions >> 61) as u32;
            positions <<= 3;
            // node i's mask is the word's byte i & 7; child `pos`'s bit in
            // the word is `bit`
            let bit = 8 * (i & 7) + pos;
            if word & (1 << bit) == 0 {
                let mask = (word >> (8 * (i & 7))) as u8;
                return (mask == 0).then_some((Node { idx: i, label: 0 }, d, 0));
            }
            // RankNav::first_child and child in one count: the children of
            // the nodes before `i` in its block and of `i` before `pos` are
            // the word's bits below `bit`; the mask and the directory entry
            // plus one come off the chain of dependent steps
            let base = u64::from(u32::from_le_bytes(dir[4 * block..4 * block + 4].try_into().ok()?)) + 1;
            let child = base + u64::from(crate::arch::count_ones(word & ((1u64 << bit) - 1)));
            // `child`'s test (a branch beside the chain of dependent steps)
            if child <= u64::from(i) || child >= n {
                return None;
            }
            i = child as u32;
        }
        let mask = *masks.get(i as usize)?;
        Some((Node { idx: i, label: 0 }, depth, mask))
    }

    #[inline]
    fn children(&self, n: Node, mask: u8, out: &mut [Node; 8]) -> Option<usize> {
        let first = self.first_child(n)?;
        let k = crate::arch::count_ones(mask);
        if first.checked_add(k)? > self.n {
            return None;
        }
        for (j, o) in out.iter_mut().take(k as usize).enumerate() {
            *o = Node { idx: first + j as u32, label: 0 };
        }
        Some(k as usize)
    }

    fn node_budget(&self) -> u64 {
        u64::from(self.n)
    }

    #[inline]
    fn children_seq(&self, n: Node, mask: u8, slot: &mut (u32, u32), out: &mut [Node; 8]) -> Option<usize> {
        let k = crate::arch::count_ones(mask);
        let first = if slot.0 == n.idx && n.idx != 0 { slot.1 } else { self.first_child(n)? };
        *slot = (n.idx.wrapping_add(1), first.wrapping_add(k));
        if first <= n.idx || first.checked_add(k)? > self.n {
            return None;
        }
        for (j, o) in out.iter_mut().take(k as usize).enumerate() {
            *o = Node { idx: first + j as u32, label: 0 };
        }
        Some(k as usize)
    }

    #[inline]
    fn skip_seq(&self, n: Node, slot: &mut (u32, u32)) {
        if slot.0 == n.idx {
            slot.0 = slot.0.wrapping_add(1);
        }
    }

    type Group = u32;

    #[inline(always)]
    fn group_seq(&self, n: Node, mask: u8, slot: &mut (u32, u32)) -> Option<u32> {
        let k = crate::arch::count_ones(mask);
        let first = if slot.0 == n.idx && n.idx != 0 { slot.1 } else { self.first_child(n)? };
        *slot = (n.idx.wrapping_add(1), first.wrapping_add(k));
        (first > n.idx && first.checked_add(k)? <= self.n).then_some(first)
    }

    #[inline(always)]
    fn member(&self, first: &u32, j: usize) -> Node {
        Node { idx: first + j as u32, label: 0 }
    }
}

/// Full variant, depth-first group order, first-child pointers.
#[derive(Clone, Copy)]
pub(crate) struct PtrNav<'a> {
    pub masks: &'a [u8],
    pub values: &'a [u8],
    /// As [`RankNav::counts`].
    pub counts: bool,
    pub first: &'a [u8],
    pub n: u32,
}

impl PtrNav<'_> {
    #[inline(always)]
    fn first_child(&self, n: Node) -> Option<u32> {
        let c = u32_at(self.first, 4 * n.idx as usize)?;
        (c > n.idx).then_some(c)
    }
}

impl Nav for PtrNav<'_> {
    #[inline(always)]
    fn first_child_index(&self, n: Node, mask: u8) -> Option<u32> {
        (mask != 0).then(|| self.first_child(n)).flatten()
    }

    #[inline(always)]
    fn root(&self) -> Option<Node> {
        (self.n > 0).then_some(Node { idx: 0, label: 0 })
    }

    #[inline(always)]
    fn get(&self, n: Node) -> Option<(f32, u8)> {
        let i = n.idx as usize;
        let value = if self.counts { 0.0 } else { f32_at(self.values, 4 * i)? };
        Some((value, *self.masks.get(i)?))
    }

    #[inline(always)]
    fn mask(&self, n: Node) -> Option<u8> {
        self.masks.get(n.idx as usize).copied()
    }

    #[inline(always)]
    fn child(&self, n: Node, mask: u8, pos: usize) -> Option<Node> {
        let c = self.first_child(n)?.checked_add(crate::arch::count_ones(mask & below(pos)))?;
        (c < self.n).then_some(Node { idx: c, label: 0 })
    }

    #[inline]
    fn children(&self, n: Node, mask: u8, out: &mut [Node; 8]) -> Option<usize> {
        let first = self.first_child(n)?;
        let k = crate::arch::count_ones(mask);
        if first.checked_add(k)? > self.n {
            return None;
        }
        for (j, o) in out.iter_mut().take(k as usize).enumerate() {
            *o = Node { idx: first + j as u32, label: 0 };
        }
        Some(k as usize)
    }

    fn node_budget(&self) -> u64 {
        u64::from(self.n)
    }

    type Group = u32;

    #[inline(always)]
    fn group_seq(&self, n: Node, mask: u8, _slot: &mut (u32, u32)) -> Option<u32> {
        let first = self.first_child(n)?;
        (first.checked_add(crate::arch::count_ones(mask))? <= self.n).then_some(first)
    }

    #[inline(always)]
    fn member(&self, first: &u32, j: usize) -> Node {
        Node { idx: first + j as u32, label: 0 }
    }
}

/// Maximum likelihood: breadth-first inner records of child labels.
#[derive(Clone, Copy)]
pub(crate) struct MlNav<'a> {
    pub labels: &'a [u8],
    pub occupancy: &'a [u8],
    pub dir: &'a [u8],
    pub log2: u32,
    /// Inner records.
    pub inner: u32,
    pub nodes: u32,
    pub root_label: u8,
    pub free: f32,
    pub occupied: f32,
}

impl MlNav<'_> {
    /// Inner children of the inner records `0..j`.
    #[inline(always)]
    pub fn rank(&self, j: u32) -> Option<u32> {
        let j = j as usize;
        let b = j >> self.log2;
        let mut s = u32_at(self.dir, 4 * b)?;
        let end = j >> 2;
        let mut w = (b << self.log2) >> 2;
        while w < end {
            s = s.wrapping_add(count_inner(u64_at(self.labels, 8 * w)?));
            w += 1;
        }
        let rem = j & 3;
        if rem != 0 {
            let word = u64_at(self.labels, 8 * end)?;
            s = s.wrapping_add(count_inner(word & ((1u64 << (16 * rem)) - 1)));
        }
        Some(s)
    }

    #[inline(always)]
    pub fn word(&self, j: u32) -> Option<u16> {
        u16_at(self.labels, 2 * j as usize)
    }

    #[inline(always)]
    pub fn occupied_bit(&self, j: u32) -> Option<bool> {
        let w = u64_at(self.occupancy, 8 * (j as usize >> 6))?;
        Some(w >> (j & 63) & 1 != 0)
    }

    #[inline(always)]
    fn make_child(&self, n: Node, w: u16, pos: usize, inner_base: u32) -> Option<Node> {
        match (w >> (2 * pos)) & 3 {
            0 => None,
            3 => {
                let lower = u64::from(w) & ((1u64 << (2 * pos)) - 1);
                let c = inner_base.checked_add(count_inner(lower))?;
                (c > n.idx && c < self.inner).then_some(Node { idx: c, label: 3 })
            }
            l => Some(Node { idx: 0, label: l as u8 }),
        }
    }
}

impl Nav for MlNav<'_> {
    #[inline(always)]
    fn root(&self) -> Option<Node> {
        match self.root_label {
            0 => None,
            l => Some(Node { idx: 0, label: l }),
        }
    }

    #[inline(always)]
    fn get(&self, n: Node) -> Option<(f32, u8)> {
        match n.label {
            1 => Some((self.free, 0)),
            2 => Some((self.occupied, 0)),
            3 => {
                let v = if self.occupied_bit(n.idx)? { self.occupied } else { self.free };
                Some((v, label_mask(self.word(n.idx)?)))
            }
            _ => None,
        }
    }

    #[inline(always)]
    fn child(&self, n: Node, _mask: u8, pos: usize) -> Option<Node> {
        if n.label != 3 {
            return None;
        }
        let w = self.word(n.idx)?;
        let base = self.rank(n.idx)?.checked_add(1)?;
        self.make_child(n, w, pos, base)
    }

    #[inline]
    fn children(&self, n: Node, _mask: u8, out: &mut [Node; 8]) -> Option<usize> {
        if n.label != 3 {
            return Some(0);
        }
        let w = self.word(n.idx)?;
        let base = self.rank(n.idx)?.checked_add(1)?;
        let mut k = 0;
        for pos in 0..8 {
            if (w >> (2 * pos)) & 3 != 0 {
                out[k] = self.make_child(n, w, pos, base)?;
                k += 1;
            }
        }
        Some(k)
    }

    fn node_budget(&self) -> u64 {
        u64::from(self.nodes)
    }

    type Group = [Node; 8];

    #[inline]
    fn group_seq(&self, n: Node, mask: u8, slot: &mut (u32, u32)) -> Option<[Node; 8]> {
        let mut out = [Node::default(); 8];
        let k = self.children_seq(n, mask, slot, &mut out)?;
        (k == crate::arch::count_ones(mask) as usize).then_some(out)
    }

    #[inline(always)]
    fn member(&self, g: &[Node; 8], j: usize) -> Node {
        g[j]
    }

    #[inline]
    fn children_seq(&self, n: Node, _mask: u8, slot: &mut (u32, u32), out: &mut [Node; 8]) -> Option<usize> {
        if n.label != 3 {
            return Some(0);
        }
        let w = self.word(n.idx)?;
        let base = if slot.0 == n.idx && n.idx != 0 { slot.1 } else { self.rank(n.idx)?.checked_add(1)? };
        *slot = (n.idx.wrapping_add(1), base.wrapping_add(count_inner(u64::from(w))));
        let mut k = 0;
        for pos in 0..8 {
            if (w >> (2 * pos)) & 3 != 0 {
                out[k] = self.make_child(n, w, pos, base)?;
                k += 1;
            }
        }
        Some(k)
    }
}

/// Per-node colours, stamps or counts of the full layouts, by node index
/// (the index of the node's value). Out-of-range reads (corrupted files)
/// give the kind's default: white, stamp or count 0.
#[derive(Clone, Copy)]
pub(crate) struct Extras<'a> {
    pub kind: TreeKind,
    pub bytes: &'a [u8],
}

impl<'a> Extras<'a> {
    pub fn new(data: &'a [u8], meta: &Meta) -> Self {
        // maximum-likelihood maps have no section (`ranges` stay empty)
        let r = match meta.header.kind {
            TreeKind::OcTree => 0..0,
            TreeKind::ColorOcTree => meta.ranges.colors.clone(),
            TreeKind::OcTreeStamped => meta.ranges.stamps.clone(),
            TreeKind::CountingOcTree => meta.ranges.values.clone(),
        };
        Extras { kind: meta.header.kind, bytes: section(data, &r) }
    }

    /// The node's extra as the tree stores it (`r | g << 8 | b << 16`, the
    /// stamp, or the count); 0 for plain maps.
    #[inline(always)]
    pub fn get(&self, n: Node) -> u32 {
        let i = n.idx as usize;
        match self.kind {
            TreeKind::OcTree => 0,
            TreeKind::ColorOcTree => match self.bytes.get(3 * i..3 * i + 3) {
                Some(c) => pack_rgb([c[0], c[1], c[2]]),
                None => WHITE,
            },
            TreeKind::OcTreeStamped | TreeKind::CountingOcTree => u32_at(self.bytes, 4 * i).unwrap_or(0),
        }
    }
}

/// The navigator of a parsed file, one variant per layout.
#[derive(Clone, Copy)]
pub(crate) enum AnyNav<'a> {
    Rank(RankNav<'a>),
    Ptr(PtrNav<'a>),
    Ml(MlNav<'a>),
}

fn section<'a>(data: &'a [u8], r: &std::ops::Range<usize>) -> &'a [u8] {
    data.get(r.clone()).unwrap_or(&[])
}

impl<'a> AnyNav<'a> {
    pub fn new(data: &'a [u8], meta: &Meta) -> Self {
        let h = &meta.header;
        let r = &meta.ranges;
        let n = h.node_count.min(u64::from(u32::MAX)) as u32;
        let counts = h.kind == TreeKind::CountingOcTree;
        match (h.variant, h.index) {
            (Variant::Full, Index::Rank) => AnyNav::Rank(RankNav {
                masks: section(data, &r.masks),
                values: section(data, &r.values),
                counts,
                dir: section(data, &r.rank),
                log2: u32::from(h.rank_block_log2),
                n,
            }),
            (Variant::Full, Index::Pointers) => AnyNav::Ptr(PtrNav {
                masks: section(data, &r.masks),
                values: section(data, &r.values),
                counts,
                first: section(data, &r.first_child),
                n,
            }),
            (Variant::MaxLikelihood, _) => AnyNav::Ml(MlNav {
                labels: section(data, &r.labels),
                occupancy: section(data, &r.inner_occupancy),
                dir: section(data, &r.rank),
                log2: u32::from(h.rank_block_log2),
                inner: h.inner_count.min(u64::from(u32::MAX)) as u32,
                nodes: n,
                root_label: h.root_label,
                free: h.sensor.clamping_min,
                occupied: h.sensor.clamping_max,
            }),
        }
    }
}

/// Runs `$body` with `$nav` bound to the concrete navigator, so that the
/// body is compiled once per layout (no per-level dispatch).
macro_rules! with_nav {
    ($any:expr, |$nav:ident| $body:expr) => {
        match $any {
            $crate::mapped::nav::AnyNav::Rank($nav) => $body,
            $crate::mapped::nav::AnyNav::Ptr($nav) => $body,
            $crate::mapped::nav::AnyNav::Ml($nav) => $body,
        }
    };
}
pub(crate) use with_nav;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_masks_and_inner_counts() {
        assert_eq!(label_mask(0), 0);
        assert_eq!(label_mask(0b11_00_10_01), 0b1011);
        assert_eq!(label_mask(0xffff), 0xff);
        assert_eq!(label_mask(0b01 << 14), 0x80);
        assert_eq!(count_inner(0b11_01_11_10), 2);
        assert_eq!(count_inner(u64::MAX), 32);
    }
}
