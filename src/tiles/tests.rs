//! Tiled maps against the single tree: merged bytes, queries, budgets,
//! tile sets on disk.

use super::*;
use crate::formats::ot::to_bytes as ot;
use crate::geometry::Point3;
use crate::key::Key;
use crate::ray::CastOptions;
use crate::scan::ScanOptions;
use crate::sensor::SensorModel;
use crate::tree::{Clock, InnerNodes, NodeKind, OccupancyTree};

/// The bundled sample's first scans (indoor lidar).
fn scans(n: usize) -> Vec<(Vec<Point3>, Point3)> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph");
    let g = crate::formats::graph::read_file(path).unwrap();
    g.nodes.iter().take(n).map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect()
}

/// A dense sphere of points 2 m around `(0.5, 0.5, 0.5)`: its rays reach
/// every voxel inside, so a few scans saturate and prune the ball in
/// blocks up to 16 voxels a side (fine tiles pruned whole, and merged
/// above the tile depth).
fn sphere() -> Vec<Point3> {
    let n = 20_000;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            let p = [r * a.cos(), r * a.sin(), z].map(|c| (0.5 + 2.0 * c) as f32);
            Point3::new(p[0], p[1], p[2])
        })
        .collect()
}

/// A small scan for the refusals.
fn wall() -> Vec<Point3> {
    (0..100).map(|i| Point3::new(1.0, 0.01 * i as f32, 0.3)).collect()
}

fn single(kind: NodeKind, scans: &[(Vec<Point3>, Point3)], opts: &ScanOptions) -> OccupancyTree {
    let mut t = OccupancyTree::with_kind(0.1, SensorModel::default(), kind).unwrap();
    for (i, (p, o)) in scans.iter().enumerate() {
        t.set_clock(Clock::Fixed(1000 + i as u32));
        t.insert_point_cloud(p, *o, opts).unwrap();
        if opts.inner == InnerNodes::Defer {
            t.update_inner_occupancy();
        }
    }
    t
}

fn tiled(kind: NodeKind, depth: u8, scans: &[(Vec<Point3>, Point3)], opts: &ScanOptions) -> TiledMap {
    let mut t = TiledMap::new(0.1, SensorModel::default(), kind, depth).unwrap();
    for (i, (p, o)) in scans.iter().enumerate() {
        t.set_clock(Clock::Fixed(1000 + i as u32));
        t.insert_point_cloud(p, *o, opts).unwrap();
        if opts.inner == InnerNodes::Defer {
            t.update_inner_occupancy().unwrap();
        }
    }
    t
}

fn test_scans() -> Vec<(Vec<Point3>, Point3)> {
    let mut s = scans(2);
    // the sphere, six times: saturates and prunes
    for _ in 0..6 {
        s.push((sphere(), Point3::new(0.5, 0.5, 0.5)));
    }
    s
}

#[test]
fn merged_tiles_are_the_single_tree_at_every_depth() {
    let scans = test_scans();
    for kind in [NodeKind::Plain, NodeKind::Stamped] {
        for inner in [InnerNodes::Update, InnerNodes::Defer] {
            if kind == NodeKind::Stamped && inner == InnerNodes::Defer {
                continue;
            }
            let opts = ScanOptions { inner, ..Default::default() };
            let want = single(kind, &scans, &opts);
            let want_bytes = ot(&want);
            for depth in [1, 2, 5, 9, 12, 14, 15] {
                let map = tiled(kind, depth, &scans, &opts);
                let merged = map.merge().unwrap();
                assert!(ot(&merged) == want_bytes, "{kind:?} {inner:?} depth {depth}");
                assert_eq!(map.stats().nodes as usize, want.size(), "{kind:?} {inner:?} depth {depth}");
                if kind == NodeKind::Stamped {
                    let stamps = |t: &OccupancyTree| t.nodes(0).map(|n| n.extra).collect::<Vec<_>>();
                    assert_eq!(stamps(&merged), stamps(&want), "stamps at depth {depth}");
                }
            }
        }
    }
}

