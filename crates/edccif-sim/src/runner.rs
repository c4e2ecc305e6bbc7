//! The network runner: any algorithm row over a measurement sequence, streaming
//! ([`Network::step`]) or whole-run ([`run`]). Buffers are allocated once when the
//! network is built; a step allocates nothing.

use std::time::Instant;

use edccif_core::models::{ConstantAcceleration, ConstantVelocity, CoordinatedTurn};
use edccif_core::{
    network_step_weighted, Fusion, Gaussian, LinkMask, MotionModel, NetworkConfig, NodeScratch,
    NodeState, Observation, StepInputs, StepReport, Trigger, TriggerState,
};
use nalgebra::{SMatrix, SVector};

use crate::algorithm::{network_config, node_deltas, Algorithm, RunOptions};
use crate::control::Control;
use crate::counters::StepMessages;
use crate::error::{Error, Result};
use crate::parallel::ParallelStep;
pub use crate::result::{check_run_size, run_bytes, RunResult};
use crate::scenario::{MotionSpec, Scenario, Sensor};
use crate::timestep::check_dt;
use crate::topology::NeighbourLists;

/// Measurement dimension of the built-in sensors.
pub const M: usize = 3;

pub use crate::counters::Counters;

/// A network of nodes running one algorithm, with state dimension `N`.
#[derive(Debug, Clone)]
pub struct Network<F, const N: usize> {
    cfg: NetworkConfig<f64>,
    motion: F,
    dt: f64,
    sensors: Vec<Sensor>,
    /// The graph and combination weights as neighbour lists (no `N × N`
    /// matrix, so that large sparse networks fit).
    graph: NeighbourLists,
    nodes: Vec<NodeState<f64, N, M>>,
    scratch: Vec<NodeScratch<f64, N, M>>,
    obs: Vec<Observation<f64, M>>,
    counters: Counters,
    /// The parallel step when switched on ([`set_parallel`](Self::set_parallel)).
    parallel: Option<Parallel<F, N>>,
    /// The phases of the parallel step run serially, which check a live
    /// [`Control`] between consensus rounds: for steps with many rounds
    /// ([`prepare_interruptible`](Self::prepare_interruptible)).
    interruptible: Option<Parallel<F, N>>,
    /// One trigger threshold per node ([`with_deltas`](Self::with_deltas)).
    deltas: Option<Vec<f64>>,
}

/// Node-rounds (nodes × consensus rounds) from which a step is long enough
/// (about 10 ms and more) to be checked for cancellation between its rounds.
pub const HEAVY_NODE_ROUNDS: usize = 50_000;

/// Signature of [`parallel_step`] for one motion model: chosen where `F: Sync`
/// is known ([`Network::set_parallel`]), so `Network` itself needs no `Sync`.
type ParallelStepFn<F, const N: usize> = fn(
    &mut ParallelStep<f64, N, M>,
    &NetworkConfig<f64>,
    &F,
    &[Sensor],
    &mut [NodeState<f64, N, M>],
    &StepInputs<'_, f64, M>,
    &Control,
) -> Result<StepReport>;

/// A network's parallel step and the function that runs it.
#[derive(Debug, Clone)]
struct Parallel<F, const N: usize> {
    step: ParallelStep<f64, N, M>,
    run: ParallelStepFn<F, N>,
}

fn parallel_step<F: MotionModel<f64, N> + Sync, const N: usize>(
    par: &mut ParallelStep<f64, N, M>,
    cfg: &NetworkConfig<f64>,
    motion: &F,
    sensors: &[Sensor],
    nodes: &mut [NodeState<f64, N, M>],
    inputs: &StepInputs<'_, f64, M>,
    ctl: &Control,
) -> Result<StepReport> {
    par.step_controlled(cfg, motion, sensors, nodes, inputs, ctl)
}

/// [`parallel_step`] of a step whose phases run as one task each
/// ([`Network::prepare_interruptible`]): the whole step is handed to rayon's
/// global pool once (inside a worker of it, e.g. a Monte Carlo run, it runs
/// where it is), so that its phases do not each go to the pool and back.
fn serial_parallel_step<F: MotionModel<f64, N> + Sync, const N: usize>(
    par: &mut ParallelStep<f64, N, M>,
    cfg: &NetworkConfig<f64>,
    motion: &F,
    sensors: &[Sensor],
    nodes: &mut [NodeState<f64, N, M>],
    inputs: &StepInputs<'_, f64, M>,
    ctl: &Control,
) -> Result<StepReport> {
    if rayon::current_thread_index().is_some() {
        par.step_controlled(cfg, motion, sensors, nodes, inputs, ctl)
    } else {
        par.in_pool(|p| p.step_controlled(cfg, motion, sensors, nodes, inputs, ctl))
    }
}

fn parse_observations(z: &[f64], k: usize, out: &mut [Observation<f64, M>]) -> Result<()> {
    if z.len() != k * M {
        return Err(Error::Shape {
            what: "z_k".into(),
            expected: format!("({k}, {M})"),
            got: format!("{} values", z.len()),
        });
    }
    for (i, row) in z.chunks_exact(M).enumerate() {
        let nan = row.iter().filter(|v| v.is_nan()).count();
        out[i] = if nan == M {
            Observation::Missing
        } else if nan > 0 || row.iter().any(|v| v.is_infinite()) {
            return Err(Error::Value {
                what: format!("measurement of node {i}"),
                problem: format!(
                    "{row:?} mixes NaN/inf with numbers; a whole row of NaN means \"no measurement\", otherwise all values must be finite"
                ),
            });
        } else {
            Observation::Measured(SVector::<f64, M>::from_column_slice(row))
        };
    }
    Ok(())
}

