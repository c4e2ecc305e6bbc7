//! Fusion across the network (`docs/algorithm.md` §4, §5): diffusion adaptation,
//! combination with covariance intersection and without it (convex combination
//! of estimates), one consensus iteration, the max-degree weights, and CI with
//! optimised weights. Everything works on borrowed slices and iterators; nothing
//! allocates.

use nalgebra::{RealField, SMatrix, SVector};

use crate::error::{Error, Result};
use crate::linalg::{c, cholesky, sym};
use crate::message::{Contribution, Gaussian, InfoPair};

/// Diffusion adaptation (P-13): `Y = sym(Y⁻ + Ī_i + Σ_j Ī_j)`,
/// `ŷ = ŷ⁻ + ī_i + Σ_j ī_j` over the contributions received from neighbours.
///
/// ```
/// use edccif_core::{fusion::adapt, Contribution, InfoPair};
/// use nalgebra::{Matrix2, Vector2};
/// let prior = InfoPair { y: Vector2::new(1.0, 0.0), ymat: Matrix2::identity() };
/// let c = Contribution { i: Vector2::new(0.5, 0.5), imat: Matrix2::identity() * 0.5 };
/// let a = adapt(&prior, &c, [&c, &c]);
/// assert_eq!(a.ymat, Matrix2::identity() * 2.5);
/// ```
pub fn adapt<'a, T: RealField + Copy, const N: usize>(
    prior: &InfoPair<T, N>,
    own: &Contribution<T, N>,
    neighbours: impl IntoIterator<Item = &'a Contribution<T, N>>,
) -> InfoPair<T, N> {
    let mut y = prior.y + own.i;
    let mut ymat = prior.ymat + own.imat;
    for c in neighbours {
        y += c.i;
        ymat += c.imat;
    }
    InfoPair {
        y,
        ymat: sym(&ymat),
    }
}

/// [`adapt`] for exactly symmetric inputs (every pair and contribution the
/// network step forms, and the [`wire`](crate::wire) format delivers): the lower
/// triangle is summed in the same order, symmetrised as `(v + v)/2` (what `sym`
/// computes on an exactly symmetric sum, overflow included) and mirrored.
/// Bit-identical to [`adapt`] on such inputs. Writes into `out` (the network
/// step's scratch) instead of returning the pair: every entry of `out` is
/// written, none is read.
pub(crate) fn adapt_symmetric_into<'a, T: RealField + Copy, const N: usize>(
    prior: &InfoPair<T, N>,
    own: &Contribution<T, N>,
    neighbours: impl IntoIterator<Item = &'a Contribution<T, N>>,
    out: &mut InfoPair<T, N>,
) {
    out.y = prior.y + own.i;
    {
        let (dst, a, b) = (
            out.ymat.as_mut_slice(),
            prior.ymat.as_slice(),
            own.imat.as_slice(),
        );
        for j in 0..N {
            for e in j * N + j..(j + 1) * N {
                dst[e] = a[e] + b[e];
            }
        }
    }
    for c in neighbours {
        out.y += c.i;
        let (dst, src) = (out.ymat.as_mut_slice(), c.imat.as_slice());
        for j in 0..N {
            for e in j * N + j..(j + 1) * N {
                dst[e] += src[e];
            }
        }
    }
    // The lower triangle symmetrised and mirrored: this writes the upper one.
    let half: T = c(0.5);
    let ymat = &mut out.ymat;
    for j in 0..N {
        for i in j..N {
            let v = ymat[(i, j)];
            let v = (v + v) * half;
            ymat[(i, j)] = v;
            ymat[(j, i)] = v;
        }
    }
}

