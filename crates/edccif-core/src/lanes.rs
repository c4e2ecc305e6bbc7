//! Lane-batched kernels: the Cholesky factorisation, the inverse through the
//! factor and the solve of [`linalg`](crate::linalg) for [`LANES`] matrices at
//! once, in a layout where entry `(i, j)` of every lane's matrix is one
//! contiguous `[T; LANES]` (`m[j][i][lane]`, column-major per lane). Every lane
//! runs exactly the operations of the scalar kernel on its own values, in the
//! same order, so each lane's result is the scalar result bit for bit; the
//! compiler turns the per-lane loops into vector instructions (two lanes per
//! instruction with SSE2, four with AVX).
//!
//! The phases' lane-batched forms ([`node`](crate::node)) use them where
//! several nodes run the same fixed sequence of arithmetic: the factors of the
//! estimates' covariances, the adapted estimates and the CI combinations of
//! the diffusion rows. Nothing here reports an error: a lane whose factorisation
//! fails (or whose result the scalar path would reject) is flagged, and the
//! caller recomputes that node with the scalar code, which names the error.

// The loops index the lanes' matrices as the scalar kernels index theirs,
// entry for entry, so that the two can be read side by side.
#![allow(clippy::needless_range_loop)]

use nalgebra::RealField;

use crate::message::{traces_surely_pd, Gaussian, InfoPair};

/// Matrices (or vectors) processed together.
pub(crate) const LANES: usize = 4;

/// One entry of every lane.
pub(crate) type Lane<T> = [T; LANES];

/// `D × D` matrices, one per lane: `m[j][i][lane]` is entry `(i, j)`.
pub(crate) type MatL<T, const D: usize> = [[Lane<T>; D]; D];

/// `D`-vectors, one per lane: `v[i][lane]`.
pub(crate) type VecL<T, const D: usize> = [Lane<T>; D];

/// A lane filled with `v`.
#[inline(always)]
pub(crate) fn splat<T: Copy>(v: T) -> Lane<T> {
    [v; LANES]
}

/// Zero matrices in every lane.
#[inline(always)]
pub(crate) fn zeros<T: RealField + Copy, const D: usize>() -> MatL<T, D> {
    [[splat(T::zero()); D]; D]
}

/// Sets a unit diagonal in the lanes from `used` on of `m`, zero matrices
/// from [`zeros`] (the content of an unused lane: its factorisation
/// succeeds, its result is ignored); the used lanes are for the caller to
/// fill. In place, so that no matrix of lanes (1.5 kB for `D = 7`) is
/// returned and copied.
#[inline(always)]
pub(crate) fn pad<T: RealField + Copy, const D: usize>(m: &mut MatL<T, D>, used: usize) {
    for (j, col) in m.iter_mut().enumerate() {
        for e in &mut col[j][used.min(LANES)..] {
            *e = T::one();
        }
    }
}

/// [`linalg::cholesky_in_place`](crate::linalg) in every lane: overwrites the
/// lower triangle with the factor and returns, per lane, whether the scalar
/// factorisation succeeds (every pivot `> 0` and a finite factor diagonal).
/// A lane that fails goes on with NaN or ±∞ (no panic); its values are
/// meaningless.
#[inline(always)]
pub(crate) fn cholesky_in_place<T: RealField + Copy, const D: usize>(
    m: &mut MatL<T, D>,
) -> [bool; LANES] {
    let one = T::one();
    let mut ok = [true; LANES];
    for j in 0..D {
        for k in 0..j {
            let factor = m[k][j].map(|v| -v);
            for i in j..D {
                let x = m[k][i];
                let y = &mut m[j][i];
                for l in 0..LANES {
                    y[l] = factor[l] * x[l] * one + one * y[l];
                }
            }
        }
        let diag = m[j][j];
        let mut denom = diag;
        for l in 0..LANES {
            ok[l] &= diag[l] > T::zero();
            denom[l] = diag[l].sqrt();
        }
        m[j][j] = denom;
        for i in (j + 1)..D {
            let y = &mut m[j][i];
            for l in 0..LANES {
                y[l] /= denom[l];
            }
        }
    }
    for (j, col) in m.iter().enumerate() {
        for l in 0..LANES {
            ok[l] &= col[j][l].is_finite();
        }
    }
    ok
}

