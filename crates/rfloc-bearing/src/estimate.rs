//! Per-beacon range and bearing from a sweep (pure; no I/O).

use std::collections::BTreeMap;
use std::f64::consts::TAU;

use rfloc_pose::{angle_diff, wrap_angle};
use serde::{Deserialize, Serialize};
use tracing::warn;

use crate::pathloss::PathLossModel;
use crate::pattern::GainPattern;
use crate::sweep::Sweep;

/// Settings of the peak search and of the variances.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorConfig {
    /// Range model.
    pub path_loss: PathLossModel,
    /// Fewest stops at which a beacon must be heard.
    pub min_samples: usize,
    /// Smallest peak-above-median contrast, dB; below it the sweep is flat.
    pub min_contrast_db: f64,
    /// A second peak within this many dB of the main one is ambiguous …
    pub ambiguity_db: f64,
    /// … if the valley between them is at least this deep below the second peak, dB.
    pub min_valley_db: f64,
    /// Competing peaks closer than this to the main one are part of the same lobe, degrees.
    pub min_peak_separation_deg: f64,
    /// Smooth the RSSI-vs-angle curve with a [1 2 1]/4 kernel before searching.
    pub smooth: bool,
    /// Half width of the window of stops around the maximum that the parabola is fitted to,
    /// degrees. Keep it inside the main lobe (≈ ±¾ of the half-power beamwidth).
    pub fit_half_width_deg: f64,
    /// Standard deviation of one RSSI reading about its local mean (receiver noise and fast
    /// fading, not shadowing), dB. Sets the peak-sharpness part of the bearing variance.
    pub rssi_noise_sigma_db: f64,
    /// Added to every bearing variance, rad² (e.g. multipath and mounting error).
    pub bearing_variance_floor_rad2: f64,
    /// The antenna's calibrated gain pattern. When given, bearing and peak level come from a
    /// least-squares fit of the whole pattern to every stop of the sweep (see
    /// `fit_pattern`) instead of the parabola over the stops near the maximum.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pattern: Option<GainPattern>,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            path_loss: PathLossModel::default(),
            min_samples: 5,
            min_contrast_db: 3.0,
            ambiguity_db: 3.0,
            min_valley_db: 3.0,
            min_peak_separation_deg: 45.0,
            smooth: true,
            fit_half_width_deg: 40.0,
            rssi_noise_sigma_db: 2.0,
            bearing_variance_floor_rad2: 0.0,
            pattern: None,
        }
    }
}

/// Range and bearing of one beacon from one sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeaconObservation {
    /// Range from the peak RSSI, m.
    pub range_m: f64,
    /// Range variance, m².
    pub range_variance_m2: f64,
    /// Bearing relative to the robot heading at `peak_sample`, radians in `(−π, π]`.
    pub bearing_rad: f64,
    /// Bearing variance, rad².
    pub bearing_variance_rad2: f64,
    /// Interpolated peak RSSI, dBm (the range comes from it; an EKF may use it directly with
    /// variance σ_shadow²).
    pub peak_rssi_dbm: f64,
    /// Peak minus median RSSI over the sweep, dB.
    pub contrast_db: f64,
    /// Index in `Sweep::samples` of the strongest stop.
    pub peak_sample: usize,
    /// Robot heading at that stop, radians.
    pub heading_at_peak_rad: f64,
    /// Stops at which the beacon was heard.
    pub samples: usize,
}

/// Why a beacon got no observation from a sweep.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Rejection {
    /// Heard at too few stops.
    #[error("heard at {have} stops, need {need}")]
    TooFewSamples {
        /// Stops with a reading.
        have: usize,
        /// Configured minimum.
        need: usize,
    },
    /// No clear maximum.
    #[error("flat sweep: contrast {contrast_db:.1} dB < {min_contrast_db:.1} dB")]
    Flat {
        /// Peak minus median, dB.
        contrast_db: f64,
        /// Configured minimum.
        min_contrast_db: f64,
    },
    /// Two separated maxima of similar strength (multipath or reflection).
    #[error("two peaks at {main_rad:.3} and {other_rad:.3} rad, {gap_db:.1} dB apart")]
    MultiPeak {
        /// Direction of the strongest peak relative to the heading at the first stop.
        main_rad: f64,
        /// Direction of the competing peak, same frame.
        other_rad: f64,
        /// Main minus competing peak level, dB.
        gap_db: f64,
    },
    /// On a partial arc the maximum is at an end, so the true peak may lie outside the arc.
    #[error("peak at the end of the arc ({angle_rad:.3} rad)")]
    PeakAtEdge {
        /// Direction of that end relative to the heading at the first stop.
        angle_rad: f64,
    },
}

