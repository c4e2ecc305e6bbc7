//! `edccif.ci_fuse`: covariance intersection of K Gaussian estimates.

use edccif_core::fusion::{ci_fuse_optimal_with, combine_ci};
use edccif_core::{CiCriterion, Gaussian, InfoPair};
use edccif_sim::control::Control;
use nalgebra::{SMatrix, SVector};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::convert::{finite_array, to_numpy, Dim};
use crate::drive::{drive_if, Progress};
use crate::errors::{IntoPyResult, ParameterError, ShapeError};

/// Largest state dimension `ci_fuse` accepts.
pub const MAX_DIM: usize = 12;

enum Weights {
    Fixed(Vec<f64>),
    Optimal(CiCriterion),
}

fn fuse_n<const N: usize>(
    xs: &[f64],
    ps: &[f64],
    k: usize,
    w: &Weights,
    ctl: &Control,
) -> PyResult<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let mut infos = Vec::with_capacity(k);
    for j in 0..k {
        if j % 4096 == 0 && ctl.is_cancelled() {
            return Err(crate::errors::to_py(edccif_sim::Error::Interrupted));
        }
        let g = Gaussian::new(
            SVector::<f64, N>::from_column_slice(&xs[j * N..(j + 1) * N]),
            SMatrix::<f64, N, N>::from_row_slice(&ps[j * N * N..(j + 1) * N * N]),
        )
        .map_err(|e| match e {
            edccif_core::Error::NotPositiveDefinite { .. }
            | edccif_core::Error::NotSymmetric { .. } => {
                crate::errors::NotPositiveDefiniteError::new_err(format!(
                    "Ps[{j}]: expected a symmetric positive-definite covariance ({e})"
                ))
            }
            other => crate::errors::to_py(other.into()),
        })?;
        infos.push(g.to_info().py()?);
    }
    let (fused, weights) = match w {
        Weights::Fixed(ws) => (
            combine_ci(ws.iter().copied().zip(infos.iter())).py()?,
            ws.clone(),
        ),
        Weights::Optimal(c) => {
            let mut ws = vec![1.0 / k as f64; k];
            let mut seen: Option<u64> = None;
            let mut watch = |done: u64, total: u64| {
                match seen {
                    None => {
                        ctl.add_total(total);
                        ctl.advance(done);
                    }
                    Some(prev) if done > prev => ctl.advance(done - prev),
                    Some(_) => {}
                }
                seen = Some(done);
                !ctl.is_cancelled()
            };
            (
                ci_fuse_optimal_with::<f64, N>(&infos, *c, &mut ws, &mut watch).py()?,
                ws,
            )
        }
    };
    let _: &[InfoPair<f64, N>] = &infos;
    Ok((
        fused.x.as_slice().to_vec(),
        fused.p.transpose().as_slice().to_vec(),
        weights,
    ))
}

/// Covariance intersection of K estimates `xs` (K, n) with covariances `Ps`
/// (K, n, n): `P⁻¹ = Σ w_j P_j⁻¹`, `P⁻¹x = Σ w_j P_j⁻¹ x_j`. `weights`: None
/// (uniform), an array of K non-negative weights (renormalised), or `"trace"` /
/// `"det"` to minimise the trace or determinant of the fused covariance.
/// Returns `(x (n,), P (n, n), weights (K,))`.
///
/// The search of `"trace"`/`"det"` grows as K³ (pairwise coordinate descent):
/// it runs with the GIL released, stops with `KeyboardInterrupt` on Ctrl-C,
/// and `progress` (True: a bar or a line every few seconds on stderr; a
/// callable: `progress(done, total)` in pairs of weights visited) reports it.
#[pyfunction]
#[pyo3(signature = (xs, Ps, weights = None, *, progress = None))]
#[allow(non_snake_case)]
pub fn ci_fuse<'py>(
    py: Python<'py>,
    xs: &Bound<'py, PyAny>,
    Ps: &Bound<'py, PyAny>,
    weights: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let progress = Progress::from_arg(progress, "ci_fuse", "pairs")?;
    let (xv, xshape) = finite_array(xs, "xs", &[Dim::Any("K"), Dim::Any("n")])?;
    let (k, n) = (xshape[0], xshape[1]);
    if n > MAX_DIM {
        return Err(ShapeError::new_err(format!(
            "xs: state dimension n must be <= {MAX_DIM}, got {n}"
        )));
    }
    let (pv, _) = finite_array(Ps, "Ps", &[Dim::Is(k), Dim::Is(n), Dim::Is(n)])?;
    // The information pairs K × (n + n²) beside the inputs.
    edccif_sim::limits::check_memory(
        || format!("ci_fuse of K = {k} estimates of dimension {n}"),
        edccif_sim::limits::product(&[k, n * n + n, 8]),
    )
    .py()?;
    let w = match weights {
        None => Weights::Fixed(vec![1.0 / k as f64; k]),
        Some(obj) => {
            if let Ok(s) = obj.extract::<String>() {
                match s.as_str() {
                    "trace" => Weights::Optimal(CiCriterion::Trace),
                    "det" | "determinant" => Weights::Optimal(CiCriterion::Determinant),
                    _ => {
                        return Err(ParameterError::new_err(format!(
                            "weights: expected None, an array of {k} weights, \"trace\" or \"det\", got {s:?}"
                        )))
                    }
                }
            } else {
                let (wv, _) = finite_array(obj, "weights", &[Dim::Is(k)])?;
                if wv.iter().any(|w| *w < 0.0) || wv.iter().sum::<f64>() <= 0.0 {
                    return Err(ParameterError::new_err(format!(
                        "weights: expected non-negative weights with a positive sum, got {wv:?}"
                    )));
                }
                Weights::Fixed(wv)
            }
        }
    };
    macro_rules! dispatch {
        ($ctl:expr, $($d:literal),*) => {
            match n {
                $($d => fuse_n::<$d>(&xv, &pv, k, &w, $ctl),)*
                _ => unreachable!("n checked above"),
            }
        };
    }
    // The search of optimal weights grows as K³; fixed weights are one pass.
    let long = matches!(w, Weights::Optimal(_)) && k >= 8 || k >= 100_000;
    let (x, p, ws) = drive_if(py, long, &progress, |ctl| {
        dispatch!(ctl, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12)
    })
    .into_result()??;
    let x: Bound<'py, PyArrayDyn<f64>> = to_numpy(py, x, &[n])?;
    let p = to_numpy(py, p, &[n, n])?;
    let ws = to_numpy(py, ws, &[k])?;
    PyTuple::new(py, [x.into_any(), p.into_any(), ws.into_any()])
}
