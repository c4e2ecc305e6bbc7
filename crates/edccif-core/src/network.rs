//! A whole synchronous network step on borrowed slices: every node's local
//! filter, then the fusion of the chosen algorithm row (`docs/algorithm.md`
//! §4, §5), as a loop over the phase functions of [`node`](crate::node). The
//! caller owns all buffers (fixed-size arrays on a vehicle, vectors allocated
//! once in a simulator); the step allocates nothing.
//!
//! [`network_step`] (and [`network_step_sparse`] over neighbour lists) is the
//! loop: the factors of the estimates' covariances `LANES` nodes at a time,
//! each node's [local phase](crate::node::node_local_into), the fusion phases
//! of every node ([`network_fusion`], which also counts the [`StepReport`]),
//! and the commit. A loop of one's own over nodes with different sensors runs
//! its local phases and then [`network_fusion`] (see the
//! [`node`](crate::node) module).
//!
//! A failed step returns the error and leaves every [`NodeState`] as it was.

use core::ops::{Deref, DerefMut};

use nalgebra::RealField;

pub use crate::config::{Fusion, NetworkConfig, NodeFilter};
use crate::error::{Error, Result};
use crate::fusion::{combine_convex, combine_information_symmetric};
use crate::fusion_rules::FusionRule;
use crate::lanes::LANES;
use crate::linalg::validate_positive;
use crate::message::Observation;
use crate::model::{MeasurementModel, MotionModel};
pub use crate::node::NodeState;
use crate::node::{
    adapt_estimates_lanes, adapt_finish, adapt_sum, combine_ci, combine_ci_lanes, combine_rule,
    consensus_round_all, local_phase, prefactor_lanes, AsPhase, PhaseScratch,
};
use crate::trigger::{Trigger, TriggerState};

/// Per-node working memory of a [`network_step`]: the node's [`PhaseScratch`],
/// which it dereferences to (`post`, `fused`, `triggered`, `guard_used`,
/// `gated`, [`prior`](PhaseScratch::prior), [`local`](PhaseScratch::local), …),
/// and the sensor's new trigger memory, committed with the fused estimate.
/// After a successful step it holds the step's intermediate results for
/// inspection and logging.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeScratch<T: RealField + Copy, const N: usize, const M: usize> {
    phase: PhaseScratch<T, N>,
    trigger: TriggerState<T, M>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> Default for NodeScratch<T, N, M> {
    fn default() -> Self {
        Self {
            phase: PhaseScratch::default(),
            trigger: TriggerState {
                last_sent: None,
                eta: T::zero(),
                rng: 0,
            },
        }
    }
}

impl<T: RealField + Copy, const N: usize, const M: usize> Deref for NodeScratch<T, N, M> {
    type Target = PhaseScratch<T, N>;
    fn deref(&self) -> &PhaseScratch<T, N> {
        &self.phase
    }
}

impl<T: RealField + Copy, const N: usize, const M: usize> DerefMut for NodeScratch<T, N, M> {
    fn deref_mut(&mut self) -> &mut PhaseScratch<T, N> {
        &mut self.phase
    }
}

impl<T: RealField + Copy, const N: usize, const M: usize> AsRef<PhaseScratch<T, N>>
    for NodeScratch<T, N, M>
{
    fn as_ref(&self) -> &PhaseScratch<T, N> {
        &self.phase
    }
}

