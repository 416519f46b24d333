//! Damaged inputs for every reader: seeded, deterministic mutants of real
//! files (golden `.ot` of each kind, `.bt` including `geb079.bt`, `.graph`,
//! `.xyz`, scan logs, ROS message payloads) and of small trees, PLY, PCD and
//! binvox files made here.
//!
//! Each mutant must give `Ok` or a clean `Err` whose byte offset (or line)
//! lies inside the input and is named by its message; it must never panic,
//! never make a single allocation larger than 64 x its size + 1 MiB (a
//! counting global allocator watches), and never call its reader more than
//! a fixed multiple of its size (no loop without progress). After the parse
//! the matching fuzz target's `check` (compiled in from `fuzz/fuzz_targets`)
//! runs on the same bytes under the same allocation bound: readers of
//! written output, writers of whatever was read.
//!
//! Damaged `.olm` maps also go through the `octolinear` binary, in
//! `cli/tests/damaged_maps.rs`.
//!
//! `OCTOLINEAR_CORRUPTION_DUMP=<dir>` writes every failing mutant there, to
//! be kept under `tests/regressions/<format>/` (replayed by
//! [`regressions_replay`]).

// the fuzz targets below test `cfg(fuzzing)`, which cargo-fuzz sets
#![allow(unexpected_cfgs)]

mod common;
use common::Rng;

#[allow(dead_code)]
#[path = "../fuzz/fuzz_targets/bt.rs"]
mod fuzz_bt;
#[allow(dead_code)]
#[path = "../fuzz/fuzz_targets/graph.rs"]
mod fuzz_graph;
#[allow(dead_code)]
#[path = "../fuzz/fuzz_targets/log.rs"]
mod fuzz_log;
#[allow(dead_code)]
#[path = "../fuzz/fuzz_targets/ot.rs"]
mod fuzz_ot;
#[allow(dead_code)]
#[path = "../fuzz/fuzz_targets/ros.rs"]
mod fuzz_ros;
#[allow(dead_code)]
#[path = "../fuzz/fuzz_targets/xyz.rs"]
mod fuzz_xyz;

#[path = "../fuzz/fuzz_targets/ply.rs"]
mod fuzz_ply;

#[path = "../fuzz/fuzz_targets/pcd.rs"]
mod fuzz_pcd;

#[path = "../fuzz/fuzz_targets/binvox.rs"]
mod fuzz_binvox;

use octolinear::formats::binvox::BinvoxError;
use octolinear::formats::graph::{GraphError, ScanGraph};
use octolinear::formats::log::LogError;
use octolinear::formats::pcd::PcdError;
use octolinear::formats::ply::PlyError;
use octolinear::formats::xyz::XyzError;
use octolinear::formats::{binvox, bt, graph, log, ot, pcd, ply, ros, xyz, TreeFileError};
use octolinear::tree::{Clock, CountingTree, InnerNodes, NodeKind, OccupancyTree};
use octolinear::{Point3, PointCloud, Pose6D, SensorModel};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::{self, BufRead, Read};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------
// Allocation accounting: the largest single allocation on this thread.

struct Tracking;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    let _ = LARGEST.try_with(|c| {
        if size > c.get() {
            c.set(size)
        }
    });
}

// SAFETY: forwards every call to the system allocator unchanged.
unsafe impl GlobalAlloc for Tracking {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        // SAFETY: the caller upholds `GlobalAlloc::realloc`'s contract.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` with `layout`.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Tracking = Tracking;

fn alloc_bound(len: usize) -> usize {
    64 * len + (1 << 20)
}

/// Runs `f` and returns the largest single allocation it made.
fn largest_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    LARGEST.with(|c| c.set(0));
    let out = f();
    (out, LARGEST.with(|c| c.get()))
}

// ---------------------------------------------------------------------------
// A reader that panics when called far more often than its input warrants.

struct Budget<'a> {
    data: &'a [u8],
    pos: usize,
    calls: u64,
    limit: u64,
}

impl<'a> Budget<'a> {
    fn new(data: &'a [u8]) -> Self {
        Budget { data, pos: 0, calls: 0, limit: 4 * data.len() as u64 + 1024 }
    }
    fn tick(&mut self) {
        self.calls += 1;
        assert!(
            self.calls <= self.limit,
            "reader called {} times on {} bytes at byte {}: a loop without progress",
            self.calls,
            self.data.len(),
            self.pos
        );
    }
}

impl Read for Budget<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.tick();
        let n = buf.len().min(self.data.len() - self.pos);
        buf[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

impl BufRead for Budget<'_> {
    fn fill_buf(&mut self) -> io::Result<&[u8]> {
        self.tick();
        Ok(&self.data[self.pos..])
    }
    fn consume(&mut self, n: usize) {
        self.pos = (self.pos + n).min(self.data.len());
    }
}

// ---------------------------------------------------------------------------
// The formats under test.

/// Where an error says the damage is.
enum Place {
    Byte(u64),
    Line(u64),
    Unknown,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Format {
    Ot,
    Bt,
    Graph,
    Xyz,
    Log,
    Ros,
    Ply,
    Pcd,
    Binvox,
}

impl Format {
    fn name(self) -> &'static str {
        match self {
            Format::Ot => "ot",
            Format::Bt => "bt",
            Format::Graph => "graph",
            Format::Xyz => "xyz",
            Format::Log => "log",
            Format::Ros => "ros",
            Format::Ply => "ply",
            Format::Pcd => "pcd",
            Format::Binvox => "binvox",
        }
    }

