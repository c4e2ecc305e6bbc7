//! The paper's data pre-processing pipeline (Sec. "Data Pre-processing") as
//! library functions. Each step returns its result and a report of what it
//! removed or changed.
//!
//! In the paper's order, for the ground truth (motion capture) and every
//! observer's measurement track:
//!
//! 0. [`drop_duplicate_stamps`]: a sample whose timestamp repeats the one before
//!    it is dropped and counted, or the input refused before any work
//!    ([`DuplicateStamps`]);
//! 1. [`remove_origin_outliers`]: samples at `(0, 0, 0)` (a detector or tracker
//!    that lost the target writes the origin);
//! 2. [`remove_abnormal_gaps`]: samples with abnormal time intervals (clock
//!    glitches, duplicated frames, stale frames after a stall);
//! 3. [`clock_offsets`] and [`align_common_span`]: each observer's clock offset
//!    against the truth's ([`TimeAlign`]: none, the recordings' starts, or
//!    estimated from the data by [`estimate_offset`]; or given per observer),
//!    reported with the alignment residual and a warning when that residual
//!    exceeds a stated multiple of the observer's noise; then all tracks cropped
//!    to the common start and end;
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

use std::str::FromStr;

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::watch::{Unwatched, Watch};
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

// ---------------------------------------------------------------- 0. duplicates

/// What happens to a sample whose timestamp repeats the one before it.
///
/// ```
/// use edccif_io::preprocess::DuplicateStamps;
/// assert_eq!("refuse".parse::<DuplicateStamps>().unwrap(), DuplicateStamps::Refuse);
/// assert!("keep".parse::<DuplicateStamps>().is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DuplicateStamps {
    /// Drop the repeat (the first sample with that stamp is kept) and count it.
    #[default]
    Drop,
    /// Refuse the input, naming the stream, the sample and the stamp, before
    /// any work runs.
    Refuse,
}

impl FromStr for DuplicateStamps {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "drop" => Ok(DuplicateStamps::Drop),
            "refuse" => Ok(DuplicateStamps::Refuse),
            _ => Err(Error::UnknownOption {
                name: format!("duplicates={s}"),
                expected: "one of drop, refuse".into(),
            }),
        }
    }
}

/// What [`drop_duplicate_stamps`] removed.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DuplicateReport {
    /// Samples dropped because their stamp repeats the previous sample's.
    pub dropped: usize,
    /// Their indices in the input.
    pub removed: Vec<usize>,
}

/// Drops every sample whose timestamp equals the previous sample's (the first
/// is kept). Other disorder (stamps going backwards) is left to
/// [`remove_abnormal_gaps`].
///
/// ```
/// use edccif_io::preprocess::drop_duplicate_stamps;
/// use edccif_io::Track;
/// let tr = Track::new(vec![0.0, 1.0, 1.0, 2.0], vec![[1.0; 3], [2.0; 3], [9.0; 3], [3.0; 3]]).unwrap();
/// let (out, rep) = drop_duplicate_stamps(&tr);
/// assert_eq!((out.t, rep.dropped, rep.removed), (vec![0.0, 1.0, 2.0], 1, vec![2]));
/// ```
pub fn drop_duplicate_stamps(track: &Track) -> (Track, DuplicateReport) {
    let keep: Vec<bool> = (0..track.len())
        .map(|j| j == 0 || track.t[j] != track.t[j - 1])
        .collect();
    let removed: Vec<usize> = keep
        .iter()
        .enumerate()
        .filter(|(_, k)| !**k)
        .map(|(j, _)| j)
        .collect();
    (
        track.select(&keep),
        DuplicateReport {
            dropped: removed.len(),
            removed,
        },
    )
}

/// Errors when a timestamp of `track` repeats the one before it, naming
/// `what`, the first such sample and the number of them.
///
/// ```
/// use edccif_io::preprocess::check_duplicate_stamps;
/// use edccif_io::Track;
/// let tr = Track::new(vec![0.0, 1.0, 1.0], vec![[1.0; 3]; 3]).unwrap();
/// let e = check_duplicate_stamps(&tr, "truth").unwrap_err().to_string();
/// assert!(e.contains("truth") && e.contains("t[2] = 1"), "{e}");
/// ```
pub fn check_duplicate_stamps(track: &Track, what: &str) -> Result<()> {
    let (_, rep) = drop_duplicate_stamps(track);
    match rep.removed.first() {
        None => Ok(()),
        Some(&j) => Err(value_err(
            what,
            format!(
                "t[{j}] = {} repeats t[{}]; {} duplicated stamp(s) in all (expected strictly \
                 increasing stamps; drop them with duplicates=drop)",
                track.t[j],
                j - 1,
                rep.dropped
            ),
        )),
    }
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

/// How the devices' clocks are aligned ([`clock_offsets`], [`align_common_span`]);
/// names `none`, `start`, `estimate` (command line `--align`).
///
/// ```
/// use edccif_io::preprocess::TimeAlign;
/// assert_eq!("estimate".parse::<TimeAlign>().unwrap(), TimeAlign::Estimate);
/// assert_eq!("start".parse::<TimeAlign>().unwrap(), TimeAlign::ShiftToFirstSample);
/// assert_eq!(TimeAlign::Keep.name(), "none");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TimeAlign {
    /// Clocks are already synchronised (`none`): only crop to the common span.
    #[serde(alias = "none")]
    Keep,
    /// The recordings started together (`start`, the paper's assumption): shift
    /// each track so that its first sample is at time 0, then crop.
    #[serde(alias = "start")]
    ShiftToFirstSample,
    /// Each observer's offset against the truth estimated from the data
    /// (`estimate`, [`estimate_offset`]): the alignment residual minimised over
    /// the offset within a window around the start alignment.
    #[default]
    Estimate,
}

