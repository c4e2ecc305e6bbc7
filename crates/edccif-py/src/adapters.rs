//! Typed adapters between the Python model objects ([`crate::models`]) and the
//! core's const-generic model traits: [`MotionAdapter<N>`] and
//! [`SensorAdapter<N, M>`] implement [`MotionModel`] and [`MeasurementModel`] for
//! every catalogue kind and for models backed by Python callables.
//!
//! A custom model's callable receives all the points of a call at once, as an
//! array `(k, n)` with one point per row, and must return `(k, n)` (motion) or
//! `(k, m)` (measurement) finite values. When it raises, returns the wrong shape or
//! non-finite values, the adapter records the named error (the Python exception
//! chained as its `__cause__`) and returns NaN, so the core's finiteness checks
//! fail the step and nothing is committed; the binding then raises the recorded
//! error instead of the core's ([`Failure::take`]).

use std::any::Any;
use std::sync::{Arc, Mutex};

use edccif_core::model::PointImages;
use edccif_core::models::{
    BearingOnly, ConstantAcceleration, ConstantVelocity, CoordinatedTurn, CoordinatedTurn2,
    LinearMotion, Position2, Position3, RandomWalk, RangeBearing, RangeOnly, RangePitchAzimuth,
};
use edccif_core::{MeasurementModel, MotionModel};
use nalgebra::{SMatrix, SVector};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

use crate::convert::{f64_array, Dim};
use crate::errors::{ModelError, NonFiniteError};

/// The first error a Python callable caused during a step (shared by the
/// adapter's trait methods, which cannot return errors themselves).
#[derive(Debug, Default)]
pub struct Failure(Mutex<Option<PyErr>>);

impl Failure {
    /// Records `e` unless an earlier error is already recorded.
    pub fn set(&self, e: PyErr) {
        let mut g = self.0.lock().unwrap_or_else(|p| p.into_inner());
        if g.is_none() {
            *g = Some(e);
        }
    }
    /// Whether an error is recorded.
    pub fn is_set(&self) -> bool {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).is_some()
    }
    /// Takes the recorded error, leaving none.
    pub fn take(&self) -> Option<PyErr> {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).take()
    }
}

/// A noise covariance given as a fixed matrix (row-major) or as a Python
/// callable of `dt` returning one.
#[derive(Debug)]
pub enum NoiseSpec {
    /// Fixed `(d, d)` matrix, row-major.
    Matrix(Vec<f64>),
    /// `Q(dt) -> (d, d)`.
    Callable(Py<PyAny>),
}

/// A motion model from Python callables: `f(X, dt)` on `(k, n)` points, `Q`, and
/// an optional Jacobian `F(x, dt) -> (n, n)`.
#[derive(Debug)]
pub struct CustomMotionSpec {
    /// `f(X, dt) -> (k, n)`.
    pub f: Py<PyAny>,
    /// `Q` or `Q(dt)`.
    pub q: NoiseSpec,
    /// State dimension.
    pub n: usize,
    /// `F(x, dt) -> (n, n)`; `None`: central finite differences of `f`.
    pub jacobian: Option<Py<PyAny>>,
}

/// A measurement model from Python callables: `h(X)` on `(k, n)` points, a fixed
/// `R`, angle components and an optional Jacobian `H(x) -> (m, n)`.
#[derive(Debug)]
pub struct CustomSensorSpec {
    /// `h(X) -> (k, m)`.
    pub h: Py<PyAny>,
    /// `R`, `(m, m)` row-major (validated symmetric positive definite).
    pub r: Vec<f64>,
    /// Measurement dimension.
    pub m: usize,
    /// State dimension.
    pub n: usize,
    /// Which components are angles (wrapped to `[−π, π)`, averaged circularly).
    pub angles: Vec<bool>,
    /// `H(x) -> (m, n)`; `None`: central finite differences of `h`.
    pub jacobian: Option<Py<PyAny>>,
}

/// A motion model of the catalogue or from Python, at run time (any `n`).
#[derive(Debug, Clone)]
pub enum MotionSpec {
    /// 3-D coordinated turn, `n = 7`.
    CoordinatedTurn(CoordinatedTurn<f64>),
    /// Planar coordinated turn `[x, y, vx, vy, ω]`, `n = 5`.
    CoordinatedTurn2D(CoordinatedTurn2<f64>),
    /// Constant velocity in `dim` dimensions, `n = 2·dim`.
    ConstantVelocity {
        /// Spatial dimension.
        dim: usize,
        /// The core model.
        model: ConstantVelocity<f64>,
    },
    /// Constant acceleration in `dim` dimensions, `n = 3·dim`.
    ConstantAcceleration {
        /// Spatial dimension.
        dim: usize,
        /// The core model.
        model: ConstantAcceleration<f64>,
    },
    /// Random walk of any dimension.
    RandomWalk {
        /// State dimension.
        n: usize,
        /// The core model.
        model: RandomWalk<f64>,
    },
    /// `x' = F x + w`, row-major `F`, `Q`.
    Linear {
        /// State dimension.
        n: usize,
        /// `F`, row-major.
        f: Vec<f64>,
        /// `Q`, row-major.
        q: Vec<f64>,
    },
    /// Python callables.
    Custom(Arc<CustomMotionSpec>),
}

