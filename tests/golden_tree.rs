//! Golden cases about the tree itself: key arithmetic (`coordkey`), reading
//! a `.bt` map and its expand/prune round trip (`readbt`), and OctoMap's
//! `deleteNode` semantics (`delete`).

mod common;

use common::*;
use octolinear::formats::{bt, ot};
use octolinear::key::{adjust_to_depth, KeySpace};
use octolinear::{InnerNodes, Key, OccupancyTree, ScanOptions};
use serde_json::Value;
use std::fmt::Write as _;

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).unwrap();
    v
}

fn bt_bytes(tree: &OccupancyTree, konst: bool) -> Vec<u8> {
    let mut v = Vec::new();
    if konst {
        bt::write_const(tree, &mut v).unwrap();
    } else {
        bt::write(tree, &mut v).unwrap();
    }
    v
}

#[test]
fn golden_coordinate_key_conversions() {
    let g = golden();
    let case = g.case("coordkey");
    let mut f = Failures::default();

    let text = g.load_text(case, "coord_to_key.csv").unwrap();
    let mut out =
        String::from("res,coord,coord_is_f32,depth,key,checked_ok,checked_key,key_to_coord,key_to_coord_f32\n");
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let ks = KeySpace::new(parse_f64hex(c[0]));
        let coord = parse_f64hex(c[1]);
        let depth: u8 = c[3].parse().unwrap();
        let key = ks.coord_to_key_at_depth_unchecked(coord, depth);
        let checked = ks.coord_to_key_at_depth(coord, depth);
        let back = ks.key_to_coord_at_depth(key, depth);
        writeln!(
            out,
            "{},{},{},{depth},{key},{},{},{},{}",
            c[0],
            c[1],
            c[2],
            u8::from(checked.is_ok()),
            checked.unwrap_or(0),
            f64hex(back),
            f32hex(back as f32)
        )
        .unwrap();
    }
    f.check_digest(&g, case, "coord_to_key.csv", out.as_bytes());

    let text = g.load_text(case, "key_to_coord.csv").unwrap();
    let mut out = String::from("res,key,depth,key_to_coord,adjust_key_at_depth,node_size\n");
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let ks = KeySpace::new(parse_f64hex(c[0]));
        let key: u16 = c[1].parse().unwrap();
        let depth: u8 = c[2].parse().unwrap();
        let coord = ks.key_to_coord_at_depth(key, depth);
        let adjusted = adjust_to_depth(key, depth);
        writeln!(out, "{},{key},{depth},{},{adjusted},{}", c[0], f64hex(coord), f64hex(ks.node_size(depth))).unwrap();
    }
    f.check_digest(&g, case, "key_to_coord.csv", out.as_bytes());

    let text = g.load_text(case, "point_to_key.csv").unwrap();
    let mut out = String::from("res,x,y,z,ok,kx,ky,kz,ok_d14,kx14,ky14,kz14,center_x,center_y,center_z\n");
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let ks = KeySpace::new(parse_f64hex(c[0]));
        let p = point_from_hex(&c[1..4]);
        let k = ks.key(p);
        let k14 = ks.key_at_depth(p, 14);
        let [x, y, z] = k.map(|k| k.0).unwrap_or([0; 3]);
        let [x14, y14, z14] = k14.map(|k| k.0).unwrap_or([0; 3]);
        let center = ks.key_to_point(Key([x, y, z]));
        writeln!(
            out,
            "{},{},{},{},{},{x},{y},{z},{},{x14},{y14},{z14},{},{},{}",
            c[0],
            c[1],
            c[2],
            c[3],
            u8::from(k.is_ok()),
            u8::from(k14.is_ok()),
            f32hex(center.x),
            f32hex(center.y),
            f32hex(center.z)
        )
        .unwrap();
    }
    f.check_digest(&g, case, "point_to_key.csv", out.as_bytes());
    f.finish("coordkey");
}

