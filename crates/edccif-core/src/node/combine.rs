//! The combination phase of the diffusion rows (`docs/algorithm.md` §4): with
//! covariance intersection, the weighted sum of the adapted information pairs
//! converted back to covariance form (the conversions `LANES` nodes at a time
//! in the network step); without it, the weighted sum of the adapted estimates.
//! A [`FusionRule`] other than the paper's CI (`docs/fusion.md`) replaces the
//! CI combination ([`combine_rule`]).

use core::cell::Cell;

use nalgebra::RealField;

use crate::error::{Error, Result};
use crate::fusion::{combine_convex, combine_information_symmetric};
use crate::fusion_rules::{combine_node, FusionRule};
use crate::lanes;
use crate::message::{Gaussian, InfoPair};

use super::order::with_own;
use super::packets::AdaptedPacket;
use super::scratch::{AsPhase, PhaseScratch};

/// Combination with covariance intersection (`docs/algorithm.md` §4, P-16,
/// P-17) of node `me`'s adapted pair (weight `c_ii`) with the adapted pairs
/// `(j, c_ij, (ŷ_j, Y_j))` that arrived:
/// `Y = Σ c_ij Y_j / Σ c_ij`, `ŷ = Σ c_ij ŷ_j / Σ c_ij`, then `P = Y⁻¹`, `x̂ = P ŷ`,
/// the weights renormalised over what arrived. Returns the fused estimate to
/// [`commit`](super::LocalOutput::commit).
///
/// Errors: a weight negative or not finite, a zero total, a sender equal to
/// `me`, a fused matrix that is not positive definite.
pub fn node_combine_ci<'a, T, const N: usize>(
    me: usize,
    own_weight: T,
    own: &'a InfoPair<T, N>,
    received: impl IntoIterator<Item = (usize, T, &'a InfoPair<T, N>)>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
{
    with_own(me, (own_weight, own), received, |items| combine_ci(items))
}

/// The CI combination of one node, the definition [`node_combine_ci`] and the
/// network step share: the weighted information sum over `items` (the node's
/// own term at its index), converted back to covariance form.
#[inline]
pub(crate) fn combine_ci<'a, T, const N: usize>(
    items: impl IntoIterator<Item = (T, &'a InfoPair<T, N>)>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
{
    combine_information_symmetric(items)?.to_gaussian()
}

/// [`combine_ci`] for the nodes in `group` (ascending, at most
/// [`LANES`](crate::lanes)): `pair(scratch, i)` is node i's weighted
/// information sum ([`combine_information_symmetric`] over what arrived),
/// converted back to covariance form through the lane kernels and written
/// into each node's `fused`. False when any of them is not formed (a weight or
/// a total the sum rejects, or a pair whose conversion the lanes decline); the
/// caller then combines every node with [`combine_ci`], which names the
/// error.
pub(crate) fn combine_ci_lanes<T, S, const N: usize>(
    group: &[usize],
    mut pair: impl FnMut(&[S], usize) -> Result<InfoPair<T, N>>,
    scratch: &mut [S],
) -> bool
where
    T: RealField + Copy,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
{
    let mut y = [lanes::splat(T::zero()); N];
    let mut ymat = lanes::zeros::<T, N>();
    lanes::pad(&mut ymat, group.len());
    for (l, &i) in group.iter().enumerate() {
        let Ok(p) = pair(scratch, i) else {
            return false;
        };
        lanes::load_pair(&mut y, &mut ymat, l, &p);
    }
    let mut p = lanes::zeros::<T, N>();
    let ok = lanes::to_gaussians(&mut y, &ymat, &mut p);
    if !ok[..group.len()].iter().all(|&o| o) {
        return false;
    }
    for (l, &i) in group.iter().enumerate() {
        lanes::store_gaussian(&y, Some(&p), l, &mut scratch[i].phase_mut().fused);
    }
    true
}

/// The combination of node `i` under a [`FusionRule`] other than the paper's
/// CI (`docs/fusion.md`, [`combine_node`]), the definition the network step
/// and [`network_fusion`](crate::network::network_fusion) use: the adapted
/// pairs of the closed neighbourhood that arrived (`heard(i)`, ascending, the
/// node's own at its index) with their weights `weight(j)` (`c_ij`), and for split CI the
/// contributions each adapted pair holds (its node's own, and those its node
/// heard unless its adaptation guard fired).
pub(crate) fn combine_rule<'a, T, S, I, const N: usize>(
    rule: FusionRule,
    i: usize,
    weight: impl Fn(usize) -> T + Copy + 'a,
    heard: impl Fn(usize) -> I + Copy + 'a,
    scratch: &'a [S],
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
    S: AsRef<PhaseScratch<T, N>>,
    I: Iterator<Item = usize> + Clone + 'a,
{
    let includes = move |j: usize, m: usize| {
        m == j || (!scratch[j].as_ref().guard_used && heard(j).any(|x| x == m))
    };
    let inputs = heard(i).map(move |j| (j, weight(j), &scratch[j].as_ref().adapted));
    let own = heard(i)
        .filter(move |&m| includes(i, m))
        .map(move |m| (m, &scratch[m].as_ref().local.contribution));
    combine_node(rule, inputs, own, includes)
}

/// Combination without covariance intersection (`docs/algorithm.md` §4, P-14; D-CIF, ED-CIF) of node `me`'s adapted estimate with those
/// `(j, c_ij, (x̂_j, P_j))` that arrived: `x̂ = Σ c_ij x̂_j / Σ c_ij`,
/// `P = sym(Σ c_ij P_j) / Σ c_ij`. Errors as [`node_combine_ci`].
pub fn node_combine_convex<'a, T, const N: usize>(
    me: usize,
    own_weight: T,
    own: &'a Gaussian<T, N>,
    received: impl IntoIterator<Item = (usize, T, &'a Gaussian<T, N>)>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
{
    with_own(me, (own_weight, own), received, |items| {
        combine_convex(items)
    })
}

/// [`node_combine_ci`] or [`node_combine_convex`] by the kind of the node's own
/// [`AdaptedPacket`]; a received packet of the other kind is an error.
pub fn node_combine<'a, T, const N: usize>(
    me: usize,
    own_weight: T,
    own: &'a AdaptedPacket<T, N>,
    received: impl IntoIterator<Item = (usize, T, &'a AdaptedPacket<T, N>)>,
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
{
    let mismatch = Cell::new(false);
    let r = match own {
        AdaptedPacket::Information(p) => node_combine_ci(
            me,
            own_weight,
            p,
            received.into_iter().filter_map(|(j, w, q)| match q {
                AdaptedPacket::Information(q) => Some((j, w, q)),
                AdaptedPacket::Estimate(_) => {
                    mismatch.set(true);
                    None
                }
            }),
        ),
        AdaptedPacket::Estimate(g) => node_combine_convex(
            me,
            own_weight,
            g,
            received.into_iter().filter_map(|(j, w, q)| match q {
                AdaptedPacket::Estimate(q) => Some((j, w, q)),
                AdaptedPacket::Information(_) => {
                    mismatch.set(true);
                    None
                }
            }),
        ),
    };
    if mismatch.get() {
        return Err(Error::InvalidParameter {
            what: "received adapted packet",
            expected: "the same kind as the node's own (information for CI, estimate without)",
        });
    }
    r
}
