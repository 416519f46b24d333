//! Layout ablation: the same OctoMap update rule on different node storage.
//!
//! [`Layout`] is the small storage interface the ablation harness drives;
//! everything else (keys, the sensor model, the scans' key lists, ray
//! stepping) is shared, so two layouts fed the same key lists build the same
//! tree and differ only in how nodes sit in memory:
//!
//! * [`pointer::PointerTree`]: the paper's layout (Hornung et al. 2013,
//!   Sect. 4): one heap node per voxel (`f32` value and a pointer to a
//!   lazily allocated array of eight child pointers): 16 B per node and 64 B
//!   per child array on x86-64. Exists to be measured.
//! * [`variants::ArenaLayout`]: octolinear's own [`OccupancyTree`] (nine
//!   bytes per node in three parallel arrays, child groups of exactly
//!   `popcount(mask)` slots), driven key by key or through the batch walk,
//!   optionally [`OccupancyTree::compact`]ed.
//! * [`variants::BlockTree`]: eight-slot blocks, one per inner node, either
//!   interleaved (`{f32, u32}` slots, 64-byte blocks) or split into a value
//!   array and a child-index array.
//!
//! Every layout applies OctoMap's `updateNode(key, delta)` exactly: the
//! early exit when the deepest existing node on the path is saturated, the
//! descent creating missing children (expanding a pruned leaf into eight
//! copies), add-and-clamp at depth 16, then bottom-up pruning of eight equal
//! leaf children or the maximum of the children. `tests/ablation.rs` checks
//! that all of them dump the same leaves as [`OccupancyTree`].
//!
//! The harness itself is `benches/ablation.rs` (`cargo bench -p
//! octolinear-ablation --bench ablation`), which writes `docs/ablation.md`.

pub mod alloc;
pub mod pointer;
pub mod report;
pub mod variants;

use octolinear::geometry::Point3;
use octolinear::key::{Key, KeySpace, TREE_DEPTH};
use octolinear::morton::MortonCode;
use octolinear::ray::RayKeys;
use octolinear::scan::{ScanError, ScanOptions};
use octolinear::sensor::SensorModel;
use octolinear::tree::OccupancyTree;

/// Node storage under test. Implementations mirror OctoMap's update rule;
/// they differ only in memory layout.
pub trait Layout {
    /// An empty map (`resolution` in metres) using `sensor` for updates.
    fn new(resolution: f64, sensor: SensorModel) -> Self
    where
        Self: Sized;

    /// OctoMap's `updateNode(key, delta, lazy_eval = false)`.
    fn apply_update(&mut self, key: Key, delta: f32, sensor: &SensorModel);

    /// One scan's updates: every free key gets a miss, then every occupied
    /// key a hit, each key once, in the given (Morton) order.
    fn apply_scan(&mut self, free: &[Key], occupied: &[Key], sensor: &SensorModel) {
        for &k in free {
            self.apply_update(k, sensor.miss, sensor);
        }
        for &k in occupied {
            self.apply_update(k, sensor.hit, sensor);
        }
    }

    /// Called once after the last scan (e.g. to compact); a no-op by default.
    fn finish(&mut self) {}

    /// OctoMap's `search(key)`: the value of the voxel, or of the pruned
    /// leaf above it; `None` for unknown space.
    fn search(&self, key: Key) -> Option<f32>;

    /// Every leaf as `(key, depth, value)`, depth first with children
    /// 0..7, keys as OctoMap's leaf iterator computes them.
    fn for_each_leaf<F: FnMut(Key, u8, f32)>(&self, f: F);

    /// Nodes in the tree (OctoMap's `size()`).
    fn node_count(&self) -> usize;

    /// Bytes the layout accounts for itself (capacities of its buffers, or
    /// the per-node sizes for the pointer layout): a formula, unlike the
    /// allocator's figures the harness measures.
    fn bytes_formula(&self) -> usize;

    /// Number of leaves.
    fn leaf_count(&self) -> usize {
        let mut n = 0;
        self.for_each_leaf(|_, _, _| n += 1);
        n
    }
}

/// The per-scan key lists every layout is driven with.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ScanKeys {
    /// Free voxels, Morton order.
    pub free: Vec<Key>,
    /// Occupied voxels, Morton order (disjoint from `free`).
    pub occupied: Vec<Key>,
}

