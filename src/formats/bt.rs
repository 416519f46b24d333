//! `.bt` files: OctoMap's compact maximum-likelihood trees
//! (`writeBinary` / `readBinary`).
//!
//! After the text header (`# Octomap OcTree binary file`) come two bytes per
//! node that has children, in depth-first pre-order; they hold two bits per
//! child `i` at bits `2i, 2i+1` of byte `i / 4` (child order 0..7): `00`
//! absent, `01` occupied leaf, `10` free leaf, `11` inner node. Values are
//! not stored: readers restore the clamping bounds. See `formats/bt.md`.

use super::header::{read_first_line, read_header, write_header, CountingReader, FirstLine, BT_FIRST_LINE};
use super::ml_records::RecordBuffer;
use super::pieces::Pieces;
use super::TreeFileError;
use crate::key::KeySpace;
use crate::sensor::SensorModel;
use crate::tree::{child_key, LeafExtremes, PreorderNode, PreorderSource, PreorderVisitor, Tee, TreeSummary};
use crate::tree::{default_extra, ChildGroup, LabelFill, NodeKind, OccupancyTree};
use std::convert::Infallible;
use std::io::{self, BufRead, Read, Write};
use std::ops::ControlFlow;
use std::path::Path;

/// Reads a `.bt` file into a tree with the default sensor model.
pub fn read(r: impl BufRead) -> Result<OccupancyTree, TreeFileError> {
    read_with_sensor(r, SensorModel::default())
}

/// Reads a `.bt` file; leaves get `sensor`'s clamping bounds, inner nodes
/// the maximum of their children and the root the upper bound, exactly as
/// OctoMap's `readBinary` does.
pub fn read_with_sensor(r: impl BufRead, sensor: SensorModel) -> Result<OccupancyTree, TreeFileError> {
    let mut r = CountingReader::new(r);
    let (size, resolution) = match peek_is_text(&mut r)? {
        true => {
            let (first, line) = read_first_line(&mut r)?;
            if first != FirstLine::Binary {
                let reason = if first == FirstLine::Full {
                    "this is a full .ot file".to_string()
                } else {
                    format!("first line is `{}`", String::from_utf8_lossy(&line[..line.len().min(60)]))
                };
                return Err(TreeFileError::WrongFormat { offset: 0, expected: ".bt file", reason });
            }
            let h = read_header(&mut r)?;
            (h.size, h.resolution)
        }
        false => read_legacy_header(&mut r)?,
    };
    let tree = if size > 0 {
        read_data(&mut r, resolution, sensor, NodeKind::Plain, size)?
    } else {
        OccupancyTree::with_sensor(resolution, sensor)
            .map_err(|_| TreeFileError::BadResolution { value: resolution, offset: None })?
    };
    if size != tree.size() as u64 {
        return Err(TreeFileError::SizeMismatch { offset: r.offset, header: size, read: tree.size() as u64 });
    }
    Ok(tree)
}

/// Reads one tree's binary node stream, root first
/// (`OccupancyOcTreeBase::readBinaryData`), into a tree of `kind` whose
/// nodes keep that kind's default colour or stamp. `size_hint` (the
/// header's unchecked `size`) only sizes the arena.
pub(crate) fn read_data<R: BufRead>(
    r: &mut CountingReader<R>,
    resolution: f64,
    sensor: SensorModel,
    kind: NodeKind,
    size_hint: u64,
) -> Result<OccupancyTree, TreeFileError> {
    let mut tree = OccupancyTree::with_kind(resolution, sensor, kind)
        .map_err(|_| TreeFileError::BadResolution { value: resolution, offset: None })?;
    let hint = usize::try_from(size_hint).unwrap_or(usize::MAX);
    let mut fill =
        LabelFill::new(default_extra(kind), hint, sensor.clamping_max, sensor.clamping_min, sensor.clamping_max);
    // each record announces at most 8 nodes: reserve what the header says,
    // as far as the bytes at hand can hold it
    let at_hand = r.chunk()?.len() / 2;
    fill.reserve(hint.min(at_hand.saturating_mul(8)));
    let too_deep = |offset: u64| TreeFileError::TooDeep { offset };
    loop {
        let base = r.offset;
        let buf = r.chunk()?;
        let mut used = 0;
        for rec in buf.chunks_exact(2) {
            fill.push(u16::from_le_bytes([rec[0], rec[1]])).map_err(|_| too_deep(base + used as u64))?;
            used += 2;
            if fill.is_complete() {
                break;
            }
        }
        r.advance(used);
        if fill.is_complete() {
            break;
        }
        // a record split between two fills of the buffer (or the end)
        let mut rec = [0u8; 2];
        let offset = r.offset;
        r.read_exact(&mut rec, "a node's child labels")?;
        fill.push(u16::from_le_bytes(rec)).map_err(|_| too_deep(offset))?;
        if fill.is_complete() {
            break;
        }
    }
    tree.set_arena_with_size(fill.finish().expect("complete"));
    Ok(tree)
}

