//! Morton (Z-order) codes of keys.
//!
//! Bit `3b` of a code is bit `b` of the x key, `3b + 1` of y and `3b + 2` of
//! z, so the three bits at level `b` are exactly OctoMap's child index
//! (x = 1, y = 2, z = 4) and sorting codes gives OctoMap's depth-first order.

use crate::key::Key;

/// A 48-bit interleaving of a key's three 16-bit indices.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MortonCode(pub u64);

/// Spreads the 16 bits of `v` to every third bit (bit `b` to bit `3b`).
#[inline(always)]
pub fn spread_bits(v: u16) -> u64 {
    let mut x = u64::from(v);
    x = (x | (x << 16)) & 0x0000_ff00_00ff;
    x = (x | (x << 8)) & 0x00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x2492_4924_9249;
    x
}

/// Inverse of [`spread_bits`]: gathers every third bit.
#[inline(always)]
pub fn compact_bits(v: u64) -> u16 {
    let mut x = v & 0x2492_4924_9249;
    x = (x | (x >> 2)) & 0x0c30_c30c_30c3;
    x = (x | (x >> 4)) & 0x00f0_0f00_f00f;
    x = (x | (x >> 8)) & 0x0000_ff00_00ff;
    x = (x | (x >> 16)) & 0xffff;
    x as u16
}

/// Byte-wise spread table for the table-driven encoder.
static SPREAD_TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut v = 0u32;
        let mut b = 0;
        while b < 8 {
            v |= ((i as u32 >> b) & 1) << (3 * b);
            b += 1;
        }
        t[i] = v;
        i += 1;
    }
    t
};

impl MortonCode {
    /// Encodes with shifts and masks (portable, branch-free).
    #[inline(always)]
    pub fn encode(key: Key) -> Self {
        let [x, y, z] = key.0;
        MortonCode(spread_bits(x) | (spread_bits(y) << 1) | (spread_bits(z) << 2))
    }

    /// The code's low 24 bits (depths 8 to 15: the low byte of each axis)
    /// of a [`Key::packed`] key, by three table look-ups: what a descent
    /// from depth 8 or deeper needs.
    #[inline(always)]
    pub fn low_levels(packed: u64) -> u64 {
        let spread = |shift: u32| u64::from(SPREAD_TABLE[((packed >> shift) & 0xff) as usize]);
        spread(0) | (spread(16) << 1) | (spread(32) << 2)
    }

    /// Encodes with a 256-entry lookup table (one load per byte and axis).
    #[inline]
    pub fn encode_table(key: Key) -> Self {
        let spread = |v: u16| -> u64 {
            u64::from(SPREAD_TABLE[(v & 0xff) as usize]) | (u64::from(SPREAD_TABLE[(v >> 8) as usize]) << 24)
        };
        let [x, y, z] = key.0;
        MortonCode(spread(x) | (spread(y) << 1) | (spread(z) << 2))
    }

    /// Encodes with BMI2 `pdep` where the CPU has it, else falls back.
    #[inline]
    pub fn encode_bmi2(key: Key) -> Self {
        #[cfg(target_arch = "x86_64")]
        if let Some(bmi2) = crate::arch::bmi2::Bmi2::detect() {
            return bmi2.morton_encode(key);
        }
        Self::encode(key)
    }

    /// Decodes back to a key.
    #[inline]
    pub fn decode(self) -> Key {
        Key([compact_bits(self.0), compact_bits(self.0 >> 1), compact_bits(self.0 >> 2)])
    }

    /// Decodes with BMI2 `pext` where the CPU has it, else falls back.
    #[inline]
    pub fn decode_bmi2(self) -> Key {
        #[cfg(target_arch = "x86_64")]
        if let Some(bmi2) = crate::arch::bmi2::Bmi2::detect() {
            return bmi2.morton_decode(self);
        }
        self.decode()
    }

    /// Child index (0..8) taken below a node at `depth` (0 = root).
    #[inline]
    pub fn child_index(self, depth: u8) -> usize {
        ((self.0 >> (3 * (15 - u32::from(depth)))) & 7) as usize
    }
}

