//! Error metrics of an estimate trajectory against the truth, per trial and over trials.

use rfloc_pose::{angle_diff, Pose2};

use crate::geometry::Point;

/// A pose at a time (seconds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedPose {
    pub t: f64,
    pub pose: Pose2,
}

impl TimedPose {
    /// A pose at time `t`.
    #[must_use]
    pub const fn new(t: f64, pose: Pose2) -> Self {
        Self { t, pose }
    }
}

/// Position and heading error statistics of one trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// Number of estimate samples compared.
    pub n: usize,
    /// Root mean square position error, metres.
    pub rmse: f64,
    /// Mean position error, metres.
    pub mean: f64,
    /// Maximum position error, metres.
    pub max: f64,
    /// Root mean square heading error, radians.
    pub rmse_theta: f64,
    /// Mean absolute heading error, radians.
    pub mean_theta: f64,
    /// Maximum absolute heading error, radians.
    pub max_theta: f64,
}

/// Truth linearly interpolated at time `t` (heading along the short way); clamped to the ends.
#[must_use]
pub fn interpolate(truth: &[TimedPose], t: f64) -> Option<Pose2> {
    let first = truth.first()?;
    if t <= first.t {
        return Some(first.pose);
    }
    let idx = truth.partition_point(|p| p.t <= t);
    match (truth.get(idx.wrapping_sub(1)), truth.get(idx)) {
        (Some(a), Some(b)) if b.t > a.t => {
            let f = (t - a.t) / (b.t - a.t);
            Some(Pose2::new(
                a.pose.x + f * (b.pose.x - a.pose.x),
                a.pose.y + f * (b.pose.y - a.pose.y),
                a.pose.theta + f * angle_diff(b.pose.theta, a.pose.theta),
            ))
        }
        (Some(a), _) => Some(a.pose),
        (None, _) => None,
    }
}

/// Errors of `estimate` against `truth` (time-sorted), the truth interpolated at each
/// estimate time. `None` when either is empty.
#[must_use]
pub fn trajectory_errors(truth: &[TimedPose], estimate: &[TimedPose]) -> Option<ErrorStats> {
    let (mut sq, mut sum, mut max, mut sq_th, mut n) = (0.0, 0.0, 0.0_f64, 0.0, 0usize);
    let (mut sum_th, mut max_th) = (0.0, 0.0_f64);
    for e in estimate {
        let t = interpolate(truth, e.t)?;
        let d = t.distance(&e.pose);
        let dth = angle_diff(e.pose.theta, t.theta);
        sq += d * d;
        sum += d;
        max = max.max(d);
        sq_th += dth * dth;
        sum_th += dth.abs();
        max_th = max_th.max(dth.abs());
        n += 1;
    }
    (n > 0).then(|| {
        let k = n as f64;
        ErrorStats {
            n,
            rmse: (sq / k).sqrt(),
            mean: sum / k,
            max,
            rmse_theta: (sq_th / k).sqrt(),
            mean_theta: sum_th / k,
            max_theta: max_th,
        }
    })
}

/// First time the truth comes within `tolerance` of `goal`.
#[must_use]
pub fn time_to_goal(truth: &[TimedPose], goal: &Point, tolerance: f64) -> Option<f64> {
    truth
        .iter()
        .find(|p| Point::new(p.pose.x, p.pose.y).distance(goal) <= tolerance)
        .map(|p| p.t)
}

/// Root mean square distance between paired points (e.g. estimated vs true beacons).
#[must_use]
pub fn rmse_points(pairs: &[(Point, Point)]) -> Option<f64> {
    if pairs.is_empty() {
        return None;
    }
    let sq: f64 = pairs.iter().map(|(a, b)| a.distance(b).powi(2)).sum();
    Some((sq / pairs.len() as f64).sqrt())
}

/// Outcome of one trial.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult {
    pub trial: usize,
    pub seed: u64,
    pub errors: Option<ErrorStats>,
    /// Seconds (or steps, per scenario) to reach the goal, `None` if never reached.
    pub time_to_goal: Option<f64>,
    pub success: bool,
    /// Extra named numbers (e.g. `beacon_rmse_1_m`).
    pub extra: Vec<(String, f64)>,
}