impl MotionSpec {
    /// The state dimension.
    pub fn n(&self) -> usize {
        match self {
            MotionSpec::CoordinatedTurn(_) => 7,
            MotionSpec::CoordinatedTurn2D(_) => 5,
            MotionSpec::ConstantVelocity { dim, .. } => 2 * dim,
            MotionSpec::ConstantAcceleration { dim, .. } => 3 * dim,
            MotionSpec::RandomWalk { n, .. } | MotionSpec::Linear { n, .. } => *n,
            MotionSpec::Custom(c) => c.n,
        }
    }
}

/// A sensor model of the catalogue or from Python, at run time.
#[derive(Debug, Clone)]
pub enum SensorSpec {
    /// Range, pitch, azimuth from a fixed point (`m = 3`, position first).
    RangePitchAzimuth(RangePitchAzimuth<f64>),
    /// 3-D position (`m = 3`).
    Position3(Position3<f64>),
    /// 2-D position (`m = 2`).
    Position2(Position2<f64>),
    /// Range and bearing in the plane (`m = 2`, component 1 an angle).
    RangeBearing(RangeBearing<f64>),
    /// Bearing in the plane (`m = 1`, an angle).
    BearingOnly(BearingOnly<f64>),
    /// Range from a point in the plane (`m = 1`).
    RangeOnly2(RangeOnly<f64, 2>),
    /// Range from a point in space (`m = 1`).
    RangeOnly3(RangeOnly<f64, 3>),
    /// `z = H x + v`, row-major `H` `(m, n)` and `R`.
    Linear {
        /// Measurement dimension.
        m: usize,
        /// State dimension.
        n: usize,
        /// `H`, row-major.
        h: Vec<f64>,
        /// `R`, row-major.
        r: Vec<f64>,
    },
    /// Python callables.
    Custom(Arc<CustomSensorSpec>),
}

impl SensorSpec {
    /// The measurement dimension.
    pub fn m(&self) -> usize {
        match self {
            SensorSpec::RangePitchAzimuth(_) | SensorSpec::Position3(_) => 3,
            SensorSpec::Position2(_) | SensorSpec::RangeBearing(_) => 2,
            SensorSpec::BearingOnly(_) | SensorSpec::RangeOnly2(_) | SensorSpec::RangeOnly3(_) => 1,
            SensorSpec::Linear { m, .. } => *m,
            SensorSpec::Custom(c) => c.m,
        }
    }
    /// The state dimension when the model fixes it (`None`: any state whose first
    /// components are the position, see [`min_n`](Self::min_n)).
    pub fn n(&self) -> Option<usize> {
        match self {
            SensorSpec::Linear { n, .. } => Some(*n),
            SensorSpec::Custom(c) => Some(c.n),
            _ => None,
        }
    }
    /// The smallest state dimension the model can measure.
    pub fn min_n(&self) -> usize {
        match self {
            SensorSpec::RangePitchAzimuth(_)
            | SensorSpec::Position3(_)
            | SensorSpec::RangeOnly3(_) => 3,
            SensorSpec::Position2(_)
            | SensorSpec::RangeBearing(_)
            | SensorSpec::BearingOnly(_)
            | SensorSpec::RangeOnly2(_) => 2,
            SensorSpec::Linear { n, .. } => *n,
            SensorSpec::Custom(c) => c.n,
        }
    }
    /// Checks that the sensor measures states of dimension `n`.
    pub fn check_state_dim(&self, n: usize, what: &str) -> PyResult<()> {
        let ok = match self.n() {
            Some(k) => k == n,
            None => n >= self.min_n(),
        };
        if ok {
            Ok(())
        } else {
            let expected = match self.n() {
                Some(k) => format!("n = {k}"),
                None => format!("n >= {} (position first)", self.min_n()),
            };
            Err(crate::errors::ShapeError::new_err(format!(
                "{what}: the sensor measures states of {expected}, got state dimension {n}"
            )))
        }
    }
}

