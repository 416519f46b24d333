//! Fuzz target: the PCD point reader (`cargo +nightly fuzz run pcd`),
//! LZF decompression included.
//!
//! [`check`] must never panic. A read with colours gives one colour per
//! point and the same points as a read without. Built without cargo-fuzz
//! this replays the files named on its command line; `tests/corruption.rs`
//! compiles it as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::pcd;

#[cfg(fuzzing)]
libfuzzer_sys::fuzz_target!(|data: &[u8]| check(data));

#[cfg(not(fuzzing))]
#[allow(dead_code)]
fn main() {
    for path in std::env::args_os().skip(1) {
        check(&std::fs::read(&path).expect("readable input"));
    }
}

fn bits(c: &octolinear::PointCloud) -> Vec<[u32; 3]> {
    c.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

pub fn check(data: &[u8]) {
    let plain = pcd::read(data, false);
    let Ok(colored) = pcd::read(data, true) else { return };
    let plain = plain.expect("a file that reads with colours reads without");
    assert_eq!(plain.colors, None);
    assert_eq!(bits(&plain.cloud), bits(&colored.cloud));
    if let Some(colors) = &colored.colors {
        assert_eq!(colors.len(), colored.cloud.len());
    }
}
