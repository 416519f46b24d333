//! The occupancy octree: OctoMap's `OcTree` semantics on a node arena.

mod arena;
pub(crate) mod blocks;
mod counting;
mod cursor;
mod iter;
mod kind;
mod level_index;
mod parallel;
mod search_index;
mod trunk;

pub use arena::ArenaUsage;
pub(crate) use arena::LabelFill;
pub(crate) use arena::{in_leaf_pool, leaf_index, prefetch_lines, Parts, WHOLE_PREFETCH_BYTES};
pub(crate) use arena::{NodeArena, NodeId};
use arena::{NodeStore, PreorderFill};
pub use counting::CountingTree;
pub(crate) use cursor::{LastAnswer, PathSearch};
pub use iter::{KeyBox, NodeItem, NodeIter};
pub use kind::{NodeKind, TreeKind};
use level_index::{LevelSlot, Reach};
#[cfg(test)]
pub(crate) use parallel::MIN_CODES as PARALLEL_MIN_CODES;
pub(crate) use search_index::LevelTables;
pub use search_index::SearchIndex;
pub(crate) use trunk::{Trunks, GRID_NODES_PER_CELL};

use crate::geometry::Point3;
use crate::key::{adjust_key_to_depth, Key, KeyError, KeySpace, TREE_DEPTH};
use crate::morton::MortonCode;
use crate::sensor::SensorModel;
use hashbrown::HashMap;

const ROOT: NodeId = 0;

/// Size in bytes OctoMap's x86-64 build reports for the tree object itself
/// in `memoryUsage()` (`sizeof(OcTreeBaseImpl<OcTreeNode, ...>)`).
const OCTOMAP_TREE_OBJECT_BYTES: usize = 320;

/// When inner nodes learn of a change below them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InnerNodes {
    /// Update (and prune) every node on the path right away, as OctoMap
    /// does with `lazy_eval = false`.
    #[default]
    Update,
    /// Leave inner nodes stale until [`OccupancyTree::update_inner_occupancy`]
    /// (`lazy_eval = true`).
    Defer,
}

/// Why a tree could not be made.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum TreeError {
    /// The resolution (the value given, metres) is zero, negative, NaN or infinite.
    #[error("resolution {0} m is not a positive finite number")]
    BadResolution(f64),
}

/// A node found by a search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Found {
    /// The node's occupancy, log-odds.
    pub value: f32,
    /// Depth of the node found (0 = root, 16 = finest).
    pub depth: u8,
    /// True when the node has no children.
    pub is_leaf: bool,
    /// Colour (`r | g << 8 | b << 16`) or time stamp, by the tree's
    /// [`NodeKind`]; 0 for plain trees.
    pub extra: u32,
}

/// An RGB colour packed as `r | g << 8 | b << 16`; white means unset.
pub const WHITE: u32 = 0x00ff_ffff;

/// Packs `[r, g, b]` as `r | g << 8 | b << 16`.
pub fn pack_rgb(rgb: [u8; 3]) -> u32 {
    u32::from(rgb[0]) | (u32::from(rgb[1]) << 8) | (u32::from(rgb[2]) << 16)
}

/// Unpacks `r | g << 8 | b << 16` to `[r, g, b]` (bits above 24 ignored).
pub fn unpack_rgb(c: u32) -> [u8; 3] {
    [c as u8, (c >> 8) as u8, (c >> 16) as u8]
}

/// Where stamped trees get the time from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Clock {
    /// Seconds since the Unix epoch, as OctoMap's `time(NULL)`.
    #[default]
    System,
    /// A fixed time (replays, tests).
    Fixed(u32),
}

impl Clock {
    /// The current time in seconds: the fixed value, or the system time
    /// truncated to `u32` (0 if the system clock is before the epoch).
    pub fn now(self) -> u32 {
        match self {
            Clock::Fixed(t) => t,
            Clock::System => {
                std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() as u32)
            }
        }
    }
}

/// The per-kind rules, with the time already read.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rules {
    pub(crate) kind: NodeKind,
    pub(crate) now: u32,
}

/// Metric bounds of the known space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Lower corner `[x, y, z]`, metres.
    pub min: [f64; 3],
    /// Upper corner `[x, y, z]`, metres.
    pub max: [f64; 3],
}

impl Bounds {
    /// Extent per axis, `max - min`, metres.
    pub fn size(&self) -> [f64; 3] {
        [self.max[0] - self.min[0], self.max[1] - self.min[1], self.max[2] - self.min[2]]
    }
}

/// How a bound is accumulated; OctoMap's two overloads differ in the last bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoundsRule {
    /// `centre ± size/2` (OctoMap's const `getMetricMin/Max`).
    CenterHalfSize,
    /// max = `(centre - size/2) + size` (OctoMap's non-const overloads,
    /// used by `volume()` and `graph2tree`'s output).
    MinPlusSize,
}

/// A probabilistic occupancy octree, bit-compatible with OctoMap's `OcTree`.
#[derive(Clone, Debug)]
pub struct OccupancyTree {
    keys: KeySpace,
    sensor: SensorModel,
    /// `None` for an empty tree (OctoMap's `root == NULL`).
    arena: Option<NodeArena>,
    /// OctoMap's maintained node counter (`size()`); it only drops by one
    /// when an inner node is deleted, exactly as OctoMap's does.
    size: usize,
    changes: Option<HashMap<Key, bool>>,
    kind: NodeKind,
    clock: Clock,
    compaction: Compaction,
    /// Where searches start ([`Trunks`]): derived after bulk changes,
    /// reset to the root by any other change (see [`Self::arena_mut`]).
    trunks: Trunks<NodeId>,
    /// Breadth-first navigation for searches of large trees; armed and
    /// dropped with the trunks.
    levels: LevelSlot,
}

/// When the arena is re-laid (see [`OccupancyTree::compact`]) to give back
/// the slots that moved and pruned child groups left free. Revisiting
/// mapped space prunes more than it creates, and those slots are only
/// reused by groups of their size: building an indoor map left up to 28%
/// of the slots free.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Compaction {
    /// After a batch update ([`OccupancyTree::update_batch`], so after each
    /// scan of `insert_point_cloud`) that leaves more than an eighth of the
    /// slots free. Each compaction follows at least that many frees, so its
    /// cost is bounded by a few slot moves per update.
    #[default]
    Automatic,
    /// Only when [`OccupancyTree::compact`] is called.
    Manual,
}

