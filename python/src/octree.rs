//! `octolinear.OcTree`: octomap-python's `OcTree` (same method names,
//! argument order and answers) on the library's tree, plus the array
//! queries (`occupancy`, `cast_rays`, `leaves`).

use crate::convert::{self, PointsArg};
use crate::nodes::{node_value, NodeIterator, OcTreeKey, OcTreeNode};
use crate::queries;
use numpy::{IntoPyArray, PyArray1, PyArrayMethods};
use octolinear::formats::{bt, ot, MapFormat};
use octolinear::key::adjust_key_to_depth;
use octolinear::sensor::{logodds, probability};
use octolinear::{
    BoundsRule, CastOptions, InnerNodes, Key, KeyBox, NodeKind, OccupancyTree, Point3, ScanOptions, UpdateBox,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyTuple};
use std::path::Path;

/// An occupancy octree, a drop-in for octomap-python's `octomap.OcTree`.
///
/// `OcTree(resolution)` makes an empty tree; `OcTree(filename)` reads a
/// `.bt` file. Maps, queries and files are bit-identical to OctoMap 1.10;
/// where a method cannot be, its docstring says so.
#[pyclass(module = "octolinear", subclass)]
pub struct OcTree {
    pub(crate) tree: OccupancyTree,
    bbx_min: Point3,
    bbx_max: Point3,
    use_bbx: bool,
    change_detection: bool,
}

impl OcTree {
    /// Wraps a tree, with OctoMap's defaults for the rest.
    pub fn from_tree(tree: OccupancyTree) -> Self {
        let origin = Point3::new(0.0, 0.0, 0.0);
        OcTree { tree, bbx_min: origin, bbx_max: origin, use_bbx: false, change_detection: false }
    }

    /// An empty tree of `kind`.
    pub fn with_kind(resolution: f64, kind: NodeKind) -> PyResult<Self> {
        let tree = OccupancyTree::with_kind(resolution, Default::default(), kind)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(Self::from_tree(tree))
    }

    fn sensor_set(&mut self, f: impl FnOnce(&mut octolinear::SensorModel, f32), prob: f64, name: &str) -> PyResult<()> {
        if !(prob > 0.0 && prob < 1.0) {
            return Err(PyValueError::new_err(format!("{name}: probability {prob} is not in (0, 1)")));
        }
        let mut s = *self.tree.sensor();
        f(&mut s, logodds(prob));
        self.tree.set_sensor(s);
        Ok(())
    }

    fn key_of(&self, p: Point3) -> Option<Key> {
        self.tree.key(p).ok()
    }

    /// Replaces the tree with one read from a file, keeping the sensor
    /// model and the change-detection setting.
    fn replace(&mut self, mut tree: OccupancyTree) {
        tree.set_sensor(*self.tree.sensor());
        tree.set_change_detection(self.change_detection);
        self.tree = tree;
    }
}

/// Maps a `.bt`/`.ot` given as data (`bytes` starting with the format's
/// first line, [`MapFormat::signature`]) or as a file name.
enum Source {
    Data(Vec<u8>),
    File(std::path::PathBuf),
}

fn source(obj: &Bound<'_, PyAny>, magic: &[u8]) -> PyResult<Source> {
    if let Ok(b) = obj.cast::<PyBytes>() {
        if b.as_bytes().starts_with(magic) {
            return Ok(Source::Data(b.as_bytes().to_vec()));
        }
    }
    Ok(Source::File(convert::path(obj)?))
}

/// Reads a `.bt` from data or a file, without the GIL.
pub fn read_bt(py: Python<'_>, obj: &Bound<'_, PyAny>, sensor: octolinear::SensorModel) -> PyResult<OccupancyTree> {
    match source(obj, MapFormat::Bt.signature())? {
        Source::Data(d) => py
            .detach(|| bt::read_with_sensor(&d[..], sensor))
            .map_err(|e| PyValueError::new_err(format!("binary map data: {e}"))),
        Source::File(path) => py
            .detach(|| {
                let f = std::fs::File::open(&path).map_err(octolinear::TreeFileError::Io)?;
                bt::read_with_sensor(std::io::BufReader::new(f), sensor)
            })
            .map_err(|e| convert::tree_file_error(&path, e)),
    }
}

/// Reads an `.ot` from data or a file, without the GIL.
pub fn read_ot(py: Python<'_>, obj: &Bound<'_, PyAny>) -> PyResult<ot::AnyTree> {
    match source(obj, MapFormat::Ot.signature())? {
        Source::Data(d) => py.detach(|| ot::read(&d[..])).map_err(|e| PyValueError::new_err(format!("map data: {e}"))),
        Source::File(path) => py.detach(|| ot::read_file(&path)).map_err(|e| match e {
            octolinear::TreeFileError::Io(io) => convert::io_error(&path, &io),
            damaged => pyo3::exceptions::PyOSError::new_err(format!(
                "failed to read OcTree from '{}': {damaged}",
                path.display()
            )),
        }),
    }
}

/// Writes with `write` into a file (atomically) or, without a file name,
/// into `bytes`; `True` for a file as octomap-python returns.
pub fn write_to<'py, T: Sync>(
    py: Python<'py>,
    filename: Option<&Bound<'py, PyAny>>,
    tree: &T,
    write: fn(&T, &mut dyn std::io::Write) -> std::io::Result<()>,
) -> PyResult<Bound<'py, PyAny>> {
    match filename {
        None => {
            let mut out = Vec::new();
            py.detach(|| write(tree, &mut out)).map_err(|e| pyo3::exceptions::PyOSError::new_err(e.to_string()))?;
            Ok(PyBytes::new(py, &out).into_any())
        }
        Some(f) => {
            let path = convert::path(f)?;
            py.detach(|| octolinear::formats::write_atomically(&path, |w| write(tree, w)))
                .map_err(|e| convert::io_error(&path, &e))?;
            Ok(PyBool::new(py, true).to_owned().into_any())
        }
    }
}

