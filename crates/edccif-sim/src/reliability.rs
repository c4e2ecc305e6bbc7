//! The reliability study behind `docs/reliability.md`: Monte Carlo accuracy and
//! health checks under injected [`faults`](crate::faults), and a long soak run.
//!
//! Health checks run at **every** step on every node's fused estimate: values
//! finite, covariance exactly symmetric and positive definite (Cholesky). The
//! accuracy metrics are taken over the node-steps of nodes that are up:
//! position RMSE `sqrt(mean ‖p̂ − p‖²)` and average NEES `eᵀ P⁻¹ e` (n = 7 for a
//! consistent filter).

use std::time::{Duration, Instant};

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::control::Control;
use crate::error::{Error, Result};
use crate::faults::{FaultInjector, Faults, Window};
use crate::runner::{AnyNetwork, Counters, M};
use crate::scenario::Scenario;
use crate::simulate::simulate;
use crate::{Algorithm, RunOptions};

/// χ²(3) 0.999 quantile: the default innovation gate for a 3-D measurement.
pub const GATE_CHI2_3_999: f64 = 16.27;

/// One fault condition of the study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Condition {
    /// Label shown in the table.
    pub label: String,
    /// Faults (their seed is replaced per run).
    pub faults: Faults,
    /// Innovation gate.
    pub gate: Option<f64>,
}

/// The study's conditions for a run of `steps` steps: message loss 0/10/30/50 %,
/// node 1 down for the middle third, a 2-s (20-step) outage of node 0's sensor
/// from the middle of the run, 5 % outliers without and with the gate.
pub fn standard_conditions(steps: usize, dt: f64) -> Vec<Condition> {
    let mut v: Vec<Condition> = [0.0, 0.1, 0.3, 0.5]
        .iter()
        .map(|&p| Condition {
            label: format!("message loss {:.0} %", 100.0 * p),
            faults: Faults {
                message_loss: p,
                ..Faults::default()
            },
            gate: None,
        })
        .collect();
    v.push(Condition {
        label: format!("node 1 down steps {}..{}", steps / 3, 2 * steps / 3),
        faults: Faults {
            dropout: vec![Window {
                node: 1,
                start: steps / 3,
                end: 2 * steps / 3,
            }],
            ..Faults::default()
        },
        gate: None,
    });
    let len = (2.0 / dt).round() as usize;
    v.push(Condition {
        label: format!("node 0 sensor out steps {}..{}", steps / 2, steps / 2 + len),
        faults: Faults {
            outage: vec![Window {
                node: 0,
                start: steps / 2,
                end: steps / 2 + len,
            }],
            ..Faults::default()
        },
        gate: None,
    });
    for gate in [None, Some(GATE_CHI2_3_999)] {
        v.push(Condition {
            label: if gate.is_some() {
                "5 % outliers (20σ), gate 16.27".into()
            } else {
                "5 % outliers (20σ), no gate".into()
            },
            faults: Faults {
                outlier_prob: 0.05,
                ..Faults::default()
            },
            gate,
        });
    }
    v
}

/// Health and accuracy sums over node-steps.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Health {
    /// Node-steps checked (all nodes, up or down).
    pub node_steps: u64,
    /// Non-finite values in fused estimates or covariances.
    pub nan: u64,
    /// Fused covariances that are not exactly symmetric.
    pub asymmetric: u64,
    /// Fused covariances whose Cholesky factorisation fails.
    pub not_pd: u64,
    /// Node-steps of nodes that were up (the accuracy terms).
    pub active_node_steps: u64,
    /// Sum of squared position errors over active node-steps.
    pub pos_sq_sum: f64,
    /// Largest position error seen on an active node (m).
    pub max_pos_err: f64,
    /// Sum of NEES over active node-steps.
    pub nees_sum: f64,
    /// Active node-steps whose NEES is inside the two-sided 99 % χ²(n) interval.
    pub nees_in_band: u64,
    /// Runner counters (summed).
    pub counters: Counters,
    /// Outliers injected.
    pub outliers: u64,
    /// Directed neighbour messages lost (link-steps).
    pub lost_links: u64,
    /// Rejoins performed.
    pub rejoins: u64,
}

