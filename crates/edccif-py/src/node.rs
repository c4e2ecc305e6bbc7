//! `edccif.Node` and `edccif.SensorTrigger`: one estimator node and one sensor's
//! event trigger, as separate objects, for running each node in its own process
//! (`edccif agent`, `edccif sensor`). The packets between the phases are plain
//! `(kind, vector, matrix)` tuples that the wire format (`encode_packet`) carries.
//!
//! A step of node `i` is: `Node.local` with what arrived from its sensor (a
//! measurement, or nothing) → the packet to publish; then, for the diffusion
//! rows, `Node.adapt` with the neighbours' contributions that arrived → the
//! packet to publish, and `Node.combine` with the neighbours' adapted estimates
//! that arrived → the fused estimate; for the consensus rows, `L` calls of
//! `Node.consensus_round`. Each phase is the
//! core's (`edccif_core::node`: `node_local_received`, `node_adapt`,
//! `node_combine`, `node_consensus_round`, `LocalOutput::commit`), the very
//! functions `network_step` loops over; this file only converts packets and keeps
//! track of the phase. Weights are renormalised over what arrived (as in
//! `run(..., faults=...)`), and the order of the sums is the in-process network
//! step's (ascending node index), so a node fed every packet reproduces `run`
//! exactly.
//!
//! The trigger runs at the sensor ([`PySensorTrigger`]): the node only learns
//! whether a measurement came (`node_local_received`). A step without one is the
//! untriggered step of the row (the error-minimised update with the last received
//! measurement `z_τ`), or a step without measurement before the first one arrived.

use edccif_core::node::{
    check_sensor_side_trigger, node_adapt, node_combine, node_consensus_round, node_local,
    node_local_received, AdaptOutput, AdaptedPacket, LocalOutput, LocalPacket,
};
use edccif_core::{
    Contribution, Fusion, Gaussian, InfoPair, MeasurementModel, MotionModel, NetworkConfig,
    NodeState, Observation, Trigger, TriggerState,
};
use edccif_sim::catalogue::{with_motion, with_sensor, MotionVisitor, SensorVisitor};
use edccif_sim::{node_config, MotionSpec, Scenario, Sensor};
use nalgebra::{SMatrix, SVector};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{f64_array, finite_array, to_numpy, Dim};
use crate::errors::{IntoPyResult, ParameterError};
use crate::runner::{algorithm, no_threads, options_from_kwargs, x0_or_default};
use crate::scenario::PyScenario;

/// Where a node is within its step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Waiting for the sensor (next: `local`).
    Idle,
    /// Local step done (next: `adapt` for diffusion).
    Local,
    /// Adaptation done (next: `combine`).
    Adapted,
    /// In consensus round `r` (next: `consensus_round`).
    Consensus(usize),
}

impl Phase {
    fn name(self) -> String {
        match self {
            Phase::Idle => "idle".into(),
            Phase::Local => "local".into(),
            Phase::Adapted => "adapted".into(),
            Phase::Consensus(r) => format!("consensus round {r}"),
        }
    }
}

/// Received packets: sender, vector (row-major values), matrix (row-major values).
type Received = Vec<(usize, Vec<f64>, Vec<f64>)>;

