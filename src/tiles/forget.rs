//! Forgetting, opt-in, for maps that move with the robot: a rolling window
//! of tiles around the latest sensor origin, and the removal of voxels
//! not seen for a while in stamped maps.
//!
//! Both are departures from OctoMap, which keeps every node it ever made
//! (its `degradeOutdatedNodes` lowers old occupied leaves towards free and
//! leaves them allocated). Off by default; a map that never calls them is
//! OctoMap's map to the byte. What they leave is the single tree with the
//! same nodes deleted (`deleteNode` of each tile root, or of each old
//! leaf), except that an inner node above the tile depth carries the latest
//! of its children's stamps where `deleteNode` would stamp it with the
//! current time.
//!
//! A window that spills instead of dropping keeps the map exact: the tiles
//! beyond it go to the memory budget's directory and come back when a scan
//! reaches them again.

use super::error::TileError;
use super::id::TileId;
use super::map::{TileState, TiledMap};
use crate::geometry::Point3;
use crate::tree::{Bounds, NodeKind};

/// A rolling window: after each scan, what happens to the tiles that lie
/// wholly farther than `radius` metres from the scan's origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    /// Metres from the latest sensor origin to the nearest point of a tile
    /// that stays.
    pub radius: f64,
    /// What becomes of the tiles beyond.
    pub beyond: Beyond,
}

/// What a [`Window`] does with the tiles outside it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Beyond {
    /// Forgotten: their space is unknown again (a departure from OctoMap).
    Drop,
    /// Written to the memory budget's directory and read back when a scan
    /// reaches them again (the map stays exact; needs a budget).
    Spill,
}

impl Window {
    /// Refuses a radius that is not a finite number ≥ 0.
    fn check(&self) -> Result<(), TileError> {
        if !(self.radius.is_finite() && self.radius >= 0.0) {
            return Err(TileError::BadWindow(self.radius));
        }
        Ok(())
    }
}

/// Distance in metres from `p` to the nearest point of the box `b`.
fn distance_to_box(p: Point3, b: &Bounds) -> f64 {
    let q = [f64::from(p.x), f64::from(p.y), f64::from(p.z)];
    let d2: f64 = (0..3)
        .map(|i| {
            let d = (b.min[i] - q[i]).max(q[i] - b.max[i]).max(0.0);
            d * d
        })
        .sum();
    d2.sqrt()
}

impl TiledMap {
    /// Applies `window` after every scan from now on (`None`: no window,
    /// the default). [`Beyond::Spill`] needs a memory budget.
    pub fn set_window(&mut self, window: Option<Window>) -> Result<(), TileError> {
        if let Some(w) = &window {
            w.check()?;
            if w.beyond == Beyond::Spill && self.budget.is_none() {
                return Err(TileError::Unsupported("a window that spills tiles needs a memory budget"));
            }
        }
        self.window = window;
        Ok(())
    }

    /// The window applied after every scan.
    pub fn window(&self) -> Option<Window> {
        self.window
    }

    /// The tiles lying wholly farther than `radius` metres from `center`,
    /// in Morton order.
    pub fn tiles_beyond(&self, center: Point3, radius: f64) -> Vec<TileId> {
        self.tiles().filter(|id| distance_to_box(center, &id.bounds(&self.keys)) > radius).collect()
    }

    /// Drops the tiles lying wholly farther than `radius` metres from
    /// `center`: their space becomes unknown (a departure from OctoMap; see
    /// the module docs). A spilled tile's file is removed. Returns the tiles
    /// dropped.
    pub fn forget_beyond(&mut self, center: Point3, radius: f64) -> Result<Vec<TileId>, TileError> {
        Window { radius, beyond: Beyond::Drop }.check()?;
        let ids = self.tiles_beyond(center, radius);
        for &id in &ids {
            self.drop_tile(id)?;
        }
        Ok(ids)
    }

    /// Writes the tiles lying wholly farther than `radius` metres from
    /// `center` to the memory budget's directory (the map stays the same).
    /// Returns the tiles written out or already out.
    pub fn spill_beyond(&mut self, center: Point3, radius: f64) -> Result<Vec<TileId>, TileError> {
        Window { radius, beyond: Beyond::Spill }.check()?;
        if self.budget.is_none() {
            return Err(TileError::Unsupported("spilling tiles needs a memory budget"));
        }
        let ids = self.tiles_beyond(center, radius);
        for &id in &ids {
            if matches!(self.tiles[&id.prefix()].state, TileState::Live { .. }) {
                self.spill(id.prefix())?;
            }
        }
        Ok(ids)
    }

    /// Applies the window, if any, for a scan from `origin`.
    pub(super) fn apply_window(&mut self, origin: Point3) -> Result<(), TileError> {
        match self.window {
            None => Ok(()),
            Some(Window { radius, beyond: Beyond::Drop }) => self.forget_beyond(origin, radius).map(drop),
            Some(Window { radius, beyond: Beyond::Spill }) => self.spill_beyond(origin, radius).map(drop),
        }
    }

