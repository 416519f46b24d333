//! Port of OctoMap's `octomap/src/testing/test_pruning.cpp`.
//!
//! OctoMap compares node pointers; here a node is identified by the depth
//! and centre key of what `search` finds ([`node_id`]). OctoMap's
//! node-level editing (`createNodeChild`, `deleteNodeChild`, `expandNode`,
//! `pruneNode`) has no counterpart in octolinear's key-based API; each step
//! is reproduced by key-based calls that leave the same tree and the same
//! node counter behind (see the comments at each step).

mod octomap_port;

use octolinear::formats::ot;
use octolinear::{InnerNodes, Key, OccupancyTree, Point3};
use octomap_port::{assert_octomap_file, child_key, float_steps, node_at, node_id};

const UPDATE: InnerNodes = InnerNodes::Update;

/// `key[2]`, `key[1]`, `key[0]` each from `center - 1` to `center + 1`.
fn neighbourhood(center: Key) -> Vec<Key> {
    let mut keys = Vec::new();
    for dz in -1i32..=1 {
        for dy in -1i32..=1 {
            for dx in -1i32..=1 {
                let k = center.0;
                keys.push(Key::new(
                    (i32::from(k[0]) + dx) as u16,
                    (i32::from(k[1]) + dy) as u16,
                    (i32::from(k[2]) + dz) as u16,
                ));
            }
        }
    }
    keys
}

/// Only `present` keys of the neighbourhood of `center` exist, each as its
/// own voxel.
#[track_caller]
fn check_neighbourhood(tree: &OccupancyTree, center: Key, present: &[Key]) {
    for key in neighbourhood(center) {
        if present.contains(&key) {
            assert_eq!(node_id(tree, key, 0), Some((16, key)), "voxel {key} exists");
        } else {
            assert_eq!(tree.search(key, 0), None, "voxel {key} does not exist");
        }
    }
}

#[track_caller]
fn check_cube_occupied(tree: &OccupancyTree, res: f32) {
    let steps = float_steps(0.005, 0.32, res);
    for &x in &steps {
        for &y in &steps {
            for &z in &steps {
                let node = tree.search_point(Point3::new(x, y, z), 0).unwrap().expect("node exists");
                assert!(tree.is_occupied(node.value));
            }
        }
    }
}

