//! Tile sets from Python (formats/tiles.md): `build_tiles` (what `octolinear
//! build IN -o OUT.tiles --tile-depth D [--task K/N]` does),
//! `write_tile_manifest` (`octolinear tiles manifest`), `convert_tiles`
//! (`octolinear convert MAP.tiles OUT`) and `plan_tiles`, the building blocks
//! of builds shared by many processes (`octolinear.dask`).

use crate::convert;
use crate::files::{build_options, graph_error, graph_scans, sensor_model};
use octolinear::formats::{bt, graph, ot, write_atomically, MapFormat};
use octolinear::tiles::{
    read_manifest, remove_unlisted_tiles, BuildInput, BuildRecord, GroupedBuild, GroupedError, Manifest, SetLock,
    TaskPart, TileError, TilePlan, TileSet, TileWork, TiledMap, MANIFEST_FILE, MAX_TASKS, PLAN_MAGIC,
};
use octolinear::{NodeKind, Point3, TreeKind};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::Path;
use std::time::Instant;

/// A tile error as the matching Python exception: `OSError` for I/O
/// (`NotADirectoryError` for a set's path that is a file), `ValueError`
/// for anything else (damaged tiles, bad manifests, refused scans, a
/// directory that cannot hold a set, a set another build holds), the file
/// in the message.
fn tile_error(e: TileError) -> PyErr {
    match e {
        TileError::Io { path, source } => convert::io_error(&path, &source),
        e @ TileError::NotADirectory { .. } => pyo3::exceptions::PyNotADirectoryError::new_err(e.to_string()),
        other => PyValueError::new_err(other.to_string()),
    }
}

/// An I/O error of a file writer walking a tile set: the tile error inside
/// when a tile could not be read, else the error on `path`.
fn walk_error(path: &Path, e: std::io::Error) -> PyErr {
    if e.get_ref().is_some_and(|inner| inner.is::<TileError>()) {
        let inner = e.into_inner().expect("checked above").downcast::<TileError>().expect("checked above");
        return tile_error(*inner);
    }
    convert::io_error(path, &e)
}

/// Checks the arguments shared by `build_tiles` and `plan_tiles`.
fn check_build_arguments(tile_depth: u8, max_range: Option<f64>, scans: Option<usize>) -> PyResult<()> {
    if !(1..=octolinear::tiles::MAX_TILE_DEPTH).contains(&tile_depth) {
        return Err(PyValueError::new_err(format!("tile_depth must be between 1 and 15, got {tile_depth}")));
    }
    if let Some(r) = max_range.filter(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(PyValueError::new_err(format!(
            "max_range must be a positive finite number of metres, got {r} (None for no limit)"
        )));
    }
    if scans == Some(0) {
        return Err(PyValueError::new_err("scans must be at least 1 (None for every scan)"));
    }
    Ok(())
}

/// `task=(k, n)` as the library's task part, checked.
fn task_part(task: (u32, u32)) -> PyResult<TaskPart> {
    let (index, count) = task;
    TaskPart::checked(index, count).ok_or_else(|| {
        PyValueError::new_err(format!("task must be (k, n) with 0 <= k < n <= {MAX_TASKS}, got ({index}, {count})"))
    })
}

/// The `plan` argument of `build_tiles`: the text of `plan_tiles` (a str
/// starting with the plan file's first line), or the path of a plan file
/// (str, bytes or os.PathLike), read as `octolinear build --plan` reads it.
fn plan_argument(plan: &Bound<'_, PyAny>) -> PyResult<TilePlan> {
    if let Ok(text) = plan.extract::<String>() {
        if text.starts_with(PLAN_MAGIC) {
            return TilePlan::parse(&text).map_err(|e| PyValueError::new_err(format!("plan: {e}")));
        }
        if !Path::new(&text).exists() {
            let shown: String = text.chars().take(60).collect();
            return Err(PyValueError::new_err(format!(
                "plan: {shown:?} is neither a plan's text (its first line `{PLAN_MAGIC} ...`, as plan_tiles returns) nor a plan file"
            )));
        }
    }
    let path = convert::path(plan).map_err(|_| {
        PyTypeError::new_err(format!(
            "plan must be the text plan_tiles returns or the path of a plan file (str, bytes or os.PathLike), got {}",
            plan.get_type().name().map_or_else(|_| "?".to_string(), |n| n.to_string())
        ))
    })?;
    TilePlan::read(&path).map_err(|e| match e {
        TileError::Io { path, source } => convert::io_error(&path, &source),
        other => PyValueError::new_err(format!("plan: {other}")),
    })
}