/// Aggregate over trials. Each `Option` is `None` when no trial provided the number.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub trials: usize,
    pub successes: usize,
    /// Mean over trials of the per-trial RMSE.
    pub rmse_m: Option<f64>,
    /// Mean over trials of the per-trial mean error.
    pub mean_error_m: Option<f64>,
    /// Mean over trials of the per-trial maximum error.
    pub max_error_m: Option<f64>,
    /// Largest per-trial maximum error.
    pub worst_error_m: Option<f64>,
    /// Mean over trials of the per-trial heading RMSE.
    pub rmse_theta_rad: Option<f64>,
    /// Mean over trials of the per-trial mean absolute heading error.
    pub mean_theta_error_rad: Option<f64>,
    /// Largest per-trial maximum heading error.
    pub worst_theta_error_rad: Option<f64>,
    /// Mean time to goal over the successful trials.
    pub time_to_goal: Option<f64>,
    /// Means of every `extra` name, in first-seen order.
    pub extra: Vec<(String, f64)>,
}

/// For every `X_nees_per_dof` with a `X_nees_dof` beside it in the trials: replaces the mean
/// over trials by the pooled NEES per degree of freedom (weighted by each trial's dof), sets
/// `X_nees_dof` to the total, and adds `X_nees_band_low` / `X_nees_band_high`, the two-sided
/// 95 % band of a consistent filter (χ² with that many dof, divided by it). When every trial
/// also gives `X_nees_eff_dof` (its NEES sums correlated terms, e.g. the beacons of one map, and
/// behaves like a scaled χ² with that many dof), the band is that of the pooled sum's mean and
/// variance, `χ²(h) / h` with `h = (Σ dᵢ)² / Σ (dᵢ² / hᵢ)`, and `X_nees_eff_dof` becomes `h`.
fn pool_nees(results: &[TrialResult], extra: &mut Vec<(String, f64)>) {
    let keys: Vec<String> = extra
        .iter()
        .filter_map(|(k, _)| k.strip_suffix("_nees_per_dof").map(str::to_string))
        .collect();
    for prefix in keys {
        let (per, dof) = (
            format!("{prefix}_nees_per_dof"),
            format!("{prefix}_nees_dof"),
        );
        let eff = format!("{prefix}_nees_eff_dof");
        // Variance of the pooled sum in units of χ²: Σ dᵢ² / hᵢ (hᵢ = dᵢ when the trial gives
        // no effective dof, i.e. its terms are independent).
        let (mut sum, mut total, mut var) = (0.0, 0.0, 0.0);
        let mut all_eff = true;
        for r in results {
            let get = |k: &str| r.extra.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
            if let (Some(v), Some(d)) = (get(&per), get(&dof)) {
                sum += v * d;
                total += d;
                let h = get(&eff).filter(|h| *h > 0.0 && h.is_finite());
                all_eff &= h.is_some();
                var += d * d / h.unwrap_or(d);
            }
        }
        if total <= 0.0 {
            continue;
        }
        // The band of a scaled χ² with the pooled sum's mean and variance (moment matching).
        let effective = if var > 0.0 {
            total * total / var
        } else {
            total
        };
        for (k, v) in extra.iter_mut() {
            if *k == per {
                *v = sum / total;
            } else if *k == dof {
                *v = total;
            } else if *k == eff && all_eff {
                *v = effective;
            }
        }
        extra.push((
            format!("{prefix}_nees_band_low"),
            chi2_quantile(effective, -1.959_964) / effective,
        ));
        extra.push((
            format!("{prefix}_nees_band_high"),
            chi2_quantile(effective, 1.959_964) / effective,
        ));
    }
}

/// Quantile of the χ² distribution with `k` degrees of freedom at the standard normal
/// quantile `z` (Wilson–Hilferty; within 1 % of the exact value from k = 3 on).
#[must_use]
pub fn chi2_quantile(k: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3).max(0.0)
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    (n > 0).then(|| s / n as f64)
}

