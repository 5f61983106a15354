//! Motion and observation models with their analytic Jacobians. Pure functions; the filter and
//! the finite-difference tests both use them.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};
use rfloc_pose::wrap_angle;

use crate::config::PathLoss;

/// Velocity motion model, midpoint Euler: with `φ = θ + ω·dt/2`,
/// `x' = x + v·dt·cos φ`, `y' = y + v·dt·sin φ`, `θ' = θ + ω·dt`.
/// Returns the new pose, `F = ∂f/∂pose` and `L = ∂f/∂(v, ω)`.
#[must_use]
pub fn velocity_motion(
    pose: &Vector3<f64>,
    v: f64,
    omega: f64,
    dt: f64,
) -> (Vector3<f64>, Matrix3<f64>, Matrix3x2<f64>) {
    let phi = pose.z + omega * dt / 2.0;
    let (s, c) = phi.sin_cos();
    let new = Vector3::new(
        pose.x + v * dt * c,
        pose.y + v * dt * s,
        wrap_angle(pose.z + omega * dt),
    );
    let f = Matrix3::new(1.0, 0.0, -v * dt * s, 0.0, 1.0, v * dt * c, 0.0, 0.0, 1.0);
    let l = Matrix3x2::new(
        dt * c,
        -v * dt * dt / 2.0 * s,
        dt * s,
        v * dt * dt / 2.0 * c,
        0.0,
        dt,
    );
    (new, f, l)
}

/// Odometry motion model: `pose' = pose ⊕ (dx, dy, dθ)` with the increment in the robot frame.
/// Returns the new pose, `F = ∂f/∂pose` and `L = ∂f/∂(dx, dy, dθ)`.
#[must_use]
pub fn odometry_motion(
    pose: &Vector3<f64>,
    delta: &Vector3<f64>,
) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
    let (s, c) = pose.z.sin_cos();
    let new = Vector3::new(
        pose.x + c * delta.x - s * delta.y,
        pose.y + s * delta.x + c * delta.y,
        wrap_angle(pose.z + delta.z),
    );
    let f = Matrix3::new(
        1.0,
        0.0,
        -s * delta.x - c * delta.y,
        0.0,
        1.0,
        c * delta.x - s * delta.y,
        0.0,
        0.0,
        1.0,
    );
    let l = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
    (new, f, l)
}

/// One scalar observation row: predicted value and its Jacobians with respect to the robot pose
/// `(x, y, θ)` and the beacon position `(bx, by)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservationRow {
    /// Predicted measurement `h(x)`.
    pub predicted: f64,
    /// `∂h/∂(x, y, θ)`.
    pub d_pose: [f64; 3],
    /// `∂h/∂(bx, by)`.
    pub d_beacon: [f64; 2],
}

fn delta(pose: &Vector3<f64>, beacon: &Vector2<f64>, min_d: f64) -> Option<(f64, f64, f64)> {
    let dx = beacon.x - pose.x;
    let dy = beacon.y - pose.y;
    let q = dx * dx + dy * dy;
    if !(q.is_finite() && q.sqrt() >= min_d) {
        return None;
    }
    Some((dx, dy, q))
}

/// Range `‖b − p‖`. `None` when the beacon is closer than `min_d`.
#[must_use]
pub fn range_row(pose: &Vector3<f64>, beacon: &Vector2<f64>, min_d: f64) -> Option<ObservationRow> {
    let (dx, dy, q) = delta(pose, beacon, min_d)?;
    let d = q.sqrt();
    Some(ObservationRow {
        predicted: d,
        d_pose: [-dx / d, -dy / d, 0.0],
        d_beacon: [dx / d, dy / d],
    })
}

/// Bearing `atan2(by − y, bx − x) − θ`, wrapped to `(−π, π]`.
#[must_use]
pub fn bearing_row(
    pose: &Vector3<f64>,
    beacon: &Vector2<f64>,
    min_d: f64,
) -> Option<ObservationRow> {
    let (dx, dy, q) = delta(pose, beacon, min_d)?;
    Some(ObservationRow {
        predicted: wrap_angle(dy.atan2(dx) - pose.z),
        d_pose: [dy / q, -dx / q, -1.0],
        d_beacon: [-dy / q, dx / q],
    })
}