/// Result of estimating every beacon of a sweep.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SweepReport {
    /// Per beacon id.
    pub beacons: BTreeMap<u64, Result<BeaconObservation, Rejection>>,
    /// Readings dropped because the RSSI was not finite.
    pub dropped_readings: usize,
    /// Stops dropped because their antenna angle or heading was not finite.
    pub dropped_samples: usize,
}

/// One point of a beacon's RSSI-vs-direction curve.
#[derive(Debug, Clone, Copy)]
struct Point {
    /// Direction relative to the heading at the first stop, radians (unwrapped).
    dir: f64,
    rssi: f64,
    n: usize,
    sample: usize,
}

/// Estimates range and bearing of every beacon heard in `sweep`.
#[must_use]
pub fn estimate_sweep(sweep: &Sweep, config: &EstimatorConfig) -> SweepReport {
    let mut report = SweepReport::default();
    let heading0 = sweep
        .samples
        .iter()
        .find(|s| s.heading_rad.is_finite())
        .map_or(0.0, |s| s.heading_rad);
    // Per beacon: (direction, sum, count, sample index) per stop.
    let mut curves: BTreeMap<u64, Vec<Point>> = BTreeMap::new();
    for (idx, s) in sweep.samples.iter().enumerate() {
        if !(s.antenna_rad.is_finite() && s.heading_rad.is_finite()) {
            report.dropped_samples += 1;
            continue;
        }
        let dir = s.antenna_rad + angle_diff(s.heading_rad, heading0);
        let mut at_stop: BTreeMap<u64, (f64, usize)> = BTreeMap::new();
        for &(id, rssi) in &s.readings {
            if !rssi.is_finite() {
                report.dropped_readings += 1;
                continue;
            }
            let e = at_stop.entry(id).or_insert((0.0, 0));
            e.0 += rssi;
            e.1 += 1;
        }
        for (id, (sum, n)) in at_stop {
            curves.entry(id).or_default().push(Point {
                dir,
                rssi: sum / n as f64,
                n,
                sample: idx,
            });
        }
    }
    if report.dropped_readings + report.dropped_samples > 0 {
        warn!(
            readings = report.dropped_readings,
            samples = report.dropped_samples,
            "non-finite values dropped from sweep"
        );
    }
    for (id, points) in curves {
        let r = estimate_beacon(points, sweep, heading0, config);
        report.beacons.insert(id, r);
    }
    report
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    match (s.get(n / 2), n % 2) {
        (Some(&m), 1) => m,
        (Some(&hi), _) => s.get(n / 2 - 1).map_or(hi, |&lo| 0.5 * (lo + hi)),
        (None, _) => f64::NAN,
    }
}

