//! `.ot` files: OctoMap's full trees (`AbstractOcTree::write` / `read`).
//!
//! Layout: the text header (`# Octomap OcTree file`, `id`, `size`, `res`,
//! `data`), then every node in depth-first pre-order (children 0..7): its
//! payload and one byte whose bit `i` says whether child `i` exists. The
//! payload depends on the tree type named by `id`: `OcTree` and
//! `OcTreeStamped` a little-endian `f32` log-odds (stamps are not stored),
//! `ColorOcTree` the log-odds then `r, g, b` bytes, and `CountingOcTree`,
//! whose id is `OcTreeBase`, a little-endian `u32` count. See `formats/ot.md`.

use super::header::{read_first_line, read_header, write_header, CountingReader, FirstLine, OT_FIRST_LINE};
use super::pieces::Pieces;
use super::TreeFileError;
use crate::sensor::SensorModel;
use crate::tree::{ChildGroup, CountingTree, NodeKind, OccupancyTree, PreorderBuilder};
use crate::tree::{PreorderNode, PreorderSource, PreorderVisitor, Tee};
use std::convert::Infallible;
use std::io::{self, BufRead, Write};
use std::ops::ControlFlow;
use std::path::Path;

pub use crate::tree::TreeKind;

/// Bytes of one node's payload in an `.ot` file of trees of `kind`.
fn payload_len(kind: TreeKind) -> usize {
    match kind {
        TreeKind::ColorOcTree => 7,
        _ => 4,
    }
}

/// A tree read from an `.ot` file.
// the occupancy variant (about 1 KB inline: the arena's vectors, node sizes,
// search starts) is what nearly every file holds; boxing it would cost every
// read an allocation and every use an indirection
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum AnyTree {
    /// `OcTree`, `ColorOcTree` or `OcTreeStamped` (see [`OccupancyTree::kind`]).
    Occupancy(OccupancyTree),
    /// `CountingOcTree`.
    Counting(CountingTree),
}

impl AnyTree {
    /// The tree's OctoMap type (what an `.ot` file's `id` line names).
    pub fn kind(&self) -> TreeKind {
        match self {
            AnyTree::Occupancy(t) => TreeKind::of(t.kind()),
            AnyTree::Counting(_) => TreeKind::CountingOcTree,
        }
    }

    /// The occupancy tree, if this is one.
    pub fn occupancy(&self) -> Option<&OccupancyTree> {
        match self {
            AnyTree::Occupancy(t) => Some(t),
            AnyTree::Counting(_) => None,
        }
    }

    /// The occupancy tree by value, if this is one.
    pub fn into_occupancy(self) -> Option<OccupancyTree> {
        match self {
            AnyTree::Occupancy(t) => Some(t),
            AnyTree::Counting(_) => None,
        }
    }
}

/// Reads an `.ot` file (`AbstractOcTree::read`).
pub fn read(r: impl BufRead) -> Result<AnyTree, TreeFileError> {
    let mut r = CountingReader::new(r);
    let (first, line) = read_first_line(&mut r)?;
    if first != FirstLine::Full {
        let reason = if first == FirstLine::Binary {
            "this is a binary .bt file".to_string()
        } else {
            format!("first line is `{}`", String::from_utf8_lossy(&line[..line.len().min(60)]))
        };
        return Err(TreeFileError::WrongFormat { offset: 0, expected: ".ot file", reason });
    }
    let header = read_header(&mut r)?;
    let kind = TreeKind::from_id(&header.id)
        .ok_or_else(|| TreeFileError::UnknownTreeType { id: header.id.clone(), offset: Some(header.id_offset) })?;
    if header.size == 0 {
        // OctoMap reads no data then, whatever follows
        return empty(kind, header.resolution);
    }
    read_data(&mut r, kind, header.resolution, header.size)
}

/// An empty tree of `kind`.
pub(crate) fn empty(kind: TreeKind, resolution: f64) -> Result<AnyTree, TreeFileError> {
    let bad_res = |_| TreeFileError::BadResolution { value: resolution, offset: None };
    Ok(match kind {
        TreeKind::CountingOcTree => AnyTree::Counting(CountingTree::new(resolution).map_err(bad_res)?),
        _ => AnyTree::Occupancy(
            OccupancyTree::with_kind(resolution, SensorModel::default(), node_kind(kind)).map_err(bad_res)?,
        ),
    })
}

fn node_kind(kind: TreeKind) -> NodeKind {
    match kind {
        TreeKind::OcTree => NodeKind::Plain,
        TreeKind::ColorOcTree => NodeKind::Color,
        // counts live in the extras, like stamps
        TreeKind::OcTreeStamped | TreeKind::CountingOcTree => NodeKind::Stamped,
    }
}