/// `a` as a `&B` when `A` and `B` are one type under two names: a catalogue
/// model's own dimension (`SVector<f64, 7>`) and the adapter's
/// (`SVector<f64, N>`), equal by construction ([`MotionAdapter::new`],
/// [`SensorAdapter::new`] check it). A borrow, not a copy; the type check is
/// resolved when the code is compiled.
#[inline(always)]
fn as_same<A: Any, B: Any>(a: &A) -> &B {
    match (a as &dyn Any).downcast_ref::<B>() {
        Some(b) => b,
        None => dims_differ(),
    }
}

/// [`as_same`] for a mutable borrow (the outputs of the batch hooks).
#[inline(always)]
fn as_same_mut<A: Any, B: Any>(a: &mut A) -> &mut B {
    match (a as &mut dyn Any).downcast_mut::<B>() {
        Some(b) => b,
        None => dims_differ(),
    }
}

/// [`as_same`] for a value (a catalogue model's result), moved, not copied
/// element by element.
#[inline(always)]
fn into_same<A: Any, B: Any>(a: A) -> B {
    let mut a = Some(a);
    match (&mut a as &mut dyn Any).downcast_mut::<Option<B>>() {
        Some(b) => match b.take() {
            Some(v) => v,
            None => dims_differ(),
        },
        None => dims_differ(),
    }
}

/// The adapters' constructors reject a model whose dimensions differ from the
/// adapter's, so this is never reached.
#[cold]
#[inline(never)]
fn dims_differ() -> ! {
    unreachable!("the adapter's dimensions are checked when it is built")
}

fn dim_mismatch(what: &str, expected: usize, got: usize) -> PyErr {
    crate::errors::ShapeError::new_err(format!(
        "{what}: the model has dimension {expected}, the filter {got}"
    ))
}

/// Calls a Python callable with `args` and converts its result to a finite
/// float array of shape `(rows, cols)` (row-major). Errors are named and chain
/// the Python exception when the callable raised.
fn call_checked<'py>(
    py: Python<'py>,
    callable: &Py<PyAny>,
    args: impl pyo3::call::PyCallArgs<'py>,
    what: &str,
    rows: usize,
    cols: usize,
) -> PyResult<Vec<f64>> {
    let out = match callable.bind(py).call1(args) {
        Ok(o) => o,
        Err(e) => {
            // KeyboardInterrupt, SystemExit: not a model error, propagate as is.
            if !e.is_instance_of::<PyException>(py) {
                return Err(e);
            }
            let shown = e
                .value(py)
                .repr()
                .map_or_else(|_| "an exception".to_string(), |r| r.to_string());
            let err = ModelError::new_err(format!(
                "{what} raised {shown} (chained as __cause__); the filter state is unchanged"
            ));
            err.set_cause(py, Some(e));
            return Err(err);
        }
    };
    let (v, _) = f64_array(
        &out,
        &format!("{what} result"),
        &[Dim::Is(rows), Dim::Is(cols)],
    )?;
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(NonFiniteError::new_err(format!(
            "{what} returned a non-finite value ({}) at row {}, column {}; expected finite values",
            v[i],
            i / cols,
            i % cols
        )));
    }
    Ok(v)
}

/// A `(k, n)` float64 array of points, one per row.
fn points_array<'py, const N: usize>(
    py: Python<'py>,
    pts: &[SVector<f64, N>],
) -> PyResult<Bound<'py, PyAny>> {
    let mut flat = Vec::with_capacity(pts.len() * N);
    for p in pts {
        flat.extend_from_slice(p.as_slice());
    }
    Ok(PyArray1::from_vec(py, flat)
        .reshape([pts.len(), N])?
        .into_any())
}

#[derive(Debug, Clone)]
enum MotionKind<const N: usize> {
    Ct(CoordinatedTurn<f64>),
    Ct2(CoordinatedTurn2<f64>),
    Cv(ConstantVelocity<f64>),
    Ca(ConstantAcceleration<f64>),
    Rw(RandomWalk<f64>),
    Linear(LinearMotion<f64, N>),
    Custom(Arc<CustomMotionSpec>),
}

/// Dispatches a `MotionModel` method over the catalogue kinds: the fixed-size
/// models (7, 5) through a copy to and from their own dimension, the others
/// directly (they are defined for every `N`).
macro_rules! motion_call {
    ($kind:expr, |$m:ident, $D:ident| $fixed:expr, |$g:ident| $generic:expr, |$c:ident| $custom:expr) => {
        match $kind {
            MotionKind::Ct($m) => {
                const $D: usize = 7;
                $fixed
            }
            MotionKind::Ct2($m) => {
                const $D: usize = 5;
                $fixed
            }
            MotionKind::Cv($g) => $generic,
            MotionKind::Ca($g) => $generic,
            MotionKind::Rw($g) => $generic,
            MotionKind::Linear($g) => $generic,
            MotionKind::Custom($c) => $custom,
        }
    };
}

