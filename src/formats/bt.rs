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
use crate::tree::{default_extra, LabelFill, NodeKind, OccupancyTree};
use crate::tree::{in_leaf_pool, NodeId, Parts};
use std::io::{self, BufRead, Write};
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
    if !(res > 0.0 && res.is_finite()) {
        return Err(TreeFileError::BadResolution { value: res, offset: Some(r.offset - 8) });
    }
    r.read_exact(&mut b4, "the legacy size")?;
    Ok((u64::from(u32::from_le_bytes(b4)), res))
}

/// Writes what OctoMap's `writeBinary` writes: the tree converted to
/// maximum likelihood and pruned. The caller's tree is left unchanged.
pub fn write(tree: &OccupancyTree, mut w: impl Write) -> io::Result<()> {
    let id = super::ot::TreeKind::of(tree.kind()).id();
    let mut out = Vec::new();
    let size = write_ml_data(tree, &mut out);
    write_header(&mut w, BT_FIRST_LINE, id, size, tree.resolution())?;
    w.write_all(&out)
}

/// Appends to `out` the node stream `toMaxLikelihood()` then `prune()`
/// would leave, without copying or changing the tree; returns the node
/// count (`size()`) that tree would have.
///
/// `prune` merges level by level from depth 15 up and stops after the
/// first level that merged nothing. One read-only pass writes the records
/// as if pruning went all the way up, dropping the subtrees that merge, and
/// counts the merges per depth. That is the answer unless a level above
/// the one where `prune` stops would merge something; then a second pass
/// writes the records with merges below that level only.
pub(crate) fn write_ml_data(tree: &OccupancyTree, out: &mut Vec<u8>) -> usize {
    let Some(arena) = tree.arena() else {
        return tree.size();
    };
    let ml = MlView::new(arena.parts(), tree.sensor());
    let stamped = tree.kind() == NodeKind::Stamped;
    let emit = |lowest: usize, out: &mut Vec<u8>, counts: &mut [usize; 16]| {
        if stamped {
            ml.emit::<true>(0, 0, lowest, out, counts);
        } else {
            ml.emit::<false>(0, 0, lowest, out, counts);
        }
    };
    out.reserve(2 * (arena.parts().masks.len() / 8 + 1));
    let start = out.len();
    let mut counts = [0usize; 16];
    emit(1, out, &mut counts);
    // as `OccupancyTree::prune`: the deepest level that merges nothing
    // stops it; only the levels below that one merge
    let stop = (1..16).rev().find(|&d| counts[d] == 0).unwrap_or(0);
    let lowest = stop.max(1);
    if counts[1..lowest].iter().any(|&c| c > 0) {
        out.truncate(start);
        emit(lowest, out, &mut [0; 16]);
    }
    tree.size() - 8 * counts[lowest..].iter().sum::<usize>()
}

/// The tree as `toMaxLikelihood()` would leave it, read in place.
///
/// Maximum likelihood leaves a node one of two values: the upper clamping
/// bound when it is occupied (class 1), else the lower (class 0). What
/// `prune` and `writeBinaryConst` then compare and test depends on the
/// class alone, so they are precomputed per class: the `.bt` label, and
/// whether the values of two classes compare equal (they may not, even
/// within a class, when a bound is NaN; they do across classes when the
/// bounds are equal).
struct MlView<'a> {
    arena: Parts<'a>,
    threshold: f32,
    /// The label of a leaf of each class: 2 when its value is occupied, else 1.
    label: [u16; 2],
    /// `equal[a][b]`: whether values of classes `a` and `b` compare equal.
    equal: [[bool; 2]; 2],
}

impl<'a> MlView<'a> {
    fn new(arena: Parts<'a>, s: &SensorModel) -> Self {
        let value = [s.clamping_min, s.clamping_max];
        let label = value.map(|v| if s.is_occupied(v) { 2 } else { 1 });
        let equal = [0, 1].map(|a| [0, 1].map(|b| value[a] == value[b]));
        MlView { arena, threshold: s.occupancy_threshold, label, equal }
    }

