//! A tile set built one group of tiles at a time: the build for a memory
//! cap that holds a map's tiles and a scan's update together.
//!
//! A scan-by-scan build under a [`MemoryBudget`] keeps its tiles within
//! the budget, but holds a whole scan's update besides (18M voxel updates
//! per scan of the full-size outdoor sequence at 0.1 m, 142 MB of codes),
//! and writes tiles out and reads them back as every scan sweeps the map.
//! A grouped build turns the loops around: the tile prefixes are cut into
//! contiguous ranges (compact regions, as a plan's tasks are), and each
//! range is built from every scan in order, casting only the rays that
//! reach it, then written to disk and dropped. Memory holds one group's
//! tiles and one scan's update restricted to them, and each tile is
//! written once. Every tile still receives every scan's updates in scan
//! order, so the tile set is the single build's. What it costs is casting:
//! a ray crossing several groups is walked by each, from the sensor.
//!
//! The groups are sized from the estimated voxel updates of their tiles
//! ([`TileWork::updates`]): a scan's for the update it holds, all scans'
//! for its tiles, at bytes per estimated update measured on the groups
//! built so far (the first group counts its update alone). The estimate
//! errs, so a group is watched as it grows: once its tiles and a
//! scan's update would pass the memory, it stops after the scan in hand
//! and splits in two ranges of about equal bytes; both go on from the
//! next scan, the upper one set aside on disk while the lower one is
//! built. A group of one tile cannot split: its tile is held whole. A
//! map whose whole estimate fits the memory is one group.
//!
//! With `T` threads, `T` workers build groups at once, each on one thread
//! within a `T`-th of the memory (casting one scan on two threads holds a
//! set per thread and was no faster on the full-size outdoor sequence);
//! they share the groups still to build and the calibration.

use super::budget::MemoryBudget;
use super::error::TileError;
use super::manifest::{BuildRecord, Manifest, TaskPart, TaskTiles, TileEntry, MANIFEST_FILE};
use super::map::{Tile, TileState, TiledMap};
use super::plan::{aligned_between, TileWork};
use crate::formats::ot::TreeKind;
use crate::geometry::Point3;
use crate::scan::ScanOptions;
use crate::sensor::SensorModel;
use crate::tree::{InnerNodes, NodeKind};
use std::ops::Range;
use std::path::PathBuf;
use std::sync::{Condvar, Mutex};
use std::time::Instant;

/// Bytes a voxel update of a scan holds while the scan is cast and
/// applied: its code in the sorted list (8), its share of the block
/// bitmaps the casting fills (64-byte blocks, a few voxels each far from
/// the sensor) and of their growth. Measured on the full-size outdoor
/// sequence at 0.05 m: with 24, builds under a 64 MiB cap peaked 24 MiB
/// (one thread) and 49 MiB (two) above it; with 48, 2 and 18 MiB.
pub const UPDATE_BYTES: usize = 48;

/// Groups are cut to this part of the memory, for the error of the
/// estimate from group to group.
const FILL: f64 = 0.8;

/// A tile set of a plain map to build group by group, within `memory`
/// bytes. (Stamped maps are not built so: their stamps would tell when
/// each group was built, not when its scans came.)
#[derive(Clone, Debug)]
pub struct GroupedBuild {
    /// Voxel edge length in metres.
    pub resolution: f64,
    /// The sensor model of the map.
    pub sensor: SensorModel,
    /// Bytes for the groups being built: their tiles
    /// ([`crate::OccupancyTree::memory_usage`]) and a scan's update for
    /// each; not counted: the program, the scans' points and the
    /// allocator's slack.
    pub memory: usize,
    /// The tile set's directory: tiles are written there as their group
    /// is done, and the manifest once all are.
    pub dir: PathBuf,
    /// How the set is built, recorded in its manifest (`None`: no record,
    /// a version 1 manifest).
    pub record: Option<BuildRecord>,
}

/// One group of a grouped build.
#[derive(Clone, Debug, PartialEq)]
pub struct BuiltGroup {
    /// The tile prefixes it covers.
    pub prefixes: Range<u64>,
    /// Estimated voxel updates of its tiles ([`TileWork::updates`]).
    pub estimate: u64,
    /// Tiles it holds.
    pub tiles: usize,
    /// Bytes its tiles' trees held once built.
    pub tile_bytes: usize,
    /// Voxel updates of its largest scan.
    pub largest_update: usize,
    /// Wall time to build and write it.
    pub seconds: f64,
}

