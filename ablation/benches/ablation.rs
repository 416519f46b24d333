//! Layout ablation: octolinear's arenas against the paper's pointer tree,
//! and the paper's Table 2 / Fig. 14 / Fig. 15 on simulated scans.
//!
//! `cargo bench -p octolinear-ablation --bench ablation` (add `-- --quick` for a small run,
//! `-- --help` for the options) writes `docs/ablation.md` and the SVG plots
//! under `docs/ablation/`. Every measurement of a layout runs in a fresh
//! child process (this binary re-invoked with `--child`), so resident
//! memory and heap figures are not polluted by earlier builds.

use octolinear::formats::{bt, ot};
use octolinear::{BoundsRule, Key, OccupancyTree, Point3, ScanOptions};
use octolinear_ablation::alloc::{self, CountingAlloc, MemSnapshot};
use octolinear_ablation::pointer::PointerTree;
use octolinear_ablation::report::{self, count, mib, ns_per, secs, table, Chart, Series};
use octolinear_ablation::variants::{ArenaBatch, ArenaCompact, ArenaPerKey, Block8, MappedLayout, Split8};
use octolinear_ablation::{cast_ray, graph2tree_sensor, paper_bytes, Layout, ScanKeys};
use octolinear_sim::{simulate, LidarConfig, SceneKind, SplitMix64};
use serde_json::{json, Value};
use std::hint::black_box;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

/// Layouts measured per dataset: (id, label, description).
const LAYOUTS: [(&str, &str, &str); 7] = [
    ("pointer", "pointer (paper)", "one `Box` per node + lazily allocated `[Option<Box<Node>>; 8]` per inner node"),
    (
        "arena-key",
        "arena, per key",
        "`OccupancyTree` (SoA arena: 9 B per node above depth 16, 4 B per voxel) driven by `update(key, delta)`",
    ),
    ("arena-batch", "arena, batch", "`OccupancyTree` driven by `update_batch` (the `insert_point_cloud` path)"),
    ("arena-compact", "arena, batch + compact", "as *arena, batch*, then `compact()` after the last scan"),
    ("block8", "block8", "8-slot blocks of `{f32 value, u32 child_block}` (64 B per inner node)"),
    ("split8", "split8", "8-slot blocks with values and child indices in separate arrays"),
    (
        "mapped",
        "mapped (.olm)",
        "the native read-only format: built as *arena, batch*, then written to `.olm` bytes in a `Vec` (full \
         variant, 8-node rank blocks) and the tree dropped; queries run in place through a `MapView` (its insertion \
         time includes the writing)",
    ),
];

// ----- options -------------------------------------------------------------

#[derive(Clone, Debug)]
struct Opts {
    quick: bool,
    scenes: Vec<SceneKind>,
    resolutions: Vec<f64>,
    outdoor_resolutions: Vec<f64>,
    indoor_scans: usize,
    outdoor_scans: usize,
    queries: usize,
    rays: usize,
    reps: usize,
    seed: u64,
    out: PathBuf,
    oracle: bool,
}

impl Opts {
    fn parse(args: &[String]) -> Opts {
        let mut o = Opts {
            quick: false,
            scenes: vec![SceneKind::Indoor, SceneKind::Outdoor],
            resolutions: vec![0.05, 0.1, 0.2],
            outdoor_resolutions: vec![0.1, 0.2, 0.4],
            indoor_scans: 24,
            outdoor_scans: 6,
            queries: 1_000_000,
            rays: 20_000,
            reps: 3,
            seed: 42,
            out: Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs"),
            oracle: octolinear_oracle::available(),
        };
        let mut it = args.iter();
        while let Some(a) = it.next() {
            let mut val = |n: &str| it.next().unwrap_or_else(|| panic!("{n} needs a value")).clone();
            match a.as_str() {
                "--quick" => {
                    o.quick = true;
                    o.resolutions = vec![0.1, 0.2];
                    o.outdoor_resolutions = vec![0.2, 0.4];
                    o.indoor_scans = 6;
                    o.outdoor_scans = 3;
                    o.queries = 200_000;
                    o.rays = 4_000;
                    o.reps = 2;
                }
                "--res" => o.resolutions = val("--res").split(',').map(|r| r.parse().expect("--res a,b,c")).collect(),
                "--outdoor-res" => {
                    o.outdoor_resolutions =
                        val("--outdoor-res").split(',').map(|r| r.parse().expect("--outdoor-res a,b,c")).collect()
                }
                "--indoor-scans" => o.indoor_scans = val("--indoor-scans").parse().expect("--indoor-scans N"),
                "--outdoor-scans" => o.outdoor_scans = val("--outdoor-scans").parse().expect("--outdoor-scans N"),
                "--queries" => o.queries = val("--queries").parse().expect("--queries N"),
                "--rays" => o.rays = val("--rays").parse().expect("--rays N"),
                "--reps" => o.reps = val("--reps").parse().expect("--reps N"),
                "--seed" => o.seed = val("--seed").parse().expect("--seed N"),
                "--out" => o.out = PathBuf::from(val("--out")),
                "--scenes" => {
                    o.scenes = val("--scenes")
                        .split(',')
                        .map(|s| match s {
                            "indoor" => SceneKind::Indoor,
                            "outdoor" => SceneKind::Outdoor,
                            _ => panic!("--scenes indoor,outdoor"),
                        })
                        .collect()
                }
                "--no-oracle" => o.oracle = false,
                "--help" | "-h" => {
                    println!(
                        "cargo bench -p octolinear-ablation --bench ablation [-- OPTIONS]\n  --quick            small run (indoor 0.1, 0.2 m, 6 scans; outdoor 0.2, 0.4 m, 3 scans)\n  --res 0.05,0.1,0.2 indoor resolutions\n  --outdoor-res 0.1,0.2,0.4 outdoor resolutions\n  --scenes indoor,outdoor\n  --indoor-scans N / --outdoor-scans N\n  --queries N  --rays N  --reps N  --seed N\n  --out DIR          where ablation.md and ablation/*.svg go (default: docs/)\n  --no-oracle        skip OctoMap even when the oracle is built"
                    );
                    std::process::exit(0);
                }
                _ => {} // `cargo bench` passes `--bench`
            }
        }
        o
    }

    fn resolutions(&self, kind: SceneKind) -> &[f64] {
        match kind {
            SceneKind::Indoor => &self.resolutions,
            SceneKind::Outdoor => &self.outdoor_resolutions,
        }
    }

    fn scans(&self, kind: SceneKind) -> usize {
        match kind {
            SceneKind::Indoor => self.indoor_scans,
            SceneKind::Outdoor => self.outdoor_scans,
        }
    }