fn estimate_beacon(
    mut pts: Vec<Point>,
    sweep: &Sweep,
    heading0: f64,
    cfg: &EstimatorConfig,
) -> Result<BeaconObservation, Rejection> {
    let n = pts.len();
    if n < cfg.min_samples.max(3) {
        return Err(Rejection::TooFewSamples {
            have: n,
            need: cfg.min_samples.max(3),
        });
    }
    pts.sort_by(|a, b| a.dir.total_cmp(&b.dir));
    // Nominal step: median of the non-zero gaps between sorted directions (repeated directions,
    // e.g. from a robot turning during the sweep, do not count).
    let gaps: Vec<f64> = pts
        .windows(2)
        .filter_map(|w| match w {
            [a, b] if b.dir - a.dir > 1e-6 => Some(b.dir - a.dir),
            _ => None,
        })
        .collect();
    let step = if gaps.is_empty() {
        TAU / n as f64
    } else {
        median(&gaps)
    };
    let first = pts.first().map_or(0.0, |p| p.dir);
    let last = pts.last().map_or(0.0, |p| p.dir);
    // Full circle: the arc plus one step closes the turn.
    let circular = last - first + step >= TAU - 0.5 * step;
    // Neighbours are adjacent points at most 1.5 steps apart (a missing stop breaks adjacency).
    let close = |a: f64, b: f64| {
        let d = if circular {
            angle_diff(b, a).abs()
        } else {
            (b - a).abs()
        };
        d <= 1.5 * step
    };
    let neighbour = |i: usize, right: bool| -> Option<usize> {
        let j = if right {
            if i + 1 < n {
                i + 1
            } else if circular {
                0
            } else {
                return None;
            }
        } else if i > 0 {
            i - 1
        } else if circular {
            n - 1
        } else {
            return None;
        };
        let (a, b) = (pts.get(i)?.dir, pts.get(j)?.dir);
        close(a, b).then_some(j)
    };

    let raw: Vec<f64> = pts.iter().map(|p| p.rssi).collect();
    let y: Vec<f64> = if cfg.smooth {
        (0..n)
            .map(|i| {
                let c = raw.get(i).copied().unwrap_or(f64::NAN);
                let l = neighbour(i, false).and_then(|j| raw.get(j).copied());
                let r = neighbour(i, true).and_then(|j| raw.get(j).copied());
                match (l, r) {
                    (Some(l), Some(r)) => 0.25 * l + 0.5 * c + 0.25 * r,
                    (Some(o), None) | (None, Some(o)) => (2.0 * c + o) / 3.0,
                    (None, None) => c,
                }
            })
            .collect()
    } else {
        raw
    };

    let (k, y0) = y
        .iter()
        .copied()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::NAN));
    let med = median(&y);
    let contrast_db = y0 - med;
    if contrast_db.is_nan() || contrast_db < cfg.min_contrast_db {
        return Err(Rejection::Flat {
            contrast_db,
            min_contrast_db: cfg.min_contrast_db,
        });
    }
    let peak = pts.get(k).copied().ok_or(Rejection::TooFewSamples {
        have: n,
        need: cfg.min_samples,
    })?;

    // Competing peaks: local maxima (ties count) within `ambiguity_db` whose valley towards the
    // main peak is at least `min_valley_db` deep.
    for i in 0..n {
        if i == k {
            continue;
        }
        let yi = y.get(i).copied().unwrap_or(f64::NAN);
        if yi < y0 - cfg.ambiguity_db {
            continue;
        }
        let is_local_max = [false, true].iter().all(|&right| {
            neighbour(i, right)
                .and_then(|j| y.get(j))
                .is_none_or(|&yj| yj <= yi)
        });
        if !is_local_max {
            continue;
        }
        let other_dir = pts.get(i).map_or(f64::NAN, |p| p.dir);
        if angle_gap(peak.dir, other_dir, circular) < cfg.min_peak_separation_deg.to_radians() {
            continue;
        }
        let valley = highest_valley(&y, i, k, circular);
        if yi - valley >= cfg.min_valley_db {
            let other = pts.get(i).map_or(f64::NAN, |p| p.dir);
            return Err(Rejection::MultiPeak {
                main_rad: wrap_angle(peak.dir),
                other_rad: wrap_angle(other),
                gap_db: y0 - yi,
            });
        }
    }

    if !circular && (k == 0 || k + 1 == n) {
        return Err(Rejection::PeakAtEdge {
            angle_rad: wrap_angle(peak.dir),
        });
    }

    // Weighted least-squares parabola (in dB) over the contiguous stops within
    // `fit_half_width_deg` of the strongest smoothed stop, on the unsmoothed means. (Moving the
    // window to the fitted vertex and refitting was tried; on noisy synthetic sweeps it made
    // the error tail longer, so it is not done.)
    let half = cfg.fit_half_width_deg.to_radians();
    let window_at = |centre: usize| -> Vec<(f64, f64, f64, usize)> {
        let Some(pc) = pts.get(centre) else {
            return Vec::new();
        };
        let mut w = vec![(0.0, pc.rssi, pc.n as f64, centre)];
        for right in [false, true] {
            let mut i = centre;
            let mut x = 0.0;
            while let Some(j) = neighbour(i, right) {
                let (Some(pi), Some(pj)) = (pts.get(i), pts.get(j)) else {
                    break;
                };
                x += angle_gap(pi.dir, pj.dir, circular) * if right { 1.0 } else { -1.0 };
                if j == centre || x.abs() > half + 1e-9 || w.len() >= n {
                    break;
                }
                w.push((x, pj.rssi, pj.n as f64, j));
                i = j;
            }
        }
        w
    };
    let quant_var = step * step / 12.0;
    let pattern_fit = cfg.pattern.as_ref().and_then(|pattern| {
        fit_pattern(&pts, peak.dir, half, step, pattern, cfg.rssi_noise_sigma_db)
    });
    let (dir, peak_rssi, mut var) = if let Some(f) = pattern_fit {
        (f.direction, f.level, f.variance)
    } else {
        let window: Vec<(f64, f64, f64)> =
            window_at(k).iter().map(|&(x, y, w, _)| (x, y, w)).collect();
        let fit = fit_parabola(&window, cfg.rssi_noise_sigma_db).map(|f| (peak.dir, f));
        match fit {
            Some((c, f)) => (c + f.vertex, f.value, f.vertex_variance.max(quant_var)),
            // Too few neighbours or not concave: keep the strongest stop.
            None => (peak.dir, y0, step * step / 4.0),
        }
    };
    var += cfg.bearing_variance_floor_rad2;

    let heading_at_peak = sweep
        .samples
        .get(peak.sample)
        .map_or(heading0, |s| s.heading_rad);
    let bearing = wrap_angle(dir - angle_diff(heading_at_peak, heading0));
    let range = cfg.path_loss.range_from_rssi(peak_rssi);
    Ok(BeaconObservation {
        range_m: range.range_m,
        range_variance_m2: range.variance_m2,
        bearing_rad: bearing,
        bearing_variance_rad2: var,
        peak_rssi_dbm: peak_rssi,
        contrast_db,
        peak_sample: peak.sample,
        heading_at_peak_rad: heading_at_peak,
        samples: n,
    })
}

