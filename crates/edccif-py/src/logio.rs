//! Logs and the real-world path from Python: MCAP recording and replay, TUM files,
//! the preprocessing pipeline.

use std::path::PathBuf;

use edccif_io::mcap_io::ChunkCompression;
use edccif_io::ros2::{read_ros2_file, Ros2Rows, Source};
use edccif_io::{
    self as logio, read_measurements_file, run_pipeline, write_mcap_file, McapRunData,
    McapWriteOptions, PipelineOptions, Track,
};
use edccif_sim::recording::{mcap_run_data, run_recording};
use edccif_sim::Scenario;
use numpy::{PyArray1, PyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{bool_array, f64_array, finite_array, to_numpy, to_numpy_bool, Dim};
use crate::errors::{IntoPyResult, ParameterError, ShapeError};
use crate::runner::{algorithm, options_from_kwargs, wrap_result, x0_or_default, PyRunResult};
use crate::scenario::{json_to_py, PyScenario};

fn write_tum_positions(path: PathBuf, t: &[f64], p: &[f64]) -> PyResult<()> {
    let track = Track::from_flat(t, p).py()?;
    logio::write_tum(path, &track, None).py()
}

fn compression(name: &str) -> PyResult<ChunkCompression> {
    match name {
        "zstd" => Ok(ChunkCompression::Zstd),
        "none" => Ok(ChunkCompression::None),
        other => Err(ParameterError::new_err(format!(
            "compression: {other:?}; expected \"zstd\" or \"none\""
        ))),
    }
}

/// Simulates one seeded run of the scenario, runs `algorithm` on it and records it:
/// `mcap`: a Foxglove-ready MCAP file (truth, measurements, trigger flags, local and
/// fused estimates with covariance ellipsoids; zstd-compressed chunks unless
/// `compression="none"`; with `ros2=True` also the measurements and the truth as
/// ROS 2 CDR `geometry_msgs/msg/PointStamped` on `/node{i}/point` and
/// `/truth/point`); `tum_dir`: `truth.txt` and `node{i}.txt` (fused estimates) in
/// TUM format for evo. Returns the RunResult.
#[pyfunction]
#[pyo3(signature = (algorithm, scenario, seed = 0, *, mcap = None, tum_dir = None, ros2 = false, compression = "zstd", **options))]
#[allow(clippy::too_many_arguments)]
pub fn record(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
    #[pyo3(from_py_with = crate::args::class_arg::scenario)] scenario: PyRef<'_, PyScenario>,
    #[pyo3(from_py_with = crate::args::named::seed)] seed: u64,
    #[pyo3(from_py_with = crate::args::opt_path_arg::mcap)] mcap: Option<PathBuf>,
    #[pyo3(from_py_with = crate::args::opt_path_arg::tum_dir)] tum_dir: Option<PathBuf>,
    #[pyo3(from_py_with = crate::args::flag_arg::ros2)] ros2: bool,
    #[pyo3(from_py_with = crate::args::more::compression)] compression: &'static str,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRunResult> {
    let alg = self::algorithm(algorithm)?;
    let opt = options_from_kwargs(options)?;
    let wopt = McapWriteOptions {
        ros2,
        compression: self::compression(compression)?,
        ..McapWriteOptions::default()
    };
    let sc = scenario.inner.clone();
    // Sizes first: the simulation, then the run with its local estimates.
    let (steps, k, n) = (sc.steps, sc.nodes(), sc.state_dim());
    edccif_sim::simulate::check_simulation_size(steps, k, n).py()?;
    edccif_sim::limits::check_memory(
        || format!("a recording of steps = {steps} with nodes = {k}"),
        edccif_sim::runner::run_bytes(steps, k, n, true, true),
    )
    .py()?;
    let r = py
        .allow_threads(move || -> edccif_sim::Result<_> {
            let sim = edccif_sim::simulate(&sc, seed)?;
            let (res, local) = run_recording(alg, &sc, &sim.z, &sim.x0_hat, &opt)?;
            if let Some(path) = &mcap {
                let data = mcap_run_data(&sc, &sim, &res, Some(&local))?;
                write_mcap_file(path, &data, &wopt)?;
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
/// NaN rows where a node has no measurement. A file whose tail is missing gives
/// the messages before the cut, with a UserWarning saying where it stopped.
#[pyfunction]
pub fn read_mcap_measurements<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
) -> PyResult<Bound<'py, PyTuple>> {
    let r = py.allow_threads(|| read_measurements_file(&path)).py()?;
    warn_truncated(py, &path, r.truncated.as_deref())?;
    let t: Vec<f64> = r.t_ns.iter().map(|v| *v as f64).collect();
    let t = to_numpy(py, t, &[r.steps])?;
    let z = to_numpy(py, r.z, &[r.steps, r.nodes, 3])?;
    let trig = to_numpy_bool(py, r.triggered, &[r.steps, r.nodes])?;
    PyTuple::new(py, [t.into_any(), z.into_any(), trig.into_any()])
}

fn sources(specs: &[String]) -> PyResult<Vec<Source>> {
    specs
        .iter()
        .map(|s| Source::parse(s))
        .collect::<edccif_io::Result<_>>()
        .py()
}

/// Reads a ROS 2 recording and puts it on rows: the distinct measurement stamps,
/// or a uniform grid at `rate_hz` (linear interpolation).
fn ros2_rows(
    path: &std::path::Path,
    measurements: &[String],
    truth: Option<&str>,
    rate_hz: Option<f64>,
    max_gap_s: Option<f64>,
) -> PyResult<Ros2Rows> {
    let m = sources(measurements)?;
    let t = truth.map(Source::parse).transpose().py()?;
    let rec = read_ros2_file(path, &m, t.as_ref()).py()?;
    match rate_hz {
        None => rec.on_stamps(),
        Some(r) => rec.resampled(r, max_gap_s.unwrap_or(3.0 / r)),
    }
    .py()
}

fn warn_truncated(py: Python<'_>, path: &std::path::Path, why: Option<&str>) -> PyResult<()> {
    if let Some(why) = why {
        let msg = format!("{}: {why}", path.display());
        let warnings = py.import("warnings")?;
        warnings.call_method1(
            "warn",
            (msg, py.get_type::<pyo3::exceptions::PyUserWarning>()),
        )?;
    }
    Ok(())
}

/// Reads positions from a ROS 2 recording (MCAP with CDR messages; zstd, lz4 or
/// uncompressed chunks): `measurements` names one source per node, `truth` an
/// optional ground-truth source, each `TOPIC` or `TOPIC#FRAME` (for `/tf`: the
/// child frame). Supported: geometry_msgs PointStamped, PoseStamped,
/// PoseWithCovarianceStamped, tf2_msgs TFMessage, nav_msgs Odometry; each
/// message's header stamp is its time. Rows: the distinct measurement stamps
/// (`rate_hz=None`), or a uniform grid at `rate_hz` with linear interpolation
/// across gaps up to `max_gap_s` (default 3 periods). Returns a dict with
/// `t_ns` (T,) int64 stamps, `t` (T,) seconds since the first row, `dt` (T,)
/// step lengths (`dt[0] = 0`), `z` (T, N, 3) (NaN where a node has no sample),
/// `truth` (T, 3) interpolated at the rows or None, `sources`, and `truncated`
/// (None, or why the file's tail is missing; a UserWarning is issued too).
#[pyfunction]
#[pyo3(signature = (path, measurements, truth = None, rate_hz = None, max_gap_s = None))]
pub fn read_ros2<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
    #[pyo3(from_py_with = crate::args::texts_arg::measurements)] measurements: Vec<String>,
    #[pyo3(from_py_with = crate::args::opt_text_arg::truth)] truth: Option<String>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::rate_hz)] rate_hz: Option<f64>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::max_gap_s)] max_gap_s: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let rows =
        py.allow_threads(|| ros2_rows(&path, &measurements, truth.as_deref(), rate_hz, max_gap_s))?;
    warn_truncated(py, &path, rows.truncated.as_deref())?;
    let d = PyDict::new(py);
    let t0 = rows.t_ns.first().copied().unwrap_or(0);
    let t: Vec<f64> = rows.t_ns.iter().map(|v| (v - t0) as f64 * 1e-9).collect();
    let t_ns: Vec<i64> = rows.t_ns.iter().map(|v| *v as i64).collect();
    d.set_item("t_ns", PyArray1::from_vec(py, t_ns))?;
    d.set_item("t", to_numpy(py, t, &[rows.steps])?)?;
    d.set_item("dt", to_numpy(py, rows.dt_s(), &[rows.steps])?)?;
    d.set_item(
        "z",
        to_numpy(py, rows.z.clone(), &[rows.steps, rows.nodes, 3])?,
    )?;
    match &rows.truth {
        Some(tr) => d.set_item("truth", to_numpy(py, tr.clone(), &[rows.steps, 3])?)?,
        None => d.set_item("truth", py.None())?,
    }
    d.set_item("sources", measurements)?;
    d.set_item("truncated", rows.truncated.clone())?;
    Ok(d)
}

/// Replays the measurements of an MCAP file into `algorithm` on the scenario
/// (whose node count must match the file's). Without `measurements`: the file's
/// `/node{i}/measurement` topics (as `edccif simulate --mcap` writes them), one
/// scenario `dt` per row. With `measurements` (one `TOPIC` or `TOPIC#FRAME` per
/// node): ROS 2 messages as `read_ros2` reads them, on the messages' own header
/// stamps: a row per distinct stamp, NaN for a node without a message then (it
/// predicts and fuses all the same), each step as long as the stamps are apart
/// (`dt[0]`, from `x0` to the first row, is the scenario's `dt`; the process
/// noise scales with each step). With `rate_hz`: resampled to a uniform grid at
/// that rate instead (linear interpolation, steps of `1/rate_hz`).
#[pyfunction]
#[pyo3(signature = (path, scenario, algorithm = "edc-cif", x0 = None, *, measurements = None, truth = None, rate_hz = None, **options))]
#[allow(clippy::too_many_arguments)]
pub fn replay(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
    #[pyo3(from_py_with = crate::args::class_arg::scenario)] scenario: PyRef<'_, PyScenario>,
    #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
    x0: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::opt_texts_arg::measurements)] measurements: Option<
        Vec<String>,
    >,
    #[pyo3(from_py_with = crate::args::opt_text_arg::truth)] truth: Option<String>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::rate_hz)] rate_hz: Option<f64>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRunResult> {
    let alg = self::algorithm(algorithm)?;
    let opt = options_from_kwargs(options)?;
    let x0v = x0_or_default(&scenario, x0)?;
    let sc: Scenario = scenario.inner.clone();
    let (nodes, z, dt) = match &measurements {
        None => {
            if truth.is_some() || rate_hz.is_some() {
                return Err(ParameterError::new_err(
                    "truth and rate_hz: only with measurements (the ROS 2 topics to read)",
                ));
            }
            let rep = py.allow_threads(|| read_measurements_file(&path)).py()?;
            warn_truncated(py, &path, rep.truncated.as_deref())?;
            (rep.nodes, rep.z, None)
        }
        Some(m) => {
            let rows = py.allow_threads(|| ros2_rows(&path, m, truth.as_deref(), rate_hz, None))?;
            warn_truncated(py, &path, rows.truncated.as_deref())?;
            let dt = rows.run_dt(sc.dt);
            (rows.nodes, rows.z, Some(dt))
        }
    };
    if nodes != sc.nodes() {
        return Err(ShapeError::new_err(format!(
            "{}: the file has {} nodes, the scenario {}",
            path.display(),
            nodes,
            sc.nodes()
        )));
    }
    let r = py
        .allow_threads(move || match dt {
            None => edccif_sim::run(alg, &sc, &z, &x0v, &opt, true),
            Some(d) => edccif_sim::run_with_dt(alg, &sc, &z, &d, &x0v, &opt, true),
        })
        .py()?;
    wrap_result(py, r, true)
}

