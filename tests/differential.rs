//! Differential tests: octolinear against the real OctoMap (the system
//! `liboctomap` through `octolinear-oracle`).
//!
//! Every test builds the same tree in both libraries from seeded random
//! operations and compares, after each mutating step (single-voxel updates:
//! every fourth), the `.ot` bytes, the `writeBinaryConst` bytes and (when
//! enabled) the change-detection sets; `writeBinary`, `computeRayKeys`,
//! `castRay`, `search` and reading `.ot`/`.bt` back are compared as operations
//! of their own. A differing case is shrunk (points, then operations dropped,
//! then options and configuration simplified, while it still differs the same
//! way) and the panic message carries a test function that can be pasted into
//! `tests/regressions/mod.rs` (it is also written to `CARGO_TARGET_TMPDIR`).
//! `slowest_random_cases` (ignored) reports where the run time goes.
//!
//! Knobs: `OCTOLINEAR_DIFF_SEED` (base seed, default fixed) and
//! `OCTOLINEAR_DIFF_SCALE` (multiplies the number of random cases). OctoMap's
//! own warnings ("out of bounds", thousands of lines for these tests) are
//! part of each test's captured output: shown with a failure or `--nocapture`.
//!
//! Not compared: bounding-box insertion (Debian's 1.9.7 has OctoMap's old
//! bounding-box semantics, octolinear follows 1.10) and NaN points (octolinear
//! deliberately skips them, OctoMap's discretize maps them to a key).

use octolinear::formats::{bt, ot};
use octolinear::ray::CastError;
use octolinear::sensor::{SensorModel, SensorProbabilities};
use octolinear::{CastOptions, InnerNodes, Key, OccupancyTree, Point3, ScanOptions};
use octolinear_oracle::{require_or_skip, OracleError, OracleTree, SensorParams};
use octolinear_sim::{simulate, LidarConfig, SceneKind, SplitMix64};
use std::fmt::Write as _;
use std::panic::{catch_unwind, AssertUnwindSafe};

#[path = "regressions/mod.rs"]
mod regressions;

// ------------------------------------------------------------------ cases

/// A custom sensor model (probabilities).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sensor {
    hit: f64,
    miss: f64,
    clamp_min: f64,
    clamp_max: f64,
    threshold: f64,
}

/// How both trees are created.
#[derive(Clone, Debug)]
struct Config {
    res: f64,
    /// `None`: OctoMap's default sensor model (`OcTree(res)` untouched).
    sensor: Option<Sensor>,
    change_detection: bool,
}

/// One step applied to both trees. Points are OctoMap's `point3d` (`f32`).
#[derive(Clone, Debug)]
enum Op {
    /// `insertPointCloud(points, origin, max_range, lazy, discretize)`;
    /// octolinear gets `threads` (`None` = rayon's global pool).
    Scan {
        origin: [f32; 3],
        points: Vec<[f32; 3]>,
        max_range: f64,
        discretize: bool,
        lazy: bool,
        threads: Option<usize>,
    },
    /// `insertPointCloudRays` ("simple" mode).
    Rays {
        origin: [f32; 3],
        points: Vec<[f32; 3]>,
        lazy: bool,
    },
    UpdateInner,
    /// `updateNode(key, occupied, lazy)`.
    UpdateKey {
        key: [u16; 3],
        occupied: bool,
        lazy: bool,
    },
    /// `updateNode(point, occupied, lazy)`.
    UpdatePoint {
        p: [f32; 3],
        occupied: bool,
        lazy: bool,
    },
    /// `updateNode(key, log_odds_delta, lazy)`.
    UpdateDelta {
        key: [u16; 3],
        delta: f32,
        lazy: bool,
    },
    /// `setNodeValue(key, value, lazy)`.
    SetValue {
        key: [u16; 3],
        value: f32,
        lazy: bool,
    },
    Prune,
    /// `expand()`; skipped (by both) when it would create too many nodes.
    Expand,
    ToMaxLikelihood,
    /// The mutating `writeBinary` (bytes compared; both trees then converted).
    WriteBinary,
    ResetChanges,
    /// `computeRayKeys(origin, end)`.
    RayKeys {
        origin: [f32; 3],
        end: [f32; 3],
    },
    /// `castRay(origin, dir, end, ignore_unknown, max_range)`.
    CastRay {
        origin: [f32; 3],
        dir: [f32; 3],
        ignore_unknown: bool,
        max_range: f64,
    },
    /// `search(key, depth)`.
    Search {
        key: [u16; 3],
        depth: u8,
    },
    /// `search(point, depth)`.
    SearchPoint {
        p: [f32; 3],
        depth: u8,
    },
    /// Reads the `.ot` and `.bt` bytes back with both libraries and compares.
    RoundTrip,
}

impl Op {
    fn mutates(&self) -> bool {
        !matches!(
            self,
            Op::RayKeys { .. } | Op::CastRay { .. } | Op::Search { .. } | Op::SearchPoint { .. } | Op::RoundTrip
        )
    }

    fn points_mut(&mut self) -> Option<&mut Vec<[f32; 3]>> {
        match self {
            Op::Scan { points, .. } | Op::Rays { points, .. } => Some(points),
            _ => None,
        }
    }

    /// The same op with one option made simpler (for shrinking).
    fn simplifications(&self) -> Vec<Op> {
        let mut out = Vec::new();
        match self {
            Op::Scan { origin, points, max_range, discretize, lazy, threads } => {
                let scan = |max_range, discretize, lazy, threads| Op::Scan {
                    origin: *origin,
                    points: points.clone(),
                    max_range,
                    discretize,
                    lazy,
                    threads,
                };
                if *max_range >= 0.0 {
                    out.push(scan(-1.0, *discretize, *lazy, *threads));
                }
                if *discretize {
                    out.push(scan(*max_range, false, *lazy, *threads));
                }
                if *lazy {
                    out.push(scan(*max_range, *discretize, false, *threads));
                }
                if threads.is_some() {
                    out.push(scan(*max_range, *discretize, *lazy, None));
                }
            }
            Op::Rays { origin, points, lazy: true } => {
                out.push(Op::Rays { origin: *origin, points: points.clone(), lazy: false })
            }
            Op::UpdateKey { key, occupied, lazy: true } => {
                out.push(Op::UpdateKey { key: *key, occupied: *occupied, lazy: false })
            }
            Op::UpdatePoint { p, occupied, lazy: true } => {
                out.push(Op::UpdatePoint { p: *p, occupied: *occupied, lazy: false })
            }
            Op::UpdateDelta { key, delta, lazy: true } => {
                out.push(Op::UpdateDelta { key: *key, delta: *delta, lazy: false })
            }
            Op::SetValue { key, value, lazy: true } => out.push(Op::SetValue { key: *key, value: *value, lazy: false }),
            _ => {}
        }
        out
    }

    fn num_points(&self) -> usize {
        match self {
            Op::Scan { points, .. } | Op::Rays { points, .. } => points.len(),
            _ => 0,
        }
    }
}

// ------------------------------------------------------------------ reproducer helpers

/// A `point3d` from the bits of its coordinates.
fn p(x: u32, y: u32, z: u32) -> [f32; 3] {
    [f32::from_bits(x), f32::from_bits(y), f32::from_bits(z)]
}

/// An `f32` from its bits (used by pasted reproducers).
#[allow(dead_code)]
fn f(bits: u32) -> f32 {
    f32::from_bits(bits)
}

/// An `f64` from its bits.
fn d(bits: u64) -> f64 {
    f64::from_bits(bits)
}

fn pt(a: [f32; 3]) -> Point3 {
    Point3::from_array(a)
}

fn code_p(a: [f32; 3]) -> String {
    format!("p(0x{:08x}, 0x{:08x}, 0x{:08x})", a[0].to_bits(), a[1].to_bits(), a[2].to_bits())
}

fn code_d(v: f64) -> String {
    format!("d(0x{:016x}) /* {v:?} */", v.to_bits())
}

fn code_f(v: f32) -> String {
    format!("f(0x{:08x}) /* {v:?} */", v.to_bits())
}

fn code_points(out: &mut String, points: &[[f32; 3]]) {
    out.push_str("vec![\n");
    for &q in points {
        let _ = writeln!(out, "                {}, // {:?}", code_p(q), q);
    }
    out.push_str("            ]");
}

