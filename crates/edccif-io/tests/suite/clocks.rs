//! Clocks in the preprocessing pipeline: the offset applied to each stream is
//! reported, estimated from the data instead of assuming common starts, given
//! per observer when known, and a residual that exceeds a stated multiple of the
//! observer's noise is warned about. Repeated stamps are dropped and counted, or
//! refused before any work.

use edccif_io::preprocess::{
    estimate_offset, noise_from_scatter, run_pipeline, DuplicateStamps, OffsetSource,
    PipelineOptions, SpatialOptions, TimeAlign,
};
use edccif_io::realworld::{generate, generate_following, PathKind, RawRecording, RealWorldConfig};
use edccif_io::Track;

/// A generated recording (the manual path, 20 s) whose observers start `delay` s
/// after the motion capture.
fn recording(seed: u64, delay: f64) -> RawRecording {
    let mut cfg = RealWorldConfig::new(PathKind::Manual, seed);
    cfg.duration_s = 20.0;
    cfg.observer_delay_s = delay;
    generate(&cfg).unwrap()
}

/// The true offset of observer i: `t_truth = t_observer + offset`.
fn true_offset(raw: &RawRecording, i: usize) -> f64 {
    raw.mocap_clock_offset_s - raw.poses[i].clock_offset_s
}

#[test]
fn the_offset_is_estimated_within_a_frame_when_the_starts_differ() {
    let frame = 1.0 / 30.0;
    for seed in [1, 2, 3] {
        let raw = recording(seed, 0.5);
        let opt = PipelineOptions::default();
        assert_eq!(opt.time_align, TimeAlign::Estimate);
        let data = run_pipeline(&raw.truth, &raw.observers, &opt).unwrap();
        let c = &data.report.clock;
        assert_eq!(c.align, "estimate");
        assert_eq!(c.sources, vec![OffsetSource::Estimated; 3]);
        assert!(c.warnings.is_empty(), "{:?}", c.warnings);
        for i in 0..3 {
            let truth = true_offset(&raw, i);
            let err = c.offsets_s[i] - truth;
            println!(
                "seed {seed} observer {i}: estimated {:.4} s, true {truth:.4} s (error {:.1} ms), \
                 start alignment {:.4} s; residual {:.1} mm, noise {:.1} mm",
                c.offsets_s[i],
                err * 1e3,
                c.start_offsets_s[i],
                c.residual_m[i] * 1e3,
                c.noise_m[i] * 1e3
            );
            assert!(err.abs() < frame, "seed {seed} observer {i}: {err}");
            // the start alignment is about 0.5 s off
            assert!((c.start_offsets_s[i] - truth + 0.5).abs() < 0.01);
            assert!(c.residual_m[i] < opt.residual_factor * c.noise_m[i]);
            // the shift of observer i puts it on the truth's clock, truth at 0
            assert!((c.shifts[i + 1] - (c.offsets_s[i] + c.shifts[0])).abs() < 1e-9);
        }
    }
}

#[test]
fn the_start_alignment_of_late_observers_is_warned_about() {
    let raw = recording(1, 0.5);
    let data = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::paper()).unwrap();
    let c = &data.report.clock;
    assert_eq!(c.sources, vec![OffsetSource::Start; 3]);
    println!(
        "start alignment: residual {:?} mm, noise {:?} mm",
        c.residual_m.iter().map(|r| r * 1e3).collect::<Vec<_>>(),
        c.noise_m.iter().map(|r| r * 1e3).collect::<Vec<_>>()
    );
    assert_eq!(c.warnings.len(), 3, "{:?}", c.warnings);
    for (i, w) in c.warnings.iter().enumerate() {
        println!("{w}");
        assert!(
            w.starts_with(&format!("observer {i}: the alignment residual")),
            "{w}"
        );
        assert!(
            w.contains("more than 3 ×") && w.contains("--align estimate"),
            "{w}"
        );
        assert!(c.residual_m[i] > 3.0 * c.noise_m[i]);
    }
    // With the starts together, the start alignment is right and quiet.
    let raw = recording(1, 0.0);
    let data = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::paper()).unwrap();
    assert!(data.report.clock.warnings.is_empty());
}

