//! Keys, nodes and node iterators as octomap-python shows them.

use crate::NullPointerException;
use numpy::{IntoPyArray, PyArray1};
use octolinear::key::adjust_key_to_depth;
use octolinear::sensor::probability;
use octolinear::tree::unpack_rgb;
use octolinear::tree::NodeKind;
use octolinear::{Found, Key, KeySpace, NodeItem, OccupancyTree};
use pyo3::exceptions::{PyIndexError, PyNotImplementedError, PyTypeError};
use pyo3::prelude::*;
use pyo3::pyclass::CompareOp;

/// A voxel address: three 16-bit cell indices (OctoMap's `OcTreeKey`).
/// Indexable (`key[0]`), comparable with any sequence of three ints.
#[pyclass(module = "octolinear", from_py_object)]
#[derive(Clone)]
pub struct OcTreeKey {
    k: [u16; 3],
}

impl OcTreeKey {
    /// The library key.
    pub fn key(&self) -> Key {
        Key(self.k)
    }
}

impl From<Key> for OcTreeKey {
    fn from(k: Key) -> Self {
        OcTreeKey { k: k.0 }
    }
}

fn key_index(i: isize) -> PyResult<usize> {
    match i {
        0..=2 => Ok(i as usize),
        -3..=-1 => Ok((i + 3) as usize),
        _ => Err(PyIndexError::new_err(format!("key index {i} out of range 0..3"))),
    }
}

#[pymethods]
impl OcTreeKey {
    /// `OcTreeKey()` is `(0, 0, 0)`; `OcTreeKey(a, b, c)` sets the cells.
    #[new]
    #[pyo3(signature = (a=0, b=0, c=0))]
    fn py_new(a: u16, b: u16, c: u16) -> Self {
        OcTreeKey { k: [a, b, c] }
    }

    fn __getitem__(&self, i: isize) -> PyResult<u16> {
        Ok(self.k[key_index(i)?])
    }

    fn __setitem__(&mut self, i: isize, v: u16) -> PyResult<()> {
        self.k[key_index(i)?] = v;
        Ok(())
    }

    fn __len__(&self) -> usize {
        3
    }

    fn __richcmp__(&self, other: &Bound<'_, PyAny>, op: CompareOp) -> PyResult<Py<PyAny>> {
        let py = other.py();
        let other: Option<[u16; 3]> =
            other.cast::<OcTreeKey>().map(|k| k.borrow().k).ok().or_else(|| other.extract().ok());
        Ok(match (op, other) {
            (CompareOp::Eq, Some(o)) => (self.k == o).into_pyobject(py)?.to_owned().into_any().unbind(),
            (CompareOp::Ne, Some(o)) => (self.k != o).into_pyobject(py)?.to_owned().into_any().unbind(),
            _ => py.NotImplemented(),
        })
    }

    fn __hash__(&self) -> u64 {
        Key(self.k).packed()
    }

    fn __repr__(&self) -> String {
        format!("OcTreeKey({}, {}, {})", self.k[0], self.k[1], self.k[2])
    }
}

/// A node as a search or an update found it: a snapshot of its value, not
/// a live reference (a later update of the tree does not change it). A
/// null node (nothing found) raises `NullPointerException` from every
/// method, as octomap-python's does, and is falsy.
#[pyclass(module = "octolinear", frozen)]
pub struct OcTreeNode {
    value: Option<f32>,
    has_children: bool,
    extra: u32,
}

impl OcTreeNode {
    /// Nothing found.
    pub fn null() -> Self {
        OcTreeNode { value: None, has_children: false, extra: 0 }
    }
    /// A found node.
    pub fn from_found(f: Found) -> Self {
        OcTreeNode { value: Some(f.value), has_children: !f.is_leaf, extra: f.extra }
    }
    /// A node with or without children; `extra` is its colour or time
    /// stamp (0 for plain trees).
    pub fn with_children(value: f32, has_children: bool, extra: u32) -> Self {
        OcTreeNode { value: Some(value), has_children, extra }
    }
    fn value(&self) -> PyResult<f32> {
        self.value.ok_or_else(|| NullPointerException::new_err("the node is null (nothing was found)"))
    }
}

