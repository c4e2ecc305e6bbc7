//! Event triggers deciding whether a sensor sends its measurement: static
//! send-on-delta (ALGORITHM.md §3 step 4) and the dynamic trigger of DEC-CKF (§5).

use nalgebra::{RealField, SVector};

use crate::angles::residual;
use crate::error::{Error, Result};
use crate::linalg::validate_positive;
use crate::model::MeasurementModel;

/// When a sensor sends.
///
/// ```
/// use edccif_core::{Trigger, TriggerState, models::Position3};
/// use nalgebra::Vector3;
/// let cam = Position3::new([0.1; 3]).unwrap();
/// let sod = Trigger::SendOnDelta { delta: 0.04 };
/// let s0 = TriggerState::<f64, 3>::new(&sod);
/// // the first measurement always goes out
/// let (sent, s1) = sod.decide::<_, 6, 3>(&cam, &s0, &Vector3::new(1.0, 0.0, 0.0));
/// assert!(sent);
/// // a change of 0.1 m: ‖Δ‖² = 0.01 ≤ 0.04, so it stays
/// let (sent, _) = sod.decide::<_, 6, 3>(&cam, &s1, &Vector3::new(1.1, 0.0, 0.0));
/// assert!(!sent);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Trigger<T> {
    /// Every measurement is sent (γ ≡ 1).
    Always,
    /// No measurement is ever sent (γ ≡ 0).
    Never,
    /// Send-on-delta: `γ = 1` iff `‖z_k − z_τ‖² > δ` (angle-wrapped difference).
    SendOnDelta {
        /// Threshold `δ` on the squared distance.
        delta: T,
    },
    /// Dynamic trigger: `γ = 1` iff `d_k > δ + η_k/θ`, with
    /// `η_{k+1} = λ η_k + δ − (1−γ) d_k`, `η_0 = δ`.
    Dynamic {
        /// Static part `δ`.
        delta: T,
        /// Decay `λ ∈ [0, 1)`.
        lambda: T,
        /// Weight `θ > 0` of the internal variable.
        theta: T,
    },
}

impl<T: RealField + Copy> Trigger<T> {
    /// The paper's dynamic-trigger defaults: `λ = 0.9`, `θ = 2`.
    pub fn dynamic(delta: T) -> Self {
        Trigger::Dynamic {
            delta,
            lambda: nalgebra::convert(0.9),
            theta: nalgebra::convert(2.0),
        }
    }

    /// Checks the parameters: `δ > 0`, `0 ≤ λ < 1`, `θ > 0`.
    pub fn validate(&self) -> Result<()> {
        match *self {
            Trigger::Always | Trigger::Never => Ok(()),
            Trigger::SendOnDelta { delta } => validate_positive(delta, "delta", false),
            Trigger::Dynamic {
                delta,
                lambda,
                theta,
            } => {
                validate_positive(delta, "delta", false)?;
                validate_positive(theta, "theta", false)?;
                if !(lambda >= T::zero() && lambda < T::one()) {
                    return Err(Error::InvalidParameter {
                        what: "lambda",
                        expected: "in [0, 1)",
                    });
                }
                Ok(())
            }
        }
    }

    /// The threshold `δ` used by the error-minimised gain (0 for `Always`/`Never`).
    pub fn delta(&self) -> T {
        match *self {
            Trigger::Always | Trigger::Never => T::zero(),
            Trigger::SendOnDelta { delta } | Trigger::Dynamic { delta, .. } => delta,
        }
    }

    /// Decides on measurement `z` given the sensor's trigger state; returns `γ` and
    /// the state after this step (the caller commits it only when its step succeeds).
    pub fn decide<H, const N: usize, const M: usize>(
        &self,
        sensor: &H,
        state: &TriggerState<T, M>,
        z: &SVector<T, M>,
    ) -> (bool, TriggerState<T, M>)
    where
        H: MeasurementModel<T, N, M> + ?Sized,
    {
        let mut next = *state;
        let gamma = match (*self, state.last_sent) {
            (Trigger::Never, _) => false,
            (Trigger::Always, _) | (_, None) => true,
            (Trigger::SendOnDelta { delta }, Some(zt)) => {
                residual(sensor, z, &zt).norm_squared() > delta
            }
            (
                Trigger::Dynamic {
                    delta,
                    lambda,
                    theta,
                },
                Some(zt),
            ) => {
                let d = residual(sensor, z, &zt).norm_squared();
                let g = d > delta + state.eta / theta;
                next.eta = lambda * state.eta + delta - if g { T::zero() } else { d };
                g
            }
        };
        if gamma {
            next.last_sent = Some(*z);
        }
        (gamma, next)
    }
}

/// A sensor's trigger memory: the last sent measurement `z_τ` (none before the
/// first send) and the dynamic trigger's internal variable `η`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct TriggerState<T: RealField + Copy, const M: usize> {
    /// The last measurement sent, `z_τ`.
    pub last_sent: Option<SVector<T, M>>,
    /// Internal variable `η_k` of the dynamic trigger.
    pub eta: T,
}

impl<T: RealField + Copy, const M: usize> TriggerState<T, M> {
    /// Fresh state: nothing sent, `η_0 = δ`.
    pub fn new(trigger: &Trigger<T>) -> Self {
        Self {
            last_sent: None,
            eta: trigger.delta(),
        }
    }
}
