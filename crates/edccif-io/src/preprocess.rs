//! The paper's data pre-processing pipeline (Sec. "Data Pre-processing") as
//! library functions. Each step returns its result and a report of what it
//! removed or changed.
//!
//! In the paper's order, for the ground truth (motion capture) and every
//! observer's measurement track:
//!
//! 1. [`remove_origin_outliers`]: samples at `(0, 0, 0)` (a detector or tracker
//!    that lost the target writes the origin);
//! 2. [`remove_abnormal_gaps`]: samples with abnormal time intervals (clock
//!    glitches, duplicated frames, stale frames after a stall);
//! 3. [`align_common_span`]: each device's clock shifted so that the recordings
//!    start together, then all tracks cropped to the common start and end;
//! 4. [`spatial_align`]: each observer's track brought into the ground-truth frame
//!    by the Umeyama rotation + translation (optionally scale) that best maps it
//!    onto the time-associated truth (what the paper does with evo);
//! 5. [`downsample`]: the ground truth reduced to the observation rate;
//! 6. [`interpolate`]: every track linearly interpolated onto a common time grid
//!    ([`common_grid`]); short gaps (dropped frames) are filled, longer ones and
//!    times outside a track give NaN (a missing measurement for the filters).
//!
//! [`run_pipeline`] chains them and returns the `(T, N, 3)` measurement array the
//! runner consumes.
//!
//! ```
//! use edccif_io::preprocess::{remove_origin_outliers, umeyama};
//! use edccif_io::Track;
//! let tr = Track::new(vec![0.0, 1.0, 2.0], vec![[1.0, 0.0, 0.0], [0.0; 3], [2.0, 0.0, 0.0]]).unwrap();
//! let (clean, rep) = remove_origin_outliers(&tr, 1e-6);
//! assert_eq!((clean.len(), rep.removed.clone()), (2, vec![1]));
//! let src = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
//! let dst: Vec<[f64; 3]> = src.iter().map(|p| [p[0] + 1.0, p[1] - 2.0, p[2]]).collect();
//! let s = umeyama(&src, &dst, false).unwrap();
//! assert!((s.translation[0] - 1.0).abs() < 1e-12 && (s.scale - 1.0).abs() < 1e-12);
//! ```

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::Track;

fn value_err(what: impl Into<String>, problem: impl Into<String>) -> Error {
    Error::Value {
        what: what.into(),
        problem: problem.into(),
    }
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    Some(if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    })
}

/// Median of the positive time steps between consecutive samples (s), if any.
pub fn median_dt(track: &Track) -> Option<f64> {
    let mut d: Vec<f64> = track
        .t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|g| *g > 0.0)
        .collect();
    median(&mut d)
}

// ---------------------------------------------------------------- 1. origin

/// What [`remove_origin_outliers`] removed.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct OriginReport {
    /// Indices (into the input) of the removed samples.
    pub removed: Vec<usize>,
}

/// Removes the samples whose three coordinates are all within `tol` of 0.
pub fn remove_origin_outliers(track: &Track, tol: f64) -> (Track, OriginReport) {
    let keep: Vec<bool> = track
        .p
        .iter()
        .map(|p| p.iter().any(|v| v.abs() > tol))
        .collect();
    let removed = keep
        .iter()
        .enumerate()
        .filter(|(_, k)| !**k)
        .map(|(j, _)| j)
        .collect();
    (track.select(&keep), OriginReport { removed })
}

// ---------------------------------------------------------------- 2. gaps

/// What [`remove_abnormal_gaps`] removed.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct GapReport {
    /// Median time step of the input (s).
    pub median_dt: f64,
    /// Indices (into the input) of the removed samples.
    pub removed: Vec<usize>,
    /// Removed because their time is not after the last kept sample.
    pub non_increasing: usize,
    /// Removed because they follow the last kept sample by less than `median / factor`.
    pub too_close: usize,
    /// Removed because they follow both their predecessor and the last kept sample by
    /// more than `factor × median`.
    pub too_late: usize,
}