#[test]
fn given_offsets_override_the_mode_and_are_reported() {
    let raw = recording(2, 0.5);
    let given = true_offset(&raw, 1);
    let opt = PipelineOptions {
        time_align: TimeAlign::ShiftToFirstSample,
        offsets: vec![(1, given)],
        ..PipelineOptions::default()
    };
    let data = run_pipeline(&raw.truth, &raw.observers, &opt).unwrap();
    let c = &data.report.clock;
    assert_eq!(
        c.sources,
        vec![
            OffsetSource::Start,
            OffsetSource::Given,
            OffsetSource::Start
        ]
    );
    assert_eq!(c.offsets_s[1], given);
    // only the observers left to the start alignment are warned about
    assert_eq!(c.warnings.len(), 2, "{:?}", c.warnings);
    assert!(c.warnings.iter().all(|w| !w.starts_with("observer 1")));
    // `none`: the truth's own clock, observers shifted by their offsets only
    let opt = PipelineOptions {
        time_align: TimeAlign::Keep,
        offsets: (0..3).map(|i| (i, true_offset(&raw, i))).collect(),
        ..PipelineOptions::default()
    };
    let data = run_pipeline(&raw.truth, &raw.observers, &opt).unwrap();
    assert_eq!(data.report.clock.shifts[0], 0.0);
    assert!(data.report.clock.warnings.is_empty());
    assert!(data.t[0] > 100.0, "the truth's clock: {}", data.t[0]);
    // bad offsets are refused, naming the observer
    for (offsets, want) in [
        (
            vec![(3, 0.1)],
            "offset of observer 3: there are 3 observers",
        ),
        (vec![(0, f64::NAN)], "offset of observer 0: must be finite"),
    ] {
        let opt = PipelineOptions {
            offsets,
            ..PipelineOptions::default()
        };
        let e = run_pipeline(&raw.truth, &raw.observers, &opt)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with(want), "{e}");
    }
}

#[test]
fn the_estimate_needs_overlap_and_says_so() {
    let raw = recording(3, 0.0);
    // a truth of 2 s cannot hold half of a 20 s observer
    let short = Track::new(raw.truth.t[..240].to_vec(), raw.truth.p[..240].to_vec()).unwrap();
    let mut obs = raw.observers[0].clone();
    // clean stamps for the direct call (the pipeline removes the glitches first)
    let keep: Vec<usize> = (1..obs.len())
        .filter(|&j| obs.t[j] > obs.t[j - 1])
        .collect();
    obs = Track::new(
        keep.iter().map(|&j| obs.t[j]).collect(),
        keep.iter().map(|&j| obs.p[j]).collect(),
    )
    .unwrap();
    let e = estimate_offset(
        &obs,
        &short,
        short.t[0] - obs.t[0],
        2.0,
        Some(&SpatialOptions::default()),
        0.25,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("cannot be estimated") && e.contains("give the offset"),
        "{e}"
    );
    // the noise estimate of a camera track: millimetres, not the motion
    let s = noise_from_scatter(&obs).unwrap();
    let norm = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
    assert!(norm > 0.002 && norm < 0.05, "{s:?}");
}

#[test]
fn repeated_stamps_are_dropped_and_counted_or_refused_first() {
    let raw = recording(4, 0.0);
    let mut obs = raw.observers.clone();
    // observer 2 repeats three stamps (a logger that wrote the frame twice)
    for j in [100, 200, 300] {
        let (t, p) = (obs[2].t[j], obs[2].p[j]);
        obs[2].t.insert(j + 1, t);
        obs[2].p.insert(j + 1, p);
    }
    let data = run_pipeline(&raw.truth, &obs, &PipelineOptions::paper()).unwrap();
    let dups: Vec<usize> = data.report.duplicates.iter().map(|d| d.dropped).collect();
    assert_eq!(dups, vec![0, 0, 0, 3]);
    // the same data as without the repeats
    let clean = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::paper()).unwrap();
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&data.z), bits(&clean.z));
    // refused, naming the stream and the sample, before any other check
    let opt = PipelineOptions {
        duplicates: DuplicateStamps::Refuse,
        ..PipelineOptions::paper()
    };
    let e = run_pipeline(&raw.truth, &obs, &opt)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("observer 2: t[101]"), "{e}");
    assert!(e.contains("3 duplicated stamp(s)"), "{e}");
}

#[test]
fn the_paper_pipeline_is_the_start_alignment_bit_for_bit() {
    // PipelineOptions::paper keeps the shifts the paper's pipeline applied:
    // every track's first sample at 0.
    let raw = recording(5, 0.0);
    let data = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::paper()).unwrap();
    let c = &data.report.clock;
    assert_eq!(c.align, "start");
    assert_eq!(c.shifts[0], -raw.truth.t[0]);
    assert_eq!(data.report.span.shifts, c.shifts);
    for (i, o) in raw.observers.iter().enumerate() {
        assert_eq!(c.shifts[i + 1], -o.t[0]);
    }
    for (name, mode) in [
        ("none", TimeAlign::Keep),
        ("start", TimeAlign::ShiftToFirstSample),
        ("estimate", TimeAlign::Estimate),
    ] {
        assert_eq!(name.parse::<TimeAlign>().unwrap(), mode);
        assert_eq!(mode.name(), name);
    }
    assert!("first".parse::<TimeAlign>().is_err());
}

