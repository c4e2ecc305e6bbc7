//! The consensus round of the consensus rows (`docs/algorithm.md` §5).

use nalgebra::RealField;

use crate::error::Result;
use crate::fusion::{check_combined, check_weight, Accumulator};
use crate::message::InfoPair;

use super::order::with_own;
use super::packets::ConsensusPacket;
use super::scratch::{AsPhase, PhaseScratch};

/// One consensus round (`docs/algorithm.md` §5) of node `me`: its current pair
/// (weight `c_ii`; the local posterior,
/// [`LocalPacket::Information`](super::LocalPacket::Information), at round 0)
/// combined with the neighbours' pairs of this round that arrived,
/// `Y ← Σ c_ij Y_j / Σ c_ij`, `ŷ ← Σ c_ij ŷ_j / Σ c_ij`. The result is the
/// packet of the next round; after the last of the `L` rounds its
/// [`to_gaussian`](InfoPair::to_gaussian) is the fused estimate.
///
/// Errors: a weight negative or not finite, a zero total, a sender equal to
/// `me`, a combined pair that is not finite
/// ([`Error::NonFinite`](crate::Error::NonFinite): non-finite packets, or
/// finite ones whose weighted sum overflows), so that no round hands NaN or
/// ±∞ on to the next.
pub fn node_consensus_round<'a, T, const N: usize>(
    me: usize,
    own_weight: T,
    own: &'a InfoPair<T, N>,
    received: impl IntoIterator<Item = (usize, T, &'a InfoPair<T, N>)>,
) -> Result<ConsensusPacket<T, N>>
where
    T: RealField + Copy,
{
    let mut next = InfoPair::zeros();
    with_own(me, (own_weight, own), received, |items| {
        let mut sum = Accumulator::new();
        for (w, p) in items {
            consensus_add(&mut sum, w, p, false)?;
        }
        consensus_pair(sum, false, &mut next)
    })?;
    Ok(next)
}

/// One term of a consensus round's weighted information sum, the first half of
/// the round [`node_consensus_round`] and the network step share: `w·p` added
/// to `sum`, the terms in ascending node index with the node's own at its
/// index. The weight is checked unless `weights_checked` (the network step's
/// rounds after the first, whose weights and arrivals are those of the first).
#[inline(always)]
pub(crate) fn consensus_add<T, const N: usize>(
    sum: &mut Accumulator<T, N>,
    w: T,
    p: &InfoPair<T, N>,
    weights_checked: bool,
) -> Result<()>
where
    T: RealField + Copy,
{
    if !weights_checked {
        check_weight(w)?;
    }
    sum.add(w, p);
    Ok(())
}

/// The second half of a consensus round: the sum divided by the total weight
/// (checked positive unless `weights_checked`) and checked finite, so that no
/// round hands NaN or ±∞ on to the next, into `out` (unchanged on error).
#[inline(always)]
pub(crate) fn consensus_pair<T, const N: usize>(
    sum: Accumulator<T, N>,
    weights_checked: bool,
    out: &mut InfoPair<T, N>,
) -> Result<()>
where
    T: RealField + Copy,
{
    let pair = match weights_checked {
        true => sum.finish_unchecked(),
        false => sum.finish()?,
    };
    check_combined(&pair.y, &pair.ymat)?;
    *out = pair;
    Ok(())
}

/// One consensus round of every active node of a serial loop, the form the
/// network step runs (round `t` reads the pairs of round `t − 1`, the local
/// posteriors for `t = 0`, and writes `cons[t % 2]`): for each node the sum of
/// [`node_consensus_round`], term by term in the same order. `heard(i)` lists
/// the nodes of node i's closed neighbourhood whose packets reach i (and i),
/// ascending; `weight(i, j)` is the combination weight `c_ij`. The weights and the
/// arrivals are those of every round of a step, so they are checked in the
/// first round only.
#[inline(always)]
pub(crate) fn consensus_round_all<T, S, I, const N: usize>(
    t: usize,
    weight: impl Fn(usize, usize) -> T,
    active: impl Fn(usize) -> bool,
    heard: impl Fn(usize) -> I,
    scratch: &mut [S],
) -> Result<()>
where
    T: RealField + Copy,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
    I: Iterator<Item = usize>,
{
    let k = scratch.len();
    let dst = t % 2;
    for i in 0..k {
        if !active(i) {
            continue;
        }
        let mut sum = Accumulator::new();
        for j in heard(i) {
            let s = scratch[j].phase();
            let pair = match t {
                0 => &s.local.posterior,
                _ => &s.cons[1 - dst],
            };
            let w = weight(i, j);
            if t == 0 {
                check_weight(w)?;
            }
            sum.add(w, pair);
        }
        let pair = match t {
            0 => sum.finish()?,
            _ => sum.finish_unchecked(),
        };
        check_combined(&pair.y, &pair.ymat)?;
        scratch[i].phase_mut().cons[dst] = pair;
    }
    Ok(())
}
