//! Error paths: every failure is a named `Error` variant (matched with its `what`
//! text), and a failed `network_step` leaves every `NodeState` as it was.

use crate::common;

use common::*;
use edccif_core::fusion::{
    ci_fuse_optimal, combine_ci, combine_convex, consensus_iteration, max_degree_weights,
    validate_adjacency, CiCriterion,
};
use edccif_core::models::{CoordinatedTurn, LinearMeasurement, Position3, RangePitchAzimuth};
use edccif_core::nalgebra::{Matrix2, Matrix3, SMatrix, Vector2};
use edccif_core::{
    cif_local, cov_local, network_step, Error, EtGain, EtOptions, EtPolicy, Fusion, Gaussian,
    InfoPair, LocalFilter, NetworkConfig, NodeFilter, NodeScratch, NodeState, Observation,
    SigmaRule, StepInputs, Trigger, TriggerState,
};

fn nonfinite(what: &'static str) -> Error {
    Error::NonFinite { what }
}
fn not_pd(what: &'static str) -> Error {
    Error::NotPositiveDefinite { what }
}

/// A symmetric, finite, indefinite "covariance" (eigenvalues of the 2×2 block
/// [[1, 2], [2, 1]] are 3 and −1).
fn indefinite() -> Mat7 {
    let mut p = p0();
    p[(0, 0)] = 1.0;
    p[(1, 1)] = 1.0;
    p[(0, 1)] = 2.0;
    p[(1, 0)] = 2.0;
    p
}

#[test]
fn gaussian_new_rejects_bad_estimates() {
    let mut x = x0();
    x[3] = f64::NAN;
    assert_eq!(
        Gaussian::new(x, p0()).unwrap_err(),
        nonfinite("state estimate x")
    );
    let mut x = x0();
    x[0] = f64::INFINITY;
    assert_eq!(
        Gaussian::new(x, p0()).unwrap_err(),
        nonfinite("state estimate x")
    );
    let mut p = p0();
    p[(2, 2)] = f64::NAN;
    assert_eq!(
        Gaussian::new(x0(), p).unwrap_err(),
        nonfinite("covariance P")
    );
    assert_eq!(
        Gaussian::new(x0(), indefinite()).unwrap_err(),
        not_pd("covariance P")
    );
    assert_eq!(
        Gaussian::new(x0(), Mat7::zeros()).unwrap_err(),
        not_pd("covariance P")
    );
    let mut p = p0();
    p[(0, 1)] = 1e-3; // asymmetric far beyond the 1e-9 relative tolerance
    assert_eq!(
        Gaussian::new(x0(), p).unwrap_err(),
        Error::NotSymmetric {
            what: "covariance P"
        }
    );
    // The error's text names the quantity.
    assert_eq!(
        not_pd("covariance P").to_string(),
        "covariance P is not symmetric positive definite"
    );
    // Information form: a non-PD information matrix cannot be turned back.
    let info = InfoPair {
        y: x0(),
        ymat: indefinite(),
    };
    assert_eq!(
        info.to_gaussian().unwrap_err(),
        not_pd("information matrix Y")
    );
    let bad = Gaussian {
        x: x0(),
        p: indefinite(),
    };
    assert_eq!(bad.to_info().unwrap_err(), not_pd("covariance P"));
}

