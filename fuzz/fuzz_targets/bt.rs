//! Fuzz target: the `.bt` reader, with and without text header
//! (`cargo +nightly fuzz run bt`).
//!
//! [`check`] must never panic. A parse fails cleanly, or gives a tree that
//! survives what `octolinear info` and `convert` do to it and whose
//! rewrite (`writeBinaryConst`) reads back to the same bytes; its ROS
//! binary message is that file's node stream. Built without cargo-fuzz
//! this replays the files named on its command line; `tests/corruption.rs`
//! compiles it as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::{bt, ot, ros};
use octolinear::{BoundsRule, OccupancyTree};

#[cfg(fuzzing)]
libfuzzer_sys::fuzz_target!(|data: &[u8]| check(data));

#[cfg(not(fuzzing))]
#[allow(dead_code)]
fn main() {
    for path in std::env::args_os().skip(1) {
        check(&std::fs::read(&path).expect("readable input"));
    }
}

fn write_const(t: &OccupancyTree) -> Vec<u8> {
    let mut out = Vec::new();
    bt::write_const(t, &mut out).expect("writing to memory");
    out
}

pub fn check(data: &[u8]) {
    let Ok(tree) = bt::read(data) else { return };
    assert_eq!(tree.calc_num_nodes(), tree.size());
    let _ = (tree.bounds(BoundsRule::CenterHalfSize), tree.volume(), tree.memory_full_grid(BoundsRule::MinPlusSize));
    let _ = (tree.memory_usage(), tree.octomap_memory_usage());
    let leaves = tree.leaves(0).inspect(|l| assert!(l.depth <= 16)).count();
    assert_eq!(leaves, tree.num_leaves());

    let once = write_const(&tree);
    let back = bt::read(&once[..]).expect("a written .bt reads back");
    assert_eq!(back.size(), tree.size());
    assert_eq!(write_const(&back), once, "writeBinaryConst(read(x)) is not stable");

    let msg = ros::binary_map_to_msg(&tree);
    assert!(once.ends_with(&msg.data), "message data is the file's node stream");
    let from_msg = ros::msg_to_map(&msg).expect("a written message reads back").into_occupancy().unwrap();
    assert_eq!(write_const(&from_msg), once);

    // convert to .ot and back
    let mut full = Vec::new();
    ot::write(&tree, &mut full).expect("writing to memory");
    let again = ot::read(&full[..]).expect("a written .ot reads back").into_occupancy().unwrap();
    assert_eq!(write_const(&again), once);
}
