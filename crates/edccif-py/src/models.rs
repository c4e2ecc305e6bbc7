//! `edccif.models`: the model catalogue and models from Python callables, as
//! Python objects. Every motion model is a `MotionModel` (state dimension `.n`,
//! batch evaluator `.f(X, dt)`, `.Q(dt)`, `.jacobian(x, dt)`), every sensor a
//! `MeasurementModel` (`.m`, `.n`, `.h(X)`, `.R`, `.jacobian(x)`, `.angles`). The
//! filters and networks turn them into the typed adapters of [`crate::adapters`]
//! through [`crate::dims`].

use std::sync::Arc;

use edccif_core::linalg::validate_covariance;
use edccif_core::models::{
    BearingOnly, ConstantAcceleration, ConstantVelocity, CoordinatedTurn, CoordinatedTurn2,
    Position2, Position3, RandomWalk, RangeBearing, RangeOnly, RangePitchAzimuth,
};
use edccif_core::{MeasurementModel, MotionModel};
use edccif_sim::timestep::check_dt;
use nalgebra::{SMatrix, SVector};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

use crate::adapters::{
    CustomMotionSpec, CustomSensorSpec, MotionAdapter, MotionSpec, NoiseSpec, SensorAdapter,
    SensorSpec,
};
use crate::convert::{f64_array, finite_array, to_numpy, Dim};
use crate::dims::{check_m, check_n};
use crate::errors::{IntoPyResult, ParameterError, ShapeError};
use crate::{with_dims, with_m, with_n};

/// Rows of a row-major `(k, N)` buffer as vectors.
pub fn rows_of<const N: usize>(flat: &[f64]) -> Vec<SVector<f64, N>> {
    flat.chunks_exact(N)
        .map(SVector::from_column_slice)
        .collect()
}

/// Row-major values of `(k, D)` vectors.
pub fn flat_rows<const D: usize>(v: &[SVector<f64, D>]) -> Vec<f64> {
    v.iter().flat_map(|x| x.iter().copied()).collect()
}

/// Row-major values of a matrix.
pub fn row_major<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>) -> Vec<f64> {
    a.transpose().as_slice().to_vec()
}

/// A finite `(d, d)` matrix, row-major.
fn square(obj: &Bound<'_, PyAny>, name: &str, d: usize) -> PyResult<Vec<f64>> {
    Ok(finite_array(obj, name, &[Dim::Is(d), Dim::Is(d)])?.0)
}

