//! The arena's arrays seen as atomics, for the threads of a parallel
//! update ([`super::shared`]): the arena's only `unsafe`.

use std::sync::atomic::{AtomicU32, AtomicU8};

// the atomics stand in for the arrays' elements: same size and alignment
const _: () = assert!(std::mem::size_of::<AtomicU32>() == 4 && std::mem::align_of::<AtomicU32>() == 4);
const _: () = assert!(std::mem::align_of::<f32>() == 4 && std::mem::align_of::<u32>() == 4);
const _: () = assert!(std::mem::size_of::<AtomicU8>() == 1 && std::mem::align_of::<AtomicU8>() == 1);

/// `s` as atomics, for as long as it stays borrowed.
pub(super) fn atomic_u32s(s: &mut [u32]) -> &[AtomicU32] {
    // SAFETY: AtomicU32 has the size, alignment (checked above) and bit
    // validity of u32; the exclusive borrow means nothing else reads or
    // writes the slice while the atomics are in use.
    unsafe { &*(s as *mut [u32] as *const [AtomicU32]) }
}

/// `s` as atomics holding the floats' bits.
pub(super) fn atomic_f32s(s: &mut [f32]) -> &[AtomicU32] {
    // SAFETY: as in `atomic_u32s`, f32 having the size and alignment of
    // u32, and every bit pattern being valid for both.
    unsafe { &*(s as *mut [f32] as *const [AtomicU32]) }
}

/// `s` as atomics.
pub(super) fn atomic_u8s(s: &mut [u8]) -> &[AtomicU8] {
    // SAFETY: as in `atomic_u32s`, for u8 and AtomicU8.
    unsafe { &*(s as *mut [u8] as *const [AtomicU8]) }
}
