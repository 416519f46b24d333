//! Side-by-side benchmark: the same jobs through OctoMap (the oracle crate,
//! Debian's liboctomap behind a C++ shim) and octolinear, alternately, in
//! one process. Each figure is the median of several repetitions.
//!
//! Run with `cargo bench -p octolinear-benches --bench side_by_side` (add `-- --quick` for a
//! small run, `-- --full` for the full-size sequences; `-- --help` lists the options).

mod common;
#[path = "side_by_side/full.rs"]
mod full;

use common::*;
use octolinear::formats::{bt, ot};
use octolinear::mapped;
use octolinear::{CastOptions, Found, OccupancyTree, Point3, SearchIndex};
use octolinear_oracle::{OracleTree, ScanBatch};
use octolinear_sim::SceneKind;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Insertion runs at most (see `Args::insert_budget`): on a shared VM a
/// small map's runs swing by a third, and its medians need many runs.
const MAX_INSERT_REPS: usize = 21;

struct Args {
    reps: usize,
    insert_reps: usize,
    /// More insertion runs (up to `MAX_INSERT_REPS`) while OctoMap's runs
    /// of the map total less than this many seconds.
    insert_budget: f64,
    scenes: Vec<SceneKind>,
    resolutions: Vec<f64>,
    indoor_scans: usize,
    outdoor_scans: usize,
    queries: usize,
    rays: usize,
    /// The full-size mode's options, when it is asked for.
    full: Option<full::FullArgs>,
}

impl Args {
    fn parse() -> Args {
        let mut a = Args {
            reps: 5,
            insert_reps: 3,
            insert_budget: 3.0,
            scenes: vec![SceneKind::Indoor, SceneKind::Outdoor],
            resolutions: vec![0.05, 0.1, 0.2],
            indoor_scans: 24,
            outdoor_scans: 6,
            queries: 1_000_000,
            rays: 20_000,
            full: None,
        };
        let mut full = full::FullArgs::new();
        let mut full_asked = false;
        let mut it = std::env::args().skip(1);
        while let Some(arg) = it.next() {
            let mut value = |name: &str| it.next().unwrap_or_else(|| panic!("{name} needs a value (see --help)"));
            match arg.as_str() {
                "--quick" => {
                    a.reps = 3;
                    a.insert_reps = 1;
                    a.insert_budget = 0.0;
                    a.resolutions = vec![0.1];
                    a.indoor_scans = 6;
                    a.outdoor_scans = 2;
                    a.queries = 200_000;
                    a.rays = 5_000;
                }
                "--reps" => a.reps = value("--reps").parse().expect("--reps N"),
                "--insert-reps" => a.insert_reps = value("--insert-reps").parse().expect("--insert-reps N"),
                "--insert-budget" => {
                    a.insert_budget = value("--insert-budget").parse().expect("--insert-budget SECONDS")
                }
                "--res" => {
                    a.resolutions = value("--res").split(',').map(|s| s.parse().expect("--res R[,R...]")).collect()
                }
                "--scene" => {
                    a.scenes = match value("--scene").as_str() {
                        "indoor" => vec![SceneKind::Indoor],
                        "outdoor" => vec![SceneKind::Outdoor],
                        "both" => vec![SceneKind::Indoor, SceneKind::Outdoor],
                        s => panic!("--scene indoor|outdoor|both, not {s}"),
                    }
                }
                "--scans" => {
                    let n = value("--scans").parse().expect("--scans N");
                    a.indoor_scans = n;
                    a.outdoor_scans = n;
                }
                "--queries" => a.queries = value("--queries").parse().expect("--queries N"),
                "--rays" => a.rays = value("--rays").parse().expect("--rays N"),
                "--full" => full_asked = true,
                "--jobs" => full.jobs = full::FullArgs::parse_jobs(&value("--jobs")),
                "--octomap-budget" => {
                    full.octomap_budget = value("--octomap-budget").parse().expect("--octomap-budget SECONDS")
                }
                "--dir" => full.dir = Some(value("--dir").into()),
                "--octolinear" => full.octolinear = value("--octolinear").into(),
                "--graph2tree" => full.graph2tree = value("--graph2tree").into(),
                "--help" | "-h" => {
                    println!(
                        "side_by_side [--quick] [--reps N] [--insert-reps N] [--insert-budget SECONDS] \
                         [--res 0.05,0.1,0.2] \
                         [--scene indoor|outdoor|both] [--scans N] [--queries N] [--rays N]\n\
                         side_by_side --full [--jobs indoor:0.05,indoor:0.1,indoor:0.2,outdoor:0.1,outdoor:0.2] \
                         [--insert-reps N] [--octomap-budget SECONDS] [--dir DIR] [--octolinear PATH] \
                         [--graph2tree PATH]\n\
                         (--full: the full-size sequences, insertion against OctoMap and `octolinear build` \
                         against graph2tree; build the CLI first: cargo build --release -p octolinear-cli)"
                    );
                    std::process::exit(0);
                }
                // `cargo bench` passes `--bench`; ignore it and other harness flags
                _ => {}
            }
        }
        a.reps = a.reps.max(1);
        a.insert_reps = a.insert_reps.max(1);
        if full_asked {
            full.reps = a.insert_reps;
            a.full = Some(full);
        }
        a
    }
}

