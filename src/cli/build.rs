//! `octolinear build`: OctoMap's `graph2tree` — integrate the scans of a
//! `.graph` file into a map.

use super::common::{progress, save_map, MapFormat};
use super::input;
use anyhow::{bail, Context, Result};
use octolinear::formats::graph;
use octolinear::formats::{bt, ot, write_atomically};
use octolinear::scan::OutOfMap;
use octolinear::sensor::{SensorModel, SensorProbabilities};
use octolinear::{BoundsRule, InnerNodes, NodeKind, OccupancyTree, Point3, Pose6D, ScanGraph, ScanOptions, ScanReport};
use std::path::PathBuf;
use std::time::Instant;

/// Build a map from a `.graph` file (like OctoMap's graph2tree) or point cloud files.
///
/// Input is a `.graph` file, or point cloud files (--points: .ply, .pcd, .las, .laz, .xyz), one
/// scan per file, each taken from a sensor pose (--pose for all files, or
/// one line `x y z roll pitch yaw` per file in --trajectory; identity by
/// default). Points are in the sensor frame; rays start at the pose.
///
/// `.ot` output is the full probabilistic tree, `.bt` the compact
/// maximum-likelihood tree; both are byte-identical to what OctoMap writes.
/// `.olm` output is the full tree in octolinear's memory-mapped format.
///
/// With --color the map is a ColorOcTree, built as OctoMap users do: per
/// scan insertPointCloud, then integrateNodeColor for every point in file
/// order, and updateInnerOccupancy once at the end (inner colours are the
/// average of their children). Colours come from PLY red/green/blue vertex
/// properties and PCD rgb/rgba fields; every --points file must have them.
/// Without --color, colours in the files are ignored. Colour maps are
/// written as .ot (id ColorOcTree) or .olm; .bt cannot hold colours.
///
/// Example: octolinear build scans.graph -o map.bt --res 0.05 --max-range 20
///
/// Example: octolinear build --points a.ply b.pcd --trajectory traj.txt -o map.bt
///
/// Example: octolinear build --points room.ply --color -o room.ot
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// Input `.graph` file (OctoMap ScanGraph).
    #[arg(required_unless_present = "points", conflicts_with = "points")]
    input: Option<PathBuf>,
    /// Point cloud files, one scan each (.ply, .pcd, .las, .laz, .xyz).
    #[arg(long, num_args = 1.., value_name = "FILE")]
    points: Vec<PathBuf>,
    /// Sensor pose of every --points file.
    #[arg(long, num_args = 6, allow_negative_numbers = true, conflicts_with = "trajectory",
          value_names = ["X", "Y", "Z", "ROLL", "PITCH", "YAW"], requires = "points")]
    pose: Option<Vec<f64>>,
    /// Text file with one pose `x y z roll pitch yaw` per --points file.
    #[arg(long, requires = "points")]
    trajectory: Option<PathBuf>,
    /// Output map, `.bt` or `.ot`.
    #[arg(short, long)]
    output: PathBuf,
    /// Voxel edge length in metres.
    #[arg(long, default_value_t = 0.1)]
    res: f64,
    /// Cut rays at this range (metres); their end points are not marked occupied.
    #[arg(long)]
    max_range: Option<f64>,
    /// Merge end points per voxel before casting rays.
    #[arg(long)]
    discretize: bool,
    /// Update ray by ray (OctoMap's insertPointCloudRays) instead of per-scan key sets.
    #[arg(long)]
    simple: bool,
    /// Only insert the first N scans.
    #[arg(long, value_name = "N")]
    scans: Option<usize>,
    /// Miss and hit probabilities.
    #[arg(long, num_args = 2, value_names = ["MISS", "HIT"])]
    sensor: Option<Vec<f64>>,
    /// Clamping probabilities.
    #[arg(long, num_args = 2, value_names = ["MIN", "MAX"])]
    clamping: Option<Vec<f64>>,
    /// Convert to maximum likelihood and prune after each scan.
    #[arg(long)]
    compress_ml: bool,
    /// Threads for ray casting (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// End points outside the map: `octomap` (what OctoMap does: no key, no
    /// update; with --discretize they wrap around), `skip` (drop and count
    /// them) or `error` (refuse the scan).
    #[arg(long, value_enum, default_value = "octomap")]
    out_of_map: OutOfMapArg,
    /// Build a colour map (ColorOcTree) from the colours of the --points
    /// files (PLY red/green/blue, PCD rgb/rgba); output .ot or .olm.
    #[arg(long)]
    color: bool,
    /// Print the statistics as one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum OutOfMapArg {
    Octomap,
    Skip,
    Error,
}

