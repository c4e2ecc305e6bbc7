//! Large networks: the workloads of the scaling study, and the network step on
//! plain slices, serial (the core's `network_step_sparse` over neighbour lists,
//! as the runner steps it) or parallel
//! ([`edccif_sim::parallel::ParallelStep`]), for measuring the parallel speed-up.
//!
//! The default scenario generalises to any number of nodes: the sensors sit on a
//! circle of radius 10 m around the target's path, evenly spaced, at heights
//! alternating 0 and 3 m ([`Scenario::paper`]); only their spacing shrinks with N.
//! The random geometric graphs place the *communication* graph's nodes in the
//! unit square with the connection radius [`rgg_radius`].
//!
//! ```
//! use edccif_bench::scaling::{scaling_workload, SliceNet, Topo};
//! use edccif_bench::Row;
//! use edccif_sim::Algorithm;
//! let w = scaling_workload(Topo::Ring, 64, 2024).unwrap();
//! assert_eq!(w.scenario.consensus_iters, Some(1433)); // the adequate L, computed once
//! let mut serial = SliceNet::new(&w, Row::new(Algorithm::EdcCif), None).unwrap();
//! let mut parallel = SliceNet::new(&w, Row::new(Algorithm::EdcCif), Some(2)).unwrap();
//! let mut warm = SliceNet::new(&w, Row::new(Algorithm::EdcCif), Some(2))
//!     .unwrap()
//!     .with_min_nodes_per_task(4)
//!     .unwrap();
//! serial.run(&w, 0..3).unwrap();
//! parallel.run(&w, 0..3).unwrap();
//! warm.run_in_pool(&w, 0..3).unwrap();
//! assert_eq!(serial.nodes, parallel.nodes); // bit for bit
//! assert_eq!(serial.nodes, warm.nodes);
//! ```

use std::fmt;
use std::hint::black_box;
use std::ops::Range;
use std::str::FromStr;

use edccif_core::models::CoordinatedTurn;
use edccif_core::{
    network_step_sparse, Gaussian, Neighbours, NetworkConfig, NodeScratch, NodeState, Observation,
    StepInputs, TriggerState,
};
use edccif_sim::parallel::ParallelStep;
use edccif_sim::runner::M;
use edccif_sim::{network_config, Error, Result, Scenario, Sensor, Topology};
use nalgebra::{SMatrix, SVector};

use crate::{rgg_radius, Row, Workload};

/// The two topologies of the scaling study.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topo {
    /// `i ↔ i ± 1 mod N`.
    Ring,
    /// Seeded random geometric graph of radius [`rgg_radius`]`(N)`.
    Rgg,
}

impl fmt::Display for Topo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Topo::Ring => "ring",
            Topo::Rgg => "rgg",
        })
    }
}

impl FromStr for Topo {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "ring" => Ok(Topo::Ring),
            "rgg" | "random-geometric" => Ok(Topo::Rgg),
            o => Err(format!("topology: expected ring or rgg, got {o:?}")),
        }
    }
}

/// The default scenario with `nodes` nodes on `topo` (the random geometric
/// graph seeded with `seed`), simulated with `seed`, with the adequate `L`
/// computed once and stored in the scenario (`consensus_iters`), so that
/// building a network does not redo the `N × N` eigen-decomposition. `L` is the
/// one the scenario would compute, so every row runs as by default.
pub fn scaling_workload(topo: Topo, nodes: usize, seed: u64) -> Result<Workload> {
    let mut sc = Scenario::paper(nodes);
    if topo == Topo::Rgg {
        sc.topology = Topology::RandomGeometric {
            radius: rgg_radius(nodes),
            seed,
        };
    }
    let l = sc.consensus_iterations()?;
    scaling_workload_with_l(sc, l, seed)
}

/// [`scaling_workload`] with the adequate `L` given (e.g. known from an earlier
/// run, to skip the eigen-decomposition under a profiler).
pub fn scaling_workload_with_l(mut sc: Scenario, adequate_l: usize, seed: u64) -> Result<Workload> {
    sc.consensus_iters = Some(adequate_l);
    Workload::new(sc, seed)
}

/// A 7-state network on plain slices, stepped by the core's `network_step_sparse` or,
/// with a thread count, by [`ParallelStep`]. For timing the two side by side.
#[derive(Debug, Clone)]
pub struct SliceNet {
    cfg: NetworkConfig<f64>,
    motion: CoordinatedTurn<f64>,
    sensors: Vec<Sensor>,
    weights: Vec<f64>,
    offsets: Vec<usize>,
    indices: Vec<usize>,
    /// Every node's state.
    pub nodes: Vec<NodeState<f64, 7, M>>,
    scratch: Vec<NodeScratch<f64, 7, M>>,
    obs: Vec<Observation<f64, M>>,
    dt: f64,
    par: Option<ParallelStep<f64, 7, M>>,
}

