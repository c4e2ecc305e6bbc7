//! `edccif.run`, `edccif.RunResult`, options parsing.

use edccif_sim::{parse_policy, Algorithm, FusionKind, RunOptions, RunResult, TriggerKind};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::args;
use crate::convert::{f64_array, finite_array, to_numpy, to_numpy_bool, Dim};
use crate::drive::{drive_if, network_work, Progress, LONG_WORK};
use crate::errors::{IntoPyResult, UnknownOptionError};
use crate::scenario::PyScenario;

/// Option names accepted by `run`, `Network` and `monte_carlo`.
pub const OPTION_NAMES: &str =
    "et_policy, delta, normalised, sigma1, sigma2, consensus_iters, fusion, force_trigger, gate, trigger, trigger_seed, threads, untriggered_closed_form";

/// The `delta` option: a number, or one per node (a list or 1-D array); each
/// finite and `> 0` (the count is checked against the nodes where the network
/// is built). Anything else is a `ParameterError` naming what was wrong.
pub fn delta_from_py(v: &Bound<'_, PyAny>) -> PyResult<edccif_sim::Delta> {
    let bad = |what: String, got: String| {
        crate::errors::ParameterError::new_err(format!(
            "{what}: expected a finite number > 0, or one per node (a list or 1-D array of them), got {got}"
        ))
    };
    if v.is_instance_of::<pyo3::types::PyBool>() || v.is_instance_of::<pyo3::types::PyString>() {
        return Err(bad("delta".into(), v.repr()?.to_string()));
    }
    let d = if let Ok(x) = v.extract::<f64>() {
        edccif_sim::Delta::All(x)
    } else if let Ok(xs) = v.extract::<Vec<f64>>() {
        if xs.is_empty() {
            return Err(bad("delta".into(), "an empty list".into()));
        }
        edccif_sim::Delta::PerNode(xs)
    } else {
        return Err(bad("delta".into(), v.repr()?.to_string()));
    };
    match &d {
        edccif_sim::Delta::All(x) if !(x.is_finite() && *x > 0.0) => {
            Err(bad("delta".into(), x.to_string()))
        }
        edccif_sim::Delta::PerNode(xs) => {
            match xs.iter().position(|x| !(x.is_finite() && *x > 0.0)) {
                Some(i) => Err(bad(format!("delta[{i}]"), xs[i].to_string())),
                None => Ok(d),
            }
        }
        _ => Ok(d),
    }
}

/// Parses an algorithm name.
pub fn algorithm(name: &str) -> PyResult<Algorithm> {
    name.parse::<Algorithm>().py()
}

/// Builds run options from keyword arguments; unknown names are errors.
pub fn options_from_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<RunOptions> {
    let mut o = RunOptions::default();
    let Some(kw) = kwargs else { return Ok(o) };
    for (k, v) in kw.iter() {
        let key: String = k.extract()?;
        if v.is_none() {
            continue;
        }
        let text = |what: &str| args::string(&v, &key, what);
        match key.as_str() {
            "et_policy" => {
                o.et_policy = Some(parse_policy(&text("\"optimal\", \"hold\" or \"skip\"")?).py()?)
            }
            "delta" => o.delta = Some(delta_from_py(&v)?),
            "normalised" => {
                if !v.is_instance_of::<pyo3::types::PyBool>() {
                    return Err(crate::errors::ParameterError::new_err(format!(
                        "normalised: expected True (delta in units of each sensor's noise) or False, got {}",
                        v.repr()?
                    )));
                }
                o.normalised = Some(v.extract()?);
            }
            "sigma1" => o.sigma1 = Some(args::real(&v, "sigma1")?),
            "sigma2" => o.sigma2 = Some(args::real(&v, "sigma2")?),
            "consensus_iters" => o.consensus_iters = Some(args::count(&v, "consensus_iters", 1)?),
            "fusion" => o.fusion = Some(text("a fusion name")?.parse::<FusionKind>().py()?),
            "force_trigger" => o.force_trigger = args::boolean(&v, "force_trigger")?,
            "gate" => o.gate = Some(args::real(&v, "gate")?),
            "trigger" => o.trigger = Some(text("a trigger name")?.parse::<TriggerKind>().py()?),
            "trigger_seed" => o.trigger_seed = Some(args::u64_arg(&v, "trigger_seed")?),
            "threads" => o.threads = Some(threads_from_py(&v)?),
            "untriggered_closed_form" => {
                if !v.is_instance_of::<pyo3::types::PyBool>() {
                    return Err(crate::errors::ParameterError::new_err(format!(
                        "untriggered_closed_form: expected True or False, got {}",
                        v.repr()?
                    )));
                }
                o.untriggered_closed_form = Some(v.extract()?);
            }
            _ => {
                return Err(UnknownOptionError::new_err(format!(
                    "unknown option {key:?}; expected one of {OPTION_NAMES}"
                )))
            }
        }
    }
    for (name, val) in [("sigma1", o.sigma1), ("sigma2", o.sigma2), ("gate", o.gate)] {
        if let Some(x) = val {
            if !(x.is_finite() && x > 0.0) {
                return Err(crate::errors::ParameterError::new_err(format!(
                    "{name}: expected a finite number > 0, got {x}"
                )));
            }
        }
    }
    if o.consensus_iters == Some(0) {
        return Err(crate::errors::ParameterError::new_err(
            "consensus_iters: expected an integer >= 1, got 0",
        ));
    }
    Ok(o)
}

