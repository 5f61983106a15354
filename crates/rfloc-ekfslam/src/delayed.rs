//! Delayed initialisation: a beacon seen without a usable range+bearing pair is triangulated
//! from several views (each a robot pose estimate plus a range, RSSI or bearing reading) once the
//! views constrain its position.

use std::collections::VecDeque;

use nalgebra::{Matrix2, Matrix2x3, Vector2, Vector3};
use rfloc_pose::wrap_angle;

use crate::config::{EkfSlamConfig, RssiHandling};
use crate::models::{bearing_row, range_row, rssi_row, ObservationRow};
use crate::observation::{BearingReading, RangeReading};

/// One stored view of a not-yet-mapped beacon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct View {
    /// Pose estimate when the view was taken.
    pub pose: Vector3<f64>,
    /// The copy of that pose kept in the filter state, if any (see
    /// [`crate::DelayedInit::view_poses_in_state`]).
    pub clone: Option<u64>,
    pub range: Option<RangeReading>,
    pub bearing: Option<BearingReading>,
}

/// A triangulated beacon.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Triangulated {
    /// Position, m.
    pub position: Vector2<f64>,
    /// Covariance from the measurement noise alone (view poses taken as exact), m².
    pub cov: Matrix2<f64>,
    /// Per view (same order as the pending views): `∂position/∂(view pose)`, from the
    /// optimality condition of the weighted least-squares fit.
    pub d_view_pose: Vec<Matrix2x3<f64>>,
}

/// Views collected for one pending beacon.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct PendingBeacon {
    pub views: VecDeque<View>,
}

#[derive(Clone, Copy)]
enum Kind {
    Range,
    Rssi,
    Bearing,
}

struct Scalar {
    /// Index of the view in the pending list.
    view: usize,
    pose: Vector3<f64>,
    kind: Kind,
    value: f64,
    variance: f64,
}

/// Converts a range-like reading to a scalar measurement according to the RSSI handling.
/// Returns `(kind, value, variance)`.
fn range_scalar(reading: &RangeReading, cfg: &EkfSlamConfig) -> (bool, f64, f64) {
    match *reading {
        RangeReading::Metres {
            range_m,
            variance_m2,
        } => (false, range_m, variance_m2),
        RangeReading::RssiDbm {
            rssi_dbm,
            variance_db2,
        } => match cfg.rssi_handling {
            RssiHandling::PathLossMeasurement => (true, rssi_dbm, variance_db2),
            RssiHandling::ConvertToRange => {
                let d = cfg.path_loss.distance_for(rssi_dbm);
                let s = d * variance_db2.sqrt() * cfg.path_loss.ln_distance_per_db();
                (false, d, s * s)
            }
        },
    }
}

/// Range in metres implied by a reading (for the linear initial guess only).
fn metric_range(reading: &RangeReading, cfg: &EkfSlamConfig) -> f64 {
    match *reading {
        RangeReading::Metres { range_m, .. } => range_m,
        RangeReading::RssiDbm { rssi_dbm, .. } => cfg.path_loss.distance_for(rssi_dbm),
    }
}

fn row(s: &Scalar, b: &Vector2<f64>, cfg: &EkfSlamConfig) -> Option<ObservationRow> {
    match s.kind {
        Kind::Range => range_row(&s.pose, b, cfg.min_distance_m),
        Kind::Rssi => rssi_row(&s.pose, b, &cfg.path_loss, cfg.min_distance_m),
        Kind::Bearing => bearing_row(&s.pose, b, cfg.min_distance_m),
    }
}