    /// Parses through a [`Budget`] reader; `Ok(())` or the error's message and place.
    fn parse(self, data: &[u8]) -> Result<(), (String, Place)> {
        fn tree_err(e: TreeFileError) -> (String, Place) {
            let place = match &e {
                TreeFileError::Header { offset, .. }
                | TreeFileError::Truncated { offset, .. }
                | TreeFileError::TooDeep { offset }
                | TreeFileError::SizeMismatch { offset, .. }
                | TreeFileError::WrongFormat { offset, .. } => Place::Byte(*offset),
                TreeFileError::BadResolution { offset, .. } | TreeFileError::UnknownTreeType { offset, .. } => {
                    offset.map_or(Place::Unknown, Place::Byte)
                }
                TreeFileError::Io(_) | TreeFileError::UnsupportedTreeType(_) => Place::Unknown,
            };
            (e.to_string(), place)
        }
        fn graph_err(e: GraphError) -> (String, Place) {
            let place = match &e {
                GraphError::Io { offset, .. }
                | GraphError::Truncated { offset, .. }
                | GraphError::BadMarker { offset, .. }
                | GraphError::CountTooLarge { offset, .. }
                | GraphError::OutOfMemory { offset, .. } => Place::Byte(*offset),
                // errors of files read again, never of bytes in memory
                GraphError::Changed { .. } | GraphError::NotRegular => Place::Unknown,
            };
            (e.to_string(), place)
        }
        match self {
            Format::Ot => ot::read(Budget::new(data)).map(drop).map_err(tree_err),
            Format::Bt => bt::read(Budget::new(data)).map(drop).map_err(tree_err),
            Format::Ros => {
                let Some(msg) = fuzz_ros::message(data) else { return Ok(()) };
                ros::msg_to_map(&msg).map(drop).map_err(|e| {
                    let (text, place) = tree_err(e);
                    // offsets count from the start of `data`, one byte in
                    let place = match place {
                        Place::Byte(o) => Place::Byte(o + 1),
                        p => p,
                    };
                    (text, place)
                })
            }
            Format::Graph => {
                let streamed = graph::read(Budget::new(data)).map(drop).map_err(graph_err);
                let in_memory = graph::read_bytes(data).map(drop).map_err(graph_err);
                match (&streamed, &in_memory) {
                    (Err(_), Ok(())) | (Ok(()), Err(_)) => Err((
                        format!(
                            "streamed {:?} but in memory {:?}",
                            streamed.map_err(|e| e.0),
                            in_memory.map_err(|e| e.0)
                        ),
                        Place::Unknown,
                    )),
                    _ => in_memory.and(streamed),
                }
            }
            Format::Xyz => xyz::read(Budget::new(data)).map(drop).map_err(|e| {
                let line = match &e {
                    XyzError::Io { line, .. }
                    | XyzError::TokenCount { line, .. }
                    | XyzError::NotANumber { line, .. }
                    | XyzError::NotFinite { line, .. }
                    | XyzError::LineTooLong { line, .. } => *line,
                };
                (e.to_string(), Place::Line(line))
            }),
            Format::Log => log::read(Budget::new(data)).map(drop).map_err(|e| {
                let line = match &e {
                    LogError::Io { line, .. }
                    | LogError::PointBeforeNode { line }
                    | LogError::TooFewTokens { line, .. }
                    | LogError::NotANumber { line, .. }
                    | LogError::NotFinite { line, .. }
                    | LogError::LineTooLong { line, .. } => *line,
                };
                (e.to_string(), Place::Line(line))
            }),
            // whole-buffer readers: the allocation bound and the mutant
            // count are what watch their loops
            Format::Ply => ply::read(data, true).map(drop).map_err(|e| {
                let place = match &e {
                    PlyError::HeaderNotText { offset }
                    | PlyError::HeaderLine { offset, .. }
                    | PlyError::DataNotText { offset }
                    | PlyError::Truncated { offset, .. } => Place::Byte(*offset as u64),
                    _ => Place::Unknown,
                };
                (e.to_string(), place)
            }),
            Format::Pcd => pcd::read(data, true).map(drop).map_err(|e| {
                let place = match &e {
                    PcdError::HeaderNotText { offset }
                    | PcdError::BadCount { offset, .. }
                    | PcdError::DataNotText { offset }
                    | PcdError::NoSizeWords { offset } => Place::Byte(*offset as u64),
                    _ => Place::Unknown,
                };
                (e.to_string(), place)
            }),
            Format::Binvox => binvox::read(data).and_then(|bv| bv.for_each_run(|_, _| {})).map_err(|e| {
                let place = match &e {
                    BinvoxError::NotANumber { offset, .. }
                    | BinvoxError::DataEnds { offset, .. }
                    | BinvoxError::Overrun { offset, .. } => Place::Byte(*offset as u64),
                    _ => Place::Unknown,
                };
                (e.to_string(), place)
            }),
        }
    }

    fn check(self) -> fn(&[u8]) {
        match self {
            Format::Ot => fuzz_ot::check,
            Format::Bt => fuzz_bt::check,
            Format::Graph => fuzz_graph::check,
            Format::Xyz => fuzz_xyz::check,
            Format::Log => fuzz_log::check,
            Format::Ros => fuzz_ros::check,
            Format::Ply => fuzz_ply::check,
            Format::Pcd => fuzz_pcd::check,
            Format::Binvox => fuzz_binvox::check,
        }
    }
}

fn panic_text(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(non-string panic)".into())
}

#[derive(Default)]
struct Tally {
    ok: usize,
    err: usize,
    failures: Vec<(String, Vec<u8>)>,
}

impl Tally {
    fn fail(&mut self, what: String, data: &[u8]) {
        self.failures.push((what, data.to_vec()));
    }

    /// One mutant: parse, then the fuzz target's checks.
    fn run(&mut self, format: Format, what: &str, data: &[u8]) {
        let len = data.len();
        let bound = alloc_bound(len);
        let (parsed, largest) = largest_allocation(|| catch_unwind(AssertUnwindSafe(|| format.parse(data))));
        match parsed {
            Err(p) => return self.fail(format!("{what}: parse panicked: {}", panic_text(p)), data),
            Ok(Ok(())) => self.ok += 1,
            Ok(Err((text, place))) => {
                self.err += 1;
                match place {
                    Place::Byte(o) if o > len as u64 => {
                        self.fail(format!("{what}: error offset {o} beyond the {len} bytes: {text}"), data)
                    }
                    Place::Byte(o) if !text.contains(&o.to_string()) && format != Format::Ros => {
                        self.fail(format!("{what}: message does not name offset {o}: {text}"), data)
                    }
                    Place::Line(l) if l > data.iter().filter(|&&b| b == b'\n').count() as u64 + 1 => {
                        self.fail(format!("{what}: error line {l} beyond the input: {text}"), data)
                    }
                    _ => {}
                }
            }
        }
        if largest > bound {
            self.fail(format!("{what}: parse allocated {largest} bytes at once for {len} input bytes"), data);
        }
        let (checked, largest) = largest_allocation(|| catch_unwind(AssertUnwindSafe(|| format.check()(data))));
        if let Err(p) = checked {
            self.fail(format!("{what}: fuzz check panicked: {}", panic_text(p)), data);
        }
        if largest > bound {
            self.fail(format!("{what}: fuzz check allocated {largest} bytes at once for {len} input bytes"), data);
        }
    }