/// Weighted combination of information pairs, `Y = sym(Σ c_j Y_j)`, `ŷ = Σ c_j ŷ_j`,
/// with the weights renormalised to sum to one over the items given (so a lost
/// message leaves a convex combination of those that arrived). This is both the
/// CI combination (P-16) and one consensus iteration.
///
/// ```
/// use edccif_core::{fusion::combine_information, InfoPair};
/// use nalgebra::{Matrix2, Vector2};
/// let a = InfoPair { y: Vector2::new(1.0, 2.0), ymat: Matrix2::identity() };
/// let f = combine_information([(0.25, &a), (0.75, &a)]).unwrap();
/// assert!((f.ymat - a.ymat).norm() < 1e-15 && (f.y - a.y).norm() < 1e-15);
/// ```
pub fn combine_information<'a, T: RealField + Copy + 'a, const N: usize>(
    items: impl IntoIterator<Item = (T, &'a InfoPair<T, N>)>,
) -> Result<InfoPair<T, N>> {
    combine_impl(items)
}

/// [`combine_information`] for inputs whose matrices are exactly symmetric (every
/// pair the network step forms is): a weighted sum of exactly symmetric matrices
/// is exactly symmetric in IEEE arithmetic, so only the lower triangle is summed
/// (and divided) and then mirrored, and the final `sym` is skipped. Results are
/// bit-identical to [`combine_information`] on such inputs. The finiteness
/// check of the result is left to the caller: a consensus round checks its pair
/// with [`check_combined`] (the next round must not start from NaN or ±∞), a
/// diffusion combination converts it with [`InfoPair::to_gaussian`], which
/// checks.
pub(crate) fn combine_information_symmetric<'a, T: RealField + Copy + 'a, const N: usize>(
    items: impl IntoIterator<Item = (T, &'a InfoPair<T, N>)>,
) -> Result<InfoPair<T, N>> {
    let mut acc = Accumulator::new();
    for (w, p) in items {
        check_weight(w)?;
        acc.add(w, p);
    }
    acc.finish()
}

/// The finiteness check of a combined pair `(ŷ, Y)`: NaN or ±∞ from non-finite
/// inputs, or from finite ones whose weighted sum overflows, is the named
/// [`Error::NonFinite`] of the combined vector or matrix.
#[inline(always)]
pub(crate) fn check_combined<T: RealField + Copy, const N: usize>(
    y: &SVector<T, N>,
    ymat: &SMatrix<T, N, N>,
) -> Result<()> {
    crate::linalg::check_finite(y, "combined information vector ŷ")?;
    crate::linalg::check_finite(ymat, "combined information matrix Y")
}

#[inline(always)]
pub(crate) fn check_weight<T: RealField + Copy>(w: T) -> Result<()> {
    if w.is_finite() && w >= T::zero() {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            what: "fusion weight",
            expected: "finite and >= 0",
        })
    }
}

/// Running weighted sum of information pairs with exactly symmetric matrices:
/// the vector and the lower triangle (column by column, the storage order), each
/// entry summed in the order of the items, as `y += p.y * w; ymat += p.ymat * w`.
/// [`add`](Self::add) takes weights already checked ([`check_weight`]);
/// [`finish`](Self::finish) checks the total.
pub(crate) struct Accumulator<T: RealField + Copy, const N: usize> {
    total: T,
    y: SVector<T, N>,
    ymat: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> Accumulator<T, N> {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            total: T::zero(),
            y: SVector::zeros(),
            ymat: SMatrix::zeros(),
        }
    }

    #[inline(always)]
    pub(crate) fn add(&mut self, w: T, p: &InfoPair<T, N>) {
        self.total += w;
        for (a, b) in self.y.iter_mut().zip(p.y.iter()) {
            *a += *b * w;
        }
        let (dst, src) = (self.ymat.as_mut_slice(), p.ymat.as_slice());
        for j in 0..N {
            let col = j * N + j..(j + 1) * N;
            for (a, b) in dst[col.clone()].iter_mut().zip(&src[col]) {
                *a += *b * w;
            }
        }
    }

    #[inline(always)]
    pub(crate) fn finish(self) -> Result<InfoPair<T, N>> {
        if !(self.total > T::zero()) {
            return Err(Error::InvalidParameter {
                what: "fusion weights",
                expected: "a positive sum",
            });
        }
        Ok(self.finish_unchecked())
    }

    /// Divides by the total (skipped when it is exactly one: `x / 1 = x`) and
    /// mirrors the lower triangle.
    #[inline(always)]
    pub(crate) fn finish_unchecked(mut self) -> InfoPair<T, N> {
        let total = self.total;
        if total != T::one() {
            for a in self.y.iter_mut() {
                *a /= total;
            }
            let dst = self.ymat.as_mut_slice();
            for j in 0..N {
                for a in &mut dst[j * N + j..(j + 1) * N] {
                    *a /= total;
                }
            }
        }
        for j in 0..N {
            for i in (j + 1)..N {
                self.ymat[(j, i)] = self.ymat[(i, j)];
            }
        }
        InfoPair {
            y: self.y,
            ymat: self.ymat,
        }
    }
}

