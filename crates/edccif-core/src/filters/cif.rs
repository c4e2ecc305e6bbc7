//! The ET-CIF local step of one node (`docs/algorithm.md` §3): cubature
//! prediction to the information prior ([`cif_predict`]), then the trigger
//! decision and the node's contribution ([`cif_update`]).

use nalgebra::{RealField, SMatrix, SVector};

use crate::error::{let_ok, Error, Result};
use crate::linalg::{all_finite, check_finite, cholesky, lower_inverse};
use crate::message::{Contribution, Gaussian, InfoPair, Observation};
use crate::model::{MeasurementModel, MotionModel};
use crate::sigma::{
    sigma_measure, sigma_measure_mean, sigma_measure_whitened, sigma_predict_checked, SigmaRule,
};
use crate::trigger::{Trigger, TriggerState};

use super::contributions::{contribution_whitened, optimal_contribution, triggered_contribution};
use super::decision::{decide_measurement, EtStep, MeasurementAction, StatsStore, TriggerOutcome};
use super::gain::EtOptions;

/// The result of one node's ET-CIF local step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CifLocal<T: RealField + Copy, const N: usize, const M: usize> {
    /// Predicted state `x̂⁻`.
    pub x_prior: SVector<T, N>,
    /// Predicted covariance `P⁻`.
    pub p_prior: SMatrix<T, N, N>,
    /// Information prior `(ŷ⁻, Y⁻)`.
    pub prior: InfoPair<T, N>,
    /// This node's contribution `(ī, Ī)`.
    pub contribution: Contribution<T, N>,
    /// `Some(γ)` when a measurement was taken, `None` when it was missing.
    pub triggered: Option<bool>,
    /// The trigger state after this step (commit it when the step is kept).
    pub trigger_state: TriggerState<T, M>,
    /// The innovation gate rejected this step's triggered measurement: the
    /// contribution is zero and the trigger state is left as it was (the step
    /// counts as missing; `triggered` stays `Some(true)` because it was sent).
    pub gated: bool,
}

impl<T: RealField + Copy, const N: usize, const M: usize> CifLocal<T, N, M> {
    /// The local-only posterior `(ŷ⁻ + ī, Y⁻ + Ī)` (ET-CIF alone).
    pub fn local_posterior(&self) -> InfoPair<T, N> {
        self.prior.updated(&self.contribution)
    }
}

/// The prior of an ET-CIF step: the predicted `(x̂⁻, P⁻)`, its information form
/// `(ŷ⁻, Y⁻) = (P⁻⁻¹ x̂⁻, P⁻⁻¹)` and the Cholesky factor of `P⁻` the update draws
/// its cubature points from. Made by [`cif_predict`], consumed by [`cif_update`].
///
/// ```
/// use edccif_core::{CifPrior, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let prior = CifPrior::new(&Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::identity() * 4.0)?)?;
/// assert_eq!(prior.info().ymat, Matrix2::identity() * 0.25);
/// assert_eq!(prior.x(), Vector2::new(1.0, 2.0));
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy)]
pub struct CifPrior<T: RealField + Copy, const N: usize> {
    x: SVector<T, N>,
    p: SMatrix<T, N, N>,
    info: InfoPair<T, N>,
    /// The lower Cholesky factor of `P⁻`.
    l: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> PartialEq for CifPrior<T, N> {
    /// Equal predicted state and covariance (the rest is derived from them).
    fn eq(&self, other: &Self) -> bool {
        self.x == other.x && self.p == other.p && self.info == other.info
    }
}

impl<T: RealField + Copy, const N: usize> CifPrior<T, N> {
    /// The prior of a predicted estimate (e.g. one kept between a predict and an
    /// update, or set by the user): fails when `P⁻` is not positive definite or
    /// its inverse not finite.
    ///
    /// ```
    /// use edccif_core::{CifPrior, Error, Gaussian};
    /// use nalgebra::{Matrix2, Vector2};
    /// let bad = Gaussian { x: Vector2::new(0.0, 0.0), p: Matrix2::new(1.0, 2.0, 2.0, 1.0) };
    /// assert_eq!(CifPrior::new(&bad).unwrap_err(), Error::NotPositiveDefinite { what: "predicted covariance P⁻" });
    /// ```
    pub fn new(prior: &Gaussian<T, N>) -> Result<Self> {
        check_finite(&prior.x, "predicted state x⁻")?;
        Self::from_predicted(&prior.x, &prior.p)
    }

