//! The arena's compaction policy: automatic compaction keeps free slots
//! under an eighth after every scan and never changes the tree.

use octolinear::formats::ot;
use octolinear::{Compaction, OccupancyTree, ScanOptions};
use octolinear_sim::{simulate, LidarConfig, SceneKind};

fn free_fraction(tree: &OccupancyTree) -> f64 {
    let u = tree.arena_usage().expect("not empty");
    u.free_slots as f64 / (u.live_slots + u.free_slots) as f64
}

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).unwrap();
    v
}

#[test]
fn automatic_compaction_bounds_free_slots_and_keeps_the_tree() {
    let cfg = LidarConfig::indoor();
    let g = simulate(SceneKind::Indoor, 24, 42, &cfg).unwrap();
    let mut auto = OccupancyTree::new(0.1).unwrap();
    let mut manual = OccupancyTree::new(0.1).unwrap();
    manual.set_compaction(Compaction::Manual);
    let mut manual_peak = 0f64;
    for node in &g.nodes {
        let (cloud, origin) = node.graph2tree();
        auto.insert_point_cloud(&cloud.points, origin, &ScanOptions::default()).unwrap();
        manual.insert_point_cloud(&cloud.points, origin, &ScanOptions::default()).unwrap();
        assert!(free_fraction(&auto) <= 0.125, "automatic: {:.3} of slots free", free_fraction(&auto));
        manual_peak = manual_peak.max(free_fraction(&manual));
    }
    // otherwise this test would not exercise a compaction
    assert!(manual_peak > 0.125, "manual peak free fraction only {manual_peak:.3}");
    assert_eq!(ot_bytes(&auto), ot_bytes(&manual));
    manual.compact();
    assert_eq!(free_fraction(&manual), 0.0);
    assert_eq!(ot_bytes(&auto), ot_bytes(&manual));
}
