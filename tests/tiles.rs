//! Tiled maps against the untiled build: random scans, tile depths and
//! memory budgets give the same map, and the same `.ot` and `.bt` bytes and
//! statistics written tile by tile; a tile set's queries answer as the
//! merged map; damaged, missing and mismatched files are errors naming the
//! tile or the manifest line, never a panic (and the manifest's fuzz
//! target holds on every damaged manifest).

// the fuzz target below tests `cfg(fuzzing)`, which cargo-fuzz sets
#![allow(unexpected_cfgs)]

use octolinear::formats::{bt, ot};
use octolinear::tiles::{MemoryBudget, TileCheck, TileError, TileSet, TiledMap};
use octolinear::tree::{PreorderSource, Summarize, TreeSummary};
use octolinear::{
    BoundsRule, CastOptions, Clock, InnerNodes, NodeKind, OccupancyTree, Point3, ScanOptions, SensorModel,
};
use proptest::prelude::*;
use std::path::Path;

#[path = "../fuzz/fuzz_targets/tiles_manifest.rs"]
mod fuzz_tiles_manifest;

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).unwrap();
    v
}

/// What a map walked as one tree writes: `.ot`, `.bt` (maximum
/// likelihood, with the records' summary) and `.bt` as it is, and the
/// summary of the walk.
fn streamed(map: &impl PreorderSource) -> (Vec<u8>, Vec<u8>, Vec<u8>, TreeSummary, TreeSummary) {
    let (mut o, mut b, mut c) = (Vec::new(), Vec::new(), Vec::new());
    let mut full = Summarize::new(map);
    ot::write_map_observed(map, &mut o, &mut full).unwrap();
    let mut ml = bt::write_map(map, &mut b).unwrap();
    let summary = ml.summary(map).unwrap();
    // the same with the records waiting in a scratch file
    let mut again = Vec::new();
    let scratch = tempfile::tempfile().unwrap();
    let mut ml = bt::write_map_observed_with_scratch(map, &mut again, &mut (), scratch).unwrap();
    assert!(again == b, "the .bt through a scratch file differs");
    assert_eq!(ml.summary(map).unwrap(), summary);
    bt::write_const_map(map, &mut c).unwrap();
    (o, b, c, full.finish(), summary)
}

/// The numbers a [`TreeSummary`] holds, as `tree` (compacted) has them.
fn summary_of(tree: &OccupancyTree) -> (u64, u64, u64, [f64; 3], [f64; 3], usize, usize, u64) {
    let mut t = tree.clone();
    t.compact();
    let at = t.nodes(0).filter(|n| t.sensor().is_at_threshold(n.value)).count() as u64;
    let b = t.bounds(BoundsRule::CenterHalfSize);
    let grid = t.memory_full_grid(BoundsRule::CenterHalfSize);
    (t.size() as u64, t.num_leaves() as u64, at, b.min, b.max, t.octomap_memory_usage(), t.memory_usage(), grid)
}

fn summary_numbers(s: &TreeSummary) -> (u64, u64, u64, [f64; 3], [f64; 3], usize, usize, u64) {
    let (b, grid) = (s.bounds, s.memory_full_grid());
    (s.nodes, s.leaves, s.at_threshold, b.min, b.max, s.octomap_memory_usage(), s.compacted_memory_usage(), grid)
}

/// A scan: points and origin, in a few metres around the map's centre (so
/// that rays cross the borders of coarse and fine tiles alike).
fn scan() -> impl Strategy<Value = (Vec<Point3>, Point3)> {
    let coord = || -2.0f32..2.0;
    let point = (coord(), coord(), coord()).prop_map(|(x, y, z)| Point3::new(x, y, z));
    // points clustered in a corner as well, so that voxels saturate and prune
    let near = (0.0f32..0.4, 0.0f32..0.4, 0.0f32..0.4).prop_map(|(x, y, z)| Point3::new(x, y, z));
    (prop::collection::vec(prop_oneof![point, near], 1..300), (coord(), coord(), coord()))
        .prop_map(|(points, (x, y, z))| (points, Point3::new(x, y, z)))
}

/// Scan options OctoMap has: max range, discretize, lazy updates.
fn options() -> impl Strategy<Value = ScanOptions> {
    (prop::option::of(0.5f64..3.0), any::<bool>(), any::<bool>()).prop_map(|(max_range, discretize, lazy)| {
        ScanOptions::default().with_max_range(max_range).with_discretize(discretize).with_inner(if lazy {
            InnerNodes::Defer
        } else {
            InnerNodes::Update
        })
    })
}