impl TimeAlign {
    /// `none`, `start` or `estimate`.
    pub fn name(self) -> &'static str {
        match self {
            TimeAlign::Keep => "none",
            TimeAlign::ShiftToFirstSample => "start",
            TimeAlign::Estimate => "estimate",
        }
    }
}

impl FromStr for TimeAlign {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "none" | "keep" => Ok(TimeAlign::Keep),
            "start" | "shift-to-first-sample" => Ok(TimeAlign::ShiftToFirstSample),
            "estimate" => Ok(TimeAlign::Estimate),
            _ => Err(Error::UnknownOption {
                name: format!("align={s}"),
                expected: "one of none, start, estimate".into(),
            }),
        }
    }
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

fn check_tracks(tracks: &[Track]) -> Result<()> {
    if tracks.is_empty() {
        return Err(value_err("tracks", "at least one track is needed"));
    }
    for (i, tr) in tracks.iter().enumerate() {
        if tr.is_empty() {
            return Err(value_err(format!("track {i}"), "is empty"));
        }
        tr.check_increasing(&format!("track {i}"))?;
    }
    Ok(())
}

/// Aligns the tracks' clocks (see [`TimeAlign`]; with `Estimate`, track 0 is the
/// reference and the others' offsets are estimated with the default spatial
/// alignment, as [`clock_offsets`] with [`PipelineOptions::default`]) and crops
/// every track to the common span `[max first time, min last time]` (within
/// 1 µs). Tracks must be non-empty with increasing timestamps.
pub fn align_common_span(tracks: &[Track], mode: TimeAlign) -> Result<(Vec<Track>, SpanReport)> {
    check_tracks(tracks)?;
    let shifts: Vec<f64> = match mode {
        TimeAlign::Keep => vec![0.0; tracks.len()],
        TimeAlign::ShiftToFirstSample => tracks.iter().map(|tr| -tr.t[0]).collect(),
        TimeAlign::Estimate => {
            let opt = PipelineOptions::default();
            clock_offsets(&tracks[0], &tracks[1..], &opt)?.shifts
        }
    };
    crop_common_span(tracks, &shifts)
}

/// Adds `shifts[i]` to every timestamp of track `i` and crops every track to the
/// common span `[max first time, min last time]` (within 1 µs). Tracks must be
/// non-empty with increasing timestamps.
pub fn crop_common_span(tracks: &[Track], shifts: &[f64]) -> Result<(Vec<Track>, SpanReport)> {
    check_tracks(tracks)?;
    if shifts.len() != tracks.len() {
        return Err(Error::Shape {
            what: "clock shifts".into(),
            expected: format!("({},)", tracks.len()),
            got: format!("({},)", shifts.len()),
        });
    }
    if let Some(i) = shifts.iter().position(|v| !v.is_finite()) {
        return Err(value_err(
            format!("clock shift of track {i}"),
            format!("must be finite, got {}", shifts[i]),
        ));
    }
    let shifts = shifts.to_vec();
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

// ---------------------------------------------------------------- clocks

/// Where an observer's clock offset came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OffsetSource {
    /// [`TimeAlign::Keep`]: the clocks are taken as synchronised.
    None,
    /// [`TimeAlign::ShiftToFirstSample`]: the recordings' first samples.
    Start,
    /// [`TimeAlign::Estimate`]: estimated from the data ([`estimate_offset`]).
    Estimated,
    /// Given by the caller ([`PipelineOptions::offsets`]).
    Given,
}