#[pymethods]
impl OcTreeNode {
    /// Log-odds occupancy.
    fn getValue(&self) -> PyResult<f32> {
        self.value()
    }
    /// Log-odds occupancy.
    fn getLogOdds(&self) -> PyResult<f32> {
        self.value()
    }
    /// Occupancy probability.
    fn getOccupancy(&self) -> PyResult<f64> {
        Ok(probability(f64::from(self.value()?)))
    }
    /// Does the node have children?
    fn hasChildren(&self) -> PyResult<bool> {
        self.value()?;
        Ok(self.has_children)
    }
    /// Colour `(r, g, b)` of a `ColorOcTree` node (white when unset).
    fn getColor(&self) -> PyResult<(u8, u8, u8)> {
        self.value()?;
        let [r, g, b] = unpack_rgb(self.extra);
        Ok((r, g, b))
    }
    /// Time stamp of an `OcTreeStamped` node, seconds.
    fn getTimestamp(&self) -> PyResult<u32> {
        self.value()?;
        Ok(self.extra)
    }
    /// Not available: nodes are snapshots. Use `OcTree.updateNode`.
    #[pyo3(signature = (*_args))]
    fn setValue(&self, _args: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<()> {
        Err(snapshot_error())
    }
    /// Not available: nodes are snapshots. Use `OcTree.updateNode`.
    #[pyo3(signature = (*_args))]
    fn setLogOdds(&self, _args: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<()> {
        Err(snapshot_error())
    }
    /// Not available: nodes are snapshots. Use `OcTree.updateNode(key, value)`.
    #[pyo3(signature = (*_args))]
    fn addValue(&self, _args: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<()> {
        Err(snapshot_error())
    }
    fn __bool__(&self) -> bool {
        self.value.is_some()
    }
    fn __repr__(&self) -> String {
        match self.value {
            Some(v) => format!("<OcTreeNode log_odds={v}>"),
            None => "<OcTreeNode null>".to_string(),
        }
    }
}

fn snapshot_error() -> PyErr {
    PyNotImplementedError::new_err(
        "octolinear nodes are snapshots, not references into the tree: change values with OcTree.updateNode",
    )
}

/// One node of an iterator's list.
#[derive(Clone, Copy)]
struct Item {
    key: Key,
    depth: u8,
    value: f32,
    extra: u32,
    is_leaf: bool,
}

/// octomap-python's `tree_iterator`, `leaf_iterator` and
/// `leaf_bbx_iterator` in one: `for it in tree.begin_leafs(): ...` yields
/// the iterator itself, positioned on each node in turn. The nodes are
/// listed when the iterator is made, so changing the tree meanwhile does
/// not affect it.
#[pyclass(module = "octolinear")]
pub struct NodeIterator {
    items: Vec<Item>,
    keys: KeySpace,
    /// The kind of the tree iterated.
    kind: NodeKind,
    pos: usize,
    started: bool,
}

impl NodeIterator {
    /// Lists the nodes of `iter`, from `tree`.
    pub fn new<'a>(tree: &OccupancyTree, iter: impl Iterator<Item = NodeItem<'a>>) -> Self {
        let items = iter
            .map(|n| Item { key: n.key, depth: n.depth, value: n.value, extra: n.extra, is_leaf: n.is_leaf })
            .collect();
        NodeIterator { items, keys: tree.key_space().clone(), kind: tree.kind(), pos: 0, started: false }
    }
    /// An iterator at its end.
    pub fn empty(tree: &OccupancyTree) -> Self {
        Self::new(tree, std::iter::empty())
    }
    fn current(&self) -> PyResult<&Item> {
        self.items.get(self.pos).ok_or_else(|| NullPointerException::new_err("the iterator is at its end"))
    }
    /// Log-odds of the current node.
    pub fn value(&self) -> PyResult<f32> {
        Ok(self.current()?.value)
    }
}

#[pymethods]
impl NodeIterator {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }
    fn __next__(mut slf: PyRefMut<'_, Self>) -> Option<PyRefMut<'_, Self>> {
        if slf.started {
            slf.pos += 1;
        }
        slf.started = true;
        (slf.pos < slf.items.len()).then_some(slf)
    }
    /// Moves to the next node and returns the iterator (`StopIteration` at
    /// the end).
    fn next(mut slf: PyRefMut<'_, Self>) -> PyResult<PyRefMut<'_, Self>> {
        if slf.pos >= slf.items.len() {
            return Err(pyo3::exceptions::PyStopIteration::new_err(()));
        }
        slf.pos += 1;
        slf.started = true;
        Ok(slf)
    }
    /// Number of nodes listed.
    fn __len__(&self) -> usize {
        self.items.len()
    }
    /// Centre of the current node, float64 array of float32 values.
    fn getCoordinate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let it = self.current()?;
        let p = self.keys.key_to_point_at_depth(it.key, it.depth);
        Ok(vec![f64::from(p.x), f64::from(p.y), f64::from(p.z)].into_pyarray(py))
    }
    /// Centre x (double arithmetic, as OctoMap's `getX`).
    fn getX(&self) -> PyResult<f64> {
        let it = self.current()?;
        Ok(self.keys.key_to_coord_at_depth(it.key.0[0], it.depth))
    }
    /// Centre y.
    fn getY(&self) -> PyResult<f64> {
        let it = self.current()?;
        Ok(self.keys.key_to_coord_at_depth(it.key.0[1], it.depth))
    }
    /// Centre z.
    fn getZ(&self) -> PyResult<f64> {
        let it = self.current()?;
        Ok(self.keys.key_to_coord_at_depth(it.key.0[2], it.depth))
    }
    /// Edge length of the current node, metres.
    fn getSize(&self) -> PyResult<f64> {
        Ok(self.keys.node_size(self.current()?.depth))
    }
    /// Depth of the current node (0 root, 16 voxel).
    fn getDepth(&self) -> PyResult<u8> {
        Ok(self.current()?.depth)
    }
    /// Key of the current node.
    fn getKey(&self) -> PyResult<OcTreeKey> {
        Ok(OcTreeKey::from(self.current()?.key))
    }
    /// Key of the current node adjusted to its depth.
    fn getIndexKey(&self) -> PyResult<OcTreeKey> {
        let it = self.current()?;
        Ok(OcTreeKey::from(adjust_key_to_depth(it.key, it.depth)))
    }
    /// Log-odds of the current node.
    fn getValue(&self) -> PyResult<f32> {
        self.value()
    }
    /// Log-odds of the current node.
    fn getLogOdds(&self) -> PyResult<f32> {
        self.value()
    }
    /// Occupancy probability of the current node.
    fn getOccupancy(&self) -> PyResult<f64> {
        Ok(probability(f64::from(self.value()?)))
    }
    /// Colour `(r, g, b)` of the current node of a `ColorOcTree`
    /// (`TypeError` on another tree's iterator, as octomap-python).
    fn getColor(&self) -> PyResult<(u8, u8, u8)> {
        if self.kind != NodeKind::Color {
            return Err(PyTypeError::new_err("getColor() is only available on ColorOcTree iterators"));
        }
        let [r, g, b] = unpack_rgb(self.current()?.extra);
        Ok((r, g, b))
    }
    /// Time stamp of the current node of an `OcTreeStamped`, seconds.
    fn getTimestamp(&self) -> PyResult<u32> {
        Ok(self.current()?.extra)
    }
    /// Is the current node a leaf (or at the iteration's depth limit)?
    fn isLeaf(&self) -> PyResult<bool> {
        Ok(self.current()?.is_leaf)
    }
}

/// The log-odds of an `OcTreeNode` or of an iterator's current node.
pub fn node_value(node: &Bound<'_, PyAny>) -> PyResult<f32> {
    if let Ok(n) = node.cast::<OcTreeNode>() {
        return n.get().value();
    }
    if let Ok(it) = node.cast::<NodeIterator>() {
        return it.borrow().value();
    }
    Err(PyTypeError::new_err(format!(
        "expected an OcTreeNode or a node iterator, got {}",
        crate::convert::type_name(node)
    )))
}
