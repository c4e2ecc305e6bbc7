//! Logs and the real-world path from Python: MCAP recording and replay, TUM files,
//! the preprocessing pipeline.

use std::path::PathBuf;

use edccif_io::mcap_io::ChunkCompression;
use edccif_io::replay_input::{prepare, InputOptions, NoiseChoice, ReplayInput};
use edccif_io::ros2::{read_ros2_file, Source};
use edccif_io::{
    self as logio, write_mcap_file, McapRunData, McapWriteOptions, PipelineOptions, Track,
};
use edccif_sim::recording::{mcap_run_data, run_recording_with_control, StoredRun, STORED_RUN};
use edccif_sim::replay::{
    check_position_scenario, resolve_stored, scenario_network, start_from_rows, ReplayReport,
    StartKind,
};
use edccif_sim::{Algorithm, Scenario};
use numpy::{PyArray1, PyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::adapters::{MotionSpec, SensorSpec};
use crate::convert::{bool_array, f64_array, finite_array, to_numpy, to_numpy_bool, Dim};
use crate::errors::{IntoPyResult, ParameterError, ScenarioError, ShapeError};
use crate::models::{PyMeasurementModel, PyMotionModel};
use crate::network::PyModelNetwork;
use crate::runner::{algorithm, options_from_kwargs, wrap_result, PyRunResult};
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
/// TUM format for evo. The MCAP file also stores what made the run (MCAP
/// metadata `edccif.run`: the scenario's TOML, the algorithm, the options, the
/// seed and the initial estimate x̂0, P0), so that `replay(mcap)` runs the same
/// filter from the same start without being told. Returns the RunResult.
///
/// Any scenario is recorded: per-node sensors of different sizes, any
/// catalogue motion, Python models by reference (stored with their
/// `python_path` made absolute). Each node's measurements keep their own size
/// (`m` in the channel's metadata); a planar target's positions are written at
/// z = 0 on the pose topics, the scene and in TUM; a scenario of the model
/// network (not the paper's kinds) has no `/node{i}/local` topics, and with
/// `ros2=True` only the nodes that measure 3 values get `/node{i}/point`.
///
/// The simulation and the run release the GIL, stop with `KeyboardInterrupt`
/// on Ctrl-C (nothing is written), and report to `progress` (True or a callable
/// `progress(done, total)` in steps: the simulation's, then the run's).
#[pyfunction]
#[pyo3(signature = (algorithm, scenario, seed = 0, *, mcap = None, tum_dir = None, ros2 = false, compression = "zstd", progress = None, **options))]
#[allow(clippy::too_many_arguments)]
pub fn record(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::args::name_arg::algorithm)] algorithm: &'static str,
    #[pyo3(from_py_with = crate::class_args::scenario)] scenario: PyRef<'_, PyScenario>,
    #[pyo3(from_py_with = crate::args::named::seed)] seed: u64,
    #[pyo3(from_py_with = crate::args::opt_path_arg::mcap)] mcap: Option<PathBuf>,
    #[pyo3(from_py_with = crate::args::opt_path_arg::tum_dir)] tum_dir: Option<PathBuf>,
    #[pyo3(from_py_with = crate::args::flag_arg::ros2)] ros2: bool,
    #[pyo3(from_py_with = crate::args::more::compression)] compression: &'static str,
    progress: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRunResult> {
    let progress = crate::drive::Progress::from_arg(progress, "record", "steps")?;
    let alg = self::algorithm(algorithm)?;
    let opt = options_from_kwargs(options)?;
    let mut wopt = McapWriteOptions {
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
    crate::refs::clear_failure();
    let r = crate::drive::drive(py, &progress, move |ctl| -> edccif_sim::Result<_> {
        let sim = edccif_sim::simulate::simulate_with_control(&sc, seed, None, ctl)?;
        let (res, local) = run_recording_with_control(alg, &sc, &sim.z, &sim.x0_hat, &opt, ctl)?;
        if let Some(path) = &mcap {
            let data = mcap_run_data(&sc, &sim, &res, Some(&local))?;
            let stored = StoredRun::new(&sc, alg, &opt, seed, &sim.x0_hat);
            wopt.metadata
                .insert(STORED_RUN.to_string(), stored.to_metadata()?);
            write_mcap_file(path, &data, &wopt)?;
        }
        if let Some(dir) = &tum_dir {
            std::fs::create_dir_all(dir).map_err(|e| {
                edccif_sim::Error::Io(format!("cannot create {}: {e}", dir.display()))
            })?;
            let n = sim.n;
            // The first position_dim states, a planar position at z = 0.
            let pd = sc.position_dim().clamp(1, 3).min(n);
            let pos = |x: &[f64]| -> [f64; 3] {
                let mut p = [0.0; 3];
                p[..pd].copy_from_slice(&x[..pd]);
                p
            };
            let t: Vec<f64> = (1..=sim.steps).map(|k| k as f64 * sc.dt).collect();
            let truth: Vec<f64> = sim.truth.chunks_exact(n).flat_map(pos).collect();
            let track = Track::from_flat(&t, &truth)?;
            logio::write_tum(dir.join("truth.txt"), &track, None)?;
            for i in 0..res.nodes {
                let p: Vec<f64> = (0..res.steps)
                    .flat_map(|k| {
                        let b = (k * res.nodes + i) * n;
                        pos(&res.estimates[b..b + n])
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
    .into_result()?
    .py();
    let r = crate::refs::finish(r)?;
    wrap_result(py, r, true)
}

/// `read_measurements_file` on a worker thread, so that Ctrl-C stops the
/// reading of a large recording (`KeyboardInterrupt`).
fn read_recording(py: Python<'_>, path: &std::path::Path) -> PyResult<edccif_io::McapReplay> {
    crate::drive::drive(py, &crate::drive::Progress::Off, |ctl| {
        edccif_io::mcap_io::read_measurements_file_watched(path, ctl)
    })
    .into_result()?
    .py()
}

/// Reads the measurements of an MCAP file written by edccif (or following its
/// documented `/node{i}/measurement` schema): `(t_ns (T,), z (T, N, 3), triggered (T, N))`,
/// NaN rows where a node has no measurement. A recording whose nodes measure
/// different sizes (a per-node scenario; each channel's metadata `m`) gives
/// `z (T, Σ m_i)`, each node's `m_i` columns in node order, as
/// `Scenario.simulate` gives it. A file whose tail is missing gives
/// the messages before the cut, with a UserWarning saying where it stopped.
#[pyfunction]
pub fn read_mcap_measurements<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
) -> PyResult<Bound<'py, PyTuple>> {
    let r = read_recording(py, &path)?;
    warn_truncated(py, &path, r.truncated.as_deref())?;
    let t: Vec<f64> = r.t_ns.iter().map(|v| *v as f64).collect();
    let t = to_numpy(py, t, &[r.steps])?;
    let z = if r.uniform() {
        to_numpy(py, r.z, &[r.steps, r.nodes, 3])?
    } else {
        let total = r.meas_dims.iter().sum();
        to_numpy(py, r.z, &[r.steps, total])?
    };
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

/// `["A=B", …]` → the frame pairs declared the same.
fn same_frames(pairs: Option<Vec<String>>) -> PyResult<Vec<(String, String)>> {
    pairs
        .unwrap_or_default()
        .iter()
        .map(|p| match p.split_once('=') {
            Some((a, b)) if !a.is_empty() && !b.is_empty() && a != b => {
                Ok((a.to_string(), b.to_string()))
            }
            _ => Err(ParameterError::new_err(format!(
                "same_frames: {p:?}; expected FRAME=OTHER_FRAME, two different non-empty frame names"
            ))),
        })
        .collect()
}

/// Reads a ROS 2 recording and makes it ready to replay (one frame, rows, noise).
#[allow(clippy::too_many_arguments)]
fn ros2_input(
    path: &std::path::Path,
    measurements: &[String],
    truth: Option<&str>,
    opt: &InputOptions,
    position: Option<&[bool]>,
) -> PyResult<(ReplayInput, edccif_io::ros2::Ros2Recording)> {
    let m = sources(measurements)?;
    let t = truth.map(Source::parse).transpose().py()?;
    let rec = read_ros2_file(path, &m, t.as_ref()).py()?;
    let all = vec![true; rec.measurements.len()];
    let input = prepare(&rec, opt, position.unwrap_or(&all))
        .map_err(|e| edccif_io::mcap_io::name_file(e, path))
        .py()?;
    Ok((input, rec))
}

fn warn(py: Python<'_>, msg: String) -> PyResult<()> {
    let warnings = py.import("warnings")?;
    warnings.call_method1(
        "warn",
        (msg, py.get_type::<pyo3::exceptions::PyUserWarning>()),
    )?;
    Ok(())
}

fn warn_truncated(py: Python<'_>, path: &std::path::Path, why: Option<&str>) -> PyResult<()> {
    match why {
        Some(why) => warn(py, format!("{}: {why}", path.display())),
        None => Ok(()),
    }
}

/// Reads positions from a ROS 2 recording (MCAP with CDR messages; zstd, lz4 or
/// uncompressed chunks): `measurements` names one source per node, `truth` an
/// optional ground-truth source, each `TOPIC` or `TOPIC#FRAME` (for `/tf`: the
/// child frame). Supported: geometry_msgs PointStamped, PoseStamped,
/// PoseWithCovarianceStamped, tf2_msgs TFMessage, nav_msgs Odometry; each
/// message's header stamp is its time, its `header.frame_id` its frame (for a
/// `/tf` source: the transform's parent frame).
///
/// Every source is brought into one frame: `frame`, default the frame of the
/// first measurement source's first message, through the recording's `/tf`
/// and `/tf_static` transforms, each message at its own stamp (a `/tf`
/// transform interpolated: translation linearly, rotation by slerp); a message
/// outside a `/tf` transform's span is dropped (counted in the report); a
/// source no transform connects is refused naming both frames and the missing
/// link. `same_frames` (["A=B", ...]) declares frames the same. Rows: the
/// distinct measurement stamps (`rate_hz=None`), or a uniform grid at
/// `rate_hz` with linear interpolation across gaps up to `max_gap_s` (default
/// 3 periods). Returns a dict with `t_ns` (T,) int64 stamps, `t` (T,) seconds
/// since the first row, `dt` (T,) step lengths (`dt[0] = 0`), `z` (T, N, 3)
/// (NaN where a node has no sample), `cov` (T, N, 3, 3) the messages' position
/// covariances rotated into the frame (NaN where a message has none, an
/// unknown or an invalid one), `truth` (T, 3) interpolated at the rows or
/// None, `frame`, `sources`, `report` (frames, transforms, dropped messages)
/// and `truncated` (None, or why the file's tail is missing; a UserWarning is
/// issued too).
#[pyfunction]
#[pyo3(signature = (path, measurements, truth = None, rate_hz = None, max_gap_s = None, *, frame = None, same_frames = None))]
#[allow(clippy::too_many_arguments)]
pub fn read_ros2<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
    #[pyo3(from_py_with = crate::args::texts_arg::measurements)] measurements: Vec<String>,
    #[pyo3(from_py_with = crate::args::opt_text_arg::truth)] truth: Option<String>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::rate_hz)] rate_hz: Option<f64>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::max_gap_s)] max_gap_s: Option<f64>,
    #[pyo3(from_py_with = crate::args::opt_text_arg::frame)] frame: Option<String>,
    #[pyo3(from_py_with = crate::args::opt_texts_arg::same_frames)] same_frames: Option<
        Vec<String>,
    >,
) -> PyResult<Bound<'py, PyDict>> {
    let opt = InputOptions {
        frame,
        same_frames: self::same_frames(same_frames)?,
        rate_hz,
        max_gap_s,
        noise: NoiseChoice::Model,
    };
    let (input, rec) =
        py.allow_threads(|| ros2_input(&path, &measurements, truth.as_deref(), &opt, None))?;
    let rows = &input.rows;
    warn_truncated(py, &path, rows.truncated.as_deref())?;
    for (src, s) in rec.sources.iter().zip(&rec.measurements) {
        if let Some(why) = &s.invalid_covariance {
            warn(
                py,
                format!(
                    "{}: source `{}`: {why}; its cov is NaN there",
                    path.display(),
                    src.name()
                ),
            )?;
        }
    }
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
    d.set_item(
        "cov",
        to_numpy(py, rows.cov.clone(), &[rows.steps, rows.nodes, 3, 3])?,
    )?;
    match &rows.truth {
        Some(tr) => d.set_item("truth", to_numpy(py, tr.clone(), &[rows.steps, 3])?)?,
        None => d.set_item("truth", py.None())?,
    }
    d.set_item("frame", input.report.frame.clone())?;
    d.set_item("sources", measurements)?;
    let report = serde_json::to_value(&input.report).unwrap_or_default();
    d.set_item("report", json_to_py(py, &report)?)?;
    d.set_item("truncated", rows.truncated.clone())?;
    Ok(d)
}

/// A motion model and its list of sensor models (Python objects).
type Models<'py> = (Bound<'py, PyAny>, Bound<'py, PyAny>);

/// The motion kinds whose start a replay takes from the rows.
fn start_kind(m: &MotionSpec) -> Option<StartKind> {
    match m {
        MotionSpec::ConstantVelocity { dim: 3, .. } => Some(StartKind::ConstantVelocity),
        MotionSpec::ConstantAcceleration { dim: 3, .. } => Some(StartKind::ConstantAcceleration),
        MotionSpec::CoordinatedTurn(_) => Some(StartKind::CoordinatedTurn),
        _ => None,
    }
}

/// The default models of a replay of position messages: constant velocity in
/// 3-D (q = 0.5 m²/s³) and a position sensor (σ = 0.01 m) per source.
fn default_models(py: Python<'_>, k: usize) -> PyResult<Models<'_>> {
    let m = py.import("edccif.models")?;
    let motion = m.getattr("ConstantVelocity")?.call1((3, 0.5))?;
    let pos = m.getattr("Position")?.call1((vec![0.01f64; 3],))?;
    let list = pyo3::types::PyList::new(py, std::iter::repeat_n(pos, k))?;
    Ok((motion, list.into_any()))
}

/// A replay on models (`ModelNetwork`'s path): the start from `x0`/`P0` or,
/// for the 3-D constant-velocity, constant-acceleration and coordinated-turn
/// models, from the first rows; the first step as long as the nominal one.
#[allow(clippy::too_many_arguments)]
fn run_models(
    py: Python<'_>,
    motion: &Bound<'_, PyAny>,
    sensors: &Bound<'_, PyAny>,
    alg_name: &str,
    x0: Option<&Bound<'_, PyAny>>,
    p0: Option<&Bound<'_, PyAny>>,
    adjacency: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
    t_ns: &[u64],
    z: &[f64],
    meas_dims: &[usize],
    dt: &[f64],
    noise: Option<&[f64]>,
    progress: &crate::drive::Progress,
) -> PyResult<(edccif_sim::RunResult, String, String)> {
    let m: PyRef<'_, PyMotionModel> = motion
        .extract()
        .map_err(|_| ParameterError::new_err("motion: expected an edccif.models motion model"))?;
    let k = meas_dims.len();
    let uniform = meas_dims.iter().all(|&m| m == 3);
    let (x0v, p0v, start) = match (x0, p0) {
        (Some(x), Some(p)) => (x.clone(), p.clone(), "given".to_string()),
        (None, None) if !uniform => {
            return Err(ParameterError::new_err(format!(
                "x0, P0: needed here; they are taken from the first rows only when every node \
                 measures a 3-D position, and the recording's nodes measure {meas_dims:?} values"
            )));
        }
        (None, None) => {
            let Some(kind) = start_kind(&m.spec) else {
                return Err(ParameterError::new_err(format!(
                    "x0, P0: needed for motion model {}; they are taken from the first rows only for \
                     ConstantVelocity(3, q), ConstantAcceleration(3, q) and CoordinatedTurn",
                    motion.repr()?
                )));
            };
            let t0 = t_ns.first().copied().unwrap_or(0);
            let ts: Vec<f64> = t_ns.iter().map(|t| (t - t0) as f64 * 1e-9).collect();
            let (xv, pd) = start_from_rows(kind, &ts, z, k).py()?;
            let n = xv.len();
            let mut pm = vec![0.0; n * n];
            for (i, v) in pd.iter().enumerate() {
                pm[i * n + i] = *v;
            }
            let np = py.import("numpy")?;
            let xa = np.call_method1("array", (xv,))?;
            let pa = np
                .call_method1("array", (pm,))?
                .call_method1("reshape", (n, n))?;
            (
                xa,
                pa,
                "from the first rows (position; velocity from up to 5 rows)".to_string(),
            )
        }
        _ => {
            return Err(ParameterError::new_err(
                "x0 and P0: give both (with models), or neither (taken from the first rows)",
            ))
        }
    };
    drop(m);
    let mut net = PyModelNetwork::create(
        motion,
        sensors,
        alg_name,
        &x0v,
        &p0v,
        adjacency,
        weights,
        Some(dt[0]),
        0.0,
        options,
    )?;
    if net.dims().len() != k {
        return Err(ShapeError::new_err(format!(
            "sensors: {} sensor models for the recording's {k} nodes; give one per node",
            net.dims().len()
        )));
    }
    if let Some(i) = (0..k).find(|&i| net.dims()[i] != meas_dims[i]) {
        return Err(ShapeError::new_err(format!(
            "sensors[{i}] measures {} values; the recording's node {i} gives {}{}",
            net.dims()[i],
            meas_dims[i],
            if uniform { " (x, y, z)" } else { "" }
        )));
    }
    let models = format!("motion {}, sensors {}", motion.repr()?, sensors.repr()?);
    let r = net.run_flat(py, z, dt, noise, progress)?;
    Ok((r, models, start))
}

/// The sources' names of an edccif recording's nodes.
fn node_sources(k: usize) -> Vec<String> {
    (0..k).map(edccif_io::mcap_io::measurement_topic).collect()
}

/// Replays the measurements of an MCAP file: an edccif recording (its
/// `/node{i}/measurement` topics) or, with `measurements`, a ROS 2 recording.
/// Returns a `RunResult` whose `report` (a dict) says what was done: frames and
/// transforms, each source's noise, messages dropped, offsets, trigger rate per
/// node, the truth's frame and RMSE (see docs/formats.md, "Replay").
///
/// **edccif recordings** (no `measurements`): a file written by
/// `edccif simulate --mcap` / `record` stores its scenario, algorithm, options,
/// seed and initial estimate; the replay runs exactly that (the original
/// estimates bit for bit) unless told otherwise: `algorithm` and `**options`
/// replace the stored ones, `x0` the stored x̂0; a `scenario` that differs from
/// the stored one is refused (`ScenarioError`) unless `override=True`. A file
/// without a stored run needs `scenario` or models (`motion` and `sensors`):
/// there is no default geometry. One scenario `dt` per row.
/// A recording of a per-node scenario replays the same way: each node's
/// measurements at their own size, which must match the scenario's nodes
/// (`ShapeError` naming the node otherwise); its Python models by reference are
/// imported from the stored `python_path` first, and one that cannot be built
/// is refused (`ScenarioError`) saying why and what to do.
///
/// **ROS 2 recordings** (`measurements`: one `TOPIC` or `TOPIC#FRAME` per node,
/// as `read_ros2` reads them): every source brought into one frame (`frame`,
/// `same_frames`, see `read_ros2`), on the messages' own header stamps (a row
/// per distinct stamp; a node without a message then predicts and still
/// fuses; each step as long as the stamps are apart) or resampled at
/// `rate_hz`. The models, as `ModelNetwork` takes them: `motion` (an
/// `edccif.models` motion model) and `sensors` (one measurement model of 3
/// values per source), with `x0`, `P0` (default for ConstantVelocity(3),
/// ConstantAcceleration(3) and CoordinatedTurn: from the first rows), `adjacency`
/// / `weights` (default: complete graph) and the options (`delta` default 0.04
/// as `ModelNetwork`); the first step as long as the stamps' median step. Or a
/// `scenario` (its models, parameters, graph, x0, P0; the first step its `dt`),
/// which must measure positions unless `scenario_sensors=True` (the messages'
/// x, y, z then read as the scenario's measurement, e.g. range, pitch,
/// azimuth). Default: ConstantVelocity(3, q=0.5) and Position(0.01) per source.
/// `noise`: `"message"` (default: each message's position covariance, rotated
/// into the frame, where it has a usable one; else the sensor model's R, with
/// a UserWarning once per source whose messages say "unknown"), `"scenario"`
/// (the sensor model's R) or a standard deviation in metres. The steps run
/// serially (`threads` > 1 is refused).
#[pyfunction]
#[pyo3(signature = (path, scenario = None, algorithm = None, x0 = None, *, P0 = None, motion = None, sensors = None, measurements = None, truth = None, rate_hz = None, frame = None, same_frames = None, noise = "message".to_string(), scenario_sensors = false, adjacency = None, weights = None, r#override = false, progress = None, **options))]
// The text signature by hand: the generated one shows the raw identifier's default as `...`.
#[pyo3(
    text_signature = "(path, scenario=None, algorithm=None, x0=None, *, P0=None, motion=None, sensors=None, measurements=None, truth=None, rate_hz=None, frame=None, same_frames=None, noise='message', scenario_sensors=False, adjacency=None, weights=None, override=False, progress=None, **options)"
)]
#[allow(clippy::too_many_arguments, non_snake_case)]
pub fn replay(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::args::path_arg::path)] path: PathBuf,
    #[pyo3(from_py_with = crate::class_args::opt_scenario)] scenario: Option<PyRef<'_, PyScenario>>,
    #[pyo3(from_py_with = crate::args::name_arg::opt_algorithm)] algorithm: Option<&'static str>,
    x0: Option<&Bound<'_, PyAny>>,
    P0: Option<&Bound<'_, PyAny>>,
    motion: Option<&Bound<'_, PyAny>>,
    sensors: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::opt_texts_arg::measurements)] measurements: Option<
        Vec<String>,
    >,
    #[pyo3(from_py_with = crate::args::opt_text_arg::truth)] truth: Option<String>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::rate_hz)] rate_hz: Option<f64>,
    #[pyo3(from_py_with = crate::args::opt_text_arg::frame)] frame: Option<String>,
    #[pyo3(from_py_with = crate::args::opt_texts_arg::same_frames)] same_frames: Option<
        Vec<String>,
    >,
    #[pyo3(from_py_with = crate::args::text_arg::noise)] noise: String,
    #[pyo3(from_py_with = crate::args::flag_arg::scenario_sensors)] scenario_sensors: bool,
    adjacency: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::more::override_flag)] r#override: bool,
    progress: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRunResult> {
    let none = |o: Option<&Bound<'_, PyAny>>| o.is_none_or(|o| o.is_none());
    let models_given = match (none(motion), none(sensors)) {
        (false, false) => true,
        (true, true) => false,
        _ => {
            return Err(ParameterError::new_err(
                "motion and sensors: give both (a motion model and one sensor model per source), or neither",
            ))
        }
    };
    let call = ReplayCall {
        py,
        file: path.display().to_string(),
        path,
        scenario: scenario.as_deref(),
        alg: algorithm.map(self::algorithm).transpose()?,
        opt: options_from_kwargs(options)?,
        noise: noise.parse::<NoiseChoice>().py()?,
        x0: x0.filter(|o| !o.is_none()),
        p0: P0.filter(|o| !o.is_none()),
        models: if models_given {
            motion.zip(sensors)
        } else {
            None
        },
        adjacency,
        weights,
        options,
        r#override,
        progress: crate::drive::Progress::from_arg(progress, "replay", "steps")?,
    };
    if call.models.is_some() && call.scenario.is_some() {
        return Err(ParameterError::new_err(
            "give either a scenario or models (motion=, sensors=), not both",
        ));
    }
    if scenario_sensors && call.scenario.is_none() {
        return Err(ParameterError::new_err(
            "scenario_sensors=True: only with a scenario (its sensors then read the messages)",
        ));
    }
    if call.models.is_none() && (call.p0.is_some() || adjacency.is_some() || weights.is_some()) {
        return Err(ParameterError::new_err(
            "P0, adjacency and weights: only with models (motion=, sensors=); a scenario has its own",
        ));
    }
    let mut report = ReplayReport {
        file: call.file.clone(),
        kind: String::new(),
        algorithm: String::new(),
        models: String::new(),
        steps: 0,
        nodes: 0,
        x0: String::new(),
        input: None,
        stored: None,
        timing: String::new(),
        offsets: String::new(),
        per_node: Vec::new(),
        trigger_rate: 0.0,
        position_rmse_m: None,
        truth_same_frame: None,
    };
    let (res, sources, truth_rows) = match measurements {
        None => {
            if truth.is_some()
                || rate_hz.is_some()
                || frame.is_some()
                || same_frames.is_some()
                || scenario_sensors
            {
                return Err(ParameterError::new_err(
                    "truth, rate_hz, frame, same_frames, scenario_sensors: only with measurements (the ROS 2 topics to read)",
                ));
            }
            call.recording(&mut report)?
        }
        Some(m) => {
            if r#override {
                return Err(ParameterError::new_err(
                    "override: only for edccif recordings (a ROS 2 recording stores no scenario)",
                ));
            }
            let input_opt = InputOptions {
                frame,
                same_frames: self::same_frames(same_frames)?,
                rate_hz,
                max_gap_s: None,
                noise: call.noise,
            };
            call.ros2(m, truth, &input_opt, scenario_sensors, &mut report)?
        }
    };
    report.fill_run(&res, &sources, truth_rows.as_deref());
    let value = serde_json::to_value(&report).unwrap_or_default();
    let dict = json_to_py(py, &value)?.unbind();
    Ok(wrap_result(py, res, true)?.with_report(dict))
}

