//! SSE4.1, used when the build enables it (`-C target-cpu=x86-64-v2` or
//! later): `roundpd`, a `floor` in one instruction.

use crate::geometry::Point3;
use crate::key::{Key, KEY_CENTER};
use std::arch::x86_64::*;

/// [`super::sse2::key_and_octant`] with `roundpd` as the `floor`, the
/// range tests on the floors.
#[target_feature(enable = "sse4.1")]
#[inline]
pub(crate) fn key_and_octant(resolution_factor: f64, p: Point3) -> Option<(Key, usize)> {
    let (ok, octant, xy, z) = {
        let factor = _mm_set1_pd(resolution_factor);
        let xy = _mm_mul_pd(factor, _mm_cvtps_pd(_mm_set_ps(0.0, 0.0, p.y, p.x)));
        // z in lane 0 alone (lane 1 converts 0.0, which is in range): a
        // broadcast was compiled into a 16-byte load of a 12-byte
        // point copied to the stack, which the processor cannot
        // forward from the copy's two stores (a stall on every point)
        let z = _mm_mul_pd(factor, _mm_cvtps_pd(_mm_set_ss(p.z)));
        let zero = _mm_setzero_pd();
        let octant = _mm_movemask_pd(_mm_cmpge_pd(xy, zero)) | (_mm_movemask_pd(_mm_cmpge_sd(z, zero)) & 1) << 2;
        let (xy, z) = (_mm_floor_pd(xy), _mm_floor_pd(z));
        let (lo, hi) = (_mm_set1_pd(-f64::from(KEY_CENTER)), _mm_set1_pd(f64::from(KEY_CENTER)));
        // false for NaN, as the scalar range test
        let in_range = |v| _mm_and_pd(_mm_cmpge_pd(v, lo), _mm_cmplt_pd(v, hi));
        let ok = _mm_movemask_pd(_mm_and_pd(in_range(xy), in_range(z))) == 3;
        let (xy, z) = (_mm_cvttpd_epi32(xy), _mm_cvttpd_epi32(z));
        (ok, octant as usize, _mm_cvtsi128_si64(xy) as u64, _mm_cvtsi128_si32(z) as u32)
    };
    super::sse2::key_of_floors(ok, octant, xy, z)
}
