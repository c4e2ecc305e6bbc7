//! A parallel network step: the phases of [`network_step`] run over the nodes on
//! several threads (rayon), with the same numbers bit for bit.
//!
//! [`network_step`] computes what the per-node phases of [`edccif_core::node`]
//! compute (local step, adaptation, combination or consensus rounds, commit),
//! summing over each node's closed neighbourhood in ascending index order.
//! Inside a phase every node only reads what the previous phase produced, so the
//! nodes of a phase can run in any order on any number of threads:
//! [`ParallelStep::step`] runs each phase as a parallel loop over the nodes, with
//! a barrier between phases, calling the public phase functions with the
//! received packets in ascending sender order. The fused estimates, trigger
//! memories and report equal those of [`network_step`] bit for bit, and so do
//! the intermediate results it keeps per node ([`local`](ParallelStep::local),
//! [`adapted`](ParallelStep::adapted), [`post`](ParallelStep::post),
//! [`fused`](ParallelStep::fused)) and the corresponding [`NodeScratch`] values
//! (tested in `tests/suite/parallel.rs`).
//!
//! It pays off only for large networks: a phase costs a few microseconds per node,
//! and every phase (every consensus round) is one fork/join of the thread pool.
//! A phase is split into tasks of at least
//! [`with_min_nodes_per_task`](ParallelStep::with_min_nodes_per_task) nodes (8
//! by default, so a network of up to 8 nodes runs on one thread); stepping many
//! times in a row inside [`in_pool`](ParallelStep::in_pool) saves handing each
//! step to the pool and back. Node i's neighbours come from lists built once
//! from the weights.
//!
//! [`NodeScratch`]: edccif_core::NodeScratch
//!
//! ```
//! use edccif_core::{network_step, NodeScratch, NodeState, Observation, StepInputs, Gaussian};
//! use edccif_sim::parallel::ParallelStep;
//! use edccif_sim::{network_config, simulate, Algorithm, RunOptions, Scenario};
//! use nalgebra::{SMatrix, SVector};
//!
//! let sc = Scenario::paper(6);
//! let sim = simulate(&sc, 1).unwrap();
//! let cfg = network_config(Algorithm::EdcCif, &sc, &RunOptions::default()).unwrap();
//! let (motion, sensors, w) = (sc.coordinated_turn().unwrap(), sc.sensor_models().unwrap(), sc.weights().unwrap());
//! let p0 = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
//! let start = Gaussian::new(SVector::from_column_slice(&sim.x0_hat), p0).unwrap();
//! let mut serial = vec![NodeState::<f64, 7, 3>::new(start, &cfg.trigger); 6];
//! let mut parallel = serial.clone();
//! let mut scratch = vec![NodeScratch::default(); 6];
//! let mut par = ParallelStep::new(&w, 6).unwrap();
//! for z in sim.z.chunks(18).take(10) {
//!     let obs: Vec<Observation<f64, 3>> = z
//!         .chunks(3)
//!         .map(|r| Observation::Measured(SVector::from_column_slice(r)))
//!         .collect();
//!     let inputs = StepInputs::new(&obs, 0.1);
//!     network_step(&cfg, &motion, &sensors, &w, &mut serial, &mut scratch, &inputs).unwrap();
//!     par.step(&cfg, &motion, &sensors, &mut parallel, &inputs).unwrap();
//! }
//! assert_eq!(serial, parallel); // bit for bit
//! ```
//!
//! [`network_step`]: edccif_core::network_step

use std::sync::{Arc, Mutex, OnceLock};

use edccif_core::fusion_rules::combine_node;
use edccif_core::node::{
    node_adapt, node_combine_ci, node_combine_convex, node_consensus_round, node_local, LocalOutput,
};
use edccif_core::{
    Error as CoreError, Fusion, Gaussian, InfoPair, LinkMask, MeasurementModel, MotionModel,
    NetworkConfig, NodeState, StepInputs, StepReport,
};
use nalgebra::RealField;
use rayon::prelude::*;
use rayon::ThreadPool;

use crate::control::Control;
use crate::error::{Error, Result};

/// The default of [`ParallelStep::with_min_nodes_per_task`]: nodes per rayon
/// task at least. Below this a task costs more to schedule than the phase work
/// it carries (a consensus round is ~0.1–1 µs per node); a network of at most
/// this many nodes runs each phase as one task, on one thread.
pub const MIN_NODES_PER_TASK: usize = 8;

