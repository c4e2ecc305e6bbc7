//! Whole-network tests of `network_step` (ALGORITHM.md §4, §5): one-node
//! diffusion is the local filter, a multi-node step is the composition of the
//! public pieces (cif_local → adapt → combine_ci / combine_convex; cov_local →
//! consensus_iteration), masks for lost links and inactive nodes, the adaptation
//! guard, and a target crossing azimuth ±π.

use crate::common;

use common::*;
use edccif_core::fusion::{
    adapt, combine_ci, combine_convex, consensus_iteration, max_degree_weights,
};
use edccif_core::models::RangePitchAzimuth;
use edccif_core::{
    cif_local, cov_local, network_step, EtOptions, EtPolicy, Fusion, Gaussian, InfoPair,
    LocalFilter, MeasurementModel, MotionModel, NetworkConfig, NodeFilter, NodeScratch, NodeState,
    Observation, StepInputs, Trigger, TriggerState,
};

fn config(filter: NodeFilter<f64>, trigger: Trigger<f64>, fusion: Fusion) -> NetworkConfig<f64> {
    NetworkConfig {
        filter,
        trigger,
        et: EtOptions::default(),
        fusion,
        rule: Default::default(),
    }
}

/// Requirement 4: a one-node network (weights [1.0]) with diffusion — with or
/// without CI — or with no fusion is exactly the local ET-CIF (`cif_local` and its
/// local posterior), bit for bit: with a single node the adaptation adds no
/// neighbour and the combination multiplies by 1. 40 steps with send-on-delta
/// (both branches) and some missing measurements.
#[test]
fn one_node_diffusion_equals_local_filter() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let mut rng = rng(100);
    let start = initial_estimate(&mut rng);
    let (_, mut obs) = simulate(&mut rng, &motion, &sensor, &x0(), 40);
    obs[7] = Observation::Missing;
    obs[23] = Observation::Missing;
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    for fusion in [Fusion::DiffusionCi, Fusion::DiffusionConvex, Fusion::Local] {
        let cfg = config(NodeFilter::Cif, trig, fusion);
        let mut nodes = [NodeState::new(start, &trig)];
        let mut scratch = [NodeScratch::default()];
        let (mut est, mut ts) = (start, TriggerState::new(&trig));
        let (mut sent, mut untriggered) = (0, 0);
        for (k, z) in obs.iter().enumerate() {
            let rep = network_step(
                &cfg,
                &motion,
                &[sensor],
                &[1.0],
                &mut nodes,
                &mut scratch,
                &StepInputs::new(core::slice::from_ref(z), 0.1),
            )
            .unwrap();
            let r = cif_local(&motion, 0.1, &sensor, &est, z, &trig, &ts, &cfg.et).unwrap();
            est = r.local_posterior().to_gaussian().unwrap();
            ts = r.trigger_state;
            assert_eq!(nodes[0].estimate, est, "{fusion:?}, step {k}");
            assert_eq!(nodes[0].trigger, ts, "{fusion:?}, step {k}");
            assert_eq!(scratch[0].triggered, r.triggered);
            assert_eq!(rep.measured, usize::from(r.triggered.is_some()));
            assert_eq!(rep.triggered, usize::from(r.triggered == Some(true)));
            assert_eq!(rep.guard_fallbacks, 0);
            sent += usize::from(r.triggered == Some(true));
            untriggered += usize::from(r.triggered == Some(false));
        }
        assert!(
            sent > 0 && untriggered > 0,
            "both trigger branches must occur"
        );
    }
}