/// Files since OctoMap 1.4 start with `#`; older ones with the int32 `3`.
fn peek_is_text<R: BufRead>(r: &mut CountingReader<R>) -> Result<bool, TreeFileError> {
    Ok(r.peek_byte()? == Some(b'#'))
}

/// The pre-1.4 layout: int32 tree type (3), float64 resolution, uint32 size.
fn read_legacy_header<R: BufRead>(r: &mut CountingReader<R>) -> Result<(u64, f64), TreeFileError> {
    let mut b4 = [0u8; 4];
    r.read_exact(&mut b4, "the legacy tree type")?;
    let kind = i32::from_le_bytes(b4);
    if kind != 3 {
        return Err(TreeFileError::WrongFormat {
            offset: 0,
            expected: ".bt file",
            reason: format!("no text header and legacy tree type {kind} is not 3"),
        });
    }
    let mut b8 = [0u8; 8];
    r.read_exact(&mut b8, "the legacy resolution")?;
    let res = f64::from_le_bytes(b8);
    if crate::key::check_resolution(res).is_err() {
        return Err(TreeFileError::BadResolution { value: res, offset: Some(r.offset - 8) });
    }
    r.read_exact(&mut b4, "the legacy size")?;
    Ok((u64::from(u32::from_le_bytes(b4)), res))
}

/// Writes what OctoMap's `writeBinary` writes: the tree converted to
/// maximum likelihood and pruned. The caller's tree is left unchanged.
pub fn write(tree: &OccupancyTree, w: impl Write) -> io::Result<()> {
    write_map(tree, w).map(|_| ())
}

/// Writes any map walked as one tree (a tree, a tiled map or a tile set)
/// as [`write()`] writes that tree: the same bytes. Returns the records
/// written, which describe the maximum-likelihood tree.
pub fn write_map(map: &impl PreorderSource, w: impl Write) -> io::Result<MlRecordStream> {
    write_map_observed(map, w, &mut ())
}

/// [`write_map`], showing every node of the map to `observer` as well,
/// once (statistics gathered while writing, without a second walk).
pub fn write_map_observed(
    map: &impl PreorderSource,
    w: impl Write,
    observer: &mut impl PreorderVisitor<Break = Infallible>,
) -> io::Result<MlRecordStream> {
    write_ml(map, w, observer, RecordBuffer::in_memory(records_hint(map.node_count())))
}

/// [`write_map_observed`] holding no more than a few megabytes of records
/// in memory: the others wait in `scratch` (a file opened for reading and
/// writing, emptied first) until the header, which counts the nodes, is
/// written. For maps whose records outgrow the memory at hand.
pub fn write_map_observed_with_scratch(
    map: &impl PreorderSource,
    w: impl Write,
    observer: &mut impl PreorderVisitor<Break = Infallible>,
    scratch: std::fs::File,
) -> io::Result<MlRecordStream> {
    write_ml(map, w, observer, RecordBuffer::with_scratch(scratch))
}

/// The maximum-likelihood tree's header and records, gathered in `out`.
fn write_ml(
    map: &impl PreorderSource,
    mut w: impl Write,
    observer: &mut impl PreorderVisitor<Break = Infallible>,
    out: RecordBuffer,
) -> io::Result<MlRecordStream> {
    let mut ml = if map.node_kind() == NodeKind::Stamped {
        ml_records::<true>(map, observer, out)?
    } else {
        ml_records::<false>(map, observer, out)?
    };
    let size = usize::try_from(ml.nodes).map_err(io::Error::other)?;
    write_header(&mut w, BT_FIRST_LINE, super::ot::TreeKind::of(map.node_kind()).id(), size, map.resolution())?;
    ml.write_records(w)?;
    Ok(ml)
}