impl<T: RealField + Copy, const N: usize, const M: usize> AsMut<PhaseScratch<T, N>>
    for NodeScratch<T, N, M>
{
    fn as_mut(&mut self) -> &mut PhaseScratch<T, N> {
        &mut self.phase
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
    /// messages this step (`None`: every message arrives). Memory O(k²):
    /// [`Self::edge_links`] is the same mask per listed edge.
    pub links: Option<&'a [bool]>,
    /// The link mask per entry of the graph's neighbour lists
    /// ([`LinkMask::Edges`]): memory O(nodes + edges). Only for the steps over
    /// lists ([`network_step_sparse`], [`network_step_weighted`]), and not
    /// together with [`Self::links`] (both are errors).
    pub edge_links: Option<&'a [bool]>,
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
            edge_links: None,
            active: None,
            deltas: None,
        }
    }

    /// The same inputs with a link mask ([`LinkMask::Dense`] sets
    /// [`Self::links`], [`LinkMask::Edges`] [`Self::edge_links`]).
    ///
    /// ```
    /// use edccif_core::{LinkMask, Observation, StepInputs};
    /// use nalgebra::Vector3;
    /// let obs = [Observation::Measured(Vector3::new(1.0, 0.0, 0.0)); 2];
    /// // two nodes that hear each other: lists [0, 1] and [0, 1]; node 0 misses node 1
    /// let edges = [true, false, true, true];
    /// let inputs = StepInputs::new(&obs, 0.1).with_links(LinkMask::Edges(&edges));
    /// assert_eq!(inputs.edge_links, Some(&edges[..]));
    /// assert_eq!(inputs.link_mask()?, Some(LinkMask::Edges(&edges)));
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    pub fn with_links(self, mask: LinkMask<'a>) -> Self {
        match mask {
            LinkMask::Dense(l) => Self {
                links: Some(l),
                edge_links: None,
                ..self
            },
            LinkMask::Edges(l) => Self {
                links: None,
                edge_links: Some(l),
                ..self
            },
        }
    }

    /// The step's link mask: [`Self::links`] or [`Self::edge_links`] (`None`:
    /// every message arrives); an error when both are set.
    pub fn link_mask(&self) -> Result<Option<LinkMask<'a>>> {
        match (self.links, self.edge_links) {
            (Some(_), Some(_)) => Err(Error::InvalidParameter {
                what: "link masks",
                expected: "at most one of links (nodes × nodes) and edge_links (per list entry)",
            }),
            (Some(l), None) => Ok(Some(LinkMask::Dense(l))),
            (None, Some(l)) => Ok(Some(LinkMask::Edges(l))),
            (None, None) => Ok(None),
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

/// Which estimator messages arrive in a step, as a dense matrix or per edge of
/// the graph's neighbour lists. For a graph of `k` nodes whose lists
/// ([`Neighbours`]) hold `e` entries (every node and its neighbours), the two
/// forms say the same with `k²` and `e` booleans.
///
/// ```
/// use edccif_core::{LinkMask, Neighbours};
/// // a path 0 - 1 - 2: lists [0, 1], [0, 1, 2], [1, 2]
/// let (offsets, indices) = ([0, 2, 5, 7], [0, 1, 0, 1, 2, 1, 2]);
/// let nb = Neighbours::new(&offsets, &indices)?;
/// // node 1 does not hear node 2 this step
/// let dense = [true, true, false, true, true, false, false, true, true];
/// let edges = [true, true, true, true, false, true, true];
/// assert!(!LinkMask::Dense(&dense).hears(&nb, 1, 2)?);
/// assert!(!LinkMask::Edges(&edges).hears(&nb, 1, 2)?);
/// // 0 and 2 are not neighbours: an edge mask has no entry for them
/// assert!(LinkMask::Edges(&edges).hears(&nb, 0, 2).is_err());
/// assert!(LinkMask::Dense(&dense[..4]).hears(&nb, 1, 2).is_err());
/// let mut out = [false; 7];
/// LinkMask::dense_to_edges(&dense, &nb, &mut out)?;
/// assert_eq!(out, edges);
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkMask<'a> {
    /// `k × k` row-major: `[i*k + j]` is true when node i receives node j's
    /// messages.
    Dense(&'a [bool]),
    /// One entry per entry of the closed neighbourhood lists
    /// ([`Neighbours`], node i's list at [`Neighbours::offset`]`(i)`):
    /// `[offset(i) + e]` is true when node i receives the messages of the
    /// `e`-th node of its list. Node i's own entry is not read (a node always
    /// has its own estimate).
    Edges(&'a [bool]),
}

impl LinkMask<'_> {
    /// Whether node i receives node j's messages (`j == i`: true). Errors
    /// (never panics) when i or j is not a node of `lists`, when the mask is
    /// shorter than `lists` needs, or, for an edge mask, when j is not in node
    /// i's list.
    pub fn hears(&self, lists: &Neighbours<'_>, i: usize, j: usize) -> Result<bool> {
        let k = lists.nodes();
        if i >= k || j >= k {
            return Err(Error::InvalidParameter {
                what: "link mask node",
                expected: "i and j below the number of nodes of the lists",
            });
        }
        if i == j {
            return Ok(true);
        }
        match *self {
            LinkMask::Dense(l) => {
                check_len("link mask (nodes × nodes)", k * k, l.len())?;
                Ok(l[i * k + j])
            }
            LinkMask::Edges(l) => {
                check_len("edge link mask (one per list entry)", lists.len(), l.len())?;
                let e = lists
                    .row(i)
                    .binary_search(&j)
                    .map_err(|_| Error::InvalidParameter {
                        what: "edge link mask",
                        expected: "j in node i's neighbour list",
                    })?;
                Ok(l[lists.offset(i) + e])
            }
        }
    }

    /// Writes the edge mask of the dense `k × k` mask `dense` over `lists`
    /// into `out` (one entry per list entry). Errors when the lengths do not
    /// match.
    pub fn dense_to_edges(dense: &[bool], lists: &Neighbours<'_>, out: &mut [bool]) -> Result<()> {
        let k = lists.nodes();
        check_len("link mask (nodes × nodes)", k * k, dense.len())?;
        check_len(
            "edge link mask (one per list entry)",
            lists.len(),
            out.len(),
        )?;
        for i in 0..k {
            let a = lists.offset(i);
            for (e, &j) in lists.row(i).iter().enumerate() {
                out[a + e] = dense[i * k + j];
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
    /// local-only posterior (`docs/algorithm.md` §4).
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

    /// Where node i's list starts in the indices (`offsets[i]`).
    #[inline(always)]
    pub fn offset(&self, i: usize) -> usize {
        self.offsets[i]
    }

    /// Length of the indices (the closed neighbourhoods' sizes summed).
    pub fn len(&self) -> usize {
        self.indices.len()
    }

    /// Whether there are no lists (no nodes).
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
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
    /// The lists (`None`: the rows are scanned).
    fn lists(&self) -> Option<Neighbours<'_>>;
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
    fn lists(&self) -> Option<Neighbours<'_>> {
        None
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
    fn lists(&self) -> Option<Neighbours<'_>> {
        Some(*self)
    }
}

/// Every node's closed neighbourhood ([`Neighbours`]) with the combination
/// weight of each listed pair: `weights[e]` is `c_ij` for the `e`-th entry of
/// the lists (node i's are `weights[offset(i)..offset(i+1)]`, its own `c_ii`
/// among them). Memory is O(nodes + edges), where a `k × k` matrix is O(k²):
/// [`network_step_weighted`] steps a large sparse network with it.
///
/// ```
/// use edccif_core::{NeighbourWeights, Neighbours};
/// // a path 0 - 1 - 2 with max-degree weights
/// let (offsets, indices) = ([0, 2, 5, 7], [0, 1, 0, 1, 2, 1, 2]);
/// let third = 1.0 / 3.0;
/// let w = [2.0 * third, third, third, third, third, third, 2.0 * third];
/// let g = NeighbourWeights::new(Neighbours::new(&offsets, &indices)?, &w)?;
/// assert_eq!(g.weight(1, 2), Some(third));
/// assert_eq!(g.weight(0, 2), None);
/// // a listed neighbour needs a positive weight
/// let bad = [1.0, 0.0, third, third, third, third, 2.0 * third];
/// assert!(NeighbourWeights::new(Neighbours::new(&offsets, &indices)?, &bad).is_err());
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeighbourWeights<'a, T> {
    neighbours: Neighbours<'a>,
    weights: &'a [T],
}

impl<'a, T: RealField + Copy> NeighbourWeights<'a, T> {
    /// The lists with one weight per entry. Errors when the lengths differ or
    /// a listed neighbour `j ≠ i` has a weight that is not positive.
    pub fn new(neighbours: Neighbours<'a>, weights: &'a [T]) -> Result<Self> {
        check_len(
            "neighbour weights (one per neighbour list entry)",
            neighbours.len(),
            weights.len(),
        )?;
        for i in 0..neighbours.nodes() {
            let a = neighbours.offset(i);
            for (e, &j) in neighbours.row(i).iter().enumerate() {
                if j != i && !(weights[a + e] > T::zero()) {
                    return Err(Error::InvalidParameter {
                        what: "neighbour weights",
                        expected: "a positive weight for every listed neighbour j of node i",
                    });
                }
            }
        }
        Ok(Self {
            neighbours,
            weights,
        })
    }

    /// The lists.
    pub fn neighbours(&self) -> &Neighbours<'a> {
        &self.neighbours
    }

    /// `c_ij` when j is in node i's list, else `None`.
    #[inline(always)]
    pub fn weight(&self, i: usize, j: usize) -> Option<T> {
        let row = self.neighbours.row(i);
        let e = row.binary_search(&j).ok()?;
        Some(self.weights[self.neighbours.offset(i) + e])
    }
}

/// The neighbourhoods and weights a step reads: a `k × k` matrix (with its
/// rows scanned or listed), or [`NeighbourWeights`].
trait Graph<T> {
    /// Checks the graph against `k` nodes (the weight matrix's length first).
    fn check(&self, k: usize) -> Result<()>;
    /// Node i's closed neighbourhood, ascending.
    fn row(&self, i: usize) -> impl Iterator<Item = usize> + Clone + '_;
    /// `c_ij` for j in node i's closed neighbourhood.
    fn weight(&self, i: usize, j: usize) -> T;
    /// The lists the rows come from (`None`: scanned from a matrix).
    fn lists(&self) -> Option<Neighbours<'_>>;
}

/// A `k × k` row-major weight matrix with the rows `R` give.
struct Matrix<'a, T, R> {
    weights: &'a [T],
    k: usize,
    rows: &'a R,
}

