//! The EKF-SLAM filter: robot pose `(x, y, θ)` followed by 2-D beacon positions, growing as
//! beacons are first seen. Known data association by [`BeaconId`].

use std::collections::HashMap;

use std::collections::HashSet;

use nalgebra::{DMatrix, DVector, Matrix2, Matrix2x3, Matrix2xX, Matrix3, Vector2, Vector3};
use rfloc_pose::{wrap_angle, EstimateMode, Pose2, PoseEstimate};

use crate::config::{CovarianceUpdate, EkfSlamConfig, RssiHandling};
use crate::delayed::{triangulate, PendingBeacon, Triangulated, View};
use crate::error::{EkfSlamError, InvalidObservation};
use crate::models::{
    bearing_row, inverse_local_point, inverse_range_bearing, inverse_rssi_bearing, odometry_motion,
    range_row, rssi_row, velocity_motion, ObservationRow,
};
use crate::observation::{BeaconId, BeaconObservation, ObservationOutcome, RangeReading};

/// Counters of what the filter did (monotonic since construction).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FilterStats {
    /// Prediction steps applied.
    pub predictions: u64,
    /// Observations used to correct the state.
    pub updates: u64,
    /// Observations rejected by the Mahalanobis gate.
    pub rejected_by_gate: u64,
    /// Beacons added to the map.
    pub beacons_added: u64,
    /// Views stored for beacons awaiting delayed initialisation.
    pub pending_views: u64,
    /// Observations that were unusable ([`InvalidObservation`]).
    pub invalid: u64,
}

/// A mapped beacon's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeaconEstimate {
    /// Beacon key.
    pub id: BeaconId,
    /// Position in the map frame, m.
    pub position: Vector2<f64>,
    /// 2×2 marginal covariance, m².
    pub covariance: Matrix2<f64>,
}

/// One scalar measurement prepared for the update.
struct Scalar {
    row: ObservationRow,
    value: f64,
    variance: f64,
    angular: bool,
    /// State index of the pose the row's `d_pose` refers to (0: the robot; else a pose copy).
    pose_col: usize,
}

/// Prior variance of a beacon position before its stored views are applied, m²: wide enough to
/// carry no information next to the views.
const UNINFORMED_VARIANCE_M2: f64 = 1e4;

/// EKF-SLAM over robot pose and beacon positions. See the crate docs for the maths.
#[derive(Debug, Clone)]
pub struct EkfSlam {
    config: EkfSlamConfig,
    x: DVector<f64>,
    p: DMatrix<f64>,
    slots: HashMap<BeaconId, usize>,
    ids: Vec<BeaconId>,
    pending: HashMap<BeaconId, PendingBeacon>,
    /// Pose copies kept for pending views, in state order (after the beacons).
    clones: Vec<u64>,
    next_clone: u64,
    stats: FilterStats,
}

fn finite3(m: &Matrix3<f64>) -> bool {
    m.iter().all(|v| v.is_finite())
}

impl EkfSlam {
    /// Starts a filter at `initial` with 3×3 pose covariance `initial_cov` (may be zero when the
    /// start pose defines the map frame). The covariance must be symmetric positive semi-definite.
    pub fn new(
        config: EkfSlamConfig,
        initial: Pose2,
        initial_cov: Matrix3<f64>,
    ) -> Result<Self, EkfSlamError> {
        if !initial.is_finite() || !finite3(&initial_cov) {
            return Err(EkfSlamError::NonFinite {
                what: "initial pose or covariance",
            });
        }
        let sym = (initial_cov + initial_cov.transpose()) / 2.0;
        if (initial_cov - sym).abs().max() > 1e-9 * (1.0 + initial_cov.abs().max())
            || sym.symmetric_eigenvalues().min() < -1e-12
        {
            return Err(EkfSlamError::Invalid {
                what: "initial covariance",
                detail: "not symmetric positive semi-definite".into(),
            });
        }
        let mut p = DMatrix::zeros(3, 3);
        p.view_mut((0, 0), (3, 3)).copy_from(&sym);
        Ok(Self {
            config,
            x: DVector::from_column_slice(&[initial.x, initial.y, wrap_angle(initial.theta)]),
            p,
            slots: HashMap::new(),
            ids: Vec::new(),
            pending: HashMap::new(),
            clones: Vec::new(),
            next_clone: 0,
            stats: FilterStats::default(),
        })
    }

