//! AVX-512F (with BMI2 and POPCNT), detected at run time: a scan's rays
//! set up eight at a time and walked sixteen at a time, one per lane of
//! AVX-512 registers (two groups of eight lanes).
//!
//! A ray's steps form one chain of dependent operations (compare the three
//! `t_max`, add the chosen increment, move the Morton code), so a scalar
//! walk waits on latency; two walks interleaved (`Casting::cast_all`'s
//! scalar path) still leave most of the machine idle. Here every lane runs
//! [`WalkState::next_code`](crate::ray::WalkState::next_code)'s arithmetic
//! on its own ray: the same double compares (ties to the higher axis), the
//! same double additions and the same end tests, so each lane visits
//! exactly the voxels of the scalar walk.
//!
//! A group's lanes walk a packet: eight rays next to each other in the
//! scan, started together from the origin and stepped in lockstep until the
//! last of them ends; then the group takes the next eight. Every ray from
//! the origin enters at its k-th step a voxel k steps (along the axes) from
//! the origin's, so rays of one packet that enter the same voxel do so at
//! the same step, and neighbouring rays of a scanning lidar run through the
//! same voxels for most of their length: a lane's code is dropped when the
//! lane below enters the same voxel. On a 64-beam lidar's scans indoors at
//! 0.1 m that leaves 28% of the steps' codes for the scan's sets, for 8%
//! more lane steps than the rays' steps (lanes whose ray has ended wait for
//! the packet's last; `packet_probe`).
//! The codes kept are packed into a buffer that is handed on in batches.
//!
//! The functions with `#[target_feature(enable = "avx512f")]` call each
//! other safely; the way in from other code is [`Avx512::cast_fan`], whose
//! token proves the processor has the instructions. Those that call the
//! set insertions (inlined into them) add BMI2, for its one-instruction
//! variable shift `shlx`, and those that count lanes add POPCNT.

use crate::geometry::{Point3, Pose6D};
use crate::key::KeySpace;
use crate::ray::{FanRay, RayFan, AXIS_MASKS};
use std::arch::x86_64::*;

/// Lanes of a group (doubles in a 512-bit register).
const LANES: usize = 8;

/// Codes gathered before they are handed on.
const BUFFER: usize = 512;

/// Proof that the processor has AVX-512F, BMI2 and POPCNT (every AVX-512
/// processor has the other two): only [`Avx512::detect`] makes one.
#[derive(Clone, Copy)]
pub(crate) struct Avx512(());

impl Avx512 {
    /// `Some` on a processor with AVX-512F, BMI2 and POPCNT.
    pub(crate) fn detect() -> Option<Self> {
        let has = std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("popcnt");
        has.then_some(Avx512(()))
    }

    /// `Casting::cast`'s work for every point of `points`, in the lanes:
    /// calls `occupied` with batches of the codes of the end voxels within
    /// `max_range` of `fan`'s origin (any distance when it is negative) and
    /// `free` with batches of the codes of the voxels the rays step into
    /// (in no particular order, some more than once). The rays are set up
    /// a chunk at a time, eight at once, each chunk walked sixteen rays at
    /// once while the lanes still hold the previous chunk's last rays.
    /// Returns whether any ray was walked (then the origin's voxel is free
    /// too, which `free` was not given).
    #[inline]
    pub(crate) fn cast_fan(
        self,
        fan: &RayFan,
        keys: &KeySpace,
        points: &[Point3],
        limits: RayLimits<'_>,
        occupied: impl FnMut(&[u64]),
        free: impl FnMut(&[u64]),
    ) -> bool {
        // SAFETY: an `Avx512` exists only on a processor with AVX-512F,
        // BMI2 and POPCNT.
        unsafe { cast_fan_lanes(fan, keys, points, limits, occupied, free) }
    }
}

impl Avx512 {
    /// [`Pose6D::transform_all`] in the AVX-512 registers: the same float
    /// operations on sixteen points at once.
    pub(crate) fn transform_all(self, pose: &Pose6D, points: &mut [Point3]) {
        // SAFETY: an `Avx512` exists only on a processor with AVX-512F.
        unsafe { transform_all(pose, points) }
    }
}

/// [`Avx512::transform_all`].
#[target_feature(enable = "avx512f")]
fn transform_all(pose: &Pose6D, points: &mut [Point3]) {
    pose.transform_blocks(points);
}

/// Where [`Avx512::cast_fan`]'s rays end.
pub(crate) struct RayLimits<'a> {
    /// Rays longer are cut there (`cut_to_range`); negative: no limit.
    pub(crate) max_range: f64,
    /// Given a ray's unit direction, the distance from the origin after
    /// which its voxels are not wanted: its walk ends there.
    pub(crate) stop: Option<&'a dyn Fn([f64; 3]) -> f64>,
}

