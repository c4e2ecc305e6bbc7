//! `edccif.reliability_report`: the reliability study behind `docs/reliability.md`
//! (same Rust function as the `edccif-reliability` binary).

use edccif_sim::reliability::{write_report, ReportSettings, RobustnessSettings};
use pyo3::prelude::*;

use crate::errors::IntoPyResult;

/// Runs the robustness study (unless `robustness=False`) and, with `soak=STEPS`,
/// the soak run; updates their blocks in `out` (default `reliability.md` in the
/// working directory; created when missing) and returns their Markdown.
#[pyfunction]
#[pyo3(signature = (out = "reliability.md".to_string(), *, runs = 50, seed = 0, nodes = vec![4, 8], soak = None, robustness = true, json = None, progress = true))]
#[allow(clippy::too_many_arguments)]
pub fn reliability_report(
    py: Python<'_>,
    out: String,
    runs: usize,
    seed: u64,
    nodes: Vec<usize>,
    soak: Option<u64>,
    robustness: bool,
    json: Option<String>,
    progress: bool,
) -> PyResult<String> {
    if runs == 0 || nodes.contains(&0) {
        return Err(crate::errors::ParameterError::new_err(
            "runs and nodes must be >= 1",
        ));
    }
    let s = ReportSettings {
        robustness: robustness.then(|| RobustnessSettings {
            nodes,
            runs,
            seed,
            ..RobustnessSettings::default()
        }),
        soak_steps: soak,
        out,
        json,
    };
    py.allow_threads(move || {
        write_report(&s, |m| {
            if progress {
                eprintln!("{m}");
            }
        })
    })
    .py()
}
