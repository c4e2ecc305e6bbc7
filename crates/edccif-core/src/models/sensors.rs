//! Sensor models of the catalogue. Every sensor measures the position held in the
//! first two (2-D sensors) or three (3-D sensors) state components, whatever
//! follows them; a state with fewer components gives NaN, which any filter reports
//! as [`Error::NonFinite`](crate::Error::NonFinite).

use nalgebra::{RealField, SMatrix, SVector, Vector1, Vector2, Vector3};

use super::undefined::{nan_matrix, nan_vector};
use crate::error::{Error, Result};
use crate::linalg::{jacobian_products_leading, validate_covariance, validate_positive};
use crate::model::{MeasurementModel, PointImages};
use crate::trig::atan2_if;

/// A finite sensor position, or [`Error::NonFinite`] naming it.
fn sensor_position<T: RealField + Copy, const D: usize>(p: [T; D]) -> Result<SVector<T, D>> {
    let p = SVector::<T, D>::from(p);
    if p.iter().all(|v| v.is_finite()) {
        Ok(p)
    } else {
        Err(Error::NonFinite {
            what: "sensor position",
        })
    }
}

/// The sensors' [`MeasurementModel::jacobian_products`]: only the first `D`
/// columns of `G` (the position) can be non-zero, so the products leave out the
/// `0·x` terms ([`jacobian_products_leading`]) and give the same bits as the
/// general ones. `$m` is the measurement dimension, `$d` the position's.
macro_rules! position_jacobian_products {
    ($m:tt, $d:tt) => {
        /// Only the first position columns of `G` can be non-zero: the products
        /// without the `0·x` terms ([`jacobian_products_leading`]), the same
        /// bits as the general ones.
        #[inline(always)]
        fn jacobian_products(
            &self,
            g: &SMatrix<T, $m, N>,
            p: &SMatrix<T, N, N>,
        ) -> (SMatrix<T, N, $m>, SMatrix<T, $m, $m>) {
            jacobian_products_leading::<T, N, $m, $d>(g, p)
        }
    };
}

/// Diagonal noise covariance from validated standard deviations.
fn diag_noise<T: RealField + Copy, const M: usize>(
    sigma: [T; M],
    what: &'static str,
) -> Result<SMatrix<T, M, M>> {
    for s in sigma {
        validate_positive(s, what, false)?;
    }
    Ok(SMatrix::<T, M, M>::from_diagonal(&SVector::<T, M>::from(
        sigma.map(|s| s * s),
    )))
}

/// The sigma-point images of a sensor that measures the first `D` state
/// components (`N ≥ D`): `eval` maps a position to `(z, cos, sin)`, applied to the
/// position part of `x ± offsets[:, j]` (column `j` of `plus`, `minus`) and of `x`
/// (`centre`).
#[inline]
fn position_points<T, const N: usize, const M: usize, const D: usize>(
    x: &SVector<T, N>,
    offsets: &SMatrix<T, N, N>,
    plus: &mut PointImages<T, M, N>,
    minus: &mut PointImages<T, M, N>,
    centre: Option<&mut PointImages<T, M, 1>>,
    eval: impl Fn(&SVector<T, D>) -> (SVector<T, M>, SVector<T, M>, SVector<T, M>),
) where
    T: RealField + Copy,
{
    let p = SVector::<T, D>::from_fn(|i, _| x[i]);
    for j in 0..N {
        let o = SVector::<T, D>::from_fn(|i, _| offsets[(i, j)]);
        plus.set(j, eval(&(p + o)));
        minus.set(j, eval(&(p - o)));
    }
    if let Some(c0) = centre {
        c0.set(0, eval(&p));
    }
}

/// Range, pitch and azimuth of the target seen from a sensor at `s`
/// (`docs/algorithm.md` §1): with `d = p − s`, `z = [|d|, atan2(dz, hypot(dx, dy)),
/// atan2(dy, dx)]`, `R = diag(σr², σa², σa²)`; components 1 and 2 are angles.
///
/// It measures any state whose first three components are the position.
///
/// ```
/// use edccif_core::{models::RangePitchAzimuth, model::MeasurementModel};
/// use nalgebra::SVector;
/// let s = RangePitchAzimuth::new([0.0, 0.0, 0.0], 0.1, 0.01).unwrap();
/// let z = MeasurementModel::<f64, 7, 3>::measure(&s, &SVector::<f64, 7>::from([3.0, 4.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
/// assert!((z[0] - 5.0).abs() < 1e-12 && z[1].abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RangePitchAzimuth<T: RealField + Copy> {
    position: Vector3<T>,
    r: SMatrix<T, 3, 3>,
    /// Fast trigonometry of the sigma-point transforms (default on):
    /// see [`MeasurementModel::fast_trig`].
    #[cfg_attr(feature = "serde", serde(default = "super::yes"))]
    fast_trig: bool,
}

