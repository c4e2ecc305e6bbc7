//! Single filters as Python objects, FilterPy-shaped: `edccif.CKF`, `UKF`, `EKF`,
//! `CIF` and the event-triggered `ETCIF`, each `(motion, sensor, x0, P0, dt=None,
//! ...)` with `predict(dt=None)`, `update(z, R=None)` and the attributes `x`, `P`
//! (copies; validated setters). They run the core's local steps on the typed
//! adapters of [`crate::adapters`], compiled for every supported `(n, m)` through
//! [`crate::dims`].
//!
//! `predict` runs the core's `cif_predict` / `cov_predict`, `update` its
//! `cif_update` / `cov_update` (at the last prediction, or at the current estimate
//! taken as a prior), so a `predict(); update(z)` pair is the network rows' local
//! step bit for bit. A failed call (bad input, a model callable that raised or
//! returned a wrong shape or non-finite values, a numerical failure) raises a
//! named error and leaves the filter as it was.

use edccif_core::{
    cif_predict, cif_update, cov_local_chained, cov_predict, cov_update, CheckedGaussian, CifPrior,
    EtOptions, EtPolicy, Gaussian, InfoPair, LocalFilter, Observation, Trigger, TriggerState,
};
use nalgebra::{SMatrix, SVector};
use numpy::{PyArray1, PyArrayDyn};
use pyo3::prelude::*;

use crate::adapters::{MotionAdapter, SensorAdapter};
use crate::convert::{f64_array, finite_array, to_numpy, Dim};
use crate::errors::{core_err, EdccifError, IntoPyResult, ParameterError, ShapeError};
use crate::models::{row_major, PyMeasurementModel, PyMotionModel};
use crate::with_dims;

/// A float64 NumPy array.
type Arr<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Which local step a filter runs.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    /// Cubature information filter (with the trigger of its configuration).
    Cif,
    /// Covariance form: CKF, UKF, EKF.
    Cov(LocalFilter<f64>),
}

/// The trigger configuration of a filter.
#[derive(Debug, Clone, Copy)]
struct Config {
    kind: Kind,
    trigger: Trigger<f64>,
    et: EtOptions<f64>,
    seed: Option<u64>,
}

/// What the Python class needs of a filter of any `(n, m)`.
trait FilterDyn: Send + Sync {
    fn n(&self) -> usize;
    fn m(&self) -> usize;
    fn predict(&mut self, dt: f64) -> PyResult<()>;
    fn update(&mut self, z: Option<&[f64]>, r: Option<&[f64]>) -> PyResult<Option<bool>>;
    fn x(&self) -> Vec<f64>;
    fn p(&self) -> Vec<f64>;
    fn info(&self) -> (Vec<f64>, Vec<f64>);
    fn set(&mut self, x: Option<&[f64]>, p: Option<&[f64]>) -> PyResult<()>;
    /// `predict(dts[k]); update(z_k, R_k)` for every step `k` (`z` row-major
    /// `(T, m)`, a row of NaN: no measurement; `rs`, when given, row-major
    /// `(T, m, m)`, each step's `R` in place of the sensor's), appending each
    /// posterior's `x` and row-major `P` and the trigger's decision to `out`. On
    /// an error at step `k` the filter is restored to its state before the batch
    /// and `(k, error)` is returned.
    fn batch(
        &mut self,
        z: &[f64],
        dts: &[f64],
        rs: Option<&[f64]>,
        out: &mut Batch,
        tick: &mut dyn FnMut(usize) -> PyResult<()>,
    ) -> Result<(), (usize, PyErr)>;
}

/// Steps of `batch_filter` between two checks for signals (Ctrl-C).
const BATCH_TICK: usize = 1024;

/// What [`FilterDyn::batch`] records per step.
#[derive(Debug, Default)]
struct Batch {
    /// Posterior means, `(T, n)` row-major.
    means: Vec<f64>,
    /// Posterior covariances, `(T, n, n)` row-major.
    covs: Vec<f64>,
    /// The trigger's decision: 1 sent, 0 not sent, -1 no measurement.
    sent: Vec<i8>,
}

/// One filter of state dimension `N`, measurement dimension `M`.
struct Single<const N: usize, const M: usize> {
    motion: MotionAdapter<N>,
    sensor: SensorAdapter<N, M>,
    cfg: Config,
    trigger_state: TriggerState<f64, M>,
    /// The current estimate (posterior after `update`, prior after `predict`).
    est: Gaussian<f64, N>,
    /// Information pair of the estimate (the information filters).
    info: InfoPair<f64, N>,
    /// The information prior of the last `predict` (CIF), until `update` uses it.
    cif_prior: Option<CifPrior<f64, N>>,
}

