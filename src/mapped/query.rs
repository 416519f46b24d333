//! Queries answered in place: OctoMap's `search`, depth-first iteration
//! (`tree_iterator`, `leaf_iterator`, `leaf_bbx_iterator`) and `castRay`,
//! each with exactly the in-memory tree's semantics.
//!
//! `search` is bounded by 16 levels. Iterators stop after as many nodes as
//! the header announces (a verified file never reaches that bound; a
//! corrupted one whose child indices alias cannot make them run longer).

use super::nav::{Extras, Nav, Node, RankNav};
use super::search_blocks::{Below, SearchBlocks};
use crate::geometry::Point3;
use crate::key::packed;
use crate::key::{adjust_key_to_depth, Key, KeySpace, TREE_DEPTH};
use crate::morton::MortonCode;
use crate::ray::{CastError, CastOptions, CastOutcome};
use crate::sensor::SensorModel;
use crate::tree::blocks::BLOCK_DEPTH;
use crate::tree::{Found, KeyBox, NodeItem, OccupancyTree, PathNodes, Trunks};

/// What ray casting needs from a map: OctoMap's `search` and its key space.
/// Implemented by [`OccupancyTree`] and by the mapped views, so that one
/// [`cast_ray`] serves both (`ray.rs` could share it too).
pub trait OccupancyLookup {
    /// The key space of the map's resolution (point to key conversions).
    fn key_space(&self) -> &KeySpace;
    /// The sensor model whose occupancy threshold classifies the values.
    fn sensor(&self) -> &SensorModel;
    /// OctoMap's `search(key, depth)`; depth 0 means 16.
    fn search(&self, key: Key, depth: u8) -> Option<Found>;
    /// False for a counting map: its values are not log-odds, so ray
    /// casting refuses it rather than answer from them.
    fn has_occupancy(&self) -> bool {
        true
    }
}

impl OccupancyLookup for OccupancyTree {
    fn key_space(&self) -> &KeySpace {
        OccupancyTree::key_space(self)
    }

    fn sensor(&self) -> &SensorModel {
        OccupancyTree::sensor(self)
    }

    #[inline]
    fn search(&self, key: Key, depth: u8) -> Option<Found> {
        OccupancyTree::search(self, key, depth)
    }
}

#[inline(always)]
pub(crate) fn normalize_depth(depth: u8) -> u8 {
    if depth == 0 || depth > TREE_DEPTH {
        TREE_DEPTH
    } else {
        depth
    }
}

/// A search's depth (0 or above 16 means 16), its key's Morton code at
/// that depth (a coarse node's centre key, as `search` takes it).
#[inline(always)]
pub(crate) fn search_target(key: Key, depth: u8) -> (u64, u8) {
    let (key, depth) = crate::tree::search_target(key, depth);
    (MortonCode::encode_table(key).0, depth)
}

/// `search` on any layout (mirrors `OccupancyTree::search`) for a
/// [`search_target`], with the node found (its `extra` is left 0), from
/// `start` (a node on the key's path and its depth, at most `depth`).
#[inline(always)]
pub(crate) fn search_from<N: Nav>(nav: N, code: u64, depth: u8, start: (Node, u8)) -> Option<(Found, Node)> {
    let (node, depth, mask) = nav.descend(start.0, start.1, depth, code)?;
    Some((Found { value: nav.get(node)?.0, depth, is_leaf: mask == 0, extra: 0 }, node))
}

/// `search` on any layout from the trunk end above the key (see
/// [`Trunks`]), the node's colour or stamp filled in.
#[inline(always)]
pub(crate) fn search<N: Nav>(
    nav: N,
    extras: Extras<'_>,
    trunks: &Trunks<Node>,
    (key, octant): (Key, usize),
    depth: u8,
) -> Option<Found> {
    let (code, depth) = search_target(key, depth);
    search_from(nav, code, depth, trunk_start(nav, trunks, (key, octant), depth))
        .map(|(f, n)| Found { extra: extras.get(n), ..f })
}

