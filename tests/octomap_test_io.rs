//! Port of OctoMap's `octomap/src/testing/test_io.cpp`, run as its
//! CMakeLists does: `test_io share/data/geb079.bt`.
//!
//! Files go to memory. OctoMap's `operator==` is [`trees_equal`];
//! `setResolution` (which octolinear's trees do not offer) is done by
//! rewriting the `res` line of the tree's `.ot` image and reading it back.

mod octomap_port;

use octolinear::formats::ot::{AnyTree, TreeKind};
use octolinear::formats::{bt, format_double, ot};
use octolinear::tree::unpack_rgb;
use octolinear::{InnerNodes, NodeKind, OccupancyTree, Point3, SensorModel};
use octomap_port::{assert_octomap_file, input, trees_equal};
use std::io::BufReader;

/// SHA-256 of the `.bt` OctoMap writes for geb079 (and for its copy).
const TEST_IO_FILE_BT: &str = "7663c2466e2fe335a27d1d592f91766c8154511e63a9615aeecdad1defb04d3b";

fn write_bt(tree: &OccupancyTree) -> Vec<u8> {
    let mut file = Vec::new();
    bt::write(tree, &mut file).expect("writeBinary");
    file
}

fn write_ot(tree: &OccupancyTree) -> Vec<u8> {
    let mut file = Vec::new();
    ot::write(tree, &mut file).expect("write");
    file
}

/// `AbstractOcTree::read` of an occupancy tree.
fn read_ot(file: &[u8]) -> OccupancyTree {
    match ot::read(file).expect("AbstractOcTree::read") {
        AnyTree::Occupancy(t) => t,
        AnyTree::Counting(_) => panic!("read a CountingOcTree"),
    }
}

/// `tree` with its resolution set to `resolution` (`setResolution`).
fn with_resolution(tree: &OccupancyTree, resolution: f64) -> OccupancyTree {
    let text = write_ot(tree);
    let start = text.windows(5).position(|w| w == b"\nres ").expect("res line") + 1;
    let end = start + text[start..].iter().position(|&b| b == b'\n').unwrap();
    let mut patched = text[..start].to_vec();
    patched.extend_from_slice(format!("res {}", format_double(resolution)).as_bytes());
    patched.extend_from_slice(&text[end..]);
    let t = read_ot(&patched);
    assert_eq!(t.resolution(), resolution);
    t
}

/// Flips the occupancy of the voxel at `p` with one update (`updateNode`).
fn flip(tree: &mut OccupancyTree, p: Point3) {
    let occupied = matches!(tree.search_point(p, 0).unwrap(), Some(n) if tree.is_occupied(n.value));
    tree.update_point(p, !occupied, InnerNodes::Update).unwrap();
}

#[test]
fn empty_octree() {
    let empty_tree = OccupancyTree::new(0.999).unwrap();
    assert_eq!(empty_tree.size(), 0);
    let bt_file = write_bt(&empty_tree);
    let ot_file = write_ot(&empty_tree);
    assert_octomap_file(&bt_file, "empty.bt", "9d0ffa3c0b73ee8e27b8fea983971c5c3a00bff90dd8731e572c91f9070d8357");
    assert_octomap_file(&ot_file, "empty.ot", "0d3789d3a2cf06113ae038368723eadfe2be4fb694de8fffcf20ec0ea0d5cebd");

    // readBinary into an OcTree(0.2) takes the file's resolution
    let empty_read_tree = bt::read(bt_file.as_slice()).expect("readBinary");
    assert_eq!(empty_read_tree.size(), 0);
    assert!(trees_equal(&empty_tree, &empty_read_tree));

    let read_tree_ot = read_ot(&ot_file);
    assert_eq!(read_tree_ot.kind(), NodeKind::Plain);
    assert_eq!(read_tree_ot.size(), 0);
    assert!(trees_equal(&empty_tree, &read_tree_ot));
}

