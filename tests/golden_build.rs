//! Every `build` case of the golden vectors: scans inserted with OctoMap's
//! parameters must give the same trees, files, statistics and query answers.

mod common;
#[path = "common/scans.rs"]
mod scans;

use common::*;
use octolinear::formats::{bt, ot};
use octolinear::ray::CastError;
use octolinear::{CastOptions, InnerNodes, OccupancyTree, Point3, ScanOptions, UpdateBox};
use rayon::prelude::*;
use scans::case_scans;
use serde_json::Value;
use std::fmt::Write as _;

fn parse_bbx(tree: &OccupancyTree, s: &str) -> UpdateBox {
    let v: Vec<f32> = s.split(',').map(|t| t.parse().unwrap()).collect();
    UpdateBox::new(tree, Point3::new(v[0], v[1], v[2]), Point3::new(v[3], v[4], v[5])).unwrap()
}

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).unwrap();
    v
}

fn bt_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    bt::write(tree, &mut v).unwrap();
    v
}

fn bt_const_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    bt::write_const(tree, &mut v).unwrap();
    v
}

fn opt_f32(v: Option<f32>) -> String {
    v.map(f32hex).unwrap_or_default()
}

/// Answers the point queries listed in `query_points.csv`.
fn query_points_csv(tree: &OccupancyTree, expected: &str) -> String {
    let mut s = String::from("i,x,y,z,key_ok,kx,ky,kz,found,logodds,occupied,found_d14,logodds_d14\n");
    for line in expected.lines().skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        let p = point_from_hex(&cols[1..4]);
        let key = tree.key(p);
        let [kx, ky, kz] = key.map(|k| k.0).unwrap_or([0; 3]);
        let found = key.ok().and_then(|k| tree.search(k, 0));
        let found14 = key.ok().and_then(|k| tree.search(k, 14));
        writeln!(
            s,
            "{},{},{},{},{},{kx},{ky},{kz},{},{},{},{},{}",
            cols[0],
            cols[1],
            cols[2],
            cols[3],
            u8::from(key.is_ok()),
            u8::from(found.is_some()),
            opt_f32(found.map(|f| f.value)),
            u8::from(found.is_some_and(|f| tree.is_occupied(f.value))),
            u8::from(found14.is_some()),
            opt_f32(found14.map(|f| f.value)),
        )
        .unwrap();
    }
    s
}

/// Answers the `castRay` queries listed in `query_castray.csv`.
fn castray_csv(tree: &OccupancyTree, expected: &str) -> String {
    let mut s = String::from("i,ox,oy,oz,dx,dy,dz,ignore_unknown,max_range,ret,ex,ey,ez\n");
    for line in expected.lines().skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        let origin = point_from_hex(&cols[1..4]);
        let dir = point_from_hex(&cols[4..7]);
        let ignore_unknown = cols[7] == "1";
        let max_range = parse_f64hex(cols[8]);
        let opts = CastOptions { ignore_unknown, max_range: Some(max_range) };
        let (ret, end) = match tree.cast_ray(origin, dir, opts) {
            Ok(o) => (o.hit(), o.end()),
            Err(CastError::Origin(_) | CastError::ZeroDirection | CastError::NoOccupancy) => {
                (false, Point3::new(f32::NAN, f32::NAN, f32::NAN))
            }
        };
        writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            cols[0],
            cols[1],
            cols[2],
            cols[3],
            cols[4],
            cols[5],
            cols[6],
            cols[7],
            cols[8],
            u8::from(ret),
            f32hex(end.x),
            f32hex(end.y),
            f32hex(end.z)
        )
        .unwrap();
    }
    s
}

/// Answers the `computeRayKeys` queries listed in `query_raykeys.csv`.
fn raykeys_csv(tree: &OccupancyTree, expected: &str) -> String {
    let mut s = String::from("i,ox,oy,oz,ex,ey,ez,ok,n,keys\n");
    for line in expected.lines().skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        let origin = point_from_hex(&cols[1..4]);
        let end = point_from_hex(&cols[4..7]);
        let (ok, keys): (bool, Vec<String>) = match tree.ray_keys(origin, end) {
            Ok(ray) => (true, ray.map(|k| format!("{}:{}:{}", k.0[0], k.0[1], k.0[2])).collect()),
            Err(_) => (false, Vec::new()),
        };
        writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{}",
            cols[0],
            cols[1],
            cols[2],
            cols[3],
            cols[4],
            cols[5],
            cols[6],
            u8::from(ok),
            keys.len(),
            keys.join(";")
        )
        .unwrap();
    }
    s
}

