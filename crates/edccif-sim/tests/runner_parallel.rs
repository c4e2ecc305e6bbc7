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
