//! Scenarios: everything that defines an experiment, read and written as TOML.

use std::f64::consts::PI;
use std::path::Path;

use edccif_core::models::{
    ConstantAcceleration, ConstantVelocity, CoordinatedTurn, Position3, RangePitchAzimuth,
};
use edccif_core::{FusionRule, MeasurementModel, PointImages, Trigger};
use nalgebra::{SMatrix, SVector};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::delta::Delta;
use crate::error::{scenario_err, Error, Result};
use crate::topology::{self, Topology};

/// Target motion model and its noise (TOML table `[motion]`, selected by `kind`).
///
/// ```
/// use edccif_sim::MotionSpec;
/// let m: MotionSpec = toml::from_str("kind = \"constant-velocity\"\nq = 0.5\ndim = 2").unwrap();
/// assert_eq!(m, MotionSpec::ConstantVelocity { q: 0.5, dim: 2 });
/// assert_eq!((m.dim(), m.spatial_dim()), (4, Some(2)));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MotionSpec {
    /// Coordinated turn, 7 states `[px, py, pz, vx, vy, vz, ω]` (ALGORITHM.md §1).
    CoordinatedTurn {
        /// Position/velocity noise intensity (m²/s³).
        q1: f64,
        /// Turn-rate noise intensity (rad²/s³).
        q2: f64,
    },
    /// Coordinated turn in the plane, 5 states `[x, y, vx, vy, ω]`.
    #[serde(rename = "coordinated-turn-2d")]
    CoordinatedTurn2D {
        /// Position/velocity noise intensity (m²/s³).
        q1: f64,
        /// Turn-rate noise intensity (rad²/s³).
        q2: f64,
    },
    /// Constant velocity, `2·dim` states `[p(dim), v(dim)]` (white acceleration).
    ConstantVelocity {
        /// White-acceleration intensity (m²/s³).
        q: f64,
        /// Spatial dimension: 1, 2 or 3 (default 3).
        #[serde(default = "three", skip_serializing_if = "is_three")]
        #[schemars(range(min = 1, max = 3), default = "three")]
        dim: usize,
    },
    /// Constant acceleration, `3·dim` states `[p(dim), v(dim), a(dim)]` (white
    /// jerk; `edccif_core::models::ConstantAcceleration`).
    ConstantAcceleration {
        /// White-jerk intensity (m²/s⁵).
        q: f64,
        /// Spatial dimension: 1, 2 or 3 (default 3).
        #[serde(default = "three", skip_serializing_if = "is_three")]
        #[schemars(range(min = 1, max = 3), default = "three")]
        dim: usize,
    },
    /// Random walk `x' = x + w`, `Q = q·dt·I`, `n` states (the first 1–3 of
    /// them are what position sensors see).
    RandomWalk {
        /// State dimension (1–12).
        #[schemars(range(min = 1, max = 12))]
        n: usize,
        /// Noise intensity (state units² per s).
        q: f64,
    },
    /// Linear motion `x' = F x + w`, `w ~ N(0, Q)`, the same `F`, `Q` whatever
    /// the time step; `n` (1–12) from the size of `f`.
    Linear {
        /// Transition matrix `F` (`n × n`, rows).
        f: Vec<Vec<f64>>,
        /// Process noise `Q` (`n × n`, rows; symmetric, positive semi-definite).
        q: Vec<Vec<f64>>,
    },
    /// A motion model of one's own in Python, by reference: `model =
    /// "module:attribute"` names an `edccif.models` motion model (e.g. a
    /// `CustomMotion`) or a callable of no arguments returning one, imported
    /// from the scenario's `python_path` and `sys.path`. Only the Python
    /// package runs it; a Rust-only run refuses the scenario.
    Python {
        /// `module:attribute`, e.g. `"turn_models:turn_motion"`.
        model: String,
        /// State dimension `n` of the model (1–12; checked against it).
        #[schemars(range(min = 1, max = 12))]
        n: usize,
    },
}

fn three() -> usize {
    3
}

fn is_three(v: &usize) -> bool {
    *v == 3
}

impl MotionSpec {
    /// State dimension.
    pub fn dim(&self) -> usize {
        match self {
            MotionSpec::CoordinatedTurn { .. } => 7,
            MotionSpec::CoordinatedTurn2D { .. } => 5,
            MotionSpec::ConstantVelocity { dim, .. } => 2 * dim,
            MotionSpec::ConstantAcceleration { dim, .. } => 3 * dim,
            MotionSpec::RandomWalk { n, .. } => *n,
            MotionSpec::Linear { f, .. } => f.len(),
            MotionSpec::Python { n, .. } => *n,
        }
    }

    /// How many leading states are the target's position (`None`: the model
    /// does not say; sensors then need only enough states).
    pub fn spatial_dim(&self) -> Option<usize> {
        match self {
            MotionSpec::CoordinatedTurn { .. } => Some(3),
            MotionSpec::CoordinatedTurn2D { .. } => Some(2),
            MotionSpec::ConstantVelocity { dim, .. }
            | MotionSpec::ConstantAcceleration { dim, .. } => Some(*dim),
            MotionSpec::RandomWalk { .. }
            | MotionSpec::Linear { .. }
            | MotionSpec::Python { .. } => None,
        }
    }

