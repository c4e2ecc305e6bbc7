//! Seeded fault injection for the network runner: lost estimator ↔ estimator
//! messages, node dropout and rejoin, sensor outages and gross measurement
//! outliers. The innovation gate that defends against outliers is an estimator
//! option ([`RunOptions::gate`](crate::RunOptions::gate)).
//!
//! Randomness comes from two ChaCha8 streams seeded with [`Faults::seed`] (stream 1:
//! message loss, stream 2: outliers), independent of the measurement simulation:
//! the same `Faults` give the same faults on any data, and changing the outlier
//! probability does not change which messages are lost. Step `s` (the `s`-th
//! call of [`FaultInjector::prepare`]) owns the loss stream's draws `s·N(N−1)`
//! to `(s+1)·N(N−1) − 1`, one per ordered pair `i ≠ j` in row-major order
//! (pair `(i, j)` is draw `s·N(N−1) + i(N−1) + j − [j > i]`, one `u64` = two
//! ChaCha words), and the outlier stream one outlier draw plus three signs per
//! node, whatever happens. The injector reads only the draws of the graph's
//! directed edges (seeking the stream to each, or none at all when the loss is 0
//! or 1), so a step costs O(nodes + edges) time and memory, and the mask
//! it gives the network is one boolean per entry of the neighbour lists
//! ([`LinkMask::Edges`]).
//!
//! ```
//! use edccif_sim::faults::{run_with_faults, Faults, Window};
//! use edccif_sim::{simulate, Algorithm, RunOptions, Scenario};
//! let sc = Scenario::paper(4);
//! let sim = simulate(&sc, 0).unwrap();
//! let faults = Faults {
//!     message_loss: 0.3,
//!     dropout: vec![Window { node: 1, start: 66, end: 133 }],
//!     outage: vec![Window { node: 0, start: 100, end: 120 }],
//!     outlier_prob: 0.05,
//!     ..Faults::default()
//! };
//! let opt = RunOptions { gate: Some(16.27), ..RunOptions::default() };
//! let r = run_with_faults(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &opt, &faults, true).unwrap();
//! assert!(r.estimates.iter().all(|v| v.is_finite()));
//! assert!(r.counters.gated > 0);
//! ```

use edccif_core::angles::wrap_angle;
use edccif_core::{LinkMask, MeasurementModel};
use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::control::Control;
use crate::error::{Error, Result};
use crate::runner::{run_inner, AnyNetwork, HookBuilder, StepHook, M};
use crate::scenario::{Scenario, Sensor};
use crate::topology::NeighbourLists;
use crate::{Algorithm, RunOptions, RunResult};

/// A half-open window of steps `[start, end)` (zero-based step indices) on one node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Window {
    /// The node.
    pub node: usize,
    /// First step of the window.
    pub start: usize,
    /// First step after the window.
    pub end: usize,
}

impl Window {
    /// Whether step `t` of node `i` is inside the window.
    pub fn contains(&self, i: usize, t: usize) -> bool {
        self.node == i && t >= self.start && t < self.end
    }
}

/// The faults of one run. `Faults::default()` injects nothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Faults {
    /// Seed of the fault streams (independent of the simulation's seed).
    #[serde(default)]
    pub seed: u64,
    /// Probability that a message on a directed estimator → estimator link is lost
    /// at a step (drawn per link and step; a lost link drops every message of that
    /// step on it: the diffusion's contribution and adapted pair, or all consensus
    /// iterations).
    #[serde(default)]
    pub message_loss: f64,
    /// Node dropout windows: the node neither computes nor sends and keeps its
    /// state. At the first step after its window it rejoins from the fused
    /// estimate of its **first** (lowest-index) neighbour that was up at the
    /// previous step and is up now; with no such neighbour it resumes from its own
    /// stale estimate.
    #[serde(default)]
    pub dropout: Vec<Window>,
    /// Sensor outage windows: the node gets no measurement (its row becomes NaN);
    /// it still predicts and fuses.
    #[serde(default)]
    pub outage: Vec<Window>,
    /// Probability that a node's measurement at a step carries a gross error.
    #[serde(default)]
    pub outlier_prob: f64,
    /// Size of a gross error in noise standard deviations: each component gets
    /// `± outlier_sigma · σ_c` (random signs; angles re-wrapped).
    #[serde(default = "default_outlier_sigma")]
    pub outlier_sigma: f64,
}

