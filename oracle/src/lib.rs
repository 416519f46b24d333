//! Test-only differential oracle: a thin, safe bridge to the real OctoMap
//! (the system `liboctomap`, e.g. Debian's `liboctomap-dev` 1.9.7).
//!
//! The C++ side is a small shim (`shim/octomap_shim.cpp`) with an `extern "C"`
//! API over an opaque handle wrapping `octomap::OcTree*`. `build.rs` compiles
//! it only when OctoMap is installed and then sets `cfg(octomap_available)`;
//! otherwise this crate still compiles, [`available`] returns `false` and every
//! constructor fails with [`OracleError::Unavailable`] (reads return `None`).
//!
//! Conventions: points are `[f32; 3]` (OctoMap's `point3d`), keys `[u16; 3]`
//! (`OcTreeKey`), resolutions and ranges `f64`. Depth arguments are `0..=16`;
//! for `search` and the iterators `0` means "full depth" as in OctoMap. A depth
//! above 16 panics (the Debian library would abort on its assertion).
//!
//! OctoMap's console output (its warnings, `MapCollection`'s per-ray lines)
//! is printed with `print!`/`eprint!` on the thread that called OctoMap, so
//! the test harness keeps it with the test that caused it (with glibc; on
//! other C libraries it stays on the console).
//!
//! OctoMap is not thread-safe, and [`OracleTree`] is neither `Send` nor `Sync`.
//! `deleteNode` is deliberately not exposed: Debian's build has assertions
//! enabled and aborts when an inner node is deleted.

use std::fmt;
use std::path::{Path, PathBuf};
use std::ptr::NonNull;

/// How to install the library the oracle needs.
pub const INSTALL_HINT: &str = "apt-get install -y liboctomap-dev";

/// `true` when the crate was built against OctoMap (the shim is linked in).
pub fn available() -> bool {
    cfg!(octomap_available)
}

/// OctoMap version reported by pkg-config at build time (`None` when the
/// oracle is unavailable; `Some("unknown")` when found without pkg-config).
pub fn octomap_version() -> Option<&'static str> {
    #[cfg(octomap_available)]
    {
        Some(env!("OCTOLINEAR_ORACLE_OCTOMAP_VERSION"))
    }
    #[cfg(not(octomap_available))]
    {
        None
    }
}

/// Environment variable that CI services set (`CI=true`). Where it is set
/// (to anything but empty, `0` or `false`), a test that needs OctoMap fails
/// when OctoMap is missing instead of skipping, so that no CI run claims a
/// comparison it did not make.
pub const CI_ENV: &str = "CI";

/// For tests: `true` if the oracle can be used. Without OctoMap the test
/// reports a skip and gets `false`, or fails under CI (see
/// [`skip_without_octomap`]).
#[track_caller]
pub fn require_or_skip(test_name: &str) -> bool {
    if available() {
        return true;
    }
    skip_without_octomap(test_name, &format!("the OctoMap oracle is unavailable (install: {INSTALL_HINT})"));
    false
}

/// For a test (or part of one) that needs a piece of OctoMap which is
/// `missing` (the library, or a tool of `octomap-tools`): reports a skip, or
/// panics with what is missing where the `CI` environment variable is set.
///
/// A skip writes one line, `<test_name>: SKIPPED ...`, straight to the
/// process's stderr: the test harness captures `println!` and `eprintln!`
/// of passing tests and would show it only on failure, but not what is
/// written to the stderr handle itself, so a plain `cargo test` shows
/// every skip among the results.
#[track_caller]
pub fn skip_without_octomap(test_name: &str, missing: &str) {
    use std::io::Write as _;
    match skip_decision(test_name, missing, std::env::var(CI_ENV).ok().as_deref()) {
        SkipDecision::Skip(line) => {
            let _ = std::io::stderr().write_all(format!("{line}\n").as_bytes());
        }
        SkipDecision::Fail(msg) => panic!("{msg}"),
    }
}

#[derive(Debug, PartialEq)]
enum SkipDecision {
    Skip(String),
    Fail(String),
}

/// What a test does when OctoMap is `missing`, given the value of `CI`.
fn skip_decision(test_name: &str, missing: &str, ci: Option<&str>) -> SkipDecision {
    match ci.map(str::trim) {
        Some(ci) if !ci.is_empty() && ci != "0" && !ci.eq_ignore_ascii_case("false") => SkipDecision::Fail(format!(
            "{test_name}: needs OctoMap, but {missing}; {CI_ENV}={ci} requires every comparison with OctoMap to run"
        )),
        _ => SkipDecision::Skip(format!(
            "{test_name}: SKIPPED, needs OctoMap, but {missing} (with {CI_ENV}=true this fails)"
        )),
    }
}

/// Environment variable naming another directory of golden vectors than the
/// one the repository carries.
pub const GOLDEN_ENV: &str = "OCTOLINEAR_GOLDEN";

/// Where the tests find OctoMap's recorded answers, the golden vectors (see
/// `tests/golden/README.md`): `tests/golden` of this workspace, which the
/// repository carries, or the directory `OCTOLINEAR_GOLDEN` names. Panics,
/// naming the directory, when it holds no `manifest.json`: a test must not
/// pass without the data it checks against.
pub fn golden_dir() -> PathBuf {
    let (dir, from) = match std::env::var_os(GOLDEN_ENV).filter(|d| !d.is_empty()) {
        Some(dir) => (PathBuf::from(dir), GOLDEN_ENV),
        None => {
            let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("the oracle is a workspace member");
            (workspace.join("tests").join("golden"), "the workspace's tests/golden")
        }
    };
    assert!(
        dir.join("manifest.json").is_file(),
        "golden vectors not found: {} (from {from}) has no manifest.json",
        dir.display()
    );
    dir
}

/// Sensor model probabilities. They are applied like OctoMap's `graph2tree`
/// tool does: `setClampingThresMin`, `setClampingThresMax`, `setProbHit`,
/// `setProbMiss`, in this order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorParams {
    pub prob_hit: f64,
    pub prob_miss: f64,
    pub clamp_min: f64,
    pub clamp_max: f64,
}

impl Default for SensorParams {
    /// OctoMap's defaults: hit 0.7, miss 0.4, clamping 0.1192 / 0.971.
    fn default() -> Self {
        SensorParams { prob_hit: 0.7, prob_miss: 0.4, clamp_min: 0.1192, clamp_max: 0.971 }
    }
}

/// The sensor model as the tree holds it: probabilities as returned by the
/// getters (`probability(logodds)`), and the stored float log-odds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorModel {
    pub clamp_min: f64,
    pub clamp_max: f64,
    pub prob_hit: f64,
    pub prob_miss: f64,
    pub occupancy_thres: f64,
    pub clamp_min_log: f32,
    pub clamp_max_log: f32,
    pub prob_hit_log: f32,
    pub prob_miss_log: f32,
    pub occupancy_thres_log: f32,
}

/// One node from `begin_leafs` / `begin_tree`, in iteration order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeInfo {
    /// The iterator's `getKey()`.
    pub key: [u16; 3],
    pub depth: u8,
    /// Always `true` for [`OracleTree::leaves`].
    pub is_leaf: bool,
    pub logodds: f32,
}

/// Result of a successful `search`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchResult {
    pub logodds: f32,
    /// `isNodeOccupied`
    pub occupied: bool,
    /// `isNodeAtThreshold`
    pub at_threshold: bool,
}

/// Everything the golden `stats.csv` reports about a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeStats {
    pub size: u64,
    pub num_leaf_nodes: u64,
    pub calc_num_nodes: u64,
    pub memory_usage: u64,
    pub memory_usage_node: u64,
    /// Computed through the const extent functions.
    pub memory_full_grid: u64,
    pub num_changes_detected: u64,
    pub resolution: f64,
    pub tree_depth: u32,
    /// Log-odds of the root, `None` for an empty tree.
    pub root_logodds: Option<f32>,
    /// Non-const `getMetricMin/Max/Size` (called after the const ones).
    pub metric_min: [f64; 3],
    pub metric_max: [f64; 3],
    pub metric_size: [f64; 3],
    /// Const overloads (`center ± size/2`).
    pub const_metric_min: [f64; 3],
    pub const_metric_max: [f64; 3],
    pub const_metric_size: [f64; 3],
    pub volume: f64,
}

