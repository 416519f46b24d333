//! A range of Morton codes seen as the aligned cubes it covers, and a
//! conservative test whether a ray's segment can reach one of them: an
//! update restricted to the range casts only the rays that can.

use crate::geometry::Point3;
use crate::key::{KeySpace, KEY_CENTER, TREE_DEPTH};
use crate::morton::MortonCode;
use std::ops::Range;

/// Every Morton code of the map: 16 bits per axis.
pub(crate) const CODE_SPACE: u64 = 1 << (3 * TREE_DEPTH as u32);

/// An axis-aligned box in metres, `[min, max]` per axis.
type MetricBox = ([f64; 3], [f64; 3]);

/// The cubes of a range of Morton codes, each grown by a voxel on every
/// side so that float rounding in the ray walk cannot reach a voxel the
/// test misses.
pub(crate) struct CodeRegion {
    /// The box around all cubes, tested first.
    outer: MetricBox,
    /// The cubes, largest first (most rays that reach the range reach those).
    cubes: Vec<MetricBox>,
}

impl CodeRegion {
    /// The region of `codes` (clipped to the map's codes) in `keys`' map.
    pub(crate) fn new(keys: &KeySpace, codes: &Range<u64>) -> Self {
        let res = keys.resolution();
        let end = codes.end.min(CODE_SPACE);
        let mut cubes = Vec::new();
        let mut start = codes.start;
        while start < end {
            // the largest aligned block of 8^level codes starting here
            let mut level = (start.trailing_zeros() / 3).min(u32::from(TREE_DEPTH));
            while start + (1u64 << (3 * level)) > end {
                level -= 1;
            }
            let low = MortonCode(start).decode().0;
            let edge = f64::from(1u32 << level);
            let min = low.map(|k| (f64::from(k) - f64::from(KEY_CENTER) - 1.0) * res);
            let max = low.map(|k| (f64::from(k) - f64::from(KEY_CENTER) + edge + 1.0) * res);
            cubes.push((min, max, level));
            start += 1 << (3 * level);
        }
        cubes.sort_by_key(|c| std::cmp::Reverse(c.2));
        let mut outer = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for (min, max, _) in &cubes {
            for i in 0..3 {
                outer.0[i] = outer.0[i].min(min[i]);
                outer.1[i] = outer.1[i].max(max[i]);
            }
        }
        CodeRegion { outer, cubes: cubes.into_iter().map(|(min, max, _)| (min, max)).collect() }
    }

    /// False only when the segment from `a` to `b` misses every cube: then
    /// no voxel its walk visits, nor its end, lies in the range.
    pub(crate) fn may_touch(&self, a: Point3, b: Point3) -> bool {
        segment_meets_box(a, b, &self.outer) && self.cubes.iter().any(|c| segment_meets_box(a, b, c))
    }
}

/// Where the rays of a scan leave a range of Morton codes for good: a
/// cover of the range by at most [`RayStop::COVER`] aligned cubes (grown
/// by a voxel), and the rays' common origin. A cube is convex, so once a
/// ray has left every cube it met it never comes back: the voxels it walks
/// after that lie outside the range, and the walk can stop there.
#[derive(Clone)]
pub(crate) struct RayStop {
    origin: [f64; 3],
    cover: Vec<MetricBox>,
    /// Added to the last exit: more than a voxel's diagonal, for the
    /// rounding of the walk's distances and of the direction.
    margin: f64,
}

impl RayStop {
    /// Most cubes in the cover.
    const COVER: u64 = 16;

