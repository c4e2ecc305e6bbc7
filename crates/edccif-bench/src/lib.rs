//! # edccif-bench
//!
//! Shared timing code for the criterion benches (`benches/edccif.rs`), the
//! paper-claims check (`benches/paper_claims.rs`) and the Table III analog
//! (`src/bin/edccif-timing.rs`).
//!
//! Everything here follows one protocol so that the numbers of the three tools
//! can be compared:
//!
//! - **Same data for every row.** A [`Workload`] holds one seeded simulation of
//!   the default scenario; every algorithm row consumes the same measurements
//!   and starts from the same initial estimate.
//! - **No handicaps.** Each row is stepped through
//!   [`AnyNetwork::step`](edccif_sim::AnyNetwork::step) on a network built
//!   beforehand; nothing is recorded inside the timed loop (the equivalent of
//!   `edccif_sim::run` with `record_covariances = false`, minus the estimate
//!   copies it makes).
//! - **Interleaved repetitions, medians.** [`interleaved_runs`] alternates the
//!   cases within every repetition (rotating the starting case), so that a burst
//!   of load from other processes on a shared machine hits all cases alike; the
//!   reported figure is the [`median`].
//! - **Two clocks.** Every run is timed with the wall clock and with the
//!   thread's CPU clock ([`RunTime`]). On a loaded machine a run that is
//!   descheduled for a time slice (several ms, longer than a whole run) inflates
//!   its wall time but not its CPU time.
//!
//! The paper's own figures (Table III, Table I) are in [`paper`].
//!
//! ```
//! use edccif_bench::{interleaved_runs, median, Workload};
//! use edccif_sim::Algorithm;
//! let w = Workload::paper(3, 0).unwrap();
//! let cases = [(Algorithm::EdcCif, &w), (Algorithm::EcCkf, &w)];
//! let samples = interleaved_runs(&cases, 3, 1).unwrap();
//! assert_eq!(samples.len(), 2);
//! assert!(median(&samples[0].wall) > 0.0 && median(&samples[0].cpu) > 0.0);
//! ```

use std::fmt;
use std::hint::black_box;
use std::ops::Range;
use std::str::FromStr;
use std::time::{Duration, Instant};

use cpu_time::ThreadTime;

use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::{
    cif_local, cov_local, cov_local_chained, CheckedGaussian, EtOptions, Gaussian, LocalFilter,
    Observation, Trigger, TriggerState,
};
use edccif_sim::runner::M;
use edccif_sim::{
    simulate, Algorithm, AnyNetwork, Result, RunOptions, Scenario, Simulation, Topology,
};
use nalgebra::{SMatrix, SVector, Vector3};

pub mod config;
pub mod fair;
pub mod paper;
pub mod scaling;
pub mod targets;

/// The seed every tool uses for its simulated data unless told otherwise.
pub const DEFAULT_SEED: u64 = 2024;

/// One row of a comparison: an algorithm row, with the consensus rows' number of
/// iterations `L` either the scenario's adequate one (`iters: None`,
/// ALGORITHM.md §5) or fixed (through [`RunOptions::consensus_iters`]; the
/// diffusion rows ignore it).
///
/// Written `ec-ckf` or `ec-ckf@L2` ([`FromStr`], [`Display`](fmt::Display)).
///
/// ```
/// use edccif_bench::Row;
/// use edccif_sim::Algorithm;
/// let r: Row = "ec-ckf@L2".parse().unwrap();
/// assert_eq!(r, Row::fixed(Algorithm::EcCkf, 2));
/// assert_eq!((r.to_string(), r.label()), ("ec-ckf@L2".to_string(), "EC-CKF (L = 2)".to_string()));
/// assert_eq!("edc-cif".parse::<Row>().unwrap(), Row::new(Algorithm::EdcCif));
/// assert!("ec-ckf@L0".parse::<Row>().is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Row {
    /// The algorithm row.
    pub alg: Algorithm,
    /// Fixed consensus iterations `L` (`None`: the adequate `L`).
    pub iters: Option<usize>,
}