/// Removes samples with abnormal time intervals. With `m` the median time step and
/// `g_last`, `g_prev` the time since the last kept sample and since the input
/// predecessor, sample `j > 0` is removed when
///
/// - `g_last ≤ 0` (a clock glitch backwards or an out-of-order sample),
/// - `g_last < m / factor` (a duplicated or bunched frame; the earlier one is kept),
/// - `min(g_prev, g_last) > factor · m` (a clock glitch forwards, or the stale
///   frame delivered after a stall; ordinary dropped frames leave gaps of a few `m`
///   and are kept for [`interpolate`] to fill).
///
/// The first sample is always kept. `factor > 1` (e.g. 3.5).
pub fn remove_abnormal_gaps(track: &Track, factor: f64) -> Result<(Track, GapReport)> {
    if !(factor.is_finite() && factor > 1.0) {
        return Err(value_err(
            "gap factor",
            format!("must be finite and > 1, got {factor}"),
        ));
    }
    let mut rep = GapReport::default();
    let Some(m) = median_dt(track) else {
        return Ok((track.clone(), rep));
    };
    rep.median_dt = m;
    let mut keep = vec![true; track.len()];
    let mut last = track.t[0];
    for (j, kj) in keep.iter_mut().enumerate().skip(1) {
        let g_last = track.t[j] - last;
        let g_prev = track.t[j] - track.t[j - 1];
        if g_last <= 0.0 {
            rep.non_increasing += 1;
        } else if g_last < m / factor {
            rep.too_close += 1;
        } else if g_prev.min(g_last) > factor * m {
            rep.too_late += 1;
        } else {
            last = track.t[j];
            continue;
        }
        *kj = false;
        rep.removed.push(j);
    }
    Ok((track.select(&keep), rep))
}

// ---------------------------------------------------------------- 3. time span

/// How [`align_common_span`] treats the devices' clocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TimeAlign {
    /// Clocks are already synchronised: only crop to the common span.
    Keep,
    /// The recordings started together: shift each track so that its first sample
    /// is at time 0 (removes per-device clock offsets), then crop.
    #[default]
    ShiftToFirstSample,
}

/// What [`align_common_span`] changed.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SpanReport {
    /// Shift added to each track's timestamps (s).
    pub shifts: Vec<f64>,
    /// Common start (s, after the shifts).
    pub start: f64,
    /// Common end (s, after the shifts).
    pub end: f64,
    /// Samples of each track cropped before the common start.
    pub removed_before: Vec<usize>,
    /// Samples of each track cropped after the common end.
    pub removed_after: Vec<usize>,
}

/// Tolerance (s) of the span crop: epoch timestamps (~1.7e9 s) carry about
/// 2.4e-7 s of rounding, which must not crop a sample at the common end.
const SPAN_EPS: f64 = 1e-6;

/// Aligns the tracks' clocks (see [`TimeAlign`]) and crops every track to the
/// common span `[max first time, min last time]` (within 1 µs). Tracks must be
/// non-empty with increasing timestamps.
pub fn align_common_span(tracks: &[Track], mode: TimeAlign) -> Result<(Vec<Track>, SpanReport)> {
    if tracks.is_empty() {
        return Err(value_err("tracks", "at least one track is needed"));
    }
    for (i, tr) in tracks.iter().enumerate() {
        if tr.is_empty() {
            return Err(value_err(format!("track {i}"), "is empty"));
        }
        tr.check_increasing(&format!("track {i}"))?;
    }
    let shifts: Vec<f64> = tracks
        .iter()
        .map(|tr| match mode {
            TimeAlign::Keep => 0.0,
            TimeAlign::ShiftToFirstSample => -tr.t[0],
        })
        .collect();
    let start = tracks
        .iter()
        .zip(&shifts)
        .map(|(tr, s)| tr.t[0] + s)
        .fold(f64::NEG_INFINITY, f64::max);
    let end = tracks
        .iter()
        .zip(&shifts)
        .map(|(tr, s)| tr.t[tr.len() - 1] + s)
        .fold(f64::INFINITY, f64::min);
    if end <= start {
        return Err(value_err(
            "tracks",
            format!("have no common time span (latest start {start} s, earliest end {end} s)"),
        ));
    }
    let mut rep = SpanReport {
        shifts: shifts.clone(),
        start,
        end,
        ..Default::default()
    };
    let mut out = Vec::with_capacity(tracks.len());
    for (tr, s) in tracks.iter().zip(&shifts) {
        let mut o = Track::default();
        let (mut before, mut after) = (0, 0);
        for (t, p) in tr.t.iter().zip(&tr.p) {
            let ts = t + s;
            if ts < start - SPAN_EPS {
                before += 1;
            } else if ts > end + SPAN_EPS {
                after += 1;
            } else {
                o.t.push(ts);
                o.p.push(*p);
            }
        }
        rep.removed_before.push(before);
        rep.removed_after.push(after);
        out.push(o);
    }
    Ok((out, rep))
}