    /// The `kind` as written in a file, e.g. `"coordinated-turn"`.
    pub fn kind(&self) -> &'static str {
        match self {
            MotionSpec::CoordinatedTurn { .. } => "coordinated-turn",
            MotionSpec::CoordinatedTurn2D { .. } => "coordinated-turn-2d",
            MotionSpec::ConstantVelocity { .. } => "constant-velocity",
            MotionSpec::ConstantAcceleration { .. } => "constant-acceleration",
            MotionSpec::RandomWalk { .. } => "random-walk",
            MotionSpec::Linear { .. } => "linear",
            MotionSpec::Python { .. } => "python",
        }
    }

    /// Whether the model has a fast trigonometry (`fast_trig`).
    pub fn has_fast_trig(&self) -> bool {
        matches!(
            self,
            MotionSpec::CoordinatedTurn { .. } | MotionSpec::CoordinatedTurn2D { .. }
        )
    }
}

/// What every sensor measures in the uniform form of a scenario (`sensors` =
/// the nodes' positions, `[measurement]` = their one sensor kind): the paper's
/// two kinds. Scenarios with other sensors, or a sensor of its own per node,
/// list them in `[[nodes]]` ([`NodeSpec`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
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

/// One node's sensor in a `[[nodes]]` scenario (the `sensor` table of a
/// node), selected by `kind`. Positions are in metres, in the plane (`[x, y]`)
/// or in space (`[x, y, z]`) as the kind says; the target's position is the
/// first 2 or 3 states of the motion model.
///
/// ```
/// use edccif_sim::SensorSpec;
/// let s: SensorSpec = toml::from_str("kind = \"bearing-only\"\nposition = [10.0, 0.0]\nsigma_b = 0.02").unwrap();
/// assert_eq!((s.meas_dim(), s.spatial_dim()), (1, 2));
/// assert!(toml::from_str::<SensorSpec>("kind = \"bearing-only\"\nposition = [10.0, 0.0]\nsigma = 0.02")
///     .unwrap_err().to_string().contains("sigma"));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SensorSpec {
    /// Range, pitch and azimuth of the target from `position` (the paper's
    /// sensor, `m = 3`, components 1 and 2 angles).
    RangePitchAzimuth {
        /// Sensor position `[x, y, z]` (m).
        position: [f64; 3],
        /// Range standard deviation (m).
        sigma_r: f64,
        /// Standard deviation of both angles (rad).
        sigma_a: f64,
    },
    /// Range and bearing in the plane from `position` (`m = 2`, component 1 an
    /// angle).
    RangeBearing {
        /// Sensor position `[x, y]` (m).
        position: [f64; 2],
        /// Range standard deviation (m).
        sigma_r: f64,
        /// Bearing standard deviation (rad).
        sigma_b: f64,
    },
    /// Bearing in the plane from `position` (`m = 1`, an angle).
    BearingOnly {
        /// Sensor position `[x, y]` (m).
        position: [f64; 2],
        /// Bearing standard deviation (rad).
        sigma_b: f64,
    },
    /// Range from `position`, in the plane (2 coordinates) or in space (3)
    /// (`m = 1`).
    RangeOnly {
        /// Sensor position `[x, y]` or `[x, y, z]` (m).
        position: Vec<f64>,
        /// Range standard deviation (m).
        sigma_r: f64,
    },
    /// The target's position, 2 or 3 coordinates (as many as `sigma` has).
    Position {
        /// Standard deviation per axis (m).
        sigma: Vec<f64>,
    },
    /// Linear measurement `z = H x + v`, `v ~ N(0, R)` (`m` rows of `h`, 1–6).
    Linear {
        /// Measurement matrix `H` (`m × n`, rows).
        h: Vec<Vec<f64>>,
        /// Noise covariance `R` (`m × m`, rows; symmetric, positive definite).
        r: Vec<Vec<f64>>,
    },
    /// A sensor of one's own in Python, by reference: `model =
    /// "module:attribute"` names an `edccif.models` measurement model (e.g. a
    /// `CustomMeasurement`) or a callable of no arguments returning one, as
    /// the motion's `kind = "python"`. Only the Python package runs it.
    Python {
        /// `module:attribute`, e.g. `"turn_models:tag"`.
        model: String,
        /// Measurement dimension `m` of the model (1–6; checked against it).
        #[schemars(range(min = 1, max = 6))]
        m: usize,
    },
}

impl SensorSpec {
    /// Measurement dimension `m`.
    pub fn meas_dim(&self) -> usize {
        match self {
            SensorSpec::RangePitchAzimuth { .. } => 3,
            SensorSpec::RangeBearing { .. } => 2,
            SensorSpec::BearingOnly { .. } | SensorSpec::RangeOnly { .. } => 1,
            SensorSpec::Position { sigma } => sigma.len(),
            SensorSpec::Linear { h, .. } => h.len(),
            SensorSpec::Python { m, .. } => *m,
        }
    }

    /// How many leading states must be the target's position (0 for a linear
    /// model, whose `h` gives its state dimension).
    pub fn spatial_dim(&self) -> usize {
        match self {
            SensorSpec::RangePitchAzimuth { .. } => 3,
            SensorSpec::RangeBearing { .. } | SensorSpec::BearingOnly { .. } => 2,
            SensorSpec::RangeOnly { position, .. } => position.len(),
            SensorSpec::Position { sigma } => sigma.len(),
            SensorSpec::Linear { .. } | SensorSpec::Python { .. } => 0,
        }
    }

