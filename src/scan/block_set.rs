//! A scan's set of voxels as bitmaps of aligned 8x8x8 blocks.
//!
//! The rays of one scan visit each free voxel about ten times (the rays
//! near the sensor share their first voxels). Setting a bit per visit
//! absorbs the repeats where they happen, and the set comes out in Morton
//! order by sorting its blocks (a few hundred per indoor scan) instead of
//! every code: an aligned block of 512 voxels is a range of 512 Morton
//! codes, so its bits, read in order, are its codes in order.

use super::key_set::KeyHasher;
use hashbrown::HashMap;
use std::hash::BuildHasherDefault;

/// Low code bits that address a voxel inside its block.
const BLOCK_BITS: u32 = 9;
/// 64-bit words per block.
const WORDS: usize = 1 << (BLOCK_BITS - 6);
/// Slots of the direct-mapped table of recently used blocks.
const RECENT_BITS: u32 = 8;

type BlockIndex = HashMap<u64, u32, BuildHasherDefault<KeyHasher>>;
/// The blocks in the slots, and where their words start: two arrays, so
/// that a slot's place in each is a scaled index (16-byte pairs cost two
/// instructions more per code).
struct RecentBlocks {
    blocks: [u64; 1 << RECENT_BITS],
    firsts: [u32; 1 << RECENT_BITS],
}

/// A set of Morton codes (48 bits).
pub(crate) struct BlockSet {
    /// Block (code >> [`BLOCK_BITS`]) to where its words start in `words`.
    index: BlockIndex,
    /// Recently used blocks and where their words start, before `index` (a
    /// fixed array: a slot needs no bounds test).
    recent: Box<RecentBlocks>,
    /// [`WORDS`] words per block, in the order the blocks were first used.
    words: Vec<u64>,
}

/// A block's slot in the table of recent ones: its code's low bits, so the
/// blocks of an 8x8x4 box of blocks take distinct slots (a multiplicative
/// hash measured slower: `docs/benchmarks.md`, "Tried and rejected").
#[inline(always)]
fn recent_slot(block: u64) -> usize {
    (block & ((1 << RECENT_BITS) - 1)) as usize
}

impl Default for BlockSet {
    fn default() -> Self {
        BlockSet {
            index: HashMap::default(),
            recent: Box::new(RecentBlocks { blocks: [u64::MAX; 1 << RECENT_BITS], firsts: [0; 1 << RECENT_BITS] }),
            words: Vec::new(),
        }
    }
}

/// Where the words of `block` start in `words`, which get a block of
/// zeros for it if it is new; `block` becomes recent.
#[inline(never)]
fn add_block(index: &mut BlockIndex, recent: &mut RecentBlocks, words: &mut Vec<u64>, block: u64) -> usize {
    let first = *index.entry(block).or_insert_with(|| {
        let first = words.len();
        words.resize(first + WORDS, 0);
        u32::try_from(first).expect("fewer than 2^29 blocks per scan")
    });
    let slot = recent_slot(block);
    (recent.blocks[slot], recent.firsts[slot]) = (block, first);
    first as usize
}

impl BlockSet {
    /// Adds `code`.
    #[inline(always)]
    pub fn insert(&mut self, code: u64) {
        self.insert_all(std::slice::from_ref(&code));
    }

    /// Adds every code of `codes`. Every code goes through the table of
    /// recent blocks: a test whether the block is the previous code's would
    /// be mispredicted at each of a ray's block changes (one step in six).
    /// The words are written through a pointer kept across the loop: through
    /// `self.words`, the compiler reloaded the vector and checked the index
    /// at every code (a small map's walk sends its sets ~2.4M codes).
    #[inline(always)]
    pub fn insert_all(&mut self, codes: &[u64]) {
        let BlockSet { index, recent, words } = self;
        let recent = &mut **recent;
        let mut base = words.as_mut_ptr();
        for &code in codes {
            let block = code >> BLOCK_BITS;
            let slot = recent_slot(block);
            let first = if recent.blocks[slot] == block {
                recent.firsts[slot] as usize
            } else {
                let first = add_block(index, recent, words, block);
                base = words.as_mut_ptr();
                first
            };
            debug_assert!(first + WORDS <= words.len() && base.cast_const() == words.as_ptr());
            // SAFETY: `first` is where a block's WORDS words start in
            // `words` (from the table, whose initial entries match no block,
            // or from `add_block`, which keeps the two in step), the offset
            // is below WORDS, and `base` is `words`' pointer since its last
            // change
            unsafe { *base.add(first + ((code >> 6) as usize & (WORDS - 1))) |= 1 << (code & 63) };
        }
    }

