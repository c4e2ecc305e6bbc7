//! The covariance-form local step of one node (CKF, EKF, UKF: the consensus
//! baselines, `docs/algorithm.md` §5): prediction ([`cov_predict`]), then the
//! trigger decision and the update ([`cov_update`]); the estimate a filter loop
//! feeds back is a [`CheckedGaussian`].

use nalgebra::{Cholesky, Const, RealField, SMatrix, SVector};

use crate::error::{let_ok, Result};
use crate::linalg::{
    c, check_finite, check_positive_definite, check_positive_definite_mirrored, cholesky,
    cholesky_lower, cholesky_mirrored, solve_rows, sym, sym_downdate, sym_sum, validate_positive,
};
use crate::message::{Gaussian, Observation};
use crate::model::{MeasurementModel, MotionModel};
use crate::sigma::{
    sigma_measure, sigma_measure_mean, sigma_predict_checked, MeasurementStats, SigmaRule,
};
use crate::trigger::{Trigger, TriggerState};

use super::decision::{decide_measurement, EtStep, MeasurementAction, StatsStore};
use super::gain::{EtGain, EtOptions};

/// The covariance-form local filters of the consensus baselines.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum LocalFilter<T> {
    /// Cubature Kalman filter (ET-CKF when triggered).
    Ckf,
    /// Extended Kalman filter with the models' Jacobians.
    Ekf,
    /// Unscented Kalman filter with scaling `(α, β, κ)`.
    Ukf {
        /// Spread `α`.
        alpha: T,
        /// Prior-knowledge weight `β`.
        beta: T,
        /// Secondary scaling `κ`.
        kappa: T,
    },
}

impl<T: RealField + Copy> LocalFilter<T> {
    /// The UKF with the table's `(α, β, κ) = (1, 2, 0)`.
    pub fn ukf_default() -> Self {
        LocalFilter::Ukf {
            alpha: T::one(),
            beta: c(2.0),
            kappa: T::zero(),
        }
    }
}

/// The result of one node's covariance-form local step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CovLocal<T: RealField + Copy, const N: usize, const M: usize> {
    /// Local posterior.
    pub posterior: Gaussian<T, N>,
    /// `Some(γ)` when a measurement was taken, `None` when it was missing.
    pub triggered: Option<bool>,
    /// The trigger state after this step.
    pub trigger_state: TriggerState<T, M>,
    /// The innovation gate rejected this step's triggered measurement (the
    /// posterior is the prior; the trigger state is left as it was).
    pub gated: bool,
}

impl<T: RealField + Copy, const N: usize, const M: usize> CovLocal<T, N, M> {
    /// A zero step for [`update`] to write.
    #[inline(always)]
    fn empty() -> Self {
        Self {
            posterior: Gaussian {
                x: SVector::zeros(),
                p: SMatrix::zeros(),
            },
            triggered: None,
            trigger_state: TriggerState {
                last_sent: None,
                eta: T::zero(),
                rng: 0,
            },
            gated: false,
        }
    }
}

/// An estimate known to pass the covariance-form step's input checks: `x`
/// finite, `P` finite and factorised by the step's Cholesky check (positive
/// definite). The fields are private, so the only ways to get one are
/// [`CheckedGaussian::new`], which makes those checks, and
/// [`cov_local_chained`], whose posterior has passed them (the step factorises
/// its posterior anyway). A filter loop that feeds each posterior back as the
/// next estimate therefore validates its input once, at the start, instead of
/// factorising `P` twice per step.
///
/// ```
/// use edccif_core::{CheckedGaussian, Error, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let g = Gaussian { x: Vector2::new(1.0, 2.0), p: Matrix2::identity() };
/// let checked = CheckedGaussian::new(&g)?;
/// assert_eq!(checked.gaussian(), &g);
/// let bad = Gaussian { x: g.x, p: Matrix2::new(1.0, 2.0, 2.0, 1.0) };
/// assert_eq!(CheckedGaussian::new(&bad).unwrap_err(), Error::NotPositiveDefinite { what: "covariance P" });
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckedGaussian<T: RealField + Copy, const N: usize> {
    g: Gaussian<T, N>,
}

