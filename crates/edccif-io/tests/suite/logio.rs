//! TUM round trips, Umeyama, each pre-processing step on crafted data, and the
//! real-world generator through the pipeline. (MCAP: `tests/suite/mcap.rs`.)

use std::path::PathBuf;

use edccif_io::preprocess::{
    align_common_span, associate, common_grid, downsample, interpolate, remove_abnormal_gaps,
    remove_origin_outliers, run_pipeline, spatial_align, umeyama, PipelineOptions, Similarity,
    SpatialOptions, TimeAlign,
};
use edccif_io::realworld::{generate, PathKind, RealWorldConfig};
use edccif_io::{format_tum, parse_tum, read_tum, write_tum, Error, Track};
use nalgebra::{Rotation3, Vector3};

fn temp_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("edccif-logio-{}-{name}", std::process::id()))
}

// ---------------------------------------------------------------- TUM

#[test]
fn tum_round_trip_file() {
    let t = vec![1_700_000_000.033_333_3, 1_700_000_000.066_666_7, 1.0 / 3.0];
    let p = vec![
        [0.1, -2.5e-7, 3.0],
        [1e6, 0.0, -0.3333333333333333],
        [1.0, 2.0, 3.0],
    ];
    let tr = Track::new(t, p).unwrap();
    let q = vec![
        [0.0, 0.0, 0.0, 1.0],
        [0.5, 0.5, 0.5, 0.5],
        [
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
        ],
    ];
    let path = temp_path("round.tum");
    write_tum(&path, &tr, Some(&q)).unwrap();
    let back = read_tum(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(back.track, tr);
    assert_eq!(back.orientations, q);
    // Positions only: identity quaternions.
    let text = format_tum(&tr, None).unwrap();
    assert!(text.starts_with('#'));
    let back = parse_tum(&text).unwrap();
    assert_eq!(back.track, tr);
    assert!(back.orientations.iter().all(|q| *q == [0.0, 0.0, 0.0, 1.0]));
    assert_eq!(back.orientations_flat().len(), 12);
}

#[test]
fn tum_comments_blank_lines_and_errors() {
    let ok = "# header\n\n  0.0 1 2 3 0 0 0 1\n# mid comment\n0.1\t4 5 6 0 0 0 1  \n";
    let tr = parse_tum(ok).unwrap();
    assert_eq!(tr.track.t, vec![0.0, 0.1]);
    assert_eq!(tr.track.p[1], [4.0, 5.0, 6.0]);

    let cases = [
        ("0 1 2 3 0 0 0 1\n0.1 1 2 3 0 0 1\n", "line 2", "found 7"),
        ("# c\n0 1 2 3 0 0 0 1\n0.1 1 2 y 0 0 0 1\n", "line 3", "tz"),
        ("0 1 2 3 0 0 0 2\n", "line 1", "norm"),
        ("0 1 2 inf 0 0 0 1\n", "line 1", "finite"),
        ("0 1 2 3 0 0 0 1 9\n", "line 1", "found 9"),
    ];
    for (text, line, what) in cases {
        let e = parse_tum(text).unwrap_err().to_string();
        assert!(e.contains(line) && e.contains(what), "{e}");
    }
    let path = temp_path("bad.tum");
    std::fs::write(&path, "0 1 2 3 0 0 0 1\nbad\n").unwrap();
    let e = read_tum(&path).unwrap_err().to_string();
    std::fs::remove_file(&path).ok();
    assert!(e.contains("bad.tum") && e.contains("line 2"), "{e}");
    assert!(matches!(
        read_tum(temp_path("missing.tum")),
        Err(Error::Io(_))
    ));
    // Mismatched orientations are a shape error.
    let tr = Track::from_flat(&[0.0], &[1.0, 2.0, 3.0]).unwrap();
    assert!(format_tum(&tr, Some(&[])).is_err());
}

// ---------------------------------------------------------------- Umeyama

fn known_transform(scale: f64) -> Similarity {
    let r = Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::new(0.3, -0.5, 0.8)),
        1.234,
    );
    Similarity {
        rotation: [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[(i, j)])),
        translation: [1.5, -0.25, 3.0],
        scale,
    }
}

