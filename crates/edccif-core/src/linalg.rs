//! Small dense linear-algebra helpers on stack matrices: symmetrisation, checked
//! Cholesky factorisation, SPD inverse, finiteness checks.

use nalgebra::{Cholesky, Const, RealField, SMatrix, SVector};

use crate::error::{Error, Result};

/// Converts an `f64` constant into the scalar type.
#[inline(always)]
pub(crate) fn c<T: RealField>(v: f64) -> T {
    nalgebra::convert(v)
}

/// `sym(A) = (A + Aᵀ)/2`.
///
/// ```
/// use nalgebra::Matrix2;
/// let a = Matrix2::new(1.0, 2.0, 4.0, 3.0);
/// assert_eq!(edccif_core::linalg::sym(&a), Matrix2::new(1.0, 3.0, 3.0, 3.0));
/// ```
#[inline]
pub fn sym<T: RealField + Copy, const D: usize>(a: &SMatrix<T, D, D>) -> SMatrix<T, D, D> {
    let half: T = c(0.5);
    (a + a.transpose()) * half
}

/// True when every entry is finite.
#[inline]
pub fn all_finite<T: RealField + Copy, const R: usize, const C: usize>(
    a: &SMatrix<T, R, C>,
) -> bool {
    // Branch-free reduction over the contiguous storage: no early exit and no
    // strided matrix iterator, so the loop vectorises.
    a.as_slice().iter().fold(true, |ok, v| ok & v.is_finite())
}

/// `F P Fᵀ` for a square `F` whose entries outside `pattern` are exactly zero:
/// `pattern[i]` lists, in ascending order, the columns of row `i` that may be
/// non-zero (exact ones count as non-zero: `1·x = x` costs one multiplication).
///
/// Every entry is the sum nalgebra's `(F * P) * F.transpose()` forms, in the same
/// order (`k` ascending), with the terms `0·x` left out. Leaving them out changes
/// no bit: adding `±0` to a non-zero partial sum returns it unchanged, and a sum
/// that starts from `±0` equals its next term. Only the sign of an entry that is
/// exactly zero may differ, and a `P` with infinite or NaN entries (where `0·∞` is
/// NaN) must be rejected by the caller first. A wrong `pattern` (a non-zero entry
/// left out) gives a wrong product, so models state it next to their Jacobian and
/// test it.
///
/// ```
/// use nalgebra::Matrix3;
/// // constant velocity on one axis with a constant third state: rows {0, 1}, {1}, {2}
/// let f = Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
/// let p = Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.0, 0.2, -0.1, 0.2, 0.5);
/// let sparse = edccif_core::linalg::congruence_sparse(&f, &p, &[&[0, 1], &[1], &[2]]);
/// assert_eq!(sparse, f * p * f.transpose());
/// ```
#[inline]
pub fn congruence_sparse<T: RealField + Copy, const N: usize>(
    f: &SMatrix<T, N, N>,
    p: &SMatrix<T, N, N>,
    pattern: &[&[usize]; N],
) -> SMatrix<T, N, N> {
    // F P, entry by entry: row i of F against column j of P.
    let mut fp = SMatrix::<T, N, N>::zeros();
    for j in 0..N {
        for (i, cols) in pattern.iter().enumerate() {
            if let Some((&k0, rest)) = cols.split_first() {
                let mut acc = f[(i, k0)] * p[(k0, j)];
                for &k in rest {
                    acc += f[(i, k)] * p[(k, j)];
                }
                fp[(i, j)] = acc;
            }
        }
    }
    // (F P) Fᵀ, column j = Σ_k F[j,k] · (F P)[:, k]: contiguous columns.
    let mut out = SMatrix::<T, N, N>::zeros();
    for (j, cols) in pattern.iter().enumerate() {
        if let Some((&k0, rest)) = cols.split_first() {
            let fjk = f[(j, k0)];
            for i in 0..N {
                out[(i, j)] = fp[(i, k0)] * fjk;
            }
            for &k in rest {
                let fjk = f[(j, k)];
                for i in 0..N {
                    out[(i, j)] += fp[(i, k)] * fjk;
                }
            }
        }
    }
    out
}

