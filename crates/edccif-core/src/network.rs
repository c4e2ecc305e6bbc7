//! A whole synchronous network step on borrowed slices: every node's local filter,
//! then the fusion of the chosen algorithm row (ALGORITHM.md §4, §5), as a loop
//! over the per-node phases of [`node`](crate::node). The caller owns all buffers
//! (fixed-size arrays on a vehicle, vectors allocated once in a simulator); the
//! step allocates nothing.
//!
//! A failed step returns the error and leaves every [`NodeState`] as it was.

use nalgebra::{RealField, SMatrix};

use crate::error::{Error, Result};
use crate::filters::{EtOptions, LocalFilter};
use crate::fusion::{
    adapt_symmetric_into, check_combined, check_weight, combine_convex, Accumulator,
};
use crate::fusion_rules::{combine_node, FusionRule};
use crate::lanes::{self, MatL, VecL, LANES};
use crate::linalg::{all_finite, validate_positive};
use crate::message::{Contribution, Gaussian, InfoPair, Observation};
use crate::model::{MeasurementModel, MotionModel};
use crate::node::{adapt_estimate, adapt_guard, local_checked_into, LocalOutput};
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

/// One algorithm: local filter, trigger, untriggered-step options, fusion and
/// the rule of the CI combination.
///
/// ```
/// use edccif_core::{NetworkConfig, Fusion, FusionRule, NodeFilter, Trigger, EtOptions};
/// let edc = NetworkConfig::<f64> {
///     filter: NodeFilter::Cif,
///     trigger: Trigger::SendOnDelta { delta: 0.04 },
///     et: EtOptions::default(),
///     fusion: Fusion::DiffusionCi,
///     rule: FusionRule::CI,
/// };
/// assert!(edc.validate().is_ok());
/// // a rule other than CI needs the CI combination of diffusion
/// let ici = NetworkConfig { rule: "ici".parse()?, ..edc };
/// assert!(ici.validate().is_ok());
/// assert!(NetworkConfig { fusion: Fusion::DiffusionConvex, ..ici }.validate().is_err());
/// # Ok::<(), edccif_core::Error>(())
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
    /// The rule of the combination under [`Fusion::DiffusionCi`]
    /// ([`fusion_rules`](crate::fusion_rules), `docs/fusion.md`); the paper's
    /// [`FusionRule::CI`] by default.
    #[cfg_attr(feature = "serde", serde(default))]
    pub rule: FusionRule,
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
            (_, Fusion::DiffusionConvex | Fusion::Consensus { .. } | Fusion::Local)
                if !self.rule.is_paper() =>
            {
                Err(Error::InvalidParameter {
                    what: "fusion rule",
                    expected: "ci unless the fusion is diffusion with CI (the rules replace its combination)",
                })
            }
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
    /// `local` in covariance form (the node's estimate before combination). Under
    /// [`Fusion::DiffusionCi`] only `post.x` is formed (the CI combination works on
    /// `local`, so the inverse is skipped; `post.p` keeps an older value) unless the
    /// adaptation guard fired; `local().to_gaussian()` gives the covariance.
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
    /// The pair after adaptation (diffusion rows).
    adapted: InfoPair<T, N>,
    cons: [InfoPair<T, N>; 2],
    /// The lower Cholesky factor of the estimate's `P` at the step's start,
    /// valid when `factored`.
    factor: SMatrix<T, N, N>,
    factored: bool,
}

impl<T: RealField + Copy, const N: usize, const M: usize> NodeScratch<T, N, M> {
    /// Information prior `(ŷ⁻, Y⁻)` (CIF only; zero otherwise).
    pub fn prior(&self) -> &InfoPair<T, N> {
        &self.out.local.prior
    }

    /// The node's contribution `(ī, Ī)` (CIF only; zero otherwise).
    pub fn contribution(&self) -> &Contribution<T, N> {
        &self.out.local.contribution
    }

    /// Information pair entering the combination: the adapted pair for diffusion
    /// (the local posterior when the guard fired), the local posterior otherwise.
    pub fn local(&self) -> &InfoPair<T, N> {
        match self.out.local.fusion {
            Fusion::DiffusionCi | Fusion::DiffusionConvex => &self.adapted,
            _ => &self.out.local.posterior,
        }
    }
}

