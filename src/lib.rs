//! octolinear: a bit-compatible, cache-oriented re-implementation of OctoMap.
//!
//! The in-memory engine ([`OccupancyTree`]) keeps nodes in a pointer-free
//! arena; keys ([`Key`], [`KeySpace`]), the sensor model ([`SensorModel`])
//! and every update rule reproduce OctoMap's arithmetic bit for bit.

pub mod formats;
pub mod geometry;
pub mod key;
pub mod morton;
pub mod ray;
pub mod scan;
pub mod sensor;
pub mod simulate;
pub mod tree;

pub use formats::graph::{ScanEdge, ScanGraph, ScanNode};
pub use geometry::{Point3, PointCloud, Pose6D, Quaternion};
pub use key::{Key, KeyError, KeySpace};
pub use morton::MortonCode;
pub use ray::{CastOptions, CastOutcome, RayKeys};
pub use scan::{OutOfMap, ScanOptions, ScanReport, UpdateBox};
pub use sensor::{SensorModel, SensorProbabilities};
pub use tree::{Bounds, BoundsRule, Found, InnerNodes, KeyBox, OccupancyTree, TreeError};
