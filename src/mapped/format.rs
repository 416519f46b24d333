//! The byte layout of `.olm` files (see `formats/olm.md`): constants, the
//! fixed 256-byte header with its section table, and the O(1) checks that
//! [`super::MappedMap::new`] runs before any query.
//!
//! Everything is little-endian. Values are decoded with `from_le_bytes` on
//! bounds-checked slices, never by casting pointers, so any byte string is
//! safe to parse.

use super::nav::Node;
use super::search_blocks::SearchBlocks;
use super::OlmError;
use crate::key::KeySpace;
use crate::sensor::SensorModel;
use crate::tree::Trunks;
use std::ops::Range;

/// First eight bytes of every `.olm` file.
pub const MAGIC: [u8; 8] = *b"OCTOLIN\0";
/// Major version this reader understands; files of another major are refused.
pub const VERSION_MAJOR: u16 = 1;
/// Minor version written; readers accept any minor of their major.
pub const VERSION_MINOR: u16 = 2;
/// Written as a little-endian `u32`; reads back as this value only when
/// the file was produced little-endian (bytes `0d 0c 0b 0a`).
pub const ENDIAN_CHECK: u32 = 0x0A0B_0C0D;
/// Length of the header, section table included.
pub const HEADER_LEN: usize = 256;
/// Every section starts at a multiple of this (a cache line).
pub const SECTION_ALIGN: u64 = 64;
/// Room in the section table.
pub const MAX_SECTIONS: usize = 6;
/// Largest node count: node indices, rank counts and child indices are `u32`.
pub const MAX_NODES: u64 = u32::MAX as u64;
/// Rank-directory block sizes allowed (log2 of the records per block).
pub const RANK_BLOCK_LOG2: std::ops::RangeInclusive<u8> = 3..=12;
/// Block size the writer uses by default for the full variant (8 records:
/// a rank is one directory entry plus one masked popcount of a word).
pub const DEFAULT_RANK_BLOCK_LOG2: u8 = 3;
/// ... and for maximum likelihood (64 records: one 128-byte run of labels),
/// where a directory entry per 8 records would add a quarter to the file.
pub const ML_RANK_BLOCK_LOG2: u8 = 6;

pub(crate) const TABLE_OFFSET: usize = 96;
pub(crate) const ENTRY_LEN: usize = 24;
pub(crate) const HEADER_CRC_OFFSET: usize = 252;

/// Byte offsets of the header fields.
pub(crate) mod field {
    pub const MAGIC: usize = 0;
    pub const VERSION_MAJOR: usize = 8;
    pub const VERSION_MINOR: usize = 10;
    pub const ENDIAN: usize = 12;
    pub const HEADER_LEN: usize = 16;
    pub const TREE_KIND: usize = 20;
    pub const VARIANT: usize = 21;
    pub const INDEX: usize = 22;
    pub const RANK_BLOCK_LOG2: usize = 23;
    pub const RESOLUTION: usize = 24;
    pub const SENSOR: usize = 32; // five f32: hit, miss, clamp min, clamp max, threshold
    pub const ROOT_LABEL: usize = 52;
    pub const SECTION_COUNT: usize = 54;
    pub const SIZE_COUNTER: usize = 56;
    pub const NODE_COUNT: usize = 64;
    pub const INNER_COUNT: usize = 72;
    pub const FILE_LENGTH: usize = 80;
}

/// The tree type stored ([`crate::tree::TreeKind`]). The full variant of a
/// colour or stamped tree has a [`SectionKind::Colors`] or
/// [`SectionKind::Stamps`] section; the maximum-likelihood variant, like
/// `.bt`, keeps only the type (nodes read back white, or with stamp 0). A
/// counting tree exists in the full variant only, its values section
/// holding each node's `u32` count.
pub use crate::tree::TreeKind;

/// The header's code for a tree type.
fn tree_kind_code(kind: TreeKind) -> u8 {
    match kind {
        TreeKind::OcTree => 0,
        TreeKind::ColorOcTree => 1,
        TreeKind::OcTreeStamped => 2,
        TreeKind::CountingOcTree => 3,
    }
}

/// What each node holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Variant {
    /// Every node's `f32` log-odds (what `.ot` stores).
    #[default]
    Full = 0,
    /// Maximum likelihood, as `.bt` stores it: per inner node two bits per
    /// child (absent / free leaf / occupied leaf / inner) and one
    /// occupancy bit; values are the clamping bounds.
    MaxLikelihood = 1,
}

