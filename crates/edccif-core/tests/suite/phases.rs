//! The per-node phases (`edccif_core::node`): nodes that run them by hand and
//! exchange `Copy` packets reproduce `network_step` bit for bit — for every fusion
//! row, with links lost and a node down — a failed phase changes nothing, the
//! sensor-side local step equals the node-side one, and nodes with different
//! measurement dimensions fuse together.

use crate::common;

use common::*;
use edccif_core::fusion::max_degree_weights;
use edccif_core::models::{CoordinatedTurn, LinearMeasurement, RangePitchAzimuth};
use edccif_core::nalgebra::{Matrix1, Matrix2, SMatrix, Vector1, Vector2};
use edccif_core::node::*;
use edccif_core::{
    network_fusion, network_step, network_step_sparse, Error, EtOptions, EtPolicy, Fusion,
    FusionRule, Gaussian, InfoPair, LocalFilter, Neighbours, NetworkConfig, NodeFilter,
    NodeScratch, NodeState, Observation, StepInputs, Trigger,
};
use rand::Rng;

const K: usize = 4;

fn config(filter: NodeFilter<f64>, trigger: Trigger<f64>, fusion: Fusion) -> NetworkConfig<f64> {
    NetworkConfig {
        filter,
        trigger,
        et: EtOptions::default(),
        fusion,
        rule: Default::default(),
    }
}

/// Every fusion row (and the local-only filters), plus EDC-CIF with σ1 = σ2 = 0.5
/// (where the adaptation guard fires, ALGORITHM.md §4).
fn rows() -> Vec<(&'static str, NetworkConfig<f64>)> {
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let cons = Fusion::Consensus { iterations: 5 };
    let mut guard = config(NodeFilter::Cif, sod, Fusion::DiffusionCi);
    guard.et = EtOptions {
        policy: EtPolicy::Optimal,
        sigma1: 0.5,
        sigma2: 0.5,
        gate: None,
        untriggered_closed_form: false,
    };
    vec![
        (
            "C-CKF",
            config(NodeFilter::Cov(LocalFilter::Ckf), Trigger::Always, cons),
        ),
        (
            "EC-EKF",
            config(NodeFilter::Cov(LocalFilter::Ekf), sod, cons),
        ),
        (
            "EC-UKF",
            config(NodeFilter::Cov(LocalFilter::ukf_default()), sod, cons),
        ),
        (
            "EC-CKF",
            config(NodeFilter::Cov(LocalFilter::Ckf), sod, cons),
        ),
        (
            "DEC-CKF",
            config(
                NodeFilter::Cov(LocalFilter::Ckf),
                Trigger::dynamic(0.04),
                cons,
            ),
        ),
        (
            "D-CIF",
            config(NodeFilter::Cif, Trigger::Always, Fusion::DiffusionConvex),
        ),
        (
            "DC-CIF",
            config(NodeFilter::Cif, Trigger::Always, Fusion::DiffusionCi),
        ),
        (
            "ED-CIF",
            config(NodeFilter::Cif, sod, Fusion::DiffusionConvex),
        ),
        ("EDC-CIF", config(NodeFilter::Cif, sod, Fusion::DiffusionCi)),
        ("EDC-CIF guard", guard),
        ("CIF consensus", config(NodeFilter::Cif, sod, cons)),
        ("ET-CIF local", config(NodeFilter::Cif, sod, Fusion::Local)),
        (
            "ET-CKF local",
            config(NodeFilter::Cov(LocalFilter::Ckf), sod, Fusion::Local),
        ),
    ]
}

type Obs = [Observation<f64, 3>; K];

/// The §6 scenario on a ring of 4: sensors, weights, start and `steps` steps of
/// observations (with `outages`, two of them missing).
fn scenario(
    seed: u64,
    steps: usize,
    outages: bool,
) -> (
    [RangePitchAzimuth<f64>; K],
    [f64; K * K],
    Gaussian<f64, 7>,
    Vec<Obs>,
) {
    let sensors: [_; K] = core::array::from_fn(|i| sensor_of(i, K));
    let mut w = [0.0; K * K];
    max_degree_weights(&ring::<{ K * K }>(), K, &mut w).unwrap();
    let mut rng = rng(seed);
    let start = initial_estimate(&mut rng);
    let motion = ct();
    let mut x = x0();
    let mut obs: Vec<Obs> = (0..steps)
        .map(|_| {
            x = propagate(&mut rng, &motion, &x);
            core::array::from_fn(|i| Observation::Measured(measure(&mut rng, &sensors[i], &x)))
        })
        .collect();
    if outages {
        obs[7][2] = Observation::Missing;
        obs[8][0] = Observation::Missing;
    }
    (sensors, w, start, obs)
}

