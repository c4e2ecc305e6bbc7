//! Scenario files: the shipped JSON Schema is the one generated from the types,
//! every file in `scenarios/` round-trips through TOML, the per-node form of
//! the catalogue runs, and keys a run would ignore are refused by name.

use std::path::{Path, PathBuf};

use edccif_sim::{run, simulate, Algorithm, RunOptions, Scenario, Topology};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scenario_files() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(root().join("scenarios"))
        .expect("scenarios/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(
        files.len() >= 5,
        "expected the paper's and the catalogue's files, got {files:?}"
    );
    files
}

#[test]
fn shipped_schema_is_the_generated_one() {
    let path = root().join("python/edccif/scenario.schema.json");
    let shipped = std::fs::read_to_string(&path).expect("python/edccif/scenario.schema.json");
    assert!(
        shipped == edccif_sim::scenario::json_schema(),
        "{} is stale: regenerate with `cargo run -p edccif-sim --bin edccif-scenario-schema -- {}`",
        path.display(),
        "python/edccif/scenario.schema.json"
    );
}

/// A Python model by reference: kept by the round trip, refused by every
/// Rust-only path with an error that names the reference.
#[test]
fn a_python_model_is_kept_and_refused_from_rust() {
    let f = root().join("scenarios/custom-turn-2d.toml");
    let sc = Scenario::from_toml_file(&f).unwrap();
    assert!(sc.has_python_models() && !sc.is_typed());
    assert_eq!(
        sc.python_dirs(),
        vec![root().join("scenarios").join("../examples")]
    );
    let text = sc.to_toml().unwrap();
    assert!(
        text.contains("model = \"turn_models:turn_motion\""),
        "{text}"
    );
    assert!(text.contains("python_path = [\"../examples\"]"), "{text}");
    let z = vec![0.0; 8 * sc.steps];
    let x0 = sc.x0.clone();
    let e = run(
        Algorithm::EdcCif,
        &sc,
        &z,
        &x0,
        &RunOptions::default(),
        false,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("motion.model") && e.contains("cannot run a Python model"),
        "{e}"
    );
    let settings = edccif_sim::McSettings {
        runs: 1,
        seed: 0,
        progress: false,
    };
    let e = edccif_sim::monte_carlo(&sc, &[Algorithm::EdcCif.into()], &settings)
        .unwrap_err()
        .to_string();
    assert!(e.contains("cannot run a Python model"), "{e}");
    // a catalogue motion with a Python sensor: the error names the node
    let mut catalogue = sc.clone();
    catalogue.motion = edccif_sim::MotionSpec::CoordinatedTurn2D { q1: 0.1, q2: 1e-4 };
    let e = simulate(&catalogue, 0).unwrap_err().to_string();
    assert!(
        e.contains("nodes[4].sensor.model") && e.contains("turn_models:position_tag"),
        "{e}"
    );
    // a malformed reference is refused when read
    let bad = text.replace("turn_models:turn_motion", "turn_models.turn_motion");
    let e = Scenario::from_toml_str(&bad).unwrap_err().to_string();
    assert!(e.contains("module:attribute"), "{e}");
}