impl<F: MotionModel<f64, N>, const N: usize> Network<F, N> {
    /// Builds a network: every node starts from `(x0, p0)`; `dt` is the nominal
    /// time step of [`step`](Self::step) and [`step_with`](Self::step_with)
    /// ([`step_dt_with`](Self::step_dt_with) takes each step's own).
    /// `weights` is the row-major `N × N` combination matrix;
    /// [`with_graph`](Self::with_graph) takes neighbour lists instead.
    pub fn new(
        cfg: NetworkConfig<f64>,
        motion: F,
        dt: f64,
        sensors: Vec<Sensor>,
        weights: Vec<f64>,
        x0: &[f64],
        p0: &SMatrix<f64, N, N>,
    ) -> Result<Self> {
        let k = sensors.len();
        let graph = NeighbourLists::from_dense(&weights, k)?;
        Self::with_graph(cfg, motion, dt, sensors, graph, x0, p0)
    }

    /// [`new`](Self::new) with the graph and weights as neighbour lists
    /// ([`Scenario::neighbours`]): memory O(N + edges), the same numbers bit
    /// for bit as with the dense matrix.
    ///
    /// ```
    /// use edccif_sim::{network_config, Algorithm, Network, RunOptions, Scenario};
    /// use nalgebra::SMatrix;
    /// let sc = Scenario::paper(100_000);
    /// let cfg = network_config(Algorithm::EdcCif, &sc, &RunOptions::default()).unwrap();
    /// let p0 = SMatrix::<f64, 7, 7>::identity() * 0.01;
    /// let net = Network::with_graph(cfg, sc.coordinated_turn().unwrap(), sc.dt, sc.sensor_models().unwrap(),
    ///                               sc.neighbours().unwrap(), &sc.x0, &p0).unwrap();
    /// assert_eq!(net.graph().row(0), &[0, 1, 99_999]);
    /// ```
    pub fn with_graph(
        cfg: NetworkConfig<f64>,
        motion: F,
        dt: f64,
        sensors: Vec<Sensor>,
        graph: NeighbourLists,
        x0: &[f64],
        p0: &SMatrix<f64, N, N>,
    ) -> Result<Self> {
        cfg.validate()?;
        check_dt(dt, "dt")?;
        let k = sensors.len();
        if graph.nodes() != k {
            return Err(Error::Shape {
                what: "neighbour lists".into(),
                expected: format!("{k} nodes (one per sensor)"),
                got: format!("{} nodes", graph.nodes()),
            });
        }
        graph.core()?;
        crate::limits::check_memory(
            || format!("a network of {k} nodes (every node's state and working memory)"),
            crate::limits::product(&[k, crate::limits::node_bytes()]),
        )?;
        if x0.len() != N {
            return Err(Error::Shape {
                what: "x0".into(),
                expected: format!("({N},)"),
                got: format!("({},)", x0.len()),
            });
        }
        if let Some(i) = x0.iter().position(|v| !v.is_finite()) {
            return Err(Error::Value {
                what: format!("x0[{i}]"),
                problem: format!("must be finite, got {}", x0[i]),
            });
        }
        let start = Gaussian::new(SVector::<f64, N>::from_column_slice(x0), *p0)?;
        Ok(Self {
            nodes: vec![NodeState::new(start, &cfg.trigger); k],
            scratch: vec![NodeScratch::default(); k],
            obs: vec![Observation::Missing; k],
            cfg,
            motion,
            dt,
            sensors,
            graph,
            counters: Counters::default(),
            parallel: None,
            interruptible: None,
            deltas: None,
        })
    }

    /// The graph and combination weights the network steps with.
    pub fn graph(&self) -> &NeighbourLists {
        &self.graph
    }

    /// Consensus rounds per step (0 for the diffusion and local rows).
    pub fn consensus_rounds(&self) -> usize {
        match self.cfg.fusion {
            Fusion::Consensus { iterations } => iterations,
            _ => 0,
        }
    }

    /// Whether a step runs at least [`HEAVY_NODE_ROUNDS`] node-rounds.
    pub fn heavy(&self) -> bool {
        self.consensus_rounds().saturating_mul(self.nodes.len()) >= HEAVY_NODE_ROUNDS
    }

    /// For a network whose steps are [`heavy`](Self::heavy): prepares the
    /// serial run of the parallel step's phases that
    /// [`step_dt_with_control`](Self::step_dt_with_control) takes under a live
    /// [`Control`], checking it between consensus rounds (the same numbers bit
    /// for bit as the serial step). Does nothing for other networks.
    pub fn prepare_interruptible(&mut self) -> Result<()>
    where
        F: Sync,
    {
        if self.heavy() && self.interruptible.is_none() {
            let k = self.nodes.len();
            // One task per phase: the phases run on one thread at a time.
            let step =
                ParallelStep::from_graph(&self.graph.core()?)?.with_min_nodes_per_task(k.max(1))?;
            let mut p = self.parallel_from(step);
            p.run = serial_parallel_step::<F, N>;
            self.interruptible = Some(p);
        }
        Ok(())
    }