impl<const N: usize, const M: usize> Single<N, M> {
    fn new(
        motion: &PyMotionModel,
        sensor: &PyMeasurementModel,
        cfg: Config,
        x0: &[f64],
        p0: &[f64],
    ) -> PyResult<Self> {
        let est =
            Gaussian::new(SVector::from_column_slice(x0), SMatrix::from_row_slice(p0)).py()?;
        let trigger_state = match cfg.seed {
            Some(s) => TriggerState::seeded(&cfg.trigger, s, 0),
            None => TriggerState::new(&cfg.trigger),
        };
        Ok(Self {
            motion: MotionAdapter::new(&motion.spec)?,
            sensor: SensorAdapter::new(&sensor.spec)?,
            cfg,
            trigger_state,
            info: est.to_info().py()?,
            est,
            cif_prior: None,
        })
    }

    /// The core result, or the error a model callable recorded (which wins: the
    /// core's error is then only its consequence).
    fn finish<T>(&self, r: edccif_core::Result<T>) -> PyResult<T> {
        let failed = self
            .motion
            .failure
            .take()
            .or_else(|| self.sensor.failure.take());
        match (failed, r) {
            (Some(e), _) => Err(e),
            (None, Ok(v)) => Ok(v),
            (None, Err(e)) => Err(core_err(&e)),
        }
    }

    /// The update at the current estimate (a prior) with `obs`: the posterior, its
    /// information pair (CIF) and the new trigger state, or the error. Nothing is
    /// committed here.
    #[allow(clippy::type_complexity)]
    fn try_update(
        &self,
        obs: &Observation<f64, M>,
    ) -> PyResult<(
        Gaussian<f64, N>,
        Option<InfoPair<f64, N>>,
        TriggerState<f64, M>,
        Option<bool>,
    )> {
        let c = &self.cfg;
        match c.kind {
            Kind::Cif => {
                let prior = match &self.cif_prior {
                    Some(p) => *p,
                    None => CifPrior::new(&self.est).py()?,
                };
                let r = cif_update(
                    &self.sensor,
                    &prior,
                    obs,
                    &c.trigger,
                    &self.trigger_state,
                    &c.et,
                );
                let r = self.finish(r)?;
                // As the network step: the local posterior in information form, then
                // its covariance form.
                let info = r.local_posterior();
                let g = info.to_gaussian().py()?;
                Ok((g, Some(info), r.trigger_state, r.triggered))
            }
            Kind::Cov(f) => {
                let r = cov_update(
                    &f,
                    &self.sensor,
                    &self.est,
                    obs,
                    &c.trigger,
                    &self.trigger_state,
                    &c.et,
                );
                let r = self.finish(r)?;
                Ok((r.posterior, None, r.trigger_state, r.triggered))
            }
        }
    }
}

impl<const N: usize, const M: usize> FilterDyn for Single<N, M> {
    fn n(&self) -> usize {
        N
    }
    fn m(&self) -> usize {
        M
    }

    fn predict(&mut self, dt: f64) -> PyResult<()> {
        match self.cfg.kind {
            Kind::Cif => {
                let r = cif_predict(&self.motion, dt, &self.est);
                let prior = self.finish(r)?;
                self.est = prior.to_gaussian();
                self.info = prior.info();
                self.cif_prior = Some(prior);
            }
            Kind::Cov(f) => {
                let r = cov_predict(&f, &self.motion, dt, &self.est);
                let prior = self.finish(r)?;
                // As the information filters: an indefinite prior (e.g. from an
                // indefinite Q) is refused, not kept.
                edccif_core::linalg::validate_covariance(
                    &prior.p,
                    "prior covariance P⁻ (P after predict)",
                )
                .py()?;
                self.est = prior;
            }
        }
        Ok(())
    }

    fn update(&mut self, z: Option<&[f64]>, r: Option<&[f64]>) -> PyResult<Option<bool>> {
        let obs = match z {
            None => Observation::Missing,
            Some(v) => Observation::Measured(SVector::from_column_slice(v)),
        };
        let r_over = match r {
            None => None,
            Some(v) => {
                let r = SMatrix::<f64, M, M>::from_row_slice(v);
                edccif_core::linalg::validate_covariance(&r, "measurement noise R").py()?;
                Some(r)
            }
        };
        self.sensor.r_override = r_over;
        let out = self.try_update(&obs);
        self.sensor.r_override = None;
        let (g, info, ts, triggered) = out?;
        edccif_core::linalg::validate_covariance(&g.p, "posterior covariance P (P after update)")
            .py()?;
        self.est = g;
        if let Some(i) = info {
            self.info = i;
        }
        self.trigger_state = ts;
        self.cif_prior = None;
        Ok(triggered)
    }

