//! The array queries shared by in-memory trees and memory-mapped maps:
//! occupancy of many points, many rays, leaves as a structured array. They
//! run without the GIL, on the threads `set_num_threads` chose.

use crate::convert::PointsView;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use octolinear::mapped::MapView;
use octolinear::{CastError, CastOptions, CastOutcome, Found, Key, KeyBox, KeySpace, NodeItem, OccupancyTree, Point3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// Threads asked for with `set_num_threads`; 0 means rayon's default
/// (`RAYON_NUM_THREADS`, else one per core).
static THREADS: AtomicUsize = AtomicUsize::new(0);

/// Most threads a call may ask for: more only share the cores, each with
/// its stack.
pub const MAX_THREADS: usize = 1024;

/// Refuses a thread count above [`MAX_THREADS`].
pub fn check_threads(n: usize) -> PyResult<()> {
    if n > MAX_THREADS {
        return Err(PyValueError::new_err(format!("{n} threads: at most {MAX_THREADS}")));
    }
    Ok(())
}

/// Sets the thread count of insertion and array queries (0: the default).
pub fn set_threads(n: usize) {
    THREADS.store(n, Ordering::Relaxed);
}

/// The thread count insertion and array queries use.
pub fn threads() -> usize {
    match THREADS.load(Ordering::Relaxed) {
        0 => rayon::current_num_threads(),
        n => n,
    }
}

/// `ScanOptions::threads`: `None` (rayon's pool) unless set.
pub fn scan_threads() -> Option<usize> {
    match THREADS.load(Ordering::Relaxed) {
        0 => None,
        n => Some(n),
    }
}

/// Runs `f` on a pool of [`threads`] threads (built once per count).
pub fn on_pool<T: Send>(f: impl FnOnce() -> T + Send) -> PyResult<T> {
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    let n = THREADS.load(Ordering::Relaxed);
    if n == 0 {
        return Ok(f());
    }
    let pool = {
        let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
        match pools.iter().find(|(k, _)| *k == n) {
            Some((_, p)) => p.clone(),
            None => {
                let p = Arc::new(
                    rayon::ThreadPoolBuilder::new()
                        .num_threads(n)
                        .build()
                        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("thread pool: {e}")))?,
                );
                pools.push((n, p.clone()));
                p
            }
        }
    };
    Ok(pool.install(f))
}

/// What the array queries need of a map.
pub trait Queries: Sync {
    /// The map's key arithmetic.
    fn key_space(&self) -> &KeySpace;
    /// Occupied by the map's threshold?
    fn occupied(&self, value: f32) -> bool;
    /// `search` of many keys at once.
    fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>);
    /// OctoMap's `castRay`.
    fn cast(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Result<CastOutcome, CastError>;
}

impl Queries for OccupancyTree {
    fn key_space(&self) -> &KeySpace {
        OccupancyTree::key_space(self)
    }
    fn occupied(&self, value: f32) -> bool {
        self.is_occupied(value)
    }
    fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>) {
        OccupancyTree::search_many(self, keys, depth, out)
    }
    fn cast(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Result<CastOutcome, CastError> {
        self.cast_ray(origin, direction, opts)
    }
}

impl Queries for MapView<'_> {
    fn key_space(&self) -> &KeySpace {
        MapView::key_space(self)
    }
    fn occupied(&self, value: f32) -> bool {
        self.is_occupied(value)
    }
    fn search_many(&self, keys: &[Key], depth: u8, out: &mut Vec<Option<Found>>) {
        MapView::search_many(self, keys, depth, out)
    }
    fn cast(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Result<CastOutcome, CastError> {
        self.cast_ray(origin, direction, opts)
    }
}

/// Occupancy states of [`occupancy`]: no node (or no key) at the point.
pub const UNKNOWN: i8 = -1;
/// A node below the occupancy threshold.
pub const FREE: i8 = 0;
/// A node at or above the occupancy threshold.
pub const OCCUPIED: i8 = 1;

/// Points per task: large enough that `search_many`'s lockstep descents
/// stay busy, small enough to share the work between threads.
const CHUNK: usize = 1 << 14;

