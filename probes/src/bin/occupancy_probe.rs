//! Scan insertion (scan by scan) and random point queries on a map built
//! from a `.graph` file, as the Python package runs them:
//! `occupancy_probe FILE RES [N]`.
//! Prints the fastest of several passes in ns per query. A probe for
//! comparing versions, not a benchmark of record.

use octolinear::formats::graph;
use octolinear::{Found, Key, OccupancyTree, Point3, ScanOptions};
use std::hint::black_box;

/// This thread's CPU time in seconds: a loaded machine's waits do not count.
fn cpu_seconds() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec for the call to fill.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// The fastest of `reps` runs of `f`, in thread CPU time.
fn best<T>(reps: usize, mut f: impl FnMut() -> T) -> f64 {
    (0..reps)
        .map(|_| {
            let t = cpu_seconds();
            black_box(f());
            cpu_seconds() - t
        })
        .fold(f64::MAX, f64::min)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().expect("FILE RES [N]");
    let res: f64 = args.get(1).map_or(0.1, |s| s.parse().expect("RES"));
    let n: usize = args.get(2).map_or(1_000_000, |s| s.parse().expect("N"));
    let g = graph::read_file(path).expect("graph");
    let scans: Vec<_> = g.nodes.iter().map(|n| n.graph2tree()).collect();
    // insertion scan by scan (as the Python package's insertPointCloud),
    // wall time, fastest of 9, one thread and two
    for threads in [1, 2] {
        let opts = ScanOptions::default().with_threads(Some(threads));
        let t = (0..9)
            .map(|_| {
                let start = std::time::Instant::now();
                let mut tree = OccupancyTree::new(res).expect("tree");
                for (cloud, origin) in &scans {
                    tree.insert_point_cloud(&cloud.points, *origin, &opts).expect("scan");
                }
                black_box(&tree);
                start.elapsed().as_secs_f64()
            })
            .fold(f64::MAX, f64::min);
        println!("insert_point_cloud, {} scans, {threads} thread(s): {:.1} ms (wall)", scans.len(), t * 1e3);
    }
    let mut tree = OccupancyTree::new(res).expect("tree");
    for (cloud, origin) in &scans {
        tree.insert_point_cloud(&cloud.points, *origin, &ScanOptions::default()).expect("scan");
    }
    let b = tree.bounds(octolinear::BoundsRule::CenterHalfSize);
    // uniform in the bounds, a fixed xorshift
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let points: Vec<Point3> = (0..n)
        .map(|_| {
            let c = [0, 1, 2].map(|i| b.min[i] + next() * (b.max[i] - b.min[i]));
            Point3::new(c[0] as f32, c[1] as f32, c[2] as f32)
        })
        .collect();
    let mut keys: Vec<Key> = points.iter().map(|&p| tree.key(p).unwrap()).collect();
    if std::env::var("MIX").is_ok() {
        // half of them leaf centres, as the side-by-side benchmark's mix
        let leaves: Vec<Key> = tree.leaves(0).map(|l| l.key).collect();
        for (i, k) in keys.iter_mut().enumerate().filter(|(i, _)| i % 2 == 0) {
            *k = leaves[(i * 7919) % leaves.len()];
        }
    }
    println!("{} nodes, {} leaves, {n} queries", tree.size(), tree.num_leaves());
    let ns = |t: f64| t * 1e9 / n as f64;
    let reps = 9;
    let bytes = octolinear::mapped::to_bytes(&tree, Default::default()).expect("olm");
    let map = octolinear::mapped::MappedMap::new(bytes).expect("view");
    let view = map.view();
    let t = best(reps, || keys.iter().filter_map(|&k| view.search(k, 0)).map(|f| f.value).sum::<f32>());
    println!("mapped search(key)          {:6.2} ns", ns(t));
    let mut out: Vec<Option<Found>> = Vec::new();
    let t = best(reps, || {
        let mut sum = 0f32;
        for c in keys.chunks(1 << 14) {
            view.search_many(c, 0, &mut out);
            sum += out.iter().flatten().map(|f| f.value).sum::<f32>();
        }
        sum
    });
    println!("mapped search_many, 16k     {:6.2} ns", ns(t));
    for round in 0..2 {
        let t = best(reps, || keys.iter().filter_map(|&k| tree.search(k, 0)).map(|f| f.value).sum::<f32>());
        println!("[{round}] search(key)            {:6.2} ns", ns(t));
        let mut out: Vec<Option<Found>> = Vec::new();
        let t = best(reps, || {
            let mut sum = 0f32;
            for c in keys.chunks(1 << 14) {
                tree.search_many(c, 0, &mut out);
                sum += out.iter().flatten().map(|f| f.value).sum::<f32>();
            }
            sum
        });
        println!("[{round}] search_many, 16k chunks {:6.2} ns", ns(t));
        let mut sorted = keys.clone();
        let t = best(reps, || {
            sorted.copy_from_slice(&keys);
            sorted.sort_unstable_by_key(|k| octolinear::MortonCode::encode(*k).0);
            sorted.len()
        });
        println!("[{round}] sort by Morton code     {:6.2} ns", ns(t));
        let t = best(reps, || sorted.iter().filter_map(|&k| tree.search(k, 0)).map(|f| f.value).sum::<f32>());
        println!("[{round}] search(key), sorted     {:6.2} ns", ns(t));
    }
}
