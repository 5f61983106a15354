//! The tag map and the exploration trajectory learned together.
//!
//! [`TagMap::learn`] places every tag from the poses the robot believed it had (odometry). The
//! odometry drifts (wheel slip the encoders do not see), so on a large floor a tag read on two
//! visits is placed between two inconsistent frames, and the map error grows with the explored
//! area (a 20 × 20 m hall: 1.2 m median). [`learn_jointly`] estimates the poses and the tags
//! together:
//!
//! - **Pose factors.** A pose whose snapshot read at least [`JointConfig::min_mapped`] mapped
//!   tags gets a Gaussian factor: the read tags' likelihood under the reader model over a coarse
//!   pose grid around the pose (recentred when the best cell is on its edge), the mean refined on
//!   a fine grid, the covariance the coarse grid's spread plus a floor for the map's own error
//!   ([`JointConfig::floor_xy`], [`JointConfig::floor_theta`]: one snapshot says little about
//!   the heading).
//! - **Forward pass.** The trajectory is processed in chunks of [`JointConfig::chunk`] steps.
//!   Within a chunk, a Kalman filter on the pose predicts each pose from the one before and its
//!   odometry increment (covariance from the odometry noise model) and updates it with its factor
//!   on the map of the tags placed before the chunk, unless the factor lies more than
//!   [`JointConfig::gate`] σ from the prediction; after [`JointConfig::relock_after`] rejections
//!   in a row the next factor is taken (the prediction is lost). Then the tags the chunk read are
//!   placed again from all poses so far (reads and misses, as [`TagMap::learn`] does, searched
//!   around their last position). A revisit thus ties the new poses to the map made on the first
//!   visit instead of blurring it, and the error stays bounded by the map, not the distance
//!   driven.
//! - **Rounds.** [`JointConfig::rounds`] times: the whole chain is smoothed (odometry factors and
//!   the accepted pose factors, Huber-weighted; Levenberg–Marquardt on the block-tridiagonal
//!   normal equations, solved exactly in O(n), a step taken only when it lowers the cost, the
//!   first pose fixed), every tag is placed again, and the factors are computed again on the new
//!   map (gated against the smoothed poses).
//! - **Pose-graph rounds.** The rounds move each pose towards a map placed from the poses
//!   themselves, so a map bent on the first visit of a place (the odometry's heading drift)
//!   stays bent: the poses of a revisit follow it. [`JointConfig::closure_rounds`] times, the
//!   factors are computed on the current map and turned into **closures**: for every
//!   [`JointConfig::closure_stride`]-th pose, the relative pose to the earlier pose (at least
//!   [`JointConfig::closure_gap`] steps before) that read the most of the same tags, taken from
//!   the two factors' means (both on one map, so where the map is off the two are off alike)
//!   with their covariances propagated. The trajectory is then optimised over the odometry and
//!   the closures alone (a pose graph; Levenberg–Marquardt with conjugate gradients
//!   preconditioned by the chain, module `posegraph`), which lets whole regions of the map
//!   rotate and shift together as the loops demand, and every tag is placed again.
//! - **Frame.** Finally poses and tags are moved rigidly so that the first
//!   [`JointConfig::anchor_steps`] poses lie on their odometry (the frame of a live robot's
//!   start).
//!
//! Units: metres, radians.

use nalgebra::{Matrix3, Vector3};
use rfloc_pose::{angle_diff, Pose2};
use serde::{Deserialize, Serialize};

use crate::posegraph::{factor_error, relative_jacobians, Closure, Graph, PoseFactor as Factor};
use crate::snapshot::Snapshot;
use crate::tagmap::{
    LikelihoodScratch, MapObservation, MappedTag, Mapper, PoseIndex, ReadModel, TagMap,
    TagMapConfig,
};

