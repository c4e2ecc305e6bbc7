//! The reproduction behind `docs/results.md`: Table II (every row, each node
//! count), Table I (ablations), the δ sweep and the σ1/σ2 sweep, each run as a
//! seeded Monte Carlo study on the default scenario, with the paper's published
//! numbers side by side.

use serde::{Deserialize, Serialize};

use crate::algorithm::{Algorithm, FusionKind, RunOptions};
use crate::control::Control;
use crate::error::Result;
use crate::montecarlo::{monte_carlo_with, McResult, McSettings, Variant};
use crate::scenario::Scenario;
use edccif_core::EtPolicy;

/// The paper's published numbers (see `crates/edccif-sim/data/README.md`).
pub const PAPER_TABLES: &str = include_str!("../data/paper_tables.json");

/// What to reproduce.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReproduceSettings {
    /// Node counts of Table II.
    pub nodes: Vec<usize>,
    /// Monte Carlo runs per configuration.
    pub runs: usize,
    /// Seed of run 0.
    pub seed: u64,
    /// Progress bars.
    pub progress: bool,
    /// Thresholds of the δ sweep.
    pub deltas: Vec<f64>,
    /// Values of the σ sweep (each applied to σ1 with σ2 = 5e-4, then to σ2 with σ1 = 5e-4).
    pub sigmas: Vec<f64>,
    /// Node count of Table I and the sweeps.
    pub ablation_nodes: usize,
    /// Where the real flights' ground truths are
    /// ([`crate::realworld::default_data_dir`] for this checkout); `None`: no
    /// real-flight section.
    #[serde(default)]
    pub flight_data_dir: Option<std::path::PathBuf>,
    /// More ground-truth files for the real-flight section, after those of
    /// `flight_data_dir` (any TUM or EuRoC file,
    /// [`FlightFile::new`](edccif_io::flights::FlightFile::new)).
    #[serde(default)]
    pub flight_files: Vec<std::path::PathBuf>,
    /// Repeated stamps in a flight's ground truth: dropped and counted, or the
    /// file refused (before any study runs).
    #[serde(default)]
    pub duplicates: edccif_io::preprocess::DuplicateStamps,
}

impl ReproduceSettings {
    /// The real-flight section's settings: the known flights of
    /// `flight_data_dir`, then `flight_files`; `None` when there are none.
    pub fn flight_settings(&self) -> Option<crate::realworld::FlightSettings> {
        let mut files: Vec<edccif_io::flights::FlightFile> = match &self.flight_data_dir {
            Some(d) => crate::realworld::FlightSettings::new(d).flights,
            None => Vec::new(),
        };
        files.extend(
            self.flight_files
                .iter()
                .map(edccif_io::flights::FlightFile::new),
        );
        if files.is_empty() {
            return None;
        }
        let mut fs = crate::realworld::FlightSettings::from_files(files);
        fs.duplicates = self.duplicates;
        Some(fs)
    }
}

impl Default for ReproduceSettings {
    fn default() -> Self {
        Self {
            nodes: vec![3, 4, 8],
            runs: 100,
            seed: 0,
            progress: false,
            deltas: (1..=10).map(|i| i as f64 / 100.0).collect(),
            sigmas: vec![5e-4, 5e-3, 5e-2, 0.1],
            ablation_nodes: 4,
            flight_data_dir: None,
            flight_files: Vec::new(),
            duplicates: edccif_io::preprocess::DuplicateStamps::Drop,
        }
    }
}

/// One point of the δ sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeltaPoint {
    /// Threshold.
    pub delta: f64,
    /// Results of the swept rows.
    pub mc: McResult,
}

/// One point of the σ sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SigmaPoint {
    /// σ1.
    pub sigma1: f64,
    /// σ2.
    pub sigma2: f64,
    /// Results (EDC-CIF).
    pub mc: McResult,
}

