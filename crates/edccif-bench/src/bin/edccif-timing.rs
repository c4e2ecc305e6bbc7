//! The paper's Table III analog: median wall time of a whole 200-step run of
//! every algorithm row on the default scenario, for N ∈ {3, 4, 8} nodes, with
//! the reduction against EC-CKF and the paper's figures beside ours.
//!
//! ```text
//! cargo run --release -p edccif-bench --bin edccif-timing -- [--reps 21] [--nodes 3,4,8] [--rows all] [--topology ring|rgg] [--seed S] [--json [--clock wall|cpu]]
//! cargo run --release -p edccif-bench --bin edccif-timing -- --ckf-step [--reps 21] [--json]
//! cargo run --release -p edccif-bench --bin edccif-timing -- --local-step [--reps 21] [--json]
//! cargo run --release -p edccif-bench --bin edccif-timing -- --fair [--nodes 3,4,8] [--fixed-l 1,2] [--reps 21] [--json]
//! cargo run --release -p edccif-bench --bin edccif-timing -- --targets [--reps 21] [--json]
//! ```
//!
//! `--targets` times the speed targets' three kernels ([`edccif_bench::targets`]:
//! the sent ET-CIF local step, the 8-node EDC-CIF network step, the EKF local
//! step) in the configuration of the flags and in the reference configuration
//! side by side, `--reps` alternating rounds of 5 batches each: medians with
//! the interquartile range, µs per step on the thread-CPU clock. It measures
//! this binary's build level only (build it with
//! `RUSTFLAGS='-C target-cpu=x86-64-v3'` for the v3 level).
//!
//! All rows consume the same simulated measurements; repetitions are
//! interleaved across all (row, N) cases; one thread. `--topology rgg` swaps the
//! ring for a seeded random geometric graph of radius
//! [`edccif_bench::rgg_radius`]`(N)` (for the scaling study). `--json` prints
//! `{"nodes": {"3": {"edc-cif": seconds, …}, …}}` (median wall seconds per run;
//! `--clock cpu`: median thread-CPU seconds). `--ckf-step` prints the
//! microseconds of one node's CKF predict + update step instead, the median of
//! `--reps` batches of 20 000 steps (`--batch`; used by `benchmarks/peers.py`);
//! `--local-step` the microseconds of one node's local step of every local
//! filter (CIF, ET-CIF sent / not sent, CKF, EKF, UKF and their untriggered ET
//! steps) on a mid-run state of the default scenario, interleaved batches of 5 000
//! steps (`--batch`; `--cases` picks some).
//!
//! Every mode measures the library's default configuration unless told
//! otherwise ([`edccif_bench::config`]): `--fast-trig` / `--libm-trig` pick the
//! models' trigonometry (the scenario's `fast_trig`), `--closed-form` /
//! `--stable-form` the ET-CIF's untriggered contribution (the scenario's
//! `untriggered_closed_form`), `--reference` the bit-exact reference path
//! (libm, stable form); they apply to every mode, `--fair` and `--ckf-step`
//! included. The first line of every text output (the `"config"` key of every
//! JSON output) names the configuration measured: the build's CPU level, the
//! CPU's, the trigonometry and the untriggered form.
//!
//! A row may fix the consensus iterations: `--rows ec-ckf@L1` is EC-CKF with
//! `L = 1` instead of the scenario's adequate `L` (`--fixed-l 1,2` adds EC-CKF
//! with each of these `L` to the rows). `--fair` prints Table III, fair
//! ([`edccif_bench::fair`]): EDC-CIF, EC-CKF with the adequate `L` and with the
//! `--fixed-l` ones (default 1, 2), medians with interquartile ranges on both
//! clocks and the per-iteration cost model (`--json`: the raw samples).

use std::error::Error;
use std::process::ExitCode;

use edccif_bench::config::{self, Config};
use edccif_bench::paper::{PaperTimes, PAPER_REDUCTIONS};
use edccif_bench::{
    ckf_step_us, interleaved_rows, local_cases, local_step_times, median, network1_ckf_step_us,
    reduction, rgg_radius, trigger_rate_row, LocalCase, LocalFixture, Row, Workload, DEFAULT_SEED,
};
use edccif_sim::{Algorithm, Topology};
use serde_json::{json, Map, Value};