    /// The stop for rays from `origin` in `keys`' map and the range `codes`.
    pub(crate) fn new(keys: &KeySpace, codes: &Range<u64>, origin: Point3) -> Self {
        let res = keys.resolution();
        let (start, last) = (codes.start, codes.end.min(CODE_SPACE) - 1);
        // the finest level of aligned blocks at which a few cover the range
        let level = (0..=u32::from(TREE_DEPTH))
            .find(|&l| (last >> (3 * l)) - (start >> (3 * l)) < Self::COVER)
            .unwrap_or(u32::from(TREE_DEPTH));
        let edge = f64::from(1u32 << level);
        let cover = ((start >> (3 * level))..=(last >> (3 * level)))
            .map(|block| {
                let low = MortonCode(block << (3 * level)).decode().0;
                let min = low.map(|k| (f64::from(k) - f64::from(KEY_CENTER) - 1.0) * res);
                let max = low.map(|k| (f64::from(k) - f64::from(KEY_CENTER) + edge + 1.0) * res);
                (min, max)
            })
            .collect();
        RayStop { origin: [origin.x, origin.y, origin.z].map(f64::from), cover, margin: 4.0 * res }
    }

    /// The distance (metres along the unit direction `dir` from the origin)
    /// beyond which the ray meets no cube of the cover: a walk can end there.
    pub(crate) fn length(&self, dir: [f64; 3]) -> f64 {
        let mut last = f64::NEG_INFINITY;
        for (min, max) in &self.cover {
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for i in 0..3 {
                if dir[i] == 0.0 {
                    if self.origin[i] < min[i] || self.origin[i] > max[i] {
                        t1 = f64::NEG_INFINITY;
                    }
                    continue;
                }
                let (ta, tb) = ((min[i] - self.origin[i]) / dir[i], (max[i] - self.origin[i]) / dir[i]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
            if t0 <= t1 {
                last = last.max(t1);
            }
        }
        last + self.margin
    }
}

/// The slab test: whether the segment from `a` to `b` meets the box.
#[inline]
fn segment_meets_box(a: Point3, b: Point3, (min, max): &MetricBox) -> bool {
    let (a, b) = ([a.x, a.y, a.z].map(f64::from), [b.x, b.y, b.z].map(f64::from));
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for i in 0..3 {
        let d = b[i] - a[i];
        if d == 0.0 {
            if a[i] < min[i] || a[i] > max[i] {
                return false;
            }
            continue;
        }
        let (ta, tb) = ((min[i] - a[i]) / d, (max[i] - a[i]) / d);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
        if t0 > t1 {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubes_cover_the_range_exactly() {
        let keys = KeySpace::new(1.0);
        for (start, end) in [(0, CODE_SPACE), (3 << 45, 5 << 45), (12345, 1 << 40), (7, 8)] {
            let r = CodeRegion::new(&keys, &(start..end));
            let volume: f64 = r.cubes.iter().map(|(min, max)| (max[0] - min[0] - 2.0).powi(3)).sum();
            assert_eq!(volume, (end - start) as f64, "{start}..{end}");
        }
        // the whole map's single cube
        assert_eq!(CodeRegion::new(&keys, &(0..CODE_SPACE)).cubes.len(), 1);
    }

    #[test]
    fn segments_are_tested_against_the_cubes() {
        let keys = KeySpace::new(1.0);
        // codes below 2^45: the octant of negative x, y and z
        let r = CodeRegion::new(&keys, &(0..1 << 45));
        let p = |x, y, z| Point3::new(x, y, z);
        assert!(r.may_touch(p(-5.0, -5.0, -5.0), p(-6.0, -6.0, -6.0)));
        assert!(r.may_touch(p(5.0, 5.0, 5.0), p(-6.0, -6.0, -6.0)));
        assert!(!r.may_touch(p(5.0, 5.0, 5.0), p(6.0, -6.0, -6.0)));
        assert!(!r.may_touch(p(5.0, 5.0, 5.0), p(5.0, 5.0, 5.0)));
        // the voxel of margin
        assert!(r.may_touch(p(0.5, 0.5, 0.5), p(0.5, 0.5, 0.5)));
        assert!(!r.may_touch(p(1.5, 0.5, 0.5), p(1.5, 0.5, 0.5)));
    }
}
