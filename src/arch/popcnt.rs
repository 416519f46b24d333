//! POPCNT, detected at run time (x86-64-v2 and later: every x86-64
//! processor since about 2009). Descents count child-mask bits at every
//! level, on their chain of dependent steps, and walks count each node's
//! children; a build for baseline x86-64 emulates the count in about ten
//! dependent instructions.

#[cfg(not(target_feature = "popcnt"))]
use std::arch::asm;

/// `x.count_ones()`, by the POPCNT instruction where the processor has it
/// even when the build does not enable it. The test of the cached
/// detection is a load and a predicted branch beside the chain of
/// dependent steps (a loop keeps the flag's address in a register, or
/// has the test moved out of it). A
/// search compiled with POPCNT and called per query was slower than the
/// emulation: the call loses what the caller's loop hoists out of the
/// inlined search. In builds with POPCNT this is `count_ones`.
#[inline(always)]
pub(crate) fn count_ones(x: impl Into<u64>) -> u32 {
    let x: u64 = x.into();
    #[cfg(not(target_feature = "popcnt"))]
    if std::arch::is_x86_feature_detected!("popcnt") {
        let n: u64;
        // SAFETY: the processor has POPCNT (checked just above); the
        // instruction reads one register and writes another and the flags.
        unsafe { asm!("popcnt {n}, {x}", x = in(reg) x, n = lateout(reg) n, options(pure, nomem, nostack)) };
        return n as u32;
    }
    x.count_ones()
}

#[cfg(test)]
mod tests {
    /// The instruction counts as `count_ones` does: every byte value, and
    /// words with bits at both ends.
    #[test]
    fn counts_equal_count_ones() {
        for m in 0..=255u8 {
            assert_eq!(super::count_ones(m), m.count_ones());
        }
        let mut s = 0x0123_4567_89ab_cdefu64;
        for _ in 0..10_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            for x in [s, s & (s >> 3), s | 1 << 63, !s] {
                assert_eq!(super::count_ones(x), x.count_ones(), "{x:#x}");
            }
        }
    }
}
