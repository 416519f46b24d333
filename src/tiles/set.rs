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
use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The lock file inside a tile set's directory ([`SetLock`]).
pub const LOCK_FILE: &str = ".lock";

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
            TopAnswer::Tile(i) => {
                let map = self.tile(i)?;
                let found = map.search(key, depth);
                // an answer read from a file truncated under it is no answer
                map.check_mapping().map_err(|e| {
                    TileError::io(self.dir.join(self.manifest.tiles[i].id.file_name()), std::io::Error::other(e))
                })?;
                Ok(found)
            }
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

/// An advisory lock on a tile set, held while a writer writes into it
/// and released when dropped (or when the process ends, however it ends).
/// A build of the whole set ([`Self::acquire`]) holds the set's lock file
/// [`LOCK_FILE`] exclusively; a task's build ([`Self::acquire_task`])
/// holds it shared, so that the tasks of a set run at once, and the
/// task's own lock file `.task-K-of-N.lock` exclusively. A second writer
/// that would write the same files fails at once with
/// [`TileError::Locked`]. The last holder removes the lock files on
/// release, and the set's directory when taking the lock created it and
/// nothing went into it (a build that failed before writing). Locks are
/// `flock`s (`File::try_lock`): on a network filesystem they hold only
/// where the filesystem passes them on.
#[derive(Debug)]
pub struct SetLock {
    /// The set's lock file, then the task's, with their paths; held while open.
    files: Vec<(PathBuf, File)>,
    /// The set's directory, when taking the lock created it.
    created: Option<PathBuf>,
}

impl Drop for SetLock {
    fn drop(&mut self) {
        for (path, file) in self.files.iter().rev() {
            // removed while held exclusively (a task's build upgrades its
            // shared hold on the set's file, which fails while other tasks
            // hold it): a writer that opened it meanwhile finds its path
            // gone once it has the lock, and opens the new one
            if file.try_lock().is_ok() {
                let _ = std::fs::remove_file(path);
            }
        }
        if let Some(dir) = &self.created {
            // only when empty
            let _ = std::fs::remove_dir(dir);
        }
    }
}

impl SetLock {
    /// Locks the tile set `dir` (created if needed) for a build of the
    /// whole set, or for [`combine_parts`].
    pub fn acquire(dir: &Path) -> Result<SetLock, TileError> {
        let created = prepare_set_dir(dir)?;
        let mut held = SetLock { files: Vec::new(), created: created.then(|| dir.to_path_buf()) };
        held.files.push(lock(dir, LOCK_FILE, true, "another build (or `tiles manifest`)")?);
        Ok(held)
    }

    /// Locks the tile set `dir` (created if needed) for the build of
    /// `task`'s part: beside the builds of other tasks, not beside a
    /// build of the whole set or of the same task.
    pub fn acquire_task(dir: &Path, task: TaskPart) -> Result<SetLock, TileError> {
        let created = prepare_set_dir(dir)?;
        let mut held = SetLock { files: Vec::new(), created: created.then(|| dir.to_path_buf()) };
        held.files.push(lock(dir, LOCK_FILE, false, "a build of the whole set (or `tiles manifest`)")?);
        let name = format!(".task-{}-of-{}.lock", task.index, task.count);
        let holder = format!("another build of task {} of {}", task.index, task.count);
        held.files.push(lock(dir, &name, true, &holder)?);
        Ok(held)
    }
}

/// Opens (creating it) and locks the lock file `name` in `dir`,
/// exclusively or shared, without waiting. A symbolic link of that name
/// is replaced by a file, never followed. A file its last holder removed
/// between the open and the lock is let go and the new one taken.
fn lock(dir: &Path, name: &str, exclusive: bool, holder: &str) -> Result<(PathBuf, File), TileError> {
    let path = dir.join(name);
    let io = |e| TileError::io(&path, e);
    for _ in 0..16 {
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_symlink()) {
            std::fs::remove_file(&path).map_err(io)?;
        }
        let mut options = OpenOptions::new();
        options.read(true).write(true).create(true).truncate(false);
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NOFOLLOW | libc::O_CLOEXEC);
        let file = options.open(&path).map_err(io)?;
        let locked = if exclusive { file.try_lock() } else { file.try_lock_shared() };
        match locked {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(TileError::Locked { dir: dir.to_path_buf(), lock: path, holder: holder.to_string() })
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io(e)),
        }
        if still_named(&file, &path) {
            return Ok((path, file));
        }
    }
    Err(io(std::io::Error::other("its lock file keeps being replaced")))
}

/// True when `path` still names the open `file`.
fn still_named(file: &File, path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (file.metadata(), std::fs::symlink_metadata(path)) {
            (Ok(a), Ok(b)) => (a.dev(), a.ino()) == (b.dev(), b.ino()),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (file, path);
        true
    }
}

/// Checks that `dir` may receive a tile set ([`super::check_set_dir`];
/// a path that exists as something else than a directory is
/// [`TileError::NotADirectory`]) and creates it if it does not exist;
/// true when it did.
fn prepare_set_dir(dir: &Path) -> Result<bool, TileError> {
    match std::fs::metadata(dir) {
        Ok(m) if !m.is_dir() => return Err(TileError::NotADirectory { dir: dir.to_path_buf() }),
        Ok(_) => {
            super::check_set_dir(dir)?;
            return Ok(false);
        }
        Err(_) => super::check_set_dir(dir)?,
    }
    create_set_dir(dir)?;
    Ok(true)
}

