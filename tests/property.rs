//! Property tests: random operation sequences on the arena tree agree with
//! a plain per-voxel `HashMap<Key, f32>` model, and the batch update path
//! gives the same tree as key-by-key updates.

use hashbrown::HashMap;
use octolinear::formats::{bt, ot, ros};
use octolinear::morton::MortonCode;
use octolinear::scan::ScanUpdate;
use octolinear::tree::NodeKind;
use octolinear::{Clock, InnerNodes, Key, OccupancyTree, ScanReport, SensorModel};
use proptest::prelude::*;
use std::io::BufReader;

/// Keys in a small cube so that pruning and expansion happen often.
const BASE: u16 = 32764;
const SPAN: u16 = 4;

#[derive(Clone, Debug)]
enum Op {
    Hit(Key),
    Miss(Key),
    Delta(Key, f32),
    Set(Key, f32),
    Delete(Key, u8),
    Prune,
    Expand,
    Compact,
    MaxLikelihood,
}

fn key() -> impl Strategy<Value = Key> {
    (0..SPAN, 0..SPAN, 0..SPAN).prop_map(|(x, y, z)| Key::new(BASE + x, BASE + y, BASE + z))
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => key().prop_map(Op::Hit),
        6 => key().prop_map(Op::Miss),
        4 => (key(), -0.4f32..0.4).prop_map(|(k, d)| Op::Delta(k, d)),
        1 => (key(), -3.0f32..3.0).prop_map(|(k, d)| Op::Delta(k, d)),
        2 => (key(), -5.0f32..5.0).prop_map(|(k, v)| Op::Set(k, v)),
        2 => (key(), prop_oneof![Just(16u8), 13u8..16]).prop_map(|(k, d)| Op::Delete(k, d)),
        1 => Just(Op::Prune),
        1 => Just(Op::Compact),
        1 => Just(Op::Expand),
        1 => Just(Op::MaxLikelihood),
    ]
}

/// Does the depth-`depth` node containing `node_key` contain `k`?
fn contains(node_key: Key, depth: u8, k: Key) -> bool {
    let shift = 16 - u32::from(depth);
    (0..3).all(|i| (u32::from(node_key.0[i]) >> shift) == (u32::from(k.0[i]) >> shift))
}

/// The voxels the tree describes: every leaf expanded to depth-16 voxels.
fn voxels(tree: &OccupancyTree) -> Vec<(Key, f32)> {
    let mut out: Vec<(Key, f32)> = Vec::new();
    for leaf in tree.leaves(0) {
        let size = 1u32 << (16 - leaf.depth);
        let lo = leaf.key.0.map(|k| (u32::from(k) >> (16 - leaf.depth)) << (16 - leaf.depth));
        if size > u32::from(SPAN) * 2 && leaf.depth < 16 {
            // a coarse leaf outside our cube can only be the bare root
            continue;
        }
        let start = out.len();
        for x in 0..size {
            for y in 0..size {
                for z in 0..size {
                    let k = Key::new((lo[0] + x) as u16, (lo[1] + y) as u16, (lo[2] + z) as u16);
                    out.push((k, leaf.value));
                }
            }
        }
        out[start..].sort_unstable_by_key(|(k, _)| MortonCode::encode(*k));
    }
    out
}

