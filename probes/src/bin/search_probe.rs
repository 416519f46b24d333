//! Splits the cost of one-at-a-time random point search on a simulated map:
//! `cargo run --release -p octolinear-probes --bin search_probe -- indoor|outdoor RES [N]`.
//! Prints the fastest of several passes, in ns per query, for the key
//! conversion alone, search by key and by point, through `SearchIndex`
//! tables at depths 9-13, and on the mapped view, over the side-by-side
//! benchmark's query mix (half leaf centres, half uniform in the bounds);
//! and leaf iteration warm and cold. A probe for profiling, not a
//! benchmark of record: the recorded figures are `side_by_side`'s.
// the side-by-side benchmark's scenes and query mix
#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::mapped::{self, MappedMap};
use octolinear::{OccupancyTree, Point3};
use octolinear_sim::SceneKind;
use std::hint::black_box;
use std::time::Instant;

fn best<T>(reps: usize, mut f: impl FnMut() -> T) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            black_box(f());
            t.elapsed().as_secs_f64()
        })
        .fold(f64::MAX, f64::min)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let kind = if args.first().map(String::as_str) == Some("outdoor") { SceneKind::Outdoor } else { SceneKind::Indoor };
    let res: f64 = args.get(1).map_or(0.2, |s| s.parse().expect("RES"));
    let n: usize = args.get(2).map_or(1_000_000, |s| s.parse().expect("N"));
    let scans = common::scans(kind, if kind == SceneKind::Indoor { 24 } else { 6 });
    let tree = common::build(&scans, res, None);
    let queries = common::query_points(&tree, n, 11);
    let keys: Vec<_> = queries.iter().map(|&p| tree.key(p).unwrap()).collect();
    let reps = 7;
    let ns = |s: f64| s * 1e9 / n as f64;
    println!("{} nodes, {} leaves, {} queries", tree.size(), tree.num_leaves(), n);
    let t = best(reps, || convert_all(&tree, &queries));
    println!("key conversion      {:6.2} ns", ns(t));
    let t = best(reps, || convert_xor(&tree, &queries));
    println!("key conversion, xor {:6.2} ns", ns(t));
    let t = best(reps, || keys.iter().filter_map(|&k| tree.search(k, 0)).map(|f| f.value).sum::<f32>());
    println!("search(key)         {:6.2} ns", ns(t));
    let t = best(reps, || search_points(&tree, &queries));
    println!("search_point        {:6.2} ns", ns(t));
    let nl = tree.num_leaves() as f64;
    let t = best(200, || tree.leaves(0).fold((0usize, 0f64), |(n, s), l| (n + 1, s + f64::from(l.value))));
    println!("leaf fold           {:6.2} ns/leaf ({:.1} us)", t * 1e9 / nl, t * 1e6);
    let t = cold_fold(&tree);
    println!("leaf fold, cold     {:6.2} ns/leaf ({:.1} us)", t * 1e9 / nl, t * 1e6);
    let mut compacted = tree.clone();
    compacted.compact();
    let t = cold_fold(&compacted);
    println!("compacted, cold     {:6.2} ns/leaf ({:.1} us)", t * 1e9 / nl, t * 1e6);
    let t = best(reps, || keys.iter().filter_map(|&k| compacted.search(k, 0)).map(|f| f.value).sum::<f32>());
    println!("compacted search(key) {:6.2} ns", ns(t));
    let deep = tree.leaves(0).filter(|l| l.depth == 16).count();
    println!("depth-16 leaves {deep} of {}", tree.num_leaves());
    for d in [9u8, 10, 11, 12, 13, 14, 15] {
        let index = octolinear::SearchIndex::at_depth(&tree, d);
        let t = best(reps, || keys.iter().filter_map(|&k| index.search(k, 0)).map(|f| f.value).sum::<f32>());
        println!("index {d} search(key)  {:6.2} ns", ns(t));
    }
    let bytes = mapped::to_bytes(&tree, Default::default()).expect("olm");
    let map = MappedMap::new(bytes).expect("view");
    let view = map.view();
    let t = best(reps, || keys.iter().filter_map(|&k| view.search(k, 0)).map(|f| f.value).sum::<f32>());
    println!("mapped search(key)  {:6.2} ns", ns(t));
    let t = best(reps, || {
        queries.iter().filter_map(|&p| view.search_point(p, 0).ok().flatten()).map(|f| f.value).sum::<f32>()
    });
    println!("mapped search_point {:6.2} ns", ns(t));
    let index = mapped::MapSearchIndex::new(view);
    let t = best(reps, || keys.iter().filter_map(|&k| index.search(k, 0)).map(|f| f.value).sum::<f32>());
    println!("mapped index {} search(key) {:6.2} ns", index.depth(), ns(t));
    let t =
        best(reps, || queries.iter().filter_map(|&p| index.search(view.key(p).ok()?, 0)).map(|f| f.value).sum::<f32>());
    println!("mapped index, points {:6.2} ns", ns(t));
}

/// The fastest of 50 leaf folds, each after writing 32 MB elsewhere (the
/// side-by-side benchmark runs each library right after the other, so its
/// small-map iteration starts with the tree out of L2).
fn cold_fold(tree: &OccupancyTree) -> f64 {
    let mut junk = vec![1u64; 4 << 20];
    let mut cold = f64::MAX;
    for _ in 0..50 {
        for (i, j) in junk.iter_mut().enumerate() {
            *j = j.wrapping_add(i as u64);
        }
        black_box(&junk);
        let t = Instant::now();
        black_box(tree.leaves(0).fold((0usize, 0f64), |(n, s), l| (n + 1, s + f64::from(l.value))));
        cold = cold.min(t.elapsed().as_secs_f64());
    }
    cold
}

#[inline(never)]
fn convert_xor(tree: &OccupancyTree, queries: &[Point3]) -> u16 {
    let mut acc = 0u16;
    for &p in queries {
        if let Ok(k) = tree.key(p) {
            acc ^= k.0[0] ^ k.0[1] ^ k.0[2];
        }
    }
    acc
}

#[inline(never)]
fn convert_all(tree: &OccupancyTree, queries: &[Point3]) -> u64 {
    queries.iter().filter_map(|&p| tree.key(p).ok()).map(|k| k.0[0] as u64).sum::<u64>()
}

#[inline(never)]
fn search_points(tree: &OccupancyTree, queries: &[Point3]) -> f32 {
    queries.iter().filter_map(|&p| tree.search_point(p, 0).ok().flatten()).map(|f| f.value).sum::<f32>()
}