impl OccupancyTree {
    /// An empty tree with OctoMap's default sensor model.
    pub fn new(resolution: f64) -> Result<Self, TreeError> {
        Self::with_sensor(resolution, SensorModel::default())
    }

    /// An empty plain tree with the given sensor model; `resolution` is
    /// the voxel edge length in metres.
    pub fn with_sensor(resolution: f64, sensor: SensorModel) -> Result<Self, TreeError> {
        Self::with_kind(resolution, sensor, NodeKind::Plain)
    }

    /// An empty tree whose nodes carry what `kind` says.
    pub fn with_kind(resolution: f64, sensor: SensorModel, kind: NodeKind) -> Result<Self, TreeError> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(TreeError::BadResolution(resolution));
        }
        Ok(OccupancyTree {
            keys: KeySpace::new(resolution),
            sensor,
            arena: None,
            size: 0,
            changes: None,
            kind,
            clock: Clock::System,
            compaction: Compaction::default(),
            trunks: Trunks::at_root(ROOT),
            levels: LevelSlot::off(),
        })
    }

    /// What the tree's nodes carry besides occupancy.
    pub fn kind(&self) -> NodeKind {
        self.kind
    }

    /// The clock stamped trees read when updating.
    pub fn set_clock(&mut self, clock: Clock) {
        self.clock = clock;
    }

    fn rules(&self) -> Rules {
        let now = if self.kind == NodeKind::Stamped { self.clock.now() } else { 0 };
        Rules { kind: self.kind, now }
    }

    /// A new arena with a root of `value`, carrying this kind's extras.
    pub(crate) fn new_arena(kind: NodeKind, value: f32) -> NodeArena {
        NodeArena::with_root_and_extras(value, default_extra(kind))
    }

    /// Voxel edge length at the finest depth, metres.
    pub fn resolution(&self) -> f64 {
        self.keys.resolution()
    }

    /// The tree's coordinate/key arithmetic.
    pub fn key_space(&self) -> &KeySpace {
        &self.keys
    }

    /// The sensor model updates use.
    pub fn sensor(&self) -> &SensorModel {
        &self.sensor
    }

    /// Replaces the sensor model; values already in the tree are left as they are.
    pub fn set_sensor(&mut self, sensor: SensorModel) {
        self.sensor = sensor;
    }

    /// True when the tree has no node at all (not even a root).
    pub fn is_empty(&self) -> bool {
        self.arena.is_none()
    }

    /// The key of the voxel containing `p`.
    #[inline]
    pub fn key(&self, p: Point3) -> Result<Key, KeyError> {
        self.keys.key(p)
    }

    /// OctoMap's `size()`: the maintained node counter.
    pub fn size(&self) -> usize {
        self.size
    }

    pub(crate) fn arena(&self) -> Option<&NodeArena> {
        self.arena.as_ref()
    }

    /// The arena for a change: searches start at the root again until
    /// [`Self::refresh_trunks`], since the change may move or remove the
    /// trunk ends. Every change goes through here.
    fn arena_mut(&mut self) -> Option<&mut NodeArena> {
        self.forget_trunks();
        self.arena.as_mut()
    }

    /// What [`Self::arena_mut`] does first, for changes that need the
    /// arena borrowed apart from other fields.
    fn forget_trunks(&mut self) {
        self.trunks.reset();
        self.levels = LevelSlot::off();
    }

    /// Derives the search starts from the current nodes (a few dozen node
    /// visits), after a change that costs far more. Their grids, at most
    /// one cell per four nodes, wait for the first search.
    fn refresh_trunks(&mut self) {
        self.levels = LevelSlot::armed(self.size);
        self.trunks = match &self.arena {
            Some(a) => {
                let p = a.parts();
                let cells = self.size / GRID_NODES_PER_CELL as usize;
                Trunks::build(ROOT, cells, |n| Some(p.mask(n)), |n, _, pos| p.descend(n, pos as u64).ok())
            }
            None => Trunks::at_root(ROOT),
        };
    }

    /// Where a search for `key` (Morton `code`, at `depth`) starts; see
    /// [`Trunks::start`].
    #[inline(always)]
    fn start(&self, p: &Parts<'_>, key: Key, depth: u8) -> (NodeId, u8) {
        self.trunks.start(key, depth, |n| Some(p.mask(n)), |n, _, pos| p.descend(n, pos as u64).ok())
    }

    /// Replaces the content with `arena`, which has no free slots (as
    /// built by [`PreorderBuilder`]): its slot count is the node count.
    pub(crate) fn set_arena_with_size(&mut self, arena: NodeArena) {
        let usage = arena.usage();
        debug_assert_eq!(usage.free_slots, 0);
        self.size = usage.live_slots;
        self.arena = Some(arena);
        self.refresh_trunks();
        debug_assert_eq!(self.size, self.calc_num_nodes());
    }

    /// Removes every node.
    pub fn clear(&mut self) {
        self.arena = None;
        self.forget_trunks();
        self.size = 0;
    }

    // ----- updates -------------------------------------------------------

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
            if created {
                changes.insert(key, true);
            } else if self.sensor.is_occupied(before) != self.sensor.is_occupied(after) {
                match changes.get(&key) {
                    None => {
                        changes.insert(key, false);
                    }
                    Some(false) => {
                        changes.remove(&key);
                    }
                    Some(true) => {}
                }
            }
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
    pub fn update_batch(&mut self, codes: &[u64], delta: f32, inner: InnerNodes) {
        self.update_batch_split(codes, delta, inner, 1, &|| {});
    }

    /// [`Self::update_batch`] with the work shared by the threads of the
    /// current rayon pool, split in `2 * workers` parts, when the batch has
    /// 262,144 codes or more and no changes are being recorded. The tree is
    /// the one [`Self::update_batch`] gives.
    pub fn update_batch_shared(&mut self, codes: &[u64], delta: f32, inner: InnerNodes, workers: usize) {
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
        let mut batch = Batch {
            arena: self.arena.as_mut().expect("root exists"),
            rules,
            sensor: self.sensor,
            delta,
            lazy: inner == InnerNodes::Defer,
            size: self.size as isize,
            changes: self.changes.as_mut(),
            split: None,
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
            for i in 0..a.mask(n).count_ones() {
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

    /// Merges complete groups of eight equal leaf children into their
    /// parent, level by level from depth 15 up, stopping at the first level
    /// where nothing merged (OctoMap's `prune`, including that early stop).
    pub fn prune(&mut self) {
        /// What a node would be after level-by-level pruning of every level
        /// below it: `Some((value, extra))` when it is or would become a
        /// leaf. Counts the merges per depth.
        fn would_merge(
            a: &NodeArena,
            n: NodeId,
            depth: u8,
            rules: Rules,
            counts: &mut [usize; 16],
        ) -> Option<(f32, u32)> {
            let mask = a.mask(n);
            if mask == 0 {
                return Some((a.value(n), a.extra(n)));
            }
            let first = a.first_child(n);
            let mut all = mask == 0xff;
            let mut first_leaf = None;
            for i in 0..mask.count_ones() {
                match would_merge(a, first + i, depth + 1, rules, counts) {
                    None => all = false,
                    Some((v, e)) => match first_leaf {
                        None => first_leaf = Some((v, e)),
                        Some((v0, e0)) => {
                            if v != v0 || (rules.kind == NodeKind::Stamped && e != e0) {
                                all = false;
                            }
                        }
                    },
                }
            }
            if all && depth >= 1 {
                counts[depth as usize] += 1;
                first_leaf
            } else {
                None
            }
        }
        fn merge_below(a: &mut NodeArena, n: NodeId, depth: u8, lowest: u8, rules: Rules, pruned: &mut usize) {
            let first = a.first_child(n);
            for i in 0..a.mask(n).count_ones() {
                merge_below(a, first + i, depth + 1, lowest, rules, pruned);
            }
            if depth >= lowest && prune_node(a, n, rules).is_some() {
                *pruned += 1;
            }
        }
        let rules = self.rules();
        let Some(a) = self.arena_mut() else { return };
        // OctoMap prunes level by level from depth 15 up and stops after the
        // first level that merged nothing; find that level first, then merge
        // everything below it in one bottom-up pass
        let mut counts = [0usize; 16];
        would_merge(a, ROOT, 0, rules, &mut counts);
        let stop = (1..TREE_DEPTH).rev().find(|&d| counts[d as usize] == 0).unwrap_or(0);
        let mut pruned = 0;
        merge_below(a, ROOT, 0, stop.max(1), rules, &mut pruned);
        self.size -= 8 * pruned;
        self.refresh_trunks();
    }

    /// Gives every leaf above depth 16 eight children holding its value
    /// (`expand`).
    pub fn expand(&mut self) {
        fn recurse(a: &mut NodeArena, n: NodeId, depth: u8, added: &mut usize) {
            if depth >= TREE_DEPTH {
                return;
            }
            if !a.has_children(n) {
                a.expand_node(n, depth);
                *added += 8;
            }
            let first = a.first_child(n);
            for i in 0..a.mask(n).count_ones() {
                recurse(a, first + i, depth + 1, added);
            }
        }
        let mut added = 0;
        if let Some(a) = self.arena_mut() {
            recurse(a, ROOT, 0, &mut added);
        }
        self.size += added;
        self.refresh_trunks();
    }

    /// Deletes the node at `depth` (0 or 16 = a voxel) containing `key`,
    /// with OctoMap's `deleteNode` semantics: pruned nodes on the way are
    /// expanded, a parent losing its last child is deleted too, and the
    /// return value is `true` only when the root is left without children
    /// (or the tree was empty).
    pub fn delete(&mut self, key: Key, depth: u8) -> bool {
        fn recurse(t: &mut OccupancyTree, n: NodeId, depth: u8, max_depth: u8, key: Key, rules: Rules) -> bool {
            if depth >= max_depth {
                return true;
            }
            let a = t.arena.as_mut().expect("root exists");
            let pos = key.child_index(depth);
            if a.child(n, pos).is_none() {
                if !a.has_children(n) && n != ROOT {
                    a.expand_node(n, depth);
                    t.size += 8;
                } else {
                    return false;
                }
            }
            let child = a.child(n, pos).expect("exists or expanded");
            if recurse(t, child, depth + 1, max_depth, key, rules) {
                let a = t.arena.as_mut().expect("root exists");
                a.remove_child(n, pos);
                t.size -= 1;
                if !a.has_children(n) {
                    return true;
                }
                update_from_children(a, n, rules);
            }
            false
        }
        if self.arena.is_none() {
            return true;
        }
        let max_depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
        let rules = self.rules();
        self.forget_trunks();
        recurse(self, ROOT, 0, max_depth, key, rules)
    }

    /// [`Self::delete`] at the voxel containing `p`.
    pub fn delete_point(&mut self, p: Point3, depth: u8) -> Result<bool, KeyError> {
        let key = self.keys.key(p)?;
        Ok(self.delete(key, depth))
    }

    // ----- queries -------------------------------------------------------

    /// OctoMap's `search(key, depth)`: the node at `depth` (0 means 16)
    /// containing `key`, or the deepest existing leaf above it. `None`
    /// when the path ends at an inner node lacking the needed child.
    #[inline(always)]
    pub fn search(&self, key: Key, depth: u8) -> Option<Found> {
        self.search_in(key, key.child_index(0), depth)
    }

    /// [`Self::search`] given the key's root child (its child index at
    /// depth 1).
    #[inline(always)]
    fn search_in(&self, key: Key, octant: usize, depth: u8) -> Option<Found> {
        let a = self.arena.as_ref()?;
        if depth == 0 || depth >= TREE_DEPTH {
            if let Some(index) = self.levels.get(a, self.size) {
                return self.answer(a, key, index.search_in(key, octant, MortonCode::encode_table(key).0));
            }
            return self.search_full(a, key, octant);
        }
        self.search_arena(key, depth)
    }

    /// [`Self::search`] at depth 16 in the arena, with as few instructions
    /// as it takes: on a map that fits the caches, the processor overlaps
    /// consecutive queries as far as its window of instructions reaches.
    #[inline(always)]
    fn search_full(&self, a: &NodeArena, key: Key, octant: usize) -> Option<Found> {
        let (masks, first_child) = (a.masks(), a.first_child_ids());
        let child = |n: NodeId, pos: u64| -> Result<NodeId, u8> {
            let m = masks[n as usize];
            if m & (1 << pos) == 0 {
                Err(m)
            } else {
                Ok(first_child[n as usize] + (u32::from(m) & ((1 << pos) - 1)).count_ones())
            }
        };
        let k = key.packed();
        let (mut node, from) = self.trunks.start_in(
            k,
            octant,
            TREE_DEPTH,
            |n| Some(masks[n as usize]),
            |n, _, pos| child(n, pos as u64).ok(),
        );
        // the child positions from depth `from` on, the next one on top
        let mut positions = if from >= 8 {
            (MortonCode::low_levels(k) << 40) << (3 * u32::from(from - 8))
        } else {
            (MortonCode::encode_table(key).0 << 16) << (3 * u32::from(from))
        };
        for d in from..TREE_DEPTH {
            match child(node, positions >> 61) {
                Ok(c) => node = c,
                Err(0) => return Some(Found { value: a.value(node), depth: d, is_leaf: true, extra: a.extra(node) }),
                Err(_) => return None,
            }
            positions <<= 3;
        }
        Some(Found { value: a.leaf_value(node), depth: TREE_DEPTH, is_leaf: true, extra: a.leaf_extra(node) })
    }

    /// The full-depth answer for `key` from where the level index got.
    #[inline(always)]
    fn answer(&self, a: &NodeArena, key: Key, reach: Reach) -> Option<Found> {
        let voxel = |value, extra| Some(Found { value, depth: TREE_DEPTH, is_leaf: true, extra });
        match reach {
            Reach::Voxel(id) => voxel(a.value(id), a.extra(id)),
            Reach::Value(value) => voxel(value, 0),
            Reach::Unknown => None,
            Reach::Coarse => self.search_arena(key, 0),
        }
    }

    /// Builds now what searches otherwise build at the first one after a
    /// bulk change: the grids below the trunks and, on trees of 2^19 nodes
    /// or more, the level index (about two leaf walks). For callers
    /// whose first query must not wait; answers do not change. Does nothing
    /// while the tree is changing (after a change other than a bulk one).
    pub fn prepare_search(&self) {
        if let Some(a) = &self.arena {
            let p = a.parts();
            self.trunks.prepare(|n| Some(p.mask(n)), |n, _, pos| p.descend(n, pos as u64).ok());
            self.levels.get(a, self.size);
        }
    }

    /// Whether full-depth searches go through the level index.
    pub(crate) fn levels_armed(&self) -> bool {
        self.levels.is_armed()
    }

    /// [`Self::search`] in the arena alone: for changes, which would drop
    /// the index they built.
    #[inline(always)]
    fn search_arena(&self, key: Key, depth: u8) -> Option<Found> {
        let a = self.arena.as_ref()?;
        let (id, depth, is_leaf) = self.search_id(key, depth)?;
        Some(Found { value: a.value(id), depth, is_leaf, extra: a.extra(id) })
    }

    /// [`Self::search`] giving the node id (valid until the next change).
    #[inline(always)]
    fn search_id(&self, key: Key, depth: u8) -> Option<(NodeId, u8, bool)> {
        let a = self.arena.as_ref()?;
        let (key, depth) = search_target(key, depth);
        // the table encoding: the code is on the query's chain of dependent
        // steps, and the table is faster than shifts and masks
        // (`docs/benchmarks.md`, "Criterion micro-benchmarks")
        let code = MortonCode::encode_table(key).0;
        let p = a.parts();
        let (node, from) = self.start(&p, key, depth);
        descend_to(&p, node, from, depth, code)
    }

    /// [`Self::search`] for many keys at once, answers in `out` (cleared
    /// first) in the order of `keys`. Eight descents advance in lockstep, so
    /// the cache misses of one overlap those of the others: for random
    /// queries this is several times the throughput of one `search` after
    /// another.
    pub fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>) {
        const LANES: usize = 8;
        out.clear();
        let Some(a) = self.arena.as_ref() else {
            out.resize(keys.len(), None);
            return;
        };
        let depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
        let p = a.parts();
        if let Some(index) = self.levels.get(a, self.size).filter(|_| depth == TREE_DEPTH) {
            let mut reach = [Reach::Unknown; level_index::LANES];
            for chunk in keys.chunks(level_index::LANES) {
                index.search_lanes(chunk, &mut reach);
                out.extend(chunk.iter().zip(&reach).map(|(&key, &r)| self.answer(a, key, r)));
            }
            return;
        }
        for chunk in keys.chunks(LANES) {
            let mut code = [0u64; LANES];
            let mut key = [Key::ROOT; LANES];
            for ((c, k), q) in code.iter_mut().zip(&mut key).zip(chunk) {
                *k = if depth == TREE_DEPTH { *q } else { adjust_key_to_depth(*q, depth) };
                *c = MortonCode::encode_table(*k).0;
            }
            // each lane starts at its trunk end: lanes join the walk at
            // that depth; those starting at `depth` itself have arrived
            let mut node = [ROOT; LANES];
            let mut joins = [0u32; TREE_DEPTH as usize + 1];
            for l in 0..chunk.len() {
                let (n, from) = self.start(&p, key[l], depth);
                node[l] = n;
                joins[from as usize] |= 1 << l;
            }
            let mut found: [Option<(NodeId, u8, bool)>; LANES] = [None; LANES];
            let mut walking = 0u32;
            let mut waiting = ((1u32 << chunk.len()) - 1) & !joins[depth as usize];
            for d in 0..depth {
                walking |= joins[d as usize];
                waiting &= !joins[d as usize];
                let shift = 3 * (TREE_DEPTH - 1 - d);
                let mut lanes = walking;
                while lanes != 0 {
                    let l = lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    match p.descend(node[l], (code[l] >> shift) & 7) {
                        Ok(c) => node[l] = c,
                        Err(m) => {
                            walking &= !(1 << l);
                            if m == 0 {
                                found[l] = Some((node[l], d, true));
                            }
                        }
                    }
                }
                if walking | waiting == 0 {
                    break;
                }
            }
            walking |= joins[depth as usize];
            while walking != 0 {
                let l = walking.trailing_zeros() as usize;
                walking &= walking - 1;
                found[l] = Some((node[l], depth, !a.has_children(node[l])));
            }
            out.extend(found[..chunk.len()].iter().map(|f| {
                f.map(|(id, depth, is_leaf)| Found { value: a.value(id), depth, is_leaf, extra: a.extra(id) })
            }));
        }
    }

    /// [`Self::search`] at the voxel containing `p`.
    #[inline]
    pub fn search_point(&self, p: Point3, depth: u8) -> Result<Option<Found>, KeyError> {
        let (key, octant) = self.keys.key_and_octant(p)?;
        Ok(self.search_in(key, octant, depth))
    }

    // ----- colour trees (`ColorOcTree`) -------------------------------------

    /// Applies `f` to the colour of the node holding `key` (OctoMap's
    /// colour setters act on whatever `search` finds, a pruned coarse leaf
    /// included); returns the new colour, `None` when nothing was found.
    fn with_color(&mut self, key: Key, f: impl FnOnce(Option<[u8; 3]>, f32) -> [u8; 3]) -> Option<[u8; 3]> {
        if self.kind != NodeKind::Color {
            return None;
        }
        let (id, _, _) = self.search_id(key, 0)?;
        let a = self.arena_mut()?;
        let e = a.extra(id);
        let current = (e != WHITE).then(|| unpack_rgb(e));
        let rgb = f(current, a.value(id));
        a.set_extra(id, pack_rgb(rgb));
        Some(rgb)
    }

    /// `setNodeColor`.
    pub fn set_color(&mut self, key: Key, rgb: [u8; 3]) -> Option<[u8; 3]> {
        self.with_color(key, |_, _| rgb)
    }

    /// `averageNodeColor`: the mean of the old colour and `rgb`.
    pub fn average_color(&mut self, key: Key, rgb: [u8; 3]) -> Option<[u8; 3]> {
        self.with_color(key, |old, _| match old {
            Some(o) => [0, 1, 2].map(|i| ((u32::from(o[i]) + u32::from(rgb[i])) / 2) as u8),
            None => rgb,
        })
    }

    /// `integrateNodeColor`: the old colour weighted by the node's
    /// occupancy probability, the new one by `0.99 - p`.
    pub fn integrate_color(&mut self, key: Key, rgb: [u8; 3]) -> Option<[u8; 3]> {
        self.with_color(key, |old, value| match old {
            Some(o) => {
                let p = crate::sensor::probability(f64::from(value));
                [0, 1, 2].map(|i| (f64::from(o[i]) * p + f64::from(rgb[i]) * (0.99 - p)) as u8)
            }
            None => rgb,
        })
    }

    /// The same tree with nodes of another kind (e.g. a colour map as plain
    /// occupancy, which OctoMap cannot do): values and structure are kept,
    /// colours or stamps dropped, new extras start at the kind's default.
    pub fn converted(&self, kind: NodeKind) -> OccupancyTree {
        let mut b = PreorderBuilder::with_hint(kind, self.size);
        b.reserve(self.size);
        let keep = kind == self.kind;
        if let Some(root) = self.root() {
            let mut stack = vec![root];
            let mut index = 0;
            while let Some(n) = stack.pop() {
                let extra = keep.then(|| n.extra());
                b.push_with_extra(n.value(), extra, n.child_mask(), index).expect("a valid tree is at most 16 deep");
                index += 1;
                for rank in (0..n.child_count()).rev() {
                    stack.extend(n.nth_child(rank));
                }
            }
        }
        let mut t = b.finish(self.resolution(), self.sensor).expect("valid resolution").expect("complete");
        t.clock = self.clock;
        t
    }

    // ----- stamped trees (`OcTreeStamped`) -----------------------------------

    /// `getLastUpdateTime`: the root's stamp.
    pub fn last_update_time(&self) -> Option<u32> {
        if self.kind != NodeKind::Stamped {
            return None;
        }
        self.arena.as_ref().map(|a| a.extra(ROOT))
    }

    /// `degradeOutdatedNodes`: every occupied leaf whose stamp is more than
    /// `max_age` seconds old gets a miss (without a new stamp). Inner nodes
    /// are left as they are, as in OctoMap.
    pub fn degrade_outdated_nodes(&mut self, max_age: u32) {
        if self.kind != NodeKind::Stamped {
            return;
        }
        let now = self.clock.now();
        let sensor = self.sensor;
        let Some(a) = self.arena_mut() else { return };
        let mut stack = vec![ROOT];
        while let Some(n) = stack.pop() {
            if a.has_children(n) {
                let first = a.first_child(n);
                stack.extend((0..a.mask(n).count_ones()).map(|i| first + i));
            } else {
                let v = a.value(n);
                if sensor.is_occupied(v) && now.wrapping_sub(a.extra(n)) > max_age {
                    a.set_value(n, sensor.apply(v, sensor.miss));
                }
            }
        }
        self.refresh_trunks();
    }

    /// A cursor on the root, `None` for an empty tree.
    pub fn root(&self) -> Option<NodeRef<'_>> {
        self.arena.as_ref().map(|arena| NodeRef { arena, id: ROOT })
    }

    /// The value of the root (OctoMap keeps it as the max of everything).
    pub fn root_value(&self) -> Option<f32> {
        self.arena.as_ref().map(|a| a.value(ROOT))
    }

    /// Whether a log-odds value counts as occupied under this tree's
    /// sensor model (`isNodeOccupied`).
    pub fn is_occupied(&self, value: f32) -> bool {
        self.sensor.is_occupied(value)
    }

    /// Every node, depth first with children 0..7 (`begin_tree(max_depth)`);
    /// `max_depth` 0 means 16.
    pub fn nodes(&self, max_depth: u8) -> NodeIter<'_> {
        NodeIter::new(self, max_depth, false, None)
    }

    /// Every leaf (and every node at `max_depth`), in OctoMap's order.
    pub fn leaves(&self, max_depth: u8) -> NodeIter<'_> {
        NodeIter::new(self, max_depth, true, None)
    }

    /// Leaves overlapping the key box, as OctoMap's `leaf_bbx_iterator`.
    pub fn leaves_in_box(&self, bbx: KeyBox, max_depth: u8) -> NodeIter<'_> {
        NodeIter::new(self, max_depth, true, Some(bbx))
    }

    /// Number of leaves (`getNumLeafNodes`).
    pub fn num_leaves(&self) -> usize {
        self.arena.as_ref().map_or(0, |a| count_leaves(a, ROOT))
    }

    /// Number of nodes reachable from the root (`calcNumNodes`).
    pub fn calc_num_nodes(&self) -> usize {
        fn count(a: &NodeArena, n: NodeId) -> usize {
            let first = a.first_child(n);
            1 + (0..a.mask(n).count_ones()).map(|i| count(a, first + i)).sum::<usize>()
        }
        self.arena.as_ref().map_or(0, |a| count(a, ROOT))
    }

    /// Metric bounds of all leaves (zero for an empty tree).
    pub fn bounds(&self, rule: BoundsRule) -> Bounds {
        if self.arena.is_none() {
            return Bounds { min: [0.0; 3], max: [0.0; 3] };
        }
        let mut b = Bounds { min: [f64::MAX; 3], max: [-f64::MAX; 3] };
        for leaf in self.leaves(0) {
            let size = self.keys.node_size(leaf.depth);
            let half = size / 2.0;
            for axis in 0..3 {
                let c = self.keys.key_to_coord_at_depth(leaf.key.0[axis], leaf.depth);
                let lo = c - half;
                let hi = match rule {
                    BoundsRule::CenterHalfSize => c + half,
                    BoundsRule::MinPlusSize => lo + size,
                };
                if lo < b.min[axis] {
                    b.min[axis] = lo;
                }
                if hi > b.max[axis] {
                    b.max[axis] = hi;
                }
            }
        }
        b
    }

    /// OctoMap's `volume()`: product of the (non-const) metric sizes.
    pub fn volume(&self) -> f64 {
        let s = self.bounds(BoundsRule::MinPlusSize).size();
        s[0] * s[1] * s[2]
    }

    /// OctoMap's `memoryFullGrid()`: bytes of a dense float grid over the
    /// bounds (OctoMap uses its const bounds, [`BoundsRule::CenterHalfSize`],
    /// unless its extent cache is filled).
    pub fn memory_full_grid(&self, rule: BoundsRule) -> u64 {
        if self.arena.is_none() {
            return 0;
        }
        let s = self.bounds(rule).size();
        let r = self.resolution();
        ((s[0] / r) * (s[1] / r) * (s[2] / r) * 4.0) as u64
    }

    /// What OctoMap's `memoryUsage()` reports for this tree on x86-64.
    pub fn octomap_memory_usage(&self) -> usize {
        let leaves = self.num_leaves();
        let inner = self.size.saturating_sub(leaves);
        OCTOMAP_TREE_OBJECT_BYTES + 16 * self.size + 64 * inner
    }

    /// Bytes this tree really holds: the arena's reserved capacity plus
    /// the tree object and change-detection map.
    pub fn memory_usage(&self) -> usize {
        let arena = self.arena.as_ref().map_or(0, |a| a.usage().bytes_reserved);
        let changes = self.changes.as_ref().map_or(0, |c| c.capacity() * (std::mem::size_of::<(Key, bool)>() + 1));
        std::mem::size_of::<Self>() + arena + changes + self.trunks.bytes() + self.levels.bytes()
    }

    /// Slot statistics of the arena.
    pub fn arena_usage(&self) -> Option<ArenaUsage> {
        self.arena.as_ref().map(|a| a.usage())
    }

    /// When the arena is compacted without being asked.
    pub fn set_compaction(&mut self, compaction: Compaction) {
        self.compaction = compaction;
    }

    /// The depth-13 subtrees as search-block runs for a mapped file (see
    /// `level_index::subtree_runs`), for a tree with `min_nodes` or more
    /// nodes at depths 13–15.
    pub(crate) fn subtree_runs(&self, min_nodes: usize) -> Option<blocks::SubtreeRuns> {
        level_index::subtree_runs(&self.arena.as_ref()?.parts(), min_nodes)
    }

    /// Re-lays the arena in depth-first (Morton) order with no free slots,
    /// so traversals walk memory forwards and no capacity is wasted.
    pub fn compact(&mut self) {
        if let Some(a) = self.arena_mut() {
            a.compact_in_place(ROOT);
        }
        self.refresh_trunks();
    }

    // ----- change detection ----------------------------------------------

    /// Starts (or stops) recording which voxels changed occupancy.
    pub fn set_change_detection(&mut self, enabled: bool) {
        if enabled {
            self.changes.get_or_insert_with(HashMap::new);
        } else {
            self.changes = None;
        }
    }

    /// Keys changed since the last reset: `true` for newly created voxels,
    /// `false` for existing voxels whose occupancy state flipped. Sorted.
    pub fn changed_keys(&self) -> Vec<(Key, bool)> {
        let mut v: Vec<_> = self.changes.iter().flat_map(|c| c.iter().map(|(k, b)| (*k, *b))).collect();
        v.sort_unstable();
        v
    }

    /// Forgets the changed keys recorded so far (`resetChangeDetection`).
    pub fn reset_change_detection(&mut self) {
        if let Some(c) = self.changes.as_mut() {
            c.clear();
        }
    }
}

