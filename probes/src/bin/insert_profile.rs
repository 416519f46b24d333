//! Scan insertion under a profiler: `cargo run --release -p
//! octolinear-probes --bin insert_profile -- indoor|outdoor|FILE.graph RES
//! THREADS [SCANS]` builds the bench's simulated scans (or reads the first
//! SCANS scans of a `.graph` file, such as `octolinear simulate` writes for
//! the full-size sequences), then times their insertion into a fresh tree.
//! Meant for `valgrind --tool=callgrind` or `perf record`.

use octolinear::internals::TreeInternals;
use octolinear::{OccupancyTree, ScanOptions};
use octolinear_sim::{simulate, LidarConfig, SceneKind};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let first = args.first().map_or("indoor", String::as_str);
    let kind = if first == "outdoor" { SceneKind::Outdoor } else { SceneKind::Indoor };
    let res: f64 = args.get(1).map_or(0.1, |s| s.parse().expect("RES"));
    let threads: usize = args.get(2).map_or(1, |s| s.parse().expect("THREADS"));
    let scans: Option<usize> = args.get(3).map(|s| s.parse().expect("SCANS"));
    let graph = if first.ends_with(".graph") {
        let mut graph = octolinear::formats::graph::read_file(first).expect("read the .graph file");
        graph.nodes.truncate(scans.unwrap_or(usize::MAX));
        graph
    } else {
        let n = scans.unwrap_or(if kind == SceneKind::Indoor { 24 } else { 6 });
        let cfg = if kind == SceneKind::Indoor { LidarConfig::indoor() } else { LidarConfig::outdoor() };
        simulate(kind, n, 7, &cfg).expect("simulate")
    };
    let scans: Vec<_> = graph.nodes.iter().map(|node| node.graph2tree()).collect();
    let points: usize = scans.iter().map(|(c, _)| c.points.len()).sum();
    let opts = ScanOptions::default().with_threads(Some(threads));
    // REPS=n repeats the whole insertion and reports the fastest run and the median
    let reps: usize = std::env::var("REPS").map_or(1, |s| s.parse().expect("REPS"));
    let mut runs = Vec::with_capacity(reps);
    let mut cpu = f64::MAX;
    let mut tree = OccupancyTree::new(res).expect("resolution");
    let mut updates = 0;
    for _ in 0..reps {
        let t = Instant::now();
        let c = cpu_time();
        tree = OccupancyTree::new(res).expect("resolution");
        updates = 0;
        let clouds = scans.iter().map(|(cloud, origin)| (cloud.points.as_slice(), *origin));
        tree.insert_point_clouds(clouds, &opts, |_, r| updates += r.free_updates + r.occupied_updates).expect("insert");
        runs.push(t.elapsed().as_secs_f64());
        cpu = cpu.min(cpu_time() - c);
    }
    runs.sort_by(f64::total_cmp);
    let (secs, median) = (runs[0], runs[runs.len() / 2]);
    println!(
        "{points} points, {updates} voxel updates, {} nodes: {:.1} ms (median {:.1} ms), CPU {:.1} ms ({:.2} Mpt/s, {:.1} M updates/s)",
        tree.size(),
        secs * 1e3,
        median * 1e3,
        cpu * 1e3,
        points as f64 / secs / 1e6,
        updates as f64 / secs / 1e6
    );
    // STEPS=1: the rays' voxel visits (repeats included), outside the timing
    if std::env::var_os("STEPS").is_some() {
        let visits: usize = scans.iter().map(|(cloud, origin)| tree.cast_codes(&cloud.points, *origin).0.len()).sum();
        println!("{visits} voxel visits by rays: {:.2} ns each", secs * 1e9 / visits as f64);
    }
}

/// CPU time of the whole process (all threads), in seconds: less disturbed
/// than wall time by other work on a shared machine.
fn cpu_time() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec for the call.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