/// [`Avx512::cast_fan`].
#[target_feature(enable = "avx512f,bmi2,popcnt")]
fn cast_fan_lanes(
    fan: &RayFan,
    keys: &KeySpace,
    points: &[Point3],
    RayLimits { max_range, stop }: RayLimits<'_>,
    mut occupied: impl FnMut(&[u64]),
    mut free: impl FnMut(&[u64]),
) -> bool {
    let mut rays = LaneRays::default();
    let mut lanes = Lanes::default();
    let mut any = false;
    // the walk's codes on their way from the lanes to `free`, zeroed once
    let mut buffer = [0u64; BUFFER + LANES];
    let mut chunks = points.chunks(LaneRays::CAPACITY).peekable();
    while let Some(chunk) = chunks.next() {
        rays.clear();
        set_up(&mut rays, fan, keys, chunk, max_range, &mut occupied);
        any |= rays.len() > 0;
        if let Some(stop) = stop {
            rays.shorten(fan.resolution, stop);
        }
        rays.pad();
        let last = chunks.peek().is_none();
        walk(&mut lanes, &rays, fan.origin_code(), last, &mut buffer, &mut free);
    }
    any
}

/// Rays set up and waiting for a lane, as a structure of arrays with room
/// for [`Self::CAPACITY`] rays and the [`LANES`] finished rays that
/// [`walk`] reads after the last one (it loads a packet's eight rays at
/// once; the lanes past the last ray are not alive).
struct LaneRays {
    t: [Box<[f64]>; 3],
    dt: [Box<[f64]>; 3],
    /// What a step subtracts from the stepped axis's bits of a code, under
    /// that axis's mask (see [`step_bits`]).
    step: Box<[u64]>,
    end: Box<[u64]>,
    length: Box<[f64]>,
    /// Rays before the padding.
    len: usize,
    padded: bool,
    /// [`set_up`]'s room for the codes of the occupied end voxels of the
    /// rays it sets up (kept here, like the walk's buffer in
    /// [`cast_fan_lanes`]: zeroed at every call, the two were 0.8% of a
    /// casting profile).
    ends: Box<[u64]>,
}

impl Default for LaneRays {
    fn default() -> Self {
        let n = Self::CAPACITY + LANES;
        let f = || vec![0.0; n].into_boxed_slice();
        let u = || vec![0; n].into_boxed_slice();
        LaneRays {
            t: [f(), f(), f()],
            dt: [f(), f(), f()],
            step: u(),
            end: u(),
            length: f(),
            len: 0,
            padded: false,
            ends: u(),
        }
    }
}

impl LaneRays {
    /// Rays a set-up may hold (88 bytes each: the arrays stay in L1).
    const CAPACITY: usize = 256;

    /// No ray waiting, and no padding: [`Self::push`] or [`set_up`] rays,
    /// then [`Self::pad`].
    fn clear(&mut self) {
        self.len = 0;
        self.padded = false;
    }

    fn len(&self) -> usize {
        self.len
    }

    /// Adds `ray` after the waiting ones (before [`Self::pad`]).
    #[inline(always)]
    fn push(&mut self, ray: FanRay) {
        assert!(!self.padded && self.len < Self::CAPACITY, "LaneRays full or padded");
        self.write(self.len, &ray);
        self.len += 1;
    }

    /// Appends the [`LANES`] rays that [`walk`] reads past the last:
    /// [`FanRay::finished`], which ends at its first step.
    fn pad(&mut self) {
        let finished = FanRay::finished();
        for n in self.len..self.len + LANES {
            self.write(n, &finished);
        }
        self.padded = true;
    }

    /// Ends each ray's walk at `stop` of its direction when that comes
    /// before its length: the direction from the distances between
    /// borders (`resolution / |dir|`, `f64::MAX` along an axis it does not
    /// move on) and the axes that step up.
    fn shorten(&mut self, resolution: f64, stop: &dyn Fn([f64; 3]) -> f64) {
        for n in 0..self.len {
            let dir = std::array::from_fn(|i| {
                let dt = self.dt[i][n];
                let up = self.step[n] & AXIS_MASKS[i] & !0b111 != 0;
                match dt {
                    f64::MAX => 0.0,
                    dt if up => resolution / dt,
                    dt => -resolution / dt,
                }
            });
            self.length[n] = self.length[n].min(stop(dir));
        }
    }

    /// `ray` at position `n` of the arrays.
    #[inline(always)]
    fn write(&mut self, n: usize, ray: &FanRay) {
        for i in 0..3 {
            self.t[i][n] = ray.t_max[i];
            self.dt[i][n] = ray.t_delta[i];
        }
        self.step[n] = step_bits(ray);
        self.end[n] = ray.end_code;
        self.length[n] = ray.length;
    }
}

/// What a step of `ray` subtracts from the stepped axis's bits of a code
/// (see [`step_code`]), for every axis at once: under an axis's mask, the
/// whole mask for a step up, the axis's lowest bit for a step down. The
/// bits of the axes that step up, and the three lowest bits.
#[inline(always)]
fn step_bits(ray: &FanRay) -> u64 {
    // the slot of an axis in `AxisSteps` (x 1, y 2, z 0)
    let up = |axis: usize| (ray.steps.add[(axis + 1) % 3] as i64) > 0;
    (0..3).filter(|&axis| up(axis)).fold(0b111, |bits, axis| bits | AXIS_MASKS[axis])
}