/// Creates the tile set's directory `dir` if it does not exist; a path
/// that exists as something else is [`TileError::NotADirectory`].
pub(crate) fn create_set_dir(dir: &Path) -> Result<(), TileError> {
    match std::fs::create_dir_all(dir) {
        Ok(()) => Ok(()),
        Err(e) => match std::fs::metadata(dir) {
            Ok(m) if !m.is_dir() => Err(TileError::NotADirectory { dir: dir.to_path_buf() }),
            _ => Err(TileError::io(dir, e)),
        },
    }
}

/// Removes the tile files in `dir` that `manifest` does not list (left by
/// an earlier build); other files are left alone. A link named like a
/// tile file is removed itself, never what it points to.
pub fn remove_unlisted_tiles(dir: &Path, manifest: &Manifest) -> Result<(), TileError> {
    let listed: std::collections::HashSet<String> = manifest.tiles.iter().map(|t| t.id.file_name()).collect();
    for item in std::fs::read_dir(dir).map_err(|e| TileError::io(dir, e))? {
        let item = item.map_err(|e| TileError::io(dir, e))?;
        let name = item.file_name();
        let Some(name) = name.to_str() else { continue };
        if super::TileId::from_file_name(name).is_some() && !listed.contains(name) {
            let path = item.path();
            // unlink: a link goes, its target stays
            std::fs::remove_file(&path).map_err(|e| TileError::io(&path, e))?;
        }
    }
    Ok(())
}

/// Bytes a node takes in the merged map's `.olm` (rank index, full
/// variant): a child mask, a log-odds value and an eighth of a directory
/// word; a stamped map's nodes 4 bytes more.
const OLM_NODE_BYTES: [f64; 2] = [5.5, 9.5];

/// Bytes of tile files beyond twice the merged map's that [`oversize`]
/// lets pass, so that small maps in a few tiles are not reported.
const OVERSIZE_SLACK: u64 = 256 << 10;

/// A tile set holding far more bytes than its map: [`oversize`]'s report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Oversize {
    /// Tiles in the set.
    pub tiles: usize,
    /// Depth of the tiles.
    pub depth: u8,
    /// Bytes of the tile files together.
    pub tile_bytes: u64,
    /// The merged map's `.olm`, estimated from its node count.
    pub merged_bytes: u64,
}

impl std::fmt::Display for Oversize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the {} tiles at depth {} hold {} bytes, {:.1}x the merged map's .olm (about {} bytes): \
             each tile file costs a few hundred bytes beyond its nodes, so small tiles make a set many times \
             its map; a smaller tile depth gives up to 8x fewer tiles per step",
            self.tiles,
            self.depth,
            self.tile_bytes,
            self.tile_bytes as f64 / self.merged_bytes.max(1) as f64,
            self.merged_bytes
        )
    }
}

/// When a whole set's tile files (`manifest`, `nodes` in the merged map)
/// hold more than twice the merged map's `.olm` bytes (estimated at 5.5
/// bytes a node, 9.5 for stamped maps) and over 256 KiB more, how much;
/// `None` for a set of sensible tiles. The bundled indoor sample, 131,161
/// nodes, holds 1.0x its `.olm` in tiles at depths 1 to 10, 1.4x at 13
/// (799 tiles), 3.2x at 14 (3,907) and 14.8x at 15 (22,853).
pub fn oversize(manifest: &Manifest, nodes: u64) -> Option<Oversize> {
    let per_node = OLM_NODE_BYTES[usize::from(manifest.node_kind() == crate::tree::NodeKind::Stamped)];
    let merged_bytes = (nodes as f64 * per_node) as u64 + crate::mapped::HEADER_LEN as u64;
    let tile_bytes: u64 = manifest.tiles.iter().map(|t| t.bytes).sum();
    (tile_bytes > merged_bytes.saturating_mul(2).saturating_add(OVERSIZE_SLACK)).then_some(Oversize {
        tiles: manifest.tiles.len(),
        depth: manifest.depth,
        tile_bytes,
        merged_bytes,
    })
}

/// Reads and parses a manifest or a task's part file.
pub fn read_manifest(path: &Path) -> Result<Manifest, TileError> {
    Manifest::read(path)
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
/// tile exactly once. Holds the set's [`SetLock`] meanwhile: a caller
/// must not hold it already.
pub fn combine_parts(dir: &Path) -> Result<Manifest, TileError> {
    if !dir.is_dir() {
        return Err(TileError::Parts { dir: dir.to_path_buf(), reason: "is not a tile set's directory".into() });
    }
    let _lock = SetLock::acquire(dir)?;
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
        let other = TaskPart::file_name(first.task.expect("a part"));
        if let Some(difference) = m.difference(first, &task.file_name(), &other) {
            return Err(parts_error(format!("{} was built otherwise than {other}: {difference}", path.display())));
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