/// A packet to publish: kind name, vector, symmetric matrix.
type Out<const N: usize> = (&'static str, SVector<f64, N>, SMatrix<f64, N, N>);

/// What arrived from a node's sensor at a step.
#[derive(Debug, Clone, Copy)]
enum Arrived<'a> {
    /// A measurement the sensor's trigger sent.
    Sent(&'a [f64]),
    /// Nothing: the sensor measured and its trigger kept the measurement
    /// (the row's untriggered step).
    Silent,
    /// The sensor took no measurement at this step (its rate, `every` or
    /// `times`): the step without measurement, as the in-process network
    /// takes a row of NaN.
    NotMeasured,
}

/// One estimator node of state dimension `N` with a sensor of measurement
/// dimension `M`: the core's per-node phases (`edccif_core::node`) with the
/// bookkeeping of where the node is in its step.
struct NodeCore<F, H, const N: usize, const M: usize> {
    cfg: NetworkConfig<f64>,
    motion: F,
    sensor: H,
    me: usize,
    /// Row `me` of the combination matrix.
    weights: Vec<f64>,
    state: NodeState<f64, N, M>,
    phase: Phase,
    /// The current step's local output (from phase `Local` on).
    local: Option<LocalOutput<f64, N, M>>,
    /// The current step's adaptation (phase `Adapted`).
    adapted: Option<AdaptOutput<f64, N>>,
    /// The current consensus round's pair.
    cons: InfoPair<f64, N>,
    /// The estimate before combination (its covariance only when formed).
    post: Gaussian<f64, N>,
    triggered: Option<bool>,
    guard_fallbacks: u64,
    gated: u64,
    steps: u64,
}

fn wrong_phase(call: &str, phase: Phase, expected: &str) -> PyErr {
    ParameterError::new_err(format!(
        "{call}: the node is at phase '{}'; expected {expected}",
        phase.name()
    ))
}

fn info_out<const N: usize>(p: &InfoPair<f64, N>) -> Out<N> {
    ("information", p.y, p.ymat)
}

impl<F, H, const N: usize, const M: usize> NodeCore<F, H, N, M>
where
    F: MotionModel<f64, N>,
    H: MeasurementModel<f64, N, M>,
{
    fn new(
        cfg: NetworkConfig<f64>,
        motion: F,
        sensor: H,
        sc: &Scenario,
        me: usize,
        x0: &[f64],
    ) -> edccif_sim::Result<Self> {
        let p0 = SMatrix::<f64, N, N>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
        let start = Gaussian::new(vec_of::<N>(x0), p0)?;
        let k = sc.nodes();
        // Node `me`'s row of the weights, from the lists (no N × N matrix).
        let g = sc.neighbours()?;
        let mut row = vec![0.0; k];
        for (&j, &c) in g.row(me).iter().zip(g.row_weights(me)) {
            row[j] = c;
        }
        Ok(Self {
            state: NodeState::new(start, &cfg.trigger),
            cfg,
            motion,
            sensor,
            me,
            weights: row,
            phase: Phase::Idle,
            local: None,
            adapted: None,
            cons: InfoPair::zeros(),
            post: start,
            triggered: None,
            guard_fallbacks: 0,
            gated: 0,
            steps: 0,
        })
    }

    fn commit(&mut self, local: &LocalOutput<f64, N, M>, fused: Gaussian<f64, N>) {
        local.commit(&mut self.state, fused);
        self.phase = Phase::Idle;
        self.local = None;
        self.adapted = None;
        self.steps += 1;
    }

    /// The current step's local output; present from phase `Local` on.
    fn current(&self, call: &str) -> PyResult<LocalOutput<f64, N, M>> {
        self.local
            .ok_or_else(|| wrong_phase(call, self.phase, "a step begun with local()"))
    }

    fn local(&mut self, arrived: Arrived<'_>, dt: f64) -> PyResult<Option<Out<N>>> {
        if self.phase != Phase::Idle {
            return Err(wrong_phase(
                "local",
                self.phase,
                "'idle' (a step's phases in order)",
            ));
        }
        let (cfg, motion, sensor, state) = (&self.cfg, &self.motion, &self.sensor, &self.state);
        let out = match arrived {
            Arrived::Sent(z) => {
                let z = SVector::<f64, M>::from_column_slice(z);
                node_local_received(cfg, motion, dt, sensor, state, Some(&z))
            }
            Arrived::Silent => node_local_received(cfg, motion, dt, sensor, state, None),
            Arrived::NotMeasured => check_sensor_side_trigger(&cfg.trigger)
                .and_then(|()| node_local(cfg, motion, dt, sensor, state, &Observation::Missing)),
        }
        .py()?;
        let fused = match out.packet() {
            LocalPacket::Silent => Some(out.local.posterior_estimate().py()?),
            _ => None,
        };
        self.gated += u64::from(out.gated);
        self.triggered = out.triggered;
        if let Some(g) = out.local.estimate {
            self.post = g;
        }
        match out.packet() {
            LocalPacket::Contribution(c) => {
                self.local = Some(out);
                self.phase = Phase::Local;
                Ok(Some(("contribution", c.i, c.imat)))
            }
            LocalPacket::Information(p) => {
                self.local = Some(out);
                self.cons = p;
                self.phase = Phase::Consensus(0);
                Ok(Some(info_out(&p)))
            }
            LocalPacket::Silent => {
                if let Some(g) = fused {
                    self.post = g;
                    self.commit(&out, g);
                }
                Ok(None)
            }
        }
    }

    fn adapt(&mut self, received: &[(usize, Contribution<f64, N>)]) -> PyResult<Out<N>> {
        if self.phase != Phase::Local {
            return Err(wrong_phase(
                "adapt",
                self.phase,
                "'local' (a diffusion row after local())",
            ));
        }
        let local = self.current("adapt")?;
        let a = node_adapt(&local.local, received.iter().map(|(_, c)| c)).py()?;
        self.post.x = a.x;
        if let Some(p) = a.covariance {
            self.post.p = p;
        }
        self.guard_fallbacks += u64::from(a.guard_used);
        self.adapted = Some(a);
        self.phase = Phase::Adapted;
        Ok(match a.packet {
            AdaptedPacket::Information(p) => info_out(&p),
            AdaptedPacket::Estimate(g) => ("estimate", g.x, g.p),
        })
    }

    fn combine(
        &mut self,
        received: &[(usize, AdaptedPacket<f64, N>)],
    ) -> PyResult<Gaussian<f64, N>> {
        let (Phase::Adapted, Some(a)) = (self.phase, self.adapted) else {
            return Err(wrong_phase(
                "combine",
                self.phase,
                "'adapted' (a diffusion row after adapt())",
            ));
        };
        let local = self.current("combine")?;
        let w = &self.weights;
        let fused = node_combine(
            self.me,
            w[self.me],
            &a.packet,
            received.iter().map(|(j, p)| (*j, w[*j], p)),
        )
        .py()?;
        self.commit(&local, fused);
        Ok(fused)
    }

    /// One consensus round; returns the next round's packet, or `None` and the
    /// fused estimate after the last round.
    fn consensus_round(
        &mut self,
        received: &[(usize, InfoPair<f64, N>)],
    ) -> PyResult<(Option<Out<N>>, Option<Gaussian<f64, N>>)> {
        let (Phase::Consensus(r), Fusion::Consensus { iterations }) = (self.phase, self.cfg.fusion)
        else {
            return Err(wrong_phase(
                "consensus_round",
                self.phase,
                "a consensus round of a consensus row",
            ));
        };
        let local = self.current("consensus_round")?;
        let w = &self.weights;
        let next = node_consensus_round(
            self.me,
            w[self.me],
            &self.cons,
            received.iter().map(|(j, p)| (*j, w[*j], p)),
        )
        .py()?;
        if r + 1 < iterations {
            self.cons = next;
            self.phase = Phase::Consensus(r + 1);
            return Ok((Some(info_out(&next)), None));
        }
        let fused = next.to_gaussian().py()?;
        self.cons = next;
        self.commit(&local, fused);
        Ok((None, Some(fused)))
    }
}

/// A packet to publish as plain values: kind, vector, row-major matrix.
type OutV = (&'static str, Vec<f64>, Vec<f64>);

fn out_values<const N: usize>((kind, v, m): Out<N>) -> OutV {
    (
        kind,
        v.as_slice().to_vec(),
        m.transpose().as_slice().to_vec(),
    )
}

fn gaussian_values<const N: usize>(g: &Gaussian<f64, N>) -> (Vec<f64>, Vec<f64>) {
    (g.x.as_slice().to_vec(), g.p.transpose().as_slice().to_vec())
}

/// A node of any state and measurement dimension, any motion and sensor: the
/// phases of [`NodeCore`] with plain values in and out.
trait NodeOps: Send + Sync {
    fn meas_dim(&self) -> usize;
    fn local(&mut self, arrived: Arrived<'_>, dt: f64) -> PyResult<Option<OutV>>;
    fn adapt(&mut self, received: &Received) -> PyResult<OutV>;
    fn combine(&mut self, received: &Received) -> PyResult<(Vec<f64>, Vec<f64>)>;
    fn consensus_round(&mut self, received: &Received) -> PyResult<Option<OutV>>;
    fn reset(&mut self, x: &[f64], p: &[f64]) -> PyResult<()>;
    fn abort_step(&mut self);
    fn estimate(&self) -> (Vec<f64>, Vec<f64>);
    fn local_estimate(&self) -> Vec<f64>;
    fn triggered(&self) -> Option<bool>;
    fn phase(&self) -> Phase;
    fn me(&self) -> usize;
    fn weights(&self) -> &[f64];
    fn fusion(&self) -> Fusion;
    /// steps, guard fallbacks, gated.
    fn counters(&self) -> [u64; 3];
}

impl<F, H, const N: usize, const M: usize> NodeOps for NodeCore<F, H, N, M>
where
    F: MotionModel<f64, N> + Send + Sync,
    H: MeasurementModel<f64, N, M> + Send + Sync,
{
    fn meas_dim(&self) -> usize {
        M
    }

    fn local(&mut self, arrived: Arrived<'_>, dt: f64) -> PyResult<Option<OutV>> {
        Ok(NodeCore::local(self, arrived, dt)?.map(out_values))
    }

    fn adapt(&mut self, received: &Received) -> PyResult<OutV> {
        let r: Vec<_> = received
            .iter()
            .map(|(j, v, m)| {
                (
                    *j,
                    Contribution {
                        i: vec_of(v),
                        imat: mat_of(m),
                    },
                )
            })
            .collect();
        Ok(out_values(NodeCore::adapt(self, &r)?))
    }

    fn combine(&mut self, received: &Received) -> PyResult<(Vec<f64>, Vec<f64>)> {
        let mut packets = Vec::with_capacity(received.len());
        for (j, v, m) in received {
            packets.push((
                *j,
                if self.cfg.fusion == Fusion::DiffusionConvex {
                    AdaptedPacket::Estimate(Gaussian::new(vec_of(v), mat_of(m)).py()?)
                } else {
                    AdaptedPacket::Information(info_of(v, m))
                },
            ));
        }
        let g = NodeCore::combine(self, &packets)?;
        Ok(gaussian_values(&g))
    }

    fn consensus_round(&mut self, received: &Received) -> PyResult<Option<OutV>> {
        let ps: Vec<_> = received
            .iter()
            .map(|(j, v, m)| (*j, info_of(v, m)))
            .collect();
        let (o, _) = NodeCore::consensus_round(self, &ps)?;
        Ok(o.map(out_values))
    }

    fn reset(&mut self, x: &[f64], p: &[f64]) -> PyResult<()> {
        if self.phase != Phase::Idle {
            return Err(wrong_phase("reset", self.phase, "'idle' (between steps)"));
        }
        self.state.estimate = Gaussian::new(vec_of(x), mat_of(p)).py()?;
        Ok(())
    }

    fn abort_step(&mut self) {
        self.phase = Phase::Idle;
        self.local = None;
        self.adapted = None;
    }

    fn estimate(&self) -> (Vec<f64>, Vec<f64>) {
        gaussian_values(&self.state.estimate)
    }

    fn local_estimate(&self) -> Vec<f64> {
        self.post.x.as_slice().to_vec()
    }

    fn triggered(&self) -> Option<bool> {
        self.triggered
    }

    fn phase(&self) -> Phase {
        self.phase
    }

    fn me(&self) -> usize {
        self.me
    }

    fn weights(&self) -> &[f64] {
        &self.weights
    }

    fn fusion(&self) -> Fusion {
        self.cfg.fusion
    }

    fn counters(&self) -> [u64; 3] {
        [self.steps, self.guard_fallbacks, self.gated]
    }
}

/// The node's sensor, once the motion fixed the state dimension `N`.
struct NodeSensorV<'a, F> {
    motion: F,
    cfg: NetworkConfig<f64>,
    sc: &'a Scenario,
    me: usize,
    x0: &'a [f64],
}

impl<F, const N: usize> SensorVisitor<N> for NodeSensorV<'_, F>
where
    F: MotionModel<f64, N> + Send + Sync + 'static,
{
    type Output = Box<dyn NodeOps>;
    fn visit<const M: usize, H>(self, sensor: H) -> edccif_sim::Result<Box<dyn NodeOps>>
    where
        H: MeasurementModel<f64, N, M> + Send + Sync + 'static,
    {
        Ok(Box::new(NodeCore::<F, H, N, M>::new(
            self.cfg,
            self.motion,
            sensor,
            self.sc,
            self.me,
            self.x0,
        )?))
    }
}

/// The node of a scenario of the model network: its catalogue (or
/// referenced) motion, then its own sensor.
struct NodeMotionV<'a> {
    cfg: NetworkConfig<f64>,
    sc: &'a Scenario,
    me: usize,
    x0: &'a [f64],
}

impl MotionVisitor for NodeMotionV<'_> {
    type Output = Box<dyn NodeOps>;
    fn visit<const N: usize, F>(self, motion: F) -> edccif_sim::Result<Box<dyn NodeOps>>
    where
        F: MotionModel<f64, N> + Send + Sync + 'static,
    {
        let spec = &self.sc.node_specs()[self.me];
        with_sensor::<N, _>(
            self.sc,
            &spec.sensor,
            NodeSensorV {
                motion,
                cfg: self.cfg,
                sc: self.sc,
                me: self.me,
                x0: self.x0,
            },
        )
    }
}

