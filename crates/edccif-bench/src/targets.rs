//! The speed targets' three kernels, timed in one place
//! (`edccif-timing --targets`):
//!
//! | case | what | target |
//! |---|---|---|
//! | `et-cif-sent` | one node's ET-CIF local step whose measurement is sent ([`LocalFixture`], `cif/sod-sent`) | ≤ 1 µs |
//! | `network-8` | one step of the 8-node EDC-CIF network, the mean over a whole 200-step run of the default scenario | ≤ 10 µs |
//! | `ekf` | one node's EKF local step ([`LocalFixture`], `ekf/always`) | ≤ 0.4 µs |
//!
//! Each batch is timed on the thread's CPU clock and the wall clock and
//! reported in µs per step. [`run_target`] runs the same steps untimed, for an
//! instruction count under callgrind (`--toggle-collect='*LocalFixture::step'`
//! for the local cases, `--toggle-collect=edccif_bench::run_steps` for the
//! network).
//!
//! ```
//! use edccif_bench::config::Config;
//! use edccif_bench::targets::{time_target, Target};
//! let t = time_target(Target::Ekf, &Config::library_default(), 2, 10).unwrap();
//! assert_eq!(t.len(), 2);
//! assert!(t.iter().all(|s| s.cpu_us > 0.0));
//! ```

use std::hint::black_box;
use std::str::FromStr;
use std::time::Instant;

use cpu_time::ThreadTime;
use edccif_sim::{Algorithm, Error, Result};

use crate::config::Config;
use crate::{local_cases, run_steps, LocalCase, LocalFixture, StepTime, Workload, DEFAULT_SEED};

/// One of the speed targets' kernels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// ET-CIF local step, measurement sent.
    EtCifSent,
    /// 8-node EDC-CIF network step.
    Network8,
    /// EKF local step.
    Ekf,
}

impl Target {
    /// All three, in the order of the targets table.
    pub const ALL: [Target; 3] = [Target::EtCifSent, Target::Network8, Target::Ekf];

    /// The name used on command lines and in JSON.
    pub fn name(&self) -> &'static str {
        match self {
            Target::EtCifSent => "et-cif-sent",
            Target::Network8 => "network-8",
            Target::Ekf => "ekf",
        }
    }

    /// What it is, for tables.
    pub fn label(&self) -> &'static str {
        match self {
            Target::EtCifSent => "ET-CIF local step, sent",
            Target::Network8 => "8-node EDC-CIF network step",
            Target::Ekf => "EKF local step",
        }
    }

    /// The target, µs per step.
    pub fn target_us(&self) -> f64 {
        match self {
            Target::EtCifSent => 1.0,
            Target::Network8 => 10.0,
            Target::Ekf => 0.4,
        }
    }

    /// Steps per batch by default (a batch of about a millisecond).
    pub fn default_batch(&self) -> usize {
        match self {
            Target::EtCifSent | Target::Ekf => 2_000,
            // One whole run of the default scenario.
            Target::Network8 => 200,
        }
    }

    fn local_case(&self) -> Option<LocalCase> {
        let name = match self {
            Target::EtCifSent => "cif/sod-sent",
            Target::Ekf => "ekf/always",
            Target::Network8 => return None,
        };
        local_cases().into_iter().find(|c| c.name == name)
    }
}

impl FromStr for Target {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Target::ALL
            .into_iter()
            .find(|t| t.name() == s)
            .ok_or_else(|| format!("unknown target {s:?}: expected et-cif-sent, network-8 or ekf"))
    }
}

// Built once per measurement: the size of its variants does not matter.
#[allow(clippy::large_enum_variant)]
enum Prepared {
    Local(Box<LocalFixture>, LocalCase),
    Network(Workload),
}

fn prepare(target: Target, config: &Config) -> Result<Prepared> {
    Ok(match target.local_case() {
        Some(case) => Prepared::Local(
            Box::new(LocalFixture::new(DEFAULT_SEED, 50)?.with_config(config)),
            case,
        ),
        None => {
            let mut w = Workload::paper(8, DEFAULT_SEED)?;
            config.apply(&mut w.scenario);
            Prepared::Network(w)
        }
    })
}

fn steps(p: &Prepared, n: usize) -> Result<()> {
    match p {
        Prepared::Local(f, case) => {
            for _ in 0..n {
                black_box(f.step(case)?);
            }
        }
        Prepared::Network(w) => {
            let mut left = n;
            while left > 0 {
                let k = left.min(w.steps());
                let mut net = w.network(Algorithm::EdcCif)?;
                run_steps(&mut net, w, 0..k)?;
                left -= k;
            }
        }
    }
    Ok(())
}

/// `batches` batches of `per_batch` steps of `target` in `config`, after one
/// untimed warm-up batch: µs per step of each batch on both clocks. The
/// network's batches build a fresh network every 200 steps (untimed only
/// when `per_batch` is a multiple of 200: use [`Target::default_batch`]).
pub fn time_target(
    target: Target,
    config: &Config,
    batches: usize,
    per_batch: usize,
) -> Result<Vec<StepTime>> {
    if batches == 0 || per_batch == 0 {
        return Err(Error::Value {
            what: "time_target".into(),
            problem: format!("batches ({batches}) and per_batch ({per_batch}) must be >= 1"),
        });
    }
    let p = prepare(target, config)?;
    steps(&p, per_batch)?;
    let mut out = Vec::with_capacity(batches);
    for _ in 0..batches {
        match &p {
            // The network is timed per run, without building the network.
            Prepared::Network(w) => {
                let mut cpu = 0.0;
                let mut wall = 0.0;
                let mut left = per_batch;
                while left > 0 {
                    let k = left.min(w.steps());
                    let t = crate::time_run_row(crate::Row::new(Algorithm::EdcCif), w, k)?;
                    cpu += t.cpu.as_secs_f64();
                    wall += t.wall.as_secs_f64();
                    left -= k;
                }
                out.push(StepTime {
                    wall_us: wall * 1e6 / per_batch as f64,
                    cpu_us: cpu * 1e6 / per_batch as f64,
                });
            }
            Prepared::Local(..) => {
                let (c0, t0) = (ThreadTime::now(), Instant::now());
                steps(&p, per_batch)?;
                let (tc, tw) = (c0.elapsed(), t0.elapsed());
                out.push(StepTime {
                    wall_us: tw.as_secs_f64() * 1e6 / per_batch as f64,
                    cpu_us: tc.as_secs_f64() * 1e6 / per_batch as f64,
                });
            }
        }
    }
    Ok(out)
}

/// Runs `n` steps of `target` in `config`, untimed (for callgrind: the local
/// steps inside `LocalFixture::step`, the network's inside `run_steps`).
pub fn run_target(target: Target, config: &Config, n: usize) -> Result<()> {
    steps(&prepare(target, config)?, n)
}
