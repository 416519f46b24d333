//! Bytes a tree writer's pre-order walk gathers in memory and hands to
//! the writer in pieces: no per-record write call, and no whole file in
//! memory.

use std::io::{self, Write};
use std::ops::ControlFlow;

/// Bytes gathered before they go to the writer.
pub(crate) const FLUSH_AT: usize = 1 << 16;

/// The bytes not yet written, and the writer.
pub(crate) struct Pieces<W> {
    /// Appended to by the walk; written and cleared by [`Self::flush_if_full`].
    pub(crate) bytes: Vec<u8>,
    w: W,
}

impl<W: Write> Pieces<W> {
    /// Ready to gather up to a piece, with room for `hint` bytes at first.
    pub(crate) fn new(w: W, hint: usize) -> Self {
        Pieces { bytes: Vec::with_capacity(hint.min(FLUSH_AT + 64)), w }
    }

    /// Writes the bytes gathered once there are [`FLUSH_AT`] of them (to be
    /// called where no record is open).
    #[inline(always)]
    pub(crate) fn flush_if_full(&mut self) -> ControlFlow<io::Error> {
        if self.bytes.len() >= FLUSH_AT {
            if let Err(e) = self.w.write_all(&self.bytes) {
                return ControlFlow::Break(e);
            }
            self.bytes.clear();
        }
        ControlFlow::Continue(())
    }

    /// Writes what is left.
    pub(crate) fn finish(mut self) -> io::Result<()> {
        self.w.write_all(&self.bytes)
    }
}
