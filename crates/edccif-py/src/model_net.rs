//! The model network behind `edccif.Network` when it is not the typed network of
//! the paper's kinds: one's own models (`Network.from_models`,
//! `edccif.ModelNetwork`) — any node count and graph, one motion model
//! (`edccif.models.*`), and per node a sensor of its own kind and measurement
//! dimension — or the catalogue models of a per-node scenario (`[[nodes]]`).
//! The logic is `edccif_sim::mixed`; this module maps the runtime sizes to const
//! generics (through [`crate::dims`]), shares the model adapters so a failing
//! Python callable's error is raised, and converts per-node arrays.

use std::sync::Arc;

use edccif_core::{Gaussian, MotionModel, StepReport};
use edccif_sim::catalogue::MotionVisitor;
use edccif_sim::mixed::{MixedNetwork, NodeSensor, SensorNode};
use edccif_sim::{Algorithm, Counters, RowParams, RunResult};
use nalgebra::{SMatrix, SVector};
use pyo3::prelude::*;

use crate::adapters::{MotionAdapter, SensorAdapter, Shared};
use crate::convert::{bool_array, f64_array, finite_array, Dim};
use crate::errors::{GraphError, IntoPyResult, ParameterError, ShapeError};
use crate::models::{PyMeasurementModel, PyMotionModel};
use crate::{with_m, with_n};

/// Default send-on-delta threshold of the event-triggered rows (the paper's δ,
/// on the squared change of the measurement vector).
pub const DEFAULT_DELTA: f64 = 0.04;

/// Something whose Python callables may have failed during a step.
pub(crate) trait Failing: Send + Sync {
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
pub(crate) trait DynNetwork: Send + Sync {
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

/// `Network.run`'s `Rs`: per node `None`, one `(m, m)` noise for every
/// step, or `(T, m, m)`; as the flat `(T, Σ m_i²)` the network takes (NaN
/// where a node keeps its sensor's `R`), `None` when every entry is `None`.
pub(crate) fn run_noise(
    rs: &Bound<'_, PyAny>,
    dims: &[usize],
    steps: usize,
) -> PyResult<Option<Vec<f64>>> {
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

pub(crate) fn type_name(o: &Bound<'_, PyAny>) -> String {
    o.get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string())
}

/// A model network with its sizes erased, with the adapters whose Python
/// callables may fail during a step.
pub(crate) struct Models {
    pub(crate) net: Box<dyn DynNetwork>,
    failing: Vec<Box<dyn Failing>>,
    /// Whether the network holds Python models a scenario names by reference
    /// (their failures are recorded in [`crate::refs`]).
    refs: bool,
    pub(crate) meas_dims: Vec<usize>,
    offsets: Vec<usize>,
}

impl Models {
    fn new(net: Box<dyn DynNetwork>, failing: Vec<Box<dyn Failing>>, refs: bool) -> Self {
        let meas_dims = net.meas_dims();
        let mut offsets = vec![0];
        for m in &meas_dims {
            offsets.push(offsets.last().copied().unwrap_or(0) + m);
        }
        Self {
            net,
            failing,
            refs,
            meas_dims,
            offsets,
        }
    }

    /// The model network of a scenario that is not
    /// [`is_typed`](edccif_sim::Scenario::is_typed): its catalogue (or
    /// referenced Python) models, built as `edccif.run` builds them
    /// ([`edccif_sim::catalogue::run_models`]), so the steps are the run's bit
    /// for bit.
    pub(crate) fn of_scenario(
        alg: Algorithm,
        sc: &edccif_sim::Scenario,
        x0: &[f64],
        opt: &edccif_sim::RunOptions,
    ) -> PyResult<Self> {
        struct Build<'a> {
            alg: Algorithm,
            sc: &'a edccif_sim::Scenario,
            x0: &'a [f64],
            opt: &'a edccif_sim::RunOptions,
        }
        impl MotionVisitor for Build<'_> {
            type Output = Box<dyn DynNetwork>;
            fn visit<const N: usize, F>(self, motion: F) -> edccif_sim::Result<Self::Output>
            where
                F: MotionModel<f64, N> + Send + Sync + 'static,
            {
                let sensors = edccif_sim::catalogue::node_sensors::<N>(self.sc)?;
                let net = edccif_sim::mixed::model_network::<N>(
                    self.alg,
                    self.sc,
                    self.x0,
                    self.opt,
                    Box::new(motion),
                    sensors,
                )?;
                Ok(Box::new(net))
            }
        }
        let refs = sc.has_python_models();
        if refs {
            crate::refs::clear_failure();
        }
        let built = edccif_sim::catalogue::with_motion(sc, Build { alg, sc, x0, opt });
        let net = crate::refs::finish(built.map_err(graph_err))?;
        Ok(Self::new(net, Vec::new(), refs))
    }

