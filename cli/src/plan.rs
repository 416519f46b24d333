//! `octolinear plan`: split a tile set's tiles into tasks of even
//! estimated work, for `build --task K/N --plan PLAN` on several machines.

use super::build::{max_range_arg, resolution_arg, scans_arg};
use super::input;
use anyhow::{bail, Context, Result};
use octolinear::formats::write_atomically;
use octolinear::tiles::{TilePlan, TileWork, MAX_TASKS, MAX_TILE_DEPTH};
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Plan a tile set built by several processes: tasks owning balanced
/// ranges of tiles.
///
/// Reads the scans of a `.graph` file (`-` for standard input) and
/// estimates the insertion work each tile at --tile-depth costs, in ray
/// steps and voxel updates (a coarse
/// pass, a small part of a build; scans of more than 16384 points are
/// sampled), then cuts the tiles, in Morton order, into --tasks contiguous
/// ranges of about equal work. Each task of a `build --task K/N --plan
/// PLAN` builds the tiles of its range and casts only the rays that reach
/// them, so the rays are shared rather than each cast N times. The ranges
/// cover every tile, whatever the estimate saw, so the map is exact; the
/// estimate only decides how even the tasks are. Give the options of the
/// build that change the rays (--res, --max-range, --discretize,
/// --scans): the build checks --res and --tile-depth against the plan.
///
/// Prints the tasks (a table, or JSON with --json); -o writes the plan
/// file (formats/tiles.md, "Plan file").
///
/// Example: octolinear plan scans.graph --tile-depth 8 --tasks 4 -o map.plan
///
/// Example: octolinear build scans.graph -o map.tiles --tile-depth 8 --task 2/4 --plan map.plan
#[derive(clap::Args)]
pub struct Args {
    /// Input `.graph` file (OctoMap ScanGraph); `-` reads standard input.
    input: PathBuf,
    /// Depth of the tiles' roots (1 to 15), as the build's --tile-depth.
    #[arg(long, value_name = "D")]
    tile_depth: u8,
    /// Number of tasks (1 to 8^D, at most 65536).
    #[arg(long, value_name = "N")]
    tasks: u32,
    /// Voxel edge length in metres, as the build's.
    #[arg(long, default_value_t = 0.1)]
    res: f64,
    /// Cut rays at this range (metres), as the build's --max-range.
    #[arg(long)]
    max_range: Option<f64>,
    /// End points merged per voxel before casting, as the build's.
    #[arg(long)]
    discretize: bool,
    /// Only the first N scans, as the build's --scans.
    #[arg(long, value_name = "N")]
    scans: Option<usize>,
    /// Write the plan file here.
    #[arg(short, long, value_name = "PLAN")]
    output: Option<PathBuf>,
    /// Print the plan as one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(a: Args) -> Result<()> {
    resolution_arg(a.res)?;
    let max_range = max_range_arg(a.max_range)?;
    let scans = scans_arg(a.scans)?.unwrap_or(usize::MAX);
    if !(1..=MAX_TILE_DEPTH).contains(&a.tile_depth) {
        bail!("--tile-depth must be between 1 and 15, got {}", a.tile_depth);
    }
    let most = (1u64 << (3 * u32::from(a.tile_depth))).min(u64::from(MAX_TASKS));
    if a.tasks == 0 || u64::from(a.tasks) > most {
        bail!(
            "--tasks must be between 1 and {most} (the tiles at depth {}, at most {MAX_TASKS} tasks), got {}",
            a.tile_depth,
            a.tasks
        );
    }
    let name = input::name(&a.input);
    let mut work = TileWork::new(a.res, a.tile_depth)?;
    let mut reader = input::open_graph(&a.input)?;
    let mut count = 0;
    for node in reader.by_ref().take(scans) {
        let node = node.with_context(|| format!("cannot read {name}"))?;
        let (cloud, origin) = node.into_graph2tree();
        work.add(&cloud.points, origin, max_range, a.discretize);
        count += 1;
    }
    let plan = work.split(a.tasks)?;
    if let Some(path) = &a.output {
        let text = plan.to_text();
        write_atomically(path, |w| w.write_all(text.as_bytes()))
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    let total: u64 = plan.tasks.iter().map(|t| t.work).sum();
    if a.json {
        let tasks: Vec<_> = plan
            .tasks
            .iter()
            .enumerate()
            .map(|(i, t)| {
                serde_json::json!({
                    "task": i, "prefix_start": t.prefixes.start, "prefix_end": t.prefixes.end,
                    "tiles": t.tiles, "work": t.work,
                })
            })
            .collect();
        let out = serde_json::json!({
            "input": name, "scans": count, "resolution": plan.resolution, "tile_depth": plan.depth,
            "work": total, "tasks": tasks, "output": a.output,
        });
        println!("{out}");
        return Ok(());
    }
    let edge = a.res * f64::from(1u32 << (16 - u32::from(a.tile_depth)));
    println!(
        "{} tasks over the tiles of depth {} ({edge} m a side) of {name} ({count} scans, {total} units of estimated work, in ray steps)",
        plan.tasks.len(),
        plan.depth,
    );
    println!("{:>6}  {:>25}  {:>7}  {:>12}  {:>6}", "task", "tile prefixes", "tiles", "work", "share");
    for (i, t) in plan.tasks.iter().enumerate() {
        let share = if total == 0 { 0.0 } else { 100.0 * t.work as f64 / total as f64 };
        let range = format!("{}..{}", t.prefixes.start, t.prefixes.end);
        println!("{i:>6}  {range:>25}  {:>7}  {:>12}  {share:>5.1}%", t.tiles, t.work);
    }
    if let Some(path) = &a.output {
        println!("Plan written to {}", path.display());
    }
    Ok(())
}

/// Reads a plan file (a regular file, [`TilePlan::read`]); its errors
/// name the file and line.
pub fn read_plan(path: &Path) -> Result<TilePlan> {
    TilePlan::read(path).with_context(|| format!("cannot read the plan {}", path.display()))
}