/// What a grouped build made.
#[derive(Clone, Debug)]
pub struct GroupedReport {
    /// The manifest written.
    pub manifest: Manifest,
    /// The groups, in prefix order.
    pub groups: Vec<BuiltGroup>,
}

/// Why a grouped build stopped; nothing is left in the directory that a
/// manifest lists.
#[derive(Debug, thiserror::Error)]
pub enum GroupedError<E> {
    /// The scans could not be read (the error the iterator gave).
    #[error("{0}")]
    Input(E),
    /// The scan at this position was refused.
    #[error("scan {index}: {source}")]
    Scan {
        /// Its position in the scans.
        index: usize,
        /// Why.
        source: TileError,
    },
    /// Tiles could not be written or read back.
    #[error(transparent)]
    Tiles(#[from] TileError),
}

/// What the groups built measured against what was estimated of them.
#[derive(Default)]
struct Calibration {
    /// Estimated updates, summed over the scans.
    summed: f64,
    /// Estimated updates of one scan, the most per tile, summed.
    largest: f64,
    tile_bytes: f64,
    largest_updates: f64,
}

impl Calibration {
    /// Bytes a group of tiles whose estimates are `summed` and `largest`
    /// will hold: its tiles (none before a group is measured: a group that
    /// outgrows the memory splits) and the update of its largest scan (as
    /// estimated before a group is measured).
    fn bytes(&self, summed: u64, largest: u64) -> f64 {
        let tiles = if self.summed > 0.0 { self.tile_bytes / self.summed } else { 0.0 };
        let scan = if self.largest > 0.0 { self.largest_updates / self.largest } else { 1.0 };
        tiles * summed as f64 + scan * (UPDATE_BYTES as f64) * largest as f64
    }

    fn add(&mut self, g: &BuiltGroup, largest: u64) {
        if g.estimate > 0 && largest > 0 {
            self.summed += g.estimate as f64;
            self.largest += largest as f64;
            self.tile_bytes += g.tile_bytes as f64;
            self.largest_updates += g.largest_update as f64;
        }
    }
}

impl GroupedBuild {
    /// Builds the tile set from `scans` (called once per group, each time
    /// giving the same scans in the same order) with the insertion
    /// options `opts`, in groups sized from `work` (the estimate of the
    /// same scans at the tile depth to build); `progress(group, scans)`
    /// after each scan. With `opts.threads` of `T` (all cores when unset),
    /// `T` groups are built at once, each on one thread within an `T`-th of
    /// the memory. Returns the manifest written and the groups.
    pub fn build<I, P, E>(
        &self,
        work: &TileWork,
        opts: &ScanOptions,
        scans: impl Fn() -> I + Sync,
        progress: impl Fn(usize, usize) + Sync,
    ) -> Result<GroupedReport, GroupedError<E>>
    where
        I: IntoIterator<Item = Result<(P, Point3), E>>,
        P: AsRef<[Point3]>,
        E: Send,
    {
        let depth = work.depth();
        let workers = opts.threads.unwrap_or_else(rayon::current_num_threads).max(1);
        let plan = Plan {
            tiles: work.updates().collect(),
            prefixes: 1u64 << (3 * u32::from(depth)),
            depth,
            limit: FILL * self.memory as f64 / workers as f64,
            whole: FILL * self.memory as f64,
            opts: ScanOptions { threads: Some(1), ..*opts },
        };
        let state = Mutex::new(State::default());
        let wake = Condvar::new();
        std::thread::scope(|s| {
            for _ in 0..workers {
                s.spawn(|| self.work(&plan, &state, &wake, &scans, &progress));
            }
        });
        let state = state.into_inner().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = state.error {
            return Err(e);
        }
        let (mut groups, mut entries) = (state.groups, state.entries);
        groups.sort_by_key(|g| g.prefixes.start);
        entries.sort_by_key(|e: &TileEntry| e.id.prefix());
        let manifest = Manifest {
            resolution: self.resolution,
            depth,
            kind: TreeKind::of(NodeKind::Plain),
            sensor: self.sensor,
            task: None,
            build: self.record.clone(),
            tiles: entries,
        };
        manifest.write(&self.dir.join(MANIFEST_FILE))?;
        Ok(GroupedReport { manifest, groups })
    }