/// How a node's children are found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Index {
    /// Breadth-first node order; the children of node `i` start at
    /// `1 + rank(i)`, `rank(i)` being the number of children of nodes
    /// `0..i`, read from a directory of per-block prefix sums plus popcounts
    /// inside the block. About 1% over the bare data.
    #[default]
    Rank = 0,
    /// Depth-first group order (the in-memory arena's compacted layout):
    /// each node stores the `u32` index of its first child. Full variant
    /// only; 4 more bytes per node.
    Pointers = 1,
}

/// Section kinds (the `kind` field of a section table entry).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SectionKind {
    /// `u8` child mask per node, zero-padded to a multiple of 8 bytes.
    Masks = 1,
    /// `f32` log-odds per node.
    Values = 2,
    /// `u32` per block of `2^rank_block_log2` records: the prefix count
    /// (children for [`SectionKind::Masks`], inner children for
    /// [`SectionKind::Labels`]) of all records before the block.
    Rank = 3,
    /// `u32` first-child index per node (0 for leaves).
    FirstChild = 4,
    /// `u16` child labels per inner node, zero-padded to a multiple of 8 bytes.
    Labels = 5,
    /// One bit per inner node (1 = occupied), in `u64` words.
    InnerOccupancy = 6,
    /// `ColorOcTree`: three bytes `r, g, b` per node (white = not set),
    /// zero-padded to a multiple of 8 bytes.
    Colors = 7,
    /// `OcTreeStamped`: `u32` time stamp per node.
    Stamps = 8,
    /// Optional, full / rank plain maps only: the depth-13 subtrees as
    /// runs of bytes with a palette of the voxel values, for full-depth
    /// searches (`search_blocks.rs`).
    SearchBlocks = 9,
}

impl SectionKind {
    /// The kind a section table entry's `kind` field names; `None` for an
    /// unknown id.
    pub fn from_id(id: u16) -> Option<Self> {
        Some(match id {
            1 => SectionKind::Masks,
            2 => SectionKind::Values,
            3 => SectionKind::Rank,
            4 => SectionKind::FirstChild,
            5 => SectionKind::Labels,
            6 => SectionKind::InnerOccupancy,
            7 => SectionKind::Colors,
            8 => SectionKind::Stamps,
            9 => SectionKind::SearchBlocks,
            _ => return None,
        })
    }

    /// Short lowercase name, e.g. "first-child", for messages.
    pub fn name(self) -> &'static str {
        match self {
            SectionKind::Masks => "masks",
            SectionKind::Values => "values",
            SectionKind::Rank => "rank",
            SectionKind::FirstChild => "first-child",
            SectionKind::Labels => "labels",
            SectionKind::InnerOccupancy => "inner-occupancy",
            SectionKind::Colors => "colors",
            SectionKind::Stamps => "stamps",
            SectionKind::SearchBlocks => "search-blocks",
        }
    }
}

/// Section table entry flag: readers that do not know the kind may skip it.
pub const SECTION_OPTIONAL: u16 = 1;

/// One section table entry.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Section {
    /// The [`SectionKind`] id (kept raw: an optional kind may be unknown).
    pub kind: u16,
    /// Flag bits, e.g. [`SECTION_OPTIONAL`].
    pub flags: u16,
    /// CRC-32 (IEEE, as zlib's) of the section's `length` bytes.
    pub crc32: u32,
    /// Byte offset of the section from the start of the file, a multiple
    /// of [`SECTION_ALIGN`].
    pub offset: u64,
    /// Length of the section in bytes.
    pub length: u64,
}

/// Everything the header says.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// Format version, (major, minor).
    pub version: (u16, u16),
    /// The tree type stored.
    pub kind: TreeKind,
    /// What each node holds.
    pub variant: Variant,
    /// How a node's children are found.
    pub index: Index,
    /// log2 of the records per rank-directory block; 0 with
    /// [`Index::Pointers`].
    pub rank_block_log2: u8,
    /// Voxel edge length in metres.
    pub resolution: f64,
    /// The tree's sensor model (all zero for a counting tree).
    pub sensor: SensorModel,
    /// Maximum likelihood only: 0 empty tree, 1 free leaf, 2 occupied leaf,
    /// 3 inner node (then the root is inner record 0).
    pub root_label: u8,
    /// OctoMap's `size()` counter of the tree written (what `.ot` headers carry).
    pub size_counter: u64,
    /// Number of nodes stored, at most [`MAX_NODES`].
    pub node_count: u64,
    /// Nodes with children.
    pub inner_count: u64,
    /// Length of the whole file in bytes (checked against the actual length).
    pub file_length: u64,
    /// The section table's entries, in table order.
    pub sections: Vec<Section>,
}

