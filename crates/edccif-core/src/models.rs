//! Built-in models: the default scenario's coordinated-turn motion and
//! range/pitch/azimuth sensor (ALGORITHM.md §1), a constant-velocity motion and a
//! 3-D position sensor (an RGB-D camera after deprojection) for the real-world
//! configuration, and linear models (useful as oracles).

use nalgebra::{RealField, SMatrix, SVector, Vector3};

use crate::error::{Error, Result};
use crate::linalg::{c, validate_covariance, validate_positive};
use crate::model::{MeasurementModel, MotionModel};

/// State dimension of [`CoordinatedTurn`]: `[px, py, pz, vx, vy, vz, ω]`.
pub const CT_DIM: usize = 7;

/// Coordinated turn in the xy plane with constant climb rate (ALGORITHM.md §1).
///
/// State `x = [px, py, pz, vx, vy, vz, ω]`; the turn rate `ω` is a random walk.
///
/// ```
/// use edccif_core::{models::CoordinatedTurn, model::MotionModel};
/// use nalgebra::SVector;
/// let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
/// let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]);
/// let x1 = ct.transition(&x, 0.1);
/// // speed in the plane is preserved by the turn
/// assert!(((x1[3].powi(2) + x1[4].powi(2)).sqrt() - 1.5).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CoordinatedTurn<T: RealField + Copy> {
    q1: T,
    q2: T,
}

/// The piecewise white-acceleration block `q·[[dt³/3, dt²/2], [dt²/2, dt]]` placed on
/// axes `(p, v)` of `m`.
fn add_cv_block<T: RealField + Copy, const N: usize>(
    m: &mut SMatrix<T, N, N>,
    p: usize,
    v: usize,
    q: T,
    dt: T,
) {
    let dt2 = dt * dt;
    m[(p, p)] = q * dt2 * dt / c(3.0);
    m[(p, v)] = q * dt2 / c(2.0);
    m[(v, p)] = m[(p, v)];
    m[(v, v)] = q * dt;
}

impl<T: RealField + Copy> CoordinatedTurn<T> {
    /// Builds the model; `q1 ≥ 0`, `q2 ≥ 0`, both finite. The time step is given
    /// at each call ([`MotionModel::transition`]).
    pub fn new(q1: T, q2: T) -> Result<Self> {
        validate_positive(q1, "q1", true)?;
        validate_positive(q2, "q2", true)?;
        Ok(Self { q1, q2 })
    }
    /// Position/velocity noise intensity `q1`.
    pub fn q1(&self) -> T {
        self.q1
    }
    /// Turn-rate noise intensity `q2`.
    pub fn q2(&self) -> T {
        self.q2
    }

    /// `(S, C, dS/dω, dC/dω)` with the small-|ω| branch of ALGORITHM.md §1, given
    /// `(sin ωdt, cos ωdt)` (computed once per call by the callers).
    #[inline]
    fn sc(w: T, dt: T, sn: T, co: T) -> (T, T, T, T) {
        if w.abs() < c(1e-9) {
            (dt, w * dt * dt / c(2.0), T::zero(), dt * dt / c(2.0))
        } else {
            let sf = sn / w;
            let cf = (T::one() - co) / w;
            let ds = (dt * co * w - sn) / (w * w);
            let dc = (dt * sn * w - (T::one() - co)) / (w * w);
            (sf, cf, ds, dc)
        }
    }
}

impl<T: RealField + Copy> MotionModel<T, 7> for CoordinatedTurn<T> {
    #[inline]
    fn transition(&self, x: &SVector<T, 7>, dt: T) -> SVector<T, 7> {
        let w = x[6];
        let (sn, cs) = (w * dt).sin_cos();
        let (s, cc, _, _) = Self::sc(w, dt, sn, cs);
        let (vx, vy) = (x[3], x[4]);
        SVector::<T, 7>::from([
            x[0] + s * vx - cc * vy,
            x[1] + cc * vx + s * vy,
            x[2] + dt * x[5],
            cs * vx - sn * vy,
            sn * vx + cs * vy,
            x[5],
            w,
        ])
    }

    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, 7, 7> {
        let mut q = SMatrix::<T, 7, 7>::zeros();
        for a in 0..3 {
            add_cv_block(&mut q, a, a + 3, self.q1, dt);
        }
        q[(6, 6)] = self.q2 * dt;
        q
    }