/// Positive gap from direction `a` to the next direction `b`.
fn angle_gap(a: f64, b: f64, circular: bool) -> f64 {
    if circular {
        angle_diff(b, a).abs()
    } else {
        (b - a).abs()
    }
}

/// Result of the gain-pattern fit.
struct PatternFit {
    /// Boresight direction that fits best, same frame as the points' directions, radians.
    direction: f64,
    /// Received level on boresight, dBm.
    level: f64,
    /// Variance of `direction` (Cramér–Rao bound of the fit), rad².
    variance: f64,
}

/// Weighted squared residuals of the stops against `level + G(dir − β)` with the level that fits
/// best for this `β` (the weighted mean of `rssi − G`). Returns `(cost, level)`.
fn pattern_cost(pts: &[Point], pattern: &GainPattern, beta: f64) -> (f64, f64) {
    let (mut sw, mut swr, mut swrr) = (0.0, 0.0, 0.0);
    for p in pts {
        let w = p.n as f64;
        let r = p.rssi - pattern.gain_db(p.dir - beta);
        sw += w;
        swr += w * r;
        swrr += w * r * r;
    }
    if sw <= 0.0 {
        return (f64::INFINITY, f64::NAN);
    }
    let level = swr / sw;
    ((swrr - swr * level).max(0.0), level)
}

/// Least-squares fit of the known gain pattern to every stop: `rssi_i = L + G(dir_i − β) + e_i`,
/// `e_i` of σ `sigma / √n_i` (`n_i` readings averaged at the stop), over the boresight
/// direction `β` and the level `L`. `β` is searched on a grid of step/8 within `half` of
/// `centre` (the strongest smoothed stop), then refined by golden-section search; `L` is solved
/// in closed form for each `β`. The variance is the Cramér–Rao bound with `L` unknown:
/// `σ² / (Σ n_i s_i² − (Σ n_i s_i)² / Σ n_i)`, `s_i = G'(dir_i − β̂)`. Every stop counts, not only
/// those near the maximum: the flanks of the lobe, where the gain changes fastest, carry most
/// of the bearing information. `None` when no minimum is found or the information is zero.
fn fit_pattern(
    pts: &[Point],
    centre: f64,
    half: f64,
    step: f64,
    pattern: &GainPattern,
    sigma: f64,
) -> Option<PatternFit> {
    if pts.len() < 3 || !(half > 0.0 && step > 0.0) {
        return None;
    }
    let grid = step / 8.0;
    let cells = (half / grid).ceil() as i64;
    let mut best: Option<(f64, f64)> = None;
    for j in -cells..=cells {
        let beta = centre + j as f64 * grid;
        let (c, _) = pattern_cost(pts, pattern, beta);
        if c.is_finite() && best.is_none_or(|(bc, _)| c < bc) {
            best = Some((c, beta));
        }
    }
    let (_, beta0) = best?;
    // Golden-section refinement within one grid cell either side.
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (beta0 - grid, beta0 + grid);
    let mut x1 = b - g * (b - a);
    let mut x2 = a + g * (b - a);
    let mut f1 = pattern_cost(pts, pattern, x1).0;
    let mut f2 = pattern_cost(pts, pattern, x2).0;
    for _ in 0..40 {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = pattern_cost(pts, pattern, x1).0;
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = pattern_cost(pts, pattern, x2).0;
        }
    }
    let beta = 0.5 * (a + b);
    let (_, level) = pattern_cost(pts, pattern, beta);
    let (mut sw, mut sws, mut swss) = (0.0, 0.0, 0.0);
    for p in pts {
        let w = p.n as f64;
        let s = pattern.slope_db_per_rad(p.dir - beta);
        sw += w;
        sws += w * s;
        swss += w * s * s;
    }
    let info = swss - sws * sws / sw.max(f64::MIN_POSITIVE);
    if !(info > 0.0 && level.is_finite() && beta.is_finite()) {
        return None;
    }
    Some(PatternFit {
        direction: beta,
        level,
        variance: sigma * sigma / info,
    })
}