    fn finish(self, format: Format, min_mutants: usize) {
        let total = self.ok + self.err + self.failures.len();
        eprintln!("{}: {} mutants, {} read, {} rejected", format.name(), total, self.ok, self.err);
        if let Some(dir) = std::env::var_os("OCTOLINEAR_CORRUPTION_DUMP") {
            let dir = PathBuf::from(dir).join(format.name());
            std::fs::create_dir_all(&dir).unwrap();
            for (i, (_, data)) in self.failures.iter().enumerate() {
                std::fs::write(dir.join(format!("failure-{i:04}")), data).unwrap();
            }
        }
        let shown: Vec<&str> = self.failures.iter().take(20).map(|(w, _)| w.as_str()).collect();
        assert!(self.failures.is_empty(), "{} failures:\n{}", self.failures.len(), shown.join("\n"));
        assert!(total >= min_mutants, "only {total} mutants");
    }
}

// ---------------------------------------------------------------------------
// Mutants.

/// Offsets worth cutting at: all of a small input, else the start, the
/// end and a sample in between.
fn cut_points(len: usize, rng: &mut Rng, sample: usize) -> Vec<usize> {
    if len <= 2048 {
        return (0..len).collect();
    }
    let mut v: Vec<usize> = (0..512).chain(len - 64..len).collect();
    v.extend((0..sample).map(|_| 512 + rng.below(len - 576)));
    v
}

/// Generic byte-level damage: truncations, bit flips, overwritten runs,
/// deletions, duplications, splices from other files and appended junk.
fn byte_mutants(base: &[u8], others: &[&[u8]], rng: &mut Rng, n: usize, mut emit: impl FnMut(String, Vec<u8>)) {
    for cut in cut_points(base.len(), rng, n) {
        emit(format!("truncated at {cut}"), base[..cut].to_vec());
    }
    let head = base.len().min(256);
    for i in 0..n {
        let mut m = base.to_vec();
        if m.is_empty() {
            break;
        }
        // half of the flips land in the first bytes (header, root)
        let at = if i % 2 == 0 { rng.below(head) } else { rng.below(m.len()) };
        let bit = rng.below(8);
        m[at] ^= 1 << bit;
        emit(format!("bit {bit} of byte {at} flipped"), m);
    }
    for _ in 0..n / 2 {
        let mut m = base.to_vec();
        let flips = 2 + rng.below(30);
        for _ in 0..flips {
            let at = rng.below(m.len());
            m[at] ^= 1 << rng.below(8);
        }
        emit(format!("{flips} random bit flips"), m);
    }
    for _ in 0..n / 2 {
        let mut m = base.to_vec();
        let at = rng.below(m.len());
        let run = (1 + rng.below(8)).min(m.len() - at);
        let fill = [0x00, 0xff, rng.byte(), b'\n', b'#'][rng.below(5)];
        m[at..at + run].fill(fill);
        emit(format!("{run} bytes at {at} set to {fill:#04x}"), m);
    }
    for _ in 0..n / 4 {
        let mut m = base.to_vec();
        let at = rng.below(m.len());
        let run = (1 + rng.below(64)).min(m.len() - at);
        m.drain(at..at + run);
        emit(format!("{run} bytes deleted at {at}"), m);
        let mut m = base.to_vec();
        let dup = m[at..at + run].to_vec();
        m.splice(at..at, dup);
        emit(format!("{run} bytes duplicated at {at}"), m);
    }
    for _ in 0..n / 2 {
        let other = others[rng.below(others.len())];
        if other.is_empty() {
            continue;
        }
        let at = rng.below(base.len() + 1);
        let from = rng.below(other.len());
        let run = (1 + rng.below(512)).min(other.len() - from);
        let mut m = base[..at].to_vec();
        m.extend_from_slice(&other[from..from + run]);
        if rng.below(2) == 0 {
            m.extend_from_slice(&base[at..]);
            emit(format!("{run} bytes of another file inserted at {at}"), m);
        } else {
            m.extend_from_slice(&other[from + run..]);
            emit(format!("cut at {at} and continued with another file from {from}"), m);
        }
    }
    for junk in [&[0u8][..], b"\n", b"\xff\xff\xff\xff", b"garbage after the end\n"] {
        let mut m = base.to_vec();
        m.extend_from_slice(junk);
        emit(format!("{} bytes appended", junk.len()), m);
    }
}

/// Random byte strings, some after a valid prefix.
fn junk_mutants(prefixes: &[&[u8]], rng: &mut Rng, n: usize, mut emit: impl FnMut(String, Vec<u8>)) {
    for i in 0..n {
        let len = [0, 1, 2, 7, 64, 700, 3000][i % 7];
        let prefix = prefixes[rng.below(prefixes.len())];
        let mut m = if i % 2 == 0 { Vec::new() } else { prefix.to_vec() };
        m.extend((0..len).map(|_| rng.byte()));
        emit(format!("{len} random bytes (seeded, #{i})"), m);
    }
}

const SIZES: &[&str] = &[
    "0",
    "1",
    "2",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "-1",
    "1e3",
    "abc",
    "",
];
const RESES: &[&str] =
    &["0", "-0", "-1", "nan", "NaN", "inf", "-inf", "1e308", "1e-320", "1e400", "0x1p-3", "0.1x", ""];
const IDS: &[&str] = &[
    "",
    "1",
    "OcTree",
    "ColorOcTree",
    "OcTreeStamped",
    "OcTreeBase",
    "CountingOcTree",
    "garbage",
    "\u{0}",
    "Oc\u{7f}Tree",
];

/// Splits a `.bt`/`.ot` file after its `data` line.
fn split_header(file: &[u8]) -> (&[u8], &[u8]) {
    let at = file.windows(6).position(|w| w == b"\ndata\n").expect("a data line") + 6;
    file.split_at(at)
}