    fn x(&self) -> Vec<f64> {
        self.est.x.as_slice().to_vec()
    }
    fn p(&self) -> Vec<f64> {
        row_major(&self.est.p)
    }
    fn info(&self) -> (Vec<f64>, Vec<f64>) {
        (self.info.y.as_slice().to_vec(), row_major(&self.info.ymat))
    }

    fn set(&mut self, x: Option<&[f64]>, p: Option<&[f64]>) -> PyResult<()> {
        let xv = x.map_or(self.est.x, SVector::from_column_slice);
        let pv = p.map_or(self.est.p, SMatrix::from_row_slice);
        let g = Gaussian::new(xv, pv).py()?;
        let info = g.to_info().py()?;
        self.est = g;
        self.info = info;
        self.cif_prior = None;
        Ok(())
    }

    fn batch(
        &mut self,
        z: &[f64],
        dts: &[f64],
        rs: Option<&[f64]>,
        out: &mut Batch,
        tick: &mut dyn FnMut(usize) -> PyResult<()>,
    ) -> Result<(), (usize, PyErr)> {
        if let Kind::Cov(f) = self.cfg.kind {
            return self.batch_cov(&f, z, dts, rs, out, tick);
        }
        let saved = (self.est, self.info, self.cif_prior, self.trigger_state);
        for (k, (zk, &dt)) in z.chunks_exact(M).zip(dts).enumerate() {
            let measured = !zk.iter().all(|v| v.is_nan());
            let rk = rs.map(|r| &r[k * M * M..(k + 1) * M * M]);
            let r = (if k % BATCH_TICK == 0 { tick(k) } else { Ok(()) })
                .and_then(|()| self.predict(dt))
                .and_then(|()| self.update(measured.then_some(zk), rk));
            match r {
                Ok(t) => {
                    out.means.extend_from_slice(self.est.x.as_slice());
                    out.covs
                        .extend_from_slice(self.est.p.transpose().as_slice());
                    out.sent.push(t.map_or(-1, i8::from));
                }
                Err(e) => {
                    (self.est, self.info, self.cif_prior, self.trigger_state) = saved;
                    return Err((k, e));
                }
            }
        }
        Ok(())
    }
}

impl<const N: usize, const M: usize> Single<N, M> {
    /// [`FilterDyn::batch`] of the covariance-form filters: the core's chained
    /// local step (`cov_local_chained`, the same numbers as `predict; update`
    /// with the estimate checked once), committed only after the last step.
    fn batch_cov(
        &mut self,
        f: &LocalFilter<f64>,
        z: &[f64],
        dts: &[f64],
        rs: Option<&[f64]>,
        out: &mut Batch,
        tick: &mut dyn FnMut(usize) -> PyResult<()>,
    ) -> Result<(), (usize, PyErr)> {
        let r = self.batch_cov_steps(f, z, dts, rs, out, tick);
        self.sensor.r_override = None;
        r
    }

    /// The steps of [`batch_cov`](Self::batch_cov), which clears the `R`
    /// override after them, on success and on error alike.
    fn batch_cov_steps(
        &mut self,
        f: &LocalFilter<f64>,
        z: &[f64],
        dts: &[f64],
        rs: Option<&[f64]>,
        out: &mut Batch,
        tick: &mut dyn FnMut(usize) -> PyResult<()>,
    ) -> Result<(), (usize, PyErr)> {
        let mut est = CheckedGaussian::new(&self.est).map_err(|e| (0, core_err(&e)))?;
        let mut ts = self.trigger_state;
        for (k, (zk, &dt)) in z.chunks_exact(M).zip(dts).enumerate() {
            if k % BATCH_TICK == 0 {
                tick(k).map_err(|e| (k, e))?;
            }
            if let Some(rs) = rs {
                let r = SMatrix::<f64, M, M>::from_row_slice(&rs[k * M * M..(k + 1) * M * M]);
                edccif_core::linalg::validate_covariance(&r, "measurement noise R")
                    .map_err(|e| (k, core_err(&e)))?;
                self.sensor.r_override = Some(r);
            }
            let c = &self.cfg;
            let obs = match zk.iter().all(|v| v.is_nan()) {
                true => Observation::Missing,
                false => Observation::Measured(SVector::from_column_slice(zk)),
            };
            let r = cov_local_chained(
                f,
                &self.motion,
                dt,
                &self.sensor,
                &est,
                &obs,
                &c.trigger,
                &ts,
                &c.et,
            );
            let (step, next) = self.finish(r).map_err(|e| (k, e))?;
            out.means.extend_from_slice(step.posterior.x.as_slice());
            out.covs
                .extend_from_slice(step.posterior.p.transpose().as_slice());
            out.sent.push(step.triggered.map_or(-1, i8::from));
            est = next;
            ts = step.trigger_state;
        }
        self.est = *est.gaussian();
        self.trigger_state = ts;
        self.cif_prior = None;
        Ok(())
    }
}