impl<T: RealField + Copy, const N: usize> CheckedGaussian<T, N> {
    /// Checks `g` as [`cov_predict`] checks its estimate: [`Error::NonFinite`]
    /// naming `"state estimate x"` when `x` is not finite, and the errors of
    /// [`cholesky`] naming `"covariance P"`
    /// ([`Error::NonFinite`], [`Error::NotPositiveDefinite`]) for `P`. Like the
    /// step, it reads `P`'s lower triangle for the factorisation (symmetry is
    /// [`Gaussian::new`]'s check).
    ///
    /// [`Error::NonFinite`]: crate::Error::NonFinite
    /// [`Error::NotPositiveDefinite`]: crate::Error::NotPositiveDefinite
    ///
    /// ```
    /// use edccif_core::{CheckedGaussian, Error, Gaussian};
    /// use nalgebra::{Matrix2, Vector2};
    /// let g = Gaussian { x: Vector2::new(f64::NAN, 0.0), p: Matrix2::identity() };
    /// assert_eq!(CheckedGaussian::new(&g).unwrap_err(), Error::NonFinite { what: "state estimate x" });
    /// ```
    pub fn new(g: &Gaussian<T, N>) -> Result<Self> {
        check_finite(&g.x, "state estimate x")?;
        check_positive_definite(&g.p, "covariance P")?;
        Ok(Self { g: *g })
    }

    /// The estimate.
    ///
    /// ```
    /// use edccif_core::{CheckedGaussian, Gaussian};
    /// use nalgebra::{Matrix1, Vector1};
    /// let g = Gaussian { x: Vector1::new(3.0), p: Matrix1::new(2.0) };
    /// assert_eq!(CheckedGaussian::new(&g)?.gaussian().x[0], 3.0);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn gaussian(&self) -> &Gaussian<T, N> {
        &self.g
    }
}

/// Kalman update from innovation statistics: `K = Pxz Pzz⁻¹`, `x̂ = x̂⁻ + K Δz`,
/// `P = sym(P⁻ − K Pxzᵀ)`.
pub fn kalman_update<T: RealField + Copy, const N: usize, const M: usize>(
    x_prior: &SVector<T, N>,
    p_prior: &SMatrix<T, N, N>,
    pxz: &SMatrix<T, N, M>,
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
) -> Result<Gaussian<T, N>> {
    let mut g = Gaussian {
        x: SVector::zeros(),
        p: SMatrix::zeros(),
    };
    kalman_update_into(x_prior, p_prior, pxz, pzz, dz, &mut g)?;
    check_finite(&g.x, "posterior state x")?;
    check_finite(&g.p, "posterior covariance P")?;
    Ok(g)
}

/// [`kalman_update`] written into `out` (on error `out` is unchanged), without
/// its final finiteness checks of the posterior, for a caller that makes them
/// next under the same names (`"posterior state x"`, and `"posterior
/// covariance P"` as the first thing [`cholesky`] does): the same result and
/// the same errors, each check made once.
#[inline(always)]
fn kalman_update_into<T: RealField + Copy, const N: usize, const M: usize>(
    x_prior: &SVector<T, N>,
    p_prior: &SMatrix<T, N, N>,
    pxz: &SMatrix<T, N, M>,
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
    out: &mut Gaussian<T, N>,
) -> Result<()> {
    check_finite(dz, "innovation Δz")?;
    let ch = cholesky(pzz, "innovation covariance Pzz")?;
    if M == 0 || M > 8 {
        // No measurement, or one long enough for nalgebra's unrolled dot
        // products: the general products.
        let k = ch.solve(&pxz.transpose()).transpose();
        out.x = x_prior + k * dz;
        out.p = sym(&(p_prior - k * pxz.transpose()));
        return Ok(());
    }
    // The same operations as `Cholesky::solve(Pxzᵀ)ᵀ`, `x̂⁻ + K Δz` and
    // `sym(P⁻ − K Pxzᵀ)` above, in the same order, so the same bits; written
    // column by column of `K` and of the result (contiguous, no transposes).
    let k = solve_rows(ch.l_dirty(), pxz);
    // x̂ = x̂⁻ + K Δz, K Δz summed over the columns of K in order.
    let mut kdz = k.column(0) * dz[0];
    for m in 1..M {
        kdz += k.column(m) * dz[m];
    }
    out.x = x_prior + kdz;
    out.p = sym_downdate(p_prior, &k, pxz, None);
    Ok(())
}