/// Node `me` of `sc`: the typed models for the paper's kinds (as `run`
/// builds them), else the catalogue's or the referenced Python models (as the
/// model network builds them).
fn build_node(
    sc: &Scenario,
    cfg: NetworkConfig<f64>,
    me: usize,
    x0: &[f64],
) -> edccif_sim::Result<Box<dyn NodeOps>> {
    if !sc.is_typed() {
        return with_motion(sc, NodeMotionV { cfg, sc, me, x0 });
    }
    let sensor: Sensor = sc.sensor_models()?[me];
    Ok(match sc.motion {
        MotionSpec::CoordinatedTurn { .. } => Box::new(NodeCore::<_, _, 7, 3>::new(
            cfg,
            sc.coordinated_turn()?,
            sensor,
            sc,
            me,
            x0,
        )?),
        MotionSpec::ConstantVelocity { .. } => Box::new(NodeCore::<_, _, 6, 3>::new(
            cfg,
            sc.constant_velocity()?,
            sensor,
            sc,
            me,
            x0,
        )?),
        MotionSpec::ConstantAcceleration { .. } => Box::new(NodeCore::<_, _, 9, 3>::new(
            cfg,
            sc.constant_acceleration()?,
            sensor,
            sc,
            me,
            x0,
        )?),
        _ => return Err(sc.model_network_error()),
    })
}

