//! The scaling study: time per network step, position RMSE and the parallel
//! speed-up of EDC-CIF and EC-CKF (adequate `L` and fixed `L`) on rings and
//! random geometric graphs of N = 3 … 1024 nodes. Raw JSON on stdout (or
//! `--out FILE`), progress on stderr. `benchmarks/scaling.py` drives it.
//!
//! ```text
//! edccif-scaling [--nodes 3,4,8,...,1024] [--topology ring,rgg] [--fixed-l 1] [--probe-l 21]
//!                [--reps 5] [--budget-s 1.0] [--max-step-s 2.0] [--rmse-budget-s 60]
//!                [--parallel-min 64] [--threads 2] [--min-nodes-per-task 8]
//!                [--parallel-only] [--parallel-rows edc-cif,ec-ckf@L1,ec-ckf@L21]
//!                [--fast-trig|--libm-trig] [--closed-form|--stable-form] [--reference]
//!                [--seed S] [--out FILE]
//! edccif-scaling --instr ROW --nodes N --topology ring|rgg --steps K [--adequate-l L]
//! ```
//!
//! For each (topology, N) the rows are EDC-CIF, EC-CKF with the adequate `L`
//! (ALGORITHM.md §5), EC-CKF with `--fixed-l` and EC-CKF with `--probe-l` (the
//! probe gives the cost of one consensus iteration). A row is timed over the
//! first S steps of fresh runs, S chosen so that its `--reps` interleaved
//! repetitions take about `--budget-s` seconds (1 ≤ S ≤ 200); the result is per
//! step. EC-CKF with the adequate `L` is measured only where one of its steps
//! takes at most `--max-step-s` (estimated from the two fixed-`L` rows);
//! otherwise it is **projected** as `t(L_fixed) + (L − L_fixed)·b`, with `b` the
//! measured cost of one iteration at that N, and marked so in the JSON. The
//! position RMSE comes from whole untimed runs, for rows whose whole run fits
//! `--rmse-budget-s`.
//!
//! For N ≥ `--parallel-min`, EDC-CIF and the fixed-`L` EC-CKF rows are also timed
//! on plain slices: the core's serial `network_step`, and
//! [`edccif_sim::parallel::ParallelStep`] on 1 and `--threads` threads (wall
//! clock and process CPU time; the thread CPU clock does not see other threads),
//! and on `--threads` threads with the whole run inside the step's pool
//! ([`ParallelStep::in_pool`](edccif_sim::parallel::ParallelStep::in_pool):
//! `parallel_n_in_pool`), in interleaved rounds, with the per-round ratios
//! serial ÷ parallel. `--min-nodes-per-task` sets the parallel step's task
//! granularity (default 8: a network of at most 8 nodes runs each phase as one
//! task; 4 splits N = 8 into two tasks per phase). Beside them, the fork/join
//! cost on a pool of `--threads` threads: handing a no-op to the pool and back
//! (`install_noop_us`), an empty phase of N items in tasks of the same size run
//! from inside the pool, and a phase of N items of under a microsecond of
//! arithmetic each, serial, from inside the pool and handed over each time; the overhead
//! is the parallel phase's time minus the serial one's ÷ threads. `--parallel-only` skips the rows' study and runs
//! only this comparison, for every N in `--nodes`, on the rows
//! `--parallel-rows`. Every row runs in the library's default configuration
//! unless `--fast-trig` / `--libm-trig`, `--closed-form` / `--stable-form` or
//! `--reference` say otherwise ([`edccif_bench::config`]); the configuration
//! measured is the first line on stderr and the JSON's `settings.config`.
//!
//! `--instr ROW` runs K steps of one row once inside
//! `edccif_bench::run_steps`, for `valgrind --tool=callgrind
//! --toggle-collect=edccif_bench::run_steps` (`--adequate-l` skips the
//! eigen-decomposition, which is slow under valgrind).

use std::error::Error;
use std::process::ExitCode;
use std::time::Instant;

