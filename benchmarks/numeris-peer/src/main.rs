//! One CKF predict + update step of edccif-core against the `numeris` crate's
//! CKF, on the same model and the same measurements, timed side by side in one
//! process.
//!
//! Model: the default scenario of edccif (`Scenario::paper(1)`): a 7-state
//! coordinated turn (dt 0.1, q1 0.5, q2 1e-4) observed by one range/pitch/azimuth
//! sensor at (10, 0, 0) with σr 0.1 m, σa 0.01 rad. Data: `simulate(paper(1),
//! seed)`, the seeded 200-step sequence and initial estimate that
//! `edccif-timing --ckf-step` filters.
//!
//! Cases, each one pass = the 200 steps filtered from the initial estimate:
//!
//! - `numeris`: `numeris::estimate::Ckf::<f64, 7, 3>`, `predict` then `update`,
//!   with the model written as closures on numeris vectors. numeris averages the
//!   points' measurements linearly and forms the innovation `z − ẑ` without
//!   wrapping, so the measurement closure returns the angles unwrapped next to
//!   the current measurement (what `benchmarks/peers.py` does for FilterPy).
//! - `edccif-cov-local`: `edccif_core::cov_local` with `LocalFilter::Ckf` and
//!   `Trigger::Always` (the step `edccif-timing --ckf-step` times).
//! - `edccif-predict-update`: `cov_predict` then `cov_update`, same filter.
//!
//! Timing: `--rounds` rounds; every round times one pass of every case on the
//! wall clock and the thread's CPU clock, starting at a rotating case. Reported
//! per step: median, quartiles and min–max over the rounds. Before timing, every
//! case's final estimate is compared with the others and with the truth; the run
//! stops with an error if they differ by more than the stated tolerance.
//!
//! `--count CASE --passes K` runs only CASE's pass K times, untimed, for
//! instruction counts under callgrind (see README.md).

use std::hint::black_box;
use std::process::ExitCode;
use std::time::Instant;

use cpu_time::ThreadTime;
use edccif_core::angles::wrap_angle;
use edccif_core::model::{MeasurementModel, MotionModel};
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::nalgebra::{SMatrix, SVector, Vector3};
use edccif_core::{
    cov_local, cov_predict, cov_update, EtOptions, Gaussian, LocalFilter, Observation, Trigger,
    TriggerState,
};
use edccif_sim::{simulate, Scenario};
use numeris::estimate::Ckf;
use numeris::{Matrix, Vector};

const N: usize = 7;
const M: usize = 3;
const DEFAULT_SEED: u64 = 2024;
/// Largest allowed difference between the final position estimates of the
/// cases (metres): far below the filters' error against the truth (~0.2 m),
/// far above what the different angle averaging moves them (see the output).
const POSITION_TOLERANCE: f64 = 1e-6;

const CASES: [&str; 4] = [
    "numeris",
    "edccif-cov-local",
    "edccif-predict-update",
    "edccif-cov-local-fast",
];

/// Everything a pass needs, built once outside the timing.
struct Setup {
    dt: f64,
    sensor_pos: [f64; 3],
    motion: CoordinatedTurn<f64>,
    sensor: RangePitchAzimuth<f64>,
    /// The same models with the opt-in fast trigonometry (`with_fast_trig`).
    motion_fast: CoordinatedTurn<f64>,
    sensor_fast: RangePitchAzimuth<f64>,
    start: Gaussian<f64, N>,
    obs: Vec<Observation<f64, M>>,
    truth_last: [f64; N],
    // numeris's inputs: the same numbers in its own types.
    nm_x0: Vector<f64, N>,
    nm_p0: Matrix<f64, N, N>,
    nm_q: Matrix<f64, N, N>,
    nm_r: Matrix<f64, M, M>,
    nm_z: Vec<Vector<f64, M>>,
}

/// A final estimate: state and covariance (row-major).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Final {
    x: [f64; N],
    p: [[f64; N]; N],
}

fn numeris_matrix<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Matrix<f64, R, C> {
    Matrix::from_fn(|r, c| m[(r, c)])
}