/// RSSI in dBm, `P_ref − 10η log10 ‖b − p‖`.
#[must_use]
pub fn rssi_row(
    pose: &Vector3<f64>,
    beacon: &Vector2<f64>,
    path_loss: &PathLoss,
    min_d: f64,
) -> Option<ObservationRow> {
    let (dx, dy, q) = delta(pose, beacon, min_d)?;
    let k = 10.0 * path_loss.eta / std::f64::consts::LN_10; // dB per neper
    Some(ObservationRow {
        predicted: path_loss.rssi_at(q.sqrt()),
        d_pose: [k * dx / q, k * dy / q, 0.0],
        d_beacon: [-k * dx / q, -k * dy / q],
    })
}

/// Inverse observation model from range `r` and bearing `β`:
/// `b = (x + r cos(θ+β), y + r sin(θ+β))`. Returns `b`, `G_v = ∂b/∂pose`, `G_z = ∂b/∂(r, β)`.
#[must_use]
pub fn inverse_range_bearing(
    pose: &Vector3<f64>,
    r: f64,
    beta: f64,
) -> (Vector2<f64>, Matrix2x3<f64>, Matrix2<f64>) {
    let (s, c) = (pose.z + beta).sin_cos();
    let b = Vector2::new(pose.x + r * c, pose.y + r * s);
    let gv = Matrix2x3::new(1.0, 0.0, -r * s, 0.0, 1.0, r * c);
    let gz = Matrix2::new(c, -r * s, s, r * c);
    (b, gv, gz)
}

/// Inverse observation model from RSSI `z` (dBm) and bearing `β`, through the path-loss range
/// `r(z) = 10^((P_ref − z)/(10η))`. Returns `b`, `G_v` and `G_z = ∂b/∂(z, β)`.
#[must_use]
pub fn inverse_rssi_bearing(
    pose: &Vector3<f64>,
    rssi_dbm: f64,
    beta: f64,
    path_loss: &PathLoss,
) -> (Vector2<f64>, Matrix2x3<f64>, Matrix2<f64>) {
    let r = path_loss.distance_for(rssi_dbm);
    let dr_dz = -r * path_loss.ln_distance_per_db();
    let (b, gv, gz_rb) = inverse_range_bearing(pose, r, beta);
    let gz = Matrix2::new(
        gz_rb[(0, 0)] * dr_dz,
        gz_rb[(0, 1)],
        gz_rb[(1, 0)] * dr_dz,
        gz_rb[(1, 1)],
    );
    (b, gv, gz)
}

/// Inverse model of a point known in the robot frame, `b = p + R(θ)·l`.
/// Returns `G_v = ∂b/∂pose` and `R(θ) = ∂b/∂l`.
#[must_use]
pub fn inverse_local_point(
    pose: &Vector3<f64>,
    local: &Vector2<f64>,
) -> (Vector2<f64>, Matrix2x3<f64>, Matrix2<f64>) {
    let (s, c) = pose.z.sin_cos();
    let b = Vector2::new(
        pose.x + c * local.x - s * local.y,
        pose.y + s * local.x + c * local.y,
    );
    let gv = Matrix2x3::new(
        1.0,
        0.0,
        -s * local.x - c * local.y,
        0.0,
        1.0,
        c * local.x - s * local.y,
    );
    (b, gv, Matrix2::new(c, -s, s, c))
}

#[cfg(test)]
mod tests {
    //! Finite-difference checks of every analytic Jacobian (central differences, h = 1e-6).
    use super::*;

    const H: f64 = 1e-6;
    const TOL: f64 = 1e-6;

    fn close(a: f64, b: f64, what: &str) {
        assert!(
            (a - b).abs() <= TOL * (1.0 + b.abs()),
            "{what}: analytic {a} vs numeric {b}"
        );
    }

