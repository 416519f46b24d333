//! A batch update shared by several threads.
//!
//! A batch's codes are sorted, so the subtrees at a fixed depth
//! ([`SPLIT_DEPTH`]) take disjoint runs of them. The update goes in three
//! steps with the result of the serial walk:
//! 1. *plan*: one thread walks the levels above that depth, creating
//!    missing nodes, and lists the subtrees with their codes (tasks);
//! 2. the tasks, in contiguous parts of about equal code counts, are
//!    applied by the pool's threads at once, each in its own subtrees of
//!    the one arena ([`NodeArena::with_shared`]), allocating from free
//!    lists of their own and from chunks of spare slots made beforehand
//!    (enough for the worst case, [`allocation_bound`]);
//! 3. *finish*: one thread walks the upper levels again, taking each
//!    subtree's "changed" answer from step 2, and updates and prunes the
//!    nodes there as the serial walk does after their children.
//!
//! Leaf values cannot depend on which thread updates them (each voxel is
//! updated once), and a node's pruning only depends on its children's
//! final state, so the tree is the one the serial walk gives; only where
//! nodes sit in the arena differs.

use super::arena::{room_for, ArenaFree, SharedArena};
use super::{Batch, NodeArena, NodeId, ROOT};
use crate::key::TREE_DEPTH;

/// Batches with fewer codes are applied by one thread: splitting costs a
/// second walk of the upper levels and room made for the workers.
pub(crate) const MIN_CODES: usize = 1 << 15;

/// Depth of the subtrees handed out: deep enough that a scan's updates
/// spread over many (a depth-9 node spans 128 voxels a side, 6.4 m at
/// 0.05 m), shallow enough that the upper levels are a small walk.
const SPLIT_DEPTH: u8 = 9;

/// Parts per thread: more than one, so that a thread whose parts went
/// slowly is helped by the others.
const PARTS_PER_WORKER: usize = 2;

/// The subtrees at the split depth, and what their workers answered.
pub(super) struct Split {
    pub(super) depth: u8,
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
    start: usize,
    end: usize,
    created: bool,
}