/// State of one [`OccupancyTree::update_batch`] walk, over the arena or,
/// in a parallel update, over one worker's share of it.
struct Batch<'a, S: NodeStore> {
    arena: &'a mut S,
    rules: Rules,
    sensor: SensorModel,
    delta: f32,
    lazy: bool,
    size: isize,
    changes: Option<&'a mut HashMap<Key, bool>>,
    /// Where the walk stops short for a parallel update
    /// ([`parallel::Split`]); `None` for a whole walk.
    split: Option<&'a mut parallel::Split>,
}

impl<S: NodeStore> Batch<'_, S> {
    /// Applies `codes` (all below `n`, which sits at `depth`) to the
    /// subtree; returns whether any voxel was updated. Like `updateNode`,
    /// whose early exit on a saturated voxel leaves the path above it alone,
    /// a node is updated and pruned only when something below it changed
    /// (which matters when earlier lazy updates left inner nodes stale).
    fn apply(&mut self, n: NodeId, depth: u8, codes: &[u64], created: bool) -> bool {
        if depth == TREE_DEPTH {
            return self.apply_leaf(n, codes[0], created);
        }
        if let Some(split) = self.split.as_deref_mut() {
            if split.is_task(depth, codes.len()) {
                return split.visit(n, depth, codes, created);
            }
        }
        // where each child's codes start: codes are sorted and share the
        // prefix above this node, so the child index is monotone in them
        let shift = 3 * (15 - u32::from(depth));
        let child_of = |c: u64| ((c >> shift) & 7) as usize;
        let mut bounds = [codes.len(); 9];
        let mut needed = 0u8;
        if depth == TREE_DEPTH - 1 {
            // children are voxels, one code each: no ranges needed
            for &c in codes {
                needed |= 1 << (c & 7);
            }
        } else {
            if codes.len() <= 64 {
                // a linear pass: stores only, no mispredicted search branches
                for (i, &c) in codes.iter().enumerate().rev() {
                    bounds[child_of(c)] = i;
                }
                for pos in (0..8).rev() {
                    bounds[pos] = bounds[pos].min(bounds[pos + 1]);
                }
            } else {
                // each child's range ends where the next begins: gallop
                // forwards from its start (the memory just read) instead of
                // binary searches over the whole list
                let n = codes.len();
                let mut start = 0;
                for (pos, b) in bounds.iter_mut().enumerate().take(8) {
                    *b = start;
                    if start == n || child_of(codes[start]) != pos {
                        continue;
                    }
                    let (mut last, mut step) = (start, 1);
                    while last + step < n && child_of(codes[last + step]) == pos {
                        last += step;
                        step *= 2;
                    }
                    let limit = (last + step).min(n);
                    start = last + 1 + codes[last + 1..limit].partition_point(|&c| child_of(c) == pos);
                }
            }
            for pos in 0..8 {
                needed |= u8::from(bounds[pos] < bounds[pos + 1]) << pos;
            }
        }
        let a = &mut *self.arena;
        let mask = a.mask(n);
        let mut new_children = 0u8;
        if mask == 0 && !created {
            // a pruned leaf: unchanged when the update saturates, else expanded
            if self.sensor.is_saturated(a.value(n), self.delta) {
                return false;
            }
            a.expand_node(n, depth);
            self.size += 8;
        } else {
            new_children = needed & !mask;
            if new_children != 0 {
                a.add_missing_children(n, new_children, 0.0, depth);
                self.size += new_children.count_ones() as isize;
            }
        }
        let (first, mask) = (a.first_child(n), a.mask(n));
        let mut changed = false;
        if depth == TREE_DEPTH - 1 {
            for &c in codes {
                let pos = (c & 7) as u32;
                let child = first + (u32::from(mask) & ((1 << pos) - 1)).count_ones();
                changed |= self.apply_leaf(child, c, new_children & (1 << pos) != 0);
            }
        } else {
            let mut rest = needed;
            while rest != 0 {
                let pos = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                let child = first + (mask & ((1u8 << pos) - 1)).count_ones();
                let range = &codes[bounds[pos]..bounds[pos + 1]];
                changed |= self.apply(child, depth + 1, range, new_children & (1 << pos) != 0);
            }
        }
        if changed && !self.lazy {
            if self.rules.kind == NodeKind::Plain {
                if prune_or_update_plain(&mut *self.arena, n) {
                    self.size -= 8;
                }
            } else if prune_node(&mut *self.arena, n, self.rules).is_some() {
                self.size -= 8;
            } else {
                update_from_children(&mut *self.arena, n, self.rules);
            }
        }
        changed
    }

    #[inline]
    fn apply_leaf(&mut self, n: NodeId, code: u64, created: bool) -> bool {
        let before = self.arena.value(n);
        if !created && self.sensor.is_saturated(before, self.delta) {
            return false;
        }
        let after = self.sensor.apply(before, self.delta);
        self.arena.set_value(n, after);
        if self.rules.kind == NodeKind::Stamped {
            self.arena.set_extra(n, self.rules.now);
        }
        if let Some(changes) = self.changes.as_deref_mut() {
            let key = crate::morton::MortonCode(code).decode();
            if created {
                changes.insert(key, true);
            } else if self.sensor.is_occupied(before) != self.sensor.is_occupied(after) {
                match changes.get(&key) {
                    None => {
                        changes.insert(key, false);
                    }
                    Some(false) => {
                        changes.remove(&key);
                    }
                    Some(true) => {}
                }
            }
        }
        true
    }
}

