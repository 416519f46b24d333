//! `.olm`: a native read-only map format queried in place, with no parse
//! step. The file is memory-mapped (or any byte buffer is borrowed) and
//! OctoMap's queries — `search`, leaf and box iteration, `castRay` — run
//! directly on its bytes, answering exactly as the in-memory
//! [`OccupancyTree`] does.
//!
//! The byte layout is specified in `formats/olm.md`. In short: a 256-byte
//! header (magic, version, endianness check, tree kind, variant,
//! resolution, sensor model, OctoMap's `size()` counter, node counts,
//! section table with CRC-32s, header CRC-32) and 64-byte-aligned
//! sections. The full variant keeps nodes in breadth-first order (each
//! level in Morton order) as a child-mask array, a log-odds array and a
//! rank directory; the children of node `i` are contiguous and start at
//! `1 + rank(i)`. The maximum-likelihood variant keeps `.bt`'s two-bit
//! child labels per inner node, one occupancy bit per inner node and a
//! rank directory over the labels.
//!
//! ```
//! use octolinear::{mapped, OccupancyTree, Point3, ScanOptions};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut tree = OccupancyTree::new(0.1)?;
//! let scan = [Point3::new(2.0, 0.5, 0.3)];
//! tree.insert_point_cloud(&scan, Point3::new(0.0, 0.0, 0.0), &ScanOptions::default())?;
//! let bytes = mapped::to_bytes(&tree, mapped::WriteOptions::default())?;
//! let map = mapped::MappedMap::new(&bytes[..])?; // O(1) header checks
//! map.verify()?; // optional O(n) walk: checksums and structure
//! let view = map.view();
//! let p = Point3::new(2.0, 0.5, 0.3);
//! assert_eq!(view.search_point(p, 0)?, tree.search_point(p, 0)?);
//! assert_eq!(view.leaves(0).count(), tree.leaves(0).count());
//! # Ok(()) }
//! ```
//!
//! # What an unverified map answers
//!
//! Opening ([`open`], [`MappedMap::new`]) is O(1): it checks the header
//! (its CRC-32 and every field), that the file is as long as the header
//! says, and that each section lies inside the file with the length the
//! node counts require. It reads no node and computes no section checksum.
//!
//! Queries on such a map are memory-safe whatever the sections hold: every
//! read is a bounds-checked copy of bytes into an integer (no pointer casts;
//! the only `unsafe` is the mapping in [`MappedMap::open`] and the
//! `SIGBUS` handler of [`guard_truncated_files`]), a search
//! descends at most 16 levels and an iteration visits at most the announced
//! node count, so no query panics, reads outside the bytes or loops without
//! bound. What nothing checks is that the bytes are the ones written: in a
//! damaged file a flipped bit in a log-odds value turns a free voxel
//! occupied or the reverse, one in a child mask makes known space unknown or
//! adds nodes that were never there, colours, stamps and counts may be
//! wrong, iterations may miss or repeat voxels, and [`MapView::search`] and
//! [`MapView::search_many`] may disagree. These answers are silently wrong.
//!
//! [`MapView::verify`] (O(file size): every checksum, the padding, the
//! index and the tree structure) rules that out: a map that passes
//! describes exactly one tree and every query answers as that tree. Verify
//! once after opening unless the file is trusted (written by this process,
//! or verified before and not changed since); [`MapView::to_tree`] and
//! [`read_file`] always verify.
//!
//! # Files changed while mapped
//!
//! A mapping shows the file as it is now, not as it was when opened. The
//! writers here ([`write_file`]) write a temporary file and rename it over
//! the old one: a mapping of the old file keeps that file (its inode) alive
//! and unchanged, so replacing a map under a reader is safe. Changing it in
//! place is not. A file rewritten in place changes the bytes under the
//! reader, which then answers as from a damaged file (above). When another
//! process truncates a mapped file, a read of a page past its new end
//! raises `SIGBUS`, which kills the process unless it handles the signal.
//!
//! A program that maps files it does not control (an embedding
//! interpreter, a server) either reads them instead ([`read_file`], or
//! [`MappedMap::new`] over the bytes read into memory), or installs the
//! crate's handler once at start, [`guard_truncated_files`]. The crate
//! registers every mapping it makes (`.olm` maps opened with [`open`],
//! the windows of a `.graph` file read through
//! [`GraphInput`](crate::formats::graph::GraphInput)); with the handler
//! installed, a read past the end of a truncated registered mapping
//! completes with zeros instead, and the mapping is marked truncated. The
//! answers computed from it since are unreliable: after each piece of work
//! on a mapped map call [`MappedMap::check_mapping`] and discard the work
//! when it returns [`Truncated`] (later calls return it too, at once);
//! [`MappedMap::verify`], [`MappedMap::to_tree`] and
//! [`MappedMap::to_counting_tree`] check it themselves, and a `.graph`
//! reader fails with an I/O error at its next read
//! ([`GraphInput::watch`](crate::formats::graph::GraphInput::watch) for the
//! bytes it has already lent). Reading zeros is safe: every read of the
//! bytes is bounds-checked (see above). A `SIGBUS` outside the crate's
//! mappings still goes to the handler installed before, or kills the
//! process. The `octolinear` tool installs [`exit_on_truncated_files`]
//! instead, which reports the file and exits with status 1.

