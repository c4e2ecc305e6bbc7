//! Replays of recordings: what a replay runs and what it reports.
//!
//! A replay feeds a recording's measurements to a network and reports what it
//! did. Two kinds of recordings are replayed:
//!
//! - **edccif recordings** (`edccif simulate/record --mcap`): the file stores
//!   what made the run ([`StoredRun`]: scenario, algorithm, options, seed,
//!   `x̂0`, `P0`), and the replay runs exactly that, through [`crate::run`] (the
//!   same network as the original, so the same estimates bit for bit).
//!   [`resolve_stored`] decides what runs when a scenario is also given: a
//!   scenario that differs from the stored one is refused unless overridden; a
//!   file without a stored run needs a scenario or models (there is no default
//!   geometry).
//! - **ROS 2 recordings**: the messages are made ready by
//!   [`edccif_io::replay_input::prepare`] (one frame, each step's noise, rows)
//!   and run on a [`MixedNetwork`] of a motion model and one sensor model per
//!   source, with each step's own time step and noise
//!   ([`MixedNetwork::run_with_noise`]). The network is built from models
//!   (Python: `edccif.replay(..., motion=..., sensors=...)`, as
//!   `ModelNetwork`), or from a scenario ([`scenario_network`]: the scenario's
//!   models, parameters and graph, the same numbers as [`crate::run_with_dt`]).
//!   Nothing reads a position as range/pitch/azimuth unless asked: a scenario
//!   whose sensors measure something else is refused for position messages
//!   ([`check_position_scenario`]) unless its sensors are chosen explicitly.
//!
//! [`ReplayReport`] is the one report of a replay: frames and transforms,
//! noise per source, messages dropped, offsets, trigger rate per node, and
//! whether the truth was compared in the same frame.
//!
//! ```
//! use edccif_sim::replay::{start_from_rows, StartKind};
//! // Two rows 0.1 s apart of one node moving at 1 m/s along x.
//! let (x0, p0) = start_from_rows(StartKind::ConstantVelocity, &[0.0, 0.1], &[0.0, 0.0, 1.0, 0.1, 0.0, 1.0], 1)?;
//! assert_eq!(x0[..3], [0.0, 0.0, 1.0]);
//! assert!((x0[3] - 1.0).abs() < 1e-12);
//! assert_eq!(p0, vec![1e-2, 1e-2, 1e-2, 0.04, 0.04, 0.04]);
//! # Ok::<(), edccif_sim::Error>(())
//! ```

use edccif_core::MotionModel;
use edccif_io::replay_input::InputReport;
use serde::{Deserialize, Serialize};

use crate::algorithm::{Algorithm, RunOptions};
use crate::error::{scenario_err, Error, Result};
use crate::mixed::{MixedNetwork, NodeSensor, SensorNode};
use crate::recording::{scenario_differences, StoredRun};
use crate::runner::RunResult;
use crate::scenario::{MotionSpec, Scenario, SensorSpec};

/// The motion models whose initial estimate a replay can take from the first
/// rows of position measurements (their states start with the 3-D position
/// and velocity).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StartKind {
    /// `[p, v]`, 6 states.
    ConstantVelocity,
    /// `[p, v, a]`, 9 states (`a₀ = 0`).
    ConstantAcceleration,
    /// `[p, v, ω]`, 7 states (`ω₀ = 0`).
    CoordinatedTurn,
}

