//! How much of a scan's ray walking revisits voxels: `cargo run --release -p
//! octolinear-probes --bin coverage_probe -- indoor|outdoor RES` walks the bench's scans'
//! rays in order with `RayKeys` and counts, per ray, the steps before its
//! first voxel that no earlier ray of the same scan visited: the most an
//! exact "skip what is already covered" scheme could leave out.
//!
//! Then what an exact skip through boxes could leave out: a stretch of a
//! ray may be skipped without walking it when the whole box between its
//! first and last voxel is covered (the walk is monotone per axis, so it
//! stays inside that box). Stretches are the voxels a ray visits in one
//! aligned cube of 2, 4 or 8 voxels a side, or runs of 4, 8 or 16 steps
//! from its start; a stretch counts when its box was covered before the
//! ray, and for cubes, also whether the whole cube was; and how many steps
//! lie before a ray's first stretch without a covered box (what skipping
//! the start of each ray could leave out). `SCANS=N`: only the first N
//! scans. `ORDER=levels`: each scan's rays in parts of 64 points taken
//! coarse to fine (part 0, then every 2^k-th part from the largest k down),
//! so that a lidar's columns come after the columns on both sides of them.
//! A probe.

#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::{Key, OccupancyTree};
use std::collections::HashSet;

/// How a ray's voxels are cut into stretches.
#[derive(Clone, Copy)]
enum Stretch {
    /// The voxels in one aligned cube of `1 << shift` a side.
    Cube(u32),
    /// Runs of this many steps.
    Steps(usize),
}

fn main() {
    let (_, res, mut scans) = common::scene_from_args();
    // SCANS=N: only the first N scans (full-size sequences take long)
    if let Some(n) = std::env::var("SCANS").ok().and_then(|s| s.parse().ok()) {
        scans.truncate(n);
    }
    let levels = std::env::var("ORDER").is_ok_and(|o| o == "levels");
    let tree = OccupancyTree::new(res).expect("resolution");
    let walks: Vec<Vec<Vec<Key>>> = scans
        .iter()
        .map(|(points, origin)| {
            let parts: Vec<&[octolinear::Point3]> = points.chunks(64).collect();
            let order: Vec<usize> = if levels { level_order(parts.len()) } else { (0..parts.len()).collect() };
            order
                .iter()
                .flat_map(|&k| parts[k])
                .filter_map(|&p| tree.ray_keys(*origin, p).ok())
                .map(Iterator::collect)
                .collect()
        })
        .collect();
    let (mut rays, mut steps, mut covered) = (0usize, 0usize, 0usize);
    for scan in &walks {
        let mut seen: HashSet<Key> = HashSet::new();
        for keys in scan {
            rays += 1;
            steps += keys.len();
            covered += keys.iter().position(|k| !seen.contains(k)).unwrap_or(keys.len());
            seen.extend(keys.iter().copied());
        }
    }
    println!(
        "{rays} rays, {steps} steps; before each ray's first new voxel: {covered} steps ({:.1}%)",
        100.0 * covered as f64 / steps as f64
    );
    for stretch in
        [Stretch::Cube(1), Stretch::Cube(2), Stretch::Cube(3), Stretch::Steps(4), Stretch::Steps(8), Stretch::Steps(16)]
    {
        let (mut stretches, mut boxed, mut skipped, mut before) = (0usize, 0usize, 0usize, 0usize);
        let (mut whole, mut whole_steps) = (0usize, 0usize);
        for scan in &walks {
            let mut seen: HashSet<Key> = HashSet::new();
            for keys in scan {
                let mut i = 0;
                let mut leading = true;
                while i < keys.len() {
                    let j = match stretch {
                        Stretch::Cube(shift) => {
                            let cube = keys[i].0.map(|v| v >> shift);
                            i + keys[i..].iter().take_while(|k| k.0.map(|v| v >> shift) == cube).count()
                        }
                        Stretch::Steps(n) => (i + n).min(keys.len()),
                    };
                    stretches += 1;
                    let lo: [u16; 3] = std::array::from_fn(|a| keys[i..j].iter().map(|k| k.0[a]).min().unwrap_or(0));
                    let hi: [u16; 3] = std::array::from_fn(|a| keys[i..j].iter().map(|k| k.0[a]).max().unwrap_or(0));
                    let inside = (lo[0]..=hi[0])
                        .all(|x| (lo[1]..=hi[1]).all(|y| (lo[2]..=hi[2]).all(|z| seen.contains(&Key([x, y, z])))));
                    leading &= inside;
                    if leading {
                        before += j - i;
                    }
                    if inside {
                        boxed += 1;
                        skipped += j - i;
                        if let Stretch::Cube(shift) = stretch {
                            let side = 1u16 << shift;
                            let base = keys[i].0.map(|v| v >> shift << shift);
                            let full = (0..side).all(|x| {
                                (0..side).all(|y| {
                                    (0..side).all(|z| seen.contains(&Key([base[0] + x, base[1] + y, base[2] + z])))
                                })
                            });
                            if full {
                                whole += 1;
                                whole_steps += j - i;
                            }
                        }
                    }
                    i = j;
                }
                seen.extend(keys.iter().copied());
            }
        }
        let name = match stretch {
            Stretch::Cube(shift) => format!("voxels in one cube of {} a side", 1 << shift),
            Stretch::Steps(n) => format!("runs of {n} steps"),
        };
        println!(
            "stretches of {name}: {stretches}, {boxed} with a covered box, holding {skipped} steps ({:.1}%); \
             {whole} in a whole covered cube, holding {whole_steps} steps ({:.1}%); \
             before a ray's first stretch without one: {before} steps ({:.1}%)",
            100.0 * skipped as f64 / steps as f64,
            100.0 * whole_steps as f64 / steps as f64,
            100.0 * before as f64 / steps as f64
        );
    }
}

/// The parts `0..n` coarse to fine: 0, then every 2^k-th part from the
/// largest `k` down.
fn level_order(n: usize) -> Vec<usize> {
    let levels = n.next_power_of_two().trailing_zeros();
    (0..n.min(1)).chain((0..levels).rev().flat_map(|k| ((1usize << k)..n).step_by(2 << k))).collect()
}
