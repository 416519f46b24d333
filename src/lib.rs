//! octolinear: a bit-compatible, cache-oriented re-implementation of OctoMap.

pub mod geometry;

pub use geometry::Point3;