    /// The network with one trigger threshold per node: node i's sensor decides
    /// with the configuration's trigger at `δ = deltas[i]` (and its untriggered
    /// steps use that `δ`); each sensor's trigger memory restarts with its own
    /// threshold. `None`: the configuration's one `δ` for every node. Errors
    /// (nothing changes) when the list is not one finite `δ > 0` per node.
    ///
    /// ```
    /// use edccif_sim::{network_config, simulate, Algorithm, Network, RunOptions, Scenario};
    /// use nalgebra::SMatrix;
    /// let sc = Scenario::paper(3);
    /// let cfg = network_config(Algorithm::EdcCif, &sc, &RunOptions::default()).unwrap();
    /// let p0 = SMatrix::<f64, 7, 7>::identity() * 0.01;
    /// let net = Network::new(cfg, sc.coordinated_turn().unwrap(), sc.dt, sc.sensor_models().unwrap(),
    ///                        sc.weights().unwrap(), &sc.x0, &p0).unwrap();
    /// let net = net.with_deltas(Some(vec![0.04, 0.01, 0.09])).unwrap();
    /// assert_eq!(net.deltas(), Some(&[0.04, 0.01, 0.09][..]));
    /// assert!(net.clone().with_deltas(Some(vec![0.04, 0.01])).is_err());
    /// ```
    pub fn with_deltas(mut self, deltas: Option<Vec<f64>>) -> Result<Self> {
        if let Some(d) = &deltas {
            crate::algorithm::Delta::PerNode(d.clone()).check(self.nodes.len())?;
            for (i, &di) in d.iter().enumerate() {
                let t = self.cfg.trigger.with_delta(di)?;
                self.nodes[i].trigger = TriggerState::new(&t);
            }
        }
        self.deltas = deltas;
        Ok(self)
    }

    /// The per-node thresholds, if set ([`with_deltas`](Self::with_deltas)).
    pub fn deltas(&self) -> Option<&[f64]> {
        self.deltas.as_deref()
    }

    /// Node i's trigger: the configuration's, at node i's threshold when the
    /// network has per-node thresholds.
    fn node_trigger(&self, i: usize) -> Trigger<f64> {
        match &self.deltas {
            // checked in `with_deltas`
            Some(d) => self
                .cfg
                .trigger
                .with_delta(d[i])
                .unwrap_or(self.cfg.trigger),
            None => self.cfg.trigger,
        }
    }

    /// Switches the parallel network step ([`ParallelStep`], rayon's global
    /// thread pool) on or off. Every step then runs the nodes of each phase on
    /// several threads, with the same numbers bit for bit as the serial step
    /// (the default): estimates, local estimates, trigger flags, reports and
    /// counters. It pays off only for large networks (N ≳ 64); see
    /// `docs/performance.md`. [`AnyNetwork::set_parallel`] is the same for the
    /// built-in networks.
    pub fn set_parallel(&mut self, on: bool) -> Result<()>
    where
        F: Sync,
    {
        self.parallel = if on {
            Some(self.parallel_from(ParallelStep::from_graph(&self.graph.core()?)?))
        } else {
            None
        };
        Ok(())
    }

    /// The parallel step continuing from the serial step's state: the
    /// pre-combination estimates a step keeps where it forms none (a node that
    /// is down) come from the scratch.
    fn parallel_from(&self, mut step: ParallelStep<f64, N, M>) -> Parallel<F, N>
    where
        F: Sync,
    {
        for (i, s) in self.scratch.iter().enumerate() {
            step.set_post(i, s.post);
        }
        Parallel {
            step,
            run: parallel_step::<F, N>,
        }
    }

    /// Whether the parallel step is on ([`set_parallel`](Self::set_parallel),
    /// [`set_threads`](Self::set_threads)).
    pub fn parallel(&self) -> bool {
        self.parallel.is_some()
    }

    /// Steps on `threads` threads: `1` is the serial step (the default),
    /// `n >= 2` the parallel step on the [`shared_pool`](crate::parallel::shared_pool)
    /// of `n` threads, with the same numbers bit for bit; `0` is an error
    /// (nothing changes). [`RunOptions::threads`](crate::RunOptions::threads)
    /// sets this for [`run`] and [`AnyNetwork::new`].
    pub fn set_threads(&mut self, threads: usize) -> Result<()>
    where
        F: Sync,
    {
        crate::parallel::check_threads(threads)?;
        self.parallel = if threads == 1 {
            None
        } else {
            let pool = crate::parallel::shared_pool(threads)?;
            let step = ParallelStep::from_graph(&self.graph.core()?)?.with_pool(pool);
            Some(self.parallel_from(step))
        };
        Ok(())
    }

