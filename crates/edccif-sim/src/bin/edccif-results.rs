//! Regenerates `docs/results.md`: `cargo run --release -p edccif-sim --bin edccif-results -- [--runs R] [--seed S] [--nodes 3,4,8] [--out docs/results.md] [--json FILE]`.

use edccif_sim::report::{reproduce, ReproduceSettings};

fn main() {
    if let Err(e) = real_main() {
        eprintln!("edccif-results: error: {e}");
        std::process::exit(2);
    }
}

fn real_main() -> Result<(), Box<dyn std::error::Error>> {
    let mut s = ReproduceSettings {
        progress: true,
        ..ReproduceSettings::default()
    };
    let mut out = String::from("docs/results.md");
    let mut json: Option<String> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut val = || args.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--runs" => s.runs = val()?.parse()?,
            "--seed" => s.seed = val()?.parse()?,
            "--nodes" => {
                s.nodes = val()?
                    .split(',')
                    .map(str::parse)
                    .collect::<Result<_, _>>()?
            }
            "--out" => out = val()?,
            "--json" => json = Some(val()?),
            "--quiet" => s.progress = false,
            "-h" | "--help" => {
                println!("usage: edccif-results [--runs R] [--seed S] [--nodes 3,4,8] [--out docs/results.md] [--json FILE] [--quiet]");
                return Ok(());
            }
            other => return Err(format!("unknown argument {other:?}").into()),
        }
    }
    let r = reproduce(&s)?;
    std::fs::write(&out, r.to_markdown())?;
    eprintln!("wrote {out}");
    if let Some(j) = json {
        std::fs::write(&j, serde_json::to_string_pretty(&r)?)?;
        eprintln!("wrote {j}");
    }
    Ok(())
}
