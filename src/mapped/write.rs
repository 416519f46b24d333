//! Tree → `.olm`. Sections are produced by walks over the tree (one
//! depth-limited walk per level for the breadth-first layouts), streamed
//! through small buffers to their final offsets; the header, which holds
//! the checksums, is written last. Memory stays bounded (a few MiB) except
//! for the pointer layout, which keeps a `u32` subtree size per node.

use super::format::{
    self, required_sections, round8, Header, Index, Section, SectionKind, TreeKind, Variant, DEFAULT_RANK_BLOCK_LOG2,
    HEADER_LEN, MAX_NODES, ML_RANK_BLOCK_LOG2, RANK_BLOCK_LOG2, SECTION_ALIGN, SECTION_OPTIONAL, VERSION_MAJOR,
    VERSION_MINOR,
};
use crate::key::TREE_DEPTH;
use crate::sensor::SensorModel;
use crate::tree::{CountingTree, NodeRef, OccupancyTree};
use std::io::{self, Seek, SeekFrom, Write};
use std::path::Path;

/// How to write a map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteOptions {
    /// What each node holds (default: [`Variant::Full`]).
    pub variant: Variant,
    /// [`Index::Pointers`] is for the full variant only.
    pub index: Index,
    /// Records per rank-directory block, as a power of two (3..=12).
    pub rank_block_log2: u8,
    /// Whether to add the search-blocks section (default: never).
    pub search_blocks: SearchBlocksSection,
}

/// When [`write()`] adds the optional search-blocks section, which makes
/// full-depth searches of large maps faster for about a fifth more file
/// (`formats/olm.md`; measured in `docs/benchmarks.md`, "Memory-mapped
/// maps"). Only a plain map in the full variant with the rank index, whose
/// voxels take at most 256 values, can have one. Off by default: a full
/// `.olm` stays within 1.15x the size of its `.ot`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SearchBlocksSection {
    /// Never add it.
    #[default]
    Never,
    /// For maps with 2^17 or more nodes at depths 13–15, where the rank
    /// layout's last levels no longer stay in the processor's caches.
    Auto,
    /// Whenever the map can have one.
    Always,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            variant: Variant::Full,
            index: Index::Rank,
            rank_block_log2: DEFAULT_RANK_BLOCK_LOG2,
            search_blocks: SearchBlocksSection::default(),
        }
    }
}

impl WriteOptions {
    /// Maximum likelihood (what `.bt` holds), rank index.
    pub fn max_likelihood() -> Self {
        WriteOptions { variant: Variant::MaxLikelihood, rank_block_log2: ML_RANK_BLOCK_LOG2, ..Self::default() }
    }

    /// Full variant with first-child pointers instead of the rank directory.
    pub fn pointers() -> Self {
        WriteOptions { index: Index::Pointers, ..Self::default() }
    }
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

/// Writes `tree` as `.olm` with the default options (full log-odds, rank
/// index) to `path`, atomically (a temporary file renamed into place).
pub fn write_file(tree: &OccupancyTree, path: &Path) -> io::Result<()> {
    write_file_with(tree, path, WriteOptions::default())
}

/// [`write_file`] with options.
pub fn write_file_with(tree: &OccupancyTree, path: &Path, opts: WriteOptions) -> io::Result<()> {
    crate::formats::write_atomically(path, |w| write(tree, w, opts))
}

/// Writes a counting tree (`CountingOcTree`, full variant) to `path`,
/// atomically; `opts.index` chooses the layout.
pub fn write_counting_file(tree: &CountingTree, path: &Path, opts: WriteOptions) -> io::Result<()> {
    crate::formats::write_atomically(path, |w| write_counting(tree, w, opts))
}

/// A counting tree as `.olm` bytes.
pub fn counting_to_bytes(tree: &CountingTree, opts: WriteOptions) -> io::Result<Vec<u8>> {
    let mut c = io::Cursor::new(Vec::new());
    write_counting(tree, &mut c, opts)?;
    Ok(c.into_inner())
}

/// Writes a counting tree: tree kind 3, its counts in the values section
/// (the four bytes `.ot` stores per node), sensor fields zero. Only the
/// full variant exists: a count has no maximum-likelihood form.
pub fn write_counting<W: Write + Seek>(tree: &CountingTree, w: &mut W, opts: WriteOptions) -> io::Result<()> {
    if opts.variant != Variant::Full {
        return Err(invalid("a counting tree has the full variant only".into()));
    }
    let zero = SensorModel { hit: 0.0, miss: 0.0, clamping_min: 0.0, clamping_max: 0.0, occupancy_threshold: 0.0 };
    let src = Source {
        root: tree.root(),
        kind: TreeKind::CountingOcTree,
        sensor: zero,
        size: tree.size(),
        resolution: tree.resolution(),
    };
    write_source(&src, w, opts, None)
}

/// What the writer needs of a tree.
struct Source<'t> {
    root: Option<NodeRef<'t>>,
    kind: TreeKind,
    sensor: SensorModel,
    /// OctoMap's `size()` counter.
    size: usize,
    resolution: f64,
}