/// Median and minimum of the repetitions.
#[derive(Clone, Copy)]
struct Stat {
    median: Duration,
    min: Duration,
}

fn median(mut v: Vec<Duration>) -> Stat {
    v.sort();
    Stat { median: v[v.len() / 2], min: v[0] }
}

fn secs(d: Duration) -> f64 {
    d.as_secs_f64()
}

/// Lets the allocator finish, outside the timed regions, the work the last
/// frees left pending. OctoMap frees a tree as hundreds of thousands of
/// small chunks; glibc parks them in its fast bins, merges them at the next
/// large allocation (`malloc_consolidate`) and sorts the merged chunks into
/// its bins during the large allocations after that, at most 10,000 per
/// allocation. That work would otherwise be charged to whichever job
/// allocates next, usually octolinear's, whose arenas are a few large
/// allocations. Large allocations here do it and nothing else.
fn settle_heap() {
    let blocks: Vec<Vec<u8>> = (0..32).map(|_| black_box(Vec::with_capacity(1 << 16))).collect();
    drop(black_box(blocks));
}

/// Times `f` once.
fn time<T>(f: impl FnOnce() -> T) -> (Duration, T) {
    let t = Instant::now();
    let r = f();
    (t.elapsed(), r)
}

/// One row of the output table.
struct Row {
    job: String,
    octomap: Stat,
    octolinear: Stat,
    /// Work per run and its unit, for the rate column (e.g. points, MB).
    work: f64,
    unit: &'static str,
}

impl Row {
    fn print(&self) {
        let rate = |d: Duration| self.work / secs(d);
        let (a, b) = (self.octomap.median, self.octolinear.median);
        println!(
            "| {:<36} | {:>10.2} | {:>10.2} | {:>7.2}x | {:>7.2}x | {:>12} | {:>12} |",
            self.job,
            secs(a) * 1e3,
            secs(b) * 1e3,
            secs(a) / secs(b),
            secs(self.octomap.min) / secs(self.octolinear.min),
            fmt_rate(rate(a), self.unit),
            fmt_rate(rate(b), self.unit),
        );
    }
}

fn fmt_rate(r: f64, unit: &str) -> String {
    if unit == "MB" {
        format!("{:.0} MB/s", r)
    } else if r >= 1e6 {
        format!("{:.1} M{}/s", r / 1e6, unit)
    } else {
        format!("{:.0} k{}/s", r / 1e3, unit)
    }
}

fn header() {
    println!(
        "| {:<36} | {:>10} | {:>10} | {:>8} | {:>8} | {:>12} | {:>12} |",
        "job", "OctoMap ms", "octolin. ms", "speed-up", "(min)", "OctoMap", "octolinear"
    );
    println!("|{:-<38}|{:->12}|{:->12}|{:->10}|{:->10}|{:->14}|{:->14}|", "", ":", ":", ":", ":", ":", ":");
}

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).expect("write .ot");
    v
}

fn to_arrays(points: &[Point3]) -> Vec<[f32; 3]> {
    points.iter().map(|p| p.to_array()).collect()
}