impl Setup {
    fn new(seed: u64) -> Result<Self, String> {
        let sc = Scenario::paper(1);
        let sim = simulate(&sc, seed).map_err(|e| e.to_string())?;
        let motion = sc.coordinated_turn().map_err(|e| e.to_string())?;
        let sensor_pos = sc.sensors[0];
        let (sigma_r, sigma_a) = match sc.measurement {
            edccif_sim::MeasurementSpec::RangePitchAzimuth { sigma_r, sigma_a } => {
                (sigma_r, sigma_a)
            }
            #[allow(unreachable_patterns)]
            _ => return Err("the default scenario's sensor is not range/pitch/azimuth".into()),
        };
        let sensor =
            RangePitchAzimuth::new(sensor_pos, sigma_r, sigma_a).map_err(|e| e.to_string())?;
        let p0 = SMatrix::<f64, N, N>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
        let x0 = SVector::<f64, N>::from_column_slice(&sim.x0_hat);
        let start = Gaussian::new(x0, p0).map_err(|e| e.to_string())?;
        let obs: Vec<Observation<f64, M>> = sim
            .z
            .chunks_exact(M)
            .map(|z| Observation::Measured(Vector3::from_column_slice(z)))
            .collect();
        let nm_z = sim
            .z
            .chunks_exact(M)
            .map(|z| Vector::from_array([z[0], z[1], z[2]]))
            .collect();
        let mut truth_last = [0.0; N];
        truth_last.copy_from_slice(&sim.truth[(sim.steps - 1) * N..sim.steps * N]);
        let q = MotionModel::<f64, N>::process_noise(&motion, sc.dt);
        let r = MeasurementModel::<f64, N, M>::noise(&sensor);
        Ok(Self {
            dt: sc.dt,
            sensor_pos,
            motion,
            sensor,
            motion_fast: motion.with_fast_trig(true),
            sensor_fast: sensor.with_fast_trig(true),
            start,
            obs,
            truth_last,
            nm_x0: Vector::from_fn(|r, _| x0[r]),
            nm_p0: numeris_matrix(&p0),
            nm_q: numeris_matrix(&q),
            nm_r: numeris_matrix(&r),
            nm_z,
        })
    }
}

/// The coordinated turn (ALGORITHM.md §1, small-|ω| branch included) on
/// numeris vectors: the formulas of `edccif_core::models::CoordinatedTurn`.
#[inline]
fn ct_transition(x: &Vector<f64, N>, dt: f64) -> Vector<f64, N> {
    let w = x[6];
    let (sn, cs) = (w * dt).sin_cos();
    let (s, c) = if w.abs() < 1e-9 {
        (dt, w * dt * dt / 2.0)
    } else {
        (sn / w, (1.0 - cs) / w)
    };
    let (vx, vy) = (x[3], x[4]);
    Vector::from_array([
        x[0] + s * vx - c * vy,
        x[1] + c * vx + s * vy,
        x[2] + dt * x[5],
        cs * vx - sn * vy,
        sn * vx + cs * vy,
        x[5],
        w,
    ])
}

/// Range, pitch, azimuth on numeris vectors (the formulas of
/// `edccif_core::models::RangePitchAzimuth::measure`), with the two angles
/// unwrapped next to the measurement `z`: numeris's CKF averages them linearly.
#[inline]
fn rpa_near(x: &Vector<f64, N>, s: &[f64; 3], z: &Vector<f64, M>) -> Vector<f64, M> {
    let (dx, dy, dz) = (x[0] - s[0], x[1] - s[1], x[2] - s[2]);
    let rho2 = dx * dx + dy * dy;
    let rho = rho2.sqrt();
    let pitch = dz.atan2(rho);
    let az = dy.atan2(dx);
    Vector::from_array([
        (rho2 + dz * dz).sqrt(),
        z[1] + wrap_angle(pitch - z[1]),
        z[2] + wrap_angle(az - z[2]),
    ])
}

#[inline(never)]
fn pass_numeris(s: &Setup) -> Result<Final, String> {
    let mut ckf = Ckf::<f64, N, M>::new(s.nm_x0, s.nm_p0);
    let dt = s.dt;
    for z in &s.nm_z {
        let z = black_box(z);
        ckf.predict(|x| ct_transition(x, dt), Some(&s.nm_q))
            .map_err(|e| format!("numeris predict: {e}"))?;
        ckf.update(z, |x| rpa_near(x, &s.sensor_pos, z), &s.nm_r)
            .map_err(|e| format!("numeris update: {e}"))?;
    }
    Ok(Final {
        x: core::array::from_fn(|i| ckf.x[i]),
        p: core::array::from_fn(|r| core::array::from_fn(|c| ckf.p[(r, c)])),
    })
}

