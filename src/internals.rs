//! Crate internals that the benchmarks, probes and the layout ablation
//! measure on their own: the batched tree walk, the raw output of ray
//! casting, OctoMap's hash key sets and the ray fan. Only with the
//! `internals` feature, which those crates enable; not part of the API.

use crate::geometry::Point3;
use crate::morton::MortonCode;
pub use crate::ray::fan::{AxisSteps, FanRay, RayFan, WalkState};
pub use crate::scan::key_set::{KeyHasher, KeySet};
use crate::scan::ScanUpdate;
use crate::tree::{InnerNodes, OccupancyTree};

/// The batched updates and ray casting that scan insertion is made of.
pub trait TreeInternals {
    /// Adds `delta` to every voxel in `codes` (Morton codes, strictly
    /// increasing) in one walk of the tree, as [`OccupancyTree::update`]
    /// on each in that order would.
    fn update_batch(&mut self, codes: &[u64], delta: f32, inner: InnerNodes);

    /// [`Self::update_batch`] with the work shared by `workers` threads of
    /// the current rayon pool when the batch is large.
    fn update_batch_shared(&mut self, codes: &[u64], delta: f32, inner: InnerNodes, workers: usize);

    /// The raw output of ray casting a scan of finite points with default
    /// options: the free codes of every ray and the occupied codes of every
    /// end point, repeats included, unsorted ([`ScanUpdate::from_codes`]
    /// removes the repeats).
    fn cast_codes(&self, points: &[Point3], origin: Point3) -> (Vec<u64>, Vec<u64>);
}

impl TreeInternals for OccupancyTree {
    fn update_batch(&mut self, codes: &[u64], delta: f32, inner: InnerNodes) {
        OccupancyTree::update_batch(self, codes, delta, inner)
    }

    fn update_batch_shared(&mut self, codes: &[u64], delta: f32, inner: InnerNodes, workers: usize) {
        OccupancyTree::update_batch_shared(self, codes, delta, inner, workers)
    }

    fn cast_codes(&self, points: &[Point3], origin: Point3) -> (Vec<u64>, Vec<u64>) {
        let (mut free, mut occupied) = (Vec::new(), Vec::new());
        let fan = RayFan::new(self.key_space(), origin).ok();
        for &p in points {
            let Ok(key) = self.key_space().key(p) else { continue };
            let code = MortonCode::encode(key).0;
            occupied.push(code);
            if let Some(fan) = &fan {
                fan.for_each_code(p, code, |c| free.push(c));
            }
        }
        (free, occupied)
    }
}

/// A scan's update as OctoMap's hash-based key sets (free, occupied).
pub fn key_sets(update: &ScanUpdate) -> (KeySet, KeySet) {
    let set = |codes: &[u64]| codes.iter().map(|&c| MortonCode(c)).collect();
    (set(&update.free), set(&update.occupied))
}