/// A finite, symmetric, positive semi-definite `(n, n)` process noise `Q`,
/// row-major: an indefinite `Q` would make every predicted covariance
/// indefinite (`NotPositiveDefiniteError` naming `Q` and its smallest
/// eigenvalue).
fn process_noise(obj: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<f64>> {
    let v = square(obj, "Q", n)?;
    let q = nalgebra::DMatrix::from_row_slice(n, n, &v);
    let scale = v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let tol = 1e-9 * scale.max(f64::MIN_POSITIVE);
    if let Some((i, j)) = (0..n)
        .flat_map(|i| (0..n).map(move |j| (i, j)))
        .find(|&(i, j)| (q[(i, j)] - q[(j, i)]).abs() > tol)
    {
        return Err(crate::errors::NotPositiveDefiniteError::new_err(format!(
            "Q: expected a symmetric positive semi-definite process noise, but Q[{i}, {j}] = {} differs from Q[{j}, {i}] = {}",
            q[(i, j)],
            q[(j, i)]
        )));
    }
    let min = q
        .symmetric_eigenvalues()
        .iter()
        .fold(f64::INFINITY, |a, &x| a.min(x));
    if min < -tol {
        return Err(crate::errors::NotPositiveDefiniteError::new_err(format!(
            "Q: expected a symmetric positive semi-definite process noise, but its smallest eigenvalue is {min:e}"
        )));
    }
    Ok(v)
}

/// A finite, symmetric positive definite `(d, d)` noise matrix, row-major.
fn covariance(obj: &Bound<'_, PyAny>, name: &str, d: usize) -> PyResult<Vec<f64>> {
    let v = square(obj, name, d)?;
    with_m!(d, |D| {
        validate_covariance(
            &SMatrix::<f64, D, D>::from_row_slice(&v),
            "measurement noise R",
        )
        .py()
        .map(|()| v.clone())
    })
}

fn callable(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Py<PyAny>> {
    if obj.is_callable() {
        Ok(obj.clone().unbind())
    } else {
        Err(ParameterError::new_err(format!(
            "{name}: expected a callable, got {}",
            obj.get_type().name()?
        )))
    }
}

/// Base of every motion model: state dimension `n`, the batch evaluator
/// `f(X, dt)`, the process noise `Q(dt)` and the Jacobian.
#[pyclass(name = "MotionModel", module = "edccif.models", subclass, frozen)]
pub struct PyMotionModel {
    /// The model.
    pub spec: MotionSpec,
    repr: String,
}

impl PyMotionModel {
    fn adapter<const N: usize>(&self) -> PyResult<MotionAdapter<N>> {
        MotionAdapter::new(&self.spec)
    }
}

#[pymethods]
impl PyMotionModel {
    /// State dimension n.
    #[getter]
    fn n(&self) -> usize {
        self.spec.n()
    }

    /// The model on a batch of states: `X` (k, n), one state per row →
    /// `f(X, dt)` (k, n).
    fn f<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = crate::args::real_arg::dt)] dt: f64,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        check_dt(dt, "dt").py()?;
        let n = self.spec.n();
        let (v, shape) = finite_array(x, "X", &[Dim::Any("k"), Dim::Is(n)])?;
        with_n!(n, |N| {
            let a = self.adapter::<N>()?;
            let out = a.transition_many(&rows_of::<N>(&v), dt);
            if let Some(e) = a.failure.take() {
                return Err(e);
            }
            to_numpy(py, flat_rows(&out), &shape)
        })
    }

    /// Process-noise covariance `Q(dt)` (n, n).
    #[pyo3(name = "Q")]
    fn q<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = crate::args::real_arg::dt)] dt: f64,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        check_dt(dt, "dt").py()?;
        let n = self.spec.n();
        with_n!(n, |N| {
            let a = self.adapter::<N>()?;
            let q = a.process_noise(dt);
            if let Some(e) = a.failure.take() {
                return Err(e);
            }
            to_numpy(py, row_major(&q), &[n, n])
        })
    }

    /// `∂f/∂x` at `x` (n,) over `dt` → (n, n) (analytic for the catalogue, the
    /// callable or finite differences for a custom model).
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = crate::args::real_arg::dt)] dt: f64,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        check_dt(dt, "dt").py()?;
        let n = self.spec.n();
        let (v, _) = finite_array(x, "x", &[Dim::Is(n)])?;
        with_n!(n, |N| {
            let a = self.adapter::<N>()?;
            let j = a.jacobian(&SVector::<f64, N>::from_column_slice(&v), dt);
            if let Some(e) = a.failure.take() {
                return Err(e);
            }
            to_numpy(py, row_major(&j), &[n, n])
        })
    }

    fn __repr__(&self) -> String {
        self.repr.clone()
    }
}

fn motion(spec: MotionSpec, repr: String) -> PyMotionModel {
    PyMotionModel { spec, repr }
}

/// Constant velocity, state `[p(dim), v(dim)]` (n = 2·dim), white-acceleration
/// noise of intensity `q` on each axis.
#[pyclass(name = "ConstantVelocity", module = "edccif.models", extends = PyMotionModel, frozen)]
pub struct PyConstantVelocity;

#[pymethods]
impl PyConstantVelocity {
    #[new]
    #[pyo3(signature = (dim, q))]
    fn new(
        #[pyo3(from_py_with = crate::args::named::dim)] dim: usize,
        #[pyo3(from_py_with = crate::args::real_arg::q)] q: f64,
    ) -> PyResult<(Self, PyMotionModel)> {
        check_spatial(dim)?;
        let model = ConstantVelocity::new(q).py()?;
        Ok((
            Self,
            motion(
                MotionSpec::ConstantVelocity { dim, model },
                format!("ConstantVelocity(dim={dim}, q={q})"),
            ),
        ))
    }
}

fn check_spatial(dim: usize) -> PyResult<()> {
    if (1..=3).contains(&dim) {
        Ok(())
    } else {
        Err(ParameterError::new_err(format!(
            "dim: expected a spatial dimension 1, 2 or 3, got {dim}"
        )))
    }
}

