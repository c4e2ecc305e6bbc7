//! Scenarios: everything that defines an experiment, read and written as TOML.

use std::f64::consts::PI;
use std::path::Path;

use edccif_core::models::{
    ConstantAcceleration, ConstantVelocity, CoordinatedTurn, Position3, RangePitchAzimuth,
};
use edccif_core::{FusionRule, MeasurementModel, PointImages, Trigger};
use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

use crate::algorithm::Delta;
use crate::error::{scenario_err, Error, Result};
use crate::topology::{self, Topology};

/// Target motion model and its noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MotionSpec {
    /// Coordinated turn, 7 states `[px, py, pz, vx, vy, vz, ω]` (ALGORITHM.md §1).
    CoordinatedTurn {
        /// Position/velocity noise intensity.
        q1: f64,
        /// Turn-rate noise intensity.
        q2: f64,
    },
    /// Constant velocity, 6 states `[px, py, pz, vx, vy, vz]`.
    ConstantVelocity {
        /// White-acceleration intensity.
        q: f64,
    },
    /// Constant acceleration, 9 states `[px, py, pz, vx, vy, vz, ax, ay, az]`
    /// (white jerk; `edccif_core::models::ConstantAcceleration`).
    ConstantAcceleration {
        /// White-jerk intensity (m²/s⁵).
        q: f64,
    },
}

impl MotionSpec {
    /// State dimension.
    pub fn dim(&self) -> usize {
        match self {
            MotionSpec::CoordinatedTurn { .. } => 7,
            MotionSpec::ConstantVelocity { .. } => 6,
            MotionSpec::ConstantAcceleration { .. } => 9,
        }
    }
}

/// What each sensor measures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MeasurementSpec {
    /// Range, pitch, azimuth (ALGORITHM.md §1).
    RangePitchAzimuth {
        /// Range standard deviation (m).
        sigma_r: f64,
        /// Angle standard deviation (rad).
        sigma_a: f64,
    },
    /// 3-D position (RGB-D camera after deprojection).
    Position {
        /// Standard deviation per axis (m).
        sigma: [f64; 3],
    },
}

/// A node's sensor: the scenario's measurement model at the node's position.
/// One type for both built-in measurement kinds (enum dispatch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sensor {
    /// Range/pitch/azimuth.
    Rpa(RangePitchAzimuth<f64>),
    /// 3-D position.
    Pos(Position3<f64>),
}

impl<const N: usize> MeasurementModel<f64, N, 3> for Sensor {
    #[inline]
    fn measure(&self, x: &SVector<f64, N>) -> SVector<f64, 3> {
        match self {
            Sensor::Rpa(s) => MeasurementModel::<f64, N, 3>::measure(s, x),
            Sensor::Pos(s) => MeasurementModel::<f64, N, 3>::measure(s, x),
        }
    }
    #[inline]
    fn noise(&self) -> SMatrix<f64, 3, 3> {
        match self {
            Sensor::Rpa(s) => MeasurementModel::<f64, N, 3>::noise(s),
            Sensor::Pos(s) => MeasurementModel::<f64, N, 3>::noise(s),
        }
    }
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        matches!(self, Sensor::Rpa(_)) && (k == 1 || k == 2)
    }
    #[inline]
    fn fast_trig(&self) -> bool {
        match self {
            Sensor::Rpa(s) => MeasurementModel::<f64, N, 3>::fast_trig(s),
            Sensor::Pos(s) => MeasurementModel::<f64, N, 3>::fast_trig(s),
        }
    }
    #[inline]
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, 3, N> {
        match self {
            Sensor::Rpa(s) => MeasurementModel::<f64, N, 3>::jacobian(s, x),
            Sensor::Pos(s) => MeasurementModel::<f64, N, 3>::jacobian(s, x),
        }
    }
    #[inline]
    fn measure_with_jacobian(&self, x: &SVector<f64, N>) -> (SVector<f64, 3>, SMatrix<f64, 3, N>) {
        match self {
            Sensor::Rpa(s) => MeasurementModel::<f64, N, 3>::measure_with_jacobian(s, x),
            Sensor::Pos(s) => MeasurementModel::<f64, N, 3>::measure_with_jacobian(s, x),
        }
    }
    #[inline]
    fn jacobian_products(
        &self,
        g: &SMatrix<f64, 3, N>,
        p: &SMatrix<f64, N, N>,
    ) -> (SMatrix<f64, N, 3>, SMatrix<f64, 3, 3>) {
        match self {
            Sensor::Rpa(s) => s.jacobian_products(g, p),
            Sensor::Pos(s) => s.jacobian_products(g, p),
        }
    }
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<f64, N>,
    ) -> (SVector<f64, 3>, SVector<f64, 3>, SVector<f64, 3>) {
        match self {
            Sensor::Rpa(s) => MeasurementModel::<f64, N, 3>::measure_with_trig(s, x),
            Sensor::Pos(s) => MeasurementModel::<f64, N, 3>::measure_with_trig(s, x),
        }
    }
    #[inline]
    fn measure_points_trig(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, 3, N>,
        minus: &mut PointImages<f64, 3, N>,
        centre: Option<&mut PointImages<f64, 3, 1>>,
    ) {
        match self {
            Sensor::Rpa(s) => s.measure_points_trig(x, offsets, plus, minus, centre),
            Sensor::Pos(s) => s.measure_points_trig(x, offsets, plus, minus, centre),
        }
    }
}

