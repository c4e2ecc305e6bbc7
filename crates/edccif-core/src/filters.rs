//! Local filters of one node: the cubature information filter with event
//! triggering (ET-CIF, ALGORITHM.md §3) and the covariance-form CKF / EKF / UKF
//! used by the consensus baselines (§5), all sharing the error-minimised gain for
//! untriggered steps.

use nalgebra::{Cholesky, Const, RealField, SMatrix, SVector};

use crate::angles::residual;
use crate::error::Result;
use crate::linalg::{
    all_finite, c, check_finite, check_positive_definite, check_positive_definite_mirrored,
    cholesky, cholesky_lower, cholesky_mirrored, lower_inverse, spd_inverse, sym,
    validate_positive,
};
use crate::message::{Contribution, Gaussian, InfoPair, Observation};
use crate::model::{MeasurementModel, MotionModel};
use crate::sigma::{
    sigma_measure, sigma_measure_mean, sigma_measure_whitened, sigma_predict_checked,
    MeasurementStats, SigmaRule,
};
use crate::silence::silent_measurement;
use crate::trigger::{Trigger, TriggerState};

/// What an estimator does at a step whose measurement was not sent (γ = 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum EtPolicy {
    /// The paper's error-minimised gain `M` with `P̄` (ALGORITHM.md §3 step 5).
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
/// assert!(!o.untriggered_closed_form); // the paper's stable form
/// // Opt in to the closed form of the untriggered contribution:
/// let fast = edccif_core::EtOptions::<f64> { untriggered_closed_form: true, ..o };
/// assert!(fast.validate().is_ok());
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
    /// closed form, [`untriggered_contribution_closed`]:
    /// `Ī = −σ1/(1+σ1) Y⁻ + Gᵀ R̃⁻¹ G`, `ī = Ī x̂⁻ + Gᵀ R̃⁻¹ Δz̄` with
    /// `R̃ = μ2 R + μ3 δ I`, the same quantities as the stable form
    /// [`untriggered_contribution`] (Woodbury identity) without `S`, `M`, `P̄`
    /// and the `N × N` inverse of `P̄`; different rounding, so off (`false`,
    /// the paper's rows) by default. The covariance-form filters (CKF, EKF,
    /// UKF), whose posterior is `P̄` itself, always use [`EtGain`] and ignore it.
    #[cfg_attr(
        feature = "serde",
        serde(default, skip_serializing_if = "core::ops::Not::not")
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
            untriggered_closed_form: false,
        }
    }
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

/// Normalised innovation squared `νᵀ Pzz⁻¹ ν`.
///
/// ```
/// use nalgebra::{Matrix2, Vector2};
/// let nis = edccif_core::normalised_innovation(&(Matrix2::<f64>::identity() * 4.0), &Vector2::new(2.0, 0.0)).unwrap();
/// assert!((nis - 1.0).abs() < 1e-12);
/// ```
pub fn normalised_innovation<T: RealField + Copy, const M: usize>(
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
) -> Result<T> {
    check_finite(dz, "innovation Δz")?;
    let nis = dz.dot(&cholesky(pzz, "innovation covariance Pzz")?.solve(dz));
    if nis.is_finite() {
        Ok(nis)
    } else {
        Err(crate::error::Error::NonFinite {
            what: "normalised innovation",
        })
    }
}

/// Whether the gate rejects an innovation (`false` without a gate).
fn gate_rejects<T: RealField + Copy, const M: usize>(
    gate: Option<T>,
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
) -> Result<bool> {
    match gate {
        None => Ok(false),
        Some(g) => Ok(normalised_innovation(pzz, dz)? > g),
    }
}

/// The error-minimised gain of an untriggered step (ALGORITHM.md §3, γ = 0):
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

/// Contribution of a triggered step (P-3, A-9, A-15): with `H = Pxzᵀ Y⁻` and
/// `D = sym(Pzz − Pxzᵀ Y⁻ Pxz)`, `Ī = sym(Hᵀ D⁻¹ H)`, `ī = Hᵀ D⁻¹ (Δz + H x̂⁻)`.
pub fn triggered_contribution<T, const N: usize, const M: usize>(
    y_prior: &SMatrix<T, N, N>,
    x_prior: &SVector<T, N>,
    stats: &MeasurementStats<T, N, M>,
    dz: &SVector<T, M>,
) -> Result<Contribution<T, N>>
where
    T: RealField + Copy,
{
    check_finite(dz, "innovation Δz")?;
    let h = stats.pxz.transpose() * y_prior;
    let d = sym(&(stats.pzz - h * stats.pxz));
    let w = cholesky(&d, "pseudo-measurement noise D")?.solve(&h); // D⁻¹ H
    let imat = sym(&(h.transpose() * w));
    let i = w.transpose() * (dz + h * x_prior);
    check_finite(&imat, "contribution Ī")?;
    check_finite(&i, "contribution ī")?;
    Ok(Contribution { i, imat })
}

/// [`triggered_contribution`] from the lower Cholesky factor `L` of the prior
/// covariance `P⁻ = L Lᵀ` (upper triangle not read) instead of `Y⁻ = P⁻⁻¹`: the
/// same quantities in exact arithmetic, different rounding (the fast path of
/// [`cif_update`] for models with [`MeasurementModel::fast_trig`]).
///
/// With `A = L⁻¹ Pxz` (forward substitution), `Hᵀ = Y⁻ Pxz = L⁻ᵀ A` (back
/// substitution) and `Pxzᵀ Y⁻ Pxz = Aᵀ A`, so `D = Pzz − Aᵀ A` (exactly
/// symmetric); with `D = C Cᵀ` and `V = C⁻¹ H`, `Ī = Vᵀ V` (one triangle, mirrored)
/// and `ī = Vᵀ C⁻¹ (Δz + H x̂⁻)`. Under the cubature rule `Pxz = w·s·L (Z⁺ − Z⁻)ᵀ`,
/// so `A = w·s·(Z⁺ − Z⁻)ᵀ` and `H = w·s·(Z⁺ − Z⁻) L⁻¹`. No `N × N` product and no
/// inverse. The errors are those of [`triggered_contribution`]: a non-finite
/// `Δz`, a `D` that is not finite or not positive definite
/// (`"pseudo-measurement noise D"`), a non-finite result.
///
/// ```
/// use edccif_core::{triggered_contribution, triggered_contribution_factored, MeasurementStats};
/// use edccif_core::linalg::{cholesky_lower, lower_inverse};
/// use nalgebra::{Matrix1, Matrix2, Matrix2x1, Vector1, Vector2};
/// let p = Matrix2::new(2.0, 0.5, 0.5, 1.0);
/// let l = cholesky_lower(&p, "P")?;
/// let stats = MeasurementStats { z_hat: Vector1::new(0.0), pzz: Matrix1::new(2.5), pxz: Matrix2x1::new(2.0, 0.5) };
/// let (x, dz) = (Vector2::new(1.0, -1.0), Vector1::new(0.3));
/// let fast = triggered_contribution_factored(&l, &x, &stats, &dz)?;
/// let reference = triggered_contribution(&lower_inverse(&l), &x, &stats, &dz)?;
/// assert!((fast.imat - reference.imat).norm() < 1e-14 && (fast.i - reference.i).norm() < 1e-14);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn triggered_contribution_factored<T, const N: usize, const M: usize>(
    l_prior: &SMatrix<T, N, N>,
    x_prior: &SVector<T, N>,
    stats: &MeasurementStats<T, N, M>,
    dz: &SVector<T, M>,
) -> Result<Contribution<T, N>>
where
    T: RealField + Copy,
{
    check_finite(dz, "innovation Δz")?;
    // The loops run down contiguous columns (axpy form) where they can.
    // A = L⁻¹ Pxz by forward substitution, column by column.
    let l = l_prior;
    let mut a = stats.pxz;
    for m in 0..M {
        for k in 0..N {
            let akm = a[(k, m)] / l[(k, k)];
            a[(k, m)] = akm;
            for i in (k + 1)..N {
                a[(i, m)] -= l[(i, k)] * akm;
            }
        }
    }
    contribution_whitened(l, x_prior, &stats.pzz, a, dz)
}