/// One step of `K` nodes, each running only its own phases and seeing only the
/// packets that reached it: `hears(i, j)` when j's packets reach i this step.
/// Returns whether any node's guard fired.
#[allow(clippy::too_many_arguments)]
fn step_by_hand(
    cfg: &NetworkConfig<f64>,
    motion: &CoordinatedTurn<f64>,
    sensors: &[RangePitchAzimuth<f64>; K],
    w: &[f64; K * K],
    nodes: &mut [NodeState<f64, 7, 3>; K],
    obs: &Obs,
    active: &[bool; K],
    hears: impl Fn(usize, usize) -> bool,
) -> Result<bool, Error> {
    // Local phase: every active node publishes its first packet.
    let mut locals = [None; K];
    for i in (0..K).filter(|&i| active[i]) {
        locals[i] = Some(node_local(
            cfg,
            motion,
            0.1,
            &sensors[i],
            &nodes[i],
            &obs[i],
        )?);
    }
    // What node i received of the packets `sent` (ascending sender order).
    fn inbox<P: Copy>(
        i: usize,
        sent: &[Option<P>; K],
        hears: &impl Fn(usize, usize) -> bool,
    ) -> Vec<(usize, P)> {
        (0..K)
            .filter(|&j| j != i && hears(i, j))
            .filter_map(|j| sent[j].map(|p| (j, p)))
            .collect()
    }
    let mut fused = [None; K];
    let mut guard = false;
    match cfg.fusion {
        Fusion::DiffusionCi | Fusion::DiffusionConvex => {
            let contributions = locals.map(|l| {
                l.map(|l| match l.packet() {
                    LocalPacket::Contribution(c) => c,
                    p => panic!("diffusion sends contributions, got {p:?}"),
                })
            });
            let mut adapted = [None; K];
            for i in (0..K).filter(|&i| active[i]) {
                let got = inbox(i, &contributions, &hears);
                let a = node_adapt(&locals[i].unwrap().local, got.iter().map(|(_, c)| c))?;
                guard |= a.guard_used;
                adapted[i] = Some(a.packet);
            }
            for i in (0..K).filter(|&i| active[i]) {
                let got = inbox(i, &adapted, &hears);
                let own = adapted[i].as_ref().unwrap();
                fused[i] = Some(node_combine(
                    i,
                    w[i * K + i],
                    own,
                    got.iter().map(|(j, p)| (*j, w[i * K + j], p)),
                )?);
            }
        }
        Fusion::Consensus { iterations } => {
            let mut current = locals.map(|l| {
                l.map(|l| match l.packet() {
                    LocalPacket::Information(p) => p,
                    p => panic!("consensus sends information pairs, got {p:?}"),
                })
            });
            for _ in 0..iterations {
                let mut next = [None; K];
                for i in (0..K).filter(|&i| active[i]) {
                    let got = inbox(i, &current, &hears);
                    next[i] = Some(node_consensus_round(
                        i,
                        w[i * K + i],
                        current[i].as_ref().unwrap(),
                        got.iter().map(|(j, p)| (*j, w[i * K + j], p)),
                    )?);
                }
                current = next;
            }
            for i in (0..K).filter(|&i| active[i]) {
                fused[i] = Some(current[i].unwrap().to_gaussian()?);
            }
        }
        Fusion::Local => {
            for i in (0..K).filter(|&i| active[i]) {
                assert_eq!(locals[i].unwrap().packet(), LocalPacket::Silent);
                fused[i] = Some(locals[i].unwrap().local.posterior_estimate()?);
            }
        }
    }
    // Commit only once every node's phases succeeded (as network_step does).
    for i in (0..K).filter(|&i| active[i]) {
        locals[i].unwrap().commit(&mut nodes[i], fused[i].unwrap());
    }
    Ok(guard)
}

