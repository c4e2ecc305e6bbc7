//! The fuzz harness shared by the cargo-fuzz targets (`fuzz_targets/`) and the
//! core's regression tests (`crates/edccif-core/tests/suite/fuzz_regressions.rs`, which
//! includes this file), so a crash input is always replayed through the same
//! decoding and invariants: arbitrary bytes → floats, matrices and model
//! parameters, and the checks made on every `Ok`. It uses only `edccif_core`.

use edccif_core::fusion::max_degree_weights;
use edccif_core::fusion::{
    adapt, ci_fuse_optimal, combine_ci, combine_convex, combine_information, consensus_iteration,
};
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::nalgebra::{SMatrix, SVector};
use edccif_core::*;

/// Reads values from the fuzzer's bytes; past the end everything is 0.
pub struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Bytes<'a> {
    /// Wraps the input.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }

    /// One byte.
    pub fn u8(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    /// A boolean.
    pub fn bool(&mut self) -> bool {
        self.u8() & 1 == 1
    }

    /// A float: mostly moderate values in about [-10, 10], sometimes special
    /// values (NaN, ±∞, 0, huge, tiny) or raw 8-byte patterns.
    pub fn f(&mut self) -> f64 {
        let tag = self.u8();
        match tag {
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
            _ => {
                let v = i16::from_le_bytes([self.u8(), self.u8()]);
                f64::from(v) / 3276.8
            }
        }
    }

    /// A positive scale: `10^(f/2)` for a moderate draw, else a raw [`f`](Self::f).
    pub fn pos(&mut self) -> f64 {
        if self.u8() < 240 {
            10f64.powf(self.f().clamp(-20.0, 20.0) / 2.0)
        } else {
            self.f()
        }
    }

    /// A vector.
    pub fn vec<const D: usize>(&mut self) -> SVector<f64, D> {
        SVector::from_fn(|_, _| self.f())
    }

    /// A covariance: usually `L Lᵀ + ε I` (PD), sometimes an arbitrary matrix.
    pub fn cov<const D: usize>(&mut self) -> SMatrix<f64, D, D> {
        if self.u8() < 230 {
            let l = SMatrix::<f64, D, D>::from_fn(|i, j| if j <= i { self.f() } else { 0.0 });
            let eps = self.pos();
            l * l.transpose() + SMatrix::identity() * eps
        } else {
            SMatrix::from_fn(|_, _| self.f())
        }
    }
}

/// Every entry finite.
pub fn finite<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> bool {
    m.iter().all(|v| v.is_finite())
}

/// Symmetric (exactly, as the core symmetrises) and Cholesky-PD.
pub fn spd<const D: usize>(m: &SMatrix<f64, D, D>) -> bool {
    finite(m) && *m == m.transpose() && m.cholesky().is_some()
}

/// The invariant of an estimate the core returned.
pub fn check_gaussian<const D: usize>(g: &Gaussian<f64, D>, what: &str) {
    assert!(finite(&g.x), "{what}: non-finite x {:?}", g.x);
    assert!(spd(&g.p), "{what}: covariance not symmetric PD {:?}", g.p);
}

/// The invariant of an information pair the core returned (finite, Y symmetric).
pub fn check_info<const D: usize>(p: &InfoPair<f64, D>, what: &str) {
    assert!(finite(&p.y) && finite(&p.ymat), "{what}: non-finite");
    assert!(p.ymat == p.ymat.transpose(), "{what}: Y not symmetric");
}

