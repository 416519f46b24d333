//! Micro-benchmarks of the core: Morton codes, key conversion, search, leaf
//! iteration, ray casting and the effect of arena compaction.
//!
//! `cargo bench -p octolinear-benches --bench core`

mod common;

use common::*;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use octolinear::{CastOptions, Key, MortonCode, OccupancyTree, Point3};
use octolinear_sim::SceneKind;
use std::hint::black_box;
use std::sync::OnceLock;
use std::time::Duration;

const N_KEYS: usize = 4096;

/// A map at 0.1 m as built by insertion (fragmented arena), its scans, and
/// a compacted copy.
struct Map {
    scans: Vec<Scan>,
    tree: OccupancyTree,
    compacted: OccupancyTree,
}

fn make_map(kind: SceneKind, n_scans: usize) -> Map {
    let scans = scans(kind, n_scans);
    let tree = build(&scans, 0.1, None);
    let mut compacted = tree.clone();
    compacted.compact();
    let u = tree.arena_usage().unwrap();
    eprintln!(
        "core: {} 0.1 m map, {} scans, {} points, {} nodes, {} leaves; as built {} live + {} \
         free slots, {} bytes; compacted {} bytes",
        kind_name(kind),
        n_scans,
        num_points(&scans),
        tree.size(),
        tree.num_leaves(),
        u.live_slots,
        u.free_slots,
        tree.memory_usage(),
        compacted.memory_usage()
    );
    Map { scans, tree, compacted }
}

/// The indoor map at 0.1 m (24 scans).
fn map() -> &'static Map {
    static MAP: OnceLock<Map> = OnceLock::new();
    MAP.get_or_init(|| make_map(SceneKind::Indoor, 24))
}

/// A larger map for the compaction benchmark: outdoor, 0.1 m, 6 scans.
fn big_map() -> &'static Map {
    static MAP: OnceLock<Map> = OnceLock::new();
    MAP.get_or_init(|| make_map(SceneKind::Outdoor, 6))
}

fn random_keys(n: usize, seed: u64) -> Vec<Key> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let v = rng.next_u64();
            Key([v as u16, (v >> 16) as u16, (v >> 32) as u16])
        })
        .collect()
}

fn morton(c: &mut Criterion) {
    let keys = random_keys(N_KEYS, 0x9e37_79b9);
    let codes: Vec<MortonCode> = keys.iter().map(|&k| MortonCode::encode(k)).collect();
    let mut g = c.benchmark_group("morton");
    g.throughput(Throughput::Elements(N_KEYS as u64));
    type Enc = fn(Key) -> MortonCode;
    for (name, f) in [
        ("encode_bits", MortonCode::encode as Enc),
        ("encode_table", MortonCode::encode_table as Enc),
        ("encode_bmi2", MortonCode::encode_bmi2 as Enc),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut acc = 0u64;
                for &k in black_box(&keys) {
                    acc ^= f(k).0;
                }
                acc
            })
        });
    }
    type Dec = fn(MortonCode) -> Key;
    for (name, f) in [("decode_bits", MortonCode::decode as Dec), ("decode_bmi2", MortonCode::decode_bmi2 as Dec)] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut acc = 0u16;
                for &m in black_box(&codes) {
                    let k = f(m);
                    acc ^= k.0[0] ^ k.0[1] ^ k.0[2];
                }
                acc
            })
        });
    }
    g.finish();
}

fn key_conversion(c: &mut Criterion) {
    let tree = OccupancyTree::new(0.1).unwrap();
    let mut rng = Rng(42);
    let points: Vec<Point3> = (0..N_KEYS)
        .map(|_| Point3::new(rng.range(-50.0, 50.0), rng.range(-50.0, 50.0), rng.range(-5.0, 5.0)))
        .collect();
    let keys: Vec<Key> = points.iter().map(|&p| tree.key(p).unwrap()).collect();
    let ks = tree.key_space();
    let mut g = c.benchmark_group("key");
    g.throughput(Throughput::Elements(N_KEYS as u64));
    g.bench_function("point_to_key_checked", |b| {
        b.iter(|| {
            let mut acc = 0u16;
            for &p in black_box(&points) {
                if let Ok(k) = tree.key(p) {
                    acc ^= k.0[0] ^ k.0[1] ^ k.0[2];
                }
            }
            acc
        })
    });
    g.bench_function("key_to_point", |b| {
        b.iter(|| {
            let mut acc = 0f32;
            for &k in black_box(&keys) {
                let p = ks.key_to_point(k);
                acc += p.x + p.y + p.z;
            }
            acc
        })
    });
    g.finish();
}

/// Keys of existing leaves (hits) and of points whose search fails (misses).
fn search_keys(tree: &OccupancyTree) -> (Vec<Key>, Vec<Key>) {
    let pts = query_points(tree, 4 * N_KEYS, 3);
    let mut hits = Vec::new();
    let mut misses = Vec::new();
    for p in pts {
        let k = tree.key(p).unwrap();
        match tree.search(k, 0) {
            Some(_) if hits.len() < N_KEYS => hits.push(k),
            None if misses.len() < N_KEYS => misses.push(k),
            _ => {}
        }
    }
    (hits, misses)
}

