//! OctoMap's order of updates within one `insertPointCloud`, for the trees
//! where that order shows: colour trees.
//!
//! `insertPointCloud` collects the free and occupied voxels of a scan in two
//! `KeySet`s and then updates them one by one in the sets' iteration order.
//! For plain and stamped trees the result does not depend on that order
//! (each voxel is updated once, and a node's final pruning only depends on
//! its children's final state), which is why `OccupancyTree::update_batch`
//! may walk the keys in Morton order. A `ColorOcTree` is different: when a
//! node's eight children become equal part-way through the pass, OctoMap
//! prunes it (the node takes the children's average colour) and the next key
//! below it expands it again, handing that average to all eight children.
//! So colour maps need the keys in OctoMap's order.
//!
//! With GCC, OctoMap's `KeySet` is `std::tr1::unordered_set<OcTreeKey,
//! OcTreeKey::KeyHash>` (see `OcTreeKey.h`), whose iteration order is fixed
//! by libstdc++'s TR1 hash table: `hash % bucket_count` buckets, each a list
//! with the newest element first, rehashing by the prime policy below (the
//! primes are libstdc++'s `__prime_list` below 2^35, more than any scan
//! needs). [`Tr1KeySet`] reproduces it; `tests/differential_color.rs` checks
//! the resulting maps byte for byte against OctoMap.

use crate::geometry::Point3;
use crate::key::Key;
use crate::ray::{point_along, RayKeys};
use crate::scan::{OutOfMap, ScanError, ScanOptions, ScanReport};
use crate::tree::OccupancyTree;

/// libstdc++'s `__prime_list` (the same for `std` and `std::tr1`), up to
/// the last entry below 2^35.
const PRIMES: [u64; 262] = [
    2,
    3,
    5,
    7,
    11,
    13,
    17,
    19,
    23,
    29,
    31,
    37,
    41,
    43,
    47,
    53,
    59,
    61,
    67,
    71,
    73,
    79,
    83,
    89,
    97,
    103,
    109,
    113,
    127,
    137,
    139,
    149,
    157,
    167,
    179,
    193,
    199,
    211,
    227,
    241,
    257,
    277,
    293,
    313,
    337,
    359,
    383,
    409,
    439,
    467,
    503,
    541,
    577,
    619,
    661,
    709,
    761,
    823,
    887,
    953,
    1031,
    1109,
    1193,
    1289,
    1381,
    1493,
    1613,
    1741,
    1879,
    2029,
    2179,
    2357,
    2549,
    2753,
    2971,
    3209,
    3469,
    3739,
    4027,
    4349,
    4703,
    5087,
    5503,
    5953,
    6427,
    6949,
    7517,
    8123,
    8783,
    9497,
    10273,
    11113,
    12011,
    12983,
    14033,
    15173,
    16411,
    17749,
    19183,
    20753,
    22447,
    24281,
    26267,
    28411,
    30727,
    33223,
    35933,
    38873,
    42043,
    45481,
    49201,
    53201,
    57557,
    62233,
    67307,
    72817,
    78779,
    85229,
    92203,
    99733,
    107897,
    116731,
    126271,
    136607,
    147793,
    159871,
    172933,
    187091,
    202409,
    218971,
    236897,
    256279,
    277261,
    299951,
    324503,
    351061,
    379787,
    410857,
    444487,
    480881,
    520241,
    562841,
    608903,
    658753,
    712697,
    771049,
    834181,
    902483,
    976369,
    1056323,
    1142821,
    1236397,
    1337629,
    1447153,
    1565659,
    1693859,
    1832561,
    1982627,
    2144977,
    2320627,
    2510653,
    2716249,
    2938679,
    3179303,
    3439651,
    3721303,
    4026031,
    4355707,
    4712381,
    5098259,
    5515729,
    5967347,
    6456007,
    6984629,
    7556579,
    8175383,
    8844859,
    9569143,
    10352717,
    11200489,
    12117689,
    13109983,
    14183539,
    15345007,
    16601593,
    17961079,
    19431899,
    21023161,
    22744717,
    24607243,
    26622317,
    28802401,
    31160981,
    33712729,
    36473443,
    39460231,
    42691603,
    46187573,
    49969847,
    54061849,
    58488943,
    63278561,
    68460391,
    74066549,
    80131819,
    86693767,
    93793069,
    101473717,
    109783337,
    118773397,
    128499677,
    139022417,
    150406843,
    162723577,
    176048909,
    190465427,
    206062531,
    222936881,
    241193053,
    260944219,
    282312799,
    305431229,
    330442829,
    357502601,
    386778277,
    418451333,
    452718089,
    489790921,
    529899637,
    573292817,
    620239453,
    671030513,
    725980837,
    785430967,
    849749479,
    919334987,
    994618837,
    1076067617,
    1164186217,
    1259520799,
    1362662261,
    1474249943,
    1594975441,
    1725587117,
    1866894511,
    2019773507,
    2185171673,
    2364114217,
    2557710269,
    2767159799,
    2993761039,
    3238918481,
    3504151727,
    3791104843,
    4101556399,
    4294967291,
    6442450933,
    8589934583,
    12884901857,
    17179869143,
    25769803693,
    34359738337,
];

