//! How much of a scan's ray walking revisits voxels: `cargo run --release
//! --example coverage_probe -- indoor|outdoor RES` walks the bench's scans'
//! rays in order with `RayKeys` and counts, per ray, the steps before its
//! first voxel that no earlier ray of the same scan visited: the most an
//! exact "skip what is already covered" scheme could leave out. A probe.

#[path = "../benches/common/mod.rs"]
mod common;

use octolinear::{Key, OccupancyTree};
use std::collections::HashSet;

fn main() {
    let (_, res, scans) = common::scene_from_args();
    let tree = OccupancyTree::new(res).expect("resolution");
    let (mut rays, mut steps, mut covered) = (0usize, 0usize, 0usize);
    for (points, origin) in &scans {
        let mut seen: HashSet<Key> = HashSet::new();
        for &p in points {
            let Ok(walk) = tree.ray_keys(*origin, p) else { continue };
            let keys: Vec<Key> = walk.collect();
            rays += 1;
            steps += keys.len();
            covered += keys.iter().position(|k| !seen.contains(k)).unwrap_or(keys.len());
            seen.extend(keys);
        }
    }
    println!(
        "{rays} rays, {steps} steps; before each ray's first new voxel: {covered} steps ({:.1}%)",
        100.0 * covered as f64 / steps as f64
    );
}