/// `a` with its `writeable` flag cleared: the filters' `x`, `P`, `y`, `Y`
/// are copies, so writing into them would change nothing.
fn read_only(a: Arr<'_>) -> PyResult<Arr<'_>> {
    a.getattr("flags")?.setattr("writeable", false)?;
    Ok(a)
}

/// Base of the single filters: `predict(dt=None)`, `update(z, R=None)`, `x`,
/// `P`.
#[pyclass(name = "SingleFilter", module = "edccif", subclass)]
pub struct PySingleFilter {
    inner: Box<dyn FilterDyn>,
    dt: Option<f64>,
    triggered: Option<bool>,
    /// The trigger's decisions in the last `batch_filter` (1, 0, -1).
    batch_sent: Vec<i8>,
    name: &'static str,
}

/// An edccif error raised at step `k` of a batch: the same type, the message
/// prefixed with `step k:`, the same `__cause__` (a model callable's exception).
/// Any other exception passes unchanged.
fn at_step(py: Python<'_>, k: usize, e: PyErr) -> PyErr {
    if !e.is_instance_of::<EdccifError>(py) {
        return e;
    }
    let err = PyErr::from_type(e.get_type(py), format!("step {k}: {}", e.value(py)));
    err.set_cause(py, e.cause(py));
    err
}

/// Refuses a `batch_filter` of `rows` steps whose outputs (means, covariances
/// and the copies of the inputs) do not fit in the memory available.
fn check_batch_size(rows: usize, n: usize, m: usize) -> PyResult<()> {
    use edccif_sim::limits::{check_memory, product};
    check_memory(
        || format!("batch_filter of rows = {rows} (means rows × {n}, covariances rows × {n} × {n}, inputs rows × {m})"),
        product(&[rows, n + n * n + 2 * m + m * m + 2, 8]),
    )
    .py()
}

/// [`edccif_sim::timestep::check_dt`] as a Python `ParameterError`.
fn check_dt(dt: f64, what: impl std::fmt::Display) -> PyResult<()> {
    edccif_sim::timestep::check_dt(dt, what).py()
}

/// `batch_filter`'s `Rs`: one `(m, m)` for every step or `(T, m, m)`, finite,
/// as `T` row-major `(m, m)` blocks (each step's positive definiteness is
/// checked at its step, with the step's index in the error).
fn batch_noise(r: &Bound<'_, PyAny>, steps: usize, m: usize) -> PyResult<Vec<f64>> {
    let py = r.py();
    match finite_array(r, "Rs", &[Dim::Is(m), Dim::Is(m)]) {
        Ok((one, _)) => return Ok(one.repeat(steps)),
        Err(e) if !e.is_instance_of::<ShapeError>(py) => return Err(e),
        Err(_) => {}
    }
    finite_array(r, "Rs", &[Dim::Is(steps), Dim::Is(m), Dim::Is(m)])
        .map(|(v, _)| v)
        .map_err(|e| match e.is_instance_of::<ShapeError>(py) {
            true => ShapeError::new_err(format!(
                "{} (Rs is one ({m}, {m}) noise covariance for every step or ({steps}, {m}, {m}), one per step)",
                e.value(py)
            )),
            false => e,
        })
}

impl PySingleFilter {
    fn build(
        name: &'static str,
        motion: &PyMotionModel,
        sensor: &PyMeasurementModel,
        x0: &Bound<'_, PyAny>,
        p0: &Bound<'_, PyAny>,
        dt: Option<f64>,
        cfg: Config,
    ) -> PyResult<Self> {
        let n = motion.spec.n();
        let m = sensor.spec.m();
        sensor.spec.check_state_dim(n, "sensor")?;
        if let Some(d) = dt {
            check_dt(d, "dt")?;
        }
        let (x, _) = finite_array(x0, "x0", &[Dim::Is(n)])?;
        let (p, _) = finite_array(p0, "P0", &[Dim::Is(n), Dim::Is(n)])?;
        cfg.trigger.validate().py()?;
        cfg.et.validate().py()?;
        let inner: Box<dyn FilterDyn> = with_dims!(n, m, |N, M| {
            Ok(Box::new(Single::<N, M>::new(motion, sensor, cfg, &x, &p)?) as Box<dyn FilterDyn>)
        })?;
        Ok(Self {
            inner,
            dt,
            triggered: None,
            batch_sent: Vec::new(),
            name,
        })
    }

    fn info_arrays<'py>(&self, py: Python<'py>) -> PyResult<(Arr<'py>, Arr<'py>)> {
        let n = self.inner.n();
        let (y, ym) = self.inner.info();
        Ok((
            read_only(to_numpy(py, y, &[n])?)?,
            read_only(to_numpy(py, ym, &[n, n])?)?,
        ))
    }
}