/// A reference network step written from ALGORITHM.md §4/§5 with the public
/// pieces, for `K` nodes: returns the fused estimates and trigger states.
#[allow(clippy::too_many_arguments)]
fn reference_step(
    cfg: &NetworkConfig<f64>,
    sensors: &[RangePitchAzimuth<f64>],
    weights: &[f64],
    nodes: &[NodeState<f64, 7, 3>],
    obs: &[Observation<f64, 3>],
    links: Option<&[bool]>,
    active: Option<&[bool]>,
) -> Vec<NodeState<f64, 7, 3>> {
    let motion = ct();
    let k = nodes.len();
    let up = |i: usize| active.is_none_or(|a| a[i]);
    let hears = |i: usize, j: usize| {
        i != j && weights[i * k + j] > 0.0 && up(j) && links.is_none_or(|l| l[i * k + j])
    };
    let mut out = nodes.to_vec();
    match cfg.filter {
        NodeFilter::Cif => {
            let local: Vec<_> = (0..k)
                .map(|i| {
                    let n = &nodes[i];
                    cif_local(
                        &motion,
                        0.1,
                        &sensors[i],
                        &n.estimate,
                        &obs[i],
                        &cfg.trigger,
                        &n.trigger,
                        &cfg.et,
                    )
                    .unwrap()
                })
                .collect();
            // Adaptation (with the §4 guard).
            let adapted: Vec<(InfoPair<f64, 7>, Gaussian<f64, 7>)> = (0..k)
                .map(|i| {
                    let a = adapt(
                        &local[i].prior,
                        &local[i].contribution,
                        (0..k)
                            .filter(|&j| hears(i, j))
                            .map(|j| &local[j].contribution),
                    );
                    match a.to_gaussian() {
                        Ok(g) => (a, g),
                        Err(_) => {
                            let l = local[i].local_posterior();
                            (l, l.to_gaussian().unwrap())
                        }
                    }
                })
                .collect();
            for i in (0..k).filter(|&i| up(i)) {
                let members = (0..k).filter(|&j| j == i || hears(i, j));
                out[i].estimate = match cfg.fusion {
                    Fusion::DiffusionCi => {
                        combine_ci(members.map(|j| (weights[i * k + j], &adapted[j].0))).unwrap()
                    }
                    Fusion::DiffusionConvex => {
                        combine_convex(members.map(|j| (weights[i * k + j], &adapted[j].1)))
                            .unwrap()
                    }
                    _ => unreachable!("reference covers diffusion only for the CIF"),
                };
                out[i].trigger = local[i].trigger_state;
            }
        }
        NodeFilter::Cov(f) => {
            let Fusion::Consensus { iterations } = cfg.fusion else {
                unreachable!()
            };
            assert!(
                links.is_none() && active.is_none(),
                "reference: consensus without masks"
            );
            let local: Vec<_> = (0..k)
                .map(|i| {
                    let n = &nodes[i];
                    cov_local(
                        &f,
                        &motion,
                        0.1,
                        &sensors[i],
                        &n.estimate,
                        &obs[i],
                        &cfg.trigger,
                        &n.trigger,
                        &cfg.et,
                    )
                    .unwrap()
                })
                .collect();
            let mut cur: Vec<_> = local
                .iter()
                .map(|l| l.posterior.to_info().unwrap())
                .collect();
            let mut next = cur.clone();
            for _ in 0..iterations {
                consensus_iteration(weights, &cur, &mut next).unwrap();
                core::mem::swap(&mut cur, &mut next);
            }
            for i in 0..k {
                out[i].estimate = cur[i].to_gaussian().unwrap();
                out[i].trigger = local[i].trigger_state;
            }
        }
    }
    out
}

/// The 4-node default scenario: sensors, ring weights, initial estimate and
/// the observations of every step.
type FourNodes = (
    [RangePitchAzimuth<f64>; 4],
    [f64; 16],
    Gaussian<f64, 7>,
    Vec<[Observation<f64, 3>; 4]>,
);

fn four_nodes(seed: u64, steps: usize) -> FourNodes {
    let sensors: [_; 4] = core::array::from_fn(|i| sensor_of(i, 4));
    let mut w = [0.0; 16];
    max_degree_weights(&ring::<16>(), 4, &mut w).unwrap();
    let mut rng = rng(seed);
    let start = initial_estimate(&mut rng);
    let motion = ct();
    let mut x = x0();
    let obs = (0..steps)
        .map(|_| {
            x = propagate(&mut rng, &motion, &x);
            core::array::from_fn(|i| Observation::Measured(measure(&mut rng, &sensors[i], &x)))
        })
        .collect();
    (sensors, w, start, obs)
}