impl Op {
    /// Rust source constructing this op (for reproducers).
    fn code(&self) -> String {
        let mut s = String::new();
        match self {
            Op::Scan { origin, points, max_range, discretize, lazy, threads } => {
                let _ = write!(
                    s,
                    "Op::Scan {{\n            origin: {}, // {origin:?}\n            points: ",
                    code_p(*origin)
                );
                code_points(&mut s, points);
                let _ = write!(
                    s,
                    ",\n            max_range: {},\n            discretize: {discretize},\n            lazy: {lazy},\n            threads: {threads:?},\n        }}",
                    code_d(*max_range)
                );
            }
            Op::Rays { origin, points, lazy } => {
                let _ = write!(
                    s,
                    "Op::Rays {{\n            origin: {}, // {origin:?}\n            points: ",
                    code_p(*origin)
                );
                code_points(&mut s, points);
                let _ = write!(s, ",\n            lazy: {lazy},\n        }}");
            }
            Op::UpdateInner => s.push_str("Op::UpdateInner"),
            Op::UpdateKey { key, occupied, lazy } => {
                let _ = write!(s, "Op::UpdateKey {{ key: {key:?}, occupied: {occupied}, lazy: {lazy} }}");
            }
            Op::UpdatePoint { p, occupied, lazy } => {
                let _ = write!(
                    s,
                    "Op::UpdatePoint {{ p: {} /* {p:?} */, occupied: {occupied}, lazy: {lazy} }}",
                    code_p(*p)
                );
            }
            Op::UpdateDelta { key, delta, lazy } => {
                let _ = write!(s, "Op::UpdateDelta {{ key: {key:?}, delta: {}, lazy: {lazy} }}", code_f(*delta));
            }
            Op::SetValue { key, value, lazy } => {
                let _ = write!(s, "Op::SetValue {{ key: {key:?}, value: {}, lazy: {lazy} }}", code_f(*value));
            }
            Op::Prune => s.push_str("Op::Prune"),
            Op::Expand => s.push_str("Op::Expand"),
            Op::ToMaxLikelihood => s.push_str("Op::ToMaxLikelihood"),
            Op::WriteBinary => s.push_str("Op::WriteBinary"),
            Op::ResetChanges => s.push_str("Op::ResetChanges"),
            Op::RayKeys { origin, end } => {
                let _ = write!(
                    s,
                    "Op::RayKeys {{ origin: {} /* {origin:?} */, end: {} /* {end:?} */ }}",
                    code_p(*origin),
                    code_p(*end)
                );
            }
            Op::CastRay { origin, dir, ignore_unknown, max_range } => {
                let _ = write!(
                    s,
                    "Op::CastRay {{ origin: {} /* {origin:?} */, dir: {} /* {dir:?} */, ignore_unknown: {ignore_unknown}, max_range: {} }}",
                    code_p(*origin),
                    code_p(*dir),
                    code_d(*max_range)
                );
            }
            Op::Search { key, depth } => {
                let _ = write!(s, "Op::Search {{ key: {key:?}, depth: {depth} }}");
            }
            Op::SearchPoint { p, depth } => {
                let _ = write!(s, "Op::SearchPoint {{ p: {} /* {p:?} */, depth: {depth} }}", code_p(*p));
            }
            Op::RoundTrip => s.push_str("Op::RoundTrip"),
        }
        s
    }
}

fn reproducer(name: &str, cfg: &Config, ops: &[Op], failure: &Failure) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "// {}: {}", failure.kind, first_line(&failure.what));
    let _ = writeln!(s, "#[test]");
    let _ = writeln!(s, "fn {name}() {{");
    let _ = writeln!(s, "    if !octolinear_oracle::require_or_skip(\"{name}\") {{\n        return;\n    }}");
    let _ = writeln!(s, "    let cfg = Config {{");
    let _ = writeln!(s, "        res: {},", code_d(cfg.res));
    match cfg.sensor {
        None => s.push_str("        sensor: None,\n"),
        Some(m) => {
            let _ = writeln!(
                s,
                "        sensor: Some(Sensor {{\n            hit: {},\n            miss: {},\n            clamp_min: {},\n            clamp_max: {},\n            threshold: {},\n        }}),",
                code_d(m.hit),
                code_d(m.miss),
                code_d(m.clamp_min),
                code_d(m.clamp_max),
                code_d(m.threshold)
            );
        }
    }
    let _ = writeln!(s, "        change_detection: {},", cfg.change_detection);
    s.push_str("    };\n    let ops = vec![\n");
    for op in ops {
        let _ = writeln!(s, "        {},", op.code());
    }
    s.push_str("    ];\n    check_regression(&cfg, &ops);\n}\n");
    s
}

fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or("")
}

// ------------------------------------------------------------------ running a case

/// The first difference found while running a case.
#[derive(Clone, Debug)]
struct Failure {
    /// Index of the op after which the trees (or answers) differed.
    step: usize,
    /// Short category; shrinking keeps it.
    kind: &'static str,
    what: String,
}

struct Pair {
    ours: OccupancyTree,
    theirs: OracleTree,
    change_detection: bool,
}

fn inner(lazy: bool) -> InnerNodes {
    if lazy {
        InnerNodes::Defer
    } else {
        InnerNodes::Update
    }
}

fn ot_bytes(t: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(t, &mut v).unwrap();
    v
}

fn bt_bytes(t: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    bt::write(t, &mut v).unwrap();
    v
}

fn bt_const_bytes(t: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    bt::write_const(t, &mut v).unwrap();
    v
}

fn new_pair(cfg: &Config) -> Pair {
    let (ours, mut theirs) = match cfg.sensor {
        None => (OccupancyTree::new(cfg.res).unwrap(), OracleTree::new(cfg.res).unwrap()),
        Some(s) => {
            let model = SensorModel::from_probabilities(&SensorProbabilities {
                hit: s.hit,
                miss: s.miss,
                clamping_min: s.clamp_min,
                clamping_max: s.clamp_max,
                occupancy_threshold: s.threshold,
            })
            .expect("valid sensor model");
            let mut t = OracleTree::with_sensor(
                cfg.res,
                &SensorParams { prob_hit: s.hit, prob_miss: s.miss, clamp_min: s.clamp_min, clamp_max: s.clamp_max },
            )
            .unwrap();
            t.set_occupancy_thres(s.threshold);
            (OccupancyTree::with_sensor(cfg.res, model).unwrap(), t)
        }
    };
    let mut ours = ours;
    if cfg.change_detection {
        ours.set_change_detection(true);
        theirs.enable_change_detection(true);
    }
    Pair { ours, theirs, change_detection: cfg.change_detection }
}

/// First position where two byte strings differ.
fn first_diff(a: &[u8], b: &[u8]) -> usize {
    a.iter().zip(b).position(|(x, y)| x != y).unwrap_or(a.len().min(b.len()))
}

/// Describes how the two trees differ: the first differing node of a full
/// pre-order dump (key, depth, leaf flag, log-odds).
fn node_diff(pair: &Pair) -> String {
    let ours: Vec<([u16; 3], u8, bool, u32)> =
        pair.ours.nodes(0).map(|n| (n.key.0, n.depth, n.is_leaf, n.value.to_bits())).collect();
    let theirs: Vec<([u16; 3], u8, bool, u32)> =
        pair.theirs.nodes(0).iter().map(|n| (n.key, n.depth, n.is_leaf, n.logodds.to_bits())).collect();
    let show = |n: Option<&([u16; 3], u8, bool, u32)>| match n {
        None => "(none)".to_string(),
        Some(&(k, dep, leaf, v)) => format!(
            "key {k:?} depth {dep} {} log-odds {} (0x{v:08x})",
            if leaf { "leaf" } else { "inner" },
            f32::from_bits(v)
        ),
    };
    match ours.iter().zip(&theirs).position(|(a, b)| a != b) {
        Some(i) => format!(
            "first differing node #{i} (pre-order): octolinear {} | OctoMap {}",
            show(ours.get(i)),
            show(theirs.get(i))
        ),
        None if ours.len() != theirs.len() => format!(
            "node counts differ: octolinear {} OctoMap {}; next: octolinear {} | OctoMap {}",
            ours.len(),
            theirs.len(),
            show(ours.get(theirs.len())),
            show(theirs.get(ours.len()))
        ),
        None => "node dumps agree (difference in the header / size counter?)".to_string(),
    }
}