    /// One worker: takes groups (one split before, else the next from the
    /// estimate) and builds them until none is left or one failed.
    fn work<I, P, E>(
        &self,
        plan: &Plan,
        state: &Mutex<State<E>>,
        wake: &Condvar,
        scans: &(impl Fn() -> I + Sync),
        progress: &(impl Fn(usize, usize) + Sync),
    ) where
        I: IntoIterator<Item = Result<(P, Point3), E>>,
        P: AsRef<[Point3]>,
    {
        let lock = || state.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            let (mut group, index) = {
                let mut st = lock();
                let group = loop {
                    if st.error.is_some() {
                        return;
                    }
                    if let Some(g) = st.pending.pop() {
                        break g;
                    }
                    if st.start < plan.prefixes {
                        let (range, limit) = plan.next_range(&mut st);
                        match self.group_map(plan.depth, range.clone(), limit) {
                            Ok(map) => break Group::new(range, map, limit),
                            Err(e) => {
                                st.error = Some(e.into());
                                wake.notify_all();
                                return;
                            }
                        }
                    }
                    if st.busy == 0 {
                        wake.notify_all();
                        return;
                    }
                    st = wake.wait(st).unwrap_or_else(|e| e.into_inner());
                };
                st.busy += 1;
                st.started += 1;
                (group, st.started - 1)
            };
            let grown = self.grow(plan, &mut group, scans(), |n| progress(index, n));
            let outcome = match grown {
                Ok(Some(upper)) => Ok(Outcome::Split(Box::new(upper))),
                Ok(None) => {
                    self.finish(&mut group, &plan.opts).map(|(b, w)| Outcome::Done(b, w)).map_err(GroupedError::from)
                }
                Err(e) => Err(e),
            };
            let mut st = lock();
            st.busy -= 1;
            match outcome {
                Ok(Outcome::Split(upper)) => st.pending.extend([*upper, group]),
                Ok(Outcome::Done(mut built, written)) => {
                    let (estimate, largest) = plan.estimate(&built.prefixes);
                    built.estimate = estimate;
                    if !group.split {
                        // a split group's halves measured part of the scans only
                        st.calibration.add(&built, largest);
                    }
                    st.groups.push(built);
                    st.entries.extend(written);
                }
                Err(e) => {
                    st.error.get_or_insert(e);
                }
            }
            wake.notify_all();
        }
    }

    /// Writes a group built, returning what it made and its tiles.
    fn finish(&self, group: &mut Group, opts: &ScanOptions) -> Result<(BuiltGroup, Vec<TileEntry>), TileError> {
        if opts.inner == InnerNodes::Defer {
            group.map.update_inner_occupancy()?;
        }
        let started = Instant::now();
        let tile_bytes = group.map.tile_bytes();
        let written = group.map.write_tiles(&self.dir)?;
        let built = BuiltGroup {
            estimate: 0,
            prefixes: group.range.clone(),
            tiles: written.len(),
            tile_bytes,
            largest_update: group.largest_update,
            seconds: group.seconds + started.elapsed().as_secs_f64(),
        };
        Ok((built, written))
    }

    /// An empty map of the tiles of `range`, spilling into the set's
    /// directory past its group's share of the memory (`limit` once
    /// filled).
    fn group_map(&self, depth: u8, range: Range<u64>, limit: f64) -> Result<TiledMap, TileError> {
        let mut map = TiledMap::new(self.resolution, self.sensor, NodeKind::Plain, depth)?;
        map.set_task(TaskPart {
            index: 0,
            count: 1,
            tiles: TaskTiles::Prefixes { start: range.start, end: range.end },
        });
        map.set_budget(MemoryBudget { bytes: (limit / FILL) as usize, dir: self.dir.clone() })?;
        Ok(map)
    }