/// A 4-node ring step of every fusion row equals the composition of the public
/// pieces written from the contract (bit for bit: same operations, same order),
/// over 25 steps, including steps with lost links and a node that is down.
#[test]
fn network_step_is_composition_of_its_parts() {
    let motion = ct();
    let (sensors, w, start, obs) = four_nodes(101, 25);
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let configs = [
        config(NodeFilter::Cif, sod, Fusion::DiffusionCi),
        config(NodeFilter::Cif, Trigger::Always, Fusion::DiffusionConvex),
        config(
            NodeFilter::Cov(LocalFilter::Ckf),
            sod,
            Fusion::Consensus { iterations: 5 },
        ),
        config(
            NodeFilter::Cov(LocalFilter::Ekf),
            sod,
            Fusion::Consensus { iterations: 2 },
        ),
        config(
            NodeFilter::Cov(LocalFilter::ukf_default()),
            Trigger::dynamic(0.04),
            Fusion::Consensus { iterations: 5 },
        ),
    ];
    // Step 5: 1 does not hear 2; 3 does not hear 0. Step 9: node 2 is down.
    let mut lost = [true; 16];
    lost[4 + 2] = false;
    lost[3 * 4] = false;
    let down = [true, true, false, true];
    for cfg in &configs {
        cfg.validate().unwrap();
        let mut nodes = [NodeState::new(start, &cfg.trigger); 4];
        let mut scratch = [NodeScratch::default(); 4];
        let diffusion = matches!(cfg.filter, NodeFilter::Cif);
        for (k, z) in obs.iter().enumerate() {
            let links = (diffusion && k == 5).then_some(&lost[..]);
            let active = (diffusion && k == 9).then_some(&down[..]);
            let expect = reference_step(cfg, &sensors, &w, &nodes, z, links, active);
            let inputs = StepInputs {
                dt: 0.1,
                observations: z,
                links,
                edge_links: None,
                active,
                deltas: None,
            };
            let before = nodes;
            let rep = network_step(
                cfg,
                &motion,
                &sensors,
                &w,
                &mut nodes,
                &mut scratch,
                &inputs,
            )
            .unwrap();
            assert_eq!(nodes.to_vec(), expect, "{:?} step {k}", cfg.fusion);
            if active.is_some() {
                assert_eq!(nodes[2], before[2], "a node that is down keeps its state");
                assert_eq!(scratch[2].triggered, None);
                assert_eq!(rep.measured, 3);
            } else {
                assert_eq!(rep.measured, 4);
            }
            let sent = scratch.iter().filter(|s| s.triggered == Some(true)).count();
            assert_eq!(rep.triggered, sent);
        }
    }
}

/// The adaptation guard (ALGORITHM.md §4): with σ1 = σ2 = 0.5 the neighbours'
/// untriggered contributions can make the adapted information indefinite. Then
/// the node falls back to its local-only posterior, reports it, and never
/// outputs a non-PD covariance. The seed is chosen so that the guard fires.
#[test]
fn adaptation_guard_falls_back_to_local_posterior() {
    let motion = ct();
    let (sensors, w, start, obs) = four_nodes(102, 200);
    let mut cfg = config(
        NodeFilter::Cif,
        Trigger::SendOnDelta { delta: 0.04 },
        Fusion::DiffusionCi,
    );
    cfg.et = EtOptions {
        policy: EtPolicy::Optimal,
        sigma1: 0.5,
        sigma2: 0.5,
        gate: None,
        untriggered_closed_form: false,
    };
    let mut nodes = [NodeState::new(start, &cfg.trigger); 4];
    let mut scratch = [NodeScratch::default(); 4];
    let mut fallbacks = 0;
    for z in &obs {
        let rep = network_step(
            &cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(z, 0.1),
        )
        .unwrap();
        assert_eq!(
            rep.guard_fallbacks,
            scratch.iter().filter(|s| s.guard_used).count()
        );
        fallbacks += rep.guard_fallbacks;
        for (n, s) in nodes.iter().zip(&scratch) {
            assert!(
                n.estimate.p.cholesky().is_some(),
                "fused covariance must stay PD"
            );
            assert!(n.estimate.x.iter().all(|v| v.is_finite()));
            if s.guard_used {
                let local_only = InfoPair {
                    y: s.prior().y + s.contribution().i,
                    ymat: edccif_core::linalg::sym(&(s.prior().ymat + s.contribution().imat)),
                };
                assert_eq!(*s.local(), local_only);
                assert_eq!(s.post, local_only.to_gaussian().unwrap());
            }
        }
    }
    assert!(fallbacks > 0, "the guard never fired; pick another seed");
}