    /// Threads a step runs on: 1 for the serial step, else those of the
    /// parallel step's pool.
    pub fn threads(&self) -> usize {
        self.parallel.as_ref().map_or(1, |p| p.step.threads())
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Restarts every sensor's trigger memory, node i's random stream keyed by
    /// `(seed, i)` (only the stochastic trigger draws from it).
    /// [`AnyNetwork::new`] does this with [`RunOptions::trigger_seed`](crate::RunOptions::trigger_seed).
    ///
    /// ```
    /// use edccif_sim::{simulate, AnyNetwork, Algorithm, RunOptions, Scenario, TriggerKind};
    /// let sc = Scenario::paper(4);
    /// let sim = simulate(&sc, 0).unwrap();
    /// let opt = RunOptions { trigger: Some(TriggerKind::Stochastic), trigger_seed: Some(7), ..RunOptions::default() };
    /// let mut a = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
    /// let mut b = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
    /// for z in sim.z.chunks(12).take(20) {
    ///     a.step(z).unwrap();
    ///     b.step(z).unwrap();
    /// }
    /// assert_eq!(a.last_triggered(), b.last_triggered());
    /// ```
    pub fn seed_triggers(&mut self, seed: u64) {
        for i in 0..self.nodes.len() {
            let t = self.node_trigger(i);
            self.nodes[i].trigger = TriggerState::seeded(&t, seed, i as u64);
        }
    }

    /// The nominal time step.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// One step of the nominal `dt` with measurements `z` (row-major `(N, 3)`; a
    /// row of NaN means no measurement). Optional `links` (`N × N`,
    /// `links[i*N+j]`: i hears j) and `active` (`N`) masks model lost messages and
    /// nodes that are down. On error nothing changes.
    pub fn step_with(
        &mut self,
        z: &[f64],
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        self.step_dt_with(z, self.dt, links, active)
    }

    /// [`step_with`](Self::step_with) over a time step `dt` of its own (the time
    /// since the previous step, finite and `> 0`): for measurements with their own
    /// timestamps. On error nothing changes.
    pub fn step_dt_with(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        self.step_dt_with_control(z, dt, links, active, Control::none())
    }

    /// [`step_dt_with`](Self::step_dt_with) under a [`Control`]: a cancelled
    /// control stops the step before it starts, or between consensus rounds
    /// of a step with many of them (see
    /// [`prepare_interruptible`](Self::prepare_interruptible)), with
    /// [`Error::Interrupted`] and nothing changed.
    pub fn step_dt_with_control(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
        ctl: &Control,
    ) -> Result<StepReport> {
        self.step_dt_with_mask(z, dt, links.map(LinkMask::Dense), active, ctl)
    }

    /// [`step_with`](Self::step_with) with the link mask in either form: `N ×
    /// N` ([`LinkMask::Dense`]) or one entry per entry of the network's
    /// neighbour lists ([`LinkMask::Edges`], indexed like
    /// [`graph`](Self::graph): memory O(N + edges) for a large network).
    /// On error nothing changes.
    ///
    /// ```
    /// use edccif_core::LinkMask;
    /// use edccif_sim::{simulate, AnyNetwork, Algorithm, RunOptions, Scenario};
    /// let sc = Scenario::paper(4);
    /// let sim = simulate(&sc, 0).unwrap();
    /// let net = || AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
    /// let (mut a, mut b) = (net(), net());
    /// // node 0 does not hear node 1: its list is [0, 1, 3]
    /// assert_eq!(a.graph().row(0), &[0, 1, 3]);
    /// let mut dense = vec![true; 16];
    /// dense[1] = false;
    /// let mut edges = vec![true; a.graph().entries()];
    /// edges[1] = false;
    /// a.step_with(&sim.z[..12], Some(&dense), None).unwrap();
    /// b.step_with_mask(&sim.z[..12], Some(LinkMask::Edges(&edges)), None).unwrap();
    /// let (mut ea, mut eb) = (vec![0.0; 28], vec![0.0; 28]);
    /// a.write_estimates(&mut ea);
    /// b.write_estimates(&mut eb);
    /// assert_eq!(ea, eb);
    /// // the wrong length is a named error
    /// assert!(b.step_with_mask(&sim.z[..12], Some(LinkMask::Edges(&edges[1..])), None).is_err());
    /// ```
    pub fn step_with_mask(
        &mut self,
        z: &[f64],
        links: Option<LinkMask<'_>>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        self.step_dt_with_mask(z, self.dt, links, active, Control::none())
    }

    /// [`step_dt_with_control`](Self::step_dt_with_control) with the link
    /// mask in either form ([`step_with_mask`](Self::step_with_mask)).
    pub fn step_dt_with_mask(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<LinkMask<'_>>,
        active: Option<&[bool]>,
        ctl: &Control,
    ) -> Result<StepReport> {
        ctl.check()?;
        check_dt(dt, "dt")?;
        let k = self.nodes.len();
        parse_observations(z, k, &mut self.obs)?;
        let mut inputs = StepInputs::new(&self.obs, dt);
        if let Some(l) = links {
            inputs = inputs.with_links(l);
        }
        inputs.active = active;
        inputs.deltas = self.deltas.as_deref();
        let graph = self.graph.core()?;
        let chosen = match (&mut self.parallel, &mut self.interruptible) {
            (Some(p), _) => Some(p),
            (None, Some(p)) if ctl.is_live() => {
                // It continues what the serial step left in the scratch.
                for (i, s) in self.scratch.iter().enumerate() {
                    p.step.set_post(i, s.post);
                }
                Some(p)
            }
            _ => None,
        };
        let report = match chosen {
            Some(Parallel { step: par, run }) => {
                let report = run(
                    par,
                    &self.cfg,
                    &self.motion,
                    &self.sensors,
                    &mut self.nodes,
                    &inputs,
                    ctl,
                )?;
                // What the serial step leaves in the scratch and the accessors read.
                for (i, s) in self.scratch.iter_mut().enumerate() {
                    s.post = *par.post(i);
                    s.triggered = par.flags(i).triggered;
                }
                report
            }
            None => network_step_weighted(
                &self.cfg,
                &self.motion,
                &self.sensors,
                &graph,
                &mut self.nodes,
                &mut self.scratch,
                &inputs,
            )?,
        };
        let step = StepMessages::new(&self.cfg, N, graph.neighbours(), links, active);
        let sensors = self.scratch.iter().map(|s| (M, s.triggered));
        self.counters.add_step(&report, &step, sensors);
        Ok(report)
    }

    /// [`step_with`](Self::step_with) without faults.
    pub fn step(&mut self, z: &[f64]) -> Result<StepReport> {
        self.step_with(z, None, None)
    }

    /// Every node's fused estimate.
    pub fn estimates(&self) -> impl Iterator<Item = &Gaussian<f64, N>> {
        self.nodes.iter().map(|n| &n.estimate)
    }

    /// Every node's estimate before combination (local posterior, or the adapted
    /// one for diffusion) at the last step.
    pub fn local_estimates(&self) -> impl Iterator<Item = &Gaussian<f64, N>> {
        self.scratch.iter().map(|s| &s.post)
    }

    /// Per-node `Some(γ)` of the last step (`None`: no measurement).
    pub fn last_triggered(&self) -> impl Iterator<Item = Option<bool>> + '_ {
        self.scratch.iter().map(|s| s.triggered)
    }

