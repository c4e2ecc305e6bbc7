//! `edccif.ModelNetwork` (also `edccif.Network.from_models`): a network of one's
//! own models — any node count and graph, one motion model (`edccif.models.*`),
//! and per node a sensor of its own kind and measurement dimension. The logic is
//! `edccif_sim::mixed`; this module maps the runtime sizes to const generics
//! (through [`crate::dims`]), shares the model adapters so a failing Python
//! callable's error is raised, and converts arrays.

use std::sync::Arc;

use edccif_core::{Gaussian, StepReport};
use edccif_sim::mixed::{MixedNetwork, NodeSensor, SensorNode};
use edccif_sim::{Algorithm, Counters, RowParams, RunResult};
use nalgebra::{SMatrix, SVector};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::adapters::{MotionAdapter, SensorAdapter, Shared};
use crate::convert::{
    bool_array, f64_array, finite_array, small_to_numpy2, to_numpy, to_numpy_bool, Dim,
};
use crate::errors::{GraphError, IntoPyResult, ParameterError, ShapeError};
use crate::models::{PyMeasurementModel, PyMotionModel};
use crate::runner::{algorithm, options_from_kwargs, step_dt, wrap_result, PyRunResult};
use crate::{with_m, with_n};

/// Default send-on-delta threshold of the event-triggered rows (the paper's δ,
/// on the squared change of the measurement vector).
pub const DEFAULT_DELTA: f64 = 0.04;

/// Something whose Python callables may have failed during a step.
trait Failing: Send + Sync {
    fn take_failure(&self) -> Option<PyErr>;
}

impl<const N: usize> Failing for Arc<MotionAdapter<N>> {
    fn take_failure(&self) -> Option<PyErr> {
        self.failure.take()
    }
}

impl<const N: usize, const M: usize> Failing for Arc<SensorAdapter<N, M>> {
    fn take_failure(&self) -> Option<PyErr> {
        self.failure.take()
    }
}

