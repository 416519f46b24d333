//! Discrete voxel keys and OctoMap's exact coordinate/key arithmetic.
//!
//! A [`Key`] addresses a voxel at the finest level (depth 16) by three `u16`
//! indices, the map centre lying between index 32767 and 32768. Every
//! conversion reproduces OctoMap's float/double arithmetic, including the
//! behaviour of C++'s `(int) floor(x)` on x86-64 for values out of range.

use crate::geometry::Point3;
use std::fmt;

/// Maximum tree depth (number of levels below the root).
pub const TREE_DEPTH: u8 = 16;
/// Key of the map centre; keys run from 0 to `2 * KEY_CENTER - 1`.
pub const KEY_CENTER: u32 = 32768;

/// A voxel address: one `u16` index per axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Key(pub [u16; 3]);

impl Key {
    /// A key from its x, y and z indices.
    pub const fn new(x: u16, y: u16, z: u16) -> Self {
        Key([x, y, z])
    }

    /// The root's key, as OctoMap's iterators report it.
    pub const ROOT: Key = Key([KEY_CENTER as u16; 3]);

    /// Index (0..8, x = 1, y = 2, z = 4) of the child containing this key
    /// below a node at `depth` (0 = root).
    #[inline(always)]
    pub fn child_index(self, depth: u8) -> usize {
        let bit = 15 - depth as u32;
        (((self.0[0] >> bit) & 1) | (((self.0[1] >> bit) & 1) << 1) | (((self.0[2] >> bit) & 1) << 2)) as usize
    }

    /// The three coordinates in one word, 16 bits apart (`x | y << 16 |
    /// z << 32`), for descents that test key bits of all axes at once.
    #[inline(always)]
    pub fn packed(self) -> u64 {
        let [x, y, z] = self.0.map(u64::from);
        x | (y << 16) | (z << 32)
    }

    /// The key OctoMap's iterators give the child `pos` of a node with key
    /// `self` at `parent_depth` (`computeChildKey`).
    #[inline]
    pub fn child_key(self, pos: usize, parent_depth: u8) -> Key {
        let offset = (KEY_CENTER >> (parent_depth + 1)) as u16;
        let extra = u16::from(offset == 0);
        let mut k = self.0;
        for (axis, item) in k.iter_mut().enumerate() {
            if pos & (1 << axis) != 0 {
                *item = item.wrapping_add(offset);
            } else {
                *item = item.wrapping_sub(offset).wrapping_sub(extra);
            }
        }
        Key(k)
    }
}

impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "({}, {}, {})", self.0[0], self.0[1], self.0[2])
    }
}

/// Why a coordinate has no key.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum KeyError {
    /// The coordinate is NaN or infinite.
    #[error("coordinate {value} is not finite")]
    NotFinite {
        /// The offending coordinate, metres.
        value: f64,
    },
    /// The coordinate lies beyond the map's extent on its axis.
    #[error("coordinate {value} lies outside the map (half extent {half_extent} m)")]
    OutOfRange {
        /// The offending coordinate, metres.
        value: f64,
        /// Half the root node's edge length, metres: the map spans `-half_extent..half_extent` on each axis.
        half_extent: f64,
    },
    /// A requested depth is greater than [`TREE_DEPTH`].
    #[error("depth {depth} exceeds the tree depth 16")]
    BadDepth {
        /// The requested depth.
        depth: u8,
    },
    /// A resolution outside [`MIN_RESOLUTION`]`..=`[`MAX_RESOLUTION`] (see
    /// [`check_resolution`]).
    #[error("resolution {value:?} m {}", resolution_problem(*.value))]
    BadResolution {
        /// The offending resolution, metres.
        value: f64,
    },
}

/// Smallest usable resolution, metres (2^-125): half a voxel must be a
/// normal float. Voxel centres are floats (OctoMap's `point3d`) half a
/// voxel from the faces; with a normal float for that half, every centre
/// of the ±32768 voxels has 17 significant bits to spare and keys
/// round-trip through centres at any scale, so float precision never
/// limits the map above this (each voxel holds at least 256 floats even at
/// the map's edge); below it, it does.
pub const MIN_RESOLUTION: f64 = 2.0 * f32::MIN_POSITIVE as f64;

