//! What a network step sends, counted in one place: the running totals of a
//! network ([`Counters`]) and the one rule that adds a step to them
//! ([`Counters::add_step`]), used by the scenario network (serial and parallel
//! steps) and the model network alike.
//!
//! Per step, in floats (`n` the state dimension, `m_i` node i's measurement
//! dimension):
//! - sensor → estimator: `m_i` per node whose sensor sent (γ = 1);
//! - estimator → sensor: `m_i + m_i(m_i+1)/2` (the prediction `(ẑ, Pzz)`) per
//!   node with a measurement, when the trigger needs the node's prediction;
//! - estimator ↔ estimator: `n + n(n+1)/2` (a vector and a symmetric matrix)
//!   per delivered directed message: both ends up and the link not lost;
//!   diffusion sends two messages per link (the contribution, then the adapted
//!   pair), consensus one per link and iteration, no fusion none.
//!
//! ```
//! use edccif_core::{Fusion, LinkMask, Neighbours, NetworkConfig, StepReport};
//! use edccif_sim::counters::{Counters, StepMessages};
//! // Two nodes that hear each other, both sending a 3-value measurement.
//! let w = [0.5, 0.5, 0.5, 0.5];
//! let (mut offsets, mut indices) = ([0; 3], [0; 4]);
//! let nb = Neighbours::from_weights(&w, 2, &mut offsets, &mut indices)?;
//! let report = StepReport { measured: 2, triggered: 2, ..StepReport::default() };
//! let step = StepMessages { fusion: Fusion::DiffusionCi, state_dim: 4, prediction_to_sensor: false,
//!                           neighbours: &nb, links: None, active: None };
//! let mut c = Counters::default();
//! c.add_step(&report, &step, [(3, Some(true)), (3, Some(true))]);
//! assert_eq!(c.values_sensor_to_estimator, 6);
//! // two directed links, two messages each, 4 + 10 floats a message
//! assert_eq!(c.values_estimator_to_estimator, 2 * 2 * 14);
//! # Ok::<(), edccif_core::Error>(())
//! ```

use edccif_core::{Fusion, LinkMask, Neighbours, NetworkConfig, StepReport};
use serde::{Deserialize, Serialize};

/// Running totals of a network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Counters {
    /// Steps taken.
    pub steps: u64,
    /// Node-steps with a measurement.
    pub measured: u64,
    /// Node-steps whose sensor sent (γ = 1).
    pub triggered: u64,
    /// Adaptation-guard fallbacks (ALGORITHM.md §4).
    pub guard_fallbacks: u64,
    /// Floats sent on sensor → estimator links (`m` per sent measurement).
    pub values_sensor_to_estimator: u64,
    /// Floats sent on estimator ↔ estimator links: per delivered directed message
    /// a vector and a symmetric matrix, `n + n(n+1)/2` floats; diffusion sends two
    /// messages per link and step (contribution, then the adapted pair), consensus
    /// one per link and iteration.
    pub values_estimator_to_estimator: u64,
    /// Triggered measurements rejected by the innovation gate
    /// ([`RunOptions::gate`](crate::RunOptions::gate)).
    #[serde(default)]
    pub gated: u64,
    /// Floats sent on estimator → sensor links: the innovation trigger's
    /// prediction `(ẑ, Pzz)`, `m + m(m+1)/2` per node-step with a measurement.
    #[serde(default)]
    pub values_estimator_to_sensor: u64,
}

/// What decides the messages of one step besides the nodes' measurements.
#[derive(Debug, Clone, Copy)]
pub struct StepMessages<'a> {
    /// The row's fusion (messages per link).
    pub fusion: Fusion,
    /// The state dimension `n`.
    pub state_dim: usize,
    /// Whether the trigger needs the node's prediction at the sensor
    /// ([`Trigger::needs_prediction`](edccif_core::Trigger::needs_prediction)).
    pub prediction_to_sensor: bool,
    /// The closed neighbourhoods of the weight matrix.
    pub neighbours: &'a Neighbours<'a>,
    /// The step's link mask, if any: `k × k` ([`LinkMask::Dense`]) or per
    /// entry of `neighbours` ([`LinkMask::Edges`]).
    pub links: Option<LinkMask<'a>>,
    /// The step's mask of the nodes that are up (`k`), if any.
    pub active: Option<&'a [bool]>,
}

impl<'a> StepMessages<'a> {
    /// The messages of a step of a network with configuration `cfg`, state
    /// dimension `state_dim`, neighbourhoods `neighbours` and the step's masks.
    pub fn new(
        cfg: &NetworkConfig<f64>,
        state_dim: usize,
        neighbours: &'a Neighbours<'a>,
        links: Option<LinkMask<'a>>,
        active: Option<&'a [bool]>,
    ) -> Self {
        Self {
            fusion: cfg.fusion,
            state_dim,
            prediction_to_sensor: cfg.trigger.needs_prediction(),
            neighbours,
            links,
            active,
        }
    }

    /// Directed messages delivered per fusion message: pairs `i ≠ j` with j
    /// in i's neighbourhood, both up, the link not lost.
    pub fn delivered_links(&self) -> u64 {
        let k = self.neighbours.nodes();
        let up = |i: usize| self.active.is_none_or(|a| a[i]);
        let mut delivered = 0u64;
        for i in (0..k).filter(|&i| up(i)) {
            let a = self.neighbours.offset(i);
            for (e, &j) in self.neighbours.row(i).iter().enumerate() {
                let kept = match self.links {
                    None => true,
                    Some(LinkMask::Dense(l)) => l[i * k + j],
                    Some(LinkMask::Edges(l)) => l[a + e],
                };
                if i != j && up(j) && kept {
                    delivered += 1;
                }
            }
        }
        delivered
    }

    /// Fusion messages per delivered link and step.
    pub fn messages_per_link(&self) -> u64 {
        match self.fusion {
            Fusion::DiffusionCi | Fusion::DiffusionConvex => 2,
            Fusion::Consensus { iterations } => iterations as u64,
            Fusion::Local => 0,
        }
    }
}

impl Counters {
    /// Adds one step: its `report`, and the floats it sent (module
    /// documentation) from `step` and `sensors`, per node its measurement
    /// dimension `m_i` and `Some(γ)` when it took a measurement (`None`: no
    /// measurement, or the node was down).
    pub fn add_step(
        &mut self,
        report: &StepReport,
        step: &StepMessages<'_>,
        sensors: impl IntoIterator<Item = (usize, Option<bool>)>,
    ) {
        self.steps += 1;
        self.measured += report.measured as u64;
        self.triggered += report.triggered as u64;
        self.guard_fallbacks += report.guard_fallbacks as u64;
        self.gated += report.gated as u64;
        for (m, triggered) in sensors {
            let m = m as u64;
            if triggered == Some(true) {
                self.values_sensor_to_estimator += m;
            }
            if triggered.is_some() && step.prediction_to_sensor {
                self.values_estimator_to_sensor += m + m * (m + 1) / 2;
            }
        }
        let n = step.state_dim as u64;
        let per_link = step.messages_per_link();
        if per_link > 0 {
            self.values_estimator_to_estimator +=
                step.delivered_links() * per_link * (n + n * (n + 1) / 2);
        }
    }
}
