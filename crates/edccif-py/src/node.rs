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

use edccif_core::models::{ConstantAcceleration, ConstantVelocity, CoordinatedTurn};
use edccif_core::node::{
    check_sensor_side_trigger, node_adapt, node_combine, node_consensus_round, node_local_received,
    AdaptOutput, AdaptedPacket, LocalOutput, LocalPacket,
};
use edccif_core::{
    Contribution, Fusion, Gaussian, InfoPair, MotionModel, NetworkConfig, NodeState, Trigger,
    TriggerState,
};
use edccif_sim::{node_config, MotionSpec, Scenario, Sensor};
use nalgebra::{SMatrix, SVector};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{f64_array, finite_array, to_numpy, Dim};
use crate::errors::{IntoPyResult, ParameterError};
use crate::runner::{algorithm, no_threads, options_from_kwargs, x0_or_default};
use crate::scenario::PyScenario;

const M: usize = 3;

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

/// One estimator node of state dimension `N`: the core's per-node phases
/// (`edccif_core::node`) with the bookkeeping of where the node is in its step.
#[derive(Debug, Clone)]
struct NodeCore<F, const N: usize> {
    cfg: NetworkConfig<f64>,
    motion: F,
    sensor: Sensor,
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

impl<F: MotionModel<f64, N>, const N: usize> NodeCore<F, N> {
    fn new(
        cfg: NetworkConfig<f64>,
        motion: F,
        sc: &Scenario,
        me: usize,
        x0: &[f64],
    ) -> PyResult<Self> {
        let p0 = SMatrix::<f64, N, N>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
        let start = Gaussian::new(vec_of::<N>(x0), p0).py()?;
        let k = sc.nodes();
        let sensor = sc.sensor_models().py()?[me];
        // Node `me`'s row of the weights, from the lists (no N × N matrix).
        let g = sc.neighbours().py()?;
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

    fn local(&mut self, z: Option<SVector<f64, M>>, dt: f64) -> PyResult<Option<Out<N>>> {
        if self.phase != Phase::Idle {
            return Err(wrong_phase(
                "local",
                self.phase,
                "'idle' (a step's phases in order)",
            ));
        }
        let out = node_local_received(
            &self.cfg,
            &self.motion,
            dt,
            &self.sensor,
            &self.state,
            z.as_ref(),
        )
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

/// The node of either built-in state dimension.
#[derive(Debug, Clone)]
enum AnyNode {
    Ct(Box<NodeCore<CoordinatedTurn<f64>, 7>>),
    Cv(Box<NodeCore<ConstantVelocity<f64>, 6>>),
    Ca(Box<NodeCore<ConstantAcceleration<f64>, 9>>),
}

macro_rules! any_node {
    ($self:expr, $n:ident => $body:expr) => {
        match $self {
            AnyNode::Ct($n) => $body,
            AnyNode::Cv($n) => $body,
            AnyNode::Ca($n) => $body,
        }
    };
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

fn out_to_py<'py, const N: usize>(
    py: Python<'py>,
    o: Option<Out<N>>,
) -> PyResult<Bound<'py, PyAny>> {
    match o {
        None => Ok(py.None().into_bound(py)),
        Some((kind, v, m)) => {
            let v = to_numpy(py, v.as_slice().to_vec(), &[N])?;
            let m = to_numpy(py, m.transpose().as_slice().to_vec(), &[N, N])?;
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

fn gaussian_to_py<'py, const N: usize>(
    py: Python<'py>,
    g: &Gaussian<f64, N>,
) -> PyResult<Bound<'py, PyTuple>> {
    let x = to_numpy(py, g.x.as_slice().to_vec(), &[N])?;
    let p = to_numpy(py, g.p.transpose().as_slice().to_vec(), &[N, N])?;
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
/// Fed every packet, a set of nodes gives exactly the estimates of `run`.
#[pyclass(name = "Node", module = "edccif")]
pub struct PyNode {
    inner: AnyNode,
    algorithm: edccif_sim::Algorithm,
    n: usize,
    k: usize,
    dt: f64,
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
        if !sc.is_typed() {
            return Err(sc.model_network_error()).py();
        }
        let inner = match sc.motion {
            MotionSpec::CoordinatedTurn { .. } => AnyNode::Ct(Box::new(NodeCore::new(
                cfg,
                sc.coordinated_turn().py()?,
                sc,
                node,
                &x0v,
            )?)),
            MotionSpec::ConstantVelocity { .. } => AnyNode::Cv(Box::new(NodeCore::new(
                cfg,
                sc.constant_velocity().py()?,
                sc,
                node,
                &x0v,
            )?)),
            MotionSpec::ConstantAcceleration { .. } => AnyNode::Ca(Box::new(NodeCore::new(
                cfg,
                sc.constant_acceleration().py()?,
                sc,
                node,
                &x0v,
            )?)),
            _ => return Err(sc.model_network_error()).py(),
        };
        Ok(Self {
            n: sc.state_dim(),
            k,
            dt: sc.dt,
            inner,
            algorithm: alg,
        })
    }

    /// Phase 1: the local step with what arrived from the sensor this step — its
    /// measurement `z` (3,), or `None` when nothing came (the untriggered step).
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
        let z = z
            .filter(|o| !o.is_none())
            .map(|o| finite_array(o, "z", &[Dim::Is(M)]))
            .transpose()?
            .map(|(v, _)| SVector::<f64, M>::from_column_slice(&v));
        any_node!(&mut self.inner, c => { let o = c.local(z, dt)?; out_to_py(py, o) })
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
        let n = self.n;
        any_node!(&mut self.inner, c => {
            let r = parse_received(received, "received", n, &c.weights, c.me)?;
            let r: Vec<_> = r.iter().map(|(j, v, m)| (*j, Contribution { i: vec_of(v), imat: mat_of(m) })).collect();
            let o = c.adapt(&r)?;
            out_to_py(py, Some(o))
        })
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
        let n = self.n;
        any_node!(&mut self.inner, c => {
            let r = parse_received(received, "received", n, &c.weights, c.me)?;
            let mut packets = Vec::with_capacity(r.len());
            for (j, v, m) in &r {
                packets.push((*j, if c.cfg.fusion == Fusion::DiffusionConvex {
                    AdaptedPacket::Estimate(Gaussian::new(vec_of(v), mat_of(m)).py()?)
                } else {
                    AdaptedPacket::Information(info_of(v, m))
                }));
            }
            let g = c.combine(&packets)?;
            gaussian_to_py(py, &g)
        })
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
        let n = self.n;
        any_node!(&mut self.inner, c => {
            let r = parse_received(received, "received", n, &c.weights, c.me)?;
            let ps: Vec<_> = r.iter().map(|(j, v, m)| (*j, info_of(v, m))).collect();
            let (o, _) = c.consensus_round(&ps)?;
            out_to_py(py, o)
        })
    }

    /// Replaces the node's estimate (a node rejoining from a neighbour's estimate);
    /// only between steps. The sensor memory `z_τ` is kept.
    fn reset(&mut self, x: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = self.n;
        let (xv, _) = finite_array(x, "x", &[Dim::Is(n)])?;
        let (pv, _) = finite_array(p, "P", &[Dim::Is(n), Dim::Is(n)])?;
        any_node!(&mut self.inner, c => {
            if c.phase != Phase::Idle {
                return Err(wrong_phase("reset", c.phase, "'idle' (between steps)"));
            }
            c.state.estimate = Gaussian::new(vec_of(&xv), mat_of(&pv)).py()?;
            Ok(())
        })
    }

    /// Abandons the current step (e.g. its deadline passed): the node keeps the
    /// estimate and sensor memory of the last completed step.
    fn abort_step(&mut self) {
        any_node!(&mut self.inner, c => {
            c.phase = Phase::Idle;
            c.local = None;
            c.adapted = None;
        })
    }

    /// Fused estimate `x` (n,) of the last completed step (x₀ before the first).
    #[getter]
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let n = self.n;
        any_node!(&self.inner, c => to_numpy(py, c.state.estimate.x.as_slice().to_vec(), &[n]))
    }

    /// Fused covariance `P` (n, n) of the last completed step.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let n = self.n;
        any_node!(&self.inner, c => to_numpy(py, c.state.estimate.p.transpose().as_slice().to_vec(), &[n, n]))
    }