fn usage() -> String {
    format!(
        "usage: edccif-timing [--reps N] [--nodes 3,4,8] [--rows edc-cif,ec-ckf,ec-ckf@L1,...] [--fixed-l 1,2] [--topology ring|rgg] [--seed S] [--json [--clock wall|cpu]] [--fair] [--ckf-step] [--local-step [--cases cif/always,...]] [--targets] [--batch STEPS] {}",
        config::FLAGS
    )
}

struct Args {
    reps: usize,
    nodes: Vec<usize>,
    rows: Vec<Row>,
    fixed_l: Vec<usize>,
    fair: bool,
    rgg: bool,
    cpu: bool,
    seed: u64,
    json: bool,
    ckf_step: bool,
    local_step: bool,
    targets: bool,
    cases: Option<Vec<String>>,
    batch: Option<usize>,
    config: Config,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        reps: 21,
        nodes: vec![3, 4, 8],
        rows: Algorithm::ALL.iter().map(|a| Row::new(*a)).collect(),
        fixed_l: Vec::new(),
        fair: false,
        rgg: false,
        cpu: false,
        seed: DEFAULT_SEED,
        json: false,
        ckf_step: false,
        local_step: false,
        targets: false,
        cases: None,
        batch: None,
        config: Config::library_default(),
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
        match arg.as_str() {
            "--reps" => {
                a.reps = value("--reps")?
                    .parse()
                    .map_err(|e| format!("--reps: {e}"))?;
                if a.reps == 0 {
                    return Err("--reps must be >= 1".into());
                }
            }
            "--nodes" => {
                a.nodes = value("--nodes")?
                    .split(',')
                    .map(|s| s.trim().parse::<usize>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| format!("--nodes: {e} (expected e.g. 3,4,8)"))?;
                if a.nodes.is_empty() || a.nodes.contains(&0) {
                    return Err("--nodes: node counts must be >= 1".into());
                }
            }
            "--rows" => {
                a.rows = value("--rows")?
                    .split(',')
                    .map(|s| s.trim().parse::<Row>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| format!("--rows: {e}"))?;
            }
            "--fixed-l" => {
                a.fixed_l = value("--fixed-l")?
                    .split(',')
                    .map(|s| s.trim().parse::<usize>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| format!("--fixed-l: {e} (expected e.g. 1,2)"))?;
                if a.fixed_l.contains(&0) {
                    return Err("--fixed-l: iterations must be >= 1".into());
                }
            }
            "--fair" => a.fair = true,
            "--topology" => {
                a.rgg = match value("--topology")?.as_str() {
                    "ring" => false,
                    "rgg" | "random-geometric" => true,
                    other => {
                        return Err(format!("--topology: expected ring or rgg, got {other:?}"))
                    }
                }
            }
            "--clock" => {
                a.cpu = match value("--clock")?.as_str() {
                    "wall" => false,
                    "cpu" => true,
                    other => return Err(format!("--clock: expected wall or cpu, got {other:?}")),
                }
            }
            "--seed" => {
                a.seed = value("--seed")?
                    .parse()
                    .map_err(|e| format!("--seed: {e}"))?
            }
            "--json" => a.json = true,
            "--ckf-step" => a.ckf_step = true,
            "--local-step" => a.local_step = true,
            "--targets" => a.targets = true,
            "--cases" => {
                a.cases = Some(
                    value("--cases")?
                        .split(',')
                        .map(|s| s.trim().to_string())
                        .collect(),
                )
            }
            "--batch" => {
                let b: usize = value("--batch")?
                    .parse()
                    .map_err(|e| format!("--batch: {e}"))?;
                if b == 0 {
                    return Err("--batch must be >= 1".into());
                }
                a.batch = Some(b);
            }
            // `cargo bench` passes --bench to every target; ignore it.
            "--bench" => {}
            "-h" | "--help" => return Err(usage()),
            other => return Err(format!("unknown argument {other:?}\n{}", usage())),
        }
    }
    Ok(a)
}

