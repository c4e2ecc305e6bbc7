//! Regression tests for the inputs `cargo fuzz` (fuzz/) found, each replayed
//! through a copy of its fuzz target's decoding and invariants:
//!
//! - `cov_local`: badly scaled inputs made `P⁻ − K Pxzᵀ` indefinite by
//!   cancellation and it was returned → `cov_local` now factorises its posterior.
//! - `cif_local`: `ŷ⁻ = Y⁻ x̂⁻` overflowed to ∞ with a finite `Y⁻` → now checked.
//! - `fusion`: `combine_information` returned non-finite sums → now checked
//!   (also `combine_convex`, which now factorises its result).
//! - `network_step`: a fused covariance from `InfoPair::to_gaussian` of a badly
//!   conditioned `Y` was indefinite → `to_gaussian` now factorises `P = Y⁻¹`.
//!   (`70979f67` was a harness bug — comparing NaN states with `==` — kept as a
//!   check that a failed step leaves the nodes bit-for-bit unchanged.)

use edccif_core::fusion::{
    adapt, ci_fuse_optimal, combine_ci, combine_convex, combine_information, consensus_iteration,
    max_degree_weights,
};
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::*;
use nalgebra::{SMatrix, SVector};

struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Bytes<'a> {
    fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }
    fn u8(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }
    fn bool(&mut self) -> bool {
        self.u8() & 1 == 1
    }
    fn f(&mut self) -> f64 {
        match self.u8() {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => 0.0,
            4 => 1e300,
            5 => 1e-300,
            6 => -1.0,
            7 => {
                let mut b = [0u8; 8];
                for v in &mut b {
                    *v = self.u8();
                }
                f64::from_le_bytes(b)
            }
            _ => f64::from(i16::from_le_bytes([self.u8(), self.u8()])) / 3276.8,
        }
    }
    fn pos(&mut self) -> f64 {
        if self.u8() < 240 {
            10f64.powf(self.f().clamp(-20.0, 20.0) / 2.0)
        } else {
            self.f()
        }
    }
    fn vec<const D: usize>(&mut self) -> SVector<f64, D> {
        SVector::from_fn(|_, _| self.f())
    }
    fn cov<const D: usize>(&mut self) -> SMatrix<f64, D, D> {
        if self.u8() < 230 {
            let l = SMatrix::<f64, D, D>::from_fn(|i, j| if j <= i { self.f() } else { 0.0 });
            let eps = self.pos();
            l * l.transpose() + SMatrix::identity() * eps
        } else {
            SMatrix::from_fn(|_, _| self.f())
        }
    }
}

fn finite<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> bool {
    m.iter().all(|v| v.is_finite())
}

fn spd<const D: usize>(m: &SMatrix<f64, D, D>) -> bool {
    finite(m) && *m == m.transpose() && m.cholesky().is_some()
}

fn check_gaussian<const D: usize>(g: &Gaussian<f64, D>, what: &str) {
    assert!(finite(&g.x), "{what}: non-finite x");
    assert!(spd(&g.p), "{what}: covariance not symmetric PD");
}

fn check_info<const D: usize>(p: &InfoPair<f64, D>, what: &str) {
    assert!(finite(&p.y) && finite(&p.ymat), "{what}: non-finite");
    assert!(p.ymat == p.ymat.transpose(), "{what}: Y not symmetric");
}

fn trigger(b: &mut Bytes) -> Trigger<f64> {
    match b.u8() % 3 {
        0 => Trigger::Always,
        1 => Trigger::SendOnDelta { delta: b.pos() },
        _ => Trigger::Dynamic {
            delta: b.pos(),
            lambda: b.f(),
            theta: b.pos(),
        },
    }
}

fn et(b: &mut Bytes, policy: EtPolicy) -> EtOptions<f64> {
    EtOptions {
        policy,
        sigma1: b.pos(),
        sigma2: b.pos(),
        gate: if b.bool() { Some(b.pos()) } else { None },
    }
}

