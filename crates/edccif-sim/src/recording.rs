//! A simulated run as a log: the [`McapRunData`] of a run (for
//! [`edccif_io::write_mcap`]), a run that also records every node's local
//! estimate, and what made the run ([`StoredRun`], stored in the file's MCAP
//! metadata so that a replay needs no scenario).
//!
//! ```
//! use edccif_io::mcap_io::{mcap_to_bytes, read_measurements, McapWriteOptions};
//! use edccif_sim::recording::mcap_run_data;
//! use edccif_sim::{run, simulate, Algorithm, RunOptions, Scenario};
//! let mut sc = Scenario::paper(4);
//! sc.steps = 20;
//! let sim = simulate(&sc, 0)?;
//! let res = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), true)?;
//! let data = mcap_run_data(&sc, &sim, &res, None)?;
//! let bytes = mcap_to_bytes(&data, &McapWriteOptions::default())?;
//! let replay = read_measurements(&bytes)?;
//! assert_eq!((replay.steps, replay.nodes), (20, 4));
//! assert_eq!(replay.z, sim.z);
//! # Ok::<(), edccif_sim::Error>(())
//! ```

use std::collections::BTreeMap;

use edccif_io::McapRunData;

use crate::algorithm::{Algorithm, RunOptions};
use crate::error::{Error, Result};
use crate::runner::RunResult;
use crate::scenario::{Scenario, SensorSpec};
use crate::simulate::Simulation;

/// The data of a simulated run: truth and measurements from `sim` (each
/// node's own `m_i` values), estimates, covariances (when recorded) and
/// trigger flags from `res`, sensor positions from the scenario (`sensors`
/// of the uniform form; a `[[nodes]]` sensor's position, a planar one at
/// `z = 0`, none drawn for a sensor without one), the position's
/// dimension ([`Scenario::position_dim`]), and optional local estimates
/// `(T, N, n)` (see [`run_recording`]; an empty slice: not recorded). Step 0
/// is at time 0.
///
/// ```
/// use edccif_io::mcap_io::{mcap_to_bytes, read_measurements, McapWriteOptions};
/// use edccif_sim::recording::mcap_run_data;
/// use edccif_sim::{run, simulate, Algorithm, RunOptions, Scenario};
/// // A per-node scenario: every node's measurement at its own size.
/// let sc = Scenario { steps: 10, ..Scenario::paper(3).per_node() };
/// let sim = simulate(&sc, 0)?;
/// let res = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), true)?;
/// let data = mcap_run_data(&sc, &sim, &res, None)?;
/// let replay = read_measurements(&mcap_to_bytes(&data, &McapWriteOptions::default())?)?;
/// assert_eq!((replay.meas_dims, replay.z), (sim.meas_dims, sim.z));
/// # Ok::<(), edccif_sim::Error>(())
/// ```
pub fn mcap_run_data(
    sc: &Scenario,
    sim: &Simulation,
    res: &RunResult,
    local_estimates: Option<&[f64]>,
) -> Result<McapRunData> {
    // The uniform form names every node's position; [[nodes]] the sensors' own.
    let sensors: Vec<f64> = if sc.nodes.is_empty() {
        sc.sensors.iter().flatten().copied().collect()
    } else {
        sc.nodes
            .iter()
            .flat_map(|nd| sensor_position(&nd.sensor))
            .collect()
    };
    let d = McapRunData {
        dt: sc.dt,
        t0_ns: 0,
        steps: res.steps,
        nodes: res.nodes,
        n: res.n,
        position_dim: Some(sc.position_dim().clamp(1, 3).min(res.n)),
        truth: Some(sim.truth.clone()),
        sensors,
        meas_dims: Some(sim.meas_dims.clone()),
        z: sim.z.clone(),
        triggered: res.triggered.clone(),
        local_estimates: local_estimates
            .filter(|l| !l.is_empty())
            .map(<[f64]>::to_vec),
        fused_estimates: res.estimates.clone(),
        fused_covariances: if res.covariances.is_empty() {
            None
        } else {
            Some(res.covariances.clone())
        },
        node_ids: None,
    };
    d.validate()?;
    Ok(d)
}

