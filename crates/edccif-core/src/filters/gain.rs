//! The untriggered step's options and its error-minimised gain
//! (`docs/algorithm.md` §3 step 5, γ = 0).

use nalgebra::{Cholesky, Const, RealField, SMatrix, SVector};

use crate::error::Result;
use crate::linalg::{c, check_finite, cholesky, solve_rows, sym, sym_downdate, validate_positive};

/// What an estimator does at a step whose measurement was not sent (γ = 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum EtPolicy {
    /// The paper's error-minimised gain `M` with `P̄` (`docs/algorithm.md` §3 step 5).
    #[default]
    Optimal,
    /// Ablation: treat the last sent `z_τ` as a fresh measurement.
    Hold,
    /// Ablation: no measurement information at all (prediction only).
    Skip,
}

/// Options of the event-triggered update: policy, the gain's `σ1`, `σ2`, an
/// optional innovation gate, and the form of the ET-CIF's untriggered
/// contribution.
///
/// ```
/// let o = edccif_core::EtOptions::<f64>::default();
/// assert_eq!((o.sigma1, o.sigma2, o.gate), (5e-4, 5e-4, None));
/// assert!(o.untriggered_closed_form); // the closed form (the default)
/// // The paper's stable form, for bit-exact agreement with its equations:
/// let stable = edccif_core::EtOptions::<f64> { untriggered_closed_form: false, ..o };
/// assert!(stable.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EtOptions<T> {
    /// Untriggered-step policy.
    pub policy: EtPolicy,
    /// `σ1 > 0` of the error-minimised gain.
    pub sigma1: T,
    /// `σ2 > 0` of the error-minimised gain.
    pub sigma2: T,
    /// Optional χ² innovation gate (an extension, not in the paper): a triggered
    /// measurement whose normalised innovation squared `νᵀ Pzz⁻¹ ν` exceeds this
    /// threshold is rejected and treated as missing for that step (e.g. `16.27`,
    /// the 0.999 quantile of χ²(3)). `None` (default): no gate.
    #[cfg_attr(feature = "serde", serde(default = "Option::default"))]
    pub gate: Option<T>,
    /// The information filter's untriggered contribution (policy `Optimal`) in
    /// closed form, [`untriggered_contribution_closed`](crate::untriggered_contribution_closed):
    /// `Ī = −σ1/(1+σ1) Y⁻ + Gᵀ R̃⁻¹ G`, `ī = Ī x̂⁻ + Gᵀ R̃⁻¹ Δz̄` with
    /// `R̃ = μ2 R + μ3 δ I`, the same quantities as the stable form
    /// [`untriggered_contribution`](crate::untriggered_contribution) (Woodbury identity) without `S`, `M`, `P̄`
    /// and the `N × N` inverse of `P̄`. On (`true`) by default: it agrees with
    /// the stable form to rounding (on the paper's rows, estimates within
    /// 3.2e-13 and covariances within 1.1e-13 of their scale; `docs/triggers.md`)
    /// at about two thirds of the instructions of an untriggered step; `false`
    /// is the paper's stable form, bit for bit. The covariance-form filters
    /// (CKF, EKF, UKF), whose posterior is `P̄` itself, always use [`EtGain`]
    /// and ignore it.
    #[cfg_attr(
        feature = "serde",
        serde(default = "yes", skip_serializing_if = "is_true")
    )]
    pub untriggered_closed_form: bool,
}

impl<T: RealField + Copy> Default for EtOptions<T> {
    fn default() -> Self {
        Self {
            policy: EtPolicy::Optimal,
            sigma1: c(5e-4),
            sigma2: c(5e-4),
            gate: None,
            untriggered_closed_form: true,
        }
    }
}

/// Serde default of [`EtOptions::untriggered_closed_form`].
#[cfg(feature = "serde")]
fn yes() -> bool {
    true
}

/// Serde helper: leave a default-on flag out.
#[cfg(feature = "serde")]
#[allow(clippy::trivially_copy_pass_by_ref)]
fn is_true(b: &bool) -> bool {
    *b
}

impl<T: RealField + Copy> EtOptions<T> {
    /// Checks `σ1 > 0`, `σ2 > 0` and, when set, `gate > 0` (all finite).
    pub fn validate(&self) -> Result<()> {
        validate_positive(self.sigma1, "sigma1", false)?;
        validate_positive(self.sigma2, "sigma2", false)?;
        if let Some(g) = self.gate {
            validate_positive(g, "gate", false)?;
        }
        Ok(())
    }
}

