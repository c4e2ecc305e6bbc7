//! Regenerates the measured sections of `docs/reliability.md`:
//! `cargo run --release -p edccif-sim --bin edccif-reliability -- [--runs R] [--seed S] [--nodes 4,8] [--soak STEPS] [--no-robustness] [--out docs/reliability.md] [--json FILE]`.
//!
//! The robustness table replaces the block between `<!-- BEGIN robustness -->` and
//! `<!-- END robustness -->`, the soak results the `soak` block; the rest of the
//! document is kept. Same function as `edccif reliability` (Python CLI).

use edccif_sim::reliability::{write_report, ReportSettings, RobustnessSettings};

fn main() {
    if let Err(e) = real_main() {
        eprintln!("edccif-reliability: error: {e}");
        std::process::exit(2);
    }
}

fn real_main() -> Result<(), Box<dyn std::error::Error>> {
    let mut rs = RobustnessSettings::default();
    let mut s = ReportSettings {
        robustness: None,
        soak_steps: None,
        out: "docs/reliability.md".into(),
        json: None,
    };
    let mut do_robustness = true;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut val = || args.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--runs" => rs.runs = val()?.parse()?,
            "--seed" => rs.seed = val()?.parse()?,
            "--nodes" => {
                rs.nodes = val()?
                    .split(',')
                    .map(str::parse)
                    .collect::<Result<_, _>>()?
            }
            "--soak" => s.soak_steps = Some(val()?.parse()?),
            "--no-robustness" => do_robustness = false,
            "--out" => s.out = val()?,
            "--json" => s.json = Some(val()?),
            "-h" | "--help" => {
                println!("usage: edccif-reliability [--runs R] [--seed S] [--nodes 4,8] [--soak STEPS] [--no-robustness] [--out docs/reliability.md] [--json FILE]");
                return Ok(());
            }
            other => return Err(format!("unknown argument {other:?}").into()),
        }
    }
    if do_robustness {
        s.robustness = Some(rs);
    }
    let md = write_report(&s, |m| eprintln!("{m}"))?;
    println!("{md}");
    Ok(())
}
