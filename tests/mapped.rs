//! The `.olm` mapped format: one query suite run against the arena tree, a
//! `Vec`-backed view, a borrowed-slice view and an mmap-backed view (every
//! layout), round trips through `.ot`/`.bt` (golden maps included), golden
//! point and ray queries answered from mapped files, and a corruption suite
//! of seeded mutants that must never panic.

// the fuzz target compiled in below tests `cfg(fuzzing)`, which cargo-fuzz sets
#![allow(unexpected_cfgs)]

mod common;

use common::*;
use octolinear::formats::{bt, ot};
use octolinear::mapped::{
    self, format, MapView, MappedMap, OccupancyLookup, OlmError, SearchBlocksSection, Variant, WriteOptions,
};
use octolinear::ray::CastError;
use octolinear::{CastOptions, CastOutcome, CountingTree, Found, Key, KeyBox, NodeKind, OccupancyTree, Point3};
use octolinear::{ScanOptions, SensorModel};
use octolinear_sim::{simulate, LidarConfig, SceneKind, SplitMix64};
use std::fmt::Write as _;

// ----- maps ------------------------------------------------------------------

fn small_lidar() -> LidarConfig {
    LidarConfig { beams: 8, horizontal_steps: 120, ..LidarConfig::indoor() }
}

fn simulated(kind: SceneKind, scans: usize, seed: u64, res: f64, cfg: &LidarConfig) -> OccupancyTree {
    simulated_kind(kind, scans, seed, res, cfg, NodeKind::Plain)
}

/// A simulated map of any node kind: colour maps get a colour per end
/// point (from its position) and their inner colours; stamped maps a
/// different second per scan.
fn simulated_kind(
    kind: SceneKind,
    scans: usize,
    seed: u64,
    res: f64,
    cfg: &LidarConfig,
    node_kind: NodeKind,
) -> OccupancyTree {
    let graph = simulate(kind, scans, seed, cfg).unwrap();
    let mut tree = OccupancyTree::with_kind(res, SensorModel::default(), node_kind).unwrap();
    for (i, node) in graph.nodes.iter().enumerate() {
        tree.set_clock(octolinear::Clock::Fixed(1_700_000_000 + 7 * i as u32));
        let (cloud, origin) = node.graph2tree();
        let colors: Vec<[u8; 3]> =
            cloud.points.iter().map(|p| [(p.x * 40.0) as u8, (p.y * 40.0) as u8, (p.z * 90.0) as u8]).collect();
        tree.insert_colored_point_cloud(&cloud.points, &colors, origin, &ScanOptions::default()).unwrap();
    }
    if node_kind == NodeKind::Color {
        tree.update_inner_occupancy();
    }
    tree
}

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).unwrap();
    v
}

fn bt_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    bt::write(tree, &mut v).unwrap();
    v
}

/// `writeBinaryConst`: the tree as it is (for trees already maximum
/// likelihood and pruned; pruning a stamped tree again after its stamps are
/// gone would merge more).
fn bt_const(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    bt::write_const(tree, &mut v).unwrap();
    v
}

/// What the maximum-likelihood variant holds: the tree converted and pruned
/// as `writeBinary` does (stamps take part in pruning), then without its
/// colours or stamps (white, 0), which `.bt` does not store.
fn ml_of(tree: &OccupancyTree) -> OccupancyTree {
    let mut t = tree.clone();
    t.to_max_likelihood();
    t.prune();
    t.converted(NodeKind::Plain).converted(tree.kind())
}

fn all_options() -> Vec<(&'static str, WriteOptions)> {
    vec![
        ("full/rank", WriteOptions::default()),
        ("full/rank blocks", WriteOptions { search_blocks: SearchBlocksSection::Always, ..Default::default() }),
        ("full/rank b64", WriteOptions { rank_block_log2: 6, ..Default::default() }),
        ("full/pointers", WriteOptions::pointers()),
        ("ml/rank", WriteOptions::max_likelihood()),
        ("ml/rank b4096", WriteOptions { rank_block_log2: 12, ..WriteOptions::max_likelihood() }),
    ]
}

// ----- one query suite for every implementation -------------------------------

type Item = (Key, u8, u32, bool, u32);

/// The queries compared between implementations.
trait Queries {
    fn lookup(&self) -> &dyn OccupancyLookup;
    fn items(&self, which: Iter, max_depth: u8) -> Vec<Item>;
    /// The leaves taken `skip` by `next`, the rest by `fold` (which has
    /// its own fast path on the view).
    fn leaves_folded(&self, max_depth: u8, skip: usize) -> Vec<Item>;
    fn cast(&self, o: Point3, d: Point3, opts: CastOptions) -> Result<CastOutcome, CastError>;
    fn search_many(&self, keys: &[Key], depth: u8) -> Vec<Option<Found>>;
}

#[derive(Clone, Copy)]
enum Iter {
    Leaves,
    Nodes,
    Box(KeyBox),
}

fn item(i: octolinear::tree::NodeItem<'_>) -> Item {
    (i.key, i.depth, i.value.to_bits(), i.is_leaf, i.extra)
}

impl Queries for OccupancyTree {
    fn lookup(&self) -> &dyn OccupancyLookup {
        self
    }
    fn items(&self, which: Iter, d: u8) -> Vec<Item> {
        let f = |n: octolinear::tree::NodeItem<'_>| (n.key, n.depth, n.value.to_bits(), n.is_leaf, n.extra);
        match which {
            Iter::Leaves => self.leaves(d).map(f).collect(),
            Iter::Nodes => self.nodes(d).map(f).collect(),
            Iter::Box(b) => self.leaves_in_box(b, d).map(f).collect(),
        }
    }
    fn leaves_folded(&self, d: u8, skip: usize) -> Vec<Item> {
        let f = |n: octolinear::tree::NodeItem<'_>| (n.key, n.depth, n.value.to_bits(), n.is_leaf, n.extra);
        let mut it = self.leaves(d);
        let head: Vec<Item> = it.by_ref().take(skip).map(f).collect();
        it.fold(head, |mut v, n| {
            v.push(f(n));
            v
        })
    }
    fn cast(&self, o: Point3, d: Point3, opts: CastOptions) -> Result<CastOutcome, CastError> {
        self.cast_ray(o, d, opts)
    }
    fn search_many(&self, keys: &[Key], depth: u8) -> Vec<Option<Found>> {
        let mut out = Vec::new();
        OccupancyTree::search_many(self, keys, depth, &mut out);
        out
    }
}

