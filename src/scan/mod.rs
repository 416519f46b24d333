//! Scan integration: OctoMap's `insertPointCloud` with per-scan key sets,
//! parallel ray casting and updates applied in Morton order.
//!
//! Per scan, the free voxels of all rays and the occupied end-point voxels
//! are collected as sets; a voxel that is an end point is never also freed;
//! then each voxel is updated once, free voxels first. Because every voxel
//! is touched once per scan, the result does not depend on the order of
//! application, so we apply in Morton order (consecutive updates share
//! their path from the root) and parallelise the ray casting freely: the
//! tree is bit-identical for any thread count.
//!
//! The sets are not hash sets, although OctoMap's are: rays walk Morton
//! codes ([`RayFan`]) and set one bit per voxel in bitmaps of aligned
//! 8x8x8 blocks (`block_set`), which absorb the repeats as they happen
//! (rays of one scan share the voxels near the sensor, about ten visits a
//! voxel indoors) and give the codes in Morton order, which the batched
//! application needs, by sorting the blocks alone. Sorting or hashing the
//! raw lists costs more (`docs/benchmarks.md`, "Tried and rejected");
//! `cargo bench --bench insert -- dedup` compares the three.
//! Hash sets remain where bitmaps do not pay: merging end points for
//! `discretize`.
//!
//! [`OccupancyTree::insert_point_clouds`] integrates a sequence of scans and,
//! with several threads, casts the following scans (each whole on one
//! thread) while one is applied.

use crate::geometry::Point3;
use crate::key::{Key, KeyError, KeySpace};
use crate::morton::MortonCode;
use crate::ray::{point_along, FanRay, RayFan, RayKeys};
use crate::tree::{InnerNodes, OccupancyTree};
use block_set::BlockSet;
use hashbrown::HashSet;
use pipeline::{Job, Pipeline, StdMonitor};
use rayon::prelude::*;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::Mutex;

mod block_set;
mod pipeline;

/// A hasher for keys: the Morton code mixed by one multiplication.
#[derive(Default, Clone, Copy)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    #[inline(always)]
    fn finish(&self) -> u64 {
        self.0
    }

    #[inline(always)]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }

    #[inline(always)]
    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 29)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        self.0 ^= self.0 >> 32;
    }
}

/// A set of keys (OctoMap's `KeySet`) as Morton codes, on hashbrown with
/// [`KeyHasher`].
pub type KeySet = HashSet<MortonCode, BuildHasherDefault<KeyHasher>>;

/// What one worker collects: the free and the occupied voxels.
#[derive(Default)]
struct Casting {
    free: BlockSet,
    occupied: BlockSet,
}

impl Casting {
    /// `computeUpdate`'s work for one end point. `fan` holds the rays'
    /// common origin; `None` when it lies outside the map (no rays then).
    #[inline]
    fn cast(&mut self, keys: &KeySpace, fan: Option<&RayFan>, p: Point3, origin: Point3, opts: &ScanOptions) {
        let (within, end) = cut_to_range(p, origin, opts);
        let Some(bbx) = opts.bbx else {
            let Some(end_code) = self.end_voxel(keys, end, within) else { return };
            if let Some(fan) = fan {
                fan.for_each_code(end, end_code, |c| self.free.insert(c));
            }
            return;
        };
        if within && bbx.contains_point(p) {
            if let Ok(k) = keys.key(p) {
                self.occupied.insert(MortonCode::encode(k).0);
            }
        }
        if let Ok(ray) = RayKeys::new(keys, origin, end) {
            for k in ray.take_while(|&k| bbx.contains_key(k)) {
                self.free.insert(MortonCode::encode(k).0);
            }
        }
    }

    /// [`Self::cast`] for every point. The steps of one ray form a chain
    /// of dependent operations, so several rays are walked at once and
    /// their chains overlap: eight or sixteen in vector lanes where the
    /// processor has AVX-512 (`ray::wide`), else two.
    fn cast_all(
        &mut self,
        keys: &KeySpace,
        fan: Option<&RayFan>,
        points: &[Point3],
        origin: Point3,
        opts: &ScanOptions,
    ) {
        let Some(fan) = fan.filter(|_| opts.bbx.is_none()) else {
            for &p in points {
                self.cast(keys, fan, p, origin, opts);
            }
            return;
        };
        #[cfg(target_arch = "x86_64")]
        if crate::ray::wide::available() {
            // SAFETY: the processor has AVX-512F and BMI2
            unsafe { self.cast_all_wide(keys, fan, points, opts) };
            return;
        }
        self.cast_all_pairs(keys, fan, points, origin, opts);
    }

    /// [`Self::cast_all`]'s walk on processors without AVX-512: rays walked
    /// two at a time, so that their two chains overlap.
    fn cast_all_pairs(&mut self, keys: &KeySpace, fan: &RayFan, points: &[Point3], origin: Point3, opts: &ScanOptions) {
        let mut points = points.iter();
        let mut ready = RayQueue::default();
        // the two walks' changing state apart from their constants, so that
        // it stays in registers
        let (mut a, mut a_steps) = self.next_ray(fan, keys, &mut points, &mut ready, origin, opts).split();
        let (mut b, mut b_steps) = self.next_ray(fan, keys, &mut points, &mut ready, origin, opts).split();
        loop {
            let (ca, cb) = (a.next_code(&a_steps), b.next_code(&b_steps));
            match ca {
                Some(c) => self.free.insert(c),
                None => (a, a_steps) = self.next_ray(fan, keys, &mut points, &mut ready, origin, opts).split(),
            }
            match cb {
                Some(c) => self.free.insert(c),
                None => {
                    (b, b_steps) = self.next_ray(fan, keys, &mut points, &mut ready, origin, opts).split();
                    if ca.is_none() && points.len() == 0 && ready.is_empty() {
                        break;
                    }
                }
            }
        }
        // the last rays
        while let Some(c) = a.next_code(&a_steps) {
            self.free.insert(c);
        }
        while let Some(c) = b.next_code(&b_steps) {
            self.free.insert(c);
        }
    }

