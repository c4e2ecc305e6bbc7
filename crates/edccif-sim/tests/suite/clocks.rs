//! Observers that start after the motion capture: the pipeline estimates their
//! clock offsets from the data, and EDC-CIF on the result is as accurate as with
//! the true offsets; the paper's start alignment shifts them by the delay.

use edccif_io::preprocess::{run_pipeline, OffsetSource, PipelineOptions};
use edccif_io::realworld::{generate, PathKind, RawRecording, RealWorldConfig};
use edccif_sim::realworld::{position_rmse, realworld_scenario, TableSettings};
use edccif_sim::{run, Algorithm, RunOptions};

/// 3-D position RMSE (m) of EDC-CIF on a recording preprocessed with `opt`.
fn rmse(raw: &RawRecording, opt: &PipelineOptions) -> (f64, Vec<f64>) {
    let data = run_pipeline(&raw.truth, &raw.observers, opt).unwrap();
    let (sc, x0) = realworld_scenario(&data, &TableSettings::default()).unwrap();
    let r = run(
        Algorithm::EdcCif,
        &sc,
        &data.z,
        &x0,
        &RunOptions::default(),
        false,
    )
    .unwrap();
    let e = position_rmse(&r.estimates, &data.truth, r.steps, r.nodes, r.n);
    (
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt(),
        data.report.clock.offsets_s,
    )
}

#[test]
fn observers_started_half_a_second_late_are_aligned_from_the_data() {
    let frame = 1.0 / 30.0;
    let (mut sum_aligned, mut sum_estimated) = (0.0, 0.0);
    for seed in [1, 2, 3, 4, 5, 6] {
        let mut cfg = RealWorldConfig::new(PathKind::Manual, seed);
        cfg.observer_delay_s = 0.5;
        let raw = generate(&cfg).unwrap();
        let truth: Vec<f64> = raw
            .poses
            .iter()
            .map(|p| raw.mocap_clock_offset_s - p.clock_offset_s)
            .collect();
        // the aligned case: the true offsets given
        let given = PipelineOptions {
            offsets: truth.iter().copied().enumerate().collect(),
            ..PipelineOptions::default()
        };
        let (aligned, _) = rmse(&raw, &given);
        let (estimated, offsets) = rmse(&raw, &PipelineOptions::default());
        let (start, _) = rmse(&raw, &PipelineOptions::paper());
        println!(
            "seed {seed}: 3-D RMSE aligned {:.2} mm, estimated {:.2} mm, start alignment {:.2} mm; \
             offset errors {:?} ms",
            aligned * 1e3,
            estimated * 1e3,
            start * 1e3,
            offsets
                .iter()
                .zip(&truth)
                .map(|(o, t)| ((o - t) * 1e4).round() / 10.0)
                .collect::<Vec<_>>()
        );
        for (o, t) in offsets.iter().zip(&truth) {
            assert!((o - t).abs() < frame, "seed {seed}: {o} vs {t}");
        }
        assert!(
            (estimated - aligned).abs() <= 0.1 * aligned,
            "seed {seed}: {estimated} vs {aligned}"
        );
        assert!(start > 3.0 * aligned, "seed {seed}: start {start}");
        sum_aligned += aligned;
        sum_estimated += estimated;
        // for comparison: the same seed recorded with the starts together
        let together = generate(&RealWorldConfig::new(PathKind::Manual, seed)).unwrap();
        let (paper, _) = rmse(&together, &PipelineOptions::paper());
        println!(
            "seed {seed}: starts together, start alignment {:.2} mm",
            paper * 1e3
        );
    }
    println!(
        "mean 3-D RMSE over 6 seeds: aligned {:.2} mm, estimated {:.2} mm",
        sum_aligned / 6.0 * 1e3,
        sum_estimated / 6.0 * 1e3
    );
    assert!((sum_estimated - sum_aligned).abs() <= 0.03 * sum_aligned);
    // the report says where each offset came from
    let raw = generate(&RealWorldConfig::new(PathKind::Manual, 1)).unwrap();
    let data = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::default()).unwrap();
    assert_eq!(data.report.clock.sources, vec![OffsetSource::Estimated; 3]);
}