#[test]
fn whole_tiles_prune_into_the_levels_above() {
    // a pruned node above the tile depth: at depth 15 the wall's saturated
    // blocks are many tiles, each one leaf
    let scans = test_scans();
    let want = single(NodeKind::Plain, &scans, &ScanOptions::default());
    let coarse = want.leaves(0).find(|l| l.depth < 14).expect("the scans prune above depth 14");
    let map = tiled(NodeKind::Plain, 15, &scans, &ScanOptions::default());
    // the tiles below that leaf are leaves of one value, merged above them
    assert_eq!(map.search(coarse.key, 0).unwrap(), want.search(coarse.key, 0));
    assert!(map.search(coarse.key, 0).unwrap().unwrap().depth < 14);
    assert!(ot(&map.merge().unwrap()) == ot(&want));
}

#[test]
fn queries_answer_as_the_single_tree() {
    let scans = test_scans();
    let want = single(NodeKind::Plain, &scans, &ScanOptions::default());
    let map = tiled(NodeKind::Plain, 6, &scans, &ScanOptions::default());
    let mut rng = 12345u64;
    let mut next = |n: u32| {
        rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((rng >> 33) % u64::from(n)) as u32
    };
    for _ in 0..3000 {
        let k = Key::new((32730 + next(80)) as u16, (32730 + next(80)) as u16, (32740 + next(60)) as u16);
        let depth = next(17) as u8;
        assert_eq!(map.search(k, depth).unwrap(), want.search(k, depth), "{k:?} at {depth}");
    }
    for _ in 0..200 {
        let o = Point3::new(next(40) as f32 / 10.0 - 2.0, next(40) as f32 / 10.0 - 2.0, 0.5);
        let d = Point3::new(next(200) as f32 - 100.0, next(200) as f32 - 100.0, next(20) as f32 - 10.0);
        let opts = CastOptions { ignore_unknown: next(2) == 0, max_range: Some(8.0) };
        let a = map.cast_ray(o, d, opts).map_err(|e| e.to_string());
        let b = want.cast_ray(o, d, opts).map_err(|e| TileError::from(e).to_string());
        assert_eq!(a, b);
    }
}

#[test]
fn a_tiny_budget_spills_and_reads_back_to_the_same_map() {
    let dir = tempfile::tempdir().unwrap();
    let scans = test_scans();
    let want = single(NodeKind::Stamped, &scans, &ScanOptions::default());
    for depth in [3, 8] {
        let mut map = TiledMap::new(0.1, SensorModel::default(), NodeKind::Stamped, depth).unwrap();
        map.set_budget(MemoryBudget { bytes: 1, dir: dir.path().join(format!("spill{depth}")) }).unwrap();
        for (i, (p, o)) in scans.iter().enumerate() {
            map.set_clock(Clock::Fixed(1000 + i as u32));
            let opts = ScanOptions { threads: Some(2), ..Default::default() };
            map.insert_point_cloud(p, *o, &opts).unwrap();
            assert_eq!(map.stats().live_tiles, 0);
        }
        let k = want.key(Point3::new(1.1, 0.0, 0.3)).unwrap();
        assert_eq!(map.search(k, 0).unwrap(), want.search(k, 0));
        assert!(ot(&map.merge().unwrap()) == ot(&want), "depth {depth}");
    }
}

#[test]
fn a_tile_set_round_trips_and_queries_map_only_their_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let scans = test_scans();
    let want = single(NodeKind::Plain, &scans, &ScanOptions::default());
    let mut map = tiled(NodeKind::Plain, 5, &scans, &ScanOptions::default());
    let set_dir = dir.path().join("m.tiles");
    let manifest = map.flush(&set_dir).unwrap();
    assert!(manifest.tiles.len() > 4);
    let set = TileSet::open(&set_dir).unwrap();
    assert_eq!(set.node_count() as usize, want.size());
    let p = Point3::new(1.1, 0.0, 0.3);
    assert_eq!(set.search_point(p, 0).unwrap(), want.search_point(p, 0).unwrap());
    assert_eq!(set.mapped_tiles(), 1);
    assert_eq!(set.verify().unwrap().tiles, manifest.tiles.len());
    assert!(ot(&set.merge().unwrap()) == ot(&want));
}