fn default_outlier_sigma() -> f64 {
    20.0
}

impl Default for Faults {
    fn default() -> Self {
        Self {
            seed: 0,
            message_loss: 0.0,
            dropout: Vec::new(),
            outage: Vec::new(),
            outlier_prob: 0.0,
            outlier_sigma: default_outlier_sigma(),
        }
    }
}

fn prob(v: f64, what: &str) -> Result<()> {
    if (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(Error::Value {
            what: format!("faults.{what}"),
            problem: format!("must be a probability in [0, 1], got {v}"),
        })
    }
}

impl Faults {
    /// Checks probabilities, sizes and windows against `nodes`.
    pub fn validate(&self, nodes: usize) -> Result<()> {
        prob(self.message_loss, "message_loss")?;
        prob(self.outlier_prob, "outlier_prob")?;
        if !(self.outlier_sigma.is_finite() && self.outlier_sigma >= 0.0) {
            return Err(Error::Value {
                what: "faults.outlier_sigma".into(),
                problem: format!("must be finite and >= 0, got {}", self.outlier_sigma),
            });
        }
        for (name, ws) in [("dropout", &self.dropout), ("outage", &self.outage)] {
            for (n, w) in ws.iter().enumerate() {
                if w.node >= nodes {
                    return Err(Error::Value {
                        what: format!("faults.{name}[{n}].node"),
                        problem: format!("{} is out of range 0..{nodes}", w.node),
                    });
                }
                if w.start > w.end {
                    return Err(Error::Value {
                        what: format!("faults.{name}[{n}]"),
                        problem: format!("start {} is after end {}", w.start, w.end),
                    });
                }
            }
        }
        Ok(())
    }

    /// Whether node `i` is up at step `t`.
    pub fn is_active(&self, i: usize, t: usize) -> bool {
        !self.dropout.iter().any(|w| w.contains(i, t))
    }

    /// Whether node `i`'s sensor is out at step `t`.
    pub fn in_outage(&self, i: usize, t: usize) -> bool {
        self.outage.iter().any(|w| w.contains(i, t))
    }
}

/// Applies [`Faults`] step by step: fills the link and active masks, edits the
/// measurement row, and performs rejoins. Holds its own random streams. Memory
/// and time per step are O(nodes + edges) of the scenario's graph
/// ([`Scenario::neighbours`]).
///
/// ```
/// use edccif_sim::faults::{FaultInjector, Faults};
/// use edccif_sim::{simulate, AnyNetwork, Algorithm, RunOptions, Scenario};
/// let sc = Scenario::paper(4);
/// let sim = simulate(&sc, 0).unwrap();
/// let mut net = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
/// let faults = Faults { message_loss: 0.5, seed: 3, ..Faults::default() };
/// let mut inj = FaultInjector::new(&faults, &sc).unwrap();
/// let mut z = sim.z[..12].to_vec();
/// inj.prepare(0, &mut z, &mut net).unwrap();
/// // one entry per entry of the ring's lists (each node and its two neighbours)
/// assert_eq!(inj.edge_links.len(), sc.neighbours().unwrap().entries());
/// net.step_with_mask(&z, Some(inj.mask()), Some(&inj.active)).unwrap();
/// ```
#[derive(Debug, Clone)]
pub struct FaultInjector {
    faults: Faults,
    k: usize,
    graph: NeighbourLists,
    sigma: Vec<[f64; M]>,
    angle: Vec<[bool; M]>,
    loss_rng: ChaCha8Rng,
    /// Index of the first loss draw of the next step (`steps · N(N−1)`).
    next_draw: u128,
    outlier_rng: ChaCha8Rng,
    /// Link mask of the current step, one entry per entry of the scenario's
    /// neighbour lists ([`Scenario::neighbours`]; [`LinkMask::Edges`]):
    /// `edge_links[offset(i) + e]` is true when node i hears the `e`-th node
    /// of its list (its own entry is always true).
    pub edge_links: Vec<bool>,
    /// Active mask of the current step.
    pub active: Vec<bool>,
    /// Outliers injected so far.
    pub outliers: u64,
    /// Messages (directed link-steps between neighbours) lost so far.
    pub lost_links: u64,
    /// Rejoins performed so far.
    pub rejoins: u64,
}

/// ChaCha words per loss draw (`random::<f64>` reads one `u64`).
const WORDS_PER_DRAW: u128 = 2;

