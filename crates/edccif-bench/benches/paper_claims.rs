//! Checks the paper's headline computation-time claims (Appendix H.B): EDC-CIF
//! reduces the whole-run time of EC-CKF by 47.20 % at N = 4 (1.32 vs 2.50 ms)
//! and by 62.55 % at N = 8 (1.85 vs 4.94 ms).
//!
//! `cargo bench -p edccif-bench --bench paper_claims`: whole 200-step runs of
//! both rows at N = 4 and 8 on the same simulated data, 30 interleaved
//! repetitions each, medians. A plain `main` (no criterion); it reports and never
//! fails on the verdict.

use edccif_bench::paper::{PaperTimes, PAPER_REDUCTIONS};
use edccif_bench::{interleaved_runs, median, reduction, Workload, DEFAULT_SEED};
use edccif_sim::Algorithm;

const REPS: usize = 30;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `cargo bench` passes `--bench`; `cargo test --benches` passes nothing
    // special either way: run a single quick repetition under test.
    let testing = !std::env::args().any(|a| a == "--bench");
    let reps = if testing { 1 } else { REPS };
    let paper = PaperTimes::load();
    let w4 = Workload::paper(4, DEFAULT_SEED)?;
    let w8 = Workload::paper(8, DEFAULT_SEED)?;
    let cases = [
        (Algorithm::EdcCif, &w4),
        (Algorithm::EcCkf, &w4),
        (Algorithm::EdcCif, &w8),
        (Algorithm::EcCkf, &w8),
    ];
    let s = interleaved_runs(&cases, reps, 2)?;
    println!(
        "paper_claims: whole 200-step runs, medians of {reps} interleaved repetitions (seed {DEFAULT_SEED}); paper figures: {}",
        paper.source
    );
    println!(
        "{:>3} {:<5} {:>13} {:>12} {:>10} | {:>10} {:>9} {:>10} | verdict",
        "N",
        "clock",
        "EDC-CIF (ms)",
        "EC-CKF (ms)",
        "reduction",
        "paper EDC",
        "paper EC",
        "paper red."
    );
    for (i, n) in [4usize, 8].into_iter().enumerate() {
        let claimed = PAPER_REDUCTIONS
            .iter()
            .find(|r| r.0 == n)
            .map(|r| r.1)
            .expect("paper figure");
        for (clock, edc, ec) in [
            ("wall", &s[2 * i].wall, &s[2 * i + 1].wall),
            ("cpu", &s[2 * i].cpu, &s[2 * i + 1].cpu),
        ] {
            let (edc, ec) = (median(edc), median(ec));
            let ours = reduction(edc, ec);
            println!(
                "{n:>3} {clock:<5} {:>13.3} {:>12.3} {:>9.2}% | {:>10.2} {:>9.2} {:>9.2}% | {}",
                edc * 1e3,
                ec * 1e3,
                100.0 * ours,
                paper.ms(n, Algorithm::EdcCif).unwrap_or(f64::NAN),
                paper.ms(n, Algorithm::EcCkf).unwrap_or(f64::NAN),
                100.0 * claimed,
                if ours >= claimed {
                    "the paper's reduction holds"
                } else {
                    "the paper's reduction DOES NOT hold"
                }
            );
        }
    }
    Ok(())
}