/// A full-depth [`search`] of a plain map with a search-blocks section:
/// the rank layout's descent to depth 13, then the node's run.
#[inline(always)]
pub(crate) fn search_through_blocks(
    nav: RankNav<'_>,
    blocks: &SearchBlocks<'_>,
    trunks: &Trunks<Node>,
    (key, octant): (Key, usize),
) -> Option<Found> {
    let (code, depth) = search_target(key, TREE_DEPTH);
    let start = trunk_start(nav, trunks, (key, octant), BLOCK_DEPTH);
    let (node, d, mask) = nav.descend(start.0, start.1, BLOCK_DEPTH, code)?;
    if d == BLOCK_DEPTH && mask != 0 {
        match blocks.below(node.idx, code) {
            Below::Value(value) => return Some(Found { value, depth, is_leaf: true, extra: 0 }),
            Below::Unknown => return None,
            Below::Descend => return search_from(nav, code, depth, (node, d)).map(|(f, _)| f),
        }
    }
    Some(Found { value: nav.get(node)?.0, depth: d, is_leaf: mask == 0, extra: 0 })
}

/// Where a search for `key` (with its root child, see
/// [`crate::KeySpace::key_and_octant`]) at `depth` starts; see
/// [`Trunks::start_in`].
#[inline(always)]
pub(crate) fn trunk_start<N: Nav>(nav: N, trunks: &Trunks<Node>, (key, octant): (Key, usize), depth: u8) -> (Node, u8) {
    trunks.start_in(key.packed(), octant, depth, |n| nav.mask(n), |n, m, pos| nav.child(n, m, pos))
}

/// Grid cells a view may always have, whatever its size: 256 KB of heap,
/// four grid levels below up to eight trunks.
const VIEW_GRID_CELLS: usize = 1 << 15;

/// The trunks of a mapped tree; `None` when it has no root.
pub(crate) fn trunks<N: Nav>(nav: N) -> Option<Trunks<Node>> {
    let cells = usize::try_from(nav.node_budget() / crate::tree::GRID_NODES_PER_CELL).unwrap_or(usize::MAX);
    let cells = cells.max(VIEW_GRID_CELLS);
    nav.root().map(|r| Trunks::build(r, cells, |n| nav.mask(n), |n, m, pos| nav.child(n, m, pos)))
}

/// [`search`] for many keys, eight descents in lockstep so that their
/// cache misses overlap (as `OccupancyTree::search_many`).
pub(crate) fn search_many<N: Nav>(
    nav: N,
    extras: Extras<'_>,
    trunks: &Trunks<Node>,
    keys: &[Key],
    depth: u8,
    out: &mut Vec<Option<Found>>,
) {
    const LANES: usize = 8;
    out.clear();
    let depth = normalize_depth(depth);
    let Some(root) = nav.root().and_then(|r| Some((r, nav.mask(r)?))) else {
        out.resize(keys.len(), None);
        return;
    };
    for chunk in keys.chunks(LANES) {
        let mut key = [Key::ROOT; LANES];
        for (k, c) in key.iter_mut().zip(chunk) {
            *k = if depth == TREE_DEPTH { *c } else { adjust_key_to_depth(*c, depth) };
        }
        // each lane starts at its trunk end and joins the walk at its depth
        // (as `OccupancyTree::search_many`)
        let mut at = [root; LANES];
        let mut joins = [0u32; TREE_DEPTH as usize + 1];
        // lanes that end on a node, at the depth where they end
        let mut ends = [depth; LANES];
        let mut ended = (1u32 << chunk.len()) - 1;
        for l in 0..chunk.len() {
            let (node, from) = trunk_start(nav, trunks, (key[l], key[l].child_index(0)), depth);
            match nav.mask(node) {
                Some(mask) => {
                    at[l] = (node, mask);
                    joins[from as usize] |= 1 << l;
                }
                None => ended &= !(1 << l),
            }
        }
        let mut walking = 0u32;
        let mut waiting = ended & !joins[depth as usize];
        for d in 0..depth {
            walking |= joins[d as usize];
            waiting &= !joins[d as usize];
            let mut lanes = walking;
            while lanes != 0 {
                let l = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                let (node, mask) = at[l];
                let pos = key[l].child_index(d);
                if mask & (1 << pos) != 0 {
                    // a corrupted file may end the walk: no answer, as `search`
                    match nav.child(node, mask, pos).and_then(|c| Some((c, nav.mask(c)?))) {
                        Some(next) => at[l] = next,
                        None => {
                            walking &= !(1 << l);
                            ended &= !(1 << l);
                        }
                    }
                } else {
                    walking &= !(1 << l);
                    ends[l] = d;
                    if mask != 0 {
                        ended &= !(1 << l);
                    }
                }
            }
            if walking | waiting == 0 {
                break;
            }
        }
        let mut found = [None; LANES];
        while ended != 0 {
            let l = ended.trailing_zeros() as usize;
            ended &= ended - 1;
            let (node, mask) = at[l];
            found[l] = nav.get(node).map(|(value, _)| Found {
                value,
                depth: ends[l],
                is_leaf: mask == 0,
                extra: extras.get(node),
            });
        }
        out.extend_from_slice(&found[..chunk.len()]);
    }
}

