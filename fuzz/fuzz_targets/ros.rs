//! Fuzz target: ROS `octomap_msgs/Octomap` payloads
//! (`cargo +nightly fuzz run ros`).
//!
//! The first input byte picks the `binary` flag (bit 0), the `id` (bits
//! 1..4) and the resolution (bits 4..7); the rest is `data`. [`check`] must
//! never panic; a map read converts back to a message with the same `data`
//! (full messages) or to one that is stable from then on (binary messages).
//! Built without cargo-fuzz this replays the files named on its command
//! line; `tests/corruption.rs` compiles it as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::ot::AnyTree;
use octolinear::formats::ros::{self, OctomapMsg};

#[cfg(fuzzing)]
libfuzzer_sys::fuzz_target!(|data: &[u8]| check(data));

#[cfg(not(fuzzing))]
#[allow(dead_code)]
fn main() {
    for path in std::env::args_os().skip(1) {
        check(&std::fs::read(&path).expect("readable input"));
    }
}

pub const IDS: [&str; 8] = ["OcTree", "ColorOcTree", "OcTreeStamped", "OcTreeBase", "1", "", "CountingOcTree", "x\0y"];
pub const RESOLUTIONS: [f64; 8] = [0.1, 0.05, 0.08, 1e-300, 1e308, 0.0, -1.0, f64::NAN];

/// The message an input encodes.
pub fn message(data: &[u8]) -> Option<OctomapMsg> {
    let (&sel, rest) = data.split_first()?;
    Some(OctomapMsg {
        binary: sel & 1 != 0,
        id: IDS[(sel >> 1) as usize & 7].to_string(),
        resolution: RESOLUTIONS[(sel >> 4) as usize & 7],
        data: rest.to_vec(),
    })
}

fn to_msg(tree: &AnyTree, binary: bool) -> OctomapMsg {
    match tree {
        AnyTree::Occupancy(t) if binary => ros::binary_map_to_msg(t),
        AnyTree::Occupancy(t) => ros::full_map_to_msg(t),
        AnyTree::Counting(c) => ros::full_counting_map_to_msg(c),
    }
}

pub fn check(data: &[u8]) {
    let Some(msg) = message(data) else { return };
    let Ok(tree) = ros::msg_to_map(&msg) else { return };
    let once = to_msg(&tree, msg.binary);
    if !msg.binary {
        assert_eq!(once.data, msg.data, "a full message converts back to itself");
    }
    let again = ros::msg_to_map(&once).expect("a written message reads back");
    assert_eq!(to_msg(&again, msg.binary), once);
    let compact = match &tree {
        AnyTree::Occupancy(t) => ros::binary_map_to_msg_compact(t),
        AnyTree::Counting(_) => return,
    };
    ros::msg_to_map(&compact).expect("a compact message reads back");
}