    /// Deletes, in a stamped map, every leaf whose stamp is older than
    /// `oldest` (seconds, the clock's scale): its space becomes unknown
    /// and its memory is freed, where OctoMap's `degradeOutdatedNodes`
    /// keeps the node. Tiles left without nodes are dropped. Spilled tiles
    /// are read back one at a time. Returns the number of leaves deleted.
    pub fn forget_older_than(&mut self, oldest: u32) -> Result<usize, TileError> {
        if self.kind != NodeKind::Stamped {
            return Err(TileError::Unsupported("only stamped maps know how old their voxels are"));
        }
        let prefixes: Vec<u64> = self.tiles.keys().copied().collect();
        let mut deleted = 0;
        for prefix in prefixes {
            self.uses += 1;
            let (mut tree, saved) = self.take_tree(prefix)?;
            let old: Vec<_> = tree.leaves(0).filter(|n| n.extra < oldest).map(|n| (n.key, n.depth)).collect();
            if old.is_empty() {
                self.put_tree(prefix, tree, saved);
                self.enforce_budget()?;
                continue;
            }
            self.changed(crate::tree::InnerNodes::Update);
            tree.set_clock(self.clock);
            let mut emptied = false;
            for &(key, depth) in &old {
                emptied = tree.delete(key, depth);
            }
            deleted += old.len();
            if emptied {
                self.remove_spilled_file(TileId::from_prefix(self.depth, prefix))?;
            } else {
                self.put_tree(prefix, tree, None);
                self.enforce_budget()?;
            }
        }
        Ok(deleted)
    }

    /// Removes tile `id` from the map, with its spilled file if any.
    fn drop_tile(&mut self, id: TileId) -> Result<(), TileError> {
        let Some(tile) = self.tiles.remove(&id.prefix()) else {
            return Ok(());
        };
        self.changed(crate::tree::InnerNodes::Update);
        match tile.state {
            TileState::Live { bytes, saved, .. } => {
                if let Some(b) = &mut self.budget {
                    b.uncount(tile.last_use, id.prefix(), bytes);
                }
                if saved.is_some() {
                    self.remove_spilled_file(id)?;
                }
            }
            TileState::Spilled(_) => self.remove_spilled_file(id)?,
        }
        Ok(())
    }

    /// Removes tile `id`'s file from the budget's directory, if there is one.
    fn remove_spilled_file(&self, id: TileId) -> Result<(), TileError> {
        let Some(b) = &self.budget else { return Ok(()) };
        let path = b.path(id);
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(TileError::io(path, e)),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::ot::to_bytes as ot;
    use crate::scan::ScanOptions;
    use crate::sensor::SensorModel;
    use crate::tiles::MemoryBudget;
    use crate::tree::{Clock, OccupancyTree};

    /// The bundled sample's first scans (indoor lidar), origins moving.
    fn scans(n: usize) -> Vec<(Vec<Point3>, Point3)> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph");
        let g = crate::formats::graph::read_file(path).unwrap();
        g.nodes.iter().take(n).map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect()
    }

    /// Every leaf: key, depth, value bits, stamp.
    fn leaves(t: &OccupancyTree) -> Vec<([u16; 3], u8, u32, u32)> {
        t.leaves(0).map(|n| (n.key.0, n.depth, n.value.to_bits(), n.extra)).collect()
    }

    /// Every node: key, depth, value bits, leaf or not.
    fn nodes(t: &OccupancyTree) -> Vec<([u16; 3], u8, u32, bool)> {
        t.nodes(0).map(|n| (n.key.0, n.depth, n.value.to_bits(), n.is_leaf)).collect()
    }

    fn build(kind: NodeKind, depth: u8, scans: &[(Vec<Point3>, Point3)]) -> (TiledMap, OccupancyTree) {
        let opts = ScanOptions::default();
        let mut tiled = TiledMap::new(0.1, SensorModel::default(), kind, depth).unwrap();
        let mut single = OccupancyTree::with_kind(0.1, SensorModel::default(), kind).unwrap();
        for (i, (p, o)) in scans.iter().enumerate() {
            tiled.set_clock(Clock::Fixed(1000 + i as u32));
            single.set_clock(Clock::Fixed(1000 + i as u32));
            tiled.insert_point_cloud(p, *o, &opts).unwrap();
            single.insert_point_cloud(p, *o, &opts).unwrap();
        }
        (tiled, single)
    }

