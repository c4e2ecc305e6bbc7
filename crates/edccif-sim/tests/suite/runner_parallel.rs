//! The runner with the parallel step switched on (`AnyNetwork::set_parallel`)
//! against the same runner with it off (the default serial step): the same
//! fused estimates and covariances, local estimates, trigger flags, step
//! reports and counters, bit for bit (`to_bits` equality on every f64), over
//! 30 steps of an 80-node ring with missing observations, lost links and a
//! node that is down. Speed is measured in `edccif-bench`, not here.

use edccif_sim::{simulate, Algorithm, AnyNetwork, RunOptions, Scenario, Topology};

const NODES: usize = 80;
const STEPS: usize = 30;

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Everything the runner exposes about the last step, as exact bits.
fn snapshot(net: &AnyNetwork) -> (Vec<u64>, Vec<u64>, Vec<u64>, Vec<Option<bool>>) {
    let n = net.state_dim();
    let (mut x, mut p, mut local) = (
        vec![0.0; NODES * n],
        vec![0.0; NODES * n * n],
        vec![0.0; NODES * n],
    );
    net.write_estimates(&mut x);
    net.write_covariances(&mut p);
    net.write_local_estimates(&mut local);
    (bits(&x), bits(&p), bits(&local), net.last_triggered())
}

fn check(alg: Algorithm, opt: RunOptions) {
    let mut sc = Scenario::paper(NODES);
    sc.topology = Topology::Ring;
    let mut sim = simulate(&sc, 4).unwrap();
    // Some missing measurements (whole NaN rows).
    for t in (0..STEPS).step_by(3) {
        let row = (t * NODES + (7 * t) % NODES) * 3;
        sim.z[row..row + 3].fill(f64::NAN);
    }
    let mut serial = AnyNetwork::new(alg, &sc, &sim.x0_hat, &opt).unwrap();
    let mut par = AnyNetwork::new(alg, &sc, &sim.x0_hat, &opt).unwrap();
    assert!(!serial.parallel(), "the serial step is the default");
    par.set_parallel(true).unwrap();
    assert!(par.parallel());
    for (t, z) in sim.z.chunks(NODES * 3).take(STEPS).enumerate() {
        // Every fourth step: a lost link (node 10 does not hear 11) and node 40 down.
        let mut links = vec![true; NODES * NODES];
        links[10 * NODES + 11] = false;
        let mut active = [true; NODES];
        active[40] = false;
        let faults = t % 4 == 1;
        let (l, a) = if faults {
            (Some(&links[..]), Some(&active[..]))
        } else {
            (None, None)
        };
        let rs = serial.step_with(z, l, a).unwrap();
        let rp = par.step_with(z, l, a).unwrap();
        assert_eq!(rs, rp, "{alg:?} step {t}: report");
        assert_eq!(snapshot(&serial), snapshot(&par), "{alg:?} step {t}");
    }
    assert_eq!(serial.counters(), par.counters());
    assert!(serial.counters().triggered > 0);
    // Switching back to the serial step mid-run keeps the two in lockstep.
    par.set_parallel(false).unwrap();
    assert!(!par.parallel());
    for z in sim.z.chunks(NODES * 3).skip(STEPS).take(3) {
        assert_eq!(serial.step(z).unwrap(), par.step(z).unwrap());
    }
    assert_eq!(snapshot(&serial), snapshot(&par));
}

#[test]
fn edc_cif_ring_80_parallel_equals_serial() {
    check(Algorithm::EdcCif, RunOptions::default());
}

#[test]
fn ec_ckf_ring_80_parallel_equals_serial() {
    // A fixed L keeps the test short; the rounds are the same code for any L.
    let opt = RunOptions {
        consensus_iters: Some(10),
        ..RunOptions::default()
    };
    check(Algorithm::EcCkf, opt);
}

#[test]
fn step_errors_leave_both_unchanged() {
    let sc = Scenario::paper(NODES);
    let sim = simulate(&sc, 2).unwrap();
    let opt = RunOptions::default();
    let mut net = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
    net.set_parallel(true).unwrap();
    let before = snapshot(&net);
    assert!(net.step(&sim.z[..NODES * 3 - 1]).is_err(), "wrong shape");
    assert!(
        net.step_dt(&sim.z[..NODES * 3], -1.0).is_err(),
        "negative dt"
    );
    assert_eq!(snapshot(&net), before);
    assert_eq!(net.counters().steps, 0);
}