/// Dynamic event-trigger parameters (DEC-CKF).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DynamicTrigger {
    /// Decay `λ ∈ [0, 1)`.
    pub lambda: f64,
    /// Weight `θ > 0`.
    pub theta: f64,
}

impl Default for DynamicTrigger {
    fn default() -> Self {
        Self {
            lambda: 0.9,
            theta: 2.0,
        }
    }
}

/// Unscented-transform parameters (EC-UKF).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UkfParams {
    /// `α`.
    pub alpha: f64,
    /// `β`.
    pub beta: f64,
    /// `κ`.
    pub kappa: f64,
}

impl Default for UkfParams {
    fn default() -> Self {
        Self {
            alpha: 1.0,
            beta: 2.0,
            kappa: 0.0,
        }
    }
}

/// A complete experiment definition.
///
/// ```
/// use edccif_sim::Scenario;
/// let s = Scenario::paper(4);
/// assert_eq!((s.nodes(), s.steps, s.state_dim()), (4, 200, 7));
/// let back = Scenario::from_toml_str(&s.to_toml().unwrap()).unwrap();
/// assert_eq!(back, s);
/// // unknown keys are rejected with their name and line
/// let err = Scenario::from_toml_str(&s.to_toml().unwrap().replace("steps =", "stepz =")).unwrap_err();
/// assert!(err.to_string().contains("stepz"));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// A label.
    pub name: String,
    /// Sampling period (s).
    pub dt: f64,
    /// Number of steps `T`.
    pub steps: usize,
    /// Send-on-delta threshold `δ`: one number for every node, or one per node
    /// (`delta = [0.04, 0.01, 0.04]` in TOML).
    pub delta: Delta,
    /// `delta` in units of each sensor's noise (`normalised = true` in TOML;
    /// default off, the paper's raw squared units): the send-on-delta family
    /// compares `ΔᵀR⁻¹Δ` with `δ` (`docs/triggers.md`, "Normalised thresholds").
    #[serde(default, skip_serializing_if = "is_false")]
    pub normalised: bool,
    /// `σ1` of the error-minimised gain.
    pub sigma1: f64,
    /// `σ2` of the error-minimised gain.
    pub sigma2: f64,
    /// Consensus iterations `L`; absent: the "adequate" `L` of ALGORITHM.md §5.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub consensus_iters: Option<usize>,
    /// True initial state `x₀`.
    pub x0: Vec<f64>,
    /// Diagonal of the initial covariance `P0` (variances).
    pub p0_diag: Vec<f64>,
    /// Sensor positions, one per node.
    pub sensors: Vec<[f64; 3]>,
    /// Motion model.
    pub motion: MotionSpec,
    /// Measurement model.
    pub measurement: MeasurementSpec,
    /// Communication topology.
    pub topology: Topology,
    /// Dynamic-trigger parameters.
    #[serde(default)]
    pub dynamic: DynamicTrigger,
    /// UKF parameters.
    #[serde(default)]
    pub ukf: UkfParams,
    /// Opt-in fast trigonometry (`fast_trig = true` in TOML; default off): the
    /// coordinated turn's and the range/pitch/azimuth sensors' `with_fast_trig`
    /// (one `sin_cos` per prediction, no `atan2` per measurement point, and the
    /// remaining `atan2`/`sin_cos`, the EKF's included, by the inline kernel
    /// `edccif_core::trig`). Results then differ from the reference path in the
    /// last bits; `docs/guide.md` §7 and `docs/performance.md` have the bounds.
    #[serde(default, skip_serializing_if = "is_false")]
    pub fast_trig: bool,
    /// Opt-in closed form of the ET-CIF's untriggered contribution
    /// (`untriggered_closed_form = true` in TOML; default off, the paper's
    /// stable form): [`EtOptions::untriggered_closed_form`](edccif_core::EtOptions::untriggered_closed_form),
    /// `Ī = −σ1/(1+σ1) Y⁻ + Gᵀ R̃⁻¹ G` without the `n × n` inverse of `P̄`.
    /// Results then differ from the stable form in the last bits
    /// (`docs/triggers.md`, "Closed form of the untriggered step"); the
    /// covariance-form rows ignore it.
    #[serde(default, skip_serializing_if = "is_false")]
    pub untriggered_closed_form: bool,
    /// The rule of the CI combination of the diffusion-with-CI rows (DC-CIF,
    /// EDC-CIF), by name (`fusion = "ici"` in TOML; `docs/fusion.md`); `None`:
    /// the paper's CI. A run's `fusion=` option replaces it.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "de_fusion_rule"
    )]
    pub fusion: Option<FusionRule>,
}

