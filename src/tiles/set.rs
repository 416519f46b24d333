//! [`TileSet`]: a tile set on disk (`NAME.tiles/`: the manifest and one
//! `.olm` file per tile) opened for queries, verification and merging.
//! Opening reads the manifest alone; a tile's file is mapped the first
//! time a query reaches it, so a query touches only its tiles.

use super::error::TileError;
use super::file::{check_tile, open_tile, TileCheck};
use super::manifest::{Manifest, TaskPart, MANIFEST_FILE};
use super::top::{Top, TopAnswer};
use crate::geometry::Point3;
use crate::key::{Key, KeySpace};
use crate::mapped::MappedMap;
use crate::ray::{CastOptions, CastOutcome};
use crate::sensor::SensorModel;
use crate::tree::Found;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A tile set opened from its directory.
pub struct TileSet {
    dir: PathBuf,
    manifest: Manifest,
    keys: KeySpace,
    top: Top,
    check: TileCheck,
    /// Each tile's mapped file, once a query reached it.
    maps: Vec<OnceLock<MappedMap<memmap2::Mmap>>>,
}

/// What [`TileSet::verify`] checked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileSetReport {
    /// Tiles checked.
    pub tiles: usize,
    /// Bytes of tile files read.
    pub bytes: u64,
    /// Nodes of the single tree the set holds.
    pub nodes: u64,
}

impl TileSet {
    /// Opens the tile set in `dir`: reads and checks its manifest. Tiles are
    /// mapped when queries reach them, each checked as [`TileCheck::Full`]
    /// says unless [`Self::set_check`] says otherwise.
    pub fn open(dir: &Path) -> Result<TileSet, TileError> {
        let path = dir.join(MANIFEST_FILE);
        let manifest = read_manifest(&path)?;
        if manifest.task.is_some() {
            return Err(TileError::Manifest {
                path,
                line: 2,
                reason: "a task's part, not a whole set's manifest".into(),
            });
        }
        let top =
            Top::build(manifest.depth, manifest.node_kind(), manifest.tiles.iter().map(|t| (t.id.prefix(), t.root)));
        let maps = (0..manifest.tiles.len()).map(|_| OnceLock::new()).collect();
        Ok(TileSet {
            dir: dir.to_path_buf(),
            keys: KeySpace::new(manifest.resolution),
            manifest,
            top,
            check: TileCheck::Full,
            maps,
        })
    }

    /// How much of each tile file is checked when it is first mapped.
    pub fn set_check(&mut self, check: TileCheck) {
        self.check = check;
    }

    /// The manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The set's directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The map's coordinate/key arithmetic.
    pub fn key_space(&self) -> &KeySpace {
        &self.keys
    }

    /// The sensor model of the map.
    pub fn sensor(&self) -> &SensorModel {
        &self.manifest.sensor
    }

    /// True when `value` (log-odds) counts as occupied.
    pub fn is_occupied(&self, value: f32) -> bool {
        self.manifest.sensor.is_occupied(value)
    }

    /// Tiles whose files have been mapped so far.
    pub fn mapped_tiles(&self) -> usize {
        self.maps.iter().filter(|m| m.get().is_some()).count()
    }

    /// Nodes of the single tree the set holds (from the manifest).
    pub fn node_count(&self) -> u64 {
        let above = u64::from(self.manifest.depth);
        self.top.node_count(|i| self.manifest.tiles[i].nodes - above)
    }

    /// Tile `i`'s mapped file, mapped and checked now if not yet.
    fn tile(&self, i: usize) -> Result<&MappedMap<memmap2::Mmap>, TileError> {
        if let Some(m) = self.maps[i].get() {
            return Ok(m);
        }
        let entry = &self.manifest.tiles[i];
        let map = open_tile(&self.dir, entry)?;
        check_tile(&map, entry, &self.manifest, self.check)
            .map_err(|reason| TileError::damaged(entry.id, self.dir.join(entry.id.file_name()), reason))?;
        // another thread may have mapped it meanwhile: either map will do
        let _ = self.maps[i].set(map);
        Ok(self.maps[i].get().expect("just set"))
    }

    /// OctoMap's `search(key, depth)` (0 means 16) on the single tree.
    pub fn search(&self, key: Key, depth: u8) -> Result<Option<Found>, TileError> {
        match self.top.search(key, depth) {
            TopAnswer::Found(f) => Ok(Some(f)),
            TopAnswer::Unknown => Ok(None),
            TopAnswer::Tile(i) => Ok(self.tile(i)?.search(key, depth)),
        }
    }

    /// [`Self::search`] at the voxel containing `p`.
    pub fn search_point(&self, p: Point3, depth: u8) -> Result<Option<Found>, TileError> {
        self.search(self.keys.key(p)?, depth)
    }

