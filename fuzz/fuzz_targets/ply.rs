//! Fuzz target: the PLY point reader (`cargo +nightly fuzz run ply`).
//!
//! [`check`] must never panic. A read with colours gives one colour per
//! point and the same points as a read without; the points, written as
//! binary and as ASCII PLY, read back bit for bit (any NaN as a NaN). Built without cargo-fuzz
//! this replays the files named on its command line; `tests/corruption.rs`
//! compiles it as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::ply;

#[cfg(fuzzing)]
libfuzzer_sys::fuzz_target!(|data: &[u8]| check(data));

#[cfg(not(fuzzing))]
#[allow(dead_code)]
fn main() {
    for path in std::env::args_os().skip(1) {
        check(&std::fs::read(&path).expect("readable input"));
    }
}

/// The coordinates' bits, every NaN as the same one (ASCII keeps no NaN
/// payload).
fn bits(c: &octolinear::PointCloud) -> Vec<[u32; 3]> {
    c.iter().map(|p| p.to_array().map(|v| if v.is_nan() { f32::NAN.to_bits() } else { v.to_bits() })).collect()
}

pub fn check(data: &[u8]) {
    let plain = ply::read(data, false);
    let Ok(colored) = ply::read(data, true) else { return };
    let plain = plain.expect("a file that reads with colours reads without");
    assert_eq!(plain.colors, None);
    assert_eq!(bits(&plain.cloud), bits(&colored.cloud));
    if let Some(colors) = &colored.colors {
        assert_eq!(colors.len(), colored.cloud.len());
    }
    let points: Vec<octolinear::Point3> = plain.cloud.iter().copied().collect();
    for ascii in [false, true] {
        let mut out = Vec::new();
        ply::write(&points, ascii, &mut out).expect("writing to memory");
        let back = ply::read(&out, true).expect("a written file reads back");
        assert_eq!(bits(&back.cloud), bits(&plain.cloud), "ascii: {ascii}");
    }
}