/// Reads one tree's node stream, root first (`OcTreeBaseImpl::readData`):
/// exactly the nodes the child masks announce, nothing after them.
/// `size_hint` (the header's unchecked `size`) only sizes the arena.
pub(crate) fn read_data<R: BufRead>(
    r: &mut CountingReader<R>,
    kind: TreeKind,
    resolution: f64,
    size_hint: u64,
) -> Result<AnyTree, TreeFileError> {
    let b = match kind {
        TreeKind::OcTree => {
            read_nodes::<R, 5>(r, kind, size_hint, |n| (f32::from_le_bytes([n[0], n[1], n[2], n[3]]), None))?
        }
        TreeKind::OcTreeStamped => {
            read_nodes::<R, 5>(r, kind, size_hint, |n| (f32::from_le_bytes([n[0], n[1], n[2], n[3]]), Some(0)))?
        }
        TreeKind::ColorOcTree => read_nodes::<R, 8>(r, kind, size_hint, |n| {
            (f32::from_le_bytes([n[0], n[1], n[2], n[3]]), Some(u32::from_le_bytes([n[4], n[5], n[6], 0])))
        })?,
        TreeKind::CountingOcTree => {
            read_nodes::<R, 5>(r, kind, size_hint, |n| (0.0, Some(u32::from_le_bytes([n[0], n[1], n[2], n[3]]))))?
        }
    };
    debug_assert!(b.is_complete());
    let bad_res = |_| TreeFileError::BadResolution { value: resolution, offset: None };
    if kind == TreeKind::CountingOcTree {
        let arena = b.finish_arena().expect("complete");
        return Ok(AnyTree::Counting(CountingTree::from_arena(resolution, arena).map_err(bad_res)?));
    }
    let tree = b.finish(resolution, SensorModel::default()).map_err(bad_res)?.expect("complete");
    Ok(AnyTree::Occupancy(tree))
}

/// The node records (`N` bytes each: payload, then the child mask) until
/// the tree is complete, decoded by `decode`. Records are taken straight
/// from the reader's buffer; only one that straddles two buffer fills is
/// copied.
fn read_nodes<R: BufRead, const N: usize>(
    r: &mut CountingReader<R>,
    kind: TreeKind,
    size_hint: u64,
    decode: impl Fn(&[u8; N]) -> (f32, Option<u32>),
) -> Result<PreorderBuilder, TreeFileError> {
    debug_assert_eq!(N, payload_len(kind) + 1);
    let mut b = PreorderBuilder::with_hint(node_kind(kind), usize::try_from(size_hint).unwrap_or(usize::MAX));
    // reserve at once what the header announces, as far as the bytes at
    // hand can hold it (the whole rest when reading from memory)
    let at_hand = r.chunk()?.len() / N;
    b.reserve(usize::try_from(size_hint).unwrap_or(usize::MAX).min(at_hand));
    let mut index = 0u64;
    let too_deep = |offset: u64| TreeFileError::TooDeep { offset };
    loop {
        let base = r.offset;
        let buf = r.chunk()?;
        let mut used = 0;
        for rec in buf.chunks_exact(N) {
            let rec: &[u8; N] = rec.try_into().expect("chunks_exact");
            let (value, extra) = decode(rec);
            b.push_with_extra(value, extra, rec[N - 1], index).map_err(|_| too_deep(base + used as u64))?;
            used += N;
            index += 1;
            if b.is_complete() {
                break;
            }
        }
        r.advance(used);
        if b.is_complete() {
            return Ok(b);
        }
        // a record split between two fills of the buffer (or the end)
        let mut rec = [0u8; N];
        let offset = r.offset;
        r.read_exact(&mut rec, "a node")?;
        let (value, extra) = decode(&rec);
        b.push_with_extra(value, extra, rec[N - 1], index).map_err(|_| too_deep(offset))?;
        index += 1;
        if b.is_complete() {
            return Ok(b);
        }
    }
}

/// Writes `tree` as OctoMap's `write` does, under its type's id.
pub fn write(tree: &OccupancyTree, w: impl Write) -> io::Result<()> {
    write_map(tree, w)
}

/// Writes any map walked as one tree (a tree, a tiled map or a tile set)
/// as [`write()`] writes that tree: the same bytes.
pub fn write_map(map: &impl PreorderSource, w: impl Write) -> io::Result<()> {
    write_map_observed(map, w, &mut ())
}

/// [`write_map`], showing every node of the walk to `observer` as well
/// (statistics gathered while writing, without a second walk).
pub fn write_map_observed(
    map: &impl PreorderSource,
    mut w: impl Write,
    observer: &mut impl PreorderVisitor<Break = Infallible>,
) -> io::Result<()> {
    let size = usize::try_from(map.node_count()).map_err(io::Error::other)?;
    write_header(&mut w, OT_FIRST_LINE, TreeKind::of(map.node_kind()).id(), size, map.resolution())?;
    write_stream(map, w, observer)
}

