//! The ablation layouts build the same tree as `OccupancyTree`: identical
//! leaf dumps (key, depth, value bits, in iteration order) on the same
//! scans, so the harness compares storage only. Also checks that the
//! measured bytes of the pointer and block layouts are what their formulas
//! say, and that the pointer layout's formula is OctoMap's `memoryUsage()`.

use octolinear::{InnerNodes, Key, OccupancyTree, Point3, ScanOptions, SensorModel};
use octolinear_ablation::alloc::{self, CountingAlloc};
use octolinear_ablation::pointer::PointerTree;
use octolinear_ablation::variants::{ArenaBatch, ArenaCompact, ArenaPerKey, Block8, MappedLayout, Split8};
use octolinear_ablation::{build, graph2tree_sensor, leaf_dump, tree_leaf_dump, Layout, LeafRecord, ScanKeys};
use octolinear_sim::{simulate, LidarConfig, SceneKind, SplitMix64};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

type Scan = (Vec<Point3>, Point3);

fn scans(kind: SceneKind, n: usize, seed: u64) -> Vec<Scan> {
    let cfg = LidarConfig { horizontal_steps: 120, ..LidarConfig::indoor() };
    let cfg = if kind == SceneKind::Outdoor { LidarConfig { max_range: 40.0, ..cfg } } else { cfg };
    let g = simulate(kind, n, seed, &cfg).unwrap();
    g.nodes
        .iter()
        .map(|node| {
            let (pc, origin) = node.graph2tree();
            (pc.points, origin)
        })
        .collect()
}

/// The reference: `insert_point_cloud` scan by scan, and the key lists.
fn reference(res: f64, sensor: SensorModel, scans: &[Scan]) -> (OccupancyTree, Vec<ScanKeys>) {
    let mut tree = OccupancyTree::with_sensor(res, sensor).unwrap();
    let mut keys = Vec::new();
    for (pts, origin) in scans {
        keys.push(ScanKeys::of_scan(&tree, pts, *origin).unwrap());
        tree.insert_point_cloud(pts, *origin, &ScanOptions::default()).unwrap();
    }
    (tree, keys)
}

fn check_all(res: f64, sensor: SensorModel, keys: &[ScanKeys], want: &[LeafRecord], want_size: usize, what: &str) {
    fn one<L: Layout>(name: &str, res: f64, sensor: SensorModel, keys: &[ScanKeys], want: &[LeafRecord], size: usize) {
        let l: L = build(res, sensor, keys);
        let got = leaf_dump(&l);
        if got != want {
            let first = got.iter().zip(want).position(|(a, b)| a != b).unwrap_or(got.len().min(want.len()));
            panic!(
                "{name}: {} leaves vs {} expected; first difference at {first}: {:?} vs {:?}",
                got.len(),
                want.len(),
                got.get(first),
                want.get(first)
            );
        }
        assert_eq!(l.node_count(), size, "{name}: node count");
        assert_eq!(l.leaf_count(), want.len(), "{name}: leaf count");
    }
    println!("{what}: {} leaves, {want_size} nodes", want.len());
    one::<PointerTree>("pointer", res, sensor, keys, want, want_size);
    one::<ArenaPerKey>("arena per key", res, sensor, keys, want, want_size);
    one::<ArenaBatch>("arena batch", res, sensor, keys, want, want_size);
    one::<ArenaCompact>("arena compact", res, sensor, keys, want, want_size);
    one::<Block8>("block8", res, sensor, keys, want, want_size);
    one::<Split8>("split8", res, sensor, keys, want, want_size);
    one::<MappedLayout>("mapped", res, sensor, keys, want, want_size);
}

#[test]
fn layouts_dump_the_same_leaves_as_occupancy_tree_on_simulated_scans() {
    let sensor = graph2tree_sensor();
    for (kind, res) in [(SceneKind::Indoor, 0.1), (SceneKind::Indoor, 0.2), (SceneKind::Outdoor, 0.25)] {
        let s = scans(kind, 3, 11);
        // the scans twice over: free space saturates, prunes, and gets
        // expanded again by later hits
        let seq: Vec<Scan> = s.iter().chain(s.iter()).chain(s.iter()).cloned().collect();
        let (tree, keys) = reference(res, sensor, &seq);
        let want = tree_leaf_dump(&tree);
        assert!(want.iter().any(|l| l.1 < 16), "{kind:?} {res}: nothing was pruned");
        check_all(res, sensor, &keys, &want, tree.size(), &format!("{kind:?} at {res} m"));
    }
}

#[test]
fn layouts_agree_under_heavy_pruning_and_expansion() {
    // random hits and misses in a small cube: constant pruning and
    // re-expansion of pruned leaves
    let sensor = SensorModel::default();
    let mut rng = SplitMix64(5);
    let mut keys = Vec::new();
    for scan in 0..80 {
        // mostly misses first (free space saturates and prunes up to 8^3
        // blocks), then many hits (pruned blocks are expanded again)
        let mut set = std::collections::BTreeMap::new();
        for _ in 0..600 {
            let k = Key::new(32768 + rng.below(16) as u16, 32768 + rng.below(16) as u16, 32768 + rng.below(8) as u16);
            let occupied = rng.below(3) == 0 && (scan >= 50 || rng.below(20) == 0);
            set.insert(octolinear::MortonCode::encode(k).0, occupied);
        }
        let free = set.iter().filter(|e| !*e.1).map(|e| octolinear::MortonCode(*e.0).decode()).collect();
        let occupied = set.iter().filter(|e| *e.1).map(|e| octolinear::MortonCode(*e.0).decode()).collect();
        keys.push(ScanKeys { free, occupied });
    }
    let mut tree = OccupancyTree::with_sensor(0.1, sensor).unwrap();
    for s in &keys {
        tree.apply_sorted(&s.free, &s.occupied, InnerNodes::Update);
    }
    let mut halfway = OccupancyTree::with_sensor(0.1, sensor).unwrap();
    for s in &keys[..50] {
        halfway.apply_sorted(&s.free, &s.occupied, InnerNodes::Update);
    }
    assert!(tree_leaf_dump(&halfway).iter().any(|l| l.1 < 15), "no multi-level pruning happened");
    let want = tree_leaf_dump(&tree);
    check_all(0.1, sensor, &keys, &want, tree.size(), "random cube");
}