/// Constant acceleration, state `[p(dim), v(dim), a(dim)]` (n = 3·dim),
/// white-jerk noise of intensity `q` on each axis.
#[pyclass(name = "ConstantAcceleration", module = "edccif.models", extends = PyMotionModel, frozen)]
pub struct PyConstantAcceleration;

#[pymethods]
impl PyConstantAcceleration {
    #[new]
    #[pyo3(signature = (dim, q))]
    fn new(
        #[pyo3(from_py_with = crate::args::named::dim)] dim: usize,
        #[pyo3(from_py_with = crate::args::real_arg::q)] q: f64,
    ) -> PyResult<(Self, PyMotionModel)> {
        check_spatial(dim)?;
        let model = ConstantAcceleration::new(q).py()?;
        Ok((
            Self,
            motion(
                MotionSpec::ConstantAcceleration { dim, model },
                format!("ConstantAcceleration(dim={dim}, q={q})"),
            ),
        ))
    }
}

/// Random walk `x' = x + w`, `Q = q·dt·I`, any state dimension `n`.
#[pyclass(name = "RandomWalk", module = "edccif.models", extends = PyMotionModel, frozen)]
pub struct PyRandomWalk;

#[pymethods]
impl PyRandomWalk {
    #[new]
    #[pyo3(signature = (n, q))]
    fn new(
        #[pyo3(from_py_with = crate::args::named::n)] n: usize,
        #[pyo3(from_py_with = crate::args::real_arg::q)] q: f64,
    ) -> PyResult<(Self, PyMotionModel)> {
        check_n(n)?;
        let model = RandomWalk::new(q).py()?;
        Ok((
            Self,
            motion(
                MotionSpec::RandomWalk { n, model },
                format!("RandomWalk(n={n}, q={q})"),
            ),
        ))
    }
}

/// Coordinated turn in the plane, state `[x, y, vx, vy, ω]` (n = 5); `q1` on
/// position/velocity, `q2` on the turn rate.
/// `fast_trig=False` switches off the fast trigonometry of the sigma-point
/// transforms (on by default) for the platform libm's, bit for bit (last-bit
/// differences; `docs/guide.md` §7).
#[pyclass(name = "CoordinatedTurn2D", module = "edccif.models", extends = PyMotionModel, frozen)]
pub struct PyCoordinatedTurn2D;

#[pymethods]
impl PyCoordinatedTurn2D {
    #[new]
    #[pyo3(signature = (q1, q2, *, fast_trig = true))]
    fn new(
        #[pyo3(from_py_with = crate::args::real_arg::q1)] q1: f64,
        #[pyo3(from_py_with = crate::args::real_arg::q2)] q2: f64,
        #[pyo3(from_py_with = crate::args::flag_arg::fast_trig)] fast_trig: bool,
    ) -> PyResult<(Self, PyMotionModel)> {
        let m = CoordinatedTurn2::new(q1, q2)
            .py()?
            .with_fast_trig(fast_trig);
        Ok((
            Self,
            motion(
                MotionSpec::CoordinatedTurn2D(m),
                format!(
                    "CoordinatedTurn2D(q1={q1}, q2={q2}{})",
                    fast_trig_repr(fast_trig)
                ),
            ),
        ))
    }
}

/// The `repr` suffix of a model built without the (default) fast
/// trigonometry (nothing when it is on, so the default `repr` is unchanged).
fn fast_trig_repr(on: bool) -> &'static str {
    if on {
        ""
    } else {
        ", fast_trig=False"
    }
}

/// Coordinated turn in the xy plane with constant climb rate, state
/// `[px, py, pz, vx, vy, vz, ω]` (n = 7), the paper's motion model.
/// `fast_trig=False` switches off the fast trigonometry of the sigma-point
/// transforms (on by default) for the platform libm's, bit for bit (last-bit
/// differences; `docs/guide.md` §7).
#[pyclass(name = "CoordinatedTurn", module = "edccif.models", extends = PyMotionModel, frozen)]
pub struct PyCoordinatedTurn;

