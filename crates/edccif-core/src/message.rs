//! What crosses the network, and what a node holds: Gaussian estimates,
//! information pairs, contributions, observations and packets. "Not sent" and
//! "no measurement" are explicit variants, never NaN.

use nalgebra::{Cholesky, Const, RealField, SMatrix, SVector};

use crate::error::{let_ok, Result};
use crate::linalg::{
    check_finite, chol_inverse, chol_inverse_into, cholesky, spd_inverse, sym, validate_covariance,
    validate_vector,
};

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

    /// [`to_info`](Self::to_info) from an already computed factor
    /// `ch = cholesky(&self.p, ..)`: the same inverse, bit for bit (the factor
    /// is the same), without factorising `P` a second time.
    pub(crate) fn info_from_factor(&self, ch: &Cholesky<T, Const<N>>) -> Result<InfoPair<T, N>> {
        let y = chol_inverse(ch);
        check_finite(&y, "covariance P")?;
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
    /// The pair updated by a contribution, `(ŷ + ī, sym(Y + Ī))`: the CIF's
    /// local posterior from its prior. One expression for every caller (the
    /// local step's result and the network step's adaptation guard), so the
    /// bits agree wherever it is formed.
    #[inline]
    pub(crate) fn updated(&self, c: &Contribution<T, N>) -> Self {
        InfoPair {
            y: self.y + c.i,
            ymat: sym(&(self.ymat + c.imat)),
        }
    }

    /// Back to covariance form: `P = Y⁻¹`, `x̂ = P ŷ` (via one Cholesky factorisation).
    ///
    /// The result is a usable covariance: for a badly conditioned `Y` the rounded
    /// inverse can be indefinite, so unless `Y` is provably well conditioned
    /// (`tr(Y)·tr(P)` small) `P` is factorised too and rejected when that fails.
    pub fn to_gaussian(&self) -> Result<Gaussian<T, N>> {
        let mut g = Gaussian {
            x: SVector::zeros(),
            p: SMatrix::zeros(),
        };
        self.write_gaussian(&mut g)?;
        Ok(g)
    }

    /// [`to_gaussian`](Self::to_gaussian) writing into `out` (a caller's
    /// buffer) instead of returning the estimate, so that the network step does
    /// not move it through a `Result`; on error `out` may hold part of it.
    #[inline]
    pub(crate) fn write_gaussian(&self, out: &mut Gaussian<T, N>) -> Result<()> {
        const WHAT_P: &str = "covariance P = Y⁻¹";
        let_ok!(ch = cholesky(&self.ymat, "information matrix Y"));
        chol_inverse_into(ch, &mut out.p);
        out.x = ch.solve(&self.y);
        if inverse_surely_pd(&self.ymat, &out.p) {
            // The factorisation of P would succeed; only its finiteness check
            // (the first thing `cholesky` does) is left to make.
            check_finite(&out.p, WHAT_P)?;
        } else if let Err(e) = &cholesky(&out.p, WHAT_P) {
            return Err(*e);
        }
        check_finite(&out.x, "state estimate x = Y⁻¹ŷ")
    }
}

/// Whether `p`, the [`chol_inverse`] of the positive-definite `y`, is certain to
/// pass [`cholesky`] (finite entries aside): true when `tr(Y)·tr(P)` is small and
/// both traces are far from under- and overflow.
///
/// Why it suffices (`u` the unit roundoff, `n = N`, `γ = n u/(1 − n u)`):
/// `tr(Y) ≥ λmax(Y)`; the computed `M ≈ L⁻¹` satisfies `L M = I + R` with
/// `‖R‖ ≤ γ ‖L‖_F ‖M‖_F ≈ γ √(tr Y · tr P) ≪ 1/2`, so `λmin(MᵀM) ≥ 1/(4 tr Y)`;
/// the rounding of the product `Mᵀ M` is at most `γ tr P` in norm, so the
/// computed `P` is positive definite with `κ₂(P) ≤ 4.1 tr(Y) tr(P)`, and
/// Cholesky completes for `κ₂ < 1/(n (n+1) u)` (Demmel; Higham, *Accuracy and
/// Stability*, Thm 10.7). The bound used, `tr Y · tr P ≤ 1/(256 n² ε)` (`ε = 2u`;
/// ≈ 3.6e11 for `f64`, `n = 7`), keeps a margin of more than 100 over that; the
/// trace range `[ε⁴, ε⁻⁴]` keeps every factor entry normal. Otherwise the caller
/// factorises `P` (the result is the same; only its cost differs).
#[inline]
fn inverse_surely_pd<T: RealField + Copy, const N: usize>(
    y: &SMatrix<T, N, N>,
    p: &SMatrix<T, N, N>,
) -> bool {
    let (mut ty, mut tp) = (T::zero(), T::zero());
    for i in 0..N {
        ty += y[(i, i)];
        tp += p[(i, i)];
    }
    traces_surely_pd::<T, N>(ty, tp)
}