/// `OcTreeKey::KeyHash`.
#[inline]
fn key_hash(k: Key) -> u64 {
    u64::from(k.0[0]).wrapping_add(1447u64.wrapping_mul(u64::from(k.0[1]))).wrapping_add(345_637 * u64::from(k.0[2]))
}

const NONE: u32 = u32::MAX;

/// A key set whose iteration order is that of libstdc++'s
/// `std::tr1::unordered_set<OcTreeKey, KeyHash>` after the same inserts.
pub(crate) struct Tr1KeySet {
    /// Head of each bucket's list (node index), `NONE` when empty.
    buckets: Vec<u32>,
    keys: Vec<Key>,
    next: Vec<u32>,
    /// `_Prime_rehash_policy::_M_next_resize`.
    next_resize: u64,
}

impl Tr1KeySet {
    /// A set as `unordered_set()` makes it (bucket hint 10).
    pub(crate) fn new() -> Self {
        let mut s = Tr1KeySet { buckets: Vec::new(), keys: Vec::new(), next: Vec::new(), next_resize: 0 };
        let n = s.next_bucket_count(10);
        s.buckets = vec![NONE; n as usize];
        s
    }

    pub(crate) fn len(&self) -> usize {
        self.keys.len()
    }

    /// `_M_next_bkt`: the first listed prime not below `n` (the last prime
    /// when none is), updating the resize threshold.
    fn next_bucket_count(&mut self, n: u64) -> u64 {
        let p = PRIMES[PRIMES[..PRIMES.len() - 1].partition_point(|&q| q < n)];
        self.next_resize = (p as f32).ceil() as u64;
        p
    }

    /// `_M_need_rehash` (max load factor 1, growth factor 2): the new bucket
    /// count if `n_ins` more elements call for one.
    fn need_rehash(&mut self, n_ins: u64) -> Option<u64> {
        let (n_bkt, n_elt) = (self.buckets.len() as u64, self.keys.len() as u64);
        if n_elt + n_ins <= self.next_resize {
            return None;
        }
        let min_bkts = n_ins as f32 + n_elt as f32;
        if min_bkts > n_bkt as f32 {
            let min_bkts = min_bkts.max(2.0 * n_bkt as f32);
            Some(self.next_bucket_count(f64::from(min_bkts).ceil() as u64))
        } else {
            self.next_resize = (n_bkt as f32).ceil() as u64;
            None
        }
    }

    /// `_M_rehash`: old buckets in order, each list from its head, every
    /// node pushed onto the head of its new bucket.
    fn rehash(&mut self, n: u64) {
        let mut fresh = vec![NONE; n as usize];
        for b in 0..self.buckets.len() {
            let mut p = self.buckets[b];
            while p != NONE {
                let after = self.next[p as usize];
                let nb = (key_hash(self.keys[p as usize]) % n) as usize;
                self.next[p as usize] = fresh[nb];
                fresh[nb] = p;
                p = after;
            }
        }
        self.buckets = fresh;
    }

    /// `insert(key)`; whether it was new.
    pub(crate) fn insert(&mut self, key: Key) -> bool {
        let code = key_hash(key);
        let mut b = (code % self.buckets.len() as u64) as usize;
        let mut p = self.buckets[b];
        while p != NONE {
            if self.keys[p as usize] == key {
                return false;
            }
            p = self.next[p as usize];
        }
        if let Some(n) = self.need_rehash(1) {
            b = (code % n) as usize;
            self.rehash(n);
        }
        let id = self.keys.len() as u32;
        self.keys.push(key);
        self.next.push(self.buckets[b]);
        self.buckets[b] = id;
        true
    }

    /// `insert(first, last)`: one rehash check for the whole range, then
    /// the keys one by one.
    pub(crate) fn insert_range(&mut self, keys: &[Key]) {
        if let Some(n) = self.need_rehash(keys.len() as u64) {
            self.rehash(n);
        }
        for &k in keys {
            self.insert(k);
        }
    }

    pub(crate) fn contains(&self, key: Key) -> bool {
        let mut p = self.buckets[(key_hash(key) % self.buckets.len() as u64) as usize];
        while p != NONE {
            if self.keys[p as usize] == key {
                return true;
            }
            p = self.next[p as usize];
        }
        false
    }

