//! Networks of one's own models: any number of nodes, one motion model, and per
//! node a sensor of its own kind and measurement dimension `m` (a bearing-only
//! node beside a range–bearing one). The information form fuses in state space,
//! so only the local step sees `m`: each node boxes a [`NodeSensor`] (its typed
//! sensor and trigger memory), and the fusion is generic over the state
//! dimension `N` only.
//!
//! # One step, the core's phases
//!
//! A single [`network_step`](edccif_core::network_step) call needs one sensor
//! type for all nodes (its measurement dimension is a const generic), so this
//! network drives the core's phases itself, as the
//! [`node`](edccif_core::node) module describes for a serial loop over nodes
//! of different sensors:
//!
//! 1. **local phase**, per node with its own typed sensor:
//!    [`node_local_into`] into the node's [`PhaseScratch`] (behind the
//!    [`NodeSensor`] object, which keeps the new trigger memory aside);
//! 2. **fusion phases** over every node's scratch at once:
//!    [`network_fusion`] (adaptation and combination, every
//!    [`FusionRule`](edccif_core::FusionRule), or the consensus rounds),
//!    which also counts the step's [`StepReport`];
//! 3. **commit**: each node that was up takes its fused estimate, its sensor
//!    its trigger memory; the step's messages go to the [`Counters`] by
//!    [`Counters::add_step`], the rule the scenario network counts by.
//!
//! These are the functions `network_step` is a loop over, in the same order
//! and with the same neighbour lists, so a network whose sensors all have the
//! same type gives the built-in network's numbers bit for bit (the tests in
//! `tests/suite/mixed.rs` compare every row and every fusion rule). The scratch lives
//! in the network: a step allocates nothing. A failed step leaves every node as
//! it was (the scratch of the step before is kept in a second buffer and put
//! back).
//!
//! ```
//! use edccif_core::models::{CoordinatedTurn, Position3, RangePitchAzimuth};
//! use edccif_core::{Gaussian, MotionModel};
//! use edccif_sim::mixed::{MixedNetwork, NodeSensor, SensorNode};
//! use edccif_sim::{Algorithm, RowParams, RunOptions};
//! use nalgebra::{SMatrix, SVector};
//!
//! let motion: Box<dyn MotionModel<f64, 7> + Send + Sync> = Box::new(CoordinatedTurn::new(0.5, 1e-4)?);
//! let sensors: Vec<Box<dyn NodeSensor<7>>> = vec![
//!     Box::new(SensorNode::<_, 3>::new(RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)?)),
//!     Box::new(SensorNode::<_, 3>::new(Position3::new([0.05; 3])?)),
//! ];
//! let start = Gaussian::new(SVector::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]),
//!                           SMatrix::<f64, 7, 7>::identity() * 0.01)?;
//! let w = [0.5, 0.5, 0.5, 0.5];
//! let mut net = MixedNetwork::new(Algorithm::EdcCif, &RowParams::paper(1), &RunOptions::default(),
//!                                 motion, sensors, w.to_vec(), start, 0.1)?;
//! // node 0: range, pitch, azimuth; node 1: a position (3 + 3 values, NaN = missing)
//! net.step(&[5.0, 0.05, 3.1, 5.0, 0.1, 1.0], 0.1)?;
//! assert!(net.estimate(0).x[0] > 4.0);
//! # Ok::<(), edccif_sim::Error>(())
//! ```

use edccif_core::model::PointImages;
use edccif_core::network::network_fusion;
use edccif_core::node::{node_local_into, PhaseScratch};
use edccif_core::{
    Gaussian, MeasurementModel, MotionModel, Neighbours, NetworkConfig, NodeState, Observation,
    StepReport, Trigger, TriggerState,
};
use nalgebra::{SMatrix, SVector};

use crate::algorithm::{row_config, Algorithm, RowParams, RunOptions};
use crate::control::Control;
use crate::counters::{Counters, StepMessages};
use crate::error::{Error, Result};
use crate::result::RunResult;
use crate::timestep::check_dt;

