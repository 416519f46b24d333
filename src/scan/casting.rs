//! Ray casting of one scan into its free and occupied voxel sets, on one
//! thread or split over a rayon pool.

use super::block_set::BlockSet;
use super::key_set::KeySet;
use super::region::{CodeRegion, RayStop, CODE_SPACE};
use super::{OutOfMap, ScanError, ScanOptions, ScanReport};
#[cfg(target_arch = "x86_64")]
use crate::arch::avx512::RayLimits;
use crate::geometry::Point3;
use crate::key::{Key, KeySpace};
use crate::morton::MortonCode;
use crate::ray::{FanRay, RayFan, RayKeys};
use rayon::prelude::*;
use std::ops::Range;

/// What one worker collects: the free and the occupied voxels whose
/// Morton codes lie in `recorded` (every code unless the update is
/// restricted to a range, whose rays' walks then end at `stop`).
pub(super) struct Casting {
    free: BlockSet,
    occupied: BlockSet,
    recorded: Range<u64>,
    stop: Option<RayStop>,
}

impl Default for Casting {
    fn default() -> Self {
        Casting::recording(0..u64::MAX, None)
    }
}

/// True when `code` lies in `range` (one comparison).
#[inline(always)]
fn in_range(range: &Range<u64>, code: u64) -> bool {
    code.wrapping_sub(range.start) < range.end.wrapping_sub(range.start)
}

impl Casting {
    /// A worker keeping only the codes in `recorded`, its walks ended at
    /// `stop`.
    fn recording(recorded: Range<u64>, stop: Option<RayStop>) -> Self {
        Casting { free: BlockSet::default(), occupied: BlockSet::default(), recorded, stop }
    }

    /// Adds a free voxel, if recorded.
    #[inline(always)]
    fn insert_free(&mut self, code: u64) {
        if in_range(&self.recorded, code) {
            self.free.insert(code);
        }
    }

    /// Adds an occupied voxel, if recorded.
    #[inline(always)]
    fn insert_occupied(&mut self, code: u64) {
        if in_range(&self.recorded, code) {
            self.occupied.insert(code);
        }
    }

    /// `computeUpdate`'s work for one end point. `fan` holds the rays'
    /// common origin; `None` when it lies outside the map (no rays then).
    #[inline]
    fn cast(&mut self, keys: &KeySpace, fan: Option<&RayFan>, p: Point3, origin: Point3, opts: &ScanOptions) {
        let (within, end) = cut_to_range(p, origin, opts);
        let Some(bbx) = opts.bbx else {
            let Some(end_code) = self.end_voxel(keys, end, within) else { return };
            if let Some(fan) = fan {
                fan.for_each_code(end, end_code, |c| self.insert_free(c));
            }
            return;
        };
        if within && bbx.contains_point(p) {
            if let Ok(k) = keys.key(p) {
                self.insert_occupied(MortonCode::encode(k).0);
            }
        }
        if let Ok(ray) = RayKeys::new(keys, origin, end) {
            for k in ray.take_while(|&k| bbx.contains_key(k)) {
                self.insert_free(MortonCode::encode(k).0);
            }
        }
    }