// ---------------------------------------------------------------- 4. Umeyama

/// A similarity transform `p ↦ s R p + t`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Similarity {
    /// Rotation `R`, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Translation `t`.
    pub translation: [f64; 3],
    /// Scale `s` (1 without scale estimation).
    pub scale: f64,
}

impl Default for Similarity {
    fn default() -> Self {
        Self {
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [0.0; 3],
            scale: 1.0,
        }
    }
}

impl Similarity {
    fn r(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.rotation[i][j])
    }

    /// `s R p + t`.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let q = self.r() * Vector3::from(p) * self.scale + Vector3::from(self.translation);
        [q[0], q[1], q[2]]
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Similarity {
        let rt = self.r().transpose();
        let t = -(rt * Vector3::from(self.translation)) / self.scale;
        Similarity {
            rotation: [0, 1, 2].map(|i| [0, 1, 2].map(|j| rt[(i, j)])),
            translation: [t[0], t[1], t[2]],
            scale: 1.0 / self.scale,
        }
    }
}

/// The least-squares similarity (Umeyama 1991) mapping `src[j]` onto `dst[j]`:
/// rotation and translation, and the scale when `with_scale` (else 1). Needs at
/// least 3 pairs not all on one line.
pub fn umeyama(src: &[[f64; 3]], dst: &[[f64; 3]], with_scale: bool) -> Result<Similarity> {
    if src.len() != dst.len() {
        return Err(Error::Shape {
            what: "umeyama dst".into(),
            expected: format!("({}, 3)", src.len()),
            got: format!("({}, 3)", dst.len()),
        });
    }
    let n = src.len();
    if n < 3 {
        return Err(value_err(
            "umeyama",
            format!("needs at least 3 point pairs, got {n}"),
        ));
    }
    if src
        .iter()
        .chain(dst)
        .any(|p| p.iter().any(|v| !v.is_finite()))
    {
        return Err(value_err("umeyama", "points must be finite"));
    }
    let nf = n as f64;
    let mean = |pts: &[[f64; 3]]| {
        pts.iter()
            .fold(Vector3::zeros(), |a, p| a + Vector3::from(*p))
            / nf
    };
    let (ms, md) = (mean(src), mean(dst));
    let mut cov = Matrix3::<f64>::zeros();
    let mut var_s = 0.0;
    for (s, d) in src.iter().zip(dst) {
        let (a, b) = (Vector3::from(*s) - ms, Vector3::from(*d) - md);
        cov += b * a.transpose();
        var_s += a.norm_squared();
    }
    cov /= nf;
    var_s /= nf;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(value_err("umeyama", "SVD did not converge"));
    };
    let mut sv = svd.singular_values;
    // Sort is not guaranteed by nalgebra: find the smallest singular value.
    let smallest = (0..3).min_by(|&a, &b| sv[a].total_cmp(&sv[b])).unwrap_or(2);
    let mut mid = sv;
    mid[smallest] = f64::INFINITY;
    let second = (0..3)
        .min_by(|&a, &b| mid[a].total_cmp(&mid[b]))
        .unwrap_or(1);
    if var_s <= 0.0 || sv[second] <= 1e-12 * sv.max().max(f64::MIN_POSITIVE) {
        return Err(value_err(
            "umeyama",
            "the source points are degenerate (all on one point or line)",
        ));
    }
    let mut s_diag = Vector3::new(1.0, 1.0, 1.0);
    if u.determinant() * v_t.determinant() < 0.0 {
        s_diag[smallest] = -1.0;
    }
    let r = u * Matrix3::from_diagonal(&s_diag) * v_t;
    for i in 0..3 {
        sv[i] *= s_diag[i];
    }
    let scale = if with_scale { sv.sum() / var_s } else { 1.0 };
    let t = md - r * ms * scale;
    Ok(Similarity {
        rotation: [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[(i, j)])),
        translation: [t[0], t[1], t[2]],
        scale,
    })
}