impl Source<'_> {
    /// The four bytes stored per node in the values section.
    #[inline]
    fn value_bytes(&self, n: NodeRef<'_>) -> [u8; 4] {
        match self.kind {
            TreeKind::CountingOcTree => n.extra().to_le_bytes(),
            _ => n.value().to_le_bytes(),
        }
    }
}

/// The `.olm` bytes of `tree`.
pub fn to_bytes(tree: &OccupancyTree, opts: WriteOptions) -> io::Result<Vec<u8>> {
    let mut c = io::Cursor::new(Vec::new());
    write(tree, &mut c, opts)?;
    Ok(c.into_inner())
}

/// Writes `tree` to a seekable writer positioned at the start of the file.
/// The full variant keeps a colour tree's colours and a stamped tree's
/// stamps. The maximum-likelihood variant stores what OctoMap's
/// `writeBinary` would: the tree converted to maximum likelihood and pruned
/// (by its kind's rules), and its type, but no colours or stamps (the
/// caller's tree is not changed).
pub fn write<W: Write + Seek>(tree: &OccupancyTree, w: &mut W, opts: WriteOptions) -> io::Result<()> {
    let ml_tree;
    let tree = match opts.variant {
        Variant::Full => tree,
        Variant::MaxLikelihood => {
            let mut t = tree.clone();
            t.to_max_likelihood();
            t.prune();
            ml_tree = t;
            &ml_tree
        }
    };
    let src = Source {
        root: tree.root(),
        kind: TreeKind::of(tree.kind()),
        sensor: *tree.sensor(),
        size: tree.size(),
        resolution: tree.resolution(),
    };
    let min_nodes = match opts.search_blocks {
        SearchBlocksSection::Auto => Some(super::search_blocks::AUTO_MIN_NODES),
        SearchBlocksSection::Always => Some(0),
        SearchBlocksSection::Never => None,
    };
    let blocks = match (opts.variant, opts.index, src.kind, min_nodes) {
        (Variant::Full, Index::Rank, TreeKind::OcTree, Some(min)) => {
            tree.subtree_runs(min).filter(|r| !r.runs.offsets.is_empty()).map(|r| super::search_blocks::encode(&r))
        }
        _ => None,
    };
    write_source(&src, w, opts, blocks.as_deref())
}

