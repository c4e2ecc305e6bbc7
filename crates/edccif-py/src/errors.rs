//! Error mapping: one exception hierarchy rooted in `ValueError`
//! (`EdccifError`); a wrong argument type is `ArgumentTypeError`, a
//! `ParameterError` that is also a `TypeError`.

use pyo3::create_exception;
use pyo3::exceptions::{PyKeyboardInterrupt, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::GILOnceCell;
use pyo3::types::{PyDict, PyType};

create_exception!(
    edccif,
    EdccifError,
    PyValueError,
    "Base of every edccif error (a ValueError)."
);
create_exception!(
    edccif,
    ShapeError,
    EdccifError,
    "An array has the wrong shape."
);
create_exception!(
    edccif,
    NonFiniteError,
    EdccifError,
    "An input holds NaN or infinity where a number is required."
);
create_exception!(
    edccif,
    NotPositiveDefiniteError,
    EdccifError,
    "A covariance or information matrix is not symmetric positive definite."
);
create_exception!(
    edccif,
    GraphError,
    EdccifError,
    "The communication graph is malformed or disconnected."
);
create_exception!(
    edccif,
    ScenarioError,
    EdccifError,
    "A scenario value or file is invalid."
);
create_exception!(
    edccif,
    ParameterError,
    EdccifError,
    "A parameter is out of range."
);
create_exception!(
    edccif,
    SizeError,
    ParameterError,
    "What a call would allocate does not fit in the memory available (the message gives the size and the limit)."
);
create_exception!(
    edccif,
    UnknownAlgorithmError,
    EdccifError,
    "An algorithm name is not one of the rows."
);
create_exception!(
    edccif,
    UnknownOptionError,
    EdccifError,
    "An option name or value is not known."
);

create_exception!(
    edccif,
    WireFormatError,
    EdccifError,
    "A packet is not a valid edccif wire-format packet (truncated, oversized, wrong version, unknown kind, bad dimension or non-finite)."
);

create_exception!(
    edccif,
    ModelError,
    EdccifError,
    "A model's Python callable raised; the original exception is this error's __cause__."
);

/// `edccif.ArgumentTypeError`, built at import (it has two bases, which
/// `create_exception!` cannot give).
static ARGUMENT_TYPE_ERROR: GILOnceCell<Py<PyType>> = GILOnceCell::new();

pub(crate) fn argument_type_error_type(py: Python<'_>) -> PyResult<&Bound<'_, PyType>> {
    ARGUMENT_TYPE_ERROR
        .get_or_try_init(py, || -> PyResult<Py<PyType>> {
            let ns = PyDict::new(py);
            ns.set_item("ParameterError", py.get_type::<ParameterError>())?;
            py.run(
                c"class ArgumentTypeError(ParameterError, TypeError):\n    \"\"\"An argument has the wrong type (a ParameterError, so an EdccifError, and a TypeError).\"\"\"\n    __module__ = 'edccif'\n",
                Some(&ns),
                None,
            )?;
            Ok(ns
                .get_item("ArgumentTypeError")?
                .ok_or_else(|| PyValueError::new_err("ArgumentTypeError was not defined"))?
                .downcast_into::<PyType>()?
                .unbind())
        })
        .map(|t| t.bind(py))
}

/// An `ArgumentTypeError` (a `ParameterError` and a `TypeError`) with `msg`,
/// which names the argument and what was expected.
pub fn argument_type_error(py: Python<'_>, msg: impl Into<String>) -> PyErr {
    let msg = msg.into();
    match argument_type_error_type(py) {
        Ok(t) => PyErr::from_type(t.clone(), msg),
        Err(e) => e,
    }
}

/// Maps a core error to the matching Python exception.
pub fn core_err(e: &edccif_core::Error) -> PyErr {
    core_to_py(e, "")
}

fn core_to_py(e: &edccif_core::Error, prefix: &str) -> PyErr {
    use edccif_core::Error as C;
    let msg = format!("{prefix}{e}");
    match e {
        C::NotPositiveDefinite { .. } | C::NotSymmetric { .. } => {
            NotPositiveDefiniteError::new_err(msg)
        }
        C::NonFinite { .. } => NonFiniteError::new_err(msg),
        C::Dimension { .. } => ShapeError::new_err(msg),
        C::DisconnectedGraph { .. } | C::InvalidGraph { .. } => GraphError::new_err(msg),
        C::InvalidParameter { .. } => ParameterError::new_err(msg),
        _ => EdccifError::new_err(msg),
    }
}

/// Maps a crate error to the matching Python exception.
pub fn to_py(e: edccif_sim::Error) -> PyErr {
    use edccif_sim::Error as E;
    match &e {
        E::Core(c) => core_to_py(c, ""),
        E::AtStep { step, source } => core_to_py(source, &format!("at step {step}: ")),
        E::Scenario { .. } | E::Parse(_) => ScenarioError::new_err(e.to_string()),
        E::Shape { .. } => ShapeError::new_err(e.to_string()),
        E::Graph { .. } => GraphError::new_err(e.to_string()),
        E::Value { .. } => ParameterError::new_err(e.to_string()),
        E::UnknownAlgorithm(_) => UnknownAlgorithmError::new_err(e.to_string()),
        E::UnknownOption { .. } => UnknownOptionError::new_err(e.to_string()),
        E::TooLarge { .. } => SizeError::new_err(e.to_string()),
        // Only a driver cancels a control, and it raises its own exception;
        // this is the fallback for one that did not.
        E::Interrupted => PyKeyboardInterrupt::new_err("interrupted"),
        _ => EdccifError::new_err(e.to_string()),
    }
}

/// `map_err` helper: `res.map_err(py_err)?`.
pub trait IntoPyResult<T> {
    /// Converts the error into the matching Python exception.
    fn py(self) -> PyResult<T>;
}

impl<T> IntoPyResult<T> for Result<T, edccif_sim::Error> {
    fn py(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}

impl<T> IntoPyResult<T> for Result<T, edccif_io::Error> {
    fn py(self) -> PyResult<T> {
        self.map_err(|e| to_py(edccif_sim::Error::from(e)))
    }
}

impl<T> IntoPyResult<T> for Result<T, edccif_core::Error> {
    fn py(self) -> PyResult<T> {
        self.map_err(|e| core_to_py(&e, ""))
    }
}
