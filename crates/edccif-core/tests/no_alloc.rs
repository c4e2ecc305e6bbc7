//! The core allocates nothing: whole network steps of every algorithm row
//! (ALGORITHM.md §5) on the 8-node ring of §6, driven from fixed-size arrays,
//! run under a counting global allocator and must make exactly zero allocation
//! calls (alloc, alloc_zeroed, realloc) over 50 steps.
//!
//! `#[global_allocator]` is per binary, hence this file of its own. Counting is
//! per thread (a thread-local "armed" flag and counter, both const-initialised
//! `Cell`s, which never allocate): libtest runs tests on parallel threads and
//! allocates for its own bookkeeping, which must not be attributed to a step.
//!
//! The workspace forbids `unsafe`; edccif-core's Cargo.toml lowers that to
//! `deny` for this crate's targets so this file can allow it (the library keeps
//! `#![forbid(unsafe_code)]`).
#![allow(unsafe_code)]

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use common::*;
use edccif_core::fusion::max_degree_weights;
use edccif_core::models::RangePitchAzimuth;
use edccif_core::{
    network_step, network_step_sparse, EtOptions, Fusion, LocalFilter, Neighbours, NetworkConfig,
    NodeFilter, NodeScratch, NodeState, Observation, StepInputs, Trigger,
};

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static ALLOCS: Cell<usize> = const { Cell::new(0) };
}

/// `System`, counting the allocation calls of armed threads.
struct Counting;

fn note_alloc() {
    // `try_with`: during thread teardown the locals may be gone; not armed then.
    let armed = ARMED.try_with(Cell::get).unwrap_or(false);
    if armed {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
    }
}

// SAFETY: every method forwards to `System` with the caller's arguments
// unchanged; the bookkeeping touches only const-initialised thread-local `Cell`s
// and never allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_alloc();
        // SAFETY: forwarded contract of `GlobalAlloc::alloc`.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_alloc();
        // SAFETY: forwarded contract of `GlobalAlloc::alloc_zeroed`.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_alloc();
        // SAFETY: forwarded contract of `GlobalAlloc::realloc`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded contract of `GlobalAlloc::dealloc`.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Runs `f` with this thread's counter armed; returns its result and the number
/// of allocation calls it made.
fn count_allocs<R>(f: impl FnOnce() -> R) -> (R, usize) {
    ALLOCS.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let r = f();
    ARMED.with(|a| a.set(false));
    (r, ALLOCS.with(Cell::get))
}

const K: usize = 8;
const STEPS: usize = 50;

/// Ring-of-8 consensus iterations of §5 (`L = 22`).
const L_RING8: usize = 22;

/// The §6 scenario with 8 nodes: sensors, observations of 50 steps (made before
/// the counted window), the common initial estimate and the final true state.
type Scenario = (
    [RangePitchAzimuth<f64>; K],
    [[Observation<f64, 3>; K]; STEPS],
    edccif_core::Gaussian<f64, 7>,
    Vec7,
);

fn scenario(seed: u64) -> Scenario {
    let sensors: [_; K] = core::array::from_fn(|i| sensor_of(i, K));
    let mut rng = rng(seed);
    let start = initial_estimate(&mut rng);
    let motion = ct();
    let mut x = x0();
    let mut obs = [[Observation::Missing; K]; STEPS];
    for row in obs.iter_mut() {
        x = propagate(&mut rng, &motion, &x);
        for (o, s) in row.iter_mut().zip(&sensors) {
            *o = Observation::Measured(measure(&mut rng, s, &x));
        }
    }
    // A few outages, so that the missing-measurement path runs too.
    obs[10][3] = Observation::Missing;
    obs[31][0] = Observation::Missing;
    (sensors, obs, start, x)
}

struct RowRun {
    allocs: usize,
    triggered: usize,
    measured: usize,
    nodes: [NodeState<f64, 7, 3>; K],
    truth: Vec7,
}

