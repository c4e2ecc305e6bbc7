//! Criterion benchmarks of edccif, grouped by topic (`cargo bench -p edccif-bench --bench edccif`):
//!
//! - `local_step`: one node's local step of every local filter on the default
//!   coordinated-turn + range/pitch/azimuth model (`cif_local`, `cov_local`);
//! - `fusion`: the fusion primitives (`adapt`, `combine_ci`, `ci_fuse_optimal`,
//!   `consensus_iteration`);
//! - `network_step`: a whole network step of every algorithm row at N = 3, 4, 8;
//! - `scaling`: EDC-CIF network steps at N = 16, 32, 64 on a ring and on a
//!   random geometric graph.
//!
//! All inputs are seeded ([`DEFAULT_SEED`]). Filter by group, e.g.
//! `cargo bench -p edccif-bench --bench edccif -- network_step/edc-cif`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use edccif_bench::{
    local_cases, rgg_radius, time_network_steps, LocalFixture, TriggerCase, Workload, DEFAULT_SEED,
};
use edccif_core::fusion::{adapt, ci_fuse_optimal, combine_ci, consensus_iteration};
use edccif_core::{
    cif_local, CiCriterion, Contribution, Gaussian, InfoPair, Observation, Trigger, TriggerState,
};
use edccif_sim::{Algorithm, Topology};
use nalgebra::{SMatrix, SVector, Vector3};

/// Steps of EDC-CIF before the fixtures' estimates are taken (past the transient).
const WARM_STEPS: usize = 50;

fn local_step(c: &mut Criterion) {
    let f = LocalFixture::new(DEFAULT_SEED, WARM_STEPS).expect("fixture");
    let mut g = c.benchmark_group("local_step");
    for case in local_cases() {
        // The fixture puts each case in the trigger situation it names.
        let sent = f.step(&case).expect("local step");
        assert_eq!(
            sent,
            Some(case.trigger != TriggerCase::SodQuiet),
            "{}",
            case.name
        );
        g.bench_function(case.name, |b| b.iter(|| f.step(&case).unwrap()));
    }
    g.finish();
}

/// Realistic fusion inputs: the 8-node default network's estimates after
/// [`WARM_STEPS`] EDC-CIF steps (as information pairs), and every node's
/// ET-CIF contribution at the next step.
struct FusionFixture {
    infos: Vec<InfoPair<f64, 7>>,
    prior: InfoPair<f64, 7>,
    contributions: Vec<Contribution<f64, 7>>,
}

impl FusionFixture {
    fn new() -> Self {
        let w = Workload::paper(8, DEFAULT_SEED).expect("workload");
        let mut net = w.network(Algorithm::EdcCif).expect("network");
        for t in 0..WARM_STEPS {
            net.step(w.z_at(t)).expect("step");
        }
        let k = w.nodes();
        let mut x = vec![0.0; k * 7];
        let mut p = vec![0.0; k * 49];
        net.write_estimates(&mut x);
        net.write_covariances(&mut p);
        let gaussians: Vec<Gaussian<f64, 7>> = (0..k)
            .map(|i| {
                Gaussian::new(
                    SVector::from_column_slice(&x[i * 7..(i + 1) * 7]),
                    SMatrix::from_row_slice(&p[i * 49..(i + 1) * 49]),
                )
                .expect("estimate")
            })
            .collect();
        let infos = gaussians
            .iter()
            .map(|g| g.to_info().expect("info"))
            .collect();
        let motion = w.scenario.coordinated_turn().expect("motion");
        let sensors = w.scenario.sensor_models().expect("sensors");
        let trig = Trigger::SendOnDelta {
            delta: w.scenario.delta.node(0),
        };
        let z = w.z_at(WARM_STEPS);
        let mut prior = None;
        let contributions = (0..k)
            .map(|i| {
                let zi = Vector3::from_column_slice(&z[i * 3..(i + 1) * 3]);
                let r = cif_local(
                    &motion,
                    0.1,
                    &sensors[i],
                    &gaussians[i],
                    &Observation::Measured(zi),
                    &trig,
                    &TriggerState::new(&trig),
                    &Default::default(),
                )
                .expect("cif");
                prior.get_or_insert(r.prior);
                r.contribution
            })
            .collect();
        Self {
            infos,
            prior: prior.expect("prior"),
            contributions,
        }
    }
}

