//! What a scan insertion is asked to do and what it reports: options,
//! the per-scan report, errors, and a scan's update (its key sets).

use crate::geometry::Point3;
use crate::key::{Key, KeyError};
use crate::tree::{InnerNodes, OccupancyTree};

/// What to do with end points outside the addressable map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OutOfMap {
    /// Exactly what OctoMap does: rays whose ends have no key are skipped
    /// (their max-range-cut part still counts), and with `discretize` the
    /// end point's key wraps around to the other side of the map.
    #[default]
    OctoMap,
    /// Drop such points before anything else, and count them.
    Skip,
    /// Refuse the whole scan, naming the first such point.
    Error,
}

/// An axis-aligned box limiting which voxels a scan updates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateBox {
    /// Lower corner, metres (inclusive).
    pub min: Point3,
    /// Upper corner, metres (inclusive).
    pub max: Point3,
    min_key: Key,
    max_key: Key,
}

impl UpdateBox {
    /// Both corners must lie inside the map of `tree`.
    pub fn new(tree: &OccupancyTree, min: Point3, max: Point3) -> Result<Self, KeyError> {
        Ok(UpdateBox { min, max, min_key: tree.key(min)?, max_key: tree.key(max)? })
    }

    #[inline]
    pub(crate) fn contains_point(&self, p: Point3) -> bool {
        p.x >= self.min.x
            && p.y >= self.min.y
            && p.z >= self.min.z
            && p.x <= self.max.x
            && p.y <= self.max.y
            && p.z <= self.max.z
    }

    #[inline]
    pub(crate) fn contains_key(&self, k: Key) -> bool {
        (0..3).all(|i| k.0[i] >= self.min_key.0[i] && k.0[i] <= self.max_key.0[i])
    }
}

/// Options of [`OccupancyTree::insert_point_cloud`], OctoMap's defaults.
/// Built from [`ScanOptions::default`] with the `with_*` methods, so that
/// a new option breaks no caller:
///
/// ```
/// # use octolinear::ScanOptions;
/// let opts = ScanOptions::default().with_max_range(Some(30.0)).with_discretize(true);
/// assert_eq!(opts.max_range, Some(30.0));
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct ScanOptions {
    /// Rays longer than this are cut and their end is not marked occupied.
    pub max_range: Option<f64>,
    /// Merge end points falling into the same voxel before casting rays
    /// from the voxel centre (`discretize`).
    pub discretize: bool,
    /// Defer inner-node updates (`lazy_eval`).
    pub inner: InnerNodes,
    /// Only update voxels inside this box (OctoMap 1.10 semantics).
    pub bbx: Option<UpdateBox>,
    /// What to do with end points outside the map.
    pub out_of_map: OutOfMap,
    /// Threads for ray casting; `None` uses rayon's global pool.
    pub threads: Option<usize>,
}

impl ScanOptions {
    /// With rays cut at `range` metres (`None`: no limit).
    pub fn with_max_range(self, range: Option<f64>) -> Self {
        ScanOptions { max_range: range, ..self }
    }

    /// With end points merged per voxel before casting, or not.
    pub fn with_discretize(self, discretize: bool) -> Self {
        ScanOptions { discretize, ..self }
    }

    /// With inner nodes updated at once or deferred.
    pub fn with_inner(self, inner: InnerNodes) -> Self {
        ScanOptions { inner, ..self }
    }

    /// With updates limited to `bbx` (`None`: everywhere).
    pub fn with_bbx(self, bbx: Option<UpdateBox>) -> Self {
        ScanOptions { bbx, ..self }
    }

    /// With end points outside the map handled as `out_of_map` says.
    pub fn with_out_of_map(self, out_of_map: OutOfMap) -> Self {
        ScanOptions { out_of_map, ..self }
    }

    /// With `threads` threads casting rays (`None`: rayon's global pool).
    pub fn with_threads(self, threads: Option<usize>) -> Self {
        ScanOptions { threads, ..self }
    }
}

/// What a scan integration did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ScanReport {
    /// Points given, before any was dropped.
    pub points: usize,
    /// Points with a NaN or infinite coordinate; always skipped.
    pub non_finite: usize,
    /// Points outside the map skipped under [`OutOfMap::Skip`].
    pub out_of_map: usize,
    /// Miss updates applied: distinct voxels for a batched scan, every
    /// update for [`OccupancyTree::insert_point_cloud_rays`].
    pub free_updates: usize,
    /// Hit updates applied, counted like `free_updates`.
    pub occupied_updates: usize,
}

/// Why a scan was refused; nothing was applied.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ScanError {
    /// The sensor origin is not finite (an origin outside the map is
    /// accepted, as in OctoMap).
    #[error("sensor origin ({x}, {y}, {z}) refused")]
    Origin {
        /// Origin x, metres.
        x: f32,
        /// Origin y, metres.
        y: f32,
        /// Origin z, metres.
        z: f32,
        /// Why the origin has no key.
        source: KeyError,
    },
    /// An end point lies outside the map under [`OutOfMap::Error`].
    #[error("point {index} ({x}, {y}, {z}) lies outside the map")]
    PointOutOfMap {
        /// Index of the point in the input slice.
        index: usize,
        /// Point x, metres.
        x: f32,
        /// Point y, metres.
        y: f32,
        /// Point z, metres.
        z: f32,
        /// Why the point has no key.
        source: KeyError,
    },
    /// The ray-casting thread pool could not be started (the message says so).
    #[error("thread pool: {0}")]
    ThreadPool(&'static str),
}