/// Requirement 6: a target whose azimuth from the sensor crosses ±π. The sensor is
/// at (10, 0, 0) and the target circles the origin on the radius-5 circle of §6
/// (noise-free motion), starting at polar angle π − 0.9: it passes (−5, 0), right
/// behind the origin, where `atan2(dy, dx)` jumps from +π to −π. 60 steps (the
/// crossing is near step 30), noisy measurements (wrapped), seeded.
///
/// Bounds (position error ‖p̂ − p‖ at every step, and no NaN):
/// - γ ≡ 1 (CIF, CKF, EKF, UKF): < 0.5 m. The position std is ≈ 0.15 m here; an
///   unwrapped azimuth innovation of ≈ 2π at range 15 m would throw the estimate
///   off by metres.
/// - send-on-delta, δ = 0.04 (one-node EDC-CIF network, ET-CKF, ET-EKF, ET-UKF):
///   < 1.0 m and < 3·σ_pos (σ_pos = √tr P_pos of the filter's own covariance).
///   Near the crossing the range barely changes, so the trigger stays silent for
///   up to ~17 steps of near-pure prediction (q1 = 0.5), and the error grows to
///   ≈ 0.6 m while σ_pos grows to ≈ 1.4 m; the seeded run peaks at 1.65 σ_pos.
#[test]
fn azimuth_crossing_pi_keeps_error_bounded() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let th: f64 = core::f64::consts::PI - 0.9;
    let start_truth = Vec7::from([
        5.0 * th.cos(),
        5.0 * th.sin(),
        1.0,
        -1.5 * th.sin(),
        1.5 * th.cos(),
        0.1,
        0.3,
    ]);
    let mut rng = rng(103);
    let start = Gaussian::new(start_truth + sample(&mut rng, &p0()), p0()).unwrap();
    let mut truth = Vec::new();
    let mut obs = Vec::new();
    let mut x = start_truth;
    for _ in 0..60 {
        x = motion.transition(&x, 0.1);
        truth.push(x);
        obs.push(Observation::Measured(measure(&mut rng, &sensor, &x)));
    }
    // The geometry really crosses ±π, and so do the (wrapped) measurements.
    let az: Vec<f64> = truth
        .iter()
        .map(|x| MeasurementModel::<f64, 7, 3>::measure(&sensor, x)[2])
        .collect();
    let crossings = az.windows(2).filter(|p| p[0] > 3.0 && p[1] < -3.0).count();
    assert_eq!(crossings, 1, "the target must cross azimuth ±π once");

    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let opts = EtOptions::default();
    let check = |name: &str, k: usize, g: &Gaussian<f64, 7>, event_triggered: bool| {
        assert!(
            g.x.iter().chain(g.p.iter()).all(|v| v.is_finite()),
            "{name}: NaN at step {k}"
        );
        let e = (g.x - truth[k]).fixed_rows::<3>(0).norm();
        if event_triggered {
            let sigma = g.p.fixed_view::<3, 3>(0, 0).trace().sqrt();
            assert!(e < 1.0, "{name}: position error {e:.3} m ≥ 1 m at step {k}");
            assert!(
                e < 3.0 * sigma,
                "{name}: error {e:.3} m ≥ 3σ = {:.3} m at step {k}",
                3.0 * sigma
            );
        } else {
            assert!(
                e < 0.5,
                "{name}: position error {e:.3} m ≥ 0.5 m at step {k}"
            );
        }
    };

    // CIF, γ ≡ 1.
    let (mut g, mut ts) = (start, TriggerState::new(&Trigger::Always));
    for (k, z) in obs.iter().enumerate() {
        let r = cif_local(&motion, 0.1, &sensor, &g, z, &Trigger::Always, &ts, &opts).unwrap();
        g = r.local_posterior().to_gaussian().unwrap();
        ts = r.trigger_state;
        check("CIF", k, &g, false);
    }
    // One-node EDC-CIF network.
    let cfg = config(NodeFilter::Cif, sod, Fusion::DiffusionCi);
    let mut nodes = [NodeState::new(start, &sod)];
    let mut scratch = [NodeScratch::default()];
    let mut sent = 0;
    for (k, z) in obs.iter().enumerate() {
        let inputs = StepInputs::new(core::slice::from_ref(z), 0.1);
        let rep = network_step(
            &cfg,
            &motion,
            &[sensor],
            &[1.0],
            &mut nodes,
            &mut scratch,
            &inputs,
        )
        .unwrap();
        sent += rep.triggered;
        check("EDC-CIF (1 node)", k, &nodes[0].estimate, true);
    }
    assert!(sent > 1 && sent < 60);
    // Covariance-form filters, with and without the trigger.
    for filt in [
        LocalFilter::Ckf,
        LocalFilter::Ekf,
        LocalFilter::ukf_default(),
    ] {
        for trig in [Trigger::Always, sod] {
            let (mut g, mut ts) = (start, TriggerState::new(&trig));
            for (k, z) in obs.iter().enumerate() {
                let r = cov_local(&filt, &motion, 0.1, &sensor, &g, z, &trig, &ts, &opts).unwrap();
                g = r.posterior;
                ts = r.trigger_state;
                check(
                    &format!("{filt:?} {trig:?}"),
                    k,
                    &g,
                    trig != Trigger::Always,
                );
            }
        }
    }
}

