//! Prints the real-world-like Table IV analog (position RMSE in mm per axis of
//! every event-triggered row, both target paths) as Markdown or JSON.
//!
//! ```text
//! edccif-realworld [--seeds N] [--duration S] [--json] [--out PATH]
//! ```
//!
//! `--seeds N` uses seeds 1..=N (default 5); `--duration S` overrides the
//! recording length; `--out PATH` writes the output to a file instead of stdout.

use std::process::ExitCode;

use edccif_sim::realworld::{realworld_markdown, realworld_table, TableSettings};

const USAGE: &str = "usage: edccif-realworld [--seeds N] [--duration S] [--json] [--out PATH]";

fn parse_args() -> Result<(TableSettings, bool, Option<String>), String> {
    let mut s = TableSettings::default();
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
            }
            "--duration" => {
                let d: f64 = value("--duration")?
                    .parse()
                    .map_err(|_| format!("--duration needs a number of seconds\n{USAGE}"))?;
                s.duration_s = Some(d);
            }
            "--json" => json = true,
            "--out" => out = Some(value("--out")?),
            "-h" | "--help" => return Err(USAGE.to_string()),
            other => return Err(format!("unknown argument {other:?}\n{USAGE}")),
        }
    }
    Ok((s, json, out))
}

fn main() -> ExitCode {
    let (settings, json, out) = match parse_args() {
        Ok(v) => v,
        Err(m) => {
            eprintln!("{m}");
            return ExitCode::from(2);
        }
    };
    let table = match realworld_table(&settings) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let text = if json {
        match serde_json::to_string_pretty(&table) {
            Ok(s) => s + "\n",
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        realworld_markdown(&table)
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