    /// [`Self::cast_all`] in the lanes of AVX-512 registers (`ray::wide`):
    /// the rays are set up a chunk at a time, eight at once, each chunk
    /// walked sixteen rays at once while the lanes still hold the previous
    /// chunk's last rays. BMI2 gives the set insertion its one-instruction
    /// variable shift (`shlx`); every AVX-512 processor has it.
    ///
    /// # Safety
    /// The processor must support AVX-512F and BMI2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,bmi2")]
    unsafe fn cast_all_wide(&mut self, keys: &KeySpace, fan: &RayFan, points: &[Point3], opts: &ScanOptions) {
        use crate::ray::wide::{set_up, walk, LaneRays, Lanes};
        let mut rays = LaneRays::default();
        let mut lanes = Lanes::default();
        let mut any = false;
        let mut chunks = points.chunks(LaneRays::CAPACITY).peekable();
        while let Some(chunk) = chunks.next() {
            rays.clear();
            set_up(&mut rays, fan, keys, chunk, opts.max_range.unwrap_or(-1.0), |c| self.occupied.insert(c));
            any |= rays.len() > 0;
            rays.pad();
            let last = chunks.peek().is_none();
            let free = &mut self.free;
            walk(&mut lanes, &rays, fan.origin_code(), last, |codes| free.insert_all(codes));
        }
        if any {
            self.free.insert(fan.origin_code());
        }
    }

    /// The next ray to walk, from `ready`, which is refilled from `points`
    /// when empty; a finished ray when both have run out.
    #[inline(always)]
    fn next_ray(
        &mut self,
        fan: &RayFan,
        keys: &KeySpace,
        points: &mut std::slice::Iter<Point3>,
        ready: &mut RayQueue,
        origin: Point3,
        opts: &ScanOptions,
    ) -> FanRay {
        if ready.is_empty() {
            self.set_up_rays(fan, keys, points, ready, origin, opts);
        }
        ready.pop().unwrap_or_else(FanRay::finished)
    }

    /// [`Self::cast`]'s work except the walk (the end point, the origin
    /// voxel, the ray's set-up) for the next [`RayQueue::CAPACITY`] points,
    /// their non-empty rays into `ready`. In a batch, the set-ups' chains
    /// of square root and divisions overlap; one at a time, as each walk
    /// ended, they were a fifth of the insertion of a small map.
    #[inline(never)]
    fn set_up_rays(
        &mut self,
        fan: &RayFan,
        keys: &KeySpace,
        points: &mut std::slice::Iter<Point3>,
        ready: &mut RayQueue,
        origin: Point3,
        opts: &ScanOptions,
    ) {
        for &p in points.take(RayQueue::CAPACITY) {
            let (within, end) = cut_to_range(p, origin, opts);
            let Some(end_code) = self.end_voxel(keys, end, within) else { continue };
            if let Some(ray) = fan.ray(end, end_code) {
                ready.push(ray);
            }
        }
        if !ready.is_empty() {
            self.free.insert(fan.origin_code());
        }
    }

    /// The Morton code of the ray end's voxel, marked occupied when the
    /// end is the point itself (`within` range); `None` outside the map.
    #[inline(always)]
    fn end_voxel(&mut self, keys: &KeySpace, end: Point3, within: bool) -> Option<u64> {
        let end_code = MortonCode::encode(keys.key(end).ok()?).0;
        if within {
            self.occupied.insert(end_code);
        }
        Some(end_code)
    }

    /// Both sets as sorted lists; the free one keeps the occupied voxels
    /// (another worker's may have them too).
    fn finish(&self) -> (Vec<u64>, Vec<u64>) {
        (self.free.sorted_codes(None), self.occupied.sorted_codes(None))
    }

    /// The scan's update, when this worker cast all of it.
    fn into_update(self) -> ScanUpdate {
        ScanUpdate { free: self.free.sorted_codes(Some(&self.occupied)), occupied: self.occupied.sorted_codes(None) }
    }
}

/// [`crate::ray::cut_to_range`] with the scan's maximum range.
#[inline(always)]
fn cut_to_range(p: Point3, origin: Point3, opts: &ScanOptions) -> (bool, Point3) {
    crate::ray::cut_to_range(p, origin, opts.max_range.unwrap_or(-1.0))
}

/// Rays set up and waiting for a walk (a stack: the order of the walks
/// does not matter, each voxel only joins a set).
#[derive(Default)]
struct RayQueue {
    rays: [Option<FanRay>; RayQueue::CAPACITY],
    len: usize,
}

impl RayQueue {
    const CAPACITY: usize = 16;

    fn is_empty(&self) -> bool {
        self.len == 0
    }