/// `(P Gᵀ, G P Gᵀ)` for an `M × N` Jacobian `G` whose columns from `D` on are
/// exactly zero (a sensor that reads only the first `D` state components, the
/// position): what [`MeasurementModel::jacobian_products`](crate::model::MeasurementModel::jacobian_products)
/// returns for the catalogue's sensors. `D ≥ N` is the general product.
///
/// Every entry is the sum nalgebra's `P * G.transpose()` and `G * (P Gᵀ)` form,
/// in the same order (`k` ascending), with the terms `0·x` of the columns
/// `k ≥ D` left out: as in [`congruence_sparse`], that changes no bit (only the
/// sign of an entry that is exactly zero may differ) provided `P` and `P Gᵀ`
/// are finite; the filters check `P` first, and a non-finite `P Gᵀ` (overflow)
/// gives a non-finite or otherwise failing step either way.
///
/// ```
/// use nalgebra::{Matrix2x4, Matrix4};
/// // a range/bearing-like Jacobian: position columns only
/// let g = Matrix2x4::new(0.6, 0.8, 0.0, 0.0, -0.16, 0.12, 0.0, 0.0);
/// let p = Matrix4::from_fn(|i, j| if i == j { 2.0 } else { 0.1 * (i + j) as f64 });
/// let (pg, gpg) = edccif_core::linalg::jacobian_products_leading::<f64, 4, 2, 2>(&g, &p);
/// assert_eq!(pg, p * g.transpose());
/// assert_eq!(gpg, g * (p * g.transpose()));
/// ```
#[inline(always)]
pub fn jacobian_products_leading<T, const N: usize, const M: usize, const D: usize>(
    g: &SMatrix<T, M, N>,
    p: &SMatrix<T, N, N>,
) -> (SMatrix<T, N, M>, SMatrix<T, M, M>)
where
    T: RealField + Copy,
{
    let d = if D < N { D } else { N };
    let mut pg = SMatrix::<T, N, M>::zeros();
    let mut gpg = SMatrix::<T, M, M>::zeros();
    if d == 0 {
        return (pg, gpg);
    }
    // P Gᵀ, column m = Σ_k G[m,k] · P[:, k] (contiguous columns of P).
    for m in 0..M {
        let g0 = g[(m, 0)];
        for i in 0..N {
            pg[(i, m)] = p[(i, 0)] * g0;
        }
        for k in 1..d {
            let gk = g[(m, k)];
            for i in 0..N {
                pg[(i, m)] += p[(i, k)] * gk;
            }
        }
    }
    // G (P Gᵀ), entry (a, b) = Σ_k G[a,k] · (P Gᵀ)[k, b].
    for b in 0..M {
        for a in 0..M {
            let mut s = g[(a, 0)] * pg[(0, b)];
            for k in 1..d {
                s += g[(a, k)] * pg[(k, b)];
            }
            gpg[(a, b)] = s;
        }
    }
    (pg, gpg)
}

/// `A Aᵀ + B Bᵀ`: the lower triangle is summed and mirrored, so the result is
/// exactly symmetric with half the multiplications of the two general products.
/// Every entry is the same sum, in the same order (`k` ascending, each product
/// `A[i,k]·A[j,k]`), as nalgebra's `A * A.transpose() + B * B.transpose()`, so
/// the two agree bit for bit.
///
/// ```
/// use nalgebra::Matrix3x2;
/// let a = Matrix3x2::new(1.0, 2.0, 0.3, -4.0, 5.5, 0.25);
/// let b = Matrix3x2::new(-0.7, 1.5, 2.0, 0.1, 3.0, -1.0);
/// let want = a * a.transpose() + b * b.transpose();
/// assert_eq!(edccif_core::linalg::sym_rank2k(&a, &b), want);
/// ```
#[inline]
pub fn sym_rank2k<T: RealField + Copy, const R: usize, const C: usize>(
    a: &SMatrix<T, R, C>,
    b: &SMatrix<T, R, C>,
) -> SMatrix<T, R, R> {
    let mut sa = SMatrix::<T, R, R>::zeros();
    let mut sb = SMatrix::<T, R, R>::zeros();
    if C == 0 {
        return sa;
    }
    // Column by column (`k` outermost) so the inner loops run down contiguous
    // columns; each entry still accumulates its products in ascending `k`.
    for j in 0..R {
        let (aj, bj) = (a[(j, 0)], b[(j, 0)]);
        for i in j..R {
            sa[(i, j)] = a[(i, 0)] * aj;
            sb[(i, j)] = b[(i, 0)] * bj;
        }
    }
    for k in 1..C {
        for j in 0..R {
            let (aj, bj) = (a[(j, k)], b[(j, k)]);
            for i in j..R {
                sa[(i, j)] += a[(i, k)] * aj;
                sb[(i, j)] += b[(i, k)] * bj;
            }
        }
    }
    for j in 0..R {
        for i in j..R {
            let v = sa[(i, j)] + sb[(i, j)];
            sa[(i, j)] = v;
            sa[(j, i)] = v;
        }
    }
    sa
}