/// What [`clock_offsets`] applied to each stream and how well it fits.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ClockReport {
    /// The alignment mode (`none`, `start`, `estimate`).
    pub align: String,
    /// Seconds added to each track's timestamps (the truth first, then the
    /// observers): the aligned clock.
    pub shifts: Vec<f64>,
    /// Per observer: its clock's offset against the truth's (s),
    /// `t_truth = t_observer + offset`.
    pub offsets_s: Vec<f64>,
    /// Per observer: the offset the start alignment would apply (s), for
    /// comparison.
    pub start_offsets_s: Vec<f64>,
    /// Per observer: where its offset came from (`start` also where the
    /// estimate was not determined by the data, with a warning).
    pub sources: Vec<OffsetSource>,
    /// Per observer: the spread of the estimate ([`OffsetEstimate::spread_s`]);
    /// NaN where nothing was estimated.
    pub spreads_s: Vec<f64>,
    /// Per observer: RMS alignment residual at the applied offset (m), see
    /// [`alignment_residual`]; NaN where too few samples overlap the truth.
    pub residual_m: Vec<f64>,
    /// Per observer: its noise (m, RMS over the three axes) estimated from its
    /// own samples ([`noise_from_scatter`]); NaN when it has too few regular
    /// samples.
    pub noise_m: Vec<f64>,
    /// The stated multiple: a residual above `residual_factor × noise` is
    /// warned about.
    pub residual_factor: f64,
    /// The warnings (also printed by the command line).
    pub warnings: Vec<String>,
}

/// Point pairs: `(observer positions, truth positions)`.
type Pairs = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// Pairs of an observer's samples (shifted by `offset`) and the truth
/// interpolated at their times.
fn pairs_at(observer: &Track, truth: &Track, offset: f64, max_gap: f64) -> Result<Pairs> {
    let times: Vec<f64> = observer.t.iter().map(|t| t + offset).collect();
    let (tp, _) = interpolate(truth, &times, max_gap)?;
    let mut src = Vec::with_capacity(tp.len());
    let mut dst = Vec::with_capacity(tp.len());
    for (o, q) in observer.p.iter().zip(&tp) {
        if q.iter().all(|v| v.is_finite()) {
            src.push(*o);
            dst.push(*q);
        }
    }
    Ok((src, dst))
}

