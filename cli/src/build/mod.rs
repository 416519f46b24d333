//! `octolinear build`: OctoMap's `graph2tree` — integrate the scans of a
//! `.graph` file into a map.

mod grouped;

use super::common::{format_g6, progress, save_map, spinner, MapFormat};
use super::input;
use super::plan;
use super::tiles;
use anyhow::{bail, Context, Result};
use octolinear::formats::atomic::ScratchDir;
use octolinear::formats::bt::MaxLikelihood;
use octolinear::formats::{bt, ot, write_atomically};
use octolinear::geometry::graph2tree_transform;
use octolinear::scan::OutOfMap;
use octolinear::sensor::{SensorModel, SensorProbabilities};
use octolinear::tiles::{Beyond, BuildInput, BuildRecord, Manifest, MemoryBudget, SetLock, TaskPart, TiledMap, Window};
use octolinear::tree::{PreorderSource, Summarize, Tee, TreeSummary};
use octolinear::{InnerNodes, KeySpace, NodeKind, OccupancyTree, Point3, PointCloud, Pose6D, ScanOptions, ScanReport};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Build a map from a `.graph` file (like OctoMap's graph2tree) or point cloud files.
///
/// Input is a `.graph` file (`-` for standard input; pipes and FIFOs are
/// read as they stream, one scan at a time), or point cloud files
/// (--points: .ply, .pcd, .las, .laz, .xyz; a name without extension, such
/// as `-` or a pipe, is recognised by its first bytes), one scan per file,
/// each taken from a sensor pose (--pose for all files, or one line
/// `x y z roll pitch yaw` per file in --trajectory; identity by default).
/// Points are in the sensor frame; rays start at the pose.
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
/// Points that cannot go into the map (NaN or infinite coordinates,
/// outside the map's ±32768 voxels) and an input without points are
/// reported as warnings on stderr, with counts.
///
/// Example: octolinear build scans.graph -o map.bt --res 0.05 --max-range 20
///
/// Example: cat scans.graph | octolinear build - -o map.bt
///
/// Example: octolinear build --points a.ply b.pcd --trajectory traj.txt -o map.bt
///
/// With an output NAME.tiles (a directory), the map is written as a tile
/// set (formats/tiles.md): the octree's subtrees at --tile-depth, one .olm
/// file each, and a manifest. `octolinear convert NAME.tiles OUT` gives the
/// bytes a plain build to OUT gives. --task K/N builds only some tiles so
/// that N processes can share the work: with --plan PLAN (from `octolinear
/// plan`) task K builds a range of tiles of about an N-th of the estimated
/// work and casts only the rays reaching it; without, tiles are shared by
/// a hash and each task casts every scan. Once all have finished, `octolinear
/// tiles manifest NAME.tiles` writes the manifest. With --memory-cap the
/// map is the same, built within that memory: from a `.graph` file, in
/// groups of neighbouring tiles that fit it together with a scan's update
/// for them, each built from every scan (read again from the file,
/// casting only the rays that reach the group) and written out (into the
/// tile set, or beside OUT in a temporary directory), one group per
/// thread at a time, each thread within its share of the cap; from
/// standard input or point files, scan by scan, the tiles not used lately
/// written out and read back when scans reach them again (a whole scan's
/// update is held besides). An .ot or .bt output is then written tile by
/// tile, never as one tree; an .olm output, laid out as a whole, merges
/// the tiles into one tree in memory at the end. Tiles cannot hold colour
/// maps, and --compress-ml (OctoMap's prune() stops at the first level
/// where nothing merged, a decision over the whole map) is not offered
/// with them.
///
/// Example: octolinear build --points room.ply --color -o room.ot
///
/// Example: octolinear build scans.graph -o map.tiles --tile-depth 8 --memory-cap 2G
///
/// Example: octolinear build scans.graph -o map.tiles --tile-depth 8 --task 0/4 --plan map.plan
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// Input `.graph` file (OctoMap ScanGraph); `-` reads standard input.
    #[arg(required_unless_present = "points", conflicts_with = "points")]
    input: Option<PathBuf>,
    /// Point cloud files, one scan each (.ply, .pcd, .las, .laz, .xyz or
    /// .txt; without extension, by content; `-` reads standard input).
    #[arg(long, num_args = 1.., value_name = "FILE")]
    points: Vec<PathBuf>,
    /// Sensor pose of every --points file.
    #[arg(long, num_args = 6, allow_negative_numbers = true, conflicts_with = "trajectory",
          value_names = ["X", "Y", "Z", "ROLL", "PITCH", "YAW"], requires = "points")]
    pose: Option<Vec<f64>>,
    /// Text file with one pose `x y z roll pitch yaw` per --points file.
    #[arg(long, requires = "points")]
    trajectory: Option<PathBuf>,
    /// Output map: `.bt` (maximum likelihood, as graph2tree writes it),
    /// `.ot` (full tree) or `.olm` (full tree, memory-mapped format).
    #[arg(short, long)]
    output: PathBuf,
    /// Voxel edge length in metres; the map spans ±32768 voxels around the
    /// origin on each axis.
    #[arg(long, default_value_t = 0.1)]
    res: f64,
    /// Cut rays at this range (metres, positive; leave it out for no limit,
    /// graph2tree's `-m -1`); their end points are not marked occupied.
    #[arg(long)]
    max_range: Option<f64>,
    /// Merge end points per voxel before casting rays.
    #[arg(long)]
    discretize: bool,
    /// Update ray by ray (OctoMap's insertPointCloudRays) instead of per-scan key sets.
    #[arg(long)]
    simple: bool,
    /// Only insert the first N scans (at least 1).
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
    /// Threads for ray casting (1 to 1024; default: all cores).
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
    /// Depth of the tiles' roots (1 to 15) for a tile set output, a
    /// --memory-cap or a --forget-beyond build [default: 8]. A tile is
    /// res * 2^(16-D) metres a side (25.6 m at 0.1 m and depth 8); aim for
    /// tiles that each hold thousands of nodes or more (a few MB of tree
    /// where scans map densely, tens of metres a side): every tile file
    /// costs a few hundred bytes beyond its nodes, and each step deeper
    /// makes up to 8x more tiles. The bundled indoor sample holds its map's
    /// bytes in 6 tiles at depth 8, 1.4x them in 799 at depth 13, and 15x
    /// them in 22,853 files at depth 15; a build warns when a set's tile
    /// files hold more than twice the merged map's .olm bytes (estimated
    /// from its nodes) and over 256 KiB more.
    #[arg(long, value_name = "D")]
    tile_depth: Option<u8>,
    /// Build only the tiles of task K of N (0 <= K < N) into a NAME.tiles
    /// output; `octolinear tiles manifest` combines the tasks' parts.
    #[arg(long, value_name = "K/N")]
    task: Option<String>,
    /// With --task: build the range of tiles the plan file (from
    /// `octolinear plan`) gives task K, casting only the rays that reach
    /// it; the plan's resolution, tile depth and task count must match.
    #[arg(long, value_name = "PLAN", requires = "task")]
    plan: Option<PathBuf>,
    /// Build within SIZE bytes of tiles and scan updates (e.g. 64M, 2G; K,
    /// M, G are powers of 1024); the rest waits on disk. The output is the
    /// same (.ot and .bt written tile by tile; .olm merged in memory).
    #[arg(long, value_name = "SIZE")]
    memory_cap: Option<String>,
    /// After each scan, forget the tiles lying wholly farther than METRES
    /// from its origin (a map that moves with the robot). A departure from
    /// OctoMap: the output is no longer OctoMap's map of the input, whose
    /// far tiles become unknown space. Builds tiled (see --tile-depth).
    #[arg(long, value_name = "METRES")]
    forget_beyond: Option<f64>,
}

