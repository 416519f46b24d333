//! The library's hot paths as a crate depending on octolinear builds them:
//! point-to-key conversion, searches, leaf iteration, ray casting, mapped
//! (`.olm`) queries, scan insertion and `.bt` writing. Run it once as
//! built by default (baseline x86-64, what a dependent crate gets) and once
//! with `RUSTFLAGS="-C target-cpu=x86-64-v2"` (POPCNT, SSE4.1) in another
//! target directory, and compare (`docs/benchmarks.md`, "Build flags and
//! downstream speed").
//!
//! Times are the process's CPU time, not wall time: on a shared machine a
//! benchmark descheduled for other processes' work would otherwise count
//! their time as its own. Everything runs on one thread.
//!
//! `cargo bench -p octolinear-benches --bench flags`

mod common;

use common::*;
use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use octolinear::formats::bt;
use octolinear::mapped::{self, MappedMap, WriteOptions};
use octolinear::{CastOptions, Key, OccupancyTree, Point3};
use octolinear_sim::SceneKind;
use std::hint::black_box;
use std::time::Duration;

/// The process's CPU time (all threads), in nanoseconds.
struct CpuTime;

fn cpu_time_ns() -> u64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `t` is a valid timespec for the call to fill.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_PROCESS_CPUTIME_ID)");
    t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
}

impl Measurement for CpuTime {
    type Intermediate = u64;
    type Value = u64;

    fn start(&self) -> u64 {
        cpu_time_ns()
    }

    fn end(&self, start: u64) -> u64 {
        cpu_time_ns() - start
    }

    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }

    fn zero(&self) -> u64 {
        0
    }

    fn to_f64(&self, v: &u64) -> f64 {
        *v as f64
    }

    fn formatter(&self) -> &dyn ValueFormatter {
        // nanoseconds, shown as durations
        static WALL: WallTime = WallTime;
        WALL.formatter()
    }
}

type Group<'a> = criterion::BenchmarkGroup<'a, CpuTime>;

const N: usize = 4096;

/// The indoor map at 0.1 m from 24 scans (the `core` benchmark's map), and
/// its scans.
fn map() -> (OccupancyTree, Vec<Scan>) {
    let scans = scans(SceneKind::Indoor, 24);
    (build(&scans, 0.1, Some(1)), scans)
}

/// Keys of existing leaves (hits) and of points whose search fails (misses).
fn search_keys(tree: &OccupancyTree) -> (Vec<Key>, Vec<Key>) {
    let (mut hits, mut misses) = (Vec::new(), Vec::new());
    for p in query_points(tree, 4 * N, 3) {
        let k = tree.key(p).unwrap();
        match tree.search(k, 0) {
            Some(_) if hits.len() < N => hits.push(k),
            None if misses.len() < N => misses.push(k),
            _ => {}
        }
    }
    (hits, misses)
}

fn queries(g: &mut Group, tree: &OccupancyTree, scans: &[Scan]) {
    let mut rng = Rng(42);
    let points: Vec<Point3> =
        (0..N).map(|_| Point3::new(rng.range(-50.0, 50.0), rng.range(-50.0, 50.0), rng.range(-5.0, 5.0))).collect();
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("point_to_key", |b| {
        b.iter(|| black_box(&points).iter().filter_map(|&p| tree.key(p).ok()).fold(0, |a, k| a ^ k.0[0] ^ k.0[2]))
    });

    let (hits, misses) = search_keys(tree);
    let search_sum = |keys: &[Key]| keys.iter().filter_map(|&k| tree.search(k, 0)).map(|f| f.value).sum::<f32>();
    g.bench_function("search_hit", |b| b.iter(|| search_sum(black_box(&hits))));
    g.bench_function("search_miss", |b| b.iter(|| search_sum(black_box(&misses))));
    let centres: Vec<Point3> = hits.iter().map(|&k| tree.key_space().key_to_point(k)).collect();
    g.bench_function("search_point", |b| {
        b.iter(|| {
            black_box(&centres).iter().filter_map(|&p| tree.search_point(p, 0).ok()?).map(|f| f.value).sum::<f32>()
        })
    });

    g.throughput(Throughput::Elements(tree.num_leaves() as u64));
    g.bench_function("leaves", |b| b.iter(|| tree.leaves(0).map(|l| f64::from(l.value)).sum::<f64>()));

    let (origins, dirs) = rays(scans, 1000, 9);
    let opts = CastOptions { ignore_unknown: true, max_range: Some(20.0) };
    g.throughput(Throughput::Elements(origins.len() as u64));
    g.bench_function("cast_ray", |b| {
        b.iter(|| origins.iter().zip(&dirs).filter(|(&o, &d)| tree.cast_ray(o, d, opts).is_ok_and(|c| c.hit())).count())
    });

    let (points, origin) = &scans[0];
    g.throughput(Throughput::Elements(points.len() as u64));
    g.bench_function("ray_keys", |b| {
        b.iter(|| {
            let rays = points.iter().filter_map(|&p| tree.ray_keys(*origin, p).ok());
            rays.flatten().fold(0u16, |a, k| a ^ k.0[0])
        })
    });
}

fn mapped_queries(g: &mut Group, tree: &OccupancyTree) {
    let bytes = mapped::to_bytes(tree, WriteOptions::default()).unwrap();
    let map = MappedMap::new(&bytes[..]).unwrap();
    let view = map.view();
    let (hits, misses) = search_keys(tree);
    let keys: Vec<Key> = hits.iter().zip(&misses).flat_map(|(&h, &m)| [h, m]).collect();
    g.throughput(Throughput::Elements(keys.len() as u64));
    g.bench_function("olm_search", |b| {
        b.iter(|| black_box(&keys).iter().filter_map(|&k| view.search(k, 0)).map(|f| f.value).sum::<f32>())
    });
    g.throughput(Throughput::Elements(tree.num_leaves() as u64));
    g.bench_function("olm_leaves", |b| b.iter(|| view.leaves(0).map(|l| f64::from(l.value)).sum::<f64>()));
}

fn updates(g: &mut Group, tree: &OccupancyTree, scans: &[Scan]) {
    let first = &scans[..4];
    g.throughput(Throughput::Elements(num_points(first) as u64));
    g.bench_function("insert_4_scans", |b| b.iter(|| build(first, 0.1, Some(1))));
    g.throughput(Throughput::Elements(tree.size() as u64));
    let mut out = Vec::new();
    g.bench_function("bt_write", |b| {
        b.iter(|| {
            out.clear();
            bt::write(tree, &mut out).unwrap();
            out.len()
        })
    });
}

fn downstream(c: &mut Criterion<CpuTime>) {
    let (tree, scans) = map();
    let mut g = c.benchmark_group("flags");
    queries(&mut g, &tree, &scans);
    mapped_queries(&mut g, &tree);
    updates(&mut g, &tree, &scans);
    g.finish();
}

fn config() -> Criterion<CpuTime> {
    Criterion::default()
        .with_measurement(CpuTime)
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
}

criterion_group! {
    name = benches;
    config = config();
    targets = downstream
}
criterion_main!(benches);