#[test]
fn every_scenario_file_round_trips() {
    for f in scenario_files() {
        let a = Scenario::from_toml_file(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        a.validate()
            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let text = a.to_toml().unwrap();
        let b = Scenario::from_toml_str(&text).unwrap();
        assert_eq!(a, b, "{}", f.display());
        assert_eq!(text, b.to_toml().unwrap(), "{}", f.display());
        // the JSON form (what Python's from_dict/to_dict carry) is the same scenario
        let json = serde_json::to_value(&a).unwrap();
        let c: Scenario = serde_json::from_value(json).unwrap();
        assert_eq!(a, c, "{}", f.display());
    }
}

#[test]
fn every_scenario_file_runs() {
    for f in scenario_files() {
        let sc = Scenario::from_toml_file(&f).unwrap();
        if sc.has_python_models() {
            // a Rust-only run refuses a Python model, naming it
            let e = simulate(&sc, 3).unwrap_err().to_string();
            assert!(
                e.contains("cannot run a Python model") && e.contains("turn_models:"),
                "{}: {e}",
                f.display()
            );
            continue;
        }
        let sim = simulate(&sc, 3).unwrap();
        let r = run(
            Algorithm::EdcCif,
            &sc,
            &sim.z,
            &sim.x0_hat,
            &RunOptions::default(),
            false,
        )
        .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let (k, n) = (sc.nodes(), sc.state_dim());
        let d = sc.motion.spatial_dim().unwrap_or(3);
        let mut se = 0.0;
        for t in 0..sc.steps {
            for i in 0..k {
                for c in 0..d {
                    let e = r.estimates[(t * k + i) * n + c] - sim.truth[t * n + c];
                    se += e * e;
                }
            }
        }
        let rmse = (se / (sc.steps * k) as f64).sqrt();
        println!(
            "{}: EDC-CIF position RMSE {rmse:.4} m over {} steps",
            sc.name, sc.steps
        );
        assert!(
            rmse.is_finite() && rmse < 1.0,
            "{}: rmse {rmse}",
            f.display()
        );
    }
}

/// The paper's files in the per-node form run on the model network with the
/// typed network's numbers, bit for bit, for every row.
#[test]
fn per_node_form_of_the_paper_is_bit_identical() {
    let sc = Scenario {
        steps: 40,
        ..Scenario::from_toml_file(root().join("scenarios/paper-4.toml")).unwrap()
    };
    let sim = simulate(&sc, 7).unwrap();
    let pn = sc.per_node();
    assert!(!pn.is_typed());
    let sim2 = simulate(&pn, 7).unwrap();
    assert_eq!(sim.z, sim2.z);
    assert_eq!(sim.truth, sim2.truth);
    for alg in Algorithm::ALL {
        let opt = RunOptions::default();
        let a = run(alg, &sc, &sim.z, &sim.x0_hat, &opt, false).unwrap();
        let b = run(alg, &pn, &sim.z, &sim.x0_hat, &opt, false).unwrap();
        assert_eq!(a.estimates, b.estimates, "{}", alg.name());
    }
}

fn err(text: &str) -> String {
    match Scenario::from_toml_str(text).and_then(|s| s.validate()) {
        Ok(()) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn unknown_and_ignored_keys_are_errors_naming_the_key() {
    let base = std::fs::read_to_string(root().join("scenarios/paper-4.toml")).unwrap();
    let ring = "[topology]\nkind = \"ring\"";
    assert!(base.contains(ring));
    // a key of no kind
    assert!(err(&base.replace("steps = 200", "steps = 200\nstepz = 3")).contains("stepz"));
    // a key the kind does not have: a ring has no centre
    let e = err(&base.replace(ring, "[topology]\nkind = \"ring\"\ncenter = 2"));
    assert!(e.contains("center"), "{e}");
    // a star's centre is used, and checked
    let star =
        Scenario::from_toml_str(&base.replace(ring, "[topology]\nkind = \"star\"\ncenter = 2"))
            .unwrap();
    assert_eq!(star.topology, Topology::Star { center: 2 });
    let a = star.adjacency().unwrap();
    assert!((0..4).filter(|&j| j != 2).all(|j| a[2 * 4 + j]));
    assert!(!a[1]);
    let e = err(&base.replace(ring, "[topology]\nkind = \"star\"\ncenter = 4"));
    assert!(e.contains("topology.center"), "{e}");
    // the name alone, as Python's replace takes it
    let line = Scenario::from_toml_str(
        &base
            .replace(ring, "")
            .replace("steps = 200", "steps = 200\ntopology = \"line\""),
    )
    .unwrap();
    assert_eq!(line.topology, Topology::Line);
    // a motion parameter of another kind
    let e = err(&base.replace("q2 = 0.0001", "q2 = 0.0001\nq = 1.0"));
    assert!(e.contains("q"), "{e}");
    // both node forms
    let e = err(&format!(
        "{base}\n[[nodes]]\nsensor = {{ kind = \"position\", sigma = [0.1, 0.1, 0.1] }}\n"
    ));
    assert!(e.contains("sensors") && e.contains("[[nodes]]"), "{e}");
    // a sensor key of another kind
    let mixed = std::fs::read_to_string(root().join("scenarios/mixed-3d.toml")).unwrap();
    let e = err(&mixed.replace("sigma_r = 0.05 }", "sigma_r = 0.05, sigma_b = 0.1 }"));
    assert!(e.contains("sigma_b"), "{e}");
    // every with times, a time that is no step's time
    let e = err(&mixed.replace("every = 5", "every = 5\ntimes = [1.0]"));
    assert!(e.contains("nodes[2].times"), "{e}");
    let e = err(&mixed.replace("times = [1.0, 2.0,", "times = [1.05, 2.0,"));
    assert!(e.contains("nodes[4].times[0]"), "{e}");
    // a 3-D sensor on a planar target
    let planar = std::fs::read_to_string(root().join("scenarios/bearing-only-2d.toml")).unwrap();
    let e = err(&planar.replace(
        "{ kind = \"bearing-only\", position = [20.0, 0.0], sigma_b = 0.01 }",
        "{ kind = \"position\", sigma = [0.1, 0.1, 0.1] }",
    ));
    assert!(e.contains("nodes[0].sensor"), "{e}");
    // one threshold per node
    let e = err(&mixed.replace(
        "delta = [0.04, 0.04, 0.01, 0.02, 0.01]",
        "delta = [0.04, 0.04]",
    ));
    assert!(e.contains("delta"), "{e}");
}

#[test]
fn every_catalogue_motion_and_sensor_runs() {
    let motions = [
        ("kind = \"coordinated-turn\"\nq1 = 0.5\nq2 = 0.0001", 7),
        ("kind = \"coordinated-turn-2d\"\nq1 = 0.5\nq2 = 0.0001", 5),
        ("kind = \"constant-velocity\"\nq = 0.5\ndim = 2", 4),
        ("kind = \"constant-velocity\"\nq = 0.5", 6),
        ("kind = \"constant-acceleration\"\nq = 0.5\ndim = 2", 6),
        ("kind = \"constant-acceleration\"\nq = 0.5", 9),
        ("kind = \"random-walk\"\nn = 3\nq = 0.1", 3),
        (
            "kind = \"linear\"\nf = [[1.0, 0.1], [0.0, 1.0]]\nq = [[0.001, 0.0], [0.0, 0.01]]",
            2,
        ),
    ];
    for (motion, n) in motions {
        let planar = matches!(n, 2 | 4 | 5) || motion.contains("dim = 2");
        let nodes = if n == 2 {
            "[[nodes]]\nsensor = { kind = \"linear\", h = [[1.0, 0.0]], r = [[0.01]] }\n\
             [[nodes]]\nsensor = { kind = \"linear\", h = [[1.0, 0.0]], r = [[0.04]] }\nevery = 2\n"
                .to_string()
        } else if planar {
            "[[nodes]]\nsensor = { kind = \"range-bearing\", position = [10.0, 0.0], sigma_r = 0.1, sigma_b = 0.01 }\n\
             [[nodes]]\nsensor = { kind = \"bearing-only\", position = [0.0, 10.0], sigma_b = 0.01 }\n\
             [[nodes]]\nsensor = { kind = \"range-only\", position = [-10.0, 0.0], sigma_r = 0.1 }\n\
             [[nodes]]\nsensor = { kind = \"position\", sigma = [0.1, 0.1] }\nevery = 3\n"
                .to_string()
        } else {
            "[[nodes]]\nsensor = { kind = \"range-pitch-azimuth\", position = [10.0, 0.0, 0.0], sigma_r = 0.1, sigma_a = 0.01 }\n\
             [[nodes]]\nsensor = { kind = \"range-only\", position = [0.0, 10.0, 1.0], sigma_r = 0.1 }\n\
             [[nodes]]\nsensor = { kind = \"position\", sigma = [0.1, 0.1, 0.1] }\ntimes = [0.5, 1.0, 1.5]\n"
                .to_string()
        };
        let x0: Vec<String> = (0..n)
            .map(|i| format!("{}", 0.1 * i as f64 + 1.0))
            .collect();
        let p0 = vec!["0.01"; n].join(", ");
        let text = format!(
            "name = \"t\"\ndt = 0.1\nsteps = 20\ndelta = 4.0\nnormalised = true\nsigma1 = 0.0005\nsigma2 = 0.0005\n\
             x0 = [{}]\np0_diag = [{p0}]\ntopology = \"complete\"\n\n[motion]\n{motion}\n\n{nodes}",
            x0.join(", ")
        );
        let sc = Scenario::from_toml_str(&text).unwrap_or_else(|e| panic!("{motion}: {e}"));
        sc.validate().unwrap_or_else(|e| panic!("{motion}: {e}"));
        assert_eq!(sc.state_dim(), n);
        let sim = simulate(&sc, 0).unwrap();
        for alg in [Algorithm::EdcCif, Algorithm::DcCif, Algorithm::CCkf] {
            let r = run(alg, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), false)
                .unwrap_or_else(|e| panic!("{motion} {}: {e}", alg.name()));
            assert!(r.estimates.iter().all(|v| v.is_finite()), "{motion}");
        }
    }
}