fn points() -> Vec<[f64; 3]> {
    (0..50)
        .map(|i| {
            let a = i as f64 * 0.37;
            [a.sin() * 2.0, (1.3 * a).cos(), 0.1 * i as f64 - 1.0]
        })
        .collect()
}

#[test]
fn umeyama_recovers_a_known_transform() {
    let src = points();
    for (scale, with_scale) in [(1.0, false), (1.0, true), (1.7, true), (0.4, true)] {
        let truth = known_transform(scale);
        let dst: Vec<[f64; 3]> = src.iter().map(|p| truth.apply(*p)).collect();
        let s = umeyama(&src, &dst, with_scale).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                assert!((s.rotation[i][j] - truth.rotation[i][j]).abs() < 1e-9);
            }
            assert!((s.translation[i] - truth.translation[i]).abs() < 1e-9);
        }
        assert!((s.scale - scale).abs() < 1e-9);
        // The inverse maps back.
        let back = s.inverse().apply(dst[7]);
        assert!((0..3).all(|c| (back[c] - src[7][c]).abs() < 1e-9));
    }
    // Planar points: still a proper rotation (det +1), no reflection.
    let planar: Vec<[f64; 3]> = src.iter().map(|p| [p[0], p[1], 0.0]).collect();
    let truth = known_transform(1.0);
    let dst: Vec<[f64; 3]> = planar.iter().map(|p| truth.apply(*p)).collect();
    let s = umeyama(&planar, &dst, false).unwrap();
    assert!((0..3).all(|i| (0..3).all(|j| (s.rotation[i][j] - truth.rotation[i][j]).abs() < 1e-9)));
    // Degenerate inputs are errors.
    let line: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 0.0, 0.0]).collect();
    assert!(umeyama(&line, &line, false).is_err());
    assert!(umeyama(&src[..2], &src[..2], false).is_err());
    assert!(umeyama(&src, &src[..10], false).is_err());
}

// ---------------------------------------------------------------- pre-processing steps

fn regular(n: usize, rate: f64, t0: f64) -> Track {
    let t: Vec<f64> = (0..n).map(|j| t0 + j as f64 / rate).collect();
    let p = t
        .iter()
        .map(|t| [t * 0.5, 1.0 + (t * 0.3).sin(), 1.2])
        .collect();
    Track::new(t, p).unwrap()
}

#[test]
fn origin_outliers_are_removed_and_reported() {
    let mut tr = regular(10, 30.0, 0.0);
    tr.p[3] = [0.0; 3];
    tr.p[7] = [0.0, 0.0, 1e-9];
    tr.p[8] = [0.0, 0.0, 1e-3]; // not at the origin
    let (clean, rep) = remove_origin_outliers(&tr, 1e-6);
    assert_eq!(rep.removed, vec![3, 7]);
    assert_eq!(clean.len(), 8);
    assert!(clean.p.iter().all(|p| p.iter().any(|v| v.abs() > 1e-6)));
}

#[test]
fn abnormal_gaps_are_removed_and_ordinary_drops_kept() {
    let base = regular(40, 30.0, 100.0);
    let mut t = base.t.clone();
    let p = base.p.clone();
    let dt = 1.0 / 30.0;
    t[5] += 0.002 - dt; // 5 duplicates 4 (2 ms later): too close
    t[10] -= 0.6; // clock glitch backwards: non-increasing
    t[15] += 0.6; // clock glitch forwards: too late
                  // Frames 20..=21 dropped (a 3-frame gap, kept), frames 26..=32 lost (stall):
                  // frame 33 is the stale frame after the stall, frame 34 is normal again.
    let keep: Vec<bool> = (0..40)
        .map(|j| !(20..=21).contains(&j) && !(26..=32).contains(&j))
        .collect();
    let tr = Track { t, p }.select_public(&keep);
    let (clean, rep) = remove_abnormal_gaps(&tr, 3.5).unwrap();
    assert!((rep.median_dt - dt).abs() < 1e-9);
    assert_eq!((rep.too_close, rep.non_increasing, rep.too_late), (1, 1, 2));
    // Indices into the selected track: 5, 10, 15, and the stale frame 33 → 33 - 2 - 7 = 24.
    assert_eq!(rep.removed, vec![5, 10, 15, 24]);
    clean.check_increasing("clean").unwrap();
    assert_eq!(clean.len(), tr.len() - 4);
    // The sample after the dropped frames (22) is kept.
    assert!(clean
        .t
        .iter()
        .any(|v| (v - (100.0 + 22.0 * dt)).abs() < 1e-9));
    assert!(remove_abnormal_gaps(&tr, 1.0).is_err());
}