impl Summary {
    /// Aggregates trial results.
    #[must_use]
    pub fn from_trials(results: &[TrialResult]) -> Summary {
        let errs = || results.iter().filter_map(|r| r.errors);
        let mut names: Vec<String> = Vec::new();
        for r in results {
            for (k, _) in &r.extra {
                if !names.contains(k) {
                    names.push(k.clone());
                }
            }
        }
        let mut extra: Vec<(String, f64)> = names
            .into_iter()
            .filter_map(|k| {
                let m = mean(
                    results
                        .iter()
                        .flat_map(|r| r.extra.iter().filter(|(n, _)| *n == k).map(|(_, v)| *v)),
                );
                m.map(|m| (k, m))
            })
            .collect();
        pool_nees(results, &mut extra);
        Summary {
            trials: results.len(),
            successes: results.iter().filter(|r| r.success).count(),
            rmse_m: mean(errs().map(|e| e.rmse)),
            mean_error_m: mean(errs().map(|e| e.mean)),
            max_error_m: mean(errs().map(|e| e.max)),
            worst_error_m: errs().map(|e| e.max).reduce(f64::max),
            rmse_theta_rad: mean(errs().map(|e| e.rmse_theta)),
            mean_theta_error_rad: mean(errs().map(|e| e.mean_theta)),
            worst_theta_error_rad: errs().map(|e| e.max_theta).reduce(f64::max),
            time_to_goal: mean(
                results
                    .iter()
                    .filter(|r| r.success)
                    .filter_map(|r| r.time_to_goal),
            ),
            extra,
        }
    }

