//! Module-level functions on files: `read` (any map), `read_graph`,
//! `build` (what `octolinear build` does) and `read_points`.

use crate::convert;
use crate::octree::{read_bt_path, tree_object};
use crate::queries;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use octolinear::formats::bounded::WholeError;
use octolinear::formats::{bt, graph, ot, pcd, ply, xyz, MapFormat};
use octolinear::sensor::{SensorModel, SensorProbabilities};
use octolinear::{OccupancyTree, Point3, ScanOptions};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use std::path::Path;

/// A map file's format, by extension or, without a known one, by its
/// first bytes.
fn map_format(path: &Path) -> PyResult<MapFormat> {
    if let Some(format) = MapFormat::from_extension(path) {
        return Ok(format);
    }
    let mut head = [0u8; 32];
    let n = {
        use std::io::Read;
        let mut f = std::fs::File::open(path).map_err(|e| convert::io_error(path, &e))?;
        f.read(&mut head).map_err(|e| convert::io_error(path, &e))?
    };
    MapFormat::sniff(&head[..n]).ok_or_else(|| {
        PyValueError::new_err(format!(
            "{}: not a map file (.bt, .ot or .olm by extension or first bytes)",
            path.display()
        ))
    })
}

/// Reads a map: `.bt`, `.ot` or `.olm` (by extension, else by the file's
/// first bytes), into memory. Returns an `OcTree` (or `ColorOcTree`,
/// `OcTreeStamped`, `CountingOcTree` as the file says). Runs without the
/// GIL. `OSError` (`FileNotFoundError`, ...) when the file cannot be read,
/// `ValueError` with the byte offset when its content is damaged.
#[pyfunction]
pub fn read<'py>(py: Python<'py>, path: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let path = convert::path(path)?;
    match map_format(&path)? {
        MapFormat::Bt => tree_object(py, read_bt_path(py, &path)?),
        MapFormat::Ot => match py.detach(|| ot::read_file(&path)).map_err(|e| convert::tree_file_error(&path, e))? {
            ot::AnyTree::Occupancy(t) => tree_object(py, t),
            ot::AnyTree::Counting(t) => Ok(Bound::new(py, crate::kinds::CountingOcTree::from_tree(t))?.into_any()),
        },
        MapFormat::Olm => {
            let map = py.detach(|| octolinear::mapped::open(&path)).map_err(|e| convert::olm_error(&path, e))?;
            if map.view().kind() == octolinear::TreeKind::CountingOcTree {
                let t = py.detach(|| map.to_counting_tree()).map_err(|e| convert::olm_error(&path, e))?;
                return Ok(Bound::new(py, crate::kinds::CountingOcTree::from_tree(t))?.into_any());
            }
            let t = py.detach(|| map.to_tree()).map_err(|e| convert::olm_error(&path, e))?;
            tree_object(py, t)
        }
    }
}

/// Writes `tree` to `path` as `.bt` (maximum likelihood), `.ot` or `.olm`
/// by extension, atomically, without the GIL.
pub fn save(py: Python<'_>, tree: &OccupancyTree, path: &Path) -> PyResult<()> {
    let format = MapFormat::from_path(path).map_err(|e| PyValueError::new_err(e.to_string()))?;
    py.detach(|| match format {
        MapFormat::Bt => bt::write_file(tree, path),
        MapFormat::Ot => ot::write_file(tree, path),
        MapFormat::Olm => octolinear::mapped::write_file(tree, path),
    })
    .map_err(|e| convert::io_error(path, &e))
}

/// A `.graph` file that could not be read: `OSError` for I/O, `ValueError`
/// for content (a truncated file included), the path in the message.
pub(crate) fn graph_error(path: &Path, e: graph::GraphError) -> PyErr {
    match e {
        graph::GraphError::Io { source, .. } if source.kind() != std::io::ErrorKind::UnexpectedEof => {
            convert::io_error(path, &source)
        }
        e @ (graph::GraphError::Changed { .. } | graph::GraphError::NotRegular) => {
            PyOSError::new_err(format!("{}: {e}", path.display()))
        }
        other => PyValueError::new_err(format!("{}: {other}", path.display())),
    }
}

fn points_array<'py>(py: Python<'py>, points: &[Point3]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = points.iter().flat_map(|p| [p.x, p.y, p.z].map(f64::from)).collect();
    flat.into_pyarray(py).reshape([points.len(), 3])
}