/// Errors of the oracle.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum OracleError {
    /// The crate was built without OctoMap.
    Unavailable,
    /// An argument OctoMap would reject with an assertion (or that is nonsense).
    InvalidArgument(&'static str),
    /// A ray longer than OctoMap's `KeyRay` capacity (100000 keys); OctoMap would abort
    /// (assertion) or overflow. Nothing was changed.
    RayTooLong,
    /// OctoMap reported failure.
    Failed(&'static str),
    /// A C++ exception was caught in the shim.
    CppException,
}

impl fmt::Display for OracleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OracleError::Unavailable => {
                write!(f, "OctoMap oracle unavailable (install: {INSTALL_HINT})")
            }
            OracleError::InvalidArgument(what) => write!(f, "invalid argument: {what}"),
            OracleError::RayTooLong => write!(f, "ray longer than OctoMap's KeyRay capacity"),
            OracleError::Failed(what) => write!(f, "OctoMap failed: {what}"),
            OracleError::CppException => write!(f, "C++ exception in the OctoMap shim"),
        }
    }
}

impl std::error::Error for OracleError {}

/// Scans prepared for [`OracleTree::insert_scans`] (flattened once, outside any timed region).
#[derive(Clone, Debug, Default)]
pub struct ScanBatch {
    xyz: Vec<[f32; 3]>,
    counts: Vec<usize>,
    origins: Vec<[f32; 3]>,
}

impl ScanBatch {
    pub fn new() -> Self {
        Self::default()
    }
    /// Appends one scan (world-frame endpoints) with its sensor origin.
    pub fn push(&mut self, points: &[[f32; 3]], origin: [f32; 3]) {
        self.xyz.extend_from_slice(points);
        self.counts.push(points.len());
        self.origins.push(origin);
    }
    pub fn num_scans(&self) -> usize {
        self.counts.len()
    }
    pub fn num_points(&self) -> usize {
        self.xyz.len()
    }
}

// ------------------------------------------------------------------ FFI

mod ffi {
    /// Opaque shim handle (`struct OloTree` in C++).
    #[repr(C)]
    pub struct OloTree {
        _private: [u8; 0],
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct OloNode {
        pub key: [u16; 3],
        pub depth: u8,
        pub is_leaf: u8,
        pub logodds: f32,
    }

    /// Opaque shim handle (`struct OloColorTree` in C++).
    #[repr(C)]
    pub struct OloColorTree {
        _private: [u8; 0],
    }

