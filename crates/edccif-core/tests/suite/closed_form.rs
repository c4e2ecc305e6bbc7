//! The closed form of the untriggered contribution
//! (`EtOptions::untriggered_closed_form`, the default, `untriggered_contribution_closed`)
//! against the stable form (`EtGain::new` + `untriggered_contribution`):
//!
//! - per call, on random SPD `P⁻`, random `G`, diagonal and non-diagonal `R`,
//!   `σ1, σ2 ∈ {5e-4, 0.1, 0.5}` and `δ ∈ {0, 0.04, 1}` (4 × 1080 cases): `Ī`
//!   and `ī` within 1e-9 of the scale of their terms (measured: at most
//!   1.6e-10), and a hand-computed value;
//! - whole ET-CIF steps of the default model: the same trigger decisions, the
//!   option does nothing to triggered steps or to the covariance-form filters
//!   (bit for bit), untriggered contributions within the same bound (measured:
//!   4.2e-16);
//! - bad input: the same named errors as the stable form (the matrix that fails
//!   definiteness is `R̃` instead of `S`), and a failed network step leaves the
//!   nodes unchanged.

use crate::common;

use common::*;
use edccif_core::fusion::max_degree_weights;
use edccif_core::models::LinearMeasurement;
use edccif_core::nalgebra::{SMatrix, SVector};
use edccif_core::{
    cif_predict, cif_update, cov_update, network_step, untriggered_contribution,
    untriggered_contribution_closed, Contribution, Error, EtGain, EtOptions, Fusion, Gaussian,
    LocalFilter, MeasurementModel, NetworkConfig, NodeFilter, NodeScratch, NodeState, Observation,
    StepInputs, Trigger, TriggerState,
};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// The per-call bound, relative to the scale of the terms (see [`compare`]).
/// Measured: at most 1.6e-10 on the random sweep, where `G P⁻ Gᵀ` exceeds
/// `R̃/μ1` by up to ~10⁵ (`δ = 0`, `R` down to 1e-4, `P⁻` up to ~10) and the
/// stable form's `P⁻ − M G P⁻` cancels; 4.2e-16 on the ET-CIF steps of the
/// default model.
const TOL: f64 = 1e-9;
const SIGMAS: [f64; 3] = [5e-4, 0.1, 0.5];
const DELTAS: [f64; 3] = [0.0, 0.04, 1.0];

fn uniform<const R: usize, const C: usize>(rng: &mut ChaCha8Rng, s: f64) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|_, _| s * rng.random_range(-1.0..1.0))
}

/// A random SPD matrix `L Lᵀ + s² I/10` of scale `s`.
fn spd<const D: usize>(rng: &mut ChaCha8Rng, s: f64) -> SMatrix<f64, D, D> {
    let l = uniform::<D, D>(rng, s);
    let a = l * l.transpose() + SMatrix::<f64, D, D>::identity() * (0.1 * s * s);
    (a + a.transpose()) * 0.5
}

fn max_abs<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>) -> f64 {
    a.abs().max()
}

/// The scale of `Ī = P̄⁻¹ − Y⁻`: the larger of `max|Y⁻|` and `max|Ī|`.
fn scale_imat(y: &SMatrix<f64, 7, 7>, imat: &SMatrix<f64, 7, 7>) -> f64 {
    max_abs(y).max(max_abs(imat))
}

/// Both forms at one input; the largest differences of `Ī` and `ī`, each
/// relative to the scale of its terms (`Ī`: the larger of `max|Y⁻|` and
/// `max|Ī|`; `ī`: the larger of `max|Y⁻ x̂⁻|`, `max|Ī x̂⁻|` and `max|ī|`), and
/// the difference of `Ī` relative to `max|Ī|` alone.
#[allow(clippy::too_many_arguments)]
fn compare<const D: usize, const K: usize>(
    x: &SVector<f64, D>,
    p: &SMatrix<f64, D, D>,
    g: &SMatrix<f64, K, D>,
    r: &SMatrix<f64, K, K>,
    delta: f64,
    opts: &EtOptions<f64>,
    dz: &SVector<f64, K>,
) -> (f64, f64, f64) {
    let y = p.cholesky().unwrap().inverse();
    let gain = EtGain::new(p, g, r, delta, opts).unwrap();
    let stable = untriggered_contribution(x, &y, g, &gain, dz).unwrap();
    let closed = untriggered_contribution_closed(x, &y, g, r, delta, opts, dz).unwrap();
    assert_eq!(closed.imat, closed.imat.transpose(), "Ī symmetric");
    let di = max_abs(&(closed.imat - stable.imat));
    let si = max_abs(&y).max(max_abs(&stable.imat));
    let sv = max_abs(&(y * x))
        .max(max_abs(&(stable.imat * x)))
        .max(max_abs(&stable.i));
    (
        di / si,
        max_abs(&(closed.i - stable.i)) / sv,
        di / max_abs(&stable.imat),
    )
}