fn norms(res: &[[f64; 3]]) -> Vec<f64> {
    res.iter()
        .map(|r| (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt())
        .collect()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// The RMS alignment residual (m) of `observer` against `truth` when the
/// observer's stamps are shifted by `offset` (`t_truth = t_observer + offset`),
/// and the number of pairs: the truth is interpolated linearly at each shifted
/// stamp (samples without a truth within `max_gap` are left out); with `spatial`
/// the residual is that of the [`umeyama`] fit of the observer onto the truth,
/// refitted without the pairs beyond `trim_factor ×` the median residual (as
/// [`spatial_align`]); without, the plain difference (the observer already in
/// the truth's frame), trimmed the same way. Errors when fewer than 3 pairs.
///
/// ```
/// use edccif_io::preprocess::{alignment_residual, SpatialOptions};
/// use edccif_io::Track;
/// let t: Vec<f64> = (0..400).map(|j| j as f64 / 100.0).collect();
/// let truth = Track::new(t.clone(), t.iter().map(|&s| [s.sin(), (0.7 * s).cos(), 0.1 * s]).collect())?;
/// // the observer's clock runs 0.25 s behind the truth's
/// let obs = Track::new(t.iter().map(|s| s - 0.25).collect(), truth.p.clone())?;
/// let (at, _) = alignment_residual(&obs, &truth, 0.25, Some(&SpatialOptions::default()), 0.25)?;
/// let (off, _) = alignment_residual(&obs, &truth, 0.0, Some(&SpatialOptions::default()), 0.25)?;
/// assert!(at < 1e-9 && off > 0.01);
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn alignment_residual(
    observer: &Track,
    truth: &Track,
    offset: f64,
    spatial: Option<&SpatialOptions>,
    max_gap: f64,
) -> Result<(f64, usize)> {
    residual_fit(observer, truth, offset, spatial, max_gap).map(|(r, n, _)| (r, n))
}

/// [`alignment_residual`] and the scale of its fit (1 without `spatial`).
fn residual_fit(
    observer: &Track,
    truth: &Track,
    offset: f64,
    spatial: Option<&SpatialOptions>,
    max_gap: f64,
) -> Result<(f64, usize, f64)> {
    let (src, dst) = pairs_at(observer, truth, offset, max_gap)?;
    let n = src.len();
    if n < 3 {
        return Err(value_err(
            "alignment residual",
            format!("only {n} samples overlap the truth at offset {offset} s (3 needed)"),
        ));
    }
    let residuals = |idx: &[usize], sim: Option<&Similarity>| -> Vec<[f64; 3]> {
        idx.iter()
            .map(|&k| {
                let q = sim.map_or(src[k], |s| s.apply(src[k]));
                [q[0] - dst[k][0], q[1] - dst[k][1], q[2] - dst[k][2]]
            })
            .collect()
    };
    let all: Vec<usize> = (0..n).collect();
    let with_scale = spatial.is_some_and(|s| s.with_scale);
    let fit = |idx: &[usize]| -> Result<Option<Similarity>> {
        match spatial {
            None => Ok(None),
            Some(_) => {
                let s2: Vec<[f64; 3]> = idx.iter().map(|&k| src[k]).collect();
                let d2: Vec<[f64; 3]> = idx.iter().map(|&k| dst[k]).collect();
                umeyama(&s2, &d2, with_scale).map(Some)
            }
        }
    };
    let mut sim = fit(&all)?;
    let mut res = norms(&residuals(&all, sim.as_ref()));
    let trim = spatial.map_or(Some(4.0), |s| s.trim_factor);
    if let Some(f) = trim {
        let med = median(&mut res.clone()).unwrap_or(0.0);
        let keep: Vec<usize> = all.iter().copied().filter(|&k| res[k] <= f * med).collect();
        if keep.len() >= 3 && keep.len() < n {
            sim = fit(&keep)?;
            res = norms(&residuals(&keep, sim.as_ref()));
        }
    }
    Ok((rms(&res), n, sim.map_or(1.0, |s| s.scale)))
}

/// The noise of a track estimated from its own samples, per axis (m): the
/// second difference `p_{j+1} − 2 p_j + p_{j−1}` of white noise `σ` has the
/// standard deviation `√6 σ`, and a smooth motion adds only `p̈ Δt²` to it; so
/// `σ ≈ 1.4826 · median|Δ²p| / √6` (the median absolute value: robust to the
/// odd outlier) over the triples of samples spaced within ±50 % of the median
/// step. `None` with fewer than 10 such triples.
///
/// ```
/// use edccif_io::preprocess::noise_from_scatter;
/// use edccif_io::Track;
/// // a straight line: no scatter
/// let tr = Track::new((0..50).map(|j| j as f64).collect(), (0..50).map(|j| [j as f64, 0.0, 1.0]).collect())?;
/// assert!(noise_from_scatter(&tr).unwrap().iter().all(|s| s.abs() < 1e-12));
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn noise_from_scatter(track: &Track) -> Option<[f64; 3]> {
    let m = median_dt(track)?;
    let regular = |g: f64| g > 0.5 * m && g < 1.5 * m;
    let mut d: [Vec<f64>; 3] = Default::default();
    for j in 1..track.len().saturating_sub(1) {
        if regular(track.t[j] - track.t[j - 1]) && regular(track.t[j + 1] - track.t[j]) {
            for (c, dc) in d.iter_mut().enumerate() {
                dc.push((track.p[j + 1][c] - 2.0 * track.p[j][c] + track.p[j - 1][c]).abs());
            }
        }
    }
    if d[0].len() < 10 {
        return None;
    }
    let k = 1.482_602_218_505_602 / 6f64.sqrt();
    let mut out = [0.0; 3];
    for (o, dc) in out.iter_mut().zip(d.iter_mut()) {
        *o = k * median(dc).unwrap_or(f64::NAN);
    }
    Some(out)
}

/// An estimated clock offset ([`estimate_offset`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OffsetEstimate {
    /// The offset (s), `t_truth = t_observer + offset`.
    pub offset_s: f64,
    /// The RMS alignment residual there (m).
    pub residual_m: f64,
    /// Pairs of samples behind it.
    pub pairs: usize,
    /// How far apart (s) the grid offsets lie whose residual is within 10 % of
    /// the least: a few frames where the data determine the offset; up to the
    /// whole window where a shift in time only moves the path rigidly (a circle,
    /// a helix, a straight line at constant speed), which the spatial fit
    /// absorbs ([`AMBIGUOUS_SPREAD_S`]).
    pub spread_s: f64,
}

/// An offset estimate whose [`OffsetEstimate::spread_s`] exceeds this (s) is
/// not determined by the data: [`clock_offsets`] keeps the start alignment for
/// that observer and says so.
pub const AMBIGUOUS_SPREAD_S: f64 = 0.25;

/// Estimates an observer's clock offset against the truth
/// (`t_truth = t_observer + offset`) by minimising [`alignment_residual`] over
/// the offset: first on a grid of one observer frame over `guess ± window_s`
/// (offsets at which fewer than half of the observer's samples overlap the truth
/// are skipped), then by golden-section search within one frame of the best grid
/// point (to 10⁻⁶ s). The residual is frame-free (each candidate gets its own
/// Umeyama fit with `spatial`), so the observer may be in its own frame.
///
/// ```
/// use edccif_io::preprocess::{estimate_offset, SpatialOptions};
/// use edccif_io::Track;
/// let t: Vec<f64> = (0..2000).map(|j| j as f64 / 100.0).collect();
/// let truth = Track::new(t.clone(), t.iter().map(|&s| [s.sin(), (0.7 * s).cos(), 0.1 * s]).collect())?;
/// // 30 Hz, its clock 100.3 s ahead of the truth's
/// let to: Vec<f64> = (30..500).map(|j| j as f64 / 30.0).collect();
/// let p = to.iter().map(|&s| [s.sin(), (0.7 * s).cos(), 0.1 * s]).collect();
/// let obs = Track::new(to.iter().map(|s| s + 100.3).collect(), p)?;
/// let guess = truth.t[0] - obs.t[0]; // the start alignment: 1 s off
/// let e = estimate_offset(&obs, &truth, guess, 2.0, Some(&SpatialOptions::default()), 0.25)?;
/// assert!((e.offset_s + 100.3).abs() < 1e-3, "{}", e.offset_s);
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn estimate_offset(
    observer: &Track,
    truth: &Track,
    guess: f64,
    window_s: f64,
    spatial: Option<&SpatialOptions>,
    max_gap: f64,
) -> Result<OffsetEstimate> {
    estimate_offset_watched(
        observer, truth, guess, window_s, spatial, max_gap, &Unwatched,
    )
}

/// The offsets [`estimate_offset`] tries on its grid (`2 · ceil(window_s /
/// frame) + 1`, the observer's median frame), before its golden-section
/// search: its work in units of [`estimate_offset_watched`]. `None` when the
/// observer has fewer than two distinct stamps.
pub fn offset_grid_len(observer: &Track, window_s: f64) -> Option<u64> {
    let frame = median_dt(observer)?;
    let steps = (window_s / frame).ceil();
    Some(if (0.0..4e18).contains(&steps) {
        2 * (steps as u64) + 1
    } else {
        u64::MAX
    })
}

/// [`estimate_offset`] counting one unit on `watch` per offset of its grid
/// ([`offset_grid_len`] in all) and stopping with [`Error::Interrupted`] soon
/// after `watch` is cancelled.
pub fn estimate_offset_watched(
    observer: &Track,
    truth: &Track,
    guess: f64,
    window_s: f64,
    spatial: Option<&SpatialOptions>,
    max_gap: f64,
    watch: &dyn Watch,
) -> Result<OffsetEstimate> {
    if !(window_s.is_finite() && window_s >= 0.0) {
        return Err(value_err(
            "offset window",
            format!("must be finite and >= 0, got {window_s}"),
        ));
    }
    if !guess.is_finite() {
        return Err(value_err(
            "offset guess",
            format!("must be finite, got {guess}"),
        ));
    }
    let frame = median_dt(observer)
        .ok_or_else(|| value_err("observer", "has fewer than two distinct stamps"))?;
    let need = (observer.len() / 2).max(10);
    let cost = |tau: f64| -> Option<(f64, usize)> {
        match alignment_residual(observer, truth, tau, spatial, max_gap) {
            Ok((r, n)) if n >= need && r.is_finite() => Some((r, n)),
            _ => None,
        }
    };
    let steps = (window_s / frame).ceil() as i64;
    let mut best: Option<(f64, f64, usize)> = None;
    let mut grid = Vec::new();
    for j in -steps..=steps {
        watch.check()?;
        watch.advance(1);
        let tau = guess + j as f64 * frame;
        if let Some((r, n)) = cost(tau) {
            grid.push((tau, r));
            if best.is_none_or(|b| r < b.1) {
                best = Some((tau, r, n));
            }
        }
    }
    let spread_s = best.map_or(f64::NAN, |b| {
        let near = grid.iter().filter(|g| g.1 <= 1.1 * b.1).map(|g| g.0);
        let (lo, hi) = near.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), t| {
            (l.min(t), h.max(t))
        });
        hi - lo
    });
    let Some((mut lo, _, _)) = best else {
        return Err(value_err(
            "clock offset",
            format!(
                "cannot be estimated: at no offset within ±{window_s} s of the start alignment do \
                 half of the observer's {} samples overlap the truth; give the offset instead",
                observer.len()
            ),
        ));
    };
    let mut hi = lo + frame;
    lo -= frame;
    // Golden-section search on [lo, hi]; an offset without enough overlap costs ∞.
    let f = |tau: f64| cost(tau).map_or(f64::INFINITY, |c| c.0);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut fa, mut fb) = (f(a), f(b));
    while hi - lo > 1e-6 {
        watch.check()?;
        if fa <= fb {
            hi = b;
            b = a;
            fb = fa;
            a = hi - g * (hi - lo);
            fa = f(a);
        } else {
            lo = a;
            a = b;
            fa = fb;
            b = lo + g * (hi - lo);
            fb = f(b);
        }
    }
    let tau = 0.5 * (lo + hi);
    let candidates = [
        (tau, cost(tau)),
        (best.map_or(tau, |b| b.0), best.map(|b| (b.1, b.2))),
    ];
    let (offset_s, (residual_m, pairs)) = candidates
        .into_iter()
        .filter_map(|(t, c)| c.map(|c| (t, c)))
        .min_by(|x, y| x.1 .0.total_cmp(&y.1 .0))
        .ok_or_else(|| value_err("clock offset", "the search found no overlap"))?;
    Ok(OffsetEstimate {
        offset_s,
        residual_m,
        pairs,
        spread_s,
    })
}

