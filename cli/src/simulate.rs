//! `octolinear simulate`: procedural scenes scanned by a spinning lidar.

use super::common::spinner;
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use octolinear::formats::graph;
use octolinear_sim::{simulate, LidarConfig, SceneKind};
use std::path::PathBuf;

#[derive(Clone, Copy, ValueEnum)]
enum Scene {
    Indoor,
    Outdoor,
}

/// Write a `.graph` file of simulated lidar scans (deterministic from the seed).
///
/// Every scan is held in memory until the file is written: a scan casts at
/// most 2^24 rays (beams × steps), all scans together at most 2^28. A scan
/// has one point per ray that hits a surface within range (less the
/// dropout): indoors nearly every ray, outdoors about three in four with
/// `--range inf` (the others see the sky).
///
/// Example: octolinear simulate --scene indoor --scans 16 --seed 1 -o indoor.graph
///
/// Example (the full-size benchmark sequences, `docs/benchmarks.md`):
/// octolinear simulate --scene indoor --scans 64 --beams 64 --steps 1250 -o indoor.graph
/// octolinear simulate --scene outdoor --scans 6 --beams 128 --steps 2048 --range inf -o outdoor.graph
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    #[arg(long, value_enum, default_value = "indoor")]
    scene: Scene,
    /// Number of scans along the trajectory (at least 1).
    #[arg(long, default_value_t = 16)]
    scans: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Vertical channels of the lidar (default 16).
    #[arg(long)]
    beams: Option<u32>,
    /// Firings per revolution (default 360): a scan casts beams × steps rays.
    #[arg(long)]
    steps: Option<u32>,
    /// Maximum range in metres (`inf`: every return, however far; default
    /// 30 indoors, 100 outdoors).
    #[arg(long)]
    range: Option<f64>,
    /// Range noise standard deviation in metres.
    #[arg(long)]
    noise: Option<f64>,
    /// Probability that a return is lost.
    #[arg(long)]
    dropout: Option<f64>,
    /// Output `.graph` file.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    let (kind, mut cfg) = match a.scene {
        Scene::Indoor => (SceneKind::Indoor, LidarConfig::indoor()),
        Scene::Outdoor => (SceneKind::Outdoor, LidarConfig::outdoor()),
    };
    if let Some(b) = a.beams {
        cfg.beams = b;
    }
    if let Some(s) = a.steps {
        cfg.horizontal_steps = s;
    }
    if let Some(r) = a.range {
        cfg.max_range = r;
    }
    if let Some(n) = a.noise {
        cfg.noise_sigma = n;
    }
    if let Some(d) = a.dropout {
        cfg.dropout = d;
    }
    if a.scans == 0 {
        bail!("--scans must be at least 1");
    }
    let phase = spinner(&format!("simulating {} scans", a.scans));
    let g = simulate(kind, a.scans, a.seed, &cfg)?;
    phase.set_message(format!("writing {}", a.output.display()));
    graph::write_file(&g, &a.output).with_context(|| format!("cannot write {}", a.output.display()))?;
    phase.finish_and_clear();
    eprintln!("wrote {} scans, {} points to {}", g.nodes.len(), g.num_points(), a.output.display());
    Ok(())
}