use cpu_time::{ProcessTime, ThreadTime};
use edccif_bench::config::{self, Config};
use edccif_bench::scaling::{scaling_workload, scaling_workload_with_l, SliceNet, Topo};
use edccif_bench::{position_rmse, rgg_radius, run_steps, time_run_row, Row, Spread, Workload};
use edccif_sim::parallel::{check_min_nodes_per_task, MIN_NODES_PER_TASK};
use edccif_sim::{Algorithm, Scenario, Topology};
use rayon::prelude::*;
use rayon::ThreadPool;
use serde_json::{json, Map, Value};

fn usage() -> String {
    format!("usage: edccif-scaling [--nodes 3,4,...] [--topology ring,rgg] [--fixed-l 1] [--probe-l 21] [--reps 5] [--budget-s 1.0] [--max-step-s 2.0] [--rmse-budget-s 60] [--parallel-min 64] [--threads 2] [--min-nodes-per-task 8] [--parallel-only] [--parallel-rows edc-cif,ec-ckf@L1,ec-ckf@L21] {} [--seed S] [--out FILE]\n       edccif-scaling --instr ROW --nodes N --topology ring|rgg --steps K [--adequate-l L]", config::FLAGS)
}

struct Args {
    nodes: Vec<usize>,
    topologies: Vec<Topo>,
    fixed_l: usize,
    probe_l: usize,
    reps: usize,
    budget_s: f64,
    max_step_s: f64,
    rmse_budget_s: f64,
    parallel_min: usize,
    threads: usize,
    min_nodes_per_task: Option<usize>,
    parallel_only: bool,
    parallel_rows: Option<Vec<Row>>,
    config: Config,
    seed: u64,
    out: Option<String>,
    instr: Option<Row>,
    steps: usize,
    adequate_l: Option<usize>,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        nodes: vec![3, 4, 8, 16, 32, 64, 128, 256, 512, 1024],
        topologies: vec![Topo::Ring, Topo::Rgg],
        fixed_l: 1,
        probe_l: 21,
        reps: 5,
        budget_s: 1.0,
        max_step_s: 2.0,
        rmse_budget_s: 60.0,
        parallel_min: 64,
        threads: 2,
        min_nodes_per_task: None,
        parallel_only: false,
        parallel_rows: None,
        config: Config::library_default(),
        seed: edccif_bench::DEFAULT_SEED,
        out: None,
        instr: None,
        steps: 10,
        adequate_l: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        if a.config.parse_flag(&arg) {
            continue;
        }
        let mut value = |name: &str| {
            it.next()
                .ok_or(format!("{name} needs a value\n{}", usage()))
        };
        fn num<T: std::str::FromStr>(name: &str, v: String) -> Result<T, String>
        where
            T::Err: std::fmt::Display,
        {
            v.trim()
                .parse()
                .map_err(|e| format!("{name}: {e} (got {v:?})"))
        }
        match arg.as_str() {
            "--nodes" => {
                a.nodes = value("--nodes")?
                    .split(',')
                    .map(|s| num("--nodes", s.to_string()))
                    .collect::<Result<_, _>>()?;
                if a.nodes.is_empty() || a.nodes.contains(&0) {
                    return Err("--nodes: node counts must be >= 1".into());
                }
            }
            "--topology" => {
                a.topologies = value("--topology")?
                    .split(',')
                    .map(str::parse)
                    .collect::<Result<_, _>>()?
            }
            "--fixed-l" => a.fixed_l = num("--fixed-l", value("--fixed-l")?)?,
            "--probe-l" => a.probe_l = num("--probe-l", value("--probe-l")?)?,
            "--reps" => a.reps = num("--reps", value("--reps")?)?,
            "--budget-s" => a.budget_s = num("--budget-s", value("--budget-s")?)?,
            "--max-step-s" => a.max_step_s = num("--max-step-s", value("--max-step-s")?)?,
            "--rmse-budget-s" => {
                a.rmse_budget_s = num("--rmse-budget-s", value("--rmse-budget-s")?)?
            }
            "--parallel-min" => a.parallel_min = num("--parallel-min", value("--parallel-min")?)?,
            "--threads" => a.threads = num("--threads", value("--threads")?)?,
            "--min-nodes-per-task" => {
                let n = num("--min-nodes-per-task", value("--min-nodes-per-task")?)?;
                check_min_nodes_per_task(n).map_err(|e| format!("--min-nodes-per-task: {e}"))?;
                a.min_nodes_per_task = Some(n);
            }
            "--parallel-only" => a.parallel_only = true,
            "--parallel-rows" => {
                a.parallel_rows = Some(
                    value("--parallel-rows")?
                        .split(',')
                        .map(str::parse)
                        .collect::<Result<_, _>>()?,
                )
            }
            "--seed" => a.seed = num("--seed", value("--seed")?)?,
            "--out" => a.out = Some(value("--out")?),
            "--instr" => a.instr = Some(value("--instr")?.parse()?),
            "--steps" => a.steps = num("--steps", value("--steps")?)?,
            "--adequate-l" => a.adequate_l = Some(num("--adequate-l", value("--adequate-l")?)?),
            "--bench" => {}
            "-h" | "--help" => return Err(usage()),
            other => return Err(format!("unknown argument {other:?}\n{}", usage())),
        }
    }
    if a.fixed_l == 0 || a.probe_l <= a.fixed_l {
        return Err("--fixed-l must be >= 1 and --probe-l larger than --fixed-l".into());
    }
    if a.reps == 0 || a.threads == 0 || a.steps == 0 {
        return Err("--reps, --threads and --steps must be >= 1".into());
    }
    Ok(a)
}