/// The node stream of the maximum-likelihood tree (`toMaxLikelihood()`
/// then `prune()`), as `.bt` records, with its node count.
pub struct MlRecordStream {
    /// The `.bt` records, in pre-order (what follows the header): in
    /// memory, or most of them in a scratch file.
    records: RecordBuffer,
    /// Nodes of the maximum-likelihood tree (`size()`, the header's).
    pub nodes: u64,
}

impl MlRecordStream {
    /// Writes the records (what follows the header) to `w`.
    pub fn write_records(&mut self, mut w: impl Write) -> io::Result<()> {
        match self.records.in_memory_bytes() {
            Some(bytes) => w.write_all(bytes),
            None => io::copy(&mut self.records.reader()?, &mut w).map(|_| ()),
        }
    }

    /// The [`TreeSummary`] of the maximum-likelihood tree the records
    /// describe, of `map`'s kind and resolution: read from the records
    /// alone. Its every node holds a clamping bound, so all count as at
    /// the threshold. Fails only when records on disk cannot be read.
    pub fn summary(&mut self, map: &impl PreorderSource) -> io::Result<TreeSummary> {
        if let Some(bytes) = self.records.in_memory_bytes() {
            return Ok(summarize(map, bytes.chunks_exact(2).map(|r| u16::from_le_bytes([r[0], r[1]]))));
        }
        let mut reader = io::BufReader::with_capacity(1 << 16, self.records.reader()?);
        let mut failed = None;
        let records = std::iter::from_fn(|| {
            let mut r = [0u8; 2];
            match reader.read_exact(&mut r) {
                Ok(()) => Some(u16::from_le_bytes(r)),
                Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => None,
                Err(e) => {
                    failed = Some(e);
                    None
                }
            }
        });
        let summary = summarize(map, records);
        failed.map_or(Ok(summary), Err)
    }
}

/// The [`TreeSummary`] of the maximum-likelihood tree of these records
/// ([`MlRecordStream::summary`]).
fn summarize(map: &impl PreorderSource, mut records: impl Iterator<Item = u16>) -> TreeSummary {
    let mut s = TreeSummary::empty(map.node_kind(), map.resolution());
    let mut extremes = LeafExtremes::new();
    if let Some(root) = records.next() {
        s.nodes = 1;
        if root == 0 {
            s.add_leaf(0);
            extremes.add([0; 4], 0);
        }
        // (key, depth, labels, next child) of each open node
        let mut path = vec![([0u16; 4], 0u8, root, 0u32)];
        while let Some(open) = path.last_mut() {
            if open.3 == 8 {
                path.pop();
                continue;
            }
            let (depth, pos) = (open.1 + 1, open.3);
            let key = child_key(open.0, pos, depth);
            open.3 += 1;
            match (open.2 >> (2 * pos)) & 3 {
                0 => continue,
                3 => path.push((key, depth, records.next().unwrap_or(0), 0)),
                _ => {
                    s.add_leaf(depth);
                    extremes.add(key, depth);
                }
            }
            s.nodes += 1;
        }
    }
    extremes.widen(&KeySpace::new(map.resolution()), &mut s.bounds);
    s.at_threshold = s.nodes;
    s.finish()
}

/// Appends to `out` the node stream `toMaxLikelihood()` then `prune()`
/// would leave, without copying or changing the tree; returns the node
/// count (`size()`) that tree would have.
pub(crate) fn write_ml_data(tree: &OccupancyTree, out: &mut Vec<u8>) -> usize {
    let mut ml = write_map(tree, io::sink()).expect("a tree's walk cannot fail");
    ml.write_records(&mut *out).expect("records in memory");
    ml.nodes as usize
}

/// The maximum-likelihood records of `map`, from a walk that `observer`
/// watches too (see [`MaxLikelihood`]).
fn ml_records<const STAMPED: bool>(
    map: &impl PreorderSource,
    observer: &mut impl PreorderVisitor<Break = Infallible>,
    out: RecordBuffer,
) -> io::Result<MlRecordStream> {
    let mut records = MlRecords::<STAMPED>::new(map.sensor(), 1, out);
    let ControlFlow::Continue(()) = map.visit_preorder(&mut Tee(observer, &mut records))?;
    records.complete(map)
}