/// Fails with [`Error::NonFinite`] naming `what` when `a` holds NaN or ±∞.
#[inline]
pub fn check_finite<T: RealField + Copy, const R: usize, const C: usize>(
    a: &SMatrix<T, R, C>,
    what: &'static str,
) -> Result<()> {
    if all_finite(a) {
        Ok(())
    } else {
        Err(Error::NonFinite { what })
    }
}

/// Cholesky factorisation of a symmetric matrix, with non-finite entries and
/// non-positive-definiteness reported as named errors. Only the lower triangle
/// of `a` is read.
///
/// The factor is computed here, not by `nalgebra::Cholesky::new`, but with the
/// same floating-point operations in the same order, so the returned
/// decomposition is the one nalgebra 0.34 computes, bit for bit, upper triangle
/// included, and so are its `l()`, `solve` and `inverse`. It fails with
/// [`Error::NonFinite`] when `a` holds NaN or ±∞, and with
/// [`Error::NotPositiveDefinite`] when a pivot is zero, negative or NaN, or the
/// factor's diagonal is not finite (a factor that is not finite and positive
/// on its diagonal would give an infinite inverse).
///
/// ```
/// use nalgebra::Matrix2;
/// use edccif_core::{linalg::cholesky, Error};
/// let a = Matrix2::new(2.0, 1.0, 1.0, 2.0);
/// let ch = cholesky(&a, "A").unwrap();
/// assert_eq!(ch.l_dirty(), nalgebra::Cholesky::new(a).unwrap().l_dirty());
/// assert_eq!(
///     cholesky(&Matrix2::new(1.0, 2.0, 2.0, 1.0), "A").unwrap_err(),
///     Error::NotPositiveDefinite { what: "A" }
/// );
/// ```
#[inline]
pub fn cholesky<T: RealField + Copy, const D: usize>(
    a: &SMatrix<T, D, D>,
    what: &'static str,
) -> Result<Cholesky<T, Const<D>>> {
    check_finite(a, what)?;
    let mut m = *a;
    if cholesky_in_place(&mut m) {
        Ok(Cholesky::pack_dirty(m))
    } else {
        Err(Error::NotPositiveDefinite { what })
    }
}

/// [`cholesky`]'s checks without its factor: `Ok(())` exactly when
/// `cholesky(a, what)` succeeds, and its errors otherwise (the same
/// factorisation, [`cholesky_in_place`], on a copy), for a caller that only
/// needs to know that `a` is positive definite.
#[inline]
pub(crate) fn check_positive_definite<T: RealField + Copy, const D: usize>(
    a: &SMatrix<T, D, D>,
    what: &'static str,
) -> Result<()> {
    check_finite(a, what)?;
    let mut m = *a;
    if cholesky_in_place(&mut m) {
        Ok(())
    } else {
        Err(Error::NotPositiveDefinite { what })
    }
}

/// [`cholesky`] for a matrix whose strict upper triangle has the finiteness of
/// its lower one (entry `(j, i)` is finite exactly when `(i, j)` is: a result
/// of [`sym`] or mirrored from one triangle): the same result and the same
/// errors, with the finiteness pass made only when the factorisation fails.
///
/// A factorisation that succeeds proves the lower triangle finite: a
/// non-finite `A[i, i]` is a NaN or negative pivot, or an infinite factor
/// diagonal; a non-finite `L[i, k]` (`k < i`) makes row `i`'s pivot
/// `A[i, i] − Σₖ L[i, k]²` NaN or −∞ (each term is `−L[i, k]²`, never +∞),
/// and a non-finite `A[i, j]` (`j < i`) makes `L[i, j]` non-finite unless
/// another `L[i, k]`, `k < j`, already is (the factors `L[j, k]` are finite
/// once row `j`'s pivot has passed). With the mirrored finiteness, the whole
/// matrix is finite; when the factorisation fails, `a` is scanned to name the
/// error as [`cholesky`] does ([`Error::NonFinite`] first).
#[inline]
pub(crate) fn cholesky_mirrored<T: RealField + Copy, const D: usize>(
    a: &SMatrix<T, D, D>,
    what: &'static str,
) -> Result<Cholesky<T, Const<D>>> {
    let mut m = *a;
    if cholesky_in_place(&mut m) {
        Ok(Cholesky::pack_dirty(m))
    } else {
        check_finite(a, what)?;
        Err(Error::NotPositiveDefinite { what })
    }
}