impl<T: RealField + Copy, R: Rows> Graph<T> for Matrix<'_, T, R> {
    fn check(&self, k: usize) -> Result<()> {
        check_len("weight matrix (nodes × nodes)", k * k, self.weights.len())?;
        self.rows.check(self.weights, k)
    }
    #[inline(always)]
    fn row(&self, i: usize) -> impl Iterator<Item = usize> + Clone + '_ {
        self.rows.row(i)
    }
    #[inline(always)]
    fn weight(&self, i: usize, j: usize) -> T {
        self.weights[i * self.k + j]
    }
    fn lists(&self) -> Option<Neighbours<'_>> {
        self.rows.lists()
    }
}

impl<T: RealField + Copy> Graph<T> for NeighbourWeights<'_, T> {
    fn check(&self, k: usize) -> Result<()> {
        check_len("neighbour lists (nodes)", k, self.neighbours.nodes())
    }
    #[inline(always)]
    fn row(&self, i: usize) -> impl Iterator<Item = usize> + Clone + '_ {
        self.neighbours.row(i).iter().copied()
    }
    #[inline(always)]
    fn weight(&self, i: usize, j: usize) -> T {
        // Only called for listed neighbours.
        NeighbourWeights::weight(self, i, j).unwrap_or(T::zero())
    }
    fn lists(&self) -> Option<Neighbours<'_>> {
        Some(self.neighbours)
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
    let k = nodes.len();
    let rows = Dense { weights, k };
    let graph = Matrix {
        weights,
        k,
        rows: &rows,
    };
    step_impl(cfg, motion, sensors, &graph, nodes, scratch, inputs)
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
    let graph = Matrix {
        weights,
        k: nodes.len(),
        rows: neighbours,
    };
    step_impl(cfg, motion, sensors, &graph, nodes, scratch, inputs)
}