fn ckf_step(args: &Args) -> Result<(), Box<dyn Error>> {
    let (batches, per_batch) = (args.reps, args.batch.unwrap_or(20_000));
    let ckf = ckf_step_us(args.seed, batches, per_batch, &args.config)?;
    let net1 = network1_ckf_step_us(args.seed, batches, per_batch, &args.config)?;
    if args.json {
        println!(
            "{}",
            json!({
                "config": args.config.to_json(),
                "ckf_step_us": ckf.wall_us,
                "ckf_step_cpu_us": ckf.cpu_us,
                "network_1node_c_ckf_step_us": net1.wall_us,
                "network_1node_c_ckf_step_cpu_us": net1.cpu_us,
            })
        );
    } else {
        println!("{}", args.config.describe());
        println!("{:<72} {:>9} {:>9}", "", "wall", "cpu");
        println!(
            "{:<72} {:>9.3} {:>9.3}",
            "CKF predict+update step (cov_local, 7-state CT, range/pitch/azimuth), us",
            ckf.wall_us,
            ckf.cpu_us
        );
        println!(
            "{:<72} {:>9.3} {:>9.3}",
            "1-node C-CKF network step (AnyNetwork::step), us", net1.wall_us, net1.cpu_us
        );
        println!(
            "(medians of {batches} batches of {per_batch} steps, seed {})",
            args.seed
        );
    }
    Ok(())
}

fn local_step(args: &Args) -> Result<(), Box<dyn Error>> {
    let f = LocalFixture::new(DEFAULT_SEED, 50)?.with_config(&args.config);
    let per_batch = args.batch.unwrap_or(5_000);
    let cases: Vec<LocalCase> = match &args.cases {
        None => local_cases().to_vec(),
        Some(names) => names
            .iter()
            .map(|n| {
                local_cases()
                    .into_iter()
                    .find(|c| c.name == n.as_str())
                    .ok_or_else(|| {
                        let all: Vec<_> = local_cases().iter().map(|c| c.name).collect();
                        format!(
                            "--cases: unknown case {n:?}; expected some of {}",
                            all.join(",")
                        )
                    })
            })
            .collect::<Result<_, _>>()?,
    };
    let times = local_step_times(&f, &cases, args.reps, per_batch)?;
    if args.json {
        let mut m = Map::new();
        for (case, t) in &times {
            m.insert(
                case.name.into(),
                json!({ "wall_us": t.wall_us, "cpu_us": t.cpu_us }),
            );
        }
        println!(
            "{}",
            json!({ "config": args.config.to_json(), "local_step_us": m })
        );
    } else {
        println!("{}", args.config.describe());
        println!(
            "One node's local step, default model, node 0 of the 4-node default scenario after 50 EDC-CIF steps;"
        );
        println!(
            "medians of {} interleaved batches of {per_batch} steps.",
            args.reps
        );
        println!(
            "{:<15} {:<20} {:>9} {:>9}",
            "case", "filter", "cpu us", "wall us"
        );
        for (case, t) in &times {
            println!(
                "{:<15} {:<20} {:>9.3} {:>9.3}",
                case.name, case.label, t.cpu_us, t.wall_us
            );
        }
    }
    Ok(())
}

fn targets(args: &Args) -> Result<(), Box<dyn Error>> {
    use edccif_bench::targets::{time_target, Target};
    use edccif_bench::Spread;
    let configs = [args.config, Config::reference()];
    // samples[config][target]: cpu µs per step of every batch.
    let mut samples = vec![vec![Vec::new(); Target::ALL.len()]; configs.len()];
    for r in 0..args.reps {
        for k in 0..configs.len() {
            let c = if r % 2 == 0 { k } else { configs.len() - 1 - k };
            for (i, t) in Target::ALL.iter().enumerate() {
                let per_batch = args.batch.unwrap_or(t.default_batch());
                for s in time_target(*t, &configs[c], 5, per_batch)? {
                    samples[c][i].push(s.cpu_us);
                }
            }
        }
    }
    if args.json {
        let mut out = Map::new();
        for (c, cfg) in configs.iter().enumerate() {
            let mut m = Map::new();
            for (i, t) in Target::ALL.iter().enumerate() {
                m.insert(
                    t.name().into(),
                    json!({"cpu_us": Spread::of(&samples[c][i]).to_json(), "target_us": t.target_us()}),
                );
            }
            out.insert(
                if c == 0 { "measured" } else { "reference" }.into(),
                json!({"config": cfg.to_json(), "targets": m}),
            );
        }
        println!("{}", Value::Object(out));
        return Ok(());
    }
    println!("measured:  {}", configs[0].describe());
    println!("reference: {}", configs[1].describe());
    println!(
        "{} alternating rounds of 5 batches; thread-CPU µs per step, median [IQR]",
        args.reps
    );
    println!(
        "{:<30} {:>8} {:>26} {:>26} {:>7}",
        "kernel", "target", "measured", "reference", "ratio"
    );
    for (i, t) in Target::ALL.iter().enumerate() {
        let (a, b) = (Spread::of(&samples[0][i]), Spread::of(&samples[1][i]));
        println!(
            "{:<30} {:>8.3} {:>8.3} [{:>7.3}-{:>7.3}] {:>8.3} [{:>7.3}-{:>7.3}] {:>7.3}",
            t.label(),
            t.target_us(),
            a.median,
            a.q1,
            a.q3,
            b.median,
            b.q1,
            b.q3,
            a.median / b.median
        );
    }
    Ok(())
}