// ---- RunOptions::threads: the whole-run entry points with the parallel step ----

use edccif_sim::faults::{run_with_faults, Faults, Window};
use edccif_sim::{monte_carlo, run, run_with_dt, McSettings, RunResult, Variant};

/// Everything a run returns except its wall time, as exact bits.
fn run_bits(r: &RunResult) -> impl PartialEq + std::fmt::Debug {
    (
        r.algorithm,
        (r.steps, r.nodes, r.n),
        bits(&r.estimates),
        bits(&r.covariances),
        r.triggered.clone(),
        r.measured.clone(),
        r.counters,
    )
}

fn with_threads(opt: RunOptions, threads: Option<usize>) -> RunOptions {
    RunOptions { threads, ..opt }
}

/// `run`, `run_with_dt` and `run_with_faults` with `threads` 2 and 3 give the
/// serial run's results bit for bit (also `threads = 1`, the serial step).
fn check_run(sc: &Scenario, steps: usize, alg: Algorithm, opt: RunOptions) {
    let sc = Scenario {
        steps,
        ..sc.clone()
    };
    let sim = simulate(&sc, 5).unwrap();
    let mut z = sim.z.clone();
    let k = sc.nodes();
    for t in (0..steps).step_by(4) {
        let row = (t * k + (5 * t) % k) * 3;
        z[row..row + 3].fill(f64::NAN);
    }
    let dt: Vec<f64> = (0..steps)
        .map(|t| sc.dt * (1.0 + 0.1 * (t % 3) as f64))
        .collect();
    let faults = Faults {
        seed: 3,
        message_loss: 0.2,
        dropout: vec![Window {
            node: k / 2,
            start: 3,
            end: 7,
        }],
        ..Faults::default()
    };
    let serial = with_threads(opt.clone(), None);
    let a = run(alg, &sc, &z, &sim.x0_hat, &serial, true).unwrap();
    let b = run_with_dt(alg, &sc, &z, &dt, &sim.x0_hat, &serial, true).unwrap();
    let c = run_with_faults(alg, &sc, &z, &sim.x0_hat, &serial, &faults, true).unwrap();
    assert!(a.counters.triggered > 0 && c.counters.measured > 0);
    for threads in [1, 2, 3] {
        let par = with_threads(opt.clone(), Some(threads));
        let what = format!("{alg:?}, {k} nodes, threads {threads}");
        let ap = run(alg, &sc, &z, &sim.x0_hat, &par, true).unwrap();
        assert_eq!(run_bits(&a), run_bits(&ap), "run: {what}");
        let bp = run_with_dt(alg, &sc, &z, &dt, &sim.x0_hat, &par, true).unwrap();
        assert_eq!(run_bits(&b), run_bits(&bp), "run_with_dt: {what}");
        let cp = run_with_faults(alg, &sc, &z, &sim.x0_hat, &par, &faults, true).unwrap();
        assert_eq!(run_bits(&c), run_bits(&cp), "run_with_faults: {what}");
    }
}

fn ring(nodes: usize) -> Scenario {
    let mut sc = Scenario::paper(nodes);
    sc.topology = Topology::Ring;
    sc
}

#[test]
fn run_threads_equals_serial_edc_cif_ring_64() {
    check_run(&ring(64), 25, Algorithm::EdcCif, RunOptions::default());
}

#[test]
fn run_threads_equals_serial_ec_ckf_ring_64() {
    let opt = RunOptions {
        consensus_iters: Some(8),
        ..RunOptions::default()
    };
    check_run(&ring(64), 25, Algorithm::EcCkf, opt);
}

#[test]
fn run_threads_equals_serial_small_paper_network() {
    // Fewer nodes than a rayon task takes: one task, the same code path.
    check_run(
        &Scenario::paper(4),
        60,
        Algorithm::EdcCif,
        RunOptions::default(),
    );
    check_run(
        &Scenario::paper(4),
        60,
        Algorithm::EcCkf,
        RunOptions::default(),
    );
}

