//! The manifest of a tile set: a versioned text file naming the map's
//! parameters (float fields as their bit patterns) and every tile with its
//! file's length, CRC-32, node count and root node. The byte-level format
//! is `formats/tiles.md`; this parser is strict (one spelling per value)
//! and reports the line of the first fault. Since version 2 a manifest
//! also records how its tiles were built ([`BuildRecord`]: the insertion
//! options, the input, the plan), so that parts and sets built otherwise
//! are told apart.
//!
//! Reading is bounded: a manifest is read from a regular file only (never
//! a FIFO or a device), line by line, each line at most
//! [`MAX_LINE_BYTES`]; task counts are at most [`MAX_TASKS`].

use super::error::TileError;
use super::id::{TileId, MAX_TILE_DEPTH};
use super::top::TileRoot;
use crate::geometry::Point3;
use crate::mapped::HEADER_LEN;
use crate::scan::{OutOfMap, ScanOptions};
use crate::sensor::SensorModel;
use crate::tree::{InnerNodes, NodeKind, TreeKind};
use std::fmt::Write as _;
use std::io::{BufRead, Read};
use std::ops::Range;
use std::path::Path;

/// First line of every manifest, before the version number.
pub const MAGIC: &str = "octolinear-tiles";
/// The newest manifest version, written when the manifest holds a
/// [`BuildRecord`]; a manifest without one is written as version 1. This
/// crate reads both.
pub const VERSION: u32 = 2;
/// A tile set's manifest file name inside its directory.
pub const MANIFEST_FILE: &str = "manifest";
/// Longest line of a manifest or a plan file, in bytes without its `\n`
/// (the longest valid line is under 110).
pub const MAX_LINE_BYTES: usize = 256;
/// Most tasks one tile set can be built by (`task K N`, a plan's `tasks`).
pub const MAX_TASKS: u32 = 1 << 16;

/// One tile of a manifest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileEntry {
    /// Which tile; its file is [`TileId::file_name`].
    pub id: TileId,
    /// Nodes in the tile's `.olm` file (the chain above the tile root included).
    pub nodes: u64,
    /// Length of the tile's file in bytes.
    pub bytes: u64,
    /// CRC-32 (IEEE, as zlib) of the whole file.
    pub crc32: u32,
    /// The tile's root node.
    pub root: TileRoot,
}

/// A task's share of a tile set built by several processes: task `index`
/// of `count` builds the tiles `tiles` says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TaskPart {
    /// This task, `0..count`.
    pub index: u32,
    /// How many tasks share the tiles.
    pub count: u32,
    /// Which tiles are this task's.
    pub tiles: TaskTiles,
}

/// How the tiles are shared among the tasks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskTiles {
    /// By [`task_of`], a hash of the tile's Morton prefix: no plan needed,
    /// but every task casts every ray.
    Hashed,
    /// The tiles whose Morton prefixes lie in `start..end` (from a
    /// [`TilePlan`](super::TilePlan)): a compact region, so that a task
    /// casts only the rays reaching it.
    Prefixes {
        /// First prefix owned.
        start: u64,
        /// First prefix past the task's.
        end: u64,
    },
}

impl TaskPart {
    /// Task `index` of `count` under the hash split ([`task_of`]).
    pub fn hashed(index: u32, count: u32) -> Self {
        TaskPart { index, count, tiles: TaskTiles::Hashed }
    }

    /// Task `index` of `count` under the hash split, when `index < count`
    /// and `count` is 1 to [`MAX_TASKS`].
    pub fn checked(index: u32, count: u32) -> Option<Self> {
        (index < count && count <= MAX_TASKS).then(|| TaskPart::hashed(index, count))
    }

    /// True when the tile belongs to this task.
    pub fn owns(self, id: TileId) -> bool {
        match self.tiles {
            TaskTiles::Hashed => task_of(id, self.count) == self.index,
            TaskTiles::Prefixes { start, end } => (start..end).contains(&id.prefix()),
        }
    }

    /// The range of tile prefixes owned, when the task owns a range.
    pub fn prefixes(self) -> Option<Range<u64>> {
        match self.tiles {
            TaskTiles::Hashed => None,
            TaskTiles::Prefixes { start, end } => Some(start..end),
        }
    }

    /// The part file this task writes in the tile set's directory.
    pub fn file_name(self) -> String {
        format!("task-{}-of-{}.manifest", self.index, self.count)
    }
}

/// The task (of `count`) that builds tile `id`: its Morton prefix, mixed
/// by one multiplication so that neighbouring tiles spread over the tasks.
pub fn task_of(id: TileId, count: u32) -> u32 {
    let mixed = id.prefix().wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 32;
    (mixed % u64::from(count.max(1))) as u32
}

/// A parsed manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct Manifest {
    /// Voxel edge length in metres.
    pub resolution: f64,
    /// Depth of the tiles' roots (1..=15).
    pub depth: u8,
    /// `OcTree` or `OcTreeStamped`.
    pub kind: TreeKind,
    /// The sensor model (log-odds) every tile was updated with.
    pub sensor: SensorModel,
    /// Set in a task's part file, `None` in a whole set's manifest.
    pub task: Option<TaskPart>,
    /// How the tiles were built; `None` when not recorded (a version 1
    /// manifest).
    pub build: Option<BuildRecord>,
    /// The tiles, in Morton order.
    pub tiles: Vec<TileEntry>,
}

/// How a tile set (or a task's part) was built, beyond the map's
/// parameters: every option that changes the rays or the values, the
/// input and the plan. Two builds that differ here may give other tiles,
/// so a part or set built otherwise is never taken for this one.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildRecord {
    /// Rays cut at this range (metres); `None` for no limit.
    pub max_range: Option<f64>,
    /// End points merged per voxel before casting.
    pub discretize: bool,
    /// Updated ray by ray (OctoMap's `insertPointCloudRays`) instead of by
    /// per-scan voxel sets.
    pub rays: bool,
    /// Inner nodes updated at once or deferred (lazy).
    pub inner: InnerNodes,
    /// What was done with end points outside the map.
    pub out_of_map: OutOfMap,
    /// Only voxels inside this box (lower, upper corner) were updated.
    pub update_box: Option<(Point3, Point3)>,
    /// Tiles wholly farther than this (metres) from each scan's origin
    /// were forgotten ([`super::Window`] with [`super::Beyond::Drop`]).
    pub forget_beyond: Option<f64>,
    /// Only the first this many scans were inserted; `None` for all.
    pub scans: Option<u64>,
    /// The input the scans came from; `None` when not known.
    pub input: Option<BuildInput>,
    /// CRC-32 of the plan's text ([`super::TilePlan::identity`]) when the
    /// task's range came from a plan.
    pub plan: Option<u32>,
}

