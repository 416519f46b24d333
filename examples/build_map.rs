//! Builds an occupancy map from recorded scans and saves it as OctoMap's
//! `.bt` file.
//!
//! ```sh
//! cargo run --release --example build_map [SCANS.graph] [OUT.bt]
//! ```
//!
//! Without arguments it reads the bundled `samples/indoor.graph` (six scans
//! of a simulated indoor lidar) and writes `indoor.bt`, which OctoMap's
//! tools (`octovis`, `octree2pointcloud`, ...) open like their own maps.
//!
//! The steps are those of OctoMap's `graph2tree`: read a scan graph (a pose
//! and a point cloud in the sensor frame per scan), move each scan into the
//! world frame, integrate the scans in order (every ray frees the voxels it
//! crosses, its end point makes its voxel more likely occupied), then write
//! the map; the bytes are the ones `graph2tree` writes for the same input.

use octolinear::formats::{bt, graph, write_atomically};
use octolinear::{BoundsRule, OccupancyTree, ScanOptions};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let input = args.next().unwrap_or_else(|| concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph").into());
    let output = args.next().unwrap_or_else(|| "indoor.bt".into());

    let scans = graph::read_file(&input).map_err(|e| format!("{input}: {e}"))?;
    // each scan in the world frame: its points and the sensor's position
    let world: Vec<_> = scans.nodes.iter().map(|node| node.graph2tree()).collect();

    // 10 cm voxels and OctoMap's default sensor model (a hit raises the
    // occupancy probability to 0.7, a miss lowers it to 0.4)
    let mut tree = OccupancyTree::new(0.1)?;
    // defaults: rays of any length, every thread of the machine
    let opts = ScanOptions::default();
    let mut scan = 0;
    tree.insert_point_clouds(
        world.iter().map(|(cloud, origin)| (cloud.points.as_slice(), *origin)),
        &opts,
        |tree, report| {
            println!(
                "scan {scan}: {} points, {} voxels seen free, {} seen occupied; the map has {} nodes",
                report.points,
                report.free_updates,
                report.occupied_updates,
                tree.size()
            );
            scan += 1;
        },
    )
    .map_err(|(scan, e)| format!("{input}: scan {scan}: {e}"))?;

    let occupied = tree.leaves(0).filter(|leaf| tree.is_occupied(leaf.value)).count();
    let [x, y, z] = tree.bounds(BoundsRule::MinPlusSize).size();
    println!(
        "{} leaves ({occupied} occupied) in {x:.1} x {y:.1} x {z:.1} m, {} bytes in memory",
        tree.num_leaves(),
        tree.memory_usage()
    );

    // a temporary file renamed into place: an error leaves no half-written map
    write_atomically(Path::new(&output), |w| bt::write(&tree, w)).map_err(|e| format!("{output}: {e}"))?;
    println!("map written to {output}");
    Ok(())
}