impl Queries for MapView<'_> {
    fn lookup(&self) -> &dyn OccupancyLookup {
        self
    }
    fn items(&self, which: Iter, d: u8) -> Vec<Item> {
        match which {
            Iter::Leaves => self.leaves(d).map(item).collect(),
            Iter::Nodes => self.nodes(d).map(item).collect(),
            Iter::Box(b) => self.leaves_in_box(b, d).map(item).collect(),
        }
    }
    fn leaves_folded(&self, d: u8, skip: usize) -> Vec<Item> {
        let mut it = self.leaves(d);
        let head: Vec<Item> = it.by_ref().take(skip).map(item).collect();
        it.fold(head, |mut v, n| {
            v.push(item(n));
            v
        })
    }
    fn cast(&self, o: Point3, d: Point3, opts: CastOptions) -> Result<CastOutcome, CastError> {
        self.cast_ray(o, d, opts)
    }
    fn search_many(&self, keys: &[Key], depth: u8) -> Vec<Option<Found>> {
        let mut out = Vec::new();
        MapView::search_many(self, keys, depth, &mut out);
        out
    }
}

impl<D: AsRef<[u8]>> Queries for MappedMap<D> {
    fn lookup(&self) -> &dyn OccupancyLookup {
        self
    }
    fn items(&self, which: Iter, d: u8) -> Vec<Item> {
        self.view().items(which, d)
    }
    fn leaves_folded(&self, d: u8, skip: usize) -> Vec<Item> {
        self.view().leaves_folded(d, skip)
    }
    fn cast(&self, o: Point3, d: Point3, opts: CastOptions) -> Result<CastOutcome, CastError> {
        mapped::cast_ray(self, o, d, opts)
    }
    fn search_many(&self, keys: &[Key], depth: u8) -> Vec<Option<Found>> {
        let mut out = Vec::new();
        MappedMap::search_many(self, keys, depth, &mut out);
        out
    }
}

fn found_bits(f: Option<Found>) -> Option<(u32, u8, bool, u32)> {
    f.map(|f| (f.value.to_bits(), f.depth, f.is_leaf, f.extra))
}

/// Runs every query on `reference` and `other` and compares bit for bit.
fn same_answers(what: &str, reference: &dyn Queries, other: &dyn Queries, seed: u64) {
    let r = reference.lookup();
    let o = other.lookup();
    assert_eq!(r.key_space(), o.key_space(), "{what}: key space");
    assert_eq!(r.sensor(), o.sensor(), "{what}: sensor");
    let mut rng = SplitMix64(seed);
    // the reference is a tree: sample keys from its leaves
    let leaves = reference.items(Iter::Leaves, 0);
    let mut keys = vec![Key::ROOT, Key::new(0, 0, 0), Key::new(65535, 65535, 65535)];
    for i in 0..600 {
        keys.push(match i % 3 {
            0 if !leaves.is_empty() => leaves[rng.below(leaves.len() as u32) as usize].0,
            1 if !leaves.is_empty() => {
                let b = leaves[rng.below(leaves.len() as u32) as usize].0;
                Key(b.0.map(|c| c.wrapping_add((rng.below(64) as u16).wrapping_sub(32))))
            }
            _ => Key([0; 3].map(|_: u16| rng.next_u64() as u16)),
        });
    }
    for depth in [0, 16, 17, 15, 14, 12, 9, 5, 1] {
        let batch = other.search_many(&keys, depth);
        for (&k, b) in keys.iter().zip(batch) {
            let expected = found_bits(r.search(k, depth));
            assert_eq!(expected, found_bits(o.search(k, depth)), "{what}: search({k}, {depth})");
            assert_eq!(expected, found_bits(b), "{what}: search_many, key {k}, depth {depth}");
        }
    }
    for d in [0, 16, 14, 13, 8, 3, 1] {
        let leaves = reference.items(Iter::Leaves, d);
        assert_eq!(leaves, other.items(Iter::Leaves, d), "{what}: leaves({d})");
        // fold from the start, from inside a depth-15 node's voxels, and after the end
        for skip in [0, 1, 7, leaves.len()] {
            assert_eq!(leaves, other.leaves_folded(d, skip), "{what}: leaves({d}) folded after {skip}");
        }
    }
    for d in [0, 14, 2] {
        assert_eq!(reference.items(Iter::Nodes, d), other.items(Iter::Nodes, d), "{what}: nodes({d})");
    }
    for _ in 0..6 {
        let a = keys[rng.below(keys.len() as u32) as usize];
        let ext = rng.below(200) as u16;
        let bbx = KeyBox { min: Key(a.0.map(|c| c.saturating_sub(ext))), max: Key(a.0.map(|c| c.saturating_add(ext))) };
        for d in [0, 14] {
            assert_eq!(
                reference.items(Iter::Box(bbx), d),
                other.items(Iter::Box(bbx), d),
                "{what}: leaves_in_box({bbx:?}, {d})"
            );
        }
    }
    let ks = r.key_space();
    for i in 0..120 {
        let origin = if leaves.is_empty() || i % 4 == 0 {
            Point3::new(0.0, 0.0, 0.0)
        } else {
            let k = leaves[rng.below(leaves.len() as u32) as usize].0;
            ks.key_to_point(k)
        };
        let dir = Point3::new(rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32, rng.range(-0.3, 0.3) as f32);
        for opts in [CastOptions::default(), CastOptions { ignore_unknown: true, max_range: Some(8.0) }] {
            assert_eq!(
                reference.cast(origin, dir, opts),
                other.cast(origin, dir, opts),
                "{what}: cast_ray({origin:?}, {dir:?}, {opts:?})"
            );
        }
    }
}

/// Checks every layout and backing (Vec, slice, mmap) against the tree.
fn check_all_backings(name: &str, tree: &OccupancyTree) {
    let ml = ml_of(tree);
    let dir = tempfile::tempdir().unwrap();
    for (label, opts) in all_options() {
        let what = format!("{name} {label}");
        let reference = match opts.variant {
            Variant::Full => tree,
            Variant::MaxLikelihood => &ml,
        };
        let bytes = mapped::to_bytes(tree, opts).unwrap();
        let owned = MappedMap::new(bytes.clone()).unwrap();
        let report = owned.verify().unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(report.nodes, reference.calc_num_nodes() as u64, "{what}");
        assert_eq!(report.leaves, reference.num_leaves() as u64, "{what}");
        assert_eq!(owned.header().size_counter, reference.size() as u64);
        same_answers(&format!("{what} (Vec)"), reference, &owned, 7);
        let borrowed = MappedMap::new(&bytes[..]).unwrap();
        same_answers(&format!("{what} (slice view)"), reference, &borrowed.view(), 8);
        let path = dir.path().join(format!("{}.olm", label.replace(['/', ' '], "_")));
        mapped::write_file_with(tree, &path, opts).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), bytes, "{what}: file bytes");
        let mm = MappedMap::open(&path).unwrap();
        mm.verify().unwrap();
        same_answers(&format!("{what} (mmap)"), reference, &mm, 9);
        // back to a tree: same bytes in OctoMap's formats
        let back = mm.to_tree().unwrap();
        assert_eq!(back.sensor(), tree.sensor());
        match opts.variant {
            Variant::Full => {
                assert_eq!(ot_bytes(&back), ot_bytes(tree), "{what}: .ot");
                assert_eq!(back.kind(), tree.kind(), "{what}: kind");
                // stamps are not in .ot: compare every node's extra
                let extras = |t: &OccupancyTree| t.nodes(0).map(|n| n.extra).collect::<Vec<_>>();
                assert!(extras(&back) == extras(tree), "{what}: colours or stamps differ");
            }
            Variant::MaxLikelihood => {
                assert_eq!(ot_bytes(&back), ot_bytes(&ml), "{what}: ML .ot");
                assert_eq!(bt_const(&back), bt_bytes(tree), "{what}: .bt")
            }
        }
    }
}