fn vec_of<const N: usize>(v: &[f64]) -> SVector<f64, N> {
    SVector::from_column_slice(v)
}

fn mat_of<const N: usize>(v: &[f64]) -> SMatrix<f64, N, N> {
    SMatrix::from_row_slice(v)
}

/// A received information pair; the matrix is symmetrised (a no-op, bit for bit,
/// on the exactly symmetric matrices the phases produce and the wire carries), as
/// the phases expect.
fn info_of<const N: usize>(v: &[f64], m: &[f64]) -> InfoPair<f64, N> {
    InfoPair {
        y: vec_of(v),
        ymat: edccif_core::linalg::sym(&mat_of(m)),
    }
}

fn out_to_py<'py>(py: Python<'py>, o: Option<OutV>, n: usize) -> PyResult<Bound<'py, PyAny>> {
    match o {
        None => Ok(py.None().into_bound(py)),
        Some((kind, v, m)) => {
            let v = to_numpy(py, v, &[n])?;
            let m = to_numpy(py, m, &[n, n])?;
            Ok(PyTuple::new(
                py,
                [
                    kind.into_pyobject(py)?.into_any(),
                    v.into_any(),
                    m.into_any(),
                ],
            )?
            .into_any())
        }
    }
}

fn gaussian_to_py<'py>(
    py: Python<'py>,
    (x, p): (Vec<f64>, Vec<f64>),
    n: usize,
) -> PyResult<Bound<'py, PyTuple>> {
    let x = to_numpy(py, x, &[n])?;
    let p = to_numpy(py, p, &[n, n])?;
    PyTuple::new(py, [x.into_any(), p.into_any()])
}