/// The local filters reject NaN measurements, NaN estimates and non-PD
/// covariances (built directly, bypassing `Gaussian::new`) with named errors.
#[test]
fn local_filters_reject_bad_inputs() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let ts = TriggerState::new(&trig);
    let opts = EtOptions::default();
    let good = Gaussian::new(x0(), p0()).unwrap();
    let z_ok = Observation::Measured(Vec3::new(5.0, 0.05, 3.1));
    let z_nan = Observation::Measured(Vec3::new(5.0, f64::NAN, 3.1));
    let mut x_nan = x0();
    x_nan[6] = f64::NAN;
    let est_nan = Gaussian { x: x_nan, p: p0() };
    let est_pnan = Gaussian {
        x: x0(),
        p: p0() * f64::NAN,
    };
    let est_npd = Gaussian {
        x: x0(),
        p: indefinite(),
    };

    let cases: [(&Gaussian<f64, 7>, &Observation<f64, 3>, Error); 4] = [
        (&good, &z_nan, nonfinite("measurement z")),
        (&est_nan, &z_ok, nonfinite("state estimate x")),
        (&est_pnan, &z_ok, nonfinite("covariance P")),
        (&est_npd, &z_ok, not_pd("covariance P")),
    ];
    for (est, z, want) in cases {
        let got = cif_local(&motion, 0.1, &sensor, est, z, &trig, &ts, &opts).unwrap_err();
        assert_eq!(got, want, "CIF");
        for f in [
            LocalFilter::Ckf,
            LocalFilter::Ekf,
            LocalFilter::ukf_default(),
        ] {
            let got = cov_local(&f, &motion, 0.1, &sensor, est, z, &trig, &ts, &opts).unwrap_err();
            assert_eq!(got, want, "{f:?}");
        }
    }
    // A NaN measurement in a step whose measurement is missing is not seen, and
    // a missing measurement is never an error.
    assert!(cif_local(
        &motion,
        0.1,
        &sensor,
        &good,
        &Observation::Missing,
        &trig,
        &ts,
        &opts
    )
    .is_ok());
}

/// Requirement 7: a failing `network_step` returns the named error and leaves
/// every node's state bit-for-bit unchanged — for failures in the local step of
/// the first, a middle and the last node, and in the fusion phase.
#[test]
fn network_step_errors_leave_nodes_unchanged() {
    let motion = ct();
    let sensors: [_; 4] = core::array::from_fn(|i| sensor_of(i, 4));
    let mut w = [0.0; 16];
    max_degree_weights(&ring::<16>(), 4, &mut w).unwrap();
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let mut rng = rng(200);
    let start = initial_estimate(&mut rng);
    let x1 = propagate(&mut rng, &motion, &x0());
    let obs: [_; 4] =
        core::array::from_fn(|i| Observation::Measured(measure(&mut rng, &sensors[i], &x1)));
    let configs = [
        NetworkConfig {
            filter: NodeFilter::Cif,
            trigger: sod,
            et: EtOptions::default(),
            fusion: Fusion::DiffusionCi,
            rule: Default::default(),
        },
        NetworkConfig {
            filter: NodeFilter::Cif,
            trigger: sod,
            et: EtOptions::default(),
            fusion: Fusion::DiffusionConvex,
            rule: Default::default(),
        },
        NetworkConfig {
            filter: NodeFilter::Cov(LocalFilter::Ckf),
            trigger: sod,
            et: EtOptions::default(),
            fusion: Fusion::Consensus { iterations: 5 },
            rule: Default::default(),
        },
    ];
    for cfg in &configs {
        // Warm up one good step so that the states are not the initial ones.
        let mut nodes = [NodeState::new(start, &sod); 4];
        let mut scratch = [NodeScratch::default(); 4];
        network_step(
            cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(&obs, 0.1),
        )
        .unwrap();

        let flat = |n: &[NodeState<f64, 7, 3>; 4]| -> Vec<f64> {
            n.iter()
                .flat_map(|s| {
                    let mut v: Vec<f64> = s
                        .estimate
                        .x
                        .iter()
                        .chain(s.estimate.p.iter())
                        .copied()
                        .collect();
                    if let Some(z) = s.trigger.last_sent {
                        v.extend(z.iter());
                    }
                    v.push(s.trigger.eta);
                    v
                })
                .collect()
        };
        let mut run = |nodes: &mut [NodeState<f64, 7, 3>; 4],
                       obs: &[Observation<f64, 3>; 4],
                       weights: &[f64],
                       want: Error,
                       tag: &str| {
            let before = *nodes;
            let bits = flat(nodes);
            let got = network_step(
                cfg,
                &motion,
                &sensors,
                weights,
                nodes,
                &mut scratch,
                &StepInputs::new(obs, 0.1),
            )
            .unwrap_err();
            assert_eq!(got, want, "{:?}: {tag}", cfg.fusion);
            assert!(
                same_bits(&bits, &flat(nodes)),
                "{:?}: {tag}: state changed",
                cfg.fusion
            );
            if bits.iter().all(|v| !v.is_nan()) {
                assert!(*nodes == before, "{:?}: {tag}: state changed", cfg.fusion);
            }
        };

        for bad in [0, 2, 3] {
            let mut o = obs;
            o[bad] = Observation::Measured(Vec3::new(f64::NAN, 0.0, 0.0));
            run(
                &mut nodes,
                &o,
                &w,
                nonfinite("measurement z"),
                &format!("NaN z at node {bad}"),
            );

            let mut n = nodes;
            n[bad].estimate.x[1] = f64::NAN;
            run(
                &mut n,
                &obs,
                &w,
                nonfinite("state estimate x"),
                &format!("NaN x at node {bad}"),
            );

            let mut n = nodes;
            n[bad].estimate.p = indefinite();
            run(
                &mut n,
                &obs,
                &w,
                not_pd("covariance P"),
                &format!("non-PD P at node {bad}"),
            );
        }
        // Fusion-phase failure: a negative self-weight of the last node is only
        // seen after every local step has succeeded.
        let mut wbad = w;
        wbad[15] = -0.5;
        run(
            &mut nodes,
            &obs,
            &wbad,
            Error::InvalidParameter {
                what: "fusion weight",
                expected: "finite and >= 0",
            },
            "negative weight",
        );
        // And the same nodes still step fine afterwards.
        network_step(
            cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(&obs, 0.1),
        )
        .unwrap();
    }
}

