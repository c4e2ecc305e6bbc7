//! The paper's computation-time figures: Table III (whole-run time `t_com` in
//! ms for N = 3, 4, 8 observers, eight rows) and the DEC-CKF time of Table I
//! (N = 4 only; Table III has no DEC-CKF column).
//!
//! [`PaperTimes::load`] reads them from `crates/edccif-sim/data/paper_tables.json`
//! when that file exists (the project's machine-readable transcription of the
//! paper's tables), and otherwise falls back to [`PaperTimes::embedded`], the
//! same numbers transcribed here from the appendix text
//! (`edc-cif-appendix.txt`, Table III and Table I).

use std::path::{Path, PathBuf};

use edccif_sim::Algorithm;
use serde_json::Value;

/// The paper's headline reductions of EDC-CIF against EC-CKF, `(N, 1 − t_edc/t_ecckf)`
/// as stated in the appendix text (Appendix H.B).
pub const PAPER_REDUCTIONS: [(usize, f64); 3] = [(3, 0.3043), (4, 0.4720), (8, 0.6255)];

/// Table III of the appendix as printed: `(N, row, ms)`.
const TABLE3_MS: [(usize, Algorithm, f64); 24] = {
    use Algorithm::*;
    [
        (3, CCkf, 1.28),
        (3, DCif, 0.97),
        (3, DcCif, 0.99),
        (3, EcEkf, 1.20),
        (3, EcUkf, 1.39),
        (3, EcCkf, 1.38),
        (3, EdCif, 0.98),
        (3, EdcCif, 0.96),
        (4, CCkf, 2.37),
        (4, DCif, 1.33),
        (4, DcCif, 1.54),
        (4, EcEkf, 2.22),
        (4, EcUkf, 2.24),
        (4, EcCkf, 2.50),
        (4, EdCif, 1.37),
        (4, EdcCif, 1.32),
        (8, CCkf, 4.69),
        (8, DCif, 2.09),
        (8, DcCif, 2.56),
        (8, EcEkf, 2.97),
        (8, EcUkf, 3.77),
        (8, EcCkf, 4.94),
        (8, EdCif, 2.19),
        (8, EdcCif, 1.85),
    ]
};

/// Table I (ablations at N = 4): DEC-CKF's time.
const TABLE1_DEC_CKF_MS: f64 = 2.47;

/// The paper's whole-run computation times.
#[derive(Debug, Clone, PartialEq)]
pub struct PaperTimes {
    /// Where the numbers came from (a file path or "embedded transcription …").
    pub source: String,
    /// `(N, row, milliseconds)`.
    pub entries: Vec<(usize, Algorithm, f64)>,
}

impl PaperTimes {
    /// The numbers transcribed from the appendix text.
    ///
    /// ```
    /// use edccif_bench::paper::PaperTimes;
    /// use edccif_sim::Algorithm;
    /// let p = PaperTimes::embedded();
    /// assert_eq!(p.ms(4, Algorithm::EdcCif), Some(1.32));
    /// assert_eq!(p.ms(4, Algorithm::DecCkf), Some(2.47));
    /// assert_eq!(p.ms(8, Algorithm::DecCkf), None);
    /// ```
    pub fn embedded() -> Self {
        let mut entries = TABLE3_MS.to_vec();
        entries.push((4, Algorithm::DecCkf, TABLE1_DEC_CKF_MS));
        Self {
            source: "embedded transcription of the appendix (Table III; DEC-CKF from Table I)"
                .into(),
            entries,
        }
    }

