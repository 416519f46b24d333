//! Fuzz target: the `.ot` reader (`cargo +nightly fuzz run ot`).
//!
//! [`check`] must never panic. A parse fails cleanly, or gives a tree that
//! survives what `octolinear info` and `convert` do to it, writes back to a
//! file that reads to the same bytes again, and travels through a ROS
//! message unchanged. Built without cargo-fuzz this is a program that
//! replays the files named on its command line; `tests/corruption.rs`
//! compiles it as a module and runs `check` on its mutants.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::ot::{self, AnyTree};
use octolinear::formats::{bt, ros};
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

fn write(tree: &AnyTree) -> Vec<u8> {
    let mut out = Vec::new();
    match tree {
        AnyTree::Occupancy(t) => ot::write(t, &mut out),
        AnyTree::Counting(c) => ot::write_counting(c, &mut out),
    }
    .expect("writing to memory");
    out
}

/// What `info` computes, then a `.bt` conversion that must read back.
pub fn exercise(t: &OccupancyTree) {
    assert_eq!(t.calc_num_nodes(), t.size());
    let _ = (t.bounds(BoundsRule::CenterHalfSize), t.volume(), t.memory_full_grid(BoundsRule::MinPlusSize));
    let _ = (t.memory_usage(), t.octomap_memory_usage());
    let mut per_depth = [0usize; 17];
    for leaf in t.leaves(0) {
        per_depth[leaf.depth as usize] += 1;
        let _ = (leaf.size().powi(3), t.is_occupied(leaf.value));
    }
    assert_eq!(per_depth.iter().sum::<usize>(), t.num_leaves());
    let mut binary = Vec::new();
    bt::write(t, &mut binary).expect("writing to memory");
    let back = bt::read(&binary[..]).expect("a written .bt reads back");
    assert!(back.size() <= t.size());
}

pub fn check(data: &[u8]) {
    let Ok(tree) = ot::read(data) else { return };
    let once = write(&tree);
    let twice = write(&ot::read(&once[..]).expect("a written .ot reads back"));
    assert_eq!(once, twice, "write(read(write(read(x)))) differs from write(read(x))");
    let msg = match &tree {
        AnyTree::Occupancy(t) => {
            exercise(t);
            ros::full_map_to_msg(t)
        }
        AnyTree::Counting(c) => ros::full_counting_map_to_msg(c),
    };
    assert!(once.ends_with(&msg.data), "message data is the file's node stream");
    let from_msg = ros::msg_to_map(&msg).expect("a written message reads back");
    assert_eq!(write(&from_msg), once);
}