impl Row {
    /// `alg` with the scenario's own (adequate) `L`.
    pub const fn new(alg: Algorithm) -> Self {
        Self { alg, iters: None }
    }

    /// `alg` with a fixed `L` (`≥ 1`).
    pub const fn fixed(alg: Algorithm, iters: usize) -> Self {
        Self {
            alg,
            iters: Some(iters),
        }
    }

    /// The paper's label, with the fixed `L` if any: `"EC-CKF (L = 1)"`.
    pub fn label(&self) -> String {
        match self.iters {
            None => self.alg.label().to_string(),
            Some(l) => format!("{} (L = {l})", self.alg.label()),
        }
    }

    /// The run options of the row (only `consensus_iters` set).
    pub fn options(&self) -> RunOptions {
        RunOptions {
            consensus_iters: self.iters,
            ..RunOptions::default()
        }
    }

    /// Whether the row fuses by consensus (so `L` matters).
    pub fn is_consensus(&self) -> bool {
        !matches!(
            self.alg,
            Algorithm::DCif | Algorithm::DcCif | Algorithm::EdCif | Algorithm::EdcCif
        )
    }
}

impl From<Algorithm> for Row {
    fn from(alg: Algorithm) -> Self {
        Self::new(alg)
    }
}

impl fmt::Display for Row {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.iters {
            None => f.write_str(self.alg.name()),
            Some(l) => write!(f, "{}@L{l}", self.alg.name()),
        }
    }
}

impl FromStr for Row {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let (alg, l) = match s.split_once('@') {
            None => (s, None),
            Some((a, l)) => (a, Some(l.trim().trim_start_matches(['L', 'l']))),
        };
        let alg: Algorithm = alg.parse().map_err(|e| format!("{e}"))?;
        match l {
            None => Ok(Self::new(alg)),
            Some(l) => match l.parse::<usize>() {
                Ok(l) if l >= 1 => Ok(Self::fixed(alg, l)),
                _ => Err(format!(
                    "row {s:?}: expected ROW or ROW@L<iterations >= 1>, e.g. ec-ckf@L2"
                )),
            },
        }
    }
}

/// One seeded experiment: a scenario and one simulated run of it (truth,
/// measurements, initial estimate), shared by all the rows timed on it.
#[derive(Debug, Clone)]
pub struct Workload {
    /// The scenario (its topology decides the network's weights).
    pub scenario: Scenario,
    /// The simulated measurements and initial estimate.
    pub sim: Simulation,
}

impl Workload {
    /// The default ("paper") scenario with `nodes` nodes on a ring, simulated with `seed`.
    pub fn paper(nodes: usize, seed: u64) -> Result<Self> {
        Self::new(Scenario::paper(nodes), seed)
    }

    /// The default scenario with another topology.
    pub fn with_topology(nodes: usize, topology: Topology, seed: u64) -> Result<Self> {
        let mut sc = Scenario::paper(nodes);
        sc.topology = topology;
        Self::new(sc, seed)
    }

    /// Simulates `scenario` with `seed`.
    pub fn new(scenario: Scenario, seed: u64) -> Result<Self> {
        scenario.validate()?;
        let sim = simulate(&scenario, seed)?;
        Ok(Self { scenario, sim })
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.sim.nodes
    }

    /// Number of steps `T` of a whole run.
    pub fn steps(&self) -> usize {
        self.sim.steps
    }

    /// The measurements of step `t` (0-based), row-major `(nodes, 3)`.
    pub fn z_at(&self, t: usize) -> &[f64] {
        let k = self.nodes() * M;
        &self.sim.z[t * k..(t + 1) * k]
    }

    /// A fresh network of `alg` at the start of the run (default run options).
    pub fn network(&self, alg: Algorithm) -> Result<AnyNetwork> {
        self.network_row(Row::new(alg))
    }