/// Serde helper: a fusion rule by name, with the names listed on error.
fn de_fusion_rule<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<FusionRule>, D::Error> {
    let s = String::deserialize(d)?;
    crate::algorithm::parse_fusion_rule(&s)
        .map(Some)
        .map_err(serde::de::Error::custom)
}

/// Serde helper: leave a default-off flag out of the serialised scenario.
fn is_false(b: &bool) -> bool {
    !*b
}

impl Scenario {
    /// The default ("paper") scenario of ALGORITHM.md §6 for `nodes` sensors.
    pub fn paper(nodes: usize) -> Self {
        let sensors = (0..nodes)
            .map(|i| {
                let a = 2.0 * PI * i as f64 / nodes as f64;
                [
                    10.0 * a.cos(),
                    10.0 * a.sin(),
                    if i % 2 == 0 { 0.0 } else { 3.0 },
                ]
            })
            .collect();
        let mut p0_diag = vec![0.01; 6];
        p0_diag.push(1e-4);
        Self {
            name: format!("paper-{nodes}"),
            dt: 0.1,
            steps: 200,
            delta: Delta::All(crate::algorithm::PAPER_DELTA),
            normalised: false,
            sigma1: 5e-4,
            sigma2: 5e-4,
            consensus_iters: None,
            x0: vec![5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3],
            p0_diag,
            sensors,
            motion: MotionSpec::CoordinatedTurn { q1: 0.5, q2: 1e-4 },
            measurement: MeasurementSpec::RangePitchAzimuth {
                sigma_r: 0.1,
                sigma_a: 0.01,
            },
            topology: Topology::Ring,
            dynamic: DynamicTrigger::default(),
            ukf: UkfParams::default(),
            fast_trig: false,
            untriggered_closed_form: false,
            fusion: None,
        }
    }

    /// Number of nodes (sensors).
    pub fn nodes(&self) -> usize {
        self.sensors.len()
    }

    /// State dimension `n`.
    pub fn state_dim(&self) -> usize {
        self.motion.dim()
    }

    /// Measurement dimension `m` (3 for both built-in sensors).
    pub fn meas_dim(&self) -> usize {
        3
    }

    /// Parses TOML; unknown keys and wrong types are errors naming the key and line.
    pub fn from_toml_str(s: &str) -> Result<Self> {
        let sc: Scenario = toml::from_str(s).map_err(|e| Error::Parse(e.to_string()))?;
        sc.validate()?;
        Ok(sc)
    }

