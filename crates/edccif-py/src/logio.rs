//! Logs and the real-world path from Python: MCAP recording and replay, TUM files,
//! the preprocessing pipeline.

use std::path::PathBuf;

use edccif_io::{
    self as logio, read_measurements_file, run_pipeline, write_mcap_file, McapWriteOptions,
    PipelineOptions, Track,
};
use edccif_sim::recording::{mcap_run_data, run_recording};
use edccif_sim::Scenario;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{finite_array, to_numpy, to_numpy_bool, Dim};
use crate::errors::{IntoPyResult, ShapeError};
use crate::runner::{algorithm, options_from_kwargs, wrap_result, x0_or_default, PyRunResult};
use crate::scenario::{json_to_py, PyScenario};

fn write_tum_positions(path: PathBuf, t: &[f64], p: &[f64]) -> PyResult<()> {
    let track = Track::from_flat(t, p).py()?;
    logio::write_tum(path, &track, None).py()
}

/// Simulates one seeded run of the scenario, runs `algorithm` on it and records it:
/// `mcap`: a Foxglove-ready MCAP file (truth, measurements, trigger flags, local and
/// fused estimates with covariance ellipsoids); `tum_dir`: `truth.txt` and
/// `node{i}.txt` (fused estimates) in TUM format for evo. Returns the RunResult.
#[pyfunction]
#[pyo3(signature = (algorithm, scenario, seed = 0, *, mcap = None, tum_dir = None, **options))]
pub fn record(
    py: Python<'_>,
    algorithm: &str,
    scenario: &PyScenario,
    seed: u64,
    mcap: Option<PathBuf>,
    tum_dir: Option<PathBuf>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRunResult> {
    let alg = self::algorithm(algorithm)?;
    let opt = options_from_kwargs(options)?;
    let sc = scenario.inner.clone();
    let r = py
        .allow_threads(move || -> edccif_sim::Result<_> {
            let sim = edccif_sim::simulate(&sc, seed)?;
            let (res, local) = run_recording(alg, &sc, &sim.z, &sim.x0_hat, &opt)?;
            if let Some(path) = &mcap {
                let data = mcap_run_data(&sc, &sim, &res, Some(&local))?;
                write_mcap_file(path, &data, &McapWriteOptions::default())?;
            }
            if let Some(dir) = &tum_dir {
                std::fs::create_dir_all(dir).map_err(|e| {
                    edccif_sim::Error::Io(format!("cannot create {}: {e}", dir.display()))
                })?;
                let n = sim.n;
                let t: Vec<f64> = (1..=sim.steps).map(|k| k as f64 * sc.dt).collect();
                let truth: Vec<f64> = sim
                    .truth
                    .chunks_exact(n)
                    .flat_map(|x| x[..3].to_vec())
                    .collect();
                let track = Track::from_flat(&t, &truth)?;
                logio::write_tum(dir.join("truth.txt"), &track, None)?;
                for i in 0..res.nodes {
                    let p: Vec<f64> = (0..res.steps)
                        .flat_map(|k| {
                            let b = (k * res.nodes + i) * n;
                            res.estimates[b..b + 3].to_vec()
                        })
                        .collect();
                    logio::write_tum(
                        dir.join(format!("node{i}.txt")),
                        &Track::from_flat(&t, &p)?,
                        None,
                    )?;
                }
            }
            Ok(res)
        })
        .py()?;
    wrap_result(py, r, true)
}

/// Reads the measurements of an MCAP file written by edccif (or following its
/// documented `/node{i}/measurement` schema): `(t_ns (T,), z (T, N, 3), triggered (T, N))`,
/// NaN rows where a node has no measurement.
#[pyfunction]
pub fn read_mcap_measurements<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<Bound<'py, PyTuple>> {
    let r = py
        .allow_threads(move || read_measurements_file(path))
        .py()?;
    let t: Vec<f64> = r.t_ns.iter().map(|v| *v as f64).collect();
    let t = to_numpy(py, t, &[r.steps])?;
    let z = to_numpy(py, r.z, &[r.steps, r.nodes, 3])?;
    let trig = to_numpy_bool(py, r.triggered, &[r.steps, r.nodes])?;
    PyTuple::new(py, [t.into_any(), z.into_any(), trig.into_any()])
}

