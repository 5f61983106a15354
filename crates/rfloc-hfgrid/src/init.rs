//! Initial pose from a 360° turn on the spot over a known tag grid.
//!
//! Maximum likelihood over `(x, y, θ₀)`, the robot pose at relative heading 0. At a stop with
//! relative heading `φ_k` the antenna sits at `(x, y) + R(θ₀ + φ_k)·a` (`a` = antenna offset in
//! the robot frame). Each stop contributes, for every known tag near the search region,
//! `log P(reported values | d)` (a mixture over the RSSI values seen at that stop) or, if it was
//! not reported, `log P(miss | d)`. The likelihood is searched on a coarse grid with edge-blurred
//! (tempered) likelihoods, then refined on a fine grid around the best cell with the model's own
//! edges; the estimate is the posterior mean over the fine window and the covariance its
//! posterior covariance (or the coarse posterior's when much mass lies outside the window).

use std::collections::HashMap;

use nalgebra::{Matrix3, Vector3};
use rfloc_pose::{angle_diff, wrap_angle, EstimateMode, Pose2, PoseEstimate};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::grid::{TagGrid, TagUid};
use crate::reading::TurnStop;
use crate::rssi::{LikelihoodTable, RssiModel, MAX_RSSI};

/// Solver settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct InitialPoseConfig {
    /// Antenna position in the robot frame, m (seed 002: 10 cm behind the centre → (−0.10, 0)).
    pub antenna_offset_m: (f64, f64),
    /// Coarse search step in position, m.
    pub coarse_step_m: f64,
    /// Coarse search step in heading, rad.
    pub coarse_heading_step_rad: f64,
    /// Fine grid points per half-window (the window spans ±3 coarse steps in each axis).
    pub fine_points_per_half: usize,
    /// Use tags that were *not* reported (negative information).
    pub use_non_detections: bool,
    /// Refuse with fewer stops that saw at least one known tag.
    pub min_usable_stops: usize,
    /// Refuse with fewer distinct known tags over the whole turn.
    pub min_distinct_tags: usize,
    /// Refuse when the usable stops cover less than this much heading (rad, circular span).
    pub min_heading_span_rad: f64,
    /// Refuse as ambiguous when the position standard deviation exceeds this (m).
    pub max_position_std_m: f64,
    /// Refuse as ambiguous when the heading standard deviation exceeds this (rad).
    pub max_heading_std_rad: f64,
}

impl Default for InitialPoseConfig {
    fn default() -> Self {
        Self {
            antenna_offset_m: (-0.10, 0.0),
            coarse_step_m: 0.008,
            coarse_heading_step_rad: 5f64.to_radians(),
            fine_points_per_half: 10,
            use_non_detections: true,
            min_usable_stops: 3,
            min_distinct_tags: 2,
            min_heading_span_rad: 90f64.to_radians(),
            max_position_std_m: 0.05,
            max_heading_std_rad: 45f64.to_radians(),
        }
    }
}

/// Why no initial pose was produced.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum InitError {
    /// No stops were given.
    #[error("no stops")]
    NoStops,
    /// A stop heading was NaN or infinite.
    #[error("stop {stop} has a non-finite heading")]
    NonFiniteHeading {
        /// Index of the stop.
        stop: usize,
    },
    /// Too few stops saw a known tag.
    #[error("{usable} usable stops, {required} required")]
    TooFewUsableStops {
        /// Stops with at least one known tag.
        usable: usize,
        /// Configured minimum.
        required: usize,
    },
    /// Too few distinct known tags were reported.
    #[error("{found} distinct known tags, {required} required")]
    TooFewDistinctTags {
        /// Distinct known tags.
        found: usize,
        /// Configured minimum.
        required: usize,
    },
    /// The usable stops cover too little of the turn.
    #[error("usable stops span {span_rad} rad of heading, {required_rad} required")]
    InsufficientHeadingSpan {
        /// Circular span covered.
        span_rad: f64,
        /// Configured minimum.
        required_rad: f64,
    },
    /// The posterior is too wide (several poses explain the readings).
    #[error("ambiguous: position std {position_std_m} m, heading std {heading_std_rad} rad")]
    Ambiguous {
        /// Posterior position standard deviation (largest axis), m.
        position_std_m: f64,
        /// Posterior heading standard deviation, rad.
        heading_std_rad: f64,
    },
    /// The configuration cannot work (non-positive steps, …).
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
}

