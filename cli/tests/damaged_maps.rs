//! The command-line tool on damaged `.olm` maps: every subcommand that
//! reads a map checks all its bytes first and refuses a damaged one with one
//! error line; `query --no-verify` answers from whatever the bytes hold,
//! without panicking. (Damaged inputs for the library's readers:
//! `tests/corruption.rs` at the repository root.)

use octolinear::{CountingTree, InnerNodes, OccupancyTree, Point3};
use std::path::Path;

#[path = "../../tests/common/mod.rs"]
mod common;
use common::Rng;

fn octolinear(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_octolinear")).args(args).output().expect("binary runs")
}

/// Requires exit code 1 with one `octolinear: error:` line naming `needle`.
fn cli_fails(args: &[&str], needle: &str) {
    let out = octolinear(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    assert!(err.starts_with("octolinear: error: ") && err.contains(needle), "{args:?}: {err:?} lacks {needle:?}");
}

/// Section table entries of an `.olm` file: (kind, byte range).
fn olm_sections(b: &[u8]) -> Vec<(u16, std::ops::Range<usize>)> {
    let count = usize::from(u16::from_le_bytes([b[54], b[55]]));
    let word = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap()) as usize;
    (0..count)
        .map(|i| {
            let e = 96 + 24 * i;
            (u16::from_le_bytes([b[e], b[e + 1]]), word(e + 8)..word(e + 8) + word(e + 16))
        })
        .collect()
}

/// Recomputes every section checksum, then the header's.
fn fix_olm_checksums(b: &mut [u8]) {
    for (i, (_, range)) in olm_sections(b).into_iter().enumerate() {
        let crc = crc32fast::hash(&b[range]);
        b[96 + 24 * i + 4..96 + 24 * i + 8].copy_from_slice(&crc.to_le_bytes());
    }
    let crc = crc32fast::hash(&b[..252]);
    b[252..256].copy_from_slice(&crc.to_le_bytes());
}

/// A map of a few thousand nodes, occupied and free, and points to ask it:
/// its leaves' centres and a few outside.
fn cli_map() -> (OccupancyTree, String) {
    let mut t = OccupancyTree::new(0.1).unwrap();
    let mut rng = Rng(0x01a5);
    for i in 0..600 {
        let c = |rng: &mut Rng| rng.below(400) as f32 / 100.0 - 2.0;
        let p = Point3::new(c(&mut rng), c(&mut rng), c(&mut rng));
        t.update_point(p, i % 3 == 0, InnerNodes::Update).unwrap();
    }
    let mut points: String =
        t.leaves(0).map(|l| l.center_point()).map(|c| format!("{} {} {}\n", c.x, c.y, c.z)).collect();
    points += "100 0 0\n-3 3 0.5\n";
    (t, points)
}

