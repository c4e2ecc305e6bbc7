//! The fault injector's link mask per edge of the graph's neighbour lists:
//! the same lost messages as the dense `N × N` draw (a reference
//! implementation of it is kept here), the same numbers as a dense mask in
//! the serial and the parallel step, and a faulted run of a ring far larger
//! than a dense mask allows per step.

use edccif_core::LinkMask;
use edccif_sim::faults::{run_with_faults, FaultInjector, Faults};
use edccif_sim::{run, simulate, Algorithm, AnyNetwork, RunOptions, Scenario, Topology};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The dense draw: per step, one uniform per ordered pair `i ≠ j` of the
/// loss stream (ChaCha8, stream 1 of the faults' seed), row-major; `[i*k+j]`
/// true when the link `i ← j` is kept.
struct DenseReference {
    rng: ChaCha8Rng,
    k: usize,
    loss: f64,
}

impl DenseReference {
    fn new(seed: u64, k: usize, loss: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(1);
        Self { rng, k, loss }
    }

    fn step(&mut self) -> Vec<bool> {
        let k = self.k;
        let mut links = vec![true; k * k];
        for i in 0..k {
            for j in 0..k {
                if i != j {
                    links[i * k + j] = self.rng.random::<f64>() >= self.loss;
                }
            }
        }
        links
    }
}

fn scenario(nodes: usize, topology: Topology) -> Scenario {
    let mut sc = Scenario::paper(nodes);
    sc.topology = topology;
    sc.steps = 8;
    sc
}

#[test]
fn the_edge_mask_draws_what_the_dense_mask_drew() {
    let topologies = [
        Topology::Ring,
        Topology::Complete,
        Topology::Line,
        Topology::Star { center: 1 },
        Topology::RandomGeometric {
            radius: 0.45,
            seed: 3,
        },
    ];
    let mut checked_lost = 0u64;
    for nodes in [2, 3, 5, 9, 40] {
        for topology in &topologies {
            let sc = scenario(nodes, topology.clone());
            let sim = simulate(&sc, 0).unwrap();
            let graph = sc.neighbours().unwrap();
            for seed in [0, 1, 12345] {
                for loss in [0.0, 0.1, 0.5, 0.93, 1.0] {
                    let faults = Faults {
                        seed,
                        message_loss: loss,
                        ..Faults::default()
                    };
                    let mut net = AnyNetwork::new(
                        Algorithm::EdcCif,
                        &sc,
                        &sim.x0_hat,
                        &RunOptions::default(),
                    )
                    .unwrap();
                    let mut inj = FaultInjector::new(&faults, &sc).unwrap();
                    let mut reference = DenseReference::new(seed, nodes, loss);
                    let mut want_lost = 0u64;
                    let mut z = vec![0.0; nodes * 3];
                    for t in 0..6 {
                        inj.prepare(t, &mut z, &mut net).unwrap();
                        let dense = reference.step();
                        let mut want = vec![false; graph.entries()];
                        let lists = graph.core().unwrap();
                        LinkMask::dense_to_edges(&dense, lists.neighbours(), &mut want).unwrap();
                        assert_eq!(
                            inj.edge_links, want,
                            "{nodes} nodes, {topology:?}, seed {seed}, loss {loss}, step {t}"
                        );
                        want_lost += (0..nodes)
                            .flat_map(|i| graph.row(i).iter().map(move |&j| (i, j)))
                            .filter(|&(i, j)| i != j && !dense[i * nodes + j])
                            .count() as u64;
                    }
                    assert_eq!(inj.lost_links, want_lost);
                    checked_lost += want_lost;
                }
            }
        }
    }
    assert!(checked_lost > 10_000, "{checked_lost}");
}

