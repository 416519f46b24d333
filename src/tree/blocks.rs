//! Depth-13 subtrees as runs of bytes, for the last steps of a full-depth
//! search on a large map.
//!
//! Per depth-13 node, one run: its child mask, its children's masks, their
//! children's masks (each level in child order), then one palette code per
//! voxel below it. A search reaching the node reads one or two cache lines
//! of its run instead of missing in the levels' arrays of megabytes each,
//! and finds its way by counting mask bits eight bytes at a time. The
//! level index of a large plain tree holds its voxels this way
//! (`level_index`), and so may a mapped file (its search-blocks section,
//! `formats/olm.md`), in the same bytes.

/// The depth of the nodes whose subtrees a run holds.
pub(crate) const BLOCK_DEPTH: u8 = 13;

/// Zero bytes after the last run, so that an eight-byte read starting in
/// any run stays inside the bytes.
pub(crate) const PADDING: usize = 8;

/// The runs of a level's depth-13 nodes.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Runs {
    /// Where each depth-13 node's run starts in `bytes`.
    pub offsets: Vec<u32>,
    /// The runs, then [`PADDING`].
    pub bytes: Vec<u8>,
}

/// A tree's depth-13 subtrees as runs, in breadth-first numbering, for a
/// mapped file.
pub(crate) struct SubtreeRuns {
    /// The breadth-first index of the first depth-13 node.
    pub first: u32,
    /// The palette: the distinct voxel values, by code.
    pub values: Vec<f32>,
    pub runs: Runs,
}

/// Where a search below a depth-13 node ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum BlockEnd {
    /// The voxel's palette code.
    Voxel(u8),
    /// The path ends at a node lacking the child: unknown space.
    Unknown,
    /// The path ends at a leaf at depth 13, 14 or 15.
    Coarse,
}

impl Runs {
    /// The runs of the depth-13 nodes, given the masks at depths 13, 14
    /// and 15 (breadth-first) and the voxels' palette codes (breadth-first
    /// too).
    pub fn build(levels: [&[u8]; 3], codes: &[u8]) -> Runs {
        let [m13, m14, m15] = levels;
        let mut bytes = Vec::with_capacity(m13.len() + m14.len() + m15.len() + codes.len() + PADDING);
        let mut offsets = Vec::with_capacity(m13.len());
        // where the next node's descendants start at each level below
        let (mut at14, mut at15, mut at_voxel) = (0, 0, 0);
        let children = |masks: &[u8]| masks.iter().map(|&m| crate::arch::count_ones(m) as usize).sum::<usize>();
        for &m in m13 {
            offsets.push(bytes.len() as u32);
            bytes.push(m);
            let n14 = crate::arch::count_ones(m) as usize;
            let s14 = &m14[at14..at14 + n14];
            let n15 = children(s14);
            let s15 = &m15[at15..at15 + n15];
            let voxels = children(s15);
            bytes.extend_from_slice(s14);
            bytes.extend_from_slice(s15);
            bytes.extend_from_slice(&codes[at_voxel..at_voxel + voxels]);
            (at14, at15, at_voxel) = (at14 + n14, at15 + n15, at_voxel + voxels);
        }
        bytes.extend_from_slice(&[0; PADDING]);
        Runs { offsets, bytes }
    }
}

/// The rest of a full-depth search for `code` (a voxel's Morton code)
/// below the depth-13 node whose run starts at `at`. `None` when the
/// bytes end early (only in a corrupted file).
#[inline(always)]
pub(crate) fn walk(b: &[u8], mut at: usize, code: u64) -> Option<BlockEnd> {
    let pos = |depth: u8| (code >> (3 * (15 - depth))) as u32 & 7;
    let below = |m: u8, p: u32| crate::arch::count_ones(u32::from(m) & ((1 << p) - 1)) as usize;
    let ended = |m: u8| Some(if m == 0 { BlockEnd::Coarse } else { BlockEnd::Unknown });
    let m13 = *b.get(at)?;
    let p = pos(BLOCK_DEPTH);
    if m13 & (1 << p) == 0 {
        return ended(m13);
    }
    // depth 14: the children of the one node at depth 13
    let (n14, r14) = (crate::arch::count_ones(m13) as usize, below(m13, p));
    let w14 = word(b, at + 1)?;
    let m14 = *b.get(at + 1 + r14)?;
    let p = pos(BLOCK_DEPTH + 1);
    if m14 & (1 << p) == 0 {
        return ended(m14);
    }
    // depth 15, after the depth-14 masks: this node's rank is the bits of
    // the masks before its parent's and of its parent's below it
    at += 1 + n14;
    let n15 = crate::arch::count_ones(w14 & low_bytes(n14)) as usize;
    let r15 = crate::arch::count_ones(w14 & low_bytes(r14)) as usize + below(m14, p);
    let m15 = *b.get(at + r15)?;
    let p = pos(BLOCK_DEPTH + 2);
    if m15 & (1 << p) == 0 {
        return ended(m15);
    }
    // the voxels, after the depth-15 masks
    let voxel = ones(b, at, r15)? + below(m15, p);
    Some(BlockEnd::Voxel(*b.get(at + n15 + voxel)?))
}

/// The eight bytes of `b` from `at` as a little-endian word.
#[inline(always)]
fn word(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

/// A mask of the low `k` bytes of a word (`k` ≤ 8).
#[inline(always)]
fn low_bytes(k: usize) -> u64 {
    // two shifts, so that k = 8 does not shift by 64
    ((1u64 << (4 * k)) << (4 * k)).wrapping_sub(1)
}

/// The set bits of `b[at..at + len]`.
#[inline(always)]
fn ones(b: &[u8], at: usize, len: usize) -> Option<usize> {
    let mut n = 0;
    let mut i = 0;
    while i + 8 <= len {
        n += crate::arch::count_ones(word(b, at + i)?);
        i += 8;
    }
    n += crate::arch::count_ones(word(b, at + i)? & low_bytes(len - i));
    Some(n as usize)
}
