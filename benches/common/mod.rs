//! Shared inputs of the benchmarks: simulated scenes and random queries.
#![allow(dead_code)]

use octolinear::{OccupancyTree, Point3, ScanOptions};
use octolinear_sim::{simulate, LidarConfig, SceneKind};

/// Seed of every simulated scene (fixed so runs are comparable).
pub const SEED: u64 = 7;

/// One scan: world-frame end points and the sensor origin.
pub type Scan = (Vec<Point3>, Point3);

/// `scans` simulated lidar scans of an indoor or outdoor scene, in the
/// world frame exactly as `graph2tree` hands them to `insertPointCloud`.
pub fn scans(kind: SceneKind, scans: usize) -> Vec<Scan> {
    let cfg = match kind {
        SceneKind::Indoor => LidarConfig::indoor(),
        SceneKind::Outdoor => LidarConfig::outdoor(),
    };
    let graph = simulate(kind, scans, SEED, &cfg).expect("simulate");
    graph
        .nodes
        .iter()
        .map(|n| {
            let (cloud, origin) = n.graph2tree();
            (cloud.points, origin)
        })
        .collect()
}

/// For the probes (`probes/src/bin/`): the scene and resolution their first two
/// arguments name (`indoor|outdoor|FILE.graph RES`; indoor, 0.2 m when absent) and the
/// benchmark's scans of that scene (24 indoors, 6 outdoors), or the scans of
/// the `.graph` file (such as the full-size sequences, `--full`), in the world
/// frame as `graph2tree` puts them.
pub fn scene_from_args() -> (SceneKind, f64, Vec<Scan>) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let first = args.first().map_or("indoor", String::as_str);
    let kind = if first == "outdoor" { SceneKind::Outdoor } else { SceneKind::Indoor };
    let res: f64 = args.get(1).map_or(0.2, |s| s.parse().expect("RES"));
    if first.ends_with(".graph") {
        let graph = octolinear::formats::graph::read_file(first).expect("read the .graph file");
        let scans = graph.nodes.iter().map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect();
        return (kind, res, scans);
    }
    (kind, res, scans(kind, if kind == SceneKind::Indoor { 24 } else { 6 }))
}

pub fn num_points(scans: &[Scan]) -> usize {
    scans.iter().map(|(p, _)| p.len()).sum()
}

pub fn kind_name(kind: SceneKind) -> &'static str {
    match kind {
        SceneKind::Indoor => "indoor",
        SceneKind::Outdoor => "outdoor",
    }
}

/// Options matching OctoMap's `insertPointCloud(points, origin)` defaults.
pub fn scan_options(threads: Option<usize>) -> ScanOptions {
    ScanOptions::default().with_threads(threads)
}

/// A tree built from `scans` at `res` with OctoMap's default parameters,
/// scan after scan (`insert_point_clouds`: with several threads, one scan
/// is applied while the next is cast).
pub fn build(scans: &[Scan], res: f64, threads: Option<usize>) -> OccupancyTree {
    let mut tree = OccupancyTree::new(res).expect("resolution");
    let opts = scan_options(threads);
    let scans = scans.iter().map(|(points, origin)| (points.as_slice(), *origin));
    tree.insert_point_clouds(scans, &opts, |_, _| {}).expect("insert");
    tree
}

/// [`build`], and the voxel updates it applied (free and occupied, summed
/// over the scans).
pub fn build_counting(scans: &[Scan], res: f64, threads: Option<usize>) -> (OccupancyTree, usize) {
    let mut tree = OccupancyTree::new(res).expect("resolution");
    let opts = scan_options(threads);
    let scans = scans.iter().map(|(points, origin)| (points.as_slice(), *origin));
    let mut updates = 0;
    tree.insert_point_clouds(scans, &opts, |_, r| updates += r.free_updates + r.occupied_updates).expect("insert");
    (tree, updates)
}

/// xorshift64*: a small deterministic generator for query inputs.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        let u = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * u
    }

    /// A random unit vector.
    pub fn direction(&mut self) -> Point3 {
        loop {
            let p = Point3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            let n = p.norm();
            if n > 0.1 && n <= 1.0 {
                return p.normalized();
            }
        }
    }
}

/// Random query points: half are leaf centres of the tree (hits), half are
/// uniform in the tree's bounding box (mostly unknown space: misses).
pub fn query_points(tree: &OccupancyTree, n: usize, seed: u64) -> Vec<Point3> {
    let mut rng = Rng(seed | 1);
    let leaves: Vec<Point3> = tree.leaves(0).map(|l| l.center_point()).collect();
    let b = tree.bounds(octolinear::BoundsRule::CenterHalfSize);
    (0..n)
        .map(|i| {
            if i % 2 == 0 && !leaves.is_empty() {
                leaves[(rng.next_u64() % leaves.len() as u64) as usize]
            } else {
                Point3::new(
                    rng.range(b.min[0] as f32, b.max[0] as f32),
                    rng.range(b.min[1] as f32, b.max[1] as f32),
                    rng.range(b.min[2] as f32, b.max[2] as f32),
                )
            }
        })
        .collect()
}

/// Random rays from the sensor origins of `scans` (free space).
pub fn rays(scans: &[Scan], n: usize, seed: u64) -> (Vec<Point3>, Vec<Point3>) {
    let mut rng = Rng(seed | 1);
    (0..n)
        .map(|_| {
            let o = scans[(rng.next_u64() % scans.len() as u64) as usize].1;
            (o, rng.direction())
        })
        .unzip()
}

/// The machine's floor for one ray's walk: nanoseconds per link of a chain
/// of double compares, each choosing what the next dependent add adds (a
/// DDA step's least work, one after the other), the fastest of seven runs
/// of 10^8 links.
pub fn dependent_step_ns() -> f64 {
    use std::hint::black_box;
    let n = 100_000_000u64;
    (0..7)
        .map(|_| {
            let t = std::time::Instant::now();
            // opaque values, in registers
            let (a, b, limit) = (black_box(1.0e-9f64), black_box(2.0e-9f64), black_box(0.5f64));
            let mut x = black_box(0.0f64);
            for _ in 0..n {
                x += std::hint::select_unpredictable(x < limit, a, b);
            }
            black_box(x);
            t.elapsed().as_secs_f64() * 1e9 / n as f64
        })
        .fold(f64::MAX, f64::min)
}
