//! What a run returns ([`RunResult`]) and the memory its arrays need
//! ([`run_bytes`], checked by [`check_run_size`]): shared by the typed network's
//! runner and the model network.

use serde::{Deserialize, Serialize};

use crate::algorithm::Algorithm;
use crate::counters::Counters;
use crate::error::Result;

/// Everything a run returns. Arrays are flat, row-major.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    /// The row that ran.
    pub algorithm: Algorithm,
    /// `T`.
    pub steps: usize,
    /// `N`.
    pub nodes: usize,
    /// `n`.
    pub n: usize,
    /// Fused estimates `(T, N, n)`.
    pub estimates: Vec<f64>,
    /// Fused covariances `(T, N, n, n)` (empty unless requested).
    pub covariances: Vec<f64>,
    /// Trigger flags `(T, N)` (false also when no measurement).
    pub triggered: Vec<bool>,
    /// Measurement present `(T, N)`.
    pub measured: Vec<bool>,
    /// Totals.
    pub counters: Counters,
    /// Wall time of the stepping loop (s).
    pub elapsed_s: f64,
}

impl RunResult {
    /// Fraction of node-steps with a measurement whose sensor sent.
    pub fn trigger_rate(&self) -> f64 {
        if self.counters.measured == 0 {
            0.0
        } else {
            self.counters.triggered as f64 / self.counters.measured as f64
        }
    }
}

/// Bytes a run of `steps` steps of `nodes` nodes with state dimension `n`
/// allocates for its result: estimates `(T, N, n)`, with `record_covariances`
/// covariances `(T, N, n, n)`, with `local` the pre-combination estimates
/// `(T, N, n)`, and two `(T, N)` flag arrays.
pub fn run_bytes(
    steps: usize,
    nodes: usize,
    n: usize,
    record_covariances: bool,
    local: bool,
) -> u128 {
    use crate::limits::product;
    let per = 1 + usize::from(local) + if record_covariances { n } else { 0 };
    product(&[steps, nodes, n, per, 8]).saturating_add(product(&[steps, nodes, 2]))
}

/// Refuses a run whose result ([`run_bytes`]) does not fit in the memory
/// available ([`limits::check_memory`](crate::limits::check_memory)).
///
/// ```
/// let e = edccif_sim::runner::check_run_size(1 << 40, 4, 7, true).unwrap_err().to_string();
/// assert!(e.contains("steps = 1099511627776"), "{e}");
/// ```
pub fn check_run_size(
    steps: usize,
    nodes: usize,
    n: usize,
    record_covariances: bool,
) -> Result<()> {
    crate::limits::check_memory(
        || {
            format!(
                "a run of steps = {steps} with nodes = {nodes} (estimates steps × nodes × {n}{})",
                if record_covariances {
                    format!(", covariances steps × nodes × {n} × {n}")
                } else {
                    String::new()
                }
            )
        },
        run_bytes(steps, nodes, n, record_covariances, false),
    )
}