/// Linear least-squares initial guess: each bearing gives the line `nᵀb = nᵀp` through the robot
/// position along the ray; each pair of ranges gives `2(p₀ − pᵢ)ᵀb = rᵢ² − r₀² − ‖pᵢ‖² + ‖p₀‖²`.
fn linear_guess(views: &VecDeque<View>, cfg: &EkfSlamConfig) -> Option<Vector2<f64>> {
    let mut ata = Matrix2::zeros();
    let mut aty = Vector2::zeros();
    let mut add = |a: Vector2<f64>, y: f64| {
        ata += a * a.transpose();
        aty += a * y;
    };
    let mut first_range: Option<(Vector2<f64>, f64)> = None;
    for v in views {
        let p = Vector2::new(v.pose.x, v.pose.y);
        if let Some(b) = v.bearing {
            let a = v.pose.z + b.bearing_rad;
            let n = Vector2::new(-a.sin(), a.cos());
            add(n, n.dot(&p));
        }
        if let Some(r) = v.range {
            let r = metric_range(&r, cfg);
            match first_range {
                None => first_range = Some((p, r)),
                Some((p0, r0)) => {
                    let a = 2.0 * (p0 - p);
                    if a.norm() > 1e-6 {
                        add(a, r * r - r0 * r0 - p.norm_squared() + p0.norm_squared());
                    }
                }
            }
        }
    }
    let det = ata.determinant();
    let scale = ata.trace() * ata.trace();
    if !(det.is_finite() && det > 1e-9 * scale.max(1e-12)) {
        return None;
    }
    ata.try_inverse().map(|inv| inv * aty)
}

/// Weighted residual cost `Σ r²/σ²`, information `Σ h hᵀ/σ²` and gradient `Σ h r/σ²` at `b`.
fn normal_equations(
    scalars: &[Scalar],
    b: &Vector2<f64>,
    cfg: &EkfSlamConfig,
) -> Option<(f64, Matrix2<f64>, Vector2<f64>)> {
    let mut info = Matrix2::zeros();
    let mut grad = Vector2::zeros();
    let mut cost = 0.0;
    for s in scalars {
        let r = row(s, b, cfg)?;
        let mut res = s.value - r.predicted;
        if matches!(s.kind, Kind::Bearing) {
            res = wrap_angle(res);
        }
        let h = Vector2::new(r.d_beacon[0], r.d_beacon[1]);
        info += h * h.transpose() / s.variance;
        grad += h * res / s.variance;
        cost += res * res / s.variance;
    }
    Some((cost, info, grad))
}

/// Gauss–Newton from `b` (full steps, 30 at most); returns the visited point of lowest cost,
/// with the information there and the cost.
fn gauss_newton(
    scalars: &[Scalar],
    mut b: Vector2<f64>,
    cfg: &EkfSlamConfig,
) -> Option<(Vector2<f64>, Matrix2<f64>, f64)> {
    let (cost, info, mut grad) = normal_equations(scalars, &b, cfg)?;
    let mut best = (b, info, cost);
    let mut info = info;
    for _ in 0..30 {
        let step = info.try_inverse()? * grad;
        b += step;
        let Some((c, i, g)) = normal_equations(scalars, &b, cfg) else {
            break;
        };
        (info, grad) = (i, g);
        if c < best.2 {
            best = (b, i, c);
        }
        if step.norm() < 1e-7 {
            break;
        }
    }
    Some(best)
}

