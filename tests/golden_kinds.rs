//! The golden `color`, `stamped` and `counting` cases: OctoMap's
//! ColorOcTree, OcTreeStamped and CountingOcTree reproduced bit for bit.

mod common;

use common::*;
use octolinear::formats::{bt, graph, ot};
use octolinear::tree::{unpack_rgb, NodeKind};
use octolinear::{Clock, CountingTree, OccupancyTree, Point3, ScanOptions};
use serde_json::Value;
use std::fmt::Write as _;

/// World-frame scans of a case's `.graph` input (graph2tree transform).
fn scans(g: &Golden, case: &Value) -> Vec<(Vec<Point3>, Point3)> {
    let gr = graph::read_file(g.input(case["input"].as_str().unwrap())).unwrap();
    gr.nodes.iter().map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect()
}

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).unwrap();
    v
}

fn dump(tree: &OccupancyTree, leaves_only: bool, extra: impl Fn(u32) -> String) -> String {
    let mut s = String::from(if leaves_only { "kx,ky,kz,depth,logodds" } else { "kx,ky,kz,depth,is_leaf,logodds" });
    s.push_str(match tree.kind() {
        NodeKind::Color => ",r,g,b\n",
        _ => ",timestamp\n",
    });
    let items: Box<dyn Iterator<Item = _>> =
        if leaves_only { Box::new(tree.leaves(0)) } else { Box::new(tree.nodes(0)) };
    for n in items {
        let [x, y, z] = n.key.0;
        if leaves_only {
            write!(s, "{x},{y},{z},{},{}", n.depth, f32hex(n.value)).unwrap();
        } else {
            write!(s, "{x},{y},{z},{},{},{}", n.depth, u8::from(n.is_leaf), f32hex(n.value)).unwrap();
        }
        writeln!(s, ",{}", extra(n.extra)).unwrap();
    }
    s
}

fn rgb(e: u32) -> String {
    let [r, g, b] = unpack_rgb(e);
    format!("{r},{g},{b}")
}

#[test]
fn golden_color_trees() {
    let g = golden();
    let mut f = Failures::default();
    for case in g.cases("color") {
        let id = case["id"].as_str().unwrap();
        let res = case["params"]["resolution"].as_f64().unwrap();
        let mut tree = OccupancyTree::with_kind(res, case_sensor(case), NodeKind::Color).unwrap();
        let calls = g.load_text(case, "color_calls.csv").unwrap();
        let mut calls = calls.lines().skip(1).peekable();
        let mut out = String::from("scan,index,method,x,y,z,r,g,b,found,r_after,g_after,b_after\n");
        for (i, (points, origin)) in scans(&g, case).iter().enumerate() {
            tree.insert_point_cloud(points, *origin, &ScanOptions::default()).unwrap();
            while let Some(line) = calls.next_if(|l| l.starts_with(&format!("{i},"))) {
                let c: Vec<&str> = line.split(',').collect();
                let p = point_from_hex(&c[3..6]);
                let color = [c[6].parse().unwrap(), c[7].parse().unwrap(), c[8].parse().unwrap()];
                let after = tree.key(p).ok().and_then(|k| match c[2] {
                    "integrate" => tree.integrate_color(k, color),
                    "average" => tree.average_color(k, color),
                    _ => tree.set_color(k, color),
                });
                let (found, [r, gg, b]) = match after {
                    Some(a) => (1, a),
                    None => (0, [0, 0, 0]),
                };
                let after = if found == 1 { format!("{r},{gg},{b}") } else { ",,".to_string() };
                writeln!(
                    out,
                    "{},{},{},{},{},{},{},{},{},{found},{after}",
                    c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
                )
                .unwrap();
            }
        }
        f.check_digest(&g, case, "color_calls.csv", out.as_bytes());
        f.check_digest(&g, case, "color_before_inner.ot", &ot_bytes(&tree));
        tree.update_inner_occupancy();
        let color_ot = ot_bytes(&tree);
        f.check_digest(&g, case, "color.ot", &color_ot);
        f.check_digest(&g, case, "leaves.csv", dump(&tree, true, rgb).as_bytes());
        f.check_digest(&g, case, "nodes.csv", dump(&tree, false, rgb).as_bytes());
        let back = ot::read(&color_ot[..]).unwrap().into_occupancy().unwrap();
        f.check(back.kind() == NodeKind::Color, || format!("{id}: .ot read-back lost the colour kind"));
        f.check_digest(&g, case, "ot_readback.ot", &ot_bytes(&back));
        tree.prune();
        f.check_digest(&g, case, "color_pruned.ot", &ot_bytes(&tree));
        f.check_digest(&g, case, "nodes_pruned.csv", dump(&tree, false, rgb).as_bytes());
        let mut bt_bytes = Vec::new();
        bt::write(&tree, &mut bt_bytes).unwrap();
        f.check_digest(&g, case, "color.bt", &bt_bytes);
        tree.to_max_likelihood();
        tree.prune();
        f.check_digest(&g, case, "color_after_writeBinary.ot", &ot_bytes(&tree));
        f.check_digest(&g, case, "nodes_after_writeBinary.csv", dump(&tree, false, rgb).as_bytes());
    }
    f.finish("color cases");
}

