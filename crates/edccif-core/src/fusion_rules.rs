//! Fusion rules for the diffusion combination beyond the paper's covariance
//! intersection (`docs/fusion.md`): CI with optimised weights, inverse
//! covariance intersection, split CI and ellipsoidal intersection, selected by
//! a [`FusionRule`] carried in [`NetworkConfig::rule`](crate::NetworkConfig::rule).
//!
//! Every rule fuses a node's own adapted pair with the adapted pairs that arrived
//! from its neighbours, each with its combination weight `c_ij`; the inputs come
//! in ascending node order. The paper's rule, [`FusionRule::Ci`] with
//! [`Weights::Fixed`], is `Y = Σ c_ij Y_j` ([`crate::fusion`]); the network step
//! keeps its own fast path for it, so the default numbers do not change.
//!
//! | rule | fused information | consistent for |
//! |---|---|---|
//! | `ci`, `ci-trace`, `ci-det` | `Y = Σ ω_j Y_j`, `ŷ = Σ ω_j ŷ_j` | any correlation |
//! | `ici`, `ici-trace`, `ici-det` | pairwise, in order: `Y = Y_a + Y_b − (ω A + (1−ω) B)⁻¹` | errors from common information |
//! | `split-ci`, `split-ci-trace`, `split-ci-det` | `Y = Σ ω_j D_j + Σ_m Ī_m` (dependent parts intersected, independent contributions added once) | correlated parts arbitrary, the contributions independent |
//! | `split-ici`, `split-ici-trace`, `split-ici-det` | the dependent parts by ICI, the contributions added once | dependent parts from common information, the contributions independent |
//! | `ei-unsafe` | pairwise, in order: the largest ellipsoid in the intersection | no guarantee |
//!
//! Nothing allocates: the inputs are iterators (cloned when a rule needs them
//! twice), the optimised weights live in a stack buffer of
//! [`MAX_OPTIMISED_INPUTS`] entries.
//!
//! ```
//! use edccif_core::fusion_rules::{fuse_information, FusionRule};
//! use edccif_core::{Gaussian, InfoPair};
//! use nalgebra::{Matrix2, Vector2};
//! let a = Gaussian { x: Vector2::new(0.0, 0.0), p: Matrix2::new(1.0, 0.0, 0.0, 4.0) };
//! let b = Gaussian { x: Vector2::new(1.0, 1.0), p: Matrix2::new(4.0, 0.0, 0.0, 1.0) };
//! let items = [(0.5, a.to_info()?), (0.5, b.to_info()?)];
//! let ci = fuse_information(FusionRule::CI, items.iter().copied(), None)?;
//! let ici = fuse_information("ici".parse()?, items.iter().copied(), None)?;
//! // ICI is less conservative than CI: its covariance is smaller here.
//! assert!(ici.p.trace() < ci.p.trace());
//! # Ok::<(), edccif_core::Error>(())
//! ```

use core::fmt;
use core::str::FromStr;

use nalgebra::{RealField, SMatrix, SVector};

use crate::error::{Error, Result};
use crate::fusion::{check_weight, CiCriterion};
use crate::linalg::{c, chol_inverse, cholesky, sym};
use crate::message::{Contribution, Gaussian, InfoPair};

/// How a rule chooses its weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weights {
    /// The combination weights `c_ij` as given (the paper's max-degree weights).
    Fixed,
    /// Weights that minimise the trace or the determinant of the fused
    /// covariance, starting from the combination weights.
    Optimal(CiCriterion),
}