/// The `threads` option: an integer >= 1 (1: the serial step, n >= 2: the
/// parallel step on n threads); anything else is a `ParameterError`.
pub(crate) fn threads_from_py(v: &Bound<'_, PyAny>) -> PyResult<usize> {
    let max = edccif_sim::limits::max_threads();
    let expected = format!(
        "an integer in 1..={max} (1: the serial step; n >= 2: the parallel network step on n threads; at most {} per core on this machine's {} cores)",
        edccif_sim::limits::THREADS_PER_CORE,
        edccif_sim::limits::cores()
    );
    args::int_in(v, "threads", 1, max as i128, &expected).map(|t| t as usize)
}

/// Consensus rounds per step of `alg` on `sc` with `opt` (0 for the other
/// fusions), without the eigenvalues of a large graph's weights: a consensus
/// row on more than 64 nodes without an explicit `consensus_iters` counts as
/// many rounds (such a call is driven as a long one).
pub fn consensus_rounds_hint(
    alg: Algorithm,
    sc: &edccif_sim::Scenario,
    opt: &RunOptions,
) -> PyResult<usize> {
    let cfg = edccif_sim::row_config(alg, &edccif_sim::RowParams::of(sc, 1), opt).py()?;
    if !matches!(cfg.fusion, edccif_core::Fusion::Consensus { .. }) {
        return Ok(0);
    }
    match opt.consensus_iters.or(sc.consensus_iters) {
        Some(l) => Ok(l),
        None if sc.nodes() <= 64 => sc.consensus_iterations().py(),
        None => Ok(usize::MAX),
    }
}

/// Refuses the `threads` option where a single node runs (it applies to whole
/// networks: `run`, `Network`, `monte_carlo`, `record`, `replay`).
pub fn no_threads(opt: &RunOptions, what: &str) -> PyResult<()> {
    match opt.threads {
        Some(t) if t > 1 => Err(crate::errors::ParameterError::new_err(format!(
            "threads: {what} is a single node and steps serially (got threads={t}); the parallel step is for whole networks (edccif.run, edccif.Network, edccif.monte_carlo)"
        ))),
        _ => Ok(()),
    }
}