/// An initial estimate `(x̂0, diag P0)` from the first rows of position
/// measurements `z` `(T, N, 3)` at times `t_s` (s): the position is the first
/// row's mean over the nodes that measured, the velocity its difference to the
/// mean of the last such row within the next 5, over their time apart (zero
/// with a single row); further states (acceleration, turn rate) start at 0.
/// `P0 = diag(10⁻² m² ×3, 0.04 m²/s² ×3, then 1 m²/s⁴ ×3 or 10⁻⁴ rad²/s²)`.
pub fn start_from_rows(
    kind: StartKind,
    t_s: &[f64],
    z: &[f64],
    nodes: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let steps = t_s.len();
    if nodes == 0 || z.len() != steps * nodes * 3 {
        return Err(Error::Shape {
            what: "z".into(),
            expected: format!("({steps}, {nodes}, 3)"),
            got: format!("{} values", z.len()),
        });
    }
    let mean = |t: usize| -> Option<[f64; 3]> {
        let mut s = [0.0; 3];
        let mut c = 0.0;
        for i in 0..nodes {
            let v = &z[(t * nodes + i) * 3..(t * nodes + i) * 3 + 3];
            if v.iter().all(|x| x.is_finite()) {
                for d in 0..3 {
                    s[d] += v[d];
                }
                c += 1.0;
            }
        }
        (c > 0.0).then(|| s.map(|x| x / c))
    };
    let rows: Vec<(usize, [f64; 3])> = (0..steps).filter_map(|t| mean(t).map(|m| (t, m))).collect();
    let Some(&(first, p)) = rows.first() else {
        return Err(Error::Value {
            what: "z".into(),
            problem: "no measurement to start from; expected at least one finite row".into(),
        });
    };
    let later = rows.iter().rfind(|(t, _)| *t > first && *t <= first + 5);
    let v = match later {
        Some(&(t, q)) => {
            let d = t_s[t] - t_s[first];
            [0, 1, 2].map(|k| (q[k] - p[k]) / d)
        }
        None => [0.0; 3],
    };
    let mut x0: Vec<f64> = p.iter().chain(&v).copied().collect();
    let mut p0 = vec![1e-2, 1e-2, 1e-2, 0.04, 0.04, 0.04];
    match kind {
        StartKind::ConstantVelocity => {}
        StartKind::ConstantAcceleration => {
            x0.extend([0.0; 3]);
            p0.extend([1.0; 3]);
        }
        StartKind::CoordinatedTurn => {
            x0.push(0.0);
            p0.push(1e-4);
        }
    }
    Ok((x0, p0))
}

/// Refuses a scenario whose sensors do not measure a position for position
/// messages (a ROS 2 message's `x, y, z`), unless `explicit` (the caller chose
/// the scenario's sensors for them on purpose).
pub fn check_position_scenario(sc: &Scenario, explicit: bool) -> Result<()> {
    let positions = sc
        .node_specs()
        .iter()
        .all(|n| matches!(&n.sensor, SensorSpec::Position { sigma } if sigma.len() == 3));
    if positions || explicit {
        return Ok(());
    }
    let kind = sc
        .node_specs()
        .iter()
        .map(|n| n.sensor.kind())
        .find(|k| *k != "position")
        .unwrap_or("position");
    Err(scenario_err(
        if sc.nodes.is_empty() { "measurement" } else { "nodes" },
        format!(
            "scenario `{}` {}, and ROS 2 messages give 3-D \
             positions (x, y, z); a position is not read as another measurement unless you \
             say so: give position models (CLI: --motion; Python: motion=, sensors=[models.Position(...)]), \
             a scenario with `measurement = {{ kind = \"position\" }}`, or, if the messages \
             really hold range/pitch/azimuth, --sensor scenario (Python: \
             sensors=[models.RangePitchAzimuth(...)] per source)",
            sc.name,
            if kind == "range-pitch-azimuth" {
                "measures range, pitch and azimuth".to_string()
            } else {
                format!("has `{kind}` sensors")
            }
        ),
    ))
}

fn scenario_network_n<const N: usize>(
    alg: Algorithm,
    sc: &Scenario,
    x0: &[f64],
    opt: &RunOptions,
    motion: Box<dyn MotionModel<f64, N> + Send + Sync>,
) -> Result<MixedNetwork<N>> {
    let sensors: Vec<Box<dyn NodeSensor<N>>> = sc
        .sensor_models()?
        .into_iter()
        .map(|s| Box::new(SensorNode::<_, 3>::new(s)) as Box<dyn NodeSensor<N>>)
        .collect();
    crate::mixed::model_network(alg, sc, x0, opt, motion, sensors)
}

