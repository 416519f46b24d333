//! Fuzz target: the plain-text scan log reader (`log2graph` input,
//! `cargo +nightly fuzz run log`).
//!
//! [`check`] must never panic; a graph read writes to a log that reads back
//! with the same nodes, points and translations. Built without cargo-fuzz
//! this replays the files named on its command line; `tests/corruption.rs`
//! compiles it as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::log;

#[cfg(fuzzing)]
libfuzzer_sys::fuzz_target!(|data: &[u8]| check(data));

#[cfg(not(fuzzing))]
#[allow(dead_code)]
fn main() {
    for path in std::env::args_os().skip(1) {
        check(&std::fs::read(&path).expect("readable input"));
    }
}

pub fn check(data: &[u8]) {
    let Ok(g) = log::read(data) else { return };
    assert_eq!(g.edges.len(), g.nodes.len().saturating_sub(1));
    let mut text = Vec::new();
    log::write(&g, &mut text).expect("a read graph is finite");
    let back = log::read(&text[..]).expect("a written log reads back");
    assert_eq!(back.nodes.len(), g.nodes.len());
    for (a, b) in g.nodes.iter().zip(&back.nodes) {
        let bits = |p: &octolinear::Point3| p.to_array().map(f32::to_bits);
        assert_eq!(bits(&a.pose.translation), bits(&b.pose.translation));
        assert_eq!(a.scan.len(), b.scan.len());
        for (p, q) in a.scan.iter().zip(&b.scan) {
            assert_eq!(bits(p), bits(q));
        }
    }
}
