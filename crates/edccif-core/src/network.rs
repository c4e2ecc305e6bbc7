//! A whole synchronous network step on borrowed slices: every node's local filter,
//! then the fusion of the chosen algorithm row (ALGORITHM.md §4, §5), as a loop
//! over the per-node phases of [`node`](crate::node). The caller owns all buffers
//! (fixed-size arrays on a vehicle, vectors allocated once in a simulator); the
//! step allocates nothing.
//!
//! A failed step returns the error and leaves every [`NodeState`] as it was.

use nalgebra::RealField;

use crate::error::{Error, Result};
use crate::filters::{EtOptions, LocalFilter};
use crate::linalg::validate_positive;
use crate::message::{Contribution, Gaussian, InfoPair, Observation};
use crate::model::{MeasurementModel, MotionModel};
use crate::node::{
    local_checked, node_adapt, node_combine_ci, node_combine_convex, node_consensus_round,
    LocalOutput,
};
use crate::trigger::{Trigger, TriggerState};

/// The local filter each node runs.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum NodeFilter<T> {
    /// Cubature information filter with event triggering (contributions in
    /// information form; required by the diffusion fusions).
    Cif,
    /// A covariance-form filter (CKF, EKF, UKF).
    Cov(LocalFilter<T>),
}

/// How the nodes' estimates are fused after the local step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Fusion {
    /// Diffusion adaptation + combination with covariance intersection (DC-CIF, EDC-CIF).
    DiffusionCi,
    /// Diffusion adaptation + convex combination of estimates (D-CIF, ED-CIF).
    DiffusionConvex,
    /// `iterations` synchronous consensus iterations on the local posteriors'
    /// information pairs (the C-/EC-/DEC- baselines).
    Consensus {
        /// Number of iterations `L ≥ 1`.
        iterations: usize,
    },
    /// No fusion: each node keeps its local posterior.
    Local,
}

/// One algorithm: local filter, trigger, untriggered-step options and fusion.
///
/// ```
/// use edccif_core::{NetworkConfig, Fusion, NodeFilter, Trigger, EtOptions};
/// let edc = NetworkConfig::<f64> {
///     filter: NodeFilter::Cif,
///     trigger: Trigger::SendOnDelta { delta: 0.04 },
///     et: EtOptions::default(),
///     fusion: Fusion::DiffusionCi,
/// };
/// assert!(edc.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct NetworkConfig<T> {
    /// Local filter.
    pub filter: NodeFilter<T>,
    /// Trigger on each sensor → estimator link.
    pub trigger: Trigger<T>,
    /// Untriggered-step policy and gain parameters.
    pub et: EtOptions<T>,
    /// Fusion across the network.
    pub fusion: Fusion,
}

impl<T: RealField + Copy> NetworkConfig<T> {
    /// Checks the parameters and that the fusion fits the filter (diffusion needs
    /// information-form contributions, i.e. [`NodeFilter::Cif`]).
    pub fn validate(&self) -> Result<()> {
        self.trigger.validate()?;
        self.et.validate()?;
        if let NodeFilter::Cov(LocalFilter::Ukf { alpha, beta, kappa }) = self.filter {
            crate::sigma::SigmaRule::unscented(2, alpha, beta, kappa)?;
        }
        match (self.filter, self.fusion) {
            (NodeFilter::Cov(_), Fusion::DiffusionCi | Fusion::DiffusionConvex) => {
                Err(Error::InvalidParameter {
                    what: "fusion",
                    expected:
                        "consensus or local for a covariance-form filter (diffusion needs the CIF)",
                })
            }
            (_, Fusion::Consensus { iterations: 0 }) => Err(Error::InvalidParameter {
                what: "consensus iterations",
                expected: ">= 1",
            }),
            _ => Ok(()),
        }
    }
}