/// What a replay ran: the run, its sources' names and the truth's rows (a ROS
/// 2 recording's `truth` topic).
type Replayed = (edccif_sim::RunResult, Vec<String>, Option<Vec<f64>>);

/// One `replay` call's arguments, checked against each other.
struct ReplayCall<'a, 'py> {
    py: Python<'py>,
    path: PathBuf,
    file: String,
    scenario: Option<&'a PyScenario>,
    alg: Option<Algorithm>,
    opt: edccif_sim::RunOptions,
    noise: NoiseChoice,
    x0: Option<&'a Bound<'py, PyAny>>,
    p0: Option<&'a Bound<'py, PyAny>>,
    /// `motion` and `sensors`, given together.
    models: Option<(&'a Bound<'py, PyAny>, &'a Bound<'py, PyAny>)>,
    adjacency: Option<&'a Bound<'py, PyAny>>,
    weights: Option<&'a Bound<'py, PyAny>>,
    options: Option<&'a Bound<'py, PyDict>>,
    r#override: bool,
    progress: crate::drive::Progress,
}

fn scenario_desc(sc: &Scenario) -> String {
    format!(
        "scenario `{}`: {:?} motion, {:?} sensors",
        sc.name,
        sc.motion,
        sc.node_specs()
            .iter()
            .map(|n| n.sensor.kind())
            .collect::<Vec<_>>()
    )
}

