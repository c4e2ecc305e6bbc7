//! `edccif.Network`: a network stepping one measurement row at a time, built
//! from any scenario (`Network(scenario, ...)`) or from one's own models
//! (`Network.from_models(...)`, and the subclass `edccif.ModelNetwork`, whose
//! constructor takes the models). A scenario of the paper's kinds runs on the
//! typed network ([`AnyNetwork`]); every other scenario, and one's own models,
//! on the model network ([`crate::model_net`]), as `edccif.run` does. Argument
//! handling (time steps, masks, start, outputs) is written once here for both.

use edccif_sim::{Algorithm, AnyNetwork, Counters};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::args;
use crate::convert::{
    bool_array, f64_array, finite_array, small_to_numpy2, to_numpy, to_numpy_bool, Dim,
};
use crate::drive::{drive, Progress};
use crate::errors::{IntoPyResult, ParameterError};
use crate::model_net::{run_noise, Models};
use crate::runner::{
    options_from_kwargs, step_dt, threads_from_py, wrap_result, x0_or_default, PyRunResult,
};
use crate::scenario::{scenario_with_graph, PyScenario};

/// What a network steps on.
enum Inner {
    /// The typed network of a scenario of the paper's kinds.
    Typed(Box<AnyNetwork>),
    /// The model network: a per-node scenario's models or one's own.
    Models(Models),
}

/// A network for streaming use: feed one step's measurements at a time.
/// `Network(scenario, "edc-cif").step(z[t])` over a sequence gives exactly the
/// estimates of `edccif.run` on the same scenario, for every scenario: one of
/// the paper's kinds (`z[t]` (N, 3)) or a per-node one (`[[nodes]]`, sensors
/// of their own kinds and sizes: `z[t]` the (Σ m_i,) row `simulate` gives, or
/// one entry per node). `Network.from_models(motion, sensors, ...)` (or
/// `edccif.ModelNetwork(...)`) builds it from one's own models.
///
/// The option `threads` (or the `threads` property, at any time) runs each step
/// of a network of the paper's kinds on several threads: 1 (the default) is the
/// serial step, n >= 2 the parallel step on n threads, with the same numbers bit
/// for bit; a parallel step releases the GIL. It pays off only for large
/// networks (about 64 nodes and more). A model network steps serially.
///
/// >>> import numpy as np, edccif
/// >>> sc = edccif.Scenario.paper(64).replace(topology="ring", steps=10)
/// >>> truth, z, x0 = sc.simulate(seed=1)
/// >>> a = edccif.Network(sc, "ec-ckf", x0, consensus_iters=4)
/// >>> b = edccif.Network(sc, "ec-ckf", x0, consensus_iters=4, threads=2)
/// >>> b.threads
/// 2
/// >>> all(np.array_equal(a.step(zk), b.step(zk)) for zk in z)
/// True
/// >>> mixed = edccif.Scenario.from_toml_str("""
/// ... name = "two-kinds"
/// ... dt = 0.1
/// ... steps = 5
/// ... delta = 4.0
/// ... normalised = true
/// ... sigma1 = 0.0005
/// ... sigma2 = 0.0005
/// ... x0 = [0.0, 0.0, 1.0, 0.5, 0.1]
/// ... p0_diag = [0.25, 0.25, 0.04, 0.04, 0.0001]
/// ... motion = { kind = "coordinated-turn-2d", q1 = 0.1, q2 = 0.0001 }
/// ... topology = { kind = "complete" }
/// ... nodes = [
/// ...   { sensor = { kind = "bearing-only", position = [20.0, 0.0], sigma_b = 0.01 } },
/// ...   { sensor = { kind = "range-bearing", position = [-20.0, 0.0], sigma_r = 0.2, sigma_b = 0.01 } },
/// ... ]
/// ... """)
/// >>> truth, z, x0 = mixed.simulate(seed=1)
/// >>> net = edccif.Network(mixed, "edc-cif", x0)
/// >>> net.meas_dims
/// [1, 2]
/// >>> steps = [net.step(zk) for zk in z]
/// >>> np.array_equal(np.stack(steps), edccif.run("edc-cif", mixed, z, x0=x0).estimates)
/// True
#[pyclass(name = "Network", module = "edccif", subclass)]
pub struct PyNetwork {
    inner: Inner,
    algorithm: Algorithm,
    k: usize,
    n: usize,
    /// Time of the current estimates (s).
    t: f64,
    /// The step of `step()`/`run()` without `t`/`dt` (`None`: one must be given).
    nominal_dt: Option<f64>,
}