/// Depth-first iteration over one layout: one frame per open level, with
/// the node's children (as the layout finds them) and the packed key of
/// child 0 (see [`crate::key::packed`]).
pub(crate) struct RawIter<'a, N: Nav> {
    nav: N,
    extras: Extras<'a>,
    keys: &'a KeySpace,
    frames: [Frame<N::Group>; TREE_DEPTH as usize],
    len: usize,
    root_pending: bool,
    max_depth: u8,
    leaves_only: bool,
    bbx: Option<KeyBox>,
    budget: u64,
    /// Per depth: where the next node's children start (see `Nav::children_seq`).
    seq: [(u32, u32); TREE_DEPTH as usize + 1],
}

#[derive(Clone, Copy, Default)]
struct Frame<G> {
    child0: u64,
    children: G,
    next: u8,
    remaining: u8,
}

impl<'a, N: Nav> RawIter<'a, N> {
    pub fn new(
        nav: N,
        extras: Extras<'a>,
        keys: &'a KeySpace,
        max_depth: u8,
        leaves_only: bool,
        bbx: Option<KeyBox>,
    ) -> Self {
        RawIter {
            budget: nav.node_budget(),
            root_pending: nav.root().is_some(),
            nav,
            extras,
            keys,
            frames: [Frame::default(); TREE_DEPTH as usize],
            len: 0,
            max_depth: normalize_depth(max_depth),
            leaves_only,
            bbx,
            seq: [(0, 0); TREE_DEPTH as usize + 1],
        }
    }

