//! One node's share of a network step, phase by phase: the only definition of a
//! step. [`network_step`](crate::network_step) is a loop over these phase
//! functions (the lane-batched forms where several nodes run the same
//! arithmetic), so a set of nodes that run the per-node forms by hand and
//! deliver every packet reproduces it bit for bit.
//!
//! | phase | per node | `LANES` nodes at once | sends | `docs/algorithm.md` |
//! |---|---|---|---|---|
//! | local step | [`node_local`] (trigger at the node), [`node_local_received`] (trigger at the sensor), [`node_local_into`] (into a [`PhaseScratch`]) | the Cholesky factors of the estimates' `P` | [`LocalPacket`]: the contribution `(ī, Ī)` (diffusion), the local posterior pair (consensus round 0), or nothing | §3, §5 |
//! | adaptation | [`node_adapt`] with the neighbours' contributions that arrived | the adapted estimates `Y_i⁻¹ ŷ_i` | [`AdaptedPacket`]: the adapted pair (CI) or estimate (convex) | §4 (with the adaptation guard) |
//! | combination | [`node_combine_ci`], [`node_combine_convex`] (or [`node_combine`] on packets) with the adapted packets that arrived; under a fusion rule other than CI [`combine_node`](crate::fusion_rules::combine_node) (`docs/fusion.md`) | the CI conversions back to covariance form (CI only) | — | §4 |
//! | consensus round (×L) | [`node_consensus_round`], then [`InfoPair::to_gaussian`](crate::InfoPair::to_gaussian) after the last | — | the round's pair | §5 |
//! | commit | [`LocalOutput::commit`] | — | — | — |
//!
//! The packets are plain `Copy` values. Every phase after the local step is generic
//! over the state dimension `N` only, not over the measurement dimension `M`, so
//! nodes with different sensors fuse together. A phase only reads the node's
//! [`NodeState`]; only the commit changes it, so a failed phase leaves the node
//! as it was.
//!
//! Combinations renormalise the weights over the node itself and the packets that
//! arrived (a lost message leaves a convex combination of the others), and sum in
//! ascending node index with the node's own term at its index, as the network step
//! does: pass the received packets in ascending sender order to reproduce it bit
//! for bit. Received matrices must be exactly symmetric, as every phase produces
//! them (the [`wire`](crate::wire) format carries the upper triangle): the sums
//! read their lower triangles.
//!
//! # Driving the phases
//!
//! - **One node per process** (an agent): [`node_local_received`] (or
//!   [`node_local`]), publish [`LocalOutput::packet`]; for the diffusion rows
//!   [`node_adapt`] with the contributions that arrived, publish
//!   [`AdaptOutput::packet`], then [`node_combine`] with the adapted packets that
//!   arrived; for the consensus rows `L` calls of [`node_consensus_round`], the
//!   last one's pair converted with `to_gaussian`; then [`LocalOutput::commit`].
//! - **A serial loop over many nodes**, also of sensors with different
//!   measurement dimensions: [`node_local_into`] for each node into its
//!   [`PhaseScratch`] (keeping the returned trigger memory aside), then
//!   [`network_fusion`](crate::network::network_fusion) over all of them (the
//!   adaptation and combination or the consensus rounds, with the lane-batched
//!   forms, and the step's [`StepReport`](crate::StepReport)); commit each
//!   node's [`PhaseScratch::fused`] and trigger memory. This is
//!   [`network_step`](crate::network_step) without its factors of `P` computed
//!   four nodes at a time.
//! - **A parallel loop** (threads): run each phase as a parallel loop over the
//!   nodes calling the per-node forms ([`node_local`], [`node_adapt`],
//!   [`node_combine_ci`] or [`node_combine_convex`], [`node_consensus_round`])
//!   with the packets in ascending sender order and a barrier between phases.
//!   Inside a phase every node reads only what the previous phase produced.
//!
//! A two-node exchange by hand, equal to [`network_step`](crate::network_step):
//!
//! ```
//! use edccif_core::node::*;
//! use edccif_core::fusion::max_degree_weights;
//! use edccif_core::models::{LinearMotion, Position3};
//! use edccif_core::*;
//! use nalgebra::{SMatrix, SVector, Vector3};
//!
//! let motion = LinearMotion::new(
//!     SMatrix::<f64, 4, 4>::identity(), SMatrix::<f64, 4, 4>::identity() * 1e-3)?;
//! let sensors = [Position3::new([0.1; 3])?, Position3::new([0.2; 3])?];
//! let mut w = [0.0; 4];
//! max_degree_weights(&[false, true, true, false], 2, &mut w)?;
//! let cfg = NetworkConfig { filter: NodeFilter::Cif, trigger: Trigger::SendOnDelta { delta: 0.04 },
//!                           et: EtOptions::default(), fusion: Fusion::DiffusionCi,
//!                           rule: FusionRule::CI };
//! let start = Gaussian::new(SVector::<f64, 4>::zeros(), SMatrix::<f64, 4, 4>::identity())?;
//! let mut nodes = [NodeState::<f64, 4, 3>::new(start, &cfg.trigger); 2];
//! let obs = [Observation::Measured(Vector3::new(1.0, 0.0, 0.0)),
//!            Observation::Measured(Vector3::new(1.1, 0.1, 0.0))];
//!
//! // Local step of each node; each publishes its contribution.
//! let l0 = node_local(&cfg, &motion, 0.1, &sensors[0], &nodes[0], &obs[0])?;
//! let l1 = node_local(&cfg, &motion, 0.1, &sensors[1], &nodes[1], &obs[1])?;
//! let (LocalPacket::Contribution(c0), LocalPacket::Contribution(c1)) = (l0.packet(), l1.packet())
//!     else { unreachable!("diffusion rows send contributions") };
//! // Adaptation with the neighbour's contribution; each publishes its adapted pair.
//! let a0 = node_adapt(&l0.local, [&c1])?;
//! let a1 = node_adapt(&l1.local, [&c0])?;
//! // Combination with the neighbour's adapted packet (sender, weight c_ij, packet).
//! let f0 = node_combine(0, w[0], &a0.packet, [(1, w[1], &a1.packet)])?;
//! let f1 = node_combine(1, w[3], &a1.packet, [(0, w[2], &a0.packet)])?;
//!
//! // The same step for the whole network at once.
//! let mut net = nodes;
//! let mut scratch = [NodeScratch::default(); 2];
//! network_step(&cfg, &motion, &sensors, &w, &mut net, &mut scratch, &StepInputs::new(&obs, 0.1))?;
//!
//! l0.commit(&mut nodes[0], f0);
//! l1.commit(&mut nodes[1], f1);
//! assert_eq!(nodes, net); // bit for bit
//!
//! // Had node 1's adapted packet been lost, node 0 would combine with itself only
//! // (its weight renormalised to one): its adapted estimate.
//! let alone = node_combine(0, w[0], &a0.packet, [])?;
//! assert!((alone.x - a0.x).norm() < 1e-12);
//! # Ok::<(), edccif_core::Error>(())
//! ```

mod adapt;
mod combine;
mod consensus;
mod local;
mod order;
mod packets;
mod scratch;
mod state;

pub use adapt::node_adapt;
pub(crate) use adapt::{adapt_estimates_lanes, adapt_finish, adapt_sum};
pub(crate) use combine::{combine_ci, combine_ci_lanes, combine_rule};
pub use combine::{node_combine, node_combine_ci, node_combine_convex};
pub(crate) use consensus::consensus_round_all;
pub use consensus::node_consensus_round;
pub use local::{check_sensor_side_trigger, node_local, node_local_into, node_local_received};
pub(crate) use local::{local_phase, prefactor_lanes};
pub use packets::{
    AdaptOutput, AdaptedPacket, ConsensusPacket, LocalEstimate, LocalOutput, LocalPacket,
};
pub(crate) use scratch::AsPhase;
pub use scratch::PhaseScratch;
pub use state::NodeState;
