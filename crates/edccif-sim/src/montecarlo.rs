//! Monte Carlo over seeds, in parallel (rayon), deterministic regardless of the
//! number of threads: run `r` simulates with seed `seed + r`, every variant runs
//! on the same data, and per-run results are summed in run order.
//!
//! Threads: the runs execute on rayon's global pool (one run per worker, as many
//! workers as cores unless `RAYON_NUM_THREADS` or [`set_worker_threads`] says
//! otherwise), which keeps every
//! core busy once there are at least as many runs as cores. A variant's
//! [`RunOptions::threads`] additionally runs every network step of its runs on
//! the shared pool of that many threads
//! ([`shared_pool`](crate::parallel::shared_pool); one pool per count, not per
//! run). The results are the same bit for bit; it pays off only when there are
//! fewer runs than cores and the network is large (about 64 nodes and more).
//! With many runs it only adds threads competing for the same cores.

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::algorithm::{Algorithm, RunOptions};
use crate::control::Control;
use crate::error::{Error, Result};
use crate::faults::{run_controlled, Faults};
use crate::metrics::{run_errors, ErrorSummary, ErrorSums, RunErrors};
use crate::runner::Counters;
use crate::scenario::Scenario;

/// One configuration to evaluate: a row plus option overrides, with a label.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Variant {
    /// Label shown in tables.
    pub label: String,
    /// The row.
    pub algorithm: Algorithm,
    /// Overrides.
    pub options: RunOptions,
}

impl From<Algorithm> for Variant {
    fn from(a: Algorithm) -> Self {
        Variant {
            label: a.label().to_string(),
            algorithm: a,
            options: RunOptions::default(),
        }
    }
}

/// Monte Carlo settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct McSettings {
    /// Number of runs.
    pub runs: usize,
    /// Seed of run 0 (run r uses `seed + r`).
    pub seed: u64,
    /// Show a progress bar on stderr (when it is a terminal).
    pub progress: bool,
}

impl Default for McSettings {
    fn default() -> Self {
        Self {
            runs: 100,
            seed: 0,
            progress: false,
        }
    }
}

/// Results of one variant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VariantStats {
    /// Label.
    pub label: String,
    /// Row.
    pub algorithm: Algorithm,
    /// Overrides used.
    pub options: RunOptions,
    /// Accuracy.
    pub errors: ErrorSummary,
    /// Triggered / measured node-steps over all runs.
    pub trigger_rate: f64,
    /// Per-node trigger rate.
    pub trigger_rate_per_node: Vec<f64>,
    /// Mean floats sent per run, sensor → estimator.
    pub values_sensor_to_estimator: f64,
    /// Mean floats sent per run, estimator ↔ estimator.
    pub values_estimator_to_estimator: f64,
    /// Mean floats sent per run, estimator → sensor (the innovation trigger's
    /// prediction).
    #[serde(default)]
    pub values_estimator_to_sensor: f64,
    /// Adaptation-guard fallbacks over all runs.
    pub guard_fallbacks: u64,
    /// Median wall time of one whole run (s). Runs execute in parallel, so this is
    /// indicative; `edccif-timing` measures time properly.
    pub elapsed_median_s: f64,
}

/// Results of a Monte Carlo study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct McResult {
    /// Scenario name.
    pub scenario: String,
    /// Nodes.
    pub nodes: usize,
    /// Steps per run.
    pub steps: usize,
    /// Runs.
    pub runs: usize,
    /// Seed of run 0.
    pub seed: u64,
    /// One entry per variant, in the order given.
    pub variants: Vec<VariantStats>,
}

struct PerRun {
    errors: RunErrors,
    trig_node: Vec<u64>,
    meas_node: Vec<u64>,
    counters: Counters,
    elapsed: f64,
}