#[test]
fn reference_octree_from_file() {
    let filename = input("geb079.bt");
    let tree = bt::read(BufReader::new(std::fs::File::open(filename).unwrap())).expect("readBinary");
    assert_eq!(tree.size(), 532566);

    // copy constructor / assignment / ==
    let mut tree_copy = tree.clone();
    assert!(trees_equal(&tree, &tree_copy));
    assert_octomap_file(&write_bt(&tree_copy), "test_io_file_copy.bt", TEST_IO_FILE_BT);

    // a different resolution makes the trees differ; setting it back, equal again
    let doubled = with_resolution(&tree_copy, tree.resolution() * 2.0);
    assert!(!trees_equal(&tree, &doubled));
    let restored = with_resolution(&doubled, tree.resolution());
    assert!(trees_equal(&tree, &restored));

    // flip one value, trees must differ afterwards
    flip(&mut tree_copy, Point3::new(0.5, 0.5, 0.5));
    assert!(!trees_equal(&tree, &tree_copy));
    drop(tree_copy);

    // swap
    let empty_t = OccupancyTree::new(tree.resolution()).unwrap();
    let mut empty_sw = empty_t.clone();
    let mut other_sw = tree.clone();
    std::mem::swap(&mut empty_sw, &mut other_sw);
    assert!(!trees_equal(&empty_t, &empty_sw));
    assert!(trees_equal(&empty_sw, &tree));
    assert!(trees_equal(&other_sw, &empty_t));

    // write again to .bt, read and compare (the tree, read from a .bt, is
    // already what OctoMap's writeBinary turns it into)
    let bt_file = write_bt(&tree);
    assert_octomap_file(&bt_file, "test_io_file.bt", TEST_IO_FILE_BT);
    let read_tree_bt = bt::read(bt_file.as_slice()).expect("readBinary");
    assert!(trees_equal(&tree, &read_tree_bt));

    // write to .ot, read through AbstractOcTree
    let ot_file = write_ot(&tree);
    assert_octomap_file(
        &ot_file,
        "test_io_file.ot",
        "4eb7ecd8e3af243e0c9e03f97acb333a4ac635f55d4fbcf70ea7a351d860faee",
    );
    let mut read_tree_ot = read_ot(&ot_file);
    assert_eq!(read_tree_ot.kind(), NodeKind::Plain);
    assert!(trees_equal(&tree, &read_tree_ot));

    // sanity test for ==: flip one node, compare again
    flip(&mut read_tree_ot, Point3::new(0.1, 0.1, 0.1));
    assert!(!trees_equal(&tree, &read_tree_ot));
}

#[test]
fn color_octree() {
    let res = 0.02;
    let mut color_tree = OccupancyTree::with_kind(res, SensorModel::default(), NodeKind::Color).unwrap();
    assert_eq!(TreeKind::of(color_tree.kind()).id(), "ColorOcTree");
    let origin = Point3::new(0.0, 0.0, 0.0);
    let okey = color_tree.key(origin).unwrap();
    color_tree.update_occupancy(okey, true, InnerNodes::Update);
    let color_red = [255, 0, 0];
    color_tree.set_color(okey, color_red).expect("node exists"); // colorNode->setColor
    color_tree.set_color(okey, color_red).expect("node exists"); // setNodeColor
    let p = Point3::new(0.1, 0.1, 0.1);
    color_tree.update_point(p, true, InnerNodes::Update).unwrap();
    color_tree.set_color(color_tree.key(p).unwrap(), [0, 0, 255]).expect("node exists");

    let file = write_ot(&color_tree);
    assert_octomap_file(
        &file,
        "test_io_color_file.ot",
        "042f437fcff1ff9e81882ba75021e286e89b21ba8f3d906391d8ceb985d5cc97",
    );
    let read_tree = ot::read(file.as_slice()).expect("AbstractOcTree::read");
    assert_eq!(read_tree.kind(), TreeKind::of(color_tree.kind()));
    let read_color_tree = read_tree.into_occupancy().unwrap();
    assert_eq!(read_color_tree.kind(), NodeKind::Color);
    assert_eq!(read_color_tree.size(), 20); // "Done (20 nodes)"
    assert!(trees_equal(&color_tree, &read_color_tree));
    let color_node = color_tree.search(okey, 0).expect("node exists");
    assert_eq!(unpack_rgb(color_node.extra), color_red);
    assert_eq!(unpack_rgb(read_color_tree.search(okey, 0).unwrap().extra), color_red);
}

#[test]
fn stamped_octree() {
    let stamped_tree = OccupancyTree::with_kind(0.05, SensorModel::default(), NodeKind::Stamped).unwrap();
    assert_eq!(TreeKind::of(stamped_tree.kind()).id(), "OcTreeStamped");
    let file = write_ot(&stamped_tree);
    assert_octomap_file(
        &file,
        "test_io_stamped_file.ot",
        "cb1631ef6ffec40e1892aef075252e7b16102b0ba22dfeb4b71e5871af8f918b",
    );
    let read_tree = ot::read(file.as_slice()).expect("AbstractOcTree::read");
    assert_eq!(read_tree.kind(), TreeKind::OcTreeStamped);
    let read_stamped_tree = read_tree.into_occupancy().unwrap();
    assert_eq!(read_stamped_tree.kind(), NodeKind::Stamped);
    assert!(trees_equal(&stamped_tree, &read_stamped_tree));
}
