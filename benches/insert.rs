//! Scan insertion: whole scan sets into a fresh tree at 0.05, 0.1 and 0.2 m
//! with 1 and 2 ray-casting threads, and the two halves of an insertion
//! timed apart: ray casting (`compute_update`) and applying the key sets,
//! in Morton order (`apply_sorted`, what `insert_point_cloud` does) versus
//! the hash sets' own iteration order.
//!
//! `cargo bench --bench insert` (filter e.g. `-- insert/indoor`).
//! Throughputs: `insert` and `compute_update` in points, `apply` in voxel
//! updates, `sort` in keys; the setup lines on stderr give both counts so
//! either rate can be derived.

mod common;

use common::*;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use octolinear::scan::ScanUpdate;
use octolinear::simulate::SceneKind;
use octolinear::{InnerNodes, Key, OccupancyTree};
use std::time::Duration;

const RESOLUTIONS: [f64; 3] = [0.05, 0.1, 0.2];

/// Indoor: 24 scans (~137k points, short rays). Outdoor: 6 scans (~26k
/// points, rays up to 100 m: ~20x the voxel updates per point).
fn scenes() -> Vec<(SceneKind, Vec<Scan>)> {
    vec![(SceneKind::Indoor, scans(SceneKind::Indoor, 24)), (SceneKind::Outdoor, scans(SceneKind::Outdoor, 6))]
}

/// Per-scan key lists: Morton-sorted, and in the hash sets' iteration order.
struct KeyLists {
    sorted: Vec<(Vec<Key>, Vec<Key>)>,
    hashed: Vec<(Vec<Key>, Vec<Key>)>,
    updates: usize,
}

fn key_lists(updates: &[ScanUpdate]) -> KeyLists {
    let sorted: Vec<_> = updates.iter().map(ScanUpdate::sorted).collect();
    let hashed: Vec<_> = updates
        .iter()
        .map(|u| (u.free.iter().map(|h| h.decode()).collect(), u.occupied.iter().map(|h| h.decode()).collect()))
        .collect();
    let n = sorted.iter().map(|(f, o)| f.len() + o.len()).sum();
    KeyLists { sorted, hashed, updates: n }
}

fn apply_all(res: f64, lists: &[(Vec<Key>, Vec<Key>)]) -> OccupancyTree {
    let mut tree = OccupancyTree::new(res).unwrap();
    for (free, occ) in lists {
        tree.apply_sorted(free, occ, InnerNodes::Update);
    }
    tree
}

fn insert(c: &mut Criterion) {
    for (kind, scans) in scenes() {
        let name = kind_name(kind);
        let points = num_points(&scans);
        for res in RESOLUTIONS {
            let mut g = c.benchmark_group(format!("insert/{name}/{res}"));
            g.throughput(Throughput::Elements(points as u64));
            for threads in [1usize, 2] {
                g.bench_function(BenchmarkId::new("threads", threads), |b| {
                    b.iter(|| build(&scans, res, Some(threads)))
                });
            }
            if res == 0.1 {
                // `threads: None` runs on rayon's global pool (2 threads here)
                // instead of building a pool per scan
                g.bench_function("global_pool", |b| b.iter(|| build(&scans, res, None)));
            }
            g.finish();
        }
    }
}

fn split(c: &mut Criterion) {
    for (kind, scans) in scenes() {
        let name = kind_name(kind);
        let points = num_points(&scans);
        for res in RESOLUTIONS {
            // the key sets depend only on the key space, not on the tree
            let empty = OccupancyTree::new(res).unwrap();
            let mut g = c.benchmark_group(format!("split/{name}/{res}"));
            g.throughput(Throughput::Elements(points as u64));
            for threads in [1usize, 2] {
                let opts = scan_options(Some(threads));
                g.bench_function(BenchmarkId::new("compute_update", threads), |b| {
                    b.iter(|| {
                        scans.iter().map(|(p, o)| empty.compute_update(p, *o, &opts).unwrap().0).collect::<Vec<_>>()
                    })
                });
            }
            let opts = scan_options(Some(1));
            let updates: Vec<ScanUpdate> =
                scans.iter().map(|(p, o)| empty.compute_update(p, *o, &opts).unwrap().0).collect();
            let lists = key_lists(&updates);
            eprintln!(
                "insert: {name} {res} m: {} scans, {points} points, {} voxel updates \
                 ({:.1} per point)",
                scans.len(),
                lists.updates,
                lists.updates as f64 / points as f64
            );
            let mut a = Vec::new();
            octolinear::formats::ot::write(&apply_all(res, &lists.sorted), &mut a).unwrap();
            let mut b = Vec::new();
            octolinear::formats::ot::write(&apply_all(res, &lists.hashed), &mut b).unwrap();
            assert!(a == b, "hash-order application gave a different tree");
            g.throughput(Throughput::Elements(lists.updates as u64));
            g.bench_function("sort_morton", |b| b.iter(|| updates.iter().map(ScanUpdate::sorted).collect::<Vec<_>>()));
            g.bench_function("apply_morton_order", |b| b.iter(|| apply_all(res, &lists.sorted)));
            g.bench_function("apply_hash_order", |b| b.iter(|| apply_all(res, &lists.hashed)));
            g.finish();
        }
    }
}

fn config() -> Criterion {
    Criterion::default().sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3))
}

criterion_group! {
    name = benches;
    config = config();
    targets = insert, split
}
criterion_main!(benches);
