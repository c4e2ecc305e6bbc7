//! Class-instance arguments: `from_py_with` converters, one per argument
//! name, that borrow an instance of a binding class (a `Scenario`, a model)
//! or raise an `ArgumentTypeError` naming the argument and the class. Apart
//! from [`args`](crate::args), which the classes' own modules use, so that
//! no module imports its importer.

use pyo3::prelude::*;

use crate::args::instance;
use crate::models::{PyMeasurementModel, PyMotionModel};
use crate::scenario::PyScenario;

/// `scenario`: an `edccif.Scenario`.
pub fn scenario<'py>(o: &Bound<'py, PyAny>) -> PyResult<PyRef<'py, PyScenario>> {
    instance(o, "scenario")
}
/// `scenario`: `None` or an `edccif.Scenario`.
pub fn opt_scenario<'py>(o: &Bound<'py, PyAny>) -> PyResult<Option<PyRef<'py, PyScenario>>> {
    if o.is_none() {
        Ok(None)
    } else {
        instance(o, "scenario").map(Some)
    }
}
/// `motion`: an `edccif.models.MotionModel`.
pub fn motion<'py>(o: &Bound<'py, PyAny>) -> PyResult<PyRef<'py, PyMotionModel>> {
    instance(o, "motion")
}
/// `sensor`: an `edccif.models.MeasurementModel`.
pub fn sensor<'py>(o: &Bound<'py, PyAny>) -> PyResult<PyRef<'py, PyMeasurementModel>> {
    instance(o, "sensor")
}