/// A consensus round between the first and the last that overflows (finite
/// information matrices whose weighted sum exceeds `f64::MAX`) is reported as
/// the non-finite combined pair of that round, and no node's state changes.
///
/// Path 0 – 1 – 2; node 2 is very sure of itself (`P = 1e-300·I`, so
/// `Y ≈ 1e300·I`), nodes 0 and 1 are not (`P = I`). Round 0 stays finite
/// everywhere (node 0 sums `1 + 1e10·1`); node 1's round-0 average is
/// `≈ Y₂/3`, so in round 1 node 0's weight `1e10` on it overflows.
#[test]
fn consensus_overflow_in_a_middle_round_is_named_and_leaves_nodes_unchanged() {
    use edccif_core::models::{LinearMotion, Position3};
    type M4 = SMatrix<f64, 4, 4>;
    let motion = LinearMotion::new(M4::identity(), M4::zeros()).unwrap();
    let sensors = [Position3::new([0.1; 3]).unwrap(); 3];
    #[rustfmt::skip]
    let w = [
        1.0, 1e10, 0.0,
        1.0, 1.0,  1.0,
        0.0, 1.0,  1.0,
    ];
    let trigger = Trigger::Always;
    let cfg = NetworkConfig {
        filter: NodeFilter::Cif,
        trigger,
        et: EtOptions::default(),
        fusion: Fusion::Consensus { iterations: 3 },
        rule: Default::default(),
    };
    let zero = edccif_core::nalgebra::SVector::<f64, 4>::zeros();
    let unsure = Gaussian::new(zero, M4::identity()).unwrap();
    let sure = Gaussian::new(zero, M4::identity() * 1e-300).unwrap();
    let mut nodes = [
        NodeState::<f64, 4, 3>::new(unsure, &trigger),
        NodeState::new(unsure, &trigger),
        NodeState::new(sure, &trigger),
    ];
    let before = nodes;
    let mut scratch = [NodeScratch::default(); 3];
    let obs = [Observation::Measured(edccif_core::nalgebra::Vector3::zeros()); 3];
    let step = |iterations, nodes: &mut [NodeState<f64, 4, 3>; 3], scratch: &mut [_; 3]| {
        let cfg = NetworkConfig {
            fusion: Fusion::Consensus { iterations },
            ..cfg
        };
        network_step(
            &cfg,
            &motion,
            &sensors,
            &w,
            nodes,
            scratch,
            &StepInputs::new(&obs, 0.1),
        )
    };
    // One round is fine: the overflow needs the second.
    let mut once = nodes;
    step(1, &mut once, &mut scratch).unwrap();
    assert!(once
        .iter()
        .all(|n| n.estimate.p.iter().all(|v| v.is_finite())));

    let e = step(3, &mut nodes, &mut scratch).unwrap_err();
    assert_eq!(e, nonfinite("combined information matrix Y"));
    assert!(nodes == before, "a failed step changed a node's state");
}