impl<T: RealField + Copy> RangePitchAzimuth<T> {
    /// A sensor at `position` with range noise `sigma_r` and angle noise `sigma_a`
    /// (standard deviations, `> 0`).
    ///
    /// ```
    /// use edccif_core::{models::RangePitchAzimuth, Error};
    /// assert!(matches!(RangePitchAzimuth::new([0.0; 3], 0.1, 0.0), Err(Error::InvalidParameter { what: "sigma_a", .. })));
    /// ```
    pub fn new(position: [T; 3], sigma_r: T, sigma_a: T) -> Result<Self> {
        let position = sensor_position(position)?;
        validate_positive(sigma_r, "sigma_r", false)?;
        validate_positive(sigma_a, "sigma_a", false)?;
        let r = SMatrix::<T, 3, 3>::from_diagonal(&Vector3::new(
            sigma_r * sigma_r,
            sigma_a * sigma_a,
            sigma_a * sigma_a,
        ));
        Ok(Self {
            position,
            r,
            fast_trig: true,
        })
    }
    /// The same sensor with fast trigonometry switched on (the default) or off
    /// ([`MeasurementModel::fast_trig`]; off: the platform libm, bit-exact):
    /// no `atan2` per sigma point, and the remaining `atan2` (the circular mean,
    /// `h(x)` for the EKF) by the kernel [`crate::trig::atan2`], within 1 ulp.
    ///
    /// ```
    /// use edccif_core::{model::MeasurementModel, models::RangePitchAzimuth};
    /// use nalgebra::SVector;
    /// let s = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)?.with_fast_trig(true);
    /// assert!(MeasurementModel::<f64, 7, 3>::fast_trig(&s));
    /// // h(x) by the kernel's atan2: the reference's angles to an ulp or two
    /// let x = SVector::<f64, 7>::from([1.0, -2.0, 3.0, 0.0, 0.0, 0.0, 0.1]);
    /// let fast = MeasurementModel::<f64, 7, 3>::measure(&s, &x);
    /// let reference = MeasurementModel::<f64, 7, 3>::measure(&s.with_fast_trig(false), &x);
    /// assert!((fast - reference).abs().max() <= 4.0 * f64::EPSILON);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    #[must_use]
    pub fn with_fast_trig(mut self, on: bool) -> Self {
        self.fast_trig = on;
        self
    }
    /// The sensor position.
    ///
    /// ```
    /// let s = edccif_core::models::RangePitchAzimuth::new([1.0, 2.0, 3.0], 0.1, 0.01).unwrap();
    /// assert_eq!(s.position().as_slice(), &[1.0, 2.0, 3.0]);
    /// ```
    pub fn position(&self) -> Vector3<T> {
        self.position
    }

    /// `([r, 0, 0], cos, sin)` of position `q`: the range and the unit vectors of
    /// the pitch and the azimuth from the geometry, `cos φ = h/r`, `sin φ = dz/r`,
    /// `cos ρ = dx/h`, `sin ρ = dy/h` (`h = |(dx, dy)|`), with `atan2(0, 0) = 0`'s
    /// `(1, 0)` at the degenerate points. Also returns `d = q − s` and `h`.
    #[inline]
    fn unit_images(&self, q: &Vector3<T>) -> ([Vector3<T>; 4], T) {
        let d = q - self.position;
        // Plain roots: positions are metres to kilometres, far from overflow.
        let rho2 = d[0] * d[0] + d[1] * d[1];
        let rho = rho2.sqrt();
        let r = (rho2 + d[2] * d[2]).sqrt();
        let (cp, sp) = if r > T::zero() {
            (rho / r, d[2] / r)
        } else {
            (T::one(), T::zero())
        };
        let (ca, sa) = if rho > T::zero() {
            (d[0] / rho, d[1] / rho)
        } else {
            (T::one(), T::zero())
        };
        (
            [
                Vector3::new(r, T::zero(), T::zero()),
                Vector3::new(T::one(), cp, ca),
                Vector3::new(T::zero(), sp, sa),
                d,
            ],
            rho,
        )
    }
}