/// The network with its state dimension erased.
trait DynNetwork: Send + Sync {
    fn meas_dims(&self) -> Vec<usize>;
    fn weights(&self) -> Vec<f64>;
    fn step(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> edccif_sim::Result<StepReport>;
    fn run(
        &mut self,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        cov: bool,
        ctl: &edccif_sim::control::Control,
    ) -> edccif_sim::Result<RunResult>;
    fn write_estimates(&self, out: &mut Vec<f64>);
    fn write_covariances(&self, out: &mut Vec<f64>);
    fn write_local_estimates(&self, out: &mut Vec<f64>);
    fn last_triggered(&self) -> Vec<Option<bool>>;
    fn counters(&self) -> Counters;
    fn reset_node(&mut self, i: usize, x: &[f64], p: &[f64]) -> edccif_sim::Result<()>;
}

impl<const N: usize> DynNetwork for MixedNetwork<N> {
    fn meas_dims(&self) -> Vec<usize> {
        MixedNetwork::meas_dims(self)
    }
    fn weights(&self) -> Vec<f64> {
        MixedNetwork::weights(self).to_vec()
    }
    fn step(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> edccif_sim::Result<StepReport> {
        self.step_with(z, dt, links, active)
    }
    fn run(
        &mut self,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        cov: bool,
        ctl: &edccif_sim::control::Control,
    ) -> edccif_sim::Result<RunResult> {
        MixedNetwork::run_with_noise_control(self, z, dt, noise, cov, ctl)
    }
    fn write_estimates(&self, out: &mut Vec<f64>) {
        for g in self.estimates() {
            out.extend_from_slice(g.x.as_slice());
        }
    }
    fn write_covariances(&self, out: &mut Vec<f64>) {
        for g in self.estimates() {
            out.extend_from_slice(g.p.transpose().as_slice());
        }
    }
    fn write_local_estimates(&self, out: &mut Vec<f64>) {
        for g in self.local_estimates() {
            out.extend_from_slice(g.x.as_slice());
        }
    }
    fn last_triggered(&self) -> Vec<Option<bool>> {
        MixedNetwork::last_triggered(self).collect()
    }
    fn counters(&self) -> Counters {
        MixedNetwork::counters(self)
    }
    fn reset_node(&mut self, i: usize, x: &[f64], p: &[f64]) -> edccif_sim::Result<()> {
        let g = Gaussian {
            x: SVector::from_column_slice(x),
            p: SMatrix::from_row_slice(p),
        };
        MixedNetwork::reset_node(self, i, g)
    }
}

type Built = (Box<dyn DynNetwork>, Vec<Box<dyn Failing>>);

#[allow(clippy::too_many_arguments)]
fn build<const N: usize>(
    alg: Algorithm,
    params: &RowParams,
    opt: &edccif_sim::RunOptions,
    motion: &PyMotionModel,
    sensors: &[PyRef<'_, PyMeasurementModel>],
    weights: Vec<f64>,
    x0: &[f64],
    p0: &[f64],
    dt: f64,
) -> PyResult<Built> {
    let m_adapter = Arc::new(MotionAdapter::<N>::new(&motion.spec)?);
    let mut failing: Vec<Box<dyn Failing>> = vec![Box::new(Arc::clone(&m_adapter))];
    let mut nodes: Vec<Box<dyn NodeSensor<N>>> = Vec::with_capacity(sensors.len());
    for s in sensors {
        let m = s.spec.m();
        let node: Box<dyn NodeSensor<N>> = with_m!(m, |M| {
            let a = Arc::new(SensorAdapter::<N, M>::new(&s.spec)?);
            failing.push(Box::new(Arc::clone(&a)));
            Ok::<Box<dyn NodeSensor<N>>, PyErr>(Box::new(SensorNode::<_, M>::new(Shared::new(a))))
        })?;
        nodes.push(node);
    }
    let start = Gaussian::new(SVector::from_column_slice(x0), SMatrix::from_row_slice(p0)).py()?;
    let net = MixedNetwork::new(
        alg,
        params,
        opt,
        Box::new(Shared::new(m_adapter)),
        nodes,
        weights,
        start,
        dt,
    )
    .map_err(graph_err)?;
    Ok((Box::new(net), failing))
}

/// Graph problems are `GraphError`s whichever layer found them.
fn graph_err(e: edccif_sim::Error) -> PyErr {
    match e {
        edccif_sim::Error::Scenario { .. } => GraphError::new_err(e.to_string()),
        other => crate::errors::to_py(other),
    }
}

/// Row-major max-degree weights of a validated adjacency.
fn weights_from(
    k: usize,
    adjacency: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
) -> PyResult<Vec<f64>> {
    let a = adjacency
        .filter(|a| !a.is_none())
        .map(|a| bool_array(a, "adjacency", &[Dim::Is(k), Dim::Is(k)]))
        .transpose()?;
    let w = weights
        .filter(|w| !w.is_none())
        .map(|w| finite_array(w, "weights", &[Dim::Is(k), Dim::Is(k)]).map(|(v, _)| v))
        .transpose()?;
    let adj = match (&a, &w) {
        (Some(a), _) => a.clone(),
        (None, Some(w)) => edccif_sim::topology::adjacency_of_weights(w, k),
        (None, None) => edccif_sim::Topology::Complete
            .adjacency(k)
            .map_err(graph_err)?,
    };
    edccif_core::fusion::validate_adjacency(&adj, k).py()?;
    match w {
        Some(w) => {
            edccif_sim::topology::validate_weights(&w, &adj, k).map_err(graph_err)?;
            Ok(w)
        }
        None => edccif_sim::topology::weights(&adj, k).map_err(graph_err),
    }
}

/// A network of one's own models: one motion model, per node a sensor of its own
/// kind and measurement dimension, any graph, every algorithm row.
///
/// >>> import numpy as np, edccif
/// >>> from edccif import models
/// >>> cv = models.CustomMotion(lambda X, dt: X, np.eye(2) * 0.01, n=2)
/// >>> pos = models.LinearMeasurement(np.eye(2), np.eye(2) * 0.1)
/// >>> x_only = models.LinearMeasurement(np.array([[1.0, 0.0]]), np.array([[0.1]]))
/// >>> net = edccif.ModelNetwork(cv, [pos, x_only], x0=np.zeros(2), P0=np.eye(2), dt=1.0)
/// >>> net.step([np.array([1.0, 2.0]), None]).shape
/// (2, 2)
#[pyclass(name = "ModelNetwork", module = "edccif")]
pub struct PyModelNetwork {
    net: Box<dyn DynNetwork>,
    failing: Vec<Box<dyn Failing>>,
    algorithm: Algorithm,
    meas_dims: Vec<usize>,
    offsets: Vec<usize>,
    k: usize,
    n: usize,
    t: f64,
    dt: Option<f64>,
}

impl PyModelNetwork {
    /// The constructor's work (`ModelNetwork(...)`, `Network.from_models`, and
    /// the replay of a recording with models).
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
    ) -> PyResult<Self> {
        let motion: PyRef<'_, PyMotionModel> = motion.extract().map_err(|_| {
            ParameterError::new_err(format!(
                "motion: expected an edccif.models motion model, got {}",
                type_name(motion)
            ))
        })?;
        let mut list: Vec<PyRef<'_, PyMeasurementModel>> = Vec::new();
        for (i, s) in sensors.try_iter()?.enumerate() {
            let s = s?;
            list.push(s.extract().map_err(|_| {
                ParameterError::new_err(format!(
                    "sensors[{i}]: expected an edccif.models measurement model, got {}",
                    type_name(&s)
                ))
            })?);
        }
        let k = list.len();
        if k == 0 {
            return Err(ParameterError::new_err(
                "sensors: expected at least one sensor (one per node)",
            ));
        }
        let alg = algorithm(algorithm_name)?;
        let opt = options_from_kwargs(options)?;
        let n = motion.spec.n();
        crate::dims::check_n(n)?;
        for (i, s) in list.iter().enumerate() {
            s.spec.check_state_dim(n, &format!("sensors[{i}]"))?;
            crate::dims::check_m(s.spec.m())?;
        }
        let (xv, _) = finite_array(x0, "x0", &[Dim::Is(n)])?;
        let (pv, _) = finite_array(p0, "P0", &[Dim::Is(n), Dim::Is(n)])?;
        if let Some(d) = dt {
            edccif_sim::timestep::check_dt(d, "dt").py()?;
        }
        if !t0.is_finite() {
            return Err(crate::errors::NonFiniteError::new_err(format!(
                "t0: the time of the initial estimate must be finite, got {t0}"
            )));
        }
        let w = weights_from(k, adjacency, weights)?;
        let iters = edccif_sim::topology::adequate_consensus_iterations(&w, k);
        let params = RowParams {
            delta: DEFAULT_DELTA,
            ..RowParams::paper(iters)
        };
        let (net, failing) = with_n!(n, |N| build::<N>(
            alg,
            &params,
            &opt,
            &motion,
            &list,
            w.clone(),
            &xv,
            &pv,
            dt.unwrap_or(1.0)
        ))?;
        let meas_dims = net.meas_dims();
        let mut offsets = vec![0];
        for m in &meas_dims {
            offsets.push(offsets.last().copied().unwrap_or(0) + m);
        }
        Ok(Self {
            net,
            failing,
            algorithm: alg,
            meas_dims,
            offsets,
            k,
            n,
            t: t0,
            dt,
        })
    }

