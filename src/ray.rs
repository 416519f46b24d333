//! Ray traversal: OctoMap's `computeRayKeys` and `castRay`, bit for bit.
//!
//! Both walk voxels with the 3D DDA of Amanatides and Woo. OctoMap mixes
//! float and double in specific places (the ray length is a float, the
//! initial border offset is rounded to float in `computeRayKeys` but not in
//! `castRay`); those roundings decide which voxel a ray visits at a tie, so
//! they are reproduced exactly here.

use crate::geometry::Point3;
use crate::key::{Key, KeyError, KeySpace};
use crate::morton::MortonCode;
use crate::sensor::SensorModel;
use crate::tree::{ArenaPath, Found, OccupancyTree, PathSearch};

pub(crate) mod fan;

use fan::{slots, AxisSteps, StepClock, AXIS_MASK_SLOTS};
pub(crate) use fan::{FanRay, RayFan, AXIS_MASKS};

/// `origin + direction * (float) range`, in float.
#[inline(always)]
pub(crate) fn point_along(origin: Point3, direction: Point3, range: f64) -> Point3 {
    let r = range as f32;
    Point3::new(origin.x + direction.x * r, origin.y + direction.y * r, origin.z + direction.z * r)
}

/// Whether `p` lies within `max_range` of `origin` (always, when it is
/// negative), and the end of the ray `insertPointCloud` casts towards it:
/// `p`, or the point at that range towards it.
#[inline(always)]
pub(crate) fn cut_to_range(p: Point3, origin: Point3, max_range: f64) -> (bool, Point3) {
    let within = max_range < 0.0 || (p - origin).norm() <= max_range;
    (within, if within { p } else { point_along(origin, (p - origin).normalized(), max_range) })
}

/// `std::min` on doubles.
#[inline(always)]
fn min(a: f64, b: f64) -> f64 {
    if b < a {
        b
    } else {
        a
    }
}

/// Index of the smallest `t_max`, ties going to the higher axis.
#[inline(always)]
fn min_axis(t: &[f64; 3]) -> usize {
    if t[0] < t[1] {
        if t[0] < t[2] {
            0
        } else {
            2
        }
    } else if t[1] < t[2] {
        1
    } else {
        2
    }
}

/// The DDA state shared by both traversals.
#[derive(Clone, Debug)]
struct Dda {
    key: Key,
    step: [i32; 3],
    t_max: [f64; 3],
    t_delta: [f64; 3],
}

impl Dda {
    fn new(keys: &KeySpace, origin: Point3, key: Key, direction: Point3, round_border: bool) -> Self {
        let o = [origin.x, origin.y, origin.z];
        let d = [direction.x, direction.y, direction.z];
        let mut step = [0; 3];
        let mut t_max = [f64::MAX; 3];
        let mut t_delta = [f64::MAX; 3];
        for i in 0..3 {
            step[i] = if d[i] > 0.0 {
                1
            } else if d[i] < 0.0 {
                -1
            } else {
                0
            };
            if step[i] != 0 {
                let offset = f64::from(step[i]) * keys.resolution() * 0.5;
                let offset = if round_border { f64::from(offset as f32) } else { offset };
                let border = keys.key_to_coord(key.0[i]) + offset;
                t_max[i] = (border - f64::from(o[i])) / f64::from(d[i]);
                t_delta[i] = keys.resolution() / f64::from(d[i].abs());
            }
        }
        Dda { key, step, t_max, t_delta }
    }

    /// Advances one voxel along `dim` (the axis of the smallest `t_max`);
    /// returns the ray parameter where the new voxel is entered.
    #[inline(always)]
    fn advance(&mut self, dim: usize) -> f64 {
        let t_entry = self.t_max[dim];
        self.key.0[dim] = self.key.0[dim].wrapping_add(self.step[dim] as u16);
        self.t_max[dim] += self.t_delta[dim];
        t_entry
    }
}

/// The keys `computeRayKeys(origin, end)` yields: every voxel the segment
/// crosses, the origin's included, the end's excluded. No buffer is needed.
#[derive(Clone, Debug)]
pub struct RayKeys {
    dda: Option<Dda>,
    end: Key,
    length: f32,
    /// The origin key is yielded before the first step.
    pending_origin: bool,
}

impl RayKeys {
    /// Starts a traversal; fails like OctoMap when either point is outside
    /// the map. Equal origin and end keys give an empty ray.
    pub fn new(keys: &KeySpace, origin: Point3, end: Point3) -> Result<Self, KeyError> {
        let key_origin = keys.key(origin)?;
        let key_end = keys.key(end)?;
        if key_origin == key_end {
            return Ok(RayKeys { dda: None, end: key_end, length: 0.0, pending_origin: false });
        }
        let d = end - origin;
        let length = d.norm() as f32;
        let direction = Point3::new(d.x / length, d.y / length, d.z / length);
        let dda = Dda::new(keys, origin, key_origin, direction, true);
        Ok(RayKeys { dda: Some(dda), end: key_end, length, pending_origin: true })
    }
}

