//! Array conversion between NumPy (row-major) and the flat row-major buffers of
//! the Rust side. Every input is shape-checked first; a bad shape raises
//! `ShapeError` naming the argument, the expected and the received shape.

use numpy::ndarray::ArrayView2;
use numpy::{
    AllowTypeChange, PyArray, PyArray1, PyArrayDyn, PyArrayLikeDyn, PyArrayMethods,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::{NonFiniteError, ShapeError};

/// One expected dimension: a fixed size or any size (named, e.g. "T").
#[derive(Clone, Copy)]
pub enum Dim {
    /// Exactly this size.
    Is(usize),
    /// Any size ≥ 1, shown with this name.
    Any(&'static str),
}

fn shape_str(dims: &[Dim]) -> String {
    let parts: Vec<String> = dims
        .iter()
        .map(|d| match d {
            Dim::Is(n) => n.to_string(),
            Dim::Any(s) => (*s).to_string(),
        })
        .collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

fn got_str(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(ToString::to_string).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// `ShapeError` unless `shape` matches `dims`.
fn check_shape(name: &str, dims: &[Dim], shape: &[usize]) -> PyResult<()> {
    let ok = shape.len() == dims.len()
        && shape.iter().zip(dims).all(|(s, d)| match d {
            Dim::Is(n) => s == n,
            Dim::Any(_) => *s >= 1,
        });
    if ok {
        Ok(())
    } else {
        Err(ShapeError::new_err(format!(
            "{name}: expected shape {}, got {}",
            shape_str(dims),
            got_str(shape)
        )))
    }
}

/// Converts any array-like to float64 and checks its shape; returns the values in
/// row-major order and the actual shape.
///
/// A C-contiguous float64 NumPy array (what streaming callers pass on every step)
/// is read directly: one type check and one copy, without the general array-like
/// conversion and its shared-borrow bookkeeping. Every other input goes through
/// the general path; both give the same values and the same errors.
pub fn f64_array(
    obj: &Bound<'_, PyAny>,
    name: &str,
    dims: &[Dim],
) -> PyResult<(Vec<f64>, Vec<usize>)> {
    if let Ok(a) = obj.downcast::<PyArrayDyn<f64>>() {
        if a.is_c_contiguous() {
            check_shape(name, dims, a.shape())?;
            check_copy(name, a.shape())?;
            // C-contiguous: the memory order is the row-major order.
            if let Ok(v) = a.to_vec() {
                return Ok((v, a.shape().to_vec()));
            }
        }
    }
    refuse_complex(obj, name)?;
    // An array's size is known before NumPy converts or copies it.
    if let Ok(shape) = obj.getattr("shape").and_then(|s| s.extract::<Vec<usize>>()) {
        check_copy(name, &shape)?;
    }
    let arr: PyArrayLikeDyn<'_, f64, AllowTypeChange> = obj.extract().map_err(|e| {
        ShapeError::new_err(format!(
            "{name}: expected a float array of shape {}, got an object that cannot be converted to float64 ({e})",
            shape_str(dims)
        ))
    })?;
    let shape = arr.shape().to_vec();
    check_shape(name, dims, &shape)?;
    check_copy(name, &shape)?;
    Ok((arr.as_array().iter().copied().collect(), shape))
}

/// `SizeError` when a copy of a float64 array of `shape` does not fit in the
/// memory available.
fn check_copy(name: &str, shape: &[usize]) -> PyResult<()> {
    use crate::errors::IntoPyResult;
    edccif_sim::limits::check_memory(
        || format!("{name} of shape {}", got_str(shape)),
        edccif_sim::limits::product(shape).saturating_mul(8),
    )
    .py()
}

/// An `ArgumentTypeError` for a complex array or scalar (NumPy would drop
/// the imaginary parts when converting to float64).
fn refuse_complex(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<()> {
    let complex = obj.is_instance_of::<pyo3::types::PyComplex>()
        || obj
            .getattr("dtype")
            .and_then(|d| d.getattr("kind"))
            .and_then(|k| k.extract::<String>())
            .is_ok_and(|k| k == "c");
    if complex {
        return Err(crate::errors::argument_type_error(
            obj.py(),
            format!(
                "{name}: expected real numbers, got complex values (their imaginary parts would be lost); pass the real part (.real) if that is what is meant"
            ),
        ));
    }
    Ok(())
}

/// Like [`f64_array`], and every value must be finite.
pub fn finite_array(
    obj: &Bound<'_, PyAny>,
    name: &str,
    dims: &[Dim],
) -> PyResult<(Vec<f64>, Vec<usize>)> {
    let (v, s) = f64_array(obj, name, dims)?;
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(NonFiniteError::new_err(format!(
            "{name}: all values must be finite, got {} at flat index {i}",
            v[i]
        )));
    }
    Ok((v, s))
}

/// A boolean mask of the given shape (any array-like of bools or 0/1 numbers).
pub fn bool_array(obj: &Bound<'_, PyAny>, name: &str, dims: &[Dim]) -> PyResult<Vec<bool>> {
    let (v, _) = f64_array(obj, name, dims)?;
    if let Some(x) = v.iter().find(|x| **x != 0.0 && **x != 1.0) {
        return Err(ShapeError::new_err(format!(
            "{name}: expected booleans (0/1), got {x}"
        )));
    }
    Ok(v.into_iter().map(|x| x != 0.0).collect())
}

/// A float64 NumPy array of the given shape from row-major values.
pub fn to_numpy<'py>(
    py: Python<'py>,
    v: Vec<f64>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    PyArray1::from_vec(py, v).reshape(shape.to_vec())
}

/// A `(rows, cols)` float64 NumPy array, owned by NumPy, with the row-major
/// values `v` copied in: one array object instead of [`to_numpy`]'s two (a flat
/// array over the Rust buffer, then its reshaped view). For the small arrays a
/// streaming call returns; large results keep [`to_numpy`], which does not copy.
pub fn small_to_numpy2<'py>(
    py: Python<'py>,
    v: &[f64],
    rows: usize,
    cols: usize,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let view = ArrayView2::from_shape((rows, cols), v).map_err(|e| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "{} values do not fill shape ({rows}, {cols}): {e}",
            v.len()
        ))
    })?;
    Ok(PyArray::from_array(py, &view).to_dyn().clone())
}

/// A bool NumPy array of the given shape from row-major values.
pub fn to_numpy_bool<'py>(
    py: Python<'py>,
    v: Vec<bool>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
    PyArray1::from_vec(py, v).reshape(shape.to_vec())
}

/// A graph's neighbour lists as Python sees them: `(offsets, indices,
/// weights)`, int64 `(N + 1,)`, int64 `(E,)` and float64 `(E,)` NumPy arrays
/// (the CSR form `scipy.sparse.csr_array((weights, indices, offsets))` takes).
pub fn neighbours_to_py<'py>(
    py: Python<'py>,
    g: &edccif_sim::topology::NeighbourLists,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let (offsets, indices, weights) = g.parts();
    let ints = |v: &[usize]| PyArray1::from_vec(py, v.iter().map(|&i| i as i64).collect());
    pyo3::types::PyTuple::new(
        py,
        [
            ints(offsets).into_any(),
            ints(indices).into_any(),
            PyArray1::from_slice(py, weights).into_any(),
        ],
    )
}
