//! `edccif.monte_carlo` and `edccif.MonteCarloResult`.

use edccif_sim::{McResult, McSettings, Variant};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

use crate::args;
use crate::convert::to_numpy;
use crate::drive::{drive, Progress};
use crate::errors::{IntoPyResult, ParameterError};
use crate::runner::{algorithm, faults_from_py, options_from_kwargs};
use crate::scenario::{json_to_py, PyScenario};

/// Parses `algorithms`: a name, or a list of names and/or dicts
/// `{"label": ..., "algorithm": ..., **options}`.
fn variants(obj: &Bound<'_, PyAny>, common: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<Variant>> {
    let items: Vec<Bound<'_, PyAny>> = if obj.is_instance_of::<PyString>() {
        vec![obj.clone()]
    } else {
        obj.try_iter()
            .map_err(|_| {
                crate::errors::argument_type_error(
                    obj.py(),
                    "algorithms: expected a name or a list of names and/or dicts",
                )
            })?
            .collect::<PyResult<_>>()?
    };
    let base = options_from_kwargs(common)?;
    items
        .into_iter()
        .map(|it| {
            if let Ok(name) = it.downcast::<PyString>() {
                let a = algorithm(&name.to_cow()?)?;
                let mut v = Variant::from(a);
                v.options = base.clone();
                Ok(v)
            } else if let Ok(d) = it.downcast::<PyDict>() {
                let d = d.copy()?;
                let name = args::string(
                    &d.get_item("algorithm")?.ok_or_else(|| {
                        ParameterError::new_err(
                            "algorithms: a dict entry needs an \"algorithm\" key",
                        )
                    })?,
                    "algorithms[].algorithm",
                    "an algorithm name",
                )?;
                d.del_item("algorithm")?;
                let label: Option<String> = match d.get_item("label")? {
                    Some(l) => {
                        d.del_item("label")?;
                        Some(args::string(&l, "algorithms[].label", "a string")?)
                    }
                    None => None,
                };
                let merged = common
                    .map(|c| c.copy())
                    .transpose()?
                    .unwrap_or_else(|| PyDict::new(d.py()));
                merged.update(d.as_mapping())?;
                let a = algorithm(&name)?;
                Ok(Variant {
                    label: label.unwrap_or_else(|| a.label().to_string()),
                    algorithm: a,
                    options: options_from_kwargs(Some(&merged))?,
                })
            } else {
                Err(crate::errors::argument_type_error(
                    it.py(),
                    format!(
                        "algorithms: expected names or dicts, got {}",
                        it.get_type().name()?
                    ),
                ))
            }
        })
        .collect()
}

/// Results of `monte_carlo`: per-variant accuracy, trigger rates, values sent and
/// timings. Dict-valued attributes are keyed by the variant label.
#[pyclass(name = "MonteCarloResult", module = "edccif", frozen)]
pub struct PyMcResult {
    inner: McResult,
}

impl PyMcResult {
    fn per_label<'py, F>(&self, py: Python<'py>, f: F) -> PyResult<Bound<'py, PyDict>>
    where
        F: Fn(Python<'py>, &edccif_sim::VariantStats) -> PyResult<Bound<'py, PyAny>>,
    {
        let d = PyDict::new(py);
        for v in &self.inner.variants {
            d.set_item(&v.label, f(py, v)?)?;
        }
        Ok(d)
    }
}

fn arr<'py>(py: Python<'py>, v: &[f64]) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    to_numpy(py, v.to_vec(), &[v.len()])
}

#[pymethods]
impl PyMcResult {
    /// Variant labels in order.
    #[getter]
    fn labels(&self) -> Vec<String> {
        self.inner
            .variants
            .iter()
            .map(|v| v.label.clone())
            .collect()
    }
    /// Runs.
    #[getter]
    fn runs(&self) -> usize {
        self.inner.runs
    }
    /// Seed of run 0 (run r used seed + r).
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed
    }
    /// Nodes.
    #[getter]
    fn nodes(&self) -> usize {
        self.inner.nodes
    }
    /// Steps per run.
    #[getter]
    fn steps(&self) -> usize {
        self.inner.steps
    }
    /// The paper's average RMSE per state variable: {label: (n,)}.
    #[getter]
    fn rmse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(py, |py, v| {
            Ok(arr(py, &v.errors.rmse_per_variable)?.into_any())
        })
    }
    /// Average position RMSE (3-D norm): {label: float}.
    #[getter]
    fn pos_rmse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(py, |py, v| {
            Ok(v.errors.pos_rmse.into_pyobject(py)?.into_any())
        })
    }
    /// Average velocity RMSE (3-D norm): {label: float}.
    #[getter]
    fn vel_rmse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(py, |py, v| {
            Ok(v.errors.vel_rmse.into_pyobject(py)?.into_any())
        })
    }
    /// Position RMSE over time: {label: (T,)}.
    #[getter]
    fn pos_rmse_curve<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(
            py,
            |py, v| Ok(arr(py, &v.errors.pos_rmse_curve)?.into_any()),
        )
    }
    /// Velocity RMSE over time: {label: (T,)}.
    #[getter]
    fn vel_rmse_curve<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(
            py,
            |py, v| Ok(arr(py, &v.errors.vel_rmse_curve)?.into_any()),
        )
    }
    /// Overall trigger rate: {label: float}.
    #[getter]
    fn trigger_rate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(py, |py, v| Ok(v.trigger_rate.into_pyobject(py)?.into_any()))
    }
    /// Average NEES: {label: float or None}.
    #[getter]
    fn nees<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(py, |py, v| Ok(v.errors.nees.into_pyobject(py)?.into_any()))
    }
    /// Median wall time of one run (s): {label: float}.
    #[getter]
    fn elapsed_median_s<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_label(py, |py, v| {
            Ok(v.elapsed_median_s.into_pyobject(py)?.into_any())
        })
    }
    /// Everything as a plain dict (JSON-compatible).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &serde_json::to_value(&self.inner).unwrap_or_default())
    }
    /// Everything as JSON text.
    fn to_json(&self) -> String {
        serde_json::to_string_pretty(&self.inner).unwrap_or_default()
    }
    /// A Markdown table of the results.
    fn to_markdown(&self) -> String {
        self.inner.to_markdown()
    }
    fn __repr__(&self) -> String {
        format!(
            "MonteCarloResult(nodes={}, runs={}, labels={:?})",
            self.inner.nodes,
            self.inner.runs,
            self.labels()
        )
    }
}