/// The second half of [`triggered_contribution_factored`], from the whitened
/// cross covariance `A = L⁻¹ Pxz` (what the fast path's sigma transform returns
/// in place of `Pxz`); `Δz` is checked here.
fn contribution_whitened<T, const N: usize, const M: usize>(
    l: &SMatrix<T, N, N>,
    x_prior: &SVector<T, N>,
    pzz: &SMatrix<T, M, M>,
    mut a: SMatrix<T, N, M>,
    dz: &SVector<T, M>,
) -> Result<Contribution<T, N>>
where
    T: RealField + Copy,
{
    check_finite(dz, "innovation Δz")?;
    // D = Pzz − Aᵀ A, lower triangle, mirrored (exactly symmetric).
    let mut d = *pzz;
    for j in 0..M {
        for i in j..M {
            let mut s = d[(i, j)];
            for k in 0..N {
                s -= a[(k, i)] * a[(k, j)];
            }
            d[(i, j)] = s;
            d[(j, i)] = s;
        }
    }
    let ch = cholesky(&d, "pseudo-measurement noise D")?;
    let cl = ch.l_dirty(); // lower triangle only

    // Hᵀ = L⁻ᵀ A by back substitution, in place (`a` becomes Hᵀ). The
    // reciprocals of `L`'s diagonal are taken once, independently of each
    // other, so the substitution's dependent chain multiplies where it
    // divided (`L` is the checked factor of `P⁻`: a positive finite diagonal).
    let mut l_recip = SVector::<T, N>::zeros();
    for i in 0..N {
        l_recip[i] = T::one() / l[(i, i)];
    }
    for m in 0..M {
        for i in (0..N).rev() {
            let mut s = a[(i, m)];
            for k in (i + 1)..N {
                s -= l[(k, i)] * a[(k, m)];
            }
            a[(i, m)] = s * l_recip[i];
        }
    }
    // u = Δz + H x̂⁻, then u ← C⁻¹ u and Vᵀ = Hᵀ C⁻ᵀ (in place: `a` becomes Vᵀ).
    let mut u = *dz;
    for m in 0..M {
        let mut hx = T::zero();
        for k in 0..N {
            hx += a[(k, m)] * x_prior[k];
        }
        u[m] += hx;
    }
    for m in 0..M {
        for k in 0..m {
            let (cmk, uk) = (cl[(m, k)], u[k]);
            u[m] -= cmk * uk;
            for i in 0..N {
                let v = a[(i, k)];
                a[(i, m)] -= cmk * v;
            }
        }
        // One division per column of `C`, not one per entry.
        let cmm_recip = T::one() / cl[(m, m)];
        u[m] *= cmm_recip;
        for i in 0..N {
            a[(i, m)] *= cmm_recip;
        }
    }
    // Ī = Vᵀ V (lower triangle, mirrored), ī = Vᵀ u.
    if M == 0 {
        return Ok(Contribution::zeros()); // no measurement, no information
    }
    let mut imat = SMatrix::<T, N, N>::zeros();
    let mut i_vec = SVector::<T, N>::zeros();
    for j in 0..N {
        let mut s = a[(j, 0)] * u[0];
        for m in 1..M {
            s += a[(j, m)] * u[m];
        }
        i_vec[j] = s;
        for i in j..N {
            let mut s = a[(i, 0)] * a[(j, 0)];
            for m in 1..M {
                s += a[(i, m)] * a[(j, m)];
            }
            imat[(i, j)] = s;
            imat[(j, i)] = s;
        }
    }
    check_finite(&imat, "contribution Ī")?;
    check_finite(&i_vec, "contribution ī")?;
    Ok(Contribution { i: i_vec, imat })
}

/// Contribution of an untriggered step in its stable form:
/// `Ī = sym(P̄⁻¹ − Y⁻)`, `ī = μ1 Gᵀ S⁻¹ Δz̄ + Ī (x̂⁻ + M Δz̄)`.
pub fn untriggered_contribution<T, const N: usize, const M: usize>(
    x_prior: &SVector<T, N>,
    y_prior: &SMatrix<T, N, N>,
    g: &SMatrix<T, M, N>,
    gain: &EtGain<T, N, M>,
    dz_bar: &SVector<T, M>,
) -> Result<Contribution<T, N>>
where
    T: RealField + Copy,
{
    check_finite(dz_bar, "innovation Δz̄")?;
    let pbar_inv = spd_inverse(&gain.p_bar, "error covariance bound P̄")?;
    let imat = sym(&(pbar_inv - y_prior));
    let i = g.transpose() * gain.s_solve(dz_bar) * gain.mu1 + imat * (x_prior + gain.m * dz_bar);
    check_finite(&i, "contribution ī")?;
    Ok(Contribution { i, imat })
}

/// Contribution of an untriggered step in closed form (opt-in,
/// [`EtOptions::untriggered_closed_form`]): with `κ = σ1/(1+σ1)`,
/// `R̃ = sym(μ2 R + μ3 δ I)` and `V = L⁻¹ G` for `R̃ = L Lᵀ`,
/// `Ī = Vᵀ V − κ sym(Y⁻) = −κ Y⁻ + Gᵀ R̃⁻¹ G`,
/// `ī = Ī x̂⁻ + Vᵀ L⁻¹ Δz̄ = Ī x̂⁻ + Gᵀ R̃⁻¹ Δz̄`.
///
/// The same quantities as [`EtGain::new`] with [`untriggered_contribution`]:
/// `S = μ1 (G P⁻ Gᵀ + R̃/μ1)`, so by the Woodbury identity
/// `P̄ = μ1 (P⁻ − P⁻ Gᵀ (S/μ1)⁻¹ G P⁻) = μ1 (Y⁻ + μ1 Gᵀ R̃⁻¹ G)⁻¹`,
/// `P̄⁻¹ = Y⁻/μ1 + Gᵀ R̃⁻¹ G` and `Ī = P̄⁻¹ − Y⁻`; and `P̄⁻¹ M = Gᵀ R̃⁻¹`,
/// `Y⁻ M = μ1 Gᵀ S⁻¹`, so `ī = μ1 Gᵀ S⁻¹ Δz̄ + Ī (x̂⁻ + M Δz̄)` reduces as
/// above (`docs/triggers.md`, "Closed form of the untriggered step").
/// It needs neither `P⁻` nor `S`, `M`, `P̄` or the `N × N` inverse of `P̄`, only
/// the Cholesky factor of the `M × M` matrix `R̃`; the results agree with the
/// stable form to rounding, not bit for bit.
///
/// Errors: those of [`EtGain::new`] for `σ1`, `σ2`, `δ` and `G`;
/// `NotPositiveDefinite`/`NonFinite` naming `R̃` when `R̃` is not positive
/// definite (where the stable form names `S`); then those of
/// [`untriggered_contribution`] for `Δz̄` and `ī`.
///
/// ```
/// use edccif_core::{untriggered_contribution, untriggered_contribution_closed, EtGain, EtOptions};
/// use nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
/// let (x, p) = (Vector2::new(1.0, -2.0), Matrix2::new(2.0, 0.3, 0.3, 1.0));
/// let (g, r, dz) = (Matrix1x2::new(1.0, 0.5), Matrix1::new(0.1), Vector1::new(0.2));
/// let y = p.try_inverse().unwrap();
/// let o = EtOptions { sigma1: 0.1, sigma2: 0.1, ..EtOptions::default() };
/// let closed = untriggered_contribution_closed(&x, &y, &g, &r, 0.04, &o, &dz)?;
/// let gain = EtGain::new(&p, &g, &r, 0.04, &o)?;
/// let stable = untriggered_contribution(&x, &y, &g, &gain, &dz)?;
/// assert!((closed.imat - stable.imat).norm() < 1e-12);
/// assert!((closed.i - stable.i).norm() < 1e-12);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn untriggered_contribution_closed<T, const N: usize, const M: usize>(
    x_prior: &SVector<T, N>,
    y_prior: &SMatrix<T, N, N>,
    g: &SMatrix<T, M, N>,
    r: &SMatrix<T, M, M>,
    delta: T,
    opts: &EtOptions<T>,
    dz_bar: &SVector<T, M>,
) -> Result<Contribution<T, N>>
where
    T: RealField + Copy,
{
    // The checks of `EtGain::new`, in its order.
    opts.validate()?;
    validate_positive(delta, "delta", true)?;
    check_finite(g, "measurement Jacobian G")?;
    let one = T::one();
    let mu2 = one + opts.sigma2;
    let mu3 = one + one / opts.sigma1 + one / opts.sigma2;
    let what = "untriggered noise R̃ = μ2 R + μ3 δ I";
    let r_tilde = sym(&(r * mu2 + SMatrix::<T, M, M>::identity() * (mu3 * delta)));
    let not_pd = crate::error::Error::NotPositiveDefinite { what };
    // V = L⁻¹ G and u = L⁻¹ Δz̄, so that Gᵀ R̃⁻¹ G = Vᵀ V and Gᵀ R̃⁻¹ Δz̄ = Vᵀ u.
    let off_diagonal_zero = (0..M).all(|j| (0..M).all(|i| i == j || r_tilde[(i, j)] == T::zero()));
    let (v, u) = if off_diagonal_zero {
        // A diagonal `R̃` (a diagonal `R`, as both catalogue angle sensors
        // have): `L` is the square roots of its diagonal, so `V` and `u` are
        // `G` and `Δz̄` with their rows scaled by the reciprocals, without a
        // factorisation or triangular solves. The errors are `cholesky`'s:
        // `NonFinite` for a non-finite `R̃`, `NotPositiveDefinite` for a
        // diagonal entry that is not positive.
        check_finite(&r_tilde, what)?;
        let mut scale = SVector::<T, M>::zeros();
        for k in 0..M {
            let d = r_tilde[(k, k)];
            if !(d > T::zero()) {
                return Err(not_pd);
            }
            // √d of a positive finite `d` is positive and finite, and so is
            // its reciprocal (at most 2⁵³⁷ for the least subnormal `d`).
            scale[k] = T::one() / d.sqrt();
        }
        check_finite(dz_bar, "innovation Δz̄")?;
        let (mut v, mut u) = (*g, *dz_bar);
        for k in 0..M {
            u[k] *= scale[k];
        }
        for j in 0..N {
            for k in 0..M {
                v[(k, j)] *= scale[k];
            }
        }
        (v, u)
    } else {
        let l = cholesky(&r_tilde, what)?.l();
        check_finite(dz_bar, "innovation Δz̄")?;
        // `cholesky` guarantees a positive finite diagonal, so the solves succeed.
        (
            l.solve_lower_triangular(g).ok_or(not_pd)?,
            l.solve_lower_triangular(dz_bar).ok_or(not_pd)?,
        )
    };
    // Ī = Vᵀ V − κ sym(Y⁻), one triangle computed and mirrored (symmetric by
    // construction); ī = Ī x̂⁻ + Vᵀ u.
    let half_kappa = opts.sigma1 / (one + opts.sigma1) * c(0.5);
    let mut imat = SMatrix::<T, N, N>::zeros();
    for j in 0..N {
        for i in j..N {
            let mut e = -(y_prior[(i, j)] + y_prior[(j, i)]) * half_kappa;
            for k in 0..M {
                e += v[(k, i)] * v[(k, j)];
            }
            imat[(i, j)] = e;
            imat[(j, i)] = e;
        }
    }
    let i = imat * x_prior + v.tr_mul(&u);
    // `ī` first: every entry of `Ī` enters `ī = Ī x̂⁻ + …` as a factor of a
    // product, a product with a NaN or ±∞ factor is NaN or ±∞ (∞·0 is NaN),
    // and so is any sum with such a term: a finite `ī` proves `Ī` finite.
    // `Ī` is checked only when `ī` fails, to name it first as before.
    if !all_finite(&i) {
        check_finite(&imat, "contribution Ī")?;
        return Err(crate::error::Error::NonFinite {
            what: "contribution ī",
        });
    }
    Ok(Contribution { i, imat })
}