/// Tile depth of tiled builds without --tile-depth: tiles of 25.6 m at
/// 0.1 m, a few MB of tree each where scans map densely.
const DEFAULT_TILE_DEPTH: u8 = 8;

/// How a tiled build runs, from the flags.
struct Tiling {
    depth: u8,
    task: Option<TaskPart>,
    memory_cap: Option<usize>,
    window: Option<Window>,
    /// The plan's identity ([`octolinear::tiles::TilePlan::identity`]).
    plan: Option<u32>,
}

/// The tiling the flags ask for; `None` for a plain build.
fn tiling(a: &Args, tile_output: bool) -> Result<Option<Tiling>> {
    if !tile_output && a.tile_depth.is_none() && a.memory_cap.is_none() && a.forget_beyond.is_none() {
        if a.task.is_some() {
            bail!("--task builds part of a tile set: the output must be NAME.tiles");
        }
        return Ok(None);
    }
    let plan = a.plan.as_deref().map(plan::read_plan).transpose()?;
    let depth = match (&plan, a.tile_depth) {
        (Some(p), Some(d)) if d != p.depth => {
            bail!("--tile-depth {d} does not match the plan's tile depth {} ({})", p.depth, plan_name(a))
        }
        (Some(p), _) => p.depth,
        (None, d) => d.unwrap_or(DEFAULT_TILE_DEPTH),
    };
    if !(1..=octolinear::tiles::MAX_TILE_DEPTH).contains(&depth) {
        bail!("--tile-depth must be between 1 and 15, got {depth}");
    }
    if a.color {
        bail!("colour maps cannot be tiled (--color with a tile set, --tile-depth or --memory-cap)");
    }
    if a.compress_ml {
        bail!("--compress-ml cannot be tiled: OctoMap's prune() decides level by level over the whole map");
    }
    let mut task = a.task.as_deref().map(tiles::task_arg).transpose()?;
    if let (Some(p), Some(t)) = (&plan, task) {
        if p.resolution != a.res {
            bail!("--res {:?} does not match the plan's resolution {:?} ({})", a.res, p.resolution, plan_name(a));
        }
        if p.tasks.len() != t.count as usize {
            bail!(
                "--task {}/{} does not match the plan's {} tasks ({})",
                t.index,
                t.count,
                p.tasks.len(),
                plan_name(a)
            );
        }
        task = Some(p.task(t.index)?);
    }
    if task.is_some() && !tile_output {
        bail!("--task builds part of a tile set: the output must be NAME.tiles");
    }
    let memory_cap = a.memory_cap.as_deref().map(tiles::size_arg).transpose()?;
    let window = match a.forget_beyond {
        Some(r) if !(r.is_finite() && r >= 0.0) => {
            bail!("--forget-beyond: expected a distance >= 0 in metres, got {r}")
        }
        Some(radius) => Some(Window { radius, beyond: Beyond::Drop }),
        None => None,
    };
    let plan = plan.as_ref().map(octolinear::tiles::TilePlan::identity);
    Ok(Some(Tiling { depth, task, memory_cap, window, plan }))
}