    /// Totals so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Replaces node `i`'s estimate (e.g. a node rejoining from a neighbour's).
    pub fn reset_node(&mut self, i: usize, estimate: Gaussian<f64, N>) -> Result<()> {
        if i >= self.nodes.len() {
            return Err(Error::Value {
                what: "node index".into(),
                problem: format!("{i} is out of range 0..{}", self.nodes.len()),
            });
        }
        self.nodes[i].estimate = Gaussian::new(estimate.x, estimate.p)?;
        Ok(())
    }

    /// Copies node `from`'s fused estimate to node `to` (a node rejoining from a
    /// neighbour); the trigger memory of `to` is kept.
    pub fn copy_estimate(&mut self, from: usize, to: usize) -> Result<()> {
        let k = self.nodes.len();
        if from >= k || to >= k {
            return Err(Error::Value {
                what: "node index".into(),
                problem: format!("{from} or {to} is out of range 0..{k}"),
            });
        }
        self.nodes[to].estimate = self.nodes[from].estimate;
        Ok(())
    }
}

/// A network of either built-in state dimension.
#[derive(Debug, Clone)]
pub enum AnyNetwork {
    /// Coordinated turn, 7 states.
    Ct(Network<CoordinatedTurn<f64>, 7>),
    /// Constant velocity, 6 states.
    Cv(Network<ConstantVelocity<f64>, 6>),
    /// Constant acceleration, 9 states.
    Ca(Network<ConstantAcceleration<f64>, 9>),
}

macro_rules! any {
    ($self:expr, $net:ident => $body:expr) => {
        match $self {
            AnyNetwork::Ct($net) => $body,
            AnyNetwork::Cv($net) => $body,
            AnyNetwork::Ca($net) => $body,
        }
    };
}

impl AnyNetwork {
    /// Builds the network of `alg` for a scenario, starting every node from
    /// `(x0, diag(p0_diag))`.
    ///
    /// ```
    /// use edccif_sim::{simulate, AnyNetwork, Algorithm, RunOptions, Scenario};
    /// let sc = Scenario::paper(4);
    /// let sim = simulate(&sc, 0).unwrap();
    /// let mut net = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
    /// net.step(&sim.z[..12]).unwrap();
    /// let mut est = vec![0.0; 4 * 7];
    /// net.write_estimates(&mut est);
    /// assert!(est.iter().all(|v| v.is_finite()));
    /// ```
    pub fn new(alg: Algorithm, sc: &Scenario, x0: &[f64], opt: &RunOptions) -> Result<Self> {
        sc.validate()?;
        let cfg = network_config(alg, sc, opt)?;
        let deltas = node_deltas(alg, Some((&sc.delta, sc.normalised)), opt, sc.nodes())?;
        let sensors = sc.sensor_models()?;
        let w = sc.neighbours()?;
        let mut net = match sc.motion {
            MotionSpec::CoordinatedTurn { .. } => {
                let p0 =
                    SMatrix::<f64, 7, 7>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
                AnyNetwork::Ct(
                    Network::with_graph(cfg, sc.coordinated_turn()?, sc.dt, sensors, w, x0, &p0)?
                        .with_deltas(deltas)?,
                )
            }
            MotionSpec::ConstantVelocity { .. } => {
                let p0 =
                    SMatrix::<f64, 6, 6>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
                AnyNetwork::Cv(
                    Network::with_graph(cfg, sc.constant_velocity()?, sc.dt, sensors, w, x0, &p0)?
                        .with_deltas(deltas)?,
                )
            }
            MotionSpec::ConstantAcceleration { .. } => {
                let p0 =
                    SMatrix::<f64, 9, 9>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
                AnyNetwork::Ca(
                    Network::with_graph(
                        cfg,
                        sc.constant_acceleration()?,
                        sc.dt,
                        sensors,
                        w,
                        x0,
                        &p0,
                    )?
                    .with_deltas(deltas)?,
                )
            }
            _ => return Err(sc.model_network_error()),
        };
        let seed = opt.trigger_seed.unwrap_or(0);
        any!(&mut net, n => n.seed_triggers(seed));
        if let Some(t) = opt.threads {
            net.set_threads(t)?;
        }
        any!(&mut net, n => n.prepare_interruptible())?;
        Ok(net)
    }

