//! One node's share of a network step, phase by phase: what a real node runs
//! between the messages it sends and receives. [`network_step`](crate::network_step)
//! is a loop over exactly these functions, so a set of nodes that run them by hand
//! and deliver every packet reproduces it bit for bit.
//!
//! | phase | function | sends | ALGORITHM.md |
//! |---|---|---|---|
//! | local step | [`node_local`] (trigger at the node) or [`node_local_received`] (trigger at the sensor) | [`LocalPacket`]: the contribution `(ī, Ī)` (diffusion), the local posterior pair (consensus round 0), or nothing | §3, §5 |
//! | adaptation | [`node_adapt`] with the neighbours' contributions that arrived | [`AdaptedPacket`]: the adapted pair (CI) or estimate (convex) | §4 (with the adaptation guard) |
//! | combination | [`node_combine_ci`], [`node_combine_convex`] (or [`node_combine`] on packets) with the adapted packets that arrived | — | §4 |
//! | consensus round (×L) | [`node_consensus_round`], then [`InfoPair::to_gaussian`] after the last | the round's pair | §5 |
//! | commit | [`LocalOutput::commit`] | — | — |
//!
//! The packets are plain `Copy` values. Every phase after the local step is generic
//! over the state dimension `N` only, not over the measurement dimension `M`, so
//! nodes with different sensors fuse together. A phase only reads the node's
//! [`NodeState`]; only [`LocalOutput::commit`] changes it, so a failed phase leaves
//! the node as it was.
//!
//! Combinations renormalise the weights over the node itself and the packets that
//! arrived (a lost message leaves a convex combination of the others), and sum in
//! ascending node index with the node's own term at its index, as the network step
//! does: pass the received packets in ascending sender order to reproduce it bit
//! for bit. Received matrices must be exactly symmetric, as every phase produces
//! them (the [`wire`](crate::wire) format carries the upper triangle).
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

use core::cell::Cell;

use nalgebra::{RealField, SMatrix, SVector};

use crate::error::{Error, Result};
use crate::filters::{cif_predict_factored, cif_update_with, cov_local_factored};
use crate::fusion::{adapt, check_combined, combine_convex, combine_information_symmetric};
use crate::linalg::{check_finite, cholesky, validate_positive};
use crate::message::{Contribution, Gaussian, InfoPair, Observation};
use crate::model::{MeasurementModel, MotionModel};
use crate::network::{Fusion, NetworkConfig, NodeFilter, NodeState};
use crate::trigger::{Trigger, TriggerState};

/// What a node publishes after its local step.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum LocalPacket<T: RealField + Copy, const N: usize> {
    /// Diffusion rows: the measurement contribution `(ī, Ī)` for the neighbours'
    /// adaptation (ALGORITHM.md §4).
    Contribution(Contribution<T, N>),
    /// Consensus rows: the local posterior pair `(ŷ, Y)`, the packet of consensus
    /// round 0 (ALGORITHM.md §5).
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

/// The result of a node's local step ([`node_local`]): the fusion part, the
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
        state.estimate = fused;
        state.trigger = self.trigger;
    }

    pub(crate) fn empty() -> Self {
        Self {
            local: LocalEstimate {
                fusion: Fusion::Local,
                prior: InfoPair::zeros(),
                contribution: Contribution::zeros(),
                posterior: InfoPair::zeros(),
                estimate: None,
            },
            trigger: TriggerState {
                last_sent: None,
                eta: T::zero(),
                rng: 0,
            },
            triggered: None,
            gated: false,
        }
    }
}

/// The result of a node's adaptation ([`node_adapt`]).
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
    /// matrix by the local posterior (ALGORITHM.md §4).
    pub guard_used: bool,
}

/// The outcome of one consensus round ([`node_consensus_round`]).
pub type ConsensusPacket<T, const N: usize> = InfoPair<T, N>;

