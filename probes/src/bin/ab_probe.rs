//! One job per run on the side-by-side benchmark's scenes and query mix, for
//! comparing two builds (run their binaries alternately) and for callgrind:
//! `cargo run --release -p octolinear-probes --bin ab_probe -- indoor|outdoor RES JOB [compact]`.
//!
//! * `time`: fastest of 9 passes over 1M queries, in ns per query: search by
//!   key and by point on the tree, `search_many`, by key and by point on
//!   the mapped view, and its `search_many`.
//! * `race`: OctoMap's search over the 1M points, then ours by point, five
//!   times, as the benchmark alternates them (each evicts the other's data).
//! * `leaves`: eight rounds of OctoMap's leaf walk followed by ours twice (as
//!   the benchmark alternates them), then the spread of 200 of ours back to
//!   back (the branch predictor learns a walk that repeats).
//! * `mleaves`: the same for the mapped view's leaf walk.
//! * `fold`, `search`, `mapped`: the leaf fold 100 times, or 200k searches
//!   twice (`search`: and once by point), and nothing else timed; for
//!   `valgrind --tool=callgrind --toggle-collect='*ab_probe::fold*'` (or
//!   `*ab_probe::by_key*`, `*ab_probe::by_point*`, `*ab_probe::view_by_key*`).
//! * `sorted`: by key on the mixed queries, then on the same grouped by
//!   answer depth (the difference: the descent's mispredicted exits).
//! * `depths`: how deep the queries' answers lie (the last entry: no answer).
//!
//! `compact` compacts the tree first. A probe, not a benchmark of record.
#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::mapped::{self, MapView, MappedMap};
use octolinear::{Key, OccupancyTree, Point3};
use octolinear_oracle::{OracleTree, ScanBatch};
use octolinear_sim::SceneKind;
use std::hint::black_box;
use std::time::Instant;

#[inline(never)]
fn by_key(t: &OccupancyTree, keys: &[Key]) -> f32 {
    keys.iter().filter_map(|&k| t.search(k, 0)).map(|f| f.value).sum()
}

#[inline(never)]
fn by_point(t: &OccupancyTree, points: &[Point3]) -> f32 {
    points.iter().filter_map(|&p| t.search_point(p, 0).ok().flatten()).map(|f| f.value).sum()
}

#[inline(never)]
fn many(t: &OccupancyTree, keys: &[Key]) -> f32 {
    let mut found = Vec::new();
    t.search_many(keys, 0, &mut found);
    found.iter().flatten().map(|f| f.value).sum()
}

#[inline(never)]
fn view_by_key(v: &MapView<'_>, keys: &[Key]) -> f32 {
    keys.iter().filter_map(|&k| v.search(k, 0)).map(|f| f.value).sum()
}

#[inline(never)]
fn view_many(v: &MapView<'_>, keys: &[Key]) -> f32 {
    let mut found = Vec::new();
    v.search_many(keys, 0, &mut found);
    found.iter().flatten().map(|f| f.value).sum()
}

#[inline(never)]
fn view_by_point(v: &MapView<'_>, points: &[Point3]) -> f32 {
    points.iter().filter_map(|&p| v.search_point(p, 0).ok().flatten()).map(|f| f.value).sum()
}

#[inline(never)]
fn fold(t: &OccupancyTree) -> (usize, f64) {
    t.leaves(0).fold((0, 0f64), |(n, s), l| (n + 1, s + f64::from(l.value)))
}

/// OctoMap's tree of the same scans.
fn oracle(scans: &[common::Scan], res: f64) -> OracleTree {
    let mut batch = ScanBatch::new();
    for (cloud, origin) in scans {
        let v: Vec<[f32; 3]> = cloud.iter().map(|p| p.to_array()).collect();
        batch.push(&v, origin.to_array());
    }
    let mut om = OracleTree::new(res).expect("oracle");
    om.insert_scans(&batch, -1.0, false, false).expect("insert");
    om
}

