//! Opens a map in octolinear's memory-mapped `.olm` format and asks it what
//! it knows about places: occupied, free or unknown, with the probability
//! of occupancy, and where rays from a position meet the first obstacle.
//! This is how a program that only reads maps (a planner, a localiser)
//! uses one.
//!
//! ```sh
//! cargo run --release --example mapped_queries -- [MAP.olm|MAP.bt|MAP.ot [X Y Z]]
//! ```
//!
//! A `.bt` or `.ot` map (from `build_map` or OctoMap's tools) is first
//! written as an `.olm` file of the same name in the current directory.
//! Without arguments the map is the bundled `samples/indoor.bt` (six scans
//! of a simulated lidar in a corridor, written as `indoor.olm`), and the
//! position `X Y Z` is (0.8, 0, 1), where the first of those scans was
//! taken.
//!
//! Opening an `.olm` file maps it into memory and checks its header only:
//! a map of gigabytes opens at once, its pages are read as queries touch
//! them, and every process that maps the file shares them. `verify` reads
//! the whole file once (every checksum and the tree's structure); after
//! that, every query answers exactly as the in-memory `OccupancyTree` the
//! file was written from, which has the same query methods.
//!
//! A map stores log-odds: `ln(p / (1 - p))` of the probability `p` that a
//! voxel is occupied. `search_point` returns the node that holds a point (a
//! voxel, or a larger node whose voxels all agree) or `None` where nothing
//! was ever observed. `cast_ray` follows a ray voxel by voxel, as OctoMap's
//! `castRay`, until it meets an occupied voxel.

use octolinear::formats::{bt, ot};
use octolinear::sensor::probability;
use octolinear::{mapped, CastOptions, CastOutcome, KeyBox, MapView, Point3};
use std::path::{Path, PathBuf};
use std::time::Instant;

type Error = Box<dyn std::error::Error>;

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (input, position) = match &args[..] {
        [] => (concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.bt"), Point3::new(0.8, 0.0, 1.0)),
        [map] => (map.as_str(), Point3::new(0.8, 0.0, 1.0)),
        [map, x, y, z] => (map.as_str(), Point3::new(x.parse()?, y.parse()?, z.parse()?)),
        _ => return Err("usage: mapped_queries [MAP.olm|MAP.bt|MAP.ot [X Y Z]]".into()),
    };
    let path = olm_file(Path::new(input))?;
    let name = path.display();

    let start = Instant::now();
    let map = mapped::open(&path).map_err(|e| format!("{name}: {e}"))?;
    println!("{name}: {} bytes, opened in {:?}", map.bytes().len(), start.elapsed());
    // Skip this for a file this process wrote or checked before: it reads
    // every byte. Queries on an unchecked damaged file never crash, but
    // may answer wrongly.
    let start = Instant::now();
    let report = map.verify().map_err(|e| format!("{name}: {e}"))?;
    println!("verified in {:?}: {} nodes, {} leaves", start.elapsed(), report.nodes, report.leaves);
    let view = map.view();

    // point queries: the position, and a point far outside what any sensor saw
    let above = Point3::new(position.x, position.y, position.z + 100.0);
    for (what, p) in [("position", position), ("100 m above", above)] {
        println!("{what} ({}, {}, {}): {}", p.x, p.y, p.z, describe(&view, p)?);
    }

    // many points at once: a line of 40 voxels along +y from the position
    // ('.' free, '#' occupied, '?' unknown)
    let res = view.resolution() as f32;
    let keys = (0..40)
        .map(|i| view.key(Point3::new(position.x, position.y + res * i as f32, position.z)))
        .collect::<Result<Vec<_>, _>>()?;
    let mut found = Vec::new();
    view.search_many(&keys, 0, &mut found);
    let line: String = found
        .iter()
        .map(|f| match f {
            None => '?',
            Some(node) if view.is_occupied(node.value) => '#',
            Some(_) => '.',
        })
        .collect();
    println!("along +y: {line}");

    // box query: the leaves in the 1 m cube around the position
    let half = Point3::new(0.5, 0.5, 0.5);
    let cube = KeyBox { min: view.key(position - half)?, max: view.key(position + half)? };
    let (mut free, mut occupied) = (0, 0);
    for leaf in view.leaves_in_box(cube, 0) {
        if view.is_occupied(leaf.value) {
            occupied += 1;
        } else {
            free += 1;
        }
    }
    println!("in the 1 m cube around it: {free} free and {occupied} occupied leaves");

    // ray queries: eight horizontal directions, 20 m at most; unknown
    // space stops a ray unless `ignore_unknown` is set
    let opts = CastOptions { ignore_unknown: false, max_range: Some(20.0) };
    for step in 0..8 {
        let angle = std::f32::consts::FRAC_PI_4 * step as f32;
        let direction = Point3::new(angle.cos(), angle.sin(), 0.0);
        let outcome = match view.cast_ray(position, direction, opts)? {
            CastOutcome::Occupied { end } => format!(
                "hits an occupied voxel at {:.2} m, centred at ({:.2}, {:.2}, {:.2})",
                end.distance(position),
                end.x,
                end.y,
                end.z
            ),
            CastOutcome::Unknown { end } => format!("meets unknown space at {:.2} m", end.distance(position)),
            CastOutcome::MaxRange { .. } => "is free for 20 m".to_string(),
            CastOutcome::LeftMap { .. } => "leaves the map".to_string(),
        };
        println!("ray towards {:>3} degrees {outcome}", 45 * step);
    }
    Ok(())
}

/// The `.olm` file to open: `input` itself, or for a `.bt` or `.ot` map
/// the `.olm` file this writes from it into the current directory.
fn olm_file(input: &Path) -> Result<PathBuf, Error> {
    let name = input.display();
    let tree = match input.extension().and_then(|e| e.to_str()) {
        Some("olm") => return Ok(input.to_path_buf()),
        Some("bt") => bt::read_file(input).map_err(|e| format!("{name}: {e}"))?,
        Some("ot") => ot::read_file(input)
            .map_err(|e| format!("{name}: {e}"))?
            .into_occupancy()
            .ok_or_else(|| format!("{name}: the map holds hit counts, not occupancy"))?,
        _ => return Err(format!("{name}: the map's name must end in .olm, .bt or .ot").into()),
    };
    let output = PathBuf::from(input.file_stem().unwrap_or_default()).with_extension("olm");
    // written atomically: a temporary file renamed into place
    mapped::write_file(&tree, &output).map_err(|e| format!("{}: {e}", output.display()))?;
    println!("{} written from {name}", output.display());
    Ok(output)
}

/// What the map knows about the place of `p`.
fn describe(view: &MapView, p: Point3) -> Result<String, Error> {
    // depth 0: the deepest node that holds the point
    Ok(match view.search_point(p, 0)? {
        None => "unknown".to_string(),
        Some(node) => format!(
            "{} (p = {:.3}, a node of depth {}, {} m wide)",
            if view.is_occupied(node.value) { "occupied" } else { "free" },
            probability(f64::from(node.value)),
            node.depth,
            view.key_space().node_size(node.depth)
        ),
    })
}