/// Local step of a node whose trigger runs at the node (ALGORITHM.md §3; §5 for
/// the covariance-form filters): predict over `dt`, decide on `obs` with the
/// row's trigger, update (or take the untriggered step). Reads `state`, changes
/// nothing; its output's [`packet`](LocalOutput::packet) is what the node publishes.
///
/// Checks `cfg` ([`NetworkConfig::validate`]) and `dt` (finite, `> 0`).
/// Under consensus or without fusion the CIF's posterior is also formed in
/// covariance form (and must be positive definite).
pub fn node_local<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    obs: &Observation<T, M>,
) -> Result<LocalOutput<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    cfg.validate()?;
    validate_positive(dt, "time step dt", false)?;
    local_checked(cfg, &cfg.trigger, motion, dt, sensor, state, obs)
}

/// Whether `trigger` can run at a sensor apart from its node: the sensor must
/// decide without the node's prediction and without random draws the node's
/// silent step would need (always, send-on-delta, dynamic).
pub fn check_sensor_side_trigger<T: RealField + Copy>(trigger: &Trigger<T>) -> Result<()> {
    if trigger.needs_prediction() || trigger.has_silent_update() {
        return Err(Error::InvalidParameter {
            what: "trigger run at the sensor",
            expected: "always, send-on-delta or dynamic (this one needs the node's prediction or \
                       updates on silence)",
        });
    }
    Ok(())
}

/// Local step of a node whose trigger runs at its sensor ([`check_sensor_side_trigger`]):
/// the node only learns whether a measurement arrived. `Some(z)` is a sent
/// measurement (`γ = 1`); `None` is the row's untriggered step with the last
/// received measurement `z_τ` (kept in `state.trigger.last_sent`), or a step
/// without measurement before the first one arrived (or for an always-sending
/// trigger). `triggered` reports whether `z` arrived.
///
/// Fed what [`Trigger::decide`] lets through, this gives the estimates of
/// [`node_local`] on the sensor's measurements bit for bit (the node's trigger
/// memory keeps `z_τ`; a dynamic trigger's `η` lives at the sensor). A sensor
/// outage looks like silence here: it is the untriggered step, not
/// [`Observation::Missing`].
///
/// ```
/// use edccif_core::node::*;
/// use edccif_core::models::{LinearMotion, Position3};
/// use edccif_core::*;
/// use nalgebra::{SMatrix, SVector, Vector3};
///
/// let motion = LinearMotion::new(
///     SMatrix::<f64, 3, 3>::identity(), SMatrix::<f64, 3, 3>::identity() * 1e-3)?;
/// let sensor = Position3::new([0.1; 3])?;
/// let cfg = NetworkConfig { filter: NodeFilter::Cif, trigger: Trigger::SendOnDelta { delta: 0.04 },
///                           et: EtOptions::default(), fusion: Fusion::DiffusionCi,
///                           rule: FusionRule::CI };
/// let start = Gaussian::new(SVector::<f64, 3>::zeros(), SMatrix::<f64, 3, 3>::identity())?;
/// let state = NodeState::<f64, 3, 3>::new(start, &cfg.trigger);
/// let z = Vector3::new(1.0, 2.0, 3.0);
/// let (sent, _) = cfg.trigger.decide::<_, 3, 3>(&sensor, &state.trigger, &z);
/// assert!(sent);
/// let at_sensor = node_local_received(&cfg, &motion, 0.1, &sensor, &state, Some(&z))?;
/// let at_node = node_local(&cfg, &motion, 0.1, &sensor, &state, &Observation::Measured(z))?;
/// assert_eq!(at_sensor, at_node);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn node_local_received<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    z: Option<&SVector<T, M>>,
) -> Result<LocalOutput<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    cfg.validate()?;
    check_sensor_side_trigger(&cfg.trigger)?;
    validate_positive(dt, "time step dt", false)?;
    let (obs, trigger) = match (z, state.trigger.last_sent, cfg.trigger) {
        (Some(z), _, _) => (Observation::Measured(*z), Trigger::Always),
        (None, _, Trigger::Always) | (None, None, _) => (Observation::Missing, cfg.trigger),
        (None, Some(zt), t) => (Observation::Measured(zt), t),
    };
    let mut out = local_checked(cfg, &trigger, motion, dt, sensor, state, &obs)?;
    out.triggered = out.triggered.map(|_| z.is_some());
    Ok(out)
}