    /// The summary as `(metric key, value)` pairs; keys match [`crate::published`].
    #[must_use]
    pub fn metrics(&self) -> Vec<(String, f64)> {
        let mut out = Vec::new();
        let mut push = |k: &str, v: Option<f64>| {
            if let Some(v) = v {
                out.push((k.to_string(), v));
            }
        };
        push("rmse_m", self.rmse_m);
        push("mean_error_m", self.mean_error_m);
        push("max_error_m", self.max_error_m);
        push("worst_error_m", self.worst_error_m);
        push("rmse_theta_rad", self.rmse_theta_rad);
        push("mean_theta_error_rad", self.mean_theta_error_rad);
        push("worst_theta_error_rad", self.worst_theta_error_rad);
        push("time_to_goal", self.time_to_goal);
        push("successes", Some(self.successes as f64));
        push("failures", Some((self.trials - self.successes) as f64));
        out.extend(self.extra.iter().cloned());
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A successful trial without pose errors or goal time, with these extra metrics.
    fn with_extras(extra: &[(&str, f64)]) -> TrialResult {
        TrialResult {
            trial: 0,
            seed: 0,
            errors: None,
            time_to_goal: None,
            success: true,
            extra: extra.iter().map(|(k, v)| ((*k).to_string(), *v)).collect(),
        }
    }

    /// The summary's extra metric `k` (the test fails when it is missing).
    fn extra(s: &Summary, k: &str) -> f64 {
        s.extra
            .iter()
            .find(|(n, _)| n == k)
            .map(|(_, v)| *v)
            .unwrap()
    }

    fn line(n: usize, dy: f64) -> Vec<TimedPose> {
        (0..n)
            .map(|i| TimedPose::new(i as f64, Pose2::new(i as f64, dy, 0.0)))
            .collect()
    }

    #[test]
    fn constant_offset_gives_equal_rmse_mean_max() {
        let e = trajectory_errors(&line(10, 0.0), &line(10, 0.3)).unwrap();
        assert_eq!(e.n, 10);
        assert!(
            (e.rmse - 0.3).abs() < 1e-12
                && (e.mean - 0.3).abs() < 1e-12
                && (e.max - 0.3).abs() < 1e-12
        );
    }

    #[test]
    fn rmse_exceeds_mean_for_uneven_errors() {
        let truth = line(4, 0.0);
        let est: Vec<TimedPose> = truth
            .iter()
            .enumerate()
            .map(|(i, p)| {
                TimedPose::new(
                    p.t,
                    Pose2::new(p.pose.x, if i == 3 { 4.0 } else { 0.0 }, 0.0),
                )
            })
            .collect();
        let e = trajectory_errors(&truth, &est).unwrap();
        assert!(
            (e.mean - 1.0).abs() < 1e-12
                && (e.rmse - 2.0).abs() < 1e-12
                && (e.max - 4.0).abs() < 1e-12
        );
    }

    #[test]
    fn truth_is_interpolated_between_samples() {
        let truth = vec![
            TimedPose::new(0.0, Pose2::new(0.0, 0.0, 3.0)),
            TimedPose::new(2.0, Pose2::new(2.0, 0.0, -3.0)),
        ];
        let p = interpolate(&truth, 1.0).unwrap();
        assert!((p.x - 1.0).abs() < 1e-12);
        // Heading interpolated across ±π, not through 0.
        assert!(p.theta.abs() > 3.0);
    }

    #[test]
    fn nees_is_pooled_over_trials_with_its_chi2_band() {
        let r = |nees: f64, dof: f64| {
            with_extras(&[("beacon_nees_per_dof", nees), ("beacon_nees_dof", dof)])
        };
        let s = Summary::from_trials(&[r(1.0, 8.0), r(2.5, 2.0)]);
        let get = |k: &str| extra(&s, k);
        assert!((get("beacon_nees_per_dof") - 1.3).abs() < 1e-12);
        assert_eq!(get("beacon_nees_dof"), 10.0);
        // χ²(10): 3.247 and 20.483 at 2.5 % and 97.5 %.
        assert!((get("beacon_nees_band_low") * 10.0 - 3.247).abs() < 0.05);
        assert!((get("beacon_nees_band_high") * 10.0 - 20.483).abs() < 0.1);
    }

    #[test]
    fn correlated_nees_terms_widen_the_band_to_their_effective_dof() {
        let r = |nees: f64, dof: f64, eff: f64| {
            with_extras(&[
                ("beacon_nees_per_dof", nees),
                ("beacon_nees_dof", dof),
                ("beacon_nees_eff_dof", eff),
            ])
        };
        // Two trials of 20 dof whose terms behave like 5 independent ones each: Var = 2·(400/5)
        // per trial, pooled h = 40² / 160 = 10, the band of χ²(10) / 10.
        let s = Summary::from_trials(&[r(1.0, 20.0, 5.0), r(0.5, 20.0, 5.0)]);
        let get = |k: &str| extra(&s, k);
        assert!((get("beacon_nees_per_dof") - 0.75).abs() < 1e-12);
        assert_eq!(get("beacon_nees_dof"), 40.0);
        assert!((get("beacon_nees_eff_dof") - 10.0).abs() < 1e-12);
        assert!((get("beacon_nees_band_low") * 10.0 - 3.247).abs() < 0.05);
        assert!((get("beacon_nees_band_high") * 10.0 - 20.483).abs() < 0.1);
    }

    #[test]
    fn goal_time_and_summary() {
        let truth = line(10, 0.0);
        assert_eq!(time_to_goal(&truth, &Point::new(5.2, 0.0), 0.5), Some(5.0));
        assert_eq!(time_to_goal(&truth, &Point::new(5.2, 3.0), 0.5), None);
        let r = |t: Option<f64>, rm: f64| TrialResult {
            trial: 0,
            seed: 0,
            errors: Some(ErrorStats {
                n: 1,
                rmse: rm,
                mean: rm,
                max: 2.0 * rm,
                rmse_theta: 0.0,
                mean_theta: 0.1,
                max_theta: rm,
            }),
            time_to_goal: t,
            success: t.is_some(),
            extra: vec![("beacon_rmse_1_m".into(), rm)],
        };
        let s = Summary::from_trials(&[r(Some(10.0), 0.2), r(None, 0.4)]);
        assert_eq!((s.trials, s.successes), (2, 1));
        assert!(
            (s.rmse_m.unwrap() - 0.3).abs() < 1e-12 && (s.max_error_m.unwrap() - 0.6).abs() < 1e-12
        );
        assert_eq!(s.time_to_goal, Some(10.0));
        assert_eq!(s.worst_error_m, Some(0.8));
        assert_eq!(s.worst_theta_error_rad, Some(0.4));
        assert!(s
            .metrics()
            .iter()
            .any(|(k, v)| k == "failures" && *v == 1.0));
        assert!(s
            .metrics()
            .iter()
            .any(|(k, v)| k == "beacon_rmse_1_m" && (*v - 0.3).abs() < 1e-12));
        assert_eq!(
            rmse_points(&[(Point::new(0.0, 0.0), Point::new(3.0, 4.0))]),
            Some(5.0)
        );
    }
}