    /// Information form of a predicted `(x̂⁻, P⁻)` whose `x̂⁻` is finite.
    fn from_predicted(x: &SVector<T, N>, p: &SMatrix<T, N, N>) -> Result<Self> {
        // `lower_inverse` reads only the lower triangle of the factor.
        let_ok!(ch = cholesky(p, "predicted covariance P⁻"));
        let y_prior = lower_inverse(ch.l_dirty());
        let info = InfoPair {
            y: y_prior * x,
            ymat: y_prior,
        };
        // `ŷ⁻` checked first: every entry of `Y⁻` enters `ŷ⁻ = Y⁻ x̂⁻` as a
        // factor of a product, a product with a NaN or ±∞ factor is NaN or
        // ±∞ (∞·0 is NaN), and so is any sum with such a term: a finite `ŷ⁻`
        // proves `Y⁻` finite. `Y⁻` is checked only when `ŷ⁻` fails, and
        // first: the error names `Y⁻` when it is not finite.
        if !all_finite(&info.y) {
            check_finite(&info.ymat, "information prior Y⁻")?;
            return Err(Error::NonFinite {
                what: "information prior ŷ⁻",
            });
        }
        Ok(Self {
            x: *x,
            p: *p,
            info,
            l: ch.l(),
        })
    }

    /// Predicted state `x̂⁻`.
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let prior = CifPrior::new(&Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?)?;
    /// assert_eq!(prior.x()[0], 3.0);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn x(&self) -> SVector<T, N> {
        self.x
    }
    /// Predicted covariance `P⁻`.
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let prior = CifPrior::new(&Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?)?;
    /// assert_eq!(prior.p()[0], 2.0);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn p(&self) -> SMatrix<T, N, N> {
        self.p
    }
    /// Information prior `(ŷ⁻, Y⁻)`.
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let prior = CifPrior::new(&Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?)?;
    /// let info = prior.info();
    /// assert!((info.y[0] - 1.5f64).abs() < 1e-15 && (info.ymat[0] - 0.5).abs() < 1e-15);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn info(&self) -> InfoPair<T, N> {
        self.info
    }
    /// `(x̂⁻, P⁻)` as a [`Gaussian`].
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let g = Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?;
    /// assert_eq!(CifPrior::new(&g)?.to_gaussian(), g);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn to_gaussian(&self) -> Gaussian<T, N> {
        Gaussian {
            x: self.x,
            p: self.p,
        }
    }
}

/// The prediction of one node's ET-CIF step (`docs/algorithm.md` §3, step 1 and the
/// information prior): cubature predict from `estimate` over `dt`.
///
/// [`cif_update`] completes the step; [`cif_local`] is the two in one call, bit
/// for bit.
///
/// ```
/// use edccif_core::{cif_predict, models::ConstantVelocity, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let cv = ConstantVelocity::new(0.01)?; // 1-D: [x, vx]
/// let prior = cif_predict(&cv, 0.5, &Gaussian::new(Vector2::new(0.0, 2.0), Matrix2::identity())?)?;
/// assert!((prior.x() - Vector2::new(1.0, 2.0)).norm() < 1e-12);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cif_predict<T, F, const N: usize>(
    motion: &F,
    dt: T,
    estimate: &Gaussian<T, N>,
) -> Result<CifPrior<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    cif_predict_factored(motion, dt, estimate, None)
}

/// [`cif_predict`] with the lower Cholesky factor of `estimate.p` when the
/// caller has it (see [`sigma_predict_checked`]): the same result and errors.
#[inline(always)]
pub(crate) fn cif_predict_factored<T, F, const N: usize>(
    motion: &F,
    dt: T,
    estimate: &Gaussian<T, N>,
    factor: Option<&SMatrix<T, N, N>>,
) -> Result<CifPrior<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    let rule = SigmaRule::cubature(N);
    // `P⁻` unchecked by the transform: `from_predicted` factorises it first,
    // and `cholesky` fails on a non-finite `P⁻` with the same error
    // (`NonFinite`, "predicted covariance P⁻").
    let_ok!(
        (x_prior, p_prior) =
            sigma_predict_checked(&rule, motion, dt, &estimate.x, &estimate.p, factor, false)
    );
    CifPrior::from_predicted(x_prior, p_prior)
}