/// [`RayFan::ray`] for every point of `points` (at most
/// [`LaneRays::CAPACITY`] less the rays already in `rays`), with
/// `Casting::cast`'s end voxel: rays longer than `max_range` (when it is
/// not negative) are cut there ([`crate::ray::cut_to_range`]); `occupied` is
/// called with the codes of the voxels of the points within range, and the
/// non-empty rays join `rays`. Ends without a key are skipped. Eight points
/// at a time, with the scalar code's operations in the same precision and
/// order (every one correctly rounded), so the rays are the same to the
/// bit; the last `points.len() % 8` by the scalar code.
#[target_feature(enable = "avx512f,bmi2,popcnt")]
fn set_up(
    rays: &mut LaneRays,
    fan: &RayFan,
    keys: &KeySpace,
    points: &[Point3],
    max_range: f64,
    mut occupied: impl FnMut(&[u64]),
) {
    assert!(!rays.padded && rays.len + points.len() <= LaneRays::CAPACITY, "LaneRays full or padded");
    let mut eight = points.chunks_exact(LANES);
    // the occupied end voxels' codes, handed on after the loop: a call in
    // the loop (a set's new block) would have every vector live across it
    // kept in memory
    let ends = &mut rays.ends;
    let mut hits = 0;
    for batch in eight.by_ref() {
        // x, y and z of the eight points: 24 consecutive floats
        // (`Point3` is `repr(C)`), the first 16 in `lo`
        debug_assert_eq!(batch.len(), LANES);
        let floats = batch.as_ptr().cast::<f32>();
        // SAFETY: `batch` holds 8 points, 96 bytes: floats 0..16 and 16..24
        let (lo, hi) = unsafe { (_mm512_loadu_ps(floats), _mm256_loadu_ps(floats.add(16))) };
        let hi = _mm512_castps256_ps512(hi);
        let axis = |first: i32| {
            let idx = _mm512_setr_epi32(
                first,
                first + 3,
                first + 6,
                first + 9,
                first + 12,
                first + 15,
                first + 18,
                first + 21,
                0,
                0,
                0,
                0,
                0,
                0,
                0,
                0,
            );
            _mm512_castps512_ps256(_mm512_permutex2var_ps(lo, idx, hi))
        };
        let p = [axis(0), axis(1), axis(2)];
        let o = [fan.origin.x, fan.origin.y, fan.origin.z].map(|v| _mm256_set1_ps(v));

        // `cut_to_range`: within range when `(p - origin).norm() <= max_range`
        // (`Point3::norm`: the float sum of squares, a double root), else
        // the end is `origin + (p - origin).normalized() * (float) max_range`
        let v = [_mm256_sub_ps(p[0], o[0]), _mm256_sub_ps(p[1], o[1]), _mm256_sub_ps(p[2], o[2])];
        let mut within: __mmask8 = 0xff;
        let mut end = p;
        if max_range >= 0.0 {
            let norm = _mm512_sqrt_pd(_mm512_cvtps_pd(squared_norm(v)));
            within = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(norm, _mm512_set1_pd(max_range));
            if within != 0xff {
                // the norm rounded to float, as `Point3::normalize` divides
                let (norm, range) = (_mm512_cvtpd_ps(norm), _mm256_set1_ps(max_range as f32));
                for i in 0..3 {
                    let cut = _mm256_add_ps(o[i], _mm256_mul_ps(_mm256_div_ps(v[i], norm), range));
                    // `p` in the lanes within range (a 512-bit blend: the
                    // 256-bit one would need AVX-512VL)
                    end[i] = _mm512_castps512_ps256(_mm512_mask_blend_ps(
                        __mmask16::from(within),
                        _mm512_castps256_ps512(cut),
                        _mm512_castps256_ps512(p[i]),
                    ));
                }
            }
        }

        // the end voxel: `coordToKeyChecked` per axis, then its Morton code
        let factor = _mm512_set1_pd(keys.resolution_factor());
        let center = f64::from(crate::key::KEY_CENTER);
        let mut in_map: __mmask8 = 0xff;
        let mut code = _mm512_setzero_si512();
        for (i, &pa) in end.iter().enumerate() {
            let floored = _mm512_roundscale_pd::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(_mm512_mul_pd(
                factor,
                _mm512_cvtps_pd(pa),
            ));
            in_map &= _mm512_cmp_pd_mask::<_CMP_GE_OQ>(floored, _mm512_set1_pd(-center))
                & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(floored, _mm512_set1_pd(center));
            let key = _mm256_add_epi32(_mm512_cvttpd_epi32(floored), _mm256_set1_epi32(center as i32));
            let spread = spread_bits(_mm512_cvtepu32_epi64(key));
            code = _mm512_or_si512(code, _mm512_sll_epi64(spread, _mm_cvtsi32_si128(i as i32)));
        }
        let hit = in_map & within;
        let to = &mut ends[hits..hits + LANES];
        // SAFETY: `to` holds LANES codes, 64 bytes
        unsafe { _mm512_storeu_si512(to.as_mut_ptr().cast(), _mm512_maskz_compress_epi64(hit, code)) };
        hits += hit.count_ones() as usize;

        // the ray (`RayFan::ray`): direction, length, per axis the step,
        // the first border's distance and the distance between borders
        let d = if within == 0xff {
            v
        } else {
            [_mm256_sub_ps(end[0], o[0]), _mm256_sub_ps(end[1], o[1]), _mm256_sub_ps(end[2], o[2])]
        };
        let length = _mm512_cvtpd_ps(_mm512_sqrt_pd(_mm512_cvtps_pd(squared_norm(d))));
        let kept = in_map & _mm512_cmpneq_epu64_mask(code, _mm512_set1_epi64(fan.origin_code as i64));
        let n = rays.len;
        let store_pd = |v: __m512d, to: &mut [f64]| {
            let to = &mut to[n..n + LANES];
            // SAFETY: `to` holds LANES values, 64 bytes
            unsafe { _mm512_storeu_pd(to.as_mut_ptr(), _mm512_maskz_compress_pd(kept, v)) };
        };
        let store_epi = |v: __m512i, to: &mut [u64]| {
            let to = &mut to[n..n + LANES];
            // SAFETY: `to` holds LANES values, 64 bytes
            unsafe { _mm512_storeu_si512(to.as_mut_ptr().cast(), _mm512_maskz_compress_epi64(kept, v)) };
        };
        let mut step = _mm512_set1_epi64(0b111);
        for i in 0..3 {
            let dir = _mm512_cvtps_pd(_mm256_div_ps(d[i], length));
            let up = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(dir, _mm512_setzero_pd());
            let moves = up | _mm512_cmp_pd_mask::<_CMP_LT_OQ>(dir, _mm512_setzero_pd());
            let border =
                _mm512_mask_blend_pd(up, _mm512_set1_pd(fan.to_border[i][0]), _mm512_set1_pd(fan.to_border[i][1]));
            let never = _mm512_set1_pd(f64::MAX);
            store_pd(_mm512_mask_div_pd(never, moves, border, dir), &mut rays.t[i]);
            store_pd(
                _mm512_mask_div_pd(never, moves, _mm512_set1_pd(fan.resolution), _mm512_abs_pd(dir)),
                &mut rays.dt[i],
            );
            step = _mm512_mask_or_epi64(step, up, step, _mm512_set1_epi64(AXIS_MASKS[i] as i64));
        }
        store_epi(step, &mut rays.step);
        store_epi(code, &mut rays.end);
        store_pd(_mm512_cvtps_pd(length), &mut rays.length);
        rays.len += kept.count_ones() as usize;
    }
    occupied(&ends[..hits]);
    for &p in eight.remainder() {
        let (within, end) = crate::ray::cut_to_range(p, fan.origin, max_range);
        let Ok(key) = keys.key(end) else { continue };
        let code = crate::morton::MortonCode::encode(key).0;
        if within {
            occupied(&[code]);
        }
        if let Some(ray) = fan.ray(end, code) {
            rays.push(ray);
        }
    }
}

