//! The memory mapping behind [`MappedMap::open`](super::MappedMap::open):
//! the module's only `unsafe`.

use std::fs::File;
use std::io;

/// Maps `file` read-only. Assumption (stated by `MappedMap::open`): the
/// file is not truncated or modified in place while mapped.
pub(super) fn map_read_only(file: &File) -> io::Result<memmap2::Mmap> {
    // SAFETY: memmap2 requires that the mapped file is not modified or
    // truncated for the lifetime of the map; see the assumption above.
    // The map is read-only and only ever read through `&[u8]`.
    unsafe { memmap2::Mmap::map(file) }
}