/// A motion model of state dimension `N` (catalogue or Python callables).
#[derive(Debug)]
pub struct MotionAdapter<const N: usize> {
    kind: MotionKind<N>,
    /// The first error a callable caused since the last [`Failure::take`].
    pub failure: Failure,
}

impl<const N: usize> MotionAdapter<N> {
    /// The adapter of `spec`; `spec.n()` must be `N`.
    pub fn new(spec: &MotionSpec) -> PyResult<Self> {
        if spec.n() != N {
            return Err(dim_mismatch("motion model", spec.n(), N));
        }
        let kind = match spec {
            MotionSpec::CoordinatedTurn(m) => MotionKind::Ct(*m),
            MotionSpec::CoordinatedTurn2D(m) => MotionKind::Ct2(*m),
            MotionSpec::ConstantVelocity { model, .. } => MotionKind::Cv(*model),
            MotionSpec::ConstantAcceleration { model, .. } => MotionKind::Ca(*model),
            MotionSpec::RandomWalk { model, .. } => MotionKind::Rw(*model),
            MotionSpec::Linear { f, q, .. } => MotionKind::Linear(
                LinearMotion::new(SMatrix::from_row_slice(f), SMatrix::from_row_slice(q))
                    .map_err(|e| crate::errors::core_err(&e))?,
            ),
            MotionSpec::Custom(c) => MotionKind::Custom(Arc::clone(c)),
        };
        Ok(Self {
            kind,
            failure: Failure::default(),
        })
    }

    /// `f` at every point, with one call for a Python model (NaN and a recorded
    /// error when the callable fails).
    pub fn transition_many(&self, pts: &[SVector<f64, N>], dt: f64) -> Vec<SVector<f64, N>> {
        match &self.kind {
            MotionKind::Custom(c) => {
                let nan = || vec![SVector::repeat(f64::NAN); pts.len()];
                if self.failure.is_set() {
                    return nan();
                }
                let r = Python::with_gil(|py| -> PyResult<Vec<f64>> {
                    let x = points_array(py, pts)?;
                    call_checked(py, &c.f, (x, dt), "CustomMotion f(X, dt)", pts.len(), N)
                });
                match r {
                    Ok(v) => v.chunks_exact(N).map(SVector::from_column_slice).collect(),
                    Err(e) => {
                        self.failure.set(e);
                        nan()
                    }
                }
            }
            _ => pts.iter().map(|x| self.transition(x, dt)).collect(),
        }
    }

    fn matrix_callable(
        &self,
        g: &Py<PyAny>,
        what: &str,
        x: Option<&SVector<f64, N>>,
        dt: f64,
    ) -> SMatrix<f64, N, N> {
        if self.failure.is_set() {
            return SMatrix::repeat(f64::NAN);
        }
        let r = Python::with_gil(|py| match x {
            Some(x) => {
                let xa = PyArray1::from_slice(py, x.as_slice());
                call_checked(py, g, (xa, dt), what, N, N)
            }
            None => call_checked(py, g, (dt,), what, N, N),
        });
        match r {
            Ok(v) => SMatrix::from_row_slice(&v),
            Err(e) => {
                self.failure.set(e);
                SMatrix::repeat(f64::NAN)
            }
        }
    }
}

impl<const N: usize> MotionModel<f64, N> for MotionAdapter<N> {
    fn transition(&self, x: &SVector<f64, N>, dt: f64) -> SVector<f64, N> {
        motion_call!(
            &self.kind,
            |m, D| into_same(MotionModel::<f64, D>::transition(m, as_same(x), dt)),
            |m| m.transition(x, dt),
            |_c| self.transition_many(core::slice::from_ref(x), dt)[0]
        )
    }

    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N> {
        motion_call!(
            &self.kind,
            |m, D| into_same(MotionModel::<f64, D>::process_noise(m, dt)),
            |m| m.process_noise(dt),
            |c| match &c.q {
                NoiseSpec::Matrix(q) => SMatrix::from_row_slice(q),
                NoiseSpec::Callable(g) => self.matrix_callable(g, "CustomMotion Q(dt)", None, dt),
            }
        )
    }

    fn jacobian(&self, x: &SVector<f64, N>, dt: f64) -> SMatrix<f64, N, N> {
        motion_call!(
            &self.kind,
            |m, D| into_same(MotionModel::<f64, D>::jacobian(m, as_same(x), dt)),
            |m| m.jacobian(x, dt),
            |c| match &c.jacobian {
                None => edccif_core::model::finite_difference_jacobian(
                    |v| self.transition(v, dt),
                    x,
                    |_| false,
                ),
                Some(g) => self.matrix_callable(g, "CustomMotion jacobian(x, dt)", Some(x), dt),
            }
        )
    }