    /// A fresh network of `row` at the start of the run.
    pub fn network_row(&self, row: Row) -> Result<AnyNetwork> {
        AnyNetwork::new(row.alg, &self.scenario, &self.sim.x0_hat, &row.options())
    }

    /// The consensus iterations `L` a network of `row` runs: the fixed one, or
    /// the scenario's adequate one.
    pub fn iterations(&self, row: Row) -> Result<usize> {
        match row.iters {
            Some(l) => Ok(l),
            None => self.scenario.consensus_iterations(),
        }
    }
}

/// Steps `net` through the workload's steps `steps`, discarding the reports.
/// Never inlined, so that callgrind can collect exactly the timed steps
/// (`--toggle-collect=edccif_bench::run_steps`).
#[inline(never)]
pub fn run_steps(net: &mut AnyNetwork, w: &Workload, steps: Range<usize>) -> Result<()> {
    for t in steps {
        black_box(net.step(black_box(w.z_at(t)))?);
    }
    Ok(())
}

/// A connection radius for [`Topology::RandomGeometric`] in the unit square that
/// gives connected graphs with high probability: `1.5·sqrt(2 ln N / N)`, capped
/// at 1 (about 2.5 times the connectivity threshold `sqrt(ln N / (π N))`).
///
/// ```
/// let r = edccif_bench::rgg_radius(64);
/// assert!(r > 0.5 && r < 0.6);
/// assert_eq!(edccif_bench::rgg_radius(2), 1.0);
/// ```
pub fn rgg_radius(nodes: usize) -> f64 {
    let n = nodes.max(2) as f64;
    (1.5 * (2.0 * n.ln() / n).sqrt()).min(1.0)
}

/// The time of one run on both clocks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunTime {
    /// Wall-clock time.
    pub wall: Duration,
    /// CPU time of the calling thread.
    pub cpu: Duration,
}

/// Time of one whole run: a fresh network of `alg` stepped through all of the
/// workload's measurements. Only the stepping loop is timed.
pub fn time_run(alg: Algorithm, w: &Workload) -> Result<RunTime> {
    time_run_row(Row::new(alg), w, w.steps())
}

/// Time of the first `steps` steps of a fresh network of `row` (`steps` capped
/// at the run's length). Only the stepping loop ([`run_steps`]) is timed.
pub fn time_run_row(row: Row, w: &Workload, steps: usize) -> Result<RunTime> {
    let mut net = w.network_row(row)?;
    let steps = steps.min(w.steps());
    let c0 = ThreadTime::now();
    let t0 = Instant::now();
    run_steps(&mut net, w, 0..steps)?;
    let wall = t0.elapsed();
    Ok(RunTime {
        wall,
        cpu: c0.elapsed(),
    })
}

/// Position RMSE (m) of a whole run of `row`: the root of the mean of the
/// squared position-error norms over every node and step (untimed).
pub fn position_rmse(row: Row, w: &Workload) -> Result<f64> {
    let r = edccif_sim::run(
        row.alg,
        &w.scenario,
        &w.sim.z,
        &w.sim.x0_hat,
        &row.options(),
        false,
    )?;
    let e = edccif_sim::metrics::run_errors(&r, &w.sim.truth, w.scenario.position_dim());
    Ok((e.pos_sq.iter().sum::<f64>() / e.pos_sq.len() as f64).sqrt())
}

/// Fraction of node-steps with a measurement whose sensor sent (γ = 1) over a
/// whole run of `alg` (untimed; for context beside the timings).
pub fn trigger_rate(alg: Algorithm, w: &Workload) -> Result<f64> {
    trigger_rate_row(Row::new(alg), w)
}