/// Reads a TUM trajectory: `(t (M,), p (M, 3), q (M, 4))` (quaternion x, y, z, w).
#[pyfunction]
pub fn read_tum<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
) -> PyResult<Bound<'py, PyTuple>> {
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
pub fn write_tum(
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
    t: &Bound<'_, PyAny>,
    p: &Bound<'_, PyAny>,
) -> PyResult<()> {
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
    #[pyo3(from_py_with = crate::args::path_arg::truth)] truth: PathBuf,
    #[pyo3(from_py_with = crate::args::paths_arg::observers)] observers: Vec<PathBuf>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::rate_hz)] rate_hz: Option<f64>,
    #[pyo3(from_py_with = crate::args::flag_arg::spatial)] spatial: bool,
    #[pyo3(from_py_with = crate::args::flag_arg::with_scale)] with_scale: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let truth = logio::read_tum(truth).py()?.track;
    let obs: Vec<Track> = observers
        .into_iter()
        .map(|p| logio::read_tum(p).map(|t| t.track))
        .collect::<edccif_io::Result<_>>()
        .py()?;
    check_grid_size(rate_hz, std::iter::once(&truth).chain(&obs))?;
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

/// Refuses a `rate_hz` that is not finite and > 0, or whose grid over the
/// tracks' longest span (`span × rate` rows of the truth and every observer)
/// does not fit in the memory available (`SizeError`).
fn check_grid_size<'a>(
    rate_hz: Option<f64>,
    tracks: impl Iterator<Item = &'a Track>,
) -> PyResult<()> {
    let Some(rate) = rate_hz else { return Ok(()) };
    if !(rate.is_finite() && rate > 0.0) {
        return Err(crate::errors::ParameterError::new_err(format!(
            "rate_hz: expected a finite rate > 0 (Hz), got {rate}"
        )));
    }
    let (mut span, mut n) = (0.0f64, 0usize);
    for tr in tracks {
        if let (Some(a), Some(b)) = (tr.t.first(), tr.t.last()) {
            span = span.max(b - a);
        }
        n += 1;
    }
    let rows = (span * rate).ceil() + 1.0;
    let rows = if rows.is_finite() && rows < 1e30 {
        rows as u128
    } else {
        u128::MAX
    };
    let values_per_row = 4 * (n as u128 + 1);
    edccif_sim::limits::check_memory(
        || format!("preprocess at rate_hz = {rate} over {span:.3} s ({rows} rows of {n} tracks)"),
        rows.saturating_mul(values_per_row).saturating_mul(8),
    )
    .py()
}

