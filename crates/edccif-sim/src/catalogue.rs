//! The model catalogue of scenario files as Rust models: a scenario's motion
//! ([`MotionSpec`]) and each node's sensor ([`SensorSpec`]) built for the
//! state dimension `N` they fix, for the model network ([`crate::mixed`]) and
//! the simulation ([`mod@crate::simulate`]).
//!
//! A caller says what to do with the models through a visitor: [`with_motion`]
//! picks the const `N` of the motion model and calls [`MotionVisitor::visit`]
//! with it; [`with_sensor`] does the same for a sensor's measurement dimension
//! `M` ([`SensorVisitor`]).
//!
//! ```
//! use edccif_sim::catalogue::{node_sensors, with_motion, MotionVisitor};
//! use edccif_sim::{Result, Scenario};
//! use edccif_core::MotionModel;
//!
//! // The state dimension and node count of a scenario's models.
//! struct Dims<'a>(&'a Scenario);
//! impl MotionVisitor for Dims<'_> {
//!     type Output = (usize, usize);
//!     fn visit<const N: usize, F>(self, _motion: F) -> Result<(usize, usize)>
//!     where
//!         F: MotionModel<f64, N> + Send + Sync + 'static,
//!     {
//!         Ok((N, node_sensors::<N>(self.0)?.len()))
//!     }
//! }
//! let sc = Scenario::paper(4).per_node();
//! assert_eq!(with_motion(&sc, Dims(&sc))?, (7, 4));
//! # Ok::<(), edccif_sim::Error>(())
//! ```

use edccif_core::model::PointImages;
use edccif_core::models::{
    BearingOnly, ConstantAcceleration, ConstantVelocity, CoordinatedTurn, CoordinatedTurn2,
    LinearMeasurement, LinearMotion, Position2, Position3, RandomWalk, RangeBearing, RangeOnly,
    RangePitchAzimuth,
};
use edccif_core::{MeasurementModel, MotionModel};
use nalgebra::{SMatrix, SVector};

use std::any::Any;
use std::sync::OnceLock;

use crate::error::{scenario_err, Result};
use crate::mixed::{NodeSensor, SensorNode};
use crate::scenario::{MotionSpec, Scenario, SensorSpec};

/// What to do with a motion model once its state dimension `N` is fixed.
pub trait MotionVisitor {
    /// The result.
    type Output;
    /// Called with the scenario's motion model.
    fn visit<const N: usize, F>(self, motion: F) -> Result<Self::Output>
    where
        F: MotionModel<f64, N> + Send + Sync + 'static;
}

/// What to do with a sensor once its measurement dimension `M` is fixed.
pub trait SensorVisitor<const N: usize> {
    /// The result.
    type Output;
    /// Called with the node's sensor.
    fn visit<const M: usize, H>(self, sensor: H) -> Result<Self::Output>
    where
        H: MeasurementModel<f64, N, M> + Send + Sync + 'static;
}

/// Runs `$body` with the const `$N` equal to `$n`, one of the listed sizes.
macro_rules! with_const {
    ($n:expr, $what:expr, |$N:ident| $body:expr; $($k:literal)+) => {
        match $n {
            $($k => {
                const $N: usize = $k;
                $body
            })+
            other => Err(scenario_err(
                $what,
                format!("dimension {other} is not supported; expected one of {}", stringify!($($k)+)),
            )),
        }
    };
}

/// A matrix from its rows (checked by [`Scenario::validate`]).
fn matrix<const R: usize, const C: usize>(rows: &[Vec<f64>]) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|i, j| rows[i][j])
}

/// A motion model of state dimension `N` built by a [`PythonModels`].
pub type BoxedMotion<const N: usize> = Box<dyn MotionModel<f64, N> + Send + Sync>;
/// A measurement model of dimensions `N`, `M` built by a [`PythonModels`].
pub type BoxedSensor<const N: usize, const M: usize> =
    Box<dyn MeasurementModel<f64, N, M> + Send + Sync>;

/// Builds the Python models a scenario names by reference (`kind =
/// "python"`, [`MotionSpec::Python`], [`SensorSpec::Python`]). The Python
/// bindings register one when they load ([`set_python_models`]); a Rust-only
/// program has none, and every path that builds such a scenario's models
/// refuses it with an error saying it cannot run a Python model.
pub trait PythonModels: Send + Sync {
    /// The motion model `reference` as a [`BoxedMotion<N>`] with `N = n`,
    /// boxed as `Any`; the error names what was wrong (import, type, size).
    fn motion(&self, sc: &Scenario, reference: &str, n: usize) -> Result<Box<dyn Any + Send>>;
    /// The measurement model `reference` as a [`BoxedSensor<N, M>`] with
    /// `N = n`, `M = m`, boxed as `Any`.
    fn sensor(
        &self,
        sc: &Scenario,
        reference: &str,
        n: usize,
        m: usize,
    ) -> Result<Box<dyn Any + Send>>;
}