impl ScanKeys {
    /// The keys OctoMap's `insertPointCloud` (default options) updates for
    /// one scan on a map of `tree`'s resolution.
    pub fn of_scan(tree: &OccupancyTree, points: &[Point3], origin: Point3) -> Result<ScanKeys, ScanError> {
        let (update, _) = tree.compute_update(points, origin, &ScanOptions::default())?;
        let (free, occupied) = update.sorted();
        Ok(ScanKeys { free, occupied })
    }

    /// The lists as Morton codes (for [`OccupancyTree::update_batch`]).
    pub fn codes(&self) -> (Vec<u64>, Vec<u64>) {
        let codes = |keys: &[Key]| keys.iter().map(|&k| MortonCode::encode(k).0).collect();
        (codes(&self.free), codes(&self.occupied))
    }

    pub fn len(&self) -> usize {
        self.free.len() + self.occupied.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Applies every scan in order, then [`Layout::finish`].
pub fn build<L: Layout>(resolution: f64, sensor: SensorModel, scans: &[ScanKeys]) -> L {
    let mut l = L::new(resolution, sensor);
    for s in scans {
        l.apply_scan(&s.free, &s.occupied, &sensor);
    }
    l.finish();
    l
}

/// A leaf as the comparison dumps it: key, depth and the value's bits.
pub type LeafRecord = (Key, u8, u32);

/// All leaves in iteration order.
pub fn leaf_dump<L: Layout>(l: &L) -> Vec<LeafRecord> {
    let mut v = Vec::new();
    l.for_each_leaf(|k, d, val| v.push((k, d, val.to_bits())));
    v
}

/// [`leaf_dump`] of an [`OccupancyTree`].
pub fn tree_leaf_dump(tree: &OccupancyTree) -> Vec<LeafRecord> {
    tree.leaves(0).map(|n| (n.key, n.depth, n.value.to_bits())).collect()
}

/// The paper's memory model (Sect. 4 / Eq. 8): inner nodes cost
/// `sizeof(node) + 8 * sizeof(pointer)`, leaves `sizeof(node)`, where a node
/// is a `float` and a pointer (padded): 40 B / 8 B with 32-bit pointers,
/// 80 B / 16 B with 64-bit pointers.
pub fn paper_bytes(inner: usize, leaves: usize, pointer_bytes: usize) -> usize {
    let node = if pointer_bytes == 4 { 8 } else { 16 };
    inner * (node + 8 * pointer_bytes) + leaves * node
}

/// A simplified `castRay` over any layout: steps the voxels from `origin`
/// along `direction` up to `max_range` (OctoMap's ray-key stepping) and
/// searches each. Returns the first occupied voxel, or `None` when the ray
/// leaves the range, leaves the map, or (unless `ignore_unknown`) meets
/// unknown space. Unlike OctoMap's `castRay` it does not look past
/// `max_range`; it is a workload for comparing layouts, not a replacement.
pub fn cast_ray<L: Layout>(
    l: &L,
    keys: &KeySpace,
    sensor: &SensorModel,
    origin: Point3,
    direction: Point3,
    max_range: f64,
    ignore_unknown: bool,
) -> Option<Key> {
    let d = direction.normalized();
    let r = max_range as f32;
    let end = Point3::new(origin.x + d.x * r, origin.y + d.y * r, origin.z + d.z * r);
    let ray = RayKeys::new(keys, origin, end).ok()?;
    for k in ray.chain(keys.key(end).ok()) {
        match l.search(k) {
            Some(v) if sensor.is_occupied(v) => return Some(k),
            Some(_) => {}
            None if ignore_unknown => {}
            None => return None,
        }
    }
    None
}

/// The key of child `pos` of a node with iterator key `key` at `depth`
/// (OctoMap's `computeChildKey`), re-exported for the layouts.
#[inline]
pub(crate) fn child_key(key: Key, pos: usize, depth: u8) -> Key {
    key.child_key(pos, depth)
}

/// Depth of a voxel.
pub(crate) const MAX_DEPTH: u8 = TREE_DEPTH;

/// The sensor model `graph2tree` (and OctoMap's `with_graph2tree_default`
/// in the oracle) uses: OctoMap's defaults read back as probabilities with
/// a 0.5 threshold, then set again.
pub fn graph2tree_sensor() -> SensorModel {
    let mut p = SensorModel::default().probabilities();
    p.occupancy_threshold = 0.5;
    SensorModel::from_probabilities(&p).expect("OctoMap's defaults are valid")
}