/// Largest usable resolution, metres (`f32::MAX / 32768`, about 1.04e34):
/// the map's edge, 32768 voxels from its centre, must be a finite float.
pub const MAX_RESOLUTION: f64 = f32::MAX as f64 / 32768.0;

/// Why [`check_resolution`] refuses `value`.
fn resolution_problem(value: f64) -> String {
    if !(value.is_finite() && value > 0.0) {
        "is not a positive finite number".into()
    } else if value < MIN_RESOLUTION {
        format!("is below the smallest usable resolution {MIN_RESOLUTION:?} m (2^-125: half a voxel must be a normal float)")
    } else {
        format!(
            "is above the largest usable resolution {MAX_RESOLUTION:?} m \
             (f32::MAX / 32768: the map's edge, 32768 voxels out, must be a finite float)"
        )
    }
}

/// The one rule for a map's resolution (voxel edge length, metres), which
/// every tree, tile set, plan and map file applies: a finite number from
/// [`MIN_RESOLUTION`] to [`MAX_RESOLUTION`]. Returns the value unchanged.
///
/// Within that range the voxel, its half and the map's edge, 32768 voxels
/// from the centre, are finite non-zero floats (and the extent
/// `resolution * 2^16` a finite double), so keys and voxel centres convert
/// both ways; outside it a map's resolution or extent would round to 0 or
/// infinity and every query of it find nothing.
pub fn check_resolution(resolution: f64) -> Result<f64, KeyError> {
    if (MIN_RESOLUTION..=MAX_RESOLUTION).contains(&resolution) {
        Ok(resolution)
    } else {
        Err(KeyError::BadResolution { value: resolution })
    }
}

/// `(int) floor(x)` as compiled for x86-64: `cvttsd2si` yields `i32::MIN`
/// for NaN and for anything outside the `i32` range.
#[inline(always)]
fn floor_to_int(x: f64) -> i32 {
    if (-2147483648.0..2147483648.0).contains(&x) {
        // truncate, then step down for negative fractions: exact, and much
        // cheaper than `f64::floor` on baseline x86-64 (no SSE4.1 `roundsd`)
        let t = x as i32;
        if f64::from(t) > x {
            t - 1
        } else {
            t
        }
    } else {
        i32::MIN
    }
}

/// The resolution-dependent half of OctoMap's key arithmetic.
#[derive(Clone, Debug, PartialEq)]
pub struct KeySpace {
    resolution: f64,
    resolution_factor: f64,
    node_sizes: [f64; 17],
}

impl KeySpace {
    /// The key space for a voxel edge length in metres, if
    /// [`check_resolution`] accepts it.
    pub fn checked(resolution: f64) -> Result<Self, KeyError> {
        Ok(Self::new(check_resolution(resolution)?))
    }

    /// The key space for a voxel edge length in metres, with OctoMap's
    /// arithmetic for any value (as OctoMap's own conversions take any
    /// double). Trees, tile sets and map files take only the resolutions
    /// [`check_resolution`] accepts; [`Self::checked`] applies that rule.
    pub fn new(resolution: f64) -> Self {
        let mut node_sizes = [0.0; 17];
        for (depth, size) in node_sizes.iter_mut().enumerate() {
            *size = resolution * f64::from(1u32 << (16 - depth));
        }
        KeySpace { resolution, resolution_factor: 1.0 / resolution, node_sizes }
    }

    /// Voxel edge length at the finest depth, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// `1 / resolution`, the factor of `coordToKey`.
    pub(crate) fn resolution_factor(&self) -> f64 {
        self.resolution_factor
    }

    /// Edge length of a node at `depth` (0 = root).
    #[inline]
    pub fn node_size(&self, depth: u8) -> f64 {
        self.node_sizes[depth as usize]
    }