/// A sensor's position as drawn in a recording's scene: `[x, y, z]`, a
/// planar one at `z = 0`, NaN for a sensor without a position.
fn sensor_position(s: &SensorSpec) -> [f64; 3] {
    let p: &[f64] = match s {
        SensorSpec::RangePitchAzimuth { position, .. } => position,
        SensorSpec::RangeBearing { position, .. } | SensorSpec::BearingOnly { position, .. } => {
            position
        }
        SensorSpec::RangeOnly { position, .. } => position,
        _ => &[],
    };
    match p {
        [x, y] => [*x, *y, 0.0],
        [x, y, z] => [*x, *y, *z],
        _ => [f64::NAN; 3],
    }
}

/// Runs `alg` like [`crate::run`] (covariances always recorded) and also records
/// every node's local (pre-combination) estimate, `(T, N, n)`, for the
/// `/node{i}/local` topics. A scenario of the model network (not
/// [`is_typed`](Scenario::is_typed): per-node sensors, other motions, Python
/// models) runs as [`crate::run`] runs it and records no local estimates
/// (the returned vector is empty).
///
/// ```
/// use edccif_sim::recording::run_recording;
/// use edccif_sim::{simulate, Algorithm, RunOptions, Scenario};
/// let mut sc = Scenario::paper(3);
/// sc.steps = 5;
/// let sim = simulate(&sc, 0)?;
/// let (res, local) = run_recording(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default())?;
/// assert_eq!(local.len(), res.estimates.len());
/// # Ok::<(), edccif_sim::Error>(())
/// ```
pub fn run_recording(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &RunOptions,
) -> Result<(RunResult, Vec<f64>)> {
    run_recording_with_control(alg, sc, z, x0, opt, crate::control::Control::none())
}

/// [`run_recording`] under a [`Control`](crate::control::Control): checked for
/// cancellation every step ([`Error::Interrupted`]),
/// counting steps as its progress.
pub fn run_recording_with_control(
    alg: Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &RunOptions,
    ctl: &crate::control::Control,
) -> Result<(RunResult, Vec<f64>)> {
    if !sc.is_typed() {
        let res = crate::faults::run_with_control(alg, sc, z, x0, opt, None, None, true, ctl)?;
        return Ok((res, Vec::new()));
    }
    let mut local = Vec::new();
    let res = crate::runner::run_inner(
        alg,
        sc,
        z,
        x0,
        opt,
        None,
        None,
        true,
        Some(&mut local),
        ctl,
        ctl,
    )?;
    Ok((res, local))
}

/// Name of the MCAP Metadata record that holds a [`StoredRun`].
pub const STORED_RUN: &str = "edccif.run";

/// Version of the [`STORED_RUN`] record's layout.
const STORED_RUN_FORMAT: &str = "1";

