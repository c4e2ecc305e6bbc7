//! The scenario networks step with neighbour lists (no `N × N` weight matrix):
//! bit for bit the numbers of the core's dense step (`network_step` with the
//! `N × N` weights), for every paper row, with and without lost links.

use edccif_core::{network_step, Gaussian, NodeScratch, NodeState, Observation, StepInputs};
use edccif_core::{Trigger, TriggerState};
use edccif_sim::{
    network_config, node_deltas, simulate, Algorithm, AnyNetwork, RunOptions, Scenario, Topology,
};
use nalgebra::{SMatrix, SVector};

/// Runs `alg` on `sc` both ways for `steps` steps; `lost(step, i, j)` drops
/// the message j → i.
fn compare(
    alg: Algorithm,
    sc: &Scenario,
    steps: usize,
    lost: &dyn Fn(usize, usize, usize) -> bool,
) {
    let k = sc.nodes();
    let sim = simulate(sc, 3).unwrap();
    let opt = RunOptions::default();
    let mut net = AnyNetwork::new(alg, sc, &sim.x0_hat, &opt).unwrap();

    // The dense reference, set up as `AnyNetwork::new` does.
    let cfg = network_config(alg, sc, &opt).unwrap();
    let deltas = node_deltas(alg, Some((&sc.delta, sc.normalised)), &opt, k).unwrap();
    let w = sc.weights().unwrap();
    let motion = sc.coordinated_turn().unwrap();
    let sensors = sc.sensor_models().unwrap();
    let p0 = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
    let start = Gaussian::new(SVector::<f64, 7>::from_column_slice(&sim.x0_hat), p0).unwrap();
    let node_trigger = |i: usize| -> Trigger<f64> {
        match &deltas {
            Some(d) => cfg.trigger.with_delta(d[i]).unwrap(),
            None => cfg.trigger,
        }
    };
    let mut nodes: Vec<NodeState<f64, 7, 3>> = (0..k)
        .map(|i| {
            let mut n = NodeState::new(start, &cfg.trigger);
            n.trigger = TriggerState::seeded(&node_trigger(i), 0, i as u64);
            n
        })
        .collect();
    let mut scratch = vec![NodeScratch::default(); k];

    let mut est = vec![0.0; k * 7];
    for (t, z) in sim.z.chunks(k * 3).take(steps).enumerate() {
        let links: Vec<bool> = (0..k * k).map(|e| !lost(t, e / k, e % k)).collect();
        let obs: Vec<Observation<f64, 3>> = z
            .chunks(3)
            .map(|r| {
                if r.iter().all(|v| v.is_nan()) {
                    Observation::Missing
                } else {
                    Observation::Measured(SVector::<f64, 3>::from_column_slice(r))
                }
            })
            .collect();
        let mut inputs = StepInputs::new(&obs, sc.dt);
        inputs.links = Some(&links);
        inputs.deltas = deltas.as_deref();
        let want = network_step(
            &cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &inputs,
        );
        let got = net.step_with(z, Some(&links), None);
        match (want, got) {
            (Ok(a), Ok(b)) => assert_eq!(a, b, "{alg:?} {k} nodes step {t}: report"),
            (Err(_), Err(_)) => return,
            (a, b) => panic!("{alg:?} {k} nodes step {t}: {a:?} vs {b:?}"),
        }
        net.write_estimates(&mut est);
        for (i, n) in nodes.iter().enumerate() {
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&est[i * 7..(i + 1) * 7]),
                bits(n.estimate.x.as_slice()),
                "{alg:?} {k} nodes step {t} node {i}"
            );
        }
    }
}

#[test]
fn every_paper_row_equals_the_dense_step_bit_for_bit() {
    for k in [4, 8] {
        let sc = Scenario::paper(k);
        for alg in Algorithm::ALL {
            compare(alg, &sc, 80, &|_, _, _| false);
        }
    }
}

#[test]
fn lost_links_and_other_topologies_equal_the_dense_step() {
    let drop = |t: usize, i: usize, j: usize| (t * 7 + i * 3 + j).is_multiple_of(5);
    for topology in [
        Topology::Star { center: 2 },
        Topology::Line,
        Topology::Complete,
        Topology::RandomGeometric {
            radius: 0.6,
            seed: 1,
        },
    ] {
        let sc = Scenario {
            topology,
            ..Scenario::paper(6)
        };
        for alg in Algorithm::ALL {
            compare(alg, &sc, 40, &drop);
        }
    }
}

#[test]
fn lists_hold_the_dense_weights_of_every_topology() {
    let custom = Topology::Custom {
        adjacency: vec![
            vec![false, true, true],
            vec![true, false, false],
            vec![true, false, false],
        ],
        weights: Some(vec![
            vec![0.5, 0.25, 0.25],
            vec![0.25, 0.75, 0.0],
            vec![0.25, 0.0, 0.75],
        ]),
    };
    for (t, n) in [
        (Topology::Ring, 1),
        (Topology::Ring, 2),
        (Topology::Ring, 9),
        (Topology::Line, 7),
        (Topology::Star { center: 3 }, 5),
        (Topology::Complete, 6),
        (
            Topology::RandomGeometric {
                radius: 0.3,
                seed: 5,
            },
            40,
        ),
        (custom, 3),
    ] {
        let g = t.neighbours(n).unwrap();
        let w = t.weights(n).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&g.to_dense().unwrap()), bits(&w), "{t:?} {n}");
        let mut want = vec![0.0; n * n];
        edccif_core::fusion::max_degree_weights(&t.adjacency(n).unwrap(), n, &mut want).unwrap();
        if !matches!(t, Topology::Custom { .. }) {
            assert_eq!(bits(&w), bits(&want), "{t:?} {n}: max-degree weights");
        }
    }
}

#[test]
fn a_random_geometric_graph_is_that_of_every_pair() {
    use rand::{Rng, SeedableRng};
    // The pairs within the radius of the first draw, tested one by one.
    let (n, radius, seed) = (300, 0.12, 4u64);
    let g = Topology::RandomGeometric { radius, seed }
        .neighbours(n)
        .unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let pts: Vec<(f64, f64)> = (0..n).map(|_| (rng.random(), rng.random())).collect();
    for i in 0..n {
        let want: Vec<usize> = (0..n)
            .filter(|&j| j == i || (pts[i].0 - pts[j].0).hypot(pts[i].1 - pts[j].1) <= radius)
            .collect();
        assert_eq!(g.row(i), want.as_slice(), "node {i}");
    }
}

#[test]
fn a_large_ring_needs_no_dense_matrix() {
    let sc = Scenario::paper(100_000);
    sc.validate().unwrap();
    let g = sc.neighbours().unwrap();
    assert_eq!(g.entries(), 300_000);
    let sim = simulate(
        &Scenario {
            steps: 2,
            ..sc.clone()
        },
        0,
    )
    .unwrap();
    let mut net =
        AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
    for z in sim.z.chunks(100_000 * 3) {
        net.step(z).unwrap();
    }
    let mut est = vec![0.0; 100_000 * 7];
    net.write_estimates(&mut est);
    assert!(est.iter().all(|v| v.is_finite()));
    // The dense getters refuse what does not fit, naming the lists.
    let big = Scenario::paper(1_000_000);
    let e = big.weights().unwrap_err().to_string();
    assert!(e.contains("neighbour lists"), "{e}");
}