/// A network of the scenario's models, parameters and graph that takes each
/// step's own noise, from `x0` (and the scenario's `P0`).
#[derive(Debug)]
pub enum ScenarioNetwork {
    /// Coordinated turn, 7 states.
    Ct(MixedNetwork<7>),
    /// Constant velocity, 6 states.
    Cv(MixedNetwork<6>),
    /// Constant acceleration, 9 states.
    Ca(MixedNetwork<9>),
}

/// Builds the [`ScenarioNetwork`] of `alg` on `sc` from `x0`: its steps are
/// those of [`crate::run`] bit for bit (a network whose sensors all have one
/// type, see [`crate::mixed`]), and it takes each step's own noise.
pub fn scenario_network(
    alg: Algorithm,
    sc: &Scenario,
    x0: &[f64],
    opt: &RunOptions,
) -> Result<ScenarioNetwork> {
    sc.validate()?;
    if let Some(t @ 2..) = opt.threads {
        return Err(Error::Value {
            what: "threads".into(),
            problem: format!(
                "got {t}; a replay of ROS 2 messages steps serially (threads 1 or unset); \
                 threads applies to replays of edccif recordings"
            ),
        });
    }
    Ok(match sc.motion {
        MotionSpec::CoordinatedTurn { .. } => ScenarioNetwork::Ct(scenario_network_n(
            alg,
            sc,
            x0,
            opt,
            Box::new(sc.coordinated_turn()?),
        )?),
        MotionSpec::ConstantVelocity { .. } => ScenarioNetwork::Cv(scenario_network_n(
            alg,
            sc,
            x0,
            opt,
            Box::new(sc.constant_velocity()?),
        )?),
        MotionSpec::ConstantAcceleration { .. } => ScenarioNetwork::Ca(scenario_network_n(
            alg,
            sc,
            x0,
            opt,
            Box::new(sc.constant_acceleration()?),
        )?),
        _ => return Err(sc.model_network_error()),
    })
}

impl ScenarioNetwork {
    /// [`MixedNetwork::run_with_noise`] (covariances recorded).
    pub fn run(&mut self, z: &[f64], dt: &[f64], noise: Option<&[f64]>) -> Result<RunResult> {
        match self {
            ScenarioNetwork::Ct(n) => n.run_with_noise(z, dt, noise, true),
            ScenarioNetwork::Cv(n) => n.run_with_noise(z, dt, noise, true),
            ScenarioNetwork::Ca(n) => n.run_with_noise(z, dt, noise, true),
        }
    }

    /// [`run`](Self::run) under a [`Control`](crate::control::Control)
    /// ([`MixedNetwork::run_with_noise_control`]): cancelled, it returns
    /// [`Error::Interrupted`] with the network as it was.
    pub fn run_with_control(
        &mut self,
        z: &[f64],
        dt: &[f64],
        noise: Option<&[f64]>,
        ctl: &crate::control::Control,
    ) -> Result<RunResult> {
        match self {
            ScenarioNetwork::Ct(n) => n.run_with_noise_control(z, dt, noise, true, ctl),
            ScenarioNetwork::Cv(n) => n.run_with_noise_control(z, dt, noise, true, ctl),
            ScenarioNetwork::Ca(n) => n.run_with_noise_control(z, dt, noise, true, ctl),
        }
    }
}

/// What a replay of an edccif recording runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved {
    /// The scenario.
    pub scenario: Scenario,
    /// The row (the given one, else the stored one, else EDC-CIF).
    pub algorithm: Algorithm,
    /// The options: the stored ones (with the stored seed's trigger streams),
    /// each given option replacing the stored one.
    pub options: RunOptions,
    /// The initial estimate (the stored `x̂0` unless a scenario overrode the
    /// stored one, then the scenario's `x0`).
    pub x0: Vec<f64>,
    /// For the report.
    pub stored: StoredUse,
}