impl<T: RealField + Copy, const N: usize> MeasurementModel<T, N, 3> for RangePitchAzimuth<T> {
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 3> {
        if N < 3 {
            return nan_vector();
        }
        let d = Vector3::new(x[0], x[1], x[2]) - self.position;
        // Plain roots: positions are metres to kilometres, far from overflow.
        let rho2 = d[0] * d[0] + d[1] * d[1];
        let rho = rho2.sqrt();
        Vector3::new(
            (rho2 + d[2] * d[2]).sqrt(),
            atan2_if(self.fast_trig, d[2], rho),
            atan2_if(self.fast_trig, d[1], d[0]),
        )
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, 3, 3> {
        self.r
    }
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        k == 1 || k == 2
    }
    #[inline]
    fn fast_trig(&self) -> bool {
        self.fast_trig
    }
    /// Unit vectors from the geometry: `cos φ = h/r`, `sin φ = dz/r`,
    /// `cos ρ = dx/h`, `sin ρ = dy/h` (`h = hypot(dx, dy)`), with `atan2(0, 0) = 0`'s
    /// `(1, 0)` at the degenerate points.
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<T, N>,
    ) -> (SVector<T, 3>, SVector<T, 3>, SVector<T, 3>) {
        if N < 3 {
            return (nan_vector(), nan_vector(), nan_vector());
        }
        let ([mut z, co, si, d], rho) = self.unit_images(&Vector3::new(x[0], x[1], x[2]));
        // The reference path's per-point hook (a model with fast trigonometry
        // takes `measure_points_trig` instead): the library's `atan2`.
        z[1] = d[2].atan2(rho);
        z[2] = d[1].atan2(d[0]);
        (z, co, si)
    }
    /// The range and the angles' unit vectors ([`measure_with_trig`](Self::measure_with_trig)
    /// without the two `atan2`).
    #[inline]
    fn measure_points_trig(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        plus: &mut PointImages<T, 3, N>,
        minus: &mut PointImages<T, 3, N>,
        centre: Option<&mut PointImages<T, 3, 1>>,
    ) {
        if N < 3 {
            return self.measure_points(x, offsets, plus, minus, centre);
        }
        position_points(x, offsets, plus, minus, centre, |q: &Vector3<T>| {
            let ([z, co, si, _], _) = self.unit_images(q);
            (z, co, si)
        });
    }
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 3, N> {
        if N < 3 {
            return nan_matrix();
        }
        let d = Vector3::new(x[0], x[1], x[2]) - self.position;
        let rho2 = d[0] * d[0] + d[1] * d[1];
        let rho = rho2.sqrt();
        let r2 = rho2 + d[2] * d[2];
        rpa_jacobian(&d, rho2, rho, r2, r2.sqrt())
    }
    /// The offset, its norms and the range shared by `h` and `G` (the
    /// expressions of [`measure`](MeasurementModel::measure) and
    /// [`jacobian`](MeasurementModel::jacobian), so the same bits).
    #[inline]
    fn measure_with_jacobian(&self, x: &SVector<T, N>) -> (SVector<T, 3>, SMatrix<T, 3, N>) {
        if N < 3 {
            return (nan_vector(), nan_matrix());
        }
        let d = Vector3::new(x[0], x[1], x[2]) - self.position;
        let rho2 = d[0] * d[0] + d[1] * d[1];
        let rho = rho2.sqrt();
        let r2 = rho2 + d[2] * d[2];
        let r = r2.sqrt();
        let z = Vector3::new(
            r,
            atan2_if(self.fast_trig, d[2], rho),
            atan2_if(self.fast_trig, d[1], d[0]),
        );
        (z, rpa_jacobian(&d, rho2, rho, r2, r))
    }
    position_jacobian_products!(3, 3);
}

/// [`RangePitchAzimuth`]'s Jacobian from the offset `d = p − s`, `ρ² = dx² + dy²`,
/// `ρ`, `r² = ρ² + dz²` and `r`.
#[inline]
fn rpa_jacobian<T: RealField + Copy, const N: usize>(
    d: &Vector3<T>,
    rho2: T,
    rho: T,
    r2: T,
    r: T,
) -> SMatrix<T, 3, N> {
    let mut g = SMatrix::<T, 3, N>::zeros();
    for a in 0..3 {
        g[(0, a)] = d[a] / r;
    }
    g[(1, 0)] = -d[2] * d[0] / (r2 * rho);
    g[(1, 1)] = -d[2] * d[1] / (r2 * rho);
    g[(1, 2)] = rho / r2;
    g[(2, 0)] = -d[1] / rho2;
    g[(2, 1)] = d[0] / rho2;
    g
}