#[pymethods]
impl PySingleFilter {
    /// Prediction over `dt` (default: the constructor's `dt`); `x`, `P` become
    /// the prior.
    #[pyo3(signature = (dt = None))]
    fn predict(
        &mut self,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
    ) -> PyResult<()> {
        let dt = match dt.or(self.dt) {
            Some(d) => d,
            None => {
                return Err(ParameterError::new_err(
                    "dt: no time step; pass predict(dt=...) or dt= to the constructor",
                ))
            }
        };
        check_dt(dt, "dt")?;
        self.inner.predict(dt)
    }

    /// Update with measurement `z` (m,) (`None`: no measurement this step), with
    /// `R` (m, m) instead of the sensor's noise for this call only.
    #[pyo3(signature = (z, R = None))]
    #[allow(non_snake_case)]
    fn update(
        &mut self,
        z: Option<&Bound<'_, PyAny>>,
        R: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        self.update_inner(z, R).map(|_| ())
    }

    /// Runs `predict(dt); update(z)` for every row of `zs` in one call, the
    /// same numbers as that loop in Python without its per-call cost.
    ///
    /// `zs` is `(T, m)` (a row of NaN: no measurement that step, as
    /// `update(None)`); `dt` a float or `(T,)` of time steps (default: the
    /// constructor's `dt`); `Rs` an `(m, m)` noise covariance for every step or
    /// `(T, m, m)`, one per step, in place of the sensor's `R` (as
    /// `update(z, R)`; default: the sensor's). Returns the posteriors' means `(T, n)` and
    /// covariances `(T, n, n)`; the filter ends at the last posterior. On an
    /// error at step `k` (the message starts with `step k:`) the filter is left
    /// as it was before the call.
    ///
    /// What it returns is checked against the memory available first
    /// (`SizeError`). Ctrl-C stops it within 1024 steps with
    /// `KeyboardInterrupt`, the filter left as it was before the call;
    /// `progress` (True: a bar or a line every few seconds on stderr; a
    /// callable: `progress(done, total)` in steps) reports it. The GIL is
    /// held (the models may be Python callables).
    #[pyo3(signature = (zs, dt = None, Rs = None, *, progress = None))]
    #[allow(non_snake_case)]
    fn batch_filter<'py>(
        &mut self,
        py: Python<'py>,
        zs: &Bound<'py, PyAny>,
        dt: Option<&Bound<'py, PyAny>>,
        Rs: Option<&Bound<'py, PyAny>>,
        progress: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(Arr<'py>, Arr<'py>)> {
        let progress = crate::drive::Progress::from_arg(progress, "batch_filter", "steps")?;
        let (n, m) = (self.inner.n(), self.inner.m());
        if let Ok(shape) = zs.getattr("shape").and_then(|s| s.extract::<Vec<usize>>()) {
            // An array's rows are known before it is copied: refuse early.
            if let Some(&rows) = shape.first() {
                check_batch_size(rows, n, m)?;
            }
        }
        let (z, shape) = f64_array(zs, "zs", &[Dim::Any("T"), Dim::Is(m)])?;
        let steps = shape[0];
        check_batch_size(steps, n, m)?;
        let dts: Vec<f64> =
            match dt.filter(|o| !o.is_none()) {
                Some(d) => match d.extract::<f64>() {
                    Ok(v) => vec![v; steps],
                    Err(_) => f64_array(d, "dt", &[Dim::Is(steps)])?.0,
                },
                None => match self.dt {
                    Some(v) => vec![v; steps],
                    None => return Err(ParameterError::new_err(
                        "dt: no time step; pass batch_filter(zs, dt=...) or dt= to the constructor",
                    )),
                },
            };
        for (k, &d) in dts.iter().enumerate() {
            check_dt(d, format_args!("dt[{k}]"))?;
        }
        let rs = match Rs.filter(|o| !o.is_none()) {
            None => None,
            Some(r) => Some(batch_noise(r, steps, m)?),
        };
        let mut out = Batch {
            means: Vec::with_capacity(steps * n),
            covs: Vec::with_capacity(steps * n * n),
            sent: Vec::with_capacity(steps),
        };
        let mut tick = |k: usize| -> PyResult<()> {
            py.check_signals()?;
            progress.report_now(py, k as u64, steps as u64)
        };
        let r = self
            .inner
            .batch(&z, &dts, rs.as_deref(), &mut out, &mut tick);
        if let Err((k, e)) = r {
            progress.close(py);
            return Err(at_step(py, k, e));
        }
        progress.report_now(py, steps as u64, steps as u64)?;
        progress.close(py);
        self.triggered = out.sent.last().and_then(|&s| (s >= 0).then_some(s == 1));
        self.batch_sent = out.sent;
        Ok((
            to_numpy(py, out.means, &[steps, n])?,
            to_numpy(py, out.covs, &[steps, n, n])?,
        ))
    }

