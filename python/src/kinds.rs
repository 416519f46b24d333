//! The other tree types of OctoMap: `ColorOcTree`, `OcTreeStamped` (both
//! an `OcTree` with a colour or a time stamp per node) and
//! `CountingOcTree` (hit counts, no occupancy).

use crate::convert;
use crate::nodes::{OcTreeKey, OcTreeNode};
use crate::octree::OcTree;
use numpy::{IntoPyArray, PyArray2, PyArrayMethods};
use octolinear::formats::ot;
use octolinear::{CountingTree, Key, NodeKind};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The key of a key-or-point argument, `None` outside the map.
fn key_or_point(keys: &octolinear::KeySpace, value: &Bound<'_, PyAny>) -> PyResult<Option<Key>> {
    if let Ok(k) = value.cast::<OcTreeKey>() {
        return Ok(Some(k.borrow().key()));
    }
    Ok(keys.key(convert::point(value, "value")?).ok())
}

/// An `OcTree` with an RGB colour per node (OctoMap's `ColorOcTree`).
/// Insertion applies updates in OctoMap's order, so colours blend exactly
/// as there; inner colours are averaged by `updateInnerOccupancy()`.
#[pyclass(extends = OcTree, module = "octolinear")]
pub struct ColorOcTree;

impl ColorOcTree {
    fn color_op(
        mut slf: PyRefMut<'_, Self>,
        value: &Bound<'_, PyAny>,
        rgb: [u8; 3],
        op: fn(&mut octolinear::OccupancyTree, Key, [u8; 3]) -> Option<[u8; 3]>,
    ) -> PyResult<OcTreeNode> {
        let base = slf.as_super();
        let Some(key) = key_or_point(base.tree.key_space(), value)? else {
            return Ok(OcTreeNode::null());
        };
        if op(&mut base.tree, key, rgb).is_none() {
            return Ok(OcTreeNode::null());
        }
        Ok(base.tree.search(key, 0).map_or_else(OcTreeNode::null, OcTreeNode::from_found))
    }
}

#[pymethods]
impl ColorOcTree {
    #[new]
    fn py_new(resolution: f64) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(OcTree::with_kind(resolution, NodeKind::Color)?).add_subclass(ColorOcTree))
    }

    /// Sets the colour of the voxel at a key or point, if it exists; returns
    /// the node (null if there is none).
    fn setNodeColor(slf: PyRefMut<'_, Self>, value: &Bound<'_, PyAny>, r: u8, g: u8, b: u8) -> PyResult<OcTreeNode> {
        Self::color_op(slf, value, [r, g, b], octolinear::OccupancyTree::set_color)
    }

    /// Averages a colour into the voxel's colour.
    fn averageNodeColor(
        slf: PyRefMut<'_, Self>,
        value: &Bound<'_, PyAny>,
        r: u8,
        g: u8,
        b: u8,
    ) -> PyResult<OcTreeNode> {
        Self::color_op(slf, value, [r, g, b], octolinear::OccupancyTree::average_color)
    }

    /// Blends a colour into the voxel's colour, weighted by its occupancy.
    fn integrateNodeColor(
        slf: PyRefMut<'_, Self>,
        value: &Bound<'_, PyAny>,
        r: u8,
        g: u8,
        b: u8,
    ) -> PyResult<OcTreeNode> {
        Self::color_op(slf, value, [r, g, b], octolinear::OccupancyTree::integrate_color)
    }
}

/// An `OcTree` with the time of the last update per node (OctoMap's
/// `OcTreeStamped`).
#[pyclass(extends = OcTree, module = "octolinear")]
pub struct OcTreeStamped;

#[pymethods]
impl OcTreeStamped {
    #[new]
    fn py_new(resolution: f64) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(OcTree::with_kind(resolution, NodeKind::Stamped)?).add_subclass(OcTreeStamped))
    }

    /// Time stamp of the root: the last update anywhere (0 if empty).
    fn getLastUpdateTime(slf: PyRef<'_, Self>) -> u32 {
        slf.as_super().tree.last_update_time().unwrap_or(0)
    }

    /// Turns voxels not updated for `time_thres` seconds to free by one
    /// miss (OctoMap's `degradeOutdatedNodes`).
    fn degradeOutdatedNodes(mut slf: PyRefMut<'_, Self>, time_thres: u32) {
        slf.as_super().tree.degrade_outdated_nodes(time_thres);
    }
}

/// Hit counts per voxel (OctoMap's `CountingOcTree`): no occupancy.
#[pyclass(module = "octolinear")]
pub struct CountingOcTree {
    tree: CountingTree,
}

impl CountingOcTree {
    /// Wraps a counting tree.
    pub fn from_tree(tree: CountingTree) -> Self {
        CountingOcTree { tree }
    }
}

#[pymethods]
impl CountingOcTree {
    #[new]
    fn py_new(resolution: f64) -> PyResult<Self> {
        Ok(Self::from_tree(CountingTree::new(resolution).map_err(|e| PyValueError::new_err(e.to_string()))?))
    }

    /// Counts one hit at a key or point; returns the voxel's new count
    /// (`None` for a point outside the map).
    fn updateNode(&mut self, value: &Bound<'_, PyAny>) -> PyResult<Option<u32>> {
        Ok(key_or_point(self.tree.key_space(), value)?.map(|k| self.tree.update(k)))
    }

    /// The count of the node at a key or point (`None` if there is none).
    #[pyo3(signature = (value, depth=0))]
    fn search(&self, value: &Bound<'_, PyAny>, depth: u32) -> PyResult<Option<u32>> {
        let depth = crate::queries::max_depth(Some(depth))?;
        Ok(key_or_point(self.tree.key_space(), value)?.and_then(|k| self.tree.count(k, depth)))
    }

    /// Centres of the voxels counted at least `min_hits` times, `(N, 3)`.
    fn getCentersMinHits<'py>(&self, py: Python<'py>, min_hits: u32) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let c = self.tree.centers_min_hits(min_hits);
        let n = c.len();
        let flat: Vec<f64> = c.iter().flat_map(|p| [p.x, p.y, p.z].map(f64::from)).collect();
        flat.into_pyarray(py).reshape([n, 3])
    }

    /// Voxel edge length, metres.
    fn getResolution(&self) -> f64 {
        self.tree.resolution()
    }

    /// Number of nodes.
    fn size(&self) -> usize {
        self.tree.size()
    }

    /// Writes the `.ot` map to `filename` (returns `True`) or returns its bytes.
    #[pyo3(signature = (filename=None))]
    fn write<'py>(&self, py: Python<'py>, filename: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyAny>> {
        crate::octree::write_to(py, filename, &self.tree, |t, w| ot::write_counting(t, w))
    }
}
