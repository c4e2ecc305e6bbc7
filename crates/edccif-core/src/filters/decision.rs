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

/// Where a local step's innovation statistics live while its decision refers
/// to them: in the caller's frame. The decision borrows them, so the
/// statistics are written once, where they are computed, and never copied
/// (moving them into a returned decision copies them three times: 5 % of an
/// EKF step's instructions, measured with callgrind).
pub(super) struct StatsStore<T: RealField + Copy, const N: usize, const M: usize> {
    /// The statistics at the prior, once computed.
    computed: Option<Result<MeasurementStats<T, N, M>>>,
    /// A silent step's pseudo-measurement: its innovation and statistics.
    silent: Option<(SVector<T, M>, MeasurementStats<T, N, M>)>,
    /// The innovation, or the held measurement's for an untriggered step.
    dz: SVector<T, M>,
    /// `G` at the prior, for the error-minimised gain.
    g: SMatrix<T, M, N>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> StatsStore<T, N, M> {
    /// An empty store.
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            computed: None,
            silent: None,
            dz: SVector::zeros(),
            g: SMatrix::zeros(),
        }
    }
}

/// What the measurement part of a local step does; the statistics and vectors
/// are borrowed from the step's [`StatsStore`].
pub(super) enum MeasurementAction<'s, T: RealField + Copy, const N: usize, const M: usize> {
    /// No measurement information: missing, gated, skipped, nothing sent yet, or
    /// a silent step that carries none.
    Nothing,
    /// A Kalman-type update with these innovation statistics and innovation
    /// (a triggered measurement, a silent step's pseudo-measurement, or the held
    /// `z_τ`).
    Update(&'s MeasurementStats<T, N, M>, &'s SVector<T, M>),
    /// The error-minimised gain of an untriggered step, at `G` with `Δz̄` (each
    /// filter computes its gain or closed form from these).
    Optimal {
        g: &'s SMatrix<T, M, N>,
        dz_bar: &'s SVector<T, M>,
    },
}

/// The trigger decision of a local step and what its measurement part does.
pub(super) struct MeasurementDecision<'s, T: RealField + Copy, const N: usize, const M: usize> {
    pub(super) outcome: TriggerOutcome<T, M>,
    pub(super) action: MeasurementAction<'s, T, N, M>,
}

/// The trigger decision, the innovation gate, the silent step and the
/// untriggered-step policy, shared by the information and the covariance
/// filters. `stats` computes the innovation statistics at the prior (sigma
/// points or linearisation) into `store`, `z_mean` only the predicted
/// measurement; each is called at most once, and only when the decision needs
/// it.
#[inline(always)]
pub(super) fn decide_measurement<'s, T, H, const N: usize, const M: usize>(
    sensor: &H,
    x_prior: &SVector<T, N>,
    obs: &Observation<T, M>,
    et: &EtStep<'_, T, M>,
    store: &'s mut StatsStore<T, N, M>,
    stats: impl Fn() -> Result<MeasurementStats<T, N, M>>,
    z_mean: impl Fn() -> Result<SVector<T, M>>,
) -> Result<MeasurementDecision<'s, T, N, M>>
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
    let StatsStore {
        computed,
        silent: pseudo,
        dz,
        g,
    } = store;
    // The innovation trigger decides on the node's prediction (sent to the
    // sensor); the other triggers decide first and the statistics follow.
    if trigger.needs_prediction() {
        *computed = Some(stats());
    }
    let prediction = match computed {
        Some(Ok(s)) => Some((&s.z_hat, &s.pzz)),
        Some(Err(e)) => return Err(*e),
        None => None,
    };
    let (gamma, next) = trigger.decide_with(sensor, et.state, z, prediction)?;
    let outcome = |trigger_state, gated| TriggerOutcome {
        triggered: Some(gamma),
        trigger_state,
        gated,
    };
    // A sent measurement and a silent step's pseudo-measurement need the
    // statistics.
    let silent = !gamma && trigger.has_silent_update();
    if (gamma || silent) && computed.is_none() {
        *computed = Some(stats());
    }
    let computed: &'s Option<Result<MeasurementStats<T, N, M>>> = computed;
    let s = match computed {
        Some(Ok(s)) => Some(s),
        Some(Err(e)) => return Err(*e),
        None => None,
    };
    if let (true, Some(s)) = (gamma, s) {
        *dz = residual(sensor, z, &s.z_hat);
        // EKF: `s.pzz` is its own S = G P⁻ Gᵀ + R.
        return Ok(match gate_rejects(opts.gate, &s.pzz, dz)? {
            true => MeasurementDecision {
                outcome: outcome(*et.state, true),
                action: MeasurementAction::Nothing,
            },
            false => MeasurementDecision {
                outcome: outcome(next, false),
                action: MeasurementAction::Update(s, dz),
            },
        });
    }
    if let (true, Some(s)) = (silent, s) {
        *pseudo = silent_measurement(trigger, sensor, &next, s)?;
        let pseudo: &'s Option<_> = pseudo;
        return Ok(MeasurementDecision {
            outcome: outcome(next, false),
            action: match pseudo {
                Some((dz, s)) => MeasurementAction::Update(s, dz),
                None => MeasurementAction::Nothing,
            },
        });
    }
    let action = match (opts.policy, next.last_sent) {
        (EtPolicy::Skip, _) | (_, None) => MeasurementAction::Nothing,
        (EtPolicy::Hold, Some(zt)) => {
            let held = stats()?;
            *dz = residual(sensor, &zt, &held.z_hat);
            *pseudo = Some((*dz, held));
            let pseudo: &'s Option<_> = pseudo;
            match pseudo {
                Some((dz, s)) => MeasurementAction::Update(s, dz),
                None => MeasurementAction::Nothing,
            }
        }
        (EtPolicy::Optimal, Some(zt)) => {
            let z_hat = z_mean()?;
            *g = sensor.jacobian(x_prior);
            *dz = residual(sensor, &zt, &z_hat);
            MeasurementAction::Optimal { g, dz_bar: dz }
        }
    };
    Ok(MeasurementDecision {
        outcome: outcome(next, false),
        action,
    })
}