    /// [`Self::cast`] for every point. The steps of one ray form a chain
    /// of dependent operations, so several rays are walked at once and
    /// their chains overlap: eight or sixteen in vector lanes where the
    /// processor has AVX-512 (`arch::avx512`), else two.
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
        if let Some(avx512) = crate::arch::avx512::Avx512::detect() {
            let Casting { free, occupied, recorded, stop } = self;
            let max_range = opts.max_range.unwrap_or(-1.0);
            let (mut kept_free, mut kept_occupied) = (Vec::new(), Vec::new());
            let occupied = |codes: &[u64]| insert_recorded(occupied, codes, recorded, &mut kept_occupied);
            let free = |codes: &[u64]| insert_recorded(free, codes, recorded, &mut kept_free);
            let stop_at = |dir| stop.as_ref().map_or(f64::INFINITY, |s| s.length(dir));
            let limits = RayLimits { max_range, stop: stop.as_ref().map(|_| &stop_at as _) };
            if avx512.cast_fan(fan, keys, points, limits, occupied, free) {
                self.insert_free(fan.origin_code());
            }
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
                Some(c) => self.insert_free(c),
                None => (a, a_steps) = self.next_ray(fan, keys, &mut points, &mut ready, origin, opts).split(),
            }
            match cb {
                Some(c) => self.insert_free(c),
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
            self.insert_free(c);
        }
        while let Some(c) = b.next_code(&b_steps) {
            self.insert_free(c);
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
            if let Some(mut ray) = fan.ray(end, end_code) {
                if let Some(stop) = &self.stop {
                    let d = end - origin;
                    let norm = d.norm();
                    ray.length = ray.length.min(stop.length([d.x, d.y, d.z].map(|v| f64::from(v) / norm)));
                }
                ready.push(ray);
            }
        }
        if !ready.is_empty() {
            self.insert_free(fan.origin_code());
        }
    }

    /// The Morton code of the ray end's voxel, marked occupied when the
    /// end is the point itself (`within` range); `None` outside the map.
    #[inline(always)]
    fn end_voxel(&mut self, keys: &KeySpace, end: Point3, within: bool) -> Option<u64> {
        let end_code = MortonCode::encode(keys.key(end).ok()?).0;
        if within {
            self.insert_occupied(end_code);
        }
        Some(end_code)
    }

    /// Both sets as sorted lists; the free one keeps the occupied voxels
    /// (another worker's may have them too).
    fn finish(self) -> (Vec<u64>, Vec<u64>) {
        (self.free.into_sorted_codes(None), self.occupied.into_sorted_codes(None))
    }

    /// The scan's update, when this worker cast all of it.
    fn into_update(self) -> ScanUpdate {
        let free = self.free.into_sorted_codes(Some(&self.occupied));
        ScanUpdate { free, occupied: self.occupied.into_sorted_codes(None) }
    }
}