/// The information filter's contribution of an untriggered step under the
/// `Optimal` policy: the closed form when `opts` asks for it, else the gain
/// [`EtGain`] and the stable form (the paper's rows).
#[allow(clippy::too_many_arguments)]
fn optimal_contribution<T, const N: usize, const M: usize>(
    x_prior: &SVector<T, N>,
    p_prior: &SMatrix<T, N, N>,
    y_prior: &SMatrix<T, N, N>,
    g: &SMatrix<T, M, N>,
    r: &SMatrix<T, M, M>,
    delta: T,
    opts: &EtOptions<T>,
    dz_bar: &SVector<T, M>,
) -> Result<Contribution<T, N>>
where
    T: RealField + Copy,
{
    if opts.untriggered_closed_form {
        untriggered_contribution_closed(x_prior, y_prior, g, r, delta, opts, dz_bar)
    } else {
        let gain = EtGain::new(p_prior, g, r, delta, opts)?;
        untriggered_contribution(x_prior, y_prior, g, &gain, dz_bar)
    }
}

/// The result of one node's ET-CIF local step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CifLocal<T: RealField + Copy, const N: usize, const M: usize> {
    /// Predicted state `x̂⁻`.
    pub x_prior: SVector<T, N>,
    /// Predicted covariance `P⁻`.
    pub p_prior: SMatrix<T, N, N>,
    /// Information prior `(ŷ⁻, Y⁻)`.
    pub prior: InfoPair<T, N>,
    /// This node's contribution `(ī, Ī)`.
    pub contribution: Contribution<T, N>,
    /// `Some(γ)` when a measurement was taken, `None` when it was missing.
    pub triggered: Option<bool>,
    /// The trigger state after this step (commit it when the step is kept).
    pub trigger_state: TriggerState<T, M>,
    /// The innovation gate rejected this step's triggered measurement: the
    /// contribution is zero and the trigger state is left as it was (the step
    /// counts as missing; `triggered` stays `Some(true)` because it was sent).
    pub gated: bool,
}

impl<T: RealField + Copy, const N: usize, const M: usize> CifLocal<T, N, M> {
    /// The local-only posterior `(ŷ⁻ + ī, Y⁻ + Ī)` (ET-CIF alone).
    pub fn local_posterior(&self) -> InfoPair<T, N> {
        self.prior.updated(&self.contribution)
    }
}

/// What the measurement part of a local step does, decided once for the
/// information and the covariance filters. The statistics and vectors are
/// borrowed from [`decide_measurement`]'s frame: it hands the decision to its
/// caller's continuation instead of moving them out through its result.
enum MeasurementAction<'a, T: RealField + Copy, const N: usize, const M: usize> {
    /// No measurement information: missing, gated, skipped, nothing sent yet, or
    /// a silent step that carries none.
    Nothing,
    /// A Kalman-type update with these innovation statistics and innovation
    /// (a triggered measurement, a silent step's pseudo-measurement, or the held
    /// `z_τ`).
    Update(&'a MeasurementStats<T, N, M>, &'a SVector<T, M>),
    /// The error-minimised gain of an untriggered step, at `G` with `Δz̄` (each
    /// filter computes its gain or closed form from these).
    Optimal {
        g: &'a SMatrix<T, M, N>,
        dz_bar: &'a SVector<T, M>,
    },
}

/// The trigger decision of a local step and what its measurement part does.
struct MeasurementDecision<'a, T: RealField + Copy, const N: usize, const M: usize> {
    triggered: Option<bool>,
    trigger_state: TriggerState<T, M>,
    gated: bool,
    action: MeasurementAction<'a, T, N, M>,
}

/// [`MeasurementAction`] owning its statistics (for a caller that takes them
/// out of [`decide_measurement`]'s frame).
enum OwnedAction<T: RealField + Copy, const N: usize, const M: usize> {
    Nothing,
    Update(MeasurementStats<T, N, M>, SVector<T, M>),
    Optimal {
        g: SMatrix<T, M, N>,
        dz_bar: SVector<T, M>,
    },
}

/// [`MeasurementDecision`] owning its statistics.
struct OwnedDecision<T: RealField + Copy, const N: usize, const M: usize> {
    triggered: Option<bool>,
    trigger_state: TriggerState<T, M>,
    gated: bool,
    action: OwnedAction<T, N, M>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> From<MeasurementDecision<'_, T, N, M>>
    for OwnedDecision<T, N, M>
{
    #[inline(always)]
    fn from(d: MeasurementDecision<'_, T, N, M>) -> Self {
        Self {
            triggered: d.triggered,
            trigger_state: d.trigger_state,
            gated: d.gated,
            action: match d.action {
                MeasurementAction::Nothing => OwnedAction::Nothing,
                MeasurementAction::Update(s, dz) => OwnedAction::Update(*s, *dz),
                MeasurementAction::Optimal { g, dz_bar } => OwnedAction::Optimal {
                    g: *g,
                    dz_bar: *dz_bar,
                },
            },
        }
    }
}

/// The trigger decision, the innovation gate, the silent step and the
/// untriggered-step policy, shared by [`cif_update`] and [`cov_update`]. `stats`
/// computes the innovation statistics at the prior (sigma points or
/// linearisation), `z_mean` only the predicted measurement; `apply` makes the
/// step's result from the decision, whose statistics it borrows (each is
/// computed once, into this frame, and read in place).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn decide_measurement<T, H, R, const N: usize, const M: usize>(
    sensor: &H,
    x_prior: &SVector<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
    stats: impl Fn() -> Result<MeasurementStats<T, N, M>>,
    z_mean: impl Fn() -> Result<SVector<T, M>>,
    apply: impl FnOnce(MeasurementDecision<'_, T, N, M>) -> Result<R>,
) -> Result<R>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let z = match obs {
        Observation::Missing => {
            return apply(MeasurementDecision {
                triggered: None,
                trigger_state: *trigger_state,
                gated: false,
                action: MeasurementAction::Nothing,
            })
        }
        Observation::Measured(z) => z,
    };
    check_finite(z, "measurement z")?;
    // The innovation trigger decides on the node's prediction (sent to the
    // sensor). Statistics are read inside their `Result`, not moved out by `?`.
    let early = match trigger.needs_prediction() {
        true => Some(stats()),
        false => None,
    };
    let pred = match &early {
        Some(Ok(s)) => Some(s),
        Some(Err(e)) => return Err(*e),
        None => None,
    };
    let (gamma, mut next) =
        trigger.decide_with(sensor, trigger_state, z, pred.map(|s| (&s.z_hat, &s.pzz)))?;
    // Statistics computed after the decision, and the silent step's.
    let late;
    let silent;
    let (dz, dz_bar, g);
    let mut gated = false;
    let action = if gamma {
        let s = match pred {
            Some(s) => s,
            None => {
                late = stats();
                match &late {
                    Ok(s) => s,
                    Err(e) => return Err(*e),
                }
            }
        };
        dz = residual(sensor, z, &s.z_hat);
        // EKF: `s.pzz` is its own S = G P⁻ Gᵀ + R.
        if gate_rejects(opts.gate, &s.pzz, &dz)? {
            gated = true;
            next = *trigger_state;
            MeasurementAction::Nothing
        } else {
            MeasurementAction::Update(s, &dz)
        }
    } else if trigger.has_silent_update() {
        let s = match pred {
            Some(s) => s,
            None => {
                late = stats();
                match &late {
                    Ok(s) => s,
                    Err(e) => return Err(*e),
                }
            }
        };
        silent = silent_measurement(trigger, sensor, &next, s);
        match &silent {
            Ok(Some((dz, s))) => MeasurementAction::Update(s, dz),
            Ok(None) => MeasurementAction::Nothing,
            Err(e) => return Err(*e),
        }
    } else {
        match (opts.policy, next.last_sent) {
            (EtPolicy::Skip, _) | (_, None) => MeasurementAction::Nothing,
            (EtPolicy::Hold, Some(zt)) => {
                late = stats();
                let s = match &late {
                    Ok(s) => s,
                    Err(e) => return Err(*e),
                };
                dz = residual(sensor, &zt, &s.z_hat);
                MeasurementAction::Update(s, &dz)
            }
            (EtPolicy::Optimal, Some(zt)) => {
                let z_hat = z_mean()?;
                g = sensor.jacobian(x_prior);
                dz_bar = residual(sensor, &zt, &z_hat);
                MeasurementAction::Optimal {
                    g: &g,
                    dz_bar: &dz_bar,
                }
            }
        }
    };
    apply(MeasurementDecision {
        triggered: Some(gamma),
        trigger_state: next,
        gated,
        action,
    })
}

