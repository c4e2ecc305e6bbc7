//! The parallel network step (`edccif_sim::parallel`) against the serial core
//! step `edccif_core::network_step`: the same node states, public scratch fields
//! and reports, bit for bit (exact `==` on every f64), over many steps of large
//! rings and random geometric graphs, with missing observations, lost links and
//! nodes that are down. Speed is measured in `edccif-bench`, not here.

use edccif_core::models::CoordinatedTurn;
use edccif_core::{
    network_step, Fusion, NetworkConfig, NodeScratch, NodeState, Observation, StepInputs,
    TriggerState,
};
use edccif_sim::parallel::ParallelStep;
use edccif_sim::{
    network_config, simulate, Algorithm, RunOptions, Scenario, Sensor, Simulation, Topology,
};
use nalgebra::{SMatrix, SVector};

type State = NodeState<f64, 7, 3>;
type Scratch = NodeScratch<f64, 7, 3>;

struct Setup {
    cfg: NetworkConfig<f64>,
    motion: CoordinatedTurn<f64>,
    sensors: Vec<Sensor>,
    weights: Vec<f64>,
    nodes: Vec<State>,
    sim: Simulation,
}

fn setup(nodes: usize, topology: Topology, alg: Algorithm, opt: &RunOptions) -> Setup {
    let mut sc = Scenario::paper(nodes);
    sc.topology = topology;
    let sim = simulate(&sc, 11).unwrap();
    let cfg = network_config(alg, &sc, opt).unwrap();
    let p0 = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
    let start = edccif_core::Gaussian::new(SVector::from_column_slice(&sim.x0_hat), p0).unwrap();
    let states = (0..nodes)
        .map(|i| {
            let mut s = NodeState::new(start, &cfg.trigger);
            s.trigger = TriggerState::seeded(&cfg.trigger, 5, i as u64);
            s
        })
        .collect();
    Setup {
        cfg,
        motion: sc.coordinated_turn().unwrap(),
        sensors: sc.sensor_models().unwrap(),
        weights: sc.weights().unwrap(),
        nodes: states,
        sim,
    }
}

fn rgg(nodes: usize) -> Topology {
    let n = nodes as f64;
    Topology::RandomGeometric {
        radius: (1.5 * (2.0 * n.ln() / n).sqrt()).min(1.0),
        seed: 3,
    }
}

/// The serial step's scratch against what the parallel step keeps, exactly.
fn assert_scratch_eq(
    cfg: &NetworkConfig<f64>,
    a: &[Scratch],
    b: &ParallelStep<f64, 7, 3>,
    step: usize,
) {
    let diffusion = matches!(cfg.fusion, Fusion::DiffusionCi | Fusion::DiffusionConvex);
    for (i, x) in a.iter().enumerate() {
        let at = format!("step {step}, node {i}");
        let f = b.flags(i);
        assert_eq!(x.triggered, f.triggered, "triggered, {at}");
        assert_eq!(x.guard_used, f.guard_used, "guard_used, {at}");
        assert_eq!(x.gated, f.gated, "gated, {at}");
        assert_eq!(&x.post, b.post(i), "post, {at}");
        assert_eq!(&x.fused, b.fused(i), "fused, {at}");
        // A node that was down keeps the serial scratch of an earlier step.
        if let Some(out) = b.local(i) {
            assert_eq!(x.prior(), &out.local.prior, "prior, {at}");
            assert_eq!(
                x.contribution(),
                &out.local.contribution,
                "contribution, {at}"
            );
            let local = if diffusion {
                b.adapted(i)
            } else {
                &out.local.posterior
            };
            assert_eq!(x.local(), local, "local, {at}");
        }
    }
}

/// How the parallel step is run in a comparison.
#[derive(Clone, Copy)]
struct Run {
    threads: usize,
    /// `with_min_nodes_per_task`, `None`: the default.
    min_nodes_per_task: Option<usize>,
    /// The whole loop inside the step's pool (`ParallelStep::in_pool`).
    in_pool: bool,
}

impl Run {
    fn threads(threads: usize) -> Self {
        Self {
            threads,
            min_nodes_per_task: None,
            in_pool: false,
        }
    }
}

/// Steps the serial and the parallel network side by side for `steps` steps;
/// step 7 has missing observations, step 13 lost links and two nodes down.
/// Returns how many node-steps were missing, sent and not sent.
fn compare(s: Setup, steps: usize, threads: usize) -> (usize, usize, usize) {
    compare_run(s, steps, Run::threads(threads))
}

fn compare_run(s: Setup, steps: usize, run: Run) -> (usize, usize, usize) {
    let k = s.nodes.len();
    let mut par = ParallelStep::new(&s.weights, k)
        .unwrap()
        .with_threads(run.threads)
        .unwrap();
    if let Some(n) = run.min_nodes_per_task {
        par = par.with_min_nodes_per_task(n).unwrap();
        assert_eq!(par.min_nodes_per_task(), n);
    }
    assert_eq!(par.threads(), run.threads);
    if run.in_pool {
        par.in_pool(|p| compare_steps(&s, steps, p))
    } else {
        compare_steps(&s, steps, &mut par)
    }
}