/// Gathers the records of the maximum-likelihood tree from a walk of the
/// map, as a visitor (so that it can watch a walk that writes another
/// format, `.ot` say), then [`Self::finish`] completes them.
///
/// `prune` merges level by level from depth 15 up and stops after the
/// first level that merged nothing. One read-only pass writes the records
/// as if pruning went all the way up, dropping the subtrees that merge, and
/// counts the merges per depth. That is the answer unless a level above
/// the one where `prune` stops would merge something; then a second walk
/// writes the records with merges below that level only.
pub struct MaxLikelihood(MlPass);

/// The records being gathered, by whether stamps take part.
enum MlPass {
    Plain(MlRecords<false>),
    Stamped(MlRecords<true>),
}

impl MaxLikelihood {
    /// Ready for a walk of `map`.
    pub fn new(map: &impl PreorderSource) -> Self {
        Self::with_buffer(map, RecordBuffer::in_memory(records_hint(map.node_count())))
    }

    /// Ready for a walk of `map`, holding no more than a few megabytes of
    /// records in memory: the others wait in `scratch` (a file opened for
    /// reading and writing, emptied first).
    pub fn with_scratch(map: &impl PreorderSource, scratch: std::fs::File) -> Self {
        Self::with_buffer(map, RecordBuffer::with_scratch(scratch))
    }

    fn with_buffer(map: &impl PreorderSource, out: RecordBuffer) -> Self {
        let sensor = map.sensor();
        MaxLikelihood(if map.node_kind() == NodeKind::Stamped {
            MlPass::Stamped(MlRecords::new(sensor, 1, out))
        } else {
            MlPass::Plain(MlRecords::new(sensor, 1, out))
        })
    }

    /// The records and node count of the maximum-likelihood tree, after
    /// the walk of `map` this visitor watched (walking it again in the
    /// rare case described above).
    pub fn finish(self, map: &impl PreorderSource) -> io::Result<MlRecordStream> {
        match self.0 {
            MlPass::Plain(r) => r.complete(map),
            MlPass::Stamped(r) => r.complete(map),
        }
    }
}

impl PreorderVisitor for MaxLikelihood {
    type Break = Infallible;

    #[inline(always)]
    fn enter(&mut self, node: &PreorderNode, children: &ChildGroup<'_>) -> ControlFlow<Infallible> {
        match &mut self.0 {
            MlPass::Plain(r) => r.enter(node, children),
            MlPass::Stamped(r) => r.enter(node, children),
        }
    }

    #[inline(always)]
    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<Infallible> {
        match &mut self.0 {
            MlPass::Plain(r) => r.leaf(node),
            MlPass::Stamped(r) => r.leaf(node),
        }
    }

    #[inline(always)]
    fn leave(&mut self, node: &PreorderNode) -> ControlFlow<Infallible> {
        match &mut self.0 {
            MlPass::Plain(r) => r.leave(node),
            MlPass::Stamped(r) => r.leave(node),
        }
    }
}

/// Bytes to reserve for a tree's records: a guess (two bytes per node
/// with children, about a sixth of the nodes on the simulated maps) that
/// saves most of the output's regrowth.
fn records_hint(nodes: u64) -> usize {
    2 * (usize::try_from(nodes).unwrap_or(usize::MAX) / 6 + 1)
}

/// The records of the tree as `toMaxLikelihood()` would leave it, read in
/// place by a pre-order walk.
///
/// Maximum likelihood leaves a node one of two values: the upper clamping
/// bound when it is occupied (class 1), else the lower (class 0). What
/// `prune` and `writeBinaryConst` then compare and test depends on the
/// class alone, so they are precomputed per class: the `.bt` label, and
/// whether the values of two classes compare equal (they may not, even
/// within a class, when a bound is NaN; they do across classes when the
/// bounds are equal).
///
/// A node with children gets its record when the walk enters it, with the
/// labels of its leaf children; each inner child adds its label when the
/// walk leaves it: 3, or, when the child merges (eight leaves that
/// `pruneNode` would merge, at depth `lowest` or deeper, once every level
/// below it is pruned), the label of a leaf of its class, its own records
/// dropped.
struct MlRecords<const STAMPED: bool> {
    threshold: f32,
    /// The label of a leaf of each class: 2 when its value is occupied, else 1.
    label: [u16; 2],
    /// `equal[a][b]`: whether values of classes `a` and `b` compare equal.
    equal: [[bool; 2]; 2],
    lowest: usize,
    out: RecordBuffer,
    /// Merges per depth.
    counts: [usize; 16],
    /// The open record of the node at each depth of the walk's path.
    path: [Open; 16],
    /// Stamped trees: the stamps of those nodes' children that are (or
    /// merged into) leaves, by position.
    stamps: [[u32; 8]; 16],
}