static PYTHON_MODELS: OnceLock<Box<dyn PythonModels>> = OnceLock::new();

/// Registers the builder of Python models (once per process; `false` when one
/// was registered already).
pub fn set_python_models(p: Box<dyn PythonModels>) -> bool {
    PYTHON_MODELS.set(p).is_ok()
}

/// The error of a Rust-only run given a scenario with a Python model.
fn no_python(field: &str, reference: &str) -> crate::Error {
    scenario_err(
        field,
        format!(
            "`{reference}` is a Python model; a Rust-only run (the Rust API, `edccif-results`, \
             the benches) cannot run a Python model: run this scenario from the Python package \
             (`edccif simulate --scenario`, `edccif.run`, `edccif.monte_carlo`)"
        ),
    )
}

fn python_motion<const N: usize>(sc: &Scenario, reference: &str) -> Result<DynMotion<N>> {
    let p = PYTHON_MODELS
        .get()
        .ok_or_else(|| no_python("motion.model", reference))?;
    let any = p.motion(sc, reference, N)?;
    any.downcast::<BoxedMotion<N>>()
        .map(|b| DynMotion(*b))
        .map_err(|_| {
            scenario_err(
                "motion.model",
                "the Python model's builder gave another type",
            )
        })
}

fn python_sensor<const N: usize, const M: usize>(
    sc: &Scenario,
    reference: &str,
) -> Result<DynSensor<N, M>> {
    let p = PYTHON_MODELS
        .get()
        .ok_or_else(|| no_python("model", reference))?;
    let any = p.sensor(sc, reference, N, M)?;
    any.downcast::<BoxedSensor<N, M>>()
        .map(|b| DynSensor(*b))
        .map_err(|_| scenario_err("model", "the Python model's builder gave another type"))
}

/// A [`BoxedMotion`] as a motion model (every method forwarded).
pub struct DynMotion<const N: usize>(pub BoxedMotion<N>);

impl<const N: usize> MotionModel<f64, N> for DynMotion<N> {
    fn transition(&self, x: &SVector<f64, N>, dt: f64) -> SVector<f64, N> {
        self.0.transition(x, dt)
    }
    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N> {
        self.0.process_noise(dt)
    }
    fn jacobian(&self, x: &SVector<f64, N>, dt: f64) -> SMatrix<f64, N, N> {
        self.0.jacobian(x, dt)
    }
    fn transition_with_jacobian(
        &self,
        x: &SVector<f64, N>,
        dt: f64,
    ) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
        self.0.transition_with_jacobian(x, dt)
    }
    fn jacobian_congruence(
        &self,
        f: &SMatrix<f64, N, N>,
        p: &SMatrix<f64, N, N>,
    ) -> SMatrix<f64, N, N> {
        self.0.jacobian_congruence(f, p)
    }
    fn transition_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        dt: f64,
        plus: &mut SMatrix<f64, N, N>,
        minus: &mut SMatrix<f64, N, N>,
        centre: Option<&mut SVector<f64, N>>,
    ) {
        self.0
            .transition_points(x, offsets, dt, plus, minus, centre)
    }
}

/// A [`BoxedSensor`] as a measurement model (every method forwarded).
pub struct DynSensor<const N: usize, const M: usize>(pub BoxedSensor<N, M>);

impl<const N: usize, const M: usize> MeasurementModel<f64, N, M> for DynSensor<N, M> {
    fn measure(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        self.0.measure(x)
    }
    fn noise(&self) -> SMatrix<f64, M, M> {
        self.0.noise()
    }
    fn is_angle(&self, k: usize) -> bool {
        self.0.is_angle(k)
    }
    fn fast_trig(&self) -> bool {
        self.0.fast_trig()
    }
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        self.0.jacobian(x)
    }
    fn measure_with_jacobian(&self, x: &SVector<f64, N>) -> (SVector<f64, M>, SMatrix<f64, M, N>) {
        self.0.measure_with_jacobian(x)
    }
    fn jacobian_products(
        &self,
        g: &SMatrix<f64, M, N>,
        p: &SMatrix<f64, N, N>,
    ) -> (SMatrix<f64, N, M>, SMatrix<f64, M, M>) {
        self.0.jacobian_products(g, p)
    }
    fn measure_with_trig(
        &self,
        x: &SVector<f64, N>,
    ) -> (SVector<f64, M>, SVector<f64, M>, SVector<f64, M>) {
        self.0.measure_with_trig(x)
    }
    fn measure_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.0.measure_points(x, offsets, plus, minus, centre)
    }
    fn measure_points_trig(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.0.measure_points_trig(x, offsets, plus, minus, centre)
    }
}

