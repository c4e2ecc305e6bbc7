//! Thresholds a user can set: the normalised send-on-delta family (the change
//! `ΔᵀR⁻¹Δ` in units of the sensor's noise, angle components wrapped), the
//! error-minimised gain of its untriggered steps (`S = μ1 G P⁻ Gᵀ + μ2 R + μ3 δ R`)
//! against the formula written out, and one threshold per node in
//! `network_step` (`StepInputs::deltas`). Failed steps leave every state as it
//! was.

use crate::common;

use common::assert_close;
use edccif_core::fusion::max_degree_weights;
use edccif_core::models::{BearingOnly, ConstantVelocity, RangeBearing};
use edccif_core::nalgebra::{Matrix2, Matrix4, SMatrix, SVector, Vector2, Vector4};
use edccif_core::trigger::noise_distance;
use edccif_core::{
    network_step, untriggered_contribution, untriggered_contribution_closed, Error, EtGain,
    EtOptions, Fusion, Gaussian, MeasurementModel, NetworkConfig, NodeFilter, NodeScratch,
    NodeState, Observation, StepInputs, Trigger, TriggerState,
};

const PI: f64 = core::f64::consts::PI;

fn rb() -> RangeBearing<f64> {
    // σ = 0.5 m in range, 0.01 rad in bearing
    RangeBearing::new([0.0, 0.0], 0.5, 0.01).unwrap()
}

#[test]
fn normalised_send_on_delta_weighs_the_change_by_the_noise() {
    let s = rb();
    let raw = Trigger::SendOnDelta { delta: 0.04 };
    let norm = Trigger::SendOnDeltaNormalised { delta: 4.0 };
    let z0 = Vector2::new(10.0, 0.5);
    // 0.6 m in range: 1.44 σ² (stays, normalised) but 0.36 m² > 0.04 (sent, raw)
    let range = Vector2::new(10.6, 0.5);
    // 0.03 rad in bearing: 9 σ² (sent, normalised) but 9e-4 rad² ≤ 0.04 (stays, raw)
    let bearing = Vector2::new(10.0, 0.53);
    for (t, expect) in [(raw, [true, false]), (norm, [false, true])] {
        let mut st = TriggerState::<f64, 2>::new(&t);
        st.last_sent = Some(z0);
        let a = t.decide_with::<_, 4, 2>(&s, &st, &range, None).unwrap().0;
        let b = t.decide_with::<_, 4, 2>(&s, &st, &bearing, None).unwrap().0;
        assert_eq!([a, b], expect, "{t:?}");
    }
    // Across ±π the bearing difference is wrapped: 0.02 rad, 4 σ² (not > 4).
    let mut st = TriggerState::<f64, 2>::new(&norm);
    st.last_sent = Some(Vector2::new(10.0, PI - 0.01));
    let across = Vector2::new(10.0, -PI + 0.01);
    assert!(
        (noise_distance::<f64, _, 4, 2>(&s, &across, &st.last_sent.unwrap()).unwrap() - 4.0).abs()
            < 1e-9
    );
    let (sent, next) = norm.decide_with::<_, 4, 2>(&s, &st, &across, None).unwrap();
    assert!(!sent);
    assert_eq!(next, st);
}

#[test]
fn normalised_dynamic_trigger_follows_its_definition() {
    let s = BearingOnly::new([0.0, 0.0], 0.01).unwrap();
    let (delta, lambda, theta) = (2.0, 0.9, 2.0);
    let t = Trigger::DynamicNormalised {
        delta,
        lambda,
        theta,
    };
    assert_eq!(t, Trigger::dynamic(delta).normalised());
    let mut st = TriggerState::<f64, 1>::new(&t);
    let (mut zt, mut eta) = (None::<f64>, delta);
    for k in 0..60 {
        let z = 0.3 + 0.004 * k as f64 + 0.01 * ((k * 7 % 5) as f64 - 2.0);
        let (g, next) = t
            .decide_with::<_, 4, 1>(&s, &st, &SVector::from([z]), None)
            .unwrap();
        // by hand: d = ((z − z_τ)/σ)², γ = d > δ + η/θ, η ← λη + δ − (1−γ) d
        let want = match zt {
            None => true,
            Some(p) => {
                let d = ((z - p) / 0.01).powi(2);
                let g = d > delta + eta / theta;
                eta = lambda * eta + delta - if g { 0.0 } else { d };
                g
            }
        };
        assert_eq!(g, want, "step {k}");
        assert!(
            (next.eta - eta).abs() < 1e-9 * eta.abs().max(1.0),
            "step {k}"
        );
        if g {
            zt = Some(z);
        }
        st = next;
    }
}

