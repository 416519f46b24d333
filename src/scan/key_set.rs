//! OctoMap's `KeySet` as a hash set of Morton codes, where the block
//! bitmaps do not pay (merging end points for `discretize`).

use crate::morton::MortonCode;
use hashbrown::HashSet;
use std::hash::{BuildHasherDefault, Hasher};

/// A hasher for keys: the Morton code mixed by one multiplication.
#[derive(Default, Clone, Copy)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    #[inline(always)]
    fn finish(&self) -> u64 {
        self.0
    }

    #[inline(always)]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }

    #[inline(always)]
    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 29)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        self.0 ^= self.0 >> 32;
    }
}

/// A set of keys (OctoMap's `KeySet`) as Morton codes, on hashbrown with
/// [`KeyHasher`].
pub type KeySet = HashSet<MortonCode, BuildHasherDefault<KeyHasher>>;
