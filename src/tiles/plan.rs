//! Plans for building a tile set on several machines: an estimate of the
//! insertion work each tile costs ([`TileWork`]), and its split into
//! tasks that each own a contiguous range of tile Morton prefixes
//! ([`TilePlan`]), cut so that the tasks' estimated work is as even as it
//! can be.
//!
//! A contiguous range of Morton prefixes is a handful of aligned cubes, a
//! compact region: a task owning one casts only the rays that reach it
//! ([`super::TiledMap::set_task`]), instead of every ray of every scan. The
//! ranges always cover every prefix `0..8^D`, so each tile belongs to
//! exactly one task even where the estimate saw no work: the map is exact
//! whatever the estimate, which only decides how even the tasks are.
//!
//! The estimate is a coarse pass over the scans: per ray (origin to the
//! point, cut at the maximum range as insertion cuts it), a walk from tile
//! to tile adding to each tile the voxel steps the ray makes inside it
//! (the L1 length of its piece of the segment in voxels), and one to the
//! tile of its end voxel. Each step also counts [`UPDATE_COST`] steps for
//! the voxel update it may cause, scaled down near the sensor, where the
//! rays of a scan overlap and share their voxels: by `(r / s)^2` at a
//! distance `r` below the scan's spread `s` (the distance at which rays
//! spread evenly over the sphere are a voxel apart: `resolution /
//! sqrt(4π / points)`). On the full-size outdoor sequence at 0.05 m this
//! brought the two tasks from 12.2 s and 8.9 s to 10.3 s and 10.8 s. Large scans are sampled (every
//! [`SAMPLE_STRIDE`]th point, weighted by the stride), so a plan costs a
//! small part of a build, and is the same for the same input.
//!
//! The plan file is text (`formats/tiles.md`, "Plan file").

use super::error::TileError;
use super::id::{TileId, MAX_TILE_DEPTH};
use super::manifest::{clip, decimal, read_text_file, TaskPart, TaskTiles, MAX_LINE_BYTES, MAX_TASKS};
use crate::geometry::Point3;
use crate::key::{KeySpace, KEY_CENTER, TREE_DEPTH};
use crate::tree::TreeError;
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::ops::Range;

/// First line of a plan file, before the version number.
pub const PLAN_MAGIC: &str = "octolinear-tile-plan";
/// The plan file version this crate writes and reads.
pub const PLAN_VERSION: u32 = 1;
/// Largest plan file read: [`MAX_TASKS`] task lines and the header, each
/// at most [`MAX_LINE_BYTES`].
pub const MAX_PLAN_BYTES: u64 = (MAX_TASKS as u64 + 4) * (MAX_LINE_BYTES as u64 + 1);
/// Scans of more points than this are sampled by [`TileWork::add_scan`].
pub const SAMPLE_ABOVE: usize = 16_384;
/// One point in this many is walked in a sampled scan.
pub const SAMPLE_STRIDE: usize = 8;

/// A voxel update's cost in ray steps, fitted on the two-task split of
/// the full-size outdoor sequence at 0.05 m (the whole build's ratio of
/// applying to casting time per update and step, 4.6, cut as far past the
/// balance point as steps alone cut before it).
pub const UPDATE_COST: f64 = 1.5;

/// Estimated insertion work per tile, in ray steps: the scans' rays'
/// voxel steps and their updates (module doc), by tile Morton prefix.
#[derive(Clone, Debug)]
pub struct TileWork {
    keys: KeySpace,
    depth: u8,
    work: BTreeMap<u64, u64>,
    /// The voxel updates alone (the part of `work` they make, without
    /// [`UPDATE_COST`]), the measure of a tile's memory: summed over the
    /// scans, and the largest of one scan.
    updates: BTreeMap<u64, (u64, u64)>,
}

impl TileWork {
    /// An empty estimate for a map of `resolution` metres split at tile
    /// depth `depth` (1..=15).
    pub fn new(resolution: f64, depth: u8) -> Result<Self, TileError> {
        if !(1..=MAX_TILE_DEPTH).contains(&depth) {
            return Err(TileError::BadDepth(depth));
        }
        crate::key::check_resolution(resolution).map_err(|_| TreeError::BadResolution(resolution))?;
        Ok(TileWork { keys: KeySpace::new(resolution), depth, work: BTreeMap::new(), updates: BTreeMap::new() })
    }

