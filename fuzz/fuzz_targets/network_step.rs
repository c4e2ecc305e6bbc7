//! A few `network_step`s of 1–4 nodes with fuzzed graph, weights, masks,
//! observations and configuration. On error no node state may change; on success
//! every active node's estimate is finite and PD.
#![no_main]
use edccif_core::fusion::max_degree_weights;
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::*;
use edccif_fuzz::*;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
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
    };
    let cfg = NetworkConfig {
        filter,
        trigger,
        et,
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
});