    /// OctoMap's `tree_center` value (a float).
    pub fn tree_center(&self) -> f32 {
        (f64::from(KEY_CENTER) / self.resolution_factor) as f32
    }

    /// Unchecked `coordToKey(double)`: out-of-range values wrap like OctoMap's.
    #[inline(always)]
    pub fn coord_to_key_unchecked(&self, coord: f64) -> u16 {
        (floor_to_int(self.resolution_factor * coord) as u32).wrapping_add(KEY_CENTER) as u16
    }

    /// Unchecked `coordToKey(double, depth)`.
    pub fn coord_to_key_at_depth_unchecked(&self, coord: f64, depth: u8) -> u16 {
        let keyval = floor_to_int(self.resolution_factor * coord);
        let diff = u32::from(TREE_DEPTH.saturating_sub(depth));
        if diff == 0 {
            return (keyval as u32).wrapping_add(KEY_CENTER) as u16;
        }
        let shifted = ((keyval >> diff) as u32).wrapping_shl(diff);
        shifted.wrapping_add(1 << (diff - 1)).wrapping_add(KEY_CENTER) as u16
    }

    /// `coordToKeyChecked(double)`: the key, or why there is none.
    #[inline(always)]
    pub fn coord_to_key(&self, coord: f64) -> Result<u16, KeyError> {
        // OctoMap's `(int) floor(x) + 32768` in range exactly when `floor(x)`
        // is in [-32768, 32768), that is when `x` is (integer bounds; NaN
        // is not)
        let scaled = self.resolution_factor * coord;
        let center = f64::from(KEY_CENTER);
        if (-center..center).contains(&scaled) {
            Ok((floor_to_int(scaled) + KEY_CENTER as i32) as u16)
        } else if !coord.is_finite() {
            Err(KeyError::NotFinite { value: coord })
        } else {
            Err(KeyError::OutOfRange { value: coord, half_extent: self.node_sizes[0] / 2.0 })
        }
    }

    /// `coordToKeyChecked(double, depth)`.
    pub fn coord_to_key_at_depth(&self, coord: f64, depth: u8) -> Result<u16, KeyError> {
        if depth > TREE_DEPTH {
            return Err(KeyError::BadDepth { depth });
        }
        Ok(adjust_to_depth(self.coord_to_key(coord)?, depth))
    }

    /// `coordToKeyChecked(point3d)`: the key of the voxel containing `p`.
    #[inline(always)]
    pub fn key(&self, p: Point3) -> Result<Key, KeyError> {
        #[cfg(target_arch = "x86_64")]
        if let Some((k, _)) = crate::arch::key_and_octant(self.resolution_factor, p) {
            return Ok(k);
        }
        self.key_per_axis(p)
    }

    /// [`Self::key`] with the key's child index at depth 1 (its root child,
    /// which picks a search's trunk), taken from the products' signs: a
    /// search can start looking up its trunk while the key's bits are still
    /// on their way out of the vector unit.
    #[inline(always)]
    pub fn key_and_octant(&self, p: Point3) -> Result<(Key, usize), KeyError> {
        #[cfg(target_arch = "x86_64")]
        if let Some(k) = crate::arch::key_and_octant(self.resolution_factor, p) {
            return Ok(k);
        }
        let key = self.key_per_axis(p)?;
        Ok((key, key.child_index(0)))
    }

    /// Whether every point of `points` has a key ([`Self::key`] is `Ok`:
    /// finite and inside the map). A block of points whose coordinates all
    /// lie within a float bound short of the map's edge is passed by one
    /// comparison per coordinate, a loop the compiler vectorises; only
    /// blocks with a point beyond it are tested point by point.
    pub fn contains_all(&self, points: &[Point3]) -> bool {
        let bound = self.inner_bound();
        points.chunks(256).all(|block| {
            let near = |v: f32| v.abs() <= bound;
            block.iter().fold(true, |ok, p| ok & near(p.x) & near(p.y) & near(p.z))
                || block.iter().all(|&p| self.key(p).is_ok())
        })
    }

