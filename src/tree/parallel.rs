//! A batch update shared by several threads.
//!
//! A batch's codes are sorted, so disjoint subtrees take disjoint runs of
//! them. The update goes in three
//! steps with the result of the serial walk:
//! 1. *plan*: one thread walks the upper levels, creating missing nodes,
//!    and lists subtrees with their codes (tasks, [`Split::is_task`]); the
//!    pool's threads then count each task's worst case of new slots
//!    ([`allocation_bound`], a pass over every code) and make the spare
//!    slots (new memory, whose page faults are most of their cost);
//! 2. the tasks, in contiguous parts of about equal code counts, are
//!    applied by the pool's threads at once, each in its own subtrees of
//!    the one arena ([`NodeArena::with_shared`]), allocating from free
//!    lists of their own and from chunks of those spare slots;
//! 3. *finish*: one thread walks the upper levels again, taking each
//!    subtree's "changed" answer from step 2, and updates and prunes the
//!    nodes there as the serial walk does after their children.
//!
//! Leaf values cannot depend on which thread updates them (each voxel is
//! updated once), and a node's pruning only depends on its children's
//! final state, so the tree is the one the serial walk gives; only where
//! nodes sit in the arena differs.

use super::arena::{ArenaFree, SharedArena};
use super::{Batch, NodeArena, NodeId, ROOT};
use crate::key::TREE_DEPTH;
use rayon::prelude::*;

/// Batches with fewer codes are applied by one thread. Splitting costs a
/// second walk of the upper levels and, above all, memory: the spare slots
/// are made for the worst case, up to 8 per node a batch visits, where a
/// scan over mapped space allocates almost nothing. At 32,768 codes an
/// indoor build's peak memory on 2 threads rose by a quarter
/// (`docs/benchmarks.md`, "Tried and rejected") for no gain in time;
/// scans of new space (outdoor) gain, and their batches are far larger.
/// Unit tests share smaller batches, dense enough to prune whole blocks.
#[cfg(not(test))]
pub(crate) const MIN_CODES: usize = 1 << 18;
#[cfg(test)]
pub(crate) const MIN_CODES: usize = 1 << 15;

/// Depths of the subtrees handed out (tasks): a node at depth
/// [`MIN_SPLIT_DEPTH`] or below whose codes are few enough
/// ([`Split::max_codes`]) is a task, and so is every node at
/// [`MAX_SPLIT_DEPTH`]. Small tasks balance the threads and keep the
/// worst case of any one task small, which sizes the spare slots made for
/// them (see [`NodeArena::with_shared`]); the upper levels stay a small
/// walk (a depth-12 node spans 16 voxels a side).
const MIN_SPLIT_DEPTH: u8 = 6;
const MAX_SPLIT_DEPTH: u8 = 12;

/// Parts per thread: more than one, so that a thread whose parts went
/// slowly is helped by the others.
const PARTS_PER_WORKER: usize = 2;

/// The subtrees handed out, and what their workers answered.
pub(super) struct Split {
    /// Codes a task may have above [`MAX_SPLIT_DEPTH`].
    max_codes: usize,
    /// Address of the batch's first code, to turn sub-slices into ranges.
    base: usize,
    tasks: Vec<Task>,
    /// The tasks' "changed" answers, once applied; `None` while planning.
    changed: Option<Vec<bool>>,
    next: usize,
}

/// A subtree at the split depth and its codes.
#[derive(Clone, Copy)]
struct Task {
    node: NodeId,
    depth: u8,
    start: usize,
    end: usize,
    created: bool,
    /// The most inner-pool and leaf-pool slots the task can allocate (set
    /// once planning is done, [`allocation_bound`]).
    bound: (usize, usize),
}

impl Split {
    /// Is the node at `depth` with `codes` below it a task?
    #[inline]
    pub(super) fn is_task(&self, depth: u8, codes: usize) -> bool {
        depth == MAX_SPLIT_DEPTH || (depth >= MIN_SPLIT_DEPTH && codes <= self.max_codes)
    }

    /// Reached task `n` at `depth` with `codes`: while planning, lists it
    /// and says nothing changed (so the walk leaves the nodes above alone);
    /// when finishing, gives its worker's answer.
    pub(super) fn visit(&mut self, n: NodeId, depth: u8, codes: &[u64], created: bool) -> bool {
        match &self.changed {
            None => {
                let start = (codes.as_ptr() as usize - self.base) / std::mem::size_of::<u64>();
                self.tasks.push(Task { node: n, depth, start, end: start + codes.len(), created, bound: (0, 0) });
                false
            }
            Some(changed) => {
                self.next += 1;
                changed[self.next - 1]
            }
        }
    }
}