/// Calls `v` with the scenario's motion model at its state dimension.
pub fn with_motion<V: MotionVisitor>(sc: &Scenario, v: V) -> Result<V::Output> {
    let fast = sc.fast_trig;
    match &sc.motion {
        MotionSpec::CoordinatedTurn { q1, q2 } => {
            v.visit::<7, _>(CoordinatedTurn::new(*q1, *q2)?.with_fast_trig(fast))
        }
        MotionSpec::CoordinatedTurn2D { q1, q2 } => {
            v.visit::<5, _>(CoordinatedTurn2::new(*q1, *q2)?.with_fast_trig(fast))
        }
        MotionSpec::ConstantVelocity { q, dim } => {
            let m = ConstantVelocity::new(*q)?;
            match dim {
                1 => v.visit::<2, _>(m),
                2 => v.visit::<4, _>(m),
                3 => v.visit::<6, _>(m),
                d => Err(scenario_err(
                    "motion.dim",
                    format!("expected 1, 2 or 3, got {d}"),
                )),
            }
        }
        MotionSpec::ConstantAcceleration { q, dim } => {
            let m = ConstantAcceleration::new(*q)?;
            match dim {
                1 => v.visit::<3, _>(m),
                2 => v.visit::<6, _>(m),
                3 => v.visit::<9, _>(m),
                d => Err(scenario_err(
                    "motion.dim",
                    format!("expected 1, 2 or 3, got {d}"),
                )),
            }
        }
        MotionSpec::RandomWalk { n, q } => {
            let m = RandomWalk::new(*q)?;
            with_const!(*n, "motion.n", |N| v.visit::<N, _>(m); 1 2 3 4 5 6 7 8 9 10 11 12)
        }
        MotionSpec::Linear { f, q } => {
            with_const!(f.len(), "motion.f", |N| v.visit::<N, _>(LinearMotion::new(
                matrix::<N, N>(f),
                matrix::<N, N>(q)
            )?); 1 2 3 4 5 6 7 8 9 10 11 12)
        }
        MotionSpec::Python { model, n } => {
            with_const!(*n, "motion.n", |N| v.visit::<N, _>(python_motion::<N>(sc, model)?); 1 2 3 4 5 6 7 8 9 10 11 12)
        }
    }
}

/// Calls `v` with node sensor `spec` for state dimension `N` (`fast_trig`:
/// the scenario's opt-in fast trigonometry).
pub fn with_sensor<const N: usize, V: SensorVisitor<N>>(
    sc: &Scenario,
    spec: &SensorSpec,
    v: V,
) -> Result<V::Output> {
    let fast = sc.fast_trig;
    match spec {
        SensorSpec::RangePitchAzimuth {
            position,
            sigma_r,
            sigma_a,
        } => v.visit::<3, _>(
            RangePitchAzimuth::new(*position, *sigma_r, *sigma_a)?.with_fast_trig(fast),
        ),
        SensorSpec::RangeBearing {
            position,
            sigma_r,
            sigma_b,
        } => {
            v.visit::<2, _>(RangeBearing::new(*position, *sigma_r, *sigma_b)?.with_fast_trig(fast))
        }
        SensorSpec::BearingOnly { position, sigma_b } => {
            v.visit::<1, _>(BearingOnly::new(*position, *sigma_b)?.with_fast_trig(fast))
        }
        SensorSpec::RangeOnly { position, sigma_r } => match position.as_slice() {
            [x, y] => v.visit::<1, _>(RangeOnly::new([*x, *y], *sigma_r)?),
            [x, y, z] => v.visit::<1, _>(RangeOnly::new([*x, *y, *z], *sigma_r)?),
            p => Err(scenario_err(
                "position",
                format!("has {} values; expected 2 or 3", p.len()),
            )),
        },
        SensorSpec::Position { sigma } => match sigma.as_slice() {
            [x, y] => v.visit::<2, _>(Position2::new([*x, *y])?),
            [x, y, z] => v.visit::<3, _>(Position3::new([*x, *y, *z])?),
            s => Err(scenario_err(
                "sigma",
                format!("has {} values; expected 2 or 3", s.len()),
            )),
        },
        SensorSpec::Linear { h, r } => {
            with_const!(h.len(), "h", |M| v.visit::<M, _>(LinearMeasurement::<f64, N, M>::new(
                matrix::<M, N>(h),
                matrix::<M, M>(r),
            )?); 1 2 3 4 5 6)
        }
        SensorSpec::Python { model, m } => {
            with_const!(*m, "m", |M| v.visit::<M, _>(python_sensor::<N, M>(sc, model)?); 1 2 3 4 5 6)
        }
    }
}

struct BoxNode;

