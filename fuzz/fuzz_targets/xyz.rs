//! Fuzz target: the `.xyz` point reader (`cargo +nightly fuzz run xyz`).
//!
//! [`check`] must never panic; a cloud read writes to text that reads back
//! to the same floats, bit for bit. Built without cargo-fuzz this replays
//! the files named on its command line; `tests/corruption.rs` compiles it
//! as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::xyz;

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
    let Ok(cloud) = xyz::read(data) else { return };
    let mut text = Vec::new();
    xyz::write(&cloud, &mut text).expect("a read cloud is finite");
    let back = xyz::read(&text[..]).expect("written text reads back");
    assert_eq!(back.len(), cloud.len());
    for (a, b) in cloud.iter().zip(&back) {
        assert_eq!(a.to_array().map(f32::to_bits), b.to_array().map(f32::to_bits));
    }
}