/// 50 network steps of `cfg` from fixed-size arrays, the weights and the neighbour
/// lists computed, the configuration validated and every step run inside the
/// counted window (odd steps over the neighbour lists, `network_step_sparse`). With
/// `masks`, steps 20..25 lose the links 1→2 and 5→4, and node 6 is down at
/// steps 40..43.
fn run_row(cfg: &NetworkConfig<f64>, seed: u64, masks: bool) -> RowRun {
    let (sensors, obs, start, truth) = scenario(seed);
    let motion = ct();
    let adjacency: [bool; K * K] = ring::<{ K * K }>();
    let mut weights = [0.0f64; K * K];
    let mut nodes: [NodeState<f64, 7, 3>; K] = [NodeState::new(start, &cfg.trigger); K];
    let mut scratch: [NodeScratch<f64, 7, 3>; K] = [NodeScratch::default(); K];
    let mut links = [true; K * K];
    links[2 * K + 1] = false;
    links[4 * K + 5] = false;
    let mut active = [true; K];
    active[6] = false;

    let ((result, triggered, measured), allocs) = count_allocs(|| {
        let mut triggered = 0;
        let mut measured = 0;
        let setup = cfg
            .validate()
            .and_then(|()| max_degree_weights(&adjacency, K, &mut weights));
        if let Err(e) = setup {
            return (Err(e), 0, 0);
        }
        let (mut offsets, mut indices) = ([0usize; K + 1], [0usize; K * K]);
        let nb = match Neighbours::from_weights(&weights, K, &mut offsets, &mut indices) {
            Ok(nb) => nb,
            Err(e) => return (Err(e), 0, 0),
        };
        for (k, z) in obs.iter().enumerate() {
            let inputs = StepInputs {
                dt: 0.1,
                observations: z,
                links: (masks && (20..25).contains(&k)).then_some(&links[..]),
                edge_links: None,
                active: (masks && (40..43).contains(&k)).then_some(&active[..]),
                deltas: None,
            };
            let step = if k % 2 == 0 {
                network_step(
                    cfg,
                    &motion,
                    &sensors,
                    &weights,
                    &mut nodes,
                    &mut scratch,
                    &inputs,
                )
            } else {
                network_step_sparse(
                    cfg,
                    &motion,
                    &sensors,
                    &weights,
                    &nb,
                    &mut nodes,
                    &mut scratch,
                    &inputs,
                )
            };
            match step {
                Ok(rep) => {
                    triggered += rep.triggered;
                    measured += rep.measured;
                }
                Err(e) => return (Err(e), triggered, measured),
            }
        }
        (Ok(()), triggered, measured)
    });
    result.unwrap();
    RowRun {
        allocs,
        triggered,
        measured,
        nodes,
        truth,
    }
}

fn row(filter: NodeFilter<f64>, trigger: Trigger<f64>, fusion: Fusion) -> NetworkConfig<f64> {
    NetworkConfig {
        filter,
        trigger,
        et: EtOptions::default(),
        fusion,
        rule: Default::default(),
    }
}

/// The run did real work: every node's final estimate is finite, PD and within
/// `bound` of the truth (fused rows: 1 m, position std ≈ 0.1 m with 8 sensors;
/// local-only rows with send-on-delta: 2 m, a lone sensor predicts through
/// untriggered stretches with q1 = 0.5).
fn assert_sane(name: &str, r: &RowRun, bound: f64) {
    for (i, n) in r.nodes.iter().enumerate() {
        assert!(
            n.estimate.x.iter().all(|v| v.is_finite()),
            "{name}: node {i} not finite"
        );
        assert!(
            n.estimate.p.cholesky().is_some(),
            "{name}: node {i} P not PD"
        );
        let e = (n.estimate.x - r.truth).fixed_rows::<3>(0).norm();
        assert!(e < bound, "{name}: node {i} position error {e} m");
    }
}

/// The counter works: an allocation inside the window is seen.
#[test]
fn counter_detects_allocations() {
    let (v, n) = count_allocs(|| vec![1u8; 16]);
    assert_eq!(v.len(), 16);
    assert!(n >= 1, "a Vec allocation was not counted");
    let ((), n) = count_allocs(|| ());
    assert_eq!(n, 0);
}

