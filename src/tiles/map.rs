//! [`TiledMap`]: a map kept as one tree per tile, updated as the single
//! tree would be, with an optional memory budget (`budget.rs`).

use super::budget::{Budget, MemoryBudget};
use super::error::TileError;
use super::file::{write_bytes, write_tile};
use super::forget::Window;
use super::id::{code_shift, TileId, MAX_TILE_DEPTH};
use super::manifest::{BuildRecord, Manifest, TaskPart, TileEntry, MANIFEST_FILE};
use super::top::{root_of, tile_root_node, Top, TopAnswer};
use crate::geometry::Point3;
use crate::key::{Key, KeySpace};
use crate::mapped::MappedMap;
use crate::ray::{CastOptions, CastOutcome, RayKeys};
use crate::scan::{compute_update_in, ScanOptions, ScanReport, ScanUpdate};
use crate::sensor::SensorModel;
use crate::tree::{Clock, Found, InnerNodes, NodeKind, OccupancyTree, TreeError, TreeKind};
use rayon::prelude::*;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

/// A map split into the octree's subtrees at a fixed depth (tiles), each
/// held as its own tree with nodes only on its path from the root and
/// below. Scans are cast once for the whole map (or, for a task owning a
/// range of tiles, for those tiles) and each tile receives the updates
/// that fall into it, so the tiles together are the single tree
/// [`OccupancyTree`] builds from the same calls: [`Self::merge`] gives it
/// node for node (hence OctoMap's bytes), and the queries answer as it
/// does. The levels above the tiles are derived from the tiles' root
/// nodes when needed (see `top.rs`).
///
/// Plain and stamped trees only: colour trees blend colours in OctoMap's
/// hash order across a scan and re-expand pruned nodes in between, which
/// tiles cannot follow. Stamped trees need a clock that never runs back
/// (an inner node's stamp is the latest of its children's).
///
/// With a [`MemoryBudget`], tiles not used lately are written to a
/// directory and read back when a scan reaches them again: memory stays
/// near the budget plus the tiles one scan touches at a time, and the map
/// is the same.
#[derive(Debug)]
pub struct TiledMap {
    pub(super) keys: KeySpace,
    pub(super) sensor: SensorModel,
    pub(super) kind: NodeKind,
    pub(super) depth: u8,
    pub(super) clock: Clock,
    /// By Morton prefix, so in tile order.
    pub(super) tiles: BTreeMap<u64, Tile>,
    /// The derived levels, built at the first query after a change.
    top: OnceLock<Top>,
    /// Deferred updates left inner nodes stale.
    pub(super) stale: bool,
    /// Only this task's tiles are updated and kept.
    task: Option<TaskPart>,
    pub(super) budget: Option<Budget>,
    /// Counts the groups of tiles updated, for the least recently used.
    pub(super) uses: u64,
    /// What is forgotten after each scan (`forget.rs`).
    pub(super) window: Option<Window>,
    /// How the map is built, recorded in the manifest [`Self::flush`] writes.
    record: Option<BuildRecord>,
}

/// One tile's tree, in memory or spilled to the budget's directory.
#[derive(Debug)]
pub(super) struct Tile {
    pub(super) state: TileState,
    pub(super) last_use: u64,
}

/// Where a tile's tree is.
#[derive(Debug)]
pub(super) enum TileState {
    /// In memory; `saved` describes its spilled file when that file holds
    /// this very tree (read back and not changed since).
    Live { tree: Box<OccupancyTree>, bytes: usize, saved: Option<TileEntry> },
    /// In the budget's directory only.
    Spilled(TileEntry),
}

/// The updates of one scan that fall into one tile.
struct Work {
    prefix: u64,
    free: Range<usize>,
    occupied: Range<usize>,
}

/// Sizes of a tiled map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TiledStats {
    /// Tiles holding nodes.
    pub tiles: usize,
    /// Of those, tiles in memory.
    pub live_tiles: usize,
    /// Bytes the tiles in memory hold.
    pub live_bytes: usize,
    /// Nodes of the single tree ([`TiledMap::merge`]'s `size()`).
    pub nodes: u64,
}