// the signal handler and its registry of mappings
#[allow(unsafe_code)]
pub(crate) mod fault;
pub mod format;
#[allow(unsafe_code)]
pub(crate) mod mapping;
mod nav;
mod query;
mod search_blocks;
mod verify;
mod write;

pub use fault::{exit_on_truncated_files, guard_truncated_files, Truncated};
pub use format::{
    Header, Index, Section, SectionKind, TreeKind, Variant, HEADER_LEN, MAGIC, VERSION_MAJOR, VERSION_MINOR,
};
pub use query::{cast_ray, OccupancyLookup};
pub use verify::VerifyReport;
pub use write::{
    counting_to_bytes, to_bytes, write, write_counting, write_counting_file, write_file, write_file_with,
    SearchBlocksSection, WriteOptions,
};

use crate::geometry::Point3;
use crate::key::{Key, KeyError, KeySpace, TREE_DEPTH};
use crate::ray::{CastError, CastOptions, CastOutcome};
use crate::sensor::SensorModel;
use crate::tree::{
    CountingTree, Found, KeyBox, LevelTables, NodeItem, OccupancyTree, PathSearch, PreorderBuilder, Trunks,
};
use format::Meta;
use nav::{with_nav, AnyNav, Extras, MlNav, Nav, Node, PtrNav, RankNav};
use query::RawIter;
use search_blocks::SearchBlocks;
use std::io;
use std::path::Path;
use std::sync::Arc;