/// Sets the number of worker threads of the Monte Carlo runs (rayon's global
/// pool) to `n`: call it once, before the first Monte Carlo run or parallel
/// step of the process. The numbers do not depend on it (see the module
/// documentation); it bounds how many cores a long study occupies.
///
/// Errors: `n == 0`, `n` above [`max_threads`](crate::limits::max_threads)
/// (4 per core), or the pool already runs with a different size (it is
/// built on first use and cannot be resized afterwards). Asking again for the
/// size it already has is fine.
///
/// ```
/// use edccif_sim::montecarlo::{set_worker_threads, worker_threads};
/// assert!(set_worker_threads(0).unwrap_err().to_string().contains(">= 1"));
/// set_worker_threads(2).unwrap();
/// assert_eq!(worker_threads(), 2);
/// set_worker_threads(2).unwrap(); // the same size again: no error
/// let e = set_worker_threads(3).unwrap_err().to_string();
/// assert!(e.contains("already runs 2"), "{e}");
/// ```
pub fn set_worker_threads(n: usize) -> Result<()> {
    if n == 0 {
        return Err(Error::Value {
            what: "worker threads (jobs)".into(),
            problem: "must be >= 1".into(),
        });
    }
    crate::limits::check_threads_bound("worker threads (jobs)", n)?;
    match rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build_global()
    {
        Ok(()) => Ok(()),
        Err(_) if rayon::current_num_threads() == n => Ok(()),
        Err(_) => Err(Error::Value {
            what: "worker threads (jobs)".into(),
            problem: format!(
                "the worker pool already runs {} threads and cannot be resized; \
                 set {n} before the first Monte Carlo run of the process",
                rayon::current_num_threads()
            ),
        }),
    }
}

/// The number of worker threads of the Monte Carlo runs (rayon's global pool;
/// building it with its default size, one per core or `RAYON_NUM_THREADS`, if
/// it does not exist yet).
///
/// ```
/// assert!(edccif_sim::montecarlo::worker_threads() >= 1);
/// ```
pub fn worker_threads() -> usize {
    rayon::current_num_threads()
}

/// Runs every variant on `settings.runs` seeded simulations of the scenario.
///
/// ```
/// use edccif_sim::{monte_carlo, Algorithm, McSettings, Scenario};
/// let sc = Scenario { steps: 50, ..Scenario::paper(3) };
/// let r = monte_carlo(&sc, &[Algorithm::EdcCif.into(), Algorithm::EcCkf.into()],
///                     &McSettings { runs: 4, seed: 0, progress: false }).unwrap();
/// assert_eq!(r.variants.len(), 2);
/// assert!(r.variants[0].errors.pos_rmse < 1.0);
/// ```
pub fn monte_carlo(sc: &Scenario, variants: &[Variant], settings: &McSettings) -> Result<McResult> {
    monte_carlo_faults_with(sc, variants, settings, None, Control::none())
}

/// Bytes a Monte Carlo study holds at once: on each of `workers` threads one
/// simulation and one run with covariances of `steps × nodes` (state
/// dimension `n`), and per variant and run its wall time.
pub fn mc_bytes(
    steps: usize,
    nodes: usize,
    n: usize,
    runs: usize,
    variants: usize,
    workers: usize,
) -> u128 {
    use crate::limits::product;
    let sim = product(&[steps, n])
        .saturating_add(product(&[steps, nodes, 3]))
        .saturating_mul(8);
    let per_run = sim.saturating_add(crate::runner::run_bytes(steps, nodes, n, true, false));
    per_run
        .saturating_mul(workers as u128)
        .saturating_add(product(&[runs, variants, 8]))
}