    /// Adds one scan (world frame points, as
    /// [`super::TiledMap::insert_point_cloud`] takes them) taken from
    /// `origin`, rays cut at `max_range` metres as insertion cuts them.
    /// Points that cast no ray in insertion (not finite, no key in the
    /// map) add nothing.
    pub fn add_scan(&mut self, points: &[Point3], origin: Point3, max_range: Option<f64>) {
        if !origin.is_finite() {
            return;
        }
        let stride = if points.len() > SAMPLE_ABOVE { SAMPLE_STRIDE } else { 1 };
        let weight = stride as f64;
        let casts = self.keys.key(origin).is_ok();
        let spread = self.keys.resolution() / (4.0 * std::f64::consts::PI / points.len().max(1) as f64).sqrt();
        // per tile: work (ray steps and their updates) and voxel updates
        let mut scan: HashMap<u64, (f64, f64)> = HashMap::new();
        for &p in points.iter().step_by(stride) {
            if !p.is_finite() {
                continue;
            }
            let (_, end) = crate::ray::cut_to_range(p, origin, max_range.unwrap_or(-1.0));
            let Ok(end_key) = self.keys.key(end) else { continue };
            let tile = scan.entry(TileId::of_key(end_key, self.depth).prefix()).or_default();
            tile.0 += weight;
            tile.1 += weight;
            if casts {
                self.walk(origin, end, weight, spread, &mut scan);
            }
        }
        // per tile, sums in ray order: the same estimate on every run
        for (prefix, (steps, updates)) in scan {
            *self.work.entry(prefix).or_default() += steps.round() as u64;
            let (summed, largest) = self.updates.entry(prefix).or_default();
            *summed += updates.round() as u64;
            *largest = (*largest).max(updates.round() as u64);
        }
    }

    /// The tiles the segment from `a` to `b` crosses, each given its
    /// share of the segment's L1 length in voxels and of the updates along
    /// it, times `weight`, as (work, updates).
    fn walk(&self, a: Point3, b: Point3, weight: f64, spread: f64, out: &mut HashMap<u64, (f64, f64)>) {
        let length = a.distance(b);
        // the updates per step: rays overlap within `spread` of the origin
        let swept = |r: f64| if r <= spread { r * r * r / (3.0 * spread * spread) } else { spread / 3.0 + r - spread };
        // the share of the segment's steps from t0 to t1, and of its updates
        let cost = |t0: f64, t1: f64| {
            let (r0, r1) = (t0 * length, t1 * length);
            let updates = if r1 > r0 { (swept(r1) - swept(r0)) / length } else { 0.0 };
            (t1 - t0, updates)
        };
        let voxels_per_tile = f64::from(1u32 << (TREE_DEPTH - self.depth));
        let last_cell = (1i64 << self.depth) - 1;
        // tile coordinates: the tile's key bits, with the fraction inside
        let tile_coord = |x: f32| (f64::from(x) / self.keys.resolution() + f64::from(KEY_CENTER)) / voxels_per_tile;
        let (u0, u1) = ([a.x, a.y, a.z].map(tile_coord), [b.x, b.y, b.z].map(tile_coord));
        let cell = |u: f64| (u.floor() as i64).clamp(0, last_cell);
        let (mut c, end) = (u0.map(cell), u1.map(cell));
        let d: [f64; 3] = std::array::from_fn(|i| u1[i] - u0[i]);
        let steps = d.iter().map(|x| x.abs()).sum::<f64>() * voxels_per_tile * weight;
        let mut t_max = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        for i in 0..3 {
            if d[i] > 0.0 {
                t_max[i] = ((c[i] + 1) as f64 - u0[i]) / d[i];
            } else if d[i] < 0.0 {
                t_max[i] = (c[i] as f64 - u0[i]) / d[i];
            }
            if d[i] != 0.0 {
                t_delta[i] = 1.0 / d[i].abs();
            }
        }
        let crossings: i64 = (0..3).map(|i| (end[i] - c[i]).abs()).sum();
        let mut t = 0.0;
        for _ in 0..=crossings {
            let axis = (0..3).fold(0, |m, i| if t_max[i] < t_max[m] { i } else { m });
            let done = c == end || t_max[axis] >= 1.0;
            let t_next = if done { 1.0 } else { t_max[axis] };
            let xyz = c.map(|v| v.clamp(0, last_cell) as u32);
            let prefix = TileId::new(self.depth, xyz).expect("a clamped tile coordinate").prefix();
            let (share, updates) = cost(t, t_next);
            let tile = out.entry(prefix).or_default();
            tile.0 += (share + UPDATE_COST * updates) * steps;
            tile.1 += updates * steps;
            if done {
                return;
            }
            c[axis] += if d[axis] > 0.0 { 1 } else { -1 };
            t_max[axis] += t_delta[axis];
            t = t_next;
        }
    }