/// [`trigger_rate`] of a [`Row`].
pub fn trigger_rate_row(row: Row, w: &Workload) -> Result<f64> {
    let mut net = w.network_row(row)?;
    for t in 0..w.steps() {
        net.step(w.z_at(t))?;
    }
    let c = net.counters();
    Ok(if c.measured == 0 {
        0.0
    } else {
        c.triggered as f64 / c.measured as f64
    })
}

/// Total wall time of `iters` network steps of `alg`, for criterion's
/// `iter_custom`. The steps walk through the workload's run from its start;
/// when the run ends a fresh network restarts it (untimed), so every timed step
/// is a real step of the run, and the average covers the transient and the
/// steady state in the proportion of a whole run.
pub fn time_network_steps(alg: Algorithm, w: &Workload, iters: u64) -> Duration {
    let template = w.network(alg).expect("network of the workload");
    let steps = w.steps() as u64;
    let mut total = Duration::ZERO;
    let mut left = iters;
    while left > 0 {
        let mut net = template.clone();
        let n = left.min(steps);
        let t0 = Instant::now();
        for t in 0..n as usize {
            black_box(net.step(black_box(w.z_at(t))).expect("network step"));
        }
        total += t0.elapsed();
        left -= n;
    }
    total
}

/// The repeated timings of one case, in seconds per whole run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Samples {
    /// Wall-clock seconds, one per repetition.
    pub wall: Vec<f64>,
    /// Thread CPU seconds, one per repetition.
    pub cpu: Vec<f64>,
}

/// Times whole runs of every case `reps` times, interleaved: repetition `r` runs
/// all cases once, starting at case `r mod cases` and wrapping around. `warmup`
/// untimed passes over all cases come first. Returns one [`Samples`] per case.
pub fn interleaved_runs(
    cases: &[(Algorithm, &Workload)],
    reps: usize,
    warmup: usize,
) -> Result<Vec<Samples>> {
    let rows: Vec<(Row, &Workload)> = cases.iter().map(|(a, w)| (Row::new(*a), *w)).collect();
    interleaved_rows(&rows, reps, warmup, None)
}

/// [`interleaved_runs`] over [`Row`]s, each run cut to its first `steps` steps
/// (`None`: whole runs).
pub fn interleaved_rows(
    cases: &[(Row, &Workload)],
    reps: usize,
    warmup: usize,
    steps: Option<usize>,
) -> Result<Vec<Samples>> {
    let len = |w: &Workload| steps.unwrap_or(w.steps());
    for _ in 0..warmup {
        for (row, w) in cases {
            time_run_row(*row, w, len(w))?;
        }
    }
    let c = cases.len();
    let mut samples = vec![Samples::default(); c];
    for r in 0..reps {
        for s in 0..c {
            let i = (r + s) % c;
            let (row, w) = cases[i];
            let t = time_run_row(row, w, len(w))?;
            samples[i].wall.push(t.wall.as_secs_f64());
            samples[i].cpu.push(t.cpu.as_secs_f64());
        }
    }
    Ok(samples)
}

/// Order statistics of a sample: minimum, quartiles (linear interpolation
/// between order statistics), median, maximum.
///
/// ```
/// let s = edccif_bench::Spread::of(&[5.0, 1.0, 4.0, 2.0, 3.0]);
/// assert_eq!((s.min, s.q1, s.median, s.q3, s.max), (1.0, 2.0, 3.0, 4.0, 5.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// Smallest value.
    pub min: f64,
    /// First quartile.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
    /// Largest value.
    pub max: f64,
}

impl Spread {
    /// The spread of `xs` (all NaN when empty).
    pub fn of(xs: &[f64]) -> Self {
        if xs.is_empty() {
            return Self {
                min: f64::NAN,
                q1: f64::NAN,
                median: f64::NAN,
                q3: f64::NAN,
                max: f64::NAN,
            };
        }
        let mut v = xs.to_vec();
        v.sort_by(f64::total_cmp);
        let q = |p: f64| {
            let h = p * (v.len() - 1) as f64;
            let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
            v[lo] + (h - lo as f64) * (v[hi] - v[lo])
        };
        Self {
            min: v[0],
            q1: q(0.25),
            median: median(&v),
            q3: q(0.75),
            max: v[v.len() - 1],
        }
    }