/// Writes the sections of `src` and, when given, the search-blocks
/// section's bytes.
fn write_source<W: Write + Seek>(
    src: &Source<'_>,
    w: &mut W,
    opts: WriteOptions,
    search_blocks: Option<&[u8]>,
) -> io::Result<()> {
    let log2 = match opts.index {
        Index::Rank => {
            if !RANK_BLOCK_LOG2.contains(&opts.rank_block_log2) {
                return Err(invalid(format!("rank block log2 {} outside {:?}", opts.rank_block_log2, RANK_BLOCK_LOG2)));
            }
            opts.rank_block_log2
        }
        Index::Pointers => {
            if opts.variant != Variant::Full {
                return Err(invalid("child pointers exist for the full variant only".into()));
            }
            0
        }
    };
    let (nodes, inner) = count(src.root);
    if nodes > MAX_NODES {
        return Err(invalid(format!("{nodes} nodes exceed the format's {MAX_NODES}")));
    }
    let sensor = src.sensor;
    let root_label = match (opts.variant, src.root) {
        (Variant::Full, _) | (_, None) => 0,
        (_, Some(r)) if r.has_children() => 3,
        (_, Some(r)) => ml_label(r, sensor.clamping_max),
    };
    // section offsets: consecutive, each aligned
    let kind = src.kind;
    let required = required_sections(kind, opts.variant, opts.index, nodes, inner, log2);
    let mut sections = Vec::with_capacity(required.len());
    let mut offset = HEADER_LEN as u64;
    for (kind, length) in &required {
        offset = offset.div_ceil(SECTION_ALIGN) * SECTION_ALIGN;
        sections.push(Section { kind: *kind as u16, flags: 0, crc32: 0, offset, length: *length });
        offset += length;
    }
    if let Some(b) = search_blocks {
        offset = offset.div_ceil(SECTION_ALIGN) * SECTION_ALIGN;
        let (kind, flags, crc32, length) =
            (SectionKind::SearchBlocks as u16, SECTION_OPTIONAL, crc32fast::hash(b), b.len());
        sections.push(Section { kind, flags, crc32, offset, length: length as u64 });
        offset += length as u64;
    }
    let file_length = offset;
    let mut sinks: Vec<Sink> = sections[..required.len()].iter().map(|s| Sink::new(s.offset)).collect();
    let sink_of = |kind: SectionKind| required.iter().position(|(k, _)| *k == kind).expect("section planned");
    // the colour or stamp sink, and how a node's extra is stored
    let extra_sink = match (kind, opts.variant) {
        (TreeKind::ColorOcTree, Variant::Full) => Some(sink_of(SectionKind::Colors)),
        (TreeKind::OcTreeStamped, Variant::Full) => Some(sink_of(SectionKind::Stamps)),
        _ => None,
    };
    let put_extra = |sinks: &mut [Sink], w: &mut W, n: NodeRef<'_>| -> io::Result<()> {
        match (kind, extra_sink) {
            (TreeKind::ColorOcTree, Some(e)) => sinks[e].put(w, &n.extra().to_le_bytes()[..3]),
            (TreeKind::OcTreeStamped, Some(e)) => sinks[e].put(w, &n.extra().to_le_bytes()),
            _ => Ok(()),
        }
    };
    match (opts.variant, opts.index) {
        (Variant::Full, Index::Rank) => {
            let (m, r, v) = (sink_of(SectionKind::Masks), sink_of(SectionKind::Rank), sink_of(SectionKind::Values));
            let block = 1u64 << log2;
            let mut i = 0u64;
            let mut children = 0u64;
            for_each_level(src.root, TREE_DEPTH, |n| {
                let mask = n.child_mask();
                if i.is_multiple_of(block) {
                    sinks[r].put(w, &(children as u32).to_le_bytes())?;
                }
                sinks[m].put(w, &[mask])?;
                sinks[v].put(w, &src.value_bytes(n))?;
                put_extra(&mut sinks, w, n)?;
                children += u64::from(crate::arch::count_ones(mask));
                i += 1;
                Ok(())
            })?;
            if i.is_multiple_of(block) {
                sinks[r].put(w, &(children as u32).to_le_bytes())?;
            }
            sinks[m].pad(w, round8(nodes) - nodes)?;
        }
        (Variant::Full, Index::Pointers) => {
            write_pointers(
                src,
                w,
                &mut sinks,
                [sink_of(SectionKind::Masks), sink_of(SectionKind::FirstChild), sink_of(SectionKind::Values)],
                &put_extra,
            )?;
            sinks[sink_of(SectionKind::Masks)].pad(w, round8(nodes) - nodes)?;
        }
        (Variant::MaxLikelihood, _) => {
            let (l, r, o) =
                (sink_of(SectionKind::Labels), sink_of(SectionKind::Rank), sink_of(SectionKind::InnerOccupancy));
            let block = 1u64 << log2;
            let mut j = 0u64;
            let mut inner_children = 0u64;
            let mut bits = 0u64;
            for_each_level(src.root, TREE_DEPTH - 1, |n| {
                if !n.has_children() {
                    return Ok(());
                }
                let mut word = 0u16;
                for (pos, c) in n.children() {
                    let label = if c.has_children() { 3 } else { ml_label(c, sensor.clamping_max) };
                    word |= u16::from(label) << (2 * pos);
                }
                if j.is_multiple_of(block) {
                    sinks[r].put(w, &(inner_children as u32).to_le_bytes())?;
                }
                sinks[l].put(w, &word.to_le_bytes())?;
                if ml_label(n, sensor.clamping_max) == 2 {
                    bits |= 1 << (j % 64);
                }
                inner_children += u64::from(super::nav::count_inner(u64::from(word)));
                j += 1;
                if j.is_multiple_of(64) {
                    sinks[o].put(w, &bits.to_le_bytes())?;
                    bits = 0;
                }
                Ok(())
            })?;
            debug_assert_eq!(j, inner);
            if j.is_multiple_of(block) {
                sinks[r].put(w, &(inner_children as u32).to_le_bytes())?;
            }
            if !j.is_multiple_of(64) {
                sinks[o].put(w, &bits.to_le_bytes())?;
            }
            sinks[l].pad(w, round8(2 * inner) - 2 * inner)?;
        }
    }
    if let (TreeKind::ColorOcTree, Some(e)) = (kind, extra_sink) {
        sinks[e].pad(w, round8(3 * nodes) - 3 * nodes)?;
    }
    for (sink, section) in sinks.iter_mut().zip(sections.iter_mut()) {
        sink.flush(w)?;
        debug_assert_eq!(sink.written, section.length, "section {}", section.kind);
        if sink.written != section.length {
            return Err(io::Error::other(format!(
                "section {} came out {} bytes, planned {}",
                section.kind, sink.written, section.length
            )));
        }
        section.crc32 = sink.crc.clone().finalize();
    }
    if let (Some(b), Some(s)) = (search_blocks, sections.last()) {
        w.seek(SeekFrom::Start(s.offset))?;
        w.write_all(b)?;
    }
    let header = Header {
        version: (VERSION_MAJOR, VERSION_MINOR),
        kind,
        variant: opts.variant,
        index: opts.index,
        rank_block_log2: log2,
        resolution: src.resolution,
        sensor,
        root_label,
        size_counter: src.size as u64,
        node_count: nodes,
        inner_count: inner,
        file_length,
        sections,
    };
    // pad the file to its full length, then the header
    if file_length > HEADER_LEN as u64 {
        let end = w.seek(SeekFrom::End(0))?;
        if end < file_length {
            w.seek(SeekFrom::Start(file_length - 1))?;
            w.write_all(&[0])?;
        }
    }
    w.seek(SeekFrom::Start(0))?;
    w.write_all(&format::encode(&header))?;
    w.seek(SeekFrom::Start(file_length))?;
    Ok(())
}

