//! The paper's metrics (ALGORITHM.md §6): per-variable average RMSE,
//! position/velocity RMSE (norm over the target's spatial axes) over time, trigger rates, values sent,
//! and average NEES as a consistency check.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::runner::RunResult;

/// Squared errors of one run, ready to be summed over Monte Carlo runs.
#[derive(Debug, Clone, PartialEq)]
pub struct RunErrors {
    /// `T`, `N`, `n`.
    pub dims: (usize, usize, usize),
    /// Squared error per `(k, i, variable)`.
    pub sq: Vec<f64>,
    /// Squared position-error norm per `(k, i)`.
    pub pos_sq: Vec<f64>,
    /// Squared velocity-error norm per `(k, i)`.
    pub vel_sq: Vec<f64>,
    /// Sum of NEES over `(k, i)` and the number of terms (0 without covariances).
    pub nees_sum: f64,
    /// Number of NEES terms.
    pub nees_count: u64,
    /// Whether any estimate or covariance was not finite.
    pub non_finite: bool,
}

/// Squared errors of a run against the truth `(T, n)`, whose first `d`
/// states are the target's position and the next `d` its velocity (the
/// paper's models: `d = 3`; planar models: 2). States beyond `n` count as
/// absent (a position-only model has no velocity error).
pub fn run_errors(r: &RunResult, truth: &[f64], d: usize) -> RunErrors {
    let (t_len, k, n) = (r.steps, r.nodes, r.n);
    let pos = 0..d.min(n);
    let vel = d.min(n)..(2 * d).min(n);
    let mut sq = vec![0.0; t_len * k * n];
    let mut pos_sq = vec![0.0; t_len * k];
    let mut vel_sq = vec![0.0; t_len * k];
    let mut nees_sum = 0.0;
    let mut nees_count = 0;
    let mut non_finite = false;
    for t in 0..t_len {
        let x = &truth[t * n..(t + 1) * n];
        for i in 0..k {
            let base = (t * k + i) * n;
            let est = &r.estimates[base..base + n];
            let e: Vec<f64> = est.iter().zip(x).map(|(a, b)| a - b).collect();
            non_finite |= e.iter().any(|v| !v.is_finite());
            for v in 0..n {
                sq[base + v] = e[v] * e[v];
            }
            pos_sq[t * k + i] = e[pos.clone()].iter().map(|v| v * v).sum();
            vel_sq[t * k + i] = e[vel.clone()].iter().map(|v| v * v).sum();
            if !r.covariances.is_empty() {
                let p = DMatrix::from_row_slice(n, n, &r.covariances[base * n..(base + n) * n]);
                match p.cholesky() {
                    Some(ch) => {
                        let ev = nalgebra::DVector::from_column_slice(&e);
                        nees_sum += ev.dot(&ch.solve(&ev));
                        nees_count += 1;
                    }
                    None => non_finite = true,
                }
            }
        }
    }
    RunErrors {
        dims: (t_len, k, n),
        sq,
        pos_sq,
        vel_sq,
        nees_sum,
        nees_count,
        non_finite,
    }
}

/// Sums of [`RunErrors`] over Monte Carlo runs (added in run order, so the
/// result does not depend on the number of threads).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ErrorSums {
    dims: (usize, usize, usize),
    runs: usize,
    sq: Vec<f64>,
    pos_sq: Vec<f64>,
    vel_sq: Vec<f64>,
    nees_sum: f64,
    nees_count: u64,
    non_finite_runs: usize,
}

impl ErrorSums {
    /// Adds one run.
    pub fn add(&mut self, e: &RunErrors) {
        if self.runs == 0 {
            self.dims = e.dims;
            self.sq = vec![0.0; e.sq.len()];
            self.pos_sq = vec![0.0; e.pos_sq.len()];
            self.vel_sq = vec![0.0; e.vel_sq.len()];
        }
        self.runs += 1;
        self.sq.iter_mut().zip(&e.sq).for_each(|(a, b)| *a += b);
        self.pos_sq
            .iter_mut()
            .zip(&e.pos_sq)
            .for_each(|(a, b)| *a += b);
        self.vel_sq
            .iter_mut()
            .zip(&e.vel_sq)
            .for_each(|(a, b)| *a += b);
        self.nees_sum += e.nees_sum;
        self.nees_count += e.nees_count;
        self.non_finite_runs += usize::from(e.non_finite);
    }

    /// The metrics: `e_k^i = sqrt(mean over runs of squared error)`, then averaged
    /// over nodes and over `k = 1..T`.
    pub fn summary(&self) -> ErrorSummary {
        let (t_len, k, n) = self.dims;
        let r = self.runs.max(1) as f64;
        let mut per_var = vec![0.0; n];
        for row in self.sq.chunks_exact(n.max(1)).take(t_len * k) {
            for (acc, sq) in per_var.iter_mut().zip(row) {
                *acc += (sq / r).sqrt();
            }
        }
        let denom = (t_len * k).max(1) as f64;
        per_var.iter_mut().for_each(|v| *v /= denom);
        let curve = |s: &[f64]| -> Vec<f64> {
            (0..t_len)
                .map(|t| (0..k).map(|i| (s[t * k + i] / r).sqrt()).sum::<f64>() / k as f64)
                .collect()
        };
        let pos_curve = curve(&self.pos_sq);
        let vel_curve = curve(&self.vel_sq);
        let mean = |c: &[f64]| c.iter().sum::<f64>() / c.len().max(1) as f64;
        ErrorSummary {
            runs: self.runs,
            rmse_per_variable: per_var,
            pos_rmse: mean(&pos_curve),
            vel_rmse: mean(&vel_curve),
            pos_rmse_curve: pos_curve,
            vel_rmse_curve: vel_curve,
            nees: if self.nees_count > 0 {
                Some(self.nees_sum / self.nees_count as f64)
            } else {
                None
            },
            non_finite_runs: self.non_finite_runs,
        }
    }
}

/// Accuracy metrics over Monte Carlo runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummary {
    /// Number of runs.
    pub runs: usize,
    /// The paper's average RMSE per state variable.
    pub rmse_per_variable: Vec<f64>,
    /// Average position RMSE (3-D norm).
    pub pos_rmse: f64,
    /// Average velocity RMSE (3-D norm).
    pub vel_rmse: f64,
    /// Position RMSE over time (node-averaged), length `T`.
    pub pos_rmse_curve: Vec<f64>,
    /// Velocity RMSE over time (node-averaged), length `T`.
    pub vel_rmse_curve: Vec<f64>,
    /// Average NEES (expected: the state dimension for a consistent filter).
    pub nees: Option<f64>,
    /// Runs in which an estimate or covariance was not finite or not PD.
    pub non_finite_runs: usize,
}
