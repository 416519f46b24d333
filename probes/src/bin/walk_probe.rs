//! What a scan's ray walks cost without the rest of insertion:
//! `cargo run --release -p octolinear-probes --bin walk_probe -- indoor|outdoor RES` sets up
//! every ray of the bench's scans (as `insert_point_cloud` does), then walks
//! them all, one at a time and two in lockstep, XOR-ing the voxel codes
//! (no key lists, no filter, no sort, no tree). Prints the ray set-up cost
//! per ray and the walk cost per step, and the cost per step of the whole
//! casting as insertion runs it (`compute_update`: on AVX-512 processors
//! the vector set-up and walk, with the scan's sets), against what one
//! double compare and one add that depends on it cost in a chain (a
//! step's least work, one after the other). A probe, not a benchmark of
//! record.

#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::internals::RayFan;
use octolinear::{MortonCode, OccupancyTree, ScanOptions};
use std::hint::black_box;
use std::time::Instant;

fn main() {
    let (_, res, scans) = common::scene_from_args();
    let tree = OccupancyTree::new(res).expect("resolution");
    let keys = tree.key_space();
    let best = |f: &dyn Fn() -> u64| {
        (0..7)
            .map(|_| {
                let t = Instant::now();
                black_box(f());
                t.elapsed().as_secs_f64()
            })
            .fold(f64::MAX, f64::min)
    };
    // into a vector that already has the room (its growth is not set-up)
    let set_up = |rays: &mut Vec<_>| {
        rays.clear();
        for (points, origin) in &scans {
            let fan = RayFan::new(keys, *origin).expect("origin in the map");
            for &p in points {
                let Ok(end) = keys.key(p) else { continue };
                rays.extend(fan.ray(p, MortonCode::encode(end).0));
            }
        }
    };
    let mut rays = Vec::new();
    set_up(&mut rays);
    let scratch = std::cell::RefCell::new(Vec::with_capacity(rays.len()));
    let setup = best(&|| {
        let mut v = scratch.borrow_mut();
        set_up(&mut v);
        v.len() as u64
    });
    let steps: u64 = rays
        .iter()
        .map(|r| {
            std::iter::from_fn({
                let (mut w, steps) = r.split();
                move || w.next_code(&steps)
            })
            .count() as u64
        })
        .sum();
    let one = best(&|| {
        let mut x = 0;
        for r in &rays {
            let (mut w, steps) = r.split();
            while let Some(c) = w.next_code(&steps) {
                x ^= c;
            }
        }
        x
    });
    let two = best(&|| {
        let mut x = 0;
        for pair in rays.chunks(2) {
            let (mut a, sa) = pair[0].split();
            let (mut b, sb) = pair[pair.len() - 1].split();
            let (mut a_done, mut b_done) = (false, pair.len() == 1);
            while !(a_done && b_done) {
                match a.next_code(&sa) {
                    Some(c) => x ^= c,
                    None => a_done = true,
                }
                match b.next_code(&sb) {
                    Some(c) => x ^= c,
                    None => b_done = true,
                }
            }
        }
        x
    });
    // the whole casting as insertion runs it (on AVX-512 processors the
    // vector set-up and walk): rays set up and walked, voxels gathered in
    // the scan's sets, and the sets read out in Morton order
    let opts = ScanOptions::default().with_threads(Some(1));
    let cast = best(&|| {
        let mut n = 0;
        for (points, origin) in &scans {
            let (update, _) = tree.compute_update(points, *origin, &opts).expect("scan");
            n += update.free.len() as u64;
        }
        n
    });
    let ns = |s: f64, n: u64| s * 1e9 / n as f64;
    println!(
        "casting as insertion does (compute_update, 1 thread): {:.2} ms ({:.2} ns a step, set-up and sets included)",
        cast * 1e3,
        ns(cast, steps)
    );
    println!(
        "{} rays, {steps} steps: set-up {:.2} ms ({:.1} ns a ray); walks one at a time {:.2} ms ({:.2} ns a step), \
         two in lockstep {:.2} ms ({:.2} ns a step)",
        rays.len(),
        setup * 1e3,
        ns(setup, rays.len() as u64),
        one * 1e3,
        ns(one, steps),
        two * 1e3,
        ns(two, steps)
    );
    println!("a dependent double compare and add, in a chain: {:.2} ns", common::dependent_step_ns());
}