/// Record counts and section lengths implied by a header.
pub(crate) fn rank_entries(records: u64, log2: u8) -> u64 {
    (records >> log2) + 1
}

pub(crate) fn round8(n: u64) -> u64 {
    n.div_ceil(8) * 8
}

/// The sections a (kind, variant, index) triple needs, with their exact
/// lengths.
pub(crate) fn required_sections(
    kind: TreeKind,
    variant: Variant,
    index: Index,
    nodes: u64,
    inner: u64,
    log2: u8,
) -> Vec<(SectionKind, u64)> {
    let mut v = layout_sections(variant, index, nodes, inner, log2);
    match (kind, variant) {
        (TreeKind::ColorOcTree, Variant::Full) => v.push((SectionKind::Colors, round8(3 * nodes))),
        (TreeKind::OcTreeStamped, Variant::Full) => v.push((SectionKind::Stamps, 4 * nodes)),
        _ => {}
    }
    v
}

fn layout_sections(variant: Variant, index: Index, nodes: u64, inner: u64, log2: u8) -> Vec<(SectionKind, u64)> {
    match (variant, index) {
        (Variant::Full, Index::Rank) => vec![
            (SectionKind::Masks, round8(nodes)),
            (SectionKind::Rank, 4 * rank_entries(nodes, log2)),
            (SectionKind::Values, 4 * nodes),
        ],
        (Variant::Full, Index::Pointers) => vec![
            (SectionKind::Masks, round8(nodes)),
            (SectionKind::FirstChild, 4 * nodes),
            (SectionKind::Values, 4 * nodes),
        ],
        (Variant::MaxLikelihood, _) => vec![
            (SectionKind::Labels, round8(2 * inner)),
            (SectionKind::Rank, 4 * rank_entries(inner, log2)),
            (SectionKind::InnerOccupancy, 8 * inner.div_ceil(64)),
        ],
    }
}

// ----- little-endian reads on bounds-checked slices ------------------------

#[inline(always)]
pub(crate) fn u16_at(b: &[u8], off: usize) -> Option<u16> {
    let s = b.get(off..off.checked_add(2)?)?;
    Some(u16::from_le_bytes(s.try_into().ok()?))
}

#[inline(always)]
pub(crate) fn u32_at(b: &[u8], off: usize) -> Option<u32> {
    let s = b.get(off..off.checked_add(4)?)?;
    Some(u32::from_le_bytes(s.try_into().ok()?))
}

#[inline(always)]
pub(crate) fn u64_at(b: &[u8], off: usize) -> Option<u64> {
    let s = b.get(off..off.checked_add(8)?)?;
    Some(u64::from_le_bytes(s.try_into().ok()?))
}

#[inline(always)]
pub(crate) fn f32_at(b: &[u8], off: usize) -> Option<f32> {
    u32_at(b, off).map(f32::from_bits)
}

fn bad(field: &'static str, value: impl ToString) -> OlmError {
    OlmError::BadField { field, value: value.to_string() }
}

/// Byte ranges of the sections a reader uses (empty when absent).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct Ranges {
    pub masks: Range<usize>,
    pub values: Range<usize>,
    pub rank: Range<usize>,
    pub first_child: Range<usize>,
    pub labels: Range<usize>,
    pub inner_occupancy: Range<usize>,
    pub colors: Range<usize>,
    pub stamps: Range<usize>,
    /// Empty when the file has no search-blocks section.
    pub search_blocks: Range<usize>,
}

impl Ranges {
    fn set(&mut self, kind: SectionKind, r: Range<usize>) {
        match kind {
            SectionKind::Masks => self.masks = r,
            SectionKind::Values => self.values = r,
            SectionKind::Rank => self.rank = r,
            SectionKind::FirstChild => self.first_child = r,
            SectionKind::Labels => self.labels = r,
            SectionKind::InnerOccupancy => self.inner_occupancy = r,
            SectionKind::Colors => self.colors = r,
            SectionKind::Stamps => self.stamps = r,
            SectionKind::SearchBlocks => self.search_blocks = r,
        }
    }
}