#[test]
fn normalised_variants_validate_and_keep_their_silent_update() {
    for t in [
        Trigger::SendOnDelta { delta: 1.0 },
        Trigger::dynamic(1.0),
        Trigger::SendOnDeltaInflated { delta: 1.0 },
    ] {
        let n = t.normalised();
        assert!(n.is_normalised() && !t.is_normalised());
        assert_eq!(n.delta(), t.delta());
        assert_eq!(n.has_silent_update(), t.has_silent_update());
        assert_eq!(n.needs_prediction(), t.needs_prediction());
        assert_eq!(n.with_delta(2.0).unwrap().delta(), 2.0);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(
                n.with_delta(bad),
                Err(Error::InvalidParameter {
                    what: "delta",
                    expected: "finite and > 0"
                })
            );
        }
    }
    // already in units of the noise, or no threshold: unchanged
    for t in [
        Trigger::Stochastic { delta: 3.0 },
        Trigger::Innovation { delta: 1.2 },
        Trigger::Always,
        Trigger::Never,
    ] {
        assert_eq!(t.normalised(), t);
        assert!(!t.is_normalised());
    }
    // a bad threshold is an error, not a silent decision
    let bad = Trigger::SendOnDeltaNormalised { delta: f64::NAN };
    let st = TriggerState::<f64, 2>::new(&bad);
    assert!(bad
        .decide_with::<_, 4, 2>(&rb(), &st, &Vector2::new(1.0, 0.0), None)
        .is_err());
}

/// `S = μ1 G P Gᵀ + μ2 R + μ3 δ R`, `M = μ1 P Gᵀ S⁻¹`, `P̄ = μ1 (I − M G) P`
/// written out with plain inverses (ALGORITHM.md §3 step 5 with `δ I_m` → `δ R`).
fn gain_by_hand(
    p: &Matrix4<f64>,
    g: &SMatrix<f64, 2, 4>,
    r: &Matrix2<f64>,
    delta: f64,
    o: &EtOptions<f64>,
) -> (SMatrix<f64, 4, 2>, Matrix4<f64>) {
    let (mu1, mu2) = (1.0 + o.sigma1, 1.0 + o.sigma2);
    let mu3 = 1.0 + 1.0 / o.sigma1 + 1.0 / o.sigma2;
    let s = g * p * g.transpose() * mu1 + r * mu2 + r * (mu3 * delta);
    let m = p * g.transpose() * s.try_inverse().unwrap() * mu1;
    let pbar = (Matrix4::identity() - m * g) * p * mu1;
    (m, pbar)
}

#[test]
fn the_untriggered_gain_of_a_normalised_threshold_bounds_the_deviation_by_delta_r() {
    let p = Matrix4::new(
        0.30, 0.02, 0.01, 0.00, //
        0.02, 0.25, 0.00, 0.01, //
        0.01, 0.00, 0.10, 0.02, //
        0.00, 0.01, 0.02, 0.12,
    );
    let x = Vector4::new(8.0, 6.0, 1.0, -0.5);
    let s = rb();
    let g = MeasurementModel::<f64, 4, 2>::jacobian(&s, &x);
    let r = MeasurementModel::<f64, 4, 2>::noise(&s);
    let dz = Vector2::new(0.3, -0.004);
    for (s1, s2) in [(5e-4, 5e-4), (0.1, 0.3), (1.0, 0.05)] {
        let o = EtOptions {
            sigma1: s1,
            sigma2: s2,
            ..EtOptions::default()
        };
        for delta in [0.5, 4.0, 20.0] {
            let t = Trigger::SendOnDeltaNormalised { delta };
            let (r_u, d_u) = t.untriggered_noise(&r, &o);
            let gain = EtGain::new(&p, &g, &r_u, d_u, &o).unwrap();
            let (m, pbar) = gain_by_hand(&p, &g, &r, delta, &o);
            assert_close(&gain.m, &m, 1e-10, 0.0, "M");
            assert_close(&gain.p_bar, &pbar, 1e-10, 0.0, "P̄");
            // the information form, stable and closed, against P̄ written out
            let y = p.try_inverse().unwrap();
            let stable = untriggered_contribution(&x, &y, &g, &gain, &dz).unwrap();
            let closed = untriggered_contribution_closed(&x, &y, &g, &r_u, d_u, &o, &dz).unwrap();
            let imat = pbar.try_inverse().unwrap() - y;
            assert_close(&stable.imat, &imat, 1e-8, 0.0, "Ī stable");
            assert_close(&closed.imat, &imat, 1e-8, 0.0, "Ī closed");
            assert_close(&closed.i, &stable.i, 1e-8, 0.0, "ī");
        }
    }
    // the raw threshold keeps the paper's (R, δ) bit for bit
    let raw = Trigger::SendOnDelta { delta: 0.04 };
    assert_eq!(raw.untriggered_noise(&r, &EtOptions::default()), (r, 0.04));
}

