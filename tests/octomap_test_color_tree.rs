//! Port of OctoMap's `octomap/src/testing/test_color_tree.cpp`.
//!
//! OctoMap colours the node pointer `updateNode` returns, which is what
//! `search` finds afterwards: octolinear's `set_color(key, ..)`. Its
//! node-level `deleteNodeChild`, `expandNode` and `pruneNode` are
//! reproduced with key-based calls leaving the same tree shape and node
//! counter (see the comments there). The colours and probabilities OctoMap
//! prints for its queries (Debian's liboctomap 1.9.7) are asserted.

mod octomap_port;

use octolinear::formats::ot;
use octolinear::sensor::probability;
use octolinear::tree::unpack_rgb;
use octolinear::{InnerNodes, NodeKind, OccupancyTree, Point3, SensorModel};
use octomap_port::{assert_octomap_file, child_key, expect_float_eq, node_at, trees_equal};

const UPDATE: InnerNodes = InnerNodes::Update;

#[test]
fn test_color_tree() {
    let res = 0.05;
    let mut tree = OccupancyTree::with_kind(res, SensorModel::default(), NodeKind::Color).unwrap();
    // occupied cells
    for x in -20i32..20 {
        for y in -20i32..20 {
            for z in -20i32..20 {
                let endpoint = Point3::new(x as f32 * 0.05 + 0.01, y as f32 * 0.05 + 0.01, z as f32 * 0.05 + 0.01);
                let key = tree.key(endpoint).unwrap();
                tree.update_occupancy(key, true, UPDATE);
                let rgb = [z * 5 + 100, x * 5 + 100, y * 5 + 100].map(|c| c as u8);
                tree.set_color(key, rgb).expect("updated node exists");
            }
        }
    }
    // free cells
    for x in -30i32..30 {
        for y in -30i32..30 {
            for z in -30i32..30 {
                let endpoint = Point3::new(x as f32 * 0.02 + 2.0, y as f32 * 0.02 + 2.0, z as f32 * 0.02 + 2.0);
                let key = tree.key(endpoint).unwrap();
                tree.update_occupancy(key, false, UPDATE);
                tree.set_color(key, [255, 255, 0]).expect("updated node exists");
                // yellow
            }
        }
    }

    // set inner node colours
    tree.update_inner_occupancy();

    // should already be pruned
    assert_eq!(tree.size(), tree.calc_num_nodes());
    let initial_size = tree.size();
    assert_eq!(initial_size, 1034);
    tree.prune();
    assert_eq!(tree.size(), tree.calc_num_nodes());
    assert_eq!(initial_size, tree.size());

    // write to / read from file
    let mut file = Vec::new();
    ot::write(&tree, &mut file).expect("write simple_color_tree.ot");
    assert_octomap_file(
        &file,
        "simple_color_tree.ot",
        "39aadfc869c91f2f92f72db3a22d527510a7b3c2c44261b45c8a60a217989b35",
    );
    let read_tree = ot::read(file.as_slice()).expect("AbstractOcTree::read");
    let read_color_tree = read_tree.into_occupancy().expect("an occupancy tree");
    assert_eq!(read_color_tree.kind(), tree.kind());
    expect_float_eq(read_color_tree.resolution(), tree.resolution());
    assert_eq!(read_color_tree.size(), tree.size());
    assert!(trees_equal(&tree, &read_color_tree));

    // queries
    for (query, rgb) in [(Point3::new(0.0, 0.0, 0.0), [175; 3]), (Point3::new(-1.0, -1.0, -1.0), [15; 3])] {
        let result = tree.search_point(query, 0).unwrap().expect("node found");
        let result2 = read_color_tree.search_point(query, 0).unwrap().expect("node found");
        assert_eq!(result.extra, result2.extra);
        assert_eq!(result.value, result2.value);
        assert_eq!(unpack_rgb(result.extra), rgb);
        expect_float_eq(probability(result.value.into()), 0.7);
    }
    let query = Point3::new(1.0, 1.0, 1.0);
    assert!(tree.search_point(query, 0).unwrap().is_none());
    assert!(read_color_tree.search_point(query, 0).unwrap().is_none());
    drop(read_color_tree);

    // pruning / expansion
    {
        assert_eq!(initial_size, tree.size());
        assert_eq!(initial_size, tree.calc_num_nodes());
        // already pruned during insertion
        tree.prune();
        assert_eq!(initial_size, tree.size());
        assert_eq!(initial_size, tree.calc_num_nodes());

        tree.expand().unwrap();
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), 89234);

        // pruned again: the initial size
        tree.prune();
        assert_eq!(initial_size, tree.size());
        assert_eq!(initial_size, tree.calc_num_nodes());
    }

    // delete / create some nodes
    {
        let initial_size = tree.size();
        assert_eq!(initial_size, tree.calc_num_nodes());

        let new_coord = Point3::new(-2.0, -2.0, -2.0);
        let new_key = tree.key(new_coord).unwrap();
        tree.update_occupancy(new_key, true, UPDATE);
        tree.set_color(new_key, [255, 0, 0]).expect("node exists");

        let inserted_size = tree.size();
        assert_eq!(inserted_size, initial_size + 6);
        assert_eq!(inserted_size, tree.calc_num_nodes());

        // the parent of the new node has only child 0
        let parent = tree.search(new_key, 15).expect("parent found");
        assert_eq!(parent.depth, 15);
        assert!(!parent.is_leaf);
        assert_eq!(node_at(&tree, new_key, 15).unwrap().child_mask(), 1);
        assert_eq!(child_key(new_key, 15, 0), new_key);
        let v0 = tree.search(new_key, 0).unwrap().value;

        // deleteNodeChild(parent, 0): the parent becomes a leaf keeping its
        // value (that of child 0). octolinear's delete would remove the
        // parent with its last child; instead children 1..7 get child 0's
        // value, which auto-prunes all eight into the parent.
        for pos in 1..8 {
            tree.set_value(child_key(new_key, 15, pos), v0, UPDATE);
        }
        let parent = tree.search(new_key, 15).unwrap();
        assert!(parent.is_leaf);
        assert_eq!(parent.value, v0);
        // OctoMap's parent keeps its colour, unset (white); the merge gave
        // it child 0's red
        assert_eq!(unpack_rgb(parent.extra), [255, 0, 0]);
        tree.set_color(new_key, [255, 255, 255]);
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size - 1);

        tree.prune();
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size - 1);

        // expandNode(parent): a deferred update of one child with the value
        // it inherits expands the parent and changes nothing else
        tree.set_value(new_key, v0, InnerNodes::Defer);
        assert_eq!(node_at(&tree, new_key, 15).unwrap().child_mask(), 0xff);
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size + 7);

        // pruneNode(parent) succeeds: the rest is pruned, so prune() merges
        // exactly this node
        tree.prune();
        let parent = tree.search(new_key, 15).unwrap();
        assert!(parent.is_leaf && parent.depth == 15);
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size - 1);

        let mut file = Vec::new();
        ot::write(&tree, &mut file).expect("write simple_color_tree_ed.ot");
        assert_octomap_file(
            &file,
            "simple_color_tree_ed.ot",
            "6bb348d48eb43d32debf733a0483927f37440edc09f3ab354bca3c2a6082a3c8",
        );
    }
}