fn check_t0(t0: f64) -> PyResult<()> {
    if t0.is_finite() {
        Ok(())
    } else {
        Err(crate::errors::NonFiniteError::new_err(format!(
            "t0: the time of the initial estimate must be finite, got {t0}"
        )))
    }
}

/// The optional `links` (k, k) and `active` (k,) masks of a step.
type Masks = (Option<Vec<bool>>, Option<Vec<bool>>);

fn masks(
    links: Option<&Bound<'_, PyAny>>,
    active: Option<&Bound<'_, PyAny>>,
    k: usize,
) -> PyResult<Masks> {
    let l = links
        .filter(|o| !o.is_none())
        .map(|o| bool_array(o, "links", &[Dim::Is(k), Dim::Is(k)]))
        .transpose()?;
    let a = active
        .filter(|o| !o.is_none())
        .map(|o| bool_array(o, "active", &[Dim::Is(k)]))
        .transpose()?;
    Ok((l, a))
}

impl PyNetwork {
    /// `Network(scenario, ...)`: the typed network for a scenario of the
    /// paper's kinds, the model network for any other.
    #[allow(clippy::too_many_arguments)]
    fn of_scenario(
        scenario: &PyScenario,
        algorithm_name: &str,
        x0: Option<&Bound<'_, PyAny>>,
        adjacency: Option<&Bound<'_, PyAny>>,
        weights: Option<&Bound<'_, PyAny>>,
        t0: f64,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let alg = crate::runner::algorithm(algorithm_name)?;
        let opt = options_from_kwargs(options)?;
        let x0v = x0_or_default(scenario, x0)?;
        check_t0(t0)?;
        let sc = scenario_with_graph(&scenario.inner, adjacency, weights)?;
        let inner = if sc.is_typed() {
            Inner::Typed(Box::new(AnyNetwork::new(alg, &sc, &x0v, &opt).py()?))
        } else {
            Inner::Models(Models::of_scenario(alg, &sc, &x0v, &opt)?)
        };
        Ok(Self {
            inner,
            algorithm: alg,
            k: sc.nodes(),
            n: sc.state_dim(),
            t: t0,
            nominal_dt: Some(sc.dt),
        })
    }