/// [`node_local`] for a configuration and `dt` already checked, with the trigger
/// to decide by (the row's, or `Always` for a measurement a sensor sent).
pub(crate) fn local_checked<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    trigger: &Trigger<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    obs: &Observation<T, M>,
) -> Result<LocalOutput<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let mut out = LocalOutput::empty();
    local_checked_into(
        cfg, trigger, motion, dt, sensor, state, None, obs, true, &mut out,
    )?;
    Ok(out)
}

/// [`local_checked`] writing its result into `out` (the network step's scratch)
/// instead of returning it; on error `out` may hold part of it.
///
/// `diffusion_posterior`: whether the CIF's local posterior pair is formed under
/// a diffusion fusion. The network step passes `false`: there only the
/// adaptation guard reads it, and the guard forms it itself
/// ([`InfoPair::updated`] of the prior and contribution kept in `out`, the same
/// expression and so the same bits); `out.local.posterior` then keeps an older
/// value.
///
/// `factor`: the lower Cholesky factor of `state.estimate.p` when the caller
/// has it (the prediction then does not factorise `P` again; the same result
/// and errors, see [`sigma_predict_checked`](crate::sigma)).
#[allow(clippy::too_many_arguments)]
pub(crate) fn local_checked_into<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    trigger: &Trigger<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    factor: Option<&SMatrix<T, N, N>>,
    obs: &Observation<T, M>,
    diffusion_posterior: bool,
    out: &mut LocalOutput<T, N, M>,
) -> Result<()>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let diffusion = matches!(cfg.fusion, Fusion::DiffusionCi | Fusion::DiffusionConvex);
    out.local.fusion = cfg.fusion;
    match cfg.filter {
        NodeFilter::Cif => {
            // `cif_local`'s two halves, the prior borrowed inside its
            // `Result`; the update hands its outcome to a continuation that
            // writes it into `out` (the prior's pair and the contribution
            // copied once each, `x̂⁻` and `P⁻` not at all).
            let pr = cif_predict_factored(motion, dt, &state.estimate, factor);
            let prior = match &pr {
                Ok(p) => p,
                Err(e) => return Err(*e),
            };
            cif_update_with(
                sensor,
                prior,
                obs,
                trigger,
                &state.trigger,
                &cfg.et,
                |contribution, triggered, trigger_state, gated| {
                    let l = &mut out.local;
                    l.prior = prior.info();
                    l.contribution = *contribution;
                    // Assigned in each branch, not as one `if` expression:
                    // the expression's value (the whole `Option<Gaussian>`)
                    // was built apart and then copied, also for `None`.
                    if diffusion {
                        if diffusion_posterior {
                            l.posterior = l.prior.updated(&l.contribution);
                        }
                        l.estimate = None;
                    } else {
                        l.posterior = l.prior.updated(&l.contribution);
                        l.estimate = Some(l.posterior.to_gaussian()?);
                    }
                    out.trigger = trigger_state;
                    out.triggered = triggered;
                    out.gated = gated;
                    Ok(())
                },
            )??;
        }
        NodeFilter::Cov(f) => {
            // The posterior's factor from the definiteness check is reused for
            // its information form (same factor, so the same inverse). Both
            // borrowed inside their `Result` (a continuation as the CIF's
            // measured no gain here: the compiler already writes them in place).
            let rf = cov_local_factored(
                &f,
                motion,
                dt,
                sensor,
                &state.estimate,
                factor,
                obs,
                trigger,
                &state.trigger,
                &cfg.et,
            );
            let (r, factor) = match &rf {
                Ok((r, factor)) => (r, factor),
                Err(e) => return Err(*e),
            };
            let l = &mut out.local;
            l.prior = InfoPair::zeros();
            l.contribution = Contribution::zeros();
            l.posterior = if matches!(cfg.fusion, Fusion::Local) {
                InfoPair::zeros()
            } else {
                r.posterior.info_from_factor(factor)?
            };
            l.estimate = Some(r.posterior);
            out.trigger = r.trigger_state;
            out.triggered = r.triggered;
            out.gated = r.gated;
        }
    }
    Ok(())
}