/// [`monte_carlo`] under a [`Control`]: every run and step checks it, and the
/// progress counts runs × variants.
///
/// Cancelled, it returns the study of the runs `0..p` that had finished, the
/// same numbers as `monte_carlo` with `runs = p` (its `runs` says `p`), when
/// `p >= 1`, and [`Error::Interrupted`] when none had; [`Control::is_cancelled`]
/// tells a partial result from a whole one. What it would allocate is checked
/// first ([`mc_bytes`], [`limits::check_memory`](crate::limits::check_memory)).
///
/// ```
/// use edccif_sim::control::Control;
/// use edccif_sim::montecarlo::monte_carlo_with;
/// use edccif_sim::{Algorithm, McSettings, Scenario};
/// let sc = Scenario { steps: 20, ..Scenario::paper(3) };
/// let ctl = Control::new();
/// ctl.cancel();
/// let settings = McSettings { runs: 4, seed: 0, progress: false };
/// let e = monte_carlo_with(&sc, &[Algorithm::EdcCif.into()], &settings, &ctl).unwrap_err();
/// assert!(e.to_string().contains("interrupted"));
/// ```
pub fn monte_carlo_with(
    sc: &Scenario,
    variants: &[Variant],
    settings: &McSettings,
    ctl: &Control,
) -> Result<McResult> {
    monte_carlo_faults_with(sc, variants, settings, None, ctl)
}

/// [`monte_carlo`] with injected faults: every run goes through
/// [`run_with_faults`](crate::faults::run_with_faults), run `r` with the fault streams seeded `faults.seed + r`
/// (wrapping) and the simulation seeded `settings.seed + r`, so run `r` equals
/// `run_with_faults(.., &Faults { seed: faults.seed + r, ..faults })` on
/// `simulate(sc, settings.seed + r)` exactly.
///
/// ```
/// use edccif_sim::faults::Faults;
/// use edccif_sim::montecarlo::monte_carlo_with_faults;
/// use edccif_sim::{monte_carlo, Algorithm, McSettings, Scenario};
/// let sc = Scenario { steps: 30, ..Scenario::paper(4) };
/// let s = McSettings { runs: 2, seed: 0, progress: false };
/// let lossy = Faults { message_loss: 0.5, ..Faults::default() };
/// let a = monte_carlo_with_faults(&sc, &[Algorithm::EdcCif.into()], &s, &lossy).unwrap();
/// let b = monte_carlo(&sc, &[Algorithm::EdcCif.into()], &s).unwrap();
/// // lost messages: fewer floats between estimators
/// assert!(a.variants[0].values_estimator_to_estimator < b.variants[0].values_estimator_to_estimator);
/// ```
pub fn monte_carlo_with_faults(
    sc: &Scenario,
    variants: &[Variant],
    settings: &McSettings,
    faults: &Faults,
) -> Result<McResult> {
    monte_carlo_faults_with(sc, variants, settings, Some(faults), Control::none())
}