/// The measurement part of one node's ET-CIF step (`docs/algorithm.md` §3, steps 2–5)
/// at a prior from [`cif_predict`]: trigger decision and contribution.
///
/// The inputs are not modified; the new trigger state is returned in the result.
///
/// ```
/// use edccif_core::{cif_predict, cif_update, models::{ConstantVelocity, Position2}, *};
/// use nalgebra::{Matrix4, Vector2, Vector4};
/// let cv = ConstantVelocity::new(0.01)?; // 2-D: [x, y, vx, vy]
/// let cam = Position2::new([0.1, 0.1])?;
/// let est = Gaussian::new(Vector4::new(0.0, 0.0, 1.0, 0.0), Matrix4::identity())?;
/// let prior = cif_predict(&cv, 0.1, &est)?;
/// let trig = Trigger::SendOnDelta { delta: 0.5 };
/// let step = cif_update(&cam, &prior, &Observation::Measured(Vector2::new(0.1, 0.0)), &trig,
///                       &TriggerState::new(&trig), &EtOptions::default())?;
/// assert_eq!(step.triggered, Some(true)); // the first measurement is always sent
/// assert_eq!(step.prior, prior.info());
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cif_update<T, H, const N: usize, const M: usize>(
    sensor: &H,
    prior: &CifPrior<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CifLocal<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let et = EtStep {
        trigger,
        state: trigger_state,
        opts,
    };
    let_ok!((contribution, outcome) = cif_update_internal(sensor, prior, obs, &et));
    Ok(CifLocal {
        x_prior: prior.x,
        p_prior: prior.p,
        prior: prior.info,
        contribution: *contribution,
        triggered: outcome.triggered,
        trigger_state: outcome.trigger_state,
        gated: outcome.gated,
    })
}

/// [`cif_update`]'s contribution and trigger outcome, the one definition
/// [`cif_update`] and the network's local phase share.
#[inline(always)]
pub(crate) fn cif_update_internal<T, H, const N: usize, const M: usize>(
    sensor: &H,
    prior: &CifPrior<T, N>,
    obs: &Observation<T, M>,
    et: &EtStep<'_, T, M>,
) -> Result<(Contribution<T, N>, TriggerOutcome<T, M>)>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let rule = SigmaRule::cubature(N);
    let x_prior = &prior.x;
    let l = prior.l * rule.scale;
    // Fast path (`fast_trig`): the statistics carry the whitened cross
    // covariance `A = L⁻¹ Pxz` in place of `Pxz` (only the contribution reads
    // it), and the contribution is taken from the factor `L` of `P⁻` without
    // `Y⁻` (see [`triggered_contribution_factored`](crate::triggered_contribution_factored)).
    let mut store = StatsStore::new();
    let decision = decide_measurement(
        sensor,
        x_prior,
        obs,
        et,
        &mut store,
        || match sensor.fast_trig() {
            true => sigma_measure_whitened(&rule, sensor, x_prior, &l),
            false => sigma_measure(&rule, sensor, x_prior, &l),
        },
        || sigma_measure_mean(&rule, sensor, x_prior, &l),
    )?;
    let contribution = match decision.action {
        MeasurementAction::Nothing => Contribution::zeros(),
        MeasurementAction::Update(stats, dz) if sensor.fast_trig() => {
            contribution_whitened(&prior.l, x_prior, &stats.pzz, stats.pxz, dz)?
        }
        MeasurementAction::Update(stats, dz) => {
            triggered_contribution(&prior.info.ymat, x_prior, stats, dz)?
        }
        MeasurementAction::Optimal { g, dz_bar } => {
            // `(R, δ)`, or for a normalised threshold `((1 + μ3δ/μ2) R, 0)`.
            let (r, delta) = et.trigger.untriggered_noise(&sensor.noise(), et.opts);
            optimal_contribution(
                x_prior,
                &prior.p,
                &prior.info.ymat,
                g,
                &r,
                delta,
                et.opts,
                dz_bar,
            )?
        }
    };
    Ok((contribution, decision.outcome))
}

/// One node's ET-CIF local step (`docs/algorithm.md` §3, steps 1–5): cubature predict from
/// the fused estimate over the time step `dt`, information prior, trigger decision
/// and contribution; [`cif_predict`] then [`cif_update`].
///
/// The inputs are not modified; the new trigger state is returned in the result.
///
/// ```
/// use edccif_core::*;
/// use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
/// use nalgebra::{SMatrix, SVector, Vector3};
/// let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
/// let s = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap();
/// let est = Gaussian::new(
///     SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]),
///     SMatrix::<f64, 7, 7>::identity() * 0.01,
/// ).unwrap();
/// let trig = Trigger::SendOnDelta { delta: 0.04 };
/// let ts = TriggerState::new(&trig);
/// let z = Observation::Measured(Vector3::new(5.0, 0.02, 3.1));
/// let out = cif_local(&ct, 0.1, &s, &est, &z, &trig, &ts, &EtOptions::default()).unwrap();
/// assert_eq!(out.triggered, Some(true));
/// let post = out.local_posterior().to_gaussian().unwrap();
/// assert!(post.p.trace() < out.p_prior.trace());
/// ```
#[allow(clippy::too_many_arguments)]
pub fn cif_local<T, F, H, const N: usize, const M: usize>(
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CifLocal<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let_ok!(prior = cif_predict(motion, dt, estimate));
    cif_update(sensor, prior, obs, trigger, trigger_state, opts)
}
