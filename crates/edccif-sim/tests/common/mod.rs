//! Helpers shared by the integration tests that compare two runs of the same
//! data (an opt-in numerical path against the reference path).

use edccif_sim::{RunResult, Simulation};

/// Position RMSE over all steps and nodes of a run's estimates `(T, N, n)`
/// against the simulation's truth `(T, n)`.
pub fn pos_rmse(est: &[f64], sim: &Simulation) -> f64 {
    let (steps, nodes, n) = (sim.steps, sim.nodes, sim.n);
    let mut s = 0.0;
    for t in 0..steps {
        for i in 0..nodes {
            for k in 0..3 {
                let d = est[(t * nodes + i) * n + k] - sim.truth[t * n + k];
                s += d * d;
            }
        }
    }
    (s / (steps * nodes) as f64).sqrt()
}

/// How far run `b` is from run `a`: the largest per-step difference of an
/// estimate entry relative to `max(|a|, 1)` (scale ≥ 1 m, m/s, rad/s), and the
/// two runs' position RMSEs.
pub fn run_difference(a: &RunResult, b: &RunResult, sim: &Simulation) -> (f64, f64, f64) {
    let worst = a
        .estimates
        .iter()
        .zip(&b.estimates)
        .map(|(x, y)| (x - y).abs() / x.abs().max(1.0))
        .fold(0.0, f64::max);
    (
        worst,
        pos_rmse(&a.estimates, sim),
        pos_rmse(&b.estimates, sim),
    )
}