fn check_inner_nodes_hold_max(tree: &OccupancyTree) -> Result<(), TestCaseError> {
    let Some(root) = tree.root() else { return Ok(()) };
    let mut stack = vec![root];
    while let Some(n) = stack.pop() {
        if n.has_children() {
            let max = n.children().map(|(_, c)| c.value()).fold(-f32::MAX, f32::max);
            prop_assert_eq!(n.value().to_bits(), max.to_bits(), "inner node is not the max of its children");
            stack.extend(n.children().map(|(_, c)| c));
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1024, ..ProptestConfig::default() })]

    #[test]
    fn tree_agrees_with_a_voxel_map(ops in prop::collection::vec(op(), 1..250)) {
        let sensor = SensorModel::default();
        let mut tree = OccupancyTree::new(0.1).unwrap();
        let mut model: HashMap<Key, f32> = HashMap::new();
        for op in &ops {
            match *op {
                Op::Hit(k) | Op::Miss(k) | Op::Delta(k, _) => {
                    let delta = match *op {
                        Op::Hit(_) => sensor.hit,
                        Op::Miss(_) => sensor.miss,
                        Op::Delta(_, d) => d,
                        _ => unreachable!(),
                    };
                    tree.update(k, delta, InnerNodes::Update);
                    let v = model.get(&k).copied().unwrap_or(0.0);
                    model.insert(k, if model.contains_key(&k) && sensor.is_saturated(v, delta) { v } else { sensor.apply(v, delta) });
                }
                Op::Set(k, v) => {
                    tree.set_value(k, v, InnerNodes::Update);
                    model.insert(k, sensor.clamp(v));
                }
                Op::Delete(k, depth) => {
                    tree.delete(k, depth);
                    model.retain(|&m, _| !contains(k, depth, m));
                    if model.is_empty() {
                        // OctoMap keeps a bare root with a stale value that the
                        // next update spreads to coarse siblings (covered by the
                        // golden delete cases); start afresh like a user would
                        tree.clear();
                    }
                }
                Op::Prune => tree.prune(),
                Op::Compact => tree.compact(),
                // a bare root would expand to 8^16 voxels, in OctoMap too
                Op::Expand if tree.root().is_some_and(|r| r.has_children()) => {
                    tree.expand().unwrap();
                }
                Op::Expand => {}
                Op::MaxLikelihood => {
                    tree.to_max_likelihood();
                    model.values_mut().for_each(|v| *v = sensor.max_likelihood(*v));
                }
            }
            prop_assert!(tree.size() < 100_000, "tree grew to {} nodes after {:?}", tree.size(), op);
        }
        let got = voxels(&tree);
        // leaves come in Morton order
        let codes: Vec<u64> = got.iter().map(|(k, _)| MortonCode::encode(*k).0).collect();
        prop_assert!(codes.windows(2).all(|w| w[0] < w[1]), "leaves out of depth-first order");
        let got: HashMap<Key, f32> = got.into_iter().collect();
        if !model.is_empty() {
            prop_assert_eq!(got.len(), model.len());
            for (k, v) in &model {
                prop_assert_eq!(got.get(k).map(|x| x.to_bits()), Some(v.to_bits()), "voxel {}", k);
                let found = tree.search(*k, 0).map(|f| f.value.to_bits());
                prop_assert_eq!(found, Some(v.to_bits()));
            }
        }
        if ops.iter().any(|o| matches!(o, Op::Delete(..))) {
            // OctoMap's deleteNode only refreshes the deepest surviving
            // parent; its ancestors keep stale maxima (the golden delete
            // cases check that), so refresh before checking the invariant
            tree.update_inner_occupancy();
        }
        check_inner_nodes_hold_max(&tree)?;
        prop_assert_eq!(tree.calc_num_nodes(), tree.nodes(0).count());
        // batched searches answer exactly as one search after another, at
        // every depth, for stored voxels and for the neighbours of each
        let mut probes: Vec<Key> = model.keys().copied().collect();
        probes.extend(model.keys().map(|k| Key::new(k.0[0] ^ 1, k.0[1], k.0[2] ^ 2)));
        let mut batch = Vec::new();
        for depth in [0, 16, 15, 13, 9, 1] {
            tree.search_many(&probes, depth, &mut batch);
            let one_by_one: Vec<_> = probes.iter().map(|k| tree.search(*k, depth)).collect();
            prop_assert_eq!(&batch, &one_by_one, "search_many at depth {}", depth);
        }
    }

    #[test]
    fn batch_updates_equal_key_by_key_updates(
        keys in prop::collection::btree_set(key(), 1..200),
        setup in prop::collection::vec((key(), prop::bool::weighted(0.9), any::<bool>()), 0..800),
        hit in any::<bool>(),
        lazy in any::<bool>(),
    ) {
        let inner = if lazy { InnerNodes::Defer } else { InnerNodes::Update };
        let mut a = OccupancyTree::new(0.05).unwrap();
        // lazy setup updates leave stale inner nodes, which only a real
        // update below may refresh
        for &(k, occ, lazy_setup) in &setup {
            a.update_occupancy(k, occ, if lazy_setup { InnerNodes::Defer } else { InnerNodes::Update });
        }
        a.prune();
        let mut b = a.clone();
        let delta = if hit { a.sensor().hit } else { a.sensor().miss };
        let mut codes: Vec<u64> = keys.iter().map(|k| MortonCode::encode(*k).0).collect();
        codes.sort_unstable();
        for &c in &codes {
            a.update(MortonCode(c).decode(), delta, inner);
        }
        // `apply_update`: the batched walk `insert_point_cloud` applies
        let update = if hit {
            ScanUpdate { free: Vec::new(), occupied: codes }
        } else {
            ScanUpdate { free: codes, occupied: Vec::new() }
        };
        b.apply_update(&update, ScanReport::default(), inner);
        let (mut x, mut y) = (Vec::new(), Vec::new());
        ot::write(&a, &mut x).unwrap();
        ot::write(&b, &mut y).unwrap();
        prop_assert!(x == y, "batch and sequential trees differ");
    }
}