    /// State estimate `x` (n,): a read-only copy (`kf.x[0] = 1` raises
    /// `ValueError: assignment destination is read-only`). Assign a whole
    /// array instead, `kf.x = x_new`, which validates the shape and
    /// finiteness.
    #[getter]
    fn x<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        read_only(to_numpy(py, self.inner.x(), &[self.inner.n()])?)
    }

    #[setter]
    fn set_x(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let (v, _) = finite_array(value, "x", &[Dim::Is(self.inner.n())])?;
        self.inner.set(Some(&v), None)
    }

    /// Covariance `P` (n, n): a read-only copy (`kf.P[0, 0] = 9` raises).
    /// Assign a whole matrix instead, `kf.P = P_new`, which validates shape,
    /// finiteness, symmetry and positive definiteness.
    #[getter(P)]
    fn p<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let n = self.inner.n();
        read_only(to_numpy(py, self.inner.p(), &[n, n])?)
    }

    #[setter(P)]
    fn set_p(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = self.inner.n();
        let (v, _) = finite_array(value, "P", &[Dim::Is(n), Dim::Is(n)])?;
        self.inner.set(None, Some(&v))
    }

    /// State dimension n.
    #[getter]
    fn dim_x(&self) -> usize {
        self.inner.n()
    }

    /// Measurement dimension m.
    #[getter]
    fn dim_z(&self) -> usize {
        self.inner.m()
    }

    /// The default time step of `predict` (`None`: none).
    #[getter]
    fn dt(&self) -> Option<f64> {
        self.dt
    }

    fn __repr__(&self) -> String {
        format!(
            "{}(dim_x={}, dim_z={}, dt={:?})",
            self.name,
            self.inner.n(),
            self.inner.m(),
            self.dt
        )
    }
}