impl Health {
    fn add(&mut self, o: &Health) {
        self.node_steps += o.node_steps;
        self.nan += o.nan;
        self.asymmetric += o.asymmetric;
        self.not_pd += o.not_pd;
        self.active_node_steps += o.active_node_steps;
        self.pos_sq_sum += o.pos_sq_sum;
        self.max_pos_err = self.max_pos_err.max(o.max_pos_err);
        self.nees_sum += o.nees_sum;
        self.nees_in_band += o.nees_in_band;
        let (c, d) = (&mut self.counters, &o.counters);
        c.steps += d.steps;
        c.measured += d.measured;
        c.triggered += d.triggered;
        c.guard_fallbacks += d.guard_fallbacks;
        c.gated += d.gated;
        c.values_sensor_to_estimator += d.values_sensor_to_estimator;
        c.values_estimator_to_estimator += d.values_estimator_to_estimator;
        c.values_estimator_to_sensor += d.values_estimator_to_sensor;
        self.outliers += o.outliers;
        self.lost_links += o.lost_links;
        self.rejoins += o.rejoins;
    }

    /// Position RMSE over active node-steps.
    pub fn pos_rmse(&self) -> f64 {
        (self.pos_sq_sum / self.active_node_steps.max(1) as f64).sqrt()
    }

    /// Average NEES over active node-steps.
    pub fn nees(&self) -> f64 {
        self.nees_sum / self.active_node_steps.max(1) as f64
    }

    /// Fraction of active node-steps with NEES in the 99 % band.
    pub fn nees_in_band_fraction(&self) -> f64 {
        self.nees_in_band as f64 / self.active_node_steps.max(1) as f64
    }

    /// Whether every health check passed (no NaN, all covariances symmetric PD).
    pub fn healthy(&self) -> bool {
        self.nan == 0 && self.asymmetric == 0 && self.not_pd == 0
    }
}

/// Two-sided 99 % interval of χ²(n) for n = 6, 7.
fn nees_band(n: usize) -> (f64, f64) {
    if n == 6 {
        (0.6757, 18.548)
    } else {
        (0.9893, 20.278)
    }
}

/// Reusable buffers for [`check_step`].
struct Checker {
    est: Vec<f64>,
    cov: Vec<f64>,
}

impl Checker {
    fn new(k: usize, n: usize) -> Self {
        Self {
            est: vec![0.0; k * n],
            cov: vec![0.0; k * n * n],
        }
    }

    /// Checks every node's fused estimate after a step against the truth `x`.
    #[allow(clippy::needless_range_loop)] // `i` indexes three buffers
    fn check_step(&mut self, net: &AnyNetwork, x: &[f64], active: &[bool], h: &mut Health) {
        let (k, n) = (net.nodes(), net.state_dim());
        net.write_estimates(&mut self.est);
        net.write_covariances(&mut self.cov);
        let band = nees_band(n);
        for i in 0..k {
            h.node_steps += 1;
            let e = &self.est[i * n..(i + 1) * n];
            let p = &self.cov[i * n * n..(i + 1) * n * n];
            let bad = e.iter().chain(p).filter(|v| !v.is_finite()).count() as u64;
            h.nan += bad;
            if bad > 0 {
                h.not_pd += 1;
                continue;
            }
            let sym = (0..n).all(|r| (0..r).all(|c| p[r * n + c] == p[c * n + r]));
            h.asymmetric += u64::from(!sym);
            let pm = DMatrix::from_row_slice(n, n, p);
            let Some(ch) = pm.cholesky() else {
                h.not_pd += 1;
                continue;
            };
            if !active[i] {
                continue;
            }
            let err = DVector::from_iterator(n, e.iter().zip(x).map(|(a, b)| a - b));
            let pos_sq = err.rows(0, 3).norm_squared();
            let nees = err.dot(&ch.solve(&err));
            h.active_node_steps += 1;
            h.pos_sq_sum += pos_sq;
            h.max_pos_err = h.max_pos_err.max(pos_sq.sqrt());
            h.nees_sum += nees;
            h.nees_in_band += u64::from(nees >= band.0 && nees <= band.1);
        }
    }
}

/// One run of `alg` on one seeded simulation with faults, checked at every step.
pub fn checked_run(
    alg: Algorithm,
    sc: &Scenario,
    cond: &Condition,
    seed: u64,
    fault_seed: u64,
) -> Result<Health> {
    checked_run_with(alg, sc, cond, seed, fault_seed, Control::none())
}