/// What a node carries from one step to the next: its fused estimate and its
/// sensor's trigger memory.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct NodeState<T: RealField + Copy, const N: usize, const M: usize> {
    /// Fused estimate (the node's output at the last step, its start at the next).
    pub estimate: Gaussian<T, N>,
    /// Trigger memory of the node's sensor.
    pub trigger: TriggerState<T, M>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> NodeState<T, N, M> {
    /// A node starting from `estimate` with a fresh trigger.
    pub fn new(estimate: Gaussian<T, N>, trigger: &Trigger<T>) -> Self {
        Self {
            estimate,
            trigger: TriggerState::new(trigger),
        }
    }
}

/// Per-node working memory of a step; after a successful step it also holds the
/// step's intermediate results for inspection and logging.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeScratch<T: RealField + Copy, const N: usize, const M: usize> {
    /// Information prior `(ŷ⁻, Y⁻)` (CIF only).
    pub prior: InfoPair<T, N>,
    /// The node's contribution `(ī, Ī)` (CIF only).
    pub contribution: Contribution<T, N>,
    /// Information pair entering the combination: the adapted pair for diffusion,
    /// the local posterior otherwise.
    pub local: InfoPair<T, N>,
    /// `local` in covariance form (the node's estimate before combination). Under
    /// [`Fusion::DiffusionCi`] only `post.x` is formed (the CI combination works on
    /// `local`, so the inverse is skipped; `post.p` keeps an older value) unless the
    /// adaptation guard fired; `local.to_gaussian()` gives the covariance.
    pub post: Gaussian<T, N>,
    /// The fused estimate of this step.
    pub fused: Gaussian<T, N>,
    /// `Some(γ)` when a measurement was taken, `None` when missing or inactive.
    pub triggered: Option<bool>,
    /// Whether the adaptation guard replaced an indefinite adapted matrix
    /// (ALGORITHM.md §4).
    pub guard_used: bool,
    /// Whether the innovation gate rejected this node's measurement this step.
    pub gated: bool,
    out: LocalOutput<T, N, M>,
    cons: [InfoPair<T, N>; 2],
}

impl<T: RealField + Copy, const N: usize, const M: usize> Default for NodeScratch<T, N, M> {
    fn default() -> Self {
        let g = Gaussian {
            x: nalgebra::SVector::zeros(),
            p: nalgebra::SMatrix::identity(),
        };
        Self {
            prior: InfoPair::zeros(),
            contribution: Contribution::zeros(),
            local: InfoPair::zeros(),
            post: g,
            fused: g,
            triggered: None,
            guard_used: false,
            gated: false,
            out: LocalOutput::empty(),
            cons: [InfoPair::zeros(); 2],
        }
    }
}

/// The per-step inputs: the time step, each node's observation, plus optional
/// masks for lost messages and inactive nodes.
#[derive(Debug, Clone, Copy)]
pub struct StepInputs<'a, T: RealField + Copy, const M: usize> {
    /// Time since the previous step (finite, `> 0`): the motion model predicts
    /// over it, so steps need not be uniform.
    pub dt: T,
    /// One observation per node.
    pub observations: &'a [Observation<T, M>],
    /// `k × k` row-major: `links[i*k + j]` is true when node i receives node j's
    /// messages this step (`None`: every message arrives).
    pub links: Option<&'a [bool]>,
    /// `active[i]` false: node i is down this step (it neither computes nor sends;
    /// its state is kept). `None`: all nodes are up.
    pub active: Option<&'a [bool]>,
}

impl<'a, T: RealField + Copy, const M: usize> StepInputs<'a, T, M> {
    /// A step of `dt` in which all messages arrive and all nodes are up.
    pub fn new(observations: &'a [Observation<T, M>], dt: T) -> Self {
        Self {
            dt,
            observations,
            links: None,
            active: None,
        }
    }
}