/// The solver's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct InitialPose {
    /// Robot pose at relative heading 0 (the start of the turn), map frame.
    pub pose: Pose2,
    /// 3×3 covariance over `(x, y, θ)`.
    pub covariance: Matrix3<f64>,
    /// Stops that saw at least one known tag.
    pub stops_used: usize,
    /// Distinct known tags reported.
    pub distinct_tags: usize,
    /// Reports of UIDs not in the grid (ignored).
    pub unknown_reports: usize,
    /// Reports with an RSSI above 7 (ignored).
    pub invalid_reports: usize,
}

impl InitialPose {
    /// As a [`PoseEstimate`] stamped `time`.
    #[must_use]
    pub fn to_estimate(&self, time: f64) -> PoseEstimate {
        PoseEstimate {
            time,
            pose: self.pose,
            covariance: self.covariance,
            mode: EstimateMode::Fix,
            source: "hfgrid-init".into(),
        }
    }
}

/// Per stop: reported tags with their value histograms, and tags that were not reported.
struct StopEvidence {
    heading: f64,
    reported: Vec<((f64, f64), [f64; 8])>,
    missed: Vec<(f64, f64)>,
}

/// A known tag's pooled reports: UID, position (m) and the normalised histogram of RSSI values.
pub(crate) type PooledTag = (TagUid, (f64, f64), [f64; 8]);

/// Pools the reports of one stop into per-tag value histograms (known tags only).
/// Returns the pooled tags, the number of unknown-UID reports and of invalid-RSSI reports.
pub(crate) fn pool_reports(
    grid: &TagGrid,
    readings: &[crate::reading::TagReading],
) -> (Vec<PooledTag>, usize, usize) {
    let mut counts: HashMap<TagUid, [f64; 8]> = HashMap::new();
    let (mut unknown, mut invalid) = (0, 0);
    for r in readings {
        if r.rssi_first > MAX_RSSI {
            invalid += 1;
            continue;
        }
        if grid.position(r.uid).is_none() {
            unknown += 1;
            continue;
        }
        let h = counts.entry(r.uid).or_insert([0.0; 8]);
        if let Some(c) = h.get_mut(usize::from(r.rssi_first)) {
            *c += 1.0;
        }
    }
    let mut out: Vec<_> = counts
        .into_iter()
        .filter_map(|(uid, mut h)| {
            let total: f64 = h.iter().sum();
            h.iter_mut().for_each(|c| *c /= total);
            grid.position(uid).map(|p| (uid, p, h))
        })
        .collect();
    out.sort_unstable_by_key(|t| t.0);
    (out, unknown, invalid)
}

/// Circular span of a set of angles: 2π minus the largest gap between neighbours.
fn heading_span(headings: &[f64]) -> f64 {
    let mut h: Vec<f64> = headings
        .iter()
        .map(|a| a.rem_euclid(std::f64::consts::TAU))
        .collect();
    h.sort_by(f64::total_cmp);
    if h.len() < 2 {
        return 0.0;
    }
    let mut gap: f64 = 0.0;
    for w in h.windows(2) {
        if let [a, b] = w {
            gap = gap.max(b - a);
        }
    }
    if let (Some(first), Some(last)) = (h.first(), h.last()) {
        gap = gap.max(std::f64::consts::TAU - (last - first));
    }
    std::f64::consts::TAU - gap
}

