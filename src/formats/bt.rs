//! `.bt` files: OctoMap's compact maximum-likelihood trees
//! (`writeBinary` / `readBinary`).
//!
//! After the text header (`# Octomap OcTree binary file`) come two bytes per
//! node that has children, in depth-first pre-order; they hold two bits per
//! child `i` at bits `2i, 2i+1` of byte `i / 4` (child order 0..7): `00`
//! absent, `01` occupied leaf, `10` free leaf, `11` inner node. Values are
//! not stored: readers restore the clamping bounds. See `formats/bt.md`.

use super::header::{read_first_line, read_header, write_header, CountingReader, FirstLine, BT_FIRST_LINE};
use super::TreeFileError;
use crate::sensor::SensorModel;
use crate::tree::{NodeArena, NodeKind, OccupancyTree};
use std::io::{self, BufRead, Write};

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
        read_data(&mut r, resolution, sensor, NodeKind::Plain)?
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
/// nodes keep that kind's default colour or stamp.
pub(crate) fn read_data<R: BufRead>(
    r: &mut CountingReader<R>,
    resolution: f64,
    sensor: SensorModel,
    kind: NodeKind,
) -> Result<OccupancyTree, TreeFileError> {
    let mut tree = OccupancyTree::with_kind(resolution, sensor, kind)
        .map_err(|_| TreeFileError::BadResolution { value: resolution, offset: None })?;
    let mut arena = OccupancyTree::new_arena(kind, sensor.clamping_max);
    read_node(r, &mut arena, 0, 0, &sensor)?;
    tree.set_arena(Some(arena));
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
    if !(res > 0.0 && res.is_finite()) {
        return Err(TreeFileError::BadResolution { value: res, offset: Some(r.offset - 8) });
    }
    r.read_exact(&mut b4, "the legacy size")?;
    Ok((u64::from(u32::from_le_bytes(b4)), res))
}

fn read_node<R: BufRead>(
    r: &mut CountingReader<R>,
    arena: &mut NodeArena,
    id: u32,
    depth: u8,
    sensor: &SensorModel,
) -> Result<(), TreeFileError> {
    let offset = r.offset;
    let mut b = [0u8; 2];
    r.read_exact(&mut b, "a node's child labels")?;
    let labels = u16::from_le_bytes(b);
    let mut mask = 0u8;
    for i in 0..8 {
        if (labels >> (2 * i)) & 3 != 0 {
            mask |= 1 << i;
        }
    }
    if mask == 0 {
        return Ok(());
    }
    if depth >= 16 {
        return Err(TreeFileError::TooDeep { offset });
    }
    let first = arena.add_children(id, mask, 0.0);
    let mut child = first;
    for i in 0..8 {
        match (labels >> (2 * i)) & 3 {
            0 => continue,
            1 => arena.set_value(child, sensor.clamping_min),
            2 => arena.set_value(child, sensor.clamping_max),
            _ => {}
        }
        child += 1;
    }
    let mut child = first;
    for i in 0..8 {
        match (labels >> (2 * i)) & 3 {
            0 => continue,
            3 => {
                read_node(r, arena, child, depth + 1, sensor)?;
                let max = (0..arena.mask(child).count_ones())
                    .map(|j| arena.value(arena.first_child(child) + j))
                    .fold(-f32::MAX, |m, v| if v > m { v } else { m });
                arena.set_value(child, max);
            }
            _ => {}
        }
        child += 1;
    }
    Ok(())
}

/// Writes what OctoMap's `writeBinary` writes: the tree converted to
/// maximum likelihood and pruned. The caller's tree is left unchanged.
pub fn write(tree: &OccupancyTree, w: impl Write) -> io::Result<()> {
    let mut ml = tree.clone();
    ml.to_max_likelihood();
    ml.prune();
    write_const(&ml, w)
}

/// Writes the tree as it is (`writeBinaryConst`): leaves are labelled
/// occupied or free by the occupancy threshold.
pub fn write_const(tree: &OccupancyTree, mut w: impl Write) -> io::Result<()> {
    let id = super::ot::TreeKind::of(tree.kind()).id();
    write_header(&mut w, BT_FIRST_LINE, id, tree.size(), tree.resolution())?;
    write_data(tree, w)
}

/// Writes the binary node stream alone, without header
/// (`writeBinaryData`): the tree as it is, like [`write_const`].
pub(crate) fn write_data(tree: &OccupancyTree, mut w: impl Write) -> io::Result<()> {
    let Some(arena) = tree.arena() else {
        return Ok(());
    };
    let sensor = tree.sensor();
    let mut out = Vec::with_capacity(1 << 16);
    let mut stack = vec![0u32];
    while let Some(n) = stack.pop() {
        let mut labels = 0u16;
        let mask = arena.mask(n);
        let first = arena.first_child(n);
        let mut child = first;
        for i in 0..8 {
            if mask & (1 << i) == 0 {
                continue;
            }
            let label = if arena.has_children(child) {
                3
            } else if sensor.is_occupied(arena.value(child)) {
                2
            } else {
                1
            };
            labels |= label << (2 * i);
            child += 1;
        }
        out.extend_from_slice(&labels.to_le_bytes());
        for i in (0..mask.count_ones()).rev() {
            if arena.has_children(first + i) {
                stack.push(first + i);
            }
        }
        if out.len() >= (1 << 16) - 4 {
            w.write_all(&out)?;
            out.clear();
        }
    }
    w.write_all(&out)
}