/// Settings of the joint learning.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointConfig {
    /// Exploration steps per chunk of the forward pass.
    pub chunk: usize,
    /// Rounds over the whole trajectory after the forward pass.
    pub rounds: usize,
    /// Odometry increment noise: σ of translation, constant (m) and per metre moved.
    pub odo_trans_abs: f64,
    pub odo_trans_rel: f64,
    /// σ of rotation: constant (rad), per radian turned, per metre moved.
    pub odo_rot_abs: f64,
    pub odo_rot_rel: f64,
    pub odo_rot_per_m: f64,
    /// Half-width and step of the coarse pose grid of a factor (m, m; rad, rad).
    pub search_xy: f64,
    pub step_xy: f64,
    pub search_theta: f64,
    pub step_theta: f64,
    /// A factor's information is multiplied by this (neighbouring poses share map errors).
    pub factor_weight: f64,
    /// σ added to a factor's spread for the map's own error (m, rad).
    pub floor_xy: f64,
    pub floor_theta: f64,
    /// Mahalanobis distance beyond which a factor is down-weighted (Huber).
    pub huber: f64,
    /// Tags that place a pose in the forward pass: position σ at most this (m) and read in
    /// at least this many snapshots.
    pub max_tag_sigma: f64,
    pub min_tag_reads: usize,
    /// Whether a factor counts the misses of mapped tags in view (not only the reads).
    pub misses: bool,
    /// A pose gets a factor when its snapshot read at least this many mapped tags.
    pub min_mapped: usize,
    /// Levenberg–Marquardt iterations per smoothing.
    pub gauss_newton: usize,
    /// After this many factors rejected in a row, the next one is taken (the pose is lost).
    pub relock_after: usize,
    /// The learned frame is the one in which the first this many poses lie on their odometry.
    pub anchor_steps: usize,
    /// The odometry is assumed to drift by at most this plus this fraction of the distance
    /// driven (m, 1); a trajectory further away has diverged.
    pub max_drift_m: f64,
    pub max_drift_rel: f64,
    /// Mahalanobis distance beyond which a factor is rejected (it disagrees with the pose
    /// predicted from the odometry by more than their uncertainties allow).
    pub gate: f64,
    /// In the forward pass, a tag places a pose only when it was first read at least this
    /// many steps before (a place seen again): tags first seen on the same stretch of driving
    /// were placed from the poses the factor would correct, and only add their bias.
    pub revisit_steps: usize,
    /// When the learning diverges, it is tried once more with this `revisit_steps` (the two
    /// fail on different explorations) before falling back to the odometry.
    pub retry_revisit_steps: usize,
    /// Pose-graph rounds after the rounds: the trajectory is optimised over the odometry and
    /// relative-pose closures between visits of one place (the map's unary factors only with
    /// weight [`JointConfig::closure_unary_weight`]), then every tag placed again.
    pub closure_rounds: usize,
    /// Two poses form a closure only when at least this many steps apart.
    pub closure_gap: usize,
    /// One closure per this many poses.
    pub closure_stride: usize,
    /// ... and only when the two read at least this many of the same mapped tags.
    pub closure_min_shared: usize,
    /// Weight of the unary map factors in the pose-graph rounds.
    pub closure_unary_weight: f64,
}

impl Default for JointConfig {
    fn default() -> Self {
        Self {
            chunk: 50,
            rounds: 2,
            odo_trans_abs: 0.003,
            odo_trans_rel: 0.02,
            odo_rot_abs: 0.003,
            odo_rot_rel: 0.02,
            odo_rot_per_m: 0.02,
            search_xy: 0.16,
            step_xy: 0.04,
            search_theta: 0.12,
            step_theta: 0.04,
            factor_weight: 1.0,
            floor_xy: 0.04,
            floor_theta: 0.15,
            huber: 2.0,
            min_mapped: 3,
            misses: true,
            max_tag_sigma: 0.08,
            min_tag_reads: 6,
            gauss_newton: 6,
            gate: 4.0,
            anchor_steps: 50,
            relock_after: 25,
            max_drift_m: 1.0,
            max_drift_rel: 0.02,
            revisit_steps: 0,
            retry_revisit_steps: 30,
            closure_rounds: 2,
            closure_gap: 50,
            closure_stride: 4,
            closure_min_shared: 4,
            closure_unary_weight: 0.0,
        }
    }
}

