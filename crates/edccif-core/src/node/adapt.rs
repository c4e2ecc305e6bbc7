//! The adaptation phase of the diffusion rows (`docs/algorithm.md` §4): a
//! node's prior plus its own and its neighbours' contributions, the estimate
//! before combination (`LANES` nodes at a time in the network step), and the
//! adaptation guard.

use nalgebra::{RealField, SMatrix, SVector};

use crate::config::Fusion;
use crate::error::{Error, Result};
use crate::fusion::adapt_symmetric_into;
use crate::lanes::{self, LANES};
use crate::linalg::{check_finite, cholesky};
use crate::message::{Contribution, Gaussian, InfoPair};

use super::packets::{AdaptOutput, AdaptedPacket, LocalEstimate};
use super::scratch::{AsPhase, PhaseScratch};

/// Diffusion adaptation (`docs/algorithm.md` §4, P-13) with the
/// contributions `(ī_j, Ī_j)` that arrived from the neighbours:
/// `Y_i = sym(Y⁻_i + Ī_i + Σ_j Ī_j)`, `ŷ_i = ŷ⁻_i + ī_i + Σ_j ī_j`.
///
/// Adaptation guard (§4): when the Cholesky factorisation of `Y_i` fails (or
/// `x̂_i` is not finite), the node falls back to its local posterior
/// `Y⁻_i + Ī_i` for this step and reports `guard_used`. Under CI the inverse of
/// `Y_i` is not formed (the combination works on the pair); without CI it is.
///
/// Errors: `local` not from a diffusion row; the local posterior not positive
/// definite when the guard needs it.
pub fn node_adapt<'a, T, const N: usize>(
    local: &LocalEstimate<T, N>,
    received: impl IntoIterator<Item = &'a Contribution<T, N>>,
) -> Result<AdaptOutput<T, N>>
where
    T: RealField + Copy,
{
    let ci = match local.fusion {
        Fusion::DiffusionCi => true,
        Fusion::DiffusionConvex => false,
        _ => {
            return Err(Error::InvalidParameter {
                what: "fusion of the adaptation phase",
                expected: "a diffusion row (diffusion-ci or diffusion-convex)",
            })
        }
    };
    let mut pair = InfoPair::zeros();
    adapt_sum(local, received, &mut pair);
    let mut post = Gaussian {
        x: SVector::zeros(),
        p: SMatrix::zeros(),
    };
    let guard_used = adapt_finish(local, &mut pair, &mut post)?;
    Ok(AdaptOutput {
        packet: match ci {
            true => AdaptedPacket::Information(pair),
            false => AdaptedPacket::Estimate(post),
        },
        pair,
        x: post.x,
        covariance: (!ci || guard_used).then_some(post.p),
        guard_used,
    })
}

/// The adapted pair of a node: its prior and contribution plus the received
/// contributions, into `out` (every entry written). The inputs are exactly
/// symmetric, so the lower triangles are summed and mirrored
/// ([`adapt_symmetric_into`]).
#[inline(always)]
pub(crate) fn adapt_sum<'a, T, const N: usize>(
    local: &LocalEstimate<T, N>,
    received: impl IntoIterator<Item = &'a Contribution<T, N>>,
    out: &mut InfoPair<T, N>,
) where
    T: RealField + Copy,
{
    adapt_symmetric_into(&local.prior, &local.contribution, received, out);
}

/// The estimate before combination from the adapted pair, or the adaptation
/// guard: writes `post` (only `post.x` under CI without the guard) and, when
/// the guard fires, replaces `adapted` by the local posterior. Whether the
/// guard fired.
#[inline]
pub(crate) fn adapt_finish<T, const N: usize>(
    local: &LocalEstimate<T, N>,
    adapted: &mut InfoPair<T, N>,
    post: &mut Gaussian<T, N>,
) -> Result<bool>
where
    T: RealField + Copy,
{
    if adapt_estimate(adapted, local.fusion == Fusion::DiffusionCi, post) {
        return Ok(false);
    }
    adapt_guard(local, adapted, post)?;
    Ok(true)
}

/// The estimate before combination from the adapted pair, written into `post`
/// (only `post.x` under CI): false when the adaptation guard must fire (the
/// factorisation of `Y_i` failed or `x̂_i` is not finite; `post` may then hold
/// part of the attempt, which the guard overwrites).
#[inline]
fn adapt_estimate<T, const N: usize>(
    adapted: &InfoPair<T, N>,
    ci: bool,
    post: &mut Gaussian<T, N>,
) -> bool
where
    T: RealField + Copy,
{
    if ci {
        if let Ok(ch) = &cholesky(&adapted.ymat, "adapted information Y") {
            post.x = ch.solve(&adapted.y);
            return check_finite(&post.x, "state estimate x = Y⁻¹ŷ").is_ok();
        }
        return false;
    }
    adapted.write_gaussian(post).is_ok()
}

/// The adaptation guard: the local-only posterior `Y⁻_i + Ī_i` (positive
/// definite by construction) replaces the adapted pair, and its covariance
/// form is written into `post`.
#[inline(never)]
fn adapt_guard<T, const N: usize>(
    local: &LocalEstimate<T, N>,
    adapted: &mut InfoPair<T, N>,
    post: &mut Gaussian<T, N>,
) -> Result<()>
where
    T: RealField + Copy,
{
    let posterior = local.prior.updated(&local.contribution);
    posterior.write_gaussian(post)?;
    *adapted = posterior;
    Ok(())
}

/// The adapted estimates of the nodes in `group` (ascending, at most
/// [`LANES`]) from their adapted pairs through the lane kernels, written into
/// their `post` (only `x` under CI); per lane, whether it was formed. A lane
/// is not formed where the per-node [`adapt_finish`] would not form it either
/// (a failed factorisation, a non-finite estimate) or takes its slow path (a
/// covariance it factorises to check): the caller runs [`adapt_finish`] for
/// that node, which forms the estimate or fires the guard.
pub(crate) fn adapt_estimates_lanes<T, S, const N: usize>(
    ci: bool,
    group: &[usize],
    scratch: &mut [S],
) -> [bool; LANES]
where
    T: RealField + Copy,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
{
    let mut y = [lanes::splat(T::zero()); N];
    let mut ymat = lanes::zeros::<T, N>();
    lanes::pad(&mut ymat, group.len());
    for (l, &i) in group.iter().enumerate() {
        lanes::load_pair(&mut y, &mut ymat, l, &scratch[i].phase().adapted);
    }
    let mut p = None;
    let ok = if ci {
        // Under CI only `x = Y⁻¹ŷ` (see `PhaseScratch::post`).
        let ok = lanes::cholesky_in_place(&mut ymat);
        lanes::chol_solve(&ymat, &mut y);
        lanes::finite(ok, y.iter())
    } else {
        let pm = p.insert(lanes::zeros::<T, N>());
        lanes::to_gaussians(&mut y, &ymat, pm)
    };
    for (l, &i) in group.iter().enumerate() {
        if ok[l] {
            lanes::store_gaussian(&y, p.as_ref(), l, &mut scratch[i].phase_mut().post);
        }
    }
    ok
}