fn compare_state(pair: &Pair) -> Result<(), (&'static str, String)> {
    let a = ot_bytes(&pair.ours);
    let b = pair.theirs.write_ot().unwrap();
    if a != b {
        return Err((
            "ot",
            format!(
                ".ot bytes differ ({} vs {} bytes, first at {}); {}; sizes: octolinear {} OctoMap {}",
                a.len(),
                b.len(),
                first_diff(&a, &b),
                node_diff(pair),
                pair.ours.size(),
                pair.theirs.size()
            ),
        ));
    }
    let a = bt_const_bytes(&pair.ours);
    let b = pair.theirs.write_bt_const().unwrap();
    if a != b {
        return Err((
            "bt_const",
            format!(
                "writeBinaryConst bytes differ ({} vs {} bytes, first at {})",
                a.len(),
                b.len(),
                first_diff(&a, &b)
            ),
        ));
    }
    if pair.change_detection {
        let a: Vec<([u16; 3], bool)> = pair.ours.changed_keys().into_iter().map(|(k, b)| (k.0, b)).collect();
        let b = pair.theirs.changed_keys();
        if a != b {
            let i = a.iter().zip(&b).position(|(x, y)| x != y);
            return Err((
                "changes",
                format!(
                    "change-detection sets differ ({} vs {} entries; first differing: octolinear {:?} OctoMap {:?})",
                    a.len(),
                    b.len(),
                    i.map_or(a.get(b.len()), |i| a.get(i)),
                    i.map_or(b.get(a.len()), |i| b.get(i))
                ),
            ));
        }
    }
    Ok(())
}

/// Leaves `expand()` would produce; `u64::MAX` when huge.
fn expanded_leaves(t: &OccupancyTree) -> u64 {
    let mut total = 0u64;
    for n in t.leaves(0) {
        total = total.saturating_add(1u64 << (3 * (16 - u32::from(n.depth))).min(63));
    }
    total
}

const NAN3: [f32; 3] = [f32::NAN; 3];