/// Checks a task granularity of the parallel step: at least 1 node per task.
/// The error names the option and what is expected.
///
/// ```
/// use edccif_sim::parallel::check_min_nodes_per_task;
/// assert!(check_min_nodes_per_task(1).is_ok() && check_min_nodes_per_task(4).is_ok());
/// let e = check_min_nodes_per_task(0).unwrap_err().to_string();
/// assert!(e.contains("min_nodes_per_task"), "{e}");
/// ```
pub fn check_min_nodes_per_task(n: usize) -> Result<()> {
    if n == 0 {
        Err(Error::Value {
            what: "min_nodes_per_task".into(),
            problem: "expected at least 1 node per rayon task of a phase (default 8), got 0".into(),
        })
    } else {
        Ok(())
    }
}

/// Checks a thread count of the network step: at least 1 (1 is the serial
/// step), at most [`max_threads`](crate::limits::max_threads). The error names
/// the option and what is expected.
///
/// ```
/// use edccif_sim::parallel::check_threads;
/// assert!(check_threads(1).is_ok() && check_threads(4).is_ok());
/// assert!(check_threads(0).unwrap_err().to_string().contains("threads"));
/// assert!(check_threads(100_000).unwrap_err().to_string().contains("per core"));
/// ```
pub fn check_threads(threads: usize) -> Result<()> {
    let max = crate::limits::max_threads();
    if (1..=max).contains(&threads) {
        Ok(())
    } else {
        Err(Error::Value {
            what: "threads".into(),
            problem: format!(
                "expected a thread count >= 1 (1: the serial step; n >= 2: the parallel step on n threads) and at most {max} ({} per core on this machine's {} cores), got {threads}",
                crate::limits::THREADS_PER_CORE,
                crate::limits::cores()
            ),
        })
    }
}

/// The thread pool of `threads` threads (`>= 1`) that every network stepping in
/// parallel with that count shares: built on first use and kept for the
/// process, so runs (and Monte Carlo runs) do not each start threads of their
/// own, and concurrent runs with the same count share its threads.
///
/// ```
/// use std::sync::Arc;
/// use edccif_sim::parallel::shared_pool;
/// let a = shared_pool(2).unwrap();
/// assert_eq!(a.current_num_threads(), 2);
/// assert!(Arc::ptr_eq(&a, &shared_pool(2).unwrap()));
/// assert!(shared_pool(0).is_err());
/// ```
pub fn shared_pool(threads: usize) -> Result<Arc<ThreadPool>> {
    check_threads(threads)?;
    type Pools = Mutex<Vec<(usize, Arc<ThreadPool>)>>;
    static POOLS: OnceLock<Pools> = OnceLock::new();
    // A panic while holding the lock cannot leave the list inconsistent.
    let mut pools = POOLS
        .get_or_init(Pools::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some((_, p)) = pools.iter().find(|(t, _)| *t == threads) {
        return Ok(Arc::clone(p));
    }
    let pool = Arc::new(build_pool(threads, "edccif-step")?);
    pools.push((threads, Arc::clone(&pool)));
    Ok(pool)
}

fn build_pool(threads: usize, name: &'static str) -> Result<ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(move |i| format!("{name}-{i}"))
        .build()
        .map_err(|e| Error::Value {
            what: "thread pool".into(),
            problem: format!("cannot start {threads} threads: {e}"),
        })
}

/// What happened at a node in the last step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NodeFlags {
    /// `Some(γ)` when a measurement was taken, `None` when missing or inactive.
    pub triggered: Option<bool>,
    /// Whether the adaptation guard fired (ALGORITHM.md §4).
    pub guard_used: bool,
    /// Whether the innovation gate rejected the measurement.
    pub gated: bool,
}

/// Buffers, neighbour lists and (optionally) a thread pool of the parallel
/// network step of `k` nodes. Built once; a step allocates nothing itself (the
/// rayon pool may).
#[derive(Debug, Clone)]
pub struct ParallelStep<T: RealField + Copy, const N: usize, const M: usize> {
    k: usize,
    graph: Graph<T>,
    phases: Phases<T, N, M>,
    pool: Option<Arc<ThreadPool>>,
    min_len: usize,
}