/// Each observer's clock offset against the truth and the shifts that put every
/// track on one clock, as [`run_pipeline`] applies them (tracks non-empty with
/// increasing stamps, e.g. after [`remove_abnormal_gaps`]):
///
/// - an observer in [`PipelineOptions::offsets`] gets the offset given;
/// - else by [`PipelineOptions::time_align`]: `none` 0, `start` the difference of
///   the first stamps, `estimate` [`estimate_offset`] within
///   [`PipelineOptions::offset_window_s`] of the start alignment.
///
/// The shifts: with `none` the truth's clock (the truth unshifted, observer i
/// shifted by its offset); otherwise the truth's first sample at 0 (with
/// `start` every track's first sample at 0, as the paper's pipeline). The report
/// also holds each observer's [`alignment_residual`] at its offset and its noise
/// ([`noise_from_scatter`]), and a warning for every observer whose residual
/// exceeds [`PipelineOptions::residual_factor`] times that noise.
pub fn clock_offsets(
    truth: &Track,
    observers: &[Track],
    opt: &PipelineOptions,
) -> Result<ClockReport> {
    clock_offsets_watched(truth, observers, opt, &Unwatched)
}

/// The work of [`clock_offsets`] in units of [`clock_offsets_watched`]: one per
/// observer, and the offsets of its grid ([`offset_grid_len`]) for each
/// observer whose offset is estimated.
pub fn clock_offsets_work(observers: &[Track], opt: &PipelineOptions) -> u64 {
    let given = |i: usize| opt.offsets.iter().any(|(k, _)| *k == i);
    observers
        .iter()
        .enumerate()
        .map(|(i, o)| {
            let grid = match opt.time_align {
                TimeAlign::Estimate if !given(i) => {
                    offset_grid_len(o, opt.offset_window_s).unwrap_or(0)
                }
                _ => 0,
            };
            grid.saturating_add(1)
        })
        .fold(0u64, u64::saturating_add)
}