fn same_point(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// Applies one op to both trees and compares. `Ok(false)`: the oracle
/// refused the op (ray too long for OctoMap's `KeyRay`); it was skipped.
fn apply(pair: &mut Pair, op: &Op) -> Result<bool, (&'static str, String)> {
    let refused = |r: Result<(), OracleError>| -> Result<bool, (&'static str, String)> {
        match r {
            Ok(()) => Ok(true),
            Err(OracleError::RayTooLong) => Ok(false),
            Err(e) => Err(("oracle", format!("oracle error: {e}"))),
        }
    };
    match op {
        Op::Scan { origin, points, max_range, discretize, lazy, threads } => {
            let r = pair.theirs.insert_point_cloud(points, *origin, *max_range, *lazy, *discretize);
            if !refused(r)? {
                return Ok(false);
            }
            let pts: Vec<Point3> = points.iter().map(|&q| pt(q)).collect();
            let opts = ScanOptions::default()
                .with_max_range((*max_range >= 0.0).then_some(*max_range))
                .with_discretize(*discretize)
                .with_inner(inner(*lazy))
                .with_threads(*threads);
            pair.ours
                .insert_point_cloud(&pts, pt(*origin), &opts)
                .map_err(|e| ("error", format!("octolinear refused the scan: {e}")))?;
        }
        Op::Rays { origin, points, lazy } => {
            let r = pair.theirs.insert_point_cloud_rays(points, *origin, -1.0, *lazy);
            if !refused(r)? {
                return Ok(false);
            }
            let pts: Vec<Point3> = points.iter().map(|&q| pt(q)).collect();
            pair.ours.insert_point_cloud_rays(&pts, pt(*origin), inner(*lazy));
        }
        Op::UpdateInner => {
            pair.ours.update_inner_occupancy();
            pair.theirs.update_inner_occupancy();
        }
        Op::UpdateKey { key, occupied, lazy } => {
            pair.ours.update_occupancy(Key(*key), *occupied, inner(*lazy));
            pair.theirs.update_node_key(*key, *occupied, *lazy);
        }
        Op::UpdatePoint { p, occupied, lazy } => {
            let a = pair.ours.update_point(pt(*p), *occupied, inner(*lazy)).is_ok();
            let b = pair.theirs.update_node(*p, *occupied, *lazy);
            if a != b {
                return Err(("update_point", format!("updateNode(point) accepted: octolinear {a} OctoMap {b}")));
            }
        }
        Op::UpdateDelta { key, delta, lazy } => {
            pair.ours.update(Key(*key), *delta, inner(*lazy));
            pair.theirs.update_node_key_logodds(*key, *delta, *lazy);
        }
        Op::SetValue { key, value, lazy } => {
            pair.ours.set_value(Key(*key), *value, inner(*lazy));
            pair.theirs.set_node_value_key(*key, *value, *lazy);
        }
        Op::Prune => {
            pair.ours.prune();
            pair.theirs.prune();
        }
        Op::Expand => {
            if expanded_leaves(&pair.ours) > 20_000 {
                return Ok(false);
            }
            pair.ours.expand().unwrap();
            pair.theirs.expand();
        }
        Op::ToMaxLikelihood => {
            pair.ours.to_max_likelihood();
            pair.theirs.to_max_likelihood();
        }
        Op::WriteBinary => {
            let a = bt_bytes(&pair.ours);
            let b = pair.theirs.write_bt().unwrap();
            pair.ours.to_max_likelihood();
            pair.ours.prune();
            if a != b {
                return Err((
                    "bt",
                    format!(
                        "writeBinary bytes differ ({} vs {} bytes, first at {})",
                        a.len(),
                        b.len(),
                        first_diff(&a, &b)
                    ),
                ));
            }
        }
        Op::ResetChanges => {
            pair.ours.reset_change_detection();
            pair.theirs.reset_change_detection();
        }
        Op::RayKeys { origin, end } => {
            let b = match pair.theirs.compute_ray_keys(*origin, *end) {
                Ok(b) => b,
                Err(OracleError::RayTooLong) => return Ok(false),
                Err(e) => return Err(("oracle", format!("oracle error: {e}"))),
            };
            let a = match pair.ours.ray_keys(pt(*origin), pt(*end)) {
                Ok(r) => (true, r.map(|k| k.0).collect::<Vec<_>>()),
                Err(_) => (false, Vec::new()),
            };
            if a.0 != b.0 || (a.0 && a.1 != b.1) {
                let i = a.1.iter().zip(&b.1).position(|(x, y)| x != y);
                return Err((
                    "ray_keys",
                    format!(
                        "computeRayKeys differs: ok octolinear {} OctoMap {}; {} vs {} keys; first difference at #{:?}: octolinear {:?} OctoMap {:?}",
                        a.0,
                        b.0,
                        a.1.len(),
                        b.1.len(),
                        i,
                        i.map_or(a.1.get(b.1.len()), |i| a.1.get(i)),
                        i.map_or(b.1.get(a.1.len()), |i| b.1.get(i)),
                    ),
                ));
            }
        }
        Op::CastRay { origin, dir, ignore_unknown, max_range } => {
            let b = pair.theirs.cast_ray(*origin, *dir, *ignore_unknown, *max_range);
            let opts = CastOptions {
                ignore_unknown: *ignore_unknown,
                // both spellings of "no limit" (OctoMap: any value <= 0)
                max_range: (*max_range != -1.0).then_some(*max_range),
            };
            let a = match pair.ours.cast_ray(pt(*origin), pt(*dir), opts) {
                Ok(o) => (o.hit(), o.end().to_array()),
                Err(CastError::Origin(_) | CastError::ZeroDirection | CastError::NoOccupancy) => (false, NAN3),
            };
            if a.0 != b.0 || !same_point(a.1, b.1) {
                return Err((
                    "cast_ray",
                    format!("castRay differs: octolinear ({}, {:?}) OctoMap ({}, {:?})", a.0, a.1, b.0, b.1),
                ));
            }
        }
        Op::Search { key, depth } => {
            let a = pair.ours.search(Key(*key), *depth);
            let b = pair.theirs.search_key(*key, *depth);
            compare_search(pair, a, b)?;
        }
        Op::SearchPoint { p, depth } => {
            let a = pair.ours.search_point(pt(*p), *depth).ok().flatten();
            let b = pair.theirs.search_node(*p, *depth);
            compare_search(pair, a, b)?;
        }
        Op::RoundTrip => {
            let ot_ours = ot_bytes(&pair.ours);
            let back = ot::read(&ot_ours[..])
                .map_err(|e| ("roundtrip", format!("octolinear cannot read its .ot: {e}")))?
                .into_occupancy()
                .ok_or(("roundtrip", "octolinear read its .ot back as a counting tree".to_string()))?;
            let again = ot_bytes(&back);
            if again != ot_ours {
                return Err((
                    "roundtrip",
                    format!(".ot read+write changes the bytes (first at {})", first_diff(&again, &ot_ours)),
                ));
            }
            let bt = bt_const_bytes(&pair.ours);
            let ours_bt =
                bt::read(&bt[..]).map_err(|e| ("roundtrip", format!("octolinear cannot read its .bt: {e}")))?;
            let theirs_bt = OracleTree::read_bt(&bt).ok_or(("roundtrip", "OctoMap cannot read the .bt".to_string()))?;
            let a = ot_bytes(&ours_bt);
            let b = theirs_bt.write_ot().unwrap();
            if a != b {
                return Err((
                    "roundtrip",
                    format!(
                        "trees read from the same .bt differ (.ot {} vs {} bytes, first at {})",
                        a.len(),
                        b.len(),
                        first_diff(&a, &b)
                    ),
                ));
            }
        }
    }
    Ok(true)
}

fn compare_search(
    pair: &Pair,
    a: Option<octolinear::Found>,
    b: Option<octolinear_oracle::SearchResult>,
) -> Result<(), (&'static str, String)> {
    let sensor = pair.ours.sensor();
    let a = a.map(|f| (f.value.to_bits(), sensor.is_occupied(f.value), sensor.is_at_threshold(f.value)));
    let b = b.map(|r| (r.logodds.to_bits(), r.occupied, r.at_threshold));
    if a != b {
        return Err((
            "search",
            format!("search differs: octolinear {a:?} OctoMap {b:?} (log-odds bits, occupied, at threshold)"),
        ));
    }
    Ok(())
}

/// Runs a case; the first difference, if any. `Ok(n)`: `n` ops were
/// skipped (refused by OctoMap's shim as too long a ray, or an `expand()`
/// too big to be worth it). Panics inside octolinear
/// count as differences.
fn run_case(cfg: &Config, ops: &[Op]) -> Result<usize, Failure> {
    let mut pair = new_pair(cfg);
    let mut skipped = 0;
    for (step, op) in ops.iter().enumerate() {
        // single-voxel updates are compared in batches of four
        let batched =
            matches!(op, Op::UpdateKey { .. } | Op::UpdatePoint { .. } | Op::UpdateDelta { .. } | Op::SetValue { .. })
                && step % 4 != 3
                && step + 1 != ops.len();
        let r = catch_unwind(AssertUnwindSafe(|| -> Result<(), (&'static str, String)> {
            let applied = apply(&mut pair, op)?;
            skipped += usize::from(!applied);
            if applied && op.mutates() && !batched {
                compare_state(&pair)?;
            }
            Ok(())
        }));
        let r = match r {
            Ok(r) => r,
            Err(e) => {
                let msg = e
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                // the pair may be inconsistent now: stop here
                return Err(Failure { step, kind: "panic", what: format!("panic: {msg}") });
            }
        };
        if let Err((kind, what)) = r {
            return Err(Failure { step, kind, what });
        }
    }
    Ok(skipped)
}

/// Runs a case (normally [`run_case`]; the shrinker's own test plants one).
type Runner = dyn Fn(&Config, &[Op]) -> Result<usize, Failure>;

/// Shrinks a failing case while it still fails with the same kind of
/// difference: drops the points of each scan, then whole ops (halving
/// chunks), then tries simpler options (no max range, discretize, lazy or
/// threads) and a simpler configuration (no change detection, default
/// sensor); repeats until nothing changes (at most 4000 runs).
fn shrink(cfg: &Config, mut ops: Vec<Op>, mut fail: Failure, run: &Runner) -> (Config, Vec<Op>, Failure, usize) {
    const MAX_RUNS: usize = 4000;
    let mut cfg = cfg.clone();
    let mut runs = 0usize;
    ops.truncate(fail.step + 1);
    let kind = fail.kind;
    let try_case = |cfg: &Config, cand: &[Op], runs: &mut usize| -> Option<Failure> {
        *runs += 1;
        match run(cfg, cand) {
            Err(f) if f.kind == kind => Some(f),
            _ => None,
        }
    };
    loop {
        let mut progress = false;
        // points of each scan
        for j in 0..ops.len() {
            let mut chunk = ops[j].num_points().div_ceil(2);
            while chunk >= 1 && runs < MAX_RUNS {
                let mut i = 0;
                while i < ops[j].num_points() && runs < MAX_RUNS {
                    let mut cand = ops.clone();
                    let pts = cand[j].points_mut().unwrap();
                    let end = (i + chunk).min(pts.len());
                    pts.drain(i..end);
                    if let Some(f) = try_case(&cfg, &cand, &mut runs) {
                        ops = cand;
                        fail = f;
                        progress = true;
                    } else {
                        i += chunk;
                    }
                }
                chunk /= 2;
            }
        }
        // whole ops
        let mut chunk = ops.len().div_ceil(2);
        while chunk >= 1 && runs < MAX_RUNS {
            let mut i = 0;
            while i < ops.len() && runs < MAX_RUNS {
                let mut cand = ops.clone();
                let end = (i + chunk).min(cand.len());
                cand.drain(i..end);
                if cand.is_empty() {
                    i += chunk;
                    continue;
                }
                if let Some(f) = try_case(&cfg, &cand, &mut runs) {
                    cand.truncate(f.step + 1);
                    ops = cand;
                    fail = f;
                    progress = true;
                } else {
                    i += chunk;
                }
            }
            chunk /= 2;
        }
        // simpler options, one at a time
        for j in 0..ops.len() {
            for simpler in ops[j].simplifications() {
                if runs >= MAX_RUNS {
                    break;
                }
                let mut cand = ops.clone();
                cand[j] = simpler;
                if let Some(f) = try_case(&cfg, &cand, &mut runs) {
                    ops = cand;
                    fail = f;
                    progress = true;
                }
            }
        }
        // simpler configuration
        let mut simpler_cfgs = Vec::new();
        if cfg.change_detection {
            simpler_cfgs.push(Config { change_detection: false, ..cfg.clone() });
        }
        if cfg.sensor.is_some() {
            simpler_cfgs.push(Config { sensor: None, ..cfg.clone() });
        }
        for c in simpler_cfgs {
            if let Some(f) = try_case(&c, &ops, &mut runs) {
                cfg = c;
                fail = f;
                progress = true;
            }
        }
        if !progress || runs >= MAX_RUNS {
            break;
        }
    }
    (cfg, ops, fail, runs)
}

/// Runs a random case; on a difference shrinks it and panics with a
/// reproducer.
fn check_case(test: &str, seed: u64, cfg: &Config, ops: Vec<Op>) -> usize {
    let fail = match run_case(cfg, &ops) {
        Ok(skipped) => return skipped,
        Err(f) => f,
    };
    let original = (ops.len(), ops.iter().map(Op::num_points).sum::<usize>());
    let original_what = fail.what.clone();
    let (cfg, ops, fail, runs) = shrink(cfg, ops, fail, &run_case);
    let cfg = &cfg;
    let name = format!("regression_{test}_{seed:016x}");
    let code = reproducer(&name, cfg, &ops, &fail);
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}.rs"));
    let _ = std::fs::write(&path, &code);
    panic!(
        "{test}: octolinear differs from OctoMap (seed 0x{seed:016x}, res {}).\n\
         original case: {} ops, {} points: {original_what}\n\
         shrunk in {runs} runs to {} ops, {} points; differs after op #{}: {}\n\
         reproducer (paste into tests/regressions/mod.rs; also written to {}):\n\n{code}",
        cfg.res,
        original.0,
        original.1,
        ops.len(),
        ops.iter().map(Op::num_points).sum::<usize>(),
        fail.step,
        fail.what,
        path.display()
    );
}

/// For kept reproducers: the case must run without any difference.
fn check_regression(cfg: &Config, ops: &[Op]) {
    if let Err(f) = run_case(cfg, ops) {
        panic!("differs after op #{} ({}): {}", f.step, f.kind, f.what);
    }
}

// ------------------------------------------------------------------ random generation

const RESOLUTIONS: [f64; 7] = [0.01, 0.05, 0.08, 0.1, 0.2, 0.5, 1.0];

fn base_seed() -> u64 {
    std::env::var("OCTOLINEAR_DIFF_SEED")
        .ok()
        .and_then(|s| {
            let s = s.trim();
            s.strip_prefix("0x").map_or_else(|| s.parse().ok(), |h| u64::from_str_radix(h, 16).ok())
        })
        .unwrap_or(0x0c70_11ea_d1ff_0001)
}

/// Number of random cases: `n` times `OCTOLINEAR_DIFF_SCALE`.
fn cases(n: usize) -> usize {
    let scale: f64 = std::env::var("OCTOLINEAR_DIFF_SCALE").ok().and_then(|s| s.parse().ok()).unwrap_or(1.0);
    ((n as f64 * scale).round() as usize).max(1)
}

fn case_seed(test: u64, i: usize) -> u64 {
    let mut r = SplitMix64(base_seed() ^ test.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ i as u64);
    r.next_u64()
}