/// A read-only cursor on a node, for structural walks (writers of other
/// formats, comparisons). Valid while the tree is borrowed.
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    arena: &'a NodeArena,
    id: NodeId,
}

impl<'a> NodeRef<'a> {
    /// The arena and id of this node, for whole-tree passes.
    pub(crate) fn arena_id(&self) -> (&'a NodeArena, NodeId) {
        (self.arena, self.id)
    }

    /// The log-odds value.
    #[inline]
    pub fn value(&self) -> f32 {
        self.arena.value(self.id)
    }

    /// Colour or stamp, by the tree's [`NodeKind`] (0 for plain trees).
    #[inline]
    pub fn extra(&self) -> u32 {
        self.arena.extra(self.id)
    }

    /// Bit `i` set when child `i` exists.
    #[inline]
    pub fn child_mask(&self) -> u8 {
        self.arena.mask(self.id)
    }

    /// True when the node has at least one child.
    #[inline]
    pub fn has_children(&self) -> bool {
        self.arena.has_children(self.id)
    }

    /// Child `pos` (0..8, x = 1, y = 2, z = 4), if it exists.
    #[inline]
    pub fn child(&self, pos: usize) -> Option<NodeRef<'a>> {
        self.arena.child(self.id, pos).map(|id| NodeRef { arena: self.arena, id })
    }

    /// Number of existing children.
    #[inline]
    pub fn child_count(&self) -> u32 {
        self.arena.mask(self.id).count_ones()
    }

    /// The `rank`-th existing child (0-based, in child order).
    #[inline]
    pub fn nth_child(&self, rank: u32) -> Option<NodeRef<'a>> {
        (rank < self.child_count()).then(|| NodeRef { arena: self.arena, id: self.arena.first_child(self.id) + rank })
    }

    /// Existing children with their index, in child order.
    pub fn children(&self) -> impl Iterator<Item = (usize, NodeRef<'a>)> + 'a {
        let arena = self.arena;
        arena.children(self.id).map(move |(i, id)| (i, NodeRef { arena, id }))
    }
}

