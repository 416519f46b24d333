//! The `octolinear` command-line tool: one module per subcommand, all
//! errors reported as one line on stderr with a non-zero exit code.

mod binvox;
mod build;
mod common;
mod compare;
mod edit;
mod eval;
mod info;
mod input;
mod log2graph;
mod mesh;
mod plan;
mod points;
mod raycast;
mod render;
mod simulate;
mod tiles;

use clap::{Parser, Subcommand};

/// OctoMap-compatible 3D occupancy maps: build, inspect, convert, query, compare, edit, evaluate and render.
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
    Verify(info::VerifyArgs),
    Compare(compare::Args),
    Crop(edit::CropArgs),
    Edit(edit::Args),
    ToPoints(points::Args),
    Eval(eval::Args),
    Log2graph(log2graph::Args),
    Binvox(binvox::Args),
    Raycast(raycast::Args),
    Render(render::Args),
    Mesh(mesh::Args),
    Tiles(tiles::Args),
    Plan(plan::Args),
}

/// Restores the default SIGPIPE action so that `octolinear ... | head`
/// ends quietly like other command-line tools instead of panicking in
/// `println!` (Rust ignores SIGPIPE by default), and has Ctrl-C, SIGTERM,
/// SIGHUP and SIGQUIT remove the temporary files of writes in progress
/// before the signal ends the process.
#[cfg(unix)]
fn set_signal_actions() {
    // SAFETY: signal() with a valid signal number and the default
    // disposition; called before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // fails only for invalid signal numbers; a failure would only lose the
    // cleanup, which the next write to the same file makes up for
    let _ = octolinear::formats::atomic::remove_temp_files_on_signals();
}

#[cfg(not(unix))]
fn set_signal_actions() {}

fn main() {
    limit_heap_retention();
    std::process::exit(run());
}

/// glibc raises its mmap threshold whenever a large block is freed, after
/// which big arrays come from the heap and freed space stays resident; a
/// fixed threshold keeps large buffers (the largest key sets, arenas) in
/// their own mappings, returned to the system when freed and grown in
/// place. Below it, a scan's buffers (its points, its sets and lists: about
/// a megabyte each on a 64-beam lidar) come from the heap, whose freed top
/// is kept up to a limit: returned at once, every scan's buffers were new
/// pages to fault in again (a sixth of a full-size indoor build's time).
fn limit_heap_retention() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        const M_TRIM_THRESHOLD: libc::c_int = -1;
        const M_MMAP_THRESHOLD: libc::c_int = -3;
        // SAFETY: mallopt only adjusts allocator tuning; called before any
        // other thread exists.
        unsafe {
            libc::mallopt(M_MMAP_THRESHOLD, 4 << 20);
            libc::mallopt(M_TRIM_THRESHOLD, 16 << 20);
        }
    }
}

/// Returns the allocator's free pages to the system, in every arena (the
/// worker threads' too, which keep theirs otherwise): between the groups
/// of a capped build, the memory of the group done.
pub(crate) fn trim_heap() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only releases free memory the allocator holds;
    // it takes the allocator's own locks.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Runs the tool; returns the process exit code.
fn run() -> i32 {
    set_signal_actions();
    common::report_truncated_files();
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
        Command::Verify(a) => info::verify(a),
        Command::Compare(a) => compare::run(a),
        Command::Crop(a) => edit::run_crop(a),
        Command::Edit(a) => edit::run(a),
        Command::ToPoints(a) => points::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Log2graph(a) => log2graph::run(a),
        Command::Binvox(a) => binvox::run(a),
        Command::Raycast(a) => raycast::run(a),
        Command::Render(a) => render::run(a),
        Command::Mesh(a) => mesh::run(a),
        Command::Tiles(a) => tiles::run(a),
        Command::Plan(a) => plan::run(a),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("octolinear: error: {}", error_line(&e));
            1
        }
    }
}

/// An error and its causes on one line, `: `-separated, outermost first.
/// The library's errors do not repeat their cause (an I/O error, a key
/// error) in their own message but give it as `source()`, so each cause
/// appears once.
fn error_line(e: &anyhow::Error) -> String {
    format!("{e:#}")
}

#[cfg(test)]
mod tests {
    use super::error_line;
    use anyhow::Context;

    #[test]
    fn an_error_line_names_each_cause_once() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("x.bt");
        let e = octolinear::formats::bt::read_file(&missing).context("cannot read x.bt").unwrap_err();
        let line = error_line(&e);
        assert!(line.starts_with("cannot read x.bt: I/O error: "), "{line}");
        assert_eq!(line.matches("os error 2").count(), 1, "{line}");
        let e = anyhow::anyhow!("inner").context("outer");
        assert_eq!(error_line(&e), "outer: inner");
    }
}