    /// The configuration in use.
    #[must_use]
    pub fn config(&self) -> &EkfSlamConfig {
        &self.config
    }

    /// Current robot pose estimate.
    #[must_use]
    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.x[0], self.x[1], self.x[2])
    }

    /// Current 3×3 robot pose covariance.
    #[must_use]
    pub fn pose_covariance(&self) -> Matrix3<f64> {
        self.p.fixed_view::<3, 3>(0, 0).into_owned()
    }

    /// The pose as a [`PoseEstimate`] stamped `time` (s): mode `Fix` once a beacon correction has
    /// been applied, else `Degraded` (dead reckoning only).
    #[must_use]
    pub fn pose_estimate(&self, time: f64) -> PoseEstimate {
        PoseEstimate {
            time,
            pose: self.pose(),
            covariance: self.pose_covariance(),
            mode: if self.stats.updates > 0 {
                EstimateMode::Fix
            } else {
                EstimateMode::Degraded
            },
            source: "ekfslam".into(),
        }
    }

    /// Full state vector `[x, y, θ, b1x, b1y, …]` (m, rad), followed by the pose copies of
    /// pending views (`x, y, θ` each, see [`crate::DelayedInit::view_poses_in_state`]).
    #[must_use]
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }

    /// Full state covariance.
    #[must_use]
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.p
    }

    /// Counters.
    #[must_use]
    pub fn stats(&self) -> FilterStats {
        self.stats
    }

    /// Number of mapped beacons.
    #[must_use]
    pub fn beacon_count(&self) -> usize {
        self.ids.len()
    }

    /// Pose copies currently kept in the state for pending views.
    #[must_use]
    pub fn view_pose_count(&self) -> usize {
        self.clones.len()
    }

    /// Beacons that have views stored but are not yet mapped.
    #[must_use]
    pub fn pending_beacons(&self) -> Vec<BeaconId> {
        let mut v: Vec<_> = self.pending.keys().copied().collect();
        v.sort_unstable();
        v
    }

    /// One mapped beacon's estimate.
    #[must_use]
    pub fn beacon(&self, id: BeaconId) -> Option<BeaconEstimate> {
        let slot = *self.slots.get(&id)?;
        let i = 3 + 2 * slot;
        Some(BeaconEstimate {
            id,
            position: Vector2::new(self.x[i], self.x[i + 1]),
            covariance: self.p.fixed_view::<2, 2>(i, i).into_owned(),
        })
    }

    /// All mapped beacons in the order they were added.
    #[must_use]
    pub fn beacons(&self) -> Vec<BeaconEstimate> {
        self.ids.iter().filter_map(|id| self.beacon(*id)).collect()
    }

    fn pose_vec(&self) -> Vector3<f64> {
        Vector3::new(self.x[0], self.x[1], self.x[2])
    }

    /// Predicts with a velocity command `v` (m/s), `omega` (rad/s) held for `dt` (s), with the
    /// configured [`crate::VelocityNoise`]. Touches only the pose rows and columns of P: O(n).
    pub fn predict_velocity(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), EkfSlamError> {
        if !(v.is_finite() && omega.is_finite() && dt.is_finite()) {
            return Err(EkfSlamError::NonFinite {
                what: "velocity command",
            });
        }
        if dt < 0.0 {
            return Err(EkfSlamError::Invalid {
                what: "time step",
                detail: format!("dt = {dt} < 0"),
            });
        }
        let (new, f, l) = velocity_motion(&self.pose_vec(), v, omega, dt);
        let n = &self.config.velocity_noise;
        let q = Matrix2::new(
            n.sigma_v * n.sigma_v,
            0.0,
            0.0,
            n.sigma_omega * n.sigma_omega,
        );
        self.apply_motion(&new, &f, &(l * q * l.transpose()));
        Ok(())
    }

    /// Predicts with an odometry increment `delta` = pose change expressed in the robot frame at
    /// the previous reading (m, m, rad), with the configured [`crate::OdometryNoise`]. O(n).
    pub fn predict_odometry(&mut self, delta: Pose2) -> Result<(), EkfSlamError> {
        if !delta.is_finite() {
            return Err(EkfSlamError::NonFinite {
                what: "odometry increment",
            });
        }
        let d = Vector3::new(delta.x, delta.y, delta.theta);
        let (new, f, l) = odometry_motion(&self.pose_vec(), &d);
        let on = &self.config.odometry_noise;
        let len = delta.x.hypot(delta.y);
        let s_xy = on.trans_per_m * len + on.floor_m;
        let s_th = on.rot_per_rad * delta.theta.abs() + on.rot_per_m * len + on.floor_rad;
        let q = Matrix3::from_diagonal(&Vector3::new(s_xy * s_xy, s_xy * s_xy, s_th * s_th));
        self.apply_motion(&new, &f, &(l * q * l.transpose()));
        Ok(())
    }

    /// Predicts with an explicit increment covariance `delta_cov` (3×3 over the increment in the
    /// robot frame) instead of the configured odometry noise.
    pub fn predict_odometry_with_covariance(
        &mut self,
        delta: Pose2,
        delta_cov: Matrix3<f64>,
    ) -> Result<(), EkfSlamError> {
        if !delta.is_finite() || !finite3(&delta_cov) {
            return Err(EkfSlamError::NonFinite {
                what: "odometry increment",
            });
        }
        let d = Vector3::new(delta.x, delta.y, delta.theta);
        let (new, f, l) = odometry_motion(&self.pose_vec(), &d);
        let q = (delta_cov + delta_cov.transpose()) / 2.0;
        self.apply_motion(&new, &f, &(l * q * l.transpose()));
        Ok(())
    }

    /// `P_rr ← F P_rr Fᵀ + N`, `P_rm ← F P_rm`, `P_mr ← P_rmᵀ`.
    fn apply_motion(&mut self, new: &Vector3<f64>, f: &Matrix3<f64>, noise: &Matrix3<f64>) {
        let n = self.x.len();
        self.x[0] = new.x;
        self.x[1] = new.y;
        self.x[2] = wrap_angle(new.z);
        let prr = self.p.fixed_view::<3, 3>(0, 0).into_owned();
        let prr_new = f * prr * f.transpose() + noise;
        let prr_new = (prr_new + prr_new.transpose()) / 2.0;
        self.p.fixed_view_mut::<3, 3>(0, 0).copy_from(&prr_new);
        if n > 3 {
            let prm = f * self.p.view((0, 3), (3, n - 3));
            self.p.view_mut((0, 3), (3, n - 3)).copy_from(&prm);
            self.p
                .view_mut((3, 0), (n - 3, 3))
                .copy_from(&prm.transpose());
        }
        self.stats.predictions += 1;
    }

    /// Processes a batch of observations taken at the current time. Mapped beacons are used
    /// first (sequential updates, each gated), then new beacons are added (inverse model when
    /// range and bearing are both present, else delayed initialisation). Returns one outcome per
    /// observation, in input order.
    pub fn update(&mut self, observations: &[BeaconObservation]) -> Vec<ObservationOutcome> {
        let mut out = vec![ObservationOutcome::Pending; observations.len()];
        let mut fresh = Vec::new();
        for (k, obs) in observations.iter().enumerate() {
            if let Err(e) = validate(obs) {
                self.stats.invalid += 1;
                if let Some(slot) = out.get_mut(k) {
                    *slot = ObservationOutcome::Invalid(e);
                }
                continue;
            }
            match self.slots.get(&obs.id).copied() {
                Some(slot) => {
                    let o = self.update_known(slot, obs);
                    if let Some(s) = out.get_mut(k) {
                        *s = o;
                    }
                }
                None => fresh.push(k),
            }
        }
        // Views stored by this batch share one copy of the pose.
        let mut batch_clone = None;
        for k in fresh {
            if let Some(obs) = observations.get(k) {
                // A beacon may appear twice in one batch: the second one is then a known update.
                let o = match self.slots.get(&obs.id).copied() {
                    Some(slot) => self.update_known(slot, obs),
                    None => self.add_new(obs, &mut batch_clone),
                };
                if let Some(s) = out.get_mut(k) {
                    *s = o;
                }
            }
        }
        self.drop_unused_clones();
        out
    }

    /// State index of pose copy `id`.
    fn clone_index(&self, id: u64) -> Option<usize> {
        let k = self.clones.iter().position(|&c| c == id)?;
        Some(3 + 2 * self.ids.len() + 3 * k)
    }

    /// The current estimate of pose copy `id`.
    fn clone_pose(&self, id: u64) -> Option<Vector3<f64>> {
        let i = self.clone_index(id)?;
        Some(Vector3::new(self.x[i], self.x[i + 1], self.x[i + 2]))
    }

    /// Appends a copy of the robot pose to the state (fully correlated with it).
    fn push_clone(&mut self) -> u64 {
        let n = self.x.len();
        let rows = self.p.rows(0, 3).into_owned();
        let prr = self.p.fixed_view::<3, 3>(0, 0).into_owned();
        let old = std::mem::replace(&mut self.p, DMatrix::zeros(0, 0));
        self.p = old.resize(n + 3, n + 3, 0.0);
        self.p.view_mut((n, 0), (3, n)).copy_from(&rows);
        self.p.view_mut((0, n), (n, 3)).copy_from(&rows.transpose());
        self.p.fixed_view_mut::<3, 3>(n, n).copy_from(&prr);
        let oldx = std::mem::replace(&mut self.x, DVector::zeros(0));
        self.x = oldx.resize_vertically(n + 3, 0.0);
        for k in 0..3 {
            self.x[n + k] = self.x[k];
        }
        let id = self.next_clone;
        self.next_clone += 1;
        self.clones.push(id);
        id
    }

    /// Marginalises out the pose copies no pending view refers to any more.
    fn drop_unused_clones(&mut self) {
        let used: HashSet<u64> = self
            .pending
            .values()
            .flat_map(|p| p.views.iter().filter_map(|v| v.clone))
            .collect();
        let unused: Vec<u64> = self
            .clones
            .iter()
            .copied()
            .filter(|c| !used.contains(c))
            .collect();
        for id in unused {
            if let Some(i) = self.clone_index(id) {
                let old = std::mem::replace(&mut self.p, DMatrix::zeros(0, 0));
                self.p = old.remove_rows(i, 3).remove_columns(i, 3);
                let oldx = std::mem::replace(&mut self.x, DVector::zeros(0));
                self.x = oldx.remove_rows(i, 3);
                self.clones.retain(|&c| c != id);
            }
        }
    }

    fn scalars(
        &self,
        obs: &BeaconObservation,
        pose: &Vector3<f64>,
        b: &Vector2<f64>,
    ) -> Result<Vec<Scalar>, InvalidObservation> {
        let cfg = &self.config;
        let mut v = Vec::with_capacity(2);
        if let Some(r) = obs.range {
            let s = match r {
                RangeReading::Metres {
                    range_m,
                    variance_m2,
                } => Scalar {
                    row: range_row(pose, b, cfg.min_distance_m)
                        .ok_or(InvalidObservation::TooClose)?,
                    value: range_m,
                    variance: variance_m2,
                    angular: false,
                    pose_col: 0,
                },
                RangeReading::RssiDbm {
                    rssi_dbm,
                    variance_db2,
                } => match cfg.rssi_handling {
                    RssiHandling::PathLossMeasurement => Scalar {
                        row: rssi_row(pose, b, &cfg.path_loss, cfg.min_distance_m)
                            .ok_or(InvalidObservation::TooClose)?,
                        value: rssi_dbm,
                        variance: variance_db2,
                        angular: false,
                        pose_col: 0,
                    },
                    RssiHandling::ConvertToRange => {
                        let d = cfg.path_loss.distance_for(rssi_dbm);
                        let sd = d * variance_db2.sqrt() * cfg.path_loss.ln_distance_per_db();
                        Scalar {
                            row: range_row(pose, b, cfg.min_distance_m)
                                .ok_or(InvalidObservation::TooClose)?,
                            value: d,
                            variance: sd * sd,
                            angular: false,
                            pose_col: 0,
                        }
                    }
                },
            };
            v.push(s);
        }
        if let Some(br) = obs.bearing {
            v.push(Scalar {
                row: bearing_row(pose, b, cfg.min_distance_m)
                    .ok_or(InvalidObservation::TooClose)?,
                value: br.bearing_rad,
                variance: br.variance_rad2,
                angular: true,
                pose_col: 0,
            });
        }
        Ok(v)
    }

    fn update_known(&mut self, slot: usize, obs: &BeaconObservation) -> ObservationOutcome {
        let i = 3 + 2 * slot;
        let pose = self.pose_vec();
        let b = Vector2::new(self.x[i], self.x[i + 1]);
        let scalars = match self.scalars(obs, &pose, &b) {
            Ok(s) => s,
            Err(e) => {
                self.stats.invalid += 1;
                return ObservationOutcome::Invalid(e);
            }
        };
        self.apply_scalars(i, &scalars, true)
    }

    /// Sequential EKF update of one beacon's 1–2 scalar measurements (one joint update).
    fn apply_scalars(&mut self, bi: usize, scalars: &[Scalar], gated: bool) -> ObservationOutcome {
        let n = self.x.len();
        let m = scalars.len();
        // M = P Hᵀ using only the 3 pose and 2 beacon columns of H: O(n·m).
        let mut mm = DMatrix::zeros(n, m);
        for (k, s) in scalars.iter().enumerate() {
            let pc = s.pose_col;
            let cols = [
                (pc, s.row.d_pose[0]),
                (pc + 1, s.row.d_pose[1]),
                (pc + 2, s.row.d_pose[2]),
                (bi, s.row.d_beacon[0]),
                (bi + 1, s.row.d_beacon[1]),
            ];
            let mut out = mm.column_mut(k);
            for (c, h) in cols {
                if h != 0.0 {
                    out.axpy(h, &self.p.column(c), 1.0);
                }
            }
        }
        let mut s_mat = DMatrix::zeros(m, m);
        let mut nu = DVector::zeros(m);
        for (a, sa) in scalars.iter().enumerate() {
            let hp = &sa.row.d_pose;
            let hb = &sa.row.d_beacon;
            let pc = sa.pose_col;
            for k in 0..m {
                s_mat[(a, k)] = hp[0] * mm[(pc, k)]
                    + hp[1] * mm[(pc + 1, k)]
                    + hp[2] * mm[(pc + 2, k)]
                    + hb[0] * mm[(bi, k)]
                    + hb[1] * mm[(bi + 1, k)];
            }
            s_mat[(a, a)] += sa.variance;
            let d = sa.value - sa.row.predicted;
            nu[a] = if sa.angular { wrap_angle(d) } else { d };
        }
        let s_mat = (&s_mat + s_mat.transpose()) / 2.0;
        let Some(chol) = s_mat.clone().cholesky() else {
            self.stats.invalid += 1;
            return ObservationOutcome::Invalid(InvalidObservation::SingularInnovation);
        };
        let nis = nu.dot(&chol.solve(&nu));
        let gate = &self.config.gate;
        let limit = if m == 1 {
            gate.chi2_1dof
        } else {
            gate.chi2_2dof
        };
        if !nis.is_finite() {
            self.stats.invalid += 1;
            return ObservationOutcome::Invalid(InvalidObservation::SingularInnovation);
        }
        if gated && gate.enabled && nis > limit {
            self.stats.rejected_by_gate += 1;
            return ObservationOutcome::Rejected { nis, dof: m };
        }
        let kt = chol.solve(&mm.transpose()); // Kᵀ = S⁻¹ Mᵀ  (m×n)
        let k = kt.transpose();
        self.x += &k * &nu;
        self.x[2] = wrap_angle(self.x[2]);
        // Both forms are applied as one pass of bitwise-symmetric rank-m corrections, so P stays
        // exactly symmetric without a separate symmetrisation pass.
        match self.config.covariance_update {
            CovarianceUpdate::Joseph => {
                // (I−KH)P(I−KH)ᵀ + KRKᵀ = P − KMᵀ − MKᵀ + K S Kᵀ, valid for any gain K;
                // K S Kᵀ = G Gᵀ with G = K L.
                let g = &k * chol.l();
                joseph_correction(&mut self.p, &k, &mm, &g);
            }
            CovarianceUpdate::Cholesky => {
                // P − W Wᵀ with W = M L⁻ᵀ, i.e. Wᵀ = L⁻¹ Mᵀ.
                let Some(wt) = chol.l().solve_lower_triangular(&mm.transpose()) else {
                    self.stats.invalid += 1;
                    return ObservationOutcome::Invalid(InvalidObservation::SingularInnovation);
                };
                downdate(&mut self.p, &wt.transpose());
            }
        }
        self.stats.updates += 1;
        ObservationOutcome::Updated { nis, dof: m }
    }

    fn add_new(
        &mut self,
        obs: &BeaconObservation,
        batch_clone: &mut Option<u64>,
    ) -> ObservationOutcome {
        let pose = self.pose_vec();
        let cfg = self.config;
        let dc = cfg.delayed_init;
        if let (Some(r), Some(b), false) = (obs.range, obs.bearing, dc.delay_range_bearing) {
            let (pos, gv, meas_cov) = match (r, cfg.rssi_handling) {
                (
                    RangeReading::RssiDbm {
                        rssi_dbm,
                        variance_db2,
                    },
                    RssiHandling::PathLossMeasurement,
                ) => {
                    let (pos, gv, gz) =
                        inverse_rssi_bearing(&pose, rssi_dbm, b.bearing_rad, &cfg.path_loss);
                    let r = Matrix2::new(variance_db2, 0.0, 0.0, b.variance_rad2);
                    (pos, gv, gz * r * gz.transpose())
                }
                (
                    RangeReading::RssiDbm {
                        rssi_dbm,
                        variance_db2,
                    },
                    RssiHandling::ConvertToRange,
                ) => {
                    let d = cfg.path_loss.distance_for(rssi_dbm);
                    let sd = d * variance_db2.sqrt() * cfg.path_loss.ln_distance_per_db();
                    let (pos, gv, gz) = inverse_range_bearing(&pose, d, b.bearing_rad);
                    let r = Matrix2::new(sd * sd, 0.0, 0.0, b.variance_rad2);
                    (pos, gv, gz * r * gz.transpose())
                }
                (
                    RangeReading::Metres {
                        range_m,
                        variance_m2,
                    },
                    _,
                ) => {
                    let (pos, gv, gz) = inverse_range_bearing(&pose, range_m, b.bearing_rad);
                    let r = Matrix2::new(variance_m2, 0.0, 0.0, b.variance_rad2);
                    (pos, gv, gz * r * gz.transpose())
                }
            };
            self.pending.remove(&obs.id);
            self.augment(obs.id, &pos, &gv, &meas_cov);
            return ObservationOutcome::Added;
        }
        let clone = if dc.view_poses_in_state {
            Some(*batch_clone.get_or_insert_with(|| self.push_clone()))
        } else {
            None
        };
        let mut entry = self.pending.remove(&obs.id).unwrap_or_default();
        entry.views.push_back(View {
            pose,
            clone,
            range: obs.range,
            bearing: obs.bearing,
        });
        while entry.views.len() > dc.max_views.max(1) {
            entry.views.pop_front();
        }
        self.stats.pending_views += 1;
        let found = triangulate(&entry, &cfg, |v| {
            v.clone.and_then(|c| self.clone_pose(c)).unwrap_or(v.pose)
        });
        let Some(tri) = found else {
            self.pending.insert(obs.id, entry);
            return ObservationOutcome::Pending;
        };
        let clone_rows: Option<Vec<usize>> = entry
            .views
            .iter()
            .map(|v| v.clone.and_then(|c| self.clone_index(c)))
            .collect();
        match clone_rows {
            Some(rows) => {
                if !self.add_with_views(obs.id, &tri, &entry) {
                    self.augment_from_views(obs.id, &tri, &rows);
                }
            }
            None => {
                // Treat the triangulated point as a point known in the current robot frame:
                // b = p + R(θ)l, l = R(θ)ᵀ(b − p), so that the new beacon gets full
                // cross-covariances with the pose and map.
                let pos = tri.position;
                let (s, c) = pose.z.sin_cos();
                let d = pos - Vector2::new(pose.x, pose.y);
                let local = Vector2::new(c * d.x + s * d.y, -s * d.x + c * d.y);
                let (_, gv, _) = inverse_local_point(&pose, &local);
                self.augment(obs.id, &pos, &gv, &tri.cov);
            }
        }
        ObservationOutcome::Added
    }

    /// Adds a beacon whose views' poses are copies in the state: at the triangulated position
    /// with an uninformed prior, then one joint EKF update with every stored view, each against
    /// its pose copy, linearised at the triangulated position (the least-squares optimum of the
    /// same views). Unlike attaching the triangulated point, this keeps the views' information
    /// beyond the beacon's two coordinates: where they over-determine it, they correct the
    /// copies' poses, and through their correlations the current pose and the map. Returns
    /// false (and leaves the filter as it was) when the update cannot be applied.
    fn add_with_views(&mut self, id: BeaconId, tri: &Triangulated, entry: &PendingBeacon) -> bool {
        let n = self.x.len();
        let (x0, p0) = (self.x.clone(), self.p.clone());
        let wide = Matrix2::identity() * UNINFORMED_VARIANCE_M2;
        self.insert_beacon(id, &tri.position, &Matrix2xX::zeros(n), &wide);
        let bi = 3 + 2 * (self.ids.len() - 1);
        let mut all = Vec::new();
        let mut usable = true;
        for v in &entry.views {
            let (Some(col), Some(pose)) = (
                v.clone.and_then(|c| self.clone_index(c)),
                v.clone.and_then(|c| self.clone_pose(c)),
            ) else {
                usable = false;
                break;
            };
            let obs = BeaconObservation {
                id,
                range: v.range,
                bearing: v.bearing,
            };
            match self.scalars(&obs, &pose, &tri.position) {
                Ok(rows) => all.extend(rows.into_iter().map(|s| Scalar { pose_col: col, ..s })),
                Err(_) => {
                    usable = false;
                    break;
                }
            }
        }
        let stats = self.stats;
        if usable
            && matches!(
                self.apply_scalars(bi, &all, false),
                ObservationOutcome::Updated { .. }
            )
        {
            return true;
        }
        // Undo the insertion.
        self.x = x0;
        self.p = p0;
        self.stats = stats;
        self.stats.beacons_added -= 1;
        self.slots.remove(&id);
        self.ids.pop();
        false
    }

    /// Adds a beacon triangulated from views whose poses are copies in the state (rows
    /// `rows[k]` for view k): with `J` the Jacobian of the position with respect to those
    /// copies, `P_Lx = J P_{views,x}` for every state and `P_LL = J P_{views,views} Jᵀ + C`.
    fn augment_from_views(&mut self, id: BeaconId, tri: &Triangulated, rows: &[usize]) {
        let n = self.x.len();
        let mut jp = Matrix2xX::zeros(n);
        for (j, &r) in tri.d_view_pose.iter().zip(rows) {
            jp += j * self.p.rows(r, 3);
        }
        let mut pll = tri.cov;
        for (j, &r) in tri.d_view_pose.iter().zip(rows) {
            pll += jp.columns(r, 3) * j.transpose();
        }
        let pll = (pll + pll.transpose()) / 2.0;
        self.insert_beacon(id, &tri.position, &jp, &pll);
    }

    /// Bailey-style augmentation: `P_LL = G_v P_vv G_vᵀ + C_z`, `P_Lx = G_v P_vx` for every
    /// existing state `x` (pose, beacons and pose copies).
    fn augment(
        &mut self,
        id: BeaconId,
        pos: &Vector2<f64>,
        gv: &Matrix2x3<f64>,
        meas_cov: &Matrix2<f64>,
    ) {
        let n = self.x.len();
        let plx = gv * self.p.view((0, 0), (3, n));
        let pvv = self.p.fixed_view::<3, 3>(0, 0).into_owned();
        let pll = gv * pvv * gv.transpose() + meas_cov;
        let pll = (pll + pll.transpose()) / 2.0;
        self.insert_beacon(id, pos, &plx, &pll);
    }

    /// Inserts a beacon after the mapped ones (before any pose copies) with cross-covariance
    /// `plx` (2×n, against the current state) and covariance `pll`.
    fn insert_beacon(
        &mut self,
        id: BeaconId,
        pos: &Vector2<f64>,
        plx: &Matrix2xX<f64>,
        pll: &Matrix2<f64>,
    ) {
        let n = self.x.len();
        let at = 3 + 2 * self.ids.len();
        let old = std::mem::replace(&mut self.p, DMatrix::zeros(0, 0));
        let mut p = old.insert_rows(at, 2, 0.0).insert_columns(at, 2, 0.0);
        // Old columns before `at` keep their index, the rest move by two.
        for j in 0..n {
            let nj = if j < at { j } else { j + 2 };
            for r in 0..2 {
                p[(at + r, nj)] = plx[(r, j)];
                p[(nj, at + r)] = plx[(r, j)];
            }
        }
        p.fixed_view_mut::<2, 2>(at, at).copy_from(pll);
        self.p = p;
        let oldx = std::mem::replace(&mut self.x, DVector::zeros(0));
        let mut x = oldx.insert_rows(at, 2, 0.0);
        x[at] = pos.x;
        x[at + 1] = pos.y;
        self.x = x;
        self.slots.insert(id, self.ids.len());
        self.ids.push(id);
        self.stats.beacons_added += 1;
    }
}