/// How a point becomes a key in [`occupancy`].
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Keys {
    /// `coordToKeyChecked`: a point outside the map is unknown.
    Checked,
    /// `coordToKey`, as octomap-python's `getLabels` calls it: a finite
    /// point outside the map wraps around to a key inside; a non-finite
    /// one is unknown.
    Wrapping,
}

/// State ([`UNKNOWN`], [`FREE`], [`OCCUPIED`]) and log-odds (NaN where
/// unknown) of the node holding each point, searched down to `depth` (0:
/// the finest). Chunks of points are converted and searched in parallel.
pub fn occupancy<M: Queries>(map: &M, points: &PointsView<'_>, depth: u8, how: Keys) -> (Vec<i8>, Vec<f32>) {
    let n = points.len();
    let mut state = vec![UNKNOWN; n];
    let mut log_odds = vec![f32::NAN; n];
    let one_chunk = |(chunk, (st, lo)): (usize, (&mut [i8], &mut [f32]))| {
        let start = chunk * CHUNK;
        let pts = points.range(start..start + st.len());
        let keys = map.key_space();
        let mut found_keys = Vec::with_capacity(pts.len());
        let mut at = Vec::with_capacity(pts.len());
        for (i, p) in pts.iter().enumerate() {
            let key = match how {
                Keys::Checked => keys.key(*p).ok(),
                Keys::Wrapping => p.is_finite().then(|| keys.key_unchecked(*p)),
            };
            if let Some(k) = key {
                found_keys.push(k);
                at.push(i as u32);
            }
        }
        let mut out = Vec::with_capacity(found_keys.len());
        map.search_many(&found_keys, depth, &mut out);
        for (i, f) in at.into_iter().zip(out) {
            if let Some(f) = f {
                st[i as usize] = if map.occupied(f.value) { OCCUPIED } else { FREE };
                lo[i as usize] = f.value;
            }
        }
    };
    if n <= CHUNK {
        one_chunk((0, (&mut state[..], &mut log_odds[..])));
    } else {
        state.par_chunks_mut(CHUNK).zip(log_odds.par_chunks_mut(CHUNK)).enumerate().for_each(one_chunk);
    }
    (state, log_odds)
}

/// One `castRay` per origin/direction pair: whether it hit, and the end
/// point OctoMap writes (NaN where the ray could not be cast: an origin
/// outside the map, a zero direction).
pub fn cast_rays<M: Queries>(
    map: &M,
    origins: &[Point3],
    directions: &[Point3],
    opts: CastOptions,
) -> (Vec<bool>, Vec<[f64; 3]>) {
    let n = directions.len();
    let one = |i: usize| {
        let origin = if origins.len() == 1 { origins[0] } else { origins[i] };
        match map.cast(origin, directions[i], opts) {
            Ok(outcome) => {
                let e = outcome.end();
                (outcome.hit(), [f64::from(e.x), f64::from(e.y), f64::from(e.z)])
            }
            Err(_) => (false, [f64::NAN; 3]),
        }
    };
    if n < 256 {
        (0..n).map(one).unzip()
    } else {
        (0..n).into_par_iter().with_min_len(64).map(one).unzip()
    }
}

/// Bytes per record of [`leaf_records`]: x, y, z, size (f64), log-odds
/// (f32), depth (u8), three bytes of padding.
pub const LEAF_RECORD: usize = 40;

/// Leaves as packed records (see [`LEAF_RECORD`] and [`leaf_dtype`]).
pub fn leaf_records<'a>(leaves: impl Iterator<Item = NodeItem<'a>>) -> Vec<u8> {
    let mut out = Vec::new();
    for n in leaves {
        let c = n.center();
        let mut rec = [0u8; LEAF_RECORD];
        rec[0..8].copy_from_slice(&c[0].to_ne_bytes());
        rec[8..16].copy_from_slice(&c[1].to_ne_bytes());
        rec[16..24].copy_from_slice(&c[2].to_ne_bytes());
        rec[24..32].copy_from_slice(&n.size().to_ne_bytes());
        rec[32..36].copy_from_slice(&n.value.to_ne_bytes());
        rec[36] = n.depth;
        out.extend_from_slice(&rec);
    }
    out
}