fn build_single(kind: NodeKind, res: f64, scans: &[(Vec<Point3>, Point3)], opts: &ScanOptions) -> OccupancyTree {
    let mut t = OccupancyTree::with_kind(res, SensorModel::default(), kind).unwrap();
    for (i, (points, origin)) in scans.iter().enumerate() {
        t.set_clock(Clock::Fixed(100 + 3 * i as u32));
        t.insert_point_cloud(points, *origin, opts).unwrap();
        if opts.inner == InnerNodes::Defer {
            t.update_inner_occupancy();
        }
    }
    t
}

fn build_tiled(
    kind: NodeKind,
    res: f64,
    depth: u8,
    budget: Option<MemoryBudget>,
    scans: &[(Vec<Point3>, Point3)],
    opts: &ScanOptions,
) -> TiledMap {
    let mut t = TiledMap::new(res, SensorModel::default(), kind, depth).unwrap();
    if let Some(b) = budget {
        t.set_budget(b).unwrap();
    }
    for (i, (points, origin)) in scans.iter().enumerate() {
        t.set_clock(Clock::Fixed(100 + 3 * i as u32));
        t.insert_point_cloud(points, *origin, opts).unwrap();
        if opts.inner == InnerNodes::Defer {
            t.update_inner_occupancy().unwrap();
        }
    }
    t
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Any scans, any tile depth, with or without a budget (down to one
    /// byte: every tile written out and read back after every group):
    /// the merged map is the untiled one, node counts and answers alike.
    #[test]
    fn tiled_builds_equal_the_untiled_build(
        scans in prop::collection::vec(scan(), 1..6),
        depth in 1u8..=15,
        cap in prop::option::of(prop_oneof![Just(1usize), 1usize..200_000]),
        opts in options(),
        stamped in any::<bool>(),
        threads in prop_oneof![Just(Some(1)), Just(Some(2)), Just(None)],
    ) {
        let kind = if stamped && opts.inner == InnerNodes::Update { NodeKind::Stamped } else { NodeKind::Plain };
        let opts = opts.with_threads(threads);
        let res = 0.1;
        let want = build_single(kind, res, &scans, &opts);
        let dir = tempfile::tempdir().unwrap();
        let budget = cap.map(|bytes| MemoryBudget { bytes, dir: dir.path().join("spill") });
        let map = build_tiled(kind, res, depth, budget, &scans, &opts);
        let merged = map.merge().unwrap();
        prop_assert!(ot_bytes(&merged) == ot_bytes(&want));
        prop_assert_eq!(map.stats().nodes as usize, want.size());
        let stamps = |t: &OccupancyTree| t.nodes(0).map(|n| n.extra).collect::<Vec<_>>();
        prop_assert_eq!(stamps(&merged), stamps(&want));
        // every leaf's centre, and its parent's, answer alike
        for leaf in want.leaves(0).step_by(5) {
            for d in [0, leaf.depth.saturating_sub(1)] {
                prop_assert_eq!(map.search(leaf.key, d).unwrap(), want.search(leaf.key, d));
            }
        }
    }

    /// The writers walk a tiled map (with or without a budget) and the
    /// tile set written from it tile by tile: `.ot`, `.bt` and `.bt` as it
    /// is come out byte for byte the untiled tree's, and the statistics of
    /// the walk and of the `.bt` records are those of the tree and of its
    /// maximum-likelihood, pruned form.
    #[test]
    fn tiled_maps_and_tile_sets_write_the_untiled_bytes_tile_by_tile(
        scans in prop::collection::vec(scan(), 1..5),
        depth in 1u8..=15,
        cap in prop::option::of(prop_oneof![Just(1usize), 1usize..200_000]),
        opts in options(),
        stamped in any::<bool>(),
    ) {
        let kind = if stamped && opts.inner == InnerNodes::Update { NodeKind::Stamped } else { NodeKind::Plain };
        let want = build_single(kind, 0.1, &scans, &opts);
        let (mut o, mut b, mut c) = (Vec::new(), Vec::new(), Vec::new());
        ot::write(&want, &mut o).unwrap();
        bt::write(&want, &mut b).unwrap();
        bt::write_const(&want, &mut c).unwrap();
        let mut ml = want.clone();
        ml.to_max_likelihood();
        ml.prune();
        let dir = tempfile::tempdir().unwrap();
        let budget = cap.map(|bytes| MemoryBudget { bytes, dir: dir.path().join("spill") });
        let mut map = build_tiled(kind, 0.1, depth, budget, &scans, &opts);
        let live = map.stats().live_tiles;
        let from_map = streamed(&map);
        prop_assert_eq!(map.stats().live_tiles, live);
        map.flush(&dir.path().join("m.tiles")).unwrap();
        let from_set = streamed(&TileSet::open(&dir.path().join("m.tiles")).unwrap());
        for (what, (so, sb, sc, full, ml_summary)) in [("map", from_map), ("set", from_set)] {
            prop_assert!(so == o, "{} .ot", what);
            prop_assert!(sb == b, "{} .bt", what);
            prop_assert!(sc == c, "{} .bt as it is", what);
            prop_assert_eq!(summary_numbers(&full), summary_of(&want), "{}", what);
            prop_assert_eq!(summary_numbers(&ml_summary), summary_of(&ml), "{} maximum likelihood", what);
        }
    }

    /// A tile set written from a tiled map answers random points (at any
    /// depth) and rays as the merged map does.
    #[test]
    fn tile_set_queries_equal_the_merged_map(
        scans in prop::collection::vec(scan(), 1..4),
        depth in 1u8..=15,
        queries in prop::collection::vec(((-3.0f32..3.0, -3.0f32..3.0, -3.0f32..3.0), 0u8..=16), 1..60),
        rays in prop::collection::vec(((-2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0), (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0), any::<bool>()), 1..30),
    ) {
        let opts = ScanOptions::default();
        let mut map = build_tiled(NodeKind::Plain, 0.1, depth, None, &scans, &opts);
        let merged = map.merge().unwrap();
        let dir = tempfile::tempdir().unwrap();
        let set_dir = dir.path().join("m.tiles");
        map.flush(&set_dir).unwrap();
        let set = TileSet::open(&set_dir).unwrap();
        prop_assert_eq!(set.node_count() as usize, merged.size());
        for ((x, y, z), d) in queries {
            let p = Point3::new(x, y, z);
            prop_assert_eq!(set.search_point(p, d).unwrap(), merged.search_point(p, d).unwrap());
        }
        for ((ox, oy, oz), (dx, dy, dz), ignore_unknown) in rays {
            let (o, dir) = (Point3::new(ox, oy, oz), Point3::new(dx, dy, dz));
            let opts = CastOptions { ignore_unknown, max_range: Some(5.0) };
            let got = set.cast_ray(o, dir, opts).map_err(|e| e.to_string());
            let want = merged.cast_ray(o, dir, opts).map_err(|e| TileError::from(e).to_string());
            prop_assert_eq!(got, want);
        }
        prop_assert!(ot_bytes(&set.merge().unwrap()) == ot_bytes(&merged));
    }
}

/// A tile set of a few scans at depth 9, written to `dir`.
fn sample_set(dir: &Path) -> TileSet {
    let scans: Vec<(Vec<Point3>, Point3)> = (0..3)
        .map(|i| {
            let points = (0..400)
                .map(|j| {
                    let a = j as f32 * 0.0157;
                    Point3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.1 * (j % 7) as f32 - 0.3)
                })
                .collect();
            (points, Point3::new(0.1 * i as f32, 0.0, 0.0))
        })
        .collect();
    let mut map = build_tiled(NodeKind::Plain, 0.1, 9, None, &scans, &ScanOptions::default());
    map.flush(dir).unwrap();
    TileSet::open(dir).unwrap()
}