    /// The scan as a build with these options casts it: [`Self::add_scan`],
    /// or with `discretize` [`Self::add_discretized_scan`].
    pub fn add(&mut self, points: &[Point3], origin: Point3, max_range: Option<f64>, discretize: bool) {
        if discretize {
            self.add_discretized_scan(points, origin, max_range);
        } else {
            self.add_scan(points, origin, max_range);
        }
    }

    /// [`Self::add_scan`] for a build with `discretize`: one ray per end
    /// voxel, from the voxel's centre, as insertion casts them.
    pub fn add_discretized_scan(&mut self, points: &[Point3], origin: Point3, max_range: Option<f64>) {
        let mut seen = hashbrown::HashSet::new();
        let centres: Vec<Point3> = points
            .iter()
            .filter_map(|&p| self.keys.key(p).ok())
            .filter(|&k| seen.insert(k))
            .map(|k| self.keys.key_to_point(k))
            .collect();
        self.add_scan(&centres, origin, max_range);
    }

    /// Estimated work by tile prefix, tiles without work left out.
    pub fn tiles(&self) -> impl Iterator<Item = (u64, u64)> + '_ {
        self.work.iter().filter(|(_, &w)| w > 0).map(|(&p, &w)| (p, w))
    }

    /// Estimated voxel updates by tile prefix: the scans' updates summed
    /// (a voxel updated by several scans counts once for each), and the
    /// most of one scan; tiles without updates left out. Memory follows
    /// them, not the ray steps.
    pub fn updates(&self) -> impl Iterator<Item = (u64, u64, u64)> + '_ {
        self.updates.iter().filter(|(_, u)| u.0 > 0).map(|(&p, &(summed, largest))| (p, summed, largest))
    }

    /// The tile depth estimated for.
    pub fn depth(&self) -> u8 {
        self.depth
    }

    /// Splits the tile prefixes `0..8^D` into `tasks` contiguous ranges
    /// (1 to `8^D` of them) whose estimated work is as even as the tiles
    /// allow: each cut goes where the work before it is nearest its share,
    /// at the most aligned prefix between two tiles with work (so the
    /// ranges are few, large cubes).
    pub fn split(&self, tasks: u32) -> Result<TilePlan, TileError> {
        let prefixes = 1u64 << (3 * u32::from(self.depth));
        let most = prefixes.min(u64::from(MAX_TASKS));
        if tasks == 0 || u64::from(tasks) > most {
            return Err(TileError::Plan {
                line: 0,
                reason: format!(
                    "{tasks} tasks: expected 1 to {most} (the tiles at depth {}, at most {MAX_TASKS} tasks)",
                    self.depth
                ),
            });
        }
        let tiles: Vec<(u64, u64)> = self.tiles().collect();
        // before[j]: the work of the tiles before tile j
        let mut before = Vec::with_capacity(tiles.len() + 1);
        before.push(0u128);
        for &(_, w) in &tiles {
            before.push(before.last().copied().unwrap_or(0) + u128::from(w));
        }
        let total = before.last().copied().unwrap_or(0);
        let n = u128::from(tasks);
        let mut cuts = vec![0u64; tasks as usize + 1];
        cuts[tasks as usize] = prefixes;
        let mut first_tile = 0;
        for (k, cut) in cuts.iter_mut().enumerate().take(tasks as usize).skip(1) {
            let share = total * k as u128 / n;
            // the first tile of task k: nearest its share, after task k-1's
            let mut j = before.partition_point(|&b| b < share).max(first_tile);
            if j > first_tile && j <= tiles.len() && share - before[j - 1] < before[j].saturating_sub(share) {
                j -= 1;
            }
            first_tile = j.min(tiles.len());
            *cut = match first_tile {
                0 => 0,
                j if j == tiles.len() => prefixes,
                j => aligned_between(tiles[j - 1].0, tiles[j].0),
            };
        }
        // tasks beyond the tiles with work still get a prefix each
        for k in 1..tasks as usize {
            cuts[k] = cuts[k].max(cuts[k - 1] + 1);
        }
        for k in (1..tasks as usize).rev() {
            cuts[k] = cuts[k].min(cuts[k + 1] - 1);
        }
        let tasks = cuts
            .windows(2)
            .map(|w| {
                let inside = tiles.iter().filter(|(p, _)| (w[0]..w[1]).contains(p));
                PlannedTask { prefixes: w[0]..w[1], tiles: inside.clone().count(), work: inside.map(|t| t.1).sum() }
            })
            .collect();
        Ok(TilePlan { resolution: self.keys.resolution(), depth: self.depth, tasks })
    }
}