    fn jacobian(&self, x: &SVector<T, 7>, dt: T) -> SMatrix<T, 7, 7> {
        let w = x[6];
        let (sn, cs) = (w * dt).sin_cos();
        let (s, cc, ds, dc) = Self::sc(w, dt, sn, cs);
        let (vx, vy) = (x[3], x[4]);
        let mut f = SMatrix::<T, 7, 7>::identity();
        f[(0, 3)] = s;
        f[(0, 4)] = -cc;
        f[(0, 6)] = ds * vx - dc * vy;
        f[(1, 3)] = cc;
        f[(1, 4)] = s;
        f[(1, 6)] = dc * vx + ds * vy;
        f[(2, 5)] = dt;
        f[(3, 3)] = cs;
        f[(3, 4)] = -sn;
        f[(3, 6)] = dt * (-sn * vx - cs * vy);
        f[(4, 3)] = sn;
        f[(4, 4)] = cs;
        f[(4, 6)] = dt * (cs * vx - sn * vy);
        f
    }
}

/// Constant velocity in 3-D, state `[px, py, pz, vx, vy, vz]`, white-acceleration
/// noise of intensity `q` on each axis.
///
/// ```
/// use edccif_core::{models::ConstantVelocity, model::MotionModel};
/// use nalgebra::SVector;
/// let cv = ConstantVelocity::new(1.0).unwrap();
/// let x = cv.transition(&SVector::<f64, 6>::from([0.0, 0.0, 0.0, 1.0, 2.0, 3.0]), 0.5);
/// assert_eq!(x[2], 1.5);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ConstantVelocity<T: RealField + Copy> {
    q: T,
}

impl<T: RealField + Copy> ConstantVelocity<T> {
    /// Builds the model; `q ≥ 0`, finite. The time step is given at each call.
    pub fn new(q: T) -> Result<Self> {
        validate_positive(q, "q", true)?;
        Ok(Self { q })
    }
    /// White-acceleration noise intensity `q`.
    pub fn q(&self) -> T {
        self.q
    }
}

impl<T: RealField + Copy> MotionModel<T, 6> for ConstantVelocity<T> {
    #[inline]
    fn transition(&self, x: &SVector<T, 6>, dt: T) -> SVector<T, 6> {
        let mut y = *x;
        for a in 0..3 {
            y[a] += dt * x[a + 3];
        }
        y
    }
    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, 6, 6> {
        let mut m = SMatrix::<T, 6, 6>::zeros();
        for a in 0..3 {
            add_cv_block(&mut m, a, a + 3, self.q, dt);
        }
        m
    }
    fn jacobian(&self, _x: &SVector<T, 6>, dt: T) -> SMatrix<T, 6, 6> {
        let mut f = SMatrix::<T, 6, 6>::identity();
        for a in 0..3 {
            f[(a, a + 3)] = dt;
        }
        f
    }
}

/// Range, pitch and azimuth of the target seen from a sensor at `s`
/// (ALGORITHM.md §1): with `d = p − s`, `z = [|d|, atan2(dz, hypot(dx, dy)),
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
}

impl<T: RealField + Copy> RangePitchAzimuth<T> {
    /// A sensor at `position` with range noise `sigma_r` and angle noise `sigma_a`
    /// (standard deviations, `> 0`).
    pub fn new(position: [T; 3], sigma_r: T, sigma_a: T) -> Result<Self> {
        let position = Vector3::from(position);
        if !position.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                what: "sensor position",
            });
        }
        validate_positive(sigma_r, "sigma_r", false)?;
        validate_positive(sigma_a, "sigma_a", false)?;
        let r = SMatrix::<T, 3, 3>::from_diagonal(&Vector3::new(
            sigma_r * sigma_r,
            sigma_a * sigma_a,
            sigma_a * sigma_a,
        ));
        Ok(Self { position, r })
    }
    /// The sensor position.
    pub fn position(&self) -> Vector3<T> {
        self.position
    }
}