    /// Inserts the scans from `group.next_scan` on until the last, or
    /// until the group's tiles and the update of its largest scan pass
    /// `limit` bytes: then it splits after the scan in hand, keeping the
    /// lower half and returning the upper one.
    fn grow<I, P, E>(
        &self,
        plan: &Plan,
        group: &mut Group,
        scans: I,
        mut progress: impl FnMut(usize),
    ) -> Result<Option<Group>, GroupedError<E>>
    where
        I: IntoIterator<Item = Result<(P, Point3), E>>,
        P: AsRef<[Point3]>,
    {
        let started = Instant::now();
        let mut split = false;
        let mut scans = scans.into_iter().skip(group.next_scan).peekable();
        while let Some(scan) = scans.next() {
            let (points, origin) = scan.map_err(GroupedError::Input)?;
            let index = group.next_scan;
            let report = group
                .map
                .insert_point_cloud(points.as_ref(), origin, &plan.opts)
                .map_err(|source| GroupedError::Scan { index, source })?;
            group.largest_update = group.largest_update.max(report.free_updates + report.occupied_updates);
            group.next_scan += 1;
            progress(group.next_scan);
            let map = &group.map;
            let over = map.tile_bytes() + group.largest_update * UPDATE_BYTES > group.limit as usize;
            // after the last scan, splitting would save nothing
            if over && map.tiles.len() > 1 && scans.peek().is_some() {
                split = true;
                break;
            }
        }
        group.seconds += started.elapsed().as_secs_f64();
        if !split {
            return Ok(None);
        }
        let at = group.map.halfway();
        let upper_range = at..group.range.end;
        let mut upper = Group {
            map: self.group_map(plan.depth, upper_range.clone(), plan.limit)?,
            range: upper_range,
            limit: plan.limit,
            next_scan: group.next_scan,
            largest_update: 0,
            seconds: 0.0,
            split: true,
        };
        group.map.move_tiles_from(at, &mut upper.map)?;
        group.range.end = at;
        // the updates measured were the whole range's: each half measures
        // its own, within a worker's share
        (group.largest_update, group.split, group.limit) = (0, true, plan.limit);
        group.map.set_task(TaskPart {
            index: 0,
            count: 1,
            tiles: TaskTiles::Prefixes { start: group.range.start, end: at },
        });
        Ok(Some(upper))
    }
}

/// A group of tiles being built: its map, the scan it goes on from, the
/// voxel updates of its largest scan so far, its time so far, whether it
/// is half of a group that split.
struct Group {
    range: Range<u64>,
    map: TiledMap,
    /// Bytes its tiles and largest update may hold before it splits.
    limit: f64,
    next_scan: usize,
    largest_update: usize,
    seconds: f64,
    split: bool,
}

/// What building a group came to.
enum Outcome {
    /// It outgrew its share and split: the upper half to go on.
    Split(Box<Group>),
    /// It is written: what it made, and its tiles.
    Done(BuiltGroup, Vec<TileEntry>),
}

impl Group {
    /// A group of `range` not begun, with its empty map.
    fn new(range: Range<u64>, map: TiledMap, limit: f64) -> Self {
        Group { range, map, limit, next_scan: 0, largest_update: 0, seconds: 0.0, split: false }
    }
}

/// What the workers share and do not change.
struct Plan {
    /// The estimates by tile: prefix, updates summed over the scans, the
    /// most of one scan.
    tiles: Vec<(u64, u64, u64)>,
    /// Tile prefixes at the depth: `8^depth`.
    prefixes: u64,
    depth: u8,
    /// Bytes a worker's group may hold.
    limit: f64,
    /// Bytes all groups may hold together.
    whole: f64,
    /// Insertion options, one thread.
    opts: ScanOptions,
}

impl Plan {
    /// The estimates (summed, largest scan) of the tiles of a range.
    fn estimate(&self, r: &Range<u64>) -> (u64, u64) {
        let t = &self.tiles;
        let (a, b) = (t.partition_point(|t| t.0 < r.start), t.partition_point(|t| t.0 < r.end));
        t[a..b].iter().fold((0, 0), |e, t| (e.0 + t.1, e.1 + t.2))
    }