impl PySingleFilter {
    fn update_inner(
        &mut self,
        z: Option<&Bound<'_, PyAny>>,
        r: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Option<bool>> {
        let m = self.inner.m();
        let z = z
            .filter(|o| !o.is_none())
            .map(|o| finite_array(o, "z", &[Dim::Is(m)]))
            .transpose()?;
        let r = r
            .filter(|o| !o.is_none())
            .map(|o| finite_array(o, "R", &[Dim::Is(m), Dim::Is(m)]))
            .transpose()?;
        let t = self.inner.update(
            z.as_ref().map(|v| v.0.as_slice()),
            r.as_ref().map(|v| v.0.as_slice()),
        )?;
        self.triggered = t;
        Ok(t)
    }
}

fn base_cfg(kind: Kind) -> Config {
    Config {
        kind,
        trigger: Trigger::Always,
        et: EtOptions::default(),
        seed: None,
    }
}

/// Cubature Kalman filter (third-degree spherical-radial rule, points redrawn at
/// the prior for the update).
#[pyclass(name = "CKF", module = "edccif", extends = PySingleFilter)]
pub struct PyCkf;

#[pymethods]
impl PyCkf {
    #[new]
    #[pyo3(signature = (motion, sensor, x0, P0, dt = None))]
    #[allow(non_snake_case)]
    fn new(
        #[pyo3(from_py_with = crate::class_args::motion)] motion: PyRef<'_, PyMotionModel>,
        #[pyo3(from_py_with = crate::class_args::sensor)] sensor: PyRef<'_, PyMeasurementModel>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
    ) -> PyResult<(Self, PySingleFilter)> {
        let cfg = base_cfg(Kind::Cov(LocalFilter::Ckf));
        Ok((
            Self,
            PySingleFilter::build("CKF", &motion, &sensor, x0, P0, dt, cfg)?,
        ))
    }
}

/// Extended Kalman filter with the models' Jacobians.
#[pyclass(name = "EKF", module = "edccif", extends = PySingleFilter)]
pub struct PyEkf;

#[pymethods]
impl PyEkf {
    #[new]
    #[pyo3(signature = (motion, sensor, x0, P0, dt = None))]
    #[allow(non_snake_case)]
    fn new(
        #[pyo3(from_py_with = crate::class_args::motion)] motion: PyRef<'_, PyMotionModel>,
        #[pyo3(from_py_with = crate::class_args::sensor)] sensor: PyRef<'_, PyMeasurementModel>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
    ) -> PyResult<(Self, PySingleFilter)> {
        let cfg = base_cfg(Kind::Cov(LocalFilter::Ekf));
        Ok((
            Self,
            PySingleFilter::build("EKF", &motion, &sensor, x0, P0, dt, cfg)?,
        ))
    }
}

/// Unscented Kalman filter with scaling `(alpha, beta, kappa)` (2n+1 points).
#[pyclass(name = "UKF", module = "edccif", extends = PySingleFilter)]
pub struct PyUkf;

#[pymethods]
impl PyUkf {
    #[new]
    #[pyo3(signature = (motion, sensor, x0, P0, dt = None, alpha = 1.0, beta = 2.0, kappa = 0.0))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        #[pyo3(from_py_with = crate::class_args::motion)] motion: PyRef<'_, PyMotionModel>,
        #[pyo3(from_py_with = crate::class_args::sensor)] sensor: PyRef<'_, PyMeasurementModel>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
        #[pyo3(from_py_with = crate::args::real_arg::alpha)] alpha: f64,
        #[pyo3(from_py_with = crate::args::real_arg::beta)] beta: f64,
        #[pyo3(from_py_with = crate::args::real_arg::kappa)] kappa: f64,
    ) -> PyResult<(Self, PySingleFilter)> {
        edccif_core::SigmaRule::unscented(motion.spec.n(), alpha, beta, kappa).py()?;
        let cfg = base_cfg(Kind::Cov(LocalFilter::Ukf { alpha, beta, kappa }));
        Ok((
            Self,
            PySingleFilter::build("UKF", &motion, &sensor, x0, P0, dt, cfg)?,
        ))
    }
}

/// Cubature information filter: the estimate is also kept as the information
/// pair `y = P⁻¹x`, `Y = P⁻¹`.
#[pyclass(name = "CIF", module = "edccif", extends = PySingleFilter)]
pub struct PyCif;

#[pymethods]
impl PyCif {
    #[new]
    #[pyo3(signature = (motion, sensor, x0, P0, dt = None))]
    #[allow(non_snake_case)]
    fn new(
        #[pyo3(from_py_with = crate::class_args::motion)] motion: PyRef<'_, PyMotionModel>,
        #[pyo3(from_py_with = crate::class_args::sensor)] sensor: PyRef<'_, PyMeasurementModel>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
    ) -> PyResult<(Self, PySingleFilter)> {
        let cfg = base_cfg(Kind::Cif);
        Ok((
            Self,
            PySingleFilter::build("CIF", &motion, &sensor, x0, P0, dt, cfg)?,
        ))
    }

    /// Information vector `y = P⁻¹x` (n,).
    #[getter]
    fn y<'py>(slf: PyRef<'py, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        Ok(slf.as_super().info_arrays(py)?.0)
    }

    /// Information matrix `Y = P⁻¹` (n, n).
    #[getter(Y)]
    fn ymat<'py>(slf: PyRef<'py, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        Ok(slf.as_super().info_arrays(py)?.1)
    }
}

fn parse_policy(s: &str) -> PyResult<EtPolicy> {
    match s {
        "optimal" => Ok(EtPolicy::Optimal),
        "hold" => Ok(EtPolicy::Hold),
        "skip" => Ok(EtPolicy::Skip),
        _ => Err(crate::errors::UnknownOptionError::new_err(format!(
            "et_policy={s:?}; expected one of optimal, hold, skip"
        ))),
    }
}

/// Event-triggered cubature information filter: the sensor's trigger decides
/// whether `z` is used; an untriggered step uses the error-minimised gain with
/// the last sent measurement (the paper's local filter). `update` returns whether
/// the measurement was sent (`None` without a measurement).
#[pyclass(name = "ETCIF", module = "edccif", extends = PySingleFilter)]
pub struct PyEtCif;