/// [`checked_run`] under a [`Control`], checked at every step.
pub fn checked_run_with(
    alg: Algorithm,
    sc: &Scenario,
    cond: &Condition,
    seed: u64,
    fault_seed: u64,
    ctl: &Control,
) -> Result<Health> {
    let sim = simulate(sc, seed)?;
    let opt = RunOptions {
        gate: cond.gate,
        ..RunOptions::default()
    };
    let mut net = AnyNetwork::new(alg, sc, &sim.x0_hat, &opt)?;
    let faults = Faults {
        seed: fault_seed,
        ..cond.faults.clone()
    };
    let mut inj = FaultInjector::new(&faults, sc)?;
    let (k, n) = (net.nodes(), net.state_dim());
    let mut chk = Checker::new(k, n);
    let mut h = Health::default();
    let mut zt = vec![0.0; k * M];
    for t in 0..sim.steps {
        ctl.check()?;
        zt.copy_from_slice(&sim.z[t * k * M..(t + 1) * k * M]);
        inj.prepare(t, &mut zt, &mut net)?;
        net.step_with_mask(&zt, Some(inj.mask()), Some(&inj.active))
            .map_err(|e| Error::Value {
                what: format!("{alg} {} (seed {seed}) at step {t}", cond.label),
                problem: e.to_string(),
            })?;
        chk.check_step(&net, &sim.truth[t * n..(t + 1) * n], &inj.active, &mut h);
    }
    h.counters = net.counters();
    h.outliers = inj.outliers;
    h.lost_links = inj.lost_links;
    h.rejoins = inj.rejoins;
    Ok(h)
}

/// Settings of the robustness study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobustnessSettings {
    /// Node counts (default scenario of each).
    pub nodes: Vec<usize>,
    /// Rows to compare.
    pub algorithms: Vec<Algorithm>,
    /// Monte Carlo runs per configuration.
    pub runs: usize,
    /// Simulation seed of run 0 (run r: `seed + r`; its faults: `seed + r + 1e6`).
    pub seed: u64,
}

impl Default for RobustnessSettings {
    fn default() -> Self {
        Self {
            nodes: vec![4, 8],
            algorithms: vec![Algorithm::EdcCif, Algorithm::EcCkf],
            runs: 50,
            seed: 0,
        }
    }
}

/// One row of the robustness table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobustnessRow {
    /// Nodes.
    pub nodes: usize,
    /// Row.
    pub algorithm: Algorithm,
    /// Condition label.
    pub condition: String,
    /// Runs.
    pub runs: usize,
    /// Sums over all runs.
    pub health: Health,
}

/// Runs every (nodes, algorithm, condition) over `runs` seeded simulations, in
/// parallel; deterministic (per-run results are summed in run order).
pub fn robustness(s: &RobustnessSettings) -> Result<Vec<RobustnessRow>> {
    robustness_with(s, Control::none())
}

/// [`robustness`] under a [`Control`]: every run checks it at every step; the
/// progress counts runs.
pub fn robustness_with(s: &RobustnessSettings, ctl: &Control) -> Result<Vec<RobustnessRow>> {
    robustness_with_progress(s, |_, _| {}, ctl)
}

/// [`robustness_with`], calling `progress(done, total)` after each (nodes,
/// algorithm, condition) configuration.
pub fn robustness_with_progress(
    s: &RobustnessSettings,
    mut progress: impl FnMut(usize, usize),
    ctl: &Control,
) -> Result<Vec<RobustnessRow>> {
    let conditions = standard_conditions(1, 1.0).len() as u64;
    ctl.add_total(
        (s.nodes.len() as u64)
            .saturating_mul(s.algorithms.len() as u64)
            .saturating_mul(conditions)
            .saturating_mul(s.runs as u64),
    );
    let total: usize = s
        .nodes
        .iter()
        .map(|&k| {
            let sc = Scenario::paper(k);
            standard_conditions(sc.steps, sc.dt).len() * s.algorithms.len()
        })
        .sum();
    let mut rows = Vec::new();
    for &k in &s.nodes {
        let sc = Scenario::paper(k);
        let conds = standard_conditions(sc.steps, sc.dt);
        for &alg in &s.algorithms {
            for cond in &conds {
                let per_run: Vec<Result<Health>> = (0..s.runs)
                    .into_par_iter()
                    .map(|r| {
                        let seed = s.seed.wrapping_add(r as u64);
                        let h = checked_run_with(
                            alg,
                            &sc,
                            cond,
                            seed,
                            seed.wrapping_add(1_000_000),
                            ctl,
                        );
                        ctl.advance(1);
                        h
                    })
                    .collect();
                let mut h = Health::default();
                for pr in per_run {
                    h.add(&pr?);
                }
                rows.push(RobustnessRow {
                    nodes: k,
                    algorithm: alg,
                    condition: cond.label.clone(),
                    runs: s.runs,
                    health: h,
                });
                progress(rows.len(), total);
            }
        }
    }
    Ok(rows)
}