/// [`network_step_sparse`] with the weights kept per listed pair
/// ([`NeighbourWeights`]) instead of a `k × k` matrix: memory O(nodes +
/// edges), for networks too large for a dense matrix. With the lists and
/// weights of a matrix, the result is bit for bit that of [`network_step`].
///
/// Errors as [`network_step`], and when the lists are not for `k` nodes.
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
/// // both nodes hear each other: every entry of the matrix is listed
/// let (offsets, indices) = ([0, 2, 4], [0, 1, 0, 1]);
/// let g = NeighbourWeights::new(Neighbours::new(&offsets, &indices)?, &w)?;
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
/// network_step_weighted(&cfg, &motion, &sensors, &g, &mut b, &mut scratch, &inputs)?;
/// assert_eq!(a, b);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn network_step_weighted<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    sensors: &[H],
    graph: &NeighbourWeights<'_, T>,
    nodes: &mut [NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
    inputs: &StepInputs<'_, T, M>,
) -> Result<StepReport>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M>,
{
    step_impl(cfg, motion, sensors, graph, nodes, scratch, inputs)
}

// Index loops: `active(i)` and the neighbour filters are indexed by node too.
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
fn step_impl<T, F, H, G, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    sensors: &[H],
    graph: &G,
    nodes: &mut [NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
    inputs: &StepInputs<'_, T, M>,
) -> Result<StepReport>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M>,
    G: Graph<T>,
{
    // A configuration that `validate` rejects (e.g. diffusion with a
    // covariance-form filter, whose nodes have no information contributions)
    // must not run silently.
    cfg.validate()?;
    validate_positive(inputs.dt, "time step dt", false)?;
    let k = nodes.len();
    check_len("sensors", k, sensors.len())?;
    graph.check(k)?;
    check_len("scratch buffers", k, scratch.len())?;
    check_len("observations", k, inputs.observations.len())?;
    let links = Links::new(k, inputs.link_mask()?, inputs.active, graph.lists())?;
    inputs.check_deltas(&cfg.trigger, k)?;

    // 1. Local phase: the factors of the estimates' `P` (every local filter
    // starts with one), `LANES` nodes at a time, then each node's step from
    // its factor (a node whose factor the lanes decline factorises in its
    // step and names the error).
    prefactor(k, &links, nodes, scratch);
    for i in 0..k {
        let s = &mut scratch[i];
        if !links.active(i) {
            s.triggered = None;
            s.guard_used = false;
            s.gated = false;
            continue;
        }
        let trigger = inputs.trigger(&cfg.trigger, i)?;
        let trigger = local_phase(
            cfg,
            &trigger,
            motion,
            inputs.dt,
            &sensors[i],
            &nodes[i],
            &inputs.observations[i],
            &mut s.phase,
        )?;
        s.trigger = trigger;
    }

    // 2. Fusion phases.
    let report = fuse(cfg.fusion, cfg.rule, graph, &links, scratch)?;

    // 3. Commit.
    for i in 0..k {
        if links.active(i) {
            let s = &scratch[i];
            nodes[i].commit(s.fused, s.trigger);
        }
    }
    Ok(report)
}