/// The prior of an ET-CIF step: the predicted `(x̂⁻, P⁻)`, its information form
/// `(ŷ⁻, Y⁻) = (P⁻⁻¹ x̂⁻, P⁻⁻¹)` and the Cholesky factor of `P⁻` the update draws
/// its cubature points from. Made by [`cif_predict`], consumed by [`cif_update`].
///
/// ```
/// use edccif_core::{CifPrior, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let prior = CifPrior::new(&Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::identity() * 4.0)?)?;
/// assert_eq!(prior.info().ymat, Matrix2::identity() * 0.25);
/// assert_eq!(prior.x(), Vector2::new(1.0, 2.0));
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy)]
pub struct CifPrior<T: RealField + Copy, const N: usize> {
    x: SVector<T, N>,
    p: SMatrix<T, N, N>,
    info: InfoPair<T, N>,
    /// The lower Cholesky factor of `P⁻`.
    l: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> PartialEq for CifPrior<T, N> {
    /// Equal predicted state and covariance (the rest is derived from them).
    fn eq(&self, other: &Self) -> bool {
        self.x == other.x && self.p == other.p && self.info == other.info
    }
}

impl<T: RealField + Copy, const N: usize> CifPrior<T, N> {
    /// The prior of a predicted estimate (e.g. one kept between a predict and an
    /// update, or set by the user): fails when `P⁻` is not positive definite or
    /// its inverse not finite.
    ///
    /// ```
    /// use edccif_core::{CifPrior, Error, Gaussian};
    /// use nalgebra::{Matrix2, Vector2};
    /// let bad = Gaussian { x: Vector2::new(0.0, 0.0), p: Matrix2::new(1.0, 2.0, 2.0, 1.0) };
    /// assert_eq!(CifPrior::new(&bad).unwrap_err(), Error::NotPositiveDefinite { what: "predicted covariance P⁻" });
    /// ```
    pub fn new(prior: &Gaussian<T, N>) -> Result<Self> {
        check_finite(&prior.x, "predicted state x⁻")?;
        Self::from_predicted(&prior.x, &prior.p)
    }

    /// Information form of a predicted `(x̂⁻, P⁻)` whose `x̂⁻` is finite. By
    /// reference: `x̂⁻` and `P⁻` are copied once, into the result.
    fn from_predicted(x: &SVector<T, N>, p: &SMatrix<T, N, N>) -> Result<Self> {
        // The factor read inside its `Result`, not moved out by `?`, and
        // written once, into the result (`lower_inverse` reads only the lower
        // triangle).
        let chol = cholesky(p, "predicted covariance P⁻");
        let ch = match &chol {
            Ok(ch) => ch,
            Err(e) => return Err(*e),
        };
        let y_prior = lower_inverse(ch.l_dirty());
        let info = InfoPair {
            y: y_prior * x,
            ymat: y_prior,
        };
        // `ŷ⁻` checked first: every entry of `Y⁻` enters `ŷ⁻ = Y⁻ x̂⁻` as a
        // factor of a product, a product with a NaN or ±∞ factor is NaN or
        // ±∞ (∞·0 is NaN), and so is any sum with such a term: a finite `ŷ⁻`
        // proves `Y⁻` finite. `Y⁻` is checked only when `ŷ⁻` fails, to name
        // the first non-finite quantity as before.
        if !all_finite(&info.y) {
            check_finite(&info.ymat, "information prior Y⁻")?;
            return Err(crate::error::Error::NonFinite {
                what: "information prior ŷ⁻",
            });
        }
        Ok(Self {
            x: *x,
            p: *p,
            info,
            l: ch.l(),
        })
    }

    /// Predicted state `x̂⁻`.
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let prior = CifPrior::new(&Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?)?;
    /// assert_eq!(prior.x()[0], 3.0);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn x(&self) -> SVector<T, N> {
        self.x
    }
    /// Predicted covariance `P⁻`.
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let prior = CifPrior::new(&Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?)?;
    /// assert_eq!(prior.p()[0], 2.0);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn p(&self) -> SMatrix<T, N, N> {
        self.p
    }
    /// Information prior `(ŷ⁻, Y⁻)`.
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let prior = CifPrior::new(&Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?)?;
    /// let info = prior.info();
    /// assert!((info.y[0] - 1.5f64).abs() < 1e-15 && (info.ymat[0] - 0.5).abs() < 1e-15);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn info(&self) -> InfoPair<T, N> {
        self.info
    }
    /// `(x̂⁻, P⁻)` as a [`Gaussian`].
    ///
    /// ```
    /// # use edccif_core::{CifPrior, Gaussian};
    /// # use nalgebra::{Matrix1, Vector1};
    /// let g = Gaussian::new(Vector1::new(3.0), Matrix1::new(2.0))?;
    /// assert_eq!(CifPrior::new(&g)?.to_gaussian(), g);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn to_gaussian(&self) -> Gaussian<T, N> {
        Gaussian {
            x: self.x,
            p: self.p,
        }
    }
}

/// The prediction of one node's ET-CIF step (ALGORITHM.md §3, step 1 and the
/// information prior): cubature predict from `estimate` over `dt`.
///
/// [`cif_update`] completes the step; [`cif_local`] is the two in one call, bit
/// for bit.
///
/// ```
/// use edccif_core::{cif_predict, models::ConstantVelocity, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let cv = ConstantVelocity::new(0.01)?; // 1-D: [x, vx]
/// let prior = cif_predict(&cv, 0.5, &Gaussian::new(Vector2::new(0.0, 2.0), Matrix2::identity())?)?;
/// assert!((prior.x() - Vector2::new(1.0, 2.0)).norm() < 1e-12);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cif_predict<T, F, const N: usize>(
    motion: &F,
    dt: T,
    estimate: &Gaussian<T, N>,
) -> Result<CifPrior<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    cif_predict_factored(motion, dt, estimate, None)
}

/// [`cif_predict`] with the lower Cholesky factor of `estimate.p` when the
/// caller has it (see [`sigma_predict_checked`]): the same result and errors.
#[inline(always)]
pub(crate) fn cif_predict_factored<T, F, const N: usize>(
    motion: &F,
    dt: T,
    estimate: &Gaussian<T, N>,
    factor: Option<&SMatrix<T, N, N>>,
) -> Result<CifPrior<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    let rule = SigmaRule::cubature(N);
    // Without `?`, and the prediction borrowed inside its `Result`: `x̂⁻`, `P⁻`
    // are copied once, into the prior (no `memcpy` of the large struct).
    // `P⁻` unchecked by the transform: `from_predicted` factorises it first,
    // and `cholesky` fails on a non-finite `P⁻` with the same error
    // (`NonFinite`, "predicted covariance P⁻").
    match &sigma_predict_checked(&rule, motion, dt, &estimate.x, &estimate.p, factor, false) {
        Ok((x_prior, p_prior)) => CifPrior::from_predicted(x_prior, p_prior),
        Err(e) => Err(*e),
    }
}