impl<const N: usize> SensorVisitor<N> for BoxNode {
    type Output = Box<dyn NodeSensor<N>>;
    fn visit<const M: usize, H>(self, sensor: H) -> Result<Self::Output>
    where
        H: MeasurementModel<f64, N, M> + Send + Sync + 'static,
    {
        Ok(Box::new(SensorNode::<H, M>::new(sensor)))
    }
}

/// Every node's sensor of `sc` for the model network, for state dimension `N`.
pub fn node_sensors<const N: usize>(sc: &Scenario) -> Result<Vec<Box<dyn NodeSensor<N>>>> {
    sc.node_specs()
        .iter()
        .enumerate()
        .map(|(i, n)| with_sensor::<N, _>(sc, &n.sensor, BoxNode).map_err(|e| at_node(e, i)))
        .collect()
}

/// Builds every model of `sc` once, and drops them: the errors of a
/// scenario's models (a Python model's import, type or dimensions; the
/// refusal of a Rust-only run) before a run.
///
/// ```
/// use edccif_sim::{catalogue::check_models, MotionSpec, Scenario};
/// assert!(check_models(&Scenario::paper(4).per_node()).is_ok());
/// let mut sc = Scenario::paper(4);
/// sc.motion = MotionSpec::Python { model: "turn_models:turn_motion".into(), n: 7 };
/// let e = check_models(&sc).unwrap_err().to_string();
/// assert!(e.contains("cannot run a Python model"), "{e}");
/// ```
pub fn check_models(sc: &Scenario) -> Result<()> {
    struct Check<'a>(&'a Scenario);
    impl MotionVisitor for Check<'_> {
        type Output = ();
        fn visit<const N: usize, F>(self, _motion: F) -> Result<()>
        where
            F: MotionModel<f64, N> + Send + Sync + 'static,
        {
            node_sensors::<N>(self.0).map(drop)
        }
    }
    with_motion(sc, Check(sc))
}

/// A sensor's error with the node it belongs to.
pub(crate) fn at_node(e: crate::Error, i: usize) -> crate::Error {
    match e {
        crate::Error::Scenario { field, problem } if field != "kind" => crate::Error::Scenario {
            field: format!("nodes[{i}].sensor.{field}"),
            problem,
        },
        other => other,
    }
}

/// Runs row `alg` on a scenario of the model network with its catalogue
/// models ([`crate::mixed::model_network`]): what [`crate::run`] and
/// [`crate::run_with_dt`] do for a scenario that is not
/// [`is_typed`](Scenario::is_typed). `z`: row-major `(T, Σ m_i)` as
/// [`crate::simulate()`] gives it (NaN where a node does not measure); `dts`:
/// each step's time step (`None`: the scenario's `dt`).
///
/// ```
/// use edccif_sim::{run, simulate, Algorithm, RunOptions, Scenario};
/// // The paper's scenario in the per-node form runs on the model network and
/// // gives the typed network's numbers.
/// let sc = Scenario { steps: 20, ..Scenario::paper(4) };
/// let sim = simulate(&sc, 1)?;
/// let typed = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), false)?;
/// let models = run(Algorithm::EdcCif, &sc.per_node(), &sim.z, &sim.x0_hat, &RunOptions::default(), false)?;
/// assert_eq!(models.estimates, typed.estimates);
/// # Ok::<(), edccif_sim::Error>(())
/// ```
pub fn run_models(
    alg: crate::Algorithm,
    sc: &Scenario,
    z: &[f64],
    x0: &[f64],
    opt: &crate::RunOptions,
    dts: Option<&[f64]>,
    record_covariances: bool,
) -> Result<crate::RunResult> {
    struct Run<'a> {
        alg: crate::Algorithm,
        sc: &'a Scenario,
        z: &'a [f64],
        x0: &'a [f64],
        opt: &'a crate::RunOptions,
        dts: Option<&'a [f64]>,
        record_covariances: bool,
    }
    impl MotionVisitor for Run<'_> {
        type Output = crate::RunResult;
        fn visit<const N: usize, F>(self, motion: F) -> Result<crate::RunResult>
        where
            F: MotionModel<f64, N> + Send + Sync + 'static,
        {
            let sensors = node_sensors::<N>(self.sc)?;
            let mut net = crate::mixed::model_network::<N>(
                self.alg,
                self.sc,
                self.x0,
                self.opt,
                Box::new(motion),
                sensors,
            )?;
            let total: usize = self.sc.meas_dims().iter().sum();
            let own;
            let dts = match self.dts {
                Some(d) => d,
                None => {
                    own = vec![self.sc.dt; self.z.len() / total.max(1)];
                    &own
                }
            };
            net.run(self.z, dts, self.record_covariances)
        }
    }
    with_motion(
        sc,
        Run {
            alg,
            sc,
            z,
            x0,
            opt,
            dts,
            record_covariances,
        },
    )
}