/// `x` moved by `n` units in the last place (through zero correctly).
fn nudge(x: f32, n: i32) -> f32 {
    let mut v = x;
    for _ in 0..n.unsigned_abs() {
        let up = n > 0;
        v = if v == 0.0 {
            if up {
                f32::from_bits(1)
            } else {
                -f32::from_bits(1)
            }
        } else if (v > 0.0) == up {
            f32::from_bits(v.to_bits() + 1)
        } else {
            f32::from_bits(v.to_bits() - 1)
        };
    }
    v
}

struct Gen {
    rng: SplitMix64,
    res: f64,
    /// Centre of the region the case works in (metres).
    center: [f64; 3],
    /// The region hugs the map edge on this axis, on this side.
    edge: Option<(usize, f64)>,
    /// Points used so far (for repeated end points).
    pool: Vec<[f32; 3]>,
    origins: Vec<[f32; 3]>,
    /// Discretized scans may keep an out-of-map end point (wrapping around).
    allow_wrap: bool,
    /// Probability that a scan sees a wall patch instead of random points.
    walls: f64,
}

impl Gen {
    fn new(seed: u64, res: f64) -> Self {
        let mut g = Gen {
            rng: SplitMix64(seed),
            res,
            center: [0.0; 3],
            edge: None,
            pool: Vec::new(),
            origins: Vec::new(),
            allow_wrap: false,
            walls: 0.0,
        };
        let half = 32768.0 * res;
        for c in &mut g.center {
            *c = if g.rng.next_f64() < 0.5 { g.rng.range(-20.0, 20.0) * res } else { g.rng.range(-0.5, 0.5) * half };
        }
        if g.chance(0.15) {
            let axis = g.rng.below(3) as usize;
            let side = if g.chance(0.5) { 1.0 } else { -1.0 };
            g.center[axis] = side * (half - g.rng.range(0.0, 4.0) * res);
            g.edge = Some((axis, side));
            g.allow_wrap = g.chance(0.04);
        }
        g
    }

    fn chance(&mut self, p: f64) -> bool {
        self.rng.next_f64() < p
    }

    fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
        xs[self.rng.below(xs.len() as u32) as usize]
    }

    fn int(&mut self, lo: i64, hi: i64) -> i64 {
        lo + self.rng.below((hi - lo + 1) as u32) as i64
    }

    /// A coordinate near `x` (metres): as is, on a voxel boundary, at a
    /// voxel centre, or a boundary moved by a few ulps or a tiny offset.
    fn coord(&mut self, x: f64) -> f32 {
        let r = self.res;
        let k = (x / r).floor();
        match self.rng.below(10) {
            0..=3 => x as f32,
            4 => (k * r) as f32,
            5 => ((k + 0.5) * r) as f32,
            6 => {
                let n = self.int(-3, 3) as i32;
                nudge((k * r) as f32, n)
            }
            7 => {
                let e = self.pick(&[1e-9, 1e-7, 1e-6, 1e-4 * r]);
                let s = if self.chance(0.5) { 1.0 } else { -1.0 };
                (k * r + s * e) as f32
            }
            8 => (k as f32) * (r as f32),
            _ => ((k + 0.5) as f32) * (r as f32),
        }
    }

    fn near(&mut self, c: [f64; 3], reach: f64) -> [f32; 3] {
        let r = self.res;
        let mut out = [0f32; 3];
        for (o, &ci) in out.iter_mut().zip(&c) {
            let x = ci + self.rng.range(-reach, reach) * r;
            *o = self.coord(x);
        }
        out
    }

    fn origin(&mut self) -> [f32; 3] {
        if !self.origins.is_empty() && self.chance(0.35) {
            let i = self.rng.below(self.origins.len() as u32) as usize;
            return self.origins[i];
        }
        let c = self.center;
        let o = self.near(c, 3.0);
        self.origins.push(o);
        o
    }

    /// Scan end points around `origin`, rays up to `reach` voxels long.
    fn points(&mut self, origin: [f32; 3], n: usize, reach: f64) -> Vec<[f32; 3]> {
        let r = self.res;
        let o = origin.map(f64::from);
        let mut out: Vec<[f32; 3]> = Vec::with_capacity(n);
        for _ in 0..n {
            let q = match self.rng.below(20) {
                0..=6 => self.near(o, reach),
                7 | 8 => {
                    // axis-aligned ray
                    let mut q = origin;
                    let axis = self.rng.below(3) as usize;
                    let m = self.int(-(reach as i64), reach as i64) as f64;
                    let frac = if self.chance(0.5) { 0.0 } else { self.rng.range(-0.5, 0.5) };
                    q[axis] = (o[axis] + (m + frac) * r) as f32;
                    q
                }
                9..=11 => {
                    // diagonal ray (DDA ties)
                    let pattern = self.pick(&[[1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1]]);
                    let m = self.int(1, reach.max(1.0) as i64) as f64;
                    let mut q = origin;
                    for axis in 0..3 {
                        if pattern[axis] != 0 {
                            let s = if self.chance(0.5) { 1.0 } else { -1.0 };
                            q[axis] = (o[axis] + s * m * r) as f32;
                        }
                    }
                    q
                }
                12 => {
                    // shorter than a voxel
                    let mut q = origin;
                    for (qi, &oi) in q.iter_mut().zip(&o) {
                        *qi = (oi + self.rng.range(-0.5, 0.5) * r) as f32;
                    }
                    q
                }
                13 | 14 if !self.pool.is_empty() || !out.is_empty() => {
                    // repeated end point
                    if !out.is_empty() && (self.pool.is_empty() || self.chance(0.5)) {
                        out[self.rng.below(out.len() as u32) as usize]
                    } else {
                        self.pool[self.rng.below(self.pool.len() as u32) as usize]
                    }
                }
                15 => origin,
                16 if self.edge.is_some() => {
                    let (axis, side) = self.edge.unwrap();
                    let mut q = self.near(o, reach.min(8.0));
                    let half = 32768.0 * r;
                    q[axis] = match self.rng.below(4) {
                        0 => (side * half) as f32,
                        1 => nudge((side * half) as f32, self.int(-2, 2) as i32),
                        _ => {
                            let x = side * (half + self.rng.range(-3.0, 3.0) * r);
                            self.coord(x)
                        }
                    };
                    q
                }
                17 if !self.pool.is_empty() => {
                    let mut q = self.pool[self.rng.below(self.pool.len() as u32) as usize];
                    let axis = self.rng.below(3) as usize;
                    q[axis] = nudge(q[axis], self.int(-2, 2) as i32);
                    q
                }
                _ => {
                    let mut q = [0f32; 3];
                    for (qi, &oi) in q.iter_mut().zip(&o) {
                        *qi = (oi + self.rng.range(-reach, reach) * r) as f32;
                    }
                    q
                }
            };
            out.push(q);
        }
        self.pool.extend_from_slice(&out);
        if self.pool.len() > 4096 {
            self.pool.drain(..2048);
        }
        out
    }

    fn reach(&mut self) -> f64 {
        self.pick(&[1.0, 3.0, 8.0, 20.0, 40.0, 80.0])
    }

    fn max_range(&mut self, origin: [f32; 3], points: &[[f32; 3]], reach: f64) -> f64 {
        match self.rng.below(10) {
            0..=4 => -1.0,
            5 if !points.is_empty() => {
                // exactly the length of one of the rays (the `<=` tie)
                let q = points[self.rng.below(points.len() as u32) as usize];
                (pt(q) - pt(origin)).norm()
            }
            6 => 0.0,
            _ => self.rng.range(0.2, 1.2) * reach * self.res,
        }
    }

    /// A patch of wall facing `origin`: end points on a grid finer than the
    /// voxels, so that repeated scans saturate (and prune) the free cone.
    fn wall(&mut self, origin: [f32; 3]) -> Vec<[f32; 3]> {
        let r = self.res;
        let o = origin.map(f64::from);
        let axis = self.rng.below(3) as usize;
        let dist = self.int(3, 12) as f64 * if self.chance(0.5) { 1.0 } else { -1.0 };
        let width = self.int(2, 6);
        let step = self.pick(&[0.5, 0.35, 1.0]);
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut out = Vec::new();
        let cells = (width as f64 / step) as i64;
        for a in 0..cells {
            for b in 0..cells {
                let mut q = [0f32; 3];
                q[axis] = (o[axis] + dist * r) as f32;
                q[u] = (o[u] + (a as f64 * step - width as f64 / 2.0) * r) as f32;
                q[v] = (o[v] + (b as f64 * step - width as f64 / 2.0) * r) as f32;
                out.push(q);
            }
        }
        self.pool.extend_from_slice(&out);
        out
    }

    fn scan(&mut self, n: usize) -> Op {
        let origin = self.origin();
        let reach = self.reach();
        let points = if self.chance(self.walls) { self.wall(origin) } else { self.points(origin, n, reach) };
        let max_range = self.max_range(origin, &points, reach);
        let threads = if self.chance(0.04) { Some(self.pick(&[1, 2, 8])) } else { None };
        let discretize = self.chance(0.3);
        let mut points = points;
        if discretize && self.edge.is_some() {
            // with `discretize` OctoMap wraps out-of-map end points to the far
            // side of the map: a 65536-voxel ray, and a big tree to compare.
            let ks = octolinear::KeySpace::new(self.res);
            // Keep at most one per scan, and only in a few cases.
            let mut wrapped = usize::from(!self.allow_wrap);
            points.retain(|&q| {
                let out = ks.key(pt(q)).is_err();
                wrapped += usize::from(out);
                !out || wrapped == 1
            });
        }
        Op::Scan { origin, points, max_range, discretize, lazy: self.chance(0.3), threads }
    }

    fn rays(&mut self, n: usize) -> Op {
        let origin = self.origin();
        let reach = self.reach();
        Op::Rays { origin, points: self.points(origin, n, reach), lazy: self.chance(0.3) }
    }

    /// A key near the region (a small cluster, so that groups fill and prune).
    fn key(&mut self, cluster: [u16; 3], spread: u16) -> [u16; 3] {
        let mut k = cluster;
        for ki in &mut k {
            *ki = ki.wrapping_add(self.rng.below(u32::from(spread)) as u16);
        }
        k
    }

    fn cluster(&mut self) -> [u16; 3] {
        let c = self.center;
        let q = self.near(c, 10.0);
        let ks = octolinear::KeySpace::new(self.res);
        let k = ks.key_unchecked(pt(q)).0;
        // aligned to 4, so that a 4^3 block covers whole groups of 8
        k.map(|x| x & !3)
    }

    /// A random query on the region.
    fn query(&mut self, tree: &OccupancyTree) -> Op {
        let c = self.center;
        match self.rng.below(6) {
            0 | 1 => {
                let origin = if self.chance(0.5) && !self.origins.is_empty() {
                    self.origins[self.rng.below(self.origins.len() as u32) as usize]
                } else {
                    self.near(c, 30.0)
                };
                let reach = self.reach();
                let end = self.points(origin, 1, reach)[0];
                Op::RayKeys { origin, end }
            }
            2 | 3 => {
                let origin = if self.chance(0.5) && !self.origins.is_empty() {
                    self.origins[self.rng.below(self.origins.len() as u32) as usize]
                } else {
                    self.near(c, 30.0)
                };
                let dir = match self.rng.below(5) {
                    0 => [0.0; 3],
                    1 => {
                        let mut v = [0f32; 3];
                        v[self.rng.below(3) as usize] = if self.chance(0.5) { 1.0 } else { -1.0 };
                        v
                    }
                    2 => {
                        let pattern = self.pick(&[[1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1]]);
                        let mut v = [0f32; 3];
                        for (vi, &pi) in v.iter_mut().zip(&pattern) {
                            if pi != 0 {
                                *vi = if self.chance(0.5) { 1.0 } else { -1.0 };
                            }
                        }
                        v
                    }
                    3 if !self.pool.is_empty() => {
                        // towards a known end point
                        let q = self.pool[self.rng.below(self.pool.len() as u32) as usize];
                        [q[0] - origin[0], q[1] - origin[1], q[2] - origin[2]]
                    }
                    _ => [
                        self.rng.range(-1.0, 1.0) as f32,
                        self.rng.range(-1.0, 1.0) as f32,
                        self.rng.range(-1.0, 1.0) as f32,
                    ],
                };
                let ignore_unknown = self.chance(0.5);
                let max_range = match self.rng.below(8) {
                    // unlimited through unknown space runs to the map edge: keep rare
                    0 if !ignore_unknown || self.chance(0.1) => -1.0,
                    1 => 0.0,
                    2 => self.res * f64::from(self.int(1, 20) as i32),
                    _ => self.rng.range(0.1, 100.0) * self.res,
                };
                Op::CastRay { origin, dir, ignore_unknown, max_range }
            }
            4 => {
                // keys of existing nodes or near them
                let depth = self.pick(&[0, 16, 16, 15, 14, 12, 10, 8, 4, 1]);
                let key = if self.chance(0.6) && !tree.is_empty() {
                    let leaves: Vec<Key> = tree.leaves(0).take(64).map(|n| n.key).collect();
                    let mut k = leaves[self.rng.below(leaves.len() as u32) as usize].0;
                    for ki in &mut k {
                        *ki = ki.wrapping_add(self.int(-2, 2) as u16);
                    }
                    k
                } else {
                    let q = self.near(c, 30.0);
                    octolinear::KeySpace::new(self.res).key_unchecked(pt(q)).0
                };
                Op::Search { key, depth }
            }
            _ => {
                let depth = self.pick(&[0, 16, 15, 13, 9, 3]);
                let p = if self.chance(0.5) && !self.pool.is_empty() {
                    self.pool[self.rng.below(self.pool.len() as u32) as usize]
                } else {
                    self.near(c, 30.0)
                };
                Op::SearchPoint { p, depth }
            }
        }
    }
}