/// Range and bearing of a target in the plane seen from a sensor at `s`: with
/// `d = p − s` (`p` the first two state components), `z = [|d|, atan2(dy, dx)]`,
/// `R = diag(σr², σb²)`; component 1 is an angle.
///
/// ```
/// use edccif_core::{models::RangeBearing, model::MeasurementModel};
/// use nalgebra::Vector4;
/// let s = RangeBearing::new([1.0, 1.0], 0.1, 0.01).unwrap();
/// let z = MeasurementModel::<f64, 4, 2>::measure(&s, &Vector4::new(1.0, 3.0, 0.0, 0.0));
/// assert!((z[0] - 2.0).abs() < 1e-15 && (z[1] - core::f64::consts::FRAC_PI_2).abs() < 1e-15);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RangeBearing<T: RealField + Copy> {
    position: Vector2<T>,
    r: SMatrix<T, 2, 2>,
    /// Fast trigonometry of the sigma-point transforms (default on):
    /// see [`MeasurementModel::fast_trig`].
    #[cfg_attr(feature = "serde", serde(default = "super::yes"))]
    fast_trig: bool,
}

impl<T: RealField + Copy> RangeBearing<T> {
    /// A sensor at `position` with range noise `sigma_r` and bearing noise
    /// `sigma_b` (standard deviations, `> 0`; the position finite).
    ///
    /// ```
    /// use edccif_core::{models::RangeBearing, Error};
    /// assert_eq!(RangeBearing::new([f64::NAN, 0.0], 0.1, 0.01).unwrap_err(), Error::NonFinite { what: "sensor position" });
    /// assert!(matches!(RangeBearing::new([0.0, 0.0], -0.1, 0.01), Err(Error::InvalidParameter { what: "sigma_r", .. })));
    /// ```
    pub fn new(position: [T; 2], sigma_r: T, sigma_b: T) -> Result<Self> {
        let position = sensor_position(position)?;
        validate_positive(sigma_r, "sigma_r", false)?;
        validate_positive(sigma_b, "sigma_b", false)?;
        let r =
            SMatrix::<T, 2, 2>::from_diagonal(&Vector2::new(sigma_r * sigma_r, sigma_b * sigma_b));
        Ok(Self {
            position,
            r,
            fast_trig: true,
        })
    }
    /// The same sensor with fast trigonometry switched on (the default) or off
    /// ([`MeasurementModel::fast_trig`]; off: the platform libm, bit-exact):
    /// no `atan2` per sigma point, and the remaining `atan2` (the circular mean,
    /// `h(x)` for the EKF) by the kernel [`crate::trig::atan2`], within 1 ulp.
    ///
    /// ```
    /// use edccif_core::{model::MeasurementModel, models::RangeBearing};
    /// let s = RangeBearing::new([0.0, 0.0], 0.1, 0.01)?.with_fast_trig(true);
    /// assert!(MeasurementModel::<f64, 4, 2>::fast_trig(&s));
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    #[must_use]
    pub fn with_fast_trig(mut self, on: bool) -> Self {
        self.fast_trig = on;
        self
    }
    /// The sensor position.
    ///
    /// ```
    /// let s = edccif_core::models::RangeBearing::new([1.0, 2.0], 0.1, 0.01).unwrap();
    /// assert_eq!(s.position().as_slice(), &[1.0, 2.0]);
    /// ```
    pub fn position(&self) -> Vector2<T> {
        self.position
    }

    /// `([r, 0], [1, cos b], [0, sin b])` of position `q`: the range and the
    /// bearing's unit vector `(dx, dy)/r`, `(1, 0)` on the sensor.
    #[inline]
    fn unit_images(&self, q: &Vector2<T>) -> (Vector2<T>, Vector2<T>, Vector2<T>) {
        let d = q - self.position;
        let r = (d[0] * d[0] + d[1] * d[1]).sqrt();
        let (cb, sb) = if r > T::zero() {
            (d[0] / r, d[1] / r)
        } else {
            (T::one(), T::zero())
        };
        (
            Vector2::new(r, T::zero()),
            Vector2::new(T::one(), cb),
            Vector2::new(T::zero(), sb),
        )
    }
}