/// Damage to the text header: lying fields, missing lines, long lines.
fn header_mutants(file: &[u8], mut emit: impl FnMut(String, Vec<u8>)) {
    let (header, body) = split_header(file);
    let text = String::from_utf8(header.to_vec()).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let rebuild = |lines: &[String], body: &[u8]| {
        let mut m = lines.join("\n").into_bytes();
        m.push(b'\n');
        m.extend_from_slice(body);
        m
    };
    let replace = |key: &str, value: Option<&str>| -> Vec<String> {
        lines
            .iter()
            .filter_map(|l| match l.split_once(' ') {
                Some((k, _)) if k == key => value.map(|v| format!("{key} {v}")),
                _ => Some(l.to_string()),
            })
            .collect()
    };
    for v in SIZES {
        emit(format!("size `{v}`"), rebuild(&replace("size", Some(v)), body));
    }
    for v in RESES {
        emit(format!("res `{v}`"), rebuild(&replace("res", Some(v)), body));
    }
    for v in IDS {
        emit(format!("id `{}`", v.escape_debug()), rebuild(&replace("id", Some(v)), body));
    }
    emit("id of 10000 characters".into(), rebuild(&replace("id", Some(&"X".repeat(10_000))), body));
    for key in ["id", "size", "res"] {
        emit(format!("no `{key}` line"), rebuild(&replace(key, None), body));
    }
    let owned: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    let without_data: Vec<String> = owned.iter().filter(|l| *l != "data").cloned().collect();
    emit("no `data` line".into(), rebuild(&without_data, body));
    emit("no `data` line, nothing after".into(), rebuild(&without_data, &[]));
    emit("header only".into(), header.to_vec());
    emit("header without the final newline".into(), header[..header.len() - 1].to_vec());
    for (i, extra) in [
        "# another comment",
        "unknown keyword here",
        "size 1",
        "res 0.5",
        "id OcTree",
        "#",
        "",
        "   ",
        "#no space after hash",
        "data trailing words",
    ]
    .iter()
    .enumerate()
    {
        for at in [1, 3, owned.len() - 1] {
            let mut l = owned.clone();
            l.insert(at.min(l.len()), extra.to_string());
            emit(format!("line `{extra}` inserted at line {at} (#{i})"), rebuild(&l, body));
        }
    }
    let mut l = owned.clone();
    l.insert(1, format!("# {}", "x".repeat(200_000)));
    emit("comment line of 200000 bytes".into(), rebuild(&l, body));
    let mut l = owned.clone();
    l.insert(1, format!("keyword {}", "y".repeat(100_000)));
    emit("unknown keyword line of 100000 bytes".into(), rebuild(&l, body));
    let mut l = owned.clone();
    l[0] = format!("{}{}", l[0], "z".repeat(100_000));
    emit("first line of 100000 bytes".into(), rebuild(&l, body));
    let mut l = owned.clone();
    l.splice(1..1, std::iter::repeat_n("#".to_string(), 20_000));
    emit("20000 comment lines".into(), rebuild(&l, body));
    let mut l = owned.clone();
    l.insert(3, format!("size {}", "9".repeat(5000)));
    emit("size token of 5000 digits".into(), rebuild(&l, body));
    let crlf: Vec<String> = owned.iter().map(|l| format!("{l}\r")).collect();
    emit("CRLF line ends".into(), rebuild(&crlf, body));
    for first in ["# Octomap OcTree file", "# Octomap OcTree binary file", "# Octomap OcTree fil", "", "#"] {
        let mut l = owned.clone();
        l[0] = first.to_string();
        emit(format!("first line `{first}`"), rebuild(&l, body));
    }
}

fn header(first: &str, id: &str, size: &str, res: &str) -> Vec<u8> {
    format!("{first}\n#\nid {id}\nsize {size}\nres {res}\ndata\n").into_bytes()
}

/// Node streams that keep announcing children, or stop early.
fn deep_ot_mutants(mut emit: impl FnMut(String, Vec<u8>)) {
    for (id, payload) in [("OcTree", 4), ("ColorOcTree", 7), ("OcTreeStamped", 4), ("OcTreeBase", 4)] {
        for mask in [0x01u8, 0x80, 0xff, 0x55] {
            for depth in [15usize, 16, 17, 18, 40, 1000] {
                let mut m = header("# Octomap OcTree file", id, "100", "0.1");
                for _ in 0..depth {
                    m.extend(std::iter::repeat_n(0x3f, payload));
                    m.push(mask);
                }
                emit(format!("{id}: {depth} nodes announcing children {mask:#04x}"), m.clone());
                // close the chain with leaves
                m.extend(std::iter::repeat_n(0u8, (payload + 1) * 8 * depth.min(20)));
                emit(format!("{id}: {depth} nodes announcing {mask:#04x}, then leaves"), m);
            }
        }
        for size in ["1", "4294967295"] {
            let mut m = header("# Octomap OcTree file", id, size, "0.1");
            emit(format!("{id}: size {size}, no data"), m.clone());
            m.extend(std::iter::repeat_n(0u8, payload));
            m.push(0xff);
            emit(format!("{id}: size {size}, root announcing 8 children that never come"), m);
        }
    }
}

fn legacy(res: f64, size: u32, body: &[u8]) -> Vec<u8> {
    let mut m = 3i32.to_le_bytes().to_vec();
    m.extend_from_slice(&res.to_le_bytes());
    m.extend_from_slice(&size.to_le_bytes());
    m.extend_from_slice(body);
    m
}

fn deep_bt_mutants(mut emit: impl FnMut(String, Vec<u8>)) {
    for labels in [[0x03u8, 0x00], [0x00, 0xc0], [0xff, 0xff], [0xcc, 0x33]] {
        for depth in [15usize, 16, 17, 40, 1000] {
            let body: Vec<u8> = std::iter::repeat_n(labels, depth).flatten().collect();
            let mut m = header("# Octomap OcTree binary file", "OcTree", "1000", "0.1");
            m.extend_from_slice(&body);
            emit(format!("{depth} nodes labelled {labels:02x?}"), m);
            emit(format!("legacy: {depth} nodes labelled {labels:02x?}"), legacy(0.1, 1000, &body));
        }
    }
    for res in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e308, 1e-320, f64::MIN_POSITIVE] {
        for size in [0u32, 1, 9, u32::MAX] {
            emit(format!("legacy res {res} size {size}"), legacy(res, size, &[0x01, 0x00]));
        }
    }
    for kind in [0i32, 1, 2, 4, -1, i32::MAX] {
        let mut m = legacy(0.1, 1, &[]);
        m[..4].copy_from_slice(&kind.to_le_bytes());
        emit(format!("legacy tree type {kind}"), m);
    }
    for cut in 0..16 {
        emit(format!("legacy header cut at {cut}"), legacy(0.1, 9, &[0x01, 0x00])[..cut].to_vec());
    }
    for size in ["1", "9", "4294967295"] {
        let mut m = header("# Octomap OcTree binary file", "OcTree", size, "0.1");
        emit(format!("size {size}, no data"), m.clone());
        m.extend_from_slice(&[0xff, 0xff]);
        emit(format!("size {size}, root announcing 8 inner children that never come"), m);
    }
}