/// The robustness table in Markdown.
pub fn robustness_markdown(rows: &[RobustnessRow]) -> String {
    let mut s = String::from(
        "| nodes | algorithm | condition | pos RMSE (m) | NEES | NEES in 99 % band | NaN | not PD / asym. | guard fallbacks | gated | outliers | lost msgs | rejoins |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let h = &r.health;
        s += &format!(
            "| {} | {} | {} | {:.4} | {:.2} | {:.1} % | {} | {} / {} | {} | {} | {} | {} | {} |\n",
            r.nodes,
            r.algorithm.label(),
            r.condition,
            h.pos_rmse(),
            h.nees(),
            100.0 * h.nees_in_band_fraction(),
            h.nan,
            h.not_pd,
            h.asymmetric,
            h.counters.guard_fallbacks,
            h.counters.gated,
            h.outliers,
            h.lost_links,
            h.rejoins,
        );
    }
    s
}

/// Settings of the soak run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SoakSettings {
    /// Nodes of the default scenario.
    pub nodes: usize,
    /// Total steps.
    pub steps: u64,
    /// Row.
    pub algorithm: Algorithm,
    /// Message-loss probability.
    pub message_loss: f64,
    /// Outlier probability.
    pub outlier_prob: f64,
    /// Innovation gate.
    pub gate: Option<f64>,
    /// Seed.
    pub seed: u64,
}

impl Default for SoakSettings {
    fn default() -> Self {
        Self {
            nodes: 8,
            steps: 1_000_000,
            algorithm: Algorithm::EdcCif,
            message_loss: 0.1,
            outlier_prob: 0.05,
            gate: Some(GATE_CHI2_3_999),
            seed: 0,
        }
    }
}

/// Results of the soak run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SoakResult {
    /// Settings used.
    pub settings: SoakSettings,
    /// Steps taken.
    pub steps: u64,
    /// Episodes (scenario runs of `T` steps) the measurement stream was made of.
    pub episodes: u64,
    /// Wall time (s).
    pub elapsed_s: f64,
    /// VmRSS (kB) before building the network.
    pub rss_start_kb: u64,
    /// VmRSS (kB) after the first episode.
    pub rss_first_episode_kb: u64,
    /// VmRSS (kB) at the end.
    pub rss_end_kb: u64,
    /// Health sums.
    pub health: Health,
    /// Largest per-episode average NEES.
    pub max_episode_nees: f64,
    /// Smallest per-episode average NEES.
    pub min_episode_nees: f64,
}

/// VmRSS of this process in kB (0 when `/proc/self/status` is unavailable).
pub fn vm_rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

/// The soak run: one network, built once, runs `steps` steps of the default
/// scenario with message loss and outliers. The measurement stream is simulated
/// on the fly, one scenario run (`T` = 200 steps) at a time, so memory holds one
/// episode only. The target model is a random walk that leaves the sensor field
/// within minutes, so at each episode start the truth is redrawn (seed
/// `seed + episode`) and every node is re-initialised with `reset_node` to that
/// episode's initial estimate; buffers, trigger memories, fault streams and
/// counters persist for the whole run. Every step is health-checked.
pub fn soak(s: &SoakSettings, progress: impl FnMut(u64)) -> Result<SoakResult> {
    soak_with(s, progress, Control::none())
}