#[test]
fn max_degree_weights_rejects_bad_graphs() {
    let mut out = [0.0f64; 9];
    // 0 - 1, 2 isolated.
    let disconnected = [false, true, false, true, false, false, false, false, false];
    assert_eq!(
        max_degree_weights(&disconnected, 3, &mut out).unwrap_err(),
        Error::DisconnectedGraph { unreachable: 2 }
    );
    let self_loop = [false, true, false, true, true, true, false, true, false];
    assert_eq!(
        max_degree_weights(&self_loop, 3, &mut out).unwrap_err(),
        Error::InvalidGraph {
            what: "self-loop",
            row: 1,
            col: 1
        }
    );
    let asymmetric = [false, true, true, true, false, true, false, true, false];
    assert_eq!(
        max_degree_weights(&asymmetric, 3, &mut out).unwrap_err(),
        Error::InvalidGraph {
            what: "asymmetric edge",
            row: 0,
            col: 2
        }
    );
    let path = [false, true, false, true, false, true, false, true, false];
    assert_eq!(
        max_degree_weights(&path[..8], 3, &mut out).unwrap_err(),
        Error::Dimension {
            what: "adjacency matrix (row-major, nodes × nodes)",
            expected: 9,
            got: 8
        }
    );
    assert_eq!(
        max_degree_weights(&path, 3, &mut out[..4]).unwrap_err(),
        Error::Dimension {
            what: "weight buffer",
            expected: 9,
            got: 4
        }
    );
    assert_eq!(
        validate_adjacency(&[], 0).unwrap_err(),
        Error::Dimension {
            what: "number of nodes",
            expected: 1,
            got: 0
        }
    );
    // A single node is a valid (trivially connected) graph with weight 1.
    let mut one = [0.0f64];
    max_degree_weights(&[false], 1, &mut one).unwrap();
    assert_eq!(one, [1.0]);
}

