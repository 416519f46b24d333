//! Occupancy updates: one voxel at a time, in sorted batches, deferred
//! inner-node updates, and the max-likelihood rewrite.

use super::batch::{Batch, ChildRanges, Splits};
use super::rules::{average_child_color, prune_node, update_from_children};
use super::{parallel, Compaction, InnerNodes, NodeArena, NodeId, NodeKind, OccupancyTree, Rules, ROOT};
use crate::geometry::Point3;
use crate::key::{Key, KeyError, TREE_DEPTH};

impl OccupancyTree {
    /// Adds a log-odds `delta` to the voxel at `key` (`updateNode(key, float)`),
    /// clamping the result. Returns the value of the node holding the voxel
    /// afterwards (a coarser node when the update pruned it).
    pub fn update(&mut self, key: Key, delta: f32, inner: InnerNodes) -> f32 {
        if let Some(found) = self.search_arena(key, 0) {
            if self.sensor.is_saturated(found.value, delta) {
                return found.value;
            }
        }
        let sensor = self.sensor;
        self.modify(key, inner, true, |v| sensor.apply(v, delta))
    }

    /// Integrates a hit (`occupied`) or a miss at `key`.
    pub fn update_occupancy(&mut self, key: Key, occupied: bool, inner: InnerNodes) -> f32 {
        let delta = if occupied { self.sensor.hit } else { self.sensor.miss };
        self.update(key, delta, inner)
    }

    /// [`Self::update_occupancy`] at the voxel containing `p`.
    pub fn update_point(&mut self, p: Point3, occupied: bool, inner: InnerNodes) -> Result<f32, KeyError> {
        let key = self.keys.key(p)?;
        Ok(self.update_occupancy(key, occupied, inner))
    }

    /// Sets the voxel's log-odds (clamped), as `setNodeValue` does.
    pub fn set_value(&mut self, key: Key, value: f32, inner: InnerNodes) -> f32 {
        let v = self.sensor.clamp(value);
        self.modify(key, inner, false, |_| v)
    }

    /// Descends to `key` creating (or expanding) nodes as OctoMap's
    /// `updateNodeRecurs` does, applies `f` to the voxel, then updates and
    /// prunes the path bottom-up unless deferred.
    fn modify(&mut self, key: Key, inner: InnerNodes, stamp: bool, f: impl FnOnce(f32) -> f32) -> f32 {
        let rules = self.rules();
        let mut created = false;
        if self.arena.is_none() {
            self.arena = Some(Self::new_arena(self.kind, 0.0));
            self.size += 1;
            created = true;
        }
        self.forget_trunks();
        let arena = self.arena.as_mut().expect("root exists");
        let mut path = [ROOT; TREE_DEPTH as usize];
        let mut node = ROOT;
        for depth in 0..TREE_DEPTH {
            let pos = key.child_index(depth);
            path[depth as usize] = node;
            node = match arena.child(node, pos) {
                Some(c) => {
                    created = false;
                    c
                }
                None if !arena.has_children(node) && !created => {
                    arena.expand_node(node, depth);
                    self.size += 8;
                    created = false;
                    arena.child(node, pos).expect("just expanded")
                }
                None => {
                    self.size += 1;
                    created = true;
                    arena.insert_child(node, pos, 0.0, depth)
                }
            };
        }
        let before = arena.value(node);
        let after = f(before);
        arena.set_value(node, after);
        if stamp && rules.kind == NodeKind::Stamped {
            arena.set_extra(node, rules.now);
        }
        if let Some(changes) = self.changes.as_mut() {
            let (was, is) = (self.sensor.is_occupied(before), self.sensor.is_occupied(after));
            super::changes::record_change(changes, key, created, was, is);
        }
        if inner == InnerNodes::Defer {
            return after;
        }
        let mut result = after;
        for &n in path.iter().rev() {
            if let Some(v) = prune_node(arena, n, rules) {
                self.size -= 8;
                result = v;
            } else {
                update_from_children(arena, n, rules);
            }
        }
        result
    }