/// What the joint learning did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JointReport {
    /// Chunks of the forward pass and rounds after it.
    pub chunks: usize,
    pub rounds: usize,
    /// Poses with a factor in the last round.
    pub factors: usize,
    /// Mean distance of the final poses from the odometry poses, m.
    pub mean_correction_m: f64,
    /// Largest distance of the final poses from the odometry poses, m.
    pub max_correction_m: f64,
    /// Factors the gate rejected in the forward pass.
    pub rejected: usize,
    /// Times the forward filter took a factor after `relock_after` rejections in a row.
    pub relocks: usize,
    /// The trajectory left the odometry by more than `max_drift_m + max_drift_rel · distance`:
    /// the result is the odometry and the map along it.
    pub diverged: bool,
    /// Mean change of the poses in the last round, m.
    pub last_round_change_m: f64,
    /// The first attempt diverged and this is the second, with `retry_revisit_steps`.
    pub retried: bool,
    /// Closures of the last pose-graph round.
    pub closures: usize,
}

/// Learns the tag map and the poses of `samples` (snapshot, odometry pose) together (see the
/// module documentation). Returns the map, one pose per sample, and a report. The first pose
/// is kept (it anchors the frame).
#[must_use]
pub fn learn_jointly(
    samples: &[(&Snapshot, Pose2)],
    model: ReadModel,
    config: TagMapConfig,
    joint: &JointConfig,
) -> (TagMap, Vec<Pose2>, JointReport) {
    let retries = joint.retry_revisit_steps != joint.revisit_steps;
    // The odometry fallback is the same whatever the settings: placed once, by the last attempt.
    let first = learn_attempt(samples, model.clone(), config, joint, !retries);
    if !first.2.diverged || !retries {
        return first;
    }
    let retry = JointConfig {
        revisit_steps: joint.retry_revisit_steps,
        ..*joint
    };
    let (map, poses, mut report) = learn_attempt(samples, model, config, &retry, true);
    if report.diverged {
        // Both diverged: the odometry and its map, reported as the first attempt.
        let fallback = JointReport {
            mean_correction_m: report.mean_correction_m,
            max_correction_m: report.max_correction_m,
            ..first.2
        };
        return (map, poses, fallback);
    }
    report.retried = true;
    (map, poses, report)
}