/// A parsed, O(1)-checked header with what queries need.
#[derive(Clone, Debug)]
pub(crate) struct Meta {
    pub header: Header,
    pub keys: KeySpace,
    pub ranges: Ranges,
    /// Where searches start, derived at the first search (a few dozen
    /// node reads, so that opening stays O(1)); `None` without a root.
    pub trunks: std::sync::OnceLock<Option<Trunks<Node>>>,
}

/// CRC-32 of the header bytes before the checksum field.
pub(crate) fn header_crc(bytes: &[u8]) -> u32 {
    crc32fast::hash(&bytes[..HEADER_CRC_OFFSET.min(bytes.len())])
}

/// Parses and checks the header: magic, version, endianness, header
/// checksum, tree kind, variant, counts, and every section's bounds and
/// length. O(1): section contents are not read.
pub(crate) fn parse(bytes: &[u8]) -> Result<Meta, OlmError> {
    let len = bytes.len() as u64;
    if bytes.len() < MAGIC.len() || bytes[..MAGIC.len()] != MAGIC {
        if bytes.len() < MAGIC.len() && MAGIC.starts_with(bytes) {
            return Err(OlmError::TooShort { len, need: HEADER_LEN as u64 });
        }
        return Err(OlmError::BadMagic);
    }
    if bytes.len() < HEADER_LEN {
        return Err(OlmError::TooShort { len, need: HEADER_LEN as u64 });
    }
    let h = &bytes[..HEADER_LEN];
    let u8_at = |off: usize| h[off];
    // fixed offsets inside a 256-byte slice: these reads cannot fail
    let r16 = |off| u16_at(h, off).unwrap_or(0);
    let r32 = |off| u32_at(h, off).unwrap_or(0);
    let r64 = |off| u64_at(h, off).unwrap_or(0);
    debug_assert_eq!(&h[field::MAGIC..field::MAGIC + 8], &MAGIC);

    let version = (r16(field::VERSION_MAJOR), r16(field::VERSION_MINOR));
    if version.0 != VERSION_MAJOR {
        return Err(OlmError::Version { major: version.0, minor: version.1 });
    }
    let endian = r32(field::ENDIAN);
    if endian != ENDIAN_CHECK {
        return Err(OlmError::Endianness { found: endian });
    }
    let stored = r32(HEADER_CRC_OFFSET);
    let computed = header_crc(h);
    if stored != computed {
        return Err(OlmError::HeaderChecksum { stored, computed });
    }
    let header_len = r32(field::HEADER_LEN);
    if header_len as usize != HEADER_LEN {
        return Err(bad("header_len", header_len));
    }
    let code = u8_at(field::TREE_KIND);
    let kinds = [TreeKind::OcTree, TreeKind::ColorOcTree, TreeKind::OcTreeStamped, TreeKind::CountingOcTree];
    let Some(kind) = kinds.into_iter().find(|&k| tree_kind_code(k) == code) else {
        return Err(bad("tree_kind", code));
    };
    let variant = match u8_at(field::VARIANT) {
        0 => Variant::Full,
        1 if kind == TreeKind::CountingOcTree => {
            return Err(bad("variant", "1 (maximum likelihood) with tree_kind 3: counts have no such variant"))
        }
        1 => Variant::MaxLikelihood,
        v => return Err(bad("variant", v)),
    };
    let index = match (variant, u8_at(field::INDEX)) {
        (_, 0) => Index::Rank,
        (Variant::Full, 1) => Index::Pointers,
        (_, i) => return Err(bad("index", i)),
    };
    let log2 = u8_at(field::RANK_BLOCK_LOG2);
    if index == Index::Rank && !RANK_BLOCK_LOG2.contains(&log2) {
        return Err(bad("rank_block_log2", log2));
    }
    if index == Index::Pointers && log2 != 0 {
        return Err(bad("rank_block_log2", log2));
    }
    let resolution = f64::from_bits(r64(field::RESOLUTION));
    if crate::key::check_resolution(resolution).is_err() {
        return Err(bad("resolution", resolution));
    }
    let s = |i: usize| f32::from_bits(r32(field::SENSOR + 4 * i));
    let sensor =
        SensorModel { hit: s(0), miss: s(1), clamping_min: s(2), clamping_max: s(3), occupancy_threshold: s(4) };
    for (name, v) in [
        ("sensor.hit", sensor.hit),
        ("sensor.miss", sensor.miss),
        ("sensor.clamping_min", sensor.clamping_min),
        ("sensor.clamping_max", sensor.clamping_max),
        ("sensor.occupancy_threshold", sensor.occupancy_threshold),
    ] {
        if !v.is_finite() {
            return Err(bad(name, v));
        }
    }
    // a counting tree has no sensor model: its fields are zero (so that a
    // relabelled occupancy map does not pass as counts)
    let sensor_bits = [sensor.hit, sensor.miss, sensor.clamping_min, sensor.clamping_max, sensor.occupancy_threshold];
    if kind == TreeKind::CountingOcTree && sensor_bits.iter().any(|v| v.to_bits() != 0) {
        return Err(bad("sensor", "not all zero in a counting map (tree_kind 3)"));
    }
    let root_label = u8_at(field::ROOT_LABEL);
    let size_counter = r64(field::SIZE_COUNTER);
    let node_count = r64(field::NODE_COUNT);
    let inner_count = r64(field::INNER_COUNT);
    let file_length = r64(field::FILE_LENGTH);
    if file_length != len {
        return Err(OlmError::FileLength { header: file_length, actual: len });
    }
    if node_count > MAX_NODES {
        return Err(bad("node_count", node_count));
    }
    // every inner node has at least one and at most eight children
    let consistent = if node_count == 0 {
        inner_count == 0
    } else {
        inner_count < node_count && node_count - 1 <= inner_count.saturating_mul(8)
    };
    if !consistent {
        return Err(bad("inner_count", format!("{inner_count} inner nodes cannot hold {node_count} nodes")));
    }
    match variant {
        Variant::Full => {
            if root_label != 0 {
                return Err(bad("root_label", root_label));
            }
        }
        Variant::MaxLikelihood => {
            let ok = match root_label {
                0 => node_count == 0,
                1 | 2 => node_count == 1,
                3 => inner_count >= 1,
                _ => false,
            };
            if !ok {
                return Err(bad("root_label", format!("{root_label} with {node_count} nodes, {inner_count} inner")));
            }
        }
    }

    let count = r16(field::SECTION_COUNT) as usize;
    if count > MAX_SECTIONS {
        return Err(bad("section_count", count));
    }
    let mut sections = Vec::with_capacity(count);
    for i in 0..count {
        let e = TABLE_OFFSET + i * ENTRY_LEN;
        sections.push(Section {
            kind: r16(e),
            flags: r16(e + 2),
            crc32: r32(e + 4),
            offset: r64(e + 8),
            length: r64(e + 16),
        });
    }
    let mut spans: Vec<(u64, u64)> = Vec::with_capacity(count);
    for s in &sections {
        let end = s.offset.checked_add(s.length);
        let reason = if s.offset < HEADER_LEN as u64 {
            Some("starts inside the header")
        } else if s.offset % SECTION_ALIGN != 0 {
            Some("is not aligned to 64 bytes")
        } else if end.is_none_or(|e| e > len) {
            Some("extends past the end of the file")
        } else if spans.iter().any(|&(o, e)| s.offset < e && o < s.offset + s.length) {
            Some("overlaps another section")
        } else {
            None
        };
        if let Some(reason) = reason {
            return Err(OlmError::Section {
                kind: s.kind,
                reason: format!("{reason} (offset {}, length {}, file {len} bytes)", s.offset, s.length),
            });
        }
        spans.push((s.offset, s.offset + s.length));
        if SectionKind::from_id(s.kind).is_none() && s.flags & SECTION_OPTIONAL == 0 {
            return Err(OlmError::Section { kind: s.kind, reason: "unknown section kind not marked optional".into() });
        }
    }
    let mut ranges = Ranges::default();
    let required = required_sections(kind, variant, index, node_count, inner_count, log2);
    for (kind, want) in &required {
        let mut found = sections.iter().filter(|s| s.kind == *kind as u16);
        let Some(s) = found.next() else {
            return Err(OlmError::Section {
                kind: *kind as u16,
                reason: format!("required {} section is missing", kind.name()),
            });
        };
        if found.next().is_some() {
            return Err(OlmError::Section { kind: *kind as u16, reason: "appears twice".into() });
        }
        if s.length != *want {
            return Err(OlmError::Section {
                kind: *kind as u16,
                reason: format!("{} section is {} bytes, the counts need {want}", kind.name(), s.length),
            });
        }
        // in bounds of `bytes` (checked above), so these fit in usize
        ranges.set(*kind, s.offset as usize..(s.offset + s.length) as usize);
    }
    // the optional search blocks: full / rank plain maps, once
    let blocks_allowed = (kind, variant, index) == (TreeKind::OcTree, Variant::Full, Index::Rank);
    let optional = |k: SectionKind| k == SectionKind::SearchBlocks && blocks_allowed;
    let mut blocks = sections.iter().filter(|s| s.kind == SectionKind::SearchBlocks as u16 && blocks_allowed);
    if let Some(s) = blocks.next() {
        if blocks.next().is_some() {
            return Err(OlmError::Section { kind: s.kind, reason: "appears twice".into() });
        }
        let range = s.offset as usize..(s.offset + s.length) as usize;
        if let Err(reason) = SearchBlocks::parse(&bytes[range.clone()], node_count) {
            return Err(OlmError::Section { kind: s.kind, reason });
        }
        ranges.set(SectionKind::SearchBlocks, range);
    }
    if let Some(s) = sections
        .iter()
        .find(|s| SectionKind::from_id(s.kind).is_some_and(|k| !optional(k) && !required.iter().any(|(r, _)| *r == k)))
    {
        return Err(OlmError::Section { kind: s.kind, reason: "section does not belong to this variant".into() });
    }
    Ok(Meta {
        header: Header {
            version,
            kind,
            variant,
            index,
            rank_block_log2: log2,
            resolution,
            sensor,
            root_label,
            size_counter,
            node_count,
            inner_count,
            file_length,
            sections,
        },
        keys: KeySpace::new(resolution),
        ranges,
        trunks: std::sync::OnceLock::new(),
    })
}