    /// State dimension.
    pub fn state_dim(&self) -> usize {
        match self {
            AnyNetwork::Ct(_) => 7,
            AnyNetwork::Cv(_) => 6,
            AnyNetwork::Ca(_) => 9,
        }
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        any!(self, n => n.nodes())
    }

    /// See [`Network::graph`].
    pub fn graph(&self) -> &NeighbourLists {
        any!(self, n => n.graph())
    }

    /// See [`Network::step_with`].
    pub fn step_with(
        &mut self,
        z: &[f64],
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        any!(self, n => n.step_with(z, links, active))
    }

    /// See [`Network::step_dt_with`].
    pub fn step_dt_with(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        any!(self, n => n.step_dt_with(z, dt, links, active))
    }

    /// See [`Network::step_dt_with_control`].
    pub fn step_dt_with_control(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
        ctl: &Control,
    ) -> Result<StepReport> {
        any!(self, n => n.step_dt_with_control(z, dt, links, active, ctl))
    }

    /// See [`Network::step_with_mask`].
    pub fn step_with_mask(
        &mut self,
        z: &[f64],
        links: Option<LinkMask<'_>>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        any!(self, n => n.step_with_mask(z, links, active))
    }

    /// See [`Network::step_dt_with_mask`].
    pub fn step_dt_with_mask(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<LinkMask<'_>>,
        active: Option<&[bool]>,
        ctl: &Control,
    ) -> Result<StepReport> {
        any!(self, n => n.step_dt_with_mask(z, dt, links, active, ctl))
    }

    /// Whether a step runs many consensus rounds (see [`Network::heavy`]).
    pub fn heavy(&self) -> bool {
        any!(self, n => n.heavy())
    }

    /// Consensus rounds per step (0 for the diffusion and local rows).
    pub fn consensus_rounds(&self) -> usize {
        any!(self, n => n.consensus_rounds())
    }

    /// One step of its own `dt` without faults (see [`Network::step_dt_with`]).
    pub fn step_dt(&mut self, z: &[f64], dt: f64) -> Result<StepReport> {
        any!(self, n => n.step_dt_with(z, dt, None, None))
    }

    /// See [`Network::step`].
    pub fn step(&mut self, z: &[f64]) -> Result<StepReport> {
        any!(self, n => n.step(z))
    }

    /// Writes the fused estimates, row-major `(N, n)`.
    pub fn write_estimates(&self, out: &mut [f64]) {
        any!(self, net => {
            let n = net.estimates().next().map_or(0, |g| g.x.len());
            for (g, o) in net.estimates().zip(out.chunks_exact_mut(n)) {
                o.copy_from_slice(g.x.as_slice());
            }
        })
    }

    /// Writes the fused covariances, row-major `(N, n, n)` (symmetric, so the
    /// column-major storage reads the same).
    pub fn write_covariances(&self, out: &mut [f64]) {
        any!(self, net => {
            let n = net.estimates().next().map_or(0, |g| g.x.len());
            for (g, o) in net.estimates().zip(out.chunks_exact_mut(n * n)) {
                o.copy_from_slice(g.p.transpose().as_slice());
            }
        })
    }

    /// Writes the pre-combination estimates of the last step, row-major `(N, n)`.
    pub fn write_local_estimates(&self, out: &mut [f64]) {
        any!(self, net => {
            let n = net.estimates().next().map_or(0, |g| g.x.len());
            for (g, o) in net.local_estimates().zip(out.chunks_exact_mut(n)) {
                o.copy_from_slice(g.x.as_slice());
            }
        })
    }

    /// Per-node `Some(γ)` of the last step.
    pub fn last_triggered(&self) -> Vec<Option<bool>> {
        any!(self, n => n.last_triggered().collect())
    }

    /// Writes the last step's flags: `triggered[i]` (sent) and `measured[i]`.
    pub fn write_triggered(&self, triggered: &mut [bool], measured: &mut [bool]) {
        any!(self, n => {
            for ((g, t), m) in n.last_triggered().zip(triggered.iter_mut()).zip(measured.iter_mut()) {
                *t = g == Some(true);
                *m = g.is_some();
            }
        })
    }

    /// Totals so far.
    pub fn counters(&self) -> Counters {
        any!(self, n => n.counters())
    }

    /// Switches the parallel network step on or off (default off): see
    /// [`Network::set_parallel`]. The numbers are the same bit for bit; only
    /// large networks (N ≳ 64) run faster.
    ///
    /// ```
    /// use edccif_sim::{simulate, AnyNetwork, Algorithm, RunOptions, Scenario};
    /// let sc = Scenario::paper(8);
    /// let sim = simulate(&sc, 0).unwrap();
    /// let opt = RunOptions::default();
    /// let mut serial = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
    /// let mut par = serial.clone();
    /// par.set_parallel(true).unwrap();
    /// assert!(par.parallel() && !serial.parallel());
    /// for z in sim.z.chunks(8 * 3).take(20) {
    ///     assert_eq!(serial.step(z).unwrap(), par.step(z).unwrap());
    /// }
    /// let (mut a, mut b) = (vec![0.0; 8 * 7], vec![0.0; 8 * 7]);
    /// serial.write_estimates(&mut a);
    /// par.write_estimates(&mut b);
    /// assert_eq!(a, b); // bit for bit
    /// ```
    pub fn set_parallel(&mut self, on: bool) -> Result<()> {
        any!(self, n => n.set_parallel(on))
    }