/// Replays the measurements of an MCAP file into `algorithm` on the scenario
/// (whose node count must match the file's).
#[pyfunction]
#[pyo3(signature = (path, scenario, algorithm = "edc-cif", x0 = None, **options))]
pub fn replay(
    py: Python<'_>,
    path: PathBuf,
    scenario: &PyScenario,
    algorithm: &str,
    x0: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRunResult> {
    let alg = self::algorithm(algorithm)?;
    let opt = options_from_kwargs(options)?;
    let x0v = x0_or_default(scenario, x0)?;
    let sc: Scenario = scenario.inner.clone();
    let rep = py.allow_threads(|| read_measurements_file(&path)).py()?;
    if rep.nodes != sc.nodes() {
        return Err(ShapeError::new_err(format!(
            "{}: the file has {} nodes, the scenario {}",
            path.display(),
            rep.nodes,
            sc.nodes()
        )));
    }
    let r = py
        .allow_threads(move || edccif_sim::run(alg, &sc, &rep.z, &x0v, &opt, true))
        .py()?;
    wrap_result(py, r, true)
}

/// Reads a TUM trajectory: `(t (M,), p (M, 3), q (M, 4))` (quaternion x, y, z, w).
#[pyfunction]
pub fn read_tum<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyTuple>> {
    let tr = logio::read_tum(path).py()?;
    let m = tr.track.len();
    let t = to_numpy(py, tr.track.t.clone(), &[m])?;
    let p = to_numpy(py, tr.track.positions_flat(), &[m, 3])?;
    let q: Vec<f64> = tr.orientations.iter().flatten().copied().collect();
    let q = to_numpy(py, q, &[m, 4])?;
    PyTuple::new(py, [t.into_any(), p.into_any(), q.into_any()])
}

/// Writes positions `p` (M, 3) at times `t` (M,) as a TUM trajectory (identity
/// orientation).
#[pyfunction]
pub fn write_tum(path: PathBuf, t: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<()> {
    let (tv, ts) = finite_array(t, "t", &[Dim::Any("M")])?;
    let (pv, _) = finite_array(p, "p", &[Dim::Is(ts[0]), Dim::Is(3)])?;
    write_tum_positions(path, &tv, &pv)
}

/// The paper's preprocessing pipeline on TUM files: removal of abnormal time gaps
/// and origin outliers, common start/end alignment, spatial alignment of each
/// observer onto the truth (Umeyama, `with_scale` optional; `spatial=False` when the
/// observers are already in the truth's frame), truth downsampling and
/// interpolation to a common rate (`rate_hz`, default: the observers' median rate).
/// Returns a dict with `t (T,)`, `truth (T, 3)`, `z (T, N, 3)` (NaN where missing),
/// `dt`, and `report` (what each step removed or changed).
#[pyfunction]
#[pyo3(signature = (truth, observers, rate_hz = None, spatial = true, with_scale = false))]
pub fn preprocess<'py>(
    py: Python<'py>,
    truth: PathBuf,
    observers: Vec<PathBuf>,
    rate_hz: Option<f64>,
    spatial: bool,
    with_scale: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let truth = logio::read_tum(truth).py()?.track;
    let obs: Vec<Track> = observers
        .into_iter()
        .map(|p| logio::read_tum(p).map(|t| t.track))
        .collect::<edccif_io::Result<_>>()
        .py()?;
    let mut opt = PipelineOptions {
        rate_hz,
        ..PipelineOptions::default()
    };
    if !spatial {
        opt.spatial = None;
    } else if let Some(s) = opt.spatial.as_mut() {
        s.with_scale = with_scale;
    }
    let a = py
        .allow_threads(move || run_pipeline(&truth, &obs, &opt))
        .py()?;
    let d = PyDict::new(py);
    let t: Bound<'py, PyArrayDyn<f64>> = to_numpy(py, a.t.clone(), &[a.steps])?;
    d.set_item("t", t)?;
    d.set_item("truth", to_numpy(py, a.truth.clone(), &[a.steps, 3])?)?;
    d.set_item("z", to_numpy(py, a.z.clone(), &[a.steps, a.nodes, 3])?)?;
    d.set_item("dt", a.dt)?;
    d.set_item(
        "report",
        json_to_py(py, &serde_json::to_value(&a.report).unwrap_or_default())?,
    )?;
    Ok(d)
}