    /// Adds `delta` to every voxel in `codes` (Morton codes, strictly
    /// increasing), with the result of calling [`Self::update`] on each in
    /// that order, but walking the tree once: keys sharing a path from the
    /// root share its traversal, and each touched inner node is updated and
    /// pruned once, after its whole subtree. This is equivalent because each
    /// voxel appears once, so leaf values do not depend on the order, and a
    /// node's final pruning only depends on its children's final state.
    #[cfg(any(test, feature = "internals"))]
    pub(crate) fn update_batch(&mut self, codes: &[u64], delta: f32, inner: InnerNodes) {
        self.update_batch_split(codes, delta, inner, 1, &|| {});
    }

    /// [`Self::update_batch`] with the work shared by the threads of the
    /// current rayon pool, split in `2 * workers` parts, when the batch has
    /// 262,144 codes or more and no changes are being recorded. The tree is
    /// the one [`Self::update_batch`] gives.
    pub(crate) fn update_batch_shared(&mut self, codes: &[u64], delta: f32, inner: InnerNodes, workers: usize) {
        self.update_batch_split(codes, delta, inner, workers, &|| {});
    }

    /// [`Self::update_batch_shared`]; `announce` is called once work is
    /// waiting to be taken, so that threads blocked elsewhere can come and
    /// help (see `rayon::yield_now`).
    pub(crate) fn update_batch_split(
        &mut self,
        codes: &[u64],
        delta: f32,
        inner: InnerNodes,
        workers: usize,
        announce: &(dyn Fn() + Sync),
    ) {
        if codes.is_empty() {
            return;
        }
        let mut created = false;
        if self.arena.is_none() {
            self.arena = Some(Self::new_arena(self.kind, 0.0));
            self.size += 1;
            created = true;
        }
        let rules = self.rules();
        self.forget_trunks();
        let splits = Splits::new(codes);
        let mut batch = Batch {
            arena: self.arena.as_mut().expect("root exists"),
            rules,
            sensor: self.sensor,
            delta,
            lazy: inner == InnerNodes::Defer,
            size: self.size as isize,
            changes: self.changes.as_mut(),
            split: None,
            ranges: ChildRanges::new(&splits, codes),
        };
        if workers > 1 && codes.len() >= parallel::MIN_CODES && batch.changes.is_none() {
            parallel::apply(&mut batch, codes, created, workers, announce);
        } else {
            batch.apply(ROOT, 0, codes, created);
        }
        self.size = batch.size as usize;
        if self.compaction == Compaction::Automatic {
            let a = self.arena_mut().expect("root exists");
            if a.free_slot_count() * 8 > a.slot_count() {
                a.compact_in_place(ROOT);
            }
        }
        self.refresh_trunks();
    }

    /// Recomputes every inner node as the maximum of its children
    /// (`updateInnerOccupancy`), after deferred updates.
    pub fn update_inner_occupancy(&mut self) {
        fn recurse(a: &mut NodeArena, n: NodeId, rules: Rules) {
            if !a.has_children(n) {
                return;
            }
            let first = a.first_child(n);
            for i in 0..crate::arch::count_ones(a.mask(n)) {
                recurse(a, first + i, rules);
            }
            update_from_children(a, n, rules);
            if rules.kind == NodeKind::Color {
                let c = average_child_color(a, n);
                a.set_extra(n, c);
            }
        }
        let rules = self.rules();
        if let Some(a) = self.arena_mut() {
            recurse(a, ROOT, rules);
        }
        self.refresh_trunks();
    }

    /// Sets every node to the clamping bound on its side of the occupancy
    /// threshold (`toMaxLikelihood`).
    pub fn to_max_likelihood(&mut self) {
        let sensor = self.sensor;
        if let Some(a) = self.arena_mut() {
            // free slots are rewritten too; their values are never read
            a.map_values(|v| sensor.max_likelihood(v));
        }
        self.refresh_trunks();
    }
}
