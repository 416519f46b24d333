//! Processor-specific code: every use of `std::arch` intrinsics, behind
//! safe functions, so that no other module needs `unsafe` for them.
//!
//! One module per instruction family, each for a measured gain on a hot
//! path (`docs/benchmarks.md`):
//!
//! * [`sse2`] (every x86-64 processor, so no detection): the ray walk's
//!   choice of axis by compare masks instead of mispredicted branches
//!   ([`sse2::StepClock`]), and cache prefetch hints ([`prefetch`]) for
//!   walks over scattered child groups.
//! * [`sse41`] (when the build enables SSE4.1): a point's key with two
//!   axes per instruction, on the critical path of a point query.
//! * [`bmi2`] (detected at run time): Morton codes by `pdep` and `pext`.
//! * [`avx512`] (AVX-512F and BMI2, detected at run time): a scan's rays
//!   set up eight at a time and walked sixteen at a time.
//!
//! Instructions detected at run time come with a token type
//! ([`bmi2::Bmi2`], [`avx512::Avx512`]) that only the detection makes, so
//! that holding one proves what the `unsafe` calls behind its methods
//! require. Every path has a portable twin outside this module (the
//! callers' fallbacks), and tests compare the two bit for bit.

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx512;
#[cfg(target_arch = "x86_64")]
pub(crate) mod bmi2;
#[cfg(target_arch = "x86_64")]
pub(crate) mod sse2;
#[cfg(all(target_arch = "x86_64", target_feature = "sse4.1"))]
pub(crate) mod sse41;

/// Asks for the cache line holding `x` (a hint: nothing on other
/// processors).
#[cfg(target_arch = "x86_64")]
pub(crate) use sse2::prefetch;

/// Asks for the cache line holding `x` (a hint: nothing on other
/// processors).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
pub(crate) fn prefetch<T>(_: &T) {}