/// Diffusion adaptation (ALGORITHM.md §4, P-eq. diff_ada) with the contributions
/// `(ī_j, Ī_j)` that arrived from the neighbours:
/// `Y_i = sym(Y⁻_i + Ī_i + Σ_j Ī_j)`, `ŷ_i = ŷ⁻_i + ī_i + Σ_j ī_j`.
///
/// Adaptation guard (§4): when the Cholesky factorisation of `Y_i` fails (or
/// `x̂_i` is not finite), the node falls back to its local posterior
/// `Y⁻_i + Ī_i` for this step and reports `guard_used`. Under CI the inverse of
/// `Y_i` is not formed (the combination works on the pair); without CI it is.
/// (The network step sums only the lower triangles of its exactly symmetric
/// matrices, with the same result bit for bit.)
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
    let adapted = adapt(&local.prior, &local.contribution, received);
    let mut post = Gaussian {
        x: SVector::zeros(),
        p: SMatrix::zeros(),
    };
    Ok(match adapt_finish(local, &adapted, ci, &mut post)? {
        Adapted::Information => AdaptOutput {
            packet: AdaptedPacket::Information(adapted),
            pair: adapted,
            x: post.x,
            covariance: None,
            guard_used: false,
        },
        Adapted::Estimate => AdaptOutput {
            packet: AdaptedPacket::Estimate(post),
            pair: adapted,
            x: post.x,
            covariance: Some(post.p),
            guard_used: false,
        },
        Adapted::Guard => AdaptOutput {
            packet: if ci {
                AdaptedPacket::Information(local.posterior)
            } else {
                AdaptedPacket::Estimate(post)
            },
            pair: local.posterior,
            x: post.x,
            covariance: Some(post.p),
            guard_used: true,
        },
    })
}

/// What [`adapt_finish`] formed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Adapted {
    /// Under CI: the adapted pair is the packet; `x` formed, not `P`.
    Information,
    /// Without CI: the adapted estimate `(x, P)` formed.
    Estimate,
    /// The guard fired: the local posterior in covariance form, `(x, P)`.
    Guard,
}

/// The second half of [`node_adapt`], given the adapted pair: the guard's check
/// and the estimate before combination, written into `post` (only `post.x`
/// under CI without the guard). Shared by [`node_adapt`] and the network step,
/// which writes into its scratch.
#[inline]
pub(crate) fn adapt_finish<T, const N: usize>(
    local: &LocalEstimate<T, N>,
    adapted: &InfoPair<T, N>,
    ci: bool,
    post: &mut Gaussian<T, N>,
) -> Result<Adapted>
where
    T: RealField + Copy,
{
    match adapt_estimate(adapted, ci, post) {
        Some(kind) => Ok(kind),
        None => adapt_guard(&local.posterior, post),
    }
}

/// The estimate before combination from the adapted pair, written into `post`
/// (only `post.x` under CI): `Some` of what was formed, `None` when the
/// adaptation guard must fire (the factorisation of `Y_i` failed or `x̂_i` is
/// not finite; `post` may then hold part of the attempt).
#[inline]
pub(crate) fn adapt_estimate<T, const N: usize>(
    adapted: &InfoPair<T, N>,
    ci: bool,
    post: &mut Gaussian<T, N>,
) -> Option<Adapted>
where
    T: RealField + Copy,
{
    // The factor is borrowed inside its `Result` and the estimate written into
    // `post` directly (no moves of large values); a failed attempt's partial
    // write is overwritten by the guard.
    if ci {
        if let Ok(ch) = &cholesky(&adapted.ymat, "adapted information Y") {
            post.x = ch.solve(&adapted.y);
            if check_finite(&post.x, "state estimate x = Y⁻¹ŷ").is_ok() {
                return Some(Adapted::Information);
            }
        }
    } else if adapted.write_gaussian(post).is_ok() {
        return Some(Adapted::Estimate);
    }
    None
}

/// The adaptation guard: the local-only posterior (PD by construction) in
/// covariance form, written into `post`.
#[inline(never)]
pub(crate) fn adapt_guard<T, const N: usize>(
    posterior: &InfoPair<T, N>,
    post: &mut Gaussian<T, N>,
) -> Result<Adapted>
where
    T: RealField + Copy,
{
    posterior.write_gaussian(post)?;
    Ok(Adapted::Guard)
}

