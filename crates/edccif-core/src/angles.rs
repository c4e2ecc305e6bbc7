//! Angle handling (ALGORITHM.md §2): wrapping to `[−π, π)` and angle-aware
//! differences of measurement vectors.

use nalgebra::{RealField, SVector};

use crate::linalg::c;
use crate::model::MeasurementModel;

/// Wraps an angle to `[−π, π)`.
///
/// ```
/// use edccif_core::angles::wrap_angle;
/// use core::f64::consts::PI;
/// assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
/// assert_eq!(wrap_angle(PI), -PI);
/// ```
#[inline]
pub fn wrap_angle<T: RealField + Copy>(a: T) -> T {
    // Already inside: `(a + π)/2π` lies in (0.02, 0.98), whose floor is 0, so the
    // general formula below would return `a − 0 = a` exactly.
    if a.abs() < c(3.0) {
        return a;
    }
    let two_pi = T::two_pi();
    let w = a - two_pi * ((a + T::pi()) / two_pi).floor();
    // Guard against rounding at the upper edge.
    if w >= T::pi() {
        w - two_pi
    } else {
        w
    }
}

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