/// Nodes running the phases by hand equal `network_step` with the same link and
/// active masks, bit for bit, at every step of every row: 60 steps, each link
/// lost with probability 0.3 at each step, node 3 down at steps 20..25.
#[test]
fn phases_by_hand_equal_network_step_with_lost_links() {
    let motion = ct();
    let (sensors, w, start, obs) = scenario(102, 60, true);
    let (mut offsets, mut indices) = ([0; K + 1], vec![0; Neighbours::count(&w, K)]);
    let nb = Neighbours::from_weights(&w, K, &mut offsets, &mut indices).unwrap();
    assert!(
        (0..K).any(|i| nb.row(i).len() < K),
        "the graph is not complete"
    );
    for (name, cfg) in rows() {
        let mut net = [NodeState::new(start, &cfg.trigger); K];
        let mut scratch = [NodeScratch::default(); K];
        let mut hand = net;
        let (mut sparse, mut sparse_scratch) = (net, scratch);
        let mut loss = rng(7);
        let (mut lost, mut guards) = (0, 0);
        for (t, z) in obs.iter().enumerate() {
            let links: [bool; K * K] = core::array::from_fn(|_| loss.random::<f64>() >= 0.3);
            let mut active = [true; K];
            active[3] = !(20..25).contains(&t);
            let up = |i: usize| active[i];
            let hears = |i: usize, j: usize| w[i * K + j] > 0.0 && up(j) && links[i * K + j];
            lost += (0..K * K)
                .filter(|&l| l / K != l % K && w[l] > 0.0 && !links[l])
                .count();
            let inputs = StepInputs {
                dt: 0.1,
                observations: z,
                links: Some(&links),
                edge_links: None,
                active: Some(&active),
                deltas: None,
            };
            let rep =
                network_step(&cfg, &motion, &sensors, &w, &mut net, &mut scratch, &inputs).unwrap();
            // The same step over neighbour lists: bit for bit, scratch included.
            let rep_sparse = network_step_sparse(
                &cfg,
                &motion,
                &sensors,
                &w,
                &nb,
                &mut sparse,
                &mut sparse_scratch,
                &inputs,
            )
            .unwrap();
            assert_eq!(rep, rep_sparse, "{name}: step {t}: sparse report");
            assert_eq!(sparse, net, "{name}: step {t}: sparse states differ");
            assert_eq!(sparse_scratch, scratch, "{name}: step {t}: sparse scratch");
            let guard =
                step_by_hand(&cfg, &motion, &sensors, &w, &mut hand, z, &active, hears).unwrap();
            assert_eq!(guard, rep.guard_fallbacks > 0, "{name}: step {t}: guard");
            guards += rep.guard_fallbacks;
            assert_eq!(hand, net, "{name}: step {t}: states differ");
        }
        assert!(lost > 0, "{name}: no link was lost");
        if name == "EDC-CIF guard" {
            assert!(guards > 0, "the guard row must exercise the guard");
        }
    }
}