fn fusion(c: &mut Criterion) {
    let f = FusionFixture::new();
    let mut g = c.benchmark_group("fusion");
    for neighbours in [2usize, 7] {
        g.bench_with_input(
            BenchmarkId::new("adapt", neighbours),
            &neighbours,
            |b, &n| {
                b.iter(|| {
                    adapt(
                        black_box(&f.prior),
                        black_box(&f.contributions[0]),
                        f.contributions[1..=n].iter(),
                    )
                })
            },
        );
    }
    for members in [3usize, 8] {
        let w = 1.0 / members as f64;
        g.bench_with_input(
            BenchmarkId::new("combine_ci", members),
            &members,
            |b, &n| b.iter(|| combine_ci(f.infos[..n].iter().map(|p| (w, black_box(p)))).unwrap()),
        );
    }
    for members in [2usize, 3] {
        g.bench_with_input(
            BenchmarkId::new("ci_fuse_optimal_trace", members),
            &members,
            |b, &n| {
                let mut weights = vec![0.0; n];
                b.iter(|| {
                    weights.iter_mut().for_each(|w| *w = 0.0); // start uniform
                    ci_fuse_optimal(black_box(&f.infos[..n]), CiCriterion::Trace, &mut weights)
                        .unwrap()
                })
            },
        );
    }
    for nodes in [4usize, 8] {
        let sc = edccif_sim::Scenario::paper(nodes);
        let weights = sc.weights().expect("weights");
        let current = f.infos[..nodes].to_vec();
        let mut next = vec![InfoPair::zeros(); nodes];
        g.bench_with_input(
            BenchmarkId::new("consensus_iteration", nodes),
            &nodes,
            |b, _| {
                b.iter(|| consensus_iteration(&weights, black_box(&current), &mut next).unwrap())
            },
        );
    }
    g.finish();
}

fn network_step(c: &mut Criterion) {
    let mut g = c.benchmark_group("network_step");
    for nodes in [3usize, 4, 8] {
        let w = Workload::paper(nodes, DEFAULT_SEED).expect("workload");
        g.throughput(Throughput::Elements(nodes as u64));
        for alg in Algorithm::ALL {
            g.bench_with_input(BenchmarkId::new(alg.name(), nodes), &w, |b, w| {
                b.iter_custom(|iters| time_network_steps(alg, w, iters))
            });
        }
    }
    g.finish();
}

fn scaling(c: &mut Criterion) {
    let mut g = c.benchmark_group("scaling");
    for nodes in [16usize, 32, 64] {
        g.throughput(Throughput::Elements(nodes as u64));
        let topologies = [
            ("edc-cif/ring", Topology::Ring),
            (
                "edc-cif/rgg",
                Topology::RandomGeometric {
                    radius: rgg_radius(nodes),
                    seed: DEFAULT_SEED,
                },
            ),
        ];
        for (name, topo) in topologies {
            let w = Workload::with_topology(nodes, topo, DEFAULT_SEED).expect("workload");
            g.bench_with_input(BenchmarkId::new(name, nodes), &w, |b, w| {
                b.iter_custom(|iters| time_network_steps(Algorithm::EdcCif, w, iters))
            });
        }
    }
    g.finish();
}

fn config() -> Criterion {
    // The header of every timing tool: the configuration measured.
    println!(
        "{}",
        edccif_bench::config::Config::library_default().describe()
    );
    Criterion::default()
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_secs(1))
        .sample_size(30)
}

/// `criterion_group!` generates an undocumented `pub fn`.
#[allow(missing_docs)]
mod group {
    use super::*;
    criterion_group! {
        name = benches;
        config = config();
        targets = local_step, fusion, network_step, scaling
    }
}
criterion_main!(group::benches);