    /// Opaque shim handle (`struct OloStampedTree` in C++).
    #[repr(C)]
    pub struct OloStampedTree {
        _private: [u8; 0],
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct OloStampedNode {
        pub key: [u16; 3],
        pub depth: u8,
        pub is_leaf: u8,
        pub logodds: f32,
        pub stamp: u32,
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct OloChange {
        pub key: [u16; 3],
        pub is_new: u8,
        pub pad: u8,
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct OloStats {
        pub size: u64,
        pub num_leaf_nodes: u64,
        pub calc_num_nodes: u64,
        pub memory_usage: u64,
        pub memory_usage_node: u64,
        pub memory_full_grid: u64,
        pub num_changes_detected: u64,
        pub resolution: f64,
        pub tree_depth: u32,
        pub has_root: u32,
        pub root_logodds: f32,
        pub pad: f32,
        pub metric_min: [f64; 3],
        pub metric_max: [f64; 3],
        pub metric_size: [f64; 3],
        pub const_metric_min: [f64; 3],
        pub const_metric_max: [f64; 3],
        pub const_metric_size: [f64; 3],
        pub volume: f64,
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct OloSensor {
        pub clamp_min: f64,
        pub clamp_max: f64,
        pub prob_hit: f64,
        pub prob_miss: f64,
        pub occupancy_thres: f64,
        pub clamp_min_log: f32,
        pub clamp_max_log: f32,
        pub prob_hit_log: f32,
        pub prob_miss_log: f32,
        pub occupancy_thres_log: f32,
    }

    pub const OLO_OK: i32 = 0;
    pub const OLO_EINVAL: i32 = -1;
    pub const OLO_ERAY_TOO_LONG: i32 = -2;
    pub const OLO_EFAILED: i32 = -3;

    /// Declares the shim functions once: real `extern "C"` declarations when
    /// OctoMap is available, unreachable stubs otherwise (never called, since
    /// no `OracleTree` can be constructed then).
    macro_rules! shim_fns {
        ($( fn $name:ident ( $($arg:ident : $ty:ty),* $(,)? ) $(-> $ret:ty)? ; )*) => {
            #[cfg(octomap_available)]
            #[allow(dead_code)] // some are only used by the tests
            extern "C" {
                $( pub fn $name($($arg: $ty),*) $(-> $ret)?; )*
            }
            $(
                #[cfg(not(octomap_available))]
                #[allow(unused_variables, dead_code, clippy::missing_safety_doc)]
                pub unsafe fn $name($($arg: $ty),*) $(-> $ret)? {
                    unreachable!("OctoMap oracle unavailable")
                }
            )*
        };
    }

    shim_fns! {
        fn olo_route_output(write: extern "C" fn(i32, *const std::ffi::c_char, usize)) -> i32;
        fn olo_free(p: *mut core::ffi::c_void);
        fn olo_tree_new(resolution: f64) -> *mut OloTree;
        fn olo_tree_new_sensor(resolution: f64, cmin: f64, cmax: f64, hit: f64, miss: f64) -> *mut OloTree;
        fn olo_tree_new_graph2tree_default(resolution: f64) -> *mut OloTree;
        fn olo_tree_free(h: *mut OloTree);
        fn olo_set_sensor(h: *mut OloTree, cmin: f64, cmax: f64, hit: f64, miss: f64) -> i32;
        fn olo_set_occupancy_thres(h: *mut OloTree, p: f64) -> i32;
        fn olo_get_sensor(h: *const OloTree, out: *mut OloSensor);
        fn olo_set_bbx(h: *mut OloTree, min: *const f32, max: *const f32) -> i32;
        fn olo_use_bbx_limit(h: *mut OloTree, enable: i32);
        fn olo_enable_change_detection(h: *mut OloTree, enable: i32);
        fn olo_reset_change_detection(h: *mut OloTree);
        fn olo_insert_point_cloud(h: *mut OloTree, xyz: *const f32, n: usize, origin: *const f32, maxrange: f64,
                                  lazy: i32, discretize: i32) -> i32;
        fn olo_insert_point_cloud_rays(h: *mut OloTree, xyz: *const f32, n: usize, origin: *const f32,
                                       maxrange: f64, lazy: i32) -> i32;
        fn olo_insert_scans(h: *mut OloTree, xyz: *const f32, counts: *const usize, origins: *const f32,
                            n_scans: usize, maxrange: f64, lazy: i32, discretize: i32) -> i32;
        fn olo_update_inner_occupancy(h: *mut OloTree) -> i32;
        fn olo_update_node_occ(h: *mut OloTree, p: *const f32, occupied: i32, lazy: i32) -> i32;
        fn olo_update_node_logodds(h: *mut OloTree, p: *const f32, delta: f32, lazy: i32) -> i32;
        fn olo_update_node_key_occ(h: *mut OloTree, k: *const u16, occupied: i32, lazy: i32) -> i32;
        fn olo_update_node_key_logodds(h: *mut OloTree, k: *const u16, delta: f32, lazy: i32) -> i32;
        fn olo_set_node_value(h: *mut OloTree, p: *const f32, value: f32, lazy: i32) -> i32;
        fn olo_set_node_value_key(h: *mut OloTree, k: *const u16, value: f32, lazy: i32) -> i32;
        fn olo_prune(h: *mut OloTree) -> i32;
        fn olo_expand(h: *mut OloTree) -> i32;
        fn olo_to_max_likelihood(h: *mut OloTree) -> i32;
        fn olo_clear(h: *mut OloTree) -> i32;
        fn olo_write(h: *mut OloTree, which: i32, out: *mut *mut u8, len: *mut usize) -> i32;
        fn olo_read_ot(data: *const u8, len: usize) -> *mut OloTree;
        fn olo_read_bt(data: *const u8, len: usize) -> *mut OloTree;
        fn olo_search(h: *const OloTree, p: *const f32, depth: u32, logodds: *mut f32, occupied: *mut i32,
                      at_threshold: *mut i32) -> i32;
        fn olo_search_key(h: *const OloTree, k: *const u16, depth: u32, logodds: *mut f32, occupied: *mut i32,
                          at_threshold: *mut i32) -> i32;
        fn olo_dump(h: *const OloTree, which: i32, max_depth: u32, out: *mut *mut OloNode, count: *mut usize) -> i32;
        fn olo_compute_ray_keys(h: *mut OloTree, origin: *const f32, end: *const f32, out: *mut *mut u16,
                                count: *mut usize) -> i32;
        fn olo_cast_ray(h: *const OloTree, origin: *const f32, direction: *const f32, ignore_unknown: i32,
                        max_range: f64, end_out: *mut f32) -> i32;
        fn olo_coord_to_key_checked(h: *const OloTree, p: *const f32, depth: u32, key: *mut u16) -> i32;
        fn olo_coord_to_key_checked_scalar(h: *const OloTree, c: f64, depth: u32, key: *mut u16) -> i32;
        fn olo_coord_to_key_scalar(h: *const OloTree, c: f64, depth: u32, key: *mut u16) -> i32;
        fn olo_key_to_coord(h: *const OloTree, k: *const u16, depth: u32, out: *mut f32) -> i32;
        fn olo_key_to_coord_scalar(h: *const OloTree, k: u16, depth: u32, out: *mut f64) -> i32;
        fn olo_stats(h: *mut OloTree, s: *mut OloStats) -> i32;
        fn olo_resolution(h: *const OloTree) -> f64;
        fn olo_size(h: *const OloTree) -> u64;
        fn olo_num_leaf_nodes(h: *const OloTree) -> u64;
        fn olo_calc_num_nodes(h: *const OloTree) -> u64;
        fn olo_memory_usage(h: *const OloTree) -> u64;
        fn olo_memory_full_grid(h: *const OloTree) -> u64;
        fn olo_metric_min_max_const(h: *const OloTree, min: *mut f64, max: *mut f64);
        fn olo_volume(h: *mut OloTree) -> f64;
        fn olo_changed_keys(h: *const OloTree, out: *mut *mut OloChange, count: *mut usize) -> i32;
        fn olo_bench_search(h: *const OloTree, xyz: *const f32, n: usize, depth: u32, out: *mut f32) -> i64;
        fn olo_bench_leaf_sum(h: *const OloTree, max_depth: u32, sum: *mut f64) -> i64;
        fn olo_bench_cast_rays(h: *const OloTree, origins: *const f32, dirs: *const f32, n: usize,
                               ignore_unknown: i32, max_range: f64, ends: *mut f32, hits: *mut u8) -> i64;
        fn olo_sizeof_node() -> usize;
        fn olo_sizeof_change() -> usize;
        fn olo_sizeof_stats() -> usize;
        fn olo_sizeof_sensor() -> usize;
        fn olo_color_new(resolution: f64, sensor: i32, cmin: f64, cmax: f64, hit: f64, miss: f64)
            -> *mut OloColorTree;
        fn olo_color_free(h: *mut OloColorTree);
        fn olo_color_insert_point_cloud(h: *mut OloColorTree, xyz: *const f32, n: usize, origin: *const f32,
            maxrange: f64, lazy: i32, discretize: i32) -> i32;
        fn olo_color_apply(h: *mut OloColorTree, which: i32, xyz: *const f32, rgb: *const u8, n: usize) -> i64;
        fn olo_color_update_node(h: *mut OloColorTree, p: *const f32, occupied: i32, lazy: i32) -> i32;
        fn olo_color_op(h: *mut OloColorTree, which: i32) -> i32;
        fn olo_color_write(h: *const OloColorTree, out: *mut *mut u8, len: *mut usize) -> i32;
        fn olo_color_search(h: *const OloColorTree, p: *const f32, depth: u32, logodds: *mut f32, rgb: *mut u8)
            -> i32;
        fn olo_stamped_new(resolution: f64) -> *mut OloStampedTree;
        fn olo_stamped_free(h: *mut OloStampedTree);
        fn olo_stamped_insert_point_cloud(h: *mut OloStampedTree, xyz: *const f32, n: usize, origin: *const f32,
            maxrange: f64, lazy: i32, discretize: i32, t: *mut u32) -> i32;
        fn olo_stamped_update_node(h: *mut OloStampedTree, p: *const f32, occupied: i32, lazy: i32, t: *mut u32)
            -> i32;
        fn olo_stamped_op(h: *mut OloStampedTree, which: i32, arg: u32, t: *mut u32) -> i32;
        fn olo_stamped_write(h: *const OloStampedTree, out: *mut *mut u8, len: *mut usize) -> i32;
        fn olo_stamped_dump(h: *const OloStampedTree, out: *mut *mut OloStampedNode, count: *mut usize) -> i32;
        fn olo_sizeof_stamped_node() -> usize;
        fn olo_mapcoll_query(path: *const std::ffi::c_char, pts: *const f32, n_pts: usize, occupied: *mut u8,
            occupancy: *mut f64, rays: *const f32, max_ranges: *const f64, n_rays: usize, ignore_unknown: i32,
            hits: *mut u8, ends: *mut f32) -> i64;
    }
}

/// `true` when OctoMap is built in. The first call routes OctoMap's console
/// output through [`print_octomap_output`]; every way into OctoMap calls this
/// first.
fn octomap_ready() -> bool {
    static ROUTE: std::sync::Once = std::sync::Once::new();
    if available() {
        // SAFETY: the callback stays valid for the life of the process, and
        // the Once makes this the first shim call of any thread.
        ROUTE.call_once(|| unsafe {
            ffi::olo_route_output(print_octomap_output);
        });
    }
    available()
}

/// Prints what OctoMap writes to stdout or stderr (`stream` 1 or 2) with
/// `print!` or `eprint!` on the thread that wrote it. The test harness thus
/// keeps OctoMap's warnings with the output of the test that caused them:
/// shown when that test fails or with `--nocapture`, and silent otherwise.
extern "C" fn print_octomap_output(stream: i32, data: *const std::ffi::c_char, len: usize) {
    if data.is_null() {
        return;
    }
    // SAFETY: the shim passes `len` readable bytes at `data`.
    let text = String::from_utf8_lossy(unsafe { std::slice::from_raw_parts(data.cast::<u8>(), len) });
    // A print that fails (closed stdout) panics; that must not unwind into C++.
    let _ = std::panic::catch_unwind(|| if stream == 1 { print!("{text}") } else { eprint!("{text}") });
}

/// Copies a shim-allocated array into a `Vec` and frees it.
///
/// # Safety
/// `ptr` must be null (then `n` is ignored) or a `malloc`ed array of `n` valid `T`s
/// that nobody else owns.
unsafe fn take_vec<T: Copy>(ptr: *mut T, n: usize) -> Vec<T> {
    if ptr.is_null() {
        return Vec::new();
    }
    // SAFETY: guaranteed by the caller: `ptr` points to `n` initialised `T`s.
    let v = unsafe { std::slice::from_raw_parts(ptr, n) }.to_vec();
    // SAFETY: `ptr` was allocated by the shim with malloc and is freed exactly once here.
    unsafe { ffi::olo_free(ptr.cast()) };
    v
}

fn check_depth(depth: u8) -> u32 {
    assert!(depth <= 16, "octree depth {depth} > 16");
    u32::from(depth)
}

fn status(code: i32, what: &'static str) -> Result<(), OracleError> {
    match code {
        ffi::OLO_OK => Ok(()),
        ffi::OLO_EINVAL => Err(OracleError::InvalidArgument(what)),
        ffi::OLO_ERAY_TOO_LONG => Err(OracleError::RayTooLong),
        ffi::OLO_EFAILED => Err(OracleError::Failed(what)),
        _ => Err(OracleError::CppException),
    }
}

/// For calls that can only fail through a C++ exception (e.g. `bad_alloc`).
fn must(code: i32, what: &'static str) -> i32 {
    assert!(code >= 0, "OctoMap shim: {what} failed ({:?})", status(code, what));
    code
}

fn validate_sensor(s: &SensorParams) -> Result<(), OracleError> {
    // OctoMap asserts logodds(hit) >= 0 and logodds(miss) <= 0.
    if !(s.prob_hit >= 0.5 && s.prob_hit <= 1.0) {
        return Err(OracleError::InvalidArgument("prob_hit must be in [0.5, 1]"));
    }
    if !(s.prob_miss >= 0.0 && s.prob_miss <= 0.5) {
        return Err(OracleError::InvalidArgument("prob_miss must be in [0, 0.5]"));
    }
    if !(s.clamp_min >= 0.0 && s.clamp_min <= 1.0 && s.clamp_max >= 0.0 && s.clamp_max <= 1.0) {
        return Err(OracleError::InvalidArgument("clamping thresholds must be in [0, 1]"));
    }
    Ok(())
}

fn validate_resolution(resolution: f64) -> Result<(), OracleError> {
    if resolution.is_finite() && resolution > 0.0 {
        Ok(())
    } else {
        Err(OracleError::InvalidArgument("resolution must be finite and > 0"))
    }
}

/// An `octomap::OcTree` owned through the shim. Dropping it deletes the tree.
pub struct OracleTree {
    // NonNull (a raw pointer) makes the type !Send and !Sync.
    ptr: NonNull<ffi::OloTree>,
}

impl Drop for OracleTree {
    fn drop(&mut self) {
        // SAFETY: `ptr` came from a shim constructor and is freed exactly once.
        unsafe { ffi::olo_tree_free(self.ptr.as_ptr()) }
    }
}

impl fmt::Debug for OracleTree {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("OracleTree").field("resolution", &self.resolution()).finish_non_exhaustive()
    }
}

impl OracleTree {
    fn from_raw(p: *mut ffi::OloTree) -> Option<Self> {
        NonNull::new(p).map(|ptr| OracleTree { ptr })
    }

    fn h(&self) -> *const ffi::OloTree {
        self.ptr.as_ptr()
    }

    fn hm(&mut self) -> *mut ffi::OloTree {
        self.ptr.as_ptr()
    }

    /// `OcTree(resolution)` with OctoMap's sensor defaults left untouched.
    pub fn new(resolution: f64) -> Result<Self, OracleError> {
        if !octomap_ready() {
            return Err(OracleError::Unavailable);
        }
        validate_resolution(resolution)?;
        // SAFETY: plain value argument; returns an owned handle or null.
        Self::from_raw(unsafe { ffi::olo_tree_new(resolution) }).ok_or(OracleError::CppException)
    }

    /// `OcTree(resolution)` then the sensor model set graph2tree-style
    /// (`setClampingThresMin/Max`, `setProbHit`, `setProbMiss`).
    pub fn with_sensor(resolution: f64, sensor: &SensorParams) -> Result<Self, OracleError> {
        if !octomap_ready() {
            return Err(OracleError::Unavailable);
        }
        validate_resolution(resolution)?;
        validate_sensor(sensor)?;
        let s = sensor;
        // SAFETY: plain value arguments (validated against OctoMap's assertions).
        let p = unsafe { ffi::olo_tree_new_sensor(resolution, s.clamp_min, s.clamp_max, s.prob_hit, s.prob_miss) };
        Self::from_raw(p).ok_or(OracleError::CppException)
    }

    /// What the golden harness calls the "default" sensor model: the
    /// probabilities are read back from the fresh tree (`getProbHit()` ...) and
    /// set again graph2tree-style.
    pub fn with_graph2tree_default(resolution: f64) -> Result<Self, OracleError> {
        if !octomap_ready() {
            return Err(OracleError::Unavailable);
        }
        validate_resolution(resolution)?;
        // SAFETY: plain value argument; returns an owned handle or null.
        Self::from_raw(unsafe { ffi::olo_tree_new_graph2tree_default(resolution) }).ok_or(OracleError::CppException)
    }

    /// `AbstractOcTree::read` of `.ot` bytes; `None` on failure or if the file is
    /// not an `OcTree`. The sensor model is OctoMap's default (`.ot` does not store it).
    pub fn read_ot(bytes: &[u8]) -> Option<Self> {
        if !octomap_ready() {
            return None;
        }
        // SAFETY: the shim copies `bytes` (pointer + length valid for the call).
        Self::from_raw(unsafe { ffi::olo_read_ot(bytes.as_ptr(), bytes.len()) })
    }

    /// A fresh `OcTree(0.1)` + `readBinary` of `.bt` bytes; `None` on failure.
    pub fn read_bt(bytes: &[u8]) -> Option<Self> {
        if !octomap_ready() {
            return None;
        }
        // SAFETY: the shim copies `bytes` (pointer + length valid for the call).
        Self::from_raw(unsafe { ffi::olo_read_bt(bytes.as_ptr(), bytes.len()) })
    }

    // -------------------------------------------------------------- settings

    /// Sets the sensor model graph2tree-style (e.g. after `read_ot`).
    pub fn set_sensor(&mut self, sensor: &SensorParams) -> Result<(), OracleError> {
        validate_sensor(sensor)?;
        let s = sensor;
        // SAFETY: valid handle; plain value arguments.
        status(
            unsafe { ffi::olo_set_sensor(self.hm(), s.clamp_min, s.clamp_max, s.prob_hit, s.prob_miss) },
            "set_sensor",
        )
    }

    /// `setOccupancyThres(p)`.
    pub fn set_occupancy_thres(&mut self, p: f64) {
        // SAFETY: valid handle; plain value argument.
        must(unsafe { ffi::olo_set_occupancy_thres(self.hm(), p) }, "setOccupancyThres");
    }

    /// The sensor model as stored in the tree.
    pub fn sensor(&self) -> SensorModel {
        let mut s = ffi::OloSensor::default();
        // SAFETY: valid handle; `s` is a valid out-pointer with the C layout.
        unsafe { ffi::olo_get_sensor(self.h(), &mut s) };
        SensorModel {
            clamp_min: s.clamp_min,
            clamp_max: s.clamp_max,
            prob_hit: s.prob_hit,
            prob_miss: s.prob_miss,
            occupancy_thres: s.occupancy_thres,
            clamp_min_log: s.clamp_min_log,
            clamp_max_log: s.clamp_max_log,
            prob_hit_log: s.prob_hit_log,
            prob_miss_log: s.prob_miss_log,
            occupancy_thres_log: s.occupancy_thres_log,
        }
    }

    /// `setBBXMin(min); setBBXMax(max); useBBXLimit(true)`.
    pub fn set_bbx(&mut self, min: [f32; 3], max: [f32; 3]) {
        // SAFETY: valid handle; the arrays hold 3 floats each.
        must(unsafe { ffi::olo_set_bbx(self.hm(), min.as_ptr(), max.as_ptr()) }, "setBBX");
    }

    /// `useBBXLimit(enable)`.
    pub fn use_bbx_limit(&mut self, enable: bool) {
        // SAFETY: valid handle.
        unsafe { ffi::olo_use_bbx_limit(self.hm(), enable.into()) }
    }

    /// `enableChangeDetection(enable)`.
    pub fn enable_change_detection(&mut self, enable: bool) {
        // SAFETY: valid handle.
        unsafe { ffi::olo_enable_change_detection(self.hm(), enable.into()) }
    }

    /// `resetChangeDetection()`.
    pub fn reset_change_detection(&mut self) {
        // SAFETY: valid handle.
        unsafe { ffi::olo_reset_change_detection(self.hm()) }
    }

    /// Contents of the change-detection map, sorted by key (the C++ container is
    /// unordered). The bool is the map's value: `true` = leaf newly created.
    pub fn changed_keys(&self) -> Vec<([u16; 3], bool)> {
        let (mut p, mut n) = (std::ptr::null_mut(), 0usize);
        // SAFETY: valid handle and out-pointers.
        must(unsafe { ffi::olo_changed_keys(self.h(), &mut p, &mut n) }, "changedKeys");
        // SAFETY: the shim returned a malloc'ed array of `n` OloChange (or null).
        let v = unsafe { take_vec(p, n) };
        let mut out: Vec<([u16; 3], bool)> = v.iter().map(|c| (c.key, c.is_new != 0)).collect();
        out.sort_unstable();
        out
    }

    // -------------------------------------------------------------- updates

    /// `insertPointCloud(points, origin, maxrange, lazy_eval, discretize)`.
    pub fn insert_point_cloud(
        &mut self,
        points: &[[f32; 3]],
        origin: [f32; 3],
        maxrange: f64,
        lazy_eval: bool,
        discretize: bool,
    ) -> Result<(), OracleError> {
        // SAFETY: valid handle; `points` is `len` contiguous [f32; 3]; the shim copies it.
        let code = unsafe {
            ffi::olo_insert_point_cloud(
                self.hm(),
                points.as_ptr().cast(),
                points.len(),
                origin.as_ptr(),
                maxrange,
                lazy_eval.into(),
                discretize.into(),
            )
        };
        status(code, "insertPointCloud")
    }

    /// `insertPointCloudRays(points, origin, maxrange, lazy_eval)` (the "simple"
    /// mode; OctoMap ignores `maxrange` there).
    pub fn insert_point_cloud_rays(
        &mut self,
        points: &[[f32; 3]],
        origin: [f32; 3],
        maxrange: f64,
        lazy_eval: bool,
    ) -> Result<(), OracleError> {
        // SAFETY: valid handle; `points` is `len` contiguous [f32; 3]; the shim copies it.
        let code = unsafe {
            ffi::olo_insert_point_cloud_rays(
                self.hm(),
                points.as_ptr().cast(),
                points.len(),
                origin.as_ptr(),
                maxrange,
                lazy_eval.into(),
            )
        };
        status(code, "insertPointCloudRays")
    }

    /// Inserts every scan of `batch` with `insertPointCloud`, the loop running in
    /// C++ (for benchmarks). With `lazy_eval`, `updateInnerOccupancy()` follows
    /// every scan, as in the golden harness.
    pub fn insert_scans(
        &mut self,
        batch: &ScanBatch,
        maxrange: f64,
        lazy_eval: bool,
        discretize: bool,
    ) -> Result<(), OracleError> {
        // SAFETY: valid handle; the batch arrays are consistent (sum(counts) == xyz.len(),
        // origins.len() == counts.len()), as maintained by ScanBatch::push.
        let code = unsafe {
            ffi::olo_insert_scans(
                self.hm(),
                batch.xyz.as_ptr().cast(),
                batch.counts.as_ptr(),
                batch.origins.as_ptr().cast(),
                batch.counts.len(),
                maxrange,
                lazy_eval.into(),
                discretize.into(),
            )
        };
        status(code, "insertPointCloud (batch)")
    }

    /// `updateInnerOccupancy()`.
    pub fn update_inner_occupancy(&mut self) {
        // SAFETY: valid handle.
        must(unsafe { ffi::olo_update_inner_occupancy(self.hm()) }, "updateInnerOccupancy");
    }

    /// `updateNode(point, occupied, lazy_eval)`; `false` if the point is outside the map.
    pub fn update_node(&mut self, p: [f32; 3], occupied: bool, lazy_eval: bool) -> bool {
        // SAFETY: valid handle; `p` holds 3 floats.
        must(
            unsafe { ffi::olo_update_node_occ(self.hm(), p.as_ptr(), occupied.into(), lazy_eval.into()) },
            "updateNode",
        ) == 1
    }

    /// `updateNode(point, log_odds_delta, lazy_eval)`; `false` if outside the map.
    pub fn update_node_logodds(&mut self, p: [f32; 3], delta: f32, lazy_eval: bool) -> bool {
        // SAFETY: valid handle; `p` holds 3 floats.
        must(unsafe { ffi::olo_update_node_logodds(self.hm(), p.as_ptr(), delta, lazy_eval.into()) }, "updateNode") == 1
    }

    /// `updateNode(key, occupied, lazy_eval)`.
    pub fn update_node_key(&mut self, key: [u16; 3], occupied: bool, lazy_eval: bool) -> bool {
        // SAFETY: valid handle; `key` holds 3 u16.
        let r = unsafe { ffi::olo_update_node_key_occ(self.hm(), key.as_ptr(), occupied.into(), lazy_eval.into()) };
        must(r, "updateNode") == 1
    }

    /// `updateNode(key, log_odds_delta, lazy_eval)`.
    pub fn update_node_key_logodds(&mut self, key: [u16; 3], delta: f32, lazy_eval: bool) -> bool {
        // SAFETY: valid handle; `key` holds 3 u16.
        let r = unsafe { ffi::olo_update_node_key_logodds(self.hm(), key.as_ptr(), delta, lazy_eval.into()) };
        must(r, "updateNode") == 1
    }

    /// `setNodeValue(point, log_odds_value, lazy_eval)`; `false` if outside the map.
    pub fn set_node_value(&mut self, p: [f32; 3], value: f32, lazy_eval: bool) -> bool {
        // SAFETY: valid handle; `p` holds 3 floats.
        must(unsafe { ffi::olo_set_node_value(self.hm(), p.as_ptr(), value, lazy_eval.into()) }, "setNodeValue") == 1
    }

    /// `setNodeValue(key, log_odds_value, lazy_eval)`.
    pub fn set_node_value_key(&mut self, key: [u16; 3], value: f32, lazy_eval: bool) -> bool {
        // SAFETY: valid handle; `key` holds 3 u16.
        let r = unsafe { ffi::olo_set_node_value_key(self.hm(), key.as_ptr(), value, lazy_eval.into()) };
        must(r, "setNodeValue") == 1
    }

    /// `prune()`.
    pub fn prune(&mut self) {
        // SAFETY: valid handle.
        must(unsafe { ffi::olo_prune(self.hm()) }, "prune");
    }

    /// `expand()`.
    pub fn expand(&mut self) {
        // SAFETY: valid handle.
        must(unsafe { ffi::olo_expand(self.hm()) }, "expand");
    }

    /// `toMaxLikelihood()`.
    pub fn to_max_likelihood(&mut self) {
        // SAFETY: valid handle.
        must(unsafe { ffi::olo_to_max_likelihood(self.hm()) }, "toMaxLikelihood");
    }

    /// `clear()`.
    pub fn clear(&mut self) {
        // SAFETY: valid handle.
        must(unsafe { ffi::olo_clear(self.hm()) }, "clear");
    }

    // -------------------------------------------------------------- I/O

    fn write_impl(&self, which: i32, what: &'static str) -> Result<Vec<u8>, OracleError> {
        let (mut p, mut n) = (std::ptr::null_mut(), 0usize);
        // SAFETY: valid handle and out-pointers. For which = 1 (writeBinary) the tree is
        // mutated; that variant is only reachable through `write_bt(&mut self)`.
        status(unsafe { ffi::olo_write(self.ptr.as_ptr(), which, &mut p, &mut n) }, what)?;
        // SAFETY: the shim returned a malloc'ed buffer of `n` bytes (or null).
        Ok(unsafe { take_vec(p, n) })
    }

    /// `write(std::ostream&)`: the `.ot` bytes.
    pub fn write_ot(&self) -> Result<Vec<u8>, OracleError> {
        self.write_impl(0, "write")
    }

    /// Non-const `writeBinary(std::ostream&)`: the `.bt` bytes. Note that OctoMap
    /// runs `toMaxLikelihood()` and `prune()` on the tree itself first.
    pub fn write_bt(&mut self) -> Result<Vec<u8>, OracleError> {
        self.write_impl(1, "writeBinary")
    }

    /// `writeBinaryConst(std::ostream&)`: the `.bt` bytes, tree unchanged.
    pub fn write_bt_const(&self) -> Result<Vec<u8>, OracleError> {
        self.write_impl(2, "writeBinaryConst")
    }

    // -------------------------------------------------------------- queries

    /// `search(point, depth)`: log-odds of the deepest existing node on the path.
    pub fn search(&self, p: [f32; 3], depth: u8) -> Option<f32> {
        self.search_node(p, depth).map(|r| r.logodds)
    }

    /// `isNodeOccupied(search(point, depth))`; `None` if not found.
    pub fn is_node_occupied(&self, p: [f32; 3], depth: u8) -> Option<bool> {
        self.search_node(p, depth).map(|r| r.occupied)
    }

    /// `search(point, depth)` with `isNodeOccupied` / `isNodeAtThreshold`.
    pub fn search_node(&self, p: [f32; 3], depth: u8) -> Option<SearchResult> {
        let d = check_depth(depth);
        let (mut l, mut o, mut t) = (0f32, 0i32, 0i32);
        // SAFETY: valid handle; `p` holds 3 floats; valid out-pointers.
        let r = must(unsafe { ffi::olo_search(self.h(), p.as_ptr(), d, &mut l, &mut o, &mut t) }, "search");
        (r == 1).then_some(SearchResult { logodds: l, occupied: o != 0, at_threshold: t != 0 })
    }

    /// `search(key, depth)`.
    pub fn search_key(&self, key: [u16; 3], depth: u8) -> Option<SearchResult> {
        let d = check_depth(depth);
        let (mut l, mut o, mut t) = (0f32, 0i32, 0i32);
        // SAFETY: valid handle; `key` holds 3 u16; valid out-pointers.
        let r = must(unsafe { ffi::olo_search_key(self.h(), key.as_ptr(), d, &mut l, &mut o, &mut t) }, "search");
        (r == 1).then_some(SearchResult { logodds: l, occupied: o != 0, at_threshold: t != 0 })
    }

    fn dump(&self, which: i32, max_depth: u8) -> Vec<NodeInfo> {
        let d = check_depth(max_depth);
        let (mut p, mut n) = (std::ptr::null_mut(), 0usize);
        // SAFETY: valid handle and out-pointers.
        must(unsafe { ffi::olo_dump(self.h(), which, d, &mut p, &mut n) }, "iterate");
        // SAFETY: the shim returned a malloc'ed array of `n` OloNode (or null).
        let v = unsafe { take_vec(p, n) };
        v.iter().map(|x| NodeInfo { key: x.key, depth: x.depth, is_leaf: x.is_leaf != 0, logodds: x.logodds }).collect()
    }

    /// Every node of `begin_leafs(max_depth)` in iteration order.
    pub fn leaves(&self, max_depth: u8) -> Vec<NodeInfo> {
        self.dump(0, max_depth)
    }

    /// Every node of `begin_tree(max_depth)` (root first) in iteration order.
    pub fn nodes(&self, max_depth: u8) -> Vec<NodeInfo> {
        self.dump(1, max_depth)
    }

    /// `computeRayKeys(origin, end, ray)`: OctoMap's return value and the key list.
    /// Fails with `RayTooLong` instead of overflowing OctoMap's `KeyRay`.
    pub fn compute_ray_keys(&mut self, origin: [f32; 3], end: [f32; 3]) -> Result<(bool, Vec<[u16; 3]>), OracleError> {
        let (mut p, mut n) = (std::ptr::null_mut(), 0usize);
        // SAFETY: valid handle; 3-float arrays; valid out-pointers.
        let r = unsafe { ffi::olo_compute_ray_keys(self.hm(), origin.as_ptr(), end.as_ptr(), &mut p, &mut n) };
        // SAFETY: the shim returned a malloc'ed array of 3*n u16 (or null); free it even on error.
        let flat = unsafe { take_vec(p, 3 * n) };
        if r < 0 {
            return Err(status(r, "computeRayKeys").unwrap_err());
        }
        Ok((r == 1, flat.chunks_exact(3).map(|k| [k[0], k[1], k[2]]).collect()))
    }

    /// `castRay(origin, direction, end, ignore_unknown, max_range)`: the return
    /// value and `end`, which is NaN before the call (still NaN = not written).
    pub fn cast_ray(
        &self,
        origin: [f32; 3],
        direction: [f32; 3],
        ignore_unknown: bool,
        max_range: f64,
    ) -> (bool, [f32; 3]) {
        let mut end = [0f32; 3];
        // SAFETY: valid handle; 3-float arrays in and out.
        let r = unsafe {
            ffi::olo_cast_ray(
                self.h(),
                origin.as_ptr(),
                direction.as_ptr(),
                ignore_unknown.into(),
                max_range,
                end.as_mut_ptr(),
            )
        };
        (must(r, "castRay") == 1, end)
    }

    /// `coordToKeyChecked(point, depth)`.
    pub fn coord_to_key_checked(&self, p: [f32; 3], depth: u8) -> Option<[u16; 3]> {
        let d = check_depth(depth);
        let mut k = [0u16; 3];
        // SAFETY: valid handle; 3-element arrays.
        let r = unsafe { ffi::olo_coord_to_key_checked(self.h(), p.as_ptr(), d, k.as_mut_ptr()) };
        (must(r, "coordToKeyChecked") == 1).then_some(k)
    }

    /// `coordToKeyChecked(double coordinate, depth)`.
    pub fn coord_to_key_checked_scalar(&self, c: f64, depth: u8) -> Option<u16> {
        let d = check_depth(depth);
        let mut k = 0u16;
        // SAFETY: valid handle; valid out-pointer.
        let r = unsafe { ffi::olo_coord_to_key_checked_scalar(self.h(), c, d, &mut k) };
        (must(r, "coordToKeyChecked") == 1).then_some(k)
    }

    /// Unchecked `coordToKey(double coordinate, depth)` (wraps around outside the map).
    pub fn coord_to_key_scalar(&self, c: f64, depth: u8) -> u16 {
        let d = check_depth(depth);
        let mut k = 0u16;
        // SAFETY: valid handle; valid out-pointer.
        must(unsafe { ffi::olo_coord_to_key_scalar(self.h(), c, d, &mut k) }, "coordToKey");
        k
    }

    /// `keyToCoord(key, depth)` as a `point3d`.
    pub fn key_to_coord(&self, key: [u16; 3], depth: u8) -> [f32; 3] {
        let d = check_depth(depth);
        let mut out = [0f32; 3];
        // SAFETY: valid handle; 3-element arrays.
        must(unsafe { ffi::olo_key_to_coord(self.h(), key.as_ptr(), d, out.as_mut_ptr()) }, "keyToCoord");
        out
    }

    /// `keyToCoord(key_type, depth)` (double).
    pub fn key_to_coord_scalar(&self, key: u16, depth: u8) -> f64 {
        let d = check_depth(depth);
        let mut out = 0f64;
        // SAFETY: valid handle; valid out-pointer.
        must(unsafe { ffi::olo_key_to_coord_scalar(self.h(), key, d, &mut out) }, "keyToCoord");
        out
    }

    // -------------------------------------------------------------- statistics

    /// All statistics. Takes `&mut self` because OctoMap's non-const extent
    /// functions and `volume()` update cached values. Beware: once the non-const
    /// `getMetricMin/Max` have run, the const overloads return that cached
    /// (`(center - size/2) + size`) maximum until the tree's size changes, so a
    /// later [`Self::metric_min_max`] or `stats()` may differ in the last bit from
    /// a fresh const computation (the const values here are taken first).
    pub fn stats(&mut self) -> TreeStats {
        let mut s = ffi::OloStats::default();
        // SAFETY: valid handle; `s` is a valid out-pointer with the C layout.
        must(unsafe { ffi::olo_stats(self.hm(), &mut s) }, "stats");
        TreeStats {
            size: s.size,
            num_leaf_nodes: s.num_leaf_nodes,
            calc_num_nodes: s.calc_num_nodes,
            memory_usage: s.memory_usage,
            memory_usage_node: s.memory_usage_node,
            memory_full_grid: s.memory_full_grid,
            num_changes_detected: s.num_changes_detected,
            resolution: s.resolution,
            tree_depth: s.tree_depth,
            root_logodds: (s.has_root != 0).then_some(s.root_logodds),
            metric_min: s.metric_min,
            metric_max: s.metric_max,
            metric_size: s.metric_size,
            const_metric_min: s.const_metric_min,
            const_metric_max: s.const_metric_max,
            const_metric_size: s.const_metric_size,
            volume: s.volume,
        }
    }

    /// `getResolution()`.
    pub fn resolution(&self) -> f64 {
        // SAFETY: valid handle.
        unsafe { ffi::olo_resolution(self.h()) }
    }

    /// `size()` (the maintained node counter).
    pub fn size(&self) -> u64 {
        // SAFETY: valid handle.
        unsafe { ffi::olo_size(self.h()) }
    }

    /// `getNumLeafNodes()`.
    pub fn num_leaf_nodes(&self) -> u64 {
        // SAFETY: valid handle.
        unsafe { ffi::olo_num_leaf_nodes(self.h()) }
    }

    /// `calcNumNodes()` (a recount).
    pub fn calc_num_nodes(&self) -> u64 {
        // SAFETY: valid handle.
        unsafe { ffi::olo_calc_num_nodes(self.h()) }
    }

    /// `memoryUsage()` (C++ `sizeof` based, x86_64 layout).
    pub fn memory_usage(&self) -> u64 {
        // SAFETY: valid handle.
        unsafe { ffi::olo_memory_usage(self.h()) }
    }

    /// `memoryFullGrid()`.
    pub fn memory_full_grid(&self) -> u64 {
        // SAFETY: valid handle.
        unsafe { ffi::olo_memory_full_grid(self.h()) }
    }

    /// Const `getMetricMin` and `getMetricMax`: (min, max). They recompute
    /// `center ± size/2` only while the tree is "size changed"; otherwise they
    /// return the values cached by the last non-const call (see [`Self::stats`]).
    pub fn metric_min_max(&self) -> ([f64; 3], [f64; 3]) {
        let (mut min, mut max) = ([0f64; 3], [0f64; 3]);
        // SAFETY: valid handle; two 3-double out arrays.
        unsafe { ffi::olo_metric_min_max_const(self.h(), min.as_mut_ptr(), max.as_mut_ptr()) };
        (min, max)
    }

    /// `volume()` (non-const in OctoMap: it refreshes the cached extent).
    pub fn volume(&mut self) -> f64 {
        // SAFETY: valid handle.
        unsafe { ffi::olo_volume(self.hm()) }
    }

    // -------------------------------------------------------------- benchmark batches

    /// `search(p, depth)` for every point, loop in C++. `out[i]` = log-odds or NaN.
    /// Returns the number of points found.
    pub fn bench_search(&self, points: &[[f32; 3]], depth: u8, out: &mut [f32]) -> usize {
        assert_eq!(points.len(), out.len(), "bench_search: out must have one slot per point");
        let d = check_depth(depth);
        // SAFETY: valid handle; `points` and `out` have the same length `n`.
        let r = unsafe { ffi::olo_bench_search(self.h(), points.as_ptr().cast(), points.len(), d, out.as_mut_ptr()) };
        assert!(r >= 0, "bench_search failed");
        r as usize
    }

    /// Iterates `begin_leafs(max_depth)` in C++ summing the log-odds (as f64).
    /// Returns (number of leaves, sum).
    pub fn bench_leaf_sum(&self, max_depth: u8) -> (usize, f64) {
        let d = check_depth(max_depth);
        let mut sum = 0f64;
        // SAFETY: valid handle; valid out-pointer.
        let r = unsafe { ffi::olo_bench_leaf_sum(self.h(), d, &mut sum) };
        assert!(r >= 0, "bench_leaf_sum failed");
        (r as usize, sum)
    }

    /// `castRay` for every (origin, direction) pair, loop in C++. Writes each end
    /// point (NaN if not written) and return value; returns the number of `true`s.
    pub fn bench_cast_rays(
        &self,
        origins: &[[f32; 3]],
        directions: &[[f32; 3]],
        ignore_unknown: bool,
        max_range: f64,
        ends: &mut [[f32; 3]],
        hits: &mut [bool],
    ) -> usize {
        let n = origins.len();
        assert!(directions.len() == n && ends.len() == n && hits.len() == n, "bench_cast_rays: length mismatch");
        // SAFETY: valid handle; all four slices have length n; the shim writes 0/1 bytes into
        // `hits`, which are valid `bool` values.
        let r = unsafe {
            ffi::olo_bench_cast_rays(
                self.h(),
                origins.as_ptr().cast(),
                directions.as_ptr().cast(),
                n,
                ignore_unknown.into(),
                max_range,
                ends.as_mut_ptr().cast(),
                hits.as_mut_ptr().cast(),
            )
        };
        assert!(r >= 0, "bench_cast_rays failed");
        r as usize
    }
}

// ------------------------------------------------------------------ ColorOcTree

/// How [`OracleColorTree::apply_colors`] sets colours (OctoMap's three
/// `ColorOcTree` colour setters, through their `(x, y, z, r, g, b)` overloads).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorOp {
    /// `integrateNodeColor`
    Integrate,
    /// `averageNodeColor`
    Average,
    /// `setNodeColor`
    Set,
}

/// An `octomap::ColorOcTree` owned through the shim.
pub struct OracleColorTree {
    ptr: NonNull<ffi::OloColorTree>,
}

impl Drop for OracleColorTree {
    fn drop(&mut self) {
        // SAFETY: `ptr` came from `olo_color_new` and is freed exactly once.
        unsafe { ffi::olo_color_free(self.ptr.as_ptr()) }
    }
}

impl fmt::Debug for OracleColorTree {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("OracleColorTree").finish_non_exhaustive()
    }
}

impl OracleColorTree {
    /// `ColorOcTree(resolution)`, then, with `sensor`, the probabilities set
    /// in graph2tree order.
    pub fn new(resolution: f64, sensor: Option<&SensorParams>) -> Result<Self, OracleError> {
        if !octomap_ready() {
            return Err(OracleError::Unavailable);
        }
        validate_resolution(resolution)?;
        let s = sensor.copied().unwrap_or_default();
        if sensor.is_some() {
            validate_sensor(&s)?;
        }
        // SAFETY: plain values; returns an owned handle or null.
        let p = unsafe {
            ffi::olo_color_new(resolution, sensor.is_some().into(), s.clamp_min, s.clamp_max, s.prob_hit, s.prob_miss)
        };
        NonNull::new(p).map(|ptr| OracleColorTree { ptr }).ok_or(OracleError::CppException)
    }

