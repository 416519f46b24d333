//! Builds an occupancy map from point clouds taken at known sensor poses
//! and saves it as OctoMap's `.bt` or `.ot` file, or octolinear's `.olm`.
//!
//! ```sh
//! cargo run --release --example build_map -- [OUT.bt|OUT.ot|OUT.olm [POSES.txt CLOUD.ply|.pcd|.xyz ...]]
//! cargo run --release --example build_map -- OUT.bt SCANS.graph
//! ```
//!
//! Without inputs it reads the three bundled scans of a simulated lidar in
//! a corridor, `samples/scans/scan0.ply`, `scan1.pcd` and `scan2.xyz`, with
//! their poses from `samples/scans/poses.txt`, and writes `OUT` (by default
//! `scans.bt`), which OctoMap's tools (`octovis`, `octree2pointcloud`, ...)
//! open like their own maps.
//!
//! Each cloud holds the points one scan measured, in the sensor's frame. A
//! poses file gives the sensor's pose in the world for each cloud: one line
//! `x y z roll pitch yaw` (metres, radians) per cloud, in the order the
//! clouds are named; lines starting with `#` are comments (the format of
//! `octolinear build --trajectory`). A `.graph` file, OctoMap's scan graph
//! that its `graph2tree` tool reads, holds the clouds and their poses in one
//! file.
//!
//! The steps are those of `graph2tree`: move each scan into the world frame,
//! integrate the scans in order (every ray frees the voxels it crosses, its
//! end point makes its voxel more likely occupied), then write the map; a
//! `.bt` or `.ot` file holds the bytes OctoMap writes for the same input.

use octolinear::formats::{bt, graph, ot, pcd, ply, xyz, MapFormat};
use octolinear::geometry::graph2tree_transform;
use octolinear::{mapped, OccupancyTree, Point3, PointCloud, Pose6D, ScanOptions};
use std::path::Path;

type Error = Box<dyn std::error::Error>;

/// The bundled inputs used without arguments: the poses file, then the clouds.
const SAMPLE_SCANS: [&str; 4] = ["poses.txt", "scan0.ply", "scan1.pcd", "scan2.xyz"];

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let output = args.first().map_or("scans.bt", String::as_str);
    let inputs: Vec<String> = if args.len() > 1 {
        args[1..].to_vec()
    } else {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/scans");
        SAMPLE_SCANS.iter().map(|name| format!("{dir}/{name}")).collect()
    };

    // every scan in the world frame: its points and the sensor's position
    let scans: Vec<(PointCloud, Point3)> = match &inputs[..] {
        [graph_file] if graph_file.ends_with(".graph") => {
            let graph = graph::read_file(graph_file).map_err(|e| format!("{graph_file}: {e}"))?;
            graph.nodes.iter().map(|node| node.graph2tree()).collect()
        }
        [poses_file, clouds @ ..] if !clouds.is_empty() => {
            let poses = read_poses(poses_file)?;
            if poses.len() != clouds.len() {
                return Err(format!("{poses_file} has {} poses for {} clouds", poses.len(), clouds.len()).into());
            }
            let mut scans = Vec::new();
            for (cloud_file, pose) in clouds.iter().zip(&poses) {
                let cloud = read_cloud(cloud_file).map_err(|e| format!("{cloud_file}: {e}"))?;
                // OctoMap's transform: points from the sensor frame into the
                // world frame, and the sensor's own position as ray origin
                scans.push(graph2tree_transform(pose, &cloud));
            }
            scans
        }
        _ => return Err("usage: build_map [OUT.bt|OUT.ot|OUT.olm [POSES.txt CLOUD... | SCANS.graph]]".into()),
    };

    // 10 cm voxels and OctoMap's default sensor model (a hit raises the
    // occupancy probability to 0.7, a miss lowers it to 0.4)
    let mut tree = OccupancyTree::new(0.1)?;
    // defaults: rays of any length, every thread of the machine; set
    // `max_range: Some(20.0)` to cut long rays as `graph2tree -m 20` does
    let opts = ScanOptions::default();
    let mut scan = 0;
    tree.insert_point_clouds(
        scans.iter().map(|(cloud, origin)| (cloud.points.as_slice(), *origin)),
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
    .map_err(|(scan, e)| format!("scan {scan}: {e}"))?;

    // Each writer writes a temporary file and renames it into place: an
    // error leaves no half-written map.
    let written = match MapFormat::from_path(Path::new(output))? {
        MapFormat::Bt => bt::write_file(&tree, output),
        MapFormat::Ot => ot::write_file(&tree, output),
        MapFormat::Olm => mapped::write_file(&tree, Path::new(output)),
    };
    written.map_err(|e| format!("{output}: {e}"))?;
    let occupied = tree.leaves(0).filter(|leaf| tree.is_occupied(leaf.value)).count();
    println!("map of {} nodes ({} leaves, {occupied} occupied) written to {output}", tree.size(), tree.num_leaves());
    Ok(())
}

/// A point cloud file, by its extension.
fn read_cloud(path: &str) -> Result<PointCloud, Error> {
    Ok(match Path::new(path).extension().and_then(|e| e.to_str()) {
        // PLY and PCD files are read whole; `true` would also read colours
        Some("ply") => ply::read(&std::fs::read(path)?, false)?.cloud,
        Some("pcd") => pcd::read(&std::fs::read(path)?, false)?.cloud,
        Some("xyz" | "txt") => xyz::read_file(path)?,
        _ => return Err("unknown point cloud format (expected .ply, .pcd, .xyz or .txt)".into()),
    })
}

/// A poses file: one `x y z roll pitch yaw` per line.
fn read_poses(path: &str) -> Result<Vec<Pose6D>, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut poses = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = line.split_whitespace().map(str::parse).collect::<Result<_, _>>().unwrap_or_default();
        let [x, y, z, roll, pitch, yaw] = v[..] else {
            return Err(format!("{path} line {}: {line:?} is not six numbers (x y z roll pitch yaw)", n + 1).into());
        };
        if !v.iter().all(|c| c.is_finite()) {
            return Err(format!("{path} line {}: {line:?} holds a value that is not finite", n + 1).into());
        }
        poses.push(Pose6D::from_euler(x as f32, y as f32, z as f32, roll, pitch, yaw));
    }
    Ok(poses)
}
