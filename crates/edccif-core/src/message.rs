//! What crosses the network, and what a node holds: Gaussian estimates,
//! information pairs, contributions, observations and packets. "Not sent" and
//! "no measurement" are explicit variants, never NaN.

use nalgebra::{RealField, SMatrix, SVector};

use crate::error::Result;
use crate::linalg::{chol_inverse, cholesky, spd_inverse, validate_covariance, validate_vector};

/// A Gaussian estimate in covariance form: mean `x` and covariance `p`.
///
/// ```
/// use edccif_core::Gaussian;
/// use nalgebra::{Matrix2, Vector2};
/// let g = Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::identity()).unwrap();
/// let back = g.to_info().unwrap().to_gaussian().unwrap();
/// assert!((back.x - g.x).norm() < 1e-12);
/// assert!(Gaussian::new(Vector2::new(f64::NAN, 0.0), Matrix2::identity()).is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Gaussian<T: RealField + Copy, const N: usize> {
    /// Mean.
    pub x: SVector<T, N>,
    /// Covariance (symmetric positive definite).
    pub p: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> Gaussian<T, N> {
    /// A validated estimate: `x` finite, `p` finite, symmetric and positive definite.
    pub fn new(x: SVector<T, N>, p: SMatrix<T, N, N>) -> Result<Self> {
        validate_vector(&x, "state estimate x")?;
        validate_covariance(&p, "covariance P")?;
        Ok(Self { x, p })
    }
    /// The information pair `(ŷ, Y) = (P⁻¹ x, P⁻¹)`.
    pub fn to_info(&self) -> Result<InfoPair<T, N>> {
        let y = spd_inverse(&self.p, "covariance P")?;
        Ok(InfoPair {
            y: y * self.x,
            ymat: y,
        })
    }
}

/// An information pair `(ŷ, Y)`: information vector and matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct InfoPair<T: RealField + Copy, const N: usize> {
    /// Information vector `ŷ = Y x̂`.
    pub y: SVector<T, N>,
    /// Information matrix `Y = P⁻¹`.
    pub ymat: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> InfoPair<T, N> {
    /// The zero pair (no information).
    pub fn zeros() -> Self {
        Self {
            y: SVector::zeros(),
            ymat: SMatrix::zeros(),
        }
    }
    /// Back to covariance form: `P = Y⁻¹`, `x̂ = P ŷ` (via one Cholesky factorisation).
    pub fn to_gaussian(&self) -> Result<Gaussian<T, N>> {
        let ch = cholesky(&self.ymat, "information matrix Y")?;
        let p = chol_inverse(&ch);
        let x = ch.solve(&self.y);
        // For a badly conditioned Y the rounded inverse can be indefinite: the
        // result must be a usable covariance, so it is factorised too.
        crate::linalg::cholesky(&p, "covariance P = Y⁻¹")?;
        crate::linalg::check_finite(&x, "state estimate x = Y⁻¹ŷ")?;
        Ok(Gaussian { x, p })
    }
}

/// A node's measurement contribution `(ī, Ī)` in information form
/// (what an estimator sends its neighbours in the diffusion adaptation).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Contribution<T: RealField + Copy, const N: usize> {
    /// Information-vector contribution `ī`.
    pub i: SVector<T, N>,
    /// Information-matrix contribution `Ī` (may be indefinite for an
    /// untriggered step, see ALGORITHM.md §4).
    pub imat: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> Contribution<T, N> {
    /// The zero contribution (no measurement information).
    pub fn zeros() -> Self {
        Self {
            i: SVector::zeros(),
            imat: SMatrix::zeros(),
        }
    }
}

/// What a node's sensor delivered at a step.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Observation<T: RealField + Copy, const M: usize> {
    /// A measurement was taken (the trigger then decides whether it is sent).
    Measured(SVector<T, M>),
    /// No measurement this step (sensor outage, dropped frame).
    Missing,
}

/// A message that may or may not have been sent (or may have been lost).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Packet<P> {
    /// The payload arrived.
    Sent(P),
    /// Nothing was sent (or nothing arrived).
    NotSent,
}

impl<P> Packet<P> {
    /// The payload, if sent.
    pub fn sent(&self) -> Option<&P> {
        match self {
            Packet::Sent(p) => Some(p),
            Packet::NotSent => None,
        }
    }
}
