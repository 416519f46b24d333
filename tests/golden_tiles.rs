//! Every scan-built golden case built as tiles: at depths from coarse
//! (tiles of half the map) to fine (2 voxels a side, pruned whole and merged
//! above), and under a memory budget so small that every tile is written
//! out and read back after each group of updates (the constants say which
//! cases get which depths), and group by group (groups split down to
//! single tiles), the `.ot` and `.bt` written tile by tile from
//! the tiled map are OctoMap's to the byte; the tile set written from it
//! writes them too, merges to the same tree, and its queries answer as
//! that merged map.

mod common;
#[path = "common/scans.rs"]
mod scans;

use common::*;
use octolinear::formats::{bt, ot};
use octolinear::tiles::{GroupedBuild, MemoryBudget, TileSet, TileWork, TiledMap};
use octolinear::tree::PreorderSource;
use octolinear::{CastOptions, InnerNodes, NodeKind, OccupancyTree, Point3, ScanOptions, UpdateBox};
use rayon::prelude::*;
use scans::{case_scans, Scan};
use serde_json::Value;

/// The depths every case is built at.
const DEPTHS: [u8; 5] = [1, 3, 8, 13, 15];

/// Depths built under a budget of one byte: the first for every case,
/// the second (thousands of tiles written and read back per scan in the
/// large cases) for every third.
const CAPPED_DEPTHS: [u8; 2] = [5, 12];

/// The depth of the group-by-group builds (a memory of one byte: groups
/// split down to single tiles).
const GROUPED_DEPTH: u8 = 6;

/// Depths whose tile sets are written and queried: the first for every
/// case, the second for every third.
const SET_DEPTHS: [u8; 2] = [3, 13];

/// Cases whose golden `.ot` is larger than this are built one at a time:
/// at tile depth 15 they hold hundreds of thousands of tiles.
const LARGE_OT_BYTES: u64 = 4 << 20;

/// The `.ot` and `.bt` bytes of a map walked as one tree (a tree, a
/// tiled map, a tile set).
fn bytes(map: &impl PreorderSource) -> (Vec<u8>, Vec<u8>) {
    let (mut o, mut b) = (Vec::new(), Vec::new());
    ot::write_map(map, &mut o).unwrap();
    bt::write_map(map, &mut b).unwrap();
    (o, b)
}

/// A case's resolution and insertion options.
fn case_options(case: &Value) -> (f64, ScanOptions) {
    let p = &case["params"];
    let res = p["resolution"].as_f64().unwrap();
    let max_range = p["maxrange"].as_f64().unwrap();
    let lazy = p["lazy_eval"].as_bool().unwrap_or(false);
    let probe = OccupancyTree::new(res).unwrap();
    let bbx = p["bbx"].as_str().map(|s| {
        let v: Vec<f32> = s.split(',').map(|t| t.parse().unwrap()).collect();
        UpdateBox::new(&probe, Point3::new(v[0], v[1], v[2]), Point3::new(v[3], v[4], v[5])).unwrap()
    });
    let opts = ScanOptions::default()
        .with_max_range((max_range >= 0.0).then_some(max_range))
        .with_discretize(p["discretize"].as_bool().unwrap_or(false))
        .with_inner(if lazy { InnerNodes::Defer } else { InnerNodes::Update })
        .with_bbx(bbx);
    (res, opts)
}

/// Builds one case as tiles at `depth`, with a budget when `spill` names
/// a directory.
fn build(case: &Value, scans: &[Scan], depth: u8, spill: Option<&std::path::Path>) -> TiledMap {
    let (res, opts) = case_options(case);
    let lazy = opts.inner == InnerNodes::Defer;
    let mut map = TiledMap::new(res, case_sensor(case), NodeKind::Plain, depth).unwrap();
    if let Some(dir) = spill {
        map.set_budget(MemoryBudget { bytes: 1, dir: dir.to_path_buf() }).unwrap();
    }
    for (points, origin) in scans {
        map.insert_point_cloud(points, *origin, &opts).unwrap();
        if lazy {
            map.update_inner_occupancy().unwrap();
        }
    }
    map
}

/// The golden point and ray queries, asked of the tile set and of the
/// merged tree.
fn check_queries(f: &mut Failures, g: &Golden, case: &Value, set: &TileSet, merged: &OccupancyTree, depth: u8) {
    let id = case["id"].as_str().unwrap();
    if let Some(text) = g.load_text(case, "query_points.csv") {
        for line in text.lines().skip(1) {
            let cols: Vec<&str> = line.split(',').collect();
            let p = point_from_hex(&cols[1..4]);
            let Ok(k) = merged.key(p) else { continue };
            for d in [0, 14] {
                let got = set.search(k, d).unwrap();
                f.check(got == merged.search(k, d), || format!("{id} depth {depth}: search {k:?} at {d}"));
            }
        }
    }
    if let Some(text) = g.load_text(case, "query_castray.csv") {
        for line in text.lines().skip(1) {
            let cols: Vec<&str> = line.split(',').collect();
            let (origin, dir) = (point_from_hex(&cols[1..4]), point_from_hex(&cols[4..7]));
            let opts = CastOptions { ignore_unknown: cols[7] == "1", max_range: Some(parse_f64hex(cols[8])) };
            let got = set.cast_ray(origin, dir, opts).map_err(|e| e.to_string());
            let want =
                merged.cast_ray(origin, dir, opts).map_err(|e| octolinear::tiles::TileError::from(e).to_string());
            f.check(got == want, || format!("{id} depth {depth}: castRay from {origin:?} along {dir:?}"));
        }
    }
}

