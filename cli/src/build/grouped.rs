//! `build --memory-cap` from a `.graph` file: the tile set built group by
//! group ([`GroupedBuild`]), each group from every scan read again from
//! the file, so that memory holds one group's tiles and a scan's update
//! for them, not a whole scan's update beside the tiles; with several
//! threads, as many groups at once.

use super::{
    input_name, print_build, print_tile_set, scan_options, write_tree, write_walked, Args, SpillDir, Tally, Tiling,
};
use crate::common::{progress, spinner, MapFormat};
use anyhow::{Context, Result};
use octolinear::formats::graph::GraphFile;
use octolinear::sensor::SensorModel;
use octolinear::tiles::{GroupedBuild, GroupedError, TileSet, TileWork};
use octolinear::{KeySpace, NodeKind, Point3};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// True when the build can be grouped: a memory cap over a whole tile set
/// (no task, no forgetting), per-scan sets, and a `.graph` file that can
/// be read again (not standard input or a pipe).
pub(super) fn applies(a: &Args, t: &Tiling) -> bool {
    t.memory_cap.is_some()
        && t.task.is_none()
        && t.window.is_none()
        && !a.simple
        && a.input.as_deref().is_some_and(|p| p.as_os_str() != "-" && p.is_file())
}

/// The scans of the `.graph` input, `n` of them at most, read again from
/// the start of the file opened first; the time spent reading is added to
/// `reading`.
fn read_scans<'a>(
    file: &'a GraphFile,
    input: &'a str,
    n: usize,
    reading: &'a Mutex<Duration>,
) -> impl Iterator<Item = Result<(Vec<Point3>, Point3)>> + 'a {
    let (reader, failed) = match file.reader() {
        Ok(r) => (Some(r), None),
        Err(e) => (None, Some(Err(anyhow::Error::new(e).context(format!("cannot read {input}"))))),
    };
    let mut nodes = reader.into_iter().flatten().take(n);
    let scans = std::iter::from_fn(move || {
        let started = Instant::now();
        let node = nodes.next();
        *reading.lock().unwrap_or_else(|e| e.into_inner()) += started.elapsed();
        Some(node?.with_context(|| format!("cannot read {input}")).map(|node| {
            let (points, origin) = node.into_graph2tree();
            (points.points, origin)
        }))
    });
    failed.into_iter().chain(scans)
}

/// Builds the map group by group into a tile set (the output's, or a
/// temporary one beside the output), then writes the output from it.
pub(super) fn run(a: &Args, t: &Tiling, sensor: SensorModel, format: MapFormat, tile_output: bool) -> Result<()> {
    let max_range = super::max_range_arg(a.max_range)?;
    let opts = scan_options(a, max_range);
    let input = input_name(a);
    let started = Instant::now();

    // one pass: the scans counted and their work per tile estimated
    let phase = spinner("estimating the tiles' work");
    // every pass reads this file, whatever its path names later
    let path = a.input.as_deref().expect("a grouped build reads a .graph file");
    let file = GraphFile::open(path).with_context(|| format!("cannot open {input}"))?;
    let mut reader = file.reader().with_context(|| format!("cannot read {input}"))?;
    let announced = reader.announced() as usize;
    let n = a.scans.map_or(announced, |s| s.min(announced));
    let (keys, mut tally) = (KeySpace::new(a.res), Tally::default());
    let mut work = TileWork::new(a.res, t.depth)?;
    for node in reader.by_ref().take(n) {
        let node = node.with_context(|| format!("cannot read {input}"))?;
        let id = node.id;
        let (points, origin) = node.into_graph2tree();
        let scan = super::Scan { id, points, origin, colors: None };
        tally.count(&scan, &keys);
        work.add(&scan.points.points, origin, max_range, a.discretize);
    }
    if n == announced {
        // every scan is taken: the rest of the file must be well-formed too
        reader.edges().with_context(|| format!("cannot read {input}"))?;
    }
    phase.finish_and_clear();

    let spill = (!tile_output).then(|| SpillDir::beside(&a.output));
    let dir = spill.as_ref().map_or_else(|| a.output.clone(), |s| s.0.clone());
    let build = GroupedBuild {
        resolution: a.res,
        sensor,
        memory: t.memory_cap.expect("a grouped build has a cap"),
        dir: dir.clone(),
        record: Some(super::build_record(a, t, max_range)?),
    };
    let bar = progress(n as u64, "inserting scans");
    let reading = Mutex::new(Duration::ZERO);
    let latest = AtomicUsize::new(0);
    let built = build.build(
        &work,
        &opts,
        || read_scans(&file, &input, n, &reading),
        |group, done| {
            if latest.fetch_max(group + 1, Ordering::Relaxed) < group + 1 {
                // a group done has freed its trees and sets: return them
                crate::trim_heap();
                bar.set_message(format!("inserting scans, tile group {}", group + 1));
            }
            bar.set_position(done as u64);
        },
    );
    bar.finish_and_clear();
    let report = built.map_err(|e| match e {
        GroupedError::Scan { index, source } => anyhow::Error::new(source)
            .context(format!("scan {}", tally.ids.get(index).copied().unwrap_or(index as u32))),
        GroupedError::Input(e) => e,
        GroupedError::Tiles(e) => e.into(),
    })?;
    let seconds = started.elapsed().as_secs_f64();
    tally.warn(a, &input, announced);
    if tile_output {
        octolinear::tiles::remove_unlisted_tiles(&a.output, &report.manifest)?;
        let set = TileSet::open(&a.output)?;
        return print_tile_set(a, &report.manifest, set.node_count(), &input, (tally.ids.len(), tally.points, seconds));
    }
    let set = TileSet::open(&dir)?;
    let (full, ml) = if format == MapFormat::Olm {
        // .olm lays out the whole tree: the tiles are merged first
        let phase = spinner("merging the tiles");
        let tree = set.merge()?;
        phase.finish_and_clear();
        write_tree(&tree, format, &a.output)?
    } else {
        // the tiles walked one at a time, straight into the file
        let phase = spinner(&format!("writing {} from the tiles", a.output.display()));
        let stats = write_walked(&set, format, &a.output, Some(&dir))?;
        phase.finish_and_clear();
        stats
    };
    drop(set);
    drop(spill);
    let read_seconds = reading.into_inner().unwrap_or_else(|e| e.into_inner()).as_secs_f64();
    print_build(a, NodeKind::Plain, &input, &tally, (seconds, read_seconds), (&full, &ml));
    Ok(())
}