/// Why an `.olm` file was refused.
#[derive(Debug, thiserror::Error)]
pub enum OlmError {
    /// Opening, mapping or reading the file failed.
    #[error("I/O error")]
    Io(#[from] io::Error),
    /// The first eight bytes are not [`MAGIC`].
    #[error("not an .olm file (magic bytes differ)")]
    BadMagic,
    /// The file is shorter than the fixed header.
    #[error("file is {len} bytes, shorter than the {need}-byte header")]
    TooShort {
        /// Length of the file in bytes.
        len: u64,
        /// Length of the header in bytes ([`HEADER_LEN`]).
        need: u64,
    },
    /// The major version is not [`VERSION_MAJOR`].
    #[error("format version {major}.{minor} is not supported (this reader reads {VERSION_MAJOR}.x)")]
    Version {
        /// Major version the file states.
        major: u16,
        /// Minor version the file states.
        minor: u16,
    },
    /// The endianness check word (byte 12) does not read as `0x0A0B0C0D`.
    #[error("endianness check word reads {found:#010x}, expected 0x0a0b0c0d (file written big-endian or corrupted)")]
    Endianness {
        /// The word read, little-endian.
        found: u32,
    },
    /// The CRC-32 of the header bytes before the checksum field (byte 252)
    /// differs from the one stored there.
    #[error("header checksum mismatch: stored {stored:#010x}, computed {computed:#010x}")]
    HeaderChecksum {
        /// Checksum stored in the header.
        stored: u32,
        /// Checksum of the header bytes as they are.
        computed: u32,
    },
    /// A header field holds a value out of range or inconsistent with the
    /// others.
    #[error("header field {field} is invalid: {value}")]
    BadField {
        /// The field's name, e.g. "resolution" or "inner_count".
        field: &'static str,
        /// The value found, or why it is inconsistent.
        value: String,
    },
    /// The file's length differs from the header's `file_length`.
    #[error("file is {actual} bytes but its header says {header} (truncated or extended)")]
    FileLength {
        /// Length the header states, in bytes.
        header: u64,
        /// Actual length of the file, in bytes.
        actual: u64,
    },
    /// A section is misplaced, missing, duplicated, of the wrong length,
    /// unknown and not optional, or holds invalid contents.
    #[error("{} section (kind {kind}): {reason}", section_name(*kind))]
    Section {
        /// The section's [`SectionKind`] id.
        kind: u16,
        /// What is wrong with it.
        reason: String,
    },
    /// A section's CRC-32 differs from the one in its table entry.
    #[error("{} section (kind {kind}): checksum mismatch (stored {stored:#010x}, computed {computed:#010x})", section_name(*kind))]
    SectionChecksum {
        /// The section's [`SectionKind`] id.
        kind: u16,
        /// Checksum stored in the section table.
        stored: u32,
        /// Checksum of the section's bytes as they are.
        computed: u32,
    },
    /// The mapped file was truncated while it was read ([`guard_truncated_files`]).
    #[error(transparent)]
    Truncated(#[from] Truncated),
    /// The nodes do not form a valid tree (found by verification or while
    /// building an in-memory tree).
    #[error("inconsistent tree structure: {0}")]
    Structure(String),
    /// The map's tree type does not suit the operation, e.g.
    /// [`MapView::to_tree`] on a counting map.
    #[error("this is a {found:?} map: {hint}")]
    Kind {
        /// The map's tree type.
        found: TreeKind,
        /// What to do instead.
        hint: &'static str,
    },
}

/// A section kind's name for messages, or `unknown` for a kind this reader
/// does not know.
fn section_name(kind: u16) -> &'static str {
    SectionKind::from_id(kind).map_or("unknown", SectionKind::name)
}

/// An `.olm` map over bytes it owns or borrows: `Vec<u8>`, `&[u8]`,
/// `&'static [u8]` or a [`memmap2::Mmap`] ([`MappedMap::open`]).
/// Construction checks the header only (O(1)); queries go through
/// [`MappedMap::view`].
pub struct MappedMap<D> {
    /// The mapping's registration, dropped before `data` unmaps it
    /// (fields drop in order); `None` for bytes that are not a mapping.
    guard: Option<MapGuard>,
    data: D,
    meta: Meta,
}

/// A mapping's entry in the crate's registry ([`guard_truncated_files`]).
struct MapGuard {
    _registration: Option<fault::Registration>,
    mark: Arc<fault::Mark>,
}

/// Whether a mapped file was found truncated: a handle that outlives the
/// mappings of the file (a `.graph` reader maps one window after another),
/// from [`GraphInput::watch`](crate::formats::graph::GraphInput::watch).
#[derive(Clone)]
pub struct MappingWatch(Arc<fault::Mark>);

impl MappingWatch {
    /// A watch of the file at `path` (`None`: unknown).
    pub(crate) fn new(path: Option<&Path>) -> Self {
        MappingWatch(fault::Mark::new(path))
    }

    /// Registers a mapping of the watched file; drop the registration
    /// before unmapping it.
    pub(crate) fn register(&self, bytes: &[u8]) -> Option<fault::Registration> {
        fault::register(bytes, &self.0)
    }

    /// `Err` once a read of a mapping of the file faulted past its end
    /// (only with [`guard_truncated_files`] installed; without it the
    /// process died).
    pub fn check(&self) -> Result<(), Truncated> {
        self.0.check()
    }

    /// The watched file, when known.
    pub fn path(&self) -> Option<&Path> {
        self.0.path()
    }
}

impl std::fmt::Debug for MappingWatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MappingWatch").field("path", &self.path()).field("check", &self.check()).finish()
    }
}

impl<D: AsRef<[u8]>> MappedMap<D> {
    /// Checks the header (O(1)) and keeps the bytes.
    pub fn new(data: D) -> Result<Self, OlmError> {
        let meta = format::parse(data.as_ref())?;
        Ok(MappedMap { guard: None, data, meta })
    }

    /// `Err(`[`Truncated`]`)` once a read of the map's mapping faulted past
    /// the end of its file, truncated in place (with
    /// [`guard_truncated_files`] installed): every answer since may come
    /// from zeros. `Ok` for a map over bytes in memory.
    pub fn check_mapping(&self) -> Result<(), Truncated> {
        self.guard.as_ref().map_or(Ok(()), |g| g.mark.check())
    }

    /// `result`, unless the mapping was found truncated meanwhile.
    fn checked<T>(&self, result: Result<T, OlmError>) -> Result<T, OlmError> {
        self.check_mapping()?;
        result
    }

