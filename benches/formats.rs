//! `.ot` and `.bt` read and write throughput (bytes of the file per second)
//! on simulated maps.
//!
//! `cargo bench -p octolinear-benches --bench formats`

mod common;

use common::*;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use octolinear::formats::{bt, ot};
use octolinear::OccupancyTree;
use octolinear_sim::SceneKind;
use std::hint::black_box;
use std::time::Duration;

/// Indoor at 0.05 m (24 scans) and outdoor at 0.1 m (6 scans).
fn maps() -> Vec<(String, OccupancyTree)> {
    [(SceneKind::Indoor, 24, 0.05), (SceneKind::Outdoor, 6, 0.1)]
        .into_iter()
        .map(|(kind, n, res)| {
            let tree = build(&scans(kind, n), res, None);
            (format!("{}_{res}", kind_name(kind)), tree)
        })
        .collect()
}

fn formats(c: &mut Criterion) {
    for (name, tree) in maps() {
        let mut ot_bytes = Vec::new();
        ot::write(&tree, &mut ot_bytes).unwrap();
        let mut bt_bytes = Vec::new();
        bt::write(&tree, &mut bt_bytes).unwrap();
        let mut ml = tree.clone();
        ml.to_max_likelihood();
        ml.prune();
        eprintln!("formats: {name}: {} nodes, .ot {} bytes, .bt {} bytes", tree.size(), ot_bytes.len(), bt_bytes.len());
        let mut g = c.benchmark_group(format!("formats/{name}"));
        g.throughput(Throughput::Bytes(ot_bytes.len() as u64));
        g.bench_function("ot_write", |b| {
            b.iter(|| {
                let mut v = Vec::with_capacity(ot_bytes.len());
                ot::write(black_box(&tree), &mut v).unwrap();
                v
            })
        });
        g.bench_function("ot_read", |b| b.iter(|| ot::read(black_box(&ot_bytes[..])).unwrap()));
        g.throughput(Throughput::Bytes(bt_bytes.len() as u64));
        // writeBinary: a max-likelihood, pruned copy, then the bytes
        g.bench_function("bt_write", |b| {
            b.iter(|| {
                let mut v = Vec::with_capacity(bt_bytes.len());
                bt::write(black_box(&tree), &mut v).unwrap();
                v
            })
        });
        // writeBinaryConst on a tree that is already max-likelihood and pruned
        g.bench_function("bt_write_const_ml", |b| {
            b.iter(|| {
                let mut v = Vec::with_capacity(bt_bytes.len());
                bt::write_const(black_box(&ml), &mut v).unwrap();
                v
            })
        });
        g.bench_function("bt_read", |b| b.iter(|| bt::read(black_box(&bt_bytes[..])).unwrap()));
        g.finish();
    }
}

fn config() -> Criterion {
    Criterion::default().sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3))
}

criterion_group! {
    name = benches;
    config = config();
    targets = formats
}
criterion_main!(benches);