/// Pairs `(i, j)` of samples of `a` and `b` (increasing timestamps) whose times
/// differ by at most `max_dt`: for each sample of `a` the nearest of `b`.
pub fn associate(a: &Track, b: &Track, max_dt: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    if b.is_empty() {
        return out;
    }
    let mut j = 0;
    for (i, t) in a.t.iter().enumerate() {
        while j + 1 < b.len() && b.t[j + 1] <= *t {
            j += 1;
        }
        let best = if j + 1 < b.len() && (b.t[j + 1] - t).abs() < (t - b.t[j]).abs() {
            j + 1
        } else {
            j
        };
        if (b.t[best] - t).abs() <= max_dt {
            out.push((i, best));
        }
    }
    out
}

/// Options of [`spatial_align`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpatialOptions {
    /// Estimate a scale too (Sim(3)); else rotation + translation (SE(3)).
    pub with_scale: bool,
    /// Largest time difference of an associated pair (s).
    pub max_dt: f64,
    /// After a first fit, refit without the pairs whose residual exceeds
    /// `trim_factor ×` the median residual (robust to spurious measurements).
    pub trim_factor: Option<f64>,
}

impl Default for SpatialOptions {
    fn default() -> Self {
        Self {
            with_scale: false,
            max_dt: 0.01,
            trim_factor: Some(4.0),
        }
    }
}

/// What [`spatial_align`] found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpatialReport {
    /// The transform applied to the track.
    pub transform: Similarity,
    /// Associated pairs.
    pub pairs: usize,
    /// Pairs left out of the final fit by the trimming.
    pub trimmed: usize,
    /// RMS of the residual norm over the pairs of the final fit (m).
    pub rmse: f64,
    /// RMS residual per axis over the pairs of the final fit (m): an estimate of
    /// the measurement noise in the reference frame.
    pub residual_rms: [f64; 3],
}

/// Brings `track` into the frame of `reference`: associates samples by time,
/// fits [`umeyama`] (optionally trimmed), and applies the transform to every
/// sample of `track`.
pub fn spatial_align(
    track: &Track,
    reference: &Track,
    opt: &SpatialOptions,
) -> Result<(Track, SpatialReport)> {
    let pairs = associate(track, reference, opt.max_dt);
    if pairs.len() < 3 {
        return Err(value_err(
            "spatial alignment",
            format!(
                "only {} samples have a reference sample within {} s (3 needed); are the clocks aligned?",
                pairs.len(),
                opt.max_dt
            ),
        ));
    }
    let src: Vec<[f64; 3]> = pairs.iter().map(|(i, _)| track.p[*i]).collect();
    let dst: Vec<[f64; 3]> = pairs.iter().map(|(_, j)| reference.p[*j]).collect();
    let residuals = |s: &Similarity, idx: &[usize]| -> Vec<[f64; 3]> {
        idx.iter()
            .map(|&k| {
                let q = s.apply(src[k]);
                [q[0] - dst[k][0], q[1] - dst[k][1], q[2] - dst[k][2]]
            })
            .collect()
    };
    let all: Vec<usize> = (0..pairs.len()).collect();
    let mut sim = umeyama(&src, &dst, opt.with_scale)?;
    let mut used = all.clone();
    if let Some(f) = opt.trim_factor {
        let res = residuals(&sim, &all);
        let norms: Vec<f64> = res
            .iter()
            .map(|r| (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt())
            .collect();
        let med = median(&mut norms.clone()).unwrap_or(0.0);
        let keep: Vec<usize> = all
            .iter()
            .copied()
            .filter(|&k| norms[k] <= f * med)
            .collect();
        if keep.len() >= 3 && keep.len() < all.len() {
            let s2: Vec<[f64; 3]> = keep.iter().map(|&k| src[k]).collect();
            let d2: Vec<[f64; 3]> = keep.iter().map(|&k| dst[k]).collect();
            sim = umeyama(&s2, &d2, opt.with_scale)?;
            used = keep;
        }
    }
    let res = residuals(&sim, &used);
    let m = res.len() as f64;
    let mut axis = [0.0; 3];
    for r in &res {
        for c in 0..3 {
            axis[c] += r[c] * r[c];
        }
    }
    let rmse = ((axis[0] + axis[1] + axis[2]) / m).sqrt();
    let residual_rms = axis.map(|v| (v / m).sqrt());
    let out = Track {
        t: track.t.clone(),
        p: track.p.iter().map(|p| sim.apply(*p)).collect(),
    };
    Ok((
        out,
        SpatialReport {
            transform: sim,
            pairs: pairs.len(),
            trimmed: pairs.len() - used.len(),
            rmse,
            residual_rms,
        },
    ))
}

// ---------------------------------------------------------------- 5. downsample

/// What [`downsample`] did.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DownsampleReport {
    /// Median input rate (Hz).
    pub input_rate_hz: f64,
    /// Target rate (Hz).
    pub rate_hz: f64,
    /// Samples kept.
    pub kept: usize,
    /// Samples removed.
    pub removed: usize,
}

