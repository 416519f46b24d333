//! The levels above the tiles, derived from the tiles' root nodes as the
//! single tree has them: each node the maximum of its children, and
//! pruned when its eight children are leaves of one value (and, in
//! stamped trees, one stamp). Searches that end above the tiles answer
//! from here; [`Top::visit`] walks the single tree in pre-order.

use super::error::TileError;
use super::id::{code_shift, TileId};
use crate::key::{Key, TREE_DEPTH};
use crate::morton::MortonCode;
use crate::tree::{ChildGroup, Found, NodeKind, NodeRef, PreorderNode, PreorderVisitor};
use std::ops::ControlFlow;

/// A tile's root node (the node at the tile depth) as the single tree
/// has it: what the levels above need to know of the tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileRoot {
    /// Log-odds occupancy.
    pub value: f32,
    /// Time stamp in stamped trees, 0 in plain ones.
    pub extra: u32,
    /// True when the whole tile is one pruned leaf.
    pub is_leaf: bool,
}

/// One node of the derived levels.
#[derive(Clone, Copy, Debug)]
struct TopNode {
    /// The node's Morton prefix at its depth.
    prefix: u64,
    value: f32,
    extra: u32,
    /// Children present (unused at the tile depth, where the tile holds
    /// the structure).
    mask: u8,
    is_leaf: bool,
    /// False below a pruned node: the single tree has no such node.
    visible: bool,
}

/// What a search above the tiles found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum TopAnswer {
    /// The answer, from the derived levels.
    Found(Found),
    /// No node: unknown space.
    Unknown,
    /// The search goes on inside the tile of this index (in tile order).
    Tile(usize),
}

/// What walks tile `i`'s subtree for [`Top::visit`].
pub(crate) type TileWalk<'w, V> =
    dyn FnMut(usize, &mut V) -> Result<ControlFlow<<V as PreorderVisitor>::Break>, TileError> + 'w;

/// The derived levels 0..=tile depth; level `depth` holds the tile roots.
#[derive(Clone, Debug)]
pub(crate) struct Top {
    depth: u8,
    levels: Vec<Vec<TopNode>>,
}

impl Top {
    /// The levels above `tiles` (ascending Morton prefixes at `depth`, each
    /// with its root node).
    pub(crate) fn build(depth: u8, kind: NodeKind, tiles: impl Iterator<Item = (u64, TileRoot)>) -> Top {
        let mut levels = vec![Vec::new(); usize::from(depth) + 1];
        levels[usize::from(depth)] = tiles
            .map(|(prefix, r)| TopNode {
                prefix,
                value: r.value,
                extra: r.extra,
                mask: 0,
                is_leaf: r.is_leaf,
                visible: true,
            })
            .collect();
        debug_assert!(levels[usize::from(depth)].windows(2).all(|w| w[0].prefix < w[1].prefix));
        for d in (0..usize::from(depth)).rev() {
            let (upper, lower) = levels.split_at_mut(d + 1);
            let below = &lower[0];
            let mut level = Vec::new();
            let mut start = 0;
            while start < below.len() {
                let parent = below[start].prefix >> 3;
                let end = start + below[start..].partition_point(|n| n.prefix >> 3 == parent);
                level.push(derive(parent, &below[start..end], kind));
                start = end;
            }
            upper[d] = level;
        }
        // nodes below a pruned node do not exist in the single tree
        for d in 1..levels.len() {
            let (upper, lower) = levels.split_at_mut(d);
            let mut parents = upper[d - 1].iter().peekable();
            for n in lower[0].iter_mut() {
                while parents.peek().is_some_and(|p| p.prefix < n.prefix >> 3) {
                    parents.next();
                }
                let p = parents.peek().expect("every node has its parent");
                n.visible = p.visible && !p.is_leaf;
            }
        }
        Top { depth, levels }
    }

    /// True when there is no tile (the single tree is empty).
    pub(crate) fn is_empty(&self) -> bool {
        self.levels[0].is_empty()
    }

    /// OctoMap's `search(key, depth)` (0 means 16) as far as the derived
    /// levels answer it.
    pub(crate) fn search(&self, key: Key, depth: u8) -> TopAnswer {
        let target = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
        let code = MortonCode::encode(key).0;
        for d in 0..=self.depth {
            let level = &self.levels[usize::from(d)];
            let prefix = code >> code_shift(d);
            let Ok(i) = level.binary_search_by_key(&prefix, |n| n.prefix) else {
                return TopAnswer::Unknown;
            };
            let n = level[i];
            let found = |is_leaf| TopAnswer::Found(Found { value: n.value, depth: d, is_leaf, extra: n.extra });
            if n.is_leaf {
                return found(true);
            }
            if d == target {
                return found(false);
            }
            if d == self.depth {
                return TopAnswer::Tile(i);
            }
        }
        unreachable!("the loop returns at the tile depth")
    }

