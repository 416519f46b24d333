//! Differential tests of the rich tree kinds against the real OctoMap (the
//! system `liboctomap` through `octolinear-oracle`): `ColorOcTree` built from
//! random coloured scans as OctoMap users build it (`insertPointCloud`, then a
//! colour setter per point, then `updateInnerOccupancy`), compared by `.ot`
//! bytes after every step and by `search` results; `OcTreeStamped` compared by
//! `.ot` bytes and by the stamp of every node. (`octolinear build --color`
//! against OctoMap: `cli/tests/differential_color.rs`.)
//!
//! OctoMap stamps with `time(NULL)`. The oracle reports the second before and
//! after each call; octolinear replays a call with that second as its clock,
//! and a case whose call straddled two seconds is run again.
//!
//! Knobs: `OCTOLINEAR_DIFF_SEED` (base seed), `OCTOLINEAR_DIFF_SCALE`
//! (multiplies the number of random cases).

mod common;
use common::colored_scan;
use octolinear::formats::ot;
use octolinear::sensor::{SensorModel, SensorProbabilities};
use octolinear::{Clock, InnerNodes, NodeKind, OccupancyTree, Point3, ScanOptions};
use octolinear_oracle::{
    require_or_skip, ColorOp, OracleColorTree, OracleError, OracleStampedTree, SensorParams, StampedNode,
};
use octolinear_sim::SplitMix64;