fn run_case(args: &Args, kind: SceneKind, res: f64, scans: &[Scan]) {
    let npoints = num_points(scans);
    let mut batch = ScanBatch::new();
    for (points, origin) in scans {
        batch.push(&to_arrays(points), origin.to_array());
    }
    println!();
    println!("### {} scene, {} m: {} scans, {} points", kind_name(kind), res, scans.len(), npoints);
    println!();
    header();

    // ----- insertion (also gives the trees for the other jobs)
    let (mut t_om, mut t_1, mut t_2) = (Vec::new(), Vec::new(), Vec::new());
    let mut om = None;
    let mut ol = None;
    let mut ol2 = None;
    // the small maps' insertions take milliseconds, and single runs on a
    // shared VM swing by a third: more runs where they cost little (an odd
    // number, for a true median)
    while t_om.len() < args.insert_reps
        || (t_om.len() < MAX_INSERT_REPS
            && (t_om.iter().sum::<Duration>().as_secs_f64() < args.insert_budget || t_om.len() % 2 == 0))
    {
        drop(om.take());
        let (d, t) = time(|| {
            let mut t = OracleTree::new(res).expect("oracle tree");
            t.insert_scans(&batch, -1.0, false, false).expect("insert");
            t
        });
        t_om.push(d);
        om = Some(t);
        drop(ol.take());
        let (d, t) = time(|| build(scans, res, Some(1)));
        t_1.push(d);
        ol = Some(t);
        drop(ol2.take());
        let (d, t) = time(|| build(scans, res, Some(2)));
        t_2.push(d);
        ol2 = Some(t);
    }
    let om = om.expect("ran");
    let mut ol = ol.expect("ran");
    let om_ot = om.write_ot().expect("oracle .ot");
    let ol_ot = ot_bytes(&ol);
    assert!(
        om_ot == ol_ot,
        "{} {res} m: octolinear's .ot differs from OctoMap's ({} vs {} bytes); \
         the comparison would be meaningless",
        kind_name(kind),
        ol_ot.len(),
        om_ot.len()
    );
    assert!(ot_bytes(&ol2.take().expect("ran")) == om_ot, "2-thread tree differs");
    let runs = t_om.len();
    let (om_ins, ol1, ol2) = (median(t_om), median(t_1), median(t_2));
    for (job, d) in [("insert, 1 thread", ol1), ("insert, 2 threads", ol2)] {
        let job = format!("{job} ({runs} run{})", if runs == 1 { "" } else { "s" });
        Row { job, octomap: om_ins, octolinear: d, work: npoints as f64, unit: "pt" }.print();
    }

    let queries = query_points(&ol, args.queries, 11);
    search_and_iterate(args, &om, &ol, &queries, "");

    // ----- castRay from sensor origins, through unknown space, 20 m
    let (origins, dirs) = rays(scans, args.rays, 5);
    let (o_arr, d_arr) = (to_arrays(&origins), to_arrays(&dirs));
    let mut ends = vec![[0f32; 3]; origins.len()];
    let mut hits = vec![false; origins.len()];
    let opts = CastOptions { ignore_unknown: true, max_range: Some(20.0) };
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..args.reps {
        let (d, h_om) = time(|| om.bench_cast_rays(&o_arr, &d_arr, true, 20.0, &mut ends, &mut hits));
        a.push(d);
        let (d, h_ol) = time(|| {
            origins.iter().zip(&dirs).filter(|(&o, &dir)| ol.cast_ray(o, dir, opts).is_ok_and(|c| c.hit())).count()
        });
        b.push(d);
        assert_eq!(h_om, h_ol, "castRay: different hit counts");
    }
    Row {
        job: "castRay (20 m, ign. unknown)".into(),
        octomap: median(a),
        octolinear: median(b),
        work: origins.len() as f64,
        unit: "ray",
    }
    .print();

    // ----- .ot write / read
    let mb = om_ot.len() as f64 / 1e6;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..args.reps {
        let (d, v) = time(|| om.write_ot().expect("write"));
        a.push(d);
        drop(v);
        settle_heap();
        let (d, v) = time(|| {
            let mut v = Vec::with_capacity(ol_ot.len());
            ot::write(&ol, &mut v).expect("write");
            v
        });
        b.push(d);
        drop(v);
        settle_heap();
    }
    Row { job: format!(".ot write ({:.1} MB)", mb), octomap: median(a), octolinear: median(b), work: mb, unit: "MB" }
        .print();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..args.reps {
        let (d, t) = time(|| OracleTree::read_ot(&om_ot).expect("read"));
        a.push(d);
        drop(t);
        settle_heap();
        let (d, t) = time(|| ot::read(&ol_ot[..]).expect("read"));
        b.push(d);
        drop(t);
        settle_heap();
    }
    Row { job: ".ot read".into(), octomap: median(a), octolinear: median(b), work: mb, unit: "MB" }.print();

    // ----- .bt write (writeBinary: max-likelihood + prune, then write) / read
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut bt_bytes = Vec::new();
    for _ in 0..args.reps {
        // OctoMap's writeBinary changes the tree: write from a fresh copy
        let mut copy = OracleTree::read_ot(&om_ot).expect("read");
        let (d, v) = time(|| copy.write_bt().expect("write"));
        a.push(d);
        drop(copy);
        settle_heap();
        let (d, w) = time(|| {
            let mut w = Vec::with_capacity(v.len());
            bt::write(&ol, &mut w).expect("write");
            w
        });
        b.push(d);
        assert!(v == w, ".bt bytes differ");
        bt_bytes = w;
    }
    let mb = bt_bytes.len() as f64 / 1e6;
    Row { job: format!(".bt write ({:.2} MB)", mb), octomap: median(a), octolinear: median(b), work: mb, unit: "MB" }
        .print();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..args.reps {
        let (d, t) = time(|| OracleTree::read_bt(&bt_bytes).expect("read"));
        a.push(d);
        drop(t);
        settle_heap();
        let (d, t) = time(|| bt::read(&bt_bytes[..]).expect("read"));
        b.push(d);
        drop(t);
        settle_heap();
    }
    Row { job: ".bt read".into(), octomap: median(a), octolinear: median(b), work: mb, unit: "MB" }.print();

    // ----- memory
    let nodes = ol.size();
    assert_eq!(om.size() as usize, nodes);
    let om_mem = om.memory_usage() as usize;
    let before = ol.memory_usage();
    ol.compact();
    let after = ol.memory_usage();
    println!();
    println!(
        "memory, {} nodes: OctoMap memoryUsage() {:.1} MB ({:.1} B/node); \
         octolinear memory_usage() {:.1} MB ({:.2} B/node) as built, \
         {:.1} MB ({:.2} B/node) after compact() — {:.1}x smaller",
        nodes,
        om_mem as f64 / 1e6,
        om_mem as f64 / nodes as f64,
        before as f64 / 1e6,
        before as f64 / nodes as f64,
        after as f64 / 1e6,
        after as f64 / nodes as f64,
        om_mem as f64 / after as f64,
    );
    println!();
    header();
    search_and_iterate(args, &om, &ol, &queries, " (compacted)");
    indexed_rows(args, &om, &ol, &queries);
    mapped_rows(args, &om, &ol, &queries, scans);
}