impl<T: RealField + Copy, const N: usize, const M: usize> Default for NodeScratch<T, N, M> {
    fn default() -> Self {
        let g = Gaussian {
            x: nalgebra::SVector::zeros(),
            p: nalgebra::SMatrix::identity(),
        };
        Self {
            post: g,
            fused: g,
            triggered: None,
            guard_used: false,
            gated: false,
            out: LocalOutput::empty(),
            adapted: InfoPair::zeros(),
            cons: [InfoPair::zeros(); 2],
            factor: SMatrix::zeros(),
            factored: false,
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
    /// One trigger threshold per node: node i's sensor decides with
    /// `cfg.trigger` [`with_delta`](Trigger::with_delta)`(deltas[i])`, and an
    /// untriggered step's gain uses that `δ`. `None`: every node uses
    /// `cfg.trigger` as it is. A dynamic trigger's `η` starts at the `δ` its
    /// [`TriggerState`] was made with (make node i's with its own trigger).
    pub deltas: Option<&'a [T]>,
}

impl<'a, T: RealField + Copy, const M: usize> StepInputs<'a, T, M> {
    /// A step of `dt` in which all messages arrive and all nodes are up.
    pub fn new(observations: &'a [Observation<T, M>], dt: T) -> Self {
        Self {
            dt,
            observations,
            links: None,
            active: None,
            deltas: None,
        }
    }

    /// The same inputs with one trigger threshold per node ([`Self::deltas`]).
    ///
    /// ```
    /// use edccif_core::{Observation, StepInputs, Trigger};
    /// use nalgebra::Vector3;
    /// let obs = [Observation::Measured(Vector3::new(1.0, 0.0, 0.0)); 2];
    /// let inputs = StepInputs::new(&obs, 0.1).with_deltas(&[0.04, 0.01]);
    /// let sod = Trigger::SendOnDelta { delta: 0.04 };
    /// assert_eq!(inputs.trigger(&sod, 1)?, Trigger::SendOnDelta { delta: 0.01 });
    /// assert!(StepInputs::new(&obs, 0.1).with_deltas(&[0.04, f64::NAN]).check_deltas(&sod, 2).is_err());
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn with_deltas(self, deltas: &'a [T]) -> Self {
        Self {
            deltas: Some(deltas),
            ..self
        }
    }

    /// Node i's trigger: `trigger` with node i's threshold when
    /// [`Self::deltas`] is set (errors as [`Trigger::with_delta`]), else
    /// `trigger` itself.
    pub fn trigger(&self, trigger: &Trigger<T>, i: usize) -> Result<Trigger<T>> {
        match self.deltas {
            None => Ok(*trigger),
            Some(d) => match d.get(i) {
                Some(&delta) => trigger.with_delta(delta),
                None => Err(Error::Dimension {
                    what: "per-node thresholds (deltas)",
                    expected: i + 1,
                    got: d.len(),
                }),
            },
        }
    }

    /// Checks [`Self::deltas`] for `k` nodes: one per node, each finite and `> 0`.
    pub fn check_deltas(&self, trigger: &Trigger<T>, k: usize) -> Result<()> {
        if let Some(d) = self.deltas {
            check_len("per-node thresholds (deltas)", k, d.len())?;
            for i in 0..k {
                self.trigger(trigger, i)?;
            }
        }
        Ok(())
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

/// Every node's closed neighbourhood (itself and the nodes `j` with
/// `weights[i*k + j] > 0`), ascending, as compressed rows over caller-owned
/// buffers: node i's list is `indices[offsets[i]..offsets[i+1]]`. Built once per
/// weight matrix with [`from_weights`](Self::from_weights) (or viewed again over
/// kept buffers with [`new`](Self::new)), it lets [`network_step_sparse`] visit
/// each node's neighbours instead of scanning a row of `k` weights in every
/// phase and consensus iteration.
///
/// ```
/// use edccif_core::{fusion::max_degree_weights, Neighbours};
/// // a path 0 - 1 - 2
/// let adj = [false, true, false, true, false, true, false, true, false];
/// let mut w = [0.0f64; 9];
/// max_degree_weights(&adj, 3, &mut w)?;
/// let (mut offsets, mut indices) = ([0usize; 4], [0usize; 3 + 4]);
/// let nb = Neighbours::from_weights(&w, 3, &mut offsets, &mut indices)?;
/// assert_eq!(nb.row(1), &[0, 1, 2]);
/// assert_eq!(nb.row(2), &[1, 2]);
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Neighbours<'a> {
    offsets: &'a [usize],
    indices: &'a [usize],
}

impl<'a> Neighbours<'a> {
    /// Writes the closed neighbourhoods of the `k × k` row-major `weights` into
    /// `offsets` (length `k + 1`) and `indices` (length at least `k` plus the
    /// number of positive off-diagonal weights; [`count`](Self::count) gives it).
    pub fn from_weights<T: RealField + Copy>(
        weights: &[T],
        k: usize,
        offsets: &'a mut [usize],
        indices: &'a mut [usize],
    ) -> Result<Self> {
        check_len("weight matrix (nodes × nodes)", k * k, weights.len())?;
        check_len("neighbour offsets (nodes + 1)", k + 1, offsets.len())?;
        let need = Self::count(weights, k);
        if indices.len() < need {
            return Err(Error::Dimension {
                what: "neighbour indices (nodes + positive off-diagonal weights)",
                expected: need,
                got: indices.len(),
            });
        }
        let mut n = 0;
        for i in 0..k {
            offsets[i] = n;
            for j in 0..k {
                if j == i || weights[i * k + j] > T::zero() {
                    indices[n] = j;
                    n += 1;
                }
            }
        }
        offsets[k] = n;
        Ok(Self {
            offsets,
            indices: &indices[..n],
        })
    }

    /// The length of `indices` that [`from_weights`](Self::from_weights) needs:
    /// `k` plus the number of positive off-diagonal weights.
    pub fn count<T: RealField + Copy>(weights: &[T], k: usize) -> usize {
        let off = (0..k * k)
            .filter(|&e| e / k != e % k && weights.get(e).is_some_and(|w| *w > T::zero()))
            .count();
        k + off
    }

    /// A view of lists kept from [`from_weights`](Self::from_weights) (e.g. in
    /// buffers a simulator owns). Checks their shape: `offsets` non-decreasing
    /// from 0 to `indices.len()`, each list strictly ascending, within `0..k`
    /// (`k = offsets.len() − 1`) and holding the node itself.
    /// [`network_step_sparse`] also checks every listed neighbour has a positive
    /// weight; a positive weight left out of the lists is not used (as if that
    /// link's messages were lost).
    pub fn new(offsets: &'a [usize], indices: &'a [usize]) -> Result<Self> {
        let bad = Error::InvalidParameter {
            what: "neighbour lists",
            expected: "offsets from 0 to indices.len(), rows ascending within 0..k, \
                       each holding its own node",
        };
        let Some(k) = offsets.len().checked_sub(1) else {
            return Err(bad);
        };
        if offsets[0] != 0 || offsets[k] != indices.len() {
            return Err(bad);
        }
        for i in 0..k {
            let (a, b) = (offsets[i], offsets[i + 1]);
            if a > b {
                return Err(bad);
            }
            let row = &indices[a..b];
            let ascending = row.windows(2).all(|w| w[0] < w[1]);
            if !ascending || row.last().is_some_and(|&j| j >= k) || !row.contains(&i) {
                return Err(bad);
            }
        }
        Ok(Self { offsets, indices })
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Node i's closed neighbourhood, ascending.
    #[inline(always)]
    pub fn row(&self, i: usize) -> &'a [usize] {
        &self.indices[self.offsets[i]..self.offsets[i + 1]]
    }
}

/// Where a node's neighbours come from: a scan of its weight row, or lists.
trait Rows {
    /// Checks the rows against the `k × k` weights (of the right length).
    fn check<T: RealField + Copy>(&self, weights: &[T], k: usize) -> Result<()>;
    /// Node i's closed neighbourhood (itself included), ascending.
    fn row(&self, i: usize) -> impl Iterator<Item = usize> + Clone + '_;
}

/// The closed neighbourhoods read off the weight matrix.
struct Dense<'a, T> {
    weights: &'a [T],
    k: usize,
}

impl<T: RealField + Copy> Rows for Dense<'_, T> {
    fn check<U: RealField + Copy>(&self, _: &[U], _: usize) -> Result<()> {
        Ok(())
    }
    #[inline(always)]
    fn row(&self, i: usize) -> impl Iterator<Item = usize> + Clone + '_ {
        let row = &self.weights[i * self.k..(i + 1) * self.k];
        (0..self.k).filter(move |&j| j == i || row[j] > T::zero())
    }
}

