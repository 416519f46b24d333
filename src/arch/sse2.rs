//! SSE and SSE2: part of every x86-64 processor, so used without a
//! detection.

use crate::geometry::Point3;
use crate::key::{Key, KEY_CENTER};
use std::arch::x86_64::*;

/// `KeySpace::key` for points inside the map, two axes per instruction:
/// the same double products and range tests as `KeySpace::coord_to_key`,
/// in half the instructions of three scalar passes (a point query's
/// conversion is on its critical path). `None` when an axis is out of
/// range or not finite. With the octant of `KeySpace::key_and_octant`: a
/// key's top bit is set exactly when the product is at least zero (-0.0
/// included).
///
/// A product `v` has a key when `floor(v)` lies in [-32768, 32768), that
/// is when `v` does (integer bounds; never for NaN). There, `floor(v)` is
/// the truncation `t`, less one when `t > v` (a negative fraction): exact,
/// in three instructions where SSE2 has no `floor` (builds that enable
/// SSE4.1 use its `roundpd` instead: [`super::sse41`]).
#[cfg_attr(target_feature = "sse4.1", allow(dead_code))]
#[inline(always)]
pub(crate) fn key_and_octant(resolution_factor: f64, p: Point3) -> Option<(Key, usize)> {
    // SAFETY: SSE2 is part of the x86-64 baseline (these intrinsics are
    // only `unsafe` for their `target_feature` attribute), and no memory
    // is accessed.
    let (ok, octant, xy, z) = unsafe {
        let factor = _mm_set1_pd(resolution_factor);
        let xy = _mm_mul_pd(factor, _mm_cvtps_pd(_mm_set_ps(0.0, 0.0, p.y, p.x)));
        // z in lane 0 alone (lane 1 converts 0.0, which is in range): a
        // broadcast was compiled into a 16-byte load of a 12-byte
        // point copied to the stack, which the processor cannot
        // forward from the copy's two stores (a stall on every point)
        let z = _mm_mul_pd(factor, _mm_cvtps_pd(_mm_set_ss(p.z)));
        let zero = _mm_setzero_pd();
        let octant = _mm_movemask_pd(_mm_cmpge_pd(xy, zero)) | (_mm_movemask_pd(_mm_cmpge_sd(z, zero)) & 1) << 2;
        let (lo, hi) = (_mm_set1_pd(-f64::from(KEY_CENTER)), _mm_set1_pd(f64::from(KEY_CENTER)));
        // false for NaN, as the scalar range test
        let in_range = |v| _mm_and_pd(_mm_cmpge_pd(v, lo), _mm_cmplt_pd(v, hi));
        let ok = _mm_movemask_pd(_mm_and_pd(in_range(xy), in_range(z))) == 3;
        let floor = |v| {
            let t = _mm_cvttpd_epi32(v);
            // all ones (-1) in the 64-bit lanes to step down, moved to the
            // 32-bit lanes 0 and 1 of the truncations
            let down = _mm_castpd_si128(_mm_cmpgt_pd(_mm_cvtepi32_pd(t), v));
            _mm_add_epi32(t, _mm_shuffle_epi32::<0b00_00_10_00>(down))
        };
        (ok, octant as usize, _mm_cvtsi128_si64(floor(xy)) as u64, _mm_cvtsi128_si32(floor(z)) as u32)
    };
    key_of_floors(ok, octant, xy, z)
}

/// The key from the floors of the three products (`xy` the x and y lanes
/// of a 64-bit register, `z` the z lane), when `ok`, with its octant.
#[inline(always)]
pub(super) fn key_of_floors(ok: bool, octant: usize, xy: u64, z: u32) -> Option<(Key, usize)> {
    let c = KEY_CENTER;
    ok.then(|| {
        let key = Key([
            (xy as u32).wrapping_add(c) as u16,
            ((xy >> 32) as u32).wrapping_add(c) as u16,
            z.wrapping_add(c) as u16,
        ]);
        (key, octant)
    })
}

/// The DDA's three `t_max` and their increments. `step` advances
/// the smallest (`min_axis`: ties go to the higher axis) and returns its
/// axis's slot (x 1, y 2, z 0; see `ray::slots`). The choice is made with
/// compare masks, not branches: the axis changes irregularly along a ray,
/// and a mispredicted branch would cost more than the whole step.
/// Adding a masked-out increment adds +0.0, which leaves a `t_max`
/// unchanged (none is NaN; a -0.0 would become +0.0, which compares the
/// same).
#[derive(Clone, Copy)]
pub struct StepClock {
    t: [__m128d; 3],
    dt: [__m128d; 3],
}

impl StepClock {
    /// The clock of a ray starting at `t` (per axis, the ray parameter of
    /// its first border) stepping by `dt`.
    #[inline(always)]
    pub(crate) fn new(t: [f64; 3], dt: [f64; 3]) -> Self {
        // SAFETY: SSE2 is part of the x86-64 baseline (these intrinsics
        // are only `unsafe` for their `target_feature` attribute), and no
        // memory is accessed.
        unsafe {
            StepClock {
                t: [_mm_set_sd(t[0]), _mm_set_sd(t[1]), _mm_set_sd(t[2])],
                dt: [_mm_set_sd(dt[0]), _mm_set_sd(dt[1]), _mm_set_sd(dt[2])],
            }
        }
    }

    /// Advances the smallest `t_max` by its increment; returns its slot.
    #[inline(always)]
    pub(crate) fn step(&mut self) -> usize {
        // SAFETY: as in `new`: baseline SSE2, registers only.
        unsafe {
            let [t0, t1, t2] = self.t;
            let lt01 = _mm_cmplt_sd(t0, t1);
            let s0 = _mm_and_pd(lt01, _mm_cmplt_sd(t0, t2));
            let s1 = _mm_andnot_pd(lt01, _mm_cmplt_sd(t1, t2));
            self.t = [
                _mm_add_sd(t0, _mm_and_pd(s0, self.dt[0])),
                _mm_add_sd(t1, _mm_and_pd(s1, self.dt[1])),
                // z steps when neither x nor y does
                _mm_add_sd(t2, _mm_andnot_pd(_mm_or_pd(s0, s1), self.dt[2])),
            ];
            // the sign bits of (s0, s1): the slot
            _mm_movemask_pd(_mm_unpacklo_pd(s0, s1)) as usize
        }
    }

    /// `min(min(t_max[0], t_max[1]), t_max[2])`.
    #[inline(always)]
    pub(crate) fn min(&self) -> f64 {
        // SAFETY: as in `new`: baseline SSE2, registers only.
        unsafe { _mm_cvtsd_f64(_mm_min_sd(_mm_min_sd(self.t[0], self.t[1]), self.t[2])) }
    }
}

/// Asks for the cache line holding `x` (into every cache level).
#[inline(always)]
pub(crate) fn prefetch<T>(x: &T) {
    // SAFETY: a prefetch is a hint that never faults nor changes memory;
    // SSE is part of the x86-64 baseline.
    unsafe { _mm_prefetch::<_MM_HINT_T0>((x as *const T).cast()) }
}