/// Builds a tree from nodes given in depth-first pre-order (children
/// 0..7), each as its value and child mask: how `.ot`-like streams and the
/// mapped format are turned back into a tree. The arena comes out in
/// depth-first order with no free slots.
pub struct PreorderBuilder {
    kind: NodeKind,
    fill: PreorderFill,
}

/// A node below depth 16 was announced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("node {index} in pre-order lies below depth 16")]
pub struct TooDeep {
    /// The `index` given with the offending node.
    pub index: u64,
}

impl PreorderBuilder {
    /// A builder for a plain tree.
    pub fn new() -> Self {
        Self::with_kind(NodeKind::Plain)
    }

    /// A builder for a tree of `kind`; give extras with [`Self::push_with_extra`].
    pub fn with_kind(kind: NodeKind) -> Self {
        PreorderBuilder { kind, fill: PreorderFill::new(default_extra(kind), 0) }
    }

    /// A builder that expects about `nodes` nodes. The hint need not be
    /// right nor trusted: memory grows toward it only as nodes arrive.
    pub(crate) fn with_hint(kind: NodeKind, nodes: usize) -> Self {
        PreorderBuilder { kind, fill: PreorderFill::new(default_extra(kind), nodes) }
    }

    /// Reserves room for `n` more nodes at once.
    pub(crate) fn reserve(&mut self, n: usize) {
        self.fill.reserve(n);
    }