/// The rule of the diffusion combination. `Ci(Weights::Fixed)` is the paper's
/// (the default); names as in [`NAMES`](Self::NAMES), equations, sources and
/// guarantees in `docs/fusion.md`.
///
/// ```
/// use edccif_core::fusion_rules::FusionRule;
/// let r: FusionRule = "ici-trace".parse().unwrap();
/// assert_eq!(r.name(), "ici-trace");
/// assert_eq!(FusionRule::default(), FusionRule::CI);
/// assert!(!FusionRule::EiUnsafe.is_guaranteed());
/// assert!("ei".parse::<FusionRule>().is_err()); // an unsafe rule only by its unsafe name
/// ```
///
/// With the `serde` feature a rule is written and read as its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusionRule {
    /// Covariance intersection `Y = Σ ω_j Y_j` (Julier & Uhlmann 1997).
    Ci(Weights),
    /// Inverse covariance intersection (Noack, Sijs, Reinhardt, Hanebeck,
    /// Automatica 2017), applied pairwise in input order.
    Ici(Weights),
    /// Split covariance intersection (Julier & Uhlmann 2001) in information
    /// form: the inputs' dependent parts intersected, the node's measurement
    /// contributions added once.
    SplitCi(Weights),
    /// Split ICI: [`SplitCi`](Self::SplitCi) with the dependent parts fused by
    /// ICI instead of CI (in ICI's class).
    SplitIci(Weights),
    /// Ellipsoidal intersection (Sijs & Lazar, Automatica 2012), pairwise in
    /// input order; no consistency guarantee.
    EiUnsafe,
}

impl Default for FusionRule {
    fn default() -> Self {
        Self::CI
    }
}

impl FusionRule {
    /// The paper's rule: CI with the combination weights.
    pub const CI: FusionRule = FusionRule::Ci(Weights::Fixed);

    /// Every rule, in the order of [`NAMES`](Self::NAMES).
    pub const ALL: [FusionRule; 13] = [
        FusionRule::Ci(Weights::Fixed),
        FusionRule::Ci(Weights::Optimal(CiCriterion::Trace)),
        FusionRule::Ci(Weights::Optimal(CiCriterion::Determinant)),
        FusionRule::Ici(Weights::Fixed),
        FusionRule::Ici(Weights::Optimal(CiCriterion::Trace)),
        FusionRule::Ici(Weights::Optimal(CiCriterion::Determinant)),
        FusionRule::SplitCi(Weights::Fixed),
        FusionRule::SplitCi(Weights::Optimal(CiCriterion::Trace)),
        FusionRule::SplitCi(Weights::Optimal(CiCriterion::Determinant)),
        FusionRule::SplitIci(Weights::Fixed),
        FusionRule::SplitIci(Weights::Optimal(CiCriterion::Trace)),
        FusionRule::SplitIci(Weights::Optimal(CiCriterion::Determinant)),
        FusionRule::EiUnsafe,
    ];

    /// The rules' names (`fusion=` in the simulator, Python and scenario files).
    pub const NAMES: [&'static str; 13] = [
        "ci",
        "ci-trace",
        "ci-det",
        "ici",
        "ici-trace",
        "ici-det",
        "split-ci",
        "split-ci-trace",
        "split-ci-det",
        "split-ici",
        "split-ici-trace",
        "split-ici-det",
        "ei-unsafe",
    ];

    /// The rule's name, e.g. `"ici-trace"`.
    pub fn name(self) -> &'static str {
        let i = Self::ALL.iter().position(|r| *r == self).unwrap_or(0);
        Self::NAMES[i]
    }

    /// The rule of a name in [`NAMES`](Self::NAMES) (exact, lower case).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::NAMES
            .iter()
            .position(|n| *n == name)
            .map(|i| Self::ALL[i])
    }

    /// Whether this is the paper's rule (the network step's fast path).
    pub fn is_paper(&self) -> bool {
        *self == Self::CI
    }

    /// Whether the rule carries a consistency guarantee for some class of
    /// correlations (all but [`EiUnsafe`](Self::EiUnsafe)).
    pub fn is_guaranteed(self) -> bool {
        !matches!(self, FusionRule::EiUnsafe)
    }

    /// Whether the rule needs the measurement contributions the inputs hold
    /// ([`combine_split`]).
    pub fn needs_contributions(self) -> bool {
        matches!(self, FusionRule::SplitCi(_) | FusionRule::SplitIci(_))
    }
}