impl<T: RealField + Copy, const N: usize> MeasurementModel<T, N, 3> for RangePitchAzimuth<T> {
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 3> {
        let d = Vector3::new(x[0], x[1], x[2]) - self.position;
        // Plain roots: positions are metres to kilometres, far from overflow.
        let rho2 = d[0] * d[0] + d[1] * d[1];
        let rho = rho2.sqrt();
        Vector3::new(
            (rho2 + d[2] * d[2]).sqrt(),
            d[2].atan2(rho),
            d[1].atan2(d[0]),
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
    /// Unit vectors from the geometry: `cos φ = h/r`, `sin φ = dz/r`,
    /// `cos ρ = dx/h`, `sin ρ = dy/h` (`h = hypot(dx, dy)`), with `atan2(0, 0) = 0`'s
    /// `(1, 0)` at the degenerate points.
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<T, N>,
    ) -> (SVector<T, 3>, SVector<T, 3>, SVector<T, 3>) {
        let d = Vector3::new(x[0], x[1], x[2]) - self.position;
        let rho2 = d[0] * d[0] + d[1] * d[1];
        let rho = rho2.sqrt();
        let r = (rho2 + d[2] * d[2]).sqrt();
        let z = Vector3::new(r, d[2].atan2(rho), d[1].atan2(d[0]));
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
            z,
            Vector3::new(T::one(), cp, ca),
            Vector3::new(T::zero(), sp, sa),
        )
    }
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, 3, N> {
        let d = Vector3::new(x[0], x[1], x[2]) - self.position;
        let rho2 = d[0] * d[0] + d[1] * d[1];
        let rho = rho2.sqrt();
        let r2 = rho2 + d[2] * d[2];
        let r = r2.sqrt();
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
    pub fn new(sigma: [T; 3]) -> Result<Self> {
        for s in sigma {
            validate_positive(s, "sigma", false)?;
        }
        Ok(Self {
            r: SMatrix::<T, 3, 3>::from_diagonal(&Vector3::new(
                sigma[0] * sigma[0],
                sigma[1] * sigma[1],
                sigma[2] * sigma[2],
            )),
        })
    }
    /// A full noise covariance (finite, symmetric, positive definite).
    pub fn with_covariance(r: SMatrix<T, 3, 3>) -> Result<Self> {
        validate_covariance(&r, "measurement noise R")?;
        Ok(Self { r })
    }
}

impl<T: RealField + Copy, const N: usize> MeasurementModel<T, N, 3> for Position3<T> {
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, 3> {
        Vector3::new(x[0], x[1], x[2])
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, 3, 3> {
        self.r
    }
    fn jacobian(&self, _x: &SVector<T, N>) -> SMatrix<T, 3, N> {
        let mut g = SMatrix::<T, 3, N>::zeros();
        for a in 0..3 {
            g[(a, a)] = T::one();
        }
        g
    }
}

/// Linear motion `x' = F x + w`, `w ~ N(0, Q)`, with a fixed `F` and `Q`: one
/// step of a discrete-time model whatever `dt` is passed (useful as an oracle and
/// for models already discretised at one rate).
///
/// ```
/// use edccif_core::{models::LinearMotion, model::MotionModel};
/// use nalgebra::{Matrix2, Vector2};
/// let m = LinearMotion::new(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity()).unwrap();
/// assert_eq!(m.transition(&Vector2::new(1.0, 2.0), 1.0), Vector2::new(3.0, 2.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LinearMotion<T: RealField + Copy, const N: usize> {
    f: SMatrix<T, N, N>,
    q: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> LinearMotion<T, N> {
    /// `F` finite, `Q` finite and symmetric.
    pub fn new(f: SMatrix<T, N, N>, q: SMatrix<T, N, N>) -> Result<Self> {
        crate::linalg::check_finite(&f, "transition matrix F")?;
        crate::linalg::check_finite(&q, "process noise Q")?;
        Ok(Self { f, q })
    }
}

impl<T: RealField + Copy, const N: usize> MotionModel<T, N> for LinearMotion<T, N> {
    #[inline]
    fn transition(&self, x: &SVector<T, N>, _dt: T) -> SVector<T, N> {
        self.f * x
    }
    #[inline]
    fn process_noise(&self, _dt: T) -> SMatrix<T, N, N> {
        self.q
    }
    #[inline]
    fn jacobian(&self, _x: &SVector<T, N>, _dt: T) -> SMatrix<T, N, N> {
        self.f
    }
}

/// Linear measurement `z = H x + v`, `v ~ N(0, R)`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LinearMeasurement<T: RealField + Copy, const N: usize, const M: usize> {
    h: SMatrix<T, M, N>,
    r: SMatrix<T, M, M>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> LinearMeasurement<T, N, M> {
    /// `H` finite; `R` finite, symmetric, positive definite.
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