/// Keeps, for each time of the grid `t₀ + j / rate_hz` over the track's span, the
/// sample nearest to it (each sample at most once).
pub fn downsample(track: &Track, rate_hz: f64) -> Result<(Track, DownsampleReport)> {
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(value_err(
            "downsample rate",
            format!("must be finite and > 0, got {rate_hz}"),
        ));
    }
    track.check_increasing("downsampled track")?;
    let mut rep = DownsampleReport {
        input_rate_hz: median_dt(track).map_or(0.0, |m| 1.0 / m),
        rate_hz,
        ..Default::default()
    };
    if track.is_empty() {
        return Ok((track.clone(), rep));
    }
    let grid = common_grid(track.t[0], track.t[track.len() - 1], rate_hz);
    let mut keep = vec![false; track.len()];
    let mut j = 0;
    for g in grid {
        while j + 1 < track.len() && track.t[j + 1] <= g {
            j += 1;
        }
        let best = if j + 1 < track.len() && (track.t[j + 1] - g).abs() < (g - track.t[j]).abs() {
            j + 1
        } else {
            j
        };
        keep[best] = true;
    }
    let out = track.select(&keep);
    rep.kept = out.len();
    rep.removed = track.len() - out.len();
    Ok((out, rep))
}

// ---------------------------------------------------------------- 6. interpolate

/// The grid `start + j / rate_hz`, `j = 0, 1, …` up to `end` (inclusive within 1e-9 s).
pub fn common_grid(start: f64, end: f64, rate_hz: f64) -> Vec<f64> {
    if !(start.is_finite() && end.is_finite() && rate_hz > 0.0) || end < start {
        return Vec::new();
    }
    let count = ((end - start) * rate_hz + 1e-9).floor() as usize + 1;
    (0..count).map(|j| start + j as f64 / rate_hz).collect()
}

/// What [`interpolate`] did.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct InterpReport {
    /// Grid times that coincide with a sample (within 1 µs).
    pub exact: usize,
    /// Grid times interpolated between two samples.
    pub interpolated: usize,
    /// Grid times interpolated across a gap longer than one median step (filled
    /// dropped frames; included in `interpolated`).
    pub filled: usize,
    /// Grid times left NaN: outside the track or inside a gap longer than `max_gap`.
    pub missing: usize,
}

