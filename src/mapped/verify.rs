//! Full verification: checksums, padding, the rank directory or child
//! pointers, and the tree structure (every node but the root has exactly
//! one parent before it, depth at most 16, counts as announced). A file
//! that passes describes exactly one tree, and every query on it answers
//! as that tree does.

use super::format::{u16_at, u32_at, u64_at, Index, Meta, SectionKind, TreeKind, Variant, HEADER_LEN};
use super::nav::{count_inner, label_mask, AnyNav, MlNav, RankNav};
use super::search_blocks::SearchBlocks;
use super::OlmError;
use crate::key::TREE_DEPTH;

/// What [`super::MapView::verify`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VerifyReport {
    /// Nodes in the tree.
    pub nodes: u64,
    /// Nodes with children.
    pub inner_nodes: u64,
    /// Nodes without children (`nodes - inner_nodes`).
    pub leaves: u64,
    /// Depth of the deepest node (0 for a lone root or an empty tree).
    pub max_depth: u8,
    /// Bytes covered by checksums (header and sections).
    pub checked_bytes: u64,
}

fn structure(msg: impl Into<String>) -> OlmError {
    OlmError::Structure(msg.into())
}

pub(crate) fn verify(data: &[u8], meta: &Meta) -> Result<VerifyReport, OlmError> {
    let h = &meta.header;
    let mut checked = HEADER_LEN as u64;
    for s in &h.sections {
        let bytes = data
            .get(s.offset as usize..(s.offset + s.length) as usize)
            .ok_or_else(|| OlmError::Section { kind: s.kind, reason: "out of bounds".into() })?;
        let computed = crc32fast::hash(bytes);
        if computed != s.crc32 {
            return Err(OlmError::SectionChecksum { kind: s.kind, stored: s.crc32, computed });
        }
        checked += s.length;
    }
    if h.kind == TreeKind::ColorOcTree && h.variant == Variant::Full {
        let colors = data.get(meta.ranges.colors.clone()).unwrap_or(&[]);
        padding_is_zero(colors, (3 * h.node_count) as usize, SectionKind::Colors)?;
    }
    let mut report = match AnyNav::new(data, meta) {
        AnyNav::Rank(nav) => verify_rank(data, nav, meta)?,
        AnyNav::Ptr(_) => verify_pointers(data, meta)?,
        AnyNav::Ml(nav) => verify_ml(nav, meta)?,
    };
    report.checked_bytes = checked;
    Ok(report)
}

fn padding_is_zero(bytes: &[u8], from: usize, kind: SectionKind) -> Result<(), OlmError> {
    match bytes.get(from..) {
        Some(tail) if tail.iter().any(|&b| b != 0) => {
            Err(OlmError::Section { kind: kind as u16, reason: "padding bytes are not zero".into() })
        }
        _ => Ok(()),
    }
}

/// Checks a rank directory against a running count: `counts(i)` is the
/// number of children of record `i`, `nonzero(i)` whether it has any.
/// Returns (total children, records with children).
fn check_prefix(
    records: u64,
    log2: u8,
    dir: &[u8],
    mut record: impl FnMut(usize) -> Option<(u32, bool)>,
) -> Result<(u64, u64), OlmError> {
    let block = 1u64 << log2;
    let mut before = 0u64;
    let mut nonzero = 0u64;
    for i in 0..=records {
        if i % block == 0 {
            let stored = u32_at(dir, 4 * (i >> log2) as usize).ok_or_else(|| structure("rank directory too short"))?;
            if u64::from(stored) != before {
                return Err(structure(format!(
                    "rank directory entry {} says {stored}, the records give {before}",
                    i >> log2
                )));
            }
        }
        if i == records {
            break;
        }
        if i >= 1 && before < i {
            return Err(structure(format!("record {i} has no parent before it (only {before} children announced)")));
        }
        let (count, has) = record(i as usize).ok_or_else(|| structure(format!("record {i} is missing")))?;
        before += u64::from(count);
        nonzero += u64::from(has);
    }
    if records > 0 && before != records - 1 {
        return Err(structure(format!("{records} records announce {before} children, not {}", records - 1)));
    }
    Ok((before, nonzero))
}

/// Level ends: `end[0] = 1`, `end[d+1] = 1 + rank(end[d])`; returns the
/// deepest non-empty level and the end after `levels` levels.
fn levels(records: u32, levels: u8, rank: impl Fn(u32) -> Option<u32>) -> (u8, u32) {
    let mut end = 1u32.min(records);
    let mut deepest = 0u8;
    for d in 1..=levels {
        if end >= records {
            break;
        }
        let next = rank(end).map_or(records, |r| r.saturating_add(1));
        if next > end {
            deepest = d;
        }
        end = next;
    }
    (deepest, end)
}