    /// The next group from the estimate: at least one tile, then as many
    /// as the calibration says fit.
    fn next_range<E>(&self, st: &mut State<E>) -> (Range<u64>, f64) {
        let (tiles, first) = (&self.tiles, st.first);
        if first == 0 {
            // a map that fits the whole memory is one group, on one thread
            let (summed, largest) = self.estimate(&(0..self.prefixes));
            if st.calibration.bytes(summed, largest) <= self.whole {
                (st.start, st.first) = (self.prefixes, tiles.len());
                return (0..self.prefixes, self.whole);
            }
        }
        let (mut last, mut summed, mut largest) = (first, 0u64, 0u64);
        while last < tiles.len()
            && (last == first || st.calibration.bytes(summed + tiles[last].1, largest + tiles[last].2) <= self.limit)
        {
            summed += tiles[last].1;
            largest += tiles[last].2;
            last += 1;
        }
        let end = if last < tiles.len() { aligned_between(tiles[last - 1].0, tiles[last].0) } else { self.prefixes };
        let range = st.start..end;
        (st.start, st.first) = (end, last);
        (range, self.limit)
    }
}

/// What the workers share and change, under a lock.
struct State<E> {
    /// Groups split, the next to build last.
    pending: Vec<Group>,
    /// The first prefix and the first estimated tile not given to a group.
    start: u64,
    first: usize,
    calibration: Calibration,
    groups: Vec<BuiltGroup>,
    entries: Vec<TileEntry>,
    /// Groups being built.
    busy: usize,
    /// Groups begun, for the progress.
    started: usize,
    /// The first failure: the others stop after their group.
    error: Option<GroupedError<E>>,
}

impl<E> Default for State<E> {
    fn default() -> Self {
        State {
            pending: Vec::new(),
            start: 0,
            first: 0,
            calibration: Calibration::default(),
            groups: Vec::new(),
            entries: Vec::new(),
            busy: 0,
            started: 0,
            error: None,
        }
    }
}

impl Tile {
    /// Bytes of its tree: in memory, or its file's when written out.
    fn bytes(&self) -> usize {
        match &self.state {
            TileState::Live { bytes, .. } => *bytes,
            TileState::Spilled(entry) => entry.bytes as usize,
        }
    }
}

impl TiledMap {
    /// Bytes of the tiles' trees, in memory or written out.
    fn tile_bytes(&self) -> usize {
        self.tiles.values().map(Tile::bytes).sum()
    }

    /// The prefix that splits the tiles in two parts of about equal bytes,
    /// the most aligned between the two tiles it falls between; needs two
    /// tiles.
    fn halfway(&self) -> u64 {
        let total = self.tile_bytes();
        let (mut below, mut previous) = (0, None);
        let mut cut = None;
        for (&prefix, tile) in &self.tiles {
            if let Some(p) = previous {
                if cut.is_none() && 2 * below >= total {
                    cut = Some(aligned_between(p, prefix));
                }
            }
            below += tile.bytes();
            previous = Some(prefix);
        }
        // past half only at the last tile: cut before it
        cut.unwrap_or_else(|| {
            let mut keys = self.tiles.keys().rev();
            let (last, before) = (keys.next().copied().unwrap_or(1), keys.next().copied().unwrap_or(0));
            aligned_between(before, last)
        })
    }

    /// Moves the tiles from prefix `at` on into `other` (a map of the same
    /// kind and budget directory), written out first: `other` reads them
    /// back when its scans reach them.
    fn move_tiles_from(&mut self, at: u64, other: &mut TiledMap) -> Result<(), TileError> {
        let moving: Vec<u64> = self.tiles.range(at..).map(|(&p, _)| p).collect();
        for &prefix in &moving {
            if matches!(self.tiles[&prefix].state, TileState::Live { .. }) {
                self.spill(prefix)?;
            }
        }
        let moved = self.tiles.split_off(&at);
        self.changed(InnerNodes::Update);
        other.changed(InnerNodes::Update);
        other.tiles.extend(moved);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::ot;
    use crate::scan::OutOfMap;
    use crate::tiles::TileSet;
    use crate::OccupancyTree;
    use std::convert::Infallible;

    /// The bundled sample's first scans (indoor lidar), and a scan of a
    /// dense ball around the first origin.
    fn scans() -> Vec<(Vec<Point3>, Point3)> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph");
        let g = crate::formats::graph::read_file(path).unwrap();
        let mut s: Vec<_> = g.nodes.iter().take(3).map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect();
        let o = s[0].1;
        let ball = (0..5000)
            .map(|i| {
                let (a, b) = (i as f32 * 0.37, i as f32 * 0.011);
                Point3::new(o.x + 1.5 * a.cos() * b.sin(), o.y + 1.5 * a.sin() * b.sin(), o.z + 1.5 * b.cos())
            })
            .collect();
        s.push((ball, o));
        s
    }