/// `cif_local` on the default models with fuzzed parameters, estimate,
/// measurement, trigger and options.
pub fn cif_local_case(data: &[u8]) {
    let mut b = Bytes::new(data);
    let dt = b.pos();
    let Ok(motion) = CoordinatedTurn::new(b.pos(), b.pos()) else {
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
    let trigger = match b.u8() % 3 {
        0 => Trigger::Always,
        1 => Trigger::SendOnDelta { delta: b.pos() },
        _ => Trigger::Dynamic {
            delta: b.pos(),
            lambda: b.f(),
            theta: b.pos(),
        },
    };
    let mut ts = TriggerState::new(&trigger);
    if b.bool() {
        ts.last_sent = Some(b.vec::<3>());
    }
    let policy = [EtPolicy::Optimal, EtPolicy::Hold, EtPolicy::Skip][usize::from(b.u8() % 3)];
    let opts = EtOptions {
        policy,
        sigma1: b.pos(),
        sigma2: b.pos(),
        gate: if b.bool() { Some(b.pos()) } else { None },
        untriggered_closed_form: false,
    };
    if let Ok(r) = cif_local(&motion, dt, &sensor, &estimate, &obs, &trigger, &ts, &opts) {
        assert!(finite(&r.x_prior), "x_prior");
        assert!(spd(&r.p_prior), "P⁻ not symmetric PD");
        check_info(&r.prior, "prior");
        assert!(
            finite(&r.contribution.i) && finite(&r.contribution.imat),
            "contribution"
        );
        if r.gated {
            assert_eq!(r.triggered, Some(true));
            assert_eq!(r.contribution.imat, SMatrix::<f64, 7, 7>::zeros());
        }
    }
}

/// `cov_local` for the CKF, EKF and UKF with fuzzed inputs.
pub fn cov_local_case(data: &[u8]) {
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
    let dt = b.pos();
    let Ok(motion) = CoordinatedTurn::new(b.pos(), b.pos()) else {
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
    let trigger = match b.u8() % 3 {
        0 => Trigger::Always,
        1 => Trigger::SendOnDelta { delta: b.pos() },
        _ => Trigger::Dynamic {
            delta: b.pos(),
            lambda: b.f(),
            theta: b.pos(),
        },
    };
    let mut ts = TriggerState::new(&trigger);
    if b.bool() {
        ts.last_sent = Some(b.vec::<3>());
    }
    let policy = [EtPolicy::Optimal, EtPolicy::Hold, EtPolicy::Skip][usize::from(b.u8() % 3)];
    let opts = EtOptions {
        policy,
        sigma1: b.pos(),
        sigma2: b.pos(),
        gate: if b.bool() { Some(b.pos()) } else { None },
        untriggered_closed_form: false,
    };
    if let Ok(r) = cov_local(
        &filter, &motion, dt, &sensor, &estimate, &obs, &trigger, &ts, &opts,
    ) {
        check_gaussian(&r.posterior, "posterior");
    }
}

/// The fusion functions: adaptation, CI / information / convex combination,
/// a consensus iteration and optimal-weight CI, on fuzzed information pairs,
/// estimates and weights.
pub fn fusion_case(data: &[u8]) {
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

    let a = adapt(&infos[0], &contribs[0], contribs[1..].iter());
    if a.to_gaussian().is_ok() {
        // `to_gaussian` succeeded: its result must satisfy the estimate invariant
        check_gaussian(&a.to_gaussian().unwrap(), "adapted");
    }
    if let Ok(g) = combine_ci(w.iter().copied().zip(infos.iter())) {
        check_gaussian(&g, "combine_ci");
    }
    if let Ok(p) = combine_information(w.iter().copied().zip(infos.iter())) {
        check_info(&p, "combine_information");
    }
    if let Ok(g) = combine_convex(w.iter().copied().zip(gs.iter())) {
        // a convex combination of valid estimates is valid; of invalid ones, finite
        if gs.iter().all(|g| Gaussian::new(g.x, g.p).is_ok()) {
            check_gaussian(&g, "combine_convex");
        } else {
            assert!(finite(&g.x) && finite(&g.p), "combine_convex: non-finite");
        }
    }
    let wm: Vec<f64> = (0..k * k).map(|_| f64::from(b.u8()) / 255.0).collect();
    let mut next = vec![InfoPair::zeros(); k];
    if consensus_iteration(&wm, &infos, &mut next).is_ok() {
        for p in &next {
            check_info(p, "consensus_iteration");
        }
    }
    let crit = if b.bool() {
        CiCriterion::Trace
    } else {
        CiCriterion::Determinant
    };
    let mut ow = vec![0.0; k];
    if let Ok(g) = ci_fuse_optimal(&infos, crit, &mut ow) {
        check_gaussian(&g, "ci_fuse_optimal");
        assert!(
            ow.iter().all(|v| v.is_finite() && *v >= 0.0),
            "CI weights {ow:?}"
        );
    }
}

/// A few `network_step`s of 1–4 nodes with fuzzed graph, weights, masks,
/// observations and configuration. On error no node state may change; on success
/// every active node's estimate is finite and PD.
pub fn network_step_case(data: &[u8]) {
    let mut b = Bytes::new(data);
    let k = 1 + usize::from(b.u8() % 4);
    let dt = b.pos();
    let Ok(motion) = CoordinatedTurn::new(b.pos(), b.pos()) else {
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
            // an invalid graph: try the ring instead
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
    let trigger = if b.bool() {
        Trigger::SendOnDelta { delta: b.pos() }
    } else {
        Trigger::Always
    };
    let et = EtOptions {
        policy: EtPolicy::Optimal,
        sigma1: b.pos(),
        sigma2: b.pos(),
        gate: if b.bool() { Some(b.pos()) } else { None },
        untriggered_closed_form: false,
    };
    // Under diffusion with CI, any fusion rule (docs/fusion.md).
    let rule = if fusion == Fusion::DiffusionCi {
        FusionRule::ALL[usize::from(b.u8()) % FusionRule::ALL.len()]
    } else {
        FusionRule::CI
    };
    let cfg = NetworkConfig {
        filter,
        trigger,
        et,
        fusion,
        rule,
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
            dt,
            observations: &obs,
            links: if b.bool() { Some(&links) } else { None },
            edge_links: None,
            active: if b.bool() { Some(&active) } else { None },
            deltas: None,
        };
        let before = nodes.clone();
        match network_step(
            &cfg,
            &motion,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &inputs,
        ) {
            Ok(rep) => {
                assert!(rep.triggered <= rep.measured && rep.measured <= k && rep.gated <= k);
                for (i, n) in nodes.iter().enumerate() {
                    if inputs.active.is_none_or(|a| a[i]) {
                        check_gaussian(&n.estimate, "fused estimate");
                    } else {
                        assert_eq!(
                            format!("{n:?}"),
                            format!("{:?}", before[i]),
                            "inactive node changed"
                        );
                    }
                }
            }
            Err(_) => {
                // compare bit patterns via Debug (NaN != NaN)
                assert_eq!(
                    format!("{nodes:?}"),
                    format!("{before:?}"),
                    "failed step changed a node"
                );
                return;
            }
        }
    }
}

/// The wire decoder on arbitrary bytes: no panic; an accepted packet has the
/// exact length of its kind and dimension, finite values, and encodes back to the
/// very same bytes. Then one packet built from the fuzzer's values (header,
/// kind, dimension, entries) must either be rejected by the encoder (non-finite
/// value) or decode to exactly the values given.
pub fn wire_case(data: &[u8]) {
    use edccif_core::wire::{self, Header, Kind};
    if let Ok(f) = wire::decode(data) {
        assert_eq!(data.len(), wire::packet_len(f.kind, f.dim));
        let vector: Vec<f64> = (0..f.dim).map(|i| f.value(i)).collect();
        assert!(vector.iter().all(|v| v.is_finite()));
        let matrix: Option<Vec<f64>> = f.kind.has_matrix().then(|| {
            (0..f.dim * f.dim)
                .map(|t| f.matrix_entry(t / f.dim, t % f.dim))
                .collect()
        });
        let mut out = [0u8; wire::MAX_PACKET_LEN];
        let n = wire::encode(f.kind, &f.header, &vector, matrix.as_deref(), &mut out)
            .expect("an accepted packet re-encodes");
        assert_eq!(&out[..n], data, "decode → encode changed the bytes");
    }
    let mut b = Bytes::new(data);
    let kind = Kind::from_byte(1 + b.u8() % 4).unwrap();
    let dim = 1 + usize::from(b.u8()) % 9;
    let header = Header {
        swarm: u32::from_le_bytes([b.u8(), b.u8(), b.u8(), b.u8()]),
        sender: u16::from_le_bytes([b.u8(), b.u8()]),
        step: u64::from(b.u8()) << 40 | u64::from(b.u8()),
        round: b.u8(),
        stamp_ns: u64::from(b.u8()) << 50 | u64::from(b.u8()),
    };
    let vector: Vec<f64> = (0..dim).map(|_| b.f()).collect();
    let mut matrix = vec![0.0; dim * dim];
    for r in 0..dim {
        for c in r..dim {
            let v = b.f();
            matrix[r * dim + c] = v;
            matrix[c * dim + r] = v;
        }
    }
    let mut out = [0u8; wire::MAX_PACKET_LEN];
    let m = kind.has_matrix().then_some(&matrix[..]);
    match wire::encode(kind, &header, &vector, m, &mut out) {
        Ok(n) => {
            let f = wire::decode(&out[..n]).expect("an encoded packet decodes");
            assert_eq!((f.header, f.kind, f.dim), (header, kind, dim));
            for (i, v) in vector.iter().enumerate() {
                assert_eq!(f.value(i).to_bits(), v.to_bits());
            }
            if kind.has_matrix() {
                for (t, v) in matrix.iter().enumerate() {
                    assert_eq!(f.matrix_entry(t / dim, t % dim).to_bits(), v.to_bits());
                }
            }
            // every strict prefix is truncated, one more byte is oversized
            assert!(matches!(
                wire::decode(&out[..n - 1]),
                Err(wire::WireError::Truncated { .. })
            ));
            assert!(matches!(
                wire::decode(&out[..n + 1]),
                Err(wire::WireError::Oversized { .. })
            ));
        }
        Err(e) => {
            assert!(
                matches!(e, wire::WireError::NonFinite { .. }),
                "unexpected encode error {e}"
            );
            assert!(vector
                .iter()
                .chain(m.unwrap_or(&[]))
                .any(|v| !v.is_finite()));
        }
    }
}