/// Parses `[(sender, vector, matrix), ...]` (finite values, shapes `(N,)`,
/// `(N, N)`), checking senders are neighbours and distinct.
fn parse_received(
    items: &Bound<'_, PyAny>,
    what: &str,
    n: usize,
    weights: &[f64],
    me: usize,
) -> PyResult<Received> {
    let mut out: Received = Vec::new();
    for (idx, item) in items.try_iter()?.enumerate() {
        let item = item?;
        let t: (usize, Bound<'_, PyAny>, Bound<'_, PyAny>) = item.extract().map_err(|_| {
            ParameterError::new_err(format!(
                "{what}[{idx}]: expected a (sender, vector, matrix) tuple"
            ))
        })?;
        let (j, v, m) = t;
        if j >= weights.len() || j == me || weights[j] <= 0.0 {
            return Err(ParameterError::new_err(format!(
                "{what}[{idx}]: sender {j} is not a neighbour of node {me}"
            )));
        }
        if out.iter().any(|(o, _, _)| *o == j) {
            return Err(ParameterError::new_err(format!(
                "{what}[{idx}]: sender {j} appears twice"
            )));
        }
        let (v, _) = finite_array(&v, &format!("{what}[{idx}] vector"), &[Dim::Is(n)])?;
        let (m, _) = finite_array(
            &m,
            &format!("{what}[{idx}] matrix"),
            &[Dim::Is(n), Dim::Is(n)],
        )?;
        out.push((j, v, m));
    }
    out.sort_by_key(|(j, _, _)| *j);
    Ok(out)
}

/// One estimator node: its local filter and its part of the fusion, driven one
/// phase at a time with the packets that arrived from its sensor and neighbours.
/// Any scenario: the paper's kinds, or per-node catalogue and referenced
/// Python models with mixed sensors. Fed every packet, a set of nodes gives
/// exactly the estimates of `run`.
#[pyclass(name = "Node", module = "edccif")]
pub struct PyNode {
    inner: Box<dyn NodeOps>,
    algorithm: edccif_sim::Algorithm,
    /// The node's scenario (its sensor's rate: [`Scenario::measures`]).
    scenario: Scenario,
    n: usize,
    k: usize,
    dt: f64,
}

impl PyNode {
    /// The packets of a phase from this node's neighbours
    /// ([`parse_received`] with this node's size, weights and index).
    fn received(&self, items: &Bound<'_, PyAny>) -> PyResult<Received> {
        parse_received(
            items,
            "received",
            self.n,
            self.inner.weights(),
            self.inner.me(),
        )
    }
}