#[test]
fn network_threads_follow_the_option() {
    let sc = Scenario::paper(8);
    let sim = simulate(&sc, 0).unwrap();
    let net = |threads| {
        AnyNetwork::new(
            Algorithm::EdcCif,
            &sc,
            &sim.x0_hat,
            &with_threads(RunOptions::default(), threads),
        )
    };
    assert_eq!(net(None).unwrap().threads(), 1);
    assert!(!net(Some(1)).unwrap().parallel());
    let two = net(Some(2)).unwrap();
    assert!(two.parallel());
    assert_eq!(two.threads(), 2);
    // The pool of a count is shared, not started per network.
    let a = edccif_sim::parallel::shared_pool(2).unwrap();
    let b = edccif_sim::parallel::shared_pool(2).unwrap();
    assert!(std::sync::Arc::ptr_eq(&a, &b));
}

#[test]
fn zero_threads_is_a_named_error() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 0).unwrap();
    let zero = with_threads(RunOptions::default(), Some(0));
    let msg = |e: edccif_sim::Error| {
        let m = e.to_string();
        assert!(
            matches!(e, edccif_sim::Error::Value { .. })
                && m.contains("threads")
                && m.contains(">= 1"),
            "{m}"
        );
    };
    msg(run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &zero, false).unwrap_err());
    msg(AnyNetwork::new(Algorithm::EcCkf, &sc, &sim.x0_hat, &zero).unwrap_err());
    let v = Variant {
        label: "x".into(),
        algorithm: Algorithm::EdcCif,
        options: zero,
    };
    let mc = McSettings {
        runs: 2,
        seed: 0,
        progress: false,
    };
    msg(monte_carlo(&sc, &[v], &mc).unwrap_err());
    let mut net =
        AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
    net.set_parallel(true).unwrap();
    msg(net.set_threads(0).unwrap_err());
    assert!(net.parallel(), "a rejected thread count changes nothing");
}

#[test]
fn monte_carlo_with_threads_equals_serial() {
    let sc = Scenario {
        steps: 30,
        ..ring(64)
    };
    let mc = McSettings {
        runs: 3,
        seed: 11,
        progress: false,
    };
    let variants = |threads| {
        [Algorithm::EdcCif, Algorithm::EcCkf].map(|a| Variant {
            label: a.label().into(),
            algorithm: a,
            options: with_threads(
                RunOptions {
                    consensus_iters: Some(6),
                    ..RunOptions::default()
                },
                threads,
            ),
        })
    };
    let s = monte_carlo(&sc, &variants(None), &mc).unwrap();
    let p = monte_carlo(&sc, &variants(Some(2)), &mc).unwrap();
    for (a, b) in s.variants.iter().zip(&p.variants) {
        assert_eq!(a.errors, b.errors, "{}", a.label);
        assert_eq!(a.trigger_rate.to_bits(), b.trigger_rate.to_bits());
        assert_eq!(a.trigger_rate_per_node, b.trigger_rate_per_node);
        assert_eq!(
            (a.values_estimator_to_estimator, a.guard_fallbacks),
            (b.values_estimator_to_estimator, b.guard_fallbacks)
        );
        assert_eq!(b.options.threads, Some(2));
    }
}

#[test]
fn switching_on_mid_run_with_a_node_down_continues_the_serial_step() {
    // A node that is down keeps its last pre-combination estimate; a parallel
    // step switched on while it is down must carry the serial step's over.
    let sc = ring(NODES);
    let sim = simulate(&sc, 6).unwrap();
    for (alg, opt) in [
        (Algorithm::EdcCif, RunOptions::default()),
        (
            Algorithm::EcCkf,
            RunOptions {
                consensus_iters: Some(4),
                ..RunOptions::default()
            },
        ),
    ] {
        let mut serial = AnyNetwork::new(alg, &sc, &sim.x0_hat, &opt).unwrap();
        let mut net = serial.clone();
        let mut active = [true; NODES];
        active[40] = false;
        for (t, z) in sim.z.chunks(NODES * 3).take(12).enumerate() {
            match t {
                4 => net.set_threads(2).unwrap(),
                7 => net.set_threads(1).unwrap(),
                9 => net.set_parallel(true).unwrap(),
                _ => {}
            }
            let a = (t % 2 == 0).then_some(&active[..]);
            assert_eq!(
                serial.step_with(z, None, a).unwrap(),
                net.step_with(z, None, a).unwrap()
            );
            assert_eq!(snapshot(&serial), snapshot(&net), "{alg:?} step {t}");
        }
    }
}
