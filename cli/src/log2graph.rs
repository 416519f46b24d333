//! `octolinear log2graph`: OctoMap's `log2graph`.

use super::common::write_output;
use anyhow::{Context, Result};
use octolinear::formats::{graph, log};
use std::path::PathBuf;

/// Convert a plain-text scan log into a `.graph` file (OctoMap's log2graph).
///
/// The log has `NODE x y z roll pitch yaw` lines, each followed by `x y z`
/// points. The output is byte for byte what log2graph writes, except node
/// ids, which log2graph leaves uninitialised (we number them 0, 1, 2...).
///
/// Example: octolinear log2graph scans.log scans.graph
#[derive(clap::Args)]
pub struct Args {
    /// Input log (text).
    input: PathBuf,
    /// Output `.graph` file.
    output: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    let file = std::fs::File::open(&a.input).with_context(|| format!("cannot open {}", a.input.display()))?;
    let g = log::read(std::io::BufReader::with_capacity(1 << 16, file))
        .with_context(|| format!("{}: not a valid scan log", a.input.display()))?;
    write_output(&a.output, |w| graph::write(&g, w))?;
    eprintln!("wrote {} scans, {} points to {}", g.nodes.len(), g.num_points(), a.output.display());
    Ok(())
}