// ---------------------------------------------------------------------------
// Inputs.

fn load(root: &Path, rel: &str) -> Vec<u8> {
    common::read_maybe_gz(&root.join(rel))
}

fn points() -> Vec<Point3> {
    vec![Point3::new(0.05, 0.05, 0.05), Point3::new(1.0, -0.3, 0.2), Point3::new(-2.0, 0.4, -0.1)]
}

/// Small trees of every kind, built here.
fn small_trees() -> Vec<(String, ot::AnyTree)> {
    let mut out = Vec::new();
    for kind in [NodeKind::Plain, NodeKind::Color, NodeKind::Stamped] {
        for n in 1..=3 {
            let mut t = OccupancyTree::with_kind(0.1, SensorModel::default(), kind).unwrap();
            t.set_clock(Clock::Fixed(1_700_000_000));
            for (i, p) in points().into_iter().take(n).enumerate() {
                t.update_point(p, i != 1, InnerNodes::Update).unwrap();
                if kind == NodeKind::Color {
                    t.set_color(t.key(p).unwrap(), [10 * i as u8, 200, 33]);
                }
            }
            out.push((format!("{kind:?} with {n} voxels"), ot::AnyTree::Occupancy(t)));
        }
    }
    let mut c = CountingTree::new(0.05).unwrap();
    for p in points() {
        c.update(c.key_space().key(p).unwrap());
    }
    out.push(("counting tree".into(), ot::AnyTree::Counting(c)));
    out
}

fn ot_bytes(t: &ot::AnyTree) -> Vec<u8> {
    let mut v = Vec::new();
    match t {
        ot::AnyTree::Occupancy(t) => ot::write(t, &mut v).unwrap(),
        ot::AnyTree::Counting(c) => ot::write_counting(c, &mut v).unwrap(),
    }
    v
}

fn small_graph() -> ScanGraph {
    let mut g = ScanGraph::new();
    g.add_node(points().into_iter().collect(), Pose6D::from_euler(0.5, 0.0, -0.25, 0.1, 0.2, 0.3));
    g.add_node(PointCloud::new(), Pose6D::from_euler(1.0, 1.0, 0.0, 0.0, 0.0, 1.5));
    g.connect_previous();
    g.add_node(points().into_iter().take(1).collect(), Pose6D::from_euler(0.0, 0.0, 0.0, 0.0, 0.0, 0.0));
    g.connect_previous();
    g
}

// ---------------------------------------------------------------------------
// The tests.

#[test]
fn ot_mutants() {
    let mut rng = Rng(0x07_0001);
    let mut tally = Tally::default();
    let mut bases: Vec<(String, Vec<u8>, usize)> =
        small_trees().iter().map(|(name, t)| (format!("small {name}"), ot_bytes(t), 60)).collect();
    let root = octolinear_oracle::golden_dir();
    for (rel, n) in [
        ("cases/delete_syn_room_r0.1/single_before.ot", 60),
        ("cases/delete_syn_room_r0.1/empty.ot", 30),
        ("cases/delete_syn_edges_r0.2/after_deletes.ot", 60),
        ("cases/counting_syn_edges_r0.05/counting.ot", 40),
        ("cases/color_syn_room_r0.1/color.ot.gz", 12),
        ("cases/stamped_syn_room_r0.1/stamped.ot.gz", 12),
    ] {
        bases.push((rel.to_string(), load(&root, rel), n));
    }
    let others: Vec<Vec<u8>> = bases.iter().map(|b| b.1.clone()).collect();
    let others: Vec<&[u8]> = others.iter().map(|v| &v[..]).collect();
    for (name, base, n) in &bases {
        tally.run(Format::Ot, &format!("{name}: intact"), base);
        byte_mutants(base, &others, &mut rng, *n, |what, m| tally.run(Format::Ot, &format!("{name}: {what}"), &m));
        if base.len() < 100_000 {
            header_mutants(base, |what, m| tally.run(Format::Ot, &format!("{name}: {what}"), &m));
        }
    }
    deep_ot_mutants(|what, m| tally.run(Format::Ot, &what, &m));
    let prefixes = [&b"# Octomap OcTree file\nid OcTree\nsize 9\nres 0.1\ndata\n"[..]];
    junk_mutants(&prefixes, &mut rng, 60, |what, m| tally.run(Format::Ot, &what, &m));
    tally.finish(Format::Ot, 3000);
}

#[test]
fn bt_mutants() {
    let mut rng = Rng(0x0b_0001);
    let mut tally = Tally::default();
    let mut bases: Vec<(String, Vec<u8>, usize)> = Vec::new();
    for (name, t) in small_trees() {
        if let ot::AnyTree::Occupancy(t) = t {
            let mut v = Vec::new();
            bt::write(&t, &mut v).unwrap();
            let (_, body) = split_header(&v);
            let body = body.to_vec();
            bases.push((format!("small {name}"), v, 40));
            bases.push((format!("legacy small {name}"), legacy(0.1, t.size() as u32, &body), 20));
        }
    }
    let root = octolinear_oracle::golden_dir();
    for (rel, n) in [
        ("inputs/geb079.bt", 50),
        ("cases/delete_syn_room_r0.1/empty.bt", 30),
        ("cases/bbx_spherical_scan_originout_r0.1_mrm1_d0/tree.bt", 60),
        ("cases/color_syn_room_r0.1/color.bt", 60),
    ] {
        bases.push((rel.to_string(), load(&root, rel), n));
    }
    let others: Vec<Vec<u8>> = bases.iter().map(|b| b.1.clone()).collect();
    let others: Vec<&[u8]> = others.iter().map(|v| &v[..]).collect();
    for (name, base, n) in &bases {
        tally.run(Format::Bt, &format!("{name}: intact"), base);
        byte_mutants(base, &others, &mut rng, *n, |what, m| tally.run(Format::Bt, &format!("{name}: {what}"), &m));
        if base.starts_with(b"#") && base.len() < 100_000 {
            header_mutants(base, |what, m| tally.run(Format::Bt, &format!("{name}: {what}"), &m));
        }
    }
    deep_bt_mutants(|what, m| tally.run(Format::Bt, &what, &m));
    let old = legacy(0.1, 9, &[]);
    let prefixes = [&b"# Octomap OcTree binary file\nid OcTree\nsize 9\nres 0.1\ndata\n"[..], &old[..]];
    junk_mutants(&prefixes, &mut rng, 60, |what, m| tally.run(Format::Bt, &what, &m));
    tally.finish(Format::Bt, 3000);
}