/// Everything the reproduction computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reproduction {
    /// Settings used.
    pub settings: ReproduceSettings,
    /// Table II: one study per node count, all nine rows.
    pub table2: Vec<McResult>,
    /// Table I: ablations on `ablation_nodes` nodes.
    pub table1: McResult,
    /// δ sweep (EDC-CIF, ED-CIF, EC-CKF).
    pub delta_sweep: Vec<DeltaPoint>,
    /// σ sweep (EDC-CIF).
    pub sigma_sweep: Vec<SigmaPoint>,
    /// Table IV analog: the real-world-like pipeline (generator → preprocessing →
    /// every ET row), RMSE in mm per axis.
    pub realworld: crate::realworld::RealWorldTable,
    /// The real-flight variant (with [`ReproduceSettings::flight_data_dir`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flights: Option<crate::realworld::FlightTable>,
}

/// The Table I variants: the method, its two ablations, and DEC-CKF.
pub fn ablation_variants() -> Vec<Variant> {
    vec![
        Algorithm::EdcCif.into(),
        Variant {
            label: "w/o optimal ET filter (hold)".into(),
            algorithm: Algorithm::EdcCif,
            options: RunOptions {
                et_policy: Some(EtPolicy::Hold),
                ..RunOptions::default()
            },
        },
        Variant {
            label: "w/o diffusion with CI (consensus)".into(),
            algorithm: Algorithm::EdcCif,
            options: RunOptions {
                fusion: Some(FusionKind::Consensus),
                ..RunOptions::default()
            },
        },
        Algorithm::DecCkf.into(),
    ]
}

/// Runs every study. Every input (the flights' ground truths included) is read
/// and checked before the first study runs.
pub fn reproduce(s: &ReproduceSettings) -> Result<Reproduction> {
    reproduce_with(s, Control::none())
}