/// Sensor model as graph2tree sets it: OctoMap's defaults read back from a
/// fresh tree, overridden by the flags, then set again.
fn sensor_model(a: &Args) -> Result<SensorModel> {
    let mut p = SensorModel::default().probabilities();
    p.occupancy_threshold = 0.5;
    if let Some(c) = &a.clamping {
        (p.clamping_min, p.clamping_max) = (c[0], c[1]);
        if !(0.0..=1.0).contains(&c[0]) || !(0.0..=1.0).contains(&c[1]) || c[0] >= c[1] {
            bail!("clamping values must satisfy 0 <= MIN < MAX <= 1, got {} {}", c[0], c[1]);
        }
    }
    if let Some(s) = &a.sensor {
        (p.miss, p.hit) = (s[0], s[1]);
        if !(0.0..=1.0).contains(&s[0]) || !(0.0..=1.0).contains(&s[1]) || s[0] >= s[1] {
            bail!("sensor model must satisfy 0 <= MISS < HIT <= 1, got {} {}", s[0], s[1]);
        }
    }
    Ok(SensorModel::from_probabilities(&SensorProbabilities { ..p })?)
}

/// graph2tree's `outputStatistics`, as numbers.
fn statistics(tree: &OccupancyTree) -> serde_json::Value {
    let sensor = tree.sensor();
    let thresholded = tree.nodes(0).filter(|n| sensor.is_at_threshold(n.value)).count();
    let size = tree.bounds(BoundsRule::CenterHalfSize).size();
    serde_json::json!({
        "nodes": tree.size(),
        "leaves": tree.num_leaves(),
        "nodes_thresholded": thresholded,
        "nodes_other": tree.size() - thresholded,
        "octomap_memory_bytes": tree.octomap_memory_usage(),
        "memory_bytes": tree.memory_usage(),
        "full_grid_bytes": tree.memory_full_grid(BoundsRule::CenterHalfSize),
        "metric_size": size,
    })
}

fn print_statistics(title: &str, s: &serde_json::Value) {
    let mb = |b: &serde_json::Value| b.as_f64().unwrap_or(0.0) / (1024.0 * 1024.0);
    println!("{title}\n===========================");
    println!(
        "Tree size: {} nodes ({} leafs). {} nodes thresholded, {} other",
        s["nodes"], s["leaves"], s["nodes_thresholded"], s["nodes_other"]
    );
    println!(
        "Memory: {} byte ({:.6} MB) as OctoMap counts it; octolinear holds {} byte ({:.6} MB)",
        s["octomap_memory_bytes"],
        mb(&s["octomap_memory_bytes"]),
        s["memory_bytes"],
        mb(&s["memory_bytes"])
    );
    println!("Full grid: {} byte ({:.6} MB)", s["full_grid_bytes"], mb(&s["full_grid_bytes"]));
    let m = &s["metric_size"];
    println!("Size: {} x {} x {} m^3\n", m[0], m[1], m[2]);
}

/// The `--points` files as a scan graph, each with its pose, and with
/// --color each scan's colours.
fn point_files(a: &Args) -> Result<(ScanGraph, Vec<input::Colors>)> {
    let poses = match (&a.pose, &a.trajectory) {
        (Some(p), _) => vec![input::pose(p)?; a.points.len()],
        (None, Some(t)) => {
            let poses = input::read_trajectory(t)?;
            if poses.len() != a.points.len() {
                bail!("{} has {} poses for {} --points files", t.display(), poses.len(), a.points.len());
            }
            poses
        }
        (None, None) => vec![Pose6D::IDENTITY; a.points.len()],
    };
    let mut g = ScanGraph::new();
    let mut colors = Vec::new();
    for (path, pose) in a.points.iter().zip(poses) {
        let scan = input::read_scan(path, a.color)?;
        if a.color {
            let c = scan.colors.with_context(|| {
                format!(
                    "{}: --color needs colours (PLY red/green/blue, PCD rgb or rgba), this file has none",
                    path.display()
                )
            })?;
            colors.push(c);
        }
        g.add_node(scan.cloud, pose);
    }
    Ok((g, colors))
}

/// `integrateNodeColor(x, y, z, r, g, b)` for every point, in order: points
/// outside the map or without a node are skipped, as OctoMap's returns NULL.
fn integrate_colors(tree: &mut OccupancyTree, points: &[Point3], colors: &[[u8; 3]]) {
    for (p, rgb) in points.iter().zip(colors) {
        if let Ok(k) = tree.key(*p) {
            tree.integrate_color(k, *rgb);
        }
    }
}