/// Every fusion rule (`docs/fusion.md`) in the combination phase: `network_step`,
/// `network_step_sparse` and a loop of one's own (`node_local_into`, then
/// `network_fusion` with the rule) agree bit for bit over 30 steps with links
/// lost and node 3 down at steps 10..15; a rule other than CI differs from CI;
/// `network_fusion` refuses a rule without diffusion with CI.
#[test]
fn every_fusion_rule_is_one_combination_phase() {
    let motion = ct();
    let (sensors, w, start, obs) = scenario(106, 30, true);
    let (mut offsets, mut indices) = ([0; K + 1], vec![0; Neighbours::count(&w, K)]);
    let nb = Neighbours::from_weights(&w, K, &mut offsets, &mut indices).unwrap();
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let mut paper = None;
    for rule in FusionRule::ALL {
        let cfg = NetworkConfig {
            rule,
            ..config(NodeFilter::Cif, sod, Fusion::DiffusionCi)
        };
        let mut net = [NodeState::new(start, &cfg.trigger); K];
        let mut scratch = [NodeScratch::default(); K];
        let (mut sparse, mut sparse_scratch) = (net, scratch);
        let mut own = net;
        let mut phases = [PhaseScratch::default(); K];
        let mut loss = rng(8);
        for (t, z) in obs.iter().enumerate() {
            let links: [bool; K * K] = core::array::from_fn(|_| loss.random::<f64>() >= 0.3);
            let mut active = [true; K];
            active[3] = !(10..15).contains(&t);
            let inputs = StepInputs {
                dt: 0.1,
                observations: z,
                links: Some(&links),
                edge_links: None,
                active: Some(&active),
                deltas: None,
            };
            let rep =
                network_step(&cfg, &motion, &sensors, &w, &mut net, &mut scratch, &inputs).unwrap();
            let rep_sparse = network_step_sparse(
                &cfg,
                &motion,
                &sensors,
                &w,
                &nb,
                &mut sparse,
                &mut sparse_scratch,
                &inputs,
            )
            .unwrap();
            assert_eq!((rep, sparse), (rep_sparse, net), "{rule}: step {t}: sparse");
            let mut triggers = [None; K];
            for i in (0..K).filter(|&i| active[i]) {
                triggers[i] = Some(
                    node_local_into(
                        &cfg,
                        &motion,
                        0.1,
                        &sensors[i],
                        &own[i],
                        &z[i],
                        &mut phases[i],
                    )
                    .unwrap(),
                );
            }
            let rep_own = network_fusion(
                cfg.fusion,
                cfg.rule,
                &w,
                None,
                Some(&links),
                Some(&active),
                &mut phases,
            )
            .unwrap();
            for i in (0..K).filter(|&i| active[i]) {
                (own[i].estimate, own[i].trigger) = (phases[i].fused, triggers[i].unwrap());
            }
            assert_eq!(
                (rep_own, own),
                (rep, net),
                "{rule}: step {t}: network_fusion"
            );
        }
        match paper {
            None => paper = Some(net),
            Some(p) => assert_ne!(p, net, "{rule} gave the bits of CI"),
        }
    }
    let mut phases = [PhaseScratch::<f64, 7>::default(); K];
    let ici: FusionRule = "ici".parse().unwrap();
    assert!(network_fusion(
        Fusion::DiffusionConvex,
        ici,
        &w,
        None,
        None,
        None,
        &mut phases
    )
    .is_err());
}

/// Estimates so badly conditioned that the network step's batched conversions
/// back to covariance form decline them (`tr Y · tr P` past the bound under
/// which the inverse is surely positive definite) and the node-by-node code
/// takes over: still the phases by hand, bit for bit, for every row.
#[test]
fn ill_conditioned_estimates_equal_the_phases_by_hand() {
    let motion = ct();
    let (sensors, w, mut start, obs) = scenario(103, 12, false);
    // Three components known to 1e5 (standard deviation), the rest as usual:
    // `tr P ≈ 3e10` against `tr Y ≥ 1e2`.
    for i in [1, 3, 5] {
        start.p[(i, i)] = 1e10;
    }
    let all = [true; K];
    let mut declined = 0;
    for (name, cfg) in rows() {
        let mut net = [NodeState::new(start, &cfg.trigger); K];
        let mut scratch = [NodeScratch::default(); K];
        let mut hand = net;
        for (t, z) in obs.iter().enumerate() {
            let inputs = StepInputs::new(z, 0.1);
            network_step(&cfg, &motion, &sensors, &w, &mut net, &mut scratch, &inputs).unwrap();
            step_by_hand(&cfg, &motion, &sensors, &w, &mut hand, z, &all, |i, j| {
                w[i * K + j] > 0.0
            })
            .unwrap();
            assert_eq!(hand, net, "{name}: step {t}: states differ");
            for n in &net {
                let y = n.estimate.p.cholesky().unwrap().inverse();
                declined += usize::from(y.trace() * n.estimate.p.trace() > 3.6e11);
            }
        }
    }
    assert!(declined > 0, "no estimate was past the bound");
}