    /// A cheap, copyable handle for queries. Its answers are those of the
    /// bytes as they are: right only if [`Self::verify`] passed or the file
    /// is trusted (module docs).
    #[inline]
    pub fn view(&self) -> MapView<'_> {
        MapView::from_parts(self.data.as_ref(), &self.meta)
    }

    /// The parsed header.
    pub fn header(&self) -> &Header {
        &self.meta.header
    }

    /// The whole file's bytes.
    pub fn bytes(&self) -> &[u8] {
        self.data.as_ref()
    }

    /// Gives back the bytes the map was made from (a mapping given back
    /// is no longer registered: see [`guard_truncated_files`]).
    pub fn into_inner(self) -> D {
        let MappedMap { guard, data, .. } = self;
        drop(guard);
        data
    }

    /// See [`MapView::verify`]; [`OlmError::Truncated`] when the mapping
    /// was found truncated ([`Self::check_mapping`]).
    pub fn verify(&self) -> Result<VerifyReport, OlmError> {
        self.checked(self.view().verify())
    }

    /// See [`MapView::search`].
    #[inline]
    pub fn search(&self, key: Key, depth: u8) -> Option<Found> {
        self.view().search(key, depth)
    }

    /// See [`MapView::search_many`].
    pub fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>) {
        self.view().search_many(keys, depth, out)
    }

    /// See [`MapView::search_point`].
    pub fn search_point(&self, p: Point3, depth: u8) -> Result<Option<Found>, KeyError> {
        self.view().search_point(p, depth)
    }

    /// See [`MapView::to_tree`]; [`OlmError::Truncated`] as for
    /// [`Self::verify`].
    pub fn to_tree(&self) -> Result<OccupancyTree, OlmError> {
        self.checked(self.view().to_tree())
    }

    /// See [`MapView::to_counting_tree`]; [`OlmError::Truncated`] as for
    /// [`Self::verify`].
    pub fn to_counting_tree(&self) -> Result<CountingTree, OlmError> {
        self.checked(self.view().to_counting_tree())
    }
}

impl MappedMap<memmap2::Mmap> {
    /// Memory-maps the file at `path` and checks its header (O(1): nothing
    /// beyond the header is read until queried). The nodes are not checked:
    /// see the module docs for what an unverified map can answer, and
    /// [`Self::verify`].
    ///
    /// The mapping is made in the module's fenced `unsafe` code.
    /// Assumption: the file is not truncated or modified in place while
    /// mapped. Writers in this crate never modify a file in place (they
    /// write a temporary file and rename it over the old one, so a mapping
    /// keeps the old contents). If another process breaks the assumption,
    /// modification makes the bytes change under the reader; all reads are
    /// bounds-checked copies of bytes into integers, so changed contents
    /// can only produce wrong answers. Truncation makes reads past the new
    /// end fault (`SIGBUS`): see the module docs, [`guard_truncated_files`]
    /// and [`Self::check_mapping`].
    pub fn open(path: &Path) -> Result<Self, OlmError> {
        let file = std::fs::File::open(path)?;
        let data = mapping::map_read_only(&file)?;
        let watch = MappingWatch::new(Some(path));
        // declared after `data`, so dropped (unregistered) before it on an error
        let registration = watch.register(&data);
        let parsed = format::parse(&data);
        watch.check()?;
        let meta = parsed?;
        Ok(MappedMap { guard: Some(MapGuard { _registration: registration, mark: watch.0 }), data, meta })
    }
}

/// Opens an `.olm` file by memory mapping ([`MappedMap::open`]): O(1),
/// header checks only, so that huge maps open at once; call
/// [`MappedMap::verify`] before trusting the answers of a file that may be
/// damaged (module docs).
pub fn open(path: &Path) -> Result<MappedMap<memmap2::Mmap>, OlmError> {
    MappedMap::open(path)
}

/// Reads an `.olm` file into an in-memory tree (open, verify, convert).
pub fn read_file(path: &Path) -> Result<OccupancyTree, OlmError> {
    open(path)?.to_tree()
}

/// Queries on a mapped file. Copyable; borrows the bytes and the parsed header.
#[derive(Clone, Copy)]
pub struct MapView<'a> {
    data: &'a [u8],
    meta: &'a Meta,
    nav: AnyNav<'a>,
    extras: Extras<'a>,
    /// The search-blocks section, when the file has one.
    blocks: Option<SearchBlocks<'a>>,
}

/// Depth-first iteration over a mapped file, in OctoMap's order.
pub struct MapIter<'a>(IterInner<'a>);

enum IterInner<'a> {
    Rank(RawIter<'a, RankNav<'a>>),
    Ptr(RawIter<'a, PtrNav<'a>>),
    /// Boxed: its frames hold listed children, three times the others' size.
    Ml(Box<RawIter<'a, MlNav<'a>>>),
}

