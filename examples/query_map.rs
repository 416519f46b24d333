//! Asks a map what it knows about places: occupied, free or unknown, with
//! the probability of occupancy, and where rays from a position meet the
//! first obstacle.
//!
//! ```sh
//! cargo run --release --example query_map [MAP.bt X Y Z]
//! ```
//!
//! With a map (from `build_map` or OctoMap's tools) it asks about the
//! position `X Y Z`; without, it builds the map of the bundled
//! `samples/indoor.graph` in memory and asks about the first scan's sensor
//! position (`indoor.bt 0.8 0 1` asks the same of `build_map`'s output).
//!
//! A map stores log-odds: `ln(p / (1 - p))` of the probability `p` that a
//! voxel is occupied, 0 for "no idea". `search_point` returns the node that
//! holds a point (a voxel, or a larger pruned node whose voxels all agree)
//! or `None` where nothing was ever observed. `cast_ray` follows a ray voxel
//! by voxel, as OctoMap's `castRay`, until it meets an occupied voxel.

use octolinear::formats::{bt, graph};
use octolinear::sensor::probability;
use octolinear::{CastOptions, CastOutcome, OccupancyTree, Point3, ScanOptions};
use std::io::BufReader;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (tree, position) = match &args[..] {
        [] => sample_map()?,
        [path, x, y, z] => {
            let file = std::fs::File::open(path).map_err(|e| format!("{path}: {e}"))?;
            let tree = bt::read(BufReader::new(file)).map_err(|e| format!("{path}: {e}"))?;
            (tree, Point3::new(x.parse()?, y.parse()?, z.parse()?))
        }
        _ => return Err("usage: query_map [MAP.bt X Y Z]".into()),
    };
    println!("map: {} leaves of {} m", tree.num_leaves(), tree.resolution());

    // point queries: the position itself, and a point far outside what the sensor saw
    for (what, p) in [("position", position), ("100 m above", Point3::new(position.x, position.y, position.z + 100.0))]
    {
        println!("{what} ({}, {}, {}): {}", p.x, p.y, p.z, describe(&tree, p)?);
    }

    // ray queries: eight horizontal directions, 20 m at most; unknown
    // space (never observed) stops a ray unless `ignore_unknown` is set
    let opts = CastOptions { ignore_unknown: false, max_range: Some(20.0) };
    for step in 0..8 {
        let angle = std::f32::consts::FRAC_PI_4 * step as f32;
        let direction = Point3::new(angle.cos(), angle.sin(), 0.0);
        let outcome = match tree.cast_ray(position, direction, opts)? {
            CastOutcome::Occupied { end } => {
                format!("hits {} at {:.2} m", describe(&tree, end)?, end.distance(position))
            }
            CastOutcome::Unknown { end } => format!("meets unknown space at {:.2} m", end.distance(position)),
            CastOutcome::MaxRange { .. } => "is free for 20 m".to_string(),
            CastOutcome::LeftMap { .. } => "leaves the map".to_string(),
        };
        println!("ray towards {:>3} degrees {outcome}", 45 * step);
    }
    Ok(())
}

/// What the map knows about the place of `p`.
fn describe(tree: &OccupancyTree, p: Point3) -> Result<String, Box<dyn std::error::Error>> {
    // depth 0: the deepest node that holds the point
    Ok(match tree.search_point(p, 0)? {
        None => "unknown".to_string(),
        Some(node) => format!(
            "{} (p = {:.3}, a node of depth {})",
            if tree.is_occupied(node.value) { "occupied" } else { "free" },
            probability(f64::from(node.value)),
            node.depth
        ),
    })
}

/// The bundled sample's map, built in memory, and the first scan's sensor
/// position (free space, seen by every ray of that scan).
fn sample_map() -> Result<(OccupancyTree, Point3), Box<dyn std::error::Error>> {
    let scans = graph::read_file(concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph"))?;
    let world: Vec<_> = scans.nodes.iter().map(|node| node.graph2tree()).collect();
    let mut tree = OccupancyTree::new(0.1)?;
    let input = world.iter().map(|(cloud, origin)| (cloud.points.as_slice(), *origin));
    tree.insert_point_clouds(input, &ScanOptions::default(), |_, _| {}).map_err(|(i, e)| format!("scan {i}: {e}"))?;
    Ok((tree, world[0].1))
}
