//! Checks a drone's planned path against a map: does any point of the
//! path come closer to an obstacle than a safety margin?
//!
//! ```sh
//! cargo run --release --example collision_check -- [--margin M] [--unknown-is-obstacle] [MAP WAYPOINTS.xyz]
//! ```
//!
//! `MAP` is a `.bt`, `.ot` or `.olm` file; `WAYPOINTS.xyz` holds the path's
//! waypoints, one `x y z` per line (metres, world frame; `#` starts a
//! comment), which the drone flies in straight segments. Without arguments
//! the map is the bundled `samples/indoor.bt` (a corridor with rooms) and
//! the path `samples/drone_path.xyz`, whose last segment turns into a wall.
//! The margin (default 0.3 m, at most 2 m) is the drone's radius plus the
//! distance it must keep. With `--unknown-is-obstacle`, space the map has
//! never observed counts as an obstacle too, as a cautious planner treats
//! it.
//!
//! For each segment, the voxels it crosses are taken in order (the map's
//! `ray_keys`, the voxel walk OctoMap's `computeRayKeys` makes); around each
//! one, every voxel in a cube reaching `margin` further on each side is
//! looked up. A cube is a little more cautious than a sphere of that radius.
//! The first voxel of the path whose cube holds an obstacle is reported,
//! with the obstacle nearest to it.

use octolinear::formats::{read_map_file, xyz};
use octolinear::{Key, OccupancyTree, Point3};

type Error = Box<dyn std::error::Error>;

/// Where a segment first comes too close to an obstacle.
struct Collision {
    /// Centre of the first voxel of the path within the margin of an obstacle.
    path_point: Point3,
    /// Centre of the obstacle voxel nearest to it.
    obstacle: Point3,
    /// The obstacle is unobserved space (with `--unknown-is-obstacle`), not
    /// an occupied voxel.
    unknown: bool,
}

fn main() -> Result<(), Error> {
    let mut margin = 0.3;
    let mut unknown_is_obstacle = false;
    let mut paths = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--margin" => {
                let value = args.next().ok_or("--margin needs a value in metres")?;
                margin = value.parse().map_err(|e| format!("--margin {value}: {e}"))?;
                if !(0.0..=2.0).contains(&margin) {
                    return Err(format!("--margin {value}: must lie between 0 and 2 m").into());
                }
            }
            "--unknown-is-obstacle" => unknown_is_obstacle = true,
            _ => paths.push(arg),
        }
    }
    let (map_file, path_file) = match &paths[..] {
        [] => (
            concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.bt").to_string(),
            concat!(env!("CARGO_MANIFEST_DIR"), "/samples/drone_path.xyz").to_string(),
        ),
        [map, path] => (map.clone(), path.clone()),
        _ => return Err("usage: collision_check [--margin M] [--unknown-is-obstacle] [MAP WAYPOINTS.xyz]".into()),
    };

    let tree = read_map_file(&map_file).map_err(|e| e.to_string())?;
    let waypoints = xyz::read_file(&path_file).map_err(|e| format!("{path_file}: {e}"))?.points;
    if waypoints.len() < 2 {
        return Err(format!("{path_file}: a path needs at least two waypoints").into());
    }
    // the margin in whole voxels, rounded up
    let reach = (margin / tree.resolution()).ceil() as i32;
    println!(
        "{} waypoints, margin {margin} m (voxels of {} m: {reach} on each side), unknown space is {}",
        waypoints.len(),
        tree.resolution(),
        if unknown_is_obstacle { "an obstacle" } else { "free" }
    );

    for (i, pair) in waypoints.windows(2).enumerate() {
        let (from, to) = (pair[0], pair[1]);
        let collision = first_collision(&tree, from, to, reach, unknown_is_obstacle)
            .map_err(|e| format!("{path_file}: segment {} (waypoint {} to {}): {e}", i + 1, i + 1, i + 2))?;
        let Some(c) = collision else {
            println!("segment {} (waypoint {} to {}, {:.2} m): clear", i + 1, i + 1, i + 2, from.distance(to));
            continue;
        };
        let [px, py, pz] = c.path_point.to_array();
        let [ox, oy, oz] = c.obstacle.to_array();
        println!(
            "first collision: segment {} (waypoint {} to {}), path voxel at ({px:.2}, {py:.2}, {pz:.2}), \
             {:.2} m along it; {} voxel at ({ox:.2}, {oy:.2}, {oz:.2})",
            i + 1,
            i + 1,
            i + 2,
            c.path_point.distance(from),
            if c.unknown { "unknown" } else { "occupied" },
        );
        return Ok(());
    }
    println!("the path is clear");
    Ok(())
}

/// The first voxel of the segment `from`–`to` within `reach` voxels of an
/// obstacle, or `None` when the whole segment keeps its distance.
fn first_collision(
    tree: &OccupancyTree,
    from: Point3,
    to: Point3,
    reach: i32,
    unknown_is_obstacle: bool,
) -> Result<Option<Collision>, Error> {
    // `ray_keys` yields the voxels from `from`'s up to, not including, `to`'s
    let last = tree.key(to)?;
    for key in tree.ray_keys(from, to)?.chain([last]) {
        if let Some((obstacle, unknown)) = nearest_obstacle(tree, key, reach, unknown_is_obstacle) {
            let keys = tree.key_space();
            return Ok(Some(Collision {
                path_point: keys.key_to_point(key),
                obstacle: keys.key_to_point(obstacle),
                unknown,
            }));
        }
    }
    Ok(None)
}

/// The obstacle voxel nearest to the voxel `center` within the cube of
/// `reach` voxels around it, and whether it is unknown space.
fn nearest_obstacle(tree: &OccupancyTree, center: Key, reach: i32, unknown_is_obstacle: bool) -> Option<(Key, bool)> {
    let mut nearest: Option<(i32, Key, bool)> = None;
    for dx in -reach..=reach {
        for dy in -reach..=reach {
            for dz in -reach..=reach {
                let distance = dx * dx + dy * dy + dz * dz;
                if nearest.is_some_and(|(d, _, _)| d <= distance) {
                    continue;
                }
                let step = |axis: usize, d: i32| center.0[axis].checked_add_signed(d as i16);
                let (Some(x), Some(y), Some(z)) = (step(0, dx), step(1, dy), step(2, dz)) else {
                    continue; // beyond the edge of the map (3.2 km away at 10 cm voxels)
                };
                let key = Key([x, y, z]);
                // depth 0: the deepest node holding the voxel; `None` where
                // the map has never observed anything
                let (blocked, unknown) = match tree.search(key, 0) {
                    Some(node) => (tree.is_occupied(node.value), false),
                    None => (unknown_is_obstacle, true),
                };
                if blocked {
                    nearest = Some((distance, key, unknown));
                }
            }
        }
    }
    nearest.map(|(_, key, unknown)| (key, unknown))
}