fn validate(obs: &BeaconObservation) -> Result<(), InvalidObservation> {
    if obs.range.is_none() && obs.bearing.is_none() {
        return Err(InvalidObservation::Empty);
    }
    if let Some(r) = obs.range {
        let (v, var, metres) = match r {
            RangeReading::Metres {
                range_m,
                variance_m2,
            } => (range_m, variance_m2, true),
            RangeReading::RssiDbm {
                rssi_dbm,
                variance_db2,
            } => (rssi_dbm, variance_db2, false),
        };
        if !(v.is_finite() && var.is_finite()) {
            return Err(InvalidObservation::NonFinite);
        }
        if var <= 0.0 {
            return Err(InvalidObservation::NonPositiveVariance);
        }
        if metres && v <= 0.0 {
            return Err(InvalidObservation::NonPositiveRange);
        }
    }
    if let Some(b) = obs.bearing {
        if !(b.bearing_rad.is_finite() && b.variance_rad2.is_finite()) {
            return Err(InvalidObservation::NonFinite);
        }
        if b.variance_rad2 <= 0.0 {
            return Err(InvalidObservation::NonPositiveVariance);
        }
    }
    Ok(())
}

/// `P[i][j] += Σₐ (G[i][a]·G[j][a] − (K[i][a]·M[j][a] + M[i][a]·K[j][a]))` over all i, j: the
/// expanded Joseph correction. Each term is symmetric in (i, j) bit for bit. Works on the
/// column-major storage directly (contiguous columns, no bounds checks in the inner loop).
fn joseph_correction(p: &mut DMatrix<f64>, k: &DMatrix<f64>, m: &DMatrix<f64>, g: &DMatrix<f64>) {
    let n = p.nrows();
    if n == 0 {
        return;
    }
    let (ks, ms, gs) = (k.as_slice(), m.as_slice(), g.as_slice());
    for ((ka, ma), ga) in ks
        .chunks_exact(n)
        .zip(ms.chunks_exact(n))
        .zip(gs.chunks_exact(n))
    {
        for (((pcol, kj), mj), gj) in p.as_mut_slice().chunks_exact_mut(n).zip(ka).zip(ma).zip(ga) {
            for (((pij, ki), mi), gi) in pcol.iter_mut().zip(ka).zip(ma).zip(ga) {
                *pij += gi * gj - (ki * mj + mi * kj);
            }
        }
    }
}

/// `P[i][j] −= Σₐ W[i][a]·W[j][a]`.
fn downdate(p: &mut DMatrix<f64>, w: &DMatrix<f64>) {
    let n = p.nrows();
    if n == 0 {
        return;
    }
    for wa in w.as_slice().chunks_exact(n) {
        for (pcol, wj) in p.as_mut_slice().chunks_exact_mut(n).zip(wa) {
            for (pij, wi) in pcol.iter_mut().zip(wa) {
                *pij -= wi * wj;
            }
        }
    }
}
