//! Python models named by reference in scenario files (`kind = "python"`,
//! `model = "module:attribute"`): the builder the bindings register with
//! `edccif_sim::catalogue` ([`register`]), so that every path that builds a
//! scenario's models (`Scenario.simulate`, `run`, `monte_carlo`, the sweeps and
//! the CLI) imports, calls and type-checks the referenced model
//! (`edccif._refs.resolve`) and runs it through the model adapters.
//!
//! A referenced callable that fails during a run records its error in its
//! adapter; the adapter hands it to [`take_failure`] when the run drops it, and
//! the binding raises it instead of the core's consequence (as
//! `ModelNetwork` does).

use std::any::Any;
use std::sync::{Arc, Mutex};

use edccif_sim::catalogue::{BoxedMotion, BoxedSensor, PythonModels};
use edccif_sim::Scenario;
use pyo3::prelude::*;

use crate::adapters::{MotionAdapter, SensorAdapter, Shared};
use crate::models::{PyMeasurementModel, PyMotionModel};
use crate::{with_m, with_n};

/// The first error a referenced model's callable recorded since the last
/// [`take_failure`].
static FAILURE: Mutex<Option<PyErr>> = Mutex::new(None);

fn record(e: PyErr) {
    let mut g = FAILURE.lock().unwrap_or_else(|p| p.into_inner());
    if g.is_none() {
        *g = Some(e);
    }
}

/// Clears a recorded failure (before a run).
pub fn clear_failure() {
    FAILURE.lock().unwrap_or_else(|p| p.into_inner()).take();
}

/// The error a referenced model's callable recorded during the last run, if any.
pub fn take_failure() -> Option<PyErr> {
    FAILURE.lock().unwrap_or_else(|p| p.into_inner()).take()
}

/// A run's result, or the error a referenced model's callable recorded
/// during it (which wins: the run's own error, or its NaN values, are only
/// its consequence).
pub fn finish<T>(r: PyResult<T>) -> PyResult<T> {
    match (take_failure(), r) {
        (Some(e), _) => Err(e),
        (None, r) => r,
    }
}

/// Hands a failure a referenced motion's callable recorded to the call that
/// ran it ([`finish`]) at once: a `Node` keeps its models between steps, and a
/// model dropped later must leave nothing behind for an unrelated run.
fn motion_failed<const N: usize>(a: &MotionAdapter<N>) {
    if let Some(e) = a.failure.take() {
        record(e);
    }
}

/// The same for a referenced sensor.
fn sensor_failed<const N: usize, const M: usize>(a: &SensorAdapter<N, M>) {
    if let Some(e) = a.failure.take() {
        record(e);
    }
}

/// The object `reference` names, imported, called and type-checked by
/// `edccif._refs.resolve` (`kind`: `"motion"` or `"measurement"`).
pub fn resolve<'py>(
    py: Python<'py>,
    sc: &Scenario,
    reference: &str,
    kind: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let dirs: Vec<String> = sc
        .python_dirs()
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    py.import("edccif._refs")?
        .call_method1("resolve", (reference, kind, dirs))
}

fn scenario_err(field: &str, e: PyErr) -> edccif_sim::Error {
    let problem = Python::with_gil(|py| e.value(py).to_string());
    edccif_sim::Error::Scenario {
        field: field.into(),
        problem,
    }
}

fn dims_err(field: &str, reference: &str, what: &str, file: usize, model: usize) -> PyErr {
    crate::errors::ScenarioError::new_err(format!(
        "the Python model `{reference}` has {what} {model}, the scenario says `{field} = {file}`"
    ))
}

/// The builder of referenced models.
struct Resolver;

impl PythonModels for Resolver {
    fn motion(
        &self,
        sc: &Scenario,
        reference: &str,
        n: usize,
    ) -> edccif_sim::Result<Box<dyn Any + Send>> {
        Python::with_gil(|py| -> PyResult<Box<dyn Any + Send>> {
            let obj = resolve(py, sc, reference, "motion")?;
            let model: PyRef<'_, PyMotionModel> = obj.extract()?;
            if model.spec.n() != n {
                return Err(dims_err(
                    "n",
                    reference,
                    "state dimension",
                    n,
                    model.spec.n(),
                ));
            }
            with_n!(n, |N| {
                let a = Arc::new(MotionAdapter::<N>::new(&model.spec)?);
                let b: BoxedMotion<N> = Box::new(Shared::with_hook(a, motion_failed::<N>));
                Ok(Box::new(b) as Box<dyn Any + Send>)
            })
        })
        .map_err(|e| scenario_err("motion.model", e))
    }

    fn sensor(
        &self,
        sc: &Scenario,
        reference: &str,
        n: usize,
        m: usize,
    ) -> edccif_sim::Result<Box<dyn Any + Send>> {
        Python::with_gil(|py| -> PyResult<Box<dyn Any + Send>> {
            let obj = resolve(py, sc, reference, "measurement")?;
            let model: PyRef<'_, PyMeasurementModel> = obj.extract()?;
            if model.spec.m() != m {
                return Err(dims_err(
                    "m",
                    reference,
                    "measurement dimension",
                    m,
                    model.spec.m(),
                ));
            }
            model
                .spec
                .check_state_dim(n, &format!("the Python model `{reference}`"))
                .map_err(|e| crate::errors::ScenarioError::new_err(e.value(py).to_string()))?;
            with_n!(n, |N| with_m!(m, |M| {
                let a = Arc::new(SensorAdapter::<N, M>::new(&model.spec)?);
                let b: BoxedSensor<N, M> = Box::new(Shared::with_hook(a, sensor_failed::<N, M>));
                Ok(Box::new(b) as Box<dyn Any + Send>)
            }))
        })
        .map_err(|e| scenario_err("model", e))
    }
}

/// Registers the builder of referenced models (when the module loads).
pub fn register() {
    edccif_sim::catalogue::set_python_models(Box::new(Resolver));
}

/// Resolves every Python model of `sc` once (import, call, type and
/// dimension checks), so that a scenario naming a missing or wrong model is
/// refused when it is read, not when it runs.
pub fn check(sc: &Scenario) -> PyResult<()> {
    if !sc.has_python_models() {
        return Ok(());
    }
    let r = edccif_sim::catalogue::check_models(sc);
    finish(r.map_err(crate::errors::to_py))
}