/// The error-minimised gain of an untriggered step (`docs/algorithm.md` §3, γ = 0):
/// `S = sym(μ1 G P⁻ Gᵀ + μ2 R + μ3 δ I)`, `M = μ1 P⁻ Gᵀ S⁻¹`,
/// `P̄ = sym(μ1 (I − M G) P⁻)`, with `μ1 = 1+σ1`, `μ2 = 1+σ2`, `μ3 = 1+1/σ1+1/σ2`.
#[derive(Debug, Clone, Copy)]
pub struct EtGain<T: RealField + Copy, const N: usize, const M: usize> {
    /// The gain `M`.
    pub m: SMatrix<T, N, M>,
    /// The error-covariance bound `P̄`.
    pub p_bar: SMatrix<T, N, N>,
    /// `μ1`.
    pub mu1: T,
    s_chol: Cholesky<T, Const<M>>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> EtGain<T, N, M> {
    /// Computes the gain at the prior `P⁻` with Jacobian `G` and noise `R`.
    ///
    /// ```
    /// use edccif_core::{EtGain, EtOptions};
    /// use nalgebra::{Matrix1, Matrix1x2, Matrix2};
    /// let g = EtGain::new(&Matrix2::<f64>::identity(), &Matrix1x2::new(1.0, 0.0), &Matrix1::new(0.1), 0.04, &EtOptions::default()).unwrap();
    /// // P̄ shrinks in the observed direction, grows by μ1 in the other
    /// assert!(g.p_bar[(0, 0)] < 1.0 && (g.p_bar[(1, 1)] - 1.0005).abs() < 1e-12);
    /// ```
    pub fn new(
        p_prior: &SMatrix<T, N, N>,
        g: &SMatrix<T, M, N>,
        r: &SMatrix<T, M, M>,
        delta: T,
        opts: &EtOptions<T>,
    ) -> Result<Self> {
        Self::with_products(p_prior, g, r, delta, opts, |g| {
            let pg = p_prior * g.transpose();
            (pg, g * pg)
        })
    }

    /// [`EtGain::new`] with `(P⁻ Gᵀ, G P⁻ Gᵀ)` from `products` (called once `G`
    /// is known to be finite), e.g. a sensor's
    /// [`jacobian_products`](MeasurementModel::jacobian_products); the same
    /// checks in the same order.
    pub(crate) fn with_products(
        p_prior: &SMatrix<T, N, N>,
        g: &SMatrix<T, M, N>,
        r: &SMatrix<T, M, M>,
        delta: T,
        opts: &EtOptions<T>,
        products: impl FnOnce(&SMatrix<T, M, N>) -> (SMatrix<T, N, M>, SMatrix<T, M, M>),
    ) -> Result<Self> {
        opts.validate()?;
        validate_positive(delta, "delta", true)?;
        check_finite(g, "measurement Jacobian G")?;
        let one = T::one();
        let mu1 = one + opts.sigma1;
        let mu2 = one + opts.sigma2;
        let mu3 = one + one / opts.sigma1 + one / opts.sigma2;
        let (pg, gpg) = products(g);
        let s = sym(&(gpg * mu1 + r * mu2 + SMatrix::<T, M, M>::identity() * (mu3 * delta)));
        let s_chol = cholesky(&s, "untriggered innovation covariance S")?;
        // M = μ1 P⁻ Gᵀ S⁻¹ = μ1 (S⁻¹ G P⁻)ᵀ
        let (m, p_bar) = if M == 0 || M > 8 {
            let m = s_chol.solve(&pg.transpose()).transpose() * mu1;
            (m, sym(&((p_prior - m * pg.transpose()) * mu1)))
        } else {
            // The same operations in the same order (see `kalman_update`).
            let m = solve_rows(s_chol.l_dirty(), &pg) * mu1;
            (m, sym_downdate(p_prior, &m, &pg, Some(mu1)))
        };
        check_finite(&m, "error-minimised gain M")?;
        check_finite(&p_bar, "error covariance bound P̄")?;
        Ok(Self {
            m,
            p_bar,
            mu1,
            s_chol,
        })
    }

    /// `S⁻¹ v`.
    pub fn s_solve(&self, v: &SVector<T, M>) -> SVector<T, M> {
        self.s_chol.solve(v)
    }
}