/// [`clock_offsets`] counting its work on `watch` ([`clock_offsets_work`] units)
/// and stopping with [`Error::Interrupted`] soon after `watch` is cancelled.
pub fn clock_offsets_watched(
    truth: &Track,
    observers: &[Track],
    opt: &PipelineOptions,
    watch: &dyn Watch,
) -> Result<ClockReport> {
    check_tracks(std::slice::from_ref(truth))?;
    check_tracks(observers)?;
    opt.check_clock(observers.len())?;
    let given = |i: usize| opt.offsets.iter().rev().find(|(k, _)| *k == i).map(|o| o.1);
    let spatial = opt.spatial.as_ref();
    let mut rep = ClockReport {
        align: opt.time_align.name().into(),
        residual_factor: opt.residual_factor,
        ..ClockReport::default()
    };
    let truth_shift = match opt.time_align {
        TimeAlign::Keep => 0.0,
        _ => -truth.t[0],
    };
    rep.shifts.push(truth_shift);
    for (i, o) in observers.iter().enumerate() {
        let start = truth.t[0] - o.t[0];
        let mut spread = f64::NAN;
        let (offset, source) = match (given(i), opt.time_align) {
            (Some(v), _) => (v, OffsetSource::Given),
            (None, TimeAlign::Keep) => (0.0, OffsetSource::None),
            (None, TimeAlign::ShiftToFirstSample) => (start, OffsetSource::Start),
            (None, TimeAlign::Estimate) => {
                let e = estimate_offset_watched(
                    o,
                    truth,
                    start,
                    opt.offset_window_s,
                    spatial,
                    opt.max_gap_s,
                    watch,
                )
                .map_err(|e| match e {
                    Error::Value { what, problem } => Error::Value {
                        what: format!("{what} of observer {i}"),
                        problem,
                    },
                    other => other,
                })?;
                spread = e.spread_s;
                if e.spread_s > AMBIGUOUS_SPREAD_S {
                    rep.warnings.push(format!(
                        "observer {i}: the data do not determine its clock offset: the alignment \
                         residual stays within 10 % of its least over {:.2} s of offsets (a path \
                         that a shift in time only moves rigidly, such as a circle, a helix or a \
                         straight line at constant speed); the start alignment ({start:.4} s) is \
                         kept. If the recordings did not start together, give it with --offset \
                         {i}=SECONDS",
                        e.spread_s
                    ));
                    (start, OffsetSource::Start)
                } else {
                    (e.offset_s, OffsetSource::Estimated)
                }
            }
        };
        rep.spreads_s.push(spread);
        // `start` without a given offset: every track's first sample at 0,
        // computed as the paper's pipeline does (the same bits).
        let shift = match source {
            OffsetSource::Start => -o.t[0],
            _ => offset + truth_shift,
        };
        rep.shifts.push(shift);
        rep.offsets_s.push(offset);
        rep.start_offsets_s.push(start);
        rep.sources.push(source);
        let (residual, scale) = residual_fit(o, truth, offset, spatial, opt.max_gap_s)
            .map_or((f64::NAN, 1.0), |r| (r.0, r.2));
        // The residual is in the truth's units: the noise too (the fit's scale).
        let noise = noise_from_scatter(o).map_or(f64::NAN, |s| {
            scale * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt()
        });
        rep.residual_m.push(residual);
        rep.noise_m.push(noise);
        if residual.is_finite() && noise.is_finite() && residual > opt.residual_factor * noise {
            let applied = match source {
                OffsetSource::None => "none (clocks taken as synchronised)".to_string(),
                OffsetSource::Start => "from the first samples".to_string(),
                OffsetSource::Estimated => format!(
                    "estimated; the first samples give {:+.4} s more",
                    start - offset
                ),
                OffsetSource::Given => "given".to_string(),
            };
            let hint = match source {
                OffsetSource::Estimated => {
                    "Check its frame and data, widen the search (--offset-window)"
                }
                _ => "Try --align estimate",
            };
            rep.warnings.push(format!(
                "observer {i}: the alignment residual {:.1} mm RMS is {:.1} × its noise ({:.1} mm, \
                 from its own sample-to-sample scatter), more than {} ×: is its clock offset \
                 {offset:.4} s ({applied}) wrong? {hint}, or give it with --offset {i}=SECONDS",
                residual * 1e3,
                residual / noise,
                noise * 1e3,
                opt.residual_factor,
            ));
        }
        watch.advance(1);
    }
    Ok(rep)
}