/// Monte Carlo over seeded runs (in parallel; deterministic for any thread count).
/// `algorithms`: a name, or a list of names and/or dicts
/// `{"label": ..., "algorithm": ..., **options}`; `options` apply to all.
/// Labels must differ (two variants of one row need labels of their own).
/// The runs already execute in parallel (one per core); the option `threads`
/// (n >= 2) additionally steps each run's network on n threads, with the same
/// numbers bit for bit, which helps only with fewer runs than cores on large
/// networks (about 64 nodes and more). `faults`: the dict of `run(faults=...)`;
/// run r injects them with the fault seed `faults["seed"] + r` (and simulates
/// with `seed + r`), exactly as `run(..., faults=...)` would.
///
/// `progress`: True (the default) shows a bar on a terminal and otherwise a
/// line on stderr at most every 5 s; False shows nothing; a callable is
/// called as `progress(done, total)` in runs × variants. The GIL is released
/// while the runs execute. Ctrl-C stops the study within a step and raises
/// `KeyboardInterrupt`; its attribute `partial` holds the `MonteCarloResult`
/// of the runs `0..p` that had finished (the same numbers as `runs=p`), or
/// `None` when none had.
#[pyfunction]
#[pyo3(
    signature = (scenario, algorithms, runs = 100, seed = 0, progress = None, *, faults = None, **options),
    text_signature = "(scenario, algorithms, runs=100, seed=0, progress=True, *, faults=None, **options)"
)]
#[allow(clippy::too_many_arguments)]
pub fn monte_carlo(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::class_args::scenario)] scenario: PyRef<'_, PyScenario>,
    algorithms: &Bound<'_, PyAny>,
    #[pyo3(from_py_with = args::named::runs)] runs: usize,
    #[pyo3(from_py_with = args::named::seed)] seed: u64,
    progress: Option<&Bound<'_, PyAny>>,
    faults: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyMcResult> {
    let vs = variants(algorithms, options)?;
    // Default progress: on.
    let progress = Progress::from_arg_default_on(py, progress, "monte_carlo", "runs")?;
    let sc = scenario.inner.clone();
    let faults = faults
        .filter(|f| !f.is_none())
        .map(|f| faults_from_py(py, f, sc.nodes()))
        .transpose()?;
    let settings = McSettings {
        runs,
        seed,
        progress: false,
    };
    crate::refs::clear_failure();
    let out = drive(py, &progress, move |ctl| {
        edccif_sim::montecarlo::monte_carlo_faults_with(&sc, &vs, &settings, faults.as_ref(), ctl)
    });
    match out.interrupt {
        None => Ok(PyMcResult {
            inner: crate::refs::finish(out.value.py())?,
        }),
        Some(e) => {
            let partial = match out.value {
                Ok(r) if r.runs >= 1 => Some(Py::new(py, PyMcResult { inner: r })?.into_any()),
                _ => None,
            };
            // Best effort: an exception object that takes no attributes keeps none.
            let _ = e.value(py).setattr("partial", partial);
            Err(e)
        }
    }
}

/// Sets the number of worker threads of the Monte Carlo runs (`monte_carlo`,
/// `reproduce`, the reliability study) to `n`, once per process, before the
/// first of them; the numbers do not depend on it. `ParameterError` for
/// `n < 1` or when the pool already runs with another size.
/// At most 4 threads per core (`ParameterError` above).
#[pyfunction]
pub fn set_worker_threads(n: &Bound<'_, PyAny>) -> PyResult<()> {
    let max = edccif_sim::limits::max_threads();
    let expected = format!(
        "an integer in 1..={max} ({} per core on this machine's {} cores)",
        edccif_sim::limits::THREADS_PER_CORE,
        edccif_sim::limits::cores()
    );
    let n = args::int_in(n, "worker threads (jobs)", 1, max as i128, &expected)? as usize;
    edccif_sim::montecarlo::set_worker_threads(n).py()
}