    #[inline(always)]
    fn push(&mut self, ray: FanRay) {
        self.rays[self.len] = Some(ray);
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<FanRay> {
        self.len = self.len.checked_sub(1)?;
        self.rays[self.len].take()
    }
}

/// Drops repeats from the sorted `codes`, and every code of the sorted
/// `except`, in one pass: each code is written, and the end of the kept
/// part only moves past it when it is kept, so repeats, which come at
/// random, cost no mispredicted branch.
fn dedup_except(codes: &mut Vec<u64>, except: &[u64]) {
    let (mut kept, mut j) = (0, 0);
    let mut prev = u64::MAX; // no code: codes have 48 bits
    for i in 0..codes.len() {
        let c = codes[i];
        while j < except.len() && except[j] < c {
            j += 1;
        }
        let drop = (c == prev) | (j < except.len() && except[j] == c);
        codes[kept] = c;
        kept += usize::from(!drop);
        prev = c;
    }
    codes.truncate(kept);
}

/// The union of sorted, repeat-free lists, sorted and repeat-free.
fn merge_sorted(mut lists: Vec<Vec<u64>>) -> Vec<u64> {
    lists.retain(|l| !l.is_empty());
    while lists.len() > 1 {
        // merge pairwise, shortest lists first
        lists.sort_unstable_by_key(|l| std::cmp::Reverse(l.len()));
        let (a, b) = (lists.pop().expect("two lists"), lists.pop().expect("two lists"));
        let mut out = Vec::with_capacity(a.len() + b.len());
        let (mut i, mut j) = (0, 0);
        while i < a.len() && j < b.len() {
            let (x, y) = (a[i], b[j]);
            out.push(x.min(y));
            i += usize::from(x <= y);
            j += usize::from(y <= x);
        }
        out.extend_from_slice(&a[i..]);
        out.extend_from_slice(&b[j..]);
        lists.push(out);
    }
    lists.pop().unwrap_or_default()
}

/// Thread pools by size, built once: a pool per scan would cost more than
/// casting a small scan's rays.
fn thread_pool(threads: usize) -> Result<std::sync::Arc<rayon::ThreadPool>, ScanError> {
    use std::sync::{Arc, Mutex};
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, p)) = pools.iter().find(|(n, _)| *n == threads) {
        return Ok(p.clone());
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|_| ScanError::ThreadPool("could not start ray-casting threads"))?;
    let pool = Arc::new(pool);
    pools.push((threads, pool.clone()));
    Ok(pool)
}

/// What to do with end points outside the addressable map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OutOfMap {
    /// Exactly what OctoMap does: rays whose ends have no key are skipped
    /// (their max-range-cut part still counts), and with `discretize` the
    /// end point's key wraps around to the other side of the map.
    #[default]
    OctoMap,
    /// Drop such points before anything else, and count them.
    Skip,
    /// Refuse the whole scan, naming the first such point.
    Error,
}

/// An axis-aligned box limiting which voxels a scan updates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateBox {
    /// Lower corner, metres (inclusive).
    pub min: Point3,
    /// Upper corner, metres (inclusive).
    pub max: Point3,
    min_key: Key,
    max_key: Key,
}

impl UpdateBox {
    /// Both corners must lie inside the map of `tree`.
    pub fn new(tree: &OccupancyTree, min: Point3, max: Point3) -> Result<Self, KeyError> {
        Ok(UpdateBox { min, max, min_key: tree.key(min)?, max_key: tree.key(max)? })
    }

    #[inline]
    pub(crate) fn contains_point(&self, p: Point3) -> bool {
        p.x >= self.min.x
            && p.y >= self.min.y
            && p.z >= self.min.z
            && p.x <= self.max.x
            && p.y <= self.max.y
            && p.z <= self.max.z
    }

    #[inline]
    pub(crate) fn contains_key(&self, k: Key) -> bool {
        (0..3).all(|i| k.0[i] >= self.min_key.0[i] && k.0[i] <= self.max_key.0[i])
    }
}

/// Options of [`OccupancyTree::insert_point_cloud`], OctoMap's defaults.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScanOptions {
    /// Rays longer than this are cut and their end is not marked occupied.
    pub max_range: Option<f64>,
    /// Merge end points falling into the same voxel before casting rays
    /// from the voxel centre (`discretize`).
    pub discretize: bool,
    /// Defer inner-node updates (`lazy_eval`).
    pub inner: InnerNodes,
    /// Only update voxels inside this box (OctoMap 1.10 semantics).
    pub bbx: Option<UpdateBox>,
    /// What to do with end points outside the map.
    pub out_of_map: OutOfMap,
    /// Threads for ray casting; `None` uses rayon's global pool.
    pub threads: Option<usize>,
}

/// What a scan integration did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ScanReport {
    /// Points given, before any was dropped.
    pub points: usize,
    /// Points with a NaN or infinite coordinate; always skipped.
    pub non_finite: usize,
    /// Points outside the map skipped under [`OutOfMap::Skip`].
    pub out_of_map: usize,
    /// Miss updates applied: distinct voxels for a batched scan, every
    /// update for [`OccupancyTree::insert_point_cloud_rays`].
    pub free_updates: usize,
    /// Hit updates applied, counted like `free_updates`.
    pub occupied_updates: usize,
}

/// Why a scan was refused; nothing was applied.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ScanError {
    /// The sensor origin is not finite (an origin outside the map is
    /// accepted, as in OctoMap).
    #[error("sensor origin ({x}, {y}, {z}): {source}")]
    Origin {
        /// Origin x, metres.
        x: f32,
        /// Origin y, metres.
        y: f32,
        /// Origin z, metres.
        z: f32,
        /// Why the origin has no key.
        source: KeyError,
    },
    /// An end point lies outside the map under [`OutOfMap::Error`].
    #[error("point {index} ({x}, {y}, {z}) lies outside the map: {source}")]
    PointOutOfMap {
        /// Index of the point in the input slice.
        index: usize,
        /// Point x, metres.
        x: f32,
        /// Point y, metres.
        y: f32,
        /// Point z, metres.
        z: f32,
        /// Why the point has no key.
        source: KeyError,
    },
    /// The ray-casting thread pool could not be started (the message says so).
    #[error("thread pool: {0}")]
    ThreadPool(&'static str),
}