/// The node stream of `map` alone, without header (`writeData`), each
/// node shown to `observer` too.
fn write_stream(
    map: &impl PreorderSource,
    mut w: impl Write,
    observer: &mut impl PreorderVisitor<Break = Infallible>,
) -> io::Result<()> {
    if TreeKind::of(map.node_kind()) == TreeKind::ColorOcTree {
        write_nodes(&mut w, |v| map.visit_preorder(&mut Tee(v, observer)), color_payload)
    } else {
        write_nodes(&mut w, |v| map.visit_preorder(&mut Tee(v, observer)), |value, _| value.to_le_bytes())
    }
}

/// The `.ot` bytes of `tree`, for tests that compare trees.
#[cfg(test)]
pub(crate) fn to_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut out = Vec::new();
    write(tree, &mut out).expect("writing to a Vec");
    out
}

/// A colour tree node's payload: log-odds, then `r, g, b`.
fn color_payload(value: f32, extra: u32) -> [u8; 7] {
    let [v0, v1, v2, v3] = value.to_le_bytes();
    let [r, g, b, _] = extra.to_le_bytes();
    [v0, v1, v2, v3, r, g, b]
}

/// Writes the node stream alone, without header (`writeData`).
pub(crate) fn write_data(tree: &OccupancyTree, w: impl Write) -> io::Result<()> {
    write_stream(tree, w, &mut ())
}

/// Writes a counting tree (`id OcTreeBase`, `u32` counts).
pub fn write_counting(tree: &CountingTree, mut w: impl Write) -> io::Result<()> {
    write_header(&mut w, OT_FIRST_LINE, TreeKind::CountingOcTree.id(), tree.size(), tree.resolution())?;
    write_counting_data(tree, w)
}

/// A counting tree's node stream alone, without header.
pub(crate) fn write_counting_data(tree: &CountingTree, mut w: impl Write) -> io::Result<()> {
    let Some(root) = tree.root() else { return Ok(()) };
    write_nodes(&mut w, |v| Ok(root.visit_preorder(v)), |_, count| count.to_le_bytes())
}

/// The pre-order node stream that `walk` drives: each node's payload
/// (made from its value and extra), then its child-existence byte.
fn write_nodes<const P: usize, W: Write, F: Fn(f32, u32) -> [u8; P]>(
    w: &mut W,
    walk: impl FnOnce(&mut NodeStream<F, &mut W>) -> io::Result<ControlFlow<io::Error>>,
    payload: F,
) -> io::Result<()> {
    let mut out = NodeStream { payload, out: Pieces::new(w, usize::MAX) };
    if let ControlFlow::Break(e) = walk(&mut out)? {
        return Err(e);
    }
    out.out.finish()
}

/// The `.ot` records of the nodes a pre-order walk visits, written in
/// pieces.
struct NodeStream<F, W> {
    payload: F,
    out: Pieces<W>,
}

impl<const P: usize, F: Fn(f32, u32) -> [u8; P], W: Write> NodeStream<F, W> {
    #[inline(always)]
    fn record(&mut self, node: &PreorderNode) {
        self.out.bytes.extend_from_slice(&(self.payload)(node.value, node.extra));
        self.out.bytes.push(node.child_mask);
    }
}

impl<const P: usize, F: Fn(f32, u32) -> [u8; P], W: Write> PreorderVisitor for NodeStream<F, W> {
    type Break = io::Error;

    #[inline(always)]
    fn enter(&mut self, node: &PreorderNode, _: &ChildGroup<'_>) -> ControlFlow<io::Error> {
        self.record(node);
        ControlFlow::Continue(())
    }

    #[inline(always)]
    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<io::Error> {
        self.record(node);
        ControlFlow::Continue(())
    }

    #[inline(always)]
    fn leave(&mut self, _: &PreorderNode) -> ControlFlow<io::Error> {
        self.out.flush_if_full()
    }
}

/// Reads an `.ot` file from disk ([`read`]).
pub fn read_file(path: impl AsRef<Path>) -> Result<AnyTree, TreeFileError> {
    read(super::buffered_file(path.as_ref())?)
}

/// Writes an occupancy tree's `.ot` file atomically ([`write()`] into a
/// temporary file that replaces `path` once complete).
pub fn write_file(tree: &OccupancyTree, path: impl AsRef<Path>) -> io::Result<()> {
    super::write_atomically(path.as_ref(), |w| write(tree, w))
}

/// Writes a counting tree's `.ot` file atomically ([`write_counting`]).
pub fn write_counting_file(tree: &CountingTree, path: impl AsRef<Path>) -> io::Result<()> {
    super::write_atomically(path.as_ref(), |w| write_counting(tree, w))
}
