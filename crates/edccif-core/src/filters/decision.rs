//! The measurement part of a local step, decided once for the information and
//! the covariance filters: the trigger decision, the innovation gate, the
//! silent step of the triggers whose silence is a measurement, and the
//! untriggered-step policy (`docs/algorithm.md` §3 steps 4–5).

use nalgebra::{RealField, SMatrix, SVector};

use crate::angles::residual;
use crate::error::{Error, Result};
use crate::linalg::{check_finite, cholesky};
use crate::message::Observation;
use crate::model::MeasurementModel;
use crate::sigma::MeasurementStats;
use crate::silence::silent_measurement;
use crate::trigger::{Trigger, TriggerState};

use super::gain::{EtOptions, EtPolicy};

/// Normalised innovation squared `νᵀ Pzz⁻¹ ν`.
///
/// ```
/// use nalgebra::{Matrix2, Vector2};
/// let nis = edccif_core::normalised_innovation(&(Matrix2::<f64>::identity() * 4.0), &Vector2::new(2.0, 0.0)).unwrap();
/// assert!((nis - 1.0).abs() < 1e-12);
/// ```
pub fn normalised_innovation<T: RealField + Copy, const M: usize>(
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
) -> Result<T> {
    check_finite(dz, "innovation Δz")?;
    let nis = dz.dot(&cholesky(pzz, "innovation covariance Pzz")?.solve(dz));
    if nis.is_finite() {
        Ok(nis)
    } else {
        Err(Error::NonFinite {
            what: "normalised innovation",
        })
    }
}

/// Whether the gate rejects an innovation (`false` without a gate).
fn gate_rejects<T: RealField + Copy, const M: usize>(
    gate: Option<T>,
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
) -> Result<bool> {
    match gate {
        None => Ok(false),
        Some(g) => Ok(normalised_innovation(pzz, dz)? > g),
    }
}

/// The trigger inputs of one local step: the row's trigger, the sensor's
/// trigger memory before the step, and the untriggered-step options.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EtStep<'a, T: RealField + Copy, const M: usize> {
    pub(crate) trigger: &'a Trigger<T>,
    pub(crate) state: &'a TriggerState<T, M>,
    pub(crate) opts: &'a EtOptions<T>,
}

/// What the trigger did in a local step: the part of the step's result that
/// is not an estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TriggerOutcome<T: RealField + Copy, const M: usize> {
    /// `Some(γ)` when a measurement was taken, `None` when it was missing.
    pub(crate) triggered: Option<bool>,
    /// The trigger memory after the step.
    pub(crate) trigger_state: TriggerState<T, M>,
    /// The innovation gate rejected the triggered measurement.
    pub(crate) gated: bool,
}

/// What the measurement part of a local step does.
pub(super) enum MeasurementAction<T: RealField + Copy, const N: usize, const M: usize> {
    /// No measurement information: missing, gated, skipped, nothing sent yet, or
    /// a silent step that carries none.
    Nothing,
    /// A Kalman-type update with these innovation statistics and innovation
    /// (a triggered measurement, a silent step's pseudo-measurement, or the held
    /// `z_τ`).
    Update(MeasurementStats<T, N, M>, SVector<T, M>),
    /// The error-minimised gain of an untriggered step, at `G` with `Δz̄` (each
    /// filter computes its gain or closed form from these).
    Optimal {
        g: SMatrix<T, M, N>,
        dz_bar: SVector<T, M>,
    },
}

/// The trigger decision of a local step and what its measurement part does.
pub(super) struct MeasurementDecision<T: RealField + Copy, const N: usize, const M: usize> {
    pub(super) outcome: TriggerOutcome<T, M>,
    pub(super) action: MeasurementAction<T, N, M>,
}

/// The trigger decision, the innovation gate, the silent step and the
/// untriggered-step policy, shared by the information and the covariance
/// filters. `stats` computes the innovation statistics at the prior (sigma
/// points or linearisation), `z_mean` only the predicted measurement; each is
/// called at most once, and only when the decision needs it.
#[inline(always)]
pub(super) fn decide_measurement<T, H, const N: usize, const M: usize>(
    sensor: &H,
    x_prior: &SVector<T, N>,
    obs: &Observation<T, M>,
    et: &EtStep<'_, T, M>,
    stats: impl Fn() -> Result<MeasurementStats<T, N, M>>,
    z_mean: impl Fn() -> Result<SVector<T, M>>,
) -> Result<MeasurementDecision<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let (trigger, opts) = (et.trigger, et.opts);
    let Observation::Measured(z) = obs else {
        return Ok(MeasurementDecision {
            outcome: TriggerOutcome {
                triggered: None,
                trigger_state: *et.state,
                gated: false,
            },
            action: MeasurementAction::Nothing,
        });
    };
    check_finite(z, "measurement z")?;
    // The innovation trigger decides on the node's prediction (sent to the
    // sensor); the other triggers decide first and the statistics follow.
    let early = match trigger.needs_prediction() {
        true => Some(stats()?),
        false => None,
    };
    let (gamma, mut next) =
        trigger.decide_with(sensor, et.state, z, early.as_ref().map(|s| (&s.z_hat, &s.pzz)))?;
    let mut gated = false;
    let action = if gamma {
        let s = match early {
            Some(s) => s,
            None => stats()?,
        };
        let dz = residual(sensor, z, &s.z_hat);
        // EKF: `s.pzz` is its own S = G P⁻ Gᵀ + R.
        if gate_rejects(opts.gate, &s.pzz, &dz)? {
            gated = true;
            next = *et.state;
            MeasurementAction::Nothing
        } else {
            MeasurementAction::Update(s, dz)
        }
    } else if trigger.has_silent_update() {
        let s = match early {
            Some(s) => s,
            None => stats()?,
        };
        match silent_measurement(trigger, sensor, &next, &s)? {
            Some((dz, s)) => MeasurementAction::Update(s, dz),
            None => MeasurementAction::Nothing,
        }
    } else {
        match (opts.policy, next.last_sent) {
            (EtPolicy::Skip, _) | (_, None) => MeasurementAction::Nothing,
            (EtPolicy::Hold, Some(zt)) => {
                let s = stats()?;
                let dz = residual(sensor, &zt, &s.z_hat);
                MeasurementAction::Update(s, dz)
            }
            (EtPolicy::Optimal, Some(zt)) => {
                let z_hat = z_mean()?;
                MeasurementAction::Optimal {
                    g: sensor.jacobian(x_prior),
                    dz_bar: residual(sensor, &zt, &z_hat),
                }
            }
        }
    };
    Ok(MeasurementDecision {
        outcome: TriggerOutcome {
            triggered: Some(gamma),
            trigger_state: next,
            gated,
        },
        action,
    })
}