/// The identity of a build's input: enough to tell that a part was built
/// from another file (or the same file since changed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildInput {
    /// A stream (standard input, a pipe): read once, nothing to compare.
    Stream,
    /// A regular file.
    File {
        /// Its length in bytes.
        bytes: u64,
        /// Its modification time, nanoseconds since the Unix epoch (0 for
        /// a time before it).
        modified_ns: u64,
    },
}

impl BuildInput {
    /// The identity of the input at `path`: its length and modification
    /// time for a regular file, [`BuildInput::Stream`] for anything else
    /// (`-`, a pipe, a FIFO, a device).
    pub fn of_path(path: &Path) -> Result<BuildInput, TileError> {
        if path.as_os_str() == "-" {
            return Ok(BuildInput::Stream);
        }
        let meta = std::fs::metadata(path).map_err(|e| TileError::io(path, e))?;
        if !meta.is_file() {
            return Ok(BuildInput::Stream);
        }
        let modified = meta.modified().map_err(|e| TileError::io(path, e))?;
        let modified_ns = modified
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        Ok(BuildInput::File { bytes: meta.len(), modified_ns })
    }
}

impl BuildRecord {
    /// The record of a build inserting scans with `opts` (batched, not ray
    /// by ray), every scan, without a window, input or plan: set those
    /// fields as the build does.
    pub fn new(opts: &ScanOptions) -> Self {
        BuildRecord {
            max_range: opts.max_range,
            discretize: opts.discretize,
            rays: false,
            inner: opts.inner,
            out_of_map: opts.out_of_map,
            update_box: opts.bbx.map(|b| (b.min, b.max)),
            forget_beyond: None,
            scans: None,
            input: None,
            plan: None,
        }
    }

    /// Each field as its manifest line's name and value.
    fn lines(&self) -> Vec<(&'static str, String)> {
        let f64_or_none = |v: Option<f64>| v.map_or_else(|| "none".to_string(), |v| format!("{:016x}", v.to_bits()));
        let yes_no = |b: bool| if b { "yes" } else { "no" }.to_string();
        vec![
            ("max_range", f64_or_none(self.max_range)),
            ("discretize", yes_no(self.discretize)),
            ("insertion", if self.rays { "rays" } else { "sets" }.into()),
            (
                "inner_nodes",
                match self.inner {
                    InnerNodes::Update => "update",
                    InnerNodes::Defer => "defer",
                }
                .into(),
            ),
            (
                "out_of_map",
                match self.out_of_map {
                    OutOfMap::OctoMap => "octomap",
                    OutOfMap::Skip => "skip",
                    OutOfMap::Error => "error",
                }
                .into(),
            ),
            (
                "update_box",
                self.update_box.map_or_else(
                    || "none".to_string(),
                    |(lo, hi)| [lo.x, lo.y, lo.z, hi.x, hi.y, hi.z].map(|v| format!("{:08x}", v.to_bits())).join(" "),
                ),
            ),
            ("forget_beyond", f64_or_none(self.forget_beyond)),
            ("scans", self.scans.map_or_else(|| "all".to_string(), |n| n.to_string())),
            (
                "input",
                match self.input {
                    None => "none".to_string(),
                    Some(BuildInput::Stream) => "stream".to_string(),
                    Some(BuildInput::File { bytes, modified_ns }) => format!("file {bytes} {modified_ns}"),
                },
            ),
            ("plan", self.plan.map_or_else(|| "none".to_string(), |c| format!("{c:08x}"))),
        ]
    }

    /// Each field's name and value as messages show them.
    fn shown(&self) -> Vec<(&'static str, String)> {
        let metres = |v: Option<f64>| v.map_or_else(|| "none".to_string(), |v| format!("{v} m"));
        let mut fields = self.lines();
        for (name, value) in &mut fields {
            match *name {
                "max_range" => *value = metres(self.max_range),
                "forget_beyond" => *value = metres(self.forget_beyond),
                "update_box" => {
                    if let Some((lo, hi)) = self.update_box {
                        *value = format!("({}, {}, {}) to ({}, {}, {})", lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
                    }
                }
                "input" => {
                    if let Some(BuildInput::File { bytes, modified_ns }) = self.input {
                        *value = format!("a file of {bytes} bytes modified at {modified_ns} ns");
                    }
                }
                _ => {}
            }
        }
        fields
    }

    /// Parses the record's lines, in order, from `lines`.
    fn parse(lines: &mut Lines<'_>) -> Result<BuildRecord, ManifestError> {
        let positive = |v: &str| hex64(v).map(f64::from_bits).filter(|r| r.is_finite() && *r > 0.0);
        let max_range = lines.field("max_range", |v| if v == "none" { Some(None) } else { positive(v).map(Some) })?;
        let discretize = lines.field("discretize", yes_no)?;
        let rays = lines.field("insertion", |v| match v {
            "sets" => Some(false),
            "rays" => Some(true),
            _ => None,
        })?;
        let inner = lines.field("inner_nodes", |v| match v {
            "update" => Some(InnerNodes::Update),
            "defer" => Some(InnerNodes::Defer),
            _ => None,
        })?;
        let out_of_map = lines.field("out_of_map", |v| match v {
            "octomap" => Some(OutOfMap::OctoMap),
            "skip" => Some(OutOfMap::Skip),
            "error" => Some(OutOfMap::Error),
            _ => None,
        })?;
        let update_box = lines.field("update_box", |v| {
            if v == "none" {
                return Some(None);
            }
            let c: Vec<f32> =
                v.split(' ').map(|f| hex32(f).map(f32::from_bits).filter(|x| x.is_finite())).collect::<Option<_>>()?;
            let [x0, y0, z0, x1, y1, z1] = c[..] else { return None };
            Some(Some((Point3::new(x0, y0, z0), Point3::new(x1, y1, z1))))
        })?;
        let forget_beyond = lines.field("forget_beyond", |v| {
            if v == "none" {
                return Some(None);
            }
            hex64(v).map(f64::from_bits).filter(|r| r.is_finite() && r.is_sign_positive()).map(Some)
        })?;
        let scans =
            lines.field("scans", |v| if v == "all" { Some(None) } else { decimal(v).filter(|&n| n >= 1).map(Some) })?;
        let input = lines.field("input", |v| match v {
            "none" => Some(None),
            "stream" => Some(Some(BuildInput::Stream)),
            _ => {
                let rest = v.strip_prefix("file ")?;
                let (bytes, modified) = rest.split_once(' ')?;
                Some(Some(BuildInput::File { bytes: decimal(bytes)?, modified_ns: decimal(modified)? }))
            }
        })?;
        let plan = lines.field("plan", |v| if v == "none" { Some(None) } else { hex32(v).map(Some) })?;
        Ok(BuildRecord {
            max_range,
            discretize,
            rays,
            inner,
            out_of_map,
            update_box,
            forget_beyond,
            scans,
            input,
            plan,
        })
    }
}

/// `yes` or `no`.
fn yes_no(v: &str) -> Option<bool> {
    match v {
        "yes" => Some(true),
        "no" => Some(false),
        _ => None,
    }
}

/// Why a manifest could not be parsed: the line (1-based; 0 for the file
/// as a whole) and what is wrong there.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ManifestError {
    /// Line of the fault.
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

impl Manifest {
    /// The node kind of the trees the tiles hold.
    pub fn node_kind(&self) -> NodeKind {
        self.kind.node_kind().unwrap_or_default()
    }