    /// The keys in iteration order: bucket by bucket, each from its head.
    pub(crate) fn ordered(&self) -> Vec<Key> {
        let mut out = Vec::with_capacity(self.keys.len());
        for &head in &self.buckets {
            let mut p = head;
            while p != NONE {
                out.push(self.keys[p as usize]);
                p = self.next[p as usize];
            }
        }
        out
    }
}

impl OccupancyTree {
    /// `insertPointCloud` with OctoMap's serial `computeUpdate` and its
    /// update order: voxel by voxel, free ones first, each set in its
    /// `KeySet` iteration order. Same points, options and report as
    /// [`Self::insert_point_cloud`], whose batched walk this replaces for
    /// colour trees.
    pub(crate) fn insert_point_cloud_in_octomap_order(
        &mut self,
        points: &[Point3],
        origin: Point3,
        opts: &ScanOptions,
    ) -> Result<ScanReport, ScanError> {
        let keys = self.key_space().clone();
        let mut report = ScanReport { points: points.len(), ..Default::default() };
        if !origin.is_finite() {
            if let Err(source) = keys.key(origin) {
                return Err(ScanError::Origin { x: origin.x, y: origin.y, z: origin.z, source });
            }
        }
        let mut cleaned: Vec<Point3> = Vec::with_capacity(points.len());
        for (index, &p) in points.iter().enumerate() {
            if !p.is_finite() {
                report.non_finite += 1;
                continue;
            }
            match (opts.out_of_map, keys.key(p)) {
                (OutOfMap::Skip, Err(_)) => report.out_of_map += 1,
                (OutOfMap::Error, Err(source)) => {
                    return Err(ScanError::PointOutOfMap { index, x: p.x, y: p.y, z: p.z, source })
                }
                _ => cleaned.push(p),
            }
        }
        if opts.discretize {
            // computeDiscreteUpdate: first point of each voxel, at its centre
            let mut seen = hashbrown::HashSet::new();
            cleaned.retain(|&p| seen.insert(keys.key_unchecked(p)));
            cleaned.iter_mut().for_each(|p| *p = keys.key_to_point(keys.key_unchecked(*p)));
        }
        let (mut free, mut occupied) = (Tr1KeySet::new(), Tr1KeySet::new());
        let max_range = opts.max_range.unwrap_or(-1.0);
        let mut ray = Vec::new();
        for &p in &cleaned {
            let within = max_range < 0.0 || (p - origin).norm() <= max_range;
            let end = if within { p } else { point_along(origin, (p - origin).normalized(), max_range) };
            match opts.bbx {
                None => {
                    if let Ok(r) = RayKeys::new(&keys, origin, end) {
                        ray.clear();
                        ray.extend(r);
                        free.insert_range(&ray);
                    }
                    if within {
                        if let Ok(k) = keys.key(p) {
                            occupied.insert(k);
                        }
                    }
                }
                Some(bbx) => {
                    if within && bbx.contains_point(p) {
                        if let Ok(k) = keys.key(p) {
                            occupied.insert(k);
                        }
                    }
                    if let Ok(r) = RayKeys::new(&keys, origin, end) {
                        for k in r.take_while(|&k| bbx.contains_key(k)) {
                            free.insert(k);
                        }
                    }
                }
            }
        }
        let free_keys: Vec<Key> = free.ordered().into_iter().filter(|&k| !occupied.contains(k)).collect();
        let occupied_keys = occupied.ordered();
        for &k in &free_keys {
            self.update_occupancy(k, false, opts.inner);
        }
        for &k in &occupied_keys {
            self.update_occupancy(k, true, opts.inner);
        }
        debug_assert_eq!(occupied.len(), occupied_keys.len());
        Ok(ScanReport { free_updates: free_keys.len(), occupied_updates: occupied_keys.len(), ..report })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primes_are_increasing_and_prime() {
        assert!(PRIMES.windows(2).all(|w| w[0] < w[1]));
        for &p in PRIMES.iter().take_while(|&&p| p < 1 << 20) {
            assert!((2..p).take_while(|d| d * d <= p).all(|d| p % d != 0), "{p}");
        }
        assert!(*PRIMES.last().unwrap() > 1 << 34);
    }

    #[test]
    fn a_fresh_set_has_eleven_buckets_and_lists_newest_first() {
        let mut s = Tr1KeySet::new();
        assert_eq!(s.buckets.len(), 11);
        // hashes 0, 11, 22: one bucket, newest first
        for x in [0u16, 11, 22] {
            assert!(s.insert(Key::new(x, 0, 0)));
        }
        assert!(!s.insert(Key::new(11, 0, 0)));
        let xs: Vec<u16> = s.ordered().iter().map(|k| k.0[0]).collect();
        assert_eq!(xs, [22, 11, 0]);
    }
}