/// A failed phase returns the named error and leaves the node's state unchanged;
/// the node then completes the same step as if nothing had happened.
#[test]
fn failed_phases_leave_the_node_unchanged() {
    let motion = ct();
    let (sensors, w, start, obs) = scenario(103, 3, false);
    let ci = config(
        NodeFilter::Cif,
        Trigger::SendOnDelta { delta: 0.04 },
        Fusion::DiffusionCi,
    );
    let mut nodes = [NodeState::new(start, &ci.trigger); K];
    let mut scratch = [NodeScratch::default(); K];
    // One good step first, so that the states are not the initial ones.
    network_step(
        &ci,
        &motion,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs[0], 0.1),
    )
    .unwrap();
    let before = nodes;
    let z = &obs[1];

    // Local phase: a NaN measurement, a bad dt, an invalid configuration.
    let nan = Observation::Measured(Vec3::new(f64::NAN, 0.0, 0.0));
    let e = node_local(&ci, &motion, 0.1, &sensors[0], &nodes[0], &nan).unwrap_err();
    assert_eq!(
        e,
        Error::NonFinite {
            what: "measurement z"
        }
    );
    let e = node_local(&ci, &motion, -0.1, &sensors[0], &nodes[0], &z[0]).unwrap_err();
    assert!(
        matches!(
            e,
            Error::InvalidParameter {
                what: "time step dt",
                ..
            }
        ),
        "{e:?}"
    );
    let bad = config(
        NodeFilter::Cov(LocalFilter::Ckf),
        ci.trigger,
        Fusion::DiffusionCi,
    );
    let e = node_local(&bad, &motion, 0.1, &sensors[0], &nodes[0], &z[0]).unwrap_err();
    assert!(
        matches!(e, Error::InvalidParameter { what: "fusion", .. }),
        "{e:?}"
    );
    // A trigger that needs the node's prediction cannot run at the sensor.
    let inn = config(
        NodeFilter::Cif,
        Trigger::Innovation { delta: 1.2 },
        Fusion::DiffusionCi,
    );
    let e = node_local_received(&inn, &motion, 0.1, &sensors[0], &nodes[0], None).unwrap_err();
    assert!(
        matches!(
            e,
            Error::InvalidParameter {
                what: "trigger run at the sensor",
                ..
            }
        ),
        "{e:?}"
    );

    let locals: [_; K] = core::array::from_fn(|i| {
        node_local(&ci, &motion, 0.1, &sensors[i], &nodes[i], &z[i]).unwrap()
    });
    let contributions: [_; K] = core::array::from_fn(|i| match locals[i].packet() {
        LocalPacket::Contribution(c) => c,
        p => panic!("{p:?}"),
    });
    // Adaptation on the output of a consensus row's local step.
    let cons = config(
        NodeFilter::Cif,
        ci.trigger,
        Fusion::Consensus { iterations: 2 },
    );
    let lc = node_local(&cons, &motion, 0.1, &sensors[0], &nodes[0], &z[0]).unwrap();
    assert!(matches!(lc.packet(), LocalPacket::Information(_)));
    let e = node_adapt(&lc.local, []).unwrap_err();
    assert!(matches!(
        e,
        Error::InvalidParameter {
            what: "fusion of the adaptation phase",
            ..
        }
    ));

    let neighbours = |i: usize| (0..K).filter(move |&j| j != i && w[i * K + j] > 0.0);
    let adapted: [_; K] = core::array::from_fn(|i| {
        node_adapt(&locals[i].local, neighbours(i).map(|j| &contributions[j])).unwrap()
    });
    let adapted = &adapted;
    let received = |i: usize| neighbours(i).map(move |j| (j, w[i * K + j], &adapted[j].packet));
    // Combination: a negative weight, a packet from the node itself, a packet of
    // the other kind.
    let e = node_combine(0, -0.5, &adapted[0].packet, received(0)).unwrap_err();
    assert_eq!(
        e,
        Error::InvalidParameter {
            what: "fusion weight",
            expected: "finite and >= 0"
        }
    );
    let e = node_combine(0, w[0], &adapted[0].packet, [(0, w[0], &adapted[0].packet)]).unwrap_err();
    assert!(
        matches!(
            e,
            Error::InvalidParameter {
                what: "received packet",
                ..
            }
        ),
        "{e:?}"
    );
    let g = AdaptedPacket::Estimate(nodes[1].estimate);
    let e = node_combine(0, w[0], &adapted[0].packet, [(1, w[1], &g)]).unwrap_err();
    assert!(
        matches!(
            e,
            Error::InvalidParameter {
                what: "received adapted packet",
                ..
            }
        ),
        "{e:?}"
    );
    // A consensus round with a zero total weight.
    let p = InfoPair {
        y: Vec7::zeros(),
        ymat: Mat7::identity(),
    };
    let e = node_consensus_round(0, 0.0, &p, [(1, 0.0, &p)]).unwrap_err();
    assert_eq!(
        e,
        Error::InvalidParameter {
            what: "fusion weights",
            expected: "a positive sum"
        }
    );
    // Finite pairs whose weighted sum overflows: the round names the overflow
    // instead of handing ±∞ on to the next round.
    let huge = InfoPair {
        y: Vec7::zeros(),
        ymat: Mat7::identity() * 1e308,
    };
    let e = node_consensus_round(0, 1.0, &huge, [(1, 1.0, &huge)]).unwrap_err();
    assert_eq!(
        e,
        Error::NonFinite {
            what: "combined information matrix Y"
        }
    );

    assert_eq!(nodes, before, "a failed phase changed a node");

    // The step completes as network_step's.
    for i in 0..K {
        let f = node_combine(i, w[i * K + i], &adapted[i].packet, received(i)).unwrap();
        locals[i].commit(&mut nodes[i], f);
    }
    let mut net = before;
    network_step(
        &ci,
        &motion,
        &sensors,
        &w,
        &mut net,
        &mut scratch,
        &StepInputs::new(z, 0.1),
    )
    .unwrap();
    assert_eq!(nodes, net);
}