    /// The node's estimate before combination at the current/last step.
    #[getter]
    fn local_estimate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let n = self.n;
        any_node!(&self.inner, c => to_numpy(py, c.post.x.as_slice().to_vec(), &[n]))
    }

    /// `True`/`False`: whether a measurement came at the current/last step;
    /// `None` when the step had no measurement at all.
    #[getter]
    fn triggered(&self) -> Option<bool> {
        any_node!(&self.inner, c => c.triggered)
    }

    /// The phase the node is at: "idle", "local", "adapted", "consensus round r".
    #[getter]
    fn phase(&self) -> String {
        any_node!(&self.inner, c => c.phase.name())
    }

    /// This node's index.
    #[getter]
    fn node(&self) -> usize {
        any_node!(&self.inner, c => c.me)
    }

    /// Neighbours' indices (ascending).
    #[getter]
    fn neighbours(&self) -> Vec<usize> {
        any_node!(&self.inner, c => (0..self.k).filter(|&j| j != c.me && c.weights[j] > 0.0).collect())
    }

    /// The fusion: "diffusion-ci", "diffusion-convex", "consensus" or "local".
    #[getter]
    fn fusion(&self) -> &'static str {
        any_node!(&self.inner, c => match c.cfg.fusion {
            Fusion::DiffusionCi => "diffusion-ci",
            Fusion::DiffusionConvex => "diffusion-convex",
            Fusion::Consensus { .. } => "consensus",
            Fusion::Local => "local",
        })
    }

    /// Consensus rounds `L` per step (0 for the other fusions).
    #[getter]
    fn rounds(&self) -> usize {
        any_node!(&self.inner, c => match c.cfg.fusion { Fusion::Consensus { iterations } => iterations, _ => 0 })
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

    /// Totals: {"steps", "guard_fallbacks", "gated"}.
    #[getter]
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        any_node!(&self.inner, c => {
            d.set_item("steps", c.steps)?;
            d.set_item("guard_fallbacks", c.guard_fallbacks)?;
            d.set_item("gated", c.gated)?;
        });
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

/// One sensor's event trigger, run where the sensor is: `decide(z)` says whether
/// `z` is sent to the node (and remembers it when it is). The trigger is the
/// row's (send-on-delta for the event-triggered rows, dynamic for DEC-CKF,
/// always for the others).
#[pyclass(name = "SensorTrigger", module = "edccif")]
pub struct PySensorTrigger {
    trigger: Trigger<f64>,
    sensor: Sensor,
    state: TriggerState<f64, M>,
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
        Ok(Self {
            trigger: cfg.trigger,
            sensor: sc.sensor_models().py()?[node],
            state: TriggerState::new(&cfg.trigger),
            sent: 0,
            measured: 0,
        })
    }

    /// Decides on measurement `z` (3,): `True` when it is to be sent. A row of NaN
    /// (no measurement) is never sent.
    fn decide(&mut self, z: &Bound<'_, PyAny>) -> PyResult<bool> {
        let (v, _) = f64_array(z, "z", &[Dim::Is(M)])?;
        if v.iter().all(|x| x.is_nan()) {
            return Ok(false);
        }
        let (v, _) = finite_array(z, "z", &[Dim::Is(M)])?;
        let z = SVector::<f64, M>::from_column_slice(&v);
        let (gamma, next) = self
            .trigger
            .decide::<Sensor, 7, M>(&self.sensor, &self.state, &z);
        self.state = next;
        self.measured += 1;
        self.sent += u64::from(gamma);
        Ok(gamma)
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