    /// True once the root and every announced node have been given.
    #[inline(always)]
    pub fn is_complete(&self) -> bool {
        self.fill.is_complete()
    }

    /// Depth of the next node to give (0 for the root); `None` when complete.
    pub fn next_depth(&self) -> Option<u8> {
        self.fill.next_depth()
    }

    /// Gives the next node. `index` only labels errors.
    pub fn push(&mut self, value: f32, mask: u8, index: u64) -> Result<(), TooDeep> {
        self.push_with_extra(value, None, mask, index)
    }

    /// Gives the next node with its colour or stamp (`None` keeps the
    /// kind's default).
    #[inline(always)]
    pub fn push_with_extra(&mut self, value: f32, extra: Option<u32>, mask: u8, index: u64) -> Result<(), TooDeep> {
        self.fill.push(value, extra, mask).map_err(|_| TooDeep { index })
    }

    /// The finished arena (root at 0); `None` when nodes are still missing.
    pub(crate) fn finish_arena(self) -> Option<Option<NodeArena>> {
        if self.fill.len() == 0 {
            return Some(None);
        }
        self.fill.finish().map(Some)
    }

    /// The finished tree; `None` when nodes are still missing.
    pub fn finish(self, resolution: f64, sensor: SensorModel) -> Result<Option<OccupancyTree>, TreeError> {
        let mut tree = OccupancyTree::with_kind(resolution, sensor, self.kind)?;
        let Some(arena) = self.finish_arena() else {
            return Ok(None);
        };
        if let Some(a) = arena {
            tree.set_arena_with_size(a);
        }
        Ok(Some(tree))
    }
}

