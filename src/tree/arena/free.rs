//! Free lists: the slot runs a pool has given back, by run length, reused
//! before the pool grows.

use super::NodeId;

/// The free slot runs of one pool, by length (index 1..=8), as ids.
#[derive(Clone, Debug, Default)]
pub(crate) struct FreeRuns {
    runs: [Vec<NodeId>; 9],
    slots: usize,
}

impl FreeRuns {
    /// Slots on the list.
    #[inline]
    pub(super) fn slots(&self) -> usize {
        self.slots
    }

    #[inline]
    pub(super) fn pop(&mut self, len: usize) -> Option<NodeId> {
        let start = self.runs[len].pop()?;
        self.slots -= len;
        Some(start)
    }

    #[inline]
    pub(super) fn push(&mut self, start: NodeId, len: usize) {
        if len > 0 {
            self.runs[len].push(start);
            self.slots += len;
        }
    }

    pub(super) fn bytes(&self) -> usize {
        self.runs.iter().map(|r| r.capacity() * std::mem::size_of::<NodeId>()).sum()
    }

    /// Deals the runs of each length out to `parts` lists.
    pub(super) fn deal(mut self, parts: usize) -> Vec<FreeRuns> {
        let mut out = vec![FreeRuns::default(); parts];
        for len in 1..9 {
            let runs = std::mem::take(&mut self.runs[len]);
            let share = runs.len().div_ceil(parts).max(1);
            for (part, runs) in out.iter_mut().zip(runs.chunks(share)) {
                part.runs[len].extend_from_slice(runs);
                part.slots += len * runs.len();
            }
        }
        out
    }

    pub(super) fn append(&mut self, other: FreeRuns) {
        for (mine, theirs) in self.runs.iter_mut().zip(other.runs) {
            mine.extend(theirs);
        }
        self.slots += other.slots;
    }

    /// Frees `len` consecutive slots from `start` as runs of at most 8.
    pub(super) fn push_span(&mut self, mut start: NodeId, mut len: usize) {
        while len > 0 {
            let run = len.min(8);
            self.push(start, run);
            start += run as NodeId;
            len -= run;
        }
    }
}
