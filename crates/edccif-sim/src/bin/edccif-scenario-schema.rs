//! Writes the JSON Schema of scenario files (generated from the scenario types,
//! `edccif_sim::scenario::json_schema`) to the given file, or to stdout.
//!
//! ```text
//! cargo run -p edccif-sim --bin edccif-scenario-schema -- python/edccif/scenario.schema.json
//! ```

use std::process::ExitCode;

fn main() -> ExitCode {
    let schema = edccif_sim::scenario::json_schema();
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [] => {
            print!("{schema}");
            ExitCode::SUCCESS
        }
        [path] if !path.starts_with('-') => match std::fs::write(path, schema) {
            Ok(()) => {
                eprintln!("wrote {path}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("edccif-scenario-schema: cannot write {path}: {e}");
                ExitCode::FAILURE
            }
        },
        _ => {
            eprintln!("usage: edccif-scenario-schema [OUT.json]  (stdout without OUT)");
            ExitCode::from(2)
        }
    }
}