fn random_config(rng: &mut SplitMix64, change_detection: f64) -> Config {
    let res = RESOLUTIONS[rng.below(RESOLUTIONS.len() as u32) as usize];
    let sensor = if rng.next_f64() < 0.5 {
        None
    } else {
        let clamp_min = rng.range(0.02, 0.45);
        let clamp_max = rng.range(0.55, 0.999);
        Some(Sensor {
            hit: if rng.next_f64() < 0.1 { 0.5 } else { rng.range(0.51, 0.99) },
            miss: if rng.next_f64() < 0.1 { 0.5 } else { rng.range(0.01, 0.49) },
            clamp_min,
            clamp_max,
            threshold: if rng.next_f64() < 0.5 { 0.5 } else { rng.range(0.1, 0.9) },
        })
    };
    Config { res, sensor, change_detection: rng.next_f64() < change_detection }
}

// ------------------------------------------------------------------ tests

/// Random scans (`insertPointCloud`) with every option, several per tree.
/// A random case: its seed, configuration and ops.
type Case = (u64, Config, Vec<Op>);

/// Makes random case number `i`.
type Generator = fn(usize) -> Case;

/// Scans (`insertPointCloud`) with every option, several per tree.
fn scans_case(i: usize) -> Case {
    let seed = case_seed(1, i);
    let mut rng = SplitMix64(seed);
    let cfg = random_config(&mut rng, 0.3);
    let mut g = Gen::new(rng.next_u64(), cfg.res);
    if g.chance(0.3) {
        g.walls = 0.7;
    }
    let mut ops = Vec::new();
    for _ in 0..g.int(2, 9) {
        let n = g.pick(&[1, 2, 5, 10, 30, 60]);
        let op = g.scan(n);
        let lazy = matches!(op, Op::Scan { lazy: true, .. });
        ops.push(op);
        if lazy && g.chance(0.6) {
            ops.push(Op::UpdateInner);
        }
        match g.rng.below(40) {
            0 | 1 => ops.push(Op::WriteBinary),
            2 => ops.push(Op::Prune),
            3 => ops.push(Op::ResetChanges),
            _ => {}
        }
    }
    ops.push(Op::WriteBinary);
    ops.push(Op::RoundTrip);
    (seed, cfg, ops)
}

/// A few scans, then queries on the tree.
fn queries_case(i: usize) -> Case {
    let seed = case_seed(2, i);
    let mut rng = SplitMix64(seed);
    let cfg = random_config(&mut rng, 0.0);
    let mut g = Gen::new(rng.next_u64(), cfg.res);
    let mut ops = Vec::new();
    for _ in 0..g.int(1, 4) {
        let n = g.pick(&[10, 30, 60]);
        ops.push(g.scan(n));
        if g.chance(0.2) {
            ops.push(Op::UpdateInner);
        }
    }
    if g.chance(0.2) {
        ops.push(Op::WriteBinary);
    }
    // octolinear's tree, to aim some queries at existing nodes
    let mut pair = new_pair(&cfg);
    for op in &ops {
        let _ = apply(&mut pair, op);
    }
    for _ in 0..60 {
        let q = g.query(&pair.ours);
        ops.push(q);
    }
    (seed, cfg, ops)
}