    /// Nodes of the single tree: those of the derived levels that it has,
    /// plus `subtree(i)` for each tile `i` it has (the tile's nodes from
    /// its root down).
    pub(crate) fn node_count(&self, subtree: impl Fn(usize) -> u64) -> u64 {
        let tiles = &self.levels[usize::from(self.depth)];
        let above: u64 = self.levels[..usize::from(self.depth)]
            .iter()
            .map(|level| level.iter().filter(|n| n.visible).count() as u64)
            .sum();
        let below: u64 = tiles
            .iter()
            .enumerate()
            .filter(|(_, n)| n.visible)
            .map(|(i, n)| if n.is_leaf { 1 } else { subtree(i) })
            .sum();
        above + below
    }

    /// Walks the single tree in pre-order, telling `visitor` of the
    /// derived nodes, and, for each tile whose root is not a leaf (nor
    /// below a pruned node), calling `tile(i, visitor)`, which walks the
    /// tile's subtree from its root (at the tile depth). The children
    /// groups of the nodes just above the tiles need the tile roots' child
    /// masks: `tile_mask(i)`.
    pub(crate) fn visit<V: PreorderVisitor>(
        &self,
        visitor: &mut V,
        tile_mask: &dyn Fn(usize) -> Result<u8, TileError>,
        tile: &mut TileWalk<'_, V>,
    ) -> Result<ControlFlow<V::Break>, TileError> {
        if self.is_empty() {
            return Ok(ControlFlow::Continue(()));
        }
        self.visit_node(0, 0, visitor, tile_mask, tile)
    }

    fn visit_node<V: PreorderVisitor>(
        &self,
        d: u8,
        i: usize,
        visitor: &mut V,
        tile_mask: &dyn Fn(usize) -> Result<u8, TileError>,
        tile: &mut TileWalk<'_, V>,
    ) -> Result<ControlFlow<V::Break>, TileError> {
        let n = self.levels[usize::from(d)][i];
        if n.is_leaf {
            return Ok(visitor.leaf(&PreorderNode { depth: d, child_mask: 0, value: n.value, extra: n.extra }));
        }
        if d == self.depth {
            return tile(i, visitor);
        }
        let below = &self.levels[usize::from(d) + 1];
        let start = below.partition_point(|c| c.prefix >> 3 < n.prefix);
        let end = start + below[start..].partition_point(|c| c.prefix >> 3 == n.prefix);
        let (mut masks, mut values, mut extras) = ([0u8; 8], [0f32; 8], [0u32; 8]);
        for (k, (j, c)) in (start..end).zip(&below[start..end]).enumerate() {
            masks[k] = match (c.is_leaf, d + 1 == self.depth) {
                (true, _) => 0,
                (false, true) => tile_mask(j)?,
                (false, false) => c.mask,
            };
            (values[k], extras[k]) = (c.value, c.extra);
        }
        let k = end - start;
        let group = ChildGroup::new(n.mask, &masks[..k], &values[..k], &extras[..k]);
        let node = PreorderNode { depth: d, child_mask: n.mask, value: n.value, extra: n.extra };
        if let ControlFlow::Break(b) = visitor.enter(&node, &group) {
            return Ok(ControlFlow::Break(b));
        }
        for j in start..end {
            if let ControlFlow::Break(b) = self.visit_node(d + 1, j, visitor, tile_mask, tile)? {
                return Ok(ControlFlow::Break(b));
            }
        }
        Ok(visitor.leave(&node))
    }
}

/// A node derived from its children (a run of the level below with one
/// parent): the rules of `pruneNode` and `updateOccupancyChildren`.
fn derive(prefix: u64, children: &[TopNode], kind: NodeKind) -> TopNode {
    let first = children[0];
    let stamped = kind == NodeKind::Stamped;
    let mut mask = 0u8;
    let mut max = -f32::MAX;
    let mut max_extra = 0;
    let mut same = true;
    for c in children {
        mask |= 1 << (c.prefix & 7);
        if c.value > max {
            max = c.value;
        }
        max_extra = max_extra.max(c.extra);
        same &= c.is_leaf && c.value == first.value && (!stamped || c.extra == first.extra);
    }
    let is_leaf = mask == 0xff && same;
    // an inner stamped node carries the time of the last change below it:
    // the latest of its children's stamps (the clock never runs back)
    let (value, extra) = if is_leaf { (first.value, first.extra) } else { (max, if stamped { max_extra } else { 0 }) };
    TopNode { prefix, value, extra, mask: if is_leaf { 0 } else { mask }, is_leaf, visible: true }
}

/// The root node of tile `id` in a tree holding that tile alone: the end
/// of the chain of single children from the tree's root; `Err` says how
/// the tree differs from that shape.
pub(crate) fn tile_root_node(root: NodeRef<'_>, id: TileId) -> Result<NodeRef<'_>, String> {
    let mut node = root;
    for d in 0..id.depth() {
        let pos = id.child_index(d);
        if node.child_mask() != 1 << pos {
            return Err(format!(
                "the node at depth {d} has child mask {:#04x}, not only child {pos} on the way to the tile",
                node.child_mask()
            ));
        }
        node = node.child(pos).expect("the mask says it exists");
    }
    Ok(node)
}

/// What the levels above need of a tile root node.
pub(crate) fn root_of(node: NodeRef<'_>) -> TileRoot {
    TileRoot { value: node.value(), extra: node.extra(), is_leaf: !node.has_children() }
}