impl Default for PreorderBuilder {
    fn default() -> Self {
        Self::new()
    }
}

/// The extra a new node of `kind` starts with; `None` for plain trees.
pub(crate) fn default_extra(kind: NodeKind) -> Option<u32> {
    match kind {
        NodeKind::Plain => None,
        NodeKind::Color => Some(WHITE),
        NodeKind::Stamped => Some(0),
    }
}

/// `getMaxChildLogOdds`.
#[inline]
fn max_child_value<S: NodeStore>(a: &S, n: NodeId) -> f32 {
    let first = a.first_child(n);
    let mut max = -f32::MAX;
    for i in 0..a.mask(n).count_ones() {
        let v = a.value(first + i);
        if v > max {
            max = v;
        }
    }
    max
}

/// `pruneNode`: merges eight equal childless children into `n` (which
/// takes child 0's data); returns the value. Stamped trees also need equal
/// stamps; colour trees ignore colours and give the merged node the average.
#[inline]
fn prune_node<S: NodeStore>(a: &mut S, n: NodeId, rules: Rules) -> Option<f32> {
    if a.mask(n) != 0xff {
        return None;
    }
    let first = a.first_child(n);
    let v = a.value(first);
    let e = a.extra(first);
    for i in 0..8 {
        let c = first + i;
        if a.has_children(c) || a.value(c) != v {
            return None;
        }
        if rules.kind == NodeKind::Stamped && a.extra(c) != e {
            return None;
        }
    }
    let extra = if rules.kind == NodeKind::Color && e != WHITE { average_child_color(a, n) } else { e };
    a.remove_all_children(n);
    a.set_value(n, v);
    a.set_extra(n, extra);
    Some(v)
}