/// What a covariance-form step knows about the estimate it starts from.
#[derive(Clone, Copy)]
enum Start<'a, T: RealField + Copy, const N: usize> {
    /// Nothing: the EKF checks `x` and factorises `P` (the sigma-point filters
    /// factorise `P` for their points, which checks it).
    Unchecked(&'a Gaussian<T, N>),
    /// It passed the input checks (a [`CheckedGaussian`]): the EKF skips them.
    Checked(&'a Gaussian<T, N>),
    /// The lower Cholesky factor of `P` that [`cholesky`] gives (strict upper
    /// triangle zero), so `P` is finite and positive definite: the sigma-point
    /// filters take their points from it, the EKF does not factorise `P`
    /// (the same results and errors, see [`sigma_predict_checked`]).
    Factored(&'a Gaussian<T, N>, &'a SMatrix<T, N, N>),
}

/// The sigma-point rule of a covariance-form filter (the EKF's is unused).
fn cov_rule<T: RealField + Copy, const N: usize>(filter: &LocalFilter<T>) -> Result<SigmaRule<T>> {
    match *filter {
        LocalFilter::Ckf | LocalFilter::Ekf => Ok(SigmaRule::cubature(N)),
        LocalFilter::Ukf { alpha, beta, kappa } => SigmaRule::unscented(N, alpha, beta, kappa),
    }
}

/// The prediction of one node's covariance-form step (CKF, EKF or UKF) from
/// `estimate` over `dt`: the prior `(x̂⁻, P⁻)`.
///
/// [`cov_update`] completes the step; [`cov_local`] is the two in one call, bit
/// for bit.
///
/// ```
/// use edccif_core::{cov_predict, models::ConstantAcceleration, Gaussian, LocalFilter};
/// use nalgebra::{Matrix3, Vector3};
/// let ca = ConstantAcceleration::new(0.0)?; // 1-D: [x, vx, ax], no noise
/// let est = Gaussian::new(Vector3::new(0.0, 1.0, 2.0), Matrix3::identity())?;
/// for filter in [LocalFilter::Ckf, LocalFilter::Ekf, LocalFilter::ukf_default()] {
///     let prior = cov_predict(&filter, &ca, 1.0, &est)?;
///     assert!((prior.x - Vector3::new(2.0, 3.0, 2.0)).norm() < 1e-12);
/// }
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cov_predict<T, F, const N: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    estimate: &Gaussian<T, N>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    predict(filter, motion, dt, Start::Unchecked(estimate))
}

