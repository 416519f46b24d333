//! Prints arena slot usage while building a map from a `.graph` file:
//! `cargo run --release --example arena_usage -- SCANS.graph RES`.
use octolinear::formats::graph;
use octolinear::{OccupancyTree, ScanOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let g = graph::read_file(&args[1])?;
    let mut tree = OccupancyTree::new(args.get(2).map_or(Ok(0.1), |r| r.parse())?)?;
    let t = std::time::Instant::now();
    for node in &g.nodes {
        let (cloud, origin) = node.graph2tree();
        tree.insert_point_cloud(&cloud.points, origin, &ScanOptions::default())?;
        let u = tree.arena_usage().expect("not empty");
        print!("{:.2} ", u.free_slots as f64 / (u.live_slots + u.free_slots) as f64);
    }
    println!("\ninsert {:?}", t.elapsed());
    let u = tree.arena_usage().expect("not empty");
    println!(
        "nodes {} live slots {} free slots {} bytes reserved {}",
        tree.size(),
        u.live_slots,
        u.free_slots,
        u.bytes_reserved
    );
    let t = std::time::Instant::now();
    tree.compact();
    println!("compact {:?}", t.elapsed());
    let u = tree.arena_usage().expect("not empty");
    println!(
        "after compact: live {} free {} bytes {} ({:.2} B/node)",
        u.live_slots,
        u.free_slots,
        u.bytes_reserved,
        u.bytes_reserved as f64 / tree.size() as f64
    );
    Ok(())
}