/// The fusion phases of one synchronous step over every node's
/// [`PhaseScratch`], after the local phase filled those of the active nodes
/// ([`node_local_into`](crate::node::node_local_into)): the adaptation and the
/// combination (the diffusion rows), the consensus rounds, or the local
/// posterior as the fused estimate (no fusion), each node's result in its
/// [`fused`](PhaseScratch::fused). Returns the step's [`StepReport`], counted
/// from the scratches' flags. The caller commits the fused estimates (and the
/// sensors' trigger memories); on error the scratches may hold partial
/// results.
///
/// `scratch` holds one entry per node, a [`PhaseScratch`] or anything that
/// holds one (a [`NodeScratch`]); `weights` is the `k × k` row-major
/// combination matrix, `neighbours` its lists when the caller keeps them
/// ([`network_step_sparse`]; `None`: read off `weights`), `links` and `active`
/// the masks of [`StepInputs`]; `fusion` and `rule` as in [`NetworkConfig`]
/// (a rule other than [`FusionRule::CI`] only with [`Fusion::DiffusionCi`]).
/// This is the fusion part of [`network_step`],
/// bit for bit; the nodes' sensors may differ in kind and measurement
/// dimension, as the fusion phases see the state only.
///
/// Errors: a length that does not match the number of nodes, neighbour lists
/// as in [`network_step_sparse`], a node whose local phase was for another
/// fusion, a rule other than CI without [`Fusion::DiffusionCi`], and the
/// fusion phases' errors.
///
/// ```
/// use edccif_core::fusion::max_degree_weights;
/// use edccif_core::models::{LinearMeasurement, LinearMotion, Position3};
/// use edccif_core::network::network_fusion;
/// use edccif_core::node::{node_local_into, PhaseScratch};
/// use edccif_core::*;
/// use nalgebra::{Matrix1, SMatrix, SVector, Vector1, Vector3};
///
/// // Node 0 measures the position (3 values), node 1 the height only (1 value).
/// let motion = LinearMotion::new(
///     SMatrix::<f64, 4, 4>::identity(), SMatrix::<f64, 4, 4>::identity() * 1e-3)?;
/// let position = Position3::new([0.1; 3])?;
/// let mut hz = SMatrix::<f64, 1, 4>::zeros();
/// hz[(0, 2)] = 1.0;
/// let height = LinearMeasurement::new(hz, Matrix1::new(0.01))?;
/// let mut w = [0.0; 4];
/// max_degree_weights(&[false, true, true, false], 2, &mut w)?;
/// let cfg = NetworkConfig { filter: NodeFilter::Cif, trigger: Trigger::SendOnDelta { delta: 0.04 },
///                           et: EtOptions::default(), fusion: Fusion::DiffusionCi,
///                           rule: FusionRule::CI };
/// let start = Gaussian::new(SVector::<f64, 4>::zeros(), SMatrix::<f64, 4, 4>::identity())?;
/// let mut n0 = NodeState::<f64, 4, 3>::new(start, &cfg.trigger);
/// let mut n1 = NodeState::<f64, 4, 1>::new(start, &cfg.trigger);
/// let mut scratch = [PhaseScratch::default(); 2];
/// let z0 = Observation::Measured(Vector3::new(1.0, 0.0, 0.5));
/// let z1 = Observation::Measured(Vector1::new(0.5));
/// let t0 = node_local_into(&cfg, &motion, 0.1, &position, &n0, &z0, &mut scratch[0])?;
/// let t1 = node_local_into(&cfg, &motion, 0.1, &height, &n1, &z1, &mut scratch[1])?;
/// let report = network_fusion(cfg.fusion, cfg.rule, &w, None, None, None, &mut scratch)?;
/// assert_eq!(report.triggered, 2);
/// // The commit.
/// (n0.estimate, n0.trigger) = (scratch[0].fused, t0);
/// (n1.estimate, n1.trigger) = (scratch[1].fused, t1);
/// assert!((n1.estimate.x[0] - 0.9).abs() < 0.1); // x, which only node 0 measures
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn network_fusion<T, S, const N: usize>(
    fusion: Fusion,
    rule: FusionRule,
    weights: &[T],
    neighbours: Option<&Neighbours<'_>>,
    links: Option<&[bool]>,
    active: Option<&[bool]>,
    scratch: &mut [S],
) -> Result<StepReport>
where
    T: RealField + Copy,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
{
    if !rule.is_paper() && fusion != Fusion::DiffusionCi {
        return Err(Error::InvalidParameter {
            what: "fusion rule",
            expected:
                "ci unless the fusion is diffusion with CI (the rules replace its combination)",
        });
    }
    let k = scratch.len();
    let dense = Dense { weights, k };
    let graph_of = |rows| Matrix { weights, k, rows };
    match neighbours {
        Some(nb) => graph_of(nb).check(k)?,
        None => check_len("weight matrix (nodes × nodes)", k * k, weights.len())?,
    }
    let links = Links::new(k, links.map(LinkMask::Dense), active, neighbours.copied())?;
    for (i, s) in scratch.iter().enumerate() {
        if links.active(i) && s.phase().local.fusion != fusion {
            return Err(Error::InvalidParameter {
                what: "local phase of a node",
                expected:
                    "the fusion of the step (run node_local_into with the same configuration)",
            });
        }
    }
    match neighbours {
        Some(nb) => fuse(fusion, rule, &graph_of(nb), &links, scratch),
        None => fuse(
            fusion,
            rule,
            &Matrix {
                weights,
                k,
                rows: &dense,
            },
            &links,
            scratch,
        ),
    }
}