/// The free and occupied voxels of one scan as Morton codes, each list
/// sorted and free of repeats, the two disjoint.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ScanUpdate {
    /// Morton codes of the voxels to update as free (misses).
    pub free: Vec<u64>,
    /// Morton codes of the voxels to update as occupied (hits).
    pub occupied: Vec<u64>,
}

impl ScanUpdate {
    /// The update from casting output (Morton codes in any order, repeats
    /// allowed), through the block sets a scan's casting fills.
    pub fn from_codes(free: &[u64], occupied: &[u64]) -> Self {
        let mut c = Casting::default();
        free.iter().for_each(|&f| c.free.insert(f));
        occupied.iter().for_each(|&o| c.occupied.insert(o));
        c.into_update()
    }

    /// The lists as keys, in Morton order.
    pub fn sorted(&self) -> (Vec<Key>, Vec<Key>) {
        let keys = |codes: &[u64]| codes.iter().map(|&c| MortonCode(c).decode()).collect();
        (keys(&self.free), keys(&self.occupied))
    }

    /// The lists as OctoMap's hash-based key sets.
    pub fn key_sets(&self) -> (KeySet, KeySet) {
        let set = |codes: &[u64]| codes.iter().map(|&c| MortonCode(c)).collect();
        (set(&self.free), set(&self.occupied))
    }

    /// Number of voxels to update, free and occupied together.
    pub fn len(&self) -> usize {
        self.free.len() + self.occupied.len()
    }

    /// True when the scan updates no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl OccupancyTree {
    /// Integrates one scan taken from `origin` (world frame points), with
    /// OctoMap's `insertPointCloud` semantics.
    pub fn insert_point_cloud(
        &mut self,
        points: &[Point3],
        origin: Point3,
        opts: &ScanOptions,
    ) -> Result<ScanReport, ScanError> {
        if self.kind() == crate::tree::NodeKind::Color {
            // colours depend on the order of updates (see `keyorder`)
            return self.insert_point_cloud_in_octomap_order(points, origin, opts);
        }
        let (update, report) = self.compute_update(points, origin, opts)?;
        Ok(match opts.threads {
            Some(1) => self.apply_update(&update, report, opts.inner),
            None => self.apply_update_on(&update, report, opts.inner, rayon::current_num_threads(), &|| {}),
            Some(n) => thread_pool(n)?.install(|| self.apply_update_on(&update, report, opts.inner, n, &|| {})),
        })
    }

    /// Applies a scan's update (from [`Self::compute_update`]): misses, then
    /// hits, each list in one batched walk. Completes `report` with the
    /// update counts.
    pub fn apply_update(&mut self, update: &ScanUpdate, report: ScanReport, inner: InnerNodes) -> ScanReport {
        self.apply_update_on(update, report, inner, 1, &|| {})
    }

    /// [`Self::apply_update`] with large batches shared by `workers`
    /// threads of the current rayon pool (see
    /// [`Self::update_batch_split`]).
    fn apply_update_on(
        &mut self,
        update: &ScanUpdate,
        report: ScanReport,
        inner: InnerNodes,
        workers: usize,
        announce: &(dyn Fn() + Sync),
    ) -> ScanReport {
        let sensor = *self.sensor();
        self.update_batch_split(&update.free, sensor.miss, inner, workers, announce);
        self.update_batch_split(&update.occupied, sensor.hit, inner, workers, announce);
        ScanReport { free_updates: update.free.len(), occupied_updates: update.occupied.len(), ..report }
    }

