//! Prints the real-world-like Table IV analog (position RMSE in mm per axis of
//! every event-triggered row, both target paths) as Markdown or JSON.
//!
//! ```text
//! edccif-realworld [--seeds N] [--duration S] [--flights [--data-dir DIR]] [--json] [--out PATH]
//! ```
//!
//! `--seeds N` uses seeds 1..=N (default 5; 20 with `--flights`); `--duration S`
//! overrides the recording length; `--flights`: the real-flight variant instead
//! (targets on the EuRoC V1_02 and TUM freiburg1_xyz trajectories read from
//! `--data-dir DIR`, default `../shared/data` beside the repository root;
//! `--duration` does not apply); `--out PATH` writes the output to a file instead of stdout.

use std::process::ExitCode;

use edccif_sim::realworld::{
    default_data_dir, flight_table, flights_markdown, realworld_markdown, realworld_table,
    FlightSettings, TableSettings,
};

const USAGE: &str = "usage: edccif-realworld [--seeds N] [--duration S] [--flights [--data-dir DIR]] [--json] [--out PATH]";

struct Args {
    table: TableSettings,
    seeds_given: bool,
    flights: Option<std::path::PathBuf>,
    json: bool,
    out: Option<String>,
}

fn parse_args() -> Result<Args, String> {
    let mut s = TableSettings::default();
    let mut flights = false;
    let mut seeds_given = false;
    let mut data_dir = None;
    let mut json = false;
    let mut out = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value\n{USAGE}"));
        match a.as_str() {
            "--seeds" => {
                let n: u64 = value("--seeds")?
                    .parse()
                    .map_err(|_| format!("--seeds needs a positive integer\n{USAGE}"))?;
                if n == 0 {
                    return Err(format!("--seeds needs a positive integer\n{USAGE}"));
                }
                s.seeds = (1..=n).collect();
                seeds_given = true;
            }
            "--duration" => {
                let d: f64 = value("--duration")?
                    .parse()
                    .map_err(|_| format!("--duration needs a number of seconds\n{USAGE}"))?;
                s.duration_s = Some(d);
            }
            "--flights" => flights = true,
            "--data-dir" => data_dir = Some(std::path::PathBuf::from(value("--data-dir")?)),
            "--json" => json = true,
            "--out" => out = Some(value("--out")?),
            "-h" | "--help" => return Err(USAGE.to_string()),
            other => return Err(format!("unknown argument {other:?}\n{USAGE}")),
        }
    }
    if data_dir.is_some() && !flights {
        return Err(format!("--data-dir: only with --flights\n{USAGE}"));
    }
    Ok(Args {
        table: s,
        seeds_given,
        flights: flights.then(|| data_dir.unwrap_or_else(default_data_dir)),
        json,
        out,
    })
}

fn main() -> ExitCode {
    let Args {
        table: settings,
        seeds_given,
        flights,
        json,
        out,
    } = match parse_args() {
        Ok(v) => v,
        Err(m) => {
            eprintln!("{m}");
            return ExitCode::from(2);
        }
    };
    let result = match flights {
        None => realworld_table(&settings)
            .map_err(|e| e.to_string())
            .and_then(|t| {
                Ok(if json {
                    serde_json::to_string_pretty(&t).map_err(|e| e.to_string())? + "\n"
                } else {
                    realworld_markdown(&t)
                })
            }),
        Some(dir) => {
            let mut fs = FlightSettings::new(dir);
            if seeds_given {
                fs.table.seeds = settings.seeds;
            }
            flight_table(&fs).map_err(|e| e.to_string()).and_then(|t| {
                Ok(if json {
                    serde_json::to_string_pretty(&t).map_err(|e| e.to_string())? + "\n"
                } else {
                    flights_markdown(&t)
                })
            })
        }
    };
    let text = match result {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    match out {
        Some(path) => {
            if let Err(e) = std::fs::write(&path, text) {
                eprintln!("error: cannot write {path}: {e}");
                return ExitCode::FAILURE;
            }
        }
        None => print!("{text}"),
    }
    ExitCode::SUCCESS
}
