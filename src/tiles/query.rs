//! Ray casting over tiles: OctoMap's `castRay` with searches that may
//! fail on a tile's file. The ray walks voxel by voxel as on the single
//! tree, each step's search going to the tile holding the voxel (or to
//! the derived levels above the tiles), so it answers as the merged map
//! does; a failed search ends the cast with that error.

use super::error::TileError;
use crate::key::{Key, KeySpace};
use crate::mapped::OccupancyLookup;
use crate::ray::{CastOptions, CastOutcome};
use crate::sensor::SensorModel;
use crate::tree::Found;
use crate::Point3;
use std::cell::RefCell;

/// An [`OccupancyLookup`] over a fallible search; the first error is kept
/// and every later search answers unknown.
struct Capture<'a, F> {
    keys: &'a KeySpace,
    sensor: &'a SensorModel,
    search: F,
    error: RefCell<Option<TileError>>,
}

impl<F: Fn(Key, u8) -> Result<Option<Found>, TileError>> OccupancyLookup for Capture<'_, F> {
    fn key_space(&self) -> &KeySpace {
        self.keys
    }

    fn sensor(&self) -> &SensorModel {
        self.sensor
    }

    fn search(&self, key: Key, depth: u8) -> Option<Found> {
        if self.error.borrow().is_some() {
            return None;
        }
        (self.search)(key, depth).unwrap_or_else(|e| {
            *self.error.borrow_mut() = Some(e);
            None
        })
    }
}

/// OctoMap's `castRay` through `search`.
pub(crate) fn cast_ray(
    keys: &KeySpace,
    sensor: &SensorModel,
    search: impl Fn(Key, u8) -> Result<Option<Found>, TileError>,
    origin: Point3,
    direction: Point3,
    opts: CastOptions,
) -> Result<CastOutcome, TileError> {
    let lookup = Capture { keys, sensor, search, error: RefCell::new(None) };
    let outcome = crate::mapped::cast_ray(&lookup, origin, direction, opts);
    if let Some(e) = lookup.error.into_inner() {
        return Err(e);
    }
    Ok(outcome?)
}