#[pymethods]
impl PyCoordinatedTurn {
    #[new]
    #[pyo3(signature = (q1, q2, *, fast_trig = true))]
    fn new(
        #[pyo3(from_py_with = crate::args::real_arg::q1)] q1: f64,
        #[pyo3(from_py_with = crate::args::real_arg::q2)] q2: f64,
        #[pyo3(from_py_with = crate::args::flag_arg::fast_trig)] fast_trig: bool,
    ) -> PyResult<(Self, PyMotionModel)> {
        let m = CoordinatedTurn::new(q1, q2).py()?.with_fast_trig(fast_trig);
        Ok((
            Self,
            motion(
                MotionSpec::CoordinatedTurn(m),
                format!(
                    "CoordinatedTurn(q1={q1}, q2={q2}{})",
                    fast_trig_repr(fast_trig)
                ),
            ),
        ))
    }
}

/// Linear motion `x' = F x + w`, `w ~ N(0, Q)` (the same `F`, `Q` whatever dt).
#[pyclass(name = "LinearMotion", module = "edccif.models", extends = PyMotionModel, frozen)]
pub struct PyLinearMotion;

#[pymethods]
impl PyLinearMotion {
    #[new]
    #[pyo3(signature = (F, Q))]
    #[allow(non_snake_case)]
    fn new(F: &Bound<'_, PyAny>, Q: &Bound<'_, PyAny>) -> PyResult<(Self, PyMotionModel)> {
        let (f, shape) = finite_array(F, "F", &[Dim::Any("n"), Dim::Any("n")])?;
        let n = shape[0];
        if shape[1] != n {
            return Err(ShapeError::new_err(format!(
                "F: expected a square matrix (n, n), got ({}, {})",
                shape[0], shape[1]
            )));
        }
        check_n(n)?;
        let q = process_noise(Q, n)?;
        let spec = MotionSpec::Linear { n, f, q };
        with_n!(n, |N| MotionAdapter::<N>::new(&spec).map(|_| ()))?;
        Ok((Self, motion(spec, format!("LinearMotion(n={n})"))))
    }
}

/// A motion model from Python: `f(X, dt)` maps a (k, n) array of states (one
/// per row; k = 2n sigma points for the CKF/CIF, 2n+1 for the UKF, 1 for single
/// states) to their (k, n) images in one call; `Q` is an (n, n) array or a
/// callable of dt; `jacobian(x, dt) -> (n, n)` (optional, for the EKF and the
/// error-minimised gain; finite differences of `f` otherwise).
#[pyclass(name = "CustomMotion", module = "edccif.models", extends = PyMotionModel, frozen)]
pub struct PyCustomMotion;

#[pymethods]
impl PyCustomMotion {
    #[new]
    #[pyo3(signature = (f, Q, n, jacobian = None))]
    #[allow(non_snake_case)]
    fn new(
        f: &Bound<'_, PyAny>,
        Q: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::named::n)] n: usize,
        jacobian: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<(Self, PyMotionModel)> {
        check_n(n)?;
        let f = callable(f, "f")?;
        let q = if Q.is_callable() {
            NoiseSpec::Callable(Q.clone().unbind())
        } else {
            NoiseSpec::Matrix(process_noise(Q, n)?)
        };
        let jacobian = jacobian
            .filter(|j| !j.is_none())
            .map(|j| callable(j, "jacobian"))
            .transpose()?;
        let spec = MotionSpec::Custom(Arc::new(CustomMotionSpec { f, q, n, jacobian }));
        Ok((Self, motion(spec, format!("CustomMotion(n={n})"))))
    }
}

/// Base of every measurement model: measurement dimension `m`, the batch
/// evaluator `h(X)`, the noise `R`, angle components and the Jacobian.
#[pyclass(name = "MeasurementModel", module = "edccif.models", subclass, frozen)]
pub struct PyMeasurementModel {
    /// The model.
    pub spec: SensorSpec,
    repr: String,
}

fn sensor(spec: SensorSpec, repr: String) -> PyMeasurementModel {
    PyMeasurementModel { spec, repr }
}

#[pymethods]
impl PyMeasurementModel {
    /// Measurement dimension m.
    #[getter]
    fn m(&self) -> usize {
        self.spec.m()
    }

