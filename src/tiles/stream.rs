//! The single tree of a tiled map or tile set walked in pre-order without
//! being built: the derived levels above the tiles from `top.rs`, and at
//! each tile root that tile's subtree from its own tree, a tile in memory
//! directly, a spilled tile or a tile set's tile read in, walked and
//! dropped before the next. The file writers take such walks
//! ([`PreorderSource`]), so a map larger than memory is written as one
//! `.ot` or `.bt` file, byte for byte the merged tree's; [`TiledMap::merge`]
//! and [`TileSet::merge`] build the tree from the same walk.

use super::error::TileError;
use super::file::{load_tree, open_to_read, root_mask_in_view};
use super::id::TileId;
use super::map::{TileState, TiledMap};
use super::set::TileSet;
use super::top::tile_root_node;
use crate::sensor::SensorModel;
use crate::tree::{ChildGroup, NodeKind, OccupancyTree, PreorderBuilder, PreorderNode, PreorderSource};
use crate::tree::{PreorderVisitor, TooDeep};
use std::io;
use std::ops::ControlFlow;

/// A visitor told of a subtree's nodes at their depths in the whole tree:
/// a tile's walk counts depths from the tile root, `by` below the root.
struct DepthShift<'v, V> {
    visitor: &'v mut V,
    by: u8,
}

impl<V: PreorderVisitor> DepthShift<'_, V> {
    #[inline(always)]
    fn shift(&self, node: &PreorderNode) -> PreorderNode {
        PreorderNode { depth: node.depth + self.by, ..*node }
    }
}

impl<V: PreorderVisitor> PreorderVisitor for DepthShift<'_, V> {
    type Break = V::Break;

    #[inline(always)]
    fn enter(&mut self, node: &PreorderNode, children: &ChildGroup<'_>) -> ControlFlow<V::Break> {
        let node = self.shift(node);
        self.visitor.enter(&node, children)
    }

    #[inline(always)]
    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<V::Break> {
        let node = self.shift(node);
        self.visitor.leaf(&node)
    }

    #[inline(always)]
    fn leave(&mut self, node: &PreorderNode) -> ControlFlow<V::Break> {
        let node = self.shift(node);
        self.visitor.leave(&node)
    }
}

/// Walks tile `id`'s subtree of `tree` (a tree holding that tile alone).
fn visit_tile<V: PreorderVisitor>(
    tree: &OccupancyTree,
    id: TileId,
    visitor: &mut V,
) -> Result<ControlFlow<V::Break>, String> {
    let root = tree.root().ok_or("the tile tree holds no node")?;
    let node = tile_root_node(root, id)?;
    Ok(node.visit_preorder(&mut DepthShift { visitor, by: id.depth() }))
}

/// The child mask of tile `id`'s root in `tree`.
fn tile_mask(tree: &OccupancyTree, id: TileId) -> Result<u8, TileError> {
    let root = tree.root().ok_or(TileError::Internal("a tile tree without nodes"))?;
    let node = tile_root_node(root, id).map_err(|_| TileError::Internal("a tile tree of the wrong shape"))?;
    Ok(node.child_mask())
}

impl TiledMap {
    /// Walks the single tree ([`Self::merge`]'s) in pre-order without
    /// building it: spilled tiles are read back one at a time, walked and
    /// dropped, so memory stays at the budget plus one tile.
    pub fn visit_preorder<V: PreorderVisitor>(&self, visitor: &mut V) -> Result<ControlFlow<V::Break>, TileError> {
        if self.stale {
            return Err(TileError::StaleInnerNodes);
        }
        let tiles: Vec<(TileId, &TileState)> =
            self.tiles.iter().map(|(&p, t)| (TileId::from_prefix(self.depth, p), &t.state)).collect();
        let mask = |i: usize| match tiles[i] {
            (id, TileState::Live { tree, .. }) => tile_mask(tree, id),
            (id, TileState::Spilled(entry)) => Ok(root_mask_in_view(self.budget_ref()?.open(entry)?.view(), id)),
        };
        self.top().visit(visitor, &mask, &mut |i, visitor| {
            let wrong_shape = |_| TileError::Internal("a tile tree of the wrong shape");
            match tiles[i] {
                (id, TileState::Live { tree, .. }) => visit_tile(tree, id, visitor).map_err(wrong_shape),
                (id, TileState::Spilled(entry)) => {
                    let tree = self.budget_ref()?.load(entry)?;
                    let _loaded = loaded::Tile::new();
                    visit_tile(&tree, id, visitor).map_err(wrong_shape)
                }
            }
        })
    }

    /// The single tree: the derived upper levels and every tile's subtree
    /// (spilled tiles are read one at a time). Its bytes in any format are
    /// those of the tree [`OccupancyTree`] builds from the same updates.
    pub fn merge(&self) -> Result<OccupancyTree, TileError> {
        let mut tree = build(self, self.kind, self.stats().nodes, |v| self.visit_preorder(v))?;
        tree.set_clock(self.clock);
        Ok(tree)
    }
}