/// [`reproduce`] under a [`Control`]: every Monte Carlo study checks it (a
/// cancelled reproduction returns [`Error::Interrupted`](crate::Error::Interrupted),
/// keeping nothing), and the progress counts runs × variants of the studies
/// started so far.
pub fn reproduce_with(s: &ReproduceSettings, ctl: &Control) -> Result<Reproduction> {
    for &n in &s.nodes {
        crate::limits::check_nodes(n)?;
        // The consensus rows' adequate iterations: the eigenvalues of the
        // dense n × n weights (the matrix and the decomposition's copies).
        crate::limits::check_memory(
            || {
                format!("nodes = {n}: the eigenvalues of the {n} × {n} weights for the consensus rows' iterations")
            },
            crate::limits::product(&[n, n, 24]),
        )?;
    }
    crate::limits::check_nodes(s.ablation_nodes)?;
    let flight_settings = s.flight_settings();
    let loaded = flight_settings
        .as_ref()
        .map(crate::realworld::load_flights)
        .transpose()?;
    let mc = |sc: &Scenario, v: &[Variant]| {
        let r = monte_carlo_with(
            sc,
            v,
            &McSettings {
                runs: s.runs,
                seed: s.seed,
                progress: s.progress,
            },
            ctl,
        )?;
        ctl.check()?;
        Ok(r)
    };
    let all: Vec<Variant> = Algorithm::ALL.iter().map(|a| (*a).into()).collect();
    let table2 = s
        .nodes
        .iter()
        .map(|&n| mc(&Scenario::paper(n), &all))
        .collect::<Result<Vec<_>>>()?;
    let base = Scenario::paper(s.ablation_nodes);
    let table1 = mc(&base, &ablation_variants())?;
    let swept: Vec<Variant> = [Algorithm::EdcCif, Algorithm::EdCif, Algorithm::EcCkf]
        .iter()
        .map(|a| (*a).into())
        .collect();
    let delta_sweep = s
        .deltas
        .iter()
        .map(|&d| {
            Ok(DeltaPoint {
                delta: d,
                mc: mc(
                    &Scenario {
                        delta: d.into(),
                        ..base.clone()
                    },
                    &swept,
                )?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let edc = [Variant::from(Algorithm::EdcCif)];
    let mut sigma_sweep = Vec::new();
    for &v in &s.sigmas {
        for (s1, s2) in [(v, 5e-4), (5e-4, v)] {
            if sigma_sweep
                .iter()
                .any(|p: &SigmaPoint| p.sigma1 == s1 && p.sigma2 == s2)
            {
                continue;
            }
            sigma_sweep.push(SigmaPoint {
                sigma1: s1,
                sigma2: s2,
                mc: mc(
                    &Scenario {
                        sigma1: s1,
                        sigma2: s2,
                        ..base.clone()
                    },
                    &edc,
                )?,
            });
        }
    }
    ctl.check()?;
    let realworld = crate::realworld::realworld_table(&crate::realworld::TableSettings::default())?;
    let flights = match (&flight_settings, &loaded) {
        (Some(fs), Some(l)) => Some(crate::realworld::flight_table_loaded(fs, l)?),
        _ => None,
    };
    ctl.check()?;
    Ok(Reproduction {
        settings: s.clone(),
        table2,
        table1,
        delta_sweep,
        sigma_sweep,
        realworld,
        flights,
    })
}

fn paper() -> serde_json::Value {
    serde_json::from_str(PAPER_TABLES).unwrap_or(serde_json::Value::Null)
}

fn paper_row(p: &serde_json::Value, table: &str, nodes: usize, row: &str) -> Option<Vec<f64>> {
    p["tables"][table]["by_nodes"][nodes.to_string()][row]
        .as_array()
        .map(|a| a.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect())
}

fn fmt_opt(v: Option<f64>, d: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.d$}"),
        _ => "–".into(),
    }
}

fn mean3(v: &[f64]) -> f64 {
    v.iter().take(3).sum::<f64>() / 3.0
}

fn mean_vel(v: &[f64]) -> f64 {
    v[3..6].iter().sum::<f64>() / 3.0
}

impl Reproduction {
    /// `docs/results.md`: every table with the paper's numbers side by side and
    /// plain statements where they agree or not.
    pub fn to_markdown(&self) -> String {
        let p = paper();
        let s = &self.settings;
        let mut md = String::new();
        md += "# Results: the paper's tables reproduced on the default scenario\n\n";
        md += &format!(
            "Generated by `edccif reproduce --runs {} --seed {}` (or `cargo run --release -p edccif-sim --bin edccif-results`). \
             Every number below comes from that run: {} Monte Carlo runs per configuration, run r simulated with seed {} + r, \
             every algorithm on the same simulated data. Scenario: the built-in default (ALGORITHM.md §6): 200 steps of 0.1 s, \
             ring topology, δ = 0.04, σ1 = σ2 = 5·10⁻⁴. The paper's numbers are quoted from `crates/edccif-sim/data/paper_tables.json` \
             (extracted from the paper and its appendix). The paper does not publish its simulation constants, so equal magnitudes are \
             not expected; orderings and trends are what can be compared. The scenario was not tuned to agree.\n\n",
            s.runs, s.seed, s.runs, s.seed
        );
        md += "Metrics (ALGORITHM.md §6): per-variable RMSE `e_k^i = sqrt(mean over runs of squared error)`, averaged over nodes and \
               k = 1..T. **pos/vel (norm)** use the 3-vector error norm (the paper's PRMSE/VRMSE equations); **pos/vel (axis mean)** is \
               the mean of the three per-axis values, which is what the paper's appendix Table I numbers equal (see the data README). \
               NEES is averaged over runs, nodes and steps; a consistent filter gives 7.\n\n";

        // Table II
        md += "## Table II: average RMSE per state variable, every row, 3 / 4 / 8 observers\n\n";
        md += "Each cell: **ours** (paper). DEC-CKF has no Table II entry in the paper. Note: the paper's 3- and 8-observer blocks are \
               printed under the labels x, y, z, ẋ, ẏ, ż but their values alternate between position- and velocity-sized numbers \
               (e.g. 3 observers, C-CKF: 0.0558, 0.2651, 0.0451, 0.2173, …), as if the rows were x, ẋ, y, ẏ, z, ż; we quote them as \
               printed. On 3 observers the ring is the complete graph, where ED-CIF and EDC-CIF coincide (every node adapts with every \
               contribution), so their rows are equal to rounding.\n\n";
        let vars = [
            "x (m)",
            "y (m)",
            "z (m)",
            "vx (m/s)",
            "vy (m/s)",
            "vz (m/s)",
            "ω (rad/s)",
        ];
        for mc in &self.table2 {
            md += &format!("### {} observers\n\n", mc.nodes);
            md += &format!(
                "| algorithm | {} | pos (norm) | vel (norm) | trigger rate | NEES | guard |\n|---|{}---|---|---|---|---|\n",
                vars.join(" | "),
                "---|".repeat(vars.len())
            );
            for v in &mc.variants {
                let pr = paper_row(&p, "table2_accuracy", mc.nodes, v.algorithm.label());
                let cells: Vec<String> = v
                    .errors
                    .rmse_per_variable
                    .iter()
                    .enumerate()
                    .map(|(i, x)| {
                        format!(
                            "**{x:.4}** ({})",
                            fmt_opt(pr.as_ref().and_then(|r| r.get(i).copied()), 4)
                        )
                    })
                    .collect();
                md += &format!(
                    "| {} | {} | {:.4} | {:.4} | {:.1} % | {} | {} |\n",
                    v.label,
                    cells.join(" | "),
                    v.errors.pos_rmse,
                    v.errors.vel_rmse,
                    100.0 * v.trigger_rate,
                    fmt_opt(v.errors.nees, 2),
                    v.guard_fallbacks
                );
            }
            md += "\n";
            md += &self.table2_findings(mc, &p);
        }

        // Table I
        let t1 = &self.table1;
        md += &format!("## Table I: ablations ({} observers)\n\n", t1.nodes);
        md += "The paper does not say what replaces the error-minimised update in \"w/o optimal ET filter\"; we use the `hold` policy \
               (the last sent measurement treated as fresh). \"w/o diffusion with CI\" is ET-CIF with consensus fusion (adequate L). \
               The paper's t_com column is compared in the computation-time section and in `docs/performance.md`.\n\n";
        md += "| variant | pos (axis mean) | paper RMSEpos | vel (axis mean) | paper RMSEvel | pos (norm) | vel (norm) | trigger rate | paper TR | NEES |\n|---|---|---|---|---|---|---|---|---|---|\n";
        let t1p = &p["tables"]["table1_ablation"]["rows"];
        let t1_key = |label: &str| -> &str {
            if label.starts_with("w/o optimal") {
                "EDC-CIF w/o optimal ET filter"
            } else if label.starts_with("w/o diffusion") {
                "EDC-CIF w/o diffusion with CI"
            } else {
                match label {
                    "DEC-CKF" => "DEC-CKF",
                    _ => "EDC-CIF",
                }
            }
        };
        for v in &t1.variants {
            let pr = &t1p[t1_key(&v.label)];
            let e = &v.errors.rmse_per_variable;
            md += &format!(
                "| {} | **{:.4}** | {} | **{:.4}** | {} | {:.4} | {:.4} | {:.1} % | {} % | {} |\n",
                v.label,
                mean3(e),
                fmt_opt(pr[0].as_f64(), 4),
                mean_vel(e),
                fmt_opt(pr[1].as_f64(), 4),
                v.errors.pos_rmse,
                v.errors.vel_rmse,
                100.0 * v.trigger_rate,
                fmt_opt(pr[3].as_f64(), 2),
                fmt_opt(v.errors.nees, 2)
            );
        }
        md += "\n";
        md += &self.table1_findings();

        // δ sweep
        md += &format!("## Trigger threshold δ ({} observers)\n\n", t1.nodes);
        md += "The paper publishes this sweep only as a figure (no numbers); its text gives a trigger rate of 52.31 % at δ = 0.04 and says \
               the error grows and the trigger rate falls as δ grows.\n\n";
        if let Some(first) = self.delta_sweep.first() {
            let labels: Vec<&str> = first.mc.variants.iter().map(|v| v.label.as_str()).collect();
            md += "| δ |";
            for l in &labels {
                md += &format!(" {l} pos (norm) | {l} vel (norm) | {l} trigger rate |");
            }
            md += "\n|---|";
            md += &"---|---|---|".repeat(labels.len());
            md += "\n";
            for pt in &self.delta_sweep {
                md += &format!("| {:.2} |", pt.delta);
                for v in &pt.mc.variants {
                    md += &format!(
                        " {:.4} | {:.4} | {:.1} % |",
                        v.errors.pos_rmse,
                        v.errors.vel_rmse,
                        100.0 * v.trigger_rate
                    );
                }
                md += "\n";
            }
            md += "\n";
            md += &self.delta_findings();
        }

        // σ sweep
        md += &format!(
            "## Scaling parameters σ1, σ2 (EDC-CIF, {} observers)\n\n",
            t1.nodes
        );
        md += "One parameter varied, the other fixed at 5·10⁻⁴, as in the paper. The paper's values at the default (0.0906 m / 0.3969 m/s) \
               match neither of its other tables, so only the trends compare.\n\n";
        md += "| varied | value | pos (norm) | vel (norm) | pos (axis mean) | vel (axis mean) | paper RMSEpos | paper RMSEvel | guard fallbacks |\n|---|---|---|---|---|---|---|---|---|\n";
        let sp = &p["tables"]["sigma_sweep"];
        let paper_vals: Vec<f64> = sp["values"]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
            .unwrap_or_default();
        for (name, pick) in [("σ1", 0usize), ("σ2", 1usize)] {
            let key = if pick == 0 { "sigma1" } else { "sigma2" };
            for pt in &self.sigma_sweep {
                let (val, other) = if pick == 0 {
                    (pt.sigma1, pt.sigma2)
                } else {
                    (pt.sigma2, pt.sigma1)
                };
                if other != 5e-4 || (val == 5e-4 && pick == 1 && pt.sigma1 != 5e-4) {
                    continue;
                }
                let v = &pt.mc.variants[0];
                let idx = paper_vals.iter().position(|x| (x - val).abs() < 1e-15);
                let pp = |col: &str| idx.and_then(|i| sp["sweeps"][key][col][i].as_f64());
                md += &format!(
                    "| {name} | {val:.0e} | {:.4} | {:.4} | {:.4} | {:.4} | {} | {} | {} |\n",
                    v.errors.pos_rmse,
                    v.errors.vel_rmse,
                    mean3(&v.errors.rmse_per_variable),
                    mean_vel(&v.errors.rmse_per_variable),
                    fmt_opt(pp("rmse_pos"), 4),
                    fmt_opt(pp("rmse_vel"), 4),
                    v.guard_fallbacks
                );
            }
        }
        md += "\n";
        md += &self.sigma_findings();

        // Table IV analog
        md += "## Table IV analog: the real-world-like pipeline\n\n";
        md += "Paper's Table IV (manually controlled flight, RMSE in mm, x/y/z): EC-EKF 9.2562/6.4443/6.5458, EC-UKF 9.2261/6.3112/6.5326, \
               EC-CKF 9.1974/6.2543/6.5183, ED-CIF 8.9307/6.2447/6.4419, EDC-CIF 8.5531/6.2434/6.4414. Ours comes from the seeded \
               real-world-like generator (3 RGB-D observers with clock offsets, jitter, dropped frames and outliers; motion-capture \
               truth), the preprocessing pipeline and every ET row (`cargo run --release -p edccif-sim --bin edccif-realworld`).\n\n";
        md += &crate::realworld::realworld_markdown(&self.realworld);
        md += "\n";

        // communication
        if let Some(mc) = self
            .table2
            .iter()
            .find(|m| m.nodes == 4)
            .or(self.table2.first())
        {
            md += &format!(
                "## Communication ({} observers, floats sent per run)\n\n",
                mc.nodes
            );
            md += "Sensor → estimator: 3 floats per sent measurement. Estimator ↔ estimator: a vector and a symmetric matrix \
                   (7 + 28 floats) per delivered message; diffusion sends two messages per link and step, consensus one per link and \
                   iteration.\n\n| algorithm | sensor → estimator | estimator ↔ estimator | trigger rate |\n|---|---|---|---|\n";
            for v in &mc.variants {
                md += &format!(
                    "| {} | {:.0} | {:.0} | {:.1} % |\n",
                    v.label,
                    v.values_sensor_to_estimator,
                    v.values_estimator_to_estimator,
                    100.0 * v.trigger_rate
                );
            }
            md += "\n";
        }
        if let Some(f) = &self.flights {
            md += &crate::realworld::flights_markdown(f);
            md += "\n";
        }
        md
    }

    fn table2_findings(&self, mc: &McResult, p: &serde_json::Value) -> String {
        let get = |a: Algorithm| mc.variants.iter().find(|v| v.algorithm == a);
        let mut out = String::from("Findings:\n");
        if let (Some(edc), Some(ed)) = (get(Algorithm::EdcCif), get(Algorithm::EdCif)) {
            let better = edc
                .errors
                .rmse_per_variable
                .iter()
                .zip(&ed.errors.rmse_per_variable)
                .filter(|(a, b)| a <= b)
                .count();
            out += &format!(
                "- EDC-CIF vs ED-CIF (CI vs plain combination): EDC-CIF is lower or equal in {better} of 7 variables (pos {:.4} vs {:.4} m).\n",
                edc.errors.pos_rmse, ed.errors.pos_rmse
            );
            let et = [
                Algorithm::EcEkf,
                Algorithm::EcUkf,
                Algorithm::EcCkf,
                Algorithm::DecCkf,
                Algorithm::EdCif,
            ];
            let mut best_all = true;
            let mut max_red: f64 = 0.0;
            for a in et {
                if let Some(b) = get(a) {
                    best_all &= edc
                        .errors
                        .rmse_per_variable
                        .iter()
                        .zip(&b.errors.rmse_per_variable)
                        .take(6)
                        .all(|(x, y)| x <= y);
                    max_red = max_red.max(1.0 - edc.errors.pos_rmse / b.errors.pos_rmse);
                }
            }
            out += &format!(
                "- The paper: EDC-CIF has the lowest RMSE of every ET scheme for every variable. Ours: {} (position and velocity \
                 components). Largest position-RMSE reduction against an ET baseline: {:.1} % (the paper claims up to 66.49 %).\n",
                if best_all { "holds" } else { "does not hold for every variable" },
                100.0 * max_red
            );
        }
        if let (Some(edc), Some(dc)) = (get(Algorithm::EdcCif), get(Algorithm::DcCif)) {
            out += &format!(
                "- Non-ET DC-CIF (every measurement sent) vs EDC-CIF: {:.4} vs {:.4} m position RMSE at {:.0} % of the measurements; ",
                dc.errors.pos_rmse,
                edc.errors.pos_rmse,
                100.0 * edc.trigger_rate
            );
            let ppaper = paper_row(p, "table2_accuracy", mc.nodes, "DC-CIF").zip(paper_row(
                p,
                "table2_accuracy",
                mc.nodes,
                "EDC-CIF",
            ));
            out += &match ppaper {
                Some((a, b)) => format!(
                    "the paper has DC-CIF x-RMSE {:.4} vs EDC-CIF {:.4}, i.e. {}.\n",
                    a[0],
                    b[0],
                    if b[0] <= a[0] {
                        "EDC-CIF as good as or better than sending everything, which we do not reproduce"
                    } else {
                        "the same ordering"
                    }
                ),
                None => "no paper value.\n".into(),
            };
        }
        if let (Some(ekf), Some(ckf)) = (get(Algorithm::EcEkf), get(Algorithm::EcCkf)) {
            out += &format!(
                "- EC-EKF vs EC-CKF: {:.4} vs {:.4} m. The paper reports EC-EKF (and at 3 observers EC-UKF) several times worse; on this \
                 scenario the sensors are 10 m away with 0.01 rad noise, where linearisation loses little, so we do not see that gap.\n",
                ekf.errors.pos_rmse, ckf.errors.pos_rmse
            );
        }
        out + "\n"
    }

    fn table1_findings(&self) -> String {
        let v = &self.table1.variants;
        let pos = |i: usize| v.get(i).map_or(f64::NAN, |x| x.errors.pos_rmse);
        format!(
            "Findings: the paper orders EDC-CIF < w/o diffusion with CI < w/o optimal ET < DEC-CKF in position RMSE. Ours: EDC-CIF {:.4}, \
             w/o optimal ET (hold) {:.4}, w/o diffusion with CI {:.4}, DEC-CKF {:.4} m. {}\n\n",
            pos(0),
            pos(1),
            pos(2),
            pos(3),
            if pos(0) < pos(1) && pos(0) < pos(2) && pos(0) < pos(3) {
                "EDC-CIF is the best of the four, as in the paper."
            } else {
                "EDC-CIF is not the best of the four here, unlike the paper."
            }
        )
    }

    fn delta_findings(&self) -> String {
        let edc: Vec<(f64, f64, f64)> = self
            .delta_sweep
            .iter()
            .map(|p| {
                (
                    p.delta,
                    p.mc.variants[0].errors.pos_rmse,
                    p.mc.variants[0].trigger_rate,
                )
            })
            .collect();
        let rate_falls = edc.windows(2).all(|w| w[1].2 <= w[0].2);
        let err_grows = edc.windows(2).filter(|w| w[1].1 >= w[0].1).count();
        let at004 = edc.iter().find(|e| (e.0 - 0.04).abs() < 1e-12).map(|e| e.2);
        format!(
            "Findings: the trigger rate {} as δ grows; the EDC-CIF position RMSE grows in {} of {} steps of the sweep. At δ = 0.04 our \
             trigger rate is {} (paper 52.31 %).\n\n",
            if rate_falls { "falls monotonically" } else { "does not fall monotonically" },
            err_grows,
            edc.len().saturating_sub(1),
            at004.map_or("–".into(), |r| format!("{:.1} %", 100.0 * r))
        )
    }

    fn sigma_findings(&self) -> String {
        let s1: Vec<f64> = self
            .sigma_sweep
            .iter()
            .filter(|p| p.sigma2 == 5e-4)
            .map(|p| p.mc.variants[0].errors.pos_rmse)
            .collect();
        let s2: Vec<f64> = self
            .sigma_sweep
            .iter()
            .filter(|p| p.sigma1 == 5e-4)
            .map(|p| p.mc.variants[0].errors.pos_rmse)
            .collect();
        let spread = |v: &[f64]| {
            let lo = v.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            if lo > 0.0 {
                hi / lo - 1.0
            } else {
                f64::NAN
            }
        };
        let guards: u64 = self
            .sigma_sweep
            .iter()
            .map(|p| p.mc.variants[0].guard_fallbacks)
            .sum();
        format!(
            "Findings: over the σ1 sweep the position RMSE varies by {:.1} %, over the σ2 sweep by {:.1} %; the paper finds accuracy \
             falling as σ1 grows and insensitivity to σ2. Adaptation-guard fallbacks (ALGORITHM.md §4) over the whole sweep: {guards}.\n\n",
            100.0 * spread(&s1),
            100.0 * spread(&s2)
        )
    }
}