/// Label of a maximum-likelihood leaf: 2 occupied (`clamping_max`), 1 free.
fn ml_label(n: NodeRef<'_>, occupied_value: f32) -> u8 {
    if n.value() == occupied_value {
        2
    } else {
        1
    }
}

/// Nodes and inner nodes reachable from the root.
fn count(root: Option<NodeRef<'_>>) -> (u64, u64) {
    let Some(root) = root else {
        return (0, 0);
    };
    let mut stack = vec![root];
    let (mut nodes, mut inner) = (0u64, 0u64);
    while let Some(n) = stack.pop() {
        nodes += 1;
        if n.has_children() {
            inner += 1;
            stack.extend(n.children().map(|(_, c)| c));
        }
    }
    (nodes, inner)
}

/// Calls `f` on every node of depth 0, then depth 1, ... up to `max_depth`,
/// each level in child order (breadth-first order), by depth-limited walks.
fn for_each_level<'t>(
    root: Option<NodeRef<'t>>,
    max_depth: u8,
    mut f: impl FnMut(NodeRef<'t>) -> io::Result<()>,
) -> io::Result<()> {
    fn walk<'t>(
        n: NodeRef<'t>,
        depth: u8,
        target: u8,
        f: &mut impl FnMut(NodeRef<'t>) -> io::Result<()>,
        found: &mut bool,
    ) -> io::Result<()> {
        if depth == target {
            *found = true;
            return f(n);
        }
        for (_, c) in n.children() {
            walk(c, depth + 1, target, f, found)?;
        }
        Ok(())
    }
    let Some(root) = root else {
        return Ok(());
    };
    for level in 0..=max_depth {
        let mut found = false;
        walk(root, 0, level, &mut f, &mut found)?;
        if !found {
            break;
        }
    }
    Ok(())
}