/// `insertPointCloudRays` ("simple" mode), mixed with ordinary scans.
fn rays_case(i: usize) -> Case {
    let seed = case_seed(3, i);
    let mut rng = SplitMix64(seed);
    let cfg = random_config(&mut rng, 0.3);
    let mut g = Gen::new(rng.next_u64(), cfg.res);
    let mut ops = Vec::new();
    for _ in 0..g.int(2, 7) {
        let n = g.pick(&[1, 3, 10, 30]);
        let op = if g.chance(0.75) { g.rays(n) } else { g.scan(n) };
        let lazy = matches!(op, Op::Rays { lazy: true, .. } | Op::Scan { lazy: true, .. });
        ops.push(op);
        if lazy && g.chance(0.6) {
            ops.push(Op::UpdateInner);
        }
    }
    ops.push(Op::WriteBinary);
    (seed, cfg, ops)
}

/// Node updates, value setting, pruning, expansion, maximum likelihood,
/// lazy updates and change detection on a few small clusters of voxels.
fn node_ops_case(i: usize) -> Case {
    let seed = case_seed(4, i);
    let mut rng = SplitMix64(seed);
    let cfg = random_config(&mut rng, 0.6);
    let mut g = Gen::new(rng.next_u64(), cfg.res);
    g.allow_wrap = false;
    let clusters: Vec<[u16; 3]> = (0..g.int(1, 3)).map(|_| g.cluster()).collect();
    let s = *new_pair(&cfg).ours.sensor();
    let (clamp_min, clamp_max, thres) = (s.clamping_min, s.clamping_max, s.occupancy_threshold);
    let mut ops = Vec::new();
    for _ in 0..g.int(20, 120) {
        let c = clusters[g.rng.below(clusters.len() as u32) as usize];
        let spread = g.pick(&[2, 4, 4, 8]);
        let key = g.key(c, spread);
        let lazy = g.chance(0.25);
        if g.chance(0.12) {
            // the same update on a whole aligned block (2^3 or 4^3 voxels,
            // sometimes but one): whole sibling groups, so it prunes
            let size = g.pick(&[2u16, 2, 4]);
            let mut base = c;
            for b in &mut base {
                *b = b.wrapping_add(size * g.rng.below(u32::from(8 / size)) as u16);
            }
            let kind = g.rng.below(3);
            let occupied = g.chance(0.5);
            let value = g.pick(&[clamp_min, clamp_max, 1.0, -1.0]);
            let delta = g.pick(&[0.5f32, -0.5, 100.0]);
            let skip = if g.chance(0.2) { g.rng.below(u32::from(size * size * size)) } else { u32::MAX };
            let mut n = 0;
            for x in 0..size {
                for y in 0..size {
                    for z in 0..size {
                        n += 1;
                        if n - 1 == skip {
                            continue;
                        }
                        let key = [base[0] + x, base[1] + y, base[2] + z];
                        ops.push(match kind {
                            0 => Op::UpdateKey { key, occupied, lazy },
                            1 => Op::SetValue { key, value, lazy },
                            _ => Op::UpdateDelta { key, delta, lazy },
                        });
                    }
                }
            }
            continue;
        }
        let op = match g.rng.below(40) {
            0..=11 => Op::UpdateKey { key, occupied: g.chance(0.6), lazy },
            12..=15 => {
                let ks = octolinear::KeySpace::new(cfg.res);
                let mut p = ks.key_to_point(Key(key)).to_array();
                if g.chance(0.5) {
                    let center = p.map(f64::from);
                    p = g.near(center, 0.6);
                }
                Op::UpdatePoint { p, occupied: g.chance(0.6), lazy }
            }
            16..=21 => Op::UpdateDelta {
                key,
                delta: match g.rng.below(6) {
                    0 => 0.0,
                    1 => g.pick(&[100.0, -100.0, 1e-7, -1e-7]),
                    _ => g.rng.range(-2.0, 2.0) as f32,
                },
                lazy,
            },
            22..=29 => Op::SetValue {
                key,
                value: match g.rng.below(6) {
                    0 => g.pick(&[clamp_min, clamp_max, thres, 0.0, -0.0]),
                    1 => {
                        let v = g.pick(&[clamp_min, clamp_max, thres]);
                        nudge(v, g.int(-1, 1) as i32)
                    }
                    2 => g.pick(&[50.0, -50.0]),
                    _ => g.rng.range(-4.0, 4.0) as f32,
                },
                lazy,
            },
            30 | 31 => Op::Prune,
            32 => Op::Expand,
            33 => Op::ToMaxLikelihood,
            34 | 35 => Op::UpdateInner,
            36 => Op::ResetChanges,
            37 => Op::WriteBinary,
            _ => {
                let n = g.pick(&[3, 10]);
                g.scan(n)
            }
        };
        ops.push(op);
    }
    ops.push(Op::UpdateInner);
    ops.push(Op::RoundTrip);
    (seed, cfg, ops)
}

/// Runs `n` random cases of a generator and prints what was covered.
fn run_random(test: &str, n: usize, gen: Generator) {
    let (mut n_ops, mut scans, mut points, mut queries, mut skipped) = (0, 0, 0, 0, 0);
    let n = cases(n);
    for i in 0..n {
        let (seed, cfg, ops) = gen(i);
        n_ops += ops.len();
        scans += ops.iter().filter(|o| matches!(o, Op::Scan { .. } | Op::Rays { .. })).count();
        queries += ops.iter().filter(|o| !o.mutates()).count();
        points += ops.iter().map(Op::num_points).sum::<usize>();
        skipped += check_case(test, seed, &cfg, ops);
    }
    println!(
        "{test}: {n} cases, {n_ops} ops ({scans} scans with {points} points, {queries} queries), \
         {skipped} ops skipped (ray too long for OctoMap / expand too big)"
    );
}

#[test]
fn random_scans_match_octomap() {
    if !require_or_skip("random_scans_match_octomap") {
        return;
    }
    run_random("random_scans", 700, scans_case);
}

/// `computeRayKeys`, `castRay` and `search` on trees built from random scans.
#[test]
fn random_queries_match_octomap() {
    if !require_or_skip("random_queries_match_octomap") {
        return;
    }
    run_random("random_queries", 200, queries_case);
}

#[test]
fn simple_mode_rays_match_octomap() {
    if !require_or_skip("simple_mode_rays_match_octomap") {
        return;
    }
    run_random("simple_mode", 250, rays_case);
}

#[test]
fn node_operation_sequences_match_octomap() {
    if !require_or_skip("node_operation_sequences_match_octomap") {
        return;
    }
    run_random("node_ops", 250, node_ops_case);
}

/// Simulated indoor and outdoor lidar scans (small beam counts).
#[test]
fn simulated_scans_match_octomap() {
    if !require_or_skip("simulated_scans_match_octomap") {
        return;
    }
    let setups = [
        (SceneKind::Indoor, 0.05, -1.0, false, false, None),
        (SceneKind::Indoor, 0.1, 8.0, true, false, Some(SensorSetup::Custom)),
        (SceneKind::Indoor, 0.2, -1.0, false, true, None),
        (SceneKind::Outdoor, 0.2, 25.0, false, false, None),
        (SceneKind::Outdoor, 0.5, -1.0, true, true, Some(SensorSetup::Custom)),
        (SceneKind::Outdoor, 1.0, -1.0, false, false, None),
    ];
    for (i, &(kind, res, max_range, discretize, lazy, sensor)) in setups.iter().enumerate() {
        let cfg_lidar = LidarConfig {
            beams: 6,
            horizontal_steps: 90,
            ..if kind == SceneKind::Indoor { LidarConfig::indoor() } else { LidarConfig::outdoor() }
        };
        let graph = simulate(kind, 4, 100 + i as u64, &cfg_lidar).unwrap();
        let cfg = Config {
            res,
            sensor: sensor.map(|_| Sensor { hit: 0.8, miss: 0.35, clamp_min: 0.2, clamp_max: 0.95, threshold: 0.6 }),
            change_detection: i % 2 == 0,
        };
        let mut ops = Vec::new();
        for node in &graph.nodes {
            let (cloud, origin) = node.graph2tree();
            ops.push(Op::Scan {
                origin: origin.to_array(),
                points: cloud.points.iter().map(|q| q.to_array()).collect(),
                max_range,
                discretize,
                lazy,
                threads: None,
            });
            if lazy {
                ops.push(Op::UpdateInner);
            }
        }
        ops.push(Op::WriteBinary);
        ops.push(Op::RoundTrip);
        check_case("simulated", i as u64, &cfg, ops);
    }
}

#[derive(Clone, Copy)]
enum SensorSetup {
    Custom,
}