/// [`cov_predict`] from what is known about the estimate; the prior it returns
/// is finite (checked under the names [`cov_update`] checks a prior with).
#[inline(always)]
fn predict<T, F, const N: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    start: Start<'_, T, N>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    let (estimate, factor) = match start {
        Start::Unchecked(g) | Start::Checked(g) => (g, None),
        Start::Factored(g, l) => (g, Some(l)),
    };
    if !matches!(filter, LocalFilter::Ekf) {
        let rule = cov_rule::<T, N>(filter)?;
        let_ok!(
            (x, p) =
                sigma_predict_checked(&rule, motion, dt, &estimate.x, &estimate.p, factor, true)
        );
        return Ok(Gaussian { x: *x, p: *p });
    }
    match start {
        Start::Unchecked(g) => {
            check_finite(&g.x, "state estimate x")?;
            // The contract of the sigma-point filters: the estimate's
            // covariance must be positive definite (a hand-built Gaussian may
            // not be).
            check_positive_definite(&g.p, "covariance P")?;
        }
        // The factor proves `P` positive definite.
        Start::Factored(g, _) => check_finite(&g.x, "state estimate x")?,
        Start::Checked(_) => {}
    }
    validate_positive(dt, "time step dt", false)?;
    let (x, f) = motion.transition_with_jacobian(&estimate.x, dt);
    check_finite(&f, "motion Jacobian F")?;
    // `estimate.p` is finite (factorised), so the structural zeros a model
    // leaves out of `F P Fᵀ` change no bit.
    let p = sym_sum(
        &motion.jacobian_congruence(&f, &estimate.p),
        &motion.process_noise(dt),
    );
    check_finite(&x, "predicted state x⁻")?;
    check_finite(&p, "predicted covariance P⁻")?;
    Ok(Gaussian { x, p })
}

/// The measurement part of one node's covariance-form step (CKF, EKF or UKF) at
/// a prior from [`cov_predict`], with a trigger and an untriggered-step policy
/// (`Optimal` uses `M`, `P̄` with `G = ∂h/∂x(x̂⁻)`).
///
/// ```
/// use edccif_core::{cov_predict, cov_update, models::{RandomWalk, Position2}, *};
/// use nalgebra::{Matrix2, Vector2};
/// let rw = RandomWalk::new(0.1)?;
/// let cam = Position2::new([1.0, 1.0])?;
/// let est = Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::identity())?;
/// let prior = cov_predict(&LocalFilter::Ckf, &rw, 1.0, &est)?; // P⁻ = 1.1 I
/// let trig = Trigger::Always;
/// let step = cov_update(&LocalFilter::Ckf, &cam, &prior, &Observation::Measured(Vector2::new(2.1, 0.0)),
///                       &trig, &TriggerState::new(&trig), &EtOptions::default())?;
/// // Kalman gain 1.1 / 2.1 per axis
/// assert!((step.posterior.x - Vector2::new(1.1, 0.0)).norm() < 1e-12);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cov_update<T, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    sensor: &H,
    prior: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CovLocal<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    cov_rule::<T, N>(filter)?;
    check_finite(&prior.x, "predicted state x⁻")?;
    check_finite(&prior.p, "predicted covariance P⁻")?;
    let et = EtStep {
        trigger,
        state: trigger_state,
        opts,
    };
    let mut step = CovLocal::empty();
    update(
        filter,
        sensor,
        prior,
        obs,
        &et,
        check_positive_definite_mirrored,
        &mut step,
    )?;
    Ok(step)
}