/// The network's neighbour lists and combination weights.
#[derive(Debug, Clone)]
struct Graph<T> {
    /// Node i's own combination weight `c_ii`.
    own_weight: Vec<T>,
    /// Node i's neighbours (without i) are `nbr[start[i]..start[i + 1]]`,
    /// ascending, with the weights `c_ij` in `nbr_weight` at the same places.
    start: Vec<usize>,
    nbr: Vec<usize>,
    nbr_weight: Vec<T>,
}

/// Per-node results of a step's phases (each phase reads the previous one's).
#[derive(Debug, Clone)]
struct Phases<T: RealField + Copy, const N: usize, const M: usize> {
    outs: Vec<Option<LocalOutput<T, N, M>>>,
    adapted: Vec<InfoPair<T, N>>,
    post: Vec<Gaussian<T, N>>,
    fused: Vec<Gaussian<T, N>>,
    flags: Vec<NodeFlags>,
    cons: [Vec<InfoPair<T, N>>; 2],
    errs: Vec<Option<CoreError>>,
}

/// Who hears whom in one step: the graph, the nodes that are up, the links
/// that did not fail; and the nodes per rayon task.
#[derive(Clone, Copy)]
struct Reach<'a, T> {
    k: usize,
    graph: &'a Graph<T>,
    links: Option<LinkMask<'a>>,
    active: Option<&'a [bool]>,
    min_len: usize,
}

impl<'a, T: RealField + Copy> Reach<'a, T> {
    /// Whether node i is up this step.
    #[inline]
    fn active(&self, i: usize) -> bool {
        self.active.is_none_or(|a| a[i])
    }

    /// The nodes whose messages reach node i: its neighbours (ascending) that
    /// are up and whose link did not fail. The `e`-th neighbour of node i is
    /// entry `start[i] + i + e + [j > i]` of the closed neighbourhood lists
    /// (node i's own entry among them).
    #[inline]
    fn heard(self, i: usize) -> impl Iterator<Item = usize> + Clone + 'a {
        let g = self.graph;
        g.nbr[g.start[i]..g.start[i + 1]]
            .iter()
            .copied()
            .enumerate()
            .filter(move |&(e, j)| {
                self.active(j)
                    && match self.links {
                        None => true,
                        Some(LinkMask::Dense(l)) => l[i * self.k + j],
                        Some(LinkMask::Edges(l)) => l[g.start[i] + i + e + usize::from(j > i)],
                    }
            })
            .map(|(_, j)| j)
    }

    /// `c_ij` for j = i or a neighbour of i.
    #[inline]
    fn w(&self, i: usize, j: usize) -> T {
        let g = self.graph;
        if i == j {
            return g.own_weight[i];
        }
        let row = &g.nbr[g.start[i]..g.start[i + 1]];
        row.binary_search(&j)
            .map_or(T::zero(), |e| g.nbr_weight[g.start[i] + e])
    }
}