    /// Integrates scans in order, with the result of calling
    /// [`Self::insert_point_cloud`] on each (`scans` gives each scan's
    /// points and origin), calling `after_each` with the tree and the
    /// scan's report once it is in. With more than one thread the work is
    /// pipelined: while one scan's update is applied to the tree, the
    /// following scans are cast, each whole on one thread (a scan's update
    /// depends on the map's key space only, never on its content), and
    /// every thread applies the next update when it is ready and casts
    /// otherwise.
    /// Stops at the first scan that is refused, with its position in
    /// `scans`; the scans before it are in.
    pub fn insert_point_clouds<I, P>(
        &mut self,
        scans: I,
        opts: &ScanOptions,
        mut after_each: impl FnMut(&mut Self, ScanReport) + Send,
    ) -> Result<(), (usize, ScanError)>
    where
        I: IntoIterator<Item = (P, Point3)>,
        I::IntoIter: Send,
        P: AsRef<[Point3]> + Send,
    {
        let scans = scans.into_iter().enumerate();
        // colour trees apply key by key in OctoMap's order: no pipeline
        if opts.threads == Some(1) || self.kind() == crate::tree::NodeKind::Color {
            for (i, (points, origin)) in scans {
                let report = self.insert_point_cloud(points.as_ref(), origin, opts).map_err(|e| (i, e))?;
                after_each(self, report);
            }
            return Ok(());
        }
        let run = |tree: &mut Self| {
            let threads = rayon::current_num_threads();
            tree.insert_pipelined(scans, threads, opts, &mut after_each)
        };
        match opts.threads {
            None => run(self),
            // a pool of its own per call rather than the cached one: workers
            // that slept long (between calls) were seen to be woken onto
            // the CPU of the thread waking them and to share it for a whole
            // scan sequence (2 threads slower than 1 in `side_by_side`),
            // while new threads start spread; starting them costs far less
            // than a sequence of scans
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|_| (0, ScanError::ThreadPool("could not start ray-casting threads")))?
                .install(|| run(self)),
        }
    }

    /// [`Self::insert_point_clouds`] on `threads` threads, all alike: a
    /// thread applies the next scan's update to the tree when it has been
    /// cast and nobody is applying, else takes the next scan and casts it
    /// whole. Updates are applied in scan order, each by whichever thread
    /// finds it ready, so no thread waits while there is work: with one
    /// thread doing all the applying, the others wait behind its casting,
    /// and its own casting holds the tree up on large maps
    /// (`docs/benchmarks.md`, "Tried and rejected"). Each scan is cast whole
    /// by one thread, so there is no merge of per-thread lists. At most one
    /// scan more than there are threads is cast ahead of the tree: each scan
    /// cast ahead holds its sets (twice the threads raised the peak memory
    /// of a 2-thread build from 22 to 24 MB).
    fn insert_pipelined<S, P>(
        &mut self,
        scans: S,
        threads: usize,
        opts: &ScanOptions,
        after_each: &mut (impl FnMut(&mut Self, ScanReport) + Send),
    ) -> Result<(), (usize, ScanError)>
    where
        S: Iterator<Item = (usize, (P, Point3))> + Send,
        P: AsRef<[Point3]> + Send,
    {
        let keys = self.key_space().clone();
        let cast_opts = ScanOptions { threads: Some(1), ..*opts };
        let pipeline = Pipeline::<StdMonitor<_>>::new(scans, threads + 1);
        // used by one thread at a time: the one applying
        let tree = Mutex::new((self, after_each));
        // nothing to do: run the pool's pending work (the applying thread's
        // shared tree update) while there is some
        let help = || rayon::yield_now() == Some(rayon::Yield::Executed);
        let work = || {
            let _stop = pipeline.stop_on_panic();
            while let Some(job) = pipeline.next_job(help) {
                match job {
                    Job::Cast(i, (points, origin)) => {
                        pipeline.cast_done(i, compute_update(&keys, points.as_ref(), origin, &cast_opts));
                    }
                    Job::Apply((update, report), share) => {
                        let mut guard = tree.lock().unwrap_or_else(|e| e.into_inner());
                        let (tree, after_each) = &mut *guard;
                        let report =
                            tree.apply_update_on(&update, report, opts.inner, if share { threads } else { 1 }, &|| {
                                pipeline.announce()
                            });
                        drop(update);
                        after_each(tree, report);
                        drop(guard);
                        pipeline.apply_done();
                    }
                }
            }
        };
        // one loop per thread of the pool, each bound to its thread: a
        // spawned loop could be stolen late by a thread waiting inside a
        // shared tree update, which would then wait on itself
        rayon::broadcast(|_| work());
        pipeline.take_refused().map_or(Ok(()), Err)
    }

    /// Integrates a coloured scan into a colour tree: the scan as
    /// [`Self::insert_point_cloud`], then each end point's colour blended in
    /// with `integrateNodeColor`, in point order (what ROS colour mapping
    /// does with OctoMap). `colors` pairs with `points`.
    pub fn insert_colored_point_cloud(
        &mut self,
        points: &[Point3],
        colors: &[[u8; 3]],
        origin: Point3,
        opts: &ScanOptions,
    ) -> Result<ScanReport, ScanError> {
        let report = self.insert_point_cloud(points, origin, opts)?;
        for (p, rgb) in points.iter().zip(colors) {
            if let Ok(k) = self.key(*p) {
                self.integrate_color(k, *rgb);
            }
        }
        Ok(report)
    }

    /// Applies a scan's key sets key by key: misses, then hits, each key
    /// once, in the given order. The result is the same for any order;
    /// [`Self::insert_point_cloud`] uses the faster [`Self::update_batch`].
    pub fn apply_sorted(&mut self, free: &[Key], occupied: &[Key], inner: InnerNodes) {
        for &k in free {
            self.update_occupancy(k, false, inner);
        }
        for &k in occupied {
            self.update_occupancy(k, true, inner);
        }
    }

    /// The free and occupied key sets of a scan (`computeUpdate`, or
    /// `computeDiscreteUpdate` with `discretize`), cast in parallel.
    pub fn compute_update(
        &self,
        points: &[Point3],
        origin: Point3,
        opts: &ScanOptions,
    ) -> Result<(ScanUpdate, ScanReport), ScanError> {
        compute_update(self.key_space(), points, origin, opts)
    }

    /// The raw output of ray casting for a scan of finite points with
    /// default options: the free codes of every ray and the occupied codes
    /// of every end point, repeats included, unsorted.
    /// [`ScanUpdate::from_codes`] turns them into [`Self::compute_update`]'s
    /// result; benchmarks use them to compare ways of removing the repeats.
    pub fn cast_codes(&self, points: &[Point3], origin: Point3) -> (Vec<u64>, Vec<u64>) {
        let (mut free, mut occupied) = (Vec::new(), Vec::new());
        let fan = RayFan::new(self.key_space(), origin).ok();
        for &p in points {
            let Ok(key) = self.key_space().key(p) else { continue };
            let code = MortonCode::encode(key).0;
            occupied.push(code);
            if let Some(fan) = &fan {
                fan.for_each_code(p, code, |c| free.push(c));
            }
        }
        (free, occupied)
    }

    /// OctoMap's `insertPointCloudRays` ("simple" mode): ray by ray, each
    /// free voxel and end point updated as it comes, duplicates included.
    pub fn insert_point_cloud_rays(&mut self, points: &[Point3], origin: Point3, inner: InnerNodes) -> ScanReport {
        let mut report = ScanReport { points: points.len(), ..Default::default() };
        for &p in points {
            if !p.is_finite() {
                report.non_finite += 1;
                continue;
            }
            let Ok(ray) = RayKeys::new(self.key_space(), origin, p) else {
                continue;
            };
            for k in ray {
                self.update_occupancy(k, false, inner);
                report.free_updates += 1;
            }
            if self.update_point(p, true, inner).is_ok() {
                report.occupied_updates += 1;
            }
        }
        report
    }

    /// OctoMap's `insertRay`: frees the voxels up to `end` and marks `end`
    /// occupied, or only frees up to `max_range` when the ray is longer.
    pub fn insert_ray(
        &mut self,
        origin: Point3,
        end: Point3,
        max_range: Option<f64>,
        inner: InnerNodes,
    ) -> Result<(), KeyError> {
        let max_range = max_range.unwrap_or(-1.0);
        let d = end - origin;
        if max_range > 0.0 && d.norm() > max_range {
            let cut = point_along(origin, d.normalized(), max_range);
            for k in self.ray_keys(origin, cut)? {
                self.update_occupancy(k, false, inner);
            }
            return Ok(());
        }
        for k in self.ray_keys(origin, end)? {
            self.update_occupancy(k, false, inner);
        }
        self.update_point(end, true, inner)?;
        Ok(())
    }
}