struct Progress(Instant);

impl Progress {
    fn say(&self, msg: impl AsRef<str>) {
        eprintln!(
            "[{:7.1} s] {}",
            self.0.elapsed().as_secs_f64(),
            msg.as_ref()
        );
    }
}

/// The workload in the configuration of the flags (the filters' models only:
/// the simulated truth is the same).
fn opt_ins(a: &Args, mut w: Workload) -> Workload {
    a.config.apply(&mut w.scenario);
    w
}

/// The 1-minute load average (`/proc/loadavg`), when readable.
fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn workload(topo: Topo, n: usize, seed: u64, l: Option<usize>) -> edccif_sim::Result<Workload> {
    match l {
        None => scaling_workload(topo, n, seed),
        Some(l) => {
            let mut sc = Scenario::paper(n);
            if topo == Topo::Rgg {
                sc.topology = Topology::RandomGeometric {
                    radius: rgg_radius(n),
                    seed,
                };
            }
            scaling_workload_with_l(sc, l, seed)
        }
    }
}

/// Seconds per step (wall, thread CPU) of a short pilot run.
fn pilot(row: Row, w: &Workload) -> edccif_sim::Result<f64> {
    let steps = 2;
    let t = time_run_row(row, w, steps)?;
    Ok(t.cpu.as_secs_f64() / steps as f64)
}

fn steps_for(budget_s: f64, reps: usize, step_s: f64, max: usize) -> usize {
    ((budget_s / reps as f64 / step_s.max(1e-9)).floor() as usize).clamp(1, max)
}

fn instr_mode(a: &Args) -> Result<(), Box<dyn Error>> {
    let row = a.instr.expect("instr row");
    let (topo, n) = (a.topologies[0], a.nodes[0]);
    let w = opt_ins(a, workload(topo, n, a.seed, a.adequate_l)?);
    let mut net = w.network_row(row)?;
    let steps = a.steps.min(w.steps());
    run_steps(&mut net, &w, 0..steps)?;
    println!(
        "{}",
        json!({"row": row.to_string(), "topology": topo.to_string(), "nodes": n, "steps": steps,
               "iterations": w.iterations(row)?, "config": a.config.to_json()})
    );
    Ok(())
}