impl<T: RealField + Copy, const N: usize> MeasurementModel<T, N, 2> for RangeBearing<T> {
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 2> {
        if N < 2 {
            return nan_vector();
        }
        let d = Vector2::new(x[0], x[1]) - self.position;
        Vector2::new(
            (d[0] * d[0] + d[1] * d[1]).sqrt(),
            atan2_if(self.fast_trig, d[1], d[0]),
        )
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, 2, 2> {
        self.r
    }
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        k == 1
    }
    #[inline]
    fn fast_trig(&self) -> bool {
        self.fast_trig
    }
    /// The bearing's unit vector from the geometry, `(dx, dy)/|d|`, and `(1, 0)`
    /// (that of `atan2(0, 0) = 0`) on the sensor.
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<T, N>,
    ) -> (SVector<T, 2>, SVector<T, 2>, SVector<T, 2>) {
        if N < 2 {
            return (nan_vector(), nan_vector(), nan_vector());
        }
        let d = Vector2::new(x[0], x[1]) - self.position;
        let (mut z, co, si) = self.unit_images(&Vector2::new(x[0], x[1]));
        // The reference path's per-point hook: the library's `atan2`.
        z[1] = d[1].atan2(d[0]);
        (z, co, si)
    }
    /// The range and the bearing's unit vector (no `atan2`).
    #[inline]
    fn measure_points_trig(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        plus: &mut PointImages<T, 2, N>,
        minus: &mut PointImages<T, 2, N>,
        centre: Option<&mut PointImages<T, 2, 1>>,
    ) {
        if N < 2 {
            return self.measure_points(x, offsets, plus, minus, centre);
        }
        position_points(x, offsets, plus, minus, centre, |q: &Vector2<T>| {
            self.unit_images(q)
        });
    }
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 2, N> {
        if N < 2 {
            return nan_matrix();
        }
        let d = Vector2::new(x[0], x[1]) - self.position;
        let r2 = d[0] * d[0] + d[1] * d[1];
        let r = r2.sqrt();
        let mut g = SMatrix::<T, 2, N>::zeros();
        g[(0, 0)] = d[0] / r;
        g[(0, 1)] = d[1] / r;
        g[(1, 0)] = -d[1] / r2;
        g[(1, 1)] = d[0] / r2;
        g
    }
    position_jacobian_products!(2, 2);
}

/// Bearing of a target in the plane seen from a sensor at `s`:
/// `z = atan2(dy, dx)` with `d = p − s`, `R = σb²`; the one component is an angle.
///
/// ```
/// use edccif_core::{models::BearingOnly, model::MeasurementModel};
/// use nalgebra::Vector4;
/// let s = BearingOnly::new([0.0, 0.0], 0.01).unwrap();
/// let z = MeasurementModel::<f64, 4, 1>::measure(&s, &Vector4::new(-1.0, 0.0, 0.0, 0.0));
/// assert!((z[0] - core::f64::consts::PI).abs() < 1e-15);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BearingOnly<T: RealField + Copy> {
    position: Vector2<T>,
    r: SMatrix<T, 1, 1>,
    /// Fast trigonometry of the sigma-point transforms (default on):
    /// see [`MeasurementModel::fast_trig`].
    #[cfg_attr(feature = "serde", serde(default = "super::yes"))]
    fast_trig: bool,
}

impl<T: RealField + Copy> BearingOnly<T> {
    /// A sensor at `position` (finite) with bearing noise `sigma_b > 0` (standard
    /// deviation, radians).
    ///
    /// ```
    /// use edccif_core::{models::BearingOnly, Error};
    /// assert!(matches!(BearingOnly::new([0.0, 0.0], 0.0), Err(Error::InvalidParameter { what: "sigma_b", .. })));
    /// ```
    pub fn new(position: [T; 2], sigma_b: T) -> Result<Self> {
        let position = sensor_position(position)?;
        Ok(Self {
            position,
            r: diag_noise([sigma_b], "sigma_b")?,
            fast_trig: true,
        })
    }
    /// The same sensor with fast trigonometry switched on (the default) or off
    /// ([`MeasurementModel::fast_trig`]; off: the platform libm, bit-exact):
    /// no `atan2` per sigma point, and the remaining `atan2` (the circular mean,
    /// `h(x)` for the EKF) by the kernel [`crate::trig::atan2`], within 1 ulp.
    ///
    /// ```
    /// use edccif_core::{model::MeasurementModel, models::BearingOnly};
    /// let s = BearingOnly::new([0.0, 0.0], 0.01)?.with_fast_trig(true);
    /// assert!(MeasurementModel::<f64, 4, 1>::fast_trig(&s));
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    #[must_use]
    pub fn with_fast_trig(mut self, on: bool) -> Self {
        self.fast_trig = on;
        self
    }
    /// The sensor position.
    ///
    /// ```
    /// let s = edccif_core::models::BearingOnly::new([1.0, 2.0], 0.01).unwrap();
    /// assert_eq!(s.position().as_slice(), &[1.0, 2.0]);
    /// ```
    pub fn position(&self) -> Vector2<T> {
        self.position
    }