#[test]
fn searches_and_ray_casts_agree() {
    let sensor = graph2tree_sensor();
    let s = scans(SceneKind::Indoor, 2, 3);
    let (tree, keys) = reference(0.1, sensor, &s);
    let p: PointerTree = build(0.1, sensor, &keys);
    let b: Split8 = build(0.1, sensor, &keys);
    let m: MappedLayout = build(0.1, sensor, &keys);
    assert!(m.map().is_some(), "finish() wrote the .olm bytes");
    let mut rng = SplitMix64(9);
    for _ in 0..20_000 {
        let k = Key::new(
            32768 - 150 + rng.below(300) as u16,
            32768 - 150 + rng.below(300) as u16,
            32768 - 20 + rng.below(60) as u16,
        );
        let want = tree.search(k, 0).map(|f| f.value.to_bits());
        assert_eq!(p.search(k).map(f32::to_bits), want, "{k}");
        assert_eq!(b.search(k).map(f32::to_bits), want, "{k}");
        assert_eq!(m.search(k).map(f32::to_bits), want, "{k}");
    }
    let ks = tree.key_space();
    let a: ArenaBatch = build(0.1, sensor, &keys);
    let mut hits = 0;
    for i in 0..500 {
        let t = i as f32 * 0.0125;
        let dir = Point3::new(t.cos(), t.sin(), 0.1 * (3.0 * t).sin());
        let o = s[0].1;
        let x = octolinear_ablation::cast_ray(&a, ks, &sensor, o, dir, 20.0, false);
        assert_eq!(x, octolinear_ablation::cast_ray(&p, ks, &sensor, o, dir, 20.0, false));
        hits += usize::from(x.is_some());
    }
    assert!(hits > 50, "only {hits} of 500 rays hit");
}

#[test]
fn unpruned_pointer_tree_is_the_expanded_tree() {
    let sensor = graph2tree_sensor();
    let s = scans(SceneKind::Indoor, 3, 11);
    let seq: Vec<Scan> = s.iter().chain(s.iter()).cloned().collect();
    let (tree, keys) = reference(0.2, sensor, &seq);
    let mut unpruned = PointerTree::without_pruning();
    for k in &keys {
        unpruned.apply_scan(&k.free, &k.occupied, &sensor);
    }
    let mut expanded = tree.clone();
    expanded.expand().unwrap();
    assert!(expanded.size() > tree.size());
    assert_eq!(unpruned.node_count(), expanded.size());
    let (inner, leaves) = unpruned.count_inner_and_leaves();
    assert_eq!(inner + leaves, expanded.calc_num_nodes());
    assert_eq!(leaves, expanded.num_leaves());
}

#[test]
fn measured_bytes_match_the_layout_formulas_and_octomaps_memory_usage() {
    assert!(alloc::is_counting());
    let sensor = graph2tree_sensor();
    let s = scans(SceneKind::Indoor, 3, 4);
    let (tree, keys) = reference(0.1, sensor, &s);

    // allocations of this thread only: other tests run concurrently
    let before = alloc::thread_live_bytes();
    let p: PointerTree = build(0.1, sensor, &keys);
    let pointer_bytes = (alloc::thread_live_bytes() - before) as usize;
    assert_eq!(pointer_bytes, p.bytes_formula());
    let (inner, leaves) = p.count_inner_and_leaves();
    assert_eq!(pointer_bytes, 16 * (inner + leaves) + 64 * inner);
    assert_eq!(pointer_bytes, octolinear_ablation::paper_bytes(inner, leaves, 8));
    // OctoMap's memoryUsage() = the tree object (320 B) + the same formula
    assert_eq!(tree.octomap_memory_usage(), 320 + pointer_bytes);
    drop(p);

    let before = alloc::thread_live_bytes();
    let b: Block8 = build(0.1, sensor, &keys);
    let block_bytes = (alloc::thread_live_bytes() - before) as usize;
    assert_eq!(block_bytes, b.bytes_formula() - std::mem::size_of::<Block8>());

    let before = alloc::thread_live_bytes();
    let a: ArenaCompact = build(0.1, sensor, &keys);
    let arena_bytes = (alloc::thread_live_bytes() - before) as usize;
    assert_eq!(arena_bytes, a.bytes_formula() - std::mem::size_of::<OccupancyTree>());
    assert!(arena_bytes * 3 <= pointer_bytes, "compacted arena {arena_bytes} B vs pointer {pointer_bytes} B");

    if octolinear_oracle::require_or_skip("ablation oracle memoryUsage") {
        let mut o = octolinear_oracle::OracleTree::with_graph2tree_default(0.1).unwrap();
        for (pts, origin) in &s {
            let pts: Vec<[f32; 3]> = pts.iter().map(|p| [p.x, p.y, p.z]).collect();
            o.insert_point_cloud(&pts, [origin.x, origin.y, origin.z], -1.0, false, false).unwrap();
        }
        assert_eq!(o.size() as usize, inner + leaves);
        assert_eq!(o.memory_usage() as usize, 320 + pointer_bytes);
    }
}