/// Requirement 7: wrong slice lengths in `network_step` are `Error::Dimension`
/// naming the argument, checked before anything is computed.
#[test]
fn network_step_rejects_wrong_lengths() {
    let motion = ct();
    let sensors: [_; 3] = core::array::from_fn(|i| sensor_of(i, 3));
    let mut w = [0.0; 9];
    max_degree_weights(
        &[false, true, true, true, false, true, true, true, false],
        3,
        &mut w,
    )
    .unwrap();
    let cfg = NetworkConfig {
        filter: NodeFilter::Cif,
        trigger: Trigger::SendOnDelta { delta: 0.04 },
        et: EtOptions::default(),
        fusion: Fusion::DiffusionCi,
        rule: Default::default(),
    };
    let start = Gaussian::new(x0(), p0()).unwrap();
    let mut nodes = [NodeState::new(start, &cfg.trigger); 3];
    let before = nodes;
    let mut scratch = [NodeScratch::default(); 3];
    let obs = [Observation::Missing; 3];
    let dim = |what, expected, got| Error::Dimension {
        what,
        expected,
        got,
    };

    let e = network_step(
        &cfg,
        &motion,
        &sensors[..2],
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs, 0.1),
    );
    assert_eq!(e.unwrap_err(), dim("sensors", 3, 2));
    let e = network_step(
        &cfg,
        &motion,
        &sensors,
        &w[..8],
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs, 0.1),
    );
    assert_eq!(e.unwrap_err(), dim("weight matrix (nodes × nodes)", 9, 8));
    let e = network_step(
        &cfg,
        &motion,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch[..1],
        &StepInputs::new(&obs, 0.1),
    );
    assert_eq!(e.unwrap_err(), dim("scratch buffers", 3, 1));
    let e = network_step(
        &cfg,
        &motion,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs[..2], 0.1),
    );
    assert_eq!(e.unwrap_err(), dim("observations", 3, 2));
    let links = [true; 8];
    let inputs = StepInputs {
        dt: 0.1,
        observations: &obs,
        links: Some(&links),
        edge_links: None,
        active: None,
        deltas: None,
    };
    let e = network_step(
        &cfg,
        &motion,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch,
        &inputs,
    );
    assert_eq!(e.unwrap_err(), dim("link mask (nodes × nodes)", 9, 8));
    let active = [true; 4];
    let inputs = StepInputs {
        dt: 0.1,
        observations: &obs,
        links: None,
        edge_links: None,
        active: Some(&active),
        deltas: None,
    };
    let e = network_step(
        &cfg,
        &motion,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch,
        &inputs,
    );
    assert_eq!(e.unwrap_err(), dim("active mask", 3, 4));
    assert_eq!(nodes, before);

    // consensus_iteration and the CI optimiser check their buffers too.
    let info = start.to_info().unwrap();
    let cur = [info; 3];
    let mut next = [info; 2];
    assert_eq!(
        consensus_iteration(&w, &cur, &mut next).unwrap_err(),
        dim("consensus output buffer", 3, 2)
    );
    let mut next = [info; 3];
    assert_eq!(
        consensus_iteration(&w[..4], &cur, &mut next).unwrap_err(),
        dim("weight matrix", 9, 4)
    );
    let mut wts = [0.0; 2];
    assert_eq!(
        ci_fuse_optimal(&cur, CiCriterion::Trace, &mut wts).unwrap_err(),
        dim("CI weight buffer", 3, 2)
    );
    assert_eq!(
        ci_fuse_optimal::<f64, 7>(&[], CiCriterion::Trace, &mut []).unwrap_err(),
        dim("CI inputs", 1, 0)
    );
}