/// Runs both jobs alternately `reps` times and checks that they agree.
fn race<T: PartialEq + std::fmt::Debug>(
    reps: usize,
    what: &str,
    mut octomap: impl FnMut() -> T,
    mut octolinear: impl FnMut() -> T,
) -> (Stat, Stat) {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let (d, x) = time(&mut octomap);
        a.push(d);
        let (d, y) = time(&mut octolinear);
        b.push(d);
        assert_eq!(x, y, "{what}: the libraries disagree");
    }
    (median(a), median(b))
}

/// OctoMap's `search(point3d)` against `search` on our side, one query
/// at a time over the same points; both read every value found.
fn race_search(
    args: &Args,
    om: &OracleTree,
    queries: &[Point3],
    what: &str,
    search: impl Fn(Point3) -> Option<Found>,
) -> (Stat, Stat) {
    let q_arr = to_arrays(queries);
    let mut out = vec![0f32; queries.len()];
    race(
        args.reps,
        what,
        || om.bench_search(&q_arr, 0, &mut out),
        || {
            queries
                .iter()
                .filter_map(|&p| search(p))
                .inspect(|f| {
                    black_box(f.value);
                })
                .count()
        },
    )
}

/// The map written to `.olm` and queried in place (from a `Vec`; an mmap'd
/// file runs the same code) against OctoMap's in-memory tree.
fn mapped_rows(args: &Args, om: &OracleTree, ol: &OccupancyTree, queries: &[Point3], scans: &[Scan]) {
    // with the search blocks where they pay (2^17+ nodes at depths 13-15)
    let opts = mapped::WriteOptions { search_blocks: mapped::SearchBlocksSection::Auto, ..Default::default() };
    let bytes = mapped::to_bytes(ol, opts).expect("write .olm");
    let plain = mapped::to_bytes(ol, mapped::WriteOptions::default()).expect("write .olm").len();
    let map = mapped::MappedMap::new(bytes).expect("open .olm");
    let view = map.view();
    println!();
    let blocks = match map.bytes().len() - plain {
        0 => String::new(),
        extra => format!(", {:.1} MB of it the search-blocks section", extra as f64 / 1e6),
    };
    println!("`.olm` ({:.1} MB{blocks}), queried in place:", map.bytes().len() as f64 / 1e6);
    println!();
    header();
    let q_arr = to_arrays(queries);
    let row = |job: &str, (octomap, octolinear): (Stat, Stat), work: usize, unit| {
        Row { job: format!("mapped: {job}"), octomap, octolinear, work: work as f64, unit }.print()
    };
    let n = queries.len();
    let times = race_search(args, om, queries, "search", |p| view.search_point(p, 0).ok().flatten());
    row("random search", times, n, "q");
    let mut out = vec![0f32; queries.len()];
    let (mut keys, mut found) = (Vec::new(), Vec::new());
    let times = race(
        args.reps,
        "search_many",
        || om.bench_search(&q_arr, 0, &mut out),
        || {
            keys.clear();
            keys.extend(queries.iter().filter_map(|&p| view.key_space().key(p).ok()));
            view.search_many(&keys, 0, &mut found);
            found.iter().filter(|f| f.is_some()).count()
        },
    );
    row("random search, batched", times, n, "q");
    let t = Instant::now();
    let index = mapped::MapSearchIndex::new(view);
    println!(
        "mapped search index: depth {}, {:.2} MB, built in {:.2} ms",
        index.depth(),
        index.bytes() as f64 / 1e6,
        t.elapsed().as_secs_f64() * 1e3
    );
    let times = race_search(args, om, queries, "indexed search", |p| index.search(view.key(p).ok()?, 0));
    row("random search, indexed", times, n, "q");
    let leaves = ol.num_leaves();
    let times = race(
        args.reps,
        "leaf iteration",
        || om.bench_leaf_sum(0),
        || view.leaves(0).fold((0, 0f64), |(n, s), l| (n + 1, s + f64::from(l.value))),
    );
    row("leaf iteration", times, leaves, "leaf");
    let (origins, dirs) = rays(scans, args.rays, 5);
    let (o_arr, d_arr) = (to_arrays(&origins), to_arrays(&dirs));
    let mut ends = vec![[0f32; 3]; origins.len()];
    let mut hits = vec![false; origins.len()];
    let opts = CastOptions { ignore_unknown: true, max_range: Some(20.0) };
    let times = race(
        args.reps,
        "castRay",
        || om.bench_cast_rays(&o_arr, &d_arr, true, 20.0, &mut ends, &mut hits),
        || origins.iter().zip(&dirs).filter(|(&o, &d)| view.cast_ray(o, d, opts).is_ok_and(|c| c.hit())).count(),
    );
    row("castRay (20 m, ign. unknown)", times, origins.len(), "ray");
}

