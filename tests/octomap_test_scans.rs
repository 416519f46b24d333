//! Port of OctoMap's `octomap/src/testing/test_scans.cpp`, run as its
//! CMakeLists does: `test_scans share/data/spherical_scan.graph`.

mod octomap_port;

use octolinear::formats::{bt, graph};
use octolinear::{OccupancyTree, Point3, PointCloud, Pose6D, ScanOptions};
use octomap_port::{assert_octomap_file, deg2rad, expect_float_eq, input};

fn compare_pose(first: &Pose6D, sec: &Pose6D) {
    let (a, b) = (first.trans(), sec.trans());
    expect_float_eq(a.x.into(), b.x.into());
    expect_float_eq(a.y.into(), b.y.into());
    expect_float_eq(a.z.into(), b.z.into());
    expect_float_eq(first.roll(), sec.roll());
    expect_float_eq(first.pitch(), sec.pitch());
    expect_float_eq(first.yaw(), sec.yaw());
}

fn compare_point(first: Point3, sec: Point3) {
    expect_float_eq(first.x.into(), sec.x.into());
    expect_float_eq(first.y.into(), sec.y.into());
    expect_float_eq(first.z.into(), sec.z.into());
}

#[test]
fn test_scans() {
    let filename = input("spherical_scan.graph");
    let reference_graph = graph::read_file(&filename).expect("reference graph reads");

    let point_on_surface = Point3::new(4.01, 0.01, 0.01);
    let mut cloud = PointCloud::new();
    for i in -50..51 {
        for j in -50..51 {
            let mut rotated = point_on_surface;
            rotated.rotate_ip(0.0, deg2rad(f64::from(i) * 0.5), deg2rad(f64::from(j) * 0.5));
            cloud.push(rotated);
        }
    }
    let origin = Pose6D::from_euler(1.0, 0.0, -0.5, 0.0, 0.0, 0.0);
    let mut graph = graph::ScanGraph::new();
    graph.add_node(cloud.clone(), origin);

    // compare with the reference file
    {
        assert_eq!(graph.nodes.len(), reference_graph.nodes.len());
        let scan_node = &graph.nodes[0];
        let ref_scan_node = &reference_graph.nodes[0];
        assert_eq!(scan_node.id, ref_scan_node.id);
        compare_pose(&scan_node.pose, &ref_scan_node.pose);
        assert_eq!(scan_node.scan.len(), ref_scan_node.scan.len());
        for (a, b) in scan_node.scan.iter().zip(ref_scan_node.scan.iter()) {
            compare_point(*a, *b);
        }
    }

    // write and read back: exactly equal
    {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("spherical_scan_out.graph");
        graph::write_file(&graph, &path).expect("writeBinary");
        let bytes = std::fs::read(&path).unwrap();
        assert_octomap_file(
            &bytes,
            "spherical_scan_out.graph",
            "ea2094cac04d8642c4257f50fec6be55a96ba3d92a2cecef8d65c2bc9a553cbb",
        );
        let re_read_graph = graph::read_file(&path).expect("readBinary");
        assert_eq!(graph.nodes.len(), re_read_graph.nodes.len());
        assert_eq!(re_read_graph.nodes.len(), 1);
        let scan_node = &graph.nodes[0];
        let read_scan_node = &re_read_graph.nodes[0];
        assert_eq!(scan_node.id, read_scan_node.id);
        assert_eq!(scan_node.pose, read_scan_node.pose);
        assert_eq!(scan_node.scan.len(), read_scan_node.scan.len());
        for (a, b) in scan_node.scan.iter().zip(read_scan_node.scan.iter()) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }

    // insert into an OcTree, in global coordinates
    {
        let mut tree = OccupancyTree::new(0.05).unwrap();
        tree.insert_point_cloud(cloud.as_slice(), origin.trans(), &ScanOptions::default()).expect("scan inserted");
        let mut file = Vec::new();
        bt::write(&tree, &mut file).expect("writeBinary spherical_scan.bt");
        assert_octomap_file(
            &file,
            "spherical_scan.bt",
            "62a24e46ece667a54e18058d74c49c4f8ac6923acbaf77b8140b4f2d5321b853",
        );
        // OctoMap reports writing 21438 nodes (the maximum-likelihood, pruned tree)
        assert_eq!(bt::read(file.as_slice()).unwrap().size(), 21438);
    }
}