fn search_sum(tree: &OccupancyTree, keys: &[Key]) -> f32 {
    let mut acc = 0f32;
    for &k in keys {
        if let Some(f) = tree.search(k, 0) {
            acc += f.value;
        }
    }
    acc
}

fn leaf_sum(tree: &OccupancyTree) -> f64 {
    tree.leaves(0).map(|l| f64::from(l.value)).sum()
}

fn search(c: &mut Criterion) {
    let m = map();
    let (hits, misses) = search_keys(&m.tree);
    let mut g = c.benchmark_group("search_indoor_0.1");
    for (name, keys) in [("hit", &hits), ("miss", &misses)] {
        g.throughput(Throughput::Elements(keys.len() as u64));
        g.bench_function(name, |b| b.iter(|| search_sum(&m.tree, black_box(keys))));
    }
    let points: Vec<Point3> = hits.iter().map(|&k| m.tree.key_space().key_to_point(k)).collect();
    g.throughput(Throughput::Elements(points.len() as u64));
    g.bench_function("hit_from_point", |b| {
        b.iter(|| {
            let mut acc = 0f32;
            for &p in black_box(&points) {
                if let Ok(Some(f)) = m.tree.search_point(p, 0) {
                    acc += f.value;
                }
            }
            acc
        })
    });
    g.finish();
}

fn leaves(c: &mut Criterion) {
    let m = map();
    let mut g = c.benchmark_group("leaves_indoor_0.1");
    g.throughput(Throughput::Elements(m.tree.num_leaves() as u64));
    g.bench_function("iterate_all", |b| b.iter(|| leaf_sum(black_box(&m.tree))));
    g.finish();
}

fn rays(c: &mut Criterion) {
    let m = map();
    let (origins, dirs) = common::rays(&m.scans, 1000, 9);
    let mut g = c.benchmark_group("ray_indoor_0.1");
    g.throughput(Throughput::Elements(origins.len() as u64));
    for (name, ignore_unknown) in [("cast_ray_20m_ignore_unknown", true), ("cast_ray_stop_unknown", false)] {
        let opts = CastOptions { ignore_unknown, max_range: Some(20.0) };
        g.bench_function(name, |b| {
            b.iter(|| {
                origins.iter().zip(&dirs).filter(|(&o, &d)| m.tree.cast_ray(o, d, opts).is_ok_and(|c| c.hit())).count()
            })
        });
    }
    // ray_keys: sensor origin to every end point of the first scan; the
    // throughput is in ray-key steps, so 1 / (steps/s) is the time per step
    let (points, origin) = &m.scans[0];
    let steps: usize = points.iter().map(|&p| m.tree.ray_keys(*origin, p).map_or(0, |r| r.count())).sum();
    eprintln!("core: ray_keys over {} rays of scan 0, {} steps in all", points.len(), steps);
    g.throughput(Throughput::Elements(steps as u64));
    g.bench_function("ray_keys_steps", |b| {
        b.iter(|| {
            let mut acc = 0u16;
            for &p in black_box(points) {
                if let Ok(r) = m.tree.ray_keys(*origin, p) {
                    for k in r {
                        acc ^= k.0[0];
                    }
                }
            }
            acc
        })
    });
    g.finish();
}

fn compaction(c: &mut Criterion) {
    for (scene, m) in [("indoor", map()), ("outdoor", big_map())] {
        compaction_on(c, scene, m);
    }
}

fn compaction_on(c: &mut Criterion, scene: &str, m: &Map) {
    let (hits, _) = search_keys(&m.tree);
    let mut g = c.benchmark_group(format!("compaction_{scene}_0.1"));
    for (name, tree) in [("as_built", &m.tree), ("compacted", &m.compacted)] {
        g.throughput(Throughput::Elements(hits.len() as u64));
        g.bench_with_input(BenchmarkId::new("search_hit", name), tree, |b, t| {
            b.iter(|| search_sum(t, black_box(&hits)))
        });
        g.throughput(Throughput::Elements(tree.num_leaves() as u64));
        g.bench_with_input(BenchmarkId::new("leaf_iteration", name), tree, |b, t| b.iter(|| leaf_sum(black_box(t))));
    }
    g.throughput(Throughput::Elements(m.tree.size() as u64));
    g.bench_function("compact", |b| {
        b.iter_batched(
            || m.tree.clone(),
            |mut t| {
                t.compact();
                t
            },
            criterion::BatchSize::LargeInput,
        )
    });
    g.finish();
}

fn config() -> Criterion {
    Criterion::default().sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3))
}

criterion_group! {
    name = benches;
    config = config();
    targets = morton, key_conversion, search, leaves, rays, compaction
}
criterion_main!(benches);
