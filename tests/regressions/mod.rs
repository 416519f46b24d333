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
    let cfg = Config { res: d(0x3fe0000000000000) /* 0.5 */, sensor: None, change_detection: false };
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

// Found after batch updates were introduced: a stale (lazily updated) inner node
// above voxels that all saturate must stay stale, as OctoMap's early exit leaves it.
#[test]
fn regression_random_scans_d826a4d0ddf76597() {
    if !octolinear_oracle::require_or_skip("regression_random_scans_d826a4d0ddf76597") {
        return;
    }
    let cfg = Config {
        res: d(0x3fb999999999999a), /* 0.1 */
        sensor: Some(Sensor {
            hit: d(0x3fe4cac2f340ec20),       /* 0.649751162628835 */
            miss: d(0x3fbdad5f76d932da),      /* 0.11592671062062312 */
            clamp_min: d(0x3fc90b1d859dfd2a), /* 0.19565171264910336 */
            clamp_max: d(0x3fe398ffbe47c75e), /* 0.6124266354001795 */
            threshold: d(0x3fe7ba4e4da408c2), /* 0.7414924160405223 */
        }),
        change_detection: false,
    };
    let ops = vec![
        Op::Scan {
            origin: p(0xc4c7ce35, 0xbf733333, 0x454cc8cd), // [-1598.444, -0.95, 3276.55]
            points: vec![
                p(0xc4c7d99a, 0xbf66670e, 0x454c87b6), // [-1598.8, -0.90001, 3272.482]
            ],
            max_range: d(0xbff0000000000000), /* -1.0 */
            discretize: false,
            lazy: true,
            threads: None,
        },
        Op::Scan {
            origin: p(0xc4c7ce35, 0xbf733333, 0x454cc8cd), // [-1598.444, -0.95, 3276.55]
            points: vec![
                p(0xc4c7af4f, 0xbeb624b9, 0x454c92ce), // [-1597.4784, -0.35574892, 3273.1753]
            ],
            max_range: d(0xbff0000000000000), /* -1.0 */
            discretize: false,
            lazy: false,
            threads: None,
        },
    ];
    check_regression(&cfg, &ops);
}

// Same cause, seen as a node merged by octolinear but left inner by OctoMap.
#[test]
fn regression_node_ops_39df32d7c7ddbae9() {
    if !octolinear_oracle::require_or_skip("regression_node_ops_39df32d7c7ddbae9") {
        return;
    }
    let cfg = Config { res: d(0x3f847ae147ae147b) /* 0.01 */, sensor: None, change_detection: false };
    let ops = vec![
        Op::SetValue { key: [32766, 32788, 32786], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::SetValue { key: [32766, 32788, 32787], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::SetValue { key: [32766, 32789, 32786], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::SetValue { key: [32766, 32789, 32787], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::SetValue { key: [32767, 32788, 32786], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::SetValue { key: [32767, 32788, 32787], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::SetValue { key: [32767, 32789, 32786], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::SetValue { key: [32767, 32789, 32787], value: f(0xbf800000) /* -1.0 */, lazy: false },
        Op::WriteBinary,
        Op::Expand,
        Op::Scan {
            origin: p(0xbd4ccccc, 0x3e32a8cb, 0x3e428f9f), // [-0.049999997, 0.17447202, 0.190001]
            points: vec![
                p(0x3ccccccd, 0x3e6986bd, 0x3e428f5c), // [0.025, 0.22805305, 0.19]
            ],
            max_range: d(0xbff0000000000000), /* -1.0 */
            discretize: false,
            lazy: false,
            threads: None,
        },
    ];
    check_regression(&cfg, &ops);
}
