//! What a silent step tells the estimator, for the triggers that go beyond the
//! paper (`docs/triggers.md`), and the seeded randomness of the stochastic trigger.
//!
//! Every silent-step update here has the same shape: the silence is a
//! *pseudo-measurement* `z̃` of the sensor with extra noise `ΔR` on top of `R`,
//! fused with the ordinary triggered formulas (the CIF's `(ī, Ī)` of ALGORITHM.md
//! §3 step 5, or a Kalman update) after `Pzz ← Pzz + ΔR`:
//!
//! | trigger | sends when | `z̃` | `ΔR` |
//! |---|---|---|---|
//! | [`Stochastic`](Trigger::Stochastic) | `ζ > exp(−½ ΔᵀR⁻¹Δ/δ)`, `ζ ~ U[0,1)` | `z_τ` | `δ R` (exact, Han et al. 2015) |
//! | [`SendOnDeltaInflated`](Trigger::SendOnDeltaInflated) | `‖Δ‖² > δ` (the paper's SoD) | `z_τ` | `δ/(m+2) I` (uniform in the δ-ball) |
//! | [`SendOnDeltaInflatedNormalised`](Trigger::SendOnDeltaInflatedNormalised) | `ΔᵀR⁻¹Δ > δ` | `z_τ` | `δ/(m+2) R` (uniform in the ellipsoid) |
//! | [`Innovation`](Trigger::Innovation) | `‖L⁻¹(z − ẑ)‖∞ > δ`, `LLᵀ = Pzz` | `ẑ` | `Pzz (1−β)/β` (Wu et al. 2013) |
//!
//! with `Δ = z_k − z_τ` (angle-wrapped) and `β = β(δ)` from [`innovation_beta`].

use nalgebra::{RealField, SMatrix, SVector};

use crate::angles::residual;
use crate::error::Result;
use crate::linalg::{c, sym};
use crate::model::MeasurementModel;
use crate::sigma::MeasurementStats;
use crate::trigger::{Trigger, TriggerState};

/// One step of the splitmix64 generator (Steele, Lea, Flood 2014): a bijective
/// mix of `x`. Counter-based: `splitmix64(state + k·0x9E37…)` is the k-th draw.
///
/// ```
/// use edccif_core::silence::splitmix64;
/// assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
/// assert_ne!(splitmix64(1), splitmix64(2));
/// ```
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The random stream of one sensor: a key from `(seed, node)`, so that every node
/// of every seeded run draws independent, reproducible numbers.
///
/// ```
/// use edccif_core::silence::stream_key;
/// assert_eq!(stream_key(7, 2), stream_key(7, 2));
/// assert_ne!(stream_key(7, 2), stream_key(7, 3));
/// assert_ne!(stream_key(7, 2), stream_key(8, 2));
/// ```
pub fn stream_key(seed: u64, node: u64) -> u64 {
    splitmix64(splitmix64(seed) ^ node.wrapping_mul(0xD1B5_4A32_D192_ED03))
}

/// The `draw`-th uniform number in `[0, 1)` of stream `key` (53 random bits).
///
/// ```
/// use edccif_core::silence::{stream_key, uniform};
/// let u: f64 = uniform(stream_key(0, 0), 5);
/// assert!((0.0..1.0).contains(&u));
/// assert_eq!(u, uniform::<f64>(stream_key(0, 0), 5));
/// ```
pub fn uniform<T: RealField + Copy>(key: u64, draw: u64) -> T {
    let bits = splitmix64(key.wrapping_add(draw.wrapping_mul(0x9E37_79B9_7F4A_7C15))) >> 11;
    c(bits as f64 * (1.0 / (1u64 << 53) as f64))
}

/// `erf(x)`: Maclaurin series for `|x| < 3`, the asymptotic series of `erfc`
/// beyond (absolute error below 1e-12 everywhere, enough for covariance factors).
///
/// ```
/// use edccif_core::silence::erf;
/// assert!((erf(1.0_f64) - 0.842_700_792_949_714_9).abs() < 1e-13);
/// assert!((erf(-0.5_f64) + 0.520_499_877_813_046_5).abs() < 1e-13);
/// assert!((erf(4.0_f64) - 0.999_999_984_582_742).abs() < 1e-13);
/// ```
pub fn erf<T: RealField + Copy>(x: T) -> T {
    let ax = x.abs();
    let two_over_sqrt_pi: T = c(core::f64::consts::FRAC_2_SQRT_PI);
    let v = if ax < c(3.0) {
        // erf(x) = 2/√π Σ (−1)ⁿ x^{2n+1} / (n! (2n+1))
        let x2 = ax * ax;
        let mut term = ax; // (−1)ⁿ x^{2n+1}/n!
        let mut sum = ax;
        let mut n = 1.0;
        while n < 120.0 {
            term = -term * x2 / c(n);
            let add = term / c(2.0 * n + 1.0);
            sum += add;
            if add.abs() < c::<T>(1e-17) * sum.abs() {
                break;
            }
            n += 1.0;
        }
        two_over_sqrt_pi * sum
    } else {
        // erfc(x) ≈ e^{−x²}/(x√π) Σ (−1)ⁿ (2n−1)!! / (2x²)ⁿ, a few terms
        let x2 = ax * ax;
        let mut term = T::one();
        let mut sum = T::one();
        for n in 1..8 {
            term = -term * c(2.0 * n as f64 - 1.0) / (x2 + x2);
            sum += term;
        }
        T::one() - (-x2).exp() / ax * two_over_sqrt_pi * c(0.5) * sum
    };
    if x < T::zero() {
        -v
    } else {
        v
    }
}