/// The scans of an OctoMap `.graph` file, each as `(points, origin)` in the
/// world frame exactly as `graph2tree` transforms them: `points` `(N, 3)`
/// and `origin` `(3,)`, float64 arrays holding the float32 values, ready
/// for `OcTree.insertPointCloud`.
#[pyfunction]
pub fn read_graph<'py>(
    py: Python<'py>,
    path: &Bound<'py, PyAny>,
) -> PyResult<Vec<(queries::Points<'py>, Bound<'py, PyArray1<f64>>)>> {
    let path = convert::path(path)?;
    let scans = py
        .detach(|| graph::read_file(&path).map(|g| g.nodes.iter().map(|n| n.graph2tree()).collect::<Vec<_>>()))
        .map_err(|e| graph_error(&path, e))?;
    scans
        .iter()
        .map(|(cloud, origin)| {
            let o = vec![f64::from(origin.x), f64::from(origin.y), f64::from(origin.z)].into_pyarray(py);
            Ok((points_array(py, &cloud.points)?, o))
        })
        .collect()
}

/// The sensor model `octolinear build` (and graph2tree) uses, with the
/// optional `(miss, hit)` and `(min, max)` clamping probabilities.
pub(crate) fn sensor_model(sensor: Option<(f64, f64)>, clamping: Option<(f64, f64)>) -> PyResult<SensorModel> {
    let mut p = SensorProbabilities::default();
    if let Some((miss, hit)) = sensor {
        (p.miss, p.hit) = (miss, hit);
    }
    if let Some((lo, hi)) = clamping {
        (p.clamping_min, p.clamping_max) = (lo, hi);
    }
    SensorModel::from_probabilities(&p).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The first `limit` scans (all with `None`) of an opened `.graph` file as
/// `(points, origin)` in the world frame, as graph2tree transforms them,
/// each read when insertion asks for it; a read error ends them and is
/// left in `failure`.
pub(crate) fn graph_scans<'a, R: graph::GraphSource>(
    reader: &'a mut graph::ScanReader<R>,
    limit: Option<usize>,
    failure: &'a mut Option<graph::GraphError>,
) -> impl Iterator<Item = (Vec<Point3>, Point3)> + 'a {
    reader.take(limit.unwrap_or(usize::MAX)).map_while(|node| match node {
        Ok(node) => {
            let (cloud, origin) = node.into_graph2tree();
            Some((cloud.points, origin))
        }
        Err(e) => {
            *failure = Some(e);
            None
        }
    })
}

/// The scan options of a build from a `.graph` file, as graph2tree inserts:
/// OctoMap's out-of-map rule, inner nodes updated, `threads` or the
/// package's default.
pub(crate) fn build_options(max_range: Option<f64>, discretize: bool, threads: Option<usize>) -> ScanOptions {
    ScanOptions::default()
        .with_max_range(max_range)
        .with_discretize(discretize)
        .with_threads(threads.or_else(crate::queries::scan_threads))
}

/// Builds a map from an OctoMap `.graph` file as `octolinear build` (and
/// OctoMap's `graph2tree`) does: every scan inserted with
/// `insertPointCloud` in the world frame; `max_range` (None: no limit),
/// `discretize`, `sensor=(miss, hit)`, `clamping=(min, max)`,
/// `compress_ml` (maximum likelihood and prune after each scan), `scans`
/// (only the first N), `threads` (default: `set_num_threads`). With
/// `output` the map is written (`.bt`: the maximum-likelihood map
/// graph2tree writes; `.ot`, `.olm`: the full tree). Returns the full
/// tree. Runs without the GIL; scans are read as they are inserted.
#[pyfunction]
#[pyo3(signature = (graph_path, output=None, resolution=0.1, max_range=None, discretize=false,
                    sensor=None, clamping=None, compress_ml=false, scans=None, threads=None))]