fn study(a: &Args) -> Result<(), Box<dyn Error>> {
    let p = Progress(Instant::now());
    p.say(a.config.describe());
    let load_start = load_average();
    let mut cases = Vec::new();
    for &topo in &a.topologies {
        for &n in &a.nodes {
            if a.parallel_only {
                p.say(format!("{topo} N = {n}: serial and parallel steps only"));
                let w = opt_ins(a, scaling_workload(topo, n, a.seed)?);
                cases.push(json!({
                    "topology": topo.to_string(), "nodes": n,
                    "steps_per_run": w.steps(),
                    "parallel": parallel_case(a, &p, topo, &w)?,
                }));
                continue;
            }
            p.say(format!(
                "{topo} N = {n}: simulating, adequate L (eigen-decomposition of the {n} x {n} weights)"
            ));
            let w = opt_ins(a, scaling_workload(topo, n, a.seed)?);
            let l = w.scenario.consensus_iters.expect("set by scaling_workload");
            let adjacency = w.scenario.adjacency()?;
            let degree = adjacency.iter().filter(|e| **e).count() as f64 / n as f64;
            let edc = Row::new(Algorithm::EdcCif);
            let adequate = Row::new(Algorithm::EcCkf);
            let fixed = Row::fixed(Algorithm::EcCkf, a.fixed_l);
            let probe = Row::fixed(Algorithm::EcCkf, a.probe_l);
            // Pilots: seconds per step, and the per-iteration estimate.
            let (pe, pf, pp) = (pilot(edc, &w)?, pilot(fixed, &w)?, pilot(probe, &w)?);
            let b_pilot = ((pp - pf) / (a.probe_l - a.fixed_l) as f64).max(0.0);
            let adequate_est = pf + (l as f64 - a.fixed_l as f64) * b_pilot;
            let measure_adequate = adequate_est <= a.max_step_s;
            p.say(format!(
                "{topo} N = {n}: L = {l}, mean degree {degree:.1}; pilot us/step EDC-CIF {:.1}, EC-CKF L={} {:.1}, L={} {:.1}, adequate ~{:.1} ({})",
                pe * 1e6,
                a.fixed_l,
                pf * 1e6,
                a.probe_l,
                pp * 1e6,
                adequate_est * 1e6,
                if measure_adequate { "measured" } else { "projected" }
            ));
            let mut timed: Vec<(Row, f64)> = vec![(edc, pe), (fixed, pf), (probe, pp)];
            if measure_adequate {
                timed.insert(1, (adequate, adequate_est));
            }
            let steps: Vec<usize> = timed
                .iter()
                .map(|(_, s)| steps_for(a.budget_s, a.reps, *s, w.steps()))
                .collect();
            let mut wall = vec![Vec::new(); timed.len()];
            let mut cpu = vec![Vec::new(); timed.len()];
            for r in 0..a.reps {
                for s in 0..timed.len() {
                    let i = (r + s) % timed.len();
                    let t = time_run_row(timed[i].0, &w, steps[i])?;
                    wall[i].push(t.wall.as_secs_f64() * 1e6 / steps[i] as f64);
                    cpu[i].push(t.cpu.as_secs_f64() * 1e6 / steps[i] as f64);
                }
            }
            let med = |row: Row| {
                timed
                    .iter()
                    .position(|(r, _)| *r == row)
                    .map(|i| Spread::of(&cpu[i]).median)
            };
            let (mf, mp) = (med(fixed).expect("fixed"), med(probe).expect("probe"));
            let b = (mp - mf) / (a.probe_l - a.fixed_l) as f64;
            let a0 = mf - a.fixed_l as f64 * b;
            let projected_adequate = a0 + l as f64 * b;
            let mut rows = Map::new();
            for (i, (row, _)) in timed.iter().enumerate() {
                let iters = w.iterations(*row)?;
                let whole_run_s = Spread::of(&cpu[i]).median * 1e-6 * w.steps() as f64;
                let rmse = if whole_run_s <= a.rmse_budget_s {
                    p.say(format!("{topo} N = {n}: RMSE of {}", row.label()));
                    Some(position_rmse(*row, &w)?)
                } else {
                    None
                };
                rows.insert(
                    row.to_string(),
                    json!({
                        "label": row.label(), "iterations": iters, "measured": true,
                        "steps_timed": steps[i], "reps": a.reps,
                        "step_wall_us": Spread::of(&wall[i]).to_json(),
                        "step_cpu_us": Spread::of(&cpu[i]).to_json(),
                        "step_wall_us_samples": wall[i], "step_cpu_us_samples": cpu[i],
                        "rmse_m": rmse,
                    }),
                );
            }
            if !measure_adequate {
                rows.insert(
                    adequate.to_string(),
                    json!({
                        "label": adequate.label(), "iterations": l, "measured": false,
                        "projected_step_cpu_us": projected_adequate,
                        "projection": format!(
                            "t(L={}) + (L - {}) x b, b = (t(L={}) - t(L={})) / {} measured at this N",
                            a.fixed_l, a.fixed_l, a.probe_l, a.fixed_l, a.probe_l - a.fixed_l),
                        "rmse_m": Value::Null,
                    }),
                );
            }
            p.say(format!(
                "{topo} N = {n}: median cpu us/step EDC-CIF {:.1}, EC-CKF L={} {:.1}, one iteration {:.2} us/step; adequate EC-CKF {} {:.1}",
                med(edc).expect("edc"),
                a.fixed_l,
                mf,
                b,
                if measure_adequate { "measured" } else { "PROJECTED" },
                med(adequate).unwrap_or(projected_adequate)
            ));
            let parallel = if n >= a.parallel_min {
                Some(parallel_case(a, &p, topo, &w)?)
            } else {
                None
            };
            cases.push(json!({
                "topology": topo.to_string(), "nodes": n, "adequate_l": l, "mean_degree": degree,
                "rgg_radius": if topo == Topo::Rgg { Some(rgg_radius(n)) } else { None },
                "steps_per_run": w.steps(),
                "rows": rows,
                "iteration_model_cpu_us": {"a_us_per_step": a0, "b_us_per_iteration_step": b,
                    "projected_adequate_us_per_step": projected_adequate,
                    "fitted_on": [a.fixed_l, a.probe_l]},
                "parallel": parallel,
            }));
        }
    }
    let out = json!({
        "tool": "edccif-scaling",
        "settings": {"reps": a.reps, "budget_s": a.budget_s, "max_step_s": a.max_step_s,
                     "rmse_budget_s": a.rmse_budget_s, "fixed_l": a.fixed_l, "probe_l": a.probe_l,
                     "parallel_min": a.parallel_min, "threads": a.threads, "seed": a.seed,
                     "min_nodes_per_task": a.min_nodes_per_task.unwrap_or(MIN_NODES_PER_TASK),
                     "parallel_only": a.parallel_only, "fast_trig": a.config.fast_trig,
                     "closed_form": a.config.closed_form, "config": a.config.to_json(),
                     "load_average_1min": {"start": load_start, "end": load_average()}},
        "cases": cases,
    });
    let text = serde_json::to_string_pretty(&out)? + "\n";
    match &a.out {
        Some(path) => std::fs::write(path, text)?,
        None => print!("{text}"),
    }
    p.say("done");
    Ok(())
}