    /// The default location of the project's transcription of the paper's tables.
    pub fn default_json_path() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../edccif-sim/data/paper_tables.json")
    }

    /// Reads [`default_json_path`](Self::default_json_path) when it exists and
    /// holds the computation times; otherwise [`embedded`](Self::embedded).
    pub fn load() -> Self {
        let path = Self::default_json_path();
        match std::fs::read_to_string(&path) {
            Ok(text) => match Self::from_json_str(&text) {
                Some(mut p) => {
                    p.source = path.canonicalize().unwrap_or(path).display().to_string();
                    p
                }
                None => {
                    let mut p = Self::embedded();
                    p.source = format!(
                        "{} (no computation times found in {})",
                        p.source,
                        path.display()
                    );
                    p
                }
            },
            Err(_) => Self::embedded(),
        }
    }

    /// Extracts the computation times from the JSON transcription of the
    /// paper's tables; `None` when none are found.
    pub fn from_json_str(text: &str) -> Option<Self> {
        let v: Value = serde_json::from_str(text).ok()?;
        let mut entries = Vec::new();
        collect_times(&v, &mut entries);
        if entries.is_empty() {
            None
        } else {
            Some(Self {
                source: "json".into(),
                entries,
            })
        }
    }

    /// The paper's time in ms of `alg` with `nodes` observers, if published.
    pub fn ms(&self, nodes: usize, alg: Algorithm) -> Option<f64> {
        self.entries
            .iter()
            .find(|(n, a, _)| *n == nodes && *a == alg)
            .map(|e| e.2)
    }

    /// The paper's reduction of EDC-CIF against EC-CKF at `nodes` observers,
    /// from its table entries.
    pub fn reduction(&self, nodes: usize) -> Option<f64> {
        Some(crate::reduction(
            self.ms(nodes, Algorithm::EdcCif)?,
            self.ms(nodes, Algorithm::EcCkf)?,
        ))
    }
}

/// Reads the schema of `crates/edccif-sim/data/README.md` (schema_version 1):
/// `tables.table3_time.by_nodes[N][row] = ms`, and from
/// `tables.table1_ablation` the rows whose `row_info.algorithm_row` names an
/// algorithm row (DEC-CKF) with their `t_com` column, at `nodes` (4 when the
/// table leaves it null, as its `nodes_note` infers).
fn collect_times(v: &Value, out: &mut Vec<(usize, Algorithm, f64)>) {
    let tables = &v["tables"];
    if let Some(by_nodes) = tables["table3_time"]["by_nodes"].as_object() {
        for (n, rows) in by_nodes {
            let (Ok(n), Some(rows)) = (n.parse::<usize>(), rows.as_object()) else {
                continue;
            };
            for (name, ms) in rows {
                if let (Ok(alg), Some(ms)) = (name.parse::<Algorithm>(), ms.as_f64()) {
                    out.push((n, alg, ms));
                }
            }
        }
    }
    let t1 = &tables["table1_ablation"];
    let col = t1["columns"]
        .as_array()
        .and_then(|c| c.iter().position(|c| c == "t_com"));
    let nodes = t1["nodes"].as_u64().map_or(4, |n| n as usize);
    if let (Some(col), Some(rows)) = (col, t1["rows"].as_object()) {
        for (key, vals) in rows {
            let alg = t1["row_info"][key]["algorithm_row"]
                .as_str()
                .and_then(|a| a.parse::<Algorithm>().ok());
            if let (Some(alg), Some(ms)) = (alg, vals[col].as_f64()) {
                if !out.iter().any(|e| e.0 == nodes && e.1 == alg) {
                    out.push((nodes, alg, ms));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_matches_the_project_transcription() {
        let path = PaperTimes::default_json_path();
        let Ok(text) = std::fs::read_to_string(&path) else {
            return; // the transcription is optional
        };
        let json = PaperTimes::from_json_str(&text).expect("computation times in the JSON");
        let emb = PaperTimes::embedded();
        assert_eq!(json.entries.len(), emb.entries.len());
        for (n, alg, ms) in &emb.entries {
            assert_eq!(json.ms(*n, *alg), Some(*ms), "N = {n}, {alg}");
        }
    }

    #[test]
    fn paper_reductions_follow_from_the_table() {
        let p = PaperTimes::embedded();
        for (n, r) in PAPER_REDUCTIONS {
            assert!((p.reduction(n).unwrap() - r).abs() < 5e-5, "N = {n}");
        }
    }
}
