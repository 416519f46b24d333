//! Python arguments to library values and library errors to Python
//! exceptions: point arrays, single points, paths, file errors.

use numpy::{PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use octolinear::Point3;
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError, PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyString};
use rayon::prelude::*;
use std::borrow::Cow;
use std::io;
use std::path::PathBuf;

/// Rows from which a C-contiguous `float64` array is converted on the
/// threads `set_num_threads` allows: a lidar scan's conversion is a few
/// percent of its insertion.
const PARALLEL_ROWS: usize = 1 << 15;

/// An `N×3` array of points as the caller gave it, kept borrowed so that
/// the conversion to the library's float points can run without the GIL
/// and, for a C-contiguous `float32` array, without a copy.
pub enum PointsArg<'py> {
    /// `float64` in any memory order (converted per point, `f64 as f32`
    /// rounding to nearest like OctoMap's `(float)` cast).
    F64(PyReadonlyArray2<'py, f64>),
    /// `float32` in any memory order.
    F32(PyReadonlyArray2<'py, f32>),
}

/// Views of a [`PointsArg`]'s data that can cross into a GIL-free closure.
pub enum PointsView<'a> {
    /// A C-contiguous `float32` array, seen as points in place.
    Points(&'a [Point3]),
    /// A C-contiguous `float64` array, `[x0, y0, z0, x1, ...]`.
    F64Flat(&'a [f64]),
    /// Any other `float64` array: read element by element.
    F64(numpy::ndarray::ArrayView2<'a, f64>),
    /// A non-contiguous `float32` array.
    F32(numpy::ndarray::ArrayView2<'a, f32>),
}

impl<'py> PointsArg<'py> {
    /// Accepts a numpy array of shape `(N, 3)` and dtype `float64` or
    /// `float32`, in any memory order and either byte order (one not the
    /// machine's is copied into the machine's first); any other array-like
    /// is converted with `numpy.asarray(obj, dtype=float64)` first.
    pub fn extract(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Self> {
        let py = obj.py();
        let numpy = py.import("numpy")?;
        let array = if obj.is_instance(&numpy.getattr("ndarray")?)? {
            obj.clone()
        } else {
            numpy.call_method1("asarray", (obj, numpy.getattr("float64")?)).map_err(|e| {
                PyTypeError::new_err(format!(
                    "{name}: expected an (N, 3) float64 or float32 array, got {} that numpy cannot convert ({e})",
                    type_name(obj)
                ))
            })?
        };
        let dtype = array.getattr("dtype")?.str()?.to_string();
        let shape: Vec<usize> = array.getattr("shape")?.extract()?;
        if shape.len() != 2 || shape[1] != 3 {
            return Err(PyValueError::new_err(format!("{name}: expected shape (N, 3), got {}", shape_text(&shape))));
        }
        // a float array in the other byte order (`>f8` on a little-endian
        // machine): a copy in the machine's order, same precision
        let kind = array.getattr("dtype")?;
        let array =
            if kind.getattr("kind")?.extract::<String>()? == "f" && !kind.getattr("isnative")?.extract::<bool>()? {
                array.call_method1("astype", (kind.call_method1("newbyteorder", ("=",))?,))?
            } else {
                array
            };
        if let Ok(a) = array.cast::<PyArray2<f64>>() {
            return Ok(PointsArg::F64(a.try_readonly().map_err(borrow_error)?));
        }
        if let Ok(a) = array.cast::<PyArray2<f32>>() {
            return Ok(PointsArg::F32(a.try_readonly().map_err(borrow_error)?));
        }
        Err(PyTypeError::new_err(format!("{name}: expected dtype float64 or float32, got {dtype}")))
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        match self {
            PointsArg::F64(a) => a.shape()[0],
            PointsArg::F32(a) => a.shape()[0],
        }
    }

    /// The data, for use without the GIL.
    pub fn view(&self) -> PointsView<'_> {
        match self {
            // `as_slice` also takes Fortran order, which is not `[x0, y0, z0, ...]`
            PointsArg::F64(a) => match a.as_slice() {
                Ok(flat) if a.is_c_contiguous() => PointsView::F64Flat(flat),
                _ => PointsView::F64(a.as_array()),
            },
            PointsArg::F32(a) => match a.as_slice() {
                Ok(flat) if a.is_c_contiguous() => PointsView::Points(as_points(flat)),
                _ => PointsView::F32(a.as_array()),
            },
        }
    }
}

impl PointsView<'_> {
    /// Number of points.
    pub fn len(&self) -> usize {
        match self {
            PointsView::Points(p) => p.len(),
            PointsView::F64Flat(f) => f.len() / 3,
            PointsView::F64(a) => a.nrows(),
            PointsView::F32(a) => a.nrows(),
        }
    }

    /// The points as the library takes them, borrowed when they already
    /// are in that form.
    pub fn points(&self) -> Cow<'_, [Point3]> {
        self.range(0..self.len())
    }

    /// The points of rows `rows`, borrowed when they already are points.
    pub fn range(&self, rows: std::ops::Range<usize>) -> Cow<'_, [Point3]> {
        let narrow = |r: numpy::ndarray::ArrayView1<'_, f64>| Point3::new(r[0] as f32, r[1] as f32, r[2] as f32);
        match self {
            PointsView::Points(p) => Cow::Borrowed(&p[rows]),
            PointsView::F64Flat(f) => {
                let flat = &f[3 * rows.start..3 * rows.end];
                let point = |c: &[f64]| Point3::new(c[0] as f32, c[1] as f32, c[2] as f32);
                if rows.len() >= PARALLEL_ROWS && crate::queries::threads() > 1 {
                    Cow::Owned(flat.par_chunks_exact(3).map(point).collect())
                } else {
                    Cow::Owned(flat.chunks_exact(3).map(point).collect())
                }
            }
            PointsView::F64(a) => Cow::Owned(rows.map(|i| narrow(a.row(i))).collect()),
            PointsView::F32(a) => Cow::Owned(rows.map(|i| Point3::new(a[[i, 0]], a[[i, 1]], a[[i, 2]])).collect()),
        }
    }
}

/// A C-contiguous `[x0, y0, z0, x1, ...]` float slice as points.
fn as_points(flat: &[f32]) -> &[Point3] {
    // `extract` checked the shape (N, 3), so the length is a multiple of 3
    debug_assert_eq!(flat.len() % 3, 0);
    // SAFETY: `Point3` is `#[repr(C)]` with three `f32` fields, so it has
    // the size of `[f32; 3]` and the alignment of `f32`; the slice holds
    // `len / 3` whole triples and the result borrows it for its lifetime.
    unsafe { std::slice::from_raw_parts(flat.as_ptr().cast::<Point3>(), flat.len() / 3) }
}

/// The error of an array that is already borrowed mutably elsewhere.
fn borrow_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("the array cannot be read: {e}"))
}

fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")),
    }
}

/// The Python type name of `obj`, for messages.
pub fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type().name().map_or_else(|_| "?".to_string(), |n| n.to_string())
}

/// Three numbers from any sequence of length 3 (a numpy array of any
/// numeric dtype, a list, a tuple).
pub fn triple(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 3]> {
    let bad = || PyTypeError::new_err(format!("{name}: expected 3 numbers (x, y, z), got {}", type_name(obj)));
    if obj.is_instance_of::<PyString>() || obj.is_instance_of::<PyBytes>() {
        return Err(bad());
    }
    let len = obj.len().map_err(|_| bad())?;
    if len != 3 {
        return Err(PyValueError::new_err(format!("{name}: expected 3 numbers (x, y, z), got {len}")));
    }
    let mut v = [0.0; 3];
    for (i, slot) in v.iter_mut().enumerate() {
        *slot = obj.get_item(i)?.extract::<f64>().map_err(|_| bad())?;
    }
    Ok(v)
}

/// [`triple`] as a float point (OctoMap's `point3d(x, y, z)`).
pub fn point(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Point3> {
    let [x, y, z] = triple(obj, name)?;
    Ok(Point3::new(x as f32, y as f32, z as f32))
}

/// A file name given as `str`, `bytes` or `os.PathLike`.
pub fn path(obj: &Bound<'_, PyAny>) -> PyResult<PathBuf> {
    if let Ok(b) = obj.cast::<PyBytes>() {
        use std::os::unix::ffi::OsStrExt;
        return Ok(PathBuf::from(std::ffi::OsStr::from_bytes(b.as_bytes())));
    }
    obj.extract::<PathBuf>().map_err(|_| {
        PyTypeError::new_err(format!("expected a file name (str, bytes or os.PathLike), got {}", type_name(obj)))
    })
}

/// An I/O error on `path` as the matching `OSError` subclass, the path in
/// the message.
pub fn io_error(path: &std::path::Path, e: &io::Error) -> PyErr {
    if let Some(t) = e.get_ref().and_then(|inner| inner.downcast_ref::<octolinear::mapped::Truncated>()) {
        return truncated_error(t);
    }
    let msg = format!("{}: {e}", path.display());
    match e.kind() {
        io::ErrorKind::NotFound => PyFileNotFoundError::new_err(msg),
        io::ErrorKind::PermissionDenied => PyPermissionError::new_err(msg),
        io::ErrorKind::IsADirectory => PyIsADirectoryError::new_err(msg),
        _ => PyOSError::new_err(msg),
    }
}

/// A map file that could not be read: `OSError` for I/O, `ValueError` for
/// content, the path in the message.
pub fn tree_file_error(path: &std::path::Path, e: octolinear::TreeFileError) -> PyErr {
    match e {
        octolinear::TreeFileError::Io(io) => io_error(path, &io),
        other => PyValueError::new_err(format!("{}: {other}", path.display())),
    }
}

/// A mapped file found truncated under the reader, as `OSError` (the
/// message names the file).
pub fn truncated_error(e: &octolinear::mapped::Truncated) -> PyErr {
    PyOSError::new_err(e.to_string())
}

/// An `.olm` file that could not be opened or read.
pub fn olm_error(path: &std::path::Path, e: octolinear::OlmError) -> PyErr {
    match e {
        octolinear::OlmError::Io(io) => io_error(path, &io),
        octolinear::OlmError::Truncated(t) => truncated_error(&t),
        other => PyValueError::new_err(format!("{}: {other}", path.display())),
    }
}
