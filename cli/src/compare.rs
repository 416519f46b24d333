//! `octolinear compare`: OctoMap's `compare_octrees` — voxel differences
//! and the Kullback-Leibler divergence between two maps.

use super::common::load_map;
use anyhow::{bail, Result};
use octolinear::sensor::{probability, SensorModel};
use octolinear::tree::NodeRef;
use octolinear::OccupancyTree;
use std::path::PathBuf;

/// Compare two maps voxel by voxel (like OctoMap's compare_octrees).
///
/// Compares at full resolution: counts of voxels known in each, voxels whose occupancy
/// or log-odds differ, and the KL divergence KLD(A || B) summed over the
/// voxels known in both, with compare_octrees' formula and summation order.
///
/// Pruned nodes count as all the voxels they cover, without expanding the
/// trees in memory.
///
/// Example: octolinear compare built.ot reference.ot --json
#[derive(clap::Args)]
pub struct Args {
    /// First map (.bt, .ot or .olm): the reference P of KLD(P || Q).
    a: PathBuf,
    /// Second map (.bt, .ot or .olm).
    b: PathBuf,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Voxel statistics of two maps.
#[derive(Default, Debug, Clone, PartialEq)]
pub struct Comparison {
    pub voxels_a: u64,
    pub voxels_b: u64,
    pub common: u64,
    pub only_a: u64,
    pub only_b: u64,
    /// Common voxels occupied in exactly one map.
    pub occupancy_differs: u64,
    pub occupied_a_free_b: u64,
    pub free_a_occupied_b: u64,
    /// Common voxels whose log-odds differ (bitwise).
    pub logodds_differ: u64,
    pub max_abs_logodds_difference: f32,
    pub kld: f64,
    /// Voxels where compare_octrees warns the divergence may be infinite.
    pub kld_warnings: u64,
}

/// What one side of the walk is at a region.
#[derive(Clone, Copy)]
enum Side<'a> {
    Unknown,
    Leaf(f32),
    Node(NodeRef<'a>),
}

impl<'a> Side<'a> {
    fn of(node: NodeRef<'a>) -> Side<'a> {
        if node.has_children() {
            Side::Node(node)
        } else {
            Side::Leaf(node.value())
        }
    }

    fn child(self, pos: usize) -> Side<'a> {
        match self {
            Side::Unknown => Side::Unknown,
            Side::Leaf(v) => Side::Leaf(v),
            Side::Node(n) => n.child(pos).map_or(Side::Unknown, Side::of),
        }
    }
}

/// compare_octrees' per-voxel divergence term.
fn kld_term(p1: f64, p2: f64) -> f64 {
    if p1 < 0.0001 {
        ((1.0 - p1) / (1.0 - p2)).ln() * (1.0 - p1)
    } else if p1 > 0.9999 {
        (p1 / p2).ln() * p1
    } else {
        0.0 + ((p1 / p2).ln() * p1 + ((1.0 - p1) / (1.0 - p2)).ln() * (1.0 - p1))
    }
}

struct Walk {
    sa: SensorModel,
    sb: SensorModel,
    c: Comparison,
    nan: Option<(f64, f64)>,
}

impl Walk {
    fn region(&mut self, a: Side<'_>, b: Side<'_>, depth: u8) {
        if matches!(a, Side::Node(_)) || matches!(b, Side::Node(_)) {
            for pos in 0..8 {
                self.region(a.child(pos), b.child(pos), depth + 1);
            }
            return;
        }
        let count = 1u64 << (3 * (16 - u32::from(depth)));
        let c = &mut self.c;
        match (a, b) {
            (Side::Leaf(va), Side::Leaf(vb)) => {
                c.voxels_a += count;
                c.voxels_b += count;
                c.common += count;
                let (oa, ob) = (self.sa.is_occupied(va), self.sb.is_occupied(vb));
                if oa != ob {
                    c.occupancy_differs += count;
                    if oa {
                        c.occupied_a_free_b += count;
                    } else {
                        c.free_a_occupied_b += count;
                    }
                }
                if va.to_bits() != vb.to_bits() {
                    c.logodds_differ += count;
                    c.max_abs_logodds_difference = c.max_abs_logodds_difference.max((va - vb).abs());
                }
                let (p1, p2) = (probability(f64::from(va)), probability(f64::from(vb)));
                if (p1 > 0.001 && p2 < 0.001) || (p1 < 0.999 && p2 > 0.999) {
                    c.kld_warnings += count;
                }
                let kld = kld_term(p1, p2);
                if kld.is_nan() {
                    self.nan.get_or_insert((p1, p2));
                }
                // compare_octrees adds the term once per voxel, in this order
                if count <= 1 << 24 {
                    for _ in 0..count {
                        c.kld += kld;
                    }
                } else {
                    c.kld += kld * count as f64;
                }
            }
            (Side::Leaf(_), Side::Unknown) => {
                c.voxels_a += count;
                c.only_a += count;
            }
            (Side::Unknown, Side::Leaf(_)) => {
                c.voxels_b += count;
                c.only_b += count;
            }
            _ => {}
        }
    }
}

/// Compares two trees of the same resolution.
pub fn compare(a: &OccupancyTree, b: &OccupancyTree) -> Result<Comparison> {
    if (a.resolution() - b.resolution()).abs() > 1e-6 {
        bail!("tree resolutions don't match: {} and {}", a.resolution(), b.resolution());
    }
    fn side(t: &OccupancyTree) -> Side<'_> {
        t.root().map_or(Side::Unknown, Side::of)
    }
    let sides = (side(a), side(b));
    let mut w = Walk { sa: *a.sensor(), sb: *b.sensor(), c: Comparison::default(), nan: None };
    w.region(sides.0, sides.1, 0);
    if let Some((p1, p2)) = w.nan {
        bail!("KLD is NaN for occupancy probabilities {p1} and {p2}");
    }
    Ok(w.c)
}