/// A tree of `kind` after `ops`; stamped trees see a clock that moves, so
/// that stamps differ between siblings.
fn tree_of(kind: NodeKind, sensor: SensorModel, ops: &[Op]) -> OccupancyTree {
    let mut tree = OccupancyTree::with_kind(0.1, sensor, kind).unwrap();
    for (i, op) in ops.iter().enumerate() {
        tree.set_clock(Clock::Fixed(i as u32 / 16));
        match *op {
            Op::Hit(k) => {
                tree.update_occupancy(k, true, InnerNodes::Update);
                if kind == NodeKind::Color && i % 3 == 0 {
                    tree.set_color(k, [i as u8, 7, 9]);
                }
            }
            Op::Miss(k) => {
                tree.update_occupancy(k, false, InnerNodes::Update);
            }
            Op::Delta(k, d) => {
                tree.update(k, d, if i % 2 == 0 { InnerNodes::Update } else { InnerNodes::Defer });
            }
            Op::Set(k, v) => {
                tree.set_value(k, v, InnerNodes::Update);
            }
            Op::Delete(k, depth) => {
                tree.delete(k, depth);
            }
            Op::Prune => tree.prune(),
            Op::Compact => tree.compact(),
            // only small expansions (a shallow leaf expands to 8^(16 - depth) nodes)
            Op::Expand if tree.root().is_some_and(|r| r.has_children()) && tree.leaves(0).all(|l| l.depth >= 13) => {
                tree.expand().unwrap();
            }
            Op::Expand => {}
            Op::MaxLikelihood => tree.to_max_likelihood(),
        }
    }
    tree
}

/// A random tree from `seed`, built node by node: a chain from the root
/// down to depth `start`, then random masks (often full) and values from a
/// small set so that equal siblings, and thus merges at various depths,
/// are common; stamps and colours from small sets too.
fn random_tree(seed: u64, kind: NodeKind, sensor: SensorModel, start: u8) -> OccupancyTree {
    use octolinear::tree::PreorderBuilder;
    let mut state = seed | 1;
    let mut next = move |n: u64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state % n
    };
    let mut b = PreorderBuilder::with_kind(kind);
    let mut index = 0;
    while let Some(depth) = b.next_depth() {
        let value = [-2.0, -0.7, 0.4, 0.85, 3.5][next(5) as usize];
        let mask = if depth < start {
            1 << next(8)
        } else if depth == 16 || next(16) < u64::from(depth - start) * 3 {
            0
        } else if next(3) > 0 {
            0xff
        } else {
            next(256) as u8
        };
        let extra = match kind {
            NodeKind::Plain => None,
            _ => Some(next(2) as u32),
        };
        b.push_with_extra(value, extra, mask, index).unwrap();
        index += 1;
    }
    b.finish(0.1, sensor).unwrap().unwrap()
}