/// A network whose nodes all start equal and see nothing (all measurements
/// missing) stays equal to the common prediction under every fusion: diffusion
/// and consensus of identical estimates return them (to rounding, rel 1e-12).
#[test]
fn identical_nodes_without_measurements_stay_at_prediction() {
    let motion = ct();
    let sensors: [_; 4] = core::array::from_fn(|i| sensor_of(i, 4));
    let mut w = [0.0; 16];
    max_degree_weights(&ring::<16>(), 4, &mut w).unwrap();
    let start = Gaussian::new(x0(), p0()).unwrap();
    let obs = [Observation::Missing; 4];
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    for cfg in [
        config(NodeFilter::Cif, sod, Fusion::DiffusionCi),
        config(NodeFilter::Cif, sod, Fusion::DiffusionConvex),
        config(NodeFilter::Cif, sod, Fusion::Consensus { iterations: 5 }),
        config(
            NodeFilter::Cov(LocalFilter::Ckf),
            sod,
            Fusion::Consensus { iterations: 5 },
        ),
    ] {
        let mut nodes = [NodeState::new(start, &sod); 4];
        let mut scratch = [NodeScratch::default(); 4];
        let mut pred = start;
        let rule = edccif_core::SigmaRule::cubature(7);
        for _ in 0..5 {
            let rep = network_step(
                &cfg,
                &motion,
                &sensors,
                &w,
                &mut nodes,
                &mut scratch,
                &StepInputs::new(&obs, 0.1),
            )
            .unwrap();
            assert_eq!((rep.measured, rep.triggered), (0, 0));
            let (x, p) =
                edccif_core::sigma::sigma_predict(&rule, &motion, 0.1, &pred.x, &pred.p).unwrap();
            pred = Gaussian { x, p };
            for n in &nodes {
                assert_close(
                    &n.estimate.x,
                    &pred.x,
                    1e-12,
                    0.0,
                    &format!("{:?} x", cfg.fusion),
                );
                assert_close(
                    &n.estimate.p,
                    &pred.p,
                    1e-12,
                    0.0,
                    &format!("{:?} P", cfg.fusion),
                );
                assert_eq!(n.trigger, TriggerState::new(&sod));
            }
        }
    }
}

/// Sanity of the full EDC-CIF on the 4-node default (§6): over 200 steps the
/// time-averaged position error of every node stays well below the single-sensor
/// level and the trigger rate is strictly between 0 and 1. Bounds: mean position
/// error < 0.25 m per node (ALGORITHM.md §6 targets ≈ 0.07 m per axis ≈ 0.12 m
/// in norm), trigger rate in (0.1, 0.95).
#[test]
fn edc_cif_four_nodes_tracks_the_target() {
    let motion = ct();
    let sensors: [_; 4] = core::array::from_fn(|i| sensor_of(i, 4));
    let mut w = [0.0; 16];
    max_degree_weights(&ring::<16>(), 4, &mut w).unwrap();
    let mut rng = rng(104);
    let start = initial_estimate(&mut rng);
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let cfg = config(NodeFilter::Cif, sod, Fusion::DiffusionCi);
    let mut nodes = [NodeState::new(start, &sod); 4];
    let mut scratch = [NodeScratch::default(); 4];
    let mut x = x0();
    let mut err = [0.0; 4];
    let mut sent = 0;
    let steps = 200;
    for _ in 0..steps {
        x = propagate(&mut rng, &motion, &x);
        let obs: [_; 4] =
            core::array::from_fn(|i| Observation::Measured(measure(&mut rng, &sensors[i], &x)));
        let rep = network_step(
            &cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(&obs, 0.1),
        )
        .unwrap();
        sent += rep.triggered;
        for (e, n) in err.iter_mut().zip(&nodes) {
            *e += (n.estimate.x - x).fixed_rows::<3>(0).norm() / steps as f64;
        }
    }
    let rate = sent as f64 / (4 * steps) as f64;
    assert!(rate > 0.1 && rate < 0.95, "trigger rate {rate}");
    for (i, e) in err.iter().enumerate() {
        assert!(*e < 0.25, "node {i}: mean position error {e:.3} m");
    }
}