    /// A float `b` such that every coordinate of magnitude at most `b` has
    /// a key: `factor * b` below the key range's end (the product rounds
    /// monotonically, so smaller magnitudes are inside too); -1 when the
    /// factor is not a positive number, so that no coordinate passes.
    fn inner_bound(&self) -> f32 {
        let center = f64::from(KEY_CENTER);
        let factor = self.resolution_factor;
        if !(factor > 0.0 && factor.is_finite()) {
            return -1.0;
        }
        let mut b = (center / factor) as f32;
        for _ in 0..4 {
            if b.is_finite() && b > 0.0 && factor * f64::from(b) < center {
                return b;
            }
            b = b.next_down();
        }
        -1.0
    }

    /// [`Self::key`] one axis at a time (the error names the first axis
    /// without a key).
    fn key_per_axis(&self, p: Point3) -> Result<Key, KeyError> {
        Ok(Key([
            self.coord_to_key(f64::from(p.x))?,
            self.coord_to_key(f64::from(p.y))?,
            self.coord_to_key(f64::from(p.z))?,
        ]))
    }

    /// `coordToKeyChecked(point3d, depth)`.
    pub fn key_at_depth(&self, p: Point3, depth: u8) -> Result<Key, KeyError> {
        Ok(Key([
            self.coord_to_key_at_depth(f64::from(p.x), depth)?,
            self.coord_to_key_at_depth(f64::from(p.y), depth)?,
            self.coord_to_key_at_depth(f64::from(p.z), depth)?,
        ]))
    }

    /// Unchecked `coordToKey(point3d)` (wraps out-of-range coordinates).
    pub fn key_unchecked(&self, p: Point3) -> Key {
        Key([
            self.coord_to_key_unchecked(f64::from(p.x)),
            self.coord_to_key_unchecked(f64::from(p.y)),
            self.coord_to_key_unchecked(f64::from(p.z)),
        ])
    }

    /// `keyToCoord(key)`: centre of a depth-16 voxel along one axis.
    #[inline(always)]
    pub fn key_to_coord(&self, key: u16) -> f64 {
        (f64::from(i32::from(key) - KEY_CENTER as i32) + 0.5) * self.resolution
    }

    /// `keyToCoord(key, depth)`: centre of the depth-`depth` node containing `key`.
    pub fn key_to_coord_at_depth(&self, key: u16, depth: u8) -> f64 {
        match depth {
            0 => 0.0,
            TREE_DEPTH => self.key_to_coord(key),
            _ => {
                let cells = f64::from(1u32 << (TREE_DEPTH - depth));
                (((f64::from(key) - f64::from(KEY_CENTER)) / cells).floor() + 0.5) * self.node_size(depth)
            }
        }
    }

    /// `keyToCoord(OcTreeKey)`: voxel centre as a float point.
    pub fn key_to_point(&self, key: Key) -> Point3 {
        Point3::new(
            self.key_to_coord(key.0[0]) as f32,
            self.key_to_coord(key.0[1]) as f32,
            self.key_to_coord(key.0[2]) as f32,
        )
    }

    /// `keyToCoord(OcTreeKey, depth)`.
    pub fn key_to_point_at_depth(&self, key: Key, depth: u8) -> Point3 {
        Point3::new(
            self.key_to_coord_at_depth(key.0[0], depth) as f32,
            self.key_to_coord_at_depth(key.0[1], depth) as f32,
            self.key_to_coord_at_depth(key.0[2], depth) as f32,
        )
    }
}

/// `adjustKeyAtDepth`: the key of the centre of the depth-`depth` node
/// containing `key` (keys of coarse nodes point at their centre).
#[inline]
pub fn adjust_to_depth(key: u16, depth: u8) -> u16 {
    let diff = u32::from(TREE_DEPTH.saturating_sub(depth));
    if diff == 0 {
        return key;
    }
    let rel = u32::from(key).wrapping_sub(KEY_CENTER);
    ((rel >> diff) << diff).wrapping_add(1 << (diff - 1)).wrapping_add(KEY_CENTER) as u16
}