    /// Reports node `n` (at `key`, `depth`) and opens a frame for its
    /// children when it is to be descended; `None` when it is not reported
    /// (an inner node of a leaf iteration, or unreadable bytes).
    #[inline(always)]
    fn visit(&mut self, n: Node, packed: u64, depth: u8) -> Option<NodeItem<'a>> {
        if self.budget == 0 {
            self.len = 0;
            return None;
        }
        self.budget -= 1;
        let (value, mask) = self.nav.get(n)?;
        let is_leaf = mask == 0 || depth >= self.max_depth;
        if mask == 0 && depth < self.max_depth {
            self.nav.skip_seq(n, &mut self.seq[depth as usize]);
        }
        if !is_leaf {
            // a layout that cannot give all the children (corrupted bytes)
            // leaves the node without descendants
            if let Some(children) = self.nav.group_seq(n, mask, &mut self.seq[depth as usize]) {
                let child0 = packed::child0(packed, depth);
                self.frames[depth as usize] = Frame { child0, children, next: 0, remaining: mask };
                self.len = depth as usize + 1;
            }
            if self.leaves_only {
                return None;
            }
        }
        let key = packed::unpack(packed);
        Some(NodeItem::new(key, depth, value, self.extras.get(n), is_leaf, self.keys))
    }

    #[inline]
    pub fn next_item(&mut self) -> Option<NodeItem<'a>> {
        self.advance(false)
    }

    /// `fold` over the rest of a walk. Where a depth-15 node's voxels come
    /// next in a walk of all leaves, they are taken in one loop here: the
    /// same steps as [`Self::next_item`]'s without its frame handling and
    /// tests.
    pub fn fold<B>(mut self, mut acc: B, f: &mut impl FnMut(B, NodeItem<'a>) -> B) -> B {
        let voxels = self.leaves_only && self.bbx.is_none() && self.max_depth == TREE_DEPTH;
        loop {
            if voxels && self.len == TREE_DEPTH as usize {
                let fr = self.frames[TREE_DEPTH as usize - 1];
                let mut remaining = fr.remaining;
                let mut next = fr.next;
                while remaining != 0 {
                    if self.budget == 0 {
                        self.len = 0;
                        return acc;
                    }
                    self.budget -= 1;
                    let pos = remaining.trailing_zeros() as usize;
                    remaining &= remaining - 1;
                    let n = self.nav.member(&fr.children, usize::from(next));
                    next += 1;
                    // a voxel's mask is 0 (else the bytes are corrupted, and
                    // `visit` reports it as a leaf all the same)
                    if let Some((value, _)) = self.nav.get(n) {
                        let key = packed::unpack(packed::child(fr.child0, pos, TREE_DEPTH - 1));
                        let item = NodeItem::new(key, TREE_DEPTH, value, self.extras.get(n), true, self.keys);
                        acc = f(acc, item);
                    }
                }
                self.len -= 1;
            }
            match self.advance(voxels) {
                Some(item) => acc = f(acc, item),
                None if voxels && self.len == TREE_DEPTH as usize => {}
                None => return acc,
            }
        }
    }

    /// [`Self::next_item`]; with `stop_at_voxels`, returns `None` also when
    /// the next frame holds a depth-15 node's voxels (`len` is then 16).
    #[inline(always)]
    fn advance(&mut self, stop_at_voxels: bool) -> Option<NodeItem<'a>> {
        if self.root_pending {
            self.root_pending = false;
            let root = self.nav.root()?;
            if let Some(item) = self.visit(root, packed::pack(Key::ROOT), 0) {
                return Some(item);
            }
        }
        while self.len > 0 {
            if stop_at_voxels && self.len == TREE_DEPTH as usize {
                return None;
            }
            let depth = self.len - 1;
            let f = &mut self.frames[depth];
            if f.remaining == 0 {
                self.len -= 1;
                continue;
            }
            let pos = f.remaining.trailing_zeros() as usize;
            f.remaining &= f.remaining - 1;
            let n = self.nav.member(&f.children, usize::from(f.next));
            f.next += 1;
            let child = packed::child(f.child0, pos, depth as u8);
            let depth = depth as u8 + 1;
            if self.bbx.is_some_and(|b| !b.overlaps(packed::unpack(child), depth)) {
                continue;
            }
            if let Some(item) = self.visit(n, child, depth) {
                return Some(item);
            }
        }
        None
    }
}

/// OctoMap's `castRay` on any map (bit-identical to
/// `OccupancyTree::cast_ray`): follows the ray from `origin` until an
/// occupied voxel, unknown space (unless ignored), the maximum range or
/// the edge of the map.
pub fn cast_ray<M: OccupancyLookup + ?Sized>(
    map: &M,
    origin: Point3,
    direction: Point3,
    opts: CastOptions,
) -> Result<CastOutcome, CastError> {
    if !map.has_occupancy() {
        return Err(CastError::NoOccupancy);
    }
    let search = |code| map.search(MortonCode(code).decode(), 0);
    crate::ray::cast_ray_with(map.key_space(), map.sensor(), search, origin, direction, opts)
}

/// A mapped layout's nodes for a [`PathSearch`] (`castRay`): the path
/// keeps each node with its value and mask, read together.
#[derive(Clone, Copy)]
pub(crate) struct MappedPath<N: Nav>(pub N);

impl<N: Nav> PathNodes for MappedPath<N> {
    type Entry = (Node, f32, u8);

    fn root(&self) -> Option<Self::Entry> {
        let r = self.0.root()?;
        let (value, mask) = self.0.get(r)?;
        Some((r, value, mask))
    }

    #[inline(always)]
    fn child(&self, (node, _, mask): Self::Entry, pos: usize) -> Option<Result<Self::Entry, u8>> {
        if mask & (1 << pos) == 0 {
            return Some(Err(mask));
        }
        let c = self.0.child(node, mask, pos)?;
        let (value, mask) = self.0.get(c)?;
        Some(Ok((c, value, mask)))
    }

    #[inline(always)]
    fn found(&self, (_, value, mask): Self::Entry, depth: u8) -> Found {
        Found { value, depth, is_leaf: mask == 0, extra: 0 }
    }
}
