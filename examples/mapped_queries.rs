//! Saves a map in octolinear's memory-mapped `.olm` format, then opens it
//! and queries it in place, as a program that only reads maps (a planner,
//! a localiser) uses it.
//!
//! ```sh
//! cargo run --release --example mapped_queries [MAP.bt X Y Z]
//! ```
//!
//! With a map (from `build_map` or OctoMap's tools) it writes `MAP.olm`
//! beside it and asks about the position `X Y Z`; without, it builds the
//! map of the bundled `samples/indoor.graph`, writes `indoor.olm` and asks
//! about the first scan's sensor position.
//!
//! Opening an `.olm` file maps it into memory and checks its header only:
//! a map of gigabytes opens at once, its pages are read as queries touch
//! them, and every process that maps the file shares them. `verify` reads
//! the whole file once (every checksum and the tree's structure); after
//! that, every query answers exactly as the in-memory tree the file was
//! written from.

use octolinear::formats::{bt, graph};
use octolinear::{mapped, CastOptions, CastOutcome, Found, KeyBox, MapView, OccupancyTree, Point3, ScanOptions};
use std::io::BufReader;
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (tree, position, output) = match &args[..] {
        [] => {
            let (tree, position) = sample_map()?;
            (tree, position, PathBuf::from("indoor.olm"))
        }
        [path, x, y, z] => {
            let file = std::fs::File::open(path).map_err(|e| format!("{path}: {e}"))?;
            let tree = bt::read(BufReader::new(file)).map_err(|e| format!("{path}: {e}"))?;
            (tree, Point3::new(x.parse()?, y.parse()?, z.parse()?), PathBuf::from(path).with_extension("olm"))
        }
        _ => return Err("usage: mapped_queries [MAP.bt X Y Z]".into()),
    };
    let name = output.display();

    // written atomically: a temporary file renamed into place
    mapped::write_file(&tree, &output).map_err(|e| format!("{name}: {e}"))?;
    println!("{name}: {} bytes for {} nodes", std::fs::metadata(&output)?.len(), tree.size());
    drop(tree);

    let start = Instant::now();
    let map = mapped::open(&output).map_err(|e| format!("{name}: {e}"))?;
    println!("opened in {:?}", start.elapsed());
    let start = Instant::now();
    let report = map.verify().map_err(|e| format!("{name}: {e}"))?;
    println!("verified in {:?}: {} leaves, {} bytes checked", start.elapsed(), report.leaves, report.checked_bytes);

    // the queries of the in-memory tree, on the file's bytes
    let view = map.view();
    let here = state(&view, view.search_point(position, 0)?);
    println!("position ({}, {}, {}): {here}", position.x, position.y, position.z);

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
        .map(|f| match state(&view, *f) {
            "occupied" => '#',
            "free" => '.',
            _ => '?',
        })
        .collect();
    println!("along +y: {line}");

    // leaves in the 1 m cube around the position
    let half = Point3::new(0.5, 0.5, 0.5);
    let bbx = KeyBox { min: view.key(position - half)?, max: view.key(position + half)? };
    let (mut free, mut occupied) = (0, 0);
    for leaf in view.leaves_in_box(bbx, 0) {
        if view.is_occupied(leaf.value) {
            occupied += 1;
        } else {
            free += 1;
        }
    }
    println!("in the 1 m cube around it: {free} free and {occupied} occupied leaves");

    // the first obstacle along +y, as OctoMap's castRay finds it
    let along_y = Point3::new(0.0, 1.0, 0.0);
    match view.cast_ray(position, along_y, CastOptions::default())? {
        CastOutcome::Occupied { end } => println!("first obstacle along +y: {:.2} m away", end.distance(position)),
        other => println!("no obstacle along +y: {other:?}"),
    }
    Ok(())
}

/// What a search answer says about a place.
fn state(view: &MapView, found: Option<Found>) -> &'static str {
    match found {
        None => "unknown",
        Some(node) if view.is_occupied(node.value) => "occupied",
        Some(_) => "free",
    }
}

/// The bundled sample's map, built in memory, and the first scan's sensor
/// position.
fn sample_map() -> Result<(OccupancyTree, Point3), Box<dyn std::error::Error>> {
    let scans = graph::read_file(concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.graph"))?;
    let world: Vec<_> = scans.nodes.iter().map(|node| node.graph2tree()).collect();
    let mut tree = OccupancyTree::new(0.1)?;
    let input = world.iter().map(|(cloud, origin)| (cloud.points.as_slice(), *origin));
    tree.insert_point_clouds(input, &ScanOptions::default(), |_, _| {}).map_err(|(i, e)| format!("scan {i}: {e}"))?;
    Ok((tree, world[0].1))
}
