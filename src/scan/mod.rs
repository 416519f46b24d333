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
//! codes (`RayFan`) and set one bit per voxel in bitmaps of aligned
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
use crate::key::{Key, KeyError};
use crate::ray::{point_along, RayKeys};
use crate::tree::{InnerNodes, OccupancyTree};
use pipeline::{Job, Pipeline, StdMonitor};
use std::ops::Range;
use std::sync::Mutex;

// its insertion loop writes through a raw pointer
#[allow(unsafe_code)]
mod block_set;
mod casting;
pub(crate) mod key_set;
mod options;
mod pipeline;
mod region;

use casting::thread_pool;
pub use casting::ScanUpdate;
pub(crate) use casting::{compute_update, compute_update_in};
pub use options::{OutOfMap, ScanError, ScanOptions, ScanReport, UpdateBox};

/// Free-space batches of at least this many codes are shared by the
/// pipeline's threads even while the next scan is still being cast:
/// applying one outlasts casting a scan, so the casting threads soon come
/// to help (outdoors at 0.1 m a scan has 17M). Smaller ones are shared only
/// when the next scan is cast already: a shared update that no thread helps
/// with costs a sixth more than the serial walk (`docs/benchmarks.md`,
/// "Where the time goes" and "Tried and rejected").
#[cfg(not(test))]
const ALWAYS_SHARED: usize = 1 << 22;
/// In tests, between the sharing threshold (2^15 there) and the largest
/// batch of the sample scans at 0.1 m (50,810 codes): that batch is shared
/// whatever the timing of the casts.
#[cfg(test)]
const ALWAYS_SHARED: usize = 40_000;
const _: () = assert!(ALWAYS_SHARED > crate::tree::PARALLEL_MIN_CODES);

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
                        let share = share || update.free.len() >= ALWAYS_SHARED;
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
    /// [`Self::insert_point_cloud`] applies them in one batched walk
    /// instead ([`Self::apply_update`]).
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

    /// [`Self::compute_update`] restricted to the voxels whose Morton codes
    /// lie in `codes`: bit for bit the unrestricted update's codes inside
    /// the range and none outside, so that processes each owning a range
    /// of tiles cast only the rays that reach their tiles.
    pub fn compute_update_in(
        &self,
        points: &[Point3],
        origin: Point3,
        opts: &ScanOptions,
        codes: Range<u64>,
    ) -> Result<(ScanUpdate, ScanReport), ScanError> {
        compute_update_in(self.key_space(), points, origin, opts, codes)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::SensorModel;
    use crate::tree::{Clock, NodeKind};

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
    pub(super) fn sample_scans() -> Vec<(Vec<Point3>, Point3)> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph");
        let g = crate::formats::graph::read_file(path).unwrap();
        g.nodes.iter().map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect()
    }

    use crate::formats::ot::to_bytes as ot;

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
            // shared whatever the timing of the casts
            assert!(largest >= ALWAYS_SHARED, "{largest} codes: nothing to share");
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
            // a fixed clock: the system's may tick between the two builds,
            // and stamps decide what prunes
            let new_tree = || {
                let mut t = OccupancyTree::with_kind(0.1, SensorModel::default(), kind).unwrap();
                t.set_clock(Clock::Fixed(7));
                t
            };
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