/// Initial pose solver over a tag grid and an RSSI model.
#[derive(Debug, Clone)]
pub struct InitialPoseSolver {
    grid: TagGrid,
    model: RssiModel,
    config: InitialPoseConfig,
}

/// A regular 2-D lookup map of per-stop log-likelihood over antenna positions.
struct AntennaMap {
    x0: f64,
    y0: f64,
    res: f64,
    nx: usize,
    ny: usize,
    values: Vec<f64>,
}

impl AntennaMap {
    fn get(&self, x: f64, y: f64) -> f64 {
        let fx = ((x - self.x0) / self.res).round();
        let fy = ((y - self.y0) / self.res).round();
        if fx < 0.0 || fy < 0.0 {
            return f64::NEG_INFINITY;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (ix, iy) = (fx as usize, fy as usize);
        if ix >= self.nx || iy >= self.ny {
            return f64::NEG_INFINITY;
        }
        self.values
            .get(iy * self.nx + ix)
            .copied()
            .unwrap_or(f64::NEG_INFINITY)
    }
}

/// A stop's evidence with each reported tag's mixture log-likelihood tabulated over distance.
struct CompiledStop<'a> {
    heading: f64,
    reported: Vec<((f64, f64), Vec<f64>)>,
    missed: &'a [(f64, f64)],
}

fn compile<'a>(evidence: &'a [StopEvidence], table: &LikelihoodTable) -> Vec<CompiledStop<'a>> {
    evidence
        .iter()
        .map(|ev| CompiledStop {
            heading: ev.heading,
            reported: ev
                .reported
                .iter()
                .map(|(pos, w)| (*pos, table.report_curve(w)))
                .collect(),
            missed: &ev.missed,
        })
        .collect()
}

fn stop_log_likelihood(table: &LikelihoodTable, ev: &CompiledStop<'_>, ax: f64, ay: f64) -> f64 {
    let mut l = 0.0;
    for ((tx, ty), curve) in &ev.reported {
        l += table.at(curve, (tx - ax).hypot(ty - ay));
    }
    for (tx, ty) in ev.missed {
        l += table.log_miss((tx - ax).hypot(ty - ay));
    }
    l
}

#[allow(clippy::cast_precision_loss)]
fn steps(n: usize) -> f64 {
    n as f64
}

impl InitialPoseSolver {
    /// A solver for `grid` with RSSI model `model`.
    #[must_use]
    pub fn new(grid: TagGrid, model: RssiModel, config: InitialPoseConfig) -> Self {
        Self {
            grid,
            model,
            config,
        }
    }

    /// The grid in use.
    #[must_use]
    pub fn grid(&self) -> &TagGrid {
        &self.grid
    }