impl Rows for Neighbours<'_> {
    fn check<T: RealField + Copy>(&self, weights: &[T], k: usize) -> Result<()> {
        check_len("neighbour lists (nodes)", k, self.nodes())?;
        for i in 0..k {
            let row = &weights[i * k..(i + 1) * k];
            if self.row(i).iter().any(|&j| j != i && !(row[j] > T::zero())) {
                return Err(Error::InvalidParameter {
                    what: "neighbour lists",
                    expected: "neighbours j of node i with a positive weight weights[i*k + j]",
                });
            }
        }
        Ok(())
    }
    #[inline(always)]
    fn row(&self, i: usize) -> impl Iterator<Item = usize> + Clone + '_ {
        Neighbours::row(self, i).iter().copied()
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
///                           et: EtOptions::default(), fusion: Fusion::DiffusionCi,
///                           rule: FusionRule::CI };
/// let start = Gaussian::new(SVector::<f64, 4>::zeros(), SMatrix::<f64, 4, 4>::identity()).unwrap();
/// let mut nodes = [NodeState::<f64, 4, 3>::new(start, &cfg.trigger); 2];
/// let mut scratch = [NodeScratch::default(); 2];
/// let obs = [Observation::Measured(Vector3::new(1.0, 0.0, 0.0)); 2];
/// let report = network_step(&cfg, &motion, &sensors, &w, &mut nodes, &mut scratch,
///                           &StepInputs::new(&obs, 0.1)).unwrap();
/// assert_eq!(report.triggered, 2);
/// assert!(nodes[0].estimate.x[0] > 0.9);
/// ```
#[allow(clippy::too_many_arguments)]
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
    let rows = Dense {
        weights,
        k: nodes.len(),
    };
    step_impl(cfg, motion, sensors, weights, &rows, nodes, scratch, inputs)
}