fn kind_of(i: u8) -> NodeKind {
    [NodeKind::Plain, NodeKind::Color, NodeKind::Stamped][usize::from(i % 3)]
}

fn check_bt_write(tree: &OccupancyTree) -> Result<(), TestCaseError> {
    let mut reference = tree.clone();
    reference.to_max_likelihood();
    reference.prune();
    let (mut want, mut got) = (Vec::new(), Vec::new());
    bt::write_const(&reference, &mut want).unwrap();
    bt::write(tree, &mut got).unwrap();
    prop_assert!(want == got, "bt::write differs from to_max_likelihood + prune + write_const");
    let msg = ros::binary_map_to_msg_compact(tree);
    prop_assert!(got.ends_with(&msg.data), "compact message differs from the .bt node stream");
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// `bt::write` works on the tree in place; it must give the bytes of a
    /// copy converted to maximum likelihood, pruned (with OctoMap's
    /// level-by-level early stop) and written as it is.
    #[test]
    fn bt_write_equals_max_likelihood_prune_write_const(
        ops in prop::collection::vec(op(), 1..250),
        kind in 0u8..3,
        threshold in prop_oneof![Just(0.0f32), -2.5f32..2.5],
    ) {
        let sensor = SensorModel { occupancy_threshold: threshold, ..SensorModel::default() };
        let tree = tree_of(kind_of(kind), sensor, &ops);
        check_bt_write(&tree)?;
    }

    /// The same on random trees whose merges happen at various depths, so
    /// that `prune`'s early stop matters.
    #[test]
    fn bt_write_equals_max_likelihood_prune_write_const_deep(
        seed in any::<u64>(),
        kind in 0u8..3,
        start in 8u8..15,
        threshold in prop_oneof![Just(0.0f32), -2.5f32..4.0],
        bounds in 0u8..5,
    ) {
        // odd clamping bounds too: equal ones (every maximum-likelihood
        // value the same), a NaN one (never equal to itself), swapped ones
        let (clamping_min, clamping_max) = match bounds {
            0 | 1 => (-2.0, 3.5),
            2 => (0.85, 0.85),
            3 => (-2.0, f32::NAN),
            _ => (3.5, -2.0),
        };
        let sensor = SensorModel { occupancy_threshold: threshold, clamping_min, clamping_max, ..SensorModel::default() };
        let tree = random_tree(seed, kind_of(kind), sensor, start);
        check_bt_write(&tree)?;
        let mut ml = tree.clone();
        ml.to_max_likelihood();
        check_bt_write(&ml)?;
    }

    /// Reading through a small buffer, where records straddle refills,
    /// gives what reading from memory gives: the same tree, or the same
    /// error at the same offset.
    #[test]
    fn chunked_reads_equal_reads_from_memory(
        ops in prop::collection::vec(op(), 1..150),
        seed in prop::option::of(any::<u64>()),
        kind in 0u8..3,
        cap in 1usize..12,
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..3),
        cut in any::<prop::sample::Index>(),
        do_cut in any::<bool>(),
    ) {
        let tree = match seed {
            Some(seed) => random_tree(seed, kind_of(kind), SensorModel::default(), 10),
            None => tree_of(kind_of(kind), SensorModel::default(), &ops),
        };
        let (mut ot_bytes, mut bt_bytes) = (Vec::new(), Vec::new());
        ot::write(&tree, &mut ot_bytes).unwrap();
        bt::write(&tree, &mut bt_bytes).unwrap();
        for bytes in [&mut ot_bytes, &mut bt_bytes] {
            for (at, b) in &flips {
                let i = at.index(bytes.len());
                bytes[i] ^= b;
            }
            if do_cut {
                bytes.truncate(cut.index(bytes.len() + 1));
            }
        }
        let written = |t: &OccupancyTree| {
            let mut v = Vec::new();
            ot::write(t, &mut v).unwrap();
            v
        };
        let ot_mem = ot::read(&ot_bytes[..]).map(|t| t.occupancy().map(written)).map_err(|e| e.to_string());
        let ot_chunked = ot::read(BufReader::with_capacity(cap, &ot_bytes[..]))
            .map(|t| t.occupancy().map(written))
            .map_err(|e| e.to_string());
        prop_assert_eq!(ot_mem, ot_chunked);
        let bt_mem = bt::read(&bt_bytes[..]).map(|t| written(&t)).map_err(|e| e.to_string());
        let bt_chunked = bt::read(BufReader::with_capacity(cap, &bt_bytes[..])).map(|t| written(&t)).map_err(|e| e.to_string());
        prop_assert_eq!(bt_mem, bt_chunked);
    }
}

