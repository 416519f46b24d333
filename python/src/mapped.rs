//! `octolinear.open_mapped`: an `.olm` map queried in place, memory-mapped.

use crate::convert;
use crate::nodes::{node_value, OcTreeKey, OcTreeNode};
use crate::octree::{cast_ray_into, cast_rays_impl, labels_impl, occupancy_impl, tree_object};
use crate::queries;
use numpy::PyArray1;
use octolinear::mapped::{MapView, MappedMap};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A memory-mapped `.olm` map: opening reads the header only (O(1)), the
/// nodes are read from the page cache as queries reach them. Read-only:
/// `search`, `getLabels`, `castRay`, `occupancy`, `cast_rays`, `leaves`;
/// `to_tree()` loads it into an `OcTree` for anything else. Answers are
/// trustworthy for files octolinear wrote; `verify()` checks every byte of
/// a file that may be damaged. A file truncated in place while mapped makes
/// the call that finds it so, and every later one, raise `OSError` naming
/// the file.
#[pyclass(module = "octolinear", frozen)]
pub struct MappedOcTree {
    map: MappedMap<memmap2::Mmap>,
    path: std::path::PathBuf,
}

impl MappedOcTree {
    /// The map's view, unless its file was found truncated.
    fn view(&self) -> PyResult<MapView<'_>> {
        self.intact()?;
        Ok(self.map.view())
    }

    /// `OSError` once a read found the file truncated under the mapping.
    fn intact(&self) -> PyResult<()> {
        self.map.check_mapping().map_err(|e| convert::truncated_error(&e))
    }

    /// `answer`, unless the file was found truncated while it was computed
    /// (then it came from zeros).
    fn checked<T>(&self, answer: PyResult<T>) -> PyResult<T> {
        self.intact()?;
        answer
    }
}

/// Opens an `.olm` map memory-mapped (header checks only, O(1)); with
/// `verify=True` every byte is checked first (`ValueError` if damaged).
#[pyfunction]
#[pyo3(signature = (path, verify=false))]
pub fn open_mapped(py: Python<'_>, path: &Bound<'_, PyAny>, verify: bool) -> PyResult<MappedOcTree> {
    let path = convert::path(path)?;
    let map = py.detach(|| octolinear::mapped::open(&path)).map_err(|e| convert::olm_error(&path, e))?;
    if verify {
        py.detach(|| map.verify()).map_err(|e| convert::olm_error(&path, e))?;
    }
    map.check_mapping().map_err(|e| convert::truncated_error(&e))?;
    Ok(MappedOcTree { map, path })
}

#[pymethods]
impl MappedOcTree {
    /// The node at a key or point, down to `depth` (0: finest); a null
    /// node if there is none.
    #[pyo3(signature = (value, depth=0))]
    fn search(&self, value: &Bound<'_, PyAny>, depth: u32) -> PyResult<OcTreeNode> {
        let depth = queries::max_depth(Some(depth))?;
        let view = self.view()?;
        let key = match value.cast::<OcTreeKey>() {
            Ok(k) => Some(k.borrow().key()),
            Err(_) => view.key(convert::point(value, "value")?).ok(),
        };
        let found = key.and_then(|k| view.search(k, depth));
        self.checked(Ok(found.map_or_else(OcTreeNode::null, OcTreeNode::from_found)))
    }

    /// Is the node (from `search`) occupied?
    fn isNodeOccupied(&self, node: &Bound<'_, PyAny>) -> PyResult<bool> {
        Ok(self.view()?.is_occupied(node_value(node)?))
    }

    /// As `OcTree.getLabels`.
    fn getLabels<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<i32>>> {
        self.checked(labels_impl(py, &self.view()?, points))
    }

    /// As `OcTree.castRay` (a counting map has no occupancy: `False`).
    #[pyo3(signature = (origin, direction, end, ignoreUnknownCells=false, maxRange=-1.0))]
    fn castRay(
        &self,
        origin: &Bound<'_, PyAny>,
        direction: &Bound<'_, PyAny>,
        end: &Bound<'_, PyAny>,
        ignoreUnknownCells: bool,
        maxRange: f64,
    ) -> PyResult<bool> {
        self.checked(cast_ray_into(&self.view()?, origin, direction, end, ignoreUnknownCells, maxRange))
    }

    /// As `OcTree.occupancy`.
    #[pyo3(signature = (points, depth=None))]
    fn occupancy<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        depth: Option<u32>,
    ) -> PyResult<queries::OccupancyArrays<'py>> {
        self.checked(occupancy_impl(py, &self.view()?, points, depth))
    }

    /// As `OcTree.cast_rays`.
    #[pyo3(signature = (origins, directions, max_range=-1.0, ignore_unknown=false))]
    fn cast_rays<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        max_range: f64,
        ignore_unknown: bool,
    ) -> PyResult<queries::RayArrays<'py>> {
        self.checked(cast_rays_impl(py, &self.view()?, origins, directions, max_range, ignore_unknown))
    }

    /// As `OcTree.leaves`.
    #[pyo3(signature = (max_depth=None, bbox=None))]
    fn leaves<'py>(
        &self,
        py: Python<'py>,
        max_depth: Option<u32>,
        bbox: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let d = queries::max_depth(max_depth)?;
        let view = self.view()?;
        let bbx = bbox.map(|b| queries::key_box(view.key_space(), b)).transpose()?;
        let records = py.detach(|| match bbx {
            Some(b) => queries::leaf_records(view.leaves_in_box(b, d)),
            None => queries::leaf_records(view.leaves(d)),
        });
        self.intact()?;
        queries::leaves_array(py, records)
    }

    /// Voxel edge length, metres.
    fn getResolution(&self) -> PyResult<f64> {
        Ok(self.view()?.resolution())
    }

    /// OctoMap's `size()` of the tree that was written.
    fn size(&self) -> PyResult<u64> {
        Ok(self.view()?.size_counter())
    }

    /// The OctoMap type name, as bytes.
    fn getTreeType<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyBytes>> {
        Ok(pyo3::types::PyBytes::new(py, self.view()?.kind().id().as_bytes()))
    }

    /// Checks every byte (checksums, index, structure); returns counts as
    /// a dict, raises `ValueError` naming the damage.
    fn verify<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.intact()?;
        let r = py.detach(|| self.map.verify()).map_err(|e| convert::olm_error(&self.path, e))?;
        let d = PyDict::new(py);
        d.set_item("nodes", r.nodes)?;
        d.set_item("inner_nodes", r.inner_nodes)?;
        d.set_item("leaves", r.leaves)?;
        d.set_item("max_depth", r.max_depth)?;
        d.set_item("checked_bytes", r.checked_bytes)?;
        Ok(d)
    }

    /// Loads the map into memory as an `OcTree` (verifying it).
    fn to_tree<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.intact()?;
        let t = py.detach(|| self.map.to_tree()).map_err(|e| convert::olm_error(&self.path, e))?;
        tree_object(py, t)
    }

    fn __repr__(&self) -> String {
        // the header's parsed copy: readable after a truncation too
        let v = self.map.view();
        format!(
            "<octolinear.MappedOcTree {} {} resolution={} nodes={}>",
            self.path.display(),
            v.kind().id(),
            v.resolution(),
            v.node_count()
        )
    }
}