/// The mapped level-skip index answers as the view, in every layout, at
/// every query depth (near the data and far from it).
#[test]
fn mapped_search_index_answers_like_the_view() {
    let tree = simulated(SceneKind::Indoor, 3, 9, 0.1, &small_lidar());
    let mut rng = SplitMix64(17);
    let mut keys: Vec<Key> = tree.leaves(0).step_by(13).map(|l| l.key).collect();
    keys.extend((0..2000).map(|_| {
        let k = |r: &mut SplitMix64| 32768u16.wrapping_add(r.below(400) as u16).wrapping_sub(200);
        Key::new(k(&mut rng), k(&mut rng), k(&mut rng))
    }));
    for (label, opts) in all_options() {
        let map = MappedMap::new(mapped::to_bytes(&tree, opts).unwrap()).unwrap();
        let view = map.view();
        let index = mapped::MapSearchIndex::new(view);
        assert!(index.depth() > 0 && index.bytes() > 0, "{label}");
        for depth in [0, 16, 15, 12, index.depth(), 3] {
            for &k in &keys {
                assert_eq!(
                    found_bits(index.search(k, depth)),
                    found_bits(view.search(k, depth)),
                    "{label} {k} {depth}"
                );
            }
        }
    }
}

#[test]
fn simulated_indoor_maps_answer_like_the_tree() {
    let tree = simulated(SceneKind::Indoor, 3, 5, 0.1, &small_lidar());
    assert!(tree.num_leaves() > 1000);
    check_all_backings("indoor 0.1", &tree);
}

#[test]
fn colour_and_stamped_maps_answer_like_the_tree() {
    for kind in [NodeKind::Color, NodeKind::Stamped] {
        let tree = simulated_kind(SceneKind::Indoor, 3, 21, 0.1, &small_lidar(), kind);
        let distinct: std::collections::HashSet<u32> = tree.nodes(0).map(|n| n.extra).collect();
        assert!(distinct.len() >= 3, "{kind:?}: extras worth comparing");
        check_all_backings(&format!("indoor {kind:?}"), &tree);
        let bytes = mapped::to_bytes(&tree, WriteOptions::default()).unwrap();
        let map = MappedMap::new(&bytes[..]).unwrap();
        let view = map.view();
        assert_eq!(view.kind().node_kind(), Some(kind));
        // the colour / stamp accessors
        for leaf in tree.leaves(0).step_by(97) {
            match kind {
                NodeKind::Color => {
                    assert_eq!(view.color(leaf.key, leaf.depth), Some(octolinear::tree::unpack_rgb(leaf.extra)));
                    assert_eq!(view.stamp(leaf.key, leaf.depth), None);
                }
                _ => {
                    assert_eq!(view.stamp(leaf.key, leaf.depth), Some(leaf.extra));
                    assert_eq!(view.color(leaf.key, leaf.depth), None);
                }
            }
        }
        // the ML variant keeps the type but, as .bt, no colours or stamps
        let ml = MappedMap::new(mapped::to_bytes(&tree, WriteOptions::max_likelihood()).unwrap()).unwrap();
        assert_eq!(ml.header().kind, format::TreeKind::of(kind));
        assert!(ml.view().leaves(0).all(|l| l.extra == if kind == NodeKind::Color { 0xff_ffff } else { 0 }));
    }
}

#[test]
fn simulated_outdoor_map_with_custom_sensor() {
    let mut tree = simulated(
        SceneKind::Outdoor,
        2,
        11,
        0.2,
        &LidarConfig { beams: 8, horizontal_steps: 90, ..LidarConfig::outdoor() },
    );
    // a sensor model that is not OctoMap's default travels with the file
    let sensor = SensorModel::from_probabilities(&octolinear::SensorProbabilities {
        hit: 0.9,
        miss: 0.3,
        clamping_min: 0.2,
        clamping_max: 0.9,
        occupancy_threshold: 0.6,
    })
    .unwrap();
    tree.set_sensor(sensor);
    check_all_backings("outdoor 0.2", &tree);
}

#[test]
fn tiny_maps_empty_single_and_pruned() {
    let empty = OccupancyTree::new(0.05).unwrap();
    check_all_backings("empty", &empty);
    for (_, opts) in all_options() {
        let b = mapped::to_bytes(&empty, opts).unwrap();
        let m = MappedMap::new(&b[..]).unwrap();
        assert!(m.view().is_empty());
        assert_eq!(m.view().leaves(0).count(), 0);
        assert_eq!(m.search(Key::ROOT, 0), None);
        assert!(m.to_tree().unwrap().is_empty());
    }
    let mut one = OccupancyTree::new(0.1).unwrap();
    one.update_point(Point3::new(1.0, 2.0, 3.0), true, Default::default()).unwrap();
    check_all_backings("one voxel", &one);
    // a tree that is only its root (every voxel deleted)
    let k = one.key(Point3::new(1.0, 2.0, 3.0)).unwrap();
    one.delete(k, 0);
    assert_eq!(one.calc_num_nodes(), 1);
    check_all_backings("lone root", &one);
    // a pruned block: 8 equal voxels merge into a depth-15 leaf
    let mut block = OccupancyTree::new(0.1).unwrap();
    for x in 0..4 {
        for y in 0..4 {
            for z in 0..2 {
                let p = Point3::new(0.05 + 0.1 * x as f32, 0.05 + 0.1 * y as f32, 0.05 + 0.1 * z as f32);
                block.update_point(p, true, Default::default()).unwrap();
            }
        }
    }
    assert!(block.leaves(0).any(|l| l.depth < 16));
    check_all_backings("pruned block", &block);
}

// ----- golden maps ---------------------------------------------------------------