fn cif_local_case(data: &[u8]) {
    let mut b = Bytes::new(data);
    let Ok(motion) = CoordinatedTurn::new(b.pos(), b.pos(), b.pos()) else {
        return;
    };
    let Ok(sensor) = RangePitchAzimuth::new([b.f(), b.f(), b.f()], b.pos(), b.pos()) else {
        return;
    };
    let estimate = Gaussian {
        x: b.vec::<7>(),
        p: b.cov::<7>(),
    };
    let obs = if b.u8() < 30 {
        Observation::Missing
    } else {
        Observation::Measured(b.vec::<3>())
    };
    let trig = trigger(&mut b);
    let mut ts = TriggerState::new(&trig);
    if b.bool() {
        ts.last_sent = Some(b.vec::<3>());
    }
    let policy = [EtPolicy::Optimal, EtPolicy::Hold, EtPolicy::Skip][usize::from(b.u8() % 3)];
    let opts = et(&mut b, policy);
    if let Ok(r) = cif_local(&motion, &sensor, &estimate, &obs, &trig, &ts, &opts) {
        assert!(finite(&r.x_prior) && spd(&r.p_prior));
        check_info(&r.prior, "prior");
        assert!(finite(&r.contribution.i) && finite(&r.contribution.imat));
    }
}

fn cov_local_case(data: &[u8]) {
    let mut b = Bytes::new(data);
    let filter = match b.u8() % 3 {
        0 => LocalFilter::Ckf,
        1 => LocalFilter::Ekf,
        _ => LocalFilter::Ukf {
            alpha: b.pos(),
            beta: b.f(),
            kappa: b.f(),
        },
    };
    let Ok(motion) = CoordinatedTurn::new(b.pos(), b.pos(), b.pos()) else {
        return;
    };
    let Ok(sensor) = RangePitchAzimuth::new([b.f(), b.f(), b.f()], b.pos(), b.pos()) else {
        return;
    };
    let estimate = Gaussian {
        x: b.vec::<7>(),
        p: b.cov::<7>(),
    };
    let obs = if b.u8() < 30 {
        Observation::Missing
    } else {
        Observation::Measured(b.vec::<3>())
    };
    let trig = trigger(&mut b);
    let mut ts = TriggerState::new(&trig);
    if b.bool() {
        ts.last_sent = Some(b.vec::<3>());
    }
    let policy = [EtPolicy::Optimal, EtPolicy::Hold, EtPolicy::Skip][usize::from(b.u8() % 3)];
    let opts = et(&mut b, policy);
    if let Ok(r) = cov_local(
        &filter, &motion, &sensor, &estimate, &obs, &trig, &ts, &opts,
    ) {
        check_gaussian(&r.posterior, "posterior");
    }
}

fn fusion_case(data: &[u8]) {
    let mut b = Bytes::new(data);
    let k = 1 + usize::from(b.u8() % 4);
    let infos: Vec<InfoPair<f64, 4>> = (0..k)
        .map(|_| InfoPair {
            y: b.vec::<4>(),
            ymat: b.cov::<4>(),
        })
        .collect();
    let gs: Vec<Gaussian<f64, 4>> = (0..k)
        .map(|_| Gaussian {
            x: b.vec::<4>(),
            p: b.cov::<4>(),
        })
        .collect();
    let w: Vec<f64> = (0..k)
        .map(|_| {
            if b.u8() < 200 {
                f64::from(b.u8()) / 255.0
            } else {
                b.f()
            }
        })
        .collect();
    let contribs: Vec<Contribution<f64, 4>> = (0..k)
        .map(|_| Contribution {
            i: b.vec::<4>(),
            imat: b.cov::<4>(),
        })
        .collect();
    if let Ok(g) = adapt(&infos[0], &contribs[0], contribs[1..].iter()).to_gaussian() {
        check_gaussian(&g, "adapted");
    }
    if let Ok(g) = combine_ci(w.iter().copied().zip(infos.iter())) {
        check_gaussian(&g, "combine_ci");
    }
    if let Ok(p) = combine_information(w.iter().copied().zip(infos.iter())) {
        check_info(&p, "combine_information");
    }
    if let Ok(g) = combine_convex(w.iter().copied().zip(gs.iter())) {
        if gs.iter().all(|g| Gaussian::new(g.x, g.p).is_ok()) {
            check_gaussian(&g, "combine_convex");
        } else {
            assert!(finite(&g.x) && finite(&g.p));
        }
    }
    let wm: Vec<f64> = (0..k * k).map(|_| f64::from(b.u8()) / 255.0).collect();
    let mut next = vec![InfoPair::zeros(); k];
    if consensus_iteration(&wm, &infos, &mut next).is_ok() {
        next.iter()
            .for_each(|p| check_info(p, "consensus_iteration"));
    }
    let crit = if b.bool() {
        CiCriterion::Trace
    } else {
        CiCriterion::Determinant
    };
    let mut ow = vec![0.0; k];
    if let Ok(g) = ci_fuse_optimal(&infos, crit, &mut ow) {
        check_gaussian(&g, "ci_fuse_optimal");
    }
}