    /// Whether the parallel step is on ([`set_parallel`](Self::set_parallel),
    /// [`set_threads`](Self::set_threads)).
    pub fn parallel(&self) -> bool {
        any!(self, n => n.parallel())
    }

    /// Steps on `threads` threads (`1`: serial, the default; `0`: an error):
    /// see [`Network::set_threads`]. [`new`](Self::new) applies
    /// [`RunOptions::threads`].
    ///
    /// ```
    /// use edccif_sim::{simulate, AnyNetwork, Algorithm, RunOptions, Scenario};
    /// let sc = Scenario::paper(8);
    /// let sim = simulate(&sc, 0).unwrap();
    /// let opt = RunOptions { threads: Some(2), ..RunOptions::default() };
    /// let mut net = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
    /// assert_eq!(net.threads(), 2);
    /// assert!(net.set_threads(0).is_err());
    /// assert_eq!(net.threads(), 2); // unchanged
    /// net.set_threads(1).unwrap();
    /// assert!(!net.parallel());
    /// ```
    pub fn set_threads(&mut self, threads: usize) -> Result<()> {
        any!(self, n => n.set_threads(threads))
    }

    /// Threads a step runs on (1: the serial step).
    pub fn threads(&self) -> usize {
        any!(self, n => n.threads())
    }

    /// See [`Network::copy_estimate`].
    pub fn copy_estimate(&mut self, from: usize, to: usize) -> Result<()> {
        any!(self, n => n.copy_estimate(from, to))
    }

    /// Resets node `i` to a given estimate (`x` of length n, `p` row-major n × n).
    pub fn reset_node(&mut self, i: usize, x: &[f64], p: &[f64]) -> Result<()> {
        any!(self, net => {
            let n = net.estimates().next().map_or(0, |g| g.x.len());
            if x.len() != n || p.len() != n * n {
                return Err(Error::Shape { what: "reset estimate".into(), expected: format!("({n},) and ({n}, {n})"), got: format!("{} and {} values", x.len(), p.len()) });
            }
            let g = Gaussian { x: SVector::from_column_slice(x), p: SMatrix::from_row_slice(p) };
            net.reset_node(i, g)
        })
    }
}

/// Runs `alg` over measurements `z` (row-major `(T, N, 3)`, NaN rows = missing)
/// from the initial estimate `x0` (`P0` from the scenario).
/// [`RunOptions::threads`] runs every step on several threads (large networks
/// only; the same numbers bit for bit).
///
/// ```
/// use edccif_sim::{run, simulate, Algorithm, RunOptions, Scenario};
/// let sc = Scenario::paper(4);
/// let sim = simulate(&sc, 1).unwrap();
/// let r = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), true).unwrap();
/// assert_eq!(r.estimates.len(), 200 * 4 * 7);
/// assert!(r.trigger_rate() > 0.2 && r.trigger_rate() < 0.9);
/// let par = RunOptions { threads: Some(2), ..RunOptions::default() };
/// let p = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &par, true).unwrap();
/// assert_eq!((p.estimates, p.counters), (r.estimates, r.counters)); // bit for bit
/// ```
pub fn run(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    record_covariances: bool,
) -> Result<RunResult> {
    run_inner(
        alg,
        sc,
        z,
        x0,
        opt,
        None,
        None,
        record_covariances,
        None,
        Control::none(),
        Control::none(),
    )
}

/// [`run`] with non-uniform time steps: `dt[t]` is the time from step `t − 1` to
/// step `t` (`dt[0]`: from the initial estimate to the first measurement), one per
/// step, each finite and `> 0`. With every `dt[t]` equal to the scenario's `dt`
/// this is [`run`], bit for bit. [`dt_from_times`] turns timestamps into steps.
///
/// ```
/// use edccif_sim::{run, run_with_dt, dt_from_times, simulate, Algorithm, RunOptions, Scenario};
/// let sc = Scenario::paper(4);
/// let sim = simulate(&sc, 1).unwrap();
/// let t: Vec<f64> = (1..=sc.steps).map(|k| k as f64 * sc.dt).collect();
/// let dt = dt_from_times(&t, 0.0).unwrap();
/// let a = run_with_dt(Algorithm::EdcCif, &sc, &sim.z, &dt, &sim.x0_hat, &RunOptions::default(), false).unwrap();
/// let b = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), false).unwrap();
/// assert!(a.estimates.iter().zip(&b.estimates).all(|(x, y)| (x - y).abs() < 1e-9));
/// ```
pub fn run_with_dt(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    dt: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    record_covariances: bool,
) -> Result<RunResult> {
    run_inner(
        alg,
        sc,
        z,
        x0,
        opt,
        None,
        Some(dt),
        record_covariances,
        None,
        Control::none(),
        Control::none(),
    )
}

/// Time steps from timestamps: `dt[0] = times[0] − t0` (`t0`: the time of the
/// initial estimate), `dt[t] = times[t] − times[t − 1]`. Times must be finite and
/// strictly increasing (after `t0`); the error names the first offending index.
///
/// ```
/// let dt = edccif_sim::dt_from_times(&[0.1, 0.25, 0.3], 0.0).unwrap();
/// assert!((dt[1] - 0.15).abs() < 1e-12);
/// assert!(edccif_sim::dt_from_times(&[0.1, 0.1], 0.0).is_err());
/// ```
pub fn dt_from_times(times: &[f64], t0: f64) -> Result<Vec<f64>> {
    let mut prev = t0;
    let mut out = Vec::with_capacity(times.len());
    for (i, &t) in times.iter().enumerate() {
        let d = t - prev;
        if !(t.is_finite() && d > 0.0 && d.is_finite()) {
            return Err(Error::Value {
                what: format!("t[{i}]"),
                problem: format!(
                    "timestamps must be finite and strictly increasing (after the initial estimate's time {t0}); got {t} after {prev}"
                ),
            });
        }
        out.push(d);
        prev = t;
    }
    Ok(out)
}