    /// The words of `block`, if it is in the set.
    fn get(&self, block: u64) -> Option<&[u64]> {
        let first = *self.index.get(&block)? as usize;
        Some(&self.words[first..][..WORDS])
    }

    /// The codes in Morton order, less those in `except`. The table of
    /// blocks goes before the codes' list is made, so that a large scan's
    /// update does not hold both (the list and the words are the rest).
    pub fn into_sorted_codes(self, except: Option<&BlockSet>) -> Vec<u64> {
        let BlockSet { index, words, .. } = self;
        let mut blocks: Vec<(u64, u32)> = index.into_iter().collect();
        blocks.sort_unstable_by_key(|&(b, _)| b);
        let count = words.iter().map(|&w| crate::arch::count_ones(w) as usize).sum();
        let mut out = Vec::with_capacity(count);
        for (block, first) in blocks {
            let words = &words[first as usize..][..WORDS];
            let drop = except.and_then(|e| e.get(block));
            for (i, &w) in words.iter().enumerate() {
                let mut w = w & !drop.map_or(0, |d| d[i]);
                let base = (block << BLOCK_BITS) | ((i as u64) << 6);
                while w != 0 {
                    out.push(base | u64::from(w.trailing_zeros()));
                    w &= w - 1;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Codes come out sorted, once each, less the excepted ones, for codes
    /// spread over many blocks (more than the table of recent ones holds)
    /// and clustered ones (repeats, shared blocks).
    #[test]
    fn sorted_codes_are_the_set_in_order() {
        let mut s = 5u64;
        let mut next = || {
            s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            s >> 16
        };
        let (mut set, mut except) = (BlockSet::default(), BlockSet::default());
        let mut model = std::collections::BTreeSet::new();
        let mut dropped = std::collections::BTreeSet::new();
        let mut codes = Vec::new();
        for i in 0..20_000 {
            // clustered codes (repeats, shared blocks) and scattered ones
            let code = if i % 3 == 0 { next() & ((1 << 48) - 1) } else { (1 << 40) + next() % 30_000 };
            set.insert(code);
            codes.push(code);
            model.insert(code);
            if i % 7 == 0 {
                except.insert(code);
                dropped.insert(code);
            }
        }
        let mut again = BlockSet::default();
        again.insert_all(&codes);
        let all: Vec<u64> = model.iter().copied().collect();
        assert_eq!(set.into_sorted_codes(None), all);
        let kept: Vec<u64> = model.difference(&dropped).copied().collect();
        assert_eq!(again.into_sorted_codes(Some(&except)), kept);
        assert_eq!(BlockSet::default().into_sorted_codes(None), Vec::<u64>::new());
    }

    /// Codes added a buffer at a time (new blocks, and so reallocations of
    /// the words, in the middle of a buffer) give the same set as one by one.
    #[test]
    fn insert_all_is_insert_of_each() {
        let codes: Vec<u64> = (0..50_000u64).map(|i| (i * 2_654_435_761) % (1 << 30)).collect();
        let (mut one, mut all) = (BlockSet::default(), BlockSet::default());
        codes.iter().for_each(|&c| one.insert(c));
        codes.chunks(512).for_each(|chunk| all.insert_all(chunk));
        assert_eq!(all.into_sorted_codes(None), one.into_sorted_codes(None));
    }
}
