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
use crate::tree::{Found, OccupancyTree};
use std::hint::select_unpredictable;

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

/// The dilated bits of each axis in a Morton code.
pub(crate) const AXIS_MASKS: [u64; 3] = [0x2492_4924_9249, 0x2492_4924_9249 << 1, 0x2492_4924_9249 << 2];

/// Per-axis values in the order of the slots [`StepClock::step`] returns
/// (z, x, y, and z again): its compare masks' sign bits are the slot, with
/// no instruction to turn them into an axis.
const fn slots(per_axis: [u64; 3]) -> [u64; 4] {
    [per_axis[2], per_axis[0], per_axis[1], per_axis[2]]
}

/// [`AXIS_MASKS`] by slot.
const AXIS_MASK_SLOTS: [u64; 4] = slots(AXIS_MASKS);

/// One ray of `computeRayKeys` walked step by step on Morton codes (see
/// `walk_codes`), from [`RayFan::ray`]: lets a caller interleave rays,
/// whose steps, each a chain of dependent operations, then overlap in the
/// processor. [`Self::split`] separates the state that changes at every
/// step from the per-axis constants, so that two walks can stay in
/// registers.
#[derive(Clone, Copy)]
pub struct FanRay {
    pub(crate) code: u64,
    pub(crate) end_code: u64,
    pub(crate) length: f64,
    // plain doubles: a ray set up out of line is returned through memory,
    // and at this size the copy is a few moves instead of a `memcpy` call
    pub(crate) t_max: [f64; 3],
    pub(crate) t_delta: [f64; 3],
    pub(crate) steps: AxisSteps,
}

/// What changes along a [`FanRay`].
#[derive(Clone, Copy)]
pub struct WalkState {
    code: u64,
    end_code: u64,
    length: f64,
    clock: StepClock,
}

/// Per axis (by `StepClock::step`'s slot), what a step adds to a Morton
/// code: `((code & mask | fill) + add) & mask` are the axis's new bits.
#[derive(Clone, Copy)]
pub struct AxisSteps {
    fill: [u64; 4],
    pub(crate) add: [u64; 4],
}

impl FanRay {
    #[inline(always)]
    fn new(start: u64, step: [i32; 3], t_max: [f64; 3], t_delta: [f64; 3], end_code: u64, length: f64) -> Self {
        FanRay { code: start, end_code, length, t_max, t_delta, steps: AxisSteps::new(step) }
    }

    /// A ray with no voxel left.
    pub fn finished() -> Self {
        FanRay::new(0, [0; 3], [0.0; 3], [1.0; 3], u64::MAX, f64::NEG_INFINITY)
    }

    /// The walk's changing state, and its constants.
    #[inline(always)]
    pub fn split(self) -> (WalkState, AxisSteps) {
        let clock = StepClock::new(self.t_max, self.t_delta);
        (WalkState { code: self.code, end_code: self.end_code, length: self.length, clock }, self.steps)
    }
}

impl AxisSteps {
    /// The constants for a ray stepping by `step` (-1, 0 or +1) per axis.
    #[inline(always)]
    fn new(step: [i32; 3]) -> Self {
        let mut fill = [0u64; 3];
        let mut add = [0u64; 3];
        for i in 0..3 {
            // without branches (see `RayFan::ray`): -1, 0 or +1 times 1 << i
            fill[i] = !AXIS_MASKS[i] & u64::from(step[i] == 1).wrapping_neg();
            add[i] = (i64::from(step[i]) << i) as u64;
        }
        AxisSteps { fill: slots(fill), add: slots(add) }
    }

    /// `code` moved one voxel along the axis of `slot`.
    #[inline(always)]
    fn apply(&self, code: u64, slot: usize) -> u64 {
        let slot = slot & 3;
        let m = AXIS_MASK_SLOTS[slot];
        ((((code & m) | self.fill[slot]).wrapping_add(self.add[slot])) & m) | (code & !m)
    }
}

impl WalkState {
    /// The next voxel's Morton code, given the ray's [`AxisSteps`]; `None`
    /// once the walk has ended.
    #[inline(always)]
    pub fn next_code(&mut self, steps: &AxisSteps) -> Option<u64> {
        // the code in one register; the axis to step comes from compare
        // masks (no branch on it), its constants from small tables
        self.code = steps.apply(self.code, self.clock.step());
        if self.code == self.end_code || self.clock.min() > self.length {
            self.length = f64::NEG_INFINITY; // stays done
            return None;
        }
        Some(self.code)
    }
}

#[cfg(target_arch = "x86_64")]
pub use crate::arch::sse2::StepClock;