    /// The catalogue model's own hook (the turn models share one `sin_cos`);
    /// a Python model's `f` and Jacobian.
    fn transition_with_jacobian(
        &self,
        x: &SVector<f64, N>,
        dt: f64,
    ) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
        motion_call!(
            &self.kind,
            |m, D| {
                let (y, f) = MotionModel::<f64, D>::transition_with_jacobian(m, as_same(x), dt);
                (into_same(y), into_same(f))
            },
            |m| m.transition_with_jacobian(x, dt),
            |_c| (self.transition(x, dt), self.jacobian(x, dt))
        )
    }

    /// The catalogue model's own hook (the turn models skip the Jacobian's
    /// structural zeros, with the same bits); the general products otherwise.
    fn jacobian_congruence(
        &self,
        f: &SMatrix<f64, N, N>,
        p: &SMatrix<f64, N, N>,
    ) -> SMatrix<f64, N, N> {
        motion_call!(
            &self.kind,
            |m, D| into_same(MotionModel::<f64, D>::jacobian_congruence(
                m,
                as_same(f),
                as_same(p)
            )),
            |m| m.jacobian_congruence(f, p),
            |_c| f * p * f.transpose()
        )
    }

    /// A Python model evaluates all `2N (+1)` points in one call (rows: the `+`
    /// points, the `−` points, then the centre); a catalogue model takes its
    /// own batch hook (a turn model with the opt-in fast trigonometry shares one
    /// `sin_cos` across the points; the others evaluate point by point).
    fn transition_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        dt: f64,
        plus: &mut SMatrix<f64, N, N>,
        minus: &mut SMatrix<f64, N, N>,
        centre: Option<&mut SVector<f64, N>>,
    ) {
        motion_call!(
            &self.kind,
            |m, D| MotionModel::<f64, D>::transition_points(
                m,
                as_same(x),
                as_same(offsets),
                dt,
                as_same_mut(plus),
                as_same_mut(minus),
                centre.map(as_same_mut),
            ),
            |m| m.transition_points(x, offsets, dt, plus, minus, centre),
            |_c| {
                let pts = sigma_rows(x, offsets, centre.is_some());
                let out = self.transition_many(&pts, dt);
                for j in 0..N {
                    plus.set_column(j, &out[j]);
                    minus.set_column(j, &out[N + j]);
                }
                if let Some(c0) = centre {
                    *c0 = out[2 * N];
                }
            }
        )
    }
}

/// The points `x + offsets[:, j]` (j < N), `x − offsets[:, j]`, and `x` when
/// `centre`: the rows a Python model receives.
fn sigma_rows<const N: usize>(
    x: &SVector<f64, N>,
    offsets: &SMatrix<f64, N, N>,
    centre: bool,
) -> Vec<SVector<f64, N>> {
    let mut pts = Vec::with_capacity(2 * N + 1);
    pts.extend((0..N).map(|j| x + offsets.column(j)));
    pts.extend((0..N).map(|j| x - offsets.column(j)));
    if centre {
        pts.push(*x);
    }
    pts
}

#[derive(Debug, Clone)]
enum SensorKind<const N: usize, const M: usize> {
    Rpa(RangePitchAzimuth<f64>),
    Pos3(Position3<f64>),
    Pos2(Position2<f64>),
    Rb(RangeBearing<f64>),
    Bo(BearingOnly<f64>),
    Ro2(RangeOnly<f64, 2>),
    Ro3(RangeOnly<f64, 3>),
    Linear(edccif_core::models::LinearMeasurement<f64, N, M>),
    Custom(Arc<CustomSensorSpec>),
}

/// Dispatches a `MeasurementModel` method over the catalogue sensors, each with
/// its own measurement dimension `K` (the results are copied to `M = K`).
macro_rules! sensor_call {
    ($kind:expr, |$s:ident, $K:ident| $fixed:expr, |$l:ident| $linear:expr, |$c:ident| $custom:expr) => {
        match $kind {
            SensorKind::Rpa($s) => {
                const $K: usize = 3;
                $fixed
            }
            SensorKind::Pos3($s) => {
                const $K: usize = 3;
                $fixed
            }
            SensorKind::Pos2($s) => {
                const $K: usize = 2;
                $fixed
            }
            SensorKind::Rb($s) => {
                const $K: usize = 2;
                $fixed
            }
            SensorKind::Bo($s) => {
                const $K: usize = 1;
                $fixed
            }
            SensorKind::Ro2($s) => {
                const $K: usize = 1;
                $fixed
            }
            SensorKind::Ro3($s) => {
                const $K: usize = 1;
                $fixed
            }
            SensorKind::Linear($l) => $linear,
            SensorKind::Custom($c) => $custom,
        }
    };
}