trait SelectPublic {
    fn select_public(&self, keep: &[bool]) -> Track;
}
impl SelectPublic for Track {
    fn select_public(&self, keep: &[bool]) -> Track {
        let mut o = Track::default();
        for (j, k) in keep.iter().enumerate() {
            if *k {
                o.t.push(self.t[j]);
                o.p.push(self.p[j]);
            }
        }
        o
    }
}

#[test]
fn common_span_shifts_clocks_and_crops() {
    let a = regular(100, 30.0, 1_700_000_000.0); // observer clock
    let b = regular(400, 120.0, 150.0); // mocap clock, longer
    let c = regular(80, 30.0, 5.0);
    let (out, rep) = align_common_span(
        &[a.clone(), b.clone(), c.clone()],
        TimeAlign::ShiftToFirstSample,
    )
    .unwrap();
    assert_eq!(rep.start, 0.0);
    assert!((rep.end - 79.0 / 30.0).abs() < 1e-9);
    assert_eq!(rep.shifts[1], -150.0);
    assert_eq!(out[2].len(), 80);
    assert_eq!(rep.removed_after[2], 0);
    assert_eq!(rep.removed_after[0], 20);
    assert!(out
        .iter()
        .all(|o| o.t[0] >= rep.start - 1e-6 && *o.t.last().unwrap() <= rep.end + 1e-6));
    // Without shifting, the three clocks do not overlap.
    assert!(align_common_span(&[a, b, c.clone()], TimeAlign::Keep).is_err());
    // Keep mode crops to the overlap.
    let d = regular(60, 30.0, 6.0);
    let (out, rep) = align_common_span(&[c, d], TimeAlign::Keep).unwrap();
    assert_eq!(rep.start, 6.0);
    assert_eq!(rep.removed_before, vec![30, 0]);
    assert_eq!(out[0].t[0], 6.0);
}

#[test]
fn association_and_spatial_alignment_recover_the_frame() {
    let truth = regular(480, 120.0, 0.0);
    // The observer sees the same path at 30 Hz in its own frame.
    let frame = known_transform(1.0);
    let to_cam = frame.inverse();
    let obs_t: Vec<f64> = (0..120).map(|j| j as f64 / 30.0).collect();
    let mut obs_p: Vec<[f64; 3]> = obs_t
        .iter()
        .map(|t| to_cam.apply([t * 0.5, 1.0 + (t * 0.3).sin(), 1.2]))
        .collect();
    obs_p[50] = to_cam.apply([10.0, 10.0, 10.0]); // a gross outlier, trimmed
    let obs = Track::new(obs_t, obs_p).unwrap();
    let pairs = associate(&obs, &truth, 0.005);
    assert_eq!(pairs.len(), 120);
    assert_eq!(pairs[1], (1, 4));
    let late = Track::new(obs.t.iter().map(|t| t + 0.003).collect(), obs.p.clone()).unwrap();
    let pairs = associate(&late, &truth, 0.005);
    assert_eq!((pairs.len(), pairs[1]), (120, (1, 4)));
    assert_eq!(associate(&late, &truth, 0.002).len(), 0);
    let (aligned, rep) = spatial_align(&obs, &truth, &SpatialOptions::default()).unwrap();
    assert_eq!(rep.trimmed, 1);
    for i in 0..3 {
        assert!((rep.transform.translation[i] - frame.translation[i]).abs() < 1e-6);
    }
    assert!(rep.rmse < 1e-3, "{}", rep.rmse);
    let p = aligned.p[10];
    let t = aligned.t[10];
    assert!((p[0] - t * 0.5).abs() < 1e-3);
    // Without a common clock nothing associates.
    let far = Track::new(obs.t.iter().map(|t| t + 100.0).collect(), obs.p.clone()).unwrap();
    assert!(spatial_align(&far, &truth, &SpatialOptions::default()).is_err());
}