/// Serialises a header (with `crc32` filled in) into its 256 bytes.
pub(crate) fn encode(h: &Header) -> [u8; HEADER_LEN] {
    let mut b = [0u8; HEADER_LEN];
    let mut put = |off: usize, bytes: &[u8]| b[off..off + bytes.len()].copy_from_slice(bytes);
    put(field::MAGIC, &MAGIC);
    put(field::VERSION_MAJOR, &h.version.0.to_le_bytes());
    put(field::VERSION_MINOR, &h.version.1.to_le_bytes());
    put(field::ENDIAN, &ENDIAN_CHECK.to_le_bytes());
    put(field::HEADER_LEN, &(HEADER_LEN as u32).to_le_bytes());
    put(field::TREE_KIND, &[tree_kind_code(h.kind)]);
    put(field::VARIANT, &[h.variant as u8]);
    put(field::INDEX, &[h.index as u8]);
    put(field::RANK_BLOCK_LOG2, &[h.rank_block_log2]);
    put(field::RESOLUTION, &h.resolution.to_le_bytes());
    let s = &h.sensor;
    for (i, v) in [s.hit, s.miss, s.clamping_min, s.clamping_max, s.occupancy_threshold].iter().enumerate() {
        put(field::SENSOR + 4 * i, &v.to_le_bytes());
    }
    put(field::ROOT_LABEL, &[h.root_label]);
    put(field::SECTION_COUNT, &(h.sections.len() as u16).to_le_bytes());
    put(field::SIZE_COUNTER, &h.size_counter.to_le_bytes());
    put(field::NODE_COUNT, &h.node_count.to_le_bytes());
    put(field::INNER_COUNT, &h.inner_count.to_le_bytes());
    put(field::FILE_LENGTH, &h.file_length.to_le_bytes());
    for (i, s) in h.sections.iter().take(MAX_SECTIONS).enumerate() {
        let e = TABLE_OFFSET + i * ENTRY_LEN;
        put(e, &s.kind.to_le_bytes());
        put(e + 2, &s.flags.to_le_bytes());
        put(e + 4, &s.crc32.to_le_bytes());
        put(e + 8, &s.offset.to_le_bytes());
        put(e + 16, &s.length.to_le_bytes());
    }
    let crc = header_crc(&b);
    b[HEADER_CRC_OFFSET..].copy_from_slice(&crc.to_le_bytes());
    b
}