/// With the trigger at the sensor (the node sees a measurement or nothing), the
/// phases give `network_step`'s estimates bit for bit for the paper's
/// sensor-side triggers (send-on-delta, dynamic, always), 60 steps without
/// outages (a node cannot tell an outage from an untriggered step).
#[test]
fn sensor_side_local_step_equals_network_step() {
    let motion = ct();
    let (sensors, w, start, obs) = scenario(104, 60, false);
    let cons = Fusion::Consensus { iterations: 5 };
    for cfg in [
        config(
            NodeFilter::Cif,
            Trigger::SendOnDelta { delta: 0.04 },
            Fusion::DiffusionCi,
        ),
        config(
            NodeFilter::Cov(LocalFilter::Ckf),
            Trigger::dynamic(0.04),
            cons,
        ),
        config(NodeFilter::Cov(LocalFilter::Ckf), Trigger::Always, cons),
    ] {
        let mut net = [NodeState::new(start, &cfg.trigger); K];
        let mut scratch = [NodeScratch::default(); K];
        let mut hand = net;
        let mut at_sensor = net.map(|n| n.trigger);
        let mut sent = 0;
        for z in &obs {
            network_step(
                &cfg,
                &motion,
                &sensors,
                &w,
                &mut net,
                &mut scratch,
                &StepInputs::new(z, 0.1),
            )
            .unwrap();
            // The sensors decide; the nodes see what they send.
            let arrived: [Option<Vec3>; K] = core::array::from_fn(|i| match z[i] {
                Observation::Measured(v) => {
                    let (gamma, next) =
                        cfg.trigger
                            .decide::<_, 7, 3>(&sensors[i], &at_sensor[i], &v);
                    at_sensor[i] = next;
                    gamma.then_some(v)
                }
                Observation::Missing => None,
            });
            sent += arrived.iter().flatten().count();
            let locals: [_; K] = core::array::from_fn(|i| {
                node_local_received(
                    &cfg,
                    &motion,
                    0.1,
                    &sensors[i],
                    &hand[i],
                    arrived[i].as_ref(),
                )
                .unwrap()
            });
            for i in 0..K {
                assert_eq!(locals[i].triggered.is_some_and(|t| t), arrived[i].is_some());
            }
            let nb = |i: usize| (0..K).filter(move |&j| j != i && w[i * K + j] > 0.0);
            let fused: [Gaussian<f64, 7>; K] = match cfg.fusion {
                Fusion::DiffusionCi => {
                    let c = locals.map(|l| l.local.contribution);
                    let a: [_; K] = core::array::from_fn(|i| {
                        node_adapt(&locals[i].local, nb(i).map(|j| &c[j]))
                            .unwrap()
                            .pair
                    });
                    core::array::from_fn(|i| {
                        node_combine_ci(
                            i,
                            w[i * K + i],
                            &a[i],
                            nb(i).map(|j| (j, w[i * K + j], &a[j])),
                        )
                        .unwrap()
                    })
                }
                _ => {
                    let mut cur = locals.map(|l| l.local.posterior);
                    for _ in 0..5 {
                        cur = core::array::from_fn(|i| {
                            node_consensus_round(
                                i,
                                w[i * K + i],
                                &cur[i],
                                nb(i).map(|j| (j, w[i * K + j], &cur[j])),
                            )
                            .unwrap()
                        });
                    }
                    cur.map(|p| p.to_gaussian().unwrap())
                }
            };
            for i in 0..K {
                locals[i].commit(&mut hand[i], fused[i]);
                assert_eq!(hand[i].estimate, net[i].estimate, "{:?}", cfg.trigger);
            }
        }
        assert!(sent > 0 && (cfg.trigger == Trigger::Always || sent < K * obs.len()));
    }
}