/// [`soak`] under a [`Control`], checked at every step.
pub fn soak_with(
    s: &SoakSettings,
    mut progress: impl FnMut(u64),
    ctl: &Control,
) -> Result<SoakResult> {
    let rss_start_kb = vm_rss_kb();
    let sc = Scenario::paper(s.nodes);
    let opt = RunOptions {
        gate: s.gate,
        ..RunOptions::default()
    };
    let faults = Faults {
        seed: s.seed.wrapping_add(1_000_000),
        message_loss: s.message_loss,
        outlier_prob: s.outlier_prob,
        ..Faults::default()
    };
    let sim0 = simulate(&sc, s.seed)?;
    let mut net = AnyNetwork::new(s.algorithm, &sc, &sim0.x0_hat, &opt)?;
    let mut inj = FaultInjector::new(&faults, &sc)?;
    let (k, n) = (net.nodes(), net.state_dim());
    let mut p0 = vec![0.0; n * n];
    for (i, v) in sc.p0_diag.iter().enumerate() {
        p0[i * n + i] = *v;
    }
    let mut chk = Checker::new(k, n);
    let mut h = Health::default();
    let mut zt = vec![0.0; k * M];
    let t0 = Instant::now();
    let mut t: u64 = 0;
    let mut episode: u64 = 0;
    let mut rss_first_episode_kb = 0;
    let (mut max_ep, mut min_ep) = (0.0f64, f64::INFINITY);
    let mut sim = sim0;
    ctl.add_total(s.steps);
    while t < s.steps {
        if episode > 0 {
            sim = simulate(&sc, s.seed.wrapping_add(episode))?;
            for i in 0..k {
                net.reset_node(i, &sim.x0_hat, &p0)?;
            }
        }
        let mut he = Health::default();
        for step in 0..sim.steps {
            if t >= s.steps {
                break;
            }
            ctl.check()?;
            zt.copy_from_slice(&sim.z[step * k * M..(step + 1) * k * M]);
            inj.prepare(t as usize, &mut zt, &mut net)?;
            net.step_with_mask(&zt, Some(inj.mask()), Some(&inj.active))
                .map_err(|e| Error::Value {
                    what: format!("soak at step {t}"),
                    problem: e.to_string(),
                })?;
            chk.check_step(
                &net,
                &sim.truth[step * n..(step + 1) * n],
                &inj.active,
                &mut he,
            );
            t += 1;
            ctl.advance(1);
        }
        if he.active_node_steps > 0 {
            max_ep = max_ep.max(he.nees());
            min_ep = min_ep.min(he.nees());
        }
        h.add(&he);
        episode += 1;
        if episode == 1 {
            rss_first_episode_kb = vm_rss_kb();
        }
        progress(t);
    }
    h.counters = net.counters();
    h.outliers = inj.outliers;
    h.lost_links = inj.lost_links;
    h.rejoins = inj.rejoins;
    Ok(SoakResult {
        settings: s.clone(),
        steps: t,
        episodes: episode,
        elapsed_s: t0.elapsed().as_secs_f64(),
        rss_start_kb,
        rss_first_episode_kb,
        rss_end_kb: vm_rss_kb(),
        health: h,
        max_episode_nees: max_ep,
        min_episode_nees: min_ep,
    })
}

impl SoakResult {
    /// The soak results in Markdown.
    pub fn to_markdown(&self) -> String {
        let h = &self.health;
        let s = &self.settings;
        format!(
            "| quantity | value |\n|---|---|\n\
| configuration | {} on the {}-node default, message loss {:.0} %, outliers {:.0} % (20σ), gate {} |\n\
| steps (episodes of 200) | {} ({}) |\n\
| wall time | {:.1} s ({:.2} µs/step) |\n\
| node-steps checked | {} |\n\
| NaN values | {} |\n\
| covariances not PD / not exactly symmetric | {} / {} |\n\
| adaptation-guard fallbacks | {} |\n\
| gated (rejected) measurements / outliers injected | {} / {} |\n\
| lost neighbour messages (directed link-steps) | {} |\n\
| position RMSE / max position error | {:.4} m / {:.3} m |\n\
| average NEES (n = 7) | {:.3} |\n\
| per-episode average NEES, min … max | {:.2} … {:.2} |\n\
| node-steps with NEES in the 99 % χ²(7) interval [0.989, 20.28] | {:.2} % |\n\
| VmRSS start / after episode 1 / end | {} kB / {} kB / {} kB |\n",
            s.algorithm.label(),
            s.nodes,
            100.0 * s.message_loss,
            100.0 * s.outlier_prob,
            s.gate.map_or("none".into(), |g| format!("{g}")),
            self.steps,
            self.episodes,
            self.elapsed_s,
            1e6 * self.elapsed_s / self.steps.max(1) as f64,
            h.node_steps,
            h.nan,
            h.not_pd,
            h.asymmetric,
            h.counters.guard_fallbacks,
            h.counters.gated,
            h.outliers,
            h.lost_links,
            h.pos_rmse(),
            h.max_pos_err,
            h.nees(),
            self.min_episode_nees,
            self.max_episode_nees,
            100.0 * h.nees_in_band_fraction(),
            self.rss_start_kb,
            self.rss_first_episode_kb,
            self.rss_end_kb,
        )
    }
}

