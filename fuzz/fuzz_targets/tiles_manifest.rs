//! Fuzz target: the tile set manifest parser (`cargo +nightly fuzz run
//! tiles_manifest`).
//!
//! [`check`] must never panic; a manifest that parses writes back to the
//! same bytes (one spelling per value) and parses again to the same
//! manifest. Built without cargo-fuzz this replays the files named on its
//! command line.
#![cfg_attr(fuzzing, no_main)]

use octolinear::tiles::Manifest;

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
    let Ok(manifest) = Manifest::parse(data) else { return };
    let written = manifest.to_bytes();
    assert_eq!(written, data, "a parsed manifest writes back to its bytes");
    assert_eq!(Manifest::parse(&written).as_ref(), Ok(&manifest));
}
