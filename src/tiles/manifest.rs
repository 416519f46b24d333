//! The manifest of a tile set: a versioned text file naming the map's
//! parameters (float fields as their bit patterns) and every tile with its
//! file's length, CRC-32, node count and root node. The byte-level format
//! is `formats/tiles.md`; this parser is strict (one spelling per value)
//! and reports the line of the first fault.

use super::id::{TileId, MAX_TILE_DEPTH};
use super::top::TileRoot;
use crate::mapped::HEADER_LEN;
use crate::sensor::SensorModel;
use crate::tree::{NodeKind, TreeKind};
use std::fmt::Write as _;
use std::ops::Range;

/// First line of every manifest, before the version number.
pub const MAGIC: &str = "octolinear-tiles";
/// The manifest version this crate writes and reads.
pub const VERSION: u32 = 1;
/// A tile set's manifest file name inside its directory.
pub const MANIFEST_FILE: &str = "manifest";

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
    /// The tiles, in Morton order.
    pub tiles: Vec<TileEntry>,
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
    pub(super) fn write(&self, path: &std::path::Path) -> Result<(), super::TileError> {
        let bytes = self.to_bytes();
        crate::formats::write_atomically(path, |w| std::io::Write::write_all(w, &bytes))
            .map_err(|e| super::TileError::io(path, e))
    }

    /// The manifest's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut s = format!("{MAGIC} {VERSION}\n");
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
        if version != VERSION {
            return Err(
                lines.fault(format!("manifest version {version} is not supported (this reader reads {VERSION})"))
            );
        }
        let mut next = lines.next()?;
        let task = match next.strip_prefix("task ") {
            Some(rest) => {
                let task = parse_task(rest).ok_or_else(|| {
                    lines.fault(format!(
                        "expected `task K N` or `task K N prefixes START END` with K < N and START < END, found `{}`",
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
        Ok(Manifest { resolution, depth, kind, sensor, task, tiles })
    }
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
    if count == 0 || index >= count || count > u64::from(u32::MAX) {
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
mod tests {
    use super::*;

    fn sample() -> Manifest {
        let root = |value, is_leaf| TileRoot { value, extra: 0, is_leaf };
        Manifest {
            resolution: 0.1,
            depth: 3,
            kind: TreeKind::OcTree,
            sensor: SensorModel::default(),
            task: None,
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
        assert_eq!(with(1, "octolinear-tiles 2").line, 1);
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