/// [`check_positive_definite`] for a matrix with the mirrored finiteness of
/// [`cholesky_mirrored`]: `Ok(())` exactly when `cholesky(a, what)` succeeds,
/// and its errors otherwise, the finiteness pass made only on failure.
#[inline]
pub(crate) fn check_positive_definite_mirrored<T: RealField + Copy, const D: usize>(
    a: &SMatrix<T, D, D>,
    what: &'static str,
) -> Result<()> {
    let mut m = *a;
    if cholesky_in_place(&mut m) {
        Ok(())
    } else {
        check_finite(a, what)?;
        Err(Error::NotPositiveDefinite { what })
    }
}

/// Overwrites the lower triangle of `m` with its Cholesky factor; false when a
/// pivot fails. The strict upper triangle is left as it was.
///
/// This is nalgebra 0.34.2's `Cholesky::new_internal` (without substitute)
/// operation for operation: column `j` is updated by the columns `k < j` in
/// ascending order through `axpy(-L[j,k], L[j.., k], 1)`, which evaluates
/// `(a·x)·1 + 1·y` per entry (written out below; the products by one are exact
/// and the compiler drops them); then the pivot `d` is replaced by `√d` and the
/// column below it divided by `√d` (a division, not a multiplication by the
/// reciprocal). nalgebra gives up on a pivot that is zero or that `try_sqrt`
/// refuses (negative or NaN), that is on `!(d > 0)`, tested here the same way
/// (for `d > 0`, `try_sqrt` is the plain `sqrt`). A factor whose diagonal is
/// not finite is rejected at the end, as the wrapper around nalgebra did (a
/// guard only: with finite input a pivot never exceeds its diagonal entry, and
/// the square root of a positive finite pivot is positive and finite).
///
/// Columns are contiguous slices of the column-major storage, so the loops
/// carry no bounds checks and unroll for the fixed `D`.
#[inline]
fn cholesky_in_place<T: RealField + Copy, const D: usize>(m: &mut SMatrix<T, D, D>) -> bool {
    let one = T::one();
    let s = m.as_mut_slice();
    for j in 0..D {
        let (left, right) = s.split_at_mut(j * D);
        let col_j = &mut right[j..D];
        for k in 0..j {
            let col_k = &left[k * D + j..(k + 1) * D];
            let factor = -col_k[0];
            for (y, &x) in col_j.iter_mut().zip(col_k) {
                *y = factor * x * one + one * *y;
            }
        }
        let Some((pivot, below)) = col_j.split_first_mut() else {
            return false; // unreachable: j < D
        };
        let diag = *pivot;
        if !(diag > T::zero()) {
            return false;
        }
        let denom = diag.sqrt();
        *pivot = denom;
        for y in below {
            *y /= denom;
        }
    }
    (0..D).all(|j| s[j * D + j].is_finite())
}

/// The lower Cholesky factor `L` of a symmetric matrix (`A = L Lᵀ`, upper
/// triangle zero), with the errors of [`cholesky`]: `cholesky(a, what)?.l()`.
///
/// ```
/// use nalgebra::Matrix3;
/// use edccif_core::linalg::{cholesky, cholesky_lower};
/// let a = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
/// let l = cholesky_lower(&a, "A").unwrap();
/// assert_eq!(l, cholesky(&a, "A").unwrap().l());
/// assert!((l * l.transpose() - a).norm() < 1e-15);
/// ```
#[inline]
pub fn cholesky_lower<T: RealField + Copy, const D: usize>(
    a: &SMatrix<T, D, D>,
    what: &'static str,
) -> Result<SMatrix<T, D, D>> {
    Ok(cholesky(a, what)?.l())
}