    /// Every statistic multiplied by `k` (e.g. seconds to µs per step).
    pub fn scaled(&self, k: f64) -> Self {
        Self {
            min: self.min * k,
            q1: self.q1 * k,
            median: self.median * k,
            q3: self.q3 * k,
            max: self.max * k,
        }
    }

    /// `{"min", "q1", "median", "q3", "max"}`.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "min": self.min, "q1": self.q1, "median": self.median, "q3": self.q3, "max": self.max,
        })
    }
}

/// Median of a sample (mean of the two middle values for an even count; NaN
/// when empty).
///
/// ```
/// assert_eq!(edccif_bench::median(&[3.0, 1.0, 2.0]), 2.0);
/// assert_eq!(edccif_bench::median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
/// ```
pub fn median(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return f64::NAN;
    }
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Relative reduction `1 − ours/baseline` (e.g. 0.47 for 47 %).
///
/// ```
/// assert!((edccif_bench::reduction(1.32, 2.50) - 0.472).abs() < 1e-12);
/// ```
pub fn reduction(ours: f64, baseline: f64) -> f64 {
    1.0 - ours / baseline
}

/// Inputs of one node's local step on the default model (ALGORITHM.md §1, §6):
/// coordinated turn (dt 0.1, q1 0.5, q2 1e-4), the range/pitch/azimuth sensor at
/// (10, 0, 0) (σr 0.1, σa 0.01), and a realistic mid-run estimate and measurement
/// of node 0 of the 4-node default scenario, in the library's default
/// configuration ([`config::Config::library_default`]; [`LocalFixture::with_config`]
/// changes it).
#[derive(Debug, Clone, Copy)]
pub struct LocalFixture {
    /// Motion model.
    pub motion: CoordinatedTurn<f64>,
    /// Node 0's sensor.
    pub sensor: RangePitchAzimuth<f64>,
    /// Node 0's fused estimate after `warm` EDC-CIF steps.
    pub estimate: Gaussian<f64, 7>,
    /// `estimate` as checked once at the boundary (what a filter loop that
    /// chains [`cov_local_chained`] steps carries from step to step).
    pub checked: CheckedGaussian<f64, 7>,
    /// Node 0's measurement of the next step.
    pub z: Vector3<f64>,
    /// Send-on-delta trigger with the default `δ = 0.04`.
    pub sod: Trigger<f64>,
    /// Default ET options (`σ1 = σ2 = 5e-4`).
    pub et: EtOptions<f64>,
}

impl LocalFixture {
    /// Runs EDC-CIF on the 4-node default scenario (seed `seed`) for `warm` steps
    /// and takes node 0's estimate and next measurement.
    pub fn new(seed: u64, warm: usize) -> Result<Self> {
        let w = Workload::paper(4, seed)?;
        let warm = warm.min(w.steps() - 1);
        let mut net = w.network(Algorithm::EdcCif)?;
        for t in 0..warm {
            net.step(w.z_at(t))?;
        }
        let k = w.nodes();
        let mut x = vec![0.0; k * 7];
        let mut p = vec![0.0; k * 49];
        net.write_estimates(&mut x);
        net.write_covariances(&mut p);
        let estimate = Gaussian::new(
            SVector::<f64, 7>::from_column_slice(&x[..7]),
            SMatrix::<f64, 7, 7>::from_row_slice(&p[..49]),
        )?;
        let z = Vector3::from_column_slice(&w.z_at(warm)[..3]);
        let motion = w.scenario.coordinated_turn()?;
        let sensor = RangePitchAzimuth::new(w.scenario.sensors[0], 0.1, 0.01)?;
        Ok(Self {
            motion,
            sensor,
            checked: CheckedGaussian::new(&estimate)?,
            estimate,
            z,
            sod: Trigger::SendOnDelta {
                delta: w.scenario.delta.node(0),
            },
            et: EtOptions::default(),
        }
        .with_config(&config::Config::library_default()))
    }