impl SliceNet {
    /// The network of `row` on the workload (coordinated-turn scenarios only),
    /// at the start of the run; `threads: Some(t)` steps it with a
    /// [`ParallelStep`] on a pool of `t` threads. The nodes start as
    /// [`AnyNetwork::new`](edccif_sim::AnyNetwork::new) starts them.
    pub fn new(w: &Workload, row: Row, threads: Option<usize>) -> Result<Self> {
        let sc = &w.scenario;
        let cfg = network_config(row.alg, sc, &row.options())?;
        let p0 = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
        if w.sim.x0_hat.len() != 7 {
            return Err(Error::Value {
                what: "scenario".into(),
                problem: "SliceNet runs the 7-state coordinated-turn scenarios only".into(),
            });
        }
        let start = Gaussian::new(SVector::from_column_slice(&w.sim.x0_hat), p0)?;
        let k = w.nodes();
        let nodes = (0..k)
            .map(|i| {
                let mut s = NodeState::new(start, &cfg.trigger);
                s.trigger = TriggerState::seeded(&cfg.trigger, 0, i as u64);
                s
            })
            .collect();
        let weights = sc.weights()?;
        let mut offsets = vec![0; k + 1];
        let mut indices = vec![0; Neighbours::count(&weights, k)];
        Neighbours::from_weights(&weights, k, &mut offsets, &mut indices)?;
        let par = threads
            .map(|t| ParallelStep::new(&weights, k).and_then(|p| p.with_threads(t)))
            .transpose()?;
        Ok(Self {
            cfg,
            motion: sc.coordinated_turn()?,
            sensors: sc.sensor_models()?,
            weights,
            offsets,
            indices,
            nodes,
            scratch: vec![NodeScratch::default(); k],
            obs: vec![Observation::Missing; k],
            dt: sc.dt,
            par,
        })
    }

    /// Splits each phase of the parallel step into tasks of at least `n` nodes
    /// ([`ParallelStep::with_min_nodes_per_task`]; no effect on the serial step).
    pub fn with_min_nodes_per_task(mut self, n: usize) -> Result<Self> {
        self.par = self
            .par
            .take()
            .map(|p| p.with_min_nodes_per_task(n))
            .transpose()?;
        Ok(self)
    }

    /// Steps through the workload's steps `steps` (a row of NaN is a missing
    /// observation); the parallel step hands each step to its pool. Never
    /// inlined (a profiler can collect it alone).
    #[inline(never)]
    pub fn run(&mut self, w: &Workload, steps: Range<usize>) -> Result<()> {
        let mut par = self.par.take();
        let r = self.run_with(w, steps, par.as_mut());
        self.par = par;
        r
    }

    /// [`run`](Self::run), with the whole loop inside the parallel step's pool
    /// ([`ParallelStep::in_pool`]): the steps start from a pool thread, which
    /// keeps the pool's threads busy between steps. The same numbers; the
    /// serial step runs as in [`run`](Self::run).
    #[inline(never)]
    pub fn run_in_pool(&mut self, w: &Workload, steps: Range<usize>) -> Result<()> {
        match self.par.take() {
            None => self.run(w, steps),
            Some(mut p) => {
                let r = p.in_pool(|p| self.run_with(w, steps, Some(p)));
                self.par = Some(p);
                r
            }
        }
    }

    fn run_with(
        &mut self,
        w: &Workload,
        steps: Range<usize>,
        mut par: Option<&mut ParallelStep<f64, 7, M>>,
    ) -> Result<()> {
        for t in steps {
            for (o, z) in self.obs.iter_mut().zip(w.z_at(t).chunks_exact(M)) {
                *o = if z[0].is_nan() {
                    Observation::Missing
                } else {
                    Observation::Measured(SVector::from_column_slice(z))
                };
            }
            let inputs = StepInputs::new(&self.obs, self.dt);
            let report = match par.as_deref_mut() {
                None => network_step_sparse(
                    &self.cfg,
                    &self.motion,
                    &self.sensors,
                    &self.weights,
                    &Neighbours::new(&self.offsets, &self.indices)?,
                    &mut self.nodes,
                    &mut self.scratch,
                    &inputs,
                )?,
                Some(p) => p.step(
                    &self.cfg,
                    &self.motion,
                    &self.sensors,
                    &mut self.nodes,
                    &inputs,
                )?,
            };
            black_box(report);
        }
        Ok(())
    }
}