/// The measurement part of one node's ET-CIF step (ALGORITHM.md §3, steps 2–5)
/// at a prior from [`cif_predict`]: trigger decision and contribution.
///
/// The inputs are not modified; the new trigger state is returned in the result.
///
/// ```
/// use edccif_core::{cif_predict, cif_update, models::{ConstantVelocity, Position2}, *};
/// use nalgebra::{Matrix4, Vector2, Vector4};
/// let cv = ConstantVelocity::new(0.01)?; // 2-D: [x, y, vx, vy]
/// let cam = Position2::new([0.1, 0.1])?;
/// let est = Gaussian::new(Vector4::new(0.0, 0.0, 1.0, 0.0), Matrix4::identity())?;
/// let prior = cif_predict(&cv, 0.1, &est)?;
/// let trig = Trigger::SendOnDelta { delta: 0.5 };
/// let step = cif_update(&cam, &prior, &Observation::Measured(Vector2::new(0.1, 0.0)), &trig,
///                       &TriggerState::new(&trig), &EtOptions::default())?;
/// assert_eq!(step.triggered, Some(true)); // the first measurement is always sent
/// assert_eq!(step.prior, prior.info());
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cif_update<T, H, const N: usize, const M: usize>(
    sensor: &H,
    prior: &CifPrior<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CifLocal<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    cif_update_with(
        sensor,
        prior,
        obs,
        trigger,
        trigger_state,
        opts,
        |contribution, triggered, trigger_state, gated| CifLocal {
            x_prior: prior.x,
            p_prior: prior.p,
            prior: prior.info,
            contribution: *contribution,
            triggered,
            trigger_state,
            gated,
        },
    )
}

/// [`cif_update`] handing its outcome to `finish` (the contribution by
/// reference, the decision's `triggered`, trigger state and `gated`) instead
/// of building a [`CifLocal`]: the network step copies the prior's pair and the
/// contribution once, straight into its scratch, and not `x̂⁻`, `P⁻` at all.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn cif_update_with<T, H, R, const N: usize, const M: usize>(
    sensor: &H,
    prior: &CifPrior<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
    finish: impl FnOnce(&Contribution<T, N>, Option<bool>, TriggerState<T, M>, bool) -> R,
) -> Result<R>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let rule = SigmaRule::cubature(N);
    // By reference: the prior is large, and only the result needs a copy.
    let (x_prior, p_prior, y_prior) = (&prior.x, &prior.p, &prior.info.ymat);
    let l = prior.l * rule.scale;
    // Fast path (`fast_trig`): the statistics carry the whitened cross
    // covariance `A = L⁻¹ Pxz` in place of `Pxz` (only the contribution reads
    // it), and the contribution is taken from the factor `L` of `P⁻` without
    // `Y⁻` (see [`triggered_contribution_factored`]).
    // The decision taken out of `decide_measurement`'s frame by value, as
    // the information filter's codegen is fastest with (measured: reading it
    // in place there costs more copies of the larger result).
    let decision = decide_measurement(
        sensor,
        x_prior,
        obs,
        trigger,
        trigger_state,
        opts,
        || match sensor.fast_trig() {
            true => sigma_measure_whitened(&rule, sensor, x_prior, &l),
            false => sigma_measure(&rule, sensor, x_prior, &l),
        },
        || sigma_measure_mean(&rule, sensor, x_prior, &l),
        |d| Ok(OwnedDecision::from(d)),
    )?;
    let contribution = match decision.action {
        OwnedAction::Nothing => Contribution::zeros(),
        OwnedAction::Update(stats, dz) if sensor.fast_trig() => {
            contribution_whitened(&prior.l, x_prior, &stats.pzz, stats.pxz, &dz)?
        }
        OwnedAction::Update(stats, dz) => triggered_contribution(y_prior, x_prior, &stats, &dz)?,
        OwnedAction::Optimal { g, dz_bar } => {
            // `(R, δ)`, or for a normalised threshold `((1 + μ3δ/μ2) R, 0)`.
            let (r, delta) = trigger.untriggered_noise(&sensor.noise(), opts);
            optimal_contribution(x_prior, p_prior, y_prior, &g, &r, delta, opts, &dz_bar)?
        }
    };
    Ok(finish(
        &contribution,
        decision.triggered,
        decision.trigger_state,
        decision.gated,
    ))
}

/// One node's ET-CIF local step (ALGORITHM.md §3, steps 1–5): cubature predict from
/// the fused estimate over the time step `dt`, information prior, trigger decision
/// and contribution; [`cif_predict`] then [`cif_update`].
///
/// The inputs are not modified; the new trigger state is returned in the result.
///
/// ```
/// use edccif_core::*;
/// use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
/// use nalgebra::{SMatrix, SVector, Vector3};
/// let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
/// let s = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap();
/// let est = Gaussian::new(
///     SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]),
///     SMatrix::<f64, 7, 7>::identity() * 0.01,
/// ).unwrap();
/// let trig = Trigger::SendOnDelta { delta: 0.04 };
/// let ts = TriggerState::new(&trig);
/// let z = Observation::Measured(Vector3::new(5.0, 0.02, 3.1));
/// let out = cif_local(&ct, 0.1, &s, &est, &z, &trig, &ts, &EtOptions::default()).unwrap();
/// assert_eq!(out.triggered, Some(true));
/// let post = out.local_posterior().to_gaussian().unwrap();
/// assert!(post.p.trace() < out.p_prior.trace());
/// ```
#[allow(clippy::too_many_arguments)]
pub fn cif_local<T, F, H, const N: usize, const M: usize>(
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CifLocal<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    // Borrowed inside the `Result` rather than copied out of it by `?`.
    match &cif_predict(motion, dt, estimate) {
        Ok(prior) => cif_update(sensor, prior, obs, trigger, trigger_state, opts),
        Err(e) => Err(*e),
    }
}

/// The covariance-form local filters of the consensus baselines.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum LocalFilter<T> {
    /// Cubature Kalman filter (ET-CKF when triggered).
    Ckf,
    /// Extended Kalman filter with the models' Jacobians.
    Ekf,
    /// Unscented Kalman filter with scaling `(α, β, κ)`.
    Ukf {
        /// Spread `α`.
        alpha: T,
        /// Prior-knowledge weight `β`.
        beta: T,
        /// Secondary scaling `κ`.
        kappa: T,
    },
}

impl<T: RealField + Copy> LocalFilter<T> {
    /// The UKF with the table's `(α, β, κ) = (1, 2, 0)`.
    pub fn ukf_default() -> Self {
        LocalFilter::Ukf {
            alpha: T::one(),
            beta: c(2.0),
            kappa: T::zero(),
        }
    }
}

/// The result of one node's covariance-form local step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CovLocal<T: RealField + Copy, const N: usize, const M: usize> {
    /// Local posterior.
    pub posterior: Gaussian<T, N>,
    /// `Some(γ)` when a measurement was taken, `None` when it was missing.
    pub triggered: Option<bool>,
    /// The trigger state after this step.
    pub trigger_state: TriggerState<T, M>,
    /// The innovation gate rejected this step's triggered measurement (the
    /// posterior is the prior; the trigger state is left as it was).
    pub gated: bool,
}

/// An estimate known to pass the covariance-form step's input checks: `x`
/// finite, `P` finite and factorised by the step's Cholesky check (positive
/// definite). The fields are private, so the only ways to get one are
/// [`CheckedGaussian::new`], which makes those checks, and
/// [`cov_local_chained`], whose posterior has passed them (the step factorises
/// its posterior anyway). A filter loop that feeds each posterior back as the
/// next estimate therefore validates its input once, at the start, instead of
/// factorising `P` twice per step.
///
/// ```
/// use edccif_core::{CheckedGaussian, Error, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let g = Gaussian { x: Vector2::new(1.0, 2.0), p: Matrix2::identity() };
/// let checked = CheckedGaussian::new(&g)?;
/// assert_eq!(checked.gaussian(), &g);
/// let bad = Gaussian { x: g.x, p: Matrix2::new(1.0, 2.0, 2.0, 1.0) };
/// assert_eq!(CheckedGaussian::new(&bad).unwrap_err(), Error::NotPositiveDefinite { what: "covariance P" });
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckedGaussian<T: RealField + Copy, const N: usize> {
    g: Gaussian<T, N>,
}