/// [`adjust_to_depth`] on all three axes.
pub fn adjust_key_to_depth(key: Key, depth: u8) -> Key {
    Key(key.0.map(|k| adjust_to_depth(k, depth)))
}

/// Keys packed as `x | y << 16 | z << 32` for depth-first walks: a walk
/// keeps, per open node, the packed key of its child 0, and child `pos` is
/// then `child0 + (SPREAD[pos] << (15 - depth))` — OctoMap's
/// `computeChildKey` (centre ± half the child's size per axis) without a
/// branch per axis.
pub(crate) mod packed {
    use super::{Key, KEY_CENTER};

    /// Bit `i` of a child index spread to the 16-bit lane of axis `i`.
    pub const SPREAD: [u64; 8] = {
        let mut t = [0u64; 8];
        let mut pos = 0;
        while pos < 8 {
            t[pos] = (pos as u64 & 1) | ((pos as u64 & 2) << 15) | ((pos as u64 & 4) << 30);
            pos += 1;
        }
        t
    };

    /// The same value in all three lanes.
    const fn lanes(v: u16) -> u64 {
        (v as u64) * 0x0000_0001_0001_0001
    }

    /// The packed key of child 0 of the node at `depth` (< 16) with packed
    /// centre key `key` (`computeChildKey` subtracts the child offset, and
    /// one more at depth 15 where the offset is 0).
    #[inline(always)]
    pub fn child0(key: u64, depth: u8) -> u64 {
        let offset = (KEY_CENTER >> (depth + 1)) as u16;
        key - lanes(offset) - lanes(u16::from(offset == 0))
    }

    /// The packed key of child `pos` of a node at `depth` whose child 0 is `child0`.
    #[inline(always)]
    pub fn child(child0: u64, pos: usize, depth: u8) -> u64 {
        child0 + (SPREAD[pos] << (15 - depth))
    }

    #[inline(always)]
    pub fn pack(k: Key) -> u64 {
        u64::from(k.0[0]) | (u64::from(k.0[1]) << 16) | (u64::from(k.0[2]) << 32)
    }

    #[inline(always)]
    pub fn unpack(k: u64) -> Key {
        Key([k as u16, (k >> 16) as u16, (k >> 32) as u16])
    }

    #[cfg(test)]
    mod tests {
        use super::*;
        use crate::key::TREE_DEPTH;