/// Adds the codes of `codes` that lie in `recorded` to `set`: all at once
/// when every code is recorded, else through `kept`.
#[inline(always)]
fn insert_recorded(set: &mut BlockSet, codes: &[u64], recorded: &Range<u64>, kept: &mut Vec<u64>) {
    if recorded.start == 0 && recorded.end == u64::MAX {
        set.insert_all(codes)
    } else {
        kept.clear();
        kept.extend(codes.iter().copied().filter(|&c| in_range(recorded, c)));
        set.insert_all(kept)
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

/// Whether every point is finite, in blocks with no early exit inside,
/// which the compiler vectorises (a test per point with an exit after each
/// was 2% of a full-size indoor build).
fn all_finite(points: &[Point3]) -> bool {
    points.chunks(256).all(|c| c.iter().fold(true, |ok, p| ok & p.x.is_finite() & p.y.is_finite() & p.z.is_finite()))
}

/// Thread pools by size, built once: a pool per scan would cost more than
/// casting a small scan's rays.
pub(super) fn thread_pool(threads: usize) -> Result<std::sync::Arc<rayon::ThreadPool>, ScanError> {
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

/// [`crate::OccupancyTree::compute_update`] for a map with key space `keys`: the
/// update depends on nothing else of the tree.
pub(crate) fn compute_update(
    keys: &KeySpace,
    points: &[Point3],
    origin: Point3,
    opts: &ScanOptions,
) -> Result<(ScanUpdate, ScanReport), ScanError> {
    compute_update_in(keys, points, origin, opts, 0..u64::MAX)
}

/// [`compute_update`] restricted to the voxels whose Morton codes lie in
/// `codes`: the same codes inside, none outside. Rays are still walked
/// from the origin (their steps depend on it), but only those whose
/// segment can reach the range's cubes.
pub(crate) fn compute_update_in(
    keys: &KeySpace,
    points: &[Point3],
    origin: Point3,
    opts: &ScanOptions,
    codes: Range<u64>,
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
    let clean = opts.out_of_map == OutOfMap::OctoMap && !opts.discretize && all_finite(points);
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
    let mut points = if clean { points } else { &cleaned[..] };
    let reaching: Vec<Point3>;
    let restricted = codes.start > 0 || codes.end < CODE_SPACE;
    if codes.start >= codes.end.min(CODE_SPACE) {
        // no voxel of the map in the range
        return Ok((ScanUpdate::default(), report));
    }
    if restricted {
        let region = CodeRegion::new(keys, &codes);
        reaching =
            points.iter().copied().filter(|&p| region.may_touch(origin, cut_to_range(p, origin, opts).1)).collect();
        points = &reaching;
    }

    let stop = restricted.then(|| RayStop::new(keys, &codes, origin));
    let fan = RayFan::new(keys, origin).ok();
    let cast = Cast { keys, fan: fan.as_ref(), origin, opts, codes: &codes, stop: stop.as_ref() };
    let run = || cast.scan(points);
    let update = match opts.threads {
        Some(1) => cast.serial(points),
        None => run(),
        Some(n) => thread_pool(n)?.install(run),
    };
    Ok((update, report))
}

/// What every worker casting one scan shares.
struct Cast<'a> {
    keys: &'a KeySpace,
    fan: Option<&'a RayFan>,
    origin: Point3,
    opts: &'a ScanOptions,
    /// The codes recorded.
    codes: &'a Range<u64>,
    /// Where walks end, for an update restricted to `codes`.
    stop: Option<&'a RayStop>,
}

impl Cast<'_> {
    /// One worker casting every ray of `points`.
    fn serial(&self, points: &[Point3]) -> ScanUpdate {
        let mut c = Casting::recording(self.codes.clone(), self.stop.cloned());
        c.cast_all(self.keys, self.fan, points, self.origin, self.opts);
        c.into_update()
    }

    /// The points shared by the current rayon pool's threads.
    fn scan(&self, points: &[Point3]) -> ScanUpdate {
        let threads = rayon::current_num_threads();
        if threads == 1 {
            return self.serial(points);
        }
        let chunk = points.len().div_ceil(2 * threads).max(512);
        let parts: Vec<(Vec<u64>, Vec<u64>)> = points
            .par_chunks(chunk)
            .fold(
                || Casting::recording(self.codes.clone(), self.stop.cloned()),
                |mut acc, chunk| {
                    acc.cast_all(self.keys, self.fan, chunk, self.origin, self.opts);
                    acc
                },
            )
            .map(|c| c.finish())
            .collect();
        let (free, occupied): (Vec<_>, Vec<_>) = parts.into_iter().unzip();
        let (mut free, occupied) = rayon::join(|| merge_sorted(free), || merge_sorted(occupied));
        dedup_except(&mut free, &occupied);
        ScanUpdate { free, occupied }
    }
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

    /// Number of voxels to update, free and occupied together.
    pub fn len(&self) -> usize {
        self.free.len() + self.occupied.len()
    }

    /// True when the scan updates no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two walks (eight or sixteen rays in AVX-512 lanes, and two
    /// rays interleaved, which processors without AVX-512 take) give the
    /// same sets, with and without a maximum range.
    #[test]
    fn vector_and_pairwise_walks_give_the_same_update() {
        #[cfg(target_arch = "x86_64")]
        if crate::arch::avx512::Avx512::detect().is_some() {
            for (res, max_range) in [(0.05, None), (0.2, None), (0.1, Some(2.5)), (0.02, Some(4.0))] {
                let keys = KeySpace::new(res);
                for (points, origin) in super::super::tests::sample_scans().into_iter().take(2) {
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

    /// Random points around a random origin, some far, some beyond the map.
    fn random_scan(seed: u64, count: usize) -> (Vec<Point3>, Point3) {
        let mut s = seed;
        let mut next = move || {
            s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let origin = Point3::new((next() * 8.0) as f32, (next() * 8.0) as f32, (next() * 2.0) as f32);
        let points = (0..count)
            .map(|i| {
                let scale = if i % 50 == 0 { 2000.0 } else { 30.0 };
                origin + Point3::new((next() * scale) as f32, (next() * scale) as f32, (next() * scale / 4.0) as f32)
            })
            .collect();
        (points, origin)
    }

    /// Cut points splitting the code space into ranges: tile-aligned ones
    /// at two depths and arbitrary codes.
    fn partitions() -> Vec<Vec<u64>> {
        let all = CODE_SPACE;
        vec![
            vec![0, all],
            vec![0, 4 << 45, all],
            vec![0, 3 << 45, (3 << 45) + (5 << 39) + (1 << 36), 6 << 45, all],
            vec![0, 0x8000_1234_5678 & (all - 1), 0xa000_0000_0001 & (all - 1), all],
        ]
    }

    /// The updates of a partition's ranges: each inside its range, and
    /// together the unrestricted update, on one thread and on several,
    /// with and without a maximum range, with the end points discretized.
    #[test]
    fn updates_in_a_partition_of_ranges_add_up_to_the_whole_update() {
        let keys = KeySpace::new(0.1);
        let mut scans = super::super::tests::sample_scans().into_iter().take(2).collect::<Vec<_>>();
        scans.extend((0..3).map(|seed| random_scan(seed, 3000)));
        for (points, origin) in &scans {
            for (threads, max_range, discretize) in
                [(Some(1), None, false), (Some(2), Some(5.0), false), (None, None, true)]
            {
                let opts = ScanOptions { threads, max_range, discretize, ..Default::default() };
                let (whole, report) = compute_update(&keys, points, *origin, &opts).unwrap();
                assert!(whole.free.len() > 100);
                for cuts in partitions() {
                    let mut joined = ScanUpdate::default();
                    for range in cuts.windows(2).map(|w| w[0]..w[1]) {
                        let (part, part_report) =
                            compute_update_in(&keys, points, *origin, &opts, range.clone()).unwrap();
                        assert_eq!(part_report, report);
                        assert!(part.free.iter().chain(&part.occupied).all(|c| range.contains(c)));
                        joined.free.extend(part.free);
                        joined.occupied.extend(part.occupied);
                    }
                    assert!(joined == whole, "{cuts:x?} {threads:?} {max_range:?}");
                }
                for empty in [5..5, CODE_SPACE..u64::MAX] {
                    assert!(compute_update_in(&keys, points, *origin, &opts, empty).unwrap().0.is_empty());
                }
            }
        }
    }

    /// The pairwise walk (processors without AVX-512), its walks ended
    /// where they leave the range, records the codes in the range, as the
    /// vector walk does.
    #[test]
    fn the_pairwise_walk_records_only_the_range() {
        let keys = KeySpace::new(0.1);
        for (points, origin) in (5..8).map(|seed| random_scan(seed, 2000)) {
            let fan = RayFan::new(&keys, origin).unwrap();
            let opts = ScanOptions::default();
            let mut whole = Casting::default();
            whole.cast_all_pairs(&keys, &fan, &points, origin, &opts);
            let whole = whole.into_update();
            for range in partitions()[2].windows(2).map(|w| w[0]..w[1]) {
                let mut part = Casting::recording(range.clone(), Some(RayStop::new(&keys, &range, origin)));
                part.cast_all_pairs(&keys, &fan, &points, origin, &opts);
                let inside = |codes: &[u64]| codes.iter().copied().filter(|c| range.contains(c)).collect::<Vec<_>>();
                let part = part.into_update();
                assert_eq!(part.free, inside(&whole.free));
                assert_eq!(part.occupied, inside(&whole.occupied));
            }
        }
    }
}