/// Which nodes are up and whose messages arrive in a step: the masks of
/// [`StepInputs`], checked against the number of nodes (and an edge mask
/// against the graph's lists).
struct Links<'a> {
    k: usize,
    mask: Option<Mask<'a>>,
    active: Option<&'a [bool]>,
}

/// A checked link mask: dense, or per entry of the lists it is indexed by.
#[derive(Clone, Copy)]
enum Mask<'a> {
    Dense(&'a [bool]),
    Edges(&'a [bool], Neighbours<'a>),
}

impl<'a> Links<'a> {
    fn new(
        k: usize,
        links: Option<LinkMask<'a>>,
        active: Option<&'a [bool]>,
        lists: Option<Neighbours<'a>>,
    ) -> Result<Self> {
        let mask = match links {
            None => None,
            Some(LinkMask::Dense(l)) => {
                check_len("link mask (nodes × nodes)", k * k, l.len())?;
                Some(Mask::Dense(l))
            }
            Some(LinkMask::Edges(l)) => {
                let Some(nb) = lists else {
                    return Err(Error::InvalidParameter {
                        what: "edge link mask",
                        expected: "neighbour lists to index it (network_step_sparse, \
                                   network_step_weighted, or network_fusion with neighbours)",
                    });
                };
                check_len(
                    "edge link mask (one per neighbour list entry)",
                    nb.len(),
                    l.len(),
                )?;
                Some(Mask::Edges(l, nb))
            }
        };
        if let Some(a) = active {
            check_len("active mask", k, a.len())?;
        }
        Ok(Self { k, mask, active })
    }