/// Words a seek forward may skip by drawing instead (one buffer of the ChaCha
/// generator: a seek regenerates it).
const SKIP_WORDS: u128 = 64;

impl FaultInjector {
    /// An injector for a scenario (validates the faults).
    pub fn new(faults: &Faults, sc: &Scenario) -> Result<Self> {
        let k = sc.nodes();
        faults.validate(k)?;
        let graph = sc.neighbours()?;
        crate::limits::check_memory(
            || {
                format!(
                    "the fault injector of {k} nodes (a link mask of {} entries)",
                    graph.entries()
                )
            },
            crate::limits::product(&[k, 16 * M + 1]).saturating_add(graph.entries() as u128),
        )?;
        let sensors = sc.sensor_models()?;
        let sigma = sensors
            .iter()
            .map(|s| {
                let r = MeasurementModel::<f64, 7, M>::noise(s);
                [r[(0, 0)].sqrt(), r[(1, 1)].sqrt(), r[(2, 2)].sqrt()]
            })
            .collect();
        let angle = sensors
            .iter()
            .map(|s: &Sensor| {
                std::array::from_fn(|c| MeasurementModel::<f64, 7, M>::is_angle(s, c))
            })
            .collect();
        let mut loss_rng = ChaCha8Rng::seed_from_u64(faults.seed);
        loss_rng.set_stream(1);
        let mut outlier_rng = ChaCha8Rng::seed_from_u64(faults.seed);
        outlier_rng.set_stream(2);
        let entries = graph.entries();
        Ok(Self {
            faults: faults.clone(),
            k,
            graph,
            sigma,
            angle,
            loss_rng,
            next_draw: 0,
            outlier_rng,
            edge_links: vec![true; entries],
            active: vec![true; k],
            outliers: 0,
            lost_links: 0,
            rejoins: 0,
        })
    }

    /// The link mask of the current step, for
    /// [`AnyNetwork::step_with_mask`] ([`Self::edge_links`]).
    pub fn mask(&self) -> LinkMask<'_> {
        LinkMask::Edges(&self.edge_links)
    }

    /// The graph the link mask is indexed by ([`Scenario::neighbours`]).
    pub fn graph(&self) -> &NeighbourLists {
        &self.graph
    }

    /// Whether the link `i ← j` (`j ≠ i`) is lost at the step whose first loss
    /// draw is `base`: draw `base + i(N−1) + j − [j > i]` of the loss stream
    /// below the loss probability.
    fn draw_lost(&mut self, base: u128, i: usize, j: usize) -> bool {
        let k = self.k as u128;
        let (i, j) = (i as u128, j as u128);
        let draw = base + i * (k - 1) + j - u128::from(j > i);
        let target = draw * WORDS_PER_DRAW;
        let at = self.loss_rng.get_word_pos();
        if target != at {
            if target > at && target - at <= SKIP_WORDS {
                for _ in 0..(target - at) / WORDS_PER_DRAW {
                    self.loss_rng.next_u64();
                }
            } else {
                self.loss_rng.set_word_pos(target);
            }
        }
        self.loss_rng.random::<f64>() < self.faults.message_loss
    }

    /// The faults being injected.
    pub fn faults(&self) -> &Faults {
        &self.faults
    }

    /// Prepares step `t`: draws the link mask, sets the active mask, blanks
    /// outages and adds outliers to `z` (row-major `(N, 3)`, edited in place), and
    /// rejoins nodes whose dropout ended (via [`AnyNetwork::copy_estimate`]).
    pub fn prepare(&mut self, t: usize, z: &mut [f64], net: &mut AnyNetwork) -> Result<()> {
        let k = self.k;
        let base = self.next_draw;
        self.next_draw += k as u128 * k.saturating_sub(1) as u128;
        let loss = self.faults.message_loss;
        for i in 0..k {
            let a = self.graph.parts().0[i];
            for e in 0..self.graph.row(i).len() {
                let j = self.graph.row(i)[e];
                // Every draw is in [0, 1): no draw is needed to know that none
                // is below 0 or all are below 1.
                let lost = j != i && (loss >= 1.0 || (loss > 0.0 && self.draw_lost(base, i, j)));
                self.edge_links[a + e] = !lost;
                self.lost_links += u64::from(lost);
            }
        }
        let f = &self.faults;
        for i in 0..k {
            self.active[i] = f.is_active(i, t);
        }
        for i in 0..k {
            let row = &mut z[i * M..(i + 1) * M];
            let u: f64 = self.outlier_rng.random();
            let signs: [bool; M] = std::array::from_fn(|_| self.outlier_rng.random());
            if f.in_outage(i, t) {
                row.fill(f64::NAN);
                continue;
            }
            if u < f.outlier_prob && row.iter().all(|v| v.is_finite()) {
                self.outliers += 1;
                for c in 0..M {
                    let e = f.outlier_sigma * self.sigma[i][c];
                    row[c] += if signs[c] { e } else { -e };
                    if self.angle[i][c] {
                        row[c] = wrap_angle(row[c]);
                    }
                }
            }
        }
        if t > 0 {
            for i in 0..k {
                if self.active[i] && !f.is_active(i, t - 1) {
                    let from = self
                        .graph
                        .row(i)
                        .iter()
                        .copied()
                        .find(|&j| j != i && self.active[j] && f.is_active(j, t - 1));
                    if let Some(j) = from {
                        net.copy_estimate(j, i)?;
                        self.rejoins += 1;
                    }
                }
            }
        }
        Ok(())
    }
}