/// Sorts 48-bit Morton codes: a least-significant-digit radix sort on
/// 12-bit digits (all four histograms counted in one pass), skipping
/// digits that are equal in every code, as the high ones of codes from one
/// region usually are.
pub fn sort_codes(codes: &mut Vec<u64>) {
    const BITS: u32 = 12;
    const BUCKETS: usize = 1 << BITS;
    if codes.len() < 256 {
        codes.sort_unstable();
        return;
    }
    debug_assert!(codes.iter().all(|&c| c < 1 << 48));
    let mut count = vec![[0u32; BUCKETS]; 4];
    for &c in codes.iter() {
        for (d, hist) in count.iter_mut().enumerate() {
            hist[((c >> (BITS * d as u32)) as usize) & (BUCKETS - 1)] += 1;
        }
    }
    let n = codes.len() as u32;
    let mut buf = vec![0u64; codes.len()];
    for (d, hist) in count.iter_mut().enumerate() {
        if hist.contains(&n) {
            continue; // every code has the same digit here
        }
        let mut sum = 0;
        for slot in hist.iter_mut() {
            let k = *slot;
            *slot = sum;
            sum += k;
        }
        let shift = BITS * d as u32;
        for &c in codes.iter() {
            let b = ((c >> shift) as usize) & (BUCKETS - 1);
            buf[hist[b] as usize] = c;
            hist[b] += 1;
        }
        std::mem::swap(codes, &mut buf);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoders_agree_and_round_trip() {
        let mut s = 0x1234_5678_9abc_def0u64;
        for _ in 0..10_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let key = Key([s as u16, (s >> 16) as u16, (s >> 32) as u16]);
            let m = MortonCode::encode(key);
            assert_eq!(MortonCode::encode_table(key), m);
            assert_eq!(MortonCode::low_levels(key.packed()), m.0 & 0xff_ffff);
            assert_eq!(MortonCode::encode_bmi2(key), m);
            assert_eq!(m.decode(), key);
            assert_eq!(m.decode_bmi2(), key);
            for depth in 0..16 {
                assert_eq!(m.child_index(depth), key.child_index(depth));
            }
        }
    }

    #[test]
    fn radix_sort_sorts_scenes_around_the_centre() {
        // keys around the map centre (every bit differs across it), in a
        // few extents, plus lists of one repeated code and of two values
        let mut s = 99u64;
        let mut rand = move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            s >> 33
        };
        for (extent, n) in [(40u64, 300), (200, 5000), (3000, 100_000), (30, 70_000), (1 << 15, 20_000)] {
            let mut v: Vec<u64> = (0..n)
                .map(|_| {
                    let k = |r: u64| (0x8000 - extent + r % (2 * extent)) as u16;
                    MortonCode::encode(Key::new(k(rand()), k(rand()), k(rand()))).0
                })
                .collect();
            let mut expected = v.clone();
            expected.sort_unstable();
            sort_codes(&mut v);
            assert_eq!(v, expected, "extent {extent}, {n} codes");
        }
        let mut same = vec![12345u64; 1000];
        sort_codes(&mut same);
        assert!(same.iter().all(|&c| c == 12345));
        let mut two: Vec<u64> = (0..1000).map(|i| if i % 3 == 0 { 1 << 47 } else { 5 }).collect();
        let mut expected = two.clone();
        expected.sort_unstable();
        sort_codes(&mut two);
        assert_eq!(two, expected);
    }

    #[test]
    fn radix_sort_sorts() {
        let mut s = 7u64;
        let mut v: Vec<u64> = (0..5000)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (s >> 16) & 0xffff_ffff_ffff
            })
            .collect();
        let mut expected = v.clone();
        expected.sort_unstable();
        sort_codes(&mut v);
        assert_eq!(v, expected);
    }

    #[test]
    fn order_is_depth_first_children_0_to_7() {
        // the last voxel below root child 0 precedes the first below child 1
        let a = MortonCode::encode(Key::new(0x7fff, 0x7fff, 0x7fff));
        let b = MortonCode::encode(Key::new(0x8000, 0, 0));
        assert!(a < b);
    }
}