    /// `([0], [cos b], [sin b])` of position `q`: the bearing's unit vector
    /// `(dx, dy)/|d|`, `(1, 0)` on the sensor.
    #[inline]
    fn unit_images(&self, q: &Vector2<T>) -> (Vector1<T>, Vector1<T>, Vector1<T>) {
        let (dx, dy) = (q[0] - self.position[0], q[1] - self.position[1]);
        let r = (dx * dx + dy * dy).sqrt();
        let (cb, sb) = if r > T::zero() {
            (dx / r, dy / r)
        } else {
            (T::one(), T::zero())
        };
        (Vector1::new(T::zero()), Vector1::new(cb), Vector1::new(sb))
    }
}

impl<T: RealField + Copy, const N: usize> MeasurementModel<T, N, 1> for BearingOnly<T> {
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 1> {
        if N < 2 {
            return nan_vector();
        }
        Vector1::new(atan2_if(
            self.fast_trig,
            x[1] - self.position[1],
            x[0] - self.position[0],
        ))
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, 1, 1> {
        self.r
    }
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        k == 0
    }
    #[inline]
    fn fast_trig(&self) -> bool {
        self.fast_trig
    }
    /// The bearing's unit vector `(dx, dy)/|d|`, `(1, 0)` on the sensor.
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<T, N>,
    ) -> (SVector<T, 1>, SVector<T, 1>, SVector<T, 1>) {
        if N < 2 {
            return (nan_vector(), nan_vector(), nan_vector());
        }
        let (dx, dy) = (x[0] - self.position[0], x[1] - self.position[1]);
        let (_, co, si) = self.unit_images(&Vector2::new(x[0], x[1]));
        // The reference path's per-point hook: the library's `atan2`.
        (Vector1::new(dy.atan2(dx)), co, si)
    }
    /// The bearing's unit vector (no `atan2`).
    #[inline]
    fn measure_points_trig(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        plus: &mut PointImages<T, 1, N>,
        minus: &mut PointImages<T, 1, N>,
        centre: Option<&mut PointImages<T, 1, 1>>,
    ) {
        if N < 2 {
            return self.measure_points(x, offsets, plus, minus, centre);
        }
        position_points(x, offsets, plus, minus, centre, |q: &Vector2<T>| {
            self.unit_images(q)
        });
    }
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 1, N> {
        if N < 2 {
            return nan_matrix();
        }
        let (dx, dy) = (x[0] - self.position[0], x[1] - self.position[1]);
        let r2 = dx * dx + dy * dy;
        let mut g = SMatrix::<T, 1, N>::zeros();
        g[(0, 0)] = -dy / r2;
        g[(0, 1)] = dx / r2;
        g
    }
    position_jacobian_products!(1, 2);
}

/// Range from a sensor at `s` in `D` dimensions (2-D or 3-D; the position is the
/// first `D` state components): `z = |p − s|`, `R = σr²`.
///
/// ```
/// use edccif_core::{models::RangeOnly, model::MeasurementModel};
/// use nalgebra::{SVector, Vector4};
/// let planar = RangeOnly::new([0.0, 0.0], 0.1).unwrap();
/// assert_eq!(MeasurementModel::<f64, 4, 1>::measure(&planar, &Vector4::new(3.0, 4.0, 9.0, 9.0))[0], 5.0);
/// let spatial = RangeOnly::new([0.0, 0.0, 1.0], 0.1).unwrap();
/// let x = SVector::<f64, 6>::from([2.0, 3.0, 7.0, 0.0, 0.0, 0.0]);
/// assert_eq!(MeasurementModel::<f64, 6, 1>::measure(&spatial, &x)[0], 7.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RangeOnly<T: RealField + Copy, const D: usize> {
    position: SVector<T, D>,
    r: SMatrix<T, 1, 1>,
}