    /// `ColorOcTree(resolution)` with the sensor model read back and set
    /// again in graph2tree order (what `octolinear build` does by default).
    pub fn with_graph2tree_default(resolution: f64) -> Result<Self, OracleError> {
        if !octomap_ready() {
            return Err(OracleError::Unavailable);
        }
        validate_resolution(resolution)?;
        // SAFETY: plain values; returns an owned handle or null.
        let p = unsafe { ffi::olo_color_new(resolution, 2, 0.0, 0.0, 0.0, 0.0) };
        NonNull::new(p).map(|ptr| OracleColorTree { ptr }).ok_or(OracleError::CppException)
    }

    /// `insertPointCloud(points, origin, maxrange, lazy_eval, discretize)`.
    pub fn insert_point_cloud(
        &mut self,
        points: &[[f32; 3]],
        origin: [f32; 3],
        maxrange: f64,
        lazy_eval: bool,
        discretize: bool,
    ) -> Result<(), OracleError> {
        // SAFETY: valid handle; `points` is `len` contiguous [f32; 3]; the shim copies it.
        let code = unsafe {
            ffi::olo_color_insert_point_cloud(
                self.ptr.as_ptr(),
                points.as_ptr().cast(),
                points.len(),
                origin.as_ptr(),
                maxrange,
                lazy_eval.into(),
                discretize.into(),
            )
        };
        status(code, "insertPointCloud")
    }

