//! The arena shared by the threads of a parallel update: spare slots made
//! up front and claimed in chunks, the arrays seen as atomics, and each
//! worker's share ([`ArenaWorker`]) with its own free lists.

use super::atomic_view::{atomic_f32s, atomic_u32s, atomic_u8s};
use super::free::FreeRuns;
use super::store::NodeStore;
use super::{in_leaf_pool, leaf_index, NodeArena, NodeId, LEAF_POOL, NO_CHILD};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU8, AtomicUsize, Ordering::Relaxed};

/// Spare slots a worker of a parallel update claims at a time.
const CHUNK: usize = 256;

/// Spare slots to make in a pool so that the workers of a parallel update,
/// which allocate at most `allocations` slots between them (runs of at
/// most 8), never run out: a worker claims a new chunk only when fewer than
/// 8 slots are left in its last, so all its chunks but the last are filled
/// to `CHUNK - 7` slots at least.
fn room_for(allocations: usize, workers: usize) -> usize {
    (allocations * CHUNK).div_ceil(CHUNK - 7) + workers * CHUNK
}

impl NodeArena {
    /// Runs `f` with the arena shared by `workers` threads ([`SharedArena`])
    /// and the free lists dealt out to them (`f` hands them back). The
    /// workers allocate from spare slots, made here for a budget: a worker
    /// takes a task only once it has reserved the task's worst case from
    /// the budget ([`ArenaWorker::reserve`]). The worst cases of all tasks
    /// (`bound`, inner and leaf pool) are four times what an outdoor scan
    /// allocates and a hundred times what a scan of mapped space does, so
    /// the budget is twice what the last parallel update allocated (a
    /// quarter of `bound` at first) plus the largest task's worst case
    /// (`largest`), and never more than `bound`; tasks the budget cannot
    /// cover are left to the caller. The slots claimed join the pools, the rest stay spare.
    /// Spare slots are initialised when made (no slot is ever
    /// uninitialised), so they are made once and kept for later runs.
    pub(crate) fn with_shared<R>(
        &mut self,
        bound: (usize, usize),
        largest: (usize, usize),
        workers: usize,
        f: impl FnOnce(&SharedArena<'_>, Vec<ArenaFree>) -> (R, Vec<ArenaFree>),
    ) -> R {
        // with no history, a quarter of the worst case (a scan of new
        // space allocates that much)
        let (i, l) = self.last_shared_use.unwrap_or((bound.0 / 4, bound.1 / 4));
        let budget = ((2 * i + largest.0).min(bound.0), (2 * l + largest.1).min(bound.1));
        let (inner, leaf) = (room_for(budget.0, workers), room_for(budget.1, workers));
        let free = std::mem::take(&mut self.free).deal(workers);
        let leaf_free = std::mem::take(&mut self.leaf_free).deal(workers);
        let lists = free.into_iter().zip(leaf_free).map(|(free, leaf_free)| ArenaFree { free, leaf_free }).collect();
        let (n, nl) = (self.inner_len(), self.leaf_len());
        assert!(n + inner < LEAF_POOL as usize, "node arena exceeds 2^31 inner slots");
        assert!(nl + leaf < LEAF_POOL as usize, "node arena exceeds 2^31 leaf slots");
        self.make_spare(inner, false);
        self.make_spare(leaf, true);
        let (result, lists, ends) = {
            let shared = SharedArena {
                inner: SharedPool {
                    arrays: Arrays::of(&mut self.values, &mut self.masks, &mut self.first_child, &mut self.extras),
                    next: AtomicUsize::new(n),
                    budget: AtomicUsize::new(budget.0),
                },
                leaf: SharedPool {
                    arrays: Arrays::of(&mut self.leaf_values, &mut [], &mut [], &mut self.leaf_extras),
                    next: AtomicUsize::new(nl),
                    budget: AtomicUsize::new(budget.1),
                },
                default_extra: self.default_extra,
            };
            let (result, lists) = f(&shared, lists);
            let used = |p: &SharedPool, budget: usize| budget - p.budget.load(Relaxed);
            self.last_shared_use = Some((used(&shared.inner, budget.0), used(&shared.leaf, budget.1)));
            (result, lists, (shared.inner.claimed(), shared.leaf.claimed()))
        };
        // what was not claimed stays as spare slots for later runs
        self.spare = self.values.len() - ends.0;
        self.leaf_spare = self.leaf_values.len() - ends.1;
        for list in lists {
            self.free.append(list.free);
            self.leaf_free.append(list.leaf_free);
        }
        result
    }

    /// Makes at least `k` spare slots in a pool, growing its arrays by an
    /// eighth at least, as the serial path does. Spare slots are written
    /// once, when made, and reused until taken.
    fn make_spare(&mut self, k: usize, leaf: bool) {
        let spare = if leaf { self.leaf_spare } else { self.spare };
        if spare >= k {
            return;
        }
        let extra = self.default_extra;
        let (values, extras) =
            if leaf { (&mut self.leaf_values, &mut self.leaf_extras) } else { (&mut self.values, &mut self.extras) };
        let (len, add) = (values.len(), k - spare);
        let more = if len + add > values.capacity() { add.max(len / 8) } else { 0 };
        grow(values, more, add, 0.0);
        if let Some(e) = extra {
            grow(extras, more, add, e);
        }
        if leaf {
            self.leaf_spare = k;
        } else {
            grow(&mut self.masks, more, add, 0);
            grow(&mut self.first_child, more, add, NO_CHILD);
            self.spare = k;
        }
    }
}

/// Appends `add` copies of `fill` to `v`, reserving `more` first. Written
/// on the pool's threads: the page faults of new memory are most of the
/// cost of making spare slots.
fn grow<T: Copy + Send + Sync>(v: &mut Vec<T>, more: usize, add: usize, fill: T) {
    v.reserve_exact(more);
    v.par_extend(rayon::iter::repeat_n(fill, add));
}

/// A worker's free lists, for both pools.
#[derive(Default)]
pub(crate) struct ArenaFree {
    free: FreeRuns,
    leaf_free: FreeRuns,
}

/// A pool's arrays as atomics (masks and first children empty in the leaf
/// pool, extras empty when off).
struct Arrays<'a> {
    values: &'a [AtomicU32],
    masks: &'a [AtomicU8],
    first_child: &'a [AtomicU32],
    extras: &'a [AtomicU32],
}