#[pymethods]
impl PyNode {
    #[new]
    #[pyo3(signature = (scenario, algorithm = "edc-cif", node = 0, x0 = None, **options))]
    fn new(
        #[pyo3(from_py_with = crate::class_args::scenario)] scenario: PyRef<'_, PyScenario>,
        #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
        #[pyo3(from_py_with = crate::args::named::node)] node: usize,
        x0: Option<&Bound<'_, PyAny>>,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let alg = self::algorithm(algorithm)?;
        let opt = options_from_kwargs(options)?;
        no_threads(&opt, "edccif.Node")?;
        let sc = &scenario.inner;
        sc.validate().py()?;
        let k = sc.nodes();
        if node >= k {
            return Err(ParameterError::new_err(format!(
                "node: expected an index in 0..{k}, got {node}"
            )));
        }
        let cfg = node_config(alg, sc, &opt, node).py()?;
        check_sensor_side(&cfg.trigger)?;
        if !cfg.rule.is_paper() {
            return Err(ParameterError::new_err(format!(
                "fusion: a Node combines with the paper's covariance intersection only, got the rule {:?}; \
                 the other rules (docs/fusion.md) run in edccif.run, Network, ModelNetwork and monte_carlo",
                cfg.rule.name()
            )));
        }
        let x0v = x0_or_default(&scenario, x0)?;
        let inner = crate::refs::finish(build_node(sc, cfg, node, &x0v).py())?;
        Ok(Self {
            n: sc.state_dim(),
            k,
            dt: sc.dt,
            scenario: sc.clone(),
            inner,
            algorithm: alg,
        })
    }