/// Portable [`StepClock`]: the same choice on booleans.
#[cfg(not(target_arch = "x86_64"))]
#[derive(Clone, Copy)]
pub struct StepClock {
    t: [f64; 3],
    dt: [f64; 3],
}

#[cfg(not(target_arch = "x86_64"))]
impl StepClock {
    #[inline(always)]
    fn new(t: [f64; 3], dt: [f64; 3]) -> Self {
        StepClock { t, dt }
    }

    #[inline(always)]
    fn step(&mut self) -> usize {
        let [t0, t1, t2] = self.t;
        let lt01 = t0 < t1;
        let s0 = lt01 & (t0 < t2);
        let s1 = !lt01 & (t1 < t2);
        let s = [s0, s1, !(s0 | s1)];
        for i in 0..3 {
            self.t[i] += select_unpredictable(s[i], self.dt[i], 0.0);
        }
        usize::from(s0) | (usize::from(s1) << 1)
    }

    #[inline(always)]
    fn min(&self) -> f64 {
        min(min(self.t[0], self.t[1]), self.t[2])
    }
}

/// Rays from one origin: what [`RayKeys::new`] derives from the origin
/// alone (its key, its distances to the voxel borders) computed once, so
/// that each ray of a scan only pays for its own direction.
#[derive(Clone, Debug)]
pub struct RayFan {
    pub(crate) origin: Point3,
    origin_key: Key,
    pub(crate) origin_code: u64,
    /// Per axis, `border - origin` for a negative (0) and a positive (1) step.
    pub(crate) to_border: [[f64; 2]; 3],
    pub(crate) resolution: f64,
}

impl RayFan {
    /// Fails like [`RayKeys::new`] when the origin lies outside the map.
    pub fn new(keys: &KeySpace, origin: Point3) -> Result<Self, KeyError> {
        let origin_key = keys.key(origin)?;
        let o = [origin.x, origin.y, origin.z];
        let mut to_border = [[0.0; 2]; 3];
        for i in 0..3 {
            for (s, step) in [(0, -1.0), (1, 1.0)] {
                // as `Dda::new` with the border offset rounded to float
                let offset = f64::from((step * keys.resolution() * 0.5) as f32);
                to_border[i][s] = keys.key_to_coord(origin_key.0[i]) + offset - f64::from(o[i]);
            }
        }
        let origin_code = MortonCode::encode(origin_key).0;
        Ok(RayFan { origin, origin_key, origin_code, to_border, resolution: keys.resolution() })
    }

    /// The key of the voxel containing the fan's origin.
    pub fn origin_key(&self) -> Key {
        self.origin_key
    }

    /// Calls `f` with the Morton code of every key `RayKeys::new(keys,
    /// origin, end)` yields, given `end_code`, the Morton code of the key of
    /// `end`.
    #[inline]
    pub fn for_each_code(&self, end: Point3, end_code: u64, mut f: impl FnMut(u64)) {
        if let Some(ray) = self.ray(end, end_code) {
            f(self.origin_code);
            let (mut state, steps) = ray.split();
            while let Some(code) = state.next_code(&steps) {
                f(code);
            }
        }
    }

    /// The Morton code of the origin's voxel, the first of every ray that
    /// is not empty.
    pub fn origin_code(&self) -> u64 {
        self.origin_code
    }

    /// The ray to `end` (`end_code` the Morton code of its key) past the
    /// origin's voxel, which [`RayKeys`] yields first; `None` when the ray
    /// is empty (`end` lies in the origin's voxel).
    #[inline]
    pub fn ray(&self, end: Point3, end_code: u64) -> Option<FanRay> {
        if end_code == self.origin_code {
            return None;
        }
        let d = end - self.origin;
        let length = d.norm() as f32;
        let dir = [d.x / length, d.y / length, d.z / length];
        // per axis without branches: a direction's signs are as good as
        // random from one ray to the next, and the divisions of an axis
        // that does not move are computed and dropped
        let mut step = [0i32; 3];
        let mut t_max = [f64::MAX; 3];
        let mut t_delta = [f64::MAX; 3];
        for i in 0..3 {
            let (up, down) = (dir[i] > 0.0, dir[i] < 0.0);
            let moves = up | down;
            let border = self.to_border[i][usize::from(up)];
            step[i] = i32::from(up) - i32::from(down);
            t_max[i] = select_unpredictable(moves, border / f64::from(dir[i]), f64::MAX);
            t_delta[i] = select_unpredictable(moves, self.resolution / f64::from(dir[i].abs()), f64::MAX);
        }
        Some(FanRay::new(self.origin_code, step, t_max, t_delta, end_code, f64::from(length)))
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
    #[error("ray origin: {0}")]
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
        let mut path = crate::tree::PathSearch::new(self);
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