/// octolinear with 1, 2 and 8 ray-casting threads gives the same bytes,
/// equal to OctoMap's.
#[test]
fn thread_count_independence() {
    if !require_or_skip("thread_count_independence") {
        return;
    }
    for (i, (kind, res)) in [(SceneKind::Indoor, 0.1), (SceneKind::Outdoor, 0.2)].into_iter().enumerate() {
        let lidar = LidarConfig {
            beams: 8,
            horizontal_steps: 180,
            ..if kind == SceneKind::Indoor { LidarConfig::indoor() } else { LidarConfig::outdoor() }
        };
        let graph = simulate(kind, 3, 7 + i as u64, &lidar).unwrap();
        let mut theirs = OracleTree::new(res).unwrap();
        let mut ours: Vec<OccupancyTree> = (0..3).map(|_| OccupancyTree::new(res).unwrap()).collect();
        for (s, node) in graph.nodes.iter().enumerate() {
            let (cloud, origin) = node.graph2tree();
            assert!(cloud.len() > 768, "want several ray-casting chunks");
            let raw: Vec<[f32; 3]> = cloud.points.iter().map(|q| q.to_array()).collect();
            let discretize = s % 2 == 1;
            theirs.insert_point_cloud(&raw, origin.to_array(), -1.0, false, discretize).unwrap();
            let want = theirs.write_ot().unwrap();
            for (t, threads) in ours.iter_mut().zip([1, 2, 8]) {
                let opts = ScanOptions::default().with_discretize(discretize).with_threads(Some(threads));
                t.insert_point_cloud(&cloud.points, origin, &opts).unwrap();
                assert!(
                    ot_bytes(t) == want,
                    "{kind:?} scan {s}: octolinear with {threads} threads differs from OctoMap"
                );
            }
        }
    }
}

/// Hand-picked edge cases: boundaries, ties, the map edge.
#[test]
fn directed_edge_cases_match_octomap() {
    if !require_or_skip("directed_edge_cases_match_octomap") {
        return;
    }
    for (ri, &res) in RESOLUTIONS.iter().enumerate() {
        let r = res as f32;
        let half = (32768.0 * res) as f32;
        let c = ((0.5 * res) as f32, (0.5 * res) as f32, (0.5 * res) as f32);
        let origins = [
            [0.0, 0.0, 0.0],
            [c.0, c.1, c.2],
            [nudge(0.0, 1), nudge(0.0, -1), 0.0],
            [r, -r, 2.0 * r],
            [half - c.0, 0.0, -half + c.2],
        ];
        let mut ops = Vec::new();
        for (oi, &o) in origins.iter().enumerate() {
            let mut points = Vec::new();
            for m in [1.0f32, 2.0, 5.0, 13.0] {
                for dir in [
                    [1.0, 0.0, 0.0],
                    [0.0, -1.0, 0.0],
                    [0.0, 0.0, 1.0],
                    [1.0, 1.0, 0.0],
                    [-1.0, 0.0, 1.0],
                    [0.0, 1.0, -1.0],
                    [1.0, 1.0, 1.0],
                    [-1.0, -1.0, -1.0],
                    [0.5, 1.0, 0.0],
                ] {
                    points.push([o[0] + dir[0] * m * r, o[1] + dir[1] * m * r, o[2] + dir[2] * m * r]);
                }
            }
            // repeated end point, the origin itself, sub-voxel rays, the map edge
            points.push(points[0]);
            points.push(o);
            points.push([o[0] + 0.25 * r, o[1], o[2]]);
            points.push([o[0] + 0.49 * r, o[1] - 0.49 * r, o[2] + 0.01 * r]);
            if oi == 4 {
                // this origin hugs the map edge: end points on and beyond it
                points.push([half, o[1], o[2]]);
                points.push([nudge(half, -1), o[1], o[2]]);
                points.push([half - 3.0 * r, o[1], -half]);
                points.push([o[0], o[1], nudge(-half, -1)]);
            }
            for variant in 0..4 {
                ops.push(Op::Scan {
                    origin: o,
                    points: points.clone(),
                    max_range: [-1.0, 3.0 * res, 0.0, 13.0 * res][(oi + variant) % 4],
                    discretize: variant % 2 == 1,
                    lazy: variant == 2,
                    threads: None,
                });
            }
            ops.push(Op::UpdateInner);
            for q in points.iter().take(20) {
                ops.push(Op::RayKeys { origin: o, end: *q });
                let dir = [q[0] - o[0], q[1] - o[1], q[2] - o[2]];
                for (ignore_unknown, max_range) in [(false, -1.0), (true, 20.0 * res), (true, 0.0)] {
                    ops.push(Op::CastRay { origin: o, dir, ignore_unknown, max_range });
                }
            }
        }
        ops.push(Op::WriteBinary);
        ops.push(Op::RoundTrip);
        let cfg = Config { res, sensor: None, change_detection: true };
        check_case("directed", ri as u64, &cfg, ops);
    }
}

/// The shrinker itself, on a planted difference: it must get down to the
/// one op and point that matter, and print the reproducer.
#[test]
fn shrinker_reduces_a_planted_difference() {
    if !require_or_skip("shrinker_reduces_a_planted_difference") {
        return;
    }
    // plant: a scan at resolution 0.1 containing a point at x = 1.25 makes
    // octolinear's tree differ (we add one update to octolinear only).
    let cfg = Config { res: 0.1, sensor: None, change_detection: false };
    let mut g = Gen::new(5, cfg.res);
    let mut ops: Vec<Op> = (0..6).map(|_| g.scan(20)).collect();
    if let Op::Scan { points, .. } = &mut ops[3] {
        points.insert(7, [1.25, 0.0, 0.0]);
    }
    let planted = |cfg: &Config, ops: &[Op]| -> Result<usize, Failure> {
        let mut pair = new_pair(cfg);
        for (step, op) in ops.iter().enumerate() {
            apply(&mut pair, op).map_err(|(kind, what)| Failure { step, kind, what })?;
            if let Op::Scan { points, .. } = op {
                if points.contains(&[1.25, 0.0, 0.0]) {
                    pair.ours.update_occupancy(Key([1, 2, 3]), true, InnerNodes::Update);
                }
            }
            compare_state(&pair).map_err(|(kind, what)| Failure { step, kind, what })?;
        }
        Ok(0)
    };
    let fail = planted(&cfg, &ops).unwrap_err();
    assert_eq!(fail.step, 3);
    let (cfg, ops, fail, _runs) = shrink(&cfg, ops, fail, &planted);
    assert_eq!(ops.len(), 1, "{ops:?}");
    assert_eq!(ops[0].num_points(), 1, "{ops:?}");
    let code = reproducer("regression_example", &cfg, &ops, &fail);
    assert!(code.contains("p(0x3fa00000, 0x00000000, 0x00000000)"), "{code}");
    assert!(code.contains("check_regression(&cfg, &ops);"), "{code}");
    // without the plant, the shrunk case agrees with OctoMap
    assert!(run_case(&cfg, &ops).is_ok());
}

/// Not a check: prints the slowest random cases of each generator (for
/// keeping the suite fast). `cargo test --test differential slowest -- --ignored --nocapture`
#[test]
#[ignore = "timing report"]
fn slowest_random_cases() {
    if !require_or_skip("slowest_random_cases") {
        return;
    }
    let gens: [(&str, usize, Generator); 4] = [
        ("scans", 400, scans_case),
        ("queries", 120, queries_case),
        ("rays", 150, rays_case),
        ("node_ops", 150, node_ops_case),
    ];
    for (name, n, gen) in gens {
        let mut times = Vec::new();
        for i in 0..cases(n) {
            let (_, cfg, ops) = gen(i);
            let t = std::time::Instant::now();
            let _ = run_case(&cfg, &ops);
            let mut pair = new_pair(&cfg);
            for op in &ops {
                let _ = apply(&mut pair, op);
            }
            let pruned = pair.ours.leaves(0).filter(|n| n.depth < 16).count();
            times.push((t.elapsed(), i, cfg.res, ops.len(), pair.ours.size(), pruned));
        }
        let total: std::time::Duration = times.iter().map(|t| t.0).sum();
        let with_pruned = times.iter().filter(|t| t.5 > 0).count();
        times.sort_by_key(|t| std::cmp::Reverse(t.0));
        println!(
            "{name}: total {total:?}, {with_pruned}/{} final trees with pruned leaves; \
             slowest (time, case, res, ops, final size, pruned leaves):",
            times.len()
        );
        for t in times.iter().take(5) {
            println!("  {t:?}");
        }
    }
}