#[test]
fn test_pruning() {
    let res = 0.01f32;
    let mut tree = OccupancyTree::new(res.into()).unwrap();

    assert_eq!(tree.size(), 0);
    tree.prune();
    assert_eq!(tree.size(), 0);

    let single_pt = Point3::new(-0.05, -0.02, 1.0);
    let single_key = tree.key(single_pt).unwrap();
    tree.update_occupancy(single_key, true, UPDATE);
    assert_eq!(node_id(&tree, single_key, 0), Some((16, single_key)));
    assert_eq!(node_id(&tree, tree.key(single_pt).unwrap(), 0), Some((16, single_key)));

    // check all neighbours, none should exist; pruning should do nothing
    check_neighbourhood(&tree, single_key, &[single_key]);
    tree.prune();
    check_neighbourhood(&tree, single_key, &[single_key]);
    // node + 1 branch of depth 16
    assert_eq!(tree.calc_num_nodes(), tree.size());
    assert_eq!(tree.size(), 17);

    // create diagonal neighbour in the same parent node
    let mut single_key2 = single_key;
    for k in &mut single_key2.0 {
        *k += 1;
    }
    tree.update_occupancy(single_key2, true, UPDATE);
    check_neighbourhood(&tree, single_key, &[single_key, single_key2]);
    assert_eq!(tree.calc_num_nodes(), tree.size());
    assert_eq!(tree.size(), 18); // one more leaf at the lowest level
    tree.prune();
    check_neighbourhood(&tree, single_key, &[single_key, single_key2]);
    assert_eq!(tree.calc_num_nodes(), tree.size());
    assert_eq!(tree.size(), 18);

    // fill the complete octant, should auto-prune
    let k = single_key.0;
    for (dx, dy, dz) in [(1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1)] {
        tree.update_occupancy(Key::new(k[0] + dx, k[1] + dy, k[2] + dz), true, UPDATE);
    }
    assert_eq!(tree.size(), 23);
    // the last node triggers auto-pruning
    let pruned_value = tree.update_occupancy(Key::new(k[0], k[1] + 1, k[2] + 1), true, UPDATE);
    assert_eq!(tree.size(), 16);
    // all queries now end at the same parent node
    let parent = node_id(&tree, single_key, 0).unwrap();
    assert_eq!(parent.0, 15);
    assert_eq!(node_id(&tree, single_key2, 0), Some(parent));
    // what updateNode returned is that (pruned) parent
    assert_eq!(tree.search(single_key, 0).unwrap().value, pruned_value);

    // larger volume pruning
    let steps = float_steps(0.005, 0.32, res);
    for &x in &steps {
        for &y in &steps {
            for &z in &steps {
                let value = tree.update_point(Point3::new(x, y, z), true, UPDATE).expect("in the map");
                assert!(tree.is_occupied(value));
            }
        }
    }
    assert_eq!(tree.calc_num_nodes(), tree.size());
    assert_eq!(tree.size(), 27);
    tree.prune();
    assert_eq!(tree.calc_num_nodes(), tree.size());
    assert_eq!(tree.size(), 27);
    tree.expand().unwrap();
    assert_eq!(tree.calc_num_nodes(), tree.size());
    assert_eq!(tree.size(), 37483);
    tree.prune();
    assert_eq!(tree.size(), 27);
    // test expansion
    check_cube_occupied(&tree, res);

    let single_key = tree.key(Point3::new(0.1, 0.1, 0.1)).unwrap();
    tree.update_occupancy(single_key, true, UPDATE);
    check_cube_occupied(&tree, res);
    assert_eq!(tree.calc_num_nodes(), tree.size());
    assert_eq!(tree.size(), 67);

    // deletion / pruning of single nodes
    {
        let initial_size = tree.size();
        assert_eq!(initial_size, tree.calc_num_nodes());
        assert_eq!(initial_size, 67);

        let new_coord = Point3::new(-2.0, -2.0, -2.0);
        let new_key = tree.key(new_coord).unwrap();
        tree.update_point(new_coord, true, UPDATE).unwrap();
        let inserted_size = tree.size();
        assert_eq!(inserted_size, tree.calc_num_nodes());
        assert_eq!(inserted_size, 83);

        // the parent of the newly inserted node has only child 7
        let parent = tree.search(new_key, 15).expect("parent found");
        assert_eq!(parent.depth, 15);
        assert!(!parent.is_leaf);
        assert_eq!(node_at(&tree, new_key, 15).unwrap().child_mask(), 1 << 7);
        let child7 = child_key(new_key, 15, 7);
        assert_eq!(child7, new_key);
        let v7 = tree.search(child7, 0).unwrap().value;

        // createNodeChild(parent, 0) + setValue(0.123): a deferred set_value
        // creates the voxel without touching the parent
        let child0 = child_key(new_key, 15, 0);
        tree.set_value(child0, 0.123, InnerNodes::Defer);
        assert_eq!(node_at(&tree, new_key, 15).unwrap().child_mask(), 1 | 1 << 7);
        assert_eq!(tree.search(child0, 0).unwrap().value, 0.123);
        let mut file = Vec::new();
        ot::write(&tree, &mut file).expect("write pruning_test_edited.ot");
        assert_octomap_file(
            &file,
            "pruning_test_edited.ot",
            "45af668d97c194c54b72dc461a1435fea09a2f755a21c83c9ac27ddb1f496ac9",
        );
        // the header's `res` is printed with 6 digits, so only the nodes
        // round-trip (OctoMap's own reader gives res 0.01, not 0.01f)
        let read = ot::read(file.as_slice()).unwrap().into_occupancy().unwrap();
        assert_eq!(read.resolution(), 0.01);
        assert!(read.nodes(0).map(|n| (n.key, n.depth, n.value)).eq(tree.nodes(0).map(|n| (n.key, n.depth, n.value))));

        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size + 1);
        tree.prune();
        assert_eq!(tree.calc_num_nodes(), inserted_size + 1);

        // deleteNodeChild(parent, 0); deleteNodeChild(parent, 7): the parent
        // becomes a leaf keeping its value (that of child 7). octolinear's
        // delete removes a parent losing its last child, so: delete child 0,
        // then give children 0..6 child 7's value, which auto-prunes them
        // into the parent.
        assert!(!tree.delete(child0, 0));
        assert_eq!(tree.size(), inserted_size);
        for pos in 0..7 {
            tree.set_value(child_key(new_key, 15, pos), v7, UPDATE);
        }
        let parent = tree.search(new_key, 15).unwrap();
        assert!(parent.is_leaf);
        assert_eq!(parent.value, v7);
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size - 1);

        tree.prune();
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size - 1);

        // expandNode(parent): a deferred update of one child with the value
        // it inherits expands the pruned parent and changes nothing else
        tree.set_value(child0, v7, InnerNodes::Defer);
        assert_eq!(node_at(&tree, new_key, 15).unwrap().child_mask(), 0xff);
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size + 7);

        // pruneNode(parent) succeeds: the rest of the tree is pruned, so
        // prune() merges exactly this node
        tree.prune();
        let parent = tree.search(new_key, 15).unwrap();
        assert!(parent.is_leaf && parent.depth == 15);
        assert_eq!(tree.size(), tree.calc_num_nodes());
        assert_eq!(tree.size(), inserted_size - 1);
    }

    let mut file = Vec::new();
    ot::write(&tree, &mut file).expect("write pruning_test_out.ot");
    // (OctoMap overwrites this file at the end; its digest here is from a
    // run writing it under another name)
    assert_octomap_file(
        &file,
        "pruning_test_out.ot (first)",
        "2a8b154565643291dac6290f94acaaae376a176f0fdaa15f53cb5889d7eaf568",
    );

    // clearing tree / recursive delete
    {
        let mut empty_tree = OccupancyTree::new(0.1234).unwrap();
        assert_eq!(empty_tree.size(), 0);
        empty_tree.clear();
        assert_eq!(empty_tree.size(), empty_tree.calc_num_nodes());
        assert_eq!(empty_tree.size(), 0);

        tree.clear();
        assert_eq!(tree.size(), 0);
        assert_eq!(tree.size(), tree.calc_num_nodes());

        tree.prune();
        assert_eq!(tree.size(), 0);
    }

    let mut file = Vec::new();
    ot::write(&tree, &mut file).expect("write pruning_test_out.ot");
    assert_octomap_file(
        &file,
        "pruning_test_out.ot",
        "d4095e1a6ae7f2b8a22d14aa940ba3b4238c55b6817bf2e198c9e094385022d1",
    );
    let read = ot::read(file.as_slice()).unwrap().into_occupancy().unwrap();
    assert_eq!(read.size(), 0);
}