/// [`linalg::chol_inverse_into`](crate::linalg) in every lane: `inv = (L Lᵀ)⁻¹`
/// from the factor in the lower triangle of `l` (the upper one is not read),
/// exactly symmetric.
#[inline(always)]
pub(crate) fn chol_inverse_into<T: RealField + Copy, const D: usize>(
    l: &MatL<T, D>,
    inv: &mut MatL<T, D>,
) {
    let mut li = [[splat(T::zero()); D]; D];
    for j in 0..D {
        for lane in 0..LANES {
            li[j][j][lane] = T::one() / l[j][j][lane];
        }
        for i in (j + 1)..D {
            let mut s = splat(T::zero());
            for k in j..i {
                for lane in 0..LANES {
                    s[lane] += l[k][i][lane] * li[j][k][lane];
                }
            }
            for lane in 0..LANES {
                li[j][i][lane] = -s[lane] / l[i][i][lane];
            }
        }
    }
    for j in 0..D {
        for i in j..D {
            let mut s = splat(T::zero());
            for k in i..D {
                for lane in 0..LANES {
                    s[lane] += li[i][k][lane] * li[j][k][lane];
                }
            }
            inv[j][i] = s;
            inv[i][j] = s;
        }
    }
}

/// nalgebra's `Cholesky::solve` in every lane: `b ← (L Lᵀ)⁻¹ b`, the forward
/// substitution column by column (`axpy`), then the back substitution with
/// the dot products nalgebra forms on its dynamic views (a zero start, the
/// terms added in ascending order).
#[inline(always)]
pub(crate) fn chol_solve<T: RealField + Copy, const D: usize>(l: &MatL<T, D>, b: &mut VecL<T, D>) {
    let one = T::one();
    for i in 0..D {
        let mut coeff = b[i];
        for lane in 0..LANES {
            coeff[lane] /= l[i][i][lane];
        }
        b[i] = coeff;
        let a = coeff.map(|v| -v);
        for r in (i + 1)..D {
            for lane in 0..LANES {
                b[r][lane] = a[lane] * l[i][r][lane] * one + one * b[r][lane];
            }
        }
    }
    for i in (0..D).rev() {
        let mut dot = splat(T::zero());
        for k in (i + 1)..D {
            for lane in 0..LANES {
                dot[lane] += l[i][k][lane] * b[k][lane];
            }
        }
        for lane in 0..LANES {
            b[i][lane] = (b[i][lane] - dot[lane]) / l[i][i][lane];
        }
    }
}

/// [`InfoPair::write_gaussian`](crate::InfoPair) in every lane: from the pairs
/// `(ŷ, Y)` (`y`, and the lower triangle of `ymat`), `P = Y⁻¹` into `p` and
/// `x̂ = Y⁻¹ŷ` into `y`. Per lane, true when the scalar conversion takes the
/// same values on its fast path: the factorisation succeeds, the trace bound
/// proves `P` positive definite, and `P` and `x̂` are finite. A false lane is
/// for the scalar code (which then factorises `P`, or names the error).
#[inline(always)]
pub(crate) fn to_gaussians<T: RealField + Copy, const D: usize>(
    y: &mut VecL<T, D>,
    ymat: &MatL<T, D>,
    p: &mut MatL<T, D>,
) -> [bool; LANES] {
    let mut m = *ymat;
    let mut ok = cholesky_in_place(&mut m);
    chol_inverse_into(&m, p);
    chol_solve(&m, y);
    let (mut ty, mut tp) = (splat(T::zero()), splat(T::zero()));
    for i in 0..D {
        for l in 0..LANES {
            ty[l] += ymat[i][i][l];
            tp[l] += p[i][i][l];
        }
    }
    // The trace bound also proves `P` finite (the scalar code's check): a
    // diagonal entry `P[i, i] = Σₖ M[k, i]²` (`M = L⁻¹`) is a sum of
    // non-negative terms, so a finite, bounded trace makes every `M[k, i]`
    // finite with `M[k, i]² ≤ tr P`, and every `P[i, j]` a sum of `D` products
    // no larger than `tr P ≤ ε⁻⁴` in magnitude: finite.
    for l in 0..LANES {
        ok[l] &= traces_surely_pd::<T, D>(ty[l], tp[l]);
    }
    finite(ok, y.iter())
}