/// The prefix in `lo + 1..=hi` with the most trailing zero bits.
pub(super) fn aligned_between(lo: u64, hi: u64) -> u64 {
    debug_assert!(lo < hi);
    let top = 63 - (lo ^ hi).leading_zeros();
    hi & !((1u64 << top) - 1)
}

/// A split of a tile set's tiles into tasks, each a contiguous range of
/// tile Morton prefixes, together `0..8^depth` in order.
#[derive(Clone, Debug, PartialEq)]
pub struct TilePlan {
    /// Voxel edge length in metres of the map planned.
    pub resolution: f64,
    /// Tile depth (1..=15).
    pub depth: u8,
    /// The tasks, in prefix order: task `i` is `tasks[i]`.
    pub tasks: Vec<PlannedTask>,
}

/// One task of a [`TilePlan`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlannedTask {
    /// The tile prefixes it owns.
    pub prefixes: Range<u64>,
    /// Tiles in the range with estimated work.
    pub tiles: usize,
    /// Estimated work (in ray steps, [`TileWork`]) of those tiles.
    pub work: u64,
}

impl TilePlan {
    /// The part task `index` builds (`--task K/N --plan`), for
    /// [`super::TiledMap::set_task`].
    pub fn task(&self, index: u32) -> Result<TaskPart, TileError> {
        let count = u32::try_from(self.tasks.len()).unwrap_or(u32::MAX);
        let t = self.tasks.get(index as usize).ok_or_else(|| TileError::Plan {
            line: 0,
            reason: format!("task {index} does not exist: the plan has {count} tasks"),
        })?;
        Ok(TaskPart { index, count, tiles: TaskTiles::Prefixes { start: t.prefixes.start, end: t.prefixes.end } })
    }

    /// The plan's identity: the CRC-32 of its text ([`Self::to_text`]),
    /// recorded in the parts built from it
    /// ([`BuildRecord::plan`](super::BuildRecord::plan)).
    pub fn identity(&self) -> u32 {
        crc32fast::hash(self.to_text().as_bytes())
    }

    /// Reads the plan file at `path`: a regular file (a FIFO, device or
    /// directory is refused before it is opened for reading), of lines no
    /// longer than [`MAX_LINE_BYTES`] and at most [`MAX_PLAN_BYTES`] in
    /// all, parsed as [`Self::parse`] does. Errors name the file (and the
    /// line).
    pub fn read(path: &std::path::Path) -> Result<TilePlan, TileError> {
        let bytes = read_text_file(path, "a tile plan", MAX_PLAN_BYTES)?;
        let text = std::str::from_utf8(&bytes).map_err(|e| TileError::PlanFile {
            path: path.to_path_buf(),
            line: 0,
            reason: format!("not UTF-8 text ({e})"),
        })?;
        TilePlan::parse(text).map_err(|e| match e {
            TileError::Plan { line, reason } => TileError::PlanFile { path: path.to_path_buf(), line, reason },
            other => other,
        })
    }