    /// The result, or the error a model callable recorded (which wins: the
    /// network's error is then only its consequence).
    fn finish<T>(&self, r: edccif_sim::Result<T>) -> PyResult<T> {
        let mut failed = None;
        for f in &self.failing {
            if let Some(e) = f.take_failure() {
                failed.get_or_insert(e);
            }
        }
        match (failed, r) {
            (Some(e), _) => Err(e),
            (None, Ok(v)) => Ok(v),
            (None, Err(e)) => Err(crate::errors::to_py(e)),
        }
    }

    /// One step's measurements: a sequence of one entry per node, each `None` or
    /// an array of the node's `m` values (all NaN: no measurement).
    fn step_measurements(&self, z: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
        let len = z.len().map_err(|_| {
            ShapeError::new_err(format!(
                "z: expected a sequence of {} per-node measurements (arrays of {:?} values or None), got {}",
                self.k, self.meas_dims, type_name(z)
            ))
        })?;
        if len != self.k {
            return Err(ShapeError::new_err(format!(
                "z: expected one measurement per node ({} nodes), got {len}",
                self.k
            )));
        }
        let mut out = Vec::with_capacity(self.offsets[self.k]);
        for (i, &m) in self.meas_dims.iter().enumerate() {
            let item = z.get_item(i)?;
            if item.is_none() {
                out.extend(std::iter::repeat_n(f64::NAN, m));
            } else {
                let (v, _) = f64_array(&item, &format!("z[{i}]"), &[Dim::Is(m)])?;
                out.extend(v);
            }
        }
        Ok(out)
    }