/// The record of a node whose subtree the walk has not left yet.
#[derive(Clone, Copy, Default)]
struct Open {
    /// Where its record lies in the output.
    at: usize,
    labels: u16,
    /// Classes of the children that are (or merged into) leaves, by position.
    occupied: u8,
    /// Children that stay inner.
    inner: u8,
    /// Inner children the walk has not left yet.
    pending: u8,
}

impl<const STAMPED: bool> MlRecords<STAMPED> {
    /// Ready for a walk, with merges at depth `lowest` or deeper, the
    /// records gathered in `out`.
    fn new(s: &SensorModel, lowest: usize, out: RecordBuffer) -> Self {
        let value = [s.clamping_min, s.clamping_max];
        let label = value.map(|v| if s.is_occupied(v) { 2 } else { 1 });
        let equal = [0, 1].map(|a| [0, 1].map(|b| value[a] == value[b]));
        MlRecords {
            threshold: s.occupancy_threshold,
            label,
            equal,
            lowest,
            out,
            counts: [0; 16],
            path: [Open::default(); 16],
            stamps: [[0; 8]; 16],
        }
    }

    /// The records and node count of the maximum-likelihood tree after a
    /// walk of `map` with merges at every depth (see [`MaxLikelihood`]).
    fn complete(self, map: &impl PreorderSource) -> io::Result<MlRecordStream> {
        // as `OccupancyTree::prune`: the deepest level that merges nothing
        // stops it; only the levels below that one merge
        let stop = (1..16).rev().find(|&d| self.counts[d] == 0).unwrap_or(0);
        let lowest = stop.max(1);
        let mut records = self.out;
        if self.counts[1..lowest].iter().any(|&c| c > 0) {
            let mut again = MlRecords::<STAMPED>::new(map.sensor(), lowest, records.emptied());
            let ControlFlow::Continue(()) = map.visit_preorder(&mut again)?;
            records = again.out;
        }
        let merged = 8 * self.counts[lowest..].iter().sum::<usize>() as u64;
        Ok(MlRecordStream { records, nodes: map.node_count() - merged })
    }

    /// A child at `pos` of the open node at `depth` that is a leaf of
    /// `class`, or merged into one.
    #[inline(always)]
    fn add_leaf(&mut self, depth: usize, pos: u32, class: u8, stamp: u32) {
        let open = &mut self.path[depth];
        open.occupied |= class << pos;
        open.labels |= self.label[usize::from(class)] << (2 * pos);
        if STAMPED {
            self.stamps[depth][pos as usize] = stamp;
        }
    }
}

impl<const STAMPED: bool> PreorderVisitor for MlRecords<STAMPED> {
    type Break = Infallible;

    #[inline(always)]
    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<Infallible> {
        if node.depth == 0 {
            // a lone root: a record without children
            self.out.push([0, 0]);
        }
        ControlFlow::Continue(())
    }

    #[inline(always)]
    fn enter(&mut self, node: &PreorderNode, children: &ChildGroup<'_>) -> ControlFlow<Infallible> {
        let depth = usize::from(node.depth);
        self.path[depth] = Open { at: self.out.len(), ..Open::default() };
        self.out.push([0, 0]);
        let (masks, values, extras) = (children.child_masks(), children.values(), children.extras());
        for (rank, pos) in children.positions() {
            if masks[rank] == 0 {
                let class = u8::from(values[rank] >= self.threshold);
                self.add_leaf(depth, pos, class, if STAMPED { extras[rank] } else { 0 });
            } else {
                self.path[depth].pending |= 1 << pos;
            }
        }
        ControlFlow::Continue(())
    }

    #[inline(always)]
    fn leave(&mut self, node: &PreorderNode) -> ControlFlow<Infallible> {
        let depth = usize::from(node.depth);
        let open = self.path[depth];
        self.out.set(open.at, open.labels.to_le_bytes());
        if depth == 0 {
            return ControlFlow::Continue(());
        }
        let merged = self.merges(node, &open);
        let parent = &mut self.path[depth - 1];
        let pos = parent.pending.trailing_zeros();
        parent.pending &= parent.pending - 1;
        match merged {
            Some(class) => {
                self.counts[depth] += 1;
                self.out.truncate(open.at);
                self.add_leaf(depth - 1, pos, class, self.stamps[depth][0]);
            }
            None => {
                parent.inner |= 1 << pos;
                parent.labels |= 3 << (2 * pos);
            }
        }
        ControlFlow::Continue(())
    }
}