/// Arithmetic iterations per item of the fork/join measurement's phases: a
/// dependent chain of multiply-adds, under a microsecond of work (0.6–1.1 µs
/// measured on the 2-vCPU test machine), of the order of one node's local step.
const FJ_ITEM_ITERS: usize = 150;

/// Wall-clock microseconds per repetition of the fork/join cost on `pool`
/// (`reps` repetitions of each): a no-op handed to the pool and back; an empty
/// phase of `n` items in tasks of at least `min_len` items, run from inside the
/// pool; a phase of `n` items of [`FJ_ITEM_ITERS`] work each on the calling
/// thread alone (serial), from inside the pool, and handed over each time.
fn fork_join_us(pool: &ThreadPool, n: usize, min_len: usize, reps: usize) -> [f64; 5] {
    use std::hint::black_box;
    let work = |x: &mut f64, iters: usize| {
        let mut y = *x;
        for _ in 0..iters {
            y = black_box(y) * 0.999_999 + 1e-9;
        }
        *x = y;
    };
    let mut v = vec![1.0f64; n];
    let phase = |v: &mut [f64], iters: usize| {
        v.par_iter_mut()
            .with_min_len(min_len)
            .for_each(|x| work(x, iters))
    };
    let time = |f: &mut dyn FnMut()| {
        let t0 = Instant::now();
        f();
        t0.elapsed().as_secs_f64() * 1e6 / reps as f64
    };
    let noop = time(&mut || {
        for _ in 0..reps {
            pool.install(|| black_box(()));
        }
    });
    let empty = time(&mut || {
        pool.install(|| {
            for _ in 0..reps {
                phase(&mut v, 0);
            }
        })
    });
    let serial = time(&mut || {
        for _ in 0..reps {
            v.iter_mut().for_each(|x| work(x, FJ_ITEM_ITERS));
        }
    });
    let in_pool = time(&mut || {
        pool.install(|| {
            for _ in 0..reps {
                phase(&mut v, FJ_ITEM_ITERS);
            }
        })
    });
    let handed = time(&mut || {
        for _ in 0..reps {
            pool.install(|| phase(&mut v, FJ_ITEM_ITERS));
        }
    });
    black_box(&v);
    [noop, empty, serial, in_pool, handed]
}