/// A faulted step with the edge mask equals the step with the dense mask of
/// the same links, serial and parallel (every row, lost links and a node
/// down).
#[test]
fn edge_and_dense_masks_step_alike() {
    let sc = scenario(
        12,
        Topology::RandomGeometric {
            radius: 0.5,
            seed: 1,
        },
    );
    let sim = simulate(&sc, 2).unwrap();
    let graph = sc.neighbours().unwrap();
    let lists = graph.core().unwrap();
    let k = sc.nodes();
    for alg in Algorithm::ALL {
        for threads in [None, Some(2)] {
            let opt = RunOptions {
                threads,
                ..RunOptions::default()
            };
            let net = || AnyNetwork::new(alg, &sc, &sim.x0_hat, &opt).unwrap();
            let (mut a, mut b) = (net(), net());
            let mut reference = DenseReference::new(4, k, 0.3);
            for (t, z) in sim.z.chunks(k * 3).enumerate() {
                let dense = reference.step();
                let mut edges = vec![false; graph.entries()];
                LinkMask::dense_to_edges(&dense, lists.neighbours(), &mut edges).unwrap();
                let active: Vec<bool> = (0..k).map(|i| i != 3 || !(3..6).contains(&t)).collect();
                let ra = a.step_with(z, Some(&dense), Some(&active)).unwrap();
                let rb = b
                    .step_with_mask(z, Some(LinkMask::Edges(&edges)), Some(&active))
                    .unwrap();
                assert_eq!(ra, rb, "{alg} {threads:?} step {t}");
                let (mut ea, mut eb) = (vec![0.0; k * a.state_dim()], vec![0.0; k * 7]);
                eb.truncate(k * b.state_dim());
                a.write_estimates(&mut ea);
                b.write_estimates(&mut eb);
                assert_eq!(ea, eb, "{alg} {threads:?} step {t}");
            }
            assert_eq!(a.counters(), b.counters(), "{alg} {threads:?}");
        }
    }
}

#[test]
fn edge_masks_of_the_wrong_length_are_named_errors() {
    let sc = scenario(5, Topology::Ring);
    let sim = simulate(&sc, 0).unwrap();
    for threads in [None, Some(2)] {
        let opt = RunOptions {
            threads,
            ..RunOptions::default()
        };
        let mut net = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
        let short = vec![true; net.graph().entries() - 1];
        let e = net
            .step_with_mask(&sim.z[..15], Some(LinkMask::Edges(&short)), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("edge link mask"), "{e}");
    }
}

/// 2,000 nodes on a ring: a faulted run needs O(nodes + edges) per step.
/// Without loss it equals the run without faults bit for bit; with loss it
/// loses about the expected share of the 4,000 directed links a step.
#[test]
fn a_faulted_ring_of_2000_nodes_runs() {
    let mut sc = Scenario::paper(2000);
    sc.steps = 3;
    let sim = simulate(&sc, 0).unwrap();
    let opt = RunOptions::default();
    let plain = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &opt, false).unwrap();
    let none = Faults {
        seed: 9,
        ..Faults::default()
    };
    let faulted = run_with_faults(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &opt,
        &none,
        false,
    )
    .unwrap();
    assert_eq!(faulted.estimates, plain.estimates);
    assert_eq!(faulted.counters, plain.counters);

    let lossy = Faults {
        seed: 9,
        message_loss: 0.25,
        ..Faults::default()
    };
    let r = run_with_faults(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &opt,
        &lossy,
        false,
    )
    .unwrap();
    assert!(r.estimates.iter().all(|v| v.is_finite()));
    assert_ne!(r.estimates, plain.estimates);
    // Diffusion sends two messages per delivered link: fewer than without loss.
    assert!(
        r.counters.values_estimator_to_estimator < plain.counters.values_estimator_to_estimator
    );
    let mut net = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
    let mut inj = FaultInjector::new(&lossy, &sc).unwrap();
    let mut z = vec![0.0; 2000 * 3];
    for t in 0..3 {
        z.copy_from_slice(&sim.z[t * 6000..(t + 1) * 6000]);
        inj.prepare(t, &mut z, &mut net).unwrap();
        net.step_with_mask(&z, Some(inj.mask()), Some(&inj.active))
            .unwrap();
    }
    // 3 steps × 4,000 directed links × 0.25 = 3,000 expected (σ ≈ 47).
    assert!((2700..3300).contains(&inj.lost_links), "{}", inj.lost_links);
    let mut e = vec![0.0; 2000 * 7];
    net.write_estimates(&mut e);
    assert_eq!(e, r.estimates[2 * 2000 * 7..]);
}