/// Everything that made a recorded run, stored in its MCAP file (Metadata
/// record [`STORED_RUN`]) so that a replay runs the same filter from the same
/// start without being told: the scenario (its TOML, which holds the geometry,
/// the models, `δ`, `σ1`, `σ2`, the graph), the algorithm, the run options,
/// the simulation seed and the initial estimate `(x̂0, P0)`.
///
/// | key | value |
/// |---|---|
/// | `format` | `1` |
/// | `edccif_version` | the version that wrote it |
/// | `scenario` | the scenario as TOML ([`Scenario::to_toml`]) |
/// | `models` | JSON `{"motion": …, "measurement": …, "sensors": […]}` (the scenario's, for reading) |
/// | `algorithm` | e.g. `edc-cif` |
/// | `options` | JSON of [`RunOptions`] (without `threads`) |
/// | `seed` | the simulation seed |
/// | `x0` | JSON array: `x̂0` (shortest round-trip decimals: read back bit for bit) |
/// | `P0` | JSON array: `P0` row-major `n × n` |
///
/// ```
/// use edccif_sim::recording::StoredRun;
/// use edccif_sim::{Algorithm, RunOptions, Scenario};
/// let sc = Scenario::paper(4);
/// let stored = StoredRun::new(&sc, Algorithm::EdcCif, &RunOptions::default(), 7, &[5.01, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]);
/// let back = StoredRun::from_metadata(&stored.to_metadata()?)?;
/// assert_eq!(back, stored);
/// assert_eq!(back.p0[8], 0.01); // P0 = diag(p0_diag), row-major
/// # Ok::<(), edccif_sim::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct StoredRun {
    /// The scenario.
    pub scenario: Scenario,
    /// The row that ran.
    pub algorithm: Algorithm,
    /// The run's options (`threads` left out: the numbers do not depend on it).
    pub options: RunOptions,
    /// The simulation seed.
    pub seed: u64,
    /// The initial estimate `x̂0`.
    pub x0: Vec<f64>,
    /// The initial covariance `P0`, row-major `n × n`.
    pub p0: Vec<f64>,
}

impl StoredRun {
    /// The stored form of a run of `alg` on `sc` from `x0` (and the scenario's
    /// `P0`); the scenario's `python_path` made absolute ([`portable`]).
    pub fn new(sc: &Scenario, alg: Algorithm, opt: &RunOptions, seed: u64, x0: &[f64]) -> Self {
        let n = sc.state_dim();
        let mut p0 = vec![0.0; n * n];
        for (i, v) in sc.p0_diag.iter().enumerate() {
            p0[i * n + i] = *v;
        }
        Self {
            scenario: portable(sc),
            algorithm: alg,
            options: RunOptions {
                threads: None,
                ..opt.clone()
            },
            seed,
            x0: x0.to_vec(),
            p0,
        }
    }

    /// The key/value pairs of the Metadata record.
    pub fn to_metadata(&self) -> Result<BTreeMap<String, String>> {
        let json = |v: serde_json::Value| v.to_string();
        let sc = &self.scenario;
        let mut m = BTreeMap::new();
        m.insert("format".into(), STORED_RUN_FORMAT.into());
        m.insert("edccif_version".into(), env!("CARGO_PKG_VERSION").into());
        m.insert("scenario".into(), sc.to_toml()?);
        m.insert(
            "models".into(),
            json(if sc.nodes.is_empty() {
                serde_json::json!({
                    "motion": sc.motion, "measurement": sc.measurement, "sensors": sc.sensors
                })
            } else {
                serde_json::json!({ "motion": sc.motion, "nodes": sc.nodes })
            }),
        );
        m.insert("algorithm".into(), self.algorithm.name().into());
        m.insert(
            "options".into(),
            serde_json::to_string(&self.options).map_err(|e| Error::Io(e.to_string()))?,
        );
        m.insert("seed".into(), self.seed.to_string());
        m.insert("x0".into(), json(serde_json::json!(self.x0)));
        m.insert("P0".into(), json(serde_json::json!(self.p0)));
        Ok(m)
    }