impl RayKeys {
    /// Calls `f` with the Morton code of every key the iterator would yield,
    /// in a tight loop that steps the interleaved code directly (see
    /// `walk_codes`).
    #[inline]
    pub fn for_each_code(self, mut f: impl FnMut(u64)) {
        let Some(dda) = self.dda else { return };
        let start = MortonCode::encode(dda.key).0;
        if !self.pending_origin {
            // the origin was already yielded and steps may have been taken:
            // finish with the iterator's own stepping
            let mut rest = RayKeys { dda: Some(dda), ..self };
            rest.by_ref().for_each(|k| f(MortonCode::encode(k).0));
            return;
        }
        f(start);
        let end_code = MortonCode::encode(self.end).0;
        walk_codes(start, dda.step, dda.t_max, dda.t_delta, end_code, f64::from(self.length), f);
    }
}

/// The stepping loop of `computeRayKeys` on Morton codes: from the voxel
/// `start` (not reported), step the axis of the smallest `t_max` and report
/// each voxel until the end voxel or a `t_max` beyond `length`.
///
/// Stepping one axis changes only that axis's interleaved bits (`mask`):
/// with the other axes' bits set to one, adding one carries straight
/// through them (and subtracting borrows through zeros), so the axis's bits
/// become `((code & mask | fill) + add) & mask` with no branch on the
/// direction. The distance check is OctoMap's `min(min(..), ..)` of the
/// `t_max`.
#[inline(always)]
fn walk_codes(
    start: u64,
    step: [i32; 3],
    t_max: [f64; 3],
    t_delta: [f64; 3],
    end_code: u64,
    length: f64,
    mut f: impl FnMut(u64),
) {
    let (mut state, steps) = FanRay::new(start, step, t_max, t_delta, end_code, length).split();
    while let Some(code) = state.next_code(&steps) {
        f(code);
    }
}

impl Iterator for RayKeys {
    type Item = Key;

    #[inline]
    fn next(&mut self) -> Option<Key> {
        let dda = self.dda.as_mut()?;
        if self.pending_origin {
            self.pending_origin = false;
            return Some(dda.key);
        }
        dda.advance(min_axis(&dda.t_max));
        if dda.key == self.end {
            self.dda = None;
            return None;
        }
        let dist = min(min(dda.t_max[0], dda.t_max[1]), dda.t_max[2]);
        if dist > f64::from(self.length) {
            self.dda = None;
            return None;
        }
        Some(dda.key)
    }
}

/// How a cast ray ended. `end` is what OctoMap writes to its `end` argument.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CastOutcome {
    /// An occupied voxel was reached (OctoMap returns `true`).
    Occupied {
        /// Centre of the occupied voxel.
        end: Point3,
    },
    /// The next voxel lies beyond the maximum range.
    MaxRange {
        /// Centre of the first voxel whose centre lies beyond the maximum range.
        end: Point3,
    },
    /// An unknown voxel was met and unknown space was not to be ignored.
    Unknown {
        /// Centre of the unknown voxel.
        end: Point3,
    },
    /// The ray reached the edge of the map.
    LeftMap {
        /// Centre of the last voxel inside the map.
        end: Point3,
    },
}

impl CastOutcome {
    /// The end point of any outcome, the voxel centre OctoMap writes to `end`.
    pub fn end(&self) -> Point3 {
        match *self {
            CastOutcome::Occupied { end }
            | CastOutcome::MaxRange { end }
            | CastOutcome::Unknown { end }
            | CastOutcome::LeftMap { end } => end,
        }
    }

    /// OctoMap's boolean return value.
    pub fn hit(&self) -> bool {
        matches!(self, CastOutcome::Occupied { .. })
    }
}

/// Why a ray could not be cast at all (OctoMap returns `false` and leaves
/// `end` untouched).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum CastError {
    /// The origin has no key (not finite or outside the map).
    #[error("ray origin refused")]
    Origin(#[from] KeyError),
    /// The direction does not move along any axis (the zero vector).
    #[error("ray direction is the zero vector")]
    ZeroDirection,
    /// The map holds hit counts (`CountingOcTree`), not occupancy.
    #[error("ray casting needs occupancy, and this map holds hit counts (CountingOcTree)")]
    NoOccupancy,
}

/// Options of [`OccupancyTree::cast_ray`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CastOptions {
    /// Continue through unknown space instead of stopping there.
    pub ignore_unknown: bool,
    /// Stop beyond this distance; `None` (or a value ≤ 0) for no limit.
    pub max_range: Option<f64>,
}

impl OccupancyTree {
    /// The voxels between `origin` and `end` ([`RayKeys`]).
    pub fn ray_keys(&self, origin: Point3, end: Point3) -> Result<RayKeys, KeyError> {
        RayKeys::new(self.key_space(), origin, end)
    }