/// `A⁻¹` from the Cholesky factor `A = L Lᵀ`: `L⁻¹` by forward substitution, then
/// the lower triangle of `L⁻ᵀ L⁻¹`, mirrored. About a third of the flops of solving
/// `L Lᵀ X = I` column by column, and exactly symmetric.
///
/// ```
/// use nalgebra::Matrix3;
/// use edccif_core::linalg::{cholesky, chol_inverse};
/// let a = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
/// let inv = chol_inverse(&cholesky(&a, "A").unwrap());
/// assert!((inv * a - Matrix3::identity()).norm() < 1e-14);
/// assert_eq!(inv, inv.transpose());
/// ```
#[inline]
pub fn chol_inverse<T: RealField + Copy, const D: usize>(
    ch: &Cholesky<T, Const<D>>,
) -> SMatrix<T, D, D> {
    lower_inverse(ch.l_dirty()) // only the lower triangle is meaningful
}

/// [`chol_inverse`] from the factor `L` itself (its upper triangle is not read),
/// e.g. from [`cholesky_lower`].
///
/// ```
/// use nalgebra::Matrix2;
/// use edccif_core::linalg::{cholesky_lower, lower_inverse};
/// let a = Matrix2::new(4.0, 2.0, 2.0, 3.0);
/// let inv = lower_inverse(&cholesky_lower(&a, "A").unwrap());
/// assert!((inv * a - Matrix2::identity()).norm() < 1e-15);
/// ```
#[inline]
pub fn lower_inverse<T: RealField + Copy, const D: usize>(
    l: &SMatrix<T, D, D>,
) -> SMatrix<T, D, D> {
    let mut inv = SMatrix::<T, D, D>::zeros();
    lower_inverse_into(l, &mut inv);
    inv
}

/// [`chol_inverse`] written into `inv` (every entry written, none read), so
/// that a caller's buffer takes the inverse without a copy of the returned
/// matrix. The same operations as [`chol_inverse`].
#[inline]
pub(crate) fn chol_inverse_into<T: RealField + Copy, const D: usize>(
    ch: &Cholesky<T, Const<D>>,
    inv: &mut SMatrix<T, D, D>,
) {
    lower_inverse_into(ch.l_dirty(), inv)
}

/// [`lower_inverse`] written into `inv` (every entry written, none read).
#[inline]
fn lower_inverse_into<T: RealField + Copy, const D: usize>(
    l: &SMatrix<T, D, D>,
    inv: &mut SMatrix<T, D, D>,
) {
    let mut li = SMatrix::<T, D, D>::zeros();
    for j in 0..D {
        li[(j, j)] = T::one() / l[(j, j)];
        for i in (j + 1)..D {
            let mut s = T::zero();
            for k in j..i {
                s += l[(i, k)] * li[(k, j)];
            }
            li[(i, j)] = -s / l[(i, i)];
        }
    }
    for j in 0..D {
        for i in j..D {
            let mut s = T::zero();
            for k in i..D {
                s += li[(k, i)] * li[(k, j)];
            }
            inv[(i, j)] = s;
            inv[(j, i)] = s;
        }
    }
}

/// Inverse of a symmetric positive-definite matrix through its Cholesky factor
/// ([`chol_inverse`]; exactly symmetric).
#[inline]
pub fn spd_inverse<T: RealField + Copy, const D: usize>(
    a: &SMatrix<T, D, D>,
    what: &'static str,
) -> Result<SMatrix<T, D, D>> {
    let inv = chol_inverse(&cholesky(a, what)?);
    check_finite(&inv, what)?;
    Ok(inv)
}

/// Checks that a user-supplied covariance is finite, symmetric (relative
/// tolerance 1e-9 of its largest entry) and positive definite.
pub fn validate_covariance<T: RealField + Copy, const D: usize>(
    p: &SMatrix<T, D, D>,
    what: &'static str,
) -> Result<()> {
    check_finite(p, what)?;
    let scale = p.iter().fold(T::zero(), |m, v| m.max(v.abs()));
    let tol = scale * c::<T>(1e-9);
    for i in 0..D {
        for j in (i + 1)..D {
            if (p[(i, j)] - p[(j, i)]).abs() > tol {
                return Err(Error::NotSymmetric { what });
            }
        }
    }
    cholesky(p, what).map(|_| ())
}

/// Checks that a vector is finite.
#[inline]
pub fn validate_vector<T: RealField + Copy, const D: usize>(
    v: &SVector<T, D>,
    what: &'static str,
) -> Result<()> {
    check_finite(v, what)
}