#[test]
fn tasks_build_parts_that_combine_into_the_set() {
    let dir = tempfile::tempdir().unwrap();
    let scans = test_scans();
    let want = single(NodeKind::Plain, &scans, &ScanOptions::default());
    let set_dir = dir.path().join("m.tiles");
    for index in 0..3 {
        let mut map = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 6).unwrap();
        map.set_task(TaskPart::hashed(index, 3));
        for (p, o) in &scans {
            map.insert_point_cloud(p, *o, &ScanOptions::default()).unwrap();
        }
        map.flush(&set_dir).unwrap();
        if index == 1 {
            assert!(matches!(combine_parts(&set_dir), Err(TileError::Parts { .. })));
        }
    }
    combine_parts(&set_dir).unwrap();
    let set = TileSet::open(&set_dir).unwrap();
    assert!(ot(&set.merge().unwrap()) == ot(&want));
}

/// Tasks owning the ranges of a plan, each casting only the rays that
/// reach its range, on one thread and pipelined: their parts combine into
/// the single tree's set.
#[test]
fn planned_tasks_build_parts_that_combine_into_the_set() {
    let dir = tempfile::tempdir().unwrap();
    let scans = test_scans();
    let want = single(NodeKind::Plain, &scans, &ScanOptions::default());
    let mut work = TileWork::new(0.1, 6).unwrap();
    for (p, o) in &scans {
        work.add_scan(p, *o, None);
    }
    let plan = work.split(3).unwrap();
    assert!(plan.tasks.iter().all(|t| t.work > 0), "{plan:?}");
    let set_dir = dir.path().join("m.tiles");
    for index in 0..3 {
        let mut map = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 6).unwrap();
        map.set_task(plan.task(index).unwrap());
        if index == 1 {
            let opts = ScanOptions { threads: Some(2), ..Default::default() };
            map.insert_point_clouds(scans.iter().map(|(p, o)| (p, *o)), &opts, |_, _| ()).unwrap();
        } else {
            for (p, o) in &scans {
                map.insert_point_cloud(p, *o, &ScanOptions::default()).unwrap();
            }
        }
        map.flush(&set_dir).unwrap();
    }
    combine_parts(&set_dir).unwrap();
    let set = TileSet::open(&set_dir).unwrap();
    assert!(ot(&set.merge().unwrap()) == ot(&want));
}

/// Parts whose ranges leave a gap, overlap, or mix with the hash split
/// are refused, naming the parts.
#[test]
fn parts_must_tile_the_prefixes_exactly() {
    let scans = test_scans();
    let part = |dir: &std::path::Path, task: TaskPart| {
        let mut map = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 2).unwrap();
        map.set_task(task);
        map.insert_point_cloud(&scans[0].0, scans[0].1, &ScanOptions::default()).unwrap();
        map.flush(dir).unwrap();
    };
    let range = |index, start, end| TaskPart { index, count: 2, tiles: TaskTiles::Prefixes { start, end } };
    let refused = |parts: &[TaskPart]| {
        let dir = tempfile::tempdir().unwrap();
        parts.iter().for_each(|&t| part(dir.path(), t));
        match combine_parts(dir.path()) {
            Err(TileError::Parts { reason, .. }) => reason,
            other => panic!("{other:?}"),
        }
    };
    let gap = refused(&[range(0, 0, 30), range(1, 31, 64)]);
    assert!(gap.contains("30..31") && gap.contains("task-1-of-2.manifest"), "{gap}");
    let overlap = refused(&[range(0, 0, 32), range(1, 31, 64)]);
    assert!(overlap.contains("task-1-of-2.manifest") && overlap.contains("overlaps task-0-of-2.manifest"), "{overlap}");
    let short = refused(&[range(0, 0, 32), range(1, 32, 63)]);
    assert!(short.contains("63..64"), "{short}");
    let mixed = refused(&[range(0, 0, 32), TaskPart::hashed(1, 2)]);
    assert!(mixed.contains("by hash") && mixed.contains("task-0-of-2.manifest"), "{mixed}");
}

#[test]
fn colour_maps_and_lazy_stamped_updates_are_refused() {
    let e = TiledMap::new(0.1, SensorModel::default(), NodeKind::Color, 4).unwrap_err();
    assert!(matches!(e, TileError::Unsupported(_)));
    assert!(matches!(TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 16), Err(TileError::BadDepth(16))));
    let mut m = TiledMap::new(0.1, SensorModel::default(), NodeKind::Stamped, 4).unwrap();
    let opts = ScanOptions { inner: InnerNodes::Defer, ..Default::default() };
    assert!(matches!(m.insert_point_cloud(&wall(), Point3::default(), &opts), Err(TileError::Unsupported(_))));
    let mut m = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 4).unwrap();
    m.insert_point_cloud(&wall(), Point3::default(), &opts).unwrap();
    assert!(matches!(m.merge(), Err(TileError::StaleInnerNodes)));
    m.update_inner_occupancy().unwrap();
    m.merge().unwrap();
}