impl fmt::Display for FusionRule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for FusionRule {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Self::from_name(s).ok_or(Error::InvalidParameter {
            what: "fusion rule",
            expected: "one of ci, ci-trace, ci-det, ici, ici-trace, ici-det, split-ci, \
                       split-ci-trace, split-ci-det, split-ici, split-ici-trace, split-ici-det, \
                       ei-unsafe",
        })
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for FusionRule {
    fn serialize<S: serde::Serializer>(&self, s: S) -> core::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

#[cfg(feature = "serde")]
impl<'de> serde::Deserialize<'de> for FusionRule {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> core::result::Result<Self, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = FusionRule;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a fusion rule name: ")?;
                for (i, n) in FusionRule::NAMES.iter().enumerate() {
                    f.write_str(if i == 0 { "" } else { ", " })?;
                    f.write_str(n)?;
                }
                Ok(())
            }
            fn visit_str<E: serde::de::Error>(
                self,
                v: &str,
            ) -> core::result::Result<FusionRule, E> {
                FusionRule::from_name(v)
                    .ok_or_else(|| E::invalid_value(serde::de::Unexpected::Str(v), &self))
            }
        }
        d.deserialize_str(Name)
    }
}

/// Largest number of inputs of a rule with optimised weights (the weights
/// live in a stack buffer of this size).
pub const MAX_OPTIMISED_INPUTS: usize = 128;

/// Golden-section steps of a line search (the bracket shrinks to 0.618³² ≈ 2·10⁻⁷).
const GOLDEN_STEPS: usize = 32;
/// Sweeps of the weight optimisation at most.
const MAX_SWEEPS: usize = 30;