    /// Calls the colour setter `op` for every point with its colour, in
    /// order; returns how many found a node.
    pub fn apply_colors(&mut self, op: ColorOp, points: &[[f32; 3]], colors: &[[u8; 3]]) -> usize {
        assert_eq!(points.len(), colors.len(), "one colour per point");
        let which = match op {
            ColorOp::Integrate => 0,
            ColorOp::Average => 1,
            ColorOp::Set => 2,
        };
        // SAFETY: valid handle; both arrays hold `len` elements of 3 values.
        let r = unsafe {
            ffi::olo_color_apply(self.ptr.as_ptr(), which, points.as_ptr().cast(), colors.as_ptr().cast(), points.len())
        };
        assert!(r >= 0, "colour setter failed");
        r as usize
    }

    /// `updateNode(point, occupied, lazy_eval)`; `false` if outside the map.
    pub fn update_node(&mut self, p: [f32; 3], occupied: bool, lazy_eval: bool) -> bool {
        // SAFETY: valid handle and point.
        must(
            unsafe { ffi::olo_color_update_node(self.ptr.as_ptr(), p.as_ptr(), occupied.into(), lazy_eval.into()) },
            "updateNode",
        ) == 1
    }

    fn op(&mut self, which: i32, what: &'static str) {
        // SAFETY: valid handle.
        must(unsafe { ffi::olo_color_op(self.ptr.as_ptr(), which) }, what);
    }

