//! Rays of one scan: [`RayFan`] sets up each ray from the origin's shared
//! values, and [`FanRay`] walks it on Morton codes (`computeRayKeys`'s
//! voxels), step by step so that callers can interleave rays. Crate
//! internals: scan insertion casts its rays with them (the `internals`
//! feature shows them to the probes).

use crate::geometry::Point3;
use crate::key::{KeyError, KeySpace};
use crate::morton::MortonCode;
use std::hint::select_unpredictable;

/// The dilated bits of each axis in a Morton code.
pub(crate) const AXIS_MASKS: [u64; 3] = [0x2492_4924_9249, 0x2492_4924_9249 << 1, 0x2492_4924_9249 << 2];

/// Per-axis values in the order of the slots [`StepClock::step`] returns
/// (z, x, y, and z again): its compare masks' sign bits are the slot, with
/// no instruction to turn them into an axis.
pub(crate) const fn slots(per_axis: [u64; 3]) -> [u64; 4] {
    [per_axis[2], per_axis[0], per_axis[1], per_axis[2]]
}

/// [`AXIS_MASKS`] by slot.
pub(crate) const AXIS_MASK_SLOTS: [u64; 4] = slots(AXIS_MASKS);

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
    pub(crate) code: u64,
    pub(crate) end_code: u64,
    pub(crate) length: f64,
    pub(crate) clock: StepClock,
}

/// Per axis (by `StepClock::step`'s slot), what a step adds to a Morton
/// code: `((code & mask | fill) + add) & mask` are the axis's new bits.
#[derive(Clone, Copy)]
pub struct AxisSteps {
    pub(crate) fill: [u64; 4],
    pub(crate) add: [u64; 4],
}

impl FanRay {
    #[inline(always)]
    pub(crate) fn new(
        start: u64,
        step: [i32; 3],
        t_max: [f64; 3],
        t_delta: [f64; 3],
        end_code: u64,
        length: f64,
    ) -> Self {
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
    pub(crate) fn new(step: [i32; 3]) -> Self {
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
    pub(crate) fn apply(&self, code: u64, slot: usize) -> u64 {
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
    pub(crate) fn new(t: [f64; 3], dt: [f64; 3]) -> Self {
        StepClock { t, dt }
    }

    #[inline(always)]
    pub(crate) fn step(&mut self) -> usize {
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
    pub(crate) fn min(&self) -> f64 {
        min(min(self.t[0], self.t[1]), self.t[2])
    }
}

/// Rays from one origin: what [`RayKeys::new`](super::RayKeys::new) derives from the origin
/// alone (its key, its distances to the voxel borders) computed once, so
/// that each ray of a scan only pays for its own direction.
#[derive(Clone, Debug)]
pub struct RayFan {
    pub(crate) origin: Point3,
    pub(crate) origin_code: u64,
    /// Per axis, `border - origin` for a negative (0) and a positive (1) step.
    pub(crate) to_border: [[f64; 2]; 3],
    pub(crate) resolution: f64,
}

impl RayFan {
    /// Fails like [`RayKeys::new`](super::RayKeys::new) when the origin lies outside the map.
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
        Ok(RayFan { origin, origin_code, to_border, resolution: keys.resolution() })
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
    /// origin's voxel, which [`RayKeys`](super::RayKeys) yields first; `None` when the ray
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