/// The tree as an `OcTree`, `ColorOcTree` or `OcTreeStamped` object by its
/// kind.
pub fn tree_object(py: Python<'_>, tree: OccupancyTree) -> PyResult<Bound<'_, PyAny>> {
    let kind = tree.kind();
    let base = OcTree::from_tree(tree);
    Ok(match kind {
        NodeKind::Plain => Bound::new(py, base)?.into_any(),
        NodeKind::Color => {
            Bound::new(py, PyClassInitializer::from(base).add_subclass(crate::kinds::ColorOcTree))?.into_any()
        }
        NodeKind::Stamped => {
            Bound::new(py, PyClassInitializer::from(base).add_subclass(crate::kinds::OcTreeStamped))?.into_any()
        }
    })
}

/// A ray argument: one origin for all rays, or one per ray.
fn origins_arg(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Point3>> {
    if obj.getattr("ndim").and_then(|d| d.extract::<usize>()).unwrap_or(2) == 1
        || obj.len().is_ok_and(|n| n == 3) && obj.get_item(0).is_ok_and(|x| x.extract::<f64>().is_ok())
    {
        return Ok(vec![convert::point(obj, "origins")?]);
    }
    let a = PointsArg::extract(obj, "origins")?;
    Ok(a.view().points().into_owned())
}

/// The shared body of `cast_rays` for in-memory and mapped maps.
pub fn cast_rays_impl<'py, M: queries::Queries>(
    py: Python<'py>,
    map: &M,
    origins: &Bound<'py, PyAny>,
    directions: &Bound<'py, PyAny>,
    max_range: f64,
    ignore_unknown: bool,
) -> PyResult<queries::RayArrays<'py>> {
    let origins = origins_arg(origins)?;
    let dirs = PointsArg::extract(directions, "directions")?;
    if origins.len() != 1 && origins.len() != dirs.len() {
        return Err(PyValueError::new_err(format!(
            "origins: {} origins for {} directions (give one origin or one per direction)",
            origins.len(),
            dirs.len()
        )));
    }
    if max_range.is_nan() {
        return Err(PyValueError::new_err("max_range is NaN (give a negative value for no limit)"));
    }
    let opts = CastOptions { ignore_unknown, max_range: (max_range > 0.0).then_some(max_range) };
    let view = dirs.view();
    let result = py.detach(|| queries::on_pool(|| queries::cast_rays(map, &origins, &view.points(), opts)))?;
    queries::ray_arrays(py, result)
}

/// The shared body of `occupancy`.
pub fn occupancy_impl<'py, M: queries::Queries>(
    py: Python<'py>,
    map: &M,
    points: &Bound<'py, PyAny>,
    depth: Option<u32>,
) -> PyResult<queries::OccupancyArrays<'py>> {
    let depth = queries::max_depth(depth)?;
    let pts = PointsArg::extract(points, "points")?;
    let view = pts.view();
    let result = py.detach(|| queries::on_pool(|| queries::occupancy(map, &view, depth, queries::Keys::Checked)))?;
    Ok(queries::occupancy_arrays(py, result))
}

/// The shared body of `getLabels`: -1 unknown, 0 free, 1 occupied, int32;
/// keys by `coordToKey` as octomap-python's.
pub fn labels_impl<'py, M: queries::Queries>(
    py: Python<'py>,
    map: &M,
    points: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<i32>>> {
    let pts = PointsArg::extract(points, "points")?;
    let view = pts.view();
    let (state, _) = py.detach(|| queries::on_pool(|| queries::occupancy(map, &view, 0, queries::Keys::Wrapping)))?;
    Ok(state.into_iter().map(i32::from).collect::<Vec<_>>().into_pyarray(py))
}

/// A depth argument of octomap-python (`0` means the finest level).
fn depth_arg(depth: u32) -> PyResult<u8> {
    queries::max_depth(Some(depth))
}

/// A key argument: an `OcTreeKey` (or anything with three integer items).
fn key_arg(obj: &Bound<'_, PyAny>) -> PyResult<Key> {
    if let Ok(k) = obj.cast::<OcTreeKey>() {
        return Ok(k.borrow().key());
    }
    let v: [u16; 3] = obj
        .extract()
        .map_err(|_| PyTypeError::new_err(format!("expected an OcTreeKey, got {}", convert::type_name(obj))))?;
    Ok(Key(v))
}

/// The library's refusal of an output too large for its limit as a
/// `MemoryError` naming the keyword argument that raises the limit.
fn output_error(e: octolinear::TreeError, argument: &str) -> PyErr {
    pyo3::exceptions::PyMemoryError::new_err(format!("{e} ({argument}=...)"))
}

fn array3<'py>(py: Python<'py>, v: [f64; 3]) -> Bound<'py, PyArray1<f64>> {
    v.to_vec().into_pyarray(py)
}