impl<T, const N: usize, const M: usize> ParallelStep<T, N, M>
where
    T: RealField + Copy + Send + Sync,
{
    /// The parallel step of a `k`-node network with the row-major `k × k`
    /// combination weights `weights` (node j is a neighbour of node i when
    /// `weights[i*k + j] > 0`, `j ≠ i`, as in [`network_step`](edccif_core::network_step)).
    /// Runs on rayon's global thread pool (see [`with_threads`](Self::with_threads)).
    pub fn new(weights: &[T], k: usize) -> Result<Self> {
        if weights.len() != k * k {
            return Err(Error::Shape {
                what: "weights".into(),
                expected: format!("({k}, {k})"),
                got: format!("{} values", weights.len()),
            });
        }
        let mut offsets = Vec::with_capacity(k + 1);
        let (mut indices, mut values) = (Vec::new(), Vec::new());
        offsets.push(0);
        for i in 0..k {
            for j in (0..k).filter(|&j| j == i || weights[i * k + j] > T::zero()) {
                indices.push(j);
                values.push(weights[i * k + j]);
            }
            offsets.push(indices.len());
        }
        let nb = edccif_core::Neighbours::new(&offsets, &indices)?;
        Self::from_graph(&edccif_core::NeighbourWeights::new(nb, &values)?)
    }

    /// The parallel step of the network whose graph and combination weights
    /// are the neighbour lists `graph` (memory O(k + edges); e.g.
    /// [`NeighbourLists::core`](crate::topology::NeighbourLists::core)), the
    /// same numbers bit for bit as [`new`](Self::new) with the dense matrix.
    ///
    /// ```
    /// use edccif_sim::{parallel::ParallelStep, Scenario};
    /// let g = Scenario::paper(100_000).neighbours().unwrap();
    /// let par = ParallelStep::<f64, 7, 3>::from_graph(&g.core().unwrap()).unwrap();
    /// assert_eq!(par.nodes(), 100_000);
    /// ```
    pub fn from_graph(graph: &edccif_core::NeighbourWeights<'_, T>) -> Result<Self> {
        let lists = graph.neighbours();
        let k = lists.nodes();
        let mut start = Vec::with_capacity(k + 1);
        let (mut nbr, mut nbr_weight) = (Vec::new(), Vec::new());
        let mut own_weight = Vec::with_capacity(k);
        start.push(0);
        for i in 0..k {
            for &j in lists.row(i) {
                // Every listed j has a weight.
                let w = graph.weight(i, j).unwrap_or(T::zero());
                if j == i {
                    own_weight.push(w);
                } else {
                    nbr.push(j);
                    nbr_weight.push(w);
                }
            }
            start.push(nbr.len());
        }
        let g = Gaussian {
            x: nalgebra::SVector::zeros(),
            p: nalgebra::SMatrix::identity(),
        };
        Ok(Self {
            k,
            graph: Graph {
                own_weight,
                start,
                nbr,
                nbr_weight,
            },
            phases: Phases {
                outs: vec![None; k],
                adapted: vec![InfoPair::zeros(); k],
                post: vec![g; k],
                fused: vec![g; k],
                flags: vec![NodeFlags::default(); k],
                cons: [vec![InfoPair::zeros(); k], vec![InfoPair::zeros(); k]],
                errs: vec![None; k],
            },
            pool: None,
            min_len: MIN_NODES_PER_TASK,
        })
    }

    /// Runs the phases on a pool of its own with `threads` threads (`1`: one
    /// worker thread, for measuring the parallel code without parallelism)
    /// instead of rayon's global pool.
    pub fn with_threads(mut self, threads: usize) -> Result<Self> {
        self.pool = Some(Arc::new(build_pool(threads.max(1), "edccif-parallel")?));
        Ok(self)
    }

    /// Runs the phases on `pool` (e.g. a [`shared_pool`]) instead of rayon's
    /// global pool.
    pub fn with_pool(mut self, pool: Arc<ThreadPool>) -> Self {
        self.pool = Some(pool);
        self
    }

    /// Splits each phase into rayon tasks of at least `n` nodes (default
    /// [`MIN_NODES_PER_TASK`] = 8; `n >= 1`, else an error naming the option).
    /// With the default, a network of at most 8 nodes runs every phase as one
    /// task; `n = k / threads` (e.g. 4 for 8 nodes on 2 threads) gives each
    /// thread a share. The numbers do not depend on `n`, bit for bit.
    ///
    /// ```
    /// use edccif_sim::parallel::ParallelStep;
    /// let w = vec![1.0 / 8.0; 64]; // 8 nodes, all connected
    /// let par = ParallelStep::<f64, 7, 3>::new(&w, 8).unwrap();
    /// assert_eq!(par.min_nodes_per_task(), 8);
    /// let par = par.with_min_nodes_per_task(4).unwrap();
    /// assert_eq!(par.min_nodes_per_task(), 4);
    /// let e = par.with_min_nodes_per_task(0).unwrap_err().to_string();
    /// assert!(e.contains("min_nodes_per_task"), "{e}");
    /// ```
    pub fn with_min_nodes_per_task(mut self, n: usize) -> Result<Self> {
        check_min_nodes_per_task(n)?;
        self.min_len = n;
        Ok(self)
    }

    /// Nodes per rayon task at least (see [`with_min_nodes_per_task`](Self::with_min_nodes_per_task)).
    pub fn min_nodes_per_task(&self) -> usize {
        self.min_len
    }

    /// Runs `op` on a thread of the step's pool (rayon's global pool without
    /// one) and returns what it returns. Every [`step`](Self::step) that `op`
    /// makes runs its phases from that thread directly: the calling thread does
    /// not hand each step to the pool and wait for it to come back (a wake-up
    /// of a pool thread and one of the caller per step), and the pool's idle
    /// threads, which look for work a while before they sleep, find the next
    /// phase when steps follow each other closely. For stepping many times in a
    /// row with small phases; the numbers are the same as those of
    /// [`step`](Self::step) called directly.
    ///
    /// ```
    /// use edccif_sim::parallel::ParallelStep;
    /// let w = vec![1.0 / 8.0; 64];
    /// let mut par = ParallelStep::<f64, 7, 3>::new(&w, 8).unwrap().with_threads(2).unwrap();
    /// let threads = par.in_pool(|p| p.threads());
    /// assert_eq!(threads, 2);
    /// ```
    pub fn in_pool<R, OP>(&mut self, op: OP) -> R
    where
        OP: FnOnce(&mut Self) -> R + Send,
        R: Send,
    {
        match self.pool.clone() {
            Some(pool) => pool.install(|| op(self)),
            None => rayon::scope(|_| op(self)),
        }
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.k
    }

    /// Threads the phases run on.
    pub fn threads(&self) -> usize {
        self.pool
            .as_ref()
            .map_or_else(rayon::current_num_threads, |p| p.current_num_threads())
    }

    /// Node i's local step of the last step (`None` before the first step and
    /// when the node was down): [`NodeScratch::prior`](edccif_core::PhaseScratch::prior)
    /// and [`contribution`](edccif_core::PhaseScratch::contribution) are its
    /// `local.prior` and `local.contribution`.
    pub fn local(&self, i: usize) -> Option<&LocalOutput<T, N, M>> {
        self.phases.outs[i].as_ref()
    }

    /// Node i's information pair after adaptation (diffusion rows; the local
    /// posterior when the guard fired): [`NodeScratch::local`](edccif_core::PhaseScratch::local).
    pub fn adapted(&self, i: usize) -> &InfoPair<T, N> {
        &self.phases.adapted[i]
    }

    /// Node i's estimate before combination, as [`NodeScratch::post`](edccif_core::PhaseScratch::post)
    /// (under CI only `x` is formed unless the guard fired).
    pub fn post(&self, i: usize) -> &Gaussian<T, N> {
        &self.phases.post[i]
    }

    /// Sets node i's estimate before combination, which a step keeps where it
    /// forms none (node i down, or only `x` formed): for switching a running
    /// network from the serial step, whose [`NodeScratch::post`](edccif_core::PhaseScratch::post)
    /// it continues.
    pub fn set_post(&mut self, i: usize, post: Gaussian<T, N>) {
        self.phases.post[i] = post;
    }

    /// Node i's fused estimate of the last step.
    pub fn fused(&self, i: usize) -> &Gaussian<T, N> {
        &self.phases.fused[i]
    }

    /// What happened at node i in the last step.
    pub fn flags(&self, i: usize) -> NodeFlags {
        self.phases.flags[i]
    }

    /// One synchronous network step, as
    /// [`network_step`](edccif_core::network_step)`(cfg, motion, sensors,
    /// weights, nodes, scratch, inputs)` with the weights given to
    /// [`new`](Self::new), and the same result bit for bit: the fused estimates
    /// and trigger memories in `nodes` and the report; on failure an error (that
    /// of the lowest-numbered node in the first phase that failed) with no
    /// [`NodeState`] changed.
    pub fn step<F, H>(
        &mut self,
        cfg: &NetworkConfig<T>,
        motion: &F,
        sensors: &[H],
        nodes: &mut [NodeState<T, N, M>],
        inputs: &StepInputs<'_, T, M>,
    ) -> edccif_core::Result<StepReport>
    where
        F: MotionModel<T, N> + Sync + ?Sized,
        H: MeasurementModel<T, N, M> + Sync,
    {
        let none = Control::none();
        let r = match self.pool.clone() {
            Some(pool) => {
                pool.install(|| self.step_inner(cfg, motion, sensors, nodes, inputs, none))
            }
            None => self.step_inner(cfg, motion, sensors, nodes, inputs, none),
        };
        r.map_err(|stop| match stop {
            Stop::Core(e) => e,
            // `Control::none()` is never cancelled.
            Stop::Interrupted => unreachable!("an inert control stopped a step"),
        })
    }

    /// [`step`](Self::step) under a [`Control`]: cancelled, the step stops
    /// before its first phase or between two consensus rounds with
    /// [`Error::Interrupted`], and no [`NodeState`] changes (they change only
    /// in the last phase). A core failure is [`Error::Core`].
    pub fn step_controlled<F, H>(
        &mut self,
        cfg: &NetworkConfig<T>,
        motion: &F,
        sensors: &[H],
        nodes: &mut [NodeState<T, N, M>],
        inputs: &StepInputs<'_, T, M>,
        ctl: &Control,
    ) -> Result<StepReport>
    where
        F: MotionModel<T, N> + Sync + ?Sized,
        H: MeasurementModel<T, N, M> + Sync,
    {
        let r = match self.pool.clone() {
            Some(pool) => {
                pool.install(|| self.step_inner(cfg, motion, sensors, nodes, inputs, ctl))
            }
            None => self.step_inner(cfg, motion, sensors, nodes, inputs, ctl),
        };
        r.map_err(|stop| match stop {
            Stop::Core(e) => Error::Core(e),
            Stop::Interrupted => Error::Interrupted,
        })
    }

    fn step_inner<F, H>(
        &mut self,
        cfg: &NetworkConfig<T>,
        motion: &F,
        sensors: &[H],
        nodes: &mut [NodeState<T, N, M>],
        inputs: &StepInputs<'_, T, M>,
        ctl: &Control,
    ) -> std::result::Result<StepReport, Stop>
    where
        F: MotionModel<T, N> + Sync + ?Sized,
        H: MeasurementModel<T, N, M> + Sync,
    {
        if ctl.is_cancelled() {
            return Err(Stop::Interrupted);
        }
        let links = self.check_step(cfg, sensors.len(), nodes.len(), inputs)?;
        let reach = Reach {
            k: self.k,
            graph: &self.graph,
            links,
            active: inputs.active,
            min_len: self.min_len,
        };
        let ph = &mut self.phases;
        // 1. Local phase.
        ph.local(&reach, cfg, motion, sensors, nodes, inputs)?;
        let mut report = ph.report(&reach);
        // 2. Fusion phases.
        match cfg.fusion {
            Fusion::DiffusionCi | Fusion::DiffusionConvex => {
                report.guard_fallbacks = ph.adapt(&reach)?;
                ph.combine(&reach, cfg)?;
            }
            Fusion::Consensus { iterations } => ph.consensus(&reach, iterations, ctl)?,
            Fusion::Local => {
                for i in (0..reach.k).filter(|&i| reach.active(i)) {
                    ph.fused[i] = ph.out(i).local.posterior_estimate()?;
                }
            }
        }
        // 3. Commit.
        for i in (0..reach.k).filter(|&i| reach.active(i)) {
            ph.out(i).commit(&mut nodes[i], ph.fused[i]);
        }
        Ok(report)
    }

    /// Checks a step's configuration and sizes (`sensors` and `nodes` of
    /// them, the inputs' masks and thresholds); the link mask.
    fn check_step<'i>(
        &self,
        cfg: &NetworkConfig<T>,
        sensors: usize,
        nodes: usize,
        inputs: &StepInputs<'i, T, M>,
    ) -> edccif_core::Result<Option<LinkMask<'i>>> {
        cfg.validate()?;
        edccif_core::linalg::validate_positive(inputs.dt, "time step dt", false)?;
        let k = self.k;
        let check = |what: &'static str, expected: usize, got: usize| {
            if expected == got {
                Ok(())
            } else {
                Err(CoreError::Dimension {
                    what,
                    expected,
                    got,
                })
            }
        };
        check("nodes", k, nodes)?;
        check("sensors", k, sensors)?;
        check("observations", k, inputs.observations.len())?;
        let links = inputs.link_mask()?;
        match links {
            None => {}
            Some(LinkMask::Dense(l)) => check("link mask (nodes × nodes)", k * k, l.len())?,
            Some(LinkMask::Edges(l)) => check(
                "edge link mask (one per neighbour list entry)",
                k + self.graph.nbr.len(),
                l.len(),
            )?,
        }
        if let Some(a) = inputs.active {
            check("active mask", k, a.len())?;
        }
        inputs.check_deltas(&cfg.trigger, k)?;
        Ok(links)
    }
}