/// Result of the least-squares parabola fit.
struct ParabolaFit {
    /// Vertex offset from the centre stop, radians (clamped to the window).
    vertex: f64,
    /// Fitted RSSI at the vertex, dB.
    value: f64,
    /// Variance of `vertex` from the fit covariance, rad².
    vertex_variance: f64,
}

/// Fits `y = a x² + b x + c` to `(x, y, weight)` points, weights being reading counts, each
/// reading with standard deviation `sigma`. `None` with fewer than three points, a singular
/// system, or a fit that is not concave.
fn fit_parabola(pts: &[(f64, f64, f64)], sigma: f64) -> Option<ParabolaFit> {
    if pts.len() < 3 {
        return None;
    }
    // Normal equations M [a b c]ᵀ = v, M = Σ w φφᵀ with φ = [x², x, 1].
    let mut m = [[0.0f64; 3]; 3];
    let mut v = [0.0f64; 3];
    for &(x, y, w) in pts {
        let phi = [x * x, x, 1.0];
        for (r, pr) in m.iter_mut().zip(phi) {
            for (c, pc) in r.iter_mut().zip(phi) {
                *c += w * pr * pc;
            }
        }
        for (vr, pr) in v.iter_mut().zip(phi) {
            *vr += w * pr * y;
        }
    }
    let inv = invert3(&m)?;
    let coef: Vec<f64> = inv
        .iter()
        .map(|r| r.iter().zip(v).map(|(a, b)| a * b).sum())
        .collect();
    let (&a, &b, &c) = (coef.first()?, coef.get(1)?, coef.get(2)?);
    if a.is_nan() || a >= 0.0 {
        return None;
    }
    let (lo, hi) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        });
    let vertex = (-b / (2.0 * a)).clamp(lo, hi);
    // Cov[a, b] = σ² (M⁻¹)[0..2, 0..2]; J = ∂x*/∂(a, b) = (b / 2a², −1 / 2a).
    let j = [b / (2.0 * a * a), -1.0 / (2.0 * a)];
    let mut var = 0.0;
    for (r, jr) in inv.iter().zip(j) {
        for (cv, jc) in r.iter().zip(j) {
            var += jr * cv * jc;
        }
    }
    Some(ParabolaFit {
        vertex,
        value: a * vertex * vertex + b * vertex + c,
        vertex_variance: sigma * sigma * var,
    })
}

/// Inverse of a 3×3 matrix by the adjugate, `None` if (nearly) singular.
fn invert3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let [[a, b, c], [d, e, f], [g, h, i]] = *m;
    let co = [
        [e * i - f * h, c * h - b * i, b * f - c * e],
        [f * g - d * i, a * i - c * g, c * d - a * f],
        [d * h - e * g, b * g - a * h, a * e - b * d],
    ];
    let det = a * co[0][0] + b * co[1][0] + c * co[2][0];
    let scale = m.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    if !det.is_finite() || det.abs() <= 1e-12 * scale.powi(3) {
        return None;
    }
    Some(co.map(|r| r.map(|x| x / det)))
}

/// The highest minimum on the paths between points `i` and `k` (both ways round if circular).
fn highest_valley(y: &[f64], i: usize, k: usize, circular: bool) -> f64 {
    let (lo, hi) = (i.min(k), i.max(k));
    let inner = y.get(lo..=hi).map_or(f64::NAN, |s| {
        s.iter().copied().fold(f64::INFINITY, f64::min)
    });
    if !circular {
        return inner;
    }
    let outer = y
        .get(hi..)
        .into_iter()
        .flatten()
        .chain(y.get(..=lo).into_iter().flatten())
        .copied()
        .fold(f64::INFINITY, f64::min);
    inner.max(outer)
}