/// Runs the `build` procedure of one case; returns its failures.
fn run_build_case(g: &Golden, case: &Value) -> Vec<String> {
    let mut f = Failures::default();
    let id = case["id"].as_str().unwrap();
    let Some(scans) = case_scans(g, case) else {
        return vec![format!("{id}: no plain-text scans for input {}", case["input"])];
    };
    let p = &case["params"];
    let res = p["resolution"].as_f64().unwrap();
    let sensor = case_sensor(case);
    let mut tree = OccupancyTree::with_sensor(res, sensor).unwrap();
    let max_range = p["maxrange"].as_f64().unwrap();
    let lazy = p["lazy_eval"].as_bool().unwrap_or(false);
    let change_detection = p["change_detection"].as_bool().unwrap_or(false);
    tree.set_change_detection(change_detection);
    let opts = ScanOptions::default()
        .with_max_range((max_range >= 0.0).then_some(max_range))
        .with_discretize(p["discretize"].as_bool().unwrap_or(false))
        .with_inner(if lazy { InnerNodes::Defer } else { InnerNodes::Update })
        .with_bbx(p["bbx"].as_str().map(|s| parse_bbx(&tree, s)));
    let mut changes = String::from("scan,kx,ky,kz,is_new\n");
    let mut original = StatsTracker::default();
    let expected = expected_stats(g, case);
    let per_scan_stats = case["harness_command_line"].as_str().unwrap_or("").contains("--per_scan_stats");
    for (i, (points, origin)) in scans.iter().enumerate() {
        tree.insert_point_cloud(points, *origin, &opts).unwrap();
        if lazy {
            tree.update_inner_occupancy();
        }
        if change_detection {
            for (k, new) in tree.changed_keys() {
                writeln!(changes, "{i},{},{},{},{}", k.0[0], k.0[1], k.0[2], u8::from(new)).unwrap();
            }
            tree.reset_change_detection();
        }
        let stage = format!("scan{i}");
        if expected.contains_key(&stage) {
            original.check(&mut f, id, &expected, &stage, &tree);
        } else if per_scan_stats {
            original.skip(&tree);
        }
    }
    if change_detection {
        f.check_digest(g, case, "changes.csv", changes.as_bytes());
    }
    original.check(&mut f, id, &expected, "built", &tree);
    let tree_ot = ot_bytes(&tree);
    f.check_digest(g, case, "tree.ot", &tree_ot);
    let mut compacted = tree.clone();
    compacted.compact();
    f.check(ot_bytes(&compacted) == tree_ot, || format!("{id}: compaction changed the tree"));
    f.check_digest(g, case, "leaves.csv", leaves_csv(&tree, 0).as_bytes());
    for (name, depth) in [("leaves_d14.csv", 14)] {
        if g.file(case, name).is_some() {
            f.check_digest(g, case, name, leaves_csv(&tree, depth).as_bytes());
        }
    }
    if g.file(case, "nodes.csv").is_some() {
        f.check_digest(g, case, "nodes.csv", nodes_csv(&tree).as_bytes());
    }
    for (name, answer) in [
        ("query_points.csv", query_points_csv as fn(&OccupancyTree, &str) -> String),
        ("query_castray.csv", castray_csv),
        ("query_raykeys.csv", raykeys_csv),
    ] {
        if let Some(expected) = g.load_text(case, name) {
            f.check_digest(g, case, name, answer(&tree, &expected).as_bytes());
        }
    }

    // .ot read back and written again
    let back = ot::read(&tree_ot[..]).unwrap().into_occupancy().unwrap();
    let back_ot = ot_bytes(&back);
    f.check(back_ot == tree_ot, || format!("{id}: .ot read-back rewrites different bytes"));
    let mut ml = back;
    let mut copy = StatsTracker::default();
    ml.set_sensor(sensor);
    ml.to_max_likelihood();
    copy.check(&mut f, id, &expected, "ml_unpruned", &ml);
    if g.file(case, "leaves_ml_unpruned.csv").is_some() {
        f.check_digest(g, case, "leaves_ml_unpruned.csv", leaves_csv(&ml, 0).as_bytes());
    }
    ml.prune();
    copy.check(&mut f, id, &expected, "ml_pruned", &ml);
    f.check_digest(g, case, "ml_pruned.ot", &ot_bytes(&ml));

    // writeBinary: the caller's tree must stay as it was
    let tree_bt = bt_bytes(&tree);
    f.check(ot_bytes(&tree) == tree_ot, || format!("{id}: bt::write changed the tree"));
    f.check_digest(g, case, "tree.bt", &tree_bt);
    f.check_digest(g, case, "after_writeBinary.ot", &ot_bytes(&ml));
    original.check(&mut f, id, &expected, "after_writeBinary", &ml);
    if g.file(case, "leaves_after_writeBinary.csv").is_some() {
        f.check_digest(g, case, "leaves_after_writeBinary.csv", leaves_csv(&ml, 0).as_bytes());
    }

    // a fresh default tree reads the .bt back
    let read = bt::read(&tree_bt[..]).unwrap();
    StatsTracker::default().check(&mut f, id, &expected, "bt_readback", &read);
    f.check_digest(g, case, "bt_readback.ot", &ot_bytes(&read));
    if g.file(case, "leaves_bt_readback.csv").is_some() {
        f.check_digest(g, case, "leaves_bt_readback.csv", leaves_csv(&read, 0).as_bytes());
    }
    f.check_digest(g, case, "bt_rewrite_const.bt", &bt_const_bytes(&read));
    f.0
}

#[test]
fn golden_build_cases_reproduce_octomap() {
    let g = golden();
    let cases = g.cases("build");
    assert!(cases.len() > 100, "manifest lists the build cases");
    let failures: Vec<String> = cases.par_iter().flat_map(|c| run_build_case(&g, c)).collect();
    Failures(failures).finish("golden build cases");
}