    /// Whether node i is up.
    #[inline(always)]
    fn active(&self, i: usize) -> bool {
        self.active.is_none_or(|a| a[i])
    }

    /// The nodes of `row`, node i's closed neighbourhood (ascending, as the
    /// graph lists it), whose messages reach i (both up, link not lost), and
    /// i itself.
    #[inline(always)]
    fn heard<'s>(
        &'s self,
        i: usize,
        row: impl Iterator<Item = usize> + Clone + 's,
    ) -> impl Iterator<Item = usize> + Clone + 's {
        let masked = self.mask.is_some() || self.active.is_some();
        let base = match self.mask {
            Some(Mask::Edges(_, nb)) => nb.offset(i),
            _ => 0,
        };
        row.enumerate()
            .filter(move |&(e, j)| {
                j == i
                    || !masked
                    || (self.active(j)
                        && match self.mask {
                            None => true,
                            Some(Mask::Dense(l)) => l[i * self.k + j],
                            Some(Mask::Edges(l, _)) => l[base + e],
                        })
            })
            .map(|(_, j)| j)
    }
}

/// Node i's scratch, to write, and the others', to read (`None` when `i` is
/// not a node).
#[inline(always)]
fn split<S>(scratch: &mut [S], i: usize) -> Option<(&mut S, Others<'_, S>)> {
    let (before, rest) = scratch.split_at_mut(i);
    let (own, after) = rest.split_first_mut()?;
    Some((own, Others { before, after, i }))
}

/// Every node's scratch but one's.
struct Others<'a, S> {
    before: &'a [S],
    after: &'a [S],
    i: usize,
}

impl<S> Others<'_, S> {
    /// Node `j`'s scratch (`j ≠ i`).
    #[inline(always)]
    fn get(&self, j: usize) -> &S {
        if j < self.i {
            &self.before[j]
        } else {
            &self.after[j - self.i - 1]
        }
    }
}

