//! `edccif.Network`: the network of a scenario's built-in models, stepping one
//! measurement row at a time.

use edccif_sim::{Algorithm, AnyNetwork};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::args;
use crate::convert::{
    bool_array, f64_array, finite_array, small_to_numpy2, to_numpy, to_numpy_bool, Dim,
};
use crate::drive::{drive, Progress};
use crate::errors::IntoPyResult;
use crate::runner::{options_from_kwargs, step_dt, threads_from_py, x0_or_default};
use crate::scenario::{scenario_with_graph, PyScenario};

/// A network for streaming use: feed one (N, 3) measurement array per step.
/// `Network(scenario, "edc-cif").step(z_k)` over a sequence gives exactly the
/// estimates of `run()`.
/// A network of the built-in models stepping one measurement row at a time.
///
/// The option `threads` (or the `threads` property, at any time) runs each step
/// on several threads: 1 (the default) is the serial step, n >= 2 the parallel
/// step on n threads, with the same numbers bit for bit; a parallel step
/// releases the GIL. It pays off only for large networks (about 64 nodes and
/// more).
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
#[pyclass(name = "Network", module = "edccif")]
pub struct PyNetwork {
    net: AnyNetwork,
    algorithm: Algorithm,
    k: usize,
    n: usize,
    zbuf: Vec<f64>,
    /// Time of the current estimates (s).
    t: f64,
    /// The nominal step of `step()` without `t`/`dt`.
    nominal_dt: f64,
}