    /// Writes the manifest to `path` atomically and synced (after the
    /// tiles it lists are on disk).
    pub fn write(&self, path: &std::path::Path) -> Result<(), super::TileError> {
        let bytes = self.to_bytes();
        crate::formats::atomic::write_entry_atomically(path, |w| std::io::Write::write_all(w, &bytes))
            .map_err(|e| super::TileError::io(path, e))
    }

    /// Reads the manifest (or a task's part) at `path`: a regular file
    /// (a FIFO, device or directory is refused before it is opened for
    /// reading), read line by line, no line longer than
    /// [`MAX_LINE_BYTES`]; every field checked as [`Self::parse`] does.
    /// Errors name the file and the line.
    pub fn read(path: &Path) -> Result<Manifest, TileError> {
        let bytes = read_text_file(path, "a tile manifest", u64::MAX)?;
        Manifest::parse(&bytes).map_err(|e| TileError::Manifest {
            path: path.to_path_buf(),
            line: e.line,
            reason: e.reason,
        })
    }

    /// The first difference between the parameters and build records of
    /// two manifests (`self` is `ours`, `other` is `theirs`), as a message;
    /// `None` when they agree. Tasks, tiles and the plans' identities are
    /// not compared.
    pub fn difference(&self, other: &Manifest, ours: &str, theirs: &str) -> Option<String> {
        let sensor = |m: &Manifest| {
            let s = m.sensor;
            [
                ("hit", s.hit),
                ("miss", s.miss),
                ("clamping_min", s.clamping_min),
                ("clamping_max", s.clamping_max),
                ("occupancy_threshold", s.occupancy_threshold),
            ]
            .map(|(n, v)| (n, format!("{v} (bits {:08x})", v.to_bits())))
        };
        let mut a: Vec<(&str, String)> = vec![
            ("resolution", format!("{} m", self.resolution)),
            ("tile_depth", self.depth.to_string()),
            ("tree_kind", self.kind.id().to_string()),
        ];
        let mut b: Vec<(&str, String)> = vec![
            ("resolution", format!("{} m", other.resolution)),
            ("tile_depth", other.depth.to_string()),
            ("tree_kind", other.kind.id().to_string()),
        ];
        a.extend(sensor(self));
        b.extend(sensor(other));
        // the plan is not compared: a range of tiles is built the same
        // whatever plan gave it (the task lines hold the ranges)
        if let (Some(x), Some(y)) = (&self.build, &other.build) {
            a.extend(x.shown().into_iter().filter(|(n, _)| *n != "plan"));
            b.extend(y.shown().into_iter().filter(|(n, _)| *n != "plan"));
        }
        if self.resolution.to_bits() != other.resolution.to_bits() {
            return Some(format!("resolution: {} in {ours}, {} in {theirs}", a[0].1, b[0].1));
        }
        for ((name, x), (_, y)) in a.iter().zip(&b) {
            if x != y {
                return Some(format!("{name}: {x} in {ours}, {y} in {theirs}"));
            }
        }
        match (&self.build, &other.build) {
            (Some(_), None) => Some(format!(
                "{ours} records the options it was built with, {theirs} does not (a version 1 manifest, of an older build)"
            )),
            (None, Some(_)) => Some(format!(
                "{theirs} records the options it was built with, {ours} does not (a version 1 manifest, of an older build)"
            )),
            _ => None,
        }
    }

    /// The manifest's bytes: version 2 with a build record, else version 1.
    pub fn to_bytes(&self) -> Vec<u8> {
        let version = if self.build.is_some() { VERSION } else { 1 };
        let mut s = format!("{MAGIC} {version}\n");
        if let Some(t) = self.task {
            let _ = match t.tiles {
                TaskTiles::Hashed => writeln!(s, "task {} {}", t.index, t.count),
                TaskTiles::Prefixes { start, end } => {
                    writeln!(s, "task {} {} prefixes {start} {end}", t.index, t.count)
                }
            };
        }
        let sensor = &self.sensor;
        let _ = writeln!(s, "resolution {:016x}", self.resolution.to_bits());
        let _ = writeln!(s, "tile_depth {}", self.depth);
        let _ = writeln!(s, "tree_kind {}", self.kind.id());
        for (name, v) in [
            ("hit", sensor.hit),
            ("miss", sensor.miss),
            ("clamping_min", sensor.clamping_min),
            ("clamping_max", sensor.clamping_max),
            ("occupancy_threshold", sensor.occupancy_threshold),
        ] {
            let _ = writeln!(s, "{name} {:08x}", v.to_bits());
        }
        if let Some(build) = &self.build {
            for (name, value) in build.lines() {
                let _ = writeln!(s, "{name} {value}");
            }
        }
        let _ = writeln!(s, "tiles {}", self.tiles.len());
        for t in &self.tiles {
            let _ = writeln!(
                s,
                "tile {} {} {} {:08x} {:08x} {} {}",
                t.id.file_name(),
                t.nodes,
                t.bytes,
                t.crc32,
                t.root.value.to_bits(),
                t.root.extra,
                if t.root.is_leaf { "leaf" } else { "inner" }
            );
        }
        let crc = crc32fast::hash(s.as_bytes());
        let _ = writeln!(s, "crc32 {crc:08x}");
        s.into_bytes()
    }