/// `Point3::norm_sq` of eight vectors given by axis: `(x * x + y * y) + z * z`
/// in float.
#[target_feature(enable = "avx512f")]
#[inline]
fn squared_norm(v: [__m256; 3]) -> __m256 {
    _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(v[0], v[0]), _mm256_mul_ps(v[1], v[1])), _mm256_mul_ps(v[2], v[2]))
}

/// [`crate::morton::spread_bits`] in every lane (values below 2^16).
#[target_feature(enable = "avx512f")]
#[inline]
fn spread_bits(v: __m512i) -> __m512i {
    let step = |x: __m512i, shift: u32, mask: u64| {
        _mm512_and_si512(
            _mm512_or_si512(x, _mm512_sll_epi64(x, _mm_cvtsi32_si128(shift as i32))),
            _mm512_set1_epi64(mask as i64),
        )
    };
    let x = step(v, 16, 0x0000_ff00_00ff);
    let x = step(x, 8, 0x00f0_0f00_f00f);
    let x = step(x, 4, 0x0c30_c30c_30c3);
    step(x, 2, 0x2492_4924_9249)
}

/// The rays in the lanes between two calls of [`walk`]: two groups of
/// [`LANES`], each walking a packet, stepped alternately so that one
/// group's chain of compares and additions overlaps the other's.
#[derive(Clone, Copy)]
struct Lanes {
    groups: [Saved; 2],
}

/// One group's registers, stored.
#[derive(Clone, Copy)]
struct Saved {
    t: [[f64; LANES]; 3],
    dt: [[f64; LANES]; 3],
    step: [u64; LANES],
    code: [u64; LANES],
    end: [u64; LANES],
    length: [f64; LANES],
    alive: __mmask8,
}