impl ReplayCall<'_, '_> {
    fn alg_name(&self) -> &'static str {
        self.alg.map_or("edc-cif", |a| a.name())
    }

    /// An edccif recording: its stored run, or the models given.
    fn recording(&self, report: &mut ReplayReport) -> PyResult<Replayed> {
        if let NoiseChoice::Sigma(_) = self.noise {
            return Err(ParameterError::new_err(
                "noise=VALUE: only for ROS 2 position messages (with measurements); an edccif \
                 recording's steps take the model's noise",
            ));
        }
        let rep = read_recording(self.py, &self.path)?;
        warn_truncated(self.py, &self.path, rep.truncated.as_deref())?;
        let stored = StoredRun::find(&rep.metadata).py()?;
        report.kind = "edccif".into();
        report.timing = "log times (one step of the scenario's dt per row)".into();
        report.offsets = "none".into();
        let srcs = node_sources(rep.nodes);
        let res = match self.models {
            Some((motion, sensors)) => {
                self.recording_on_models(rep, stored.as_ref(), motion, sensors, report)?
            }
            None => self.recording_stored(rep, stored.as_ref(), report)?,
        };
        Ok((res, srcs, None))
    }

    /// An edccif recording on the models given: each step as long as the rows
    /// are apart, the first as long as their median step.
    fn recording_on_models(
        &self,
        rep: edccif_io::McapReplay,
        stored: Option<&StoredRun>,
        motion: &Bound<'_, PyAny>,
        sensors: &Bound<'_, PyAny>,
        report: &mut ReplayReport,
    ) -> PyResult<edccif_sim::RunResult> {
        let file = &self.file;
        if stored.is_some() && !self.r#override {
            return Err(ScenarioError::new_err(format!(
                "{file} stores the run that made it (scenario `{}`); replaying it with \
                 other models needs override=True (CLI --override), or replay it \
                 without models",
                stored.map_or("", |s| s.scenario.name.as_str())
            )));
        }
        let t0 = rep.t_ns.first().copied().unwrap_or(0);
        let mut dt: Vec<f64> = rep
            .t_ns
            .iter()
            .scan(t0, |prev, t| {
                let d = (t - *prev) as f64 * 1e-9;
                *prev = *t;
                Some(d)
            })
            .collect();
        let nominal = {
            let mut d: Vec<f64> = dt.iter().skip(1).copied().collect();
            d.sort_by(f64::total_cmp);
            d.get(d.len() / 2).copied()
        };
        let Some(nominal) = nominal else {
            return Err(ParameterError::new_err(format!(
                "{file}: fewer than two rows; a replay on models needs the step from two stamps"
            )));
        };
        dt[0] = nominal;
        let (r, models, start) = run_models(
            self.py,
            motion,
            sensors,
            self.alg_name(),
            self.x0,
            self.p0,
            self.adjacency,
            self.weights,
            self.options,
            &rep.t_ns,
            &rep.z,
            &rep.meas_dims,
            &dt,
            None,
            &self.progress,
        )?;
        report.models = models;
        report.x0 = start;
        report.timing = "log times (each step as long as the rows are apart)".into();
        Ok(r)
    }

    /// An edccif recording on its stored run (or the scenario given), each
    /// node's measurements at the scenario's sizes.
    fn recording_stored(
        &self,
        rep: edccif_io::McapReplay,
        stored: Option<&StoredRun>,
        report: &mut ReplayReport,
    ) -> PyResult<edccif_sim::RunResult> {
        let (py, file) = (self.py, &self.file);
        let sc = self.scenario.map(|s| &s.inner);
        let resolved =
            resolve_stored(file, stored, sc, self.alg, &self.opt, self.r#override).py()?;
        if rep.nodes != resolved.scenario.nodes() {
            return Err(ShapeError::new_err(format!(
                "{file}: the file has {} nodes, the scenario {}",
                rep.nodes,
                resolved.scenario.nodes()
            )));
        }
        let want = resolved.scenario.meas_dims();
        if rep.meas_dims != want {
            let i = (0..want.len())
                .find(|&i| rep.meas_dims[i] != want[i])
                .unwrap_or(0);
            return Err(ShapeError::new_err(format!(
                "{file}: node {i} measures {} values in the file (its channel {}), the \
                 scenario's node {i} ({}) measures {}; every node's measurement size must \
                 match: replay with the scenario the file was made with (the stored one: \
                 leave out scenario=)",
                rep.meas_dims[i],
                edccif_io::mcap_io::measurement_topic(i),
                resolved.scenario.node_specs()[i].sensor.kind(),
                want[i]
            )));
        }
        if resolved.scenario.has_python_models() {
            // The models are imported here, so that a module that is not
            // importable is refused with what to do.
            crate::refs::check(&resolved.scenario).map_err(|e| {
                let dirs = if resolved.scenario.python_path.is_empty() {
                    "none".to_string()
                } else {
                    resolved.scenario.python_path.join(", ")
                };
                let cause = e.value(py).str().map(|s| s.to_string()).unwrap_or_default();
                let err = ScenarioError::new_err(format!(
                    "{file}: the recorded scenario `{}` names Python models, which the \
                     replay imports (python_path stored in the file: {dirs}), and one \
                     cannot be built: {cause}; make its module importable (put its \
                     directory on PYTHONPATH, or where the stored python_path points), or \
                     pass the scenario file with the models (scenario=FILE with \
                     override=True; CLI --scenario FILE --override)",
                    resolved.scenario.name
                ));
                err.set_cause(py, Some(e));
                err
            })?;
        }
        let n = resolved.scenario.state_dim();
        let (x0v, x0_from) = match self.x0 {
            Some(o) => (
                crate::convert::finite_array(o, "x0", &[Dim::Is(n)])?.0,
                "given".to_string(),
            ),
            None => (resolved.x0.clone(), resolved.stored.x0.clone()),
        };
        report.models = scenario_desc(&resolved.scenario);
        report.x0 = x0_from;
        report.stored = Some(resolved.stored.clone());
        let z = rep.z;
        crate::refs::clear_failure();
        // Ctrl-C stops a long replay (the run checks it every step).
        let r = crate::drive::drive(py, &self.progress, move |ctl| {
            edccif_sim::faults::run_with_control(
                resolved.algorithm,
                &resolved.scenario,
                &z,
                &x0v,
                &resolved.options,
                None,
                None,
                true,
                ctl,
            )
        })
        .into_result()?
        .py();
        crate::refs::finish(r)
    }

    /// A ROS 2 recording: the topics `m` brought into one frame, run on the
    /// scenario or the models (given or the defaults).
    fn ros2(
        &self,
        m: Vec<String>,
        truth: Option<String>,
        input_opt: &InputOptions,
        scenario_sensors: bool,
        report: &mut ReplayReport,
    ) -> PyResult<Replayed> {
        let (py, file) = (self.py, &self.file);
        report.kind = "ros2".into();
        // Whether each node's sensor measures a position.
        let (model_objs, position) = self.ros2_models(m.len(), scenario_sensors)?;
        let path = &self.path;
        let (input, _rec) = py
            .allow_threads(|| ros2_input(path, &m, truth.as_deref(), input_opt, Some(&position)))?;
        warn_truncated(py, &self.path, input.rows.truncated.as_deref())?;
        for u in &input.report.noise {
            if let Some(w) = &u.warning {
                warn(py, format!("{file}: {w}"))?;
            }
        }
        let rows = &input.rows;
        let r = match (self.scenario, &model_objs) {
            (Some(sc), _) => {
                let sc = sc.inner.clone();
                if rows.nodes != sc.nodes() {
                    return Err(ShapeError::new_err(format!(
                        "{file}: {} measurement sources, the scenario has {} nodes",
                        rows.nodes,
                        sc.nodes()
                    )));
                }
                let n = sc.state_dim();
                let (x0v, x0_from) = match self.x0 {
                    Some(o) => (
                        crate::convert::finite_array(o, "x0", &[Dim::Is(n)])?.0,
                        "given",
                    ),
                    None => (sc.x0.clone(), "the scenario's x0"),
                };
                report.models = scenario_desc(&sc);
                report.x0 = x0_from.into();
                let dt = rows.run_dt(sc.dt);
                let a = self.alg.unwrap_or(Algorithm::EdcCif);
                let z = rows.z.clone();
                let noise = input.noise.clone();
                let opt = self.opt.clone();
                crate::drive::drive(py, &self.progress, move |ctl| {
                    scenario_network(a, &sc, &x0v, &opt)?.run_with_control(
                        &z,
                        &dt,
                        noise.as_deref(),
                        ctl,
                    )
                })
                .into_result()?
                .py()?
            }
            (None, Some((mo, se))) => {
                let Some(nominal) = rows.nominal_dt() else {
                    return Err(ParameterError::new_err(format!(
                        "{file}: fewer than two stamps; pass rate_hz (CLI --rate) or a scenario (its dt)"
                    )));
                };
                let dt = rows.run_dt(nominal);
                let (r, models, start) = run_models(
                    py,
                    mo,
                    se,
                    self.alg_name(),
                    self.x0,
                    self.p0,
                    self.adjacency,
                    self.weights,
                    self.options,
                    &rows.t_ns,
                    &rows.z,
                    &vec![3; rows.nodes],
                    &dt,
                    input.noise.as_deref(),
                    &self.progress,
                )?;
                report.models = if self.models.is_some() {
                    models
                } else {
                    format!("default: {models}")
                };
                report.x0 = start;
                r
            }
            (None, None) => unreachable!("models are set without a scenario"),
        };
        report.truth_same_frame = input.report.truth.as_ref().map(|t| t.same_frame);
        report.timing = input.report.timing.clone();
        report.offsets = input.report.offsets.clone();
        let truth_rows = input.rows.truth.clone();
        report.input = Some(input.report);
        Ok((r, m, truth_rows))
    }

    /// The models of a ROS 2 replay of `sources` topics (none with a scenario:
    /// it has its own) and whether each node's sensor measures a position.
    fn ros2_models(
        &self,
        sources: usize,
        scenario_sensors: bool,
    ) -> PyResult<(Option<Models<'_>>, Vec<bool>)> {
        if let Some(sc) = self.scenario {
            if !sc.inner.is_typed() {
                return Err(ScenarioError::new_err(format!(
                    "measurements (a ROS 2 recording): scenario `{}` has {}; a ROS 2 \
                     replay with a scenario runs the paper's kinds only (one \
                     [measurement] for every node, a 3-D coordinated-turn, \
                     constant-velocity or constant-acceleration motion); give the models \
                     instead (Python: motion=, sensors= with one edccif.models model of 3 \
                     values per source; CLI: --motion), or read the messages with \
                     edccif.read_ros2 and run them with edccif.run(algorithm, scenario, z, \
                     dt=...) on z (T, sum of the nodes' m)",
                    sc.inner.name,
                    if sc.inner.nodes.is_empty() {
                        format!("the motion `{}`", sc.inner.motion.kind())
                    } else {
                        "a sensor of its own per node ([[nodes]])".to_string()
                    }
                )));
            }
            check_position_scenario(&sc.inner, scenario_sensors).py()?;
            let pos = sc
                .inner
                .node_specs()
                .iter()
                .all(|n| matches!(n.sensor, edccif_sim::SensorSpec::Position { .. }));
            return Ok((None, vec![pos; sources]));
        }
        let (mo, se) = match self.models {
            Some((a, b)) => (a.clone(), b.clone()),
            None => default_models(self.py, sources)?,
        };
        let len = se.len().map_err(|_| {
            ParameterError::new_err(
                "sensors: expected a sequence of edccif.models measurement models",
            )
        })?;
        if len != sources {
            return Err(ShapeError::new_err(format!(
                "sensors: {len} sensor models for {sources} measurement sources; give one per source"
            )));
        }
        let mut pos = Vec::with_capacity(len);
        for i in 0..len {
            let s = se.get_item(i)?;
            let s: PyRef<'_, PyMeasurementModel> = s.extract().map_err(|_| {
                ParameterError::new_err(format!(
                    "sensors[{i}]: expected an edccif.models measurement model"
                ))
            })?;
            pos.push(matches!(s.spec, SensorSpec::Position3(_)));
        }
        Ok((Some((mo, se)), pos))
    }
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