    /// Parses a manifest; every field is checked (see `formats/tiles.md`).
    pub fn parse(bytes: &[u8]) -> Result<Manifest, ManifestError> {
        let whole = |reason: String| ManifestError { line: 0, reason };
        let text = std::str::from_utf8(bytes).map_err(|e| whole(format!("not UTF-8 text ({e})")))?;
        if !text.ends_with('\n') {
            return Err(whole("does not end with a newline (truncated?)".into()));
        }
        if let Some((i, line)) = text.lines().enumerate().find(|(_, l)| l.len() > MAX_LINE_BYTES) {
            return Err(ManifestError {
                line: i + 1,
                reason: format!("line of {} bytes, longer than any manifest line ({MAX_LINE_BYTES})", line.len()),
            });
        }
        // the checksum covers every byte before the last line
        let body_end = text[..text.len() - 1].rfind('\n').map_or(0, |i| i + 1);
        let mut lines = Lines { lines: text[..body_end].lines(), number: 0 };
        let last_line = text[..body_end].lines().count() + 1;
        let crc_text = &text[body_end..text.len() - 1];
        let stored = crc_text.strip_prefix("crc32 ").and_then(hex32).ok_or_else(|| ManifestError {
            line: last_line,
            reason: format!("expected `crc32 XXXXXXXX`, found `{}`", clip(crc_text)),
        })?;
        let computed = crc32fast::hash(&text.as_bytes()[..body_end]);
        if stored != computed {
            return Err(ManifestError {
                line: last_line,
                reason: format!("checksum mismatch: stored {stored:08x}, computed {computed:08x}"),
            });
        }

        let version = lines.field(MAGIC, |v| v.parse::<u32>().ok().filter(|_| canonical(v)))?;
        if version != 1 && version != VERSION {
            return Err(lines.fault(format!(
                "manifest version {version} is not supported (this reader reads versions 1 and {VERSION})"
            )));
        }
        let mut next = lines.next()?;
        let task = match next.strip_prefix("task ") {
            Some(rest) => {
                let task = parse_task(rest).ok_or_else(|| {
                    lines.fault(format!(
                        "expected `task K N` or `task K N prefixes START END` with K < N <= {MAX_TASKS} and START < END, found `{}`",
                        clip(next)
                    ))
                })?;
                next = lines.next()?;
                Some(task)
            }
            None => None,
        };
        let resolution = lines.value(next, "resolution", |v| {
            hex64(v).map(f64::from_bits).filter(|&r| crate::key::check_resolution(r).is_ok())
        })?;
        let depth = lines.field("tile_depth", |v| {
            decimal(v).filter(|d| (1..=u64::from(MAX_TILE_DEPTH)).contains(d)).map(|d| d as u8)
        })?;
        if let Some(range) = task.and_then(TaskPart::prefixes).filter(|r| r.end > 1 << (3 * u32::from(depth))) {
            return Err(ManifestError {
                line: 2,
                reason: format!(
                    "prefix range {}..{} exceeds the {} tiles of depth {depth}",
                    range.start,
                    range.end,
                    1u64 << (3 * u32::from(depth))
                ),
            });
        }
        let kind = lines.field("tree_kind", |v| {
            TreeKind::from_id(v).filter(|k| matches!(k, TreeKind::OcTree | TreeKind::OcTreeStamped))
        })?;
        let mut sensor_value = |name| lines.field(name, |v| hex32(v).map(f32::from_bits).filter(|x| x.is_finite()));
        let sensor = SensorModel {
            hit: sensor_value("hit")?,
            miss: sensor_value("miss")?,
            clamping_min: sensor_value("clamping_min")?,
            clamping_max: sensor_value("clamping_max")?,
            occupancy_threshold: sensor_value("occupancy_threshold")?,
        };
        let build = if version >= 2 { Some(BuildRecord::parse(&mut lines)?) } else { None };
        let count = lines.field("tiles", decimal)?;
        let mut tiles: Vec<TileEntry> = Vec::new();
        for _ in 0..count {
            let line = lines.next()?;
            let entry = parse_tile(line, depth, kind).map_err(|reason| lines.fault(reason))?;
            if let Some(prev) = tiles.last() {
                if prev.id.prefix() >= entry.id.prefix() {
                    return Err(lines.fault(format!("tile {} does not follow {} in Morton order", entry.id, prev.id)));
                }
            }
            if let Some(t) = task.filter(|t| !t.owns(entry.id)) {
                return Err(lines.fault(format!("tile {} is not one of task {} of {}", entry.id, t.index, t.count)));
            }
            tiles.push(entry);
        }
        if let Some(extra) = lines.lines.next() {
            lines.number += 1;
            return Err(lines.fault(format!("unexpected line `{}` after the {count} tiles", clip(extra))));
        }
        Ok(Manifest { resolution, depth, kind, sensor, task, build, tiles })
    }
}

/// Reads the text file at `path` (`what` names it in errors): a regular
/// file only, checked before it is opened for reading (so a FIFO never
/// blocks) and again once open (without blocking), read line by line, no
/// line longer than [`MAX_LINE_BYTES`] and no more than `limit` bytes.
pub(super) fn read_text_file(path: &Path, what: &str, limit: u64) -> Result<Vec<u8>, TileError> {
    use std::os::unix::fs::OpenOptionsExt;
    let not_regular = |kind: &str| {
        TileError::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("is {kind}, not a regular file: {what} is read from a regular file"),
            ),
        )
    };
    let kind_of = |t: std::fs::FileType| {
        use std::os::unix::fs::FileTypeExt;
        if t.is_dir() {
            "a directory"
        } else if t.is_fifo() {
            "a FIFO"
        } else if t.is_char_device() || t.is_block_device() {
            "a device"
        } else if t.is_socket() {
            "a socket"
        } else {
            "not a regular file"
        }
    };
    let meta = std::fs::metadata(path).map_err(|e| TileError::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(kind_of(meta.file_type())));
    }
    // non-blocking, in case the name now leads to a FIFO
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| TileError::io(path, e))?;
    let meta = file.metadata().map_err(|e| TileError::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(kind_of(meta.file_type())));
    }
    if meta.len() > limit {
        return Err(TileError::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("is {} bytes, more than {what} can be ({limit})", meta.len()),
            ),
        ));
    }
    let mut reader = std::io::BufReader::new(file).take(meta.len().min(limit));
    let mut bytes = Vec::new();
    let mut line = 0usize;
    loop {
        line += 1;
        let start = bytes.len();
        let n = (&mut reader)
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut bytes)
            .map_err(|e| TileError::io(path, e))?;
        if n == 0 {
            return Ok(bytes);
        }
        let body = bytes.len() - start - usize::from(bytes.last() == Some(&b'\n'));
        if body > MAX_LINE_BYTES {
            return Err(TileError::io(
                path,
                std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!("line {line} is longer than {MAX_LINE_BYTES} bytes: not {what}"),
                ),
            ));
        }
    }
}