/// Serial core step vs the parallel step on 1 and `threads` threads, and on
/// `threads` threads run inside its pool, on slices; and the fork/join cost.
fn parallel_case(
    a: &Args,
    p: &Progress,
    topo: Topo,
    w: &Workload,
) -> Result<Value, Box<dyn Error>> {
    let n = w.nodes();
    let min_len = a.min_nodes_per_task.unwrap_or(MIN_NODES_PER_TASK);
    let mut out = Map::new();
    let rows = a.parallel_rows.clone().unwrap_or_else(|| {
        vec![
            Row::new(Algorithm::EdcCif),
            Row::fixed(Algorithm::EcCkf, a.fixed_l),
            Row::fixed(Algorithm::EcCkf, a.probe_l),
        ]
    });
    // (name, threads, whole run inside the pool)
    let variants: [(&str, Option<usize>, bool); 4] = [
        ("serial", None, false),
        ("parallel_1", Some(1), false),
        ("parallel_n", Some(a.threads), false),
        ("parallel_n_in_pool", Some(a.threads), true),
    ];
    let nv = variants.len();
    for row in rows {
        // Pilot on the serial step.
        let mut net = SliceNet::new(w, row, None)?;
        let c0 = ThreadTime::now();
        net.run(w, 0..2)?;
        let step_s = c0.elapsed().as_secs_f64() / 2.0;
        let steps = steps_for(a.budget_s, a.reps, step_s, w.steps());
        let mut wall = vec![Vec::new(); nv];
        let mut proc_cpu = vec![Vec::new(); nv];
        let mut states = Vec::new();
        for r in 0..a.reps {
            for s in 0..nv {
                let i = (r + s) % nv;
                let (_, threads, in_pool) = variants[i];
                let mut net = match threads {
                    None => SliceNet::new(w, row, None)?,
                    Some(t) => SliceNet::new(w, row, Some(t))?.with_min_nodes_per_task(min_len)?,
                };
                let (c0, t0) = (ProcessTime::now(), Instant::now());
                if in_pool {
                    net.run_in_pool(w, 0..steps)?;
                } else {
                    net.run(w, 0..steps)?;
                }
                wall[i].push(t0.elapsed().as_secs_f64() * 1e6 / steps as f64);
                proc_cpu[i].push(c0.elapsed().as_secs_f64() * 1e6 / steps as f64);
                if r == 0 {
                    states.push((i, net.nodes));
                }
            }
        }
        states.sort_by_key(|s| s.0);
        let identical = states.windows(2).all(|s| s[0].1 == s[1].1);
        let med = |i: usize| Spread::of(&wall[i]).median;
        // Under load the fastest repetition is the least disturbed one.
        let best = |i: usize| Spread::of(&wall[i]).min;
        // Serial ÷ parallel within each round (the variants of a round ran back to back).
        let ratios =
            |i: usize| -> Vec<f64> { wall[0].iter().zip(&wall[i]).map(|(s, x)| s / x).collect() };
        let speedup = med(0) / med(2);
        p.say(format!(
            "{topo} N = {n}: parallel {} ({min_len} nodes per task at least): serial {:.2} us/step [{:.2}-{:.2}], parallel x1 {:.2}, x{} {:.2} [{:.2}-{:.2}], x{} in pool {:.2} [{:.2}-{:.2}] (wall medians [IQR]) -> speed-up {:.2}, in pool {:.2} (per-round ratio medians {:.2}, {:.2}); same numbers: {identical}",
            row.label(), med(0), Spread::of(&wall[0]).q1, Spread::of(&wall[0]).q3, med(1),
            a.threads, med(2), Spread::of(&wall[2]).q1, Spread::of(&wall[2]).q3,
            a.threads, med(3), Spread::of(&wall[3]).q1, Spread::of(&wall[3]).q3,
            speedup, med(0) / med(3), Spread::of(&ratios(2)).median, Spread::of(&ratios(3)).median
        ));
        let mut v = Map::new();
        for (i, (name, _, _)) in variants.iter().enumerate() {
            v.insert(
                (*name).into(),
                json!({"step_wall_us": Spread::of(&wall[i]).to_json(),
                       "step_process_cpu_us": Spread::of(&proc_cpu[i]).to_json(),
                       "step_wall_us_samples": wall[i]}),
            );
        }
        v.insert("threads".into(), json!(a.threads));
        v.insert("min_nodes_per_task".into(), json!(min_len));
        v.insert("steps_timed".into(), json!(steps));
        v.insert("speedup_wall".into(), json!(speedup));
        v.insert("speedup_wall_in_pool".into(), json!(med(0) / med(3)));
        v.insert(
            "round_ratio_serial_over_parallel_n".into(),
            Spread::of(&ratios(2)).to_json(),
        );
        v.insert(
            "round_ratio_serial_over_parallel_n_in_pool".into(),
            Spread::of(&ratios(3)).to_json(),
        );
        v.insert("speedup_vs_parallel_1".into(), json!(med(1) / med(2)));
        v.insert("speedup_wall_min".into(), json!(best(0) / best(2)));
        v.insert("speedup_wall_min_in_pool".into(), json!(best(0) / best(3)));
        v.insert("speedup_vs_parallel_1_min".into(), json!(best(1) / best(2)));
        v.insert(
            "process_cpu_ratio".into(),
            json!(Spread::of(&proc_cpu[2]).median / Spread::of(&proc_cpu[0]).median),
        );
        v.insert(
            "process_cpu_ratio_in_pool".into(),
            json!(Spread::of(&proc_cpu[3]).median / Spread::of(&proc_cpu[0]).median),
        );
        v.insert("bit_identical".into(), json!(identical));
        out.insert(row.to_string(), Value::Object(v));
    }
    // The fork/join cost on a pool like the parallel step's.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads)
        .build()?;
    let fj_reps = 1000;
    let mut fj = vec![Vec::new(); 5];
    for _ in 0..a.reps {
        for (k, us) in fork_join_us(&pool, n, min_len, fj_reps)
            .into_iter()
            .enumerate()
        {
            fj[k].push(us);
        }
    }
    let m = |k: usize| Spread::of(&fj[k]).median;
    p.say(format!(
        "{topo} N = {n}: fork/join on {} threads, {min_len} items per task at least (medians over {} rounds of {fj_reps}): no-op handed over {:.2} us; empty phase in pool {:.2} us; a phase of {n} x {FJ_ITEM_ITERS} iterations: serial {:.2} us, in pool {:.2} us, handed over {:.2} us -> overhead over serial/{}: {:.2} us in pool, {:.2} us handed over",
        a.threads, a.reps, m(0), m(1), m(2), m(3), m(4), a.threads,
        m(3) - m(2) / a.threads as f64, m(4) - m(2) / a.threads as f64
    ));
    out.insert(
        "fork_join".into(),
        json!({"threads": a.threads, "items": n, "min_items_per_task": min_len,
               "iterations_per_item": FJ_ITEM_ITERS,
               "reps_per_round": fj_reps, "rounds": a.reps,
               "install_noop_us": Spread::of(&fj[0]).to_json(),
               "empty_phase_in_pool_us": Spread::of(&fj[1]).to_json(),
               "work_phase_serial_us": Spread::of(&fj[2]).to_json(),
               "work_phase_in_pool_us": Spread::of(&fj[3]).to_json(),
               "work_phase_handed_over_us": Spread::of(&fj[4]).to_json(),
               "overhead_in_pool_us": m(3) - m(2) / a.threads as f64,
               "overhead_handed_over_us": m(4) - m(2) / a.threads as f64}),
    );
    Ok(Value::Object(out))
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let r = if args.instr.is_some() {
        instr_mode(&args)
    } else {
        study(&args)
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("edccif-scaling: {e}");
            ExitCode::FAILURE
        }
    }
}