/// The paper's preprocessing pipeline on TUM files: duplicated stamps dropped
/// and counted (`duplicates="refuse"`: refused before any work), origin outliers
/// and abnormal time gaps removed, the observers' clocks aligned with the truth's
/// (`align`: `"estimate"` (default) minimises the alignment residual over each
/// observer's offset within `offset_window` s of the start alignment, `"start"`
/// assumes the recordings started together, `"none"` takes the clocks as
/// synchronised; `offsets` gives some observers' offsets instead, a dict from the
/// observer's index or file stem to seconds, `t_truth = t_observer + offset`),
/// the common span, spatial alignment of each observer onto the truth (Umeyama,
/// `with_scale` optional; `spatial=False` when the observers are already in the
/// truth's frame), truth downsampling and interpolation to a common rate
/// (`rate_hz`, default: the observers' median rate). An observer whose alignment
/// residual exceeds `residual_factor` times its own noise gets a `UserWarning`.
/// Returns a dict with `t (T,)`, `truth (T, 3)`, `z (T, N, 3)` (NaN where
/// missing), `dt`, and `report` (what each step removed or changed; the offsets
/// applied under `report["clock"]`). The work runs with the GIL released, stops
/// with `KeyboardInterrupt` on Ctrl-C, and reports to `progress` (True: a bar
/// or a line every few seconds on stderr; a callable: `progress(done, total)`,
/// counted in the offsets tried while estimating clocks and one unit per
/// observer and stage after that; see `edccif_io::preprocess::run_pipeline_watched`).
#[pyfunction]
#[pyo3(signature = (truth, observers, rate_hz = None, spatial = true, with_scale = false, *, align = "estimate".to_string(), offsets = None, offset_window = 2.0, residual_factor = 3.0, duplicates = "drop".to_string(), progress = None))]
#[pyo3(
    text_signature = "(truth, observers, rate_hz=None, spatial=True, with_scale=False, *, align='estimate', offsets=None, offset_window=2.0, residual_factor=3.0, duplicates='drop', progress=None)"
)]
#[allow(clippy::too_many_arguments)]
pub fn preprocess<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = crate::args::path_arg::truth)] truth: PathBuf,
    #[pyo3(from_py_with = crate::args::paths_arg::observers)] observers: Vec<PathBuf>,
    #[pyo3(from_py_with = crate::args::opt_real_arg::rate_hz)] rate_hz: Option<f64>,
    #[pyo3(from_py_with = crate::args::flag_arg::spatial)] spatial: bool,
    #[pyo3(from_py_with = crate::args::flag_arg::with_scale)] with_scale: bool,
    #[pyo3(from_py_with = crate::args::text_arg::align)] align: String,
    offsets: Option<&Bound<'py, PyAny>>,
    #[pyo3(from_py_with = crate::args::real_arg::offset_window)] offset_window: f64,
    #[pyo3(from_py_with = crate::args::real_arg::residual_factor)] residual_factor: f64,
    #[pyo3(from_py_with = crate::args::text_arg::duplicates)] duplicates: String,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let progress = crate::drive::Progress::from_arg(progress, "preprocess", "units")?;
    let time_align = align.parse::<edccif_io::preprocess::TimeAlign>().py()?;
    let duplicates = duplicates
        .parse::<edccif_io::preprocess::DuplicateStamps>()
        .py()?;
    if observers.is_empty() {
        return Err(crate::errors::ParameterError::new_err(
            "observers: expected at least one observer file",
        ));
    }
    let stems: Vec<String> = observers
        .iter()
        .map(|p| {
            p.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        })
        .collect();
    let mut given = Vec::new();
    if let Some(d) = offsets.filter(|o| !o.is_none()) {
        let d = d.downcast::<PyDict>().map_err(|_| {
            crate::errors::argument_type_error(
                py,
                format!(
                    "offsets: expected a dict from observer (index or file stem) to seconds, got {}",
                    d.get_type()
                        .name()
                        .map_or_else(|_| "?".into(), |n| n.to_string())
                ),
            )
        })?;
        for (k, v) in d.iter() {
            let i = observer_index(&k, &stems)?;
            let secs: f64 = v.extract().map_err(|_| {
                crate::errors::ParameterError::new_err(format!(
                    "offsets[{}]: expected a number of seconds, got {}",
                    k.repr().map(|r| r.to_string()).unwrap_or_default(),
                    v.repr().map(|r| r.to_string()).unwrap_or_default()
                ))
            })?;
            given.push((i, secs));
        }
    }
    let mut opt = PipelineOptions {
        rate_hz,
        time_align,
        offsets: given,
        offset_window_s: offset_window,
        residual_factor,
        duplicates,
        ..PipelineOptions::default()
    };
    if !spatial {
        opt.spatial = None;
    } else if let Some(s) = opt.spatial.as_mut() {
        s.with_scale = with_scale;
    }
    // Every input is read and checked before any work runs.
    opt.check_clock(observers.len()).py()?;
    let truth = logio::read_tum(truth).py()?.track;
    let obs: Vec<Track> = observers
        .into_iter()
        .map(|p| logio::read_tum(p).map(|t| t.track))
        .collect::<edccif_io::Result<_>>()
        .py()?;
    check_grid_size(rate_hz, std::iter::once(&truth).chain(&obs))?;
    // On a worker thread (Ctrl-C and progress are served here meanwhile).
    let a = crate::drive::drive(py, &progress, move |ctl| {
        edccif_io::preprocess::run_pipeline_watched(&truth, &obs, &opt, ctl)
    })
    .into_result()?
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
    let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
    for w in &a.report.clock.warnings {
        PyErr::warn(py, &category, &std::ffi::CString::new(w.as_str())?, 1)?;
    }
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

/// An observer named by its index (an int, or a string of one) or its file's
/// stem; otherwise a `ParameterError` listing the names.
fn observer_index(k: &Bound<'_, PyAny>, stems: &[String]) -> PyResult<usize> {
    let n = stems.len();
    let found = if k.is_instance_of::<pyo3::types::PyBool>() {
        None
    } else if let Ok(i) = k.extract::<i64>() {
        usize::try_from(i).ok().filter(|&i| i < n)
    } else if let Ok(s) = k.extract::<String>() {
        s.trim()
            .parse::<usize>()
            .ok()
            .filter(|&i| i < n)
            .or_else(|| stems.iter().position(|t| *t == s))
    } else {
        None
    };
    found.ok_or_else(|| {
        crate::errors::ParameterError::new_err(format!(
            "offsets: {} is not an observer; expected an index 0..{} or a file stem ({}); the truth \
             is the reference clock",
            k.repr().map(|r| r.to_string()).unwrap_or_default(),
            n.saturating_sub(1),
            stems.join(", ")
        ))
    })
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
        position_dim: None,
        sensors: sens,
        meas_dims: None,
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
