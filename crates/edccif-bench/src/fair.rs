//! Table III, fair: EDC-CIF against EC-CKF with the adequate number of consensus
//! iterations `L` and with fixed small `L`, whole runs timed side by side, with
//! the spread of the repetitions and a per-iteration cost model.
//!
//! The consensus rows cost `t(L) ≈ a + L·b` per node-step: `a` the local CKF
//! step with the conversions around the fusion, `b` one consensus iteration.
//! EDC-CIF's node-step `d` has no `L`. From two measured `L` of EC-CKF,
//! [`IterationModel`] gives `a`, `b` and the break-even `L* = (d − a) / b` above
//! which EDC-CIF is the cheaper row.
//!
//! ```
//! use edccif_bench::fair::{measure, render};
//! use edccif_bench::config::Config;
//! let cases = measure(&[3], &[1, 2], 2, 0, 7, &Config::library_default()).unwrap();
//! assert_eq!(cases[0].rows.len(), 4); // EDC-CIF, EC-CKF (adequate), L = 1, L = 2
//! assert!(render(&cases).contains("EC-CKF (L = 2)"));
//! ```

use edccif_sim::Algorithm;
use serde_json::{json, Map, Value};

use crate::config::Config;
use crate::paper::{PaperTimes, PAPER_REDUCTIONS};
use crate::{
    interleaved_rows, median, reduction, trigger_rate_row, Result, Row, Samples, Spread, Workload,
};

/// The measurements of one network size.
#[derive(Debug, Clone)]
pub struct FairCase {
    /// Number of nodes.
    pub nodes: usize,
    /// Steps per run.
    pub steps: usize,
    /// The scenario's adequate `L`.
    pub adequate_l: usize,
    /// The rows, EDC-CIF first, then EC-CKF (adequate), then EC-CKF with the fixed `L`s.
    pub rows: Vec<Row>,
    /// Seconds per whole run, one [`Samples`] per row.
    pub samples: Vec<Samples>,
    /// Trigger rate of each row's run.
    pub trigger_rate: Vec<f64>,
}

impl FairCase {
    fn index(&self, row: Row) -> Option<usize> {
        self.rows.iter().position(|r| *r == row)
    }

    /// Median CPU seconds per run of `row`.
    pub fn cpu(&self, row: Row) -> Option<f64> {
        self.index(row).map(|i| median(&self.samples[i].cpu))
    }

    /// Median wall seconds per run of `row`.
    pub fn wall(&self, row: Row) -> Option<f64> {
        self.index(row).map(|i| median(&self.samples[i].wall))
    }

    /// The `L` a row runs with.
    pub fn iterations(&self, row: Row) -> usize {
        row.iters.unwrap_or(self.adequate_l)
    }

    /// The per-iteration model of EC-CKF from the CPU medians.
    pub fn model(&self) -> Option<IterationModel> {
        let ec: Vec<(usize, f64)> = self
            .rows
            .iter()
            .filter(|r| r.alg == Algorithm::EcCkf)
            .map(|r| (self.iterations(*r), self.cpu(*r).expect("row")))
            .collect();
        let lo = ec.iter().min_by_key(|p| p.0)?;
        let hi = ec.iter().max_by_key(|p| p.0)?;
        let per = (self.steps * self.nodes) as f64;
        let d = self.cpu(Row::new(Algorithm::EdcCif))? / per;
        IterationModel::from_two(*lo, *hi, per, d)
    }
}

/// `t(L) = a + L·b` per node-step of EC-CKF, against EDC-CIF's `d`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IterationModel {
    /// Seconds per node-step outside the iterations.
    pub a: f64,
    /// Seconds per node and consensus iteration.
    pub b: f64,
    /// EDC-CIF's seconds per node-step.
    pub d: f64,
    /// The two `L` the model was fitted on.
    pub fitted_on: (usize, usize),
}

