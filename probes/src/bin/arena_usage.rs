//! Prints the free fraction of arena slots after each scan while building a
//! map from a `.graph` file, then the compaction's time and effect:
//! `cargo run --release -p octolinear-probes --bin arena_usage -- SCANS.graph [RES] [manual]`
//! (`manual`: no automatic compaction during the build).
use octolinear::formats::graph;
use octolinear::{Compaction, OccupancyTree, ScanOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let g = graph::read_file(&args[1])?;
    let mut tree = OccupancyTree::new(args.get(2).map_or(Ok(0.1), |r| r.parse())?)?;
    if args.get(3).is_some_and(|a| a == "manual") {
        tree.set_compaction(Compaction::Manual);
    }
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