impl TileSet {
    /// Walks the single tree ([`Self::merge`]'s) in pre-order without
    /// building it: each tile is mapped, checked against the manifest
    /// (length, header and CRC-32, whatever [`Self::set_check`] says),
    /// read, walked and dropped in turn.
    pub fn visit_preorder<V: PreorderVisitor>(&self, visitor: &mut V) -> Result<ControlFlow<V::Break>, TileError> {
        let manifest = self.manifest();
        let damaged = |i: usize, reason| {
            let id = manifest.tiles[i].id;
            TileError::damaged(id, self.dir().join(id.file_name()), reason)
        };
        let mask = |i: usize| {
            let entry = &manifest.tiles[i];
            let map = open_to_read(self.dir(), entry, Some(manifest))?;
            Ok(root_mask_in_view(map.view(), entry.id))
        };
        self.top().visit(visitor, &mask, &mut |i, visitor| {
            let entry = &manifest.tiles[i];
            let map = open_to_read(self.dir(), entry, Some(manifest))?;
            let tree = load_tree(&map, entry).map_err(|reason| damaged(i, reason))?;
            drop(map);
            let _loaded = loaded::Tile::new();
            visit_tile(&tree, entry.id, visitor).map_err(|reason| damaged(i, reason))
        })
    }

    /// The single tree, each tile checked (length, header, CRC-32) and
    /// read in turn.
    pub fn merge(&self) -> Result<OccupancyTree, TileError> {
        build(self, self.manifest().node_kind(), self.node_count(), |v| self.visit_preorder(v))
    }
}

/// The tree a walk gives, node by node.
struct Build<'b> {
    builder: &'b mut PreorderBuilder,
    stamped: bool,
}

impl Build<'_> {
    #[inline(always)]
    fn push(&mut self, node: &PreorderNode) -> ControlFlow<TooDeep> {
        let extra = self.stamped.then_some(node.extra);
        match self.builder.push_with_extra(node.value, extra, node.child_mask, 0) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => ControlFlow::Break(e),
        }
    }
}

impl PreorderVisitor for Build<'_> {
    type Break = TooDeep;

    #[inline(always)]
    fn enter(&mut self, node: &PreorderNode, _: &ChildGroup<'_>) -> ControlFlow<TooDeep> {
        self.push(node)
    }

    #[inline(always)]
    fn leaf(&mut self, node: &PreorderNode) -> ControlFlow<TooDeep> {
        self.push(node)
    }
}

/// Builds the tree of `map` (of `kind`, about `nodes` nodes) from `walk`.
fn build(
    map: &impl PreorderSource,
    kind: NodeKind,
    nodes: u64,
    walk: impl FnOnce(&mut Build<'_>) -> Result<ControlFlow<TooDeep>, TileError>,
) -> Result<OccupancyTree, TileError> {
    let mut builder = PreorderBuilder::with_hint(kind, usize::try_from(nodes).unwrap_or(usize::MAX));
    let stamped = kind == NodeKind::Stamped;
    if walk(&mut Build { builder: &mut builder, stamped })?.is_break() {
        return Err(TileError::Internal("a merged node lies below depth 16"));
    }
    builder.finish(map.resolution(), *map.sensor())?.ok_or(TileError::Internal("the merged node stream is incomplete"))
}

/// A walk that could not read a tile, as the writers' I/O error (the
/// [`TileError`] inside, with its tile and file).
fn walk_error(e: TileError) -> io::Error {
    io::Error::other(e)
}

impl PreorderSource for TiledMap {
    fn node_kind(&self) -> NodeKind {
        self.kind
    }

    fn resolution(&self) -> f64 {
        self.keys.resolution()
    }

    fn sensor(&self) -> &SensorModel {
        &self.sensor
    }

    fn node_count(&self) -> u64 {
        self.stats().nodes
    }

    fn visit_preorder<V: PreorderVisitor>(&self, visitor: &mut V) -> io::Result<ControlFlow<V::Break>> {
        TiledMap::visit_preorder(self, visitor).map_err(walk_error)
    }
}

impl PreorderSource for TileSet {
    fn node_kind(&self) -> NodeKind {
        self.manifest().node_kind()
    }

    fn resolution(&self) -> f64 {
        self.manifest().resolution
    }

    fn sensor(&self) -> &SensorModel {
        TileSet::sensor(self)
    }

    fn node_count(&self) -> u64 {
        TileSet::node_count(self)
    }

    fn visit_preorder<V: PreorderVisitor>(&self, visitor: &mut V) -> io::Result<ControlFlow<V::Break>> {
        TileSet::visit_preorder(self, visitor).map_err(walk_error)
    }
}

/// How many tiles read from disk for a walk exist at once (tests check
/// that a walk holds one at most); nothing outside tests.
pub(super) mod loaded {
    #[cfg(test)]
    thread_local! {
        /// Tiles read for a walk and not dropped yet, and the most at once.
        pub(in crate::tiles) static COUNT: std::cell::Cell<(usize, usize)> = const { std::cell::Cell::new((0, 0)) };
    }

    /// One tile read for a walk, counted while it lives.
    pub(in crate::tiles) struct Tile(());

    impl Tile {
        pub(in crate::tiles) fn new() -> Self {
            #[cfg(test)]
            COUNT.with(|c| {
                let (now, peak) = c.get();
                c.set((now + 1, peak.max(now + 1)));
            });
            Tile(())
        }
    }

    impl Drop for Tile {
        fn drop(&mut self) {
            #[cfg(test)]
            COUNT.with(|c| c.set((c.get().0 - 1, c.get().1)));
        }
    }
}