#[test]
fn golden_read_bt_expand_and_prune() {
    let g = golden();
    let case = g.case("geb079_readbt");
    let id = "geb079_readbt";
    let expected = expected_stats(&g, case);
    let mut f = Failures::default();
    let input = std::fs::read(g.input("inputs/geb079.bt")).unwrap();
    let mut tree = bt::read(&input[..]).unwrap();
    let mut stats = StatsTracker::default();
    stats.check(&mut f, id, &expected, "read", &tree);
    f.check_digest(&g, case, "leaves.csv", leaves_csv(&tree, 0).as_bytes());
    f.check_digest(&g, case, "leaves_d14.csv", leaves_csv(&tree, 14).as_bytes());
    f.check_digest(&g, case, "nodes.csv", nodes_csv(&tree).as_bytes());
    f.check_digest(&g, case, "read.ot", &ot_bytes(&tree));
    f.check_digest(&g, case, "rewrite_const.bt", &bt_bytes(&tree, true));
    f.check(bt_bytes(&tree, true) == input, || format!("{id}: rewriting the .bt changes its bytes"));
    f.check_digest(&g, case, "rewrite.bt", &bt_bytes(&tree, false));
    tree.to_max_likelihood();
    tree.prune();
    stats.check(&mut f, id, &expected, "after_writeBinary", &tree);
    tree.expand().unwrap();
    stats.check(&mut f, id, &expected, "expanded", &tree);
    f.check_digest(&g, case, "leaves_expanded.csv", leaves_csv(&tree, 0).as_bytes());
    f.check_digest(&g, case, "expanded.ot", &ot_bytes(&tree));
    tree.prune();
    stats.check(&mut f, id, &expected, "reprune", &tree);
    f.check_digest(&g, case, "leaves_reprune.csv", leaves_csv(&tree, 0).as_bytes());
    f.check_digest(&g, case, "reprune.ot", &ot_bytes(&tree));
    f.check_digest(&g, case, "reprune_const.bt", &bt_bytes(&tree, true));
    f.finish(id);
}

/// Builds the tree of a `delete` case from its input's plain-text scans.
fn build_for_delete(g: &Golden, case: &Value) -> OccupancyTree {
    let stem = case["input"].as_str().unwrap().trim_start_matches("inputs/").trim_end_matches(".graph");
    let origins = std::fs::read_to_string(g.input(&format!("inputs/{stem}.origins.csv"))).unwrap();
    let mut tree =
        OccupancyTree::with_sensor(case["params"]["resolution"].as_f64().unwrap(), case_sensor(case)).unwrap();
    for line in origins.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let points = read_xyz(&std::fs::read_to_string(g.input(&format!("inputs/{}", c[1]))).unwrap());
        tree.insert_point_cloud(&points, point_from_hex(&c[2..5]), &ScanOptions::default()).unwrap();
    }
    tree
}

#[test]
fn golden_delete_node_semantics() {
    let g = golden();
    let mut f = Failures::default();
    for case in g.cases("delete") {
        let id = case["id"].as_str().unwrap();
        let expected = expected_stats(&g, case);
        let mut tree = build_for_delete(&g, case);
        let mut stats = StatsTracker::default();
        stats.check(&mut f, id, &expected, "built", &tree);
        f.check_digest(&g, case, "before.ot", &ot_bytes(&tree));
        let ops = g.load_text(case, "delete_ops.csv").unwrap();
        let mut out = String::from("op,kx,ky,kz,depth,ret,size_after,num_leaf_nodes_after,root_logodds_after\n");
        for line in ops.lines().skip(1) {
            let c: Vec<&str> = line.split(',').collect();
            let key = Key([c[1].parse().unwrap(), c[2].parse().unwrap(), c[3].parse().unwrap()]);
            let depth: u8 = c[4].parse().unwrap();
            let ret = tree.delete(key, depth);
            let root = tree.root_value().map(f32hex).unwrap_or_default();
            writeln!(
                out,
                "{},{},{},{},{depth},{},{},{},{root}",
                c[0],
                c[1],
                c[2],
                c[3],
                u8::from(ret),
                tree.size(),
                tree.num_leaves()
            )
            .unwrap();
        }
        f.check_digest(&g, case, "delete_ops.csv", out.as_bytes());
        stats.check(&mut f, id, &expected, "after_deletes", &tree);
        f.check_digest(&g, case, "after_deletes.ot", &ot_bytes(&tree));
        f.check_digest(&g, case, "leaves.csv", leaves_csv(&tree, 0).as_bytes());
        f.check_digest(&g, case, "nodes.csv", nodes_csv(&tree).as_bytes());

        if let Some(single) = g.load(case, "single_before.ot") {
            // the voxel OctoMap updated, recovered from its file
            let read = ot::read(&single[..]).unwrap().into_occupancy().unwrap();
            let leaf = read.leaves(0).next().unwrap().key;
            let mut one = OccupancyTree::with_sensor(read.resolution(), case_sensor(case)).unwrap();
            one.update_occupancy(leaf, true, InnerNodes::Update);
            f.check_digest(&g, case, "single_before.ot", &ot_bytes(&one));
            let ret = one.delete(leaf, 0);
            f.check(ret, || format!("{id}: deleting the only voxel returns false"));
            f.check_digest(&g, case, "single_after_delete.ot", &ot_bytes(&one));
            f.check(!one.delete(leaf, 0), || format!("{id}: deleting a missing voxel returns true"));
            let mut empty = OccupancyTree::new(read.resolution()).unwrap();
            f.check(empty.delete(leaf, 0), || format!("{id}: deleting on an empty tree returns false"));
            one.clear();
            f.check_digest(&g, case, "empty.ot", &ot_bytes(&one));
            f.check_digest(&g, case, "empty.bt", &bt_bytes(&one, false));
        }
    }
    f.finish("delete cases");
}