/// Requirement 8: EDC-CIF (ET-CIF, send-on-delta δ = 0.04, diffusion with CI)
/// on the 8-node ring allocates nothing over 50 steps, with and without lost
/// links and a node outage, with the stable and the opt-in closed-form
/// untriggered contribution.
#[test]
fn edc_cif_network_steps_allocate_nothing() {
    let stable = row(
        NodeFilter::Cif,
        Trigger::SendOnDelta { delta: 0.04 },
        Fusion::DiffusionCi,
    );
    let closed = NetworkConfig {
        et: EtOptions {
            untriggered_closed_form: true,
            ..stable.et
        },
        ..stable
    };
    for (cfg, masks) in [
        (stable, false),
        (stable, true),
        (closed, false),
        (closed, true),
    ] {
        let r = run_row(&cfg, 400, masks);
        assert_eq!(
            r.allocs, 0,
            "EDC-CIF (masks {masks}, closed form {}) allocated {} times",
            cfg.et.untriggered_closed_form, r.allocs
        );
        assert!(
            r.triggered > 0 && r.triggered < r.measured,
            "both trigger branches must run"
        );
        assert_sane("EDC-CIF", &r, 1.0);
    }
}

/// Requirement 8: EC-CKF (ET-CKF, send-on-delta, 22 consensus iterations on the
/// ring of 8) allocates nothing over 50 steps.
#[test]
fn ec_ckf_network_steps_allocate_nothing() {
    let cfg = row(
        NodeFilter::Cov(LocalFilter::Ckf),
        Trigger::SendOnDelta { delta: 0.04 },
        Fusion::Consensus {
            iterations: L_RING8,
        },
    );
    let r = run_row(&cfg, 401, false);
    assert_eq!(r.allocs, 0, "EC-CKF allocated {} times", r.allocs);
    assert!(r.triggered > 0 && r.triggered < r.measured);
    assert_sane("EC-CKF", &r, 1.0);
}

/// Every row of the paper's tables (ALGORITHM.md §5), plus the local-only
/// filters, allocates nothing over 50 steps.
#[test]
fn every_table_row_allocates_nothing() {
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let cons = Fusion::Consensus {
        iterations: L_RING8,
    };
    let rows = [
        (
            "C-CKF",
            row(NodeFilter::Cov(LocalFilter::Ckf), Trigger::Always, cons),
        ),
        ("EC-EKF", row(NodeFilter::Cov(LocalFilter::Ekf), sod, cons)),
        (
            "EC-UKF",
            row(NodeFilter::Cov(LocalFilter::ukf_default()), sod, cons),
        ),
        (
            "DEC-CKF",
            row(
                NodeFilter::Cov(LocalFilter::Ckf),
                Trigger::dynamic(0.04),
                cons,
            ),
        ),
        (
            "D-CIF",
            row(NodeFilter::Cif, Trigger::Always, Fusion::DiffusionConvex),
        ),
        (
            "DC-CIF",
            row(NodeFilter::Cif, Trigger::Always, Fusion::DiffusionCi),
        ),
        ("ED-CIF", row(NodeFilter::Cif, sod, Fusion::DiffusionConvex)),
        ("ET-CIF local", row(NodeFilter::Cif, sod, Fusion::Local)),
        (
            "ET-UKF local",
            row(
                NodeFilter::Cov(LocalFilter::ukf_default()),
                sod,
                Fusion::Local,
            ),
        ),
        (
            "CIF consensus",
            row(NodeFilter::Cif, sod, Fusion::Consensus { iterations: 3 }),
        ),
        (
            "EDC-CIF stochastic",
            row(
                NodeFilter::Cif,
                Trigger::Stochastic { delta: 3.0 },
                Fusion::DiffusionCi,
            ),
        ),
        (
            "EDC-CIF sod-inflated",
            row(
                NodeFilter::Cif,
                Trigger::SendOnDeltaInflated { delta: 0.04 },
                Fusion::DiffusionCi,
            ),
        ),
        (
            "EDC-CIF innovation",
            row(
                NodeFilter::Cif,
                Trigger::Innovation { delta: 1.2 },
                Fusion::DiffusionCi,
            ),
        ),
        (
            "EC-CKF innovation",
            row(
                NodeFilter::Cov(LocalFilter::Ckf),
                Trigger::Innovation { delta: 1.2 },
                cons,
            ),
        ),
    ];
    for (i, (name, cfg)) in rows.iter().enumerate() {
        let r = run_row(cfg, 410 + i as u64, i.is_multiple_of(2));
        assert_eq!(r.allocs, 0, "{name} allocated {} times", r.allocs);
        let bound = if cfg.fusion == Fusion::Local {
            2.0
        } else {
            1.0
        };
        assert_sane(name, &r, bound);
    }
}