/// How a replay used the run stored in a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredUse {
    /// Whether the file stores a run.
    pub stored: bool,
    /// `stored`, `given` or `given (override)`.
    pub scenario: String,
    /// Where `x̂0` came from.
    pub x0: String,
    /// Where the algorithm came from.
    pub algorithm: String,
    /// The stored seed, if any.
    pub seed: Option<u64>,
    /// Fields where a given scenario differs from the stored one.
    pub differences: Vec<String>,
}

/// Decides what a replay of an edccif recording runs (see the module docs):
/// `stored` from the file, `given` the caller's scenario, `algorithm` the
/// caller's row, `given_opt` the caller's options (`None` fields keep the
/// stored ones), `override_` whether a differing scenario is accepted.
/// `file` names the recording in errors.
pub fn resolve_stored(
    file: &str,
    stored: Option<&StoredRun>,
    given: Option<&Scenario>,
    algorithm: Option<Algorithm>,
    given_opt: &RunOptions,
    override_: bool,
) -> Result<Resolved> {
    let merge = |base: &RunOptions| RunOptions {
        et_policy: given_opt.et_policy.or(base.et_policy),
        delta: given_opt.delta.clone().or_else(|| base.delta.clone()),
        normalised: given_opt.normalised.or(base.normalised),
        sigma1: given_opt.sigma1.or(base.sigma1),
        sigma2: given_opt.sigma2.or(base.sigma2),
        consensus_iters: given_opt.consensus_iters.or(base.consensus_iters),
        fusion: given_opt.fusion.or(base.fusion),
        force_trigger: given_opt.force_trigger || base.force_trigger,
        gate: given_opt.gate.or(base.gate),
        trigger: given_opt.trigger.or(base.trigger),
        trigger_seed: given_opt.trigger_seed.or(base.trigger_seed),
        threads: given_opt.threads,
        untriggered_closed_form: given_opt
            .untriggered_closed_form
            .or(base.untriggered_closed_form),
    };
    match (stored, given) {
        (None, None) => Err(scenario_err(
            "scenario",
            format!(
                "{file} stores no scenario (it was not written by `edccif simulate --mcap` or \
                 `edccif.record`), and there is no default geometry: give the scenario it was \
                 made with (--scenario FILE; Python scenario=) or models (--motion; Python \
                 motion=, sensors=)"
            ),
        )),
        (None, Some(sc)) => Ok(Resolved {
            scenario: sc.clone(),
            algorithm: algorithm.unwrap_or(Algorithm::EdcCif),
            options: given_opt.clone(),
            x0: sc.x0.clone(),
            stored: StoredUse {
                stored: false,
                scenario: "given".into(),
                x0: "the scenario's x0".into(),
                algorithm: if algorithm.is_some() {
                    "given"
                } else {
                    "default (edc-cif)"
                }
                .into(),
                seed: None,
                differences: Vec::new(),
            },
        }),
        (Some(st), given) => {
            let differences = match given {
                Some(sc) => scenario_differences(&st.scenario, sc)?,
                None => Vec::new(),
            };
            if !differences.is_empty() && !override_ {
                return Err(scenario_err(
                    "scenario",
                    format!(
                        "{file} was made with scenario `{}` (stored in its metadata), and the \
                         given scenario `{}` differs from it in: {}; replay without a scenario to \
                         use the stored one, or pass --override (Python override=True) to replay \
                         with the given one",
                        st.scenario.name,
                        given.map_or("", |s| s.name.as_str()),
                        differences.join(", ")
                    ),
                ));
            }
            let overridden = !differences.is_empty();
            let scenario = if overridden {
                given.cloned().unwrap_or_else(|| st.scenario.clone())
            } else {
                st.scenario.clone()
            };
            let x0 = if overridden {
                scenario.x0.clone()
            } else {
                st.x0.clone()
            };
            Ok(Resolved {
                algorithm: algorithm.unwrap_or(st.algorithm),
                options: merge(&st.options),
                x0,
                stored: StoredUse {
                    stored: true,
                    scenario: if overridden {
                        "given (override)"
                    } else if given.is_some() {
                        "stored (the given one equals it)"
                    } else {
                        "stored"
                    }
                    .into(),
                    x0: if overridden {
                        "the given scenario's x0"
                    } else {
                        "stored (the run's x̂0)"
                    }
                    .into(),
                    algorithm: match algorithm {
                        Some(a) if a != st.algorithm => {
                            format!("given ({}; the recording ran {})", a, st.algorithm)
                        }
                        _ => "stored".into(),
                    },
                    seed: Some(st.seed),
                    differences,
                },
                scenario,
            })
        }
    }
}