/// [`monte_carlo_with`] with optional faults ([`monte_carlo_with_faults`]).
pub fn monte_carlo_faults_with(
    sc: &Scenario,
    variants: &[Variant],
    settings: &McSettings,
    faults: Option<&Faults>,
    ctl: &Control,
) -> Result<McResult> {
    sc.validate()?;
    if let Some(f) = faults {
        f.validate(sc.nodes())?;
    }
    if settings.runs == 0 {
        return Err(Error::Value {
            what: "runs".into(),
            problem: "must be >= 1".into(),
        });
    }
    if variants.is_empty() {
        return Err(Error::Value {
            what: "algorithms".into(),
            problem: "at least one algorithm is needed".into(),
        });
    }
    // Fail fast on bad options before spending time.
    for v in variants {
        crate::algorithm::network_config(v.algorithm, sc, &v.options)?;
    }
    for (i, v) in variants.iter().enumerate() {
        if let Some(w) = variants[..i].iter().find(|w| w.label == v.label) {
            return Err(Error::Value {
                what: "algorithms".into(),
                problem: format!(
                    "two variants have the label {:?} ({} and {}); give each a label of its own",
                    v.label,
                    w.algorithm.name(),
                    v.algorithm.name()
                ),
            });
        }
    }
    let k = sc.nodes();
    let workers = rayon::current_num_threads().min(settings.runs).max(1);
    crate::limits::check_memory(
        || {
            format!(
                "a Monte Carlo study of runs = {} × {} variants (steps = {}, nodes = {k}; one simulation and run per worker thread, {workers} threads)",
                settings.runs,
                variants.len(),
                sc.steps
            )
        },
        mc_bytes(
            sc.steps,
            k,
            sc.state_dim(),
            settings.runs,
            variants.len(),
            workers,
        ),
    )?;
    ctl.add_total((settings.runs as u64).saturating_mul(variants.len() as u64));
    let bar = if settings.progress {
        let b = ProgressBar::new((settings.runs * variants.len()) as u64);
        b.set_style(
            ProgressStyle::with_template(
                "{prefix} [{bar:30}] {pos}/{len} runs·algorithms, {elapsed} elapsed, ETA {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        b.set_prefix(format!("{} ({k} nodes)", sc.name));
        b
    } else {
        ProgressBar::hidden()
    };
    let mut sums: Vec<ErrorSums> = vec![ErrorSums::default(); variants.len()];
    let mut trig = vec![vec![0u64; k]; variants.len()];
    let mut meas = vec![vec![0u64; k]; variants.len()];
    let mut totals = vec![Counters::default(); variants.len()];
    let mut elapsed = vec![Vec::new(); variants.len()];
    const CHUNK: usize = 32;
    let mut start = 0;
    // Runs 0..finished have been summed; a cancelled study stops there.
    let mut finished = 0;
    'chunks: while start < settings.runs {
        let end = (start + CHUNK).min(settings.runs);
        let chunk: Vec<Result<Vec<PerRun>>> = (start..end)
            .into_par_iter()
            .map(|r| {
                ctl.check()?;
                let seed = settings.seed.wrapping_add(r as u64);
                let sim = crate::simulate::simulate_inner(sc, seed, None, ctl, Control::none())?;
                // with faults, run r injects them with the fault seed `faults.seed + r`
                let run_faults = faults.map(|f| Faults {
                    seed: f.seed.wrapping_add(r as u64),
                    ..f.clone()
                });
                let out = variants
                    .iter()
                    .map(|v| {
                        // stochastic triggers: a stream per run (same seeds → same numbers)
                        let opt = RunOptions {
                            trigger_seed: v.options.trigger_seed.or(Some(seed)),
                            ..v.options.clone()
                        };
                        let res = run_controlled(
                            v.algorithm,
                            sc,
                            &sim.z,
                            &sim.x0_hat,
                            &opt,
                            run_faults.as_ref(),
                            None,
                            true,
                            ctl,
                            Control::none(),
                        )
                        .map_err(|e| match e {
                            Error::Interrupted => e,
                            e => Error::Value {
                                what: format!("{} (run {r}, seed {seed})", v.label),
                                problem: e.to_string(),
                            },
                        })?;
                        let mut trig_node = vec![0u64; k];
                        let mut meas_node = vec![0u64; k];
                        for t in 0..res.steps {
                            for i in 0..k {
                                trig_node[i] += u64::from(res.triggered[t * k + i]);
                                meas_node[i] += u64::from(res.measured[t * k + i]);
                            }
                        }
                        bar.inc(1);
                        ctl.advance(1);
                        Ok(PerRun {
                            errors: run_errors(&res, &sim.truth, sc.position_dim()),
                            trig_node,
                            meas_node,
                            counters: res.counters,
                            elapsed: res.elapsed_s,
                        })
                    })
                    .collect::<Result<Vec<_>>>()?;
                Ok(out)
            })
            .collect();
        for per_run in chunk {
            let per_run = match per_run {
                Ok(p) => p,
                Err(Error::Interrupted) => break 'chunks,
                Err(e) => return Err(e),
            };
            finished += 1;
            for (v, pr) in per_run.into_iter().enumerate() {
                sums[v].add(&pr.errors);
                for i in 0..k {
                    trig[v][i] += pr.trig_node[i];
                    meas[v][i] += pr.meas_node[i];
                }
                let t = &mut totals[v];
                t.triggered += pr.counters.triggered;
                t.measured += pr.counters.measured;
                t.guard_fallbacks += pr.counters.guard_fallbacks;
                t.gated += pr.counters.gated;
                t.values_sensor_to_estimator += pr.counters.values_sensor_to_estimator;
                t.values_estimator_to_estimator += pr.counters.values_estimator_to_estimator;
                t.values_estimator_to_sensor += pr.counters.values_estimator_to_sensor;
                elapsed[v].push(pr.elapsed);
            }
        }
        start = end;
    }
    bar.finish_and_clear();
    if finished == 0 {
        ctl.check()?;
    }
    let runs = finished as f64;
    let stats = variants
        .iter()
        .enumerate()
        .map(|(v, var)| {
            let t = totals[v];
            VariantStats {
                label: var.label.clone(),
                algorithm: var.algorithm,
                options: var.options.clone(),
                errors: sums[v].summary(),
                trigger_rate: if t.measured > 0 {
                    t.triggered as f64 / t.measured as f64
                } else {
                    0.0
                },
                trigger_rate_per_node: trig[v]
                    .iter()
                    .zip(&meas[v])
                    .map(|(a, b)| if *b > 0 { *a as f64 / *b as f64 } else { 0.0 })
                    .collect(),
                values_sensor_to_estimator: t.values_sensor_to_estimator as f64 / runs,
                values_estimator_to_estimator: t.values_estimator_to_estimator as f64 / runs,
                values_estimator_to_sensor: t.values_estimator_to_sensor as f64 / runs,
                guard_fallbacks: t.guard_fallbacks,
                elapsed_median_s: median(&mut elapsed[v]),
            }
        })
        .collect();
    Ok(McResult {
        scenario: sc.name.clone(),
        nodes: k,
        steps: sc.steps,
        runs: finished,
        seed: settings.seed,
        variants: stats,
    })
}

/// Median (sorts in place); 0 for an empty slice.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

impl McResult {
    /// A Markdown table: per-variable RMSE, position/velocity RMSE, trigger rate,
    /// NEES, guard fallbacks and median run time.
    pub fn to_markdown(&self) -> String {
        let n = self
            .variants
            .first()
            .map_or(0, |v| v.errors.rmse_per_variable.len());
        let names: &[&str] = if n == 7 {
            &["px", "py", "pz", "vx", "vy", "vz", "ω"]
        } else {
            &["px", "py", "pz", "vx", "vy", "vz"]
        };
        let mut s = format!(
            "{} — {} nodes, {} steps, {} runs, seeds {}..{}\n\n| algorithm | {} | pos RMSE (m) | vel RMSE (m/s) | trigger rate | NEES | guard | time/run (ms) |\n|---|{}---|---|---|---|---|---|\n",
            self.scenario,
            self.nodes,
            self.steps,
            self.runs,
            self.seed,
            self.seed + self.runs as u64 - 1,
            names.join(" | "),
            "---|".repeat(names.len())
        );
        for v in &self.variants {
            let vars: Vec<String> = v
                .errors
                .rmse_per_variable
                .iter()
                .map(|x| format!("{x:.4}"))
                .collect();
            s += &format!(
                "| {} | {} | {:.4} | {:.4} | {:.1} % | {} | {} | {:.3} |\n",
                v.label,
                vars.join(" | "),
                v.errors.pos_rmse,
                v.errors.vel_rmse,
                100.0 * v.trigger_rate,
                v.errors.nees.map_or("–".into(), |x| format!("{x:.2}")),
                v.guard_fallbacks,
                1e3 * v.elapsed_median_s
            );
        }
        s
    }
}
