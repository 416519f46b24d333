//! Port of OctoMap's `octomap/src/testing/test_iterators.cpp`, run as its
//! CMakeLists does: `test_iterators share/data/geb079.bt` (max depth 16).
//!
//! OctoMap compares its iterators with a recursive walk computing centres
//! the old (deprecated) way; that walk is reproduced here over
//! [`octolinear::tree::NodeRef`]. The counts OctoMap prints for geb079
//! (from Debian's liboctomap 1.9.7) are asserted as well.

mod octomap_port;

use octolinear::formats::bt;
use octolinear::tree::{KeyBox, NodeRef};
use octolinear::{BoundsRule, InnerNodes, Key, OccupancyTree, Point3};
use octomap_port::{expect_near, input, node_id};
use std::collections::HashMap;
use std::io::BufReader;

const TREE_MAX_VAL: f64 = 32768.0;
const MAX_DEPTH: u8 = 16;

/// OctoMap's `OcTreeVolume`: a centre and an edge length.
type Volume = (Point3, f64);

fn compute_child_center(pos: usize, center_offset: f32, parent: Point3) -> Point3 {
    let axis = |bit: usize, c: f32| if pos & bit != 0 { c + center_offset } else { c - center_offset };
    Point3::new(axis(1, parent.x), axis(2, parent.y), axis(4, parent.z))
}

/// `getLeafNodesRecurs`: leaves (or nodes at `max_depth`) of the given
/// occupancy, in depth-first order.
#[allow(clippy::too_many_arguments)]
fn leaf_nodes_recurs(
    voxels: &mut Vec<Volume>,
    max_depth: u8,
    node: NodeRef<'_>,
    depth: u8,
    parent_center: Point3,
    tree_center: Point3,
    tree: &OccupancyTree,
    occupied: bool,
) {
    if depth > max_depth {
        return;
    }
    if node.has_children() && depth != max_depth {
        let center_offset = (f64::from(tree_center.x) / 2f64.powi(i32::from(depth) + 1)) as f32;
        for (pos, child) in node.children() {
            let search_center = compute_child_center(pos, center_offset, parent_center);
            leaf_nodes_recurs(voxels, max_depth, child, depth + 1, search_center, tree_center, tree, occupied);
        }
    } else if tree.is_occupied(node.value()) == occupied {
        let voxel_size = tree.resolution() * 2f64.powi(16 - i32::from(depth));
        voxels.push((parent_center - tree_center, voxel_size));
    }
}

/// `getVoxelsRecurs`: every node, children before their parent.
fn voxels_recurs(
    voxels: &mut Vec<Volume>,
    max_depth: u8,
    node: NodeRef<'_>,
    depth: u8,
    parent_center: Point3,
    tree_center: Point3,
    tree: &OccupancyTree,
) {
    if depth > max_depth {
        return;
    }
    if node.has_children() && depth != max_depth {
        let center_offset = f64::from(tree_center.x) / 2f64.powi(i32::from(depth) + 1);
        for (pos, child) in node.children() {
            let search_center = compute_child_center(pos, center_offset as f32, parent_center);
            voxels_recurs(voxels, max_depth, child, depth + 1, search_center, tree_center, tree);
        }
    }
    let voxel_size = tree.resolution() * 2f64.powi(16 - i32::from(depth));
    voxels.push((parent_center - tree_center, voxel_size));
}

/// `compareResults`: same length, centres within 5 mm, pairwise.
#[track_caller]
fn compare_results(list_iterator: &[Volume], list_depr: &[Volume]) {
    assert_eq!(list_iterator.len(), list_depr.len());
    for (a, b) in list_iterator.iter().zip(list_depr) {
        expect_near(a.0.x.into(), b.0.x.into(), 0.005);
        expect_near(a.0.y.into(), b.0.y.into(), 0.005);
        expect_near(a.0.z.into(), b.0.z.into(), 0.005);
        assert_eq!(a.1, b.1);
    }
}

/// OctoMap sorts both lists of all nodes before comparing (its predicate is
/// no strict order); here by size, then by the centre snapped to the
/// half-voxel grid, so rounding noise cannot reorder equal centres.
fn sort_volumes(list: &mut [Volume], resolution: f64) {
    let half = resolution / 2.0;
    let snap = |c: f32| (f64::from(c) / half).round() as i64;
    list.sort_by(|a, b| {
        a.1.total_cmp(&b.1)
            .then_with(|| [snap(a.0.x), snap(a.0.y), snap(a.0.z)].cmp(&[snap(b.0.x), snap(b.0.y), snap(b.0.z)]))
    });
}

fn point_box(tree: &OccupancyTree, min: Point3, max: Point3) -> KeyBox {
    KeyBox { min: tree.key(min).expect("bbx min in the map"), max: tree.key(max).expect("bbx max in the map") }
}

