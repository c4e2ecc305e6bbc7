//! # edccif-sim
//!
//! Everything around the numerical core that a researcher runs: [`Scenario`]s
//! (TOML), seeded truth and measurements ([`simulate()`]), the network runner for
//! every [`Algorithm`] row of the paper ([`run`], [`AnyNetwork`] for streaming),
//! [`metrics`], parallel [`monte_carlo`], and the report that regenerates
//! `docs/results.md` ([`report`]), the real-world-like experiment ([`realworld`]),
//! the recording of runs as logs ([`recording`]) and their replay ([`replay`]). File formats and the
//! preprocessing pipeline are in the `edccif-io` crate.
//!
//! ```
//! use edccif_sim::{run, simulate, Algorithm, RunOptions, Scenario};
//! let sc = Scenario::paper(4);
//! let sim = simulate(&sc, 0)?;
//! let res = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), false)?;
//! println!("trigger rate {:.0} %", 100.0 * res.trigger_rate());
//! # Ok::<(), edccif_sim::Error>(())
//! ```

pub mod algorithm;
pub mod catalogue;
pub mod control;
pub mod counters;
mod delta;
mod error;
pub mod faults;
#[doc = include_str!("../../../docs/guide.md")]
pub mod guide {}
pub mod limits;
pub mod metrics;
pub mod mixed;
pub mod montecarlo;
mod names;
pub mod parallel;
pub mod realworld;
pub mod recording;
pub mod reliability;
pub mod replay;
pub mod report;
mod result;
pub mod runner;
pub mod scenario;
pub mod simulate;
pub mod timestep;
pub mod topology;

pub use algorithm::{
    network_config, node_config, node_deltas, parse_fusion_rule, parse_policy, row_config,
    Algorithm, Delta, FusionKind, RowParams, RunOptions, TriggerKind, DEFAULT_NORMALISED_DELTA,
    PAPER_DELTA,
};
pub use error::{Error, Result};
pub use montecarlo::{monte_carlo, McResult, McSettings, Variant, VariantStats};
pub use runner::{dt_from_times, run, run_with_dt, AnyNetwork, Counters, Network, RunResult};
pub use scenario::{MeasurementSpec, MotionSpec, NodeSpec, Scenario, Sensor, SensorSpec};
pub use simulate::{simulate, simulate_with_dt, Simulation};
pub use topology::Topology;