/// One node's part of a replay.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NodeReport {
    /// The node's source (`TOPIC[#FRAME]`, or `/node{i}/measurement`).
    pub source: String,
    /// Steps with a measurement.
    pub measured: usize,
    /// Of those, steps whose sensor sent.
    pub triggered: usize,
    /// `triggered / measured` (`None` without a measurement).
    pub trigger_rate: Option<f64>,
}

/// The one report of a replay (stdout and `--json` of `edccif replay`,
/// `RunResult.report` in Python).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayReport {
    /// The recording.
    pub file: String,
    /// `ros2` or `edccif`.
    pub kind: String,
    /// The row that ran.
    pub algorithm: String,
    /// What ran: the models or scenario, in words.
    pub models: String,
    /// Steps `T`.
    pub steps: usize,
    /// Nodes `N`.
    pub nodes: usize,
    /// Where the initial estimate came from.
    pub x0: String,
    /// For a ROS 2 recording: frames, transforms, noise, dropped messages,
    /// timing and offsets.
    pub input: Option<InputReport>,
    /// For an edccif recording: how its stored run was used.
    pub stored: Option<StoredUse>,
    /// Timing of an edccif recording's rows (`log times`).
    pub timing: String,
    /// Offsets applied to the streams' clocks.
    pub offsets: String,
    /// Per node.
    pub per_node: Vec<NodeReport>,
    /// Triggered / measured over all nodes.
    pub trigger_rate: f64,
    /// RMSE of the fused positions against the truth (m), over the rows where
    /// the truth is known; `None` without a truth.
    pub position_rmse_m: Option<f64>,
    /// Whether the truth and the estimates were compared in one frame (`None`:
    /// no truth).
    pub truth_same_frame: Option<bool>,
}

impl ReplayReport {
    /// The per-node counts, trigger rates and the RMSE against `truth`
    /// (`(T, 3)`, NaN where unknown) of a run.
    pub fn fill_run(&mut self, res: &RunResult, sources: &[String], truth: Option<&[f64]>) {
        let (t, k, n) = (res.steps, res.nodes, res.n);
        self.steps = t;
        self.nodes = k;
        self.algorithm = res.algorithm.name().into();
        self.trigger_rate = res.trigger_rate();
        self.per_node = (0..k)
            .map(|i| {
                let measured = (0..t).filter(|&s| res.measured[s * k + i]).count();
                let triggered = (0..t).filter(|&s| res.triggered[s * k + i]).count();
                NodeReport {
                    source: sources.get(i).cloned().unwrap_or_default(),
                    measured,
                    triggered,
                    trigger_rate: (measured > 0).then(|| triggered as f64 / measured as f64),
                }
            })
            .collect();
        self.position_rmse_m = truth.and_then(|tr| {
            let mut sum = 0.0;
            let mut count = 0usize;
            for s in 0..t.min(tr.len() / 3) {
                let p = &tr[s * 3..s * 3 + 3];
                if !p.iter().all(|v| v.is_finite()) {
                    continue;
                }
                for i in 0..k {
                    let e = &res.estimates[(s * k + i) * n..(s * k + i) * n + 3];
                    sum += (0..3).map(|d| (e[d] - p[d]).powi(2)).sum::<f64>();
                    count += 1;
                }
            }
            (count > 0).then(|| (sum / count as f64).sqrt())
        });
    }
}