fn compare_steps(
    s: &Setup,
    steps: usize,
    par: &mut ParallelStep<f64, 7, 3>,
) -> (usize, usize, usize) {
    let k = s.nodes.len();
    let mut serial = s.nodes.clone();
    let mut parallel = s.nodes.clone();
    let mut s1 = vec![Scratch::default(); k];
    let (mut missing, mut sent, mut quiet) = (0, 0, 0);
    for t in 0..steps {
        let z = &s.sim.z[t * k * 3..(t + 1) * k * 3];
        let obs: Vec<Observation<f64, 3>> = z
            .chunks(3)
            .enumerate()
            .map(|(i, r)| {
                if t == 7 && i % 5 == 1 {
                    Observation::Missing
                } else {
                    Observation::Measured(SVector::from_column_slice(r))
                }
            })
            .collect();
        let links: Vec<bool> = (0..k * k).map(|e| t != 13 || e % 7 != 3).collect();
        let active: Vec<bool> = (0..k).map(|i| t != 13 || (i != 2 && i != k / 2)).collect();
        let mut inputs = StepInputs::new(&obs, 0.1);
        if t == 13 {
            inputs.links = Some(&links);
            inputs.active = Some(&active);
        }
        let r1 = network_step(
            &s.cfg,
            &s.motion,
            &s.sensors,
            &s.weights,
            &mut serial,
            &mut s1,
            &inputs,
        )
        .unwrap();
        let r2 = par
            .step(&s.cfg, &s.motion, &s.sensors, &mut parallel, &inputs)
            .unwrap();
        assert_eq!(r1, r2, "report, step {t}");
        assert_eq!(serial, parallel, "node states, step {t}");
        assert_scratch_eq(&s.cfg, &s1, par, t);
        for x in &s1 {
            match x.triggered {
                None => missing += 1,
                Some(true) => sent += 1,
                Some(false) => quiet += 1,
            }
        }
    }
    (missing, sent, quiet)
}

fn check(nodes: usize, topology: Topology, alg: Algorithm, opt: RunOptions) {
    let s = setup(nodes, topology, alg, &opt);
    let (missing, sent, quiet) = compare(s, 40, 2);
    // The comparison covered missing observations and both trigger outcomes.
    assert!(missing >= nodes / 5, "missing {missing}");
    assert!(sent > 0 && (quiet > 0 || !alg.is_event_triggered()));
}

#[test]
fn edc_cif_ring_64_bit_for_bit() {
    check(64, Topology::Ring, Algorithm::EdcCif, RunOptions::default());
}

#[test]
fn edc_cif_rgg_96_bit_for_bit() {
    check(96, rgg(96), Algorithm::EdcCif, RunOptions::default());
}

#[test]
fn ec_ckf_ring_64_bit_for_bit() {
    let opt = RunOptions {
        consensus_iters: Some(6),
        ..RunOptions::default()
    };
    check(64, Topology::Ring, Algorithm::EcCkf, opt);
}

#[test]
fn ec_ckf_rgg_80_adequate_l_bit_for_bit() {
    // The graph's own adequate L (an odd or even count exercises both buffers).
    check(80, rgg(80), Algorithm::EcCkf, RunOptions::default());
}

#[test]
fn ed_cif_and_local_fusion_bit_for_bit() {
    check(64, Topology::Ring, Algorithm::EdCif, RunOptions::default());
    let opt = RunOptions {
        fusion: Some(edccif_sim::FusionKind::Local),
        ..RunOptions::default()
    };
    check(64, Topology::Ring, Algorithm::EcCkf, opt);
}

#[test]
fn more_threads_than_cores_same_numbers() {
    let s = setup(
        72,
        Topology::Ring,
        Algorithm::EdcCif,
        &RunOptions::default(),
    );
    compare(s, 12, 5);
    let s = setup(
        72,
        Topology::Ring,
        Algorithm::EdcCif,
        &RunOptions::default(),
    );
    compare(s, 12, 1);
}

