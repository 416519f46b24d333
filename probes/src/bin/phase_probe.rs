//! Where a scan sequence's insertion time goes, phase by phase, and what
//! that predicts for more threads: `cargo run --release -p
//! octolinear-probes --bin phase_probe -- indoor|outdoor|FILE.graph RES
//! [SCANS]`. Each scan is cast (`compute_update` on one thread: set-up,
//! walk, the scan's sets and their read-out) and applied (`apply_update`,
//! one thread) apart, timed in thread CPU time (less disturbed than wall
//! time on a shared machine); REPS=n gives the fastest of n runs per phase.
//! The batches large enough to be shared by the threads are also applied
//! to copies of the tree shared on pools of one and two threads (wall
//! time), which gives the model their serial and parallel parts. Then the
//! same scans through `insert_point_clouds` on 1, 2, 4... threads up to
//! the processor count, in wall time, against the model. A probe, not a
//! benchmark of record.

#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::internals::TreeInternals;
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
    let one = ScanOptions::default().with_threads(Some(1));
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
    let (serial, one_thread, two_threads) = shared_batches(res, &scans, reps);
    // a shared batch's time on T threads as a fraction of its serial walk,
    // `lone + parallel / T`, from its times on one and two threads
    // (no shared batches: nothing to split, and no 0 / 0 to poison the bound)
    let (lone, parallel) = if serial > 0.0 {
        let lone = (2.0 * two_threads - one_thread).max(0.0) / serial;
        (lone, 2.0 * two_threads / serial - 2.0 * lone)
    } else {
        (0.0, 0.0)
    };
    if serial > 0.0 {
        println!(
            "shared batches: serial {:.1} ms, shared on 1 / 2 threads {:.1} / {:.1} ms (wall): on T threads \
             {lone:.2} + {parallel:.2} / T of the serial walk",
            serial * 1e3,
            one_thread * 1e3,
            two_threads * 1e3
        );
    }
    // the pipeline: scans are cast in parallel and their updates applied in
    // order, one at a time (shared batches by all threads), so once the
    // casting is spread thin enough the chain of updates after the first
    // scan's casting bounds the time
    let bound = |threads: f64| {
        if threads == 1.0 {
            return c + a;
        }
        let shared_cpu = if serial > 0.0 { one_thread / serial } else { 1.0 };
        let spread = cast[0] + (c - cast[0] + a - a_shared + a_shared * shared_cpu) / threads;
        let chain = cast[0] + (a - a_shared) + a_shared * (lone + parallel / threads);
        spread.max(chain)
    };
    println!("| threads | model (ms) | measured wall (ms) |");
    println!("| ---: | ---: | ---: |");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    for threads in [1, 2, 4, 8, 16] {
        let measured = if threads <= cores {
            let opts = ScanOptions::default().with_threads(Some(threads));
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

/// The scans inserted one after the other, each batch of [`SHARED_BATCH`]
/// codes or more applied to copies of the tree before it: serially, and
/// shared on pools of one and two threads. The sums of the fastest of `reps` wall times, in seconds:
/// (serial, one thread, two threads).
fn shared_batches(res: f64, scans: &[common::Scan], reps: usize) -> (f64, f64, f64) {
    let pools: Vec<rayon::ThreadPool> =
        [1, 2].iter().map(|&n| rayon::ThreadPoolBuilder::new().num_threads(n).build().expect("pool")).collect();
    let one = ScanOptions::default().with_threads(Some(1));
    let mut tree = OccupancyTree::new(res).expect("resolution");
    let (hit, miss) = (tree.sensor().hit, tree.sensor().miss);
    let mut sums = (0.0, 0.0, 0.0);
    for (points, origin) in scans {
        let (update, _) = tree.compute_update(points, *origin, &one).expect("scan");
        // each batch applied in turn, as `apply_update` does; the tree takes
        // the large ones shared on two threads (as a build shares them when
        // a thread is free), so that the copies start with what earlier
        // shared updates leave (spare slots, the budget from the last one's
        // use), as a build's tree does; the map is the same either way
        for (codes, delta) in [(&update.free, miss), (&update.occupied, hit)] {
            if codes.len() < SHARED_BATCH {
                tree.update_batch(codes, delta, InnerNodes::Update);
                continue;
            }
            let best = |apply: &dyn Fn(&mut OccupancyTree)| {
                (0..reps)
                    .map(|_| {
                        let mut copy = tree.clone();
                        let t = Instant::now();
                        apply(&mut copy);
                        t.elapsed().as_secs_f64()
                    })
                    .fold(f64::MAX, f64::min)
            };
            sums.0 += best(&|t| t.update_batch(codes, delta, InnerNodes::Update));
            sums.1 += best(&|t| pools[0].install(|| t.update_batch_shared(codes, delta, InnerNodes::Update, 2)));
            sums.2 += best(&|t| pools[1].install(|| t.update_batch_shared(codes, delta, InnerNodes::Update, 2)));
            pools[1].install(|| tree.update_batch_shared(codes, delta, InnerNodes::Update, 2));
        }
    }
    sums
}

/// CPU time of the calling thread, in seconds.
fn thread_cpu() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec for the call.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