/// One node's sensor with its trigger memory, behind a trait object so that
/// nodes of different measurement dimensions share one network. The state
/// dimension `N` is the network's; the measurement dimension is the node's own.
pub trait NodeSensor<const N: usize>: Send + Sync {
    /// Measurement dimension `m` of this node.
    fn meas_dim(&self) -> usize;
    /// The row's local phase ([`node_local_into`]) from `estimate` over `dt`
    /// with this node's measurement `z` (`m` values, all NaN: none), into the
    /// node's `out`. The new trigger memory is kept aside until
    /// [`commit`](Self::commit); the node's state is unchanged.
    fn local(
        &mut self,
        cfg: &NetworkConfig<f64>,
        motion: &dyn MotionModel<f64, N>,
        dt: f64,
        estimate: &Gaussian<f64, N>,
        z: &[f64],
        out: &mut PhaseScratch<f64, N>,
    ) -> Result<()>;
    /// Keeps the trigger memory of the last [`local`](Self::local) step.
    fn commit(&mut self);
    /// Restarts the trigger memory for `trigger`, with the stream `(seed, node)`
    /// of the stochastic trigger.
    fn reset_trigger(&mut self, trigger: &Trigger<f64>, seed: u64, node: u64);
    /// Saves the trigger memory for [`rollback`](Self::rollback).
    fn checkpoint(&mut self);
    /// Restores the trigger memory saved by [`checkpoint`](Self::checkpoint).
    fn rollback(&mut self);
    /// The measurement noise `R` of the following [`local`](Self::local)
    /// steps: `Some(r)` (row-major `m × m`, checked finite, symmetric and
    /// positive definite) in place of the sensor's own, `None` back to the
    /// sensor's. A node that cannot take one refuses `Some`.
    fn set_noise(&mut self, r: Option<&[f64]>) -> Result<()> {
        match r {
            None => Ok(()),
            Some(_) => Err(Error::Value {
                what: "measurement noise".into(),
                problem: "this node's sensor takes no per-step noise".into(),
            }),
        }
    }
}

/// A sensor with its noise `R` replaced (everything else the sensor's own).
struct WithNoise<'a, H, const M: usize> {
    sensor: &'a H,
    r: SMatrix<f64, M, M>,
}

impl<H, const N: usize, const M: usize> MeasurementModel<f64, N, M> for WithNoise<'_, H, M>
where
    H: MeasurementModel<f64, N, M>,
{
    #[inline]
    fn measure(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        self.sensor.measure(x)
    }
    #[inline]
    fn noise(&self) -> SMatrix<f64, M, M> {
        self.r
    }
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        self.sensor.is_angle(k)
    }
    #[inline]
    fn fast_trig(&self) -> bool {
        self.sensor.fast_trig()
    }
    #[inline]
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        self.sensor.jacobian(x)
    }
    #[inline]
    fn measure_with_jacobian(&self, x: &SVector<f64, N>) -> (SVector<f64, M>, SMatrix<f64, M, N>) {
        self.sensor.measure_with_jacobian(x)
    }
    #[inline]
    fn jacobian_products(
        &self,
        g: &SMatrix<f64, M, N>,
        p: &SMatrix<f64, N, N>,
    ) -> (SMatrix<f64, N, M>, SMatrix<f64, M, M>) {
        self.sensor.jacobian_products(g, p)
    }
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<f64, N>,
    ) -> (SVector<f64, M>, SVector<f64, M>, SVector<f64, M>) {
        self.sensor.measure_with_trig(x)
    }
    #[inline]
    fn measure_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.sensor.measure_points(x, offsets, plus, minus, centre)
    }
    #[inline]
    fn measure_points_trig(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.sensor
            .measure_points_trig(x, offsets, plus, minus, centre)
    }
}

/// A typed sensor `H` of measurement dimension `M` as a [`NodeSensor`].
#[derive(Debug, Clone)]
pub struct SensorNode<H, const M: usize> {
    sensor: H,
    trigger: TriggerState<f64, M>,
    pending: TriggerState<f64, M>,
    saved: TriggerState<f64, M>,
    /// The noise of the next local steps, in place of the sensor's.
    noise: Option<SMatrix<f64, M, M>>,
}

impl<H, const M: usize> SensorNode<H, M> {
    /// A node with sensor `sensor` and a fresh trigger memory (the network
    /// resets it for its row).
    pub fn new(sensor: H) -> Self {
        let t = TriggerState::new(&Trigger::Always);
        Self {
            sensor,
            trigger: t,
            pending: t,
            saved: t,
            noise: None,
        }
    }