/// The initial estimate: `x0` (shape-checked, finite) or the scenario's x₀.
pub fn x0_or_default(sc: &PyScenario, x0: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<f64>> {
    let n = sc.inner.state_dim();
    match x0 {
        None => Ok(sc.inner.x0.clone()),
        Some(obj) => Ok(finite_array(obj, "x0", &[Dim::Is(n)])?.0),
    }
}

/// The result of `edccif.run`.
#[pyclass(name = "RunResult", module = "edccif", frozen)]
pub struct PyRunResult {
    inner: RunResult,
    #[pyo3(get)]
    /// Fused estimates (T, N, n).
    estimates: Py<PyArrayDyn<f64>>,
    #[pyo3(get)]
    /// Fused covariances (T, N, n, n) (empty (0,) when not recorded).
    covariances: Py<PyArrayDyn<f64>>,
    #[pyo3(get)]
    /// Trigger flags (T, N) bool (False also where no measurement).
    triggered: Py<PyArrayDyn<bool>>,
    #[pyo3(get)]
    /// Measurement present (T, N) bool.
    measured: Py<PyArrayDyn<bool>>,
    #[pyo3(get)]
    /// The replay's report (a dict: frames and transforms, noise per source,
    /// messages dropped, offsets, trigger rate per node, the truth's frame;
    /// see `edccif.replay`); `None` for other runs.
    report: Option<Py<PyAny>>,
}

impl PyRunResult {
    /// The result with a replay's report.
    pub fn with_report(mut self, report: Py<PyAny>) -> Self {
        self.report = Some(report);
        self
    }
}

#[pymethods]
impl PyRunResult {
    /// The row that ran, e.g. "edc-cif".
    #[getter]
    fn algorithm(&self) -> &'static str {
        self.inner.algorithm.name()
    }
    /// Triggered / measured node-steps.
    #[getter]
    fn trigger_rate(&self) -> f64 {
        self.inner.trigger_rate()
    }
    /// Floats sent: {"sensor_to_estimator": int, "estimator_to_estimator": int,
    /// "estimator_to_sensor": int} (the last: the innovation trigger's prediction).
    #[getter]
    fn values_sent<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item(
            "sensor_to_estimator",
            self.inner.counters.values_sensor_to_estimator,
        )?;
        d.set_item(
            "estimator_to_estimator",
            self.inner.counters.values_estimator_to_estimator,
        )?;
        d.set_item(
            "estimator_to_sensor",
            self.inner.counters.values_estimator_to_sensor,
        )?;
        Ok(d)
    }
    /// Adaptation-guard fallbacks (ALGORITHM.md §4).
    #[getter]
    fn guard_fallbacks(&self) -> u64 {
        self.inner.counters.guard_fallbacks
    }
    /// Triggered measurements rejected by the innovation gate (`gate=` option).
    #[getter]
    fn gated(&self) -> u64 {
        self.inner.counters.gated
    }
    /// Wall time of the stepping loop (s).
    #[getter]
    fn elapsed_s(&self) -> f64 {
        self.inner.elapsed_s
    }
    /// Steps T.
    #[getter]
    fn steps(&self) -> usize {
        self.inner.steps
    }
    /// Nodes N.
    #[getter]
    fn nodes(&self) -> usize {
        self.inner.nodes
    }
    fn __repr__(&self) -> String {
        format!(
            "RunResult(algorithm={:?}, steps={}, nodes={}, trigger_rate={:.3}, elapsed_s={:.6})",
            self.inner.algorithm.name(),
            self.inner.steps,
            self.inner.nodes,
            self.inner.trigger_rate(),
            self.inner.elapsed_s
        )
    }
}