impl<'a> Iterator for MapIter<'a> {
    type Item = NodeItem<'a>;

    #[inline]
    fn next(&mut self) -> Option<NodeItem<'a>> {
        match &mut self.0 {
            IterInner::Rank(i) => i.next_item(),
            IterInner::Ptr(i) => i.next_item(),
            IterInner::Ml(i) => i.next_item(),
        }
    }

    /// One match on the layout, then a loop without it.
    #[inline]
    fn fold<B, F: FnMut(B, Self::Item) -> B>(self, init: B, mut f: F) -> B {
        fn run<'a, N: Nav, B>(i: RawIter<'a, N>, acc: B, f: &mut impl FnMut(B, NodeItem<'a>) -> B) -> B {
            i.fold(acc, f)
        }
        match self.0 {
            IterInner::Rank(i) => run(i, init, &mut f),
            IterInner::Ptr(i) => run(i, init, &mut f),
            IterInner::Ml(i) => run(*i, init, &mut f),
        }
    }
}

impl<'a> MapView<'a> {
    fn from_parts(data: &'a [u8], meta: &'a Meta) -> Self {
        // checked when the map was opened
        let blocks = data
            .get(meta.ranges.search_blocks.clone())
            .filter(|b| !b.is_empty())
            .and_then(|b| SearchBlocks::parse(b, meta.header.node_count).ok());
        MapView { data, meta, nav: AnyNav::new(data, meta), extras: Extras::new(data, meta), blocks }
    }