    /// The same fixture with the models' opt-in fast trigonometry on or off
    /// (`CoordinatedTurn::with_fast_trig`, `RangePitchAzimuth::with_fast_trig`).
    #[must_use]
    pub fn with_fast_trig(mut self, on: bool) -> Self {
        self.motion = self.motion.with_fast_trig(on);
        self.sensor = self.sensor.with_fast_trig(on);
        self
    }

    /// The same fixture with the ET-CIF's untriggered contribution in closed
    /// form on or off ([`EtOptions::untriggered_closed_form`]).
    #[must_use]
    pub fn with_closed_form(mut self, on: bool) -> Self {
        self.et.untriggered_closed_form = on;
        self
    }

    /// The same fixture in the configuration `config` (trigonometry and
    /// untriggered form).
    #[must_use]
    pub fn with_config(self, config: &config::Config) -> Self {
        self.with_fast_trig(config.fast_trig)
            .with_closed_form(config.closed_form)
    }

    /// A trigger state under which `z` is sent (γ = 1): the last sent
    /// measurement is 1 m of range away.
    pub fn state_triggering(&self) -> TriggerState<f64, 3> {
        TriggerState {
            last_sent: Some(self.z + Vector3::new(1.0, 0.0, 0.0)),
            eta: self.sod.delta(),
            rng: 0,
        }
    }

    /// A trigger state under which `z` is not sent (γ = 0): it was sent last.
    pub fn state_quiet(&self) -> TriggerState<f64, 3> {
        TriggerState {
            last_sent: Some(self.z),
            eta: self.sod.delta(),
            rng: 0,
        }
    }

    /// One local step of `case` on the fixture's inputs; returns `Some(γ)`.
    /// Never inlined, so that a profiler can attribute its cost
    /// (`--toggle-collect=*LocalFixture::step`).
    #[inline(never)]
    pub fn step(&self, case: &LocalCase) -> Result<Option<bool>> {
        let always = Trigger::Always;
        let (trigger, state) = match case.trigger {
            TriggerCase::Always => (always, TriggerState::new(&always)),
            TriggerCase::SodSent => (self.sod, self.state_triggering()),
            TriggerCase::SodQuiet => (self.sod, self.state_quiet()),
        };
        let obs = Observation::Measured(self.z);
        Ok(match case.filter {
            LocalKind::Cif => {
                cif_local(
                    &self.motion,
                    0.1,
                    &self.sensor,
                    black_box(&self.estimate),
                    black_box(&obs),
                    &trigger,
                    &state,
                    &self.et,
                )?
                .triggered
            }
            LocalKind::Cov(f) => {
                cov_local(
                    &f,
                    &self.motion,
                    0.1,
                    &self.sensor,
                    black_box(&self.estimate),
                    black_box(&obs),
                    &trigger,
                    &state,
                    &self.et,
                )?
                .triggered
            }
            LocalKind::CovChained(f) => {
                cov_local_chained(
                    &f,
                    &self.motion,
                    0.1,
                    &self.sensor,
                    black_box(&self.checked),
                    black_box(&obs),
                    &trigger,
                    &state,
                    &self.et,
                )?
                .0
                .triggered
            }
        })
    }
}

/// Which local filter a [`LocalCase`] runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LocalKind {
    /// `cif_local`: the (ET-)CIF of the diffusion rows.
    Cif,
    /// `cov_local` with a covariance-form filter (CKF, EKF, UKF).
    Cov(LocalFilter<f64>),
    /// `cov_local_chained` with a covariance-form filter: the step of a filter
    /// loop whose estimate is the previous step's posterior, checked once.
    CovChained(LocalFilter<f64>),
}