impl IterationModel {
    /// The model through `(L_lo, t_lo)` and `(L_hi, t_hi)` (seconds per run;
    /// `per`: node-steps per run); `None` when the two `L` are equal.
    ///
    /// ```
    /// use edccif_bench::fair::IterationModel;
    /// let m = IterationModel::from_two((1, 12.0), (5, 20.0), 2.0, 9.0).unwrap();
    /// assert_eq!((m.a, m.b), (5.0, 1.0));
    /// assert_eq!(m.break_even(), 4.0);
    /// ```
    pub fn from_two(lo: (usize, f64), hi: (usize, f64), per: f64, d: f64) -> Option<Self> {
        if hi.0 <= lo.0 {
            return None;
        }
        let b = (hi.1 - lo.1) / per / (hi.0 - lo.0) as f64;
        let a = lo.1 / per - lo.0 as f64 * b;
        Some(Self {
            a,
            b,
            d,
            fitted_on: (lo.0, hi.0),
        })
    }

    /// `L*` at which EC-CKF costs what EDC-CIF does.
    pub fn break_even(&self) -> f64 {
        (self.d - self.a) / self.b
    }
}

/// Times whole runs of EDC-CIF, EC-CKF (adequate `L`) and EC-CKF with each
/// `fixed` `L`, on the default scenario with `nodes` nodes on a ring (seed
/// `seed`) in the configuration `config`: all cases of all sizes interleaved,
/// `reps` repetitions after `warmup` untimed passes.
pub fn measure(
    nodes: &[usize],
    fixed: &[usize],
    reps: usize,
    warmup: usize,
    seed: u64,
    config: &Config,
) -> Result<Vec<FairCase>> {
    let mut rows = vec![Row::new(Algorithm::EdcCif), Row::new(Algorithm::EcCkf)];
    rows.extend(fixed.iter().map(|&l| Row::fixed(Algorithm::EcCkf, l)));
    let workloads = nodes
        .iter()
        .map(|&n| {
            Workload::paper(n, seed).map(|mut w| {
                config.apply(&mut w.scenario);
                w
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let cases: Vec<(Row, &Workload)> = workloads
        .iter()
        .flat_map(|w| rows.iter().map(move |r| (*r, w)))
        .collect();
    let samples = interleaved_rows(&cases, reps, warmup, None)?;
    workloads
        .iter()
        .enumerate()
        .map(|(k, w)| {
            Ok(FairCase {
                nodes: w.nodes(),
                steps: w.steps(),
                adequate_l: w.scenario.consensus_iterations()?,
                rows: rows.clone(),
                samples: samples[k * rows.len()..(k + 1) * rows.len()].to_vec(),
                trigger_rate: rows
                    .iter()
                    .map(|r| trigger_rate_row(*r, w))
                    .collect::<Result<_>>()?,
            })
        })
        .collect()
}

/// The raw samples and medians as JSON:
/// `{"nodes": {"4": {"adequate_l": 5, "rows": {"ec-ckf@L1": {"wall_s": […], "cpu_s": […], …}}}}}`.
pub fn to_json(cases: &[FairCase]) -> Value {
    let mut nodes = Map::new();
    for c in cases {
        let mut rows = Map::new();
        for (i, r) in c.rows.iter().enumerate() {
            rows.insert(
                r.to_string(),
                json!({
                    "label": r.label(),
                    "iterations": c.iterations(*r),
                    "trigger_rate": c.trigger_rate[i],
                    "wall_s": c.samples[i].wall,
                    "cpu_s": c.samples[i].cpu,
                    "wall": Spread::of(&c.samples[i].wall).to_json(),
                    "cpu": Spread::of(&c.samples[i].cpu).to_json(),
                }),
            );
        }
        let model = c.model().map(|m| {
            json!({"a_s": m.a, "b_s": m.b, "d_s": m.d, "break_even_l": m.break_even(),
                   "fitted_on": [m.fitted_on.0, m.fitted_on.1]})
        });
        nodes.insert(
            c.nodes.to_string(),
            json!({"steps": c.steps, "adequate_l": c.adequate_l, "rows": rows,
                   "per_node_step_model_cpu": model}),
        );
    }
    json!({ "nodes": nodes })
}

/// The comparison as text: per size, every row's median whole-run time on both
/// clocks with its interquartile range, µs per node-step, the reduction of
/// EDC-CIF against the row, the paper's reduction, and the iteration model.
pub fn render(cases: &[FairCase]) -> String {
    let paper = PaperTimes::load();
    let mut out = String::new();
    let mut line = |s: String| {
        out.push_str(&s);
        out.push('\n');
    };
    let reps = cases.first().map_or(0, |c| c.samples[0].cpu.len());
    line(format!(
        "Table III, fair: whole {}-step runs, medians [interquartile range] of {reps} interleaved repetitions, one thread.",
        cases.first().map_or(0, |c| c.steps)
    ));
    line(
        "EDC-CIF vs = 1 - t(EDC-CIF)/t(row) on the CPU clock; EC-CKF runs with the adequate L and with fixed small L."
            .into(),
    );
    for c in cases {
        let edc = Row::new(Algorithm::EdcCif);
        let claimed = PAPER_REDUCTIONS
            .iter()
            .find(|r| r.0 == c.nodes)
            .map(|r| r.1)
            .or_else(|| paper.reduction(c.nodes));
        line(String::new());
        line(format!(
            "N = {} (ring, adequate L = {}){}",
            c.nodes,
            c.adequate_l,
            claimed.map_or(String::new(), |p| format!(
                "; paper: EDC-CIF {:.2}% below EC-CKF",
                100.0 * p
            ))
        ));
        line(format!(
            "{:<16} {:>4} {:>26} {:>26} {:>9} {:>6} {:>13}",
            "row", "L", "wall ms [IQR]", "cpu ms [IQR]", "us/n-step", "TR", "EDC-CIF vs"
        ));
        let per = (c.steps * c.nodes) as f64;
        for (i, r) in c.rows.iter().enumerate() {
            let (w, p) = (
                Spread::of(&c.samples[i].wall).scaled(1e3),
                Spread::of(&c.samples[i].cpu).scaled(1e3),
            );
            let vs = if *r == edc {
                "-".to_string()
            } else {
                format!(
                    "{:.1}%",
                    100.0 * reduction(c.cpu(edc).expect("edc"), c.cpu(*r).expect("row"))
                )
            };
            line(format!(
                "{:<16} {:>4} {:>8.3} [{:>7.3}-{:>7.3}] {:>8.3} [{:>7.3}-{:>7.3}] {:>9.2} {:>5.1}% {:>13}",
                r.label(),
                if r.is_consensus() { c.iterations(*r).to_string() } else { "-".into() },
                w.median,
                w.q1,
                w.q3,
                p.median,
                p.q1,
                p.q3,
                p.median * 1e3 / per,
                100.0 * c.trigger_rate[i],
                vs
            ));
        }
        match c.model() {
            Some(m) if m.b > 0.0 => {
            line(format!(
                "cost model (cpu, per node-step, fitted on L = {} and {}): EC-CKF = {:.3} us + L x {:.3} us per iteration; EDC-CIF = {:.3} us;",
                m.fitted_on.0,
                m.fitted_on.1,
                m.a * 1e6,
                m.b * 1e6,
                m.d * 1e6
            ));
            line(format!(
                "  one consensus iteration = {:.0}% of an EDC-CIF node-step; EDC-CIF is the cheaper row for L > {:.1} (adequate L here: {}).",
                100.0 * m.b / m.d,
                m.break_even(),
                c.adequate_l
            ));
            }
            Some(m) => line(format!(
                "cost model (cpu, fitted on L = {} and {}): the iterations' cost is below the timing noise here; see the instruction counts.",
                m.fitted_on.0, m.fitted_on.1
            )),
            None => {}
        }
    }
    out
}