impl TiledMap {
    /// An empty map of `kind` split at tile depth `depth` (1..=15), with
    /// voxels of `resolution` metres.
    pub fn new(resolution: f64, sensor: SensorModel, kind: NodeKind, depth: u8) -> Result<Self, TileError> {
        if !(1..=MAX_TILE_DEPTH).contains(&depth) {
            return Err(TileError::BadDepth(depth));
        }
        crate::key::check_resolution(resolution).map_err(|_| TreeError::BadResolution(resolution))?;
        if kind == NodeKind::Color {
            return Err(TileError::Unsupported(
                "colour trees cannot be tiled: their colours depend on OctoMap's update order across the whole scan",
            ));
        }
        Ok(TiledMap {
            keys: KeySpace::new(resolution),
            sensor,
            kind,
            depth,
            clock: Clock::System,
            tiles: BTreeMap::new(),
            top: OnceLock::new(),
            stale: false,
            task: None,
            budget: None,
            uses: 0,
            window: None,
            record: None,
        })
    }

    /// Keeps the tiles in memory within `budget` (see [`MemoryBudget`]);
    /// creates its directory. A map's budget is set once.
    pub fn set_budget(&mut self, budget: MemoryBudget) -> Result<(), TileError> {
        if self.budget.is_some() {
            return Err(TileError::Unsupported("a tiled map's memory budget is set once"));
        }
        super::set::create_set_dir(&budget.dir)?;
        let mut b = Budget::new(budget);
        for (&prefix, tile) in &self.tiles {
            if let TileState::Live { bytes, .. } = tile.state {
                b.count_live(tile.last_use, prefix, bytes);
            }
        }
        self.budget = Some(b);
        self.enforce_budget()
    }

    /// Updates and keeps only the tiles of `task`: one of several processes
    /// building parts of one tile set ([`Self::flush`] then writes the
    /// task's part of the manifest). A task owning a range of tile
    /// prefixes casts only the rays that can reach its tiles.
    pub fn set_task(&mut self, task: TaskPart) {
        self.task = Some(task);
    }

    /// Records how the map is built (the insertion options, the input,
    /// the plan) in the manifest or task part [`Self::flush`] writes, so
    /// that a set or part built otherwise is never taken for this one.
    pub fn set_build_record(&mut self, record: BuildRecord) {
        self.record = Some(record);
    }

    /// The Morton codes a scan's casting records: the task's tiles' when it
    /// owns a range of them, else every code.
    fn cast_codes(&self) -> Range<u64> {
        match self.task.and_then(TaskPart::prefixes) {
            Some(r) => {
                let shift = code_shift(self.depth);
                (r.start << shift)..(r.end << shift)
            }
            None => 0..u64::MAX,
        }
    }

    /// The clock stamped maps read when updating.
    pub fn set_clock(&mut self, clock: Clock) {
        self.clock = clock;
    }

    /// Depth of the tiles' roots.
    pub fn tile_depth(&self) -> u8 {
        self.depth
    }

    /// What the map's nodes carry besides occupancy.
    pub fn kind(&self) -> NodeKind {
        self.kind
    }

    /// Voxel edge length, metres.
    pub fn resolution(&self) -> f64 {
        self.keys.resolution()
    }

    /// The map's coordinate/key arithmetic.
    pub fn key_space(&self) -> &KeySpace {
        &self.keys
    }

    /// The sensor model updates use.
    pub fn sensor(&self) -> &SensorModel {
        &self.sensor
    }

    /// The key of the voxel containing `p`.
    pub fn key(&self, p: Point3) -> Result<Key, crate::KeyError> {
        self.keys.key(p)
    }

    /// True when `value` (log-odds) counts as occupied.
    pub fn is_occupied(&self, value: f32) -> bool {
        self.sensor.is_occupied(value)
    }

