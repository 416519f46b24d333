//! Scan insertion: whole scan sets into a fresh tree at 0.05, 0.1 and 0.2 m
//! with 1 and 2 threads, and the parts of an insertion timed apart: ray
//! casting with the key lists made repeat-free and sorted
//! (`compute_update`); that deduplication alone, as done (sort the raw
//! codes, drop repeats, remove the occupied codes from the free ones by
//! merging) and with hashbrown key sets as OctoMap does with its
//! `KeySet`s (then sorted for the batched walk); and applying the lists:
//! in one batched walk (`update_batch`, what `insert_point_cloud` does),
//! or key by key (`apply_sorted`) in Morton order and in the hash sets'
//! own iteration order. Before timing, the three applications are checked
//! to give the same `.ot` bytes.
//!
//! `cargo bench -p octolinear-benches --bench insert` (filter e.g. `-- insert/indoor`).
//! Throughputs: `insert` and `compute_update` in points, `dedup` in raw
//! codes, `apply` in voxel updates. Each scene and resolution also prints
//! (stderr) its counts and the rates of a plain timing: points and voxel
//! updates per second and nanoseconds per ray-key step.

mod common;

use common::*;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use octolinear::formats::ot;
use octolinear::internals::{key_sets, KeySet, TreeInternals};
use octolinear::scan::ScanUpdate;
use octolinear::{InnerNodes, Key, OccupancyTree};
use octolinear_sim::SceneKind;
use std::cell::OnceCell;
use std::time::{Duration, Instant};

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
    let codes = updates.iter().map(|u| (u.free.clone(), u.occupied.clone())).collect();
    let sorted = updates.iter().map(ScanUpdate::sorted).collect();
    let hashed = updates
        .iter()
        .map(|u| {
            let (free, occupied) = key_sets(u);
            (free.iter().map(|h| h.decode()).collect(), occupied.iter().map(|h| h.decode()).collect())
        })
        .collect();
    KeyLists { codes, sorted, hashed }
}

/// The deduplication by sorting: both lists radix-sorted and freed of
/// repeats, the occupied codes removed from the free ones by merging
/// (octolinear's way before the block sets).
fn dedup_sort(free: &[u64], occupied: &[u64]) -> ScanUpdate {
    let sorted = |codes: &[u64]| {
        let mut v = codes.to_vec();
        octolinear::morton::sort_codes(&mut v);
        v.dedup();
        v
    };
    let (mut free, occupied) = (sorted(free), sorted(occupied));
    let mut j = 0;
    free.retain(|&c| {
        while j < occupied.len() && occupied[j] < c {
            j += 1;
        }
        j == occupied.len() || occupied[j] != c
    });
    ScanUpdate { free, occupied }
}

/// The deduplication OctoMap's way: hash sets, the occupied keys removed
/// from the free set, then (for the batched walk) sorted.
fn dedup_hash(free: &[u64], occupied: &[u64]) -> ScanUpdate {
    let mut f: KeySet = free.iter().map(|&c| octolinear::MortonCode(c)).collect();
    let o: KeySet = occupied.iter().map(|&c| octolinear::MortonCode(c)).collect();
    f.retain(|k| !o.contains(k));
    let sorted = |set: KeySet| {
        let mut v: Vec<u64> = set.into_iter().map(|c| c.0).collect();
        octolinear::morton::sort_codes(&mut v);
        v
    };
    ScanUpdate { free: sorted(f), occupied: sorted(o) }
}

/// Fastest of `reps` runs of `f`, in seconds.
fn best_of(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::MAX, f64::min)
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
            let n_updates: usize = updates.iter().map(ScanUpdate::len).sum();
            let raw: Vec<(Vec<u64>, Vec<u64>)> = scans.iter().map(|(p, o)| empty.cast_codes(p, *o)).collect();
            let n_raw: usize = raw.iter().map(|(f, o)| f.len() + o.len()).sum();
            // every voxel step of every ray, the origin voxel included
            let steps: usize = scans
                .iter()
                .flat_map(|(p, o)| p.iter().map(move |q| (q, o)))
                .map(|(q, o)| empty.ray_keys(*o, *q).map_or(0, |r| r.count()))
                .sum();
            let t_cast = best_of(3, || {
                for (p, o) in &scans {
                    std::hint::black_box(empty.compute_update(p, *o, &opts).unwrap());
                }
            });
            let t_insert = best_of(3, || {
                std::hint::black_box(build(&scans, res, Some(1)));
            });
            eprintln!(
                "insert: {name} {res} m: {} scans, {points} points, {steps} ray-key steps ({:.1} per point), \
                 {n_raw} raw codes (every ray step and end point), {n_updates} voxel updates ({:.2} per point)",
                scans.len(),
                steps as f64 / points as f64,
                n_updates as f64 / points as f64
            );
            eprintln!(
                "insert: {name} {res} m, 1 thread: insert {:.1} ms = {:.2} M points/s, {:.2} M voxel updates/s, \
                 {:.2} ns per ray-key step; compute_update {:.1} ms = {:.2} ns per ray-key step",
                t_insert * 1e3,
                points as f64 / t_insert / 1e6,
                n_updates as f64 / t_insert / 1e6,
                t_insert * 1e9 / steps as f64,
                t_cast * 1e3,
                t_cast * 1e9 / steps as f64
            );
            for (i, (f, o)) in raw.iter().enumerate() {
                let u = ScanUpdate::from_codes(f, o);
                assert!(u == updates[i] && dedup_hash(f, o) == u && dedup_sort(f, o) == u, "deduplications differ");
            }
            g.throughput(Throughput::Elements(n_raw as u64));
            g.bench_function("dedup_blocks", |b| {
                b.iter(|| raw.iter().map(|(f, o)| ScanUpdate::from_codes(f, o)).collect::<Vec<_>>())
            });
            g.bench_function("dedup_sort", |b| {
                b.iter(|| raw.iter().map(|(f, o)| dedup_sort(f, o)).collect::<Vec<_>>())
            });
            g.bench_function("dedup_hash", |b| {
                b.iter(|| raw.iter().map(|(f, o)| dedup_hash(f, o)).collect::<Vec<_>>())
            });
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