/// Every stored `.ot` (OcTree) of the golden set: `.ot → .olm → .ot` gives
/// the bytes the `.ot` reader and writer give, for every layout.
#[test]
fn golden_ot_files_round_trip() {
    let g = golden();
    let mut f = Failures::default();
    let (mut files, mut identical, mut counting) = (0, 0, 0);
    let mut kinds = std::collections::BTreeMap::new();
    for case in g.manifest["cases"].as_array().unwrap() {
        let id = case["id"].as_str().unwrap();
        for file in case["files"].as_array().unwrap() {
            if file["kind"] != "ot" || file["stored"] == "digest-only" {
                continue;
            }
            let name = file["name"].as_str().unwrap();
            let bytes = g.load(case, name).unwrap();
            let tree = match ot::read(&bytes[..]) {
                Ok(ot::AnyTree::Occupancy(tree)) => tree,
                Ok(ot::AnyTree::Counting(tree)) => {
                    counting += 1;
                    check_counting_round_trip(&mut f, &format!("{id}/{name}"), &tree, &bytes);
                    continue;
                }
                Err(e) => panic!("{id}/{name}: {e}"),
            };
            files += 1;
            *kinds.entry(format!("{:?}", tree.kind())).or_insert(0) += 1;
            let plain = ot_bytes(&tree);
            identical += usize::from(plain == bytes);
            for (label, opts) in all_options() {
                if opts.variant != Variant::Full {
                    continue;
                }
                let olm = mapped::to_bytes(&tree, opts).unwrap();
                let map = MappedMap::new(olm).unwrap();
                let back = match map.to_tree() {
                    Ok(t) => t,
                    Err(e) => {
                        f.0.push(format!("{id}/{name} {label}: {e}"));
                        continue;
                    }
                };
                f.check(ot_bytes(&back) == plain, || format!("{id}/{name} {label}: .ot bytes differ after .olm"));
            }
            // the ML variant equals what writeBinary stores
            let olm = mapped::to_bytes(&tree, WriteOptions::max_likelihood()).unwrap();
            let back = MappedMap::new(olm).unwrap().to_tree().unwrap();
            f.check(bt_const(&back) == bt_bytes(&tree), || format!("{id}/{name} ml: .bt bytes differ after .olm"));
        }
    }
    eprintln!(
        "{files} golden .ot files ({kinds:?}), {identical} rewritten byte-identically by the .ot writer; \
         {counting} counting trees"
    );
    assert!(files > 50);
    assert!(counting > 0, "the golden set has counting trees");
    assert!(kinds.get("Color").is_some_and(|&n| n > 0) && kinds.get("Stamped").is_some_and(|&n| n > 0), "{kinds:?}");
    f.finish("golden .ot round trips");
}

/// A counting tree through `.olm` in both layouts: the same `.ot` bytes
/// back, the same counts from `count` at every depth, the same nodes.
fn check_counting_round_trip(f: &mut Failures, what: &str, tree: &CountingTree, ot_file: &[u8]) {
    let mut plain = Vec::new();
    ot::write_counting(tree, &mut plain).unwrap();
    for (label, opts) in [("full/rank", WriteOptions::default()), ("full/pointers", WriteOptions::pointers())] {
        let map = MappedMap::new(mapped::counting_to_bytes(tree, opts).unwrap()).unwrap();
        let view = map.view();
        assert_eq!(view.kind(), format::TreeKind::CountingOcTree);
        let back = view.to_counting_tree().unwrap();
        let mut again = Vec::new();
        ot::write_counting(&back, &mut again).unwrap();
        f.check(again == plain && plain == ot_file, || format!("{what} {label}: .ot bytes differ after .olm"));
        let nodes = |it: &mut dyn Iterator<Item = (Key, u8, bool, u32)>| it.collect::<Vec<_>>();
        let want = nodes(&mut tree.nodes(0).map(|n| (n.key, n.depth, n.is_leaf, n.extra)));
        let got = nodes(&mut view.nodes(0).map(|n| (n.key, n.depth, n.is_leaf, n.extra)));
        f.check(want == got, || format!("{what} {label}: nodes differ"));
        f.check(view.nodes(0).all(|n| n.value == 0.0), || format!("{what} {label}: counting values are not 0"));
        for n in tree.nodes(0) {
            for depth in [0, n.depth, n.depth.saturating_sub(2)] {
                let want = tree.count(n.key, depth);
                f.check(view.count(n.key, depth) == want, || {
                    format!("{what} {label}: count at {} depth {depth}", n.key)
                });
            }
        }
        f.check(view.count(Key::new(1, 2, 3), 0) == tree.count(Key::new(1, 2, 3), 0), || format!("{what}: far key"));
        f.check(matches!(view.to_tree(), Err(OlmError::Kind { .. })), || format!("{what}: to_tree accepted counts"));
        f.check(view.color(Key::ROOT, 0).is_none() && view.stamp(Key::ROOT, 0).is_none(), || what.to_string());
        // counts are no log-odds: rays are refused, not cast through values of 0
        let (o, d) = (Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.2, 0.1));
        let rays = [
            view.cast_ray(o, d, CastOptions::default()),
            mapped::cast_ray(&view, o, d, CastOptions::default()),
            mapped::cast_ray(&map, o, d, CastOptions::default()),
        ];
        f.check(rays.iter().all(|r| matches!(r, Err(CastError::NoOccupancy))), || format!("{what}: rays {rays:?}"));
    }
    let ml = mapped::counting_to_bytes(tree, WriteOptions::max_likelihood());
    f.check(ml.is_err(), || format!("{what}: a counting tree written as maximum likelihood"));
}

#[test]
fn counting_trees_through_olm() {
    // a counting tree with repeated hits, and an empty one
    let mut tree = CountingTree::new(0.1).unwrap();
    let mut rng = SplitMix64(5);
    for i in 0..3000 {
        let c = |r: &mut SplitMix64| (r.below(400) as f32 - 200.0) / 100.0;
        let p = Point3::new(c(&mut rng), c(&mut rng), c(&mut rng) / 4.0);
        tree.update_point(p).unwrap();
        if i % 3 == 0 {
            tree.update_point(p).unwrap();
        }
    }
    let mut f = Failures::default();
    let mut ot_file = Vec::new();
    ot::write_counting(&tree, &mut ot_file).unwrap();
    assert!(tree.nodes(0).map(|n| n.extra).max() > Some(2));
    check_counting_round_trip(&mut f, "random counts", &tree, &ot_file);
    let empty = CountingTree::new(0.2).unwrap();
    let mut ot_file = Vec::new();
    ot::write_counting(&empty, &mut ot_file).unwrap();
    check_counting_round_trip(&mut f, "empty", &empty, &ot_file);
    // occupancy maps have no counts, counting maps no occupancy tree
    let plain = MappedMap::new(sample_bytes(WriteOptions::default())).unwrap();
    assert_eq!(plain.view().count(Key::ROOT, 0), None);
    assert!(matches!(plain.view().to_counting_tree(), Err(OlmError::Kind { .. })));
    f.finish("counting trees through .olm");
}

