//! The `octolinear` Python module: octolinear's occupancy maps from
//! Python. `OcTree` is a drop-in for octomap-python's `octomap.OcTree`
//! (same names, argument order and bit-identical answers and files); the
//! array methods (`occupancy`, `cast_rays`, `leaves`) and the module
//! functions (`read`, `open_mapped`, `read_graph`, `build`, `read_points`)
//! answer whole numpy arrays in one call, without the GIL; `build_tiles`,
//! `plan_tiles`, `write_tile_manifest` and `convert_tiles` build tile sets
//! in parts, which `octolinear.dask` shares among a Dask cluster's workers.

// Python method names follow octomap-python (camelCase), argument names too
#![allow(non_snake_case)]

mod convert;
mod files;
mod kinds;
mod mapped;
mod nodes;
mod octree;
mod queries;
mod tiles;

use pyo3::prelude::*;

pyo3::create_exception!(
    octolinear,
    NullPointerException,
    pyo3::exceptions::PyException,
    "Raised by a node or iterator that refers to nothing (a search that found no node, an iterator at its end), as octomap-python raises it."
);

/// Sets the number of threads insertion and the array queries use (`0`:
/// the default, `RAYON_NUM_THREADS` or one per core; at most 1024). The
/// result of every call is the same for any thread count.
#[pyfunction]
fn set_num_threads(n: usize) -> PyResult<()> {
    queries::check_threads(n)?;
    queries::set_threads(n);
    Ok(())
}

/// The number of threads insertion and the array queries use.
#[pyfunction]
fn get_num_threads() -> usize {
    queries::threads()
}

#[pymodule]
fn _octolinear(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // a mapped file truncated under a call raises OSError instead of
    // killing the interpreter with SIGBUS
    octolinear::mapped::guard_truncated_files()
        .map_err(|e| pyo3::exceptions::PyOSError::new_err(format!("cannot install the SIGBUS handler: {e}")))?;
    m.add_class::<octree::OcTree>()?;
    m.add_class::<kinds::ColorOcTree>()?;
    m.add_class::<kinds::OcTreeStamped>()?;
    m.add_class::<kinds::CountingOcTree>()?;
    m.add_class::<nodes::OcTreeKey>()?;
    m.add_class::<nodes::OcTreeNode>()?;
    m.add_class::<nodes::NodeIterator>()?;
    m.add_class::<mapped::MappedOcTree>()?;
    m.add("NullPointerException", m.py().get_type::<NullPointerException>())?;
    m.add_function(wrap_pyfunction!(files::read, m)?)?;
    m.add_function(wrap_pyfunction!(files::read_graph, m)?)?;
    m.add_function(wrap_pyfunction!(files::build, m)?)?;
    m.add_function(wrap_pyfunction!(files::read_points, m)?)?;
    m.add_function(wrap_pyfunction!(mapped::open_mapped, m)?)?;
    m.add_function(wrap_pyfunction!(tiles::build_tiles, m)?)?;
    m.add_function(wrap_pyfunction!(tiles::plan_tiles, m)?)?;
    m.add_function(wrap_pyfunction!(tiles::write_tile_manifest, m)?)?;
    m.add_function(wrap_pyfunction!(tiles::convert_tiles, m)?)?;
    m.add_function(wrap_pyfunction!(set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(get_num_threads, m)?)?;
    m.add("UNKNOWN", queries::UNKNOWN)?;
    m.add("FREE", queries::FREE)?;
    m.add("OCCUPIED", queries::OCCUPIED)?;
    Ok(())
}
