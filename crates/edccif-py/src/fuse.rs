//! `edccif.ci_fuse`: covariance intersection of K Gaussian estimates;
//! `edccif.fuse`: K estimates by any fusion rule (`docs/fusion.md`).

use edccif_core::fusion::{ci_fuse_optimal_with, combine_ci};
use edccif_core::fusion_rules::fuse_information;
use edccif_core::{CiCriterion, FusionRule, Gaussian, InfoPair};
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

/// The `j`-th of K stacked estimates (`xs` (K, N), `Ps` (K, N, N) row-major),
/// or a `NotPositiveDefiniteError` naming `Ps[j]`.
fn estimate_at<const N: usize>(xs: &[f64], ps: &[f64], j: usize) -> PyResult<Gaussian<f64, N>> {
    Gaussian::new(
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
    })
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
        let g = estimate_at::<N>(xs, ps, j)?;
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

fn fuse_rule_n<const N: usize>(
    xs: &[f64],
    ps: &[f64],
    k: usize,
    rule: FusionRule,
    weights: &[f64],
    independent: Option<(&[f64], &[f64])>,
) -> PyResult<(Vec<f64>, Vec<f64>)> {
    let mut items = Vec::with_capacity(k);
    for (j, &w) in weights.iter().enumerate().take(k) {
        let g = estimate_at::<N>(xs, ps, j)?;
        items.push((w, g.to_info().py()?));
    }
    let ind = independent.map(|(i, imat)| InfoPair {
        y: SVector::<f64, N>::from_column_slice(i),
        ymat: SMatrix::<f64, N, N>::from_row_slice(imat),
    });
    let fused = fuse_information(rule, items.iter().copied(), ind.as_ref()).py()?;
    Ok((
        fused.x.as_slice().to_vec(),
        fused.p.transpose().as_slice().to_vec(),
    ))
}

/// Fuses K estimates `xs` (K, n) with covariances `Ps` (K, n, n) by a fusion
/// rule of `edccif.FUSION_RULES` (equations, sources and guarantees in
/// `docs/fusion.md`), in the order given. `weights`: K non-negative weights
/// (renormalised; default uniform): CI's weights, the start of the optimised
/// ones (`-trace`, `-det`), ICI's shares of its common-information bound;
/// `ei-unsafe` ignores them. `independent`: `(i (n,), I (n, n))`, information
/// independent of every input (e.g. measurement contributions), added once after
/// the rule; with `split-ci` the estimates are then the inputs' dependent parts.
/// Returns `(x (n,), P (n, n))`.
///
/// >>> import numpy as np, edccif
/// >>> xs = np.array([[0.0, 0.0], [1.0, 1.0]])
/// >>> Ps = np.array([np.diag([1.0, 4.0]), np.diag([4.0, 1.0])])
/// >>> x_ci, P_ci = edccif.fuse(xs, Ps, "ci")
/// >>> x_ici, P_ici = edccif.fuse(xs, Ps, "ici")
/// >>> bool(np.trace(P_ici) < np.trace(P_ci))   # ICI is less conservative
/// True
#[pyfunction]
#[pyo3(signature = (xs, Ps, rule = String::from("ci"), weights = None, independent = None))]
#[pyo3(text_signature = "(xs, Ps, rule='ci', weights=None, independent=None)")]
#[allow(non_snake_case)]
pub fn fuse<'py>(
    py: Python<'py>,
    xs: &Bound<'py, PyAny>,
    Ps: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = crate::args::text_arg::rule)] rule: String,
    weights: Option<&Bound<'py, PyAny>>,
    independent: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let independent = match independent {
        None => None,
        Some(obj) => Some(
            obj.extract::<(Bound<'py, PyAny>, Bound<'py, PyAny>)>()
                .map_err(|_| {
                    crate::errors::argument_type_error(
                        py,
                        "independent: expected a pair (i (n,), I (n, n)) or None",
                    )
                })?,
        ),
    };
    let rule = FusionRule::from_name(&rule).ok_or_else(|| {
        crate::errors::UnknownOptionError::new_err(format!(
            "rule: unknown fusion rule {rule:?}; expected one of {}",
            FusionRule::NAMES.join(", ")
        ))
    })?;
    let (xv, xshape) = finite_array(xs, "xs", &[Dim::Any("K"), Dim::Any("n")])?;
    let (k, n) = (xshape[0], xshape[1]);
    if n > MAX_DIM {
        return Err(ShapeError::new_err(format!(
            "xs: state dimension n must be <= {MAX_DIM}, got {n}"
        )));
    }
    let (pv, _) = finite_array(Ps, "Ps", &[Dim::Is(k), Dim::Is(n), Dim::Is(n)])?;
    // The weighted information pairs K × (1 + n + n²) beside the inputs.
    edccif_sim::limits::check_memory(
        || format!("fuse of K = {k} estimates of dimension {n}"),
        edccif_sim::limits::product(&[k, n * n + n + 1, 8]),
    )
    .py()?;
    let wv = match weights {
        None => vec![1.0 / k as f64; k],
        Some(obj) => {
            let (wv, _) = finite_array(obj, "weights", &[Dim::Is(k)])?;
            if wv.iter().any(|w| *w < 0.0) || wv.iter().sum::<f64>() <= 0.0 {
                return Err(ParameterError::new_err(format!(
                    "weights: expected non-negative weights with a positive sum, got {wv:?}"
                )));
            }
            wv
        }
    };
    let ind = match &independent {
        None => None,
        Some((i, imat)) => {
            let (iv, _) = finite_array(i, "independent[0]", &[Dim::Is(n)])?;
            let (mv, _) = finite_array(imat, "independent[1]", &[Dim::Is(n), Dim::Is(n)])?;
            let asym = (0..n).any(|r| {
                (0..n).any(|c| {
                    (mv[r * n + c] - mv[c * n + r]).abs()
                        > 1e-9 * mv.iter().fold(0.0f64, |a, v| a.max(v.abs()))
                })
            });
            if asym {
                return Err(ParameterError::new_err(
                    "independent[1]: expected a symmetric information matrix",
                ));
            }
            Some((iv, mv))
        }
    };
    let ind_ref = ind.as_ref().map(|(a, b)| (a.as_slice(), b.as_slice()));
    macro_rules! dispatch {
        ($($d:literal),*) => {
            match n {
                $($d => fuse_rule_n::<$d>(&xv, &pv, k, rule, &wv, ind_ref)?,)*
                _ => unreachable!("n checked above"),
            }
        };
    }
    let (x, p) = dispatch!(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12);
    let x: Bound<'py, PyArrayDyn<f64>> = to_numpy(py, x, &[n])?;
    let p = to_numpy(py, p, &[n, n])?;
    PyTuple::new(py, [x.into_any(), p.into_any()])
}

/// The fusion rule names accepted by `fusion=` and `fuse` (`docs/fusion.md`).
#[pyfunction]
pub fn fusion_rules<'py>(py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyList>> {
    pyo3::types::PyList::new(py, FusionRule::NAMES)
}
