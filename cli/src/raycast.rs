//! `octolinear raycast`: OctoMap's `castRay` from the command line.

use super::common::{load_map, point_arg};
use anyhow::{bail, Context, Result};
use octolinear::{CastOptions, CastOutcome};
use std::path::PathBuf;

/// Cast one ray through a map (OctoMap's castRay).
///
/// Prints how the ray ended (occupied, max_range, unknown or left_map) and the centre of the last
/// voxel visited.
///
/// Example: octolinear raycast map.bt --origin 0 0 1 --direction 1 0 0 --max-range 10 --json
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    map: PathBuf,
    /// Start of the ray.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true, required = true)]
    origin: Vec<f64>,
    /// Direction (need not be normalised).
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true, required = true)]
    direction: Vec<f64>,
    /// Stop after this distance in metres.
    #[arg(long)]
    max_range: Option<f64>,
    /// Continue through unknown space instead of stopping there.
    #[arg(long)]
    ignore_unknown: bool,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let origin = point_arg(&a.origin, "--origin")?;
    let direction = point_arg(&a.direction, "--direction")?;
    if let Some(r) = a.max_range {
        if !(r.is_finite() && r > 0.0) {
            bail!("--max-range must be a positive finite number, got {r}");
        }
    }
    let tree = load_map(&a.map)?.tree;
    let outcome = tree
        .cast_ray(origin, direction, CastOptions { ignore_unknown: a.ignore_unknown, max_range: a.max_range })
        .context("cannot cast the ray")?;
    let name = match outcome {
        CastOutcome::Occupied { .. } => "occupied",
        CastOutcome::MaxRange { .. } => "max_range",
        CastOutcome::Unknown { .. } => "unknown",
        CastOutcome::LeftMap { .. } => "left_map",
    };
    let end = outcome.end();
    let distance = (end - origin).norm();
    if a.json {
        let out = serde_json::json!({
            "outcome": name, "hit": outcome.hit(),
            "end": [end.x, end.y, end.z], "distance": distance,
        });
        println!("{out}");
    } else {
        println!("{name} at {} {} {} (distance {distance:.4} m)", end.x, end.y, end.z);
    }
    Ok(())
}
