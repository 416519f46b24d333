//! Deterministic procedural scenes scanned by a simulated spinning lidar.
//!
//! Output is a [`ScanGraph`](octolinear::formats::graph::ScanGraph) whose
//! points are in the sensor frame, so the graph2tree transform puts them in
//! the world. Reproducibility: everything is
//! derived from the seed with our own SplitMix64 (no crate whose stream may
//! change), each lidar column gets its own random stream (results do not
//! depend on the rayon thread count), and only IEEE-exact operations are used
//! (+, -, *, /, sqrt, floor, round; sin/cos are our own polynomials), so the
//! bytes are the same on every platform.

mod lidar;
mod math;
mod random;
mod scene;

pub use lidar::*;
pub use random::SplitMix64;
pub use scene::*;