/// The manifest (or task part) an earlier build with these parameters and
/// build record (options, input, plan) left in `dir`, when every tile it
/// lists is there and verifies fully; `None` when it is missing,
/// unreadable, built otherwise or its tiles do not verify (the build then
/// runs again).
fn finished_build(dir: &Path, wanted: &Manifest) -> Option<Manifest> {
    let name = wanted.task.map_or_else(|| MANIFEST_FILE.to_string(), TaskPart::file_name);
    let found = read_manifest(&dir.join(name)).ok()?;
    if found.task != wanted.task || found.difference(wanted, "found", "wanted").is_some() {
        return None;
    }
    TileSet::verify_tiles(dir, &found).ok()?;
    Some(found)
}

/// Nodes of the single tree the whole set in `dir` holds.
fn set_nodes(dir: &Path) -> PyResult<u64> {
    Ok(TileSet::open(dir).map_err(tile_error)?.node_count())
}

/// The summary dict of what `manifest` lists: `tiles`, `nodes`, `bytes`,
/// `seconds`.
fn summary<'py>(
    py: Python<'py>,
    manifest: &Manifest,
    nodes: Option<u64>,
    started: Instant,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("tiles", manifest.tiles.len())?;
    d.set_item("nodes", nodes)?;
    d.set_item("bytes", manifest.tiles.iter().map(|t| t.bytes).sum::<u64>())?;
    d.set_item("seconds", started.elapsed().as_secs_f64())?;
    Ok(d)
}

/// Builds a tile set (formats/tiles.md) in `out_dir` from an OctoMap
/// `.graph` file, as `octolinear build GRAPH -o OUT.tiles --tile-depth D`
/// does: the same tiles, which `convert_tiles` writes as the `.ot` and
/// `.bt` bytes of `build`. Scans are read one at a time; runs without the
/// GIL. `resolution`, `max_range`, `discretize`, `sensor`, `clamping`,
/// `scans` and `threads` as for `build`.
///
/// `out_dir` must be named `NAME.tiles`, or be an empty directory or a
/// tile set; a `manifest` or part file in it must be a tile set's
/// (`ValueError` otherwise, nothing written). The build holds the set's
/// lock (`.lock` in `out_dir`) throughout, as `octolinear build` does: a
/// second build of the same set, or of the same task, fails at once. The
/// manifest records how the set was built: the options, the input's length
/// and modification time, the plan.
///
/// With `task=(k, n)` only task `k`'s share of the tiles is built and its
/// part file `task-k-of-n.manifest` written (`--task k/n`); once all `n`
/// tasks are done, `write_tile_manifest` combines the parts (refusing
/// parts built otherwise). `plan` is the text of `plan_tiles` for the same
/// `n`, or the path of a plan file (`octolinear plan -o`), which gives each
/// task a balanced range of tiles; without it the tiles are shared by a
/// hash of their position. With `resume=True` a build whose manifest (or
/// part file) is already in `out_dir`, built with the same parameters,
/// options, input (length and modification time) and plan, and whose
/// tiles all verify (lengths, CRC-32s, structure), is not run again; one
/// built otherwise is built again.
///
/// With `memory_cap` (bytes) the whole set is built within that memory
/// (`--memory-cap`): in groups of neighbouring tiles, each built from
/// every scan (the file read again) and written out, one group per thread
/// at a time; the tiles are the same.
///
/// Returns a dict: `tiles`, `bytes` (of tile files), `nodes` (of the whole
/// map; `None` for a task), `seconds`, `task` (`(k, n)` or `None`),
/// `skipped` (resumed), `scans` and `points` (`None` when skipped).
#[pyfunction]
#[pyo3(signature = (graph_path, out_dir, *, resolution=0.1, tile_depth, max_range=None, discretize=false,
                    sensor=None, clamping=None, scans=None, threads=None, task=None, plan=None, resume=false,
                    memory_cap=None))]