/// The fusion phases depend on the state dimension only: three nodes with
/// sensors of 3, 2 and 1 measurement components (range/pitch/azimuth; x-y
/// position; height) fuse into estimates within 1 m of the truth for 100 steps,
/// while the height-only node alone loses the horizontal position (> 1 m).
#[test]
fn nodes_with_different_measurement_dimensions_fuse() {
    let motion = ct();
    let rpa0 = sensor_of(0, 4);
    let mut hxy = SMatrix::<f64, 2, 7>::zeros();
    hxy[(0, 0)] = 1.0;
    hxy[(1, 1)] = 1.0;
    let xy = LinearMeasurement::new(hxy, Matrix2::identity() * 0.01).unwrap();
    let mut hz = SMatrix::<f64, 1, 7>::zeros();
    hz[(0, 2)] = 1.0;
    let height = LinearMeasurement::new(hz, Matrix1::new(0.01)).unwrap();
    let cfg = config(
        NodeFilter::Cif,
        Trigger::SendOnDelta { delta: 0.04 },
        Fusion::DiffusionCi,
    );
    // A path 0 - 1 - 2.
    let mut w = [0.0; 9];
    max_degree_weights(
        &[false, true, false, true, false, true, false, true, false],
        3,
        &mut w,
    )
    .unwrap();
    let mut rng = rng(105);
    let start = initial_estimate(&mut rng);
    let mut n0 = NodeState::<f64, 7, 3>::new(start, &cfg.trigger);
    let mut n1 = NodeState::<f64, 7, 2>::new(start, &cfg.trigger);
    let mut n2 = NodeState::<f64, 7, 1>::new(start, &cfg.trigger);
    let mut alone = n2;
    let mut x = x0();
    let mut worst_alone: f64 = 0.0;
    for t in 0..100 {
        x = propagate(&mut rng, &motion, &x);
        let z0 = Observation::Measured(measure(&mut rng, &rpa0, &x));
        let z1 = Observation::Measured(
            Vector2::new(x[0], x[1]) + sample(&mut rng, &(Matrix2::identity() * 0.01)),
        );
        let z2 = Observation::Measured(Vector1::new(x[2]) + sample(&mut rng, &Matrix1::new(0.01)));
        let l0 = node_local(&cfg, &motion, 0.1, &rpa0, &n0, &z0).unwrap();
        let l1 = node_local(&cfg, &motion, 0.1, &xy, &n1, &z1).unwrap();
        let l2 = node_local(&cfg, &motion, 0.1, &height, &n2, &z2).unwrap();
        let la = node_local(
            &config(cfg.filter, cfg.trigger, Fusion::Local),
            &motion,
            0.1,
            &height,
            &alone,
            &z2,
        )
        .unwrap();
        let (c0, c1, c2) = (
            l0.local.contribution,
            l1.local.contribution,
            l2.local.contribution,
        );
        let a0 = node_adapt(&l0.local, [&c1]).unwrap();
        let a1 = node_adapt(&l1.local, [&c0, &c2]).unwrap();
        let a2 = node_adapt(&l2.local, [&c1]).unwrap();
        let f0 = node_combine(0, w[0], &a0.packet, [(1, w[1], &a1.packet)]).unwrap();
        let f1 = node_combine(
            1,
            w[4],
            &a1.packet,
            [(0, w[3], &a0.packet), (2, w[5], &a2.packet)],
        )
        .unwrap();
        let f2 = node_combine(2, w[8], &a2.packet, [(1, w[7], &a1.packet)]).unwrap();
        l0.commit(&mut n0, f0);
        l1.commit(&mut n1, f1);
        l2.commit(&mut n2, f2);
        la.commit(&mut alone, la.local.posterior_estimate().unwrap());
        let err = |g: &Gaussian<f64, 7>| (g.x - x).fixed_rows::<3>(0).norm();
        if t >= 20 {
            for (i, g) in [&n0.estimate, &n1.estimate, &n2.estimate]
                .into_iter()
                .enumerate()
            {
                assert!(err(g) < 1.0, "node {i} at step {t}: {} m", err(g));
                assert!(g.p.cholesky().is_some());
            }
        }
        worst_alone = worst_alone.max(err(&alone.estimate));
    }
    assert!(
        worst_alone > 1.0,
        "the height-only node alone stayed within {worst_alone} m"
    );
}