/// Every byte of a tile file, damaged: the full check finds it and names
/// the tile; opening with header checks only and merging (which verifies)
/// never panics.
#[test]
fn every_damaged_tile_byte_is_an_error_naming_the_tile() {
    let dir = tempfile::tempdir().unwrap();
    let set_dir = dir.path().join("m.tiles");
    let set = sample_set(&set_dir);
    let entry = *set.manifest().tiles.iter().max_by_key(|t| t.bytes).unwrap();
    let path = set_dir.join(entry.id.file_name());
    let original = std::fs::read(&path).unwrap();
    let key = octolinear::MortonCode(entry.id.code_range().0).decode();
    let step = (original.len() / 300).max(1);
    for at in (0..original.len()).step_by(step) {
        let mut bytes = original.clone();
        bytes[at] ^= 0x41;
        std::fs::write(&path, &bytes).unwrap();
        let set = TileSet::open(&set_dir).unwrap();
        let e = set.verify().unwrap_err();
        assert!(matches!(&e, TileError::DamagedTile { tile, .. } if *tile == entry.id), "byte {at}: {e}");
        assert!(e.to_string().contains(&format!("tile {}", entry.id)), "{e}");
        assert!(set.merge().is_err(), "byte {at}: merged a damaged tile");
        assert!(set.search(key, 0).is_err(), "byte {at}: a search used a damaged tile");
        let mut loose = TileSet::open(&set_dir).unwrap();
        loose.set_check(TileCheck::Header);
        let _ = loose.search(key, 0);
    }
    std::fs::write(&path, &original).unwrap();
    // a tile file from another tile: the manifest's length and CRC differ
    let other = set.manifest().tiles.iter().find(|t| t.id != entry.id && t.bytes != entry.bytes).unwrap();
    std::fs::copy(set_dir.join(other.id.file_name()), &path).unwrap();
    let e = TileSet::open(&set_dir).unwrap().verify().unwrap_err();
    assert!(matches!(e, TileError::DamagedTile { tile, .. } if tile == entry.id), "{e}");
    std::fs::write(&path, &original).unwrap();
    TileSet::open(&set_dir).unwrap().verify().unwrap();
}