impl Split {
    /// Reached subtree `n` with `codes`: while planning, lists it and says
    /// nothing changed (so the walk leaves the nodes above alone); when
    /// finishing, gives its worker's answer.
    pub(super) fn visit(&mut self, n: NodeId, codes: &[u64], created: bool) -> bool {
        match &self.changed {
            None => {
                let start = (codes.as_ptr() as usize - self.base) / std::mem::size_of::<u64>();
                self.tasks.push(Task { node: n, start, end: start + codes.len(), created });
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
    let t0 = std::time::Instant::now();
    let mut split =
        Split { depth: SPLIT_DEPTH, base: codes.as_ptr() as usize, tasks: Vec::new(), changed: None, next: 0 };
    walk_upper_levels(batch, &mut split, codes, created);
    let tasks = &std::mem::take(&mut split.tasks)[..];
    let parts = partition(tasks, workers * PARTS_PER_WORKER);
    let (inner, leaf) = allocation_bound(tasks, codes);

    let (rules, sensor, delta, lazy) = (batch.rules, batch.sensor, batch.delta, batch.lazy);
    let run = |shared: &SharedArena<'_>, tasks: &[Task], free: ArenaFree| {
        let t = std::time::Instant::now();
        let mut worker = shared.worker(free);
        let mut b = Batch { arena: &mut worker, rules, sensor, delta, lazy, size: 0, changes: None, split: None };
        let changed: Vec<bool> =
            tasks.iter().map(|t| b.apply(t.node, SPLIT_DEPTH, &codes[t.start..t.end], t.created)).collect();
        let size = b.size;
        if std::env::var("PDEBUG").is_ok() {
            eprintln!("  part {:?} on {:?}", t.elapsed(), rayon::current_thread_index());
        }
        (changed, size, worker.finish())
    };
    let t1 = std::time::Instant::now();
    let room = (room_for(inner, parts.len()), room_for(leaf, parts.len()));
    let results = batch.arena.with_shared(room.0, room.1, parts.len(), |shared, lists| {
        let mut results: Vec<(Vec<bool>, isize, ArenaFree)> =
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
    let t2 = std::time::Instant::now();
    let mut changed = Vec::with_capacity(tasks.len());
    for (flags, size, _) in results {
        changed.extend(flags);
        batch.size += size;
    }

    split.changed = Some(changed);
    walk_upper_levels(batch, &mut split, codes, created);
    let t3 = std::time::Instant::now();
    if std::env::var("PDEBUG").is_ok() {
        eprintln!(
            "codes {} tasks {} bound {}/{} slots {} | plan {:?} par {:?} finish {:?}",
            codes.len(),
            tasks.len(),
            inner,
            leaf,
            batch.arena.slot_count(),
            t1 - t0,
            t2 - t1,
            t3 - t2
        );
    }
}

/// The walk above the split depth, planning or finishing per `split`.
fn walk_upper_levels(batch: &mut Batch<'_, NodeArena>, split: &mut Split, codes: &[u64], created: bool) {
    let mut top = Batch {
        arena: &mut *batch.arena,
        rules: batch.rules,
        sensor: batch.sensor,
        delta: batch.delta,
        lazy: batch.lazy,
        size: 0,
        changes: None,
        split: Some(split),
    };
    top.apply(ROOT, 0, codes, created);
    batch.size += top.size;
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

/// Upper bounds of the inner-pool and leaf-pool slots the tasks can
/// allocate: a visited node allocates at most one run of at most 8 slots
/// (new children, or an expansion), in the leaf pool at depth 15, and the
/// nodes a task visits are the distinct prefixes of its codes at depths
/// [`SPLIT_DEPTH`]..=15.
fn allocation_bound(tasks: &[Task], codes: &[u64]) -> (usize, usize) {
    let below = usize::from(TREE_DEPTH - 1 - SPLIT_DEPTH);
    let (mut inner, mut leaf) = (0, 0);
    for t in tasks {
        let codes = &codes[t.start..t.end];
        // the first code's whole path from the split depth
        inner += below;
        leaf += 1;
        for pair in codes.windows(2) {
            // the first depth whose child index differs: the two codes
            // share the nodes down to it and none below
            let top_bit = 63 - (pair[0] ^ pair[1]).leading_zeros() as usize;
            let first_new = usize::from(TREE_DEPTH) - top_bit / 3;
            inner += usize::from(TREE_DEPTH - 1).saturating_sub(first_new.max(usize::from(SPLIT_DEPTH)));
            leaf += usize::from(first_new <= usize::from(TREE_DEPTH - 1));
        }
    }
    (8 * inner, 8 * leaf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;
    use crate::morton::MortonCode;
    use crate::sensor::SensorModel;
    use crate::simulate::SplitMix64;
    use crate::tree::{Clock, InnerNodes, NodeKind, OccupancyTree};

    /// `n` random voxels (sorted codes, no repeats) in a cube of `side`
    /// voxels a side at the map's centre, where the first levels split.
    fn random_codes(rng: &mut SplitMix64, n: usize, side: u32) -> Vec<u64> {
        let c = |rng: &mut SplitMix64| (32768 - side / 2 + rng.below(side)) as u16;
        let mut codes: Vec<u64> = (0..n).map(|_| MortonCode::encode(Key::new(c(rng), c(rng), c(rng))).0).collect();
        codes.sort_unstable();
        codes.dedup();
        codes
    }

    fn ot(t: &OccupancyTree) -> Vec<u8> {
        let mut out = Vec::new();
        crate::formats::ot::write(t, &mut out).unwrap();
        out
    }

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

    fn task(start: usize, end: usize) -> Task {
        Task { node: 0, start, end, created: false }
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
        let codes = [0b000, 0b001];
        assert_eq!(allocation_bound(&[task(0, 2)], &codes), (8 * 6, 8));
        // differing at depth 14: a second depth-15 parent
        let codes = [0b000, 0b001_000];
        assert_eq!(allocation_bound(&[task(0, 2)], &codes), (8 * 6, 16));
        // differing at depth 10: new nodes at depths 11..=15
        let codes = [0, 1 << (3 * 5)];
        assert_eq!(allocation_bound(&[task(0, 2)], &codes), (8 * (6 + 4), 16));
    }
}