/// A measurement model of state dimension `N`, measurement dimension `M`
/// (catalogue or Python callables), with an optional one-call override of `R`.
#[derive(Debug)]
pub struct SensorAdapter<const N: usize, const M: usize> {
    kind: SensorKind<N, M>,
    r_custom: SMatrix<f64, M, M>,
    /// When set, [`noise`](MeasurementModel::noise) returns it instead of the
    /// model's `R` (a filter's `update(z, R=...)`).
    pub r_override: Option<SMatrix<f64, M, M>>,
    /// The first error a callable caused since the last [`Failure::take`].
    pub failure: Failure,
}

impl<const N: usize, const M: usize> SensorAdapter<N, M> {
    /// The adapter of `spec` for states of dimension `N`; `spec.m()` must be `M`.
    pub fn new(spec: &SensorSpec) -> PyResult<Self> {
        if spec.m() != M {
            return Err(dim_mismatch("measurement model", spec.m(), M));
        }
        spec.check_state_dim(N, "measurement model")?;
        let mut r_custom = SMatrix::zeros();
        let kind = match spec {
            SensorSpec::RangePitchAzimuth(s) => SensorKind::Rpa(*s),
            SensorSpec::Position3(s) => SensorKind::Pos3(*s),
            SensorSpec::Position2(s) => SensorKind::Pos2(*s),
            SensorSpec::RangeBearing(s) => SensorKind::Rb(*s),
            SensorSpec::BearingOnly(s) => SensorKind::Bo(*s),
            SensorSpec::RangeOnly2(s) => SensorKind::Ro2(*s),
            SensorSpec::RangeOnly3(s) => SensorKind::Ro3(*s),
            SensorSpec::Linear { h, r, .. } => SensorKind::Linear(
                edccif_core::models::LinearMeasurement::new(
                    SMatrix::from_row_slice(h),
                    SMatrix::from_row_slice(r),
                )
                .map_err(|e| crate::errors::core_err(&e))?,
            ),
            SensorSpec::Custom(c) => {
                r_custom = SMatrix::from_row_slice(&c.r);
                SensorKind::Custom(Arc::clone(c))
            }
        };
        Ok(Self {
            kind,
            r_custom,
            r_override: None,
            failure: Failure::default(),
        })
    }

    /// `h` at every point, with one call for a Python model (NaN and a recorded
    /// error when the callable fails).
    pub fn measure_many(&self, pts: &[SVector<f64, N>]) -> Vec<SVector<f64, M>> {
        match &self.kind {
            SensorKind::Custom(c) => {
                let nan = || vec![SVector::repeat(f64::NAN); pts.len()];
                if self.failure.is_set() {
                    return nan();
                }
                let r = Python::with_gil(|py| -> PyResult<Vec<f64>> {
                    let x = points_array(py, pts)?;
                    call_checked(py, &c.h, (x,), "CustomMeasurement h(X)", pts.len(), M)
                });
                match r {
                    Ok(v) => v.chunks_exact(M).map(SVector::from_column_slice).collect(),
                    Err(e) => {
                        self.failure.set(e);
                        nan()
                    }
                }
            }
            _ => pts.iter().map(|x| self.measure(x)).collect(),
        }
    }

    /// `(z, cos, sin)` of a Python model's measurement (trigonometry of its angle
    /// components).
    fn with_trig(&self, z: SVector<f64, M>) -> (SVector<f64, M>, SVector<f64, M>, SVector<f64, M>) {
        let mut co = SVector::<f64, M>::zeros();
        let mut si = SVector::<f64, M>::zeros();
        for k in 0..M {
            if self.is_angle(k) {
                let (s, c) = z[k].sin_cos();
                si[k] = s;
                co[k] = c;
            }
        }
        (z, co, si)
    }
}

impl<const N: usize, const M: usize> MeasurementModel<f64, N, M> for SensorAdapter<N, M> {
    fn measure(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        sensor_call!(
            &self.kind,
            |s, K| into_same(MeasurementModel::<f64, N, K>::measure(s, x)),
            |s| s.measure(x),
            |_c| self.measure_many(core::slice::from_ref(x))[0]
        )
    }

    fn noise(&self) -> SMatrix<f64, M, M> {
        if let Some(r) = self.r_override {
            return r;
        }
        sensor_call!(
            &self.kind,
            |s, K| into_same(MeasurementModel::<f64, N, K>::noise(s)),
            |s| s.noise(),
            |_c| self.r_custom
        )
    }

