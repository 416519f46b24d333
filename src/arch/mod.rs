//! Processor-specific code: every use of `std::arch` intrinsics and
//! instructions, behind safe functions, so that no other module needs
//! `unsafe` for them.
//!
//! The library is built for baseline x86-64, as a crate depending on it
//! builds it, and picks faster instructions at run time where they pay
//! (`docs/benchmarks.md`, "Build flags and downstream speed"). One module
//! per instruction family, each for a measured gain on a hot path:
//!
//! * [`sse2`] (every x86-64 processor, so no detection): the ray walk's
//!   choice of axis by compare masks instead of mispredicted branches
//!   ([`sse2::StepClock`]); a point's key with two axes per instruction
//!   and `floor` by truncation ([`key_and_octant`], on the critical path of
//!   a point query); cache prefetch hints ([`prefetch`]) for walks over
//!   scattered child groups.
//! * [`sse41`] (when the build enables SSE4.1): the point's key with
//!   `roundpd` as its `floor`.
//! * [`popcnt`] (detected at run time): the child-mask counts of every
//!   descent and walk ([`count_ones`]).
//! * [`bmi2`] (detected at run time): Morton codes by `pdep` and `pext`.
//! * [`avx512`] (AVX-512F with BMI2 and POPCNT, detected at run time): a
//!   scan's rays set up eight at a time and walked sixteen at a time.
//!
//! Instruction sets detected at run time for a whole computation come with
//! a token type ([`bmi2::Bmi2`], [`avx512::Avx512`]) that only the
//! detection makes, so that holding one proves what the `unsafe` calls
//! behind its methods require. Every path has a portable twin (the
//! callers' fallbacks, or `count_ones` and `KeySpace::coord_to_key`), and
//! tests compare the two bit for bit.

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx512;
#[cfg(target_arch = "x86_64")]
pub(crate) mod bmi2;
#[cfg(target_arch = "x86_64")]
pub(crate) mod popcnt;
#[cfg(target_arch = "x86_64")]
pub(crate) mod sse2;
// compiled in every build, so that its test runs wherever the processor
// has SSE4.1
#[cfg(target_arch = "x86_64")]
#[cfg_attr(not(target_feature = "sse4.1"), allow(dead_code))]
pub(crate) mod sse41;

#[cfg(target_arch = "x86_64")]
use crate::{geometry::Point3, key::Key};

#[cfg(target_arch = "x86_64")]
pub(crate) use popcnt::count_ones;
#[cfg(target_arch = "x86_64")]
pub(crate) use sse2::prefetch;

/// The set bits of `x` (other processors: the build's own instruction).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
pub(crate) fn count_ones(x: impl Into<u64>) -> u32 {
    x.into().count_ones()
}

/// Asks for the cache line holding `x` (other processors: nothing).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
pub(crate) fn prefetch<T>(_: &T) {}

/// `KeySpace::key_and_octant` for points inside the map (`None` when an
/// axis has no key): by SSE2, or by SSE4.1 when the build enables it.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn key_and_octant(resolution_factor: f64, p: Point3) -> Option<(Key, usize)> {
    #[cfg(target_feature = "sse4.1")]
    // SAFETY: the build enables SSE4.1 for all code (the `cfg` above).
    return unsafe { sse41::key_and_octant(resolution_factor, p) };
    #[cfg(not(target_feature = "sse4.1"))]
    sse2::key_and_octant(resolution_factor, p)
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::key::KeySpace;

    /// Both vector conversions give the scalar `coord_to_key`'s key (its
    /// root child as octant), or `None` where an axis has no key: at voxel
    /// borders and map edges and one float either side, ±0, the smallest
    /// and largest floats, NaN and infinities. The SSE4.1 one where the
    /// processor has it.
    #[test]
    fn vector_point_keys_equal_scalar_keys() {
        let with_sse41 = std::arch::is_x86_feature_detected!("sse4.1");
        for res in [0.01, 0.05, 0.1, 0.2, 0.3, 1.0] {
            let ks = KeySpace::new(res);
            let edge = (ks.node_size(0) / 2.0) as f32;
            let tiny = f32::from_bits(1);
            let mut values =
                vec![0.0f32, -0.0, tiny, -tiny, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, f32::MIN];
            for base in [edge, -edge, res as f32, -(res as f32), 1.5 * res as f32, -17.0 * res as f32, 0.5] {
                values.extend([base, base.next_up(), base.next_down()]);
            }
            for &a in &values {
                for &b in &[0.0f32, a, -edge, 3.7] {
                    for p in [Point3::new(a, b, b), Point3::new(b, a, b), Point3::new(b, b, a)] {
                        let axis = |v: f32| ks.coord_to_key(f64::from(v)).ok();
                        let want =
                            (|| Some(Key([axis(p.x)?, axis(p.y)?, axis(p.z)?])))().map(|k| (k, k.child_index(0)));
                        assert_eq!(sse2::key_and_octant(ks.resolution_factor(), p), want, "{p:?} at {res}");
                        if with_sse41 {
                            // SAFETY: the processor has SSE4.1 (checked above)
                            let got = unsafe { sse41::key_and_octant(ks.resolution_factor(), p) };
                            assert_eq!(got, want, "SSE4.1, {p:?} at {res}");
                        }
                    }
                }
            }
        }
    }
}