/// Fuses weighted information pairs `(c_j, (ŷ_j, Y_j))` by `rule`, in the
/// order given, and adds `independent` (information known to be independent
/// of every input, e.g. the node's measurement contributions under split CI)
/// exactly once; returns the fused estimate in covariance form.
///
/// For [`FusionRule::SplitCi`] and [`FusionRule::SplitIci`] the items are the
/// inputs' dependent parts (see [`combine_split`], which forms them); for the
/// other rules the inputs themselves.
///
/// Errors: no input, a weight negative or not finite, weights summing to zero,
/// more than [`MAX_OPTIMISED_INPUTS`] inputs with optimised weights, an input
/// that is not positive definite where the rule needs its covariance (ICI, EI),
/// and a fused matrix that is not positive definite. Nothing is changed on
/// error (the function only reads its inputs).
///
/// ```
/// use edccif_core::fusion_rules::{fuse_information, FusionRule};
/// use edccif_core::InfoPair;
/// use nalgebra::{Matrix2, Vector2};
/// let a = InfoPair { y: Vector2::new(1.0, 0.0), ymat: Matrix2::identity() };
/// // Every consistent rule gives back an input fused with itself.
/// for rule in ["ci", "ci-trace", "ici", "ici-det", "split-ci"] {
///     let f = fuse_information(rule.parse()?, [(0.5, a), (0.5, a)].into_iter(), None)?;
///     assert!((f.p - Matrix2::identity()).norm() < 1e-9, "{rule}");
/// }
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn fuse_information<T, I, const N: usize>(
    rule: FusionRule,
    items: I,
    independent: Option<&InfoPair<T, N>>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
    I: Iterator<Item = (T, InfoPair<T, N>)> + Clone,
{
    let (k, total) = check_items(items.clone())?;
    let fused = match rule {
        FusionRule::Ci(w) | FusionRule::SplitCi(w) => intersect(w, items, k, total)?,
        FusionRule::Ici(w) | FusionRule::SplitIci(w) => {
            sequential(items, total, |a, b, wa, wb| ici_pair(a, b, wa, wb, w))?
        }
        FusionRule::EiUnsafe => sequential(items, total, |a, b, _, _| ei_pair(a, b))?,
    };
    let fused = match independent {
        Some(ind) => InfoPair {
            y: fused.y + ind.y,
            ymat: sym(&(fused.ymat + ind.ymat)),
        },
        None => fused,
    };
    fused.to_gaussian()
}

/// The number of items and their total weight; checks every weight.
fn check_items<T, I, const N: usize>(items: I) -> Result<(usize, T)>
where
    T: RealField + Copy,
    I: Iterator<Item = (T, InfoPair<T, N>)>,
{
    let (mut k, mut total) = (0usize, T::zero());
    for (w, _) in items {
        check_weight(w)?;
        k += 1;
        total += w;
    }
    if k == 0 {
        return Err(Error::Dimension {
            what: "fusion inputs",
            expected: 1,
            got: 0,
        });
    }
    if !(total > T::zero()) {
        return Err(Error::InvalidParameter {
            what: "fusion weights",
            expected: "a positive sum",
        });
    }
    Ok((k, total))
}

/// CI of the items with the given (renormalised) or optimised weights.
fn intersect<T, I, const N: usize>(
    weights: Weights,
    items: I,
    k: usize,
    total: T,
) -> Result<InfoPair<T, N>>
where
    T: RealField + Copy,
    I: Iterator<Item = (T, InfoPair<T, N>)> + Clone,
{
    match weights {
        Weights::Fixed => Ok(weighted_sum(items.map(|(w, p)| (w / total, p)))),
        Weights::Optimal(criterion) => {
            if k > MAX_OPTIMISED_INPUTS {
                return Err(Error::Dimension {
                    what: "fusion inputs with optimised weights",
                    expected: MAX_OPTIMISED_INPUTS,
                    got: k,
                });
            }
            let mut w = [T::zero(); MAX_OPTIMISED_INPUTS];
            for (slot, (wj, _)) in w.iter_mut().zip(items.clone()) {
                *slot = wj / total;
            }
            let w = &mut w[..k];
            optimise_weights(w, &SMatrix::zeros(), |j| nth(&items, j).ymat, criterion)?;
            Ok(weighted_sum(
                w.iter().copied().zip(items).map(|(wj, (_, p))| (wj, p)),
            ))
        }
    }
}

fn nth<T, I, const N: usize>(items: &I, j: usize) -> InfoPair<T, N>
where
    T: RealField + Copy,
    I: Iterator<Item = (T, InfoPair<T, N>)> + Clone,
{
    // `j` is below the count taken from the same iterator.
    items
        .clone()
        .nth(j)
        .map_or_else(InfoPair::zeros, |(_, p)| p)
}

/// `(Σ w_j ŷ_j, sym(Σ w_j Y_j))`.
fn weighted_sum<T, const N: usize>(
    items: impl Iterator<Item = (T, InfoPair<T, N>)>,
) -> InfoPair<T, N>
where
    T: RealField + Copy,
{
    let mut y = SVector::<T, N>::zeros();
    let mut ymat = SMatrix::<T, N, N>::zeros();
    for (w, p) in items {
        y += p.y * w;
        ymat += p.ymat * w;
    }
    InfoPair {
        y,
        ymat: sym(&ymat),
    }
}

/// The criterion of a fused information matrix: `tr(Y⁻¹)` or `log det(Y⁻¹)`;
/// `+∞` when `Y` is not positive definite.
fn cost<T: RealField + Copy, const N: usize>(y: &SMatrix<T, N, N>, criterion: CiCriterion) -> T {
    match cholesky(&sym(y), "fused information") {
        Err(_) => c(f64::INFINITY),
        Ok(ch) => match criterion {
            CiCriterion::Trace => chol_inverse(&ch).trace(),
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

/// Minimises `cost(base + Σ_j w_j M_j)` over the weight simplex, starting at
/// `w` (non-negative, summing to one), by exact line searches (golden section)
/// towards and away from one vertex at a time: moving weight `t` to input `j`
/// and scaling the others by `(1 − t)/(1 − w_j)`. The cost is convex in the
/// weights (trace of an inverse, minus a log-determinant, of a matrix affine in
/// them), and these directions span the simplex, so the search stops at its
/// minimum; only improvements are accepted, so the result is never worse than
/// the start. Works for any number of inputs with `k` line searches per sweep.
fn optimise_weights<T, const N: usize>(
    w: &mut [T],
    base: &SMatrix<T, N, N>,
    m: impl Fn(usize) -> SMatrix<T, N, N>,
    criterion: CiCriterion,
) -> Result<()>
where
    T: RealField + Copy,
{
    let k = w.len();
    // `base + Σ_{i ≠ skip} w_i M_i`, summed afresh (no cancellation).
    let sum_without = |w: &[T], skip: usize| {
        let mut y = *base;
        for (i, wi) in w.iter().enumerate() {
            if i != skip && *wi > T::zero() {
                y += m(i) * *wi;
            }
        }
        y
    };
    let mut best = cost(&sum_without(w, usize::MAX), criterion);
    if !best.is_finite() {
        return Err(Error::NotPositiveDefinite {
            what: "fused information at the starting weights",
        });
    }
    if k < 2 {
        return Ok(());
    }
    for _ in 0..MAX_SWEEPS {
        let start = best;
        for j in 0..k {
            let wj = w[j];
            let rest_w = w
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != j)
                .fold(T::zero(), |a, (_, v)| a + *v);
            if !(rest_w > T::zero()) {
                continue; // every other weight is zero: the others' searches move it
            }
            let mj = m(j);
            // The other inputs' combination with their weights renormalised.
            let rest = (sum_without(w, j) - *base) / rest_w;
            let at = |t: T| {
                let f = cost(&(*base + mj * t + rest * (T::one() - t)), criterion);
                // A cost that is not a number counts as infinite.
                if f.is_finite() || f > T::zero() {
                    f
                } else {
                    c(f64::INFINITY)
                }
            };
            let (tb, fb) = golden_min(&at, wj, best);
            if tb != wj {
                let scale = (T::one() - tb) / rest_w;
                for (i, wi) in w.iter_mut().enumerate() {
                    *wi = if i == j { tb } else { *wi * scale };
                }
                best = fb;
            }
        }
        if !(start - best > start.abs() * c::<T>(1e-10)) {
            break;
        }
    }
    // Renormalise the rounding drift of the repeated scalings.
    let s = w.iter().fold(T::zero(), |a, v| a + *v);
    if !(s > T::zero() && s.is_finite()) || w.iter().any(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: "optimised fusion weights",
        });
    }
    w.iter_mut().for_each(|v| *v /= s);
    Ok(())
}

/// Golden-section search of `f` on `[0, 1]` ([`GOLDEN_STEPS`] steps); the best
/// of the bracket's points, both ends and the current point `(t0, f0)`, which
/// is kept unless something is strictly better.
fn golden_min<T: RealField + Copy>(f: &impl Fn(T) -> T, t0: T, f0: T) -> (T, T) {
    let inv_phi: T = c(0.618_033_988_749_894_9);
    let (mut lo, mut hi) = (T::zero(), T::one());
    let mut x1 = hi - (hi - lo) * inv_phi;
    let mut x2 = lo + (hi - lo) * inv_phi;
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..GOLDEN_STEPS {
        if f1 <= f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - (hi - lo) * inv_phi;
            f1 = f(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + (hi - lo) * inv_phi;
            f2 = f(x2);
        }
    }
    let mut best = (t0, f0);
    for (t, ft) in [
        (x1, f1),
        (x2, f2),
        (T::zero(), f(T::zero())),
        (T::one(), f(T::one())),
    ] {
        if ft < best.1 {
            best = (t, ft);
        }
    }
    best
}

/// A pair in both forms: the running result of a sequential rule.
struct Both<T: RealField + Copy, const N: usize> {
    info: InfoPair<T, N>,
    cov: Gaussian<T, N>,
}

impl<T: RealField + Copy, const N: usize> Both<T, N> {
    fn of(info: InfoPair<T, N>, what: &'static str) -> Result<Self> {
        let cov = info.to_gaussian().map_err(|e| match e {
            Error::NotPositiveDefinite { .. } => Error::NotPositiveDefinite { what },
            other => other,
        })?;
        Ok(Self { info, cov })
    }
}

/// Fuses the items one after the other with a two-input rule
/// `pair(a, b, W_a, w_b)` (`W_a` the accumulated weight).
fn sequential<T, I, const N: usize>(
    mut items: I,
    total: T,
    pair: impl Fn(&Both<T, N>, &Both<T, N>, T, T) -> Result<InfoPair<T, N>>,
) -> Result<InfoPair<T, N>>
where
    T: RealField + Copy,
    I: Iterator<Item = (T, InfoPair<T, N>)>,
{
    const WHAT: &str = "fusion input (information matrix)";
    // Inputs of zero weight are left out, as a CI combination leaves them out.
    let mut acc: Option<(Both<T, N>, T)> = None;
    for (w, p) in items.by_ref() {
        if !(w > T::zero()) {
            continue;
        }
        let b = Both::of(p, WHAT)?;
        acc = Some(match acc {
            None => (b, w / total),
            Some((a, wa)) => {
                let f = pair(&a, &b, wa, w / total)?;
                (Both::of(f, "fused information")?, wa + w / total)
            }
        });
    }
    acc.map(|(a, _)| a.info).ok_or(Error::InvalidParameter {
        what: "fusion weights",
        expected: "a positive sum",
    })
}

/// Inverse covariance intersection of two estimates (Noack et al. 2017,
/// eqs. for `C⁻¹` and the gains `K`, `L`), in information form:
/// `S = ω A + (1 − ω) B`, `Y = Y_a + Y_b − S⁻¹`,
/// `ŷ = ŷ_a + ŷ_b − S⁻¹ (ω a + (1 − ω) b)`. `ω` is the new input's share
/// `w_b/(W_a + w_b)` ([`Weights::Fixed`]) or minimises the criterion.
fn ici_pair<T: RealField + Copy, const N: usize>(
    a: &Both<T, N>,
    b: &Both<T, N>,
    wa: T,
    wb: T,
    weights: Weights,
) -> Result<InfoPair<T, N>> {
    let at = |omega: T| -> Result<InfoPair<T, N>> {
        let one_m = T::one() - omega;
        let s = sym(&(a.cov.p * omega + b.cov.p * one_m));
        let sinv = chol_inverse(&cholesky(&s, "ICI common-information bound S")?);
        let mean = a.cov.x * omega + b.cov.x * one_m;
        Ok(InfoPair {
            y: a.info.y + b.info.y - sinv * mean,
            ymat: sym(&(a.info.ymat + b.info.ymat - sinv)),
        })
    };
    let omega = match weights {
        Weights::Fixed => wb / (wa + wb),
        Weights::Optimal(criterion) => {
            let f = |omega: T| {
                let v = at(omega).map_or(c(f64::INFINITY), |p| cost(&p.ymat, criterion));
                if v.is_finite() || v > T::zero() {
                    v
                } else {
                    c(f64::INFINITY)
                }
            };
            golden_min(&f, wb / (wa + wb), f(wb / (wa + wb))).0
        }
    };
    at(omega)
}

/// Ellipsoidal intersection of two estimates (Sijs & Lazar 2012, eqs. 8–16),
/// in the basis that whitens `A` and diagonalises `B`: with `Y_a = L Lᵀ` and
/// `Lᵀ B L = U diag(d) Uᵀ`, `T = L⁻ᵀ U` maps `A` to `I` and `B` to `diag(d)`;
/// the mutual covariance is `diag(max(1, d))`, the fused covariance
/// `diag(min(1, d))` (the largest ellipsoid inside both), the fused mean takes
/// each component from the estimate with the smaller variance there (the
/// average where `d = 1`, Sijs & Lazar's `η`). In information form
/// `Y = L U diag(max(1, 1/d)) Uᵀ Lᵀ`, `ŷ = L U diag(max(1, 1/d)) x̂`.
fn ei_pair<T: RealField + Copy, const N: usize>(
    a: &Both<T, N>,
    b: &Both<T, N>,
) -> Result<InfoPair<T, N>> {
    let l = cholesky(&a.info.ymat, "EI first input (information matrix)")?.l();
    let m = sym(&(l.transpose() * b.cov.p * l));
    let (d, u) = jacobi_eigen(&m);
    let lu = l * u;
    let mu_a = lu.transpose() * a.cov.x; // Uᵀ Lᵀ a
    let mu_b = lu.transpose() * b.cov.x;
    let zeta: T = c(1e-10);
    let mut xh = SVector::<T, N>::zeros();
    let mut inv_p = SVector::<T, N>::zeros();
    for i in 0..N {
        let di = d[i];
        if !(di > T::zero()) || !di.is_finite() {
            return Err(Error::NotPositiveDefinite {
                what: "EI second input (covariance)",
            });
        }
        let dg = if di > T::one() { di } else { T::one() };
        let eta = if (di - T::one()).abs() < zeta * c(10.0) {
            zeta
        } else {
            T::zero()
        };
        let wa = T::one() / di - T::one() / dg + eta;
        let wb = T::one() - T::one() / dg + eta;
        let mu_g = (mu_a[i] * wa + mu_b[i] * wb) / (wa + wb);
        let ph = if di < T::one() { di } else { T::one() };
        xh[i] = ph * (mu_a[i] + mu_b[i] / di - mu_g / dg);
        inv_p[i] = T::one() / ph;
    }
    let scaled = SMatrix::<T, N, N>::from_fn(|r, col| lu[(r, col)] * inv_p[col]);
    Ok(InfoPair {
        y: scaled * xh,
        ymat: sym(&(scaled * lu.transpose())),
    })
}

/// Eigenvalues and orthonormal eigenvectors (columns) of a symmetric matrix by
/// cyclic Jacobi rotations (Golub & Van Loan, *Matrix Computations*, §8.5):
/// small, allocation-free and accurate to a few ulps of `‖A‖` for the state
/// dimensions of this crate.
pub fn jacobi_eigen<T: RealField + Copy, const N: usize>(
    a: &SMatrix<T, N, N>,
) -> (SVector<T, N>, SMatrix<T, N, N>) {
    let mut a = sym(a);
    let mut v = SMatrix::<T, N, N>::identity();
    let eps = T::default_epsilon();
    for _ in 0..60 {
        let mut off = T::zero();
        let mut norm = T::zero();
        for j in 0..N {
            for i in 0..N {
                let s = a[(i, j)] * a[(i, j)];
                norm += s;
                if i != j {
                    off += s;
                }
            }
        }
        if !(off > eps * eps * norm) {
            break;
        }
        for p in 0..N {
            for q in (p + 1)..N {
                let apq = a[(p, q)];
                if apq == T::zero() {
                    continue;
                }
                let theta = (a[(q, q)] - a[(p, p)]) / (c::<T>(2.0) * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + T::one()).sqrt());
                let t = if theta == T::zero() { T::one() } else { t };
                let cs = T::one() / (t * t + T::one()).sqrt();
                let sn = t * cs;
                for k in 0..N {
                    let (akp, akq) = (a[(k, p)], a[(k, q)]);
                    a[(k, p)] = cs * akp - sn * akq;
                    a[(k, q)] = sn * akp + cs * akq;
                }
                for k in 0..N {
                    let (apk, aqk) = (a[(p, k)], a[(q, k)]);
                    a[(p, k)] = cs * apk - sn * aqk;
                    a[(q, k)] = sn * apk + cs * aqk;
                }
                for k in 0..N {
                    let (vkp, vkq) = (v[(k, p)], v[(k, q)]);
                    v[(k, p)] = cs * vkp - sn * vkq;
                    v[(k, q)] = sn * vkp + cs * vkq;
                }
            }
        }
    }
    (SVector::from_fn(|i, _| a[(i, i)]), v)
}