    /// OctoMap's `castRay` on the single tree; maps the tiles the ray reaches.
    pub fn cast_ray(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Result<CastOutcome, TileError> {
        super::query::cast_ray(&self.keys, self.sensor(), |k, d| self.search(k, d), origin, direction, opts)
    }

    /// Checks every tile fully (length, CRC-32, `.olm` checksums and
    /// structure, root node against the manifest), whatever
    /// [`Self::set_check`] says; the first fault is the error.
    pub fn verify(&self) -> Result<TileSetReport, TileError> {
        let bytes = Self::verify_tiles(&self.dir, &self.manifest)?;
        Ok(TileSetReport { tiles: self.manifest.tiles.len(), bytes, nodes: self.node_count() })
    }

    /// Checks every tile `manifest` lists (a whole set's or a task's part)
    /// fully against its file in `dir`, as [`Self::verify`] does, and
    /// returns the bytes read: how a build in parts that was interrupted
    /// knows which tasks' tiles it can keep.
    pub fn verify_tiles(dir: &Path, manifest: &Manifest) -> Result<u64, TileError> {
        let mut bytes = 0;
        for entry in &manifest.tiles {
            let map = open_tile(dir, entry)?;
            check_tile(&map, entry, manifest, TileCheck::Full)
                .map_err(|reason| TileError::damaged(entry.id, dir.join(entry.id.file_name()), reason))?;
            bytes += entry.bytes;
        }
        Ok(bytes)
    }

    /// The derived levels above the tiles.
    pub(super) fn top(&self) -> &Top {
        &self.top
    }
}

/// Reads and parses a manifest or a task's part file.
pub fn read_manifest(path: &Path) -> Result<Manifest, TileError> {
    let bytes = std::fs::read(path).map_err(|e| TileError::io(path, e))?;
    Manifest::parse(&bytes).map_err(|e| TileError::Manifest {
        path: path.to_path_buf(),
        line: e.line,
        reason: e.reason,
    })
}

/// Checks that the parts share the tiles one way: all by the hash split,
/// or by prefix ranges that cover the `8^depth` tile prefixes exactly once
/// (no gap, no overlap), so that every tile of the map was built.
fn check_ranges(parts: &[(PathBuf, Manifest)], depth: u8) -> Result<(), String> {
    let name = |m: &Manifest| m.task.map(TaskPart::file_name).unwrap_or_default();
    let mut ranges: Vec<(std::ops::Range<u64>, String)> = Vec::new();
    let mut hashed = None;
    for (_, m) in parts {
        match m.task.and_then(TaskPart::prefixes) {
            Some(r) => ranges.push((r, name(m))),
            None => hashed = Some(name(m)),
        }
    }
    let Some((_, ranged)) = ranges.first() else { return Ok(()) };
    if let Some(h) = hashed {
        return Err(format!("{h} shares the tiles by hash, {ranged} by a prefix range (parts of different plans)"));
    }
    ranges.sort_by_key(|(r, _)| (r.start, r.end));
    let tiles = 1u64 << (3 * u32::from(depth));
    let mut covered = (0, String::from("the start of the prefixes"));
    for (r, part) in ranges {
        match r.start.cmp(&covered.0) {
            std::cmp::Ordering::Greater => {
                return Err(format!(
                    "no part holds the tile prefixes {}..{} (a gap between {} and {part})",
                    covered.0, r.start, covered.1
                ))
            }
            std::cmp::Ordering::Less => {
                return Err(format!(
                    "{part} (prefixes {}..{}) overlaps {} (up to {})",
                    r.start, r.end, covered.1, covered.0
                ))
            }
            std::cmp::Ordering::Equal => covered = (r.end, part),
        }
    }
    if covered.0 != tiles {
        return Err(format!("no part holds the tile prefixes {}..{tiles} (after {})", covered.0, covered.1));
    }
    Ok(())
}

/// Combines the task parts in `dir` (`task-K-of-N.manifest`, written by
/// [`super::TiledMap::flush`] of each task) into the set's manifest, written
/// atomically; the parts are then removed. Every part of one count must be
/// there, with the same parameters, and prefix ranges must cover every
/// tile exactly once.
pub fn combine_parts(dir: &Path) -> Result<Manifest, TileError> {
    let parts_error = |reason: String| TileError::Parts { dir: dir.to_path_buf(), reason };
    let mut parts = Vec::new();
    let listing = std::fs::read_dir(dir).map_err(|e| TileError::io(dir, e))?;
    for item in listing {
        let item = item.map_err(|e| TileError::io(dir, e))?;
        let name = item.file_name();
        let Some(name) = name.to_str() else { continue };
        if name.starts_with("task-") && name.ends_with(".manifest") {
            let path = item.path();
            let m = read_manifest(&path)?;
            let task = m.task.ok_or_else(|| parts_error(format!("{name} is not a task's part")))?;
            if name != task.file_name() {
                return Err(parts_error(format!("{name} holds the part of task {} of {}", task.index, task.count)));
            }
            parts.push((path, m));
        }
    }
    let Some((_, first)) = parts.first() else {
        return Err(parts_error("holds no task parts (task-K-of-N.manifest)".into()));
    };
    let count = first.task.map_or(0, |t| t.count);
    let mut seen = vec![false; count as usize];
    for (path, m) in &parts {
        let task = m.task.expect("checked above");
        if task.count != count {
            return Err(parts_error(format!(
                "{} is a part of {} tasks, another of {count}",
                path.display(),
                task.count
            )));
        }
        let parameters = |m: &Manifest| Manifest { task: None, tiles: Vec::new(), ..m.clone() };
        if parameters(m) != parameters(first) {
            let other = TaskPart::file_name(first.task.expect("a part"));
            return Err(parts_error(format!("{} was built with other parameters than {other}", path.display())));
        }
        seen[task.index as usize] = true;
    }
    if let Some(missing) = seen.iter().position(|s| !s) {
        return Err(parts_error(format!("the part of task {missing} of {count} is missing")));
    }
    check_ranges(&parts, first.depth).map_err(parts_error)?;
    let mut tiles: Vec<_> = parts.iter().flat_map(|(_, m)| m.tiles.iter().copied()).collect();
    tiles.sort_by_key(|t| t.id.prefix());
    let manifest = Manifest { task: None, tiles, ..first.clone() };
    manifest.write(&dir.join(MANIFEST_FILE))?;
    for (path, _) in &parts {
        std::fs::remove_file(path).map_err(|e| TileError::io(path, e))?;
    }
    Ok(manifest)
}