    /// `updateInnerOccupancy()` (ColorOcTree's: also averages inner colours).
    pub fn update_inner_occupancy(&mut self) {
        self.op(0, "updateInnerOccupancy")
    }

    pub fn prune(&mut self) {
        self.op(1, "prune")
    }

    pub fn expand(&mut self) {
        self.op(2, "expand")
    }

    pub fn to_max_likelihood(&mut self) {
        self.op(3, "toMaxLikelihood")
    }

    /// `write(std::ostream&)`: the `.ot` bytes, id `ColorOcTree`.
    pub fn write_ot(&self) -> Result<Vec<u8>, OracleError> {
        let (mut p, mut n) = (std::ptr::null_mut(), 0usize);
        // SAFETY: valid handle and out-pointers.
        status(unsafe { ffi::olo_color_write(self.ptr.as_ptr(), &mut p, &mut n) }, "write")?;
        // SAFETY: the shim returned a malloc'ed buffer of `n` bytes (or null).
        Ok(unsafe { take_vec(p, n) })
    }

    /// `search(point, depth)`: log-odds and colour.
    pub fn search(&self, p: [f32; 3], depth: u8) -> Option<(f32, [u8; 3])> {
        let d = check_depth(depth);
        let (mut v, mut rgb) = (0f32, [0u8; 3]);
        // SAFETY: valid handle and out-pointers (rgb holds 3 bytes).
        let r = unsafe { ffi::olo_color_search(self.ptr.as_ptr(), p.as_ptr(), d, &mut v, rgb.as_mut_ptr()) };
        (must(r, "search") == 1).then_some((v, rgb))
    }
}

// ------------------------------------------------------------------ OcTreeStamped

/// One node of [`OracleStampedTree::nodes`] (`begin_tree` order).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StampedNode {
    pub key: [u16; 3],
    pub depth: u8,
    pub is_leaf: bool,
    pub logodds: f32,
    pub stamp: u32,
}

/// The wall clock (`time(NULL)`) OctoMap read before and after a call;
/// when equal, every stamp the call wrote is that second.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Seconds {
    pub before: u32,
    pub after: u32,
}

