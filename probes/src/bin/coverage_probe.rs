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
//! ray, and for cubes, also whether the whole cube was. `SCANS=N`: only
//! the first N scans. A probe.

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
    let tree = OccupancyTree::new(res).expect("resolution");
    let walks: Vec<Vec<Vec<Key>>> = scans
        .iter()
        .map(|(points, origin)| {
            points.iter().filter_map(|&p| tree.ray_keys(*origin, p).ok()).map(Iterator::collect).collect()
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
        let (mut stretches, mut boxed, mut skipped) = (0usize, 0usize, 0usize);
        let (mut whole, mut whole_steps) = (0usize, 0usize);
        for scan in &walks {
            let mut seen: HashSet<Key> = HashSet::new();
            for keys in scan {
                let mut i = 0;
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
             {whole} in a whole covered cube, holding {whole_steps} steps ({:.1}%)",
            100.0 * skipped as f64 / steps as f64,
            100.0 * whole_steps as f64 / steps as f64
        );
    }
}