pub fn run(a: Args) -> Result<()> {
    let ta = load_map(&a.a)?.tree;
    let tb = load_map(&a.b)?.tree;
    let c = compare(&ta, &tb)?;
    if a.json {
        let out = serde_json::json!({
            "a": a.a, "b": a.b, "resolution": ta.resolution(),
            "voxels_a": c.voxels_a, "voxels_b": c.voxels_b, "common": c.common,
            "only_a": c.only_a, "only_b": c.only_b,
            "occupancy_differs": c.occupancy_differs,
            "occupied_a_free_b": c.occupied_a_free_b,
            "free_a_occupied_b": c.free_a_occupied_b,
            "logodds_differ": c.logodds_differ,
            "max_abs_logodds_difference": c.max_abs_logodds_difference,
            "kld": c.kld, "kld_warnings": c.kld_warnings,
        });
        println!("{out}");
        return Ok(());
    }
    println!(
        "Voxels at full resolution: {} in A, {} in B, {} in both ({} only in A, {} only in B)",
        c.voxels_a, c.voxels_b, c.common, c.only_a, c.only_b
    );
    println!(
        "Occupancy differs: {} voxels ({} occupied in A and free in B, {} free in A and occupied in B)",
        c.occupancy_differs, c.occupied_a_free_b, c.free_a_occupied_b
    );
    println!("Log-odds differ: {} voxels (max |difference| {})", c.logodds_differ, c.max_abs_logodds_difference);
    if c.only_a + c.only_b > 0 {
        println!("Note: the maps know different voxels; the KLD covers the common ones only");
    }
    if c.kld_warnings > 0 {
        println!(
            "Warning: {} voxels have a probability near 0 or 1 in B but not in A (KLD may be unbounded)",
            c.kld_warnings
        );
    }
    println!("KLD: {}", super::common::format_g6(c.kld));
    Ok(())
}