    /// Phase 1: the local step with what arrived from the sensor this step — its
    /// measurement `z` (m,), `None` when nothing came (the untriggered step), or
    /// a row of NaN when the sensor took no measurement at this step (its rate:
    /// `measures(t)` is false; the step without measurement, as `run` takes NaN).
    /// Returns the packet to publish, `(kind, vector, matrix)` with kind
    /// "contribution" (diffusion rows) or "information" (consensus round 0), or
    /// `None` (no fusion: the step is complete). `dt`: time since the previous step
    /// (default: the scenario's period).
    #[pyo3(signature = (z = None, dt = None))]
    fn local<'py>(
        &mut self,
        py: Python<'py>,
        z: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let dt = dt.unwrap_or(self.dt);
        let m = self.inner.meas_dim();
        let z = match z.filter(|o| !o.is_none()) {
            None => None,
            Some(o) => {
                let (v, _) = f64_array(o, "z", &[Dim::Is(m)])?;
                if v.iter().all(|x| x.is_nan()) {
                    Some(None)
                } else {
                    Some(Some(finite_array(o, "z", &[Dim::Is(m)])?.0))
                }
            }
        };
        let arrived = match &z {
            None => Arrived::Silent,
            Some(None) => Arrived::NotMeasured,
            Some(Some(v)) => Arrived::Sent(v),
        };
        let o = crate::refs::finish(self.inner.local(arrived, dt))?;
        out_to_py(py, o, self.n)
    }

    /// Phase 2 (diffusion rows): adaptation with the neighbours' contributions that
    /// arrived, `[(sender, i, I), ...]`. Returns the packet to publish for the
    /// combination: ("information", ŷ, Y) for CI diffusion, ("estimate", x, P) for
    /// convex diffusion.
    fn adapt<'py>(
        &mut self,
        py: Python<'py>,
        received: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let r = self.received(received)?;
        let o = self.inner.adapt(&r)?;
        out_to_py(py, Some(o), self.n)
    }

    /// Phase 3 (diffusion rows): combination with the neighbours' packets from
    /// `adapt` that arrived, `[(sender, vector, matrix), ...]`, weights
    /// renormalised over them and the node itself. Ends the step; returns the
    /// fused `(x, P)`.
    fn combine<'py>(
        &mut self,
        py: Python<'py>,
        received: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let r = self.received(received)?;
        let g = self.inner.combine(&r)?;
        gaussian_to_py(py, g, self.n)
    }

    /// Consensus rows: one round with the neighbours' "information" packets of this
    /// round that arrived. Returns the next round's packet to publish, or `None`
    /// after the last of the `rounds` rounds (the step is then complete and
    /// `estimate`/`covariance` hold the fused estimate).
    fn consensus_round<'py>(
        &mut self,
        py: Python<'py>,
        received: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let r = self.received(received)?;
        let o = self.inner.consensus_round(&r)?;
        out_to_py(py, o, self.n)
    }

    /// Replaces the node's estimate (a node rejoining from a neighbour's estimate);
    /// only between steps. The sensor memory `z_τ` is kept.
    fn reset(&mut self, x: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = self.n;
        let (xv, _) = finite_array(x, "x", &[Dim::Is(n)])?;
        let (pv, _) = finite_array(p, "P", &[Dim::Is(n), Dim::Is(n)])?;
        self.inner.reset(&xv, &pv)
    }

    /// Abandons the current step (e.g. its deadline passed): the node keeps the
    /// estimate and sensor memory of the last completed step.
    fn abort_step(&mut self) {
        self.inner.abort_step()
    }

    /// Whether this node's sensor measures at step `t` (0-based; the step's
    /// time is `(t + 1)·dt`): its `every` or `times` in a per-node scenario,
    /// else every step. At a step where it does not, the node's `local` takes
    /// a row of NaN (what `Scenario.simulate` gives there).
    fn measures(&self, #[pyo3(from_py_with = crate::args::named::step)] t: usize) -> bool {
        self.scenario.measures(self.inner.me(), t)
    }

    /// Fused estimate `x` (n,) of the last completed step (x₀ before the first).
    #[getter]
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(py, self.inner.estimate().0, &[self.n])
    }

    /// Fused covariance `P` (n, n) of the last completed step.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(py, self.inner.estimate().1, &[self.n, self.n])
    }

    /// The node's estimate before combination at the current/last step.
    #[getter]
    fn local_estimate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(py, self.inner.local_estimate(), &[self.n])
    }

    /// `True`/`False`: whether a measurement came at the current/last step;
    /// `None` when the step had no measurement at all.
    #[getter]
    fn triggered(&self) -> Option<bool> {
        self.inner.triggered()
    }

    /// The phase the node is at: "idle", "local", "adapted", "consensus round r".
    #[getter]
    fn phase(&self) -> String {
        self.inner.phase().name()
    }

    /// This node's index.
    #[getter]
    fn node(&self) -> usize {
        self.inner.me()
    }

    /// Neighbours' indices (ascending).
    #[getter]
    fn neighbours(&self) -> Vec<usize> {
        let (me, w) = (self.inner.me(), self.inner.weights());
        (0..self.k).filter(|&j| j != me && w[j] > 0.0).collect()
    }

    /// The fusion: "diffusion-ci", "diffusion-convex", "consensus" or "local".
    #[getter]
    fn fusion(&self) -> &'static str {
        match self.inner.fusion() {
            Fusion::DiffusionCi => "diffusion-ci",
            Fusion::DiffusionConvex => "diffusion-convex",
            Fusion::Consensus { .. } => "consensus",
            Fusion::Local => "local",
        }
    }

    /// Consensus rounds `L` per step (0 for the other fusions).
    #[getter]
    fn rounds(&self) -> usize {
        match self.inner.fusion() {
            Fusion::Consensus { iterations } => iterations,
            _ => 0,
        }
    }

    /// The algorithm row.
    #[getter]
    fn algorithm(&self) -> &'static str {
        self.algorithm.name()
    }

    /// State dimension n.
    #[getter]
    fn state_dim(&self) -> usize {
        self.n
    }

    /// Measurement dimension m of this node's sensor.
    #[getter]
    fn meas_dim(&self) -> usize {
        self.inner.meas_dim()
    }

    /// Totals: {"steps", "guard_fallbacks", "gated"}.
    #[getter]
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let [steps, guard, gated] = self.inner.counters();
        d.set_item("steps", steps)?;
        d.set_item("guard_fallbacks", guard)?;
        d.set_item("gated", gated)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "Node(algorithm={:?}, node={}, phase={:?})",
            self.algorithm.name(),
            self.node(),
            self.phase()
        )
    }
}

fn check_sensor_side(t: &Trigger<f64>) -> PyResult<()> {
    check_sensor_side_trigger(t).map_err(|e| ParameterError::new_err(format!("trigger {t:?}: {e}")))
}

/// A sensor's trigger with its memory, for any sensor.
trait Decide: Send + Sync {
    fn meas_dim(&self) -> usize;
    /// The trigger's decision on `z` (`m` finite values); remembers it.
    fn decide(&mut self, z: &[f64]) -> bool;
}

struct TriggerCore<H, const N: usize, const M: usize> {
    trigger: Trigger<f64>,
    sensor: H,
    state: TriggerState<f64, M>,
}

impl<H, const N: usize, const M: usize> Decide for TriggerCore<H, N, M>
where
    H: MeasurementModel<f64, N, M> + Send + Sync,
{
    fn meas_dim(&self) -> usize {
        M
    }
    fn decide(&mut self, z: &[f64]) -> bool {
        let z = SVector::<f64, M>::from_column_slice(z);
        let (gamma, next) = self
            .trigger
            .decide::<H, N, M>(&self.sensor, &self.state, &z);
        self.state = next;
        gamma
    }
}