    /// Appends the record of inner node `n` at `depth` and those of its
    /// subtree, merging the nodes at depth `lowest` or deeper that merge
    /// once every level below them is pruned, and counts those per depth.
    /// Returns `Some((class, stamp))` when `n` itself merges: the caller
    /// then drops what was appended and labels `n` a leaf of that class.
    fn emit<const STAMPED: bool>(
        &self,
        n: NodeId,
        depth: usize,
        lowest: usize,
        out: &mut Vec<u8>,
        counts: &mut [usize; 16],
    ) -> Option<(u8, u32)> {
        let at = out.len();
        out.extend_from_slice(&[0, 0]);
        let a = self.arena;
        let mask = a.mask(n);
        let first = a.first_child[n as usize];
        let group = first..first + crate::arch::count_ones(mask);
        // ask for the child groups of the inner children now, all at once,
        // rather than one after the other as the recursion reaches them
        if !in_leaf_pool(first) {
            for g in group.clone() {
                if a.masks[g as usize] != 0 {
                    a.prefetch_group(a.first_child[g as usize]);
                }
            }
        }
        let mut labels = 0u16;
        // classes by child position; children that stay inner
        let mut occupied = 0u8;
        let mut inner = 0u8;
        let mut stamps_equal = true;
        let mut stamp0 = 0;
        let mut rest = mask;
        for c in group {
            let pos = rest.trailing_zeros();
            rest &= rest - 1;
            let (class, stamp) = if a.mask(c) == 0 {
                (u8::from(a.value(c) >= self.threshold), if STAMPED { a.extra(c) } else { 0 })
            } else {
                let before = out.len();
                match self.emit::<STAMPED>(c, depth + 1, lowest, out, counts) {
                    Some(leaf) => {
                        out.truncate(before);
                        leaf
                    }
                    None => {
                        inner |= 1 << pos;
                        labels |= 3 << (2 * pos);
                        continue;
                    }
                }
            };
            occupied |= class << pos;
            labels |= self.label[usize::from(class)] << (2 * pos);
            if STAMPED {
                if pos == 0 {
                    stamp0 = stamp;
                } else if stamp != stamp0 {
                    stamps_equal = false;
                }
            }
        }
        out[at..at + 2].copy_from_slice(&labels.to_le_bytes());
        // `pruneNode`: eight leaves whose values (and stamps) all equal
        // child 0's
        if mask != 0xff || inner != 0 || depth < lowest || !stamps_equal {
            return None;
        }
        let class0 = usize::from(occupied & 1);
        let others = occupied >> 1;
        if (others != 0 && !self.equal[1][class0]) || (others != 0x7f && !self.equal[0][class0]) {
            return None;
        }
        counts[depth] += 1;
        Some((class0 as u8, stamp0))
    }
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
    let parts = arena.parts();
    let mut out = Vec::with_capacity(2 * (parts.masks.len() / 8 + 1));
    write_const_node(parts, tree.sensor(), 0, &mut out);
    w.write_all(&out)
}

/// Appends the record of node `n` (which has children) and those of its
/// subtree: children with children are labelled 3, leaves 2 when occupied,
/// else 1.
fn write_const_node(a: Parts<'_>, sensor: &SensorModel, n: NodeId, out: &mut Vec<u8>) {
    let mask = a.mask(n);
    let first = a.first_child[n as usize];
    let group = first..first + crate::arch::count_ones(mask);
    let inner_group = !in_leaf_pool(first);
    // ask for the inner children's groups before the recursion needs them
    if inner_group {
        for c in group.clone() {
            if a.masks[c as usize] != 0 {
                a.prefetch_group(a.first_child[c as usize]);
            }
        }
    }
    let mut labels = 0u16;
    let mut rest = mask;
    for c in group.clone() {
        let pos = rest.trailing_zeros();
        rest &= rest - 1;
        let label = if a.mask(c) != 0 {
            3
        } else if sensor.is_occupied(a.value(c)) {
            2
        } else {
            1
        };
        labels |= label << (2 * pos);
    }
    out.extend_from_slice(&labels.to_le_bytes());
    if inner_group {
        for c in group {
            if a.masks[c as usize] != 0 {
                write_const_node(a, sensor, c, out);
            }
        }
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