// ---------------------------------------------------------------- pipeline

/// Options of [`run_pipeline`]. [`Default`] estimates the clock offsets from the
/// data; [`PipelineOptions::paper`] is the paper's pipeline (the recordings'
/// starts aligned), which `docs/results.md` uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PipelineOptions {
    /// `factor` of [`remove_abnormal_gaps`].
    pub gap_factor: f64,
    /// `tol` of [`remove_origin_outliers`] (m).
    pub origin_tol: f64,
    /// Clock handling ([`clock_offsets`]).
    pub time_align: TimeAlign,
    /// Observers' clock offsets given by the caller: `(observer index, offset
    /// in s)`, `t_truth = t_observer + offset`; they override `time_align` for
    /// those observers.
    #[serde(default)]
    pub offsets: Vec<(usize, f64)>,
    /// Half-width (s) of the window around the start alignment in which
    /// [`estimate_offset`] searches.
    #[serde(default = "default_offset_window")]
    pub offset_window_s: f64,
    /// A clock alignment whose residual exceeds this multiple of the observer's
    /// noise is warned about ([`ClockReport::warnings`]).
    #[serde(default = "default_residual_factor")]
    pub residual_factor: f64,
    /// Samples whose stamp repeats the previous one: dropped and counted, or the
    /// input refused before any work.
    #[serde(default)]
    pub duplicates: DuplicateStamps,
    /// Spatial alignment of each observer onto the truth; `None`: the observers'
    /// tracks are already in the truth's frame.
    pub spatial: Option<SpatialOptions>,
    /// Common frame rate (Hz); `None`: the median rate of the observers.
    pub rate_hz: Option<f64>,
    /// `max_gap` of [`interpolate`] (s): longer gaps stay missing.
    pub max_gap_s: f64,
}

fn default_offset_window() -> f64 {
    2.0
}

fn default_residual_factor() -> f64 {
    3.0
}

impl Default for PipelineOptions {
    fn default() -> Self {
        Self {
            gap_factor: 3.5,
            origin_tol: 1e-6,
            time_align: TimeAlign::Estimate,
            offsets: Vec::new(),
            offset_window_s: default_offset_window(),
            residual_factor: default_residual_factor(),
            duplicates: DuplicateStamps::Drop,
            spatial: Some(SpatialOptions::default()),
            rate_hz: None,
            max_gap_s: 0.25,
        }
    }
}

impl PipelineOptions {
    /// The paper's pipeline: the default with the recordings' starts aligned
    /// ([`TimeAlign::ShiftToFirstSample`]), as the generated recordings of
    /// `docs/results.md` are made (started together).
    pub fn paper() -> Self {
        Self {
            time_align: TimeAlign::ShiftToFirstSample,
            ..Self::default()
        }
    }

    /// Checks the clock options for `observers` observers: given offsets finite
    /// and for an existing observer, the window finite and `>= 0`, the factor
    /// finite and `> 0`.
    pub fn check_clock(&self, observers: usize) -> Result<()> {
        for &(i, v) in &self.offsets {
            if i >= observers {
                return Err(value_err(
                    format!("offset of observer {i}"),
                    format!(
                        "there are {observers} observers (0 to {})",
                        observers.saturating_sub(1)
                    ),
                ));
            }
            if !v.is_finite() {
                return Err(value_err(
                    format!("offset of observer {i}"),
                    format!("must be finite, got {v}"),
                ));
            }
        }
        if !(self.offset_window_s.is_finite() && self.offset_window_s >= 0.0) {
            return Err(value_err(
                "offset_window_s",
                format!("must be finite and >= 0, got {}", self.offset_window_s),
            ));
        }
        if !(self.residual_factor.is_finite() && self.residual_factor > 0.0) {
            return Err(value_err(
                "residual_factor",
                format!("must be finite and > 0, got {}", self.residual_factor),
            ));
        }
        Ok(())
    }
}