impl StepHook for FaultInjector {
    fn prepare(&mut self, t: usize, z: &mut [f64], net: &mut AnyNetwork) -> Result<()> {
        FaultInjector::prepare(self, t, z, net)
    }
    fn links(&self) -> LinkMask<'_> {
        self.mask()
    }
    fn active(&self) -> &[bool] {
        &self.active
    }
}

/// Calls `run` with the builder of the [`FaultInjector`] of `faults` (`None`
/// without faults): the run loop builds it once the network is built.
fn with_injector<T>(faults: Option<&Faults>, run: impl FnOnce(Option<HookBuilder<'_>>) -> T) -> T {
    match faults {
        None => run(None),
        Some(f) => run(Some(&|sc: &Scenario| -> Result<Box<dyn StepHook>> {
            Ok(Box::new(FaultInjector::new(f, sc)?))
        })),
    }
}

/// [`run`](crate::run) with injected faults: same inputs and result (the
/// counters include the gate's rejections); the fused estimates of a node that is
/// down are its kept (stale) estimates.
pub fn run_with_faults(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    faults: &Faults,
    record_covariances: bool,
) -> Result<RunResult> {
    run_with_control(
        alg,
        sc,
        z,
        x0,
        opt,
        Some(faults),
        None,
        record_covariances,
        Control::none(),
    )
}

/// [`run_with_faults`] with non-uniform time steps (`dt` as in
/// [`run_with_dt`](crate::run_with_dt)).
#[allow(clippy::too_many_arguments)]
pub fn run_with_faults_dt(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    dt: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    faults: &Faults,
    record_covariances: bool,
) -> Result<RunResult> {
    run_with_control(
        alg,
        sc,
        z,
        x0,
        opt,
        Some(faults),
        Some(dt),
        record_covariances,
        Control::none(),
    )
}

/// [`run`](crate::run), [`run_with_dt`](crate::run_with_dt) (`dts`), or
/// [`run_with_faults`] (`faults`, with or without `dts`) under a [`Control`]: checked for
/// cancellation at every step (and between the consensus rounds of a step with
/// many of them), with [`Error::Interrupted`]; steps count as its progress.
/// What it would allocate is checked first
/// ([`check_run_size`](crate::runner::check_run_size)).
#[allow(clippy::too_many_arguments)]
pub fn run_with_control(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    faults: Option<&Faults>,
    dts: Option<&[f64]>,
    record_covariances: bool,
    ctl: &Control,
) -> Result<RunResult> {
    run_controlled(
        alg,
        sc,
        z,
        x0,
        opt,
        faults,
        dts,
        record_covariances,
        ctl,
        ctl,
    )
}

/// [`run_with_control`] whose steps count as the progress of `progress`
/// ([`Control::none`] for a caller that counts its own units, e.g. a Monte
/// Carlo study's runs), cancelled through `ctl`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_controlled(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    faults: Option<&Faults>,
    dts: Option<&[f64]>,
    record_covariances: bool,
    ctl: &Control,
    progress: &Control,
) -> Result<RunResult> {
    with_injector(faults, |hook| {
        run_inner(
            alg,
            sc,
            z,
            x0,
            opt,
            hook,
            dts,
            record_covariances,
            None,
            ctl,
            progress,
        )
    })
}