fn sweep<const D: usize, const K: usize>(seed: u64) -> (f64, f64, f64, usize) {
    let mut rng = rng(seed);
    let (mut wi, mut wv, mut wrel, mut cases) = (0.0f64, 0.0f64, 0.0f64, 0);
    for round in 0..40 {
        let s = [0.03, 0.3, 3.0][round % 3];
        let p = spd::<D>(&mut rng, s);
        let g = uniform::<K, D>(&mut rng, 1.0);
        // Diagonal R (the built-in sensors) and full SPD R.
        let r = if round % 2 == 0 {
            SMatrix::<f64, K, K>::from_fn(|i, j| {
                if i == j {
                    10f64.powf(rng.random_range(-4.0..0.0))
                } else {
                    0.0
                }
            })
        } else {
            spd::<K>(&mut rng, 0.3)
        };
        let x = uniform::<D, 1>(&mut rng, 10.0);
        let dz = uniform::<K, 1>(&mut rng, 0.3);
        for sigma1 in SIGMAS {
            for sigma2 in SIGMAS {
                for delta in DELTAS {
                    let opts = EtOptions {
                        sigma1,
                        sigma2,
                        ..EtOptions::default()
                    };
                    let (ei, ev, erel) = compare(&x, &p, &g, &r, delta, &opts, &dz);
                    assert!(
                        ei < TOL && ev < TOL,
                        "seed {seed} round {round} σ1 {sigma1} σ2 {sigma2} δ {delta}: Ī {ei:e}, ī {ev:e}"
                    );
                    wi = wi.max(ei);
                    wv = wv.max(ev);
                    wrel = wrel.max(erel);
                    cases += 1;
                }
            }
        }
    }
    (wi, wv, wrel, cases)
}

#[test]
fn closed_form_equals_the_stable_form_on_random_inputs() {
    let results = [
        ("N 7, M 3", sweep::<7, 3>(1)),
        ("N 4, M 2", sweep::<4, 2>(2)),
        ("N 6, M 1", sweep::<6, 1>(3)),
        ("N 3, M 3", sweep::<3, 3>(4)),
    ];
    for (tag, (wi, wv, wrel, cases)) in results {
        eprintln!(
            "{tag}: {cases} cases, worst Ī {wi:.2e} of its scale ({wrel:.2e} of max|Ī|), ī {wv:.2e} of its scale"
        );
        // The comparison is not vacuous: the forms differ in their rounding.
        assert!(wi > 0.0 && wv > 0.0, "{tag}: identical bits");
    }
}

/// A hand-checkable case: `P⁻ = I`, `G = [1 0]`, `R = r`: `Ī = −κ I + e₁e₁ᵀ/r̃`.
#[test]
fn closed_form_matches_a_hand_computed_value() {
    let p = SMatrix::<f64, 2, 2>::identity();
    let g = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
    let r = SMatrix::<f64, 1, 1>::new(0.1);
    let (s1, s2, delta) = (0.1, 0.5, 0.04);
    let opts = EtOptions {
        sigma1: s1,
        sigma2: s2,
        ..EtOptions::default()
    };
    let rt = (1.0 + s2) * 0.1 + (1.0 + 1.0 / s1 + 1.0 / s2) * delta;
    let kappa = s1 / (1.0 + s1);
    let x = SVector::<f64, 2>::new(1.0, 2.0);
    let dz = SVector::<f64, 1>::new(0.3);
    let c = untriggered_contribution_closed(&x, &p, &g, &r, delta, &opts, &dz).unwrap();
    let want = SMatrix::<f64, 2, 2>::new(1.0 / rt - kappa, 0.0, 0.0, -kappa);
    assert!((c.imat - want).abs().max() < 1e-14, "{}", c.imat);
    let want_i = want * x + SVector::<f64, 2>::new(0.3 / rt, 0.0);
    assert!((c.i - want_i).abs().max() < 1e-14, "{}", c.i);
}

