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
use super::TreeFileError;
use crate::sensor::SensorModel;
use crate::tree::{CountingTree, NodeKind, NodeRef, OccupancyTree, PreorderBuilder};
use std::io::{self, BufRead, Write};

/// The tree types an `.ot` file may hold, by their header id.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TreeKind {
    OcTree,
    OcTreeStamped,
    ColorOcTree,
    CountingOcTree,
}

impl TreeKind {
    pub fn from_id(id: &str) -> Option<TreeKind> {
        match id {
            "OcTree" => Some(TreeKind::OcTree),
            "OcTreeStamped" => Some(TreeKind::OcTreeStamped),
            "ColorOcTree" => Some(TreeKind::ColorOcTree),
            // CountingOcTree does not override getTreeType()
            "OcTreeBase" => Some(TreeKind::CountingOcTree),
            _ => None,
        }
    }

    /// The id OctoMap writes for this type.
    pub fn id(self) -> &'static str {
        match self {
            TreeKind::OcTree => "OcTree",
            TreeKind::OcTreeStamped => "OcTreeStamped",
            TreeKind::ColorOcTree => "ColorOcTree",
            TreeKind::CountingOcTree => "OcTreeBase",
        }
    }

    pub fn of(kind: NodeKind) -> TreeKind {
        match kind {
            NodeKind::Plain => TreeKind::OcTree,
            NodeKind::Color => TreeKind::ColorOcTree,
            NodeKind::Stamped => TreeKind::OcTreeStamped,
        }
    }

    /// Bytes of one node's payload.
    fn payload_len(self) -> usize {
        match self {
            TreeKind::ColorOcTree => 7,
            _ => 4,
        }
    }
}

/// A tree read from an `.ot` file.
#[derive(Clone, Debug)]
pub enum AnyTree {
    /// `OcTree`, `ColorOcTree` or `OcTreeStamped` (see [`OccupancyTree::kind`]).
    Occupancy(OccupancyTree),
    /// `CountingOcTree`.
    Counting(CountingTree),
}

impl AnyTree {
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
    read_data(&mut r, kind, header.resolution)
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
pub(crate) fn read_data<R: BufRead>(
    r: &mut CountingReader<R>,
    kind: TreeKind,
    resolution: f64,
) -> Result<AnyTree, TreeFileError> {
    let mut b = PreorderBuilder::with_kind(node_kind(kind));
    let mut buf = [0u8; 8];
    let len = kind.payload_len() + 1;
    let mut index = 0;
    while !b.is_complete() {
        let offset = r.offset;
        r.read_exact(&mut buf[..len], "a node")?;
        let word = [buf[0], buf[1], buf[2], buf[3]];
        let (value, extra) = match kind {
            TreeKind::OcTree => (f32::from_le_bytes(word), None),
            TreeKind::OcTreeStamped => (f32::from_le_bytes(word), Some(0)),
            TreeKind::ColorOcTree => (f32::from_le_bytes(word), Some(u32::from_le_bytes([buf[4], buf[5], buf[6], 0]))),
            TreeKind::CountingOcTree => (0.0, Some(u32::from_le_bytes(word))),
        };
        b.push_with_extra(value, extra, buf[len - 1], index).map_err(|_| TreeFileError::TooDeep { offset })?;
        index += 1;
    }
    let bad_res = |_| TreeFileError::BadResolution { value: resolution, offset: None };
    if kind == TreeKind::CountingOcTree {
        let arena = b.finish_arena().expect("complete");
        return Ok(AnyTree::Counting(CountingTree::from_arena(resolution, arena).map_err(bad_res)?));
    }
    let tree = b.finish(resolution, SensorModel::default()).map_err(bad_res)?.expect("complete");
    Ok(AnyTree::Occupancy(tree))
}

/// Writes `tree` as OctoMap's `write` does, under its type's id.
pub fn write(tree: &OccupancyTree, mut w: impl Write) -> io::Result<()> {
    let kind = TreeKind::of(tree.kind());
    write_header(&mut w, OT_FIRST_LINE, kind.id(), tree.size(), tree.resolution())?;
    write_data(tree, w)
}

/// Writes the node stream alone, without header (`writeData`).
pub(crate) fn write_data(tree: &OccupancyTree, mut w: impl Write) -> io::Result<()> {
    let kind = TreeKind::of(tree.kind());
    write_nodes(tree.root(), &mut w, |n, out| {
        out.extend_from_slice(&n.value().to_le_bytes());
        if kind == TreeKind::ColorOcTree {
            out.extend_from_slice(&n.extra().to_le_bytes()[..3]);
        }
    })
}

/// Writes a counting tree (`id OcTreeBase`, `u32` counts).
pub fn write_counting(tree: &CountingTree, mut w: impl Write) -> io::Result<()> {
    write_header(&mut w, OT_FIRST_LINE, TreeKind::CountingOcTree.id(), tree.size(), tree.resolution())?;
    write_counting_data(tree, w)
}

/// A counting tree's node stream alone, without header.
pub(crate) fn write_counting_data(tree: &CountingTree, mut w: impl Write) -> io::Result<()> {
    write_nodes(tree.root(), &mut w, |n, out| out.extend_from_slice(&n.extra().to_le_bytes()))
}

/// The pre-order node stream: payload, then the child-existence byte.
fn write_nodes(
    root: Option<NodeRef<'_>>,
    w: &mut impl Write,
    payload: impl Fn(&NodeRef<'_>, &mut Vec<u8>),
) -> io::Result<()> {
    let Some(root) = root else { return Ok(()) };
    let mut out = Vec::with_capacity(1 << 16);
    let mut stack = vec![root];
    while let Some(n) = stack.pop() {
        payload(&n, &mut out);
        out.push(n.child_mask());
        for rank in (0..n.child_count()).rev() {
            stack.extend(n.nth_child(rank));
        }
        if out.len() >= (1 << 16) - 16 {
            w.write_all(&out)?;
            out.clear();
        }
    }
    w.write_all(&out)
}