/// The received items `(sender, weight, packet)` with the node's own
/// `(weight, packet)` inserted before the first sender above `me`: the
/// ascending-index order of the network step when the senders ascend.
struct WithOwn<'a, I, P, T> {
    received: I,
    me: usize,
    own: Option<(T, &'a P)>,
    held: Option<(T, &'a P)>,
    from_self: bool,
}

impl<'a, I, P, T> Iterator for WithOwn<'a, I, P, T>
where
    I: Iterator<Item = (usize, T, &'a P)>,
{
    type Item = (T, &'a P);
    fn next(&mut self) -> Option<Self::Item> {
        if let Some(h) = self.held.take() {
            return Some(h);
        }
        match self.received.next() {
            Some((j, w, p)) => {
                self.from_self |= j == self.me;
                if j > self.me {
                    if let Some(own) = self.own.take() {
                        self.held = Some((w, p));
                        return Some(own);
                    }
                }
                Some((w, p))
            }
            None => self.own.take(),
        }
    }
}

/// Runs `combine` over the node's own term and the received ones in order;
/// rejects a packet that claims to come from the node itself.
fn with_own<'a, T, P, I, R>(
    me: usize,
    own: (T, &'a P),
    received: I,
    combine: impl FnOnce(&mut WithOwn<'a, I::IntoIter, P, T>) -> Result<R>,
) -> Result<R>
where
    T: RealField + Copy,
    I: IntoIterator<Item = (usize, T, &'a P)>,
{
    let mut items = WithOwn {
        received: received.into_iter(),
        me,
        own: Some(own),
        held: None,
        from_self: false,
    };
    let r = combine(&mut items);
    if items.from_self {
        return Err(Error::InvalidParameter {
            what: "received packet",
            expected: "a sender other than the node itself",
        });
    }
    r
}

/// Combination with covariance intersection (ALGORITHM.md §4, P-eq.
/// diff_com_Y_ci, diff_com_x_ci) of node `me`'s adapted pair (weight `c_ii`)
/// with the adapted pairs `(j, c_ij, (ŷ_j, Y_j))` that arrived:
/// `Y = Σ c_ij Y_j / Σ c_ij`, `ŷ = Σ c_ij ŷ_j / Σ c_ij`, then `P = Y⁻¹`, `x̂ = P ŷ`,
/// the weights renormalised over what arrived. Returns the fused estimate to
/// [`commit`](LocalOutput::commit).
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
    // The same weighted information sum as a consensus round, then back to
    // covariance form (`to_gaussian` checks finiteness).
    with_own(me, (own_weight, own), received, |items| {
        combine_information_symmetric(items)
    })?
    .to_gaussian()
}

/// Combination without covariance intersection (ALGORITHM.md §4, P-eq.
/// diff_com; D-CIF, ED-CIF) of node `me`'s adapted estimate with those
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

/// One consensus round (ALGORITHM.md §5) of node `me`: its current pair
/// (weight `c_ii`; the local posterior, [`LocalPacket::Information`], at round 0)
/// combined with the neighbours' pairs of this round that arrived,
/// `Y ← Σ c_ij Y_j / Σ c_ij`, `ŷ ← Σ c_ij ŷ_j / Σ c_ij`. The result is the
/// packet of the next round; after the last of the `L` rounds its
/// [`to_gaussian`](InfoPair::to_gaussian) is the fused estimate.
///
/// Errors: a weight negative or not finite, a zero total, a sender equal to
/// `me`, a combined pair that is not finite ([`Error::NonFinite`]: non-finite
/// packets, or finite ones whose weighted sum overflows), so that no round
/// hands NaN or ±∞ on to the next.
pub fn node_consensus_round<'a, T, const N: usize>(
    me: usize,
    own_weight: T,
    own: &'a InfoPair<T, N>,
    received: impl IntoIterator<Item = (usize, T, &'a InfoPair<T, N>)>,
) -> Result<ConsensusPacket<T, N>>
where
    T: RealField + Copy,
{
    with_own(me, (own_weight, own), received, |items| {
        let pair = combine_information_symmetric(items)?;
        check_combined(&pair.y, &pair.ymat)?;
        Ok(pair)
    })
}