/// [`inverse_surely_pd`] from the two traces (summed from zero in index order).
#[inline(always)]
pub(crate) fn traces_surely_pd<T: RealField + Copy, const N: usize>(ty: T, tp: T) -> bool {
    let eps = T::default_epsilon();
    let e4 = eps * eps * eps * eps;
    let n: T = nalgebra::convert(N as f64);
    let bound = T::one() / (nalgebra::convert::<f64, T>(256.0) * n * n * eps);
    // `!(a > b)`-style comparisons are false for NaN, so NaN never takes the
    // fast path.
    ty >= e4 && ty * e4 <= T::one() && tp >= e4 && tp * e4 <= T::one() && ty * tp <= bound
}

/// A node's measurement contribution `(ī, Ī)` in information form
/// (what an estimator sends its neighbours in the diffusion adaptation).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Contribution<T: RealField + Copy, const N: usize> {
    /// Information-vector contribution `ī`.
    pub i: SVector<T, N>,
    /// Information-matrix contribution `Ī` (may be indefinite for an
    /// untriggered step, see `docs/algorithm.md` §4).
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic SPD matrices `D (A Aᵀ + δ I) D` over many conditions and
    /// scales.
    fn spd(seed: &mut u64) -> SMatrix<f64, 7, 7> {
        let mut next = || {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (*seed >> 11) as f64 / (1u64 << 53) as f64
        };
        // Rank 1 to 7 plus δ I: conditions up to ~1e19, so that some inverses
        // are indefinite.
        let rank = 1 + (next() * 7.0) as usize;
        let a = SMatrix::<f64, 7, 7>::from_fn(|_, j| if j < rank { next() - 0.5 } else { 0.0 });
        let delta = 10f64.powf(-19.0 * next());
        let d = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::<f64, 7>::from_fn(|_, _| {
            10f64.powf(8.0 * next() - 4.0)
        }));
        let y = d * (a * a.transpose() + SMatrix::identity() * delta) * d;
        crate::linalg::sym(&y)
    }

    #[test]
    fn the_fast_check_of_to_gaussian_never_skips_a_failing_factorisation() {
        let mut seed = 11;
        let (mut fast, mut total, mut bad) = (0, 0, 0);
        for _ in 0..20_000 {
            let y = spd(&mut seed);
            let Ok(ch) = cholesky(&y, "Y") else { continue };
            let p = chol_inverse(&ch);
            total += 1;
            let factorises = cholesky(&p, "P").is_ok();
            bad += usize::from(!factorises);
            if inverse_surely_pd(&y, &p) {
                fast += 1;
                assert!(factorises, "{y}");
            }
        }
        // Both paths are taken, and some inverses are indefinite (the smallest
        // `tr Y · tr P` among them is ~1e20 here, the bound ~3.6e11).
        assert!(
            fast > total / 20 && fast < total && bad > 0,
            "{fast}, {bad} of {total}"
        );
    }

    #[test]
    fn to_gaussian_equals_the_full_factorisation_bit_for_bit() {
        let mut seed = 5;
        for _ in 0..5_000 {
            let ymat = spd(&mut seed);
            let pair = InfoPair {
                y: SVector::<f64, 7>::from_fn(|i, _| i as f64 - 3.0),
                ymat,
            };
            let reference = cholesky(&ymat, "information matrix Y").and_then(|ch| {
                let p = chol_inverse(&ch);
                let x = ch.solve(&pair.y);
                cholesky(&p, "covariance P = Y⁻¹")?;
                check_finite(&x, "state estimate x = Y⁻¹ŷ")?;
                Ok(Gaussian { x, p })
            });
            assert_eq!(pair.to_gaussian(), reference);
        }
        // NaN and ∞ are still rejected by name.
        let mut bad = InfoPair {
            y: SVector::<f64, 7>::zeros(),
            ymat: SMatrix::<f64, 7, 7>::identity(),
        };
        bad.y[2] = f64::NAN;
        assert_eq!(
            bad.to_gaussian().unwrap_err(),
            crate::Error::NonFinite {
                what: "state estimate x = Y⁻¹ŷ"
            }
        );
    }
}