#[allow(clippy::too_many_arguments)]
pub fn build_tiles<'py>(
    py: Python<'py>,
    graph_path: &Bound<'py, PyAny>,
    out_dir: &Bound<'py, PyAny>,
    resolution: f64,
    tile_depth: u8,
    max_range: Option<f64>,
    discretize: bool,
    sensor: Option<(f64, f64)>,
    clamping: Option<(f64, f64)>,
    scans: Option<usize>,
    threads: Option<usize>,
    task: Option<(u32, u32)>,
    plan: Option<&Bound<'py, PyAny>>,
    resume: bool,
    memory_cap: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let started = Instant::now();
    let path = convert::path(graph_path)?;
    let dir = convert::path(out_dir)?;
    check_build_arguments(tile_depth, max_range, scans)?;
    match threads {
        Some(0) => return Err(PyValueError::new_err("threads must be at least 1")),
        Some(n) => crate::queries::check_threads(n)?,
        None => {}
    }
    let task = task.map(task_part).transpose()?;
    let (task, plan_identity) = match plan {
        Some(plan) => {
            let Some(t) = task else {
                return Err(PyValueError::new_err("plan needs task=(k, n): the task of the plan to build"));
            };
            let plan = plan_argument(plan)?;
            (Some(planned_task(&plan, resolution, tile_depth, t)?), Some(plan.identity()))
        }
        None => (task, None),
    };
    match memory_cap {
        Some(0) => return Err(PyValueError::new_err("memory_cap must be at least 1 byte")),
        Some(_) if task.is_some() => {
            return Err(PyValueError::new_err("memory_cap builds the whole tile set: it does not take a task"))
        }
        _ => {}
    }
    let sensor = sensor_model(sensor, clamping)?;
    let mut map = TiledMap::new(resolution, sensor, NodeKind::Plain, tile_depth).map_err(tile_error)?;
    if let Some(t) = task {
        map.set_task(t);
    }
    let opts = build_options(max_range, discretize, threads);
    let record = BuildRecord {
        scans: scans.map(|n| n as u64),
        input: Some(BuildInput::of_path(&path).map_err(tile_error)?),
        plan: plan_identity,
        ..BuildRecord::new(&opts)
    };
    map.set_build_record(record.clone());
    let wanted = Manifest {
        resolution,
        depth: tile_depth,
        kind: TreeKind::OcTree,
        sensor,
        task,
        build: Some(record.clone()),
        tiles: Vec::new(),
    };
    type Built = (Manifest, Option<u64>, Option<(usize, usize)>);
    let (manifest, nodes, built) = py.detach(|| -> PyResult<Built> {
        // one build at a time writes the set (a task's beside other
        // tasks'); taking the lock checks that `dir` may hold a set
        // (`check_set_dir`) and creates it
        let _lock = match task {
            Some(t) => SetLock::acquire_task(&dir, t),
            None => SetLock::acquire(&dir),
        }
        .map_err(tile_error)?;
        if let Some(found) = resume.then(|| finished_build(&dir, &wanted)).flatten() {
            let nodes = if task.is_none() { Some(set_nodes(&dir)?) } else { None };
            return Ok((found, nodes, None));
        }
        if let Some(memory) = memory_cap {
            // every pass reads the file opened here, whatever its path names later
            let file = graph::GraphFile::open(&path).map_err(|e| graph_error(&path, e))?;
            let (work, count) = estimate(&file, &path, resolution, tile_depth, max_range, discretize, scans)?;
            let grouped = GroupedBuild { resolution, sensor, memory, dir: dir.clone(), record: Some(record.clone()) };
            let read = || -> ScansRead {
                match file.reader() {
                    Ok(reader) => Box::new(reader.take(scans.unwrap_or(usize::MAX)).map(|node| {
                        let (cloud, origin) = node?.into_graph2tree();
                        Ok((cloud.points, origin))
                    })),
                    Err(e) => Box::new(std::iter::once(Err(e))),
                }
            };
            let report = grouped.build(&work, &opts, read, |_, _| {}).map_err(|e| match e {
                GroupedError::Input(e) => graph_error(&path, e),
                GroupedError::Scan { index, source } => {
                    PyValueError::new_err(format!("{}: scan {index}: {source}", path.display()))
                }
                GroupedError::Tiles(e) => tile_error(e),
            })?;
            let manifest = report.manifest;
            remove_unlisted_tiles(&dir, &manifest).map_err(tile_error)?;
            let nodes = set_nodes(&dir)?;
            return Ok((manifest, Some(nodes), Some(count)));
        }
        let mut reader = graph::open(&path).map_err(|e| graph_error(&path, e))?;
        let (mut failure, mut count) = (None, (0, 0));
        let stream = graph_scans(&mut reader, scans, &mut failure).inspect(|(points, _)| {
            count.0 += 1;
            count.1 += points.len();
        });
        map.insert_point_clouds(stream, &opts, |_, _| {})
            .map_err(|(i, e)| PyValueError::new_err(format!("{}: scan {i}: {e}", path.display())))?;
        if let Some(e) = failure {
            return Err(graph_error(&path, e));
        }
        let manifest = map.flush(&dir).map_err(tile_error)?;
        if task.is_none() {
            remove_unlisted_tiles(&dir, &manifest).map_err(tile_error)?;
        }
        let nodes = task.is_none().then(|| map.stats().nodes);
        Ok((manifest, nodes, Some(count)))
    })?;
    let d = summary(py, &manifest, nodes, started)?;
    d.set_item("task", manifest.task.map(|t| (t.index, t.count)))?;
    d.set_item("skipped", built.is_none())?;
    d.set_item("scans", built.map(|b| b.0))?;
    d.set_item("points", built.map(|b| b.1))?;
    Ok(d)
}