fn final_of(g: &Gaussian<f64, N>) -> Final {
    Final {
        x: core::array::from_fn(|i| g.x[i]),
        p: core::array::from_fn(|r| core::array::from_fn(|c| g.p[(r, c)])),
    }
}

#[inline(never)]
fn pass_cov_local(s: &Setup) -> Result<Final, String> {
    cov_local_pass(s, &s.motion, &s.sensor)
}

/// `cov_local` with the models' opt-in fast trigonometry (last-bit differences).
#[inline(never)]
fn pass_cov_local_fast(s: &Setup) -> Result<Final, String> {
    cov_local_pass(s, &s.motion_fast, &s.sensor_fast)
}

#[inline(always)]
fn cov_local_pass(
    s: &Setup,
    motion: &CoordinatedTurn<f64>,
    sensor: &RangePitchAzimuth<f64>,
) -> Result<Final, String> {
    let trigger = Trigger::Always;
    let ts = TriggerState::new(&trigger);
    let et = EtOptions::default();
    let mut est = s.start;
    for obs in &s.obs {
        let r = cov_local(
            &LocalFilter::Ckf,
            motion,
            s.dt,
            sensor,
            black_box(&est),
            black_box(obs),
            &trigger,
            &ts,
            &et,
        )
        .map_err(|e| format!("cov_local: {e}"))?;
        est = r.posterior;
    }
    Ok(final_of(&est))
}

#[inline(never)]
fn pass_predict_update(s: &Setup) -> Result<Final, String> {
    let trigger = Trigger::Always;
    let ts = TriggerState::new(&trigger);
    let et = EtOptions::default();
    let mut est = s.start;
    for obs in &s.obs {
        let prior = cov_predict(&LocalFilter::Ckf, &s.motion, s.dt, black_box(&est))
            .map_err(|e| format!("cov_predict: {e}"))?;
        let r = cov_update(
            &LocalFilter::Ckf,
            &s.sensor,
            &prior,
            black_box(obs),
            &trigger,
            &ts,
            &et,
        )
        .map_err(|e| format!("cov_update: {e}"))?;
        est = r.posterior;
    }
    Ok(final_of(&est))
}

fn run_case(case: usize, s: &Setup) -> Result<Final, String> {
    match case {
        0 => pass_numeris(s),
        1 => pass_cov_local(s),
        2 => pass_predict_update(s),
        _ => pass_cov_local_fast(s),
    }
}

/// Median, quartiles (linear interpolation), min and max of `xs`.
fn summary(xs: &[f64]) -> [f64; 5] {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let q = |f: f64| {
        let pos = f * (v.len() - 1) as f64;
        let (i, frac) = (pos.floor() as usize, pos - pos.floor());
        if i + 1 < v.len() {
            v[i] + frac * (v[i + 1] - v[i])
        } else {
            v[i]
        }
    };
    [q(0.5), q(0.25), q(0.75), v[0], v[v.len() - 1]]
}

