//! Cache prefetch hints for tree walks over scattered child groups.

/// Arenas (and mapped files) up to this size are prefetched whole before
/// an iteration: a quarter of the smallest L2 of current x86 and Arm cores
/// (1 MB here), so the lines stay there for the walk.
pub(crate) const WHOLE_PREFETCH_BYTES: usize = 256 << 10;

/// [`prefetch`] for every 64-byte line of `s`.
pub(crate) fn prefetch_lines<T>(s: &[T]) {
    let step = (64 / std::mem::size_of::<T>().max(1)).max(1);
    for i in (0..s.len()).step_by(step) {
        prefetch(s, i);
    }
    if let Some(last) = s.len().checked_sub(1) {
        prefetch(s, last);
    }
}

/// Asks for the cache line holding `s[i]` (nothing when `i` is out of
/// range): tree walks over an arena whose groups lie scattered after many
/// updates ask for the groups they will visit next all at once.
#[inline(always)]
pub(crate) fn prefetch<T>(s: &[T], i: usize) {
    if let Some(x) = s.get(i) {
        crate::arch::prefetch(x);
    }
}