impl Seconds {
    /// The one second the call ran in, if it did not straddle two.
    pub fn single(self) -> Option<u32> {
        (self.before == self.after).then_some(self.before)
    }
}

/// An `octomap::OcTreeStamped` owned through the shim (OctoMap's default
/// sensor model). Stamps are OctoMap's own `time(NULL)`.
pub struct OracleStampedTree {
    ptr: NonNull<ffi::OloStampedTree>,
}

impl Drop for OracleStampedTree {
    fn drop(&mut self) {
        // SAFETY: `ptr` came from `olo_stamped_new` and is freed exactly once.
        unsafe { ffi::olo_stamped_free(self.ptr.as_ptr()) }
    }
}

impl fmt::Debug for OracleStampedTree {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("OracleStampedTree").finish_non_exhaustive()
    }
}

impl OracleStampedTree {
    pub fn new(resolution: f64) -> Result<Self, OracleError> {
        if !octomap_ready() {
            return Err(OracleError::Unavailable);
        }
        validate_resolution(resolution)?;
        // SAFETY: plain value; returns an owned handle or null.
        let p = unsafe { ffi::olo_stamped_new(resolution) };
        NonNull::new(p).map(|ptr| OracleStampedTree { ptr }).ok_or(OracleError::CppException)
    }

