//! One large batch update, serial against shared: `cargo run --release -p
//! octolinear-probes --bin batch_probe -- outdoor|indoor|FILE.graph RES SCAN
//! [REPS]` inserts the bench's scans (or a `.graph` file's) before `SCAN`,
//! then times applying that scan's free-space batch to copies of the tree:
//! with `update_batch`, and with `update_batch_shared` on pools of one and
//! two threads (one thread shows what sharing costs, two what it gains).
//! Prints CPU and wall times (the fastest of REPS).

use octolinear::internals::TreeInternals;
use octolinear::{InnerNodes, OccupancyTree, ScanOptions};
use octolinear_sim::{simulate, LidarConfig, SceneKind};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let kind = if args.first().map(String::as_str) == Some("indoor") { SceneKind::Indoor } else { SceneKind::Outdoor };
    let res: f64 = args.get(1).map_or(0.05, |s| s.parse().expect("RES"));
    let scan: usize = args.get(2).map_or(3, |s| s.parse().expect("SCAN"));
    let reps: usize = args.get(3).map_or(5, |s| s.parse().expect("REPS"));
    let graph = match args.first().filter(|a| a.ends_with(".graph")) {
        Some(file) => {
            let mut graph = octolinear::formats::graph::read_file(file).expect("read the .graph file");
            graph.nodes.truncate(scan + 1);
            graph
        }
        None => {
            let cfg = if kind == SceneKind::Indoor { LidarConfig::indoor() } else { LidarConfig::outdoor() };
            simulate(kind, scan + 1, 7, &cfg).expect("simulate")
        }
    };
    let scans: Vec<_> = graph.nodes.iter().map(|node| node.graph2tree()).collect();
    let mut base = OccupancyTree::new(res).expect("resolution");
    let opts = ScanOptions::default().with_threads(Some(1));
    for (cloud, origin) in &scans[..scan] {
        base.insert_point_cloud(&cloud.points, *origin, &opts).expect("insert");
    }
    let (cloud, origin) = &scans[scan];
    let (update, _) = base.compute_update(&cloud.points, *origin, &opts).expect("cast");
    let miss = base.sensor().miss;
    println!("{} codes into a tree of {} nodes", update.free.len(), base.size());
    let pools: Vec<rayon::ThreadPool> =
        [1, 2].iter().map(|&n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap()).collect();
    // ONLY=0|1|2 runs one of the three (for a profiler)
    let only: Option<usize> = std::env::var("ONLY").ok().map(|s| s.parse().expect("ONLY"));
    let mut best = [(f64::MAX, f64::MAX); 3];
    for _ in 0..reps {
        for (i, b) in best.iter_mut().enumerate() {
            if only.is_some_and(|o| o != i) {
                continue;
            }
            let mut t = base.clone();
            let (w, c) = (Instant::now(), cpu_time());
            match i {
                0 => t.update_batch(&update.free, miss, InnerNodes::Update),
                _ => pools[i - 1].install(|| t.update_batch_shared(&update.free, miss, InnerNodes::Update, 2)),
            }
            let (w, c) = (w.elapsed().as_secs_f64(), cpu_time() - c);
            *b = (b.0.min(w), b.1.min(c));
            std::hint::black_box(&t);
        }
    }
    for (name, (w, c)) in ["serial", "shared, 1 thread", "shared, 2 threads"].iter().zip(best) {
        println!("{name:>18}: {:7.2} ms wall, {:7.2} ms CPU", w * 1e3, c * 1e3);
    }
}

fn cpu_time() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec for the call.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