/// A position sensor in the plane whose noise the test chooses (a singular one
/// makes the normalised decision fail).
#[derive(Clone, Copy)]
struct Pos2 {
    r: Matrix2<f64>,
}

impl MeasurementModel<f64, 4, 2> for Pos2 {
    fn measure(&self, x: &Vector4<f64>) -> Vector2<f64> {
        Vector2::new(x[0], x[1])
    }
    fn noise(&self) -> Matrix2<f64> {
        self.r
    }
}

fn start() -> Gaussian<f64, 4> {
    Gaussian::new(Vector4::new(0.0, 0.0, 1.0, 0.5), Matrix4::identity() * 0.5).unwrap()
}

fn cfg(trigger: Trigger<f64>, fusion: Fusion) -> NetworkConfig<f64> {
    NetworkConfig {
        filter: NodeFilter::Cif,
        trigger,
        et: EtOptions::default(),
        fusion,
        rule: Default::default(),
    }
}

fn path(k: usize, i: usize) -> Vector2<f64> {
    let t = 0.1 * k as f64;
    // a deterministic wiggle per node stands in for the noise
    let e = 0.05 * (((k * 13 + i * 7) % 11) as f64 - 5.0) / 5.0;
    Vector2::new(t + e, 0.5 * t - e)
}

#[test]
fn per_node_thresholds_equal_separate_networks_when_nodes_do_not_fuse() {
    let motion = ConstantVelocity::new(0.05).unwrap();
    let sensors = [Pos2 {
        r: Matrix2::identity() * 0.01,
    }; 3];
    let w = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    for trig in [
        Trigger::SendOnDelta { delta: 0.04 },
        Trigger::dynamic(0.04),
        Trigger::SendOnDeltaNormalised { delta: 1.0 },
    ] {
        // in m², or in units of R = 0.01 I
        let unit = if trig.is_normalised() { 100.0 } else { 1.0 };
        let deltas = [0.002 * unit, 0.02 * unit, 0.2 * unit];
        let c = cfg(trig, Fusion::Local);
        let mut all: Vec<NodeState<f64, 4, 2>> = deltas
            .iter()
            .map(|&d| NodeState::new(start(), &trig.with_delta(d).unwrap()))
            .collect();
        let mut scratch = [NodeScratch::default(); 3];
        // node i alone with its own δ, in a network of the same three sensors
        let mut alone: Vec<Vec<NodeState<f64, 4, 2>>> = deltas
            .iter()
            .map(|&d| vec![NodeState::new(start(), &trig.with_delta(d).unwrap()); 3])
            .collect();
        let mut sent = [0; 3];
        for k in 1..80 {
            let obs: Vec<Observation<f64, 2>> =
                (0..3).map(|i| Observation::Measured(path(k, i))).collect();
            network_step(
                &c,
                &motion,
                &sensors,
                &w,
                &mut all,
                &mut scratch,
                &StepInputs::new(&obs, 0.1).with_deltas(&deltas),
            )
            .unwrap();
            for i in 0..3 {
                sent[i] += usize::from(scratch[i].triggered == Some(true));
            }
            for (i, a) in alone.iter_mut().enumerate() {
                let ci = cfg(trig.with_delta(deltas[i]).unwrap(), Fusion::Local);
                let mut sc = [NodeScratch::default(); 3];
                network_step(
                    &ci,
                    &motion,
                    &sensors,
                    &w,
                    a,
                    &mut sc,
                    &StepInputs::new(&obs, 0.1),
                )
                .unwrap();
                assert_eq!(all[i], a[i], "{trig:?} node {i} step {k}");
            }
        }
        // the thresholds differ enough to change the decisions
        assert!(sent[0] > sent[1] && sent[1] > sent[2], "{trig:?} {sent:?}");
    }
}