/// A directory on disk, under `target/`, for the tile files of one build,
/// removed when dropped: files in a memory file system would add to the
/// memory of test binaries running side by side.
fn scratch_dir() -> tempfile::TempDir {
    tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap()
}

fn run_case(g: &Golden, (index, case): (usize, &Value)) -> Vec<String> {
    let mut f = Failures::default();
    let id = case["id"].as_str().unwrap();
    let Some(scans) = case_scans(g, case) else {
        return vec![format!("{id}: no plain-text scans")];
    };
    let every_third = index % 3 == 0;
    let capped = CAPPED_DEPTHS.into_iter().take(if every_third { 2 } else { 1 });
    let runs = DEPTHS.map(|d| (d, false)).into_iter().chain(capped.map(|d| (d, true)));
    // group by group, in groups split until they hold one tile
    let dir = scratch_dir();
    let (res, opts) = case_options(case);
    let mut work = TileWork::new(res, GROUPED_DEPTH).unwrap();
    for (points, origin) in &scans {
        work.add_scan(points, *origin, opts.max_range);
    }
    let grouped = GroupedBuild {
        resolution: res,
        sensor: case_sensor(case),
        memory: 1,
        dir: dir.path().to_path_buf(),
        record: None,
    };
    let given = || scans.iter().map(|(p, o)| Ok::<_, std::convert::Infallible>((p, *o)));
    grouped.build(&work, &opts, given, |_, _| {}).unwrap();
    let (o, b) = bytes(&TileSet::open(dir.path()).unwrap());
    let before = f.0.len();
    f.check_digest(g, case, "tree.ot", &o);
    f.check_digest(g, case, "tree.bt", &b);
    for failure in &mut f.0[before..] {
        *failure = format!("grouped at tile depth {GROUPED_DEPTH}: {failure}");
    }
    drop(dir);
    for (depth, capped) in runs {
        // declared before the map, so removed after it
        let dir = scratch_dir();
        let spill = capped.then(|| dir.path().join("spill"));
        let mut map = build(case, &scans, depth, spill.as_deref());
        if spill.is_some() {
            f.check(map.stats().live_tiles == 0, || format!("{id}: tiles stayed in memory under a 1-byte budget"));
        }
        let (o, b) = bytes(&map);
        let what = if capped { "capped " } else { "" };
        let before = f.0.len();
        f.check_digest(g, case, "tree.ot", &o);
        f.check_digest(g, case, "tree.bt", &b);
        for failure in &mut f.0[before..] {
            *failure = format!("{what}tile depth {depth}: {failure}");
        }
        if depth == SET_DEPTHS[0] || (every_third && depth == SET_DEPTHS[1]) {
            let set_dir = dir.path().join("set");
            map.flush(&set_dir).unwrap();
            let set = TileSet::open(&set_dir).unwrap();
            let merged = map.merge().unwrap();
            check_queries(&mut f, g, case, &set, &merged, depth);
            f.check(bytes(&merged) == (o.clone(), b.clone()), || format!("{id} depth {depth}: the merge differs"));
            f.check(bytes(&set) == (o, b), || format!("{id} depth {depth}: the set writes other bytes"));
        }
    }
    f.0
}

#[test]
fn golden_build_cases_built_as_tiles_merge_to_octomap_bytes() {
    let g = golden();
    let cases = g.cases("build");
    assert!(cases.len() > 100, "manifest lists the build cases");
    // the largest cases one at a time (at tile depth 15 each holds
    // hundreds of thousands of tiles), beside the others in parallel
    let large = |c: &Value| g.file(c, "tree.ot").is_some_and(|f| f.bytes > LARGE_OT_BYTES);
    let (large, rest): (Vec<_>, Vec<_>) = cases.into_iter().enumerate().partition(|(_, c)| large(c));
    let (mut failures, rest): (Vec<String>, Vec<String>) = rayon::join(
        || large.into_iter().flat_map(|case| run_case(&g, case)).collect(),
        || rest.into_par_iter().flat_map_iter(|case| run_case(&g, case)).collect(),
    );
    failures.extend(rest);
    Failures(failures).finish("golden build cases as tiles");
}
