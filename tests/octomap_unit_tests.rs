//! Port of OctoMap's `octomap/src/testing/unit_tests.cpp`: one test per
//! scenario the CMakeLists runs (`unit_tests MathVector`, ..., `OcTreeKey`).

mod octomap_port;

use octolinear::formats::{bt, graph};
use octolinear::sensor::{logodds, probability, SensorModel, SensorProbabilities};
use octolinear::{Clock, InnerNodes, NodeKind, OccupancyTree, Point3, PointCloud, Pose6D, Quaternion, ScanOptions};
use octomap_port::{assert_octomap_file, deg2rad, expect_float_eq};
use std::f64::consts::PI;

#[test]
fn deg2rad_is_octomaps_constant() {
    #[allow(clippy::excessive_precision)]
    let octomap: f64 = 0.01745329251994329575;
    assert_eq!(deg2rad(1.0), octomap);
}

#[test]
fn math_vector() {
    let twos = Point3::new(2.0, 2.0, 2.0);
    let ones = Point3::new(1.0, 1.0, 1.0);
    let subtraction = twos - ones;
    let addition = twos + ones;
    let multiplication = twos * 2.0;
    for (s, (a, m)) in
        subtraction.to_array().into_iter().zip(addition.to_array().into_iter().zip(multiplication.to_array()))
    {
        expect_float_eq(s.into(), 1.0);
        expect_float_eq(a.into(), 3.0);
        expect_float_eq(m.into(), 4.0);
    }

    let mut rotation = ones;
    rotation.rotate_ip(PI, 1.0, 0.1);
    expect_float_eq(rotation.x.into(), 1.2750367);
    expect_float_eq(rotation.y.into(), -1.1329513);
    expect_float_eq(rotation.z.into(), 0.30116868);
}

#[test]
fn math_pose() {
    // C++ passes `0.1f` and `(float) M_PI/4.` to double parameters
    let (pitch, yaw) = (f64::from(0.1f32), f64::from(PI as f32) / 4.0);
    let a = Pose6D::from_euler(1.0, 0.1, 0.1, 0.0, pitch, yaw);
    let _b = Pose6D::default();

    let trans = Point3::new(1.0, 0.1, 0.1);
    let rot = Quaternion::from_euler(0.0, pitch, yaw);
    let c = Pose6D::new(trans, rot);

    assert_eq!(a, c);
    expect_float_eq(c.yaw(), PI / 4.0);

    let t = c.transform(trans);
    expect_float_eq(t.x.into(), 1.6399229);
    expect_float_eq(t.y.into(), 0.8813442);
    expect_float_eq(t.z.into(), 0.099667005);

    let c_inv = c.inv();
    let t2 = c_inv.transform(t);
    expect_float_eq(t2.x.into(), trans.x.into());
    expect_float_eq(t2.y.into(), trans.y.into());
    expect_float_eq(t2.z.into(), trans.z.into());
}

#[test]
fn insert_ray() {
    for p in [0.5, 0.1, 0.99] {
        expect_float_eq(p, probability(logodds(p).into()));
    }
    for l in [0.0f32, -4.0, 2.0] {
        expect_float_eq(l.into(), logodds(probability(l.into())).into());
    }

    let sensor = SensorModel::from_probabilities(&SensorProbabilities { hit: 0.7, miss: 0.4, ..Default::default() })
        .expect("valid sensor model");
    let mut tree = OccupancyTree::with_sensor(0.05, sensor).unwrap();
    let origin = Point3::new(0.01, 0.01, 0.02);
    let mut point_on_surface = Point3::new(2.01, 0.01, 0.01);
    for _ in 0..360 {
        for _ in 0..360 {
            tree.insert_ray(origin, origin + point_on_surface, None, InnerNodes::Update).expect("ray inserted");
            point_on_surface.rotate_ip(0.0, 0.0, deg2rad(1.0));
        }
        point_on_surface.rotate_ip(0.0, deg2rad(1.0), 0.0);
    }
    let mut file = Vec::new();
    bt::write(&tree, &mut file).expect("writeBinary");
    assert_octomap_file(&file, "sphere_rays.bt", "39b613a5811d5e35696c042a7441800a74e21ee324f6e62a586151cf9e5098bb");
    // OctoMap's writeBinary turns the tree itself into its maximum-likelihood,
    // pruned form before the size is checked
    tree.to_max_likelihood();
    tree.prune();
    assert_eq!(tree.size(), 50615);
    assert_eq!(bt::read(file.as_slice()).expect("readBinary").size(), 50615);
}