/// The trigger situation of a [`LocalCase`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriggerCase {
    /// No trigger: every measurement is used (the plain filter).
    Always,
    /// Send-on-delta, and the measurement is sent (γ = 1).
    SodSent,
    /// Send-on-delta, and the measurement is not sent (γ = 0): the
    /// error-minimised update.
    SodQuiet,
}

/// One node's local step: a filter in a trigger situation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalCase {
    /// Short name, e.g. `"cif/sod-quiet"` (also the criterion benchmark id).
    pub name: &'static str,
    /// What it is, e.g. `"ET-CIF, not sent"`.
    pub label: &'static str,
    /// The filter.
    pub filter: LocalKind,
    /// The trigger situation.
    pub trigger: TriggerCase,
}

/// The local-step matrix: CIF, ET-CIF sent / not sent, CKF, ET-CKF not sent,
/// EKF, EKF chained (its estimate the checked posterior of the step before),
/// ET-EKF not sent, UKF (1, 2, 0), ET-UKF not sent.
pub fn local_cases() -> [LocalCase; 10] {
    use LocalKind::{Cif, Cov, CovChained};
    use TriggerCase::{Always, SodQuiet, SodSent};
    let ukf = LocalFilter::ukf_default();
    let case = |name, label, filter, trigger| LocalCase {
        name,
        label,
        filter,
        trigger,
    };
    [
        case("cif/always", "CIF", Cif, Always),
        case("cif/sod-sent", "ET-CIF, sent", Cif, SodSent),
        case("cif/sod-quiet", "ET-CIF, not sent", Cif, SodQuiet),
        case("ckf/always", "CKF", Cov(LocalFilter::Ckf), Always),
        case(
            "ckf/sod-quiet",
            "ET-CKF, not sent",
            Cov(LocalFilter::Ckf),
            SodQuiet,
        ),
        case("ekf/always", "EKF", Cov(LocalFilter::Ekf), Always),
        case(
            "ekf/chained",
            "EKF, chained",
            CovChained(LocalFilter::Ekf),
            Always,
        ),
        case(
            "ekf/sod-quiet",
            "ET-EKF, not sent",
            Cov(LocalFilter::Ekf),
            SodQuiet,
        ),
        case("ukf/always", "UKF (1, 2, 0)", Cov(ukf), Always),
        case("ukf/sod-quiet", "ET-UKF, not sent", Cov(ukf), SodQuiet),
    ]
}

/// Median µs per local step of each of `cases` (e.g. [`local_cases`]) on the
/// fixture: `rounds` rounds, each timing a batch of `per_batch` steps of every
/// case in turn (rotating the first case), after one warm-up round.
pub fn local_step_times(
    f: &LocalFixture,
    cases: &[LocalCase],
    rounds: usize,
    per_batch: usize,
) -> Result<Vec<(LocalCase, StepTime)>> {
    let c = cases.len();
    let mut wall = vec![Vec::with_capacity(rounds); c];
    let mut cpu = vec![Vec::with_capacity(rounds); c];
    for r in 0..=rounds {
        for s in 0..c {
            let i = (r + s) % c;
            let c0 = ThreadTime::now();
            let t0 = Instant::now();
            for _ in 0..per_batch {
                black_box(f.step(&cases[i])?);
            }
            let (tw, tc) = (t0.elapsed(), c0.elapsed());
            if r > 0 {
                wall[i].push(tw.as_secs_f64() * 1e6 / per_batch as f64);
                cpu[i].push(tc.as_secs_f64() * 1e6 / per_batch as f64);
            }
        }
    }
    Ok(cases
        .iter()
        .enumerate()
        .map(|(i, case)| {
            (
                *case,
                StepTime {
                    wall_us: median(&wall[i]),
                    cpu_us: median(&cpu[i]),
                },
            )
        })
        .collect())
}