/// `β(δ) = 1 − Var(ε | |ε| ≤ δ)` for `ε ~ N(0, 1)`:
/// `β = √(2/π) δ e^{−δ²/2} / erf(δ/√2)` (Wu, Jia, Johansson, Shi 2013), the share
/// of a measurement's variance reduction that a silent step of the innovation
/// trigger still gives. `β → 1` as `δ → 0`, `β → 0` as `δ → ∞`.
///
/// ```
/// use edccif_core::silence::innovation_beta;
/// let b: f64 = innovation_beta(1.0);
/// assert!((b - 0.708_874_9).abs() < 1e-6); // 1 − Var of N(0,1) on [−1, 1]
/// assert!(innovation_beta(1e-4_f64) > 0.999_999 && innovation_beta(10.0_f64) < 1e-19);
/// ```
pub fn innovation_beta<T: RealField + Copy>(delta: T) -> T {
    let sqrt2: T = c(core::f64::consts::SQRT_2);
    let small: T = c(1e-6);
    if delta < small {
        // series: 1 − Var ≈ 1 − δ²/3
        return T::one() - delta * delta / c(3.0);
    }
    let num =
        c::<T>(0.797_884_560_802_865_4) /* √(2/π) */ * delta * (-(delta * delta) / c(2.0)).exp();
    let b = num / erf(delta / sqrt2);
    b.max(T::zero()).min(T::one())
}

/// The silent step of a trigger as a pseudo-measurement: innovation `Δz̃ = z̃ − ẑ`
/// (wrapped) and the innovation statistics with `Pzz + ΔR`. `None` when the
/// trigger has no update of its own ([`Trigger::has_silent_update`] is false: the
/// caller applies its [`EtPolicy`](crate::EtPolicy)), or when the silence carries
/// no information (the innovation trigger with `β(δ) ≈ 0`, or nothing sent yet).
///
/// `next` is the trigger state after the decision (its `last_sent` is `z_τ`);
/// `stats` are the node's innovation statistics at its prior.
///
/// ```
/// use edccif_core::silence::silent_measurement;
/// use edccif_core::{models::Position3, MeasurementStats, Trigger, TriggerState};
/// use nalgebra::{Matrix3, SMatrix, Vector3};
/// let cam = Position3::new([0.1; 3]).unwrap();
/// let trig = Trigger::SendOnDeltaInflated { delta: 0.05 };
/// let mut state = TriggerState::<f64, 3>::new(&trig);
/// state.last_sent = Some(Vector3::new(1.0, 0.0, 0.0));
/// let stats = MeasurementStats::<f64, 6, 3> {
///     z_hat: Vector3::new(0.9, 0.0, 0.0),
///     pzz: Matrix3::identity() * 0.02,
///     pxz: SMatrix::zeros(),
/// };
/// let (dz, s) = silent_measurement::<f64, _, 6, 3>(&trig, &cam, &state, &stats).unwrap().unwrap();
/// assert!((dz - Vector3::new(0.1, 0.0, 0.0)).norm() < 1e-12);
/// // the δ-ball of radius √0.05 in 3-D: covariance 0.05/5 = 0.01 per axis
/// assert!((s.pzz[(0, 0)] - 0.03).abs() < 1e-12);
/// ```
pub fn silent_measurement<T, H, const N: usize, const M: usize>(
    trigger: &Trigger<T>,
    sensor: &H,
    next: &TriggerState<T, M>,
    stats: &MeasurementStats<T, N, M>,
) -> Result<Option<(SVector<T, M>, MeasurementStats<T, N, M>)>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let (dz, extra): (SVector<T, M>, SMatrix<T, M, M>) = match (*trigger, next.last_sent) {
        (Trigger::Stochastic { delta }, Some(zt)) => {
            (residual(sensor, &zt, &stats.z_hat), sensor.noise() * delta)
        }
        (Trigger::SendOnDeltaInflated { delta }, Some(zt)) => (
            residual(sensor, &zt, &stats.z_hat),
            SMatrix::<T, M, M>::identity() * (delta / c((M + 2) as f64)),
        ),
        (Trigger::SendOnDeltaInflatedNormalised { delta }, Some(zt)) => (
            residual(sensor, &zt, &stats.z_hat),
            sensor.noise() * (delta / c((M + 2) as f64)),
        ),
        (Trigger::Innovation { delta }, _) => {
            let beta = innovation_beta(delta);
            if !(beta > c(1e-12)) {
                return Ok(None);
            }
            (
                SVector::<T, M>::zeros(),
                stats.pzz * ((T::one() - beta) / beta),
            )
        }
        _ => return Ok(None),
    };
    crate::linalg::check_finite(&extra, "silent-step noise ΔR")?;
    Ok(Some((
        dz,
        MeasurementStats {
            z_hat: stats.z_hat,
            pzz: sym(&(stats.pzz + extra)),
            pxz: stats.pxz,
        },
    )))
}