    /// Reads the Metadata record back; every key is checked (a damaged or
    /// foreign record is an error naming the key).
    pub fn from_metadata(m: &BTreeMap<String, String>) -> Result<Self> {
        let bad = |key: &str, problem: String| Error::Value {
            what: format!("MCAP metadata `{STORED_RUN}`, key `{key}`"),
            problem,
        };
        let get = |key: &str| {
            m.get(key)
                .ok_or_else(|| bad(key, "missing".into()))
                .map(String::as_str)
        };
        let format = get("format")?;
        if format != STORED_RUN_FORMAT {
            return Err(bad(
                "format",
                format!("version {format:?}; this edccif reads version {STORED_RUN_FORMAT}"),
            ));
        }
        let scenario = Scenario::from_toml_str(get("scenario")?)
            .map_err(|e| bad("scenario", e.to_string()))?;
        let algorithm: Algorithm = get("algorithm")?
            .parse()
            .map_err(|e: Error| bad("algorithm", e.to_string()))?;
        let options: RunOptions =
            serde_json::from_str(get("options")?).map_err(|e| bad("options", e.to_string()))?;
        let seed: u64 = get("seed")?
            .parse()
            .map_err(|e| bad("seed", format!("{e}")))?;
        let floats = |key: &str, len: usize| -> Result<Vec<f64>> {
            let v: Vec<f64> =
                serde_json::from_str(get(key)?).map_err(|e| bad(key, e.to_string()))?;
            if v.len() != len || v.iter().any(|x| !x.is_finite()) {
                return Err(bad(
                    key,
                    format!("expected {len} finite numbers, got {} values", v.len()),
                ));
            }
            Ok(v)
        };
        let n = scenario.state_dim();
        let x0 = floats("x0", n)?;
        let p0 = floats("P0", n * n)?;
        let back = Self {
            scenario,
            algorithm,
            options,
            seed,
            x0,
            p0,
        };
        // P0 is the scenario's diag(p0_diag): a file that says otherwise is damaged.
        let expect = Self::new(&back.scenario, algorithm, &back.options, seed, &back.x0);
        if expect.p0 != back.p0 {
            return Err(bad(
                "P0",
                "does not equal diag(p0_diag) of the stored scenario".into(),
            ));
        }
        Ok(back)
    }

    /// The stored run of a file's metadata, if it has one.
    pub fn find(metadata: &BTreeMap<String, BTreeMap<String, String>>) -> Result<Option<Self>> {
        metadata
            .get(STORED_RUN)
            .map(Self::from_metadata)
            .transpose()
    }
}

/// The scenario with its `python_path` resolved to absolute directories (as
/// [`Scenario::python_dirs`] finds them, canonical where they exist), so
/// that it names the same Python modules wherever it is read, e.g. from a
/// recording's metadata.
///
/// ```
/// let mut sc = edccif_sim::Scenario::paper(3);
/// sc.python_path = vec!["models".into()];
/// let p = edccif_sim::recording::portable(&sc);
/// assert!(std::path::Path::new(&p.python_path[0]).is_absolute());
/// assert_eq!(edccif_sim::recording::portable(&p), p);
/// ```
pub fn portable(sc: &Scenario) -> Scenario {
    let mut out = sc.clone();
    out.python_path = sc
        .python_dirs()
        .iter()
        .map(|d| {
            std::fs::canonicalize(d)
                .or_else(|_| std::path::absolute(d))
                .unwrap_or_else(|_| d.clone())
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    out.source_dir = Default::default();
    out
}

/// The top-level fields in which two scenarios differ (by their TOML, with
/// `python_path` resolved as [`portable`] does), e.g. `["sensors", "dt"]`;
/// empty when they are equal.
///
/// ```
/// use edccif_sim::recording::scenario_differences;
/// use edccif_sim::Scenario;
/// let a = Scenario::paper(4);
/// let mut b = a.clone();
/// b.dt = 0.05;
/// assert_eq!(scenario_differences(&a, &b)?, vec!["dt".to_string()]);
/// assert!(scenario_differences(&a, &a)?.is_empty());
/// # Ok::<(), edccif_sim::Error>(())
/// ```
pub fn scenario_differences(a: &Scenario, b: &Scenario) -> Result<Vec<String>> {
    let value = |s: &Scenario| serde_json::to_value(s).map_err(|e| Error::Io(e.to_string()));
    let (va, vb) = (value(&portable(a))?, value(&portable(b))?);
    let empty = serde_json::Map::new();
    let (oa, ob) = (
        va.as_object().unwrap_or(&empty),
        vb.as_object().unwrap_or(&empty),
    );
    let mut keys: Vec<&String> = oa.keys().chain(ob.keys()).collect();
    keys.sort();
    keys.dedup();
    Ok(keys
        .into_iter()
        .filter(|k| oa.get(*k) != ob.get(*k))
        .cloned()
        .collect())
}
