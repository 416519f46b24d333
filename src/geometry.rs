//! Points, quaternions and 6-DoF poses with OctoMap's `octomath` float behaviour.

/// A point in metres, single precision like OctoMap's `point3d`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Point3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

impl Point3 {
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }
}