/// The step starts from the Cholesky factors of the estimates' `P`, four
/// nodes at a time; a node whose `P` the batched factorisation declines (a
/// non-finite entry, also one in the upper triangle that the factorisation
/// does not read, or an indefinite `P`) factorises in its own local step.
/// The step then fails with exactly the error of that node's local filter
/// (`cif_local` / `cov_local` on its estimate), leaves every node as it was,
/// and a healthy network still steps bit for bit as the composition of its
/// parts. Five nodes: a group of four and a group of one, the bad node in
/// either.
#[test]
fn a_covariance_the_batched_factorisation_declines_gets_the_local_steps_error() {
    let motion = ct();
    let (_, _, start, obs4) = four_nodes(103, 3);
    let sensors: [_; 5] = core::array::from_fn(|i| sensor_of(i, 5));
    let mut w = [0.0; 25];
    max_degree_weights(&ring::<25>(), 5, &mut w).unwrap();
    let z: [Observation<f64, 3>; 5] = core::array::from_fn(|i| obs4[0][i % 4]);
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let configs = [
        config(NodeFilter::Cif, sod, Fusion::DiffusionCi),
        config(
            NodeFilter::Cov(LocalFilter::Ckf),
            sod,
            Fusion::Consensus { iterations: 3 },
        ),
        config(
            NodeFilter::Cov(LocalFilter::Ekf),
            sod,
            Fusion::Consensus { iterations: 3 },
        ),
        config(
            NodeFilter::Cov(LocalFilter::ukf_default()),
            sod,
            Fusion::Consensus { iterations: 3 },
        ),
    ];
    let mut upper_nan = start;
    upper_nan.p[(1, 4)] = f64::NAN;
    let mut lower_inf = start;
    lower_inf.p[(4, 1)] = f64::INFINITY;
    let mut indefinite = start;
    indefinite.p[(2, 2)] = -1.0;
    let mut both = indefinite;
    both.x[0] = f64::NAN; // the state's check comes first
    for cfg in &configs {
        for bad in [upper_nan, lower_inf, indefinite, both] {
            for at in [1, 4] {
                let mut nodes = [NodeState::new(start, &cfg.trigger); 5];
                nodes[at].estimate = bad;
                let before = nodes;
                let mut scratch = [NodeScratch::default(); 5];
                let err = network_step(
                    cfg,
                    &motion,
                    &sensors,
                    &w,
                    &mut nodes,
                    &mut scratch,
                    &StepInputs::new(&z, 0.1),
                )
                .unwrap_err();
                let ts = TriggerState::new(&cfg.trigger);
                let expect = match cfg.filter {
                    NodeFilter::Cif => cif_local(
                        &motion,
                        0.1,
                        &sensors[at],
                        &bad,
                        &z[at],
                        &cfg.trigger,
                        &ts,
                        &cfg.et,
                    )
                    .unwrap_err(),
                    NodeFilter::Cov(f) => cov_local(
                        &f,
                        &motion,
                        0.1,
                        &sensors[at],
                        &bad,
                        &z[at],
                        &cfg.trigger,
                        &ts,
                        &cfg.et,
                    )
                    .unwrap_err(),
                };
                assert_eq!(err, expect, "{:?} node {at}", cfg.filter);
                // (as text: the bad node's NaN is not equal to itself)
                assert_eq!(
                    format!("{nodes:?}"),
                    format!("{before:?}"),
                    "a failed step changes no node"
                );
            }
        }
    }
}