/// The measurement and graph of `InsertScan` (which `ReadGraph` reads back).
fn insert_scan_graph() -> (PointCloud, Point3, graph::ScanGraph) {
    let mut measurement = PointCloud::new();
    let origin = Point3::new(0.01, 0.01, 0.02);
    let mut point_on_surface = Point3::new(2.01, 0.01, 0.01);
    for _ in 0..360 {
        for _ in 0..360 {
            measurement.push(origin + point_on_surface);
            point_on_surface.rotate_ip(0.0, 0.0, deg2rad(1.0));
        }
        point_on_surface.rotate_ip(0.0, deg2rad(1.0), 0.0);
    }
    let mut graph = graph::ScanGraph::new();
    let node_pose = Pose6D::from_euler(origin.x, origin.y, origin.z, 0.0, 0.0, 0.0);
    graph.add_node(measurement.clone(), node_pose);
    (measurement, origin, graph)
}

#[test]
fn insert_scan() {
    let (measurement, origin, graph) = insert_scan_graph();
    let mut tree = OccupancyTree::new(0.05).unwrap();
    tree.insert_point_cloud(measurement.as_slice(), origin, &ScanOptions::default()).expect("scan inserted");
    assert_eq!(tree.size(), 53959);

    let dir = tempfile::tempdir().unwrap();
    graph::write_file(&graph, dir.path().join("test.graph")).expect("writeBinary");
    let bytes = std::fs::read(dir.path().join("test.graph")).unwrap();
    assert_octomap_file(&bytes, "test.graph", "65db6b42d4928bff6424395cf4282d968767c2f58f9a0d2b601942ddf02024a4");
}

#[test]
fn read_graph() {
    // OctoMap reads the file InsertScan wrote; here the graph is written anew.
    let (measurement, _, graph) = insert_scan_graph();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("test.graph");
    graph::write_file(&graph, &path).unwrap();
    let read = graph::read_file(&path).expect("readBinary");
    assert_eq!(read.nodes.len(), 1);
    assert_eq!(read.nodes[0].scan.len(), 129600);
    assert_eq!(read.nodes[0].scan, measurement);
    assert_eq!(read, graph);
}

#[test]
fn stamped_tree() {
    // OctoMap reads the wall clock and sleeps one second between updates;
    // a fixed clock advanced by one second does the same deterministically.
    const T0: u32 = 1_700_000_000;
    let mut stamped_tree = OccupancyTree::with_kind(0.05, SensorModel::default(), NodeKind::Stamped).unwrap();
    stamped_tree.set_clock(Clock::Fixed(T0));
    for x in -20..20 {
        for y in -20..20 {
            for z in -20..20 {
                let p = Point3::new(x as f32 * 0.05 + 0.01, y as f32 * 0.05 + 0.01, z as f32 * 0.05 + 0.01);
                stamped_tree.update_point(p, true, InnerNodes::Update).unwrap();
            }
        }
    }
    let query = Point3::new(0.1, 0.1, 0.1);
    let qkey = stamped_tree.key(query).unwrap();
    let result = stamped_tree.search(qkey, 0).expect("node found");
    let tree_time = stamped_tree.last_update_time().unwrap();
    let node_time = result.extra;
    assert!(tree_time > 0);
    assert_eq!(node_time, T0);

    stamped_tree.set_clock(Clock::Fixed(T0 + 1));
    // integrateMissNoTime(result): a clamped miss on the node, no new stamp,
    // no inner-node update (set_value neither stamps nor, deferred, touches
    // the path)
    let sensor = *stamped_tree.sensor();
    stamped_tree.set_value(qkey, sensor.apply(result.value, sensor.miss), InnerNodes::Defer);
    let result = stamped_tree.search(qkey, 0).expect("node found");
    assert_eq!(node_time, result.extra);
    assert!(result.value < sensor.hit);

    let query2 = Point3::new(0.1, 0.1, 0.3);
    stamped_tree.update_point(query2, true, InnerNodes::Update).unwrap();
    let result2 = stamped_tree.search_point(query2, 0).unwrap().expect("node found");
    let result = stamped_tree.search(qkey, 0).expect("node found");
    assert!(result.extra < result2.extra);
    assert_eq!(Some(result2.extra), stamped_tree.last_update_time());
}

#[test]
fn octree_key() {
    let tree = OccupancyTree::new(0.05).unwrap();
    let key = tree.key(Point3::new(0.0, 0.0, 0.0)).expect("in the map");
    let p_inv = tree.key_space().key_to_point(key);
    expect_float_eq(0.025, p_inv.x.into());
    expect_float_eq(0.025, p_inv.y.into());
    expect_float_eq(0.025, p_inv.z.into());
}