/// One attempt of [`learn_jointly`] with these settings; when it diverges and `fallback` is
/// set, the result is the odometry and the map placed along it (otherwise the diverged
/// trajectory, flagged).
fn learn_attempt(
    samples: &[(&Snapshot, Pose2)],
    model: ReadModel,
    config: TagMapConfig,
    joint: &JointConfig,
    fallback: bool,
) -> (TagMap, Vec<Pose2>, JointReport) {
    let snapshots: Vec<&Snapshot> = samples.iter().map(|(s, _)| *s).collect();
    let odometry: Vec<Pose2> = samples.iter().map(|(_, p)| *p).collect();
    let n = odometry.len();
    let mapper = Mapper::new(&snapshots, model, config);
    let mut report = JointReport::default();
    if n == 0 {
        return (mapper.build(&[]), Vec::new(), report);
    }
    let increments: Vec<Pose2> = odometry
        .windows(2)
        .filter_map(|w| Some(w.get(1)?.relative_to(w.first()?)))
        .collect();
    let odo_info: Vec<Matrix3<f64>> = increments
        .iter()
        .map(|u| odometry_information(u, joint))
        .collect();
    // The mapped tags each snapshot read (mapper indices).
    let mut read_by: Vec<Vec<usize>> = vec![Vec::new(); n];
    for k in 0..mapper.tag_count() {
        for (i, _) in mapper.reads_of(k) {
            if let Some(v) = read_by.get_mut(*i) {
                v.push(k);
            }
        }
    }
    let mut poses = odometry.clone();
    let mut located: Vec<Option<MappedTag>> = vec![None; mapper.tag_count()];
    let mut factors: Vec<Option<Factor>> = vec![None; n];
    let mut work = FactorWork::default();
    let chunk = joint.chunk.max(1);

    // Forward pass: a Kalman filter on the pose (odometry prediction, map factor update,
    // gated), the map of everything placed before the chunk; then the chunk's tags placed.
    let first_read: Vec<usize> = (0..mapper.tag_count())
        .map(|k| mapper.reads_of(k).first().map_or(usize::MAX, |(i, _)| *i))
        .collect();
    let mut cov = Matrix3::<f64>::zeros();
    let mut start = 0;
    while start < n {
        let end = (start + chunk).min(n);
        let seen_before = start.saturating_sub(joint.revisit_steps);
        let map = mapper.build_from(
            located
                .iter()
                .zip(&first_read)
                .filter(|(_, first)| joint.revisit_steps == 0 || **first < seen_before)
                .filter_map(|(t, _)| t.as_ref())
                .filter(|t| t.sigma <= joint.max_tag_sigma && t.reads >= joint.min_tag_reads)
                .cloned(),
        );
        filter_steps(
            &map,
            &snapshots,
            &increments,
            start..end,
            &mut poses,
            &mut cov,
            &mut factors,
            joint,
            &mut work,
            &mut report,
        );
        // Place the tags the chunk read, from every pose so far.
        let index = mapper.index(poses.get(..end).unwrap_or(&[]));
        let mut affected = vec![false; located.len()];
        for ks in read_by.get(start..end).unwrap_or(&[]) {
            for &k in ks {
                if let Some(a) = affected.get_mut(k) {
                    *a = true;
                }
            }
        }
        place_again(&mapper, &index, &mut located, |k| {
            affected.get(k).copied().unwrap_or(false)
        });
        report.chunks += 1;
        start = end;
    }
    report.factors = factors.iter().flatten().count();
    // Rounds: smooth the whole chain with the factors, place every tag again, and compute
    // the factors again on the new map (gated against the smoothed poses).
    for round in 0..joint.rounds {
        let before = poses.clone();
        smooth(&mut poses, &increments, &odo_info, &factors, joint);
        place_again(&mapper, &mapper.index(&poses), &mut located, |_| true);
        report.rounds += 1;
        #[allow(clippy::cast_precision_loss)]
        {
            report.last_round_change_m = poses
                .iter()
                .zip(&before)
                .map(|(a, b)| a.distance(b))
                .sum::<f64>()
                / n as f64;
        }
        if round + 1 < joint.rounds {
            let map = mapper.build(&located);
            gated_factors(&map, &snapshots, &poses, joint, &mut work, &mut factors);
            report.factors = factors.iter().flatten().count();
        }
    }
    // Pose-graph rounds: closures between visits of one place, from the factors on the
    // current map; the whole trajectory moves to agree with them and the odometry.
    for _ in 0..joint.closure_rounds {
        let map = mapper.build(&located);
        gated_factors(&map, &snapshots, &poses, joint, &mut work, &mut factors);
        let closures = closures(&factors, &read_by, &mapper, joint);
        report.closures = closures.len();
        if closures.is_empty() {
            // Nothing ties the visits together: the rounds' trajectory stands (the odometry
            // alone would only undo their corrections).
            break;
        }
        let unary: Vec<Option<Factor>> = factors
            .iter()
            .map(|f| {
                f.filter(|_| joint.closure_unary_weight > 0.0)
                    .map(|f| Factor {
                        mean: f.mean,
                        info: f.info * joint.closure_unary_weight,
                    })
            })
            .collect();
        Graph {
            increments: &increments,
            odo_info: &odo_info,
            factors: &unary,
            closures: &closures,
            huber: joint.huber,
        }
        .optimise(&mut poses, joint.gauss_newton);
        place_again(&mapper, &mapper.index(&poses), &mut located, |_| true);
        report.rounds += 1;
    }
    // The frame: the rigid motion that puts the first `anchor_steps` poses on their odometry
    // (which has not drifted yet there), applied to the poses and the tags.
    // The first poses where the final map puts them (their factors), against their odometry.
    let m = joint.anchor_steps.clamp(1, n);
    let map = mapper.build(&located);
    let (mut placed, mut believed) = (Vec::new(), Vec::new());
    for ((p, o), s) in poses.iter().zip(&odometry).zip(&snapshots).take(m) {
        if let Some(f) = factor(&map, &map.observe(s), p, joint, &mut work) {
            placed.push(f.mean);
            believed.push(*o);
        }
    }
    if placed.len() >= 3 {
        let frame = align(&placed, &believed);
        for q in &mut poses {
            *q = frame.compose(q);
        }
        for t in located.iter_mut().flatten() {
            let (x, y) = frame.transform_point(t.x, t.y);
            t.x = x;
            t.y = y;
        }
    }
    // A trajectory that left its odometry by more than the odometry can drift (a constant
    // plus a fraction of the distance driven) has diverged: keep the odometry and the map
    // along it instead.
    let mut driven = 0.0;
    let mut diverged = false;
    for (i, (p, o)) in poses.iter().zip(&odometry).enumerate() {
        if let Some(u) = i.checked_sub(1).and_then(|k| increments.get(k)) {
            driven += u.x.hypot(u.y);
        }
        if p.distance(o) > joint.max_drift_m + joint.max_drift_rel * driven || !p.is_finite() {
            diverged = true;
            break;
        }
    }
    report.diverged = diverged;
    if diverged && fallback {
        poses.clone_from(&odometry);
        let index = mapper.index(&poses);
        for (k, slot) in located.iter_mut().enumerate() {
            *slot = mapper.locate_tag(k, &index, None);
        }
    }
    let corrections: Vec<f64> = poses
        .iter()
        .zip(&odometry)
        .map(|(a, b)| a.distance(b))
        .collect();
    #[allow(clippy::cast_precision_loss)]
    {
        report.mean_correction_m = corrections.iter().sum::<f64>() / n as f64;
    }
    report.max_correction_m = corrections.iter().copied().fold(0.0, f64::max);
    (mapper.build(&located), poses, report)
}