    /// The state dimension the model needs, or `None` when it measures any state
    /// whose first components are the position (see `min_n`).
    #[getter]
    fn n(&self) -> Option<usize> {
        self.spec.n()
    }

    /// The smallest state dimension the model measures.
    #[getter]
    fn min_n(&self) -> usize {
        self.spec.min_n()
    }

    /// Indices of the angle components (wrapped to [−π, π), averaged circularly).
    #[getter]
    fn angles(&self) -> PyResult<Vec<usize>> {
        let m = self.spec.m();
        let n = self.spec.n().unwrap_or(self.spec.min_n());
        with_dims!(n, m, |N, M| {
            let a = SensorAdapter::<N, M>::new(&self.spec)?;
            Ok((0..M).filter(|&k| a.is_angle(k)).collect())
        })
    }

    /// Measurement-noise covariance `R` (m, m).
    #[getter(R)]
    fn r<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let m = self.spec.m();
        let n = self.spec.n().unwrap_or(self.spec.min_n());
        with_dims!(n, m, |N, M| {
            let a = SensorAdapter::<N, M>::new(&self.spec)?;
            to_numpy(py, row_major(&a.noise()), &[m, m])
        })
    }

    /// The model on a batch of states: `X` (k, n), one state per row → `h(X)`
    /// (k, m).
    fn h<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let (v, shape) = finite_array(x, "X", &[Dim::Any("k"), Dim::Any("n")])?;
        let (k, n) = (shape[0], shape[1]);
        self.spec.check_state_dim(n, "X")?;
        let m = self.spec.m();
        with_dims!(n, m, |N, M| {
            let a = SensorAdapter::<N, M>::new(&self.spec)?;
            let out = a.measure_many(&rows_of::<N>(&v));
            if let Some(e) = a.failure.take() {
                return Err(e);
            }
            to_numpy(py, flat_rows(&out), &[k, m])
        })
    }

    /// `∂h/∂x` at `x` (n,) → (m, n).
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let (v, shape) = finite_array(x, "x", &[Dim::Any("n")])?;
        let n = shape[0];
        self.spec.check_state_dim(n, "x")?;
        let m = self.spec.m();
        with_dims!(n, m, |N, M| {
            let a = SensorAdapter::<N, M>::new(&self.spec)?;
            let j = a.jacobian(&SVector::<f64, N>::from_column_slice(&v));
            if let Some(e) = a.failure.take() {
                return Err(e);
            }
            to_numpy(py, row_major(&j), &[m, n])
        })
    }

    fn __repr__(&self) -> String {
        self.repr.clone()
    }
}

fn point<const D: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; D]> {
    let (v, _) = finite_array(obj, name, &[Dim::Is(D)])?;
    let mut a = [0.0; D];
    a.copy_from_slice(&v);
    Ok(a)
}

/// Position measurement `z = p + v` of the first 2 or 3 state components (as
/// many as `sigma` has values), noise standard deviations `sigma` per axis.
#[pyclass(name = "Position", module = "edccif.models", extends = PyMeasurementModel, frozen)]
pub struct PyPosition;

#[pymethods]
impl PyPosition {
    #[new]
    #[pyo3(signature = (sigma))]
    fn new(sigma: &Bound<'_, PyAny>) -> PyResult<(Self, PyMeasurementModel)> {
        let (s, _) = f64_array(sigma, "sigma", &[Dim::Any("d")])?;
        let spec = match s.len() {
            2 => SensorSpec::Position2(Position2::new([s[0], s[1]]).py()?),
            3 => SensorSpec::Position3(Position3::new([s[0], s[1], s[2]]).py()?),
            d => {
                return Err(ShapeError::new_err(format!(
                    "sigma: expected 2 or 3 standard deviations (x, y[, z]), got {d}"
                )))
            }
        };
        Ok((Self, sensor(spec, format!("Position(sigma={s:?})"))))
    }
}

/// Range, pitch and azimuth of the target (the first 3 state components) seen
/// from `sensor_xyz`, noise `sigma_r` on the range and `sigma_a` on both angles
/// (components 1 and 2 are angles); the paper's sensor.
/// `fast_trig=False` switches off the fast trigonometry of the sigma-point
/// transforms (on by default) for the platform libm's, bit for bit (last-bit
/// differences; `docs/guide.md` §7).
#[pyclass(name = "RangePitchAzimuth", module = "edccif.models", extends = PyMeasurementModel, frozen)]
pub struct PyRangePitchAzimuth;