    /// Reads a TOML file.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::Io(format!("cannot read {}: {e}", path.display())))?;
        Self::from_toml_str(&text).map_err(|e| match e {
            Error::Parse(m) => Error::Parse(format!("{}: {m}", path.display())),
            other => other,
        })
    }

    /// Writes TOML.
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| Error::Parse(e.to_string()))
    }

    /// Checks every field; the error names the field and what is expected.
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64, field: &str| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(scenario_err(
                    field,
                    format!("must be finite and > 0, got {v}"),
                ))
            }
        };
        pos(self.dt, "dt")?;
        if self.steps == 0 {
            return Err(scenario_err("steps", "must be >= 1"));
        }
        self.delta.check(self.sensors.len()).map_err(|e| match e {
            Error::Value { what, problem } => scenario_err(what, problem),
            other => other,
        })?;
        pos(self.sigma1, "sigma1")?;
        pos(self.sigma2, "sigma2")?;
        if self.consensus_iters == Some(0) {
            return Err(scenario_err(
                "consensus_iters",
                "must be >= 1 (or absent for the adequate L)",
            ));
        }
        let n = self.state_dim();
        if self.x0.len() != n {
            return Err(scenario_err(
                "x0",
                format!(
                    "has {} entries, the motion model has {n} states",
                    self.x0.len()
                ),
            ));
        }
        if let Some(i) = self.x0.iter().position(|v| !v.is_finite()) {
            return Err(scenario_err(format!("x0[{i}]"), "must be finite"));
        }
        if self.p0_diag.len() != n {
            return Err(scenario_err(
                "p0_diag",
                format!(
                    "has {} entries, the motion model has {n} states",
                    self.p0_diag.len()
                ),
            ));
        }
        for (i, v) in self.p0_diag.iter().enumerate() {
            pos(*v, &format!("p0_diag[{i}]"))?;
        }
        if self.sensors.is_empty() {
            return Err(scenario_err("sensors", "at least one sensor is needed"));
        }
        for (i, s) in self.sensors.iter().enumerate() {
            if s.iter().any(|v| !v.is_finite()) {
                return Err(scenario_err(format!("sensors[{i}]"), "must be finite"));
            }
        }
        match &self.motion {
            MotionSpec::CoordinatedTurn { q1, q2 } => {
                if !(q1.is_finite() && *q1 >= 0.0) {
                    return Err(scenario_err("motion.q1", "must be finite and >= 0"));
                }
                if !(q2.is_finite() && *q2 >= 0.0) {
                    return Err(scenario_err("motion.q2", "must be finite and >= 0"));
                }
            }
            MotionSpec::ConstantVelocity { q } | MotionSpec::ConstantAcceleration { q } => {
                if !(q.is_finite() && *q >= 0.0) {
                    return Err(scenario_err("motion.q", "must be finite and >= 0"));
                }
            }
        }
        match &self.measurement {
            MeasurementSpec::RangePitchAzimuth { sigma_r, sigma_a } => {
                pos(*sigma_r, "measurement.sigma_r")?;
                pos(*sigma_a, "measurement.sigma_a")?;
            }
            MeasurementSpec::Position { sigma } => {
                for (i, s) in sigma.iter().enumerate() {
                    pos(*s, &format!("measurement.sigma[{i}]"))?;
                }
            }
        }
        self.weights()?;
        let d = self.dynamic;
        Trigger::Dynamic {
            delta: self.delta.node(0),
            lambda: d.lambda,
            theta: d.theta,
        }
        .validate()
        .map_err(|e| scenario_err("dynamic", e.to_string()))?;
        edccif_core::SigmaRule::<f64>::unscented(n, self.ukf.alpha, self.ukf.beta, self.ukf.kappa)
            .map_err(|e| scenario_err("ukf", e.to_string()))?;
        Ok(())
    }

    /// The validated row-major adjacency.
    pub fn adjacency(&self) -> Result<Vec<bool>> {
        self.topology.adjacency(self.nodes())
    }

    /// The combination weight matrix (row-major): the topology's own
    /// (see [`Topology::weights`]) or max-degree.
    pub fn weights(&self) -> Result<Vec<f64>> {
        self.topology.weights(self.nodes())
    }

    /// A copy with its own communication graph: `adjacency` (row-major `N × N`)
    /// and/or combination `weights` (row-major `N × N`, see
    /// [`topology::validate_weights`]). With weights but no adjacency, the graph
    /// is where the weights are `> 0` off the diagonal; with an adjacency but no
    /// weights, the weights are max-degree. Disconnected or asymmetric graphs and
    /// weights that are not symmetric and row-stochastic are errors
    /// ([`Error::Graph`] or the core's graph errors).
    ///
    /// ```
    /// use edccif_sim::Scenario;
    /// let sc = Scenario::paper(3);
    /// let w = [0.5, 0.25, 0.25, 0.25, 0.5, 0.25, 0.25, 0.25, 0.5];
    /// let custom = sc.with_graph(None, Some(&w)).unwrap();
    /// assert_eq!(custom.weights().unwrap(), w.to_vec());
    /// assert_eq!(custom.adjacency().unwrap(), sc.adjacency().unwrap()); // a ring of 3 is complete
    /// let line = [false, true, false, true, false, true, false, true, false];
    /// assert!(sc.with_graph(Some(&line), Some(&w)).is_err()); // weight on a missing edge
    /// ```
    pub fn with_graph(&self, adjacency: Option<&[bool]>, weights: Option<&[f64]>) -> Result<Self> {
        let n = self.nodes();
        let shape = |what: &str, len: usize| Error::Shape {
            what: what.into(),
            expected: format!("({n}, {n}) (one row and column per node)"),
            got: format!("{len} values"),
        };
        if adjacency.is_none() && weights.is_none() {
            return Ok(self.clone());
        }
        if let Some(a) = adjacency {
            if a.len() != n * n {
                return Err(shape("adjacency", a.len()));
            }
        }
        if let Some(w) = weights {
            if w.len() != n * n {
                return Err(shape("weights", w.len()));
            }
        }
        let a: Vec<bool> = match (adjacency, weights) {
            (Some(a), _) => a.to_vec(),
            (None, Some(w)) => topology::adjacency_of_weights(w, n),
            (None, None) => unreachable!("handled above"),
        };
        let rows = |i: usize| a[i * n..(i + 1) * n].to_vec();
        let topology = Topology::Custom {
            adjacency: (0..n).map(rows).collect(),
            weights: weights.map(|w| w.chunks(n).map(<[f64]>::to_vec).collect()),
        };
        let sc = Self {
            topology,
            ..self.clone()
        };
        sc.validate()?;
        Ok(sc)
    }

    /// Consensus iterations in force: the scenario's, or the adequate `L`.
    pub fn consensus_iterations(&self) -> Result<usize> {
        match self.consensus_iters {
            Some(l) => Ok(l),
            None => Ok(topology::adequate_consensus_iterations(
                &self.weights()?,
                self.nodes(),
            )),
        }
    }

    /// The nodes' sensors.
    pub fn sensor_models(&self) -> Result<Vec<Sensor>> {
        self.sensors
            .iter()
            .map(|p| {
                Ok(match &self.measurement {
                    MeasurementSpec::RangePitchAzimuth { sigma_r, sigma_a } => Sensor::Rpa(
                        RangePitchAzimuth::new(*p, *sigma_r, *sigma_a)?
                            .with_fast_trig(self.fast_trig),
                    ),
                    MeasurementSpec::Position { sigma } => Sensor::Pos(Position3::new(*sigma)?),
                })
            })
            .collect()
    }

    /// The coordinated-turn model (errors if the scenario uses another motion).
    pub fn coordinated_turn(&self) -> Result<CoordinatedTurn<f64>> {
        match self.motion {
            MotionSpec::CoordinatedTurn { q1, q2 } => {
                Ok(CoordinatedTurn::new(q1, q2)?.with_fast_trig(self.fast_trig))
            }
            _ => Err(scenario_err("motion", "is not coordinated-turn")),
        }
    }

    /// The constant-velocity model (errors if the scenario uses another motion).
    pub fn constant_velocity(&self) -> Result<ConstantVelocity<f64>> {
        match self.motion {
            MotionSpec::ConstantVelocity { q } => Ok(ConstantVelocity::new(q)?),
            _ => Err(scenario_err("motion", "is not constant-velocity")),
        }
    }

    /// The constant-acceleration model (errors if the scenario uses another motion).
    pub fn constant_acceleration(&self) -> Result<ConstantAcceleration<f64>> {
        match self.motion {
            MotionSpec::ConstantAcceleration { q } => Ok(ConstantAcceleration::new(q)?),
            _ => Err(scenario_err("motion", "is not constant-acceleration")),
        }
    }
}