/// The forward filter over `range`: each pose predicted from the one before and its odometry
/// increment (covariance `cov` propagated), then updated with its factor on `map` unless the
/// gate rejects it; accepted factors are kept in `factors`.
#[allow(clippy::too_many_arguments)]
fn filter_steps(
    map: &TagMap,
    snapshots: &[&Snapshot],
    increments: &[Pose2],
    range: std::ops::Range<usize>,
    poses: &mut [Pose2],
    cov: &mut Matrix3<f64>,
    factors: &mut [Option<Factor>],
    joint: &JointConfig,
    work: &mut FactorWork,
    report: &mut JointReport,
) {
    for i in range {
        if i > 0 {
            let (Some(prev), Some(u)) = (poses.get(i - 1).copied(), increments.get(i - 1)) else {
                continue;
            };
            let (s, c) = prev.theta.sin_cos();
            let f = Matrix3::new(
                1.0,
                0.0,
                -s * u.x - c * u.y,
                0.0,
                1.0,
                c * u.x - s * u.y,
                0.0,
                0.0,
                1.0,
            );
            let g = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
            let q = odometry_information(u, joint)
                .try_inverse()
                .unwrap_or_else(Matrix3::zeros);
            *cov = f * *cov * f.transpose() + g * q * g.transpose();
            if let Some(p) = poses.get_mut(i) {
                *p = prev.compose(u);
            }
        }
        let (Some(pred), Some(snap)) = (poses.get(i).copied(), snapshots.get(i)) else {
            continue;
        };
        let obs = map.observe(snap);
        let Some(fac) = factor(map, &obs, &pred, joint, work) else {
            continue;
        };
        let Some(r) = fac.info.try_inverse() else {
            continue;
        };
        let e = Vector3::new(
            fac.mean.x - pred.x,
            fac.mean.y - pred.y,
            angle_diff(fac.mean.theta, pred.theta),
        );
        let Some(s_inv) = (*cov + r).try_inverse() else {
            continue;
        };
        let mut s_inv = s_inv;
        if (e.transpose() * s_inv * e).x > joint.gate * joint.gate {
            report.rejected += 1;
            work.rejected_streak += 1;
            if work.rejected_streak < joint.relock_after.max(1) {
                continue;
            }
            // The map has disagreed with the prediction for a while: the prediction is lost
            // (it drifted beyond the gate). Take the map's word for it.
            *cov += r * 100.0;
            let Some(inv) = (*cov + r).try_inverse() else {
                continue;
            };
            s_inv = inv;
            report.relocks += 1;
        }
        work.rejected_streak = 0;
        let k = *cov * s_inv;
        let d = k * e;
        if let Some(p) = poses.get_mut(i) {
            *p = Pose2::new(pred.x + d.x, pred.y + d.y, pred.theta + d.z);
        }
        *cov = (Matrix3::identity() - k) * *cov;
        *cov = 0.5 * (*cov + cov.transpose());
        if let Some(slot) = factors.get_mut(i) {
            *slot = Some(fac);
        }
    }
}

