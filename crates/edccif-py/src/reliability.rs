//! `edccif.reliability_report`: the reliability study behind `docs/reliability.md`
//! (same Rust function as the `edccif-reliability` binary).

use edccif_sim::reliability::{write_report_with, ReportSettings, RobustnessSettings};
use pyo3::prelude::*;

use crate::errors::IntoPyResult;

/// Runs the robustness study (unless `robustness=False`) and, with `soak=STEPS`,
/// the soak run; updates their blocks in `out` (default `reliability.md` in the
/// working directory; created when missing) and returns their Markdown.
/// `progress`: None or True (default) prints the study's lines on stderr, False
/// none, a callable is called as `progress(done, total)` in runs and soak steps.
#[pyfunction]
#[pyo3(signature = (out = std::path::PathBuf::from("reliability.md"), *, runs = 50, seed = 0, nodes = vec![4, 8], soak = None, robustness = true, json = None, progress = None))]
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
    progress: Option<&Bound<'_, PyAny>>,
) -> PyResult<String> {
    // None/True/False: the study's own lines on stderr (default) or none; a
    // callable: `progress(done, total)` in runs and soak steps, and no lines.
    let (lines, reporter) = match progress.filter(|p| !p.is_none()) {
        None => (true, crate::drive::Progress::Off),
        Some(p) if p.downcast::<pyo3::types::PyBool>().is_ok() => {
            (p.is_truthy()?, crate::drive::Progress::Off)
        }
        Some(p) => (
            false,
            crate::drive::Progress::from_arg(Some(p), "reliability", "runs")?,
        ),
    };
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
    crate::drive::drive(py, &reporter, move |ctl| {
        write_report_with(
            &s,
            |m| {
                if lines {
                    eprintln!("{m}");
                }
            },
            ctl,
        )
    })
    .into_result()?
    .py()
}