    /// The catalogue sensor's opt-in fast trigonometry (a Python model has none).
    fn fast_trig(&self) -> bool {
        sensor_call!(
            &self.kind,
            |s, K| MeasurementModel::<f64, N, K>::fast_trig(s),
            |s| s.fast_trig(),
            |_c| false
        )
    }

    fn is_angle(&self, k: usize) -> bool {
        sensor_call!(
            &self.kind,
            |s, K| MeasurementModel::<f64, N, K>::is_angle(s, k),
            |s| s.is_angle(k),
            |c| c.angles.get(k).copied().unwrap_or(false)
        )
    }

    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        sensor_call!(
            &self.kind,
            |s, K| into_same(MeasurementModel::<f64, N, K>::jacobian(s, x)),
            |s| s.jacobian(x),
            |c| match &c.jacobian {
                None => edccif_core::model::finite_difference_jacobian(
                    |v| self.measure(v),
                    x,
                    |k| self.is_angle(k),
                ),
                Some(g) => {
                    if self.failure.is_set() {
                        return SMatrix::repeat(f64::NAN);
                    }
                    let r = Python::with_gil(|py| {
                        let xa = PyArray1::from_slice(py, x.as_slice());
                        call_checked(py, g, (xa,), "CustomMeasurement jacobian(x)", M, N)
                    });
                    match r {
                        Ok(v) => SMatrix::from_row_slice(&v),
                        Err(e) => {
                            self.failure.set(e);
                            SMatrix::repeat(f64::NAN)
                        }
                    }
                }
            }
        )
    }

    /// The catalogue sensor's own hook (`h` and `G` share the offset and its
    /// norms, with the same bits); a Python model's `h` and Jacobian.
    fn measure_with_jacobian(&self, x: &SVector<f64, N>) -> (SVector<f64, M>, SMatrix<f64, M, N>) {
        sensor_call!(
            &self.kind,
            |s, K| {
                let (z, g) = MeasurementModel::<f64, N, K>::measure_with_jacobian(s, x);
                (into_same(z), into_same(g))
            },
            |s| s.measure_with_jacobian(x),
            |_c| (self.measure(x), self.jacobian(x))
        )
    }

    /// The catalogue sensor's own hook (only the position columns of `G`, with
    /// the same bits); the general products otherwise.
    fn jacobian_products(
        &self,
        g: &SMatrix<f64, M, N>,
        p: &SMatrix<f64, N, N>,
    ) -> (SMatrix<f64, N, M>, SMatrix<f64, M, M>) {
        sensor_call!(
            &self.kind,
            |s, K| {
                let (pg, gpg) = MeasurementModel::<f64, N, K>::jacobian_products(s, as_same(g), p);
                (into_same(pg), into_same(gpg))
            },
            |s| s.jacobian_products(g, p),
            |_c| {
                let pg = p * g.transpose();
                (pg, g * pg)
            }
        )
    }

    fn measure_with_trig(
        &self,
        x: &SVector<f64, N>,
    ) -> (SVector<f64, M>, SVector<f64, M>, SVector<f64, M>) {
        sensor_call!(
            &self.kind,
            |s, K| {
                let (z, c, si) = MeasurementModel::<f64, N, K>::measure_with_trig(s, x);
                (into_same(z), into_same(c), into_same(si))
            },
            |s| s.measure_with_trig(x),
            |_c| self.with_trig(self.measure(x))
        )
    }

    /// A Python model evaluates all `2N (+1)` points in one call (rows: the `+`
    /// points, the `−` points, then the centre); a catalogue sensor takes its
    /// own batch hook.
    fn measure_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        sensor_call!(
            &self.kind,
            |s, K| MeasurementModel::<f64, N, K>::measure_points(
                s,
                x,
                offsets,
                as_same_mut(plus),
                as_same_mut(minus),
                centre.map(as_same_mut),
            ),
            |s| s.measure_points(x, offsets, plus, minus, centre),
            |_c| {
                let pts = sigma_rows(x, offsets, centre.is_some());
                let out = self.measure_many(&pts);
                for j in 0..N {
                    plus.set(j, self.with_trig(out[j]));
                    minus.set(j, self.with_trig(out[N + j]));
                }
                if let Some(c0) = centre {
                    c0.set(0, self.with_trig(out[2 * N]));
                }
            }
        )
    }

    /// The catalogue sensor's own hook (no `atan2` for the angles the
    /// mean-only transform does not read); [`measure_points`](Self::measure_points)
    /// for a Python model.
    fn measure_points_trig(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        sensor_call!(
            &self.kind,
            |s, K| MeasurementModel::<f64, N, K>::measure_points_trig(
                s,
                x,
                offsets,
                as_same_mut(plus),
                as_same_mut(minus),
                centre.map(as_same_mut),
            ),
            |s| s.measure_points_trig(x, offsets, plus, minus, centre),
            |_c| self.measure_points(x, offsets, plus, minus, centre)
        )
    }
}