/// [`prune_node`], else [`update_from_children`], for plain trees in one
/// pass over the children; returns whether `n` was pruned.
#[inline]
fn prune_or_update_plain<S: NodeStore>(a: &mut S, n: NodeId) -> bool {
    let mask = a.mask(n);
    let first = a.first_child(n);
    let v0 = a.value(first);
    let mut max = -f32::MAX;
    let mut same = mask == 0xff;
    for i in 0..mask.count_ones() {
        let c = first + i;
        let v = a.value(c);
        if v > max {
            max = v;
        }
        same &= (v == v0) & !a.has_children(c);
    }
    if same {
        a.remove_all_children(n);
        a.set_value(n, v0);
    } else {
        a.set_value(n, max);
    }
    same
}

/// `updateOccupancyChildren`: the maximum of the children's values (and,
/// for stamped trees, the current time).
#[inline]
fn update_from_children<S: NodeStore>(a: &mut S, n: NodeId, rules: Rules) {
    let v = max_child_value(a, n);
    a.set_value(n, v);
    if rules.kind == NodeKind::Stamped {
        a.set_extra(n, rules.now);
    }
}

/// `getAverageChildColor`: integer mean over children whose colour is set,
/// white when none is.
fn average_child_color<S: NodeStore>(a: &S, n: NodeId) -> u32 {
    let (mut sum, mut count) = ([0u32; 3], 0u32);
    let first = a.first_child(n);
    for c in first..first + a.mask(n).count_ones() {
        let e = a.extra(c);
        if e != WHITE {
            let rgb = unpack_rgb(e);
            for k in 0..3 {
                sum[k] += u32::from(rgb[k]);
            }
            count += 1;
        }
    }
    if count == 0 {
        return WHITE;
    }
    pack_rgb([(sum[0] / count) as u8, (sum[1] / count) as u8, (sum[2] / count) as u8])
}

fn count_leaves(a: &NodeArena, n: NodeId) -> usize {
    if !a.has_children(n) {
        return 1;
    }
    let first = a.first_child(n);
    (0..a.mask(n).count_ones()).map(|i| count_leaves(a, first + i)).sum()
}

/// A search's key and depth as OctoMap's `search` takes them: depth 0 (or
/// above 16) means 16, and a coarser depth's key is its node's centre key.
#[inline(always)]
pub(crate) fn search_target(key: Key, depth: u8) -> (Key, u8) {
    let depth = if depth == 0 || depth > TREE_DEPTH { TREE_DEPTH } else { depth };
    (if depth == TREE_DEPTH { key } else { adjust_key_to_depth(key, depth) }, depth)
}

/// The rest of a search for the Morton `code` from `node`, which lies at
/// depth `from` on its path, down to `depth`: the node found, its depth
/// and whether it is a leaf; `None` when the path ends at an inner node
/// lacking the needed child (unknown space).
#[inline(always)]
fn descend_to(p: &Parts<'_>, mut node: NodeId, from: u8, depth: u8, code: u64) -> Option<(NodeId, u8, bool)> {
    for d in from..depth {
        match p.descend(node, (code >> (3 * (TREE_DEPTH - 1 - d))) & 7) {
            Ok(c) => node = c,
            Err(m) => return (m == 0).then_some((node, d, true)),
        }
    }
    Some((node, depth, depth == TREE_DEPTH || p.masks[node as usize] == 0))
}