/// Runs one algorithm row over measurements `z` (T, N, 3) — a row of NaN means
/// "no measurement this step" — from the initial estimate `x0` (default: the
/// scenario's x₀; P0 from the scenario).
///
/// The steps' times, for rows at non-uniform times (default: the scenario's
/// uniform `dt` at every step), are given in one of two ways:
/// - `t` (T,): the measurements' timestamps (s), finite and strictly increasing
///   after `t0` (the time of `x0`); each step predicts over its own interval;
/// - `dt` (T,): each step's own length in seconds (`dt[0]`: from the initial
///   estimate to the first row; each finite and > 0).
///
/// The option `delta` is the trigger threshold: one number, or one per node (a
/// list or 1-D array); `normalised=True` puts the send-on-delta family's `delta`
/// in units of each sensor's noise (`(z − z_τ)ᵀR⁻¹(z − z_τ) > δ`; default 16;
/// see `docs/triggers.md`).
///
/// The option `threads` runs every network step on several threads: 1 (the
/// default) is the serial step, n >= 2 the parallel step on n threads, with the
/// same numbers bit for bit; it pays off only for large networks (about 64
/// nodes and more). A value < 1 or above 4 per core raises `ParameterError`.
/// The GIL is released while the run steps; a long run (many steps, nodes or
/// consensus rounds) stops with `KeyboardInterrupt` on Ctrl-C within a step
/// (or a consensus round), and `progress` (True: a bar or a line every few
/// seconds on stderr; a callable: `progress(done, total)` in steps) reports
/// it. What the run would allocate is checked first (`SizeError`).
///
/// >>> import numpy as np, edccif
/// >>> sc = edccif.Scenario.paper(64).replace(topology="ring", steps=20)
/// >>> truth, z, x0 = sc.simulate(seed=0)
/// >>> serial = edccif.run("edc-cif", sc, z, x0=x0)
/// >>> fast = edccif.run("edc-cif", sc, z, x0=x0, threads=2)
/// >>> np.array_equal(serial.estimates, fast.estimates)
/// True
#[pyfunction]
#[pyo3(signature = (algorithm, scenario, z, x0 = None, *, t = None, t0 = 0.0, dt = None, record_covariances = true, faults = None, progress = None, **options))]
#[allow(clippy::too_many_arguments)]
pub fn run(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
    #[pyo3(from_py_with = crate::class_args::scenario)] scenario: PyRef<'_, PyScenario>,
    z: &Bound<'_, PyAny>,
    x0: Option<&Bound<'_, PyAny>>,
    t: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::real_arg::t0)] t0: f64,
    dt: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::flag_arg::record_covariances)] record_covariances: bool,
    faults: Option<&Bound<'_, PyAny>>,
    progress: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRunResult> {
    let progress = Progress::from_arg(progress, "run", "steps")?;
    let faults = faults
        .filter(|f| !f.is_none())
        .map(|f| faults_from_py(py, f, scenario.inner.nodes()))
        .transpose()?;
    let alg = self::algorithm(algorithm)?;
    let opt = options_from_kwargs(options)?;
    let k = scenario.inner.nodes();
    if let Ok(shape) = z.getattr("shape").and_then(|s| s.extract::<Vec<usize>>()) {
        // What the run returns, refused before z is copied.
        if let Some(&steps) = shape.first() {
            let n = scenario.inner.state_dim();
            edccif_sim::runner::check_run_size(steps, k, n, record_covariances).py()?;
        }
    }
    // (T, N, m), or (T, Σ m_i) for sensors of different dimensions (as `simulate` gives it)
    let (zv, zshape) = match scenario.inner.meas_dim() {
        Some(m) => f64_array(z, "z", &[Dim::Any("T"), Dim::Is(k), Dim::Is(m)])?,
        None => {
            let total = scenario.inner.meas_dims().iter().sum();
            f64_array(z, "z", &[Dim::Any("T"), Dim::Is(total)])?
        }
    };
    let t = t.filter(|t| !t.is_none());
    let dt = dt.filter(|d| !d.is_none());
    if t.is_some() && dt.is_some() {
        return Err(crate::errors::ParameterError::new_err(
            "t and dt: give the steps' times one way, timestamps t or step lengths dt, not both",
        ));
    }
    let dts = match (t, dt) {
        (Some(t), _) => Some(dt_from_timestamps(t, t0, zshape[0])?),
        (None, Some(d)) => Some(finite_array(d, "dt", &[Dim::Is(zshape[0])])?.0),
        (None, None) => None,
    };
    let x0v = x0_or_default(&scenario, x0)?;
    let sc = scenario.inner.clone();
    let steps = zshape[0];
    edccif_sim::runner::check_run_size(steps, k, sc.state_dim(), record_covariances).py()?;
    let rounds = consensus_rounds_hint(alg, &sc, &opt)?;
    let long = network_work(steps, k, rounds) >= LONG_WORK;
    crate::refs::clear_failure();
    let r = crate::refs::finish(
        drive_if(py, long, &progress, move |ctl| {
            edccif_sim::faults::run_with_control(
                alg,
                &sc,
                &zv,
                &x0v,
                &opt,
                faults.as_ref(),
                dts.as_deref(),
                record_covariances,
                ctl,
            )
        })
        .into_result()?
        .py(),
    )?;
    wrap_result(py, r, record_covariances)
}

/// Time steps from a timestamp array `t` of shape `(steps,)` after `t0`: finite,
/// strictly increasing (the error names the first offending index).
pub fn dt_from_timestamps(t: &Bound<'_, PyAny>, t0: f64, steps: usize) -> PyResult<Vec<f64>> {
    if !t0.is_finite() {
        return Err(crate::errors::NonFiniteError::new_err(format!(
            "t0: the time of the initial estimate must be finite, got {t0}"
        )));
    }
    let (tv, _) = f64_array(t, "t", &[Dim::Is(steps)])?;
    if let Some(i) = tv.iter().position(|v| !v.is_finite()) {
        return Err(crate::errors::NonFiniteError::new_err(format!(
            "t[{i}]: timestamps must be finite, got {}",
            tv[i]
        )));
    }
    edccif_sim::dt_from_times(&tv, t0).py()
}