impl Default for Lanes {
    /// Every lane holds [`FanRay::finished`], and no lane is alive.
    fn default() -> Self {
        let r = FanRay::finished();
        let saved = Saved {
            t: r.t_max.map(|t| [t; LANES]),
            dt: r.t_delta.map(|dt| [dt; LANES]),
            step: [step_bits(&r); LANES],
            code: [r.code; LANES],
            end: [r.end_code; LANES],
            length: [r.length; LANES],
            alive: 0,
        };
        Lanes { groups: [saved; 2] }
    }
}

/// [`LANES`] rays in registers (named fields: arrays of vectors would be
/// kept in memory).
#[derive(Clone, Copy)]
struct Group {
    t0: __m512d,
    t1: __m512d,
    t2: __m512d,
    dt0: __m512d,
    dt1: __m512d,
    dt2: __m512d,
    step: __m512i,
    code: __m512i,
    end: __m512i,
    length: __m512d,
    /// The lanes whose ray has not ended.
    alive: __mmask8,
}

impl Group {
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn load(s: &Saved) -> Self {
        // SAFETY: each array holds LANES values, 64 bytes
        let pd = |a: &[f64; LANES]| unsafe { _mm512_loadu_pd(a.as_ptr()) };
        // SAFETY: as for `pd`
        let epi = |a: &[u64; LANES]| unsafe { _mm512_loadu_si512(a.as_ptr().cast()) };
        Group {
            t0: pd(&s.t[0]),
            t1: pd(&s.t[1]),
            t2: pd(&s.t[2]),
            dt0: pd(&s.dt[0]),
            dt1: pd(&s.dt[1]),
            dt2: pd(&s.dt[2]),
            step: epi(&s.step),
            code: epi(&s.code),
            end: epi(&s.end),
            length: pd(&s.length),
            alive: s.alive,
        }
    }

    #[target_feature(enable = "avx512f")]
    #[inline]
    fn store(&self, s: &mut Saved) {
        // SAFETY: each array holds LANES values, 64 bytes
        let pd = |v: __m512d, a: &mut [f64; LANES]| unsafe { _mm512_storeu_pd(a.as_mut_ptr(), v) };
        // SAFETY: as for `pd`
        let epi = |v: __m512i, a: &mut [u64; LANES]| unsafe { _mm512_storeu_si512(a.as_mut_ptr().cast(), v) };
        pd(self.t0, &mut s.t[0]);
        pd(self.t1, &mut s.t[1]);
        pd(self.t2, &mut s.t[2]);
        pd(self.dt0, &mut s.dt[0]);
        pd(self.dt1, &mut s.dt[1]);
        pd(self.dt2, &mut s.dt[2]);
        epi(self.step, &mut s.step);
        epi(self.code, &mut s.code);
        epi(self.end, &mut s.end);
        pd(self.length, &mut s.length);
        s.alive = self.alive;
    }

    /// One step of every lane (`WalkState::next_code`): the axis of the
    /// smallest `t_max`, ties to the higher axis (`min_axis`). A lane's ray
    /// ends (it leaves `alive`) when the new voxel is the end voxel, or every
    /// `t_max` lies beyond the ray's length (OctoMap's `min(min(..), ..) >
    /// length`, with no NaN among them). Lanes no longer alive step on
    /// unseen.
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn step(&mut self) {
        let (t0, t1, t2) = (self.t0, self.t1, self.t2);
        let lt01 = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(t0, t1);
        let lt02 = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(t0, t2);
        let lt12 = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(t1, t2);
        let s0 = lt01 & lt02;
        let s1 = !lt01 & lt12;
        let s2 = !(s0 | s1);
        self.t0 = _mm512_mask_add_pd(t0, s0, t0, self.dt0);
        self.t1 = _mm512_mask_add_pd(t1, s1, t1, self.dt1);
        self.t2 = _mm512_mask_add_pd(t2, s2, t2, self.dt2);
        let mask = _mm512_mask_blend_epi64(
            s0,
            _mm512_mask_blend_epi64(
                s1,
                _mm512_set1_epi64(AXIS_MASKS[2] as i64),
                _mm512_set1_epi64(AXIS_MASKS[1] as i64),
            ),
            _mm512_set1_epi64(AXIS_MASKS[0] as i64),
        );
        self.code = step_code(self.code, mask, _mm512_and_si512(mask, self.step));
        let nearest = _mm512_min_pd(_mm512_min_pd(self.t0, self.t1), self.t2);
        let beyond = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(nearest, self.length);
        self.alive &= !(_mm512_cmpeq_epi64_mask(self.code, self.end) | beyond);
    }

