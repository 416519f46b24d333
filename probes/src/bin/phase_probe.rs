//! Where a scan sequence's insertion time goes, phase by phase, and what
//! that predicts for more threads: `cargo run --release -p
//! octolinear-probes --bin phase_probe -- indoor|outdoor|FILE.graph RES
//! [SCANS]`. Each scan is cast (`compute_update` on one thread: set-up,
//! walk, the scan's sets and their read-out) and applied (`apply_update`,
//! one thread) apart, timed in thread CPU time (less disturbed than wall
//! time on a shared machine); REPS=n gives the fastest of n runs per phase.
//! Then the same scans through `insert_point_clouds` on 1, 2, 4... threads
//! up to the processor count, in wall time, against the model. A probe,
//! not a benchmark of record.

#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::{InnerNodes, OccupancyTree, ScanOptions};
use std::time::Instant;

/// Codes from which a batch is shared by the threads (`tree::parallel`).
const SHARED_BATCH: usize = 1 << 18;

fn main() {
    let (_, res, mut scans) = common::scene_from_args();
    if let Some(n) = std::env::args().nth(3) {
        scans.truncate(n.parse().expect("SCANS"));
    }
    let reps: usize = std::env::var("REPS").map_or(3, |s| s.parse().expect("REPS"));
    let one = ScanOptions { threads: Some(1), ..ScanOptions::default() };
    // per scan, the fastest of the runs: casting, applying
    let mut cast = vec![f64::MAX; scans.len()];
    let mut apply = vec![f64::MAX; scans.len()];
    // per scan, the share of its codes in batches the threads share
    let mut shared = vec![0.0; scans.len()];
    for _ in 0..reps {
        let mut tree = OccupancyTree::new(res).expect("resolution");
        for (i, (points, origin)) in scans.iter().enumerate() {
            let t = thread_cpu();
            let (update, report) = tree.compute_update(points, *origin, &one).expect("scan");
            cast[i] = cast[i].min(thread_cpu() - t);
            let t = thread_cpu();
            tree.apply_update(&update, report, InnerNodes::Update);
            apply[i] = apply[i].min(thread_cpu() - t);
            let large = [&update.free, &update.occupied].into_iter().map(Vec::len).filter(|&n| n >= SHARED_BATCH);
            shared[i] = large.sum::<usize>() as f64 / update.len().max(1) as f64;
        }
    }
    let (c, a): (f64, f64) = (cast.iter().sum(), apply.iter().sum());
    let a_shared: f64 = apply.iter().zip(&shared).map(|(t, f)| t * f).sum();
    println!(
        "{} scans, thread CPU, fastest of {reps} per phase: casting {:.1} ms ({:.0}%), tree update {:.1} ms \
         ({:.0}%; {:.0}% of it in batches of {SHARED_BATCH}+ codes, which the threads share)",
        scans.len(),
        c * 1e3,
        100.0 * c / (c + a),
        a * 1e3,
        100.0 * a / (c + a),
        100.0 * a_shared / a
    );
    // the pipeline: scans are cast in parallel and their updates applied in
    // order, one at a time (shared batches by all threads, at a sixth more
    // CPU: `docs/benchmarks.md`), so once the casting is spread thin enough
    // the chain of updates after the first scan's casting bounds the time
    let bound = |threads: f64| {
        let spread = cast[0] + (c - cast[0] + a) / threads;
        let chain = cast[0] + (a - a_shared) + a_shared * if threads > 1.0 { 7.0 / 6.0 / threads } else { 1.0 };
        spread.max(chain)
    };
    println!("| threads | model (ms) | measured wall (ms) |");
    println!("| ---: | ---: | ---: |");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    for threads in [1, 2, 4, 8, 16] {
        let measured = if threads <= cores {
            let opts = ScanOptions { threads: Some(threads), ..ScanOptions::default() };
            let best = (0..reps)
                .map(|_| {
                    let mut tree = OccupancyTree::new(res).expect("resolution");
                    let t = Instant::now();
                    let input = scans.iter().map(|(p, o)| (p.as_slice(), *o));
                    tree.insert_point_clouds(input, &opts, |_, _| {}).expect("insert");
                    t.elapsed().as_secs_f64()
                })
                .fold(f64::MAX, f64::min);
            format!("{:.1}", best * 1e3)
        } else {
            "-".into()
        };
        println!("| {threads} | {:.1} | {measured} |", bound(threads as f64) * 1e3);
    }
}

/// CPU time of the calling thread, in seconds.
fn thread_cpu() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec for the call.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