/// Counts the nodes a walk reports and, at each, how many tiles read for
/// the walk exist.
struct TileCounter {
    nodes: u64,
    most_loaded: usize,
}

impl crate::tree::PreorderVisitor for TileCounter {
    type Break = std::convert::Infallible;

    fn enter(
        &mut self,
        node: &crate::tree::PreorderNode,
        _: &crate::tree::ChildGroup<'_>,
    ) -> std::ops::ControlFlow<Self::Break> {
        self.leaf(node)
    }

    fn leaf(&mut self, _: &crate::tree::PreorderNode) -> std::ops::ControlFlow<Self::Break> {
        self.nodes += 1;
        self.most_loaded = self.most_loaded.max(super::stream::loaded::COUNT.with(|c| c.get().0));
        std::ops::ControlFlow::Continue(())
    }
}

#[test]
fn a_walk_of_a_spilled_map_or_a_tile_set_holds_one_tile_read_from_disk_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let scans = test_scans();
    let want = single(NodeKind::Plain, &scans, &ScanOptions::default());
    let mut map = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 11).unwrap();
    map.set_budget(MemoryBudget { bytes: 1, dir: dir.path().join("spill") }).unwrap();
    for (p, o) in &scans {
        map.insert_point_cloud(p, *o, &ScanOptions::default()).unwrap();
    }
    assert!(map.stats().tiles > 30, "{:?}", map.stats());
    map.flush(&dir.path().join("set.tiles")).unwrap();
    let set = TileSet::open(&dir.path().join("set.tiles")).unwrap();
    let check = |what: &str, walk: &dyn Fn(&mut TileCounter) -> Result<(), TileError>| {
        super::stream::loaded::COUNT.with(|c| c.set((0, 0)));
        let mut counter = TileCounter { nodes: 0, most_loaded: 0 };
        walk(&mut counter).unwrap();
        assert_eq!(counter.nodes, want.size() as u64, "{what}");
        // inside the tiles one tile was read, never two at once
        assert_eq!(counter.most_loaded, 1, "{what}");
        assert_eq!(super::stream::loaded::COUNT.with(|c| c.get()), (0, 1), "{what}");
        assert_eq!(map.stats().live_tiles, 0, "{what}: the walk kept tiles in memory");
    };
    check("spilled map", &|v| map.visit_preorder(v).map(|_| ()));
    check("tile set", &|v| set.visit_preorder(v).map(|_| ()));
}

/// The set's manifest rewritten with `change` applied to it.
fn rewrite_manifest(set_dir: &std::path::Path, change: impl FnOnce(&mut Manifest)) {
    let path = set_dir.join(MANIFEST_FILE);
    let mut m = read_manifest(&path).unwrap();
    change(&mut m);
    std::fs::write(&path, m.to_bytes()).unwrap();
}

/// A tile file that is not the one its manifest line describes (same
/// length, node count and root; another CRC-32, as a tile of another build
/// of the map would be) is refused by the merge, the walk the file writers
/// take, and queries checked fully, naming the file and the CRC-32.
#[test]
fn a_tile_file_other_than_the_manifests_feeds_no_merge_walk_or_query() {
    let dir = tempfile::tempdir().unwrap();
    let scans = test_scans();
    let mut map = tiled(NodeKind::Plain, 5, &scans, &ScanOptions::default());
    let set_dir = dir.path().join("m.tiles");
    map.flush(&set_dir).unwrap();
    let p = Point3::new(1.1, 0.0, 0.3);
    let reached = TileId::of_key(map.key(p).unwrap(), 5);
    rewrite_manifest(&set_dir, |m| {
        let entry = m.tiles.iter_mut().find(|t| t.id == reached).unwrap();
        entry.crc32 ^= 0x8000_0001;
    });
    let file = set_dir.join(reached.file_name());
    let is_crc_error = |e: &TileError| {
        matches!(e, TileError::DamagedTile { tile, path, reason }
            if *tile == reached && *path == file && reason.contains("CRC-32"))
    };
    let set = TileSet::open(&set_dir).unwrap();
    let e = set.merge().unwrap_err();
    assert!(is_crc_error(&e), "{e}");
    let e = crate::formats::ot::write_map(&set, std::io::sink()).unwrap_err();
    let inner = e.get_ref().and_then(|e| e.downcast_ref::<TileError>()).unwrap();
    assert!(is_crc_error(inner), "{e}");
    let e = set.search_point(p, 0).unwrap_err();
    assert!(is_crc_error(&e), "{e}");
    assert!(is_crc_error(&set.verify().unwrap_err()));
}