    /// The sensor.
    pub fn sensor(&self) -> &H {
        &self.sensor
    }
}

impl<H, const N: usize, const M: usize> NodeSensor<N> for SensorNode<H, M>
where
    H: MeasurementModel<f64, N, M> + Send + Sync,
{
    fn meas_dim(&self) -> usize {
        M
    }

    fn local(
        &mut self,
        cfg: &NetworkConfig<f64>,
        motion: &dyn MotionModel<f64, N>,
        dt: f64,
        estimate: &Gaussian<f64, N>,
        z: &[f64],
        out: &mut PhaseScratch<f64, N>,
    ) -> Result<()> {
        let obs = if z.iter().all(|v| v.is_nan()) {
            Observation::Missing
        } else {
            Observation::Measured(SVector::<f64, M>::from_column_slice(z))
        };
        let state = NodeState {
            estimate: *estimate,
            trigger: self.trigger,
        };
        self.pending = match self.noise {
            None => node_local_into(cfg, motion, dt, &self.sensor, &state, &obs, out)?,
            Some(r) => {
                let s = WithNoise {
                    sensor: &self.sensor,
                    r,
                };
                node_local_into(cfg, motion, dt, &s, &state, &obs, out)?
            }
        };
        Ok(())
    }

    fn commit(&mut self) {
        self.trigger = self.pending;
    }

    fn reset_trigger(&mut self, trigger: &Trigger<f64>, seed: u64, node: u64) {
        self.trigger = TriggerState::seeded(trigger, seed, node);
        self.pending = self.trigger;
    }

    fn checkpoint(&mut self) {
        self.saved = self.trigger;
    }

    fn rollback(&mut self) {
        self.trigger = self.saved;
    }

    fn set_noise(&mut self, r: Option<&[f64]>) -> Result<()> {
        self.noise = match r {
            None => None,
            Some(v) => {
                if v.len() != M * M {
                    return Err(Error::Shape {
                        what: "measurement noise".into(),
                        expected: format!("({M}, {M})"),
                        got: format!("{} values", v.len()),
                    });
                }
                let m = SMatrix::<f64, M, M>::from_row_slice(v);
                edccif_core::linalg::validate_covariance(&m, "measurement noise R")?;
                Some(m)
            }
        };
        Ok(())
    }
}

/// A network of `k` nodes over state dimension `N`, each with its own sensor.
pub struct MixedNetwork<const N: usize> {
    algorithm: Algorithm,
    cfg: NetworkConfig<f64>,
    /// Each node's configuration: `cfg` with the trigger at the node's own
    /// threshold ([`RunOptions::delta`] per node), else `cfg`.
    node_cfgs: Vec<NetworkConfig<f64>>,
    motion: Box<dyn MotionModel<f64, N> + Send + Sync>,
    sensors: Vec<Box<dyn NodeSensor<N>>>,
    /// Node i's measurement values are `z[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<usize>,
    weights: Vec<f64>,
    /// The closed neighbourhoods of `weights` ([`Neighbours`]), built once.
    neighbour_offsets: Vec<usize>,
    neighbour_indices: Vec<usize>,
    estimates: Vec<Gaussian<f64, N>>,
    /// Every node's working memory through the phases of the last step.
    scratch: Vec<PhaseScratch<f64, N>>,
    /// The scratch before the step under way, restored when it fails.
    saved: Vec<PhaseScratch<f64, N>>,
    dt: f64,
    counters: Counters,
}

impl<const N: usize> std::fmt::Debug for MixedNetwork<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MixedNetwork")
            .field("algorithm", &self.algorithm)
            .field("nodes", &self.sensors.len())
            .field("state_dim", &N)
            .field("meas_dims", &self.meas_dims())
            .finish()
    }
}

