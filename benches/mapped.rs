//! `.olm` mapped maps against the in-memory arena: open time, random point
//! queries, leaf iteration, `castRay`, and file sizes against `.ot`/`.bt`.
//!
//! `cargo bench -p octolinear-benches --bench mapped` (modest sample sizes). Environment:
//! `OLM_BENCH_SCANS` (default 12) scans of the simulated outdoor map at
//! 0.1 m; `OLM_SCALE=<scans>` instead runs the scale experiment: a map of
//! that many outdoor scans at 0.05 m written to `OLM_SCALE_DIR` (default
//! the system temp dir), then open time and resident memory after 100k
//! random queries on the mapped file, printed (no criterion).

use criterion::{black_box, criterion_group, BenchmarkId, Criterion};
use octolinear::formats::{bt, ot};
use octolinear::mapped::{self, MappedMap, WriteOptions};
use octolinear::{CastOptions, Key, OccupancyTree, Point3, ScanOptions};
use octolinear_sim::{simulate, LidarConfig, SceneKind, SplitMix64};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn build(scans: usize, res: f64, compact: bool) -> OccupancyTree {
    let graph = simulate(SceneKind::Outdoor, scans, 21, &LidarConfig::outdoor()).unwrap();
    let mut tree = OccupancyTree::new(res).unwrap();
    for node in &graph.nodes {
        let (cloud, origin) = node.graph2tree();
        tree.insert_point_cloud(&cloud.points, origin, &ScanOptions::default()).unwrap();
    }
    if compact {
        tree.compact();
    }
    tree
}

fn file_len(p: &Path) -> u64 {
    std::fs::metadata(p).unwrap().len()
}

/// Query keys: half inside leaves, half near them (some unknown space).
fn query_keys(tree: &OccupancyTree, n: usize, seed: u64) -> Vec<Key> {
    let leaves: Vec<Key> = tree.leaves(0).map(|l| l.key).collect();
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|i| {
            let k = leaves[rng.below(leaves.len() as u32) as usize];
            if i % 2 == 0 {
                k
            } else {
                Key(k.0.map(|c| c.wrapping_add((rng.below(32) as u16).wrapping_sub(16))))
            }
        })
        .collect()
}

fn rays(tree: &OccupancyTree, n: usize) -> Vec<(Point3, Point3)> {
    let mut rng = SplitMix64(5);
    let leaves: Vec<Key> = tree.leaves(0).map(|l| l.key).collect();
    (0..n)
        .map(|_| {
            let k = leaves[rng.below(leaves.len() as u32) as usize];
            let o = tree.key_space().key_to_point(k);
            let d = Point3::new(rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32, rng.range(-0.2, 0.2) as f32);
            (o, d)
        })
        .collect()
}