/// A spilled tile's file that no longer holds what was spilled (another
/// CRC-32 than the one recorded when it was written) is refused when read
/// back for an update, a merge, a walk or a copy into a set.
#[test]
fn a_spilled_tile_changed_on_disk_is_never_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let scans = test_scans();
    let mut map = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 5).unwrap();
    map.set_budget(MemoryBudget { bytes: 1, dir: dir.path().join("spill") }).unwrap();
    for (p, o) in &scans {
        map.insert_point_cloud(p, *o, &ScanOptions::default()).unwrap();
    }
    let (&prefix, tile) =
        map.tiles.iter_mut().find(|(_, t)| matches!(t.state, super::map::TileState::Spilled(_))).unwrap();
    let super::map::TileState::Spilled(entry) = &mut tile.state else { unreachable!() };
    // as if the file on disk had been replaced by another of its length
    entry.crc32 ^= 1;
    let id = TileId::from_prefix(5, prefix);
    let refused = |e: TileError| match e {
        TileError::DamagedTile { tile, reason, .. } => tile == id && reason.contains("CRC-32"),
        _ => false,
    };
    assert!(refused(map.merge().unwrap_err()));
    let e = crate::formats::ot::write_map(&map, std::io::sink()).unwrap_err();
    assert!(e.to_string().contains("CRC-32"), "{e}");
    assert!(refused(map.flush(&dir.path().join("copy.tiles")).unwrap_err()));
    assert!(refused(map.update_key(id.key_range().0, true, InnerNodes::Update).unwrap_err()));
}

#[test]
fn a_set_lock_admits_one_build_of_the_set_or_of_each_task() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("m.tiles");
    let locked = |r: Result<SetLock, TileError>| match r {
        Err(TileError::Locked { dir, lock, holder }) => {
            assert_eq!(dir, set);
            format!("{holder} {}", lock.display())
        }
        other => panic!("{other:?}"),
    };
    let whole = SetLock::acquire(&set).unwrap();
    assert!(set.join(LOCK_FILE).is_file());
    assert!(locked(SetLock::acquire(&set)).contains("another build"));
    assert!(locked(SetLock::acquire_task(&set, TaskPart::hashed(0, 2))).contains("whole set"));
    drop(whole);
    // a set the lock created and nothing went into is gone with it
    assert!(!set.exists());
    std::fs::create_dir(&set).unwrap();
    drop(SetLock::acquire(&set).unwrap());
    assert!(set.is_dir() && std::fs::read_dir(&set).unwrap().next().is_none(), "lock files left");
    let (t0, t1) = (TaskPart::hashed(0, 2), TaskPart::hashed(1, 2));
    let first = SetLock::acquire_task(&set, t0).unwrap();
    let second = SetLock::acquire_task(&set, t1).unwrap();
    assert!(locked(SetLock::acquire_task(&set, t0)).contains("task 0 of 2"));
    assert!(locked(SetLock::acquire(&set)).contains("another build"));
    let mut map = tiled(NodeKind::Plain, 3, &test_scans()[..1], &ScanOptions::default());
    map.set_task(t0);
    map.flush(&set).unwrap();
    drop(first);
    assert!(set.join(LOCK_FILE).exists(), "task 1 of 2 holds it still");
    drop(second);
    assert!(set.join("task-0-of-2.manifest").is_file(), "a set written into stays");
    assert!(!set.join(LOCK_FILE).exists() && !set.join(".task-0-of-2.lock").exists());
    let _whole = SetLock::acquire(&set).unwrap();
    let e = combine_parts(&set).unwrap_err();
    assert!(matches!(e, TileError::Locked { .. }), "{e}");
    // a file where the set should be
    let file = dir.path().join("f.tiles");
    std::fs::write(&file, "x").unwrap();
    let e = SetLock::acquire(&file).unwrap_err();
    assert!(matches!(e, TileError::NotADirectory { .. }), "{e}");
    let text = e.to_string();
    assert!(text.contains("exists and is not a directory") && text.contains("remove it"), "{text}");
    assert_eq!(text.matches("exists").count(), 1, "{text}");
}