pub fn run(a: Args) -> Result<()> {
    let format = MapFormat::of(&a.output)?;
    let sensor = sensor_model(&a)?;
    if a.color && a.input.is_some() {
        bail!("--color needs --points files with colours (a .graph file has none)");
    }
    if a.color && format == MapFormat::Bt {
        bail!("{}: a colour map needs .ot or .olm output (.bt holds no colours)", a.output.display());
    }
    let kind = if a.color { NodeKind::Color } else { NodeKind::Plain };
    let mut tree = OccupancyTree::with_kind(a.res, sensor, kind)?;
    if a.threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    if let Some(r) = a.max_range {
        if !r.is_finite() {
            bail!("--max-range must be a finite number, got {r}");
        }
    }
    let (mut g, mut colors, input) = match &a.input {
        Some(input) => (
            graph::read_file(input).with_context(|| format!("cannot read {}", input.display()))?,
            Vec::new(),
            input.display().to_string(),
        ),
        None => {
            let (g, colors) = point_files(&a)?;
            (g, colors, format!("{} point files", a.points.len()))
        }
    };
    let n = a.scans.unwrap_or(g.nodes.len()).min(g.nodes.len());
    let points: usize = g.nodes[..n].iter().map(|s| s.scan.points.len()).sum();
    let opts = ScanOptions {
        max_range: a.max_range,
        discretize: a.discretize,
        inner: InnerNodes::Update,
        bbx: None,
        out_of_map: match a.out_of_map {
            OutOfMapArg::Octomap => OutOfMap::OctoMap,
            OutOfMapArg::Skip => OutOfMap::Skip,
            OutOfMapArg::Error => OutOfMap::Error,
        },
        threads: a.threads,
    };
    let bar = progress(n as u64, "inserting scans");
    let (mut non_finite, mut skipped_out_of_map, start) = (0, 0, Instant::now());
    g.nodes.truncate(n);
    colors.truncate(n);
    let mut after_each = |tree: &mut OccupancyTree, report: ScanReport| {
        non_finite += report.non_finite;
        skipped_out_of_map += report.out_of_map;
        if a.compress_ml {
            tree.to_max_likelihood();
            tree.prune();
        }
        bar.inc(1);
    };
    if a.simple || a.color {
        // scan by scan: colours are blended in after each scan's occupancy
        let mut colors = colors.into_iter();
        for mut node in std::mem::take(&mut g.nodes) {
            let (cloud, origin) = node.graph2tree();
            node.scan = Default::default(); // release each scan once transformed
            let report = if a.simple {
                tree.insert_point_cloud_rays(&cloud.points, origin, InnerNodes::Update)
            } else {
                tree.insert_point_cloud(&cloud.points, origin, &opts).with_context(|| format!("scan {}", node.id))?
            };
            if let Some(c) = colors.next() {
                integrate_colors(&mut tree, &cloud.points, &c);
            }
            after_each(&mut tree, report);
        }
    } else {
        // scan by scan, each released once transformed; with several
        // threads the following scans are cast while one is applied
        let ids: Vec<_> = g.nodes.iter().map(|node| node.id).collect();
        let scans = std::mem::take(&mut g.nodes).into_iter().map(|node| {
            let (cloud, origin) = node.graph2tree();
            (cloud.points, origin)
        });
        tree.insert_point_clouds(scans, &opts, after_each)
            .map_err(|(i, e)| anyhow::Error::new(e).context(format!("scan {}", ids[i])))?;
    }
    if a.color {
        // inner nodes: maximum occupancy and average colour of their children
        tree.update_inner_occupancy();
    }
    let seconds = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    // one tree throughout (no copies): peak memory is the tree, compacted
    // in place, plus a scan's key sets
    tree.compact();
    let full = statistics(&tree);
    if format != MapFormat::Bt {
        save_map(&tree, &a.output)?;
    }
    tree.to_max_likelihood();
    tree.prune();
    tree.compact();
    let ml_stats = statistics(&tree);
    if format == MapFormat::Bt {
        // already maximum likelihood and pruned: what writeBinary writes
        write_atomically(&a.output, |w| bt::write_const(&tree, w))
            .with_context(|| format!("cannot write {}", a.output.display()))?;
    }
    if a.json {
        let out = serde_json::json!({
            "input": input, "output": a.output, "tree_type": ot::TreeKind::of(kind).id(),
            "scans": n, "points": points,
            "non_finite_points_skipped": non_finite,
            "out_of_map_points_skipped": skipped_out_of_map,
            "insert_seconds": seconds,
            "points_per_second": points as f64 / seconds.max(1e-12),
            "tree": full, "max_likelihood_tree": ml_stats,
        });
        println!("{out}");
    } else {
        println!("Data points in graph: {points} ({n} scans)");
        if non_finite > 0 {
            println!("Skipped {non_finite} points with NaN or infinite coordinates");
        }
        if skipped_out_of_map > 0 {
            println!("Skipped {skipped_out_of_map} points outside the map");
        }
        println!("time to insert scans: {seconds} sec");
        println!("time to insert 100.000 points took: {} sec (avg)\n", seconds / (points as f64 / 100000.0));
        print_statistics("Pruned tree (lossless compression)", &full);
        print_statistics("Pruned max-likelihood tree (lossy compression)", &ml_stats);
        println!("Map written to {}", a.output.display());
    }
    Ok(())
}