    #[test]
    fn dropped_tiles_leave_the_single_tree_less_their_subtrees() {
        let s = scans(4);
        for kind in [NodeKind::Plain, NodeKind::Stamped] {
            for depth in [9, 11, 13] {
                let (mut tiled, mut single) = build(kind, depth, &s);
                let before = tiled.tiles().count();
                let dropped = tiled.forget_beyond(s[3].1, 2.0).unwrap();
                assert!(!dropped.is_empty() && dropped.len() < before, "depth {depth}: {} of {before}", dropped.len());
                for id in &dropped {
                    assert!(distance_to_box(s[3].1, &id.bounds(tiled.key_space())) > 2.0);
                    let (low, _) = id.key_range();
                    single.delete(low, depth);
                }
                // OctoMap's `deleteNode` counts a deleted subtree as one node
                // (its size goes stale, and with it the `.ot` header): the
                // nodes themselves are compared
                let merged = tiled.merge().unwrap();
                assert!(nodes(&merged) == nodes(&single), "{kind:?} depth {depth}: the nodes differ");
                assert_eq!(merged.size(), merged.nodes(0).count());
                assert!(leaves(&merged) == leaves(&single), "{kind:?} depth {depth}: leaves differ");
                // nothing left beyond the radius
                assert!(tiled.tiles_beyond(s[3].1, 2.0).is_empty());
            }
        }
    }

    #[test]
    fn a_window_drops_as_the_robot_moves_and_a_spilling_window_keeps_the_map() {
        let s = scans(6);
        let opts = ScanOptions::default();
        let radius = 3.0;
        let mut windowed = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 11).unwrap();
        windowed.set_window(Some(Window { radius, beyond: Beyond::Drop })).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mut spilling = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 11).unwrap();
        spilling.set_budget(MemoryBudget { bytes: usize::MAX, dir: dir.path().into() }).unwrap();
        spilling.set_window(Some(Window { radius, beyond: Beyond::Spill })).unwrap();
        let mut single = OccupancyTree::new(0.1).unwrap();
        let mut by_hand = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 11).unwrap();
        for (p, o) in &s {
            windowed.insert_point_cloud(p, *o, &opts).unwrap();
            spilling.insert_point_cloud(p, *o, &opts).unwrap();
            single.insert_point_cloud(p, *o, &opts).unwrap();
            by_hand.insert_point_cloud(p, *o, &opts).unwrap();
            by_hand.forget_beyond(*o, radius).unwrap();
            assert!(windowed.tiles_beyond(*o, radius).is_empty());
            for id in spilling.tiles_beyond(*o, radius) {
                assert!(matches!(spilling.tiles[&id.prefix()].state, TileState::Spilled(_)), "{id} is live");
            }
        }
        let windowed = ot(&windowed.merge().unwrap());
        assert!(windowed == ot(&by_hand.merge().unwrap()), "the window drops what forget_beyond drops");
        assert!(windowed != ot(&single), "the window dropped nothing");
        assert!(ot(&spilling.merge().unwrap()) == ot(&single), "spilling changed the map");
        assert!(spilling.stats().live_tiles < spilling.stats().tiles, "nothing was spilled");
        // the pipelined insertion applies the window after every scan too
        let mut pipelined = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 11).unwrap();
        pipelined.set_window(Some(Window { radius, beyond: Beyond::Drop })).unwrap();
        let two = ScanOptions { threads: Some(2), ..opts };
        pipelined.insert_point_clouds(s.iter().map(|(p, o)| (p.as_slice(), *o)), &two, |_, _| {}).unwrap();
        assert!(ot(&pipelined.merge().unwrap()) == windowed, "the pipelined window differs");
    }

    #[test]
    fn old_leaves_are_deleted_as_delete_node_deletes_them() {
        let s = scans(5);
        for depth in [2, 8, 12] {
            let (mut tiled, mut single) = build(NodeKind::Stamped, depth, &s);
            tiled.set_clock(Clock::Fixed(2000));
            single.set_clock(Clock::Fixed(2000));
            let old: Vec<_> = single.leaves(0).filter(|n| n.extra < 1003).map(|n| (n.key, n.depth)).collect();
            assert!(!old.is_empty());
            for &(k, d) in &old {
                single.delete(k, d);
            }
            let deleted = tiled.forget_older_than(1003).unwrap();
            assert_eq!(deleted, old.len(), "depth {depth}");
            let merged = tiled.merge().unwrap();
            assert!(ot(&merged) == ot(&single), "depth {depth}: .ot bytes differ");
            assert_eq!(leaves(&merged), leaves(&single), "depth {depth}");
            assert!(merged.leaves(0).all(|n| n.extra >= 1003));
        }
        // everything older than the last scan: only its voxels stay
        let (mut tiled, _) = build(NodeKind::Stamped, 8, &s);
        let tiles = tiled.tiles().count();
        tiled.forget_older_than(u32::MAX).unwrap();
        assert!(tiled.is_empty(), "{tiles} tiles");
    }

    #[test]
    fn bad_windows_and_plain_maps_are_refused() {
        let mut t = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 8).unwrap();
        for r in [f64::NAN, -1.0, f64::INFINITY] {
            assert!(matches!(
                t.set_window(Some(Window { radius: r, beyond: Beyond::Drop })),
                Err(TileError::BadWindow(_))
            ));
            assert!(t.forget_beyond(Point3::new(0.0, 0.0, 0.0), r).is_err());
        }
        assert!(t.set_window(Some(Window { radius: 1.0, beyond: Beyond::Spill })).is_err());
        assert!(t.spill_beyond(Point3::new(0.0, 0.0, 0.0), 1.0).is_err());
        assert!(t.forget_older_than(5).is_err());
    }
}
