//! Event triggers deciding whether a sensor sends its measurement: static
//! send-on-delta (`docs/algorithm.md` §3 step 4), the dynamic trigger of DEC-CKF (§5),
//! and the triggers whose silence is itself a measurement (`docs/triggers.md`,
//! updates in [`silence`](crate::silence)).

use nalgebra::{RealField, SMatrix, SVector};

use crate::angles::residual;
use crate::error::{Error, Result};
use crate::linalg::{cholesky, validate_positive};
use crate::model::MeasurementModel;
use crate::rng::{stream_key, uniform};

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
    /// Open-loop stochastic send-on-delta (Han et al., IEEE TAC 2015): draw
    /// `ζ ~ U[0, 1)` and send iff `ζ > exp(−½ ΔᵀR⁻¹Δ / δ)`, `Δ = z_k − z_τ`. A
    /// silent step is then exactly a measurement `z_τ` with noise `(1+δ) R`.
    Stochastic {
        /// Scale `δ > 0` (dimensionless; larger sends less).
        delta: T,
    },
    /// The paper's send-on-delta decision, with the silence used as the
    /// measurement `z_τ` whose noise is inflated by the covariance `δ/(m+2) I` of
    /// the uniform distribution on the ball `‖Δ‖² ≤ δ` (after Sijs and Lazar 2012).
    SendOnDeltaInflated {
        /// Threshold `δ` on the squared distance.
        delta: T,
    },
    /// Innovation trigger (Wu, Jia, Johansson, Shi, IEEE TAC 2013): send iff
    /// `‖L⁻¹(z_k − ẑ)‖∞ > δ` with `LLᵀ = Pzz`, the node's predicted measurement and
    /// innovation covariance, which the node sends to its sensor each step (see
    /// [`Trigger::needs_prediction`]). A silent step keeps the share `β(δ)` of a
    /// measurement's update ([`innovation_beta`](crate::silence::innovation_beta)).
    Innovation {
        /// Threshold `δ > 0` on each whitened innovation component.
        delta: T,
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
            Trigger::SendOnDelta { delta }
            | Trigger::Stochastic { delta }
            | Trigger::SendOnDeltaInflated { delta }
            | Trigger::Innovation { delta } => validate_positive(delta, "delta", false),
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

    /// The threshold `δ` (used by the error-minimised gain; 0 for `Always`/`Never`).
    pub fn delta(&self) -> T {
        match *self {
            Trigger::Always | Trigger::Never => T::zero(),
            Trigger::SendOnDelta { delta }
            | Trigger::Dynamic { delta, .. }
            | Trigger::Stochastic { delta }
            | Trigger::SendOnDeltaInflated { delta }
            | Trigger::Innovation { delta } => delta,
        }
    }

    /// Whether the decision needs the node's prediction `(ẑ, Pzz)` at the sensor
    /// ([`Trigger::Innovation`]): the node sends it to its sensor after its
    /// prediction, before the sensor decides (`m + m(m+1)/2` floats per step).
    ///
    /// ```
    /// use edccif_core::Trigger;
    /// assert!(Trigger::Innovation { delta: 1.2 }.needs_prediction());
    /// assert!(!Trigger::Stochastic { delta: 3.0 }.needs_prediction());
    /// ```
    pub fn needs_prediction(&self) -> bool {
        matches!(self, Trigger::Innovation { .. })
    }

    /// Whether a silent step has this trigger's own update
    /// ([`silent_measurement`](crate::silence::silent_measurement)) instead of
    /// the [`EtPolicy`](crate::EtPolicy) of the paper's triggers.
    ///
    /// ```
    /// use edccif_core::Trigger;
    /// assert!(Trigger::SendOnDeltaInflated { delta: 0.04 }.has_silent_update());
    /// assert!(!Trigger::SendOnDelta { delta: 0.04 }.has_silent_update());
    /// ```
    pub fn has_silent_update(&self) -> bool {
        matches!(
            self,
            Trigger::Stochastic { .. }
                | Trigger::SendOnDeltaInflated { .. }
                | Trigger::Innovation { .. }
        )
    }

    /// Decides on measurement `z` given the sensor's trigger state; returns `γ` and
    /// the state after this step (the caller commits it only when its step succeeds).
    ///
    /// Without the node's prediction the [`Innovation`](Trigger::Innovation)
    /// trigger sends; a [`Stochastic`](Trigger::Stochastic) trigger whose sensor
    /// noise `R` is not positive definite sends too. Use
    /// [`decide_with`](Self::decide_with) to get those cases as errors.
    pub fn decide<H, const N: usize, const M: usize>(
        &self,
        sensor: &H,
        state: &TriggerState<T, M>,
        z: &SVector<T, M>,
    ) -> (bool, TriggerState<T, M>)
    where
        H: MeasurementModel<T, N, M> + ?Sized,
    {
        match self.decide_with(sensor, state, z, None) {
            Ok(r) => r,
            Err(_) => {
                let mut next = state.advanced();
                next.last_sent = Some(*z);
                (true, next)
            }
        }
    }

    /// [`decide`](Self::decide) with the node's prediction `(ẑ, Pzz)` when
    /// [`needs_prediction`](Self::needs_prediction) (ignored otherwise).
    ///
    /// ```
    /// use edccif_core::{Trigger, TriggerState, models::Position3};
    /// use nalgebra::{Matrix3, Vector3};
    /// let cam = Position3::new([0.1; 3]).unwrap();
    /// let inn = Trigger::Innovation { delta: 1.0 };
    /// let s = TriggerState::<f64, 3>::new(&inn);
    /// let pzz = Matrix3::identity() * 0.04; // whitened: divide by 0.2
    /// let z_hat = Vector3::new(1.0, 0.0, 0.0);
    /// let near = Vector3::new(1.1, 0.0, 0.0); // 0.5 σ
    /// let far = Vector3::new(1.3, 0.0, 0.0);  // 1.5 σ
    /// assert!(!inn.decide_with::<_, 6, 3>(&cam, &s, &near, Some((&z_hat, &pzz))).unwrap().0);
    /// assert!(inn.decide_with::<_, 6, 3>(&cam, &s, &far, Some((&z_hat, &pzz))).unwrap().0);
    /// ```
    pub fn decide_with<H, const N: usize, const M: usize>(
        &self,
        sensor: &H,
        state: &TriggerState<T, M>,
        z: &SVector<T, M>,
        prediction: Option<(&SVector<T, M>, &SMatrix<T, M, M>)>,
    ) -> Result<(bool, TriggerState<T, M>)>
    where
        H: MeasurementModel<T, N, M> + ?Sized,
    {
        let mut next = *state;
        if let Trigger::Stochastic { .. } = self {
            // one draw per decision, also on the first one, so that the k-th
            // decision always uses the k-th number of the stream
            next = state.advanced();
        }
        let gamma = match (*self, state.last_sent) {
            (Trigger::Never, _) => false,
            (Trigger::Always, _) => true,
            (Trigger::Innovation { delta }, _) => match prediction {
                None => {
                    return Err(Error::InvalidParameter {
                        what: "prediction",
                        expected: "the node's (ẑ, Pzz) for the innovation trigger",
                    })
                }
                Some((z_hat, pzz)) => {
                    let e = cholesky(pzz, "innovation covariance Pzz")?
                        .l()
                        .solve_lower_triangular(&residual(sensor, z, z_hat))
                        .ok_or(Error::NonFinite {
                            what: "whitened innovation",
                        })?;
                    e.amax() > delta
                }
            },
            (_, None) => true,
            (Trigger::SendOnDelta { delta }, Some(zt))
            | (Trigger::SendOnDeltaInflated { delta }, Some(zt)) => {
                residual(sensor, z, &zt).norm_squared() > delta
            }
            (Trigger::Stochastic { delta }, Some(zt)) => {
                let d = residual(sensor, z, &zt);
                let q = d.dot(&cholesky(&sensor.noise(), "measurement noise R")?.solve(&d));
                let zeta: T = uniform(state.rng, 0);
                zeta > (-(q / (delta + delta))).exp()
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
        Ok((gamma, next))
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
    /// Random stream of the stochastic trigger: `splitmix64(rng)` is the next
    /// uniform draw (its top 53 bits), then `rng` advances by the splitmix64
    /// increment. Set from `(seed, node)` by [`TriggerState::seeded`].
    #[cfg_attr(feature = "serde", serde(default))]
    pub rng: u64,
}

impl<T: RealField + Copy, const M: usize> TriggerState<T, M> {
    /// Fresh state: nothing sent, `η_0 = δ`.
    pub fn new(trigger: &Trigger<T>) -> Self {
        Self::seeded(trigger, 0, 0)
    }

    /// Fresh state whose random stream (stochastic trigger) is keyed by
    /// `(seed, node)`, so that runs are reproducible and nodes independent.
    ///
    /// ```
    /// use edccif_core::{Trigger, TriggerState};
    /// let t = Trigger::Stochastic { delta: 2.0 };
    /// let a = TriggerState::<f64, 3>::seeded(&t, 1, 0);
    /// assert_eq!(a, TriggerState::seeded(&t, 1, 0));
    /// assert_ne!(a.rng, TriggerState::<f64, 3>::seeded(&t, 1, 1).rng);
    /// ```
    pub fn seeded(trigger: &Trigger<T>, seed: u64, node: u64) -> Self {
        Self {
            last_sent: None,
            eta: trigger.delta(),
            rng: stream_key(seed, node),
        }
    }

    /// The state with the random stream advanced by one draw; the draw itself is
    /// `splitmix64(self.rng)`.
    fn advanced(&self) -> Self {
        Self {
            rng: self.rng.wrapping_add(0x9E37_79B9_7F4A_7C15),
            ..*self
        }
    }
}