    /// The exact command that reproduces this run.
    fn command(&self) -> String {
        if self.quick {
            "cargo bench -p octolinear-ablation --bench ablation -- --quick".into()
        } else {
            "cargo bench -p octolinear-ablation --bench ablation".into()
        }
    }
}

fn scene_name(k: SceneKind) -> &'static str {
    match k {
        SceneKind::Indoor => "indoor",
        SceneKind::Outdoor => "outdoor",
    }
}

fn lidar(k: SceneKind) -> LidarConfig {
    match k {
        SceneKind::Indoor => LidarConfig::indoor(),
        SceneKind::Outdoor => LidarConfig::outdoor(),
    }
}

// ----- scans on disk (parent -> children) -----------------------------------

type Scan = (Vec<Point3>, Point3);

fn write_scans(path: &Path, scans: &[Scan]) {
    let mut b = Vec::new();
    b.extend((scans.len() as u32).to_le_bytes());
    for (pts, o) in scans {
        for v in [o.x, o.y, o.z] {
            b.extend(v.to_le_bytes());
        }
        b.extend((pts.len() as u32).to_le_bytes());
        for p in pts {
            for v in [p.x, p.y, p.z] {
                b.extend(v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, b).expect("write scans");
}

fn read_scans(path: &Path) -> Vec<Scan> {
    let mut b = Vec::new();
    std::fs::File::open(path).and_then(|mut f| f.read_to_end(&mut b)).expect("read scans");
    let mut at = 0;
    let mut u32_ = |b: &[u8]| {
        let v = u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
        at += 4;
        v
    };
    let n = u32_(&b);
    let mut out = Vec::new();
    for _ in 0..n {
        let o = Point3::new(f32::from_bits(u32_(&b)), f32::from_bits(u32_(&b)), f32::from_bits(u32_(&b)));
        let m = u32_(&b);
        let pts =
            (0..m).map(|_| Point3::new(f32::from_bits(u32_(&b)), f32::from_bits(u32_(&b)), f32::from_bits(u32_(&b))));
        let pts: Vec<Point3> = pts.collect();
        out.push((pts, o));
    }
    out
}

// ----- the workload every child derives identically --------------------------

struct Workload {
    keys: Vec<ScanKeys>,
    queries: Vec<Key>,
    /// (origin, direction)
    rays: Vec<(Point3, Point3)>,
    max_range: f64,
}

fn workload(res: f64, scans: &[Scan], queries: usize, rays: usize, seed: u64, max_range: f64) -> Workload {
    let tree = OccupancyTree::with_sensor(res, graph2tree_sensor()).unwrap();
    let keys: Vec<ScanKeys> = scans.iter().map(|(p, o)| ScanKeys::of_scan(&tree, p, *o).unwrap()).collect();
    let mut lo = [u16::MAX; 3];
    let mut hi = [0u16; 3];
    for k in keys.iter().flat_map(|s| s.occupied.iter()) {
        for a in 0..3 {
            lo[a] = lo[a].min(k.0[a]);
            hi[a] = hi[a].max(k.0[a]);
        }
    }
    let occupied: Vec<Key> = keys.iter().flat_map(|s| s.occupied.iter().copied()).collect();
    let mut rng = SplitMix64(seed);
    let q = (0..queries)
        .map(|i| {
            if i % 2 == 0 && !occupied.is_empty() {
                occupied[rng.below(occupied.len() as u32) as usize]
            } else {
                Key::new(
                    lo[0] + rng.below(u32::from(hi[0] - lo[0]) + 1) as u16,
                    lo[1] + rng.below(u32::from(hi[1] - lo[1]) + 1) as u16,
                    lo[2] + rng.below(u32::from(hi[2] - lo[2]) + 1) as u16,
                )
            }
        })
        .collect();
    let r = (0..rays)
        .map(|i| {
            let o = scans[i % scans.len()].1;
            let az = rng.range(0.0, std::f64::consts::TAU);
            let el = rng.range(-0.35, 0.35);
            (o, Point3::new((el.cos() * az.cos()) as f32, (el.cos() * az.sin()) as f32, el.sin() as f32))
        })
        .collect();
    Workload { keys, queries: q, rays: r, max_range }
}

// ----- children -----------------------------------------------------------------

struct ChildArgs {
    what: String,
    scans: PathBuf,
    res: f64,
    queries: usize,
    rays: usize,
    reps: usize,
    seed: u64,
    max_range: f64,
}

fn child_main(args: &[String]) {
    let get = |n: &str| {
        let i = args.iter().position(|a| a == n).unwrap_or_else(|| panic!("child needs {n}"));
        args[i + 1].clone()
    };
    let c = ChildArgs {
        what: get("--child"),
        scans: PathBuf::from(get("--scans")),
        res: get("--res").parse().unwrap(),
        queries: get("--queries").parse().unwrap(),
        rays: get("--rays").parse().unwrap(),
        reps: get("--reps").parse().unwrap(),
        seed: get("--seed").parse().unwrap(),
        max_range: get("--max-range").parse().unwrap(),
    };
    let v = match c.what.as_str() {
        "pointer" => run_layout::<PointerTree>(&c),
        "arena-key" => run_layout::<ArenaPerKey>(&c),
        "arena-batch" => run_layout::<ArenaBatch>(&c),
        "arena-compact" => run_layout::<ArenaCompact>(&c),
        "block8" => run_layout::<Block8>(&c),
        "split8" => run_layout::<Split8>(&c),
        "mapped" => run_layout::<MappedLayout>(&c),
        "stats" => run_stats(&c),
        "octomap" => run_octomap(&c),
        other => panic!("unknown child job {other}"),
    };
    println!("ABLATION-JSON {v}");
}

fn min_time(reps: usize, mut f: impl FnMut() -> u64) -> (f64, u64) {
    let mut best = f64::MAX;
    let mut check = 0;
    for _ in 0..reps.max(1) {
        let t = Instant::now();
        check = black_box(f());
        best = best.min(t.elapsed().as_secs_f64());
    }
    (best, check)
}

fn run_layout<L: Layout>(c: &ChildArgs) -> Value {
    let sensor = graph2tree_sensor();
    let scans = read_scans(&c.scans);
    let w = workload(c.res, &scans, c.queries, c.rays, c.seed, c.max_range);
    drop(scans);
    let keys = octolinear::KeySpace::new(c.res);

    let m0 = MemSnapshot::take();
    alloc::reset_peak();
    let calls0 = alloc::alloc_calls();
    let mut l = L::new(c.res, sensor);
    let mut insert_s = 0.0;
    let mut series_live = Vec::new();
    let mut series_heap = Vec::new();
    let mut series_nodes = Vec::new();
    let mut updates = 0usize;
    for s in &w.keys {
        let t = Instant::now();
        l.apply_scan(&s.free, &s.occupied, &sensor);
        insert_s += t.elapsed().as_secs_f64();
        updates += s.len();
        series_live.push(alloc::live_bytes().saturating_sub(m0.live));
        series_heap.push(alloc::heap_in_use().unwrap_or(0).saturating_sub(m0.heap));
        series_nodes.push(l.node_count());
    }
    let t = Instant::now();
    l.finish();
    let finish_s = t.elapsed().as_secs_f64();
    let peak = alloc::peak_bytes().saturating_sub(m0.live);
    let calls = alloc::alloc_calls() - calls0;
    let m1 = MemSnapshot::take().since(&m0);
    if let Some(last) = series_live.last_mut() {
        *last = m1.live; // after finish (compaction)
    }
    if let Some(last) = series_heap.last_mut() {
        *last = m1.heap;
    }

    let (search_s, search_sum) = min_time(c.reps, || {
        let mut acc = 0u64;
        for &q in &w.queries {
            if let Some(v) = l.search(q) {
                acc = acc.wrapping_add(u64::from(v.to_bits()));
            }
        }
        acc
    });
    let mut leaves = 0usize;
    let (iter_s, iter_sum) = min_time(c.reps, || {
        let mut acc = 0u64;
        let mut n = 0usize;
        l.for_each_leaf(|k, d, v| {
            n += 1;
            acc = acc.wrapping_add(u64::from(v.to_bits()) ^ u64::from(k.0[0]) ^ u64::from(d));
        });
        leaves = n;
        acc
    });
    let sensor2 = sensor;
    let (ray_s, ray_hits) = min_time(1, || {
        let mut hits = 0u64;
        for &(o, d) in &w.rays {
            if let Some(k) = cast_ray(&l, &keys, &sensor2, o, d, w.max_range, true) {
                hits += 1 + u64::from(k.0[0]);
            }
        }
        hits
    });
    json!({
        "nodes": l.node_count(), "leaves": leaves, "formula": l.bytes_formula(),
        "live": m1.live, "heap": m1.heap, "rss": m1.rss, "peak": peak, "alloc_calls": calls,
        "updates": updates, "insert_s": insert_s, "finish_s": finish_s,
        "series_live": series_live, "series_heap": series_heap, "series_nodes": series_nodes,
        "search_s": search_s, "search_n": w.queries.len(), "search_sum": search_sum.to_string(),
        "iter_s": iter_s, "iter_sum": iter_sum.to_string(),
        "ray_s": ray_s, "rays": w.rays.len(), "ray_check": ray_hits.to_string(),
    })
}

/// Table 2 figures and the real API end to end (`insert_point_cloud`).
fn run_stats(c: &ChildArgs) -> Value {
    let sensor = graph2tree_sensor();
    let scans = read_scans(&c.scans);
    let m0 = MemSnapshot::take();
    let mut tree = OccupancyTree::with_sensor(c.res, sensor).unwrap();
    let mut insert_s = 0.0;
    let mut series_octomap = Vec::new();
    for (pts, o) in &scans {
        let t = Instant::now();
        tree.insert_point_cloud(pts, *o, &ScanOptions::default()).unwrap();
        insert_s += t.elapsed().as_secs_f64();
        series_octomap.push(tree.octomap_memory_usage());
    }
    let m1 = MemSnapshot::take().since(&m0);
    let counts = |t: &OccupancyTree| {
        let leaves = t.num_leaves();
        let nodes = t.calc_num_nodes();
        (nodes, leaves, nodes - leaves)
    };
    let b = tree.bounds(BoundsRule::MinPlusSize);
    let size = b.size();
    let known: f64 = tree.leaves(0).map(|n| n.size().powi(3)).sum();
    let occupied: f64 = tree.leaves(0).filter(|n| tree.is_occupied(n.value)).map(|n| n.size().powi(3)).sum();
    let grid = tree.memory_full_grid(BoundsRule::CenterHalfSize);
    let (n, l, i) = counts(&tree);
    let voxels = tree.leaves(0).filter(|n| n.depth == 16).count();
    let mut ot_bytes = Vec::new();
    ot::write(&tree, &mut ot_bytes).unwrap();
    let mut bt_bytes = Vec::new();
    bt::write(&tree, &mut bt_bytes).unwrap();

    let mut ml = tree.clone();
    ml.to_max_likelihood();
    ml.prune();
    let (mn, mlv, mi) = counts(&ml);
    let ml_octomap = ml.octomap_memory_usage();
    ml.compact();
    let ml_arena = ml.memory_usage();
    drop(ml);

    let mut compact = tree.clone();
    compact.compact();
    let pruned_arena = compact.memory_usage();
    drop(compact);

    let mut full = tree.clone();
    full.expand().unwrap();
    let (fnodes, fl, fi) = counts(&full);
    let full_octomap = full.octomap_memory_usage();
    full.compact();
    let full_arena = full.memory_usage();
    drop(full);

    json!({
        "size": size, "known_volume": known, "occupied_volume": occupied, "full_grid": grid,
        "pruned": {"nodes": n, "leaves": l, "inner": i, "voxels": voxels, "octomap": tree.octomap_memory_usage(),
                   "paper32": paper_bytes(i, l, 4), "paper64": paper_bytes(i, l, 8), "arena_compact": pruned_arena},
        "ml": {"nodes": mn, "leaves": mlv, "inner": mi, "octomap": ml_octomap,
               "paper32": paper_bytes(mi, mlv, 4), "paper64": paper_bytes(mi, mlv, 8), "arena_compact": ml_arena},
        "unpruned": {"nodes": fnodes, "leaves": fl, "inner": fi, "octomap": full_octomap,
                     "paper32": paper_bytes(fi, fl, 4), "paper64": paper_bytes(fi, fl, 8), "arena_compact": full_arena},
        "ot": ot_bytes.len(), "bt": bt_bytes.len(),
        "api": {"insert_s": insert_s, "live": m1.live, "heap": m1.heap, "rss": m1.rss,
                "memory_usage": tree.memory_usage(), "threads": rayon::current_num_threads()},
        "series_octomap_formula": series_octomap,
        "points": scans.iter().map(|s| s.0.len()).sum::<usize>(),
    })
}

/// The same scans through real OctoMap (the oracle), in this process.
fn run_octomap(c: &ChildArgs) -> Value {
    use octolinear_oracle::OracleTree;
    let scans = read_scans(&c.scans);
    let w = workload(c.res, &scans, c.queries, c.rays, c.seed, c.max_range);
    let keys = octolinear::KeySpace::new(c.res);
    let queries: Vec<[f32; 3]> = w
        .queries
        .iter()
        .map(|&k| {
            let p = keys.key_to_point(k);
            [p.x, p.y, p.z]
        })
        .collect();
    let origins: Vec<[f32; 3]> = w.rays.iter().map(|r| [r.0.x, r.0.y, r.0.z]).collect();
    let dirs: Vec<[f32; 3]> = w.rays.iter().map(|r| [r.1.x, r.1.y, r.1.z]).collect();
    let pts: Vec<(Vec<[f32; 3]>, [f32; 3])> =
        scans.iter().map(|(p, o)| (p.iter().map(|p| [p.x, p.y, p.z]).collect(), [o.x, o.y, o.z])).collect();
    drop(scans);
    drop(w.keys);
    let mut out = vec![0f32; queries.len()];
    let mut ends = vec![[0f32; 3]; origins.len()];
    let mut hits = vec![false; origins.len()];

    let m0 = MemSnapshot::take();
    let mut tree = OracleTree::with_graph2tree_default(c.res).expect("oracle");
    let mut insert_s = 0.0;
    let mut series_heap = Vec::new();
    let mut series_formula = Vec::new();
    for (p, o) in &pts {
        let t = Instant::now();
        tree.insert_point_cloud(p, *o, -1.0, false, false).unwrap();
        insert_s += t.elapsed().as_secs_f64();
        series_heap.push(alloc::heap_in_use().unwrap_or(0).saturating_sub(m0.heap));
        series_formula.push(tree.memory_usage());
    }
    let m1 = MemSnapshot::take().since(&m0);
    if let Some(last) = series_heap.last_mut() {
        *last = m1.heap;
    }
    let (search_s, search_sum) = min_time(c.reps, || {
        tree.bench_search(&queries, 0, &mut out);
        out.iter().filter(|v| !v.is_nan()).fold(0u64, |a, v| a.wrapping_add(u64::from(v.to_bits())))
    });
    let mut leaves = 0;
    let (iter_s, _) = min_time(c.reps, || {
        let (n, s) = tree.bench_leaf_sum(0);
        leaves = n;
        s.to_bits()
    });
    let (ray_s, ray_hits) =
        min_time(1, || tree.bench_cast_rays(&origins, &dirs, true, w.max_range, &mut ends, &mut hits) as u64);
    json!({
        "nodes": tree.size(), "leaves": leaves, "formula": tree.memory_usage(),
        "heap": m1.heap, "rss": m1.rss, "live": m1.live, "insert_s": insert_s,
        "series_heap": series_heap, "series_formula": series_formula,
        "search_s": search_s, "search_n": queries.len(), "search_sum": search_sum.to_string(),
        "iter_s": iter_s, "ray_s": ray_s, "rays": origins.len(), "ray_hits": ray_hits,
    })
}

// ----- parent --------------------------------------------------------------------

fn spawn(exe: &Path, what: &str, scans: &Path, res: f64, o: &Opts, max_range: f64) -> Value {
    let t = Instant::now();
    let out = Command::new(exe)
        .args(["--child", what, "--scans"])
        .arg(scans)
        .args(["--res", &res.to_string(), "--queries", &o.queries.to_string(), "--rays", &o.rays.to_string()])
        .args(["--reps", &o.reps.to_string(), "--seed", &o.seed.to_string(), "--max-range", &max_range.to_string()])
        .output()
        .expect("run child");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout.lines().find_map(|l| l.strip_prefix("ABLATION-JSON "));
    match (out.status.success(), line) {
        (true, Some(l)) => {
            eprintln!("  {what:<14} {:>6.1} s", t.elapsed().as_secs_f64());
            serde_json::from_str(l).expect("child JSON")
        }
        _ => panic!("child {what} at {res} m failed: {}\n{}", out.status, String::from_utf8_lossy(&out.stderr)),
    }
}

struct Dataset {
    scene: SceneKind,
    res: f64,
    scans: usize,
    stats: Value,
    layouts: Vec<Value>,
    octomap: Option<Value>,
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

fn u(v: &Value) -> u64 {
    v.as_u64().unwrap_or(0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--child") {
        child_main(&args);
        return;
    }
    let o = Opts::parse(&args);
    assert!(alloc::is_counting(), "the counting allocator is not installed");
    let exe = std::env::current_exe().expect("own path");
    let started = Instant::now();
    let load_start = loadavg();
    let tmp = std::env::temp_dir().join(format!("octolinear-ablation-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let mut datasets = Vec::new();
    for &scene in &o.scenes {
        let n = o.scans(scene);
        eprintln!("simulating {} ({n} scans)", scene_name(scene));
        let g = simulate(scene, n, o.seed, &lidar(scene)).expect("simulate");
        let scans: Vec<Scan> = g
            .nodes
            .iter()
            .map(|node| {
                let (pc, origin) = node.graph2tree();
                (pc.points, origin)
            })
            .collect();
        let path = tmp.join(format!("{}.scans", scene_name(scene)));
        write_scans(&path, &scans);
        let max_range = lidar(scene).max_range.min(50.0);
        for &res in o.resolutions(scene) {
            eprintln!("{} at {res} m", scene_name(scene));
            let stats = spawn(&exe, "stats", &path, res, &o, max_range);
            let layouts = LAYOUTS.iter().map(|(id, _, _)| spawn(&exe, id, &path, res, &o, max_range)).collect();
            let octomap = o.oracle.then(|| spawn(&exe, "octomap", &path, res, &o, max_range));
            datasets.push(Dataset { scene, res, scans: n, stats, layouts, octomap });
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    let elapsed = started.elapsed().as_secs_f64();
    write_report(&o, &datasets, elapsed, [load_start, loadavg()]);
}

/// The 1/5/15-minute load averages (`/proc/loadavg`).
fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" / "))
        .unwrap_or_else(|_| "unknown".into())
}

// ----- the report ------------------------------------------------------------------

fn name(d: &Dataset) -> String {
    format!("{} {} m", scene_name(d.scene), d.res)
}

fn layout_index(id: &str) -> usize {
    LAYOUTS.iter().position(|l| l.0 == id).unwrap()
}

fn write_report(o: &Opts, ds: &[Dataset], elapsed: f64, load: [String; 2]) {
    let plots = o.out.join("ablation");
    std::fs::create_dir_all(&plots).unwrap();
    let mut md = String::new();
    let w = |md: &mut String, s: &str| {
        md.push_str(s);
        md.push('\n');
    };
    w(&mut md, "# Layout ablation: octolinear's arenas against the paper's pointer tree");
    w(&mut md, "");
    w(
        &mut md,
        &format!(
            "Generated by `{}` in {:.0} s; every number and plot below comes from that run \
             (nothing is typed in). Source: `ablation/benches/ablation.rs`, `ablation/src/`.",
            o.command(),
            elapsed
        ),
    );
    w(&mut md, "");
    w(&mut md, "## Machine");
    w(&mut md, "");
    let mut rows: Vec<Vec<String>> = report::machine_description().into_iter().map(|(k, v)| vec![k, v]).collect();
    rows.push(vec!["load average 1/5/15 min, run start".into(), load[0].clone()]);
    rows.push(vec!["load average 1/5/15 min, run end".into(), load[1].clone()]);
    w(&mut md, &table(&["what", "value"], &[false, false], &rows));
    w(
        &mut md,
        &format!(
            "OctoMap oracle: {}",
            match (o.oracle, octolinear_oracle::octomap_version()) {
                (true, Some(v)) => format!("liboctomap {v}, linked in-process through `octolinear-oracle`"),
                _ => "not available (OctoMap columns omitted)".into(),
            }
        ),
    );
    w(&mut md, "");
    w(&mut md, "## Setup");
    w(&mut md, "");
    w(
        &mut md,
        &format!(
            "* Data: the procedural simulator (`simulate::simulate`, seed {}), indoor scene with the \
             VLP-16-like `LidarConfig::indoor()` ({} scans) and outdoor scene with `LidarConfig::outdoor()` \
             ({} scans, 100 m range), each scan put in the world frame as graph2tree does; resolutions {} indoors \
             and {} outdoors (the outdoor maps are far larger: 100 m rays).",
            o.seed,
            o.indoor_scans,
            o.outdoor_scans,
            o.resolutions.iter().map(|r| format!("{r} m")).collect::<Vec<_>>().join(", "),
            o.outdoor_resolutions.iter().map(|r| format!("{r} m")).collect::<Vec<_>>().join(", ")
        ),
    );
    w(
        &mut md,
        "* Every layout is driven with the same per-scan key lists (`compute_update` → `ScanUpdate::sorted()`: \
         misses, then hits, each key once, Morton order) under the graph2tree sensor model, applying OctoMap's \
         `updateNode` rule (early exit on saturation, expansion of pruned leaves, add and clamp, bottom-up \
         prune-or-max). `ablation/tests/ablation.rs` checks that all layouts dump identical leaves (key, depth, value \
         bits) to `OccupancyTree::insert_point_cloud` on simulated scans, so only storage differs.",
    );
    w(&mut md, "* Layouts:");
    for (id, label, desc) in LAYOUTS {
        w(&mut md, &format!("  * **{label}** (`{id}`): {desc}."));
    }
    w(
        &mut md,
        "  * **OctoMap**: the real library (Debian's liboctomap through the oracle), `insertPointCloud` on the same \
         scans (it casts its own rays; the map is the same, as the search checksums below confirm).",
    );
    w(
        &mut md,
        "* Each (dataset, layout) runs in a fresh child process. Memory figures are differences between a snapshot \
         taken just before the first scan and one after the last (after `malloc_trim(0)`):",
    );
    w(
        &mut md,
        "  * **requested**: bytes Rust code asked for and still holds, counted by a `#[global_allocator]` wrapping \
         `System` (`ablation/src/alloc.rs`): real capacities, not formulas. Blind to C++ (OctoMap).",
    );
    w(
        &mut md,
        "  * **heap**: glibc's `mallinfo2()` in-use bytes (`uordblks + hblkhd`, all arenas): every malloc chunk \
         including its 8-byte header and 16-byte rounding — a 16 B `Box` occupies 32 B, a 64 B child array 80 B. \
         Sees Rust and C++ alike, so it is the like-for-like figure against OctoMap.",
    );
    w(
        &mut md,
        "  * **RSS**: growth of `VmRSS` (`/proc/self/status`). Pages only count once touched, so a `Vec`'s unused \
         capacity beyond 128 KiB (mmap'ed) is not resident; small maps are dominated by page granularity and \
         malloc's own reserves. In-process caveat for OctoMap: the oracle shim and liboctomap are linked into the \
         same process and allocate through the same glibc malloc, so its RSS growth also contains whatever \
         the library caches; the child process holds nothing else of size.",
    );
    w(
        &mut md,
        "  * **formula**: what the layout says of itself: `16·nodes + 64·inner` for the pointer tree (its exact \
         `Box` sizes, = the paper's 64-bit model), `memory_usage()` (reserved capacity) for the arena, slot \
         capacity for the block layouts, `memoryUsage()` for OctoMap (`320 + 16·size + 64·inner`).",
    );
    w(
        &mut md,
        "* The paper's model (Sect. 4, Eq. 8): `n_inner · (s_node + 8·s_ptr) + n_leaf · s_node`, \
         i.e. 40 B per inner node and 8 B per leaf with 32-bit pointers, 80 B / 16 B with 64-bit pointers.",
    );
    w(&mut md, "");

    // --- Table 2
    w(&mut md, "## The paper's Table 2 on simulated data");
    w(&mut md, "");
    w(
        &mut md,
        "Memory in MiB by the paper's model with 64-bit pointers (= OctoMap's `memoryUsage()` less its 320-byte \
         tree object); the 32-bit model's figure in parentheses. *No compression* is the tree without pruning: \
         the pruned tree after `expand()`, whose node set is exactly that of a tree built with pruning disabled \
         (checked in `ablation/tests/ablation.rs` against the pointer layout driven without pruning). *Pruned* is the \
         map as built (lossless compression); *max. likelihood* is `to_max_likelihood(); prune()`. *Mapped* is \
         the bounding box of all leaves; *known* sums the volumes of all leaves (observed space). `.ot` and \
         `.bt` are the file sizes octolinear (= OctoMap) writes for the map.",
    );
    w(&mut md, "");
    let mut rows = Vec::new();
    for d in ds {
        let s = &d.stats;
        let sz: Vec<f64> = s["size"].as_array().map(|a| a.iter().map(f).collect()).unwrap_or_default();
        let mem = |k: &str| format!("{} ({})", mib(f(&s[k]["paper64"])), mib(f(&s[k]["paper32"])));
        rows.push(vec![
            name(d),
            d.scans.to_string(),
            format!("{:.1} × {:.1} × {:.1}", sz[0], sz[1], sz[2]),
            format!("{:.0}", f(&s["known_volume"])),
            mib(f(&s["full_grid"])),
            mem("unpruned"),
            mem("pruned"),
            mem("ml"),
            mib(f(&s["ot"])),
            mib(f(&s["bt"])),
        ]);
    }
    w(
        &mut md,
        &table(
            &[
                "dataset",
                "scans",
                "mapped (m)",
                "known (m³)",
                "full 3D grid",
                "no compression",
                "pruned",
                "max. likelihood",
                ".ot",
                ".bt",
            ],
            &[false, true, true, true, true, true, true, true, true, true],
            &rows,
        ),
    );
    w(&mut md, "");
    w(&mut md, "Node counts behind it, and octolinear's compacted arena for the same three trees (MiB):");
    w(&mut md, "");
    let mut rows = Vec::new();
    for d in ds {
        let s = &d.stats;
        let n = |k: &str| format!("{} / {}", count(u(&s[k]["nodes"])), count(u(&s[k]["inner"])));
        rows.push(vec![
            name(d),
            n("unpruned"),
            n("pruned"),
            n("ml"),
            mib(f(&s["unpruned"]["arena_compact"])),
            mib(f(&s["pruned"]["arena_compact"])),
            mib(f(&s["ml"]["arena_compact"])),
        ]);
    }
    w(
        &mut md,
        &table(
            &[
                "dataset",
                "no compr. nodes / inner",
                "pruned nodes / inner",
                "ML nodes / inner",
                "arena: no compr.",
                "arena: pruned",
                "arena: ML",
            ],
            &[false, true, true, true, true, true, true],
            &rows,
        ),
    );
    w(&mut md, "");

    // --- measured memory per layout
    w(&mut md, "## Measured memory per layout (pruned map as built)");
    w(&mut md, "");
    w(&mut md, "MiB; **requested** by the counting allocator, then glibc **heap** and **RSS** growth.");
    w(&mut md, "");
    let mut headers: Vec<String> = vec!["dataset".into(), "nodes".into(), "model 64-bit".into()];
    for (_, label, _) in LAYOUTS {
        headers.push(format!("{label}: requested / heap / RSS"));
    }
    headers.push("OctoMap: memoryUsage() / heap / RSS".into());
    let mut rows = Vec::new();
    for d in ds {
        let mut r = vec![name(d), count(u(&d.stats["pruned"]["nodes"])), mib(f(&d.stats["pruned"]["paper64"]))];
        for l in &d.layouts {
            r.push(format!("{} / {} / {}", mib(f(&l["live"])), mib(f(&l["heap"])), mib(f(&l["rss"]))));
        }
        r.push(match &d.octomap {
            Some(om) => format!("{} / {} / {}", mib(f(&om["formula"])), mib(f(&om["heap"])), mib(f(&om["rss"]))),
            None => "–".into(),
        });
        rows.push(r);
    }
    let hdr: Vec<&str> = headers.iter().map(String::as_str).collect();
    let right: Vec<bool> = (0..hdr.len()).map(|i| i > 0).collect();
    w(&mut md, &table(&hdr, &right, &rows));
    w(&mut md, "");
    w(&mut md, "Bytes per node (requested / heap), and peak requested bytes during the build relative to the final:");
    w(&mut md, "");
    let mut headers: Vec<String> = vec!["dataset".into()];
    for (_, label, _) in LAYOUTS {
        headers.push(format!("{label}: B/node (peak ×)"));
    }
    headers.push("OctoMap heap B/node".into());
    let mut rows = Vec::new();
    for d in ds {
        let nodes = f(&d.stats["pruned"]["nodes"]);
        let mut r = vec![name(d)];
        for l in &d.layouts {
            r.push(format!(
                "{:.1} / {:.1} ({:.2}×)",
                f(&l["live"]) / nodes,
                f(&l["heap"]) / nodes,
                f(&l["peak"]) / f(&l["live"]).max(1.0)
            ));
        }
        r.push(d.octomap.as_ref().map_or("–".into(), |om| format!("{:.1}", f(&om["heap"]) / nodes)));
        rows.push(r);
    }
    let hdr: Vec<&str> = headers.iter().map(String::as_str).collect();
    let right: Vec<bool> = (0..hdr.len()).map(|i| i > 0).collect();
    w(&mut md, &table(&hdr, &right, &rows));
    w(&mut md, "");

    // --- targets
    w(&mut md, "## The project's targets");
    w(&mut md, "");
    w(
        &mut md,
        "Target 1: the default in-memory layout (`OccupancyTree` as `insert_point_cloud` builds it, i.e. *arena, \
         batch*, not compacted) at most 1/4 of the pointer layout's measured bytes. Target 2: at most 1/3 of \
         OctoMap's resident memory on the same map. Ratios are octolinear ÷ other; ✅ = met.",
    );
    w(&mut md, "");
    let mut rows = Vec::new();
    let (ab, ac, p) = (layout_index("arena-batch"), layout_index("arena-compact"), layout_index("pointer"));
    let mark = |x: f64, lim: f64| if x <= lim { format!("{x:.3} ✅") } else { format!("{x:.3} ❌") };
    for d in ds {
        let a = &d.layouts[ab];
        let c = &d.layouts[ac];
        let pt = &d.layouts[p];
        let frac = f(&d.stats["pruned"]["inner"]) / f(&d.stats["pruned"]["nodes"]);
        let voxels = f(&d.stats["pruned"]["voxels"]) / f(&d.stats["pruned"]["nodes"]);
        let mut r = vec![
            name(d),
            format!("{frac:.3}"),
            format!("{voxels:.3}"),
            format!("{:.3}", (9.0 - 5.0 * voxels) / (16.0 + 64.0 * frac)),
            mark(f(&a["live"]) / f(&pt["live"]), 0.25),
            mark(f(&a["heap"]) / f(&pt["heap"]), 0.25),
            mark(f(&c["live"]) / f(&pt["live"]), 0.25),
        ];
        match &d.octomap {
            Some(om) => {
                r.push(mark(f(&a["rss"]) / f(&om["rss"]), 1.0 / 3.0));
                r.push(mark(f(&a["heap"]) / f(&om["heap"]), 1.0 / 3.0));
                r.push(mark(f(&c["rss"]) / f(&om["rss"]), 1.0 / 3.0));
            }
            None => r.extend(["–".to_string(), "–".to_string(), "–".to_string()]),
        }
        rows.push(r);
    }
    w(
        &mut md,
        &table(
            &[
                "dataset",
                "f",
                "v",
                "bound",
                "T1 requested",
                "T1 heap",
                "T1 requested, compacted",
                "T2 RSS",
                "T2 heap",
                "T2 RSS, compacted",
            ],
            &[false, true, true, true, true, true, true, true, true, true],
            &rows,
        ),
    );
    w(&mut md, "");
    w(
        &mut md,
        "Reading: the arena holds 9 B per node above depth 16 and 4 B per depth-16 voxel (value-only leaf pool), \
         `9 − 5·v` B per node where `v` is the fraction of nodes at depth 16 (column *v*); the pointer tree holds \
         `16 + 64·f` B per node where `f` is the fraction of inner nodes (column *f*). So on requested bytes the \
         ratio is bounded below by `(9 − 5·v) / (16 + 64·f)` (column *bound*: growth slack of the arena's vectors \
         and free runs come on top unless compacted). Against malloc's real footprint (heap: a 16 B box is a 32 B chunk, a 64 B child \
         array an 80 B chunk) the pointer tree costs `32 + 80·f` B per node.",
    );
    w(&mut md, "");
    // --- speed
    w(&mut md, "## Speed per layout");
    w(&mut md, "");
    w(
        &mut md,
        &format!(
            "Insertion: applying all scans' key lists (ns per key update; for OctoMap `insertPointCloud` end to end \
             including its own ray casting, and octolinear's `insert_point_cloud` end to end on {} threads, in the \
             last columns). Search: {} `search(key)` queries (half occupied voxels, half uniform in the \
             map's box), best of {}. Iteration: all leaves, best of {}. Rays: {} casts through the trait \
             (`ablation::cast_ray`, unknown cells ignored, max range min(sensor range, 50 m)); OctoMap runs its own \
             `castRay` with the same arguments. Times in ns per item; *arena, batch + compact* includes the \
             compaction. The machine is shared (see the load averages above): with a load above its core count, \
             timings carry tens of percent of noise, and the memory figures none.",
            d_threads(ds),
            count(o.queries as u64),
            o.reps,
            o.reps,
            count(o.rays as u64)
        ),
    );
    w(&mut md, "");
    let mut headers: Vec<String> = vec!["dataset".into(), "measure".into()];
    for (_, label, _) in LAYOUTS {
        headers.push(label.to_string());
    }
    headers.push("OctoMap".into());
    headers.push("octolinear `insert_point_cloud`".into());
    let mut rows = Vec::new();
    for d in ds {
        let updates = u(&d.layouts[0]["updates"]) as usize;
        let pts = u(&d.stats["points"]) as usize;
        let mut ins = vec![name(d), "insert (ns/update)".into()];
        let mut sea = vec![String::new(), "search (ns/query)".into()];
        let mut it = vec![String::new(), "leaf iteration (ns/leaf)".into()];
        let mut ray = vec![String::new(), "cast ray (µs/ray)".into()];
        for l in &d.layouts {
            ins.push(ns_per(f(&l["insert_s"]) + f(&l["finish_s"]), updates));
            sea.push(ns_per(f(&l["search_s"]), u(&l["search_n"]) as usize));
            it.push(ns_per(f(&l["iter_s"]), u(&l["leaves"]) as usize));
            ray.push(format!("{:.2}", f(&l["ray_s"]) * 1e6 / f(&l["rays"]).max(1.0)));
        }
        match &d.octomap {
            Some(om) => {
                ins.push(format!("{} ({} ns/point)", secs(f(&om["insert_s"])), ns_per(f(&om["insert_s"]), pts)));
                sea.push(ns_per(f(&om["search_s"]), u(&om["search_n"]) as usize));
                it.push(ns_per(f(&om["iter_s"]), u(&om["leaves"]) as usize));
                ray.push(format!("{:.2}", f(&om["ray_s"]) * 1e6 / f(&om["rays"]).max(1.0)));
            }
            None => {
                for r in [&mut ins, &mut sea, &mut it, &mut ray] {
                    r.push("–".into());
                }
            }
        }
        let api = &d.stats["api"];
        ins.push(format!("{} ({} ns/point)", secs(f(&api["insert_s"])), ns_per(f(&api["insert_s"]), pts)));
        for r in [&mut sea, &mut it, &mut ray] {
            r.push(String::new());
        }
        rows.extend([ins, sea, it, ray]);
    }
    let hdr: Vec<&str> = headers.iter().map(String::as_str).collect();
    let right: Vec<bool> = (0..hdr.len()).map(|i| i > 1).collect();
    w(&mut md, &table(&hdr, &right, &rows));
    w(&mut md, "");
    // consistency
    let mut consistent = true;
    for d in ds {
        let s0 = &d.layouts[0]["search_sum"];
        let r0 = &d.layouts[0]["ray_check"];
        let i0 = &d.layouts[0]["iter_sum"];
        for l in &d.layouts {
            consistent &= l["search_sum"] == *s0 && l["ray_check"] == *r0 && l["iter_sum"] == *i0;
            consistent &= l["nodes"] == d.layouts[0]["nodes"];
        }
        if let Some(om) = &d.octomap {
            consistent &= om["search_sum"] == *s0 && om["nodes"] == d.stats["pruned"]["nodes"];
        }
    }
    w(
        &mut md,
        &format!(
            "Cross-check: every layout returned the same search checksum, leaf-iteration checksum, ray-hit checksum \
             and node count on every dataset{}: {}.",
            if o.oracle { ", and OctoMap the same search checksum and node count" } else { "" },
            if consistent { "yes" } else { "**NO — see the raw data**" }
        ),
    );
    w(&mut md, "");

    // --- plots
    w(&mut md, "## Memory over the scan sequence (the paper's Fig. 14)");
    w(&mut md, "");
    for &scene in &o.scenes {
        let finest = o.resolutions(scene).iter().copied().fold(f64::MAX, f64::min);
        let Some(d) = ds.iter().find(|d| d.scene == scene && d.res == finest) else { continue };
        let mut series = Vec::new();
        for (i, (_, label, _)) in LAYOUTS.iter().enumerate() {
            if ["arena-key", "split8", "mapped"].contains(&LAYOUTS[i].0) {
                continue; // same curves as arena-batch / block8 / arena-batch
            }
            let pts = d.layouts[i]["series_live"]
                .as_array()
                .map(|a| a.iter().enumerate().map(|(k, v)| ((k + 1) as f64, f(v) / 1048576.0)).collect())
                .unwrap_or_default();
            series.push(Series { name: label.to_string(), points: pts, dashed: false });
        }
        let pts = d.layouts[layout_index("pointer")]["series_heap"]
            .as_array()
            .map(|a| a.iter().enumerate().map(|(k, v)| ((k + 1) as f64, f(v) / 1048576.0)).collect())
            .unwrap_or_default();
        series.push(Series { name: "pointer (heap)".into(), points: pts, dashed: true });
        if let Some(om) = &d.octomap {
            let pts = om["series_heap"]
                .as_array()
                .map(|a| a.iter().enumerate().map(|(k, v)| ((k + 1) as f64, f(v) / 1048576.0)).collect())
                .unwrap_or_default();
            series.push(Series { name: "OctoMap (heap)".into(), points: pts, dashed: false });
            let pts = om["series_formula"]
                .as_array()
                .map(|a| a.iter().enumerate().map(|(k, v)| ((k + 1) as f64, f(v) / 1048576.0)).collect())
                .unwrap_or_default();
            series.push(Series { name: "OctoMap memoryUsage()".into(), points: pts, dashed: true });
        }
        let chart = Chart {
            title: format!("Memory over {} scans, {} scene at {} m", d.scans, scene_name(scene), d.res),
            x_label: "scans integrated".into(),
            y_label: "MiB".into(),
            log_x: false,
            log_y: false,
            series,
        };
        let file = format!("memory_over_scans_{}.svg", scene_name(scene));
        std::fs::write(plots.join(&file), chart.to_svg()).unwrap();
        w(&mut md, &format!("![memory over scans, {}](ablation/{file})", scene_name(scene)));
        w(&mut md, "");
    }
    w(&mut md, "## Memory versus resolution (the paper's Fig. 15)");
    w(&mut md, "");
    for &scene in &o.scenes {
        let mut d: Vec<&Dataset> = ds.iter().filter(|d| d.scene == scene).collect();
        d.sort_by(|a, b| a.res.total_cmp(&b.res));
        if d.is_empty() {
            continue;
        }
        let mut series = vec![Series {
            name: "full 3D grid".into(),
            points: d.iter().map(|d| (d.res, f(&d.stats["full_grid"]) / 1048576.0)).collect(),
            dashed: true,
        }];
        series.push(Series {
            name: "no compression (model)".into(),
            points: d.iter().map(|d| (d.res, f(&d.stats["unpruned"]["paper64"]) / 1048576.0)).collect(),
            dashed: true,
        });
        for (i, (id, label, _)) in LAYOUTS.iter().enumerate() {
            if *id == "arena-key" || *id == "split8" {
                continue;
            }
            series.push(Series {
                name: label.to_string(),
                points: d.iter().map(|d| (d.res, f(&d.layouts[i]["live"]) / 1048576.0)).collect(),
                dashed: false,
            });
        }
        if d.iter().all(|d| d.octomap.is_some()) {
            series.push(Series {
                name: "OctoMap (heap)".into(),
                points: d.iter().map(|d| (d.res, f(&d.octomap.as_ref().unwrap()["heap"]) / 1048576.0)).collect(),
                dashed: false,
            });
        }
        series.push(Series {
            name: ".bt file".into(),
            points: d.iter().map(|d| (d.res, f(&d.stats["bt"]) / 1048576.0)).collect(),
            dashed: true,
        });
        let chart = Chart {
            title: format!("Memory vs resolution, {} scene ({} scans)", scene_name(scene), d[0].scans),
            x_label: "resolution (m)".into(),
            y_label: "MiB (log)".into(),
            log_x: true,
            log_y: true,
            series,
        };
        let file = format!("memory_vs_resolution_{}.svg", scene_name(scene));
        std::fs::write(plots.join(&file), chart.to_svg()).unwrap();
        w(&mut md, &format!("![memory vs resolution, {}](ablation/{file})", scene_name(scene)));
        w(&mut md, "");
    }
    w(
        &mut md,
        "Solid lines: measured bytes — requested bytes (counting allocator) for the Rust layouts, glibc heap for \
         OctoMap. Dashed lines: the pointer layout's glibc heap, OctoMap's `memoryUsage()`, the paper's model for \
         the unpruned tree, the full grid and the `.bt` file size. *arena, batch + compact* is compacted once, after \
         the last scan (the last point of its curve over scans). *arena, per key* and *split8* are left out of the \
         plots: their curves coincide with *arena, batch* and *block8* (see the tables); so does *mapped (.olm)*'s \
         curve over scans until its last point, so it is only in the plots over resolution.",
    );
    w(&mut md, "");
    w(&mut md, "## What is not here");
    w(&mut md, "");
    w(
        &mut md,
        "* The mapped layout is measured from a `Vec`; an `Mmap` of the same bytes runs the same code, but its \
         resident memory depends on which pages were touched (see `docs/benchmarks.md`, memory-mapped maps).",
    );
    w(
        &mut md,
        "* `ablation::cast_ray` is a simplified `castRay` (key stepping from `RayKeys` plus a search per voxel, \
         no look past the range); it measures storage, not OctoMap's exact ray semantics. OctoMap's figure uses \
         its real `castRay`.",
    );
    w(
        &mut md,
        "* The counting allocator adds two relaxed atomic updates per allocation to every Rust layout (most to \
         the pointer layout, which allocates per node).",
    );
    w(&mut md, "");
    w(&mut md, "## Raw data");
    w(&mut md, "");
    w(&mut md, "Every child's JSON output, for reruns and checks:");
    w(&mut md, "");
    w(&mut md, "<details><summary>JSON</summary>");
    w(&mut md, "");
    w(&mut md, "```json");
    for d in ds {
        let mut layouts = serde_json::Map::new();
        for (i, (id, _, _)) in LAYOUTS.iter().enumerate() {
            let mut v = d.layouts[i].clone();
            if let Some(m) = v.as_object_mut() {
                m.remove("series_heap");
                m.remove("series_nodes");
            }
            layouts.insert(id.to_string(), v);
        }
        let mut stats = d.stats.clone();
        if let Some(m) = stats.as_object_mut() {
            m.remove("series_octomap_formula");
        }
        let mut om = d.octomap.clone().unwrap_or(Value::Null);
        if let Some(m) = om.as_object_mut() {
            m.remove("series_heap");
            m.remove("series_formula");
        }
        let v = json!({"dataset": name(d), "scans": d.scans, "stats": stats, "layouts": layouts, "octomap": om});
        w(&mut md, &v.to_string());
    }
    w(&mut md, "```");
    w(&mut md, "");
    w(&mut md, "</details>");
    let path = o.out.join("ablation.md");
    let mut f = std::fs::File::create(&path).unwrap();
    f.write_all(md.as_bytes()).unwrap();
    eprintln!("wrote {} and {}", path.display(), plots.display());
}

fn d_threads(ds: &[Dataset]) -> u64 {
    ds.first().map_or(0, |d| u(&d.stats["api"]["threads"]))
}
