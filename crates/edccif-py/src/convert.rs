//! Array conversion between NumPy (row-major) and the flat row-major buffers of
//! the Rust side. Every input is shape-checked first; a bad shape raises
//! `ShapeError` naming the argument, the expected and the received shape.

use numpy::{
    AllowTypeChange, PyArray1, PyArrayDyn, PyArrayLikeDyn, PyArrayMethods, PyUntypedArrayMethods,
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

/// Converts any array-like to float64 and checks its shape; returns the values in
/// row-major order and the actual shape.
pub fn f64_array(
    obj: &Bound<'_, PyAny>,
    name: &str,
    dims: &[Dim],
) -> PyResult<(Vec<f64>, Vec<usize>)> {
    let arr: PyArrayLikeDyn<'_, f64, AllowTypeChange> = obj.extract().map_err(|e| {
        ShapeError::new_err(format!(
            "{name}: expected a float array of shape {}, got an object that cannot be converted to float64 ({e})",
            shape_str(dims)
        ))
    })?;
    let shape = arr.shape().to_vec();
    let ok = shape.len() == dims.len()
        && shape.iter().zip(dims).all(|(s, d)| match d {
            Dim::Is(n) => s == n,
            Dim::Any(_) => *s >= 1,
        });
    if !ok {
        return Err(ShapeError::new_err(format!(
            "{name}: expected shape {}, got {}",
            shape_str(dims),
            got_str(&shape)
        )));
    }
    Ok((arr.as_array().iter().copied().collect(), shape))
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

/// A bool NumPy array of the given shape from row-major values.
pub fn to_numpy_bool<'py>(
    py: Python<'py>,
    v: Vec<bool>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
    PyArray1::from_vec(py, v).reshape(shape.to_vec())
}