/// Depth-first group order with first-child indices.
fn write_pointers<W: Write + Seek>(
    src: &Source<'_>,
    w: &mut W,
    sinks: &mut [Sink],
    [m, fc, v]: [usize; 3],
    put_extra: &impl Fn(&mut [Sink], &mut W, NodeRef<'_>) -> io::Result<()>,
) -> io::Result<()> {
    let Some(root) = src.root else {
        return Ok(());
    };
    // subtree sizes in depth-first pre-order
    fn sizes(n: NodeRef<'_>, out: &mut Vec<u32>) -> u32 {
        let at = out.len();
        out.push(0);
        let mut s = 1u32;
        for (_, c) in n.children() {
            s += sizes(c, out);
        }
        out[at] = s;
        s
    }
    let mut size = Vec::new();
    sizes(root, &mut size);
    let mut put = |sinks: &mut [Sink], n: NodeRef<'_>, first: u32| -> io::Result<()> {
        sinks[m].put(w, &[n.child_mask()])?;
        sinks[fc].put(w, &first.to_le_bytes())?;
        sinks[v].put(w, &src.value_bytes(n))?;
        put_extra(sinks, w, n)
    };
    put(sinks, root, u32::from(root.has_children()))?;
    // (node, its pre-order index, where its children group starts)
    let mut stack = vec![(root, 0u32, 1u32)];
    while let Some((n, pre, group)) = stack.pop() {
        if !n.has_children() {
            continue;
        }
        let k = crate::arch::count_ones(n.child_mask());
        // groups of the children's subtrees follow this group in order
        let mut next_group = group + k;
        let mut child_pre = pre + 1;
        let mut pending = Vec::with_capacity(8);
        for (_, c) in n.children() {
            let first = if c.has_children() { next_group } else { 0 };
            put(sinks, c, first)?;
            pending.push((c, child_pre, next_group));
            let s = size[child_pre as usize];
            next_group += s - 1;
            child_pre += s;
        }
        stack.extend(pending.into_iter().rev());
    }
    Ok(())
}

/// A section being streamed to its place in the file.
struct Sink {
    pos: u64,
    buf: Vec<u8>,
    crc: crc32fast::Hasher,
    written: u64,
}

const CHUNK: usize = 1 << 18;

impl Sink {
    fn new(offset: u64) -> Self {
        Sink { pos: offset, buf: Vec::new(), crc: crc32fast::Hasher::new(), written: 0 }
    }

    #[inline]
    fn put<W: Write + Seek>(&mut self, w: &mut W, bytes: &[u8]) -> io::Result<()> {
        self.buf.extend_from_slice(bytes);
        if self.buf.len() >= CHUNK {
            self.flush(w)?;
        }
        Ok(())
    }

    fn pad<W: Write + Seek>(&mut self, w: &mut W, zeros: u64) -> io::Result<()> {
        for _ in 0..zeros {
            self.put(w, &[0])?;
        }
        Ok(())
    }

    fn flush<W: Write + Seek>(&mut self, w: &mut W) -> io::Result<()> {
        if self.buf.is_empty() {
            return Ok(());
        }
        w.seek(SeekFrom::Start(self.pos))?;
        w.write_all(&self.buf)?;
        self.crc.update(&self.buf);
        self.pos += self.buf.len() as u64;
        self.written += self.buf.len() as u64;
        self.buf.clear();
        Ok(())
    }
}
