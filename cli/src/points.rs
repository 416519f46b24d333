//! `octolinear to-points`: OctoMap's `octree2pointcloud` — voxel centres
//! as a point cloud (.xyz, .ply or .pcd).

use super::common::{depth_arg, extension, format_g6, load_map, write_output, OutputArg};
use anyhow::{bail, Result};
use octolinear::{Key, OccupancyTree, Point3};
use std::io::Write;
use std::path::PathBuf;

/// Write the centres of the occupied (or free) voxels as a point cloud (octree2pointcloud).
///
/// Pruned nodes are expanded first, as octree2pointcloud does, so every
/// voxel of the chosen depth gives one point, in OctoMap's iteration order.
/// `.pcd` output is octree2pointcloud's ASCII file, `.xyz` one `x y z` per
/// line (exact floats), `.ply` binary little endian unless `--ascii`.
///
/// Example: octolinear to-points map.bt -o occupied.ply --depth 14
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// Input map (.bt, .ot or .olm).
    map: PathBuf,
    /// Output cloud (.xyz, .ply or .pcd).
    #[command(flatten)]
    output: OutputArg,
    /// Free voxels instead of occupied ones.
    #[arg(long)]
    free: bool,
    /// Tree depth of the voxels (1 to 16: 16 = full resolution, lower = coarser;
    /// a coarse node is occupied when any voxel below it is).
    #[arg(long, default_value_t = 16)]
    depth: u8,
    /// Write .ply as text.
    #[arg(long)]
    ascii: bool,
}

/// The most points `to-points` writes: the library's bound on outputs
/// that grow with the map's extent, 2^28 (3 GB of coordinates in memory,
/// and a point count every format's header can hold).
const MAX_POINTS: u64 = octolinear::tree::OUTPUT_LIMIT;

/// Calls `f(key, centre)` for every node at `depth` (expanding coarser
/// leaves) whose value satisfies `want`, in depth-first child order.
pub fn for_each_voxel(
    tree: &OccupancyTree,
    depth: u8,
    want: impl Fn(f32) -> bool,
    mut f: impl FnMut(Key, Point3, f32),
) {
    fn expand(tree: &OccupancyTree, key: Key, d: u8, depth: u8, v: f32, f: &mut impl FnMut(Key, Point3, f32)) {
        if d == depth {
            f(key, tree.key_space().key_to_point_at_depth(key, d), v);
            return;
        }
        for pos in 0..8 {
            expand(tree, key.child_key(pos, d), d + 1, depth, v, f);
        }
    }
    for leaf in tree.leaves(depth) {
        if want(leaf.value) {
            expand(tree, leaf.key, leaf.depth, depth, leaf.value, &mut f);
        }
    }
}

pub fn run(a: Args) -> Result<()> {
    let format = extension(a.output.path(), &["xyz", "ply", "pcd"])?;
    let depth = depth_arg(a.depth)?;
    let tree = load_map(&a.map)?.tree;
    let sensor = *tree.sensor();
    let free = a.free;
    let count = tree.voxel_count(depth, |v| sensor.is_occupied(v) != free);
    if count > MAX_POINTS {
        bail!(
            "{} {} voxels at depth {depth} exceed the limit of {MAX_POINTS} (2^28) points; a lower --depth gives fewer",
            count,
            if free { "free" } else { "occupied" }
        );
    }
    let mut points = Vec::with_capacity(count as usize);
    for_each_voxel(&tree, depth, |v| sensor.is_occupied(v) != free, |_, p, _| points.push(p));
    write_output(a.output.path(), |w| match format.as_str() {
        "xyz" => octolinear::formats::xyz::write(&points.clone().into(), w),
        "pcd" => write_pcd(&points, w),
        _ => octolinear::formats::ply::write(&points, a.ascii, w),
    })?;
    eprintln!(
        "wrote {} {} voxel centres to {}",
        points.len(),
        if free { "free" } else { "occupied" },
        a.output.path().display()
    );
    Ok(())
}

/// octree2pointcloud's ASCII PCD.
fn write_pcd(points: &[Point3], mut w: impl Write) -> std::io::Result<()> {
    let n = points.len();
    write!(
        w,
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n\
         WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 0 0 0 1\nPOINTS {n}\nDATA ascii\n"
    )?;
    for p in points {
        writeln!(w, "{} {} {}", format_g6(f64::from(p.x)), format_g6(f64::from(p.y)), format_g6(f64::from(p.z)))?;
    }
    Ok(())
}
