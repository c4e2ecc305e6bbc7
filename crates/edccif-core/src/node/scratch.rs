//! A node's working memory through the phases of one step.

use nalgebra::{RealField, SMatrix, SVector};

use crate::config::Fusion;
use crate::message::{Contribution, Gaussian, InfoPair};

use super::packets::LocalEstimate;

/// One node's working memory through the phases of a step, in state space only
/// (no measurement dimension): what the local phase hands to the fusion phases
/// and what they write. After a successful step it holds the step's
/// intermediate results for inspection and logging.
///
/// [`node_local_into`](super::node_local_into) fills the local part;
/// [`network_fusion`](crate::network::network_fusion) runs the fusion phases
/// over a network's scratches. A [`NodeScratch`](crate::NodeScratch) is one of
/// these plus the sensor's new trigger memory (and dereferences to it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseScratch<T: RealField + Copy, const N: usize> {
    /// The local posterior in covariance form (the node's estimate before
    /// combination). Under [`Fusion::DiffusionCi`] only `post.x` is formed (the
    /// CI combination works on the adapted pair [`local`](Self::local), so the
    /// inverse is skipped; `post.p` keeps an older value) unless the adaptation
    /// guard fired; `local().to_gaussian()` gives the covariance.
    pub post: Gaussian<T, N>,
    /// The fused estimate of this step.
    pub fused: Gaussian<T, N>,
    /// `Some(γ)` when a measurement was taken, `None` when missing or inactive.
    pub triggered: Option<bool>,
    /// Whether the adaptation guard replaced an indefinite adapted matrix
    /// (`docs/algorithm.md` §4).
    pub guard_used: bool,
    /// Whether the innovation gate rejected this node's measurement this step.
    pub gated: bool,
    /// The local step's part for the fusion phases.
    pub(crate) local: LocalEstimate<T, N>,
    /// The pair after adaptation (diffusion rows).
    pub(crate) adapted: InfoPair<T, N>,
    /// The consensus rounds' pairs: round `t` writes `cons[t % 2]`.
    pub(crate) cons: [InfoPair<T, N>; 2],
    /// The lower Cholesky factor of the estimate's `P` at the step's start,
    /// valid when `factored` (the network step's factors, four nodes at a time).
    pub(crate) factor: SMatrix<T, N, N>,
    pub(crate) factored: bool,
}

impl<T: RealField + Copy, const N: usize> PhaseScratch<T, N> {
    /// Information prior `(ŷ⁻, Y⁻)` (CIF only; zero otherwise).
    pub fn prior(&self) -> &InfoPair<T, N> {
        &self.local.prior
    }

    /// The node's contribution `(ī, Ī)` (CIF only; zero otherwise).
    pub fn contribution(&self) -> &Contribution<T, N> {
        &self.local.contribution
    }

    /// Information pair entering the combination: the adapted pair for diffusion
    /// (the local posterior when the guard fired), the local posterior otherwise.
    pub fn local(&self) -> &InfoPair<T, N> {
        match self.local.fusion {
            Fusion::DiffusionCi | Fusion::DiffusionConvex => &self.adapted,
            _ => &self.local.posterior,
        }
    }

    /// The local step's part for the fusion phases (its `posterior` is formed
    /// where a fusion phase reads it: not under diffusion, whose adaptation
    /// guard forms it when it fires).
    pub fn local_estimate(&self) -> &LocalEstimate<T, N> {
        &self.local
    }
}

impl<T: RealField + Copy, const N: usize> Default for PhaseScratch<T, N> {
    fn default() -> Self {
        let g = Gaussian {
            x: SVector::zeros(),
            p: SMatrix::identity(),
        };
        Self {
            post: g,
            fused: g,
            triggered: None,
            guard_used: false,
            gated: false,
            local: LocalEstimate::empty(),
            adapted: InfoPair::zeros(),
            cons: [InfoPair::zeros(); 2],
            factor: SMatrix::zeros(),
            factored: false,
        }
    }
}

impl<T: RealField + Copy, const N: usize> AsRef<PhaseScratch<T, N>> for PhaseScratch<T, N> {
    fn as_ref(&self) -> &PhaseScratch<T, N> {
        self
    }
}

impl<T: RealField + Copy, const N: usize> AsMut<PhaseScratch<T, N>> for PhaseScratch<T, N> {
    fn as_mut(&mut self) -> &mut PhaseScratch<T, N> {
        self
    }
}

/// Typed access to the [`PhaseScratch`] inside a network's per-node storage
/// (a [`PhaseScratch`] itself, or a [`NodeScratch`](crate::NodeScratch)): the
/// phases loop over `&mut [S]` with `S: AsRef<PhaseScratch> + AsMut<PhaseScratch>`.
pub(crate) trait AsPhase<T: RealField + Copy, const N: usize> {
    fn phase(&self) -> &PhaseScratch<T, N>;
    fn phase_mut(&mut self) -> &mut PhaseScratch<T, N>;
}

impl<T, S, const N: usize> AsPhase<T, N> for S
where
    T: RealField + Copy,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
{
    #[inline(always)]
    fn phase(&self) -> &PhaseScratch<T, N> {
        self.as_ref()
    }
    #[inline(always)]
    fn phase_mut(&mut self) -> &mut PhaseScratch<T, N> {
        self.as_mut()
    }
}