#[allow(clippy::too_many_arguments)]
pub fn build<'py>(
    py: Python<'py>,
    graph_path: &Bound<'py, PyAny>,
    output: Option<&Bound<'py, PyAny>>,
    resolution: f64,
    max_range: Option<f64>,
    discretize: bool,
    sensor: Option<(f64, f64)>,
    clamping: Option<(f64, f64)>,
    compress_ml: bool,
    scans: Option<usize>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    let path = convert::path(graph_path)?;
    let output = output.map(convert::path).transpose()?;
    if let Some(r) = max_range.filter(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(PyValueError::new_err(format!(
            "max_range must be a positive finite number of metres, got {r} (None for no limit)"
        )));
    }
    match threads {
        Some(0) => return Err(PyValueError::new_err("threads must be at least 1")),
        Some(n) => crate::queries::check_threads(n)?,
        None => {}
    }
    let sensor = sensor_model(sensor, clamping)?;
    let mut tree = OccupancyTree::with_sensor(resolution, sensor).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let opts = build_options(max_range, discretize, threads);
    let built = py.detach(|| -> Result<OccupancyTree, PyErr> {
        let input = graph::GraphInput::open(&path).map_err(|e| convert::io_error(&path, &e))?;
        // a file truncated under the reader: zeros were read (OSError)
        let watch = input.watch();
        let truncated = || watch.check().map_err(|e| convert::truncated_error(&e));
        let len = input.file_len();
        let mut reader = graph::ScanReader::with_len(input, len)
            .map_err(|e| truncated().err().unwrap_or_else(|| graph_error(&path, e)))?;
        let mut failure = None;
        let stream = graph_scans(&mut reader, scans, &mut failure);
        let inserted = tree
            .insert_point_clouds(stream, &opts, |t, _| {
                if compress_ml {
                    t.to_max_likelihood();
                    t.prune();
                }
            })
            .map_err(|(i, e)| PyValueError::new_err(format!("{}: scan {i}: {e}", path.display())));
        truncated()?;
        inserted?;
        if let Some(e) = failure {
            return Err(graph_error(&path, e));
        }
        tree.compact();
        Ok(tree)
    })?;
    if let Some(out) = output {
        save(py, &built, &out)?;
    }
    Ok(Bound::new(py, crate::octree::OcTree::from_tree(built))?.into_any())
}

/// Reads a point cloud file: PLY (ASCII or binary), PCD (ASCII, binary,
/// binary_compressed) or XYZ text (`.xyz`, `.txt`, `.csv`), by extension.
/// Returns the points, `(N, 3)` float64 holding float32 values; with
/// `colors=True`, `(points, colors)` where `colors` is `(N, 3)` uint8 or
/// `None` if the file has none. A line of an XYZ file or of a PLY or PCD
/// header longer than 1 MiB, or a pipe or device holding more than 4 GiB,
/// is a `ValueError`.
#[pyfunction]
#[pyo3(signature = (path, colors=false))]
pub fn read_points<'py>(py: Python<'py>, path: &Bound<'py, PyAny>, colors: bool) -> PyResult<Bound<'py, PyAny>> {
    let path = convert::path(path)?;
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    let read = || -> Result<octolinear::formats::ColoredCloud, PyErr> {
        let bad = |e: &dyn std::fmt::Display| PyValueError::new_err(format!("{}: {e}", path.display()));
        match ext.as_str() {
            // a regular file read to its length, a FIFO or device within
            // the library's bounds; I/O errors are OSError
            "ply" => ply::read_file(&path, colors).map_err(|e| match e {
                ply::PlyError::Read(WholeError::Io(e)) => convert::io_error(&path, &e),
                e => bad(&e),
            }),
            "pcd" => pcd::read_file(&path, colors).map_err(|e| match e {
                pcd::PcdError::Read(WholeError::Io(e)) => convert::io_error(&path, &e),
                e => bad(&e),
            }),
            "xyz" | "txt" | "csv" => {
                let file = std::fs::File::open(&path).map_err(|e| convert::io_error(&path, &e))?;
                let cloud = xyz::read(std::io::BufReader::new(file)).map_err(|e| bad(&e))?;
                Ok(octolinear::formats::ColoredCloud { cloud, colors: None })
            }
            _ => Err(PyValueError::new_err(format!(
                "{}: unknown point cloud format (use .ply, .pcd, .xyz, .txt or .csv)",
                path.display()
            ))),
        }
    };
    let cloud = py.detach(read)?;
    let points = points_array(py, &cloud.cloud.points)?.into_any();
    if !colors {
        return Ok(points);
    }
    let colors = match cloud.colors {
        Some(c) => {
            let n = c.len();
            let flat: Vec<u8> = c.into_iter().flatten().collect();
            flat.into_pyarray(py).reshape([n, 3])?.into_any()
        }
        None => py.None().into_bound(py),
    };
    Ok(pyo3::types::PyTuple::new(py, [points, colors])?.into_any())
}
