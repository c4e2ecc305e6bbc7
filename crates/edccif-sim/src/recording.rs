//! A simulated run as a log: the [`McapRunData`] of a run (for
//! [`edccif_io::write_mcap`]) and a run that also records every node's local
//! estimate.
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

use edccif_io::McapRunData;

use crate::algorithm::{Algorithm, RunOptions};
use crate::error::Result;
use crate::runner::RunResult;
use crate::scenario::Scenario;
use crate::simulate::Simulation;

/// The data of a simulated run: truth and measurements from `sim`, estimates,
/// covariances (when recorded) and trigger flags from `res`, sensor positions from
/// the scenario, and optional local estimates `(T, N, n)` (see [`run_recording`]).
/// Step 0 is at time 0.
pub fn mcap_run_data(
    sc: &Scenario,
    sim: &Simulation,
    res: &RunResult,
    local_estimates: Option<&[f64]>,
) -> Result<McapRunData> {
    let d = McapRunData {
        dt: sc.dt,
        t0_ns: 0,
        steps: res.steps,
        nodes: res.nodes,
        n: res.n,
        truth: Some(sim.truth.clone()),
        sensors: sc.sensors.iter().flatten().copied().collect(),
        z: sim.z.clone(),
        triggered: res.triggered.clone(),
        local_estimates: local_estimates.map(<[f64]>::to_vec),
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

/// Runs `alg` like [`crate::run`] (covariances always recorded) and also records
/// every node's local (pre-combination) estimate, `(T, N, n)`, for the
/// `/node{i}/local` topics.
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
        crate::control::Control::none(),
        crate::control::Control::none(),
    )?;
    Ok((res, local))
}