    fn estimates_array<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = Vec::with_capacity(self.k * self.n);
        self.net.write_estimates(&mut v);
        small_to_numpy2(py, &v, self.k, self.n)
    }

    /// Every node's measurement dimension.
    pub(crate) fn dims(&self) -> &[usize] {
        &self.meas_dims
    }

    /// Runs `T = dt.len()` steps on flat rows `z` `(T, Σ m_i)` with optional
    /// per-step noise `(T, Σ m_i²)` (NaN: the sensor's own), covariances
    /// recorded; on error the network is unchanged. Reports its steps to `progress`.
    pub(crate) fn run_flat(
        &mut self,
        py: Python<'_>,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        progress: &crate::drive::Progress,
    ) -> PyResult<RunResult> {
        // Long runs (or runs with a progress reporter) stop on Ctrl-C with the network as it was.
        let long = crate::drive::network_work(dt.len(), self.k, 0) >= crate::drive::LONG_WORK
            || !matches!(progress, crate::drive::Progress::Off);
        let net = &mut self.net;
        let r = crate::drive::drive_if(py, long, progress, |ctl| net.run(z, dt, noise, true, ctl))
            .into_result()?;
        let r = self.finish(r)?;
        self.t += dt.iter().sum::<f64>();
        Ok(r)
    }
}

/// `ModelNetwork.run`'s `Rs`: per node `None`, one `(m, m)` noise for every
/// step, or `(T, m, m)`; as the flat `(T, Σ m_i²)` the network takes (NaN
/// where a node keeps its sensor's `R`), `None` when every entry is `None`.
fn run_noise(rs: &Bound<'_, PyAny>, dims: &[usize], steps: usize) -> PyResult<Option<Vec<f64>>> {
    let k = dims.len();
    let len = rs.len().map_err(|_| {
        ShapeError::new_err(format!(
            "Rs: expected a sequence of {k} per-node noises (None, (m, m) or (T, m, m)), got {}",
            type_name(rs)
        ))
    })?;
    if len != k {
        return Err(ShapeError::new_err(format!(
            "Rs: expected one entry per node ({k} nodes), got {len}"
        )));
    }
    let per_step: usize = dims.iter().map(|m| m * m).sum();
    let mut out = vec![f64::NAN; steps * per_step];
    let mut any = false;
    let mut off = 0;
    for (i, &m) in dims.iter().enumerate() {
        let item = rs.get_item(i)?;
        if !item.is_none() {
            let name = format!("Rs[{i}]");
            let py = item.py();
            let blocks = match finite_array(&item, &name, &[Dim::Is(m), Dim::Is(m)]) {
                Ok((one, _)) => one.repeat(steps),
                Err(e) if !e.is_instance_of::<ShapeError>(py) => return Err(e),
                Err(_) => finite_array(&item, &name, &[Dim::Is(steps), Dim::Is(m), Dim::Is(m)])?.0,
            };
            for s in 0..steps {
                let dst = s * per_step + off;
                out[dst..dst + m * m].copy_from_slice(&blocks[s * m * m..(s + 1) * m * m]);
            }
            any = true;
        }
        off += m * m;
    }
    Ok(any.then_some(out))
}

