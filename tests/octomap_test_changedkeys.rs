//! Port of OctoMap's `octomap/src/testing/test_changedkeys.cpp`.
//!
//! OctoMap's program only prints, after each step, how many changed keys
//! are occupied, free or missing from the (expanded) tree next to the
//! actual occupied and free leaves. Here those counts are asserted: the
//! values OctoMap prints (Debian's liboctomap 1.9.7), no key missing, and
//! the change set equal to the set of all voxels (change detection ran
//! since the tree was empty and nothing was deleted). When the OctoMap
//! oracle is available the same steps run through it and the change sets
//! and leaves must be identical.

mod octomap_port;

use octolinear::{InnerNodes, OccupancyTree, Point3, ScanOptions};
use octolinear_oracle::OracleTree;
use octomap_port::deg2rad;

#[derive(Debug, PartialEq, Eq)]
struct Changes {
    changed_occupied: usize,
    changed_free: usize,
    missing_changed: usize,
    actual_occupied: usize,
    actual_free: usize,
}

/// `printChanges`: expands the tree, classifies the changed keys and the
/// leaves, prunes again.
fn print_changes(tree: &mut OccupancyTree) -> Changes {
    let mut c =
        Changes { changed_occupied: 0, changed_free: 0, missing_changed: 0, actual_occupied: 0, actual_free: 0 };
    tree.expand().unwrap();
    for (key, _) in tree.changed_keys() {
        match tree.search(key, 0) {
            Some(node) if tree.is_occupied(node.value) => c.changed_occupied += 1,
            Some(_) => c.changed_free += 1,
            None => c.missing_changed += 1,
        }
    }
    for node in tree.nodes(0).filter(|n| n.is_leaf) {
        if tree.is_occupied(node.value) {
            c.actual_occupied += 1;
        } else {
            c.actual_free += 1;
        }
    }
    // every voxel ever created is recorded, and they are all there
    let mut voxels: Vec<_> = tree.leaves(0).map(|n| (n.depth, n.key)).collect();
    voxels.sort_unstable();
    let changed: Vec<_> = tree.changed_keys().into_iter().map(|(k, _)| (16, k)).collect();
    assert_eq!(voxels, changed);
    tree.prune();
    c
}

#[track_caller]
fn check(tree: &mut OccupancyTree, oracle: &mut Option<OracleTree>, occupied: usize, free: usize) {
    let c = print_changes(tree);
    let expected = Changes {
        changed_occupied: occupied,
        changed_free: free,
        missing_changed: 0,
        actual_occupied: occupied,
        actual_free: free,
    };
    assert_eq!(c, expected);
    if let Some(o) = oracle.as_mut() {
        o.expand();
        o.prune();
        let ours: Vec<_> = tree.changed_keys().into_iter().map(|(k, new)| (k.0, new)).collect();
        assert_eq!(ours, o.changed_keys());
        let leaves: Vec<_> = tree.leaves(0).map(|n| (n.key.0, n.depth, n.value)).collect();
        let theirs: Vec<_> = o.leaves(0).into_iter().map(|n| (n.key, n.depth, n.logodds)).collect();
        assert_eq!(leaves, theirs);
    }
}

#[test]
fn test_changedkeys() {
    let mut tree = OccupancyTree::new(0.05).unwrap();
    tree.set_change_detection(true);
    let mut oracle = octolinear_oracle::require_or_skip("test_changedkeys (oracle cross-check)")
        .then(|| OracleTree::new(0.05).expect("oracle tree"));
    if let Some(o) = oracle.as_mut() {
        o.enable_change_detection(true);
    }

    let origin = Point3::new(0.01, 0.01, 0.02);
    let point_on_surface = Point3::new(4.01, 0.01, 0.01);
    tree.insert_ray(origin, point_on_surface, None, InnerNodes::Update).expect("ray inserted");
    if let Some(o) = oracle.as_mut() {
        // insertPointCloudRays of one point is insertRay without a max range
        o.insert_point_cloud_rays(&[point_on_surface.to_array()], origin.to_array(), -1.0, false).unwrap();
    }
    check(&mut tree, &mut oracle, 1, 80);

    let p = Point3::new(2.01, 0.01, 0.01);
    tree.update(tree.key(p).unwrap(), 2.0, InnerNodes::Update);
    if let Some(o) = oracle.as_mut() {
        assert!(o.update_node_logodds(p.to_array(), 2.0, false));
    }
    check(&mut tree, &mut oracle, 2, 79);

    tree.update(tree.key(p).unwrap(), -2.0, InnerNodes::Update);
    if let Some(o) = oracle.as_mut() {
        assert!(o.update_node_logodds(p.to_array(), -2.0, false));
    }
    check(&mut tree, &mut oracle, 1, 80);

    // spherical scan
    for i in -100..101 {
        let cloud: Vec<Point3> = (-100..101)
            .map(|j| {
                let mut rotated = point_on_surface;
                rotated.rotate_ip(0.0, deg2rad(f64::from(i) * 0.5), deg2rad(f64::from(j) * 0.5));
                rotated
            })
            .collect();
        tree.insert_point_cloud(&cloud, origin, &ScanOptions::default()).expect("scan inserted");
        if let Some(o) = oracle.as_mut() {
            let pts: Vec<[f32; 3]> = cloud.iter().map(|p| p.to_array()).collect();
            o.insert_point_cloud(&pts, origin.to_array(), -1.0, false, false).unwrap();
        }
    }
    check(&mut tree, &mut oracle, 19386, 462595);
}
