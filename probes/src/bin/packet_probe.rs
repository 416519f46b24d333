//! How much neighbouring rays repeat each other's voxels when walked in
//! packets: `cargo run --release -p octolinear-probes --bin packet_probe --
//! indoor|outdoor|FILE.graph RES`. Rays of each scan, in the scan's order,
//! go in packets of 1, 4, 8 and 16, each packet's rays stepped in lockstep
//! (as `arch::avx512` does with eight); per step a ray's voxel is counted
//! unless the ray before it in the packet enters the same voxel. Prints the
//! codes left for the scan's sets and the lane steps (lanes whose ray has
//! ended wait for the packet's last), both against the rays' steps; and of
//! the packets' steps, those where every lane's ray is alive and all enter
//! one voxel (*uniform*), and those before a packet's rays first part
//! (*in the common prefix*): what a walk stepping a whole packet as one
//! ray could save. A probe, not a benchmark of record.

#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::internals::RayFan;
use octolinear::{MortonCode, OccupancyTree};

fn main() {
    let (_, res, scans) = common::scene_from_args();
    let tree = OccupancyTree::new(res).expect("resolution");
    let keys = tree.key_space();
    for packet in [1usize, 4, 8, 16] {
        let (mut steps, mut lane_steps, mut kept) = (0u64, 0u64, 0u64);
        let (mut prefix_steps, mut uniform_steps, mut all_alive_steps) = (0u64, 0u64, 0u64);
        for (points, origin) in &scans {
            let fan = RayFan::new(keys, *origin).expect("origin in the map");
            let rays: Vec<_> =
                points.iter().filter_map(|&p| fan.ray(p, MortonCode::encode(keys.key(p).ok()?).0)).collect();
            for rays in rays.chunks(packet) {
                let mut walks: Vec<_> = rays.iter().map(|r| Some(r.split())).collect();
                let mut codes = vec![None; walks.len()];
                let mut in_prefix = true;
                while walks.iter().any(Option::is_some) {
                    for (walk, code) in walks.iter_mut().zip(&mut codes) {
                        *code = walk.as_mut().and_then(|(w, s)| w.next_code(s));
                        if code.is_none() {
                            *walk = None;
                        }
                    }
                    lane_steps += packet as u64;
                    let all_alive = codes.iter().all(Option::is_some) && codes.len() == packet;
                    let same = all_alive && codes.iter().all(|c| *c == codes[0]);
                    in_prefix &= same;
                    prefix_steps += u64::from(in_prefix);
                    uniform_steps += u64::from(same);
                    all_alive_steps += u64::from(all_alive);
                    for (i, code) in codes.iter().enumerate() {
                        if code.is_some() {
                            steps += 1;
                            kept += u64::from(i == 0 || codes[i - 1] != *code);
                        }
                    }
                }
            }
        }
        println!(
            "packets of {packet:2}: {steps} ray steps, {:.2} of them kept for the sets, {:.2}x as many lane steps",
            kept as f64 / steps as f64,
            lane_steps as f64 / steps as f64
        );
        let group_steps = lane_steps as f64 / packet as f64;
        println!(
            "  group steps {group_steps:.0}: in the common prefix {:.3}, uniform {:.3}, all alive {:.3}",
            prefix_steps as f64 / group_steps,
            uniform_steps as f64 / group_steps,
            all_alive_steps as f64 / group_steps
        );
    }
}