fn type_name(o: &Bound<'_, PyAny>) -> String {
    o.get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string())
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
    ) -> PyResult<Self> {
        Self::create(
            motion, sensors, algorithm, x0, P0, adjacency, weights, dt, t0, options,
        )
    }

    /// One step: `z` has one entry per node, `None` or the node's (m,) values (a
    /// NaN entry: no measurement, the node predicts and still fuses). The step
    /// predicts over `dt`, or up to the timestamp `t`, or over the constructor's
    /// `dt`. Optional `links` (k, k) and `active` (k,) masks as for `Network.step`.
    /// Returns the fused estimates (k, n). On error the network is unchanged.
    #[pyo3(signature = (z, *, t = None, dt = None, links = None, active = None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        z: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::t)] t: Option<f64>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
        links: Option<&Bound<'py, PyAny>>,
        active: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        if t.is_none() && dt.is_none() && self.dt.is_none() {
            return Err(ParameterError::new_err(
                "no time step: pass step(z, t=...) or step(z, dt=...), or dt= to the constructor",
            ));
        }
        let d = step_dt(t, dt, self.t, self.dt.unwrap_or(f64::NAN))?;
        let zv = self.step_measurements(z)?;
        let l = links
            .filter(|o| !o.is_none())
            .map(|o| bool_array(o, "links", &[Dim::Is(self.k), Dim::Is(self.k)]))
            .transpose()?;
        let a = active
            .filter(|o| !o.is_none())
            .map(|o| bool_array(o, "active", &[Dim::Is(self.k)]))
            .transpose()?;
        let r = self.net.step(&zv, d, l.as_deref(), a.as_deref());
        self.finish(r)?;
        self.t = t.unwrap_or(self.t + d);
        self.estimates_array(py)
    }

    /// Runs `T` steps: `z` has one entry per node, `None` or an array (T, m) of
    /// that node's measurements (NaN rows: none that step); `t` (T,) the
    /// timestamps (after the network's `t`) or `dt` one step (float or (T,)),
    /// default the constructor's `dt`; `Rs` each step's measurement noise, one
    /// entry per node: `None` (the sensor's own `R`), an (m, m) for every step
    /// or (T, m, m), one per step (each finite, symmetric, positive definite;
    /// the error names the step and node). Continues
    /// from the current state and returns a `RunResult`; on error the network
    /// is unchanged.
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
        let progress = crate::drive::Progress::from_arg(progress, "ModelNetwork.run", "steps")?;
        let len = z.len().map_err(|_| {
            ShapeError::new_err(format!(
                "z: expected a sequence of {} per-node arrays (T, m) or None, got {}",
                self.k,
                type_name(z)
            ))
        })?;
        if len != self.k {
            return Err(ShapeError::new_err(format!(
                "z: expected one array per node ({} nodes), got {len}",
                self.k
            )));
        }
        let mut cols: Vec<Option<(Vec<f64>, usize)>> = Vec::with_capacity(self.k);
        let mut steps = None;
        for (i, &m) in self.meas_dims.iter().enumerate() {
            let item = z.get_item(i)?;
            if item.is_none() {
                cols.push(None);
                continue;
            }
            let dims = match steps {
                Some(s) => [Dim::Is(s), Dim::Is(m)],
                None => [Dim::Any("T"), Dim::Is(m)],
            };
            let (v, shape) = f64_array(&item, &format!("z[{i}]"), &dims)?;
            steps = Some(shape[0]);
            cols.push(Some((v, m)));
        }
        let t_vec = t.filter(|o| !o.is_none());
        let dt_obj = dt.filter(|o| !o.is_none());
        let steps = match (steps, t_vec) {
            (Some(s), _) => s,
            (None, Some(tv)) => tv.len()?,
            (None, None) => {
                return Err(ShapeError::new_err(
                    "z: every node's entry is None; pass t= to give the number of steps",
                ))
            }
        };
        let dts: Vec<f64> = match (t_vec, dt_obj) {
            (Some(_), Some(_)) => {
                return Err(ParameterError::new_err(
                    "give either t (timestamps) or dt (time steps), not both",
                ))
            }
            (Some(tv), None) => crate::runner::dt_from_timestamps(tv, self.t, steps)?,
            (None, Some(d)) => match d.extract::<f64>() {
                Ok(v) => vec![v; steps],
                Err(_) => f64_array(d, "dt", &[Dim::Is(steps)])?.0,
            },
            (None, None) => match self.dt {
                Some(v) => vec![v; steps],
                None => return Err(ParameterError::new_err(
                    "no time step: pass run(z, t=...) or run(z, dt=...), or dt= to the constructor",
                )),
            },
        };
        let total = self.offsets[self.k];
        edccif_sim::runner::check_run_size(steps, self.k, self.n, record_covariances).py()?;
        let mut flat = vec![f64::NAN; steps * total];
        for (i, c) in cols.iter().enumerate() {
            if let Some((v, m)) = c {
                for s in 0..steps {
                    let dst = s * total + self.offsets[i];
                    flat[dst..dst + m].copy_from_slice(&v[s * m..(s + 1) * m]);
                }
            }
        }
        let noise = match Rs.filter(|o| !o.is_none()) {
            Some(rs) => run_noise(rs, &self.meas_dims, steps)?,
            None => None,
        };
        // Long runs on a worker thread (a model's Python callables take the GIL
        // there), stopping on Ctrl-C with the network as it was.
        let long = crate::drive::network_work(steps, self.k, 0) >= crate::drive::LONG_WORK;
        let net = &mut self.net;
        let r = crate::drive::drive_if(py, long, &progress, |ctl| {
            net.run(&flat, &dts, noise.as_deref(), record_covariances, ctl)
        })
        .into_result()?;
        let r = self.finish(r)?;
        self.t += dts.iter().sum::<f64>();
        if let Some(tv) = t_vec {
            if let Ok(last) = tv.get_item(steps - 1).and_then(|o| o.extract::<f64>()) {
                self.t = last;
            }
        }
        wrap_result(py, r, record_covariances)
    }

    /// Fused estimates (k, n).
    #[getter]
    fn estimates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.estimates_array(py)
    }

    /// Fused covariances (k, n, n).
    #[getter]
    fn covariances<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = Vec::with_capacity(self.k * self.n * self.n);
        self.net.write_covariances(&mut v);
        to_numpy(py, v, &[self.k, self.n, self.n])
    }

    /// Pre-combination estimates of the last step (k, n).
    #[getter]
    fn local_estimates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let mut v = Vec::with_capacity(self.k * self.n);
        self.net.write_local_estimates(&mut v);
        to_numpy(py, v, &[self.k, self.n])
    }

    /// Trigger flags of the last step (k,) bool (False also where no measurement).
    #[getter]
    fn triggered<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        let t = self
            .net
            .last_triggered()
            .into_iter()
            .map(|g| g == Some(true))
            .collect();
        to_numpy_bool(py, t, &[self.k])
    }

    /// Totals so far (dict, as `Network.counters`).
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

    /// Time of the current estimates (s).
    #[getter]
    fn t(&self) -> f64 {
        self.t
    }

    /// Number of nodes k.
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
        self.meas_dims.clone()
    }

    /// Combination weights (k, k).
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(py, self.net.weights(), &[self.k, self.k])
    }

    /// Replaces node `i`'s estimate (`x` (n,), `P` (n, n), checked).
    #[pyo3(signature = (i, x, P))]
    #[allow(non_snake_case)]
    fn reset_node(
        &mut self,
        #[pyo3(from_py_with = crate::args::named::i)] i: usize,
        x: &Bound<'_, PyAny>,
        P: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let (xv, _) = finite_array(x, "x", &[Dim::Is(self.n)])?;
        let (pv, _) = finite_array(P, "P", &[Dim::Is(self.n), Dim::Is(self.n)])?;
        self.net.reset_node(i, &xv, &pv).py()
    }

    fn __repr__(&self) -> String {
        format!(
            "ModelNetwork(algorithm={:?}, nodes={}, state_dim={}, meas_dims={:?})",
            self.algorithm.name(),
            self.k,
            self.n,
            self.meas_dims
        )
    }
}

/// `Network.from_models(...)`: the same as `ModelNetwork(...)`.
#[allow(clippy::too_many_arguments)]
pub fn from_models(
    motion: &Bound<'_, PyAny>,
    sensors: &Bound<'_, PyAny>,
    algorithm: &str,
    x0: &Bound<'_, PyAny>,
    p0: &Bound<'_, PyAny>,
    adjacency: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
    dt: Option<f64>,
    t0: f64,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyModelNetwork> {
    PyModelNetwork::create(
        motion, sensors, algorithm, x0, p0, adjacency, weights, dt, t0, options,
    )
}