    /// The parsed header.
    pub fn header(&self) -> &'a Header {
        &self.meta.header
    }

    /// The search starts ([`query::trunks`]), derived once per map.
    #[inline]
    fn trunks(&self) -> Option<&'a Trunks<Node>> {
        self.meta.trunks.get_or_init(|| with_nav!(self.nav, |nav| query::trunks(nav))).as_ref()
    }

    /// The whole file's bytes.
    pub fn bytes(&self) -> &'a [u8] {
        self.data
    }

    /// Voxel edge length in metres.
    pub fn resolution(&self) -> f64 {
        self.meta.header.resolution
    }

    /// The sensor model stored with the map (all zero for a counting map).
    pub fn sensor(&self) -> &'a SensorModel {
        &self.meta.header.sensor
    }

    /// The key space of the map's resolution (point to key conversions).
    pub fn key_space(&self) -> &'a KeySpace {
        &self.meta.keys
    }

    /// What each node holds: full log-odds or maximum likelihood.
    pub fn variant(&self) -> Variant {
        self.meta.header.variant
    }

    /// `OcTree`, `ColorOcTree` or `OcTreeStamped`.
    pub fn kind(&self) -> TreeKind {
        self.meta.header.kind
    }

    /// OctoMap's `size()` counter of the tree that was written.
    pub fn size_counter(&self) -> u64 {
        self.meta.header.size_counter
    }

    /// Number of nodes stored.
    pub fn node_count(&self) -> u64 {
        self.meta.header.node_count
    }

    /// Whether the map has no nodes at all.
    pub fn is_empty(&self) -> bool {
        self.meta.header.node_count == 0
    }

    /// Whether a log-odds `value` counts as occupied: at or above the
    /// stored sensor model's occupancy threshold.
    pub fn is_occupied(&self, value: f32) -> bool {
        self.meta.header.sensor.is_occupied(value)
    }

    /// The key of the voxel containing `p`.
    #[inline]
    pub fn key(&self, p: Point3) -> Result<Key, KeyError> {
        self.meta.keys.key(p)
    }

    /// Checks every byte: section checksums, padding, the rank directory
    /// or child pointers, and that the nodes form one tree of depth ≤ 16
    /// with the announced counts. O(file size).
    pub fn verify(&self) -> Result<VerifyReport, OlmError> {
        verify::verify(self.data, self.meta)
    }

    /// OctoMap's `search(key, depth)` (depth 0 means 16): the node at
    /// `depth` containing `key`, or the deepest existing leaf above it;
    /// `None` when the path ends at an inner node lacking the child.
    /// `Found::extra` holds the node's colour or stamp, as the tree's.
    #[inline(always)]
    pub fn search(&self, key: Key, depth: u8) -> Option<Found> {
        self.search_in((key, key.child_index(0)), depth)
    }

    /// [`Self::search`] given the key's root child.
    #[inline(always)]
    fn search_in(&self, key: (Key, usize), depth: u8) -> Option<Found> {
        let trunks = self.trunks()?;
        if let (Some(blocks), AnyNav::Rank(nav)) = (&self.blocks, &self.nav) {
            if query::normalize_depth(depth) == TREE_DEPTH {
                return query::search_through_blocks(*nav, blocks, trunks, key);
            }
        }
        with_nav!(self.nav, |nav| query::search(nav, self.extras, trunks, key, depth))
    }

    /// The colour of the node [`Self::search`] finds (`getColor`; white
    /// when never set); `None` when nothing is found or the map has no
    /// colours.
    pub fn color(&self, key: Key, depth: u8) -> Option<[u8; 3]> {
        if self.meta.header.kind != TreeKind::ColorOcTree {
            return None;
        }
        self.search(key, depth).map(|f| crate::tree::unpack_rgb(f.extra))
    }

    /// The time stamp of the node [`Self::search`] finds (`getTimestamp`);
    /// `None` when nothing is found or the map has no stamps.
    pub fn stamp(&self, key: Key, depth: u8) -> Option<u32> {
        if self.meta.header.kind != TreeKind::OcTreeStamped {
            return None;
        }
        self.search(key, depth).map(|f| f.extra)
    }

    /// The hit count of the node [`Self::search`] finds in a counting map
    /// (`CountingOcTree::search(key, depth)->getCount()`); `None` when
    /// nothing is found or the map holds no counts.
    pub fn count(&self, key: Key, depth: u8) -> Option<u32> {
        if self.meta.header.kind != TreeKind::CountingOcTree {
            return None;
        }
        self.search(key, depth).map(|f| f.extra)
    }

    /// [`Self::search`] at the voxel containing `p`.
    #[inline]
    pub fn search_point(&self, p: Point3, depth: u8) -> Result<Option<Found>, KeyError> {
        Ok(self.search_in(self.meta.keys.key_and_octant(p)?, depth))
    }

    /// [`Self::search`] for many keys at once, answers in `out` in the order
    /// of `keys` (as [`OccupancyTree::search_many`]: maps under 2^19 nodes
    /// one key after another, larger ones in lockstep lanes). The lanes
    /// read the node arrays only: on a damaged file with a search-blocks
    /// section that was not verified, their full-depth answers may differ
    /// from `search`'s.
    pub fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>) {
        let Some(trunks) = self.trunks() else {
            out.clear();
            out.resize(keys.len(), None);
            return;
        };
        if self.node_count() < crate::tree::LOCKSTEP_MIN_NODES as u64 {
            out.clear();
            out.extend(keys.iter().map(|&k| self.search(k, depth)));
            return;
        }
        with_nav!(self.nav, |nav| query::search_many(nav, self.extras, trunks, keys, depth, out))
    }

    /// The root's value, `None` for an empty map.
    pub fn root_value(&self) -> Option<f32> {
        with_nav!(self.nav, |nav| nav.root().and_then(|r| nav.get(r)).map(|(v, _)| v))
    }

    fn iter(&self, max_depth: u8, leaves_only: bool, bbx: Option<KeyBox>) -> MapIter<'a> {
        // as the arena's iterators: a walk over all of a small map asks for
        // all of it at once (a prefetch never faults, on unmapped pages
        // neither)
        if bbx.is_none() && self.data.len() <= crate::tree::WHOLE_PREFETCH_BYTES {
            crate::tree::prefetch_lines(self.data);
        }
        let keys = &self.meta.keys;
        let e = self.extras;
        MapIter(match self.nav {
            AnyNav::Rank(n) => IterInner::Rank(RawIter::new(n, e, keys, max_depth, leaves_only, bbx)),
            AnyNav::Ptr(n) => IterInner::Ptr(RawIter::new(n, e, keys, max_depth, leaves_only, bbx)),
            AnyNav::Ml(n) => IterInner::Ml(Box::new(RawIter::new(n, e, keys, max_depth, leaves_only, bbx))),
        })
    }

    /// Every node, depth first with children 0..7 (`begin_tree(max_depth)`).
    pub fn nodes(&self, max_depth: u8) -> MapIter<'a> {
        self.iter(max_depth, false, None)
    }

    /// Every leaf (and every node at `max_depth`), in OctoMap's order.
    pub fn leaves(&self, max_depth: u8) -> MapIter<'a> {
        self.iter(max_depth, true, None)
    }

    /// Leaves overlapping the key box, as OctoMap's `leaf_bbx_iterator`.
    pub fn leaves_in_box(&self, bbx: KeyBox, max_depth: u8) -> MapIter<'a> {
        self.iter(max_depth, true, Some(bbx))
    }

    /// The answers of `castRay`'s search cursor to `codes`, in order.
    #[cfg(test)]
    pub(crate) fn path_search_all(&self, codes: &[u64]) -> Vec<Option<Found>> {
        with_nav!(self.nav, |nav| {
            let mut path = PathSearch::new(query::MappedPath(nav));
            codes.iter().map(|&c| path.search(c)).collect()
        })
    }

    /// OctoMap's `castRay`, as [`OccupancyTree::cast_ray`]. A counting map
    /// has no occupancy: [`CastError::NoOccupancy`].
    pub fn cast_ray(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Result<CastOutcome, CastError> {
        if !self.has_occupancy() {
            return Err(CastError::NoOccupancy);
        }
        let (keys, sensor) = (&self.meta.keys, &self.meta.header.sensor);
        with_nav!(self.nav, |nav| {
            let mut path = PathSearch::new(query::MappedPath(nav));
            crate::ray::cast_ray_with(keys, sensor, |c| path.search(c), origin, direction, opts)
        })
    }

    /// The in-memory tree (after [`Self::verify`]). Its `size()` is the
    /// recounted node count, as after OctoMap's `.ot` reader; the stored
    /// counter is [`Self::size_counter`].
    pub fn to_tree(&self) -> Result<OccupancyTree, OlmError> {
        let h = &self.meta.header;
        let kind = h.kind.node_kind().ok_or(OlmError::Kind {
            found: h.kind,
            hint: "it holds counts, not occupancy (read it with to_counting_tree)",
        })?;
        let builder = self.preorder(PreorderBuilder::with_kind(kind))?;
        builder
            .finish(h.resolution, h.sensor)
            .map_err(|e| OlmError::Structure(e.to_string()))?
            .ok_or_else(|| OlmError::Structure("node stream ended early".into()))
    }

    /// The in-memory counting tree of a `CountingOcTree` map (after
    /// [`Self::verify`]).
    pub fn to_counting_tree(&self) -> Result<CountingTree, OlmError> {
        let h = &self.meta.header;
        if h.kind != TreeKind::CountingOcTree {
            return Err(OlmError::Kind { found: h.kind, hint: "it holds no counts (read it with to_tree)" });
        }
        // counts travel as extras, like stamps
        let builder = self.preorder(PreorderBuilder::with_kind(crate::tree::NodeKind::Stamped))?;
        let arena = builder.finish_arena().ok_or_else(|| OlmError::Structure("node stream ended early".into()))?;
        CountingTree::from_arena(h.resolution, arena).map_err(|e| OlmError::Structure(e.to_string()))
    }

    /// Verifies the file, then feeds its nodes to `builder` in pre-order.
    fn preorder(&self, mut builder: PreorderBuilder) -> Result<PreorderBuilder, OlmError> {
        self.verify()?;
        let pushed = with_nav!(self.nav, |nav| preorder(nav, self.extras, &mut builder));
        pushed.map_err(OlmError::Structure)?;
        Ok(builder)
    }
}