/// Median microseconds per step on both clocks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepTime {
    /// Wall-clock µs per step.
    pub wall_us: f64,
    /// Thread-CPU µs per step.
    pub cpu_us: f64,
}

fn batch_medians(
    batches: usize,
    steps_per_batch: usize,
    mut batch: impl FnMut() -> Result<()>,
) -> Result<StepTime> {
    let mut wall = Vec::with_capacity(batches);
    let mut cpu = Vec::with_capacity(batches);
    batch()?; // warm-up
    for _ in 0..batches {
        let c0 = ThreadTime::now();
        let t0 = Instant::now();
        batch()?;
        wall.push(t0.elapsed().as_secs_f64() * 1e6 / steps_per_batch as f64);
        cpu.push(c0.elapsed().as_secs_f64() * 1e6 / steps_per_batch as f64);
    }
    Ok(StepTime {
        wall_us: median(&wall),
        cpu_us: median(&cpu),
    })
}

/// Microseconds per CKF predict + update step (`cov_local` with
/// [`LocalFilter::Ckf`] and [`Trigger::Always`]) of a single node on the default
/// model, filtering the measurements of sensor 0 of a 1-node default scenario
/// (seed `seed`) and restarting from the initial estimate at the end of the run.
/// Returns the medians over `batches` batches of `steps_per_batch` steps each,
/// in the configuration `config`.
pub fn ckf_step_us(
    seed: u64,
    batches: usize,
    steps_per_batch: usize,
    config: &config::Config,
) -> Result<StepTime> {
    let mut w = Workload::paper(1, seed)?;
    config.apply(&mut w.scenario);
    let motion = w.scenario.coordinated_turn()?;
    let sensor =
        RangePitchAzimuth::new(w.scenario.sensors[0], 0.1, 0.01)?.with_fast_trig(config.fast_trig);
    let p0 = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::from_column_slice(&w.scenario.p0_diag));
    let start = Gaussian::new(SVector::<f64, 7>::from_column_slice(&w.sim.x0_hat), p0)?;
    let trigger = Trigger::Always;
    let ts = TriggerState::new(&trigger);
    let et = EtOptions::default();
    let obs: Vec<Observation<f64, 3>> = (0..w.steps())
        .map(|t| Observation::Measured(Vector3::from_column_slice(w.z_at(t))))
        .collect();
    let mut est = start;
    let mut t = 0;
    batch_medians(batches, steps_per_batch, || {
        for _ in 0..steps_per_batch {
            let r = cov_local(
                &LocalFilter::Ckf,
                &motion,
                0.1,
                &sensor,
                black_box(&est),
                black_box(&obs[t]),
                &trigger,
                &ts,
                &et,
            )?;
            est = r.posterior;
            t += 1;
            if t == obs.len() {
                t = 0;
                est = start;
            }
        }
        Ok(())
    })
}

/// Microseconds per step of a 1-node C-CKF network through
/// [`AnyNetwork::step`] (CKF plus one trivial consensus iteration and the
/// information/covariance conversions): the Rust counterpart of stepping
/// `edccif.Network(Scenario.paper(nodes=1), algorithm="c-ckf")` from Python,
/// in the configuration `config`.
pub fn network1_ckf_step_us(
    seed: u64,
    batches: usize,
    steps_per_batch: usize,
    config: &config::Config,
) -> Result<StepTime> {
    let mut w = Workload::paper(1, seed)?;
    config.apply(&mut w.scenario);
    let template = w.network(Algorithm::CCkf)?;
    let mut net = template.clone();
    let mut t = 0;
    batch_medians(batches, steps_per_batch, || {
        for _ in 0..steps_per_batch {
            black_box(net.step(black_box(w.z_at(t)))?);
            t += 1;
            if t == w.steps() {
                t = 0;
                net.clone_from(&template);
            }
        }
        Ok(())
    })
}