/// Plans how `tasks` tasks share the tiles of a build of `graph_path`
/// (`build_tiles` with the same `resolution`, `tile_depth`, `max_range`,
/// `discretize`, `scans`): each task gets a contiguous range of tiles of
/// about equal estimated ray-casting work, and casts only the rays that
/// reach its range. Returns the plan's text (formats/tiles.md, the file
/// `octolinear plan -o` writes), for `build_tiles(..., task=(k, tasks),
/// plan=text)`. Reads the scans once, without the GIL.
#[pyfunction]
#[pyo3(signature = (graph_path, *, resolution=0.1, tile_depth, tasks, max_range=None, discretize=false, scans=None))]
#[allow(clippy::too_many_arguments)]
pub fn plan_tiles(
    py: Python<'_>,
    graph_path: &Bound<'_, PyAny>,
    resolution: f64,
    tile_depth: u8,
    tasks: u32,
    max_range: Option<f64>,
    discretize: bool,
    scans: Option<usize>,
) -> PyResult<String> {
    check_build_arguments(tile_depth, max_range, scans)?;
    octolinear::key::check_resolution(resolution).map_err(|e| PyValueError::new_err(e.to_string()))?;
    if tasks == 0 {
        return Err(PyValueError::new_err("tasks must be at least 1"));
    }
    let path = convert::path(graph_path)?;
    let (work, _) = py.detach(|| {
        let file = graph::GraphFile::open(&path).map_err(|e| graph_error(&path, e))?;
        estimate(&file, &path, resolution, tile_depth, max_range, discretize, scans)
    })?;
    Ok(work.split(tasks).map_err(tile_error)?.to_text())
}