    /// Follows a ray until it meets an occupied voxel, as OctoMap's `castRay`.
    pub fn cast_ray(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Result<CastOutcome, CastError> {
        let mut path = PathSearch::new(ArenaPath::new(self));
        cast_ray_with(self.key_space(), self.sensor(), |c| path.search(c), origin, direction, opts)
    }

    /// Where a ray from `origin` along `direction` enters the voxel centred
    /// at `center` (OctoMap's `getRayIntersection`), moved `delta` further.
    pub fn ray_intersection(&self, origin: Point3, direction: Point3, center: Point3, delta: f64) -> Option<Point3> {
        let half = (self.resolution() / 2.0) as f32;
        let c = [center.x, center.y, center.z];
        let o = [origin.x, origin.y, origin.z];
        let d = [direction.x, direction.y, direction.z];
        let mut out_d = f64::MAX;
        let mut found = false;
        for axis in 0..3 {
            // `normal.dot(direction)` with a unit normal along `axis`,
            // evaluated like Vector3::dot (float sum, zero terms included)
            let mut n = [0.0f32; 3];
            n[axis] = 1.0;
            let line_dot_normal = f64::from(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]);
            if line_dot_normal == 0.0 {
                continue;
            }
            for sign in [-1.0f32, 1.0] {
                let mut plane = c;
                plane[axis] = c[axis] + sign * half;
                let diff = [plane[0] - o[0], plane[1] - o[1], plane[2] - o[2]];
                let dist = f64::from(diff[0] * n[0] + diff[1] * n[1] + diff[2] * n[2]) / line_dot_normal;
                let fd = dist as f32;
                let hit = [d[0] * fd + o[0], d[1] * fd + o[1], d[2] * fd + o[2]];
                let inside = (0..3).filter(|&j| j != axis).all(|j| {
                    let lo = f64::from(c[j] - half) - 1e-6;
                    let hi = f64::from(c[j] + half) + 1e-6;
                    !(f64::from(hit[j]) < lo || f64::from(hit[j]) > hi)
                });
                if inside {
                    out_d = min(out_d, dist);
                    found = true;
                }
            }
        }
        found.then(|| {
            let t = (out_d + delta) as f32;
            Point3::new(d[0] * t + o[0], d[1] * t + o[1], d[2] * t + o[2])
        })
    }
}

/// OctoMap's `castRay` over any map, given its voxel search (depth 16) by
/// Morton code: shared by the arena tree and the memory-mapped view, so
/// both step exactly alike. The walk stays on Morton codes (as
/// [`FanRay`]); keys are decoded only where a point is reported or the
/// maximum range is tested.
pub(crate) fn cast_ray_with(
    keys: &KeySpace,
    sensor: &SensorModel,
    mut search: impl FnMut(u64) -> Option<Found>,
    origin: Point3,
    direction: Point3,
    opts: CastOptions,
) -> Result<CastOutcome, CastError> {
    let center_of = |code: u64| keys.key_to_point(MortonCode(code).decode());
    let start = keys.key(origin)?;
    let mut code = MortonCode::encode(start).0;
    match search(code) {
        Some(n) if sensor.is_occupied(n.value) => return Ok(CastOutcome::Occupied { end: center_of(code) }),
        Some(_) => {}
        None if !opts.ignore_unknown => return Ok(CastOutcome::Unknown { end: center_of(code) }),
        None => {}
    }
    let direction = direction.normalized();
    let dda = Dda::new(keys, origin, start, direction, false);
    if dda.step == [0; 3] {
        return Err(CastError::ZeroDirection);
    }
    let steps = AxisSteps::new(dda.step);
    // per axis, its bits in a code at the last key before leaving the map
    // (an axis that does not step is never chosen, and no code matches)
    let edge = slots(std::array::from_fn(|i| match dda.step[i] {
        1 => AXIS_MASKS[i],
        -1 => 0,
        _ => u64::MAX,
    }));
    let mut clock = StepClock::new(dda.t_max, dda.t_delta);
    let max_range = opts.max_range.unwrap_or(-1.0);
    let max_range_set = max_range > 0.0;
    let max_range_sq = max_range * max_range;
    // A voxel entered at ray parameter `t` has its centre within `t` plus a
    // half diagonal (< one resolution) of the origin; below this bound the
    // exact float test of OctoMap cannot fire and is skipped.
    let surely_inside = (max_range - keys.resolution()) * (1.0 - 1e-6);
    let o = [origin.x, origin.y, origin.z];
    loop {
        // the smallest t_max is where the next voxel is entered
        let t_entry = clock.min();
        let slot = clock.step() & 3;
        if code & AXIS_MASK_SLOTS[slot] == edge[slot] {
            return Ok(CastOutcome::LeftMap { end: center_of(code) });
        }
        code = steps.apply(code, slot);
        if max_range_set && t_entry >= surely_inside {
            let end = center_of(code);
            let e = [end.x, end.y, end.z];
            let mut dist_sq = 0.0f64;
            for j in 0..3 {
                let d = e[j] - o[j];
                dist_sq += f64::from(d * d);
            }
            if dist_sq > max_range_sq {
                return Ok(CastOutcome::MaxRange { end });
            }
        }
        match search(code) {
            Some(n) if sensor.is_occupied(n.value) => return Ok(CastOutcome::Occupied { end: center_of(code) }),
            Some(_) => {}
            None if !opts.ignore_unknown => return Ok(CastOutcome::Unknown { end: center_of(code) }),
            None => {}
        }
    }
}