    /// The plan file's text.
    pub fn to_text(&self) -> String {
        let mut s = format!("{PLAN_MAGIC} {PLAN_VERSION}\n");
        let _ = writeln!(s, "resolution {}", self.resolution);
        let _ = writeln!(s, "tile_depth {}", self.depth);
        let _ = writeln!(s, "tasks {}", self.tasks.len());
        for (i, t) in self.tasks.iter().enumerate() {
            let _ = writeln!(s, "task {i} {} {} {} {}", t.prefixes.start, t.prefixes.end, t.tiles, t.work);
        }
        s
    }

    /// Parses a plan file; every field is checked, and the ranges must
    /// cover `0..8^depth` in order. Errors name the line.
    pub fn parse(text: &str) -> Result<TilePlan, TileError> {
        let fault = |line: usize, reason: String| TileError::Plan { line, reason };
        let lines: Vec<&str> = text.lines().collect();
        if let Some((i, l)) = lines.iter().enumerate().find(|(_, l)| l.len() > MAX_LINE_BYTES) {
            return Err(fault(
                i + 1,
                format!("line of {} bytes, longer than any plan line ({MAX_LINE_BYTES})", l.len()),
            ));
        }
        let line = |i: usize| lines.get(i).copied().ok_or_else(|| fault(i + 1, "the plan ends early".into()));
        let field = |i: usize, name: &str| -> Result<&str, TileError> {
            let l = line(i)?;
            l.strip_prefix(name)
                .and_then(|v| v.strip_prefix(' '))
                .ok_or_else(|| fault(i + 1, format!("expected `{name} VALUE`, found `{}`", clip(l))))
        };
        let magic = line(0)?;
        let version = magic.strip_prefix(PLAN_MAGIC).and_then(|v| v.strip_prefix(' ')).and_then(decimal);
        match version {
            Some(v) if v == u64::from(PLAN_VERSION) => {}
            Some(v) => {
                return Err(fault(1, format!("plan version {v} is not supported (this reader reads {PLAN_VERSION})")))
            }
            None => {
                return Err(fault(
                    1,
                    format!("not a tile plan: expected `{PLAN_MAGIC} {PLAN_VERSION}`, found `{}`", clip(magic)),
                ))
            }
        }
        let res_text = field(1, "resolution")?;
        let resolution = res_text
            .parse::<f64>()
            .map_err(|_| fault(2, format!("resolution `{}`: expected a positive number of metres", clip(res_text))))?;
        crate::key::check_resolution(resolution).map_err(|e| fault(2, e.to_string()))?;
        let depth_text = field(2, "tile_depth")?;
        let depth = decimal(depth_text)
            .filter(|d| (1..=u64::from(MAX_TILE_DEPTH)).contains(d))
            .ok_or_else(|| fault(3, format!("tile depth `{}`: expected 1 to 15", clip(depth_text))))?
            as u8;
        let prefixes = 1u64 << (3 * u32::from(depth));
        let count_text = field(3, "tasks")?;
        let most = prefixes.min(u64::from(MAX_TASKS));
        let count = decimal(count_text).filter(|&n| n >= 1 && n <= most).ok_or_else(|| {
            fault(
                4,
                format!(
                    "task count `{}`: expected 1 to {most} at tile depth {depth} (at most {MAX_TASKS} tasks)",
                    clip(count_text)
                ),
            )
        })?;

        let mut tasks = Vec::new();
        let mut next_start = 0;
        for index in 0..count {
            let at = 4 + index as usize;
            let fields: Vec<&str> = field(at, "task")?.split(' ').collect();
            let numbers: Option<Vec<u64>> = fields.iter().map(|f| decimal(f)).collect();
            let Some([i, start, end, tiles, work]) = numbers.as_deref().and_then(|n| <[u64; 5]>::try_from(n).ok())
            else {
                return Err(fault(
                    at + 1,
                    format!("expected `task INDEX START END TILES WORK`, found `{}`", clip(lines[at])),
                ));
            };
            let reason = if i != index {
                format!("task {i} where task {index} comes")
            } else if start != next_start {
                format!("task {i} starts at prefix {start}, not where the previous ends ({next_start})")
            } else if end <= start || end > prefixes {
                format!("task {i}: prefixes {start}..{end} is not a non-empty range within 0..{prefixes}")
            } else if tiles > end - start {
                format!("task {i}: {tiles} tiles cannot lie in {} prefixes", end - start)
            } else if index + 1 == count && end != prefixes {
                format!("the last task ends at prefix {end}, not {prefixes}: tiles after it would belong to no task")
            } else {
                tasks.push(PlannedTask { prefixes: start..end, tiles: tiles as usize, work });
                next_start = end;
                continue;
            };
            return Err(fault(at + 1, reason));
        }
        if let Some(extra) = lines.get(4 + count as usize) {
            return Err(fault(
                5 + count as usize,
                format!("unexpected line `{}` after the {count} tasks", clip(extra)),
            ));
        }
        Ok(TilePlan { resolution, depth, tasks })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A work map with the given work per prefix.
    fn work_of(depth: u8, tiles: &[(u64, u64)]) -> TileWork {
        let mut w = TileWork::new(0.1, depth).unwrap();
        w.work.extend(tiles.iter().copied());
        w
    }

    fn assert_covers(plan: &TilePlan) {
        let prefixes = 1u64 << (3 * u32::from(plan.depth));
        assert_eq!(plan.tasks.first().unwrap().prefixes.start, 0);
        assert_eq!(plan.tasks.last().unwrap().prefixes.end, prefixes);
        for w in plan.tasks.windows(2) {
            assert_eq!(w[0].prefixes.end, w[1].prefixes.start);
        }
        assert!(plan.tasks.iter().all(|t| !t.prefixes.is_empty()));
    }

    #[test]
    fn the_split_covers_every_prefix_once() {
        let work = work_of(2, &[(5, 10), (6, 1), (40, 7)]);
        for tasks in [1, 2, 3, 4, 10, 64] {
            let plan = work.split(tasks).unwrap();
            assert_eq!(plan.tasks.len(), tasks as usize);
            assert_covers(&plan);
            assert_eq!(plan.tasks.iter().map(|t| t.work).sum::<u64>(), 18);
            assert_eq!(plan.tasks.iter().map(|t| t.tiles).sum::<usize>(), 3);
            for k in 0..tasks {
                let part = plan.task(k).unwrap();
                let owners = (0..64).filter(|&p| part.owns(TileId::from_prefix(2, p))).count() as u64;
                assert_eq!(owners, plan.tasks[k as usize].prefixes.end - plan.tasks[k as usize].prefixes.start);
            }
        }
        // an empty estimate still covers the space
        assert_covers(&work_of(3, &[]).split(5).unwrap());
        assert!(matches!(work.split(0), Err(TileError::Plan { .. })));
        assert!(matches!(work.split(65), Err(TileError::Plan { .. })));
        assert!(matches!(work.split(3).unwrap().task(3), Err(TileError::Plan { .. })));
    }

    /// A skewed map (a few heavy tiles among many light ones): no task
    /// gets more than its share plus the heaviest tile.
    #[test]
    fn the_split_is_balanced_on_a_skewed_map() {
        let mut tiles = Vec::new();
        let mut s = 9u64;
        for p in (0..4096).step_by(3) {
            s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            let w = if p % 97 == 0 { 50_000 + (s >> 50) } else { s >> 54 };
            tiles.push((p, w));
        }
        let work = work_of(4, &tiles);
        let total: u64 = tiles.iter().map(|t| t.1).sum();
        let heaviest = tiles.iter().map(|t| t.1).max().unwrap();
        for tasks in [2, 3, 7, 16] {
            let plan = work.split(tasks).unwrap();
            assert_covers(&plan);
            let most = plan.tasks.iter().map(|t| t.work).max().unwrap();
            assert!(most <= total / u64::from(tasks) + heaviest, "{tasks}: {most} of {total}");
            let least = plan.tasks.iter().map(|t| t.work).min().unwrap();
            assert!(least + heaviest >= total / u64::from(tasks), "{tasks}: {least} of {total}");
        }
    }

    #[test]
    fn cuts_fall_on_aligned_prefixes() {
        assert_eq!(aligned_between(5, 6), 6);
        assert_eq!(aligned_between(5, 13), 8);
        assert_eq!(aligned_between(0, 63), 32);
        assert_eq!(aligned_between(63, 64), 64);
    }

    #[test]
    fn work_follows_the_rays() {
        // a ray's work: its steps, and UPDATE_COST more per step beyond
        // the scan's spread (r^2/spread^2 of it within), plus its end
        // voxel; sums in floating point, rounded: within a unit
        let spread_of = |points: usize| 1.0 / (4.0 * std::f64::consts::PI / points as f64).sqrt();
        let near = |r: f64, spread: f64| r * r * r / (3.0 * spread * spread);
        let close = |got: Vec<(u64, u64)>, want: &[(u64, f64)]| {
            got.len() == want.len() && got.iter().zip(want).all(|(g, w)| g.0 == w.0 && (g.1 as f64 - w.1).abs() <= 1.0)
        };
        let mut work = TileWork::new(1.0, 4).unwrap();
        // tiles of 4096 voxels: a ray of 5000 m along +x from a voxel
        // centre crosses two tiles, 4095.5 m in the first
        let origin = Point3::new(0.5, 0.5, 0.5);
        work.add_scan(&[Point3::new(5000.5, 0.5, 0.5)], origin, None);
        let first = TileId::new(4, [8, 8, 8]).unwrap().prefix();
        let second = TileId::new(4, [9, 8, 8]).unwrap().prefix();
        let spread = spread_of(1);
        let in_first = 4095.5 + UPDATE_COST * (near(spread, spread) + 4095.5 - spread);
        let in_second = 904.5 * (1.0 + UPDATE_COST) + 1.0;
        let got: Vec<(u64, u64)> = work.tiles().collect();
        assert!(close(got.clone(), &[(first, in_first), (second, in_second)]), "{got:?}");
        // cut at 100 m: 100 steps and the end voxel, all in the first tile
        let mut cut = TileWork::new(1.0, 4).unwrap();
        cut.add_scan(&[Point3::new(5000.5, 0.5, 0.5), Point3::new(f32::NAN, 0.0, 0.0)], origin, Some(100.0));
        let spread = spread_of(2);
        let in_first = 100.0 + UPDATE_COST * (near(spread, spread) + 100.0 - spread) + 1.0;
        let got: Vec<(u64, u64)> = cut.tiles().collect();
        assert!(close(got.clone(), &[(first, in_first)]), "{got:?}");
        // a large scan is sampled, and weighted up; its rays, 10 m long,
        // lie within its spread (36 m)
        let many = vec![Point3::new(10.5, 0.5, 0.5); SAMPLE_ABOVE + 1];
        let mut sampled = TileWork::new(1.0, 4).unwrap();
        sampled.add_scan(&many, origin, None);
        let walked = (SAMPLE_ABOVE + 1).div_ceil(SAMPLE_STRIDE) * SAMPLE_STRIDE;
        let per_ray = 10.0 + UPDATE_COST * near(10.0, spread_of(SAMPLE_ABOVE + 1)) + 1.0;
        let got: Vec<(u64, u64)> = sampled.tiles().collect();
        assert!(close(got.clone(), &[(first, per_ray * walked as f64)]), "{got:?}");
    }

    #[test]
    fn a_plan_round_trips_as_text() {
        let plan = work_of(3, &[(5, 10), (100, 20), (300, 5)]).split(3).unwrap();
        let text = plan.to_text();
        assert!(text.starts_with("octolinear-tile-plan 1\nresolution 0.1\ntile_depth 3\ntasks 3\ntask 0 0 "));
        assert_eq!(TilePlan::parse(&text).unwrap(), plan);
    }

    /// Task counts are bounded ([`MAX_TASKS`]) before anything is
    /// allocated for them, in plans read and in splits asked for.
    #[test]
    fn task_counts_are_bounded() {
        let text = "octolinear-tile-plan 1\nresolution 0.1\ntile_depth 15\ntasks 4294967295\ntask 0 0 1 0 0\n";
        match TilePlan::parse(text) {
            Err(TileError::Plan { line: 4, reason }) => assert!(reason.contains("at most 65536 tasks"), "{reason}"),
            other => panic!("{other:?}"),
        }
        let work = work_of(8, &[(5, 10)]);
        assert!(matches!(work.split(MAX_TASKS + 1), Err(TileError::Plan { .. })));
        assert_eq!(work_of(6, &[(5, 10)]).split(MAX_TASKS / 2).unwrap().tasks.len(), MAX_TASKS as usize / 2);
    }

    /// A plan is read from a regular file of bounded lines: a device, a
    /// FIFO and an endless line are refused at once, naming the file.
    #[test]
    fn plans_are_read_from_regular_files_only() {
        use crate::tiles::manifest::tests::{chain, make_fifo, within_seconds};
        let dir = tempfile::tempdir().unwrap();
        let e = within_seconds(|| chain(&TilePlan::read(std::path::Path::new("/dev/zero")).unwrap_err()));
        assert!(e.contains("/dev/zero") && e.contains("not a regular file"), "{e}");
        let fifo = dir.path().join("map.plan");
        make_fifo(&fifo);
        let path = fifo.clone();
        let e = within_seconds(move || chain(&TilePlan::read(&path).unwrap_err()));
        assert!(e.contains("map.plan") && e.contains("a FIFO"), "{e}");
        let long = dir.path().join("long.plan");
        std::fs::write(&long, vec![b'7'; 1 << 20]).unwrap();
        assert!(chain(&TilePlan::read(&long).unwrap_err()).contains("longer than 256 bytes"));
        let plan = work_of(3, &[(5, 10), (100, 20)]).split(2).unwrap();
        let good = dir.path().join("good.plan");
        std::fs::write(&good, plan.to_text()).unwrap();
        assert_eq!(TilePlan::read(&good).unwrap(), plan);
        std::fs::write(&good, plan.to_text().replace("tasks 2", "tasks 3")).unwrap();
        match TilePlan::read(&good) {
            Err(e @ TileError::PlanFile { line: 7, .. }) => assert!(e.to_string().contains("good.plan: line 7")),
            other => panic!("{other:?}"),
        }
        // a plan's identity follows its text
        let other = work_of(3, &[(5, 10), (300, 20)]).split(2).unwrap();
        assert_ne!(plan.identity(), other.identity());
        assert_eq!(plan.identity(), TilePlan::parse(&plan.to_text()).unwrap().identity());
    }

    #[test]
    fn parse_errors_name_the_line() {
        let text = work_of(3, &[(5, 10), (100, 20)]).split(2).unwrap().to_text();
        let lines: Vec<&str> = text.lines().collect();
        let with = |at: usize, new: &str| {
            let mut l = lines.clone();
            l[at - 1] = new;
            match TilePlan::parse(&(l.join("\n") + "\n")) {
                Err(TileError::Plan { line, reason }) => (line, reason),
                other => panic!("{other:?}"),
            }
        };
        assert_eq!(with(1, "octolinear-tiles 1").0, 1);
        assert!(with(1, "octolinear-tile-plan 2").1.contains("version 2"));
        assert!(with(2, "resolution -0.1").1.contains("positive"));
        assert!(with(3, "tile_depth 16").1.contains("1 to 15"));
        assert!(with(4, "tasks 0").1.contains("1 to 512"));
        assert!(with(4, "tasks 3") == (7, "the plan ends early".into()));
        assert_eq!(with(4, "tasks 1").0, 5);
        assert!(with(5, "task 1 0 64 1 10").1.contains("task 1 where task 0"));
        assert!(with(5, "task 0 1 64 1 10").1.contains("starts at prefix 1"));
        assert!(with(5, "task 0 0 0 0 0").1.contains("non-empty"));
        assert!(with(5, "task 0 0 64 65 10").1.contains("65 tiles"));
        assert!(with(5, "task 0 0 64 1").1.contains("expected `task INDEX"));
        assert!(with(6, "task 1 64 500 1 20").1.contains("not 512"));
        let (line, reason) = match TilePlan::parse(&(text.clone() + "task 2 512 513 0 0\n")) {
            Err(TileError::Plan { line, reason }) => (line, reason),
            other => panic!("{other:?}"),
        };
        assert!(line == 7 && reason.contains("unexpected line"), "{line} {reason}");
        assert!(matches!(TilePlan::parse(""), Err(TileError::Plan { line: 1, .. })));
    }
}