/// [`network_step`] with the neighbours taken from lists built once per weight
/// matrix ([`Neighbours::from_weights`]) instead of a scan of the weight row in
/// every phase and consensus iteration: O(edges) instead of O(k²) per phase.
/// With the lists of `weights` the result is bit for bit that of
/// [`network_step`].
///
/// Errors as [`network_step`], and when the lists are not for `k` nodes or list a
/// neighbour `j ≠ i` whose weight `weights[i*k + j]` is not positive.
///
/// ```
/// use edccif_core::*;
/// use edccif_core::fusion::max_degree_weights;
/// use edccif_core::models::{LinearMotion, Position3};
/// use nalgebra::{SMatrix, SVector, Vector3};
///
/// let motion = LinearMotion::new(
///     SMatrix::<f64, 4, 4>::identity(), SMatrix::<f64, 4, 4>::identity() * 1e-3)?;
/// let sensors = [Position3::new([0.1; 3])?; 2];
/// let mut w = [0.0; 4];
/// max_degree_weights(&[false, true, true, false], 2, &mut w)?;
/// let (mut offsets, mut indices) = ([0; 3], [0; 4]);
/// let nb = Neighbours::from_weights(&w, 2, &mut offsets, &mut indices)?;
/// let cfg = NetworkConfig { filter: NodeFilter::Cif, trigger: Trigger::SendOnDelta { delta: 0.04 },
///                           et: EtOptions::default(), fusion: Fusion::DiffusionCi,
///                           rule: FusionRule::CI };
/// let start = Gaussian::new(SVector::<f64, 4>::zeros(), SMatrix::<f64, 4, 4>::identity())?;
/// let mut a = [NodeState::<f64, 4, 3>::new(start, &cfg.trigger); 2];
/// let mut b = a;
/// let mut scratch = [NodeScratch::default(); 2];
/// let obs = [Observation::Measured(Vector3::new(1.0, 0.0, 0.0)); 2];
/// let inputs = StepInputs::new(&obs, 0.1);
/// network_step(&cfg, &motion, &sensors, &w, &mut a, &mut scratch, &inputs)?;
/// network_step_sparse(&cfg, &motion, &sensors, &w, &nb, &mut b, &mut scratch, &inputs)?;
/// assert_eq!(a, b);
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn network_step_sparse<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    sensors: &[H],
    weights: &[T],
    neighbours: &Neighbours<'_>,
    nodes: &mut [NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
    inputs: &StepInputs<'_, T, M>,
) -> Result<StepReport>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M>,
{
    step_impl(
        cfg, motion, sensors, weights, neighbours, nodes, scratch, inputs,
    )
}