/// The scans of a `.graph` file as a grouped build reads them, each time
/// from the start.
type ScansRead = Box<dyn Iterator<Item = Result<(Vec<Point3>, Point3), graph::GraphError>>>;

/// The estimated work per tile of a build of the `.graph` file `file`
/// (opened from `path`), with the scans and points read.
fn estimate(
    file: &graph::GraphFile,
    path: &Path,
    resolution: f64,
    tile_depth: u8,
    max_range: Option<f64>,
    discretize: bool,
    scans: Option<usize>,
) -> PyResult<(TileWork, (usize, usize))> {
    let mut work = TileWork::new(resolution, tile_depth).map_err(tile_error)?;
    let mut reader = file.reader().map_err(|e| graph_error(path, e))?;
    let (mut failure, mut count) = (None, (0, 0));
    for (points, origin) in graph_scans(&mut reader, scans, &mut failure) {
        count = (count.0 + 1, count.1 + points.len());
        work.add(&points, origin, max_range, discretize);
    }
    match failure {
        Some(e) => Err(graph_error(path, e)),
        None => Ok((work, count)),
    }
}

/// Task `task` of `plan`, checked against the build's parameters.
fn planned_task(plan: &TilePlan, resolution: f64, tile_depth: u8, task: TaskPart) -> PyResult<TaskPart> {
    if plan.resolution != resolution || plan.depth != tile_depth || plan.tasks.len() != task.count as usize {
        return Err(PyValueError::new_err(format!(
            "the plan is for resolution {}, tile_depth {} and {} tasks; the build asks resolution {resolution}, tile_depth {tile_depth}, task ({}, {})",
            plan.resolution,
            plan.depth,
            plan.tasks.len(),
            task.index,
            task.count
        )));
    }
    plan.task(task.index).map_err(tile_error)
}

/// Combines the task parts in `out_dir` (`task-K-of-N.manifest`, written by
/// `build_tiles(..., task=(k, n))`) into the tile set's manifest, as
/// `octolinear tiles manifest` does: every part of one `n` must be there,
/// built with the same parameters; the parts are removed. Returns a dict:
/// `tiles`, `nodes` (of the whole map), `bytes` (of tile files), `seconds`.
#[pyfunction]
pub fn write_tile_manifest<'py>(py: Python<'py>, out_dir: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
    let started = Instant::now();
    let dir = convert::path(out_dir)?;
    let (manifest, nodes) = py.detach(|| -> PyResult<_> {
        let manifest = octolinear::tiles::combine_parts(&dir).map_err(tile_error)?;
        Ok((manifest, set_nodes(&dir)?))
    })?;
    summary(py, &manifest, Some(nodes), started)
}

/// Writes the map of the tile set `tiles_dir` to `output`, atomically, as
/// `octolinear convert MAP.tiles OUT` does: `.ot` and `.bt` tile by tile
/// (one tile in memory at a time), the bytes `build` writes for the same
/// input; `.olm` from the tiles merged into one tree. Every tile is checked
/// fully as it is read. Runs without the GIL.
#[pyfunction]
pub fn convert_tiles(py: Python<'_>, tiles_dir: &Bound<'_, PyAny>, output: &Bound<'_, PyAny>) -> PyResult<()> {
    let dir = convert::path(tiles_dir)?;
    let output = convert::path(output)?;
    let format = MapFormat::from_path(&output).map_err(|e| PyValueError::new_err(e.to_string()))?;
    py.detach(|| {
        let set = TileSet::open(&dir).map_err(tile_error)?;
        let written = match format {
            MapFormat::Bt => write_atomically(&output, |w| bt::write_map(&set, w).map(|_| ())),
            MapFormat::Ot => write_atomically(&output, |w| ot::write_map(&set, w)),
            MapFormat::Olm => {
                let tree = set.merge().map_err(tile_error)?;
                octolinear::mapped::write_file(&tree, &output)
            }
        };
        written.map_err(|e| walk_error(&output, e))
    })
}