/// Feeds the nodes in depth-first pre-order to the builder.
fn preorder<N: Nav>(nav: N, extras: Extras<'_>, b: &mut PreorderBuilder) -> Result<(), String> {
    let Some(root) = nav.root() else {
        return Ok(());
    };
    let mut stack = vec![(root, 0usize)];
    let mut seq = [(0u32, 0u32); 17];
    let mut index = 0u64;
    let budget = nav.node_budget();
    while let Some((n, depth)) = stack.pop() {
        if index >= budget || depth > 16 {
            return Err("more nodes reachable than announced".into());
        }
        let (value, mask) = nav.get(n).ok_or("node out of range")?;
        let extra = (extras.kind != TreeKind::OcTree).then(|| extras.get(n));
        b.push_with_extra(value, extra, mask, index).map_err(|e| e.to_string())?;
        index += 1;
        if mask == 0 {
            nav.skip_seq(n, &mut seq[depth]);
        } else {
            let mut ch = [Node::default(); 8];
            let k = nav.children_seq(n, mask, &mut seq[depth], &mut ch).ok_or("children out of range")?;
            stack.extend(ch[..k].iter().rev().map(|&c| (c, depth + 1)));
        }
    }
    Ok(())
}

/// A level-skip index over a mapped view (see [`crate::SearchIndex`]):
/// hash tables of the nodes at a few depths, built by walking only the
/// levels down to them, so a search probes once and walks the levels
/// below. Opt-in for query-heavy work; opening stays O(1).
pub struct MapSearchIndex<'a> {
    view: MapView<'a>,
    tables: LevelTables<IndexEntry>,
}