    /// `Network.from_models(...)`, `ModelNetwork(...)` and the replay of a
    /// recording with models.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn of_models(
        motion: &Bound<'_, PyAny>,
        sensors: &Bound<'_, PyAny>,
        algorithm_name: &str,
        x0: &Bound<'_, PyAny>,
        p0: &Bound<'_, PyAny>,
        adjacency: Option<&Bound<'_, PyAny>>,
        weights: Option<&Bound<'_, PyAny>>,
        dt: Option<f64>,
        t0: f64,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let alg = crate::runner::algorithm(algorithm_name)?;
        let opt = options_from_kwargs(options)?;
        check_t0(t0)?;
        let (models, k, n) =
            Models::of_models(motion, sensors, alg, &opt, x0, p0, adjacency, weights, dt)?;
        Ok(Self {
            inner: Inner::Models(models),
            algorithm: alg,
            k,
            n,
            t: t0,
            nominal_dt: dt,
        })
    }

    /// Every node's measurement dimension.
    pub(crate) fn dims(&self) -> Vec<usize> {
        match &self.inner {
            Inner::Typed(_) => vec![edccif_sim::runner::M; self.k],
            Inner::Models(m) => m.meas_dims.clone(),
        }
    }

    /// The model network, or the error that a scenario of the paper's kinds
    /// does not take `what`.
    fn models(&mut self, what: &str) -> PyResult<&mut Models> {
        match &mut self.inner {
            Inner::Models(m) => Ok(m),
            Inner::Typed(_) => Err(ParameterError::new_err(format!(
                "{what}: takes a network of models (Network.from_models, or a per-node \
                 scenario); for a scenario of the paper's kinds use edccif.run or step()"
            ))),
        }
    }

    /// Runs `T = dt.len()` steps of the model network on flat rows `z`
    /// `(T, Σ m_i)` with optional per-step noise `(T, Σ m_i²)` (NaN: the
    /// sensor's own), covariances recorded; on error the network is unchanged.
    /// Reports its steps to `progress`.
    pub(crate) fn run_flat(
        &mut self,
        py: Python<'_>,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        progress: &Progress,
    ) -> PyResult<edccif_sim::RunResult> {
        let k = self.k;
        let m = self.models("run")?;
        // Long runs (or runs with a progress reporter) stop on Ctrl-C with the network as it was.
        let long = crate::drive::network_work(dt.len(), k, 0) >= crate::drive::LONG_WORK
            || !matches!(progress, Progress::Off);
        m.begin();
        let net = &mut m.net;
        let r = crate::drive::drive_if(py, long, progress, |ctl| net.run(z, dt, noise, true, ctl))
            .into_result()?;
        let r = m.finish(r)?;
        self.t += dt.iter().sum::<f64>();
        Ok(r)
    }

    fn counters_value(&self) -> Counters {
        match &self.inner {
            Inner::Typed(net) => net.counters(),
            Inner::Models(m) => m.net.counters(),
        }
    }
}