/// Requirement 7: invalid trigger and gain parameters are
/// `Error::InvalidParameter` naming the parameter.
#[test]
fn invalid_parameters_are_rejected() {
    let inv = |what, expected| Error::InvalidParameter { what, expected };
    for delta in [0.0, -0.04, f64::NAN, f64::INFINITY] {
        assert_eq!(
            Trigger::SendOnDelta { delta }.validate().unwrap_err(),
            inv("delta", "finite and > 0"),
            "delta = {delta}"
        );
        assert_eq!(
            Trigger::dynamic(delta).validate().unwrap_err(),
            inv("delta", "finite and > 0")
        );
    }
    assert!(Trigger::SendOnDelta { delta: 0.04 }.validate().is_ok());
    assert!(Trigger::<f64>::Always.validate().is_ok());
    assert!(Trigger::<f64>::Never.validate().is_ok());
    let dynamic = |lambda, theta| Trigger::Dynamic {
        delta: 0.04,
        lambda,
        theta,
    };
    assert_eq!(
        dynamic(1.0, 2.0).validate().unwrap_err(),
        inv("lambda", "in [0, 1)")
    );
    assert_eq!(
        dynamic(-0.1, 2.0).validate().unwrap_err(),
        inv("lambda", "in [0, 1)")
    );
    assert_eq!(
        dynamic(f64::NAN, 2.0).validate().unwrap_err(),
        inv("lambda", "in [0, 1)")
    );
    assert_eq!(
        dynamic(0.9, 0.0).validate().unwrap_err(),
        inv("theta", "finite and > 0")
    );
    assert!(dynamic(0.0, 2.0).validate().is_ok());

    let et = |sigma1, sigma2| EtOptions {
        policy: EtPolicy::Optimal,
        sigma1,
        sigma2,
        gate: None,
        untriggered_closed_form: false,
    };
    assert_eq!(
        et(0.0, 1e-3).validate().unwrap_err(),
        inv("sigma1", "finite and > 0")
    );
    assert_eq!(
        et(1e-3, f64::NAN).validate().unwrap_err(),
        inv("sigma2", "finite and > 0")
    );
    assert_eq!(
        et(-1.0, -1.0).validate().unwrap_err(),
        inv("sigma1", "finite and > 0")
    );

    // The gain checks its own inputs.
    let p = Matrix2::<f64>::identity();
    let g = edccif_core::nalgebra::Matrix1x2::new(1.0, 0.0);
    let r = edccif_core::nalgebra::Matrix1::new(0.1);
    assert_eq!(
        EtGain::new(&p, &g, &r, -1.0, &EtOptions::default()).unwrap_err(),
        inv("delta", "finite and >= 0")
    );
    assert_eq!(
        EtGain::new(&p, &g, &r, 0.04, &et(0.0, 1.0)).unwrap_err(),
        inv("sigma1", "finite and > 0")
    );
    let g_nan = edccif_core::nalgebra::Matrix1x2::new(f64::NAN, 0.0);
    assert_eq!(
        EtGain::new(&p, &g_nan, &r, 0.04, &EtOptions::default()).unwrap_err(),
        nonfinite("measurement Jacobian G")
    );

    // Models.
    assert_eq!(
        CoordinatedTurn::new(-0.5, 1e-4).unwrap_err(),
        inv("q1", "finite and >= 0")
    );
    assert_eq!(
        RangePitchAzimuth::new([0.0; 3], 0.0, 0.01).unwrap_err(),
        inv("sigma_r", "finite and > 0")
    );
    assert_eq!(
        RangePitchAzimuth::new([f64::NAN, 0.0, 0.0], 0.1, 0.01).unwrap_err(),
        nonfinite("sensor position")
    );
    assert_eq!(
        Position3::with_covariance(Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0))
            .unwrap_err(),
        not_pd("measurement noise R")
    );
    assert_eq!(
        LinearMeasurement::<f64, 2, 2>::new(Matrix2::identity(), Matrix2::new(1.0, 0.5, 0.0, 1.0))
            .unwrap_err(),
        Error::NotSymmetric {
            what: "measurement noise R"
        }
    );
    assert_eq!(
        SigmaRule::<f64>::unscented(7, 0.0, 2.0, 0.0).unwrap_err(),
        inv(
            "unscented (alpha, beta, kappa)",
            "finite, with alpha^2 (n + kappa) > 0"
        )
    );

    // Fusion weights.
    let a = Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::identity()).unwrap();
    let ai = a.to_info().unwrap();
    assert_eq!(
        combine_ci([(0.0, &ai), (0.0, &ai)]).unwrap_err(),
        inv("fusion weights", "a positive sum")
    );
    assert_eq!(
        combine_ci([(f64::NAN, &ai)]).unwrap_err(),
        inv("fusion weight", "finite and >= 0")
    );
    assert_eq!(
        combine_convex([(-1.0, &a), (2.0, &a)]).unwrap_err(),
        inv("fusion weight", "finite and >= 0")
    );
    assert_eq!(
        combine_convex::<f64, 2>([]).unwrap_err(),
        inv("fusion weights", "a positive sum")
    );
}