struct Fixture {
    tree: OccupancyTree,
    dir: tempfile::TempDir,
    files: Vec<(&'static str, PathBuf)>,
}

fn fixture() -> Fixture {
    let scans = std::env::var("OLM_BENCH_SCANS").ok().and_then(|s| s.parse().ok()).unwrap_or(12);
    let t = Instant::now();
    let tree = build(scans, 0.1, true);
    eprintln!(
        "map: {scans} outdoor scans at 0.1 m, {} nodes, {} leaves, built in {:.1} s",
        tree.calc_num_nodes(),
        tree.num_leaves(),
        t.elapsed().as_secs_f64()
    );
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    let ot_path = dir.path().join("map.ot");
    octolinear::formats::write_atomically(&ot_path, |w| ot::write(&tree, w)).unwrap();
    let bt_path = dir.path().join("map.bt");
    octolinear::formats::write_atomically(&bt_path, |w| bt::write(&tree, w)).unwrap();
    for (name, opts) in [
        ("olm-rank", WriteOptions::default()),
        ("olm-pointers", WriteOptions::pointers()),
        ("olm-rank-b32", WriteOptions { rank_block_log2: 5, ..Default::default() }),
        ("olm-rank-b256", WriteOptions { rank_block_log2: 8, ..Default::default() }),
        ("olm-ml", WriteOptions::max_likelihood()),
    ] {
        let p = dir.path().join(format!("{name}.olm"));
        let t = Instant::now();
        mapped::write_file_with(&tree, &p, opts).unwrap();
        eprintln!("write {name}: {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
        files.push((name, p));
    }
    let (ot_len, bt_len) = (file_len(&ot_path), file_len(&bt_path));
    eprintln!(".ot {ot_len} bytes, .bt {bt_len} bytes");
    for (name, p) in &files {
        let l = file_len(p);
        eprintln!("{name}: {l} bytes = {:.3}x .ot, {:.3}x .bt", l as f64 / ot_len as f64, l as f64 / bt_len as f64);
        let m = MappedMap::open(p).unwrap();
        let t = Instant::now();
        m.verify().unwrap();
        eprintln!("verify {name}: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    }
    Fixture { tree, dir, files }
}

/// Best of `rounds` interleaved runs of each contender (robust to the
/// load of a shared machine), in ms.
fn paired(what: &str, rounds: usize, contenders: &mut [(&str, &mut dyn FnMut() -> f64)]) {
    let mut best = vec![f64::MAX; contenders.len()];
    let mut sink = 0.0;
    for _ in 0..rounds {
        for (i, (_, f)) in contenders.iter_mut().enumerate() {
            let t = Instant::now();
            sink += f();
            best[i] = best[i].min(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    black_box(sink);
    let base = best[0];
    let line: Vec<String> =
        contenders.iter().zip(&best).map(|((n, _), b)| format!("{n} {b:.2} ms ({:.2}x)", b / base)).collect();
    eprintln!("paired {what}: {}", line.join(", "));
}

fn summary(fx: &Fixture) {
    let tree = &fx.tree;
    let keys = query_keys(tree, 10_000, 1);
    let rs = rays(tree, 300);
    let maps: Vec<_> = fx.files.iter().map(|(n, p)| (*n, MappedMap::open(p).unwrap())).collect();
    let views: Vec<_> = maps.iter().map(|(n, m)| (*n, m.view())).collect();
    let search_tree = || keys.iter().filter_map(|&k| tree.search(k, 0)).map(|f| f.value as f64).sum::<f64>();
    let mut a = search_tree;
    let mut fs: Vec<Box<dyn FnMut() -> f64>> = views
        .iter()
        .map(|(_, v)| {
            let v = *v;
            let keys = &keys;
            Box::new(move || keys.iter().filter_map(|&k| v.search(k, 0)).map(|f| f.value as f64).sum::<f64>())
                as Box<dyn FnMut() -> f64>
        })
        .collect();
    let mut c: Vec<(&str, &mut dyn FnMut() -> f64)> = vec![("arena", &mut a)];
    for ((n, _), f) in views.iter().zip(fs.iter_mut()) {
        c.push((n, f.as_mut()));
    }
    paired("search 10k keys", 15, &mut c);

    let mut a = || tree.leaves(0).map(|l| l.value as f64).sum::<f64>();
    let mut fs: Vec<Box<dyn FnMut() -> f64>> = views
        .iter()
        .map(|(_, v)| {
            let v = *v;
            Box::new(move || v.leaves(0).map(|l| l.value as f64).sum::<f64>()) as Box<dyn FnMut() -> f64>
        })
        .collect();
    let mut c: Vec<(&str, &mut dyn FnMut() -> f64)> = vec![("arena", &mut a)];
    for ((n, _), f) in views.iter().zip(fs.iter_mut()) {
        c.push((n, f.as_mut()));
    }
    paired("all leaves", 5, &mut c);

    let opts = CastOptions { ignore_unknown: false, max_range: Some(30.0) };
    let mut a = || rs.iter().filter(|(o, d)| tree.cast_ray(*o, *d, opts).is_ok_and(|r| r.hit())).count() as f64;
    let mut fs: Vec<Box<dyn FnMut() -> f64>> = views
        .iter()
        .map(|(_, v)| {
            let v = *v;
            let rs = &rs;
            Box::new(move || rs.iter().filter(|(o, d)| v.cast_ray(*o, *d, opts).is_ok_and(|r| r.hit())).count() as f64)
                as Box<dyn FnMut() -> f64>
        })
        .collect();
    let mut c: Vec<(&str, &mut dyn FnMut() -> f64)> = vec![("arena", &mut a)];
    for ((n, _), f) in views.iter().zip(fs.iter_mut()) {
        c.push((n, f.as_mut()));
    }
    paired("cast_ray 300", 10, &mut c);
}

fn benches(c: &mut Criterion) {
    let fx = fixture();
    summary(&fx);
    if std::env::var_os("OLM_SUMMARY_ONLY").is_some() {
        return;
    }
    let tree = &fx.tree;
    let keys = query_keys(tree, 10_000, 1);
    let ml = {
        let mut t = tree.clone();
        t.to_max_likelihood();
        t.prune();
        t
    };

    let mut g = c.benchmark_group("open");
    g.sample_size(50);
    for (name, p) in &fx.files {
        g.bench_function(*name, |b| b.iter(|| black_box(MappedMap::open(p).unwrap())));
    }
    let bytes = std::fs::read(&fx.files[0].1).unwrap();
    g.bench_function("header checks only (slice)", |b| b.iter(|| black_box(MappedMap::new(&bytes[..]).unwrap())));
    g.bench_function("ot-read (parse)", |b| {
        let p = fx.dir.path().join("map.ot");
        b.iter(|| {
            let f = std::io::BufReader::new(std::fs::File::open(&p).unwrap());
            black_box(ot::read(f).unwrap())
        })
    });
    g.finish();

    let maps: Vec<_> = fx.files.iter().map(|(n, p)| (*n, MappedMap::open(p).unwrap())).collect();

    let mut g = c.benchmark_group("search 10k keys");
    g.sample_size(20);
    g.bench_function("arena", |b| {
        b.iter(|| keys.iter().filter_map(|&k| tree.search(k, 0)).map(|f| f.value).sum::<f32>())
    });
    g.bench_function("arena ml", |b| {
        b.iter(|| keys.iter().filter_map(|&k| ml.search(k, 0)).map(|f| f.value).sum::<f32>())
    });
    for (name, m) in &maps {
        let v = m.view();
        g.bench_function(*name, |b| {
            b.iter(|| keys.iter().filter_map(|&k| v.search(k, 0)).map(|f| f.value).sum::<f32>())
        });
    }
    g.finish();

    let mut g = c.benchmark_group("leaves");
    g.sample_size(10);
    g.bench_function("arena", |b| b.iter(|| tree.leaves(0).map(|l| l.value).sum::<f32>()));
    for (name, m) in &maps {
        if name.contains("-b") {
            continue;
        }
        let v = m.view();
        g.bench_function(*name, |b| b.iter(|| v.leaves(0).map(|l| l.value).sum::<f32>()));
    }
    g.finish();

    let rs = rays(tree, 500);
    let opts = CastOptions { ignore_unknown: false, max_range: Some(30.0) };
    let mut g = c.benchmark_group("cast_ray 500");
    g.sample_size(10);
    g.bench_function("arena", |b| {
        b.iter(|| rs.iter().filter(|(o, d)| tree.cast_ray(*o, *d, opts).is_ok_and(|r| r.hit())).count())
    });
    for (name, m) in &maps {
        if name.contains("-b") {
            continue;
        }
        let v = m.view();
        g.bench_with_input(BenchmarkId::new("view", name), &v, |b, v| {
            b.iter(|| rs.iter().filter(|(o, d)| v.cast_ray(*o, *d, opts).is_ok_and(|r| r.hit())).count())
        });
    }
    g.finish();
}

/// Resident KiB of the mappings of `path` (from /proc/self/smaps).
fn mapped_rss_kib(path: &Path) -> u64 {
    let name = path.to_string_lossy();
    let Ok(smaps) = std::fs::read_to_string("/proc/self/smaps") else {
        return 0;
    };
    let mut inside = false;
    let mut total = 0;
    for line in smaps.lines() {
        let first = line.split_whitespace().next().unwrap_or("");
        if first.contains('-') && first.chars().all(|c| c.is_ascii_hexdigit() || c == '-') {
            inside = line.ends_with(name.as_ref());
        } else if inside && line.starts_with("Rss:") {
            total += line.split_whitespace().nth(1).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
        }
    }
    total
}

fn vm_rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmRSS:")).and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

/// The scale experiment (see the module docs).
fn scale(scans: usize) {
    let dir = std::env::var_os("OLM_SCALE_DIR").map(PathBuf::from).unwrap_or_else(std::env::temp_dir);
    let path = dir.join("olm-scale.olm");
    let t = Instant::now();
    let tree = build(scans, 0.05, false);
    let nodes = tree.calc_num_nodes();
    eprintln!(
        "scale: {scans} outdoor scans at 0.05 m: {nodes} nodes, built in {:.0} s, RSS {} MiB",
        t.elapsed().as_secs_f64(),
        vm_rss_kib() / 1024
    );
    let t = Instant::now();
    mapped::write_file(&tree, &path).unwrap();
    eprintln!("scale: wrote {} bytes in {:.1} s", file_len(&path), t.elapsed().as_secs_f64());
    let keys = query_keys(&tree, 100_000, 9);
    drop(tree);
    eprintln!("scale: tree dropped, RSS {} MiB", vm_rss_kib() / 1024);
    let rss0 = vm_rss_kib();
    let t = Instant::now();
    let map = MappedMap::open(&path).unwrap();
    let open = t.elapsed();
    let v = map.view();
    let t = Instant::now();
    let found = keys.iter().filter(|&&k| v.search(k, 0).is_some()).count();
    let q = t.elapsed();
    let rss1 = vm_rss_kib();
    eprintln!("scale: resident pages of the mapped file after the queries: {} MiB", mapped_rss_kib(&path) / 1024);
    eprintln!(
        "scale: open {:.1} µs; 100k random searches ({found} found) in {:.1} ms ({:.0} ns each, cold page cache not forced); RSS {} MiB before open, {} MiB after the queries (+{} MiB of {} MiB mapped)",
        open.as_secs_f64() * 1e6,
        q.as_secs_f64() * 1e3,
        q.as_secs_f64() * 1e9 / keys.len() as f64,
        rss0 / 1024,
        rss1 / 1024,
        (rss1.saturating_sub(rss0)) / 1024,
        file_len(&path) >> 20,
    );
    let t = Instant::now();
    let report = map.verify().unwrap();
    eprintln!(
        "scale: verify {:.1} s ({} nodes), RSS {} MiB",
        t.elapsed().as_secs_f64(),
        report.nodes,
        vm_rss_kib() / 1024
    );
    if std::env::var_os("OLM_SCALE_KEEP").is_none() {
        let _ = std::fs::remove_file(&path);
    }
}

criterion_group! {
    name = group;
    config = Criterion::default()
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    targets = benches
}

fn main() {
    if let Some(scans) = std::env::var("OLM_SCALE").ok().and_then(|s| s.parse().ok()) {
        scale(scans);
        return;
    }
    group();
    Criterion::default().configure_from_args().final_summary();
}