        /// The packed child step gives `computeChildKey`'s keys on random
        /// paths from the root to depth 16.
        #[test]
        fn packed_child_step_equals_child_key() {
            let mut seed = 0x2545_f491_4f6c_dd1du64;
            for _ in 0..2000 {
                let mut key = Key::ROOT;
                for depth in 0..TREE_DEPTH {
                    seed ^= seed << 13;
                    seed ^= seed >> 7;
                    seed ^= seed << 17;
                    let pos = (seed % 8) as usize;
                    let want = key.child_key(pos, depth);
                    assert_eq!(unpack(child(child0(pack(key), depth), pos, depth)), want, "{key} {pos} {depth}");
                    key = want;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn child_index_uses_x1_y2_z4() {
        let k = Key::new(0x8000, 0, 0);
        assert_eq!(k.child_index(0), 1);
        let k = Key::new(0, 0x8000, 0x8000);
        assert_eq!(k.child_index(0), 6);
        let k = Key::new(1, 0, 1);
        assert_eq!(k.child_index(15), 5);
    }

    /// The rule's bounds are the usable ones: at both, the voxel, its
    /// half, and the map's extent are finite non-zero floats; one step
    /// beyond, or at the values that once made maps of resolution 0 or
    /// infinity, the rule refuses, naming the value and the range.
    #[test]
    fn resolutions_outside_the_usable_range_are_refused() {
        for r in [MIN_RESOLUTION, MAX_RESOLUTION, 0.05, 1.0] {
            assert_eq!(check_resolution(r), Ok(r));
            let ks = KeySpace::checked(r).unwrap();
            let (half, edge) = ((r / 2.0) as f32, (ks.node_size(0) / 2.0) as f32);
            assert!(half.is_normal() && edge.is_finite() && edge > 0.0, "{r}");
            assert!((r as f32).is_normal() && ks.node_size(0).is_finite() && ks.tree_center().is_finite());
        }
        for r in [
            0.0,
            -0.1,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e-300,
            1e300,
            MIN_RESOLUTION.next_down(),
            MAX_RESOLUTION.next_up(),
        ] {
            let e = check_resolution(r).unwrap_err();
            assert!(matches!(e, KeyError::BadResolution { value } if value.to_bits() == r.to_bits()), "{r}");
            let text = e.to_string();
            assert!(text.starts_with(&format!("resolution {r:?} m is ")), "{text}");
            let why = if r.is_nan() || r <= 0.0 || r.is_infinite() {
                "not a positive finite number"
            } else if r < 1.0 {
                "below the smallest usable resolution 2.350988701644575e-38 m (2^-125"
            } else {
                "above the largest usable resolution 1.0384593098099636e34 m"
            };
            assert!(text.contains(why), "{text}");
            assert!(KeySpace::checked(r).is_err());
        }
    }

    #[test]
    fn floor_to_int_matches_x86_cvttsd2si() {
        assert_eq!(floor_to_int(-0.5), -1);
        assert_eq!(floor_to_int(f64::NAN), i32::MIN);
        assert_eq!(floor_to_int(1e300), i32::MIN);
        assert_eq!(floor_to_int(-1e300), i32::MIN);
        assert_eq!(floor_to_int(2147483647.5), i32::MAX);
    }

    #[test]
    fn checked_keys_reject_non_finite_and_far_points() {
        let ks = KeySpace::new(0.1);
        assert!(matches!(ks.coord_to_key(f64::NAN), Err(KeyError::NotFinite { .. })));
        assert!(matches!(ks.coord_to_key(f64::INFINITY), Err(KeyError::NotFinite { .. })));
        assert!(matches!(ks.coord_to_key(3276.8), Err(KeyError::OutOfRange { .. })));
        assert_eq!(ks.coord_to_key(-3276.8), Ok(0));
        assert_eq!(ks.coord_to_key(0.0), Ok(32768));
        assert_eq!(ks.coord_to_key(-0.0), Ok(32768));
    }

    /// `coord_to_key` is OctoMap's `floor(resolution_factor * x) + 32768`,
    /// in range exactly when that floor is in [-32768, 32768): at integer
    /// products and one ulp either side, near zero and the map edges, and
    /// for random coordinates.
    #[test]
    fn checked_keys_are_the_floor_of_the_product() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        for res in [0.01, 0.05, 0.1, 0.3, 1.0] {
            let ks = KeySpace::new(res);
            let mut coords: Vec<f64> = vec![0.0, -0.0, 1e-300, -1e-300, f64::from(f32::from_bits(1)), -1e-45];
            for n in [0.0, 1.0, -1.0, 7.0, -7.0, 32767.0, -32768.0, 32768.0, -32769.0] {
                let c = n * res;
                coords.extend([c, c.next_up(), c.next_down()]);
                let f = f64::from(c as f32);
                coords.extend([f, f64::from((c as f32).next_up()), f64::from((c as f32).next_down())]);
            }
            for _ in 0..20_000 {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                coords.push(f64::from(f32::from_bits(s as u32)) % (ks.node_size(0) * 0.6));
            }
            for c in coords {
                let floored = (ks.resolution_factor * c).floor();
                let want = (-32768.0..32768.0).contains(&floored).then(|| (floored as i32 + 32768) as u16);
                assert_eq!(ks.coord_to_key(c).ok(), want, "{c:e} at {res}");
            }
        }
    }

    /// The two-lane conversion gives the per-axis keys and errors for
    /// values at and one ulp beside voxel borders and the map's edges, for
    /// -0.0, the smallest values either side of zero, NaN and infinities,
    /// on every axis, at several resolutions; with the octant, the key's
    /// root child.
    #[test]
    fn point_keys_equal_per_axis_keys() {
        for res in [0.01, 0.05, 0.1, 0.2, 0.3, 1.0] {
            let ks = KeySpace::new(res);
            let edge = (ks.node_size(0) / 2.0) as f32;
            let tiny = f32::from_bits(1);
            let mut values =
                vec![0.0f32, -0.0, tiny, -tiny, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, f32::MIN];
            for base in [edge, -edge, res as f32, -(res as f32), 1.5 * res as f32, 17.0 * res as f32, 0.5] {
                values.extend([base, f32::from_bits(base.to_bits() + 1), f32::from_bits(base.to_bits() - 1)]);
            }
            for &a in &values {
                for &b in &[0.0f32, a, -edge, 3.7] {
                    for p in [Point3::new(a, b, b), Point3::new(b, a, b), Point3::new(b, b, a)] {
                        let expected = ks.key_per_axis(p);
                        let with_octant = ks.key_and_octant(p).map(|(k, o)| (k, o == k.child_index(0)));
                        assert_eq!(with_octant.ok(), expected.as_ref().ok().map(|&k| (k, true)), "{p:?} at {res}");
                        match (ks.key(p), expected) {
                            (Ok(k), Ok(e)) => assert_eq!(k, e, "{p:?} at {res}"),
                            // NaN payloads compare unequal: compare the kinds and bits
                            (Err(x), Err(y)) => assert_eq!(format!("{x:?}"), format!("{y:?}"), "{p:?} at {res}"),
                            (got, e) => panic!("{p:?} at {res}: {got:?}, per axis {e:?}"),
                        }
                    }
                }
            }
        }
    }

    /// `contains_all` says what testing every point's key says, for blocks
    /// of points inside, at and just past the map's edges (where the fast
    /// bound must not pass a point without a key), and non-finite ones.
    #[test]
    fn contains_all_agrees_with_every_key() {
        for res in [0.01, 0.05, 0.1, 0.2, 0.3, 1.0, 0.123_456_7] {
            let ks = KeySpace::new(res);
            let edge = (ks.node_size(0) / 2.0) as f32;
            let bound = ks.inner_bound();
            assert!(bound > 0.99 * edge, "{res}: bound {bound}, edge {edge}");
            let mut values = vec![0.0f32, -0.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3.7];
            for base in [edge, -edge, bound, -bound] {
                for ulps in 0..6 {
                    values.extend([base.next_up(), base.next_down()].map(|v| f32::from_bits(v.to_bits() + ulps)));
                    values.extend([base.next_up(), base.next_down()].map(|v| f32::from_bits(v.to_bits() - ulps)));
                }
            }
            for &a in &values {
                for p in [Point3::new(a, 1.0, -2.0), Point3::new(1.0, a, 0.5), Point3::new(-0.5, 2.0, a)] {
                    let block = vec![Point3::new(0.25, -0.25, 1.0); 300].into_iter().chain([p]).collect::<Vec<_>>();
                    assert_eq!(ks.contains_all(&block), ks.key(p).is_ok(), "{p:?} at {res}");
                }
            }
        }
        assert!(!KeySpace::new(f64::NAN).contains_all(&[Point3::new(0.0, 0.0, 0.0)]));
        assert!(KeySpace::new(0.1).contains_all(&[]));
    }

    #[test]
    fn root_child_keys_step_by_quarter_extent() {
        let c = Key::ROOT.child_key(0, 0);
        assert_eq!(c, Key::new(16384, 16384, 16384));
        let c = Key::ROOT.child_key(7, 0);
        assert_eq!(c, Key::new(49152, 49152, 49152));
        // at the last level the negative side steps one further
        let leaf = Key::new(101, 101, 101).child_key(0, 15);
        assert_eq!(leaf, Key::new(100, 100, 100));
    }
}