#[pymethods]
impl PyEtCif {
    #[new]
    #[pyo3(signature = (motion, sensor, x0, P0, dt = None, trigger = "sod", delta = None,
                        sigma1 = 5e-4, sigma2 = 5e-4, et_policy = None, gate = None, trigger_seed = None,
                        untriggered_closed_form = true, normalised = false))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        #[pyo3(from_py_with = crate::class_args::motion)] motion: PyRef<'_, PyMotionModel>,
        #[pyo3(from_py_with = crate::class_args::sensor)] sensor: PyRef<'_, PyMeasurementModel>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::dt)] dt: Option<f64>,
        #[pyo3(from_py_with = crate::args::name_arg::trigger)] trigger: &'static str,
        #[pyo3(from_py_with = crate::args::opt_real_arg::delta)] delta: Option<f64>,
        #[pyo3(from_py_with = crate::args::real_arg::sigma1)] sigma1: f64,
        #[pyo3(from_py_with = crate::args::real_arg::sigma2)] sigma2: f64,
        #[pyo3(from_py_with = crate::args::opt_text_arg::et_policy)] et_policy: Option<String>,
        #[pyo3(from_py_with = crate::args::opt_real_arg::gate)] gate: Option<f64>,
        trigger_seed: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::args::flag_arg::untriggered_closed_form)]
        untriggered_closed_form: bool,
        #[pyo3(from_py_with = crate::args::flag_arg::normalised)] normalised: bool,
    ) -> PyResult<(Self, PySingleFilter)> {
        let trigger_seed = trigger_seed
            .filter(|s| !s.is_none())
            .map(|s| crate::args::u64_arg(s, "trigger_seed"))
            .transpose()?;
        for (name, v) in [
            ("delta", delta),
            ("sigma1", Some(sigma1)),
            ("sigma2", Some(sigma2)),
            ("gate", gate),
        ] {
            if let Some(x) = v {
                if !(x.is_finite() && x > 0.0) {
                    return Err(ParameterError::new_err(format!(
                        "{name}: expected a finite number > 0, got {x}"
                    )));
                }
            }
        }
        let kind = trigger.parse::<edccif_sim::TriggerKind>().py()?;
        let sc = edccif_sim::Scenario::paper(1);
        let delta = delta.unwrap_or_else(|| {
            if normalised {
                kind.default_delta_for(edccif_sim::DEFAULT_NORMALISED_DELTA)
            } else {
                kind.default_delta(&sc)
            }
        });
        let (t, implied) = kind.trigger(delta, &sc);
        let t = if normalised { t.normalised() } else { t };
        let policy = match et_policy {
            Some(p) => parse_policy(&p)?,
            None => EtPolicy::default(),
        };
        let cfg = Config {
            kind: Kind::Cif,
            trigger: t,
            et: EtOptions {
                policy: implied.unwrap_or(policy),
                sigma1,
                sigma2,
                gate,
                untriggered_closed_form,
            },
            seed: trigger_seed,
        };
        Ok((
            Self,
            PySingleFilter::build("ETCIF", &motion, &sensor, x0, P0, dt, cfg)?,
        ))
    }

    /// Update with measurement `z` (m,) through the trigger; returns `True` when
    /// it was sent, `False` when the untriggered step ran, `None` without `z`.
    #[pyo3(signature = (z, R = None))]
    #[allow(non_snake_case)]
    fn update(
        mut slf: PyRefMut<'_, Self>,
        z: Option<&Bound<'_, PyAny>>,
        R: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Option<bool>> {
        slf.as_super().update_inner(z, R)
    }

    /// Whether the last update's measurement was sent (`None`: no measurement).
    #[getter]
    fn triggered(slf: PyRef<'_, Self>) -> Option<bool> {
        slf.as_super().triggered
    }

    /// The trigger's decision at every step of the last `batch_filter` (T,)
    /// int8: 1 sent, 0 not sent (the untriggered step ran), -1 no measurement;
    /// empty before the first call.
    #[getter]
    fn batch_sent<'py>(slf: PyRef<'py, Self>, py: Python<'py>) -> Bound<'py, PyArray1<i8>> {
        PyArray1::from_slice(py, &slf.as_super().batch_sent)
    }

    /// Information vector `y = P⁻¹x` (n,).
    #[getter]
    fn y<'py>(slf: PyRef<'py, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        Ok(slf.as_super().info_arrays(py)?.0)
    }

    /// Information matrix `Y = P⁻¹` (n, n).
    #[getter(Y)]
    fn ymat<'py>(slf: PyRef<'py, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        Ok(slf.as_super().info_arrays(py)?.1)
    }
}
