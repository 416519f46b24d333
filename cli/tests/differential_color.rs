//! `octolinear build --color` on PLY and PCD files against the real OctoMap
//! (the system `liboctomap` through `octolinear-oracle`) fed the same points
//! through the same calls. The coloured scans are those of
//! `tests/differential_color.rs` at the repository root.
//!
//! Knob: `OCTOLINEAR_DIFF_SEED` (base seed).

use octolinear::geometry::graph2tree_transform;
use octolinear::{Point3, PointCloud, Pose6D};
use octolinear_oracle::{require_or_skip, ColorOp, OracleColorTree};
use octolinear_sim::SplitMix64;
use std::process::Command;

#[path = "../../tests/common/mod.rs"]
mod common;
use common::colored_scan;

fn base_seed() -> u64 {
    std::env::var("OCTOLINEAR_DIFF_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(0x00c0_10c0_ffee)
}

fn p3(p: [f32; 3]) -> Point3 {
    Point3::new(p[0], p[1], p[2])
}

/// Where two `.ot` streams first differ, for the failure message.
fn first_difference(a: &[u8], b: &[u8]) -> String {
    let at = a.iter().zip(b).position(|(x, y)| x != y).unwrap_or(a.len().min(b.len()));
    format!("lengths {} vs {}, first difference at byte {at}", a.len(), b.len())
}

fn ply_binary(pts: &[[f32; 3]], cols: &[[u8; 3]]) -> Vec<u8> {
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n\
         end_header\n",
        pts.len()
    )
    .into_bytes();
    for (p, c) in pts.iter().zip(cols) {
        for v in p {
            b.extend(v.to_le_bytes());
        }
        b.extend(c);
        b.push(200);
    }
    b
}

fn pcd_binary(pts: &[[f32; 3]], cols: &[[u8; 3]]) -> Vec<u8> {
    let n = pts.len();
    let mut b = format!(
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {n}\n\
         HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n"
    )
    .into_bytes();
    for (p, c) in pts.iter().zip(cols) {
        for v in p {
            b.extend(v.to_le_bytes());
        }
        let packed = (u32::from(c[0]) << 16) | (u32::from(c[1]) << 8) | u32::from(c[2]);
        b.extend(packed.to_le_bytes());
    }
    b
}

/// `octolinear build --color` gives the bytes OctoMap writes for the same
/// scans taken through the same calls.
#[test]
fn cli_color_build_matches_octomap() {
    if !require_or_skip("cli_color_build_matches_octomap") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut rng = SplitMix64(base_seed() ^ 0xc11);
    let res = 0.05;
    let (a, ca) = colored_scan(&mut rng, res, [0.0; 3], 1500);
    let (b, cb) = colored_scan(&mut rng, res, [0.0; 3], 900);
    let pa = dir.path().join("a.ply");
    let pb = dir.path().join("b.pcd");
    std::fs::write(&pa, ply_binary(&a, &ca)).unwrap();
    std::fs::write(&pb, pcd_binary(&b, &cb)).unwrap();
    let poses = [[0.5, -0.25, 0.125, 0.0, 0.25, 0.5], [-1.0, 0.5, 0.0, 0.125, 0.0, -0.75]];
    let traj: String = poses.iter().map(|p| p.map(|v| v.to_string()).join(" ") + "\n").collect();
    let tp = dir.path().join("traj.txt");
    std::fs::write(&tp, traj).unwrap();
    let out = dir.path().join("c.ot");
    let status = Command::new(env!("CARGO_BIN_EXE_octolinear"))
        .args(["build", "--color", "--res", "0.05", "--points"])
        .args([&pa, &pb])
        .arg("--trajectory")
        .arg(&tp)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let mine = std::fs::read(&out).unwrap();
    assert!(mine.windows(16).any(|w| w == b"\nid ColorOcTree\n"), "not a ColorOcTree");

    let mut theirs = OracleColorTree::with_graph2tree_default(res).unwrap();
    for ((pts, cols), pose) in [(&a, &ca), (&b, &cb)].into_iter().zip(poses) {
        let pose = Pose6D::from_euler(pose[0] as f32, pose[1] as f32, pose[2] as f32, pose[3], pose[4], pose[5]);
        let cloud = PointCloud { points: pts.iter().copied().map(p3).collect() };
        let (world, origin) = graph2tree_transform(&pose, &cloud);
        let w: Vec<[f32; 3]> = world.points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let o = [origin.x, origin.y, origin.z];
        theirs.insert_point_cloud(&w, o, -1.0, false, false).unwrap();
        theirs.apply_colors(ColorOp::Integrate, &w, cols);
    }
    theirs.update_inner_occupancy();
    let want = theirs.write_ot().unwrap();
    assert!(mine == want, "build --color differs from OctoMap: {}", first_difference(&mine, &want));
}