/// Linear interpolation of `track` (increasing timestamps) at the `grid` times.
/// Grid times outside the track, or between two samples more than `max_gap` s
/// apart, give NaN.
pub fn interpolate(
    track: &Track,
    grid: &[f64],
    max_gap: f64,
) -> Result<(Vec<[f64; 3]>, InterpReport)> {
    track.check_increasing("interpolated track")?;
    let mut rep = InterpReport::default();
    let step = median_dt(track).unwrap_or(f64::INFINITY);
    let mut out = Vec::with_capacity(grid.len());
    let n = track.len();
    let mut j = 0;
    const EPS: f64 = 1e-6;
    for &g in grid {
        if n == 0 || g < track.t[0] - EPS || g > track.t[n - 1] + EPS {
            out.push([f64::NAN; 3]);
            rep.missing += 1;
            continue;
        }
        while j + 1 < n && track.t[j + 1] <= g {
            j += 1;
        }
        if (g - track.t[j]).abs() <= EPS {
            out.push(track.p[j]);
            rep.exact += 1;
            continue;
        }
        if j + 1 < n && (track.t[j + 1] - g).abs() <= EPS {
            out.push(track.p[j + 1]);
            rep.exact += 1;
            continue;
        }
        if j + 1 >= n || g < track.t[j] {
            out.push([f64::NAN; 3]);
            rep.missing += 1;
            continue;
        }
        let (t0, t1) = (track.t[j], track.t[j + 1]);
        let gap = t1 - t0;
        if gap > max_gap {
            out.push([f64::NAN; 3]);
            rep.missing += 1;
            continue;
        }
        let a = (g - t0) / gap;
        let (p0, p1) = (track.p[j], track.p[j + 1]);
        out.push([0, 1, 2].map(|c| p0[c] + a * (p1[c] - p0[c])));
        rep.interpolated += 1;
        if gap > 1.5 * step {
            rep.filled += 1;
        }
    }
    Ok((out, rep))
}

// ---------------------------------------------------------------- pipeline

/// Options of [`run_pipeline`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PipelineOptions {
    /// `factor` of [`remove_abnormal_gaps`].
    pub gap_factor: f64,
    /// `tol` of [`remove_origin_outliers`] (m).
    pub origin_tol: f64,
    /// Clock handling of [`align_common_span`].
    pub time_align: TimeAlign,
    /// Spatial alignment of each observer onto the truth; `None`: the observers'
    /// tracks are already in the truth's frame.
    pub spatial: Option<SpatialOptions>,
    /// Common frame rate (Hz); `None`: the median rate of the observers.
    pub rate_hz: Option<f64>,
    /// `max_gap` of [`interpolate`] (s): longer gaps stay missing.
    pub max_gap_s: f64,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        Self {
            gap_factor: 3.5,
            origin_tol: 1e-6,
            time_align: TimeAlign::ShiftToFirstSample,
            spatial: Some(SpatialOptions::default()),
            rate_hz: None,
            max_gap_s: 0.25,
        }
    }
}

/// Everything the pipeline did, per track (index 0: the truth, then observers).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PipelineReport {
    /// Step 1, per track.
    pub origin: Vec<OriginReport>,
    /// Step 2, per track.
    pub gaps: Vec<GapReport>,
    /// Step 3.
    pub span: SpanReport,
    /// Step 4, per observer (empty without spatial alignment).
    pub spatial: Vec<SpatialReport>,
    /// Step 5 (the truth).
    pub downsample: DownsampleReport,
    /// Step 6, per track.
    pub interp: Vec<InterpReport>,
    /// The common frame rate (Hz).
    pub rate_hz: f64,
}

/// The pipeline's output, ready for the runner. Arrays are flat, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct AlignedData {
    /// Frame period `1 / rate` (s).
    pub dt: f64,
    /// `T`.
    pub steps: usize,
    /// `N` observers.
    pub nodes: usize,
    /// Grid times `(T,)` (s, in the aligned clock).
    pub t: Vec<f64>,
    /// Truth positions `(T, 3)`; NaN rows where the truth is missing.
    pub truth: Vec<f64>,
    /// Measurements in the truth's frame `(T, N, 3)`; NaN rows where missing.
    pub z: Vec<f64>,
    /// Each observer's origin in the truth's frame `(N, 3)` (the translation of
    /// its spatial alignment; zeros without spatial alignment).
    pub sensors: Vec<f64>,
    /// Pooled per-axis RMS of the spatial-alignment residuals (m): an estimate of
    /// the measurement noise (`None` without spatial alignment).
    pub noise_rms: Option<[f64; 3]>,
    /// What each step did.
    pub report: PipelineReport,
}