/// `boundingBoxTest`.
fn bounding_box_test(tree: &mut OccupancyTree) -> usize {
    // the complete tree as box: the same leaves as without a box
    let b = tree.bounds(BoundsRule::MinPlusSize);
    let bbx_min = Point3::new(b.min[0] as f32, b.min[1] as f32, b.min[2] as f32);
    let bbx_max = Point3::new(b.max[0] as f32, b.max[1] as f32, b.max[2] as f32);
    let full = point_box(tree, bbx_min, bbx_max);
    let mut it = tree.leaves(0);
    let mut it_bbx = tree.leaves_in_box(full, 0);
    loop {
        match (it.next(), it_bbx.next()) {
            (Some(a), Some(b)) => assert_eq!((a.key, a.depth, a.value), (b.key, b.depth, b.value)),
            (None, None) => break,
            (a, b) => panic!("leaf iterators end apart: {:?} / {:?}", a.map(|n| n.key), b.map(|n| n.key)),
        }
    }

    // an actual bounding box (OctoMap: only works properly on an expanded tree)
    tree.expand().unwrap();
    let bbx = point_box(tree, Point3::new(-1.0, -1.0, -1.0), Point3::new(3.0, 2.0, 1.0));
    let in_box = |k: Key| (0..3).all(|i| k.0[i] >= bbx.min.0[i] && k.0[i] <= bbx.max.0[i]);
    let mut bbx_voxels: HashMap<Key, f64> = HashMap::new();
    let mut count = 0;
    for leaf in tree.leaves_in_box(bbx, 0) {
        count += 1;
        // a leaf, existing in the tree as that very node
        assert!(leaf.is_leaf);
        let node = crate::octomap_port::node_at(tree, leaf.key, leaf.depth).expect("leaf exists");
        assert!(!node.has_children());
        assert_eq!(node_id(tree, leaf.key, 0), Some((leaf.depth, leaf.key)));
        assert!(in_box(leaf.key), "leaf {} outside the box", leaf.key);
        bbx_voxels.insert(leaf.key, leaf.size());
    }
    assert_eq!(bbx_voxels.len(), count);

    // compare with a manual check of all leaves
    for leaf in tree.leaves(0) {
        if in_box(leaf.key) {
            assert_eq!(bbx_voxels.get(&leaf.key), Some(&leaf.size()), "leaf {} missed by the box", leaf.key);
        }
    }
    count
}

#[test]
fn iterate_empty_tree() {
    let empty_tree = OccupancyTree::new(0.2).unwrap();
    assert_eq!(empty_tree.size(), 0);
    assert_eq!(empty_tree.calc_num_nodes(), 0);
    assert_eq!(empty_tree.nodes(MAX_DEPTH).count(), 0);
    assert_eq!(empty_tree.leaves(MAX_DEPTH).count(), 0);
    let b = point_box(&empty_tree, Point3::new(-0.1, -0.1, -0.1), Point3::new(0.1, 0.1, 0.1));
    assert_eq!(empty_tree.leaves_in_box(b, MAX_DEPTH).count(), 0);
    let b = KeyBox { min: Key::new(10, 10, 16), max: Key::new(10, 10, 18) };
    assert_eq!(empty_tree.leaves_in_box(b, MAX_DEPTH).count(), 0);

    let mut empty_tree = empty_tree;
    assert_eq!(bounding_box_test(&mut empty_tree), 0);
}

#[test]
fn iterate_geb079() {
    let path = input("geb079.bt");
    let mut tree = bt::read(BufReader::new(std::fs::File::open(path).unwrap())).expect("geb079.bt reads");
    assert!(tree.size() > 1);

    // number of leaves
    let num_leafs_recurs = tree.num_leaves();
    let num_leafs_it = tree.leaves(0).count();
    assert_eq!(num_leafs_it, num_leafs_recurs);
    assert_eq!(num_leafs_it, 428144);

    let tc = (TREE_MAX_VAL * tree.resolution()) as f32;
    let tree_center = Point3::new(tc, tc, tc);
    let root = tree.root().unwrap();

    // all occupied leaves
    let mut list_depr = Vec::new();
    leaf_nodes_recurs(&mut list_depr, MAX_DEPTH, root, 0, tree_center, tree_center, &tree, true);
    let list_iterator: Vec<Volume> =
        tree.leaves(MAX_DEPTH).filter(|n| tree.is_occupied(n.value)).map(|n| (n.center_point(), n.size())).collect();
    compare_results(&list_iterator, &list_depr);
    assert_eq!(list_iterator.len(), 143729);

    // all free leaves
    let list_iterator: Vec<Volume> =
        tree.leaves(MAX_DEPTH).filter(|n| !tree.is_occupied(n.value)).map(|n| (n.center_point(), n.size())).collect();
    let mut list_depr = Vec::new();
    leaf_nodes_recurs(&mut list_depr, MAX_DEPTH, root, 0, tree_center, tree_center, &tree, false);
    compare_results(&list_iterator, &list_depr);
    assert_eq!(list_iterator.len(), 284415);

    // all nodes
    let mut list_depr = Vec::new();
    voxels_recurs(&mut list_depr, MAX_DEPTH, root, 0, tree_center, tree_center, &tree);
    let mut list_iterator: Vec<Volume> = tree.nodes(MAX_DEPTH).map(|n| (n.center_point(), n.size())).collect();
    sort_volumes(&mut list_iterator, tree.resolution());
    sort_volumes(&mut list_depr, tree.resolution());
    compare_results(&list_iterator, &list_depr);
    assert_eq!(list_iterator.len(), 532566);

    // all leaves at max depth
    assert_eq!(tree.leaves(MAX_DEPTH).count(), 428144);

    // bounding boxes
    assert_eq!(bounding_box_test(&mut tree), 26915);
}

#[test]
fn iterate_tree_with_one_node() {
    let mut simple_tree = OccupancyTree::new(0.01).unwrap();
    let key = simple_tree.key(Point3::new(10.0, 10.0, 10.0)).unwrap();
    simple_tree.update(key, 5.0, InnerNodes::Update);
    let leaves: Vec<_> = simple_tree.leaves(MAX_DEPTH).collect();
    assert_eq!(leaves.len(), 1);
    assert_eq!((leaves[0].key, leaves[0].depth), (key, 16));
    for c in leaves[0].center() {
        expect_near(c, 10.005, 1e-6);
    }
    assert_eq!(leaves[0].value, simple_tree.sensor().clamping_max);
}