    /// `insertPointCloud(points, origin, maxrange, lazy_eval, discretize)`.
    pub fn insert_point_cloud(
        &mut self,
        points: &[[f32; 3]],
        origin: [f32; 3],
        maxrange: f64,
        lazy_eval: bool,
        discretize: bool,
    ) -> Result<Seconds, OracleError> {
        let mut t = [0u32; 2];
        // SAFETY: valid handle; `points` is `len` contiguous [f32; 3]; `t` holds two u32.
        let code = unsafe {
            ffi::olo_stamped_insert_point_cloud(
                self.ptr.as_ptr(),
                points.as_ptr().cast(),
                points.len(),
                origin.as_ptr(),
                maxrange,
                lazy_eval.into(),
                discretize.into(),
                t.as_mut_ptr(),
            )
        };
        status(code, "insertPointCloud")?;
        Ok(Seconds { before: t[0], after: t[1] })
    }

    /// `updateNode(point, occupied, lazy_eval)`: whether a node was found, and when.
    pub fn update_node(&mut self, p: [f32; 3], occupied: bool, lazy_eval: bool) -> (bool, Seconds) {
        let mut t = [0u32; 2];
        // SAFETY: valid handle, point and `t`.
        let r = unsafe {
            ffi::olo_stamped_update_node(
                self.ptr.as_ptr(),
                p.as_ptr(),
                occupied.into(),
                lazy_eval.into(),
                t.as_mut_ptr(),
            )
        };
        (must(r, "updateNode") == 1, Seconds { before: t[0], after: t[1] })
    }

    fn op(&mut self, which: i32, arg: u32, what: &'static str) -> Seconds {
        let mut t = [0u32; 2];
        // SAFETY: valid handle and `t`.
        must(unsafe { ffi::olo_stamped_op(self.ptr.as_ptr(), which, arg, t.as_mut_ptr()) }, what);
        Seconds { before: t[0], after: t[1] }
    }

    pub fn update_inner_occupancy(&mut self) -> Seconds {
        self.op(0, 0, "updateInnerOccupancy")
    }

    pub fn prune(&mut self) -> Seconds {
        self.op(1, 0, "prune")
    }

    /// `degradeOutdatedNodes(max_age)`.
    pub fn degrade_outdated_nodes(&mut self, max_age: u32) -> Seconds {
        self.op(2, max_age, "degradeOutdatedNodes")
    }

    /// `write(std::ostream&)`: the `.ot` bytes, id `OcTreeStamped` (no stamps).
    pub fn write_ot(&self) -> Result<Vec<u8>, OracleError> {
        let (mut p, mut n) = (std::ptr::null_mut(), 0usize);
        // SAFETY: valid handle and out-pointers.
        status(unsafe { ffi::olo_stamped_write(self.ptr.as_ptr(), &mut p, &mut n) }, "write")?;
        // SAFETY: the shim returned a malloc'ed buffer of `n` bytes (or null).
        Ok(unsafe { take_vec(p, n) })
    }

    /// Every node (`begin_tree`) with its stamp.
    pub fn nodes(&self) -> Vec<StampedNode> {
        let (mut p, mut n) = (std::ptr::null_mut(), 0usize);
        // SAFETY: valid handle and out-pointers.
        must(unsafe { ffi::olo_stamped_dump(self.ptr.as_ptr(), &mut p, &mut n) }, "begin_tree");
        // SAFETY: the shim returned a malloc'ed array of `n` nodes (or null).
        let v = unsafe { take_vec(p, n) };
        v.iter()
            .map(|x| StampedNode {
                key: x.key,
                depth: x.depth,
                is_leaf: x.is_leaf != 0,
                logodds: x.logodds,
                stamp: x.stamp,
            })
            .collect()
    }
}

// ------------------------------------------------------------------ MapCollection

/// A ray for [`map_collection_query`]: `castRay(origin, direction, end,
/// ignore_unknown, max_range)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollectionRay {
    pub origin: [f32; 3],
    pub direction: [f32; 3],
    pub max_range: f64,
}

/// What OctoMap's `MapCollection<MapNode<OcTree>>` answers.
#[derive(Clone, Debug, PartialEq)]
pub struct CollectionAnswers {
    /// Submaps read (`size()`).
    pub submaps: usize,
    /// `isOccupied` and `getOccupancy` per point.
    pub points: Vec<(bool, f64)>,
    /// `castRay`'s result and end point per ray (NaN when not written).
    pub rays: Vec<(bool, [f32; 3])>,
}

/// Reads the collection file at `path` with OctoMap's `MapCollection` and
/// asks it about `points` and `rays`. OctoMap prints a line per submap and
/// ray to stdout.
pub fn map_collection_query(
    path: &std::path::Path,
    points: &[[f32; 3]],
    rays: &[CollectionRay],
    ignore_unknown: bool,
) -> Result<CollectionAnswers, OracleError> {
    if !octomap_ready() {
        return Err(OracleError::Unavailable);
    }
    let path = std::ffi::CString::new(path.to_str().ok_or(OracleError::InvalidArgument("path is not UTF-8"))?)
        .map_err(|_| OracleError::InvalidArgument("path holds a NUL byte"))?;
    let (mut occ, mut prob) = (vec![0u8; points.len()], vec![0f64; points.len()]);
    let flat: Vec<f32> = rays.iter().flat_map(|r| r.origin.into_iter().chain(r.direction)).collect();
    let ranges: Vec<f64> = rays.iter().map(|r| r.max_range).collect();
    let (mut hits, mut ends) = (vec![0u8; rays.len()], vec![[0f32; 3]; rays.len()]);
    // SAFETY: a valid C string; every array has the length passed with it.
    let n = unsafe {
        ffi::olo_mapcoll_query(
            path.as_ptr(),
            points.as_ptr().cast(),
            points.len(),
            occ.as_mut_ptr(),
            prob.as_mut_ptr(),
            flat.as_ptr(),
            ranges.as_ptr(),
            rays.len(),
            ignore_unknown.into(),
            hits.as_mut_ptr(),
            ends.as_mut_ptr().cast(),
        )
    };
    if n < 0 {
        return Err(OracleError::CppException);
    }
    Ok(CollectionAnswers {
        submaps: n as usize,
        points: occ.iter().zip(prob).map(|(&o, p)| (o != 0, p)).collect(),
        rays: hits.iter().zip(ends).map(|(&h, e)| (h != 0, e)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_octomap_is_a_skip_outside_ci_and_a_failure_in_it() {
        let missing = "graph2tree is not installed (apt-get install -y octomap-tools)";
        for ci in [None, Some(""), Some("0"), Some("false"), Some("FALSE"), Some(" ")] {
            assert_eq!(
                skip_decision("t", missing, ci),
                SkipDecision::Skip(format!("t: SKIPPED, needs OctoMap, but {missing} (with CI=true this fails)")),
                "CI={ci:?}"
            );
        }
        for ci in ["true", "1", "yes", "TRUE"] {
            assert_eq!(
                skip_decision("t", missing, Some(ci)),
                SkipDecision::Fail(format!(
                    "t: needs OctoMap, but {missing}; CI={ci} requires every comparison with OctoMap to run"
                ))
            );
        }
    }

    #[test]
    fn unavailable_constructors_fail() {
        if available() {
            return;
        }
        assert_eq!(OracleTree::new(0.1).unwrap_err(), OracleError::Unavailable);
        assert!(OracleTree::read_bt(b"x").is_none());
    }

    #[test]
    fn ffi_layouts_match() {
        if !require_or_skip("ffi_layouts_match") {
            return;
        }
        // SAFETY: argument-less functions returning sizeof values.
        unsafe {
            assert_eq!(ffi::olo_sizeof_node(), std::mem::size_of::<ffi::OloNode>());
            assert_eq!(ffi::olo_sizeof_change(), std::mem::size_of::<ffi::OloChange>());
            assert_eq!(ffi::olo_sizeof_stats(), std::mem::size_of::<ffi::OloStats>());
            assert_eq!(ffi::olo_sizeof_sensor(), std::mem::size_of::<ffi::OloSensor>());
            assert_eq!(ffi::olo_sizeof_stamped_node(), std::mem::size_of::<ffi::OloStampedNode>());
        }
    }
}