/// The fusion phases of [`network_fusion`] for checked inputs. Every
/// combination sums over the closed neighbourhood in ascending index order,
/// the node's own term at its index: the order of the per-node phases with the
/// received packets in ascending sender order.
// Index loops: the masks and neighbour rows are indexed by node too.
#[allow(clippy::needless_range_loop)]
fn fuse<T, G, S, const N: usize>(
    fusion: Fusion,
    rule: FusionRule,
    graph: &G,
    links: &Links<'_>,
    scratch: &mut [S],
) -> Result<StepReport>
where
    T: RealField + Copy,
    G: Graph<T>,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
{
    let k = scratch.len();
    let mut report = StepReport::default();
    for i in 0..k {
        let s = scratch[i].phase();
        if links.active(i) {
            if let Some(g) = s.triggered {
                report.measured += 1;
                report.triggered += usize::from(g);
            }
            report.gated += usize::from(s.gated);
        }
    }
    // Node i's neighbours whose messages reach it, itself included, ascending.
    let heard = |i: usize| links.heard(i, graph.row(i));
    match fusion {
        Fusion::DiffusionCi | Fusion::DiffusionConvex => {
            let ci = fusion == Fusion::DiffusionCi;
            // Adaptation: the adapted sums (they cannot fail), then the
            // estimates `LANES` nodes at a time; a node whose lane the kernels
            // decline takes the per-node form (and the guard) in ascending
            // order, so that errors come as from a node-by-node loop.
            for i in 0..k {
                if !links.active(i) {
                    continue;
                }
                let Some((own, others)) = split(scratch, i) else {
                    continue;
                };
                let own = own.phase_mut();
                let received = heard(i)
                    .filter(|&j| j != i)
                    .map(|j| &others.get(j).phase().local.contribution);
                adapt_sum(&own.local, received, &mut own.adapted);
            }
            for_each_group(
                k,
                |i| links.active(i),
                |group| {
                    let ok = adapt_estimates_lanes(ci, group, scratch);
                    for (l, &i) in group.iter().enumerate() {
                        let s = scratch[i].phase_mut();
                        s.guard_used =
                            !ok[l] && adapt_finish(&s.local, &mut s.adapted, &mut s.post)?;
                        report.guard_fallbacks += usize::from(s.guard_used);
                    }
                    Ok(true)
                },
            )?;
            // Combination: under CI, the conversions `LANES` nodes at a time;
            // when any of them is declined, every node by the per-node form
            // (which names the error).
            let pair = |sc: &[S], i: usize| {
                combine_information_symmetric(
                    heard(i).map(|j| (graph.weight(i, j), &sc[j].phase().adapted)),
                )
            };
            // A rule other than the paper's CI replaces the CI combination
            // (node by node).
            let paper = rule.is_paper();
            let batched = ci
                && paper
                && for_each_group(
                    k,
                    |i| links.active(i),
                    |group| Ok(combine_ci_lanes(group, pair, scratch)),
                )?;
            for i in 0..k {
                if batched || !links.active(i) {
                    continue;
                }
                let row = |j: usize| graph.weight(i, j);
                let sc = &*scratch;
                let fused = if ci && !paper {
                    combine_rule(rule, i, row, heard, sc)?
                } else if ci {
                    combine_ci(heard(i).map(|j| (row(j), &sc[j].phase().adapted)))?
                } else {
                    combine_convex(heard(i).map(|j| (row(j), &sc[j].phase().post)))?
                };
                scratch[i].phase_mut().fused = fused;
            }
        }
        Fusion::Consensus { iterations } => consensus_rounds(iterations, graph, links, scratch)?,
        Fusion::Local => {
            for i in 0..k {
                if links.active(i) {
                    let s = scratch[i].phase_mut();
                    s.fused = s.local.posterior_estimate()?;
                }
            }
        }
    }
    Ok(report)
}

/// The consensus rounds of [`fuse`] (each one `consensus_round_all` of
/// [`node`](crate::node)), then each node's last pair in covariance form. Not
/// inlined, so that the rounds' code does not depend on the inlining of the
/// diffusion phases beside them.
#[inline(never)]
#[allow(clippy::needless_range_loop)]
fn consensus_rounds<T, G, S, const N: usize>(
    iterations: usize,
    graph: &G,
    links: &Links<'_>,
    scratch: &mut [S],
) -> Result<()>
where
    T: RealField + Copy,
    G: Graph<T>,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
{
    let k = scratch.len();
    for t in 0..iterations {
        consensus_round_all(
            t,
            |i, j| graph.weight(i, j),
            |i| links.active(i),
            |i| links.heard(i, graph.row(i)),
            scratch,
        )?;
    }
    let last = (iterations - 1) % 2;
    for i in 0..k {
        if links.active(i) {
            let PhaseScratch { cons, fused, .. } = scratch[i].phase_mut();
            cons[last].write_gaussian(fused)?;
        }
    }
    Ok(())
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

/// The factors phase ([`prefactor_lanes`]) for every active node, [`LANES`]
/// at a time. Not inlined: the step's other phases keep the code they have
/// without it.
#[inline(never)]
fn prefactor<T: RealField + Copy, const N: usize, const M: usize>(
    k: usize,
    links: &Links<'_>,
    nodes: &[NodeState<T, N, M>],
    scratch: &mut [NodeScratch<T, N, M>],
) {
    // The factors phase cannot fail.
    let _ = for_each_group(
        k,
        |i| links.active(i),
        |group| {
            prefactor_lanes(group, |i| &nodes[i].estimate, scratch);
            Ok(true)
        },
    );
}