/// `.bt → .olm (ML) → .bt` restores the input bytes: the example map and
/// every stored `.bt` of the golden set.
#[test]
fn golden_bt_files_round_trip() {
    let g = golden();
    let mut f = Failures::default();
    let mut inputs = vec![("inputs/geb079.bt".to_string(), std::fs::read(g.input("inputs/geb079.bt")).unwrap())];
    for case in g.manifest["cases"].as_array().unwrap() {
        for file in case["files"].as_array().unwrap() {
            if file["kind"] == "bt" && file["stored"] != "digest-only" {
                let name = file["name"].as_str().unwrap();
                if let Some(b) = g.load(case, name) {
                    inputs.push((format!("{}/{name}", case["id"].as_str().unwrap()), b));
                }
            }
        }
    }
    let mut checked = 0;
    for (name, bytes) in &inputs {
        let Ok(tree) = bt::read(&bytes[..]) else {
            continue;
        };
        let mut plain = Vec::new();
        bt::write_const(&tree, &mut plain).unwrap();
        if plain != *bytes {
            continue; // ColorOcTree .bt files: the OcTree writer names another type
        }
        let olm = mapped::to_bytes(&tree, WriteOptions::max_likelihood()).unwrap();
        let map = MappedMap::new(&olm[..]).unwrap();
        map.verify().unwrap();
        let back = map.to_tree().unwrap();
        // the tree readBinary gives (root clamping_max, inner = max of children)
        f.check(ot_bytes(&back) == ot_bytes(&tree), || format!("{name}: tree differs after .olm"));
        let mut out = Vec::new();
        bt::write_const(&back, &mut out).unwrap();
        f.check(out == *bytes, || format!("{name}: .bt bytes differ after .olm"));
        checked += 1;
        if name.ends_with("geb079.bt") {
            let full = mapped::to_bytes(&tree, WriteOptions::default()).unwrap();
            eprintln!(
                "geb079: .bt {} bytes, .olm ML {} ({:.3}x), .ot {} bytes, .olm full {} ({:.3}x)",
                bytes.len(),
                olm.len(),
                olm.len() as f64 / bytes.len() as f64,
                ot_bytes(&tree).len(),
                full.len(),
                full.len() as f64 / ot_bytes(&tree).len() as f64
            );
            same_answers("geb079 ML", &tree, &map, 3);
            let fm = MappedMap::new(full).unwrap();
            same_answers("geb079 full", &tree, &fm, 4);
        }
    }
    assert!(checked > 10);
    f.finish("golden .bt round trips");
}

fn opt_f32(v: Option<f32>) -> String {
    v.map(f32hex).unwrap_or_default()
}

/// `query_points.csv` and `query_castray.csv` of every build case whose
/// `tree.ot` is stored, answered from a memory-mapped `.olm`.
#[test]
fn golden_queries_from_mapped_files() {
    let g = golden();
    let dir = tempfile::tempdir().unwrap();
    let mut f = Failures::default();
    let mut answered = 0;
    let (mut t_points, mut t_rays) = (0.0, 0.0);
    for case in g.cases("build") {
        let Some(tree_ot) = g.load(case, "tree.ot") else {
            continue;
        };
        let points = g.load_text(case, "query_points.csv");
        let rays = g.load_text(case, "query_castray.csv");
        if points.is_none() && rays.is_none() {
            continue;
        }
        let tree = ot::read(&tree_ot[..]).unwrap().into_occupancy().unwrap();
        let path = dir.path().join("case.olm");
        for opts in [WriteOptions::default(), WriteOptions::pointers()] {
            mapped::write_file_with(&tree, &path, opts).unwrap();
            let map = mapped::open(&path).unwrap();
            let view = map.view();
            let t0 = std::time::Instant::now();
            if let Some(expected) = &points {
                let mut s = String::from("i,x,y,z,key_ok,kx,ky,kz,found,logodds,occupied,found_d14,logodds_d14\n");
                for line in expected.lines().skip(1) {
                    let c: Vec<&str> = line.split(',').collect();
                    let p = point_from_hex(&c[1..4]);
                    let key = view.key(p);
                    let [kx, ky, kz] = key.map(|k| k.0).unwrap_or([0; 3]);
                    let found = key.ok().and_then(|k| view.search(k, 0));
                    let found14 = key.ok().and_then(|k| view.search(k, 14));
                    writeln!(
                        s,
                        "{},{},{},{},{},{kx},{ky},{kz},{},{},{},{},{}",
                        c[0],
                        c[1],
                        c[2],
                        c[3],
                        u8::from(key.is_ok()),
                        u8::from(found.is_some()),
                        opt_f32(found.map(|f| f.value)),
                        u8::from(found.is_some_and(|f| view.is_occupied(f.value))),
                        u8::from(found14.is_some()),
                        opt_f32(found14.map(|f| f.value)),
                    )
                    .unwrap();
                }
                f.check_digest(&g, case, "query_points.csv", s.as_bytes());
            }
            t_points += t0.elapsed().as_secs_f64();
            let t0 = std::time::Instant::now();
            // rays are costly (up to 65536 searches each): default layout only
            let rays = rays.as_ref().filter(|_| opts == WriteOptions::default());
            if let Some(expected) = rays {
                let mut s = String::from("i,ox,oy,oz,dx,dy,dz,ignore_unknown,max_range,ret,ex,ey,ez\n");
                for line in expected.lines().skip(1) {
                    let c: Vec<&str> = line.split(',').collect();
                    let opts = CastOptions { ignore_unknown: c[7] == "1", max_range: Some(parse_f64hex(c[8])) };
                    let (ret, end) = match view.cast_ray(point_from_hex(&c[1..4]), point_from_hex(&c[4..7]), opts) {
                        Ok(o) => (o.hit(), o.end()),
                        Err(_) => (false, Point3::new(f32::NAN, f32::NAN, f32::NAN)),
                    };
                    writeln!(
                        s,
                        "{},{},{},{},{},{},{},{},{},{},{},{},{}",
                        c[0],
                        c[1],
                        c[2],
                        c[3],
                        c[4],
                        c[5],
                        c[6],
                        c[7],
                        c[8],
                        u8::from(ret),
                        f32hex(end.x),
                        f32hex(end.y),
                        f32hex(end.z)
                    )
                    .unwrap();
                }
                f.check_digest(&g, case, "query_castray.csv", s.as_bytes());
            }
            t_rays += t0.elapsed().as_secs_f64();
        }
        answered += 1;
    }
    eprintln!("{answered} golden cases answered from mapped files; points {t_points:.1} s, rays {t_rays:.1} s");
    assert!(answered > 20);
    f.finish("golden queries from mapped files");
}

// ----- header checks ---------------------------------------------------------------

fn sample_bytes(opts: WriteOptions) -> Vec<u8> {
    sample_bytes_of(opts, NodeKind::Plain)
}

fn sample_bytes_of(opts: WriteOptions, kind: NodeKind) -> Vec<u8> {
    let tree = simulated_kind(
        SceneKind::Indoor,
        1,
        3,
        0.2,
        &LidarConfig { beams: 4, horizontal_steps: 60, ..LidarConfig::indoor() },
        kind,
    );
    mapped::to_bytes(&tree, opts).unwrap()
}

