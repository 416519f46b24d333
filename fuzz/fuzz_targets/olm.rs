//! Fuzz target: `.olm` mapped maps on arbitrary bytes
//! (`cargo +nightly fuzz run olm`).
//!
//! [`check`] must never panic: opening checks the header, then `verify`,
//! searches, iterations, `castRay` and the conversion to a tree (or a
//! counting tree) run on
//! whatever the bytes hold. When `verify` accepts, every answer must be the
//! answer of the tree the file converts to, and that tree written again
//! must verify and answer the same. Built without cargo-fuzz this replays
//! the files named on its command line; `tests/mapped.rs` compiles it as a
//! module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::mapped::{self, MappedMap, WriteOptions};
use octolinear::{CastOptions, Found, Key, KeyBox, Point3};

#[cfg(fuzzing)]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    check(data);
});

#[cfg(not(fuzzing))]
#[allow(dead_code)]
fn main() {
    for path in std::env::args_os().skip(1) {
        check(&std::fs::read(&path).expect("readable input"));
    }
}

/// Value bits, depth, leaf flag and colour, stamp or count.
type Answer = Option<(u32, u8, bool, u32)>;

fn bits(f: Option<Found>) -> Answer {
    f.map(|f| (f.value.to_bits(), f.depth, f.is_leaf, f.extra))
}

/// Keys near the map centre, where small maps live, derived from the data.
fn keys(data: &[u8]) -> Vec<Key> {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in data.iter().take(64) {
        h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
    }
    let mut out = vec![Key::ROOT, Key::new(0, 0, 0), Key::new(65535, 65535, 65535)];
    for _ in 0..24 {
        h ^= h >> 29;
        h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
        let k = |s: u32| 32768u16.wrapping_add((h >> s) as u16 % 64).wrapping_sub(32);
        out.push(Key::new(k(0), k(16), k(32)));
    }
    out
}

fn answers(search: impl Fn(Key, u8) -> Option<Found>, keys: &[Key]) -> Vec<Answer> {
    let mut v = Vec::with_capacity(keys.len() * 4);
    for &k in keys {
        for d in [0, 16, 14, 3] {
            v.push(bits(search(k, d)));
        }
    }
    v
}

/// Opens, verifies and queries `data`; returns (opened, verified).
pub fn check(data: &[u8]) -> (bool, bool) {
    let Ok(map) = MappedMap::new(data) else {
        return (false, false);
    };
    let view = map.view();
    let verified = view.verify().is_ok();
    let keys = keys(data);
    let found = answers(|k, d| view.search(k, d), &keys);
    // the level-skip index answers as the view (checked where verified)
    let index = mapped::MapSearchIndex::new(view);
    let indexed = answers(|k, d| index.search(k, d), &keys);
    // batched searches answer as single ones, even on corrupted bytes,
    // except where a single full-depth search reads the search-blocks
    // section, which only `verify` checks against the node arrays that the
    // batched search reads
    let blocks = view.header().sections.iter().any(|s| s.kind == mapped::SectionKind::SearchBlocks as u16);
    let mut batch = Vec::new();
    for d in [0, 16, 14, 3] {
        if blocks && !verified && (d == 0 || d == 16) {
            continue;
        }
        view.search_many(&keys, d, &mut batch);
        let single: Vec<_> = keys.iter().map(|&k| bits(view.search(k, d))).collect();
        assert_eq!(batch.iter().map(|&f| bits(f)).collect::<Vec<_>>(), single);
    }
    let leaves: Vec<_> = view.leaves(0).map(|l| (l.key, l.depth, l.value.to_bits())).collect();
    let nodes = view.nodes(13).count();
    let bbx = KeyBox { min: Key::new(32700, 32700, 32700), max: Key::new(32800, 32800, 32800) };
    let in_box = view.leaves_in_box(bbx, 0).count();
    let _ = view.root_value();
    let opts = CastOptions { ignore_unknown: true, max_range: Some(4.0) };
    let origin = Point3::new(0.05, 0.05, 0.05);
    let dirs = [Point3::new(1.0, 0.3, 0.1), Point3::new(-0.2, -1.0, 0.5)];
    let rays: Vec<_> = dirs.iter().map(|&d| view.cast_ray(origin, d, opts)).collect();
    let counts: Vec<_> = keys.iter().map(|&k| view.count(k, 0)).collect();
    let tree = view.to_tree();
    let counting = view.to_counting_tree();
    if verified {
        assert_eq!(indexed, found, "indexed searches differ");
    }
    if !verified {
        assert!(tree.is_err(), "to_tree accepted an unverified file");
        assert!(counting.is_err(), "to_counting_tree accepted an unverified file");
        return (true, false);
    }
    if view.kind() == mapped::TreeKind::CountingOcTree {
        assert!(tree.is_err(), "to_tree accepted a counting map");
        assert!(rays.iter().all(|r| matches!(r, Err(octolinear::ray::CastError::NoOccupancy))), "{rays:?}");
        let counting = counting.expect("a verified counting file converts to a counting tree");
        assert_eq!(counts, keys.iter().map(|&k| counting.count(k, 0)).collect::<Vec<_>>());
        let node = |key, depth, extra| (key, depth, extra);
        let nodes: Vec<_> = view.nodes(0).map(|n| node(n.key, n.depth, n.extra)).collect();
        assert_eq!(nodes, counting.nodes(0).map(|n| node(n.key, n.depth, n.extra)).collect::<Vec<_>>());
        let again = mapped::counting_to_bytes(&counting, WriteOptions::default()).expect("writing to memory");
        let again = MappedMap::new(&again[..]).expect("a written file opens");
        again.verify().expect("a written file verifies");
        assert_eq!(counts, keys.iter().map(|&k| again.view().count(k, 0)).collect::<Vec<_>>());
        return (true, true);
    }
    assert!(counting.is_err() && counts.iter().all(Option::is_none), "counts from an occupancy map");
    let tree = tree.expect("a verified file converts to a tree");
    assert_eq!(found, answers(|k, d| tree.search(k, d), &keys));
    let tree_leaves: Vec<_> = tree.leaves(0).map(|l| (l.key, l.depth, l.value.to_bits())).collect();
    assert_eq!(leaves, tree_leaves);
    assert_eq!(nodes, tree.nodes(13).count());
    assert_eq!(in_box, tree.leaves_in_box(bbx, 0).count());
    for (d, r) in dirs.iter().zip(&rays) {
        assert_eq!(*r, tree.cast_ray(origin, *d, opts));
    }
    // written again, in the default layout, it verifies and answers alike
    // (the maximum-likelihood variant only as such: rewriting it prunes)
    let opts =
        if view.variant() == mapped::Variant::Full { WriteOptions::default() } else { WriteOptions::max_likelihood() };
    let again = mapped::to_bytes(&tree, opts).expect("writing to memory");
    let again = MappedMap::new(&again[..]).expect("a written file opens");
    again.verify().expect("a written file verifies");
    if view.variant() == mapped::Variant::Full {
        assert_eq!(found, answers(|k, d| again.search(k, d), &keys));
    }
    (true, true)
}