fn network_step_case(data: &[u8]) {
    let mut b = Bytes::new(data);
    let k = 1 + usize::from(b.u8() % 4);
    let Ok(motion) = CoordinatedTurn::new(b.pos(), b.pos(), b.pos()) else {
        return;
    };
    let mut sensors = Vec::new();
    for _ in 0..k {
        let Ok(s) = RangePitchAzimuth::new([b.f(), b.f(), b.f()], b.pos(), b.pos()) else {
            return;
        };
        sensors.push(s);
    }
    let adjacency: Vec<bool> = (0..k * k).map(|_| b.bool()).collect();
    let mut w = vec![0.0; k * k];
    if b.u8() < 200 {
        if max_degree_weights(&adjacency, k, &mut w).is_err() {
            let ring: Vec<bool> = (0..k * k)
                .map(|ij| {
                    let (i, j) = (ij / k, ij % k);
                    i != j && ((i + 1) % k == j || (j + 1) % k == i)
                })
                .collect();
            if max_degree_weights(&ring, k, &mut w).is_err() {
                return;
            }
        }
    } else {
        w.iter_mut().for_each(|v| *v = b.f());
    }
    let filter = match b.u8() % 4 {
        0 => NodeFilter::Cov(LocalFilter::Ckf),
        1 => NodeFilter::Cov(LocalFilter::Ekf),
        2 => NodeFilter::Cov(LocalFilter::ukf_default()),
        _ => NodeFilter::Cif,
    };
    let fusion = match b.u8() % 4 {
        0 => Fusion::DiffusionCi,
        1 => Fusion::DiffusionConvex,
        2 => Fusion::Consensus {
            iterations: usize::from(b.u8() % 4),
        },
        _ => Fusion::Local,
    };
    let trig = if b.bool() {
        Trigger::SendOnDelta { delta: b.pos() }
    } else {
        Trigger::Always
    };
    let cfg = NetworkConfig {
        filter,
        trigger: trig,
        et: et(&mut b, EtPolicy::Optimal),
        fusion,
    };
    let start = Gaussian {
        x: b.vec::<7>(),
        p: b.cov::<7>(),
    };
    let mut nodes = vec![NodeState::<f64, 7, 3>::new(start, &cfg.trigger); k];
    let mut scratch = vec![NodeScratch::default(); k];
    for _ in 0..3 {
        let obs: Vec<Observation<f64, 3>> = (0..k)
            .map(|_| {
                if b.u8() < 40 {
                    Observation::Missing
                } else {
                    Observation::Measured(b.vec::<3>())
                }
            })
            .collect();
        let links: Vec<bool> = (0..k * k).map(|_| b.u8() > 60).collect();
        let active: Vec<bool> = (0..k).map(|_| b.u8() > 30).collect();
        let inputs = StepInputs {
            observations: &obs,
            links: if b.bool() { Some(&links) } else { None },
            active: if b.bool() { Some(&active) } else { None },
        };
        let before = format!("{nodes:?}");
        match network_step(
            &cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &inputs,
        ) {
            Ok(_) => {
                for (i, n) in nodes.iter().enumerate() {
                    if inputs.active.is_none_or(|a| a[i]) {
                        check_gaussian(&n.estimate, "fused estimate");
                    }
                }
            }
            Err(_) => {
                assert_eq!(format!("{nodes:?}"), before, "failed step changed a node");
                return;
            }
        }
    }
}