#[test]
fn golden_stamped_trees() {
    let g = golden();
    let mut f = Failures::default();
    for case in g.cases("stamped") {
        let id = case["id"].as_str().unwrap();
        let res = case["params"]["resolution"].as_f64().unwrap();
        let expected = expected_stats(&g, case);
        let mut tree = OccupancyTree::with_kind(res, case_sensor(case), NodeKind::Stamped).unwrap();
        let scans = scans(&g, case);
        for (i, (points, origin)) in scans.iter().enumerate() {
            tree.set_clock(Clock::Fixed(1_000_000 + 10 * i as u32));
            tree.insert_point_cloud(points, *origin, &ScanOptions::default()).unwrap();
        }
        let stamp = |e: u32| e.to_string();
        f.check_digest(&g, case, "stamped.ot", &ot_bytes(&tree));
        f.check_digest(&g, case, "leaves.csv", dump(&tree, true, stamp).as_bytes());
        f.check_digest(&g, case, "nodes.csv", dump(&tree, false, stamp).as_bytes());
        let last = expected.get("built").and_then(|s| s.get("last_update_time")).cloned();
        let ours = tree.last_update_time().map(|t| t.to_string());
        f.check(last == ours, || format!("{id}: last_update_time {ours:?}, expected {last:?}"));
        tree.set_clock(Clock::Fixed(1_000_000 + 10 * scans.len() as u32 + 5));
        tree.degrade_outdated_nodes(12);
        f.check_digest(&g, case, "leaves_degraded.csv", dump(&tree, true, stamp).as_bytes());
        f.check_digest(&g, case, "stamped_degraded.ot", &ot_bytes(&tree));
    }
    f.finish("stamped cases");
}

#[test]
fn golden_counting_trees() {
    let g = golden();
    let mut f = Failures::default();
    for case in g.cases("counting") {
        let res = case["params"]["resolution"].as_f64().unwrap();
        let mut tree = CountingTree::new(res).unwrap();
        let mut out = String::from("scan,index,x,y,z,returned,count_after\n");
        for (i, (points, _)) in scans(&g, case).iter().enumerate() {
            for (j, p) in points.iter().enumerate() {
                let (ret, count) = match tree.update_point(*p) {
                    Ok(c) => (1, c.to_string()),
                    Err(_) => (0, String::new()),
                };
                writeln!(out, "{i},{j},{},{},{},{ret},{count}", f32hex(p.x), f32hex(p.y), f32hex(p.z)).unwrap();
            }
        }
        f.check_digest(&g, case, "updates.csv", out.as_bytes());
        let mut bytes = Vec::new();
        ot::write_counting(&tree, &mut bytes).unwrap();
        f.check_digest(&g, case, "counting.ot", &bytes);
        let mut nodes = String::from("kx,ky,kz,depth,is_leaf,count\n");
        for n in tree.nodes(0) {
            let [x, y, z] = n.key.0;
            writeln!(nodes, "{x},{y},{z},{},{},{}", n.depth, u8::from(n.is_leaf), n.extra).unwrap();
        }
        f.check_digest(&g, case, "nodes.csv", nodes.as_bytes());
        // `count(key, depth)` finds each of those nodes (CountingOcTree::search;
        // depth 0 means 16 there, so not the root)
        for n in tree.nodes(0).skip(1) {
            f.check(tree.count(n.key, n.depth) == Some(n.extra), || format!("count at {} depth {}", n.key, n.depth));
        }
        for hits in 1..=3 {
            let mut s = String::from("x,y,z\n");
            for p in tree.centers_min_hits(hits) {
                writeln!(s, "{},{},{}", f32hex(p.x), f32hex(p.y), f32hex(p.z)).unwrap();
            }
            f.check_digest(&g, case, &format!("centers_min_hits_{hits}.csv"), s.as_bytes());
        }
        let back = match ot::read(&bytes[..]).unwrap() {
            ot::AnyTree::Counting(t) => t,
            other => panic!("read back as {:?}", other.kind()),
        };
        let mut again = Vec::new();
        ot::write_counting(&back, &mut again).unwrap();
        f.check_digest(&g, case, "ot_readback.ot", &again);
    }
    f.finish("counting cases");
}