/// Replaces the text between `<!-- BEGIN {tag} -->` and `<!-- END {tag} -->` in
/// `doc` (appending the block when the markers are missing).
pub fn replace_block(doc: &str, tag: &str, body: &str) -> String {
    let begin = format!("<!-- BEGIN {tag} -->");
    let end = format!("<!-- END {tag} -->");
    let block = format!("{begin}\n{body}\n{end}");
    match (doc.find(&begin), doc.find(&end)) {
        (Some(a), Some(b)) if b > a => format!("{}{}{}", &doc[..a], block, &doc[b + end.len()..]),
        _ => format!("{doc}\n{block}\n"),
    }
}

/// What [`write_report`] runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReportSettings {
    /// The robustness study (`None`: keep the document's robustness block).
    pub robustness: Option<RobustnessSettings>,
    /// Soak steps (`None`: keep the document's soak block).
    pub soak_steps: Option<u64>,
    /// The Markdown document to update (created when missing).
    pub out: String,
    /// Also write the numbers as JSON here.
    pub json: Option<String>,
}

/// Runs the robustness study and/or the soak and updates their blocks in
/// `settings.out` (the rest of the document is kept); returns the Markdown of
/// what was measured. Used by the `edccif-reliability` binary and by
/// `edccif reliability` (Python).
pub fn write_report(settings: &ReportSettings, log: impl FnMut(&str)) -> Result<String> {
    write_report_with(settings, log, Control::none())
}

/// [`write_report`] under a [`Control`] (the robustness runs and the soak
/// check it at every step; a cancelled report writes nothing).
pub fn write_report_with(
    settings: &ReportSettings,
    mut log: impl FnMut(&str),
    ctl: &Control,
) -> Result<String> {
    let out = &settings.out;
    let mut doc = std::fs::read_to_string(out).unwrap_or_else(|_| "# Reliability\n".into());
    let mut report = serde_json::Map::new();
    let mut printed = String::new();
    if let Some(rs) = &settings.robustness {
        let t0 = Instant::now();
        let mut last = t0;
        // a line at most every 5 s (and the last), terminal or not
        let rows = robustness_with_progress(
            rs,
            |done, total| {
                if done == total || last.elapsed() >= Duration::from_secs(5) {
                    last = Instant::now();
                    log(&format!(
                        "robustness: {done}/{total} configurations, {:.0} s elapsed",
                        t0.elapsed().as_secs_f64()
                    ));
                }
            },
            ctl,
        )?;
        let md = robustness_markdown(&rows);
        let all_ok = rows.iter().all(|r| r.health.healthy());
        let body = format!(
            "Command: `cargo run --release -p edccif-sim --bin edccif-reliability -- --runs {} --seed {} --nodes {}` ({:.1} s).\n\n{md}\nAll health checks passed: **{}**.\n",
            rs.runs,
            rs.seed,
            rs.nodes.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(","),
            t0.elapsed().as_secs_f64(),
            if all_ok { "yes" } else { "NO" },
        );
        doc = replace_block(&doc, "robustness", &body);
        printed += &body;
        report.insert(
            "robustness".into(),
            serde_json::to_value(&rows).map_err(|e| Error::Io(e.to_string()))?,
        );
        if !all_ok {
            log("some health check failed");
        }
    }
    if let Some(steps) = settings.soak_steps {
        let ss = SoakSettings {
            steps,
            ..SoakSettings::default()
        };
        let mut next = steps / 10;
        let r = soak_with(
            &ss,
            |t| {
                if t >= next {
                    log(&format!("soak: {t}/{steps} steps"));
                    next += steps / 10;
                }
            },
            ctl,
        )?;
        let body = format!(
            "Command: `cargo run --release -p edccif-sim --bin edccif-reliability -- --no-robustness --soak {steps}`.\n\n{}",
            r.to_markdown()
        );
        doc = replace_block(&doc, "soak", &body);
        printed += &body;
        report.insert(
            "soak".into(),
            serde_json::to_value(&r).map_err(|e| Error::Io(e.to_string()))?,
        );
    }
    std::fs::write(out, doc).map_err(|e| Error::Io(format!("cannot write {out}: {e}")))?;
    log(&format!("wrote {out}"));
    if let Some(j) = &settings.json {
        let text = serde_json::to_string_pretty(&report).map_err(|e| Error::Io(e.to_string()))?;
        std::fs::write(j, text).map_err(|e| Error::Io(format!("cannot write {j}: {e}")))?;
        log(&format!("wrote {j}"));
    }
    Ok(printed)
}
