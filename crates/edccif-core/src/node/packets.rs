//! What the phases hand on: the packets a node publishes, and the results of
//! its local step and adaptation.

use nalgebra::{RealField, SMatrix, SVector};

use crate::config::Fusion;
use crate::error::Result;
use crate::message::{Contribution, Gaussian, InfoPair};
use crate::trigger::TriggerState;

use super::state::NodeState;

/// What a node publishes after its local step.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum LocalPacket<T: RealField + Copy, const N: usize> {
    /// Diffusion rows: the measurement contribution `(ī, Ī)` for the neighbours'
    /// adaptation (`docs/algorithm.md` §4).
    Contribution(Contribution<T, N>),
    /// Consensus rows: the local posterior pair `(ŷ, Y)`, the packet of consensus
    /// round 0 (`docs/algorithm.md` §5).
    Information(InfoPair<T, N>),
    /// No fusion: nothing is sent; the local posterior is the node's output.
    Silent,
}

/// What a node publishes after its adaptation, for the neighbours' combination.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum AdaptedPacket<T: RealField + Copy, const N: usize> {
    /// Combination with covariance intersection: the adapted pair `(ŷ_i, Y_i)`.
    Information(InfoPair<T, N>),
    /// Combination without CI: the adapted estimate `(x̂_i, P_i)`.
    Estimate(Gaussian<T, N>),
}

/// The part of a node's local step the fusion phases need (no measurement
/// dimension).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LocalEstimate<T: RealField + Copy, const N: usize> {
    /// The fusion the step belongs to (it decides the phases that follow).
    pub fusion: Fusion,
    /// Information prior `(ŷ⁻, Y⁻)` (CIF; zero for covariance-form filters).
    pub prior: InfoPair<T, N>,
    /// The node's contribution `(ī, Ī)` (CIF; zero for covariance-form filters).
    pub contribution: Contribution<T, N>,
    /// The local posterior pair: `(ŷ⁻ + ī, Y⁻ + Ī)` for the CIF, `P⁻¹(x̂, I)` for a
    /// covariance-form filter (zero for a covariance-form filter without fusion,
    /// which never needs it).
    pub posterior: InfoPair<T, N>,
    /// The local posterior in covariance form when the step formed it
    /// (covariance-form filters; the CIF under consensus or without fusion).
    /// The diffusion rows skip the inverse: see [`posterior_estimate`](Self::posterior_estimate).
    pub estimate: Option<Gaussian<T, N>>,
}

impl<T: RealField + Copy, const N: usize> LocalEstimate<T, N> {
    /// Zero pairs and no estimate: a buffer for a local step to write.
    pub(crate) fn empty() -> Self {
        Self {
            fusion: Fusion::Local,
            prior: InfoPair::zeros(),
            contribution: Contribution::zeros(),
            posterior: InfoPair::zeros(),
            estimate: None,
        }
    }

    /// The packet to publish after the local step.
    pub fn packet(&self) -> LocalPacket<T, N> {
        match self.fusion {
            Fusion::DiffusionCi | Fusion::DiffusionConvex => {
                LocalPacket::Contribution(self.contribution)
            }
            Fusion::Consensus { .. } => LocalPacket::Information(self.posterior),
            Fusion::Local => LocalPacket::Silent,
        }
    }

    /// The local posterior in covariance form: [`estimate`](Self::estimate) when
    /// formed, otherwise `posterior` converted. Without fusion this is the node's
    /// output of the step.
    pub fn posterior_estimate(&self) -> Result<Gaussian<T, N>> {
        match self.estimate {
            Some(g) => Ok(g),
            None => self.posterior.to_gaussian(),
        }
    }
}

/// The result of a node's local step ([`node_local`](super::node_local)): the fusion part, the
/// sensor's trigger memory to commit, and what happened.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LocalOutput<T: RealField + Copy, const N: usize, const M: usize> {
    /// What the fusion phases need.
    pub local: LocalEstimate<T, N>,
    /// The trigger memory after this step (committed by [`commit`](Self::commit)).
    pub trigger: TriggerState<T, M>,
    /// `Some(γ)` when a measurement was taken, `None` when none was.
    pub triggered: Option<bool>,
    /// Whether the innovation gate rejected the measurement.
    pub gated: bool,
}

impl<T: RealField + Copy, const N: usize, const M: usize> LocalOutput<T, N, M> {
    /// The packet to publish after the local step ([`LocalEstimate::packet`]).
    pub fn packet(&self) -> LocalPacket<T, N> {
        self.local.packet()
    }

    /// Ends the node's step: `state` takes the fused estimate (the node's output
    /// now and its start at the next step) and the sensor's new trigger memory.
    /// The only phase that changes the node.
    pub fn commit(&self, state: &mut NodeState<T, N, M>, fused: Gaussian<T, N>) {
        state.commit(fused, self.trigger);
    }
}

/// The result of a node's adaptation ([`node_adapt`](super::node_adapt)).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct AdaptOutput<T: RealField + Copy, const N: usize> {
    /// The packet to publish, and the node's own term in its combination.
    pub packet: AdaptedPacket<T, N>,
    /// The information pair after adaptation: the adapted pair, or the local
    /// posterior when the guard fired.
    pub pair: InfoPair<T, N>,
    /// The node's estimate before combination, `x̂_i = Y_i⁻¹ ŷ_i`.
    pub x: SVector<T, N>,
    /// Its covariance when formed: under combination without CI, or when the
    /// guard fired (the CI combination works on `pair` and skips the inverse).
    pub covariance: Option<SMatrix<T, N, N>>,
    /// Whether the adaptation guard replaced an indefinite adapted information
    /// matrix by the local posterior (`docs/algorithm.md` §4).
    pub guard_used: bool,
}

/// The outcome of one consensus round ([`node_consensus_round`](super::node_consensus_round)).
pub type ConsensusPacket<T, const N: usize> = InfoPair<T, N>;