#[test]
fn downsampling_keeps_one_sample_per_frame() {
    let truth = regular(481, 120.0, 0.0);
    let (ds, rep) = downsample(&truth, 30.0).unwrap();
    assert_eq!(ds.len(), 121);
    assert_eq!((rep.kept, rep.removed), (121, 360));
    assert!((rep.input_rate_hz - 120.0).abs() < 1e-6);
    for (j, t) in ds.t.iter().enumerate() {
        assert!((t - j as f64 / 30.0).abs() < 1e-9);
    }
    assert!(downsample(&truth, 0.0).is_err());
}

#[test]
fn interpolation_fills_short_gaps_only() {
    let t = vec![0.0, 0.1, 0.2, 0.3, 0.7, 0.8];
    let p = t.iter().map(|t| [2.0 * t, -t, 1.0]).collect();
    let tr = Track::new(t, p).unwrap();
    let grid = common_grid(-0.05, 0.85, 20.0);
    assert_eq!(grid.len(), 19);
    let (out, rep) = interpolate(&tr, &grid, 0.25).unwrap();
    for (g, q) in grid.iter().zip(&out) {
        let inside = (0.0..=0.3).contains(g) || (0.7..=0.8 + 1e-9).contains(g);
        if inside {
            assert!(
                (q[0] - 2.0 * g).abs() < 1e-12 && (q[1] + g).abs() < 1e-12,
                "{g}"
            );
        } else {
            assert!(q.iter().all(|v| v.is_nan()), "{g}");
        }
    }
    assert_eq!(rep.exact + rep.interpolated + rep.missing, 19);
    assert!(rep.missing >= 8); // before 0, 0.35..0.65, after 0.8
                               // With a larger max_gap the gap is filled.
    let (out, rep) = interpolate(&tr, &grid, 0.5).unwrap();
    assert!((out[10][0] - 2.0 * grid[10]).abs() < 1e-12);
    assert!(rep.filled > 0);
    assert_eq!(common_grid(0.0, 1.0, 30.0).len(), 31);
}

#[test]
fn pipeline_on_a_generated_recording() {
    let mut cfg = RealWorldConfig::new(PathKind::Circle, 7);
    cfg.duration_s = 10.0;
    let raw = generate(&cfg).unwrap();
    assert_eq!(raw.observers.len(), 3);
    let data = run_pipeline(&raw.truth, &raw.observers, &PipelineOptions::default()).unwrap();
    assert_eq!(data.nodes, 3);
    assert!((data.dt - 1.0 / 30.0).abs() < 1e-3);
    assert_eq!(data.truth.len(), 3 * data.steps);
    assert_eq!(data.z.len(), 9 * data.steps);
    assert!(data.steps > 280);
    // Camera origins recovered (they are the spatial transforms' translations).
    for (i, pose) in raw.poses.iter().enumerate() {
        for c in 0..3 {
            assert!((data.sensors[3 * i + c] - pose.position[c]).abs() < 0.05);
        }
    }
    // Measurements now in the world frame, close to the truth.
    let mut sq = 0.0;
    let mut cnt = 0.0;
    for t in 0..data.steps {
        for i in 0..3 {
            let z = &data.z[(t * 3 + i) * 3..(t * 3 + i) * 3 + 3];
            let x = &data.truth[t * 3..t * 3 + 3];
            if z[0].is_finite() && x[0].is_finite() {
                sq += (0..3).map(|c| (z[c] - x[c]).powi(2)).sum::<f64>();
                cnt += 1.0;
            }
        }
    }
    let rms = (sq / cnt).sqrt();
    assert!(rms < 0.05, "measurement RMS error {rms}");
    let r = &data.report;
    assert!(
        r.origin
            .iter()
            .skip(1)
            .map(|o| o.removed.len())
            .sum::<usize>()
            > 0
    );
    assert_eq!(r.spatial.len(), 3);
    assert!(r.downsample.removed > 0);
}