    /// The `kind` as written in a file, e.g. `"bearing-only"`.
    pub fn kind(&self) -> &'static str {
        match self {
            SensorSpec::RangePitchAzimuth { .. } => "range-pitch-azimuth",
            SensorSpec::RangeBearing { .. } => "range-bearing",
            SensorSpec::BearingOnly { .. } => "bearing-only",
            SensorSpec::RangeOnly { .. } => "range-only",
            SensorSpec::Position { .. } => "position",
            SensorSpec::Linear { .. } => "linear",
            SensorSpec::Python { .. } => "python",
        }
    }

    /// Whether the model has a fast trigonometry (`fast_trig`).
    pub fn has_fast_trig(&self) -> bool {
        matches!(
            self,
            SensorSpec::RangePitchAzimuth { .. }
                | SensorSpec::RangeBearing { .. }
                | SensorSpec::BearingOnly { .. }
        )
    }

    /// Checks the values; `field` names the sensor in errors (e.g.
    /// `nodes[2].sensor`), `n` is the state dimension and `spatial` the
    /// motion's spatial dimension, if it has one.
    fn validate(&self, field: &str, n: usize, spatial: Option<usize>) -> Result<()> {
        let key = |k: &str| format!("{field}.{k}");
        let finite_pos = |v: f64, k: &str| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(scenario_err(
                    key(k),
                    format!("must be finite and > 0, got {v}"),
                ))
            }
        };
        let finite_all = |p: &[f64], k: &str| -> Result<()> {
            match p.iter().position(|v| !v.is_finite()) {
                Some(i) => Err(scenario_err(format!("{}[{i}]", key(k)), "must be finite")),
                None => Ok(()),
            }
        };
        let two_or_three = |len: usize, k: &str, what: &str| -> Result<()> {
            if len == 2 || len == 3 {
                Ok(())
            } else {
                Err(scenario_err(
                    key(k),
                    format!("has {len} values; expected 2 or 3 ({what})"),
                ))
            }
        };
        match self {
            SensorSpec::RangePitchAzimuth {
                position,
                sigma_r,
                sigma_a,
            } => {
                finite_all(position, "position")?;
                finite_pos(*sigma_r, "sigma_r")?;
                finite_pos(*sigma_a, "sigma_a")?;
            }
            SensorSpec::RangeBearing {
                position,
                sigma_r,
                sigma_b,
            } => {
                finite_all(position, "position")?;
                finite_pos(*sigma_r, "sigma_r")?;
                finite_pos(*sigma_b, "sigma_b")?;
            }
            SensorSpec::BearingOnly { position, sigma_b } => {
                finite_all(position, "position")?;
                finite_pos(*sigma_b, "sigma_b")?;
            }
            SensorSpec::RangeOnly { position, sigma_r } => {
                two_or_three(position.len(), "position", "[x, y] or [x, y, z]")?;
                finite_all(position, "position")?;
                finite_pos(*sigma_r, "sigma_r")?;
            }
            SensorSpec::Position { sigma } => {
                two_or_three(sigma.len(), "sigma", "one standard deviation per axis")?;
                for (i, v) in sigma.iter().enumerate() {
                    finite_pos(*v, &format!("sigma[{i}]"))?;
                }
            }
            SensorSpec::Linear { h, r } => {
                let m = h.len();
                if !(1..=MAX_MEAS_DIM).contains(&m) {
                    return Err(scenario_err(
                        key("h"),
                        format!("has {m} rows; expected 1 to {MAX_MEAS_DIM} (the measurement dimension)"),
                    ));
                }
                check_matrix(h, m, n, &key("h"))?;
                check_matrix(r, m, m, &key("r"))?;
                let rm = nalgebra::DMatrix::from_fn(m, m, |i, j| r[i][j]);
                if (0..m).any(|i| {
                    (0..m)
                        .any(|j| (rm[(i, j)] - rm[(j, i)]).abs() > 1e-12 * (1.0 + rm[(i, j)].abs()))
                }) {
                    return Err(scenario_err(key("r"), "must be symmetric"));
                }
                if rm.cholesky().is_none() {
                    return Err(scenario_err(key("r"), "must be positive definite"));
                }
            }
            SensorSpec::Python { model, m } => {
                check_reference(model, &key("model"))?;
                if !(1..=MAX_MEAS_DIM).contains(m) {
                    return Err(scenario_err(
                        key("m"),
                        format!("expected a measurement dimension 1 to {MAX_MEAS_DIM}, got {m}"),
                    ));
                }
            }
        }
        let d = self.spatial_dim();
        if d > n {
            return Err(scenario_err(
                key("kind"),
                format!(
                    "`{}` measures a {d}-D position, the motion model has only {n} states",
                    self.kind()
                ),
            ));
        }
        if let Some(s) = spatial {
            if d > s {
                return Err(scenario_err(
                    key("kind"),
                    format!(
                        "`{}` measures a {d}-D position, the motion model's position is {s}-D",
                        self.kind()
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// One node of a `[[nodes]]` scenario: its sensor and when it measures.
/// Without `every` or `times` the sensor measures at every step; the node's
/// trigger threshold is its entry of the scenario's `delta` (one number for
/// every node, or a list with one per node).
///
/// ```
/// use edccif_sim::NodeSpec;
/// let n: NodeSpec = toml::from_str("sensor = { kind = \"position\", sigma = [0.05, 0.05] }\nevery = 5").unwrap();
/// assert_eq!(n.every, Some(5));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NodeSpec {
    /// The node's sensor.
    pub sensor: SensorSpec,
    /// Measures at every `every`-th step only (steps `every`, `2·every`, …,
    /// counted from 1; default 1: every step).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 1))]
    pub every: Option<usize>,
    /// Measures at these times only (s; increasing, each a step's time
    /// `k·dt`, `1 ≤ k ≤ steps`). Not with `every`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub times: Option<Vec<f64>>,
}

impl NodeSpec {
    /// A node whose sensor measures at every step.
    pub fn new(sensor: SensorSpec) -> Self {
        Self {
            sensor,
            every: None,
            times: None,
        }
    }
}

/// A Python model reference `module:attribute`: a dotted module name and a
/// dotted attribute path, each of Python identifiers.
fn check_reference(reference: &str, field: &str) -> Result<()> {
    let dotted = |s: &str| {
        !s.is_empty()
            && s.split('.').all(|part| {
                let mut c = part.chars();
                c.next()
                    .is_some_and(|first| first == '_' || first.is_alphabetic())
                    && c.all(|ch| ch == '_' || ch.is_alphanumeric())
            })
    };
    match reference.split_once(':') {
        Some((module, attr)) if dotted(module) && dotted(attr) => Ok(()),
        _ => Err(scenario_err(
            field,
            format!(
                "`{reference}` is not a Python model reference; expected `module:attribute` \
                 (e.g. \"turn_models:turn_motion\")"
            ),
        )),
    }
}

/// Largest state dimension a scenario's model may have.
pub const MAX_STATE_DIM: usize = 12;
/// Largest measurement dimension a scenario's sensor may have.
pub const MAX_MEAS_DIM: usize = 6;

/// An `rows × cols` matrix of finite numbers, given as rows.
fn check_matrix(a: &[Vec<f64>], rows: usize, cols: usize, field: &str) -> Result<()> {
    if a.len() != rows || a.iter().any(|r| r.len() != cols) {
        return Err(Error::Shape {
            what: field.into(),
            expected: format!("({rows}, {cols})"),
            got: format!(
                "({}, {:?})",
                a.len(),
                a.iter().map(Vec::len).collect::<Vec<_>>()
            ),
        });
    }
    for (i, r) in a.iter().enumerate() {
        if let Some(j) = r.iter().position(|v| !v.is_finite()) {
            return Err(scenario_err(format!("{field}[{i}][{j}]"), "must be finite"));
        }
    }
    Ok(())
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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
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

/// A complete experiment definition; the file format (every key, its unit,
/// default and allowed values) is in `docs/formats.md`, "Scenario files", and
/// [`json_schema`] is its JSON Schema.
///
/// The nodes are given in one of two forms: the **uniform form** of the
/// paper's files, `sensors` (one position per node) with one `[measurement]`
/// for all, or **per node**, `[[nodes]]` ([`NodeSpec`]: each node's own
/// sensor kind, position, noise and rate). Scenarios in the uniform form with
/// a 3-D coordinated-turn, constant-velocity or constant-acceleration motion
/// run on the typed network ([`Scenario::is_typed`]); every other scenario runs
/// on the model network ([`crate::mixed`]).
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "edccif scenario")]
pub struct Scenario {
    /// A label.
    pub name: String,
    /// Sampling period (s).
    pub dt: f64,
    /// Number of steps `T`.
    pub steps: usize,
    /// Send-on-delta threshold `δ`: one number for every node, or one per node
    /// (`delta = [0.04, 0.01, 0.04]` in TOML); in the measurement's raw squared
    /// units, or in units of its noise when `normalised`.
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
    #[schemars(range(min = 1))]
    pub consensus_iters: Option<usize>,
    /// True initial state `x₀`.
    pub x0: Vec<f64>,
    /// Diagonal of the initial covariance `P0` (variances).
    pub p0_diag: Vec<f64>,
    /// Uniform form: the node positions `[x, y, z]` (m), one per node, with
    /// one `measurement` for all (empty in the per-node form).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<[f64; 3]>,
    /// Motion model.
    pub motion: MotionSpec,
    /// Uniform form: every node's sensor kind and noise (`None` in the
    /// per-node form).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measurement: Option<MeasurementSpec>,
    /// Per-node form: each node's sensor and rate (empty in the uniform form).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub nodes: Vec<NodeSpec>,
    /// Communication topology.
    pub topology: Topology,
    /// Dynamic-trigger parameters.
    #[serde(default)]
    pub dynamic: DynamicTrigger,
    /// UKF parameters.
    #[serde(default)]
    pub ukf: UkfParams,
    /// Fast trigonometry (`fast_trig = false` in TOML for the reference path;
    /// default on): the coordinated turn's and the range/pitch/azimuth,
    /// range-bearing and bearing-only sensors' `with_fast_trig` (one `sin_cos`
    /// per prediction, no `atan2` per measurement point, and the remaining
    /// `atan2`/`sin_cos`, the EKF's included, by the inline kernel
    /// `edccif_core::trig`, within 2 ulp of the platform's libm). Results differ
    /// from the reference path (`false`: the platform's libm, bit for bit) in
    /// the last bits; models without a fast path ignore it. `docs/guide.md` §7
    /// and `docs/performance.md` have the bounds.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub fast_trig: bool,
    /// Closed form of the ET-CIF's untriggered contribution
    /// (`untriggered_closed_form = false` in TOML for the paper's stable form;
    /// default on): [`EtOptions::untriggered_closed_form`](edccif_core::EtOptions::untriggered_closed_form),
    /// `Ī = −σ1/(1+σ1) Y⁻ + Gᵀ R̃⁻¹ G` without the `n × n` inverse of `P̄`.
    /// Results differ from the stable form in the last bits
    /// (`docs/triggers.md`, "Closed form of the untriggered step"); the
    /// covariance-form rows ignore it.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub untriggered_closed_form: bool,
    /// The rule of the CI combination of the diffusion-with-CI rows (DC-CIF,
    /// EDC-CIF), by name (`fusion = "ici"` in TOML; `docs/fusion.md`); `None`:
    /// the paper's CI. A run's `fusion=` option replaces it.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "de_fusion_rule"
    )]
    #[schemars(with = "Option<String>")]
    pub fusion: Option<FusionRule>,
    /// Directories searched first for the modules of the Python models
    /// (`kind = "python"`), relative to the scenario file's directory (or to
    /// the working directory for a scenario not read from a file); put at the
    /// front of `sys.path` when a model is imported.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub python_path: Vec<String>,
    /// The directory of the file the scenario was read from
    /// ([`Scenario::from_toml_file`]), which `python_path` is relative to. Not
    /// part of the scenario's value: not written, not compared.
    #[serde(skip)]
    #[schemars(skip)]
    pub source_dir: SourceDir,
}

/// Where a scenario was read from (see [`Scenario::source_dir`]): equal to
/// every other, so that the same scenario read from a file or from text
/// compares equal.
///
/// ```
/// use edccif_sim::scenario::SourceDir;
/// assert_eq!(SourceDir(Some("a".into())), SourceDir(None));
/// ```
#[derive(Debug, Clone, Default)]
pub struct SourceDir(pub Option<std::path::PathBuf>);

impl PartialEq for SourceDir {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Parses the name of a fusion rule (`docs/fusion.md`) for a scenario's
/// `fusion` key: the rule names only (the structural fusions are run options).
///
/// ```
/// assert!(edccif_sim::parse_fusion_rule("split-ci").is_ok());
/// assert!(edccif_sim::parse_fusion_rule("consensus").unwrap_err().to_string().contains("ici"));
/// ```
pub fn parse_fusion_rule(s: &str) -> Result<FusionRule> {
    let key = s.trim().to_ascii_lowercase().replace('_', "-");
    let key = if key == "diffusion-ci" {
        "ci".to_string()
    } else {
        key
    };
    FusionRule::from_name(&key).ok_or_else(|| Error::UnknownOption {
        name: format!("fusion={s}"),
        expected: format!("a fusion rule: one of {}", FusionRule::NAMES.join(", ")),
    })
}

/// Serde helper: a fusion rule by name, with the names listed on error.
fn de_fusion_rule<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<FusionRule>, D::Error> {
    let s = String::deserialize(d)?;
    parse_fusion_rule(&s)
        .map(Some)
        .map_err(serde::de::Error::custom)
}

/// Serde helper: leave a default-off flag out of the serialised scenario.
fn is_false(b: &bool) -> bool {
    !*b
}

/// Serde helper: leave a default-on flag out of the serialised scenario.
fn is_true(b: &bool) -> bool {
    *b
}

/// Serde default of the default-on flags.
fn yes() -> bool {
    true
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
            delta: Delta::All(crate::delta::PAPER_DELTA),
            normalised: false,
            sigma1: 5e-4,
            sigma2: 5e-4,
            consensus_iters: None,
            x0: vec![5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3],
            p0_diag,
            sensors,
            motion: MotionSpec::CoordinatedTurn { q1: 0.5, q2: 1e-4 },
            measurement: Some(MeasurementSpec::RangePitchAzimuth {
                sigma_r: 0.1,
                sigma_a: 0.01,
            }),
            nodes: Vec::new(),
            topology: Topology::Ring,
            dynamic: DynamicTrigger::default(),
            ukf: UkfParams::default(),
            fast_trig: true,
            untriggered_closed_form: true,
            fusion: None,
            python_path: Vec::new(),
            source_dir: SourceDir::default(),
        }
    }

    /// Number of nodes (sensors).
    pub fn nodes(&self) -> usize {
        if self.nodes.is_empty() {
            self.sensors.len()
        } else {
            self.nodes.len()
        }
    }

    /// State dimension `n`.
    pub fn state_dim(&self) -> usize {
        self.motion.dim()
    }

    /// The one measurement dimension `m` of every node, when they share one
    /// (`None` for sensors of different dimensions).
    ///
    /// ```
    /// assert_eq!(edccif_sim::Scenario::paper(4).meas_dim(), Some(3));
    /// ```
    pub fn meas_dim(&self) -> Option<usize> {
        let dims = self.meas_dims();
        let first = *dims.first()?;
        dims.iter().all(|m| *m == first).then_some(first)
    }

    /// Every node's measurement dimension, in node order.
    pub fn meas_dims(&self) -> Vec<usize> {
        self.node_specs()
            .iter()
            .map(|n| n.sensor.meas_dim())
            .collect()
    }

    /// Whether the scenario runs on the typed network of the paper's kinds:
    /// the uniform form (`sensors` + `[measurement]`) with a 3-D
    /// coordinated-turn, constant-velocity or constant-acceleration motion.
    /// Every other scenario runs on the model network ([`crate::mixed`]).
    ///
    /// ```
    /// use edccif_sim::Scenario;
    /// assert!(Scenario::paper(4).is_typed());
    /// assert!(!Scenario::paper(4).per_node().is_typed());
    /// ```
    pub fn is_typed(&self) -> bool {
        self.nodes.is_empty()
            && matches!(
                self.motion,
                MotionSpec::CoordinatedTurn { .. }
                    | MotionSpec::ConstantVelocity { dim: 3, .. }
                    | MotionSpec::ConstantAcceleration { dim: 3, .. }
            )
    }

    /// Whether a model of the scenario is a Python model (`kind = "python"`,
    /// run by the Python package only).
    ///
    /// ```
    /// use edccif_sim::{MotionSpec, Scenario};
    /// let mut sc = Scenario::paper(4);
    /// assert!(!sc.has_python_models());
    /// sc.motion = MotionSpec::Python { model: "turn_models:turn_motion".into(), n: 7 };
    /// assert!(sc.has_python_models() && !sc.is_typed());
    /// ```
    pub fn has_python_models(&self) -> bool {
        matches!(self.motion, MotionSpec::Python { .. })
            || self
                .nodes
                .iter()
                .any(|n| matches!(n.sensor, SensorSpec::Python { .. }))
    }

    /// The directories of `python_path`, relative to the scenario file's
    /// directory when it was read from one, in order.
    pub fn python_dirs(&self) -> Vec<std::path::PathBuf> {
        self.python_path
            .iter()
            .map(|d| match &self.source_dir.0 {
                Some(base) => base.join(d),
                None => std::path::PathBuf::from(d),
            })
            .collect()
    }

    /// How many leading states are the target's position: the motion's own
    /// (`MotionSpec::spatial_dim`), else the most any node's sensor reads
    /// (`SensorSpec::spatial_dim`), else up to 3 of the states.
    pub fn position_dim(&self) -> usize {
        self.motion.spatial_dim().unwrap_or_else(|| {
            let s = self
                .node_specs()
                .iter()
                .map(|n| n.sensor.spatial_dim())
                .max();
            match s {
                Some(d) if d > 0 => d,
                _ => self.motion.dim().min(3),
            }
        })
    }

    /// Every node's sensor and rate: the `[[nodes]]` of the per-node form, or
    /// the uniform form's sensors as nodes (each measuring at every step).
    pub fn node_specs(&self) -> Vec<NodeSpec> {
        if !self.nodes.is_empty() {
            return self.nodes.clone();
        }
        let Some(m) = &self.measurement else {
            return Vec::new();
        };
        self.sensors
            .iter()
            .map(|p| {
                NodeSpec::new(match m {
                    MeasurementSpec::RangePitchAzimuth { sigma_r, sigma_a } => {
                        SensorSpec::RangePitchAzimuth {
                            position: *p,
                            sigma_r: *sigma_r,
                            sigma_a: *sigma_a,
                        }
                    }
                    MeasurementSpec::Position { sigma } => SensorSpec::Position {
                        sigma: sigma.to_vec(),
                    },
                })
            })
            .collect()
    }

    /// The same scenario in the per-node form (`[[nodes]]`): the same models,
    /// so the same simulation and estimates, on the model network.
    pub fn per_node(&self) -> Self {
        Self {
            nodes: self.node_specs(),
            sensors: Vec::new(),
            measurement: None,
            ..self.clone()
        }
    }

    /// Whether node `i` measures at step `t` (0-based; the step's time is
    /// `(t + 1)·dt`): its `every` or `times`, else every step.
    ///
    /// ```
    /// let mut sc = edccif_sim::Scenario::paper(2).per_node();
    /// sc.nodes[1].every = Some(3);
    /// let steps: Vec<usize> = (0..7).filter(|&t| sc.measures(1, t)).collect();
    /// assert_eq!(steps, [2, 5]);
    /// ```
    pub fn measures(&self, i: usize, t: usize) -> bool {
        let Some(node) = self.nodes.get(i) else {
            return true;
        };
        if let Some(times) = &node.times {
            return times.iter().any(|s| self.step_of_time(*s) == Some(t + 1));
        }
        node.every.is_none_or(|k| (t + 1).is_multiple_of(k))
    }

    /// The 1-based step whose time `k·dt` is `s` (to 1e-9 of a step), if any.
    fn step_of_time(&self, s: f64) -> Option<usize> {
        let k = (s / self.dt).round();
        ((s / self.dt - k).abs() <= 1e-9 && k >= 1.0).then_some(k as usize)
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
        let mut sc = Self::from_toml_str(&text).map_err(|e| match e {
            Error::Parse(m) => Error::Parse(format!("{}: {m}", path.display())),
            other => other,
        })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        sc.source_dir = SourceDir(Some(if dir.as_os_str().is_empty() {
            std::path::PathBuf::from(".")
        } else {
            dir.to_path_buf()
        }));
        Ok(sc)
    }

    /// Writes TOML.
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| Error::Parse(e.to_string()))
    }

    /// Checks every field; the error names the field and what is expected.
    /// Values a run would ignore are errors too (both node forms given, `every`
    /// with `times`).
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
        crate::limits::check_nodes(self.nodes())?;
        if let Some(entries) = self.topology.entries_bound(self.nodes()) {
            crate::topology::check_lists(self.nodes(), entries)?;
        }
        let nonneg = |v: f64, field: &str| -> Result<()> {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(scenario_err(
                    field,
                    format!("must be finite and >= 0, got {v}"),
                ))
            }
        };
        pos(self.dt, "dt")?;
        if self.steps == 0 {
            return Err(scenario_err("steps", "must be >= 1"));
        }
        self.validate_node_forms()?;
        let k = self.nodes();
        self.delta.check(k).map_err(|e| match e {
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
        match &self.motion {
            MotionSpec::CoordinatedTurn { q1, q2 } | MotionSpec::CoordinatedTurn2D { q1, q2 } => {
                nonneg(*q1, "motion.q1")?;
                nonneg(*q2, "motion.q2")?;
            }
            MotionSpec::ConstantVelocity { q, dim }
            | MotionSpec::ConstantAcceleration { q, dim } => {
                nonneg(*q, "motion.q")?;
                if !(1..=3).contains(dim) {
                    return Err(scenario_err(
                        "motion.dim",
                        format!("expected a spatial dimension 1, 2 or 3, got {dim}"),
                    ));
                }
            }
            MotionSpec::RandomWalk { n, q } => {
                nonneg(*q, "motion.q")?;
                if !(1..=MAX_STATE_DIM).contains(n) {
                    return Err(scenario_err(
                        "motion.n",
                        format!("expected a state dimension 1 to {MAX_STATE_DIM}, got {n}"),
                    ));
                }
            }
            MotionSpec::Linear { f, q } => {
                let n = f.len();
                if !(1..=MAX_STATE_DIM).contains(&n) {
                    return Err(scenario_err(
                        "motion.f",
                        format!(
                            "has {n} rows; expected 1 to {MAX_STATE_DIM} (the state dimension)"
                        ),
                    ));
                }
                check_matrix(f, n, n, "motion.f")?;
                check_matrix(q, n, n, "motion.q")?;
                if (0..n).any(|i| {
                    (0..n).any(|j| (q[i][j] - q[j][i]).abs() > 1e-12 * (1.0 + q[i][j].abs()))
                }) {
                    return Err(scenario_err("motion.q", "must be symmetric"));
                }
            }
            MotionSpec::Python { model, n } => {
                check_reference(model, "motion.model")?;
                if !(1..=MAX_STATE_DIM).contains(n) {
                    return Err(scenario_err(
                        "motion.n",
                        format!("expected a state dimension 1 to {MAX_STATE_DIM}, got {n}"),
                    ));
                }
            }
        }
        if let Some(i) = self.python_path.iter().position(|d| d.trim().is_empty()) {
            return Err(scenario_err(
                format!("python_path[{i}]"),
                "is empty; expected a directory (relative to the scenario file)",
            ));
        }
        if !self.python_path.is_empty() && !self.has_python_models() {
            return Err(scenario_err(
                "python_path",
                "is given, but no model of this scenario is a Python model (`kind = \"python\"`); \
                 remove it",
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
        if self.nodes.is_empty() {
            for (i, s) in self.sensors.iter().enumerate() {
                if s.iter().any(|v| !v.is_finite()) {
                    return Err(scenario_err(format!("sensors[{i}]"), "must be finite"));
                }
            }
            match &self.measurement {
                Some(MeasurementSpec::RangePitchAzimuth { sigma_r, sigma_a }) => {
                    pos(*sigma_r, "measurement.sigma_r")?;
                    pos(*sigma_a, "measurement.sigma_a")?;
                }
                Some(MeasurementSpec::Position { sigma }) => {
                    for (i, s) in sigma.iter().enumerate() {
                        pos(*s, &format!("measurement.sigma[{i}]"))?;
                    }
                }
                None => {}
            }
            let spatial = self.motion.spatial_dim();
            if spatial.is_some_and(|d| d < 3) || n < 3 {
                return Err(scenario_err(
                    "measurement",
                    format!(
                        "measures a 3-D position, the motion `{}` has a {}-D one; give each \
                         node a sensor of the motion's dimension in [[nodes]]",
                        self.motion.kind(),
                        spatial.unwrap_or(n).min(n)
                    ),
                ));
            }
        } else {
            let spatial = self.motion.spatial_dim();
            for (i, node) in self.nodes.iter().enumerate() {
                node.sensor
                    .validate(&format!("nodes[{i}].sensor"), n, spatial)?;
                self.validate_rate(i, node)?;
            }
        }
        self.neighbours()?;
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

    /// Exactly one of the two node forms, complete.
    fn validate_node_forms(&self) -> Result<()> {
        if !self.nodes.is_empty() {
            for (key, given) in [
                ("sensors", !self.sensors.is_empty()),
                ("measurement", self.measurement.is_some()),
            ] {
                if given {
                    return Err(scenario_err(
                        key,
                        "is given with [[nodes]]; use either the uniform form (`sensors` and \
                         `[measurement]`) or one sensor per node in [[nodes]], not both",
                    ));
                }
            }
            return Ok(());
        }
        match (self.sensors.is_empty(), self.measurement.is_some()) {
            (true, _) => Err(scenario_err(
                "nodes",
                "no node: give [[nodes]] (one sensor per node) or `sensors` (node positions) \
                 with one `[measurement]`",
            )),
            (false, false) => Err(scenario_err(
                "measurement",
                "missing: `sensors` (node positions) needs a `[measurement]` table, the sensor \
                 of every node (or give each node its own sensor in [[nodes]])",
            )),
            (false, true) => Ok(()),
        }
    }

    /// A node's `every` or `times`.
    fn validate_rate(&self, i: usize, node: &NodeSpec) -> Result<()> {
        match (node.every, &node.times) {
            (Some(_), Some(_)) => Err(scenario_err(
                format!("nodes[{i}].times"),
                "is given with `every`; give one of them (every k-th step, or the times)",
            )),
            (Some(0), None) => Err(scenario_err(format!("nodes[{i}].every"), "must be >= 1")),
            (Some(k), None) if k > self.steps => Err(scenario_err(
                format!("nodes[{i}].every"),
                format!(
                    "is {k}, more than the {} steps: the sensor would never measure",
                    self.steps
                ),
            )),
            (_, Some(times)) => {
                if times.is_empty() {
                    return Err(scenario_err(
                        format!("nodes[{i}].times"),
                        "is empty: the sensor would never measure",
                    ));
                }
                let mut last = 0;
                for (j, s) in times.iter().enumerate() {
                    let field = format!("nodes[{i}].times[{j}]");
                    let Some(k) = self.step_of_time(*s).filter(|_| s.is_finite()) else {
                        return Err(scenario_err(
                            field,
                            format!(
                                "is {s} s, not a step's time: expected k·dt (dt = {} s, k = 1 to {})",
                                self.dt, self.steps
                            ),
                        ));
                    };
                    if k > self.steps {
                        return Err(scenario_err(
                            field,
                            format!(
                                "is {s} s, after the last step ({} s)",
                                self.steps as f64 * self.dt
                            ),
                        ));
                    }
                    if k <= last {
                        return Err(scenario_err(field, "times must increase"));
                    }
                    last = k;
                }
                Ok(())
            }
            (Some(_), None) | (None, None) => Ok(()),
        }
    }

    /// The validated row-major adjacency (`N × N`; refused with
    /// [`Error::TooLarge`] when it does not fit, see
    /// [`neighbours`](Self::neighbours)).
    pub fn adjacency(&self) -> Result<Vec<bool>> {
        self.topology.adjacency(self.nodes())
    }

    /// The combination weight matrix (row-major `N × N`): the topology's own
    /// (see [`Topology::weights`]) or max-degree. Refused with
    /// [`Error::TooLarge`] when it does not fit; [`neighbours`](Self::neighbours)
    /// is the same graph and weights as lists.
    pub fn weights(&self) -> Result<Vec<f64>> {
        self.topology.weights(self.nodes())
    }

    /// The graph and combination weights as neighbour lists
    /// ([`Topology::neighbours`]): what the scenario's networks step with,
    /// memory O(N + edges).
    ///
    /// ```
    /// use edccif_sim::Scenario;
    /// let sc = Scenario::paper(100_000);
    /// let g = sc.neighbours().unwrap();
    /// assert_eq!(g.entries(), 300_000);
    /// let small = Scenario::paper(8);
    /// assert_eq!(small.neighbours().unwrap().to_dense().unwrap(), small.weights().unwrap());
    /// ```
    pub fn neighbours(&self) -> Result<crate::topology::NeighbourLists> {
        self.topology.neighbours(self.nodes())
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
            None => {
                let l2 = self.neighbours()?.lambda2().map_err(|e| match e {
                    Error::TooLarge { what, needed, limit } => Error::TooLarge {
                        what: format!(
                            "the adequate consensus_iters (the eigenvalues of {what}; give consensus_iters instead)"
                        ),
                        needed,
                        limit,
                    },
                    e => e,
                })?;
                Ok(topology::iterations_of_lambda2(l2))
            }
        }
    }

    /// The nodes' sensors on the typed network (an error naming the model
    /// network for a scenario that is not [`is_typed`](Self::is_typed)).
    pub fn sensor_models(&self) -> Result<Vec<Sensor>> {
        let m = match (&self.measurement, self.is_typed()) {
            (Some(m), true) => m,
            _ => return Err(self.model_network_error()),
        };
        self.sensors
            .iter()
            .map(|p| {
                Ok(match m {
                    MeasurementSpec::RangePitchAzimuth { sigma_r, sigma_a } => Sensor::Rpa(
                        RangePitchAzimuth::new(*p, *sigma_r, *sigma_a)?
                            .with_fast_trig(self.fast_trig),
                    ),
                    MeasurementSpec::Position { sigma } => Sensor::Pos(Position3::new(*sigma)?),
                })
            })
            .collect()
    }

    /// The error of a typed path given a scenario of the model network.
    pub fn model_network_error(&self) -> Error {
        scenario_err(
            if self.nodes.is_empty() {
                "motion"
            } else {
                "nodes"
            },
            format!(
                "scenario `{}` has {}; this path takes only the paper's kinds (one \
                 `[measurement]` for every node, a 3-D coordinated-turn, constant-velocity or \
                 constant-acceleration motion); run it with `run`/`simulate` (the model \
                 network, `edccif_sim::mixed::model_network`)",
                self.name,
                self.model_network_reason().unwrap_or_default()
            ),
        )
    }

    /// What makes the scenario one of the model network rather than of the
    /// paper's kinds, in words; `None` when it [`is_typed`](Self::is_typed).
    ///
    /// ```
    /// use edccif_sim::{MotionSpec, Scenario};
    /// assert_eq!(Scenario::paper(4).model_network_reason(), None);
    /// let r = Scenario::paper(4).per_node().model_network_reason().unwrap();
    /// assert_eq!(r, "a sensor of its own per node ([[nodes]])");
    /// let mut sc = Scenario::paper(4);
    /// sc.motion = MotionSpec::ConstantVelocity { q: 0.1, dim: 2 };
    /// assert_eq!(sc.model_network_reason().unwrap(), "the motion `constant-velocity` (dim = 2)");
    /// ```
    pub fn model_network_reason(&self) -> Option<String> {
        if self.is_typed() {
            return None;
        }
        if !self.nodes.is_empty() {
            return Some("a sensor of its own per node ([[nodes]])".to_string());
        }
        let dim = match self.motion {
            MotionSpec::ConstantVelocity { dim, .. }
            | MotionSpec::ConstantAcceleration { dim, .. } => format!(" (dim = {dim})"),
            _ => String::new(),
        };
        Some(format!("the motion `{}`{dim}", self.motion.kind()))
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
            MotionSpec::ConstantVelocity { q, .. } => Ok(ConstantVelocity::new(q)?),
            _ => Err(scenario_err("motion", "is not constant-velocity")),
        }
    }

    /// The constant-acceleration model (errors if the scenario uses another motion).
    pub fn constant_acceleration(&self) -> Result<ConstantAcceleration<f64>> {
        match self.motion {
            MotionSpec::ConstantAcceleration { q, .. } => Ok(ConstantAcceleration::new(q)?),
            _ => Err(scenario_err("motion", "is not constant-acceleration")),
        }
    }
}

/// The JSON Schema of scenario files, generated from the types above (the
/// deserialisation contract: what [`Scenario::from_toml_str`] accepts, before
/// [`Scenario::validate`]'s checks across fields). Shipped as
/// `python/edccif/scenario.schema.json` (regenerate with
/// `cargo run -p edccif-sim --bin edccif-scenario-schema -- python/edccif/scenario.schema.json`).
///
/// ```
/// let schema = edccif_sim::scenario::json_schema();
/// assert!(schema.contains("\"title\": \"edccif scenario\""));
/// ```
pub fn json_schema() -> String {
    let schema = schemars::schema_for!(Scenario);
    let mut text = serde_json::to_string_pretty(&schema).expect("a schema serialises");
    text.push('\n');
    text
}