/// What a tiled build records in its manifest: the options that change
/// the rays or the values, the `.graph` input's identity, the plan's.
fn build_record(a: &Args, t: &Tiling, max_range: Option<f64>) -> Result<BuildRecord> {
    let input = a.input.as_deref().map(BuildInput::of_path).transpose()?;
    Ok(BuildRecord {
        rays: a.simple,
        forget_beyond: t.window.filter(|w| w.beyond == Beyond::Drop).map(|w| w.radius),
        scans: a.scans.map(|n| n as u64),
        input,
        plan: t.plan,
        ..BuildRecord::new(&scan_options(a, max_range))
    })
}

/// The --plan file as messages name it.
fn plan_name(a: &Args) -> String {
    a.plan.as_deref().map_or_else(String::new, |p| p.display().to_string())
}

/// A temporary directory for the tiles a capped build writes out: the
/// library's [`ScratchDir`] `.OUT.spill-<pid>` beside the output, removed
/// when dropped, on SIGINT, SIGTERM, SIGHUP and SIGQUIT, and (after a
/// SIGKILL) by the next build or write to the same output.
struct SpillDir(PathBuf, Option<ScratchDir>);

impl SpillDir {
    /// The scratch directory beside `output`, created now; where that
    /// fails, the writer's own creation of the directory reports why.
    fn beside(output: &Path) -> Self {
        match ScratchDir::beside(output) {
            Ok(dir) => SpillDir(dir.path().to_path_buf(), Some(dir)),
            Err(_) => {
                let name = output.file_name().map_or_else(|| "map".into(), |n| n.to_string_lossy().into_owned());
                SpillDir(output.with_file_name(format!(".{name}.spill-{}", std::process::id())), None)
            }
        }
    }
}

