//! The records of a maximum-likelihood `.bt` tree while they are gathered:
//! in memory, or with a scratch file, all but the last few megabytes on
//! disk. They cannot go straight to the output: the header before them
//! counts the nodes, known only at the end, and a record changes until
//! the walk leaves its node (its children's labels; its subtree dropped
//! when it merges).

use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom, Write};

/// Bytes kept in memory before they go to the scratch file.
const IN_MEMORY: usize = 4 << 20;

/// A growing byte buffer of two-byte records: appended to, rewritten
/// and cut back anywhere.
pub(crate) struct RecordBuffer {
    /// The bytes from `head` on.
    tail: Vec<u8>,
    /// Bytes before the tail, in the scratch file.
    head: usize,
    scratch: Option<File>,
    /// Tail length at which it moves to the scratch file.
    spill_at: usize,
    /// The first error of the scratch file; later writes are skipped.
    error: Option<io::Error>,
}

impl RecordBuffer {
    /// In memory only, with room for `hint` bytes.
    pub(crate) fn in_memory(hint: usize) -> Self {
        RecordBuffer { tail: Vec::with_capacity(hint), head: 0, scratch: None, spill_at: usize::MAX, error: None }
    }

    /// Past a few megabytes in `scratch` (emptied first).
    pub(crate) fn with_scratch(scratch: File) -> Self {
        let error = scratch.set_len(0).err();
        RecordBuffer {
            tail: Vec::with_capacity(IN_MEMORY),
            head: 0,
            scratch: Some(scratch),
            spill_at: IN_MEMORY,
            error,
        }
    }

    /// An empty buffer of the same kind, reusing the scratch file.
    pub(crate) fn emptied(self) -> Self {
        match self.scratch {
            Some(file) => Self::with_scratch(file),
            None => Self::in_memory(self.tail.len()),
        }
    }

    /// Bytes in the buffer.
    #[inline(always)]
    pub(crate) fn len(&self) -> usize {
        self.head + self.tail.len()
    }

    /// Appends a record.
    #[inline(always)]
    pub(crate) fn push(&mut self, record: [u8; 2]) {
        if self.tail.len() >= self.spill_at {
            self.spill();
        }
        self.tail.extend_from_slice(&record);
    }

    /// Rewrites the record at byte `at`.
    #[inline(always)]
    pub(crate) fn set(&mut self, at: usize, record: [u8; 2]) {
        match at.checked_sub(self.head) {
            Some(i) => self.tail[i..i + 2].copy_from_slice(&record),
            None => self.on_disk(|f| {
                f.seek(SeekFrom::Start(at as u64))?;
                f.write_all(&record)
            }),
        }
    }

    /// Cuts the buffer back to `len` bytes.
    #[inline(always)]
    pub(crate) fn truncate(&mut self, len: usize) {
        match len.checked_sub(self.head) {
            Some(i) => self.tail.truncate(i),
            None => {
                self.tail.clear();
                self.head = len;
                self.on_disk(|f| f.set_len(len as u64));
            }
        }
    }

    /// Moves the tail to the end of the scratch file.
    #[cold]
    fn spill(&mut self) {
        let (head, tail) = (self.head, std::mem::take(&mut self.tail));
        self.on_disk(|f| {
            f.seek(SeekFrom::Start(head as u64))?;
            f.write_all(&tail)
        });
        self.head += tail.len();
        self.tail = tail;
        self.tail.clear();
    }

    /// Runs `op` on the scratch file unless an earlier one failed.
    fn on_disk(&mut self, op: impl FnOnce(&mut File) -> io::Result<()>) {
        if self.error.is_some() {
            return;
        }
        match self.scratch.as_mut() {
            Some(f) => self.error = op(f).err(),
            None => self.error = Some(io::Error::other("records on disk without a scratch file")),
        }
    }

    /// The bytes, from the first, once the walk is done; the first error
    /// of the scratch file if one failed.
    pub(crate) fn reader(&mut self) -> io::Result<impl Read + '_> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        let head: Box<dyn Read + '_> = match self.scratch.as_mut() {
            Some(f) => {
                f.seek(SeekFrom::Start(0))?;
                Box::new(f.take(self.head as u64))
            }
            None => Box::new(io::empty()),
        };
        Ok(head.chain(&self.tail[..]))
    }

    /// The bytes in memory, when none went to disk.
    pub(crate) fn in_memory_bytes(&self) -> Option<&[u8]> {
        (self.head == 0).then_some(&self.tail[..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same pushes, rewrites and cuts in memory and through a scratch
    /// file (spilling many times) give the same bytes.
    #[test]
    fn a_scratch_file_holds_what_memory_holds() {
        let mut disk = RecordBuffer::with_scratch(tempfile::tempfile().unwrap());
        disk.spill_at = 64;
        let mut memory = RecordBuffer::in_memory(0);
        let (mut state, mut spilled) = (12345u64, false);
        for i in 0..20_000u32 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let record = (i as u16).to_le_bytes();
            match state >> 61 {
                0 if memory.len() > 8 => {
                    // mostly a subtree's few records, now and then deep
                    let back = if state >> 58 & 7 == 0 { memory.len() } else { 200 };
                    let at = memory.len() - ((state >> 20) as usize % (back.min(memory.len()) / 2)) * 2;
                    memory.truncate(at);
                    disk.truncate(at);
                }
                1 | 2 if memory.len() > 2 => {
                    let at = (state >> 20) as usize % (memory.len() / 2) * 2;
                    memory.set(at, record);
                    disk.set(at, record);
                }
                _ => {
                    memory.push(record);
                    disk.push(record);
                }
            }
            assert_eq!(memory.len(), disk.len());
            spilled |= disk.head > 0;
        }
        assert!(spilled && disk.head > 0, "nothing went to disk");
        let (mut a, mut b) = (Vec::new(), Vec::new());
        memory.reader().unwrap().read_to_end(&mut a).unwrap();
        disk.reader().unwrap().read_to_end(&mut b).unwrap();
        assert!(a == b);
        assert_eq!(memory.in_memory_bytes(), Some(&a[..]));
        assert_eq!(disk.in_memory_bytes(), None);
    }
}