/// The time step of one streaming step from `t=` (a timestamp after `last`) or
/// `dt=` (an interval), or `nominal` when neither is given.
pub fn step_dt(t: Option<f64>, dt: Option<f64>, last: f64, nominal: f64) -> PyResult<f64> {
    match (t, dt) {
        (Some(_), Some(_)) => Err(crate::errors::ParameterError::new_err(
            "give either t (a timestamp) or dt (an interval), not both",
        )),
        (Some(t), None) => {
            if !t.is_finite() {
                return Err(crate::errors::NonFiniteError::new_err(format!(
                    "t: the timestamp must be finite, got {t}"
                )));
            }
            if t <= last {
                return Err(crate::errors::ParameterError::new_err(format!(
                    "t: timestamps must be strictly increasing; got {t} after {last}"
                )));
            }
            let d = t - last;
            if !d.is_finite() {
                return Err(crate::errors::ParameterError::new_err(format!(
                    "t: the interval {t} - {last} is not finite"
                )));
            }
            Ok(d)
        }
        (None, Some(d)) => edccif_sim::timestep::check_dt(d, "dt").py().map(|()| d),
        (None, None) => Ok(nominal),
    }
}

/// Parses a `faults` dict (keys of `edccif_sim::faults::Faults`: `seed`,
/// `message_loss`, `dropout`/`outage` as lists of `(node, start, end)`,
/// `outlier_prob`, `outlier_sigma`) and checks it against `nodes`.
pub fn faults_from_py(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    nodes: usize,
) -> PyResult<edccif_sim::faults::Faults> {
    if !obj.is_instance_of::<PyDict>() {
        return Err(crate::errors::argument_type_error(
            py,
            format!(
                "faults: expected a dict of faults (see run), got {}",
                obj.get_type()
                    .name()
                    .map_or_else(|_| "?".into(), |n| n.to_string())
            ),
        ));
    }
    // A value JSON cannot hold (a complex, an object) is a wrong type too.
    let mut v = crate::scenario::py_to_json(py, obj).map_err(|e| {
        if e.is_instance_of::<pyo3::exceptions::PyTypeError>(py) {
            crate::errors::argument_type_error(py, format!("faults: {}", e.value(py)))
        } else {
            e
        }
    })?;
    let serde_json::Value::Object(map) = &mut v else {
        return Err(crate::errors::ParameterError::new_err(
            "faults: expected a dict",
        ));
    };
    // (node, start, end) tuples → {node, start, end}
    for key in ["dropout", "outage"] {
        if let Some(serde_json::Value::Array(ws)) = map.get_mut(key) {
            for w in ws.iter_mut() {
                if let serde_json::Value::Array(t) = w {
                    if t.len() == 3 {
                        *w = serde_json::json!({"node": t[0], "start": t[1], "end": t[2]});
                    }
                }
            }
        }
    }
    let f: edccif_sim::faults::Faults = serde_json::from_value(v).map_err(|e| {
        let msg = format!("faults: {e}");
        if msg.contains("unknown field") {
            UnknownOptionError::new_err(msg)
        } else {
            crate::errors::ParameterError::new_err(msg)
        }
    })?;
    f.validate(nodes).py()?;
    Ok(f)
}

/// Wraps a Rust run result with its NumPy arrays.
pub fn wrap_result(
    py: Python<'_>,
    r: RunResult,
    record_covariances: bool,
) -> PyResult<PyRunResult> {
    let (t, k, n) = (r.steps, r.nodes, r.n);
    let cov_shape: Vec<usize> = if record_covariances {
        vec![t, k, n, n]
    } else {
        vec![0]
    };
    let mut r = r;
    let estimates = to_numpy(py, std::mem::take(&mut r.estimates), &[t, k, n])?.unbind();
    let covariances = to_numpy(py, std::mem::take(&mut r.covariances), &cov_shape)?.unbind();
    let triggered = to_numpy_bool(py, std::mem::take(&mut r.triggered), &[t, k])?.unbind();
    let measured = to_numpy_bool(py, std::mem::take(&mut r.measured), &[t, k])?.unbind();
    Ok(PyRunResult {
        inner: r,
        estimates,
        covariances,
        triggered,
        measured,
        report: None,
    })
}