/// Applies `codes` below the root with `batch`'s settings, on `workers`
/// threads of the current rayon pool; adds the node count's change to
/// `batch.size`.
pub(super) fn apply(
    batch: &mut Batch<'_, NodeArena>,
    codes: &[u64],
    created: bool,
    workers: usize,
    announce: &(dyn Fn() + Sync),
) {
    // about eight tasks per part at least
    let max_codes = (codes.len() / (8 * workers * PARTS_PER_WORKER)).max(1024);
    let mut split = Split { max_codes, base: codes.as_ptr() as usize, tasks: Vec::new(), changed: None, next: 0 };
    walk_upper_levels(batch, &mut split, codes, created);
    let mut tasks = std::mem::take(&mut split.tasks);
    // a pass over every code, bound by memory: on the pool's threads
    tasks.par_iter_mut().for_each(|t| t.bound = allocation_bound(&codes[t.start..t.end], t.depth));
    let tasks = &tasks[..];
    let parts = partition(tasks, workers * PARTS_PER_WORKER);
    let total = tasks.iter().fold((0, 0), |(i, l), t| (i + t.bound.0, l + t.bound.1));
    let largest = tasks.iter().fold((0, 0), |(i, l), t| (i.max(t.bound.0), l.max(t.bound.1)));

    let (rules, sensor, delta, lazy, ranges) = (batch.rules, batch.sensor, batch.delta, batch.lazy, batch.ranges);
    // per task: changed, or `None` when the spare slots could not be
    // promised to it (applied afterwards, by this thread)
    let run = |shared: &SharedArena<'_>, tasks: &[Task], free: ArenaFree| {
        let mut worker = shared.worker(free);
        let mut changed = Vec::with_capacity(tasks.len());
        let mut size = 0;
        for t in tasks {
            if !worker.reserve(t.bound) {
                changed.push(None);
                continue;
            }
            let mut b = Batch {
                arena: &mut worker,
                rules,
                sensor,
                delta,
                lazy,
                size: 0,
                changes: None,
                split: None,
                ranges: ranges.restart(),
            };
            changed.push(Some(b.apply(t.node, t.depth, &codes[t.start..t.end], t.created)));
            size += b.size;
            worker.release();
        }
        (changed, size, worker.finish())
    };
    let results = batch.arena.with_shared(total, largest, parts.len(), |shared, lists| {
        let mut results: Vec<(Vec<Option<bool>>, isize, ArenaFree)> =
            lists.into_iter().map(|list| (Vec::new(), 0, list)).collect();
        rayon::scope(|scope| {
            let mut pairs = parts.iter().zip(results.iter_mut());
            let first = pairs.next();
            for (part, out) in pairs {
                let run = &run;
                scope.spawn(move |_| *out = run(shared, &tasks[part.clone()], std::mem::take(&mut out.2)));
            }
            announce();
            if let Some((part, out)) = first {
                *out = run(shared, &tasks[part.clone()], std::mem::take(&mut out.2));
            }
        });
        let lists = results.iter_mut().map(|r| std::mem::take(&mut r.2)).collect();
        (results, lists)
    });
    let mut changed = Vec::with_capacity(tasks.len());
    for (flags, size, _) in results {
        changed.extend(flags);
        batch.size += size;
    }
    let changed =
        changed.into_iter().zip(tasks).map(|(c, t)| c.unwrap_or_else(|| apply_task(batch, t, codes))).collect();

    split.changed = Some(changed);
    walk_upper_levels(batch, &mut split, codes, created);
}

#[cfg(test)]
thread_local! {
    /// Tasks [`apply_task`] applied on this thread (tests check that it
    /// happens).
    static LEFT_OVER: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Applies one task on this thread, to the arena itself.
fn apply_task(batch: &mut Batch<'_, NodeArena>, t: &Task, codes: &[u64]) -> bool {
    #[cfg(test)]
    LEFT_OVER.set(LEFT_OVER.get() + 1);
    let mut b = on_arena(batch, None);
    let changed = b.apply(t.node, t.depth, &codes[t.start..t.end], t.created);
    batch.size += b.size;
    changed
}

/// The walk above the tasks, planning or finishing per `split`.
fn walk_upper_levels(batch: &mut Batch<'_, NodeArena>, split: &mut Split, codes: &[u64], created: bool) {
    let mut top = on_arena(batch, Some(split));
    top.apply(ROOT, 0, codes, created);
    batch.size += top.size;
}

/// A walk with `batch`'s settings on its arena, counting nodes from 0.
fn on_arena<'b>(batch: &'b mut Batch<'_, NodeArena>, split: Option<&'b mut Split>) -> Batch<'b, NodeArena> {
    Batch {
        arena: &mut *batch.arena,
        rules: batch.rules,
        sensor: batch.sensor,
        delta: batch.delta,
        lazy: batch.lazy,
        size: 0,
        changes: None,
        split,
        ranges: batch.ranges.restart(),
    }
}