/// Random search through a [`SearchIndex`] (level-skip hash table) on the
/// compacted tree, one query at a time and batched.
fn indexed_rows(args: &Args, om: &OracleTree, ol: &OccupancyTree, queries: &[Point3]) {
    let t = Instant::now();
    let index = SearchIndex::new(ol);
    let built = t.elapsed();
    println!(
        "search index: depth {}, {:.2} MB ({:.2} B/node), built in {:.1} ms",
        index.depth(),
        index.bytes() as f64 / 1e6,
        index.bytes() as f64 / ol.calc_num_nodes() as f64,
        built.as_secs_f64() * 1e3
    );
    let q_arr = to_arrays(queries);
    let keys: Vec<_> = queries.iter().filter_map(|&p| ol.key(p).ok()).collect();
    let mut out = vec![0f32; queries.len()];
    let row = |job: &str, (octomap, octolinear): (Stat, Stat)| {
        Row { job: job.to_string(), octomap, octolinear, work: queries.len() as f64, unit: "q" }.print()
    };
    let times = race_search(args, om, queries, "indexed search", |p| index.search(ol.key(p).ok()?, 0));
    row("random search, indexed", times);
    let mut found = Vec::with_capacity(keys.len());
    let times = race(
        args.reps,
        "indexed search_many",
        || om.bench_search(&q_arr, 0, &mut out),
        || {
            index.search_many(&keys, 0, &mut found);
            found.iter().filter(|f| f.is_some()).count()
        },
    );
    row("random search, indexed + batched", times);
}