#[test]
fn one_threshold_per_node_all_equal_is_the_network_threshold_bit_for_bit() {
    let motion = ConstantVelocity::new(0.05).unwrap();
    let sensors = [Pos2 {
        r: Matrix2::identity() * 0.01,
    }; 3];
    let mut w = [0.0; 9];
    max_degree_weights(
        &[false, true, false, true, false, true, false, true, false],
        3,
        &mut w,
    )
    .unwrap();
    let trig = Trigger::SendOnDelta { delta: 0.03 };
    let c = cfg(trig, Fusion::DiffusionCi);
    let mut a = [NodeState::new(start(), &trig); 3];
    let mut b = a;
    let (mut sa, mut sb) = ([NodeScratch::default(); 3], [NodeScratch::default(); 3]);
    for k in 1..60 {
        let obs: Vec<Observation<f64, 2>> =
            (0..3).map(|i| Observation::Measured(path(k, i))).collect();
        let inputs = StepInputs::new(&obs, 0.1);
        network_step(&c, &motion, &sensors, &w, &mut a, &mut sa, &inputs).unwrap();
        network_step(
            &c,
            &motion,
            &sensors,
            &w,
            &mut b,
            &mut sb,
            &inputs.with_deltas(&[0.03; 3]),
        )
        .unwrap();
        assert_eq!(a, b, "step {k}");
    }
}

#[test]
fn bad_thresholds_and_a_failed_normalised_decision_change_nothing() {
    let motion = ConstantVelocity::new(0.05).unwrap();
    let good = Pos2 {
        r: Matrix2::identity() * 0.01,
    };
    let w = [0.5, 0.5, 0.5, 0.5];
    let trig = Trigger::SendOnDeltaNormalised { delta: 2.0 };
    let c = cfg(trig, Fusion::DiffusionCi);
    let mut nodes = [NodeState::new(start(), &trig); 2];
    let mut scratch = [NodeScratch::default(); 2];
    let obs = [
        Observation::Measured(path(1, 0)),
        Observation::Measured(path(1, 1)),
    ];
    network_step(
        &c,
        &motion,
        &[good; 2],
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs, 0.1),
    )
    .unwrap();
    let before = nodes;
    let obs = [
        Observation::Measured(path(2, 0)),
        Observation::Measured(path(2, 1)),
    ];
    for (deltas, want) in [
        (
            &[2.0][..],
            Error::Dimension {
                what: "per-node thresholds (deltas)",
                expected: 2,
                got: 1,
            },
        ),
        (
            &[2.0, f64::NAN][..],
            Error::InvalidParameter {
                what: "delta",
                expected: "finite and > 0",
            },
        ),
        (
            &[-1.0, 2.0][..],
            Error::InvalidParameter {
                what: "delta",
                expected: "finite and > 0",
            },
        ),
    ] {
        let r = network_step(
            &c,
            &motion,
            &[good; 2],
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(&obs, 0.1).with_deltas(deltas),
        );
        assert_eq!(r.unwrap_err(), want);
        assert_eq!(nodes, before);
    }
    // A sensor whose R is singular: the normalised change cannot be formed.
    let singular = Pos2 {
        r: Matrix2::new(0.01, 0.0, 0.0, 0.0),
    };
    let r = network_step(
        &c,
        &motion,
        &[good, singular],
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs, 0.1),
    );
    assert_eq!(
        r.unwrap_err(),
        Error::NotPositiveDefinite {
            what: "measurement noise R"
        }
    );
    assert_eq!(nodes, before);
}