impl<'a> Arrays<'a> {
    fn of(values: &'a mut [f32], masks: &'a mut [u8], first_child: &'a mut [u32], extras: &'a mut [u32]) -> Self {
        Arrays {
            values: atomic_f32s(values),
            masks: atomic_u8s(masks),
            first_child: atomic_u32s(first_child),
            extras: atomic_u32s(extras),
        }
    }
}

/// The arena, shared by the workers of a parallel batch update
/// ([`NodeArena::with_shared`]). Each worker changes only the nodes of its
/// own subtrees, so no slot is used by two; the arrays are relaxed atomics
/// all the same (plain loads and stores on x86-64), so that a slot used
/// twice would be a wrong answer, never a data race.
pub(crate) struct SharedArena<'a> {
    inner: SharedPool<'a>,
    leaf: SharedPool<'a>,
    default_extra: Option<u32>,
}

/// One pool: its slots, then spare slots that workers claim by chunks.
struct SharedPool<'a> {
    arrays: Arrays<'a>,
    /// The first unclaimed slot.
    next: AtomicUsize,
    /// Slots not reserved by a task ([`ArenaWorker::reserve`]).
    budget: AtomicUsize,
}

impl SharedPool<'_> {
    /// Where the claimed slots end.
    fn claimed(&self) -> usize {
        self.next.load(Relaxed).min(self.arrays.values.len())
    }

    /// Takes `k` slots from the budget, if it has them.
    fn reserve(&self, k: usize) -> bool {
        self.budget.fetch_update(Relaxed, Relaxed, |b| b.checked_sub(k)).is_ok()
    }

    /// Claims a chunk of spare slots; returns its first slot. The budget
    /// keeps the claims within the spare slots: a worker claims a chunk
    /// only for the slots of a task's reservation, and only when fewer
    /// than 8 are left in its last (see [`room_for`]).
    fn claim(&self) -> usize {
        let start = self.next.fetch_add(CHUNK, Relaxed);
        assert!(start + CHUNK <= self.arrays.values.len(), "a parallel update outgrew the spare slots made for it");
        start
    }
}

impl SharedArena<'_> {
    /// A worker that allocates from `free` first, then from chunks of
    /// spare slots.
    pub(crate) fn worker(&self, free: ArenaFree) -> ArenaWorker<'_, '_> {
        ArenaWorker { shared: self, lists: free, chunk: (0, 0), leaf_chunk: (0, 0), reserved: (0, 0), taken: (0, 0) }
    }

    /// The arrays holding node `n`, and its index there.
    #[inline(always)]
    fn pool(&self, n: NodeId) -> (&Arrays<'_>, usize) {
        if in_leaf_pool(n) {
            (&self.leaf.arrays, leaf_index(n))
        } else {
            (&self.inner.arrays, n as usize)
        }
    }
}

/// One worker's view of a [`SharedArena`]: its own free lists, and the
/// chunk of spare slots it allocates new runs from.
pub(crate) struct ArenaWorker<'s, 'a> {
    shared: &'s SharedArena<'a>,
    lists: ArenaFree,
    /// The unallocated rest of the worker's chunk of each pool, as
    /// (first, end) slot indices.
    chunk: (usize, usize),
    leaf_chunk: (usize, usize),
    /// The current task's reservation, and the slots it took from chunks.
    reserved: (usize, usize),
    taken: (usize, usize),
}

impl ArenaWorker<'_, '_> {
    /// Reserves a task's worst case (inner-pool and leaf-pool slots) from
    /// the budget of spare slots; `false` when the budget cannot cover it,
    /// and the task must not be applied through this worker.
    pub(crate) fn reserve(&mut self, k: (usize, usize)) -> bool {
        let (inner, leaf) = (&self.shared.inner, &self.shared.leaf);
        if !inner.reserve(k.0) {
            return false;
        }
        if !leaf.reserve(k.1) {
            inner.budget.fetch_add(k.0, Relaxed);
            return false;
        }
        self.reserved = k;
        self.taken = (0, 0);
        true
    }