#[pymethods]
impl PyRangePitchAzimuth {
    #[new]
    #[pyo3(signature = (sensor_xyz, sigma_r, sigma_a, *, fast_trig = true))]
    fn new(
        sensor_xyz: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::real_arg::sigma_r)] sigma_r: f64,
        #[pyo3(from_py_with = crate::args::real_arg::sigma_a)] sigma_a: f64,
        #[pyo3(from_py_with = crate::args::flag_arg::fast_trig)] fast_trig: bool,
    ) -> PyResult<(Self, PyMeasurementModel)> {
        let p = point::<3>(sensor_xyz, "sensor_xyz")?;
        let model = RangePitchAzimuth::new(p, sigma_r, sigma_a)
            .py()?
            .with_fast_trig(fast_trig);
        Ok((
            Self,
            sensor(
                SensorSpec::RangePitchAzimuth(model),
                format!(
                    "RangePitchAzimuth(sensor_xyz={p:?}, sigma_r={sigma_r}, sigma_a={sigma_a}{})",
                    fast_trig_repr(fast_trig)
                ),
            ),
        ))
    }
}

/// Range and bearing in the plane of the target (the first 2 state components)
/// from `sensor_xy`; `z = [|d|, atan2(dy, dx)]`, component 1 an angle.
/// `fast_trig=False` switches off the fast trigonometry of the sigma-point
/// transforms (on by default) for the platform libm's, bit for bit (last-bit
/// differences; `docs/guide.md` §7).
#[pyclass(name = "RangeBearing", module = "edccif.models", extends = PyMeasurementModel, frozen)]
pub struct PyRangeBearing;

#[pymethods]
impl PyRangeBearing {
    #[new]
    #[pyo3(signature = (sensor_xy, sigma_r, sigma_b, *, fast_trig = true))]
    fn new(
        sensor_xy: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::real_arg::sigma_r)] sigma_r: f64,
        #[pyo3(from_py_with = crate::args::real_arg::sigma_b)] sigma_b: f64,
        #[pyo3(from_py_with = crate::args::flag_arg::fast_trig)] fast_trig: bool,
    ) -> PyResult<(Self, PyMeasurementModel)> {
        let p = point::<2>(sensor_xy, "sensor_xy")?;
        let model = RangeBearing::new(p, sigma_r, sigma_b)
            .py()?
            .with_fast_trig(fast_trig);
        Ok((
            Self,
            sensor(
                SensorSpec::RangeBearing(model),
                format!(
                    "RangeBearing(sensor_xy={p:?}, sigma_r={sigma_r}, sigma_b={sigma_b}{})",
                    fast_trig_repr(fast_trig)
                ),
            ),
        ))
    }
}

/// Bearing in the plane of the target (the first 2 state components) from
/// `sensor_xy`; `z = [atan2(dy, dx)]`, an angle.
/// `fast_trig=False` switches off the fast trigonometry of the sigma-point
/// transforms (on by default) for the platform libm's, bit for bit (last-bit
/// differences; `docs/guide.md` §7).
#[pyclass(name = "BearingOnly", module = "edccif.models", extends = PyMeasurementModel, frozen)]
pub struct PyBearingOnly;

#[pymethods]
impl PyBearingOnly {
    #[new]
    #[pyo3(signature = (sensor_xy, sigma_b, *, fast_trig = true))]
    fn new(
        sensor_xy: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::real_arg::sigma_b)] sigma_b: f64,
        #[pyo3(from_py_with = crate::args::flag_arg::fast_trig)] fast_trig: bool,
    ) -> PyResult<(Self, PyMeasurementModel)> {
        let p = point::<2>(sensor_xy, "sensor_xy")?;
        let model = BearingOnly::new(p, sigma_b).py()?.with_fast_trig(fast_trig);
        Ok((
            Self,
            sensor(
                SensorSpec::BearingOnly(model),
                format!(
                    "BearingOnly(sensor_xy={p:?}, sigma_b={sigma_b}{})",
                    fast_trig_repr(fast_trig)
                ),
            ),
        ))
    }
}