/// A small counting tree with varied counts, as `.olm`.
fn counting_sample_bytes(opts: WriteOptions) -> Vec<u8> {
    let mut t = CountingTree::new(0.1).unwrap();
    for i in 0..60u32 {
        let f = i as f32;
        let p = Point3::new((f * 0.37) % 1.5 - 0.7, (f * 0.73) % 1.1 - 0.5, (f * 0.11) % 0.6);
        for _ in 0..=(i % 3) {
            t.update_point(p).unwrap();
        }
    }
    mapped::counting_to_bytes(&t, opts).unwrap()
}

fn fix_header_crc(b: &mut [u8]) {
    if b.len() >= format::HEADER_LEN {
        let crc = crc32fast::hash(&b[..252]);
        b[252..256].copy_from_slice(&crc.to_le_bytes());
    }
}

/// Recomputes every section checksum the table names, then the header's.
fn fix_all_crcs(b: &mut [u8]) {
    if b.len() < format::HEADER_LEN {
        return;
    }
    let count = u16::from_le_bytes([b[54], b[55]]).min(6) as usize;
    for i in 0..count {
        let e = 96 + 24 * i;
        let off = u64::from_le_bytes(b[e + 8..e + 16].try_into().unwrap());
        let len = u64::from_le_bytes(b[e + 16..e + 24].try_into().unwrap());
        let Some(end) = off.checked_add(len) else {
            continue;
        };
        if end as usize <= b.len() {
            let crc = crc32fast::hash(&b[off as usize..end as usize]);
            b[e + 4..e + 8].copy_from_slice(&crc.to_le_bytes());
        }
    }
    fix_header_crc(b);
}

#[test]
fn header_checks_name_the_problem() {
    let good = sample_bytes(WriteOptions::default());
    assert!(MappedMap::new(&good[..]).is_ok());
    let err = |b: &[u8]| MappedMap::new(b).unwrap_err();
    assert!(matches!(err(&good[..100]), OlmError::TooShort { .. }));
    assert!(matches!(err(b"OCTO"), OlmError::TooShort { .. }));
    assert!(matches!(err(b"# Octomap OcTree file\n"), OlmError::BadMagic));
    let mut b = good.clone();
    b[8] = 2;
    assert!(matches!(err(&b), OlmError::Version { major: 2, .. }));
    let mut b = good.clone();
    b[12..16].copy_from_slice(&0x0A0B_0C0Du32.to_be_bytes());
    assert!(matches!(err(&b), OlmError::Endianness { .. }));
    let mut b = good.clone();
    b[30] ^= 1;
    assert!(matches!(err(&b), OlmError::HeaderChecksum { .. }));
    // a colour or stamped kind without its section, an unknown kind
    for kind in [1u8, 2] {
        let mut b = good.clone();
        b[20] = kind;
        fix_header_crc(&mut b);
        assert!(matches!(err(&b), OlmError::Section { kind: 7 | 8, .. }), "{:?}", err(&b));
    }
    // an occupancy map relabelled as counts: its sensor fields give it away
    let mut b = good.clone();
    b[20] = 3;
    fix_header_crc(&mut b);
    assert!(matches!(err(&b), OlmError::BadField { field: "sensor", .. }), "{:?}", err(&b));
    let mut b = good.clone();
    b[20] = 4;
    fix_header_crc(&mut b);
    assert!(matches!(err(&b), OlmError::BadField { field: "tree_kind", .. }));
    // counts have no maximum-likelihood variant
    let mut b = counting_sample_bytes(WriteOptions::default());
    assert!(MappedMap::new(&b[..]).is_ok());
    b[21] = 1;
    fix_header_crc(&mut b);
    assert!(matches!(err(&b), OlmError::BadField { field: "variant", .. }), "{:?}", err(&b));
    let mut b = good.clone();
    b.push(0);
    assert!(matches!(err(&b), OlmError::FileLength { .. }));
    let mut b = good.clone();
    b.pop();
    assert!(matches!(err(&b), OlmError::FileLength { .. }));
    // a node count the sections cannot hold
    let mut b = good.clone();
    let n = u64::from_le_bytes(b[64..72].try_into().unwrap()) + 1;
    b[64..72].copy_from_slice(&n.to_le_bytes());
    fix_header_crc(&mut b);
    assert!(matches!(err(&b), OlmError::Section { .. } | OlmError::BadField { .. }));
    // a section checksum is only checked by verify
    let mut b = good.clone();
    let last = b.len() - 1;
    b[last] ^= 0x40;
    let m = MappedMap::new(&b[..]).unwrap();
    assert!(matches!(m.verify(), Err(OlmError::SectionChecksum { .. })));
    // resolution
    let mut b = good.clone();
    b[24..32].copy_from_slice(&f64::NAN.to_le_bytes());
    fix_header_crc(&mut b);
    assert!(matches!(err(&b), OlmError::BadField { field: "resolution", .. }));
    // the example in formats/olm.md
    let mut t = OccupancyTree::new(0.1).unwrap();
    t.update_point(Point3::new(0.05, 0.05, 0.05), true, Default::default()).unwrap();
    let ex = mapped::to_bytes(&t, WriteOptions::default()).unwrap();
    let m = MappedMap::new(&ex[..]).unwrap();
    m.verify().unwrap();
    assert_eq!(ex.len(), 452);
    assert_eq!(m.header().node_count, 17);
    let listed = spec_example();
    if listed != ex {
        let hex: Vec<String> = ex
            .chunks(16)
            .enumerate()
            .map(|(i, c)| {
                format!("{:03x}: {}", 16 * i, c.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" "))
            })
            .collect();
        panic!("formats/olm.md example differs from the writer's bytes:\n{}", hex.join("\n"));
    }
}

/// The bytes listed in the example of `formats/olm.md` (`OFFSET: hex ... | note`,
/// `00*N` for a run of zeros).
fn spec_example() -> Vec<u8> {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/formats/olm.md")).unwrap();
    let start = doc.find("<!-- olm-example-begin -->").unwrap();
    let end = doc.find("<!-- olm-example-end -->").unwrap();
    let mut out = Vec::new();
    for line in doc[start..end].lines() {
        let Some((off, rest)) = line.split_once(": ") else {
            continue;
        };
        let Ok(off) = usize::from_str_radix(off, 16) else {
            continue;
        };
        assert_eq!(off, out.len(), "formats/olm.md example: offset {off:#x} out of sequence");
        let bytes = rest.split('|').next().unwrap();
        for tok in bytes.split_whitespace() {
            if let Some(n) = tok.strip_prefix("00*") {
                out.resize(out.len() + n.parse::<usize>().unwrap(), 0);
            } else {
                out.push(u8::from_str_radix(tok, 16).unwrap());
            }
        }
    }
    out
}

// ----- corruption suite ----------------------------------------------------------------

/// The fuzz target's check: open, verify, query; never panics, and a
/// verified file answers as the tree it converts to.
#[path = "../fuzz/fuzz_targets/olm.rs"]
#[allow(dead_code)]
mod olm_fuzz;