    /// Ends the task reserved for: gives back what it did not take.
    pub(crate) fn release(&mut self) {
        let (r, t) = (self.reserved, self.taken);
        assert!(t.0 <= r.0 && t.1 <= r.1, "a task took more slots than its reservation");
        self.shared.inner.budget.fetch_add(r.0 - t.0, Relaxed);
        self.shared.leaf.budget.fetch_add(r.1 - t.1, Relaxed);
        self.reserved = (0, 0);
    }

    /// Ends the worker; the rest of its chunks joins its free lists.
    pub(crate) fn finish(mut self) -> ArenaFree {
        let (a, b) = self.chunk;
        self.lists.free.push_span(a as NodeId, b - a);
        let (a, b) = self.leaf_chunk;
        self.lists.leaf_free.push_span(LEAF_POOL | a as NodeId, b - a);
        self.lists
    }

    /// `len` slots from the worker's chunk of a pool, claiming a new chunk
    /// when fewer are left (the rest becomes a free run).
    #[inline]
    fn take(&mut self, len: usize, leaf: bool) -> NodeId {
        let (chunk, pool, free, tag) = if leaf {
            (&mut self.leaf_chunk, &self.shared.leaf, &mut self.lists.leaf_free, LEAF_POOL)
        } else {
            (&mut self.chunk, &self.shared.inner, &mut self.lists.free, 0)
        };
        if chunk.1 - chunk.0 < len {
            free.push(tag | chunk.0 as NodeId, chunk.1 - chunk.0);
            let start = pool.claim();
            *chunk = (start, start + CHUNK);
        }
        let id = chunk.0;
        chunk.0 += len;
        if leaf {
            self.taken.1 += len;
        } else {
            self.taken.0 += len;
        }
        tag | id as NodeId
    }
}

impl NodeStore for ArenaWorker<'_, '_> {
    #[inline(always)]
    fn value(&self, n: NodeId) -> f32 {
        let (a, i) = self.shared.pool(n);
        f32::from_bits(a.values[i].load(Relaxed))
    }
    #[inline(always)]
    fn set_value(&mut self, n: NodeId, v: f32) {
        let (a, i) = self.shared.pool(n);
        a.values[i].store(v.to_bits(), Relaxed);
    }
    #[inline(always)]
    fn extra(&self, n: NodeId) -> u32 {
        let (a, i) = self.shared.pool(n);
        a.extras.get(i).map_or(0, |e| e.load(Relaxed))
    }
    #[inline(always)]
    fn set_extra(&mut self, n: NodeId, v: u32) {
        let (a, i) = self.shared.pool(n);
        if let Some(e) = a.extras.get(i) {
            e.store(v, Relaxed);
        }
    }
    #[inline(always)]
    fn mask(&self, n: NodeId) -> u8 {
        if in_leaf_pool(n) {
            return 0;
        }
        self.shared.inner.arrays.masks[n as usize].load(Relaxed)
    }
    #[inline(always)]
    fn first_child(&self, n: NodeId) -> NodeId {
        if in_leaf_pool(n) {
            return NO_CHILD;
        }
        self.shared.inner.arrays.first_child[n as usize].load(Relaxed)
    }
    #[inline(always)]
    fn set_children(&mut self, n: NodeId, mask: u8, first: NodeId) {
        let a = &self.shared.inner.arrays;
        a.masks[n as usize].store(mask, Relaxed);
        a.first_child[n as usize].store(first, Relaxed);
    }
    #[inline(always)]
    fn default_extra(&self) -> Option<u32> {
        self.shared.default_extra
    }
    #[inline]
    fn alloc_run(&mut self, len: usize, leaf: bool) -> NodeId {
        let list = if leaf { &mut self.lists.leaf_free } else { &mut self.lists.free };
        match list.pop(len) {
            Some(start) => start,
            None => self.take(len, leaf),
        }
    }
    #[inline]
    fn free_run(&mut self, start: NodeId, len: usize) {
        if in_leaf_pool(start) {
            self.lists.leaf_free.push(start, len);
        } else {
            self.lists.free.push(start, len);
        }
    }
    #[inline(always)]
    fn copy_slot(&mut self, from: NodeId, to: NodeId) {
        let v = self.value(from);
        self.set_value(to, v);
        if self.shared.default_extra.is_some() {
            let e = self.extra(from);
            self.set_extra(to, e);
        }
        if !in_leaf_pool(from) {
            let (m, f) = (self.mask(from), self.first_child(from));
            self.set_children(to, m, f);
        }
    }
    #[inline(always)]
    fn init_slot(&mut self, id: NodeId, value: f32, extra: Option<u32>) {
        self.set_value(id, value);
        if let Some(e) = extra {
            self.set_extra(id, e);
        }
        if !in_leaf_pool(id) {
            self.set_children(id, 0, NO_CHILD);
        }
    }
}