/// Microseconds of one run of `f`, and its result.
fn micros<T>(f: impl FnOnce() -> T) -> (f64, T) {
    let t = Instant::now();
    let r = black_box(f());
    (t.elapsed().as_secs_f64() * 1e6, r)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        eprintln!("ab_probe indoor|outdoor RES time|race|leaves|mleaves|fold|search|mapped|depths [compact]");
        std::process::exit(2);
    }
    let kind = if args[0] == "outdoor" { SceneKind::Outdoor } else { SceneKind::Indoor };
    let res: f64 = args[1].parse().expect("RES");
    let scans = common::scans(kind, if kind == SceneKind::Indoor { 24 } else { 6 });
    let mut tree = common::build(&scans, res, None);
    if args.get(3).map(String::as_str) == Some("compact") {
        tree.compact();
    }
    let n = if args[2] == "time" || args[2] == "race" { 1_000_000 } else { 200_000 };
    let points = common::query_points(&tree, n, 11);
    let keys: Vec<Key> = points.iter().map(|&p| tree.key(p).expect("in the map")).collect();
    // the search blocks where they pay, as the benchmark writes them
    let opts = mapped::WriteOptions { search_blocks: mapped::SearchBlocksSection::Auto, ..Default::default() };
    let bytes = mapped::to_bytes(&tree, opts).expect("olm");
    let map = MappedMap::new(bytes).expect("view");
    let view = map.view();
    match args[2].as_str() {
        "time" => {
            let best = |f: &dyn Fn() -> f32| (0..9).map(|_| micros(f).0 * 1e3 / n as f64).fold(f64::MAX, f64::min);
            println!(
                "ns per query: tree by key {:6.2}, by point {:6.2}, search_many {:6.2}; \
                 mapped by key {:6.2}, by point {:6.2}, search_many {:6.2}",
                best(&|| by_key(&tree, &keys)),
                best(&|| by_point(&tree, &points)),
                best(&|| many(&tree, &keys)),
                best(&|| view_by_key(&view, &keys)),
                best(&|| view_by_point(&view, &points)),
                best(&|| view_many(&view, &keys)),
            );
        }
        "race" => {
            let om = oracle(&scans, res);
            let q: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
            let mut out = vec![0f32; q.len()];
            for _ in 0..5 {
                let (theirs, _) = micros(|| om.bench_search(&q, 0, &mut out));
                let (ours, _) = micros(|| by_point(&tree, &points));
                println!(
                    "OctoMap {:6.1} ns, then ours {:6.1} ns a query: {:.2}x",
                    theirs * 1e3 / n as f64,
                    ours * 1e3 / n as f64,
                    theirs / ours
                );
            }
        }
        "leaves" => {
            let om = oracle(&scans, res);
            for _ in 0..8 {
                let (theirs, a) = micros(|| om.bench_leaf_sum(0));
                let (after, b) = micros(|| fold(&tree));
                let (again, _) = micros(|| fold(&tree));
                assert_eq!(a, b, "the walks disagree");
                println!("OctoMap {theirs:7.1} us, then ours {after:6.1} us, ours again {again:6.1} us");
            }
            let mut v: Vec<f64> = (0..200).map(|_| micros(|| fold(&tree)).0).collect();
            v.sort_by(f64::total_cmp);
            println!("ours back to back: min {:.1}, median {:.1}, max {:.1} us", v[0], v[100], v[199]);
        }
        "mleaves" => {
            let om = oracle(&scans, res);
            let view_fold = || view.leaves(0).fold((0, 0f64), |(n, s), l| (n + 1, s + f64::from(l.value)));
            for _ in 0..8 {
                let (theirs, _) = micros(|| om.bench_leaf_sum(0));
                let (after, _) = micros(view_fold);
                let (again, _) = micros(view_fold);
                println!("OctoMap {theirs:7.1} us, then the view {after:6.1} us, again {again:6.1} us");
            }
        }
        "fold" => {
            for _ in 0..100 {
                black_box(fold(&tree));
            }
        }
        "search" => {
            black_box(by_key(&tree, &keys));
            black_box(by_key(&tree, &keys));
            black_box(by_point(&tree, &points));
        }
        "mapped" => {
            black_box(view_by_key(&view, &keys));
            black_box(view_by_key(&view, &keys));
        }
        "sorted" => {
            // the same keys grouped by answer depth: how much of a query's
            // time is the descent's mispredicted exits
            let mut sorted = keys.clone();
            sorted.sort_by_key(|&k| tree.search(k, 0).map_or(17, |f| f.depth));
            let best = |k: &[Key]| {
                (0..9).map(|_| micros(|| by_key(&tree, k)).0 * 1e3 / k.len() as f64).fold(f64::MAX, f64::min)
            };
            let mut by_octant = keys.clone();
            by_octant.sort_by_key(|&k| k.child_index(0));
            println!(
                "ns per query by key: mixed {:6.2}, grouped by answer depth {:6.2}, by root child {:6.2}",
                best(&keys),
                best(&sorted),
                best(&by_octant)
            );
        }
        "depths" => {
            let mut hist = [0usize; 18];
            for &k in &keys {
                hist[tree.search(k, 0).map_or(17, |f| usize::from(f.depth))] += 1;
            }
            println!("answers at depths 0..=16, then none: {hist:?}");
        }
        job => panic!("unknown job {job}"),
    }
}