/// A node in a [`MapSearchIndex`] table, with what a search's first step
/// below it needs where the layout allows it (rank and pointer layouts:
/// child `pos` is `first` plus the children before `pos`), so that the
/// step reads nothing from the file.
#[derive(Clone, Copy, Default)]
struct IndexEntry {
    node: Node,
    mask: u8,
    /// 0 (never a child's index: the root's) when the step is not known.
    first: u32,
}

impl<'a> MapSearchIndex<'a> {
    /// Builds the tables for `view`, walking the levels down to the
    /// deepest table.
    pub fn new(view: MapView<'a>) -> Self {
        let tables = with_nav!(view.nav, |nav| {
            let entry = |node: Node| {
                let mask = nav.mask(node).unwrap_or(0);
                // known only when all the children lie in the file
                let first = nav
                    .first_child_index(node, mask)
                    .filter(|&f| u64::from(f) + u64::from(crate::arch::count_ones(mask)) <= view.node_count())
                    .unwrap_or(0);
                IndexEntry { node, mask, first }
            };
            let trunk_depth = view.trunks().map_or(0, |t| t.shallowest_end());
            LevelTables::build(nav.root().map(entry), view.node_count(), None, trunk_depth, |e, out| {
                let mut ch = [Node::default(); 8];
                let Some(k) = nav.children(e.node, e.mask, &mut ch) else { return };
                let positions = (0..8).filter(|p| e.mask & (1 << p) != 0);
                out.extend(positions.zip(ch[..k].iter().map(|&c| entry(c))));
            })
        });
        MapSearchIndex { view, tables }
    }

    /// The depth of the deepest table (0: none).
    pub fn depth(&self) -> u8 {
        self.tables.depth()
    }

    /// Heap bytes of the tables.
    pub fn bytes(&self) -> usize {
        self.tables.bytes()
    }

    /// [`MapView::search`], from the deepest table that answers (one step
    /// below it taken from the table), or from the trunk end when none does.
    #[inline]
    pub fn search(&self, key: Key, depth: u8) -> Option<Found> {
        let trunks = self.view.trunks()?;
        let (code, depth) = query::search_target(key, depth);
        let (start, depth) = match self.tables.start(key, depth) {
            Some((e, d)) if e.first != 0 && d < depth => {
                let pos = (code >> (3 * (TREE_DEPTH - 1 - d))) & 7;
                if e.mask & (1 << pos) != 0 {
                    let c = e.first + crate::arch::count_ones(e.mask & nav::below(pos as usize));
                    (Some((Node { idx: c, label: 0 }, d + 1)), depth)
                } else if e.mask == 0 {
                    (Some((e.node, d)), d)
                } else {
                    return None;
                }
            }
            Some((e, d)) => (Some((e.node, d)), depth),
            // no table answers: the trunk's grid, in the same layout dispatch
            None => (None, depth),
        };
        with_nav!(self.view.nav, |nav| {
            let start = start.unwrap_or_else(|| query::trunk_start(nav, trunks, (key, key.child_index(0)), depth));
            query::search_from(nav, code, depth, start).map(|(f, n)| Found { extra: self.view.extras.get(n), ..f })
        })
    }
}

impl OccupancyLookup for MapView<'_> {
    fn key_space(&self) -> &KeySpace {
        &self.meta.keys
    }

    fn sensor(&self) -> &SensorModel {
        &self.meta.header.sensor
    }

    #[inline]
    fn search(&self, key: Key, depth: u8) -> Option<Found> {
        MapView::search(self, key, depth)
    }

    fn has_occupancy(&self) -> bool {
        self.meta.header.kind != TreeKind::CountingOcTree
    }
}

impl<D: AsRef<[u8]>> OccupancyLookup for MappedMap<D> {
    fn key_space(&self) -> &KeySpace {
        &self.meta.keys
    }

    fn sensor(&self) -> &SensorModel {
        &self.meta.header.sensor
    }

    #[inline]
    fn search(&self, key: Key, depth: u8) -> Option<Found> {
        self.view().search(key, depth)
    }

    fn has_occupancy(&self) -> bool {
        self.view().has_occupancy()
    }
}

impl<D> std::fmt::Debug for MappedMap<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MappedMap").field("header", &self.meta.header).finish_non_exhaustive()
    }
}

impl std::fmt::Debug for MapView<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MapView").field("header", &self.meta.header).finish_non_exhaustive()
    }
}
