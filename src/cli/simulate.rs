//! `octolinear simulate`: procedural scenes scanned by a spinning lidar.

use anyhow::{Context, Result};
use clap::ValueEnum;
use octolinear::formats::graph;
use octolinear::simulate::{simulate, LidarConfig, SceneKind};
use std::path::PathBuf;

#[derive(Clone, Copy, ValueEnum)]
enum Scene {
    Indoor,
    Outdoor,
}

/// Write a `.graph` file of simulated lidar scans (deterministic from the seed).
///
/// Example: octolinear simulate --scene indoor --scans 16 --seed 1 -o indoor.graph
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    #[arg(long, value_enum, default_value = "indoor")]
    scene: Scene,
    /// Number of scans along the trajectory.
    #[arg(long, default_value_t = 16)]
    scans: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Vertical channels of the lidar.
    #[arg(long)]
    beams: Option<u32>,
    /// Firings per revolution.
    #[arg(long)]
    steps: Option<u32>,
    /// Maximum range in metres.
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
    let g = simulate(kind, a.scans, a.seed, &cfg)?;
    graph::write_file(&g, &a.output).with_context(|| format!("cannot write {}", a.output.display()))?;
    eprintln!("wrote {} scans, {} points to {}", g.nodes.len(), g.num_points(), a.output.display());
    Ok(())
}