/// [`cov_update`] at a finite prior (from [`predict`], or checked by
/// [`cov_update`]), written into `out` (on error `out` may hold part of the
/// step). `finish` is the posterior's definiteness check,
/// [`check_positive_definite_mirrored`] or, for a caller converting the
/// posterior to information form (the consensus rows), [`cholesky_mirrored`],
/// whose factor it returns with the step so that `P` is not factorised again.
#[inline(always)]
fn update<T, H, K, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    sensor: &H,
    prior: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    et: &EtStep<'_, T, M>,
    finish: impl FnOnce(&SMatrix<T, N, N>, &'static str) -> Result<K>,
    out: &mut CovLocal<T, N, M>,
) -> Result<K>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let rule = cov_rule::<T, N>(filter)?;
    let (x_prior, p_prior) = (&prior.x, &prior.p);
    // Innovation statistics at the prior: sigma points, or linearisation for the EKF.
    let stats = || -> Result<MeasurementStats<T, N, M>> {
        match filter {
            LocalFilter::Ekf => {
                let (z_hat, g) = sensor.measure_with_jacobian(x_prior);
                check_finite(&g, "measurement Jacobian G")?;
                // `P⁻` is finite, so the structural zeros a model leaves out
                // of `P⁻ Gᵀ` and `G P⁻ Gᵀ` change no bit.
                let (pxz, gpg) = sensor.jacobian_products(&g, p_prior);
                Ok(MeasurementStats {
                    z_hat,
                    pzz: sym_sum(&gpg, &sensor.noise()),
                    pxz,
                })
            }
            _ => {
                let l = cholesky_lower(p_prior, "predicted covariance P⁻")? * rule.scale;
                sigma_measure(&rule, sensor, x_prior, &l)
            }
        }
    };
    let z_mean = || -> Result<SVector<T, M>> {
        match filter {
            LocalFilter::Ekf => {
                let z = sensor.measure(x_prior);
                check_finite(&z, "predicted measurement ẑ")?;
                Ok(z)
            }
            _ => {
                let l = cholesky_lower(p_prior, "predicted covariance P⁻")? * rule.scale;
                sigma_measure_mean(&rule, sensor, x_prior, &l)
            }
        }
    };
    let mut store = StatsStore::new();
    let decision = decide_measurement(sensor, x_prior, obs, et, &mut store, stats, z_mean)?;
    out.triggered = decision.outcome.triggered;
    out.trigger_state = decision.outcome.trigger_state;
    out.gated = decision.outcome.gated;
    match decision.action {
        MeasurementAction::Nothing => out.posterior = *prior,
        MeasurementAction::Update(s, dz) => {
            // The posterior's finiteness is checked below under the names
            // `kalman_update` would check it with.
            kalman_update_into(x_prior, p_prior, &s.pxz, &s.pzz, dz, &mut out.posterior)?;
        }
        MeasurementAction::Optimal { g, dz_bar } => {
            // The posterior is `P̄` itself: the closed form of the information
            // filter's contribution does not apply here. The sensor's products
            // of `G` with the finite `P⁻`.
            let (r, delta) = et.trigger.untriggered_noise(&sensor.noise(), et.opts);
            let gain = EtGain::with_products(p_prior, g, &r, delta, et.opts, |g| {
                sensor.jacobian_products(g, p_prior)
            })?;
            out.posterior.x = x_prior + gain.m * dz_bar;
            out.posterior.p = gain.p_bar;
        }
    }
    // The update's `P⁻ − K Pxzᵀ` (and `P̄`) can lose definiteness by
    // cancellation when the inputs are badly scaled: never return such a
    // covariance.
    check_finite(&out.posterior.x, "posterior state x")?;
    // The posterior `P` is the finite prior, a `sym` or mirrored result, or the
    // finite `P̄`: its upper triangle has the finiteness of its lower one, so a
    // factorisation that succeeds proves it finite and the finiteness pass is
    // made only to name a failure (`finish` is one of the mirrored checks).
    finish(&out.posterior.p, "posterior covariance P")
}

/// One node's covariance-form local step (CKF, EKF or UKF) with a trigger and
/// an untriggered-step policy (`Optimal` uses `M`, `P̄` with `G = ∂h/∂x(x̂⁻)`):
/// [`cov_predict`] then [`cov_update`].
///
/// ```
/// use edccif_core::{cov_local, models::{RandomWalk, Position2}, *};
/// use nalgebra::{Matrix2, Vector2};
/// let (rw, cam) = (RandomWalk::new(0.1)?, Position2::new([1.0, 1.0])?);
/// let est = Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::identity())?;
/// let trig = Trigger::Always;
/// let step = cov_local(&LocalFilter::Ekf, &rw, 1.0, &cam, &est, &Observation::Measured(Vector2::new(2.1, 0.0)),
///                      &trig, &TriggerState::new(&trig), &EtOptions::default())?;
/// assert!((step.posterior.x - Vector2::new(1.1, 0.0)).norm() < 1e-12);
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn cov_local<T, F, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CovLocal<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let et = EtStep {
        trigger,
        state: trigger_state,
        opts,
    };
    let_ok!(prior = predict(filter, motion, dt, Start::Unchecked(estimate)));
    let mut step = CovLocal::empty();
    update(
        filter,
        sensor,
        prior,
        obs,
        &et,
        check_positive_definite_mirrored,
        &mut step,
    )?;
    Ok(step)
}