/// [`OccupancyTree::compute_update`] for a map with key space `keys`: the
/// update depends on nothing else of the tree.
pub fn compute_update(
    keys: &KeySpace,
    points: &[Point3],
    origin: Point3,
    opts: &ScanOptions,
) -> Result<(ScanUpdate, ScanReport), ScanError> {
    let mut report = ScanReport { points: points.len(), ..Default::default() };
    let origin_key = keys.key(origin);
    if let Err(source) = origin_key {
        // OctoMap casts no ray then, but still marks in-map end points
        // occupied; only a non-finite origin is refused outright.
        if !origin.is_finite() {
            return Err(ScanError::Origin { x: origin.x, y: origin.y, z: origin.z, source });
        }
    }
    // only OctoMap's policy lets points without a key through to the
    // casting (which skips them); the input is used as it is when
    // nothing is to be dropped or changed
    let clean = opts.out_of_map == OutOfMap::OctoMap && !opts.discretize && points.iter().all(|p| p.is_finite());
    let mut cleaned: Vec<Point3> = Vec::new();
    if !clean {
        cleaned.reserve(points.len());
        for (index, &p) in points.iter().enumerate() {
            if !p.is_finite() {
                report.non_finite += 1;
                continue;
            }
            if opts.out_of_map != OutOfMap::OctoMap {
                if let Err(source) = keys.key(p) {
                    if opts.out_of_map == OutOfMap::Error {
                        return Err(ScanError::PointOutOfMap { index, x: p.x, y: p.y, z: p.z, source });
                    }
                    report.out_of_map += 1;
                    continue;
                }
            }
            cleaned.push(p);
        }
    }
    if opts.discretize {
        let mut seen = KeySet::default();
        cleaned.retain(|&p| seen.insert(MortonCode::encode(keys.key_unchecked(p))));
        cleaned.iter_mut().for_each(|p| *p = keys.key_to_point(keys.key_unchecked(*p)));
    }
    let points = if clean { points } else { &cleaned[..] };

    let fan = RayFan::new(keys, origin).ok();
    let run = || cast_scan(keys, points, fan.as_ref(), origin, opts);
    let update = match opts.threads {
        Some(1) => cast_serial(keys, points, fan.as_ref(), origin, opts),
        None => run(),
        Some(n) => thread_pool(n)?.install(run),
    };
    Ok((update, report))
}

fn cast_serial(
    keys: &KeySpace,
    points: &[Point3],
    fan: Option<&RayFan>,
    origin: Point3,
    opts: &ScanOptions,
) -> ScanUpdate {
    let mut c = Casting::default();
    c.cast_all(keys, fan, points, origin, opts);
    c.into_update()
}

