//! `octolinear` subcommands: one module per tool, all errors reported as
//! one line on stderr with a non-zero exit code.

mod build;
mod common;
mod info;
mod simulate;

use clap::{Parser, Subcommand};

/// OctoMap-compatible 3D occupancy maps: build, inspect, convert and query.
#[derive(Parser)]
#[command(name = "octolinear", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Simulate(simulate::Args),
    Build(build::Args),
    Info(info::Args),
    Convert(info::ConvertArgs),
    Query(info::QueryArgs),
}

/// Runs the tool; returns the process exit code.
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return code;
        }
    };
    let result = match cli.command {
        Command::Simulate(a) => simulate::run(a),
        Command::Build(a) => build::run(a),
        Command::Info(a) => info::run(a),
        Command::Convert(a) => info::convert(a),
        Command::Query(a) => info::query(a),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("octolinear: error: {e:#}");
            1
        }
    }
}