impl<T: RealField + Copy, const N: usize> CheckedGaussian<T, N> {
    /// Checks `g` as [`cov_predict`] checks its estimate: [`Error::NonFinite`]
    /// naming `"state estimate x"` when `x` is not finite, and the errors of
    /// [`cholesky`] naming `"covariance P"`
    /// ([`Error::NonFinite`], [`Error::NotPositiveDefinite`]) for `P`. Like the
    /// step, it reads `P`'s lower triangle for the factorisation (symmetry is
    /// [`Gaussian::new`]'s check).
    ///
    /// [`Error::NonFinite`]: crate::Error::NonFinite
    /// [`Error::NotPositiveDefinite`]: crate::Error::NotPositiveDefinite
    ///
    /// ```
    /// use edccif_core::{CheckedGaussian, Error, Gaussian};
    /// use nalgebra::{Matrix2, Vector2};
    /// let g = Gaussian { x: Vector2::new(f64::NAN, 0.0), p: Matrix2::identity() };
    /// assert_eq!(CheckedGaussian::new(&g).unwrap_err(), Error::NonFinite { what: "state estimate x" });
    /// ```
    pub fn new(g: &Gaussian<T, N>) -> Result<Self> {
        check_finite(&g.x, "state estimate x")?;
        check_positive_definite(&g.p, "covariance P")?;
        Ok(Self { g: *g })
    }

    /// The estimate.
    ///
    /// ```
    /// use edccif_core::{CheckedGaussian, Gaussian};
    /// use nalgebra::{Matrix1, Vector1};
    /// let g = Gaussian { x: Vector1::new(3.0), p: Matrix1::new(2.0) };
    /// assert_eq!(CheckedGaussian::new(&g)?.gaussian().x[0], 3.0);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn gaussian(&self) -> &Gaussian<T, N> {
        &self.g
    }
}

/// Kalman update from innovation statistics: `K = Pxz Pzz⁻¹`, `x̂ = x̂⁻ + K Δz`,
/// `P = sym(P⁻ − K Pxzᵀ)`.
pub fn kalman_update<T: RealField + Copy, const N: usize, const M: usize>(
    x_prior: &SVector<T, N>,
    p_prior: &SMatrix<T, N, N>,
    pxz: &SMatrix<T, N, M>,
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
) -> Result<Gaussian<T, N>> {
    let mut g = Gaussian {
        x: SVector::zeros(),
        p: SMatrix::zeros(),
    };
    kalman_update_into(x_prior, p_prior, pxz, pzz, dz, &mut g)?;
    check_finite(&g.x, "posterior state x")?;
    check_finite(&g.p, "posterior covariance P")?;
    Ok(g)
}

/// [`kalman_update`] written into `out` (on error `out` is unchanged), without
/// its final finiteness checks of the posterior, for a caller that makes them
/// next under the same names (`"posterior state x"`, and `"posterior
/// covariance P"` as the first thing [`cholesky`] does): the same result and
/// the same errors, each check made once.
#[inline(always)]
fn kalman_update_into<T: RealField + Copy, const N: usize, const M: usize>(
    x_prior: &SVector<T, N>,
    p_prior: &SMatrix<T, N, N>,
    pxz: &SMatrix<T, N, M>,
    pzz: &SMatrix<T, M, M>,
    dz: &SVector<T, M>,
    out: &mut Gaussian<T, N>,
) -> Result<()> {
    check_finite(dz, "innovation Δz")?;
    let chol = cholesky(pzz, "innovation covariance Pzz");
    let ch = match &chol {
        Ok(ch) => ch,
        Err(e) => return Err(*e),
    };
    if M == 0 || M > 8 {
        // No measurement, or one long enough for nalgebra's unrolled dot
        // products: the general products.
        let k = ch.solve(&pxz.transpose()).transpose();
        out.x = x_prior + k * dz;
        out.p = sym(&(p_prior - k * pxz.transpose()));
        return Ok(());
    }
    // The same operations as `Cholesky::solve(Pxzᵀ)ᵀ`, `x̂⁻ + K Δz` and
    // `sym(P⁻ − K Pxzᵀ)` above, in the same order, so the same bits; written
    // column by column of `K` and of the result (contiguous, no transposes).
    let k = solve_rows(ch.l_dirty(), pxz);
    // x̂ = x̂⁻ + K Δz, K Δz summed over the columns of K in order.
    let mut kdz = k.column(0) * dz[0];
    for m in 1..M {
        kdz += k.column(m) * dz[m];
    }
    out.x = x_prior + kdz;
    out.p = sym_downdate(p_prior, &k, pxz, None);
    Ok(())
}

/// `Cholesky::solve(&b.transpose()).transpose()` for `S = L Lᵀ` (`l` read in
/// its lower triangle only, `1 ≤ M ≤ 8`): row `i` of the result solves
/// `S kᵢ = B[i, :]ᵀ`. The operations of nalgebra's solve in its order (forward
/// substitution by `L`, then back substitution by `Lᵀ` with its dot products
/// summed from zero, as nalgebra's unrolled dot does below eight terms), for
/// all rows at once: the same bits, no transposes.
#[inline(always)]
fn solve_rows<T: RealField + Copy, const N: usize, const M: usize>(
    l: &SMatrix<T, M, M>,
    b: &SMatrix<T, N, M>,
) -> SMatrix<T, N, M> {
    let mut k = *b;
    for c in 0..M {
        let lcc = l[(c, c)];
        for i in 0..N {
            k[(i, c)] /= lcc;
        }
        for r in (c + 1)..M {
            let lrc = l[(r, c)];
            for i in 0..N {
                let kic = k[(i, c)];
                k[(i, r)] -= kic * lrc;
            }
        }
    }
    for c in (0..M).rev() {
        let mut dot = SVector::<T, N>::zeros();
        for r in (c + 1)..M {
            let lrc = l[(r, c)];
            for i in 0..N {
                dot[i] += lrc * k[(i, r)];
            }
        }
        let lcc = l[(c, c)];
        for i in 0..N {
            k[(i, c)] = (k[(i, c)] - dot[i]) / lcc;
        }
    }
    k
}

/// `sym(P − K Bᵀ)`, or `sym((P − K Bᵀ)·s)` with a `scale` (`M ≥ 1`): the sums
/// of nalgebra's `K * B.transpose()` in its order (column `j` is
/// `Σₘ K[:, m] B[j, m]`), and `sym(A) = (A + Aᵀ)/2` from one triangle, mirrored
/// (the two entries of a pair are the same sum): the same bits as the general
/// expressions.
#[inline(always)]
fn sym_downdate<T: RealField + Copy, const N: usize, const M: usize>(
    p: &SMatrix<T, N, N>,
    k: &SMatrix<T, N, M>,
    b: &SMatrix<T, N, M>,
    scale: Option<T>,
) -> SMatrix<T, N, N> {
    let mut a = *p;
    for j in 0..N {
        for i in 0..N {
            let mut kb = k[(i, 0)] * b[(j, 0)];
            for m in 1..M {
                kb += k[(i, m)] * b[(j, m)];
            }
            a[(i, j)] -= kb;
        }
    }
    if let Some(s) = scale {
        a *= s;
    }
    let half: T = c(0.5);
    let mut out = a;
    for j in 0..N {
        for i in (j + 1)..N {
            let v = (a[(i, j)] + a[(j, i)]) * half;
            out[(i, j)] = v;
            out[(j, i)] = v;
        }
        out[(j, j)] = (a[(j, j)] + a[(j, j)]) * half;
    }
    out
}

/// `sym(A + B)` from one triangle, mirrored: entry `(i, j)` of `sym(A + B)` is
/// `((A[i,j] + B[i,j]) + (A[j,i] + B[j,i]))·½` and entry `(j, i)` the same two
/// sums added the other way round, which is the same number (floating-point
/// addition is commutative; only the payload of a NaN may differ, and the
/// callers reject non-finite results). Half the additions and
/// multiplications of the general expression, the same bits.
#[inline(always)]
fn sym_sum<T: RealField + Copy, const D: usize>(
    a: &SMatrix<T, D, D>,
    b: &SMatrix<T, D, D>,
) -> SMatrix<T, D, D> {
    let half: T = c(0.5);
    let mut out = *a;
    for j in 0..D {
        let d = a[(j, j)] + b[(j, j)];
        out[(j, j)] = (d + d) * half;
        for i in (j + 1)..D {
            let v = ((a[(i, j)] + b[(i, j)]) + (a[(j, i)] + b[(j, i)])) * half;
            out[(i, j)] = v;
            out[(j, i)] = v;
        }
    }
    out
}

/// The sigma-point rule of a covariance-form filter (the EKF's is unused).
fn cov_rule<T: RealField + Copy, const N: usize>(filter: &LocalFilter<T>) -> Result<SigmaRule<T>> {
    match *filter {
        LocalFilter::Ckf | LocalFilter::Ekf => Ok(SigmaRule::cubature(N)),
        LocalFilter::Ukf { alpha, beta, kappa } => SigmaRule::unscented(N, alpha, beta, kappa),
    }
}

