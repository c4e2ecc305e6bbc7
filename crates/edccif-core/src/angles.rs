//! Angle handling (`docs/algorithm.md` §2): the angle-aware difference of two
//! measurements of a model ([`residual`]), the deviation of angles from their
//! circular mean ([`angle_deviation`]), and wrapping to `[−π, π)`
//! ([`wrap_angle`], defined with the other elementary angle functions in
//! [`trig`](crate::trig), below the model traits that use it).

use nalgebra::{RealField, SVector};

use crate::linalg::c;
use crate::model::MeasurementModel;
use crate::trig::atan2;
pub use crate::trig::wrap_angle;

/// `a − b`, with the components the model declares as angles wrapped to `[−π, π)`.
///
/// ```
/// use edccif_core::{angles::residual, models::RangePitchAzimuth};
/// use nalgebra::Vector3;
/// let s = RangePitchAzimuth::new([0.0, 0.0, 0.0], 0.1, 0.01).unwrap();
/// let d = residual::<f64, _, 7, 3>(&s, &Vector3::new(1.0, 0.0, 3.1), &Vector3::new(1.0, 0.0, -3.1));
/// assert!((d[2] - (6.2 - 2.0 * core::f64::consts::PI)).abs() < 1e-12);
/// ```
#[inline]
pub fn residual<T, H, const N: usize, const M: usize>(
    model: &H,
    a: &SVector<T, M>,
    b: &SVector<T, M>,
) -> SVector<T, M>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let mut d = a - b;
    for k in 0..M {
        if model.is_angle(k) {
            d[k] = wrap_angle(d[k]);
        }
    }
    d
}

/// The deviation `wrap(θ − θ̄)` of an angle `θ` from an angle `θ̄`, given their unit
/// vectors `(cos θ, sin θ)` and `(cos θ̄, sin θ̄)`: `atan2` of `(cos θ, sin θ)` rotated
/// by `−θ̄`, in `[−π, π]`. The sigma-point transforms of a model that opts into
/// fast trigonometry ([`MeasurementModel::fast_trig`]) take each point's
/// deviation from the circular mean this way, so no point needs its own `atan2`.
/// Small deviations (`|tan| ≤ 1/16`, the usual case) use the Taylor series of
/// `atan` to `t¹³` (truncation error below `9.3e-19·|t|`), the rest the fast
/// trigonometry's [`atan2`]. The result agrees with
/// `wrap(atan2(sin θ, cos θ) − θ̄)` to a few ulp of `π`, not bit for bit.
///
/// ```
/// use edccif_core::angles::angle_deviation;
/// let (a, b) = (3.1f64, -3.1f64);
/// let d = angle_deviation((a.cos(), a.sin()), (b.cos(), b.sin()));
/// assert!((d - (6.2 - 2.0 * core::f64::consts::PI)).abs() < 1e-14);
/// let d = angle_deviation((0.3f64.cos(), 0.3f64.sin()), (0.28f64.cos(), 0.28f64.sin()));
/// assert!((d - 0.02).abs() < 1e-15);
/// ```
#[inline]
pub fn angle_deviation<T: RealField + Copy>((ca, sa): (T, T), (cm, sm): (T, T)) -> T {
    let y = sa * cm - ca * sm; // sin(θ − θ̄)
    let x = ca * cm + sa * sm; // cos(θ − θ̄)
    if x > T::zero() && y.abs() <= x * c(0.0625) {
        atan_small(y / x)
    } else {
        wrap_angle(atan2(y, x))
    }
}

/// [`angle_deviation`] of `K` angles at once (their cosines and sines as
/// vectors) from one mean direction: the same numbers, computed in passes that
/// vectorise (the series for all when every deviation is small).
#[inline]
pub(crate) fn angle_deviations<T: RealField + Copy, const K: usize>(
    cos: &SVector<T, K>,
    sin: &SVector<T, K>,
    (cm, sm): (T, T),
) -> SVector<T, K> {
    let y = sin * cm - cos * sm;
    let x = cos * cm + sin * sm;
    let tau: T = c(0.0625);
    let mut small = true;
    for j in 0..K {
        small &= x[j] > T::zero() && y[j].abs() <= x[j] * tau;
    }
    if small {
        y.component_div(&x).map(atan_small)
    } else {
        SVector::<T, K>::from_fn(|j, _| angle_deviation((cos[j], sin[j]), (cm, sm)))
    }
}

/// `atan(t)` for `|t| ≤ 1/16`: the Taylor series to `t¹³` (the next term is below
/// `|t|·2⁻⁵⁶/15 ≈ 9.3e-19·|t|`), in Horner form on `t²`.
#[inline]
fn atan_small<T: RealField + Copy>(t: T) -> T {
    let t2 = t * t;
    let mut p: T = c(1.0 / 13.0);
    for k in (0..6).rev() {
        let coef: T = c(1.0 / (2 * k + 1) as f64);
        p = coef - t2 * p;
    }
    t * p
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the reference `wrap(atan2(sin θ, cos θ) − θ̄)` over the whole circle
    /// and both branches (series and `atan2`): within 1e-15 absolute (a few ulp
    /// of π, the rounding of the reference's subtraction; the series itself is
    /// accurate to 1e-18 relative).
    #[test]
    fn angle_deviation_matches_the_reference() {
        let mut worst = 0.0f64;
        for i in 0..2000 {
            let mean = (i as f64 / 2000.0 - 0.5) * 0.999 * core::f64::consts::TAU;
            for d in [
                -3.0, -1.0, -0.2, -0.125, -0.0625, -1e-3, -1e-9, 0.0, 1e-7, 0.05, 0.062, 0.124,
                0.4, 2.9,
            ] {
                let theta = mean + d;
                let got = angle_deviation((theta.cos(), theta.sin()), (mean.cos(), mean.sin()));
                let want = wrap_angle(theta.sin().atan2(theta.cos()) - mean);
                worst = worst.max((got - want).abs());
            }
        }
        assert!(worst < 1e-15, "largest difference {worst:e}");
    }

    /// The batched form returns the scalar form's numbers, on both of its paths.
    #[test]
    fn angle_deviations_is_the_scalar_form() {
        let mean = 0.7f64;
        for spread in [0.01, 1.5] {
            let th = SVector::<f64, 5>::from_fn(|j, _| mean + spread * (j as f64 - 2.0));
            let got = angle_deviations(
                &th.map(f64::cos),
                &th.map(f64::sin),
                (mean.cos(), mean.sin()),
            );
            for j in 0..5 {
                let one = angle_deviation((th[j].cos(), th[j].sin()), (mean.cos(), mean.sin()));
                assert_eq!(got[j], one);
            }
        }
    }
}