/// Tries to triangulate the beacon, with the views' poses as given by `pose_of` (the stored
/// estimate, or the current estimate of the view's pose copy in the state). Returns its position,
/// covariance and Jacobians when the views constrain it well enough (see [`crate::DelayedInit`]).
pub(crate) fn triangulate(
    pending: &PendingBeacon,
    cfg: &EkfSlamConfig,
    pose_of: impl Fn(&View) -> Vector3<f64>,
) -> Option<Triangulated> {
    let dc = &cfg.delayed_init;
    if pending.views.len() < dc.min_views.max(2) {
        return None;
    }
    let views: VecDeque<View> = pending
        .views
        .iter()
        .map(|v| View {
            pose: pose_of(v),
            ..*v
        })
        .collect();
    let mut baseline: f64 = 0.0;
    for a in &views {
        for b in &views {
            baseline = baseline.max((a.pose.x - b.pose.x).hypot(a.pose.y - b.pose.y));
        }
    }
    if baseline < dc.min_baseline_m {
        return None;
    }
    let mut scalars = Vec::new();
    for (k, v) in views.iter().enumerate() {
        if let Some(r) = v.range {
            let (is_rssi, value, variance) = range_scalar(&r, cfg);
            scalars.push(Scalar {
                view: k,
                pose: v.pose,
                kind: if is_rssi { Kind::Rssi } else { Kind::Range },
                value,
                variance,
            });
        }
        if let Some(b) = v.bearing {
            scalars.push(Scalar {
                view: k,
                pose: v.pose,
                kind: Kind::Bearing,
                value: b.bearing_rad,
                variance: b.variance_rad2,
            });
        }
    }
    if scalars.len() < 3 {
        return None;
    }
    // The problem is not convex (ranges from RSSI are noisy, bearings from a short baseline
    // nearly parallel): Gauss–Newton from several starting points, the lowest cost wins.
    let bearings_only: VecDeque<View> = views.iter().map(|v| View { range: None, ..*v }).collect();
    let mut starts: Vec<Vector2<f64>> =
        [linear_guess(&views, cfg), linear_guess(&bearings_only, cfg)]
            .into_iter()
            .flatten()
            .collect();
    let inverse: Vec<Vector2<f64>> = views
        .iter()
        .filter_map(|v| {
            let (r, b) = (v.range?, v.bearing?);
            let a = v.pose.z + b.bearing_rad;
            let d = metric_range(&r, cfg);
            Some(Vector2::new(v.pose.x + d * a.cos(), v.pose.y + d * a.sin()))
        })
        .collect();
    if !inverse.is_empty() {
        starts.push(inverse.iter().sum::<Vector2<f64>>() / inverse.len() as f64);
    }
    let (b, info, cost) = starts
        .into_iter()
        .filter_map(|b0| gauss_newton(&scalars, b0, cfg))
        .min_by(|a, b| a.2.total_cmp(&b.2))?;
    let cov = info.try_inverse()?;
    let dof = (scalars.len() - 2) as f64;
    let max_cost = dof + 4.0 * (2.0 * dof).sqrt() + 10.0;
    let eig = cov.symmetric_eigenvalues();
    let max_var = eig.max();
    // The relaxed bound: a σ small against the distance, after enough views.
    let centre = views
        .iter()
        .map(|v| Vector2::new(v.pose.x, v.pose.y))
        .sum::<Vector2<f64>>()
        / views.len() as f64;
    let relaxed = dc.relax_after_views > 0
        && views.len() >= dc.relax_after_views
        && max_var.sqrt() <= dc.max_relative_std * (b - centre).norm();
    if !(b.x.is_finite()
        && b.y.is_finite()
        && cost <= max_cost
        && max_var > 0.0
        && (max_var.sqrt() <= dc.max_std_m || relaxed))
    {
        return None;
    }
    // At the optimum Σ h_bᵀ r / σ² = 0; perturbing a view pose by δc moves each of its residuals
    // by −h_c·δc, so δb = −C Σ h_b h_cᵀ δc / σ² over that view's scalars.
    let mut d_view_pose = vec![Matrix2x3::zeros(); views.len()];
    for s in &scalars {
        let r = row(s, &b, cfg)?;
        let hb = Vector2::new(r.d_beacon[0], r.d_beacon[1]);
        let hc = Vector3::new(r.d_pose[0], r.d_pose[1], r.d_pose[2]);
        if let Some(j) = d_view_pose.get_mut(s.view) {
            *j -= cov * hb * hc.transpose() / s.variance;
        }
    }
    Some(Triangulated {
        position: b,
        cov: (cov + cov.transpose()) / 2.0,
        d_view_pose,
    })
}