fn verify_rank(data: &[u8], nav: RankNav<'_>, meta: &Meta) -> Result<VerifyReport, OlmError> {
    let h = &meta.header;
    let n = h.node_count;
    padding_is_zero(nav.masks, n as usize, SectionKind::Masks)?;
    let (_, inner) = check_prefix(n, h.rank_block_log2, nav.dir, |i| {
        let m = *nav.masks.get(i)?;
        Some((crate::arch::count_ones(m), m != 0))
    })?;
    if inner != h.inner_count {
        return Err(structure(format!("{inner} nodes have children, the header says {}", h.inner_count)));
    }
    // all nodes within depths 0..=16
    let (deepest, end) = levels(nav.n, TREE_DEPTH, |i| nav.rank(i));
    if u64::from(end) != n {
        return Err(structure(format!("nodes {end}..{n} lie below depth {TREE_DEPTH}")));
    }
    if let Some(blocks) = data.get(meta.ranges.search_blocks.clone()).filter(|b| !b.is_empty()) {
        let blocks = SearchBlocks::parse(blocks, n)
            .map_err(|reason| OlmError::Section { kind: SectionKind::SearchBlocks as u16, reason })?;
        // where depths 13 to 16 start
        let starts = [12, 13, 14, 15].map(|d| levels(nav.n, d, |i| nav.rank(i)).1);
        blocks.verify(nav, starts)?;
    }
    Ok(VerifyReport { nodes: n, inner_nodes: inner, leaves: n - inner, max_depth: deepest, checked_bytes: 0 })
}

fn verify_ml(nav: MlNav<'_>, meta: &Meta) -> Result<VerifyReport, OlmError> {
    let h = &meta.header;
    let records = h.inner_count;
    padding_is_zero(nav.labels, 2 * records as usize, SectionKind::Labels)?;
    // occupancy bits past the last record
    if !records.is_multiple_of(64) {
        let last = u64_at(nav.occupancy, 8 * (records / 64) as usize).unwrap_or(0);
        if last >> (records % 64) != 0 {
            return Err(OlmError::Section {
                kind: SectionKind::InnerOccupancy as u16,
                reason: "bits past the last inner node are not zero".into(),
            });
        }
    }
    let mut labelled = 0u64;
    let mut empty_record = None;
    let (_, _) = check_prefix(records, h.rank_block_log2, nav.dir, |j| {
        let w = u16_at(nav.labels, 2 * j)?;
        if w == 0 && empty_record.is_none() {
            empty_record = Some(j);
        }
        labelled += u64::from(crate::arch::count_ones(label_mask(w)));
        Some((count_inner(u64::from(w)), true))
    })?;
    if let Some(j) = empty_record {
        return Err(structure(format!("inner node record {j} has no children")));
    }
    let nodes = if h.root_label == 0 { 0 } else { 1 + labelled };
    if nodes != h.node_count {
        return Err(structure(format!("the labels hold {nodes} nodes, the header says {}", h.node_count)));
    }
    // inner nodes lie at depths 0..=15 (a depth-16 voxel has no children)
    let (deepest_inner, end) = levels(nav.inner, TREE_DEPTH - 1, |j| nav.rank(j));
    if u64::from(end) != records {
        return Err(structure(format!("inner nodes {end}..{records} lie at depth 16 or below")));
    }
    let max_depth = if records == 0 { 0 } else { deepest_inner + 1 };
    Ok(VerifyReport { nodes, inner_nodes: records, leaves: nodes - records, max_depth, checked_bytes: 0 })
}

/// Depth-first group order: walking the tree depth first, each inner
/// node's children group must start exactly where the previous group ended.
fn verify_pointers(data: &[u8], meta: &Meta) -> Result<VerifyReport, OlmError> {
    let h = &meta.header;
    debug_assert!(h.variant == Variant::Full && h.index == Index::Pointers);
    let r = &meta.ranges;
    let masks = data.get(r.masks.clone()).unwrap_or(&[]);
    let first = data.get(r.first_child.clone()).unwrap_or(&[]);
    let n = h.node_count;
    padding_is_zero(masks, n as usize, SectionKind::Masks)?;
    if n == 0 {
        return Ok(VerifyReport::default());
    }
    let mut next = 1u64;
    let mut inner = 0u64;
    let mut deepest = 0u8;
    let mut stack: Vec<(u64, u8)> = vec![(0, 0)];
    while let Some((i, depth)) = stack.pop() {
        let m = *masks.get(i as usize).ok_or_else(|| structure(format!("node {i} out of range")))?;
        let fc = u64::from(u32_at(first, 4 * i as usize).unwrap_or(0));
        deepest = deepest.max(depth);
        if m == 0 {
            if fc != 0 {
                return Err(structure(format!("leaf {i} has first-child index {fc}, not 0")));
            }
            continue;
        }
        inner += 1;
        if depth >= TREE_DEPTH {
            return Err(structure(format!("node {i} has children at depth 16")));
        }
        if fc != next {
            return Err(structure(format!("node {i}'s children start at {fc}, expected {next}")));
        }
        let k = u64::from(crate::arch::count_ones(m));
        if next + k > n {
            return Err(structure(format!("node {i}'s children run past the {n} nodes")));
        }
        next += k;
        for c in (fc..fc + k).rev() {
            stack.push((c, depth + 1));
        }
    }
    if next != n {
        return Err(structure(format!("{} of the {n} nodes are not reachable from the root", n - next)));
    }
    if inner != h.inner_count {
        return Err(structure(format!("{inner} nodes have children, the header says {}", h.inner_count)));
    }
    Ok(VerifyReport { nodes: n, inner_nodes: inner, leaves: n - inner, max_depth: deepest, checked_bytes: 0 })
}
