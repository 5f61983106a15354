//! Delayed initialisation: a beacon seen without a usable range+bearing pair is triangulated
//! from several views (each a robot pose estimate plus a range, RSSI or bearing reading) once the
//! views constrain its position.

use std::collections::VecDeque;

use nalgebra::{Matrix2, Vector2, Vector3};
use rfloc_pose::wrap_angle;

use crate::config::{EkfSlamConfig, RssiHandling};
use crate::models::{bearing_row, range_row, rssi_row, ObservationRow};
use crate::observation::{BearingReading, RangeReading};

/// One stored view of a not-yet-mapped beacon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct View {
    pub pose: Vector3<f64>,
    pub range: Option<RangeReading>,
    pub bearing: Option<BearingReading>,
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

/// Tries to triangulate the beacon. Returns its position and 2×2 covariance when the views
/// constrain it well enough (see [`crate::DelayedInit`]).
pub(crate) fn triangulate(
    pending: &PendingBeacon,
    cfg: &EkfSlamConfig,
) -> Option<(Vector2<f64>, Matrix2<f64>)> {
    let dc = &cfg.delayed_init;
    if pending.views.len() < dc.min_views.max(2) {
        return None;
    }
    let mut baseline: f64 = 0.0;
    for a in &pending.views {
        for b in &pending.views {
            baseline = baseline.max((a.pose.x - b.pose.x).hypot(a.pose.y - b.pose.y));
        }
    }
    if baseline < dc.min_baseline_m {
        return None;
    }
    let mut scalars = Vec::new();
    for v in &pending.views {
        if let Some(r) = v.range {
            let (is_rssi, value, variance) = range_scalar(&r, cfg);
            scalars.push(Scalar {
                pose: v.pose,
                kind: if is_rssi { Kind::Rssi } else { Kind::Range },
                value,
                variance,
            });
        }
        if let Some(b) = v.bearing {
            scalars.push(Scalar {
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
    let mut b = linear_guess(&pending.views, cfg)?;
    let mut info = Matrix2::zeros();
    let mut cost = 0.0;
    for _ in 0..30 {
        info = Matrix2::zeros();
        let mut grad = Vector2::zeros();
        cost = 0.0;
        for s in &scalars {
            let r = row(s, &b, cfg)?;
            let mut res = s.value - r.predicted;
            if matches!(s.kind, Kind::Bearing) {
                res = wrap_angle(res);
            }
            let h = Vector2::new(r.d_beacon[0], r.d_beacon[1]);
            info += h * h.transpose() / s.variance;
            grad += h * res / s.variance;
            cost += res * res / s.variance;
        }
        let step = info.try_inverse()? * grad;
        b += step;
        if step.norm() < 1e-7 {
            break;
        }
    }
    let cov = info.try_inverse()?;
    let dof = (scalars.len() - 2) as f64;
    let max_cost = dof + 4.0 * (2.0 * dof).sqrt() + 10.0;
    let eig = cov.symmetric_eigenvalues();
    let max_var = eig.max();
    if !(b.x.is_finite()
        && b.y.is_finite()
        && cost <= max_cost
        && max_var > 0.0
        && max_var.sqrt() <= dc.max_std_m)
    {
        return None;
    }
    Some((b, (cov + cov.transpose()) / 2.0))
}