fn max_abs_diff(a: &Final, b: &Final) -> (f64, f64, f64) {
    let dx = (0..N).map(|i| (a.x[i] - b.x[i]).abs()).fold(0.0, f64::max);
    let dpos = (0..3)
        .map(|i| (a.x[i] - b.x[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    let dp = (0..N)
        .flat_map(|r| (0..N).map(move |c| (r, c)))
        .map(|(r, c)| (a.p[r][c] - b.p[r][c]).abs())
        .fold(0.0, f64::max);
    (dpos, dx, dp)
}

struct Args {
    rounds: usize,
    seed: u64,
    json: Option<String>,
    count: Option<usize>,
    passes: usize,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        rounds: 301,
        seed: DEFAULT_SEED,
        json: None,
        count: None,
        passes: 10,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut val = || it.next().ok_or(format!("{k} needs a value"));
        match k.as_str() {
            "--rounds" => a.rounds = val()?.parse().map_err(|e| format!("--rounds: {e}"))?,
            "--seed" => a.seed = val()?.parse().map_err(|e| format!("--seed: {e}"))?,
            "--json" => a.json = Some(val()?),
            "--passes" => a.passes = val()?.parse().map_err(|e| format!("--passes: {e}"))?,
            "--count" => {
                let v = val()?;
                a.count = Some(CASES.iter().position(|c| *c == v).ok_or(format!(
                    "--count: unknown case {v:?}, expected one of {CASES:?}"
                ))?)
            }
            "-h" | "--help" => {
                println!(
                    "numeris-peer [--rounds R] [--seed S] [--json OUT.json]\n\
                     numeris-peer --count CASE [--passes K]   (CASE: {})",
                    CASES.join(", ")
                );
                std::process::exit(0);
            }
            _ => return Err(format!("unknown argument {k:?} (try --help)")),
        }
    }
    if a.rounds == 0 || a.passes == 0 {
        return Err("--rounds and --passes must be at least 1".into());
    }
    Ok(a)
}

fn run() -> Result<(), String> {
    let args = parse_args()?;
    let s = Setup::new(args.seed)?;
    let steps = s.obs.len();

    if let Some(case) = args.count {
        // Untimed passes for callgrind: instructions per step = Ir / (passes × steps).
        for _ in 0..args.passes {
            black_box(run_case(case, &s)?);
        }
        println!(
            "{}: {} passes of {steps} steps = {} steps",
            CASES[case],
            args.passes,
            args.passes * steps
        );
        return Ok(());
    }

    // Same estimate check, before any timing.
    let finals: Vec<Final> = (0..CASES.len())
        .map(|c| run_case(c, &s))
        .collect::<Result<_, _>>()?;
    let err_truth: Vec<f64> = finals
        .iter()
        .map(|f| {
            (0..3)
                .map(|i| (f.x[i] - s.truth_last[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let (d_nm_pos, d_nm_x, d_nm_p) = max_abs_diff(&finals[0], &finals[1]);
    let (d_split_pos, d_split_x, d_split_p) = max_abs_diff(&finals[1], &finals[2]);
    let (d_fast_pos, d_fast_x, d_fast_p) = max_abs_diff(&finals[1], &finals[3]);

    // Nobody is timed on a diverged run.
    if d_nm_pos > POSITION_TOLERANCE
        || d_split_pos > POSITION_TOLERANCE
        || d_fast_pos > POSITION_TOLERANCE
    {
        return Err(format!(
            "the filters' final positions differ by more than {POSITION_TOLERANCE} m: \
             numeris vs cov_local {d_nm_pos:.3e}, cov_local vs predict+update {d_split_pos:.3e}, \
             cov_local vs its fast trigonometry {d_fast_pos:.3e}"
        ));
    }

    let mut wall = vec![Vec::with_capacity(args.rounds); CASES.len()];
    let mut cpu = vec![Vec::with_capacity(args.rounds); CASES.len()];
    for c in 0..CASES.len() {
        black_box(run_case(c, &s)?); // warm-up
    }
    for round in 0..args.rounds {
        for k in 0..CASES.len() {
            let c = (round + k) % CASES.len();
            let c0 = ThreadTime::now();
            let t0 = Instant::now();
            let f = run_case(c, &s)?;
            let w = t0.elapsed();
            let u = c0.elapsed();
            if f != finals[c] {
                return Err(format!(
                    "{}: a timed pass ended elsewhere than the checked one",
                    CASES[c]
                ));
            }
            wall[c].push(w.as_secs_f64() * 1e6 / steps as f64);
            cpu[c].push(u.as_secs_f64() * 1e6 / steps as f64);
        }
    }

    println!(
        "numeris-peer: one CKF predict + update step, default model (7-state coordinated turn, \
         dt {}, range/pitch/azimuth sensor at {:?}), simulate(paper(1), seed {}), {steps} steps per pass",
        s.dt, s.sensor_pos, args.seed
    );
    println!(
        "{} interleaved rounds (one pass of every case per round, rotating start); µs per step",
        args.rounds
    );
    println!(
        "{:<24} {:>8} {:>8} {:>8} {:>8} {:>8}   {:>8} {:>8} {:>8} {:>8} {:>8}",
        "case", "cpu med", "q1", "q3", "min", "max", "wall med", "q1", "q3", "min", "max"
    );
    let mut json_cases = serde_json::Map::new();
    let cpu_sum: Vec<[f64; 5]> = cpu.iter().map(|v| summary(v)).collect();
    let wall_sum: Vec<[f64; 5]> = wall.iter().map(|v| summary(v)).collect();
    for c in 0..CASES.len() {
        let (u, w) = (cpu_sum[c], wall_sum[c]);
        println!(
            "{:<24} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3}   {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
            CASES[c], u[0], u[1], u[2], u[3], u[4], w[0], w[1], w[2], w[3], w[4]
        );
        let stats = |a: [f64; 5]| serde_json::json!({"median": a[0], "q1": a[1], "q3": a[2], "min": a[3], "max": a[4]});
        json_cases.insert(
            CASES[c].into(),
            serde_json::json!({
                "cpu_us_per_step": stats(u),
                "wall_us_per_step": stats(w),
                "final_x": finals[c].x,
                "final_position_error_m": err_truth[c],
            }),
        );
    }
    // Ratios of medians, and the per-round ratio's median (both cases of a
    // round ran within ~1 ms of each other).
    let per_round_ratio = |a: usize, b: usize, v: &[Vec<f64>]| {
        let r: Vec<f64> = v[a].iter().zip(&v[b]).map(|(x, y)| x / y).collect();
        summary(&r)
    };
    println!("ratios (numeris / edccif), CPU: median of per-round ratios [q1, q3]");
    let mut json_ratios = serde_json::Map::new();
    for c in 1..CASES.len() {
        let r = per_round_ratio(0, c, &cpu);
        let rw = per_round_ratio(0, c, &wall);
        println!(
            "  numeris / {:<22} cpu {:.2} [{:.2}, {:.2}]   wall {:.2} [{:.2}, {:.2}]   \
             ratio of medians cpu {:.2}",
            CASES[c],
            r[0],
            r[1],
            r[2],
            rw[0],
            rw[1],
            rw[2],
            cpu_sum[0][0] / cpu_sum[c][0]
        );
        json_ratios.insert(
            format!("numeris/{}", CASES[c]),
            serde_json::json!({"cpu_median": r[0], "cpu_q1": r[1], "cpu_q3": r[2],
                               "wall_median": rw[0], "wall_q1": rw[1], "wall_q3": rw[2]}),
        );
    }
    println!("same estimate check (after {steps} steps, from the same initial estimate):");
    for (c, e) in err_truth.iter().enumerate() {
        println!("  {:<24} position error vs truth {e:.6} m", CASES[c]);
    }
    println!(
        "  numeris vs edccif-cov-local: position {d_nm_pos:.3e} m, max |Δx| {d_nm_x:.3e}, \
         max |ΔP| {d_nm_p:.3e} (tolerance: position {POSITION_TOLERANCE:.0e} m)"
    );
    println!(
        "  edccif-cov-local vs edccif-predict-update: position {d_split_pos:.3e} m, \
         max |Δx| {d_split_x:.3e}, max |ΔP| {d_split_p:.3e}"
    );
    println!(
        "  edccif-cov-local vs edccif-cov-local-fast: position {d_fast_pos:.3e} m, \
         max |Δx| {d_fast_x:.3e}, max |ΔP| {d_fast_p:.3e}"
    );

    if let Some(path) = args.json {
        let doc = serde_json::json!({
            "seed": args.seed,
            "steps_per_pass": steps,
            "rounds": args.rounds,
            "numeris_version": "0.6.0",
            "cases": json_cases,
            "ratios": json_ratios,
            "check": {
                "numeris_vs_cov_local": {"position_m": d_nm_pos, "max_abs_dx": d_nm_x, "max_abs_dp": d_nm_p},
                "cov_local_vs_predict_update": {"position_m": d_split_pos, "max_abs_dx": d_split_x, "max_abs_dp": d_split_p},
                "cov_local_vs_fast_trig": {"position_m": d_fast_pos, "max_abs_dx": d_fast_x, "max_abs_dp": d_fast_p},
                "position_tolerance_m": POSITION_TOLERANCE,
            },
        });
        std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap() + "\n")
            .map_err(|e| format!("{path}: {e}"))?;
    }

    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("numeris-peer: {e}");
            ExitCode::FAILURE
        }
    }
}