    /// A packet's lanes: the rays of `rays` from `at` on, eight or as many
    /// as are left, each from the origin's voxel; and where the rays after
    /// them start. `rays` must be padded and `at <= rays.len` (else the
    /// slices below panic). A new group rather than one changed through a
    /// reference, and always inlined (so without `target_feature`, which
    /// forbids that): where the compiler left the call out of line, the
    /// group went through memory, and with a reference kept it there
    /// through the whole walk (inlined, casting is 5-8% faster indoors at
    /// 0.2 m).
    ///
    /// # Safety
    /// The processor must support AVX-512F.
    #[inline(always)]
    unsafe fn start(rays: &LaneRays, at: usize, origin: __m512i) -> (Self, usize) {
        debug_assert!(at <= rays.len && rays.padded);
        // SAFETY: the processor has AVX-512F (the caller's contract), and
        // the slice holds LANES values, 64 bytes
        let pd = |from: &[f64]| unsafe { _mm512_loadu_pd(from[at..at + LANES].as_ptr()) };
        // SAFETY: as for `pd`
        let epi = |from: &[u64]| unsafe { _mm512_loadu_si512(from[at..at + LANES].as_ptr().cast()) };
        let n = (rays.len - at).min(LANES);
        let group = Group {
            t0: pd(&rays.t[0]),
            t1: pd(&rays.t[1]),
            t2: pd(&rays.t[2]),
            dt0: pd(&rays.dt[0]),
            dt1: pd(&rays.dt[1]),
            dt2: pd(&rays.dt[2]),
            step: epi(&rays.step),
            code: origin,
            end: epi(&rays.end),
            length: pd(&rays.length),
            alive: ((1u32 << n) - 1) as __mmask8,
        };
        (group, at + n)
    }
}

/// Appends the codes of the lanes in `going` to `buffer` at `filled`,
/// less a lane's that repeats the code its neighbour below appends (the
/// rays of a packet often enter the same voxel at the same step); returns
/// the new `filled`.
///
/// # Safety
/// `filled <= BUFFER`: the store writes [`LANES`] codes from `filled`.
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn append(buffer: &mut [u64; BUFFER + LANES], filled: usize, code: __m512i, going: __mmask8) -> usize {
    debug_assert!(filled <= BUFFER);
    let below = _mm512_alignr_epi64::<7>(code, code);
    let repeat = _mm512_cmpeq_epi64_mask(code, below) & (going << 1);
    let kept = going & !repeat;
    // SAFETY: `filled <= BUFFER` (the caller's contract), and the buffer
    // has LANES slots more
    unsafe { _mm512_storeu_si512(buffer.as_mut_ptr().add(filled).cast(), _mm512_maskz_compress_epi64(kept, code)) };
    filled + kept.count_ones() as usize
}

/// Walks the rays of `rays` (all from the voxel `origin_code`) through the
/// lanes, calling `visit` with the codes of the voxels they step into, in
/// batches and in no particular order (a voxel may come more than once).
/// Returns once every ray of `rays` has entered a lane; with `drain`, once
/// every lane's ray has ended. Rays still in the lanes stay in `lanes` for
/// the next call. Packets are made of rays in the order of `rays`.
#[target_feature(enable = "avx512f,bmi2,popcnt")]
fn walk(
    lanes: &mut Lanes,
    rays: &LaneRays,
    origin_code: u64,
    drain: bool,
    buffer: &mut [u64; BUFFER + LANES],
    mut visit: impl FnMut(&[u64]),
) {
    assert!(rays.padded, "LaneRays::pad before walk");
    let mut next = 0usize;
    // through an opaque pointer, so that `fill` is never inlined here
    // (`#[inline(never)]` did not keep it out)
    let fill_fn: Fill = std::hint::black_box(fill);
    loop {
        // SAFETY: the processor has AVX-512F and POPCNT (this function
        // runs only where its target features are); `rays` is padded
        // (asserted above), `next` starts at 0 and `fill` keeps it within
        // `rays.len`
        let (filled, done) = unsafe { fill_fn(lanes, rays, &mut next, origin_code, drain, buffer) };
        visit(&buffer[..filled]);
        if done {
            return;
        }
    }
}

/// [`fill`]'s signature, for the pointer [`walk`] calls it through.
type Fill = unsafe fn(&mut Lanes, &LaneRays, &mut usize, u64, bool, &mut [u64; BUFFER + LANES]) -> (usize, bool);