#[pymethods]
impl PyNetwork {
    /// `scenario`: any `edccif.Scenario` (per-node ones included); `algorithm`:
    /// a row of `edccif.ALGORITHMS`; `x0` (n,): the start (default the
    /// scenario's). `adjacency` (N, N) bool and/or `weights` (N, N) replace the
    /// scenario's graph (see `Scenario.replace(topology=..., weights=...)`);
    /// `t0` is the time of the initial estimate for `step(z, t=...)`. Options
    /// as for `edccif.run`.
    #[new]
    #[pyo3(signature = (scenario, algorithm = "edc-cif", x0 = None, *, adjacency = None, weights = None, t0 = 0.0, **options))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        #[pyo3(from_py_with = crate::class_args::scenario)] scenario: PyRef<'_, PyScenario>,
        #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
        x0: Option<&Bound<'_, PyAny>>,
        adjacency: Option<&Bound<'_, PyAny>>,
        weights: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::args::real_arg::t0)] t0: f64,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        Self::of_scenario(&scenario, algorithm, x0, adjacency, weights, t0, options)
    }

    /// One step; returns the fused estimates (N, n). `z`: for a scenario of
    /// the paper's kinds (N, 3) (a NaN row: no measurement); for a model
    /// network the (Σ m_i,) row `Scenario.simulate` gives (NaN where a node
    /// does not measure), or one entry per node, `None` or the node's (m,)
    /// values. Optional `links` (N, N) bool (`links[i, j]`: i hears j) and
    /// `active` (N,) bool masks model lost messages and nodes that are down.
    /// The step predicts over `dt` (s), or up to the timestamp `t` (after the
    /// network's `t`), or over the scenario's (or constructor's) `dt` when
    /// neither is given. On error the network is unchanged.
    #[pyo3(signature = (z, links = None, active = None, *, t = None, dt = None))]
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        z: &Bound<'py, PyAny>,
        links: Option<&Bound<'py, PyAny>>,
        active: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::t)] t: Option<f64>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        if t.is_none() && dt.is_none() && self.nominal_dt.is_none() {
            return Err(ParameterError::new_err(
                "no time step: pass step(z, t=...) or step(z, dt=...), or dt= to the constructor",
            ));
        }
        let d = step_dt(t, dt, self.t, self.nominal_dt.unwrap_or(f64::NAN))?;
        let k = self.k;
        match &mut self.inner {
            Inner::Typed(net) => {
                let (zv, _) = f64_array(z, "z", &[Dim::Is(k), Dim::Is(3)])?;
                let (l, a) = masks(links, active, k)?;
                let (l, a) = (l.as_deref(), a.as_deref());
                let stepped = if net.heavy() {
                    // Many consensus rounds: on a worker thread, interruptible between rounds.
                    drive(py, &Progress::Off, |ctl| {
                        net.step_dt_with_control(&zv, d, l, a, ctl)
                    })
                    .into_result()?
                } else if net.parallel() {
                    // The parallel step is for large networks: let other Python threads run.
                    py.allow_threads(|| net.step_dt_with(&zv, d, l, a))
                } else {
                    net.step_dt_with(&zv, d, l, a)
                };
                stepped.py()?;
            }
            Inner::Models(m) => {
                let zv = m.step_measurements(z)?;
                let (l, a) = masks(links, active, k)?;
                m.begin();
                let r = m.net.step(&zv, d, l.as_deref(), a.as_deref());
                m.finish(r)?;
            }
        }
        self.t = t.unwrap_or(self.t + d);
        self.estimates(py)
    }

    /// Runs `T` steps of a model network (one's own models or a per-node
    /// scenario's) and returns a `RunResult`, continuing from the current
    /// state. `z`: the (T, Σ m_i) array `Scenario.simulate` gives, or one entry
    /// per node, `None` or an array (T, m) of that node's measurements (NaN
    /// rows: none that step); `t` (T,) the timestamps (after the network's
    /// `t`) or `dt` one step (float or (T,)), default the scenario's (or
    /// constructor's) `dt`; `Rs` each step's measurement noise, one entry per
    /// node: `None` (the sensor's own `R`), an (m, m) for every step or
    /// (T, m, m), one per step (each finite, symmetric, positive definite; the
    /// error names the step and node). On error the network is unchanged. A
    /// network of the paper's kinds raises `ParameterError` (`edccif.run` runs
    /// those).
    ///
    /// A long run stops on Ctrl-C with `KeyboardInterrupt` and the network as
    /// it was; `progress` (True, or a callable `progress(done, total)` in
    /// steps) reports it.
    #[pyo3(signature = (z, *, t = None, dt = None, record_covariances = true, Rs = None, progress = None))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn run(
        &mut self,
        py: Python<'_>,
        z: &Bound<'_, PyAny>,
        t: Option<&Bound<'_, PyAny>>,
        dt: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::args::flag_arg::record_covariances)] record_covariances: bool,
        Rs: Option<&Bound<'_, PyAny>>,
        progress: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyRunResult> {
        let progress = Progress::from_arg(progress, "ModelNetwork.run", "steps")?;
        let (k, n, t_now, nominal) = (self.k, self.n, self.t, self.nominal_dt);
        let m = self.models("run")?;
        let t_vec = t.filter(|o| !o.is_none());
        let dt_obj = dt.filter(|o| !o.is_none());
        let (flat, steps) = m.run_measurements(z, t_vec)?;
        let dts: Vec<f64> = match (t_vec, dt_obj) {
            (Some(_), Some(_)) => {
                return Err(ParameterError::new_err(
                    "give either t (timestamps) or dt (time steps), not both",
                ))
            }
            (Some(tv), None) => crate::runner::dt_from_timestamps(tv, t_now, steps)?,
            (None, Some(d)) => match d.extract::<f64>() {
                Ok(v) => vec![v; steps],
                Err(_) => f64_array(d, "dt", &[Dim::Is(steps)])?.0,
            },
            (None, None) => match nominal {
                Some(v) => vec![v; steps],
                None => return Err(ParameterError::new_err(
                    "no time step: pass run(z, t=...) or run(z, dt=...), or dt= to the constructor",
                )),
            },
        };
        edccif_sim::runner::check_run_size(steps, k, n, record_covariances).py()?;
        let noise = match Rs.filter(|o| !o.is_none()) {
            Some(rs) => run_noise(rs, &m.meas_dims, steps)?,
            None => None,
        };
        // Long runs on a worker thread (a model's Python callables take the GIL
        // there), stopping on Ctrl-C with the network as it was.
        let long = crate::drive::network_work(steps, k, 0) >= crate::drive::LONG_WORK;
        m.begin();
        let net = &mut m.net;
        let r = crate::drive::drive_if(py, long, &progress, |ctl| {
            net.run(&flat, &dts, noise.as_deref(), record_covariances, ctl)
        })
        .into_result()?;
        let r = m.finish(r)?;
        self.t += dts.iter().sum::<f64>();
        if let Some(tv) = t_vec {
            if let Ok(last) = tv.get_item(steps - 1).and_then(|o| o.extract::<f64>()) {
                self.t = last;
            }
        }
        wrap_result(py, r, record_covariances)
    }

    /// A network of one's own models (`edccif.models`): the same as
    /// `edccif.ModelNetwork(motion, sensors, algorithm, x0=..., P0=..., ...)`.
    #[staticmethod]
    #[pyo3(signature = (motion, sensors, algorithm = "edc-cif", *, x0, P0, adjacency = None, weights = None, dt = None, t0 = 0.0, **options))]
    #[allow(clippy::too_many_arguments, non_snake_case)]
    fn from_models(
        py: Python<'_>,
        motion: &Bound<'_, PyAny>,
        sensors: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        adjacency: Option<&Bound<'_, PyAny>>,
        weights: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
        #[pyo3(from_py_with = crate::args::real_arg::t0)] t0: f64,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Py<PyModelNetwork>> {
        let base = Self::of_models(
            motion, sensors, algorithm, x0, P0, adjacency, weights, dt, t0, options,
        )?;
        Py::new(
            py,
            PyClassInitializer::from(base).add_subclass(PyModelNetwork),
        )
    }

    /// Time of the current estimates (s): `t0` plus the steps taken.
    #[getter]
    fn t(&self) -> f64 {
        self.t
    }

    /// Number of nodes N.
    #[getter]
    fn nodes(&self) -> usize {
        self.k
    }

    /// State dimension n.
    #[getter]
    fn state_dim(&self) -> usize {
        self.n
    }

    /// Every node's measurement dimension.
    #[getter]
    fn meas_dims(&self) -> Vec<usize> {
        self.dims()
    }

    /// Threads a step runs on: 1 for the serial step (the default), n for the
    /// parallel network step on n threads. Setting it switches between the two
    /// at any time (the numbers are the same bit for bit); a value < 1 raises
    /// `ParameterError` and changes nothing. A model network steps serially
    /// (only 1 is accepted).
    #[getter]
    fn threads(&self) -> usize {
        match &self.inner {
            Inner::Typed(net) => net.threads(),
            Inner::Models(_) => 1,
        }
    }

    #[setter]
    fn set_threads(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let t = threads_from_py(value)?;
        match &mut self.inner {
            Inner::Typed(net) => net.set_threads(t).py(),
            Inner::Models(_) if t == 1 => Ok(()),
            Inner::Models(_) => Err(ParameterError::new_err(format!(
                "threads: got {t}; a model network steps serially (threads 1); the \
                 parallel step is for scenarios of the paper's kinds"
            ))),
        }
    }

    /// Combination weights in use (N, N). Dense: `SizeError` when N × N does
    /// not fit in memory (`neighbours` holds the same weights as lists).
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let w = match &self.inner {
            Inner::Typed(net) => net.graph().to_dense().py()?,
            Inner::Models(m) => m.net.weights(),
        };
        to_numpy(py, w, &[self.k, self.k])
    }

    /// The graph and combination weights in use as neighbour lists
    /// `(offsets, indices, weights)`, as `Scenario.neighbours`.
    #[getter]
    fn neighbours<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        match &self.inner {
            Inner::Typed(net) => crate::convert::neighbours_to_py(py, net.graph()),
            Inner::Models(m) => {
                let g = edccif_sim::topology::NeighbourLists::from_dense(&m.net.weights(), self.k)
                    .py()?;
                crate::convert::neighbours_to_py(py, &g)
            }
        }
    }

    /// Fused estimates (N, n).
    #[getter]
    fn estimates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = vec![0.0; self.k * self.n];
        match &self.inner {
            Inner::Typed(net) => net.write_estimates(&mut v),
            Inner::Models(m) => {
                v.clear();
                m.net.write_estimates(&mut v);
            }
        }
        small_to_numpy2(py, &v, self.k, self.n)
    }

    /// Fused covariances (N, n, n).
    #[getter]
    fn covariances<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = vec![0.0; self.k * self.n * self.n];
        match &self.inner {
            Inner::Typed(net) => net.write_covariances(&mut v),
            Inner::Models(m) => {
                v.clear();
                m.net.write_covariances(&mut v);
            }
        }
        to_numpy(py, v, &[self.k, self.n, self.n])
    }

    /// Pre-combination estimates of the last step (N, n).
    #[getter]
    fn local_estimates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = vec![0.0; self.k * self.n];
        match &self.inner {
            Inner::Typed(net) => net.write_local_estimates(&mut v),
            Inner::Models(m) => {
                v.clear();
                m.net.write_local_estimates(&mut v);
            }
        }
        to_numpy(py, v, &[self.k, self.n])
    }

    /// Trigger flags of the last step (N,) bool (False also where no measurement).
    #[getter]
    fn triggered<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        let t = match &self.inner {
            Inner::Typed(net) => {
                let mut t = vec![false; self.k];
                let mut m = vec![false; self.k];
                net.write_triggered(&mut t, &mut m);
                t
            }
            Inner::Models(m) => m
                .net
                .last_triggered()
                .into_iter()
                .map(|g| g == Some(true))
                .collect(),
        };
        to_numpy_bool(py, t, &[self.k])
    }

    /// Totals so far (dict).
    #[getter]
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::scenario::json_to_py(
            py,
            &serde_json::to_value(self.counters_value()).unwrap_or_default(),
        )
    }

    /// The algorithm row.
    #[getter]
    fn algorithm(&self) -> &'static str {
        self.algorithm.name()
    }

    /// Replaces node `i`'s estimate (e.g. when a node rejoins): `i` in `0..N`
    /// (else `ParameterError`), `x` (n,), `P` (n, n), checked; on error the
    /// network is unchanged.
    #[pyo3(signature = (i, x, P))]
    #[allow(non_snake_case)]
    fn reset_node(
        &mut self,
        i: &Bound<'_, PyAny>,
        x: &Bound<'_, PyAny>,
        P: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let i = args::index(i, "i", self.k)?;
        let (xv, _) = finite_array(x, "x", &[Dim::Is(self.n)])?;
        let (pv, _) = finite_array(P, "P", &[Dim::Is(self.n), Dim::Is(self.n)])?;
        match &mut self.inner {
            Inner::Typed(net) => net.reset_node(i, &xv, &pv).py(),
            Inner::Models(m) => m.net.reset_node(i, &xv, &pv).py(),
        }
    }

    fn __repr__(slf: &Bound<'_, Self>) -> PyResult<String> {
        let class = slf.get_type().name()?.to_string();
        let me = slf.borrow();
        Ok(match &me.inner {
            Inner::Typed(_) => format!(
                "{class}(algorithm={:?}, nodes={}, state_dim={})",
                me.algorithm.name(),
                me.k,
                me.n
            ),
            Inner::Models(m) => format!(
                "{class}(algorithm={:?}, nodes={}, state_dim={}, meas_dims={:?})",
                me.algorithm.name(),
                me.k,
                me.n,
                m.meas_dims
            ),
        })
    }
}