fn cast_scan(
    keys: &KeySpace,
    points: &[Point3],
    fan: Option<&RayFan>,
    origin: Point3,
    opts: &ScanOptions,
) -> ScanUpdate {
    let threads = rayon::current_num_threads();
    if threads == 1 {
        return cast_serial(keys, points, fan, origin, opts);
    }
    let chunk = points.len().div_ceil(2 * threads).max(512);
    let parts: Vec<(Vec<u64>, Vec<u64>)> = points
        .par_chunks(chunk)
        .fold(Casting::default, |mut acc, chunk| {
            acc.cast_all(keys, fan, chunk, origin, opts);
            acc
        })
        .map(|c| c.finish())
        .collect();
    let (free, occupied): (Vec<_>, Vec<_>) = parts.into_iter().unzip();
    let (mut free, occupied) = rayon::join(|| merge_sorted(free), || merge_sorted(occupied));
    dedup_except(&mut free, &occupied);
    ScanUpdate { free, occupied }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::SensorModel;
    use crate::tree::NodeKind;

    fn scan() -> Vec<Point3> {
        vec![
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(f32::NAN, 0.0, 0.0),
            Point3::new(0.0, f32::INFINITY, 0.0),
            Point3::new(5000.0, 0.0, 0.0), // outside a 0.1 m map (±3276.8 m)
            Point3::new(0.0, 2.0, 0.0),
        ]
    }

    #[test]
    fn non_finite_points_are_skipped_and_counted() {
        let mut t = OccupancyTree::new(0.1).unwrap();
        let r = t.insert_point_cloud(&scan(), Point3::default(), &ScanOptions::default()).unwrap();
        assert_eq!(r.points, 5);
        assert_eq!(r.non_finite, 2);
        assert_eq!(r.occupied_updates, 2, "the far point has no key and is not marked");
        assert!(t.is_occupied(t.search_point(Point3::new(1.0, 0.0, 0.0), 0).unwrap().unwrap().value));
    }

    #[test]
    fn out_of_map_points_follow_the_chosen_policy() {
        let origin = Point3::default();
        let mut t = OccupancyTree::new(0.1).unwrap();
        let opts = ScanOptions { out_of_map: OutOfMap::Error, ..Default::default() };
        let err = t.insert_point_cloud(&scan(), origin, &opts).unwrap_err();
        assert!(matches!(err, ScanError::PointOutOfMap { index: 3, .. }), "{err}");
        assert!(t.is_empty(), "a refused scan changes nothing");

        let opts = ScanOptions { out_of_map: OutOfMap::Skip, ..Default::default() };
        let r = t.insert_point_cloud(&scan(), origin, &opts).unwrap();
        assert_eq!((r.non_finite, r.out_of_map, r.occupied_updates), (2, 1, 2));

        // with a max range OctoMap still frees the cut ray towards the far point
        let mut a = OccupancyTree::new(0.1).unwrap();
        let mut b = OccupancyTree::new(0.1).unwrap();
        let far = [Point3::new(5000.0, 0.0, 0.0)];
        let octomap = ScanOptions { max_range: Some(3.0), ..Default::default() };
        let skip = ScanOptions { out_of_map: OutOfMap::Skip, ..octomap };
        a.insert_point_cloud(&far, origin, &octomap).unwrap();
        b.insert_point_cloud(&far, origin, &skip).unwrap();
        assert!(a.num_leaves() > 0);
        assert!(b.is_empty());
    }

    #[test]
    fn a_non_finite_origin_is_refused() {
        let mut t = OccupancyTree::new(0.1).unwrap();
        let err = t.insert_point_cloud(&scan(), Point3::new(f32::NAN, 0.0, 0.0), &ScanOptions::default());
        assert!(matches!(err, Err(ScanError::Origin { .. })));
    }

    /// The bundled sample's six scans of a simulated indoor lidar
    /// (`samples/indoor.graph`), in the world frame, with their origins. At
    /// 0.1 m each scan frees 39k to 72k voxels: enough for the threads to
    /// share its tree update.
    fn sample_scans() -> Vec<(Vec<Point3>, Point3)> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph");
        let g = crate::formats::graph::read_file(path).unwrap();
        g.nodes.iter().map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect()
    }

    use crate::formats::ot::to_bytes as ot;

    /// The two walks (eight or sixteen rays in AVX-512 lanes, and two
    /// rays interleaved, which processors without AVX-512 take) give the
    /// same sets, with and without a maximum range.
    #[test]
    fn vector_and_pairwise_walks_give_the_same_update() {
        #[cfg(target_arch = "x86_64")]
        if crate::ray::wide::available() {
            for (res, max_range) in [(0.05, None), (0.2, None), (0.1, Some(2.5)), (0.02, Some(4.0))] {
                let keys = KeySpace::new(res);
                for (points, origin) in sample_scans().into_iter().take(2) {
                    let fan = RayFan::new(&keys, origin).ok();
                    let opts = ScanOptions { max_range, ..Default::default() };
                    let (mut wide, mut pairs) = (Casting::default(), Casting::default());
                    wide.cast_all(&keys, fan.as_ref(), &points, origin, &opts);
                    pairs.cast_all_pairs(&keys, fan.as_ref().unwrap(), &points, origin, &opts);
                    let (wide, pairs) = (wide.into_update(), pairs.into_update());
                    assert!(wide.free.len() > 1000, "{res} m: {} free voxels", wide.free.len());
                    assert!(wide == pairs, "{res} m, max range {max_range:?}");
                }
            }
            return;
        }
        eprintln!("skipped: no AVX-512F (only the pairwise walk runs here)");
    }

    #[test]
    fn thread_count_does_not_change_the_tree() {
        let scans = &sample_scans()[..3];
        let mut bytes = Vec::new();
        for threads in [1, 2, 8] {
            let mut t = OccupancyTree::new(0.05).unwrap();
            for (points, origin) in scans {
                let opts = ScanOptions { threads: Some(threads), ..Default::default() };
                t.insert_point_cloud(points, *origin, &opts).unwrap();
            }
            bytes.push(ot(&t));
        }
        assert!(bytes[0] == bytes[1] && bytes[1] == bytes[2]);
    }

    /// Free-space batches large enough to be shared by the threads
    /// (`update_batch_split`), inside the pipeline, where the thread waiting
    /// for work helps: the tree stays the one-thread tree.
    #[test]
    fn shared_tree_updates_in_the_pipeline_give_the_same_tree() {
        let scans = &sample_scans()[..3];
        let mut trees = Vec::new();
        for threads in [Some(1), Some(2), Some(8)] {
            let mut t = OccupancyTree::new(0.1).unwrap();
            let opts = ScanOptions { threads, ..Default::default() };
            let mut largest = 0;
            let input = scans.iter().map(|(p, o)| (p.as_slice(), *o));
            t.insert_point_clouds(input, &opts, |_, r| largest = largest.max(r.free_updates)).unwrap();
            assert!(largest >= crate::tree::PARALLEL_MIN_CODES, "{largest} codes: nothing to share");
            trees.push(ot(&t));
        }
        assert!(trees[0] == trees[1] && trees[1] == trees[2]);
    }

    /// Many threads over many short scans, with a few large ones whose
    /// tree updates are shared while the other threads wait for work: the
    /// hand-off never loses a wakeup (a lost one hangs the run) and the
    /// tree is the one-thread tree. Each run is watched by a timer.
    #[test]
    fn many_threads_on_many_short_scans_always_finish() {
        let mut scans = sample_scans();
        let short = scans.split_off(2);
        for (points, origin) in &short[2..] {
            scans.extend(points.chunks(25).map(|c| (c.to_vec(), *origin)));
        }
        let middle = scans.len() / 2;
        scans.swap(1, middle);
        let build = |threads| {
            let mut t = OccupancyTree::new(0.1).unwrap();
            let opts = ScanOptions { threads, ..Default::default() };
            t.insert_point_clouds(scans.iter().map(|(p, o)| (p.as_slice(), *o)), &opts, |_, _| {}).unwrap();
            ot(&t)
        };
        let expected = build(Some(1));
        let scans = &scans;
        std::thread::scope(|scope| {
            for (run, threads) in [256, 64, 33, 256, 7, 128].repeat(2).into_iter().enumerate() {
                let (done, finished) = std::sync::mpsc::channel();
                let watched = scope.spawn(move || {
                    let mut t = OccupancyTree::new(0.1).unwrap();
                    let opts = ScanOptions { threads: Some(threads), ..Default::default() };
                    t.insert_point_clouds(scans.iter().map(|(p, o)| (p.as_slice(), *o)), &opts, |_, _| {}).unwrap();
                    let _ = done.send(());
                    ot(&t)
                });
                if finished.recv_timeout(std::time::Duration::from_secs(120)).is_err() {
                    // a hung pipeline never returns: end the test process
                    eprintln!("run {run} on {threads} threads hung");
                    std::process::abort();
                }
                assert!(watched.join().unwrap() == expected, "run {run}, {threads} threads");
            }
        });
    }

    #[test]
    fn pipelined_insertion_matches_scan_by_scan() {
        let scans = sample_scans().split_off(2);
        // colour trees must keep OctoMap's key order: colours blended in
        // after each scan make that order visible in the next one
        for kind in [NodeKind::Plain, NodeKind::Color, NodeKind::Stamped] {
            let new_tree = || OccupancyTree::with_kind(0.1, SensorModel::default(), kind).unwrap();
            let paint = |t: &mut OccupancyTree, scan: usize| {
                if kind == NodeKind::Color {
                    for (i, p) in scans[scan].0.iter().enumerate() {
                        let k = t.key(*p).unwrap();
                        t.integrate_color(k, [(i * 7) as u8, (scan * 50) as u8, (i * 13) as u8]);
                    }
                }
            };
            let mut expected = new_tree();
            let mut reports = Vec::new();
            for (i, (points, origin)) in scans.iter().enumerate() {
                reports.push(expected.insert_point_cloud(points, *origin, &ScanOptions::default()).unwrap());
                paint(&mut expected, i);
            }
            for threads in [Some(1), Some(2), Some(8), None] {
                let mut t = new_tree();
                let opts = ScanOptions { threads, ..Default::default() };
                let mut got = Vec::new();
                let input = scans.iter().map(|(p, o)| (p.as_slice(), *o));
                t.insert_point_clouds(input, &opts, |t, r| {
                    paint(t, got.len());
                    got.push(r)
                })
                .unwrap();
                assert_eq!(got, reports, "{kind:?}, {threads:?} threads");
                assert!(ot(&t) == ot(&expected), "{kind:?}, {threads:?} threads");
            }
        }

        // a refused scan stops the sequence after the scans before it
        let mut bad = scans.clone();
        bad[2].0.push(Point3::new(1e9, 0.0, 0.0));
        for threads in [Some(1), Some(2), Some(8)] {
            let opts = ScanOptions { threads, out_of_map: OutOfMap::Error, ..Default::default() };
            let mut t = OccupancyTree::new(0.1).unwrap();
            let mut n = 0;
            let input = bad.iter().map(|(p, o)| (p.as_slice(), *o));
            let err = t.insert_point_clouds(input, &opts, |_, _| n += 1).unwrap_err();
            assert_eq!(err.0, 2);
            assert!(matches!(err.1, ScanError::PointOutOfMap { .. }));
            assert_eq!(n, 2);
        }

        // a panic in the callback reaches the caller; the casters stop
        for threads in [Some(2), Some(8)] {
            let opts = ScanOptions { threads, ..Default::default() };
            let caught = std::panic::catch_unwind(|| {
                let mut t = OccupancyTree::new(0.1).unwrap();
                let input = scans.iter().map(|(p, o)| (p.as_slice(), *o));
                let _ = t.insert_point_clouds(input, &opts, |_, _| panic!("callback"));
            });
            assert!(caught.is_err());
        }
    }
}