    fn poses() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(0.3, -1.2, 0.4),
            Vector3::new(-2.0, 5.0, 3.0),
            Vector3::new(1.0, 1.0, -2.9),
            Vector3::new(0.0, 0.0, std::f64::consts::PI - 1e-3),
        ]
    }

    fn beacons() -> Vec<Vector2<f64>> {
        vec![
            Vector2::new(3.0, 2.0),
            Vector2::new(-4.0, -1.0),
            Vector2::new(0.5, -3.5),
        ]
    }

    #[test]
    fn velocity_motion_jacobians_match_finite_differences() {
        for p in poses() {
            for &(v, w, dt) in &[(0.4, 0.3, 0.1), (1.2, -0.8, 0.5), (0.0, 1.0, 0.2)] {
                let (_, f, l) = velocity_motion(&p, v, w, dt);
                for j in 0..3 {
                    let mut a = p;
                    let mut b = p;
                    a[j] += H;
                    b[j] -= H;
                    let (fa, _, _) = velocity_motion(&a, v, w, dt);
                    let (fb, _, _) = velocity_motion(&b, v, w, dt);
                    for i in 0..3 {
                        let num = if i == 2 {
                            wrap_angle(fa[i] - fb[i])
                        } else {
                            fa[i] - fb[i]
                        } / (2.0 * H);
                        close(f[(i, j)], num, "F_vel");
                    }
                }
                for j in 0..2 {
                    let (va, wa, vb, wb) = if j == 0 {
                        (v + H, w, v - H, w)
                    } else {
                        (v, w + H, v, w - H)
                    };
                    let (fa, _, _) = velocity_motion(&p, va, wa, dt);
                    let (fb, _, _) = velocity_motion(&p, vb, wb, dt);
                    for i in 0..3 {
                        let num = if i == 2 {
                            wrap_angle(fa[i] - fb[i])
                        } else {
                            fa[i] - fb[i]
                        } / (2.0 * H);
                        close(l[(i, j)], num, "L_vel");
                    }
                }
            }
        }
    }

    #[test]
    fn odometry_motion_jacobians_match_finite_differences() {
        for p in poses() {
            let d = Vector3::new(0.3, -0.05, 0.2);
            let (_, f, l) = odometry_motion(&p, &d);
            for j in 0..3 {
                let (mut a, mut b) = (p, p);
                a[j] += H;
                b[j] -= H;
                let (mut da, mut db) = (d, d);
                da[j] += H;
                db[j] -= H;
                let (fa, _, _) = odometry_motion(&a, &d);
                let (fb, _, _) = odometry_motion(&b, &d);
                let (ga, _, _) = odometry_motion(&p, &da);
                let (gb, _, _) = odometry_motion(&p, &db);
                for i in 0..3 {
                    let diff = |x: f64, y: f64| if i == 2 { wrap_angle(x - y) } else { x - y };
                    close(f[(i, j)], diff(fa[i], fb[i]) / (2.0 * H), "F_odo");
                    close(l[(i, j)], diff(ga[i], gb[i]) / (2.0 * H), "L_odo");
                }
            }
        }
    }

    type RowFn<'a> = &'a dyn Fn(&Vector3<f64>, &Vector2<f64>) -> Option<ObservationRow>;

    fn check_row(row_fn: RowFn<'_>, angular: bool) {
        for p in poses() {
            for b in beacons() {
                let row = row_fn(&p, &b).unwrap();
                let diff = |x: f64, y: f64| if angular { wrap_angle(x - y) } else { x - y };
                for j in 0..3 {
                    let (mut pa, mut pb) = (p, p);
                    pa[j] += H;
                    pb[j] -= H;
                    let num = diff(
                        row_fn(&pa, &b).unwrap().predicted,
                        row_fn(&pb, &b).unwrap().predicted,
                    ) / (2.0 * H);
                    close(row.d_pose[j], num, "H_pose");
                }
                for j in 0..2 {
                    let (mut ba, mut bb) = (b, b);
                    ba[j] += H;
                    bb[j] -= H;
                    let num = diff(
                        row_fn(&p, &ba).unwrap().predicted,
                        row_fn(&p, &bb).unwrap().predicted,
                    ) / (2.0 * H);
                    close(row.d_beacon[j], num, "H_beacon");
                }
            }
        }
    }

    #[test]
    fn observation_jacobians_match_finite_differences() {
        check_row(&|p, b| range_row(p, b, 1e-3), false);
        check_row(&|p, b| bearing_row(p, b, 1e-3), true);
        let pl = PathLoss::default();
        check_row(&|p, b| rssi_row(p, b, &pl, 1e-3), false);
    }

    #[test]
    fn inverse_model_jacobians_match_finite_differences() {
        let pl = PathLoss {
            p_ref_dbm: -29.0,
            eta: 2.0,
        };
        for p in poses() {
            let (r, beta, z) = (2.5, -0.7, -40.0);
            let (_, gv, gz) = inverse_range_bearing(&p, r, beta);
            let (_, gv2, gz2) = inverse_rssi_bearing(&p, z, beta, &pl);
            let (_, gv3, gl3) = inverse_local_point(&p, &Vector2::new(1.5, -0.4));
            for j in 0..3 {
                let (mut a, mut b) = (p, p);
                a[j] += H;
                b[j] -= H;
                let na =
                    inverse_range_bearing(&a, r, beta).0 - inverse_range_bearing(&b, r, beta).0;
                let nb = inverse_rssi_bearing(&a, z, beta, &pl).0
                    - inverse_rssi_bearing(&b, z, beta, &pl).0;
                let nc = inverse_local_point(&a, &Vector2::new(1.5, -0.4)).0
                    - inverse_local_point(&b, &Vector2::new(1.5, -0.4)).0;
                for i in 0..2 {
                    close(gv[(i, j)], na[i] / (2.0 * H), "Gv");
                    close(gv2[(i, j)], nb[i] / (2.0 * H), "Gv_rssi");
                    close(gv3[(i, j)], nc[i] / (2.0 * H), "Gv_local");
                }
            }
            let n_r = (inverse_range_bearing(&p, r + H, beta).0
                - inverse_range_bearing(&p, r - H, beta).0)
                / (2.0 * H);
            let n_b = (inverse_range_bearing(&p, r, beta + H).0
                - inverse_range_bearing(&p, r, beta - H).0)
                / (2.0 * H);
            let n_z = (inverse_rssi_bearing(&p, z + H, beta, &pl).0
                - inverse_rssi_bearing(&p, z - H, beta, &pl).0)
                / (2.0 * H);
            let l = Vector2::new(1.5, -0.4);
            let n_lx = (inverse_local_point(&p, &(l + Vector2::new(H, 0.0))).0
                - inverse_local_point(&p, &(l - Vector2::new(H, 0.0))).0)
                / (2.0 * H);
            for i in 0..2 {
                close(gz[(i, 0)], n_r[i], "Gz_r");
                close(gz[(i, 1)], n_b[i], "Gz_beta");
                close(gz2[(i, 0)], n_z[i], "Gz_rssi");
                close(gl3[(i, 0)], n_lx[i], "Gl");
            }
        }
    }

    #[test]
    fn bearing_to_beacon_behind_robot_is_wrapped() {
        // Robot heading +170°, beacon straight behind-left: bearing must be near ±180°, never ±360°.
        let p = Vector3::new(0.0, 0.0, 170f64.to_radians());
        let b = Vector2::new(1.0, -0.1);
        let row = bearing_row(&p, &b, 1e-3).unwrap();
        assert!(row.predicted.abs() <= std::f64::consts::PI);
        let expected = wrap_angle((-0.1f64).atan2(1.0) - 170f64.to_radians());
        assert!((row.predicted - expected).abs() < 1e-12);
    }
}