/// The numpy dtype of [`leaf_records`]: fields `x`, `y`, `z`, `size`
/// (float64), `log_odds` (float32), `depth` (uint8).
pub fn leaf_dtype(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let spec = PyDict::new(py);
    spec.set_item("names", ["x", "y", "z", "size", "log_odds", "depth"])?;
    spec.set_item("formats", ["f8", "f8", "f8", "f8", "f4", "u1"])?;
    spec.set_item("offsets", [0, 8, 16, 24, 32, 36])?;
    spec.set_item("itemsize", LEAF_RECORD)?;
    py.import("numpy")?.getattr("dtype")?.call1((spec,))
}

/// Records as a numpy structured array, without a copy.
pub fn leaves_array(py: Python<'_>, records: Vec<u8>) -> PyResult<Bound<'_, PyAny>> {
    let bytes: Bound<'_, PyArray1<u8>> = records.into_pyarray(py);
    bytes.call_method1("view", (leaf_dtype(py)?,))
}

/// `bbox=(min, max)` as the inclusive key box OctoMap's bounding-box
/// iterator uses; both corners must lie in the map.
pub fn key_box(keys: &KeySpace, bbox: &Bound<'_, PyAny>) -> PyResult<KeyBox> {
    let (lo, hi): (Bound<'_, PyAny>, Bound<'_, PyAny>) = bbox
        .extract()
        .map_err(|_| pyo3::exceptions::PyTypeError::new_err("bbox: expected a pair (min, max) of 3-vectors"))?;
    let lo = crate::convert::point(&lo, "bbox min")?;
    let hi = crate::convert::point(&hi, "bbox max")?;
    Ok(KeyBox { min: corner_key(keys, lo, "min")?, max: corner_key(keys, hi, "max")? })
}

/// The key of a box corner (`what`: "min" or "max"); `ValueError` naming
/// the corner when it lies outside the map or is NaN.
pub fn corner_key(keys: &KeySpace, p: Point3, what: &str) -> PyResult<Key> {
    keys.key(p).map_err(|e| PyValueError::new_err(format!("bbox {what} ({}, {}, {}): {e}", p.x, p.y, p.z)))
}

/// `ValueError` (as [`key_box`]'s) when a corner of a box has a NaN
/// coordinate: such a box has no extent to iterate, where a corner merely
/// outside the map makes an empty box.
pub fn reject_nan_corners(keys: &KeySpace, lo: Point3, hi: Point3) -> PyResult<()> {
    for (p, what) in [(lo, "min"), (hi, "max")] {
        if [p.x, p.y, p.z].iter().any(|c| c.is_nan()) {
            corner_key(keys, p, what)?;
        }
    }
    Ok(())
}

/// `max_depth=None` as the library's 0 (every level), else 1..=16.
pub fn max_depth(depth: Option<u32>) -> PyResult<u8> {
    match depth {
        None | Some(0) => Ok(0),
        Some(d @ 1..=16) => Ok(d as u8),
        Some(d) => Err(PyValueError::new_err(format!("depth {d} is outside 0..=16"))),
    }
}

/// `(state, log_odds)` as [`occupancy_arrays`] returns them.
pub type OccupancyArrays<'py> = (Bound<'py, PyArray1<i8>>, Bound<'py, PyArray1<f32>>);
/// `(hit, end)` as [`ray_arrays`] returns them.
pub type RayArrays<'py> = (Bound<'py, PyArray1<bool>>, Bound<'py, PyArray2<f64>>);
/// An `(N, 3)` float64 array of points.
pub type Points<'py> = Bound<'py, PyArray2<f64>>;

/// The `(state, log_odds)` pair of arrays [`occupancy`] returns.
pub fn occupancy_arrays<'py>(py: Python<'py>, (state, log_odds): (Vec<i8>, Vec<f32>)) -> OccupancyArrays<'py> {
    (state.into_pyarray(py), log_odds.into_pyarray(py))
}

/// The `(hit, end)` pair of arrays [`cast_rays`] returns.
pub fn ray_arrays<'py>(py: Python<'py>, (hit, end): (Vec<bool>, Vec<[f64; 3]>)) -> PyResult<RayArrays<'py>> {
    let n = end.len();
    let flat: Vec<f64> = end.into_iter().flatten().collect();
    let end = flat.into_pyarray(py).reshape([n, 3])?;
    Ok((hit.into_pyarray(py), end))
}