#[test]
fn a_path_that_time_only_moves_rigidly_keeps_the_start_alignment_and_says_so() {
    // A helix: a shift in time is a rotation about its axis plus a translation
    // along it, which the spatial fit absorbs; the residual cannot tell.
    let t: Vec<f64> = (0..=2400).map(|j| 1000.0 + j as f64 / 120.0).collect();
    let p = t
        .iter()
        .map(|&s| {
            let a = 0.5 * (s - 1000.0);
            [a.cos(), a.sin(), 1.0 + 0.02 * (s - 1000.0)]
        })
        .collect();
    let helix = Track::new(t, p).unwrap();
    let raw = generate_following(&RealWorldConfig::new(PathKind::Manual, 4), &helix).unwrap();
    let data = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::default()).unwrap();
    let c = &data.report.clock;
    assert_eq!(c.sources, vec![OffsetSource::Start; 3]);
    assert!(c.spreads_s.iter().all(|s| *s > 1.0), "{:?}", c.spreads_s);
    assert_eq!(c.warnings.len(), 3, "{:?}", c.warnings);
    assert!(
        c.warnings[0].contains("do not determine its clock offset"),
        "{}",
        c.warnings[0]
    );
    // the start alignment kept is the paper's, bit for bit
    let paper = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::paper()).unwrap();
    assert_eq!(paper.report.clock.shifts, c.shifts);
    // where the data determine it, the spread is a few frames
    let raw = recording(1, 0.5);
    let data = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::default()).unwrap();
    assert!(
        data.report.clock.spreads_s.iter().all(|s| *s < 0.15),
        "{:?}",
        data.report.clock.spreads_s
    );
}

/// Counts like `edccif_sim::control::Control`, and cancels itself once `stop_at`
/// units are done.
struct Counter {
    done: std::sync::atomic::AtomicU64,
    total: std::sync::atomic::AtomicU64,
    totals_declared: std::sync::atomic::AtomicU64,
    stop_at: u64,
}

impl Counter {
    fn new(stop_at: u64) -> Self {
        use std::sync::atomic::AtomicU64;
        Counter {
            done: AtomicU64::new(0),
            total: AtomicU64::new(0),
            totals_declared: AtomicU64::new(0),
            stop_at,
        }
    }
    fn get(&self) -> (u64, u64) {
        use std::sync::atomic::Ordering::Relaxed;
        (self.done.load(Relaxed), self.total.load(Relaxed))
    }
}

impl edccif_io::watch::Watch for Counter {
    fn add_total(&self, n: u64) {
        use std::sync::atomic::Ordering::Relaxed;
        self.total.fetch_add(n, Relaxed);
        self.totals_declared.fetch_add(1, Relaxed);
    }
    fn advance(&self, n: u64) {
        self.done.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    }
    fn is_cancelled(&self) -> bool {
        self.get().0 >= self.stop_at
    }
}

#[test]
fn the_watched_pipeline_counts_its_work_to_the_total_and_gives_the_same_answer() {
    use edccif_io::preprocess::{offset_grid_len, run_pipeline_watched};
    let raw = recording(1, 0.5);
    for opt in [PipelineOptions::default(), PipelineOptions::paper()] {
        let c = Counter::new(u64::MAX);
        let watched = run_pipeline_watched(&raw.truth, &raw.observers, &opt, &c).unwrap();
        let plain = run_pipeline(&raw.truth, &raw.observers, &opt).unwrap();
        // Bit for bit (the arrays hold NaN where data are missing: compare the bits).
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(bits(&watched.z) == bits(&plain.z) && bits(&watched.truth) == bits(&plain.truth));
        assert!(bits(&watched.t) == bits(&plain.t) && watched.dt.to_bits() == plain.dt.to_bits());
        assert!(format!("{:?}", watched.report) == format!("{:?}", plain.report));
        let (done, total) = c.get();
        assert_eq!(done, total);
        assert_eq!(
            c.totals_declared.load(std::sync::atomic::Ordering::Relaxed),
            1
        );
        // 3 observers: clock (1 each, + the offset grid when estimated),
        // spatial (1 each), downsampling (1), interpolation (4 tracks).
        let grids: u64 = if opt.time_align == TimeAlign::Estimate {
            // On the cleaned tracks, as the pipeline runs it.
            use edccif_io::preprocess::{
                drop_duplicate_stamps, remove_abnormal_gaps, remove_origin_outliers,
            };
            raw.observers
                .iter()
                .map(|o| {
                    let (d, _) = drop_duplicate_stamps(o);
                    let (a, _) = remove_origin_outliers(&d, opt.origin_tol);
                    let (b, _) = remove_abnormal_gaps(&a, opt.gap_factor).unwrap();
                    offset_grid_len(&b, opt.offset_window_s).unwrap()
                })
                .sum()
        } else {
            0
        };
        println!("{:?}: {total} units", opt.time_align);
        assert_eq!(total, grids + 3 + 3 + 1 + 4);
    }
}

#[test]
fn a_cancelled_pipeline_stops_with_interrupted() {
    use edccif_io::preprocess::run_pipeline_watched;
    let raw = recording(1, 0.5);
    for stop_at in [0, 1, 50, 200] {
        let c = Counter::new(stop_at);
        let e = run_pipeline_watched(&raw.truth, &raw.observers, &PipelineOptions::default(), &c)
            .unwrap_err();
        assert_eq!(e, edccif_io::Error::Interrupted);
        assert_eq!(
            c.get().0,
            stop_at,
            "it stops at the first check after the cancel"
        );
    }
}
