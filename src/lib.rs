//! octolinear: a bit-compatible, cache-oriented re-implementation of OctoMap.

pub mod formats;
pub mod geometry;
pub mod simulate;

pub use formats::graph::{ScanEdge, ScanGraph, ScanNode};
pub use geometry::{Point3, PointCloud, Pose6D, Quaternion};