    /// Estimates the pose at the start of the turn from the readings of each stop.
    pub fn solve(&self, stops: &[TurnStop]) -> Result<InitialPose, InitError> {
        let c = &self.config;
        if !(c.coarse_step_m > 0.0 && c.coarse_heading_step_rad > 0.0 && c.fine_points_per_half > 0)
        {
            return Err(InitError::InvalidConfig("steps must be positive".into()));
        }
        if stops.is_empty() {
            return Err(InitError::NoStops);
        }
        if let Some(k) = stops.iter().position(|s| !s.heading_rad.is_finite()) {
            return Err(InitError::NonFiniteHeading { stop: k });
        }
        let (ax, ay) = c.antenna_offset_m;
        let arm = ax.hypot(ay);

        // Pool reports and find the region the centre can be in.
        let mut pooled = Vec::new();
        let (mut unknown, mut invalid) = (0, 0);
        let mut distinct: Vec<TagUid> = Vec::new();
        for s in stops {
            let (p, u, i) = pool_reports(&self.grid, &s.readings);
            unknown += u;
            invalid += i;
            distinct.extend(p.iter().map(|t| t.0));
            pooled.push((s.heading_rad, p));
        }
        distinct.sort_unstable();
        distinct.dedup();
        let usable: Vec<f64> = pooled
            .iter()
            .filter(|(_, p)| !p.is_empty())
            .map(|(h, _)| *h)
            .collect();
        if usable.len() < c.min_usable_stops {
            return Err(InitError::TooFewUsableStops {
                usable: usable.len(),
                required: c.min_usable_stops,
            });
        }
        if distinct.len() < c.min_distinct_tags {
            return Err(InitError::TooFewDistinctTags {
                found: distinct.len(),
                required: c.min_distinct_tags,
            });
        }
        let span = heading_span(&usable);
        if span + 1e-9 < c.min_heading_span_rad {
            return Err(InitError::InsufficientHeadingSpan {
                span_rad: span,
                required_rad: c.min_heading_span_rad,
            });
        }
        // The centre lies within `arm + range` of every reported tag: intersect those boxes
        // (falling back to their union if a stray report makes the intersection empty).
        let hard = arm + self.model.max_range_m() + 3.0 * self.model.edge_sigma_m + c.coarse_step_m;
        let (mut ix_lo, mut ix_hi, mut iy_lo, mut iy_hi) = (f64::MIN, f64::MAX, f64::MIN, f64::MAX);
        let (mut ux_lo, mut ux_hi, mut uy_lo, mut uy_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for (_, p) in &pooled {
            for (_, (x, y), _) in p {
                ix_lo = ix_lo.max(x - hard);
                ix_hi = ix_hi.min(x + hard);
                iy_lo = iy_lo.max(y - hard);
                iy_hi = iy_hi.min(y + hard);
                ux_lo = ux_lo.min(x - hard);
                ux_hi = ux_hi.max(x + hard);
                uy_lo = uy_lo.min(y - hard);
                uy_hi = uy_hi.max(y + hard);
            }
        }
        let (cx_lo, cx_hi, cy_lo, cy_hi) = if ix_lo < ix_hi && iy_lo < iy_hi {
            (ix_lo, ix_hi, iy_lo, iy_hi)
        } else {
            (ux_lo, ux_hi, uy_lo, uy_hi)
        };
        let coarse_table = LikelihoodTable::new(&self.model, c.coarse_step_m, 0.0005);
        let reach = coarse_table.reach_m;
        let mid = ((cx_lo + cx_hi) / 2.0, (cy_lo + cy_hi) / 2.0);
        let half_diag = ((cx_hi - cx_lo).hypot(cy_hi - cy_lo)) / 2.0;
        let nearby = self.grid.tags_within(mid.0, mid.1, half_diag + arm + reach);
        let evidence: Vec<StopEvidence> = pooled
            .iter()
            .map(|(h, p)| {
                let reported: Vec<_> = p.iter().map(|(_, pos, w)| (*pos, *w)).collect();
                let missed = if c.use_non_detections {
                    nearby
                        .iter()
                        .filter(|(uid, _, _)| !p.iter().any(|(u, _, _)| u == uid))
                        .map(|(_, x, y)| (*x, *y))
                        .collect()
                } else {
                    Vec::new()
                };
                StopEvidence {
                    heading: *h,
                    reported,
                    missed,
                }
            })
            .collect();

        // Coarse search with tempered likelihoods over per-stop antenna maps. Each map starts at
        // the "far from every reported tag" value and each tag stamps only the cells within reach.
        let res = c.coarse_step_m / 2.0;
        let (mx0, my0) = (cx_lo - arm - res, cy_lo - arm - res);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (mnx, mny) = (
            ((cx_hi - cx_lo + 2.0 * arm) / res).ceil() as usize + 3,
            ((cy_hi - cy_lo + 2.0 * arm) / res).ceil() as usize + 3,
        );
        let far = 10.0 * reach;
        let maps: Vec<AntennaMap> = evidence
            .iter()
            .map(|ev| {
                let base: f64 = ev
                    .reported
                    .iter()
                    .map(|(_, w)| coarse_table.log_report(w, far))
                    .sum();
                let mut values = vec![base; mnx * mny];
                let mut stamp = |tx: f64, ty: f64, f: &dyn Fn(f64) -> f64| {
                    let lo = |v: f64, o: f64| (((v - reach - o) / res).floor().max(0.0)) as usize;
                    let hi = |v: f64, o: f64, n: usize| {
                        ((((v + reach - o) / res).ceil().max(0.0)) as usize).min(n)
                    };
                    for iy in lo(ty, my0)..hi(ty, my0, mny) {
                        let y = my0 + steps(iy) * res;
                        for ix in lo(tx, mx0)..hi(tx, mx0, mnx) {
                            let d = (mx0 + steps(ix) * res - tx).hypot(y - ty);
                            if d <= reach {
                                if let Some(v) = values.get_mut(iy * mnx + ix) {
                                    *v += f(d);
                                }
                            }
                        }
                    }
                };
                for ((tx, ty), w) in &ev.reported {
                    let far_value = coarse_table.log_report(w, far);
                    stamp(*tx, *ty, &|d| coarse_table.log_report(w, d) - far_value);
                }
                for (tx, ty) in &ev.missed {
                    stamp(*tx, *ty, &|d| coarse_table.log_miss(d));
                }
                AntennaMap {
                    x0: mx0,
                    y0: my0,
                    res,
                    nx: mnx,
                    ny: mny,
                    values,
                }
            })
            .collect();
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (nx, ny, nh) = (
            ((cx_hi - cx_lo) / c.coarse_step_m).ceil() as usize + 1,
            ((cy_hi - cy_lo) / c.coarse_step_m).ceil() as usize + 1,
            (std::f64::consts::TAU / c.coarse_heading_step_rad)
                .round()
                .max(1.0) as usize,
        );
        let hstep = std::f64::consts::TAU / steps(nh);
        let mut coarse: Vec<(f64, f64, f64, f64)> = Vec::with_capacity(nx * ny * nh);
        for ih in 0..nh {
            let th = -std::f64::consts::PI + steps(ih) * hstep;
            let offsets: Vec<(f64, f64)> = evidence
                .iter()
                .map(|ev| {
                    let (s, co) = (th + ev.heading).sin_cos();
                    (co * ax - s * ay, s * ax + co * ay)
                })
                .collect();
            for iy in 0..ny {
                let y = cy_lo + steps(iy) * c.coarse_step_m;
                for ix in 0..nx {
                    let x = cx_lo + steps(ix) * c.coarse_step_m;
                    let l: f64 = maps
                        .iter()
                        .zip(&offsets)
                        .map(|(m, (ox, oy))| m.get(x + ox, y + oy))
                        .sum();
                    coarse.push((x, y, th, l));
                }
            }
        }
        let best = coarse
            .iter()
            .copied()
            .filter(|t| t.3.is_finite())
            .max_by(|a, b| a.3.total_cmp(&b.3))
            .ok_or_else(|| InitError::InvalidConfig("empty search region".into()))?;

        // Fine window around the best coarse cell, with the model's own edges.
        let fine_table = LikelihoodTable::new(&self.model, 0.0, 0.0002);
        let half_xy = 3.0 * c.coarse_step_m;
        let half_h = 3.0 * hstep;
        let nf = c.fine_points_per_half;
        let fxy = half_xy / steps(nf);
        let fh = half_h / steps(nf);
        let compiled = compile(&evidence, &fine_table);
        let mut fine = Vec::with_capacity((2 * nf + 1).pow(3));
        for ih in 0..=(2 * nf) {
            let th = best.2 - half_h + steps(ih) * fh;
            for iy in 0..=(2 * nf) {
                let y = best.1 - half_xy + steps(iy) * fxy;
                for ix in 0..=(2 * nf) {
                    let x = best.0 - half_xy + steps(ix) * fxy;
                    let l: f64 = compiled
                        .iter()
                        .map(|ev| {
                            let (s, co) = (th + ev.heading).sin_cos();
                            stop_log_likelihood(
                                &fine_table,
                                ev,
                                x + co * ax - s * ay,
                                y + s * ax + co * ay,
                            )
                        })
                        .sum();
                    fine.push((x, y, th, l));
                }
            }
        }
        let (mean, cov_fine) = moments(&fine, best.2, (fxy, fxy, fh))
            .ok_or_else(|| InitError::InvalidConfig("degenerate fine posterior".into()))?;
        // Coarse (tempered) posterior: how much mass lies outside the fine window?
        let (_, cov_coarse) =
            moments(&coarse, mean.z, (c.coarse_step_m, c.coarse_step_m, hstep))
                .ok_or_else(|| InitError::InvalidConfig("degenerate coarse posterior".into()))?;
        let lmax = best.3;
        let (mut inside, mut total) = (0.0, 0.0);
        for &(x, y, th, l) in coarse.iter().filter(|s| s.3 - lmax > -30.0) {
            let w = (l - lmax).exp();
            total += w;
            if (x - best.0).abs() <= half_xy
                && (y - best.1).abs() <= half_xy
                && angle_diff(th, best.2).abs() <= half_h
            {
                inside += w;
            }
        }
        let outside_fraction = if total > 0.0 {
            1.0 - inside / total
        } else {
            1.0
        };
        let covariance = if outside_fraction > 0.05 {
            cov_coarse
        } else {
            cov_fine
        };
        let pos_std = covariance
            .fixed_view::<2, 2>(0, 0)
            .symmetric_eigenvalues()
            .max()
            .max(0.0)
            .sqrt();
        let head_std = covariance[(2, 2)].max(0.0).sqrt();
        if pos_std > c.max_position_std_m || head_std > c.max_heading_std_rad {
            return Err(InitError::Ambiguous {
                position_std_m: pos_std,
                heading_std_rad: head_std,
            });
        }
        Ok(InitialPose {
            pose: Pose2::new(mean.x, mean.y, mean.z),
            covariance,
            stops_used: usable.len(),
            distinct_tags: distinct.len(),
            unknown_reports: unknown,
            invalid_reports: invalid,
        })
    }
}

/// Posterior mean and covariance of weighted samples `(x, y, θ, log w)`; θ is taken relative to
/// `theta_ref` (wrapped) so the moments are local. Adds the grid quantisation `step²/12`.
fn moments(
    samples: &[(f64, f64, f64, f64)],
    theta_ref: f64,
    step: (f64, f64, f64),
) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    let lmax = samples
        .iter()
        .map(|s| s.3)
        .filter(|l| l.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if !lmax.is_finite() {
        return None;
    }
    // Samples more than e^-30 below the maximum contribute nothing measurable.
    let kept: Vec<_> = samples.iter().filter(|s| s.3 - lmax > -30.0).collect();
    let mut wsum = 0.0;
    let mut m = Vector3::zeros();
    for &&(x, y, th, l) in &kept {
        let w = (l - lmax).exp();
        wsum += w;
        m += w * Vector3::new(x, y, angle_diff(th, theta_ref));
    }
    if wsum <= 0.0 {
        return None;
    }
    m /= wsum;
    let mut cov = Matrix3::zeros();
    for &&(x, y, th, l) in &kept {
        let w = (l - lmax).exp() / wsum;
        let d = Vector3::new(x - m.x, y - m.y, angle_diff(th, theta_ref) - m.z);
        cov += w * d * d.transpose();
    }
    cov += Matrix3::from_diagonal(&Vector3::new(
        step.0 * step.0,
        step.1 * step.1,
        step.2 * step.2,
    )) / 12.0;
    Some((Vector3::new(m.x, m.y, wrap_angle(theta_ref + m.z)), cov))
}
