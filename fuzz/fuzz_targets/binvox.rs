//! Fuzz target: the binvox reader (`cargo +nightly fuzz run binvox`).
//!
//! [`check`] must never panic. The runs of a grid that reads cover it in
//! order, and every voxel's coordinates lie inside the grid. Built without
//! cargo-fuzz this replays the files named on its command line;
//! `tests/corruption.rs` compiles it as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::binvox;

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
    let Ok(bv) = binvox::read(data) else { return };
    let [d, h, w] = bv.dim;
    assert_eq!(Some(bv.size), d.checked_mul(h).and_then(|s| s.checked_mul(w)));
    let mut next = 0;
    let covered = bv.for_each_run(|_, run| {
        assert_eq!(run.start, next, "runs in order");
        next = run.end;
        // a few voxels per run: the grid may be huge
        for j in [run.start, run.end.saturating_sub(1)].into_iter().filter(|j| run.contains(j)) {
            let [x, y, z] = bv.coords(j);
            assert!(x < d && z < h && y < w, "voxel {j} at {x} {y} {z} outside {:?}", bv.dim);
        }
    });
    if covered.is_ok() {
        assert_eq!(next, bv.size);
    }
}
