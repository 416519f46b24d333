//! The optional search-blocks section (kind 9, `formats/olm.md`): a large
//! plain map's depth-13 subtrees as runs of bytes (the layout of
//! [`crate::tree::blocks`]) with a palette of the voxel values, so that a
//! full-depth search's last four steps read one or two cache lines instead
//! of missing in four levels of the masks, rank and values sections.
//!
//! Section layout, little-endian: `u32 first` (the breadth-first index of
//! the first depth-13 node), `u32 count` (depth-13 nodes), `u32 palette`
//! (distinct voxel values, at most 256), `u32 runs` (bytes of the runs, their
//! eight zero bytes included); then the palette (`f32` each), a `u32`
//! offset per depth-13 node (where its run starts in the runs), the runs,
//! and zero bytes up to a multiple of 8.

use super::format::u32_at;
use super::nav::RankNav;
use super::OlmError;
use crate::tree::blocks::{self, BlockEnd, Runs, SubtreeRuns, PADDING};

const FIELDS: usize = 16;

/// Nodes at depths 13–15 from which `SearchBlocksSection::Auto` writes the
/// section. Lower than the in-memory index's threshold: the rank layout's
/// levels take more cache than the index's words, and a view shares the
/// caches with other work, which evicts its last levels between queries
/// (measured in `docs/benchmarks.md`, "Memory-mapped maps"). Of the bench
/// maps, indoor 0.05 m (0.19M such nodes) and the outdoor ones get the
/// section; indoor 0.1 m (31k) stays without.
pub(crate) const AUTO_MIN_NODES: usize = 1 << 17;

/// The section's parts, over the file's bytes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SearchBlocks<'a> {
    first: u32,
    count: u32,
    palette: &'a [u8],
    offsets: &'a [u8],
    runs: &'a [u8],
    /// The zero bytes after the runs.
    tail: &'a [u8],
}

/// What a search below a depth-13 node found.
pub(crate) enum Below {
    Value(f32),
    Unknown,
    /// A leaf above depth 16, or bytes that give no answer: the layout's
    /// own descent answers.
    Descend,
}

impl<'a> SearchBlocks<'a> {
    /// The section's parts after O(1) checks against the node count.
    pub fn parse(section: &'a [u8], nodes: u64) -> Result<Self, String> {
        let field = |i: usize| {
            u32_at(section, 4 * i).ok_or_else(|| format!("{} bytes, shorter than its fields", section.len()))
        };
        let (first, count, palette, runs) = (field(0)?, field(1)?, field(2)? as usize, field(3)? as usize);
        if palette > 256 {
            return Err(format!("palette of {palette} values (at most 256)"));
        }
        if u64::from(first) + u64::from(count) > nodes {
            return Err(format!(
                "depth-13 nodes {first}..{} past the {nodes} nodes",
                u64::from(first) + u64::from(count)
            ));
        }
        let at_offsets = FIELDS + 4 * palette;
        let at_runs = at_offsets + 4 * count as usize;
        let end = at_runs + runs;
        if runs < PADDING || end.next_multiple_of(8) != section.len() {
            return Err(format!("{} bytes, its fields give {end} (runs of {runs} bytes)", section.len()));
        }
        Ok(SearchBlocks {
            first,
            count,
            palette: &section[FIELDS..at_offsets],
            offsets: &section[at_offsets..at_runs],
            runs: &section[at_runs..end],
            tail: &section[end..],
        })
    }

    /// The rest of a full-depth search for the Morton `code` below node
    /// `index`, a depth-13 node with children.
    #[inline(always)]
    pub fn below(&self, index: u32, code: u64) -> Below {
        // (no closures: one of them was compiled as an out-of-line call)
        let j = index.wrapping_sub(self.first);
        let at = if j < self.count { u32_at(self.offsets, 4 * j as usize) } else { None };
        let found = match at {
            Some(at) => blocks::walk(self.runs, at as usize, code),
            None => None,
        };
        match found {
            Some(BlockEnd::Voxel(c)) => match u32_at(self.palette, 4 * usize::from(c)) {
                Some(bits) => Below::Value(f32::from_bits(bits)),
                None => Below::Descend,
            },
            Some(BlockEnd::Unknown) => Below::Unknown,
            Some(BlockEnd::Coarse) | None => Below::Descend,
        }
    }

    /// Checks the section against the masks and values it repeats: the
    /// depth-13 nodes, every run, and a palette entry for each voxel value.
    pub fn verify(&self, nav: RankNav<'_>, level_starts: [u32; 4]) -> Result<(), OlmError> {
        let bad = |reason: String| OlmError::Section { kind: super::SectionKind::SearchBlocks as u16, reason };
        let [s13, s14, s15, s16] = level_starts.map(|s| s as usize);
        if (self.first as usize, self.count as usize) != (s13, s14.saturating_sub(s13)) {
            return Err(bad(format!(
                "holds depth-13 nodes {}..{}, the masks put them at {s13}..{s14}",
                self.first,
                self.first + self.count
            )));
        }
        let mut palette = std::collections::HashMap::new();
        for (code, b) in self.palette.chunks_exact(4).enumerate() {
            if palette.insert(u32::from_le_bytes(b.try_into().expect("four bytes")), code as u8).is_some() {
                return Err(bad(format!("palette entry {code} repeats a value")));
            }
        }
        let n = nav.n as usize;
        let mut codes = Vec::with_capacity(n.saturating_sub(s16));
        for i in s16..n {
            let bits = u32_at(nav.values, 4 * i).ok_or_else(|| bad("values section too short".into()))?;
            let code = palette
                .get(&bits)
                .ok_or_else(|| bad(format!("voxel {i}'s value {} is not in the palette", f32::from_bits(bits))))?;
            codes.push(*code);
        }
        let masks = |a: usize, b: usize| nav.masks.get(a..b).ok_or_else(|| bad("masks section too short".into()));
        let want = Runs::build([masks(s13, s14)?, masks(s14, s15)?, masks(s15, s16)?], &codes);
        let stored: Vec<u32> =
            self.offsets.chunks_exact(4).map(|b| u32::from_le_bytes(b.try_into().expect("four bytes"))).collect();
        if stored != want.offsets || self.runs != want.bytes.as_slice() {
            return Err(bad("runs differ from the masks and values".into()));
        }
        if self.tail.iter().any(|&b| b != 0) {
            return Err(bad("padding bytes are not zero".into()));
        }
        Ok(())
    }
}

/// The section's bytes for a tree's runs.
pub(crate) fn encode(r: &SubtreeRuns) -> Vec<u8> {
    let (offsets, runs) = (&r.runs.offsets, &r.runs.bytes);
    let mut b = Vec::with_capacity(FIELDS + 4 * r.values.len() + 4 * offsets.len() + runs.len() + 8);
    for v in [r.first, offsets.len() as u32, r.values.len() as u32, runs.len() as u32] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend(r.values.iter().flat_map(|v| v.to_le_bytes()));
    b.extend(offsets.iter().flat_map(|o| o.to_le_bytes()));
    b.extend_from_slice(runs);
    b.resize(b.len().next_multiple_of(8), 0);
    b
}