// Index loops: `active(i)` and the neighbour filters are indexed by node too.
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
fn step_impl<T, F, H, R, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    sensors: &[H],
    weights: &[T],
    rows: &R,
    nodes: &mut [NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
    inputs: &StepInputs<'_, T, M>,
) -> Result<StepReport>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M>,
    R: Rows,
{
    // A configuration that `validate` rejects (e.g. diffusion with a
    // covariance-form filter, whose nodes have no information contributions)
    // must not run silently.
    cfg.validate()?;
    validate_positive(inputs.dt, "time step dt", false)?;
    let k = nodes.len();
    check_len("sensors", k, sensors.len())?;
    check_len("weight matrix (nodes × nodes)", k * k, weights.len())?;
    rows.check(weights, k)?;
    check_len("scratch buffers", k, scratch.len())?;
    check_len("observations", k, inputs.observations.len())?;
    if let Some(l) = inputs.links {
        check_len("link mask (nodes × nodes)", k * k, l.len())?;
    }
    if let Some(a) = inputs.active {
        check_len("active mask", k, a.len())?;
    }
    inputs.check_deltas(&cfg.trigger, k)?;
    let active = |i: usize| inputs.active.is_none_or(|a| a[i]);
    // For j in i's closed neighbourhood: j's messages reach i (both up, link
    // not lost), or j is i itself.
    let masked = inputs.links.is_some() || inputs.active.is_some();
    let arrives = |i: usize, j: usize| {
        j == i || !masked || (active(j) && inputs.links.is_none_or(|l| l[i * k + j]))
    };
    let mut report = StepReport::default();

    // 1. Local phase. Every local filter starts with the Cholesky factor of
    // its estimate's `P` (the sigma-point filters' points, the EKF's input
    // check): those of `LANES` nodes at a time first (the same bits); a node
    // whose factor the lanes decline factorises in its step.
    prefactor(k, &active, nodes, scratch);
    for i in 0..k {
        let s = &mut scratch[i];
        s.guard_used = false;
        s.gated = false;
        if !active(i) {
            s.triggered = None;
            continue;
        }
        let trigger = inputs.trigger(&cfg.trigger, i)?;
        local_checked_into(
            cfg,
            &trigger,
            motion,
            inputs.dt,
            &sensors[i],
            &nodes[i],
            s.factored.then_some(&s.factor),
            &inputs.observations[i],
            false,
            &mut s.out,
        )?;
        if let Some(g) = s.out.local.estimate {
            s.post = g;
        }
        s.triggered = s.out.triggered;
        s.gated = s.out.gated;
        if let Some(g) = s.triggered {
            report.measured += 1;
            report.triggered += usize::from(g);
        }
        report.gated += usize::from(s.gated);
    }

    // 2. Fusion phases. Every combination sums over the closed neighbourhood in
    // ascending index order, the node's own term at its index: the order of the
    // `node_*` phases with the received packets in ascending sender order.
    match cfg.fusion {
        Fusion::DiffusionCi | Fusion::DiffusionConvex => {
            let ci = cfg.fusion == Fusion::DiffusionCi;
            // The adapted sums first (they cannot fail), then the estimates
            // of `LANES` nodes at a time; a node whose lane the batched
            // kernels decline takes the scalar path (and the guard) here, in
            // ascending order, so that errors come as from a node-by-node loop.
            for i in 0..k {
                if !active(i) {
                    continue;
                }
                // Node i's scratch apart from the others', so that the adapted
                // pair is summed straight into it (no copy of the pair).
                let (before, rest) = scratch.split_at_mut(i);
                let Some((s, after)) = rest.split_first_mut() else {
                    continue;
                };
                let (before, after) = (&*before, &*after);
                adapt_symmetric_into(
                    &s.out.local.prior,
                    &s.out.local.contribution,
                    rows.row(i).filter(|&j| j != i && arrives(i, j)).map(|j| {
                        let other = if j < i { &before[j] } else { &after[j - i - 1] };
                        &other.out.local.contribution
                    }),
                    &mut s.adapted,
                );
            }
            for_each_group(k, active, |group| {
                let ok = adapt_estimates_lanes(ci, group, scratch);
                for (l, &i) in group.iter().enumerate() {
                    let s = &mut scratch[i];
                    s.guard_used = !ok[l] && adapt_scalar(ci, s)?;
                    report.guard_fallbacks += usize::from(s.guard_used);
                }
                Ok(true)
            })?;
            // The combinations, `LANES` at a time; when any of them is
            // declined, all of them again node by node (which names the error).
            let paper = cfg.rule.is_paper();
            let batched = ci
                && paper
                && for_each_group(k, active, |group| {
                    Ok(combine_ci_lanes(weights, rows, k, &arrives, group, scratch))
                })?;
            for i in 0..k {
                if batched || !active(i) {
                    continue;
                }
                let row = &weights[i * k..(i + 1) * k];
                if ci && !paper {
                    let g = combine_rule_at(cfg.rule, i, weights, rows, k, &arrives, scratch)?;
                    scratch[i].fused = g;
                } else if ci {
                    let mut acc = Accumulator::new();
                    for j in rows.row(i) {
                        if arrives(i, j) {
                            check_weight(row[j])?;
                            acc.add(row[j], &scratch[j].adapted);
                        }
                    }
                    acc.finish()?.write_gaussian(&mut scratch[i].fused)?;
                } else {
                    let arrived = rows.row(i).filter(|&j| arrives(i, j));
                    scratch[i].fused = combine_convex(arrived.map(|j| (row[j], &scratch[j].post)))?;
                }
            }
        }
        Fusion::Consensus { iterations } => {
            // Round t reads the pairs of round t − 1 (the local posteriors for
            // t = 0) and writes `cons[t % 2]`.
            for t in 0..iterations {
                let dst = t % 2;
                for i in 0..k {
                    if !active(i) {
                        continue;
                    }
                    let row = &weights[i * k..(i + 1) * k];
                    let mut acc = Accumulator::new();
                    for j in rows.row(i) {
                        if arrives(i, j) {
                            let pair = match t {
                                0 => &scratch[j].out.local.posterior,
                                _ => &scratch[j].cons[1 - dst],
                            };
                            // The weights and the links are those of every
                            // iteration: checked in the first one.
                            if t == 0 {
                                check_weight(row[j])?;
                            }
                            acc.add(row[j], pair);
                        }
                    }
                    let pair = if t == 0 {
                        acc.finish()?
                    } else {
                        acc.finish_unchecked()
                    };
                    // Every round's pair, not only the last one's (which
                    // `to_gaussian` checks): an overflow is named where it
                    // happens instead of feeding NaN or ±∞ to the next round.
                    check_combined(&pair.y, &pair.ymat)?;
                    scratch[i].cons[dst] = pair;
                }
            }
            let last = (iterations - 1) % 2;
            for i in 0..k {
                if !active(i) {
                    continue;
                }
                let s = &mut scratch[i];
                s.cons[last].write_gaussian(&mut s.fused)?;
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

/// Calls `f` with the active nodes in ascending order, [`LANES`] at a time
/// (the last group may be shorter); stops at the first `Ok(false)` or error.
/// `Ok(true)` when every group returned `Ok(true)`.
fn for_each_group(
    k: usize,
    active: impl Fn(usize) -> bool,
    mut f: impl FnMut(&[usize]) -> Result<bool>,
) -> Result<bool> {
    let mut group = [0usize; LANES];
    let mut used = 0;
    for i in (0..k).filter(|&i| active(i)) {
        group[used] = i;
        used += 1;
        if used == LANES {
            if !f(&group)? {
                return Ok(false);
            }
            used = 0;
        }
    }
    if used > 0 {
        return f(&group[..used]);
    }
    Ok(true)
}

/// [`prefactor_lanes`] for every active node, [`LANES`] at a time. Not
/// inlined: the step's other phases keep the code they have without it.
#[inline(never)]
fn prefactor<T: RealField + Copy, const N: usize, const M: usize>(
    k: usize,
    active: &impl Fn(usize) -> bool,
    nodes: &[NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
) {
    // `prefactor_lanes` cannot fail.
    let _ = for_each_group(k, active, |group| {
        prefactor_lanes(group, nodes, scratch);
        Ok(true)
    });
}

/// The lower Cholesky factors of the estimates' covariances of the nodes in
/// `group` through [`lanes::cholesky_in_place`] (each lane the factor of the
/// scalar [`cholesky`](crate::linalg::cholesky) bit for bit), written into
/// their scratch with a zero strict upper triangle, as
/// [`Cholesky::l`](nalgebra::Cholesky::l) gives it. A node whose `P` has a
/// non-finite entry or whose factorisation fails gets none (`factored` false):
/// its prediction factorises `P` itself and names the error.
fn prefactor_lanes<T: RealField + Copy, const N: usize, const M: usize>(
    group: &[usize],
    nodes: &[NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
) {
    let mut m = lanes::zeros::<T, N>();
    lanes::pad(&mut m, group.len());
    for (l, &i) in group.iter().enumerate() {
        let p = &nodes[i].estimate.p;
        for (j, col) in m.iter_mut().enumerate() {
            for (r, e) in col.iter_mut().enumerate().skip(j) {
                e[l] = p[(r, j)];
            }
        }
    }
    let ok = lanes::cholesky_in_place(&mut m);
    for (l, &i) in group.iter().enumerate() {
        let s = &mut scratch[i];
        s.factored = ok[l] && all_finite(&nodes[i].estimate.p);
        if s.factored {
            for (j, col) in m.iter().enumerate() {
                for (r, v) in col.iter().enumerate() {
                    s.factor[(r, j)] = if r >= j { v[l] } else { T::zero() };
                }
            }
        }
    }
}

/// Loads pair `p` into lane `l` (the vector and the lower triangle).
#[inline(always)]
fn load_lane<T: RealField + Copy, const N: usize>(
    y: &mut VecL<T, N>,
    ymat: &mut MatL<T, N>,
    l: usize,
    p: &InfoPair<T, N>,
) {
    for (j, col) in ymat.iter_mut().enumerate() {
        y[j][l] = p.y[j];
        for (i, e) in col.iter_mut().enumerate().skip(j) {
            e[l] = p.ymat[(i, j)];
        }
    }
}

/// Lane `l`'s estimate into `g` (`P` only when `p` is given).
#[inline(always)]
fn store_lane<T: RealField + Copy, const N: usize>(
    x: &VecL<T, N>,
    p: Option<&MatL<T, N>>,
    l: usize,
    g: &mut Gaussian<T, N>,
) {
    for (i, v) in x.iter().enumerate() {
        g.x[i] = v[l];
    }
    if let Some(p) = p {
        for (j, col) in p.iter().enumerate() {
            for (i, v) in col.iter().enumerate() {
                g.p[(i, j)] = v[l];
            }
        }
    }
}

/// The adapted estimates of the nodes in `group` ([`adapt_estimate`] on each
/// node's adapted pair) through the lane kernels, written into their `post`;
/// per lane, whether it was formed. A lane is not formed where the scalar
/// [`adapt_estimate`] fails (a failed factorisation, a non-finite estimate) or
/// takes its slow path (a covariance it factorises to check): the caller runs
/// the scalar path there, which forms the estimate or fires the guard.
fn adapt_estimates_lanes<T: RealField + Copy, const N: usize, const M: usize>(
    ci: bool,
    group: &[usize],
    scratch: &mut [NodeScratch<T, N, M>],
) -> [bool; LANES] {
    let mut y = [lanes::splat(T::zero()); N];
    let mut ymat = lanes::zeros::<T, N>();
    lanes::pad(&mut ymat, group.len());
    for (l, &i) in group.iter().enumerate() {
        load_lane(&mut y, &mut ymat, l, &scratch[i].adapted);
    }
    let mut p = None;
    let ok = if ci {
        // Under CI only `x = Y⁻¹ŷ` (see `NodeScratch::post`).
        let ok = lanes::cholesky_in_place(&mut ymat);
        lanes::chol_solve(&ymat, &mut y);
        lanes::finite(ok, y.iter())
    } else {
        let pm = p.insert(lanes::zeros::<T, N>());
        lanes::to_gaussians(&mut y, &ymat, pm)
    };
    for (l, &i) in group.iter().enumerate() {
        if ok[l] {
            store_lane(&y, p.as_ref(), l, &mut scratch[i].post);
        }
    }
    ok
}

/// A node's adapted estimate node by node, the guard included; whether the
/// guard fired.
#[inline(never)]
fn adapt_scalar<T: RealField + Copy, const N: usize, const M: usize>(
    ci: bool,
    s: &mut NodeScratch<T, N, M>,
) -> Result<bool> {
    if adapt_estimate(&s.adapted, ci, &mut s.post).is_some() {
        return Ok(false);
    }
    // The local step left the CIF's local posterior unformed under
    // diffusion: only the guard needs it.
    let l = &mut s.out.local;
    l.posterior = l.prior.updated(&l.contribution);
    adapt_guard(&l.posterior, &mut s.post)?;
    s.adapted = l.posterior;
    Ok(true)
}

/// The CI combinations of the nodes in `group` (as in the node-by-node loop:
/// the weighted sum of the arrived adapted pairs, converted with
/// [`InfoPair::write_gaussian`]) through the lane kernels, written into their
/// `fused`. False when any of them is not formed: a weight or a total the loop
/// rejects, or a pair whose conversion the lanes decline; the caller then runs
/// the node-by-node loop for every node.
fn combine_ci_lanes<T, R, const N: usize, const M: usize>(
    weights: &[T],
    rows: &R,
    k: usize,
    arrives: &impl Fn(usize, usize) -> bool,
    group: &[usize],
    scratch: &mut [NodeScratch<T, N, M>],
) -> bool
where
    T: RealField + Copy,
    R: Rows,
{
    let mut y = [lanes::splat(T::zero()); N];
    let mut ymat = lanes::zeros::<T, N>();
    lanes::pad(&mut ymat, group.len());
    for (l, &i) in group.iter().enumerate() {
        let row = &weights[i * k..(i + 1) * k];
        let mut acc = Accumulator::new();
        for j in rows.row(i) {
            if arrives(i, j) {
                if check_weight(row[j]).is_err() {
                    return false;
                }
                acc.add(row[j], &scratch[j].adapted);
            }
        }
        let Ok(pair) = acc.finish() else {
            return false;
        };
        load_lane(&mut y, &mut ymat, l, &pair);
    }
    let mut p = lanes::zeros::<T, N>();
    let ok = lanes::to_gaussians(&mut y, &ymat, &mut p);
    if !ok[..group.len()].iter().all(|&o| o) {
        return false;
    }
    for (l, &i) in group.iter().enumerate() {
        store_lane(&y, Some(&p), l, &mut scratch[i].fused);
    }
    true
}

/// Node i's combination under a rule other than the paper's CI
/// ([`combine_node`]): the arrived adapted pairs with their weights, and for
/// split CI the contributions each adapted pair holds (its node's own, and
/// the arrived ones unless the adaptation guard fired there).
fn combine_rule_at<T, R, const N: usize, const M: usize>(
    rule: FusionRule,
    i: usize,
    weights: &[T],
    rows: &R,
    k: usize,
    arrives: &impl Fn(usize, usize) -> bool,
    scratch: &[NodeScratch<T, N, M>],
) -> Result<Gaussian<T, N>>
where
    T: RealField + Copy,
    R: Rows,
{
    let row = &weights[i * k..(i + 1) * k];
    let inputs = rows
        .row(i)
        .filter(move |&j| arrives(i, j))
        .map(move |j| (j, row[j], &scratch[j].adapted));
    let includes = move |j: usize, m: usize| {
        m == j || (!scratch[j].guard_used && arrives(j, m) && rows.row(j).any(|x| x == m))
    };
    let own = rows
        .row(i)
        .filter(move |&m| includes(i, m))
        .map(move |m| (m, &scratch[m].out.local.contribution));
    combine_node(rule, inputs, own, includes)
}