/// The prediction of one node's covariance-form step (CKF, EKF or UKF) from
/// `estimate` over `dt`: the prior `(x̂⁻, P⁻)`.
///
/// [`cov_update`] completes the step; [`cov_local`] is the two in one call, bit
/// for bit.
///
/// ```
/// use edccif_core::{cov_predict, models::ConstantAcceleration, Gaussian, LocalFilter};
/// use nalgebra::{Matrix3, Vector3};
/// let ca = ConstantAcceleration::new(0.0)?; // 1-D: [x, vx, ax], no noise
/// let est = Gaussian::new(Vector3::new(0.0, 1.0, 2.0), Matrix3::identity())?;
/// for filter in [LocalFilter::Ckf, LocalFilter::Ekf, LocalFilter::ukf_default()] {
///     let prior = cov_predict(&filter, &ca, 1.0, &est)?;
///     assert!((prior.x - Vector3::new(2.0, 3.0, 2.0)).norm() < 1e-12);
/// }
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cov_predict<T, F, const N: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    estimate: &Gaussian<T, N>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    cov_predict_inner(filter, motion, dt, estimate, false, None)
}

/// [`cov_predict`]; with `input_checked`, `estimate` is known to pass the
/// EKF's input checks (`x` finite, `P` factorised by [`cholesky`]: a
/// [`CheckedGaussian`]), so the EKF does not make them again. The sigma-point
/// filters factorise `P` for their points either way, unless `factor`, the
/// lower Cholesky factor of `P` that [`cholesky`] gives, is passed: then `P` is
/// known finite and positive definite, the sigma-point filters take their
/// points from it and the EKF does not factorise `P` to check it (the same
/// results and errors, see [`sigma_predict_checked`]).
#[inline(always)]
fn cov_predict_inner<T, F, const N: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    estimate: &Gaussian<T, N>,
    input_checked: bool,
    factor: Option<&SMatrix<T, N, N>>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    // Each arm writes its result once (no tuple moved into a `Gaussian`).
    match filter {
        LocalFilter::Ekf => {
            if !input_checked {
                check_finite(&estimate.x, "state estimate x")?;
                // Same contract as the sigma-point filters: the estimate's
                // covariance must be positive definite (a hand-built Gaussian
                // may not be); a factor proves it.
                if factor.is_none() {
                    check_positive_definite(&estimate.p, "covariance P")?;
                }
            }
            validate_positive(dt, "time step dt", false)?;
            let (x, f) = motion.transition_with_jacobian(&estimate.x, dt);
            check_finite(&f, "motion Jacobian F")?;
            // `estimate.p` is finite (its Cholesky above), so the structural
            // zeros a model leaves out of `F P Fᵀ` change no bit.
            let p = sym_sum(
                &motion.jacobian_congruence(&f, &estimate.p),
                &motion.process_noise(dt),
            );
            check_finite(&x, "predicted state x⁻")?;
            check_finite(&p, "predicted covariance P⁻")?;
            Ok(Gaussian { x, p })
        }
        _ => match &sigma_predict_checked(
            &cov_rule::<T, N>(filter)?,
            motion,
            dt,
            &estimate.x,
            &estimate.p,
            factor,
            true,
        ) {
            Ok((x, p)) => Ok(Gaussian { x: *x, p: *p }),
            Err(e) => Err(*e),
        },
    }
}

/// The measurement part of one node's covariance-form step (CKF, EKF or UKF) at
/// a prior from [`cov_predict`], with a trigger and an untriggered-step policy
/// (`Optimal` uses `M`, `P̄` with `G = ∂h/∂x(x̂⁻)`).
///
/// ```
/// use edccif_core::{cov_predict, cov_update, models::{RandomWalk, Position2}, *};
/// use nalgebra::{Matrix2, Vector2};
/// let rw = RandomWalk::new(0.1)?;
/// let cam = Position2::new([1.0, 1.0])?;
/// let est = Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::identity())?;
/// let prior = cov_predict(&LocalFilter::Ckf, &rw, 1.0, &est)?; // P⁻ = 1.1 I
/// let trig = Trigger::Always;
/// let step = cov_update(&LocalFilter::Ckf, &cam, &prior, &Observation::Measured(Vector2::new(2.1, 0.0)),
///                       &trig, &TriggerState::new(&trig), &EtOptions::default())?;
/// // Kalman gain 1.1 / 2.1 per axis
/// assert!((step.posterior.x - Vector2::new(1.1, 0.0)).norm() < 1e-12);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn cov_update<T, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    sensor: &H,
    prior: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CovLocal<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    // Borrowed inside the `Result`: the step is copied once, into the result.
    match &cov_update_inner(
        filter,
        sensor,
        prior,
        obs,
        trigger,
        trigger_state,
        opts,
        false,
        check_positive_definite_mirrored,
    ) {
        Ok((step, ())) => Ok(*step),
        Err(e) => Err(*e),
    }
}

/// [`cov_update`]; with `prior_checked`, `prior` comes from [`cov_predict`],
/// which has checked that it is finite under the names the update would check
/// it with, so the update does not check it again. `finish` is the
/// posterior's definiteness check, [`check_positive_definite_mirrored`] or,
/// for a caller converting the posterior to information form (the consensus
/// rows), [`cholesky_mirrored`] whose factor it returns with the step, so that
/// `P` is not factorised again (a check that returns `()` makes the result
/// just the step: no factor is carried or copied).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn cov_update_inner<T, H, K, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    sensor: &H,
    prior: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
    prior_checked: bool,
    finish: impl FnOnce(&SMatrix<T, N, N>, &'static str) -> Result<K>,
) -> Result<(CovLocal<T, N, M>, K)>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let rule = cov_rule::<T, N>(filter)?;
    if !prior_checked {
        check_finite(&prior.x, "predicted state x⁻")?;
        check_finite(&prior.p, "predicted covariance P⁻")?;
    }
    // By reference: the prior is copied only when it is the posterior.
    let (x_prior, p_prior) = (&prior.x, &prior.p);
    // Innovation statistics at the prior: sigma points, or linearisation for the EKF.
    let stats = || -> Result<MeasurementStats<T, N, M>> {
        match filter {
            LocalFilter::Ekf => {
                let (z_hat, g) = sensor.measure_with_jacobian(x_prior);
                check_finite(&g, "measurement Jacobian G")?;
                // `P⁻` is finite (checked above), so the structural zeros a
                // model leaves out of `P⁻ Gᵀ` and `G P⁻ Gᵀ` change no bit.
                let (pxz, gpg) = sensor.jacobian_products(&g, p_prior);
                Ok(MeasurementStats {
                    z_hat,
                    pzz: sym_sum(&gpg, &sensor.noise()),
                    pxz,
                })
            }
            _ => {
                let l = cholesky_lower(p_prior, "predicted covariance P⁻")? * rule.scale;
                sigma_measure(&rule, sensor, x_prior, &l)
            }
        }
    };
    let z_mean = || -> Result<SVector<T, M>> {
        match filter {
            LocalFilter::Ekf => {
                let z = sensor.measure(x_prior);
                check_finite(&z, "predicted measurement ẑ")?;
                Ok(z)
            }
            _ => {
                let l = cholesky_lower(p_prior, "predicted covariance P⁻")? * rule.scale;
                sigma_measure_mean(&rule, sensor, x_prior, &l)
            }
        }
    };
    decide_measurement(
        sensor,
        x_prior,
        obs,
        trigger,
        trigger_state,
        opts,
        stats,
        z_mean,
        |decision| {
            // The posterior is written once, into the result.
            let mut out = CovLocal {
                posterior: Gaussian {
                    x: SVector::zeros(),
                    p: SMatrix::zeros(),
                },
                triggered: decision.triggered,
                trigger_state: decision.trigger_state,
                gated: decision.gated,
            };
            match decision.action {
                MeasurementAction::Nothing => out.posterior = *prior,
                MeasurementAction::Update(s, dz) => {
                    // The posterior's finiteness is checked below under the
                    // names `kalman_update` would check it with.
                    kalman_update_into(x_prior, p_prior, &s.pxz, &s.pzz, dz, &mut out.posterior)?;
                }
                MeasurementAction::Optimal { g, dz_bar } => {
                    // The posterior is `P̄` itself: the closed form of the
                    // information filter's contribution does not apply here.
                    // The sensor's products of `G` with `P⁻` (finite, checked
                    // above).
                    let (r, delta) = trigger.untriggered_noise(&sensor.noise(), opts);
                    let gain = EtGain::with_products(p_prior, g, &r, delta, opts, |g| {
                        sensor.jacobian_products(g, p_prior)
                    })?;
                    out.posterior.x = x_prior + gain.m * dz_bar;
                    out.posterior.p = gain.p_bar;
                }
            }
            // The update's `P⁻ − K Pxzᵀ` (and `P̄`) can lose definiteness by
            // cancellation when the inputs are badly scaled: never return such
            // a covariance.
            check_finite(&out.posterior.x, "posterior state x")?;
            // The posterior `P` is the finite prior, a `sym` or mirrored
            // result, or the finite `P̄`: its upper triangle has the
            // finiteness of its lower one, so a factorisation that succeeds
            // proves it finite and the finiteness pass is made only to name a
            // failure (the same errors; `finish` is one of the mirrored
            // checks).
            let factor = finish(&out.posterior.p, "posterior covariance P")?;
            Ok((out, factor))
        },
    )
}