    /// The tiles holding nodes, in Morton order.
    pub fn tiles(&self) -> impl Iterator<Item = TileId> + '_ {
        self.tiles.keys().map(|&p| TileId::from_prefix(self.depth, p))
    }

    /// True when no tile holds a node.
    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    /// Integrates one scan as [`OccupancyTree::insert_point_cloud`] does:
    /// the scan's voxel sets are computed once for the whole map, then
    /// each tile's share is applied to its tree. An I/O error of a budget
    /// leaves the scan partly applied.
    pub fn insert_point_cloud(
        &mut self,
        points: &[Point3],
        origin: Point3,
        opts: &ScanOptions,
    ) -> Result<ScanReport, TileError> {
        self.check_inner(opts.inner)?;
        let (update, report) = compute_update_in(&self.keys, points, origin, opts, self.cast_codes())?;
        let report = match opts.threads {
            Some(1) => self.apply_update_on(&update, report, opts.inner, 1),
            None => self.apply_update_on(&update, report, opts.inner, rayon::current_num_threads()),
            Some(n) => pool(n)?.install(|| self.apply_update_on(&update, report, opts.inner, n)),
        }?;
        self.apply_window(origin)?;
        Ok(report)
    }

    /// Integrates scans in order, as [`Self::insert_point_cloud`] on each,
    /// calling `after_each` once a scan is in. With more than one thread
    /// the next scan is cast while one is applied. Stops at the first scan
    /// refused, with its position in `scans`.
    pub fn insert_point_clouds<I, P>(
        &mut self,
        scans: I,
        opts: &ScanOptions,
        mut after_each: impl FnMut(&mut Self, ScanReport) + Send,
    ) -> Result<(), (usize, TileError)>
    where
        I: IntoIterator<Item = (P, Point3)>,
        I::IntoIter: Send,
        P: AsRef<[Point3]> + Send,
    {
        self.check_inner(opts.inner).map_err(|e| (0, e))?;
        let mut scans = scans.into_iter().enumerate();
        if opts.threads == Some(1) {
            for (i, (points, origin)) in scans {
                let report = self.insert_point_cloud(points.as_ref(), origin, opts).map_err(|e| (i, e))?;
                after_each(self, report);
            }
            return Ok(());
        }
        let mut run = |map: &mut Self| -> Result<(), (usize, TileError)> {
            let keys = map.keys.clone();
            let cast_opts = ScanOptions { threads: None, ..*opts };
            let codes = map.cast_codes();
            let cast = |(points, origin): (P, Point3)| {
                compute_update_in(&keys, points.as_ref(), origin, &cast_opts, codes.clone())
            };
            let workers = rayon::current_num_threads();
            let Some((mut i, first)) = scans.next() else { return Ok(()) };
            let mut origin = first.1;
            let mut current = cast(first);
            loop {
                let next = scans.next();
                let (applied, cast_next) = rayon::join(
                    || -> Result<ScanReport, TileError> {
                        let (update, report) = current?;
                        let report = map.apply_update_on(&update, report, opts.inner, workers)?;
                        map.apply_window(origin)?;
                        Ok(report)
                    },
                    || next.map(|(j, scan)| (j, scan.1, cast(scan))),
                );
                after_each(map, applied.map_err(|e| (i, e))?);
                match cast_next {
                    Some((j, o, c)) => (i, origin, current) = (j, o, c),
                    None => return Ok(()),
                }
            }
        };
        match opts.threads {
            Some(n) => pool(n).map_err(|e| (0, e))?.install(|| run(self)),
            None => run(self),
        }
    }

    /// OctoMap's `insertPointCloudRays` ("simple" mode), as
    /// [`OccupancyTree::insert_point_cloud_rays`]: ray by ray, each voxel
    /// updated in its tile as it comes.
    pub fn insert_point_cloud_rays(
        &mut self,
        points: &[Point3],
        origin: Point3,
        inner: InnerNodes,
    ) -> Result<ScanReport, TileError> {
        self.check_inner(inner)?;
        let mut report = ScanReport { points: points.len(), ..Default::default() };
        for &p in points {
            if !p.is_finite() {
                report.non_finite += 1;
                continue;
            }
            let Ok(ray) = RayKeys::new(&self.keys, origin, p) else {
                continue;
            };
            for k in ray {
                self.update_key(k, false, inner)?;
                report.free_updates += 1;
            }
            if let Ok(k) = self.keys.key(p) {
                self.update_key(k, true, inner)?;
                report.occupied_updates += 1;
            }
        }
        // once per scan: the rays of a scan cross the same tiles again and again
        self.enforce_budget()?;
        self.apply_window(origin)?;
        Ok(report)
    }

    /// Integrates a hit (`occupied`) or a miss at `key` in its tile, as
    /// [`OccupancyTree::update_occupancy`] does in the single tree.
    pub fn update_key(&mut self, key: Key, occupied: bool, inner: InnerNodes) -> Result<(), TileError> {
        self.check_inner(inner)?;
        let id = TileId::of_key(key, self.depth);
        if self.task.is_some_and(|t| !t.owns(id)) {
            return Ok(());
        }
        self.changed(inner);
        self.uses += 1;
        let (mut tree, _) = self.take_tree(id.prefix())?;
        tree.set_clock(self.clock);
        tree.update_occupancy(key, occupied, inner);
        self.put_tree(id.prefix(), tree, None);
        Ok(())
    }

    /// Applies a scan's update (from [`OccupancyTree::compute_update`]), each tile's share
    /// to its tree; completes `report` with the update counts.
    pub fn apply_update(
        &mut self,
        update: &ScanUpdate,
        report: ScanReport,
        inner: InnerNodes,
    ) -> Result<ScanReport, TileError> {
        self.check_inner(inner)?;
        self.apply_update_on(update, report, inner, 1)
    }

    /// Refuses what tiles cannot do exactly: deferred updates of stamped
    /// trees (updating the inner nodes afterwards stamps them all with
    /// that time, which the derived levels do not know).
    fn check_inner(&self, inner: InnerNodes) -> Result<(), TileError> {
        if inner == InnerNodes::Defer && self.kind == NodeKind::Stamped {
            return Err(TileError::Unsupported("deferred (lazy) updates of stamped maps cannot be tiled"));
        }
        Ok(())
    }

    /// Forgets what a change makes stale.
    pub(super) fn changed(&mut self, inner: InnerNodes) {
        self.top = OnceLock::new();
        self.stale |= inner == InnerNodes::Defer;
    }

    /// [`Self::apply_update`] with the tiles shared by `workers` threads of
    /// the current rayon pool.
    fn apply_update_on(
        &mut self,
        update: &ScanUpdate,
        report: ScanReport,
        inner: InnerNodes,
        workers: usize,
    ) -> Result<ScanReport, TileError> {
        let work = self.route(&update.free, &update.occupied);
        self.changed(inner);
        // as the single tree, which reads the clock once per batch
        let stamped = self.kind == NodeKind::Stamped;
        let now = if stamped { (self.clock.now(), self.clock.now()) } else { (0, 0) };
        let (miss, hit) = (self.sensor.miss, self.sensor.hit);
        let apply = |tree: &mut OccupancyTree, w: &Work, workers: usize| {
            tree.set_clock(Clock::Fixed(now.0));
            tree.update_batch_shared(&update.free[w.free.clone()], miss, inner, workers);
            tree.set_clock(Clock::Fixed(now.1));
            tree.update_batch_shared(&update.occupied[w.occupied.clone()], hit, inner, workers);
        };
        // with a budget, a few tiles at a time, so that the ones done can
        // be written out before the next are read
        let group = if self.budget.is_some() { workers.max(1) } else { work.len().max(1) };
        for chunk in work.chunks(group) {
            self.uses += 1;
            let mut trees = Vec::with_capacity(chunk.len());
            for w in chunk {
                match self.take_tree(w.prefix) {
                    Ok(t) => trees.push(t),
                    Err(e) => {
                        for (w, (tree, saved)) in chunk.iter().zip(trees) {
                            self.put_tree(w.prefix, tree, saved);
                        }
                        return Err(e);
                    }
                }
            }
            if workers > 1 && trees.len() > 1 {
                trees.par_iter_mut().zip(chunk).for_each(|((tree, _), w)| apply(tree, w, 1));
            } else {
                for ((tree, _), w) in trees.iter_mut().zip(chunk) {
                    apply(tree, w, workers);
                }
            }
            for (w, (tree, _)) in chunk.iter().zip(trees) {
                self.put_tree(w.prefix, tree, None);
            }
            self.enforce_budget()?;
        }
        Ok(ScanReport { free_updates: update.free.len(), occupied_updates: update.occupied.len(), ..report })
    }

    /// The tiles' shares of a scan's sorted lists, in tile order, less the
    /// tiles of other tasks.
    fn route(&self, free: &[u64], occupied: &[u64]) -> Vec<Work> {
        let shift = code_shift(self.depth);
        let runs = |codes: &[u64]| {
            let mut out = Vec::new();
            let mut start = 0;
            while start < codes.len() {
                let prefix = codes[start] >> shift;
                let end = start + codes[start..].partition_point(|&c| c >> shift == prefix);
                out.push((prefix, start..end));
                start = end;
            }
            out
        };
        let (free, occupied) = (runs(free), runs(occupied));
        let (mut f, mut o) = (free.into_iter().peekable(), occupied.into_iter().peekable());
        let mut work = Vec::new();
        loop {
            let prefix = match (f.peek(), o.peek()) {
                (Some(a), Some(b)) => a.0.min(b.0),
                (Some(a), None) => a.0,
                (None, Some(b)) => b.0,
                (None, None) => break,
            };
            let take = |it: &mut std::iter::Peekable<std::vec::IntoIter<(u64, Range<usize>)>>| {
                it.next_if(|r| r.0 == prefix).map_or(0..0, |r| r.1)
            };
            let (fr, or) = (take(&mut f), take(&mut o));
            if self.task.is_none_or(|t| t.owns(TileId::from_prefix(self.depth, prefix))) {
                work.push(Work { prefix, free: fr, occupied: or });
            }
        }
        work
    }

    /// A new, empty tile tree.
    pub(super) fn new_tile_tree(&self) -> OccupancyTree {
        let mut t = OccupancyTree::with_kind(self.keys.resolution(), self.sensor, self.kind)
            .expect("the resolution was checked");
        t.set_clock(self.clock);
        t
    }

    /// Recomputes every inner node as the maximum of its children
    /// (`updateInnerOccupancy`), after deferred updates.
    pub fn update_inner_occupancy(&mut self) -> Result<(), TileError> {
        let prefixes: Vec<u64> = self.tiles.keys().copied().collect();
        for prefix in prefixes {
            self.uses += 1;
            let (mut tree, _) = self.take_tree(prefix)?;
            tree.update_inner_occupancy();
            self.put_tree(prefix, tree, None);
            self.enforce_budget()?;
        }
        self.stale = false;
        self.top = OnceLock::new();
        Ok(())
    }

    /// The derived levels above the tiles.
    pub(super) fn top(&self) -> &Top {
        self.top.get_or_init(|| {
            let roots = self.tiles.iter().map(|(&prefix, tile)| {
                let root = match &tile.state {
                    TileState::Live { tree, .. } => {
                        let root = tree.root().expect("a tile tree holds its path");
                        root_of(tile_root_node(root, TileId::from_prefix(self.depth, prefix)).expect("a tile's shape"))
                    }
                    TileState::Spilled(entry) => entry.root,
                };
                (prefix, root)
            });
            Top::build(self.depth, self.kind, roots)
        })
    }

    /// OctoMap's `search(key, depth)` (0 means 16) on the single tree.
    /// Fails only when a spilled tile's file cannot be read.
    pub fn search(&self, key: Key, depth: u8) -> Result<Option<Found>, TileError> {
        self.search_cached(key, depth, &RefCell::new(None))
    }

    /// [`Self::search`] reusing the last spilled tile mapped in `cache`.
    fn search_cached(
        &self,
        key: Key,
        depth: u8,
        cache: &RefCell<Option<(u64, MappedMap<memmap2::Mmap>)>>,
    ) -> Result<Option<Found>, TileError> {
        match self.top().search(key, depth) {
            TopAnswer::Found(f) => Ok(Some(f)),
            TopAnswer::Unknown => Ok(None),
            TopAnswer::Tile(_) => {
                let prefix = TileId::of_key(key, self.depth).prefix();
                match &self.tiles[&prefix].state {
                    TileState::Live { tree, .. } => Ok(tree.search(key, depth)),
                    TileState::Spilled(entry) => {
                        let mut cache = cache.borrow_mut();
                        if cache.as_ref().is_none_or(|(p, _)| *p != prefix) {
                            *cache = Some((prefix, self.budget_ref()?.open(entry)?));
                        }
                        Ok(cache.as_ref().expect("just filled").1.search(key, depth))
                    }
                }
            }
        }
    }

    /// [`Self::search`] at the voxel containing `p`.
    pub fn search_point(&self, p: Point3, depth: u8) -> Result<Option<Found>, TileError> {
        self.search(self.keys.key(p)?, depth)
    }

    /// OctoMap's `castRay` on the single tree.
    pub fn cast_ray(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Result<CastOutcome, TileError> {
        let cache = RefCell::new(None);
        super::query::cast_ray(
            &self.keys,
            &self.sensor,
            |k, d| self.search_cached(k, d, &cache),
            origin,
            direction,
            opts,
        )
    }

    /// Sizes: tiles, memory, and the single tree's node count.
    pub fn stats(&self) -> TiledStats {
        let tiles: Vec<&Tile> = self.tiles.values().collect();
        let nodes = self.top().node_count(|i| {
            let above = u64::from(self.depth);
            match &tiles[i].state {
                TileState::Live { tree, .. } => tree.size() as u64 - above,
                TileState::Spilled(entry) => entry.nodes - above,
            }
        });
        let live = tiles.iter().filter(|t| matches!(t.state, TileState::Live { .. })).count();
        let live_bytes = tiles
            .iter()
            .map(|t| match &t.state {
                TileState::Live { bytes, .. } => *bytes,
                TileState::Spilled(_) => 0,
            })
            .sum();
        TiledStats { tiles: self.tiles.len(), live_tiles: live, live_bytes, nodes }
    }

    /// Writes the map as a tile set in `dir` (created if needed): each
    /// tile's file atomically, then, once the filesystem has them on disk,
    /// the manifest (or, for a task, its part file), atomically and
    /// synced. Files of tiles the map does not hold are left alone.
    /// Returns the manifest written.
    pub fn flush(&mut self, dir: &Path) -> Result<Manifest, TileError> {
        let entries = self.write_tiles(dir)?;
        let manifest = Manifest {
            resolution: self.keys.resolution(),
            depth: self.depth,
            kind: TreeKind::of(self.kind),
            sensor: self.sensor,
            task: self.task,
            build: self.record.clone(),
            tiles: entries,
        };
        let name = self.task.map_or_else(|| MANIFEST_FILE.to_string(), TaskPart::file_name);
        manifest.write(&dir.join(name))?;
        Ok(manifest)
    }

    /// Writes each tile's file into `dir` (created if needed) atomically,
    /// then waits for the filesystem to have them on disk; returns their
    /// descriptions in tile order.
    pub(super) fn write_tiles(&self, dir: &Path) -> Result<Vec<TileEntry>, TileError> {
        if self.stale {
            return Err(TileError::StaleInnerNodes);
        }
        super::set::create_set_dir(dir)?;
        let spill_dir_is_dir = self.budget.as_ref().is_some_and(|b| b.is_dir(dir));
        let mut entries = Vec::with_capacity(self.tiles.len());
        for (&prefix, tile) in &self.tiles {
            let id = TileId::from_prefix(self.depth, prefix);
            let path = dir.join(id.file_name());
            let entry = match &tile.state {
                TileState::Live { saved: Some(entry), .. } | TileState::Spilled(entry) if spill_dir_is_dir => *entry,
                TileState::Live { tree, .. } => write_tile(tree, id, &path)?,
                TileState::Spilled(entry) => {
                    // checked against what was spilled before it is copied
                    let spilled = self.budget_ref()?.open(entry)?;
                    write_bytes(&path, spilled.bytes())?;
                    *entry
                }
            };
            entries.push(entry);
        }
        // every tile on disk before a manifest lists them
        crate::formats::atomic::sync_filesystem(dir).map_err(|e| TileError::io(dir, e))?;
        Ok(entries)
    }
}

/// A rayon pool of `n` threads.
fn pool(n: usize) -> Result<rayon::ThreadPool, TileError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|_| TileError::Scan(crate::ScanError::ThreadPool("could not start threads")))
}
