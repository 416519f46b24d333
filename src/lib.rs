//! octolinear: a bit-compatible, cache-oriented re-implementation of OctoMap.
//!
//! The in-memory engine ([`OccupancyTree`]) keeps nodes in a pointer-free
//! arena; keys ([`Key`], [`KeySpace`]), the sensor model ([`SensorModel`])
//! and every update rule reproduce OctoMap's arithmetic bit for bit.
//!
//! ```
//! use octolinear::{formats::bt, OccupancyTree, Point3, ScanOptions};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut tree = OccupancyTree::new(0.1)?; // 10 cm voxels, OctoMap's sensor model
//! let scan = vec![Point3::new(2.0, 0.5, 0.3), Point3::new(2.0, 0.6, 0.3)];
//! tree.insert_point_cloud(&scan, Point3::new(0.0, 0.0, 0.0), &ScanOptions::default())?;
//! let hit = tree.search_point(Point3::new(2.0, 0.5, 0.3), 0)?;
//! assert!(tree.is_occupied(hit.unwrap().value));
//! let mut file = Vec::new();
//! bt::write(&tree, &mut file)?; // the bytes OctoMap's writeBinary writes
//! # Ok(()) }
//! ```
//!
//! Errors say what failed and where (file, line, byte offset, value). An
//! error caused by another one (an I/O error, a key outside the map) gives
//! it as [`std::error::Error::source`] and does not repeat it in its own
//! message: print the chain for the whole story (anyhow's `{:#}` does).

#![deny(missing_docs)]
#![deny(unsafe_code)]

#[allow(unsafe_code)]
mod arch;
pub mod collection;
pub mod formats;
pub mod geometry;
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod internals;
pub mod key;
mod keyorder;
pub mod mapped;
pub mod morton;
pub mod ray;
pub mod scan;
pub mod sensor;
pub mod tiles;
pub mod tree;

pub use collection::{MapCollection, MapNode};
pub use formats::graph::{ScanEdge, ScanGraph, ScanNode};
pub use formats::ot::AnyTree;
pub use formats::TreeFileError;
pub use geometry::{Point3, PointCloud, Pose6D, Quaternion};
pub use key::{Key, KeyError, KeySpace};
pub use mapped::{MapView, MappedMap, OlmError};
pub use morton::MortonCode;
pub use ray::{CastError, CastOptions, CastOutcome, RayKeys};
pub use scan::{OutOfMap, ScanError, ScanOptions, ScanReport, UpdateBox};
pub use sensor::{SensorError, SensorModel, SensorProbabilities};
pub use tree::{
    Bounds, BoundsRule, Clock, Compaction, CountingTree, Found, InnerNodes, KeyBox, NodeItem, NodeKind, OccupancyTree,
    SearchIndex, Summarize, TreeError, TreeKind, TreeSummary,
};