impl<const N: usize> MixedNetwork<N> {
    /// Builds the network of row `alg` (parameters `params`, overridden by
    /// `opt` as for the scenario networks): every node starts from `start`; the
    /// graph is where `weights` (row-major `k × k`, checked by
    /// [`validate_weights`](crate::topology::validate_weights)) is `> 0` off the
    /// diagonal; `dt` is the nominal time step of [`step_nominal`](Self::step_nominal).
    /// It steps serially: [`RunOptions::threads`] above 1 is an error.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        alg: Algorithm,
        params: &RowParams,
        opt: &RunOptions,
        motion: Box<dyn MotionModel<f64, N> + Send + Sync>,
        sensors: Vec<Box<dyn NodeSensor<N>>>,
        weights: Vec<f64>,
        start: Gaussian<f64, N>,
        dt: f64,
    ) -> Result<Self> {
        check_dt(dt, "dt")?;
        let k = sensors.len();
        if k == 0 {
            return Err(Error::Value {
                what: "sensors".into(),
                problem: "at least one node is needed".into(),
            });
        }
        if weights.len() != k * k {
            return Err(Error::Shape {
                what: "weights".into(),
                expected: format!("({k}, {k}) (one row and column per sensor)"),
                got: format!("{} values", weights.len()),
            });
        }
        let adjacency = crate::topology::adjacency_of_weights(&weights, k);
        edccif_core::fusion::validate_adjacency(&adjacency, k)?;
        crate::topology::validate_weights(&weights, &adjacency, k)?;
        let start = Gaussian::new(start.x, start.p)?;
        let cfg = row_config(alg, params, opt)?;
        let triggers = match crate::algorithm::node_deltas(alg, None, opt, k)? {
            Some(d) => d
                .iter()
                .map(|&di| cfg.trigger.with_delta(di))
                .collect::<edccif_core::Result<Vec<_>>>()?,
            None => vec![cfg.trigger; k],
        };
        if let Some(t @ 2..) = opt.threads {
            return Err(Error::Value {
                what: "threads".into(),
                problem: format!(
                    "got {t}; a network of one's own models steps serially (threads 1 or unset); the parallel step is for the built-in networks (AnyNetwork, run)"
                ),
            });
        }
        let mut offsets = Vec::with_capacity(k + 1);
        offsets.push(0);
        for s in &sensors {
            offsets.push(offsets.last().copied().unwrap_or(0) + s.meas_dim());
        }
        let node_cfgs = triggers
            .into_iter()
            .map(|trigger| NetworkConfig { trigger, ..cfg })
            .collect();
        let mut neighbour_offsets = vec![0; k + 1];
        let mut neighbour_indices = vec![0; Neighbours::count(&weights, k)];
        Neighbours::from_weights(&weights, k, &mut neighbour_offsets, &mut neighbour_indices)?;
        let mut blank = PhaseScratch::default();
        (blank.post, blank.fused) = (start, start);
        let mut net = Self {
            algorithm: alg,
            cfg,
            node_cfgs,
            motion,
            sensors,
            offsets,
            weights,
            neighbour_offsets,
            neighbour_indices,
            estimates: vec![start; k],
            scratch: vec![blank; k],
            saved: vec![blank; k],
            dt,
            counters: Counters::default(),
        };
        net.seed_triggers(opt.trigger_seed.unwrap_or(0));
        Ok(net)
    }

    /// Restarts every sensor's trigger memory, node i's random stream keyed by
    /// `(seed, i)` (only the stochastic trigger draws from it).
    pub fn seed_triggers(&mut self, seed: u64) {
        for (i, s) in self.sensors.iter_mut().enumerate() {
            s.reset_trigger(&self.node_cfgs[i].trigger, seed, i as u64);
        }
    }

    /// Node i's trigger (the configuration's at node i's threshold).
    pub fn trigger(&self, i: usize) -> Option<&Trigger<f64>> {
        self.node_cfgs.get(i).map(|c| &c.trigger)
    }

    /// The row.
    pub fn algorithm(&self) -> Algorithm {
        self.algorithm
    }

    /// The core configuration of the row.
    pub fn config(&self) -> &NetworkConfig<f64> {
        &self.cfg
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.sensors.len()
    }

    /// Every node's measurement dimension.
    pub fn meas_dims(&self) -> Vec<usize> {
        self.sensors.iter().map(|s| s.meas_dim()).collect()
    }

    /// Total measurement values per step (`Σ m_i`): the length of `z` in
    /// [`step`](Self::step), node 0's values first.
    pub fn meas_total(&self) -> usize {
        self.offsets[self.sensors.len()]
    }

    /// The combination weights (row-major `k × k`).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The nominal time step.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Node `i`'s fused estimate (panics if `i` is out of range).
    pub fn estimate(&self, i: usize) -> &Gaussian<f64, N> {
        &self.estimates[i]
    }

    /// Every node's fused estimate.
    pub fn estimates(&self) -> &[Gaussian<f64, N>] {
        &self.estimates
    }

    /// Every node's estimate before combination at the last step.
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

    /// Replaces node `i`'s estimate (checked: finite, covariance SPD).
    pub fn reset_node(&mut self, i: usize, estimate: Gaussian<f64, N>) -> Result<()> {
        if i >= self.estimates.len() {
            return Err(Error::Value {
                what: "node index".into(),
                problem: format!("{i} is out of range 0..{}", self.estimates.len()),
            });
        }
        self.estimates[i] = Gaussian::new(estimate.x, estimate.p)?;
        Ok(())
    }

    /// One step of the nominal `dt`.
    pub fn step_nominal(&mut self, z: &[f64]) -> Result<StepReport> {
        self.step_with(z, self.dt, None, None)
    }

    /// One step over `dt` with measurements `z` (every node's `m_i` values
    /// concatenated; a node's values all NaN: no measurement).
    pub fn step(&mut self, z: &[f64], dt: f64) -> Result<StepReport> {
        self.step_with(z, dt, None, None)
    }

    /// Checks a step's measurements: length `Σ m_i`; per node all NaN or all finite.
    pub fn check_measurements(&self, z: &[f64]) -> Result<()> {
        let k = self.sensors.len();
        if z.len() != self.meas_total() {
            return Err(Error::Shape {
                what: "z".into(),
                expected: format!(
                    "{} values (the nodes' measurement dimensions {:?})",
                    self.meas_total(),
                    self.meas_dims()
                ),
                got: format!("{} values", z.len()),
            });
        }
        for i in 0..k {
            let row = &z[self.offsets[i]..self.offsets[i + 1]];
            let nan = row.iter().filter(|v| v.is_nan()).count();
            if (nan > 0 && nan < row.len()) || row.iter().any(|v| v.is_infinite()) {
                return Err(Error::Value {
                    what: format!("measurement of node {i}"),
                    problem: format!(
                        "{row:?} mixes NaN/inf with numbers; all NaN means \"no measurement\", otherwise all values must be finite"
                    ),
                });
            }
        }
        Ok(())
    }

    /// [`step`](Self::step) with optional `links` (`k × k`, `links[i*k+j]`: i
    /// hears j) and `active` (`k`) masks for lost messages and nodes that are
    /// down. On error nothing changes: neither the estimates and trigger
    /// memories nor the last step's [`local_estimates`](Self::local_estimates)
    /// and [`last_triggered`](Self::last_triggered).
    pub fn step_with(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        self.saved.copy_from_slice(&self.scratch);
        let r = self.step_inner(z, dt, links, active);
        if r.is_err() {
            self.scratch.copy_from_slice(&self.saved);
        }
        r
    }

    /// [`step_with`](Self::step_with) without restoring the scratch on error
    /// (the commit to the estimates and trigger memories is its last action).
    // Index loops: the mask, the measurement offsets and five per-node
    // vectors are indexed by node.
    #[allow(clippy::needless_range_loop)]
    fn step_inner(
        &mut self,
        z: &[f64],
        dt: f64,
        links: Option<&[bool]>,
        active: Option<&[bool]>,
    ) -> Result<StepReport> {
        check_dt(dt, "dt")?;
        self.check_measurements(z)?;
        let k = self.sensors.len();
        for (what, len) in [
            ("links", links.map(<[bool]>::len)),
            ("active", active.map(<[bool]>::len)),
        ] {
            let want = if what == "links" { k * k } else { k };
            if let Some(l) = len {
                if l != want {
                    return Err(Error::Shape {
                        what: what.into(),
                        expected: format!("{want} values"),
                        got: format!("{l} values"),
                    });
                }
            }
        }
        let up = |i: usize| active.is_none_or(|a| a[i]);

        // 1. Local phase, each node with its own sensor (the only phase that
        // sees its measurement dimension).
        for i in 0..k {
            let s = &mut self.scratch[i];
            if !up(i) {
                s.triggered = None;
                s.guard_used = false;
                s.gated = false;
                continue;
            }
            let zi = &z[self.offsets[i]..self.offsets[i + 1]];
            self.sensors[i].local(
                &self.node_cfgs[i],
                &*self.motion,
                dt,
                &self.estimates[i],
                zi,
                s,
            )?;
        }

        // 2. Fusion phases over every node's scratch (state space only).
        let neighbours = Neighbours::new(&self.neighbour_offsets, &self.neighbour_indices)?;
        let report = network_fusion(
            self.cfg.fusion,
            self.cfg.rule,
            &self.weights,
            Some(&neighbours),
            links,
            active,
            &mut self.scratch,
        )?;

        // 3. Commit.
        for i in 0..k {
            if up(i) {
                self.estimates[i] = self.scratch[i].fused;
                self.sensors[i].commit();
            }
        }
        let step = StepMessages::new(
            &self.cfg,
            N,
            &neighbours,
            links.map(edccif_core::LinkMask::Dense),
            active,
        );
        let sensors =
            (self.sensors.iter().zip(&self.scratch)).map(|(n, s)| (n.meas_dim(), s.triggered));
        self.counters.add_step(&report, &step, sensors);
        Ok(report)
    }

    /// Runs the network over `T` steps: `z` row-major `(T, Σ m_i)`, `dt` one time
    /// step per row. On error (naming the step) the estimates, the last step's
    /// [`local_estimates`](Self::local_estimates) and
    /// [`last_triggered`](Self::last_triggered), the trigger memories and the
    /// counters are as they were before the run.
    pub fn run(&mut self, z: &[f64], dt: &[f64], record_covariances: bool) -> Result<RunResult> {
        self.run_with_noise(z, dt, None, record_covariances)
    }

    /// [`run`](Self::run) with each step's own measurement noise: `noise`
    /// row-major `(T, Σ m_i²)`, per step every node's `m_i × m_i` noise `R`
    /// (row-major) in node order, all NaN where the node's sensor keeps its own
    /// `R`. Each given `R` must be finite, symmetric and positive definite (the
    /// error names the step and node). With no noise given (`None`, or all NaN)
    /// this is [`run`](Self::run), bit for bit; a step with a given `R` equals
    /// a step of a sensor whose own `R` is that matrix.
    ///
    /// ```
    /// use edccif_core::models::{ConstantVelocity, Position3};
    /// use edccif_core::{Gaussian, MotionModel};
    /// use edccif_sim::mixed::{MixedNetwork, NodeSensor, SensorNode};
    /// use edccif_sim::{Algorithm, RowParams, RunOptions};
    /// use nalgebra::{SMatrix, SVector};
    /// let build = |sigma: f64| {
    ///     let motion: Box<dyn MotionModel<f64, 6> + Send + Sync> = Box::new(ConstantVelocity::new(0.5).unwrap());
    ///     let sensors: Vec<Box<dyn NodeSensor<6>>> = vec![Box::new(SensorNode::<_, 3>::new(Position3::new([sigma; 3]).unwrap()))];
    ///     let start = Gaussian::new(SVector::zeros(), SMatrix::<f64, 6, 6>::identity()).unwrap();
    ///     MixedNetwork::new(Algorithm::DcCif, &RowParams::paper(1), &RunOptions::default(),
    ///                       motion, sensors, vec![1.0], start, 0.1).unwrap()
    /// };
    /// let z = [0.1, 0.0, 0.0, 0.2, 0.0, 0.0];
    /// // The noise of σ = 0.3 m given per step equals a sensor of σ = 0.3 m.
    /// let r = [0.09, 0.0, 0.0, 0.0, 0.09, 0.0, 0.0, 0.0, 0.09];
    /// let noise: Vec<f64> = r.iter().chain(&r).copied().collect();
    /// let a = build(0.01).run_with_noise(&z, &[0.1, 0.1], Some(&noise), true)?;
    /// let b = build(0.3).run(&z, &[0.1, 0.1], true)?;
    /// assert_eq!(a.estimates, b.estimates);
    /// # Ok::<(), edccif_sim::Error>(())
    /// ```
    pub fn run_with_noise(
        &mut self,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        record_covariances: bool,
    ) -> Result<RunResult> {
        self.run_with_noise_control(z, dt, noise, record_covariances, Control::none())
    }

    /// [`run`](Self::run) under a [`Control`], checked at every step: cancelled,
    /// it returns [`Error::Interrupted`] with the network as it was before the
    /// run. What the run returns is checked against the memory available first.
    pub fn run_with_control(
        &mut self,
        z: &[f64],
        dt: &[f64],
        record_covariances: bool,
        ctl: &Control,
    ) -> Result<RunResult> {
        self.run_with_noise_control(z, dt, None, record_covariances, ctl)
    }

    /// [`run_with_noise`](Self::run_with_noise) under a [`Control`]
    /// ([`run_with_control`](Self::run_with_control)).
    pub fn run_with_noise_control(
        &mut self,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        record_covariances: bool,
        ctl: &Control,
    ) -> Result<RunResult> {
        crate::result::check_run_size(dt.len(), self.nodes(), N, record_covariances)?;
        let estimates = self.estimates.clone();
        let scratch = self.scratch.clone();
        let counters = self.counters;
        for s in &mut self.sensors {
            s.checkpoint();
        }
        let r = self.run_inner(z, dt, noise, record_covariances, ctl);
        for s in &mut self.sensors {
            // Back to each sensor's own noise (clearing always succeeds).
            let _ = s.set_noise(None);
        }
        if r.is_err() {
            self.estimates = estimates;
            self.scratch = scratch;
            self.counters = counters;
            for s in &mut self.sensors {
                s.rollback();
            }
        }
        r
    }

    fn run_inner(
        &mut self,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        record_covariances: bool,
        ctl: &Control,
    ) -> Result<RunResult> {
        let k = self.nodes();
        let m = self.meas_total();
        let steps = dt.len();
        let dims = self.meas_dims();
        let per_step: usize = dims.iter().map(|d| d * d).sum();
        if let Some(r) = noise {
            if r.len() != steps * per_step {
                return Err(Error::Shape {
                    what: "noise".into(),
                    expected: format!(
                        "({steps}, {per_step}) (per step every node's m × m noise, m = {dims:?})"
                    ),
                    got: format!("{} values", r.len()),
                });
            }
        }
        if z.len() != steps * m {
            return Err(Error::Shape {
                what: "z".into(),
                expected: format!("({steps}, {m}) (one row of every node's values per step)"),
                got: format!("{} values", z.len()),
            });
        }
        for (i, &v) in dt.iter().enumerate() {
            check_dt(v, format_args!("dt[{i}]"))?;
        }
        for t in 0..steps {
            self.check_measurements(&z[t * m..(t + 1) * m])
                .map_err(|e| match e {
                    Error::Value { what, problem } => Error::Value {
                        what: format!("step {t}: {what}"),
                        problem,
                    },
                    other => other,
                })?;
        }
        let mut estimates = Vec::with_capacity(steps * k * N);
        let mut covariances = Vec::with_capacity(if record_covariances {
            steps * k * N * N
        } else {
            0
        });
        let mut triggered = Vec::with_capacity(steps * k);
        let mut measured = Vec::with_capacity(steps * k);
        let t0 = std::time::Instant::now();
        ctl.add_total(steps as u64);
        for t in 0..steps {
            ctl.check()?;
            if let Some(r) = noise {
                let mut off = t * per_step;
                for (i, d) in dims.iter().enumerate() {
                    let block = &r[off..off + d * d];
                    off += d * d;
                    let given = if block.iter().all(|v| v.is_nan()) {
                        None
                    } else {
                        Some(block)
                    };
                    self.sensors[i].set_noise(given).map_err(|e| match e {
                        Error::Core(source) => Error::Value {
                            what: format!("step {t}: measurement noise of node {i}"),
                            problem: source.to_string(),
                        },
                        Error::Value { what, problem } => Error::Value {
                            what: format!("step {t}: {what} of node {i}"),
                            problem,
                        },
                        other => other,
                    })?;
                }
            }
            // `run` restores the scratch of the whole run on error.
            self.step_inner(&z[t * m..(t + 1) * m], dt[t], None, None)
                .map_err(|e| match e {
                    Error::Core(source) => Error::AtStep { step: t, source },
                    Error::Value { what, problem } => Error::Value {
                        what: format!("step {t}: {what}"),
                        problem,
                    },
                    other => other,
                })?;
            for g in &self.estimates {
                estimates.extend_from_slice(g.x.as_slice());
                if record_covariances {
                    covariances.extend_from_slice(g.p.transpose().as_slice());
                }
            }
            for g in self.last_triggered() {
                triggered.push(g == Some(true));
                measured.push(g.is_some());
            }
            ctl.advance(1);
        }
        Ok(RunResult {
            algorithm: self.algorithm,
            steps,
            nodes: k,
            n: N,
            estimates,
            covariances,
            triggered,
            measured,
            counters: self.counters,
            elapsed_s: t0.elapsed().as_secs_f64(),
        })
    }
}

