//! Event triggers deciding whether a sensor sends its measurement: static
//! send-on-delta (ALGORITHM.md §3 step 4), the dynamic trigger of DEC-CKF (§5),
//! and the triggers whose silence is itself a measurement (`docs/triggers.md`,
//! updates in [`silence`](crate::silence)). The send-on-delta family also comes
//! *normalised* (`…Normalised` variants): the change is measured in units of the
//! sensor's noise, `ΔᵀR⁻¹Δ`, so that one threshold fits metres and radians.

use nalgebra::{RealField, SMatrix, SVector};

use crate::angles::residual;
use crate::error::{Error, Result};
use crate::filters::EtOptions;
use crate::linalg::{cholesky, validate_positive};
use crate::model::MeasurementModel;
use crate::silence::{stream_key, uniform};

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
    /// [`SendOnDelta`](Trigger::SendOnDelta) in units of the sensor's noise:
    /// `γ = 1` iff `ΔᵀR⁻¹Δ > δ`, `Δ = z_k − z_τ` (angle-wrapped). An untriggered
    /// step's error-minimised gain bounds the deviation by `δ R` instead of `δ I`
    /// ([`untriggered_noise`](Trigger::untriggered_noise)).
    SendOnDeltaNormalised {
        /// Threshold `δ` on the squared Mahalanobis distance (dimensionless).
        delta: T,
    },
    /// [`Dynamic`](Trigger::Dynamic) with `d_k = ΔᵀR⁻¹Δ` (units of the noise).
    DynamicNormalised {
        /// Static part `δ` (dimensionless).
        delta: T,
        /// Decay `λ ∈ [0, 1)`.
        lambda: T,
        /// Weight `θ > 0` of the internal variable.
        theta: T,
    },
    /// [`SendOnDeltaInflated`](Trigger::SendOnDeltaInflated) in units of the
    /// noise: sends iff `ΔᵀR⁻¹Δ > δ`; the silence is `z_τ` with its noise
    /// inflated by `δ/(m+2) R`, the covariance of the uniform distribution on the
    /// ellipsoid `ΔᵀR⁻¹Δ ≤ δ`.
    SendOnDeltaInflatedNormalised {
        /// Threshold `δ` on the squared Mahalanobis distance (dimensionless).
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
            | Trigger::Innovation { delta }
            | Trigger::SendOnDeltaNormalised { delta }
            | Trigger::SendOnDeltaInflatedNormalised { delta } => {
                validate_positive(delta, "delta", false)
            }
            Trigger::Dynamic {
                delta,
                lambda,
                theta,
            }
            | Trigger::DynamicNormalised {
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
            | Trigger::Innovation { delta }
            | Trigger::SendOnDeltaNormalised { delta }
            | Trigger::DynamicNormalised { delta, .. }
            | Trigger::SendOnDeltaInflatedNormalised { delta } => delta,
        }
    }

    /// The same trigger with threshold `delta` (e.g. one node's own δ), checked
    /// with [`validate`](Self::validate). `Always` and `Never` have no threshold
    /// and stay as they are (`delta` is still checked).
    ///
    /// ```
    /// use edccif_core::Trigger;
    /// let t = Trigger::dynamic(0.04).with_delta(0.01).unwrap();
    /// assert_eq!(t, Trigger::dynamic(0.01));
    /// assert!(Trigger::SendOnDelta { delta: 0.04 }.with_delta(f64::NAN).is_err());
    /// assert!(Trigger::SendOnDelta { delta: 0.04 }.with_delta(-1.0).is_err());
    /// ```
    pub fn with_delta(self, delta: T) -> Result<Self> {
        validate_positive(delta, "delta", false)?;
        let t = match self {
            Trigger::Always | Trigger::Never => self,
            Trigger::SendOnDelta { .. } => Trigger::SendOnDelta { delta },
            Trigger::Stochastic { .. } => Trigger::Stochastic { delta },
            Trigger::SendOnDeltaInflated { .. } => Trigger::SendOnDeltaInflated { delta },
            Trigger::Innovation { .. } => Trigger::Innovation { delta },
            Trigger::SendOnDeltaNormalised { .. } => Trigger::SendOnDeltaNormalised { delta },
            Trigger::SendOnDeltaInflatedNormalised { .. } => {
                Trigger::SendOnDeltaInflatedNormalised { delta }
            }
            Trigger::Dynamic { lambda, theta, .. } => Trigger::Dynamic {
                delta,
                lambda,
                theta,
            },
            Trigger::DynamicNormalised { lambda, theta, .. } => Trigger::DynamicNormalised {
                delta,
                lambda,
                theta,
            },
        };
        t.validate()?;
        Ok(t)
    }

    /// The trigger with its change measured in units of the sensor's noise,
    /// `ΔᵀR⁻¹Δ`: send-on-delta, dynamic and the inflated send-on-delta become
    /// their `…Normalised` variants with the same parameters. The stochastic and
    /// innovation triggers already weigh the change by the noise (`R`, `Pzz`),
    /// and `Always`/`Never` have no threshold: they are returned unchanged.
    ///
    /// ```
    /// use edccif_core::Trigger;
    /// let t = Trigger::SendOnDelta { delta: 4.0 }.normalised();
    /// assert_eq!(t, Trigger::SendOnDeltaNormalised { delta: 4.0 });
    /// assert!(t.is_normalised() && t.normalised() == t);
    /// assert_eq!(Trigger::Stochastic { delta: 3.0 }.normalised(), Trigger::Stochastic { delta: 3.0 });
    /// ```
    pub fn normalised(self) -> Self {
        match self {
            Trigger::SendOnDelta { delta } => Trigger::SendOnDeltaNormalised { delta },
            Trigger::SendOnDeltaInflated { delta } => {
                Trigger::SendOnDeltaInflatedNormalised { delta }
            }
            Trigger::Dynamic {
                delta,
                lambda,
                theta,
            } => Trigger::DynamicNormalised {
                delta,
                lambda,
                theta,
            },
            other => other,
        }
    }

    /// Whether the threshold applies to `ΔᵀR⁻¹Δ` (a `…Normalised` variant)
    /// rather than to `‖Δ‖²` in the measurement's raw units.
    pub fn is_normalised(&self) -> bool {
        matches!(
            self,
            Trigger::SendOnDeltaNormalised { .. }
                | Trigger::DynamicNormalised { .. }
                | Trigger::SendOnDeltaInflatedNormalised { .. }
        )
    }

    /// The noise and threshold the error-minimised gain of an untriggered step
    /// ([`EtGain`](crate::EtGain), ALGORITHM.md §3 step 5) uses for this trigger:
    /// `S = μ1 G P⁻ Gᵀ + μ2 R' + μ3 δ' I`.
    ///
    /// The gain bounds the second moment of the unsent deviation `Δ = z_k − z_τ`
    /// by what the trigger guarantees about it. With the paper's threshold
    /// `‖Δ‖² ≤ δ` gives `ΔΔᵀ ⪯ δ I`, and `(R', δ') = (R, δ)`. With a normalised
    /// threshold `ΔᵀR⁻¹Δ ≤ δ` gives, by Cauchy–Schwarz,
    /// `(vᵀΔ)² ≤ (vᵀRv)(ΔᵀR⁻¹Δ) ≤ δ vᵀRv` for every `v`, i.e. `ΔΔᵀ ⪯ δ R`, so
    /// `S = μ1 G P⁻ Gᵀ + μ2 R + μ3 δ R`: returned as `R' = (1 + μ3 δ/μ2) R`,
    /// `δ' = 0` (`docs/triggers.md`, "Normalised thresholds").
    ///
    /// ```
    /// use edccif_core::{EtOptions, Trigger};
    /// use nalgebra::Matrix2;
    /// let r = Matrix2::new(0.25, 0.0, 0.0, 1e-4);
    /// let o = EtOptions::default();
    /// assert_eq!(Trigger::SendOnDelta { delta: 0.04 }.untriggered_noise(&r, &o), (r, 0.04));
    /// let (r2, d2) = Trigger::SendOnDeltaNormalised { delta: 4.0 }.untriggered_noise(&r, &o);
    /// let (mu2, mu3) = (1.0 + o.sigma2, 1.0 + 1.0 / o.sigma1 + 1.0 / o.sigma2);
    /// assert_eq!(d2, 0.0);
    /// assert!((r2 * mu2 - (r * mu2 + r * (mu3 * 4.0))).norm() < 1e-12 * (r2 * mu2).norm());
    /// ```
    pub fn untriggered_noise<const M: usize>(
        &self,
        r: &SMatrix<T, M, M>,
        opts: &EtOptions<T>,
    ) -> (SMatrix<T, M, M>, T) {
        if self.is_normalised() {
            let one = T::one();
            let mu2 = one + opts.sigma2;
            let mu3 = one + one / opts.sigma1 + one / opts.sigma2;
            (r * (one + mu3 * self.delta() / mu2), T::zero())
        } else {
            (*r, self.delta())
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
                | Trigger::SendOnDeltaInflatedNormalised { .. }
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
        self.validate()?;
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
            (Trigger::SendOnDeltaNormalised { delta }, Some(zt))
            | (Trigger::SendOnDeltaInflatedNormalised { delta }, Some(zt)) => {
                noise_distance(sensor, z, &zt)? > delta
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
            (
                Trigger::DynamicNormalised {
                    delta,
                    lambda,
                    theta,
                },
                Some(zt),
            ) => {
                let d = noise_distance(sensor, z, &zt)?;
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

/// `ΔᵀR⁻¹Δ` with `Δ = z − z_τ` (angle components wrapped) and `R` the sensor's
/// noise: the change in units of the noise. Errors when `R` is not positive
/// definite or the result is not finite.
///
/// ```
/// use edccif_core::{models::RangeBearing, trigger::noise_distance};
/// use nalgebra::Vector2;
/// let rb = RangeBearing::new([0.0, 0.0], 0.5, 0.01).unwrap(); // σ = 0.5 m, 0.01 rad
/// // 1 σ in range and 2 σ in bearing (across ±π): 1 + 4 = 5
/// let a = Vector2::new(10.0, 3.14);
/// let b = Vector2::new(10.5, 3.14 + 0.02 - 2.0 * std::f64::consts::PI);
/// let d = noise_distance::<f64, _, 4, 2>(&rb, &b, &a).unwrap();
/// assert!((d - 5.0).abs() < 1e-9);
/// ```
pub fn noise_distance<T, H, const N: usize, const M: usize>(
    sensor: &H,
    z: &SVector<T, M>,
    z_tau: &SVector<T, M>,
) -> Result<T>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let d = residual(sensor, z, z_tau);
    let q = d.dot(&cholesky(&sensor.noise(), "measurement noise R")?.solve(&d));
    if q.is_finite() {
        Ok(q)
    } else {
        Err(Error::NonFinite {
            what: "normalised change (z − z_τ)ᵀR⁻¹(z − z_τ)",
        })
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
