//! The consensus round of the consensus rows (`docs/algorithm.md` §5).

use nalgebra::RealField;

use crate::error::Result;
use crate::fusion::{check_combined, combine_information_symmetric};
use crate::message::InfoPair;

use super::order::with_own;
use super::packets::ConsensusPacket;

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
        consensus_round_into(items, &mut next)
    })?;
    Ok(next)
}

/// One consensus round of one node, the definition [`node_consensus_round`]
/// and the network step share: the weighted information sum over `items` (the
/// node's own term at its index), checked finite, into `out` (unchanged on
/// error).
#[inline(always)]
pub(crate) fn consensus_round_into<'a, T, const N: usize>(
    items: impl IntoIterator<Item = (T, &'a InfoPair<T, N>)>,
    out: &mut InfoPair<T, N>,
) -> Result<()>
where
    T: RealField + Copy,
{
    let pair = combine_information_symmetric(items)?;
    // Every round's pair, not only the last one's (which `to_gaussian`
    // checks): an overflow is named where it happens instead of feeding NaN
    // or ±∞ to the next round.
    check_combined(&pair.y, &pair.ymat)?;
    *out = pair;
    Ok(())
}