/// A network of one's own models: one motion model, per node a sensor of its own
/// kind and measurement dimension, any graph, every algorithm row. An
/// `edccif.Network` (every method and property is `Network`'s); only the
/// constructor differs: `ModelNetwork(...)` is `Network.from_models(...)`.
///
/// >>> import numpy as np, edccif
/// >>> from edccif import models
/// >>> cv = models.CustomMotion(lambda X, dt: X, np.eye(2) * 0.01, n=2)
/// >>> pos = models.LinearMeasurement(np.eye(2), np.eye(2) * 0.1)
/// >>> x_only = models.LinearMeasurement(np.array([[1.0, 0.0]]), np.array([[0.1]]))
/// >>> net = edccif.ModelNetwork(cv, [pos, x_only], x0=np.zeros(2), P0=np.eye(2), dt=1.0)
/// >>> net.step([np.array([1.0, 2.0]), None]).shape
/// (2, 2)
/// >>> isinstance(net, edccif.Network)
/// True
#[pyclass(extends = PyNetwork, name = "ModelNetwork", module = "edccif")]
pub struct PyModelNetwork;

impl PyModelNetwork {
    /// The network the constructor builds (also the replay of a recording
    /// with models).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn create(
        motion: &Bound<'_, PyAny>,
        sensors: &Bound<'_, PyAny>,
        algorithm_name: &str,
        x0: &Bound<'_, PyAny>,
        p0: &Bound<'_, PyAny>,
        adjacency: Option<&Bound<'_, PyAny>>,
        weights: Option<&Bound<'_, PyAny>>,
        dt: Option<f64>,
        t0: f64,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PyNetwork> {
        PyNetwork::of_models(
            motion,
            sensors,
            algorithm_name,
            x0,
            p0,
            adjacency,
            weights,
            dt,
            t0,
            options,
        )
    }
}