#[test]
fn bad_inputs_same_error_and_nodes_unchanged() {
    let s = setup(
        64,
        Topology::Ring,
        Algorithm::EdcCif,
        &RunOptions::default(),
    );
    let k = s.nodes.len();
    let mut par = ParallelStep::new(&s.weights, k).unwrap();
    let mut nodes = s.nodes.clone();
    let mut s1 = vec![Scratch::default(); k];
    // Too few observations.
    let obs = vec![Observation::Missing; k - 1];
    let inputs = StepInputs::new(&obs, 0.1);
    let e1 = network_step(
        &s.cfg, &s.motion, &s.sensors, &s.weights, &mut nodes, &mut s1, &inputs,
    )
    .unwrap_err();
    let e2 = par
        .step(&s.cfg, &s.motion, &s.sensors, &mut nodes, &inputs)
        .unwrap_err();
    assert_eq!(e1, e2);
    // A non-finite time step.
    let obs = vec![Observation::Missing; k];
    let e = par
        .step(
            &s.cfg,
            &s.motion,
            &s.sensors,
            &mut nodes,
            &StepInputs::new(&obs, f64::NAN),
        )
        .unwrap_err();
    assert!(e.to_string().contains("dt"), "{e}");
    // A measurement that breaks one node's local step: error, no state changed.
    let mut obs: Vec<Observation<f64, 3>> = s.sim.z[..k * 3]
        .chunks(3)
        .map(|r| Observation::Measured(SVector::from_column_slice(r)))
        .collect();
    obs[9] = Observation::Measured(SVector::from([f64::INFINITY, 0.0, 0.0]));
    obs[40] = Observation::Measured(SVector::from([f64::NAN, 0.0, 0.0]));
    let inputs = StepInputs::new(&obs, 0.1);
    let mut serial = s.nodes.clone();
    let e1 = network_step(
        &s.cfg,
        &s.motion,
        &s.sensors,
        &s.weights,
        &mut serial,
        &mut s1,
        &inputs,
    );
    let e2 = par.step(&s.cfg, &s.motion, &s.sensors, &mut nodes, &inputs);
    assert!(e1.is_err(), "a non-finite measurement must fail the step");
    assert_eq!(e1.map(|_| ()), e2.map(|_| ()));
    assert_eq!(nodes, s.nodes);
    // Wrong weights.
    assert!(ParallelStep::<f64, 7, 3>::new(&s.weights[1..], k).is_err());
}

fn check_run(nodes: usize, alg: Algorithm, opt: RunOptions, run: Run) {
    let s = setup(nodes, Topology::Ring, alg, &opt);
    let (missing, sent, quiet) = compare_run(s, 40, run);
    assert!(missing >= 1, "missing {missing}");
    assert!(sent > 0 && (quiet > 0 || !alg.is_event_triggered()));
}

#[test]
fn eight_nodes_in_tasks_of_four_bit_for_bit() {
    // 8 nodes in two tasks of 4 per phase on 2 threads, handed to the pool per
    // step and with the whole loop inside the pool.
    for in_pool in [false, true] {
        let run = Run {
            threads: 2,
            min_nodes_per_task: Some(4),
            in_pool,
        };
        check_run(8, Algorithm::EdcCif, RunOptions::default(), run);
        let opt = RunOptions {
            consensus_iters: Some(5),
            ..RunOptions::default()
        };
        check_run(8, Algorithm::EcCkf, opt, run);
    }
}

#[test]
fn small_networks_any_granularity_bit_for_bit() {
    // One node per task, uneven tasks (3 of 8 or 16 nodes), more tasks than
    // threads, and a granularity larger than the network.
    for (nodes, min, threads) in [(8, 1, 2), (8, 3, 2), (16, 4, 2), (16, 3, 3), (8, 100, 2)] {
        let run = Run {
            threads,
            min_nodes_per_task: Some(min),
            in_pool: min % 2 == 1,
        };
        check_run(nodes, Algorithm::EdcCif, RunOptions::default(), run);
    }
    let run = Run {
        threads: 2,
        min_nodes_per_task: Some(1),
        in_pool: false,
    };
    check_run(8, Algorithm::EdCif, RunOptions::default(), run);
}

#[test]
fn min_nodes_per_task_zero_is_an_error_naming_the_option() {
    let w = Scenario::paper(8).weights().unwrap();
    let par = ParallelStep::<f64, 7, 3>::new(&w, 8).unwrap();
    assert_eq!(par.min_nodes_per_task(), 8, "the default is unchanged");
    let e = par.clone().with_min_nodes_per_task(0).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("min_nodes_per_task"), "{msg}");
    assert!(msg.contains(">= 1") || msg.contains("at least 1"), "{msg}");
    assert!(matches!(e, edccif_sim::Error::Value { .. }), "{e:?}");
    assert!(edccif_sim::parallel::check_min_nodes_per_task(0).is_err());
    assert_eq!(
        par.with_min_nodes_per_task(1).unwrap().min_nodes_per_task(),
        1
    );
}

#[test]
fn in_pool_on_the_global_pool_same_numbers() {
    // Without a pool of its own the step runs on rayon's global pool.
    let s = setup(8, Topology::Ring, Algorithm::EdcCif, &RunOptions::default());
    let mut par = ParallelStep::new(&s.weights, 8)
        .unwrap()
        .with_min_nodes_per_task(4)
        .unwrap();
    let (missing, sent, _) = par.in_pool(|p| compare_steps(&s, 20, p));
    assert!(missing >= 1 && sent > 0);
}
