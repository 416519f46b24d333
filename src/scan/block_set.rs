//! A scan's set of voxels as bitmaps of aligned 8x8x8 blocks.
//!
//! The rays of one scan visit each free voxel about ten times (the rays
//! near the sensor share their first voxels). Setting a bit per visit
//! absorbs the repeats where they happen, and the set comes out in Morton
//! order by sorting its blocks (a few hundred per indoor scan) instead of
//! every code: an aligned block of 512 voxels is a range of 512 Morton
//! codes, so its bits, read in order, are its codes in order.

use super::KeyHasher;
use hashbrown::HashMap;
use std::hash::BuildHasherDefault;

/// Low code bits that address a voxel inside its block.
const BLOCK_BITS: u32 = 9;
/// 64-bit words per block.
const WORDS: usize = 1 << (BLOCK_BITS - 6);
/// Slots of the direct-mapped table of recently used blocks.
const RECENT_BITS: u32 = 8;

/// A set of Morton codes (48 bits).
pub(crate) struct BlockSet {
    /// Block (code >> [`BLOCK_BITS`]) to its number in `words`.
    index: HashMap<u64, u32, BuildHasherDefault<KeyHasher>>,
    /// Recently used blocks and their numbers, before `index` (a fixed
    /// array: a slot needs no bounds test).
    recent: Box<[(u64, u32); 1 << RECENT_BITS]>,
    /// [`WORDS`] words per block, in the order the blocks were first used.
    words: Vec<u64>,
}

/// A block's slot in the table of recent ones: its code's low bits, so the
/// blocks of an 8x8x4 box of blocks take distinct slots (a multiplicative
/// hash here cost 5% of a small map's insertion).
#[inline(always)]
fn recent_slot(block: u64) -> usize {
    (block & ((1 << RECENT_BITS) - 1)) as usize
}

impl Default for BlockSet {
    fn default() -> Self {
        BlockSet { index: HashMap::default(), recent: Box::new([(u64::MAX, 0); 1 << RECENT_BITS]), words: Vec::new() }
    }
}

impl BlockSet {
    /// Adds `code`. Every call goes through the table of recent blocks: a
    /// test whether the block is the previous code's would be mispredicted
    /// at each of a ray's block changes (one step in six).
    #[inline(always)]
    pub fn insert(&mut self, code: u64) {
        let block = code >> BLOCK_BITS;
        let (b, n) = self.recent[recent_slot(block)];
        let n = if b == block { n as usize } else { self.add_block(block) };
        self.words[n * WORDS + ((code >> 6) as usize & (WORDS - 1))] |= 1 << (code & 63);
    }

    /// The number of `block`, which is added if new; it becomes recent.
    #[inline(never)]
    fn add_block(&mut self, block: u64) -> usize {
        let words = &mut self.words;
        let n = *self.index.entry(block).or_insert_with(|| {
            let n = words.len() / WORDS;
            words.resize(words.len() + WORDS, 0);
            u32::try_from(n).expect("fewer than 2^32 blocks per scan")
        });
        self.recent[recent_slot(block)] = (block, n);
        n as usize
    }

    /// The words of `block`, if it is in the set.
    fn get(&self, block: u64) -> Option<&[u64]> {
        let n = *self.index.get(&block)? as usize;
        Some(&self.words[n * WORDS..][..WORDS])
    }

    /// The codes in Morton order, less those in `except`.
    pub fn sorted_codes(&self, except: Option<&BlockSet>) -> Vec<u64> {
        let mut blocks: Vec<(u64, u32)> = self.index.iter().map(|(&b, &n)| (b, n)).collect();
        blocks.sort_unstable_by_key(|&(b, _)| b);
        let count = self.words.iter().map(|w| w.count_ones() as usize).sum();
        let mut out = Vec::with_capacity(count);
        for (block, n) in blocks {
            let words = &self.words[n as usize * WORDS..][..WORDS];
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
        for i in 0..20_000 {
            // clustered codes (repeats, shared blocks) and scattered ones
            let code = if i % 3 == 0 { next() & ((1 << 48) - 1) } else { (1 << 40) + next() % 30_000 };
            set.insert(code);
            model.insert(code);
            if i % 7 == 0 {
                except.insert(code);
                dropped.insert(code);
            }
        }
        let all: Vec<u64> = model.iter().copied().collect();
        assert_eq!(set.sorted_codes(None), all);
        let kept: Vec<u64> = model.difference(&dropped).copied().collect();
        assert_eq!(set.sorted_codes(Some(&except)), kept);
        assert_eq!(BlockSet::default().sorted_codes(None), Vec::<u64>::new());
    }
}