/// The trigger of a node's sensor, once the motion fixed `N`.
struct TriggerSensorV(Trigger<f64>);

impl<const N: usize> SensorVisitor<N> for TriggerSensorV {
    type Output = Box<dyn Decide>;
    fn visit<const M: usize, H>(self, sensor: H) -> edccif_sim::Result<Box<dyn Decide>>
    where
        H: MeasurementModel<f64, N, M> + Send + Sync + 'static,
    {
        Ok(Box::new(TriggerCore::<H, N, M> {
            state: TriggerState::new(&self.0),
            trigger: self.0,
            sensor,
        }))
    }
}

struct TriggerMotionV<'a> {
    trigger: Trigger<f64>,
    sc: &'a Scenario,
    me: usize,
}

impl MotionVisitor for TriggerMotionV<'_> {
    type Output = Box<dyn Decide>;
    fn visit<const N: usize, F>(self, _motion: F) -> edccif_sim::Result<Box<dyn Decide>>
    where
        F: MotionModel<f64, N> + Send + Sync + 'static,
    {
        let spec = &self.sc.node_specs()[self.me];
        with_sensor::<N, _>(self.sc, &spec.sensor, TriggerSensorV(self.trigger))
    }
}

/// The trigger of node `me`'s sensor in `sc`, with the sensor `run` builds.
fn build_trigger(
    sc: &Scenario,
    trigger: Trigger<f64>,
    me: usize,
) -> edccif_sim::Result<Box<dyn Decide>> {
    if !sc.is_typed() {
        return with_motion(sc, TriggerMotionV { trigger, sc, me });
    }
    let sensor: Sensor = sc.sensor_models()?[me];
    Ok(Box::new(TriggerCore::<Sensor, 7, 3> {
        state: TriggerState::new(&trigger),
        trigger,
        sensor,
    }))
}

/// One sensor's event trigger, run where the sensor is: `decide(z)` says whether
/// `z` is sent to the node (and remembers it when it is). The trigger is the
/// row's (send-on-delta for the event-triggered rows, dynamic for DEC-CKF,
/// always for the others) with the node's threshold, on the node's sensor of
/// any kind (the scenario's per-node catalogue or referenced Python model).
#[pyclass(name = "SensorTrigger", module = "edccif")]
pub struct PySensorTrigger {
    inner: Box<dyn Decide>,
    sent: u64,
    measured: u64,
}

#[pymethods]
impl PySensorTrigger {
    #[new]
    #[pyo3(signature = (scenario, algorithm = "edc-cif", node = 0, **options))]
    fn new(
        #[pyo3(from_py_with = crate::class_args::scenario)] scenario: PyRef<'_, PyScenario>,
        #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
        #[pyo3(from_py_with = crate::args::named::node)] node: usize,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let alg = self::algorithm(algorithm)?;
        let opt = options_from_kwargs(options)?;
        no_threads(&opt, "edccif.SensorTrigger")?;
        let sc = &scenario.inner;
        let k = sc.nodes();
        if node >= k {
            return Err(ParameterError::new_err(format!(
                "node: expected an index in 0..{k}, got {node}"
            )));
        }
        let cfg = node_config(alg, sc, &opt, node).py()?;
        check_sensor_side(&cfg.trigger)?;
        let inner = crate::refs::finish(build_trigger(sc, cfg.trigger, node).py())?;
        Ok(Self {
            inner,
            sent: 0,
            measured: 0,
        })
    }

    /// Decides on measurement `z` (m,): `True` when it is to be sent. A row of NaN
    /// (no measurement) is never sent.
    fn decide(&mut self, z: &Bound<'_, PyAny>) -> PyResult<bool> {
        let m = self.inner.meas_dim();
        let (v, _) = f64_array(z, "z", &[Dim::Is(m)])?;
        if v.iter().all(|x| x.is_nan()) {
            return Ok(false);
        }
        let (v, _) = finite_array(z, "z", &[Dim::Is(m)])?;
        let gamma = crate::refs::finish(Ok(self.inner.decide(&v)))?;
        self.measured += 1;
        self.sent += u64::from(gamma);
        Ok(gamma)
    }

    /// Measurement dimension m of the sensor.
    #[getter]
    fn meas_dim(&self) -> usize {
        self.inner.meas_dim()
    }

    /// Measurements decided on so far.
    #[getter]
    fn measured(&self) -> u64 {
        self.measured
    }

    /// Measurements sent so far.
    #[getter]
    fn sent(&self) -> u64 {
        self.sent
    }
}