/// The option changes only the CIF's untriggered step: the same decisions, the
/// triggered and covariance-form steps bit for bit, the untriggered
/// contribution within the per-call bound.
#[test]
fn whole_steps_with_the_option_on_and_off() {
    let motion = ct();
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let mut rng = rng(7);
    let (mut untriggered, mut worst) = (0, 0.0f64);
    for i in 0..60 {
        let sensor = sensor_of(i % 4, 4);
        let est = initial_estimate(&mut rng);
        let x1 = propagate(&mut rng, &motion, &x0());
        let z = measure(&mut rng, &sensor, &x1);
        let obs = Observation::Measured(z);
        // Alternate: z was sent last (quiet), or far away (sent).
        let last = if i % 3 == 0 {
            z + Vec3::new(1.0, 0.0, 0.0)
        } else {
            z
        };
        let ts = TriggerState {
            last_sent: Some(last),
            eta: 0.04,
            rng: 0,
        };
        for sigma in SIGMAS {
            let off = EtOptions {
                sigma1: sigma,
                sigma2: sigma,
                untriggered_closed_form: false,
                ..EtOptions::default()
            };
            let on = EtOptions {
                untriggered_closed_form: true,
                ..off
            };
            let prior = cif_predict(&motion, 0.1, &est).unwrap();
            let a = cif_update(&sensor, &prior, &obs, &sod, &ts, &off).unwrap();
            let b = cif_update(&sensor, &prior, &obs, &sod, &ts, &on).unwrap();
            assert_eq!(a.triggered, b.triggered);
            assert_eq!(a.trigger_state, b.trigger_state);
            assert_eq!(a.prior, b.prior);
            if a.triggered == Some(true) {
                assert_eq!(a.contribution, b.contribution, "triggered: bit for bit");
            } else {
                untriggered += 1;
                let c: (&Contribution<f64, 7>, &Contribution<f64, 7>) =
                    (&a.contribution, &b.contribution);
                let y = a.prior.ymat;
                let ei = max_abs(&(c.0.imat - c.1.imat)) / scale_imat(&y, &c.0.imat);
                let sv = max_abs(&(y * a.x_prior))
                    .max(max_abs(&(c.0.imat * a.x_prior)))
                    .max(max_abs(&c.0.i));
                let ev = max_abs(&(c.0.i - c.1.i)) / sv;
                assert!(ei < TOL && ev < TOL, "step {i} σ {sigma}: {ei:e} {ev:e}");
                assert_ne!(a.contribution, b.contribution, "closed form not taken");
                worst = worst.max(ei).max(ev);
            }
            // Covariance-form filters ignore the option.
            let cov_prior = Gaussian {
                x: prior.x(),
                p: prior.p(),
            };
            for f in [LocalFilter::Ckf, LocalFilter::Ekf] {
                let a = cov_update(&f, &sensor, &cov_prior, &obs, &sod, &ts, &off).unwrap();
                let b = cov_update(&f, &sensor, &cov_prior, &obs, &sod, &ts, &on).unwrap();
                assert_eq!(a, b, "{f:?}");
            }
        }
    }
    eprintln!("{untriggered} untriggered steps, worst {worst:.2e}");
    assert!(
        untriggered >= 60,
        "too few untriggered steps: {untriggered}"
    );
}