/// The rigid motion `T` (as a pose) that minimises `Σ |T ∘ from_i − to_i|²` over the positions,
/// with the rotation taken from the positions when they spread more than 0.5 m, otherwise from
/// the mean heading difference.
fn align(from: &[Pose2], to: &[Pose2]) -> Pose2 {
    #[allow(clippy::cast_precision_loss)]
    let k = from.len().max(1) as f64;
    let mean = |v: &[Pose2]| {
        (
            v.iter().map(|p| p.x).sum::<f64>() / k,
            v.iter().map(|p| p.y).sum::<f64>() / k,
        )
    };
    let ((fx, fy), (tx, ty)) = (mean(from), mean(to));
    let (mut sxx, mut sxy, mut spread) = (0.0, 0.0, 0.0_f64);
    for (a, b) in from.iter().zip(to) {
        let (ax, ay, bx, by) = (a.x - fx, a.y - fy, b.x - tx, b.y - ty);
        sxx += ax * bx + ay * by;
        sxy += ax * by - ay * bx;
        spread = spread.max(ax.hypot(ay));
    }
    let theta = if spread > 0.5 {
        sxy.atan2(sxx)
    } else {
        let (s, c) = from.iter().zip(to).fold((0.0, 0.0), |(s, c), (a, b)| {
            let d = angle_diff(b.theta, a.theta);
            (s + d.sin(), c + d.cos())
        });
        f64::atan2(s, c)
    };
    let (s, c) = theta.sin_cos();
    Pose2::new(tx - (c * fx - s * fy), ty - (s * fx + c * fy), theta)
}

/// Information (inverse covariance) of an odometry increment.
fn odometry_information(u: &Pose2, j: &JointConfig) -> Matrix3<f64> {
    let dist = u.x.hypot(u.y);
    let st = j.odo_trans_abs + j.odo_trans_rel * dist;
    let sr = j.odo_rot_abs + j.odo_rot_rel * u.theta.abs() + j.odo_rot_per_m * dist;
    Matrix3::from_diagonal(&Vector3::new(
        1.0 / (st * st).max(1e-12),
        1.0 / (st * st).max(1e-12),
        1.0 / (sr * sr).max(1e-12),
    ))
}

/// Buffers of the factor computations.
#[derive(Debug, Default)]
struct FactorWork {
    candidates: Vec<Pose2>,
    scores: Vec<(f64, f64)>,
    scratch: LikelihoodScratch,
    /// Factors the forward filter's gate rejected in a row.
    rejected_streak: usize,
}

/// Scores `w.candidates` into `w.scores`: the read tags' terms, plus the misses with
/// [`JointConfig::misses`].
fn score(map: &TagMap, obs: &MapObservation, j: &JointConfig, w: &mut FactorWork) {
    if j.misses {
        map.log_likelihoods_unpacked(&w.candidates, obs, &mut w.scratch, &mut w.scores);
    } else {
        map.read_log_likelihoods(&w.candidates, obs, &mut w.scratch, &mut w.scores);
    }
}

/// The poses of a grid of `(2·nx + 1)² (2·nt + 1)` around `c`.
fn grid(c: &Pose2, step: f64, nx: i32, step_t: f64, nt: i32, out: &mut Vec<Pose2>) {
    out.clear();
    for ix in -nx..=nx {
        for iy in -nx..=nx {
            for it in -nt..=nt {
                out.push(Pose2::new(
                    c.x + f64::from(ix) * step,
                    c.y + f64::from(iy) * step,
                    c.theta + f64::from(it) * step_t,
                ));
            }
        }
    }
}