/// A tile listed in the manifest without a file is an error naming it,
/// for every use; the other tiles still answer.
#[test]
fn a_missing_tile_is_reported_not_unknown_space() {
    let dir = tempfile::tempdir().unwrap();
    let set_dir = dir.path().join("m.tiles");
    let set = sample_set(&set_dir);
    let gone = set.manifest().tiles.iter().find(|t| !t.root.is_leaf).unwrap().id;
    std::fs::remove_file(set_dir.join(gone.file_name())).unwrap();
    let set = TileSet::open(&set_dir).unwrap();
    let inside = octolinear::MortonCode(gone.code_range().0).decode();
    for e in [set.search(inside, 0).unwrap_err(), set.verify().unwrap_err(), set.merge().unwrap_err()] {
        assert!(matches!(&e, TileError::MissingTile { tile, .. } if *tile == gone), "{e}");
        assert!(e.to_string().contains("is missing"));
    }
    let elsewhere = set.manifest().tiles.iter().find(|t| t.id != gone && !t.root.is_leaf).unwrap().id;
    set.search(octolinear::MortonCode(elsewhere.code_range().0).decode(), 0).unwrap();
}

/// Damaged manifests: every flipped byte and every truncation is an error
/// with the manifest's path (and a line), never a panic; a manifest that
/// lies about a tile (checksum recomputed) is caught when the tile is read.
#[test]
fn damaged_manifests_are_errors_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let set_dir = dir.path().join("m.tiles");
    let set = sample_set(&set_dir);
    let path = set_dir.join(octolinear::tiles::MANIFEST_FILE);
    let original = std::fs::read(&path).unwrap();
    fuzz_tiles_manifest::check(&original);
    for at in 0..original.len() {
        let mut bytes = original.clone();
        bytes[at] ^= 0x04;
        fuzz_tiles_manifest::check(&bytes);
        std::fs::write(&path, &bytes).unwrap();
        let e = TileSet::open(&set_dir).err().unwrap_or_else(|| panic!("byte {at} went unnoticed"));
        assert!(matches!(e, TileError::Manifest { .. }), "{e}");
        assert!(e.to_string().contains("manifest: line"), "{e}");
    }
    for len in (0..original.len()).step_by(7) {
        fuzz_tiles_manifest::check(&original[..len]);
        std::fs::write(&path, &original[..len]).unwrap();
        assert!(TileSet::open(&set_dir).is_err());
    }
    // a root value changed and the checksum made to match: the tile's
    // check finds that its root differs
    let text = String::from_utf8(original.clone()).unwrap();
    let entry = set.manifest().tiles.iter().find(|t| !t.root.is_leaf).unwrap();
    let old = format!("{:08x} {} inner", entry.root.value.to_bits(), entry.root.extra);
    let new = format!("{:08x} {} inner", (entry.root.value + 1.0).to_bits(), entry.root.extra);
    let body = text[..text.rfind("crc32 ").unwrap()].replacen(&old, &new, 1);
    let lying = format!("{body}crc32 {:08x}\n", crc32fast::hash(body.as_bytes()));
    std::fs::write(&path, lying).unwrap();
    let e = TileSet::open(&set_dir).unwrap().verify().unwrap_err();
    assert!(
        matches!(&e, TileError::DamagedTile { tile, reason, .. } if *tile == entry.id && reason.contains("root")),
        "{e}"
    );
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(TileSet::open(&set_dir), Err(TileError::Io { .. })));
}