/// [`walk`]'s steps until `buffer` is nearly full (returns its codes'
/// count and `false`) or the walk is done (`true`). Apart from `visit`, so
/// that no call sits inside the loop: around a call every vector register
/// is lost, and the lanes' registers would be kept in memory all along.
///
/// # Safety
/// The processor must support AVX-512F and POPCNT, `rays` must be padded
/// and `*next <= rays.len`.
#[target_feature(enable = "avx512f,popcnt")]
unsafe fn fill(
    lanes: &mut Lanes,
    rays: &LaneRays,
    next: &mut usize,
    origin_code: u64,
    drain: bool,
    buffer: &mut [u64; BUFFER + LANES],
) -> (usize, bool) {
    debug_assert!(rays.padded && *next <= rays.len);
    let mut filled = 0usize;
    let origin = _mm512_set1_epi64(origin_code as i64);
    let mut a = Group::load(&lanes.groups[0]);
    let mut b = Group::load(&lanes.groups[1]);
    let len = rays.len;
    let mut at = *next;
    let done = loop {
        a.step();
        b.step();
        // SAFETY: `filled <= BUFFER - LANES` at the start of each turn
        // (the `break` below), and each append adds at most LANES
        unsafe {
            filled = append(buffer, filled, a.code, a.alive);
            filled = append(buffer, filled, b.code, b.alive);
        }
        // a group whose packet has ended takes the next one (a branch
        // taken once a packet: a packet's rays take tens of steps); `at`
        // stays within `len` (the caller's contract for `*next`, then
        // `start`)
        if a.alive == 0 {
            // SAFETY: the processor has AVX-512F (this function's contract)
            (a, at) = unsafe { Group::start(rays, at, origin) };
        }
        if b.alive == 0 {
            // SAFETY: as for `a`
            (b, at) = unsafe { Group::start(rays, at, origin) };
        }
        if at == len && (!drain || (a.alive | b.alive) == 0) {
            break true;
        }
        if filled > BUFFER - LANES {
            break false;
        }
    };
    a.store(&mut lanes.groups[0]);
    b.store(&mut lanes.groups[1]);
    *next = at;
    (filled, done)
}