/// Neighbour lists: malformed lists and lists naming a non-neighbour are named
/// errors that change nothing; a neighbour left out is not heard.
#[test]
fn neighbour_lists_are_checked() {
    let bad = |offsets: &[usize], indices: &[usize]| {
        matches!(
            Neighbours::new(offsets, indices),
            Err(Error::InvalidParameter {
                what: "neighbour lists",
                ..
            })
        )
    };
    assert!(bad(&[], &[]));
    assert!(bad(&[0, 2], &[0])); // offsets beyond the indices
    assert!(bad(&[0, 1, 2], &[1, 0])); // rows without their own node
    assert!(bad(&[0, 2, 3], &[1, 0, 1])); // a row not ascending
    assert!(bad(&[0, 2, 4], &[0, 2, 0, 1])); // index out of range
    assert!(bad(&[1, 2, 3], &[0, 0, 1])); // not starting at 0
    let ok = Neighbours::new(&[0, 2, 4], &[0, 1, 0, 1]).unwrap();
    assert_eq!((ok.nodes(), ok.row(1)), (2, &[0usize, 1][..]));
    let mut short = [0usize; 3];
    assert!(
        Neighbours::from_weights(&[0.5f64, 0.5, 0.5, 0.5], 2, &mut [0; 3], &mut short).is_err()
    );

    let motion = ct();
    let (sensors, w, start, obs) = scenario(104, 2, false);
    let cfg = config(
        NodeFilter::Cif,
        Trigger::SendOnDelta { delta: 0.04 },
        Fusion::DiffusionCi,
    );
    let mut nodes = [NodeState::new(start, &cfg.trigger); K];
    let before = nodes;
    let mut scratch = [NodeScratch::default(); K];
    let inputs = StepInputs::new(&obs[0], 0.1);
    // Every node listed as everyone's neighbour, though not all weights are > 0.
    let (offsets, indices): (Vec<usize>, Vec<usize>) = (
        (0..=K).map(|i| i * K).collect(),
        (0..K * K).map(|e| e % K).collect(),
    );
    assert!(w.contains(&0.0), "the graph is not complete");
    let all = Neighbours::new(&offsets, &indices).unwrap();
    let err = network_step_sparse(
        &cfg,
        &motion,
        &sensors,
        &w,
        &all,
        &mut nodes,
        &mut scratch,
        &inputs,
    );
    assert!(matches!(
        err,
        Err(Error::InvalidParameter {
            what: "neighbour lists",
            ..
        })
    ));
    assert_eq!(nodes, before);
    // Lists for another number of nodes.
    let two = Neighbours::new(&[0, 1, 2], &[0, 1]).unwrap();
    let err = network_step_sparse(
        &cfg,
        &motion,
        &sensors,
        &w,
        &two,
        &mut nodes,
        &mut scratch,
        &inputs,
    );
    assert!(matches!(err, Err(Error::Dimension { .. })));
    assert_eq!(nodes, before);
    // Each node alone: the lists decide who is heard, as if every link were lost.
    let (offsets, indices): (Vec<usize>, Vec<usize>) = ((0..=K).collect(), (0..K).collect());
    let alone = Neighbours::new(&offsets, &indices).unwrap();
    let mut lost = nodes;
    network_step_sparse(
        &cfg,
        &motion,
        &sensors,
        &w,
        &alone,
        &mut nodes,
        &mut scratch,
        &inputs,
    )
    .unwrap();
    let links = [false; K * K];
    let masked = StepInputs {
        links: Some(&links),
        edge_links: None,
        ..inputs
    };
    network_step(
        &cfg,
        &motion,
        &sensors,
        &w,
        &mut lost,
        &mut scratch,
        &masked,
    )
    .unwrap();
    assert_eq!(nodes, lost);
}