/// [`cov_local`] from an estimate known to pass its input checks (a
/// [`CheckedGaussian`], e.g. the previous step's posterior), returning the
/// posterior also as a [`CheckedGaussian`] for the next step: the filter loop
/// of a single node, with `P` factorised once per step (the posterior's
/// definiteness check) instead of twice. The same result, bit for bit, and the
/// same errors as [`cov_local`] on the same estimate; a failed step changes
/// nothing (the caller keeps its estimate and trigger state).
///
/// ```
/// use edccif_core::{cov_local, cov_local_chained, models::{RandomWalk, Position2}, *};
/// use nalgebra::{Matrix2, Vector2};
/// let (rw, cam) = (RandomWalk::new(0.1)?, Position2::new([1.0, 1.0])?);
/// let est = Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::identity())?;
/// let (trig, opts) = (Trigger::Always, EtOptions::default());
/// let mut state = (CheckedGaussian::new(&est)?, TriggerState::new(&trig));
/// for z in [Vector2::new(2.1, 0.0), Vector2::new(2.0, 0.1)] {
///     let obs = Observation::Measured(z);
///     let plain = cov_local(&LocalFilter::Ekf, &rw, 1.0, &cam, state.0.gaussian(), &obs,
///                           &trig, &state.1, &opts)?;
///     let (step, next) = cov_local_chained(&LocalFilter::Ekf, &rw, 1.0, &cam, &state.0, &obs,
///                                          &trig, &state.1, &opts)?;
///     assert_eq!(step, plain);
///     assert_eq!(next.gaussian(), &step.posterior);
///     state = (next, step.trigger_state);
/// }
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn cov_local_chained<T, F, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &CheckedGaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<(CovLocal<T, N, M>, CheckedGaussian<T, N>)>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let et = EtStep {
        trigger,
        state: trigger_state,
        opts,
    };
    let_ok!(prior = predict(filter, motion, dt, Start::Checked(&estimate.g)));
    let mut step = CovLocal::empty();
    update(
        filter,
        sensor,
        prior,
        obs,
        &et,
        check_positive_definite_mirrored,
        &mut step,
    )?;
    // The posterior passed the update's checks (`x` finite, `P` factorised):
    // those of `CheckedGaussian::new`.
    Ok((step, CheckedGaussian { g: step.posterior }))
}

/// [`cov_local`] from an estimate whose lower Cholesky factor `factor` the
/// caller has (see [`Start::Factored`]), also returning the Cholesky factor of
/// the posterior `P` that its definiteness check computed.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn cov_local_factored<T, F, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &Gaussian<T, N>,
    factor: Option<&SMatrix<T, N, N>>,
    obs: &Observation<T, M>,
    et: &EtStep<'_, T, M>,
) -> Result<(CovLocal<T, N, M>, Cholesky<T, Const<N>>)>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let start = match factor {
        Some(l) => Start::Factored(estimate, l),
        None => Start::Unchecked(estimate),
    };
    let_ok!(prior = predict(filter, motion, dt, start));
    let mut step = CovLocal::empty();
    let factor = update(filter, sensor, prior, obs, et, cholesky_mirrored, &mut step)?;
    Ok((step, factor))
}
