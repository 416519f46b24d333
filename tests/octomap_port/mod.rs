//! Helpers shared by the ports of OctoMap's own test programs
//! (`octomap/src/testing/*.cpp`): input files, OctoMap's test macros,
//! its tree comparison (`operator==`) and node-level queries.
#![allow(dead_code)]

use octolinear::key::adjust_key_to_depth;
use octolinear::tree::NodeRef;
use octolinear::{Key, NodeKind, OccupancyTree};
use std::path::PathBuf;

/// OctoMap's `DEG2RAD(x)`: `(x) * 0.01745329251994329575`.
pub fn deg2rad(x: f64) -> f64 {
    x * 0.017_453_292_519_943_295
}

/// A data file OctoMap's CMakeLists passes to its tests (`share/data/...`),
/// taken from the inputs of the golden vectors.
pub fn input(name: &str) -> PathBuf {
    let path = octolinear_oracle::golden_dir().join("inputs").join(name);
    assert!(path.is_file(), "OctoMap test input {} not found", path.display());
    path
}

/// `EXPECT_FLOAT_EQ` of OctoMap's `testing.h`: `|a - b| <= 1e-5`.
#[track_caller]
pub fn expect_float_eq(a: f64, b: f64) {
    assert!((a - b).abs() <= 1e-5, "expected {a} == {b} (within 1e-5)");
}

/// `EXPECT_NEAR`.
#[track_caller]
pub fn expect_near(a: f64, b: f64, prec: f64) {
    assert!((a - b).abs() <= prec, "expected |{a} - {b}| <= {prec}");
}

/// OctoMap's `OcTreeBaseImpl::operator==`: same resolution and node
/// counter, and the same nodes (key, depth, node `==`) in `tree_iterator`
/// order. Node `==` compares the value, plus the colour of colour nodes and
/// the stamp of stamped nodes.
pub fn trees_equal(a: &OccupancyTree, b: &OccupancyTree) -> bool {
    if a.kind() != b.kind() || a.resolution() != b.resolution() || a.size() != b.size() {
        return false;
    }
    let with_extra = a.kind() != NodeKind::Plain;
    let mut ib = b.nodes(0);
    for na in a.nodes(0) {
        let Some(nb) = ib.next() else { return false };
        if na.depth != nb.depth || na.key != nb.key || na.value != nb.value || (with_extra && na.extra != nb.extra) {
            return false;
        }
    }
    ib.next().is_none()
}

/// The identity of the node `search(key, depth)` finds: its depth and the
/// key of its centre. Two searches give the same OctoMap node pointer
/// exactly when these agree.
pub fn node_id(tree: &OccupancyTree, key: Key, depth: u8) -> Option<(u8, Key)> {
    tree.search(key, depth).map(|f| (f.depth, adjust_key_to_depth(key, f.depth)))
}

/// The node at exactly `depth` on the path to `key`, if it exists
/// (OctoMap's node pointer, for `nodeChildExists` and friends).
pub fn node_at(tree: &OccupancyTree, key: Key, depth: u8) -> Option<NodeRef<'_>> {
    let mut node = tree.root()?;
    for d in 0..depth {
        node = node.child(key.child_index(d))?;
    }
    Some(node)
}

/// The key of child `pos` of the node at `depth` containing `key`.
pub fn child_key(key: Key, depth: u8, pos: usize) -> Key {
    adjust_key_to_depth(key, depth).child_key(pos, depth)
}

/// `for (float v = start; v <= end; v += step)`, in float arithmetic.
pub fn float_steps(start: f32, end: f32, step: f32) -> Vec<f32> {
    let mut v = Vec::new();
    let mut x = start;
    while x <= end {
        v.push(x);
        x += step;
    }
    v
}

/// Asserts that `bytes` are the file OctoMap's test program writes as
/// `name`, by its SHA-256 (taken from running the program against Debian's
/// liboctomap 1.9.7, which writes these files as 1.10 does).
#[track_caller]
pub fn assert_octomap_file(bytes: &[u8], name: &str, sha256: &str) {
    use sha2::{Digest, Sha256};
    let digest: String = Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(digest, sha256, "{name} differs from what OctoMap writes ({} bytes)", bytes.len());
}