fn base_seed() -> u64 {
    std::env::var("OCTOLINEAR_DIFF_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(0x00c0_10c0_ffee)
}

fn scale(n: usize) -> usize {
    let k: f64 = std::env::var("OCTOLINEAR_DIFF_SCALE").ok().and_then(|s| s.parse().ok()).unwrap_or(1.0);
    ((n as f64 * k).round() as usize).max(1)
}

fn p3(p: [f32; 3]) -> Point3 {
    Point3::new(p[0], p[1], p[2])
}

fn ot_bytes(t: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(t, &mut v).unwrap();
    v
}

/// Where two `.ot` streams first differ, for the failure message.
fn first_difference(a: &[u8], b: &[u8]) -> String {
    let at = a.iter().zip(b).position(|(x, y)| x != y).unwrap_or(a.len().min(b.len()));
    format!("lengths {} vs {}, first difference at byte {at}", a.len(), b.len())
}

fn apply_color(t: &mut OccupancyTree, op: ColorOp, pts: &[[f32; 3]], cols: &[[u8; 3]]) -> usize {
    let mut found = 0;
    for (p, c) in pts.iter().zip(cols) {
        let Ok(k) = t.key(p3(*p)) else { continue };
        let r = match op {
            ColorOp::Integrate => t.integrate_color(k, *c),
            ColorOp::Average => t.average_color(k, *c),
            ColorOp::Set => t.set_color(k, *c),
        };
        found += usize::from(r.is_some());
    }
    found
}

/// One random colour case; `Err` when OctoMap refused it (a ray too long for
/// its `KeyRay`), a panic with the case's description when the trees differ.
fn color_case(seed: u64, res: f64, custom_sensor: bool) -> Result<(), OracleError> {
    let mut rng = SplitMix64(seed);
    let sensor = custom_sensor.then(|| SensorParams {
        prob_hit: rng.range(0.55, 0.95),
        prob_miss: rng.range(0.1, 0.45),
        clamp_min: rng.range(0.05, 0.3),
        clamp_max: rng.range(0.8, 0.99),
    });
    let mut theirs = OracleColorTree::new(res, sensor.as_ref())?;
    let model = match &sensor {
        None => SensorModel::default(),
        Some(s) => SensorModel::from_probabilities(&SensorProbabilities {
            hit: s.prob_hit,
            miss: s.prob_miss,
            clamping_min: s.clamp_min,
            clamping_max: s.clamp_max,
            occupancy_threshold: 0.5,
        })
        .unwrap(),
    };
    let mut ours = OccupancyTree::with_kind(res, model, NodeKind::Color).unwrap();
    let what = |step: &str| format!("seed {seed:#x}, res {res}, sensor {sensor:?}: {step}");
    let compare = |ours: &OccupancyTree, theirs: &OracleColorTree, step: &str| {
        let (a, b) = (ot_bytes(ours), theirs.write_ot().unwrap());
        assert!(a == b, "{}: .ot bytes differ ({})", what(step), first_difference(&a, &b));
    };
    let scans = 1 + rng.below(4) as usize;
    let mut all_points = Vec::new();
    for s in 0..scans {
        let origin = [rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32, rng.range(-0.5, 0.5) as f32];
        let n = 200 + rng.below(1000) as usize;
        let (pts, cols) = colored_scan(&mut rng, res, origin, n);
        let max_range = (rng.below(4) == 0).then(|| rng.range(1.0, 6.0));
        let discretize = rng.below(3) == 0;
        let lazy = rng.below(5) == 0;
        theirs.insert_point_cloud(&pts, origin, max_range.unwrap_or(-1.0), lazy, discretize)?;
        let inner = if lazy { InnerNodes::Defer } else { InnerNodes::Update };
        let opts = ScanOptions::default().with_max_range(max_range).with_discretize(discretize).with_inner(inner);
        let points: Vec<Point3> = pts.iter().copied().map(p3).collect();
        let op = match rng.below(10) {
            0 => ColorOp::Average,
            1 => ColorOp::Set,
            _ => ColorOp::Integrate,
        };
        if op == ColorOp::Integrate && rng.below(2) == 0 {
            // the library's one-call form
            ours.insert_colored_point_cloud(&points, &cols, p3(origin), &opts).unwrap();
        } else if rng.below(3) == 0 {
            // the pipelined form on two threads must keep OctoMap's key order
            let two = opts.with_threads(Some(2));
            ours.insert_point_clouds([(points.as_slice(), p3(origin))], &two, |_, _| {}).unwrap();
            apply_color(&mut ours, op, &pts, &cols);
        } else {
            ours.insert_point_cloud(&points, p3(origin), &opts).unwrap();
            apply_color(&mut ours, op, &pts, &cols);
        }
        let found = theirs.apply_colors(op, &pts, &cols);
        if op != ColorOp::Integrate {
            assert_eq!(apply_color(&mut ours.clone(), op, &pts, &cols), found, "{}", what("nodes found"));
        }
        compare(
            &ours,
            &theirs,
            &format!("scan {s} ({op:?}, range {max_range:?}, discretize {discretize}, lazy {lazy})"),
        );
        if lazy || rng.below(3) == 0 {
            ours.update_inner_occupancy();
            theirs.update_inner_occupancy();
            compare(&ours, &theirs, &format!("updateInnerOccupancy after scan {s}"));
        }
        match rng.below(8) {
            0 => {
                ours.expand().unwrap();
                theirs.expand();
                compare(&ours, &theirs, &format!("expand after scan {s}"));
                ours.prune();
                theirs.prune();
                compare(&ours, &theirs, &format!("prune after scan {s}"));
            }
            1 => {
                ours.to_max_likelihood();
                theirs.to_max_likelihood();
                ours.prune();
                theirs.prune();
                compare(&ours, &theirs, &format!("toMaxLikelihood + prune after scan {s}"));
            }
            _ => {}
        }
        all_points.extend(pts);
    }
    ours.update_inner_occupancy();
    theirs.update_inner_occupancy();
    compare(&ours, &theirs, "final updateInnerOccupancy");
    for _ in 0..200 {
        let p = all_points[rng.below(all_points.len() as u32) as usize];
        let depth = rng.below(17) as u8;
        let a = ours.search_point(p3(p), depth).unwrap().map(|f| (f.value, octolinear::tree::unpack_rgb(f.extra)));
        assert_eq!(a, theirs.search(p, depth), "{}", what(&format!("search {p:?} at depth {depth}")));
    }
    Ok(())
}

#[test]
fn color_trees_match_octomap_on_random_scans() {
    if !require_or_skip("color_trees_match_octomap_on_random_scans") {
        return;
    }
    let resolutions = [0.05, 0.1, 0.2, 0.25, 0.03, 0.5];
    let mut ran = 0;
    for i in 0..scale(18) {
        let res = resolutions[i % resolutions.len()];
        let seed = base_seed().wrapping_add(i as u64 * 0x9e37_79b9);
        match color_case(seed, res, i % 3 == 2) {
            Ok(()) => ran += 1,
            Err(OracleError::RayTooLong) => {}
            Err(e) => panic!("seed {seed:#x}: {e}"),
        }
    }
    assert!(ran >= scale(18) * 3 / 4, "only {ran} cases ran");
}

/// OctoMap's single-voxel colour calls on a pruned map: the setters act on
/// the coarse leaf holding the voxel.
#[test]
fn color_updates_on_pruned_leaves_match_octomap() {
    if !require_or_skip("color_updates_on_pruned_leaves_match_octomap") {
        return;
    }
    let mut rng = SplitMix64(base_seed() ^ 0x5eed);
    for &res in &[0.1, 0.05] {
        let mut theirs = OracleColorTree::new(res, None).unwrap();
        let mut ours = OccupancyTree::with_kind(res, SensorModel::default(), NodeKind::Color).unwrap();
        // a solid block, saturated: it prunes to coarse leaves
        let mut block = Vec::new();
        for x in 0..16 {
            for y in 0..16 {
                for z in 0..8 {
                    block.push(
                        [(x as f64 + 0.5) * res, (y as f64 + 0.5) * res, (z as f64 + 0.5) * res].map(|c| c as f32),
                    );
                }
            }
        }
        for _ in 0..6 {
            for p in &block {
                theirs.update_node(*p, true, false);
                ours.update_point(p3(*p), true, InnerNodes::Update).unwrap();
            }
        }
        let cols: Vec<[u8; 3]> = block.iter().map(|_| [0, 1, 2].map(|_| rng.below(256) as u8)).collect();
        for op in [ColorOp::Set, ColorOp::Integrate, ColorOp::Average, ColorOp::Integrate] {
            let found = theirs.apply_colors(op, &block, &cols);
            assert_eq!(apply_color(&mut ours, op, &block, &cols), found);
            assert_eq!(ot_bytes(&ours), theirs.write_ot().unwrap(), "res {res}, {op:?}");
        }
        ours.update_inner_occupancy();
        theirs.update_inner_occupancy();
        assert_eq!(ot_bytes(&ours), theirs.write_ot().unwrap(), "res {res}, updateInnerOccupancy");
        ours.expand().unwrap();
        theirs.expand();
        ours.prune();
        theirs.prune();
        assert_eq!(ot_bytes(&ours), theirs.write_ot().unwrap(), "res {res}, expand + prune");
    }
}

// ------------------------------------------------------------------ OcTreeStamped

fn our_stamps(t: &OccupancyTree) -> Vec<StampedNode> {
    t.nodes(0)
        .map(|n| StampedNode { key: n.key.0, depth: n.depth, is_leaf: n.is_leaf, logodds: n.value, stamp: n.extra })
        .collect()
}

enum StampedStep {
    Scan { pts: Vec<[f32; 3]>, origin: [f32; 3], max_range: Option<f64>, discretize: bool },
    Update { p: [f32; 3], occupied: bool },
    Degrade(u32),
    Wait,
}

/// Runs `steps` on both trees; `None` when an OctoMap call straddled two
/// seconds (the caller retries).
fn stamped_run(res: f64, steps: &[StampedStep]) -> Option<()> {
    let mut theirs = OracleStampedTree::new(res).unwrap();
    let mut ours = OccupancyTree::with_kind(res, SensorModel::default(), NodeKind::Stamped).unwrap();
    for (i, step) in steps.iter().enumerate() {
        let t = match step {
            StampedStep::Scan { pts, origin, max_range, discretize } => {
                let t = theirs.insert_point_cloud(pts, *origin, max_range.unwrap_or(-1.0), false, *discretize).unwrap();
                ours.set_clock(Clock::Fixed(t.single()?));
                let opts = ScanOptions::default().with_max_range(*max_range).with_discretize(*discretize);
                let points: Vec<Point3> = pts.iter().copied().map(p3).collect();
                ours.insert_point_cloud(&points, p3(*origin), &opts).unwrap();
                t
            }
            StampedStep::Update { p, occupied } => {
                let (_, t) = theirs.update_node(*p, *occupied, false);
                ours.set_clock(Clock::Fixed(t.single()?));
                ours.update_point(p3(*p), *occupied, InnerNodes::Update).unwrap();
                t
            }
            StampedStep::Degrade(age) => {
                let t = theirs.degrade_outdated_nodes(*age);
                ours.set_clock(Clock::Fixed(t.single()?));
                ours.degrade_outdated_nodes(*age);
                t
            }
            StampedStep::Wait => {
                // into the next second
                let now = || std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap();
                let start = now().as_secs();
                while now().as_secs() == start {
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
                continue;
            }
        };
        assert_eq!(ot_bytes(&ours), theirs.write_ot().unwrap(), "res {res}, step {i} at {t:?}: .ot bytes differ");
        let (a, b) = (our_stamps(&ours), theirs.nodes());
        assert_eq!(a.len(), b.len(), "res {res}, step {i}: node counts differ");
        if let Some(k) = (0..a.len()).find(|&k| a[k] != b[k]) {
            panic!("res {res}, step {i}: node {k} differs: ours {:?}, OctoMap {:?}", a[k], b[k]);
        }
        assert_eq!(ours.last_update_time(), b.first().map(|n| n.stamp), "res {res}, step {i}: getLastUpdateTime");
    }
    Some(())
}

fn stamped_retrying(res: f64, steps: &[StampedStep]) {
    for _ in 0..5 {
        if stamped_run(res, steps).is_some() {
            return;
        }
    }
    panic!("every attempt straddled a second boundary");
}

#[test]
fn stamped_trees_match_octomap_on_random_scans() {
    if !require_or_skip("stamped_trees_match_octomap_on_random_scans") {
        return;
    }
    let mut rng = SplitMix64(base_seed() ^ 0x57a4);
    for (i, &res) in [0.1, 0.05, 0.2, 0.25].iter().cycle().take(scale(8)).enumerate() {
        let mut steps = Vec::new();
        for _ in 0..1 + rng.below(3) {
            let origin = [rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32, 0.0];
            let n = 200 + rng.below(800) as usize;
            let (pts, _) = colored_scan(&mut rng, res, origin, n);
            let max_range = (rng.below(4) == 0).then(|| rng.range(1.0, 6.0));
            for p in pts.iter().step_by(97).take(5) {
                steps.push(StampedStep::Update { p: *p, occupied: rng.below(2) == 0 });
            }
            steps.push(StampedStep::Scan { pts, origin, max_range, discretize: rng.below(3) == 0 });
        }
        steps.push(StampedStep::Degrade(if i % 2 == 0 { 0 } else { 100 }));
        stamped_retrying(res, &steps);
    }
}

/// Stamps of different seconds: the second scan's voxels carry a newer
/// stamp, pruning needs equal stamps, and degrading with age 0 gives every
/// occupied leaf of the first second a miss.
#[test]
fn stamped_trees_match_octomap_across_seconds() {
    if !require_or_skip("stamped_trees_match_octomap_across_seconds") {
        return;
    }
    let mut rng = SplitMix64(base_seed() ^ 0x5ec0);
    let res = 0.1;
    let (a, _) = colored_scan(&mut rng, res, [0.0; 3], 600);
    let (b, _) = colored_scan(&mut rng, res, [0.5, 0.0, 0.0], 600);
    let steps = vec![
        StampedStep::Scan { pts: a, origin: [0.0; 3], max_range: None, discretize: false },
        StampedStep::Wait,
        StampedStep::Scan { pts: b, origin: [0.5, 0.0, 0.0], max_range: None, discretize: false },
        StampedStep::Degrade(0),
        StampedStep::Degrade(0),
    ];
    stamped_retrying(res, &steps);
}