#[pymethods]
impl PyModelNetwork {
    /// `motion`: an `edccif.models` motion model (state dimension n); `sensors`:
    /// one `edccif.models` measurement model per node, each with its own m;
    /// `algorithm`: a row of `edccif.ALGORITHMS`; `x0` (n,), `P0` (n, n): every
    /// node's start; `adjacency` (k, k) bool and/or `weights` (k, k) (symmetric,
    /// rows summing to 1, > 0 exactly on the edges; default: the complete graph
    /// with max-degree weights); `dt`: the nominal step of `step(z)` without
    /// `t`/`dt`; `t0`: the time of `x0`. Options as for `edccif.run` (`delta`
    /// default 0.04 on the squared change of a node's measurement vector;
    /// `sigma1`, `sigma2` default 5e-4; `consensus_iters` default the adequate
    /// L of the weights).
    #[new]
    #[pyo3(signature = (motion, sensors, algorithm = "edc-cif", *, x0, P0, adjacency = None, weights = None, dt = None, t0 = 0.0, **options))]
    #[allow(clippy::too_many_arguments, non_snake_case)]
    fn new(
        motion: &Bound<'_, PyAny>,
        sensors: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        adjacency: Option<&Bound<'_, PyAny>>,
        weights: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
        #[pyo3(from_py_with = crate::args::real_arg::t0)] t0: f64,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<(Self, PyNetwork)> {
        let base = Self::create(
            motion, sensors, algorithm, x0, P0, adjacency, weights, dt, t0, options,
        )?;
        Ok((Self, base))
    }
}