#[test]
fn kinds_convert_without_touching_values_or_structure() {
    let mut color = OccupancyTree::with_kind(0.1, SensorModel::default(), NodeKind::Color).unwrap();
    for i in 0..50u16 {
        let k = Key::new(BASE + i % 4, BASE + (i / 4) % 4, BASE + i / 16);
        color.update_occupancy(k, i % 3 != 0, InnerNodes::Update);
        color.set_color(k, [i as u8, 2 * i as u8, 3 * i as u8]);
    }
    let plain = color.converted(NodeKind::Plain);
    assert_eq!(plain.kind(), NodeKind::Plain);
    let a: Vec<_> = color.nodes(0).map(|n| (n.key, n.depth, n.value.to_bits())).collect();
    let b: Vec<_> = plain.nodes(0).map(|n| (n.key, n.depth, n.value.to_bits(), n.extra)).collect();
    assert_eq!(a, b.iter().map(|&(k, d, v, _)| (k, d, v)).collect::<Vec<_>>());
    assert!(b.iter().all(|&(.., e)| e == 0));
    let back = plain.converted(NodeKind::Color);
    assert!(back.nodes(0).all(|n| n.extra == octolinear::tree::WHITE));
    let same = color.converted(NodeKind::Color);
    let (mut x, mut y) = (Vec::new(), Vec::new());
    ot::write(&color, &mut x).unwrap();
    ot::write(&same, &mut y).unwrap();
    assert_eq!(x, y);
}

/// OctoMap's `prune()` goes level by level from depth 15 up and stops at the
/// first level where nothing merged: equal sibling leaves at depth 14 stay
/// unmerged while no depth-15 node is collapsible.
#[test]
fn prune_stops_at_the_first_level_without_merges() {
    use octolinear::tree::PreorderBuilder;
    let mut b = PreorderBuilder::new();
    let mut index = 0;
    for _ in 0..13 {
        b.push(1.0, 0x01, index).unwrap(); // a chain down child 0
        index += 1;
    }
    b.push(1.0, 0xff, index).unwrap(); // depth 13: eight depth-14 leaves
    for i in 0..8 {
        b.push(1.0, 0, index + 1 + i).unwrap();
    }
    let mut tree = b.finish(0.1, SensorModel::default()).unwrap().unwrap();
    assert_eq!(tree.size(), 22);
    tree.prune();
    assert_eq!(tree.size(), 22, "no depth-15 node merges, so prune stops at once");

    // an aligned 4x4x4 block elsewhere, inserted lazily: it merges at depths 15
    // and 14, so this time pruning goes on up and merges the depth-14 leaves too
    let base = 40000u16;
    for x in 0..4 {
        for y in 0..4 {
            for z in 0..4 {
                tree.set_value(Key::new(base + x, base + y, base + z), 1.0, InnerNodes::Defer);
            }
        }
    }
    tree.update_inner_occupancy();
    let before = tree.size();
    tree.prune();
    assert_eq!(before - tree.size(), 8 * (8 + 1) + 8, "block merged at 15 and 14, old leaves at 13");
    assert!(tree.leaves(0).all(|l| l.depth <= 14));
}
