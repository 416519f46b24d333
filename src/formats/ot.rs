//! `.ot` files: OctoMap's full trees (`AbstractOcTree::write` / `read`).
//!
//! Layout: the text header (`# Octomap OcTree file`, `id`, `size`, `res`,
//! `data`), then every node in depth-first pre-order (children 0..7): its
//! payload (for `OcTree` a little-endian `f32` log-odds) and one byte whose
//! bit `i` says whether child `i` exists. See `formats/ot.md`.

use super::header::{
    read_first_line, read_header, write_header, CountingReader, FirstLine, OT_FIRST_LINE,
};
use super::TreeFileError;
use crate::sensor::SensorModel;
use crate::tree::{OccupancyTree, PreorderBuilder};
use std::io::{self, BufRead, Write};

/// The tree kinds an `.ot` file may hold, by their header id.
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
            "CountingOcTree" => Some(TreeKind::CountingOcTree),
            _ => None,
        }
    }

    pub fn id(self) -> &'static str {
        match self {
            TreeKind::OcTree => "OcTree",
            TreeKind::OcTreeStamped => "OcTreeStamped",
            TreeKind::ColorOcTree => "ColorOcTree",
            TreeKind::CountingOcTree => "CountingOcTree",
        }
    }
}

/// A tree read from an `.ot` file.
#[derive(Clone, Debug)]
pub enum AnyTree {
    /// `OcTree`.
    Occupancy(OccupancyTree),
    /// `OcTreeStamped`: its `.ot` data holds log-odds only (no stamps).
    Stamped(OccupancyTree),
}

impl AnyTree {
    pub fn kind(&self) -> TreeKind {
        match self {
            AnyTree::Occupancy(_) => TreeKind::OcTree,
            AnyTree::Stamped(_) => TreeKind::OcTreeStamped,
        }
    }

    /// The occupancy part of any kind.
    pub fn occupancy(&self) -> &OccupancyTree {
        match self {
            AnyTree::Occupancy(t) | AnyTree::Stamped(t) => t,
        }
    }

    pub fn into_occupancy(self) -> OccupancyTree {
        match self {
            AnyTree::Occupancy(t) | AnyTree::Stamped(t) => t,
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
            format!(
                "first line is `{}`",
                String::from_utf8_lossy(&line[..line.len().min(60)])
            )
        };
        return Err(TreeFileError::WrongFormat {
            expected: ".ot",
            reason,
        });
    }
    let header = read_header(&mut r)?;
    let kind = TreeKind::from_id(&header.id)
        .ok_or_else(|| TreeFileError::UnknownTreeType(header.id.clone()))?;
    match kind {
        TreeKind::OcTree | TreeKind::OcTreeStamped => {}
        _ => return Err(TreeFileError::UnsupportedTreeType(header.id)),
    }
    let tree = if header.size > 0 {
        read_nodes(&mut r, header.resolution)?
    } else {
        OccupancyTree::new(header.resolution)
            .map_err(|_| TreeFileError::BadResolution(header.resolution))?
    };
    Ok(match kind {
        TreeKind::OcTreeStamped => AnyTree::Stamped(tree),
        _ => AnyTree::Occupancy(tree),
    })
}

/// Reads the pre-order node stream (value, child byte) into a tree.
fn read_nodes<R: BufRead>(
    r: &mut CountingReader<R>,
    resolution: f64,
) -> Result<OccupancyTree, TreeFileError> {
    let mut b = PreorderBuilder::new();
    let mut buf = [0u8; 5];
    let mut index = 0;
    while !b.is_complete() {
        let offset = r.offset;
        r.read_exact(&mut buf, "a node")?;
        let value = f32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]);
        b.push(value, buf[4], index)
            .map_err(|_| TreeFileError::TooDeep { offset })?;
        index += 1;
    }
    b.finish(resolution, SensorModel::default())
        .map_err(|_| TreeFileError::BadResolution(resolution))?
        .ok_or(TreeFileError::Truncated {
            offset: r.offset,
            what: "the node stream",
        })
}

/// Writes `tree` as OctoMap's `OcTree::write` does.
pub fn write(tree: &OccupancyTree, w: impl Write) -> io::Result<()> {
    write_kind(tree, TreeKind::OcTree, w)
}

/// Writes an occupancy tree under the header id of `kind` (`OcTree` or
/// `OcTreeStamped`, whose `.ot` data are the same).
pub fn write_kind(tree: &OccupancyTree, kind: TreeKind, mut w: impl Write) -> io::Result<()> {
    write_header(
        &mut w,
        OT_FIRST_LINE,
        kind.id(),
        tree.size(),
        tree.resolution(),
    )?;
    let Some(arena) = tree.arena() else {
        return Ok(());
    };
    let mut out = Vec::with_capacity(1 << 16);
    let mut stack = vec![0u32];
    while let Some(n) = stack.pop() {
        out.extend_from_slice(&arena.value(n).to_le_bytes());
        let mask = arena.mask(n);
        out.push(mask);
        let first = arena.first_child(n);
        for i in (0..mask.count_ones()).rev() {
            stack.push(first + i);
        }
        if out.len() >= (1 << 16) - 8 {
            w.write_all(&out)?;
            out.clear();
        }
    }
    w.write_all(&out)
}