impl<T: RealField + Copy, const D: usize> RangeOnly<T, D> {
    /// A sensor at `position` (finite, `D` = 2 or 3 coordinates) with range noise
    /// `sigma_r > 0` (standard deviation).
    ///
    /// ```
    /// use edccif_core::{models::RangeOnly, Error};
    /// assert!(matches!(RangeOnly::new([0.0; 3], f64::NAN), Err(Error::InvalidParameter { what: "sigma_r", .. })));
    /// assert!(matches!(RangeOnly::new([0.0; 4], 0.1), Err(Error::InvalidParameter { what: "RangeOnly dimension D", .. })));
    /// ```
    pub fn new(position: [T; D], sigma_r: T) -> Result<Self> {
        if D != 2 && D != 3 {
            return Err(Error::InvalidParameter {
                what: "RangeOnly dimension D",
                expected: "2 or 3 sensor coordinates",
            });
        }
        let position = sensor_position(position)?;
        Ok(Self {
            position,
            r: diag_noise([sigma_r], "sigma_r")?,
        })
    }
    /// The sensor position.
    ///
    /// ```
    /// let s = edccif_core::models::RangeOnly::new([1.0, 2.0], 0.1).unwrap();
    /// assert_eq!(s.position().as_slice(), &[1.0, 2.0]);
    /// ```
    pub fn position(&self) -> SVector<T, D> {
        self.position
    }
}

impl<T: RealField + Copy, const N: usize, const D: usize> MeasurementModel<T, N, 1>
    for RangeOnly<T, D>
{
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 1> {
        if N < D {
            return nan_vector();
        }
        let mut r2 = T::zero();
        for a in 0..D {
            let d = x[a] - self.position[a];
            r2 += d * d;
        }
        Vector1::new(r2.sqrt())
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, 1, 1> {
        self.r
    }
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 1, N> {
        if N < D {
            return nan_matrix();
        }
        let r = MeasurementModel::<T, N, 1>::measure(self, x)[0];
        let mut g = SMatrix::<T, 1, N>::zeros();
        for a in 0..D {
            g[(0, a)] = (x[a] - self.position[a]) / r;
        }
        g
    }
    position_jacobian_products!(1, D);
}

/// A 2-D position measurement, `z = (x, y) + v`, `v ~ N(0, R)`, for any state
/// whose first two components are the position.
///
/// ```
/// use edccif_core::{models::Position2, model::MeasurementModel};
/// use nalgebra::Vector4;
/// let cam = Position2::new([0.1, 0.2]).unwrap();
/// let z = MeasurementModel::<f64, 4, 2>::measure(&cam, &Vector4::new(1.0, 2.0, 3.0, 4.0));
/// assert_eq!(z.as_slice(), &[1.0, 2.0]);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Position2<T: RealField + Copy> {
    r: SMatrix<T, 2, 2>,
}

impl<T: RealField + Copy> Position2<T> {
    /// Independent noise with standard deviations `sigma` per axis (`> 0`).
    ///
    /// ```
    /// use edccif_core::{models::Position2, Error};
    /// assert!(matches!(Position2::new([0.1, -0.1]), Err(Error::InvalidParameter { what: "sigma", .. })));
    /// ```
    pub fn new(sigma: [T; 2]) -> Result<Self> {
        Ok(Self {
            r: diag_noise(sigma, "sigma")?,
        })
    }
    /// A full noise covariance (finite, symmetric, positive definite).
    ///
    /// ```
    /// use edccif_core::{models::Position2, Error};
    /// use nalgebra::Matrix2;
    /// assert!(Position2::with_covariance(Matrix2::new(1.0, 0.5, 0.5, 1.0)).is_ok());
    /// assert!(Position2::with_covariance(Matrix2::new(1.0, 2.0, 2.0, 1.0)).is_err());
    /// ```
    pub fn with_covariance(r: SMatrix<T, 2, 2>) -> Result<Self> {
        validate_covariance(&r, "measurement noise R")?;
        Ok(Self { r })
    }
}