fn exercise(bytes: &[u8]) -> (bool, bool) {
    olm_fuzz::check(bytes)
}

/// Files kept under `tests/regressions/olm/` (found by fuzzing) pass the
/// fuzz target's check.
#[test]
fn fuzz_regressions_replay() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/regressions/olm");
    let mut paths: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    paths.sort();
    assert!(!paths.is_empty());
    for p in paths {
        let bytes = std::fs::read(&p).unwrap();
        let result = std::panic::catch_unwind(|| exercise(&bytes));
        assert!(result.is_ok(), "{} fails the fuzz check", p.display());
    }
}

fn mutate(base: &[u8], kind: u64, rng: &mut SplitMix64) -> Vec<u8> {
    let mut b = base.to_vec();
    let len = b.len() as u32;
    let pos = |rng: &mut SplitMix64, b: &[u8]| rng.below(b.len().max(1) as u32) as usize;
    match kind {
        // truncation
        0 => b.truncate(rng.below(len) as usize),
        // bit flips anywhere
        1 => {
            for _ in 0..1 + rng.below(8) {
                let p = pos(rng, &b);
                b[p] ^= 1 << rng.below(8);
            }
        }
        // bit flips with every checksum fixed: reaches the structure checks
        2 => {
            for _ in 0..1 + rng.below(4) {
                let p = format::HEADER_LEN + rng.below(len - format::HEADER_LEN as u32) as usize;
                b[p] ^= 1 << rng.below(8);
            }
            fix_all_crcs(&mut b);
        }
        // splice: a run of the file copied over another place
        3 => {
            let n = 1 + rng.below(64) as usize;
            let from = pos(rng, &b);
            let to = pos(rng, &b);
            let chunk: Vec<u8> = b[from..(from + n).min(b.len())].to_vec();
            for (i, v) in chunk.into_iter().enumerate() {
                if to + i < b.len() {
                    b[to + i] = v;
                }
            }
            if rng.below(2) == 0 {
                fix_all_crcs(&mut b);
            }
        }
        // lying header fields (counts, sizes, labels, variant...)
        4 => {
            let fields: [(usize, usize); 12] = [
                (20, 1),
                (21, 1),
                (22, 1),
                (23, 1),
                (52, 1),
                (54, 2),
                (56, 8),
                (64, 8),
                (72, 8),
                (80, 8),
                (24, 8),
                (40, 4),
            ];
            let (off, n) = fields[rng.below(fields.len() as u32) as usize];
            let v = match rng.below(4) {
                0 => rng.next_u64(),
                1 => u64::MAX,
                2 => rng.next_u64() % 16,
                _ => {
                    let mut cur = [0u8; 8];
                    cur[..n].copy_from_slice(&b[off..off + n]);
                    u64::from_le_bytes(cur).wrapping_add(rng.below(5) as u64).wrapping_sub(2)
                }
            };
            b[off..off + n].copy_from_slice(&v.to_le_bytes()[..n]);
            fix_header_crc(&mut b);
        }
        // lying section table entries
        5 => {
            let e = 96 + 24 * rng.below(6) as usize;
            let off = e + [0, 8, 16][rng.below(3) as usize];
            let width = if off == e { 2 } else { 8 };
            let v = match rng.below(4) {
                0 => rng.next_u64(),
                1 => u64::from(rng.below(len + 128)) & !63,
                2 => u64::MAX - rng.below(100) as u64,
                _ => u64::from(rng.below(8)),
            };
            b[off..off + width].copy_from_slice(&v.to_le_bytes()[..width]);
            if rng.below(2) == 0 {
                fix_all_crcs(&mut b);
            } else {
                fix_header_crc(&mut b);
            }
        }
        // random bytes over a section, checksums fixed
        6 => {
            let start = format::HEADER_LEN + rng.below(len - format::HEADER_LEN as u32) as usize;
            let n = (1 + rng.below(32) as usize).min(b.len() - start);
            for v in &mut b[start..start + n] {
                *v = rng.next_u64() as u8;
            }
            fix_all_crcs(&mut b);
        }
        // garbage appended, file length fixed
        _ => {
            for _ in 0..1 + rng.below(100) {
                b.push(rng.next_u64() as u8);
            }
            let l = b.len() as u64;
            b[80..88].copy_from_slice(&l.to_le_bytes());
            fix_header_crc(&mut b);
        }
    }
    b
}

#[test]
fn corrupted_files_never_panic() {
    let mut total = 0;
    let mut opened = 0;
    let mut verified = 0;
    // every layout of a plain map; colour and stamped maps in both full layouts
    let mut bases: Vec<(String, Vec<u8>)> =
        all_options().into_iter().map(|(label, opts)| (label.to_string(), sample_bytes(opts))).collect();
    for kind in [NodeKind::Color, NodeKind::Stamped] {
        for (label, opts) in [("full/rank", WriteOptions::default()), ("full/pointers", WriteOptions::pointers())] {
            bases.push((format!("{kind:?} {label}"), sample_bytes_of(opts, kind)));
        }
    }
    for (label, opts) in [("full/rank", WriteOptions::default()), ("full/pointers", WriteOptions::pointers())] {
        bases.push((format!("counting {label}"), counting_sample_bytes(opts)));
    }
    for (label, base) in &bases {
        let mut rng = SplitMix64(0x0c70_11ea_u64 ^ base.len() as u64);
        assert_eq!(exercise(base), (true, true), "{label}");
        for i in 0..1200u64 {
            let m = mutate(base, i % 8, &mut rng);
            let (o, v) = exercise(&m);
            total += 1;
            opened += usize::from(o);
            verified += usize::from(v);
        }
    }
    // pure noise
    let mut rng = SplitMix64(99);
    for _ in 0..300 {
        let n = rng.below(2048) as usize;
        let mut b: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
        if rng.below(2) == 0 && b.len() >= 8 {
            b[..8].copy_from_slice(&format::MAGIC);
        }
        exercise(&b);
        total += 1;
    }
    eprintln!("{total} mutants: {opened} opened, {verified} verified");
    assert!(total >= 10_000);
    assert!(opened > total / 4, "the mutants should reach past the header");
}