/// The number of worker threads of the Monte Carlo runs.
#[pyfunction]
pub fn worker_threads() -> usize {
    edccif_sim::montecarlo::worker_threads()
}

/// The algorithm names, in table order.
#[pyfunction]
pub fn algorithms<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    PyList::new(py, edccif_sim::Algorithm::NAMES)
}

/// The trigger names accepted by `trigger=` (see `docs/triggers.md`).
#[pyfunction]
pub fn triggers<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    PyList::new(py, edccif_sim::TriggerKind::NAMES)
}

/// The name of an algorithm as `algorithms()` spells it, from any spelling the
/// library accepts (case, surrounding space and `_` for `-` ignored: the paper's
/// `EDC-CIF` is `edc-cif`); `UnknownAlgorithmError` otherwise. The one parser of
/// algorithm names, shared by the Python API and the command line.
#[pyfunction]
pub fn algorithm_name(name: &str) -> PyResult<&'static str> {
    Ok(name.parse::<edccif_sim::Algorithm>().py()?.name())
}

/// The name of a trigger as `triggers()` spells it, from any spelling the
/// library accepts (as `algorithm_name`); `UnknownOptionError` otherwise.
#[pyfunction]
pub fn trigger_name(name: &str) -> PyResult<&'static str> {
    Ok(name.parse::<edccif_sim::TriggerKind>().py()?.name())
}

/// Runs the studies behind the paper's tables (Table II per node count, Table I
/// ablations, δ and σ sweeps, the real-world-like experiment) and returns
/// `(markdown, json)`: the report with the paper's numbers side by side, and
/// every number as JSON text. With `flight_data_dir` (the directory of the EuRoC
/// and TUM ground-truth files) and/or `flight_files` (any TUM or EuRoC
/// ground-truth files) also the real-flight section of `docs/results.md`; every
/// file is read and checked before the first study runs (repeated stamps dropped
/// and counted, or with `duplicates="refuse"` refused).
///
/// `progress` as for `monte_carlo` (runs × variants of the studies started so
/// far). The GIL is released while it runs; Ctrl-C stops it within a step
/// and raises `KeyboardInterrupt` (nothing is kept).
#[pyfunction]
#[pyo3(
    signature = (nodes, runs = 100, seed = 0, progress = None, deltas = None, sigmas = None, flight_data_dir = None, flight_files = None, duplicates = "drop".to_string()),
    text_signature = "(nodes, runs=100, seed=0, progress=True, deltas=None, sigmas=None, flight_data_dir=None, flight_files=None, duplicates='drop')"
)]
#[allow(clippy::too_many_arguments)]
pub fn reproduce(
    py: Python<'_>,
    #[pyo3(from_py_with = args::named::node_list)] nodes: Vec<usize>,
    #[pyo3(from_py_with = args::named::runs)] runs: usize,
    #[pyo3(from_py_with = args::named::seed)] seed: u64,
    progress: Option<&Bound<'_, PyAny>>,
    deltas: Option<&Bound<'_, PyAny>>,
    sigmas: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = args::opt_path_arg::flight_data_dir)] flight_data_dir: Option<
        std::path::PathBuf,
    >,
    #[pyo3(from_py_with = args::opt_paths_arg::flight_files)] flight_files: Option<
        Vec<std::path::PathBuf>,
    >,
    #[pyo3(from_py_with = args::text_arg::duplicates)] duplicates: String,
) -> PyResult<(String, String)> {
    let duplicates = duplicates
        .parse::<edccif_io::preprocess::DuplicateStamps>()
        .py()?;
    if nodes.is_empty() {
        return Err(ParameterError::new_err(
            "nodes: expected at least one node count >= 1, got []",
        ));
    }
    let progress = Progress::from_arg_default_on(py, progress, "reproduce", "runs")?;
    let deltas = deltas
        .filter(|d| !d.is_none())
        .map(|d| args::positives(d, "deltas"))
        .transpose()?;
    let sigmas = sigmas
        .filter(|d| !d.is_none())
        .map(|d| args::positives(d, "sigmas"))
        .transpose()?;
    let mut s = edccif_sim::report::ReproduceSettings {
        ablation_nodes: if nodes.contains(&4) { 4 } else { nodes[0] },
        nodes,
        runs,
        seed,
        progress: false,
        flight_data_dir,
        flight_files: flight_files.unwrap_or_default(),
        duplicates,
        ..Default::default()
    };
    if let Some(d) = deltas {
        s.deltas = d;
    }
    if let Some(x) = sigmas {
        s.sigmas = x;
    }
    let r = drive(py, &progress, move |ctl| {
        edccif_sim::report::reproduce_with(&s, ctl)
    })
    .into_result()?
    .py()?;
    let json = serde_json::to_string(&r).map_err(|e| ParameterError::new_err(e.to_string()))?;
    Ok((r.to_markdown(), json))
}