fn point_array(py: Python<'_>, p: Point3) -> Bound<'_, PyArray1<f64>> {
    array3(py, [f64::from(p.x), f64::from(p.y), f64::from(p.z)])
}

#[pymethods]
impl OcTree {
    #[new]
    #[pyo3(signature = (arg))]
    fn py_new(py: Python<'_>, arg: &Bound<'_, PyAny>) -> PyResult<Self> {
        if let Ok(res) = arg.extract::<f64>() {
            if arg.is_instance_of::<PyBool>() {
                return Err(PyTypeError::new_err("OcTree(resolution): expected a number, got bool"));
            }
            return Self::with_kind(res, NodeKind::Plain);
        }
        let tree = read_bt(py, arg, Default::default())?;
        Ok(Self::from_tree(tree))
    }

    /// Integrates a scan: `pointcloud` is `(N, 3)` (float64 or float32, any
    /// memory order; float32 C-contiguous arrays are used in place), in the
    /// world frame, taken from `origin`. Rays longer than `maxrange` (if
    /// positive) are cut and their ends not marked. `lazy_eval` defers
    /// inner-node updates to `updateInnerOccupancy()`; `discretize` merges
    /// end points per voxel first. Bit-identical to OctoMap's
    /// `insertPointCloud`; points with NaN or infinite coordinates are
    /// skipped (OctoMap's result with them is undefined), a non-finite
    /// origin raises `ValueError`. Runs without the GIL, on the threads set
    /// by `octolinear.set_num_threads`.
    #[pyo3(signature = (pointcloud, origin, maxrange=-1.0, lazy_eval=false, discretize=false))]
    fn insertPointCloud(
        &mut self,
        py: Python<'_>,
        pointcloud: &Bound<'_, PyAny>,
        origin: &Bound<'_, PyAny>,
        maxrange: f64,
        lazy_eval: bool,
        discretize: bool,
    ) -> PyResult<()> {
        let pts = PointsArg::extract(pointcloud, "pointcloud")?;
        let origin = convert::point(origin, "origin")?;
        if maxrange.is_nan() {
            return Err(PyValueError::new_err("maxrange is NaN (give -1 for no limit)"));
        }
        let bbx = if self.use_bbx {
            Some(UpdateBox::new(&self.tree, self.bbx_min, self.bbx_max).map_err(|e| {
                PyValueError::new_err(format!("bounding box limit: a corner lies outside the map: {e}"))
            })?)
        } else {
            None
        };
        let opts = ScanOptions::default()
            .with_max_range((maxrange >= 0.0).then_some(maxrange))
            .with_discretize(discretize)
            .with_inner(if lazy_eval { InnerNodes::Defer } else { InnerNodes::Update })
            .with_bbx(bbx)
            .with_threads(queries::scan_threads());
        let view = pts.view();
        let tree = &mut self.tree;
        py.detach(|| tree.insert_point_cloud(&view.points(), origin, &opts))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(())
    }

    /// Integrates one measurement at `value` (an `OcTreeKey` or a point):
    /// `update` is `True`/`False` (hit/miss) or a log-odds change. Returns
    /// the updated node (a snapshot of its value; see `OcTreeNode`), or a
    /// null node if the point lies outside the map.
    #[pyo3(signature = (value, update, lazy_eval=false))]
    fn updateNode(
        &mut self,
        value: &Bound<'_, PyAny>,
        update: &Bound<'_, PyAny>,
        lazy_eval: bool,
    ) -> PyResult<OcTreeNode> {
        let inner = if lazy_eval { InnerNodes::Defer } else { InnerNodes::Update };
        let key = if value.is_instance_of::<OcTreeKey>() {
            Some(key_arg(value)?)
        } else {
            self.key_of(convert::point(value, "value")?)
        };
        let Some(key) = key else {
            return Ok(OcTreeNode::null());
        };
        let v = if let Ok(b) = update.cast::<PyBool>() {
            self.tree.update_occupancy(key, b.is_true(), inner)
        } else {
            let delta: f32 = update.extract().map_err(|_| {
                PyTypeError::new_err(format!(
                    "update: expected a bool or a log-odds number, got {}",
                    convert::type_name(update)
                ))
            })?;
            self.tree.update(key, delta, inner)
        };
        Ok(self.tree.search(key, 0).map_or(OcTreeNode::with_children(v, false, 0), OcTreeNode::from_found))
    }

    /// `updateNode` for each of `values` (keys or points).
    #[pyo3(signature = (values, update, lazy_eval=false))]
    fn updateNodes(&mut self, values: &Bound<'_, PyAny>, update: &Bound<'_, PyAny>, lazy_eval: bool) -> PyResult<()> {
        if values.is_none() {
            return Ok(());
        }
        for v in values.try_iter()? {
            self.updateNode(&v?, update, lazy_eval)?;
        }
        Ok(())
    }

    /// The node at `value` (an `OcTreeKey` or a point), searched down to
    /// `depth` (0: the finest). A node not found is a null node, whose
    /// methods raise `NullPointerException` as octomap-python's do (and
    /// which is falsy). The node is a snapshot of the value.
    #[pyo3(signature = (value, depth=0))]
    fn search(&self, value: &Bound<'_, PyAny>, depth: u32) -> PyResult<OcTreeNode> {
        let depth = depth_arg(depth)?;
        let key = if value.is_instance_of::<OcTreeKey>() {
            Some(key_arg(value)?)
        } else {
            self.key_of(convert::point(value, "value")?)
        };
        Ok(key.and_then(|k| self.tree.search(k, depth)).map_or_else(OcTreeNode::null, OcTreeNode::from_found))
    }

    /// Is the node (from `search`, `updateNode` or an iterator) occupied?
    fn isNodeOccupied(&self, node: &Bound<'_, PyAny>) -> PyResult<bool> {
        Ok(self.tree.is_occupied(node_value(node)?))
    }

    /// Is the node's log-odds at a clamping bound?
    fn isNodeAtThreshold(&self, node: &Bound<'_, PyAny>) -> PyResult<bool> {
        Ok(self.tree.sensor().is_at_threshold(node_value(node)?))
    }

    /// Casts a ray from `origin` along `direction` until an occupied voxel:
    /// returns whether one was hit and writes the end voxel's centre into
    /// `end` (a writable sequence of 3) whenever OctoMap does (every cast
    /// that starts: also on unknown space, range or map edge). Nothing is
    /// written when the origin lies outside the map or the direction is
    /// zero. `maxRange` ≤ 0 means no limit.
    #[pyo3(signature = (origin, direction, end, ignoreUnknownCells=false, maxRange=-1.0))]
    fn castRay(
        &self,
        origin: &Bound<'_, PyAny>,
        direction: &Bound<'_, PyAny>,
        end: &Bound<'_, PyAny>,
        ignoreUnknownCells: bool,
        maxRange: f64,
    ) -> PyResult<bool> {
        cast_ray_into(&self.tree, origin, direction, end, ignoreUnknownCells, maxRange)
    }

    /// Occupancy label of each point of an `(N, 3)` array: -1 unknown (no
    /// node), 0 free, 1 occupied; int32. As octomap-python's, the key of a
    /// point outside the map wraps around (OctoMap's unchecked
    /// `coordToKey`); points with NaN or infinite coordinates (undefined
    /// there) are -1. One call, without the GIL; `occupancy()` gives -1
    /// outside the map instead.
    fn getLabels<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<i32>>> {
        labels_impl(py, &self.tree, points)
    }

    /// Centres of the occupied and of the free voxels, `(occupied, empty)`,
    /// each `(N, 3)` float64, leaf by leaf in iteration order; a leaf
    /// coarser than the resolution gives every voxel centre inside it (x,
    /// then y, then z ascending), computed in octomap-python's arithmetic.
    /// A leaf at depth d holds 8^(16-d) voxels: the points are counted
    /// first, and more than `max_points` (default 2^28, 6 GB of
    /// coordinates) raise `MemoryError` before anything is allocated.
    #[pyo3(signature = (*, max_points=octolinear::tree::OUTPUT_LIMIT))]
    fn extractPointCloud<'py>(
        &self,
        py: Python<'py>,
        max_points: u64,
    ) -> PyResult<(queries::Points<'py>, queries::Points<'py>)> {
        let tree = &self.tree;
        let (total, occupied) = py
            .detach(|| {
                let total = tree.voxels_within(16, |_| true, max_points, "extractPointCloud")?;
                Ok((total, tree.voxel_count(16, |v| tree.is_occupied(v))))
            })
            .map_err(|e| output_error(e, "max_points"))?;
        let (occ, free) = py.detach(|| {
            // octomap-python holds the resolution in a C float
            let res = f64::from(tree.resolution() as f32);
            let capacity = |n: u64| Vec::with_capacity(3 * n as usize);
            let (mut occ, mut free) = (capacity(occupied), capacity(total - occupied));
            for n in tree.leaves(0) {
                let c = n.center_point();
                let out = if tree.is_occupied(n.value) { &mut occ } else { &mut free };
                let dim = (n.size() / res).round_ties_even().max(1.0) as usize;
                let shift = (dim as f64 / 2.0 - 0.5) * res;
                let corner = [c.x, c.y, c.z].map(|v| f64::from(v) - shift);
                for i in 0..dim {
                    for j in 0..dim {
                        for k in 0..dim {
                            out.extend([
                                corner[0] + i as f64 * res,
                                corner[1] + j as f64 * res,
                                corner[2] + k as f64 * res,
                            ]);
                        }
                    }
                }
            }
            (occ, free)
        });
        let shape = |v: Vec<f64>| {
            let n = v.len() / 3;
            v.into_pyarray(py).reshape([n, 3])
        };
        Ok((shape(occ)?, shape(free)?))
    }

    /// Reads a `.bt` map (a file name, or `bytes` holding the file) into
    /// this tree, keeping its sensor model. Returns `True`; as
    /// octomap-python, `False` when the file cannot be read or the map is
    /// damaged (a `RuntimeWarning` says why), the tree unchanged.
    fn readBinary(&mut self, py: Python<'_>, filename: &Bound<'_, PyAny>) -> PyResult<bool> {
        match read_bt(py, filename, *self.tree.sensor()) {
            Ok(tree) => {
                self.replace(tree);
                Ok(true)
            }
            Err(e) if e.is_instance_of::<pyo3::exceptions::PyOSError>(py) || e.is_instance_of::<PyValueError>(py) => {
                let message = std::ffi::CString::new(format!("readBinary: {e}").replace('\0', "\\0"))?;
                let category = py.get_type::<pyo3::exceptions::PyRuntimeWarning>();
                PyErr::warn(py, &category, &message, 1)?;
                Ok(false)
            }
            Err(e) => Err(e),
        }
    }

    /// Writes the `.bt` map to `filename` (atomically; returns `True`) or,
    /// without one, returns its bytes. As OctoMap's `writeBinary`, the tree
    /// is first converted to maximum likelihood and pruned.
    #[pyo3(signature = (filename=None))]
    fn writeBinary<'py>(
        &mut self,
        py: Python<'py>,
        filename: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let tree = &mut self.tree;
        py.detach(|| {
            tree.to_max_likelihood();
            tree.prune();
        });
        write_to(py, filename, &self.tree, |t, w| bt::write_const(t, w))
    }

    /// Writes the full `.ot` map to `filename` (atomically; returns `True`)
    /// or, without one, returns its bytes.
    #[pyo3(signature = (filename=None))]
    fn write<'py>(&self, py: Python<'py>, filename: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyAny>> {
        write_to(py, filename, &self.tree, |t, w| ot::write(t, w))
    }

    /// Reads an `.ot` map (a file name, or `bytes` holding the file) and
    /// returns a new tree of the file's type (`OcTree`, `ColorOcTree`,
    /// `OcTreeStamped`, `CountingOcTree`). Call it on the class:
    /// `OcTree.read(filename)`. As octomap-python: a file that cannot be
    /// opened raises `OSError` (`FileNotFoundError`, ...), a damaged file
    /// `OSError` ("failed to read OcTree from ..."), damaged bytes
    /// `ValueError`.
    #[staticmethod]
    fn read<'py>(py: Python<'py>, filename: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        match read_ot(py, filename)? {
            ot::AnyTree::Occupancy(t) => tree_object(py, t),
            ot::AnyTree::Counting(t) => Ok(Bound::new(py, crate::kinds::CountingOcTree::from_tree(t))?.into_any()),
        }
    }

    /// Iterator over every node, depth first in OctoMap's order, down to
    /// `maxDepth` (0: all levels). The nodes are listed when it is made.
    #[pyo3(signature = (maxDepth=0))]
    fn begin_tree(&self, py: Python<'_>, maxDepth: u32) -> PyResult<NodeIterator> {
        let d = depth_arg(maxDepth)?;
        let tree = &self.tree;
        Ok(py.detach(|| NodeIterator::new(tree, tree.nodes(d))))
    }

    /// Iterator over the leaves (nodes at `maxDepth` count as leaves).
    #[pyo3(signature = (maxDepth=0))]
    fn begin_leafs(&self, py: Python<'_>, maxDepth: u32) -> PyResult<NodeIterator> {
        let d = depth_arg(maxDepth)?;
        let tree = &self.tree;
        Ok(py.detach(|| NodeIterator::new(tree, tree.leaves(d))))
    }

    /// Iterator over the leaves overlapping the box `bbx_min`..`bbx_max`
    /// (empty if a corner lies outside the map, as in OctoMap; a NaN
    /// coordinate raises `ValueError`, as `leaves(bbox=...)`).
    #[pyo3(signature = (bbx_min, bbx_max, maxDepth=0))]
    fn begin_leafs_bbx(
        &self,
        py: Python<'_>,
        bbx_min: &Bound<'_, PyAny>,
        bbx_max: &Bound<'_, PyAny>,
        maxDepth: u32,
    ) -> PyResult<NodeIterator> {
        let d = depth_arg(maxDepth)?;
        let (lo, hi) = (convert::point(bbx_min, "bbx_min")?, convert::point(bbx_max, "bbx_max")?);
        let tree = &self.tree;
        queries::reject_nan_corners(tree.key_space(), lo, hi)?;
        Ok(py.detach(|| match (tree.key(lo), tree.key(hi)) {
            (Ok(min), Ok(max)) => NodeIterator::new(tree, tree.leaves_in_box(KeyBox { min, max }, d)),
            _ => NodeIterator::empty(tree),
        }))
    }

    /// An exhausted tree iterator (octomap-python's `end_tree`).
    fn end_tree(&self) -> NodeIterator {
        NodeIterator::empty(&self.tree)
    }

    /// An exhausted leaf iterator.
    fn end_leafs(&self) -> NodeIterator {
        NodeIterator::empty(&self.tree)
    }

    /// An exhausted bounding-box leaf iterator.
    fn end_leafs_bbx(&self) -> NodeIterator {
        NodeIterator::empty(&self.tree)
    }

    /// Lower corner of the known space, metres (float64, as OctoMap's
    /// `getMetricMin`; zeros for an empty tree).
    fn getMetricMin<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array3(py, self.tree.bounds(BoundsRule::MinPlusSize).min)
    }

    /// Upper corner of the known space (OctoMap's non-const `getMetricMax`).
    fn getMetricMax<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array3(py, self.tree.bounds(BoundsRule::MinPlusSize).max)
    }

    /// Extent of the known space per axis.
    fn getMetricSize<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array3(py, self.tree.bounds(BoundsRule::MinPlusSize).size())
    }

    /// Voxel edge length, metres.
    fn getResolution(&self) -> f64 {
        self.tree.resolution()
    }

    /// Changes the resolution, keeping every node: the map scales (OctoMap's
    /// `setResolution`). Costs a copy of the tree.
    fn setResolution(&mut self, py: Python<'_>, r: f64) -> PyResult<()> {
        OccupancyTree::new(r).map_err(|e| PyValueError::new_err(e.to_string()))?;
        let tree = &self.tree;
        let rescaled = py.detach(|| -> Result<ot::AnyTree, String> {
            // the tree as an .ot whose header names the new resolution in full
            let mut data = Vec::new();
            ot::write(tree, &mut data).map_err(|e| e.to_string())?;
            let end = data.windows(6).position(|w| w == b"\ndata\n").ok_or("no data line")?;
            let header = std::str::from_utf8(&data[..end]).map_err(|e| e.to_string())?;
            let mut out: Vec<u8> = header
                .lines()
                .map(|l| if l.starts_with("res ") { format!("res {r:?}\n") } else { format!("{l}\n") })
                .collect::<String>()
                .into_bytes();
            out.extend_from_slice(&data[end + 1..]);
            ot::read(&out[..]).map_err(|e| e.to_string())
        });
        match rescaled {
            Ok(ot::AnyTree::Occupancy(t)) => {
                self.replace(t);
                Ok(())
            }
            Ok(ot::AnyTree::Counting(_)) => Err(pyo3::exceptions::PyRuntimeError::new_err(
                "setResolution: the rescaled copy is not an occupancy tree",
            )),
            Err(e) => Err(pyo3::exceptions::PyRuntimeError::new_err(format!("setResolution: {e}"))),
        }
    }

    /// Levels below the root: 16.
    fn getTreeDepth(&self) -> u32 {
        16
    }

    /// The OctoMap type name, as bytes (`b"OcTree"`, `b"ColorOcTree"`, ...).
    fn getTreeType<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, octolinear::TreeKind::of(self.tree.kind()).id().as_bytes())
    }

    /// Number of nodes (OctoMap's maintained counter).
    fn size(&self) -> usize {
        self.tree.size()
    }

    /// Number of nodes, counted.
    fn calcNumNodes(&self) -> usize {
        self.tree.calc_num_nodes()
    }

    /// Number of leaves.
    fn getNumLeafNodes(&self) -> usize {
        self.tree.num_leaves()
    }

    /// Bytes this tree holds. Not OctoMap's figure (its pointer tree needs
    /// several times more): `memoryUsageOctoMap()` gives that.
    fn memoryUsage(&self) -> usize {
        self.tree.memory_usage()
    }

    /// What OctoMap's `memoryUsage()` reports for the same tree.
    fn memoryUsageOctoMap(&self) -> usize {
        self.tree.octomap_memory_usage()
    }

    /// OctoMap's `sizeof(OcTreeNode)`: 16.
    fn memoryUsageNode(&self) -> usize {
        16
    }

    /// Bytes of a full 3D grid over the known space, as OctoMap computes it.
    fn memoryFullGrid(&self) -> u64 {
        self.tree.memory_full_grid(BoundsRule::MinPlusSize)
    }

    /// Volume of the known space's bounding box, cubic metres.
    fn volume(&self) -> f64 {
        self.tree.volume()
    }

    /// Sets every node to its maximum-likelihood value (clamping bound).
    fn toMaxLikelihood(&mut self, py: Python<'_>) {
        let tree = &mut self.tree;
        py.detach(|| tree.to_max_likelihood());
    }

    /// Merges children with equal values into their parent (lossless).
    fn prune(&mut self, py: Python<'_>) {
        let tree = &mut self.tree;
        py.detach(|| tree.prune());
    }

    /// Splits every pruned node down to the finest level. A leaf at depth d
    /// becomes 8^(16-d) voxels: the nodes to add are counted first, and
    /// more than `max_nodes` (default 2^28) raise `MemoryError`, the tree
    /// unchanged.
    #[pyo3(signature = (*, max_nodes=octolinear::tree::OUTPUT_LIMIT))]
    fn expand(&mut self, py: Python<'_>, max_nodes: u64) -> PyResult<()> {
        let tree = &mut self.tree;
        py.detach(|| tree.expand_within(max_nodes)).map_err(|e| output_error(e, "max_nodes"))?;
        Ok(())
    }

    /// Recomputes inner nodes after `lazy_eval` updates.
    fn updateInnerOccupancy(&mut self, py: Python<'_>) {
        let tree = &mut self.tree;
        py.detach(|| tree.update_inner_occupancy());
    }

    /// Removes every node.
    fn clear(&mut self) {
        self.tree.clear();
    }

    /// Deletes the node holding `value` at `depth` (octomap-python's default
    /// 1; 0 means the finest level). Returns whether one was deleted.
    #[pyo3(signature = (value, depth=1))]
    fn deleteNode(&mut self, value: &Bound<'_, PyAny>, depth: u32) -> PyResult<bool> {
        let d = depth_arg(depth)?;
        Ok(self.tree.delete_point(convert::point(value, "value")?, d).unwrap_or(false))
    }

    /// The root node (a null node for an empty tree).
    fn getRoot(&self) -> OcTreeNode {
        match self.tree.root() {
            Some(r) => OcTreeNode::with_children(r.value(), r.has_children(), r.extra()),
            None => OcTreeNode::null(),
        }
    }

    /// The key of a point (OctoMap's unchecked `coordToKey`: a point outside
    /// the map gives a wrapped key), at the finest level or at `depth`.
    #[pyo3(signature = (coord, depth=None))]
    fn coordToKey(&self, coord: &Bound<'_, PyAny>, depth: Option<u32>) -> PyResult<OcTreeKey> {
        let p = convert::point(coord, "coord")?;
        let ks = self.tree.key_space();
        Ok(OcTreeKey::from(match depth {
            None => ks.key_unchecked(p),
            Some(d) => {
                let d = depth_arg(d)?;
                let d = if d == 0 { 16 } else { d };
                Key([p.x, p.y, p.z].map(|c| ks.coord_to_key_at_depth_unchecked(f64::from(c), d)))
            }
        }))
    }

    /// `(True, key)` for a point inside the map, else `(False, None)`.
    #[pyo3(signature = (coord, depth=None))]
    fn coordToKeyChecked<'py>(
        &self,
        py: Python<'py>,
        coord: &Bound<'py, PyAny>,
        depth: Option<u32>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let p = convert::point(coord, "coord")?;
        let d = match depth {
            None => 16,
            Some(d) => match depth_arg(d)? {
                0 => 16,
                d => d,
            },
        };
        let key = self.tree.key_space().key_at_depth(p, d);
        match key {
            Ok(k) => PyTuple::new(
                py,
                [true.into_pyobject(py)?.to_owned().into_any(), Bound::new(py, OcTreeKey::from(k))?.into_any()],
            ),
            Err(_) => PyTuple::new(py, [false.into_pyobject(py)?.to_owned().into_any(), py.None().into_bound(py)]),
        }
    }

    /// Centre of the voxel of `key` (at `depth`, if given), float64 array
    /// of float32 values.
    #[pyo3(signature = (key, depth=None))]
    fn keyToCoord<'py>(
        &self,
        py: Python<'py>,
        key: &Bound<'py, PyAny>,
        depth: Option<u32>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let k = key_arg(key)?;
        let ks = self.tree.key_space();
        let p = match depth {
            None => ks.key_to_point(k),
            Some(d) => ks.key_to_point_at_depth(k, depth_arg(d)?),
        };
        Ok(point_array(py, p))
    }

    /// The key of the node at `depth` that contains `key`.
    fn adjustKeyAtDepth(&self, key: &Bound<'_, PyAny>, depth: u32) -> PyResult<OcTreeKey> {
        let d = depth_arg(depth)?;
        let d = if d == 0 { 16 } else { d };
        Ok(OcTreeKey::from(adjust_key_to_depth(key_arg(key)?, d)))
    }

    // --- sensor model -------------------------------------------------

    /// Probability a hit assigns.
    fn getProbHit(&self) -> f64 {
        probability(f64::from(self.tree.sensor().hit))
    }
    /// Log-odds of a hit.
    fn getProbHitLog(&self) -> f32 {
        self.tree.sensor().hit
    }
    /// Probability a miss assigns.
    fn getProbMiss(&self) -> f64 {
        probability(f64::from(self.tree.sensor().miss))
    }
    /// Log-odds of a miss.
    fn getProbMissLog(&self) -> f32 {
        self.tree.sensor().miss
    }
    /// Upper clamping bound, probability.
    fn getClampingThresMax(&self) -> f64 {
        probability(f64::from(self.tree.sensor().clamping_max))
    }
    /// Upper clamping bound, log-odds.
    fn getClampingThresMaxLog(&self) -> f32 {
        self.tree.sensor().clamping_max
    }
    /// Lower clamping bound, probability.
    fn getClampingThresMin(&self) -> f64 {
        probability(f64::from(self.tree.sensor().clamping_min))
    }
    /// Lower clamping bound, log-odds.
    fn getClampingThresMinLog(&self) -> f32 {
        self.tree.sensor().clamping_min
    }
    /// Occupancy threshold, probability.
    fn getOccupancyThres(&self) -> f64 {
        probability(f64::from(self.tree.sensor().occupancy_threshold))
    }
    /// Occupancy threshold, log-odds.
    fn getOccupancyThresLog(&self) -> f32 {
        self.tree.sensor().occupancy_threshold
    }
    /// Sets the hit probability (in (0, 1), else `ValueError`).
    fn setProbHit(&mut self, prob: f64) -> PyResult<()> {
        self.sensor_set(|s, v| s.hit = v, prob, "setProbHit")
    }
    /// Sets the miss probability.
    fn setProbMiss(&mut self, prob: f64) -> PyResult<()> {
        self.sensor_set(|s, v| s.miss = v, prob, "setProbMiss")
    }
    /// Sets the upper clamping bound.
    fn setClampingThresMax(&mut self, thresProb: f64) -> PyResult<()> {
        self.sensor_set(|s, v| s.clamping_max = v, thresProb, "setClampingThresMax")
    }
    /// Sets the lower clamping bound.
    fn setClampingThresMin(&mut self, thresProb: f64) -> PyResult<()> {
        self.sensor_set(|s, v| s.clamping_min = v, thresProb, "setClampingThresMin")
    }
    /// Sets the occupancy threshold.
    fn setOccupancyThres(&mut self, prob: f64) -> PyResult<()> {
        self.sensor_set(|s, v| s.occupancy_threshold = v, prob, "setOccupancyThres")
    }

    // --- bounding box -------------------------------------------------

    /// Sets the lower corner of the update bounding box.
    fn setBBXMin(&mut self, min: &Bound<'_, PyAny>) -> PyResult<()> {
        self.bbx_min = convert::point(min, "min")?;
        Ok(())
    }
    /// Sets the upper corner of the update bounding box.
    fn setBBXMax(&mut self, max: &Bound<'_, PyAny>) -> PyResult<()> {
        self.bbx_max = convert::point(max, "max")?;
        Ok(())
    }
    /// Limits `insertPointCloud` to the bounding box (or not).
    fn useBBXLimit(&mut self, enable: bool) {
        self.use_bbx = enable;
    }
    /// Is the bounding-box limit on?
    fn bbxSet(&self) -> bool {
        self.use_bbx
    }
    /// Is `p` inside the bounding box (float comparisons, as OctoMap)?
    fn inBBX(&self, p: &Bound<'_, PyAny>) -> PyResult<bool> {
        let p = convert::point(p, "p")?;
        let (lo, hi) = (self.bbx_min, self.bbx_max);
        Ok(p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z)
    }
    /// Lower corner of the bounding box.
    fn getBBXMin<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        point_array(py, self.bbx_min)
    }
    /// Upper corner of the bounding box.
    fn getBBXMax<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        point_array(py, self.bbx_max)
    }
    /// Half extent of the bounding box, `(max - min) / 2`.
    fn getBBXBounds<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        point_array(py, (self.bbx_max - self.bbx_min) * 0.5)
    }
    /// Centre of the bounding box.
    fn getBBXCenter<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        point_array(py, self.bbx_min + (self.bbx_max - self.bbx_min) * 0.5)
    }

    // --- change detection -----------------------------------------------

    /// Starts (or stops) recording which voxels change.
    #[pyo3(signature = (enable=true))]
    fn enableChangeDetection(&mut self, enable: bool) {
        self.change_detection = enable;
        self.tree.set_change_detection(enable);
    }
    /// Is change detection on?
    fn isChangeDetectionEnabled(&self) -> bool {
        self.change_detection
    }
    /// Forgets the changes recorded so far.
    fn resetChangeDetection(&mut self) {
        self.tree.reset_change_detection();
    }
    /// Number of voxels changed since the last reset.
    fn numChangesDetected(&self) -> usize {
        self.tree.changed_keys().len()
    }
    /// The changed voxels as `(key, created)` pairs, sorted by key:
    /// `created` is `True` for new voxels, `False` for voxels whose
    /// occupancy state flipped (OctoMap's `changedKeysBegin()` range).
    fn changedKeys(&self) -> Vec<(OcTreeKey, bool)> {
        self.tree.changed_keys().into_iter().map(|(k, c)| (OcTreeKey::from(k), c)).collect()
    }

    // --- array queries ----------------------------------------------------

    /// Occupancy of each point of an `(N, 3)` array in one call, without
    /// the GIL: `(state, log_odds)` with `state` int8 (-1 unknown: no node
    /// or outside the map, 0 free, 1 occupied) and `log_odds` float32 (NaN
    /// where unknown). `depth` limits the search (None: finest).
    #[pyo3(signature = (points, depth=None))]
    fn occupancy<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        depth: Option<u32>,
    ) -> PyResult<queries::OccupancyArrays<'py>> {
        occupancy_impl(py, &self.tree, points, depth)
    }

    /// Many `castRay`s in one call, in parallel without the GIL: `origins`
    /// is one point or `(N, 3)`, `directions` `(N, 3)`. Returns `(hit,
    /// end)`: bool `(N,)` and float64 `(N, 3)`, the end as `castRay` writes
    /// it (NaN for rays that cannot be cast: origin outside the map, zero
    /// direction). `max_range` ≤ 0 means no limit.
    #[pyo3(signature = (origins, directions, max_range=-1.0, ignore_unknown=false))]
    fn cast_rays<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        max_range: f64,
        ignore_unknown: bool,
    ) -> PyResult<queries::RayArrays<'py>> {
        cast_rays_impl(py, &self.tree, origins, directions, max_range, ignore_unknown)
    }

    /// The leaves as a numpy structured array (fields `x`, `y`, `z`, `size`:
    /// float64; `log_odds`: float32; `depth`: uint8), in iteration order,
    /// down to `max_depth` (None: all levels), optionally only those
    /// overlapping `bbox=(min, max)`.
    #[pyo3(signature = (max_depth=None, bbox=None))]
    fn leaves<'py>(
        &self,
        py: Python<'py>,
        max_depth: Option<u32>,
        bbox: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let d = queries::max_depth(max_depth)?;
        let bbx = bbox.map(|b| queries::key_box(self.tree.key_space(), b)).transpose()?;
        let tree = &self.tree;
        let records = py.detach(|| match bbx {
            Some(b) => queries::leaf_records(tree.leaves_in_box(b, d)),
            None => queries::leaf_records(tree.leaves(d)),
        });
        queries::leaves_array(py, records)
    }

    /// Writes the map as `.bt`, `.ot` or `.olm` by the file's extension
    /// (`.bt`: the maximum-likelihood tree, leaving this tree unchanged).
    fn save(&self, py: Python<'_>, path: &Bound<'_, PyAny>) -> PyResult<()> {
        let path = convert::path(path)?;
        let tree = &self.tree;
        crate::files::save(py, tree, &path)
    }

    fn __repr__(&self) -> String {
        format!(
            "<octolinear.{} resolution={} nodes={}>",
            octolinear::TreeKind::of(self.tree.kind()).id(),
            self.tree.resolution(),
            self.tree.size()
        )
    }
}

/// octomap-python's `castRay` on any map: `end` is filled when the cast
/// starts.
pub fn cast_ray_into<M: queries::Queries>(
    map: &M,
    origin: &Bound<'_, PyAny>,
    direction: &Bound<'_, PyAny>,
    end: &Bound<'_, PyAny>,
    ignore_unknown: bool,
    max_range: f64,
) -> PyResult<bool> {
    let (o, d) = (convert::point(origin, "origin")?, convert::point(direction, "direction")?);
    let opts = CastOptions { ignore_unknown, max_range: (max_range > 0.0).then_some(max_range) };
    match map.cast(o, d, opts) {
        Ok(outcome) => {
            let e = outcome.end();
            for (i, v) in [e.x, e.y, e.z].into_iter().enumerate() {
                end.set_item(i, f64::from(v))?;
            }
            Ok(outcome.hit())
        }
        Err(_) => Ok(false),
    }
}

/// Reads the `.bt` at `path` (helper of `octolinear.read`).
pub fn read_bt_path(py: Python<'_>, path: &Path) -> PyResult<OccupancyTree> {
    py.detach(|| bt::read_file(path)).map_err(|e| convert::tree_file_error(path, e))
}