#[test]
fn ros_mutants() {
    let mut rng = Rng(0x2050_0001);
    let mut tally = Tally::default();
    let mut bases: Vec<(String, Vec<u8>)> = Vec::new();
    let encode = |msg: &ros::OctomapMsg| {
        let id = fuzz_ros::IDS.iter().position(|i| *i == msg.id).unwrap() as u8;
        let res = fuzz_ros::RESOLUTIONS.iter().position(|r| *r == msg.resolution).unwrap() as u8;
        let mut v = vec![msg.binary as u8 | id << 1 | res << 4];
        v.extend_from_slice(&msg.data);
        v
    };
    for (name, t) in small_trees() {
        match &t {
            ot::AnyTree::Occupancy(t) => {
                bases.push((format!("binary {name}"), encode(&ros::binary_map_to_msg(t))));
                bases.push((format!("full {name}"), encode(&ros::full_map_to_msg(t))));
            }
            ot::AnyTree::Counting(c) => bases.push((format!("full {name}"), encode(&ros::full_counting_map_to_msg(c)))),
        }
    }
    let root = octolinear_oracle::golden_dir();
    let geb = bt::read(&load(&root, "inputs/geb079.bt")[..]).unwrap();
    bases.push(("binary geb079".into(), encode(&ros::binary_map_to_msg(&geb))));
    let counting = load(&root, "cases/counting_syn_edges_r0.05/counting.ot");
    let mut full = vec![3u8 << 1 | 1 << 4];
    full.extend_from_slice(split_header(&counting).1);
    bases.push(("full counting golden".into(), full));
    let others: Vec<Vec<u8>> = bases.iter().map(|b| b.1.clone()).collect();
    let others: Vec<&[u8]> = others.iter().map(|v| &v[..]).collect();
    for (name, base) in &bases {
        tally.run(Format::Ros, &format!("{name}: intact"), base);
        for sel in 0..=255u8 {
            let mut m = base.clone();
            m[0] = sel;
            tally.run(Format::Ros, &format!("{name}: selector {sel:#04x}"), &m);
        }
        let n = if base.len() > 10_000 { 30 } else { 60 };
        byte_mutants(base, &others, &mut rng, n, |what, m| tally.run(Format::Ros, &format!("{name}: {what}"), &m));
    }
    junk_mutants(&[&[0u8][..], &[1u8]], &mut rng, 100, |what, m| tally.run(Format::Ros, &what, &m));
    tally.finish(Format::Ros, 3000);
}

#[test]
fn graph_mutants() {
    let mut rng = Rng(0x6a_0001);
    let mut tally = Tally::default();
    let mut small = Vec::new();
    graph::write(&small_graph(), &mut small).unwrap();
    let mut bases: Vec<(String, Vec<u8>, usize)> = vec![("small graph with edges".into(), small, 200)];
    let root = octolinear_oracle::golden_dir();
    for (rel, n) in
        [("inputs/syn_mapedge_r010.graph", 150), ("inputs/syn_edges.graph", 100), ("inputs/spherical_scan.graph", 20)]
    {
        bases.push((rel.to_string(), load(&root, rel), n));
    }
    let others: Vec<Vec<u8>> = bases.iter().map(|b| b.1.clone()).collect();
    let others: Vec<&[u8]> = others.iter().map(|v| &v[..]).collect();
    for (name, base, n) in &bases {
        tally.run(Format::Graph, &format!("{name}: intact"), base);
        byte_mutants(base, &others, &mut rng, *n, |what, m| tally.run(Format::Graph, &format!("{name}: {what}"), &m));
        // lying counts: node count, first point count, edge count
        let edge_count_at = base.len() - 4 - graph::read_bytes(base).unwrap().edges.len() * (8 + 64 + 8);
        for (field, at) in [("node count", 0), ("point count", 4), ("edge count", edge_count_at)] {
            for v in [0u32, 1, 2, 1000, 0x7fff_ffff, u32::MAX] {
                let mut m = base.clone();
                m[at..at + 4].copy_from_slice(&v.to_le_bytes());
                tally.run(Format::Graph, &format!("{name}: {field} {v}"), &m);
            }
        }
    }
    junk_mutants(&[&[1, 0, 0, 0][..]], &mut rng, 60, |what, m| tally.run(Format::Graph, &what, &m));
    tally.finish(Format::Graph, 1500);
}

#[test]
fn text_mutants() {
    let mut rng = Rng(0x7e_0001);
    let mut xyz_bases: Vec<(String, Vec<u8>, usize)> =
        vec![("small cloud".into(), b"0.05 0.05 0.05\n1 -0.3 0.2\n-2 0.4 -0.1\n".to_vec(), 150)];
    let mut log_text = Vec::new();
    log::write(&small_graph(), &mut log_text).unwrap();
    let mut log_bases: Vec<(String, Vec<u8>, usize)> = vec![("small log".into(), log_text, 200)];
    let root = octolinear_oracle::golden_dir();
    xyz_bases.push(("syn_mapedge_r010.scan0.xyz".into(), load(&root, "inputs/syn_mapedge_r010.scan0.xyz"), 150));
    xyz_bases.push(("syn_edges.scan0.xyz".into(), load(&root, "inputs/syn_edges.scan0.xyz"), 100));
    let g = graph::read_bytes(&load(&root, "inputs/syn_mapedge_r010.graph")).unwrap();
    let mut text = Vec::new();
    log::write(&g, &mut text).unwrap();
    log_bases.push(("log of syn_mapedge_r010".into(), text, 150));
    let specials: Vec<(&str, Vec<u8>)> = vec![
        ("long line", [b"1 2 ".to_vec(), vec![b'3'; 300_000], b"\n".to_vec()].concat()),
        ("long line without newline", vec![b'7'; 300_000]),
        ("many blank lines", b"\n".repeat(50_000)),
        ("many tokens", b"1 ".repeat(100_000)),
        ("nul bytes", vec![0u8; 5000]),
        ("NODE only", b"NODE\n".to_vec()),
        ("NODE with nan", b"NODE 0 0 0 nan 0 0\n1 2 3\n".to_vec()),
        ("point before node", b"1 2 3\nNODE 0 0 0 0 0 0\n".to_vec()),
        ("overflow", b"1e39 0 0\n".to_vec()),
        ("CR only", b"\r\n\r\n".to_vec()),
        ("invalid utf-8", b"\xff\xfe 1 2\n".to_vec()),
    ];
    for (format, bases) in [(Format::Xyz, &xyz_bases), (Format::Log, &log_bases)] {
        let mut tally = Tally::default();
        let others: Vec<&[u8]> = xyz_bases.iter().chain(log_bases.iter()).map(|b| &b.1[..]).collect();
        for (name, base, n) in bases {
            tally.run(format, &format!("{name}: intact"), base);
            byte_mutants(base, &others, &mut rng, *n, |what, m| tally.run(format, &format!("{name}: {what}"), &m));
        }
        for (what, m) in &specials {
            tally.run(format, what, m);
        }
        junk_mutants(&[b"NODE 0 0 0 0 0 0\n"], &mut rng, 60, |what, m| tally.run(format, &what, &m));
        tally.finish(format, 1000);
    }
}