#[cfg(unix)]
#[test]
fn writes_into_a_set_replace_links_and_never_write_through_them() {
    use std::os::unix::fs::symlink;
    let dir = tempfile::tempdir().unwrap();
    let outside = dir.path().join("outside");
    std::fs::create_dir(&outside).unwrap();
    let scans = test_scans();
    let mut map = tiled(NodeKind::Plain, 5, &scans, &ScanOptions::default());
    let set = dir.path().join("m.tiles");
    std::fs::create_dir(&set).unwrap();
    // links named like every file the writers write, and a stale tile
    let stale = TileId::from_prefix(5, 7).file_name();
    let mut names: Vec<String> = map.tiles().map(|t| t.file_name()).collect();
    names.extend([MANIFEST_FILE.to_string(), "task-0-of-2.manifest".into(), stale.clone(), LOCK_FILE.into()]);
    for name in &names {
        std::fs::write(outside.join(name), "precious").unwrap();
        symlink(outside.join(name), set.join(name)).unwrap();
    }
    // (a build takes the lock first, which refuses a link named `manifest`)
    let mut part = tiled(NodeKind::Plain, 5, &scans[..1], &ScanOptions::default());
    part.set_task(TaskPart::hashed(0, 2));
    part.flush(&set).unwrap();
    let manifest = map.flush(&set).unwrap();
    remove_unlisted_tiles(&set, &manifest).unwrap();
    drop(SetLock::acquire(&set).unwrap());
    // a budget's directory too
    let spill = dir.path().join("spill");
    std::fs::create_dir(&spill).unwrap();
    let mut capped = TiledMap::new(0.1, SensorModel::default(), NodeKind::Plain, 5).unwrap();
    for name in &names[..2] {
        symlink(outside.join(name), spill.join(name)).unwrap();
    }
    capped.set_budget(MemoryBudget { bytes: 1, dir: spill.clone() }).unwrap();
    for (p, o) in &scans {
        capped.insert_point_cloud(p, *o, &ScanOptions::default()).unwrap();
    }
    for name in &names {
        assert_eq!(std::fs::read_to_string(outside.join(name)).unwrap(), "precious", "{name} written through");
        if name == LOCK_FILE {
            assert!(set.join(name).symlink_metadata().is_err(), "the lock file stays after its build");
        } else if name != &stale {
            assert!(!set.join(name).symlink_metadata().unwrap().file_type().is_symlink(), "{name}");
        }
    }
    assert!(!set.join(&stale).exists() && set.join(&stale).symlink_metadata().is_err(), "the stale link stays");
    for name in &names[..2] {
        assert!(spill.join(name).symlink_metadata().unwrap().is_file(), "{name}");
    }
    let set = TileSet::open(&set).unwrap();
    assert!(ot(&set.merge().unwrap()) == ot(&map.merge().unwrap()));
}

/// Far more tile bytes than the merged map's are reported; sensible
/// depths are not.
#[test]
fn oversized_sets_are_those_of_far_more_tile_bytes_than_the_map() {
    let scans = scans(12);
    let report = |depth| {
        let mut map = tiled(NodeKind::Plain, depth, &scans, &ScanOptions::default());
        let dir = tempfile::tempdir().unwrap();
        let manifest = map.flush(&dir.path().join("s.tiles")).unwrap();
        let nodes = TileSet::open(&dir.path().join("s.tiles")).unwrap().node_count();
        oversize(&manifest, nodes)
    };
    assert_eq!(report(8), None);
    let over = report(15).expect("depth 15 holds far more bytes than the map");
    assert!(over.tile_bytes > 2 * over.merged_bytes, "{over:?}");
    assert!(over.to_string().contains("smaller tile depth"), "{over}");
}