impl<const STAMPED: bool> MlRecords<STAMPED> {
    /// `pruneNode`'s test on a node whose subtree the walk has left: eight
    /// leaves whose values (and stamps) all equal child 0's. `Some(class)`
    /// of the leaf it becomes.
    #[inline(always)]
    fn merges(&self, node: &PreorderNode, open: &Open) -> Option<u8> {
        if node.child_mask != 0xff || open.inner != 0 || usize::from(node.depth) < self.lowest {
            return None;
        }
        let stamps = &self.stamps[usize::from(node.depth)];
        if STAMPED && stamps.iter().any(|&s| s != stamps[0]) {
            return None;
        }
        let class0 = usize::from(open.occupied & 1);
        let others = open.occupied >> 1;
        if (others != 0 && !self.equal[1][class0]) || (others != 0x7f && !self.equal[0][class0]) {
            return None;
        }
        Some(class0 as u8)
    }
}

/// Writes the tree as it is (`writeBinaryConst`): leaves are labelled
/// occupied or free by the occupancy threshold.
pub fn write_const(tree: &OccupancyTree, w: impl Write) -> io::Result<()> {
    write_const_map(tree, w)
}

/// Writes any map walked as one tree as [`write_const`] writes that tree:
/// the same bytes.
pub fn write_const_map(map: &impl PreorderSource, mut w: impl Write) -> io::Result<()> {
    let id = super::ot::TreeKind::of(map.node_kind()).id();
    let size = usize::try_from(map.node_count()).map_err(io::Error::other)?;
    write_header(&mut w, BT_FIRST_LINE, id, size, map.resolution())?;
    write_const_data(map, w)
}

/// Writes the binary node stream alone, without header
/// (`writeBinaryData`): the tree as it is, like [`write_const`].
pub(crate) fn write_data(tree: &OccupancyTree, w: impl Write) -> io::Result<()> {
    write_const_data(tree, w)
}

/// [`write_data`] of any map.
fn write_const_data(map: &impl PreorderSource, w: impl Write) -> io::Result<()> {
    let hint = records_hint(map.node_count());
    let mut records = ConstRecords { sensor: map.sensor(), out: Pieces::new(w, hint) };
    if let ControlFlow::Break(e) = map.visit_preorder(&mut records)? {
        return Err(e);
    }
    records.out.finish()
}

/// The records of the tree as it is: per node with children, children with
/// children labelled 3, leaves 2 when occupied, else 1; written in pieces
/// (no record changes once made).
struct ConstRecords<'s, W> {
    sensor: &'s SensorModel,
    out: Pieces<W>,
}

impl<W: Write> PreorderVisitor for ConstRecords<'_, W> {
    type Break = io::Error;

    #[inline(always)]
    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<io::Error> {
        if node.depth == 0 {
            // a lone root: a record without children
            self.out.bytes.extend_from_slice(&[0, 0]);
        }
        ControlFlow::Continue(())
    }

    #[inline(always)]
    fn leave(&mut self, _: &PreorderNode) -> ControlFlow<io::Error> {
        self.out.flush_if_full()
    }

    #[inline(always)]
    fn enter(&mut self, _: &PreorderNode, children: &ChildGroup<'_>) -> ControlFlow<io::Error> {
        let (masks, values) = (children.child_masks(), children.values());
        let mut labels = 0u16;
        for (rank, pos) in children.positions() {
            let label = if masks[rank] != 0 {
                3
            } else if self.sensor.is_occupied(values[rank]) {
                2
            } else {
                1
            };
            labels |= label << (2 * pos);
        }
        self.out.bytes.extend_from_slice(&labels.to_le_bytes());
        ControlFlow::Continue(())
    }
}

/// Reads a `.bt` file from disk ([`read`]).
pub fn read_file(path: impl AsRef<Path>) -> Result<OccupancyTree, TreeFileError> {
    read(super::buffered_file(path.as_ref())?)
}

/// Writes a `.bt` file atomically ([`write()`] into a temporary file that
/// replaces `path` once complete).
pub fn write_file(tree: &OccupancyTree, path: impl AsRef<Path>) -> io::Result<()> {
    super::write_atomically(path.as_ref(), |w| write(tree, w))
}