#[test]
fn cif_local_regressions() {
    cif_local_case(CIF_LOCAL_74C5AE23);
}

#[test]
fn cov_local_regressions() {
    cov_local_case(COV_LOCAL_D9D1704C);
}

#[test]
fn fusion_regressions() {
    fusion_case(FUSION_0860408A);
}

#[test]
fn network_step_regressions() {
    network_step_case(NETWORK_STEP_3A80A97D);
    network_step_case(NETWORK_STEP_70979F67);
}

/// `fuzz/artifacts/cif_local/crash-74c5ae2351a4d9cec262f055af76215f56e48f8d`
const CIF_LOCAL_74C5AE23: &[u8] = &[
    3, 253, 255, 250, 253, 5, 3, 3, 3, 3, 3, 2, 3, 3, 7, 7, 7, 7, 39, 7, 5, 7, 7, 7, 7, 7, 7, 7, 7,
    7, 7, 7, 35, 7, 7, 7, 7, 7, 7, 254, 7, 3, 3, 79, 79, 79, 79, 79, 79, 79, 79, 79, 79, 79, 79,
    79, 79, 79, 79, 79, 79, 79, 79, 79, 79, 79, 79, 79, 36, 79, 79, 79, 79, 79, 79, 79, 79, 79, 79,
    79, 79, 79, 79, 79, 3, 3, 3, 3, 3, 3, 3, 3, 3, 5, 3, 3, 3, 75, 79, 79, 79, 79, 79, 79, 79, 111,
    79, 79, 79, 79, 79, 79, 79, 79, 79, 33, 79, 79, 79, 79, 79, 79, 244, 79, 79, 79, 79, 79, 79,
    79, 79, 3, 3, 5, 3, 98, 3, 47, 1, 3, 3, 7, 0,
];

/// `fuzz/artifacts/cov_local/crash-d9d1704cc174391186a0b680cfe0fb56446a0560`
const COV_LOCAL_D9D1704C: &[u8] = &[
    10, 11, 1, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110,
    110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110,
    110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110,
    110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110,
    110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110,
    110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110,
    110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110,
    110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 110, 247, 247, 247, 247, 247,
    247, 247, 247, 247, 247, 247, 247, 247, 110, 110, 110, 110, 110, 110, 110,
];

/// `fuzz/artifacts/fusion/crash-0860408ae2b47e4082e462dc60e26fe315e1a5a4`
const FUSION_0860408A: &[u8] = &[
    0, 0, 0, 5, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 8, 0, 0, 1, 0, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0,
    1, 0, 0, 1, 2,
];

/// `fuzz/artifacts/network_step/crash-3a80a97dd6071b059f37bbdad2167de20c6ddb80`
const NETWORK_STEP_3A80A97D: &[u8] = &[
    0, 1, 1, 6, 6, 6, 6, 6, 6, 6, 6, 6, 6, 6, 138, 59, 1, 6, 149, 3, 6, 6, 149, 3, 0, 6, 6, 6, 6,
    138, 6, 6, 6, 6, 6, 6, 6, 3, 3, 3, 3, 5, 5, 5, 5, 5, 5, 5, 6, 6, 6, 6, 6, 6, 6, 6, 6, 6, 138,
    59, 1, 6, 149, 3, 6, 6, 149, 3, 0, 6, 6, 6, 6, 138, 6, 6, 5, 5, 5, 5, 5, 5, 5, 5, 5, 10,
];

/// `fuzz/artifacts/network_step/crash-70979f677ce1bb7ba9132e1d41b9c43bb22306be`
const NETWORK_STEP_70979F67: &[u8] =
    &[4, 4, 4, 86, 86, 86, 86, 86, 86, 86, 86, 4, 4, 4, 4, 4, 4, 4];
