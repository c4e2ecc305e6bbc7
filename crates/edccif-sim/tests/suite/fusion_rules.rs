//! Fusion rules in the simulator's networks (`docs/fusion.md`): every rule runs
//! on whole seeded runs without error, `ci` is the default bit for bit, the
//! parallel step and the mixed-sensor network give the serial step's numbers,
//! and a failed step leaves the network as it was.

use edccif_core::FusionRule;
use edccif_sim::{run, simulate, Algorithm, FusionKind, RunOptions, Scenario, TriggerKind};

fn opts(rule: FusionRule, trigger: Option<TriggerKind>) -> RunOptions {
    RunOptions {
        fusion: Some(if rule.is_paper() {
            FusionKind::DiffusionCi
        } else {
            FusionKind::Rule(rule)
        }),
        trigger,
        ..RunOptions::default()
    }
}

/// Whole 200-step runs of the 4-node default with every rule and the paper's,
/// the sending-everything and the stochastic trigger: finite, no guard
/// fallbacks. Seed 10 with `split-ci-det` once produced a non-finite fused
/// matrix (an optimiser that formed the other inputs' sum by subtraction).
#[test]
fn every_rule_runs_whole_runs() {
    let sc = Scenario::paper(4);
    for seed in [10, 11] {
        let sim = simulate(&sc, seed).unwrap();
        for rule in FusionRule::ALL {
            for trigger in [
                None,
                Some(TriggerKind::Always),
                Some(TriggerKind::Stochastic),
            ] {
                let r = run(
                    Algorithm::EdcCif,
                    &sc,
                    &sim.z,
                    &sim.x0_hat,
                    &opts(rule, trigger),
                    false,
                )
                .unwrap_or_else(|e| panic!("{rule} {trigger:?} seed {seed}: {e}"));
                assert!(r.estimates.iter().all(|v| v.is_finite()), "{rule}");
                assert_eq!(r.counters.guard_fallbacks, 0, "{rule}");
            }
        }
    }
}

#[test]
fn ci_is_the_default_and_the_scenario_rule_applies_to_the_ci_rows() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 2).unwrap();
    let base = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        false,
    )
    .unwrap();
    let ci = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &opts(FusionRule::CI, None),
        false,
    )
    .unwrap();
    assert_eq!(base.estimates, ci.estimates);
    let ici: FusionRule = "ici".parse().unwrap();
    let with_rule = Scenario {
        fusion: Some(ici),
        ..sc.clone()
    };
    let a = run(
        Algorithm::EdcCif,
        &with_rule,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        false,
    )
    .unwrap();
    let b = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &opts(ici, None),
        false,
    )
    .unwrap();
    assert_eq!(a.estimates, b.estimates);
    assert_ne!(a.estimates, base.estimates);
    // the rows without the CI combination keep theirs
    for alg in [Algorithm::EdCif, Algorithm::EcCkf] {
        let x = run(
            alg,
            &with_rule,
            &sim.z,
            &sim.x0_hat,
            &RunOptions::default(),
            false,
        )
        .unwrap();
        let y = run(alg, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), false).unwrap();
        assert_eq!(x.estimates, y.estimates, "{alg}");
    }
    // and the scenario's rule round-trips through TOML
    let back = Scenario::from_toml_str(&with_rule.to_toml().unwrap()).unwrap();
    assert_eq!(back.fusion, Some(ici));
    assert!(
        Scenario::from_toml_str(&with_rule.to_toml().unwrap().replace("\"ici\"", "\"ei\""))
            .unwrap_err()
            .to_string()
            .contains("ei-unsafe")
    );
}

#[test]
fn parallel_step_equals_the_serial_one_for_every_rule() {
    let mut sc = Scenario::paper(8);
    sc.steps = 40;
    let sim = simulate(&sc, 4).unwrap();
    for rule in FusionRule::ALL {
        let serial = run(
            Algorithm::EdcCif,
            &sc,
            &sim.z,
            &sim.x0_hat,
            &opts(rule, None),
            false,
        )
        .unwrap();
        let par = RunOptions {
            threads: Some(2),
            ..opts(rule, None)
        };
        let p = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &par, false).unwrap();
        assert_eq!(serial.estimates, p.estimates, "{rule}");
    }
}

/// A recording's stored run keeps the fusion rule (the run's `fusion` option
/// and the scenario's `fusion` key), so a replay of it gives the run's
/// estimates bit for bit, not the paper's CI.
#[test]
fn a_stored_run_keeps_its_fusion_rule() {
    use edccif_sim::recording::StoredRun;
    use edccif_sim::replay::resolve_stored;
    let mut sc = Scenario::paper(4);
    sc.steps = 40;
    sc.fusion = Some("split-ci".parse().unwrap());
    let sim = simulate(&sc, 5).unwrap();
    let ci = RunOptions::default();
    let ici = opts("ici".parse().unwrap(), None);
    for (opt, scenario_rule) in [(&ci, true), (&ici, false)] {
        let stored = StoredRun::new(&sc, Algorithm::EdcCif, opt, 5, &sim.x0_hat);
        let back = StoredRun::from_metadata(&stored.to_metadata().unwrap()).unwrap();
        assert_eq!(back, stored);
        assert_eq!(back.scenario.fusion, sc.fusion);
        assert_eq!(back.options.fusion, opt.fusion);
        let r =
            resolve_stored("f", Some(&back), None, None, &RunOptions::default(), false).unwrap();
        let first = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, opt, true).unwrap();
        let again = run(r.algorithm, &r.scenario, &sim.z, &r.x0, &r.options, true).unwrap();
        assert_eq!(
            first
                .estimates
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            again
                .estimates
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            "scenario rule: {scenario_rule}"
        );
        // and the rule matters: the paper's CI gives other numbers
        let mut plain = sc.clone();
        plain.fusion = None;
        let paper = run(Algorithm::EdcCif, &plain, &sim.z, &sim.x0_hat, &ci, true).unwrap();
        assert_ne!(paper.estimates, again.estimates);
    }
}