/// Writes estimates (and optionally measurements, truth, covariances) as an MCAP
/// file with edccif's topics (Foxglove schemas; see docs/formats.md), for runs
/// made outside `record`, e.g. one node of a distributed run. Shapes: `fused`
/// (T, K, n) with n ≥ 3; `covariances` (T, K, n, n) (ellipsoids); `z` (T, K, 3)
/// (NaN: no measurement; default all NaN); `triggered` (T, K) (default False);
/// `sensors` (K, 3) (default: none drawn); `truth` (T, d) with d ≥ 3; `local`
/// (T, K, n). `nodes`: the K node ids used in the topic names (`/node{id}/...`),
/// default 0..K−1. Step t is at `t0_ns + round(t·dt·1e9)` ns.
#[pyfunction]
#[pyo3(signature = (path, *, dt, fused, covariances = None, z = None, triggered = None, sensors = None, truth = None, t0_ns = 0, nodes = None, local = None, ros2 = false, compression = "zstd"))]
#[allow(clippy::too_many_arguments)]
pub fn write_mcap(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
    #[pyo3(from_py_with = crate::args::real_arg::dt)] dt: f64,
    fused: &Bound<'_, PyAny>,
    covariances: Option<&Bound<'_, PyAny>>,
    z: Option<&Bound<'_, PyAny>>,
    triggered: Option<&Bound<'_, PyAny>>,
    sensors: Option<&Bound<'_, PyAny>>,
    truth: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::more::t0_ns)] t0_ns: u64,
    #[pyo3(from_py_with = crate::args::opt_counts_arg::nodes)] nodes: Option<Vec<usize>>,
    local: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::flag_arg::ros2)] ros2: bool,
    #[pyo3(from_py_with = crate::args::more::compression)] compression: &'static str,
) -> PyResult<()> {
    let (fv, fs) = f64_array(
        fused,
        "fused",
        &[Dim::Any("T"), Dim::Any("K"), Dim::Any("n")],
    )?;
    let (t, k, n) = (fs[0], fs[1], fs[2]);
    let cov = covariances
        .map(|c| {
            f64_array(
                c,
                "covariances",
                &[Dim::Is(t), Dim::Is(k), Dim::Is(n), Dim::Is(n)],
            )
        })
        .transpose()?
        .map(|x| x.0);
    let zv = match z {
        Some(a) => f64_array(a, "z", &[Dim::Is(t), Dim::Is(k), Dim::Is(3)])?.0,
        None => vec![f64::NAN; t * k * 3],
    };
    let trig = match triggered {
        Some(a) => bool_array(a, "triggered", &[Dim::Is(t), Dim::Is(k)])?,
        None => vec![false; t * k],
    };
    let sens = match sensors {
        Some(a) => f64_array(a, "sensors", &[Dim::Is(k), Dim::Is(3)])?.0,
        None => vec![f64::NAN; k * 3],
    };
    let tr = truth
        .map(|a| f64_array(a, "truth", &[Dim::Is(t), Dim::Any("d")]))
        .transpose()?
        .map(|x| x.0);
    let loc = local
        .map(|a| f64_array(a, "local", &[Dim::Is(t), Dim::Is(k), Dim::Is(n)]))
        .transpose()?
        .map(|x| x.0);
    let data = McapRunData {
        dt,
        t0_ns,
        steps: t,
        nodes: k,
        n,
        truth: tr,
        sensors: sens,
        z: zv,
        triggered: trig,
        local_estimates: loc,
        fused_estimates: fv,
        fused_covariances: cov,
        node_ids: nodes,
    };
    let opt = McapWriteOptions {
        ros2,
        compression: self::compression(compression)?,
        ..McapWriteOptions::default()
    };
    py.allow_threads(|| write_mcap_file(&path, &data, &opt))
        .py()
}
