//! Scan insertion: whole scan sets into a fresh tree at 0.05, 0.1 and 0.2 m
//! with 1 and 2 ray-casting threads, and the parts of an insertion timed
//! apart: ray casting (`compute_update`), sorting the key sets by Morton
//! code, and applying them: in one batched walk (`update_batch`, what
//! `insert_point_cloud` does), or key by key (`apply_sorted`) in Morton
//! order and in the hash sets' own iteration order. Before timing, the
//! three applications are checked to give the same `.ot` bytes.
//!
//! `cargo bench --bench insert` (filter e.g. `-- insert/indoor`).
//! Throughputs: `insert` and `compute_update` in points, `apply` in voxel
//! updates, `sort` in keys; the setup lines on stderr give both counts so
//! either rate can be derived.

mod common;

use common::*;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use octolinear::formats::ot;
use octolinear::scan::ScanUpdate;
use octolinear::simulate::SceneKind;
use octolinear::{InnerNodes, Key, OccupancyTree};
use std::cell::OnceCell;
use std::time::Duration;

const RESOLUTIONS: [f64; 3] = [0.05, 0.1, 0.2];

/// Indoor: 24 scans (~137k points, short rays). Outdoor: 6 scans (~26k
/// points, rays up to 100 m: ~20x the voxel updates per point).
fn scenes() -> Vec<(SceneKind, Vec<Scan>)> {
    vec![(SceneKind::Indoor, scans(SceneKind::Indoor, 24)), (SceneKind::Outdoor, scans(SceneKind::Outdoor, 6))]
}

/// Per-scan key lists: sorted Morton codes (what `insert_point_cloud`
/// applies with `update_batch`), keys in Morton order and keys in the hash
/// sets' own iteration order (both for `apply_sorted`, key by key).
struct KeyLists {
    codes: Vec<(Vec<u64>, Vec<u64>)>,
    sorted: Vec<(Vec<Key>, Vec<Key>)>,
    hashed: Vec<(Vec<Key>, Vec<Key>)>,
}

fn key_lists(updates: &[ScanUpdate]) -> KeyLists {
    let codes = updates.iter().map(ScanUpdate::sorted_codes).collect();
    let sorted = updates.iter().map(ScanUpdate::sorted).collect();
    let hashed = updates
        .iter()
        .map(|u| (u.free.iter().map(|h| h.decode()).collect(), u.occupied.iter().map(|h| h.decode()).collect()))
        .collect();
    KeyLists { codes, sorted, hashed }
}

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).unwrap();
    v
}

/// What `insert_point_cloud` does after ray casting: one batched walk for
/// the misses, one for the hits.
fn apply_batches(res: f64, lists: &[(Vec<u64>, Vec<u64>)]) -> OccupancyTree {
    let mut tree = OccupancyTree::new(res).unwrap();
    let sensor = *tree.sensor();
    for (free, occ) in lists {
        tree.update_batch(free, sensor.miss, InnerNodes::Update);
        tree.update_batch(occ, sensor.hit, InnerNodes::Update);
    }
    tree
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
            let n_updates: usize = updates.iter().map(|u| u.free.len() + u.occupied.len()).sum();
            eprintln!(
                "insert: {name} {res} m: {} scans, {points} points, {n_updates} voxel updates ({:.1} per point)",
                scans.len(),
                n_updates as f64 / points as f64
            );
            // built on first use, so that benchmarks filtered out cost nothing
            let lists = OnceCell::new();
            let lists = || {
                lists.get_or_init(|| {
                    let lists = key_lists(&updates);
                    let reference = ot_bytes(&apply_batches(res, &lists.codes));
                    for (order, l) in [("Morton", &lists.sorted), ("hash", &lists.hashed)] {
                        let tree = apply_all(res, l);
                        assert!(ot_bytes(&tree) == reference, "key-by-key application in {order} order differs");
                    }
                    lists
                })
            };
            g.throughput(Throughput::Elements(n_updates as u64));
            g.bench_function("sort_morton", |b| {
                b.iter(|| updates.iter().map(ScanUpdate::sorted_codes).collect::<Vec<_>>())
            });
            g.bench_function("apply_batch_morton", |b| {
                let l = lists();
                b.iter(|| apply_batches(res, &l.codes))
            });
            g.bench_function("apply_per_key_morton", |b| {
                let l = lists();
                b.iter(|| apply_all(res, &l.sorted))
            });
            g.bench_function("apply_per_key_hash_order", |b| {
                let l = lists();
                b.iter(|| apply_all(res, &l.hashed))
            });
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