/// `code` moved one voxel along the axis whose bits are `mask`: the axis's
/// bits minus `by` (the mask itself for a step up: `x - mask` is `(x |
/// !mask) + 1`, whose carry runs through the other axes' bits; the axis's
/// lowest bit for a step down, whose borrow runs through them), the other
/// bits kept.
#[target_feature(enable = "avx512f")]
#[inline]
fn step_code(code: __m512i, mask: __m512i, by: __m512i) -> __m512i {
    let moved = _mm512_sub_epi64(_mm512_and_si512(code, mask), by);
    // bitwise `mask ? moved : code`
    _mm512_ternarylogic_epi64::<0xe4>(moved, code, mask)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::morton::MortonCode;

    /// A deterministic generator (64-bit LCG, high bits).
    struct Lcg(u64);

    impl Lcg {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            self.0 >> 11
        }

        fn float(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * (self.next() % 1_000_000) as f32 / 1e6
        }
    }

    /// End points that probe the set-up's corners: voxel borders, rays along
    /// axes and diagonals, ends inside the origin's voxel, points outside
    /// the map, plain random ones.
    fn points(rng: &mut Lcg, origin: Point3, res: f64, n: usize) -> Vec<Point3> {
        let res = res as f32;
        (0..n)
            .map(|i| {
                let mut p = Point3::new(rng.float(-6.0, 6.0), rng.float(-6.0, 6.0), rng.float(-3.0, 3.0));
                let (a, b) = (p.x, p.y.abs().max(0.5));
                match i % 12 {
                    0 => p = Point3::new((p.x / res).round() * res, (p.y / res).round() * res, p.z),
                    1 => p = Point3::new(p.x, origin.y, origin.z),
                    2 => p = Point3::new(origin.x, origin.y, p.z),
                    // diagonals: from a voxel centre, equal t_max on two or
                    // three axes at every step (the ties)
                    3 => p = Point3::new(origin.x + a, origin.y + a, origin.z - a),
                    9 => p = Point3::new(origin.x, origin.y + a, origin.z + a),
                    10 => p = Point3::new(origin.x + b, origin.y, origin.z - b),
                    11 => p = Point3::new(origin.x - a, origin.y + a, origin.z),
                    // along z to a border: t_max may equal the length
                    8 => {
                        let up = if i % 2 == 0 { 1.0 } else { -1.0 };
                        p = Point3::new(origin.x, origin.y, origin.z + up * ((i % 7) as f32 + 0.5) * res)
                    }
                    4 => p = Point3::new(origin.x + 0.1 * res, origin.y - 0.1 * res, origin.z),
                    5 if i % 4 == 1 => p.x = 4.0e6,
                    6 => p = Point3::new(-p.x * 1e-3, p.y * 1e-3, 0.0),
                    _ => {}
                }
                p
            })
            .collect()
    }

    /// The scalar set-up's rays and occupied codes, in point order
    /// (`Casting::cast`'s end voxel and `RayFan::ray`).
    fn scalar_set_up(fan: &RayFan, keys: &KeySpace, points: &[Point3], max_range: f64) -> (LaneRays, Vec<u64>) {
        let mut rays = LaneRays::default();
        let mut occupied = Vec::new();
        for &p in points {
            let (within, end) = crate::ray::cut_to_range(p, fan.origin, max_range);
            let Ok(key) = keys.key(end) else { continue };
            let code = MortonCode::encode(key).0;
            if within {
                occupied.push(code);
            }
            if let Some(ray) = fan.ray(end, code) {
                rays.push(ray);
            }
        }
        (rays, occupied)
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// The vectorised set-up gives the scalar one's rays, bit for bit, and
    /// the same occupied codes, at resolutions from 1 cm to 1 m, with and
    /// without a maximum range (rays cut at it, ends beyond it not marked).
    #[test]
    fn set_up_matches_the_scalar_set_up() {
        if Avx512::detect().is_none() {
            eprintln!("skipped: no AVX-512F");
            return;
        }
        let mut rng = Lcg(3);
        for res in [0.01, 0.05, 0.1, 0.2, 0.37, 1.0] {
            let keys = KeySpace::new(res);
            for round in 0..20 {
                let mut origin = Point3::new(rng.float(-2.0, 2.0), rng.float(-2.0, 2.0), rng.float(-1.0, 1.0));
                if round % 2 == 0 {
                    origin = keys.key_to_point(keys.key(origin).unwrap());
                }
                let fan = RayFan::new(&keys, origin).unwrap();
                // not a multiple of eight
                let pts = points(&mut rng, origin, res, 253);
                // no range, a zero one, one that cuts most rays, one that cuts a few
                let max_range = [-1.0, 0.0, 1.5, 5.0][round % 4];
                let (want, want_occupied) = scalar_set_up(&fan, &keys, &pts, max_range);
                let mut got = LaneRays::default();
                let mut got_occupied = Vec::new();
                // SAFETY: AVX-512F, BMI2 and POPCNT are available (checked above)
                unsafe { set_up(&mut got, &fan, &keys, &pts, max_range, |c| got_occupied.extend_from_slice(c)) };
                assert_eq!(got_occupied, want_occupied, "res {res}");
                let n = want.len();
                assert_eq!(got.len(), n, "res {res}");
                for i in 0..3 {
                    assert_eq!(bits(&got.t[i][..n]), bits(&want.t[i][..n]), "t_max, axis {i}, res {res}");
                    assert_eq!(bits(&got.dt[i][..n]), bits(&want.dt[i][..n]), "t_delta, axis {i}, res {res}");
                }
                assert_eq!(got.step[..n], want.step[..n], "steps, res {res}");
                assert_eq!(got.end[..n], want.end[..n], "res {res}");
                assert_eq!(bits(&got.length[..n]), bits(&want.length[..n]), "res {res}");
            }
        }
    }

    /// The voxels a ray enters past the origin's, by the scalar walk.
    fn scalar_walk(fan: &RayFan, keys: &KeySpace, p: Point3) -> Vec<u64> {
        let Ok(key) = keys.key(p) else { return Vec::new() };
        let mut codes = Vec::new();
        fan.for_each_code(p, MortonCode::encode(key).0, |c| codes.push(c));
        codes.into_iter().skip(1).collect()
    }

    /// Walked alone, each ray enters exactly the scalar walk's voxels, in
    /// its order; walked together, over several set-ups (rays stay in the
    /// lanes from one call to the next), the scan enters the same set of
    /// voxels, every ray's first and last included.
    #[test]
    fn walks_match_the_scalar_walk() {
        if Avx512::detect().is_none() {
            eprintln!("skipped: no AVX-512F");
            return;
        }
        let mut rng = Lcg(11);
        for res in [0.01, 0.1, 0.2, 1.0] {
            let keys = KeySpace::new(res);
            let origin = Point3::new(rng.float(-1.0, 1.0), rng.float(-1.0, 1.0), rng.float(-1.0, 1.0));
            // a voxel's centre, where diagonal rays tie at every border
            let origin = keys.key_to_point(keys.key(origin).unwrap());
            let fan = RayFan::new(&keys, origin).unwrap();
            let pts = points(&mut rng, origin, res, 700);
            let mut rays = LaneRays::default();
            let mut buffer = [0u64; BUFFER + LANES];
            for &p in &pts {
                rays.clear();
                // SAFETY: AVX-512F, BMI2 and POPCNT are available (checked above)
                unsafe { set_up(&mut rays, &fan, &keys, &[p], -1.0, |_: &[u64]| {}) };
                rays.pad();
                let mut got = Vec::new();
                // SAFETY: as for `set_up`
                unsafe {
                    walk(&mut Lanes::default(), &rays, fan.origin_code, true, &mut buffer, |c| got.extend_from_slice(c))
                };
                assert_eq!(got, scalar_walk(&fan, &keys, p), "res {res}, end {p:?}");
            }
            let want: std::collections::BTreeSet<u64> = pts.iter().flat_map(|&p| scalar_walk(&fan, &keys, p)).collect();
            let mut got = std::collections::BTreeSet::new();
            let mut lanes = Lanes::default();
            let chunks: Vec<&[Point3]> = pts.chunks(97).collect();
            for (i, chunk) in chunks.iter().enumerate() {
                rays.clear();
                // SAFETY: AVX-512F, BMI2 and POPCNT are available (checked above)
                unsafe { set_up(&mut rays, &fan, &keys, chunk, -1.0, |_: &[u64]| {}) };
                rays.pad();
                let last = i + 1 == chunks.len();
                // SAFETY: as for `set_up`
                unsafe {
                    walk(&mut lanes, &rays, fan.origin_code, last, &mut buffer, |c| got.extend(c.iter().copied()))
                };
            }
            assert!(want.len() > 300, "the rays enter many voxels ({})", want.len());
            assert_eq!(got, want, "res {res}");
        }
    }
}