/// Random point search (one query at a time, then batched) and full leaf
/// iteration on the same tree in both libraries.
fn search_and_iterate(args: &Args, om: &OracleTree, ol: &OccupancyTree, queries: &[Point3], suffix: &str) {
    let q_arr = to_arrays(queries);
    let row = |job: &str, (octomap, octolinear): (Stat, Stat), work: usize, unit| {
        Row { job: format!("{job}{suffix}"), octomap, octolinear, work: work as f64, unit }.print()
    };
    // random search (half leaf centres, half uniform in the bounds)
    let times = race_search(args, om, queries, "search", |p| ol.search_point(p, 0).ok().flatten());
    row("random search", times, queries.len(), "q");
    // the same queries through search_many (eight descents in lockstep)
    let mut out = vec![0f32; queries.len()];
    let (mut keys, mut found) = (Vec::with_capacity(queries.len()), Vec::with_capacity(queries.len()));
    let times = race(
        args.reps,
        "search_many",
        || om.bench_search(&q_arr, 0, &mut out),
        || {
            keys.clear();
            keys.extend(queries.iter().filter_map(|&p| ol.key(p).ok()));
            ol.search_many(&keys, 0, &mut found);
            found.iter().filter(|f| f.is_some()).count()
        },
    );
    row("random search, batched", times, queries.len(), "q");
    // full leaf iteration
    let times = race(
        args.reps,
        "leaf iteration",
        || om.bench_leaf_sum(0),
        || ol.leaves(0).fold((0, 0f64), |(n, s), l| (n + 1, s + f64::from(l.value))),
    );
    row("leaf iteration", times, ol.num_leaves(), "leaf");
}

fn main() {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    if argv.first().map(String::as_str) == Some(full::LAUNCH) {
        full::launch(&argv[1..]);
    }
    if !octolinear_oracle::available() {
        println!(
            "side_by_side: skipped, OctoMap oracle unavailable \
             (install: apt-get install -y liboctomap-dev)"
        );
        return;
    }
    let args = Args::parse();
    if let Some(full) = &args.full {
        full::run_full(full);
        return;
    }
    println!(
        "side_by_side: OctoMap {} (system library via the oracle shim) vs octolinear; \
         median of {} runs ({} or more for insertion: up to {MAX_INSERT_REPS} while OctoMap's \
         insertion runs of a map total under {} s); times in ms; speed-up = OctoMap time / \
         octolinear time, of the medians and (min) of the fastest runs; rates from the medians",
        octolinear_oracle::octomap_version().unwrap_or("?"),
        args.reps,
        args.insert_reps,
        args.insert_budget
    );
    for &kind in &args.scenes {
        let n = match kind {
            SceneKind::Indoor => args.indoor_scans,
            SceneKind::Outdoor => args.outdoor_scans,
        };
        let scans = scans(kind, n);
        for &res in &args.resolutions {
            run_case(&args, kind, res, &scans);
        }
    }
    println!();
    println!(
        "peak RSS of the process (VmHWM): {} — OctoMap and octolinear trees live in the \
         same process, so this is not separable per library",
        peak_rss()
    );
}

fn peak_rss() -> String {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).map(|l| l.trim_start_matches("VmHWM:").trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}