#[test]
fn cli_refuses_damaged_olm_maps() {
    use octolinear::mapped::{self, MappedMap, SearchBlocksSection, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (tree, points) = cli_map();
    std::fs::write(at("q.xyz"), points).unwrap();
    std::fs::write(at("good.olm"), mapped::to_bytes(&tree, WriteOptions::default()).unwrap()).unwrap();
    let mut counting = CountingTree::new(0.1).unwrap();
    for l in tree.leaves(0) {
        counting.update_point(l.center_point()).unwrap();
    }
    let blocks = WriteOptions { search_blocks: SearchBlocksSection::Always, ..WriteOptions::default() };
    let bases = [
        ("full", mapped::to_bytes(&tree, WriteOptions::default()).unwrap()),
        ("pointers", mapped::to_bytes(&tree, WriteOptions::pointers()).unwrap()),
        ("maximum likelihood", mapped::to_bytes(&tree, WriteOptions::max_likelihood()).unwrap()),
        ("search blocks", mapped::to_bytes(&tree, blocks).unwrap()),
        ("counting", mapped::counting_to_bytes(&counting, WriteOptions::default()).unwrap()),
    ];
    let (map, q, good) = (at("m.olm"), at("q.xyz"), at("good.olm"));
    let (map, q, good) = (map.as_str(), q.as_str(), good.as_str());
    let outputs = [at("out.ot"), at("out.xyz"), at("out.bt"), at("crop.bt"), at("out.ply"), at("out.png")];
    let o = |i: usize| outputs[i].as_str();
    let commands: [Vec<&str>; 12] = [
        vec!["info", map],
        vec!["convert", map, o(0)],
        vec!["query", map, "--points", q],
        vec!["query", map, "--points", q, "--format", "decimal"],
        vec!["verify", map],
        vec!["compare", good, map],
        vec!["to-points", map, o(1)],
        vec!["edit", map, o(2)],
        vec!["crop", map, o(3), "--min", "-1", "-1", "-1", "--max", "1", "1", "1"],
        vec!["raycast", map, "--origin", "0", "0", "0", "--direction", "1", "0", "0"],
        vec!["mesh", map, "-o", o(4)],
        vec!["render", map, "-o", o(5)],
    ];
    let mut rng = Rng(0x0c11);
    let (mut refused, mut accepted) = (0, 0);
    for (label, base) in &bases {
        let sections = olm_sections(base);
        for i in 0..8 {
            // bits flipped inside one section; every other mutant with its
            // checksums recomputed, so that the structure checks decide
            let mut m = base.clone();
            let (_, range) = &sections[rng.below(sections.len())];
            for _ in 0..1 + rng.below(3) {
                m[range.start + rng.below(range.len())] ^= 1 << rng.below(8);
            }
            let fixed = i % 2 == 1;
            if fixed {
                fix_olm_checksums(&mut m);
            }
            std::fs::write(map, &m).unwrap();
            let what = format!("{label} mutant {i}");
            let valid = MappedMap::new(&m[..]).is_ok_and(|v| v.verify().is_ok());
            if valid {
                // a damage the format cannot see (a value changed with its checksum)
                assert!(fixed, "{what}: a flipped bit passed the checksums");
                accepted += 1;
                assert!(octolinear(&["query", map, "--points", q]).status.success(), "{what}");
            } else {
                refused += 1;
                let needle = if fixed { "not a valid .olm map" } else { "checksum mismatch" };
                for args in &commands {
                    cli_fails(args, needle);
                }
                for out in &outputs {
                    assert!(!Path::new(out).exists(), "{what}: {out} written from a damaged map");
                }
            }
            // unverified: an answer or a clean error, never a panic or a signal
            let out = octolinear(&["query", map, "--points", q, "--no-verify"]);
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(matches!(out.status.code(), Some(0 | 1)) && !err.contains("panicked"), "{what}: {err}");
            assert!(out.status.success() || err.starts_with("octolinear: error: "), "{what}: {err}");
        }
    }
    eprintln!("{refused} damaged maps refused, {accepted} still valid");
    assert!(refused > 3 * accepted, "most mutants damage the map");
}

/// A damage only the checksums see: every log-odds negated, so occupied
/// voxels read free and free ones occupied. `query` refuses the map; with
/// `--no-verify` it answers from the damaged bytes, wrongly.
#[test]
fn query_no_verify_answers_from_damaged_bytes() {
    use octolinear::mapped::{self, SectionKind, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let (tree, points) = cli_map();
    let q = dir.path().join("q.xyz");
    std::fs::write(&q, points).unwrap();
    let mut bytes = mapped::to_bytes(&tree, WriteOptions::default()).unwrap();
    let (good, bad) = (dir.path().join("good.olm"), dir.path().join("bad.olm"));
    std::fs::write(&good, &bytes).unwrap();
    let (_, values) = olm_sections(&bytes).into_iter().find(|(k, _)| *k == SectionKind::Values as u16).unwrap();
    for sign in values.skip(3).step_by(4) {
        bytes[sign] ^= 0x80;
    }
    std::fs::write(&bad, &bytes).unwrap();
    let (good, bad, q) = (good.to_str().unwrap(), bad.to_str().unwrap(), q.to_str().unwrap());
    cli_fails(
        &["query", bad, "--points", q],
        "bad.olm: not a valid .olm map: values section (kind 2): checksum mismatch",
    );
    let answers = |map: &str, flags: &[&str]| {
        let out = octolinear(&[&["query", map, "--points", q], flags].concat());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    let (right, wrong) = (answers(good, &[]), answers(bad, &["--no-verify"]));
    assert_eq!(right, answers(good, &["--no-verify"]));
    assert!(right.contains(",occupied,") && right.contains(",free,"));
    assert_eq!(right.lines().count(), wrong.lines().count());
    let flipped = |state: &str| match state {
        "occupied" => "free".to_string(),
        "free" => "occupied".to_string(),
        other => other.to_string(),
    };
    for (r, w) in right.lines().zip(wrong.lines()) {
        let (r, w): (Vec<&str>, Vec<&str>) = (r.split(',').collect(), w.split(',').collect());
        assert_eq!((&r[..3], flipped(r[3])), (&w[..3], w[3].to_string()));
    }
}