/// The factor of one pose: the read tags' likelihood over a coarse grid around `center`
/// (moved to the best cell when that lies on the grid's edge, at most twice), then a fine grid
/// around the best coarse cell; mean and covariance of the normalised likelihood.
fn factor(
    map: &TagMap,
    obs: &MapObservation,
    center: &Pose2,
    j: &JointConfig,
    w: &mut FactorWork,
) -> Option<Factor> {
    if obs.mapped < j.min_mapped.max(1) {
        return None;
    }
    #[allow(clippy::cast_possible_truncation)]
    let nx = (j.search_xy / j.step_xy.max(1e-3)).round().clamp(1.0, 20.0) as i32;
    #[allow(clippy::cast_possible_truncation)]
    let nt = (j.search_theta / j.step_theta.max(1e-3))
        .round()
        .clamp(1.0, 20.0) as i32;
    let mut c = *center;
    let mut best = c;
    for attempt in 0..3 {
        grid(&c, j.step_xy, nx, j.step_theta, nt, &mut w.candidates);
        score(map, obs, j, w);
        let (k, _) = w
            .scores
            .iter()
            .enumerate()
            .max_by(|a, b| a.1 .0.total_cmp(&b.1 .0))?;
        best = *w.candidates.get(k)?;
        let on_edge = (best.x - c.x).abs() > j.search_xy - 1e-9
            || (best.y - c.y).abs() > j.search_xy - 1e-9
            || (best.theta - c.theta).abs() > j.search_theta - 1e-9;
        if !on_edge || attempt == 2 {
            break;
        }
        c = best;
    }
    // The spread: the coarse grid's normalised likelihood about its best cell, plus the
    // grid's resolution.
    let (_, spread) = moments(&w.candidates, &w.scores, &best)?;
    // The mean: a fine grid, a quarter of the coarse steps, two steps either side.
    let (fs, ft) = (j.step_xy / 4.0, j.step_theta / 4.0);
    grid(&best, fs, 2, ft, 2, &mut w.candidates);
    score(map, obs, j, w);
    let (m, _) = moments(&w.candidates, &w.scores, &best)?;
    let (cs, ct) = (j.step_xy, j.step_theta);
    // The map's own error (the likelihood's shape assumes exact tag positions): a floor.
    let cov = spread
        + Matrix3::from_diagonal(&Vector3::new(
            cs * cs / 12.0 + j.floor_xy * j.floor_xy,
            cs * cs / 12.0 + j.floor_xy * j.floor_xy,
            ct * ct / 12.0 + j.floor_theta * j.floor_theta,
        ));
    let info = cov.try_inverse()? * j.factor_weight.max(0.0);
    Some(Factor {
        mean: Pose2::new(best.x + m.x, best.y + m.y, best.theta + m.z),
        info: 0.5 * (info + info.transpose()),
    })
}

/// Mean offset from `about` and covariance of the normalised likelihoods `scores` of
/// `candidates`.
fn moments(
    candidates: &[Pose2],
    scores: &[(f64, f64)],
    about: &Pose2,
) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    let top = scores.iter().map(|s| s.0).fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() {
        return None;
    }
    let (mut sw, mut m, mut mm) = (0.0, Vector3::zeros(), Matrix3::zeros());
    for (p, s) in candidates.iter().zip(scores) {
        let e = Vector3::new(
            p.x - about.x,
            p.y - about.y,
            angle_diff(p.theta, about.theta),
        );
        let wt = (s.0 - top).exp();
        sw += wt;
        m += wt * e;
        mm += wt * e * e.transpose();
    }
    if sw <= 0.0 {
        return None;
    }
    m /= sw;
    let cov = mm / sw - m * m.transpose();
    Some((m, 0.5 * (cov + cov.transpose())))
}

/// Places again the tags `k` with `which(k)` from the poses of `index`, each searched around
/// its last position (kept where the search finds nothing).
fn place_again(
    mapper: &Mapper<'_>,
    index: &PoseIndex,
    located: &mut [Option<MappedTag>],
    which: impl Fn(usize) -> bool,
) {
    for (k, slot) in located.iter_mut().enumerate() {
        if which(k) {
            let warm = slot.as_ref().map(|t| (t.x, t.y));
            *slot = mapper.locate_tag(k, index, warm).or(slot.take());
        }
    }
}

/// The factor of every pose on `map`, kept when within the gate of the pose.
fn gated_factors(
    map: &TagMap,
    snapshots: &[&Snapshot],
    poses: &[Pose2],
    joint: &JointConfig,
    work: &mut FactorWork,
    factors: &mut [Option<Factor>],
) {
    let gate = joint.gate * joint.gate;
    for ((slot, p), s) in factors.iter_mut().zip(poses).zip(snapshots) {
        *slot = factor(map, &map.observe(s), p, joint, work).filter(|f| {
            let e = factor_error(p, f);
            (e.transpose() * f.info * e).x <= gate
        });
    }
}