impl Drop for SpillDir {
    fn drop(&mut self) {
        if self.1.take().is_none() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
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

/// Writes the map `tree` to `output` in `format`, and returns the
/// statistics of the full and of the maximum-likelihood tree, from the
/// tree as built: converting, pruning and compacting it in place cost
/// twice the walks below on a large map.
fn write_tree(tree: &OccupancyTree, format: MapFormat, output: &Path) -> Result<(Value, Value)> {
    let phase = spinner(&format!("writing {}", output.display()));
    let stats = if format == MapFormat::Olm {
        save_map(tree, output)?;
        // the maximum-likelihood tree's statistics from its `.bt` records,
        // as for the other formats
        let ml = bt::write_map(tree, std::io::sink()).and_then(|mut ml| ml.summary(tree));
        let ml = ml.context("cannot gather the maximum-likelihood statistics")?;
        Ok((statistics(tree), summary_statistics(&ml)))
    } else {
        write_walked(tree, format, output, None)
    };
    phase.finish_and_clear();
    stats
}

/// Writes a tree, a tiled map or a tile set to `output` (`.ot` or `.bt`)
/// without changing or merging it: one walk (across the tiles) writes the
/// file and gathers the full tree's statistics, and the
/// maximum-likelihood tree's come from its `.bt` records; they equal those
/// of the tree converted and pruned. With `scratch` (a directory), the
/// records wait there, not in memory.
fn write_walked<M: PreorderSource>(
    map: &M,
    format: MapFormat,
    output: &Path,
    scratch: Option<&Path>,
) -> Result<(Value, Value)> {
    let scratch = scratch.map(scratch_file).transpose()?;
    let mut full = Summarize::new(map);
    let mut ml = None;
    let written = match format {
        MapFormat::Ot => {
            let mut records = match scratch {
                Some(file) => MaxLikelihood::with_scratch(map, file),
                None => MaxLikelihood::new(map),
            };
            write_atomically(output, |w| ot::write_map_observed(map, w, &mut Tee(&mut full, &mut records)))
                .and_then(|()| records.finish(map))
        }
        _ => write_atomically(output, |w| {
            ml = Some(match scratch {
                Some(file) => bt::write_map_observed_with_scratch(map, w, &mut full, file)?,
                None => bt::write_map_observed(map, w, &mut full)?,
            });
            Ok(())
        })
        .map(|()| ml.take().expect("written")),
    };
    let summary = written.and_then(|mut ml| ml.summary(map));
    let ml = summary.with_context(|| format!("cannot write {}", output.display()))?;
    Ok((summary_statistics(&full.finish()), summary_statistics(&ml)))
}

/// A new file in `dir` for records that wait on disk, removed at once (it
/// lives while open).
pub(super) fn scratch_file(dir: &Path) -> Result<std::fs::File> {
    let path = dir.join(format!("records-{}", std::process::id()));
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create_new(true)
        .open(&path)
        .with_context(|| format!("cannot create {}", path.display()))?;
    let _ = std::fs::remove_file(&path);
    Ok(file)
}

/// [`statistics`] from a [`TreeSummary`]: the same numbers, with memory as
/// the tree would hold it once compacted.
fn summary_statistics(s: &TreeSummary) -> Value {
    serde_json::json!({
        "nodes": s.nodes,
        "leaves": s.leaves,
        "nodes_thresholded": s.at_threshold,
        "nodes_other": s.nodes - s.at_threshold,
        "octomap_memory_bytes": s.octomap_memory_usage(),
        "memory_bytes": s.compacted_memory_usage(),
        "full_grid_bytes": s.memory_full_grid(),
        "metric_size": s.bounds.size(),
    })
}

/// graph2tree's `outputStatistics`, as numbers (the node count is
/// OctoMap's `size()` counter, as graph2tree prints it).
fn statistics(tree: &OccupancyTree) -> serde_json::Value {
    let mut stats = summary_statistics(&tree.summary());
    stats["nodes"] = tree.size().into();
    stats["nodes_other"] = (tree.size() as u64 - stats["nodes_thresholded"].as_u64().unwrap_or(0)).into();
    stats
}

/// Prints statistics as graph2tree does (numbers at C++ stream precision 6,
/// without the binary noise of the full double), with the bytes
/// octolinear holds beside OctoMap's figure.
fn print_statistics(title: &str, s: &serde_json::Value) {
    let mb = |b: &serde_json::Value| format_g6(b.as_f64().unwrap_or(0.0) / (1024.0 * 1024.0));
    println!("{title}\n===========================");
    println!(
        "Tree size: {} nodes ({} leafs). {} nodes thresholded, {} other",
        s["nodes"], s["leaves"], s["nodes_thresholded"], s["nodes_other"]
    );
    println!(
        "Memory: {} byte ({} MB) as OctoMap counts it; octolinear holds {} byte ({} MB)",
        s["octomap_memory_bytes"],
        mb(&s["octomap_memory_bytes"]),
        s["memory_bytes"],
        mb(&s["memory_bytes"])
    );
    println!("Full grid: {} byte ({} MB)", s["full_grid_bytes"], mb(&s["full_grid_bytes"]));
    let m: Vec<String> = (0..3).map(|i| format_g6(s["metric_size"][i].as_f64().unwrap_or(f64::NAN))).collect();
    println!("Size: {} x {} x {} m^3\n", m[0], m[1], m[2]);
}

/// Most `--threads`: more only share the cores, each with its stack.
const MAX_THREADS: usize = 1024;

/// Checks a `--res` value by the library's rule
/// ([`octolinear::key::check_resolution`]).
pub(super) fn resolution_arg(res: f64) -> Result<f64> {
    octolinear::key::check_resolution(res).map_err(|e| anyhow::anyhow!("--res: {e}"))
}

/// Checks a `--max-range` value: positive and finite, as for `raycast`;
/// no limit is said by leaving the flag out (graph2tree's `-m -1` and
/// OctoMap's negative `maxrange`).
pub(super) fn max_range_arg(range: Option<f64>) -> Result<Option<f64>> {
    match range {
        Some(r) if !(r.is_finite() && r > 0.0) => {
            bail!("--max-range must be a positive finite number of metres, got {r} (leave it out for no limit)")
        }
        r => Ok(r),
    }
}

/// Checks a `--scans` value: at least one scan.
pub(super) fn scans_arg(scans: Option<usize>) -> Result<Option<usize>> {
    if scans == Some(0) {
        bail!("--scans must be at least 1 (leave it out for every scan)");
    }
    Ok(scans)
}

/// The insertion options the flags ask for.
fn scan_options(a: &Args, max_range: Option<f64>) -> ScanOptions {
    let out_of_map = match a.out_of_map {
        OutOfMapArg::Octomap => OutOfMap::OctoMap,
        OutOfMapArg::Skip => OutOfMap::Skip,
        OutOfMapArg::Error => OutOfMap::Error,
    };
    ScanOptions::default()
        .with_max_range(max_range)
        .with_discretize(a.discretize)
        .with_out_of_map(out_of_map)
        .with_threads(a.threads)
}

/// A warning on stderr, in the form of the errors.
fn warn(message: &str) {
    eprintln!("octolinear: warning: {message}");
}

/// One scan ready to insert: world-frame points, sensor origin, and with
/// --color the points' colours.
struct Scan {
    id: u32,
    points: PointCloud,
    origin: Point3,
    colors: Option<input::Colors>,
}

/// Scans, read one at a time as insertion asks for them.
type Scans<'a> = Box<dyn Iterator<Item = Result<Scan>> + Send + 'a>;

/// The `--points` files as scans, each with its pose, each read when its
/// turn comes.
fn point_files(a: &Args) -> Result<Scans<'_>> {
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
    if a.points.iter().filter(|p| p.as_os_str() == "-").count() > 1 {
        bail!("--points names standard input (-) more than once");
    }
    input::check_read_once(&a.points, "--points")?;
    let scans = a.points.iter().zip(poses).enumerate().map(|(i, (path, pose))| {
        let scan = input::read_scan(path, a.color)?;
        let colors = if a.color {
            Some(scan.colors.with_context(|| {
                format!(
                    "{}: --color needs colours (PLY red/green/blue, PCD rgb or rgba), this file has none",
                    input::name(path)
                )
            })?)
        } else {
            None
        };
        let (points, origin) = graph2tree_transform(&pose, &scan.cloud);
        Ok(Scan { id: i as u32, points, origin, colors })
    });
    Ok(Box::new(scans))
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

/// Inserts scan by scan, each applied before the next is read: OctoMap's
/// insertPointCloudRays with `simple`, else insertPointCloud; colours are
/// blended in after each scan's occupancy.
fn insert_one_by_one(
    tree: &mut OccupancyTree,
    scans: impl Iterator<Item = Scan>,
    simple: bool,
    opts: &ScanOptions,
    mut after_each: impl FnMut(&mut OccupancyTree, ScanReport),
) -> Result<()> {
    for scan in scans {
        let report = if simple {
            tree.insert_point_cloud_rays(&scan.points.points, scan.origin, InnerNodes::Update)
        } else {
            tree.insert_point_cloud(&scan.points.points, scan.origin, opts)
                .with_context(|| format!("scan {}", scan.id))?
        };
        if let Some(c) = &scan.colors {
            integrate_colors(tree, &scan.points.points, c);
        }
        after_each(tree, report);
    }
    Ok(())
}

/// Inserts scans into a tiled map: ray by ray with `simple`, else with
/// per-scan sets, the next scan cast while one is applied; `tick` after
/// each scan.
fn insert_tiled(
    map: &mut TiledMap,
    scans: impl Iterator<Item = Scan> + Send,
    simple: bool,
    opts: &ScanOptions,
    tick: impl Fn() + Send + Sync,
) -> Result<(), (usize, octolinear::tiles::TileError)> {
    if simple {
        for (i, scan) in scans.enumerate() {
            map.insert_point_cloud_rays(&scan.points.points, scan.origin, InnerNodes::Update).map_err(|e| (i, e))?;
            tick();
        }
        return Ok(());
    }
    map.insert_point_clouds(scans.map(|scan| (scan.points.points, scan.origin)), opts, |_, _| tick())
}

/// Writes a tiled build's tile set (or its task's part) and reports it.
fn finish_tile_set(a: &Args, map: &mut TiledMap, input: &str, inserted: (usize, usize, f64)) -> Result<()> {
    let phase = spinner(&format!("writing {}", a.output.display()));
    let manifest = map.flush(&a.output)?;
    if manifest.task.is_none() {
        octolinear::tiles::remove_unlisted_tiles(&a.output, &manifest)?;
    }
    phase.finish_and_clear();
    print_tile_set(a, &manifest, map.stats().nodes, input, inserted)
}

/// Reports a tile set written (or a task's part): what went in, where it
/// went, `nodes` in the single tree.
fn print_tile_set(
    a: &Args,
    manifest: &Manifest,
    nodes: u64,
    input: &str,
    (scans, points, seconds): (usize, usize, f64),
) -> Result<()> {
    let bytes: u64 = manifest.tiles.iter().map(|t| t.bytes).sum();
    if let Some(over) = octolinear::tiles::oversize(manifest, nodes).filter(|_| manifest.task.is_none()) {
        warn(&format!("{}: {over} (see build --help, --tile-depth)", a.output.display()));
    }
    if a.json {
        let out = serde_json::json!({
            "input": input, "output": a.output, "tree_type": manifest.kind.id(),
            "scans": scans, "points": points, "insert_seconds": seconds,
            "tile_depth": manifest.depth, "tiles": manifest.tiles.len(), "tile_bytes": bytes,
            "task": manifest.task.map(|t| [t.index, t.count]),
            "nodes": if manifest.task.is_none() { Some(nodes) } else { None },
        });
        println!("{out}");
        return Ok(());
    }
    println!("Data points in graph: {points} ({scans} scans)");
    println!("time to insert scans: {seconds} sec");
    match manifest.task {
        Some(t) => println!(
            "Tiles of task {} of {} written to {} ({} tiles, {bytes} bytes); once every task is done, run: octolinear tiles manifest {}",
            t.index,
            t.count,
            a.output.display(),
            manifest.tiles.len(),
            a.output.display()
        ),
        None => println!(
            "Map written to {} ({} tiles at depth {}, {bytes} bytes; {nodes} nodes merged)",
            a.output.display(),
            manifest.tiles.len(),
            manifest.depth
        ),
    }
    Ok(())
}

/// What went into the map, counted as the scans stream past.
#[derive(Default)]
struct Tally {
    /// Ids of the scans handed to insertion, in order.
    ids: Vec<u32>,
    points: usize,
    /// Finite points without a key in the map.
    out_of_map: usize,
    /// Points with a NaN or infinite coordinate (never inserted).
    non_finite: usize,
}

impl Tally {
    fn count(&mut self, scan: &Scan, keys: &KeySpace) {
        self.ids.push(scan.id);
        self.points += scan.points.len();
        // blocks of points that all have keys (nearly always all of them)
        // are passed in one vectorised test
        for block in scan.points.points.chunks(1024).filter(|block| !keys.contains_all(block)) {
            for &p in block {
                if !p.is_finite() {
                    self.non_finite += 1;
                } else if keys.key(p).is_err() {
                    self.out_of_map += 1;
                }
            }
        }
    }

    /// Warnings for what the map lacks: no scans, no points, points that
    /// could not be placed.
    fn warn(&self, a: &Args, input: &str, announced: usize) {
        let scans = self.ids.len();
        if let Some(asked) = a.scans.filter(|&s| s > announced) {
            warn(&format!("--scans {asked} asks for more than the {announced} scans of {input}; all were inserted"));
        }
        if scans == 0 {
            warn(&format!("{input} holds no scans: the map is empty"));
        } else if self.points == 0 {
            warn(&format!("the {scans} scans of {input} hold no points: the map is empty"));
        }
        if self.non_finite > 0 {
            warn(&format!(
                "{} of {} points have NaN or infinite coordinates and were skipped",
                self.non_finite, self.points
            ));
        }
        if self.out_of_map > 0 {
            let what = match a.out_of_map {
                OutOfMapArg::Octomap if a.discretize => {
                    "wrapped around to the other side of the map, as OctoMap's discretized insertion does"
                }
                OutOfMapArg::Octomap => "were not marked and cast no ray (beyond a --max-range cut), as in OctoMap",
                OutOfMapArg::Skip | OutOfMapArg::Error => "were skipped (--out-of-map skip)",
            };
            warn(&format!(
                "{} of {} points lie outside the map, which spans ±{:?} m at --res {:?}; they {what}",
                self.out_of_map,
                self.points,
                32768.0 * a.res,
                a.res
            ));
        }
    }
}

/// The input as messages name it.
fn input_name(a: &Args) -> String {
    match &a.input {
        Some(path) => input::name(path),
        None => format!("{} point files", a.points.len()),
    }
}

pub fn run(a: Args) -> Result<()> {
    let tile_output = tiles::is_tile_set(&a.output);
    // a tile set is written by its own path below; `format` then only
    // passes the checks that concern other outputs
    let format = if tile_output { MapFormat::Ot } else { MapFormat::from_path(&a.output)? };
    let sensor = sensor_model(&a)?;
    if a.color && a.input.is_some() {
        bail!("--color needs --points files with colours (a .graph file has none)");
    }
    if a.color && format == MapFormat::Bt {
        bail!("{}: a colour map needs .ot or .olm output (.bt holds no colours)", a.output.display());
    }
    resolution_arg(a.res)?;
    let max_range = max_range_arg(a.max_range)?;
    scans_arg(a.scans)?;
    if a.threads.is_some_and(|t| !(1..=MAX_THREADS).contains(&t)) {
        bail!("--threads must be between 1 and {MAX_THREADS}, got {}", a.threads.unwrap_or_default());
    }
    let kind = if a.color { NodeKind::Color } else { NodeKind::Plain };
    let mut tree = OccupancyTree::with_kind(a.res, sensor, kind)?;
    let tiling = tiling(&a, tile_output)?;
    // one build at a time writes a set (a task's beside other tasks'),
    // from before the first tile to after the manifest
    let _set_lock = match (&tiling, tile_output) {
        (Some(Tiling { task: Some(task), .. }), true) => Some(SetLock::acquire_task(&a.output, *task)?),
        (_, true) => Some(SetLock::acquire(&a.output)?),
        (_, false) => None,
    };
    if let Some(t) = tiling.as_ref().filter(|t| grouped::applies(&a, t)) {
        return grouped::run(&a, t, sensor, format, tile_output);
    }
    let mut spill_dir = None;
    let mut tiled = match &tiling {
        Some(t) => {
            let mut map = TiledMap::new(a.res, sensor, kind, t.depth)?;
            if let Some(task) = t.task {
                map.set_task(task);
            }
            if let Some(bytes) = t.memory_cap {
                let dir = if tile_output {
                    a.output.clone()
                } else {
                    let spill = SpillDir::beside(&a.output);
                    let dir = spill.0.clone();
                    spill_dir = Some(spill);
                    dir
                };
                map.set_budget(MemoryBudget { bytes, dir })?;
            }
            map.set_window(t.window)?;
            map.set_build_record(build_record(&a, t, max_range)?);
            Some(map)
        }
        None => None,
    };
    let input = input_name(&a);
    let mut graph = a.input.as_deref().map(input::open_graph).transpose()?;
    let (announced, source): (usize, Scans<'_>) = match graph.as_mut() {
        Some(reader) => {
            let announced = reader.announced() as usize;
            let scans = reader.by_ref().map(|node| {
                let node = node.with_context(|| format!("cannot read {input}"))?;
                let id = node.id;
                let (points, origin) = node.into_graph2tree();
                Ok(Scan { id, points, origin, colors: None })
            });
            (announced, Box::new(scans))
        }
        None => (a.points.len(), point_files(&a)?),
    };
    let n = a.scans.map_or(announced, |s| s.min(announced));
    let opts = scan_options(&a, max_range);
    let bar = progress(n as u64, "inserting scans");
    let (keys, mut tally, mut failure, start) = (KeySpace::new(a.res), Tally::default(), None, Instant::now());
    let mut reading = Duration::ZERO;
    let after_each = |tree: &mut OccupancyTree, _: ScanReport| {
        if a.compress_ml {
            tree.to_max_likelihood();
            tree.prune();
        }
        bar.inc(1);
    };
    // the first read error ends the scans; it is reported once those before
    // it are in (nothing is written then)
    let mut source = source.take(n);
    let (failure_slot, counted, read_time) = (&mut failure, &mut tally, &mut reading);
    let scans = std::iter::from_fn(move || {
        if failure_slot.is_some() {
            return None;
        }
        let started = Instant::now();
        let scan = source.next();
        *read_time += started.elapsed();
        match scan? {
            Ok(scan) => {
                counted.count(&scan, &keys);
                Some(scan)
            }
            Err(e) => {
                *failure_slot = Some(e);
                None
            }
        }
    });
    let inserted = if let Some(map) = tiled.as_mut() {
        insert_tiled(map, scans, a.simple, &opts, || bar.inc(1))
            .map_err(|(i, e)| anyhow::Error::new(e).context(format!("scan {}", tally.ids[i])))
    } else if a.simple || a.color {
        insert_one_by_one(&mut tree, scans, a.simple, &opts, after_each)
    } else {
        // with several threads the following scans are cast while one is applied
        tree.insert_point_clouds(scans.map(|scan| (scan.points.points, scan.origin)), &opts, after_each)
            .map_err(|(i, e)| anyhow::Error::new(e).context(format!("scan {}", tally.ids[i])))
    };
    bar.finish_and_clear();
    // a scan refused comes before one that could not be read
    inserted?;
    if let Some(e) = failure {
        return Err(e);
    }
    if let Some(reader) = graph.filter(|_| n == announced) {
        // every scan was taken: the rest of the file must be well-formed too
        reader.edges().with_context(|| format!("cannot read {input}"))?;
    }
    if a.color {
        // inner nodes: maximum occupancy and average colour of their children
        let phase = spinner("updating inner nodes");
        tree.update_inner_occupancy();
        phase.finish_and_clear();
    }
    let (seconds, read_seconds) = (start.elapsed().as_secs_f64(), reading.as_secs_f64());
    tally.warn(&a, &input, announced);
    let (scans, points) = (tally.ids.len(), tally.points);
    let (full, ml_stats) = match tiled {
        Some(mut map) if tile_output => return finish_tile_set(&a, &mut map, &input, (scans, points, seconds)),
        Some(map) if format != MapFormat::Olm => {
            // the tiles walked one at a time, straight into the file
            let phase = spinner(&format!("writing {} from the tiles", a.output.display()));
            let stats = write_walked(&map, format, &a.output, spill_dir.as_ref().map(|d| d.0.as_path()))?;
            phase.finish_and_clear();
            drop(map);
            drop(spill_dir);
            stats
        }
        Some(map) => {
            // .olm lays out the whole tree (its levels and counts ahead of
            // the nodes): the tiles are merged first
            let phase = spinner("merging the tiles");
            tree = map.merge()?;
            phase.finish_and_clear();
            drop(map);
            drop(spill_dir);
            write_tree(&tree, format, &a.output)?
        }
        None => write_tree(&tree, format, &a.output)?,
    };
    print_build(&a, kind, &input, &tally, (seconds, read_seconds), (&full, &ml_stats));
    Ok(())
}

/// Reports a map built: what went in, graph2tree's statistics of the full
/// and of the maximum-likelihood tree, where it went.
fn print_build(
    a: &Args,
    kind: NodeKind,
    input: &str,
    tally: &Tally,
    (seconds, read_seconds): (f64, f64),
    (full, ml_stats): (&Value, &Value),
) {
    let (scans, points) = (tally.ids.len(), tally.points);
    if a.json {
        let out = serde_json::json!({
            "input": input, "output": a.output, "tree_type": ot::TreeKind::of(kind).id(),
            "scans": scans, "points": points,
            "non_finite_points_skipped": tally.non_finite,
            "out_of_map_points": tally.out_of_map,
            "insert_seconds": seconds, "read_seconds": read_seconds,
            "points_per_second": points as f64 / seconds.max(1e-12),
            "tree": full, "max_likelihood_tree": ml_stats,
        });
        println!("{out}");
    } else {
        println!("Data points in graph: {points} ({scans} scans)");
        println!("time to insert scans: {seconds} sec");
        println!("time to read them, included above (scans are read as they are inserted): {read_seconds} sec");
        println!("time to insert 100.000 points took: {} sec (avg)\n", seconds / (points as f64 / 100000.0));
        print_statistics("Pruned tree (lossless compression)", full);
        print_statistics("Pruned max-likelihood tree (lossy compression)", ml_stats);
        println!("Map written to {}", a.output.display());
    }
}