/// Everything the pipeline did, per track (index 0: the truth, then observers).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PipelineReport {
    /// Step 0, per track.
    pub duplicates: Vec<DuplicateReport>,
    /// Step 1, per track.
    pub origin: Vec<OriginReport>,
    /// Step 2, per track.
    pub gaps: Vec<GapReport>,
    /// Step 3: the clock offsets applied, with their residuals and warnings.
    pub clock: ClockReport,
    /// Step 3: the common span.
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
    run_pipeline_watched(truth, observers, opt, &Unwatched)
}

/// [`run_pipeline`] counting its work on `watch` and stopping with
/// [`Error::Interrupted`] soon after `watch` is cancelled. The work is declared
/// once, after the tracks are cleaned (duplicates, outliers, gaps: linear and
/// quick): the clock offsets ([`clock_offsets_work`]), one unit per observer
/// for the spatial alignment, one for the truth's downsampling, and one per
/// track for the interpolation.
///
/// ```
/// use std::sync::atomic::{AtomicU64, Ordering};
/// use edccif_io::preprocess::{run_pipeline_watched, PipelineOptions};
/// use edccif_io::realworld::{generate, PathKind, RealWorldConfig};
/// use edccif_io::watch::Watch;
/// struct Count(AtomicU64, AtomicU64);
/// impl Watch for Count {
///     fn add_total(&self, n: u64) { self.1.fetch_add(n, Ordering::Relaxed); }
///     fn advance(&self, n: u64) { self.0.fetch_add(n, Ordering::Relaxed); }
///     fn is_cancelled(&self) -> bool { false }
/// }
/// let raw = generate(&RealWorldConfig::new(PathKind::Circle, 1))?;
/// let c = Count(AtomicU64::new(0), AtomicU64::new(0));
/// run_pipeline_watched(&raw.truth, &raw.observers, &PipelineOptions::default(), &c)?;
/// assert!(c.1.load(Ordering::Relaxed) > 0);
/// assert_eq!(c.0.load(Ordering::Relaxed), c.1.load(Ordering::Relaxed));
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn run_pipeline_watched(
    truth: &Track,
    observers: &[Track],
    opt: &PipelineOptions,
    watch: &dyn Watch,
) -> Result<AlignedData> {
    if observers.is_empty() {
        return Err(value_err(
            "observers",
            "at least one observer track is needed",
        ));
    }
    let name = |i: usize| {
        if i == 0 {
            "truth".to_string()
        } else {
            format!("observer {}", i - 1)
        }
    };
    // Every input is checked before any work runs.
    opt.check_clock(observers.len())?;
    if opt.duplicates == DuplicateStamps::Refuse {
        for (i, tr) in std::iter::once(truth).chain(observers).enumerate() {
            check_duplicate_stamps(tr, &name(i))?;
        }
    }
    let mut rep = PipelineReport::default();
    let mut tracks = Vec::with_capacity(observers.len() + 1);
    for (i, tr) in std::iter::once(truth).chain(observers).enumerate() {
        watch.check()?;
        let name = name(i);
        let (d, dup) = drop_duplicate_stamps(tr);
        rep.duplicates.push(dup);
        let (a, o) = remove_origin_outliers(&d, opt.origin_tol);
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
    let k = observers.len() as u64;
    let spatial_work = if opt.spatial.is_some() { k } else { 0 };
    watch.add_total(
        clock_offsets_work(&tracks[1..], opt)
            .saturating_add(spatial_work)
            .saturating_add(1)
            .saturating_add(k + 1),
    );
    rep.clock = clock_offsets_watched(&tracks[0], &tracks[1..], opt, watch)?;
    let (tracks, span) = crop_common_span(&tracks, &rep.clock.shifts)?;
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
            watch.advance(1);
            watch.check()?;
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
    watch.advance(1);
    watch.check()?;
    let grid = common_grid(rep.span.start, rep.span.end, rate);
    let t_len = grid.len();
    let k = obs.len();
    let (tp, ti) = interpolate(&truth_ds, &grid, opt.max_gap_s)?;
    rep.interp.push(ti);
    watch.advance(1);
    let mut z = vec![f64::NAN; t_len * k * 3];
    for (i, o) in obs.iter().enumerate() {
        watch.check()?;
        let (zp, zi) = interpolate(o, &grid, opt.max_gap_s)?;
        rep.interp.push(zi);
        watch.advance(1);
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
