//! Kept reproducers of differences between octolinear and OctoMap found by
//! `tests/differential.rs`. When a random case differs, the panic message
//! (and a file in `target/tmp/`) holds a shrunk `#[test] fn regression_...`
//! that calls [`check_regression`]: paste it below (and `cargo fmt`). Values are written as
//! bit patterns (`p(x, y, z)` points, `f(..)` floats, `d(..)` doubles) so the
//! case is exact. Mark a case `#[ignore = "known bug: ..."]` until it is fixed.
#![allow(unused_imports, clippy::unreadable_literal)]

use super::{check_regression, d, f, p, Config, Op, Sensor};

// Documents the format, and pins a diagonal ray from a voxel centre (exact
// DDA ties between x and y at every step) at resolution 0.5.
#[test]
fn regression_example_diagonal_tie() {
    if !octolinear_oracle::require_or_skip("regression_example_diagonal_tie") {
        return;
    }
    if !octolinear_oracle::require_or_skip("regression_example_diagonal_tie") {
        return;
    }
    let cfg = Config {
        res: d(0x3fe0000000000000), /* 0.5 */
        sensor: None,
        change_detection: false,
    };
    let ops = vec![
        Op::Scan {
            origin: p(0x3e800000, 0x3e800000, 0x3e800000), // [0.25, 0.25, 0.25]
            points: vec![
                p(0x40900000, 0x40900000, 0x3e800000), // [4.5, 4.5, 0.25]
                p(0xc0700000, 0x3e800000, 0xc0700000), // [-3.75, 0.25, -3.75]
            ],
            max_range: d(0xbff0000000000000), /* -1.0 */
            discretize: false,
            lazy: false,
            threads: None,
        },
        Op::RayKeys {
            origin: p(0x3e800000, 0x3e800000, 0x3e800000), /* [0.25, 0.25, 0.25] */
            end: p(0x40900000, 0x40900000, 0x40900000),    /* [4.5, 4.5, 4.5] */
        },
        Op::CastRay {
            origin: p(0x3e800000, 0x3e800000, 0x3e800000), /* [0.25, 0.25, 0.25] */
            dir: p(0x3f800000, 0x3f800000, 0x00000000),    /* [1.0, 1.0, 0.0] */
            ignore_unknown: true,
            max_range: d(0x4024000000000000), /* 10.0 */
        },
    ];
    check_regression(&cfg, &ops);
}
