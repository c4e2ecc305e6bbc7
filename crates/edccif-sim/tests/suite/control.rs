//! Stopping long computations (`edccif_sim::control`) and sizes checked before
//! allocating (`edccif_sim::limits`): a step with many consensus rounds run
//! round by round under a live control gives the serial core step's numbers
//! bit for bit, a cancelled step changes nothing, a cancelled Monte Carlo
//! study keeps the runs it finished (equal to a study of that many runs), and
//! sizes that cannot fit are refused with `Error::TooLarge`.

use std::sync::atomic::{AtomicUsize, Ordering};

use edccif_sim::control::Control;
use edccif_sim::faults::run_with_control;
use edccif_sim::montecarlo::monte_carlo_with;
use edccif_sim::{
    monte_carlo, run, simulate, Algorithm, AnyNetwork, Error, McSettings, RunOptions, Scenario,
};

fn heavy_options(rounds: usize) -> RunOptions {
    RunOptions {
        consensus_iters: Some(rounds),
        ..RunOptions::default()
    }
}

#[test]
fn many_rounds_under_a_live_control_equal_the_serial_step() {
    let sc = Scenario {
        steps: 4,
        ..Scenario::paper(5)
    };
    let sim = simulate(&sc, 3).unwrap();
    let opt = heavy_options(12_000); // 5 × 12 000 node-rounds: a heavy step
    let mut serial = AnyNetwork::new(Algorithm::EcCkf, &sc, &sim.x0_hat, &opt).unwrap();
    let mut live = serial.clone();
    assert!(live.heavy());
    let ctl = Control::new();
    for z in sim.z.chunks(5 * 3) {
        let a = serial.step_dt(z, sc.dt).unwrap();
        let b = live
            .step_dt_with_control(z, sc.dt, None, None, &ctl)
            .unwrap();
        assert_eq!(a, b);
        let (mut ea, mut eb) = (vec![0.0; 5 * 7], vec![0.0; 5 * 7]);
        serial.write_estimates(&mut ea);
        live.write_estimates(&mut eb);
        assert_eq!(ea, eb); // bit for bit
        let (mut ca, mut cb) = (vec![0.0; 5 * 49], vec![0.0; 5 * 49]);
        serial.write_covariances(&mut ca);
        live.write_covariances(&mut cb);
        assert_eq!(ca, cb);
    }
    assert_eq!(serial.counters(), live.counters());
}

#[test]
fn a_cancelled_step_changes_nothing() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 0).unwrap();
    let mut net =
        AnyNetwork::new(Algorithm::EcCkf, &sc, &sim.x0_hat, &heavy_options(50_000)).unwrap();
    net.step_dt(&sim.z[..12], sc.dt).unwrap();
    let before = net.clone();
    let ctl = Control::new();
    ctl.cancel();
    let e = net
        .step_dt_with_control(&sim.z[12..24], sc.dt, None, None, &ctl)
        .unwrap_err();
    assert_eq!(e, Error::Interrupted);
    let (mut a, mut b) = (vec![0.0; 28], vec![0.0; 28]);
    before.write_estimates(&mut a);
    net.write_estimates(&mut b);
    assert_eq!(a, b);
    assert_eq!(before.counters(), net.counters());
    // And the network goes on as if nothing had happened.
    let mut again = before.clone();
    net.step_dt(&sim.z[12..24], sc.dt).unwrap();
    again.step_dt(&sim.z[12..24], sc.dt).unwrap();
    net.write_estimates(&mut a);
    again.write_estimates(&mut b);
    assert_eq!(a, b);
}

#[test]
fn a_run_under_a_control_counts_its_steps_and_equals_run() {
    let sc = Scenario {
        steps: 30,
        ..Scenario::paper(4)
    };
    let sim = simulate(&sc, 2).unwrap();
    let opt = RunOptions::default();
    let ctl = Control::new();
    let a = run_with_control(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &opt,
        None,
        None,
        true,
        &ctl,
    )
    .unwrap();
    let b = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &opt, true).unwrap();
    assert_eq!((a.estimates, a.covariances), (b.estimates, b.covariances));
    assert_eq!(ctl.progress(), (30, 30));
}

#[test]
fn a_cancelled_monte_carlo_keeps_the_runs_it_finished() {
    let sc = Scenario {
        steps: 10,
        ..Scenario::paper(3)
    };
    let variants = [Algorithm::EdcCif.into(), Algorithm::EcCkf.into()];
    let settings = McSettings {
        runs: 200,
        seed: 5,
        progress: false,
    };
    let ctl = Control::new();
    // Cancel from inside, once a few runs × variants are done.
    let seen = AtomicUsize::new(0);
    let watcher = |c: &Control| loop {
        let (done, _) = c.progress();
        if done >= 40 {
            c.cancel();
            return;
        }
        seen.fetch_add(1, Ordering::Relaxed);
        std::thread::yield_now();
    };
    let part = std::thread::scope(|s| {
        s.spawn(|| watcher(&ctl));
        monte_carlo_with(&sc, &variants, &settings, &ctl)
    })
    .unwrap();
    assert!(ctl.is_cancelled());
    assert!(part.runs >= 1 && part.runs < 200, "{}", part.runs);
    let full = monte_carlo(
        &sc,
        &variants,
        &McSettings {
            runs: part.runs,
            ..settings
        },
    )
    .unwrap();
    for (p, f) in part.variants.iter().zip(&full.variants) {
        assert_eq!(p.errors, f.errors);
        assert_eq!(p.trigger_rate, f.trigger_rate);
        assert_eq!(p.values_sensor_to_estimator, f.values_sensor_to_estimator);
    }
}

#[test]
fn sizes_that_cannot_fit_are_refused() {
    let big = Scenario {
        steps: 1 << 50,
        ..Scenario::paper(4)
    };
    let e = simulate(&big, 0).unwrap_err();
    assert!(matches!(e, Error::TooLarge { .. }), "{e}");
    let settings = McSettings {
        runs: 2,
        seed: 0,
        progress: false,
    };
    let e = monte_carlo(&big, &[Algorithm::EdcCif.into()], &settings).unwrap_err();
    assert!(e.to_string().contains("Monte Carlo"), "{e}");
    let mut huge = Scenario::paper(4);
    huge.sensors = vec![[0.0; 3]; 100_000_000];
    let e = huge.validate().unwrap_err();
    assert!(e.to_string().contains("nodes = 100000000"), "{e}");
}

#[test]
fn duplicate_labels_are_refused() {
    let sc = Scenario {
        steps: 5,
        ..Scenario::paper(3)
    };
    let e = monte_carlo(
        &sc,
        &[Algorithm::EdcCif.into(), Algorithm::EdcCif.into()],
        &McSettings {
            runs: 1,
            seed: 0,
            progress: false,
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("two variants have the label"), "{e}");
}