/// `ok` with the lanes that hold a non-finite entry among `entries` cleared.
#[inline(always)]
pub(crate) fn finite<'a, T: RealField + Copy + 'a>(
    mut ok: [bool; LANES],
    entries: impl IntoIterator<Item = &'a Lane<T>>,
) -> [bool; LANES] {
    for e in entries {
        for l in 0..LANES {
            ok[l] &= e[l].is_finite();
        }
    }
    ok
}

/// Loads pair `p` into lane `l` (the vector and the lower triangle).
#[inline(always)]
pub(crate) fn load_pair<T: RealField + Copy, const D: usize>(
    y: &mut VecL<T, D>,
    ymat: &mut MatL<T, D>,
    l: usize,
    p: &InfoPair<T, D>,
) {
    for (j, col) in ymat.iter_mut().enumerate() {
        y[j][l] = p.y[j];
        for (i, e) in col.iter_mut().enumerate().skip(j) {
            e[l] = p.ymat[(i, j)];
        }
    }
}

/// Lane `l`'s estimate into `g` (`P` only when `p` is given).
#[inline(always)]
pub(crate) fn store_gaussian<T: RealField + Copy, const D: usize>(
    x: &VecL<T, D>,
    p: Option<&MatL<T, D>>,
    l: usize,
    g: &mut Gaussian<T, D>,
) {
    for (i, v) in x.iter().enumerate() {
        g.x[i] = v[l];
    }
    if let Some(p) = p {
        for (j, col) in p.iter().enumerate() {
            for (i, v) in col.iter().enumerate() {
                g.p[(i, j)] = v[l];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::{chol_inverse, cholesky};
    use nalgebra::{SMatrix, SVector};

    fn next(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    fn load<const D: usize>(m: &mut MatL<f64, D>, lane: usize, a: &SMatrix<f64, D, D>) {
        for j in 0..D {
            for i in 0..D {
                m[j][i][lane] = a[(i, j)];
            }
        }
    }

    /// Seeded symmetric matrices: positive definite (well and badly
    /// conditioned, with exact zeros), indefinite, and with NaN/∞ entries.
    fn case<const D: usize>(seed: &mut u64, kind: u64) -> SMatrix<f64, D, D> {
        let f = SMatrix::<f64, D, D>::from_fn(|_, _| next(seed));
        let mut a = f * f.transpose() + SMatrix::identity() * 1e-3;
        match kind % 6 {
            1 => {
                for i in 0..D {
                    for j in 0..D {
                        if (i < 3) != (j < 3) {
                            a[(i, j)] = 0.0;
                        }
                    }
                }
            }
            2 => a = f + f.transpose(),
            3 => {
                let v = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][(kind / 6 % 3) as usize];
                let (i, j) = ((kind / 18) as usize % D, (kind / 7) as usize % D);
                a[(i, j)] = v;
                a[(j, i)] = v;
            }
            4 => a *= 1e-300,
            5 => a *= 1e150,
            _ => {}
        }
        a
    }

    #[test]
    fn every_lane_is_the_scalar_kernel_bit_for_bit() {
        let mut seed = 17;
        let mut compared = [0usize; 2];
        for round in 0..2_000u64 {
            let mats: [SMatrix<f64, 7, 7>; LANES] =
                core::array::from_fn(|l| case(&mut seed, round * LANES as u64 + l as u64));
            let vecs: [SVector<f64, 7>; LANES] =
                core::array::from_fn(|_| SVector::from_fn(|_, _| next(&mut seed) * 3.0));
            let mut m = zeros::<f64, 7>();
            pad(&mut m, 0);
            let mut b = [splat(0.0); 7];
            for l in 0..LANES {
                load(&mut m, l, &mats[l]);
                for i in 0..7 {
                    b[i][l] = vecs[l][i];
                }
            }
            let ok = cholesky_in_place(&mut m);
            let mut inv = zeros::<f64, 7>();
            chol_inverse_into(&m, &mut inv);
            chol_solve(&m, &mut b);
            for l in 0..LANES {
                let scalar = cholesky(&mats[l], "A");
                // `cholesky` also rejects a non-finite input up front, which
                // the factorisation of a symmetric matrix catches as well.
                assert_eq!(ok[l], scalar.is_ok(), "round {round} lane {l}");
                let Ok(ch) = scalar else {
                    compared[1] += 1;
                    continue;
                };
                compared[0] += 1;
                let want_inv = chol_inverse(&ch);
                let want_x = ch.solve(&vecs[l]);
                for j in 0..7 {
                    for i in j..7 {
                        assert_eq!(
                            m[j][i][l].to_bits(),
                            ch.l_dirty()[(i, j)].to_bits(),
                            "factor ({i}, {j}), round {round} lane {l}"
                        );
                    }
                    for i in 0..7 {
                        assert_eq!(
                            inv[j][i][l].to_bits(),
                            want_inv[(i, j)].to_bits(),
                            "inverse ({i}, {j}), round {round} lane {l}"
                        );
                    }
                    assert_eq!(
                        b[j][l].to_bits(),
                        want_x[j].to_bits(),
                        "solve [{j}], round {round} lane {l}"
                    );
                }
            }
        }
        // both outcomes were exercised
        assert!(compared[0] > 3_000 && compared[1] > 1_000, "{compared:?}");
    }

    #[test]
    fn to_gaussians_is_write_gaussian_where_it_accepts() {
        use crate::message::InfoPair;
        let mut seed = 29;
        let (mut accepted, mut declined_ok) = (0usize, 0usize);
        for round in 0..2_000u64 {
            let pairs: [InfoPair<f64, 7>; LANES] = core::array::from_fn(|l| {
                let mut ymat = case(&mut seed, round * LANES as u64 + l as u64);
                if round % 7 == 3 {
                    // condition number past the trace bound: the scalar code
                    // factorises P, the lanes decline
                    ymat[(0, 0)] *= 1e14;
                }
                InfoPair {
                    y: SVector::from_fn(|_, _| next(&mut seed) * 3.0),
                    ymat,
                }
            });
            let mut y = [splat(0.0); 7];
            let mut ymat = zeros::<f64, 7>();
            pad(&mut ymat, 0);
            for l in 0..LANES {
                load(&mut ymat, l, &pairs[l].ymat);
                for i in 0..7 {
                    y[i][l] = pairs[l].y[i];
                }
            }
            let mut p = zeros::<f64, 7>();
            let ok = to_gaussians(&mut y, &ymat, &mut p);
            for l in 0..LANES {
                let want = pairs[l].to_gaussian();
                if !ok[l] {
                    declined_ok += usize::from(want.is_ok());
                    continue;
                }
                let want = want.expect("an accepted lane converts");
                accepted += 1;
                for i in 0..7 {
                    assert_eq!(
                        y[i][l].to_bits(),
                        want.x[i].to_bits(),
                        "x[{i}] round {round}"
                    );
                    for j in 0..7 {
                        assert_eq!(
                            p[j][i][l].to_bits(),
                            want.p[(i, j)].to_bits(),
                            "P round {round}"
                        );
                    }
                }
            }
        }
        assert!(
            accepted > 2_000 && declined_ok > 100,
            "{accepted} {declined_ok}"
        );
    }
}