impl<T, const N: usize, const M: usize> Phases<T, N, M>
where
    T: RealField + Copy + Send + Sync,
{
    /// Node i's local output (node i is up).
    #[inline]
    fn out(&self, i: usize) -> &LocalOutput<T, N, M> {
        self.outs[i]
            .as_ref()
            .expect("active nodes have a local output")
    }

    /// The local phase: every node that is up predicts, decides whether its
    /// sensor sends, and forms its contribution.
    fn local<F, H>(
        &mut self,
        reach: &Reach<'_, T>,
        cfg: &NetworkConfig<T>,
        motion: &F,
        sensors: &[H],
        states: &[NodeState<T, N, M>],
        inputs: &StepInputs<'_, T, M>,
    ) -> edccif_core::Result<()>
    where
        F: MotionModel<T, N> + Sync + ?Sized,
        H: MeasurementModel<T, N, M> + Sync,
    {
        self.outs
            .par_iter_mut()
            .zip(self.post.par_iter_mut())
            .zip(self.flags.par_iter_mut())
            .zip(self.errs.par_iter_mut())
            .enumerate()
            .with_min_len(reach.min_len)
            .for_each(|(i, (((out, post), flags), err))| {
                flags.guard_used = false;
                flags.gated = false;
                if !reach.active(i) {
                    flags.triggered = None;
                    *out = None;
                    return;
                }
                // Node i's own threshold (checked above).
                let node_cfg = NetworkConfig {
                    trigger: inputs.trigger(&cfg.trigger, i).unwrap_or(cfg.trigger),
                    ..*cfg
                };
                match node_local(
                    &node_cfg,
                    motion,
                    inputs.dt,
                    &sensors[i],
                    &states[i],
                    &inputs.observations[i],
                ) {
                    Ok(o) => {
                        if let Some(g) = o.local.estimate {
                            *post = g;
                        }
                        flags.triggered = o.triggered;
                        flags.gated = o.gated;
                        *out = Some(o);
                    }
                    Err(e) => *err = Some(e),
                }
            });
        first_error(&mut self.errs)
    }

    /// The counts of the local phase (measured, triggered, gated).
    fn report(&self, reach: &Reach<'_, T>) -> StepReport {
        let mut report = StepReport::default();
        for (i, f) in self.flags.iter().enumerate() {
            if !reach.active(i) {
                continue;
            }
            if let Some(g) = f.triggered {
                report.measured += 1;
                report.triggered += usize::from(g);
            }
            report.gated += usize::from(f.gated);
        }
        report
    }

    /// Diffusion's adaptation: every node adds the contributions it heard.
    /// Returns the number of nodes whose guard fell back to the local
    /// posterior.
    fn adapt(&mut self, reach: &Reach<'_, T>) -> edccif_core::Result<usize> {
        let outs = &self.outs;
        let out = |i: usize| outs[i].as_ref().expect("active nodes have a local output");
        self.adapted
            .par_iter_mut()
            .zip(self.post.par_iter_mut())
            .zip(self.flags.par_iter_mut())
            .zip(self.errs.par_iter_mut())
            .enumerate()
            .with_min_len(reach.min_len)
            .for_each(|(i, (((adapted, post), flags), err))| {
                if !reach.active(i) {
                    return;
                }
                match node_adapt(
                    &out(i).local,
                    reach.heard(i).map(|j| &out(j).local.contribution),
                ) {
                    Ok(a) => {
                        *adapted = a.pair;
                        post.x = a.x;
                        if let Some(p) = a.covariance {
                            post.p = p;
                        }
                        flags.guard_used = a.guard_used;
                    }
                    Err(e) => *err = Some(e),
                }
            });
        first_error(&mut self.errs)?;
        Ok(self
            .flags
            .iter()
            .enumerate()
            .filter(|(i, f)| reach.active(*i) && f.guard_used)
            .count())
    }

    /// Diffusion's combination: covariance intersection of the adapted pairs
    /// (the paper's rule, or another of `fusion_rules`), or the convex
    /// combination of the estimates.
    fn combine(&mut self, reach: &Reach<'_, T>, cfg: &NetworkConfig<T>) -> edccif_core::Result<()> {
        let ci = cfg.fusion == Fusion::DiffusionCi;
        let (outs, adapted, post, flags) = (&self.outs, &self.adapted, &self.post, &self.flags);
        let out = |i: usize| outs[i].as_ref().expect("active nodes have a local output");
        let reach = *reach;
        // A fusion rule other than the paper's CI (`fusion_rules`): the closed
        // neighbourhood that arrived, ascending, and for split CI the
        // contributions each adapted pair holds.
        let closed = move |i: usize| {
            reach
                .heard(i)
                .filter(move |&j| j < i)
                .chain(std::iter::once(i))
                .chain(reach.heard(i).filter(move |&j| j > i))
        };
        let includes = move |j: usize, m: usize| {
            m == j || (!flags[j].guard_used && reach.heard(j).any(|x| x == m))
        };
        self.fused
            .par_iter_mut()
            .zip(self.errs.par_iter_mut())
            .enumerate()
            .with_min_len(reach.min_len)
            .for_each(|(i, (f, err))| {
                if !reach.active(i) {
                    return;
                }
                let r = if ci && !cfg.rule.is_paper() {
                    combine_node(
                        cfg.rule,
                        closed(i).map(|j| (j, reach.w(i, j), &adapted[j])),
                        closed(i)
                            .filter(|&m| includes(i, m))
                            .map(|m| (m, &out(m).local.contribution)),
                        includes,
                    )
                } else if ci {
                    node_combine_ci(
                        i,
                        reach.w(i, i),
                        &adapted[i],
                        reach.heard(i).map(|j| (j, reach.w(i, j), &adapted[j])),
                    )
                } else {
                    node_combine_convex(
                        i,
                        reach.w(i, i),
                        &post[i],
                        reach.heard(i).map(|j| (j, reach.w(i, j), &post[j])),
                    )
                };
                match r {
                    Ok(g) => *f = g,
                    Err(e) => *err = Some(e),
                }
            });
        first_error(&mut self.errs)
    }

    /// Consensus: `iterations` rounds from the local posteriors, checking
    /// `ctl` before each, then every node's fused estimate.
    fn consensus(
        &mut self,
        reach: &Reach<'_, T>,
        iterations: usize,
        ctl: &Control,
    ) -> std::result::Result<(), Stop> {
        for (i, c) in self.cons[0].iter_mut().enumerate() {
            if let Some(o) = &self.outs[i] {
                *c = o.local.posterior;
            }
        }
        for t in 0..iterations {
            if ctl.is_cancelled() {
                return Err(Stop::Interrupted);
            }
            let [a, b] = &mut self.cons;
            let (src, dst) = if t % 2 == 0 { (&*a, b) } else { (&*b, a) };
            dst.par_iter_mut()
                .zip(self.errs.par_iter_mut())
                .enumerate()
                .with_min_len(reach.min_len)
                .for_each(|(i, (d, err))| {
                    if !reach.active(i) {
                        return;
                    }
                    match node_consensus_round(
                        i,
                        reach.w(i, i),
                        &src[i],
                        reach.heard(i).map(|j| (j, reach.w(i, j), &src[j])),
                    ) {
                        Ok(p) => *d = p,
                        Err(e) => *err = Some(e),
                    }
                });
            first_error(&mut self.errs)?;
        }
        let cons = &self.cons[iterations % 2];
        self.fused
            .par_iter_mut()
            .zip(self.errs.par_iter_mut())
            .enumerate()
            .with_min_len(reach.min_len)
            .for_each(|(i, (f, err))| {
                if reach.active(i) {
                    match cons[i].to_gaussian() {
                        Ok(g) => *f = g,
                        Err(e) => *err = Some(e),
                    }
                }
            });
        Ok(first_error(&mut self.errs)?)
    }
}

/// Why a step stopped: a core failure, or a cancelled [`Control`].
#[derive(Debug)]
enum Stop {
    Core(CoreError),
    Interrupted,
}

impl From<CoreError> for Stop {
    fn from(e: CoreError) -> Self {
        Stop::Core(e)
    }
}

/// The lowest-numbered error of the phase just run, clearing the slots.
fn first_error(errs: &mut [Option<CoreError>]) -> edccif_core::Result<()> {
    let mut first = None;
    for e in errs.iter_mut() {
        if let Some(err) = e.take() {
            first.get_or_insert(err);
        }
    }
    first.map_or(Ok(()), Err)
}