/// Writes small seed files for `cargo fuzz run olm` to `fuzz/corpus/olm`
/// (`cargo test --test mapped write_fuzz_seeds -- --ignored`).
#[test]
#[ignore]
fn write_fuzz_seeds() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/olm");
    std::fs::create_dir_all(&dir).unwrap();
    let mut trees = vec![("empty", OccupancyTree::new(0.1).unwrap())];
    let mut t = OccupancyTree::new(0.1).unwrap();
    t.update_point(Point3::new(0.05, 0.05, 0.05), true, Default::default()).unwrap();
    trees.push(("voxel", t.clone()));
    for (i, p) in [(0.3, -0.2, 0.1), (-0.4, 0.25, 0.05), (0.15, 0.15, -0.3)].into_iter().enumerate() {
        t.update_point(Point3::new(p.0, p.1, p.2), i % 2 == 0, Default::default()).unwrap();
    }
    trees.push(("voxels", t));
    let mut block = OccupancyTree::new(0.1).unwrap();
    for i in 0..8 {
        let p =
            Point3::new(0.05 + 0.1 * (i & 1) as f32, 0.05 + 0.1 * ((i >> 1) & 1) as f32, 0.05 + 0.1 * (i >> 2) as f32);
        block.update_point(p, true, Default::default()).unwrap();
    }
    trees.push(("block", block.clone()));
    // a colour block with a few colours, and a stamped one
    let mut color = block.converted(NodeKind::Color);
    color.expand().unwrap();
    for (i, leaf) in block.leaves(0).map(|l| l.key).collect::<Vec<_>>().into_iter().enumerate().take(5) {
        color.set_color(leaf, [40 * i as u8, 255 - 30 * i as u8, 7]);
    }
    color.update_inner_occupancy();
    trees.push(("color", color));
    let mut stamped = OccupancyTree::with_kind(0.1, SensorModel::default(), NodeKind::Stamped).unwrap();
    for (i, p) in [(0.05, 0.05, 0.05), (0.3, -0.2, 0.1), (-0.4, 0.25, 0.05)].into_iter().enumerate() {
        stamped.set_clock(octolinear::Clock::Fixed(1000 + i as u32));
        stamped.update_point(Point3::new(p.0, p.1, p.2), true, Default::default()).unwrap();
    }
    trees.push(("stamped", stamped));
    for (name, tree) in &trees {
        for (label, opts) in all_options() {
            let b = mapped::to_bytes(tree, opts).unwrap();
            let file = format!("{name}-{}.olm", label.replace(['/', ' '], "-"));
            std::fs::write(dir.join(file), b).unwrap();
        }
    }
}

/// Damage to a counting map's sections: its counts (values section) cut,
/// of the wrong length or missing are refused on opening; a changed count
/// is caught by `verify` (checksum), and queries on it never panic.
#[test]
fn counting_section_damage_is_caught() {
    let good = counting_sample_bytes(WriteOptions::default());
    let err = |b: &[u8]| MappedMap::new(b).unwrap_err();
    let header = MappedMap::new(&good[..]).unwrap().header().clone();
    let at = header.sections.iter().position(|s| s.kind == format::SectionKind::Values as u16).unwrap();
    let (entry, counts) = (96 + 24 * at, header.sections[at]);
    // truncated: the file length no longer matches; with the header fixed, the section ends past the file
    assert!(matches!(err(&good[..good.len() - 4]), OlmError::FileLength { .. }));
    let mut b = good[..good.len() - 4].to_vec();
    let len = b.len() as u64;
    b[80..88].copy_from_slice(&len.to_le_bytes());
    fix_header_crc(&mut b);
    assert!(matches!(err(&b), OlmError::Section { kind: 2, .. }), "{:?}", err(&b));
    // wrong length
    let mut b = good.clone();
    b[entry + 16..entry + 24].copy_from_slice(&(counts.length - 4).to_le_bytes());
    fix_header_crc(&mut b);
    assert!(matches!(err(&b), OlmError::Section { kind: 2, ref reason } if reason.contains("bytes")), "{:?}", err(&b));
    // missing: the entry renamed to an optional unknown kind
    let mut b = good.clone();
    b[entry..entry + 4].copy_from_slice(&[0x40, 0, 1, 0]);
    fix_header_crc(&mut b);
    assert!(
        matches!(err(&b), OlmError::Section { kind: 2, ref reason } if reason.contains("missing")),
        "{:?}",
        err(&b)
    );
    // a changed count: only verify sees it; queries still answer without panicking
    let mut b = good.clone();
    b[counts.offset as usize] ^= 0x10;
    let m = MappedMap::new(&b[..]).unwrap();
    assert!(matches!(m.verify(), Err(OlmError::SectionChecksum { kind: 2, .. })));
    assert!(m.view().to_counting_tree().is_err());
    let root_count = |m: &MappedMap<&[u8]>| m.view().nodes(0).next().map(|n| n.extra);
    let before = root_count(&MappedMap::new(&good[..]).unwrap());
    assert_eq!(root_count(&m), before.map(|c| c ^ 0x10));
}

/// The search-blocks section: written only on request (and for a small map
/// only when asked for always), and a damaged run is caught by
/// `verify` while searches still answer without panicking.
#[test]
fn search_blocks_section_is_optional_and_checked() {
    let always = WriteOptions { search_blocks: SearchBlocksSection::Always, ..Default::default() };
    let never = WriteOptions { search_blocks: SearchBlocksSection::Never, ..Default::default() };
    let (good, plain) = (sample_bytes(always), sample_bytes(never));
    assert_eq!(sample_bytes(WriteOptions::default()), plain, "none by default");
    let auto = WriteOptions { search_blocks: SearchBlocksSection::Auto, ..Default::default() };
    assert_eq!(sample_bytes(auto), plain, "a small map gets none when the writer decides");
    let kind = format::SectionKind::SearchBlocks as u16;
    let header = MappedMap::new(&good[..]).unwrap().header().clone();
    let at = header.sections.iter().position(|s| s.kind == kind).expect("written");
    let section = header.sections[at];
    assert_eq!(section.flags, format::SECTION_OPTIONAL);
    assert_eq!(
        &good[format::HEADER_LEN..plain.len()],
        &plain[format::HEADER_LEN..],
        "the other sections are as without"
    );
    // no palette for a colour map: no section even when asked
    let color = sample_bytes_of(always, NodeKind::Color);
    assert!(!MappedMap::new(&color[..]).unwrap().header().sections.iter().any(|s| s.kind == kind));
    // a changed palette code, checksums fixed: verify names the section
    let runs_end = (section.offset + section.length) as usize - 16;
    let mut b = good.clone();
    b[runs_end] ^= 1;
    fix_all_crcs(&mut b);
    let m = MappedMap::new(&b[..]).unwrap();
    assert!(matches!(m.verify(), Err(OlmError::Section { kind: 9, .. })), "{:?}", m.verify());
    // fields that do not add up are refused at open
    let mut b = good.clone();
    b[section.offset as usize + 8..section.offset as usize + 12].copy_from_slice(&300u32.to_le_bytes());
    fix_all_crcs(&mut b);
    assert!(matches!(MappedMap::new(&b[..]), Err(OlmError::Section { kind: 9, .. })));
    // the section in a maximum-likelihood file does not belong there
    let ml =
        sample_bytes(WriteOptions { search_blocks: SearchBlocksSection::Always, ..WriteOptions::max_likelihood() });
    assert!(!MappedMap::new(&ml[..]).unwrap().header().sections.iter().any(|s| s.kind == kind));
}