/// Contiguous runs of `tasks`, at most `parts`, with about equal code
/// counts.
fn partition(tasks: &[Task], parts: usize) -> Vec<std::ops::Range<usize>> {
    let total: usize = tasks.iter().map(|t| t.end - t.start).sum();
    let mut out = Vec::with_capacity(parts);
    let (mut start, mut sum) = (0, 0);
    for (i, t) in tasks.iter().enumerate() {
        sum += t.end - t.start;
        // close part k once the running count reaches k/parts of the total
        if sum * parts >= total * (out.len() + 1) {
            out.push(start..i + 1);
            start = i + 1;
        }
    }
    if start < tasks.len() {
        out.push(start..tasks.len());
    }
    out
}

/// Upper bounds of the inner-pool and leaf-pool slots a task with `codes`
/// can allocate: a visited node allocates at most one run of at most 8
/// slots (new children, or an expansion), in the leaf pool at depth 15,
/// and the nodes a task at `depth` visits are the distinct prefixes of its
/// codes at depths `depth..=15`.
fn allocation_bound(codes: &[u64], depth: u8) -> (usize, usize) {
    // per pair of codes, the level of their highest differing bit (bit
    // 3 * level + 0..3): they share the nodes down to depth 15 - level and
    // part there, so the second code's path adds level - 1 inner nodes
    // below the parting one and, when level > 0, a depth-15 node (its
    // slots in the leaf pool); within a task the pair parts below `depth`
    let (mut levels, mut parted) = (0usize, 0usize);
    for pair in codes.windows(2) {
        // codes are strictly increasing, so the xor is never 0 (the `| 1`
        // only spares `ilog2` the test)
        let level = ((pair[0] ^ pair[1]) | 1).ilog2() as usize / 3;
        levels += level;
        parted += usize::from(level != 0);
    }
    // the first code's whole path from the task's node
    let inner = usize::from(TREE_DEPTH - 1 - depth) + levels - parted;
    (8 * inner, 8 * (1 + parted))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;
    use crate::morton::MortonCode;
    use crate::sensor::SensorModel;
    use crate::tree::{Clock, InnerNodes, NodeKind, OccupancyTree};

    /// SplitMix64 (the simulator's generator): a fixed stream, so that the
    /// random batches are the same on every run.
    struct SplitMix64(u64);

    impl SplitMix64 {
        /// Uniform integer in `0..n`.
        fn below(&mut self, n: u32) -> u32 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((((z ^ (z >> 31)) >> 32) * u64::from(n)) >> 32) as u32
        }
    }

    /// `n` random voxels (sorted codes, no repeats) in a cube of `side`
    /// voxels a side at the map's centre, where the first levels split.
    fn random_codes(rng: &mut SplitMix64, n: usize, side: u32) -> Vec<u64> {
        random_codes_from(rng, n, 32768 - side / 2, side)
    }

    /// `n` random voxels in the cube of `side` voxels from key `low` on
    /// every axis.
    fn random_codes_from(rng: &mut SplitMix64, n: usize, low: u32, side: u32) -> Vec<u64> {
        let c = |rng: &mut SplitMix64| (low + rng.below(side)) as u16;
        let mut codes: Vec<u64> = (0..n).map(|_| MortonCode::encode(Key::new(c(rng), c(rng), c(rng))).0).collect();
        codes.sort_unstable();
        codes.dedup();
        codes
    }

    use crate::formats::ot::to_bytes as ot;

    /// Batches shared by 2, 3 and 8 workers give the serial walk's tree:
    /// new space, revisits that saturate and prune whole blocks (dense
    /// cubes), pruned leaves that must be expanded, and lazy updates; for
    /// plain and stamped trees.
    #[test]
    fn shared_batches_give_the_serial_tree() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        for kind in [NodeKind::Plain, NodeKind::Stamped] {
            let mut rng = SplitMix64(7);
            // cubes of 40 and 80 voxels: dense enough for whole groups of
            // eight to saturate alike and be pruned
            let batches: Vec<(Vec<u64>, bool, InnerNodes)> = (0..14)
                .map(|i| {
                    let side = if i % 3 == 0 { 80 } else { 40 };
                    let inner = if i == 9 { InnerNodes::Defer } else { InnerNodes::Update };
                    (random_codes(&mut rng, 60_000, side), i % 4 != 3, inner)
                })
                .collect();
            let mut serial = OccupancyTree::with_kind(0.1, SensorModel::default(), kind).unwrap();
            serial.set_clock(Clock::Fixed(1234));
            let mut shared: Vec<OccupancyTree> = vec![serial.clone(); 3];
            for (codes, hit, inner) in &batches {
                assert!(codes.len() >= MIN_CODES);
                let delta = if *hit { serial.sensor().hit } else { serial.sensor().miss };
                serial.update_batch(codes, delta, *inner);
                for (t, workers) in shared.iter_mut().zip([2, 3, 8]) {
                    pool.install(|| t.update_batch_split(codes, delta, *inner, workers, &|| {}));
                }
                let want = ot(&serial);
                for t in &shared {
                    assert_eq!(t.size(), serial.size(), "{kind:?}");
                    assert!(ot(t) == want, "{kind:?}");
                }
            }
            // the batches pruned: some leaves lie above the voxels
            assert!(serial.leaves(16).any(|l| l.depth < 16), "{kind:?}: nothing was pruned");
        }
    }

    /// A shared batch over mapped space allocates little, so the next one
    /// gets a small budget of spare slots; when that one maps new space,
    /// the tasks the budget cannot cover are applied afterwards, and the
    /// tree is still the serial walk's.
    #[test]
    fn tasks_beyond_the_budget_are_applied_after() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let mut rng = SplitMix64(11);
        let known = random_codes(&mut rng, 60_000, 48);
        // new space: far from the first cube, spread over many tasks
        let new = random_codes_from(&mut rng, 60_000, 20_000, 400);
        let mut serial = OccupancyTree::new(0.1).unwrap();
        let hit = serial.sensor().hit;
        let mut shared = serial.clone();
        for codes in [&known, &known, &known, &new] {
            serial.update_batch(codes, hit, InnerNodes::Update);
            // counted on the thread that applies the left-over tasks
            let left = pool.install(|| {
                let before = LEFT_OVER.get();
                shared.update_batch_shared(codes, hit, InnerNodes::Update, 2);
                LEFT_OVER.get() - before
            });
            assert!(ot(&shared) == ot(&serial));
            if std::ptr::eq(codes, &new) {
                assert!(left > 0, "every task was covered");
            }
        }
    }

    fn task(start: usize, end: usize) -> Task {
        Task { node: 0, depth: 9, start, end, created: false, bound: (0, 0) }
    }

    #[test]
    fn parts_are_contiguous_and_cover_every_task() {
        let tasks: Vec<Task> = [5, 1, 1, 9, 2, 2, 2, 7, 1]
            .iter()
            .scan(0, |at, &n| {
                *at += n;
                Some(task(*at - n, *at))
            })
            .collect();
        for parts in 1..12 {
            let p = partition(&tasks, parts);
            assert!(p.len() <= parts && !p.is_empty());
            assert_eq!(p[0].start, 0);
            assert_eq!(p.last().unwrap().end, tasks.len());
            assert!(p.windows(2).all(|w| w[0].end == w[1].start && w[0].start < w[0].end));
        }
        assert_eq!(partition(&tasks, 2), vec![0..4, 4..9]);
    }

    #[test]
    fn the_bound_counts_distinct_prefixes_below_the_split() {
        // two voxels with the same depth-15 parent: one path of inner nodes
        // (depths 9..=14) and one leaf group
        assert_eq!(allocation_bound(&[0b000, 0b001], 9), (8 * 6, 8));
        // differing at depth 14: a second depth-15 parent
        assert_eq!(allocation_bound(&[0b000, 0b001_000], 9), (8 * 6, 16));
        // differing at depth 10: new nodes at depths 11..=15
        assert_eq!(allocation_bound(&[0, 1 << (3 * 5)], 9), (8 * (6 + 4), 16));
        // a task at depth 12: inner nodes at depths 12..=14 only; the
        // second code adds the depth-14 and depth-15 nodes
        assert_eq!(allocation_bound(&[0, 1 << (3 * 2)], 12), (8 * (3 + 1), 16));
    }

    /// The bound is 8 slots per distinct prefix, counted directly: the
    /// codes' prefixes at depths `depth..=14` in the inner pool, at depth
    /// 15 in the leaf pool, for random codes below one node of each depth.
    #[test]
    fn the_bound_is_eight_slots_per_distinct_prefix() {
        let mut rng = SplitMix64(11);
        for depth in [9u8, 11, 13, 15] {
            // a node at `depth` spans 2^(16 - depth) voxels a side
            let side = 1u32 << (16 - depth);
            for n in [1, 2, 40, 3000] {
                let codes = random_codes_from(&mut rng, n, 32768 - side, side);
                let prefixes = |d: u8| {
                    let shift = 3 * u32::from(TREE_DEPTH - d);
                    codes.iter().map(|c| c >> shift).collect::<std::collections::HashSet<_>>().len()
                };
                let inner: usize = (depth..TREE_DEPTH - 1).map(prefixes).sum();
                let leaf = prefixes(TREE_DEPTH - 1);
                assert_eq!(allocation_bound(&codes, depth), (8 * inner, 8 * leaf), "depth {depth}, {n} codes");
            }
        }
    }
}
