//! `edccif.reliability_report`: the reliability study behind `docs/reliability.md`
//! (same Rust function as the `edccif-reliability` binary).

use edccif_sim::reliability::{write_report_with, ReportSettings, RobustnessSettings};
use pyo3::prelude::*;

use crate::errors::IntoPyResult;

/// Runs the robustness study (unless `robustness=False`) and, with `soak=STEPS`,
/// the soak run; updates their blocks in `out` (default `reliability.md` in the
/// working directory; created when missing) and returns their Markdown.
#[pyfunction]
#[pyo3(signature = (out = std::path::PathBuf::from("reliability.md"), *, runs = 50, seed = 0, nodes = vec![4, 8], soak = None, robustness = true, json = None, progress = true))]
#[allow(clippy::too_many_arguments)]
pub fn reliability_report(
    py: Python<'_>,
    #[pyo3(from_py_with = crate::args::path_arg::out)] out: std::path::PathBuf,
    #[pyo3(from_py_with = crate::args::named::runs)] runs: usize,
    #[pyo3(from_py_with = crate::args::named::seed)] seed: u64,
    #[pyo3(from_py_with = crate::args::named::node_list)] nodes: Vec<usize>,
    soak: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = crate::args::flag_arg::robustness)] robustness: bool,
    #[pyo3(from_py_with = crate::args::opt_text_arg::json)] json: Option<String>,
    #[pyo3(from_py_with = crate::args::flag_arg::progress)] progress: bool,
) -> PyResult<String> {
    for &n in &nodes {
        edccif_sim::limits::check_nodes(n).py()?;
    }
    let soak = soak
        .filter(|s| !s.is_none())
        .map(|s| crate::args::count(s, "soak", 1).map(|v| v as u64))
        .transpose()?;
    let s = ReportSettings {
        robustness: robustness.then(|| RobustnessSettings {
            nodes,
            runs,
            seed,
            ..RobustnessSettings::default()
        }),
        soak_steps: soak,
        out: out.to_string_lossy().into_owned(),
        json,
    };
    // Ctrl-C stops it within a step (nothing is written).
    crate::drive::drive(py, &crate::drive::Progress::Off, move |ctl| {
        write_report_with(
            &s,
            |m| {
                if progress {
                    eprintln!("{m}");
                }
            },
            ctl,
        )
    })
    .into_result()?
    .py()
}
