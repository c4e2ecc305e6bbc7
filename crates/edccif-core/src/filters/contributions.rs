//! The information contributions `(ī, Ī)` a node adds to its prior
//! (`docs/algorithm.md` §3 step 5): of a triggered step, in the paper's form
//! and from the prior's Cholesky factor, and of an untriggered step, in the
//! paper's stable form and in closed form.

use nalgebra::{RealField, SMatrix, SVector};

use crate::error::{Error, Result};
use crate::linalg::{all_finite, c, check_finite, cholesky, spd_inverse, sym, validate_positive};
use crate::message::Contribution;
use crate::sigma::MeasurementStats;

use super::gain::{EtGain, EtOptions};

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
/// [`cif_update`](crate::cif_update) for models with
/// [`MeasurementModel::fast_trig`](crate::MeasurementModel::fast_trig)).
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
pub(super) fn contribution_whitened<T, const N: usize, const M: usize>(
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
    let not_pd = Error::NotPositiveDefinite { what };
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
    // `Ī` is checked only when `ī` fails, and first: the error names `Ī`
    // when it is not finite.
    if !all_finite(&i) {
        check_finite(&imat, "contribution Ī")?;
        return Err(Error::NonFinite {
            what: "contribution ī",
        });
    }
    Ok(Contribution { i, imat })
}

/// The information filter's contribution of an untriggered step under the
/// `Optimal` policy: the closed form when `opts` asks for it, else the gain
/// [`EtGain`] and the stable form (the paper's rows).
#[allow(clippy::too_many_arguments)]
pub(super) fn optimal_contribution<T, const N: usize, const M: usize>(
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