fn combine_impl<'a, T: RealField + Copy + 'a, const N: usize>(
    items: impl IntoIterator<Item = (T, &'a InfoPair<T, N>)>,
) -> Result<InfoPair<T, N>> {
    let mut total = T::zero();
    let mut y = SVector::<T, N>::zeros();
    let mut ymat = SMatrix::<T, N, N>::zeros();
    for (w, p) in items {
        check_weight(w)?;
        total += w;
        y += p.y * w;
        ymat += p.ymat * w;
    }
    if !(total > T::zero()) {
        return Err(Error::InvalidParameter {
            what: "fusion weights",
            expected: "a positive sum",
        });
    }
    let (y, ymat) = (y / total, sym(&(ymat / total)));
    check_combined(&y, &ymat)?;
    Ok(InfoPair { y, ymat })
}

/// Combination with covariance intersection: [`combine_information`], then back to
/// covariance form (P-17).
pub fn combine_ci<'a, T: RealField + Copy + 'a, const N: usize>(
    items: impl IntoIterator<Item = (T, &'a InfoPair<T, N>)>,
) -> Result<Gaussian<T, N>> {
    combine_information(items)?.to_gaussian()
}

/// Combination without CI (P-14): `x̂ = Σ c_j x̂_j`, `P = sym(Σ c_j P_j)`,
/// weights renormalised over the items given.
///
/// ```
/// use edccif_core::{fusion::combine_convex, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let a = Gaussian { x: Vector2::new(0.0, 0.0), p: Matrix2::identity() };
/// let b = Gaussian { x: Vector2::new(2.0, 0.0), p: Matrix2::identity() * 3.0 };
/// let f = combine_convex([(0.5, &a), (0.5, &b)]).unwrap();
/// assert_eq!(f.x, Vector2::new(1.0, 0.0));
/// assert_eq!(f.p, Matrix2::identity() * 2.0);
/// ```
pub fn combine_convex<'a, T: RealField + Copy + 'a, const N: usize>(
    items: impl IntoIterator<Item = (T, &'a Gaussian<T, N>)>,
) -> Result<Gaussian<T, N>> {
    let mut total = T::zero();
    let mut x = SVector::<T, N>::zeros();
    let mut p = SMatrix::<T, N, N>::zeros();
    for (w, g) in items {
        if !(w.is_finite() && w >= T::zero()) {
            return Err(Error::InvalidParameter {
                what: "fusion weight",
                expected: "finite and >= 0",
            });
        }
        total += w;
        x += g.x * w;
        p += g.p * w;
    }
    if !(total > T::zero()) {
        return Err(Error::InvalidParameter {
            what: "fusion weights",
            expected: "a positive sum",
        });
    }
    let (x, p) = (x / total, sym(&(p / total)));
    crate::linalg::check_finite(&x, "combined state x")?;
    crate::linalg::cholesky(&p, "combined covariance P")?;
    Ok(Gaussian { x, p })
}

/// The paper's max-degree weights (P-15) for a `k × k` row-major adjacency:
/// `c_ij = 1/(1+Δ)` for neighbours, `c_ii = 1 − Σ_j c_ij`, 0 otherwise, `Δ` the
/// maximum degree. Rejects self-loops, asymmetric entries and disconnected graphs.
///
/// ```
/// use edccif_core::fusion::max_degree_weights;
/// // a path 0 - 1 - 2
/// let adj = [false, true, false, true, false, true, false, true, false];
/// let mut w = [0.0f64; 9];
/// max_degree_weights(&adj, 3, &mut w).unwrap();
/// let want = [2.0 / 3.0, 1.0 / 3.0, 0.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0, 0.0, 1.0 / 3.0, 2.0 / 3.0];
/// // c_ii = 1 − Σ_j c_ij is exact only up to rounding
/// assert!(w.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-15));
/// let disconnected = [false, true, false, true, false, false, false, false, false];
/// assert!(max_degree_weights(&disconnected, 3, &mut w).is_err());
/// ```
pub fn max_degree_weights<T: RealField + Copy>(
    adjacency: &[bool],
    k: usize,
    out: &mut [T],
) -> Result<()> {
    validate_adjacency(adjacency, k)?;
    if out.len() != k * k {
        return Err(Error::Dimension {
            what: "weight buffer",
            expected: k * k,
            got: out.len(),
        });
    }
    let max_deg = (0..k)
        .map(|i| adjacency[i * k..(i + 1) * k].iter().filter(|a| **a).count())
        .max()
        .unwrap_or(0);
    let cw = T::one() / c::<T>((1 + max_deg) as f64);
    for i in 0..k {
        let mut self_w = T::one();
        for j in 0..k {
            out[i * k + j] = if adjacency[i * k + j] {
                self_w -= cw;
                cw
            } else {
                T::zero()
            };
        }
        out[i * k + i] = self_w;
    }
    Ok(())
}

/// Checks a `k × k` row-major adjacency: square, no self-loops, symmetric, connected.
pub fn validate_adjacency(adjacency: &[bool], k: usize) -> Result<()> {
    if k == 0 {
        return Err(Error::Dimension {
            what: "number of nodes",
            expected: 1,
            got: 0,
        });
    }
    if adjacency.len() != k * k {
        return Err(Error::Dimension {
            what: "adjacency matrix (row-major, nodes × nodes)",
            expected: k * k,
            got: adjacency.len(),
        });
    }
    for i in 0..k {
        if adjacency[i * k + i] {
            return Err(Error::InvalidGraph {
                what: "self-loop",
                row: i,
                col: i,
            });
        }
        for j in (i + 1)..k {
            if adjacency[i * k + j] != adjacency[j * k + i] {
                return Err(Error::InvalidGraph {
                    what: "asymmetric edge",
                    row: i,
                    col: j,
                });
            }
        }
    }
    // Connectivity without allocation: breadth-first sweeps from node 0 over a
    // stack bitset.
    reachable_all(adjacency, k)
}

fn reachable_all(adjacency: &[bool], k: usize) -> Result<()> {
    const WORDS: usize = 16; // up to 1024 nodes without allocation
    if k > WORDS * 64 {
        return Err(Error::Dimension {
            what: "number of nodes (core graph check)",
            expected: WORDS * 64,
            got: k,
        });
    }
    let mut seen = [0u64; WORDS];
    seen[0] = 1;
    loop {
        let mut changed = false;
        for i in 0..k {
            if seen[i / 64] & (1 << (i % 64)) == 0 {
                continue;
            }
            for j in 0..k {
                if adjacency[i * k + j] && seen[j / 64] & (1 << (j % 64)) == 0 {
                    seen[j / 64] |= 1 << (j % 64);
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    match (0..k).find(|j| seen[j / 64] & (1 << (j % 64)) == 0) {
        Some(unreachable) => Err(Error::DisconnectedGraph { unreachable }),
        None => Ok(()),
    }
}

/// One synchronous consensus iteration over all nodes:
/// `next_i = Σ_j c_ij current_j` (information form), for a `k × k` row-major
/// weight matrix.
pub fn consensus_iteration<T: RealField + Copy, const N: usize>(
    weights: &[T],
    current: &[InfoPair<T, N>],
    next: &mut [InfoPair<T, N>],
) -> Result<()> {
    let k = current.len();
    if weights.len() != k * k {
        return Err(Error::Dimension {
            what: "weight matrix",
            expected: k * k,
            got: weights.len(),
        });
    }
    if next.len() != k {
        return Err(Error::Dimension {
            what: "consensus output buffer",
            expected: k,
            got: next.len(),
        });
    }
    for (i, out) in next.iter_mut().enumerate() {
        let row = &weights[i * k..(i + 1) * k];
        *out = combine_information(
            row.iter()
                .zip(current)
                .filter(|(w, _)| **w > T::zero())
                .map(|(w, p)| (*w, p)),
        )?;
    }
    Ok(())
}

/// What an optimised CI minimises (MATLAB's `fusecovint` offers the same two).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum CiCriterion {
    /// Trace of the fused covariance.
    Trace,
    /// Determinant of the fused covariance.
    Determinant,
}

/// The criterion at weights `w`; `+∞` when `Σ w_j Y_j` is not positive definite.
fn ci_cost<T: RealField + Copy, const N: usize>(
    infos: &[InfoPair<T, N>],
    w: &[T],
    criterion: CiCriterion,
) -> T {
    let mut ymat = SMatrix::<T, N, N>::zeros();
    for (p, wj) in infos.iter().zip(w) {
        ymat += p.ymat * *wj;
    }
    match cholesky(&sym(&ymat), "fused information") {
        Err(_) => c(f64::INFINITY),
        Ok(ch) => match criterion {
            CiCriterion::Trace => ch.inverse().trace(),
            // minimise det(P) ⇔ minimise −log det(Y) = −2 Σ log L_ii
            CiCriterion::Determinant => {
                -c::<T>(2.0)
                    * ch.l_dirty()
                        .diagonal()
                        .iter()
                        .fold(T::zero(), |a, d| a + d.ln())
            }
        },
    }
}

/// Covariance intersection with weights chosen to minimise the trace or the
/// determinant of the fused covariance (an extension beyond the paper). The cost
/// is convex in the weights; pairwise golden-section coordinate descent starts at
/// the weights in `weights` (uniform if they do not sum to a positive number) and
/// accepts only improvements, so the result is never worse than the start.
/// On return `weights` holds the chosen weights.
///
/// ```
/// use edccif_core::{fusion::{ci_fuse_optimal, CiCriterion}, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let a = Gaussian { x: Vector2::new(0.0, 0.0), p: Matrix2::new(1.0, 0.0, 0.0, 4.0) };
/// let b = Gaussian { x: Vector2::new(1.0, 1.0), p: Matrix2::new(4.0, 0.0, 0.0, 1.0) };
/// let infos = [a.to_info().unwrap(), b.to_info().unwrap()];
/// let mut w = [0.0f64; 2];
/// let f = ci_fuse_optimal(&infos, CiCriterion::Trace, &mut w).unwrap();
/// assert!((w[0] - 0.5).abs() < 1e-6); // symmetric problem
/// assert!(f.p.trace() <= a.p.trace().min(b.p.trace()));
/// ```
pub fn ci_fuse_optimal<T: RealField + Copy, const N: usize>(
    infos: &[InfoPair<T, N>],
    criterion: CiCriterion,
    weights: &mut [T],
) -> Result<Gaussian<T, N>> {
    ci_fuse_optimal_with(infos, criterion, weights, &mut |_, _| true)
}

/// [`ci_fuse_optimal`] with a watch: `watch(done, total)` is called at every
/// step of the line searches with the pairs of weights visited so far and the
/// most it may visit (50 sweeps over the `K(K − 1)/2` pairs); when it returns
/// `false` the search stops with [`Error::Interrupted`] (`weights` then holds
/// the weights reached so far; no fused estimate is formed). For long
/// searches (the cost grows as `K³`) that a caller must be able to stop or
/// watch.
///
/// ```
/// use edccif_core::{fusion::{ci_fuse_optimal_with, CiCriterion}, Error, Gaussian};
/// use nalgebra::{Matrix2, Vector2};
/// let a = Gaussian { x: Vector2::new(0.0, 0.0), p: Matrix2::new(1.0, 0.0, 0.0, 4.0) };
/// let b = Gaussian { x: Vector2::new(1.0, 1.0), p: Matrix2::new(4.0, 0.0, 0.0, 1.0) };
/// let infos = [a.to_info().unwrap(), b.to_info().unwrap()];
/// let mut w = [0.5f64, 0.5];
/// let e = ci_fuse_optimal_with(&infos, CiCriterion::Trace, &mut w, &mut |_, _| false);
/// assert_eq!(e.unwrap_err(), Error::Interrupted);
/// let mut calls = 0;
/// let f = ci_fuse_optimal_with(&infos, CiCriterion::Trace, &mut w, &mut |_, _| { calls += 1; true });
/// assert!(f.is_ok() && calls > 0);
/// ```
pub fn ci_fuse_optimal_with<T: RealField + Copy, const N: usize>(
    infos: &[InfoPair<T, N>],
    criterion: CiCriterion,
    weights: &mut [T],
    watch: &mut dyn FnMut(u64, u64) -> bool,
) -> Result<Gaussian<T, N>> {
    let k = infos.len();
    if k == 0 {
        return Err(Error::Dimension {
            what: "CI inputs",
            expected: 1,
            got: 0,
        });
    }
    if weights.len() != k {
        return Err(Error::Dimension {
            what: "CI weight buffer",
            expected: k,
            got: weights.len(),
        });
    }
    let sum = weights.iter().fold(T::zero(), |a, w| a + *w);
    if !(sum > T::zero()) || weights.iter().any(|w| !w.is_finite() || *w < T::zero()) {
        let u = T::one() / c::<T>(k as f64);
        weights.iter_mut().for_each(|w| *w = u);
    } else {
        weights.iter_mut().for_each(|w| *w /= sum);
    }
    let mut best = ci_cost(infos, weights, criterion);
    if !best.is_finite() {
        return Err(Error::NotPositiveDefinite {
            what: "CI fused information at the starting weights",
        });
    }
    let inv_phi: T = c(0.618_033_988_749_894_9);
    const SWEEPS: u64 = 50;
    let pairs = (k as u64).saturating_mul(k.saturating_sub(1) as u64) / 2;
    let total = pairs.saturating_mul(SWEEPS);
    let mut visited = 0u64;
    for _sweep in 0..SWEEPS {
        let start = best;
        for a in 0..k {
            for b in (a + 1)..k {
                visited += 1;
                if !watch(visited - 1, total) {
                    return Err(Error::Interrupted);
                }
                let s = weights[a] + weights[b];
                if !(s > T::zero()) {
                    continue;
                }
                let (wa0, wb0) = (weights[a], weights[b]);
                let eval = |t: T, w: &mut [T]| {
                    w[a] = t;
                    w[b] = s - t;
                    ci_cost(infos, w, criterion)
                };
                let (mut lo, mut hi) = (T::zero(), s);
                let mut x1 = hi - (hi - lo) * inv_phi;
                let mut x2 = lo + (hi - lo) * inv_phi;
                let mut f1 = eval(x1, weights);
                let mut f2 = eval(x2, weights);
                for _ in 0..60 {
                    if !watch(visited - 1, total) {
                        return Err(Error::Interrupted);
                    }
                    if f1 <= f2 {
                        hi = x2;
                        x2 = x1;
                        f2 = f1;
                        x1 = hi - (hi - lo) * inv_phi;
                        f1 = eval(x1, weights);
                    } else {
                        lo = x1;
                        x1 = x2;
                        f1 = f2;
                        x2 = lo + (hi - lo) * inv_phi;
                        f2 = eval(x2, weights);
                    }
                }
                // candidates: the bracket's best and both ends of the segment
                let mut cand = [(x1, f1), (x2, f2), (T::zero(), T::zero()), (s, T::zero())];
                cand[2].1 = eval(T::zero(), weights);
                cand[3].1 = eval(s, weights);
                let (mut tb, mut fb) = (wa0, best);
                for (t, f) in cand {
                    if f < fb {
                        tb = t;
                        fb = f;
                    }
                }
                weights[a] = tb;
                weights[b] = s - tb;
                if tb == wa0 {
                    weights[b] = wb0;
                }
                best = fb;
            }
        }
        if !(start - best > start.abs() * c::<T>(1e-12)) {
            break;
        }
    }
    combine_ci(weights.iter().copied().zip(infos.iter()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn symmetric(seed: &mut u64, scale: f64) -> SMatrix<f64, 7, 7> {
        let a = SMatrix::<f64, 7, 7>::from_fn(|_, _| {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * scale
        });
        sym(&a)
    }

    #[test]
    fn the_symmetric_kernels_equal_the_general_ones_bit_for_bit() {
        let mut seed = 3;
        for scale in [1e-300, 1e-3, 1.0, 1e5, 1e307, f64::MAX] {
            for _ in 0..200 {
                let prior = InfoPair {
                    y: SVector::from_fn(|i, _| i as f64 * scale.min(1e300)),
                    ymat: symmetric(&mut seed, scale),
                };
                let cs: [Contribution<f64, 7>; 3] = core::array::from_fn(|_| Contribution {
                    i: SVector::from_fn(|i, _| 1.0 - i as f64),
                    imat: symmetric(&mut seed, scale),
                });
                let a = adapt(&prior, &cs[0], &cs[1..]);
                // Stale entries in the buffer must not matter.
                let mut b = InfoPair {
                    y: SVector::repeat(f64::NAN),
                    ymat: SMatrix::repeat(f64::NAN),
                };
                adapt_symmetric_into(&prior, &cs[0], &cs[1..], &mut b);
                // NaN from overflow compares unequal: compare the bits.
                let bits = |m: &SMatrix<f64, 7, 7>| m.map(f64::to_bits);
                assert_eq!(bits(&a.ymat), bits(&b.ymat));
                assert_eq!(a.y, b.y);
                let pairs = [prior, a, b];
                let items = || [(0.25, &pairs[0]), (0.5, &pairs[1]), (1.0 / 3.0, &pairs[2])];
                let general = combine_information(items());
                let lean = combine_information_symmetric(items());
                match general {
                    Ok(g) => assert_eq!(g, lean.unwrap()),
                    // The general form also checks finiteness.
                    Err(_) => {
                        assert!(lean.is_err() || !crate::linalg::all_finite(&lean.unwrap().ymat))
                    }
                }
            }
        }
    }
}
