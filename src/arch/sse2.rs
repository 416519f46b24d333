//! SSE and SSE2: part of every x86-64 processor, so used without a
//! detection.

use std::arch::x86_64::*;

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