/// Closures between visits: for every `closure_stride`-th pose with a factor, the earlier pose
/// (at least `closure_gap` steps before, with a factor) that read the most of the same mapped
/// tags, if at least `closure_min_shared`. The measurement is the relative pose of the two
/// factors' means (both on the same map, so the map's error where they are cancels), its
/// covariance the two factors' propagated.
fn closures(
    factors: &[Option<Factor>],
    read_by: &[Vec<usize>],
    mapper: &Mapper<'_>,
    joint: &JointConfig,
) -> Vec<Closure> {
    let n = factors.len();
    let mut shared = vec![0_u32; n];
    let mut touched: Vec<usize> = Vec::new();
    let mut out = Vec::new();
    for (b, tags) in read_by
        .iter()
        .enumerate()
        .step_by(joint.closure_stride.max(1))
    {
        let Some(Some(fb)) = factors.get(b) else {
            continue;
        };
        let Some(limit) = b.checked_sub(joint.closure_gap.max(1)) else {
            continue;
        };
        for &k in tags {
            for (i, _) in mapper.reads_of(k) {
                if *i > limit || !matches!(factors.get(*i), Some(Some(_))) {
                    continue;
                }
                if let Some(c) = shared.get_mut(*i) {
                    if *c == 0 {
                        touched.push(*i);
                    }
                    *c += 1;
                }
            }
        }
        let best = touched
            .iter()
            .map(|&i| (shared.get(i).copied().unwrap_or(0), i))
            .max();
        for &i in &touched {
            if let Some(c) = shared.get_mut(i) {
                *c = 0;
            }
        }
        touched.clear();
        let Some((count, a)) = best else {
            continue;
        };
        let Some(Some(fa)) = factors.get(a) else {
            continue;
        };
        if (count as usize) < joint.closure_min_shared {
            continue;
        }
        let (ja, jb) = relative_jacobians(&fa.mean, &fb.mean);
        let (Some(ca), Some(cb)) = (fa.info.try_inverse(), fb.info.try_inverse()) else {
            continue;
        };
        let cov = ja * ca * ja.transpose() + jb * cb * jb.transpose();
        let Some(info) = cov.try_inverse() else {
            continue;
        };
        out.push(Closure {
            a,
            b,
            z: fb.mean.relative_to(&fa.mean),
            info: 0.5 * (info + info.transpose()),
        });
    }
    out
}

/// Levenberg–Marquardt on the chain with its unary factors (see [`Graph`]).
fn smooth(
    poses: &mut [Pose2],
    increments: &[Pose2],
    odo_info: &[Matrix3<f64>],
    factors: &[Option<Factor>],
    j: &JointConfig,
) {
    Graph {
        increments,
        odo_info,
        factors,
        closures: &[],
        huber: j.huber,
    }
    .optimise(poses, j.gauss_newton);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothing_pulls_a_drifted_chain_onto_its_factors() {
        // A straight run along x whose odometry turned by 1° per step: factors at the true
        // poses every fifth step bring the chain back.
        let truth: Vec<Pose2> = (0..60)
            .map(|i| Pose2::new(0.1 * f64::from(i), 0.0, 0.0))
            .collect();
        let increments: Vec<Pose2> = (0..59).map(|_| Pose2::new(0.1, 0.0, 0.0087)).collect();
        let mut poses = vec![truth[0]];
        for u in &increments {
            let last = *poses.last().unwrap_or(&truth[0]);
            poses.push(last.compose(u));
        }
        let before = poses.last().unwrap_or(&truth[0]).distance(&truth[59]);
        let j = JointConfig::default();
        let info: Vec<Matrix3<f64>> = increments
            .iter()
            .map(|u| odometry_information(u, &j))
            .collect();
        let factors: Vec<Option<Factor>> = truth
            .iter()
            .enumerate()
            .map(|(i, p)| {
                (i % 5 == 0).then_some(Factor {
                    mean: *p,
                    info: Matrix3::from_diagonal(&Vector3::new(1e4, 1e4, 1e3)),
                })
            })
            .collect();
        smooth(&mut poses, &increments, &info, &factors, &j);
        let after = poses
            .iter()
            .zip(&truth)
            .map(|(a, b)| a.distance(b))
            .fold(0.0, f64::max);
        let mean = poses
            .iter()
            .zip(&truth)
            .map(|(a, b)| a.distance(b))
            .sum::<f64>()
            / 60.0;
        // The odometry bends the run 0.5 m off; the smoothed chain stays within the bend the
        // odometry makes between two factors.
        assert!(before > 0.5, "{before}");
        assert!(after < 0.08 && mean < 0.04, "worst {after}, mean {mean}");
        assert_eq!(poses[0], truth[0]);
    }
}