    fn estimate(scans: &[(Vec<Point3>, Point3)], depth: u8) -> TileWork {
        let mut work = TileWork::new(0.1, depth).unwrap();
        for (p, o) in scans {
            work.add_scan(p, *o, None);
        }
        work
    }

    fn ot_bytes(map: &impl crate::tree::PreorderSource) -> Vec<u8> {
        let mut out = Vec::new();
        ot::write_map(map, &mut out).unwrap();
        out
    }

    fn build(dir: &std::path::Path, memory: usize, depth: u8, scans: &[(Vec<Point3>, Point3)]) -> GroupedReport {
        let b = GroupedBuild {
            resolution: 0.1,
            sensor: SensorModel::default(),
            memory,
            dir: dir.to_path_buf(),
            record: None,
        };
        let opts = ScanOptions::default();
        let given = || scans.iter().map(|(p, o)| Ok::<_, Infallible>((p, *o)));
        b.build(&estimate(scans, depth), &opts, given, |_, _| {}).unwrap()
    }

    #[test]
    fn groups_split_or_not_give_the_single_tree() {
        let scans = scans();
        let mut single = OccupancyTree::new(0.1).unwrap();
        for (p, o) in &scans {
            single.insert_point_cloud(p, *o, &ScanOptions::default()).unwrap();
        }
        let want = ot::to_bytes(&single);
        for depth in [3, 7, 10] {
            // a byte: every group splits down to single tiles; a gigabyte: one group
            for memory in [1, 1 << 30] {
                let dir = tempfile::tempdir().unwrap();
                let report = build(dir.path(), memory, depth, &scans);
                let set = TileSet::open(dir.path()).unwrap();
                assert!(ot_bytes(&set) == want, "depth {depth}, memory {memory}");
                assert_eq!(report.manifest.tiles.len(), set.manifest().tiles.len());
                let groups = report.groups.len();
                if memory == 1 {
                    let tiles = report.manifest.tiles.len();
                    assert!(groups >= tiles.min(2), "depth {depth}: {groups} groups for {tiles} tiles");
                    assert!(report.groups.iter().all(|g| g.tiles <= 1), "depth {depth}: a group kept several tiles");
                } else {
                    assert_eq!(groups, 1, "depth {depth}");
                }
                let covered: Vec<_> = report.groups.iter().map(|g| g.prefixes.clone()).collect();
                assert_eq!(covered.first().unwrap().start, 0);
                assert_eq!(covered.last().unwrap().end, 1 << (3 * u32::from(depth)));
                assert!(covered.windows(2).all(|w| w[0].end == w[1].start));
            }
        }
    }

    #[test]
    fn a_read_error_and_a_refused_scan_stop_the_build_without_a_manifest() {
        let scans = scans();
        let dir = tempfile::tempdir().unwrap();
        let b = GroupedBuild {
            resolution: 0.1,
            sensor: SensorModel::default(),
            memory: 1,
            dir: dir.path().to_path_buf(),
            record: None,
        };
        let work = estimate(&scans, 7);
        let failing = || scans.iter().enumerate().map(|(i, (p, o))| if i == 2 { Err("bad scan") } else { Ok((p, *o)) });
        let e = b.build(&work, &ScanOptions::default(), failing, |_, _| {}).unwrap_err();
        assert!(matches!(e, GroupedError::Input("bad scan")), "{e}");
        assert!(!dir.path().join(MANIFEST_FILE).exists());

        let mut far = scans.clone();
        far[1].0.push(Point3::new(1e6, 0.0, 0.0));
        let opts = ScanOptions { out_of_map: OutOfMap::Error, ..Default::default() };
        let given = || far.iter().map(|(p, o)| Ok::<_, Infallible>((p, *o)));
        let e = b.build(&work, &opts, given, |_, _| {}).unwrap_err();
        assert!(matches!(e, GroupedError::Scan { index: 1, .. }), "{e}");
        assert!(!dir.path().join(MANIFEST_FILE).exists());
    }
}