/// Checks a scalar parameter: finite and `> 0` (or `>= 0` when `allow_zero`).
pub fn validate_positive<T: RealField + Copy>(
    v: T,
    what: &'static str,
    allow_zero: bool,
) -> Result<()> {
    let ok = v.is_finite() && (v > T::zero() || (allow_zero && v == T::zero()));
    if ok {
        Ok(())
    } else if allow_zero {
        Err(Error::InvalidParameter {
            what,
            expected: "finite and >= 0",
        })
    } else {
        Err(Error::InvalidParameter {
            what,
            expected: "finite and > 0",
        })
    }
}

/// `Cholesky::solve(&b.transpose()).transpose()` for `S = L Lᵀ` (`l` read in
/// its lower triangle only, `1 ≤ M ≤ 8`): row `i` of the result solves
/// `S kᵢ = B[i, :]ᵀ`. The operations of nalgebra's solve in its order (forward
/// substitution by `L`, then back substitution by `Lᵀ` with its dot products
/// summed from zero, as nalgebra's unrolled dot does below eight terms), for
/// all rows at once: the same bits, no transposes.
#[inline(always)]
pub(crate) fn solve_rows<T: RealField + Copy, const N: usize, const M: usize>(
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
pub(crate) fn sym_downdate<T: RealField + Copy, const N: usize, const M: usize>(
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
pub(crate) fn sym_sum<T: RealField + Copy, const D: usize>(
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic values spread over several magnitudes and both signs.
    fn filled<const R: usize, const C: usize>(seed: &mut u64) -> SMatrix<f64, R, C> {
        SMatrix::from_fn(|_, _| {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            u * 10f64.powi((*seed % 7) as i32 - 3)
        })
    }

    #[test]
    fn congruence_sparse_matches_the_general_products_bit_for_bit() {
        // The coordinated turn's pattern, and a random F zeroed outside it.
        const PATTERN: [&[usize]; 7] = crate::models::CT_JACOBIAN_PATTERN;
        let mut seed = 11;
        for round in 0..400 {
            let mut f = filled::<7, 7>(&mut seed);
            for (i, cols) in PATTERN.iter().enumerate() {
                for k in 0..7 {
                    if !cols.contains(&k) {
                        f[(i, k)] = 0.0;
                    } else if i == k && round % 2 == 0 {
                        f[(i, k)] = 1.0;
                    }
                }
            }
            let p = filled::<7, 7>(&mut seed);
            let want = f * p * f.transpose();
            assert_eq!(congruence_sparse(&f, &p, &PATTERN), want);
            // the dense pattern is the general product itself
            const DENSE: [&[usize]; 7] = [&[0, 1, 2, 3, 4, 5, 6]; 7];
            assert_eq!(congruence_sparse(&f, &p, &DENSE), want);
        }
    }

    #[test]
    fn sym_rank2k_matches_the_general_products_bit_for_bit() {
        let mut seed = 7;
        for _ in 0..200 {
            let (a, b) = (filled::<7, 7>(&mut seed), filled::<7, 7>(&mut seed));
            assert_eq!(sym_rank2k(&a, &b), a * a.transpose() + b * b.transpose());
            let (a, b) = (filled::<3, 7>(&mut seed), filled::<3, 7>(&mut seed));
            assert_eq!(sym_rank2k(&a, &b), a * a.transpose() + b * b.transpose());
        }
    }

    /// The inverse of a lower factor by forward substitution, row by row into a
    /// returned matrix: the reference for the bits of `chol_inverse_into`.
    fn lower_inverse_rows(l: &SMatrix<f64, 7, 7>) -> SMatrix<f64, 7, 7> {
        let mut li = SMatrix::<f64, 7, 7>::zeros();
        for j in 0..7 {
            li[(j, j)] = 1.0 / l[(j, j)];
            for i in (j + 1)..7 {
                let mut s = 0.0;
                for k in j..i {
                    s += l[(i, k)] * li[(k, j)];
                }
                li[(i, j)] = -s / l[(i, i)];
            }
        }
        let mut inv = SMatrix::<f64, 7, 7>::zeros();
        for j in 0..7 {
            for i in j..7 {
                let mut s = 0.0;
                for k in i..7 {
                    s += li[(k, i)] * li[(k, j)];
                }
                inv[(i, j)] = s;
                inv[(j, i)] = s;
            }
        }
        inv
    }

    #[test]
    fn chol_inverse_into_is_the_returned_inverse_bit_for_bit() {
        let mut seed = 5;
        for case in 0..1000 {
            let f = filled::<7, 7>(&mut seed);
            let mut a = f * f.transpose() + SMatrix::<f64, 7, 7>::identity() * 1e-3;
            if case % 3 == 1 {
                // exact zeros in the factor (block-diagonal), where only the
                // sign of a zero could differ
                for i in 0..7 {
                    for j in 0..7 {
                        if (i < 3) != (j < 3) {
                            a[(i, j)] = 0.0;
                        }
                    }
                }
            }
            let ch = cholesky(&a, "A").unwrap();
            let mut got = SMatrix::<f64, 7, 7>::from_element(f64::NAN);
            chol_inverse_into(&ch, &mut got);
            let want = lower_inverse_rows(ch.l_dirty());
            for (g, w) in got.iter().zip(want.iter()) {
                assert_eq!(g.to_bits(), w.to_bits(), "case {case}");
            }
            assert_eq!(lower_inverse(ch.l_dirty()), got);
        }
    }

    #[test]
    fn lower_inverse_equals_chol_inverse() {
        let mut seed = 11;
        for _ in 0..50 {
            let b = filled::<7, 7>(&mut seed);
            let a = b * b.transpose() + SMatrix::<f64, 7, 7>::identity() * 1e-3;
            let ch = Cholesky::new(a).unwrap();
            assert_eq!(
                lower_inverse(&cholesky_lower(&a, "A").unwrap()),
                chol_inverse(&ch)
            );
        }
    }

    /// The mirrored variants against `cholesky` / `check_positive_definite`:
    /// the same factor (bits of the packed storage) or the same error, on
    /// seeded symmetric matrices that are positive definite, indefinite,
    /// nearly singular or huge (a finite input whose factor overflows), each
    /// also with one to three symmetric pairs set to NaN, +∞ or −∞ (diagonal
    /// entries included).
    #[test]
    fn mirrored_cholesky_matches_cholesky() {
        fn same<const D: usize>(a: &SMatrix<f64, D, D>) -> bool {
            let (full, mirrored) = (cholesky(a, "A"), cholesky_mirrored(a, "A"));
            let factors = match (&full, &mirrored) {
                (Ok(f), Ok(m)) => f
                    .l_dirty()
                    .iter()
                    .zip(m.l_dirty().iter())
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                (Err(f), Err(m)) => f == m,
                _ => false,
            };
            factors
                && check_positive_definite(a, "A") == check_positive_definite_mirrored(a, "A")
                && check_positive_definite(a, "A") == full.map(|_| ())
        }
        let mut seed = 11;
        let (mut ok, mut not_pd, mut non_finite) = (0, 0, 0);
        for case in 0..3_000 {
            let b = filled::<7, 7>(&mut seed);
            let mut a = match case % 4 {
                0 => b * b.transpose() + SMatrix::identity() * 1e-3,
                1 => sym(&b),
                2 => b * b.transpose(),
                _ => b * b.transpose() * 1e300 + SMatrix::identity() * 1e307,
            };
            assert!(same(&a), "case {case}: {a}");
            match cholesky(&a, "A") {
                Ok(_) => ok += 1,
                Err(_) => not_pd += 1,
            }
            for k in 0..(1 + case % 3) {
                let r = (seed >> 20) as usize;
                let (i, j) = (r % 7, (r / 7) % 7);
                let bad = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][(r / 49 + k) % 3];
                a[(i, j)] = bad;
                a[(j, i)] = bad;
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            }
            assert!(same(&a), "case {case} with non-finite entries: {a}");
            assert_eq!(
                cholesky_mirrored(&a, "A").unwrap_err(),
                Error::NonFinite { what: "A" }
            );
            non_finite += 1;
        }
        assert!(ok > 1_000 && not_pd > 300 && non_finite == 3_000);
    }

    #[test]
    fn all_finite_sees_every_entry() {
        let mut a = SMatrix::<f64, 7, 7>::identity();
        assert!(all_finite(&a));
        for (i, bad) in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY]
            .into_iter()
            .enumerate()
        {
            a[(6 - i, 3 + i)] = bad;
            assert!(!all_finite(&a));
            a[(6 - i, 3 + i)] = 0.0;
        }
    }
}

#[cfg(test)]
mod kernel_tests {
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