/// Small PLY files: ASCII with a face element before the vertices and
/// float colours, binary of both byte orders with integer colours.
fn ply_bases() -> Vec<(String, Vec<u8>)> {
    let pts = points();
    let head = |format: &str, color: &str| {
        format!(
            "ply\nformat {format} 1.0\ncomment test\nelement face 2\nproperty list uchar int vertex_indices\n\
             element vertex {}\nproperty float x\nproperty {color} red\nproperty float y\nproperty float z\n\
             property {color} green\nproperty {color} blue\nend_header\n",
            pts.len()
        )
        .into_bytes()
    };
    let mut ascii = head("ascii", "float");
    ascii.extend_from_slice(b"3 0 1 2\n4 0 1 2 3\n");
    for (i, p) in pts.iter().enumerate() {
        let c = (i % 5) as f32 / 4.0;
        ascii.extend_from_slice(format!("{} {c} {} {} 0.5 1\n", p.x, p.y, p.z).as_bytes());
    }
    let mut files = vec![("ascii ply".to_string(), ascii)];
    for (name, little) in [("binary_little_endian", true), ("binary_big_endian", false)] {
        let mut f = head(name, "uchar");
        let int = |v: i32| if little { v.to_le_bytes() } else { v.to_be_bytes() };
        let float = |v: f32| if little { v.to_le_bytes() } else { v.to_be_bytes() };
        for face in [&[0, 1, 2][..], &[0, 1, 2, 3]] {
            f.push(face.len() as u8);
            face.iter().for_each(|&i| f.extend_from_slice(&int(i)));
        }
        for (i, p) in pts.iter().enumerate() {
            f.extend_from_slice(&float(p.x));
            f.push(i as u8);
            f.extend_from_slice(&float(p.y));
            f.extend_from_slice(&float(p.z));
            f.extend_from_slice(&[200, 7]);
        }
        files.push((format!("{name} ply"), f));
    }
    files
}

/// Small PCD files of the three data kinds, with a packed colour and a
/// field of COUNT 2.
fn pcd_bases() -> Vec<(String, Vec<u8>)> {
    let pts = points();
    let n = pts.len();
    let head = |kind: &str| {
        format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb normal\nSIZE 4 4 4 4 2\nTYPE F F F U I\nCOUNT 1 1 1 1 2\n\
             WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {kind}\n"
        )
        .into_bytes()
    };
    let rgb = |i: usize| 0x0010_2030u32 + i as u32;
    let mut ascii = head("ascii");
    for (i, p) in pts.iter().enumerate() {
        ascii.extend_from_slice(format!("{} {} {} {} -1 {i}\n", p.x, p.y, p.z, rgb(i)).as_bytes());
    }
    let fields = |i: usize, p: &Point3| -> [Vec<u8>; 5] {
        [
            p.x.to_le_bytes().to_vec(),
            p.y.to_le_bytes().to_vec(),
            p.z.to_le_bytes().to_vec(),
            rgb(i).to_le_bytes().to_vec(),
            [(-1i16).to_le_bytes(), (i as i16).to_le_bytes()].concat(),
        ]
    };
    let mut binary = head("binary");
    for (i, p) in pts.iter().enumerate() {
        fields(i, p).iter().for_each(|f| binary.extend_from_slice(f));
    }
    let mut soa = Vec::new();
    for f in 0..5 {
        for (i, p) in pts.iter().enumerate() {
            soa.extend_from_slice(&fields(i, p)[f]);
        }
    }
    let comp = common::lzf_compress(&soa);
    let mut compressed = head("binary_compressed");
    compressed.extend_from_slice(&(comp.len() as u32).to_le_bytes());
    compressed.extend_from_slice(&(soa.len() as u32).to_le_bytes());
    compressed.extend_from_slice(&comp);
    vec![("ascii pcd".into(), ascii), ("binary pcd".into(), binary), ("compressed pcd".into(), compressed)]
}

/// A small binvox grid with runs of both values.
fn binvox_base() -> Vec<u8> {
    let mut f = b"#binvox 1\ndim 6 5 4\ntranslate -0.5 0.25 1\nscale 1.5\ndata\n".to_vec();
    f.extend_from_slice(&[0, 17, 1, 40, 0, 3, 1, 60]);
    f
}

#[test]
fn point_file_and_grid_mutants() {
    let mut rng = Rng(0x7e_0002);
    let ply = ply_bases();
    let pcd = pcd_bases();
    let grid = vec![("binvox grid".to_string(), binvox_base())];
    let specials: Vec<(&str, Vec<u8>)> = vec![
        ("ply: huge empty element", b"ply\nformat ascii 1.0\nelement e 18446744073709551615\nend_header\n".to_vec()),
        (
            "ply: huge list",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty list uint float x\nend_header\n\xff\xff\xff\xff"
                .to_vec(),
        ),
        ("pcd: lying LZF size", [&pcd[2].1[..pcd[2].1.len() - 1], &[0xff]].concat()),
        ("binvox: huge grid", b"#binvox 1\ndim 2000000 2000000 2000000\ndata\n\x01\xff".to_vec()),
    ];
    for (format, bases, floor) in [(Format::Ply, &ply, 1000), (Format::Pcd, &pcd, 1000), (Format::Binvox, &grid, 300)] {
        let mut tally = Tally::default();
        let others: Vec<&[u8]> = ply.iter().chain(&pcd).chain(&grid).map(|b| &b.1[..]).collect();
        for (name, base) in bases {
            tally.run(format, &format!("{name}: intact"), base);
            byte_mutants(base, &others, &mut rng, 150, |what, m| tally.run(format, &format!("{name}: {what}"), &m));
        }
        for (what, m) in &specials {
            tally.run(format, what, m);
        }
        let prefix = &bases[0].1[..bases[0].1.iter().position(|&b| b == b'\n').unwrap() + 1];
        junk_mutants(&[prefix], &mut rng, 60, |what, m| tally.run(format, &what, &m));
        tally.finish(format, floor);
    }
}