    /// The model network of one's own models (`edccif.models`), its
    /// arguments checked; returns it with the node count and state dimension.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn of_models(
        motion: &Bound<'_, PyAny>,
        sensors: &Bound<'_, PyAny>,
        alg: Algorithm,
        opt: &edccif_sim::RunOptions,
        x0: &Bound<'_, PyAny>,
        p0: &Bound<'_, PyAny>,
        adjacency: Option<&Bound<'_, PyAny>>,
        weights: Option<&Bound<'_, PyAny>>,
        dt: Option<f64>,
    ) -> PyResult<(Self, usize, usize)> {
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
        let w = weights_from(k, adjacency, weights)?;
        let iters = edccif_sim::topology::adequate_consensus_iterations(&w, k);
        let params = RowParams {
            delta: DEFAULT_DELTA,
            ..RowParams::paper(iters)
        };
        let (net, failing) = with_n!(n, |N| build::<N>(
            alg,
            &params,
            opt,
            &motion,
            &list,
            w,
            &xv,
            &pv,
            dt.unwrap_or(1.0)
        ))?;
        Ok((Self::new(net, failing, false), k, n))
    }

    /// The result, or the error a model callable recorded (which wins: the
    /// network's error is then only its consequence).
    pub(crate) fn finish<T>(&self, r: edccif_sim::Result<T>) -> PyResult<T> {
        let mut failed = None;
        for f in &self.failing {
            if let Some(e) = f.take_failure() {
                failed.get_or_insert(e);
            }
        }
        if self.refs {
            if let Some(e) = crate::refs::take_failure() {
                failed.get_or_insert(e);
            }
        }
        match (failed, r) {
            (Some(e), _) => Err(e),
            (None, Ok(v)) => Ok(v),
            (None, Err(e)) => Err(crate::errors::to_py(e)),
        }
    }

    /// Clears what a referenced model recorded before (ahead of a step or run).
    pub(crate) fn begin(&self) {
        if self.refs {
            crate::refs::clear_failure();
        }
    }

    /// Values of one step's measurements of every node.
    pub(crate) fn total(&self) -> usize {
        self.offsets[self.meas_dims.len()]
    }

    /// One step's measurements, flat `(Σ m_i,)`: a 1-D array (a row of the
    /// `z` `Scenario.simulate` gives), or a sequence of one entry per node,
    /// each `None` or an array of the node's `m` values (all NaN: no
    /// measurement).
    pub(crate) fn step_measurements(&self, z: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
        let k = self.meas_dims.len();
        if ndim(z) == Some(1) {
            return Ok(f64_array(z, "z", &[Dim::Is(self.total())])?.0);
        }
        let len = z.len().map_err(|_| {
            ShapeError::new_err(format!(
                "z: expected a ({},) array or a sequence of {k} per-node measurements (arrays of {:?} values or None), got {}",
                self.total(), self.meas_dims, type_name(z)
            ))
        })?;
        if len != k {
            return Err(ShapeError::new_err(format!(
                "z: expected one measurement per node ({k} nodes), got {len}"
            )));
        }
        let mut out = Vec::with_capacity(self.total());
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

    /// A run's measurements, flat `(T, Σ m_i)`, and `T`: a 2-D array (the `z`
    /// `Scenario.simulate` gives), or a sequence of one entry per node, each
    /// `None` or an array `(T, m)` of that node's measurements (NaN rows: none
    /// that step); `t` gives `T` when every entry is `None`.
    pub(crate) fn run_measurements(
        &self,
        z: &Bound<'_, PyAny>,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<(Vec<f64>, usize)> {
        let k = self.meas_dims.len();
        let total = self.total();
        if ndim(z) == Some(2) {
            let (v, shape) = f64_array(z, "z", &[Dim::Any("T"), Dim::Is(total)])?;
            return Ok((v, shape[0]));
        }
        let len = z.len().map_err(|_| {
            ShapeError::new_err(format!(
                "z: expected a (T, {total}) array or a sequence of {k} per-node arrays (T, m) or None, got {}",
                type_name(z)
            ))
        })?;
        if len != k {
            return Err(ShapeError::new_err(format!(
                "z: expected one array per node ({k} nodes), got {len}"
            )));
        }
        let mut cols: Vec<Option<(Vec<f64>, usize)>> = Vec::with_capacity(k);
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
        let steps = match (steps, t) {
            (Some(s), _) => s,
            (None, Some(tv)) => tv.len()?,
            (None, None) => {
                return Err(ShapeError::new_err(
                    "z: every node's entry is None; pass t= to give the number of steps",
                ))
            }
        };
        let mut flat = vec![f64::NAN; steps * total];
        for (i, c) in cols.iter().enumerate() {
            if let Some((v, m)) = c {
                for s in 0..steps {
                    let dst = s * total + self.offsets[i];
                    flat[dst..dst + m].copy_from_slice(&v[s * m..(s + 1) * m]);
                }
            }
        }
        Ok((flat, steps))
    }
}

/// `ndim` of a NumPy array (`None` for anything else).
fn ndim(o: &Bound<'_, PyAny>) -> Option<usize> {
    o.getattr("ndim").ok()?.extract().ok()
}