/// A rule other than split CI on the inputs `(j, c_ij, (ŷ_j, Y_j))` of a node's
/// combination (its own adapted pair at its index among the arrived ones,
/// ascending): [`fuse_information`] on the pairs.
///
/// ```
/// use edccif_core::fusion_rules::{combine_rule, FusionRule};
/// use edccif_core::InfoPair;
/// use nalgebra::{Matrix2, Vector2};
/// let a = InfoPair { y: Vector2::new(1.0, 0.0), ymat: Matrix2::identity() };
/// let b = InfoPair { y: Vector2::new(0.0, 2.0), ymat: Matrix2::identity() * 2.0 };
/// let f = combine_rule(FusionRule::CI, [(0, 0.5, &a), (1, 0.5, &b)].into_iter())?;
/// assert!((f.p - Matrix2::identity() / 1.5).norm() < 1e-15);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn combine_rule<'a, T, I, const N: usize>(rule: FusionRule, inputs: I) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy + 'a,
    I: Iterator<Item = (usize, T, &'a InfoPair<T, N>)> + Clone,
{
    if rule.needs_contributions() {
        return Err(Error::InvalidParameter {
            what: "fusion rule",
            expected: "a rule without contributions here (split CI: combine_split)",
        });
    }
    fuse_information(rule, inputs.map(|(_, w, p)| (w, *p)), None)
}

/// Split CI of a node's combination (`docs/fusion.md`): the inputs
/// `(j, c_ij, (ŷ_j, Y_j))` are the adapted pairs that arrived (the node's own
/// among them); `own` are the contributions `(m, (ī_m, Ī_m))` in the node's own
/// adapted pair (its own and those it received); `includes(j, m)` says whether
/// node `j`'s adapted pair holds `m`'s contribution. Each input's dependent
/// part `D_j = (ŷ_j, Y_j) − Σ_{m ∈ own, includes(j, m)} (ī_m, Ī_m)` (its prior
/// and the contributions the node does not hold) is intersected with the
/// rule's weights (ICI for [`FusionRule::SplitIci`]), and the node's
/// contributions are added once: `Y = Σ ω_j D_j + Σ_{m ∈ own} Ī_m` for split CI.
///
/// Consistent when the contributions are measurement information with noise
/// independent across sensors and of every prior (the estimates' other
/// correlations arbitrary): then each `D_j` is independent of the node's
/// contributions.
///
/// ```
/// use edccif_core::fusion_rules::{combine_split, FusionRule, Weights};
/// use edccif_core::{Contribution, InfoPair};
/// use nalgebra::{Matrix2, Vector2};
/// // Two nodes with the same prior; each adapted with both contributions.
/// let prior = InfoPair { y: Vector2::new(0.0, 0.0), ymat: Matrix2::identity() };
/// let c = [Contribution { i: Vector2::new(1.0, 0.0), imat: Matrix2::identity() }; 2];
/// let adapted = InfoPair { y: prior.y + c[0].i + c[1].i, ymat: prior.ymat + c[0].imat + c[1].imat };
/// let f = combine_split(FusionRule::SplitCi(Weights::Fixed),
///                       [(0, 0.5, &adapted), (1, 0.5, &adapted)].into_iter(),
///                       [(0, &c[0]), (1, &c[1])].into_iter(), |_, _| true)?;
/// assert!((f.p - Matrix2::identity() / 3.0).norm() < 1e-15); // = the adapted pair
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn combine_split<'a, T, I, O, const N: usize>(
    rule: FusionRule,
    inputs: I,
    own: O,
    includes: impl Fn(usize, usize) -> bool + Copy,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy + 'a,
    I: Iterator<Item = (usize, T, &'a InfoPair<T, N>)> + Clone,
    O: Iterator<Item = (usize, &'a Contribution<T, N>)> + Clone,
{
    let mut independent = InfoPair::<T, N>::zeros();
    for (_, cm) in own.clone() {
        independent.y += cm.i;
        independent.ymat += cm.imat;
    }
    independent.ymat = sym(&independent.ymat);
    let dependent = inputs.map(move |(j, w, p)| {
        let mut d = *p;
        for (m, cm) in own.clone() {
            if includes(j, m) {
                d.y -= cm.i;
                d.ymat -= cm.imat;
            }
        }
        (w, d)
    });
    if !rule.needs_contributions() {
        return Err(Error::InvalidParameter {
            what: "fusion rule",
            expected: "split-ci or split-ici (their variants) for combine_split",
        });
    }
    fuse_information(rule, dependent, Some(&independent))
}

/// [`combine_rule`] or [`combine_split`] by the rule: the combination of a node
/// under any rule, given the contributions for split CI.
pub fn combine_node<'a, T, I, O, const N: usize>(
    rule: FusionRule,
    inputs: I,
    own: O,
    includes: impl Fn(usize, usize) -> bool + Copy,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy + 'a,
    I: Iterator<Item = (usize, T, &'a InfoPair<T, N>)> + Clone,
    O: Iterator<Item = (usize, &'a Contribution<T, N>)> + Clone,
{
    if rule.needs_contributions() {
        combine_split(rule, inputs, own, includes)
    } else {
        combine_rule(rule, inputs)
    }
}