/// Checks that `dir` may receive a tile set's files (tiles, `manifest`,
/// task parts), so that a build never writes over, or removes, files of
/// something else: `dir` must be named `NAME.tiles` or be an empty
/// directory or hold a tile set (its `manifest` or a task's part file
/// starts as a manifest); and any `manifest` or part file in it must be
/// octolinear's. A path that is not a directory is refused.
pub fn check_set_dir(dir: &Path) -> Result<(), TileError> {
    let refuse = |reason: String| TileError::SetDir { dir: dir.to_path_buf(), reason };
    let named = is_tile_set_name(dir);
    let meta = match std::fs::symlink_metadata(dir) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return if named {
                Ok(())
            } else {
                Err(refuse(
                    "a tile set is a directory named NAME.tiles (or an empty directory): give the output that name"
                        .into(),
                ))
            };
        }
        Err(e) => return Err(TileError::io(dir, e)),
    };
    let meta =
        if meta.file_type().is_symlink() { std::fs::metadata(dir).map_err(|e| TileError::io(dir, e))? } else { meta };
    if !meta.is_dir() {
        return Err(refuse("exists and is not a directory: a tile set is a directory".into()));
    }
    let (mut empty, mut ours) = (true, false);
    for item in std::fs::read_dir(dir).map_err(|e| TileError::io(dir, e))? {
        let item = item.map_err(|e| TileError::io(dir, e))?;
        empty = false;
        let name = item.file_name();
        let Some(name) = name.to_str() else { continue };
        if name == MANIFEST_FILE || (name.starts_with("task-") && name.ends_with(".manifest")) {
            let path = item.path();
            if !starts_as_manifest(&path) {
                return Err(refuse(format!(
                    "holds a file {name} that is not a tile set's manifest: a build would replace it"
                )));
            }
            ours = true;
        }
    }
    if named || empty || ours {
        Ok(())
    } else {
        Err(refuse(
            "is neither named NAME.tiles nor empty nor a tile set (no manifest): a build would write its tiles among other files"
                .into(),
        ))
    }
}

/// True when `path` is named as a tile set: extension `.tiles` (any case).
pub fn is_tile_set_name(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("tiles"))
}

/// True when `path` is a regular file (not followed through a link) whose
/// first line is a manifest's.
fn starts_as_manifest(path: &Path) -> bool {
    let Ok(meta) = std::fs::symlink_metadata(path) else { return false };
    if !meta.is_file() {
        return false;
    }
    let mut head = [0u8; MAGIC.len() + 1];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut head)).is_ok()
        && head.starts_with(MAGIC.as_bytes())
        && head[MAGIC.len()] == b' '
}

/// The body's lines, numbered.
struct Lines<'a> {
    lines: std::str::Lines<'a>,
    number: usize,
}

impl<'a> Lines<'a> {
    fn fault(&self, reason: String) -> ManifestError {
        ManifestError { line: self.number, reason }
    }

    fn next(&mut self) -> Result<&'a str, ManifestError> {
        self.number += 1;
        self.lines.next().ok_or_else(|| ManifestError { line: self.number, reason: "the manifest ends early".into() })
    }

    /// The next line as `name VALUE`, the value parsed by `parse`.
    fn field<T>(&mut self, name: &str, parse: impl FnOnce(&str) -> Option<T>) -> Result<T, ManifestError> {
        let line = self.next()?;
        self.value(line, name, parse)
    }

    fn value<T>(&self, line: &str, name: &str, parse: impl FnOnce(&str) -> Option<T>) -> Result<T, ManifestError> {
        line.strip_prefix(name)
            .and_then(|rest| rest.strip_prefix(' '))
            .and_then(parse)
            .ok_or_else(|| self.fault(format!("expected a valid `{name}` line, found `{}`", clip(line))))
    }
}

/// A `task` line's fields after `task `.
fn parse_task(rest: &str) -> Option<TaskPart> {
    let fields: Vec<&str> = rest.split(' ').collect();
    let (index, count, tiles) = match fields[..] {
        [i, c] => (decimal(i)?, decimal(c)?, TaskTiles::Hashed),
        [i, c, "prefixes", start, end] => {
            let (start, end) = (decimal(start)?, decimal(end)?);
            (decimal(i)?, decimal(c)?, TaskTiles::Prefixes { start, end })
        }
        _ => return None,
    };
    if count == 0 || index >= count || count > u64::from(MAX_TASKS) {
        return None;
    }
    let task = TaskPart { index: index as u32, count: count as u32, tiles };
    task.prefixes().is_none_or(|r| r.start < r.end).then_some(task)
}

/// One `tile` line.
fn parse_tile(line: &str, depth: u8, kind: TreeKind) -> Result<TileEntry, String> {
    let fields: Vec<&str> = line.split(' ').collect();
    let [tag, name, nodes, bytes, crc, value, extra, leaf] = fields[..] else {
        return Err(format!("expected `tile FILE NODES BYTES CRC32 VALUE EXTRA leaf|inner`, found `{}`", clip(line)));
    };
    if tag != "tile" {
        return Err(format!("expected a `tile` line, found `{}`", clip(line)));
    }
    let id = TileId::from_file_name(name).ok_or_else(|| format!("`{}` is not a tile file name", clip(name)))?;
    if id.depth() != depth {
        return Err(format!("tile {id} is not at the tile depth {depth}"));
    }
    let nodes = decimal(nodes).ok_or_else(|| format!("node count `{}` is not a number", clip(nodes)))?;
    let bytes = decimal(bytes).ok_or_else(|| format!("byte size `{}` is not a number", clip(bytes)))?;
    let crc32 = hex32(crc).ok_or_else(|| format!("CRC-32 `{}` is not 8 hex digits", clip(crc)))?;
    let value = hex32(value)
        .map(f32::from_bits)
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("root value `{}` is not the bits of a finite float", clip(value)))?;
    let extra = decimal(extra)
        .and_then(|e| u32::try_from(e).ok())
        .ok_or_else(|| format!("root stamp `{}` is not a 32-bit number", clip(extra)))?;
    let is_leaf = match leaf {
        "leaf" => true,
        "inner" => false,
        other => return Err(format!("expected `leaf` or `inner`, found `{}`", clip(other))),
    };
    if kind == TreeKind::OcTree && extra != 0 {
        return Err(format!("tile {id}: an OcTree's root stamp must be 0, found {extra}"));
    }
    // the chain of nodes above the tile root, the root, and below it
    // at least a child when it is not a leaf
    let least = u64::from(depth) + 1 + u64::from(!is_leaf);
    if nodes < least || (is_leaf && nodes != least) || nodes > u64::from(u32::MAX) {
        return Err(format!("tile {id}: {nodes} nodes cannot hold a {} tile root at depth {depth}", leaf));
    }
    if bytes < HEADER_LEN as u64 {
        return Err(format!("tile {id}: {bytes} bytes is shorter than an .olm header"));
    }
    Ok(TileEntry { id, nodes, bytes, crc32, root: TileRoot { value, extra, is_leaf } })
}

