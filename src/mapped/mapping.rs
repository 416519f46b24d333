//! The memory mappings behind [`MappedMap::open`](super::MappedMap::open)
//! and the `.graph` reader's [`GraphInput`](crate::formats::graph::GraphInput).
//! Their callers register each mapping with the crate's registry
//! ([`super::MappingWatch`]), so that [`super::guard_truncated_files`] can
//! tell a read past the end of a truncated file from any other fault.

use std::fs::File;
use std::io;

/// Maps `file` read-only. Assumption (stated by `MappedMap::open`): the
/// file is not truncated or modified in place while mapped, or, when
/// truncated, [`super::guard_truncated_files`] replaces the pages past its
/// end by zeros.
pub(super) fn map_read_only(file: &File) -> io::Result<memmap2::Mmap> {
    // SAFETY: memmap2 requires that the mapped file is not modified or
    // truncated for the lifetime of the map; see the assumption above.
    // The map is read-only and only ever read through `&[u8]`, by
    // bounds-checked copies, so bytes that change (or turn to zeros)
    // under the reader give wrong answers, not undefined behaviour.
    unsafe { memmap2::Mmap::map(file) }
}

/// Maps `len` bytes of `file` from `offset` (a multiple of the page size)
/// read-only, under the same assumption as [`map_read_only`] (stated by
/// `GraphInput`).
pub(crate) fn map_range(file: &File, offset: u64, len: usize) -> io::Result<memmap2::Mmap> {
    // SAFETY: as in `map_read_only`: the file is assumed not to change
    // while mapped, and the map is only read through `&[u8]`.
    unsafe { memmap2::MmapOptions::new().offset(offset).len(len).map(file) }
}