/// Range of the target from `sensor_pos` (2 or 3 coordinates: the first 2 or 3
/// state components are the position); `z = [|d|]`.
#[pyclass(name = "RangeOnly", module = "edccif.models", extends = PyMeasurementModel, frozen)]
pub struct PyRangeOnly;

#[pymethods]
impl PyRangeOnly {
    #[new]
    #[pyo3(signature = (sensor_pos, sigma_r))]
    fn new(
        sensor_pos: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::real_arg::sigma_r)] sigma_r: f64,
    ) -> PyResult<(Self, PyMeasurementModel)> {
        let (p, _) = finite_array(sensor_pos, "sensor_pos", &[Dim::Any("d")])?;
        let spec = match p.len() {
            2 => SensorSpec::RangeOnly2(RangeOnly::new([p[0], p[1]], sigma_r).py()?),
            3 => SensorSpec::RangeOnly3(RangeOnly::new([p[0], p[1], p[2]], sigma_r).py()?),
            d => {
                return Err(ShapeError::new_err(format!(
                    "sensor_pos: expected 2 or 3 coordinates, got {d}"
                )))
            }
        };
        Ok((
            Self,
            sensor(
                spec,
                format!("RangeOnly(sensor_pos={p:?}, sigma_r={sigma_r})"),
            ),
        ))
    }
}

/// Linear measurement `z = H x + v`, `v ~ N(0, R)`.
#[pyclass(name = "LinearMeasurement", module = "edccif.models", extends = PyMeasurementModel, frozen)]
pub struct PyLinearMeasurement;

#[pymethods]
impl PyLinearMeasurement {
    #[new]
    #[pyo3(signature = (H, R))]
    #[allow(non_snake_case)]
    fn new(H: &Bound<'_, PyAny>, R: &Bound<'_, PyAny>) -> PyResult<(Self, PyMeasurementModel)> {
        let (h, shape) = finite_array(H, "H", &[Dim::Any("m"), Dim::Any("n")])?;
        let (m, n) = (shape[0], shape[1]);
        check_n(n)?;
        check_m(m)?;
        let r = covariance(R, "R", m)?;
        let spec = SensorSpec::Linear { m, n, h, r };
        Ok((
            Self,
            sensor(spec, format!("LinearMeasurement(m={m}, n={n})")),
        ))
    }
}

/// A measurement model from Python: `h(X)` maps a (k, n) array of states (one
/// per row) to their (k, m) measurements in one call; `R` (m, m) symmetric
/// positive definite; `angles`: indices of angle components; `jacobian(x) -> (m,
/// n)` (optional; finite differences of `h` otherwise).
#[pyclass(name = "CustomMeasurement", module = "edccif.models", extends = PyMeasurementModel, frozen)]
pub struct PyCustomMeasurement;

#[pymethods]
impl PyCustomMeasurement {
    #[new]
    #[pyo3(signature = (h, R, m, n, angles = Vec::new(), jacobian = None))]
    #[allow(non_snake_case)]
    fn new(
        h: &Bound<'_, PyAny>,
        R: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::named::m)] m: usize,
        #[pyo3(from_py_with = crate::args::named::n)] n: usize,
        #[pyo3(from_py_with = crate::args::named::angles)] angles: Vec<usize>,
        jacobian: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<(Self, PyMeasurementModel)> {
        check_n(n)?;
        check_m(m)?;
        let h = callable(h, "h")?;
        let r = covariance(R, "R", m)?;
        let mut is_angle = vec![false; m];
        for &k in &angles {
            if k >= m {
                return Err(ParameterError::new_err(format!(
                    "angles: expected component indices in 0..{m}, got {k}"
                )));
            }
            is_angle[k] = true;
        }
        let jacobian = jacobian
            .filter(|j| !j.is_none())
            .map(|j| callable(j, "jacobian"))
            .transpose()?;
        let spec = SensorSpec::Custom(Arc::new(CustomSensorSpec {
            h,
            r,
            m,
            n,
            angles: is_angle,
            jacobian,
        }));
        Ok((
            Self,
            sensor(
                spec,
                format!("CustomMeasurement(m={m}, n={n}, angles={angles:?})"),
            ),
        ))
    }
}