#[pymethods]
impl PyNetwork {
    /// `adjacency` (N, N) bool and/or `weights` (N, N) replace the scenario's
    /// graph (see `Scenario.replace(topology=..., weights=...)`); `t0` is the time
    /// of the initial estimate for `step(z, t=...)`.
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
        let alg = crate::runner::algorithm(algorithm)?;
        let opt = options_from_kwargs(options)?;
        let x0v = x0_or_default(&scenario, x0)?;
        if !t0.is_finite() {
            return Err(crate::errors::NonFiniteError::new_err(format!(
                "t0: the time of the initial estimate must be finite, got {t0}"
            )));
        }
        let sc = scenario_with_graph(&scenario.inner, adjacency, weights)?;
        let net = AnyNetwork::new(alg, &sc, &x0v, &opt).py()?;
        Ok(Self {
            k: net.nodes(),
            n: net.state_dim(),
            net,
            algorithm: alg,
            zbuf: Vec::new(),
            t: t0,
            nominal_dt: sc.dt,
        })
    }

    /// One step with measurements `z_k` (N, 3) (a NaN row: no measurement); returns
    /// the fused estimates (N, n). Optional `links` (N, N) bool (`links[i, j]`: i hears
    /// j) and `active` (N,) bool masks model lost messages and nodes that are down.
    /// The step predicts over `dt` (s), or up to the timestamp `t` (after the
    /// network's `t`), or over the scenario's `dt` when neither is given.
    /// On error the network is unchanged.
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
        let d = step_dt(t, dt, self.t, self.nominal_dt)?;
        let (zv, _) = f64_array(z, "z", &[Dim::Is(self.k), Dim::Is(3)])?;
        self.zbuf = zv;
        let l = links
            .map(|o| bool_array(o, "links", &[Dim::Is(self.k), Dim::Is(self.k)]))
            .transpose()?;
        let a = active
            .map(|o| bool_array(o, "active", &[Dim::Is(self.k)]))
            .transpose()?;
        let (net, zbuf) = (&mut self.net, &self.zbuf);
        let stepped = if net.heavy() {
            // Many consensus rounds: on a worker thread, interruptible between rounds.
            drive(py, &Progress::Off, |ctl| {
                net.step_dt_with_control(zbuf, d, l.as_deref(), a.as_deref(), ctl)
            })
            .into_result()?
        } else if net.parallel() {
            // The parallel step is for large networks: let other Python threads run.
            py.allow_threads(|| net.step_dt_with(zbuf, d, l.as_deref(), a.as_deref()))
        } else {
            net.step_dt_with(zbuf, d, l.as_deref(), a.as_deref())
        };
        stepped.py()?;
        self.t = t.unwrap_or(self.t + d);
        self.estimates(py)
    }

    /// A network of one's own models (`edccif.models`): the same as
    /// `edccif.ModelNetwork(motion, sensors, algorithm, x0=..., P0=..., ...)`.
    #[staticmethod]
    #[pyo3(signature = (motion, sensors, algorithm = "edc-cif", *, x0, P0, adjacency = None, weights = None, dt = None, t0 = 0.0, **options))]
    #[allow(clippy::too_many_arguments, non_snake_case)]
    fn from_models(
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
    ) -> PyResult<crate::network::PyModelNetwork> {
        crate::network::from_models(
            motion, sensors, algorithm, x0, P0, adjacency, weights, dt, t0, options,
        )
    }

    /// Time of the current estimates (s): `t0` plus the steps taken.
    #[getter]
    fn t(&self) -> f64 {
        self.t
    }

    /// Threads a step runs on: 1 for the serial step (the default), n for the
    /// parallel network step on n threads. Setting it switches between the two
    /// at any time (the numbers are the same bit for bit); a value < 1 raises
    /// `ParameterError` and changes nothing.
    #[getter]
    fn threads(&self) -> usize {
        self.net.threads()
    }

    #[setter]
    fn set_threads(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let t = threads_from_py(value)?;
        self.net.set_threads(t).py()
    }

    /// Combination weights in use (N, N). Dense: `SizeError` when N × N does
    /// not fit in memory (`neighbours` holds the same weights as lists).
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(py, self.net.graph().to_dense().py()?, &[self.k, self.k])
    }

    /// The graph and combination weights in use as neighbour lists
    /// `(offsets, indices, weights)`, as `Scenario.neighbours`.
    #[getter]
    fn neighbours<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        crate::convert::neighbours_to_py(py, self.net.graph())
    }

    /// Fused estimates (N, n).
    #[getter]
    fn estimates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = vec![0.0; self.k * self.n];
        self.net.write_estimates(&mut v);
        small_to_numpy2(py, &v, self.k, self.n)
    }

    /// Fused covariances (N, n, n).
    #[getter]
    fn covariances<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = vec![0.0; self.k * self.n * self.n];
        self.net.write_covariances(&mut v);
        to_numpy(py, v, &[self.k, self.n, self.n])
    }

    /// Pre-combination estimates of the last step (N, n).
    #[getter]
    fn local_estimates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = vec![0.0; self.k * self.n];
        self.net.write_local_estimates(&mut v);
        to_numpy(py, v, &[self.k, self.n])
    }

    /// Trigger flags of the last step (N,) bool.
    #[getter]
    fn triggered<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        let mut t = vec![false; self.k];
        let mut m = vec![false; self.k];
        self.net.write_triggered(&mut t, &mut m);
        to_numpy_bool(py, t, &[self.k])
    }

    /// Totals so far (dict).
    #[getter]
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::scenario::json_to_py(
            py,
            &serde_json::to_value(self.net.counters()).unwrap_or_default(),
        )
    }

    /// The algorithm row.
    #[getter]
    fn algorithm(&self) -> &'static str {
        self.algorithm.name()
    }

    /// Replaces node `i`'s estimate (e.g. when a node rejoins); `i` in
    /// `0..N`, else `ParameterError`.
    fn reset_node(
        &mut self,
        i: &Bound<'_, PyAny>,
        x: &Bound<'_, PyAny>,
        p: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let i = args::index(i, "i", self.k)?;
        let (xv, _) = finite_array(x, "x", &[Dim::Is(self.n)])?;
        let (pv, _) = finite_array(p, "P", &[Dim::Is(self.n), Dim::Is(self.n)])?;
        self.net.reset_node(i, &xv, &pv).py()
    }

    fn __repr__(&self) -> String {
        format!(
            "Network(algorithm={:?}, nodes={}, state_dim={})",
            self.algorithm.name(),
            self.k,
            self.n
        )
    }
}