/// Inputs kept under `tests/regressions/<format>/` (crashes found by
/// fuzzing or by the mutants above) must now read cleanly.
#[test]
fn regressions_replay() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/regressions");
    for format in [
        Format::Ot,
        Format::Bt,
        Format::Graph,
        Format::Xyz,
        Format::Log,
        Format::Ros,
        Format::Ply,
        Format::Pcd,
        Format::Binvox,
    ] {
        let mut tally = Tally::default();
        let Ok(entries) = std::fs::read_dir(dir.join(format.name())) else { continue };
        let mut paths: Vec<PathBuf> = entries.map(|e| e.unwrap().path()).collect();
        paths.sort();
        for p in paths {
            tally.run(format, &p.display().to_string(), &std::fs::read(&p).unwrap());
        }
        tally.finish(format, 0);
    }
}

/// Every error the damaged headers give names its offset in its message.
#[test]
fn errors_name_their_offsets() {
    let cases: &[(&[u8], &str)] = &[
        (b"# Octomap OcTree file\nid OcTree\nsize 1\nres 0\ndata\n", "at byte 43"),
        (b"# Octomap OcTree file\nid Nope\nsize 1\nres 0.1\ndata\n", "at byte 25"),
        (b"# Octomap OcTree file\nid OcTree\nsize 1\nres 0.1\n", "at byte 47"),
        (b"# Octomap OcTree file\nid OcTree\nsize 1\nres 0.1\ndata\n\0\0\0", "at byte 52"),
        (b"# Octomap OcTree binary file\nid OcTree\nsize 1\nres 0.1\ndata\n", "at byte 0"),
        (b"garbage", "at byte 0"),
    ];
    for (data, needle) in cases {
        let e = ot::read(&data[..]).unwrap_err().to_string();
        assert!(e.contains(needle), "{e:?} lacks {needle:?}");
    }
    let e = bt::read(&b"# Octomap OcTree binary file\nid OcTree\nsize 7\nres 0.1\ndata\n\x01\x00"[..])
        .unwrap_err()
        .to_string();
    assert!(e.contains("byte 61") && e.contains("announces 7") && e.contains("holds 2"), "{e}");
    let e = bt::read(&legacy(-1.0, 1, &[])[..]).unwrap_err().to_string();
    assert!(e.contains("at byte 4"), "{e}");
}

/// The harness itself notices big allocations and readers that loop.
#[test]
fn harness_sees_allocations_and_loops() {
    let (v, largest) = largest_allocation(|| vec![1u8; 5 << 20]);
    assert!(largest >= 5 << 20 && v.len() == 5 << 20);
    let looped = catch_unwind(|| {
        let mut r = Budget::new(b"abc");
        loop {
            let _ = r.fill_buf();
        }
    });
    assert!(panic_text(looped.unwrap_err()).contains("without progress"));
}

/// The tiny trees whose bytes `formats/bt.md`, `ot.md` and `ros.md` show:
/// resolution 1, voxel (0.5, 0.5, 0.5) hit once, its +x neighbour
/// (1.5, 0.5, 0.5) seen free once.
fn example_tree(kind: NodeKind) -> OccupancyTree {
    let mut t = OccupancyTree::with_kind(1.0, SensorModel::default(), kind).unwrap();
    t.set_clock(Clock::Fixed(0));
    t.update_point(Point3::new(0.5, 0.5, 0.5), true, InnerNodes::Update).unwrap();
    t.update_point(Point3::new(1.5, 0.5, 0.5), false, InnerNodes::Update).unwrap();
    if kind == NodeKind::Color {
        t.set_color(t.key(Point3::new(0.5, 0.5, 0.5)).unwrap(), [255, 0, 0]);
        t.update_inner_occupancy();
    }
    t
}

/// `xxd` output (16 bytes a line, 2-byte groups, ASCII column).
fn xxd(bytes: &[u8]) -> String {
    let mut out = String::new();
    for (i, line) in bytes.chunks(16).enumerate() {
        let mut hex = String::new();
        for (j, b) in line.iter().enumerate() {
            if j > 0 && j % 2 == 0 {
                hex.push(' ');
            }
            hex += &format!("{b:02x}");
        }
        let ascii: String = line.iter().map(|&b| if (0x20..0x7f).contains(&b) { b as char } else { '.' }).collect();
        out += &format!("{:08x}: {hex:<39}  {ascii}\n", i * 16);
    }
    out
}

/// The hex dumps in the format documents are what the library writes.
#[test]
fn doc_examples_match_the_library() {
    let doc =
        |name: &str| std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("formats").join(name)).unwrap();
    let plain = example_tree(NodeKind::Plain);
    let color = example_tree(NodeKind::Color);
    let mut bt_file = Vec::new();
    bt::write(&plain, &mut bt_file).unwrap();
    let mut ot_file = Vec::new();
    ot::write(&plain, &mut ot_file).unwrap();
    let mut color_ot = Vec::new();
    ot::write(&color, &mut color_ot).unwrap();
    let msg = ros::binary_map_to_msg_compact(&plain);
    let full = ros::full_map_to_msg(&plain);
    assert!(bt_file.ends_with(&msg.data) && ot_file.ends_with(&full.data));
    assert_eq!(ros::binary_map_to_msg(&plain).data, msg.data, "the example tree is already minimal");
    if let Some(dir) = std::env::var_os("OCTOLINEAR_WRITE_EXAMPLES") {
        let dir = PathBuf::from(dir);
        std::fs::write(dir.join("example.bt"), &bt_file).unwrap();
        std::fs::write(dir.join("example.ot"), &ot_file).unwrap();
        std::fs::write(dir.join("example_color.ot"), &color_ot).unwrap();
        std::fs::write(dir.join("example_binary_msg.bin"), &msg.data).unwrap();
        std::fs::write(dir.join("example_full_msg.bin"), &full.data).unwrap();
    }
    for (name, bytes) in
        [("bt.md", &bt_file), ("ot.md", &ot_file), ("ot.md", &color_ot), ("ros.md", &msg.data), ("ros.md", &full.data)]
    {
        let dump = xxd(bytes);
        assert!(doc(name).contains(&dump), "formats/{name} lacks this dump:\n{dump}");
    }
}