/// One node's covariance-form local step (CKF, EKF or UKF) with a trigger and
/// an untriggered-step policy (`Optimal` uses `M`, `P̄` with `G = ∂h/∂x(x̂⁻)`):
/// [`cov_predict`] then [`cov_update`].
///
/// ```
/// use edccif_core::{cov_local, models::{RandomWalk, Position2}, *};
/// use nalgebra::{Matrix2, Vector2};
/// let (rw, cam) = (RandomWalk::new(0.1)?, Position2::new([1.0, 1.0])?);
/// let est = Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::identity())?;
/// let trig = Trigger::Always;
/// let step = cov_local(&LocalFilter::Ekf, &rw, 1.0, &cam, &est, &Observation::Measured(Vector2::new(2.1, 0.0)),
///                      &trig, &TriggerState::new(&trig), &EtOptions::default())?;
/// assert!((step.posterior.x - Vector2::new(1.1, 0.0)).norm() < 1e-12);
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn cov_local<T, F, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<CovLocal<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    // Borrowed inside the `Result`: the step is copied once, into the result.
    match &cov_local_inner(
        filter,
        motion,
        dt,
        sensor,
        estimate,
        obs,
        trigger,
        trigger_state,
        opts,
        false,
        None,
        check_positive_definite_mirrored,
    ) {
        Ok((step, ())) => Ok(*step),
        Err(e) => Err(*e),
    }
}

/// [`cov_local`] from an estimate known to pass its input checks (a
/// [`CheckedGaussian`], e.g. the previous step's posterior), returning the
/// posterior also as a [`CheckedGaussian`] for the next step: the filter loop
/// of a single node, with `P` factorised once per step (the posterior's
/// definiteness check) instead of twice. The same result, bit for bit, and the
/// same errors as [`cov_local`] on the same estimate; a failed step changes
/// nothing (the caller keeps its estimate and trigger state).
///
/// ```
/// use edccif_core::{cov_local, cov_local_chained, models::{RandomWalk, Position2}, *};
/// use nalgebra::{Matrix2, Vector2};
/// let (rw, cam) = (RandomWalk::new(0.1)?, Position2::new([1.0, 1.0])?);
/// let est = Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::identity())?;
/// let (trig, opts) = (Trigger::Always, EtOptions::default());
/// let mut state = (CheckedGaussian::new(&est)?, TriggerState::new(&trig));
/// for z in [Vector2::new(2.1, 0.0), Vector2::new(2.0, 0.1)] {
///     let obs = Observation::Measured(z);
///     let plain = cov_local(&LocalFilter::Ekf, &rw, 1.0, &cam, state.0.gaussian(), &obs,
///                           &trig, &state.1, &opts)?;
///     let (step, next) = cov_local_chained(&LocalFilter::Ekf, &rw, 1.0, &cam, &state.0, &obs,
///                                          &trig, &state.1, &opts)?;
///     assert_eq!(step, plain);
///     assert_eq!(next.gaussian(), &step.posterior);
///     state = (next, step.trigger_state);
/// }
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn cov_local_chained<T, F, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &CheckedGaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<(CovLocal<T, N, M>, CheckedGaussian<T, N>)>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    // The posterior passed `finish`'s checks (`x` finite, `P` factorised):
    // the checks of `CheckedGaussian::new`.
    match &cov_local_inner(
        filter,
        motion,
        dt,
        sensor,
        &estimate.g,
        obs,
        trigger,
        trigger_state,
        opts,
        true,
        None,
        check_positive_definite_mirrored,
    ) {
        Ok((step, ())) => Ok((*step, CheckedGaussian { g: step.posterior })),
        Err(e) => Err(*e),
    }
}

/// [`cov_local`], also returning the Cholesky factor of the posterior `P`
/// that its definiteness check computed (see [`cov_update_inner`]); `factor`,
/// the lower Cholesky factor of `estimate.p` when the caller has it (see
/// [`cov_predict_inner`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn cov_local_factored<T, F, H, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &Gaussian<T, N>,
    factor: Option<&SMatrix<T, N, N>>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
) -> Result<(CovLocal<T, N, M>, Cholesky<T, Const<N>>)>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    // Borrowed inside the `Result`, as elsewhere.
    match &cov_local_inner(
        filter,
        motion,
        dt,
        sensor,
        estimate,
        obs,
        trigger,
        trigger_state,
        opts,
        false,
        factor,
        cholesky_mirrored,
    ) {
        Ok((step, factor)) => Ok((*step, *factor)),
        Err(e) => Err(*e),
    }
}

/// [`cov_local_factored`]; with `input_checked`, `estimate` is known to pass
/// the input checks, and `factor` as in [`cov_predict_inner`]; `finish` as in
/// [`cov_update_inner`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn cov_local_inner<T, F, H, K, const N: usize, const M: usize>(
    filter: &LocalFilter<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    estimate: &Gaussian<T, N>,
    obs: &Observation<T, M>,
    trigger: &Trigger<T>,
    trigger_state: &TriggerState<T, M>,
    opts: &EtOptions<T>,
    input_checked: bool,
    factor: Option<&SMatrix<T, N, N>>,
    finish: impl FnOnce(&SMatrix<T, N, N>, &'static str) -> Result<K>,
) -> Result<(CovLocal<T, N, M>, K)>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    // The prior borrowed inside its `Result`, not moved out by `?`; it is
    // finite (checked by the prediction under the update's names).
    match &cov_predict_inner(filter, motion, dt, estimate, input_checked, factor) {
        Ok(prior) => cov_update_inner(
            filter,
            sensor,
            prior,
            obs,
            trigger,
            trigger_state,
            opts,
            true,
            finish,
        ),
        Err(e) => Err(*e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values over several magnitudes, both signs, and exact zeros.
    fn filled<const D: usize>(seed: &mut u64) -> SMatrix<f64, D, D> {
        SMatrix::from_fn(|_, _| {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            if seed.is_multiple_of(11) {
                return 0.0;
            }
            let u = (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            u * 10f64.powi((*seed % 9) as i32 - 4)
        })
    }

    fn bits<const D: usize>(a: &SMatrix<f64, D, D>) -> [u64; 64] {
        let mut out = [0; 64];
        for (o, v) in out.iter_mut().zip(a.iter()) {
            *o = v.to_bits();
        }
        out
    }

    /// `sym_downdate` against the general expressions
    /// `sym(P − K Bᵀ)` and `sym((P − K Bᵀ)·s)`, bit for bit, for `M = 3` and
    /// `M = 1`.
    #[test]
    fn sym_downdate_equals_the_general_expressions_bit_for_bit() {
        fn rect<const R: usize, const C: usize>(seed: &mut u64) -> SMatrix<f64, R, C> {
            let big = filled::<7>(seed);
            SMatrix::from_fn(|i, j| big[(i, j)])
        }
        let mut seed = 5;
        for case in 0..2_000 {
            let p = filled::<7>(&mut seed);
            let scale = (case % 2 == 1).then_some(1.0 + (case as f64) * 1e-4);
            let (k3, b3) = (rect::<7, 3>(&mut seed), rect::<7, 3>(&mut seed));
            let general = match scale {
                None => sym(&(p - k3 * b3.transpose())),
                Some(s) => sym(&((p - k3 * b3.transpose()) * s)),
            };
            assert_eq!(
                bits(&sym_downdate(&p, &k3, &b3, scale)),
                bits(&general),
                "case {case}, M = 3"
            );
            let (k1, b1) = (rect::<7, 1>(&mut seed), rect::<7, 1>(&mut seed));
            let general = match scale {
                None => sym(&(p - k1 * b1.transpose())),
                Some(s) => sym(&((p - k1 * b1.transpose()) * s)),
            };
            assert_eq!(
                bits(&sym_downdate(&p, &k1, &b1, scale)),
                bits(&general),
                "case {case}, M = 1"
            );
        }
    }

    #[test]
    fn sym_sum_equals_sym_of_the_sum_bit_for_bit() {
        let mut seed = 3;
        for _ in 0..2_000 {
            let (a, b) = (filled::<7>(&mut seed), filled::<7>(&mut seed));
            assert_eq!(bits(&sym_sum(&a, &b)), bits(&sym(&(a + b))));
            let (a, b) = (filled::<3>(&mut seed), filled::<3>(&mut seed));
            assert_eq!(bits(&sym_sum(&a, &b)), bits(&sym(&(a + b))));
        }
    }
}