/// Runs the whole pipeline on a ground-truth track and the observers' tracks
/// (each in its own clock and, with spatial alignment, its own frame).
pub fn run_pipeline(
    truth: &Track,
    observers: &[Track],
    opt: &PipelineOptions,
) -> Result<AlignedData> {
    if observers.is_empty() {
        return Err(value_err(
            "observers",
            "at least one observer track is needed",
        ));
    }
    let mut rep = PipelineReport::default();
    let mut tracks = Vec::with_capacity(observers.len() + 1);
    for (i, tr) in std::iter::once(truth).chain(observers).enumerate() {
        let name = if i == 0 {
            "truth".to_string()
        } else {
            format!("observer {}", i - 1)
        };
        let (a, o) = remove_origin_outliers(tr, opt.origin_tol);
        let (b, g) = remove_abnormal_gaps(&a, opt.gap_factor)?;
        if b.len() < 2 {
            return Err(value_err(
                name,
                format!("has {} usable samples after outlier removal", b.len()),
            ));
        }
        rep.origin.push(o);
        rep.gaps.push(g);
        tracks.push(b);
    }
    let (tracks, span) = align_common_span(&tracks, opt.time_align)?;
    rep.span = span;
    let (truth, mut obs) = (tracks[0].clone(), tracks[1..].to_vec());
    let mut noise_rms = None;
    let mut sensors = vec![0.0; 3 * obs.len()];
    if let Some(sp) = &opt.spatial {
        let mut acc = [0.0; 3];
        let mut count = 0.0;
        for (i, o) in obs.iter_mut().enumerate() {
            let (aligned, r) = spatial_align(o, &truth, sp).map_err(|e| match e {
                Error::Value { what, problem } => Error::Value {
                    what: format!("{what} of observer {i}"),
                    problem,
                },
                other => other,
            })?;
            *o = aligned;
            let used = (r.pairs - r.trimmed) as f64;
            for (a, r) in acc.iter_mut().zip(r.residual_rms) {
                *a += r * r * used;
            }
            count += used;
            sensors[3 * i..3 * i + 3].copy_from_slice(&r.transform.translation);
            rep.spatial.push(r);
        }
        noise_rms = Some(acc.map(|v| (v / count).sqrt()));
    }
    let rate = match opt.rate_hz {
        Some(r) if r.is_finite() && r > 0.0 => r,
        Some(r) => {
            return Err(value_err(
                "rate_hz",
                format!("must be finite and > 0, got {r}"),
            ))
        }
        None => {
            let mut m: Vec<f64> = obs.iter().filter_map(median_dt).collect();
            let md = median(&mut m).ok_or_else(|| value_err("observers", "have no time steps"))?;
            1.0 / md
        }
    };
    rep.rate_hz = rate;
    let (truth_ds, ds) = downsample(&truth, rate)?;
    rep.downsample = ds;
    let grid = common_grid(rep.span.start, rep.span.end, rate);
    let t_len = grid.len();
    let k = obs.len();
    let (tp, ti) = interpolate(&truth_ds, &grid, opt.max_gap_s)?;
    rep.interp.push(ti);
    let mut z = vec![f64::NAN; t_len * k * 3];
    for (i, o) in obs.iter().enumerate() {
        let (zp, zi) = interpolate(o, &grid, opt.max_gap_s)?;
        rep.interp.push(zi);
        for (t, p) in zp.iter().enumerate() {
            z[(t * k + i) * 3..(t * k + i) * 3 + 3].copy_from_slice(p);
        }
    }
    Ok(AlignedData {
        dt: 1.0 / rate,
        steps: t_len,
        nodes: k,
        t: grid,
        truth: tp.iter().flatten().copied().collect(),
        z,
        sensors,
        noise_rms,
        report: rep,
    })
}