/// The model network of row `alg` on scenario `sc` (either node form) from
/// the given models: `motion` (state dimension `N`) and one sensor per node
/// (for the scenario's own catalogue models:
/// [`catalogue::node_sensors`](crate::catalogue::node_sensors) and the motion
/// of [`catalogue::with_motion`](crate::catalogue::with_motion)). Every node
/// starts from `x0` with the scenario's `P0`; the parameters (`δ` per node,
/// `normalised`, `σ1`, `σ2`, `L`, dynamic trigger, UKF), the graph and the
/// nominal `dt` are the scenario's, overridden by `opt` as for
/// [`crate::run`]. Each node's rate is in its measurements (NaN where it does
/// not measure, as [`crate::simulate()`] gives them).
///
/// ```
/// use edccif_core::MotionModel;
/// use edccif_sim::catalogue::{node_sensors, with_motion, MotionVisitor};
/// use edccif_sim::mixed::model_network;
/// use edccif_sim::{run, simulate, Algorithm, Result, RunOptions, RunResult, Scenario};
///
/// struct Run<'a>(&'a Scenario, &'a edccif_sim::Simulation);
/// impl MotionVisitor for Run<'_> {
///     type Output = RunResult;
///     fn visit<const N: usize, F>(self, motion: F) -> Result<RunResult>
///     where
///         F: MotionModel<f64, N> + Send + Sync + 'static,
///     {
///         let (sc, sim) = (self.0, self.1);
///         let mut net = model_network::<N>(Algorithm::EdcCif, sc, &sim.x0_hat, &RunOptions::default(),
///                                          Box::new(motion), node_sensors::<N>(sc)?)?;
///         net.run(&sim.z, &vec![sc.dt; sc.steps], false)
///     }
/// }
/// // The paper's scenario in the per-node form: the typed network's numbers.
/// let sc = Scenario { steps: 20, ..Scenario::paper(4) };
/// let sim = simulate(&sc, 1)?;
/// let typed = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), false)?;
/// let per_node = sc.per_node();
/// let models = with_motion(&per_node, Run(&per_node, &sim))?;
/// assert_eq!(models.estimates, typed.estimates);
/// # Ok::<(), edccif_sim::Error>(())
/// ```
pub fn model_network<const N: usize>(
    alg: Algorithm,
    sc: &crate::Scenario,
    x0: &[f64],
    opt: &RunOptions,
    motion: Box<dyn MotionModel<f64, N> + Send + Sync>,
    sensors: Vec<Box<dyn NodeSensor<N>>>,
) -> Result<MixedNetwork<N>> {
    sc.validate()?;
    let k = sc.nodes();
    if sensors.len() != k {
        return Err(Error::Shape {
            what: "sensors".into(),
            expected: format!("{k} (one per node of the scenario)"),
            got: format!("{}", sensors.len()),
        });
    }
    if x0.len() != N || sc.p0_diag.len() != N {
        return Err(Error::Shape {
            what: "x0".into(),
            expected: format!("({},) (the scenario's state dimension)", sc.p0_diag.len()),
            got: format!("({},), a motion model of {N} states", x0.len()),
        });
    }
    let iters = match opt.consensus_iters {
        Some(l) => l,
        None => sc.consensus_iterations()?,
    };
    let mut opt = opt.clone();
    if opt.delta.is_none() {
        let scenario = Some((&sc.delta, sc.normalised));
        if let Some(d) = crate::algorithm::node_deltas(alg, scenario, &opt, k)? {
            opt.delta = Some(crate::Delta::PerNode(d));
        }
    }
    let p0 = SMatrix::<f64, N, N>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
    let start = Gaussian::new(SVector::from_column_slice(x0), p0)?;
    MixedNetwork::new(
        alg,
        &RowParams::of(sc, iters),
        &opt,
        motion,
        sensors,
        sc.weights()?,
        start,
        sc.dt,
    )
}
