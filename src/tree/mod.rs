//! The occupancy octree: OctoMap's `OcTree` semantics on a node arena.
//!
//! This file holds [`OccupancyTree`], its small types and its core
//! (construction, accessors, where searches start); its other methods are
//! grouped by concept in `update`, `structure`, `search`, `extras`,
//! `stats` and `changes`.

mod arena;
mod batch;
pub(crate) mod blocks;
mod changes;
mod counting;
mod cursor;
mod extras;
mod iter;
mod kind;
mod level_index;
mod parallel;
mod preorder;
mod rules;
mod search;
pub(crate) use search::LOCKSTEP_MIN_NODES;
mod search_index;
mod stats;
mod structure;
mod trunk;
mod update;

pub use arena::ArenaUsage;
pub(crate) use arena::LabelFill;
pub(crate) use arena::{leaf_index, prefetch_lines, Parts, WHOLE_PREFETCH_BYTES};
pub(crate) use arena::{NodeArena, NodeId};
use batch::Batch;
pub use counting::CountingTree;
pub(crate) use cursor::{ArenaPath, PathNodes, PathSearch};
pub(crate) use extras::default_extra;
pub use iter::{KeyBox, NodeItem, NodeIter};
pub use kind::{NodeKind, TreeKind};
use level_index::LevelSlot;
pub(crate) use parallel::MIN_CODES as PARALLEL_MIN_CODES;
pub use preorder::{ChildGroup, NodeRef, PreorderBuilder, PreorderNode, PreorderSource, PreorderVisitor, Tee, TooDeep};
use search::descend_to;
pub(crate) use search::search_target;
pub(crate) use search_index::LevelTables;
pub use search_index::SearchIndex;
pub(crate) use stats::{child_key, LeafExtremes};
pub use stats::{Summarize, TreeSummary};
pub(crate) use trunk::{Trunks, GRID_NODES_PER_CELL};

use crate::geometry::Point3;
use crate::key::{Key, KeyError, KeySpace};
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

/// Why a tree could not be made, or an operation was refused.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum TreeError {
    /// The resolution (the value given, metres) is outside the usable
    /// range ([`crate::key::check_resolution`]).
    #[error("{}", bad_resolution(.0))]
    BadResolution(f64),
    /// An operation whose output grows with the map's extent would make
    /// more than its limit: `count` items (nodes or points, as `what`
    /// says) against `limit` (by default [`OUTPUT_LIMIT`]).
    #[error("{what}: {count} {items} exceed the limit of {limit}{}; a higher limit allows it", power_of_two(*.limit))]
    TooLarge {
        /// The operation refused (`"expand"`, `"point extraction"`, ...).
        what: &'static str,
        /// What is counted (`"nodes"`, `"points"`, ...).
        items: &'static str,
        /// How many it would make (saturated at `u64::MAX`).
        count: u64,
        /// The limit it was given.
        limit: u64,
    },
}

/// The default limit of the operations whose output grows with the map's
/// extent rather than with its nodes ([`OccupancyTree::expand_within`],
/// [`OccupancyTree::voxels_within`]): 2^28 nodes or points. A leaf at depth
/// `d` stands for `8^(16 - d)` voxels, so a file of a few nodes can
/// describe a map whose expansion needs terabytes; 2^28 points of three
/// floats take 3 GB, 2^28 nodes up to 2.4 GB.
pub const OUTPUT_LIMIT: u64 = 1 << 28;

fn bad_resolution(value: &f64) -> KeyError {
    KeyError::BadResolution { value: *value }
}

/// " (2^k)" for a power of two `v`, else nothing.
fn power_of_two(v: u64) -> String {
    if v.is_power_of_two() {
        format!(" (2^{})", v.trailing_zeros())
    } else {
        String::new()
    }
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
    /// After a batch update (`OccupancyTree::update_batch`, so after each
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
        crate::key::check_resolution(resolution).map_err(|_| TreeError::BadResolution(resolution))?;
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
}