/// Work a run does before each network step: what
/// [`FaultInjector`](crate::faults::FaultInjector) does to inject faults. The
/// run loop knows a hook only through this trait.
pub(crate) trait StepHook {
    /// Prepares step `t`: may edit the measurement row `z` (row-major
    /// `(N, 3)`, in place) and the network (a node's rejoin).
    fn prepare(&mut self, t: usize, z: &mut [f64], net: &mut AnyNetwork) -> Result<()>;
    /// The link mask of the step being prepared.
    fn links(&self) -> LinkMask<'_>;
    /// The active mask of the step being prepared.
    fn active(&self) -> &[bool];
}

/// Builds a run's [`StepHook`] for its scenario; called once the network is
/// built, so that the network's errors come before the hook's.
pub(crate) type HookBuilder<'a> = &'a dyn Fn(&Scenario) -> Result<Box<dyn StepHook>>;

/// [`run`] with an optional [`StepHook`] (faults: [`crate::faults`]) and, with
/// `local`, the pre-combination estimates `(T, N, n)` of every step (for MCAP
/// recording).
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_inner(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    hook: Option<HookBuilder<'_>>,
    dts: Option<&[f64]>,
    record_covariances: bool,
    mut local: Option<&mut Vec<f64>>,
    ctl: &Control,
    progress: &Control,
) -> Result<RunResult> {
    if !sc.is_typed() && hook.is_none() && local.is_none() {
        return crate::catalogue::run_models(alg, sc, z, x0, opt, dts, record_covariances);
    }
    let mut net = AnyNetwork::new(alg, sc, x0, opt)?;
    let mut inj = hook.map(|h| h(sc)).transpose()?;
    let k = net.nodes();
    let n = net.state_dim();
    if !z.len().is_multiple_of(k * M) || z.is_empty() {
        return Err(Error::Shape {
            what: "z".into(),
            expected: format!("(T, {k}, {M})"),
            got: format!("{} values", z.len()),
        });
    }
    let steps = z.len() / (k * M);
    if let Some(d) = dts {
        if d.len() != steps {
            return Err(Error::Shape {
                what: "dt".into(),
                expected: format!("({steps},), one time step per measurement step"),
                got: format!("({},)", d.len()),
            });
        }
        for (i, &v) in d.iter().enumerate() {
            check_dt(v, format_args!("dt[{i}]"))?;
        }
    }
    crate::limits::check_memory(
        || {
            format!(
                "a run of steps = {steps} with nodes = {k} (estimates steps × nodes × {n}{}{})",
                if record_covariances {
                    format!(", covariances steps × nodes × {n} × {n}")
                } else {
                    String::new()
                },
                if local.is_some() {
                    ", local estimates steps × nodes × n"
                } else {
                    ""
                }
            )
        },
        run_bytes(steps, k, n, record_covariances, local.is_some()),
    )?;
    progress.add_total(steps as u64);
    let mut estimates = vec![0.0; steps * k * n];
    let mut covariances = if record_covariances {
        vec![0.0; steps * k * n * n]
    } else {
        Vec::new()
    };
    let mut triggered = vec![false; steps * k];
    let mut measured = vec![false; steps * k];
    if let Some(l) = local.as_deref_mut() {
        *l = vec![0.0; steps * k * n];
    }
    let t0 = Instant::now();
    let mut zt = vec![0.0; k * M];
    for t in 0..steps {
        zt.copy_from_slice(&z[t * k * M..(t + 1) * k * M]);
        let dt = dts.map_or(sc.dt, |d| d[t]);
        ctl.check()?;
        let stepped = match inj.as_mut() {
            None => net.step_dt_with_control(&zt, dt, None, None, ctl),
            Some(inj) => inj.prepare(t, &mut zt, &mut net).and_then(|()| {
                net.step_dt_with_mask(&zt, dt, Some(inj.links()), Some(inj.active()), ctl)
            }),
        };
        progress.advance(1);
        stepped.map_err(|e| match e {
            Error::Core(source) => Error::AtStep { step: t, source },
            other => other,
        })?;
        net.write_estimates(&mut estimates[t * k * n..(t + 1) * k * n]);
        if record_covariances {
            net.write_covariances(&mut covariances[t * k * n * n..(t + 1) * k * n * n]);
        }
        if let Some(l) = local.as_deref_mut() {
            net.write_local_estimates(&mut l[t * k * n..(t + 1) * k * n]);
        }
        net.write_triggered(
            &mut triggered[t * k..(t + 1) * k],
            &mut measured[t * k..(t + 1) * k],
        );
    }
    let elapsed_s = t0.elapsed().as_secs_f64();
    Ok(RunResult {
        algorithm: alg,
        steps,
        nodes: k,
        n,
        estimates,
        covariances,
        triggered,
        measured,
        counters: net.counters(),
        elapsed_s,
    })
}