/// Requirement 7: `NetworkConfig::validate` rejects diffusion with a
/// covariance-form filter, zero consensus iterations and bad parameters; and
/// `network_step` applies the same validation (a step with an invalid
/// configuration fails before touching anything).
#[test]
fn network_config_validation() {
    let cfg = |filter, trigger, fusion| NetworkConfig {
        filter,
        trigger,
        et: EtOptions::default(),
        fusion,
        rule: Default::default(),
    };
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let diffusion_needs_cif = Error::InvalidParameter {
        what: "fusion",
        expected: "consensus or local for a covariance-form filter (diffusion needs the CIF)",
    };
    for f in [
        LocalFilter::Ckf,
        LocalFilter::Ekf,
        LocalFilter::ukf_default(),
    ] {
        for fusion in [Fusion::DiffusionCi, Fusion::DiffusionConvex] {
            assert_eq!(
                cfg(NodeFilter::Cov(f), sod, fusion).validate().unwrap_err(),
                diffusion_needs_cif
            );
        }
        assert!(
            cfg(NodeFilter::Cov(f), sod, Fusion::Consensus { iterations: 5 })
                .validate()
                .is_ok()
        );
        assert!(cfg(NodeFilter::Cov(f), sod, Fusion::Local)
            .validate()
            .is_ok());
    }
    assert_eq!(
        cfg(NodeFilter::Cif, sod, Fusion::Consensus { iterations: 0 })
            .validate()
            .unwrap_err(),
        Error::InvalidParameter {
            what: "consensus iterations",
            expected: ">= 1"
        }
    );
    let bad_delta = Trigger::SendOnDelta { delta: -1.0 };
    assert_eq!(
        cfg(NodeFilter::Cif, bad_delta, Fusion::DiffusionCi)
            .validate()
            .unwrap_err(),
        Error::InvalidParameter {
            what: "delta",
            expected: "finite and > 0"
        }
    );
    let mut c = cfg(NodeFilter::Cif, sod, Fusion::DiffusionCi);
    c.et.sigma2 = 0.0;
    assert_eq!(
        c.validate().unwrap_err(),
        Error::InvalidParameter {
            what: "sigma2",
            expected: "finite and > 0"
        }
    );
    let bad_ukf = LocalFilter::Ukf {
        alpha: f64::NAN,
        beta: 2.0,
        kappa: 0.0,
    };
    assert!(cfg(NodeFilter::Cov(bad_ukf), sod, Fusion::Local)
        .validate()
        .is_err());

    // network_step validates the configuration it is given.
    let motion = ct();
    let sensors = [sensor_of(0, 2), sensor_of(1, 2)];
    let w = [0.5, 0.5, 0.5, 0.5];
    let start = Gaussian::new(x0(), p0()).unwrap();
    let obs = [Observation::Measured(Vec3::new(5.0, 0.0, 3.0)); 2];
    for (bad, want) in [
        (
            cfg(NodeFilter::Cov(LocalFilter::Ckf), sod, Fusion::DiffusionCi),
            diffusion_needs_cif,
        ),
        (
            cfg(NodeFilter::Cif, bad_delta, Fusion::DiffusionCi),
            Error::InvalidParameter {
                what: "delta",
                expected: "finite and > 0",
            },
        ),
        (
            cfg(NodeFilter::Cif, sod, Fusion::Consensus { iterations: 0 }),
            Error::InvalidParameter {
                what: "consensus iterations",
                expected: ">= 1",
            },
        ),
    ] {
        let mut nodes = [NodeState::new(start, &sod); 2];
        let before = nodes;
        let mut scratch = [NodeScratch::default(); 2];
        let got = network_step(
            &bad,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(&obs, 0.1),
        );
        assert_eq!(got.unwrap_err(), want);
        assert_eq!(nodes, before);
    }
}

/// Numerically impossible inputs surface as named errors, never as NaN output:
/// a Pzz that is not PD in `kalman_update`, a CI combination of indefinite
/// information.
#[test]
fn impossible_numerics_are_named_errors() {
    let x = Vector2::new(0.0, 0.0);
    let p = Matrix2::identity();
    let pxz = SMatrix::<f64, 2, 1>::new(1.0, 0.0);
    let pzz = edccif_core::nalgebra::Matrix1::new(-1.0);
    let dz = edccif_core::nalgebra::Vector1::new(0.5);
    assert_eq!(
        edccif_core::kalman_update(&x, &p, &pxz, &pzz, &dz).unwrap_err(),
        not_pd("innovation covariance Pzz")
    );
    let neg = InfoPair {
        y: Vector2::new(1.0, 0.0),
        ymat: -Matrix2::identity(),
    };
    assert_eq!(
        combine_ci([(1.0, &neg)]).unwrap_err(),
        not_pd("information matrix Y")
    );
    let mut w = [0.5];
    assert_eq!(
        ci_fuse_optimal(&[neg], CiCriterion::Determinant, &mut w).unwrap_err(),
        not_pd("CI fused information at the starting weights")
    );
}