impl<T: RealField + Copy, const N: usize> MeasurementModel<T, N, 2> for Position2<T> {
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 2> {
        if N < 2 {
            return nan_vector();
        }
        Vector2::new(x[0], x[1])
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, 2, 2> {
        self.r
    }
    fn jacobian(&self, _x: &SVector<T, N>) -> SMatrix<T, 2, N> {
        if N < 2 {
            return nan_matrix();
        }
        let mut g = SMatrix::<T, 2, N>::zeros();
        for a in 0..2 {
            g[(a, a)] = T::one();
        }
        g
    }
    position_jacobian_products!(2, 2);
}

/// A 3-D position measurement (an RGB-D camera's detection after deprojection),
/// `z = p + v`, `v ~ N(0, R)`, for any state whose first three components are the
/// position.
///
/// ```
/// use edccif_core::{models::Position3, model::MeasurementModel};
/// use nalgebra::SVector;
/// let cam = Position3::new([0.01, 0.01, 0.02]).unwrap();
/// let z = MeasurementModel::<f64, 6, 3>::measure(&cam, &SVector::<f64, 6>::from([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]));
/// assert_eq!(z.as_slice(), &[1.0, 2.0, 3.0]);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Position3<T: RealField + Copy> {
    r: SMatrix<T, 3, 3>,
}

impl<T: RealField + Copy> Position3<T> {
    /// Independent noise with standard deviations `sigma` per axis (`> 0`).
    ///
    /// ```
    /// use edccif_core::{models::Position3, Error};
    /// assert!(matches!(Position3::new([0.1, 0.1, 0.0]), Err(Error::InvalidParameter { what: "sigma", .. })));
    /// ```
    pub fn new(sigma: [T; 3]) -> Result<Self> {
        Ok(Self {
            r: diag_noise(sigma, "sigma")?,
        })
    }
    /// A full noise covariance (finite, symmetric, positive definite).
    ///
    /// ```
    /// use edccif_core::{models::Position3, Error};
    /// use nalgebra::Matrix3;
    /// assert!(Position3::with_covariance(Matrix3::identity() * 0.01).is_ok());
    /// ```
    pub fn with_covariance(r: SMatrix<T, 3, 3>) -> Result<Self> {
        validate_covariance(&r, "measurement noise R")?;
        Ok(Self { r })
    }
}

impl<T: RealField + Copy, const N: usize> MeasurementModel<T, N, 3> for Position3<T> {
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 3> {
        if N < 3 {
            return nan_vector();
        }
        Vector3::new(x[0], x[1], x[2])
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, 3, 3> {
        self.r
    }
    fn jacobian(&self, _x: &SVector<T, N>) -> SMatrix<T, 3, N> {
        if N < 3 {
            return nan_matrix();
        }
        let mut g = SMatrix::<T, 3, N>::zeros();
        for a in 0..3 {
            g[(a, a)] = T::one();
        }
        g
    }
    position_jacobian_products!(3, 3);
}

/// Linear measurement `z = H x + v`, `v ~ N(0, R)`.
///
/// ```
/// use edccif_core::{models::LinearMeasurement, model::MeasurementModel};
/// use nalgebra::{Matrix1, Matrix1x2, Vector1, Vector2};
/// let s = LinearMeasurement::new(Matrix1x2::new(1.0, -1.0), Matrix1::new(0.1)).unwrap();
/// assert_eq!(s.measure(&Vector2::new(3.0, 1.0)), Vector1::new(2.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LinearMeasurement<T: RealField + Copy, const N: usize, const M: usize> {
    h: SMatrix<T, M, N>,
    r: SMatrix<T, M, M>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> LinearMeasurement<T, N, M> {
    /// `H` finite; `R` finite, symmetric, positive definite.
    ///
    /// ```
    /// use edccif_core::{models::LinearMeasurement, Error};
    /// use nalgebra::{Matrix1, Matrix1x2};
    /// let e = LinearMeasurement::new(Matrix1x2::new(1.0, 0.0), Matrix1::new(-1.0)).unwrap_err();
    /// assert!(matches!(e, Error::NotPositiveDefinite { what: "measurement noise R" }));
    /// ```
    pub fn new(h: SMatrix<T, M, N>, r: SMatrix<T, M, M>) -> Result<Self> {
        crate::linalg::check_finite(&h, "measurement matrix H")?;
        validate_covariance(&r, "measurement noise R")?;
        Ok(Self { h, r })
    }
}

impl<T: RealField + Copy, const N: usize, const M: usize> MeasurementModel<T, N, M>
    for LinearMeasurement<T, N, M>
{
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, M> {
        self.h * x
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, M, M> {
        self.r
    }
    #[inline]
    fn jacobian(&self, _x: &SVector<T, N>) -> SMatrix<T, M, N> {
        self.h
    }
}