/// Bad parameters and inputs give the stable form's named errors.
#[test]
fn bad_input_gives_the_same_named_errors() {
    let p = SMatrix::<f64, 2, 2>::new(2.0, 0.3, 0.3, 1.0);
    let y = p.try_inverse().unwrap();
    let x = SVector::<f64, 2>::new(1.0, -1.0);
    let g = SMatrix::<f64, 1, 2>::new(1.0, 0.5);
    let r = SMatrix::<f64, 1, 1>::new(0.1);
    let dz = SVector::<f64, 1>::new(0.2);
    let ok = EtOptions::<f64>::default();
    let both = |g: &SMatrix<f64, 1, 2>,
                r: &SMatrix<f64, 1, 1>,
                delta: f64,
                o: &EtOptions<f64>,
                dz: &SVector<f64, 1>| {
        let stable = EtGain::new(&p, g, r, delta, o)
            .and_then(|gain| untriggered_contribution(&x, &y, g, &gain, dz));
        let closed = untriggered_contribution_closed(&x, &y, g, r, delta, o, dz);
        (stable.unwrap_err(), closed.unwrap_err())
    };
    let inv = |what, expected| Error::InvalidParameter { what, expected };
    for (o, want) in [
        (
            EtOptions { sigma1: 0.0, ..ok },
            inv("sigma1", "finite and > 0"),
        ),
        (
            EtOptions {
                sigma2: f64::NAN,
                ..ok
            },
            inv("sigma2", "finite and > 0"),
        ),
        (
            EtOptions {
                gate: Some(-1.0),
                ..ok
            },
            inv("gate", "finite and > 0"),
        ),
    ] {
        assert_eq!(both(&g, &r, 0.04, &o, &dz), (want, want));
    }
    for delta in [-0.04, f64::NAN, f64::INFINITY] {
        let want = inv("delta", "finite and >= 0");
        assert_eq!(both(&g, &r, delta, &ok, &dz), (want, want), "δ {delta}");
    }
    let g_nan = SMatrix::<f64, 1, 2>::new(f64::NAN, 0.0);
    let want = Error::NonFinite {
        what: "measurement Jacobian G",
    };
    assert_eq!(both(&g_nan, &r, 0.04, &ok, &dz), (want, want));
    let dz_inf = SVector::<f64, 1>::new(f64::INFINITY);
    let want = Error::NonFinite {
        what: "innovation Δz̄",
    };
    assert_eq!(both(&g, &r, 0.04, &ok, &dz_inf), (want, want));
    // A non-finite or indefinite noise: the same variant, naming the matrix
    // each form factorises (`S`, `R̃`).
    let r_tilde = "untriggered noise R̃ = μ2 R + μ3 δ I";
    let s = "untriggered innovation covariance S";
    let r_nan = SMatrix::<f64, 1, 1>::new(f64::NAN);
    assert_eq!(
        both(&g, &r_nan, 0.04, &ok, &dz),
        (
            Error::NonFinite { what: s },
            Error::NonFinite { what: r_tilde }
        )
    );
    let r_neg = SMatrix::<f64, 1, 1>::new(-1e4);
    assert_eq!(
        both(&g, &r_neg, 0.04, &ok, &dz),
        (
            Error::NotPositiveDefinite { what: s },
            Error::NotPositiveDefinite { what: r_tilde }
        )
    );
}

/// A sensor whose noise is not positive definite (a model that skipped the
/// checks of the built-in ones).
struct BadNoise(LinearMeasurement<f64, 7, 3>);

impl MeasurementModel<f64, 7, 3> for BadNoise {
    fn measure(&self, x: &Vec7) -> Vec3 {
        self.0.measure(x)
    }
    fn noise(&self) -> SMatrix<f64, 3, 3> {
        SMatrix::identity() * -1e-3
    }
}

/// An untriggered network step that fails (`R̃ = μ2 R + μ3 δ I` indefinite for
/// `σ1 = σ2 = 1000`: `μ2 ≈ 1001`, `μ3 ≈ 1.002`) returns the named error and
/// leaves every node as it was, with the option on and off (the stable form
/// fails at `P̄`, which is then indefinite as well).
#[test]
fn failed_untriggered_steps_leave_the_nodes_unchanged() {
    let motion = ct();
    let h = SMatrix::<f64, 3, 7>::from_fn(|i, j| if j == 2 * i { 1.0 } else { 0.0 });
    let lin = LinearMeasurement::new(h, SMatrix::identity() * 1e-2).unwrap();
    let sensors: [_; 4] = core::array::from_fn(|_| BadNoise(lin));
    let mut w = [0.0; 16];
    max_degree_weights(&ring::<16>(), 4, &mut w).unwrap();
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let mut rng = rng(9);
    let stable_cfg = NetworkConfig {
        filter: NodeFilter::Cif,
        trigger: sod,
        et: EtOptions {
            sigma1: 1e3,
            sigma2: 1e3,
            untriggered_closed_form: false,
            ..EtOptions::default()
        },
        fusion: Fusion::DiffusionCi,
        rule: Default::default(),
    };
    let closed_cfg = NetworkConfig {
        et: EtOptions {
            untriggered_closed_form: true,
            ..stable_cfg.et
        },
        ..stable_cfg
    };
    let z = measure(&mut rng, &lin, &x0());
    let obs = [Observation::Measured(z); 4];
    // Every node sent this very measurement last: nobody sends now.
    let mut start = NodeState::new(Gaussian::new(x0(), p0() * 100.0).unwrap(), &sod);
    start.trigger.last_sent = Some(z);
    for (cfg, want) in [
        (&closed_cfg, "untriggered noise R̃ = μ2 R + μ3 δ I"),
        (&stable_cfg, "error covariance bound P̄"),
    ] {
        let mut nodes = [start; 4];
        let mut scratch = [NodeScratch::default(); 4];
        let err = network_step(
            cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(&obs, 0.1),
        )
        .unwrap_err();
        assert_eq!(err, Error::NotPositiveDefinite { what: want });
        assert_eq!(nodes, [start; 4], "a failed step changes no node");
    }
}