fn fair(args: &Args) -> Result<(), Box<dyn Error>> {
    let fixed = if args.fixed_l.is_empty() {
        vec![1, 2]
    } else {
        args.fixed_l.clone()
    };
    let cases =
        edccif_bench::fair::measure(&args.nodes, &fixed, args.reps, 1, args.seed, &args.config)?;
    if args.json {
        let mut out = edccif_bench::fair::to_json(&cases);
        out["config"] = args.config.to_json();
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!("{}", args.config.describe());
        print!("{}", edccif_bench::fair::render(&cases));
    }
    Ok(())
}

fn table(args: &Args) -> Result<(), Box<dyn Error>> {
    let mut rows = args.rows.clone();
    rows.extend(
        args.fixed_l
            .iter()
            .map(|&l| Row::fixed(Algorithm::EcCkf, l)),
    );
    if !args.json {
        // The text table compares against EC-CKF and states the EDC-CIF verdict.
        rows.extend([Row::new(Algorithm::EcCkf), Row::new(Algorithm::EdcCif)]);
    }
    rows.sort();
    rows.dedup();
    let workloads = args
        .nodes
        .iter()
        .map(|&n| {
            if args.rgg {
                let topology = Topology::RandomGeometric {
                    radius: rgg_radius(n),
                    seed: args.seed,
                };
                Workload::with_topology(n, topology, args.seed)
            } else {
                Workload::paper(n, args.seed)
            }
            .map(|mut w| {
                // The filters' models only: the simulated truth is the same.
                args.config.apply(&mut w.scenario);
                w
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let cases: Vec<(Row, &Workload)> = workloads
        .iter()
        .flat_map(|w| rows.iter().map(move |a| (*a, w)))
        .collect();
    let samples = interleaved_rows(&cases, args.reps, 1, None)?;
    // (wall, cpu) medians in seconds per run.
    let med = |alg: Row, w: &Workload| -> (f64, f64) {
        let i = cases
            .iter()
            .position(|(a, x)| *a == alg && std::ptr::eq(*x, w))
            .expect("case");
        (median(&samples[i].wall), median(&samples[i].cpu))
    };

    if args.json {
        let mut nodes = Map::new();
        for w in &workloads {
            let mut row_times = Map::new();
            for &alg in &rows {
                let (wall, cpu) = med(alg, w);
                row_times.insert(alg.to_string(), json!(if args.cpu { cpu } else { wall }));
            }
            nodes.insert(w.nodes().to_string(), Value::Object(row_times));
        }
        println!(
            "{}",
            json!({ "config": args.config.to_json(), "nodes": nodes })
        );
        return Ok(());
    }

    let paper = PaperTimes::load();
    println!("{}", args.config.describe());
    println!(
        "Whole {}-step runs of the default scenario (seed {}); medians of {} interleaved repetitions, one thread;",
        workloads[0].steps(),
        args.seed,
        args.reps
    );
    println!(
        "wall = wall-clock time, cpu = the thread's CPU time (not inflated when the OS deschedules the thread);"
    );
    println!("TR = trigger rate of the run (sent / measured node-steps).");
    println!(
        "Paper figures (Table III; DEC-CKF from Table I): {}.",
        paper.source
    );
    let mut verdicts = Vec::new();
    for w in &workloads {
        let n = w.nodes();
        let (base_w, base_c) = med(Row::new(Algorithm::EcCkf), w);
        let l = w.scenario.consensus_iterations()?;
        let adjacency = w.scenario.adjacency()?;
        let degree = adjacency.iter().filter(|a| **a).count() as f64 / n as f64;
        println!();
        println!(
            "N = {n} ({:?} topology, mean degree {degree:.1}, consensus iterations L = {l})",
            w.scenario.topology
        );
        println!(
            "{:<14} {:>9} {:>9} {:>9} {:>10} {:>10} {:>6} | {:>10} {:>10}",
            "row",
            "wall ms",
            "cpu ms",
            "cpu us/st",
            "wall vs EC",
            "cpu vs EC",
            "TR",
            "paper ms",
            "paper vs EC"
        );
        for &alg in &rows {
            let (tw, tc) = med(alg, w);
            // The paper's figures are for its own (adequate) L.
            let p = paper.ms(n, alg.alg).filter(|_| alg.iters.is_none());
            let pr = p
                .zip(paper.ms(n, Algorithm::EcCkf))
                .map(|(a, b)| reduction(a, b));
            println!(
                "{:<14} {:>9.3} {:>9.3} {:>9.2} {:>9.1}% {:>9.1}% {:>5.1}% | {:>10} {:>10}",
                alg.label(),
                tw * 1e3,
                tc * 1e3,
                tc * 1e6 / w.steps() as f64,
                100.0 * reduction(tw, base_w),
                100.0 * reduction(tc, base_c),
                100.0 * trigger_rate_row(alg, w)?,
                p.map_or("-".into(), |v| format!("{v:.2}")),
                pr.map_or("-".into(), |v| format!("{:.1}%", 100.0 * v)),
            );
        }
        let (edc_w, edc_c) = med(Row::new(Algorithm::EdcCif), w);
        let (ours_w, ours_c) = (reduction(edc_w, base_w), reduction(edc_c, base_c));
        let claimed = PAPER_REDUCTIONS
            .iter()
            .find(|(m, _)| *m == n)
            .map(|r| r.1)
            .or_else(|| paper.reduction(n));
        match claimed {
            Some(c) => {
                let verdict = match (ours_w >= c, ours_c >= c) {
                    (true, true) => "HOLDS",
                    (false, false) => "DOES NOT HOLD",
                    _ => "is INCONCLUSIVE (the clocks disagree)",
                };
                println!(
                    "EDC-CIF vs EC-CKF at N = {n}: ours {:.2}% wall / {:.2}% cpu, paper {:.2}% -> the paper's reduction {verdict}.",
                    100.0 * ours_w,
                    100.0 * ours_c,
                    100.0 * c,
                );
                verdicts.push((n, verdict));
            }
            None => println!(
                "EDC-CIF vs EC-CKF at N = {n}: ours {:.2}% wall / {:.2}% cpu (the paper gives no figure for N = {n}).",
                100.0 * ours_w,
                100.0 * ours_c
            ),
        }
        // Among the paper's rows (fixed-L variants are not rows of the paper).
        let fastest = |by: fn((f64, f64)) -> f64| {
            rows.iter()
                .copied()
                .filter(|r| r.iters.is_none())
                .min_by(|a, b| by(med(*a, w)).total_cmp(&by(med(*b, w))))
                .expect("rows")
        };
        let (fw, fc) = (fastest(|t| t.0), fastest(|t| t.1));
        let edc = Row::new(Algorithm::EdcCif);
        let claim = if fw == edc && fc == edc {
            "holds"
        } else {
            "DOES NOT HOLD"
        };
        println!(
            "Fastest row at N = {n}: {} (wall), {} (cpu) -> the paper's claim that EDC-CIF is the fastest row {claim}.",
            fw.label(),
            fc.label()
        );
    }
    if !verdicts.is_empty() {
        println!();
        println!(
            "Summary: the paper's EDC-CIF-vs-EC-CKF computation-time reductions: {}.",
            verdicts
                .iter()
                .map(|(n, v)| format!("N = {n}: {}", v.to_lowercase()))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok(())
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let r = if args.targets {
        targets(&args)
    } else if args.ckf_step {
        ckf_step(&args)
    } else if args.local_step {
        local_step(&args)
    } else if args.fair {
        fair(&args)
    } else {
        table(&args)
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("edccif-timing: {e}");
            ExitCode::FAILURE
        }
    }
}