/// Counters of one network step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct StepReport {
    /// Nodes that took a measurement.
    pub measured: usize,
    /// Nodes whose sensor sent (γ = 1).
    pub triggered: usize,
    /// Nodes whose adapted information matrix was indefinite and fell back to the
    /// local-only posterior (ALGORITHM.md §4).
    pub guard_fallbacks: usize,
    /// Nodes whose triggered measurement the innovation gate rejected
    /// ([`EtOptions::gate`](crate::EtOptions::gate)).
    pub gated: usize,
}

fn check_len(what: &'static str, expected: usize, got: usize) -> Result<()> {
    if expected == got {
        Ok(())
    } else {
        Err(Error::Dimension {
            what,
            expected,
            got,
        })
    }
}

/// One synchronous step of the whole network.
///
/// `weights` is the `k × k` row-major combination matrix (e.g. from
/// [`max_degree_weights`](crate::fusion::max_degree_weights)); node j is a
/// neighbour of node i when `weights[i*k + j] > 0`, `j ≠ i`. `sensors`, `nodes`,
/// `scratch` and `inputs.observations` have one entry per node.
///
/// The configuration is checked with [`NetworkConfig::validate`] first.
/// On success every active node's [`NodeState`] holds the fused estimate and
/// `scratch` the step's intermediate results; on error no [`NodeState`] is
/// changed (`scratch` may hold partial results).
///
/// ```
/// use edccif_core::*;
/// use edccif_core::fusion::max_degree_weights;
/// use edccif_core::models::{LinearMotion, Position3};
/// use nalgebra::{Matrix2, SMatrix, SVector, Vector3};
///
/// // 2 nodes, 1-D constant velocity, both seeing position.
/// let motion = LinearMotion::new(
///     SMatrix::<f64, 4, 4>::identity(), SMatrix::<f64, 4, 4>::identity() * 1e-3).unwrap();
/// let sensors = [Position3::new([0.1; 3]).unwrap(); 2];
/// let mut w = [0.0; 4];
/// max_degree_weights(&[false, true, true, false], 2, &mut w).unwrap();
/// let cfg = NetworkConfig { filter: NodeFilter::Cif, trigger: Trigger::SendOnDelta { delta: 0.04 },
///                           et: EtOptions::default(), fusion: Fusion::DiffusionCi };
/// let start = Gaussian::new(SVector::<f64, 4>::zeros(), SMatrix::<f64, 4, 4>::identity()).unwrap();
/// let mut nodes = [NodeState::<f64, 4, 3>::new(start, &cfg.trigger); 2];
/// let mut scratch = [NodeScratch::default(); 2];
/// let obs = [Observation::Measured(Vector3::new(1.0, 0.0, 0.0)); 2];
/// let report = network_step(&cfg, &motion, &sensors, &w, &mut nodes, &mut scratch,
///                           &StepInputs::new(&obs, 0.1)).unwrap();
/// assert_eq!(report.triggered, 2);
/// assert!(nodes[0].estimate.x[0] > 0.9);
/// ```
// Index loops: `active(i)` and the neighbour filters are indexed by node too.
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
pub fn network_step<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    sensors: &[H],
    weights: &[T],
    nodes: &mut [NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
    inputs: &StepInputs<'_, T, M>,
) -> Result<StepReport>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M>,
{
    // A configuration that `validate` rejects (e.g. diffusion with a
    // covariance-form filter, whose nodes have no information contributions)
    // must not run silently.
    cfg.validate()?;
    validate_positive(inputs.dt, "time step dt", false)?;
    let k = nodes.len();
    check_len("sensors", k, sensors.len())?;
    check_len("weight matrix (nodes × nodes)", k * k, weights.len())?;
    check_len("scratch buffers", k, scratch.len())?;
    check_len("observations", k, inputs.observations.len())?;
    if let Some(l) = inputs.links {
        check_len("link mask (nodes × nodes)", k * k, l.len())?;
    }
    if let Some(a) = inputs.active {
        check_len("active mask", k, a.len())?;
    }
    let active = |i: usize| inputs.active.is_none_or(|a| a[i]);
    // j's messages reach i (j ≠ i): neighbours, both up, link not lost.
    let hears = |i: usize, j: usize| {
        i != j
            && weights[i * k + j] > T::zero()
            && active(j)
            && inputs.links.is_none_or(|l| l[i * k + j])
    };
    let mut report = StepReport::default();

    // 1. Local phase.
    for i in 0..k {
        let s = &mut scratch[i];
        s.guard_used = false;
        s.gated = false;
        if !active(i) {
            s.triggered = None;
            continue;
        }
        let out = local_checked(
            cfg,
            &cfg.trigger,
            motion,
            inputs.dt,
            &sensors[i],
            &nodes[i],
            &inputs.observations[i],
        )?;
        s.prior = out.local.prior;
        s.contribution = out.local.contribution;
        s.local = out.local.posterior;
        if let Some(g) = out.local.estimate {
            s.post = g;
        }
        s.triggered = out.triggered;
        s.gated = out.gated;
        s.out = out;
        if let Some(g) = s.triggered {
            report.measured += 1;
            report.triggered += usize::from(g);
        }
        report.gated += usize::from(s.gated);
    }

    // 2. Fusion phases.
    match cfg.fusion {
        Fusion::DiffusionCi | Fusion::DiffusionConvex => {
            for i in 0..k {
                if !active(i) {
                    continue;
                }
                let a = node_adapt(
                    &scratch[i].out.local,
                    (0..k)
                        .filter(|&j| hears(i, j))
                        .map(|j| &scratch[j].out.local.contribution),
                )?;
                let s = &mut scratch[i];
                // Under CI without the guard only `x` is formed (see `post`).
                s.local = a.pair;
                s.post.x = a.x;
                if let Some(p) = a.covariance {
                    s.post.p = p;
                }
                s.guard_used = a.guard_used;
                report.guard_fallbacks += usize::from(a.guard_used);
            }
            for i in 0..k {
                if !active(i) {
                    continue;
                }
                let received = (0..k).filter(|&j| hears(i, j));
                let w = |j: usize| weights[i * k + j];
                scratch[i].fused = if cfg.fusion == Fusion::DiffusionCi {
                    node_combine_ci(
                        i,
                        w(i),
                        &scratch[i].local,
                        received.map(|j| (j, w(j), &scratch[j].local)),
                    )?
                } else {
                    node_combine_convex(
                        i,
                        w(i),
                        &scratch[i].post,
                        received.map(|j| (j, w(j), &scratch[j].post)),
                    )?
                };
            }
        }
        Fusion::Consensus { iterations } => {
            for s in scratch.iter_mut() {
                s.cons[0] = s.local;
            }
            for t in 0..iterations {
                let (src, dst) = (t % 2, (t + 1) % 2);
                for i in 0..k {
                    if !active(i) {
                        continue;
                    }
                    let next = node_consensus_round(
                        i,
                        weights[i * k + i],
                        &scratch[i].cons[src],
                        (0..k)
                            .filter(|&j| hears(i, j))
                            .map(|j| (j, weights[i * k + j], &scratch[j].cons[src])),
                    )?;
                    scratch[i].cons[dst] = next;
                }
            }
            let last = iterations % 2;
            for i in 0..k {
                if !active(i) {
                    continue;
                }
                scratch[i].fused = scratch[i].cons[last].to_gaussian()?;
            }
        }
        Fusion::Local => {
            for i in 0..k {
                if !active(i) {
                    continue;
                }
                scratch[i].fused = scratch[i].out.local.posterior_estimate()?;
            }
        }
    }

    // 3. Commit.
    for i in 0..k {
        if !active(i) {
            continue;
        }
        scratch[i].out.commit(&mut nodes[i], scratch[i].fused);
    }
    Ok(report)
}