/// A decimal number as the writer spells it (no sign, no leading zero).
pub(super) fn decimal(s: &str) -> Option<u64> {
    canonical(s).then(|| s.parse().ok()).flatten()
}

fn canonical(s: &str) -> bool {
    !s.is_empty() && s.len() <= 20 && s.bytes().all(|b| b.is_ascii_digit()) && (s == "0" || !s.starts_with('0'))
}

/// Exactly 8 lowercase hex digits.
fn hex32(s: &str) -> Option<u32> {
    (s.len() == 8 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')))
        .then(|| u32::from_str_radix(s, 16).ok())
        .flatten()
}

/// Exactly 16 lowercase hex digits.
fn hex64(s: &str) -> Option<u64> {
    (s.len() == 16 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')))
        .then(|| u64::from_str_radix(s, 16).ok())
        .flatten()
}

/// At most 60 characters of `s`, for messages.
pub(super) fn clip(s: &str) -> String {
    let mut out: String = s.chars().take(60).collect();
    if out.len() < s.len() {
        out.push('…');
    }
    out
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    fn sample() -> Manifest {
        let root = |value, is_leaf| TileRoot { value, extra: 0, is_leaf };
        Manifest {
            resolution: 0.1,
            depth: 3,
            kind: TreeKind::OcTree,
            sensor: SensorModel::default(),
            task: None,
            build: None,
            tiles: vec![
                TileEntry {
                    id: TileId::new(3, [1, 2, 3]).unwrap(),
                    nodes: 9,
                    bytes: 700,
                    crc32: 0xdead_beef,
                    root: root(0.5, false),
                },
                TileEntry {
                    id: TileId::new(3, [7, 7, 7]).unwrap(),
                    nodes: 4,
                    bytes: 512,
                    crc32: 1,
                    root: root(-2.0, true),
                },
            ],
        }
    }

    #[test]
    fn a_manifest_round_trips() {
        let m = sample();
        let bytes = m.to_bytes();
        assert_eq!(Manifest::parse(&bytes), Ok(m.clone()));
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.starts_with("octolinear-tiles 1\nresolution 3fb999999999999a\ntile_depth 3\ntree_kind OcTree\n"));
        let part = Manifest { task: Some(TaskPart::hashed(0, 1)), ..m.clone() };
        assert_eq!(Manifest::parse(&part.to_bytes()), Ok(part));
        let range = TaskPart { index: 1, count: 2, tiles: TaskTiles::Prefixes { start: 53, end: 512 } };
        let part = Manifest { task: Some(range), ..m };
        let bytes = part.to_bytes();
        assert!(String::from_utf8_lossy(&bytes).contains("\ntask 1 2 prefixes 53 512\n"));
        assert_eq!(Manifest::parse(&bytes), Ok(part));
    }

    #[test]
    fn every_damaged_byte_is_an_error_with_a_line() {
        let bytes = sample().to_bytes();
        for i in 0..bytes.len() {
            for flip in [1u8, 0x20, 0x80] {
                let mut b = bytes.clone();
                b[i] ^= flip;
                let e = Manifest::parse(&b).unwrap_err();
                assert!(e.line <= 14, "{e:?}");
            }
        }
        for len in 0..bytes.len() {
            assert!(Manifest::parse(&bytes[..len]).is_err());
        }
    }

    /// Faults behind a valid checksum: each is found and placed on its line.
    #[test]
    fn faults_are_reported_on_their_line() {
        let text = String::from_utf8(sample().to_bytes()).unwrap();
        let body: Vec<&str> = text.lines().filter(|l| !l.starts_with("crc32")).collect();
        let with = |line: usize, new: &str| {
            let mut b = body.clone();
            b[line - 1] = new;
            let mut s = b.join("\n") + "\n";
            let crc = crc32fast::hash(s.as_bytes());
            s += &format!("crc32 {crc:08x}\n");
            Manifest::parse(s.as_bytes()).unwrap_err()
        };
        assert_eq!(with(1, "octolinear-tiles 3").line, 1);
        assert_eq!(with(3, "tile_depth 16").line, 3);
        assert_eq!(with(4, "tree_kind ColorOcTree").line, 4);
        assert_eq!(with(10, "tiles 3").line, 13);
        assert_eq!(with(10, "tiles 1").line, 12);
        let swapped = body[11].to_string();
        assert!(with(11, &swapped).reason.contains("Morton order"));
        assert!(with(12, "tile d3-7-7-7.olm 5 512 00000001 c0000000 0 leaf").reason.contains("nodes"));
        assert!(with(12, "tile d2-3-3-3.olm 3 512 00000001 c0000000 0 leaf").reason.contains("tile depth"));
        assert!(with(12, "tile ../x.olm 4 512 00000001 c0000000 0 leaf").reason.contains("file name"));
        assert!(with(12, "tile d3-7-7-7.olm 4 512 00000001 7fc00000 0 leaf").reason.contains("finite"));
    }

    /// A part's task line: its range checked against the tile depth and
    /// its tiles against the range.
    #[test]
    fn a_range_part_holds_only_its_tiles() {
        let part = |task: &str| {
            let text = String::from_utf8(sample().to_bytes()).unwrap();
            let mut body: Vec<&str> = text.lines().filter(|l| !l.starts_with("crc32")).collect();
            body.insert(1, task);
            let mut s = body.join("\n") + "\n";
            s += &format!("crc32 {:08x}\n", crc32fast::hash(s.as_bytes()));
            Manifest::parse(s.as_bytes())
        };
        // the sample's tiles have prefixes 53 (d3-1-2-3) and 511 (d3-7-7-7)
        assert!(part("task 0 1 prefixes 0 512").is_ok());
        assert!(part("task 1 2 prefixes 53 512").is_ok());
        let e = part("task 0 2 prefixes 0 53").unwrap_err();
        assert!(e.line == 12 && e.reason.contains("d3-1-2-3 is not one of task 0 of 2"), "{e:?}");
        let e = part("task 0 2 prefixes 0 513").unwrap_err();
        assert!(e.line == 2 && e.reason.contains("exceeds the 512 tiles"), "{e:?}");
        for bad in ["task 0 2 prefixes 5 5", "task 0 2 prefixes 1", "task 0 2 range 0 512", "task 2 2"] {
            assert_eq!(part(bad).unwrap_err().line, 2, "{bad}");
        }
    }

    fn record() -> BuildRecord {
        BuildRecord {
            max_range: Some(20.0),
            scans: Some(3),
            input: Some(BuildInput::File { bytes: 123_456, modified_ns: 1_700_000_000_123_456_789 }),
            plan: Some(0x0123_abcd),
            ..BuildRecord::new(&ScanOptions::default())
        }
    }

    /// Version 2 records the build; version 1 (no record) is still read.
    #[test]
    fn a_build_record_round_trips_and_version_1_is_read() {
        let m = Manifest { build: Some(record()), task: Some(TaskPart::hashed(1, 2)), ..sample() };
        let bytes = m.to_bytes();
        let text = String::from_utf8(bytes.clone()).unwrap();
        assert!(text.starts_with("octolinear-tiles 2\ntask 1 2\n"), "{text}");
        assert!(text.contains("\nmax_range 4034000000000000\ndiscretize no\ninsertion sets\n"), "{text}");
        assert!(text.contains("\nscans 3\ninput file 123456 1700000000123456789\nplan 0123abcd\ntiles 2\n"), "{text}");
        assert_eq!(Manifest::parse(&bytes), Ok(m.clone()));
        let every = BuildRecord {
            discretize: true,
            rays: true,
            inner: InnerNodes::Defer,
            out_of_map: OutOfMap::Skip,
            update_box: Some((Point3::new(-1.0, -2.0, -3.0), Point3::new(1.0, 2.5, 3.0))),
            forget_beyond: Some(0.0),
            input: Some(BuildInput::Stream),
            ..record()
        };
        let m2 = Manifest { build: Some(every), ..m.clone() };
        assert_eq!(Manifest::parse(&m2.to_bytes()), Ok(m2));
        // without a record: version 1, as before
        let v1 = sample().to_bytes();
        assert!(v1.starts_with(b"octolinear-tiles 1\nresolution "));
        assert_eq!(Manifest::parse(&v1).unwrap().build, None);
        // damage anywhere in a version 2 file is found
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x20;
            assert!(Manifest::parse(&b).is_err(), "{i}");
        }
    }

    /// A record's fields behind a valid checksum: each spelling checked.
    #[test]
    fn a_bad_record_line_is_refused_on_its_line() {
        let text = String::from_utf8(Manifest { build: Some(record()), ..sample() }.to_bytes()).unwrap();
        let body: Vec<&str> = text.lines().filter(|l| !l.starts_with("crc32")).collect();
        let with = |line: usize, new: &str| {
            let mut b = body.clone();
            assert!(b[line - 1].split(' ').next() == new.split(' ').next(), "{new}");
            b[line - 1] = new;
            let mut s = b.join("\n") + "\n";
            s += &format!("crc32 {:08x}\n", crc32fast::hash(s.as_bytes()));
            Manifest::parse(s.as_bytes())
        };
        for (line, bad) in [
            (10, "max_range 0000000000000000"),
            (10, "max_range 20"),
            (11, "discretize 1"),
            (12, "insertion batched"),
            (13, "inner_nodes lazy"),
            (14, "out_of_map wrap"),
            (15, "update_box 00000000 00000000"),
            (16, "forget_beyond 8000000000000000"),
            (17, "scans 0"),
            (18, "input file 12"),
            (19, "plan 123"),
        ] {
            let e = with(line, bad).unwrap_err();
            assert_eq!(e.line, line, "{bad}: {e:?}");
        }
        assert!(with(17, "scans all").is_ok() && with(19, "plan none").is_ok() && with(18, "input none").is_ok());
    }

    /// Two parts built with other options are told apart, the option named.
    #[test]
    fn parts_built_otherwise_are_not_combined() {
        let dir = tempfile::tempdir().unwrap();
        let part = |index, build: Option<BuildRecord>| Manifest {
            task: Some(TaskPart::hashed(index, 2)),
            build,
            tiles: vec![],
            ..sample()
        };
        part(0, Some(record())).write(&dir.path().join("task-0-of-2.manifest")).unwrap();
        let other = BuildRecord { max_range: None, ..record() };
        part(1, Some(other.clone())).write(&dir.path().join("task-1-of-2.manifest")).unwrap();
        let e = super::super::combine_parts(dir.path()).unwrap_err().to_string();
        assert!(e.contains("max_range: ") && e.contains("20 m") && e.contains("none"), "{e}");
        assert!(!dir.path().join(MANIFEST_FILE).exists());
        let message = part(0, Some(record())).difference(&part(1, None), "a", "b").unwrap();
        assert!(message.contains("version 1"), "{message}");
        let input = BuildRecord { input: Some(BuildInput::File { bytes: 1, modified_ns: 2 }), ..record() };
        let message = part(0, Some(record())).difference(&part(1, Some(input)), "a", "b").unwrap();
        assert!(message.starts_with("input: "), "{message}");
        assert_eq!(part(0, Some(record())).difference(&part(1, Some(record())), "a", "b"), None);
        let planned = BuildRecord { plan: None, ..record() };
        assert_eq!(part(0, Some(record())).difference(&part(1, Some(planned)), "a", "b"), None);
        // the same options: combined
        part(1, Some(record())).write(&dir.path().join("task-1-of-2.manifest")).unwrap();
        assert_eq!(super::super::combine_parts(dir.path()).unwrap().build, Some(record()));
    }

    /// A part claiming more tasks than a set can have is refused as it is
    /// read, before anything is allocated for its tasks.
    #[test]
    fn task_counts_are_bounded() {
        let text = String::from_utf8(Manifest { tiles: vec![], ..sample() }.to_bytes()).unwrap();
        let part = |task: &str| {
            let mut body: Vec<&str> = text.lines().filter(|l| !l.starts_with("crc32")).collect();
            body.insert(1, task);
            let mut s = body.join("\n") + "\n";
            s += &format!("crc32 {:08x}\n", crc32fast::hash(s.as_bytes()));
            s
        };
        let e = Manifest::parse(part("task 0 4294967295").as_bytes()).unwrap_err();
        assert!(e.line == 2 && e.reason.contains(&MAX_TASKS.to_string()), "{e:?}");
        assert!(Manifest::parse(part(&format!("task 0 {}", MAX_TASKS + 1)).as_bytes()).is_err());
        assert!(Manifest::parse(part(&format!("task 0 {MAX_TASKS}")).as_bytes()).is_ok());
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("task-0-of-4294967295.manifest"), part("task 0 4294967295")).unwrap();
        let started = std::time::Instant::now();
        let e = super::super::combine_parts(dir.path()).unwrap_err().to_string();
        assert!(e.contains("line 2"), "{e}");
        assert!(started.elapsed().as_secs() < 5);
        assert!(TaskPart::checked(0, MAX_TASKS).is_some() && TaskPart::checked(0, MAX_TASKS + 1).is_none());
        assert!(TaskPart::checked(2, 2).is_none());
    }

    /// An error with its sources, as a program shows it.
    pub(in crate::tiles) fn chain(e: &dyn std::error::Error) -> String {
        let mut s = e.to_string();
        let mut next = e.source();
        while let Some(inner) = next {
            s += &format!(": {inner}");
            next = inner.source();
        }
        s
    }

    /// Runs `f` on a thread; fails the test if it takes more than 10 s
    /// (a reader blocked on a FIFO or reading a device for ever).
    pub(in crate::tiles) fn within_seconds<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || tx.send(f()));
        rx.recv_timeout(std::time::Duration::from_secs(10)).expect("the reader did not return within 10 s")
    }

    /// A FIFO at `path`.
    pub(in crate::tiles) fn make_fifo(path: &Path) {
        let made = std::process::Command::new("mkfifo").arg(path).status().expect("mkfifo runs");
        assert!(made.success(), "mkfifo {}", path.display());
    }

    /// A manifest is read from a regular file only, in bounded lines: a
    /// device, a FIFO and an endless line are refused at once.
    #[test]
    fn only_regular_files_of_short_lines_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let e = within_seconds(|| chain(&Manifest::read(Path::new("/dev/zero")).unwrap_err()));
        assert!(e.contains("/dev/zero") && e.contains("a device, not a regular file"), "{e}");
        let fifo = dir.path().join("manifest");
        make_fifo(&fifo);
        let path = fifo.clone();
        let e = within_seconds(move || chain(&Manifest::read(&path).unwrap_err()));
        assert!(e.contains("a FIFO, not a regular file") && e.contains(&fifo.display().to_string()), "{e}");
        let e = within_seconds(|| chain(&Manifest::read(Path::new("/")).unwrap_err()));
        assert!(e.contains("a directory"), "{e}");
        let long = dir.path().join("long");
        std::fs::write(&long, vec![b'x'; 1 << 20]).unwrap();
        let e = chain(&Manifest::read(&long).unwrap_err());
        assert!(e.contains("line 1 is longer than 256 bytes"), "{e}");
        let good = dir.path().join("good");
        let m = Manifest { build: Some(record()), ..sample() };
        m.write(&good).unwrap();
        assert_eq!(Manifest::read(&good).unwrap(), m);
        // a long line in bytes parsed directly
        let mut bytes = m.to_bytes();
        bytes.splice(0..0, vec![b'y'; 300]);
        assert_eq!(Manifest::parse(&bytes).unwrap_err().line, 1);
    }

    /// Only a `.tiles` name, an empty directory or a tile set receives a
    /// set, and never over a `manifest` of someone else's.
    #[test]
    fn sets_are_written_only_where_they_belong() {
        let dir = tempfile::tempdir().unwrap();
        let at = |name: &str| dir.path().join(name);
        assert!(check_set_dir(&at("new.tiles")).is_ok());
        assert!(check_set_dir(&at("NEW.TILES")).is_ok());
        let e = check_set_dir(&at("x.bt")).unwrap_err().to_string();
        assert!(e.contains("x.bt") && e.contains("NAME.tiles"), "{e}");
        std::fs::write(at("file.tiles"), b"").unwrap();
        assert!(check_set_dir(&at("file.tiles")).unwrap_err().to_string().contains("not a directory"));
        std::fs::create_dir(at("empty")).unwrap();
        assert!(check_set_dir(&at("empty")).is_ok());
        std::fs::create_dir(at("user")).unwrap();
        std::fs::write(at("user/notes.txt"), b"mine").unwrap();
        std::fs::write(at("user/d3-1-2-3.olm"), b"mine too").unwrap();
        let e = check_set_dir(&at("user")).unwrap_err().to_string();
        assert!(e.contains("neither named NAME.tiles nor empty nor a tile set"), "{e}");
        std::fs::write(at("user/manifest"), b"my shopping list\n").unwrap();
        let e = check_set_dir(&at("user")).unwrap_err().to_string();
        assert!(e.contains("manifest that is not a tile set's manifest"), "{e}");
        std::fs::create_dir(at("user.tiles")).unwrap();
        std::fs::write(at("user.tiles/task-0-of-2.manifest"), b"not mine\n").unwrap();
        assert!(check_set_dir(&at("user.tiles")).is_err());
        std::fs::create_dir(at("set")).unwrap();
        std::fs::write(at("set/notes.txt"), b"beside a set").unwrap();
        sample().write(&at("set/manifest")).unwrap();
        assert!(check_set_dir(&at("set")).is_ok());
        // a link to a directory is taken as the directory; a FIFO named manifest is not a manifest
        std::os::unix::fs::symlink(at("set"), at("link")).unwrap();
        assert!(check_set_dir(&at("link")).is_ok());
        std::fs::create_dir(at("fifo.tiles")).unwrap();
        make_fifo(&at("fifo.tiles/manifest"));
        let path = at("fifo.tiles");
        assert!(within_seconds(move || check_set_dir(&path).is_err()));
    }

    #[test]
    fn tasks_share_the_tiles() {
        for count in [1, 2, 3, 7] {
            let mut per_task = vec![0; count as usize];
            for p in 0..512 {
                let id = TileId::from_prefix(3, p);
                let k = task_of(id, count);
                per_task[k as usize] += 1;
                assert!(TaskPart::hashed(k, count).owns(id));
            }
            assert!(per_task.iter().all(|&n| n > 0), "{per_task:?}");
        }
    }
}