/// A shared handle on an adapter, the one way the networks and the scenario
/// runs hold a Python-side model: it forwards every method of
/// [`MotionModel`] and [`MeasurementModel`] to the adapter (so the model's
/// `fast_trig`, point transforms and Jacobian products reach the filter as
/// they do for the catalogue model itself), and runs its hook after every
/// call that evaluates the model and when dropped (a referenced model hands
/// a failure its callable recorded to the call that ran it).
pub struct Shared<A> {
    adapter: Arc<A>,
    hook: Option<fn(&A)>,
}

impl<A> Shared<A> {
    /// A handle on `adapter` with no hook.
    pub fn new(adapter: Arc<A>) -> Self {
        Self {
            adapter,
            hook: None,
        }
    }
    /// A handle on `adapter` that calls `hook` with it after every call that
    /// evaluates the model and when dropped.
    pub fn with_hook(adapter: Arc<A>, hook: fn(&A)) -> Self {
        Self {
            adapter,
            hook: Some(hook),
        }
    }
    /// Runs the hook, then hands `r` back.
    #[inline]
    fn after<R>(&self, r: R) -> R {
        if let Some(hook) = self.hook {
            hook(&self.adapter);
        }
        r
    }
}

impl<A> Drop for Shared<A> {
    fn drop(&mut self) {
        if let Some(hook) = self.hook {
            hook(&self.adapter);
        }
    }
}

impl<const N: usize, A: MotionModel<f64, N>> MotionModel<f64, N> for Shared<A> {
    #[inline]
    fn transition(&self, x: &SVector<f64, N>, dt: f64) -> SVector<f64, N> {
        self.after(self.adapter.transition(x, dt))
    }
    #[inline]
    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N> {
        self.after(self.adapter.process_noise(dt))
    }
    #[inline]
    fn jacobian(&self, x: &SVector<f64, N>, dt: f64) -> SMatrix<f64, N, N> {
        self.after(self.adapter.jacobian(x, dt))
    }
    #[inline]
    fn transition_with_jacobian(
        &self,
        x: &SVector<f64, N>,
        dt: f64,
    ) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
        self.after(self.adapter.transition_with_jacobian(x, dt))
    }
    #[inline]
    fn jacobian_congruence(
        &self,
        f: &SMatrix<f64, N, N>,
        p: &SMatrix<f64, N, N>,
    ) -> SMatrix<f64, N, N> {
        self.after(self.adapter.jacobian_congruence(f, p))
    }
    #[inline]
    fn transition_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        dt: f64,
        plus: &mut SMatrix<f64, N, N>,
        minus: &mut SMatrix<f64, N, N>,
        centre: Option<&mut SVector<f64, N>>,
    ) {
        self.adapter
            .transition_points(x, offsets, dt, plus, minus, centre);
        self.after(())
    }
}

impl<const N: usize, const M: usize, A: MeasurementModel<f64, N, M>> MeasurementModel<f64, N, M>
    for Shared<A>
{
    #[inline]
    fn measure(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        self.after(self.adapter.measure(x))
    }
    #[inline]
    fn noise(&self) -> SMatrix<f64, M, M> {
        self.after(self.adapter.noise())
    }
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        self.adapter.is_angle(k)
    }
    #[inline]
    fn fast_trig(&self) -> bool {
        self.adapter.fast_trig()
    }
    #[inline]
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        self.after(self.adapter.jacobian(x))
    }
    #[inline]
    fn measure_with_jacobian(&self, x: &SVector<f64, N>) -> (SVector<f64, M>, SMatrix<f64, M, N>) {
        self.after(self.adapter.measure_with_jacobian(x))
    }
    #[inline]
    fn jacobian_products(
        &self,
        g: &SMatrix<f64, M, N>,
        p: &SMatrix<f64, N, N>,
    ) -> (SMatrix<f64, N, M>, SMatrix<f64, M, M>) {
        self.after(self.adapter.jacobian_products(g, p))
    }
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<f64, N>,
    ) -> (SVector<f64, M>, SVector<f64, M>, SVector<f64, M>) {
        self.after(self.adapter.measure_with_trig(x))
    }
    #[inline]
    fn measure_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.adapter.measure_points(x, offsets, plus, minus, centre);
        self.after(())
    }
    #[inline]
    fn measure_points_trig(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.adapter
            .measure_points_trig(x, offsets, plus, minus, centre);
        self.after(())
    }
}
